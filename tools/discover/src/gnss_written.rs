//! What `--write-config` writes, held out against the GNSS positions.
//!
//! On surface runs split into folds (each log, or one log's two halves), each fold is navigated
//! with the navigator configuration that the whole of discovery — the velocities' selection, the
//! GNSS decision, the navigation check that withholds — writes from the other folds alone, and
//! scored against its GNSS over the same windows as the nominal and the two-point installations
//! of the GNSS evidence. The position fit's own held-out figures judge only what the positions
//! name; this judges the calibration a user would deploy, on a run it has not seen.

use super::ChannelKind;
use super::findings::{DiscoverReport, FoundEffect, Refit, Withheld, components_of};
use super::gnss_evidence::{HeldOutEffect, WrittenHeldOut};
use super::outputs::{at_nominal, navigator_tables, written_model};
use anyhow::Context;
use auvnav_calibrate::surface::{Candidate, FittedParam, score_installation};
use auvnav_calibrate::voyage::VoyageSpec;
use auvnav_log::{LogMessage, LogReader, write_log_atomically};
use auvnav_sim::effects::Effects;
use std::path::{Path, PathBuf};

/// Scores each fold of `r.gnss` with what discovery writes from the other folds, and withholds
/// from what this run writes an effect with which a fold held out navigates worse than without
/// it (its mean square window error larger by more than [`super::fit::Selection::min_gain`]),
/// where the other folds write it and the windows can see it ([`visible`]).
///
/// `discover` runs the whole of discovery, with the options of this run, on other logs.
pub fn held_out(
    r: &mut DiscoverReport,
    discover: &dyn Fn(Vec<PathBuf>) -> anyhow::Result<DiscoverReport>,
) {
    let Some(g) = r.gnss.as_deref() else { return };
    if g.fold_specs.len() < 2 {
        return;
    }
    let (specs, params) = (g.fold_specs.clone(), g.params.clone());
    let (threshold, moving_bed) = (g.threshold_m, g.moving_bed);
    let dir = std::env::temp_dir().join(format!(
        "auvnav-discover-folds-{}-{}",
        std::process::id(),
        NEXT.fetch_add(1, std::sync::atomic::Ordering::Relaxed)
    ));
    let written: Vec<WrittenHeldOut> = (0..specs.len())
        .map(|k| {
            let fold = specs[k].name();
            let score = |e: &Effects| {
                score_installation(&specs[k], &candidate(e), threshold, moving_bed)
                    .map_err(|e| e.to_string())
            };
            let others = match from_others(discover, &specs, k, &dir) {
                Ok(o) => o,
                Err(e) => return failed(fold, format!("{e:#}")),
            };
            let model = written_model(&others);
            let with = match score(&model) {
                Ok(s) => s,
                Err(e) => return failed(fold, e),
            };
            let written = installation_effects(&others)
                .map(|e| HeldOutEffect {
                    name: e.name.clone(),
                    value: e.value.clone(),
                    rms_without_m: score(&at_nominal(&model, &others.nominal_model, &[&e.name]))
                        .ok()
                        .map(|s| s.rms_error_m),
                })
                .collect();
            WrittenHeldOut {
                fold,
                written,
                score: Some(with),
                error: None,
            }
        })
        .collect();
    let _ = std::fs::remove_dir_all(&dir);
    // Worse: the fold's mean square window error grows by more than the selection's smallest
    // gain.
    let min_gain = super::fit::Selection::default().min_gain;
    let refuted: Vec<Withheld> = installation_effects(r)
        .filter_map(|e| {
            let worse: Vec<String> = written
                .iter()
                .filter_map(|w| {
                    let with = w.score.as_ref()?.rms_error_m;
                    let x = w.written.iter().find(|x| x.name == e.name)?;
                    let without = x.rms_without_m?;
                    (visible(&params, x) && with * with > without * without * (1.0 + min_gain))
                        .then(|| format!("{} {with:.2} m with it, {without:.2} m without", w.fold))
                })
                .collect();
            (!worse.is_empty()).then(|| Withheld {
                name: e.name.clone(),
                note: format!(
                    "held out against the GNSS, a fold navigates worse with it as the other folds \
                     write it: {}",
                    worse.join("; ")
                ),
            })
        })
        .collect();
    r.withheld.extend(refuted);
    if let Some(g) = r.gnss.as_mut() {
        g.written_held_out = written;
    }
}

