//! Error-state extended Kalman filter around the strapdown solution.
//!
//! Error definitions (estimate minus truth unless stated):
//! - `dp`: position error, NED metres;
//! - `dv`: velocity error, NED (m/s);
//! - `phi`: attitude error (psi-angle), `C_b^n(est) = (I - [phi x]) C_b^n(true)` (rad);
//! - `dbg`, `dba`: residual gyro / accelerometer bias, true minus estimated (rad/s, m/s^2), so the
//!   corrected IMU output is in error by `+dbg`, `+dba`.
//!
//! Continuous error dynamics (Titterton & Weston psi-angle form, NED):
//! `dp' = dv`;
//! `dv' = f^n x phi + C dba - (2 w_ie + w_en) x dv + (0, 0, 2 g / R dp_D)`;
//! `phi' = -(w_ie + w_en) x phi + dw_en(dv) - C dbg`, with `dw_en = (dv_E/R_N, -dv_N/R_M, -dv_E tan L / R_N)`;
//! biases: random walks driven by the bias-instability noise.
//!
//! Parameter states follow the 15 core states: DVL mounting (small rotation, 3), DVL scale factor
//! (1), DVL lever arm (3) and DVL time offset (1), all "estimate minus truth" and constant in time,
//! then the USBL measurement errors (slant range, two range differences: 3), first-order Gauss–
//! Markov processes `b' = -b / tau + w` (S-USBL). Parameter states appear only in measurement
//! models, never in `F`, so the covariance propagation handles them as a block with diagonal
//! transition `A = diag(a_i)`, `a_i = exp(-dt / tau_i)` (1 for constants):
//! `P_cc <- Phi P_cc Phi^T + Q`, `P_cp <- Phi P_cp A`, `P_pp <- A P_pp A + diag(s_i^2 (1 - a_i^2))`
//! with `s_i` the stationary standard deviation. A parameter state that is switched off has zero
//! variance and zero correlation, so no update can move it; switching one on costs nothing in the
//! propagation beyond the 15 x 11 cross block.

use nalgebra::{SMatrix, SVector, Vector3};

/// Number of error states.
pub const N: usize = 26;
/// Number of core states (navigation errors and IMU biases) that have dynamics.
pub const CORE: usize = 15;
/// Index of the first component of each block.
pub const POS: usize = 0;
pub const VEL: usize = 3;
pub const ATT: usize = 6;
pub const BG: usize = 9;
pub const BA: usize = 12;
/// DVL mounting error: `C_dvl->body(est) = C_dvl->body(true) (I + [dm x])` (rad).
pub const DVL_MOUNT: usize = 15;
/// DVL scale-factor error (estimate minus truth, 1).
pub const DVL_SCALE: usize = 18;
/// DVL lever-arm error (body frame, m).
pub const DVL_LEVER: usize = 19;
/// DVL time-offset error (s).
pub const DVL_TIME: usize = 22;
/// USBL measurement errors: slant range, range differences 1-3 and 2-4 (m), estimate minus truth.
pub const USBL: usize = 23;
/// Number of parameter states.
pub const PARAMS: usize = N - CORE;
const _: () = assert!(BA + 3 == CORE, "core layout must fill CORE");
const _: () = assert!(USBL + 3 == N, "state layout must fill N");

pub type StateVector = SVector<f64, N>;
pub type Covariance = SMatrix<f64, N, N>;
/// The dynamics of the core states.
pub type CoreMatrix = SMatrix<f64, CORE, CORE>;

#[derive(Debug, thiserror::Error, PartialEq)]
pub enum FilterError {
    #[error("innovation covariance is not positive definite")]
    SingularInnovation,
    #[error("state covariance lost positive definiteness (diagonal {index} = {value})")]
    NotPositiveDefinite { index: usize, value: f64 },
}

/// The result of one measurement update.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct UpdateReport<const M: usize> {
    pub innovation: SVector<f64, M>,
    pub innovation_variance: SVector<f64, M>,
    /// Normalised innovation squared divided by the gate (above 1: rejected; see `ekf::gate`).
    pub test_ratio: f64,
    pub fused: bool,
}

/// Error covariance (the error state itself is reset to zero after each correction).
#[derive(Debug, Clone, PartialEq)]
pub struct ErrorFilter {
    pub p: Covariance,
    /// Correlation time of each parameter state (s; infinite: constant).
    pub param_correlation_s: SVector<f64, PARAMS>,
    /// Stationary standard deviation of each Gauss–Markov parameter state.
    pub param_stationary_std: SVector<f64, PARAMS>,
}

