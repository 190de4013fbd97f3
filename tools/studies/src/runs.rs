//! A Monte Carlo study as independent runs: the plan (options checked, scenario loaded), one run
//! by its index, and the report from the runs in index order. The single-machine runner
//! ([`run_local`]) and a distributed engine (the Python package's `auvnav.fleet`, each run a task)
//! call the same three steps, so a run's result depends only on the options and its index,
//! wherever it ran.
//!
//! A run's result travels between processes as bytes ([`encode_run`], [`decode_run`]: postcard,
//! exact for every `f64`, NaN included, which JSON is not).

use crate::StudyError;
use serde::Serialize;
use serde::de::DeserializeOwned;

/// A study of `runs()` independent runs.
pub trait RunStudy: Sync {
    /// One run's result.
    type Run: Serialize + DeserializeOwned + Send;
    /// The study's report.
    type Report: Serialize;
    /// How many runs the options ask for.
    fn runs(&self) -> usize;
    /// Run `k` (0-based; its seed is the first seed plus `k`).
    fn run(&self, k: usize) -> Result<Self::Run, StudyError>;
    /// The report from every run's result, in index order, and the wall time the runs took.
    fn report(&self, runs: Vec<Self::Run>, wall_s: f64) -> Result<Self::Report, StudyError>;
}

/// Runs every run of `study` on `threads` workers of this machine, advancing `bar`.
pub fn run_local<S: RunStudy>(
    study: &S,
    threads: usize,
    bar: &indicatif::ProgressBar,
) -> Result<S::Report, StudyError> {
    let start = std::time::Instant::now();
    let runs =
        crate::parallel::map_runs_with_progress(study.runs(), threads, bar, |k| study.run(k))?;
    study.report(runs, start.elapsed().as_secs_f64())
}

/// A run's result as bytes.
pub fn encode_run<T: Serialize>(run: &T) -> Result<Vec<u8>, StudyError> {
    postcard::to_allocvec(run).map_err(StudyError::RunBytes)
}

/// A run's result from [`encode_run`]'s bytes.
pub fn decode_run<T: DeserializeOwned>(bytes: &[u8]) -> Result<T, StudyError> {
    postcard::from_bytes(bytes).map_err(StudyError::RunBytes)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn run_results_travel_as_bytes_exactly_nan_included() {
        let v = vec![
            (1.0_f64, f64::NAN),
            (-0.0, 1e-310),
            (f64::INFINITY, 0.1 + 0.2),
        ];
        let back: Vec<(f64, f64)> = decode_run(&encode_run(&v).expect("encode")).expect("decode");
        let bits = |v: &[(f64, f64)]| -> Vec<(u64, u64)> {
            v.iter().map(|(a, b)| (a.to_bits(), b.to_bits())).collect()
        };
        assert_eq!(bits(&back), bits(&v));
        assert!(decode_run::<Vec<(f64, f64)>>(&[0xff, 0xff]).is_err());
    }
}
