//! What every device's conversion shares: standard gravity, the documented measurement ranges
//! beyond which a sample is not a measurement, and a DVL message's time of validity, altitude,
//! sound speed and device time.

use auvnav_shm_schema::{DvlVelocityV1, ImuSampleV1};

/// Standard gravity, for accelerometers that report in g (m/s^2).
pub const STANDARD_GRAVITY: f64 = 9.806_65;

/// A device's documented measurement range: a sample beyond it was not measured (a corrupted
/// value that passed the checksum, or a saturated sensor) and is flagged invalid.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ImuRange {
    /// Largest angular rate per axis (rad/s).
    pub max_rate_rad_s: f64,
    /// Largest specific force per axis (m/s²).
    pub max_specific_force_m_s2: f64,
}

impl ImuRange {
    /// Clears the validity of the gyro or accelerometer triad of `m` when a value is beyond the
    /// range (increments divided by the interval); false when it did.
    pub fn check(&self, m: &mut ImuSampleV1) -> bool {
        let per_s = if m.status & ImuSampleV1::STATUS_INCREMENTS != 0 {
            1.0 / m.interval_s
        } else {
            1.0
        };
        let within = |v: &[f64; 3], max: f64| v.iter().all(|x| (x * per_s).abs() <= max);
        let mut ok = true;
        if !within(&m.angular, self.max_rate_rad_s) {
            m.status &= !ImuSampleV1::STATUS_GYRO_VALID;
            ok = false;
        }
        if !within(&m.specific, self.max_specific_force_m_s2) {
            m.status &= !ImuSampleV1::STATUS_ACCEL_VALID;
            ok = false;
        }
        ok
    }
}

/// A DVL message read at `host_time_ns` from a device that reports no latency: valid at the read
/// time minus `latency_s` (the driver configuration's).
pub(crate) fn dvl_message(host_time_ns: u64, latency_s: f64, sequence: u64) -> DvlVelocityV1 {
    let latency_ns = (latency_s.max(0.0) * 1e9) as u64;
    DvlVelocityV1 {
        host_time_ns,
        sequence,
        validity_time_ns: host_time_ns.saturating_sub(latency_ns),
        ..Default::default()
    }
}

/// The altitude as the mean of the beams' valid vertical distances (none: not valid).
pub(crate) fn set_altitude(m: &mut DvlVelocityV1, vertical: &[f64]) {
    if !vertical.is_empty() {
        m.altitude_m = vertical.iter().sum::<f64>() / vertical.len() as f64;
        m.validity |= DvlVelocityV1::VALID_ALTITUDE;
    }
}

/// The sound speed the device reports, when within the schema's range.
pub(crate) fn set_sound_speed(m: &mut DvlVelocityV1, c: f64) {
    if (1375.0..=1650.0).contains(&c) {
        m.sound_speed_m_s = c;
        m.validity |= DvlVelocityV1::VALID_SOUND_SPEED;
    }
}

/// The device time of a DVL message in ns (its own, or the time of validity).
pub(crate) fn dvl_device_time_ns(m: &DvlVelocityV1) -> u64 {
    if m.validity & DvlVelocityV1::VALID_DEVICE_TIME != 0 {
        m.device_time_ns
    } else {
        m.validity_time_ns
    }
}
