//! From decoded device frames to the schema messages the drivers publish. Pure: the caller
//! passes the host time at read return and the sequence number.
//!
//! Long on purpose: frames to schema messages for every device class with shared validity rules,
//! and its tests.

use crate::kvh::KvhSample;
use crate::nortek::BottomTrack;
use crate::pd0::{CoordinateSystem, Ensemble};
use crate::seatrac::AcoFix;
use crate::wldvl::Velocity;
use crate::xsens::MtData2;
use auvnav_shm_schema::{DvlVelocityV1, ImuSampleV1, MagnetometerV1, UsblFixV1};
use serde::{Deserialize, Serialize};

/// Standard gravity, for accelerometers that report in g (m/s^2).
pub const STANDARD_GRAVITY: f64 = 9.806_65;

/// A Water Linked `wrz` velocity report as a DVL message. The Water Linked frame (x forward,
/// y right, z down, vehicle velocity) is the schema's DVL frame. The time of validity is the host
/// read time minus the device's own latency (time of transmission minus time of validity).
/// The velocity is marked valid only when the device says so and it is finite.
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
            .all(|s| s.is_finite() && *s <= 10.0)
        {
            m.validity |= DvlVelocityV1::VALID_STD;
        }
    }
    if v.altitude_m.is_finite() && (0.0..=1000.0).contains(&v.altitude_m) {
        m.validity |= DvlVelocityV1::VALID_ALTITUDE;
    }
    m
}

/// How a KVH 1750/1775 is configured (=ROTFMT, =ROTUNITS, =TEMPUNITS, data rate): the messages
/// do not say.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct KvhConfig {
    /// Gyro fields are angle increments (=ROTFMT DELTA) rather than rates (=ROTFMT RATE).
    pub increments: bool,
    /// Gyro fields are in degrees (=ROTUNITS DEG) rather than radians.
    pub degrees: bool,
    /// Output rate (Hz).
    pub rate_hz: f64,
    /// Temperature field in hundredths of a degree rather than degrees (=TEMPUNITS).
    pub temperature_centi: bool,
}

/// A device's documented measurement range: a sample beyond it was not measured (a corrupted
/// value that passed the checksum, or a saturated sensor) and is flagged invalid.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ImuRange {
    /// Largest angular rate per axis (rad/s).
    pub max_rate_rad_s: f64,
    /// Largest specific force per axis (m/s²).
    pub max_specific_force_m_s2: f64,
}

/// KVH 1750/1775: ±490 °/s, accelerometers ±10 g (±30 g in the high-g option, taken here);
/// 10 % beyond for a saturated reading.
pub const KVH_RANGE: ImuRange = ImuRange {
    max_rate_rad_s: 490.0 * 1.1 * std::f64::consts::PI / 180.0,
    max_specific_force_m_s2: 30.0 * 1.1 * STANDARD_GRAVITY,
};

/// Xsens MTi: ±2000 °/s, accelerometers ±16 g (MTi-600: ±10 g; the larger range), 10 % beyond.
pub const XSENS_RANGE: ImuRange = ImuRange {
    max_rate_rad_s: 2000.0 * 1.1 * std::f64::consts::PI / 180.0,
    max_specific_force_m_s2: 16.0 * 1.1 * STANDARD_GRAVITY,
};

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

/// A KVH sample as an IMU message. Accelerometers report g (or g*s as increments); the axes are
/// the unit's case frame, which the driver's mounting configuration relates to the body.
pub fn kvh_sample(s: &KvhSample, cfg: &KvhConfig, host_time_ns: u64, sequence: u64) -> ImuSampleV1 {
    let angle_scale = if cfg.degrees {
        std::f64::consts::PI / 180.0
    } else {
        1.0
    };
    let interval_s = if cfg.rate_hz > 0.0 {
        1.0 / cfg.rate_hz
    } else {
        f64::NAN
    };
    let mut status = 0;
    if s.gyro_valid().iter().all(|&v| v) {
        status |= ImuSampleV1::STATUS_GYRO_VALID;
    }
    if s.accel_valid().iter().all(|&v| v) {
        status |= ImuSampleV1::STATUS_ACCEL_VALID;
    }
    if cfg.increments {
        status |= ImuSampleV1::STATUS_INCREMENTS;
    }
    let temperature_c = if cfg.temperature_centi {
        f32::from(s.temperature_raw) / 100.0
    } else {
        f32::from(s.temperature_raw)
    };
    if (-60.0..=120.0).contains(&temperature_c) {
        status |= ImuSampleV1::STATUS_TEMPERATURE_VALID;
    }
    let device_time_ns = match s.timestamp_us {
        Some(t) => {
            status |= ImuSampleV1::STATUS_DEVICE_TIME_VALID;
            u64::from(t) * 1000
        }
        None => 0,
    };
    ImuSampleV1 {
        host_time_ns,
        device_time_ns,
        sequence,
        angular: s.gyro.map(|g| f64::from(g) * angle_scale),
        specific: s.accel.map(|a| f64::from(a) * STANDARD_GRAVITY),
        interval_s,
        temperature_c,
        status,
    }
}

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

