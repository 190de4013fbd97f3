//! The navigator: strapdown mechanisation plus the error-state filter with DVL velocity and depth
//! aiding. It consumes sensor messages in timestamp order and produces navigation solutions and
//! per-aid diagnostics. It reads no clock: time comes from the messages.
//!
//! Covariance propagation runs at `covariance_interval_s` (default 20 Hz), not at the IMU rate:
//! the error dynamics change slowly compared with the IMU interval, a 15-state propagation costs
//! about 7 000 flops, and doing it at 200–1000 Hz would dominate the replay time that offline
//! calibration depends on. The pending interval is always propagated before a measurement update,
//! so updates see the covariance at their own time.

use crate::earth::{self, Geodetic};
use crate::filter::{self, DynamicsInputs, ErrorFilter, ProcessNoise, StateVector, skew};
use crate::strapdown::{ImuIncrement, NavState, Strapdown};
use crate::usbl::{
    self, AdaptiveNoise, Coupling, ResponderGeometry, UsblArray, UsblConfig, UsblFilter,
};
use auvnav_shm_schema::{
    AidDiagnosticsV1, AidSource, DepthV1, DvlVelocityV1, GnssFixV1, ImuSampleV1, NavMode,
    NavSolutionV1, UsblFixV1,
};
use nalgebra::{DMatrix, DVector, Matrix3, Rotation3, SMatrix, SVector, UnitQuaternion, Vector3};
use serde::{Deserialize, Serialize};
use std::collections::VecDeque;

/// Chi-square gate, 3 degrees of freedom, 99.9 %.
pub const GATE_CHI2_3DOF: f64 = 16.27;
/// Chi-square gate, 1 degree of freedom, 99.9 %.
pub const GATE_CHI2_1DOF: f64 = 10.83;

/// The navigation configuration shared by the daemon, replay and every offline tool.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct NavConfig {
    /// Gyro angle random walk (deg/sqrt(h)). Default 0.005.
    pub gyro_angle_random_walk_deg_sqrt_h: f64,
    /// Accelerometer velocity random walk (m/s/sqrt(h)). Default 0.002.
    pub accel_velocity_random_walk_m_s_sqrt_h: f64,
    /// Gyro bias random walk (deg/h/sqrt(h)). Default 0.002.
    pub gyro_bias_walk_deg_h_sqrt_h: f64,
    /// Accelerometer bias random walk (ug/sqrt(h)). Default 5.
    pub accel_bias_walk_ug_sqrt_h: f64,
    /// Initial one-sigma position uncertainty (m). Default 1.
    pub initial_position_std_m: f64,
    /// Initial one-sigma velocity uncertainty (m/s). Default 0.1.
    pub initial_velocity_std_m_s: f64,
    /// Initial one-sigma roll/pitch uncertainty (deg). Default 0.05.
    pub initial_tilt_std_deg: f64,
    /// Initial one-sigma heading uncertainty (deg). Default 0.1.
    pub initial_heading_std_deg: f64,
    /// Initial one-sigma gyro bias (deg/h). Default 0.05.
    pub initial_gyro_bias_std_deg_h: f64,
    /// Initial one-sigma accelerometer bias (ug). Default 100.
    pub initial_accel_bias_std_ug: f64,
    /// DVL velocity noise per axis when the device gives none (m/s). Default 0.02.
    pub dvl_velocity_std_m_s: f64,
    /// DVL mounting angles roll, pitch, yaw of the DVL frame w.r.t. the body (deg). Default 0.
    pub dvl_mount_deg: [f64; 3],
    /// DVL scale factor (1 = none). Default 1.
    pub dvl_scale_factor: f64,
    /// DVL position in the body frame (m). Default 0.
    pub dvl_lever_arm_m: [f64; 3],
    /// Depth noise (m). Default 0.1.
    pub depth_std_m: f64,
    /// Gate for DVL velocity (chi-square, 3 dof). Default 16.27 (99.9 %).
    pub dvl_gate_chi2: f64,
    /// Gate for depth (chi-square, 1 dof). Default 10.83 (99.9 %).
    pub depth_gate_chi2: f64,
    /// Covariance propagation interval (s). Default 0.05.
    pub covariance_interval_s: f64,
    /// Without a fused DVL velocity for this long the mode is degraded (s). Default 5.
    pub dvl_timeout_s: f64,
    /// IMU gaps longer than this many nominal intervals are bridged and counted (count). Default 10.
    pub imu_max_gap_intervals: f64,
    /// Integrate each IMU sample over the difference of the device's time stamps (when both
    /// samples carry one and it is between 0 and 1 s) instead of the host's read times: removes
    /// the read-time jitter of a live serial line, and keeps the integration right when a log is
    /// played faster than real time. Default false (host time, as recorded logs are stamped).
    pub imu_dt_from_device_time: bool,
    /// DVL time offset: the velocity stamped at t is the vehicle's at t - offset (s). Default 0.
    pub dvl_time_offset_s: f64,
    /// Estimate the DVL mounting angles (parameter states). Default false.
    pub estimate_dvl_mounting: bool,
    /// Initial one-sigma of the DVL mounting angles when estimated (deg). Default 1.
    pub initial_dvl_mounting_std_deg: f64,
    /// Estimate the DVL scale factor (parameter state). Default false.
    pub estimate_dvl_scale: bool,
    /// Initial one-sigma of the DVL scale factor when estimated (1). Default 0.01.
    pub initial_dvl_scale_std: f64,
    /// Estimate the DVL lever arm (parameter states). Default false.
    pub estimate_dvl_lever_arm: bool,
    /// Initial one-sigma of the DVL lever arm when estimated (m). Default 0.5.
    pub initial_dvl_lever_arm_std_m: f64,
    /// Estimate the DVL time offset (parameter state). Default false.
    pub estimate_dvl_time_offset: bool,
    /// Initial one-sigma of the DVL time offset when estimated (s). Default 0.2.
    pub initial_dvl_time_offset_std_s: f64,
    /// GNSS antenna position in the body frame (m). Default 0.
    pub gnss_lever_arm_m: [f64; 3],
    /// Smallest GNSS position one-sigma used, whatever the receiver reports (m). Default 0.5.
    pub gnss_min_std_m: f64,
    /// Gate for GNSS position (chi-square, 3 dof). Default 16.27 (99.9 %).
    pub gnss_gate_chi2: f64,
    /// One-sigma of a zero-velocity update per axis (m/s). Default 0.01.
    pub zero_velocity_std_m_s: f64,
    /// After valid DVL velocities have been rejected without a break for this long, the velocity
    /// covariance is re-opened (cross-covariances dropped, the innovation added to the variances)
    /// and the measurement fused: the filter had become too sure of a wrong velocity (s; 0 =
    /// never). Default 5.
    pub dvl_reset_after_s: f64,
    /// USBL fusion (`[navigation.usbl]`): the station's array, the coupling and the filter.
    /// Default none: USBL fixes are counted and not used.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub usbl: Option<UsblConfig>,
}

