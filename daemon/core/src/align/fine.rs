//! Fine alignment by a Kalman filter with three selectable error models (S-ALIGN), for the
//! `auvnav align` comparison. The strapdown mechanisation is shared; the models differ in the
//! error state, its dynamics and the DVL measurement:
//!
//! * **Model 1 — body-frame velocity error** (18 states: φ, δv^b, δp, ε, ∇, ψ_m). The SINS
//!   velocity is compared with the DVL in body axes, so the measurement is linear in the state
//!   whatever the attitude error: z = ṽ^b − C_d^b(ψ̂_m) ṽ_d = δv^b + [v^b×] δψ_m. The dynamics carry
//!   the coupling instead (docs/alignment.md derives them):
//!   δv̇^b = −[(ω_ib^b + C_n^b ω_ie^n)×] δv^b − C_n^b [g^n×] φ − [v^b×] C_n^b [ω_ie^n×] φ + [v^b×] ε + ∇.
//! * **Model 2 — navigation-frame velocity error with mounting states** (18 states: φ, δv^n, δp,
//!   ε, ∇, ψ_m): z = ṽ^n − C̃_b^n C_d^b(ψ̂_m) ṽ_d = δv^n − [v^n×] φ + C_b^n [v^b×] δψ_m.
//! * **Model 3 — navigation-frame, no mounting states** (15 states): z = δv^n − [v^n×] φ.
//!
//! φ is the attitude error with C̃_b^n = (I − [φ×]) C_b^n; δ(·) = estimate − true (δψ_m too).
//! Errors are fed back after every update (closed loop).

use crate::earth::{earth_rate_ned, gravity_ned, offset_position, transport_rate_ned};
use crate::strapdown::{ImuIncrement, NavState, Strapdown};
use nalgebra::{DMatrix, DVector, Matrix3, Rotation3, UnitQuaternion, Vector3};

/// Which error model the filter uses.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ErrorModel {
    /// Model 1: body-frame velocity error with mounting-angle states (18).
    BodyVelocity,
    /// Model 2: navigation-frame velocity error with mounting-angle states (18).
    NavigationWithMounting,
    /// Model 3: navigation-frame velocity error (15).
    Navigation,
}

impl ErrorModel {
    pub fn number(self) -> u8 {
        match self {
            ErrorModel::BodyVelocity => 1,
            ErrorModel::NavigationWithMounting => 2,
            ErrorModel::Navigation => 3,
        }
    }
    pub fn from_number(n: u8) -> Option<ErrorModel> {
        match n {
            1 => Some(ErrorModel::BodyVelocity),
            2 => Some(ErrorModel::NavigationWithMounting),
            3 => Some(ErrorModel::Navigation),
            _ => None,
        }
    }
    fn states(self) -> usize {
        if self == ErrorModel::Navigation {
            15
        } else {
            18
        }
    }
}

const PHI: usize = 0;
const DV: usize = 3;
const DP: usize = 6;
const EPS: usize = 9;
const NAB: usize = 12;
const PSI: usize = 15;

/// Noise and initial uncertainty of the alignment filter (the seed's settings by default).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FineAlignConfig {
    /// Gyro angle random walk (deg/√h).
    pub gyro_arw_deg_sqrt_h: f64,
    /// Accelerometer velocity random walk (m/s/√h).
    pub accel_vrw_m_s_sqrt_h: f64,
    /// DVL velocity noise per axis (m/s).
    pub dvl_std_m_s: f64,
    pub initial_tilt_std_deg: f64,
    pub initial_heading_std_deg: f64,
    pub initial_velocity_std_m_s: f64,
    pub initial_position_std_m: f64,
    pub initial_gyro_bias_std_deg_h: f64,
    pub initial_accel_bias_std_ug: f64,
    pub initial_mounting_std_deg: f64,
    /// Covariance propagation interval (s).
    pub covariance_interval_s: f64,
}

