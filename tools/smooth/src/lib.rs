//! `auvnav smooth`: post-processing of recorded voyages with the forward–backward smoother of the
//! navigation core (`auvnav_core::smoother`).
//!
//! Each log runs twice through the replay (the session's one feed path): the first run records
//! the filter's epochs, the backward pass smooths them, and the second run — the same solutions,
//! the core being deterministic — writes each solution twice: as the filter had it (`nav/solution`)
//! and smoothed (`nav/solution_smoothed`, same schema, smoothed standard deviations). Fixes from
//! the log (GNSS, USBL) and from a fix file (`--fixes`, [`fixes`]) aid both runs. Against the log's
//! truth or reference channel the forward and smoothed horizontal errors are compared at every
//! reference epoch.
//!
//! A library: options in, typed reports and the output files out; it never prints (with the
//! `clap` feature, the option structs are also the command line's).
//!
//! Long on purpose: the smoothing command (options, the two passes, the outputs) and its report
//! types, which export, report and montecarlo build on.
#![forbid(unsafe_code)]

pub mod error;
pub mod export;
pub use auvnav_import::fixes;
pub mod montecarlo;
pub mod report;
pub mod retime;
mod writer;

use auvnav_core::ekf;
use auvnav_core::smoother::{SmoothedParameters, SmoothedTrack, SmoothedValue, SmootherLog};
use auvnav_log::{LogHeader, LogMessage, write_log_atomically};
use auvnav_replay::{Output, Replay, ReplayOptions, replay_config, run_log};
use auvnav_shm_schema::{AidDiagnosticsV1, AidSource, NavSolutionV1, TruthStateV1};
pub use error::SmoothError;
use serde::Serialize;
use std::io::Write;
use std::path::{Path, PathBuf};

/// The channel of the smoothed solution, beside the forward `nav/solution`.
pub const NAV_SOLUTION_SMOOTHED: &str = "nav/solution_smoothed";

/// Command-line arguments of `auvnav smooth`.
#[derive(Debug, Clone)]
#[cfg_attr(feature = "clap", derive(clap::Args))]
pub struct SmoothOptions {
    /// The logs to smooth (MCAP written by the recorder, `auvnav import` or `auvnav sim`); each
    /// is smoothed on its own.
    #[cfg_attr(feature = "clap", arg(required = true))]
    pub logs: Vec<PathBuf>,
    /// Folder for the outputs (created): per log `<name>.smoothed.csv`, `<name>.smoothed.mcap`,
    /// `<name>.parameters.json`, `<name>.geojson`, `<name>.kml`, `<name>.track.csv`.
    #[cfg_attr(feature = "clap", arg(long))]
    pub out: PathBuf,
    /// Configuration TOML (`[navigation]`, `[initial]`), as for `auvnav replay`.
    #[cfg_attr(feature = "clap", arg(long))]
    pub config: Option<PathBuf>,
    /// Position fixes: CSV `time_s, latitude_deg, longitude_deg, depth_m, std_m` on the log's
    /// clock (e.g. surface fixes before and after a dive); fused as GNSS positions.
    #[cfg_attr(feature = "clap", arg(long))]
    pub fixes: Option<PathBuf>,
    /// Fuse the log's USBL fixes with this coupling (as `auvnav replay --usbl`).
    #[cfg_attr(feature = "clap", arg(long, value_parser = auvnav_studies::args::config_enum::<auvnav_core::aid::usbl::Coupling>(auvnav_core::aid::usbl::Coupling::NAMES)))]
    pub usbl: Option<auvnav_core::aid::usbl::Coupling>,
    /// Points per second in the GeoJSON, KML and plain CSV exports.
    #[cfg_attr(feature = "clap", arg(long, default_value_t = 1.0))]
    pub export_rate: f64,
    /// Solutions per second in `<name>.smoothed.csv` and `<name>.smoothed.mcap` (the first
    /// solution of each period, forward and smoothed alike); default: every solution (the IMU
    /// rate, about 200 MB of CSV per hour at 200 Hz). The figures and the report use every
    /// solution either way.
    #[cfg_attr(feature = "clap", arg(long))]
    pub solution_rate: Option<f64>,
    /// Unix time (s) of the log's time 0, for the UTC column of the plain CSV; otherwise taken
    /// from the first GNSS fix with a valid GNSS time, else the column stays empty.
    #[cfg_attr(feature = "clap", arg(long))]
    pub unix_time_of_log_zero: Option<f64>,
    /// Keep at most this many MiB of the smoother's epochs in memory; the rest goes to a
    /// temporary file in `--spill-dir` (default: the output folder).
    #[cfg_attr(feature = "clap", arg(long, default_value_t = 1024))]
    pub memory_budget_mib: usize,
    /// Folder for the smoother's spill file.
    #[cfg_attr(feature = "clap", arg(long))]
    pub spill_dir: Option<PathBuf>,
    /// Write a report (Markdown, SVG figures, JSON) into this folder.
    #[cfg_attr(feature = "clap", arg(long))]
    pub report: Option<PathBuf>,
    /// Print the result as JSON.
    #[cfg_attr(feature = "clap", arg(long))]
    pub json: bool,
}

