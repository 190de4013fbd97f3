//! The navigator: strapdown mechanisation plus the error-state filter ([`NavCore`]), and the aid
//! sources that correct it (`crate::aid`: DVL, depth, GNSS, zero velocity, USBL). It consumes
//! sensor messages in timestamp order and produces navigation solutions and per-aid diagnostics.
//! It reads no clock: time comes from the messages.
//!
//! Covariance propagation runs at `covariance_interval_s` (default 20 Hz), not at the IMU rate:
//! the error dynamics change slowly compared with the IMU interval, a 15-state propagation costs
//! about 7 000 flops, and doing it at 200–1000 Hz would dominate the replay time that offline
//! calibration depends on. The pending interval is always propagated before a measurement update,
//! so updates see the covariance at their own time.

use crate::aid::AidUpdate;
use crate::aid::depth::DepthAid;
use crate::aid::dvl::{DvlAid, DvlParameters};
use crate::aid::gnss::GnssAid;
use crate::aid::usbl::UsblAid;
use crate::aid::zero_velocity::ZeroVelocityAid;
pub use crate::config::NavConfig;
use crate::earth::{self, Geodetic};
use crate::ekf::{self, DynamicsInputs, ErrorFilter, ProcessNoise, StateVector};
use crate::strapdown::{ImuIncrement, NavState, Strapdown};
use auvnav_shm_schema::{
    AidDiagnosticsV1, AidSource, DepthV1, DvlVelocityV1, GnssFixV1, ImuSampleV1, NavMode,
    NavSolutionV1, UsblFixV1,
};
use nalgebra::{UnitQuaternion, Vector3};
use serde::Serialize;

const DEG: f64 = std::f64::consts::PI / 180.0;
const UG: f64 = 9.806_65e-6;

/// Counters of inputs the navigator skipped.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize)]
pub struct NavCounters {
    pub imu_samples: u64,
    /// IMU samples with a non-increasing time stamp (skipped).
    pub imu_out_of_order: u64,
    /// IMU samples with non-finite or invalid values (skipped).
    pub imu_invalid: u64,
    /// IMU gaps longer than the allowed number of intervals (bridged with one long step).
    pub imu_gaps: u64,
    pub dvl_fused: u64,
    pub dvl_rejected: u64,
    pub dvl_invalid: u64,
    /// Velocity covariance re-opened after a run of DVL rejections (see `dvl_reset_after_s`).
    pub dvl_resets: u64,
    pub depth_fused: u64,
    pub depth_rejected: u64,
    pub depth_invalid: u64,
    pub gnss_fused: u64,
    pub gnss_rejected: u64,
    pub gnss_invalid: u64,
    pub zero_velocity_fused: u64,
    pub zero_velocity_rejected: u64,
    pub usbl_fused: u64,
    /// USBL fixes rejected by the innovation gate.
    pub usbl_rejected: u64,
    /// USBL fixes without the fields the coupling needs, or with values out of range.
    pub usbl_invalid: u64,
    /// USBL fixes received without a `[navigation.usbl]` configuration.
    pub usbl_unconfigured: u64,
    /// Times the USBL gate reopened after a run of rejections.
    pub usbl_reopened: u64,
    /// USBL updates that failed numerically (covariance not positive definite).
    pub usbl_failed: u64,
    /// Aiding messages older than the navigation state (skipped).
    pub aid_late: u64,
}