impl Default for FineAlignConfig {
    fn default() -> Self {
        FineAlignConfig {
            gyro_arw_deg_sqrt_h: 0.002,
            accel_vrw_m_s_sqrt_h: 0.0005,
            dvl_std_m_s: 0.1,
            initial_tilt_std_deg: 0.1,
            initial_heading_std_deg: 10.0,
            initial_velocity_std_m_s: 0.1,
            initial_position_std_m: 10.0,
            initial_gyro_bias_std_deg_h: 0.01,
            initial_accel_bias_std_ug: 100.0,
            initial_mounting_std_deg: 1.0,
            covariance_interval_s: 0.1,
        }
    }
}

fn skew(v: &Vector3<f64>) -> Matrix3<f64> {
    v.cross_matrix()
}

/// The alignment filter.
pub struct FineAligner {
    pub model: ErrorModel,
    cfg: FineAlignConfig,
    sd: Strapdown,
    p: DMatrix<f64>,
    gyro_bias: Vector3<f64>,
    accel_bias: Vector3<f64>,
    mount: Vector3<f64>,
    pending_dt: f64,
    mean_w: Vector3<f64>,
    mean_f: Vector3<f64>,
    last_w: Vector3<f64>,
}

impl FineAligner {
    pub fn new(model: ErrorModel, cfg: FineAlignConfig, initial: NavState) -> Self {
        let n = model.states();
        let deg = std::f64::consts::PI / 180.0;
        let mut p = DMatrix::zeros(n, n);
        let mut set = |i: usize, s: [f64; 3]| {
            for k in 0..3 {
                p[(i + k, i + k)] = s[k] * s[k];
            }
        };
        let t = cfg.initial_tilt_std_deg * deg;
        set(PHI, [t, t, cfg.initial_heading_std_deg * deg]);
        set(DV, [cfg.initial_velocity_std_m_s; 3]);
        set(DP, [cfg.initial_position_std_m; 3]);
        set(EPS, [cfg.initial_gyro_bias_std_deg_h * deg / 3600.0; 3]);
        set(NAB, [cfg.initial_accel_bias_std_ug * 9.806_65e-6; 3]);
        if n == 18 {
            set(PSI, [cfg.initial_mounting_std_deg * deg; 3]);
        }
        if model == ErrorModel::BodyVelocity {
            // The initial uncertainty is stated in navigation-frame terms (velocity error δv^n,
            // attitude error φ). In body axes δv^b = C_n^b δv^n − C_n^b [v^n×] φ: a heading error
            // is also a body-velocity error, correlated with it. Transform, as S-ALIGN's state
            // transformation does; otherwise the filter starts overconfident in δv^b.
            let c_nb = initial.c_body_to_ned().transpose();
            let mut t = DMatrix::<f64>::identity(n, n);
            t.view_mut((DV, PHI), (3, 3))
                .copy_from(&(-c_nb * skew(&initial.velocity_ned)));
            t.view_mut((DV, DV), (3, 3)).copy_from(&c_nb);
            p = &t * &p * t.transpose();
        }
        FineAligner {
            model,
            cfg,
            sd: Strapdown::new(initial),
            p,
            gyro_bias: Vector3::zeros(),
            accel_bias: Vector3::zeros(),
            mount: Vector3::zeros(),
            pending_dt: 0.0,
            mean_w: Vector3::zeros(),
            mean_f: Vector3::zeros(),
            last_w: Vector3::zeros(),
        }
    }

    pub fn state(&self) -> &NavState {
        &self.sd.state
    }

    /// Estimated DVL mounting angles (roll, pitch, yaw of the DVL frame w.r.t. the body; rad).
    pub fn mounting(&self) -> Vector3<f64> {
        self.mount
    }

    /// Estimated IMU biases: gyro (rad/s), accelerometer (m/s²).
    pub fn imu_biases(&self) -> (Vector3<f64>, Vector3<f64>) {
        (self.gyro_bias, self.accel_bias)
    }

