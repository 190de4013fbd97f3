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
//!
//! Long on purpose: the navigator's state and feed (IMU propagation, covariance scheduling, the aid
//! list and each aid's correction) work on one filter and are read as one; the aids' models are in
//! `aid/`.

use crate::aid::AidUpdate;
use crate::aid::depth::DepthAid;
use crate::aid::dvl::{DvlAid, DvlEstimation, DvlParameters, SoundSpeed};
use crate::aid::gnss::GnssAid;
use crate::aid::magnetometer::MagnetometerAid;
use crate::aid::ranges::RangeAid;
use crate::aid::usbl::UsblAid;
use crate::aid::zero_velocity::ZeroVelocityAid;
pub use crate::config::NavConfig;
use crate::config::SoundSpeedSource;
use crate::ekf::{self, ProcessNoise, StateVector};
use crate::nav_core::{ImuTiming, NavCore};
use crate::strapdown::NavState;
use auvnav_shm_schema::{
    AcousticArrayPoseV1, AcousticRangesV1, AidDiagnosticsV1, DepthV1, DvlVelocityV1, GnssFixV1,
    ImuSampleV1, MagnetometerV1, NavMode, NavSolutionV1, SoundVelocityV1, UsblFixV1,
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
    /// IMU samples flagged invalid, or with values not finite or beyond the plausible range
    /// (skipped).
    pub imu_invalid: u64,
    /// IMU gaps longer than the allowed number of intervals (integrated over their length, the
    /// covariance grown by the motion nobody measured).
    pub imu_gaps: u64,
    /// IMU samples whose device-time step jumped ahead of the host's or stalled (integrated
    /// over the host's step).
    pub imu_clock_jumps: u64,
    pub dvl_fused: u64,
    pub dvl_rejected: u64,
    pub dvl_invalid: u64,
    /// Velocity covariance re-opened after a run of DVL rejections (see `dvl_reset_after_s`).
    pub dvl_resets: u64,
    /// DVL velocities corrected for the sound speed (`dvl_sound_speed_source`).
    pub dvl_sound_speed_corrected: u64,
    /// DVL water-track velocities fused, rejected by the gate and invalid (with the
    /// water-current states, `water_current_std_m_s`), and received without them (not fused).
    pub dvl_water_track_fused: u64,
    pub dvl_water_track_rejected: u64,
    pub dvl_water_track_invalid: u64,
    pub dvl_water_track_unused: u64,
    /// DVL bottom lock lost (a valid bottom-track reading followed by an invalid one) and
    /// regained.
    pub dvl_bottom_lock_lost: u64,
    pub dvl_bottom_lock_regained: u64,
    /// DVL readings without an instrument velocity fused from their beams (`dvl_beam_fusion`),
    /// and beams refused by their own gate.
    pub dvl_beam_readings_fused: u64,
    pub dvl_beams_rejected: u64,
    /// DVL readings whose velocity was solved again from their four beams with the configured
    /// per-beam corrections.
    pub dvl_beam_corrected: u64,
    /// Sound-velocity readings that set the DVL's sound-speed correction
    /// (`dvl_sound_speed_source = "topic"`), and readings ignored (another source configured, or
    /// out of 1375..1650 m/s).
    pub sound_velocity_used: u64,
    pub sound_velocity_ignored: u64,
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
    /// Acoustic ranges (one per receiver) fused, rejected by the gate, and invalid (out of
    /// range, or from a receiver the configuration does not place).
    pub ranges_fused: u64,
    pub ranges_rejected: u64,
    pub ranges_invalid: u64,
    /// Range messages received without a `[navigation.ranges]` configuration, and older than
    /// its `max_latency_s`.
    pub ranges_unconfigured: u64,
    pub ranges_late: u64,
    /// Times the range aid reopened the position after a run of rejections.
    pub ranges_reopened: u64,
    /// Ranges of a moving array without its pose at the time.
    pub ranges_without_array_pose: u64,
    /// Array poses taken, and refused (invalid, or the array is configured fixed).
    pub array_poses: u64,
    pub array_poses_invalid: u64,
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
    pub(crate) ranges: RangeAid,
    magnetometer: Option<MagnetometerAid>,
    magnetometer_unconfigured: u64,
    dvl_timeout_s: f64,
    /// `dvl_sound_speed_source = "topic"`: the sound speed the DVL assumed when it reports none.
    sound_speed_topic: Option<f64>,
    sound_velocity_used: u64,
    sound_velocity_ignored: u64,
    position_unknown_std_m: f64,
    solution_sequence: u64,
    /// The covariance was updated (an aid, a reopening, a coast, a restore) since the last
    /// soundness check: the whole matrix is examined.
    covariance_changed: bool,
    /// The covariance was propagated since the last check: its variances are examined (a
    /// propagation turns a sound covariance into a sound one; the correlations are examined
    /// at the next update, before its correction is used).
    covariance_propagated: bool,
}

