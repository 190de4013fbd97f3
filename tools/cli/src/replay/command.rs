//! The `auvnav replay` command: arguments, the configuration a replay runs with (file, log header
//! or default, with `--usbl`), the outputs (CSV or MCAP) and the report.

#[allow(unused_imports)]
use super::*;

/// Command-line arguments of `auvnav replay`.
#[derive(clap::Args, Debug, Clone)]
pub struct ReplayArgs {
    /// The log to replay (MCAP written by auvnav).
    pub log: PathBuf,
    /// Configuration TOML: `[navigation]` (filter settings) and an optional `[initial]` state.
    #[arg(long)]
    pub config: Option<PathBuf>,
    /// Write the solution and the diagnostics: MCAP, or CSV when the name ends in .csv (the
    /// diagnostics then go to NAME.diagnostics.csv).
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// Write every Nth solution (diagnostics are always all written).
    #[arg(long, default_value_t = 1)]
    pub decimate: u64,
    /// Distance travelled beyond which points enter the error/distance figure (m).
    #[arg(long, default_value_t = 100.0)]
    pub min_distance: f64,
    /// Fuse the USBL fixes with this coupling (loose or tight; adaptive unscented filter): the
    /// configuration's `[navigation.usbl]`, or else the station survey in the log header of a
    /// simulated voyage.
    #[arg(long, value_parser = crate::args::config_enum::<auvnav_core::aid::usbl::Coupling>(auvnav_core::aid::usbl::Coupling::NAMES))]
    pub usbl: Option<auvnav_core::aid::usbl::Coupling>,
    /// Compare the solutions with those the log recorded on `nav/solution` (the daemon's live
    /// output in a recording): report the first that differs, exit with status 3 unless every
    /// recorded solution is reproduced.
    #[arg(long)]
    pub compare_recorded: bool,
    /// Print the result as JSON.
    #[arg(long)]
    pub json: bool,
}

/// The result of a replay.
#[derive(Debug, Clone, Serialize)]
pub struct ReplayReport {
    pub log: String,
    /// Where the configuration came from (a file, the log header, or the defaults).
    pub configuration: String,
    pub initial_state: Option<InitialReport>,
    /// Present when the log has a truth channel.
    pub accuracy: Option<Accuracy>,
    pub samples_processed: u64,
    pub log_duration_s: f64,
    pub wall_s: f64,
    pub real_time_factor: f64,
    pub counts: ReplayCounts,
    pub navigator: NavCounters,
    /// IMU biases and DVL installation at the end of the replay (estimated where the
    /// configuration switches their states on, otherwise as configured).
    pub final_parameters: Option<FinalParameters>,
    /// Why the log ended early, when it did (for example a truncated file).
    pub log_error: Option<String>,
    /// With `--compare-recorded`: the replay against the recorded solutions.
    pub recorded_comparison: Option<RecordedComparison>,
}

/// Reads `log` and feeds every message to `replay`. A truncated or damaged tail ends the replay
/// with what was read and the reason in the second value; a log that cannot be read at all is an
/// error.
pub fn run_log(
    log: &Path,
    replay: &mut Replay,
    out: &mut dyn FnMut(Output) -> anyhow::Result<()>,
) -> anyhow::Result<(LogHeader, Option<String>)> {
    let mut reader = LogReader::open(log)?;
    let header = reader
        .read_header()
        .with_context(|| format!("reading {}", log.display()))?;
    loop {
        let processed = reader.next_decoded_with(|decoded| match decoded {
            Ok(m) => replay.process(m, out),
            Err(_) => {
                replay.counts.malformed += 1;
                Ok(())
            }
        });
        let damaged = |stopped: Option<String>| -> Option<String> {
            let c = reader_corruption(&reader);
            match (stopped, c) {
                (s, None) => s,
                (None, Some(c)) => Some(format!("damaged: {c}")),
                (Some(s), Some(c)) => Some(format!("{s}; damaged: {c}")),
            }
        };
        match processed {
            Ok(Some(r)) => r?,
            Ok(None) => {
                replay.finish(out)?;
                return Ok((header, damaged(None)));
            }
            Err(e @ (LogError::Truncated | LogError::Mcap(_))) => {
                replay.finish(out)?;
                return Ok((header, damaged(Some(e.to_string()))));
            }
            Err(e) => return Err(e).with_context(|| format!("reading {}", log.display())),
        }
    }
}