impl Default for NavConfig {
    fn default() -> Self {
        NavConfig {
            gyro_angle_random_walk_deg_sqrt_h: 0.005,
            accel_velocity_random_walk_m_s_sqrt_h: 0.002,
            gyro_bias_walk_deg_h_sqrt_h: 0.002,
            accel_bias_walk_ug_sqrt_h: 5.0,
            initial_position_std_m: 1.0,
            initial_velocity_std_m_s: 0.1,
            initial_tilt_std_deg: 0.05,
            initial_heading_std_deg: 0.1,
            initial_gyro_bias_std_deg_h: 0.05,
            initial_accel_bias_std_ug: 100.0,
            dvl_velocity_std_m_s: 0.02,
            dvl_mount_deg: [0.0; 3],
            dvl_scale_factor: 1.0,
            dvl_lever_arm_m: [0.0; 3],
            depth_std_m: 0.1,
            dvl_gate_chi2: GATE_CHI2_3DOF,
            depth_gate_chi2: GATE_CHI2_1DOF,
            covariance_interval_s: 0.05,
            dvl_timeout_s: 5.0,
            imu_max_gap_intervals: 10.0,
            imu_dt_from_device_time: false,
            dvl_time_offset_s: 0.0,
            estimate_dvl_mounting: false,
            initial_dvl_mounting_std_deg: 1.0,
            estimate_dvl_scale: false,
            initial_dvl_scale_std: 0.01,
            estimate_dvl_lever_arm: false,
            initial_dvl_lever_arm_std_m: 0.5,
            estimate_dvl_time_offset: false,
            initial_dvl_time_offset_std_s: 0.2,
            gnss_lever_arm_m: [0.0; 3],
            gnss_min_std_m: 0.5,
            gnss_gate_chi2: GATE_CHI2_3DOF,
            zero_velocity_std_m_s: 0.01,
            dvl_reset_after_s: 5.0,
            usbl: None,
        }
    }
}

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

/// The navigator.
#[derive(Debug, Clone)]
pub struct Navigator {
    cfg: NavConfig,
    noise: ProcessNoise,
    sd: Strapdown,
    kf: ErrorFilter,
    gyro_bias: Vector3<f64>,
    accel_bias: Vector3<f64>,
    dvl: DvlParameters,
    last_imu_ns: Option<u64>,
    last_imu_device_ns: Option<u64>,
    last_omega_ib: Vector3<f64>,
    last_f_body: Vector3<f64>,
    pending_dt: f64,
    pending_f_ned: Vector3<f64>,
    last_dvl_fused_s: f64,
    dvl_rejected_since_s: Option<f64>,
    solution_sequence: u64,
    diagnostics_sequence: u64,
    usbl: Option<UsblFusion>,
    pub counters: NavCounters,
}

/// The USBL fusion state: the surveyed array, the current estimate of the USBL measurement errors
/// (Gauss–Markov, tight coupling) and the noise estimator.
#[derive(Debug, Clone)]
struct UsblFusion {
    cfg: UsblConfig,
    array: UsblArray,
    lever_arm_b: Vector3<f64>,
    /// Estimated measurement errors [δR, δΔR13, δΔR24] (m), subtracted from the measurement.
    errors: Vector3<f64>,
    /// Started at the first usable fix (the loose noise depends on its geometry).
    noise: Option<AdaptiveNoise>,
    last_fused_s: Option<f64>,
    /// The vehicle's recent poses (time, position, attitude), for fixes whose time of validity
    /// lies in the past; `max_latency_s` of them.
    poses: VecDeque<(f64, Geodetic, UnitQuaternion<f64>)>,
}

impl UsblFusion {
    /// The vehicle's pose at `t` (linear between the recorded poses; the oldest or newest one
    /// outside them).
    fn pose_at(&self, t: f64) -> Option<(Geodetic, UnitQuaternion<f64>)> {
        let after = self.poses.partition_point(|p| p.0 < t);
        match (
            after.checked_sub(1).and_then(|i| self.poses.get(i)),
            self.poses.get(after),
        ) {
            (Some(a), Some(b)) if b.0 > a.0 => {
                let w = (t - a.0) / (b.0 - a.0);
                let position = Geodetic {
                    latitude_rad: a.1.latitude_rad + w * (b.1.latitude_rad - a.1.latitude_rad),
                    longitude_rad: a.1.longitude_rad + w * (b.1.longitude_rad - a.1.longitude_rad),
                    height_m: a.1.height_m + w * (b.1.height_m - a.1.height_m),
                };
                Some((position, a.2.slerp(&b.2, w)))
            }
            (_, Some(p)) | (Some(p), None) => Some((p.1, p.2)),
            (None, None) => None,
        }
    }
}