impl SmoothOptions {
    /// `logs` smoothed into `out` with the command's defaults (no fix file, one exported point
    /// per second, every solution, 1 GiB in memory before spilling, no report, progress shown).
    pub fn new(logs: Vec<PathBuf>, out: impl Into<PathBuf>) -> SmoothOptions {
        SmoothOptions {
            logs,
            out: out.into(),
            config: None,
            fixes: None,
            usbl: None,
            export_rate: 1.0,
            solution_rate: None,
            unix_time_of_log_zero: None,
            memory_budget_mib: 1024,
            spill_dir: None,
            report: None,
            json: false,
        }
    }
}

/// Horizontal error figures against the reference (m).
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize)]
pub struct ErrorFigures {
    pub horizontal_error_rms_m: f64,
    pub horizontal_error_max_m: f64,
    pub horizontal_error_final_m: f64,
}

impl ErrorFigures {
    fn of(errors: &[f64]) -> ErrorFigures {
        if errors.is_empty() {
            return ErrorFigures::default();
        }
        ErrorFigures {
            horizontal_error_rms_m: (errors.iter().map(|e| e * e).sum::<f64>()
                / errors.len() as f64)
                .sqrt(),
            horizontal_error_max_m: errors.iter().copied().fold(0.0, f64::max),
            horizontal_error_final_m: errors.last().copied().unwrap_or(0.0),
        }
    }
}

/// Forward and smoothed against the log's truth or reference channel.
#[derive(Debug, Clone, Default, PartialEq, Serialize)]
pub struct AgainstReference {
    /// Reference epochs compared (those while the filter ran).
    pub epochs: usize,
    pub forward: ErrorFigures,
    pub smoothed: ErrorFigures,
    /// Mean over the epochs of the horizontal normalised estimation error squared of the
    /// smoothed track (2 degrees of freedom: 2 when the smoothed covariance is honest).
    pub smoothed_nees_horizontal_mean: f64,
    /// The same for the forward track.
    pub forward_nees_horizontal_mean: f64,
}

/// Fixes used and what became of them.
#[derive(Debug, Clone, Default, Serialize)]
pub struct FixUse {
    /// Fixes of the fix file inside the log's time span (fed).
    pub from_file: usize,
    /// Fixes of the fix file outside the log's time span (not used).
    pub from_file_outside_log: usize,
    pub gnss_fused: u64,
    pub gnss_rejected: u64,
    pub usbl_fused: u64,
    pub usbl_rejected: u64,
}

/// One fix's innovation (GNSS or USBL), for the report.
#[derive(Debug, Clone, Copy, Serialize)]
pub struct FixInnovation {
    pub time_s: f64,
    pub source: &'static str,
    /// Observation minus prediction (m; for a GNSS fix north, east, down).
    pub innovation: [f64; 3],
    pub test_ratio: f64,
    pub fused: bool,
}

/// Smoothed IMU biases at an epoch.
#[derive(Debug, Clone, Serialize)]
pub struct SmoothedBiases {
    pub time_s: f64,
    pub gyro_bias_deg_h: [SmoothedValue; 3],
    pub accel_bias_ug: [SmoothedValue; 3],
}

/// The smoothed parameter states at the first and last epoch of the (last) chain.
#[derive(Debug, Clone, Serialize)]
pub struct ParameterReport {
    pub first: SmoothedParameters,
    pub last: SmoothedParameters,
    pub imu_biases_first: Option<SmoothedBiases>,
    pub imu_biases_last: Option<SmoothedBiases>,
}