/// The inertial core of the navigator: the strapdown solution, the error filter, the IMU bias
/// estimates and what the aids' models need from the last IMU sample. Aid sources work on it
/// (`crate::aid`); the navigator applies their corrections.
#[derive(Debug, Clone)]
pub struct NavCore {
    noise: ProcessNoise,
    sd: Strapdown,
    /// The error filter (its covariance is what the aids update).
    pub kf: ErrorFilter,
    gyro_bias: Vector3<f64>,
    accel_bias: Vector3<f64>,
    /// Estimates of the parameter states that have a process (Gauss–Markov, e.g. the USBL
    /// errors): their mean decays between updates; constant parameter states keep theirs in the
    /// aid that owns them.
    pub markov_means: nalgebra::SVector<f64, { ekf::PARAMS }>,
    last_imu_ns: Option<u64>,
    last_imu_device_ns: Option<u64>,
    /// The last bias-corrected angular rate (rad/s, body).
    pub last_omega_ib: Vector3<f64>,
    /// The last bias-corrected specific force (m/s², body).
    pub last_f_body: Vector3<f64>,
    pending_dt: f64,
    pending_f_ned: Vector3<f64>,
    diagnostics_sequence: u64,
    covariance_interval_s: f64,
    imu_max_gap_intervals: f64,
    imu_dt_from_device_time: bool,
    /// IMU and lateness counters (the aids count the rest).
    pub counters: CoreCounters,
}

/// What the inertial core counted.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct CoreCounters {
    pub imu_samples: u64,
    pub imu_out_of_order: u64,
    pub imu_invalid: u64,
    pub imu_gaps: u64,
    pub aid_late: u64,
}

impl NavCore {
    fn new(cfg: &NavConfig, initial: NavState) -> NavCore {
        let mut p0 = StateVector::zeros();
        for i in 0..3 {
            p0[ekf::POS + i] = cfg.initial_position_std_m.powi(2);
            p0[ekf::VEL + i] = cfg.initial_velocity_std_m_s.powi(2);
            p0[ekf::BG + i] = (cfg.initial_gyro_bias_std_deg_h * DEG / 3600.0).powi(2);
            p0[ekf::BA + i] = (cfg.initial_accel_bias_std_ug * UG).powi(2);
        }
        p0[ekf::ATT] = (cfg.initial_tilt_std_deg * DEG).powi(2);
        p0[ekf::ATT + 1] = (cfg.initial_tilt_std_deg * DEG).powi(2);
        p0[ekf::ATT + 2] = (cfg.initial_heading_std_deg * DEG).powi(2);
        DvlAid::initial_variances(cfg, &mut p0);
        let noise = ProcessNoise {
            gyro_noise: cfg.gyro_angle_random_walk_deg_sqrt_h * DEG / 60.0,
            accel_noise: cfg.accel_velocity_random_walk_m_s_sqrt_h / 60.0,
            gyro_bias_walk: cfg.gyro_bias_walk_deg_h_sqrt_h * DEG / 3600.0 / 60.0,
            accel_bias_walk: cfg.accel_bias_walk_ug_sqrt_h * UG / 60.0,
        };
        NavCore {
            noise,
            sd: Strapdown::new(initial),
            kf: ErrorFilter::new(&p0),
            gyro_bias: Vector3::zeros(),
            accel_bias: Vector3::zeros(),
            markov_means: nalgebra::SVector::zeros(),
            last_imu_ns: None,
            last_imu_device_ns: None,
            last_omega_ib: Vector3::zeros(),
            last_f_body: Vector3::zeros(),
            pending_dt: 0.0,
            pending_f_ned: Vector3::zeros(),
            diagnostics_sequence: 0,
            covariance_interval_s: cfg.covariance_interval_s,
            imu_max_gap_intervals: cfg.imu_max_gap_intervals,
            imu_dt_from_device_time: cfg.imu_dt_from_device_time,
            counters: CoreCounters::default(),
        }
    }

    /// The navigation state.
    pub fn state(&self) -> &NavState {
        &self.sd.state
    }

