//! The configuration of the navigation: the core's `[navigation]` table ([`NavConfig`]), the
//! session's start (`[initial]` or `[alignment]`, [`SessionConfig`]) and the daemon's file
//! ([`DaemonConfig`]: those plus outputs, deadlines and health). One type per table, each with
//! `deny_unknown_fields` and documented units and defaults, and one validation
//! ([`NavConfig::problems`], [`SessionConfig::problems`], [`DaemonConfig::validate`]) that the
//! daemon, replay and every tool apply, so no program accepts a configuration another rejects.
//! Files are written by serialising these types ([`DaemonConfig::to_toml`]).
//!
//! Long on purpose: every table of the configuration with its defaults, units and validation in one
//! place, so that no program accepts a configuration another rejects.

use crate::earth::Geodetic;
use crate::ekf::gate;
use crate::strapdown::NavState;
use crate::strapdown::initial_state;
use serde::{Deserialize, Serialize};

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
    /// The compass's deviation card, `[A, B, C, D, E]` (deg, |·| ≤ 45; the simulator's
    /// `heading.deviation`): taken out of an attitude channel's heading before it is used, which
    /// dead reckoning of a surface run does (the filter does not read a compass). Default 0.
    pub compass_deviation_deg: [f64; 5],
    /// Depth noise (m). Default 0.1.
    pub depth_std_m: f64,
    /// Depth (pressure) sensor position in the body frame (m, |·| ≤ 50): it reads the depth of
    /// that point, so pitch and roll move its reading (the simulator's `depth.lever_arm`).
    /// Default 0.
    pub depth_lever_arm_m: [f64; 3],
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
    /// With `imu_dt_from_device_time`, a device-time step longer than the host-time step plus
    /// this is a clock jump: the host-time step is integrated instead, and the sample counted
    /// (s, 0.001..10). Default 0.1.
    pub imu_clock_tolerance_s: f64,
    /// Largest plausible angular rate per axis (deg/s, 1..10000): a sample beyond it is not
    /// integrated (counted invalid). Default 2000 (above every navigation IMU's range).
    pub imu_max_rate_deg_s: f64,
    /// Largest plausible specific force per axis (m/s², 1..2000): a sample beyond it is not
    /// integrated (counted invalid). Default 300 (about 30 g).
    pub imu_max_specific_force_m_s2: f64,
    /// Over an IMU gap (and after a restart or a reinitialisation) the motion nobody measured is
    /// taken as an acceleration of this one-sigma held over the gap: it grows the velocity and
    /// position variances (m/s², 0..50). Default 0.2.
    pub imu_gap_accel_std_m_s2: f64,
    /// ... and a rotation rate of this one-sigma, which grows the attitude variances (deg/s,
    /// 0..100). Default 1.
    pub imu_gap_rate_std_deg_s: f64,
    /// The solution's mode is "position unknown" while its horizontal position standard
    /// deviation exceeds this (m, 1..1e7). Default 1000.
    pub position_unknown_std_m: f64,
    /// DVL time offset: the velocity stamped at t is the vehicle's at t - offset (s). Default 0.
    /// A negative offset (a reading stamped before the motion it describes) is applied by
    /// holding each reading until the filter reaches that moment; a positive one to first order
    /// (v(t - offset) ≈ v(t) - offset·a).
    pub dvl_time_offset_s: f64,
    /// Estimate the DVL mounting angles (parameter states). Default false.
    pub estimate_dvl_mounting: bool,
    /// Initial one-sigma of the DVL mounting angles when estimated (deg). Default 1.
    pub initial_dvl_mounting_std_deg: f64,
    /// Initial one-sigma of each mounting angle (roll, pitch, yaw; deg) when they differ: the
    /// yaw of a DVL is often known to degrees and its roll and pitch to a fraction of one.
    /// Replaces `initial_dvl_mounting_std_deg` when given. Default none.
    pub initial_dvl_mounting_axis_std_deg: Option<[f64; 3]>,
    /// Estimate the DVL scale factor (parameter state). Default false.
    pub estimate_dvl_scale: bool,
    /// Initial one-sigma of the DVL scale factor when estimated (1). Default 0.01.
    pub initial_dvl_scale_std: f64,
    /// Estimate the DVL lever arm (parameter states). Default false.
    pub estimate_dvl_lever_arm: bool,
    /// Initial one-sigma of the DVL lever arm when estimated (m). Default 0.5.
    pub initial_dvl_lever_arm_std_m: f64,
    /// Estimate the DVL time offset (parameter state). Default false. The state models what the
    /// retiming of `dvl_time_offset_s` leaves to first order, which comes out short for an offset
    /// of a second (from 0, −0.39 to −0.55 s on the Snapir AUV's −1.0 s): configure the offset
    /// `auvnav smooth` or `auvnav discover` finds, and estimate the rest.
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
    /// Gate for zero-velocity updates (chi-square, 3 dof). Default 16.27 (99.9 %).
    pub zero_velocity_gate_chi2: f64,
    /// After valid DVL velocities have been rejected without a break for this long, the velocity
    /// covariance is re-opened (cross-covariances dropped, the innovation added to the variances)
    /// and the measurement fused: the filter had become too sure of a wrong velocity (s; 0 =
    /// never). Default 5.
    pub dvl_reset_after_s: f64,
    /// Stationary one-sigma of the horizontal water current (m/s; 0 = no current states, and
    /// DVL water-track velocities are not fused). With it, the filter carries the current north
    /// and east as Gauss–Markov states, learns it while the DVL reports bottom and water track
    /// together, and navigates on water track (velocity relative to the water) when bottom lock
    /// is lost. Default 0.
    pub water_current_std_m_s: f64,
    /// Correlation time of the water current (s): how fast it may change while nothing observes
    /// it (bottom lock lost). Default 10800 (3 h, the time scale of tidal currents); a shorter
    /// one lets the current absorb what water track says about the velocity.
    pub water_current_correlation_s: f64,
    /// Fuse the DVL's beam (radial) velocities when it reports no instrument velocity but some
    /// beams (one beam blocked, a beam-coordinate reading without a solution): each beam gated
    /// alone, the accepted ones fused together. Default false.
    pub dvl_beam_fusion: bool,
    /// The beams' angle from the DVL's z axis (the Janus angle, deg, 5..60). Default 30.
    pub dvl_beam_angle_deg: f64,
    /// The beams' azimuths about the DVL's z axis from its x axis (deg), beams 1..4. Default
    /// 45, 135, 225, 315 (the simulator's head).
    pub dvl_beam_azimuths_deg: [f64; 4],
    /// One-sigma of a beam velocity (m/s). Default 0.01.
    pub dvl_beam_velocity_std_m_s: f64,
    /// Where the true speed of sound at the DVL comes from. A DVL computes its velocity with a
    /// sound speed it assumes (the one it reports, else `dvl_assumed_sound_speed_m_s`); with
    /// the true one known the velocity is corrected by true / assumed (a Janus piston DVL:
    /// 1 % of sound speed is 1 % of distance). `"none"` (default): no correction; `"value"`:
    /// `sound_speed_m_s`; `"dvl"`: the DVL measures it and used it, so its velocity stands.
    pub dvl_sound_speed_source: SoundSpeedSource,
    /// The true speed of sound at the DVL for `dvl_sound_speed_source = "value"` (m/s,
    /// 1375..1650). Default 1500.
    pub sound_speed_m_s: f64,
    /// The sound speed a DVL that reports none assumed (m/s, 1375..1650). Default 1500.
    pub dvl_assumed_sound_speed_m_s: f64,
    /// The DVL installation as a table (`[navigation.dvl]`, what `auvnav calibrate dvl` writes).
    /// When present it replaces `dvl_mount_deg`, `dvl_scale_factor`, `dvl_lever_arm_m` and
    /// `dvl_time_offset_s`, which must then stay at their defaults. Default none.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub dvl: Option<DvlInstallation>,
    /// USBL fusion (`[navigation.usbl]`): the station's array, the coupling and the filter.
    /// Default none: USBL fixes are counted and not used.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub usbl: Option<crate::aid::usbl::UsblConfig>,
    /// Acoustic ranges (`[navigation.ranges]`): LBL beacons, a moving array's receivers or a
    /// single beacon, each range fused alone. Uses the acoustic error states the tight USBL uses:
    /// not with `usbl.coupling = "tight"`.
    pub ranges: Option<crate::aid::ranges::RangesConfig>,
    /// Magnetic heading aid (`[navigation.magnetometer]`): the calibration (what `auvnav
    /// calibrate mag` writes), the field model, noise and gate. Default none: readings are
    /// counted and not used.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub magnetometer: Option<crate::aid::magnetometer::MagnetometerConfig>,
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
            compass_deviation_deg: [0.0; 5],
            depth_std_m: 0.1,
            depth_lever_arm_m: [0.0; 3],
            dvl_gate_chi2: gate::CHI2_3DOF_999,
            depth_gate_chi2: gate::CHI2_1DOF_999,
            covariance_interval_s: 0.05,
            dvl_timeout_s: 5.0,
            imu_max_gap_intervals: 10.0,
            imu_dt_from_device_time: false,
            imu_clock_tolerance_s: 0.1,
            imu_max_rate_deg_s: 2000.0,
            imu_max_specific_force_m_s2: 300.0,
            imu_gap_accel_std_m_s2: 0.2,
            imu_gap_rate_std_deg_s: 1.0,
            position_unknown_std_m: 1000.0,
            dvl_time_offset_s: 0.0,
            estimate_dvl_mounting: false,
            initial_dvl_mounting_std_deg: 1.0,
            initial_dvl_mounting_axis_std_deg: None,
            estimate_dvl_scale: false,
            initial_dvl_scale_std: 0.01,
            estimate_dvl_lever_arm: false,
            initial_dvl_lever_arm_std_m: 0.5,
            estimate_dvl_time_offset: false,
            initial_dvl_time_offset_std_s: 0.2,
            gnss_lever_arm_m: [0.0; 3],
            gnss_min_std_m: 0.5,
            gnss_gate_chi2: gate::CHI2_3DOF_999,
            zero_velocity_std_m_s: 0.01,
            zero_velocity_gate_chi2: gate::CHI2_3DOF_999,
            dvl_reset_after_s: 5.0,
            water_current_std_m_s: 0.0,
            water_current_correlation_s: 10800.0,
            dvl_beam_fusion: false,
            dvl_beam_angle_deg: 30.0,
            dvl_beam_azimuths_deg: [45.0, 135.0, 225.0, 315.0],
            dvl_beam_velocity_std_m_s: 0.01,
            dvl_sound_speed_source: SoundSpeedSource::None,
            sound_speed_m_s: 1500.0,
            dvl_assumed_sound_speed_m_s: 1500.0,
            dvl: None,
            usbl: None,
            ranges: None,
            magnetometer: None,
        }
    }
}

