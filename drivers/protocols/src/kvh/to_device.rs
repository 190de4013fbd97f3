//! KVH 1750/1775: schema messages encoded in its protocol (emulation).

use super::to_schema::KvhConfig;
use crate::kvh::{self, KvhSample};
use crate::schema_rules::STANDARD_GRAVITY;
use auvnav_shm_schema::ImuSampleV1;

/// An IMU message as a KVH 1750 message (format B when the sample has a device time) in the
/// units `cfg` describes; `counter` is the unit's 8-bit sequence.
pub fn kvh_from_imu(m: &ImuSampleV1, cfg: &KvhConfig, counter: u8) -> Vec<u8> {
    let angle_scale = if cfg.degrees {
        180.0 / std::f64::consts::PI
    } else {
        1.0
    };
    let mut status = 0u8;
    if m.status & ImuSampleV1::STATUS_GYRO_VALID != 0 {
        status |= 0x07;
    }
    if m.status & ImuSampleV1::STATUS_ACCEL_VALID != 0 {
        status |= 0x70;
    }
    let temperature = if cfg.temperature_centi {
        f64::from(m.temperature_c) * 100.0
    } else {
        f64::from(m.temperature_c)
    };
    let s = KvhSample {
        gyro: m.angular.map(|g| (g * angle_scale) as f32),
        accel: m.specific.map(|a| (a / STANDARD_GRAVITY) as f32),
        status,
        sequence: counter,
        temperature_raw: temperature.round().clamp(-32768.0, 32767.0) as i16,
        timestamp_us: (m.status & ImuSampleV1::STATUS_DEVICE_TIME_VALID != 0)
            .then_some((m.device_time_ns / 1000) as u32),
    };
    kvh::encode(&s)
}
