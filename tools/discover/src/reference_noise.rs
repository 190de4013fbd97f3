//! The reference velocity's own noise, and what interpolating between its samples takes of it.
//!
//! A DVL reading with a time offset τ is compared with the reference at t − τ, interpolated
//! between two samples. Where the samples carry noise of their own (a surface run's velocity
//! over ground, differenced from GNSS positions or read from VTG), the interpolated value at a
//! fraction f of the interval is (1 − f)·a + f·b, whose noise variance is (1 − 2f(1 − f)) of a
//! sample's: half a sample from one, the residual's variance falls by a quarter of the
//! reference's for no reason in the data, and least squares takes a time offset for it. On
//! simulated boats recorded as surface runs (GNSS positions 2 cm white, nothing hidden) nine
//! null runs in ten named a time offset of 0.3–0.5 s, and with 20 cm of GNSS noise the null
//! runs' offset was 0.50 s.
//!
//! Where the reference carries such noise, the DVL's fits evaluate its velocity with the cubic
//! B-spline on the four samples around each time ([`crate::spline`],
//! [`Reference::with_smoothed_velocity`]), whose noise gain varies little and smoothly between
//! samples. With linear interpolation and the penalty below alone, the estimate stuck to the
//! sample times: on the lake run, hidden offsets of 0.2 and 0.4 s came out 0.0 and 0.17 s.
//!
//! The fit gives back what the interpolation takes: per reading the reference's sample noise
//! variance (summed over the components) times 2f(1 − f) (linear) or 1/2 − Σw²(f) (the
//! spline's weights w), a penalty on τ alone
//! ([`crate::fit::Problem::fit`]; the held-out scores likewise). The variance is measured with
//! the DVL as the witness ([`velocity_noise`]): over three readings on consecutive reference
//! samples evenly spaced, the second difference of the reference's prediction carries the
//! motion's and six times the reference noise's variance, and its product with the DVL's second
//! difference (aligned in time) the motion's alone (the two sensors' noise is independent), so
//! the difference is the reference's noise, whatever the motion does between samples (a boat in
//! waves) and whatever the DVL's own noise. A reference without noise (a simulation's truth) gives none
//! within its sampling error, and nothing changes.

use super::{Channel, Reference};
use auvnav_sim::effects::Effects;

/// Triples whose two intervals differ by more than this share of their mean are not used.
const EVEN_SPACING: f64 = 0.1;
/// The noise is taken as measured only this many of its standard errors above zero.
const SIGNIFICANT: f64 = 3.0;

/// Shifts of the DVL's readings (s) over which the witness is aligned with the reference.
const WITNESS_SHIFT_S: f64 = 2.0;
const WITNESS_STEP_S: f64 = 0.1;

/// The DVL channel's reference velocity noise from sample to sample, summed over the
/// components ((m/s)²): over evenly spaced triples of reference samples at readings, the mean of
/// ⟨Δ²p, Δ²p − Δ²z⟩ / 6, with p the nominal prediction from the reference and z the DVL's
/// readings interpolated at the samples' times plus a shift, the shift (within ±2 s) that
/// makes it least: where the DVL lags the reference, its second differences at the same times
/// share less of the motion's, and that share would be counted as the reference's noise (on a
/// lake run with 0.4 s of offset hidden, half as much again). 0 where fewer than 20 triples are
/// found or the mean is not three of its standard errors above zero. `epochs`: the readings of
/// `ch` the `nominal` model predicts from `reference`, in time order.
pub(crate) fn velocity_noise(
    ch: &Channel,
    reference: &Reference,
    nominal: &Effects,
    epochs: &[usize],
) -> f64 {
    let on_sample = |t: f64| reference.at(t).is_some() && reference.interpolation_at(t).is_none();
    let times: Vec<f64> = epochs.iter().map(|&i| ch.times[i]).collect();
    // The readings at `t` (linear between consecutive epochs no further apart than the gap).
    let z_at = |t: f64| -> Option<[f64; 3]> {
        let k = times.partition_point(|&x| x <= t);
        let a = k.checked_sub(1)?;
        let va = ch.values[epochs[a]];
        if times[a] == t {
            return Some([va[0], va[1], va[2]]);
        }
        let b = *epochs.get(k)?;
        let h = times[k] - times[a];
        if h > reference.max_gap_s {
            return None;
        }
        let f = (t - times[a]) / h;
        let vb = ch.values[b];
        Some(std::array::from_fn(|j| va[j] + (vb[j] - va[j]) * f))
    };
    let mut triples: Vec<([f64; 3], [[f64; 3]; 3])> = Vec::new();
    for w in times.windows(3) {
        let t = [w[0], w[1], w[2]];
        let (h1, h2) = (t[1] - t[0], t[2] - t[1]);
        if h1 <= 0.0 || h2 <= 0.0 || h1.max(h2) > reference.max_gap_s {
            continue;
        }
        if (h1 - h2).abs() > EVEN_SPACING * 0.5 * (h1 + h2) || !t.iter().all(|&s| on_sample(s)) {
            continue;
        }
        let pred: Option<Vec<[f64; 3]>> = t
            .iter()
            .map(|&s| ch.kind.predict(nominal, reference, s))
            .collect();
        if let Some(pred) = pred {
            triples.push((t, [pred[0], pred[1], pred[2]]));
        }
    }
    if triples.len() < 20 {
        return 0.0;
    }
    let steps = (WITNESS_SHIFT_S / WITNESS_STEP_S).round() as i32;
    let mut best: Option<(f64, f64)> = None;
    for k in -steps..=steps {
        let shift = f64::from(k) * WITNESS_STEP_S;
        let x: Vec<f64> = triples
            .iter()
            .filter_map(|(t, pred)| {
                let z = [
                    z_at(t[0] + shift)?,
                    z_at(t[1] + shift)?,
                    z_at(t[2] + shift)?,
                ];
                let xi: f64 = (0..3)
                    .map(|j| {
                        let dp = pred[2][j] - 2.0 * pred[1][j] + pred[0][j];
                        let dz = z[2][j] - 2.0 * z[1][j] + z[0][j];
                        dp * (dp - dz)
                    })
                    .sum();
                xi.is_finite().then_some(xi / 6.0)
            })
            .collect();
        if x.len() < 20 {
            continue;
        }
        let n = x.len() as f64;
        let mean = x.iter().sum::<f64>() / n;
        let se = (x.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / (n - 1.0) / n).sqrt();
        if best.is_none_or(|(m, _)| mean < m) {
            best = Some((mean, se));
        }
    }
    match best {
        Some((mean, se)) if mean > SIGNIFICANT * se => mean,
        _ => 0.0,
    }
}

