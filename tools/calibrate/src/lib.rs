//! S-CAL: offline DVL calibration from recorded voyages, by the navigation core the daemon runs.
//!
//! A [`Problem`] is a set of voyages ([`voyage::Voyage`], in memory), the navigation
//! configuration and the distance threshold; its objective is the S-CAL mean CEP50 of
//! error/distance over the fixes beyond the threshold, each voyage dead-reckoned by a full replay
//! through the navigation session ([`objective::run_voyage`]). Four methods search the
//! installation ([`params::ParameterSet`]): [`two_point`] (the seed's formulas), [`scal`] (the published S-CAL method: Latin
//! hypercube → response surface → particle swarm), [`gauss_newton`] (Gauss–Newton with replay
//! sensitivities, the default) and [`smoother`] (the installation states of the filter, smoothed
//! over each voyage and fused across them). [`command`] is `auvnav calibrate dvl` as a function
//! (options in, a typed report out); [`report`] writes JSON, the `[navigation.dvl]` table and the
//! report directory. [`mag`] calibrates a magnetometer. With the `clap` feature, the option
//! structs are also the command line's; the library never prints.
#![forbid(unsafe_code)]

pub mod command;
mod error;
pub mod gauss_newton;
pub mod mag;
pub mod objective;
pub mod options;
pub mod params;
pub mod report;
pub mod scal;
pub mod smoother;
pub mod surface;
pub mod two_point;
pub mod voyage;

pub use command::*;
pub use error::{CalibrationError, Source};
pub use options::*;
pub use report::{installation_of, recommended};

use auvnav_core::config::NavConfig;
use auvnav_studies::parallel::map_runs;
use objective::{Record, VoyageRun, run_voyage};
use std::sync::atomic::{AtomicUsize, Ordering};
use voyage::Voyage;

/// Voyages, configuration and threshold: what a calibration scores candidates on.
pub struct Problem<'a> {
    pub voyages: &'a [Voyage],
    pub nav: NavConfig,
    pub threshold_m: f64,
    pub threads: usize,
    replays: AtomicUsize,
}

/// One candidate scored by full replay of every voyage.
#[derive(Debug, Clone)]
pub struct Evaluation {
    pub runs: Vec<VoyageRun>,
    /// CEP50 of error/distance per voyage.
    pub cep50: Vec<f64>,
    /// Their mean: the S-CAL objective.
    pub objective: f64,
}

impl<'a> Problem<'a> {
    pub fn new(voyages: &'a [Voyage], nav: NavConfig, threshold_m: f64, threads: usize) -> Self {
        Problem {
            voyages,
            nav,
            threshold_m,
            threads,
            replays: AtomicUsize::new(0),
        }
    }

    /// Full replays (candidate × all voyages) done so far.
    pub fn full_replays(&self) -> usize {
        self.replays.load(Ordering::Relaxed)
    }

    /// Scores runs of every voyage (in voyage order) made with one candidate.
    pub fn score(&self, runs: Vec<VoyageRun>) -> Evaluation {
        let cep50: Vec<f64> = self
            .voyages
            .iter()
            .zip(&runs)
            .map(|(v, r)| r.cep50(&v.fixes, self.threshold_m))
            .collect();
        let objective = cep50.iter().sum::<f64>() / cep50.len().max(1) as f64;
        Evaluation {
            runs,
            cep50,
            objective,
        }
    }

    /// Scores `x` (voyages in parallel).
    pub fn evaluate(&self, x: &[f64; 8], record: Record) -> anyhow::Result<Evaluation> {
        let runs = map_runs(self.voyages.len(), self.threads, |k| -> anyhow::Result<_> {
            run_voyage(&self.voyages[k], &self.nav, x, record)
        })?;
        self.replays.fetch_add(1, Ordering::Relaxed);
        Ok(self.score(runs))
    }

    /// The objectives of many candidates (every candidate × voyage pair in parallel).
    pub fn objectives(&self, xs: &[[f64; 8]]) -> anyhow::Result<Vec<f64>> {
        let nv = self.voyages.len();
        let cep = map_runs(xs.len() * nv, self.threads, |k| -> anyhow::Result<_> {
            let (c, v) = (k / nv, k % nv);
            let run = run_voyage(&self.voyages[v], &self.nav, &xs[c], Record::default())?;
            Ok(run.cep50(&self.voyages[v].fixes, self.threshold_m))
        })?;
        self.replays.fetch_add(xs.len(), Ordering::Relaxed);
        Ok(cep
            .chunks(nv)
            .map(|c| c.iter().sum::<f64>() / nv as f64)
            .collect())
    }
}

/// What a method found.
#[derive(Debug, Clone)]
pub struct MethodResult {
    /// The eight installation parameters (estimated ones set, others at their prior).
    pub x: [f64; 8],
    /// Standard deviation per estimated parameter index (fast only).
    pub std: Vec<(usize, f64)>,
    /// Whether the voyages determine each estimated parameter (fast only).
    pub determined: Vec<(usize, bool)>,
    /// Pairs of parameters the voyages cannot separate, with their correlation.
    pub inseparable: Vec<(String, String, f64)>,
    /// (full replays so far, best objective so far) after each evaluation.
    pub history: Vec<(usize, f64)>,
    /// Evaluations of the replay surrogate (sensitivity sets), not full replays.
    pub surrogate_evaluations: usize,
    /// The response-surface optimum and its full-replay objective (seed only).
    pub surface_optimum: Option<([f64; 8], f64)>,
    pub notes: Vec<String>,
}

impl MethodResult {
    pub fn new(x: [f64; 8]) -> MethodResult {
        MethodResult {
            x,
            std: Vec::new(),
            determined: Vec::new(),
            inseparable: Vec::new(),
            history: Vec::new(),
            surrogate_evaluations: 0,
            surface_optimum: None,
            notes: Vec::new(),
        }
    }
}