/// Where the true speed of sound at the DVL comes from (`dvl_sound_speed_source`).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum SoundSpeedSource {
    /// No correction.
    #[default]
    None,
    /// The configured `sound_speed_m_s`.
    Value,
    /// The DVL measures it and used it: its velocity stands.
    Dvl,
    /// The latest reading of a CTD or sound-velocity probe (`sound_velocity` topic); no
    /// correction before the first one.
    Topic,
}

/// The DVL installation (`[navigation.dvl]`): the same quantities, units and sign conventions as
/// the simulator's effects `dvl.mount_roll`, `dvl.mount_pitch`, `dvl.mount_yaw`,
/// `dvl.scale_factor`, `dvl.lever_arm` and `dvl.time_offset`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct DvlInstallation {
    /// Mounting roll, pitch, yaw of the DVL frame w.r.t. the body (deg). Default 0.
    pub mount_deg: [f64; 3],
    /// Scale factor: the DVL reads this times the true velocity (1 = none). Default 1.
    pub scale_factor: f64,
    /// DVL position in the body frame (m). Default 0.
    pub lever_arm_m: [f64; 3],
    /// The velocity stamped at t is the vehicle's at t - offset (s). Default 0.
    pub time_offset_s: f64,
    /// Each beam's own scale-factor error (ppm, beams 1..4; the simulator's
    /// `dvl.beam_scale_factor`): a reading that carries all four beam velocities is solved again
    /// from its beams divided by `1 + s`, in place of the device's velocity. Default 0.
    #[serde(skip_serializing_if = "all_zero")]
    pub beam_scale_factor_ppm: [f64; 4],
    /// Each beam's angle error (deg; `dvl.beam_angle_error`): the beam's true angle from the DVL's
    /// z axis is `dvl_beam_angle_deg` plus this, at its configured azimuth; used as the scale
    /// factor is. Default 0.
    #[serde(skip_serializing_if = "all_zero")]
    pub beam_angle_error_deg: [f64; 4],
    /// Where these values come from (free text, e.g. the calibration run). Default empty.
    #[serde(skip_serializing_if = "String::is_empty")]
    pub source: String,
}