    /// Integrates one IMU sample; false when it was skipped (invalid, out of order; counted).
    fn integrate(&mut self, m: &ImuSampleV1) -> bool {
        let t_ns = m.host_time_ns;
        let finite = m
            .angular
            .iter()
            .chain(m.specific.iter())
            .all(|x| x.is_finite());
        let valid_bits = ImuSampleV1::STATUS_GYRO_VALID | ImuSampleV1::STATUS_ACCEL_VALID;
        if !finite
            || m.status & valid_bits != valid_bits
            || !(m.interval_s > 0.0 && m.interval_s < 1.0)
        {
            self.counters.imu_invalid += 1;
            return false;
        }
        let state_ns = (self.sd.state.time_s * 1e9).round() as u64;
        let last = self.last_imu_ns.unwrap_or(state_ns);
        let device_ns =
            (m.status & ImuSampleV1::STATUS_DEVICE_TIME_VALID != 0).then_some(m.device_time_ns);
        // With device time, samples completed by one read (same host time) are still ordered
        // and integrated over their own intervals.
        let device_dt = match (
            self.imu_dt_from_device_time,
            device_ns,
            self.last_imu_device_ns,
        ) {
            (true, Some(now), Some(prev)) if now > prev && now - prev < 1_000_000_000 => {
                Some((now - prev) as f64 * 1e-9)
            }
            _ => None,
        };
        if (device_dt.is_none() && t_ns <= last) || t_ns < last {
            self.counters.imu_out_of_order += 1;
            return false;
        }
        let mut dt = device_dt.unwrap_or((t_ns - last) as f64 * 1e-9);
        self.last_imu_device_ns = device_ns;
        if dt > self.imu_max_gap_intervals * m.interval_s {
            self.counters.imu_gaps += 1;
            // Bridge the gap with the sample's own rates over its nominal interval only; the
            // missing time still passes (the state time follows the message time).
            dt = dt.min(1.0);
        }
        self.last_imu_ns = Some(t_ns);
        self.counters.imu_samples += 1;
        let increments = m.status & ImuSampleV1::STATUS_INCREMENTS != 0;
        let (w, f) = if increments {
            (
                Vector3::from(m.angular) / m.interval_s,
                Vector3::from(m.specific) / m.interval_s,
            )
        } else {
            (Vector3::from(m.angular), Vector3::from(m.specific))
        };
        let w = w - self.gyro_bias;
        let f = f - self.accel_bias;
        self.last_omega_ib = w;
        self.last_f_body = f;
        let c_before = self.sd.state.c_body_to_ned();
        self.sd.propagate(&ImuIncrement {
            dtheta: w * dt,
            dv: f * dt,
            dt,
        });
        self.sd.state.time_s = t_ns as f64 * 1e-9;
        self.pending_f_ned += c_before * f * dt;
        self.pending_dt += dt;
        true
    }

    /// Propagates the covariance over the pending interval (no-op when none is pending); the
    /// interval propagated, for the aids' own processes.
    pub fn propagate_covariance(&mut self) -> Option<f64> {
        if self.pending_dt <= 0.0 {
            return None;
        }
        let s = &self.sd.state;
        let inputs = DynamicsInputs {
            c_body_to_ned: s.c_body_to_ned(),
            specific_force_ned: self.pending_f_ned / self.pending_dt,
            velocity_ned: s.velocity_ned,
            latitude_rad: s.position.latitude_rad,
            height_m: s.position.height_m,
        };
        let f = ekf::dynamics_matrix(&inputs);
        self.kf
            .predict(&f, &inputs.c_body_to_ned, &self.noise, self.pending_dt);
        // The expected value of a Gauss-Markov parameter state decays with its correlation
        // time (constants: a = 1).
        let a = self.kf.param_transition(self.pending_dt);
        for i in 0..ekf::PARAMS {
            self.markov_means[i] *= a[i];
        }
        let dt = self.pending_dt;
        self.pending_dt = 0.0;
        self.pending_f_ned = Vector3::zeros();
        Some(dt)
    }

