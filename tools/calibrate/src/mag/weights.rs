//! Weights of the two S-MAG constraints, estimated from the data instead of fixed equal.
//!
//! The field-norm residual `|B|/R − 1` carries the magnetometer's noise and whatever the model
//! leaves out; it gets one variance for every sample. The gravity–field residual `f̂·B/R − λ`
//! assumes the specific force is gravity: a sample taken while the vehicle accelerates (waves, a
//! turn, a thruster kick) measures a tilted vertical, so its variance grows with how far the
//! specific force is from quasi-static. Each sample's dynamics `e` combines the departure of
//! `|f|` from the recording's median (gravity) and the specific force's scatter over the
//! half-second around it, both relative to gravity; the dip variance is modelled as
//! `σ² = σ₀² + c²·e²`, with σ₀ and c estimated by least squares on the squared residuals of the
//! current calibration. Weights are 1/σ²; [`weighted_lm`] alternates weights and calibration,
//! then takes off the bias the magnetometer's own noise puts into the least-squares optimum
//! ([`remove_noise_bias`]).

use super::fit::{self, Calibration, FitError, LmFit, MagSample, Model, Weights};
use nalgebra::Vector3;
use serde::Serialize;

/// The estimated noise model behind a set of weights (reported).
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct NoiseModel {
    /// σ of the field-norm residual (fraction of the field).
    pub norm_std: f64,
    /// σ of the gravity–field residual of a quasi-static sample (cosine units).
    pub dip_std_static: Option<f64>,
    /// Growth of that σ per unit of dynamics (fraction of gravity).
    pub dip_std_per_dynamics: Option<f64>,
    /// Share of the samples whose dip weight is at least half the quasi-static one.
    pub quasi_static_fraction: Option<f64>,
}

/// Smallest σ allowed for either residual: keeps a perfect (noise-free) fit's weights finite.
const SIGMA_FLOOR: f64 = 1e-6;

/// Each sample's dynamics: the departure of the specific force from quasi-static, as a fraction
/// of gravity (NaN without a specific force).
pub fn dynamics(samples: &[MagSample]) -> Vec<f64> {
    let mut norms: Vec<f64> = samples
        .iter()
        .filter_map(|s| s.specific_force.map(|f| f.norm()))
        .filter(|n| n.is_finite())
        .collect();
    if norms.is_empty() {
        return vec![f64::NAN; samples.len()];
    }
    norms.sort_by(f64::total_cmp);
    let g = norms[norms.len() / 2].max(1e-12);
    // Half-width of the scatter window in samples: half a second at the median interval.
    let dt = fit::median_interval(samples).unwrap_or(1.0);
    let half = ((0.5 / dt).round() as usize).clamp(1, 500);
    samples
        .iter()
        .enumerate()
        .map(|(i, s)| {
            let Some(f) = s.specific_force else {
                return f64::NAN;
            };
            let dev = (f.norm() - g) / g;
            let lo = i.saturating_sub(half);
            let hi = (i + half + 1).min(samples.len());
            let (mut sum, mut sq, mut n) = (nalgebra::Vector3::zeros(), 0.0, 0usize);
            for t in &samples[lo..hi] {
                // A gap or a new recording ends the window.
                if (t.time_s - s.time_s).abs() > 1.0 {
                    continue;
                }
                if let Some(ft) = t.specific_force {
                    sum += ft;
                    sq += ft.norm_squared();
                    n += 1;
                }
            }
            let var = if n > 1 {
                let m = sum / n as f64;
                (sq / n as f64 - m.norm_squared()).max(0.0)
            } else {
                0.0
            };
            (dev * dev + var / (g * g)).sqrt()
        })
        .collect()
}

