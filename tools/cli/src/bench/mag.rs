//! `auvnav bench mag`: wall time of each magnetometer calibration method on 10 000 simulated
//! samples (full attitude coverage and AUV-like ±15° tilt), median of the repeats, with the
//! hard-iron error and the held-out heading error of each; with `--recording`, every method on
//! measured recordings at several fit fractions, scored on the held-out rest by the same metric
//! code (the comparison against the simplest baseline and the peers).

use crate::calibrate::mag::command::heading_check;
use crate::calibrate::mag::fit::SwarmSettings;
use crate::calibrate::mag::simulated::{Attitudes, samples};
use crate::calibrate::mag::{
    CalibrateMagOptions, MagMethod, ReferenceField, Thresholds, calibrate_mag, run_method,
};
use serde::Serialize;
use std::path::PathBuf;

#[derive(Debug, Serialize)]
struct Row {
    coverage: &'static str,
    method: MagMethod,
    model: String,
    median_wall_s: f64,
    hard_iron_error_ut: f64,
    heading_error_rms_deg: Option<f64>,
}

/// Every method, the default first.
const METHODS: [MagMethod; 5] = [
    MagMethod::Auto,
    MagMethod::Lm,
    MagMethod::Sphere,
    MagMethod::Ellipsoid,
    MagMethod::Seed,
];

/// One method on one measured recording and split.
#[derive(Debug, Serialize)]
struct MeasuredRow {
    recording: String,
    fit_fraction: f64,
    method: MagMethod,
    model: String,
    status: String,
    wall_s: f64,
    /// Held-out field-norm spread (fraction of the field) and dip standard deviation (deg).
    norm_spread: Option<f64>,
    dip_std_deg: Option<f64>,
    error: Option<String>,
}

fn measured(recordings: &[PathBuf], fractions: &[f64]) -> Vec<MeasuredRow> {
    let mut rows = Vec::new();
    for path in recordings {
        for &f in fractions {
            // The raw readings' held-out spreads: every method's report has them.
            let raw_row = rows.len();
            rows.push(MeasuredRow {
                recording: path.display().to_string(),
                fit_fraction: f,
                method: MagMethod::Auto,
                model: "raw readings".into(),
                status: "-".into(),
                wall_s: 0.0,
                norm_spread: None,
                dip_std_deg: None,
                error: None,
            });
            for method in METHODS {
                let mut a = CalibrateMagOptions::new(vec![path.clone()]);
                a.fit_fraction = f;
                a.method = method;
                let t = std::time::Instant::now();
                let r = calibrate_mag(&a);
                let wall_s = t.elapsed().as_secs_f64();
                let recording = path.display().to_string();
                let row = match r {
                    Ok(r) => {
                        if let Some(b) = r.spreads.evaluation_before
                            && rows[raw_row].norm_spread.is_none()
                        {
                            rows[raw_row].norm_spread = Some(b.norm_std_fraction);
                            rows[raw_row].dip_std_deg = b.dip_std_deg;
                        }
                        let after = r.spreads.evaluation_after;
                        MeasuredRow {
                            recording,
                            fit_fraction: f,
                            method,
                            model: format!("{:?}", r.model),
                            status: r.status.into(),
                            wall_s,
                            norm_spread: after.map(|s| s.norm_std_fraction),
                            dip_std_deg: after.and_then(|s| s.dip_std_deg),
                            error: None,
                        }
                    }
                    Err(e) => MeasuredRow {
                        recording,
                        fit_fraction: f,
                        method,
                        model: "-".into(),
                        status: "refused".into(),
                        wall_s,
                        norm_spread: None,
                        dip_std_deg: None,
                        error: Some(e.to_string()),
                    },
                };
                rows.push(row);
            }
        }
    }
    rows
}

