//! The kernel a noisy reference velocity is evaluated with between its samples
//! ([`crate::Reference::with_smoothed_velocity`]): the uniform cubic B-spline on the four samples
//! around each time.
//!
//! Linear interpolation keeps all of a sample's noise variance on a sample and half of it
//! half-way, with a kink at each sample: a fit that moves the comparison in time (a time offset)
//! is drawn to the sample times, the more so the noisier the reference. The B-spline keeps
//! between 0.46 and 0.5 of it at every fraction of the interval, varying smoothly; what it varies
//! by is given back to the fit ([`crate::Reference::interpolation_loss`]). Its kernel is
//! symmetric, so it moves nothing in time, but it smooths the motion: (2 + cos 2πν)/3 at ν cycles
//! per sample on a sample, 2 % at 0.06 cycles per sample. A sharpened kernel (the filter
//! [−1/6, 4/3, −1/6] before the spline, flat to the fourth order) keeps 0.62–0.72 of the noise,
//! and was measured worse on the lake run and on the simulated surface runs: the more the gain
//! varies, the more a misjudged noise variance moves the estimate.

/// The cubic B-spline's weights of the four samples around a fraction `f` of the middle interval
/// (the first weight is for the sample before that interval's start), and their derivatives in
/// `f`.
pub fn weights(f: f64) -> ([f64; 4], [f64; 4]) {
    let g = 1.0 - f;
    let (f2, f3) = (f * f, f * f * f);
    (
        [
            g * g * g / 6.0,
            (3.0 * f3 - 6.0 * f2 + 4.0) / 6.0,
            (-3.0 * f3 + 3.0 * f2 + 3.0 * f + 1.0) / 6.0,
            f3 / 6.0,
        ],
        [
            -g * g / 2.0,
            1.5 * f2 - 2.0 * f,
            -1.5 * f2 + f + 0.5,
            f2 / 2.0,
        ],
    )
}

/// The share of a sample's noise variance the kernel keeps at `f` (Σw²), its derivative in `f`,
/// and the noise variance its slope in `f` carries (Σw'²), for white sample noise.
pub fn noise_gain(f: f64) -> (f64, f64, f64) {
    let (w, d) = weights(f);
    let g = w.iter().map(|x| x * x).sum();
    let g1 = 2.0 * w.iter().zip(&d).map(|(a, b)| a * b).sum::<f64>();
    let slope = d.iter().map(|x| x * x).sum();
    (g, g1, slope)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_kernel_keeps_lines_and_its_noise_gain_varies_little_and_smoothly() {
        for i in 0..=20 {
            let f = f64::from(i) / 20.0;
            let (w, d) = weights(f);
            // Samples at −1 … 2 around the interval [0, 1].
            let x = |k: usize| k as f64 - 1.0;
            let sum: f64 = w.iter().sum();
            let line: f64 = (0..4).map(|k| w[k] * x(k)).sum();
            assert!((sum - 1.0).abs() < 1e-12, "{f}: {sum}");
            assert!((line - f).abs() < 1e-12, "{f}: {line}");
            assert!(d.iter().sum::<f64>().abs() < 1e-12);
            let slope: f64 = (0..4).map(|k| d[k] * x(k)).sum();
            assert!((slope - 1.0).abs() < 1e-12, "{f}: {slope}");
            let (g, _, _) = noise_gain(f);
            assert!((0.459..=0.5 + 1e-12).contains(&g), "{f}: {g}");
        }
        for f in [0.1, 0.37, 0.5, 0.8] {
            let e = 1e-6;
            let numeric = (noise_gain(f + e).0 - noise_gain(f - e).0) / (2.0 * e);
            assert!((numeric - noise_gain(f).1).abs() < 1e-8, "{f}");
        }
        // No kink at a sample: the gain's slope vanishes on both sides of it.
        assert!(noise_gain(0.0).1.abs() < 1e-12 && noise_gain(1.0).1.abs() < 1e-12);
        // Continuous across a sample: the end of one interval is the start of the next.
        let (end, _) = weights(1.0);
        let (start, _) = weights(0.0);
        assert!((0..3).all(|k| (end[k + 1] - start[k]).abs() < 1e-12) && start[3] == 0.0);
    }
}
