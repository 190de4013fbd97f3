//! `auvnav bench discover --surface N`: hidden-effect trials on surface runs (a boat with a
//! compass, a DVL and GNSS, no IMU; `auvnav_discover::surface_trials`), where the GNSS positions
//! decide the installation and the compass deviation and the moving bed are among the effects
//! hidden. Half the trials have white sensor noise, half a Gauss–Markov DVL velocity error on
//! top; each half is half null, half one effect hidden.

use super::discover_misses::Misses;
use crate::calibrate::Progress;
use crate::discover::hidden_effects::SetTrial;
use crate::discover::surface_trials::{SURFACE_HIDDEN, surface_draw, surface_trial};
use crate::parallel::map_runs;
use serde::Serialize;
use std::collections::BTreeMap;
use std::path::Path;
use std::sync::Mutex;

/// One noise kind's trials.
#[derive(Debug, Serialize)]
pub(super) struct SurfaceFamily {
    pub(super) null_trials: usize,
    pub(super) null_false_discoveries: usize,
    pub(super) hidden_trials: usize,
    /// The hidden name and nothing else, the value within 10 %.
    pub(super) hidden_correct: usize,
    /// The hidden name and nothing else, whatever the value.
    pub(super) hidden_named_right: usize,
    /// Hidden trials where an effect that was not hidden was reported.
    pub(super) hidden_false_discoveries: usize,
    /// How the hidden trials that did not name the hidden effect accounted for it.
    pub(super) hidden_misses: Misses,
    /// `hidden_named_right` over the hidden trials the report neither puts below its floor nor
    /// calls not excited.
    pub(super) hidden_named_right_where_detectable_rate: f64,
    /// Per hidden effect: trials, named right, correct, and what was reported (or "none").
    pub(super) per_effect: Vec<SurfaceEffect>,
    pub(super) trials: Vec<SetTrial>,
}

#[derive(Debug, Serialize)]
pub(super) struct SurfaceEffect {
    pub(super) hidden: String,
    pub(super) trials: usize,
    pub(super) named_right: usize,
    pub(super) correct: usize,
    pub(super) reported: BTreeMap<String, usize>,
}

/// The surface trials' figures.
#[derive(Debug, Serialize)]
pub(super) struct SurfaceSummary {
    /// Effects the trials hide, with the range their magnitudes are drawn from.
    pub(super) hidden_from: Vec<(String, f64, f64)>,
    pub(super) white: SurfaceFamily,
    pub(super) coloured: SurfaceFamily,
}

/// Runs `n` surface trials on `threads` threads in `dir`: seeds 500 001.. (white null), 600 001..
/// (white hidden), 700 001.. (coloured null), 800 001.. (coloured hidden), shifted by `offset`
/// (below 50 000: the blocks never meet).
pub(super) fn run(
    n: usize,
    offset: u64,
    threads: usize,
    dir: &Path,
    json: bool,
) -> anyhow::Result<SurfaceSummary> {
    std::fs::create_dir_all(dir)?;
    let half = |x: usize| (x / 2, x - x / 2);
    let (white, coloured) = half(n);
    let (white_null, white_hidden) = half(white);
    let (coloured_null, coloured_hidden) = half(coloured);
    let jobs: Vec<(u64, bool, bool)> = (0..white_null)
        .map(|k| (500_001 + k as u64, false, false))
        .chain((0..white_hidden).map(|k| (600_001 + k as u64, false, true)))
        .chain((0..coloured_null).map(|k| (700_001 + k as u64, true, false)))
        .chain((0..coloured_hidden).map(|k| (800_001 + k as u64, true, true)))
        .collect();
    let progress = Mutex::new((Progress::new(!json), 0usize));
    let results = map_runs(jobs.len(), threads, |k| -> anyhow::Result<SetTrial> {
        let (seed, coloured, hidden) = jobs[k];
        let seed = seed + offset;
        let h: Vec<_> = if hidden {
            vec![surface_draw(seed)]
        } else {
            Vec::new()
        };
        let t = surface_trial(seed, &h, coloured, dir)?;
        if let Ok(mut p) = progress.lock() {
            p.1 += 1;
            let done = p.1;
            p.0.update("surface trials", done, jobs.len());
        }
        Ok(t)
    });
    let _ = std::fs::remove_dir_all(dir);
    let results = results?;
    let (white_trials, coloured_trials) = results.split_at(white);
    Ok(SurfaceSummary {
        hidden_from: SURFACE_HIDDEN
            .iter()
            .map(|(n, lo, hi)| (n.to_string(), *lo, *hi))
            .collect(),
        white: family(white_trials, white_null),
        coloured: family(coloured_trials, coloured_null),
    })
}

