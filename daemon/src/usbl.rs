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
use serde::{Deserialize, Serialize};

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

/// The result of a measurement update (unscented or linearised).
#[derive(Debug, Clone)]
pub struct MeasurementUpdate {
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
) -> Option<MeasurementUpdate> {
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
    Some(MeasurementUpdate {
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
/// R_i ← b R_i + (1 − b) (ε_i² − (H P⁻ Hᵀ)_ii), kept within [r_min, r_max]. The weight is
/// constant: the starting value counts as a full memory of measurements. (The bias-corrected
/// weights d_k = (1 − b) / (1 − b^(k+1)) of the textbook form give the first innovation weight 1:
/// one small innovation then set R far below the truth, the gate became too narrow and R could
/// not grow back while H P⁻ Hᵀ exceeded it — seen in the docking Monte Carlo.) R_i is only
/// learnt while (H P⁻ Hᵀ)_ii < R_i: while the state's own uncertainty dominates, ε_i² says little about the noise and an undetected outlier would inflate it (seen in
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
    /// Learn the noise from the innovations (false: fixed noise, gating only).
    pub learn: bool,
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
            learn: true,
            consecutive: 0,
            rejected: 0,
            reopened: 0,
        }
    }

    /// The current noise covariance (diagonal).
    pub fn covariance(&self) -> DMatrix<f64> {
        DMatrix::from_diagonal(&self.r)
    }

    /// Replaces the variances (a fixed-noise filter whose noise follows the geometry).
    pub fn set_variances(&mut self, r: &DVector<f64>) {
        self.r.copy_from(r);
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
        self.consecutive = 0;
        if outlier {
            self.reopened += 1;
            // The noise has changed (or the state is off): restart from this innovation.
            for i in 0..eps.len() {
                let sample = eps[i] * eps[i] - hph[(i, i)];
                self.r[i] = self.r[i].max(sample).clamp(self.r_min, self.r_max);
            }
            return true;
        }
        if !self.learn {
            return true;
        }
        let d = 1.0 - self.fading;
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

/// How USBL measurements enter the filter.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize, clap::ValueEnum)]
#[serde(rename_all = "lowercase")]
pub enum Coupling {
    /// The device's position fix (conventional).
    Loose,
    /// Slant range and the two range differences, with Gauss–Markov error states (S-USBL).
    #[default]
    Tight,
}

/// Which filter fuses the USBL measurements.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize, clap::ValueEnum)]
#[serde(rename_all = "lowercase")]
pub enum UsblFilter {
    /// Unscented update with the configured (fixed) noise and innovation gating.
    Ukf,
    /// Adaptive linearised Kalman update: Jacobian of the same model, the noise learnt on line
    /// (Sage–Husa) and the same gating.
    Akf,
    /// Adaptive unscented update: unscented update, noise learnt on line, gating.
    #[default]
    Aukf,
}

/// The `[navigation.usbl]` configuration: the station's array as surveyed, the responder on the
/// vehicle, the measurement noise and error processes, the coupling and the filter.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct UsblConfig {
    /// Loose (position fix) or tight (slant range and range differences). Default tight.
    pub coupling: Coupling,
    /// ukf, akf or aukf. Default aukf.
    pub filter: UsblFilter,
    /// Surveyed position of the central transducer (deg, deg, m above the ellipsoid).
    pub array_latitude_deg: f64,
    pub array_longitude_deg: f64,
    pub array_height_m: f64,
    /// Surveyed yaw of the array x axis (hydrophones 1 → 3 on −x… +x) from north (deg).
    pub array_yaw_deg: f64,
    /// Distance between opposite hydrophones (m). Default 0.5.
    pub baseline_m: f64,
    /// Responder position in the vehicle body frame (m). Default 0.
    pub responder_lever_arm_m: [f64; 3],
    /// Slant-range noise (m). Default 0.1.
    pub range_std_m: f64,
    /// Range-difference noise (m). Default 0.002.
    pub range_difference_std_m: f64,
    /// Azimuth/elevation noise of devices that report angles (deg). Default 0.2.
    pub angle_std_deg: f64,
    /// Slant-range error process (sound speed, timing): stationary one-sigma (m). Default 0.2.
    pub range_error_std_m: f64,
    /// Its correlation time (s). Default 300.
    pub range_error_correlation_s: f64,
    /// Range-difference error process (array orientation, phase calibration): stationary
    /// one-sigma (m; about baseline × orientation uncertainty in rad). Default 0.01.
    pub range_difference_error_std_m: f64,
    /// Its correlation time (s). Default 3600 (an orientation error is constant; its effect on
    /// the range differences changes with the direction to the vehicle).
    pub range_difference_error_correlation_s: f64,
    /// Gate on each component's squared normalised innovation (chi-square, 1 dof). Default
    /// 10.83 (99.9 %).
    pub gate_chi2: f64,
    /// Fading factor of the noise estimate (akf, aukf; memory about 1 / (1 − b) fixes). Default
    /// 0.98.
    pub fading: f64,
    /// Consecutive rejections after which the gate reopens. Default 20.
    pub reopen_after: u32,
    /// Longest slant range accepted (m). Default 5000.
    pub max_range_m: f64,
    /// Oldest fix accepted, by its time of validity against the navigation state (s). A fix
    /// is evaluated against the vehicle's position and attitude at its time of validity (kept
    /// for this long) and corrects the current state: the navigation errors change little over
    /// a few seconds. Default 3.
    pub max_latency_s: f64,
    /// Sigma-point spread α. Default 0.5.
    pub unscented_alpha: f64,
    /// Sigma-point prior-knowledge β. Default 2.
    pub unscented_beta: f64,
    /// Sigma-point secondary scaling κ. Default 0.
    pub unscented_kappa: f64,
}

impl Default for UsblConfig {
    fn default() -> Self {
        let u = UnscentedParams::default();
        UsblConfig {
            coupling: Coupling::Tight,
            filter: UsblFilter::Aukf,
            array_latitude_deg: 0.0,
            array_longitude_deg: 0.0,
            array_height_m: 0.0,
            array_yaw_deg: 0.0,
            baseline_m: 0.5,
            responder_lever_arm_m: [0.0; 3],
            range_std_m: 0.1,
            range_difference_std_m: 0.002,
            angle_std_deg: 0.2,
            range_error_std_m: 0.2,
            range_error_correlation_s: 300.0,
            range_difference_error_std_m: 0.01,
            range_difference_error_correlation_s: 3600.0,
            gate_chi2: 10.83,
            fading: 0.98,
            reopen_after: 20,
            max_range_m: 5000.0,
            max_latency_s: 3.0,
            unscented_alpha: u.alpha,
            unscented_beta: u.beta,
            unscented_kappa: u.kappa,
        }
    }
}

impl UsblConfig {
    /// The surveyed array.
    pub fn array(&self) -> UsblArray {
        UsblArray::level(
            Geodetic {
                latitude_rad: self.array_latitude_deg.to_radians(),
                longitude_rad: self.array_longitude_deg.to_radians(),
                height_m: self.array_height_m,
            },
            self.array_yaw_deg.to_radians(),
            self.baseline_m,
        )
    }

    pub fn unscented(&self) -> UnscentedParams {
        UnscentedParams {
            alpha: self.unscented_alpha,
            beta: self.unscented_beta,
            kappa: self.unscented_kappa,
        }
    }

    /// Every value that makes no sense, as `key: problem`.
    pub fn problems(&self) -> Vec<String> {
        let mut out = Vec::new();
        let mut need = |key: &str, ok: bool, what: &str| {
            if !ok {
                out.push(format!("usbl.{key}: {what}"));
            }
        };
        need(
            "array_latitude_deg",
            self.array_latitude_deg.abs() <= 90.0,
            "must be within ±90",
        );
        need(
            "array_longitude_deg",
            self.array_longitude_deg.abs() <= 180.0,
            "must be within ±180",
        );
        need(
            "array_height_m",
            (-11000.0..=1000.0).contains(&self.array_height_m),
            "must be within -11000..1000",
        );
        need(
            "baseline_m",
            self.baseline_m > 0.0 && self.baseline_m <= 10.0,
            "must be in (0, 10]",
        );
        for (key, v) in [
            ("range_std_m", self.range_std_m),
            ("range_difference_std_m", self.range_difference_std_m),
            ("angle_std_deg", self.angle_std_deg),
            ("range_error_correlation_s", self.range_error_correlation_s),
            (
                "range_difference_error_correlation_s",
                self.range_difference_error_correlation_s,
            ),
            ("gate_chi2", self.gate_chi2),
            ("max_range_m", self.max_range_m),
        ] {
            need(key, v > 0.0 && !v.is_nan(), "must be positive");
        }
        need(
            "max_latency_s",
            (0.0..=30.0).contains(&self.max_latency_s),
            "must be within 0..30",
        );
        for (key, v) in [
            ("range_error_std_m", self.range_error_std_m),
            (
                "range_difference_error_std_m",
                self.range_difference_error_std_m,
            ),
        ] {
            need(key, v >= 0.0 && v.is_finite(), "must be zero or positive");
        }
        need(
            "fading",
            self.fading > 0.0 && self.fading < 1.0,
            "must be in (0, 1)",
        );
        need(
            "unscented_alpha",
            self.unscented_alpha > 0.0 && self.unscented_alpha <= 1.0,
            "must be in (0, 1]",
        );
        out
    }
}

/// A USBL measurement ready for the filter.
#[derive(Debug, Clone, PartialEq)]
pub struct UsblMeasurement {
    /// Tight: [R, ΔR13, ΔR24] (m). Loose: the responder's position from the array in
    /// line-of-sight coordinates [along the line of sight, across it horizontally (azimuth),
    /// across it vertically (elevation)] (m), in which the fix's noise is uncorrelated.
    pub z: Vector3<f64>,
    /// Nominal noise covariance (diagonal).
    pub r: Matrix3<f64>,
    /// Loose: rotation from the array's NED frame to the line-of-sight coordinates (so the
    /// adaptive estimate and the gate work on independent components); tight: identity.
    pub frame: Matrix3<f64>,
}

/// Why a fix cannot be used.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
pub enum UsblInputError {
    #[error("no slant range")]
    NoRange,
    #[error("slant range missing, non-finite or out of range")]
    BadRange,
    #[error("neither range differences nor angles")]
    NoDirection,
    #[error("range differences or angles non-finite or out of range")]
    BadDirection,
}

/// The measurement the configured coupling uses from a device fix. Range differences are taken
/// as reported, or derived from azimuth/elevation through the baseline (far field); the loose fix
/// is the device's position, or computed from range and angles, turned into the array's NED frame
/// through the surveyed orientation.
pub fn measurement(
    cfg: &UsblConfig,
    array: &UsblArray,
    m: &auvnav_shm_schema::UsblFixV1,
) -> Result<UsblMeasurement, UsblInputError> {
    use auvnav_shm_schema::UsblFixV1 as F;
    if m.validity & F::VALID_RANGE == 0 {
        return Err(UsblInputError::NoRange);
    }
    let range = m.slant_range_m;
    if !(range.is_finite() && range > 0.0 && range <= cfg.max_range_m) {
        return Err(UsblInputError::BadRange);
    }
    let angles = m.validity & F::VALID_ANGLES != 0;
    let angles_ok = m.azimuth_rad.is_finite()
        && m.azimuth_rad.abs() <= 2.0 * std::f64::consts::PI
        && m.elevation_rad.abs() <= std::f64::consts::FRAC_PI_2;
    let sr = cfg.range_std_m;
    let sa = cfg.angle_std_deg.to_radians();
    match cfg.coupling {
        Coupling::Tight => {
            let (d, sd) = if m.validity & F::VALID_RANGE_DIFFERENCES != 0 {
                let d = m.range_difference_m;
                if !d
                    .iter()
                    .all(|x| x.is_finite() && x.abs() <= cfg.baseline_m * 1.05)
                {
                    return Err(UsblInputError::BadDirection);
                }
                (d, cfg.range_difference_std_m)
            } else if angles {
                if !angles_ok {
                    return Err(UsblInputError::BadDirection);
                }
                (
                    range_differences_from_angles(cfg.baseline_m, m.azimuth_rad, m.elevation_rad),
                    cfg.baseline_m * sa,
                )
            } else {
                return Err(UsblInputError::NoDirection);
            };
            Ok(UsblMeasurement {
                z: Vector3::new(range, d[0], d[1]),
                r: Matrix3::from_diagonal(&Vector3::new(sr * sr, sd * sd, sd * sd)),
                frame: Matrix3::identity(),
            })
        }
        Coupling::Loose => {
            if !angles || !angles_ok {
                return Err(if angles {
                    UsblInputError::BadDirection
                } else {
                    UsblInputError::NoDirection
                });
            }
            let (az, el) = (m.azimuth_rad, m.elevation_rad);
            let z = if m.validity & F::VALID_POSITION != 0
                && m.position_array_m.iter().all(|x| x.is_finite())
            {
                array.c_ned_to_array.transpose() * Vector3::from(m.position_array_m)
            } else {
                fix_position_ned(array, range, az, el)
            };
            // Line-of-sight coordinates (array frame): along it, and the directions in which
            // the azimuth and the elevation move the fix; their noise: range, R cos(el) σ_az,
            // R σ_el.
            let u = Vector3::new(el.cos() * az.cos(), el.cos() * az.sin(), -el.sin());
            let e_az = Vector3::new(-az.sin(), az.cos(), 0.0);
            let e_el = u.cross(&e_az);
            let rows = Matrix3::from_rows(&[u.transpose(), e_az.transpose(), e_el.transpose()]);
            let frame = rows * array.c_ned_to_array;
            let across_az = (range * el.cos() * sa).max(1e-3);
            let across_el = (range * sa).max(1e-3);
            Ok(UsblMeasurement {
                z: frame * z,
                r: Matrix3::from_diagonal(&Vector3::new(
                    sr * sr,
                    across_az * across_az,
                    across_el * across_el,
                )),
                frame,
            })
        }
    }
}

/// Where the responder is, given the navigation state: the responder in the array frame for the
/// nominal state, and how position and attitude errors move it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ResponderGeometry {
    /// Responder in the array frame for the nominal state (m).
    pub nominal_a: Vector3<f64>,
    /// Rotation vehicle NED → array frame.
    pub c_ned_to_array: Matrix3<f64>,
    /// Lever arm in the vehicle's NED frame (m).
    pub lever_ned: Vector3<f64>,
}

