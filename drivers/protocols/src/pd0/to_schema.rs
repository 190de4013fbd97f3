//! Teledyne RDI PD0: its frames as the schema messages the driver publishes.

use crate::pd0::{CoordinateSystem, Ensemble};
use crate::schema_rules::*;
use auvnav_shm_schema::DvlVelocityV1;

/// The epoch of PD0 times: 2000-01-01 00:00 (PD0's two-digit years count from 2000).
fn pd0_epoch() -> chrono::NaiveDateTime {
    chrono::NaiveDate::from_ymd_opt(2000, 1, 1)
        .and_then(|d| d.and_hms_opt(0, 0, 0))
        .unwrap_or_default()
}

/// PD0's real-time clock (two-digit year from 2000, month, day, hour, minute, second,
/// hundredths) as nanoseconds since 2000-01-01 00:00; `None` for an impossible date or time
/// (31 February, 29 February outside leap years, hour 24, ...), decided by the calendar of
/// `chrono`.
pub fn pd0_rtc_ns(rtc: &[u8; 7]) -> Option<u64> {
    let [yy, mo, dd, hh, mi, ss, cs] = *rtc;
    if cs > 99 {
        return None;
    }
    let t = chrono::NaiveDate::from_ymd_opt(2000 + i32::from(yy), u32::from(mo), u32::from(dd))?
        .and_hms_opt(u32::from(hh), u32::from(mi), u32::from(ss))?;
    let s = u64::try_from((t - pd0_epoch()).num_seconds()).ok()?;
    Some(s * 1_000_000_000 + u64::from(cs) * 10_000_000)
}

/// PD0's real-time clock for a time in ns since 2000-01-01 (the inverse of [`pd0_rtc_ns`] to the
/// hundredth; the year wraps after 2099 as the device's two digits do).
pub fn pd0_rtc(ns: u64) -> [u8; 7] {
    use chrono::{Datelike, Timelike};
    let total_cs = ns / 10_000_000;
    let t = pd0_epoch() + chrono::TimeDelta::seconds((total_cs / 100) as i64);
    [
        (t.year() - 2000).rem_euclid(100) as u8,
        t.month() as u8,
        t.day() as u8,
        t.hour() as u8,
        t.minute() as u8,
        t.second() as u8,
        (total_cs % 100) as u8,
    ]
}

/// System configuration bit of a convex transducer head (clear: concave).
pub const PD0_CONVEX: u16 = 0x0008;

/// An RDI PD0 ensemble as a DVL message, or `None` when it has no bottom-track block.
///
/// Axes: RDI instrument and ship coordinates are x starboard, y forward, z up (beam 3 forward,
/// transducer down); the schema's DVL frame is x forward, y starboard, z down, so
/// `[x, y, z]_dvl = [y, x, -z]_rdi`. PD0 records the bottom's velocity relative to the
/// instrument; the vehicle's is its negative. Beam coordinates: the beam velocities are
/// published, and the velocity from them by RDI's beam-to-instrument transformation
/// ([`crate::pd0::beam_to_instrument`]; three beams suffice). Earth coordinates (east,
/// north, up) are rotated back to the instrument with the ensemble's own heading, pitch, roll and
/// EX bits ([`crate::pd0::earth_to_instrument`]), then taken as instrument coordinates. Ranges: PD0 gives vertical range per beam;
/// the schema's slant range is vertical / cos(beam angle). PD0 carries no latency, so the time
/// of validity is the read time minus `latency_s` from the driver configuration.
pub fn pd0_velocity(
    e: &Ensemble,
    host_time_ns: u64,
    latency_s: f64,
    sequence: u64,
) -> Option<DvlVelocityV1> {
    let bt = e.bottom_track.as_ref()?;
    let mut m = dvl_message(host_time_ns, latency_s, sequence);
    let system = e
        .fixed
        .as_ref()
        .map_or(CoordinateSystem::Beam, |f| f.coordinate_system);
    let beam_angle = e.fixed.as_ref().and_then(|f| f.beam_angle_deg);
    match system {
        CoordinateSystem::Instrument | CoordinateSystem::Ship => {
            if let Some(v) = bt.vehicle_velocity_m_s()
                && v.iter().all(|x| x.abs() < 20.0)
            {
                m.velocity_dvl_m_s = [v[1], v[0], -v[2]];
                m.validity |= DvlVelocityV1::VALID_VELOCITY;
                m.beams_used = 3;
                if let Some(err) = bt.velocity_m_s[3] {
                    m.figure_of_merit_m_s = err.abs();
                    m.validity |= DvlVelocityV1::VALID_FOM;
                    m.beams_used = 4;
                }
            }
        }
        CoordinateSystem::Beam => {
            let mut good = [None; 4];
            for (i, v) in bt.velocity_m_s.iter().enumerate() {
                if let Some(v) = v
                    && v.abs() < 20.0
                {
                    m.beam_velocity_m_s[i] = *v;
                    m.validity |= DvlVelocityV1::VALID_BEAM_VELOCITY << i;
                    m.beams_used += 1;
                    good[i] = Some(*v);
                }
            }
            // The instrument velocity from the beams (three-beam solution with one bad), then
            // as the instrument coordinates above.
            let convex = e
                .fixed
                .as_ref()
                .is_some_and(|f| f.system_configuration & PD0_CONVEX != 0);
            if let Some(angle) = beam_angle
                && let Some((v, error)) = crate::pd0::beam_to_instrument(&good, angle, convex)
                && v.iter().all(|x| x.abs() < 20.0)
            {
                m.velocity_dvl_m_s = [-v[1], -v[0], v[2]];
                m.validity |= DvlVelocityV1::VALID_VELOCITY;
                if let Some(err) = error {
                    m.figure_of_merit_m_s = err.abs();
                    m.validity |= DvlVelocityV1::VALID_FOM;
                }
            }
        }
        CoordinateSystem::Earth => {
            // Rotated back with the ensemble's heading, pitch, roll and EX bits, then as the
            // instrument coordinates above (the error velocity stands as it is).
            if let [Some(east), Some(north), Some(up), error] = bt.velocity_m_s
                && let Some(r) = crate::pd0::earth_to_instrument(e, [east, north, up])
                && r.iter().all(|x| x.abs() < 20.0)
            {
                m.velocity_dvl_m_s = [-r[1], -r[0], r[2]];
                m.validity |= DvlVelocityV1::VALID_VELOCITY;
                m.beams_used = 3;
                if let Some(err) = error {
                    m.figure_of_merit_m_s = err.abs();
                    m.validity |= DvlVelocityV1::VALID_FOM;
                    m.beams_used = 4;
                }
            }
        }
    }
    let mut vertical = Vec::with_capacity(4);
    for (i, r) in bt.range_m.iter().enumerate() {
        if let Some(r) = r
            && *r > 0.0
            && *r <= 1000.0
        {
            vertical.push(*r);
            if let Some(a) = beam_angle {
                m.beam_range_m[i] = r / a.to_radians().cos();
                m.validity |= DvlVelocityV1::VALID_BEAM_RANGE << i;
            }
        }
    }
    set_altitude(&mut m, &vertical);
    set_pd0_leader(&mut m, e);
    Some(m)
}

