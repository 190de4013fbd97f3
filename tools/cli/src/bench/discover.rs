//! `auvnav bench discover`: hidden-effect trials over many seeded draws (the right name with the
//! value within 10 %, and nothing else), null trials (false discoveries), the confusion table
//! (which effects were reported for which hidden one) and the wall time per trial; trials with two
//! effects hidden at once; the detection floor (each effect at fractions of its smallest drawn
//! magnitude); and the wall time of discovery on each measured data set.

use super::discover_measured::{MeasuredTiming, measured_timings};
use super::discover_misses::Misses;
use super::discover_surface::SurfaceSummary;
use crate::calibrate::Progress;
use crate::discover::hidden_effects::{
    HIDDEN, SetTrial, Trial, coloured, draw, draw_of, draw_pair, installation_effects, scaled,
    trial_set, trial_set_with, trial_voyages,
};
use crate::parallel::{default_threads, map_runs};
use serde::Serialize;
use std::collections::BTreeMap;
use std::sync::Mutex;

#[derive(Debug, Serialize)]
struct PerEffect {
    hidden: String,
    trials: usize,
    correct: usize,
    /// Reported names (or "none") and how often.
    reported: BTreeMap<String, usize>,
    /// Median relative error of the estimate where the name was right.
    median_relative_error: Option<f64>,
}

#[derive(Debug, Serialize)]
struct Summary {
    hidden_trials: usize,
    correct: usize,
    correct_rate: f64,
    /// Hidden trials where an effect other than the hidden one was reported.
    false_discoveries_with_effect: usize,
    /// How the hidden trials that did not name the hidden effect accounted for it.
    misses: Misses,
    null_trials: usize,
    null_false_discoveries: usize,
    null_false_discovery_rate: f64,
    per_effect: Vec<PerEffect>,
    median_trial_wall_s: f64,
    /// Trials with two effects hidden at once.
    pair_trials: usize,
    pairs_correct: usize,
    pairs_correct_rate: f64,
    /// Pair trials where an effect that was not hidden was reported.
    pairs_false_discoveries: usize,
    /// Per effect and magnitude fraction: how often the name was reported, and how often it was
    /// right within 10 % with nothing else.
    floor: Vec<FloorRow>,
    /// Trials with coloured DVL noise (a Gauss–Markov velocity error): nothing hidden, and one
    /// effect hidden.
    coloured_null_trials: usize,
    coloured_null_false_discoveries: usize,
    coloured_null_false_discovery_rate: f64,
    coloured_hidden_trials: usize,
    coloured_hidden_correct: usize,
    coloured_hidden_correct_rate: f64,
    /// Coloured hidden trials where an effect that was not hidden was reported.
    coloured_hidden_false_discoveries: usize,
    /// Coloured hidden trials with the hidden name and nothing else, whatever the value.
    coloured_hidden_named_right: usize,
    /// Coloured hidden trials whose named estimate lies within three reported standard
    /// deviations of the hidden value (of those named).
    coloured_hidden_within_3_sigma: usize,
    /// How the coloured hidden trials that did not name the hidden effect accounted for it.
    coloured_hidden_misses: Misses,
    /// `coloured_hidden_named_right` over the hidden trials the report neither puts below its
    /// floor nor calls not excited (the rate the target is set on).
    coloured_hidden_named_right_where_detectable_rate: f64,
    coloured: Vec<SetTrial>,
    /// The same noise over three voyages of one vehicle discovered together (each voyage its
    /// own noise realisation; an installation effect hidden in all three, or nothing).
    voyages_null_trials: usize,
    voyages_null_false_discoveries: usize,
    voyages_hidden_trials: usize,
    voyages_hidden_correct: usize,
    voyages_hidden_false_discoveries: usize,
    voyages_hidden_named_right: usize,
    voyages_hidden_misses: Misses,
    /// As `coloured_hidden_named_right_where_detectable_rate`, for the three voyages.
    voyages_hidden_named_right_where_detectable_rate: f64,
    voyages: Vec<SetTrial>,
    /// Discovery on the measured data sets (import in memory and discovery, per item).
    measured: Vec<MeasuredTiming>,
    /// Surface runs (compass, DVL, GNSS; no IMU), white and coloured, null and hidden.
    surface: Option<SurfaceSummary>,
    wall_s: f64,
    threads: usize,
    trials: Vec<Trial>,
    pairs: Vec<SetTrial>,
}