/// The weights of the two constraints for `c` on `samples` (`dynamics` from [`dynamics`]),
/// with the noise model they come from.
pub fn estimate(
    samples: &[MagSample],
    dynamics: &[f64],
    field_ut: f64,
    c: &Calibration,
) -> (Weights, NoiseModel) {
    let n = samples.len().max(1) as f64;
    let r1: Vec<f64> = samples
        .iter()
        .map(|s| c.apply(&s.field_ut).norm() / field_ut - 1.0)
        .collect();
    let m1 = r1.iter().sum::<f64>() / n;
    let norm_var = (r1.iter().map(|r| (r - m1).powi(2)).sum::<f64>() / n).max(SIGMA_FLOOR.powi(2));
    // Gravity–field residuals against their mean (λ), with each sample's dynamics.
    let pairs: Vec<(f64, f64)> = samples
        .iter()
        .zip(dynamics)
        .filter_map(|(s, e)| {
            let f = s.specific_force?.try_normalize(1e-9)?;
            e.is_finite()
                .then(|| (f.dot(&c.apply(&s.field_ut)) / field_ut, e * e))
        })
        .collect();
    if pairs.len() < 3 {
        return (
            Weights {
                norm: 1.0 / norm_var,
                dip: Vec::new(),
            },
            NoiseModel {
                norm_std: norm_var.sqrt(),
                dip_std_static: None,
                dip_std_per_dynamics: None,
                quasi_static_fraction: None,
            },
        );
    }
    let k = pairs.len() as f64;
    let lambda = c
        .lambda
        .unwrap_or_else(|| pairs.iter().map(|p| p.0).sum::<f64>() / k);
    // r² = a + b·e² by least squares, a and b not negative.
    let (mut sx, mut sy, mut sxx, mut sxy) = (0.0, 0.0, 0.0, 0.0);
    for (v, e2) in &pairs {
        let y = (v - lambda).powi(2);
        sx += e2;
        sy += y;
        sxx += e2 * e2;
        sxy += e2 * y;
    }
    let det = k * sxx - sx * sx;
    let (mut a, mut b) = if det > 1e-300 {
        ((sxx * sy - sx * sxy) / det, (k * sxy - sx * sy) / det)
    } else {
        (sy / k, 0.0)
    };
    if b < 0.0 {
        (a, b) = (sy / k, 0.0);
    }
    if a < SIGMA_FLOOR.powi(2) {
        a = SIGMA_FLOOR.powi(2);
        // Refit the slope alone with the intercept at its floor.
        b = if sxx > 0.0 {
            ((sxy - a * sx) / sxx).max(0.0)
        } else {
            0.0
        };
    }
    let dip: Vec<f64> = dynamics
        .iter()
        .map(|e| {
            if e.is_finite() {
                1.0 / (a + b * e * e)
            } else {
                0.0
            }
        })
        .collect();
    let quasi = dynamics
        .iter()
        .filter(|e| e.is_finite() && b * *e * *e <= a)
        .count() as f64
        / k;
    (
        Weights {
            norm: 1.0 / norm_var,
            dip,
        },
        NoiseModel {
            norm_std: norm_var.sqrt(),
            dip_std_static: Some(a.sqrt()),
            dip_std_per_dynamics: Some(b.sqrt()),
            quasi_static_fraction: Some(quasi),
        },
    )
}

/// A Levenberg–Marquardt fit whose constraint weights are estimated from the data: an
/// equal-weight fit, then twice the weights from its residuals ([`estimate`]) and a
/// refit from where it stands.
pub fn weighted_lm(
    samples: &[MagSample],
    field_ut: f64,
    horizontal_ut: f64,
    model: Model,
    start: &Calibration,
) -> Result<(LmFit, Option<NoiseModel>), FitError> {
    let mut f = fit::levenberg_marquardt(samples, field_ut, horizontal_ut, model, start)?;
    if model == Model::Plane {
        return Ok((f, None));
    }
    let e = dynamics(samples);
    let mut noise = None;
    for _ in 0..2 {
        let (w, m) = estimate(samples, &e, field_ut, &f.calibration);
        f = fit::levenberg_marquardt_weighted(
            samples,
            field_ut,
            horizontal_ut,
            model,
            &f.calibration,
            &w,
        )?;
        noise = Some(m);
    }
    if let Some(m) = &noise {
        let (w, _) = estimate(samples, &e, field_ut, &f.calibration);
        f = remove_noise_bias(samples, field_ut, horizontal_ut, &f, &w, m)?;
    }
    Ok((f, noise))
}

/// The field nearest to a calibrated field `b` that the fit holds exactly: magnitude `field_ut`
/// and, with a specific force and a fitted λ, the angle to it whose cosine is λ (the
/// azimuth about the specific force kept).
fn consistent_field(
    b: &Vector3<f64>,
    x: &MagSample,
    lambda: Option<f64>,
    field_ut: f64,
) -> Vector3<f64> {
    let along = x
        .specific_force
        .and_then(|f| f.try_normalize(1e-9))
        .zip(lambda.filter(|l| l.abs() < 1.0));
    if let Some((f, l)) = along
        && let Some(u) = (b - f * f.dot(b)).try_normalize(1e-12)
    {
        return field_ut * (l * f + (1.0 - l * l).sqrt() * u);
    }
    b * (field_ut / b.norm().max(1e-12))
}

