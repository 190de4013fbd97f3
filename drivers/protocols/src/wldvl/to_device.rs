//! Water Linked DVL: schema messages encoded in its protocol (emulation).

use crate::schema_rules::*;
use crate::wldvl::{self, Velocity, WlFrame};
use auvnav_shm_schema::DvlVelocityV1;

/// A DVL message as a Water Linked `wrz` line. The device clock is the message's device time (or
/// time of validity) in microseconds; time of transmission = validity + `latency_s`.
pub fn wrz_from_dvl(m: &DvlVelocityV1, latency_s: f64) -> Vec<u8> {
    let tov_us = dvl_device_time_ns(m) / 1000;
    let var = |i: usize| {
        if m.validity & DvlVelocityV1::VALID_STD != 0 {
            m.velocity_std_m_s[i] * m.velocity_std_m_s[i]
        } else {
            0.0
        }
    };
    let v = Velocity {
        velocity_m_s: m.velocity_dvl_m_s,
        valid: m.validity & DvlVelocityV1::VALID_VELOCITY != 0,
        altitude_m: if m.validity & DvlVelocityV1::VALID_ALTITUDE != 0 {
            m.altitude_m
        } else {
            -1.0
        },
        figure_of_merit_m_s: m.figure_of_merit_m_s,
        covariance: [var(0), 0.0, 0.0, 0.0, var(1), 0.0, 0.0, 0.0, var(2)],
        time_of_validity_us: tov_us,
        time_of_transmission_us: tov_us + (latency_s.max(0.0) * 1e6).round() as u64,
        time_since_last_ms: 0.0,
        status: 0,
    };
    wldvl::encode(&WlFrame::Velocity(v))
}