fn family(trials: &[SetTrial], null: usize) -> SurfaceFamily {
    let (nulls, hidden) = trials.split_at(null);
    let misses = Misses::of(hidden.iter().flat_map(|t| t.misses.iter().flatten()));
    let named_right = hidden.iter().filter(|t| t.named_right).count();
    let mut per: BTreeMap<String, SurfaceEffect> = BTreeMap::new();
    for t in hidden {
        let Some(h) = t.hidden.first() else { continue };
        let e = per.entry(h.name.clone()).or_insert_with(|| SurfaceEffect {
            hidden: h.name.clone(),
            trials: 0,
            named_right: 0,
            correct: 0,
            reported: BTreeMap::new(),
        });
        e.trials += 1;
        e.named_right += usize::from(t.named_right);
        e.correct += usize::from(t.correct);
        if t.found.is_empty() {
            *e.reported.entry("none".into()).or_default() += 1;
        }
        for f in &t.found {
            *e.reported.entry(f.clone()).or_default() += 1;
        }
    }
    SurfaceFamily {
        null_trials: nulls.len(),
        null_false_discoveries: nulls.iter().filter(|t| t.false_discovery).count(),
        hidden_trials: hidden.len(),
        hidden_correct: hidden.iter().filter(|t| t.correct).count(),
        hidden_named_right: named_right,
        hidden_false_discoveries: hidden.iter().filter(|t| t.false_discovery).count(),
        hidden_named_right_where_detectable_rate: named_right as f64
            / misses.detectable(hidden.len()).max(1) as f64,
        hidden_misses: misses,
        per_effect: per.into_values().collect(),
        trials: trials.to_vec(),
    }
}

/// Prints the surface trials' figures and every trial that was not right.
pub(super) fn print(s: &SurfaceSummary) {
    for (label, f) in [("white", &s.white), ("coloured", &s.coloured)] {
        println!(
            "surface runs, {label} noise: null {}/{} with a false discovery; hidden {}/{} right \
             name within 10 % and nothing else, {}/{} the right name and nothing else ({:.1} % of \
             those not below the floor or not excited), {} with another effect reported; {}",
            f.null_false_discoveries,
            f.null_trials,
            f.hidden_correct,
            f.hidden_trials,
            f.hidden_named_right,
            f.hidden_trials,
            100.0 * f.hidden_named_right_where_detectable_rate,
            f.hidden_false_discoveries,
            f.hidden_misses.describe()
        );
        for e in &f.per_effect {
            println!(
                "  {:<20} {:>3} trials, {:>3} named right, {:>3} within 10 %: {}",
                e.hidden,
                e.trials,
                e.named_right,
                e.correct,
                e.reported
                    .iter()
                    .map(|(k, v)| format!("{k} x{v}"))
                    .collect::<Vec<_>>()
                    .join(", ")
            );
        }
        for t in f.trials.iter().filter(|t| !t.correct) {
            println!(
                "  seed {}: hidden {:?}, found {:?}, relative errors {:?}, misses {:?}",
                t.seed,
                t.hidden
                    .iter()
                    .map(|h| format!("{} {:?}", h.name, h.value))
                    .collect::<Vec<_>>(),
                t.found,
                t.relative_errors,
                t.misses
            );
        }
    }
}
