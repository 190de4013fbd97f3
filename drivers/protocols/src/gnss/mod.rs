//! From a GNSS receiver's sentences or messages to [`GnssFixV1`]: the NMEA sentences of one
//! epoch gathered into one fix, a u-blox `NAV-PVT` converted as it is.
//!
//! **Epochs.** A receiver sends several sentences per fix (`RMC`, `VTG`, `GGA`, `GST`, `ZDA` in an
//! order of its own), all stamped with the same time of day, except `VTG` and `HDT`, which carry
//! none. An epoch ends when a sentence with another time arrives; after the first epoch the
//! gatherer knows which sentences the receiver sends per epoch, and an epoch that has them all is
//! finished at once instead of one fix period later.
//!
//! **Time.** The fix is valid at the host time of the epoch's first sentence minus the configured
//! latency. Its device time is GPS time, `UTC + leap seconds` (18 s since 2017-01-01,
//! configurable), when a date is known (`RMC`, `ZDA`, or the last date seen earlier on the same
//! day).
//!
//! **Uncertainty.** With `GST`: the RMS of the latitude and longitude standard deviations (per
//! axis) and the altitude standard deviation. Without: HDOP times the configured user equivalent
//! range error, twice that vertically. `NAV-PVT`: its horizontal and vertical accuracy estimates,
//! taken as one sigma per axis.
//!
//! **Velocity.** `NAV-PVT` gives NED velocity; NMEA only speed and course over ground (north and
//! east; down is 0), and only while the course is reported (receivers leave it empty when still).

pub mod to_device;

use crate::nmea::{Date, Gga, Gst, NmeaSentence, Rmc, TimeOfDay, Vtg};
use crate::ubx::NavPvt;
use auvnav_shm_schema::GnssFixV1;
use serde::{Deserialize, Serialize};

/// GPS time minus UTC since 2017-01-01 (s).
pub const GPS_MINUS_UTC_S: i32 = 18;
/// The GPS epoch, 1980-01-06 00:00:00 UTC, in Unix seconds.
pub const GPS_EPOCH_UNIX_S: i64 = 315_964_800;
const KNOT_M_S: f64 = 1852.0 / 3600.0;

/// GNSS receiver settings (`[settings.gnss]`).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct GnssSettings {
    /// One-sigma range error per unit of HDOP, for a fix without `GST` (m, 0.01..100, default 3).
    pub uere_m: f64,
    /// GPS time minus UTC (s, 0..100, default 18).
    pub leap_seconds: i32,
    /// Publish fixes only while the vehicle is at the surface: the latest depth on the bus is
    /// shallower than `surface_depth_m` and younger than `depth_timeout_s` (default true; false
    /// for a surface vessel).
    pub surface_only: bool,
    /// Deepest depth at which the antenna is out of the water (m, 0..10, default 0.5).
    pub surface_depth_m: f64,
    /// A depth older than this no longer says where the vehicle is (s, 0.1..60, default 3).
    pub depth_timeout_s: f64,
}

impl Default for GnssSettings {
    fn default() -> Self {
        GnssSettings {
            uere_m: 3.0,
            leap_seconds: GPS_MINUS_UTC_S,
            surface_only: true,
            surface_depth_m: 0.5,
            depth_timeout_s: 3.0,
        }
    }
}

/// The sentences of one epoch.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Epoch {
    pub time: Option<TimeOfDay>,
    /// Host time of the read that completed the epoch's first sentence (ns).
    pub host_time_ns: u64,
    pub gga: Option<Gga>,
    pub rmc: Option<Rmc>,
    pub vtg: Option<Vtg>,
    pub gst: Option<Gst>,
    pub date: Option<Date>,
    pub heading_deg: Option<f64>,
    kinds: u8,
}

const GGA: u8 = 1;
const RMC: u8 = 2;
const VTG: u8 = 4;
const GST: u8 = 8;
const ZDA: u8 = 16;
const HDT: u8 = 32;