    /// Applies an error-state estimate to the navigation state and the biases.
    pub fn correct(&mut self, dx: &StateVector) {
        let s = &mut self.sd.state;
        let dp = Vector3::new(dx[ekf::POS], dx[ekf::POS + 1], dx[ekf::POS + 2]);
        s.position = earth::offset_position(&s.position, &(-dp));
        s.velocity_ned -= Vector3::new(dx[ekf::VEL], dx[ekf::VEL + 1], dx[ekf::VEL + 2]);
        let phi = Vector3::new(dx[ekf::ATT], dx[ekf::ATT + 1], dx[ekf::ATT + 2]);
        s.q_body_to_ned = UnitQuaternion::from_scaled_axis(phi) * s.q_body_to_ned;
        self.gyro_bias += Vector3::new(dx[ekf::BG], dx[ekf::BG + 1], dx[ekf::BG + 2]);
        self.accel_bias += Vector3::new(dx[ekf::BA], dx[ekf::BA + 1], dx[ekf::BA + 2]);
        for i in 0..ekf::PARAMS {
            self.markov_means[i] -= dx[ekf::CORE + i];
        }
    }

    /// An aid more than one covariance interval older than the state is not fused (counted).
    pub fn aid_is_late(&mut self, t_ns: u64) -> bool {
        let state_ns = (self.sd.state.time_s * 1e9).round() as i128;
        let late =
            (state_ns - i128::from(t_ns)) as f64 * 1e-9 > self.covariance_interval_s.max(0.05);
        if late {
            self.counters.aid_late += 1;
        }
        late
    }

    /// Fresh diagnostics of an aid message (numbered in processing order).
    pub fn diagnostics(&mut self, t_ns: u64, source: AidSource) -> AidDiagnosticsV1 {
        self.diagnostics_sequence += 1;
        AidDiagnosticsV1 {
            host_time_ns: t_ns,
            sequence: self.diagnostics_sequence,
            source: source as u32,
            ..Default::default()
        }
    }

    /// Copies an update's innovation into the diagnostics (as observation minus prediction) and
    /// sets the fused/rejected flag; the correction to apply when it was fused.
    pub fn report<const M: usize>(
        result: Result<(StateVector, ekf::UpdateReport<M>), ekf::FilterError>,
        d: &mut AidDiagnosticsV1,
    ) -> Option<StateVector> {
        match result {
            Ok((dx, rep)) => {
                for i in 0..M.min(3) {
                    d.innovation[i] = -rep.innovation[i];
                    d.innovation_variance[i] = rep.innovation_variance[i];
                }
                d.test_ratio = rep.test_ratio;
                if rep.fused {
                    d.flags = AidDiagnosticsV1::FLAG_FUSED;
                    Some(dx)
                } else {
                    d.flags = AidDiagnosticsV1::FLAG_REJECTED;
                    None
                }
            }
            Err(_) => {
                d.flags = AidDiagnosticsV1::FLAG_REJECTED;
                None
            }
        }
    }
}

/// The navigator: the inertial core and the aid sources.
#[derive(Debug, Clone)]
pub struct Navigator {
    core: NavCore,
    // The aid sources. A new aid is a field here, its `on_<aid>` below, and (when it has
    // parameter states without a process) its line in `apply`.
    dvl: DvlAid,
    depth: DepthAid,
    gnss: GnssAid,
    zero_velocity: ZeroVelocityAid,
    usbl: UsblAid,
    dvl_timeout_s: f64,
    solution_sequence: u64,
}

impl Navigator {
    /// Starts navigating from a known initial state (alignment is a separate mode).
    pub fn new(cfg: NavConfig, initial: NavState) -> Navigator {
        let mut core = NavCore::new(&cfg, initial);
        let usbl = UsblAid::new(cfg.usbl.as_ref(), &mut core.kf);
        Navigator {
            dvl: DvlAid::new(&cfg, initial.time_s),
            depth: DepthAid::new(&cfg),
            gnss: GnssAid::new(&cfg),
            zero_velocity: ZeroVelocityAid::new(&cfg),
            usbl,
            core,
            dvl_timeout_s: cfg.dvl_timeout_s,
            solution_sequence: 0,
        }
    }

