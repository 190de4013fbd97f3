//! `auvnav montecarlo smoother`: the smoother's consistency and gain by Monte Carlo.
//!
//! Each run simulates the scenario with sensor errors drawn from the statistics the filter
//! assumes (`auvnav_studies::nees::matched_effects`), starts the navigator from the truth perturbed
//! by a draw of its initial covariance (the start fix), adds one position fix at the end of the
//! run (the truth plus a draw of `--end-fix-std`, fed with that std), and smooths the run: the
//! first pass records, the backward pass smooths, the second pass maps each solution. At every
//! truth epoch it records the forward and the smoothed position error normalised per axis by the
//! forward and the smoothed standard deviations: averaged over `N` runs, `N` times the
//! run-averaged value of a consistent estimate is chi-square with `N` degrees of freedom, whatever
//! the correlation between the axes. The smoother keeps per-epoch variances, not the full
//! covariance, so per-axis NEES is the test it can give exactly.

use crate::SmoothError;
use auvnav_core::earth;
use auvnav_core::feed::SensorMessage;
use auvnav_core::navigator::NavConfig;
use auvnav_core::session::{Session, SessionConfig, SessionOutput};
use auvnav_core::smoother::{SmoothedTrack, SmootherLog};
use auvnav_core::strapdown::truth_position;
use auvnav_log::LogMessage;
use auvnav_shm_schema::{GnssFixV1, NavSolutionV1, TruthStateV1};
use auvnav_sim::{self as sim, SimConfig, rng::Rng, scenario::Scenario};
use auvnav_studies::nees::{chi2_quantile, matched_effects};
use auvnav_studies::parallel::map_runs_with_progress;
use serde::Serialize;

#[derive(Debug, Clone)]
#[cfg_attr(feature = "clap", derive(clap::Args))]
pub struct SmootherMonteCarloOptions {
    /// Number of Monte Carlo runs.
    #[cfg_attr(feature = "clap", arg(long, default_value_t = 50))]
    pub runs: usize,
    /// Built-in scenario or scenario file (default: the 6 km survey, DVL and depth only).
    #[cfg_attr(feature = "clap", arg(long, default_value = "survey"))]
    pub scenario: String,
    /// Simulated seconds per run (default: the whole scenario).
    #[cfg_attr(feature = "clap", arg(long))]
    pub seconds: Option<f64>,
    /// First seed; run k uses seed + k.
    #[cfg_attr(feature = "clap", arg(long, default_value_t = 1))]
    pub seed: u64,
    /// DVL beam noise (m/s).
    #[cfg_attr(feature = "clap", arg(long, default_value_t = 0.01))]
    pub dvl_beam_noise: f64,
    /// One-sigma of the fix at the end of the run (m, horizontal and vertical).
    #[cfg_attr(feature = "clap", arg(long, default_value_t = 3.0))]
    pub end_fix_std: f64,
    /// Configuration TOML with a `[navigation]` table (the filter and the simulated errors both
    /// follow it).
    #[cfg_attr(feature = "clap", arg(long))]
    pub config: Option<std::path::PathBuf>,
    /// Write the run-averaged values per truth epoch to this CSV: time, forward and smoothed
    /// per-axis NEES (north, east, down), forward and smoothed squared horizontal error (m²).
    #[cfg_attr(feature = "clap", arg(long))]
    pub series: Option<std::path::PathBuf>,
    /// Worker threads (default: the available cores).
    #[cfg_attr(feature = "clap", arg(long))]
    pub threads: Option<usize>,
    #[cfg_attr(feature = "clap", arg(long))]
    pub json: bool,
}

/// The run-averaged NEES of one axis over the epochs.
#[derive(Debug, Clone, Copy, Serialize)]
pub struct AxisConsistency {
    /// Mean over epochs of the run-averaged NEES (1 when consistent).
    pub mean_anees: f64,
    /// Fraction of epochs whose run-averaged NEES is inside the 95 % bounds.
    pub fraction_inside: f64,
    pub fraction_above: f64,
    pub fraction_below: f64,
    /// 95 % interval of `mean_anees` from resampling whole runs (percentile bootstrap): it
    /// carries the correlation between the epochs of one run. Consistent when it holds 1.
    pub run_interval_95: [f64; 2],
}