fn kind(s: &NmeaSentence) -> u8 {
    match s {
        NmeaSentence::Gga(_) => GGA,
        NmeaSentence::Rmc(_) => RMC,
        NmeaSentence::Vtg(_) => VTG,
        NmeaSentence::Gst(_) => GST,
        NmeaSentence::Zda(_) => ZDA,
        NmeaSentence::Hdt { .. } => HDT,
        NmeaSentence::Other { .. } => 0,
    }
}

impl Epoch {
    fn add(&mut self, s: NmeaSentence) {
        self.kinds |= kind(&s);
        match s {
            NmeaSentence::Gga(g) => self.gga = Some(g),
            NmeaSentence::Rmc(r) => {
                if r.date.is_some() {
                    self.date = r.date;
                }
                self.rmc = Some(r);
            }
            NmeaSentence::Vtg(v) => self.vtg = Some(v),
            NmeaSentence::Gst(g) => self.gst = Some(g),
            NmeaSentence::Zda(z) => {
                if z.date.is_some() {
                    self.date = z.date;
                }
            }
            NmeaSentence::Hdt { heading_deg } => self.heading_deg = heading_deg,
            NmeaSentence::Other { .. } => {}
        }
    }

    /// Whether the epoch has a sentence with a position.
    pub fn has_position_sentence(&self) -> bool {
        self.kinds & (GGA | RMC) != 0
    }
}

/// Gathers NMEA sentences into epochs.
#[derive(Debug, Clone, Default)]
pub struct EpochGatherer {
    current: Option<Epoch>,
    /// The current epoch was finished early (it had every expected sentence).
    finished: bool,
    /// Every sentence kind seen with the current time, also after an early finish.
    kinds_at_time: u8,
    /// The sentence kinds of the last whole epoch.
    expected: u8,
    /// Time-less sentences that arrived after the current epoch finished: the next one's.
    carry: Vec<NmeaSentence>,
    carry_host_ns: u64,
    /// The last date seen and the time of day it was seen at.
    last_date: Option<(Date, TimeOfDay)>,
    ready: std::collections::VecDeque<Epoch>,
}

impl EpochGatherer {
    pub fn new() -> Self {
        Self::default()
    }

    /// Adds a sentence completed by a read that returned at `host_ns`.
    pub fn push(&mut self, s: NmeaSentence, host_ns: u64) {
        if matches!(s, NmeaSentence::Other { .. }) {
            return;
        }
        match s.time() {
            Some(t) => {
                let same = self.current.as_ref().is_some_and(|e| e.time == Some(t));
                if !same {
                    self.close();
                    let mut e = Epoch {
                        time: Some(t),
                        host_time_ns: host_ns,
                        ..Default::default()
                    };
                    if !self.carry.is_empty() {
                        e.host_time_ns = self.carry_host_ns;
                    }
                    for c in self.carry.drain(..) {
                        e.add(c);
                    }
                    self.kinds_at_time = e.kinds;
                    self.current = Some(e);
                    self.finished = false;
                }
                self.kinds_at_time |= kind(&s);
                if !self.finished
                    && let Some(e) = self.current.as_mut()
                {
                    e.add(s);
                }
            }
            None => {
                self.kinds_at_time |= kind(&s);
                match self.current.as_mut() {
                    Some(e) if !self.finished => e.add(s),
                    _ => {
                        if self.carry.is_empty() {
                            self.carry_host_ns = host_ns;
                        }
                        self.carry.push(s);
                    }
                }
            }
        }
        self.finish_if_complete();
    }

    fn finish_if_complete(&mut self) {
        if self.finished || self.expected == 0 {
            return;
        }
        if let Some(e) = &self.current
            && e.kinds & self.expected == self.expected
        {
            let e = e.clone();
            self.emit(e);
            self.finished = true;
        }
    }

    /// Ends the current epoch (a sentence of another time arrived).
    fn close(&mut self) {
        if let Some(e) = self.current.take() {
            if self.kinds_at_time & (GGA | RMC) != 0 {
                self.expected = self.kinds_at_time;
            }
            if !self.finished {
                self.emit(e);
            }
        }
        self.finished = false;
    }

