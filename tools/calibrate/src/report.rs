//! The calibration's outputs: the report structure (`--json`), a text summary, the
//! `[navigation.dvl]` table (`--write-config`, atomic) and the report directory (`--report`:
//! Markdown, SVG plots, the JSON).
//!
//! Long on purpose: the report's structure, its text, the configuration table and the report
//! directory are the one output of a calibration: a change to the JSON is a change to the text and
//! the Markdown.

use super::objective::VoyageRun;
use super::options::{CalibrateDvlOptions, Method};
use super::params::{NAMES, ParameterSet};
use super::params::{installation, installation_vector};
use super::two_point::TwoPointVoyage;
use super::voyage::{DistanceSource, FixSource, Voyage};
use super::{Evaluation, MethodResult};
use anyhow::Context;
use auvnav_core::earth;
use auvnav_replay::svg::{PALETTE, Series, plot};
use serde::Serialize;
use std::fmt::Write as _;
use std::path::Path;

#[derive(Debug, Clone, Serialize)]
pub struct ParameterRow {
    /// The simulator's effect name (a lever-arm component as `dvl.lever_arm.x`).
    pub name: String,
    pub unit: String,
    pub value: f64,
    /// One-sigma: from the curvature of the objective (Gauss–Newton with the replay's
    /// sensitivities and the prior), see `std_source`.
    pub std: Option<f64>,
    pub prior: f64,
    pub prior_std: f64,
    pub min: f64,
    pub max: f64,
    /// `estimated`, `held_at_prior` (the voyages do not determine it) or `not_estimated`.
    pub status: String,
    pub determined: Option<bool>,
}

#[derive(Debug, Clone, Serialize)]
pub struct VoyageRow {
    pub name: String,
    pub start: String,
    pub distance_m: f64,
    pub distance_source: DistanceSource,
    pub fixes: usize,
    pub fixes_scored: usize,
    pub cep50_before: f64,
    pub cep50_after: f64,
    pub end_error_before_m: f64,
    pub end_error_after_m: f64,
    pub max_error_before_m: f64,
    pub max_error_after_m: f64,
    pub dvl_fused_after: u64,
    pub dvl_rejected_after: u64,
}

#[derive(Debug, Clone, Serialize)]
pub struct HoldoutRow {
    pub voyage: String,
    /// CEP50 of error/distance of the held-out voyage with the starting installation.
    pub before: f64,
    /// … with the installation fitted on the other voyages by the method.
    pub after: f64,
    /// … with the two-point installation of the other voyages.
    pub two_point_after: f64,
    pub parameters: Vec<(String, f64)>,
}

#[derive(Debug, Clone, Serialize)]
pub struct Holdout {
    pub scheme: &'static str,
    pub voyages: Vec<HoldoutRow>,
    pub mean_before: f64,
    pub mean_after: f64,
    pub mean_two_point_after: f64,
}

#[derive(Debug, Clone, Serialize)]
pub struct Objective {
    pub before: f64,
    pub after: f64,
    /// How every objective value in this report was computed.
    pub scored_by: &'static str,
}

#[derive(Debug, Clone, Serialize)]
pub struct Comparison {
    pub parameters: Vec<(String, f64)>,
    pub objective: f64,
}

#[derive(Debug, Clone, Serialize)]
pub struct Evaluations {
    /// Full replays of every voyage (one candidate each) for the fit and its re-score.
    pub full_replays_fit: usize,
    /// Wall time of the fit and its re-score (s): what `bench calibrate` compares.
    pub fit_wall_s: f64,
    /// Sensitivity sets computed from a replay's DVL epochs (fast): surrogate, not scored.
    pub surrogate_jacobians: usize,
    /// Wall time of the whole command: loading, baseline, fit, comparison, hold-out (s).
    pub wall_s: f64,
    pub full_replays_per_second: f64,
    pub threads: usize,
}

