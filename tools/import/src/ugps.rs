//! A UGPS G2 acoustic log.

#[allow(unused_imports)]
use super::*;

/// Command-line arguments of `auvnav import ugps-g2`.
#[derive(Debug, Clone)]
#[cfg_attr(feature = "clap", derive(clap::Args))]
pub struct UgpsOptions {
    /// The Water Linked Underwater GPS G2 acoustic log (`…_g2_acoustic.csv`), or a folder with one.
    pub input: PathBuf,
    /// Output log (written atomically).
    #[cfg_attr(feature = "clap", arg(long))]
    pub out: PathBuf,
    /// Print the summary as JSON.
    #[cfg_attr(feature = "clap", arg(long))]
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
    /// The topside's position log beside the acoustic one (`*_g2_position.csv`), when there.
    pub position_file: Option<String>,
    /// The array's poses written (the topside's GNSS position and heading), and rows left out
    /// (missing or unparsable fields, no fix, time going backwards, before the first acoustic
    /// row).
    pub array_poses: usize,
    pub array_poses_left_out: usize,
    /// Position rows repeating the previous pose (the file is written at 5 Hz whatever the GNSS
    /// rate): left out, so that a held value does not stop the boat between fixes.
    pub array_poses_repeated: usize,
}

/// The acoustic CSV of `input` (the file itself, or the one `*_g2_acoustic.csv` in a folder).
fn ugps_acoustic_file(input: &Path) -> Result<PathBuf> {
    if !input.is_dir() {
        return Ok(input.to_path_buf());
    }
    let mut found: Vec<PathBuf> = std::fs::read_dir(input)
        .read_context(|| format!("reading {}", input.display()))?
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
        0 => malformed!("{}: no *_g2_acoustic.csv file", input.display()),
        _ => malformed!(
            "{}: {} *_g2_acoustic.csv files; name one",
            input.display(),
            found.len()
        ),
    }
}

