//! Topic (iceoryx2 service) names. Every process builds its service names from these constants
//! and a deployment prefix ([`service_name`]), so concurrent test runs never share topics. The log
//! channels carry the same names without the prefix.

/// IMU samples ([`crate::ImuSampleV1`]).
pub const IMU: &str = "imu";
/// DVL velocity ([`crate::DvlVelocityV1`]).
pub const DVL: &str = "dvl";
/// USBL fixes ([`crate::UsblFixV1`]).
pub const USBL: &str = "usbl";
/// Depth ([`crate::DepthV1`]).
pub const DEPTH: &str = "depth";
/// Magnetometer ([`crate::MagnetometerV1`]).
pub const MAGNETOMETER: &str = "magnetometer";
/// Per-receiver acoustic ranges with the device's fix ([`crate::AcousticRangesV1`]; fused by the
/// daemon's range aid, `[navigation.ranges]`).
pub const ACOUSTIC_RANGES: &str = "acoustic_ranges";
/// The pose of a moving acoustic array from its boat's GNSS and heading
/// ([`crate::AcousticArrayPoseV1`]).
pub const ACOUSTIC_ARRAY_POSE: &str = "acoustic_array_pose";
/// GNSS fixes ([`crate::GnssFixV1`]).
pub const GNSS: &str = "gnss";
/// The speed of sound from a CTD or sound-velocity probe ([`crate::SoundVelocityV1`]).
pub const SOUND_VELOCITY: &str = "sound_velocity";
/// Heading, pitch and roll from a compass or an AHRS ([`crate::AttitudeV1`]; written by the
/// importers of surface runs and read by dead reckoning, not yet fused by the daemon).
pub const ATTITUDE: &str = "attitude";
/// Navigation solution ([`crate::NavSolutionV1`]).
pub const NAV_SOLUTION: &str = "nav/solution";
/// Per-aid-source diagnostics ([`crate::AidDiagnosticsV1`]).
pub const NAV_AID_DIAGNOSTICS: &str = "nav/aid_diagnostics";
/// Aid messages the daemon applied late ([`crate::LateAidV1`]), for replay.
pub const NAV_LATE_AIDS: &str = "nav/late_aids";
/// The daemon's session starts and checkpoints ([`crate::SessionEventV1`]), for replay across
/// restarts.
pub const NAV_SESSION_EVENTS: &str = "nav/session_events";
/// Process health of every process ([`crate::ProcessHealthV1`]).
pub const HEALTH: &str = "health";
/// Raw device bytes of one driver ([`crate::RawBytesV1`]): `raw/<driver name>`.
pub fn raw(driver: &str) -> String {
    format!("raw/{driver}")
}
/// Simulated truth (log only, [`crate::TruthStateV1`]).
pub const TRUTH: &str = "truth";

/// The default deployment prefix of service names.
pub const DEFAULT_PREFIX: &str = "auvnav";

/// Every topic that carries sensor data into the fusion daemon.
pub const SENSOR_TOPICS: [&str; 9] = [
    IMU,
    DVL,
    USBL,
    DEPTH,
    MAGNETOMETER,
    GNSS,
    SOUND_VELOCITY,
    ACOUSTIC_RANGES,
    ACOUSTIC_ARRAY_POSE,
];

/// The iceoryx2 service name of `topic` under a deployment prefix: `"{prefix}/{topic}"`.
pub fn service_name(prefix: &str, topic: &str) -> String {
    format!("{prefix}/{topic}")
}