#[derive(Debug, Clone, Serialize)]
pub struct CalibrationReport {
    pub method: Method,
    pub fixes: FixSource,
    pub threshold_m: f64,
    pub voyages: Vec<VoyageRow>,
    pub parameters: Vec<ParameterRow>,
    /// Pairs the voyages cannot separate: (a, b, correlation).
    pub inseparable: Vec<(String, String, f64)>,
    pub objective: Objective,
    /// The seed method's response-surface optimum, re-scored by full replay.
    pub surface_optimum: Option<Comparison>,
    /// The two-point method on the same voyages, re-scored by full replay.
    pub two_point: Option<Comparison>,
    pub two_point_voyages: Vec<TwoPointVoyage>,
    pub holdout: Option<Holdout>,
    pub evaluations: Evaluations,
    /// (full replays so far, best objective so far).
    pub history: Vec<(usize, f64)>,
    pub notes: Vec<String>,
    pub verdict: String,
}

impl CalibrationReport {
    /// The provenance written with the calibrated table.
    pub fn source_note(&self) -> String {
        let names: Vec<&str> = self.voyages.iter().map(|v| v.name.as_str()).collect();
        format!(
            "auvnav calibrate dvl --method {} on {} voyage(s): {}",
            serde_json::to_value(self.method)
                .ok()
                .and_then(|v| v.as_str().map(str::to_string))
                .unwrap_or_default(),
            names.len(),
            names.join(", ")
        )
    }
}

/// The estimated parameters' values of `x`, by name.
pub fn values(params: &ParameterSet, x: &[f64; 8]) -> Vec<(String, f64)> {
    params
        .estimated()
        .into_iter()
        .map(|i| (NAMES[i].to_string(), x[i]))
        .collect()
}

pub struct Inputs<'a> {
    pub args: &'a CalibrateDvlOptions,
    pub params: &'a ParameterSet,
    pub voyages: &'a [Voyage],
    pub baseline: &'a Evaluation,
    pub after: &'a Evaluation,
    pub result: &'a MethodResult,
    pub two_point_voyages: Vec<TwoPointVoyage>,
    pub two_point_cmp: Option<([f64; 8], f64)>,
    pub holdout: Vec<HoldoutRow>,
    pub full_replays_fit: usize,
    pub fit_wall_s: f64,
    pub wall_s: f64,
    pub threads: usize,
}

fn errors(run: &VoyageRun) -> (f64, f64) {
    let norms: Vec<f64> = run.errors_ne.iter().map(|e| e[0].hypot(e[1])).collect();
    (
        norms.last().copied().unwrap_or(f64::NAN),
        norms.iter().copied().fold(0.0, f64::max),
    )
}

fn mean(x: impl Iterator<Item = f64>) -> f64 {
    let v: Vec<f64> = x.collect();
    v.iter().sum::<f64>() / v.len().max(1) as f64
}

