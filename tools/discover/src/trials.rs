//! The hidden-effect and null trials of `auvnav bench discover` as a study of independent runs
//! ([`auvnav_studies::runs::RunStudy`]): trial k < `hidden` hides the effect drawn for seed k + 1,
//! the others (null trials) hide nothing and use seeds from 100 001. The benchmark and a
//! distributed engine (the Python package's `auvnav.fleet`) run the same trials.

use super::hidden_effects::{Trial, draw, trial};
use auvnav_studies::StudyError;
use serde::Serialize;

/// How many trials of each kind.
#[derive(Debug, Clone)]
#[cfg_attr(feature = "clap", derive(clap::Args))]
pub struct TrialsOptions {
    /// Trials with a hidden effect (seeds 1, 2, ...).
    #[cfg_attr(feature = "clap", arg(long, default_value_t = 20))]
    pub hidden: usize,
    /// Trials with nothing hidden (seeds 100001, 100002, ...).
    #[cfg_attr(feature = "clap", arg(long, default_value_t = 10))]
    pub null: usize,
    /// Include every trial in the report (`per_run`).
    #[cfg_attr(feature = "clap", arg(long))]
    pub per_run: bool,
    /// Added to every trial's seed (below 50 000): the same trials on other draws.
    #[cfg_attr(feature = "clap", arg(long, default_value_t = 0))]
    pub seed_offset: u64,
}

/// The trials' outcome.
#[derive(Debug, Clone, Serialize)]
pub struct TrialsReport {
    pub hidden: usize,
    pub null: usize,
    /// Hidden trials with the right name, the value within 10 % and nothing else.
    pub correct: usize,
    /// Hidden trials whose effect was named (whatever its value and the rest).
    pub named: usize,
    /// Null trials where something was named.
    pub null_false_discoveries: usize,
    pub correct_fraction: f64,
    pub null_false_discovery_fraction: f64,
    /// With `per_run`: every trial, hidden ones first.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub per_run: Option<Vec<Trial>>,
    pub wall_s: f64,
}

/// The trial study.
pub struct TrialsStudy {
    args: TrialsOptions,
}

impl TrialsStudy {
    pub fn new(a: &TrialsOptions) -> Result<TrialsStudy, StudyError> {
        if a.seed_offset >= 50_000 {
            return Err(StudyError::Options(format!(
                "--seed-offset {}: below 50000, so that the hidden and null trials keep their \
                 blocks of seeds",
                a.seed_offset
            )));
        }
        Ok(TrialsStudy { args: a.clone() })
    }

    /// The seed and the hidden effect of trial `k`.
    pub fn seed_of(&self, k: usize) -> (u64, bool) {
        let o = self.args.seed_offset;
        if k < self.args.hidden {
            (o + k as u64 + 1, true)
        } else {
            (o + 100_001 + (k - self.args.hidden) as u64, false)
        }
    }
}

impl auvnav_studies::runs::RunStudy for TrialsStudy {
    type Run = Trial;
    type Report = TrialsReport;

    fn runs(&self) -> usize {
        self.args.hidden + self.args.null
    }

    fn run(&self, k: usize) -> Result<Trial, StudyError> {
        let (seed, hide) = self.seed_of(k);
        let dir = std::env::temp_dir().join(format!(
            "auvnav-trial-{}-{seed}-{}",
            std::process::id(),
            if hide { "hidden" } else { "null" }
        ));
        std::fs::create_dir_all(&dir).map_err(|e| StudyError::run(k, e))?;
        let result = trial(seed, hide.then(|| draw(seed)), &dir);
        let _ = std::fs::remove_dir_all(&dir);
        Ok(result.map_err(|e| StudyError::run(k, e))?.0)
    }

    fn report(&self, runs: Vec<Trial>, wall_s: f64) -> Result<TrialsReport, StudyError> {
        let a = &self.args;
        if runs.len() != a.hidden + a.null {
            return Err(StudyError::Results(format!(
                "{} trial results for {} trials",
                runs.len(),
                a.hidden + a.null
            )));
        }
        let (hidden, null) = runs.split_at(a.hidden);
        let correct = hidden.iter().filter(|t| t.correct).count();
        let named = hidden
            .iter()
            .filter(|t| t.hidden.as_ref().is_some_and(|h| t.found.contains(&h.name)))
            .count();
        let null_false_discoveries = null.iter().filter(|t| t.false_discovery).count();
        let fraction = |n: usize, of: usize| if of > 0 { n as f64 / of as f64 } else { 0.0 };
        Ok(TrialsReport {
            hidden: a.hidden,
            null: a.null,
            correct,
            named,
            null_false_discoveries,
            correct_fraction: fraction(correct, a.hidden),
            null_false_discovery_fraction: fraction(null_false_discoveries, a.null),
            per_run: a.per_run.then_some(runs),
            wall_s,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::super::hidden_effects::{HIDDEN, Hidden, draw_of};

    /// A trial's hidden effect travels between the study's processes as bytes, with and without
    /// the settings beside its value.
    #[test]
    fn a_hidden_effect_survives_the_study_runners_bytes() {
        use auvnav_studies::runs::{decode_run, encode_run};
        let periodic = HIDDEN
            .iter()
            .position(|(n, _, _)| *n == "dvl.periodic_velocity_error")
            .expect("drawn");
        for h in [
            Hidden::new("dvl.mount_yaw", vec![1.5]),
            draw_of(3, periodic),
        ] {
            let back: Hidden = decode_run(&encode_run(&h).expect("encode")).expect("decode");
            assert_eq!(
                (back.name, back.value, back.with),
                (h.name, h.value, h.with)
            );
        }
    }
}