impl Navigator {
    /// Starts navigating from a known initial state (alignment is a separate mode).
    pub fn new(cfg: NavConfig, initial: NavState) -> Navigator {
        let mut p0 = StateVector::zeros();
        for i in 0..3 {
            p0[filter::POS + i] = cfg.initial_position_std_m.powi(2);
            p0[filter::VEL + i] = cfg.initial_velocity_std_m_s.powi(2);
            p0[filter::BG + i] = (cfg.initial_gyro_bias_std_deg_h * DEG / 3600.0).powi(2);
            p0[filter::BA + i] = (cfg.initial_accel_bias_std_ug * UG).powi(2);
        }
        p0[filter::ATT] = (cfg.initial_tilt_std_deg * DEG).powi(2);
        p0[filter::ATT + 1] = (cfg.initial_tilt_std_deg * DEG).powi(2);
        p0[filter::ATT + 2] = (cfg.initial_heading_std_deg * DEG).powi(2);
        for i in 0..3 {
            if cfg.estimate_dvl_mounting {
                p0[filter::DVL_MOUNT + i] = (cfg.initial_dvl_mounting_std_deg * DEG).powi(2);
            }
            if cfg.estimate_dvl_lever_arm {
                p0[filter::DVL_LEVER + i] = cfg.initial_dvl_lever_arm_std_m.powi(2);
            }
        }
        if cfg.estimate_dvl_scale {
            p0[filter::DVL_SCALE] = cfg.initial_dvl_scale_std.powi(2);
        }
        if cfg.estimate_dvl_time_offset {
            p0[filter::DVL_TIME] = cfg.initial_dvl_time_offset_std_s.powi(2);
        }
        let noise = ProcessNoise {
            gyro_noise: cfg.gyro_angle_random_walk_deg_sqrt_h * DEG / 60.0,
            accel_noise: cfg.accel_velocity_random_walk_m_s_sqrt_h / 60.0,
            gyro_bias_walk: cfg.gyro_bias_walk_deg_h_sqrt_h * DEG / 3600.0 / 60.0,
            accel_bias_walk: cfg.accel_bias_walk_ug_sqrt_h * UG / 60.0,
        };
        let [r, p, y] = cfg.dvl_mount_deg;
        let dvl = DvlParameters {
            c_dvl_to_body: Rotation3::from_euler_angles(r * DEG, p * DEG, y * DEG).into_inner(),
            scale: cfg.dvl_scale_factor,
            lever_arm_m: Vector3::from(cfg.dvl_lever_arm_m),
            time_offset_s: cfg.dvl_time_offset_s,
        };
        let mut kf = ErrorFilter::new(&p0);
        let usbl = cfg.usbl.as_ref().map(|u| {
            if u.coupling == Coupling::Tight {
                kf.set_gauss_markov(
                    filter::USBL,
                    u.range_error_correlation_s,
                    u.range_error_std_m,
                );
                for i in 1..3 {
                    kf.set_gauss_markov(
                        filter::USBL + i,
                        u.range_difference_error_correlation_s,
                        u.range_difference_error_std_m,
                    );
                }
            }
            UsblFusion {
                array: u.array(),
                lever_arm_b: Vector3::from(u.responder_lever_arm_m),
                errors: Vector3::zeros(),
                noise: None,
                last_fused_s: None,
                poses: VecDeque::new(),
                cfg: u.clone(),
            }
        });
        Navigator {
            noise,
            sd: Strapdown::new(initial),
            kf,
            usbl,
            gyro_bias: Vector3::zeros(),
            accel_bias: Vector3::zeros(),
            dvl,
            last_imu_ns: None,
            last_imu_device_ns: None,
            last_omega_ib: Vector3::zeros(),
            last_f_body: Vector3::zeros(),
            pending_dt: 0.0,
            pending_f_ned: Vector3::zeros(),
            last_dvl_fused_s: initial.time_s,
            dvl_rejected_since_s: None,
            solution_sequence: 0,
            diagnostics_sequence: 0,
            counters: NavCounters::default(),
            cfg,
        }
    }

    pub fn state(&self) -> &NavState {
        &self.sd.state
    }

    pub fn covariance(&self) -> &filter::Covariance {
        &self.kf.p
    }

    /// The current DVL installation parameters (estimated when their states are switched on).
    pub fn dvl_parameters(&self) -> &DvlParameters {
        &self.dvl
    }

    /// Starts from known IMU bias estimates (an alignment filter's): gyro (rad/s), accelerometer
    /// (m/s^2).
    pub fn set_imu_biases(&mut self, gyro: Vector3<f64>, accel: Vector3<f64>) {
        self.gyro_bias = gyro;
        self.accel_bias = accel;
    }

    /// The current IMU bias estimates: gyro (rad/s), accelerometer (m/s^2).
    pub fn imu_biases(&self) -> (Vector3<f64>, Vector3<f64>) {
        (self.gyro_bias, self.accel_bias)
    }

