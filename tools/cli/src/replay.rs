//! `auvnav replay`: runs a log through the navigation core as fast as it can.
//!
//! The same [`Navigator`] the daemon runs consumes the log's sensor messages in log order. The
//! initial state comes from the configuration's `[initial]` table when it has one, otherwise from
//! the first record of the log's truth channel (simulated truth, or the reference solution of an
//! imported data set); sensor messages before that are counted and skipped. When the log has a
//! truth channel, the solution is compared with it at every truth epoch (linear interpolation
//! between the two solutions around the epoch).

use crate::accuracy::{Accuracy, AccuracyTracker};
use anyhow::{Context, bail};
use auvnav_core::earth::Geodetic;
use auvnav_core::navigator::{NavCounters, Navigator, initial_state};
use auvnav_core::session::{Session, SessionOutput};
use auvnav_log::{LogError, LogHeader, LogMessage, LogReader, write_log_atomically};
use auvnav_shm_schema::{AidDiagnosticsV1, NavSolutionV1, TruthStateV1, topic};
use serde::Serialize;
use std::io::Write;
use std::path::{Path, PathBuf};

pub use auvnav_core::session::{InitialReport, InitialState};

/// The replay configuration file: `[navigation]` (the core's `NavConfig`) and an optional
/// `[initial]` state — the same file the daemon's `[navigation]`/`[initial]` tables hold.
pub type ReplayConfig = auvnav_core::session::SessionConfig;

/// Reads a replay configuration file and validates it as the daemon does.
pub fn load_config(path: &Path) -> anyhow::Result<ReplayConfig> {
    let text = std::fs::read_to_string(path)
        .with_context(|| format!("reading configuration {}", path.display()))?;
    let cfg: ReplayConfig =
        toml::from_str(&text).with_context(|| format!("configuration {}", path.display()))?;
    cfg.validate()
        .with_context(|| format!("configuration {}", path.display()))?;
    Ok(cfg)
}