fn all_zero(v: &[f64; 4]) -> bool {
    v.iter().all(|x| *x == 0.0)
}

impl DvlInstallation {
    /// Whether per-beam corrections are configured.
    pub fn corrects_beams(&self) -> bool {
        !all_zero(&self.beam_scale_factor_ppm) || !all_zero(&self.beam_angle_error_deg)
    }
}

impl Default for DvlInstallation {
    fn default() -> Self {
        DvlInstallation {
            mount_deg: [0.0; 3],
            scale_factor: 1.0,
            lever_arm_m: [0.0; 3],
            time_offset_s: 0.0,
            beam_scale_factor_ppm: [0.0; 4],
            beam_angle_error_deg: [0.0; 4],
            source: String::new(),
        }
    }
}

impl NavConfig {
    /// The DVL installation in force: the `[navigation.dvl]` table when there is one, otherwise
    /// the flat `dvl_*` keys.
    pub fn dvl_installation(&self) -> DvlInstallation {
        self.dvl.clone().unwrap_or_else(|| DvlInstallation {
            mount_deg: self.dvl_mount_deg,
            scale_factor: self.dvl_scale_factor,
            lever_arm_m: self.dvl_lever_arm_m,
            time_offset_s: self.dvl_time_offset_s,
            ..DvlInstallation::default()
        })
    }

    /// Sets the DVL installation: into the `[navigation.dvl]` table (the flat keys go back to
    /// their defaults, so the configuration stays valid).
    /// The initial one-sigma of the mounting roll, pitch and yaw when estimated (deg).
    pub fn dvl_mounting_std_deg(&self) -> [f64; 3] {
        self.initial_dvl_mounting_axis_std_deg
            .unwrap_or([self.initial_dvl_mounting_std_deg; 3])
    }

    pub fn set_dvl_installation(&mut self, d: DvlInstallation) {
        let defaults = NavConfig::default();
        self.dvl_mount_deg = defaults.dvl_mount_deg;
        self.dvl_scale_factor = defaults.dvl_scale_factor;
        self.dvl_lever_arm_m = defaults.dvl_lever_arm_m;
        self.dvl_time_offset_s = defaults.dvl_time_offset_s;
        self.dvl = Some(d);
    }
}

