//! Surface runs (a compass, a DVL and GNSS throughout, no IMU): the GNSS positions as the
//! evidence that decides the DVL installation.
//!
//! The velocities against the GPS velocity see a boat ADCP's installation through a residual
//! that stays correlated for tens of seconds (a moving bed, the compass's own slow error), and
//! a coloured residual can fake an effect of one voyage. The GNSS positions do not come from the
//! DVL: the run is dead-reckoned from the compass and the DVL through a candidate installation
//! and compared with the GNSS displacement over S-CAL's windows of at least a threshold distance
//! (`auvnav_calibrate::surface`, deviations widened by the windows' overlap). The run is split
//! into folds — each log when there are several, else two halves of equal GNSS track length —
//! and an installation parameter is **named** when
//! 1. on all folds it stands five deviations from nominal,
//! 2. every fold held out navigates no worse against its GNSS with what the other folds write,
//!    and at least one fold's others write it, and
//! 3. the velocities' own estimate (named or undetermined) agrees with it within three combined
//!    deviations.
//!
//! Otherwise it is reported as pointed at but not determined (with what would settle it),
//! consistent with nominal, not excited, or below the floor, in the position fit's words. The
//! velocity-domain significance stays beside it as the second figure.

use super::ChannelKind;
use super::analysis::json_of;
use super::findings::{DiscoverReport, FoundEffect};
pub use super::gnss_evidence::{GnssDecision, GnssEvidence};
use auvnav_calibrate::surface::{self, Candidate, FittedParam, HeldOut, ScoreSet};
use auvnav_calibrate::voyage::VoyageSpec;
use auvnav_replay::surface::{SurfaceRun, read_surface_run};
use std::path::PathBuf;

/// Fold widths below this many metres of GNSS track make the windows mostly GNSS noise.
const MIN_THRESHOLD_M: f64 = 20.0;
/// S-CAL's own window distance: no run needs longer windows.
const MAX_THRESHOLD_M: f64 = 5000.0;
/// Windows a quarter of a fold's track: each fold scores several independent stretches.
const THRESHOLD_SHARE: f64 = 0.25;
/// Combined deviations within which the velocities' estimate agrees with the positions'.
const AGREE_SIGMAS: f64 = 3.0;

/// The vocabulary effect of a position-fit parameter and the component it is.
pub(crate) fn effect_of(parameter: &str) -> (&str, usize) {
    match parameter {
        "dvl.lever_arm.x" => ("dvl.lever_arm", 0),
        "dvl.lever_arm.y" => ("dvl.lever_arm", 1),
        p => match p.strip_prefix("heading.deviation.") {
            // The card's B, C, D, E follow its constant A in the effect's values.
            Some(c) => ("heading.deviation", 1 + "bcde".find(c).unwrap_or(0)),
            None => (p, 0),
        },
    }
}

/// GNSS track length (m) over fixes at least a second apart where the DVL has a reading within
/// a second and a half (only there can a window be scored), and the time at which half of it is
/// covered.
fn track(run: &SurfaceRun) -> (f64, f64) {
    let dvl_near = |t: f64| {
        let i = run.dvl.partition_point(|d| d.t_s < t);
        [i.checked_sub(1), Some(i)]
            .into_iter()
            .flatten()
            .filter_map(|j| run.dvl.get(j))
            .any(|d| (d.t_s - t).abs() <= 1.5)
    };
    let mut along: Vec<(f64, f64)> = Vec::new();
    let mut last: Option<(f64, f64, f64)> = None;
    let mut total = 0.0;
    for &f in &run.fixes {
        match last {
            None => last = Some(f),
            Some(p) if f.0 - p.0 >= 1.0 => {
                if dvl_near(p.0) && dvl_near(f.0) {
                    total += (f.1 - p.1).hypot(f.2 - p.2);
                }
                along.push((f.0, total));
                last = Some(f);
            }
            Some(_) => {}
        }
    }
    let middle = along
        .iter()
        .find(|a| a.1 >= 0.5 * total)
        .map_or(0.0, |a| a.0);
    (total, middle)
}

