//! `auvnav calibrate dvl`: arguments, the run (baseline, method, re-score, hold-out) and its
//! outputs.

use super::fast;
use super::objective::Record;
use super::params::{NAMES, ParameterSet, installation, installation_vector};
use super::report::{self, CalibrationReport};
use super::seed::SeedSettings;
use super::two_point;
use super::voyage::{DistanceSource, FixSource, Voyage, VoyageSpec};
use super::{Evaluation, MethodResult, Problem};
use anyhow::{Context, bail};
use auvnav_core::session::SessionConfig;
use std::path::PathBuf;
use std::time::Instant;

/// The calibration methods.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize)]
#[cfg_attr(feature = "clap", derive(clap::ValueEnum))]
#[serde(rename_all = "kebab-case")]
pub enum Method {
    /// Gauss–Newton with replay sensitivities, priors and an observability test (ours).
    Fast,
    /// Latin hypercube → quadratic response surface → particle swarm (the S-CAL seed).
    Seed,
    /// The seed's two-point formulas on the start and end fixes (yaw and scale only).
    TwoPoint,
    /// The filter's installation states, smoothed over each voyage with its fixes as aids and
    /// fused across the voyages (one shared installation).
    Smoother,
}

/// Hold-out evaluation.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize)]
#[cfg_attr(feature = "clap", derive(clap::ValueEnum))]
#[serde(rename_all = "kebab-case")]
pub enum Holdout {
    /// Leave-one-voyage-out when there are at least 3 voyages, else none.
    Auto,
    /// Leave each voyage out in turn: fit on the others, score the one left out.
    Loo,
    None,
}

#[derive(Debug, Clone)]
#[cfg_attr(feature = "clap", derive(clap::Args))]
pub struct CalibrateDvlArgs {
    /// Voyages: logs, or time windows of one as LOG@START..END (seconds from its first message).
    #[cfg_attr(feature = "clap", arg(required = true))]
    pub voyages: Vec<VoyageSpec>,
    /// Where the fixes come from: the GNSS channel, or the truth / reference channel.
    #[cfg_attr(feature = "clap", arg(long, default_value = "gnss"))]
    pub fixes: FixSource,
    #[cfg_attr(feature = "clap", arg(long, value_enum, default_value_t = Method::Fast))]
    pub method: Method,
    /// Only fixes at least this far along the track score (m; S-CAL: 5 km).
    #[cfg_attr(feature = "clap", arg(long, default_value_t = 5000.0))]
    pub threshold: f64,
    /// Navigation configuration (the daemon's or replay's file: [navigation], [initial]); its
    /// DVL installation is the starting point and the default prior.
    #[cfg_attr(feature = "clap", arg(long))]
    pub config: Option<PathBuf>,
    /// Parameters to estimate, comma-separated (dvl.mount_roll, dvl.mount_pitch, dvl.mount_yaw,
    /// dvl.scale_factor, dvl.lever_arm[.x|.y|.z], dvl.time_offset, dvl.mounting); default: the
    /// seed's four.
    #[cfg_attr(feature = "clap", arg(long, value_delimiter = ','))]
    pub params: Vec<String>,
    /// Bounds of a parameter: NAME=MIN,MAX (repeatable).
    #[cfg_attr(feature = "clap", arg(long = "bound", value_name = "NAME=MIN,MAX", value_parser = auvnav_studies::args::name_and_two_numbers))]
    pub bounds: Vec<String>,
    /// Prior of a parameter: NAME=MEAN,STD (repeatable).
    #[cfg_attr(feature = "clap", arg(long = "prior", value_name = "NAME=MEAN,STD", value_parser = auvnav_studies::args::name_and_two_numbers))]
    pub priors: Vec<String>,
    /// TOML file with one table per parameter: estimate, min, max, prior, prior_std.
    #[cfg_attr(feature = "clap", arg(long))]
    pub limits: Option<PathBuf>,
    /// Seed of the seed method's Latin hypercube and swarm.
    #[cfg_attr(feature = "clap", arg(long, default_value_t = 1))]
    pub seed: u64,
    /// Latin-hypercube samples (seed method).
    #[cfg_attr(feature = "clap", arg(long, default_value_t = 100))]
    pub lhs_samples: usize,
    /// Swarm size (seed method).
    #[cfg_attr(feature = "clap", arg(long, default_value_t = 20))]
    pub particles: usize,
    /// Swarm iterations at most (seed method).
    #[cfg_attr(feature = "clap", arg(long, default_value_t = 20))]
    pub iterations: usize,
    #[cfg_attr(feature = "clap", arg(long, value_enum, default_value_t = Holdout::Auto))]
    pub holdout: Holdout,
    /// Worker threads (default: the available cores).
    #[cfg_attr(feature = "clap", arg(long))]
    pub threads: Option<usize>,
    /// Print the result as JSON.
    #[cfg_attr(feature = "clap", arg(long))]
    pub json: bool,
    /// Write the calibrated [navigation.dvl] table to this file (atomically).
    #[cfg_attr(feature = "clap", arg(long))]
    pub write_config: Option<PathBuf>,
    /// Write a report (Markdown, SVG plots, JSON) into this directory.
    #[cfg_attr(feature = "clap", arg(long))]
    pub report: Option<PathBuf>,
}

