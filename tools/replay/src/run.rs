//! A whole replay as one call ([`replay`]): the configuration it runs with (file, log header or
//! default, with a USBL coupling), the outputs (CSV or MCAP) and the report.

#[allow(unused_imports)]
use super::*;

/// What to replay and how (the options of `auvnav replay`).
#[derive(Debug, Clone)]
pub struct ReplayOptions {
    /// The log to replay (MCAP written by auvnav).
    pub log: PathBuf,
    /// Configuration TOML: `[navigation]` (filter settings) and an optional `[initial]` state.
    pub config: Option<PathBuf>,
    /// Write the solution and the diagnostics: MCAP, or CSV when the name ends in .csv (the
    /// diagnostics then go to NAME.diagnostics.csv).
    pub out: Option<PathBuf>,
    /// Write every Nth solution (diagnostics are always all written).
    pub decimate: u64,
    /// Distance travelled beyond which points enter the error/distance figure (m).
    pub min_distance: f64,
    /// Fuse the USBL fixes with this coupling (adaptive unscented filter): the configuration's
    /// `[navigation.usbl]`, or else the station survey in the log header of a simulated voyage.
    pub usbl: Option<auvnav_core::aid::usbl::Coupling>,
    /// Compare the solutions with those the log recorded on `nav/solution`.
    pub compare_recorded: bool,
    /// Where the truth channel's point sits from the IMU (body axes FRD, m): each truth record is
    /// moved to the IMU before it starts the navigation or is compared with it (and so written
    /// to the outputs). None: the truth describes the IMU.
    pub reference_lever_arm: Option<[f64; 3]>,
}

