//! What an acoustic system does to its own fixes, from a log of its ranges and fixes: the
//! one-sigma it reports against the fixes' own scatter, and how its fixes compare with per-ping
//! least-squares fixes from its own ranges — smoothed by an exponential filter of the time
//! constant that matches them best (the simulator's `usbl.fix_time_constant`).

use auvnav_log::LogMessage;
use auvnav_shm_schema::AcousticRangesV1;
use nalgebra::{Matrix2, Vector2, Vector3};
use serde::Serialize;

/// Time constants tried for the device's smoothing (s).
const TIME_CONSTANTS_S: [f64; 10] = [0.0, 0.5, 1.0, 1.5, 2.0, 3.0, 4.0, 6.0, 8.0, 12.0];

/// Per-ping fixes farther than this from the device's (m) are left out of the comparison: the
/// least-squares solution failed (a bad range, a flat geometry).
const FAR_M: f64 = 10.0;

/// The device's fixes against its one-sigma and against per-ping fixes from its own ranges.
#[derive(Debug, Clone, Serialize)]
pub struct DeviceFixModel {
    /// Distinct fixes, and the median one-sigma the device reports for them (m).
    pub fixes: usize,
    pub reported_std_median_m: f64,
    /// White scatter of the device's fixes (m): robust (1.4826 × the median absolute second
    /// difference of consecutive fixes less than 3 s apart, over √1.5), along the line from the
    /// array to the vehicle (radial) and across it (tangential).
    pub scatter_radial_m: f64,
    pub scatter_tangential_m: f64,
    /// Per-ping least-squares fixes from the ranges (three or more) at the given receivers and
    /// the device's depth: how many, how many were left out (beyond 10 m of the device's), and
    /// their white scatter.
    pub ping_fixes: usize,
    pub ping_fixes_far: usize,
    pub ping_scatter_radial_m: f64,
    pub ping_scatter_tangential_m: f64,
    /// Median horizontal distance from the device's fixes to the per-ping fixes smoothed
    /// exponentially with each time constant tried: (s, m).
    pub smoothing_fit: Vec<(f64, f64)>,
    /// The time constant of the best fit (s).
    pub best_time_constant_s: f64,
}