/// An initial state given in the configuration.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct InitialState {
    /// Latitude (deg, WGS-84).
    pub latitude_deg: f64,
    /// Longitude (deg).
    pub longitude_deg: f64,
    /// Height above the ellipsoid (m; negative below it).
    pub height_m: f64,
    /// Velocity (m/s, NED; default 0).
    #[serde(default)]
    pub velocity_ned_m_s: [f64; 3],
    /// Roll, pitch, yaw (deg).
    pub euler_deg: [f64; 3],
}

impl InitialState {
    /// The navigation state at `time_s`.
    pub fn state(&self, time_s: f64) -> NavState {
        initial_state(
            time_s,
            Geodetic {
                latitude_rad: self.latitude_deg.to_radians(),
                longitude_rad: self.longitude_deg.to_radians(),
                height_m: self.height_m,
            },
            self.velocity_ned_m_s,
            self.euler_deg.map(f64::to_radians),
        )
    }
}

/// Initial alignment when the attitude is unknown (`[alignment]`): the position is given, the
/// attitude found by the coarse aligner (`crate::align`), then refined by the navigation filter
/// with the DVL (fine alignment) until the heading's standard deviation meets the criterion.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct AlignmentConfig {
    /// Latitude (deg, WGS-84).
    pub latitude_deg: f64,
    /// Longitude (deg).
    pub longitude_deg: f64,
    /// Height above the ellipsoid (m; negative below it).
    pub height_m: f64,
    /// Coarse alignment duration (s, 10..3600; default 120).
    #[serde(default = "default_coarse_s")]
    pub coarse_s: f64,
    /// The vehicle is at rest during coarse alignment: velocity epochs are zero and need no DVL
    /// (default false: DVL-aided in motion).
    #[serde(default)]
    pub moored: bool,
    /// Heading standard deviation handed to the filter after the coarse stage (deg; default 2).
    #[serde(default = "default_coarse_heading_std")]
    pub coarse_heading_std_deg: f64,
    /// Roll/pitch standard deviation handed to the filter (deg; default 0.05).
    #[serde(default = "default_coarse_tilt_std")]
    pub coarse_tilt_std_deg: f64,
    /// Convergence criterion: the mode becomes navigating when the filter's heading standard
    /// deviation falls below this (deg; default 0.1).
    #[serde(default = "default_aligned_heading_std")]
    pub aligned_heading_std_deg: f64,
    /// Fine-alignment error model between the coarse stage and navigation: 1 (body-frame
    /// velocity error, mounting states), 2 (navigation frame, mounting states), 3 (navigation
    /// frame), or 0 to refine in the navigation filter itself (default 1). With 1–3 the
    /// navigation filter starts, when the criterion is met, from the alignment filter's state,
    /// IMU biases, DVL mounting estimate and standard deviations (cross-covariances dropped).
    #[serde(default = "default_fine_model")]
    pub fine_model: u8,
    /// Where the coarse heading comes from: "gyrocompass" (the Earth's rotation seen by the
    /// gyros; needs navigation-grade gyros) or "magnetometer" (the calibrated field of
    /// `[navigation.magnetometer]` and the declination of the field model, for vehicles whose
    /// gyros cannot find north). Default "gyrocompass".
    #[serde(default)]
    pub heading_source: HeadingSource,
}

/// The coarse alignment's heading source.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum HeadingSource {
    #[default]
    Gyrocompass,
    Magnetometer,
}

fn default_fine_model() -> u8 {
    1
}

fn default_coarse_s() -> f64 {
    120.0
}
fn default_coarse_heading_std() -> f64 {
    2.0
}
fn default_coarse_tilt_std() -> f64 {
    0.05
}
fn default_aligned_heading_std() -> f64 {
    0.1
}

/// The navigation part of a configuration: `[navigation]` (the core's [`NavConfig`]), an
/// optional `[initial]` state and the aid delay.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct SessionConfig {
    /// An aid message stamped t is applied just before the first IMU sample stamped later than
    /// t + aid_delay_s (s, 0..1; default 0). Live, the delay gives aid messages from other
    /// processes time to arrive before the IMU passes them, so the order of processing depends
    /// only on the time stamps, and a replay of the recording reproduces it exactly; the daemon
    /// uses 0.02 s.
    pub aid_delay_s: f64,
    pub navigation: NavConfig,
    pub initial: Option<InitialState>,
    /// Used when `[initial]` is absent.
    pub alignment: Option<AlignmentConfig>,
}

/// Outputs (`[output]`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct OutputConfig {
    /// Publish every Nth navigation solution (count, 1..1000, default 1 = IMU rate).
    pub solution_decimation: u32,
    /// Also write every solution to this CSV file (the format of `auvnav replay --out F.csv`);
    /// empty for none (default).
    pub nav_csv: String,
    /// Write every aid diagnostic to this CSV file; empty for none (default).
    pub diagnostics_csv: String,
    /// Write, per navigation solution, the host times of its stages to this CSV file (ns,
    /// `imu_host_time_ns,woke_ns,received_ns,computed_ns,published_ns`: the IMU driver's read
    /// time stamp, the daemon's wake-up, the sensor topics drained, the solution computed, the
    /// solution published), for latency breakdowns; empty for none (default).
    pub stage_times_csv: String,
}