    /// Applies a fused aid's correction to the core and to the aids' parameter states.
    fn apply(&mut self, u: AidUpdate) -> AidDiagnosticsV1 {
        if let Some(dx) = &u.correction {
            self.core.correct(dx);
            self.dvl.correct(dx);
        }
        u.diagnostics
    }

    pub fn state(&self) -> &NavState {
        &self.core.sd.state
    }

    pub fn covariance(&self) -> &ekf::Covariance {
        &self.core.kf.p
    }

    /// The current DVL installation parameters (estimated when their states are switched on).
    pub fn dvl_parameters(&self) -> &DvlParameters {
        &self.dvl.params
    }

    /// Starts from known IMU bias estimates (an alignment filter's): gyro (rad/s), accelerometer
    /// (m/s^2).
    pub fn set_imu_biases(&mut self, gyro: Vector3<f64>, accel: Vector3<f64>) {
        self.core.gyro_bias = gyro;
        self.core.accel_bias = accel;
    }

    /// The current IMU bias estimates: gyro (rad/s), accelerometer (m/s^2).
    pub fn imu_biases(&self) -> (Vector3<f64>, Vector3<f64>) {
        (self.core.gyro_bias, self.core.accel_bias)
    }

    /// Takes `m` as the sample the navigation starts at: its times are where the integration of
    /// the next sample begins (it is not integrated itself).
    pub fn start_at_imu(&mut self, m: &ImuSampleV1) {
        self.core.last_imu_ns = Some(m.host_time_ns);
        self.core.last_imu_device_ns =
            (m.status & ImuSampleV1::STATUS_DEVICE_TIME_VALID != 0).then_some(m.device_time_ns);
    }

    /// Processes one IMU sample; returns the solution at its time, or `None` if it was skipped.
    pub fn on_imu(&mut self, m: &ImuSampleV1) -> Option<NavSolutionV1> {
        if !self.core.integrate(m) {
            return None;
        }
        self.usbl.after_imu(&self.core.sd.state);
        if self.core.pending_dt >= self.core.covariance_interval_s {
            self.core.propagate_covariance();
        }
        Some(self.solution(m.host_time_ns))
    }

    /// Fuses a DVL velocity (`crate::aid::dvl`).
    pub fn on_dvl(&mut self, m: &DvlVelocityV1) -> AidDiagnosticsV1 {
        let u = self.dvl.fuse(&mut self.core, m);
        self.apply(u)
    }

    /// Fuses a depth measurement (`crate::aid::depth`).
    pub fn on_depth(&mut self, m: &DepthV1) -> AidDiagnosticsV1 {
        let u = self.depth.fuse(&mut self.core, m);
        self.apply(u)
    }

    /// Fuses a GNSS position (`crate::aid::gnss`).
    pub fn on_gnss(&mut self, m: &GnssFixV1) -> AidDiagnosticsV1 {
        let u = self.gnss.fuse(&mut self.core, m);
        self.apply(u)
    }

    /// Fuses a zero-velocity observation at `t_ns` (`crate::aid::zero_velocity`).
    pub fn on_zero_velocity(&mut self, t_ns: u64) -> AidDiagnosticsV1 {
        let u = self.zero_velocity.fuse(&mut self.core, t_ns);
        self.apply(u)
    }

    /// Fuses a USBL fix from the docking station (`crate::aid::usbl`).
    pub fn on_usbl(&mut self, m: &UsblFixV1) -> AidDiagnosticsV1 {
        let u = self.usbl.fuse(&mut self.core, m);
        self.apply(u)
    }

    /// The estimated USBL measurement errors [δR, δΔR13, δΔR24] (m) and the noise variances in
    /// use, when USBL fusion is configured and has seen a fix.
    pub fn usbl_estimates(&self) -> Option<(Vector3<f64>, Vector3<f64>)> {
        self.usbl.estimates(&self.core)
    }