    /// Takes `m` as the sample the navigation starts at: its times are where the integration of
    /// the next sample begins (it is not integrated itself).
    pub fn start_at_imu(&mut self, m: &ImuSampleV1) {
        self.last_imu_ns = Some(m.host_time_ns);
        self.last_imu_device_ns =
            (m.status & ImuSampleV1::STATUS_DEVICE_TIME_VALID != 0).then_some(m.device_time_ns);
    }

    /// Processes one IMU sample; returns the solution at its time, or `None` if it was skipped.
    pub fn on_imu(&mut self, m: &ImuSampleV1) -> Option<NavSolutionV1> {
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
            return None;
        }
        let state_ns = (self.sd.state.time_s * 1e9).round() as u64;
        let last = self.last_imu_ns.unwrap_or(state_ns);
        let device_ns =
            (m.status & ImuSampleV1::STATUS_DEVICE_TIME_VALID != 0).then_some(m.device_time_ns);
        // With device time, samples completed by one read (same host time) are still ordered
        // and integrated over their own intervals.
        let device_dt = match (
            self.cfg.imu_dt_from_device_time,
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
            return None;
        }
        let mut dt = device_dt.unwrap_or((t_ns - last) as f64 * 1e-9);
        self.last_imu_device_ns = device_ns;
        if dt > self.cfg.imu_max_gap_intervals * m.interval_s {
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
        if let Some(u) = self.usbl.as_mut() {
            let s = &self.sd.state;
            u.poses.push_back((s.time_s, s.position, s.q_body_to_ned));
            while u
                .poses
                .front()
                .is_some_and(|p| s.time_s - p.0 > u.cfg.max_latency_s + 0.1)
            {
                u.poses.pop_front();
            }
        }
        if self.pending_dt >= self.cfg.covariance_interval_s {
            self.propagate_covariance();
        }
        Some(self.solution(t_ns))
    }

    fn propagate_covariance(&mut self) {
        if self.pending_dt <= 0.0 {
            return;
        }
        let s = &self.sd.state;
        let inputs = DynamicsInputs {
            c_body_to_ned: s.c_body_to_ned(),
            specific_force_ned: self.pending_f_ned / self.pending_dt,
            velocity_ned: s.velocity_ned,
            latitude_rad: s.position.latitude_rad,
            height_m: s.position.height_m,
        };
        let f = filter::dynamics_matrix(&inputs);
        self.kf
            .predict(&f, &inputs.c_body_to_ned, &self.noise, self.pending_dt);
        if let Some(u) = self.usbl.as_mut() {
            // The expected value of a Gauss-Markov error decays with its correlation time.
            let a = self.kf.param_transition(self.pending_dt);
            for i in 0..3 {
                u.errors[i] *= a[filter::USBL - filter::CORE + i];
            }
        }
        self.pending_dt = 0.0;
        self.pending_f_ned = Vector3::zeros();
    }

    /// Applies an error-state estimate to the navigation state and the biases.
    fn correct(&mut self, dx: &StateVector) {
        let s = &mut self.sd.state;
        let dp = Vector3::new(dx[filter::POS], dx[filter::POS + 1], dx[filter::POS + 2]);
        s.position = earth::offset_position(&s.position, &(-dp));
        s.velocity_ned -= Vector3::new(dx[filter::VEL], dx[filter::VEL + 1], dx[filter::VEL + 2]);
        let phi = Vector3::new(dx[filter::ATT], dx[filter::ATT + 1], dx[filter::ATT + 2]);
        s.q_body_to_ned = UnitQuaternion::from_scaled_axis(phi) * s.q_body_to_ned;
        self.gyro_bias += Vector3::new(dx[filter::BG], dx[filter::BG + 1], dx[filter::BG + 2]);
        self.accel_bias += Vector3::new(dx[filter::BA], dx[filter::BA + 1], dx[filter::BA + 2]);
        let dm = Vector3::new(
            dx[filter::DVL_MOUNT],
            dx[filter::DVL_MOUNT + 1],
            dx[filter::DVL_MOUNT + 2],
        );
        self.dvl.c_dvl_to_body *= Rotation3::from_scaled_axis(-dm).into_inner();
        self.dvl.scale -= dx[filter::DVL_SCALE];
        self.dvl.lever_arm_m -= Vector3::new(
            dx[filter::DVL_LEVER],
            dx[filter::DVL_LEVER + 1],
            dx[filter::DVL_LEVER + 2],
        );
        self.dvl.time_offset_s -= dx[filter::DVL_TIME];
        if let Some(u) = self.usbl.as_mut() {
            u.errors -= Vector3::new(dx[filter::USBL], dx[filter::USBL + 1], dx[filter::USBL + 2]);
        }
    }

    fn aid_is_late(&mut self, t_ns: u64) -> bool {
        // An aid more than one covariance interval older than the state is not fused.
        let state_ns = (self.sd.state.time_s * 1e9).round() as i128;
        let late =
            (state_ns - i128::from(t_ns)) as f64 * 1e-9 > self.cfg.covariance_interval_s.max(0.05);
        if late {
            self.counters.aid_late += 1;
        }
        late
    }

    fn diagnostics(&mut self, t_ns: u64, source: AidSource) -> AidDiagnosticsV1 {
        self.diagnostics_sequence += 1;
        AidDiagnosticsV1 {
            host_time_ns: t_ns,
            sequence: self.diagnostics_sequence,
            source: source as u32,
            ..Default::default()
        }
    }