impl Default for OutputConfig {
    fn default() -> Self {
        OutputConfig {
            solution_decimation: 1,
            nav_csv: String::new(),
            diagnostics_csv: String::new(),
            stage_times_csv: String::new(),
        }
    }
}

/// Deadlines after which a silent sensor is reported lost (`[deadlines]`; s, 0 = none).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct Deadlines {
    /// IMU (s, default 0.1).
    pub imu_s: f64,
    /// DVL (s, default 3).
    pub dvl_s: f64,
    /// Depth (s, default 3).
    pub depth_s: f64,
    /// USBL (s, default 0: fixes come when the station pings).
    pub usbl_s: f64,
    /// GNSS (s, default 0: only at the surface).
    pub gnss_s: f64,
}

impl Default for Deadlines {
    fn default() -> Self {
        Deadlines {
            imu_s: 0.1,
            dvl_s: 3.0,
            depth_s: 3.0,
            usbl_s: 0.0,
            gnss_s: 0.0,
        }
    }
}

/// Checkpoints (`[checkpoint]`): the daemon writes its navigation state to a file, atomically, and
/// after a crash or a restart continues from it instead of the configured start.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct CheckpointConfig {
    /// The checkpoint file (its folder must exist); empty for none (default). The unit in
    /// `deploy/` uses `/var/lib/auvnav/auvnavd.checkpoint.json`.
    pub path: String,
    /// Time between checkpoints (s, 0.1..3600). Default 2.
    pub interval_s: f64,
    /// One-sigma speed at which the vehicle may have moved while the daemon was down: the
    /// position standard deviation grows by this times the time elapsed, the velocity's by this
    /// (m/s, 0..50). Default 2.5.
    pub drift_m_s: f64,
    /// A checkpoint older than this (wall clock), unreadable, or not sound is not used: the
    /// daemon starts from `[initial]`/`[alignment]` with its position flagged unknown (s,
    /// 1..1e6). Default 3600.
    pub max_age_s: f64,
    /// The position standard deviation of such a start (m, 1..1e7). Default 10000.
    pub unknown_position_std_m: f64,
}

impl Default for CheckpointConfig {
    fn default() -> Self {
        CheckpointConfig {
            path: String::new(),
            interval_s: 2.0,
            drift_m_s: 2.5,
            max_age_s: 3600.0,
            unknown_position_std_m: 10_000.0,
        }
    }
}

/// `auvnavd`'s configuration file.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct DaemonConfig {
    /// Node name and the name in the health message (default `auvnavd`).
    #[serde(default = "default_name")]
    pub name: String,
    /// Service-name prefix of the deployment (default `auvnav`).
    #[serde(default = "default_prefix")]
    pub prefix: String,
    /// Aid delay (s, 0..1, default 0.02): see the module documentation.
    #[serde(default = "default_aid_delay")]
    pub aid_delay_s: f64,
    /// Health message period (s, 0.05..60, default 1).
    #[serde(default = "default_health_period")]
    pub health_period_s: f64,
    /// The navigation core's configuration ([`NavConfig`]).
    #[serde(default)]
    pub navigation: NavConfig,
    /// Initial state; when absent, `[alignment]` finds the attitude (position given).
    pub initial: Option<InitialState>,
    /// Initial alignment ([`AlignmentConfig`]): used without `[initial]`.
    pub alignment: Option<AlignmentConfig>,
    #[serde(default)]
    pub output: OutputConfig,
    #[serde(default)]
    pub deadlines: Deadlines,
    #[serde(default)]
    pub checkpoint: CheckpointConfig,
}

fn default_name() -> String {
    "auvnavd".into()
}
fn default_prefix() -> String {
    auvnav_shm_schema::topic::DEFAULT_PREFIX.into()
}
fn default_aid_delay() -> f64 {
    0.02
}
fn default_health_period() -> f64 {
    1.0
}

/// Configuration problems, each as `key = value: what is expected`.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("{}", .0.join("; "))]
pub struct ConfigError(pub Vec<String>);

/// Collects `key = value: expected lo..=hi` problems.
struct Problems(Vec<String>);

impl Problems {
    fn range(&mut self, key: &str, v: f64, lo: f64, hi: f64) {
        if !(v.is_finite() && v >= lo && v <= hi) {
            self.0.push(format!("{key} = {v}: expected {lo}..={hi}"));
        }
    }

    /// A process or service name part: 1..=64 ASCII letters, digits, `_`, `-`, `.`, `/`.
    fn name(&mut self, key: &str, v: &str) {
        let ok = (1..=64).contains(&v.len())
            && v.chars()
                .all(|c| c.is_ascii_alphanumeric() || "_-./".contains(c));
        if !ok {
            self.0.push(format!(
                "{key} = {v:?}: expected 1 to 64 ASCII letters, digits, '_', '-', '.', '/'"
            ));
        }
    }

    fn array(&mut self, key: &str, v: &[f64], lo: f64, hi: f64) {
        for (i, x) in v.iter().enumerate() {
            self.range(&format!("{key}[{i}]"), *x, lo, hi);
        }
    }

