//! USBL measurement models (S-USBL) and the unscented measurement update.
//!
//! The docking station carries the USBL array: a central transducer at the surveyed position and
//! four hydrophones in the array frame a (x, y horizontal, z down; yaw surveyed from north),
//! 1 and 3 on ±x, 2 and 4 on ±y, at half the baseline from the centre. The vehicle carries the
//! responder at lever arm l^b from the IMU.
//!
//! * **Tight** ([`predict_tight`]): slant range R = |p_a| from the central transducer and the range
//!   differences ΔR13 = |p_a − h1| − |p_a − h3|, ΔR24 = |p_a − h2| − |p_a − h4|, with
//!   p_a = C_n^a (r_auv − r_array + C_b^n l^b) — exact geometry (the NED offset is exact, through
//!   ECEF, and the lever arm is turned from the vehicle's NED into the array's).
//! * **Loose** ([`fix_position_ned`]): the device's own fix from slant range and angles, as a
//!   position of the responder in the array's NED frame.
//! * **Angles to range differences** ([`range_differences_from_angles`]): for devices that report
//!   azimuth/elevation instead of range differences, the far-field relation ΔR13 ≈ −b·u_x,
//!   ΔR24 ≈ −b·u_y (u the unit direction to the responder); its error is below b²/R.
//!
//! The measurements are nonlinear in the state; [`unscented_update`] updates an error state with
//! sigma points (parameters named in [`UnscentedParams`]) and equals the Kalman update when the
//! measurement is linear.

use crate::earth::{Geodetic, c_ecef_to_ned, ned_offset};
use nalgebra::{DMatrix, DVector, Matrix3, Rotation3, Vector3};

/// The station's USBL array as surveyed.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct UsblArray {
    /// Position of the central transducer.
    pub position: Geodetic,
    /// Rotation NED → array frame (from the surveyed yaw, and roll/pitch when known).
    pub c_ned_to_array: Matrix3<f64>,
    /// Hydrophone positions in the array frame (m).
    pub hydrophones: [Vector3<f64>; 4],
}

impl UsblArray {
    /// A level array at `position`, its x axis `yaw_rad` from north, hydrophones at ±b/2 on x (1,
    /// 3) and y (2, 4).
    pub fn level(position: Geodetic, yaw_rad: f64, baseline_m: f64) -> UsblArray {
        let h = baseline_m / 2.0;
        UsblArray {
            position,
            c_ned_to_array: Rotation3::from_euler_angles(0.0, 0.0, yaw_rad)
                .inverse()
                .into_inner(),
            hydrophones: [
                Vector3::new(h, 0.0, 0.0),
                Vector3::new(0.0, h, 0.0),
                Vector3::new(-h, 0.0, 0.0),
                Vector3::new(0.0, -h, 0.0),
            ],
        }
    }

    /// The responder in the array frame (m): vehicle (IMU) position, attitude C_b^n (the
    /// vehicle's local NED), lever arm. The lever arm is turned from the vehicle's NED into the
    /// array's (they differ by the arc between them: 0.3 mrad at 2 km).
    pub fn responder_in_array(
        &self,
        vehicle: &Geodetic,
        c_body_to_ned: &Matrix3<f64>,
        lever_arm_b: &Vector3<f64>,
    ) -> Vector3<f64> {
        let c_vehicle_ned_to_array_ned =
            c_ecef_to_ned(self.position.latitude_rad, self.position.longitude_rad)
                * c_ecef_to_ned(vehicle.latitude_rad, vehicle.longitude_rad).transpose();
        self.c_ned_to_array
            * (ned_offset(&self.position, vehicle)
                + c_vehicle_ned_to_array_ned * c_body_to_ned * lever_arm_b)
    }
}

/// The tight measurement [R, ΔR13, ΔR24] (m) predicted for a responder at `p_a` (array frame).
pub fn predict_tight(array: &UsblArray, p_a: &Vector3<f64>) -> Vector3<f64> {
    let r = array.hydrophones.map(|h| (p_a - h).norm());
    Vector3::new(p_a.norm(), r[0] - r[2], r[1] - r[3])
}