/// The cross-product matrix: `skew(a) * b = a x b`.
pub fn skew(v: &Vector3<f64>) -> nalgebra::Matrix3<f64> {
    nalgebra::Matrix3::new(0.0, -v.z, v.y, v.z, 0.0, -v.x, -v.y, v.x, 0.0)
}

/// Everything the error dynamics depend on, averaged over the propagation interval.
#[derive(Debug, Clone, Copy)]
pub struct DynamicsInputs {
    pub c_body_to_ned: nalgebra::Matrix3<f64>,
    pub specific_force_ned: Vector3<f64>,
    pub velocity_ned: Vector3<f64>,
    pub latitude_rad: f64,
    pub height_m: f64,
}

/// Continuous-time error dynamics matrix F of the core states (parameter states are constant).
pub fn dynamics_matrix(d: &DynamicsInputs) -> CoreMatrix {
    let lat = d.latitude_rad;
    let rm = crate::earth::meridian_radius(lat) + d.height_m;
    let rn = crate::earth::prime_vertical_radius(lat) + d.height_m;
    let w_ie = crate::earth::earth_rate_ned(lat);
    let w_en = crate::earth::transport_rate_ned(lat, d.height_m, &d.velocity_ned);
    let g = crate::earth::normal_gravity(lat, d.height_m);
    let c = d.c_body_to_ned;
    let mut f = CoreMatrix::zeros();
    f.fixed_view_mut::<3, 3>(POS, VEL)
        .copy_from(&nalgebra::Matrix3::identity());
    f.fixed_view_mut::<3, 3>(VEL, ATT)
        .copy_from(&skew(&d.specific_force_ned));
    f.fixed_view_mut::<3, 3>(VEL, BA).copy_from(&c);
    f.fixed_view_mut::<3, 3>(VEL, VEL)
        .copy_from(&(-skew(&(2.0 * w_ie + w_en))));
    f[(VEL + 2, POS + 2)] = 2.0 * g / ((rm * rn).sqrt());
    f.fixed_view_mut::<3, 3>(ATT, ATT)
        .copy_from(&(-skew(&(w_ie + w_en))));
    f[(ATT, VEL + 1)] = 1.0 / rn;
    f[(ATT + 1, VEL)] = -1.0 / rm;
    f[(ATT + 2, VEL + 1)] = -lat.tan() / rn;
    f.fixed_view_mut::<3, 3>(ATT, BG).copy_from(&(-c));
    f
}

/// Process noise densities.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ProcessNoise {
    /// Gyro white noise density (rad/s/sqrt(Hz)) = angle random walk.
    pub gyro_noise: f64,
    /// Accelerometer white noise density (m/s^2/sqrt(Hz)) = velocity random walk.
    pub accel_noise: f64,
    /// Gyro bias random-walk density (rad/s^2/sqrt(Hz)).
    pub gyro_bias_walk: f64,
    /// Accelerometer bias random-walk density (m/s^3/sqrt(Hz)).
    pub accel_bias_walk: f64,
}

impl ErrorFilter {
    pub fn new(p0_diagonal: &StateVector) -> Self {
        ErrorFilter {
            p: Covariance::from_diagonal(p0_diagonal),
            param_correlation_s: SVector::repeat(f64::INFINITY),
            param_stationary_std: SVector::zeros(),
        }
    }

    /// Makes state `index` (a parameter state) a first-order Gauss–Markov process with correlation
    /// time `tau_s` and stationary standard deviation `std`, starting from its stationary variance.
    pub fn set_gauss_markov(&mut self, index: usize, tau_s: f64, std: f64) {
        assert!(
            (CORE..N).contains(&index),
            "only parameter states can be Gauss-Markov"
        );
        self.param_correlation_s[index - CORE] = tau_s;
        self.param_stationary_std[index - CORE] = std;
        self.p[(index, index)] = std * std;
    }

    /// The transition factor `exp(-dt / tau)` of each parameter state over `dt`.
    pub fn param_transition(&self, dt: f64) -> SVector<f64, PARAMS> {
        self.param_correlation_s.map(|tau| (-dt / tau).exp())
    }

