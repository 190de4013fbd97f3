//! KVH 1750/1775: its frames as the schema messages the driver publishes.

use crate::kvh::KvhSample;
use crate::schema_rules::*;
use auvnav_shm_schema::ImuSampleV1;
use serde::{Deserialize, Serialize};

/// How a KVH 1750/1775 is configured (=ROTFMT, =ROTUNITS, =TEMPUNITS, data rate): the messages
/// do not say.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct KvhConfig {
    /// Gyro fields are angle increments (=ROTFMT DELTA) rather than rates (=ROTFMT RATE).
    pub increments: bool,
    /// Gyro fields are in degrees (=ROTUNITS DEG) rather than radians.
    pub degrees: bool,
    /// Output rate (Hz).
    pub rate_hz: f64,
    /// Temperature field in hundredths of a degree rather than degrees (=TEMPUNITS).
    pub temperature_centi: bool,
}

/// KVH 1750/1775: ±490 °/s, accelerometers ±10 g (±30 g in the high-g option, taken here);
/// 10 % beyond for a saturated reading.
pub const KVH_RANGE: ImuRange = ImuRange {
    max_rate_rad_s: 490.0 * 1.1 * std::f64::consts::PI / 180.0,
    max_specific_force_m_s2: 30.0 * 1.1 * STANDARD_GRAVITY,
};

/// A KVH sample as an IMU message. Accelerometers report g (or g*s as increments); the axes are
/// the unit's case frame, which the driver's mounting configuration relates to the body.
pub fn kvh_sample(s: &KvhSample, cfg: &KvhConfig, host_time_ns: u64, sequence: u64) -> ImuSampleV1 {
    let angle_scale = if cfg.degrees {
        std::f64::consts::PI / 180.0
    } else {
        1.0
    };
    let interval_s = if cfg.rate_hz > 0.0 {
        1.0 / cfg.rate_hz
    } else {
        f64::NAN
    };
    let mut status = 0;
    if s.gyro_valid().iter().all(|&v| v) {
        status |= ImuSampleV1::STATUS_GYRO_VALID;
    }
    if s.accel_valid().iter().all(|&v| v) {
        status |= ImuSampleV1::STATUS_ACCEL_VALID;
    }
    if cfg.increments {
        status |= ImuSampleV1::STATUS_INCREMENTS;
    }
    let temperature_c = if cfg.temperature_centi {
        f32::from(s.temperature_raw) / 100.0
    } else {
        f32::from(s.temperature_raw)
    };
    if (-60.0..=120.0).contains(&temperature_c) {
        status |= ImuSampleV1::STATUS_TEMPERATURE_VALID;
    }
    let device_time_ns = match s.timestamp_us {
        Some(t) => {
            status |= ImuSampleV1::STATUS_DEVICE_TIME_VALID;
            u64::from(t) * 1000
        }
        None => 0,
    };
    ImuSampleV1 {
        host_time_ns,
        device_time_ns,
        sequence,
        angular: s.gyro.map(|g| f64::from(g) * angle_scale),
        specific: s.accel.map(|a| f64::from(a) * STANDARD_GRAVITY),
        interval_s,
        temperature_c,
        status,
    }
}
