//! Nortek DVL: its frames as the schema messages the driver publishes.

use crate::nortek::BottomTrack;
use crate::schema_rules::*;
use auvnav_shm_schema::DvlVelocityV1;

/// A Nortek DVL bottom-track record as a DVL message. The record's X, Y, Z is taken as the
/// vehicle's velocity in the head frame (X along beam 1, Z out of the transducer face, right
/// handed): with the head looking down and beam 1 forward that is the DVL frame (x forward,
/// y starboard, z down) as it stands; any other installation is the DVL mounting of the
/// navigation configuration. Z is the mean of Z1 and Z2 when both are valid. The velocity is
/// valid when X, Y and a Z are (neither the −32.768 m/s sentinel nor the invalid figure of merit
/// 10 m/s). The figure of merit published is the larger of X's and Y's; the record carries no
/// standard deviation and no beam angle, so neither the std nor slant ranges are published; the
/// altitude is the mean of the beams' vertical distances. Nortek records carry no latency: the
/// time of validity is the read time minus `latency_s`.
pub fn nortek_velocity(
    bt: &BottomTrack,
    host_time_ns: u64,
    latency_s: f64,
    sequence: u64,
) -> DvlVelocityV1 {
    let mut m = dvl_message(host_time_ns, latency_s, sequence);
    let [x, y, z1, z2] = bt.xyz;
    let z = match (z1.valid(), z2.valid()) {
        (true, true) => Some(0.5 * (f64::from(z1.velocity_m_s) + f64::from(z2.velocity_m_s))),
        (true, false) => Some(f64::from(z1.velocity_m_s)),
        (false, true) => Some(f64::from(z2.velocity_m_s)),
        (false, false) => None,
    };
    if let Some(z) = z
        && x.valid()
        && y.valid()
    {
        let v = [f64::from(x.velocity_m_s), f64::from(y.velocity_m_s), z];
        if v.iter().all(|c| c.abs() < 20.0) {
            m.velocity_dvl_m_s = v;
            m.validity |= DvlVelocityV1::VALID_VELOCITY;
            let fom = f64::from(x.figure_of_merit_m_s.max(y.figure_of_merit_m_s));
            if (0.0..=10.0).contains(&fom) {
                m.figure_of_merit_m_s = fom;
                m.validity |= DvlVelocityV1::VALID_FOM;
            }
        }
    }
    m.beams_used = bt.beam.iter().filter(|b| b.valid()).count() as u32;
    let distances: Vec<f64> = bt
        .beam_distance_m
        .iter()
        .map(|d| f64::from(*d))
        .filter(|d| *d > 0.0 && *d <= 1000.0)
        .collect();
    set_altitude(&mut m, &distances);
    set_sound_speed(&mut m, f64::from(bt.sound_speed_m_s));
    if let Some(t) = bt.unix_time_ns() {
        m.device_time_ns = t;
        m.validity |= DvlVelocityV1::VALID_DEVICE_TIME;
    }
    m
}