/// One output of the navigator.
#[derive(Debug, Clone, Copy)]
pub enum Output<'a> {
    Solution(&'a NavSolutionV1),
    Diagnostics(&'a AidDiagnosticsV1),
    /// A truth record of the input, passed through so outputs can be compared with it.
    Truth(&'a TruthStateV1),
}

/// What a replay skipped or could not use, per kind of input.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize)]
pub struct ReplayCounts {
    pub messages: u64,
    pub imu: u64,
    pub dvl: u64,
    pub depth: u64,
    pub gnss: u64,
    /// USBL fixes (fused when the configuration has `[navigation.usbl]`; the navigator's
    /// counters say what became of them).
    pub usbl: u64,
    pub truth: u64,
    /// Sensor messages before the initial state was known (skipped).
    pub before_start: u64,
    /// Messages this replay does not use (magnetometer, outputs of an earlier run).
    pub unused: u64,
    /// Channels with a schema this program does not know (skipped).
    pub unknown: u64,
    /// Messages whose bytes do not match their schema (skipped).
    pub malformed: u64,
    /// Truth records older than the solution they would be compared with (skipped).
    pub truth_late: u64,
}

/// Estimated parameters at the end of a replay.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct FinalParameters {
    pub gyro_bias_deg_h: [f64; 3],
    pub accel_bias_ug: [f64; 3],
    /// DVL mounting roll, pitch, yaw w.r.t. the body (deg).
    pub dvl_mount_deg: [f64; 3],
    pub dvl_scale_factor: f64,
    pub dvl_lever_arm_m: [f64; 3],
    pub dvl_time_offset_s: f64,
}

impl FinalParameters {
    pub fn of(nav: &Navigator) -> FinalParameters {
        let (bg, ba) = nav.imu_biases();
        let d = nav.dvl_parameters();
        let (r, p, y) = nalgebra::Rotation3::from_matrix_unchecked(d.c_dvl_to_body).euler_angles();
        FinalParameters {
            gyro_bias_deg_h: (bg * 3600.0).map(f64::to_degrees).into(),
            accel_bias_ug: (ba / 9.806_65e-6).into(),
            dvl_mount_deg: [r.to_degrees(), p.to_degrees(), y.to_degrees()],
            dvl_scale_factor: d.scale,
            dvl_lever_arm_m: d.lever_arm_m.into(),
            dvl_time_offset_s: d.time_offset_s,
        }
    }
}

/// The replay state machine, fed one message at a time.
pub struct Replay {
    session: Session,
    tracker: AccuracyTracker,
    has_truth: bool,
    prev_solution: Option<NavSolutionV1>,
    pending_truth: Option<TruthStateV1>,
    pub counts: ReplayCounts,
    first_time_ns: Option<u64>,
    last_time_ns: u64,
}

impl Replay {
    pub fn new(cfg: &ReplayConfig, min_distance_m: f64) -> Replay {
        Replay {
            session: Session::new(cfg),
            tracker: AccuracyTracker::new(min_distance_m),
            has_truth: false,
            prev_solution: None,
            pending_truth: None,
            counts: ReplayCounts::default(),
            first_time_ns: None,
            last_time_ns: 0,
        }
    }

    pub fn navigator(&self) -> Option<&Navigator> {
        self.session.navigator()
    }

    /// Passes the session's outputs on, following the solutions for the truth comparison.
    fn forward<'o>(
        prev: &'o mut Option<NavSolutionV1>,
        pending: &'o mut Option<TruthStateV1>,
        tracker: &'o mut AccuracyTracker,
        out: &'o mut dyn FnMut(Output) -> anyhow::Result<()>,
    ) -> impl FnMut(SessionOutput) -> anyhow::Result<()> + 'o {
        move |o| match o {
            SessionOutput::Solution(sol) => {
                out(Output::Solution(sol))?;
                if let (Some(t), Some(p)) = (*pending, *prev)
                    && sol.host_time_ns >= t.host_time_ns
                {
                    tracker.add(&interpolate(&p, sol, t.host_time_ns), &t);
                    *pending = None;
                }
                *prev = Some(*sol);
                Ok(())
            }
            SessionOutput::Diagnostics(d) => out(Output::Diagnostics(d)),
        }
    }

    /// Processes one message in log order; outputs go to `out`.
    pub fn process(
        &mut self,
        m: &LogMessage,
        out: &mut dyn FnMut(Output) -> anyhow::Result<()>,
    ) -> anyhow::Result<()> {
        self.counts.messages += 1;
        let mut fwd = Self::forward(
            &mut self.prev_solution,
            &mut self.pending_truth,
            &mut self.tracker,
            out,
        );
        match m {
            LogMessage::Truth(t) => {
                drop(fwd);
                self.counts.truth += 1;
                self.has_truth = true;
                out(Output::Truth(t))?;
                self.note_time(t.host_time_ns);
                if !self.session.started()
                    && !self.session.has_configured_initial()
                    && !self.session.has_alignment()
                {
                    let state = initial_state(
                        t.host_time_ns as f64 * 1e-9,
                        Geodetic {
                            latitude_rad: t.latitude_rad,
                            longitude_rad: t.longitude_rad,
                            height_m: t.height_m,
                        },
                        t.velocity_ned_m_s,
                        t.euler_rad,
                    );
                    let mut fwd = Self::forward(
                        &mut self.prev_solution,
                        &mut self.pending_truth,
                        &mut self.tracker,
                        out,
                    );
                    self.session
                        .start(state, "first record of the truth channel", &mut fwd)?;
                }
                self.compare(t);
            }
            LogMessage::Imu(_)
            | LogMessage::Dvl(_)
            | LogMessage::Depth(_)
            | LogMessage::Gnss(_)
            | LogMessage::Usbl(_) => {
                match m {
                    LogMessage::Imu(_) => self.counts.imu += 1,
                    LogMessage::Dvl(_) => self.counts.dvl += 1,
                    LogMessage::Depth(_) => self.counts.depth += 1,
                    LogMessage::Gnss(_) => self.counts.gnss += 1,
                    _ => self.counts.usbl += 1,
                }
                if let Some(x) = m.sensor() {
                    self.session.feed(&x, &mut fwd)?;
                    drop(fwd);
                    self.note_time(x.host_time_ns());
                }
            }
            LogMessage::Unknown => self.counts.unknown += 1,
            _ => self.counts.unused += 1,
        }
        self.counts.before_start = self.session.before_start;
        Ok(())
    }

    /// Applies the aid messages still waiting for an IMU sample: call at the end of the input.
    pub fn finish(
        &mut self,
        out: &mut dyn FnMut(Output) -> anyhow::Result<()>,
    ) -> anyhow::Result<()> {
        let mut fwd = Self::forward(
            &mut self.prev_solution,
            &mut self.pending_truth,
            &mut self.tracker,
            out,
        );
        self.session.finish(&mut fwd)
    }

    fn note_time(&mut self, t_ns: u64) {
        self.first_time_ns.get_or_insert(t_ns);
        self.last_time_ns = self.last_time_ns.max(t_ns);
    }

    fn compare(&mut self, t: &TruthStateV1) {
        let Some(prev) = self.prev_solution else {
            return;
        };
        if prev.host_time_ns == t.host_time_ns {
            self.tracker.add(&prev, t);
        } else if prev.host_time_ns > t.host_time_ns {
            self.counts.truth_late += 1;
        } else {
            // Wait for the first solution at or after the truth epoch. A newer truth record
            // replaces one still waiting (only possible when the IMU is slower than the truth).
            if self.pending_truth.replace(*t).is_some() {
                self.counts.truth_late += 1;
            }
        }
    }

    /// The accuracy against the truth channel, when the log has one.
    pub fn accuracy(&self) -> Option<Accuracy> {
        self.has_truth.then(|| self.tracker.result())
    }

    pub fn initial(&self) -> Option<&InitialReport> {
        self.session.initial()
    }

    pub fn nav_counters(&self) -> NavCounters {
        self.session
            .navigator()
            .map(|n| n.counters())
            .unwrap_or_default()
    }

    /// Log time covered by the messages seen (s).
    pub fn duration_s(&self) -> f64 {
        self.first_time_ns
            .map(|f| (self.last_time_ns - f) as f64 * 1e-9)
            .unwrap_or(0.0)
    }
}

