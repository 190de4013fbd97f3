//! `auvnav bench guard`'s report and how it judges its ratios: the median pair ratio and the run's noise, against
//! the baseline for this build profile and processor, and the pairs of a confirming round merged
//! into the first round's.

use super::guard_baseline::GuardBaseline;
use anyhow::Context;
use serde::Serialize;
use std::path::Path;

/// One workload's alternating runs.
#[derive(Debug, Clone, Serialize)]
pub struct GuardWorkload {
    pub name: String,
    /// Wall time of each run of this build (s), in the order run.
    pub this_wall_s: Vec<f64>,
    /// Wall time of each run of the other side (the base build or the reference workload).
    pub other_wall_s: Vec<f64>,
    /// This build's time over the other's, pair by pair (> 1: this build is slower).
    pub pair_ratios: Vec<f64>,
    pub median_ratio: f64,
    /// Half the spread of the middle half of the pair ratios, relative to their median (%): how
    /// far one ratio strays from the median on this machine now.
    pub noise_percent: f64,
    /// Against the baseline (reference mode with a baseline): the baseline's ratio, the
    /// slowdown (%; negative: faster) and the verdict.
    pub baseline_ratio: Option<f64>,
    pub slowdown_percent: Option<f64>,
    pub verdict: Option<String>,
    /// Whether it passed, where judged.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub passed: Option<bool>,
}

impl GuardWorkload {
    /// A workload's runs, not judged yet: pair by pair this build's time over the other's, their
    /// median and noise.
    pub fn of_runs(name: &str, this_wall_s: Vec<f64>, other_wall_s: Vec<f64>) -> GuardWorkload {
        let pair_ratios: Vec<f64> = this_wall_s
            .iter()
            .zip(&other_wall_s)
            .map(|(x, y)| x / y)
            .collect();
        let (median_ratio, noise_percent) = median_and_noise(&pair_ratios);
        GuardWorkload {
            name: name.into(),
            this_wall_s,
            other_wall_s,
            pair_ratios,
            median_ratio,
            noise_percent,
            baseline_ratio: None,
            slowdown_percent: None,
            verdict: None,
            passed: None,
        }
    }

    /// Judged and failed.
    pub fn failed(&self) -> bool {
        self.passed == Some(false)
    }
}

/// The guard's report.
#[derive(Debug, Clone, Serialize)]
pub struct GuardReport {
    pub this: String,
    /// The other side: a base build's path, or "the reference workload".
    pub other: String,
    /// The build profile of this binary ("release" or "dev"): baselines are kept per profile.
    pub profile: String,
    pub cpu: Option<usize>,
    pub log_hours: f64,
    pub pairs: usize,
    pub workloads: Vec<GuardWorkload>,
    /// Whether every judged workload passed (true when nothing was judged).
    pub passed: bool,
    /// The workloads that were slower than the baseline after `pairs` pairs and ran as many
    /// again, judged on all their pairs.
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub confirmed: Vec<String>,
}

pub(super) fn profile() -> &'static str {
    if cfg!(debug_assertions) {
        "dev"
    } else {
        "release"
    }
}

/// The processor's model name and this machine's CPU count: where a baseline was measured.
pub(super) fn cpu_model() -> String {
    let info = std::fs::read_to_string("/proc/cpuinfo").unwrap_or_default();
    let model = info
        .lines()
        .find(|l| l.starts_with("model name"))
        .and_then(|l| l.split(':').nth(1))
        .map_or("unknown processor", str::trim);
    // Counted from /proc/cpuinfo: this process may already be pinned to one of them.
    let n = info.lines().filter(|l| l.starts_with("processor")).count();
    format!("{model}, {n} CPUs")
}

/// Median and noise (half the interquartile range over the median, %) of `ratios`.
fn median_and_noise(ratios: &[f64]) -> (f64, f64) {
    let mut s = ratios.to_vec();
    s.sort_by(f64::total_cmp);
    let q = |p: f64| {
        let x = p * (s.len() - 1) as f64;
        let (i, f) = (x.floor() as usize, x - x.floor());
        s[i] + (s[(i + 1).min(s.len() - 1)] - s[i]) * f
    };
    let m = q(0.5);
    (m, 50.0 * (q(0.75) - q(0.25)) / m)
}

/// Judges `w` against `baseline`: a slowdown beyond `limit_percent` and beyond twice the run's
/// noise fails; one within the limit passes; one beyond the limit but within the noise cannot be
/// told from it and fails too (the guard never passes what it cannot judge).
pub(super) fn judge(w: &mut GuardWorkload, baseline: f64, limit_percent: f64) -> bool {
    let slowdown = (w.median_ratio / baseline - 1.0) * 100.0;
    w.baseline_ratio = Some(baseline);
    w.slowdown_percent = Some(slowdown);
    let (passed, verdict) = if slowdown <= limit_percent {
        (
            true,
            format!("{slowdown:+.1} % against the baseline: within the {limit_percent} % limit"),
        )
    } else if slowdown > 2.0 * w.noise_percent {
        (
            false,
            format!(
                "{slowdown:+.1} % against the baseline: slower beyond the {limit_percent} % limit and beyond this run's noise ({:.1} %)",
                w.noise_percent
            ),
        )
    } else {
        (
            false,
            format!(
                "{slowdown:+.1} % against the baseline, but this run's noise is {:.1} %: cannot be judged here; run with more --pairs on a quieter machine",
                w.noise_percent
            ),
        )
    };
    w.verdict = Some(verdict);
    w.passed = Some(passed);
    passed
}

