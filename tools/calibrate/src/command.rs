//! `auvnav calibrate dvl`: arguments, the run (baseline, method, re-score, hold-out) and its
//! outputs.

use super::gauss_newton;
use super::objective::Record;
use super::options::{CalibrateDvlOptions, Holdout, Method};
use super::params::ParameterSet;
use super::report::{self, CalibrationReport};
use super::scal::SeedSettings;
use super::two_point;
use super::voyage::{DistanceSource, FixSource, Voyage, VoyageSpec};
use super::{Evaluation, MethodResult, Problem};
use crate::CalibrationError;
use crate::error::{unusable, usage};
use auvnav_core::session::SessionConfig;
use std::path::PathBuf;
use std::time::Instant;

pub use auvnav_studies::progress::Progress;

/// The navigation configuration: `--config`, or, for a recording, the daemon's configuration
/// embedded in its header (as `auvnav replay` takes it), or the defaults.
fn load_session_config(
    path: Option<&PathBuf>,
    first_voyage: Option<&std::path::Path>,
) -> Result<SessionConfig, CalibrationError> {
    if let Some(p) = path {
        return Ok(auvnav_replay::load_config(p)?);
    }
    if let Some(log) = first_voyage {
        let failed = |e: auvnav_log::LogError| CalibrationError::Read {
            path: log.to_path_buf(),
            source: e.into(),
        };
        let header = auvnav_log::LogReader::open(log)
            .map_err(failed)?
            .read_header()
            .map_err(failed)?;
        if header.producer == "auvnav record" && !header.config.trim().is_empty() {
            return auvnav_replay::session_config_from_toml(&header.config).map_err(|e| {
                auvnav_replay::ReplayError::EmbeddedConfig {
                    log: log.to_path_buf(),
                    source: e.into(),
                }
                .into()
            });
        }
    }
    Ok(SessionConfig::default())
}