    fn emit(&mut self, mut e: Epoch) {
        if let Some(t) = e.time {
            match e.date {
                Some(d) => self.last_date = Some((d, t)),
                None => {
                    // Earlier on the same day: the date still holds.
                    if let Some((d, seen)) = self.last_date
                        && seen <= t
                    {
                        e.date = Some(d);
                    }
                }
            }
        }
        if e.has_position_sentence() {
            self.ready.push_back(e);
        }
    }

    /// The next finished epoch with a position sentence.
    pub fn pop(&mut self) -> Option<Epoch> {
        self.ready.pop_front()
    }
}

fn clamp_std(v: f64) -> f64 {
    if v.is_finite() {
        v.clamp(0.01, 1000.0)
    } else {
        1000.0
    }
}

/// GPS time (ns since the GPS epoch) of a UTC instant in Unix nanoseconds.
pub fn gps_time_ns(unix_ns: i64, leap_seconds: i32) -> Option<u64> {
    let ns = unix_ns - GPS_EPOCH_UNIX_S * 1_000_000_000 + i64::from(leap_seconds) * 1_000_000_000;
    u64::try_from(ns).ok()
}

/// The fix of an epoch, valid at its first sentence's host time minus `latency_s`; `None` when
/// the receiver has no usable position in it (no fix, a warning status, an estimated position).
pub fn fix_from_epoch(e: &Epoch, s: &GnssSettings, latency_s: f64) -> Option<GnssFixV1> {
    let mut m = GnssFixV1 {
        host_time_ns: e
            .host_time_ns
            .saturating_sub((latency_s.max(0.0) * 1e9) as u64),
        ..Default::default()
    };
    let position = match (&e.gga, &e.rmc) {
        (Some(g), _) => {
            // 0 no fix, 6 estimated (dead reckoning), 7 manual input, 8 simulator.
            if !matches!(g.quality, 1..=5 | 9) {
                return None;
            }
            let (lat, lon) = (g.latitude_deg?, g.longitude_deg?);
            if matches!(g.quality, 2 | 4 | 5 | 9) {
                m.validity |= GnssFixV1::DIFFERENTIAL;
            }
            m.satellites = g.satellites.unwrap_or(0);
            if let (Some(alt), Some(sep)) = (g.altitude_msl_m, g.geoid_separation_m) {
                m.height_m = alt + sep;
                if (-1000.0..=10000.0).contains(&m.height_m) {
                    m.validity |= GnssFixV1::VALID_HEIGHT;
                }
            }
            (lat, lon)
        }
        (None, Some(r)) if r.valid => (r.latitude_deg?, r.longitude_deg?),
        _ => return None,
    };
    m.latitude_rad = position.0.to_radians();
    m.longitude_rad = position.1.to_radians();
    m.validity |= GnssFixV1::VALID_POSITION;
    let hdop_std = e
        .gga
        .as_ref()
        .and_then(|g| g.hdop)
        .map(|h| h * s.uere_m)
        .unwrap_or(10.0 * s.uere_m);
    let (h, v) = match &e.gst {
        Some(Gst {
            latitude_std_m: Some(a),
            longitude_std_m: Some(b),
            altitude_std_m,
            ..
        }) => {
            let h = ((a * a + b * b) / 2.0).sqrt();
            (h, altitude_std_m.unwrap_or(2.0 * h))
        }
        _ => (hdop_std, 2.0 * hdop_std),
    };
    m.horizontal_std_m = clamp_std(h);
    m.vertical_std_m = clamp_std(v);
    let speed_course = match (&e.rmc, &e.vtg) {
        (
            Some(Rmc {
                speed_knots: Some(v),
                course_deg: Some(c),
                ..
            }),
            _,
        )
        | (
            _,
            Some(Vtg {
                speed_knots: Some(v),
                course_deg: Some(c),
            }),
        ) => Some((v * KNOT_M_S, c.to_radians())),
        _ => None,
    };
    if let Some((v, c)) = speed_course
        && v.abs() < 100.0
    {
        m.velocity_ned_m_s = [v * c.cos(), v * c.sin(), 0.0];
        m.validity |= GnssFixV1::VALID_VELOCITY;
    }
    if let (Some(d), Some(t)) = (e.date, e.time) {
        let day = chrono::NaiveDate::from_ymd_opt(d.year, d.month, d.day)?;
        let unix_ns = day.and_hms_opt(0, 0, 0)?.and_utc().timestamp() * 1_000_000_000
            + i64::from(t.ms) * 1_000_000;
        if let Some(g) = gps_time_ns(unix_ns, s.leap_seconds) {
            m.device_time_ns = g;
            m.validity |= GnssFixV1::VALID_DEVICE_TIME;
        }
    }
    Some(m)
}