/// What a reader passed over as damaged, when it did.
fn reader_corruption<R: std::io::Read>(reader: &LogReader<R>) -> Option<String> {
    let c = reader.corruption();
    c.any().then(|| c.to_string())
}

/// `path` + `.partial`: where a file is written before it is renamed into place.
pub fn partial_path(path: &Path) -> PathBuf {
    let mut p = path.as_os_str().to_owned();
    p.push(".partial");
    PathBuf::from(p)
}

/// The CSV file that receives the diagnostics when the solution goes to `nav_csv`.
pub fn diagnostics_csv_path(nav_csv: &Path) -> PathBuf {
    nav_csv.with_extension("diagnostics.csv")
}

pub use auvnav_core::csv::{DIAGNOSTICS_HEADER, write_diagnostics_row};

/// The navigation part (`aid_delay_s`, `[navigation]`, `[initial]`, `[alignment]`) of a
/// configuration that
/// may hold more (the daemon's, embedded in a recording's header).
pub fn session_config_from_toml(text: &str) -> anyhow::Result<ReplayConfig> {
    let table: toml::Table = toml::from_str(text).context("parsing the embedded configuration")?;
    let mut keep = toml::Table::new();
    for key in ["aid_delay_s", "navigation", "initial", "alignment"] {
        if let Some(v) = table.get(key) {
            keep.insert(key.to_string(), v.clone());
        }
    }
    let cfg: ReplayConfig = keep
        .try_into()
        .context("the embedded configuration's navigation tables")?;
    cfg.validate()
        .context("the embedded configuration's navigation tables")?;
    Ok(cfg)
}

/// The configuration a replay runs with, and where it came from.
pub fn replay_config(a: &ReplayArgs) -> anyhow::Result<(ReplayConfig, String)> {
    let (mut cfg, mut source) = base_replay_config(a)?;
    if let Some(coupling) = a.usbl {
        match cfg.navigation.usbl.as_mut() {
            Some(u) => u.coupling = coupling,
            None => {
                let header = LogReader::open(&a.log)?
                    .read_header()
                    .with_context(|| format!("reading {}", a.log.display()))?;
                let station =
                    auvnav_sim::StationGeometry::from_notes(&header.notes).with_context(|| {
                        format!(
                            "--usbl: {} has no station survey in its header; give the station \
                             in [navigation.usbl] of --config",
                            a.log.display()
                        )
                    })?;
                cfg.navigation.usbl = Some(auvnav_core::aid::usbl::UsblConfig {
                    coupling,
                    ..station.usbl_config()
                });
                source.push_str(", USBL station from the log header");
            }
        }
    }
    Ok((cfg, source))
}

fn base_replay_config(a: &ReplayArgs) -> anyhow::Result<(ReplayConfig, String)> {
    if let Some(p) = &a.config {
        return Ok((load_config(p)?, p.display().to_string()));
    }
    // A recording carries the daemon's configuration: replay with it, as the daemon ran.
    let header = LogReader::open(&a.log)?
        .read_header()
        .with_context(|| format!("reading {}", a.log.display()))?;
    if header.producer == "auvnav record" && !header.config.trim().is_empty() {
        return Ok((
            session_config_from_toml(&header.config)?,
            "the log header (embedded by auvnav record)".to_string(),
        ));
    }
    Ok((ReplayConfig::default(), "defaults".to_string()))
}

