//! `auvnav calibrate mag`: magnetometer calibration with the attitude a vehicle can reach (S-MAG).
//!
//! [`fit`] holds the fits; this module chooses and checks them: the reference field (the world
//! magnetic model at the recording's position and date, or given), the method, the automatic
//! fallback to a constrained model when the attitude coverage does not determine the full soft
//! iron, and the quality measures (field-norm and dip spreads before and after, sphere coverage,
//! parameter standard deviations, disturbance) that make the verdict.

pub mod command;
pub mod fit;
pub mod gyro;
pub use auvnav_import::mag as input;
pub mod report;
pub mod select;
pub mod simulated;
pub mod weights;

use fit::{Calibration, FitError, LmFit, MagSample, Model, SwarmSettings};
use nalgebra::Vector3;
use serde::Serialize;

pub use command::{CalibrateMagOptions, calibrate_mag};
pub use weights::weighted_lm;

/// `auvnav calibrate mag` as a function: the calibration, then the files it asks for (the
/// `[navigation.magnetometer]` table, the report directory).
pub fn run(a: &CalibrateMagOptions) -> Result<command::MagReport, crate::CalibrationError> {
    let r = calibrate_mag(a)?;
    if let Some(p) = &a.write_config {
        report::write_config(p, &r).map_err(|e| crate::CalibrationError::output(p, e))?;
    }
    if let Some(d) = &a.report {
        report::write_report_dir(d, &r, &r.samples)
            .map_err(|e| crate::CalibrationError::output(d, e))?;
    }
    Ok(r)
}

/// The calibration methods (`--method`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[cfg_attr(feature = "clap", derive(clap::ValueEnum))]
#[serde(rename_all = "kebab-case")]
pub enum MagMethod {
    /// Every candidate (sphere, ellipsoid, weighted norm + dip in each model, none) scored on
    /// held-out blocks of the fit part; the best that is not worse than the sphere fit.
    Auto,
    /// Hard iron and one scale by the linear sphere fit (the simplest baseline).
    Sphere,
    /// The 10-coefficient ellipsoid fit, K by Cholesky (the seed's baseline).
    Ellipsoid,
    /// The seed's 13-unknown multi-constraint cost by particle swarm.
    Seed,
    /// The multi-constraint cost by Levenberg–Marquardt with automatic constrained fallbacks.
    Lm,
}

/// The field the calibration scales to.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct ReferenceField {
    /// Total intensity (µT).
    pub intensity_ut: f64,
    /// Inclination (deg, positive down), when known.
    pub inclination_deg: Option<f64>,
    /// Declination (deg east), when known.
    pub declination_deg: Option<f64>,
    /// Where it came from ("WMM-2025 at … on …", "--field-ut", "the readings' sphere fit").
    pub source: &'static str,
}

/// Limits behind the verdict and the fallbacks.
#[derive(Debug, Clone, Copy, Serialize)]
pub struct Thresholds {
    /// Largest standard deviation of a soft-iron element for it to count as determined.
    pub soft_iron_std: f64,
    /// Largest hard-iron standard deviation, as a fraction of the field.
    pub hard_iron_std_fraction: f64,
    /// Largest normalised condition number of the fit's normal matrix.
    pub condition: f64,
    /// Field-norm spread after calibration above which the data are called disturbed (fraction).
    pub norm_spread: f64,
    /// Largest difference of the readings' field magnitude from the model (fraction) before the
    /// environment is called disturbed (only with a field model).
    pub model_difference: f64,
    /// Dip spread after calibration above which the data are called disturbed (deg).
    pub dip_spread_deg: f64,
    /// Least fraction of the 26 sphere directions seen for a full 3-D fit to be trusted.
    pub coverage: f64,
}

impl Default for Thresholds {
    fn default() -> Self {
        Thresholds {
            soft_iron_std: 0.01,
            hard_iron_std_fraction: 0.01,
            condition: 1e8,
            norm_spread: 0.03,
            model_difference: 0.25,
            dip_spread_deg: 3.0,
            coverage: 0.35,
        }
    }
}

/// Spreads of the field norm and of the gravity–field angle over a set of samples.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Spreads {
    /// Mean field norm (µT).
    pub norm_mean_ut: f64,
    /// Standard deviation of the norm as a fraction of the reference field.
    pub norm_std_fraction: f64,
    /// Mean dip (deg): the angle of the field below the plane normal to the specific force.
    pub dip_mean_deg: Option<f64>,
    /// Standard deviation of the dip (deg).
    pub dip_std_deg: Option<f64>,
}

