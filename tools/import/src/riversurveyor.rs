//! A SonTek RiverSurveyor (M9, S5) export: RiverSurveyor Live's MATLAB file.
//!
//! What the file holds (one row per sample, 1 s for the M9): `BottomTrack.BT_Vel` (east, north,
//! up, difference velocity in the configured coordinate system; the bottom's velocity relative to
//! the instrument, so the boat's is its negative), `System.Time` (the ADCP clock, seconds since
//! 2000-01-01 in the local time the clock was set to), the compass's `System.Heading` (magnetic)
//! and `System.True_North_ADP_Heading` (plus `Setup.magneticDeclination`), `Compass.Pitch` and
//! `Compass.Roll`, and every GGA and VTG sentence received during the sample
//! (`RawGPSData.Gga*`, with `GgaTimeStamp`, the ADCP clock when it arrived).
//!
//! Time base, established from the file itself:
//! - **The ADCP clock against UTC** from each GGA's receive stamp minus its UTC: the low (5 %)
//!   quantile of that difference, which is the clock's offset plus the shortest transmission
//!   delay (the ADCP clock on the Lake Caputh runs 1 h 7.86 s ahead of UTC). Each fix is placed
//!   on the ADCP clock at its UTC plus that offset, not at its arrival.
//! - **The moment a bottom-track velocity describes**: the sample averages the pings of the
//!   interval starting at `System.Time` (the sentences received during the interval are filed
//!   with it), so its time of validity is the interval's middle, `System.Time + Δ/2`.
//!   On the M9 lake run the GPS velocity over that interval matches the bottom track best at
//!   that time (within ±0.25 s).
//!
//! Output: the DVL channel in the instrument frame (x the compass's forward axis, y starboard,
//! z down; the earth-frame velocity rotated back with the sample's own heading, pitch and roll,
//! the inverse of what RiverSurveyor Live applied), a reference at each sample from the GPS
//! (position interpolated, velocity over ground over the sample's interval, vertical 0) with the
//! compass's attitude, the compass on the attitude channel, and every GGA fix as a GNSS fix. Time 0 is the first sample's start.

#[allow(unused_imports)]
use super::*;
use crate::gps_reference::{
    GpsSample, interpolate_gps, north_east_of, surface_reference, velocity_from_positions,
};
use crate::mat5::{MatFile, MatValue};
use crate::pd0::GpsVelocity;

/// Command-line arguments of `auvnav import riversurveyor`.
#[derive(Debug, Clone)]
#[cfg_attr(feature = "clap", derive(clap::Args))]
pub struct RiverSurveyorOptions {
    /// A RiverSurveyor Live MATLAB export (`.mat`, M9 or S5) with bottom track and GPS.
    pub file: PathBuf,
    /// Output log (written atomically).
    #[cfg_attr(feature = "clap", arg(long))]
    pub out: PathBuf,
    /// Where the reference velocity comes from: a straight line through the GGA positions of the
    /// sample's interval (the default: the M9's 10 Hz fixes), or VTG course and speed over
    /// ground averaged over it (`auto`: VTG when the file has it). The M9's VTG lags its
    /// positions: `auvnav discover` finds a time offset of −0.38 s against it, none against GGA.
    #[cfg_attr(feature = "clap", arg(long, value_enum, default_value_t = GpsVelocity::Gga))]
    pub velocity: GpsVelocity,
    /// One-sigma horizontal position uncertainty of a GGA fix at HDOP 1 (m); each fix's is this
    /// times its sample's HDOP.
    #[cfg_attr(feature = "clap", arg(long, default_value_t = 1.0))]
    pub gnss_std_m: f64,
    /// Print the summary as JSON.
    #[cfg_attr(feature = "clap", arg(long))]
    pub json: bool,
}