/// The folds of the logs and the windows' threshold: each log a fold, or one log's two halves.
fn folds(logs: &[PathBuf], threshold_m: Option<f64>) -> Result<(Vec<VoyageSpec>, f64), String> {
    let mut specs = Vec::new();
    let mut shortest = f64::INFINITY;
    for log in logs {
        let name = log.display().to_string();
        let run = read_surface_run(log, &name, None).map_err(|e| e.to_string())?;
        let (total, middle) = track(&run);
        if logs.len() == 1 {
            // Boundaries to a tenth of a second: the folds' names stay readable.
            let middle = (10.0 * middle).round() / 10.0;
            let end = (run.fixes.last().map_or(0.0, |f| f.0) + 1.0).ceil();
            for w in [(0.0, middle), (middle, end)] {
                specs.push(VoyageSpec {
                    path: log.clone(),
                    window_s: Some(w),
                });
            }
            shortest = 0.5 * total;
        } else {
            specs.push(VoyageSpec {
                path: log.clone(),
                window_s: None,
            });
            shortest = shortest.min(total);
        }
    }
    let threshold =
        threshold_m.unwrap_or((THRESHOLD_SHARE * shortest).clamp(MIN_THRESHOLD_M, MAX_THRESHOLD_M));
    Ok((specs, threshold))
}

/// The starting installation: the nominal model's.
fn nominal_candidate(r: &DiscoverReport) -> Candidate {
    let (dvl, _) = super::outputs::navigator_tables(&r.nominal_model, &[ChannelKind::Dvl], "");
    Candidate {
        dvl: dvl.unwrap_or_default(),
        compass_deviation_deg: r.nominal_model.heading_deviation,
    }
}

/// Whether every log is a surface run (`None` if some cannot be read).
pub fn all_surface_runs(logs: &[PathBuf]) -> Option<bool> {
    let mut all = true;
    for log in logs {
        all &= surface::is_surface_run(log).ok()?;
    }
    Some(all)
}

/// Decides the DVL installation of surface runs on their GNSS positions and updates the report:
/// what the positions name joins the effects found (and leaves the undetermined and the floors),
/// the evidence is kept in `r.gnss`.
pub fn decide(
    logs: &[PathBuf],
    threshold_m: Option<f64>,
    moving_bed: bool,
    r: &mut DiscoverReport,
) {
    let (specs, threshold) = match folds(logs, threshold_m) {
        Ok(x) => x,
        Err(e) => {
            r.notes.push(format!("GNSS positions not used: {e}"));
            return;
        }
    };
    let start = nominal_candidate(r);
    let fit = match surface::calibrate_surface(&specs, &start, &[], threshold, moving_bed) {
        Ok(f) => f,
        Err(e) => {
            r.notes.push(format!("GNSS positions not used: {e}"));
            return;
        }
    };
    let velocity_named: Vec<String> = r.effects.iter().map(|e| e.name.clone()).collect();
    let mut decisions = Vec::new();
    for p in &fit.params {
        let d = decision(p, &fit.held_out, r);
        if d.verdict == "named" {
            name(
                p,
                &d.note,
                held_out_gain(p, &fit.held_out),
                &velocity_named,
                r,
            );
        }
        decisions.push(d);
    }
    r.gnss = Some(Box::new(GnssEvidence {
        folds: fit.runs,
        fold_specs: specs,
        threshold_m: threshold,
        moving_bed,
        params: fit.params,
        in_sample: fit.in_sample,
        held_out: fit.held_out,
        decisions,
        written_held_out: Vec::new(),
    }));
}

/// The relative drop of the held-out window errors' mean square over the folds whose others
/// write `p`.
fn held_out_gain(p: &FittedParam, held_out: &[HeldOut]) -> f64 {
    let (mut before, mut after) = (0.0, 0.0);
    for h in held_out.iter().filter(|h| h.written.contains(&p.name)) {
        let n = h.scores.nominal.windows as f64;
        before += n * h.scores.nominal.rms_error_m.powi(2);
        after += n * h.scores.calibrated.rms_error_m.powi(2);
    }
    if before > 0.0 {
        1.0 - after / before
    } else {
        0.0
    }
}