// Long on purpose: assembles the report from the calibration's results, one field per documented
// field of the JSON (docs/json.md).
pub fn build(i: Inputs) -> CalibrationReport {
    let r = i.result;
    let parameters: Vec<ParameterRow> = i
        .params
        .all
        .iter()
        .enumerate()
        .map(|(k, p)| {
            let std = r.std.iter().find(|(j, _)| *j == k).map(|(_, s)| *s);
            let determined = r.determined.iter().find(|(j, _)| *j == k).map(|(_, d)| *d);
            let status = if !p.estimate {
                "not_estimated"
            } else if matches!(i.args.method, Method::Fast | Method::Smoother)
                && determined == Some(false)
            {
                "held_at_prior"
            } else if i.args.method == Method::TwoPoint && k != 2 && k != 3 {
                "not_estimated"
            } else {
                "estimated"
            };
            ParameterRow {
                name: p.name.to_string(),
                unit: p.unit.to_string(),
                value: r.x[k],
                std: if p.estimate { std } else { None },
                prior: p.prior,
                prior_std: p.prior_std,
                min: p.min,
                max: p.max,
                status: status.to_string(),
                determined,
            }
        })
        .collect();
    let voyages: Vec<VoyageRow> = i
        .voyages
        .iter()
        .enumerate()
        .map(|(k, v)| {
            let (eb, mb) = errors(&i.baseline.runs[k]);
            let (ea, ma) = errors(&i.after.runs[k]);
            VoyageRow {
                name: v.name.clone(),
                start: v.start_source.to_string(),
                distance_m: v.distance_m(),
                distance_source: v.distance_source,
                fixes: v.fixes.len(),
                fixes_scored: i.after.runs[k].scored(&v.fixes, i.args.threshold).len(),
                cep50_before: i.baseline.cep50[k],
                cep50_after: i.after.cep50[k],
                end_error_before_m: eb,
                end_error_after_m: ea,
                max_error_before_m: mb,
                max_error_after_m: ma,
                dvl_fused_after: i.after.runs[k].dvl_fused,
                dvl_rejected_after: i.after.runs[k].dvl_rejected,
            }
        })
        .collect();
    let holdout = (!i.holdout.is_empty()).then(|| Holdout {
        scheme: "leave-one-voyage-out",
        mean_before: mean(i.holdout.iter().map(|h| h.before)),
        mean_after: mean(i.holdout.iter().map(|h| h.after)),
        mean_two_point_after: mean(i.holdout.iter().map(|h| h.two_point_after)),
        voyages: i.holdout,
    });
    let mut notes = r.notes.clone();
    let held: Vec<&str> = parameters
        .iter()
        .filter(|p| p.status == "held_at_prior")
        .map(|p| p.name.as_str())
        .collect();
    let fitted: Vec<String> = parameters
        .iter()
        .filter(|p| p.status == "estimated" && p.determined != Some(false))
        .map(|p| match p.std {
            Some(s) => format!("{} = {:.4} ± {:.4} {}", p.name, p.value, s, p.unit),
            None => format!("{} = {:.4} {}", p.name, p.value, p.unit),
        })
        .collect();
    let undetermined_fit: Vec<&str> = parameters
        .iter()
        .filter(|p| p.status == "estimated" && p.determined == Some(false))
        .map(|p| p.name.as_str())
        .collect();
    let mut verdict = String::new();
    if fitted.is_empty() {
        verdict.push_str("These voyages determine none of the estimated parameters; the installation stays at its prior. ");
    } else {
        let _ = write!(verdict, "Determined: {}. ", fitted.join("; "));
    }
    let insignificant: Vec<&str> = parameters
        .iter()
        .filter(|p| {
            p.status == "estimated"
                && p.determined == Some(true)
                && p.std.is_some_and(|s| (p.value - p.prior).abs() < 2.0 * s)
        })
        .map(|p| p.name.as_str())
        .collect();
    if !insignificant.is_empty() {
        let _ = write!(
            verdict,
            "{} {} within two standard deviations of the prior: the voyages find no significant correction. ",
            insignificant.join(", "),
            if insignificant.len() == 1 {
                "is"
            } else {
                "are"
            }
        );
    }
    if !held.is_empty() {
        let _ = write!(
            verdict,
            "These voyages cannot determine {} (posterior std above half the prior's): held at the prior. ",
            held.join(", ")
        );
    }
    if !undetermined_fit.is_empty() {
        let _ = write!(
            verdict,
            "Warning: the {} method set {} although these voyages do not determine them; those values fit noise. ",
            serde_json::to_value(i.args.method)
                .ok()
                .and_then(|v| v.as_str().map(str::to_string))
                .unwrap_or_default(),
            undetermined_fit.join(", ")
        );
    }
    for (a, b, c) in &r.inseparable {
        let _ = write!(
            verdict,
            "{a} and {b} cannot be told apart on these voyages (correlation {c:.2}). "
        );
    }
    if let Some(h) = &holdout {
        let _ = write!(
            verdict,
            "Held-out voyages: CEP50 {:.5} -> {:.5} ({:+.1} %; two-point {:.5}).",
            h.mean_before,
            h.mean_after,
            100.0 * (h.mean_after / h.mean_before - 1.0),
            h.mean_two_point_after
        );
    }
    if i.voyages.len() < 3 && holdout.is_none() {
        notes.push("fewer than 3 voyages: no hold-out evaluation, the objective is scored on the voyages the fit used".into());
    }
    CalibrationReport {
        method: i.args.method,
        fixes: i.args.fixes,
        threshold_m: i.args.threshold,
        voyages,
        parameters,
        inseparable: r.inseparable.clone(),
        objective: Objective {
            before: i.baseline.objective,
            after: i.after.objective,
            scored_by: "full replay of every voyage through the navigation session (INS/DVL/depth dead reckoning, fixes not fused)",
        },
        surface_optimum: r.surface_optimum.map(|(x, f)| Comparison {
            parameters: values(i.params, &x),
            objective: f,
        }),
        two_point: i.two_point_cmp.map(|(x, f)| Comparison {
            parameters: vec![(NAMES[2].to_string(), x[2]), (NAMES[3].to_string(), x[3])],
            objective: f,
        }),
        two_point_voyages: i.two_point_voyages,
        holdout,
        evaluations: Evaluations {
            full_replays_fit: i.full_replays_fit,
            fit_wall_s: i.fit_wall_s,
            surrogate_jacobians: r.surrogate_evaluations,
            wall_s: i.wall_s,
            full_replays_per_second: i.full_replays_fit as f64 / i.fit_wall_s.max(1e-9),
            threads: i.threads,
        },
        history: r.history.clone(),
        notes,
        verdict,
    }
}