    /// A geodetic position: latitude within ±89.9° (the navigation frame is singular at the
    /// poles), longitude within ±180°, height −12 000..10 000 m.
    fn position(&mut self, table: &str, lat: f64, lon: f64, h: f64) {
        self.range(&format!("{table}.latitude_deg"), lat, -89.9, 89.9);
        self.range(&format!("{table}.longitude_deg"), lon, -180.0, 180.0);
        self.range(&format!("{table}.height_m"), h, -12000.0, 10000.0);
    }
}

pub use auvnav_shm_schema::stage_times::output_path_problem;

impl NavConfig {
    /// Every value of `[navigation]` that makes no sense, as `navigation.key …`.
    // Long on purpose: one rule per key of `[navigation]`, in the table's order, so every
    // key's check is read beside the others; a list, not logic.
    pub fn problems(&self) -> Vec<String> {
        let mut p = Problems(Vec::new());
        for (key, v, lo, hi) in [
            (
                "gyro_angle_random_walk_deg_sqrt_h",
                self.gyro_angle_random_walk_deg_sqrt_h,
                0.0,
                10.0,
            ),
            (
                "accel_velocity_random_walk_m_s_sqrt_h",
                self.accel_velocity_random_walk_m_s_sqrt_h,
                0.0,
                10.0,
            ),
            (
                "gyro_bias_walk_deg_h_sqrt_h",
                self.gyro_bias_walk_deg_h_sqrt_h,
                0.0,
                100.0,
            ),
            (
                "accel_bias_walk_ug_sqrt_h",
                self.accel_bias_walk_ug_sqrt_h,
                0.0,
                1e5,
            ),
            (
                "initial_position_std_m",
                self.initial_position_std_m,
                1e-3,
                1e7,
            ),
            (
                "initial_velocity_std_m_s",
                self.initial_velocity_std_m_s,
                1e-4,
                100.0,
            ),
            (
                "initial_tilt_std_deg",
                self.initial_tilt_std_deg,
                1e-4,
                90.0,
            ),
            (
                "initial_heading_std_deg",
                self.initial_heading_std_deg,
                1e-4,
                180.0,
            ),
            (
                "initial_gyro_bias_std_deg_h",
                self.initial_gyro_bias_std_deg_h,
                0.0,
                1e5,
            ),
            (
                "initial_accel_bias_std_ug",
                self.initial_accel_bias_std_ug,
                0.0,
                1e6,
            ),
            (
                "dvl_velocity_std_m_s",
                self.dvl_velocity_std_m_s,
                1e-4,
                10.0,
            ),
            ("dvl_scale_factor", self.dvl_scale_factor, 0.5, 2.0),
            ("depth_std_m", self.depth_std_m, 1e-4, 100.0),
            ("dvl_gate_chi2", self.dvl_gate_chi2, 0.1, 1e6),
            ("depth_gate_chi2", self.depth_gate_chi2, 0.1, 1e6),
            (
                "covariance_interval_s",
                self.covariance_interval_s,
                1e-3,
                1.0,
            ),
            ("dvl_timeout_s", self.dvl_timeout_s, 0.1, 3600.0),
            (
                "imu_max_gap_intervals",
                self.imu_max_gap_intervals,
                1.5,
                1e6,
            ),
            (
                "imu_clock_tolerance_s",
                self.imu_clock_tolerance_s,
                1e-3,
                10.0,
            ),
            ("imu_max_rate_deg_s", self.imu_max_rate_deg_s, 1.0, 10000.0),
            (
                "imu_max_specific_force_m_s2",
                self.imu_max_specific_force_m_s2,
                1.0,
                2000.0,
            ),
            (
                "imu_gap_accel_std_m_s2",
                self.imu_gap_accel_std_m_s2,
                0.0,
                50.0,
            ),
            (
                "imu_gap_rate_std_deg_s",
                self.imu_gap_rate_std_deg_s,
                0.0,
                100.0,
            ),
            (
                "position_unknown_std_m",
                self.position_unknown_std_m,
                1.0,
                1e7,
            ),
            ("dvl_time_offset_s", self.dvl_time_offset_s, -5.0, 5.0),
            (
                "initial_dvl_mounting_std_deg",
                self.initial_dvl_mounting_std_deg,
                1e-4,
                180.0,
            ),
            (
                "initial_dvl_scale_std",
                self.initial_dvl_scale_std,
                1e-6,
                1.0,
            ),
            (
                "initial_dvl_lever_arm_std_m",
                self.initial_dvl_lever_arm_std_m,
                1e-4,
                50.0,
            ),
            (
                "initial_dvl_time_offset_std_s",
                self.initial_dvl_time_offset_std_s,
                1e-5,
                10.0,
            ),
            ("gnss_min_std_m", self.gnss_min_std_m, 1e-3, 1000.0),
            ("gnss_gate_chi2", self.gnss_gate_chi2, 0.1, 1e6),
            (
                "zero_velocity_std_m_s",
                self.zero_velocity_std_m_s,
                1e-5,
                10.0,
            ),
            (
                "zero_velocity_gate_chi2",
                self.zero_velocity_gate_chi2,
                0.1,
                1e6,
            ),
            ("dvl_reset_after_s", self.dvl_reset_after_s, 0.0, 3600.0),
            (
                "water_current_std_m_s",
                self.water_current_std_m_s,
                0.0,
                5.0,
            ),
            (
                "water_current_correlation_s",
                self.water_current_correlation_s,
                1.0,
                1e7,
            ),
            ("dvl_beam_angle_deg", self.dvl_beam_angle_deg, 5.0, 60.0),
            (
                "dvl_beam_velocity_std_m_s",
                self.dvl_beam_velocity_std_m_s,
                1e-4,
                1.0,
            ),
            ("sound_speed_m_s", self.sound_speed_m_s, 1375.0, 1650.0),
            (
                "dvl_assumed_sound_speed_m_s",
                self.dvl_assumed_sound_speed_m_s,
                1375.0,
                1650.0,
            ),
        ]
        .into_iter()
        .chain(
            self.initial_dvl_mounting_axis_std_deg
                .into_iter()
                .flatten()
                .map(|v| ("initial_dvl_mounting_axis_std_deg", v, 1e-4, 180.0)),
        ) {
            p.range(&format!("navigation.{key}"), v, lo, hi);
        }
        p.array(
            "navigation.dvl_mount_deg",
            &self.dvl_mount_deg,
            -180.0,
            180.0,
        );
        p.array(
            "navigation.dvl_lever_arm_m",
            &self.dvl_lever_arm_m,
            -50.0,
            50.0,
        );
        p.array(
            "navigation.compass_deviation_deg",
            &self.compass_deviation_deg,
            -45.0,
            45.0,
        );
        p.array(
            "navigation.depth_lever_arm_m",
            &self.depth_lever_arm_m,
            -50.0,
            50.0,
        );
        p.array(
            "navigation.gnss_lever_arm_m",
            &self.gnss_lever_arm_m,
            -50.0,
            50.0,
        );
        p.array(
            "navigation.dvl_beam_azimuths_deg",
            &self.dvl_beam_azimuths_deg,
            -360.0,
            360.0,
        );
        let mut out = p.0;
        if let Some(d) = &self.dvl {
            let defaults = NavConfig::default();
            if self.dvl_mount_deg != defaults.dvl_mount_deg
                || self.dvl_scale_factor != defaults.dvl_scale_factor
                || self.dvl_lever_arm_m != defaults.dvl_lever_arm_m
                || self.dvl_time_offset_s != defaults.dvl_time_offset_s
            {
                out.push(
                    "navigation.dvl: the DVL installation is given twice; with a [navigation.dvl] \
                     table, leave dvl_mount_deg, dvl_scale_factor, dvl_lever_arm_m and \
                     dvl_time_offset_s out of [navigation]"
                        .to_string(),
                );
            }
            let mut p = Problems(Vec::new());
            p.range("navigation.dvl.scale_factor", d.scale_factor, 0.5, 2.0);
            p.range("navigation.dvl.time_offset_s", d.time_offset_s, -5.0, 5.0);
            p.array("navigation.dvl.mount_deg", &d.mount_deg, -180.0, 180.0);
            p.array("navigation.dvl.lever_arm_m", &d.lever_arm_m, -50.0, 50.0);
            p.array(
                "navigation.dvl.beam_scale_factor_ppm",
                &d.beam_scale_factor_ppm,
                -100_000.0,
                100_000.0,
            );
            p.array(
                "navigation.dvl.beam_angle_error_deg",
                &d.beam_angle_error_deg,
                -5.0,
                5.0,
            );
            out.extend(p.0);
        }
        if let Some(u) = &self.usbl {
            out.extend(u.problems().into_iter().map(|p| format!("navigation.{p}")));
        }
        if let Some(r) = &self.ranges {
            out.extend(r.problems().into_iter().map(|p| format!("navigation.{p}")));
            if r.usbl_fixes && self.usbl.is_some() {
                out.push(
                    "navigation.ranges.usbl_fixes: not with navigation.usbl (both would fuse the \
                     station's fixes); configure one of them"
                        .into(),
                );
            } else if self
                .usbl
                .as_ref()
                .is_some_and(|u| u.coupling == crate::aid::usbl::Coupling::Tight)
            {
                out.push(
                    "navigation.ranges: not with navigation.usbl.coupling = \"tight\" (both use \
                     the acoustic error states); fuse the docking array's hydrophones as ranges, \
                     or its fixes loosely"
                        .into(),
                );
            }
        }
        if let Some(m) = &self.magnetometer {
            out.extend(m.problems().into_iter().map(|p| format!("navigation.{p}")));
        }
        out
    }
}

