//! `auvnav import`: measured data sets into auvnav logs.
//!
//! `snapir`: the Snapir AUV data set (13 segments of 400 s: `imu_NN.csv` 100 Hz specific force and
//! angular rate, `dvl_NN.csv` 1 Hz body-frame bottom-track velocity, `ref_NN.csv` the
//! post-processed INS reference at the DVL epochs). The IMU and the DVL become sensor channels,
//! the reference becomes the truth channel, and the reference depth (`-alt_m`) becomes a depth
//! channel whose metadata says it is derived from the reference, not an independent sensor.
//! Times are the files' own (0 at the segment start) in nanoseconds.

use anyhow::{Context, bail};
use auvnav_log::{LogHeader, LogMessage, LogWriter, write_log_atomically};
use auvnav_shm_schema::{DepthV1, DvlVelocityV1, GnssFixV1, ImuSampleV1, TruthStateV1, topic};
use nalgebra::UnitQuaternion;
use serde::Serialize;
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

/// Command-line arguments of `auvnav import snapir`.
#[derive(clap::Args, Debug, Clone)]
pub struct SnapirArgs {
    /// The data set folder (with imu_NN.csv, dvl_NN.csv, ref_NN.csv).
    pub dir: PathBuf,
    /// Segment number (1..13).
    #[arg(long)]
    pub segment: u32,
    /// Output log (MCAP).
    #[arg(long)]
    pub out: PathBuf,
    /// Time stamps: `nominal` (sample index at 100 Hz IMU / 1 Hz DVL and reference) or `file`
    /// (the files' time column, which spreads each file evenly over 0..400 s).
    #[arg(long, value_enum, default_value_t = TimeBase::Nominal)]
    pub time_base: TimeBase,
    /// Keep the reference on its own clock instead of aligning it to the IMU clock (see
    /// [`estimate_reference_offset`]).
    #[arg(long)]
    pub no_align: bool,
    /// Print the summary as JSON.
    #[arg(long)]
    pub json: bool,
}

/// How the imported samples are stamped.
///
/// The files' time columns are `linspace(0, 400, rows)` (IMU step 400/39999 s, DVL and reference
/// step 400/399 s), so the 1 Hz streams are stretched by 1 s over a segment against the 100 Hz
/// IMU. Stamping by sample index at the nominal rates makes the integrated gyro heading agree with
/// the reference far better (docs/measured-data.md), so it is the default.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum TimeBase {
    Nominal,
    File,
}

/// IMU rate of the data set (Hz).
pub const SNAPIR_IMU_HZ: f64 = 100.0;
/// DVL and reference rate of the data set (Hz).
pub const SNAPIR_DVL_HZ: f64 = 1.0;

/// Rows read and skipped per file.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize)]
pub struct FileCounts {
    pub rows: u64,
    /// Rows with a wrong field count, a field that is not a number, or a non-finite value.
    pub malformed: u64,
    /// Rows whose time does not increase (duplicates or out of order).
    pub out_of_order: u64,
}

#[derive(Debug, Clone, Serialize)]
pub struct SnapirSummary {
    pub segment: u32,
    pub time_base: TimeBase,
    /// The reference-to-IMU clock alignment, when done.
    pub alignment: Option<ClockAlignment>,
    /// Reference rows that fall before the first IMU sample after alignment (dropped).
    pub reference_before_imu: u64,
    pub imu: FileCounts,
    pub dvl: FileCounts,
    pub reference: FileCounts,
    pub duration_s: f64,
    pub messages: u64,
}

/// One parsed CSV file: rows of `N` numbers with an increasing first column.
struct Table<const N: usize> {
    rows: Vec<[f64; N]>,
    counts: FileCounts,
}

/// A reader of a CSV file as the import tools want it: fields trimmed, rows of any length
/// accepted (a row of the wrong length is the caller's to count, not a fatal error).
fn csv_reader(path: &Path) -> anyhow::Result<csv::Reader<std::fs::File>> {
    csv::ReaderBuilder::new()
        .flexible(true)
        .trim(csv::Trim::All)
        .from_path(path)
        .with_context(|| format!("reading {}", path.display()))
}

/// The next record of `reader`: `Ok(None)` at the end, `Ok(Some(Err(())))` for a row the CSV
/// reader rejects (invalid UTF-8), an error for an I/O failure.
fn next_record(
    reader: &mut csv::Reader<std::fs::File>,
    record: &mut csv::StringRecord,
    path: &Path,
) -> anyhow::Result<Option<Result<(), ()>>> {
    match reader.read_record(record) {
        Ok(true) => Ok(Some(Ok(()))),
        Ok(false) => Ok(None),
        Err(e) if matches!(e.kind(), csv::ErrorKind::Io(_)) => {
            Err(e).with_context(|| format!("reading {}", path.display()))
        }
        Err(_) => Ok(Some(Err(()))),
    }
}

fn read_table<const N: usize>(path: &Path, header: &str) -> anyhow::Result<Table<N>> {
    let mut reader = csv_reader(path)?;
    let found = reader
        .headers()
        .with_context(|| format!("reading the header of {}", path.display()))?
        .iter()
        .collect::<Vec<_>>()
        .join(",");
    if found != header {
        bail!(
            "{}: header is {found:?}, expected {header:?}",
            path.display()
        );
    }
    let mut t = Table {
        rows: Vec::new(),
        counts: FileCounts::default(),
    };
    let mut record = csv::StringRecord::new();
    while let Some(read) = next_record(&mut reader, &mut record, path)? {
        // A line of blanks only (a trailing line with spaces) is no row.
        if read.is_ok() && record.iter().all(str::is_empty) {
            continue;
        }
        t.counts.rows += 1;
        let mut row = [0.0; N];
        let ok = read.is_ok()
            && record.len() == N
            && record
                .iter()
                .zip(row.iter_mut())
                .all(|(field, v)| match field.parse::<f64>() {
                    Ok(x) if x.is_finite() => {
                        *v = x;
                        true
                    }
                    _ => false,
                });
        if !ok {
            t.counts.malformed += 1;
            continue;
        }
        if t.rows.last().is_some_and(|p| row[0] <= p[0]) || row[0] < 0.0 {
            t.counts.out_of_order += 1;
            continue;
        }
        t.rows.push(row);
    }
    if t.rows.is_empty() {
        bail!("{}: no usable rows", path.display());
    }
    Ok(t)
}

