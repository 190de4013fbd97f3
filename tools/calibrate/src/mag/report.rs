//! The magnetometer calibration's outputs: text, the `[navigation.magnetometer]` table, and the
//! report directory with its plots.

use super::command::MagReport;
use super::fit::MagSample;
use anyhow::Context;
use auvnav_core::aid::magnetometer::MagnetometerConfig;
use auvnav_replay::svg::{PALETTE, Series, plot};
use auvnav_replay::write_atomically;
use std::fmt::Write as _;
use std::path::Path;

fn opt(v: Option<f64>, digits: usize) -> String {
    v.map_or("-".into(), |v| format!("{v:.digits$}"))
}

/// The human-readable report.
pub fn text(r: &MagReport) -> String {
    let mut s = String::new();
    let _ = writeln!(
        s,
        "magnetometer calibration ({:?}, model: {}) of {} fitted + {} held-out samples ({} skipped)",
        r.method,
        r.model.name(),
        r.samples_fit,
        r.samples_evaluation,
        r.samples_skipped
    );
    let _ = writeln!(s, "unit: {}", r.unit);
    let _ = writeln!(
        s,
        "reference field: {:.2} µT, dip {} deg, declination {} deg ({})",
        r.reference.intensity_ut,
        opt(r.reference.inclination_deg, 2),
        opt(r.reference.declination_deg, 2),
        r.reference.source
    );
    for e in &r.effects {
        let v: Vec<String> = e
            .value
            .iter()
            .zip(&e.std)
            .map(|(v, s)| match s {
                Some(s) => format!("{v:.4}±{s:.4}"),
                None => format!("{v:.4}"),
            })
            .collect();
        let _ = writeln!(s, "{:<14} [{}] {}", e.name, v.join(", "), e.unit);
    }
    for reason in &r.reasons {
        let _ = writeln!(s, "model: {reason}");
    }
    if let Some(sel) = &r.selection {
        let _ = writeln!(
            s,
            "held-out blocks ({} of {} samples, each fitted on the others): candidate, norm \
             spread, dip spread",
            sel.blocks, sel.block_samples
        );
        for c in &sel.scores {
            let mark = if c.candidate == sel.chosen { "*" } else { " " };
            match &c.failed {
                Some(why) => {
                    let _ = writeln!(s, " {mark} {:<58} not fitted: {why}", c.name);
                }
                None => {
                    let _ = writeln!(
                        s,
                        " {mark} {:<58} {:>8.3} % {:>9} deg",
                        c.name,
                        c.norm_spread.unwrap_or(f64::NAN) * 100.0,
                        opt(c.dip_std_deg, 3)
                    );
                }
            }
        }
    }
    if let Some(m) = &r.noise_model {
        let _ = writeln!(
            s,
            "weights: norm σ {:.3} %, dip σ {} (quasi-static) + {} per g of dynamics, {} of the \
             samples quasi-static",
            m.norm_std * 100.0,
            opt(m.dip_std_static, 4),
            opt(m.dip_std_per_dynamics, 3),
            m.quasi_static_fraction
                .map_or("-".into(), |q| format!("{:.0} %", q * 100.0))
        );
    }
    let sp = &r.spreads;
    let row = |name: &str, b: &super::Spreads, a: &super::Spreads| {
        format!(
            "{name:<10} norm spread {:.3} % -> {:.3} %   dip spread {} -> {} deg",
            b.norm_std_fraction * 100.0,
            a.norm_std_fraction * 100.0,
            opt(b.dip_std_deg, 3),
            opt(a.dip_std_deg, 3)
        )
    };
    let _ = writeln!(s, "{}", row("fit", &sp.fit_before, &sp.fit_after));
    if let (Some(b), Some(a)) = (&sp.evaluation_before, &sp.evaluation_after) {
        let _ = writeln!(s, "{}", row("held-out", b, a));
    }
    let _ = writeln!(
        s,
        "coverage: {:.0} % of 26 directions; axis ranges x {:.2} y {:.2} z {:.2}; max roll {} pitch {} deg",
        r.coverage_calibrated.sphere_fraction * 100.0,
        r.coverage_calibrated.axis_range[0],
        r.coverage_calibrated.axis_range[1],
        r.coverage_calibrated.axis_range[2],
        opt(r.coverage_calibrated.max_roll_deg, 1),
        opt(r.coverage_calibrated.max_pitch_deg, 1)
    );
    if let Some(c) = r.condition_number {
        let _ = writeln!(s, "condition number {c:.3e}");
    }
    if let Some(h) = &r.heading {
        let _ = writeln!(
            s,
            "heading error vs reference attitude: {:.3} -> {:.3} deg RMS ({} samples)",
            h.before_rms_deg, h.after_rms_deg, h.samples
        );
    }
    let _ = writeln!(s, "wall time {:.3} s", r.wall_s);
    for v in &r.verdict {
        let _ = writeln!(s, "verdict: {v}");
    }
    s
}