/// Where the outputs of one log went.
#[derive(Debug, Clone, Serialize)]
pub struct Outputs {
    pub smoothed_csv: String,
    pub mcap: String,
    pub parameters_json: String,
    pub geojson: String,
    pub kml: String,
    pub plain_csv: String,
}

/// What smoothing one log gave.
#[derive(Debug, Clone, Serialize)]
pub struct LogSmoothReport {
    pub log: String,
    pub configuration: String,
    pub outputs: Outputs,
    pub log_duration_s: f64,
    pub imu_samples: u64,
    /// Covariance epochs smoothed.
    pub epochs: usize,
    /// Times the filter started or restarted (each a chain of its own).
    pub chains: u64,
    /// Epochs where a smoothed variance came out above the filtered one (should be 0).
    pub epochs_smoothed_variance_above_filtered: u64,
    pub solutions_smoothed: u64,
    /// Solutions before the filter ran (alignment), written unchanged.
    pub solutions_outside_filter: u64,
    pub fixes: FixUse,
    pub against_reference: Option<AgainstReference>,
    pub parameters: Option<ParameterReport>,
    /// With the DVL time offset estimated: the offsets (s) the readings were retimed at, one per
    /// run after the first, the last being the run reported (`retime`); empty for one run.
    pub dvl_retimed_s: Vec<f64>,
    /// UTC of the log's time 0 used for the exports, and where it came from.
    pub unix_time_of_log_zero: Option<f64>,
    pub utc_source: String,
    pub forward_wall_s: f64,
    pub backward_wall_s: f64,
    pub second_pass_wall_s: f64,
    /// Log time over the whole wall time of the three passes.
    pub real_time_factor: f64,
    /// Bytes of epochs the smoother wrote to its spill file.
    pub spilled_bytes: u64,
    pub log_error: Option<String>,
    #[serde(skip)]
    pub figures: report::Figures,
}

/// What `auvnav smooth` gave.
#[derive(Debug, Clone, Serialize)]
pub struct SmoothReport {
    pub fix_file: Option<fixes::FixFile>,
    pub logs: Vec<LogSmoothReport>,
    /// The process's peak resident memory so far (MiB; Linux `VmHWM`), when the system says.
    pub peak_memory_mib: Option<f64>,
}

/// This process's peak resident memory (MiB), from `/proc/self/status`.
pub fn peak_memory_mib() -> Option<f64> {
    let status = std::fs::read_to_string("/proc/self/status").ok()?;
    let line = status.lines().find(|l| l.starts_with("VmHWM:"))?;
    let kib: f64 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kib / 1024.0)
}

/// Forward and smoothed solutions against the reference epochs: each reference epoch between two
/// solutions is compared with both interpolated to its time.
#[derive(Default)]
struct Comparison {
    truths: Vec<TruthStateV1>,
    next: usize,
    /// The previous forward and smoothed solutions' times and positions (all the comparison
    /// uses of them: copying whole solutions at 200 Hz cost more than the rest of it).
    prev: Option<(Position, Position)>,
    forward: Vec<f64>,
    smoothed: Vec<f64>,
    nees_smoothed: Vec<f64>,
    nees_forward: Vec<f64>,
}

/// A solution's time and position.
#[derive(Debug, Clone, Copy)]
struct Position {
    time_ns: u64,
    latitude_rad: f64,
    longitude_rad: f64,
    height_m: f64,
}

impl Position {
    fn of(s: &NavSolutionV1) -> Self {
        Position {
            time_ns: s.host_time_ns,
            latitude_rad: s.latitude_rad,
            longitude_rad: s.longitude_rad,
            height_m: s.height_m,
        }
    }

    /// `b` at `t_ns`, its position interpolated from this one's (as `auvnav_replay::interpolate`
    /// does; the other fields are `b`'s).
    fn towards(&self, b: &NavSolutionV1, t_ns: u64) -> NavSolutionV1 {
        let a = NavSolutionV1 {
            host_time_ns: self.time_ns,
            latitude_rad: self.latitude_rad,
            longitude_rad: self.longitude_rad,
            height_m: self.height_m,
            ..*b
        };
        auvnav_replay::interpolate(&a, b, t_ns)
    }
}