/// How the calibrated (or raw) field directions cover the sphere.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Coverage {
    /// Fraction of 26 directions (cube faces, edges, corners) with samples near them.
    pub sphere_fraction: f64,
    /// Per axis, the range (max − min)/2 of the unit field component: 1 = the axis saw the whole
    /// field both ways, 0 = it saw one value.
    pub axis_range: [f64; 3],
    /// Tilt range of the specific force: the largest roll and pitch magnitudes (deg).
    pub max_roll_deg: Option<f64>,
    pub max_pitch_deg: Option<f64>,
}

/// The spreads of a calibration on a set of samples.
pub fn spreads(samples: &[MagSample], c: &Calibration, reference_ut: f64) -> Spreads {
    let n = samples.len().max(1) as f64;
    let norms: Vec<f64> = samples
        .iter()
        .map(|s| c.apply(&s.field_ut).norm())
        .collect();
    let mean = norms.iter().sum::<f64>() / n;
    let var = norms.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / n;
    let dips: Vec<f64> = samples
        .iter()
        .filter_map(|s| {
            let f = s.specific_force?.try_normalize(1e-9)?;
            let b = c.apply(&s.field_ut).try_normalize(1e-12)?;
            // −f̂ points down: dip = asin(−f̂·B̂).
            Some((-f.dot(&b)).clamp(-1.0, 1.0).asin().to_degrees())
        })
        .collect();
    let (dip_mean, dip_std) = if dips.is_empty() {
        (None, None)
    } else {
        let m = dips.iter().sum::<f64>() / dips.len() as f64;
        let v = dips.iter().map(|x| (x - m).powi(2)).sum::<f64>() / dips.len() as f64;
        (Some(m), Some(v.sqrt()))
    };
    Spreads {
        norm_mean_ut: mean,
        norm_std_fraction: var.sqrt() / reference_ut,
        dip_mean_deg: dip_mean,
        dip_std_deg: dip_std,
    }
}

/// The 26 directions of the cube's faces, edges and corners.
fn directions() -> Vec<Vector3<f64>> {
    let mut d = Vec::with_capacity(26);
    for x in -1..=1 {
        for y in -1..=1 {
            for z in -1..=1 {
                if (x, y, z) != (0, 0, 0) {
                    d.push(Vector3::new(x as f64, y as f64, z as f64).normalize());
                }
            }
        }
    }
    d
}

/// The coverage of the calibrated field directions and the tilt range.
pub fn coverage(samples: &[MagSample], c: &Calibration) -> Coverage {
    let dirs = directions();
    let mut counts = vec![0usize; dirs.len()];
    let mut lo = [f64::INFINITY; 3];
    let mut hi = [f64::NEG_INFINITY; 3];
    let (mut roll, mut pitch, mut tilts) = (0.0f64, 0.0f64, 0usize);
    for s in samples {
        if let Some(u) = c.apply(&s.field_ut).try_normalize(1e-12) {
            let k = (0..dirs.len())
                .max_by(|&a, &b| dirs[a].dot(&u).total_cmp(&dirs[b].dot(&u)))
                .unwrap_or(0);
            counts[k] += 1;
            for i in 0..3 {
                lo[i] = lo[i].min(u[i]);
                hi[i] = hi[i].max(u[i]);
            }
        }
        if let Some(f) = s.specific_force {
            let (r, p) = fit::tilt_from_specific_force(&f);
            roll = roll.max(r.abs());
            pitch = pitch.max(p.abs());
            tilts += 1;
        }
    }
    let need = (samples.len() / 1000).max(3);
    let seen = counts.iter().filter(|&&c| c >= need).count();
    Coverage {
        sphere_fraction: seen as f64 / dirs.len() as f64,
        axis_range: std::array::from_fn(|i| {
            if hi[i] >= lo[i] {
                (hi[i] - lo[i]) / 2.0
            } else {
                0.0
            }
        }),
        max_roll_deg: (tilts > 0).then(|| roll.to_degrees()),
        max_pitch_deg: (tilts > 0).then(|| pitch.to_degrees()),
    }
}

/// What a method produced.
#[derive(Debug, Clone)]
pub struct MethodOutcome {
    pub method: MagMethod,
    pub calibration: Calibration,
    /// The model the calibration is in (the ellipsoid and the swarm estimate a full K).
    pub model: Model,
    /// The Levenberg–Marquardt fit behind it (lm only).
    pub lm: Option<LmFit>,
    /// Why the model was chosen, including every fallback taken.
    pub reasons: Vec<String>,
    /// Swarm evaluations (seed only).
    pub evaluations: Option<usize>,
    /// The estimated weights' noise model (weighted Levenberg–Marquardt fits).
    pub noise: Option<weights::NoiseModel>,
    /// The held-out comparison of every candidate (auto only).
    pub selection: Option<select::Selection>,
}