    /// Copies an update's innovation into the diagnostics (as observation minus prediction) and
    /// applies the correction when it was fused; returns whether it was.
    fn finish_update<const M: usize>(
        &mut self,
        result: Result<(StateVector, filter::UpdateReport<M>), filter::FilterError>,
        d: &mut AidDiagnosticsV1,
    ) -> bool {
        match result {
            Ok((dx, rep)) => {
                for i in 0..M.min(3) {
                    d.innovation[i] = -rep.innovation[i];
                    d.innovation_variance[i] = rep.innovation_variance[i];
                }
                d.test_ratio = rep.test_ratio;
                if rep.fused {
                    self.correct(&dx);
                    d.flags = AidDiagnosticsV1::FLAG_FUSED;
                } else {
                    d.flags = AidDiagnosticsV1::FLAG_REJECTED;
                }
                rep.fused
            }
            Err(_) => {
                d.flags = AidDiagnosticsV1::FLAG_REJECTED;
                false
            }
        }
    }

    /// Fuses a DVL velocity: `h(x) = s C_b^d (C_n^b v^n + omega_eb^b x l)` minus the time-offset
    /// term (see [`dvl_model`]).
    pub fn on_dvl(&mut self, m: &DvlVelocityV1) -> AidDiagnosticsV1 {
        let t_ns = m.validity_time_ns;
        let mut d = self.diagnostics(t_ns, AidSource::DvlVelocity);
        d.dimension = 3;
        let z = Vector3::from(m.velocity_dvl_m_s);
        if m.validity & DvlVelocityV1::VALID_VELOCITY == 0
            || !z.iter().all(|x| x.is_finite())
            || z.norm() > 20.0
        {
            self.counters.dvl_invalid += 1;
            d.flags = AidDiagnosticsV1::FLAG_REJECTED;
            return d;
        }
        if self.aid_is_late(t_ns) {
            d.flags = AidDiagnosticsV1::FLAG_REJECTED;
            return d;
        }
        self.propagate_covariance();
        let (predicted, h) = dvl_model(
            &self.sd.state,
            &self.last_omega_ib,
            &self.last_f_body,
            &self.dvl,
        );
        let y = predicted - z;
        let sigma = if m.validity & DvlVelocityV1::VALID_STD != 0 {
            Vector3::from(m.velocity_std_m_s).map(|x| x.max(1e-3))
        } else {
            Vector3::repeat(self.cfg.dvl_velocity_std_m_s)
        };
        let r = Matrix3::from_diagonal(&sigma.map(|x| x * x));
        d.observation = z.into();
        d.observation_variance = r.diagonal().into();
        let t = t_ns as f64 * 1e-9;
        let mut result = self.kf.update(&y, &h, &r, self.cfg.dvl_gate_chi2);
        let rejected = matches!(result, Ok((_, ref rep)) if !rep.fused);
        let since = *self.dvl_rejected_since_s.get_or_insert(t);
        if rejected && self.cfg.dvl_reset_after_s > 0.0 && t - since >= self.cfg.dvl_reset_after_s {
            self.reopen_velocity(&(self.sd.state.c_body_to_ned() * y));
            self.counters.dvl_resets += 1;
            d.flags |= AidDiagnosticsV1::FLAG_RESET;
            let (predicted, h) = dvl_model(
                &self.sd.state,
                &self.last_omega_ib,
                &self.last_f_body,
                &self.dvl,
            );
            result = self.kf.update(&(predicted - z), &h, &r, f64::INFINITY);
        }
        let reset = d.flags & AidDiagnosticsV1::FLAG_RESET;
        if self.finish_update(result, &mut d) {
            self.counters.dvl_fused += 1;
            self.last_dvl_fused_s = t;
            self.dvl_rejected_since_s = None;
        } else {
            self.counters.dvl_rejected += 1;
        }
        d.flags |= reset;
        d
    }

    /// Drops the velocity states' cross-covariances and adds `innovation_ned` squared to their
    /// variances, so the next velocity measurement is believed again.
    fn reopen_velocity(&mut self, innovation_ned: &Vector3<f64>) {
        let p = &mut self.kf.p;
        for i in 0..3 {
            let v = filter::VEL + i;
            let keep = p[(v, v)] + innovation_ned[i].powi(2);
            for j in 0..filter::N {
                p[(v, j)] = 0.0;
                p[(j, v)] = 0.0;
            }
            p[(v, v)] = keep;
        }
    }

    /// Fuses a depth measurement: `h(x) = -height`.
    pub fn on_depth(&mut self, m: &DepthV1) -> AidDiagnosticsV1 {
        let t_ns = m.host_time_ns;
        let mut d = self.diagnostics(t_ns, AidSource::Depth);
        d.dimension = 1;
        if m.validity & DepthV1::VALID_DEPTH == 0
            || !m.depth_m.is_finite()
            || !(-10.0..=11000.0).contains(&m.depth_m)
        {
            self.counters.depth_invalid += 1;
            d.flags = AidDiagnosticsV1::FLAG_REJECTED;
            return d;
        }
        if self.aid_is_late(t_ns) {
            d.flags = AidDiagnosticsV1::FLAG_REJECTED;
            return d;
        }
        self.propagate_covariance();
        let y = SVector::<f64, 1>::new(-self.sd.state.position.height_m - m.depth_m);
        let mut h = SMatrix::<f64, 1, { filter::N }>::zeros();
        h[(0, filter::POS + 2)] = 1.0;
        let r = SMatrix::<f64, 1, 1>::new(self.cfg.depth_std_m.powi(2));
        d.observation[0] = m.depth_m;
        d.observation_variance[0] = r[(0, 0)];
        let result = self.kf.update(&y, &h, &r, self.cfg.depth_gate_chi2);
        if self.finish_update(result, &mut d) {
            self.counters.depth_fused += 1;
        } else {
            self.counters.depth_rejected += 1;
        }
        d
    }