fn horizontal_error(s: &NavSolutionV1, t: &TruthStateV1) -> nalgebra::Vector3<f64> {
    let g = |lat, lon, h| auvnav_core::earth::Geodetic {
        latitude_rad: lat,
        longitude_rad: lon,
        height_m: h,
    };
    auvnav_core::earth::ned_offset(
        &g(t.latitude_rad, t.longitude_rad, t.height_m),
        &g(s.latitude_rad, s.longitude_rad, s.height_m),
    )
}

fn nees_h(e: &nalgebra::Vector3<f64>, s: &NavSolutionV1) -> f64 {
    let (sn, se) = (s.position_std_ned_m[0], s.position_std_ned_m[1]);
    if sn > 0.0 && se > 0.0 {
        (e.x / sn).powi(2) + (e.y / se).powi(2)
    } else {
        f64::NAN
    }
}

impl Comparison {
    fn solution(&mut self, fwd: &NavSolutionV1, sm: &NavSolutionV1, figures: &mut report::Figures) {
        let t = fwd.host_time_ns;
        if let Some((pf, ps)) = self.prev {
            while let Some(truth) = self.truths.get(self.next) {
                if truth.host_time_ns > t {
                    break;
                }
                self.next += 1;
                if truth.host_time_ns <= pf.time_ns {
                    continue;
                }
                let f = pf.towards(fwd, truth.host_time_ns);
                let s = ps.towards(sm, truth.host_time_ns);
                let (ef, es) = (horizontal_error(&f, truth), horizontal_error(&s, truth));
                self.forward.push(ef.xy().norm());
                self.smoothed.push(es.xy().norm());
                self.nees_forward.push(nees_h(&ef, &f));
                self.nees_smoothed.push(nees_h(&es, &s));
                figures.reference(truth, ef.xy().norm(), es.xy().norm());
            }
        } else {
            while self
                .truths
                .get(self.next)
                .is_some_and(|x| x.host_time_ns <= t)
            {
                self.next += 1;
            }
        }
        self.prev = Some((Position::of(fwd), Position::of(sm)));
    }

    fn result(&self) -> Option<AgainstReference> {
        if self.forward.is_empty() {
            return None;
        }
        let mean = |v: &[f64]| {
            let f: Vec<f64> = v.iter().copied().filter(|x| x.is_finite()).collect();
            f.iter().sum::<f64>() / f.len().max(1) as f64
        };
        Some(AgainstReference {
            epochs: self.forward.len(),
            forward: ErrorFigures::of(&self.forward),
            smoothed: ErrorFigures::of(&self.smoothed),
            smoothed_nees_horizontal_mean: mean(&self.nees_smoothed),
            forward_nees_horizontal_mean: mean(&self.nees_forward),
        })
    }
}

/// The file name stem of a log.
fn stem(log: &Path) -> String {
    log.file_stem()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_else(|| "log".into())
}

fn replay_options(a: &SmoothOptions, log: &Path) -> ReplayOptions {
    ReplayOptions {
        config: a.config.clone(),
        usbl: a.usbl,
        ..ReplayOptions::new(log)
    }
}

fn biases_at(
    track: &SmoothedTrack,
    i: usize,
    sol: Option<&NavSolutionV1>,
) -> Option<SmoothedBiases> {
    let sol = sol?;
    let var = track.epochs.variance(i);
    let deg_h = |rad_s: f64| rad_s.to_degrees() * 3600.0;
    let ug = |m_s2: f64| m_s2 / 9.806_65e-6;
    Some(SmoothedBiases {
        time_s: track.epochs.time_ns[i] as f64 * 1e-9,
        gyro_bias_deg_h: std::array::from_fn(|k| SmoothedValue {
            value: deg_h(sol.gyro_bias_rad_s[k]),
            std: deg_h(var[ekf::BG + k].sqrt()),
        }),
        accel_bias_ug: std::array::from_fn(|k| SmoothedValue {
            value: ug(sol.accel_bias_m_s2[k]),
            std: ug(var[ekf::BA + k].sqrt()),
        }),
    })
}

