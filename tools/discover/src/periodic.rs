//! The periodic DVL velocity error (`dvl.periodic_velocity_error`): its period and phase from the
//! residual's strongest spectral line, so that the fit estimates its amplitudes as it does every
//! other candidate's (linearly, with the channel's noise model and the held-out selection).
//!
//! The line search fits, at each frequency of a grid from four cycles over the channel's span
//! ([`MIN_CYCLES`]) to a quarter of its reading rate (and at most 0.25 Hz: the platform
//! oscillations and swells this effect describes are slower), a sine and a cosine to each axis of
//! the residual with every other candidate fitted, and sums the explained power over the axes,
//! each axis scaled by its variance. The strongest frequency is refined by a parabola through its
//! neighbours; the axes' common phase is the leading direction of their (sine, cosine)
//! coefficients. The line's height is read against the spectrum around it (the median within half
//! its frequency or six periodogram resolutions of it, whichever is wider, the line's own main
//! lobe left out), so that a coloured residual's slope does not read as a line. The line stands
//! out when that height passes the level the strongest of the band's noise powers passes once in
//! a hundred spectra ([`FALSE_ALARM`]); only then is the effect a candidate. The same height gives
//! the deviations of the period and the phase (the Cramér–Rao bounds of a sinusoid in noise at
//! that level) and, where no line stands out, the amplitude that would have made one.

use super::fit::Problem;
use super::{Channel, ChannelKind, Reference};
use auvnav_sim::effects::Effects;
use serde::Serialize;

/// The candidate this module serves.
pub const EFFECT: &str = "dvl.periodic_velocity_error";

/// The line found in a channel's residual.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct PeriodicLine {
    /// `dvl.periodic_velocity_error_period` (s) and its one-sigma.
    pub period_s: f64,
    pub period_std_s: f64,
    /// `dvl.periodic_velocity_error_phase` (deg, at t = 0 of the recording's clock) and its
    /// one-sigma.
    pub phase_deg: f64,
    pub phase_std_deg: f64,
    /// The line's power over the median of the spectrum around it (about 1 for noise).
    pub line_to_background: f64,
    /// Cycles the channel's span holds.
    pub cycles: f64,
    /// The height over the background a line must have to stand out of noise: the level one
    /// in a hundred noise-only spectra exceeds at its highest over the searched band.
    pub threshold: f64,
    /// Per axis, the amplitude (m/s) that alone would lift this line to the threshold: the
    /// detection floor when no line stands out.
    pub floor_m_s: [f64; 3],
}

impl PeriodicLine {
    /// Whether the line stands out of the spectrum around it: the candidate is offered at it.
    pub fn stands_out(&self) -> bool {
        self.line_to_background >= self.threshold
    }
}

/// The chance that the strongest noise line of a searched band exceeds the threshold.
pub const FALSE_ALARM: f64 = 0.01;

/// Fewest cycles over the channel's span a line may have: fewer and a slowly varying error (a
/// Gauss–Markov one, a drifting current) passes for a period.
pub const MIN_CYCLES: f64 = 4.0;
/// Highest frequency searched (Hz).
pub const MAX_FREQUENCY_HZ: f64 = 0.25;
/// Grid points per 1/span (the periodogram's natural resolution).
const OVERSAMPLING: f64 = 4.0;

/// `ch` with the strongest line of its residual (every other candidate fitted;
/// [`Channel::periodic_line`]), standing out or not; None when `ch` is not a DVL channel, already
/// has its line, or its span or readings hold no band to search.
pub fn with_line(ch: &Channel, reference: &Reference, nominal: &Effects) -> Option<Channel> {
    if ch.kind != ChannelKind::Dvl || ch.periodic_line.is_some() {
        return None;
    }
    let p = Problem::new(ch, reference, nominal.clone());
    if p.epochs.len() < 50 {
        return None;
    }
    let all = p.candidates();
    let f = p.fit(&all, &p.epochs);
    let res = p.residuals(&p.effects(&all, &f.theta), &p.epochs);
    let times: Vec<f64> = p.epochs.iter().map(|&i| ch.times[i]).collect();
    let line = strongest_line(&times, &res, ch.kind.dims())?;
    let mut out = ch.clone();
    out.periodic_line = Some(line);
    Some(out)
}

