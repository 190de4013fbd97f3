//! The sensor messages a navigation session takes, as one type: what the bus, a log and a
//! simulator carry to the core's feed path (`auvnav_core::feed`). It lives with the messages so
//! that a reader of logs can hand them over without the navigation core.
use crate::{
    AcousticArrayPoseV1, AcousticRangesV1, DepthV1, DvlVelocityV1, GnssFixV1, ImuSampleV1,
    LateAidV1, MagnetometerV1, SoundVelocityV1, UsblFixV1,
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
    /// The speed of sound (a CTD), for `dvl_sound_speed_source = "topic"`.
    SoundVelocity(SoundVelocityV1),
    /// Ranges of an acoustic system, for the range aid (`[navigation.ranges]`).
    AcousticRanges(AcousticRangesV1),
    /// Where a moving acoustic array is, for the range aid: not an aid itself.
    AcousticArrayPose(AcousticArrayPoseV1),
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
            SensorMessage::SoundVelocity(m) => m.host_time_ns,
            SensorMessage::AcousticRanges(m) => m.host_time_ns,
            SensorMessage::AcousticArrayPose(m) => m.host_time_ns,
        }
    }

    /// The publisher's sequence number.
    pub fn sequence(&self) -> u64 {
        match self {
            SensorMessage::Imu(m) => m.sequence,
            SensorMessage::Dvl(m) => m.sequence,
            SensorMessage::Depth(m) => m.sequence,
            SensorMessage::Gnss(m) => m.sequence,
            SensorMessage::Usbl(m) => m.sequence,
            SensorMessage::Magnetometer(m) => m.sequence,
            SensorMessage::SoundVelocity(m) => m.sequence,
            SensorMessage::AcousticRanges(m) => m.sequence,
            SensorMessage::AcousticArrayPose(m) => m.sequence,
        }
    }

    /// The aid topic code of a late-aid record (`LateAidV1::TOPIC_*`); `None` for the IMU.
    pub fn aid_topic(&self) -> Option<u32> {
        Some(match self {
            SensorMessage::Imu(_) => return None,
            SensorMessage::Dvl(_) => LateAidV1::TOPIC_DVL,
            SensorMessage::Depth(_) => LateAidV1::TOPIC_DEPTH,
            SensorMessage::Gnss(_) => LateAidV1::TOPIC_GNSS,
            SensorMessage::Usbl(_) => LateAidV1::TOPIC_USBL,
            SensorMessage::Magnetometer(_) => LateAidV1::TOPIC_MAGNETOMETER,
            SensorMessage::SoundVelocity(_) => LateAidV1::TOPIC_SOUND_VELOCITY,
            SensorMessage::AcousticRanges(_) => LateAidV1::TOPIC_ACOUSTIC_RANGES,
            SensorMessage::AcousticArrayPose(_) => LateAidV1::TOPIC_ACOUSTIC_ARRAY_POSE,
        })
    }
}