/// The `[navigation.magnetometer]` table of the calibration.
pub fn config_toml(r: &MagReport) -> anyhow::Result<String> {
    if r.model == super::fit::Model::None {
        anyhow::bail!(
            "nothing to write: no calibration scored better than the raw readings on held-out \
             blocks ({})",
            r.verdict.join("; ")
        );
    }
    #[derive(serde::Serialize)]
    struct Navigation {
        magnetometer: MagnetometerConfig,
    }
    #[derive(serde::Serialize)]
    struct File {
        navigation: Navigation,
    }
    let soft = r
        .calibration
        .soft_iron()
        .context("the fitted soft iron is singular")?;
    let mut m = MagnetometerConfig {
        hard_iron_ut: r.calibration.hard_iron_ut.into(),
        source: format!(
            "auvnav calibrate mag ({:?}, {}) of {}",
            r.method,
            r.model.name(),
            r.inputs.join(", ")
        ),
        ..Default::default()
    };
    for i in 0..3 {
        for j in 0..3 {
            m.soft_iron[3 * i + j] = soft[(i, j)];
        }
    }
    let body = toml::to_string(&File {
        navigation: Navigation { magnetometer: m },
    })?;
    Ok(format!(
        "# Magnetometer calibration from `auvnav calibrate mag` (status: {}).\n# Add \
         model_date (decimal year) or declination_deg and intensity_ut before use.\n{body}",
        r.status
    ))
}

pub fn write_config(path: &Path, r: &MagReport) -> anyhow::Result<()> {
    Ok(write_atomically(path, &config_toml(r)?)?)
}

/// Every n-th sample so a plot holds at most `max` points.
fn thin(samples: &[MagSample], max: usize) -> impl Iterator<Item = &MagSample> {
    let step = samples.len().div_ceil(max.max(1)).max(1);
    samples.iter().step_by(step)
}

/// The report directory: report.md, report.json, calibration.toml, projections.svg per plane,
/// norm_histogram.svg.
pub fn write_report_dir(dir: &Path, r: &MagReport, samples: &[MagSample]) -> anyhow::Result<()> {
    std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    write_atomically(
        &dir.join("report.json"),
        &auvnav_replay::json::to_string_pretty(r)?,
    )?;
    write_atomically(&dir.join("calibration.toml"), &config_toml(r)?)?;
    let c = &r.calibration;
    let radius = r.reference.intensity_ut;
    let mut figures = Vec::new();
    for (name, (i, j)) in [("xy", (0, 1)), ("xz", (0, 2)), ("yz", (1, 2))] {
        let axis = ["x", "y", "z"];
        let raw: Vec<(f64, f64)> = thin(samples, 2000)
            .map(|s| (s.field_ut[i], s.field_ut[j]))
            .collect();
        let cal: Vec<(f64, f64)> = thin(samples, 2000)
            .map(|s| {
                let b = c.apply(&s.field_ut);
                (b[i], b[j])
            })
            .collect();
        let circle: Vec<(f64, f64)> = (0..=180)
            .map(|k| {
                let a = k as f64 * std::f64::consts::TAU / 180.0;
                (radius * a.cos(), radius * a.sin())
            })
            .collect();
        let svg = plot(
            &format!("Readings on the {name} plane: raw and calibrated"),
            &format!("{} (µT)", axis[i]),
            &format!("{} (µT)", axis[j]),
            &[
                Series {
                    name: "raw".into(),
                    points: raw,
                    color: PALETTE[1],
                    markers: true,
                    dashed: false,
                },
                Series {
                    name: "calibrated".into(),
                    points: cal,
                    color: PALETTE[0],
                    markers: true,
                    dashed: false,
                },
                Series {
                    name: "reference field".into(),
                    points: circle,
                    color: PALETTE[2],
                    markers: false,
                    dashed: true,
                },
            ],
            true,
        );
        let file = format!("projection_{name}.svg");
        write_atomically(&dir.join(&file), &svg)?;
        figures.push(file);
    }
    // Norm histogram, relative to the reference, before (scaled to the raw mean) and after.
    let raw_mean = samples.iter().map(|s| s.field_ut.norm()).sum::<f64>() / samples.len() as f64;
    let hist = |values: Vec<f64>| -> Vec<(f64, f64)> {
        let bins = 60;
        let (lo, hi) = (0.8, 1.2);
        let mut h = vec![0.0; bins];
        for v in values {
            let k = ((v - lo) / (hi - lo) * bins as f64).floor();
            if k >= 0.0 && (k as usize) < bins {
                h[k as usize] += 1.0;
            }
        }
        (0..bins)
            .map(|k| (lo + (k as f64 + 0.5) * (hi - lo) / bins as f64, h[k]))
            .collect()
    };
    let svg = plot(
        "Field norm / reference (raw: / its mean)",
        "norm ratio",
        "samples",
        &[
            Series {
                name: "raw".into(),
                points: hist(
                    samples
                        .iter()
                        .map(|s| s.field_ut.norm() / raw_mean)
                        .collect(),
                ),
                color: PALETTE[1],
                markers: false,
                dashed: false,
            },
            Series {
                name: "calibrated".into(),
                points: hist(
                    samples
                        .iter()
                        .map(|s| c.apply(&s.field_ut).norm() / radius)
                        .collect(),
                ),
                color: PALETTE[0],
                markers: false,
                dashed: false,
            },
        ],
        false,
    );
    write_atomically(&dir.join("norm_histogram.svg"), &svg)?;
    figures.push("norm_histogram.svg".into());
    let mut md = String::from("# Magnetometer calibration\n\n```\n");
    md.push_str(&text(r));
    md.push_str("```\n\n");
    for f in &figures {
        let _ = writeln!(md, "![{f}]({f})\n");
    }
    write_atomically(&dir.join("report.md"), &md)?;
    Ok(())
}