fn parameters(
    track: &SmoothedTrack,
    first: Option<&NavSolutionV1>,
    last: Option<&NavSolutionV1>,
) -> Option<ParameterReport> {
    let [(first_i, first_p), (last_i, last_p)] = track.last_chain_parameters()?;
    Some(ParameterReport {
        first: first_p,
        last: last_p,
        imu_biases_first: biases_at(track, first_i, first),
        imu_biases_last: biases_at(track, last_i, last),
    })
}

/// Smooths one log with the fixes of `fix_file` (those inside the log's time span).
pub fn smooth_log(
    a: &SmoothOptions,
    log: &Path,
    fix_file: Option<&fixes::FixFile>,
) -> Result<LogSmoothReport, SmoothError> {
    smooth_log_with(a, log, fix_file, &|_| {})
}

/// [`smooth_log`] with the replay configuration adjusted first (e.g. installation states
/// switched on).
// Long on purpose: the two replays and the smoothing between them over one log share the replay
// configuration, the recorded epochs and the output writers.
pub fn smooth_log_with(
    a: &SmoothOptions,
    log: &Path,
    fix_file: Option<&fixes::FixFile>,
    adjust: &dyn Fn(&mut auvnav_replay::ReplayConfig),
) -> Result<LogSmoothReport, SmoothError> {
    let (mut cfg, configuration) = replay_config(&replay_options(a, log))?;
    adjust(&mut cfg);
    let name = stem(log);
    let spill_dir = a.spill_dir.clone().unwrap_or_else(|| a.out.clone());
    // The fixes inside the log's time span (from a quick read before the passes), fed in both
    // passes so that both see the same messages.
    let fix_messages = |span: Option<(u64, u64)>| -> (Vec<LogMessage>, usize, usize) {
        let Some(f) = fix_file else {
            return (Vec::new(), 0, 0);
        };
        let mut inside = Vec::new();
        let mut outside = 0;
        for (i, x) in f.fixes.iter().enumerate() {
            let g = x.to_gnss(i as u64 + 1);
            match span {
                Some((t0, t1)) if g.host_time_ns < t0 || g.host_time_ns > t1 => outside += 1,
                _ => inside.push(LogMessage::Gnss(g)),
            }
        }
        let n = inside.len();
        (inside, n, outside)
    };
    let scan = scan_log(log)?;
    let (span, gnss_time) = (scan.span_ns, scan.unix_time_of_log_zero);
    let (fix_msgs, from_file, from_file_outside_log) = fix_messages(span);

    // First pass: the forward filter, recording its epochs, and the backward pass over them;
    // again with the DVL readings retimed while an estimated DVL time offset moves (`retime`).
    let budget = a.memory_budget_mib.saturating_mul(1 << 20);
    let pass = |cfg: &auvnav_replay::ReplayConfig| {
        forward_and_back(cfg, log, fix_msgs.clone(), &spill_dir, budget)
    };
    let mut passes = pass(&cfg)?;
    let mut dvl_retimed_s = Vec::new();
    let mut earlier_walls_s = (0.0, 0.0);
    while dvl_retimed_s.len() < retime::MAX_RETIMINGS {
        let estimate = passes.track.last_chain_parameters();
        let Some(offset) = retime::next_offset(&cfg.navigation, estimate.as_ref()) else {
            break;
        };
        retime::set_dvl_time_offset(&mut cfg.navigation, offset);
        dvl_retimed_s.push(offset);
        earlier_walls_s.0 += passes.forward_wall_s;
        earlier_walls_s.1 += passes.backward_wall_s;
        passes = pass(&cfg)?;
    }
    let ForwardAndBack {
        mut track,
        truths,
        forward_solutions,
        chains,
        spilled_bytes,
        log_error,
        forward_wall_s,
        backward_wall_s,
    } = passes;
    // The walls count every run's passes.
    let (forward_wall_s, backward_wall_s) = (
        forward_wall_s + earlier_walls_s.0,
        backward_wall_s + earlier_walls_s.1,
    );

    // Second pass: the same forward run, each solution written as it was and smoothed.
    let t_second = std::time::Instant::now();
    let mut second = Replay::new(&cfg, 100.0);
    second.inject(fix_msgs);
    let mut cmp = Comparison {
        truths,
        ..Default::default()
    };
    let mut figures = report::Figures::default();
    let mut decimator = export::Decimator::new(a.export_rate);
    let mut written_period = None;
    let period_ns = a.solution_rate.map(|hz| (1e9 / hz).round().max(1.0) as u64);
    let mut innovations = Vec::new();
    let mut second_solutions = 0u64;
    let (mut first_smoothed, mut last_smoothed) = (None, None);
    let csv_path = a.out.join(format!("{name}.smoothed.csv"));
    let mcap_path = a.out.join(format!("{name}.smoothed.mcap"));
    let csv_partial = auvnav_replay::partial_path(&csv_path);
    // A megabyte at a time: some 200 MB per hour at 200 Hz, in 8 kB writes a system call per
    // 30 rows.
    let mut csv = std::io::BufWriter::with_capacity(
        1 << 20,
        std::fs::File::create(&csv_partial).map_err(|e| SmoothError::output(&csv_path, e))?,
    );
    writeln!(csv, "{}", auvnav_core::csv::NAV_HEADER)
        .map_err(|e| SmoothError::output(&csv_path, e))?;
    let mut header = LogHeader::new("auvnav smooth", &toml::to_string(&cfg).unwrap_or_default());
    header
        .notes
        .insert("smooth.source_log".into(), log.display().to_string());
    let written = write_log_atomically(&mcap_path, &header, |w| {
        writer::write_beside(w, &mut csv, |out| {
            run_log(log, &mut second, &mut |o| {
                match o {
                    Output::Solution(s) => {
                        second_solutions += 1;
                        let sm = track.apply(s);
                        // The first solution of each output period (every one without a rate).
                        let period = period_ns.map(|p| s.host_time_ns / p);
                        if period.is_none() || period != written_period {
                            written_period = period;
                            out.push(writer::Item::Solution {
                                filtered: *s,
                                smoothed: sm,
                            })?;
                        }
                        let filtering = track
                            .epochs
                            .time_ns
                            .first()
                            .is_some_and(|&t0| s.host_time_ns >= t0);
                        if filtering {
                            cmp.solution(s, &sm, &mut figures);
                            figures.solution(s, &sm);
                            decimator.push(export::TrackPoint::of(&sm));
                            first_smoothed.get_or_insert(sm);
                            last_smoothed = Some(sm);
                        }
                    }
                    Output::Diagnostics(d) => {
                        out.push(writer::Item::Diagnostics(*d))?;
                        if let Some(i) = fix_innovation(d) {
                            innovations.push(i);
                        }
                    }
                    Output::Truth(t) => out.push(writer::Item::Truth(*t))?,
                    Output::LateAid(r) => out.push(writer::Item::LateAid(*r))?,
                }
                Ok(())
            })
        })?;
        Ok(())
    });
    let finish_csv = (|| -> anyhow::Result<()> {
        written?;
        csv.flush()?;
        std::fs::rename(&csv_partial, &csv_path)?;
        Ok(())
    })();
    if let Err(e) = finish_csv {
        let _ = std::fs::remove_file(&csv_partial);
        return Err(SmoothError::Output {
            path: a.out.clone(),
            source: e
                .context(format!("writing the outputs of {}", log.display()))
                .into(),
        });
    }
    if second_solutions != forward_solutions {
        return Err(SmoothError::NotRepeatable(format!(
            "{}: the second pass gave {second_solutions} solutions, the first {forward_solutions}: \
             the replay is not deterministic here, the smoothed track would not match",
            log.display()
        )));
    }
    let second_pass_wall_s = t_second.elapsed().as_secs_f64();

    let (unix_offset, utc_source) = match (a.unix_time_of_log_zero, gnss_time) {
        (Some(o), _) => (Some(o), "--unix-time-of-log-zero".to_string()),
        (None, Some(o)) => (
            Some(o),
            "the first GNSS fix with a valid GNSS time".to_string(),
        ),
        (None, None) => (
            None,
            "none: the UTC column is empty (log time in time_s)".to_string(),
        ),
    };
    let points = decimator.finish();
    let outputs = Outputs {
        smoothed_csv: csv_path.display().to_string(),
        mcap: mcap_path.display().to_string(),
        parameters_json: a
            .out
            .join(format!("{name}.parameters.json"))
            .display()
            .to_string(),
        geojson: a.out.join(format!("{name}.geojson")).display().to_string(),
        kml: a.out.join(format!("{name}.kml")).display().to_string(),
        plain_csv: a
            .out
            .join(format!("{name}.track.csv"))
            .display()
            .to_string(),
    };
    let write = auvnav_replay::write_atomically;
    write(
        Path::new(&outputs.geojson),
        &export::geojson(&name, &points, unix_offset),
    )?;
    write(Path::new(&outputs.kml), &export::kml(&name, &points))?;
    write(
        Path::new(&outputs.plain_csv),
        &export::plain_csv(&points, unix_offset),
    )?;
    let params = parameters(&track, first_smoothed.as_ref(), last_smoothed.as_ref());
    let params_json = serde_json::to_string_pretty(&params)
        .map_err(|e| SmoothError::output(Path::new(&outputs.parameters_json), e))?;
    write(Path::new(&outputs.parameters_json), &params_json)?;
    let nav = second.nav_counters();
    let duration = second.duration_s();
    let wall = forward_wall_s + backward_wall_s + second_pass_wall_s;
    figures.innovations = innovations;
    Ok(LogSmoothReport {
        log: log.display().to_string(),
        configuration,
        outputs,
        log_duration_s: duration,
        imu_samples: second.counts.imu,
        epochs: track.epochs.len(),
        chains,
        epochs_smoothed_variance_above_filtered: track.larger_than_filtered,
        solutions_smoothed: track.solutions_smoothed,
        solutions_outside_filter: track.solutions_outside,
        fixes: FixUse {
            from_file,
            from_file_outside_log,
            gnss_fused: nav.gnss_fused,
            gnss_rejected: nav.gnss_rejected,
            usbl_fused: nav.usbl_fused,
            usbl_rejected: nav.usbl_rejected,
        },
        against_reference: cmp.result(),
        parameters: params,
        dvl_retimed_s,
        unix_time_of_log_zero: unix_offset,
        utc_source,
        forward_wall_s,
        backward_wall_s,
        second_pass_wall_s,
        real_time_factor: if wall > 0.0 { duration / wall } else { 0.0 },
        spilled_bytes,
        log_error,
        figures,
    })
}