    /// What the navigator and its aids counted.
    pub fn counters(&self) -> NavCounters {
        let (c, dvl, depth, gnss, zv, usbl) = (
            &self.core.counters,
            &self.dvl.counters,
            &self.depth.counters,
            &self.gnss.counters,
            &self.zero_velocity.counters,
            &self.usbl.counters,
        );
        NavCounters {
            imu_samples: c.imu_samples,
            imu_out_of_order: c.imu_out_of_order,
            imu_invalid: c.imu_invalid,
            imu_gaps: c.imu_gaps,
            dvl_fused: dvl.fused,
            dvl_rejected: dvl.rejected,
            dvl_invalid: dvl.invalid,
            dvl_resets: self.dvl.resets,
            depth_fused: depth.fused,
            depth_rejected: depth.rejected,
            depth_invalid: depth.invalid,
            gnss_fused: gnss.fused,
            gnss_rejected: gnss.rejected,
            gnss_invalid: gnss.invalid,
            zero_velocity_fused: zv.fused,
            zero_velocity_rejected: zv.rejected,
            usbl_fused: usbl.fused,
            usbl_rejected: usbl.rejected,
            usbl_invalid: usbl.invalid,
            usbl_unconfigured: usbl.unconfigured,
            usbl_reopened: usbl.reopened,
            usbl_failed: usbl.failed,
            aid_late: c.aid_late,
        }
    }

    /// The navigation solution now.
    pub fn solution(&mut self, t_ns: u64) -> NavSolutionV1 {
        self.solution_sequence += 1;
        let s = &self.core.sd.state;
        let q = s.q_body_to_ned;
        let p = &self.core.kf.p;
        let std = |i: usize| {
            [
                p[(i, i)].sqrt(),
                p[(i + 1, i + 1)].sqrt(),
                p[(i + 2, i + 2)].sqrt(),
            ]
        };
        let dvl_ok = s.time_s - self.dvl.last_fused_s <= self.dvl_timeout_s;
        let mut health = NavSolutionV1::HEALTH_IMU;
        if dvl_ok {
            health |= NavSolutionV1::HEALTH_DVL;
        }
        let usbl_fused_s = self.usbl.last_fused_s();
        if usbl_fused_s.is_some_and(|t| s.time_s - t <= self.dvl_timeout_s) {
            health |= NavSolutionV1::HEALTH_USBL;
        }
        NavSolutionV1 {
            host_time_ns: t_ns,
            sequence: self.solution_sequence,
            latitude_rad: s.position.latitude_rad,
            longitude_rad: s.position.longitude_rad,
            height_m: s.position.height_m,
            velocity_ned_m_s: s.velocity_ned.into(),
            quaternion_body_to_ned: [q.w, q.i, q.j, q.k],
            euler_rad: s.euler(),
            position_std_ned_m: std(ekf::POS),
            velocity_std_ned_m_s: std(ekf::VEL),
            attitude_std_rad: std(ekf::ATT),
            gyro_bias_rad_s: self.core.gyro_bias.into(),
            accel_bias_m_s2: self.core.accel_bias.into(),
            mode: if dvl_ok {
                NavMode::Navigating
            } else {
                NavMode::Degraded
            } as u32,
            sensor_health: health,
        }
    }
}

/// Convenience: the initial state from a geodetic position, NED velocity and Euler angles.
pub fn initial_state(
    time_s: f64,
    position: Geodetic,
    velocity_ned: [f64; 3],
    euler_rad: [f64; 3],
) -> NavState {
    NavState {
        time_s,
        position,
        velocity_ned: Vector3::from(velocity_ned),
        q_body_to_ned: UnitQuaternion::from_euler_angles(euler_rad[0], euler_rad[1], euler_rad[2]),
    }
}