/// A DVL message read at `host_time_ns` from a device that reports no latency: valid at the read
/// time minus `latency_s` (the driver configuration's).
fn dvl_message(host_time_ns: u64, latency_s: f64, sequence: u64) -> DvlVelocityV1 {
    let latency_ns = (latency_s.max(0.0) * 1e9) as u64;
    DvlVelocityV1 {
        host_time_ns,
        sequence,
        validity_time_ns: host_time_ns.saturating_sub(latency_ns),
        ..Default::default()
    }
}

/// The altitude as the mean of the beams' valid vertical distances (none: not valid).
fn set_altitude(m: &mut DvlVelocityV1, vertical: &[f64]) {
    if !vertical.is_empty() {
        m.altitude_m = vertical.iter().sum::<f64>() / vertical.len() as f64;
        m.validity |= DvlVelocityV1::VALID_ALTITUDE;
    }
}

/// The sound speed the device reports, when within the schema's range.
fn set_sound_speed(m: &mut DvlVelocityV1, c: f64) {
    if (1375.0..=1650.0).contains(&c) {
        m.sound_speed_m_s = c;
        m.validity |= DvlVelocityV1::VALID_SOUND_SPEED;
    }
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

#[cfg(test)]
mod tests {

    #[test]
    fn pd0_clock_dates_follow_the_calendar() {
        // 2000-01-01 00:00:00.00 is the epoch; 2024-02-29 exists, 2023-02-29 and 31 February not.
        assert_eq!(pd0_rtc_ns(&[0, 1, 1, 0, 0, 0, 0]), Some(0));
        assert_eq!(
            pd0_rtc_ns(&[0, 1, 2, 0, 0, 1, 50]),
            Some(86_401_500_000_000)
        );
        assert!(pd0_rtc_ns(&[24, 2, 29, 12, 0, 0, 0]).is_some());
        assert_eq!(pd0_rtc_ns(&[23, 2, 29, 12, 0, 0, 0]), None);
        assert_eq!(pd0_rtc_ns(&[23, 2, 31, 12, 0, 0, 0]), None);
        assert_eq!(pd0_rtc_ns(&[23, 4, 31, 12, 0, 0, 0]), None);
        assert_eq!(pd0_rtc_ns(&[23, 4, 30, 24, 0, 0, 0]), None);
        assert_eq!(pd0_rtc_ns(&[23, 4, 30, 23, 59, 59, 100]), None);
        for ns in [
            0,
            86_401_500_000_000,
            762_000_123_450_000_000,
            3_155_759_999_990_000_000,
        ] {
            assert_eq!(pd0_rtc_ns(&pd0_rtc(ns)), Some(ns - ns % 10_000_000), "{ns}");
        }
    }

    use super::*;

    #[test]
    fn water_linked_report_becomes_a_dvl_message_with_its_latency_removed() {
        let v = Velocity {
            velocity_m_s: [0.12, -0.4, 2.0],
            valid: true,
            altitude_m: 1.3,
            figure_of_merit_m_s: 1.855,
            covariance: [1e-4, 0.0, 0.0, 0.0, 4e-4, 0.0, 0.0, 0.0, 9e-4],
            time_of_validity_us: 1_000,
            time_of_transmission_us: 151_000,
            time_since_last_ms: 123.0,
            status: 0,
        };
        let m = water_linked_velocity(&v, 10_000_000_000, 7);
        assert_eq!(m.validity_time_ns, 10_000_000_000 - 150_000_000);
        assert_eq!(m.velocity_dvl_m_s, [0.12, -0.4, 2.0]);
        assert!((m.velocity_std_m_s[1] - 0.02).abs() < 1e-12);
        let need = DvlVelocityV1::VALID_VELOCITY
            | DvlVelocityV1::VALID_STD
            | DvlVelocityV1::VALID_ALTITUDE;
        assert_eq!(m.validity & need, need);
        let invalid = water_linked_velocity(
            &Velocity {
                valid: false,
                altitude_m: -1.0,
                ..v
            },
            0,
            8,
        );
        assert_eq!(invalid.validity & need, 0);
    }

    #[test]
    fn kvh_sample_units_follow_the_configuration() {
        let s = KvhSample {
            gyro: [1.0, -2.0, 0.5],
            accel: [0.0, 0.0, -1.0],
            status: 0x77,
            sequence: 3,
            temperature_raw: 2950,
            timestamp_us: Some(12),
        };
        let cfg = KvhConfig {
            increments: false,
            degrees: true,
            rate_hz: 1000.0,
            temperature_centi: true,
        };
        let m = kvh_sample(&s, &cfg, 5, 9);
        assert!((m.angular[0] - 1f64.to_radians()).abs() < 1e-15);
        assert!((m.specific[2] + STANDARD_GRAVITY).abs() < 1e-12);
        assert!((m.temperature_c - 29.5).abs() < 1e-6);
        assert_eq!((m.interval_s, m.device_time_ns), (0.001, 12_000));
        let ok = ImuSampleV1::STATUS_GYRO_VALID
            | ImuSampleV1::STATUS_ACCEL_VALID
            | ImuSampleV1::STATUS_TEMPERATURE_VALID
            | ImuSampleV1::STATUS_DEVICE_TIME_VALID;
        assert_eq!(m.status, ok);
        // Gyros not yet valid (the "early" capture): the message says so.
        let early = kvh_sample(&KvhSample { status: 0x70, ..s }, &cfg, 5, 10);
        assert_eq!(early.status & ImuSampleV1::STATUS_GYRO_VALID, 0);
    }
}