/// The solution at `t_ns` between `a` and `b` (position, velocity and heading interpolated
/// linearly; the rest taken from `b`).
pub fn interpolate(a: &NavSolutionV1, b: &NavSolutionV1, t_ns: u64) -> NavSolutionV1 {
    let span = b.host_time_ns.saturating_sub(a.host_time_ns);
    if span == 0 {
        return *b;
    }
    let w = t_ns.saturating_sub(a.host_time_ns) as f64 / span as f64;
    let lerp = |x: f64, y: f64| x + (y - x) * w;
    let mut s = *b;
    s.host_time_ns = t_ns;
    s.latitude_rad = lerp(a.latitude_rad, b.latitude_rad);
    s.longitude_rad = lerp(a.longitude_rad, b.longitude_rad);
    s.height_m = lerp(a.height_m, b.height_m);
    for i in 0..3 {
        s.velocity_ned_m_s[i] = lerp(a.velocity_ned_m_s[i], b.velocity_ned_m_s[i]);
    }
    let dyaw = (b.euler_rad[2] - a.euler_rad[2] + std::f64::consts::PI)
        .rem_euclid(std::f64::consts::TAU)
        - std::f64::consts::PI;
    s.euler_rad[2] = a.euler_rad[2] + dyaw * w;
    s
}

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
    #[arg(long, value_enum)]
    pub usbl: Option<auvnav_core::aid::usbl::Coupling>,
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
    pub log_seconds: f64,
    pub wall_seconds: f64,
    pub real_time_factor: f64,
    pub counts: ReplayCounts,
    pub navigator: NavCounters,
    /// IMU biases and DVL installation at the end of the replay (estimated where the
    /// configuration switches their states on, otherwise as configured).
    pub final_parameters: Option<FinalParameters>,
    /// Why the log ended early, when it did (for example a truncated file).
    pub log_error: Option<String>,
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
        let raw = match reader.next_message() {
            Ok(Some(raw)) => raw,
            Ok(None) => {
                replay.finish(out)?;
                return Ok((header, None));
            }
            Err(e @ (LogError::Truncated | LogError::Mcap(_))) => {
                replay.finish(out)?;
                return Ok((header, Some(e.to_string())));
            }
            Err(e) => return Err(e).with_context(|| format!("reading {}", log.display())),
        };
        match raw.decode_any() {
            Ok(m) => replay.process(&m, out)?,
            Err(_) => replay.counts.malformed += 1,
        }
    }
}

fn partial_path(path: &Path) -> PathBuf {
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
                let header = LogReader::open(&a.log)
                    .and_then(|mut r| r.read_header())
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
    let header = LogReader::open(&a.log)
        .and_then(|mut r| r.read_header())
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
                        Output::Truth(_) => {}
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
                    }
                    Ok(())
                })?
                .1;
                Ok(())
            })?;
        }
    }
    let wall = start.elapsed().as_secs_f64();
    if replay.initial().is_none() {
        bail!(
            "{}: no initial state: the log has no truth channel and the configuration no [initial] table",
            a.log.display()
        );
    }
    let log_seconds = replay.duration_s();
    Ok(ReplayReport {
        log: a.log.display().to_string(),
        configuration: config_source,
        initial_state: replay.initial().cloned(),
        accuracy: replay.accuracy(),
        samples_processed: replay.counts.imu,
        log_seconds,
        wall_seconds: wall,
        real_time_factor: if wall > 0.0 { log_seconds / wall } else { 0.0 },
        counts: replay.counts,
        navigator: replay.nav_counters(),
        final_parameters: replay.navigator().map(FinalParameters::of),
        log_error,
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
        r.log_seconds,
        r.wall_seconds,
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
    let skipped = n.imu_out_of_order + n.imu_invalid + n.aid_late + r.counts.before_start;
    if skipped > 0 || n.imu_gaps > 0 {
        println!(
            "  skipped: {} IMU out of order, {} IMU invalid, {} late aids, {} before the initial state; {} IMU gaps bridged",
            n.imu_out_of_order, n.imu_invalid, n.aid_late, r.counts.before_start, n.imu_gaps
        );
    }
    if let Some(e) = &r.log_error {
        println!("  the log ended early: {e}");
    }
}