#[derive(Debug, Serialize)]
struct FloorRow {
    effect: String,
    /// Fraction of the magnitudes the main trials draw from (`HIDDEN` range).
    fraction: f64,
    /// Smallest and largest magnitude of this row (offset from nominal, per component).
    magnitude: [f64; 2],
    trials: usize,
    named: usize,
    correct: usize,
}

/// Options of `auvnav bench discover`.
#[derive(Debug, Clone)]
pub struct DiscoverBench {
    pub hidden: usize,
    pub null: usize,
    pub pairs: usize,
    /// Trials per effect and magnitude fraction of the detection floor (0: none).
    pub floor: usize,
    /// Trials with coloured DVL noise: half with nothing hidden, half with one effect hidden.
    pub coloured: usize,
    /// The same over three voyages discovered together (half null, half one installation
    /// effect hidden in all three).
    pub coloured_voyages: usize,
    /// Surface trials (a boat without an IMU): half white, half coloured, each half null and hidden.
    pub surface: usize,
    pub seed_offset: u64,
    /// `../shared/data` (or another copy): time discovery on the measured data sets in it.
    pub data: Option<std::path::PathBuf>,
    pub json: bool,
}

/// Fractions of the drawn magnitudes the detection floor tries.
pub const FLOOR_FRACTIONS: [f64; 4] = [1.0, 0.5, 0.25, 0.125];