/// The velocities' estimate of one component of `effect` (named or undetermined): value and
/// deviation.
fn velocity_estimate(r: &DiscoverReport, effect: &str, k: usize) -> Option<(f64, f64)> {
    let pick = |v: &serde_json::Value| match v {
        serde_json::Value::Array(a) => a.get(k).and_then(|x| x.as_f64()),
        x => x.as_f64(),
    };
    let found = r
        .effects
        .iter()
        .find(|e| e.name == effect)
        .map(|e| (&e.value, &e.std));
    let pointed = r
        .undetermined
        .iter()
        .find(|u| u.name == effect)
        .map(|u| (&u.value, &u.std));
    let (v, s) = found.or(pointed)?;
    Some((pick(v)?, pick(s)?))
}

fn decision(p: &FittedParam, held_out: &[HeldOut], r: &DiscoverReport) -> GnssDecision {
    let (effect, k) = effect_of(&p.name);
    let sigmas = (p.estimate - p.start).abs() / p.std;
    let verdict = |v: &str, note: String| GnssDecision {
        parameter: p.name.clone(),
        effect: effect.into(),
        verdict: v.into(),
        note,
    };
    if !p.written {
        let v = if p.verdict.starts_with("not excited") {
            "not excited"
        } else if p.verdict.starts_with("consistent") {
            "consistent with nominal"
        } else {
            "not determined"
        };
        // The position fit's own wording without the verdict it starts with and the "not
        // written" it ends with (the decision says both).
        let why = [
            "not determined: ",
            "not excited: ",
            "consistent with its starting value ",
        ]
        .iter()
        .find_map(|x| p.verdict.strip_prefix(x))
        .unwrap_or(&p.verdict);
        return verdict(v, why.trim_end_matches(": not written").to_string());
    }
    let writing: Vec<&HeldOut> = held_out
        .iter()
        .filter(|h| h.written.contains(&p.name))
        .collect();
    let worse: Vec<&HeldOut> = writing
        .iter()
        .copied()
        .filter(|h| h.scores.calibrated.rms_error_m > h.scores.nominal.rms_error_m)
        .collect();
    let held = |h: &HeldOut| {
        format!(
            "{} {:.2} → {:.2} m",
            h.run, h.scores.nominal.rms_error_m, h.scores.calibrated.rms_error_m
        )
    };
    let held_text = writing
        .iter()
        .map(|h| held(h))
        .collect::<Vec<_>>()
        .join(", ");
    if writing.is_empty() {
        return verdict(
            "not determined",
            format!(
                "{:.4} ± {:.4} {} from the GNSS positions ({sigmas:.1}σ on all folds), but no fold alone \
                 determines it, so no held-out fold can confirm it: a longer run or a second run would \
                 settle it",
                p.estimate, p.std, p.unit
            ),
        );
    }
    if !worse.is_empty() {
        return verdict(
            "not determined",
            format!(
                "{:.4} ± {:.4} {} from the GNSS positions ({sigmas:.1}σ), but held out the folds \
                 navigate worse with what the others write (window RMS {held_text}): these runs \
                 point at it without determining it",
                p.estimate, p.std, p.unit
            ),
        );
    }
    let velocities = velocity_estimate(r, effect, k);
    if let Some((v, s)) = velocities {
        let combined = p.std.hypot(s);
        if (v - p.estimate).abs() > AGREE_SIGMAS * combined {
            return verdict(
                "disagrees",
                format!(
                    "{:.4} ± {:.4} {} from the GNSS positions ({sigmas:.1}σ) but {v:.4} ± {s:.4} from \
                     the velocities: more than {AGREE_SIGMAS} combined deviations apart, so one of \
                     the two references carries an error the model lacks (not named)",
                    p.estimate, p.std, p.unit
                ),
            );
        }
    }
    let agreement = match velocities {
        Some((v, s)) => format!("; the velocities' {v:.4} ± {s:.4} agrees"),
        None => String::new(),
    };
    verdict(
        "named",
        format!(
            "GNSS positions ({} folds): {:.4} ± {:.4} {}, {sigmas:.1}σ from nominal; held out, \
             window RMS {held_text}{agreement}",
            held_out.len(),
            p.estimate,
            p.std,
            p.unit
        ),
    )
}