impl ReplayOptions {
    /// Replay `log` with the defaults: its own configuration, every solution, no output file.
    pub fn new(log: impl Into<PathBuf>) -> ReplayOptions {
        ReplayOptions {
            log: log.into(),
            config: None,
            out: None,
            decimate: 1,
            min_distance: 100.0,
            usbl: None,
            compare_recorded: false,
            reference_lever_arm: None,
        }
    }
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
    /// The daemon's session starts the recording holds: restarts of the daemon, each replayed
    /// from the checkpoint it continued from.
    pub sessions: crate::restarts::RestartCounts,
    pub navigator: NavCounters,
    /// IMU biases and DVL installation at the end of the replay (estimated where the
    /// configuration switches their states on, otherwise as configured).
    pub final_parameters: Option<FinalParameters>,
    /// Why the log ended early, when it did (for example a truncated file).
    pub log_error: Option<String>,
    /// With `--compare-recorded`: the replay against the recorded solutions.
    pub recorded_comparison: Option<RecordedComparison>,
    /// A surface run (a compass on the attitude channel, GNSS fixes, no IMU): its dead
    /// reckoning through the configured DVL installation against the fixes.
    pub dead_reckoning: Option<crate::surface::DeadReckoningAccuracy>,
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

/// Writes `text` to `path` atomically: into `path.partial`, synced, then renamed into place; on
/// failure nothing is left behind.
pub fn write_atomically(path: &Path, text: &str) -> Result<(), ReplayError> {
    let tmp = partial_path(path);
    let result = (|| -> std::io::Result<()> {
        let mut f = std::fs::File::create(&tmp)?;
        f.write_all(text.as_bytes())?;
        f.sync_all()?;
        std::fs::rename(&tmp, path)?;
        Ok(())
    })();
    if result.is_err() {
        let _ = std::fs::remove_file(&tmp);
    }
    result.map_err(|e| ReplayError::Output {
        path: path.to_path_buf(),
        source: e.into(),
    })
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

/// The log's header, or why it cannot be read.
fn log_header(log: &Path) -> Result<LogHeader, ReplayError> {
    let read = || -> Result<LogHeader, LogError> { LogReader::open(log)?.read_header() };
    read().map_err(|e| ReplayError::Log {
        path: log.to_path_buf(),
        source: e.into(),
    })
}

/// The configuration a replay runs with, and where it came from.
pub fn replay_config(a: &ReplayOptions) -> Result<(ReplayConfig, String), ReplayError> {
    let (mut cfg, mut source) = base_replay_config(a)?;
    if let Some(coupling) = a.usbl {
        match cfg.navigation.usbl.as_mut() {
            Some(u) => u.coupling = coupling,
            None => {
                let header = log_header(&a.log)?;
                let station =
                    auvnav_sim::StationGeometry::from_notes(&header.notes).ok_or_else(|| {
                        ReplayError::Input(format!(
                            "--usbl: {} has no station survey in its header; give the station \
                             in [navigation.usbl] of --config",
                            a.log.display()
                        ))
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

fn base_replay_config(a: &ReplayOptions) -> Result<(ReplayConfig, String), ReplayError> {
    if let Some(p) = &a.config {
        return Ok((load_config(p)?, p.display().to_string()));
    }
    // A recording carries the daemon's configuration: replay with it, as the daemon ran.
    let header = log_header(&a.log)?;
    if header.producer == "auvnav record" && !header.config.trim().is_empty() {
        let cfg =
            session_config_from_toml(&header.config).map_err(|e| ReplayError::EmbeddedConfig {
                log: a.log.clone(),
                source: crate::error::boxed(e),
            })?;
        return Ok((
            cfg,
            "the log header (embedded by auvnav record)".to_string(),
        ));
    }
    Ok((ReplayConfig::default(), "defaults".to_string()))
}

/// Replays a log: the configuration, the outputs, the report.
pub fn replay(a: &ReplayOptions) -> Result<ReplayReport, ReplayError> {
    if !(a.min_distance.is_finite() && a.min_distance >= 0.0) {
        return Err(ReplayError::Options(format!(
            "min_distance {}: must be >= 0 m",
            a.min_distance
        )));
    }
    if let Some(l) = a.reference_lever_arm
        && !l.iter().all(|x| x.is_finite() && x.abs() <= 100.0)
    {
        return Err(ReplayError::Options(format!(
            "reference_lever_arm {l:?}: expected three finite distances within ±100 m"
        )));
    }
    let (cfg, config_source) = replay_config(a)?;
    let decimate = a.decimate.max(1);
    let mut replay = Replay::new(&cfg, a.min_distance);
    if let Some(l) = a.reference_lever_arm {
        replay.set_reference_lever_arm(l);
    }
    if a.compare_recorded {
        replay.compare_with_recorded();
    }
    let start = std::time::Instant::now();
    let mut solutions = 0u64;
    let mut log_error = None;
    let config_text = toml::to_string(&cfg).unwrap_or_default();
    match &a.out {
        None => {
            log_error = run_log(&a.log, &mut replay, &mut |_| Ok(()))
                .map_err(|e| read_failure(&a.log, e))?
                .1;
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
                writeln!(nav_w, "{}", auvnav_core::csv::NAV_HEADER)?;
                writeln!(diag_w, "{DIAGNOSTICS_HEADER}")?;
                log_error = run_log(&a.log, &mut replay, &mut |o| {
                    match o {
                        Output::Solution(s) => {
                            solutions += 1;
                            if (solutions - 1).is_multiple_of(decimate) {
                                auvnav_core::csv::write_nav_row(&mut nav_w, s)
                                    .context(WritingOutput)?;
                            }
                        }
                        Output::Diagnostics(d) => {
                            write_diagnostics_row(&mut diag_w, d).context(WritingOutput)?
                        }
                        Output::Truth(_) | Output::LateAid(_) => {}
                    }
                    Ok(())
                })
                .context(ReadingLog)?
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
            result.map_err(|e| output_or_read_failure(&a.log, path, e))?;
        }
        Some(path) => {
            let mut header = LogHeader::new("auvnav replay", &config_text);
            header
                .notes
                .insert("replay.source_log".into(), a.log.display().to_string());
            write_log_atomically(path, &header, |w| {
                log_error = run_log(&a.log, &mut replay, &mut |o| {
                    let written = match o {
                        Output::Solution(s) => {
                            solutions += 1;
                            if (solutions - 1).is_multiple_of(decimate) {
                                w.write(topic::NAV_SOLUTION, s)
                            } else {
                                Ok(())
                            }
                        }
                        Output::Diagnostics(d) => w.write(topic::NAV_AID_DIAGNOSTICS, d),
                        Output::Truth(t) => w.write(topic::TRUTH, t),
                        Output::LateAid(r) => w.write(topic::NAV_LATE_AIDS, r),
                    };
                    written.context(WritingOutput)
                })
                .context(ReadingLog)?
                .1;
                Ok(())
            })
            .map_err(|e| output_or_read_failure(&a.log, path, e))?;
        }
    }
    let wall = start.elapsed().as_secs_f64();
    // With [alignment] the solutions are the alignment's, also when it did not finish.
    if replay.initial().is_none() && !replay.has_alignment() {
        return Err(ReplayError::Input(format!(
            "{}: no initial state: the log has no truth channel and the configuration no [initial] table",
            a.log.display()
        )));
    }
    let log_duration_s = replay.duration_s();
    let dead_reckoning = dead_reckoning(&a.log, &cfg, replay.counts.imu)?;
    Ok(ReplayReport {
        log: a.log.display().to_string(),
        configuration: config_source,
        initial_state: replay.initial().cloned(),
        accuracy: if replay.counts.imu == 0 {
            None
        } else {
            replay.accuracy()
        },
        samples_processed: replay.counts.imu,
        log_duration_s,
        wall_s: wall,
        real_time_factor: if wall > 0.0 {
            log_duration_s / wall
        } else {
            0.0
        },
        counts: replay.counts,
        sessions: replay.restart_counts(),
        navigator: replay.nav_counters(),
        final_parameters: replay.navigator().map(FinalParameters::of),
        log_error,
        recorded_comparison: replay.recorded_comparison().cloned(),
        dead_reckoning,
    })
}

/// Without an IMU sample the filter navigated on nothing: a surface run (a compass, GNSS) is
/// dead-reckoned from its compass instead.
fn dead_reckoning(
    log: &Path,
    cfg: &auvnav_core::config::SessionConfig,
    imu_samples: u64,
) -> Result<Option<crate::surface::DeadReckoningAccuracy>, ReplayError> {
    if imu_samples > 0 || !crate::surface::is_surface_run(log)? {
        return Ok(None);
    }
    let run = crate::surface::read_surface_run(log, &log.display().to_string(), None)?;
    Ok(run.accuracy(
        &cfg.navigation.dvl_installation(),
        &cfg.navigation.compass_deviation_deg,
    ))
}

/// Marks an error of an output sink (a CSV row, an MCAP record) inside `run_log`'s error.
#[derive(Debug)]
struct WritingOutput;

impl std::fmt::Display for WritingOutput {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str("writing the output")
    }
}

/// Marks `run_log`'s own error (reading the log, or a sink's error marked [`WritingOutput`]).
#[derive(Debug)]
struct ReadingLog;

impl std::fmt::Display for ReadingLog {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str("replaying the log")
    }
}

/// A failure while reading the log (`run_log`'s error when no output is written).
fn read_failure(log: &Path, e: anyhow::Error) -> ReplayError {
    ReplayError::Log {
        path: log.to_path_buf(),
        source: crate::error::boxed(e),
    }
}

/// A failure of a replay that writes `out`: the output's when a sink or the file failed, the
/// log's when the reader did.
fn output_or_read_failure(log: &Path, out: &Path, e: anyhow::Error) -> ReplayError {
    if e.downcast_ref::<WritingOutput>().is_none() && e.downcast_ref::<ReadingLog>().is_some() {
        read_failure(log, e)
    } else {
        ReplayError::Output {
            path: out.to_path_buf(),
            source: crate::error::boxed(e),
        }
    }
}