/// Fits again what `--write-config` keeps once [`held_out`] withheld effects: `discover`
/// runs the whole of discovery with them never selected. Fitted beside a withheld effect, a
/// kept one that the motion couples to it carries part of it (on the lake run a time offset and
/// the lever arm's forward component trade in the turns: forward speed × offset). A kept effect
/// whose refitted value agrees with its value beside them (every component within
/// [`AGREE_SIGMAS`] combined deviations) is written as refitted; one that moves further, or is
/// no longer named, is not determined apart from what was withheld and is withheld too; an
/// effect named only without them stands in for them and is not written. Where the refit fails,
/// a note says so and the effects kept are written as fitted beside them.
pub fn refit(
    r: &mut DiscoverReport,
    discover: &dyn Fn(Vec<String>) -> anyhow::Result<DiscoverReport>,
) {
    if r.withheld.is_empty() {
        return;
    }
    let without: Vec<String> = r.withheld.iter().map(|w| w.name.clone()).collect();
    let again = match discover(without.clone()) {
        Ok(a) => a,
        Err(e) => {
            r.notes.push(format!(
                "--write-config: fitting again without {} failed ({e:#}); the effects kept are \
                 written as fitted beside them",
                without.join(", ")
            ));
            return;
        }
    };
    let list = without.join(", ");
    let mut changes = Vec::new();
    let mut withheld = again.withheld.clone();
    for e in installation_effects(r) {
        let Some(x) = again.effects.iter().find(|x| x.name == e.name) else {
            changes.push(format!(
                "{} {} {} beside {list}, not named without",
                e.name,
                shown(e),
                e.unit
            ));
            withheld.push(Withheld {
                name: e.name.clone(),
                note: format!("named beside {list} only, which is withheld"),
            });
            continue;
        };
        let sigmas = apart(e, x);
        let moved = format!(
            "{} {} {unit} beside {list}, {} {unit} without ({sigmas:.1} combined deviations apart)",
            e.name,
            shown(e),
            shown(x),
            unit = e.unit
        );
        if sigmas > AGREE_SIGMAS {
            withheld.push(Withheld {
                name: e.name.clone(),
                note: format!("not determined apart from {list}: {moved}"),
            });
        }
        changes.push(moved);
    }
    for x in installation_effects(&again).filter(|x| !r.effects.iter().any(|e| e.name == x.name)) {
        changes.push(format!(
            "{} {} {} named only without {list}",
            x.name,
            shown(x),
            x.unit
        ));
        withheld.push(Withheld {
            name: x.name.clone(),
            note: format!("named only once {list} is left out: it stands in for it"),
        });
    }
    if changes.is_empty() {
        changes.push("nothing else named".into());
    }
    r.refit = Some(Box::new(Refit {
        without,
        effects: again.effects.clone(),
        withheld,
        changes,
        model: again.model,
    }));
}

/// An effect's value with its deviation, rounded to the deviation's second digit.
fn shown(e: &FoundEffect) -> String {
    let (v, d) = (components_of(&e.value), components_of(&e.std));
    let v: Vec<f64> = v.iter().map(|x| x.unwrap_or(f64::NAN)).collect();
    let d: Vec<f64> = (0..v.len())
        .map(|k| d.get(k).copied().flatten().unwrap_or(f64::NAN))
        .collect();
    super::analysis::with_deviation(&v, &d)
}

/// A kept effect's refitted value agrees with its value beside the withheld effects within this
/// many combined deviations (the GNSS evidence's agreement between positions and velocities).
const AGREE_SIGMAS: f64 = 3.0;

/// The largest distance of a component of `a`'s value from `b`'s, in their combined deviations
/// (infinite where a deviation is missing and the values differ).
fn apart(a: &FoundEffect, b: &FoundEffect) -> f64 {
    let (va, vb) = (components_of(&a.value), components_of(&b.value));
    let (sa, sb) = (components_of(&a.std), components_of(&b.std));
    (0..va.len().max(vb.len()))
        .map(|k| {
            let at = |v: &[Option<f64>]| v.get(k).copied().flatten();
            match (at(&va), at(&vb)) {
                (Some(x), Some(y)) if x == y => 0.0,
                (Some(x), Some(y)) => {
                    let combined = at(&sa)
                        .unwrap_or(f64::NAN)
                        .hypot(at(&sb).unwrap_or(f64::NAN));
                    if combined.is_finite() && combined > 0.0 {
                        (x - y).abs() / combined
                    } else {
                        f64::INFINITY
                    }
                }
                _ => f64::INFINITY,
            }
        })
        .fold(0.0, f64::max)
}

