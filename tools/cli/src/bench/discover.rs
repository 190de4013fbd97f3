//! `auvnav bench discover`: hidden-effect trials over many seeded draws (the right name with the
//! value within 10 %, and nothing else), null trials (false discoveries), the confusion table
//! (which effects were reported for which hidden one) and the wall time per trial.

use crate::calibrate::Progress;
use crate::discover::hidden::{Trial, draw, trial};
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
    version: u32,
    hidden_trials: usize,
    correct: usize,
    correct_rate: f64,
    /// Hidden trials where an effect other than the hidden one was reported.
    false_discoveries_with_effect: usize,
    null_trials: usize,
    null_false_discoveries: usize,
    null_false_discovery_rate: f64,
    per_effect: Vec<PerEffect>,
    median_trial_wall_seconds: f64,
    wall_seconds: f64,
    threads: usize,
    trials: Vec<Trial>,
}

/// Runs `hidden` trials (seeds 1..=hidden) and `null` trials (seeds 100 001..) on `threads`.
pub fn discover(hidden: usize, null: usize, json: bool) -> anyhow::Result<()> {
    let start = std::time::Instant::now();
    let threads = default_threads();
    let dir = std::env::temp_dir().join(format!("auvnav-bench-discover-{}", std::process::id()));
    std::fs::create_dir_all(&dir)?;
    let total = hidden + null;
    let progress = Mutex::new((Progress::new(!json), 0usize));
    let results = map_runs(total, threads, |k| {
        let t0 = std::time::Instant::now();
        let (seed, h) = if k < hidden {
            let seed = k as u64 + 1;
            (seed, Some(draw(seed)))
        } else {
            (100_001 + (k - hidden) as u64, None)
        };
        let (t, _) = trial(seed, h, &dir)?;
        if let Ok(mut p) = progress.lock() {
            p.1 += 1;
            let done = p.1;
            p.0.update("discovery trials", done, total);
        }
        Ok((t, t0.elapsed().as_secs_f64()))
    });
    let _ = std::fs::remove_dir_all(&dir);
    let results = results?;
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
        version: 1,
        hidden_trials: with.len(),
        correct,
        correct_rate: correct as f64 / with.len().max(1) as f64,
        false_discoveries_with_effect: with.iter().filter(|t| t.false_discovery).count(),
        null_trials: without.len(),
        null_false_discoveries: null_fd,
        null_false_discovery_rate: null_fd as f64 / without.len().max(1) as f64,
        per_effect: per.into_values().collect(),
        median_trial_wall_seconds: walls.get(walls.len() / 2).copied().unwrap_or(0.0),
        wall_seconds: start.elapsed().as_secs_f64(),
        threads,
        trials,
    };
    if json {
        println!("{}", serde_json::to_string_pretty(&s)?);
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
    println!(
        "median {:.2} s per trial (simulation + discovery), {:.1} s wall on {} threads",
        s.median_trial_wall_seconds, s.wall_seconds, s.threads
    );
    Ok(())
}
