//! Water Linked DVL: its frames as the schema messages the driver publishes.

use crate::wldvl::Velocity;
use auvnav_shm_schema::DvlVelocityV1;

/// A Water Linked `wrz` velocity report as a DVL message. The Water Linked frame (x forward,
/// y right, z down, vehicle velocity) is the schema's DVL frame. The time of validity is the host
/// read time minus the device's own latency (time of transmission minus time of validity).
/// The velocity is marked valid only when the device says so and it is finite; its standard
/// deviations only when every one is above zero and at most 10 m/s (a zero variance is none
/// given: the navigator then uses its configured noise, not a perfect velocity).
pub fn water_linked_velocity(v: &Velocity, host_time_ns: u64, sequence: u64) -> DvlVelocityV1 {
    let latency_ns = v
        .time_of_transmission_us
        .saturating_sub(v.time_of_validity_us)
        .saturating_mul(1000);
    let mut m = DvlVelocityV1 {
        host_time_ns,
        device_time_ns: v.time_of_validity_us.saturating_mul(1000),
        sequence,
        validity_time_ns: host_time_ns.saturating_sub(latency_ns),
        velocity_dvl_m_s: v.velocity_m_s,
        velocity_std_m_s: [
            v.covariance[0].max(0.0).sqrt(),
            v.covariance[4].max(0.0).sqrt(),
            v.covariance[8].max(0.0).sqrt(),
        ],
        beam_velocity_m_s: [0.0; 4],
        beam_range_m: [0.0; 4],
        altitude_m: v.altitude_m,
        figure_of_merit_m_s: v.figure_of_merit_m_s,
        sound_speed_m_s: 0.0,
        validity: DvlVelocityV1::VALID_DEVICE_TIME,
        beams_used: 0,
    };
    let finite = v
        .velocity_m_s
        .iter()
        .all(|x| x.is_finite() && x.abs() < 20.0);
    if v.valid && finite {
        m.validity |= DvlVelocityV1::VALID_VELOCITY | DvlVelocityV1::VALID_FOM;
        if m.velocity_std_m_s
            .iter()
            .all(|s| s.is_finite() && *s > 0.0 && *s <= 10.0)
        {
            m.validity |= DvlVelocityV1::VALID_STD;
        }
    }
    if v.altitude_m.is_finite() && (0.0..=1000.0).contains(&v.altitude_m) {
        m.validity |= DvlVelocityV1::VALID_ALTITUDE;
    }
    m
}