impl CalibrateDvlArgs {
    /// The command's defaults for `voyages` (what the command line gives without options).
    pub fn new(voyages: Vec<VoyageSpec>) -> CalibrateDvlArgs {
        CalibrateDvlArgs {
            voyages,
            fixes: FixSource::Gnss,
            method: Method::Fast,
            threshold: 5000.0,
            config: None,
            params: Vec::new(),
            bounds: Vec::new(),
            priors: Vec::new(),
            limits: None,
            seed: 1,
            lhs_samples: 100,
            particles: 20,
            iterations: 20,
            holdout: Holdout::Auto,
            threads: None,
            json: true,
            write_config: None,
            report: None,
        }
    }
}

pub use auvnav_studies::progress::Progress;

/// The navigation configuration: `--config`, or, for a recording, the daemon's configuration
/// embedded in its header (as `auvnav replay` takes it), or the defaults.
fn load_session_config(
    path: Option<&PathBuf>,
    first_voyage: Option<&std::path::Path>,
) -> anyhow::Result<SessionConfig> {
    if let Some(p) = path {
        return auvnav_replay::load_config(p);
    }
    if let Some(log) = first_voyage {
        let header = auvnav_log::LogReader::open(log)?
            .read_header()
            .with_context(|| format!("reading {}", log.display()))?;
        if header.producer == "auvnav record" && !header.config.trim().is_empty() {
            return auvnav_replay::session_config_from_toml(&header.config)
                .with_context(|| format!("{}", log.display()));
        }
    }
    Ok(SessionConfig::default())
}

fn parameter_set(args: &CalibrateDvlArgs, cfg: &SessionConfig) -> anyhow::Result<ParameterSet> {
    let mut params = ParameterSet::new(&cfg.navigation.dvl_installation());
    if let Some(path) = &args.limits {
        let text = std::fs::read_to_string(path)
            .with_context(|| format!("reading --limits {}", path.display()))?;
        params.apply_limits(&text, &path.display().to_string())?;
    }
    if !args.params.is_empty() {
        params.select(&args.params)?;
    }
    for b in &args.bounds {
        params.set_bound(b)?;
    }
    for p in &args.priors {
        params.set_prior(p)?;
    }
    params.validate()?;
    Ok(params)
}

/// Runs `method` on `problem` from its baseline evaluation.
fn run_method(
    method: Method,
    problem: &Problem,
    params: &ParameterSet,
    settings: &SeedSettings,
    baseline: &Evaluation,
    progress: &mut Progress,
) -> anyhow::Result<(MethodResult, Vec<two_point::TwoPointVoyage>)> {
    let mut p = |l: &str, d: usize, t: usize| progress.update(l, d, t);
    match method {
        Method::Fast => Ok((fast::calibrate(problem, params, &mut p)?, Vec::new())),
        Method::Seed => Ok((
            super::seed::calibrate(problem, params, settings, &mut p)?,
            Vec::new(),
        )),
        Method::TwoPoint => two_point::calibrate(problem, params, baseline),
        Method::Smoother => Ok((
            super::smoother::calibrate(problem, params, &mut p)?,
            Vec::new(),
        )),
    }
}

/// Loads the voyages and checks that each can be scored.
pub fn load_voyages(
    specs: &[VoyageSpec],
    fixes: FixSource,
    cfg: &SessionConfig,
) -> anyhow::Result<Vec<Voyage>> {
    specs.iter().map(|s| Voyage::load(s, fixes, cfg)).collect()
}