/// What `auvnav import riversurveyor` read and wrote.
#[derive(Debug, Clone, Default, Serialize)]
pub struct RiverSurveyorSummary {
    /// The instrument's serial number and the MAT file's header text.
    pub serial_number: String,
    pub mat_header: String,
    pub samples: u64,
    /// The sample interval (s, the median spacing of `System.Time`).
    pub interval_s: f64,
    /// Samples with a usable bottom-track velocity, and those left out (invalid or zero
    /// velocity, missing attitude, a time that does not increase).
    pub bottom_track_velocity: u64,
    pub bottom_track_invalid: u64,
    pub bad_time: u64,
    /// Compass samples written to the attitude channel.
    pub attitude: u64,
    /// Declination the export applied to the compass heading (deg, east positive).
    pub magnetic_declination_deg: f64,
    /// GGA sentences used, and those left out: no fix (quality 0, position 0), a UTC time that
    /// does not fit the ADCP clock (garbage time fields in a dropout), or a repeat of a UTC
    /// already used.
    pub gga: u64,
    pub gga_no_fix: u64,
    pub gga_bad_time: u64,
    pub gga_repeated: u64,
    pub vtg: u64,
    /// ADCP clock minus UTC (s), from the GGA receive stamps.
    pub adcp_clock_minus_utc_s: f64,
    /// The spread of the GGA transmission delay (s, 95th minus 5th percentile of receive stamp
    /// minus UTC).
    pub gga_delay_spread_s: f64,
    pub velocity: GpsVelocity,
    /// Reference records written (samples with GPS around them), and samples without.
    pub reference: u64,
    pub no_reference: u64,
    pub duration_s: f64,
    /// The first sample's date on the ADCP clock (`YYYY-MM-DD`, the local time it was set to).
    pub start_date: String,
}

/// Column-major numeric array `name` of struct `s`, checked to be `rows` × `cols`.
fn array<'a>(
    file: &'a MatFile,
    s: &str,
    name: &str,
    rows: Option<usize>,
    cols: usize,
) -> Result<(usize, &'a [f64])> {
    let Some(st) = file.get(s) else {
        malformed!("the file has no {s} struct (not a RiverSurveyor Live export?)");
    };
    let Some((dims, data)) = st.field(name).and_then(MatValue::numeric) else {
        malformed!("{s}.{name} is missing or not numeric");
    };
    // A vector is n × 1 or 1 × n; a matrix n × cols.
    let n = match dims {
        [r, 1] | [1, r] if cols == 1 => Some(*r),
        [r, c] if *c == cols => Some(*r),
        _ => None,
    }
    .filter(|r| rows.is_none_or(|n0| n0 == *r));
    let Some(n) = n else {
        malformed!(
            "{s}.{name} has dimensions {dims:?}, expected {} × {cols}",
            rows.map_or("n".to_string(), |r| r.to_string())
        );
    };
    Ok((n, data))
}

/// `hhmmss.ss` as seconds of the day, `None` for a field that is not a time.
fn utc_seconds(hms: f64) -> Option<f64> {
    if !(0.0..240_000.0).contains(&hms) {
        return None;
    }
    let h = (hms / 10_000.0).floor();
    let m = ((hms - h * 10_000.0) / 100.0).floor();
    let s = hms - h * 10_000.0 - m * 100.0;
    (m < 60.0 && s < 61.0).then_some(h * 3600.0 + m * 60.0 + s)
}

/// The `q`-quantile of `v` (sorted in place), `None` when empty.
fn quantile(v: &mut [f64], q: f64) -> Option<f64> {
    v.sort_by(f64::total_cmp);
    let i = ((v.len() as f64 - 1.0) * q).round() as usize;
    v.get(i).copied()
}

/// `x` wrapped into (−half, half].
fn wrap(x: f64, period: f64) -> f64 {
    let r = x.rem_euclid(period);
    if r > period / 2.0 { r - period } else { r }
}

const DAY_S: f64 = 86_400.0;