impl Reference {
    /// Where a state at `t_s` is interpolated from: the fraction of the way between the two
    /// samples and their interval (s); None on a sample, outside, or across a gap.
    pub fn interpolation_at(&self, t_s: f64) -> Option<(f64, f64)> {
        let s = &self.samples;
        let i = s.partition_point(|x| x.0 <= t_s);
        let (t0, t1) = (s.get(i.checked_sub(1)?)?.0, s.get(i)?.0);
        let h = t1 - t0;
        if t0 == t_s || h > self.max_gap_s || h <= 0.0 {
            return None;
        }
        Some(((t_s - t0) / h, h))
    }

    /// The noise variance interpolating at `t − tau` takes from the reference velocity, summed
    /// over the readings at `times`, its first derivative in `tau`, and the curvature in `tau`
    /// the fit gives back: Σ v·2f(1 − f) for linear interpolation, Σ v·(1/2 − Σw²(f)) for the
    /// smoothed velocity ([`Reference::with_smoothed_velocity`]), where f is the reading's
    /// fraction of its interval and `v` the reference's sample noise summed over the components
    /// ([`velocity_noise`]). The curvature is minus twice the noise variance the regressor (the
    /// reference velocity's slope in τ) carries, 2v/h² between linear samples and vΣw'²/h² on
    /// the B-spline: the part of JᵀJ that is the reference's noise, not information. For linear
    /// interpolation it is also the loss's second derivative.
    pub fn interpolation_loss(
        &self,
        times: impl Iterator<Item = f64>,
        tau: f64,
        v: f64,
    ) -> [f64; 3] {
        if v <= 0.0 {
            return [0.0; 3];
        }
        let mut out = [0.0; 3];
        for t in times {
            if self.smooths_velocity() {
                if let Some((_, f, h)) = self.spline_at(t - tau) {
                    let (g, g1, slope) = crate::spline::noise_gain(f);
                    // v (g(0) − g(f)) with g(0) = 1/2, smooth in τ; df/dτ = −1/h.
                    out[0] += v * (0.5 - g);
                    out[1] += v * g1 / h;
                    // The regressor (the velocity's slope in τ) carries the noise variance
                    // v Σw'²/h²: twice that, taken from the curvature.
                    out[2] -= 2.0 * v * slope / (h * h);
                }
                continue;
            }
            if let Some((f, h)) = self.interpolation_at(t - tau) {
                // df/dτ = −1/h.
                out[0] += v * 2.0 * f * (1.0 - f);
                out[1] += -v * (2.0 - 4.0 * f) / h;
                out[2] += -4.0 * v / (h * h);
            }
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Samples once a second: the loss is 0 on a sample, v/2 half-way, with the derivatives of
    /// v·2f(1 − f) in τ (f = 1 − τ for a reading on a sample and 0 < τ < 1).
    #[test]
    fn the_loss_is_the_interpolations_lost_variance() {
        let truth: Vec<auvnav_shm_schema::TruthStateV1> = (0..10)
            .map(|k| auvnav_shm_schema::TruthStateV1 {
                host_time_ns: k * 1_000_000_000,
                quaternion_body_to_ned: [1.0, 0.0, 0.0, 0.0],
                ..Default::default()
            })
            .collect();
        let r = Reference::from_truth(&truth);
        let at = |tau: f64| r.interpolation_loss([4.0, 5.0].into_iter(), tau, 0.01);
        assert_eq!(at(0.0), [0.0, 0.0, 0.0]);
        let half = at(0.5);
        assert!((half[0] - 2.0 * 0.01 * 0.5).abs() < 1e-12, "{half:?}");
        assert!(half[1].abs() < 1e-12, "{half:?}");
        let q = at(0.25);
        // f = 0.75 for both readings: 2f(1 − f) = 0.375, d/dτ = −v(2 − 4f)/h = v, d²/dτ² = −4v/h².
        assert!((q[0] - 2.0 * 0.01 * 0.375).abs() < 1e-12, "{q:?}");
        assert!((q[1] - 2.0 * 0.01 * 1.0).abs() < 1e-12, "{q:?}");
        assert!((q[2] + 2.0 * 0.04).abs() < 1e-12, "{q:?}");
        assert_eq!(r.interpolation_loss([4.0].into_iter(), 0.5, 0.0), [0.0; 3]);
    }
}