/// Judges every workload of `report` that the baseline file at `path` has a ratio for, on this
/// processor.
pub(super) fn judge_against(
    report: &mut GuardReport,
    path: &Path,
    limit_percent: f64,
) -> anyhow::Result<()> {
    let text =
        std::fs::read_to_string(path).with_context(|| format!("reading {}", path.display()))?;
    let b = GuardBaseline::parse(&text).with_context(|| format!("reading {}", path.display()))?;
    let here = cpu_model();
    let ratios = match b.find(profile(), &here) {
        Ok(found) => &found.ratios,
        Err(elsewhere) if elsewhere.is_empty() => anyhow::bail!(
            "{} has no baseline for the {} profile",
            path.display(),
            profile()
        ),
        Err(elsewhere) => {
            for w in &mut report.workloads {
                w.verdict = Some(format!(
                    "not judged: the {} baselines were measured on {}, this is {here}; add one \
                     for it with --write-baseline",
                    profile(),
                    elsewhere.join(" and ")
                ));
            }
            return Ok(());
        }
    };
    for w in &mut report.workloads {
        if let Some(&r) = ratios.get(&w.name) {
            report.passed &= judge(w, r, limit_percent);
        }
    }
    Ok(())
}

/// Adds the runs of a confirming round to the workloads of the same name, recomputes their median
/// and noise over all pairs and clears their verdicts (to be judged again).
pub(super) fn merge(workloads: &mut [GuardWorkload], more: Vec<GuardWorkload>) {
    for m in more {
        let Some(w) = workloads.iter_mut().find(|w| w.name == m.name) else {
            continue;
        };
        let this = [w.this_wall_s.as_slice(), &m.this_wall_s].concat();
        let other = [w.other_wall_s.as_slice(), &m.other_wall_s].concat();
        *w = GuardWorkload::of_runs(&m.name, this, other);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn workload(ratios: &[f64]) -> GuardWorkload {
        GuardWorkload::of_runs("replay core", ratios.to_vec(), vec![1.0; ratios.len()])
    }

    #[test]
    fn the_noise_is_half_the_middle_spread_over_the_median() {
        let (m, n) = median_and_noise(&[5.0, 1.0, 3.0, 2.0, 4.0]);
        assert_eq!(m, 3.0);
        assert!((n - 100.0 / 3.0).abs() < 1e-12, "{n}");
        assert_eq!(median_and_noise(&[2.0]), (2.0, 0.0));
    }

    /// 20 % slower with a quiet run fails; 5 % slower passes; 20 % slower in a run whose ratios
    /// scatter by more than that cannot be judged and fails too; faster passes.
    #[test]
    fn a_slowdown_beyond_the_limit_and_the_noise_fails() {
        let mut w = workload(&[1.19, 1.2, 1.21, 1.2, 1.2]);
        assert!(!judge(&mut w, 1.0, 10.0));
        assert!(
            w.verdict
                .as_deref()
                .expect("judged")
                .contains("beyond the 10 % limit")
        );
        assert!((w.slowdown_percent.expect("judged") - 20.0).abs() < 1e-9);
        let mut w = workload(&[1.04, 1.05, 1.06]);
        assert!(judge(&mut w, 1.0, 10.0));
        let mut w = workload(&[0.7, 1.2, 1.7, 1.0, 1.5]);
        assert!(!judge(&mut w, 1.0, 10.0));
        assert!(
            w.verdict
                .as_deref()
                .expect("judged")
                .contains("cannot be judged")
        );
        let mut w = workload(&[0.8, 0.8, 0.8]);
        assert!(judge(&mut w, 1.0, 10.0));
    }

    /// A first round hit by noise (a 20 % slowdown in four of five pairs) and a quiet second
    /// round: judged on all ten pairs, the build passes; a build slower in both rounds fails.
    #[test]
    fn a_confirming_round_is_judged_with_the_first() {
        let mut w = vec![workload(&[1.2, 1.21, 1.19, 1.0, 1.2])];
        assert!(!judge(&mut w[0], 1.0, 10.0));
        merge(&mut w, vec![workload(&[1.0, 1.01, 0.99, 1.0, 1.0])]);
        assert_eq!(w[0].pair_ratios.len(), 10);
        assert!(w[0].verdict.is_none() && w[0].passed.is_none());
        assert!(judge(&mut w[0], 1.0, 10.0), "{:?}", w[0].verdict);
        let mut w = vec![workload(&[1.2, 1.21, 1.19, 1.2, 1.2])];
        merge(&mut w, vec![workload(&[1.2, 1.19, 1.21, 1.2, 1.2])]);
        assert!(!judge(&mut w[0], 1.0, 10.0));
    }
}
