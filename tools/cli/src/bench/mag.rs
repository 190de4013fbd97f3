//! `auvnav bench mag`: wall time of each magnetometer calibration method on 10 000 simulated
//! samples (full attitude coverage and AUV-like ±15° tilt), median of the repeats, with the
//! hard-iron error and the held-out heading error of each.

use crate::calibrate::mag::command::heading_check;
use crate::calibrate::mag::fit::SwarmSettings;
use crate::calibrate::mag::simulated::{Attitudes, samples};
use crate::calibrate::mag::{MagMethod, ReferenceField, Thresholds, run_method};
use serde::Serialize;

#[derive(Debug, Serialize)]
struct Row {
    coverage: &'static str,
    method: MagMethod,
    model: String,
    median_wall_s: f64,
    hard_iron_error_ut: f64,
    heading_error_rms_deg: Option<f64>,
}

/// Runs the benchmark; prints a table or JSON.
pub fn mag(samples_n: usize, repeat: usize, json: bool) -> anyhow::Result<()> {
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
        for method in [MagMethod::Ellipsoid, MagMethod::Seed, MagMethod::Lm] {
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
    if json {
        crate::json::print(&serde_json::json!({
            "samples": samples_n,
            "repeat": repeat,
            "rows": rows,
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
    }
    Ok(())
}
