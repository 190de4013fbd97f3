//! `auvnav bench discover --surface N`: hidden-effect trials on surface runs (a boat with a
//! compass, a DVL and GNSS, no IMU; `auvnav_discover::surface_trials`), where the GNSS positions
//! decide the installation and the compass deviation and the moving bed are among the effects
//! hidden. Half the trials have white sensor noise, half a Gauss–Markov DVL velocity error on
//! top; each half is half null, half one effect hidden.

use super::discover_misses::Misses;
use crate::calibrate::Progress;
use crate::discover::hidden_effects::SetTrial;
use crate::discover::surface_trials::{SURFACE_HIDDEN, WrittenFold, surface_draw, surface_trial};
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
    /// Every trial's folds (null and hidden) navigated with what `--write-config` writes from
    /// the other fold, where it writes anything.
    pub(super) written: WrittenFigures,
    pub(super) trials: Vec<SetTrial>,
}

/// What `auvnav discover --write-config` writes from one half of a run, navigating the other.
#[derive(Debug, Serialize)]
pub(super) struct WrittenFigures {
    /// Folds where the other half's discovery writes anything.
    pub(super) folds: usize,
    /// Of those, closer to the GNSS than with the nominal installation.
    pub(super) better_than_nominal: usize,
    /// Of those, closer than with S-CAL's two-point installation from the other half.
    pub(super) better_than_two_point: usize,
    /// Median over those folds of 1 − written / two-point window RMS.
    pub(super) median_gain_over_two_point: f64,
}

fn written_figures(folds: &[WrittenFold]) -> WrittenFigures {
    let writing: Vec<&WrittenFold> = folds.iter().filter(|f| f.writes).collect();
    let mut gains: Vec<f64> = writing
        .iter()
        .map(|f| 1.0 - f.written_m / f.two_point_m)
        .filter(|g| g.is_finite())
        .collect();
    gains.sort_by(f64::total_cmp);
    WrittenFigures {
        folds: writing.len(),
        better_than_nominal: writing.iter().filter(|f| f.written_m < f.nominal_m).count(),
        better_than_two_point: writing
            .iter()
            .filter(|f| f.written_m < f.two_point_m)
            .count(),
        median_gain_over_two_point: gains.get(gains.len() / 2).copied().unwrap_or(f64::NAN),
    }
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
    let results = map_runs(
        jobs.len(),
        threads,
        |k| -> anyhow::Result<(SetTrial, Vec<WrittenFold>)> {
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
        },
    );
    let _ = std::fs::remove_dir_all(dir);
    let results = results?;
    let (white_trials, coloured_trials) = results.split_at(white);
    let family = |t: &[(SetTrial, Vec<WrittenFold>)], null| {
        let trials: Vec<SetTrial> = t.iter().map(|x| x.0.clone()).collect();
        let folds: Vec<WrittenFold> = t.iter().flat_map(|x| x.1.iter().copied()).collect();
        family(&trials, null, written_figures(&folds))
    };
    Ok(SurfaceSummary {
        hidden_from: SURFACE_HIDDEN
            .iter()
            .map(|(n, lo, hi)| (n.to_string(), *lo, *hi))
            .collect(),
        white: family(white_trials, white_null),
        coloured: family(coloured_trials, coloured_null),
    })
}

fn family(trials: &[SetTrial], null: usize, written: WrittenFigures) -> SurfaceFamily {
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
        written,
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
        let w = &f.written;
        println!(
            "  what --write-config writes from one half, on the other: {} halves written to, {} \
             closer to the GNSS than nominal, {} closer than the two-point installation (median \
             gain over it {:.1} %)",
            w.folds,
            w.better_than_nominal,
            w.better_than_two_point,
            100.0 * w.median_gain_over_two_point
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