/// The report as text for a terminal.
pub fn text(r: &CalibrationReport) -> String {
    let mut s = String::new();
    let _ = writeln!(
        s,
        "DVL calibration ({:?}, {} voyage(s), fixes {:?}, threshold {} m)",
        r.method,
        r.voyages.len(),
        r.fixes,
        r.threshold_m
    );
    let _ = writeln!(
        s,
        "\n{:<20} {:>12} {:>10} {:>10} {:>10}  status",
        "parameter", "value", "std", "prior", "unit"
    );
    for p in &r.parameters {
        let std = p
            .std
            .map(|x| format!("{x:.5}"))
            .unwrap_or_else(|| "-".into());
        let _ = writeln!(
            s,
            "{:<20} {:>12.5} {:>10} {:>10.4} {:>10}  {}",
            p.name, p.value, std, p.prior, p.unit, p.status
        );
    }
    let _ = writeln!(
        s,
        "\n{:<28} {:>10} {:>12} {:>12} {:>10} {:>10}",
        "voyage", "distance", "CEP50 before", "CEP50 after", "end before", "end after"
    );
    for v in &r.voyages {
        let _ = writeln!(
            s,
            "{:<28} {:>9.0}m {:>12.6} {:>12.6} {:>9.2}m {:>9.2}m",
            v.name,
            v.distance_m,
            v.cep50_before,
            v.cep50_after,
            v.end_error_before_m,
            v.end_error_after_m
        );
    }
    let _ = writeln!(
        s,
        "\nobjective (mean CEP50, full replay): {:.6} -> {:.6}",
        r.objective.before, r.objective.after
    );
    if let Some(t) = &r.two_point {
        let _ = writeln!(
            s,
            "two-point on the same voyages:        {:.6}",
            t.objective
        );
    }
    if let Some(h) = &r.holdout {
        let _ = writeln!(
            s,
            "held out ({}): {:.6} -> {:.6} (two-point {:.6})",
            h.scheme, h.mean_before, h.mean_after, h.mean_two_point_after
        );
    }
    let _ = writeln!(
        s,
        "fit: {} full replays in {:.1} s ({:.2}/s on {} threads); whole run {:.1} s",
        r.evaluations.full_replays_fit,
        r.evaluations.fit_wall_s,
        r.evaluations.full_replays_per_second,
        r.evaluations.threads,
        r.evaluations.wall_s
    );
    for n in &r.notes {
        let _ = writeln!(s, "note: {n}");
    }
    let _ = writeln!(s, "\n{}", r.verdict);
    s
}