/// Runs `auvnav replay`.
pub fn run(a: &ReplayArgs) -> anyhow::Result<ReplayReport> {
    let (cfg, config_source) = replay_config(a)?;
    if !(a.min_distance.is_finite() && a.min_distance >= 0.0) {
        bail!("--min-distance {}: must be >= 0 m", a.min_distance);
    }
    let decimate = a.decimate.max(1);
    let mut replay = Replay::new(&cfg, a.min_distance);
    if a.compare_recorded {
        replay.compare_with_recorded();
    }
    let start = std::time::Instant::now();
    let mut solutions = 0u64;
    let mut log_error = None;
    let config_text = toml::to_string(&cfg).unwrap_or_default();
    match &a.out {
        None => {
            log_error = run_log(&a.log, &mut replay, &mut |_| Ok(()))?.1;
        }
        Some(path) if path.extension().is_some_and(|e| e == "csv") => {
            let diag_path = diagnostics_csv_path(path);
            let (nav_partial, diag_partial) = (partial_path(path), partial_path(&diag_path));
            let result = (|| -> anyhow::Result<()> {
                let mut nav_w = std::io::BufWriter::new(
                    std::fs::File::create(&nav_partial)
                        .with_context(|| format!("creating {}", nav_partial.display()))?,
                );
                let mut diag_w = std::io::BufWriter::new(
                    std::fs::File::create(&diag_partial)
                        .with_context(|| format!("creating {}", diag_partial.display()))?,
                );
                writeln!(nav_w, "{}", crate::csv::NAV_HEADER)?;
                writeln!(diag_w, "{DIAGNOSTICS_HEADER}")?;
                log_error = run_log(&a.log, &mut replay, &mut |o| {
                    match o {
                        Output::Solution(s) => {
                            solutions += 1;
                            if (solutions - 1).is_multiple_of(decimate) {
                                crate::csv::write_nav_row(&mut nav_w, s)?;
                            }
                        }
                        Output::Diagnostics(d) => write_diagnostics_row(&mut diag_w, d)?,
                        Output::Truth(_) | Output::LateAid(_) => {}
                    }
                    Ok(())
                })?
                .1;
                nav_w.flush()?;
                diag_w.flush()?;
                std::fs::rename(&nav_partial, path)?;
                std::fs::rename(&diag_partial, &diag_path)?;
                Ok(())
            })();
            if result.is_err() {
                let _ = std::fs::remove_file(&nav_partial);
                let _ = std::fs::remove_file(&diag_partial);
            }
            result?;
        }
        Some(path) => {
            let mut header = LogHeader::new("auvnav replay", &config_text);
            header
                .notes
                .insert("replay.source_log".into(), a.log.display().to_string());
            write_log_atomically(path, &header, |w| {
                log_error = run_log(&a.log, &mut replay, &mut |o| {
                    match o {
                        Output::Solution(s) => {
                            solutions += 1;
                            if (solutions - 1).is_multiple_of(decimate) {
                                w.write(topic::NAV_SOLUTION, s)?;
                            }
                        }
                        Output::Diagnostics(d) => w.write(topic::NAV_AID_DIAGNOSTICS, d)?,
                        Output::Truth(t) => w.write(topic::TRUTH, t)?,
                        Output::LateAid(r) => w.write(topic::NAV_LATE_AIDS, r)?,
                    }
                    Ok(())
                })?
                .1;
                Ok(())
            })?;
        }
    }
    let wall = start.elapsed().as_secs_f64();
    // With [alignment] the solutions are the alignment's, also when it did not finish.
    if replay.initial().is_none() && !replay.has_alignment() {
        bail!(
            "{}: no initial state: the log has no truth channel and the configuration no [initial] table",
            a.log.display()
        );
    }
    let log_duration_s = replay.duration_s();
    Ok(ReplayReport {
        log: a.log.display().to_string(),
        configuration: config_source,
        initial_state: replay.initial().cloned(),
        accuracy: replay.accuracy(),
        samples_processed: replay.counts.imu,
        log_duration_s,
        wall_s: wall,
        real_time_factor: if wall > 0.0 {
            log_duration_s / wall
        } else {
            0.0
        },
        counts: replay.counts,
        navigator: replay.nav_counters(),
        final_parameters: replay.navigator().map(FinalParameters::of),
        log_error,
        recorded_comparison: replay.recorded_comparison().cloned(),
    })
}