    /// Fuses a GNSS position: `h(x) = p + C_b^n l` (antenna lever arm `l`), compared in local NED
    /// metres around the fix.
    pub fn on_gnss(&mut self, m: &GnssFixV1) -> AidDiagnosticsV1 {
        let t_ns = m.host_time_ns;
        let mut d = self.diagnostics(t_ns, AidSource::GnssPosition);
        d.dimension = 3;
        let need = GnssFixV1::VALID_POSITION | GnssFixV1::VALID_HEIGHT;
        let fix = Geodetic {
            latitude_rad: m.latitude_rad,
            longitude_rad: m.longitude_rad,
            height_m: m.height_m,
        };
        if m.validity & need != need
            || !(m.latitude_rad.abs() <= std::f64::consts::FRAC_PI_2
                && m.longitude_rad.abs() <= std::f64::consts::PI
                && (-1000.0..=10000.0).contains(&m.height_m)
                && (0.0..=1000.0).contains(&m.horizontal_std_m)
                && (0.0..=1000.0).contains(&m.vertical_std_m))
        {
            self.counters.gnss_invalid += 1;
            d.flags = AidDiagnosticsV1::FLAG_REJECTED;
            return d;
        }
        if self.aid_is_late(t_ns) {
            d.flags = AidDiagnosticsV1::FLAG_REJECTED;
            return d;
        }
        self.propagate_covariance();
        let (y, h) = gnss_model(
            &self.sd.state,
            &Vector3::from(self.cfg.gnss_lever_arm_m),
            &fix,
        );
        let sh = m.horizontal_std_m.max(self.cfg.gnss_min_std_m);
        let sv = m.vertical_std_m.max(self.cfg.gnss_min_std_m);
        let r = Matrix3::from_diagonal(&Vector3::new(sh * sh, sh * sh, sv * sv));
        d.observation = [m.latitude_rad, m.longitude_rad, m.height_m];
        d.observation_variance = r.diagonal().into();
        let result = self.kf.update(&y, &h, &r, self.cfg.gnss_gate_chi2);
        if self.finish_update(result, &mut d) {
            self.counters.gnss_fused += 1;
        } else {
            self.counters.gnss_rejected += 1;
        }
        d
    }

    /// Fuses a zero-velocity observation (the vehicle is known to be still, for example moored
    /// alongside or sitting on the seabed): `h(x) = v^n`. The caller decides when this holds;
    /// the IMU alone cannot tell rest from uniform motion.
    pub fn on_zero_velocity(&mut self, t_ns: u64) -> AidDiagnosticsV1 {
        let mut d = self.diagnostics(t_ns, AidSource::ZeroVelocity);
        d.dimension = 3;
        if self.aid_is_late(t_ns) {
            d.flags = AidDiagnosticsV1::FLAG_REJECTED;
            return d;
        }
        self.propagate_covariance();
        let y = self.sd.state.velocity_ned;
        let mut h = SMatrix::<f64, 3, { filter::N }>::zeros();
        h.fixed_view_mut::<3, 3>(0, filter::VEL)
            .copy_from(&Matrix3::identity());
        let r = Matrix3::identity() * self.cfg.zero_velocity_std_m_s.powi(2);
        d.observation_variance = r.diagonal().into();
        let result = self.kf.update(&y, &h, &r, self.cfg.dvl_gate_chi2);
        if self.finish_update(result, &mut d) {
            self.counters.zero_velocity_fused += 1;
        } else {
            self.counters.zero_velocity_rejected += 1;
        }
        d
    }