/// [`with_line`], or `ch` as it is.
pub fn lined(ch: &Channel, reference: &Reference, nominal: &Effects) -> Channel {
    with_line(ch, reference, nominal).unwrap_or_else(|| ch.clone())
}

/// The strongest line of the residual `res` (reading-major, `d` components per reading) at
/// `times`; None when the span or the readings cannot hold [`MIN_CYCLES`] resolved cycles.
pub fn strongest_line(times: &[f64], res: &[f64], d: usize) -> Option<PeriodicLine> {
    let m = times.len();
    if m < 50 || d == 0 || res.len() != m * d {
        return None;
    }
    let (t0, t1) = (times[0], times[m - 1]);
    let span = t1 - t0;
    let mut gaps: Vec<f64> = times.windows(2).map(|w| w[1] - w[0]).collect();
    gaps.sort_by(f64::total_cmp);
    let dt = gaps[gaps.len() / 2];
    if !(span > 0.0 && dt > 0.0) {
        return None;
    }
    let df = 1.0 / (OVERSAMPLING * span);
    let f_lo = MIN_CYCLES / span;
    let f_hi = (0.25 / dt).min(MAX_FREQUENCY_HZ);
    if f_hi <= f_lo * 1.5 {
        return None;
    }
    // The spectrum around a line at f: within max(f / 2, 6 / span) of it, its own main lobe
    // (±2 / span) left out; the grid reaches that far on both sides of the searched band.
    let reach = |f: f64| (0.5 * f).max(6.0 / span);
    let g_lo = (f_lo - reach(f_lo)).max(df);
    let count = ((f_hi + reach(f_hi) - g_lo) / df).ceil() as usize + 1;
    let freqs: Vec<f64> = (0..count).map(|j| g_lo + j as f64 * df).collect();
    let moments = axis_moments(res, d);
    let power = periodogram(times, res, &moments, &freqs);
    let searched = |j: usize| freqs[j] >= f_lo && freqs[j] <= f_hi;
    let peak = (1..count - 1)
        .filter(|&j| searched(j))
        .max_by(|&a, &b| power[a].total_cmp(&power[b]))?;
    // A parabola through the peak and its neighbours (the grid is fine: 1/4 of a bin).
    let (a, b, c) = (power[peak - 1], power[peak], power[peak + 1]);
    let den = a - 2.0 * b + c;
    let shift = if den < 0.0 {
        (0.5 * (a - c) / den).clamp(-0.5, 0.5)
    } else {
        0.0
    };
    let f = freqs[peak] + shift * df;
    let mut band: Vec<f64> = (0..count)
        .filter(|&j| (freqs[j] - f).abs() <= reach(f) && (freqs[j] - f).abs() > 2.0 / span)
        .map(|j| power[j])
        .collect();
    if band.len() < 8 {
        return None;
    }
    band.sort_by(f64::total_cmp);
    // The median of a sum of d axes' two-degree-of-freedom powers, as its mean.
    let median_to_mean = chi_square_median_over_mean(2 * d);
    let background = band[band.len() / 2] / median_to_mean;
    let line_power = single_power(times, res, &moments, f);
    let ratio = line_power.total / background.max(f64::MIN_POSITIVE);
    let excess = (ratio - 1.0).max(1e-9);
    // Cramér–Rao bounds at the background's level (see the module's documentation).
    let omega_std = (6.0 / (d as f64 * span * span * excess)).sqrt();
    let centre_phase_std = (1.0 / (2.0 * d as f64 * excess)).sqrt();
    let t_mid = 0.5 * (t0 + t1);
    let phase_std = (centre_phase_std.powi(2) + (t_mid * omega_std).powi(2)).sqrt();
    let period = 1.0 / f;
    // The strongest of the band's noise powers: its grid points (the search takes the highest
    // of the oversampled grid, refined) count rather than its independent frequencies.
    let independent = ((f_hi - f_lo) * span * OVERSAMPLING).max(1.0);
    let threshold = threshold_for(d, FALSE_ALARM / independent);
    let m = times.len() as f64;
    let floor_m_s = std::array::from_fn(|k| match moments.get(k) {
        Some(&(_, var)) => (2.0 * var * (threshold - 1.0) * background / m).sqrt(),
        None => f64::NAN,
    });
    Some(PeriodicLine {
        period_s: period,
        period_std_s: period * period * omega_std / std::f64::consts::TAU,
        phase_deg: line_power.phase_rad.to_degrees(),
        phase_std_deg: phase_std.to_degrees().min(180.0),
        line_to_background: ratio,
        cycles: span * f,
        threshold,
        floor_m_s,
    })
}

