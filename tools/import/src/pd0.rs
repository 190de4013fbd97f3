//! A PD0 file with GPS.

#[allow(unused_imports)]
use super::*;

/// How the GPS velocity of `auvnav import pd0` is formed.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize)]
#[cfg_attr(feature = "clap", derive(clap::ValueEnum))]
#[serde(rename_all = "snake_case")]
pub enum GpsVelocity {
    /// VTG course and speed over ground when the file has them, otherwise GGA positions.
    #[default]
    Auto,
    /// VTG course and speed over ground (interpolated to the ensemble).
    Vtg,
    /// A straight line through the GGA positions within ±1 s of the ensemble.
    Gga,
}

/// Command-line arguments of `auvnav import pd0`.
#[derive(Debug, Clone)]
#[cfg_attr(feature = "clap", derive(clap::Args))]
pub struct Pd0Options {
    /// A Teledyne RDI PD0 file with bottom track and GPS in WinRiver NMEA blocks (GGA, VTG).
    pub file: PathBuf,
    /// Output log (written atomically).
    #[cfg_attr(feature = "clap", arg(long))]
    pub out: PathBuf,
    /// Where the reference velocity comes from.
    #[cfg_attr(feature = "clap", arg(long, value_enum, default_value_t = GpsVelocity::Auto))]
    pub velocity: GpsVelocity,
    /// Position fixes logged elsewhere (a glider's or an AUV's surface fixes): CSV `time_s,
    /// latitude_deg, longitude_deg, depth_m, std_m` with time in seconds from the first ensemble
    /// (the format of `auvnav smooth --fixes`), written as GNSS fixes for `auvnav calibrate dvl`
    /// and `auvnav smooth`.
    #[cfg_attr(feature = "clap", arg(long))]
    pub fixes: Option<PathBuf>,
    /// Print the summary as JSON.
    #[cfg_attr(feature = "clap", arg(long))]
    pub json: bool,
}

/// What `auvnav import pd0` read and wrote.
#[derive(Debug, Clone, Serialize)]
pub struct Pd0Summary {
    pub ensembles: u64,
    /// Ensembles with a bottom-track velocity in ship or instrument coordinates.
    pub bottom_track_velocity: u64,
    /// Ensembles dropped: no real-time clock, or time going backwards.
    pub bad_time: u64,
    pub coordinate_system: String,
    pub gga: u64,
    pub vtg: u64,
    /// GGA sentences without a fix (left out).
    pub gga_no_fix: u64,
    /// Ensembles whose heading, pitch and roll were written to the attitude channel.
    pub attitude: u64,
    /// GGA fixes written as GNSS fixes (none with `--fixes`, whose fixes take their place).
    pub gnss_from_gga: u64,
    pub velocity: GpsVelocity,
    /// Reference records written (ensembles with GPS on both sides).
    pub reference: u64,
    pub duration_s: f64,
    /// Bytes the decoder skipped or could not decode (checksum errors, bad blocks).
    pub decoder_errors: u64,
    /// Fixes from `--fixes` written as GNSS fixes, and those outside the file's time span (left
    /// out).
    pub fixes_written: u64,
    pub fixes_outside: u64,
    /// Lines of the fix file that did not parse (left out).
    pub fixes_unparsable_lines: u64,
    /// The first ensemble's date on the DVL's clock (`YYYY-MM-DD`; empty without one).
    pub start_date: String,
    /// Where the heading is the ADCP's own compass (the fixed leader's sensor source): the
    /// heading bias (EB) it adds, the declination set in the instrument (deg, east positive).
    pub declination_applied_deg: Option<f64>,
}

