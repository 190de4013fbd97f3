//! The gain measured where it matters: each log replayed through the navigator with the nominal
//! installation and with the effects found (held out), and the effects the navigator
//! configuration carries: where the held-out navigation of some log gets worse with every effect
//! found, `--write-config` writes the largest set of them with which no log does, so that the
//! effects that do not hurt are still written.

use super::ChannelKind;
use super::findings::{DiscoverReport, NavigationGain, Withheld};
use super::outputs::{analysed, at_nominal, navigator_depth_lever_arm, navigator_tables};
use anyhow::Context;
use auvnav_core::aid::magnetometer::MagnetometerConfig;
use auvnav_replay::accuracy::Accuracy;
use auvnav_replay::{Replay, ReplayConfig, ReplayOptions};
use auvnav_sim::effects::{Effects, SPECS};
use std::path::{Path, PathBuf};

/// A log's navigation replayed with one configuration: its accuracy, the DVL readings fused
/// and refused.
type Run = (Accuracy, u64, u64);

/// One log's replay inputs: the log, its base configuration and where that came from, and the
/// lever arm its reference is moved to the IMU by.
struct LogReplay {
    log: PathBuf,
    base: ReplayConfig,
    source: String,
    options: ReplayOptions,
    reference_lever_arm: Option<[f64; 3]>,
}

impl LogReplay {
    fn new(log: &Path, reference_lever_arm: Option<[f64; 3]>) -> anyhow::Result<LogReplay> {
        let options = ReplayOptions::new(log);
        let (base, source) = auvnav_replay::replay_config(&options)?;
        Ok(LogReplay {
            log: log.to_path_buf(),
            base,
            source,
            options,
            reference_lever_arm,
        })
    }

    /// The log's configuration with the navigator tables of the effects `e`.
    fn config(&self, e: &Effects, kinds: &[ChannelKind]) -> ReplayConfig {
        let mut cfg = self.base.clone();
        let (dvl, mag) = navigator_tables(e, kinds, "auvnav discover");
        if let Some(d) = dvl {
            cfg.navigation.set_dvl_installation(d);
        }
        if let Some(l) = navigator_depth_lever_arm(e, kinds) {
            cfg.navigation.depth_lever_arm_m = l;
        }
        // The magnetometer aid is only recalibrated where the configuration uses it.
        if let (Some(m), Some(old)) = (mag, cfg.navigation.magnetometer.as_ref()) {
            cfg.navigation.magnetometer = Some(MagnetometerConfig {
                heading_std_deg: old.heading_std_deg,
                gate_chi2: old.gate_chi2,
                field_tolerance: old.field_tolerance,
                min_interval_s: old.min_interval_s,
                ..m
            });
        }
        cfg
    }

    /// The log replayed with the effects `e`; None without IMU samples or reference epochs.
    fn run(&self, e: &Effects, kinds: &[ChannelKind]) -> anyhow::Result<Option<Run>> {
        let mut replay = Replay::new(&self.config(e, kinds), self.options.min_distance);
        if let Some(l) = self.reference_lever_arm {
            replay.set_reference_lever_arm(l);
        }
        auvnav_replay::run_log(&self.log, &mut replay, &mut |_| Ok(()))
            .with_context(|| format!("replaying {}", self.log.display()))?;
        if replay.counts.imu == 0 {
            return Ok(None);
        }
        let c = replay.nav_counters();
        Ok(replay
            .accuracy()
            .filter(|a| a.epochs > 0)
            .map(|a| (a, c.dvl_fused, c.dvl_rejected)))
    }

    fn gain(&self, before: &Run, after: &Run) -> NavigationGain {
        let (worse, verdict) = NavigationGain::judge(&before.0, &after.0);
        NavigationGain {
            worse,
            verdict,
            log: self.log.display().to_string(),
            configuration: self.source.clone(),
            before: before.0.clone(),
            after: after.0.clone(),
            dvl_fused_before: before.1,
            dvl_rejected_before: before.2,
            dvl_fused_after: after.1,
            dvl_rejected_after: after.2,
            reference_lever_arm_m: self.reference_lever_arm,
        }
    }
}