/// The auto method: the held-out selection, then the chosen candidate fitted on every sample.
fn run_auto(samples: &[MagSample], reference: &ReferenceField) -> Result<MethodOutcome, FitError> {
    let selection = select::select(samples, reference);
    let (chosen, mut reasons) = match &selection {
        Some(s) => (
            s.chosen,
            vec![format!("chosen on held-out blocks: {}", s.reason)],
        ),
        None => (
            select::Candidate::Lm(Model::HardIron),
            vec![format!(
                "too few readings for {} held-out blocks of {}: the weighted hard-iron fit",
                select::BLOCKS,
                select::MIN_BLOCK
            )],
        ),
    };
    let f = select::fit_candidate(chosen, samples, reference)?;
    if let Some(l) = &f.lm {
        reasons.push(format!(
            "{}: condition {:.2e}, {} iterations",
            l.model.name(),
            l.condition,
            l.iterations
        ));
    }
    Ok(MethodOutcome {
        method: MagMethod::Auto,
        calibration: f.calibration,
        model: chosen.model(),
        lm: f.lm,
        reasons,
        evaluations: None,
        noise: f.noise,
        selection,
    })
}

/// The largest standard deviation among a fit's soft-iron parameters and among its hard-iron
/// parameters.
fn std_by_kind(f: &LmFit) -> (f64, f64) {
    let names = fit::parameter_names(f.model);
    let mut k: f64 = 0.0;
    let mut b: f64 = 0.0;
    for (n, s) in names.iter().zip(&f.std) {
        let s = if s.is_nan() { 0.0 } else { *s };
        if n.starts_with('k') || *n == "scale" {
            k = k.max(s);
        } else if n.starts_with('b') {
            b = b.max(s);
        }
    }
    (k, b)
}

