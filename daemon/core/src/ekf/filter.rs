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
//! then the acoustic measurement errors (5 slots: the USBL's slant range and two range differences,
//! or the range aid's range biases and sound-speed scale), first-order Gauss–Markov processes
//! `b' = -b / tau + w` (S-USBL), then the horizontal water current (north,
//! east: 2), Gauss–Markov too, seen only through DVL water-track velocities. Parameter states appear only in measurement
//! models, never in `F`, so the covariance propagation handles them as a block with diagonal
//! transition `A = diag(a_i)`, `a_i = exp(-dt / tau_i)` (1 for constants):
//! `P_cc <- Phi P_cc Phi^T + Q`, `P_cp <- Phi P_cp A`, `P_pp <- A P_pp A + diag(s_i^2 (1 - a_i^2))`
//! with `s_i` the stationary standard deviation. A parameter state that is switched off has zero
//! variance and zero correlation, so no update can move it; switching one on costs nothing in the
//! propagation beyond the 15 x 15 cross block.

use nalgebra::{SMatrix, SVector, Vector3};

/// Number of error states.
pub const N: usize = 30;
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
/// Acoustic measurement errors, estimate minus truth: the USBL's slant range and range
/// differences 1-3 and 2-4 (m) in the first three, or the range aid's biases and scale
/// (`crate::aid::ranges`) in as many as it is configured with.
pub const USBL: usize = 23;
/// Number of acoustic error slots.
pub const ACOUSTIC_SLOTS: usize = 5;
/// Water-current error, north and east (m/s, estimate minus truth).
pub const CURRENT: usize = USBL + ACOUSTIC_SLOTS;
/// Number of parameter states.
pub const PARAMS: usize = N - CORE;
const _: () = assert!(BA + 3 == CORE, "core layout must fill CORE");
const _: () = assert!(CURRENT + 2 == N, "state layout must fill N");

pub type StateVector = SVector<f64, N>;
pub type Covariance = SMatrix<f64, N, N>;

/// Re-opens a block of three states after an aid was refused for too long: drops their
/// cross-covariances and adds `extra_variances` to their variances, so that the aid's next
/// measurement is believed again (the DVL re-opens the velocity, the USBL the position).
pub fn reopen_block(p: &mut Covariance, first: usize, extra_variances: [f64; 3]) {
    for (i, extra) in extra_variances.into_iter().enumerate() {
        let k = first + i;
        let keep = p[(k, k)] + extra;
        for j in 0..N {
            p[(k, j)] = 0.0;
            p[(j, k)] = 0.0;
        }
        p[(k, k)] = keep;
    }
}
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