/// Replays each log with an IMU and a reference twice: with the navigator tables of the nominal
/// effects and with those of the effects found, held out (several voyages: fitted on the other
/// voyages; one voyage: on the first part of each channel); the rest of the configuration is
/// what `auvnav replay LOG` would use. Logs without an IMU or a reference are skipped with a
/// note. Where the navigation of some log gets worse, effects are withheld until none does
/// ([`withhold`]) and each log's navigation with the rest is given as `navigation_written`.
pub fn navigation_gain(logs: &[PathBuf], r: &mut DiscoverReport) {
    let kinds = analysed(r);
    if !kinds.contains(&ChannelKind::Dvl) && !kinds.contains(&ChannelKind::Magnetometer) {
        return;
    }
    let shared_lever_arm = reference_lever_arm(r);
    if let Some(l) = shared_lever_arm {
        r.notes.push(format!(
            "navigation scored at the IMU: the logs' reference moved by ({:.2}, {:.2}, {:.2}) m \
             (body axes), where the logs found it against their smoothed motion (combined over \
             the logs)",
            l[0], l[1], l[2]
        ));
    }
    // Each compared log: its replay, the effects it is replayed with, its nominal run.
    let mut compared: Vec<(LogReplay, Effects, Run)> = Vec::new();
    for (i, log) in logs.iter().enumerate() {
        // Several voyages: each is replayed with the installation fitted on the others (held
        // out); one voyage: with the effects fitted on the first part of each channel.
        let after = match &r.voyages {
            Some(v) => v.held_out_models.get(i).unwrap_or(&r.model),
            None => &r.held_out_model,
        };
        let lever_arm = shared_lever_arm.or_else(|| own_reference_lever_arm(r, log));
        let compared_log = LogReplay::new(log, lever_arm).and_then(|l| {
            let before = l.run(&r.nominal_model, &kinds)?;
            let after_run = l.run(after, &kinds)?;
            Ok(before.zip(after_run).map(|(b, a)| (l, b, a)))
        });
        match compared_log {
            Ok(Some((l, before, after_run))) => {
                let g = l.gain(&before, &after_run);
                if g.worse {
                    r.notes.push(worse_note(r, &g));
                }
                r.navigation.push(g);
                compared.push((l, after.clone(), before));
            }
            Ok(None) if r.gnss.is_some() => r.notes.push(format!(
                "{}: a surface run: its navigation is judged by dead reckoning against its GNSS \
                 positions (the GNSS evidence)",
                log.display()
            )),
            Ok(None) => r.notes.push(format!(
                "{}: no IMU or no reference: navigation error not compared",
                log.display()
            )),
            Err(e) => r.notes.push(format!(
                "{}: navigation replay failed: {e:#}",
                log.display()
            )),
        }
    }
    if r.navigation.iter().any(|g| g.worse) {
        withhold_worsening(r, &compared, &kinds);
    }
}

/// The note on a log whose navigation the effects found make worse.
fn worse_note(r: &DiscoverReport, g: &NavigationGain) -> String {
    let why = if r.reference == "smoothed" {
        "they describe the sensors against the IMU's own (smoothed) motion, yet the navigation \
         does not gain from them on this log (its error is taken against the log's reference, \
         moved to the IMU where its lever arm was found)"
    } else {
        "they describe the sensors against the reference, and the reference is not the IMU's \
         motion (its velocity at another point or time; compare with --reference smoothed)"
    };
    format!(
        "{}: the navigation gets {} with the effects found: {why}. Check against the \
         navigator's own estimates (estimate_dvl_* in [navigation]) before using \
         navigation.toml",
        g.log, g.verdict
    )
}

/// The effects found that change the navigator configuration of some log (an effect the
/// navigator does not take, e.g. an IMU scale factor, is not one).
fn navigator_effects(
    nominal: &Effects,
    models: &[&Effects],
    kinds: &[ChannelKind],
) -> Vec<&'static str> {
    let tables = |e: &Effects| {
        format!(
            "{:?}",
            (
                navigator_tables(e, kinds, ""),
                navigator_depth_lever_arm(e, kinds)
            )
        )
    };
    SPECS
        .iter()
        .map(|s| s.name)
        .filter(|name| {
            models.iter().any(|m| {
                let Some(v) = nominal.get(name) else {
                    return false;
                };
                let mut reset = (*m).clone();
                reset.set(name, &v).is_ok() && tables(&reset) != tables(m)
            })
        })
        .collect()
}

/// How one log's navigation with a set of effects compares with the nominal one.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Judged {
    pub worse: bool,
    /// How much worse: the sum of the log ratios of the position and velocity RMS that grew.
    pub excess: f64,
}