/// The responder position (array NED frame: north, east, down from the transducer, m) from a slant
/// range and the array-frame azimuth (from x towards y) and elevation (positive towards −z, up).
pub fn fix_position_ned(
    array: &UsblArray,
    range_m: f64,
    azimuth: f64,
    elevation: f64,
) -> Vector3<f64> {
    let p_a = range_m
        * Vector3::new(
            elevation.cos() * azimuth.cos(),
            elevation.cos() * azimuth.sin(),
            -elevation.sin(),
        );
    array.c_ned_to_array.transpose() * p_a
}

/// Far-field range differences [ΔR13, ΔR24] from angles (for devices that report angles): the
/// direction u = (cos el cos az, cos el sin az, −sin el) and ΔR13 ≈ −b u_x, ΔR24 ≈ −b u_y for a
/// cross array of baseline b. The approximation error is below b²/R.
pub fn range_differences_from_angles(baseline_m: f64, azimuth: f64, elevation: f64) -> [f64; 2] {
    [
        -baseline_m * elevation.cos() * azimuth.cos(),
        -baseline_m * elevation.cos() * azimuth.sin(),
    ]
}

/// Sigma-point parameters of the unscented transform: spread α (0 < α ≤ 1), prior-knowledge β
/// (2 is optimal for Gaussians), secondary scaling κ (usually 0).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct UnscentedParams {
    pub alpha: f64,
    pub beta: f64,
    pub kappa: f64,
}

impl Default for UnscentedParams {
    fn default() -> Self {
        UnscentedParams {
            alpha: 0.5,
            beta: 2.0,
            kappa: 0.0,
        }
    }
}

/// The result of an unscented update.
#[derive(Debug, Clone)]
pub struct UnscentedUpdate {
    /// The estimated error state (to feed back).
    pub dx: DVector<f64>,
    /// The updated covariance.
    pub p: DMatrix<f64>,
    /// Innovation z − ẑ and its covariance.
    pub innovation: DVector<f64>,
    pub innovation_cov: DMatrix<f64>,
}

/// Updates an error state (mean zero, covariance `p`) with measurement `z` (noise covariance
/// `r`), where `h(δx)` predicts the measurement for the nominal state corrected by δx. `None` when
/// a covariance is not positive definite.
pub fn unscented_update(
    p: &DMatrix<f64>,
    z: &DVector<f64>,
    r: &DMatrix<f64>,
    h: &dyn Fn(&DVector<f64>) -> DVector<f64>,
    params: UnscentedParams,
) -> Option<UnscentedUpdate> {
    let n = p.nrows();
    let m = z.len();
    let nf = n as f64;
    let lambda = params.alpha * params.alpha * (nf + params.kappa) - nf;
    let scaled = p * (nf + lambda);
    let l = scaled.cholesky()?.l();
    let wm0 = lambda / (nf + lambda);
    let wc0 = wm0 + 1.0 - params.alpha * params.alpha + params.beta;
    let wi = 1.0 / (2.0 * (nf + lambda));
    // Sigma points: 0, +columns, −columns.
    let mut points = Vec::with_capacity(2 * n + 1);
    points.push(DVector::zeros(n));
    for i in 0..n {
        points.push(l.column(i).into_owned());
    }
    for i in 0..n {
        points.push(-l.column(i).into_owned());
    }
    let zs: Vec<DVector<f64>> = points.iter().map(h).collect();
    let weight_m = |k: usize| if k == 0 { wm0 } else { wi };
    let weight_c = |k: usize| if k == 0 { wc0 } else { wi };
    let mut z_mean = DVector::zeros(m);
    for (k, zk) in zs.iter().enumerate() {
        z_mean += zk * weight_m(k);
    }
    let mut s = r.clone();
    let mut pxz = DMatrix::zeros(n, m);
    for (k, (xk, zk)) in points.iter().zip(&zs).enumerate() {
        let dz = zk - &z_mean;
        s += &dz * dz.transpose() * weight_c(k);
        pxz += xk * dz.transpose() * weight_c(k);
    }
    let s_inv = s.clone().try_inverse()?;
    let k = &pxz * &s_inv;
    let innovation = z - &z_mean;
    let dx = &k * &innovation;
    let mut p_new = p - &k * &s * k.transpose();
    p_new = (&p_new + p_new.transpose()) * 0.5;
    Some(UnscentedUpdate {
        dx,
        p: p_new,
        innovation,
        innovation_cov: s,
    })
}