/// The first pass over one log (the forward filter, recording its epochs) and the backward pass.
struct ForwardAndBack {
    track: SmoothedTrack,
    truths: Vec<TruthStateV1>,
    forward_solutions: u64,
    chains: u64,
    spilled_bytes: u64,
    log_error: Option<String>,
    forward_wall_s: f64,
    backward_wall_s: f64,
}

fn forward_and_back(
    cfg: &auvnav_replay::ReplayConfig,
    log: &Path,
    fix_msgs: Vec<LogMessage>,
    spill_dir: &Path,
    memory_budget_bytes: usize,
) -> Result<ForwardAndBack, SmoothError> {
    let t_start = std::time::Instant::now();
    let mut first = Replay::new(cfg, 100.0);
    first.inject(fix_msgs);
    first.record_for_smoothing(SmootherLog::spilling(spill_dir, memory_budget_bytes));
    let mut truths = Vec::new();
    let mut forward_solutions = 0u64;
    let (_, log_error) = run_log(log, &mut first, &mut |o| {
        match o {
            Output::Truth(t) => truths.push(*t),
            Output::Solution(_) => forward_solutions += 1,
            _ => {}
        }
        Ok(())
    })
    .map_err(|e| SmoothError::Log {
        path: log.to_path_buf(),
        source: e.into(),
    })?;
    if first.counts.imu == 0 {
        return Err(SmoothError::Input(format!(
            "{}: the log has no IMU samples: nothing to smooth",
            log.display()
        )));
    }
    if first.initial().is_none() && !first.has_alignment() {
        return Err(SmoothError::Input(format!(
            "{}: no initial state: the log has no truth channel and the configuration no [initial] table",
            log.display()
        )));
    }
    let Some(run) = first.finish_recording() else {
        return Err(SmoothError::Input(format!(
            "{}: the navigation filter never started",
            log.display()
        )));
    };
    let chains = run.log.chains;
    let spilled_bytes = run.log.spilled_bytes();
    let forward_wall_s = t_start.elapsed().as_secs_f64();
    let t_back = std::time::Instant::now();
    let track = run.smooth().map_err(|e| SmoothError::Backward {
        log: log.to_path_buf(),
        source: e.into(),
    })?;
    Ok(ForwardAndBack {
        track,
        truths,
        forward_solutions,
        chains,
        spilled_bytes,
        log_error,
        forward_wall_s,
        backward_wall_s: t_back.elapsed().as_secs_f64(),
    })
}