/// The DVL sound-speed correction a configuration asks for (`dvl_sound_speed_source`), or
/// `None`.
pub fn sound_speed_correction(cfg: &NavConfig) -> Option<SoundSpeed> {
    match cfg.dvl_sound_speed_source {
        SoundSpeedSource::Value => Some(SoundSpeed {
            true_m_s: cfg.sound_speed_m_s,
            assumed_default_m_s: cfg.dvl_assumed_sound_speed_m_s,
        }),
        // From the topic: set by each reading (`Navigator::on_sound_velocity`).
        SoundSpeedSource::None | SoundSpeedSource::Dvl | SoundSpeedSource::Topic => None,
    }
}

/// The covariance of a checkpoint: this build's states, or the 28 of the builds that had three
/// acoustic error slots (written before this build: its two water-current states move after the
/// two new slots, which start switched off); `None` for any other size.
fn checkpoint_covariance(v: &[f64]) -> Option<ekf::Covariance> {
    const OLD_N: usize = 28;
    const OLD_CURRENT: usize = 26;
    if v.len() == ekf::N * ekf::N {
        return Some(ekf::Covariance::from_iterator(v.iter().copied()));
    }
    if v.len() != OLD_N * OLD_N {
        return None;
    }
    let to_new = |i: usize| {
        if i < OLD_CURRENT {
            i
        } else {
            i + ekf::CURRENT - OLD_CURRENT
        }
    };
    let mut p = ekf::Covariance::zeros();
    for j in 0..OLD_N {
        for i in 0..OLD_N {
            p[(to_new(i), to_new(j))] = v[i + OLD_N * j];
        }
    }
    Some(p)
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
        fn on<T>(flag: bool, std: T) -> Option<T> {
            flag.then_some(std)
        }
        DvlAid::initial_variances(
            &mut p0,
            &DvlEstimation {
                mounting_std_deg: on(cfg.estimate_dvl_mounting, cfg.dvl_mounting_std_deg()),
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
            clock_tolerance_s: cfg.imu_clock_tolerance_s,
            max_rate_rad_s: cfg.imu_max_rate_deg_s * DEG,
            max_specific_force_m_s2: cfg.imu_max_specific_force_m_s2,
            gap_accel_std_m_s2: cfg.imu_gap_accel_std_m_s2,
            gap_rate_std_rad_s: cfg.imu_gap_rate_std_deg_s * DEG,
        };
        let mut core = NavCore::new(initial, &p0, Self::process_noise(&cfg), timing);
        let usbl = UsblAid::new(cfg.usbl.as_ref(), &mut core.kf);
        let ranges = RangeAid::new(cfg.ranges.as_ref(), &mut core.kf);
        let d = cfg.dvl_installation();
        let dvl = DvlParameters::new(d.mount_deg, d.scale_factor, d.lever_arm_m, d.time_offset_s);
        let mut dvl = DvlAid::new(
            dvl,
            cfg.dvl_velocity_std_m_s,
            cfg.dvl_gate_chi2,
            cfg.dvl_reset_after_s,
            initial.time_s,
        );
        dvl.retimed_s = dvl_retime_s(&cfg);
        dvl.sound_speed = sound_speed_correction(&cfg);
        if cfg.water_current_std_m_s > 0.0 {
            for k in 0..2 {
                core.kf.set_gauss_markov(
                    ekf::CURRENT + k,
                    cfg.water_current_correlation_s,
                    cfg.water_current_std_m_s,
                );
            }
            dvl.water_current = true;
        }
        if d.corrects_beams() {
            dvl.beam_correction = crate::aid::dvl::BeamCorrection::new(
                cfg.dvl_beam_angle_deg,
                cfg.dvl_beam_azimuths_deg,
                d.beam_scale_factor_ppm,
                d.beam_angle_error_deg,
            );
        }
        if cfg.dvl_beam_fusion {
            dvl.beams = Some((
                crate::aid::dvl::beam_directions(cfg.dvl_beam_angle_deg, cfg.dvl_beam_azimuths_deg),
                cfg.dvl_beam_velocity_std_m_s,
            ));
        }
        Navigator {
            dvl,
            depth: DepthAid::new(
                cfg.depth_std_m,
                cfg.depth_gate_chi2,
                Vector3::from(cfg.depth_lever_arm_m),
            ),
            gnss: GnssAid::new(cfg.gnss_lever_arm_m, cfg.gnss_min_std_m, cfg.gnss_gate_chi2),
            zero_velocity: ZeroVelocityAid::new(
                cfg.zero_velocity_std_m_s,
                cfg.zero_velocity_gate_chi2,
            ),
            usbl,
            ranges,
            magnetometer: cfg.magnetometer.as_ref().map(MagnetometerAid::new),
            magnetometer_unconfigured: 0,
            core,
            dvl_timeout_s: cfg.dvl_timeout_s,
            sound_speed_topic: (cfg.dvl_sound_speed_source == SoundSpeedSource::Topic)
                .then_some(cfg.dvl_assumed_sound_speed_m_s),
            sound_velocity_used: 0,
            sound_velocity_ignored: 0,
            position_unknown_std_m: cfg.position_unknown_std_m,
            solution_sequence: 0,
            covariance_changed: true,
            covariance_propagated: false,
        }
    }

    /// Applies a fused aid's correction to the core and to the aids' parameter states.
    fn apply(&mut self, u: AidUpdate) -> AidDiagnosticsV1 {
        // Even a rejected update may have propagated the covariance.
        self.covariance_changed = true;
        if let Some(dx) = &u.correction {
            self.core.correct(dx);
            self.dvl.correct(dx);
            self.ranges.correct(dx);
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

    /// True when the state and the covariance are finite and the covariance is one
    /// ([`NavCore::is_sound`]).
    pub fn is_sound(&self) -> bool {
        self.core.is_sound()
    }

    /// False when `sol` (this navigator's latest solution) holds a value that is not finite, or
    /// the state or covariance is not sound; the solution is examined always, the whole
    /// covariance when an aid (or a reopening, a coast) changed it since the last call, and the
    /// state and the variances when it was only propagated (at the propagation interval).
    pub fn still_sound(&mut self, sol: &NavSolutionV1) -> bool {
        let finite = sol.all_finite();
        if !finite {
            return false;
        }
        let propagated = std::mem::take(&mut self.covariance_propagated);
        if std::mem::take(&mut self.covariance_changed) {
            self.core.is_sound()
        } else if propagated {
            self.core.variances_are_sound()
        } else {
            true
        }
    }

    /// Moves the navigator over `dt_s` seconds that it did not see (the time since the state it
    /// was restored from, or a restart): the position coasts with the velocity, the covariance
    /// grows by the unknown motion (as over an IMU gap), and the IMU sample `m` starts the
    /// integration again.
    pub fn coast(&mut self, dt_s: f64, m: &ImuSampleV1) {
        let dt = dt_s.max(0.0);
        let c = &mut self.core;
        c.propagate_covariance();
        if dt > 0.0 {
            let s = &mut c.sd.state;
            s.position = crate::earth::offset_position(&s.position, &(s.velocity_ned * dt));
            c.grow_for_unobserved_motion(dt);
        }
        c.sd.state.time_s = m.host_time_ns as f64 * 1e-9;
        self.covariance_changed = true;
        self.start_at_imu(m);
    }

    /// Adds to the position (m²) and velocity ((m/s)²) variances: what the vehicle may have done
    /// while nobody watched.
    pub fn grow_variances(&mut self, position_m2: f64, velocity_m2_s2: f64) {
        self.core.add_variances(position_m2, velocity_m2_s2, 0.0);
        self.covariance_changed = true;
    }

    /// Starts (or restarts, dropping what it held) the trace of covariance epochs and corrections
    /// a smoother records (`crate::ekf::trace`).
    pub(crate) fn start_trace(&mut self) {
        self.core.trace = Some(ekf::trace::Trace::default());
    }

    /// The trace events since the last call.
    pub(crate) fn take_trace(&mut self) -> Vec<ekf::trace::TraceEvent> {
        self.core
            .trace
            .as_mut()
            .map(|t| std::mem::take(&mut t.events))
            .unwrap_or_default()
    }

    /// The time of the state (ns).
    pub(crate) fn state_time_ns(&self) -> u64 {
        self.core.state_time_ns()
    }

    /// The nominal values of the parameter states (for the smoother's report).
    pub(crate) fn nominal_parameters(&self) -> crate::smoother::NominalParameters {
        crate::smoother::NominalParameters {
            time_ns: self.state_time_ns(),
            dvl: self.dvl.params,
            markov_means: self.core.markov_means.into(),
        }
    }

    #[doc(hidden)]
    pub fn poison_covariance_for_tests(&mut self) {
        self.core.kf.p[(ekf::POS, ekf::VEL)] = f64::NAN;
        self.covariance_changed = true;
    }

    /// The sequence number of the last solution made.
    pub fn last_sequence(&self) -> u64 {
        self.solution_sequence
    }

    /// Numbers the next solutions after `last` (a navigator replacing another).
    pub fn continue_numbering(&mut self, last: u64) {
        self.solution_sequence = last;
    }

    /// What a restart needs to continue from this navigator ([`Checkpoint`]).
    pub fn checkpoint(&self) -> Checkpoint {
        let s = &self.core.sd.state;
        let q = s.q_body_to_ned;
        let d = &self.dvl.params;
        Checkpoint {
            format_version: 1,
            time_s: s.time_s,
            latitude_rad: s.position.latitude_rad,
            longitude_rad: s.position.longitude_rad,
            height_m: s.position.height_m,
            velocity_ned_m_s: s.velocity_ned.into(),
            quaternion_body_to_ned: [q.w, q.i, q.j, q.k],
            gyro_bias_rad_s: self.core.gyro_bias.into(),
            accel_bias_m_s2: self.core.accel_bias.into(),
            covariance: self.core.kf.p.iter().copied().collect(),
            dvl: crate::config::DvlInstallation {
                mount_deg: d.mount_deg(),
                scale_factor: d.scale,
                lever_arm_m: d.lever_arm_m.into(),
                time_offset_s: d.time_offset_s,
                ..Default::default()
            },
        }
    }

    /// A navigator continuing from `cp` under `cfg` (the checkpoint's covariance, biases and DVL
    /// installation; its time is the checkpoint's). `None` when the checkpoint is not sound.
    pub fn from_checkpoint(cfg: NavConfig, cp: &Checkpoint) -> Option<Navigator> {
        let p = checkpoint_covariance(&cp.covariance)?;
        let q = nalgebra::Quaternion::new(
            cp.quaternion_body_to_ned[0],
            cp.quaternion_body_to_ned[1],
            cp.quaternion_body_to_ned[2],
            cp.quaternion_body_to_ned[3],
        );
        if !(q.norm() > 0.5 && q.norm() < 2.0) {
            return None;
        }
        let state = NavState {
            time_s: cp.time_s,
            position: crate::earth::Geodetic {
                latitude_rad: cp.latitude_rad,
                longitude_rad: cp.longitude_rad,
                height_m: cp.height_m,
            },
            velocity_ned: Vector3::from(cp.velocity_ned_m_s),
            q_body_to_ned: nalgebra::UnitQuaternion::from_quaternion(q),
        };
        let mut cfg = cfg;
        let mut d = cp.dvl.clone();
        d.source = "restored from a checkpoint".into();
        // The per-beam corrections are configured, not estimated: the configuration's stand.
        let configured = cfg.dvl_installation();
        d.beam_scale_factor_ppm = configured.beam_scale_factor_ppm;
        d.beam_angle_error_deg = configured.beam_angle_error_deg;
        cfg.set_dvl_installation(d);
        let mut nav = Navigator::new(cfg, state);
        nav.core.kf.p = p;
        nav.set_imu_biases(
            Vector3::from(cp.gyro_bias_rad_s),
            Vector3::from(cp.accel_bias_m_s2),
        );
        nav.is_sound().then_some(nav)
    }

    /// Processes one IMU sample; returns the solution at its time, or `None` if it was skipped.
    pub fn on_imu(&mut self, m: &ImuSampleV1) -> Option<NavSolutionV1> {
        if !self.core.integrate(m) {
            return None;
        }
        self.usbl.after_imu(&self.core.sd.state);
        self.ranges.after_imu(&self.core.sd.state);
        if self.core.pending_dt >= self.core.covariance_interval_s {
            self.core.propagate_covariance();
            self.covariance_propagated = true;
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

    /// Fuses a docking station's fix through the range aid, when it is configured to take them
    /// (`[navigation.ranges] usbl_fixes`): the diagnostics of its slant range and of each range
    /// difference; `None` when the range aid does not take fixes (they go to
    /// [`Navigator::on_usbl`]).
    pub fn on_usbl_as_ranges(&mut self, m: &UsblFixV1) -> Option<[Option<AidDiagnosticsV1>; 3]> {
        if !self.ranges.takes_usbl_fixes() {
            return None;
        }
        let mut out = [None; 3];
        if !self.ranges.accepts_usbl_fix(&self.core, m) {
            return Some(out);
        }
        for (part, slot) in out.iter_mut().enumerate() {
            if let Some(u) = self.ranges.fuse_usbl_part(&mut self.core, m, part) {
                *slot = Some(self.apply(u));
            }
        }
        Some(out)
    }

    /// Fuses each receiver's range of an acoustic system alone (`crate::aid::ranges`): the
    /// diagnostics of each range (receiver k's in slot k), none when the message is not used
    /// (counted: unconfigured, late).
    pub fn on_acoustic_ranges(&mut self, m: &AcousticRangesV1) -> [Option<AidDiagnosticsV1>; 4] {
        let mut out = [None; 4];
        if !self.ranges.accepts(&self.core, m) {
            return out;
        }
        for (k, slot) in out.iter_mut().enumerate() {
            if let Some(u) = self.ranges.fuse_one(&mut self.core, m, k) {
                *slot = Some(self.apply(u));
            }
        }
        out
    }

    /// Takes a moving acoustic array's pose (`crate::aid::ranges`).
    pub fn on_acoustic_array_pose(&mut self, m: &AcousticArrayPoseV1) {
        self.ranges.on_array_pose(m);
    }

    /// Each receiver's estimated range bias (m; the shared one repeated), when the range aid is
    /// configured.
    pub fn receiver_biases(&self) -> Option<Vec<f64>> {
        self.ranges.receiver_biases(&self.core)
    }

    /// The range aid's range bias (m; receiver 0's when each has its own) and sound-speed scale
    /// error, when configured.
    pub fn range_estimates(&self) -> Option<(f64, f64)> {
        self.ranges.estimates(&self.core)
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

    /// Takes a sound-velocity reading (a CTD): with `dvl_sound_speed_source = "topic"` its sound
    /// speed corrects the DVL velocities from now on; otherwise, or out of range, it is counted
    /// and ignored.
    pub fn on_sound_velocity(&mut self, m: &SoundVelocityV1) {
        let valid = m.validity & SoundVelocityV1::VALID_SOUND_SPEED != 0
            && (1375.0..=1650.0).contains(&m.sound_speed_m_s);
        match self.sound_speed_topic {
            Some(assumed) if valid => {
                self.dvl.sound_speed = Some(SoundSpeed {
                    true_m_s: m.sound_speed_m_s,
                    assumed_default_m_s: assumed,
                });
                self.sound_velocity_used += 1;
            }
            _ => self.sound_velocity_ignored += 1,
        }
        self.ranges.on_sound_velocity(m);
    }

    /// The estimated water current, north and east (m/s), and its standard deviations, when the
    /// water-current states are on.
    pub fn water_current(&self) -> Option<([f64; 2], [f64; 2])> {
        if !self.dvl.water_current {
            return None;
        }
        let k = ekf::CURRENT - ekf::CORE;
        let p = &self.core.kf.p;
        Some((
            [self.core.markov_means[k], self.core.markov_means[k + 1]],
            [
                p[(ekf::CURRENT, ekf::CURRENT)].sqrt(),
                p[(ekf::CURRENT + 1, ekf::CURRENT + 1)].sqrt(),
            ],
        ))
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
            imu_clock_jumps: c.imu_clock_jumps,
            dvl_fused: dvl.fused,
            dvl_rejected: dvl.rejected,
            dvl_invalid: dvl.invalid,
            dvl_resets: self.dvl.resets,
            dvl_sound_speed_corrected: self.dvl.sound_speed_corrected,
            dvl_water_track_fused: self.dvl.water_track.fused,
            dvl_water_track_rejected: self.dvl.water_track.rejected,
            dvl_water_track_invalid: self.dvl.water_track.invalid,
            dvl_water_track_unused: self.dvl.water_track_unused,
            dvl_bottom_lock_lost: self.dvl.bottom_lock_lost,
            dvl_bottom_lock_regained: self.dvl.bottom_lock_regained,
            dvl_beam_readings_fused: self.dvl.beam_readings_fused,
            dvl_beams_rejected: self.dvl.beams_rejected,
            dvl_beam_corrected: self.dvl.beam_corrected,
            sound_velocity_used: self.sound_velocity_used,
            sound_velocity_ignored: self.sound_velocity_ignored,
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
            ranges_fused: self.ranges.counters.fused,
            ranges_rejected: self.ranges.counters.rejected,
            ranges_invalid: self.ranges.counters.invalid,
            ranges_unconfigured: self.ranges.counters.unconfigured,
            ranges_late: self.ranges.counters.late,
            ranges_reopened: self.ranges.counters.reopened,
            ranges_without_array_pose: self.ranges.counters.no_array_pose,
            array_poses: self.ranges.counters.array_poses,
            array_poses_invalid: self.ranges.counters.array_poses_invalid,
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
        // The acoustic position aid: the USBL's fixes or the range aid's ranges.
        let usbl_fused_s = match (self.usbl.last_fused_s(), self.ranges.last_fused_s()) {
            (Some(a), Some(b)) => Some(a.max(b)),
            (a, b) => a.or(b),
        };
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
            mode: if p[(ekf::POS, ekf::POS)].max(p[(ekf::POS + 1, ekf::POS + 1)])
                > self.position_unknown_std_m.powi(2)
            {
                NavMode::PositionUnknown
            } else if dvl_ok {
                NavMode::Navigating
            } else {
                NavMode::Degraded
            } as u32,
            sensor_health: health,
        }
    }
}

/// What the daemon writes to disk to continue after a restart: the navigation state, the IMU
/// biases, the whole error covariance (column order) and the DVL installation in force.
#[derive(Debug, Clone, PartialEq, Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Checkpoint {
    pub format_version: u32,
    /// Time of validity (s, host monotonic clock of the process that wrote it).
    pub time_s: f64,
    pub latitude_rad: f64,
    pub longitude_rad: f64,
    pub height_m: f64,
    pub velocity_ned_m_s: [f64; 3],
    /// w, x, y, z.
    pub quaternion_body_to_ned: [f64; 4],
    pub gyro_bias_rad_s: [f64; 3],
    pub accel_bias_m_s2: [f64; 3],
    /// The error covariance, N × N in column order.
    pub covariance: Vec<f64>,
    pub dvl: crate::config::DvlInstallation,
}

/// The initial state from a geodetic position, NED velocity and Euler angles (in `strapdown`).
pub use crate::strapdown::initial_state;

/// The DVL time offset applied by retiming the readings (s, ≤ 0): a negative configured offset
/// means a reading stamped t describes the motion at t − offset, later than its stamp, so the
/// session holds it until the filter reaches that moment instead of extrapolating the velocity
/// to first order over the offset. A positive offset (a reading describing the past) stays in
/// the first-order model.
pub fn dvl_retime_s(cfg: &NavConfig) -> f64 {
    cfg.dvl_installation().time_offset_s.min(0.0)
}
