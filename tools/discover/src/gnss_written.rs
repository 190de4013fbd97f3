//! What `--write-config` writes, held out against the GNSS positions.
//!
//! On surface runs split into folds (each log, or one log's two halves), each fold is navigated
//! with the navigator configuration that the whole of discovery — the velocities' selection, the
//! GNSS decision, the navigation check that withholds — writes from the other folds alone, and
//! scored against its GNSS over the same windows as the nominal and the two-point installations
//! of the GNSS evidence. The position fit's own held-out figures judge only what the positions
//! name; this judges the calibration a user would deploy, on a run it has not seen.

use super::ChannelKind;
use super::findings::{DiscoverReport, FoundEffect, Withheld};
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
