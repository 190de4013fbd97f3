//! The one feed path: every program that runs the navigation core over sensor messages — the
//! daemon on the bus, `auvnav replay` on a log, the Monte Carlo studies, the benchmarks and the
//! tests — hands each message to `Session::feed` (`crate::session`) as a [`SensorMessage`]. The
//! session decides the order in which aids meet the IMU stream (time stamp + aid delay, then
//! kind, then sequence), so a figure measured by any of them measures the code the daemon runs.
use auvnav_shm_schema::{
    DepthV1, DvlVelocityV1, GnssFixV1, ImuSampleV1, MagnetometerV1, UsblFixV1,
};

/// A sensor message for the navigation session.
#[derive(Debug, Clone, Copy)]
pub enum SensorMessage {
    Imu(ImuSampleV1),
    Dvl(DvlVelocityV1),
    Depth(DepthV1),
    Gnss(GnssFixV1),
    Usbl(UsblFixV1),
    Magnetometer(MagnetometerV1),
}

impl SensorMessage {
    /// The host time stamp (ns).
    pub fn host_time_ns(&self) -> u64 {
        match self {
            SensorMessage::Imu(m) => m.host_time_ns,
            SensorMessage::Dvl(m) => m.host_time_ns,
            SensorMessage::Depth(m) => m.host_time_ns,
            SensorMessage::Gnss(m) => m.host_time_ns,
            SensorMessage::Usbl(m) => m.host_time_ns,
            SensorMessage::Magnetometer(m) => m.host_time_ns,
        }
    }
}