    /// Fuses a USBL fix from the docking station by the configured coupling and filter (S-USBL).
    ///
    /// Tight: `z = [R, ΔR13, ΔR24]`, predicted from the state by the exact array geometry plus
    /// the Gauss–Markov error states; loose: the fix as a position, in line-of-sight coordinates.
    /// The update runs over every state with non-zero variance (unscented for ukf/aukf,
    /// linearised for akf); the innovation passes the gate of the noise estimator before anything
    /// is changed, so a rejected fix moves neither the state nor the noise estimate.
    pub fn on_usbl(&mut self, m: &UsblFixV1) -> AidDiagnosticsV1 {
        let t_ns = m.validity_time_ns;
        let source = match self.usbl.as_ref().map(|u| u.cfg.coupling) {
            Some(Coupling::Loose) => AidSource::UsblPosition,
            _ => AidSource::UsblSlantRange,
        };
        let mut d = self.diagnostics(t_ns, source);
        d.dimension = 3;
        d.flags = AidDiagnosticsV1::FLAG_REJECTED;
        let Some(u) = self.usbl.as_ref() else {
            self.counters.usbl_unconfigured += 1;
            return d;
        };
        let meas = match usbl::measurement(&u.cfg, &u.array, m) {
            Ok(x) => x,
            Err(_) => {
                self.counters.usbl_invalid += 1;
                return d;
            }
        };
        let t_valid = t_ns as f64 * 1e-9;
        if self.sd.state.time_s - t_valid > u.cfg.max_latency_s {
            self.counters.aid_late += 1;
            return d;
        }
        self.propagate_covariance();
        let Some(u) = self.usbl.as_mut() else {
            return d;
        };
        // The geometry at the fix's time of validity; the errors are those of now.
        let s = &self.sd.state;
        let (position, attitude) = if t_valid < s.time_s {
            u.pose_at(t_valid).unwrap_or((s.position, s.q_body_to_ned))
        } else {
            (s.position, s.q_body_to_ned)
        };
        let geometry = ResponderGeometry::new(
            &u.array,
            &position,
            &attitude.to_rotation_matrix().into_inner(),
            &u.lever_arm_b,
        );
        let noise = u.noise.get_or_insert_with(|| {
            let r0 = meas.r.diagonal();
            let scale = r0.max();
            let mut n = AdaptiveNoise::new(
                DVector::from_column_slice(r0.as_slice()),
                u.cfg.fading,
                (0.1f64 * 0.1) * r0.min(),
                1.0e4 * scale,
                u.cfg.gate_chi2,
            );
            n.reopen_after = u.cfg.reopen_after;
            n.learn = u.cfg.filter != UsblFilter::Ukf;
            n
        });
        // The states the update runs over: every one with non-zero variance.
        let active: Vec<usize> = (0..filter::N)
            .filter(|&i| self.kf.p[(i, i)] > 0.0)
            .collect();
        let slot = |state: usize| active.iter().position(|&i| i == state);
        let pos = [0, 1, 2].map(|i| slot(filter::POS + i));
        let att = [0, 1, 2].map(|i| slot(filter::ATT + i));
        let err = [0, 1, 2].map(|i| slot(filter::USBL + i));
        let pick = |dx: &DVector<f64>, idx: &[Option<usize>; 3]| {
            Vector3::from(idx.map(|k| k.map_or(0.0, |k| dx[k])))
        };
        let coupling = u.cfg.coupling;
        let errors = u.errors;
        let array = u.array;
        // Loose: array frame → line-of-sight coordinates of this fix.
        let to_los = meas.frame * u.array.c_ned_to_array.transpose();
        let h = move |dx: &DVector<f64>| -> DVector<f64> {
            let p_a = geometry.responder_given_error(&pick(dx, &pos), &pick(dx, &att));
            let z = match coupling {
                Coupling::Tight => usbl::predict_tight(&array, &p_a) + errors - pick(dx, &err),
                Coupling::Loose => to_los * p_a,
            };
            DVector::from_column_slice(z.as_slice())
        };
        let p: DMatrix<f64> = DMatrix::from_fn(active.len(), active.len(), |i, j| {
            self.kf.p[(active[i], active[j])]
        });
        let z = DVector::from_column_slice(meas.z.as_slice());
        let unscented = u.cfg.unscented();
        let kind = u.cfg.filter;
        let update = |r: &DMatrix<f64>| match kind {
            UsblFilter::Akf => usbl::linearized_update(&p, &z, r, &h),
            UsblFilter::Ukf | UsblFilter::Aukf => usbl::unscented_update(&p, &z, r, &h, unscented),
        };
        // Fixed noise (ukf): this fix's configured noise (diagonal in the measurement's
        // coordinates); adaptive: the estimator's.
        if kind == UsblFilter::Ukf {
            noise.set_variances(&DVector::from_column_slice(meas.r.diagonal().as_slice()));
        }
        let r_used = noise.covariance();
        let Some(mut upd) = update(&r_used) else {
            self.counters.usbl_failed += 1;
            return d;
        };
        let hph = &upd.innovation_cov - &r_used;
        let reopened = noise.reopened;
        let accepted = noise.observe(&upd.innovation, &hph);
        if noise.reopened != reopened {
            self.counters.usbl_reopened += 1;
            d.flags |= AidDiagnosticsV1::FLAG_RESET;
            let r = noise.covariance();
            match update(&r) {
                Some(x) => upd = x,
                None => {
                    self.counters.usbl_failed += 1;
                    return d;
                }
            }
        }
        for i in 0..3 {
            d.observation[i] = meas.z[i];
            d.innovation[i] = upd.innovation[i];
            d.innovation_variance[i] = upd.innovation_cov[(i, i)];
            d.observation_variance[i] = noise.variances()[i];
        }
        let s_inv = upd.innovation_cov.clone().try_inverse();
        d.test_ratio = s_inv.map_or(f64::INFINITY, |si| {
            (upd.innovation.transpose() * si * &upd.innovation)[(0, 0)] / GATE_CHI2_3DOF
        });
        if !accepted {
            self.counters.usbl_rejected += 1;
            return d;
        }
        if (0..upd.p.nrows()).any(|i| !(upd.p[(i, i)].is_finite() && upd.p[(i, i)] >= 0.0)) {
            self.counters.usbl_failed += 1;
            return d;
        }
        let mut dx = StateVector::zeros();
        for (a, &i) in active.iter().enumerate() {
            dx[i] = upd.dx[a];
            for (b, &j) in active.iter().enumerate() {
                self.kf.p[(i, j)] = upd.p[(a, b)];
            }
        }
        u.last_fused_s = Some(t_valid);
        self.correct(&dx);
        self.counters.usbl_fused += 1;
        d.flags = AidDiagnosticsV1::FLAG_FUSED | (d.flags & AidDiagnosticsV1::FLAG_RESET);
        d
    }

    /// The estimated USBL measurement errors [δR, δΔR13, δΔR24] (m) and the noise variances in
    /// use, when USBL fusion is configured and has seen a fix.
    pub fn usbl_estimates(&self) -> Option<(Vector3<f64>, Vector3<f64>)> {
        let u = self.usbl.as_ref()?;
        let v = u.noise.as_ref()?.variances();
        Some((u.errors, Vector3::new(v[0], v[1], v[2])))
    }