    /// Standard deviations (diagonal of the covariance) of attitude (rad), velocity (m/s; body
    /// axes for model 1), position (m), gyro bias (rad/s), accelerometer bias (m/s²).
    pub fn std_devs(&self) -> [Vector3<f64>; 5] {
        let d = |i: usize| Vector3::from_fn(|k, _| self.p[(i + k, i + k)].max(0.0).sqrt());
        [d(PHI), d(DV), d(DP), d(EPS), d(NAB)]
    }

    /// Heading standard deviation (rad).
    pub fn heading_std(&self) -> f64 {
        self.p[(PHI + 2, PHI + 2)].max(0.0).sqrt()
    }

    /// Mounting-angle standard deviations (rad), for the models that estimate them.
    pub fn mounting_std(&self) -> Option<Vector3<f64>> {
        (self.model.states() == 18)
            .then(|| Vector3::from_fn(|i, _| self.p[(PSI + i, PSI + i)].max(0.0).sqrt()))
    }

    /// One IMU interval: raw rate (rad/s) and specific force (m/s²) held over `dt`.
    pub fn on_imu(&mut self, w_raw: &Vector3<f64>, f_raw: &Vector3<f64>, dt: f64) {
        let w = w_raw - self.gyro_bias;
        let f = f_raw - self.accel_bias;
        self.sd.propagate(&ImuIncrement {
            dtheta: w * dt,
            dv: f * dt,
            dt,
        });
        self.last_w = w;
        self.mean_w += w * dt;
        self.mean_f += f * dt;
        self.pending_dt += dt;
        if self.pending_dt >= self.cfg.covariance_interval_s {
            self.propagate_covariance();
        }
    }

    fn propagate_covariance(&mut self) {
        let t = self.pending_dt;
        let w_ib = self.mean_w / t;
        let f_b = self.mean_f / t;
        self.pending_dt = 0.0;
        self.mean_w = Vector3::zeros();
        self.mean_f = Vector3::zeros();
        let s = &self.sd.state;
        let lat = s.position.latitude_rad;
        let h = s.position.height_m;
        let c_bn = s.c_body_to_ned();
        let c_nb = c_bn.transpose();
        let v_n = s.velocity_ned;
        let v_b = c_nb * v_n;
        let w_ie = earth_rate_ned(lat);
        let w_en = transport_rate_ned(lat, h, &v_n);
        let w_in = w_ie + w_en;
        let g_n = gravity_ned(lat, h);
        let n = self.model.states();
        let mut f = DMatrix::zeros(n, n);
        let mut put = |r: usize, c: usize, m: &Matrix3<f64>| {
            f.view_mut((r, c), (3, 3)).copy_from(m);
        };
        put(PHI, PHI, &(-skew(&w_in)));
        put(PHI, EPS, &(-c_bn));
        // Noise input: gyro white noise (3) then accelerometer white noise (3).
        let mut g = DMatrix::zeros(n, 6);
        g.view_mut((PHI, 0), (3, 3)).copy_from(&(-c_bn));
        match self.model {
            ErrorModel::BodyVelocity => {
                put(
                    DV,
                    PHI,
                    &(-c_nb * skew(&g_n) - skew(&v_b) * c_nb * skew(&w_ie)),
                );
                put(DV, DV, &(-skew(&(w_ib + c_nb * w_ie))));
                put(DV, EPS, &skew(&v_b));
                put(DV, NAB, &Matrix3::identity());
                put(DP, PHI, &skew(&v_n));
                put(DP, DV, &c_bn);
                g.view_mut((DV, 0), (3, 3)).copy_from(&skew(&v_b));
                g.view_mut((DV, 3), (3, 3)).copy_from(&Matrix3::identity());
            }
            ErrorModel::NavigationWithMounting | ErrorModel::Navigation => {
                let f_n = c_bn * f_b;
                put(DV, PHI, &skew(&f_n));
                put(DV, DV, &(-skew(&(2.0 * w_ie + w_en))));
                put(DV, NAB, &c_bn);
                put(DP, DV, &Matrix3::identity());
                g.view_mut((DV, 3), (3, 3)).copy_from(&c_bn);
            }
        }
        let ft = &f * t;
        let phi = DMatrix::identity(n, n) + &ft + &ft * &ft * 0.5;
        let deg = std::f64::consts::PI / 180.0;
        let qg = (self.cfg.gyro_arw_deg_sqrt_h * deg / 60.0).powi(2);
        let qa = (self.cfg.accel_vrw_m_s_sqrt_h / 60.0).powi(2);
        let qc = DMatrix::from_diagonal(&DVector::from_vec(vec![qg, qg, qg, qa, qa, qa]));
        let q = &g * qc * g.transpose() * t;
        self.p = &phi * &self.p * phi.transpose() + q;
        self.p = (&self.p + self.p.transpose()) * 0.5;
    }

