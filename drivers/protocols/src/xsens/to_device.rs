//! Xsens MTi (XBus MTData2): schema messages encoded in its protocol (emulation).

use crate::xsens::{self, MtData2};
use auvnav_shm_schema::{ImuSampleV1, MagnetometerV1};

/// An IMU message as an Xsens MTData2 message: delta-q/delta-v in increment mode, rate of turn
/// and acceleration otherwise, with packet counter, sample time fine and temperature.
pub fn xsens_from_imu(m: &ImuSampleV1, packet_counter: u16) -> Vec<u8> {
    let mut d = MtData2 {
        packet_counter: Some(packet_counter),
        sample_time_fine: (m.status & ImuSampleV1::STATUS_DEVICE_TIME_VALID != 0)
            .then_some((m.device_time_ns / 100_000) as u32),
        temperature_c: (m.status & ImuSampleV1::STATUS_TEMPERATURE_VALID != 0)
            .then_some(f64::from(m.temperature_c)),
        ..Default::default()
    };
    if m.status & ImuSampleV1::STATUS_INCREMENTS != 0 {
        let a = m.angular;
        let angle = (a[0] * a[0] + a[1] * a[1] + a[2] * a[2]).sqrt();
        let (w, k) = if angle > 1e-15 {
            ((angle / 2.0).cos(), (angle / 2.0).sin() / angle)
        } else {
            (1.0, 0.5)
        };
        d.delta_q = Some([w, a[0] * k, a[1] * k, a[2] * k]);
        d.delta_v = Some(m.specific);
    } else {
        d.rate_of_turn = Some(m.angular);
        d.acceleration = Some(m.specific);
    }
    xsens::encode_mtdata2(&d)
}

/// A magnetometer message as an Xsens MTData2 message carrying the magnetic field in normalised
/// units of `unit_ut` µT (the inverse of [`super::to_schema::xsens_magnetometer`]), with packet
/// counter, sample time fine and temperature. An invalid field is sent as NaN.
pub fn xsens_from_magnetometer(m: &MagnetometerV1, unit_ut: f64, packet_counter: u16) -> Vec<u8> {
    let field = if m.validity & MagnetometerV1::VALID_FIELD != 0 {
        m.field_t.map(|b| b * 1e6 / unit_ut)
    } else {
        [f64::NAN; 3]
    };
    xsens::encode_mtdata2(&MtData2 {
        packet_counter: Some(packet_counter),
        sample_time_fine: (m.validity & MagnetometerV1::VALID_DEVICE_TIME != 0)
            .then_some((m.device_time_ns / 100_000) as u32),
        temperature_c: (m.validity & MagnetometerV1::VALID_TEMPERATURE != 0)
            .then_some(f64::from(m.temperature_c)),
        magnetic_field: Some(field),
        ..Default::default()
    })
}