/// On-line estimate of a diagonal measurement-noise covariance from the innovations (Sage–Husa
/// with a fading factor), with innovation gating so that outliers (multipath jumps) neither enter
/// the state nor the noise estimate.
///
/// With innovation ε and predicted measurement covariance H P⁻ Hᵀ, per component i:
/// d_k = (1 − b) / (1 − b^(k+1)), R_i ← (1 − d_k) R_i + d_k (ε_i² − (H P⁻ Hᵀ)_ii), kept within
/// [r_min, r_max]. R_i is only learnt while (H P⁻ Hᵀ)_ii < R_i: while the state's own uncertainty
/// dominates, ε_i² says little about the noise and an undetected outlier would inflate it (seen in
/// the test: one 20 m jump at the start raised σ to 6 m). A component whose ε_i² / (H P⁻ Hᵀ + R)_ii
/// exceeds `gate_chi2` rejects the
/// whole measurement. After `reopen_after` consecutive rejections the noise is assumed to have
/// changed: the next measurement is accepted and its innovation taken as the new noise (counted),
/// so a real change of the noise cannot lock the gate shut for ever.
#[derive(Debug, Clone)]
pub struct AdaptiveNoise {
    r: DVector<f64>,
    /// Fading factor b (0.9..1): the memory is about 1 / (1 − b) measurements.
    pub fading: f64,
    pub r_min: f64,
    pub r_max: f64,
    /// Gate on the normalised squared innovation per component (χ², 1 degree of freedom).
    pub gate_chi2: f64,
    pub reopen_after: u32,
    k: u64,
    consecutive: u32,
    /// Measurements rejected by the gate.
    pub rejected: u64,
    /// Times the gate was reopened after a run of rejections.
    pub reopened: u64,
}

impl AdaptiveNoise {
    /// Starts from the diagonal `r0` (variances).
    pub fn new(r0: DVector<f64>, fading: f64, r_min: f64, r_max: f64, gate_chi2: f64) -> Self {
        AdaptiveNoise {
            r: r0,
            fading,
            r_min,
            r_max,
            gate_chi2,
            reopen_after: 20,
            k: 0,
            consecutive: 0,
            rejected: 0,
            reopened: 0,
        }
    }

    /// The current noise covariance (diagonal).
    pub fn covariance(&self) -> DMatrix<f64> {
        DMatrix::from_diagonal(&self.r)
    }

    /// The current variances.
    pub fn variances(&self) -> &DVector<f64> {
        &self.r
    }

    /// Gates the innovation `eps` (predicted measurement covariance without noise `hph`) and, if
    /// it passes, updates the estimate. Returns whether the measurement is to be used.
    pub fn observe(&mut self, eps: &DVector<f64>, hph: &DMatrix<f64>) -> bool {
        let outlier = (0..eps.len()).any(|i| {
            let s = hph[(i, i)] + self.r[i];
            let e2 = eps[i] * eps[i];
            e2.is_nan() || e2 > self.gate_chi2 * s
        });
        if outlier && self.consecutive < self.reopen_after {
            self.consecutive += 1;
            self.rejected += 1;
            return false;
        }
        if outlier {
            self.reopened += 1;
        }
        self.consecutive = 0;
        let b = self.fading;
        let d = (1.0 - b) / (1.0 - b.powi((self.k + 1).min(i32::MAX as u64) as i32));
        self.k += 1;
        for i in 0..eps.len() {
            if hph[(i, i)] >= self.r[i] {
                continue;
            }
            let sample = eps[i] * eps[i] - hph[(i, i)];
            let v = (1.0 - d) * self.r[i] + d * sample;
            self.r[i] = v.clamp(self.r_min, self.r_max);
        }
        true
    }
}