/// Whether the GNSS windows can see the effect as the other folds write it: some component
/// departs from nominal by at least one deviation of the position fit on all folds. A smaller
/// change (a time offset, which the windows see only where the speed changes) moves a fold's
/// window error by noise, and the fold does not judge it.
fn visible(params: &[FittedParam], e: &HeldOutEffect) -> bool {
    params.iter().any(|p| {
        let (effect, k) = super::gnss::effect_of(&p.name);
        let value = match &e.value {
            serde_json::Value::Array(v) => v.get(k).and_then(|x| x.as_f64()),
            v => v.as_f64().filter(|_| k == 0),
        };
        effect == e.name && value.is_some_and(|v| p.std.is_finite() && (v - p.start).abs() >= p.std)
    })
}

/// Distinguishes the folder of each call in one process (the benchmark runs trials in threads).
static NEXT: std::sync::atomic::AtomicUsize = std::sync::atomic::AtomicUsize::new(0);

fn failed(fold: String, error: String) -> WrittenHeldOut {
    WrittenHeldOut {
        fold,
        written: Vec::new(),
        score: None,
        error: Some(error),
    }
}

/// Effects of the velocity channel that the navigator configuration carries and the surface dead
/// reckoning applies (a moving bed is the river's, a periodic error the navigator does not
/// model, the beams' effects need the beams channel).
const WRITTEN: &[&str] = &[
    "dvl.mount_roll",
    "dvl.mount_pitch",
    "dvl.mount_yaw",
    "dvl.scale_factor",
    "dvl.sound_speed",
    "dvl.lever_arm",
    "dvl.time_offset",
    "heading.deviation",
];

/// The effects found that the navigator configuration writes for a surface run and that are not
/// withheld: the DVL's installation and the compass's deviation.
fn installation_effects(r: &DiscoverReport) -> impl Iterator<Item = &FoundEffect> {
    r.effects.iter().filter(|e| {
        WRITTEN.contains(&e.name.as_str()) && !r.withheld.iter().any(|w| w.name == e.name)
    })
}

/// The installation a model makes for the surface dead reckoning.
fn candidate(model: &Effects) -> Candidate {
    let (dvl, _) = navigator_tables(model, &[ChannelKind::Dvl], "");
    Candidate {
        dvl: dvl.unwrap_or_default(),
        compass_deviation_deg: model.heading_deviation,
    }
}

/// Discovery on every fold but `k` (a half of a log cut into a log of its own).
fn from_others(
    discover: &dyn Fn(Vec<PathBuf>) -> anyhow::Result<DiscoverReport>,
    specs: &[VoyageSpec],
    k: usize,
    dir: &Path,
) -> anyhow::Result<DiscoverReport> {
    let mut logs = Vec::new();
    for (j, s) in specs.iter().enumerate().filter(|(j, _)| *j != k) {
        match s.window_s {
            None => logs.push(s.path.clone()),
            Some(w) => {
                std::fs::create_dir_all(dir)
                    .with_context(|| format!("creating {}", dir.display()))?;
                let name = s
                    .path
                    .file_stem()
                    .map_or_else(|| "fold".into(), |n| n.to_string_lossy().into_owned());
                let out = dir.join(format!("{name}-fold{j}.mcap"));
                cut(&s.path, w, &out)?;
                logs.push(out);
            }
        }
    }
    discover(logs).context("discovering on the other folds")
}