    /// Propagates the covariance over `dt` with `F` held constant: `Phi = I + F dt + (F dt)^2/2`,
    /// `Q` from the noise densities mapped through the body-to-NED rotation.
    pub fn predict(
        &mut self,
        f: &CoreMatrix,
        c_body_to_ned: &nalgebra::Matrix3<f64>,
        q: &ProcessNoise,
        dt: f64,
    ) {
        let fdt = f * dt;
        let phi = CoreMatrix::identity() + fdt + 0.5 * fdt * fdt;
        let mut qd = CoreMatrix::zeros();
        let c = c_body_to_ned;
        let qv = c * c.transpose() * (q.accel_noise * q.accel_noise * dt);
        let qa = c * c.transpose() * (q.gyro_noise * q.gyro_noise * dt);
        qd.fixed_view_mut::<3, 3>(VEL, VEL).copy_from(&qv);
        qd.fixed_view_mut::<3, 3>(ATT, ATT).copy_from(&qa);
        for i in 0..3 {
            qd[(BG + i, BG + i)] = q.gyro_bias_walk * q.gyro_bias_walk * dt;
            qd[(BA + i, BA + i)] = q.accel_bias_walk * q.accel_bias_walk * dt;
        }
        let p_cc: CoreMatrix = self.p.fixed_view::<CORE, CORE>(0, 0).into_owned();
        let p_cp: SMatrix<f64, CORE, PARAMS> =
            self.p.fixed_view::<CORE, PARAMS>(0, CORE).into_owned();
        let p_cc = phi * p_cc * phi.transpose() + qd;
        let a = self.param_transition(dt);
        let mut p_cp = phi * p_cp;
        let mut p_pp: SMatrix<f64, PARAMS, PARAMS> =
            self.p.fixed_view::<PARAMS, PARAMS>(CORE, CORE).into_owned();
        for j in 0..PARAMS {
            if a[j] < 1.0 {
                p_cp.column_mut(j).scale_mut(a[j]);
                for i in 0..PARAMS {
                    p_pp[(i, j)] *= a[j];
                    p_pp[(j, i)] *= a[j];
                }
                p_pp[(j, j)] += self.param_stationary_std[j].powi(2) * (1.0 - a[j] * a[j]);
            }
        }
        self.p.fixed_view_mut::<CORE, CORE>(0, 0).copy_from(&p_cc);
        self.p
            .fixed_view_mut::<CORE, PARAMS>(0, CORE)
            .copy_from(&p_cp);
        self.p
            .fixed_view_mut::<PARAMS, CORE>(CORE, 0)
            .copy_from(&p_cp.transpose());
        self.p
            .fixed_view_mut::<PARAMS, PARAMS>(CORE, CORE)
            .copy_from(&p_pp);
        self.symmetrise();
    }

    fn symmetrise(&mut self) {
        self.p = 0.5 * (self.p + self.p.transpose());
    }

    /// Linear update for `y = h(x_est) - z = H dx + noise` with noise covariance `r`, gated at
    /// `gate` (chi-square value of the NIS). Returns the error-state estimate to apply (zero when
    /// rejected) and the report. Joseph form.
    pub fn update<const M: usize>(
        &mut self,
        y: &SVector<f64, M>,
        h: &SMatrix<f64, M, N>,
        r: &SMatrix<f64, M, M>,
        gate: f64,
    ) -> Result<(StateVector, UpdateReport<M>), FilterError> {
        let s = h * self.p * h.transpose() + r;
        let s_inv = s.try_inverse().ok_or(FilterError::SingularInnovation)?;
        let nis = (y.transpose() * s_inv * y)[(0, 0)];
        let outcome = super::gate::nis(nis, gate);
        let report = UpdateReport {
            innovation: *y,
            innovation_variance: s.diagonal(),
            test_ratio: outcome.test_ratio,
            fused: outcome.passed,
        };
        if !report.fused {
            return Ok((StateVector::zeros(), report));
        }
        let k = self.p * h.transpose() * s_inv;
        let dx = k * y;
        let ikh = Covariance::identity() - k * h;
        self.p = ikh * self.p * ikh.transpose() + k * r * k.transpose();
        self.symmetrise();
        for i in 0..N {
            let v = self.p[(i, i)];
            if !(v.is_finite() && v >= 0.0) {
                return Err(FilterError::NotPositiveDefinite { index: i, value: v });
            }
        }
        Ok((dx, report))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn update_reduces_variance_and_rejects_outliers() {
        let mut f = ErrorFilter::new(&StateVector::from_element(1.0));
        let mut h = SMatrix::<f64, 1, N>::zeros();
        h[(0, POS + 2)] = 1.0;
        let r = SMatrix::<f64, 1, 1>::new(1.0);
        let (dx, rep) = f
            .update(&SVector::<f64, 1>::new(1.0), &h, &r, 10.83)
            .expect("update");
        assert!(rep.fused);
        assert!((dx[POS + 2] - 0.5).abs() < 1e-12);
        assert!((f.p[(POS + 2, POS + 2)] - 0.5).abs() < 1e-12);
        let (dx, rep) = f
            .update(&SVector::<f64, 1>::new(100.0), &h, &r, 10.83)
            .expect("update");
        assert!(!rep.fused && dx == StateVector::zeros());
    }
}
