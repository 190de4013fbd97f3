//! What a residual series looks like: level, spread, whiteness (Ljung–Box), its strongest
//! periodic component, and its correlation with the motion.

use serde::Serialize;

/// Lags of the Ljung–Box statistic.
pub const LAGS: usize = 20;
/// χ²(20) at 99 %: a Ljung–Box Q above this says the residual is not white.
pub const CHI2_20_99: f64 = 37.566;

/// The description of one residual component.
#[derive(Debug, Clone, Serialize)]
pub struct Description {
    pub mean: f64,
    pub std: f64,
    pub rms: f64,
    /// Autocorrelation at lag 1 (epochs).
    pub lag1: f64,
    /// Ljung–Box Q over [`LAGS`] lags.
    pub ljung_box_q: f64,
    pub white: bool,
    /// The strongest spectral line (Hz) when its power exceeds ten times the median.
    pub peak_hz: Option<f64>,
    /// Motion regressors with |correlation| ≥ 0.3: (name, correlation).
    pub correlated_with: Vec<(String, f64)>,
}

/// Describes `r` sampled at `t` (s), against named regressors sampled at the same epochs.
pub fn describe(t: &[f64], r: &[f64], regressors: &[(&str, Vec<f64>)]) -> Description {
    let n = r.len();
    let mean = r.iter().sum::<f64>() / n.max(1) as f64;
    let var = r.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / n.max(1) as f64;
    let rms = (r.iter().map(|x| x * x).sum::<f64>() / n.max(1) as f64).sqrt();
    let acf = |lag: usize| -> f64 {
        if var <= 0.0 || lag >= n {
            return 0.0;
        }
        let s: f64 = (0..n - lag)
            .map(|i| (r[i] - mean) * (r[i + lag] - mean))
            .sum();
        s / (n as f64 * var)
    };
    let lags = LAGS.min(n.saturating_sub(2));
    let q = n as f64
        * (n as f64 + 2.0)
        * (1..=lags)
            .map(|k| acf(k).powi(2) / (n - k) as f64)
            .sum::<f64>();
    Description {
        mean,
        std: var.sqrt(),
        rms,
        lag1: acf(1),
        ljung_box_q: q,
        white: q < CHI2_20_99,
        peak_hz: spectral_peak(t, r),
        correlated_with: regressors
            .iter()
            .filter_map(|(name, x)| {
                let c = correlation(x, r);
                (c.abs() >= 0.3).then(|| (name.to_string(), c))
            })
            .collect(),
    }
}

/// Pearson correlation (0 when either series is constant).
pub fn correlation(x: &[f64], y: &[f64]) -> f64 {
    let n = x.len().min(y.len());
    if n < 3 {
        return 0.0;
    }
    let (mx, my) = (
        x[..n].iter().sum::<f64>() / n as f64,
        y[..n].iter().sum::<f64>() / n as f64,
    );
    let (mut sxy, mut sxx, mut syy) = (0.0, 0.0, 0.0);
    for i in 0..n {
        let (a, b) = (x[i] - mx, y[i] - my);
        sxy += a * b;
        sxx += a * a;
        syy += b * b;
    }
    if sxx <= 0.0 || syy <= 0.0 {
        0.0
    } else {
        sxy / (sxx * syy).sqrt()
    }
}

/// The periodogram of `r` (mean removed): at most 512 points, evenly resampled by index; 128
/// frequencies up to the Nyquist frequency of the mean interval. Empty for fewer than 32 points
/// or no time span.
pub fn periodogram(t: &[f64], r: &[f64]) -> Vec<(f64, f64)> {
    periodogram_up_to(t, r, None)
}

/// The Nyquist frequency [`periodogram`] uses for times `t` (None: fewer than 32 or no span).
pub fn periodogram_nyquist(t: &[f64]) -> Option<f64> {
    let n = t.len();
    if n < 32 {
        return None;
    }
    let stride = n.div_ceil(512);
    let dt = (t[n - 1] - t[0]) / (n - 1) as f64 * stride as f64;
    (dt > 0.0).then(|| 0.5 / dt)
}

/// [`periodogram`] on 128 frequencies up to `nyquist` (None: the series' own), so that series
/// with different gaps share one frequency grid.
pub fn periodogram_up_to(t: &[f64], r: &[f64], nyquist: Option<f64>) -> Vec<(f64, f64)> {
    let n = r.len().min(t.len());
    let Some(own) = periodogram_nyquist(&t[..n]) else {
        return Vec::new();
    };
    let nyquist = nyquist.unwrap_or(own);
    let mean = r[..n].iter().sum::<f64>() / n as f64;
    let idx: Vec<usize> = (0..n).step_by(n.div_ceil(512)).collect();
    (1..=128)
        .map(|k| {
            let f = nyquist * k as f64 / 128.0;
            let (mut c, mut s) = (0.0, 0.0);
            for &i in &idx {
                let ph = 2.0 * std::f64::consts::PI * f * (t[i] - t[0]);
                c += (r[i] - mean) * ph.cos();
                s += (r[i] - mean) * ph.sin();
            }
            (f, (c * c + s * s) / idx.len() as f64)
        })
        .collect()
}

/// The strongest line of the [`periodogram`], when it stands ten times above the median power.
fn spectral_peak(t: &[f64], r: &[f64]) -> Option<f64> {
    let power = periodogram(t, r);
    let mut sorted: Vec<f64> = power.iter().map(|p| p.1).collect();
    sorted.sort_by(f64::total_cmp);
    let median = *sorted.get(sorted.len() / 2)?;
    let &(f, p) = power.iter().max_by(|a, b| a.1.total_cmp(&b.1))?;
    (p > 10.0 * median && median > 0.0).then_some(f)
}