fn parameter_set(
    args: &CalibrateDvlOptions,
    cfg: &SessionConfig,
) -> Result<ParameterSet, CalibrationError> {
    let mut params = ParameterSet::new(&cfg.navigation.dvl_installation());
    if let Some(path) = &args.limits {
        let text = match std::fs::read_to_string(path) {
            Ok(t) => t,
            Err(e) => usage!("reading --limits {}: {e}", path.display()),
        };
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
) -> Result<(MethodResult, Vec<two_point::TwoPointVoyage>), CalibrationError> {
    let mut p = |l: &str, d: usize, t: usize| progress.update(l, d, t);
    let (result, voyages) = match method {
        Method::Fast => gauss_newton::calibrate(problem, params, &mut p).map(|r| (r, Vec::new())),
        Method::Seed => {
            super::scal::calibrate(problem, params, settings, &mut p).map(|r| (r, Vec::new()))
        }
        Method::TwoPoint => two_point::calibrate(problem, params, baseline),
        Method::Smoother => {
            super::smoother::calibrate(problem, params, &mut p).map(|r| (r, Vec::new()))
        }
    }
    .map_err(CalibrationError::method)?;
    Ok((result, voyages))
}

/// Loads the voyages and checks that each can be scored.
pub fn load_voyages(
    specs: &[VoyageSpec],
    fixes: FixSource,
    cfg: &SessionConfig,
) -> Result<Vec<Voyage>, CalibrationError> {
    specs.iter().map(|s| Voyage::load(s, fixes, cfg)).collect()
}

/// The calibration of surface runs ([`crate::surface`]) when every voyage is one (a compass and
/// GNSS, no IMU); `None` when none is (the replay-based calibration applies); an error when the
/// voyages are of both kinds. Writes `--write-config` itself.
pub fn calibrate_dvl_surface(
    args: &CalibrateDvlOptions,
) -> Result<Option<crate::surface::SurfaceReport>, CalibrationError> {
    let channels = args
        .voyages
        .iter()
        .map(|v| auvnav_replay::surface::channels(&v.path, args.compass))
        .collect::<Result<Vec<(bool, bool)>, _>>()?;
    if args.compass
        && let Some((v, _)) = args.voyages.iter().zip(&channels).find(|(_, c)| !c.1)
    {
        usage!(
            "--compass: {} has no attitude channel (a compass or an AHRS) to dead-reckon with",
            v.name()
        );
    }
    let kinds: Vec<bool> = channels
        .iter()
        .map(|(imu, attitude)| *attitude && (!imu || args.compass))
        .collect();
    if !kinds.iter().any(|k| *k) {
        return Ok(None);
    }
    if !kinds.iter().all(|k| *k) {
        usage!(
            "the voyages mix surface runs (compass and GNSS, no IMU) with runs that have an IMU: calibrate them separately"
        );
    }
    if !(args.threshold.is_finite() && args.threshold > 0.0) {
        usage!(
            "--threshold {}: expected a distance in metres > 0",
            args.threshold
        );
    }
    let first_voyage = args.voyages.first().map(|v| v.path.as_path());
    let cfg = load_session_config(args.config.as_ref(), first_voyage)?;
    let start = crate::surface::Candidate {
        dvl: cfg.navigation.dvl_installation(),
        compass_deviation_deg: cfg.navigation.compass_deviation_deg,
    };
    let mut report = crate::surface::calibrate_surface(
        &args.voyages,
        &start,
        &args.params,
        args.threshold,
        args.moving_bed,
    )?;
    let yaw = report
        .params
        .iter()
        .find(|p| p.name == "dvl.mount_yaw" && p.std.is_finite())
        .map(|p| (p.estimate, p.std, "fitted"));
    (report.compass, report.notes) =
        crate::surface::compass::declinations(args.voyages.iter().map(|v| v.path.as_path()), yaw);
    if let Some(path) = &args.write_config {
        crate::surface::write_config(path, &report)
            .map_err(|e| CalibrationError::output(path, e))?;
    }
    Ok(Some(report))
}

/// The whole calibration: returns the report (also what `--json` prints).
// Long on purpose: the calibration as the recipe the report documents (options checked, voyages
// read, method, held-out evaluation, report); each step is a function.
pub fn calibrate_dvl(args: &CalibrateDvlOptions) -> Result<CalibrationReport, CalibrationError> {
    let started = Instant::now();
    if !(args.threshold.is_finite() && args.threshold >= 0.0) {
        usage!(
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
        problem
            .evaluate(&prior, record_all)
            .map_err(CalibrationError::navigation)?
            .runs
    };
    for (v, r) in voyages.iter_mut().zip(&runs) {
        if v.distance_source == DistanceSource::StartingDeadReckoning {
            v.set_distances_from_track(&r.track);
        }
    }
    for v in &voyages {
        if !v.fixes.iter().any(|f| f.distance_m >= args.threshold) {
            unusable!(
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
    let after = problem
        .evaluate(&result.x, record_all)
        .map_err(CalibrationError::navigation)?;
    let fit_wall_s = fit_started.elapsed().as_secs_f64();
    // The smoother's standard deviations are its own; the others get the fast method's analysis.
    if !matches!(args.method, Method::Fast | Method::Smoother) {
        let a = gauss_newton::analyse(&problem, &params, &after.runs, &result.x)
            .map_err(CalibrationError::method)?;
        result.std = a.std;
        result.determined = a.determined;
        result.inseparable = a.inseparable;
    }
    let replays_for_fit = problem.full_replays() - replays_before_fit;

    // The two-point method on the same voyages, for comparison.
    let two_point_cmp = if args.method != Method::TwoPoint {
        let (tp, _) =
            two_point::calibrate(&problem, &params, &baseline).map_err(CalibrationError::method)?;
        let e = problem
            .objectives(&[tp.x])
            .map_err(CalibrationError::navigation)?;
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
        usage!("--holdout loo needs at least 2 voyages");
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
            let (tp, _) = two_point::calibrate(&sub, &params, &sub_baseline)
                .map_err(CalibrationError::method)?;
            let held = std::slice::from_ref(&voyages[k]);
            let test = Problem::new(held, cfg.navigation.clone(), args.threshold, threads);
            let scores = test
                .objectives(&[fit.x, tp.x])
                .map_err(CalibrationError::navigation)?;
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
        report::write_config(path, &report).map_err(|e| CalibrationError::output(path, e))?;
    }
    if let Some(dir) = &args.report {
        report::write_report_dir(dir, &report, &voyages, &baseline, &after, &result)
            .map_err(|e| CalibrationError::output(dir, e))?;
    }
    Ok(report)
}