impl SessionConfig {
    /// Every value of the session's tables that makes no sense (`[navigation]`, `aid_delay_s`,
    /// `[alignment]`), as `key = value: expected …`.
    pub fn problems(&self) -> Vec<String> {
        let mut p = Problems(self.navigation.problems());
        p.range("aid_delay_s", self.aid_delay_s, 0.0, 1.0);
        if let Some(i) = &self.initial {
            p.position("initial", i.latitude_deg, i.longitude_deg, i.height_m);
            p.array("initial.velocity_ned_m_s", &i.velocity_ned_m_s, -50.0, 50.0);
            p.range("initial.euler_deg[0]", i.euler_deg[0], -180.0, 180.0);
            p.range("initial.euler_deg[1]", i.euler_deg[1], -90.0, 90.0);
            p.range("initial.euler_deg[2]", i.euler_deg[2], -360.0, 360.0);
        }
        if let Some(a) = &self.alignment {
            p.position("alignment", a.latitude_deg, a.longitude_deg, a.height_m);
            p.range("alignment.coarse_s", a.coarse_s, 10.0, 3600.0);
            p.range(
                "alignment.coarse_heading_std_deg",
                a.coarse_heading_std_deg,
                0.01,
                180.0,
            );
            p.range(
                "alignment.coarse_tilt_std_deg",
                a.coarse_tilt_std_deg,
                0.001,
                10.0,
            );
            p.range(
                "alignment.aligned_heading_std_deg",
                a.aligned_heading_std_deg,
                0.001,
                10.0,
            );
            p.range("alignment.fine_model", f64::from(a.fine_model), 0.0, 3.0);
            if a.heading_source == HeadingSource::Magnetometer
                && self.navigation.magnetometer.is_none()
            {
                p.0.push(
                    "alignment.heading_source = \"magnetometer\": needs a [navigation.magnetometer] \
                     table (its calibration and field model)"
                        .into(),
                );
            }
        }
        p.0
    }