/// What one quick read of a log tells before the passes: the first and last sensor time stamps
/// (ns), and the Unix time of the log's time 0 from the first GNSS fix with a valid GNSS time
/// (GPS time less the 18 leap seconds in force since 2017).
struct LogScan {
    span_ns: Option<(u64, u64)>,
    unix_time_of_log_zero: Option<f64>,
}

fn scan_log(log: &Path) -> Result<LogScan, SmoothError> {
    const GPS_EPOCH_UNIX_S: f64 = 315_964_800.0;
    const LEAP_S: f64 = 18.0;
    let failed = |e: auvnav_log::LogError| SmoothError::Log {
        path: log.to_path_buf(),
        source: e.into(),
    };
    let mut r = auvnav_log::LogReader::open(log).map_err(failed)?;
    r.read_header().map_err(failed)?;
    let mut span: Option<(u64, u64)> = None;
    let mut unix_offset = None;
    while let Ok(Some(step)) = r.next_decoded_with(|m| {
        let Ok(m) = m else {
            return Ok::<(), SmoothError>(());
        };
        if let Some(s) = m.sensor() {
            let t = s.host_time_ns();
            span = Some(span.map_or((t, t), |(a, b)| (a.min(t), b.max(t))));
        }
        if let LogMessage::Gnss(g) = m
            && unix_offset.is_none()
            && g.validity & auvnav_shm_schema::GnssFixV1::VALID_DEVICE_TIME != 0
        {
            unix_offset = Some(
                GPS_EPOCH_UNIX_S + g.device_time_ns as f64 * 1e-9
                    - LEAP_S
                    - g.host_time_ns as f64 * 1e-9,
            );
        }
        Ok(())
    }) {
        step?;
    }
    Ok(LogScan {
        span_ns: span,
        unix_time_of_log_zero: unix_offset,
    })
}

