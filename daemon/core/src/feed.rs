//! The one feed path: every program that runs the navigation core over sensor messages — the
//! daemon on the bus, `auvnav replay` on a log, the Monte Carlo studies, the benchmarks and the
//! tests — hands each message to [`Session::feed`] as a [`SensorMessage`]. The session decides
//! the order in which aids meet the IMU stream (time stamp + aid delay, then kind, then
//! sequence), so a figure measured by any of them measures the code the daemon runs.

use crate::session::{Session, SessionOutput};
use auvnav_shm_schema::{DepthV1, DvlVelocityV1, GnssFixV1, ImuSampleV1, UsblFixV1};

/// A sensor message for the navigation session.
#[derive(Debug, Clone, Copy)]
pub enum SensorMessage {
    Imu(ImuSampleV1),
    Dvl(DvlVelocityV1),
    Depth(DepthV1),
    Gnss(GnssFixV1),
    Usbl(UsblFixV1),
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
        }
    }
}

impl Session {
    /// Feeds one sensor message. IMU samples are processed at once (after the aid messages due
    /// before them); aid messages wait for their turn. Outputs go to `out`.
    pub fn feed<E>(
        &mut self,
        m: &SensorMessage,
        out: &mut dyn FnMut(SessionOutput) -> Result<(), E>,
    ) -> Result<(), E> {
        match m {
            SensorMessage::Imu(x) => return self.on_imu(x, out),
            SensorMessage::Dvl(x) => self.on_dvl(x),
            SensorMessage::Depth(x) => self.on_depth(x),
            SensorMessage::Gnss(x) => self.on_gnss(x),
            SensorMessage::Usbl(x) => self.on_usbl(x),
        }
        Ok(())
    }
}