/// Replaces each row's time with its index at `hz`, the index recovered from the file's own
/// (median) spacing so that skipped rows leave a gap.
fn restamp<const N: usize>(rows: &mut [[f64; N]], hz: f64) {
    let Some(first) = rows.first() else {
        return;
    };
    let t0 = first[0];
    let mut spacing: Vec<f64> = rows.windows(2).map(|w| w[1][0] - w[0][0]).collect();
    spacing.sort_by(f64::total_cmp);
    let step = spacing.get(spacing.len() / 2).copied().unwrap_or(1.0 / hz);
    for r in rows.iter_mut() {
        let index = ((r[0] - t0) / step).round();
        r[0] = index / hz;
    }
}

/// The clock offset between a reference attitude series and a gyro.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct ClockAlignment {
    /// Add this to a reference time to get the IMU time of the same instant (s).
    pub offset_s: f64,
    /// RMS over the reference intervals of the angle between the reference's and the gyro's
    /// rotation over the interval, at the chosen offset (deg).
    pub residual_deg: f64,
    /// The same at zero offset (deg).
    pub residual_at_zero_deg: f64,
}

/// Search range of the clock alignment (s).
pub const ALIGNMENT_SEARCH_S: f64 = 2.0;
/// Step of the clock alignment search (s).
pub const ALIGNMENT_STEP_S: f64 = 0.01;

/// Estimates the clock offset between the IMU and the reference by comparing, over every
/// reference interval, the body rotation the reference attitude shows with the rotation the gyro
/// integrates over the same interval shifted by the offset; returns the offset with the smallest
/// RMS angle on a grid of `ALIGNMENT_STEP_S` over `±ALIGNMENT_SEARCH_S`. Earth rate is ignored
/// (0.004 deg per second). The reference attitude comes from an INS that shares nothing with this
/// clock, so the estimate uses the reference only to align clocks, never to correct the sensors.
pub fn estimate_reference_offset(imu: &[[f64; 7]], reference: &[[f64; 10]]) -> ClockAlignment {
    // Cumulative gyro attitude at each IMU time (body rotation from the first sample).
    let mut q = UnitQuaternion::identity();
    let mut cumulative = Vec::with_capacity(imu.len());
    cumulative.push(q);
    for w in imu.windows(2) {
        let dt = w[1][0] - w[0][0];
        let rate = nalgebra::Vector3::new(w[1][4], w[1][5], w[1][6]);
        q *= UnitQuaternion::from_scaled_axis(rate * dt);
        cumulative.push(q);
    }
    let times: Vec<f64> = imu.iter().map(|r| r[0]).collect();
    let at = |t: f64| -> Option<UnitQuaternion<f64>> {
        if !(times[0]..=times[times.len() - 1]).contains(&t) {
            return None;
        }
        let i = times.partition_point(|&x| x <= t).clamp(1, times.len() - 1);
        let w = (t - times[i - 1]) / (times[i] - times[i - 1]);
        Some(cumulative[i - 1].nlerp(&cumulative[i], w))
    };
    let attitude = |r: &[f64; 10]| UnitQuaternion::from_euler_angles(r[7], r[8], r[9]);
    let residual = |offset: f64| -> f64 {
        let (mut sum, mut n) = (0.0, 0usize);
        for pair in reference.windows(2) {
            let (Some(a), Some(b)) = (at(pair[0][0] + offset), at(pair[1][0] + offset)) else {
                continue;
            };
            let gyro = a.inverse() * b;
            let truth = attitude(&pair[0]).inverse() * attitude(&pair[1]);
            sum += (truth.inverse() * gyro).angle().powi(2);
            n += 1;
        }
        if n == 0 {
            f64::INFINITY
        } else {
            (sum / n as f64).sqrt()
        }
    };
    let steps = (ALIGNMENT_SEARCH_S / ALIGNMENT_STEP_S).round() as i64;
    let mut best = (f64::INFINITY, 0.0);
    for k in -steps..=steps {
        let offset = k as f64 * ALIGNMENT_STEP_S;
        let r = residual(offset);
        if r < best.0 {
            best = (r, offset);
        }
    }
    ClockAlignment {
        offset_s: best.1,
        residual_deg: best.0.to_degrees(),
        residual_at_zero_deg: residual(0.0).to_degrees(),
    }
}

fn ns(t: f64) -> u64 {
    (t * 1e9).round() as u64
}