fn median(v: &mut [f64]) -> f64 {
    if v.is_empty() {
        return f64::NAN;
    }
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

/// Robust white scatter of a series of horizontal fixes, radial and tangential to `dir`.
fn scatter(t: &[f64], p: &[Vector2<f64>], dir: &[Vector2<f64>]) -> (f64, f64) {
    let (mut radial, mut tangential) = (Vec::new(), Vec::new());
    for i in 1..p.len().saturating_sub(1) {
        if t[i + 1] - t[i - 1] >= 3.0 || dir[i].norm() < 1e-6 {
            continue;
        }
        let u = dir[i].normalize();
        let w = Vector2::new(-u.y, u.x);
        let e = p[i] - 0.5 * (p[i - 1] + p[i + 1]);
        radial.push(e.dot(&u).abs());
        tangential.push(e.dot(&w).abs());
    }
    let k = 1.4826 / 1.5f64.sqrt();
    (k * median(&mut radial), k * median(&mut tangential))
}

/// The horizontal least-squares fix of one update's ranges from `receivers` at depth `z`,
/// starting at `start` (Gauss–Newton); `None` with fewer than three ranges or a flat geometry.
fn ping_fix(
    m: &AcousticRangesV1,
    receivers: &[[f64; 3]],
    z: f64,
    start: Vector2<f64>,
) -> Option<Vector2<f64>> {
    let used: Vec<usize> = (0..receivers.len().min(4))
        .filter(|&k| m.range_valid(k))
        .collect();
    if used.len() < 3 {
        return None;
    }
    let mut p = start;
    for _ in 0..20 {
        let (mut info, mut b) = (Matrix2::zeros(), Vector2::zeros());
        for &k in &used {
            let d = Vector3::new(p.x, p.y, z) - Vector3::from(receivers[k]);
            let r = d.norm().max(1e-3);
            let g = d.xy() / r;
            info += g * g.transpose();
            b += g * (m.range_m[k] - r);
        }
        let step = info.try_inverse()? * b;
        p += step;
        if step.norm() < 1e-4 {
            return Some(p);
        }
    }
    p.iter().all(|x| x.is_finite()).then_some(p)
}

/// The device's fixes in `messages` (distinct ones, in the array frame) against its reported
/// one-sigma and against per-ping fixes from its ranges at `receivers` (array frame, m).
pub fn device_fix_model(messages: &[LogMessage], receivers: &[[f64; 3]]) -> DeviceFixModel {
    let mut fixes: Vec<&AcousticRangesV1> = Vec::new();
    for m in messages {
        if let LogMessage::AcousticRanges(r) = m
            && r.validity & AcousticRangesV1::VALID_POSITION != 0
            && fixes
                .last()
                .is_none_or(|f| f.position_array_m != r.position_array_m)
        {
            fixes.push(r);
        }
    }
    let t: Vec<f64> = fixes.iter().map(|f| f.host_time_ns as f64 * 1e-9).collect();
    let device: Vec<Vector2<f64>> = fixes
        .iter()
        .map(|f| Vector2::new(f.position_array_m[0], f.position_array_m[1]))
        .collect();
    let (scatter_radial_m, scatter_tangential_m) = scatter(&t, &device, &device);
    let mut stds: Vec<f64> = fixes
        .iter()
        .map(|f| f64::from(f.position_std_m))
        .filter(|s| s.is_finite())
        .collect();
    // Per-ping fixes beside the device's.
    let (mut tp, mut dp, mut lp) = (Vec::new(), Vec::new(), Vec::new());
    let mut far = 0;
    for (i, f) in fixes.iter().enumerate() {
        let Some(p) = ping_fix(f, receivers, f.position_array_m[2], device[i]) else {
            continue;
        };
        if (p - device[i]).norm() > FAR_M {
            far += 1;
            continue;
        }
        tp.push(t[i]);
        dp.push(device[i]);
        lp.push(p);
    }
    let (ping_scatter_radial_m, ping_scatter_tangential_m) = scatter(&tp, &lp, &dp);
    let smoothing_fit: Vec<(f64, f64)> = TIME_CONSTANTS_S
        .iter()
        .map(|&tau| {
            let mut s = lp.first().copied().unwrap_or_default();
            let mut d: Vec<f64> = Vec::with_capacity(lp.len());
            for i in 0..lp.len() {
                let dt = if i == 0 {
                    f64::INFINITY
                } else {
                    tp[i] - tp[i - 1]
                };
                s = if tau > 0.0 && dt < 5.0 * tau {
                    s + (lp[i] - s) * (1.0 - (-dt / tau).exp())
                } else {
                    lp[i]
                };
                d.push((s - dp[i]).norm());
            }
            (tau, median(&mut d))
        })
        .collect();
    let best_time_constant_s = smoothing_fit
        .iter()
        .filter(|x| x.1.is_finite())
        .min_by(|a, b| a.1.total_cmp(&b.1))
        .map_or(f64::NAN, |x| x.0);
    DeviceFixModel {
        fixes: fixes.len(),
        reported_std_median_m: median(&mut stds),
        scatter_radial_m,
        scatter_tangential_m,
        ping_fixes: lp.len(),
        ping_fixes_far: far,
        ping_scatter_radial_m,
        ping_scatter_tangential_m,
        smoothing_fit,
        best_time_constant_s,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A simulated survey under a four-receiver array whose device smooths its fixes with 3 s
    /// (`usbl.fix_time_constant`), with the scenario's range noise and without outliers: the
    /// per-ping fixes rebuilt from its ranges, smoothed, match its fixes best at 3 s, and its
    /// fixes scatter less than the per-ping ones.
    #[test]
    fn the_smoothing_of_a_simulated_device_is_found() {
        let scenario = auvnav_sim::scenario::Scenario::load("ranges_array").expect("scenario");
        let receivers: Vec<[f64; 3]> = scenario
            .acoustic
            .as_ref()
            .expect("an acoustic system")
            .receivers()
            .iter()
            .map(|r| [r.x, r.y, r.z])
            .collect();
        let mut effects = scenario.effects().expect("the scenario's effects");
        effects
            .set("usbl.fix_time_constant", &[3.0])
            .expect("effect");
        effects
            .set("usbl.outlier_fraction", &[0.0])
            .expect("effect");
        effects.set("usbl.dropout", &[0.0]).expect("effect");
        let cfg = auvnav_sim::SimConfig {
            scenario,
            effects,
            seed: 3,
            duration_s: Some(300.0),
        };
        let (messages, _) = auvnav_sim::simulate_to_vec(&cfg).expect("simulate");
        let m = device_fix_model(&messages, &receivers);
        assert!(m.ping_fixes > 250, "{m:?}");
        assert_eq!(m.best_time_constant_s, 3.0, "{m:?}");
        let at_best = m.smoothing_fit.iter().find(|x| x.0 == 3.0).expect("3 s").1;
        // Exact but for the solvers' stopping rules (a step under 0.1 mm).
        assert!(at_best < 1e-3, "{m:?}");
        assert!(
            m.scatter_tangential_m < 0.5 * m.ping_scatter_tangential_m,
            "{m:?}"
        );
    }
}