/// The whole calibration: returns the report (also what `--json` prints).
pub fn calibrate_dvl(args: &CalibrateDvlArgs) -> anyhow::Result<CalibrationReport> {
    let started = Instant::now();
    if !(args.threshold.is_finite() && args.threshold >= 0.0) {
        bail!(
            "--threshold {}: expected a distance in metres >= 0",
            args.threshold
        );
    }
    let first_voyage = args.voyages.first().map(|v| v.path.as_path());
    let cfg = load_session_config(args.config.as_ref(), first_voyage)?;
    let params = parameter_set(args, &cfg)?;
    let threads = args
        .threads
        .unwrap_or_else(auvnav_studies::parallel::default_threads)
        .max(1);
    let mut voyages = load_voyages(&args.voyages, args.fixes, &cfg)?;
    let mut progress = Progress::new(!args.json);
    let prior = params.prior_vector();
    let record_all = Record {
        track: true,
        epochs: true,
    };

    // Baseline with the starting installation; distances for voyages without truth come from
    // its track (the errors at the fixes do not depend on them, so the runs are only re-scored).
    let runs = {
        let problem = Problem::new(&voyages, cfg.navigation.clone(), args.threshold, threads);
        problem.evaluate(&prior, record_all)?.runs
    };
    for (v, r) in voyages.iter_mut().zip(&runs) {
        if v.distance_source == DistanceSource::StartingDeadReckoning {
            v.set_distances_from_track(&r.track);
        }
    }
    for v in &voyages {
        if !v.fixes.iter().any(|f| f.distance_m >= args.threshold) {
            bail!(
                "voyage {}: no fix at or beyond the distance threshold {} m (its last fix is {:.0} m along the track); lower --threshold",
                v.name,
                args.threshold,
                v.distance_m()
            );
        }
    }
    let problem = Problem::new(&voyages, cfg.navigation.clone(), args.threshold, threads);
    let baseline = problem.score(runs);
    let settings = SeedSettings {
        lhs_samples: args.lhs_samples,
        particles: args.particles,
        iterations: args.iterations,
        seed: args.seed,
        ..Default::default()
    };
    let fit_started = Instant::now();
    let replays_before_fit = problem.full_replays();
    let (mut result, two_point_voyages) = run_method(
        args.method,
        &problem,
        &params,
        &settings,
        &baseline,
        &mut progress,
    )?;
    let after = problem.evaluate(&result.x, record_all)?;
    let fit_wall_s = fit_started.elapsed().as_secs_f64();
    // The smoother's standard deviations are its own; the others get the fast method's analysis.
    if !matches!(args.method, Method::Fast | Method::Smoother) {
        let a = fast::analyse(&problem, &params, &after.runs, &result.x)?;
        result.std = a.std;
        result.determined = a.determined;
        result.inseparable = a.inseparable;
    }
    let replays_for_fit = problem.full_replays() - replays_before_fit;

    // The two-point method on the same voyages, for comparison.
    let two_point_cmp = if args.method != Method::TwoPoint {
        let (tp, _) = two_point::calibrate(&problem, &params, &baseline)?;
        let e = problem.objectives(&[tp.x])?;
        Some((tp.x, e[0]))
    } else {
        None
    };

    // Hold-out: leave one voyage out.
    let loo = match args.holdout {
        Holdout::Loo => true,
        Holdout::None => false,
        Holdout::Auto => voyages.len() >= 3,
    };
    if loo && voyages.len() < 2 {
        bail!("--holdout loo needs at least 2 voyages");
    }
    let mut holdout = Vec::new();
    if loo {
        for k in 0..voyages.len() {
            progress.update("hold-out (leave one out)", k, voyages.len());
            let train: Vec<Voyage> = voyages
                .iter()
                .enumerate()
                .filter(|(i, _)| *i != k)
                .map(|(_, v)| v.clone())
                .collect();
            let sub = Problem::new(&train, cfg.navigation.clone(), args.threshold, threads);
            let sub_baseline = Evaluation {
                runs: baseline
                    .runs
                    .iter()
                    .enumerate()
                    .filter(|(i, _)| *i != k)
                    .map(|(_, r)| r.clone())
                    .collect(),
                cep50: Vec::new(),
                objective: f64::NAN,
            };
            let mut quiet = Progress::new(false);
            let (fit, _) = run_method(
                args.method,
                &sub,
                &params,
                &settings,
                &sub_baseline,
                &mut quiet,
            )?;
            let (tp, _) = two_point::calibrate(&sub, &params, &sub_baseline)?;
            let held = std::slice::from_ref(&voyages[k]);
            let test = Problem::new(held, cfg.navigation.clone(), args.threshold, threads);
            let scores = test.objectives(&[fit.x, tp.x])?;
            holdout.push(report::HoldoutRow {
                voyage: voyages[k].name.clone(),
                before: baseline.cep50[k],
                after: scores[0],
                two_point_after: scores[1],
                parameters: report::values(&params, &fit.x),
            });
        }
        progress.update("hold-out (leave one out)", voyages.len(), voyages.len());
    }

    let report = report::build(report::Inputs {
        args,
        params: &params,
        voyages: &voyages,
        baseline: &baseline,
        after: &after,
        result: &result,
        two_point_voyages,
        two_point_cmp,
        holdout,
        full_replays_fit: replays_for_fit,
        fit_wall_s,
        wall_s: started.elapsed().as_secs_f64(),
        threads,
    });
    if let Some(path) = &args.write_config {
        report::write_config(path, &report)?;
    }
    if let Some(dir) = &args.report {
        report::write_report_dir(dir, &report, &voyages, &baseline, &after, &result)?;
    }
    Ok(report)
}

/// The installation a report recommends, as eight numbers.
pub fn recommended(report: &CalibrationReport) -> [f64; 8] {
    let mut x = [0.0; 8];
    for p in &report.parameters {
        if let Some(i) = NAMES.iter().position(|n| *n == p.name) {
            x[i] = p.value;
        }
    }
    x
}

/// Round trip used by the tests: the TOML the tool writes is the installation it reports.
pub fn installation_of(report: &CalibrationReport) -> auvnav_core::config::DvlInstallation {
    let x = recommended(report);
    let mut d = installation(&x);
    d.source = report.source_note();
    debug_assert_eq!(installation_vector(&d), x);
    d
}