/// The messages of a RiverSurveyor export: DVL, truth (reference) and GNSS fixes in time
/// order, and the summary.
// Long on purpose: the file's arrays are read, placed on one clock and paired in one pass, with
// their counters.
pub fn riversurveyor_messages(
    file: &MatFile,
    velocity: GpsVelocity,
    gnss_std_m: f64,
) -> Result<(Vec<(&'static str, LogMessage)>, RiverSurveyorSummary)> {
    let mut s = RiverSurveyorSummary {
        mat_header: file.header.clone(),
        velocity,
        ..Default::default()
    };
    let setup = file.get("Setup");
    let coordinate_system = setup
        .and_then(|x| x.field("coordinateSystem"))
        .and_then(MatValue::scalar);
    if coordinate_system != Some(2.0) {
        malformed!(
            "Setup.coordinateSystem is {coordinate_system:?}: only earth coordinates (2) are \
             read (the bottom track is rotated back with the sample's attitude)"
        );
    }
    s.magnetic_declination_deg = setup
        .and_then(|x| x.field("magneticDeclination"))
        .and_then(MatValue::scalar)
        .unwrap_or(0.0);
    s.serial_number = match file.get("SystemHW").and_then(|x| x.field("SerialNumber")) {
        Some(MatValue::Char { text, .. }) => text.trim().to_string(),
        Some(v) => v.scalar().map(|x| x.to_string()).unwrap_or_default(),
        None => String::new(),
    };
    let (n, time) = array(file, "System", "Time", None, 1)?;
    if n == 0 {
        malformed!("System.Time holds no samples");
    }
    s.samples = n as u64;
    let rows = Some(n);
    let (_, heading) = array(file, "System", "True_North_ADP_Heading", rows, 1)?;
    let (_, pitch) = array(file, "Compass", "Pitch", rows, 1)?;
    let (_, roll) = array(file, "Compass", "Roll", rows, 1)?;
    let (_, bt) = array(file, "BottomTrack", "BT_Vel", rows, 4)?;
    let bt_depth = array(file, "BottomTrack", "BT_Depth", rows, 1)
        .ok()
        .map(|x| x.1);
    let draft = setup
        .and_then(|x| x.field("sensorDepth"))
        .and_then(MatValue::scalar)
        .unwrap_or(0.0);
    let (_, hdop) = array(file, "GPS", "HDOP", rows, 1)?;
    let (_, geoid) = array(file, "GPS", "GpsGeoid", rows, 1)?;
    let (_, sats) = array(file, "GPS", "Satellites", rows, 1)?;
    // Raw sentences: n rows, up to k sentences per row.
    let raw = |name: &str| -> Result<(usize, &[f64])> {
        let Some((dims, data)) = file
            .get("RawGPSData")
            .and_then(|r| r.field(name))
            .and_then(MatValue::numeric)
        else {
            malformed!("RawGPSData.{name} is missing or not numeric");
        };
        match dims {
            [r, k] if *r == n && data.len() == n * k => Ok((*k, data)),
            _ => malformed!("RawGPSData.{name} has dimensions {dims:?}, expected {n} × k"),
        }
    };
    let (k, gga_stamp) = raw("GgaTimeStamp")?;
    let gga_utc = raw("GgaUTC")?.1;
    let gga_lat = raw("GgaLatitude")?.1;
    let gga_lon = raw("GgaLongitude")?.1;
    let gga_alt = raw("GgaAltitude")?.1;
    let gga_quality = raw("GgaQuality")?.1;
    let vtg = match (
        raw("VtgTimeStamp"),
        raw("VtgTmgTrue"),
        raw("VtgSogMPS"),
        raw("VtgMode"),
    ) {
        (Ok((kv, st)), Ok(c), Ok(v), Ok(m)) => Some((kv, st, c.1, v.1, m.1)),
        _ => None,
    };
    // Sample interval and start.
    let mut steps: Vec<f64> = time.windows(2).map(|w| w[1] - w[0]).collect();
    let interval = quantile(&mut steps, 0.5)
        .filter(|d| *d > 0.0)
        .unwrap_or(1.0);
    s.interval_s = interval;
    let t0 = time[0];
    if !t0.is_finite() {
        malformed!("System.Time[0] is {t0}");
    }
    if t0 >= 0.0 {
        s.start_date = super::date_since_2000((t0 * 1e9) as u64);
    }
    // ADCP clock minus UTC from every fix's receive stamp.
    let fix_ok = |i: usize| {
        gga_quality[i] > 0.0
            && gga_stamp[i] > 0.0
            && gga_lat[i].abs() <= 90.0
            && gga_lon[i].abs() <= 180.0
            && (gga_lat[i] != 0.0 || gga_lon[i] != 0.0)
    };
    let mut differences: Vec<f64> = (0..n * k)
        .filter(|&i| fix_ok(i))
        .filter_map(|i| Some(wrap(gga_stamp[i] - utc_seconds(gga_utc[i])?, DAY_S)))
        .collect();
    // The offset's whole part can sit at either side of a day boundary; centre on the median.
    let median = quantile(&mut differences, 0.5);
    let offset = median.and_then(|m| {
        let mut d: Vec<f64> = differences.iter().map(|x| m + wrap(x - m, DAY_S)).collect();
        let lo = quantile(&mut d, 0.05)?;
        s.gga_delay_spread_s = quantile(&mut d, 0.95)? - lo;
        Some(lo)
    });
    s.adcp_clock_minus_utc_s = offset.unwrap_or(f64::NAN);
    // GGA fixes on the ADCP clock: (time from t0, lat deg, lon deg, ellipsoidal height m, hdop,
    // satellites).
    let mut fixes: Vec<(f64, f64, f64, f64, f64, f64)> = Vec::new();
    for row in 0..n {
        for j in 0..k {
            let i = row + n * j;
            if gga_quality[i] == 0.0 && gga_stamp[i] == 0.0 && gga_utc[i] == 0.0 {
                continue; // an unused slot of the row
            }
            if !fix_ok(i) {
                s.gga_no_fix += 1;
                continue;
            }
            let (Some(off), Some(utc)) = (offset, utc_seconds(gga_utc[i])) else {
                s.gga_bad_time += 1;
                continue;
            };
            // The fix's UTC on the ADCP clock, on the day of its receive stamp.
            let t = gga_stamp[i] + wrap(utc + off - gga_stamp[i], DAY_S);
            // A delay beyond a few seconds is not transmission: a time field that is wrong.
            if !(-0.5..=5.0).contains(&(gga_stamp[i] - t)) {
                s.gga_bad_time += 1;
                continue;
            }
            let h = gga_alt[i]
                + if geoid[row].is_finite() {
                    geoid[row]
                } else {
                    0.0
                };
            fixes.push((t - t0, gga_lat[i], gga_lon[i], h, hdop[row], sats[row]));
        }
    }
    fixes.sort_by(|a, b| a.0.total_cmp(&b.0));
    let before = fixes.len();
    fixes.dedup_by(|a, b| (a.0 - b.0).abs() < 1e-6);
    s.gga_repeated = (before - fixes.len()) as u64;
    s.gga = fixes.len() as u64;
    // VTG velocities (time, north, east) on the same clock, placed at their receive stamps less
    // the GGA's shortest delay.
    let mut vtg_samples: Vec<GpsSample> = Vec::new();
    if let Some((kv, stamp, course, speed, mode)) = vtg {
        // A VTG has no time of its own: it is placed at its receive stamp less the GGA's
        // median transmission delay.
        let delay = median.zip(offset).map_or(0.0, |(m, o)| m - o);
        for i in 0..n * kv {
            let c = course[i].to_radians();
            // Mode 'N' (78) is not valid; 0 is an unused slot.
            if stamp[i] > 0.0
                && mode[i] != 0.0
                && mode[i] != 78.0
                && c.is_finite()
                && speed[i].is_finite()
                && speed[i] >= 0.0
            {
                vtg_samples.push((
                    stamp[i] - delay - t0,
                    speed[i] * c.cos(),
                    speed[i] * c.sin(),
                ));
            }
        }
        vtg_samples.sort_by(|a, b| a.0.total_cmp(&b.0));
        vtg_samples.dedup_by(|a, b| a.0 == b.0);
    }
    s.vtg = vtg_samples.len() as u64;
    let use_vtg = match velocity {
        GpsVelocity::Vtg => true,
        GpsVelocity::Gga => false,
        GpsVelocity::Auto => vtg_samples.len() >= 2,
    };
    if use_vtg && vtg_samples.len() < 2 {
        bad_option!(
            "--velocity vtg: the file has {} VTG sentences",
            vtg_samples.len()
        );
    }
    // Local north/east of the fixes around the first.
    let positions = north_east_of(fixes.iter().map(|f| (f.0, f.1, f.2)));
    let mut out: Vec<(u64, u8, &'static str, LogMessage)> = Vec::new();
    for (seq, f) in fixes.iter().enumerate() {
        if f.0 < 0.0 {
            continue; // before the first sample: the log starts at 0
        }
        let std = gnss_std_m
            * if f.4.is_finite() && f.4 > 0.0 {
                f.4
            } else {
                1.0
            };
        let fix = GnssFixV1 {
            host_time_ns: ns(f.0),
            sequence: seq as u64,
            latitude_rad: f.1.to_radians(),
            longitude_rad: f.2.to_radians(),
            height_m: f.3,
            horizontal_std_m: std,
            vertical_std_m: 2.0 * std,
            satellites: if f.5.is_finite() {
                f.5.clamp(0.0, 255.0) as u32
            } else {
                0
            },
            validity: GnssFixV1::VALID_POSITION | GnssFixV1::VALID_HEIGHT,
            ..Default::default()
        };
        out.push((fix.host_time_ns, 0, topic::GNSS, LogMessage::Gnss(fix)));
    }
    let heights: Vec<GpsSample> = fixes.iter().map(|f| (f.0, f.3, 0.0)).collect();
    let lat_lon_deg: Vec<GpsSample> = fixes.iter().map(|f| (f.0, f.1, f.2)).collect();
    let mut last = f64::NEG_INFINITY;
    for row in 0..n {
        let start = time[row] - t0;
        if !start.is_finite() || start <= last || start < 0.0 {
            s.bad_time += 1;
            continue;
        }
        last = start;
        let t = start + interval / 2.0;
        let host = ns(t);
        let (psi, theta, phi) = (
            heading[row].to_radians(),
            pitch[row].to_radians(),
            roll[row].to_radians(),
        );
        let v = [bt[row], bt[row + n], bt[row + 2 * n], bt[row + 3 * n]];
        let attitude_ok = psi.is_finite() && theta.abs() < 1.0 && phi.abs() < 1.0;
        let q = UnitQuaternion::from_euler_angles(phi, theta, psi);
        if attitude_ok {
            let a = AttitudeV1 {
                host_time_ns: host,
                device_time_ns: ns_of((time[row] + interval / 2.0).max(0.0)),
                sequence: row as u64,
                euler_rad: [phi, theta, psi],
                declination_rad: s.magnetic_declination_deg.to_radians(),
                validity: AttitudeV1::VALID_ATTITUDE
                    | AttitudeV1::VALID_DEVICE_TIME
                    | AttitudeV1::HEADING_TRUE,
                ..Default::default()
            };
            s.attitude += 1;
            out.push((host, 1, topic::ATTITUDE, LogMessage::Attitude(a)));
        }
        let velocity_ok = v[..3].iter().all(|x| x.is_finite() && x.abs() < 20.0)
            && v[..3].iter().any(|x| *x != 0.0);
        if attitude_ok && velocity_ok {
            // The boat's velocity (the negative of the bottom's), east-north-up → north-east-
            // down, into the instrument frame with the attitude the export rotated it out with.
            let ned = nalgebra::Vector3::new(-v[1], -v[0], v[2]);
            let body = q.inverse() * ned;
            let mut d = DvlVelocityV1 {
                host_time_ns: host,
                device_time_ns: ns_of((time[row] + interval / 2.0).max(0.0)),
                sequence: row as u64,
                validity_time_ns: host,
                velocity_dvl_m_s: [body.x, body.y, body.z],
                validity: DvlVelocityV1::VALID_VELOCITY | DvlVelocityV1::VALID_DEVICE_TIME,
                beams_used: 3,
                ..Default::default()
            };
            if v[3].is_finite() && v[3].abs() < 10.0 {
                d.figure_of_merit_m_s = v[3].abs();
                d.validity |= DvlVelocityV1::VALID_FOM;
                d.beams_used = 4;
            }
            if let Some(depth) = bt_depth.map(|b| b[row] - draft)
                && depth > 0.0
                && depth < 1000.0
            {
                d.altitude_m = depth;
                d.validity |= DvlVelocityV1::VALID_ALTITUDE;
            }
            s.bottom_track_velocity += 1;
            out.push((host, 2, topic::DVL, LogMessage::Dvl(d)));
        } else {
            s.bottom_track_invalid += 1;
        }
        if !attitude_ok {
            s.no_reference += 1;
            continue;
        }
        let vel = if use_vtg {
            // The mean VTG velocity over the sample's interval.
            let lo = vtg_samples.partition_point(|x| x.0 < start);
            let hi = vtg_samples.partition_point(|x| x.0 < start + interval);
            let w = &vtg_samples[lo..hi];
            (!w.is_empty()).then(|| {
                let m = w.len() as f64;
                (
                    w.iter().map(|x| x.1).sum::<f64>() / m,
                    w.iter().map(|x| x.2).sum::<f64>() / m,
                )
            })
        } else {
            velocity_from_positions(&positions, t, interval / 2.0)
        };
        let max_gap = 1.5 * interval.max(0.2);
        let (Some(v_ne), Some(lat_lon), Some((h, _))) = (
            vel,
            interpolate_gps(&lat_lon_deg, t, max_gap),
            interpolate_gps(&heights, t, max_gap),
        ) else {
            s.no_reference += 1;
            continue;
        };
        let truth = surface_reference(host, s.reference, lat_lon, h, v_ne, [phi, theta, psi]);
        s.reference += 1;
        out.push((host, 3, topic::TRUTH, LogMessage::Truth(truth)));
    }
    out.sort_by_key(|&(t, order, _, _)| (t, order));
    s.duration_s = (time[n - 1] - t0 + interval).max(0.0);
    Ok((out.into_iter().map(|(_, _, t, m)| (t, m)).collect(), s))
}

/// Imports a RiverSurveyor Live MATLAB export into a log at `out` (written atomically).
pub fn riversurveyor(a: &RiverSurveyorOptions) -> Result<RiverSurveyorSummary> {
    if !(a.gnss_std_m > 0.0 && a.gnss_std_m <= 100.0) {
        bad_option!("--gnss-std-m {} is not in (0, 100]", a.gnss_std_m);
    }
    let bytes = std::fs::read(&a.file).read_context(|| format!("reading {}", a.file.display()))?;
    let file = crate::mat5::parse(&bytes)
        .map_err(|e| ImportError::Malformed(format!("{}: {e}", a.file.display())))?;
    let (messages, summary) = riversurveyor_messages(&file, a.velocity, a.gnss_std_m)?;
    if summary.reference == 0 {
        malformed!(
            "{}: no sample has GPS around it ({} GGA fixes used, {} without a fix, {} with a bad \
             time): nothing to compare the bottom track with",
            a.file.display(),
            summary.gga,
            summary.gga_no_fix,
            summary.gga_bad_time
        );
    }
    let header = import_header(
        "auvnav import riversurveyor",
        a.file.display().to_string(),
        format!(
            "SonTek RiverSurveyor (serial {}) bottom track, compass and GPS from a RiverSurveyor \
             Live MATLAB export; time 0 = the first sample's start on the ADCP clock; the ADCP \
             clock is UTC + {:.3} s",
            summary.serial_number, summary.adcp_clock_minus_utc_s
        ),
        &summary,
    );
    let mut header = header;
    super::dated_compass_notes(
        &mut header,
        &summary.start_date,
        Some(summary.magnetic_declination_deg),
    );
    write_log_atomically(&a.out, &header, |w: &mut LogWriter<_>| {
        w.declare::<GnssFixV1>(
            topic::GNSS,
            &note(&[(
                "source",
                "every GGA fix with a position (RawGPSData), at its UTC placed on the ADCP clock; height = GGA altitude + geoid separation; horizontal σ = --gnss-std-m × HDOP",
            )]),
        )?;
        w.declare::<AttitudeV1>(
            topic::ATTITUDE,
            &note(&[(
                "source",
                "the ADCP's internal compass: true heading (magnetic + the export's declination), pitch and roll, at the middle of the sample's interval",
            )]),
        )?;
        w.declare::<DvlVelocityV1>(
            topic::DVL,
            &note(&[(
                "source",
                "RiverSurveyor bottom track: the earth-frame velocity (east, north, up), negated (the boat's, not the bottom's) and rotated into the instrument frame (x forward, y starboard, z down) with the sample's compass heading (true: magnetic + the export's declination), pitch and roll; valid at the middle of the sample's interval",
            )]),
        )?;
        w.declare::<TruthStateV1>(
            topic::TRUTH,
            &note(&[(
                "source",
                "reference from GPS: GGA position interpolated to the sample's middle, velocity over ground over the sample's interval (VTG mean or a line through the GGA positions); attitude is the ADCP's own compass heading (true), pitch and roll (not independent of the bottom track's rotation); vertical velocity 0 (surface vessel); rates unknown (NaN)",
            )]),
        )?;
        for (t, m) in &messages {
            match m {
                LogMessage::Dvl(x) => w.write(t, x)?,
                LogMessage::Truth(x) => w.write(t, x)?,
                LogMessage::Gnss(x) => w.write(t, x)?,
                LogMessage::Attitude(x) => w.write(t, x)?,
                _ => {}
            }
        }
        Ok(())
    })
    .map_err(crate::error::output(&a.out))?;
    Ok(summary)
}

#[cfg(test)]
#[path = "riversurveyor_tests.rs"]
mod riversurveyor_tests;