    /// A DVL velocity (DVL axes, m/s) valid now; returns the innovation norm.
    pub fn on_dvl(&mut self, v_dvl: &Vector3<f64>) -> f64 {
        if self.pending_dt > 0.0 {
            self.propagate_covariance();
        }
        let n = self.model.states();
        let s = &self.sd.state;
        let c_bn = s.c_body_to_ned();
        let c_nb = c_bn.transpose();
        let v_n = s.velocity_ned;
        let v_b = c_nb * v_n;
        let c_db =
            Rotation3::from_euler_angles(self.mount.x, self.mount.y, self.mount.z).into_inner();
        let v_meas_b = c_db * v_dvl;
        let mut h = DMatrix::zeros(3, n);
        let z = match self.model {
            ErrorModel::BodyVelocity => {
                h.view_mut((0, DV), (3, 3)).copy_from(&Matrix3::identity());
                h.view_mut((0, PSI), (3, 3)).copy_from(&skew(&v_b));
                v_b - v_meas_b
            }
            ErrorModel::NavigationWithMounting | ErrorModel::Navigation => {
                h.view_mut((0, PHI), (3, 3)).copy_from(&(-skew(&v_n)));
                h.view_mut((0, DV), (3, 3)).copy_from(&Matrix3::identity());
                if self.model == ErrorModel::NavigationWithMounting {
                    h.view_mut((0, PSI), (3, 3)).copy_from(&(c_bn * skew(&v_b)));
                }
                v_n - c_bn * v_meas_b
            }
        };
        let r = DMatrix::identity(3, 3) * self.cfg.dvl_std_m_s.powi(2);
        let s_mat = &h * &self.p * h.transpose() + &r;
        let Some(s_inv) = s_mat.clone().try_inverse() else {
            return f64::NAN;
        };
        let k = &self.p * h.transpose() * s_inv;
        let zv = DVector::from_column_slice(z.as_slice());
        let x = &k * &zv;
        let i_kh = DMatrix::identity(n, n) - &k * &h;
        self.p = &i_kh * &self.p * i_kh.transpose() + &k * &r * k.transpose();
        self.p = (&self.p + self.p.transpose()) * 0.5;
        self.feedback(&x, &v_b);
        z.norm()
    }

    /// Closed-loop correction of the mechanisation with the estimated errors.
    fn feedback(&mut self, x: &DVector<f64>, v_b_before: &Vector3<f64>) {
        let v3 = |i: usize| Vector3::new(x[i], x[i + 1], x[i + 2]);
        let phi = v3(PHI);
        let s = &mut self.sd.state;
        // C_b^n = (I + [φ×]) C̃_b^n.
        let q_corr = UnitQuaternion::from_scaled_axis(phi);
        s.q_body_to_ned = q_corr * s.q_body_to_ned;
        match self.model {
            ErrorModel::BodyVelocity => {
                let v_b = v_b_before - v3(DV);
                s.velocity_ned = s.c_body_to_ned() * v_b;
            }
            _ => s.velocity_ned -= v3(DV),
        }
        s.position = offset_position(&s.position, &(-v3(DP)));
        self.gyro_bias += v3(EPS);
        self.accel_bias += v3(NAB);
        if self.model.states() == 18 {
            self.mount -= v3(PSI);
        }
    }
}