/// Replicates of the parametric bootstrap behind [`remove_noise_bias`].
const BIAS_REPLICATES: usize = 4;

/// The fit's bias from the magnetometer's own noise, estimated by a parametric bootstrap and
/// taken off. The norm residual is not linear in the reading, so white reading noise biases the
/// least-squares optimum; with little attitude change the hard iron along the vertical and the
/// matching scale are nearly one direction of the problem and the bias grows along it (0.16 µT
/// of vertical hard iron for 0.1 µT of noise at ±20° of tilt, against a standard deviation of
/// 0.04 µT). The readings are rebuilt from the fit (each calibrated field moved to the nearest
/// one the fit holds exactly, [`consistent_field`], and mapped back through the fit), given
/// white noise of the size the norm residual shows, and refitted; the mean shift of the refits
/// is the bias.
fn remove_noise_bias(
    samples: &[MagSample],
    field_ut: f64,
    horizontal_ut: f64,
    f: &LmFit,
    w: &Weights,
    noise: &NoiseModel,
) -> Result<LmFit, FitError> {
    let c = &f.calibration;
    let Some(s) = c.k.try_inverse() else {
        return Ok(f.clone());
    };
    let k_scale = c.k.determinant().abs().cbrt().max(1e-12);
    let sigma = noise.norm_std * field_ut / k_scale;
    // The replicates in parallel, each with its own stream: the same result on any core count.
    use rayon::prelude::*;
    let refits = (0..BIAS_REPLICATES)
        .into_par_iter()
        .map(|k| {
            let mut rng = auvnav_sim::rng::Rng::new(1 + k as u64, "calibrate.mag.noise-bias");
            let synthetic: Vec<MagSample> = samples
                .iter()
                .map(|x| {
                    let b = consistent_field(&c.apply(&x.field_ut), x, c.lambda, field_ut);
                    let n = Vector3::new(rng.gauss(sigma), rng.gauss(sigma), rng.gauss(sigma));
                    MagSample {
                        field_ut: s * b + c.hard_iron_ut + n,
                        ..*x
                    }
                })
                .collect();
            fit::levenberg_marquardt_weighted(&synthetic, field_ut, horizontal_ut, f.model, c, w)
        })
        .collect::<Result<Vec<LmFit>, FitError>>()?;
    let mut shift = vec![0.0; f.parameters.len()];
    for r in &refits {
        for (acc, (a, b)) in shift.iter_mut().zip(r.parameters.iter().zip(&f.parameters)) {
            *acc += (a - b) / BIAS_REPLICATES as f64;
        }
    }
    let parameters: Vec<f64> = f
        .parameters
        .iter()
        .zip(&shift)
        .map(|(p, d)| p - d)
        .collect();
    Ok(LmFit {
        calibration: fit::calibration_of(f.model, &parameters),
        parameters,
        ..f.clone()
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn accelerated_samples_get_less_weight_than_quiet_ones() {
        // Quiet first half, shaken second half; the field constraint's residual follows the
        // shaking (the specific force leans).
        let mut s = Vec::new();
        for i in 0..2000 {
            let t = i as f64 * 0.05;
            let shake = if i >= 1000 {
                2.0 * (t * 7.0).sin()
            } else {
                0.0
            };
            let f = Vector3::new(shake, 0.0, -9.81);
            let a = t * 0.3;
            s.push(MagSample {
                time_s: t,
                field_ut: Vector3::new(20.0 * a.cos(), 20.0 * a.sin(), 40.0),
                specific_force: Some(f),
                angular_rate: None,
                truth_rpy: None,
            });
        }
        let e = dynamics(&s);
        assert!(e[500] < 1e-6 && e[1500] > 0.05, "{} {}", e[500], e[1500]);
        let c = Calibration::identity();
        let (w, m) = estimate(&s, &e, 44.72, &c);
        assert!(w.dip_of(500) > 10.0 * w.dip_of(1500), "{m:?}");
        assert!(m.quasi_static_fraction.expect("dip model") > 0.45, "{m:?}");
    }
}
