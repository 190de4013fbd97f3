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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_zero_covariance_is_no_standard_deviation() {
        let mut v = Velocity {
            velocity_m_s: [0.3, 0.0, 0.01],
            valid: true,
            altitude_m: 20.0,
            figure_of_merit_m_s: 0.002,
            covariance: [4e-6, 0.0, 0.0, 0.0, 4e-6, 0.0, 0.0, 0.0, 9e-6],
            time_of_validity_us: 1_000_000,
            time_of_transmission_us: 1_020_000,
            time_since_last_ms: 200.0,
            status: 0,
        };
        let m = water_linked_velocity(&v, 5_000_000_000, 1);
        assert_ne!(m.validity & DvlVelocityV1::VALID_STD, 0);
        assert!((m.velocity_std_m_s[2] - 0.003).abs() < 1e-12);
        assert_eq!(m.validity_time_ns, 4_980_000_000);
        v.covariance = [0.0; 9];
        let m = water_linked_velocity(&v, 5_000_000_000, 2);
        assert_eq!(m.validity & DvlVelocityV1::VALID_STD, 0);
        assert_ne!(m.validity & DvlVelocityV1::VALID_VELOCITY, 0);
    }
}
