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
use crate::aid::dvl::{DvlAid, DvlEstimation, DvlParameters};
use crate::aid::gnss::GnssAid;
use crate::aid::magnetometer::MagnetometerAid;
use crate::aid::usbl::UsblAid;
use crate::aid::zero_velocity::ZeroVelocityAid;
pub use crate::config::NavConfig;
use crate::ekf::{self, ProcessNoise, StateVector};
use crate::nav_core::{ImuTiming, NavCore};
use crate::strapdown::NavState;
use auvnav_shm_schema::{
    AidDiagnosticsV1, DepthV1, DvlVelocityV1, GnssFixV1, ImuSampleV1, MagnetometerV1, NavMode,
    NavSolutionV1, UsblFixV1,
};
use nalgebra::Vector3;
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
    pub magnetometer_fused: u64,
    /// Magnetic headings rejected by the innovation gate.
    pub magnetometer_rejected: u64,
    /// Magnetometer readings flagged invalid, not finite, or without a local field.
    pub magnetometer_invalid: u64,
    /// Readings whose calibrated magnitude is far from the field model (a disturbed
    /// environment or a calibration that does not hold): not fused.
    pub magnetometer_disturbed: u64,
    /// Readings received without a `[navigation.magnetometer]` configuration.
    pub magnetometer_unconfigured: u64,
    /// Aiding messages older than the navigation state (skipped).
    pub aid_late: u64,
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
    magnetometer: Option<MagnetometerAid>,
    magnetometer_unconfigured: u64,
    dvl_timeout_s: f64,
    solution_sequence: u64,
}

impl Navigator {
    /// The variances of the core states (position, velocity, attitude, IMU biases) that `cfg`
    /// starts with; parameter states are zero (off) until an aid switches them on.
    fn initial_variances(cfg: &NavConfig) -> StateVector {
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
        p0
    }

    /// The IMU's process noise of `cfg`, in SI units.
    fn process_noise(cfg: &NavConfig) -> ProcessNoise {
        ProcessNoise {
            gyro_noise: cfg.gyro_angle_random_walk_deg_sqrt_h * DEG / 60.0,
            accel_noise: cfg.accel_velocity_random_walk_m_s_sqrt_h / 60.0,
            gyro_bias_walk: cfg.gyro_bias_walk_deg_h_sqrt_h * DEG / 3600.0 / 60.0,
            accel_bias_walk: cfg.accel_bias_walk_ug_sqrt_h * UG / 60.0,
        }
    }

    /// Starts navigating from a known initial state (alignment is a separate mode).
    pub fn new(cfg: NavConfig, initial: NavState) -> Navigator {
        let mut p0 = Self::initial_variances(&cfg);
        let on = |flag: bool, std: f64| flag.then_some(std);
        DvlAid::initial_variances(
            &mut p0,
            &DvlEstimation {
                mounting_std_deg: on(cfg.estimate_dvl_mounting, cfg.initial_dvl_mounting_std_deg),
                scale_std: on(cfg.estimate_dvl_scale, cfg.initial_dvl_scale_std),
                lever_arm_std_m: on(cfg.estimate_dvl_lever_arm, cfg.initial_dvl_lever_arm_std_m),
                time_offset_std_s: on(
                    cfg.estimate_dvl_time_offset,
                    cfg.initial_dvl_time_offset_std_s,
                ),
            },
        );
        let timing = ImuTiming {
            covariance_interval_s: cfg.covariance_interval_s,
            imu_max_gap_intervals: cfg.imu_max_gap_intervals,
            imu_dt_from_device_time: cfg.imu_dt_from_device_time,
        };
        let mut core = NavCore::new(initial, &p0, Self::process_noise(&cfg), timing);
        let usbl = UsblAid::new(cfg.usbl.as_ref(), &mut core.kf);
        let d = cfg.dvl_installation();
        let dvl = DvlParameters::new(d.mount_deg, d.scale_factor, d.lever_arm_m, d.time_offset_s);
        Navigator {
            dvl: DvlAid::new(
                dvl,
                cfg.dvl_velocity_std_m_s,
                cfg.dvl_gate_chi2,
                cfg.dvl_reset_after_s,
                initial.time_s,
            ),
            depth: DepthAid::new(cfg.depth_std_m, cfg.depth_gate_chi2),
            gnss: GnssAid::new(cfg.gnss_lever_arm_m, cfg.gnss_min_std_m, cfg.gnss_gate_chi2),
            zero_velocity: ZeroVelocityAid::new(
                cfg.zero_velocity_std_m_s,
                cfg.zero_velocity_gate_chi2,
            ),
            usbl,
            magnetometer: cfg.magnetometer.as_ref().map(MagnetometerAid::new),
            magnetometer_unconfigured: 0,
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

    /// Fuses a magnetometer reading as a magnetic heading (`crate::aid::magnetometer`); `None`
    /// (counted) without a `[navigation.magnetometer]` configuration.
    pub fn on_magnetometer(&mut self, m: &MagnetometerV1) -> Option<AidDiagnosticsV1> {
        let Some(aid) = self.magnetometer.as_mut() else {
            self.magnetometer_unconfigured += 1;
            return None;
        };
        let u = aid.fuse(&mut self.core, m);
        Some(self.apply(u))
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
        let mag = self
            .magnetometer
            .as_ref()
            .map(|m| m.counters)
            .unwrap_or_default();
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
            magnetometer_fused: mag.common.fused,
            magnetometer_rejected: mag.common.rejected,
            magnetometer_invalid: mag.common.invalid,
            magnetometer_disturbed: mag.disturbed,
            magnetometer_unconfigured: self.magnetometer_unconfigured,
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
        let mag_fused_ns = self.magnetometer.as_ref().and_then(|m| m.last_fused_ns());
        if mag_fused_ns.is_some_and(|t| s.time_s - t as f64 * 1e-9 <= self.dvl_timeout_s) {
            health |= NavSolutionV1::HEALTH_MAGNETOMETER;
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

/// The initial state from a geodetic position, NED velocity and Euler angles (in `strapdown`).
pub use crate::strapdown::initial_state;