/// The height x (power over its mean) a sum of `d` axes' noise powers (χ² with 2d degrees of
/// freedom over 2d) exceeds with probability `p`.
fn threshold_for(d: usize, p: f64) -> f64 {
    let k = d.max(1);
    // Survival of χ²(2k) at y: e^(−y/2) Σ_{i<k} (y/2)^i / i!.
    let survival = |x: f64| {
        let h = x * k as f64;
        let (mut term, mut sum) = (1.0, 1.0);
        for i in 1..k {
            term *= h / i as f64;
            sum += term;
        }
        (-h).exp() * sum
    };
    let (mut lo, mut hi) = (1.0, 200.0);
    for _ in 0..100 {
        let mid = 0.5 * (lo + hi);
        if survival(mid) > p {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    hi
}

/// The amplitudes of a periodic error found at phase `phase_deg`, written at the phase nearer
/// `wanted_phase_deg`: a sin(ωt + φ) and −a sin(ωt + φ + 180°) are the same error, and discovery
/// writes the one whose largest amplitude is positive.
pub fn amplitudes_near_phase(amplitude: &[f64], phase_deg: f64, wanted_phase_deg: f64) -> Vec<f64> {
    if (phase_deg - wanted_phase_deg).to_radians().cos() < 0.0 {
        amplitude.iter().map(|a| -a).collect()
    } else {
        amplitude.to_vec()
    }
}

/// The median of a χ² variable with `k` degrees of freedom over its mean (Wilson–Hilferty).
fn chi_square_median_over_mean(k: usize) -> f64 {
    let k = k.max(1) as f64;
    (1.0 - 2.0 / (9.0 * k)).powi(3)
}

/// Each axis's mean and variance (`res` reading-major, `d` per reading), for the powers' scaling
/// and the floor.
fn axis_moments(res: &[f64], d: usize) -> Vec<(f64, f64)> {
    let m = (res.len() / d) as f64;
    (0..d)
        .map(|k| {
            let mean = res.iter().skip(k).step_by(d).sum::<f64>() / m;
            let var = res
                .iter()
                .skip(k)
                .step_by(d)
                .map(|x| (x - mean).powi(2))
                .sum::<f64>()
                / m;
            (mean, var.max(f64::MIN_POSITIVE))
        })
        .collect()
}

/// The power the sine and cosine of each frequency `freqs` explain, summed over the axes (each
/// over its variance). The sines and cosines advance by rotation along the grid (uniform in
/// frequency), so only two per reading are evaluated.
fn periodogram(times: &[f64], res: &[f64], moments: &[(f64, f64)], freqs: &[f64]) -> Vec<f64> {
    let d = moments.len();
    let n = freqs.len();
    let df = if n > 1 { freqs[1] - freqs[0] } else { 0.0 };
    // Per frequency: Σcc, Σss, Σcs, then per axis Σrc, Σrs.
    let width = 3 + 2 * d;
    let mut acc = vec![0.0; n * width];
    let tau = std::f64::consts::TAU;
    let t_ref = times[0];
    for (i, &t) in times.iter().enumerate() {
        let t = t - t_ref;
        let (mut s, mut c) = (tau * freqs[0] * t).sin_cos();
        let (ds, dc) = (tau * df * t).sin_cos();
        let r = &res[i * d..i * d + d];
        for j in 0..n {
            let a = &mut acc[j * width..(j + 1) * width];
            a[0] += c * c;
            a[1] += s * s;
            a[2] += c * s;
            for k in 0..d {
                let x = r[k] - moments[k].0;
                a[3 + 2 * k] += x * c;
                a[4 + 2 * k] += x * s;
            }
            (s, c) = (s * dc + c * ds, c * dc - s * ds);
        }
    }
    (0..n)
        .map(|j| {
            let a = &acc[j * width..(j + 1) * width];
            (0..d)
                .map(|k| {
                    let (x, y) = solve2(a[0], a[1], a[2], a[3 + 2 * k], a[4 + 2 * k]);
                    (x * a[3 + 2 * k] + y * a[4 + 2 * k]) / moments[k].1
                })
                .sum()
        })
        .collect()
}

/// The least-squares (cosine, sine) coefficients for normal equations [cc cs; cs ss].
fn solve2(cc: f64, ss: f64, cs: f64, rc: f64, rs: f64) -> (f64, f64) {
    let det = cc * ss - cs * cs;
    if det.abs() <= 1e-12 * (cc * ss).abs().max(f64::MIN_POSITIVE) {
        return (0.0, 0.0);
    }
    ((ss * rc - cs * rs) / det, (cc * rs - cs * rc) / det)
}

/// The power at one frequency (as [`periodogram`]) and the axes' common phase at t = 0.
struct LinePower {
    total: f64,
    phase_rad: f64,
}

fn single_power(times: &[f64], res: &[f64], moments: &[(f64, f64)], f: f64) -> LinePower {
    let d = moments.len();
    let w = std::f64::consts::TAU * f;
    let width = 3 + 2 * d;
    let mut a = vec![0.0; width];
    for (i, &t) in times.iter().enumerate() {
        // Absolute time: the phase is the vocabulary's, at t = 0 of the recording's clock.
        let (s, c) = (w * t).sin_cos();
        a[0] += c * c;
        a[1] += s * s;
        a[2] += c * s;
        for k in 0..d {
            let x = res[i * d + k] - moments[k].0;
            a[3 + 2 * k] += x * c;
            a[4 + 2 * k] += x * s;
        }
    }
    let mut total = 0.0;
    // Σ over the axes of (sine, cosine)(sine, cosine)ᵀ, each axis over its variance: its leading
    // direction is (cos φ, sin φ) of A sin(ωt + φ) = A cos φ sin ωt + A sin φ cos ωt.
    let (mut m11, mut m22, mut m12) = (0.0, 0.0, 0.0);
    let mut coefficients = Vec::with_capacity(d);
    for k in 0..d {
        let (cos_coef, sin_coef) = solve2(a[0], a[1], a[2], a[3 + 2 * k], a[4 + 2 * k]);
        let v = moments[k].1;
        total += (cos_coef * a[3 + 2 * k] + sin_coef * a[4 + 2 * k]) / v;
        m11 += sin_coef * sin_coef / v;
        m22 += cos_coef * cos_coef / v;
        m12 += sin_coef * cos_coef / v;
        coefficients.push((sin_coef, cos_coef));
    }
    let theta = 0.5 * (2.0 * m12).atan2(m11 - m22);
    let (u, v) = (theta.cos(), theta.sin());
    // The sign that makes the largest amplitude positive.
    let amplitude = |(s, c): (f64, f64)| s * u + c * v;
    let largest = coefficients
        .iter()
        .map(|&x| amplitude(x))
        .max_by(|a, b| a.abs().total_cmp(&b.abs()))
        .unwrap_or(0.0);
    let phase = if largest < 0.0 {
        (-v).atan2(-u)
    } else {
        v.atan2(u)
    };
    LinePower {
        total,
        phase_rad: phase,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Readings every 0.2 s for `span` s: a sine on x and, in antiphase at half the amplitude,
    /// on y, with near-Gaussian white noise (σ 5.8 mm/s: four uniforms summed) from a linear
    /// congruential stream seeded with `seed`.
    fn series(
        seed: u64,
        period: f64,
        phase_deg: f64,
        amplitude: f64,
        span: f64,
    ) -> (Vec<f64>, Vec<f64>) {
        let mut state = seed;
        let mut noise = || {
            let mut x = 0.0;
            for _ in 0..4 {
                state = state
                    .wrapping_mul(6364136223846793005)
                    .wrapping_add(1442695040888963407);
                x += (state >> 11) as f64 / (1u64 << 53) as f64 - 0.5;
            }
            x * 0.02
        };
        let times: Vec<f64> = (0..(span / 0.2) as usize)
            .map(|i| 100.0 + i as f64 * 0.2)
            .collect();
        let w = std::f64::consts::TAU / period;
        let phi = phase_deg.to_radians();
        let res = times
            .iter()
            .flat_map(|&t| {
                let e = amplitude * (w * t + phi).sin();
                [e + noise(), -0.5 * e + noise(), noise()]
            })
            .collect();
        (times, res)
    }

    #[test]
    fn a_line_in_noise_gives_its_period_and_phase() {
        let (times, res) = series(12345, 86.0, 40.0, 0.01, 1800.0);
        let l = strongest_line(&times, &res, 3).expect("a line");
        assert!(l.stands_out(), "{l:?}");
        assert!((l.period_s - 86.0).abs() < 0.2, "{l:?}");
        assert!((l.phase_deg - 40.0).abs() < 3.0, "{l:?}");
        assert!(l.line_to_background > 100.0, "{l:?}");
        assert!(
            (l.period_s - 86.0).abs() < 4.0 * l.period_std_s + 0.05,
            "{l:?}"
        );
    }

    /// Noise alone: the threshold is set for one false line in a hundred noise spectra, so of
    /// twenty at most two stand out (chance of three or more: 0.1 %); and a line of twice
    /// the floor's amplitude on one axis stands out at its period.
    #[test]
    fn noise_alone_has_no_line_standing_out() {
        let mut out = 0;
        for seed in 1..=20 {
            let (times, res) = series(seed, 86.0, 40.0, 0.0, 1200.0);
            let l = strongest_line(&times, &res, 3).expect("a strongest frequency");
            out += usize::from(l.stands_out());
            if l.stands_out() {
                continue;
            }
            let w = std::f64::consts::TAU / 86.0;
            let lifted: Vec<f64> = res
                .iter()
                .enumerate()
                .map(|(i, r)| match i % 3 {
                    0 => r + 2.0 * l.floor_m_s[0] * (w * times[i / 3]).sin(),
                    _ => *r,
                })
                .collect();
            let m = strongest_line(&times, &lifted, 3).expect("a line");
            assert!(m.stands_out(), "{m:?}");
            assert!((m.period_s - 86.0).abs() < 3.0 * m.period_std_s, "{m:?}");
        }
        assert!(
            out <= 2,
            "{out} of 20 noise spectra had a line standing out"
        );
    }

    #[test]
    fn the_threshold_is_the_chi_square_tail() {
        // χ²(2) over 2 is exponential: P(x > t) = e^(−t).
        assert!((threshold_for(1, 0.01) - 0.01f64.ln().abs()).abs() < 1e-9);
        // χ²(6) exceeds 16.81 with probability 0.01.
        assert!((threshold_for(3, 0.01) * 6.0 - 16.812).abs() < 0.01);
    }

    #[test]
    fn a_sign_of_the_amplitudes_is_a_half_turn_of_the_phase() {
        let a = [0.01, -0.02, 0.0];
        assert_eq!(amplitudes_near_phase(&a, 30.0, 60.0), a.to_vec());
        assert_eq!(
            amplitudes_near_phase(&a, 30.0, -140.0),
            vec![-0.01, 0.02, -0.0]
        );
        // The same error at both: a sin(ωt + φ) = −a sin(ωt + φ + 180°).
        let (w, t, phi) = (0.3f64, 7.0f64, 30f64.to_radians());
        let b = amplitudes_near_phase(&a, 30.0, -150.0);
        for k in 0..3 {
            let x = a[k] * (w * t + phi).sin();
            let y = b[k] * (w * t + phi + std::f64::consts::PI).sin();
            assert!((x - y).abs() < 1e-15);
        }
    }

    /// A line slower than the span holds MIN_CYCLES of is not searched for: what is found is
    /// inside the band (within half a grid step of its edge).
    #[test]
    fn no_period_longer_than_the_band_allows_is_reported() {
        let span = 200.0;
        let (times, res) = series(7, 86.0, 40.0, 0.01, span);
        if let Some(l) = strongest_line(&times, &res, 3) {
            let longest = (times[times.len() - 1] - times[0]) / MIN_CYCLES;
            assert!(l.period_s <= longest * 1.04, "{l:?}");
        }
    }
}