/// The messages of one segment in time order, and the summary.
pub fn snapir_messages(
    dir: &Path,
    segment: u32,
    time_base: TimeBase,
    align: bool,
) -> anyhow::Result<(Vec<(&'static str, LogMessage)>, SnapirSummary)> {
    if !(1..=99).contains(&segment) {
        bail!("--segment {segment}: segments are numbered 1..13");
    }
    let file = |kind: &str| dir.join(format!("{kind}_{segment:02}.csv"));
    let imu = read_table::<7>(
        &file("imu"),
        "time_s,f_x_m_s2,f_y_m_s2,f_z_m_s2,w_x_rad_s,w_y_rad_s,w_z_rad_s",
    )?;
    let dvl = read_table::<4>(&file("dvl"), "time_s,v_x_m_s,v_y_m_s,v_z_m_s")?;
    let reference = read_table::<10>(
        &file("ref"),
        "time_s,lon_rad,lat_rad,alt_m,v_n_m_s,v_e_m_s,v_d_m_s,roll_rad,pitch_rad,yaw_rad",
    )?;
    // Re-stamp by row index when asked (rows skipped as malformed keep their slot).
    let (mut imu, mut dvl, mut reference) = (imu, dvl, reference);
    if time_base == TimeBase::Nominal {
        restamp(&mut imu.rows, SNAPIR_IMU_HZ);
        restamp(&mut dvl.rows, SNAPIR_DVL_HZ);
        restamp(&mut reference.rows, SNAPIR_DVL_HZ);
    }
    let alignment = align.then(|| estimate_reference_offset(&imu.rows, &reference.rows));
    let mut reference_before_imu = 0;
    if let Some(a) = alignment {
        let t0 = imu.rows[0][0];
        reference.rows.retain_mut(|r| {
            r[0] += a.offset_s;
            let keep = r[0] >= t0;
            reference_before_imu += u64::from(!keep);
            keep
        });
        if reference.rows.is_empty() {
            bail!("segment {segment}: no reference row is left after the clock alignment");
        }
    }
    let mut out: Vec<(u64, u8, &'static str, LogMessage)> = Vec::new();
    // The nominal interval: the median spacing of the IMU times.
    let mut spacing: Vec<f64> = imu.rows.windows(2).map(|w| w[1][0] - w[0][0]).collect();
    spacing.sort_by(f64::total_cmp);
    let nominal = spacing.get(spacing.len() / 2).copied().unwrap_or(0.01);
    let mut prev_t: Option<f64> = None;
    for (i, r) in imu.rows.iter().enumerate() {
        let interval = prev_t.map(|p| r[0] - p).unwrap_or(nominal);
        prev_t = Some(r[0]);
        let m = ImuSampleV1 {
            host_time_ns: ns(r[0]),
            device_time_ns: ns(r[0]),
            sequence: i as u64,
            angular: [r[4], r[5], r[6]],
            specific: [r[1], r[2], r[3]],
            interval_s: interval,
            temperature_c: f32::NAN,
            status: ImuSampleV1::STATUS_GYRO_VALID
                | ImuSampleV1::STATUS_ACCEL_VALID
                | ImuSampleV1::STATUS_DEVICE_TIME_VALID,
        };
        // Order within one time stamp: truth, then IMU, then aids.
        out.push((m.host_time_ns, 1, topic::IMU, LogMessage::Imu(m)));
    }
    for (i, r) in dvl.rows.iter().enumerate() {
        let m = DvlVelocityV1 {
            host_time_ns: ns(r[0]),
            device_time_ns: ns(r[0]),
            sequence: i as u64,
            validity_time_ns: ns(r[0]),
            velocity_dvl_m_s: [r[1], r[2], r[3]],
            velocity_std_m_s: [f64::NAN; 3],
            beam_velocity_m_s: [f64::NAN; 4],
            beam_range_m: [f64::NAN; 4],
            altitude_m: f64::NAN,
            figure_of_merit_m_s: f64::NAN,
            sound_speed_m_s: f64::NAN,
            validity: DvlVelocityV1::VALID_VELOCITY | DvlVelocityV1::VALID_DEVICE_TIME,
            beams_used: 0,
        };
        out.push((m.host_time_ns, 2, topic::DVL, LogMessage::Dvl(m)));
    }
    for (i, r) in reference.rows.iter().enumerate() {
        let (lon, lat, alt) = (r[1], r[2], r[3]);
        let euler = [r[7], r[8], r[9]];
        let q = UnitQuaternion::from_euler_angles(euler[0], euler[1], euler[2]);
        let truth = TruthStateV1 {
            host_time_ns: ns(r[0]),
            sequence: i as u64,
            latitude_rad: lat,
            longitude_rad: lon,
            height_m: alt,
            velocity_ned_m_s: [r[4], r[5], r[6]],
            quaternion_body_to_ned: [q.w, q.i, q.j, q.k],
            euler_rad: euler,
            angular_rate_rad_s: [f64::NAN; 3],
            specific_force_m_s2: [f64::NAN; 3],
        };
        out.push((
            truth.host_time_ns,
            0,
            topic::TRUTH,
            LogMessage::Truth(truth),
        ));
        let depth = DepthV1 {
            host_time_ns: ns(r[0]),
            device_time_ns: ns(r[0]),
            sequence: i as u64,
            depth_m: -alt,
            pressure_pa: f64::NAN,
            water_density_kg_m3: f64::NAN,
            temperature_c: f32::NAN,
            validity: DepthV1::VALID_DEPTH,
        };
        out.push((
            depth.host_time_ns,
            3,
            topic::DEPTH,
            LogMessage::Depth(depth),
        ));
    }
    out.sort_by_key(|&(t, order, _, _)| (t, order));
    let first = out.first().map(|m| m.0).unwrap_or(0);
    let last = out.last().map(|m| m.0).unwrap_or(0);
    let summary = SnapirSummary {
        segment,
        time_base,
        alignment,
        reference_before_imu,
        imu: imu.counts,
        dvl: dvl.counts,
        reference: reference.counts,
        duration_s: (last - first) as f64 * 1e-9,
        messages: out.len() as u64,
    };
    Ok((
        out.into_iter().map(|(_, _, t, m)| (t, m)).collect(),
        summary,
    ))
}

fn note(pairs: &[(&str, &str)]) -> BTreeMap<String, String> {
    pairs
        .iter()
        .map(|(k, v)| (k.to_string(), v.to_string()))
        .collect()
}

/// Imports one segment into a log at `out` (written atomically).
pub fn snapir(a: &SnapirArgs) -> anyhow::Result<SnapirSummary> {
    let (messages, summary) = snapir_messages(&a.dir, a.segment, a.time_base, !a.no_align)?;
    let mut header = LogHeader::new("auvnav import snapir", "");
    header
        .notes
        .insert("source".into(), a.dir.display().to_string());
    header
        .notes
        .insert("source.segment".into(), a.segment.to_string());
    header.notes.insert(
        "source.description".into(),
        "Snapir AUV (ECA A18-D), Phins FOG INS 100 Hz, RDI Workhorse DVL 1 Hz, Delph post-processed reference; time 0 = segment start".into(),
    );
    header.notes.insert(
        "replay.initial_state".into(),
        "from the reference (truth channel) at the segment start".into(),
    );
    let counts = serde_json::to_string(&summary)?;
    header.notes.insert("import.counts".into(), counts);
    write_log_atomically(&a.out, &header, |w: &mut LogWriter<_>| {
        w.declare::<ImuSampleV1>(
            topic::IMU,
            &note(&[(
                "source",
                "imu_NN.csv: body frame x forward, y starboard, z down; angular rate and specific force (not increments)",
            )]),
        )?;
        w.declare::<DvlVelocityV1>(
            topic::DVL,
            &note(&[(
                "source",
                "dvl_NN.csv: bottom-track velocity already in the vehicle body frame (mounting unknown, treated as identity)",
            )]),
        )?;
        w.declare::<TruthStateV1>(
            topic::TRUTH,
            &note(&[(
                "source",
                "ref_NN.csv: post-processed INS/DVL reference solution (not independent of the DVL); rates and specific force unknown (NaN)",
            )]),
        )?;
        w.declare::<DepthV1>(
            topic::DEPTH,
            &note(&[(
                "source",
                "derived from the reference solution: depth = -alt_m of ref_NN.csv; not an independent pressure sensor",
            )]),
        )?;
        for (t, m) in &messages {
            match m {
                LogMessage::Imu(x) => w.write(t, x)?,
                LogMessage::Dvl(x) => w.write(t, x)?,
                LogMessage::Truth(x) => w.write(t, x)?,
                LogMessage::Depth(x) => w.write(t, x)?,
                _ => {}
            }
        }
        Ok(())
    })
    .with_context(|| format!("writing {}", a.out.display()))?;
    Ok(summary)
}

/// How the GPS velocity of `auvnav import pd0` is formed.
#[derive(clap::ValueEnum, Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum GpsVelocity {
    /// VTG course and speed over ground when the file has them, otherwise GGA positions.
    Auto,
    /// VTG course and speed over ground (interpolated to the ensemble).
    Vtg,
    /// A straight line through the GGA positions within ±1 s of the ensemble.
    Gga,
}

/// Command-line arguments of `auvnav import pd0`.
#[derive(clap::Args, Debug, Clone)]
pub struct Pd0Args {
    /// A Teledyne RDI PD0 file with bottom track and GPS in WinRiver NMEA blocks (GGA, VTG).
    pub file: PathBuf,
    /// Output log (written atomically).
    #[arg(long)]
    pub out: PathBuf,
    /// Where the reference velocity comes from.
    #[arg(long, value_enum, default_value_t = GpsVelocity::Auto)]
    pub velocity: GpsVelocity,
    /// Position fixes logged elsewhere (a glider's or an AUV's surface fixes): CSV `time_s,
    /// latitude_deg, longitude_deg, depth_m, std_m` with time in seconds from the first ensemble
    /// (the format of `auvnav smooth --fixes`), written as GNSS fixes for `auvnav calibrate dvl`
    /// and `auvnav smooth`.
    #[arg(long)]
    pub fixes: Option<PathBuf>,
    /// Print the summary as JSON.
    #[arg(long)]
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
}

/// A GPS sample on the ensemble clock: time (s), north and east (m from the first fix), or
/// north and east velocity (m/s).
type GpsSample = (f64, f64, f64);

/// Linear interpolation of `s` at `t` between samples at most `max_gap` s apart.
fn interpolate_gps(s: &[GpsSample], t: f64, max_gap: f64) -> Option<(f64, f64)> {
    let i = s.partition_point(|x| x.0 <= t);
    let (a, b) = (s.get(i.checked_sub(1)?)?, s.get(i)?);
    if b.0 - a.0 > max_gap || b.0 <= a.0 {
        return None;
    }
    let f = (t - a.0) / (b.0 - a.0);
    Some((a.1 + (b.1 - a.1) * f, a.2 + (b.2 - a.2) * f))
}

/// Velocity from positions: least-squares line through the samples within ±`half` s of `t`
/// (at least three, spanning at least `half`).
fn velocity_from_positions(s: &[GpsSample], t: f64, half: f64) -> Option<(f64, f64)> {
    let lo = s.partition_point(|x| x.0 < t - half);
    let hi = s.partition_point(|x| x.0 <= t + half);
    let w = &s[lo..hi];
    if w.len() < 3 || w[w.len() - 1].0 - w[0].0 < half {
        return None;
    }
    let n = w.len() as f64;
    let mt = w.iter().map(|x| x.0).sum::<f64>() / n;
    let stt: f64 = w.iter().map(|x| (x.0 - mt).powi(2)).sum();
    let slope = |k: usize| {
        let m = w
            .iter()
            .map(|x| if k == 1 { x.1 } else { x.2 })
            .sum::<f64>()
            / n;
        w.iter()
            .map(|x| (x.0 - mt) * (if k == 1 { x.1 } else { x.2 } - m))
            .sum::<f64>()
            / stt
    };
    Some((slope(1), slope(2)))
}

/// The messages of a PD0 file with GPS: the DVL channel (bottom track, as the DVL driver
/// converts it) and a reference at each ensemble from the GPS (position, velocity over ground)
/// with the DVL's own heading, pitch and roll as attitude.
pub fn pd0_messages(
    bytes: &[u8],
    velocity: GpsVelocity,
) -> anyhow::Result<(Vec<(&'static str, LogMessage)>, Pd0Summary)> {
    use auvnav_drivers::convert::{pd0_rtc_ns, pd0_velocity};
    use auvnav_drivers::pd0::{NmeaBlock, decode_all};
    let (ensembles, stats) = decode_all(bytes);
    let mut s = Pd0Summary {
        ensembles: ensembles.len() as u64,
        bottom_track_velocity: 0,
        bad_time: 0,
        coordinate_system: String::new(),
        gga: 0,
        vtg: 0,
        gga_no_fix: 0,
        velocity,
        reference: 0,
        duration_s: 0.0,
        decoder_errors: stats.checksum_errors + stats.malformed,
        fixes_written: 0,
        fixes_outside: 0,
        fixes_unparsable_lines: 0,
    };
    if let Some(f) = ensembles.iter().find_map(|e| e.fixed.as_ref()) {
        s.coordinate_system = format!("{:?}", f.coordinate_system).to_lowercase();
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
        let t = (ns as i128 - *t0.get_or_insert(ns) as i128) as f64 * 1e-9;
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
    fixes.sort_by(|a, b| a.0.total_cmp(&b.0));
    vtg.sort_by(|a, b| a.0.total_cmp(&b.0));
    vtg.dedup_by(|a, b| a.0 == b.0);
    let use_vtg = match velocity {
        GpsVelocity::Vtg => true,
        GpsVelocity::Gga => false,
        GpsVelocity::Auto => vtg.len() >= 2,
    };
    if use_vtg && vtg.len() < 2 {
        bail!("--velocity vtg: the file has {} VTG sentences", vtg.len());
    }
    // Local north/east (m) of the fixes around the first one.
    let origin = fixes.first().map(|f| (f.1.to_radians(), f.2.to_radians()));
    let positions: Vec<GpsSample> = match origin {
        Some((lat0, lon0)) => {
            let (rm, rn) = (
                auvnav_core::earth::meridian_radius(lat0),
                auvnav_core::earth::A,
            );
            fixes
                .iter()
                .map(|f| {
                    (
                        f.0,
                        (f.1.to_radians() - lat0) * rm,
                        (f.2.to_radians() - lon0) * rn * lat0.cos(),
                    )
                })
                .collect()
        }
        None => Vec::new(),
    };
    let heights: Vec<GpsSample> = fixes.iter().map(|f| (f.0, f.3, 0.0)).collect();
    let mut out = Vec::new();
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
        let vel = if use_vtg {
            interpolate_gps(&vtg, *t, 1.5)
        } else {
            velocity_from_positions(&positions, *t, 1.0)
        };
        let (Some((vn, ve)), Some(_), Some((h, _))) = (
            vel,
            interpolate_gps(&positions, *t, 1.5),
            interpolate_gps(&heights, *t, 1.5),
        ) else {
            continue;
        };
        let (lat, lon) = {
            // Interpolated in degrees between the bracketing fixes.
            let i = fixes.partition_point(|f| f.0 <= *t);
            let (a, b) = (&fixes[i - 1], &fixes[i]);
            let f = (t - a.0) / (b.0 - a.0);
            (a.1 + (b.1 - a.1) * f, a.2 + (b.2 - a.2) * f)
        };
        let euler = [
            v.roll_deg.to_radians(),
            v.pitch_deg.to_radians(),
            v.heading_deg.to_radians(),
        ];
        let q = UnitQuaternion::from_euler_angles(euler[0], euler[1], euler[2]);
        let truth = TruthStateV1 {
            host_time_ns: host,
            sequence: s.reference,
            latitude_rad: lat.to_radians(),
            longitude_rad: lon.to_radians(),
            height_m: h,
            velocity_ned_m_s: [vn, ve, 0.0],
            quaternion_body_to_ned: [q.w, q.i, q.j, q.k],
            euler_rad: euler,
            angular_rate_rad_s: [f64::NAN; 3],
            specific_force_m_s2: [f64::NAN; 3],
        };
        s.reference += 1;
        out.push((host, 0, topic::TRUTH, LogMessage::Truth(truth)));
    }
    out.sort_by_key(|&(t, order, _, _)| (t, order));
    s.duration_s = timed.last().map_or(0.0, |x| x.0);
    Ok((out.into_iter().map(|(_, _, t, m)| (t, m)).collect(), s))
}

/// Imports a PD0 file with GPS into a log at `out` (written atomically).
pub fn pd0(a: &Pd0Args) -> anyhow::Result<Pd0Summary> {
    let bytes = std::fs::read(&a.file).with_context(|| format!("reading {}", a.file.display()))?;
    let (messages, mut summary) = pd0_messages(&bytes, a.velocity)?;
    let fix_file = a
        .fixes
        .as_deref()
        .map(crate::smooth::fixes::read)
        .transpose()?;
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
        bail!(
            "{}: no ensemble has GPS on both sides ({} GGA fixes, {} VTG) and no --fixes inside \
             its time span: nothing to compare the bottom track with",
            a.file.display(),
            summary.gga,
            summary.vtg
        );
    }
    let mut header = LogHeader::new("auvnav import pd0", "");
    header
        .notes
        .insert("source".into(), a.file.display().to_string());
    header.notes.insert(
        "source.description".into(),
        "Teledyne RDI PD0 bottom track with GPS (WinRiver NMEA blocks); time 0 = first ensemble \
         on the DVL's clock"
            .into(),
    );
    header
        .notes
        .insert("import.counts".into(), serde_json::to_string(&summary)?);
    write_log_atomically(&a.out, &header, |w: &mut LogWriter<_>| {
        w.declare::<DvlVelocityV1>(
            topic::DVL,
            &note(&[(
                "source",
                "PD0 bottom track converted as the DVL driver does (ship/instrument coordinates to x forward, y starboard, z down; the vehicle's velocity)",
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
        }
        // The fixes in time order among the ensemble's messages.
        let mut next_fix = gnss.iter().peekable();
        for (t, m) in &messages {
            let t_ns = match m {
                LogMessage::Dvl(x) => x.host_time_ns,
                LogMessage::Truth(x) => x.host_time_ns,
                _ => 0,
            };
            while let Some(f) = next_fix.next_if(|f| f.host_time_ns <= t_ns) {
                w.write(topic::GNSS, f)?;
            }
            match m {
                LogMessage::Dvl(x) => w.write(t, x)?,
                LogMessage::Truth(x) => w.write(t, x)?,
                _ => {}
            }
        }
        for f in next_fix {
            w.write(topic::GNSS, f)?;
        }
        Ok(())
    })
    .with_context(|| format!("writing {}", a.out.display()))?;
    Ok(summary)
}

#[cfg(test)]
mod pd0_tests {
    use super::*;

    #[test]
    fn gps_velocity_from_positions_and_interpolation() {
        // 1 m/s north, 0.5 m/s east, sampled at 5 Hz.
        let s: Vec<GpsSample> = (0..20)
            .map(|i| {
                let t = i as f64 * 0.2;
                (t, t, 0.5 * t)
            })
            .collect();
        let (vn, ve) = velocity_from_positions(&s, 2.0, 1.0).expect("velocity");
        assert!((vn - 1.0).abs() < 1e-12 && (ve - 0.5).abs() < 1e-12);
        assert!(velocity_from_positions(&s, 10.0, 1.0).is_none());
        let (n, e) = interpolate_gps(&s, 1.1, 1.5).expect("inside");
        assert!((n - 1.1).abs() < 1e-12 && (e - 0.55).abs() < 1e-12);
        assert!(interpolate_gps(&s, -0.1, 1.5).is_none());
        assert!(interpolate_gps(&[(0.0, 0.0, 0.0), (3.0, 1.0, 1.0)], 1.0, 1.5).is_none());
    }

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

#[cfg(test)]
mod table_tests {
    use super::*;

    fn file(name: &str, text: &str) -> PathBuf {
        let dir = std::env::temp_dir().join(format!("import-table-{}", std::process::id()));
        std::fs::create_dir_all(&dir).expect("directory");
        let p = dir.join(name);
        std::fs::write(&p, text).expect("write");
        p
    }

    #[test]
    fn bad_rows_are_counted_by_kind_and_the_good_ones_kept() {
        let p = file(
            "t.csv",
            "time_s,a,b\r\n0.0,1,2\r\n0.1, 3 ,4\r\n0.2,5\r\n0.3,nan,1\r\n0.4,x,1\r\n   \r\n\
             0.1,9,9\r\n0.5,6,7,8\r\n0.6,6,7\r\n",
        );
        let t = read_table::<3>(&p, "time_s,a,b").expect("table");
        assert_eq!(
            t.rows,
            vec![[0.0, 1.0, 2.0], [0.1, 3.0, 4.0], [0.6, 6.0, 7.0]]
        );
        assert_eq!(t.counts.rows, 8);
        // Too few fields, NaN, text, too many fields.
        assert_eq!(t.counts.malformed, 4);
        assert_eq!(t.counts.out_of_order, 1);
    }

    #[test]
    fn a_wrong_header_or_no_usable_row_is_an_error_naming_the_file() {
        let p = file("h.csv", "time,a,b\n0,1,2\n");
        let e = read_table::<3>(&p, "time_s,a,b").err().expect("error");
        assert!(
            e.to_string().contains("h.csv") && e.to_string().contains("header"),
            "{e}"
        );
        let p = file("empty.csv", "time_s,a,b\nx,y,z\n");
        let e = read_table::<3>(&p, "time_s,a,b").err().expect("error");
        assert!(e.to_string().contains("no usable rows"), "{e}");
        let missing = std::env::temp_dir()
            .join("no-such-dir-import")
            .join("m.csv");
        assert!(read_table::<3>(&missing, "time_s,a,b").is_err());
    }
}

/// Command-line arguments of `auvnav import mag-csv`.
#[derive(clap::Args, Debug, Clone)]
pub struct MagCsvArgs {
    /// A CSV file with magnetometer and accelerometer columns (a header line names them; lines
    /// starting with `#` are comments).
    pub file: PathBuf,
    /// Output log (written atomically).
    #[arg(long)]
    pub out: PathBuf,
    #[command(flatten)]
    pub columns: crate::calibrate::mag::input::CsvColumnArgs,
    /// Print the summary as JSON.
    #[arg(long)]
    pub json: bool,
}

/// What `auvnav import mag-csv` read and wrote.
#[derive(Debug, Clone, Default, Serialize)]
pub struct MagCsvSummary {
    /// Rows written (a magnetometer reading, with the accelerometer's when the row has one).
    pub readings: usize,
    /// Of them, rows with an accelerometer reading.
    pub with_accelerometer: usize,
    /// Rows left out (a magnetometer value missing or not a number, a bad time).
    pub skipped: usize,
    /// Rows whose time does not increase (left out).
    pub out_of_order: usize,
    pub duration_s: f64,
    pub field_unit: String,
    pub accelerometer_unit: String,
    /// Decimal year of the first row, when the time column is a calendar time.
    pub date: Option<f64>,
}

/// Standard gravity (m/s²): accelerometer readings in g are converted with it.
const STANDARD_GRAVITY: f64 = 9.80665;

/// The messages of a magnetometer CSV recording (an IMU sample with the specific force, then the
/// magnetometer reading, per row; time 0 = first row) and the summary.
pub fn mag_csv_messages(
    a: &MagCsvArgs,
) -> anyhow::Result<(Vec<(&'static str, LogMessage)>, MagCsvSummary)> {
    use auvnav_shm_schema::MagnetometerV1;
    let cols = a.columns.columns()?;
    let rec = crate::calibrate::mag::input::read_csv(&a.file, &cols)?;
    let mut s = MagCsvSummary {
        skipped: rec.skipped,
        field_unit: rec.unit_note.clone(),
        date: rec.whereabouts.date,
        ..Default::default()
    };
    // Accelerometer unit: g when the median magnitude is near 1, m/s² when near 9.8.
    let mut norms: Vec<f64> = rec
        .samples
        .iter()
        .filter_map(|x| x.specific_force.map(|f| f.norm()))
        .collect();
    norms.sort_by(f64::total_cmp);
    let accel_scale = match norms.get(norms.len() / 2) {
        Some(&m) if m < 3.0 => {
            s.accelerometer_unit = format!("g (median magnitude {m:.3}), converted to m/s²");
            STANDARD_GRAVITY
        }
        Some(&m) => {
            s.accelerometer_unit = format!("m/s² (median magnitude {m:.3})");
            1.0
        }
        None => {
            s.accelerometer_unit = "none (no accelerometer columns)".into();
            1.0
        }
    };
    let Some(t0) = rec.samples.first().map(|x| x.time_s) else {
        bail!("{}: no magnetometer rows", a.file.display());
    };
    let mut out = Vec::with_capacity(2 * rec.samples.len());
    let mut last_ns: Option<u64> = None;
    let mut last_t = t0;
    for x in &rec.samples {
        let dt = x.time_s - t0;
        if dt.is_nan() || dt < 0.0 || last_ns.is_some_and(|l| ns_of(dt) <= l) {
            s.out_of_order += 1;
            continue;
        }
        let host = ns_of(dt);
        let interval = (x.time_s - last_t).clamp(1e-3, 0.999);
        last_t = x.time_s;
        last_ns = Some(host);
        s.readings += 1;
        if let Some(f) = x.specific_force {
            s.with_accelerometer += 1;
            out.push((
                topic::IMU,
                LogMessage::Imu(ImuSampleV1 {
                    host_time_ns: host,
                    device_time_ns: host,
                    sequence: s.with_accelerometer as u64,
                    angular: [0.0; 3],
                    specific: (f * accel_scale).into(),
                    interval_s: interval,
                    temperature_c: 0.0,
                    status: ImuSampleV1::STATUS_ACCEL_VALID,
                }),
            ));
        }
        out.push((
            topic::MAGNETOMETER,
            LogMessage::Magnetometer(MagnetometerV1 {
                host_time_ns: host,
                device_time_ns: host,
                sequence: s.readings as u64,
                field_t: (x.field_ut * 1e-6).into(),
                temperature_c: 0.0,
                validity: MagnetometerV1::VALID_FIELD,
            }),
        ));
        s.duration_s = dt;
    }
    Ok((out, s))
}

fn ns_of(seconds: f64) -> u64 {
    (seconds * 1e9).round() as u64
}

/// Imports a magnetometer CSV recording into a log at `out` (written atomically).
pub fn mag_csv(a: &MagCsvArgs) -> anyhow::Result<MagCsvSummary> {
    use auvnav_shm_schema::MagnetometerV1;
    let (messages, summary) = mag_csv_messages(a)?;
    let mut header = LogHeader::new("auvnav import mag-csv", "");
    header
        .notes
        .insert("source".into(), a.file.display().to_string());
    header.notes.insert(
        "source.description".into(),
        format!(
            "magnetometer CSV: field {}, accelerometer {}; time 0 = first row{}",
            summary.field_unit,
            summary.accelerometer_unit,
            summary
                .date
                .map_or(String::new(), |d| format!(" (decimal year {d:.4})"))
        ),
    );
    header
        .notes
        .insert("import.counts".into(), serde_json::to_string(&summary)?);
    write_log_atomically(&a.out, &header, |w: &mut LogWriter<_>| {
        w.declare::<ImuSampleV1>(
            topic::IMU,
            &note(&[(
                "source",
                "the CSV's accelerometer columns as specific force in the sensor's axes (no gyro: angular rate not valid)",
            )]),
        )?;
        w.declare::<MagnetometerV1>(
            topic::MAGNETOMETER,
            &note(&[("source", "the CSV's magnetometer columns, in the sensor's axes")]),
        )?;
        for (t, m) in &messages {
            match m {
                LogMessage::Imu(x) => w.write(t, x)?,
                LogMessage::Magnetometer(x) => w.write(t, x)?,
                _ => {}
            }
        }
        Ok(())
    })
    .with_context(|| format!("writing {}", a.out.display()))?;
    Ok(summary)
}

/// Command-line arguments of `auvnav import ugps-g2`.
#[derive(clap::Args, Debug, Clone)]
pub struct UgpsArgs {
    /// The Water Linked Underwater GPS G2 acoustic log (`…_g2_acoustic.csv`), or a folder with one.
    pub input: PathBuf,
    /// Output log (written atomically).
    #[arg(long)]
    pub out: PathBuf,
    /// Print the summary as JSON.
    #[arg(long)]
    pub json: bool,
}

/// What `auvnav import ugps-g2` read and wrote.
#[derive(Debug, Clone, Default, Serialize)]
pub struct UgpsSummary {
    pub file: String,
    /// Rows in the file.
    pub rows: usize,
    /// Acoustic updates written (rows whose fix or ranges changed).
    pub updates: usize,
    /// Of them, with a valid position fix.
    pub with_position: usize,
    /// Valid ranges per receiver among the updates written.
    pub ranges: [usize; 4],
    /// Rows repeating the previous update (the log is written at 5 Hz whatever the acoustic
    /// rate): left out.
    pub repeated: usize,
    /// Rows with a missing or unparsable field, or a time going backwards: left out.
    pub malformed: usize,
    pub duration_s: f64,
    /// Unix time of the first row (s).
    pub start_unix_s: f64,
}

/// The acoustic CSV of `input` (the file itself, or the one `*_g2_acoustic.csv` in a folder).
fn ugps_acoustic_file(input: &Path) -> anyhow::Result<PathBuf> {
    if !input.is_dir() {
        return Ok(input.to_path_buf());
    }
    let mut found: Vec<PathBuf> = std::fs::read_dir(input)
        .with_context(|| format!("reading {}", input.display()))?
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| {
            p.file_name()
                .and_then(|n| n.to_str())
                .is_some_and(|n| n.ends_with("_g2_acoustic.csv"))
        })
        .collect();
    found.sort();
    match found.len() {
        1 => Ok(found.remove(0)),
        0 => bail!("{}: no *_g2_acoustic.csv file", input.display()),
        _ => bail!(
            "{}: {} *_g2_acoustic.csv files; name one",
            input.display(),
            found.len()
        ),
    }
}

/// The messages of a UGPS G2 acoustic log (time 0 = first row) and the summary. The position
/// (x, y, z down, relative to the topside) becomes the device's fix in the array frame; the
/// receivers' configured positions are not in the log (flag not set).
pub fn ugps_messages(
    input: &Path,
) -> anyhow::Result<(Vec<(&'static str, LogMessage)>, UgpsSummary)> {
    use auvnav_shm_schema::AcousticRangesV1;
    let file = ugps_acoustic_file(input)?;
    let mut reader = csv_reader(&file)?;
    let names = reader
        .headers()
        .with_context(|| format!("reading the header of {}", file.display()))?
        .clone();
    if names.iter().all(str::is_empty) {
        bail!("{}: empty file", file.display());
    }
    let col = |n: &str| -> anyhow::Result<usize> {
        names
            .iter()
            .position(|x| x == n)
            .with_context(|| format!("{}: no column {n:?}", file.display()))
    };
    let t_col = col("timestamp")?;
    let valid_col = col("position_valid")?;
    let pos = [col("x")?, col("y")?, col("z")?];
    let std_col = col("std")?;
    let mut dist = [0; 4];
    let mut nsd = [0; 4];
    let mut rssi = [0; 4];
    let mut rvalid = [0; 4];
    for k in 0..4 {
        dist[k] = col(&format!("distance_r{k}"))?;
        nsd[k] = col(&format!("nsd_r{k}"))?;
        rssi[k] = col(&format!("rssi_r{k}"))?;
        rvalid[k] = col(&format!("valid_r{k}"))?;
    }
    let mut s = UgpsSummary {
        file: file.display().to_string(),
        ..Default::default()
    };
    let mut out = Vec::new();
    let mut t0: Option<f64> = None;
    let mut last_t = f64::NEG_INFINITY;
    let mut last_key: Option<[u64; 8]> = None;
    let mut f = csv::StringRecord::new();
    while let Some(read) = next_record(&mut reader, &mut f, &file)? {
        if read.is_ok() && f.iter().all(str::is_empty) {
            continue;
        }
        s.rows += 1;
        if read.is_err() {
            s.malformed += 1;
            continue;
        }
        let num = |k: usize| f.get(k).and_then(|v| v.parse::<f64>().ok());
        let flag = |k: usize| match f.get(k) {
            Some("True") | Some("true") | Some("1") => Some(true),
            Some("False") | Some("false") | Some("0") => Some(false),
            _ => None,
        };
        let parsed = (|| {
            let t = num(t_col)?;
            let valid = flag(valid_col)?;
            let p = [num(pos[0])?, num(pos[1])?, num(pos[2])?];
            let sd = num(std_col)?;
            let mut r = [0.0; 4];
            let mut ok = [false; 4];
            let mut n = [0.0f32; 4];
            let mut q = [0.0f32; 4];
            for k in 0..4 {
                r[k] = num(dist[k])?;
                ok[k] = flag(rvalid[k])?;
                n[k] = num(nsd[k])? as f32;
                q[k] = num(rssi[k])? as f32;
            }
            Some((t, valid, p, sd, r, ok, n, q))
        })();
        let Some((t, valid, p, sd, r, ok, n, q)) = parsed else {
            s.malformed += 1;
            continue;
        };
        if !t.is_finite() || t <= last_t {
            s.malformed += 1;
            continue;
        }
        last_t = t;
        let key = [
            p[0].to_bits(),
            p[1].to_bits(),
            p[2].to_bits(),
            r[0].to_bits(),
            r[1].to_bits(),
            r[2].to_bits(),
            r[3].to_bits(),
            u64::from(valid),
        ];
        if last_key == Some(key) {
            s.repeated += 1;
            continue;
        }
        last_key = Some(key);
        let start = *t0.get_or_insert(t);
        let host = ns_of(t - start);
        let mut validity = AcousticRangesV1::VALID_SIGNAL;
        for k in 0..4 {
            if ok[k] && r[k] > 0.0 && r[k].is_finite() {
                validity |= AcousticRangesV1::VALID_RANGE << k;
                s.ranges[k] += 1;
            }
        }
        if valid && p.iter().all(|x| x.is_finite()) {
            validity |= AcousticRangesV1::VALID_POSITION;
            s.with_position += 1;
            if sd.is_finite() && sd >= 0.0 {
                validity |= AcousticRangesV1::VALID_POSITION_STD;
            }
        }
        s.updates += 1;
        s.duration_s = t - start;
        out.push((
            topic::ACOUSTIC_RANGES,
            LogMessage::AcousticRanges(AcousticRangesV1 {
                host_time_ns: host,
                device_time_ns: host,
                sequence: s.updates as u64,
                range_m: r,
                receiver_position_m: [0.0; 12],
                position_array_m: p,
                position_std_m: sd as f32,
                noise_db: n,
                rssi_db: q,
                validity,
                reserved: [0; 2],
            }),
        ));
    }
    s.start_unix_s = t0.unwrap_or(f64::NAN);
    if s.updates == 0 {
        bail!(
            "{}: no acoustic update ({} rows, {} malformed)",
            file.display(),
            s.rows,
            s.malformed
        );
    }
    Ok((out, s))
}

/// Imports a UGPS G2 acoustic log into a log at `out` (written atomically).
pub fn ugps(a: &UgpsArgs) -> anyhow::Result<UgpsSummary> {
    use auvnav_shm_schema::AcousticRangesV1;
    let (messages, summary) = ugps_messages(&a.input)?;
    let mut header = LogHeader::new("auvnav import ugps-g2", "");
    header.notes.insert("source".into(), summary.file.clone());
    header.notes.insert(
        "source.description".into(),
        format!(
            "Water Linked Underwater GPS G2 acoustic log: per-receiver distances and the system's \
             locator position (x, y, z down relative to the topside); rows repeating the previous \
             update left out; time 0 = Unix time {:.3}",
            summary.start_unix_s
        ),
    );
    header
        .notes
        .insert("import.counts".into(), serde_json::to_string(&summary)?);
    write_log_atomically(&a.out, &header, |w: &mut LogWriter<_>| {
        w.declare::<AcousticRangesV1>(
            topic::ACOUSTIC_RANGES,
            &note(&[(
                "source",
                "distance_r0..r3 (valid_r*), x/y/z and std of the locator fix, nsd_r* and rssi_r*; receiver positions not in the log",
            )]),
        )?;
        for (t, m) in &messages {
            if let LogMessage::AcousticRanges(x) = m {
                w.write(t, x)?;
            }
        }
        Ok(())
    })
    .with_context(|| format!("writing {}", a.out.display()))?;
    Ok(summary)
}