    /// The navigation solution now.
    pub fn solution(&mut self, t_ns: u64) -> NavSolutionV1 {
        self.solution_sequence += 1;
        let s = &self.sd.state;
        let q = s.q_body_to_ned;
        let p = &self.kf.p;
        let std = |i: usize| {
            [
                p[(i, i)].sqrt(),
                p[(i + 1, i + 1)].sqrt(),
                p[(i + 2, i + 2)].sqrt(),
            ]
        };
        let dvl_ok = s.time_s - self.last_dvl_fused_s <= self.cfg.dvl_timeout_s;
        let mut health = NavSolutionV1::HEALTH_IMU;
        if dvl_ok {
            health |= NavSolutionV1::HEALTH_DVL;
        }
        let usbl_fused_s = self.usbl.as_ref().and_then(|u| u.last_fused_s);
        if usbl_fused_s.is_some_and(|t| s.time_s - t <= self.cfg.dvl_timeout_s) {
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
            position_std_ned_m: std(filter::POS),
            velocity_std_ned_m_s: std(filter::VEL),
            attitude_std_rad: std(filter::ATT),
            gyro_bias_rad_s: self.gyro_bias.into(),
            accel_bias_m_s2: self.accel_bias.into(),
            mode: if dvl_ok {
                NavMode::Navigating
            } else {
                NavMode::Degraded
            } as u32,
            sensor_health: health,
        }
    }
}

/// The DVL installation: mounting, scale factor, lever arm and time offset.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DvlParameters {
    /// Rotation DVL frame -> body frame.
    pub c_dvl_to_body: Matrix3<f64>,
    /// Scale factor (1 = none).
    pub scale: f64,
    /// DVL position in the body frame (m).
    pub lever_arm_m: Vector3<f64>,
    /// The velocity stamped at t is the vehicle's at t - offset (s).
    pub time_offset_s: f64,
}

/// The DVL measurement model: predicted velocity in the DVL frame,
/// `h = s C_b^d (v_b + omega_eb^b x l) - tau s C_b^d a_b` with `v_b = C_n^b v^n` and
/// `a_b = d v_b / dt = f_b + C_n^b g^n - omega_eb^b x v_b` (so the measurement stamped at t is the
/// velocity at t - tau to first order), and its Jacobian w.r.t. the error state:
/// `dh/d dv = s C_b^d (I + tau [omega_eb x]) C_n^b`,
/// `dh/d phi = -(dh/d dv) [v x] + tau s C_b^d C_n^b [g x]`, `dh/d dm = [h x]` (mounting),
/// `dh/d ds = h / s`, `dh/d dl = s C_b^d [omega_eb x]`, `dh/d dtau = -s C_b^d a_b`. Neglected: the
/// Earth-rate part of `omega_eb` through the attitude (below 1e-4 of the lever-arm term) and the
/// dependence on the bias errors (second order).
/// `omega_ib_body` and `f_body` are the bias-corrected IMU outputs.
pub fn dvl_model(
    s: &NavState,
    omega_ib_body: &Vector3<f64>,
    f_body: &Vector3<f64>,
    p: &DvlParameters,
) -> (Vector3<f64>, SMatrix<f64, 3, { filter::N }>) {
    let c_nb = s.c_body_to_ned().transpose();
    let c_bd = p.c_dvl_to_body.transpose();
    let lat = s.position.latitude_rad;
    let w_ie_b = c_nb * earth::earth_rate_ned(lat);
    let w_eb = omega_ib_body - w_ie_b;
    let v_b = c_nb * s.velocity_ned;
    let a_b = f_body + c_nb * earth::gravity_ned(lat, s.position.height_m) - w_eb.cross(&v_b);
    let unscaled = c_bd * (v_b + w_eb.cross(&p.lever_arm_m) - p.time_offset_s * a_b);
    let predicted = p.scale * unscaled;
    let mut h = SMatrix::<f64, 3, { filter::N }>::zeros();
    // v_b and a_b through the velocity and the attitude: C_n^b(est) = C_n^b (I + [phi x]).
    let through_v = p.scale * c_bd * (Matrix3::identity() + p.time_offset_s * skew(&w_eb)) * c_nb;
    h.fixed_view_mut::<3, 3>(0, filter::VEL)
        .copy_from(&through_v);
    let g_n = earth::gravity_ned(lat, s.position.height_m);
    h.fixed_view_mut::<3, 3>(0, filter::ATT).copy_from(
        &(-through_v * skew(&s.velocity_ned)
            + p.scale * p.time_offset_s * c_bd * c_nb * skew(&g_n)),
    );
    h.fixed_view_mut::<3, 3>(0, filter::DVL_MOUNT)
        .copy_from(&skew(&predicted));
    h.fixed_view_mut::<3, 1>(0, filter::DVL_SCALE)
        .copy_from(&unscaled);
    h.fixed_view_mut::<3, 3>(0, filter::DVL_LEVER)
        .copy_from(&(p.scale * c_bd * skew(&w_eb)));
    h.fixed_view_mut::<3, 1>(0, filter::DVL_TIME)
        .copy_from(&(-p.scale * c_bd * a_b));
    (predicted, h)
}

/// The GNSS position model: the innovation `y = (p + C_b^n l) - fix` in NED metres and its
/// Jacobian (`dy/d dp = I`, `dy/d phi = [(C_b^n l) x]`).
pub fn gnss_model(
    s: &NavState,
    lever_arm_body: &Vector3<f64>,
    fix: &Geodetic,
) -> (Vector3<f64>, SMatrix<f64, 3, { filter::N }>) {
    let arm_ned = s.c_body_to_ned() * lever_arm_body;
    let y = earth::ned_offset(fix, &s.position) + arm_ned;
    let mut h = SMatrix::<f64, 3, { filter::N }>::zeros();
    h.fixed_view_mut::<3, 3>(0, filter::POS)
        .copy_from(&Matrix3::identity());
    h.fixed_view_mut::<3, 3>(0, filter::ATT)
        .copy_from(&skew(&arm_ned));
    (y, h)
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