/// Puts a parameter the positions name into the report. An effect the velocities named keeps
/// their (finer) estimate and gains the positions' confirmation in its evidence; otherwise the
/// positions' estimate goes into the model (all readings and the held-out fit alike) and among
/// the effects found, and the effect leaves the undetermined and the floors.
fn name(
    p: &FittedParam,
    evidence: &str,
    gain: f64,
    velocity_named: &[String],
    r: &mut DiscoverReport,
) {
    let (effect, k) = effect_of(&p.name);
    if velocity_named.iter().any(|n| n == effect)
        && let Some(e) = r.effects.iter_mut().find(|e| e.name == effect)
    {
        e.evidence = format!("{}; confirmed by {}: {evidence}", e.evidence, p.name);
        return;
    }
    let Some(nominal) = r.nominal_model.get(effect) else {
        return;
    };
    for model in [&mut r.model, &mut r.held_out_model] {
        let mut values = model.get(effect).unwrap_or_else(|| nominal.clone());
        values[k] = p.estimate;
        let _ = model.set(effect, &values);
    }
    r.undetermined.retain(|u| u.name != effect);
    r.floors.retain(|f| f.name != effect);
    let mut value = nominal.clone();
    value[k] = p.estimate;
    // Components the positions do not estimate have no deviation (null in the report).
    let mut std = vec![f64::NAN; nominal.len()];
    std[k] = p.std;
    // A second component of the same effect (the lever arm's y after its x) joins the first.
    if let Some(e) = r.effects.iter_mut().find(|e| e.name == effect) {
        if let (serde_json::Value::Array(v), serde_json::Value::Array(s)) =
            (&mut e.value, &mut e.std)
        {
            v[k] = serde_json::json!(p.estimate);
            s[k] = serde_json::json!(p.std);
        }
        e.evidence = format!("{}; {}: {evidence}", e.evidence, p.name);
        return;
    }
    r.effects.push(FoundEffect {
        name: effect.into(),
        value: json_of(&value),
        std: json_of(&std),
        nominal: json_of(&nominal),
        unit: p.unit.clone(),
        channel: ChannelKind::Dvl,
        evidence: format!("{}: {evidence}", p.name),
        gain,
        equivalent: None,
        line: None,
    });
}

/// The GNSS evidence as a section of the Markdown report.
pub fn markdown(g: &GnssEvidence) -> String {
    use std::fmt::Write;
    let mut m = String::new();
    let _ = writeln!(
        m,
        "## GNSS positions (independent of the DVL)\n\nThe runs dead-reckoned from compass and DVL \
         against the GNSS displacement over windows of {:.0} m{}; folds: {}.\n",
        g.threshold_m,
        if g.moving_bed {
            ", each fold's bed velocity fitted as a nuisance"
        } else {
            ""
        },
        g.folds.join(", ")
    );
    let _ = writeln!(m, "| parameter | verdict | why |\n|---|---|---|");
    for d in &g.decisions {
        let _ = writeln!(m, "| {} | {} | {} |", d.parameter, d.verdict, d.note);
    }
    let _ = writeln!(
        m,
        "\n| scored | windows | nominal (m RMS) | two-point | fitted / written by the others |\n|---|---|---|---|---|"
    );
    let row = |m: &mut String, label: &str, s: &ScoreSet| {
        let _ = writeln!(
            m,
            "| {label} | {} | {:.2} | {:.2} | {:.2} |",
            s.nominal.windows,
            s.nominal.rms_error_m,
            s.two_point.rms_error_m,
            s.calibrated.rms_error_m
        );
    };
    row(&mut m, "all folds", &g.in_sample);
    for h in &g.held_out {
        row(&mut m, &format!("{} held out", h.run), &h.scores);
    }
    let _ = writeln!(m);
    m
}