/// One column of a product: `sum_k a[k] b(k)` for the `K` columns `a[k]` of a matrix, summed
/// in ascending `k` from `a[0] b(0)`, the order of nalgebra's matrix product (so the same bits),
/// with the column kept in registers rather than stored back after each `k`.
#[inline(always)]
fn column_product<const R: usize, const K: usize>(
    a: &[[f64; R]; K],
    b: impl Fn(usize) -> f64,
) -> [f64; R] {
    let b0 = b(0);
    let mut acc: [f64; R] = a[0].map(|x| x * b0);
    for (k, col) in a.iter().enumerate().skip(1) {
        let bk = b(k);
        for (acc, x) in acc.iter_mut().zip(col) {
            *acc += x * bk;
        }
    }
    acc
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

    /// The transition factor `exp(-dt / tau)` of each parameter state over `dt` (1 for the
    /// constants).
    pub fn param_transition(&self, dt: f64) -> SVector<f64, PARAMS> {
        self.param_correlation_s.map(|tau| {
            if tau.is_finite() {
                (-dt / tau).exp()
            } else {
                1.0
            }
        })
    }

    /// Propagates the covariance over `dt` with `F` held constant: `Phi = I + F dt + (F dt)^2/2`,
    /// `Q` from the noise densities mapped through the body-to-NED rotation.
    ///
    /// The bias rows of `F` are zero, so `Phi = [[A, B], [0, I]]` with `A` the 9 x 9 navigation
    /// block and `B` its 9 x 6 coupling to the biases. The product is formed in these blocks
    /// (`T = Phi P` for the navigation rows only, then `T Phi^T`), about half the work of the dense
    /// 15 x 15 products; the result is the same matrix.
    ///
    /// On x86-64 processors with AVX2 the same code runs compiled for AVX2 (chosen at run time):
    /// four-wide instead of two-wide arithmetic, the same operations in the same order, so the
    /// same bits (no fused multiply-add: Rust never contracts a product and a sum into one).
    pub fn predict(
        &mut self,
        f: &CoreMatrix,
        c_body_to_ned: &nalgebra::Matrix3<f64>,
        q: &ProcessNoise,
        dt: f64,
    ) {
        #[cfg(target_arch = "x86_64")]
        if std::arch::is_x86_feature_detected!("avx2") {
            // The one unsafe block of the navigation core.
            #[allow(unsafe_code)]
            // SAFETY: the processor has AVX2 (checked just above).
            unsafe {
                self.predict_avx2(f, c_body_to_ned, q, dt)
            };
            return;
        }
        self.predict_portable(f, c_body_to_ned, q, dt);
    }

    /// [`ErrorFilter::predict`] compiled for AVX2.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    fn predict_avx2(
        &mut self,
        f: &CoreMatrix,
        c_body_to_ned: &nalgebra::Matrix3<f64>,
        q: &ProcessNoise,
        dt: f64,
    ) {
        self.predict_portable(f, c_body_to_ned, q, dt);
    }

    /// [`ErrorFilter::predict`] for any processor (inlined into the AVX2 version).
    #[inline(always)]
    fn predict_portable(
        &mut self,
        f: &CoreMatrix,
        c_body_to_ned: &nalgebra::Matrix3<f64>,
        q: &ProcessNoise,
        dt: f64,
    ) {
        const NAV: usize = 9;
        const _: () = assert!(BG == NAV, "the biases follow the navigation states");
        // Only the navigation rows of Phi differ from the identity; as the bias rows of F are
        // zero, the navigation rows of (F dt)^2 are (F dt)_nn (F dt)_nav.
        let fdt_nav: SMatrix<f64, NAV, CORE> = f.fixed_view::<NAV, CORE>(0, 0) * dt;
        let half_fdt_nn: SMatrix<f64, NAV, NAV> = 0.5 * fdt_nav.fixed_view::<NAV, NAV>(0, 0);
        let half_fdt_nn = &half_fdt_nn.data.0;
        let mut phi: [[f64; NAV]; CORE] = fdt_nav.data.0;
        for (j, phi_col) in phi.iter_mut().enumerate() {
            let sq = column_product(half_fdt_nn, |k| fdt_nav.data.0[j][k]);
            for (x, s) in phi_col.iter_mut().zip(sq) {
                *x += s;
            }
        }
        for (i, col) in phi.iter_mut().enumerate().take(NAV) {
            col[i] += 1.0;
        }
        // T = (Phi P) for the navigation rows, every column (core and parameter states); the
        // bias rows of Phi P are those of P. A parameter state switched off (or never correlated
        // with the core) has a zero column in P_cp, and so in T: not multiplied. Columns of the
        // arrays are columns of the matrices (nalgebra's storage is column-major).
        let p = &self.p.data.0;
        let mut t = [[0.0; NAV]; N];
        for (j, t_col) in t.iter_mut().enumerate() {
            let p_col = &p[j];
            if j < CORE || p_col[..CORE].iter().any(|v| *v != 0.0) {
                *t_col = column_product(&phi, |k| p_col[k]);
            }
        }
        // Phi P Phi^T, navigation block: T_core Phi_nav^T, plus the noise; the only block not
        // symmetric by construction (the covariance was symmetric before).
        let t_core: &[[f64; NAV]; CORE] = t[..CORE].try_into().expect("CORE columns");
        let mut p_nn = [[0.0; NAV]; NAV];
        for (j, col) in p_nn.iter_mut().enumerate() {
            *col = column_product(t_core, |k| phi[k][j]);
        }
        let c = c_body_to_ned;
        let cct = c * c.transpose();
        let qv = cct * (q.accel_noise * q.accel_noise * dt);
        let qa = cct * (q.gyro_noise * q.gyro_noise * dt);
        for i in 0..3 {
            for j in 0..3 {
                p_nn[VEL + j][VEL + i] += qv[(i, j)];
                p_nn[ATT + j][ATT + i] += qa[(i, j)];
            }
        }
        let a_par = self.param_transition(dt);
        let p = &mut self.p.data.0;
        for j in 0..NAV {
            for i in 0..NAV {
                p[j][i] = 0.5 * (p_nn[j][i] + p_nn[i][j]);
            }
        }
        // Navigation x bias and navigation x parameter: T's columns (bias and parameter rows
        // of Phi are those of the identity); bias x bias and parameter blocks unchanged.
        for (j, t_col) in t.iter().enumerate().skip(NAV) {
            for (i, v) in t_col.iter().enumerate() {
                p[j][i] = *v;
                p[i][j] = *v;
            }
        }
        let p = &mut self.p;
        for i in 0..3 {
            p[(BG + i, BG + i)] += q.gyro_bias_walk * q.gyro_bias_walk * dt;
            p[(BA + i, BA + i)] += q.accel_bias_walk * q.accel_bias_walk * dt;
        }
        // Gauss-Markov parameter states: P_cp A, A P_pp A + their driving noise.
        for j in 0..PARAMS {
            if a_par[j] < 1.0 {
                let col = CORE + j;
                for i in 0..N {
                    if i != col {
                        p[(i, col)] *= a_par[j];
                        p[(col, i)] *= a_par[j];
                    }
                }
                p[(col, col)] = p[(col, col)] * a_par[j] * a_par[j]
                    + self.param_stationary_std[j].powi(2) * (1.0 - a_par[j] * a_par[j]);
            }
        }
    }

    /// Makes the covariance exactly symmetric (in place).
    fn symmetrise(&mut self) {
        let p = &mut self.p;
        for j in 0..N {
            for i in (j + 1)..N {
                let v = 0.5 * (p[(i, j)] + p[(j, i)]);
                p[(i, j)] = v;
                p[(j, i)] = v;
            }
        }
    }

    /// Linear update for `y = h(x_est) - z = H dx + noise` with noise covariance `r`, gated at
    /// `gate` (chi-square value of the NIS). Returns the error-state estimate to apply (zero when
    /// rejected) and the report. Joseph form `(I - K H) P (I - K H)^T + K R K^T`, evaluated
    /// expanded as `P - K U^T - U K^T + K S K^T` with `U = P H^T`, `S = H U + R`: the same matrix
    /// for any gain, in O(N^2 M) rather than O(N^3).
    pub fn update<const M: usize>(
        &mut self,
        y: &SVector<f64, M>,
        h: &SMatrix<f64, M, N>,
        r: &SMatrix<f64, M, M>,
        gate: f64,
    ) -> Result<(StateVector, UpdateReport<M>), FilterError> {
        let u = self.p * h.transpose();
        let s = h * u + r;
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
        let k = u * s_inv;
        let dx = k * y;
        let ku = k * u.transpose();
        self.p += k * (s * k.transpose()) - ku - ku.transpose();
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

    /// A symmetric positive definite covariance with correlations everywhere.
    fn dense_covariance() -> Covariance {
        let mut x = 0.37_f64;
        let m = Covariance::from_fn(|_, _| {
            x = (x * 3.7 + 0.13).fract();
            x - 0.5
        });
        m * m.transpose() + Covariance::identity() * 0.1
    }

    fn max_relative_difference(a: &Covariance, b: &Covariance) -> f64 {
        (a - b).abs().max() / b.abs().max()
    }

    fn propagation_inputs() -> (DynamicsInputs, ProcessNoise) {
        let inputs = DynamicsInputs {
            c_body_to_ned: *nalgebra::Rotation3::from_euler_angles(0.1, -0.2, 2.0).matrix(),
            specific_force_ned: Vector3::new(0.3, -0.2, -9.81),
            velocity_ned: Vector3::new(2.0, 0.5, 0.1),
            latitude_rad: 0.6,
            height_m: -40.0,
        };
        let q = ProcessNoise {
            gyro_noise: 1e-5,
            accel_noise: 1e-4,
            gyro_bias_walk: 1e-8,
            accel_bias_walk: 1e-7,
        };
        (inputs, q)
    }

    /// A dense covariance with the DVL lever-arm states switched off (zero rows and columns).
    fn covariance_with_states_off() -> Covariance {
        let mut p = dense_covariance();
        for i in DVL_LEVER..DVL_LEVER + 3 {
            p.row_mut(i).fill(0.0);
            p.column_mut(i).fill(0.0);
        }
        p
    }

    #[test]
    fn states_switched_off_stay_off_and_the_rest_matches_the_dense_product() {
        let (inputs, q) = propagation_inputs();
        let f = dynamics_matrix(&inputs);
        let dt = 0.05;
        let mut filter = ErrorFilter::new(&StateVector::from_element(1.0));
        filter.p = covariance_with_states_off();
        let before = filter.p;
        filter.predict(&f, &inputs.c_body_to_ned, &q, dt);
        for i in DVL_LEVER..DVL_LEVER + 3 {
            assert!(filter.p.row(i).iter().all(|v| *v == 0.0));
            assert!(filter.p.column(i).iter().all(|v| *v == 0.0));
        }
        let fdt = f * dt;
        let phi = CoreMatrix::identity() + fdt + 0.5 * fdt * fdt;
        let mut big_phi = Covariance::identity();
        big_phi.fixed_view_mut::<CORE, CORE>(0, 0).copy_from(&phi);
        let reference = big_phi * before * big_phi.transpose();
        // Q only touches the core diagonal blocks: compare the core x parameter block.
        let d = (filter.p.fixed_view::<CORE, PARAMS>(0, CORE)
            - reference.fixed_view::<CORE, PARAMS>(0, CORE))
        .abs()
        .max()
            / reference.abs().max();
        assert!(d < 1e-13, "relative difference {d:e}");
    }

    #[test]
    fn the_avx2_propagation_gives_the_same_bits_as_the_portable_one() {
        #[cfg(target_arch = "x86_64")]
        if std::arch::is_x86_feature_detected!("avx2") {
            let (inputs, q) = propagation_inputs();
            let f = dynamics_matrix(&inputs);
            for p in [dense_covariance(), covariance_with_states_off()] {
                let mut a = ErrorFilter::new(&StateVector::from_element(1.0));
                a.p = p;
                a.set_gauss_markov(USBL, 60.0, 0.5);
                let mut b = a.clone();
                for _ in 0..100 {
                    a.predict_portable(&f, &inputs.c_body_to_ned, &q, 0.05);
                    #[allow(unsafe_code)]
                    // SAFETY: the processor has AVX2 (checked above).
                    unsafe {
                        b.predict_avx2(&f, &inputs.c_body_to_ned, &q, 0.05)
                    };
                }
                let bits = |m: &Covariance| m.iter().map(|v| v.to_bits()).collect::<Vec<_>>();
                assert_eq!(bits(&a.p), bits(&b.p));
            }
            return;
        }
        eprintln!("no AVX2 on this processor: only the portable propagation exists here");
    }

    #[test]
    fn block_propagation_equals_the_dense_product() {
        let inputs = DynamicsInputs {
            c_body_to_ned: *nalgebra::Rotation3::from_euler_angles(0.1, -0.2, 2.0).matrix(),
            specific_force_ned: Vector3::new(0.3, -0.2, -9.81),
            velocity_ned: Vector3::new(2.0, 0.5, 0.1),
            latitude_rad: 0.6,
            height_m: -40.0,
        };
        let f = dynamics_matrix(&inputs);
        let q = ProcessNoise {
            gyro_noise: 1e-5,
            accel_noise: 1e-4,
            gyro_bias_walk: 1e-8,
            accel_bias_walk: 1e-7,
        };
        let dt = 0.05;
        let mut filter = ErrorFilter::new(&StateVector::from_element(1.0));
        filter.p = dense_covariance();
        filter.set_gauss_markov(USBL, 60.0, 0.5);
        filter.set_gauss_markov(USBL + 1, 30.0, 0.2);
        let before = filter.p;
        filter.predict(&f, &inputs.c_body_to_ned, &q, dt);
        // The dense reference: P_cc <- Phi P_cc Phi^T + Q, P_cp <- Phi P_cp A, P_pp <- A P_pp A + Q_p.
        let fdt = f * dt;
        let phi = CoreMatrix::identity() + fdt + 0.5 * fdt * fdt;
        let mut big_phi = Covariance::identity();
        big_phi.fixed_view_mut::<CORE, CORE>(0, 0).copy_from(&phi);
        let a = filter.param_transition(dt);
        for j in 0..PARAMS {
            big_phi[(CORE + j, CORE + j)] = a[j];
        }
        let mut qd = Covariance::zeros();
        let c = inputs.c_body_to_ned;
        qd.fixed_view_mut::<3, 3>(VEL, VEL)
            .copy_from(&(c * c.transpose() * (q.accel_noise * q.accel_noise * dt)));
        qd.fixed_view_mut::<3, 3>(ATT, ATT)
            .copy_from(&(c * c.transpose() * (q.gyro_noise * q.gyro_noise * dt)));
        for i in 0..3 {
            qd[(BG + i, BG + i)] = q.gyro_bias_walk * q.gyro_bias_walk * dt;
            qd[(BA + i, BA + i)] = q.accel_bias_walk * q.accel_bias_walk * dt;
        }
        for j in 0..PARAMS {
            qd[(CORE + j, CORE + j)] = filter.param_stationary_std[j].powi(2) * (1.0 - a[j] * a[j]);
        }
        let reference = big_phi * before * big_phi.transpose() + qd;
        let d = max_relative_difference(&filter.p, &reference);
        assert!(d < 1e-13, "relative difference {d:e}");
    }

    #[test]
    fn expanded_joseph_update_equals_the_product_form() {
        let mut filter = ErrorFilter::new(&StateVector::from_element(1.0));
        filter.p = dense_covariance();
        let before = filter.p;
        let mut h = SMatrix::<f64, 3, N>::zeros();
        for i in 0..3 {
            h[(i, VEL + i)] = 1.0;
            h[(i, DVL_SCALE)] = 0.3 * (i as f64 + 1.0);
            h[(i, ATT + (i + 1) % 3)] = -0.5;
        }
        let r = SMatrix::<f64, 3, 3>::from_diagonal(&Vector3::new(0.01, 0.02, 0.03));
        let y = Vector3::new(0.1, -0.05, 0.02);
        let (dx, rep) = filter.update(&y, &h, &r, 1e9).expect("update");
        assert!(rep.fused);
        let s = h * before * h.transpose() + r;
        let k = before * h.transpose() * s.try_inverse().expect("S invertible");
        let ikh = Covariance::identity() - k * h;
        let reference = ikh * before * ikh.transpose() + k * r * k.transpose();
        let d = max_relative_difference(&filter.p, &reference);
        assert!(d < 1e-12, "relative difference {d:e}");
        assert!((dx - k * y).abs().max() < 1e-12);
    }
}