/// Writes the messages of `log` within `window` (seconds from its first DVL, attitude or GNSS
/// message, the time base of the folds) into `out`; messages without a time are left out.
fn cut(log: &Path, window: (f64, f64), out: &Path) -> anyhow::Result<()> {
    let mut r = LogReader::open(log).with_context(|| format!("reading {}", log.display()))?;
    let header = r.read_header()?;
    let mut messages = Vec::new();
    while let Some(m) = r.next_message()? {
        messages.push(m);
    }
    let time = |m: &LogMessage| match m {
        LogMessage::Dvl(d) => Some(d.validity_time_ns),
        LogMessage::Attitude(x) => Some(x.host_time_ns),
        LogMessage::Gnss(x) => Some(x.host_time_ns),
        LogMessage::Truth(x) => Some(x.host_time_ns),
        other => other.sensor().map(|s| s.host_time_ns()),
    };
    let first = messages.iter().find_map(|m| match m.decode_any() {
        Ok(d @ (LogMessage::Dvl(_) | LogMessage::Attitude(_) | LogMessage::Gnss(_))) => time(&d),
        _ => None,
    });
    let Some(first) = first else {
        anyhow::bail!("{}: no DVL, attitude or GNSS message", log.display());
    };
    let inside = |t: u64| (window.0..=window.1).contains(&((t as f64 - first as f64) * 1e-9));
    write_log_atomically(out, &header, |w| {
        for m in &messages {
            if let Ok(d) = m.decode_any()
                && time(&d).is_some_and(inside)
            {
                w.write_raw(m)?;
            }
        }
        Ok(())
    })?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn effect(name: &str, value: f64, std: f64) -> FoundEffect {
        FoundEffect {
            name: name.into(),
            value: value.into(),
            std: std.into(),
            nominal: 0.0.into(),
            unit: String::new(),
            channel: ChannelKind::Dvl,
            evidence: String::new(),
            gain: 0.1,
            equivalent: None,
            line: None,
        }
    }

    fn report(effects: Vec<FoundEffect>) -> DiscoverReport {
        let mut r = DiscoverReport::new(&Effects::default());
        r.effects = effects;
        r
    }

    fn withheld_by_refit(r: &DiscoverReport) -> Vec<&str> {
        let f = r.refit.as_ref().expect("refitted");
        f.withheld.iter().map(|w| w.name.as_str()).collect()
    }

    #[test]
    fn what_moves_without_the_withheld_effect_or_stands_in_for_it_is_withheld_too() {
        let mut r = report(vec![
            effect("dvl.mount_yaw", 2.0, 0.2),
            effect("dvl.lever_arm", -0.2, 0.02),
            effect("dvl.time_offset", -0.13, 0.02),
            effect("dvl.mount_pitch", 0.5, 0.05),
        ]);
        r.withheld.push(Withheld {
            name: "dvl.lever_arm".into(),
            note: String::new(),
        });
        let asked = std::cell::RefCell::new(Vec::new());
        let again = |without: Vec<String>| {
            asked.borrow_mut().push(without);
            let mut a = report(vec![
                // Within its deviations: written as refitted.
                effect("dvl.mount_yaw", 2.1, 0.2),
                // 0.17 s away, 6 combined deviations: not determined apart from the lever arm.
                effect("dvl.time_offset", -0.30, 0.02),
                // Named only without the lever arm.
                effect("dvl.scale_factor", 1.01, 0.001),
            ]);
            a.model.set("dvl.mount_yaw", &[2.1]).expect("an effect");
            // As if the refit's GNSS decision named the withheld effect again.
            a.model
                .set("dvl.lever_arm", &[-0.2, -0.2, 0.0])
                .expect("an effect");
            Ok(a)
        };
        refit(&mut r, &again);
        assert_eq!(asked.into_inner(), vec![vec!["dvl.lever_arm".to_string()]]);
        let mut withheld = withheld_by_refit(&r);
        withheld.sort_unstable();
        assert_eq!(
            withheld,
            ["dvl.mount_pitch", "dvl.scale_factor", "dvl.time_offset"]
        );
        let written = super::super::outputs::written_model(&r);
        assert_eq!(written.get("dvl.mount_yaw"), Some(vec![2.1]));
        assert_eq!(written.get("dvl.lever_arm"), Some(vec![0.0; 3]));
    }

    #[test]
    fn nothing_withheld_nothing_refitted() {
        let mut r = report(vec![effect("dvl.mount_yaw", 2.0, 0.2)]);
        refit(&mut r, &|_| panic!("no refit without a withheld effect"));
        assert!(r.refit.is_none());
    }

    #[test]
    fn apart_is_the_largest_component_distance_in_combined_deviations() {
        let mut a = effect("dvl.lever_arm", 0.0, 0.0);
        a.value = serde_json::json!([0.0, 1.0]);
        a.std = serde_json::json!([0.3, 0.3]);
        let mut b = a.clone();
        b.value = serde_json::json!([0.0, 0.0]);
        b.std = serde_json::json!([0.3, 0.4]);
        assert!((apart(&a, &b) - 2.0).abs() < 1e-12);
        b.std = serde_json::json!([0.3, null]);
        assert_eq!(apart(&a, &b), f64::INFINITY);
    }
}