/// Runs `hidden` trials (seeds 1..=hidden), `null` trials (seeds 100 001..), `pairs` trials with
/// two effects (seeds 200 001..), the detection floor (seeds 300 000 + 1000 × effect + 100 ×
/// fraction + k; at most 100 per fraction), the coloured-noise trials (null: seeds 400 001..,
/// hidden: 410 001..) and the coloured three-voyage trials (null: 420 001.., hidden: 430 001..;
/// voyage i of trial s with seed 16 s + i), all shifted by `seed_offset`, on all cores; then
/// the measured data sets one at a time.
// Long on purpose: every trial kind of the benchmark (hidden, null, pairs, floors, coloured,
// voyages) laid out and scored in one place, so their seeds are seen together.
pub fn discover(o: &DiscoverBench) -> anyhow::Result<()> {
    let (hidden, null, json) = (o.hidden, o.null, o.json);
    let start = std::time::Instant::now();
    let threads = default_threads();
    let dir = std::env::temp_dir().join(format!("auvnav-bench-discover-{}", std::process::id()));
    std::fs::create_dir_all(&dir)?;
    let off = o.seed_offset;
    let floor_jobs: Vec<(usize, f64, u64)> = (0..HIDDEN.len())
        .flat_map(|e| {
            FLOOR_FRACTIONS
                .iter()
                .enumerate()
                .flat_map(move |(fi, &f)| {
                    (0..o.floor).map(move |j| {
                        (e, f, 300_000 + 1000 * e as u64 + 100 * fi as u64 + j as u64)
                    })
                })
        })
        .collect();
    let halves = |n: usize| (n / 2, n - n / 2);
    let (coloured_null, coloured_hidden) = halves(o.coloured);
    let (voyages_null, voyages_hidden) = halves(o.coloured_voyages);
    let extra = o.pairs + floor_jobs.len() + o.coloured + o.coloured_voyages;
    let installation = installation_effects();
    let total = hidden + null;
    let progress = Mutex::new((Progress::new(!json), 0usize));
    // The hidden and null trials are the library's trial study (the runs a cluster runs too).
    let study =
        crate::discover::trials::TrialsStudy::new(&crate::discover::trials::TrialsOptions {
            hidden,
            null,
            per_run: false,
            seed_offset: off,
        })?;
    let results = map_runs(total, threads, |k| -> anyhow::Result<_> {
        let t0 = std::time::Instant::now();
        let t = auvnav_studies::runs::RunStudy::run(&study, k)?;
        if let Ok(mut p) = progress.lock() {
            p.1 += 1;
            let done = p.1;
            p.0.update("discovery trials", done, total);
        }
        Ok((t, t0.elapsed().as_secs_f64()))
    })?;
    let set_results = map_runs(extra, threads, |k| -> anyhow::Result<_> {
        let floor_end = o.pairs + floor_jobs.len();
        let t = if k < o.pairs {
            let seed = 200_001 + off + k as u64;
            trial_set(seed, &draw_pair(seed), &dir)?.0
        } else if k < floor_end {
            let (e, f, seed) = floor_jobs[k - o.pairs];
            trial_set(seed + off, &[scaled(&draw_of(seed + off, e), f)], &dir)?.0
        } else if k < floor_end + coloured_null {
            let seed = 400_001 + off + (k - floor_end) as u64;
            trial_set_with(seed, &[], &coloured(seed), &dir)?.0
        } else if k < floor_end + o.coloured {
            let seed = 410_001 + off + (k - floor_end - coloured_null) as u64;
            trial_set_with(seed, &[draw(seed)], &coloured(seed), &dir)?.0
        } else if k < floor_end + o.coloured + voyages_null {
            let seed = 420_001 + off + (k - floor_end - o.coloured) as u64;
            trial_voyages(seed, &[], 3, &dir)?
        } else {
            let seed = 430_001 + off + (k - floor_end - o.coloured - voyages_null) as u64;
            let e = installation[(seed as usize) % installation.len()];
            trial_voyages(seed, &[draw_of(seed, e)], 3, &dir)?
        };
        if let Ok(mut p) = progress.lock() {
            p.1 += 1;
            let done = p.1;
            p.0.update("discovery trials", done, total + extra);
        }
        Ok(t)
    });
    let _ = std::fs::remove_dir_all(&dir);
    let set_results = set_results?;
    let (pairs, rest) = set_results.split_at(o.pairs);
    let (floor_trials, rest) = rest.split_at(floor_jobs.len());
    let (coloured_trials, voyage_trials) = rest.split_at(o.coloured);
    let (v_null, v_hidden) = voyage_trials.split_at(voyages_null);
    let (c_null, c_hidden) = coloured_trials.split_at(coloured_null);
    let c_null_fd = c_null.iter().filter(|t| t.false_discovery).count();
    let c_hidden_correct = c_hidden.iter().filter(|t| t.correct).count();
    let misses_of =
        |trials: &[SetTrial]| Misses::of(trials.iter().flat_map(|t| t.misses.iter().flatten()));
    let rate = |n: usize, of: usize| n as f64 / of.max(1) as f64;
    let (c_misses, v_misses) = (misses_of(c_hidden), misses_of(v_hidden));
    let named_right = |trials: &[SetTrial]| trials.iter().filter(|t| t.named_right).count();
    let (c_named_right, v_named_right) = (named_right(c_hidden), named_right(v_hidden));
    let mut floor = Vec::new();
    for (e, (name, lo, hi)) in HIDDEN.iter().enumerate() {
        for &f in &FLOOR_FRACTIONS {
            let rows: Vec<&SetTrial> = floor_jobs
                .iter()
                .zip(floor_trials)
                .filter(|((je, jf, _), _)| *je == e && *jf == f)
                .map(|(_, t)| t)
                .collect();
            if rows.is_empty() {
                continue;
            }
            floor.push(FloorRow {
                effect: name.to_string(),
                fraction: f,
                magnitude: [lo * f, hi * f],
                trials: rows.len(),
                named: rows
                    .iter()
                    .filter(|t| t.found.contains(&name.to_string()))
                    .count(),
                correct: rows.iter().filter(|t| t.correct).count(),
            });
        }
    }
    let surface = (o.surface > 0)
        .then(|| super::discover_surface::run(o.surface, off, threads, &dir, json))
        .transpose()?;
    let measured = match &o.data {
        Some(d) => measured_timings(d)?,
        None => Vec::new(),
    };
    let mut walls: Vec<f64> = results.iter().map(|r| r.1).collect();
    walls.sort_by(f64::total_cmp);
    let trials: Vec<Trial> = results.into_iter().map(|r| r.0).collect();
    let (with, without): (Vec<&Trial>, Vec<&Trial>) =
        trials.iter().partition(|t| t.hidden.is_some());
    let mut per: BTreeMap<String, PerEffect> = BTreeMap::new();
    let mut errors: BTreeMap<String, Vec<f64>> = BTreeMap::new();
    for t in &with {
        let Some(h) = &t.hidden else { continue };
        let e = per.entry(h.name.clone()).or_insert_with(|| PerEffect {
            hidden: h.name.clone(),
            trials: 0,
            correct: 0,
            reported: BTreeMap::new(),
            median_relative_error: None,
        });
        e.trials += 1;
        e.correct += usize::from(t.correct);
        if t.found.is_empty() {
            *e.reported.entry("none".into()).or_default() += 1;
        }
        for f in &t.found {
            *e.reported.entry(f.clone()).or_default() += 1;
        }
        if let Some(r) = t.relative_error {
            errors.entry(h.name.clone()).or_default().push(r);
        }
    }
    for (name, mut v) in errors {
        v.sort_by(f64::total_cmp);
        if let Some(e) = per.get_mut(&name) {
            e.median_relative_error = v.get(v.len() / 2).copied();
        }
    }
    let correct = with.iter().filter(|t| t.correct).count();
    let null_fd = without.iter().filter(|t| t.false_discovery).count();
    let s = Summary {
        hidden_trials: with.len(),
        correct,
        correct_rate: correct as f64 / with.len().max(1) as f64,
        false_discoveries_with_effect: with.iter().filter(|t| t.false_discovery).count(),
        misses: Misses::of(with.iter().filter_map(|t| t.miss.as_ref())),
        null_trials: without.len(),
        null_false_discoveries: null_fd,
        null_false_discovery_rate: null_fd as f64 / without.len().max(1) as f64,
        per_effect: per.into_values().collect(),
        median_trial_wall_s: walls.get(walls.len() / 2).copied().unwrap_or(0.0),
        pair_trials: pairs.len(),
        pairs_correct: pairs.iter().filter(|t| t.correct).count(),
        pairs_correct_rate: pairs.iter().filter(|t| t.correct).count() as f64
            / pairs.len().max(1) as f64,
        pairs_false_discoveries: pairs.iter().filter(|t| t.false_discovery).count(),
        floor,
        coloured_null_trials: c_null.len(),
        coloured_null_false_discoveries: c_null_fd,
        coloured_null_false_discovery_rate: c_null_fd as f64 / c_null.len().max(1) as f64,
        coloured_hidden_trials: coloured_hidden,
        coloured_hidden_correct: c_hidden_correct,
        coloured_hidden_correct_rate: c_hidden_correct as f64 / coloured_hidden.max(1) as f64,
        coloured_hidden_false_discoveries: c_hidden.iter().filter(|t| t.false_discovery).count(),
        coloured_hidden_named_right: c_named_right,
        coloured_hidden_within_3_sigma: c_hidden
            .iter()
            .filter(|t| t.within_3_sigma.iter().all(|w| w.unwrap_or(false)))
            .count(),
        coloured_hidden_named_right_where_detectable_rate: rate(
            c_named_right,
            c_misses.detectable(coloured_hidden),
        ),
        coloured_hidden_misses: c_misses,
        coloured: coloured_trials.to_vec(),
        voyages_null_trials: v_null.len(),
        voyages_null_false_discoveries: v_null.iter().filter(|t| t.false_discovery).count(),
        voyages_hidden_trials: voyages_hidden,
        voyages_hidden_correct: v_hidden.iter().filter(|t| t.correct).count(),
        voyages_hidden_false_discoveries: v_hidden.iter().filter(|t| t.false_discovery).count(),
        voyages_hidden_named_right: v_named_right,
        voyages_hidden_named_right_where_detectable_rate: rate(
            v_named_right,
            v_misses.detectable(voyages_hidden),
        ),
        voyages_hidden_misses: v_misses,
        voyages: voyage_trials.to_vec(),
        measured,
        surface,
        wall_s: start.elapsed().as_secs_f64(),
        threads,
        trials,
        pairs: pairs.to_vec(),
    };
    if json {
        crate::json::print(&s)?;
        return Ok(());
    }
    println!(
        "hidden effects: {}/{} right name with the value within 10 % and nothing else ({:.1} %); \
         {} with another effect reported",
        s.correct,
        s.hidden_trials,
        100.0 * s.correct_rate,
        s.false_discoveries_with_effect
    );
    println!("  {}", s.misses.describe());
    println!(
        "null data: {}/{} with a false discovery ({:.1} %)",
        s.null_false_discoveries,
        s.null_trials,
        100.0 * s.null_false_discovery_rate
    );
    println!(
        "{:<20} {:>6} {:>8} {:>12}  reported",
        "hidden", "trials", "correct", "median error"
    );
    for e in &s.per_effect {
        println!(
            "{:<20} {:>6} {:>8} {:>11.2}%  {}",
            e.hidden,
            e.trials,
            e.correct,
            100.0 * e.median_relative_error.unwrap_or(f64::NAN),
            e.reported
                .iter()
                .map(|(k, v)| format!("{k} x{v}"))
                .collect::<Vec<_>>()
                .join(", ")
        );
    }
    if s.pair_trials > 0 {
        println!(
            "two effects hidden: {}/{} both named within 10 % and nothing else ({:.1} %); {} with an effect reported that was not hidden",
            s.pairs_correct,
            s.pair_trials,
            100.0 * s.pairs_correct_rate,
            s.pairs_false_discoveries
        );
        for t in s.pairs.iter().filter(|t| !t.correct) {
            println!(
                "  seed {}: hidden {:?}, found {:?}, relative errors {:?}",
                t.seed,
                t.hidden.iter().map(|h| &h.name).collect::<Vec<_>>(),
                t.found,
                t.relative_errors
            );
        }
    }
    if s.coloured_null_trials + s.coloured_hidden_trials > 0 {
        println!(
            "coloured DVL noise (Gauss-Markov velocity error): null {}/{} with a false discovery \
             ({:.1} %); hidden {}/{} right name within 10 % and nothing else ({:.1} %), {} with \
             another effect reported",
            s.coloured_null_false_discoveries,
            s.coloured_null_trials,
            100.0 * s.coloured_null_false_discovery_rate,
            s.coloured_hidden_correct,
            s.coloured_hidden_trials,
            100.0 * s.coloured_hidden_correct_rate,
            s.coloured_hidden_false_discoveries
        );
        println!(
            "  hidden: {}/{} the right name and nothing else (any value), {}/{} ({:.1} %) of those \
             not below the floor or not excited; {} within 3 reported standard deviations; {}",
            s.coloured_hidden_named_right,
            s.coloured_hidden_trials,
            s.coloured_hidden_named_right,
            s.coloured_hidden_misses
                .detectable(s.coloured_hidden_trials),
            100.0 * s.coloured_hidden_named_right_where_detectable_rate,
            s.coloured_hidden_within_3_sigma,
            s.coloured_hidden_misses.describe()
        );
        for t in s.coloured.iter().filter(|t| !t.correct) {
            println!(
                "  seed {}: hidden {:?}, found {:?}, relative errors {:?}, misses {:?} (size over \
                 the floor {:?})",
                t.seed,
                t.hidden.iter().map(|h| &h.name).collect::<Vec<_>>(),
                t.found,
                t.relative_errors,
                t.misses,
                t.sizes_over_floor
            );
        }
    }
    if s.voyages_null_trials + s.voyages_hidden_trials > 0 {
        println!(
            "coloured DVL noise, three voyages discovered together: null {}/{} with a false \
             discovery; an installation effect hidden in all three: {}/{} right name within 10 % \
             and nothing else, {} with another effect reported",
            s.voyages_null_false_discoveries,
            s.voyages_null_trials,
            s.voyages_hidden_correct,
            s.voyages_hidden_trials,
            s.voyages_hidden_false_discoveries
        );
        println!(
            "  hidden: {}/{} the right name and nothing else (any value), {}/{} ({:.1} %) of those \
             not below the floor or not excited; {}",
            s.voyages_hidden_named_right,
            s.voyages_hidden_trials,
            s.voyages_hidden_named_right,
            s.voyages_hidden_misses.detectable(s.voyages_hidden_trials),
            100.0 * s.voyages_hidden_named_right_where_detectable_rate,
            s.voyages_hidden_misses.describe()
        );
        for t in s.voyages.iter().filter(|t| !t.correct) {
            println!(
                "  seed {}: hidden {:?}, found {:?}, relative errors {:?}",
                t.seed,
                t.hidden.iter().map(|h| &h.name).collect::<Vec<_>>(),
                t.found,
                t.relative_errors
            );
        }
    }
    if !s.floor.is_empty() {
        println!(
            "detection floor: {:<18} {:>8} {:>22} {:>6} {:>6} {:>8}",
            "effect", "fraction", "magnitude", "trials", "named", "correct"
        );
        for r in &s.floor {
            println!(
                "                 {:<18} {:>8} {:>10.4}..{:<10.4} {:>6} {:>6} {:>8}",
                r.effect, r.fraction, r.magnitude[0], r.magnitude[1], r.trials, r.named, r.correct
            );
        }
    }
    if let Some(x) = &s.surface {
        super::discover_surface::print(x);
    }
    for m in &s.measured {
        println!(
            "measured {}: median {:.2} s, max {:.2} s, total {:.2} s over {} item(s) (import in memory + discovery)",
            m.data_set, m.median_wall_s, m.max_wall_s, m.total_wall_s, m.items
        );
    }
    println!(
        "median {:.2} s per trial (simulation + discovery), {:.1} s wall on {} threads",
        s.median_trial_wall_s, s.wall_s, s.threads
    );
    Ok(())
}
