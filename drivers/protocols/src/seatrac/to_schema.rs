//! Blueprint Subsea SeaTrac: its frames as the schema messages the driver publishes.

use crate::seatrac::AcoFix;
use auvnav_shm_schema::{AcousticRangesV1, UsblFixV1};

/// A SeaTrac `ACOFIX_T` as a USBL message.
///
/// The slant range is the device's; the one-way travel time is range / sound speed (this
/// avoids the question of which internal offsets the device's own time field includes).
/// Azimuth and elevation are taken as the schema defines them (azimuth from array x towards y,
/// elevation positive above the array's horizontal plane) — an assumption, as the sign of the
/// device's elevation is not stated in the material at hand. The device's position (easting,
/// northing, depth relative to the local beacon, attitude-compensated) is written as the
/// array-frame position `[northing, easting, depth]`: exact when the array frame is the
/// beacon's levelled, north-aligned frame, which is the frame the device reports in. SeaTrac
/// reports no range differences. `beacon_id` is the remote beacon (the fix's source).
pub fn seatrac_fix(f: &AcoFix, host_time_ns: u64, latency_s: f64, sequence: u64) -> UsblFixV1 {
    let latency_ns = (latency_s.max(0.0) * 1e9) as u64;
    let mut m = UsblFixV1 {
        host_time_ns,
        sequence,
        validity_time_ns: host_time_ns.saturating_sub(latency_ns),
        beacon_id: u32::from(f.source_id),
        ..Default::default()
    };
    let c = f.sound_speed_m_s;
    if (1375.0..=1650.0).contains(&c) {
        m.sound_speed_m_s = c;
        m.validity |= UsblFixV1::VALID_SOUND_SPEED;
    }
    if let Some(r) = &f.range
        && r.distance_m > 0.0
        && r.distance_m <= 10_000.0
    {
        m.slant_range_m = r.distance_m;
        if m.validity & UsblFixV1::VALID_SOUND_SPEED != 0 {
            m.travel_time_s = r.distance_m / c;
        }
        m.validity |= UsblFixV1::VALID_RANGE;
    }
    if let Some(u) = &f.usbl {
        let az = u.azimuth_deg.to_radians();
        let el = u.elevation_deg.to_radians();
        if az.abs() <= std::f64::consts::TAU && el.abs() <= std::f64::consts::FRAC_PI_2 {
            m.azimuth_rad = (az + std::f64::consts::PI).rem_euclid(std::f64::consts::TAU)
                - std::f64::consts::PI;
            m.elevation_rad = el;
            m.validity |= UsblFixV1::VALID_ANGLES;
        }
        if !u.channel_rssi_db.is_empty() {
            for (dst, src) in m.rssi_db.iter_mut().zip(&u.channel_rssi_db) {
                *dst = *src as f32;
            }
            m.validity |= UsblFixV1::VALID_RSSI;
        }
        if u.fit_error.is_finite() && (0.0..=1000.0).contains(&u.fit_error) {
            m.fit_error_m = u.fit_error as f32;
            m.validity |= UsblFixV1::VALID_FIT_ERROR;
        }
    }
    if let Some([east, north, depth]) = f.position_m {
        m.position_array_m = [north, east, depth];
        m.validity |= UsblFixV1::VALID_POSITION;
    }
    m
}

/// A SeaTrac fix's range as one range of an acoustic ranges message: receiver slot `slot`
/// (the beacon's place in the driver's `range_beacons`), for ranging LBL beacons one after the
/// other. `host_time_ns` is the time the reply arrived at the vehicle: the frame's time less
/// `latency_s` (the range aid takes a message's host time as the reception). `None` when the fix
/// has no range, or one outside 0..10 km.
pub fn seatrac_range(
    f: &AcoFix,
    slot: usize,
    host_time_ns: u64,
    latency_s: f64,
) -> Option<AcousticRangesV1> {
    let r = f.range.as_ref()?;
    if slot >= 4 || !(r.distance_m > 0.0 && r.distance_m <= 10_000.0) {
        return None;
    }
    let latency_ns = (latency_s.max(0.0) * 1e9) as u64;
    let mut m = AcousticRangesV1 {
        host_time_ns: host_time_ns.saturating_sub(latency_ns),
        validity: AcousticRangesV1::VALID_RANGE << slot,
        ..Default::default()
    };
    m.range_m[slot] = r.distance_m;
    Some(m)
}