fn fix_innovation(d: &AidDiagnosticsV1) -> Option<FixInnovation> {
    let source = match d.source {
        s if s == AidSource::GnssPosition as u32 => "gnss",
        s if s == AidSource::UsblPosition as u32 => "usbl",
        s if s == AidSource::UsblSlantRange as u32 => "usbl_range",
        _ => return None,
    };
    Some(FixInnovation {
        time_s: d.host_time_ns as f64 * 1e-9,
        source,
        innovation: d.innovation,
        test_ratio: d.test_ratio,
        fused: d.flags & AidDiagnosticsV1::FLAG_FUSED != 0,
    })
}

/// Runs `auvnav smooth`.
pub fn run(a: &SmoothOptions) -> Result<SmoothReport, SmoothError> {
    if !(a.export_rate.is_finite() && a.export_rate > 0.0) {
        return Err(SmoothError::Options(format!(
            "--export-rate {}: must be > 0 points per second",
            a.export_rate
        )));
    }
    if let Some(hz) = a.solution_rate
        && !(hz.is_finite() && hz > 0.0)
    {
        return Err(SmoothError::Options(format!(
            "--solution-rate {hz}: must be > 0 solutions per second"
        )));
    }
    std::fs::create_dir_all(&a.out).map_err(|e| SmoothError::output(&a.out, e))?;
    let fix_file = a.fixes.as_deref().map(fixes::read).transpose()?;
    let mut logs = Vec::new();
    let mut progress = auvnav_studies::progress::Progress::new(!a.json);
    for (i, log) in a.logs.iter().enumerate() {
        progress.update("smoothing logs", i, a.logs.len());
        logs.push(smooth_log(a, log, fix_file.as_ref())?);
    }
    progress.update("smoothing logs", a.logs.len(), a.logs.len());
    let r = SmoothReport {
        fix_file,
        logs,
        peak_memory_mib: peak_memory_mib(),
    };
    if let Some(dir) = &a.report {
        report::write(dir, &r).map_err(|e| SmoothError::output(dir, e))?;
    }
    Ok(r)
}