impl Judged {
    fn of(before: &Accuracy, after: &Accuracy) -> Judged {
        let grown = |b: f64, a: f64| {
            if b > 0.0 && a > b { (a / b).ln() } else { 0.0 }
        };
        Judged {
            worse: NavigationGain::judge(before, after).0,
            excess: grown(before.horizontal_error_rms_m, after.horizontal_error_rms_m)
                + grown(
                    before.horizontal_velocity_error_rms_m_s,
                    after.horizontal_velocity_error_rms_m_s,
                ),
        }
    }
}

/// An effect [`withhold`] leaves out, and the logs that navigate worse than the nominal
/// installation when it is added to the effects kept.
#[derive(Debug, Clone, PartialEq)]
pub struct Left<'a> {
    pub name: &'a str,
    pub worse_with: Vec<usize>,
}

/// Up to this many effects every subset is tried; beyond, backward elimination.
const EXHAUSTIVE_MAX: usize = 6;

/// The largest set of the effects `names` with which no log navigates worse than with the
/// nominal installation (among sets of that size, the one whose navigation grows least), and
/// for each effect left out, the logs that navigate worse when it is added back. `full` judges
/// every log with all the effects (already replayed); `judge(set)` replays every log with the
/// effects `set` and judges each against its nominal run. With up
/// to [`EXHAUSTIVE_MAX`] effects every subset is tried, largest first; with more, the effects
/// are taken out one at a time, each time the one whose removal leaves the fewest logs worse
/// (then the least excess). An empty set is the nominal installation.
pub fn withhold<'a>(
    names: &[&'a str],
    full: Vec<Judged>,
    mut judge: impl FnMut(&[&'a str]) -> Vec<Judged>,
) -> (Vec<&'a str>, Vec<Left<'a>>) {
    let mut seen: std::collections::HashMap<Vec<&'a str>, Vec<Judged>> =
        std::iter::once((names.to_vec(), full)).collect();
    let mut judged = |set: &[&'a str]| -> Vec<Judged> {
        seen.entry(set.to_vec())
            .or_insert_with(|| judge(set))
            .clone()
    };
    let score = |j: &[Judged]| {
        (
            j.iter().filter(|x| x.worse).count(),
            j.iter().map(|x| x.excess).sum::<f64>(),
        )
    };
    let better = |a: (usize, f64), b: (usize, f64)| a.0 < b.0 || (a.0 == b.0 && a.1 < b.1);
    let subset = |mask: usize| -> Vec<&'a str> {
        (0..names.len())
            .filter(|i| mask & (1 << i) != 0)
            .map(|i| names[i])
            .collect()
    };
    let kept: Vec<&'a str> = if names.len() <= EXHAUSTIVE_MAX {
        let mut found = None;
        for size in (1..=names.len()).rev() {
            let mut best: Option<(Vec<&'a str>, (usize, f64))> = None;
            for mask in (0..1usize << names.len()).filter(|m| m.count_ones() as usize == size) {
                let set = subset(mask);
                let sc = score(&judged(&set));
                if sc.0 == 0 && best.as_ref().is_none_or(|(_, b)| better(sc, *b)) {
                    best = Some((set, sc));
                }
            }
            if let Some((set, _)) = best {
                found = Some(set);
                break;
            }
        }
        found.unwrap_or_default()
    } else {
        let mut kept = names.to_vec();
        while !kept.is_empty() && score(&judged(&kept)).0 > 0 {
            let mut best: Option<(usize, (usize, f64))> = None;
            for i in 0..kept.len() {
                let mut without = kept.clone();
                without.remove(i);
                let sc = score(&judged(&without));
                if best.as_ref().is_none_or(|(_, b)| better(sc, *b)) {
                    best = Some((i, sc));
                }
            }
            let Some((i, _)) = best else { break };
            kept.remove(i);
        }
        kept
    };
    let left = names
        .iter()
        .filter(|n| !kept.contains(n))
        .map(|&name| {
            let with: Vec<&'a str> = names
                .iter()
                .copied()
                .filter(|n| *n == name || kept.contains(n))
                .collect();
            let j = judged(&with);
            Left {
                name,
                worse_with: (0..j.len()).filter(|&k| j[k].worse).collect(),
            }
        })
        .collect();
    (kept, left)
}

/// Withholds the effects with which some compared log navigates worse ([`withhold`]),
/// replaying the logs in parallel; records what is withheld and why in
/// `r.withheld`, and each log's navigation with the rest in `r.navigation_written` (when
/// something is left).
fn withhold_worsening(
    r: &mut DiscoverReport,
    compared: &[(LogReplay, Effects, Run)],
    kinds: &[ChannelKind],
) {
    let models: Vec<&Effects> = compared.iter().map(|(_, m, _)| m).collect();
    let names = navigator_effects(&r.nominal_model, &models, kinds);
    let nominal = r.nominal_model.clone();
    let replay_all = |kept: &[&str]| -> Vec<Option<Run>> {
        let threads = std::thread::available_parallelism().map_or(1, |n| n.get());
        let chunk = compared.len().div_ceil(threads).max(1);
        let left: Vec<&str> = names
            .iter()
            .copied()
            .filter(|n| !kept.contains(n))
            .collect();
        std::thread::scope(|s| {
            let handles: Vec<_> = compared
                .chunks(chunk)
                .map(|part| {
                    let (left, nominal) = (&left, &nominal);
                    s.spawn(move || {
                        part.iter()
                            .map(|(l, m, _)| {
                                l.run(&at_nominal(m, nominal, left), kinds).ok().flatten()
                            })
                            .collect::<Vec<_>>()
                    })
                })
                .collect();
            handles
                .into_iter()
                .flat_map(|h| h.join().unwrap_or_default())
                .collect()
        })
    };
    let judged = |runs: &[Option<Run>]| -> Vec<Judged> {
        compared
            .iter()
            .zip(runs)
            .map(|((_, _, before), run)| match run {
                Some(a) => Judged::of(&before.0, &a.0),
                // A replay that failed with these effects counts as worse.
                None => Judged {
                    worse: true,
                    excess: f64::INFINITY,
                },
            })
            .collect()
    };
    // With every effect found, each log is already judged.
    let full = r
        .navigation
        .iter()
        .map(|g| Judged::of(&g.before, &g.after))
        .collect();
    // The runs of every set replayed, so that the set kept is not replayed again.
    let mut runs_of: std::collections::HashMap<Vec<&str>, Vec<Option<Run>>> = Default::default();
    let (kept, left) = withhold(&names, full, |kept| {
        let runs = replay_all(kept);
        let j = judged(&runs);
        runs_of.insert(kept.to_vec(), runs);
        j
    });
    for s in &left {
        let logs: Vec<&str> = s
            .worse_with
            .iter()
            .filter_map(|&k| compared.get(k).and_then(|(l, _, _)| l.log.to_str()))
            .collect();
        r.withheld.push(Withheld {
            name: s.name.into(),
            note: if logs.is_empty() {
                "taken out by the elimination (more effects than every subset is tried for); \
                 added back alone to the effects kept it leaves no log worse"
                    .into()
            } else {
                format!(
                    "added to the effects kept, the held-out navigation is worse than with the \
                     nominal installation on {}",
                    logs.join(", ")
                )
            },
        });
    }
    if kept.is_empty() {
        return;
    }
    let runs = runs_of.remove(&kept).unwrap_or_else(|| replay_all(&kept));
    for ((l, _, before), run) in compared.iter().zip(&runs) {
        if let Some(after) = run {
            r.navigation_written.push(l.gain(before, after));
        }
    }
}

/// A log's reference lever arm (value, one sigma) as `--reference smoothed` found it: its
/// velocity read as a DVL on the vehicle against the smoothed motion.
fn lever_arm_of(found: &super::findings::ReferenceAgainstImu) -> Option<([f64; 3], [f64; 3])> {
    let (_, value, std) = found
        .effects
        .iter()
        .find(|(n, _, _)| n == "dvl.lever_arm")?;
    let v = <[f64; 3]>::try_from(super::findings::values_of(value)?).ok()?;
    let s = <[f64; 3]>::try_from(super::findings::values_of(std)?).ok()?;
    Some((v, s))
}

/// Where the log's own reference sits from the IMU, when `--reference smoothed` found it.
fn own_reference_lever_arm(r: &DiscoverReport, log: &Path) -> Option<[f64; 3]> {
    let name = log.display().to_string();
    let found = r.reference_against_imu.iter().find(|x| x.log == name)?;
    lever_arm_of(found).map(|(v, _)| v)
}

/// Where the reference sits from the IMU, combined over the logs that found it (the reference
/// is the vehicle's: one point for every voyage): each component the information-weighted mean
/// of the logs' estimates. None with fewer than two logs' estimates.
fn reference_lever_arm(r: &DiscoverReport) -> Option<[f64; 3]> {
    let found: Vec<([f64; 3], [f64; 3])> = r
        .reference_against_imu
        .iter()
        .filter_map(lever_arm_of)
        .filter(|(v, s)| v.iter().chain(s).all(|x| x.is_finite()) && s.iter().all(|x| *x > 0.0))
        .collect();
    if found.len() < 2 {
        return None;
    }
    Some(std::array::from_fn(|i| {
        let w: f64 = found.iter().map(|(_, s)| s[i].powi(-2)).sum();
        found.iter().map(|(v, s)| v[i] * s[i].powi(-2)).sum::<f64>() / w
    }))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// [`withhold`] with the full set judged by `judge` itself.
    fn search<'a>(
        names: &[&'a str],
        mut judge: impl FnMut(&[&'a str]) -> Vec<Judged>,
    ) -> (Vec<&'a str>, Vec<Left<'a>>) {
        let full = judge(names);
        withhold(names, full, judge)
    }

    fn judged(worse: &[bool]) -> Vec<Judged> {
        worse
            .iter()
            .map(|&w| Judged {
                worse: w,
                excess: if w { 0.5 } else { 0.0 },
            })
            .collect()
    }

    #[test]
    fn the_effect_that_makes_a_log_worse_is_withheld_and_the_rest_kept() {
        // Three logs; "b" makes the second worse, the others help every log.
        let (kept, left) = search(&["a", "b", "c"], |set| {
            judged(&[false, set.contains(&"b"), false])
        });
        assert_eq!(kept, vec!["a", "c"]);
        assert_eq!(
            left,
            vec![Left {
                name: "b",
                worse_with: vec![1]
            }]
        );
    }

    #[test]
    fn the_largest_set_that_hurts_no_log_is_kept() {
        // "a" and "b" together hurt log 0, "c" hurts log 2: the sets that hurt no log are
        // {a} and {b}; c is left out, and with it added log 2 is worse.
        let (kept, left) = search(&["a", "b", "c"], |set| {
            judged(&[
                set.contains(&"a") && set.contains(&"b"),
                false,
                set.contains(&"c"),
            ])
        });
        assert_eq!(kept.len(), 1);
        assert!(!kept.contains(&"c"), "{kept:?}");
        let c = left.iter().find(|l| l.name == "c").expect("c left out");
        assert_eq!(c.worse_with, vec![2]);
        // With a fourth effect that hurts nothing, the largest such sets are {a, d} and {b, d}.
        let (kept, _) = search(&["a", "b", "c", "d"], |set| {
            judged(&[
                set.contains(&"a") && set.contains(&"b"),
                false,
                set.contains(&"c"),
            ])
        });
        assert_eq!(kept.len(), 2);
        assert!(kept.contains(&"d"), "{kept:?}");
        // Nothing hurts: nothing withheld, nothing replayed beyond the full set.
        let mut calls = 0;
        let (kept, left) = withhold(&["a", "b"], judged(&[false, false]), |_| {
            calls += 1;
            judged(&[false, false])
        });
        assert_eq!((kept, left.len(), calls), (vec!["a", "b"], 0, 0));
        // Every set hurts: all are withheld, the nominal installation is what is left.
        let (kept, left) = search(&["a", "b"], |set| judged(&[!set.is_empty()]));
        assert!(kept.is_empty());
        assert_eq!(left.len(), 2);
    }

    #[test]
    fn beyond_the_exhaustive_size_effects_are_taken_out_one_at_a_time() {
        let names = ["a", "b", "c", "d", "e", "f", "g", "h"];
        let mut calls = 0;
        let (kept, left) = withhold(&names, judged(&[true, true]), |set| {
            calls += 1;
            judged(&[set.contains(&"c"), set.contains(&"f")])
        });
        assert_eq!(kept, vec!["a", "b", "d", "e", "g", "h"]);
        assert_eq!(left.len(), 2);
        // Two rounds of eight and seven removals; far below 2⁸ subsets.
        assert!(calls <= 8 + 7, "{calls}");
    }
}
