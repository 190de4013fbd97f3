//! Xsens MTi (XBus MTData2): its frames as the schema messages the driver publishes.

use crate::schema_rules::*;
use crate::xsens::MtData2;
use auvnav_shm_schema::{ImuSampleV1, MagnetometerV1};

/// Xsens MTi: ±2000 °/s, accelerometers ±16 g (MTi-600: ±10 g; the larger range), 10 % beyond.
pub const XSENS_RANGE: ImuRange = ImuRange {
    max_rate_rad_s: 2000.0 * 1.1 * std::f64::consts::PI / 180.0,
    max_specific_force_m_s2: 16.0 * 1.1 * STANDARD_GRAVITY,
};

/// An Xsens MTData2 message as an IMU message, or `None` when it carries neither
/// delta-q/delta-v nor rate of turn/acceleration. Increments are preferred (they integrate
/// the full-rate signal); their interval is `1 / rate_hz` of the configured output rate.
/// Delta-q becomes the rotation vector 2·atan2(|q_v|, q_w)·q_v/|q_v|. The device time is the
/// sample time fine (100 us units).
pub fn xsens_sample(
    d: &MtData2,
    rate_hz: f64,
    host_time_ns: u64,
    sequence: u64,
) -> Option<ImuSampleV1> {
    let interval_s = if rate_hz > 0.0 {
        1.0 / rate_hz
    } else {
        f64::NAN
    };
    let mut m = ImuSampleV1 {
        host_time_ns,
        sequence,
        interval_s,
        ..Default::default()
    };
    if let (Some(q), Some(dv)) = (d.delta_q, d.delta_v) {
        let n = (q[1] * q[1] + q[2] * q[2] + q[3] * q[3]).sqrt();
        let angle = 2.0 * n.atan2(q[0]);
        let k = if n > 1e-15 { angle / n } else { 2.0 };
        m.angular = [q[1] * k, q[2] * k, q[3] * k];
        m.specific = dv;
        m.status |= ImuSampleV1::STATUS_INCREMENTS;
    } else if let (Some(w), Some(a)) = (d.rate_of_turn, d.acceleration) {
        m.angular = w;
        m.specific = a;
    } else {
        return None;
    }
    if m.angular.iter().all(|x| x.is_finite()) {
        m.status |= ImuSampleV1::STATUS_GYRO_VALID;
    }
    if m.specific.iter().all(|x| x.is_finite()) {
        m.status |= ImuSampleV1::STATUS_ACCEL_VALID;
    }
    if let Some(t) = xsens_temperature(d) {
        m.temperature_c = t;
        m.status |= ImuSampleV1::STATUS_TEMPERATURE_VALID;
    }
    if let Some(t) = xsens_device_time_ns(d) {
        m.device_time_ns = t;
        m.status |= ImuSampleV1::STATUS_DEVICE_TIME_VALID;
    }
    Some(m)
}

/// The temperature of an Xsens message when plausible (°C, −60..120).
fn xsens_temperature(d: &MtData2) -> Option<f32> {
    d.temperature_c
        .filter(|t| (-60.0..=120.0).contains(t))
        .map(|t| t as f32)
}

/// The device time of an Xsens message: sample time fine (units of 100 µs) in ns.
fn xsens_device_time_ns(d: &MtData2) -> Option<u64> {
    d.sample_time_fine.map(|t| u64::from(t) * 100_000)
}

/// The magnetic field of an Xsens MTData2 message as a magnetometer message: the normalised field
/// times `unit_ut` (µT per normalised unit), in tesla, in the sensor frame as sent (calibration
/// is the navigator's). None when the message carries no magnetic field. A non-finite or
/// implausible (|B| ≥ 1 mT) field is published without VALID_FIELD, so the navigator counts it.
pub fn xsens_magnetometer(
    d: &MtData2,
    unit_ut: f64,
    host_time_ns: u64,
    sequence: u64,
) -> Option<MagnetometerV1> {
    let b = d.magnetic_field?;
    let field_t = b.map(|x| x * unit_ut * 1e-6);
    let mut m = MagnetometerV1 {
        host_time_ns,
        sequence,
        field_t,
        ..Default::default()
    };
    let norm = field_t.iter().map(|x| x * x).sum::<f64>().sqrt();
    if norm.is_finite() && norm < 1e-3 {
        m.validity |= MagnetometerV1::VALID_FIELD;
    }
    if let Some(t) = xsens_temperature(d) {
        m.temperature_c = t;
        m.validity |= MagnetometerV1::VALID_TEMPERATURE;
    }
    if let Some(t) = xsens_device_time_ns(d) {
        m.device_time_ns = t;
        m.validity |= MagnetometerV1::VALID_DEVICE_TIME;
    }
    Some(m)
}