/// The fix of a `NAV-PVT` read at `host_ns`; `None` without a GNSS position (no fix, dead
/// reckoning or time only, or `gnssFixOK` clear).
pub fn fix_from_nav_pvt(
    p: &NavPvt,
    host_ns: u64,
    s: &GnssSettings,
    latency_s: f64,
) -> Option<GnssFixV1> {
    if p.flags & NavPvt::GNSS_FIX_OK == 0 || !matches!(p.fix_type, 2..=4) {
        return None;
    }
    let mut m = GnssFixV1 {
        host_time_ns: host_ns.saturating_sub((latency_s.max(0.0) * 1e9) as u64),
        latitude_rad: p.latitude_deg.to_radians(),
        longitude_rad: p.longitude_deg.to_radians(),
        height_m: p.height_m,
        horizontal_std_m: clamp_std(p.horizontal_accuracy_m),
        vertical_std_m: clamp_std(p.vertical_accuracy_m),
        satellites: u32::from(p.satellites),
        validity: GnssFixV1::VALID_POSITION,
        ..Default::default()
    };
    if p.fix_type != 2 && (-1000.0..=10000.0).contains(&p.height_m) {
        m.validity |= GnssFixV1::VALID_HEIGHT;
    }
    if p.velocity_ned_m_s.iter().all(|v| v.abs() < 100.0) {
        m.velocity_ned_m_s = p.velocity_ned_m_s;
        m.validity |= GnssFixV1::VALID_VELOCITY;
    }
    if p.flags & NavPvt::DIFF_SOLN != 0 || p.carrier_solution() != 0 {
        m.validity |= GnssFixV1::DIFFERENTIAL;
    }
    if let Some(g) = p.utc_ns().and_then(|u| gps_time_ns(u, s.leap_seconds)) {
        // The epoch is at the GPS time of week `iTOW`; the UTC fields differ from it by the
        // receiver's clock error (0.1 ms on a NEO-M8N). The week comes from the UTC date.
        const WEEK_NS: i64 = 7 * 86_400 * 1_000_000_000;
        let g = g as i64;
        let mut t = g - g.rem_euclid(WEEK_NS) + i64::from(p.itow_ms) * 1_000_000;
        if t - g > WEEK_NS / 2 {
            t -= WEEK_NS;
        } else if g - t > WEEK_NS / 2 {
            t += WEEK_NS;
        }
        m.device_time_ns = u64::try_from(t).unwrap_or(g as u64);
        m.validity |= GnssFixV1::VALID_DEVICE_TIME;
    }
    Some(m)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::nmea::{NmeaDecoder, sentence};

    fn gather(lines: &[&str]) -> (Vec<Epoch>, Vec<usize>) {
        // Returns the epochs and, for each, the index of the line after which it came out.
        let mut d = NmeaDecoder::new();
        let mut g = EpochGatherer::new();
        let (mut out, mut at) = (Vec::new(), Vec::new());
        for (i, l) in lines.iter().enumerate() {
            d.push(&sentence(l));
            while let Some(s) = d.next_sentence() {
                g.push(s.expect("good"), i as u64 * 10);
            }
            while let Some(e) = g.pop() {
                out.push(e);
                at.push(i);
            }
        }
        (out, at)
    }

    const EPOCH_1: [&str; 5] = [
        "GNRMC,003956.00,A,4552.65403,S,17030.00668,E,0.025,,120419,,,A,V",
        "GNVTG,,T,,M,0.025,N,0.045,K,A",
        "GNGGA,003956.00,4552.65403,S,17030.00668,E,1,12,0.64,14.2,M,1.8,M,,",
        "GNGST,003956.00,235111,,,,2.3,3.5,4.0",
        "GNZDA,003956.00,12,04,2019,00,00",
    ];

    #[test]
    fn after_the_first_epoch_a_complete_one_comes_out_at_its_last_sentence() {
        let mut lines: Vec<String> = EPOCH_1.iter().map(|s| s.to_string()).collect();
        for l in EPOCH_1 {
            lines.push(l.replace("003956.00", "003957.00"));
        }
        let refs: Vec<&str> = lines.iter().map(|s| s.as_str()).collect();
        let (epochs, at) = gather(&refs);
        // The first epoch ends when the second begins; the second as soon as its ZDA is in.
        assert_eq!(at, vec![5, 9]);
        let f = fix_from_epoch(&epochs[0], &GnssSettings::default(), 0.0).expect("a fix");
        assert_eq!(f.host_time_ns, 0);
        assert!((f.latitude_rad.to_degrees() + (45.0 + 52.65403 / 60.0)).abs() < 1e-9);
        assert!((f.height_m - 16.0).abs() < 1e-9);
        let expected_h = ((2.3f64 * 2.3 + 3.5 * 3.5) / 2.0).sqrt();
        assert!((f.horizontal_std_m - expected_h).abs() < 1e-12);
        assert_eq!(f.vertical_std_m, 4.0);
        assert_eq!(f.satellites, 12);
        // 2019-04-12 00:39:56 UTC is GPS week 2048, 5 d 00:40:14 (18 leap seconds).
        let gps_s = f.device_time_ns as f64 * 1e-9;
        assert_eq!(gps_s, (2048.0 * 7.0 + 5.0) * 86400.0 + 40.0 * 60.0 + 14.0);
        // No course while still: no velocity.
        assert_eq!(f.validity & GnssFixV1::VALID_VELOCITY, 0);
        assert_eq!(epochs[1].host_time_ns, 50);
    }

    #[test]
    fn a_fix_needs_a_position_and_a_date_from_earlier_the_same_day_serves() {
        let lines = [
            "GPGGA,235959.00,,,,,0,00,99.99,,,,,,",
            "GPRMC,235959.00,V,,,,,,,241126,,",
            "GPGGA,000000.00,4916.45,N,12311.12,W,6,08,1.0,10.0,M,0.0,M,,",
            "GPRMC,000000.00,A,4916.45,N,12311.12,W,,,,,",
            "GPGGA,000001.00,4916.45,N,12311.12,W,2,08,1.5,10.0,M,-2.0,M,,",
            "GPRMC,000001.00,A,4916.45,N,12311.12,W,10.0,090.0,,,",
            "GPGGA,000002.00,4916.45,N,12311.12,W,4,08,1.5,10.0,M,-2.0,M,,",
        ];
        let (epochs, _) = gather(&lines);
        let s = GnssSettings::default();
        let fixes: Vec<_> = epochs.iter().map(|e| fix_from_epoch(e, &s, 0.0)).collect();
        assert_eq!(fixes[0], None, "quality 0");
        assert_eq!(fixes[1], None, "quality 6 (estimated)");
        let f = fixes[2].expect("a differential fix");
        assert_ne!(f.validity & GnssFixV1::DIFFERENTIAL, 0);
        assert_eq!(f.horizontal_std_m, 4.5);
        // 23:59:59 on the 24th then 00:00:01: the old date no longer holds.
        assert_eq!(f.validity & GnssFixV1::VALID_DEVICE_TIME, 0);
        assert!((f.velocity_ned_m_s[1] - 10.0 * KNOT_M_S).abs() < 1e-9);
        assert!(f.velocity_ned_m_s[0].abs() < 1e-9);
    }
}