/// The sound speed and the device time of a PD0 ensemble's variable leader, when it has one.
fn set_pd0_leader(m: &mut DvlVelocityV1, e: &Ensemble) {
    if let Some(v) = &e.variable {
        set_sound_speed(m, v.sound_speed_m_s);
        if let Some(t) = pd0_rtc_ns(&v.rtc) {
            m.device_time_ns = t;
            m.validity |= DvlVelocityV1::VALID_DEVICE_TIME;
        }
    }
}

/// The water-track velocity of a PD0 ensemble: its bottom-track block's water-mass reference
/// layer (the water's velocity relative to the instrument, in the ensemble's coordinates and with
/// bottom track's sign convention) as the vehicle's velocity relative to the water in the DVL
/// frame, flagged `TRACK_WATER`; `None` without a usable layer (not computed, fewer than three
/// beams, earth coordinates). Time of validity, sound speed and device time as
/// [`pd0_velocity`]'s.
pub fn pd0_water_track(
    e: &Ensemble,
    host_time_ns: u64,
    latency_s: f64,
    sequence: u64,
) -> Option<DvlVelocityV1> {
    let bt = e.bottom_track.as_ref()?;
    let rl = &bt.reference_layer_velocity_m_s;
    let fixed = e.fixed.as_ref();
    let (r, error) = match fixed.map_or(CoordinateSystem::Beam, |f| f.coordinate_system) {
        CoordinateSystem::Instrument | CoordinateSystem::Ship => ([rl[0]?, rl[1]?, rl[2]?], rl[3]),
        CoordinateSystem::Beam => {
            let convex = fixed.is_some_and(|f| f.system_configuration & PD0_CONVEX != 0);
            crate::pd0::beam_to_instrument(rl, fixed?.beam_angle_deg?, convex)?
        }
        CoordinateSystem::Earth => {
            let r = crate::pd0::earth_to_instrument(e, [rl[0]?, rl[1]?, rl[2]?])?;
            (r, rl[3])
        }
    };
    if !r.iter().all(|x| x.is_finite() && x.abs() < 20.0) {
        return None;
    }
    let mut m = dvl_message(host_time_ns, latency_s, sequence);
    // The vehicle relative to the water is minus the water relative to the instrument; the DVL
    // frame from the instrument's as for bottom track.
    m.velocity_dvl_m_s = [-r[1], -r[0], r[2]];
    m.validity |= DvlVelocityV1::VALID_VELOCITY | DvlVelocityV1::TRACK_WATER;
    if let Some(err) = error {
        m.figure_of_merit_m_s = err.abs();
        m.validity |= DvlVelocityV1::VALID_FOM;
    }
    set_pd0_leader(&mut m, e);
    Some(m)
}