fn print_measured(rows: &[MeasuredRow]) {
    println!(
        "\n{:<34} {:>5} {:<10} {:<10} {:<13} {:>9} {:>9} {:>9}",
        "recording (held-out rest)",
        "fit",
        "method",
        "model",
        "status",
        "norm %",
        "dip °",
        "wall s"
    );
    for r in rows {
        let name = std::path::Path::new(&r.recording)
            .file_name()
            .map_or(r.recording.clone(), |n| n.to_string_lossy().into_owned());
        let method = if r.model == "raw readings" {
            "raw".to_string()
        } else {
            format!("{:?}", r.method).to_lowercase()
        };
        println!(
            "{:<34} {:>5.2} {:<10} {:<10} {:<13} {:>9} {:>9} {:>9.3}{}",
            name,
            r.fit_fraction,
            method,
            r.model,
            r.status,
            r.norm_spread
                .map_or("-".into(), |v| format!("{:.3}", v * 100.0)),
            r.dip_std_deg.map_or("-".into(), |v| format!("{v:.3}")),
            r.wall_s,
            r.error
                .as_ref()
                .map_or(String::new(), |e| format!("  ({e})"))
        );
    }
}

/// Runs the benchmark; prints a table or JSON. With `recordings`, also every method on each at
/// each of `fractions`.
pub fn mag(
    samples_n: usize,
    repeat: usize,
    recordings: &[PathBuf],
    fractions: &[f64],
    json: bool,
) -> anyhow::Result<()> {
    let e = auvnav_sim::effects::Effects {
        mag_hard_iron: [9.0, -11.0, 6.5],
        mag_soft_iron: [1.06, 0.03, -0.04, 0.03, 0.95, 0.02, -0.04, 0.02, 1.02],
        mag_intensity: 49.0,
        mag_inclination: 52.0,
        mag_noise: 0.1,
        ..Default::default()
    };
    let reference = ReferenceField {
        intensity_ut: 49.0,
        inclination_deg: Some(52.0),
        declination_deg: Some(0.0),
        source: "--field-ut",
    };
    let mut rows = Vec::new();
    for (name, att) in [
        ("full", Attitudes::Full),
        ("auv-15deg", Attitudes::Limited { tilt_deg: 15.0 }),
    ] {
        let fit = samples(&e, att, samples_n, 0.02, 101);
        let eval = samples(&e, att, samples_n / 2, 0.02, 202);
        for method in METHODS {
            let mut times = Vec::new();
            let mut last = None;
            for _ in 0..repeat.max(1) {
                let t = std::time::Instant::now();
                let o = run_method(
                    method,
                    &fit,
                    &reference,
                    &Thresholds::default(),
                    SwarmSettings::default(),
                    None,
                );
                times.push(t.elapsed().as_secs_f64());
                last = Some(o);
            }
            times.sort_by(f64::total_cmp);
            let (model, hard, heading) = match last {
                Some(Ok(o)) => (
                    format!("{:?}", o.model),
                    (o.calibration.hard_iron_ut - nalgebra::Vector3::from(e.mag_hard_iron)).norm(),
                    heading_check(&eval, &o.calibration).map(|h| h.after_rms_deg),
                ),
                Some(Err(x)) => (format!("failed: {x}"), f64::NAN, None),
                None => ("not run".into(), f64::NAN, None),
            };
            rows.push(Row {
                coverage: name,
                method,
                model,
                median_wall_s: times[times.len() / 2],
                hard_iron_error_ut: hard,
                heading_error_rms_deg: heading,
            });
        }
    }
    let measured_rows = measured(recordings, fractions);
    if json {
        crate::json::print(&serde_json::json!({
            "samples": samples_n,
            "repeat": repeat,
            "rows": rows,
            "measured": measured_rows,
        }))?;
    } else {
        println!(
            "{:<10} {:<10} {:<10} {:>12} {:>14} {:>12}",
            "coverage", "method", "model", "wall (ms)", "hard iron (µT)", "heading (°)"
        );
        for r in &rows {
            println!(
                "{:<10} {:<10} {:<10} {:>12.1} {:>14.3} {:>12}",
                r.coverage,
                format!("{:?}", r.method),
                r.model,
                r.median_wall_s * 1e3,
                r.hard_iron_error_ut,
                r.heading_error_rms_deg
                    .map_or("-".into(), |h| format!("{h:.3}"))
            );
        }
        if !measured_rows.is_empty() {
            print_measured(&measured_rows);
        }
    }
    Ok(())
}