/// The messages of a PD0 file with GPS: the DVL channel (bottom track, as the DVL driver
/// converts it) and a reference at each ensemble from the GPS (position, velocity over ground)
/// with the DVL's own heading, pitch and roll as attitude.
// Long on purpose: one pass over a PD0 stream with the GPS blocks between its ensembles, pairing
// each ensemble with its fix, with its counters.
pub fn pd0_messages(
    bytes: &[u8],
    velocity: GpsVelocity,
) -> Result<(Vec<(&'static str, LogMessage)>, Pd0Summary)> {
    use auvnav_protocols::pd0::{NmeaBlock, decode_all};
    use auvnav_protocols::to_schema::{pd0_rtc_ns, pd0_velocity};
    let (ensembles, stats) = decode_all(bytes);
    let mut s = Pd0Summary {
        ensembles: ensembles.len() as u64,
        bottom_track_velocity: 0,
        bad_time: 0,
        coordinate_system: String::new(),
        gga: 0,
        vtg: 0,
        gga_no_fix: 0,
        attitude: 0,
        gnss_from_gga: 0,
        velocity,
        reference: 0,
        duration_s: 0.0,
        decoder_errors: stats.checksum_errors + stats.malformed,
        fixes_written: 0,
        fixes_outside: 0,
        fixes_unparsable_lines: 0,
        start_date: String::new(),
        declination_applied_deg: None,
    };
    if let Some(f) = ensembles.iter().find_map(|e| e.fixed.as_ref()) {
        s.coordinate_system = format!("{:?}", f.coordinate_system).to_lowercase();
        // Sensor source bit 4: the heading comes from the transducer's own (magnetic) compass.
        if f.sensor_source & 0x10 != 0 {
            s.declination_applied_deg = Some(f.heading_bias_deg);
        }
    }
    // Ensemble times on the DVL's clock, seconds from the first ensemble.
    let mut t0: Option<u64> = None;
    let mut last = f64::NEG_INFINITY;
    let mut timed = Vec::new();
    for e in &ensembles {
        let Some(ns) = e.variable.as_ref().and_then(|v| pd0_rtc_ns(&v.rtc)) else {
            s.bad_time += 1;
            continue;
        };
        let first = *t0.get_or_insert(ns);
        if s.start_date.is_empty() {
            s.start_date = date_since_2000(first);
        }
        let t = (ns as i128 - first as i128) as f64 * 1e-9;
        if t <= last {
            s.bad_time += 1;
            continue;
        }
        last = t;
        timed.push((t, e));
    }
    // GPS samples on the same clock: sentence time = ensemble time − WinRiver's delta.
    // GGA fixes: (time, latitude deg, longitude deg, altitude m).
    let mut fixes: Vec<(f64, f64, f64, f64)> = Vec::new();
    // Per fix: quality, satellites, HDOP.
    let mut gga_quality: Vec<(u8, u8, f64)> = Vec::new();
    let mut vtg: Vec<GpsSample> = Vec::new();
    let mut seen_utc = std::collections::HashSet::new();
    for (t, e) in &timed {
        for n in &e.nmea {
            match n {
                NmeaBlock::Gga {
                    delta_time_s,
                    utc,
                    latitude_deg,
                    longitude_deg,
                    fix_quality,
                    altitude_m,
                    satellites,
                    hdop,
                    ..
                } => {
                    if *fix_quality == 0 || !latitude_deg.is_finite() {
                        s.gga_no_fix += 1;
                    } else if seen_utc.insert(utc.clone()) {
                        s.gga += 1;
                        fixes.push((
                            t - delta_time_s,
                            *latitude_deg,
                            *longitude_deg,
                            f64::from(*altitude_m),
                        ));
                        gga_quality.push((*fix_quality, *satellites, f64::from(*hdop)));
                    }
                }
                NmeaBlock::Vtg {
                    delta_time_s,
                    true_track_deg,
                    speed_over_ground_m_s,
                } => {
                    let c = f64::from(*true_track_deg).to_radians();
                    if c.is_finite() && speed_over_ground_m_s.is_finite() {
                        s.vtg += 1;
                        vtg.push((
                            t - delta_time_s,
                            speed_over_ground_m_s * c.cos(),
                            speed_over_ground_m_s * c.sin(),
                        ));
                    }
                }
                _ => {}
            }
        }
    }
    let mut order: Vec<usize> = (0..fixes.len()).collect();
    order.sort_by(|&a, &b| fixes[a].0.total_cmp(&fixes[b].0));
    let fixes: Vec<(f64, f64, f64, f64)> = order.iter().map(|&i| fixes[i]).collect();
    let gga_quality: Vec<(u8, u8, f64)> = order.iter().map(|&i| gga_quality[i]).collect();
    vtg.sort_by(|a, b| a.0.total_cmp(&b.0));
    vtg.dedup_by(|a, b| a.0 == b.0);
    let use_vtg = match velocity {
        GpsVelocity::Vtg => true,
        GpsVelocity::Gga => false,
        GpsVelocity::Auto => vtg.len() >= 2,
    };
    if use_vtg && vtg.len() < 2 {
        bad_option!("--velocity vtg: the file has {} VTG sentences", vtg.len());
    }
    // Local north/east (m) of the fixes around the first one.
    let positions = north_east_of(fixes.iter().map(|f| (f.0, f.1, f.2)));
    let heights: Vec<GpsSample> = fixes.iter().map(|f| (f.0, f.3, 0.0)).collect();
    let lat_lon_deg: Vec<GpsSample> = fixes.iter().map(|f| (f.0, f.1, f.2)).collect();
    let mut out = Vec::new();
    // Every GGA fix inside the file's time span as a GNSS fix (σ = 1 m × HDOP).
    for (f, q) in fixes.iter().zip(&gga_quality) {
        if f.0 < 0.0 {
            continue;
        }
        let std = if q.2.is_finite() && q.2 > 0.0 {
            q.2
        } else {
            1.0
        };
        let g = GnssFixV1 {
            host_time_ns: ns(f.0),
            sequence: s.gnss_from_gga,
            latitude_rad: f.1.to_radians(),
            longitude_rad: f.2.to_radians(),
            height_m: f.3,
            horizontal_std_m: std,
            vertical_std_m: 2.0 * std,
            satellites: u32::from(q.1),
            validity: GnssFixV1::VALID_POSITION
                | GnssFixV1::VALID_HEIGHT
                | if q.0 >= 2 { GnssFixV1::DIFFERENTIAL } else { 0 },
            ..Default::default()
        };
        s.gnss_from_gga += 1;
        out.push((g.host_time_ns, 3u8, topic::GNSS, LogMessage::Gnss(g)));
    }
    for (seq, (t, e)) in timed.iter().enumerate() {
        let host = ns(*t);
        if let Some(d) = pd0_velocity(e, host, 0.0, seq as u64) {
            if d.validity & DvlVelocityV1::VALID_VELOCITY != 0 {
                s.bottom_track_velocity += 1;
            }
            out.push((host, 1u8, topic::DVL, LogMessage::Dvl(d)));
        }
        let Some(v) = e.variable.as_ref() else {
            continue;
        };
        let euler = [
            v.roll_deg.to_radians(),
            v.pitch_deg.to_radians(),
            v.heading_deg.to_radians(),
        ];
        if euler.iter().all(|x| x.is_finite()) {
            let a = AttitudeV1 {
                host_time_ns: host,
                sequence: s.attitude,
                euler_rad: euler,
                validity: AttitudeV1::VALID_ATTITUDE,
                ..Default::default()
            };
            s.attitude += 1;
            out.push((host, 2, topic::ATTITUDE, LogMessage::Attitude(a)));
        }
        let vel = if use_vtg {
            interpolate_gps(&vtg, *t, 1.5)
        } else {
            velocity_from_positions(&positions, *t, 1.0)
        };
        let (Some(v_ne), Some(lat_lon), Some((h, _))) = (
            vel,
            interpolate_gps(&lat_lon_deg, *t, 1.5),
            interpolate_gps(&heights, *t, 1.5),
        ) else {
            continue;
        };
        let truth = surface_reference(host, s.reference, lat_lon, h, v_ne, euler);
        s.reference += 1;
        out.push((host, 0, topic::TRUTH, LogMessage::Truth(truth)));
    }
    out.sort_by_key(|&(t, order, _, _)| (t, order));
    s.duration_s = timed.last().map_or(0.0, |x| x.0);
    Ok((out.into_iter().map(|(_, _, t, m)| (t, m)).collect(), s))
}

/// Imports a PD0 file with GPS into a log at `out` (written atomically).
pub fn pd0(a: &Pd0Options) -> Result<Pd0Summary> {
    let bytes = std::fs::read(&a.file).read_context(|| format!("reading {}", a.file.display()))?;
    let (mut messages, mut summary) = pd0_messages(&bytes, a.velocity)?;
    let fix_file = a.fixes.as_deref().map(crate::fixes::read).transpose()?;
    if fix_file.is_some() {
        // The fixes logged elsewhere take the place of the file's own GGA.
        messages.retain(|(_, m)| !matches!(m, LogMessage::Gnss(_)));
        summary.gnss_from_gga = 0;
    }
    let gga_gnss = summary.gnss_from_gga > 0;
    let mut gnss = Vec::new();
    if let Some(f) = &fix_file {
        summary.fixes_unparsable_lines = f.unparsable_lines as u64;
        for fix in &f.fixes {
            if (0.0..=summary.duration_s).contains(&fix.time_s) {
                gnss.push(fix.to_gnss(gnss.len() as u64));
            } else {
                summary.fixes_outside += 1;
            }
        }
        summary.fixes_written = gnss.len() as u64;
    }
    if summary.reference == 0 && gnss.is_empty() {
        malformed!(
            "{}: no ensemble has GPS on both sides ({} GGA fixes, {} VTG) and no --fixes inside \
             its time span: nothing to compare the bottom track with",
            a.file.display(),
            summary.gga,
            summary.vtg
        );
    }
    let header = import_header(
        "auvnav import pd0",
        a.file.display().to_string(),
        "Teledyne RDI PD0 bottom track with GPS (WinRiver NMEA blocks); time 0 = first ensemble \
         on the DVL's clock",
        &summary,
    );
    let mut header = header;
    dated_compass_notes(
        &mut header,
        &summary.start_date,
        summary.declination_applied_deg,
    );
    write_log_atomically(&a.out, &header, |w: &mut LogWriter<_>| {
        w.declare::<DvlVelocityV1>(
            topic::DVL,
            &note(&[(
                "source",
                "PD0 bottom track converted as the DVL driver does (ship/instrument coordinates to x forward, y starboard, z down; the vehicle's velocity)",
            )]),
        )?;
        w.declare::<AttitudeV1>(
            topic::ATTITUDE,
            &note(&[(
                "source",
                "the DVL's own heading, pitch and roll (each ensemble's variable leader: its compass, with whatever heading alignment and declination the instrument was set to)",
            )]),
        )?;
        w.declare::<TruthStateV1>(
            topic::TRUTH,
            &note(&[(
                "source",
                "reference from GPS: GGA position and VTG course/speed over ground (or GGA position differences), interpolated to the ensemble; attitude is the DVL's own heading, pitch and roll (its compass, not independent); vertical velocity 0 (surface vessel); rates unknown (NaN)",
            )]),
        )?;
        if !gnss.is_empty() {
            w.declare::<GnssFixV1>(
                topic::GNSS,
                &note(&[(
                    "source",
                    "position fixes from --fixes (logged elsewhere), on the ensemble clock",
                )]),
            )?;
        } else if gga_gnss {
            w.declare::<GnssFixV1>(
                topic::GNSS,
                &note(&[(
                    "source",
                    "the file's GGA fixes (WinRiver NMEA blocks) at their sentence times on the ensemble clock; horizontal σ = 1 m × HDOP",
                )]),
            )?;
        }
        // The fixes in time order among the ensemble's messages.
        let mut next_fix = gnss.iter().peekable();
        for (t, m) in &messages {
            let t_ns = match m {
                LogMessage::Dvl(x) => x.host_time_ns,
                LogMessage::Truth(x) => x.host_time_ns,
                LogMessage::Attitude(x) => x.host_time_ns,
                LogMessage::Gnss(x) => x.host_time_ns,
                _ => 0,
            };
            while let Some(f) = next_fix.next_if(|f| f.host_time_ns <= t_ns) {
                w.write(topic::GNSS, f)?;
            }
            match m {
                LogMessage::Dvl(x) => w.write(t, x)?,
                LogMessage::Truth(x) => w.write(t, x)?,
                LogMessage::Attitude(x) => w.write(t, x)?,
                LogMessage::Gnss(x) => w.write(t, x)?,
                _ => {}
            }
        }
        for f in next_fix {
            w.write(topic::GNSS, f)?;
        }
        Ok(())
    })
    .map_err(crate::error::output(&a.out))?;
    Ok(summary)
}

#[cfg(test)]
mod pd0_tests {
    use super::*;

    #[test]
    fn bytes_without_ensembles_give_nothing_and_no_panic() {
        for bytes in [
            &b""[..],
            &[0x7f, 0x7f, 0xff, 0xff, 0, 0][..],
            &[0x55; 4096][..],
        ] {
            let (m, s) = pd0_messages(bytes, GpsVelocity::Auto).expect("no error");
            assert!(m.is_empty());
            assert_eq!(s.reference, 0);
        }
        assert!(pd0_messages(b"", GpsVelocity::Vtg).is_err());
    }
}