    /// `Ok` when [`SessionConfig::problems`] finds none.
    pub fn validate(&self) -> Result<(), ConfigError> {
        let p = self.problems();
        if p.is_empty() {
            Ok(())
        } else {
            Err(ConfigError(p))
        }
    }
}

impl Default for DaemonConfig {
    /// The defaults of every key, without a start (`[initial]` or `[alignment]` must be added).
    fn default() -> Self {
        DaemonConfig {
            name: default_name(),
            prefix: default_prefix(),
            aid_delay_s: default_aid_delay(),
            health_period_s: default_health_period(),
            navigation: NavConfig::default(),
            initial: None,
            alignment: None,
            output: OutputConfig::default(),
            deadlines: Deadlines::default(),
            checkpoint: CheckpointConfig::default(),
        }
    }
}

impl DaemonConfig {
    /// Parses and validates the daemon's configuration file text.
    pub fn from_toml(text: &str) -> Result<DaemonConfig, ConfigError> {
        let cfg: DaemonConfig =
            toml::from_str(text).map_err(|e| ConfigError(vec![e.to_string()]))?;
        cfg.validate()?;
        Ok(cfg)
    }

    /// The configuration as TOML text (what `from_toml` reads back).
    pub fn to_toml(&self) -> Result<String, ConfigError> {
        toml::to_string(self).map_err(|e| ConfigError(vec![e.to_string()]))
    }

    /// Every problem of the file: the session's, the daemon's own ranges, and a missing start.
    pub fn validate(&self) -> Result<(), ConfigError> {
        let mut p = Problems(self.session().problems());
        p.range("health_period_s", self.health_period_s, 0.05, 60.0);
        p.range(
            "output.solution_decimation",
            f64::from(self.output.solution_decimation),
            1.0,
            1000.0,
        );
        let d = &self.deadlines;
        for (k, v) in [
            ("deadlines.imu_s", d.imu_s),
            ("deadlines.dvl_s", d.dvl_s),
            ("deadlines.depth_s", d.depth_s),
            ("deadlines.usbl_s", d.usbl_s),
            ("deadlines.gnss_s", d.gnss_s),
        ] {
            p.range(k, v, 0.0, 3600.0);
        }
        let c = &self.checkpoint;
        p.range("checkpoint.interval_s", c.interval_s, 0.1, 3600.0);
        p.range("checkpoint.drift_m_s", c.drift_m_s, 0.0, 50.0);
        p.range("checkpoint.max_age_s", c.max_age_s, 1.0, 1e6);
        p.range(
            "checkpoint.unknown_position_std_m",
            c.unknown_position_std_m,
            1.0,
            1e7,
        );
        p.name("name", &self.name);
        p.name("prefix", &self.prefix);
        if self.initial.is_none() && self.alignment.is_none() {
            p.0.push(
                "give [initial] (a known state) or [alignment] (a known position; the daemon \
                 finds the attitude)"
                    .into(),
            );
        }
        if p.0.is_empty() {
            Ok(())
        } else {
            Err(ConfigError(p.0))
        }
    }

    /// Problems of the files the daemon will write: each non-empty output path's folder must
    /// exist and the path must not be a folder (checked at start and by `--check-config`, not by
    /// the offline tools that read a configuration recorded elsewhere).
    pub fn path_problems(&self) -> Vec<String> {
        let mut out = Vec::new();
        for (key, path) in [
            ("output.nav_csv", &self.output.nav_csv),
            ("output.diagnostics_csv", &self.output.diagnostics_csv),
            ("output.stage_times_csv", &self.output.stage_times_csv),
            ("checkpoint.path", &self.checkpoint.path),
        ] {
            if let Some(p) = output_path_problem(path) {
                out.push(format!("{key} = {path:?}: {p}"));
            }
        }
        out
    }

    /// The session's part of the file.
    pub fn session(&self) -> SessionConfig {
        SessionConfig {
            aid_delay_s: self.aid_delay_s,
            navigation: self.navigation.clone(),
            initial: self.initial.clone(),
            alignment: self.alignment.clone(),
        }
    }
}