/// Prints a replay report for people.
pub fn print_report(r: &ReplayReport) {
    println!("auvnav replay: {}", r.log);
    if let Some(i) = &r.initial_state {
        println!(
            "  initial state from the {} at t = {:.3} s: {:.7} deg N, {:.7} deg E, height {:.2} m, \
             v_ned [{:.3}, {:.3}, {:.3}] m/s, roll/pitch/yaw [{:.3}, {:.3}, {:.3}] deg",
            i.source,
            i.time_s,
            i.latitude_deg,
            i.longitude_deg,
            i.height_m,
            i.velocity_ned_m_s[0],
            i.velocity_ned_m_s[1],
            i.velocity_ned_m_s[2],
            i.euler_deg[0],
            i.euler_deg[1],
            i.euler_deg[2]
        );
    }
    if let Some(acc) = &r.accuracy {
        println!(
            "  horizontal error: final {:.2} m, max {:.2} m, CEP50 {:.2} m over {:.0} m travelled",
            acc.horizontal_error_final_m,
            acc.horizontal_error_max_m,
            acc.horizontal_error_cep50_m,
            acc.distance_travelled_m
        );
        println!(
            "  error/distance CEP50 {:.3} %, heading error RMS {:.4} deg",
            acc.error_per_distance_cep50_percent, acc.heading_error_rms_deg
        );
    }
    let n = &r.navigator;
    println!(
        "  {} IMU samples, {:.0} s of log in {:.3} s (real-time factor {:.0}); fused {} DVL ({} rejected, {} invalid), {} depth ({} rejected), {} GNSS ({} rejected)",
        r.samples_processed,
        r.log_duration_s,
        r.wall_s,
        r.real_time_factor,
        n.dvl_fused,
        n.dvl_rejected,
        n.dvl_invalid,
        n.depth_fused,
        n.depth_rejected,
        n.gnss_fused,
        n.gnss_rejected
    );
    if n.usbl_unconfigured > 0 {
        println!(
            "  {} USBL fixes not used (no [navigation.usbl]; --usbl tight uses a simulated log's station)",
            n.usbl_unconfigured
        );
    } else if r.counts.usbl > 0 {
        println!(
            "  USBL: {} fused, {} rejected by the gate ({} reopenings), {} invalid, {} late",
            n.usbl_fused, n.usbl_rejected, n.usbl_reopened, n.usbl_invalid, n.aid_late
        );
    }
    if n.magnetometer_unconfigured > 0 {
        println!(
            "  {} magnetometer readings not used (no [navigation.magnetometer])",
            n.magnetometer_unconfigured
        );
    } else if r.counts.magnetometer > 0 {
        println!(
            "  magnetometer heading: {} fused, {} rejected by the gate, {} disturbed, {} invalid",
            n.magnetometer_fused,
            n.magnetometer_rejected,
            n.magnetometer_disturbed,
            n.magnetometer_invalid
        );
    }
    let skipped = n.imu_out_of_order + n.imu_invalid + n.aid_late + r.counts.before_start;
    if skipped > 0 || n.imu_gaps > 0 {
        println!(
            "  skipped: {} IMU out of order, {} IMU invalid, {} late aids, {} before the initial state; {} IMU gaps bridged",
            n.imu_out_of_order, n.imu_invalid, n.aid_late, r.counts.before_start, n.imu_gaps
        );
    }
    let c = &r.counts;
    if c.written_out_of_order > 0 || c.late_aid_records > 0 || c.late_aids > 0 {
        println!(
            "  order: {} messages written out of time order put in their place ({} beyond the {:.0} s window); \
             {} aids applied late as the daemon's {} late-aid records say ({} records unmatched)",
            c.written_out_of_order,
            c.beyond_reorder_window,
            super::order::REORDER_WINDOW_NS as f64 * 1e-9,
            c.late_aids,
            c.late_aid_records,
            c.late_aid_records_unmatched
        );
    }
    if let Some(e) = &r.log_error {
        println!("  the log was not read whole: {e}");
    }
    if let Some(c) = &r.recorded_comparison {
        println!(
            "  against the recorded solutions: {} compared, {} differ, {} without a replayed solution{}",
            c.compared,
            c.differing,
            c.unmatched_recorded,
            match &c.first_difference {
                Some((t, what)) => format!("; first at t = {:.6} s: {what}", *t as f64 * 1e-9),
                None => String::new(),
            }
        );
    }
}