/// The messages of a UGPS G2 acoustic log (time 0 = first row) and the summary. The position
/// (x, y, z down, relative to the topside) becomes the device's fix in the array frame; the
/// receivers' configured positions are not in the log (flag not set).
pub fn ugps_messages(input: &Path) -> Result<(Vec<(&'static str, LogMessage)>, UgpsSummary)> {
    use auvnav_shm_schema::AcousticRangesV1;
    let file = ugps_acoustic_file(input)?;
    let mut reader = csv_reader(&file)?;
    let names = reader
        .headers()
        .read_context(|| format!("reading the header of {}", file.display()))?
        .clone();
    if names.iter().all(str::is_empty) {
        malformed!("{}: empty file", file.display());
    }
    let col = |n: &str| -> Result<usize> {
        names.iter().position(|x| x == n).ok_or_else(|| {
            crate::ImportError::Malformed(format!("{}: no column {n:?}", file.display()))
        })
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
        malformed!(
            "{}: no acoustic update ({} rows, {} malformed)",
            file.display(),
            s.rows,
            s.malformed
        );
    }
    add_array_poses(&file, &mut out, &mut s)?;
    Ok((out, s))
}

/// The topside's poses beside the acoustic log `file` (when there), merged into `out` on one time
/// line: the poses between the acoustic updates (stable: an update and a pose of the same instant
/// keep the file order, acoustic first).
fn add_array_poses(
    file: &Path,
    out: &mut Vec<(&'static str, LogMessage)>,
    s: &mut UgpsSummary,
) -> Result<()> {
    let Some(position) = ugps_position_file(file) else {
        return Ok(());
    };
    s.position_file = Some(position.display().to_string());
    let poses = ugps_array_poses(&position, s.start_unix_s, s)?;
    out.extend(poses);
    out.sort_by_key(|(_, m)| match m {
        LogMessage::AcousticRanges(x) => x.host_time_ns,
        LogMessage::AcousticArrayPose(x) => x.host_time_ns,
        _ => 0,
    });
    Ok(())
}

/// The topside's position log beside an acoustic log: `<prefix>_g2_position.csv`.
fn ugps_position_file(acoustic: &Path) -> Option<PathBuf> {
    let name = acoustic.file_name()?.to_str()?;
    let prefix = name.strip_suffix("_g2_acoustic.csv")?;
    let p = acoustic.with_file_name(format!("{prefix}_g2_position.csv"));
    p.is_file().then_some(p)
}

/// The array's poses from the topside's position log (`timestamp, lat, lon, orientation,
/// fix_quality, …`): its GNSS position and heading, on the acoustic log's time base (`t0`, Unix
/// s). The log gives no one-sigma (the navigator's configured one applies).
fn ugps_array_poses(
    file: &Path,
    t0: f64,
    s: &mut UgpsSummary,
) -> Result<Vec<(&'static str, LogMessage)>> {
    use auvnav_shm_schema::AcousticArrayPoseV1 as P;
    let mut reader = csv_reader(file)?;
    let names = reader
        .headers()
        .read_context(|| format!("reading the header of {}", file.display()))?
        .clone();
    let col = |n: &str| -> Result<usize> {
        names.iter().position(|x| x == n).ok_or_else(|| {
            crate::ImportError::Malformed(format!("{}: no column {n:?}", file.display()))
        })
    };
    let cols = [
        col("timestamp")?,
        col("lat")?,
        col("lon")?,
        col("orientation")?,
        col("fix_quality")?,
    ];
    let mut out = Vec::new();
    let mut last_t = f64::NEG_INFINITY;
    let mut last_pose: Option<[u64; 3]> = None;
    let mut f = csv::StringRecord::new();
    while let Some(read) = next_record(&mut reader, &mut f, file)? {
        if read.is_ok() && f.iter().all(str::is_empty) {
            continue;
        }
        let v = cols.map(|k| f.get(k).and_then(|x| x.parse::<f64>().ok()));
        let [Some(t), Some(lat), Some(lon), Some(heading), Some(quality)] = v else {
            s.array_poses_left_out += 1;
            continue;
        };
        let usable = read.is_ok()
            && t.is_finite()
            && t > last_t
            && t >= t0
            && quality > 0.0
            && lat.abs() <= 90.0
            && lon.abs() <= 180.0
            && (0.0..=360.0).contains(&heading);
        if !usable {
            s.array_poses_left_out += 1;
            continue;
        }
        last_t = t;
        let pose = [lat.to_bits(), lon.to_bits(), heading.to_bits()];
        if last_pose == Some(pose) {
            s.array_poses_repeated += 1;
            continue;
        }
        last_pose = Some(pose);
        s.array_poses += 1;
        let host = ns_of(t - t0);
        out.push((
            topic::ACOUSTIC_ARRAY_POSE,
            LogMessage::AcousticArrayPose(P {
                host_time_ns: host,
                device_time_ns: host,
                sequence: s.array_poses as u64,
                latitude_rad: lat.to_radians(),
                longitude_rad: lon.to_radians(),
                euler_rad: [0.0, 0.0, heading.to_radians()],
                validity: P::VALID_POSITION | P::VALID_HEADING | P::VALID_DEVICE_TIME,
                ..Default::default()
            }),
        ));
    }
    Ok(out)
}

/// Imports a UGPS G2 acoustic log into a log at `out` (written atomically).
pub fn ugps(a: &UgpsOptions) -> Result<UgpsSummary> {
    use auvnav_shm_schema::AcousticRangesV1;
    let (messages, summary) = ugps_messages(&a.input)?;
    let header = import_header(
        "auvnav import ugps-g2",
        summary.file.clone(),
        format!(
            "Water Linked Underwater GPS G2 acoustic log: per-receiver distances and the system's \
             locator position (x, y, z down relative to the topside); rows repeating the previous \
             update left out; time 0 = Unix time {:.3}",
            summary.start_unix_s
        ),
        &summary,
    );
    write_log_atomically(&a.out, &header, |w: &mut LogWriter<_>| {
        w.declare::<AcousticRangesV1>(
            topic::ACOUSTIC_RANGES,
            &note(&[(
                "source",
                "distance_r0..r3 (valid_r*), x/y/z and std of the locator fix, nsd_r* and rssi_r*; receiver positions not in the log",
            )]),
        )?;
        if summary.position_file.is_some() {
            w.declare::<auvnav_shm_schema::AcousticArrayPoseV1>(
                topic::ACOUSTIC_ARRAY_POSE,
                &note(&[(
                    "source",
                    "lat, lon and orientation (the topside's heading) of *_g2_position.csv: the array frame the fixes x, y, z are in; no one-sigma in the log",
                )]),
            )?;
        }
        for (t, m) in &messages {
            match m {
                LogMessage::AcousticRanges(x) => w.write(t, x)?,
                LogMessage::AcousticArrayPose(x) => w.write(t, x)?,
                _ => {}
            }
        }
        Ok(())
    })
    .map_err(crate::error::output(&a.out))?;
    Ok(summary)
}