/// Runs `method` on `samples` with the reference field; for `lm`, chooses the richest model the
/// data determine (full → diagonal → hard iron → heading plane), with the reason for each step.
// Long on purpose: the fallback chain of the Levenberg–Marquardt method (full, diagonal, hard iron,
// heading plane) with each step's reason: one decision list.
pub fn run_method(
    method: MagMethod,
    samples: &[MagSample],
    reference: &ReferenceField,
    limits: &Thresholds,
    swarm: SwarmSettings,
    forced_model: Option<Model>,
) -> Result<MethodOutcome, FitError> {
    let r = reference.intensity_ut;
    match method {
        MagMethod::Auto if forced_model.is_none() => run_auto(samples, reference),
        MagMethod::Sphere => Ok(MethodOutcome {
            method,
            calibration: select::fit_candidate(select::Candidate::Sphere, samples, reference)?
                .calibration,
            model: Model::HardIron,
            lm: None,
            reasons: vec!["sphere fit: hard iron and one scale, linear least squares".into()],
            evaluations: None,
            noise: None,
            selection: None,
        }),
        MagMethod::Ellipsoid => Ok(MethodOutcome {
            method,
            calibration: fit::ellipsoid(samples, r)?,
            model: Model::Full,
            lm: None,
            reasons: vec!["ellipsoid fit: all ten quadric coefficients".into()],
            evaluations: None,
            noise: None,
            selection: None,
        }),
        MagMethod::Seed => {
            let (c, evaluations) = fit::swarm(samples, r, swarm)?;
            Ok(MethodOutcome {
                method,
                calibration: c,
                model: Model::Full,
                lm: None,
                reasons: vec![format!(
                    "particle swarm: {} particles, {} evaluations, seed {}",
                    swarm.particles, evaluations, swarm.seed
                )],
                evaluations: Some(evaluations),
                noise: None,
                selection: None,
            })
        }
        // A model given with auto is the lm method in that model.
        MagMethod::Lm | MagMethod::Auto => {
            let horizontal = reference
                .inclination_deg
                .map_or(r, |i| r * i.to_radians().cos());
            let (centre, radius) = match fit::sphere(samples) {
                Ok(v) => v,
                Err(FitError::Planar(why))
                    if forced_model.is_none() || forced_model == Some(Model::Plane) =>
                {
                    // Level turns only: the heading plane is all the readings can give.
                    let n = samples.len() as f64;
                    let mean = samples.iter().map(|s| s.field_ut).sum::<Vector3<f64>>() / n;
                    let rad = samples
                        .iter()
                        .map(|s| (s.field_ut - mean).xy().norm())
                        .sum::<f64>()
                        / n;
                    let s0 = horizontal / rad.max(1e-9);
                    let start = Calibration {
                        k: nalgebra::Matrix3::from_diagonal(&Vector3::new(s0, s0, 1.0)),
                        hard_iron_ut: Vector3::new(mean.x, mean.y, 0.0),
                        lambda: None,
                    };
                    let (f, noise) = weighted_lm(samples, r, horizontal, Model::Plane, &start)?;
                    return Ok(MethodOutcome {
                        method,
                        calibration: f.calibration,
                        model: Model::Plane,
                        lm: Some(f),
                        reasons: vec![format!(
                            "{why}; {}: the z hard iron and scale are not determined",
                            Model::Plane.name()
                        )],
                        evaluations: None,
                        noise,
                        selection: None,
                    });
                }
                Err(e) => return Err(e),
            };
            let sphere_start = Calibration {
                k: nalgebra::Matrix3::identity() * (r / radius),
                hard_iron_ut: centre,
                lambda: None,
            };
            let mut reasons = Vec::new();
            let start = match fit::ellipsoid(samples, r) {
                Ok(e) => e,
                Err(e) => {
                    reasons.push(format!("started from the sphere fit ({e})"));
                    sphere_start
                }
            };
            let order: Vec<Model> = match forced_model {
                Some(m) => vec![m],
                None => vec![Model::Full, Model::Diagonal, Model::HardIron, Model::Plane],
            };
            let mut last: Option<LmFit> = None;
            let mut last_noise = None;
            for (i, model) in order.iter().enumerate() {
                let from = if *model == Model::Full {
                    &start
                } else {
                    &sphere_start
                };
                let (f, noise) = weighted_lm(samples, r, horizontal, *model, from)?;
                last_noise = noise;
                let (k_std, b_std) = std_by_kind(&f);
                let mut why = Vec::new();
                if !f.condition.is_finite() || f.condition > limits.condition {
                    why.push(format!(
                        "condition number {:.2e} (limit {:.0e})",
                        f.condition, limits.condition
                    ));
                }
                if *model != Model::HardIron && k_std > limits.soft_iron_std {
                    why.push(format!(
                        "soft-iron std {:.4} (limit {})",
                        k_std, limits.soft_iron_std
                    ));
                }
                if b_std > limits.hard_iron_std_fraction * r {
                    why.push(format!(
                        "hard-iron std {:.3} µT (limit {:.3} µT)",
                        b_std,
                        limits.hard_iron_std_fraction * r
                    ));
                }
                let is_last = i + 1 == order.len();
                if why.is_empty() || is_last {
                    if !why.is_empty() {
                        reasons.push(format!(
                            "{}: kept as the last resort although {}",
                            model.name(),
                            why.join(", ")
                        ));
                    } else {
                        reasons.push(format!(
                            "{}: determined (condition {:.2e}, soft-iron std ≤ {:.4}, hard-iron \
                             std ≤ {:.3} µT)",
                            model.name(),
                            f.condition,
                            k_std,
                            b_std
                        ));
                    }
                    last = Some(f);
                    break;
                }
                reasons.push(format!(
                    "{} not determined: {}",
                    model.name(),
                    why.join(", ")
                ));
                last = Some(f);
            }
            let f = last.ok_or_else(|| FitError::Degenerate("no model was fitted".into()))?;
            Ok(MethodOutcome {
                method,
                calibration: f.calibration,
                model: f.model,
                lm: Some(f),
                reasons,
                evaluations: None,
                noise: last_noise,
                selection: None,
            })
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn coverage_of_a_full_sphere_and_a_flat_ring() {
        let mut full = Vec::new();
        let mut ring = Vec::new();
        for i in 0..2000 {
            let a = i as f64 * 0.37;
            let b = (i as f64 * 0.011).sin() * 1.5;
            full.push(MagSample {
                time_s: 0.0,
                field_ut: 50.0 * Vector3::new(b.cos() * a.cos(), b.cos() * a.sin(), b.sin()),
                specific_force: None,
                angular_rate: None,
                truth_rpy: None,
            });
            ring.push(MagSample {
                time_s: 0.0,
                field_ut: Vector3::new(25.0 * a.cos(), 25.0 * a.sin(), 43.0),
                specific_force: Some(Vector3::new(0.0, 0.0, -9.8)),
                angular_rate: None,
                truth_rpy: None,
            });
        }
        let id = Calibration::identity();
        let cf = coverage(&full, &id);
        let cr = coverage(&ring, &id);
        assert!(cf.sphere_fraction > 0.9, "{cf:?}");
        assert!(cr.sphere_fraction < 0.4, "{cr:?}");
        assert!(cr.axis_range[2] < 0.01 && cr.axis_range[0] > 0.49);
        assert_eq!(cr.max_roll_deg, Some(0.0));
    }
}