impl AxisConsistency {
    /// True when the runs' interval holds 1.
    pub fn consistent(&self) -> bool {
        (self.run_interval_95[0]..=self.run_interval_95[1]).contains(&1.0)
    }
}

/// The 95 % percentile-bootstrap interval of the mean of `per_run` (2 000 resamples of whole
/// runs, a fixed random stream so that a report repeats).
fn run_interval(per_run: &[f64]) -> [f64; 2] {
    const RESAMPLES: usize = 2000;
    let n = per_run.len();
    let mut rng = Rng::new(n as u64, "montecarlo.smoother.bootstrap");
    let mut means: Vec<f64> = (0..RESAMPLES)
        .map(|_| {
            (0..n)
                .map(|_| per_run[((rng.uniform() * n as f64) as usize).min(n - 1)])
                .sum::<f64>()
                / n as f64
        })
        .collect();
    means.sort_by(f64::total_cmp);
    [
        means[(0.025 * RESAMPLES as f64) as usize],
        means[(0.975 * RESAMPLES as f64) as usize - 1],
    ]
}

/// Forward or smoothed: consistency per axis and the error.
#[derive(Debug, Clone, Serialize)]
pub struct EstimateFigures {
    pub north: AxisConsistency,
    pub east: AxisConsistency,
    pub down: AxisConsistency,
    /// Horizontal error RMS over epochs and runs (m).
    pub horizontal_error_rms_m: f64,
}

#[derive(Debug, Clone, Serialize)]
pub struct SmootherMonteCarloReport {
    pub scenario: String,
    pub runs: usize,
    pub epochs: usize,
    pub run_duration_s: f64,
    pub end_fix_std_m: f64,
    /// Two-sided 95 % bounds of the run-averaged per-axis NEES (1 degree of freedom per run).
    pub lower_bound: f64,
    pub upper_bound: f64,
    pub forward: EstimateFigures,
    pub smoothed: EstimateFigures,
    /// Smoothed over forward horizontal RMS error.
    pub rms_ratio: f64,
    /// Runs whose end fix the filter refused (it then does not reach the smoother).
    pub runs_end_fix_rejected: usize,
    pub wall_s: f64,
    /// The run-averaged rows per truth epoch (see `--series`).
    #[serde(skip)]
    pub series: Vec<[f64; 9]>,
}

/// Per truth epoch of one run: time (s), forward and smoothed normalised squared errors (N, E,
/// D) and squared horizontal errors.
type EpochRow = [f64; 9];

struct RunResult {
    rows: Vec<EpochRow>,
    duration_s: f64,
    end_fix_fused: bool,
}

/// Feeds `messages` (sensor messages in time order, the end fix among them) through a session
/// started at `start`; `on` sees every solution and every truth record in order.
fn pass(
    cfg: &NavConfig,
    messages: &[LogMessage],
    start: auvnav_core::strapdown::NavState,
    end_fix: &GnssFixV1,
    log: Option<SmootherLog>,
    on: &mut dyn FnMut(Item),
) -> Session {
    let mut session = Session::new(&SessionConfig {
        navigation: cfg.clone(),
        ..Default::default()
    });
    if let Some(log) = log {
        session.record_for_smoothing(log);
    }
    let start_ns = (start.time_s * 1e9).round() as u64;
    let Ok(()) = session.start(start, "truth perturbed by a draw of P0", &mut sink(on));
    let mut fix = Some(*end_fix);
    for m in messages {
        if let LogMessage::Truth(t) = m {
            on(Item::Truth(t));
            continue;
        }
        let Some(x) = m.sensor() else { continue };
        if matches!(x, SensorMessage::Gnss(_) | SensorMessage::Usbl(_))
            || x.host_time_ns() < start_ns
        {
            continue;
        }
        if let Some(f) = fix.take_if(|f| f.host_time_ns <= x.host_time_ns()) {
            let Ok(()) = session.feed(&SensorMessage::Gnss(f), &mut sink(on));
        }
        let Ok(()) = session.feed(&x, &mut sink(on));
    }
    if let Some(f) = fix {
        let Ok(()) = session.feed(&SensorMessage::Gnss(f), &mut sink(on));
    }
    let Ok(()) = session.finish(&mut sink(on));
    session
}

