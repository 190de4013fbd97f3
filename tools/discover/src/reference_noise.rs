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
//! the DVL as the witness ([`velocity_noise`]): over three consecutive reference
//! samples nearest the readings, evenly spaced, the second difference of the reference's prediction carries the
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
/// components ((m/s)²): over evenly spaced triples of the reference samples nearest the readings,
/// the mean of
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
    // Consecutive reference samples nearest the readings: the readings themselves where they are
    // on samples (an importer's reference at the pings); a DVL whose pings fall between the
    // samples (a reading late or early against its GNSS) is witnessed on them all the same, its
    // readings interpolated to the samples' times below. A reference sampled faster than the
    // readings gives no consecutive triple: its sample-to-sample noise is not seen at the
    // readings' spacing.
    let mut nearest: Vec<usize> = times
        .iter()
        .filter_map(|&t| reference.nearest_sample(t))
        .collect();
    nearest.dedup();
    let mut triples: Vec<([f64; 3], [[f64; 3]; 3])> = Vec::new();
    for w in nearest.windows(3) {
        if w[1] != w[0] + 1 || w[2] != w[1] + 1 {
            continue;
        }
        let t = [w[0], w[1], w[2]].map(|k| reference.sample_time(k));
        let (h1, h2) = (t[1] - t[0], t[2] - t[1]);
        if h1 <= 0.0 || h2 <= 0.0 || h1.max(h2) > reference.max_gap_s {
            continue;
        }
        if (h1 - h2).abs() > EVEN_SPACING * 0.5 * (h1 + h2) {
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
    let mut best: Option<(f64, f64, Vec<f64>)> = None;
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
        let (mean, se) = mean_and_error(&x);
        if best.as_ref().is_none_or(|(m, _, _)| mean < *m) {
            best = Some((mean, se, x));
        }
    }
    match best {
        Some((mean, se, x)) if mean > SIGNIFICANT * se && stationary(&x, mean) => mean,
        _ => 0.0,
    }
}

/// The mean of `x` and its standard error.
fn mean_and_error(x: &[f64]) -> (f64, f64) {
    let n = x.len() as f64;
    let mean = x.iter().sum::<f64>() / n;
    let var = x.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / (n - 1.0).max(1.0);
    (mean, (var / n).sqrt())
}

/// Quarters of the triples the witness is taken in four consecutive stretches of the run.
const STRETCHES: usize = 4;
/// The stretches' χ² above which their means disagree. The terms are products of noisy second
/// differences, heavy-tailed, and their χ² runs far above the 3-degree-of-freedom law on pure
/// sample noise: over the 1809 witnesses of the simulated surface benchmark (`auvnav bench
/// discover --surface 200`) its median was 4.2, its 97th percentile 18.5 and its largest 65.5;
/// Snapir's segments 7 and 11, where the DVL and the reference part for a stretch, give 2.4e4
/// and 9.5e5.
const STRETCHES_DISAGREE: f64 = 100.0;

/// Whether the witness's terms `x` (in time order) measure one noise variance throughout: the
/// means of four consecutive stretches agree with `mean` within their standard errors (χ² at
/// most [`STRETCHES_DISAGREE`]). A reference's sample noise is the same all along; a stretch where
/// the DVL and the reference disagree for another reason (a DVL that loses the bottom, a
/// reference that departs — Snapir's segment 11, whose last half gives a "noise" two hundred times
/// its first half's) is not noise of the reference and must not be given back as such.
fn stationary(x: &[f64], mean: f64) -> bool {
    let len = x.len().div_ceil(STRETCHES);
    let chi2: f64 = x
        .chunks(len)
        .filter(|c| c.len() >= 2)
        .map(|c| {
            let (m, se) = mean_and_error(c);
            if se > 0.0 {
                ((m - mean) / se).powi(2)
            } else {
                0.0
            }
        })
        .sum();
    chi2 <= STRETCHES_DISAGREE
}

impl Reference {
    /// The index of the sample nearest `t_s`, when it is less than half the longest interpolated
    /// gap away.
    pub fn nearest_sample(&self, t_s: f64) -> Option<usize> {
        let s = &self.samples;
        let i = s.partition_point(|x| x.0 <= t_s);
        [i.checked_sub(1), Some(i)]
            .into_iter()
            .flatten()
            .filter(|&j| j < s.len())
            .min_by(|&a, &b| (s[a].0 - t_s).abs().total_cmp(&(s[b].0 - t_s).abs()))
            .filter(|&j| (s[j].0 - t_s).abs() < 0.5 * self.max_gap_s)
    }

    /// The time of sample `k` (s).
    pub fn sample_time(&self, k: usize) -> f64 {
        self.samples[k].0
    }

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

    /// The witness's terms from one noise all along are stationary; a stretch where they are a
    /// hundred times larger (the DVL and the reference parting) is not.
    #[test]
    fn a_witness_that_changes_along_the_run_is_not_noise() {
        let mut state = 7u64;
        let mut gauss = || {
            // Sum of twelve uniforms: a unit normal to the accuracy needed here.
            (0..12)
                .map(|_| {
                    state = state
                        .wrapping_mul(6_364_136_223_846_793_005)
                        .wrapping_add(1_442_695_040_888_963_407);
                    (state >> 11) as f64 / (1u64 << 53) as f64
                })
                .sum::<f64>()
                - 6.0
        };
        // Products of two noisy differences, as the witness forms them: heavy-tailed.
        let x: Vec<f64> = (0..400).map(|_| 1e-4 * (gauss() * gauss() + 1.0)).collect();
        let (mean, se) = mean_and_error(&x);
        assert!(mean > SIGNIFICANT * se, "{mean} ± {se}");
        assert!(stationary(&x, mean));
        let mut parted = x.clone();
        for v in &mut parted[300..] {
            *v *= 100.0;
        }
        let (mean, _) = mean_and_error(&parted);
        assert!(!stationary(&parted, mean));
    }
}