/// The `[navigation.dvl]` table of the report's installation.
pub fn config_toml(r: &CalibrationReport) -> anyhow::Result<String> {
    #[derive(Serialize)]
    struct Navigation {
        dvl: auvnav_core::config::DvlInstallation,
    }
    #[derive(Serialize)]
    struct File {
        navigation: Navigation,
    }
    let body = toml::to_string(&File {
        navigation: Navigation {
            dvl: installation_of(r),
        },
    })?;
    Ok(format!(
        "# DVL installation from `auvnav calibrate dvl` (objective {:.6} -> {:.6}).\n{body}",
        r.objective.before, r.objective.after
    ))
}

use auvnav_replay::write_atomically;

pub fn write_config(path: &Path, r: &CalibrationReport) -> anyhow::Result<()> {
    Ok(write_atomically(path, &config_toml(r)?)?)
}

fn ne_track(v: &Voyage, run: &VoyageRun) -> Vec<(f64, f64)> {
    let origin = v.start.position;
    run.track
        .iter()
        .map(|(_, p)| {
            let o = earth::ned_offset(&origin, p);
            (o.y, o.x)
        })
        .collect()
}

/// The report directory: `report.md`, `report.json`, `calibration.toml` and SVG plots.
// Long on purpose: writes the report directory: the Markdown with its tables and one SVG per
// figure, in the order the report reads.
pub fn write_report_dir(
    dir: &Path,
    r: &CalibrationReport,
    voyages: &[Voyage],
    baseline: &Evaluation,
    after: &Evaluation,
    result: &MethodResult,
) -> anyhow::Result<()> {
    std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    write_atomically(
        &dir.join("report.json"),
        &auvnav_replay::json::to_string_pretty(r)?,
    )?;
    write_atomically(&dir.join("calibration.toml"), &config_toml(r)?)?;
    let mut figures = Vec::new();
    for (k, v) in voyages.iter().enumerate() {
        let origin = v.start.position;
        let fixes: Vec<(f64, f64)> = v
            .fixes
            .iter()
            .map(|f| {
                let o = earth::ned_offset(&origin, &f.position);
                (o.y, o.x)
            })
            .collect();
        let svg = plot(
            &format!("{}: dead reckoning against the fixes", v.name),
            "east (m)",
            "north (m)",
            &[
                Series {
                    name: "fixes".into(),
                    points: fixes,
                    color: "#000000",
                    markers: true,
                    dashed: false,
                },
                Series {
                    name: "before".into(),
                    points: ne_track(v, &baseline.runs[k]),
                    color: PALETTE[1],
                    markers: false,
                    dashed: true,
                },
                Series {
                    name: "after".into(),
                    points: ne_track(v, &after.runs[k]),
                    color: PALETTE[0],
                    markers: false,
                    dashed: false,
                },
            ],
            true,
        );
        let name = format!("track_{:02}.svg", k + 1);
        write_atomically(&dir.join(&name), &svg)?;
        figures.push((format!("Voyage {}", v.name), name));
    }
    let mut series = Vec::new();
    for (k, v) in voyages.iter().enumerate() {
        let color = PALETTE[k % PALETTE.len()];
        for (run, dashed, tag) in [
            (&baseline.runs[k], true, "before"),
            (&after.runs[k], false, "after"),
        ] {
            series.push(Series {
                name: format!("{} {tag}", v.name),
                points: v
                    .fixes
                    .iter()
                    .zip(&run.errors_ne)
                    .map(|(f, e)| (f.distance_m, e[0].hypot(e[1])))
                    .collect(),
                color,
                markers: false,
                dashed,
            });
        }
    }
    write_atomically(
        &dir.join("error_vs_distance.svg"),
        &plot(
            "Horizontal error against distance travelled",
            "distance (m)",
            "error (m)",
            &series,
            false,
        ),
    )?;
    figures.push((
        "Error against distance (dashed: before)".into(),
        "error_vs_distance.svg".into(),
    ));
    if result.history.len() > 1 {
        let pts: Vec<(f64, f64)> = result
            .history
            .iter()
            .map(|(n, f)| (*n as f64, *f))
            .collect();
        write_atomically(
            &dir.join("convergence.svg"),
            &plot(
                "Best objective against full replays",
                "full replays",
                "mean CEP50 of error/distance",
                &[Series {
                    name: "best so far".into(),
                    points: pts,
                    color: PALETTE[0],
                    markers: false,
                    dashed: false,
                }],
                false,
            ),
        )?;
        figures.push(("Convergence".into(), "convergence.svg".into()));
    }
    let mut md = String::new();
    let _ = writeln!(md, "# DVL calibration report\n");
    let _ = writeln!(md, "{}\n", r.verdict);
    let _ = writeln!(
        md,
        "Method `{:?}`, fixes `{:?}`, threshold {} m. Every objective below is a full replay through the navigation session ({}).\n",
        r.method, r.fixes, r.threshold_m, r.objective.scored_by
    );
    let _ = writeln!(
        md,
        "## Parameters\n\n| parameter | value | std | prior | prior std | unit | status |\n|---|---|---|---|---|---|---|"
    );
    for p in &r.parameters {
        let std = p
            .std
            .map(|x| format!("{x:.5}"))
            .unwrap_or_else(|| "–".into());
        let _ = writeln!(
            md,
            "| {} | {:.5} | {} | {:.4} | {:.4} | {} | {} |",
            p.name, p.value, std, p.prior, p.prior_std, p.unit, p.status
        );
    }
    let _ = writeln!(
        md,
        "\n## Voyages\n\n| voyage | distance (m) | fixes scored | CEP50 before | CEP50 after | end error before (m) | end error after (m) |\n|---|---|---|---|---|---|---|"
    );
    for v in &r.voyages {
        let _ = writeln!(
            md,
            "| {} | {:.0} | {} | {:.6} | {:.6} | {:.2} | {:.2} |",
            v.name,
            v.distance_m,
            v.fixes_scored,
            v.cep50_before,
            v.cep50_after,
            v.end_error_before_m,
            v.end_error_after_m
        );
    }
    let _ = writeln!(
        md,
        "\nObjective (mean CEP50): {:.6} → {:.6}.",
        r.objective.before, r.objective.after
    );
    if let Some(t) = &r.two_point {
        let _ = writeln!(
            md,
            "Two-point method on the same voyages: {:.6}.",
            t.objective
        );
    }
    if let Some(h) = &r.holdout {
        let _ = writeln!(
            md,
            "\n## Held-out voyages ({})\n\n| voyage | before | after | two-point |\n|---|---|---|---|",
            h.scheme
        );
        for row in &h.voyages {
            let _ = writeln!(
                md,
                "| {} | {:.6} | {:.6} | {:.6} |",
                row.voyage, row.before, row.after, row.two_point_after
            );
        }
        let _ = writeln!(
            md,
            "| **mean** | {:.6} | {:.6} | {:.6} |",
            h.mean_before, h.mean_after, h.mean_two_point_after
        );
    }
    let _ = writeln!(
        md,
        "\nFit: {} full replays in {:.1} s on {} threads (whole run {:.1} s).\n",
        r.evaluations.full_replays_fit,
        r.evaluations.fit_wall_s,
        r.evaluations.threads,
        r.evaluations.wall_s
    );
    for n in &r.notes {
        let _ = writeln!(md, "- {n}");
    }
    for (title, file) in figures {
        let _ = writeln!(md, "\n### {title}\n\n![{title}]({file})");
    }
    write_atomically(&dir.join("report.md"), &md)?;
    Ok(())
}

/// The installation a report recommends, as eight numbers.
pub fn recommended(report: &CalibrationReport) -> [f64; 8] {
    let mut x = [0.0; 8];
    for p in &report.parameters {
        if let Some(i) = NAMES.iter().position(|n| *n == p.name) {
            x[i] = p.value;
        }
    }
    x
}

/// Round trip used by the tests: the TOML the tool writes is the installation it reports.
pub fn installation_of(report: &CalibrationReport) -> auvnav_core::config::DvlInstallation {
    let x = recommended(report);
    let mut d = installation(&x);
    d.source = report.source_note();
    debug_assert_eq!(installation_vector(&d), x);
    d
}