/// The session's outputs as items for `on`.
fn sink<'a>(
    on: &'a mut dyn FnMut(Item),
) -> impl FnMut(SessionOutput) -> Result<(), std::convert::Infallible> + 'a {
    move |o| {
        match o {
            SessionOutput::Solution(s) => on(Item::Solution(s)),
            SessionOutput::Diagnostics(d) => on(Item::Diagnostics(d)),
            _ => {}
        }
        Ok(())
    }
}

fn position(s: &NavSolutionV1) -> earth::Geodetic {
    earth::Geodetic {
        latitude_rad: s.latitude_rad,
        longitude_rad: s.longitude_rad,
        height_m: s.height_m,
    }
}

enum Item<'a> {
    Solution(&'a NavSolutionV1),
    Diagnostics(&'a auvnav_shm_schema::AidDiagnosticsV1),
    Truth(&'a TruthStateV1),
}

fn one_run(
    a: &SmootherMonteCarloOptions,
    scenario: &Scenario,
    cfg: &NavConfig,
    k: usize,
) -> Result<RunResult, SmoothError> {
    let failed = |e: Box<dyn std::error::Error + Send + Sync>| SmoothError::Run {
        index: k,
        source: e,
    };
    let seed = a.seed.wrapping_add(k as u64);
    let mut rng = Rng::new(seed, "montecarlo.smoother");
    let effects = matched_effects(cfg, a.dvl_beam_noise, &mut rng).map_err(|e| failed(e.into()))?;
    let (messages, summary) = sim::simulate_to_vec(&SimConfig {
        scenario: scenario.clone(),
        effects,
        seed,
        duration_s: a.seconds,
    })?;
    let truths: Vec<&TruthStateV1> = messages
        .iter()
        .filter_map(|m| match m {
            LogMessage::Truth(t) => Some(t),
            _ => None,
        })
        .collect();
    let (Some(first), Some(last)) = (truths.first(), truths.last()) else {
        return Err(failed("the simulation has no truth records".into()));
    };
    let start = auvnav_studies::perturbed_start::perturbed_start(cfg, first, &mut rng);
    let end = truth_position(last);
    let std = a.end_fix_std;
    let (dn, de, dd) = (rng.gauss(std), rng.gauss(std), rng.gauss(std));
    let moved = earth::offset_position(&end, &nalgebra::Vector3::new(dn, de, dd));
    let end_fix = GnssFixV1 {
        host_time_ns: last.host_time_ns,
        latitude_rad: moved.latitude_rad,
        longitude_rad: moved.longitude_rad,
        height_m: moved.height_m,
        horizontal_std_m: std,
        vertical_std_m: std,
        validity: GnssFixV1::VALID_POSITION | GnssFixV1::VALID_HEIGHT,
        ..Default::default()
    };

    let mut end_fix_fused = false;
    let mut first_pass = pass(
        cfg,
        &messages,
        start,
        &end_fix,
        Some(SmootherLog::in_memory()),
        &mut |i| {
            if let Item::Diagnostics(d) = i
                && d.host_time_ns == end_fix.host_time_ns
                && d.flags & auvnav_shm_schema::AidDiagnosticsV1::FLAG_FUSED != 0
            {
                end_fix_fused = true;
            }
        },
    );
    let mut track: SmoothedTrack = first_pass
        .finish_recording()
        .ok_or_else(|| failed("the session recorded nothing".into()))?
        .smooth()
        .map_err(|e| failed(e.into()))?;
    let mut rows = Vec::new();
    let mut last: Option<(NavSolutionV1, NavSolutionV1)> = None;
    pass(cfg, &messages, start, &end_fix, None, &mut |i| match i {
        Item::Solution(s) => last = Some((*s, track.apply(s))),
        Item::Truth(t) => {
            let Some((f, s)) = last.filter(|(f, _)| f.host_time_ns == t.host_time_ns) else {
                return;
            };
            let truth = truth_position(t);
            let mut row = [0.0; 9];
            row[0] = t.host_time_ns as f64 * 1e-9;
            for (j, sol) in [f, s].iter().enumerate() {
                let e = earth::ned_offset(&truth, &position(sol));
                for axis in 0..3 {
                    row[1 + 3 * j + axis] = (e[axis] / sol.position_std_ned_m[axis]).powi(2);
                }
                row[7 + j] = e.x * e.x + e.y * e.y;
            }
            rows.push(row);
        }
        Item::Diagnostics(_) => {}
    });
    Ok(RunResult {
        rows,
        duration_s: summary.duration_s,
        end_fix_fused,
    })
}

/// Runs the Monte Carlo.
pub fn smoother_monte_carlo(
    a: &SmootherMonteCarloOptions,
    cfg: &NavConfig,
) -> Result<SmootherMonteCarloReport, SmoothError> {
    if a.runs == 0 {
        return Err(SmoothError::Options("--runs must be at least 1".into()));
    }
    if !(a.end_fix_std.is_finite() && a.end_fix_std > 0.0) {
        return Err(SmoothError::Options("--end-fix-std must be > 0 m".into()));
    }
    let started = std::time::Instant::now();
    let scenario = Scenario::load(&a.scenario).map_err(auvnav_sim::SimError::from)?;
    let threads = a
        .threads
        .unwrap_or_else(auvnav_studies::parallel::default_threads)
        .max(1);
    let mut progress = auvnav_studies::progress::Progress::new(!a.json);
    let bar = progress.runs("smoothed runs", a.runs);
    let results = map_runs_with_progress(a.runs, threads, &bar, |k| one_run(a, &scenario, cfg, k))?;
    bar.finish_and_clear();
    let epochs = results.iter().map(|r| r.rows.len()).min().unwrap_or(0);
    if epochs == 0 {
        return Err(SmoothError::Input("no truth epoch to evaluate".into()));
    }
    let n = a.runs as f64;
    let lower = chi2_quantile(n, -1.959_964) / n;
    let upper = chi2_quantile(n, 1.959_964) / n;
    // Run-averaged values per epoch (the runs share the scenario's truth epochs).
    let averaged: Vec<EpochRow> = (0..epochs)
        .map(|i| {
            let mut s = [0.0; 9];
            for r in &results {
                for (acc, v) in s.iter_mut().zip(r.rows[i]) {
                    *acc += v;
                }
            }
            s.map(|v| v / n)
        })
        .collect();
    let axis = |c: usize| {
        let m = averaged.len() as f64;
        let per_run: Vec<f64> = results
            .iter()
            .map(|r| r.rows[..epochs].iter().map(|row| row[c]).sum::<f64>() / m)
            .collect();
        let above = averaged.iter().filter(|r| r[c] > upper).count() as f64 / m;
        let below = averaged.iter().filter(|r| r[c] < lower).count() as f64 / m;
        AxisConsistency {
            mean_anees: averaged.iter().map(|r| r[c]).sum::<f64>() / m,
            fraction_inside: 1.0 - above - below,
            fraction_above: above,
            fraction_below: below,
            run_interval_95: run_interval(&per_run),
        }
    };
    let rms =
        |c: usize| (averaged.iter().map(|r| r[c]).sum::<f64>() / averaged.len() as f64).sqrt();
    let figures = |j: usize| EstimateFigures {
        north: axis(1 + 3 * j),
        east: axis(2 + 3 * j),
        down: axis(3 + 3 * j),
        horizontal_error_rms_m: rms(7 + j),
    };
    let (forward, smoothed) = (figures(0), figures(1));
    Ok(SmootherMonteCarloReport {
        scenario: scenario.name.clone(),
        runs: a.runs,
        epochs,
        run_duration_s: results.iter().map(|r| r.duration_s).fold(0.0, f64::max),
        end_fix_std_m: a.end_fix_std,
        lower_bound: lower,
        upper_bound: upper,
        rms_ratio: smoothed.horizontal_error_rms_m / forward.horizontal_error_rms_m,
        forward,
        smoothed,
        runs_end_fix_rejected: results.iter().filter(|r| !r.end_fix_fused).count(),
        wall_s: started.elapsed().as_secs_f64(),
        series: averaged,
    })
}