impl ResponderGeometry {
    pub fn new(
        array: &UsblArray,
        vehicle: &Geodetic,
        c_body_to_ned: &Matrix3<f64>,
        lever_arm_b: &Vector3<f64>,
    ) -> Self {
        let c_vehicle_ned_to_array_ned =
            c_ecef_to_ned(array.position.latitude_rad, array.position.longitude_rad)
                * c_ecef_to_ned(vehicle.latitude_rad, vehicle.longitude_rad).transpose();
        ResponderGeometry {
            nominal_a: array.responder_in_array(vehicle, c_body_to_ned, lever_arm_b),
            c_ned_to_array: array.c_ned_to_array * c_vehicle_ned_to_array_ned,
            lever_ned: c_body_to_ned * lever_arm_b,
        }
    }

    /// The true responder (array frame) if the navigation state is in error by `dp` (NED, m,
    /// estimate minus truth) and `phi` (attitude error, C_est = (I − [φ×]) C_true).
    pub fn responder_given_error(&self, dp: &Vector3<f64>, phi: &Vector3<f64>) -> Vector3<f64> {
        self.nominal_a + self.c_ned_to_array * (phi.cross(&self.lever_ned) - dp)
    }
}

/// Numerical Jacobian of `h` at δx = 0 (central differences of `step`), for the linearised
/// (adaptive KF) update.
pub fn jacobian(
    n: usize,
    m: usize,
    h: &dyn Fn(&DVector<f64>) -> DVector<f64>,
    step: f64,
) -> DMatrix<f64> {
    let mut jac = DMatrix::zeros(m, n);
    let mut dx = DVector::zeros(n);
    for j in 0..n {
        dx[j] = step;
        let plus = h(&dx);
        dx[j] = -step;
        let minus = h(&dx);
        dx[j] = 0.0;
        jac.set_column(j, &((plus - minus) / (2.0 * step)));
    }
    jac
}

/// The linearised Kalman update with the same interface as [`unscented_update`]: `h` is
/// linearised at δx = 0 by [`jacobian`]; Joseph form.
pub fn linearized_update(
    p: &DMatrix<f64>,
    z: &DVector<f64>,
    r: &DMatrix<f64>,
    h: &dyn Fn(&DVector<f64>) -> DVector<f64>,
) -> Option<MeasurementUpdate> {
    let n = p.nrows();
    let m = z.len();
    let hj = jacobian(n, m, h, 1e-3);
    let s = &hj * p * hj.transpose() + r;
    let s_inv = s.clone().try_inverse()?;
    // The innovation is z − h(0); h(δx) ≈ h(0) + H δx, so the gain maps it with the sign of H.
    let k = p * hj.transpose() * &s_inv;
    let innovation = z - h(&DVector::zeros(n));
    let dx = &k * &innovation;
    let ikh = DMatrix::identity(n, n) - &k * &hj;
    let mut p_new = &ikh * p * ikh.transpose() + &k * r * k.transpose();
    p_new = (&p_new + p_new.transpose()) * 0.5;
    Some(MeasurementUpdate {
        dx,
        p: p_new,
        innovation,
        innovation_cov: s,
    })
}
