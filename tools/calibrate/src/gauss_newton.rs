//! `fast`: Gauss–Newton on the position residuals at the fixes, with sensitivities from the
//! replay itself, a prior on every parameter, and an observability test that holds what the
//! voyages cannot determine at its prior.
//!
//! Why this method: the S-CAL objective is a smooth function of the installation (the dead
//! reckoning's position is, to first order, the integral of `C_b^n (C_d^b z / s − ω × l + τ a_b)`
//! over the DVL epochs), so the residual vector's Jacobian is nearly constant and a few
//! Gauss–Newton steps reach the optimum that a swarm needs hundreds of replays to approach. Each
//! iteration costs one full replay of every voyage (in parallel): the residuals come from the
//! replay, the Jacobian from the same replay's DVL epochs — the navigator's attitude, rates and
//! velocity at each DVL epoch, with the position sensitivity accumulated epoch by epoch
//! (a surrogate of the replay, re-checked by the next replay, so its approximation only affects
//! the convergence rate, never the reported objective). The Jacobian also gives what the swarm
//! cannot: a standard deviation per parameter, the correlations, and whether the voyages
//! determine a parameter at all.
//!
//! Noise model: the residuals `e = (δN, δE) / D` at the fixes are correlated along a voyage (a
//! dead-reckoning error is a random walk), so their variance is estimated from the fit's residual
//! sum of squares over an effective number of independent residuals (per voyage and axis,
//! `N (1 − ρ) / (1 + ρ)` from the lag-one autocorrelation ρ). A parameter counts as determined
//! when the data shrink its prior standard deviation by more than half; otherwise it is held at
//! its prior and reported so. Parameters the data cannot separate (|correlation| > 0.95) are
//! listed as pairs.

use super::objective::{DvlEpoch, Record, VoyageRun};
use super::params::ParameterSet;
use super::{MethodResult, Problem};
use nalgebra::{DMatrix, DVector, Matrix3, Rotation3, Vector3};

/// A parameter is determined when its posterior std is below this fraction of its prior std.
pub const DETERMINED_RATIO: f64 = 0.5;
/// Correlation above which two parameters are reported as not separable.
pub const INSEPARABLE_CORRELATION: f64 = 0.95;
const MAX_ITERATIONS: usize = 8;

/// The implied body velocity of a DVL measurement under the installation `x`:
/// `C_d^b z / s − ω × l + τ a_b` (the inverse of the core's DVL model to first order in τ).
fn body_velocity(
    x: &[f64; 8],
    z: &Vector3<f64>,
    omega: &Vector3<f64>,
    a_b: &Vector3<f64>,
) -> Vector3<f64> {
    let c: Matrix3<f64> =
        Rotation3::from_euler_angles(x[0].to_radians(), x[1].to_radians(), x[2].to_radians())
            .into_inner();
    c * z / x[3] - omega.cross(&Vector3::new(x[4], x[5], x[6])) + x[7] * a_b
}

/// Body-frame accelerations at the epochs (central differences of the body velocity).
fn accelerations(epochs: &[DvlEpoch]) -> Vec<Vector3<f64>> {
    let n = epochs.len();
    (0..n)
        .map(|k| {
            let (a, b) = (k.saturating_sub(1), (k + 1).min(n - 1));
            let dt = epochs[b].t_s - epochs[a].t_s;
            if dt > 0.0 && dt < 10.0 {
                (epochs[b].v_body - epochs[a].v_body) / dt
            } else {
                Vector3::zeros()
            }
        })
        .collect()
}

/// Sensitivity of the horizontal position at each fix time (rows 2i, 2i+1: north, east) to each
/// of the parameters `idx` (columns), in metres per parameter unit.
fn position_sensitivity(
    epochs: &[DvlEpoch],
    fix_times_s: &[f64],
    x: &[f64; 8],
    idx: &[usize],
    steps: &[f64],
) -> DMatrix<f64> {
    let acc = accelerations(epochs);
    let mut out = DMatrix::zeros(2 * fix_times_s.len(), idx.len());
    // Per epoch: d(v^n)/d(theta_j) (horizontal), held until the next epoch.
    let rates: Vec<Vec<[f64; 2]>> = epochs
        .iter()
        .zip(&acc)
        .map(|(e, a)| {
            idx.iter()
                .zip(steps)
                .map(|(&j, &h)| {
                    let (mut xp, mut xm) = (*x, *x);
                    xp[j] += h;
                    xm[j] -= h;
                    let d = (body_velocity(&xp, &e.z, &e.omega_body, a)
                        - body_velocity(&xm, &e.z, &e.omega_body, a))
                        / (2.0 * h);
                    let n = e.c_body_to_ned * d;
                    [n.x, n.y]
                })
                .collect()
        })
        .collect();
    let mut cum = vec![[0.0f64; 2]; idx.len()];
    let mut k = 0usize;
    let mut t_prev = epochs.first().map(|e| e.t_s).unwrap_or(0.0);
    for (i, &tf) in fix_times_s.iter().enumerate() {
        // Integrate the held rates up to the fix time.
        while k < epochs.len() && epochs[k].t_s <= tf {
            let t_next = epochs.get(k + 1).map(|e| e.t_s.min(tf)).unwrap_or(tf);
            let dt = (t_next - epochs[k].t_s.max(t_prev)).max(0.0);
            for (c, r) in cum.iter_mut().zip(&rates[k]) {
                c[0] += r[0] * dt;
                c[1] += r[1] * dt;
            }
            t_prev = t_next;
            if epochs.get(k + 1).is_some_and(|e| e.t_s <= tf) {
                k += 1;
            } else {
                break;
            }
        }
        for (j, c) in cum.iter().enumerate() {
            out[(2 * i, j)] = c[0];
            out[(2 * i + 1, j)] = c[1];
        }
    }
    out
}

/// Residuals (weighted so that their sum of squares is the mean over voyages of the mean over
/// points of (δD/D)²), their Jacobian w.r.t. the parameters `idx`, and the effective number of
/// independent residuals.
struct Linearisation {
    e: DVector<f64>,
    j: DMatrix<f64>,
    m_eff: f64,
}

fn linearise(
    problem: &Problem,
    runs: &[VoyageRun],
    x: &[f64; 8],
    idx: &[usize],
    steps: &[f64],
) -> Linearisation {
    let mut rows_e = Vec::new();
    let mut rows_j: Vec<Vec<f64>> = Vec::new();
    let mut m_eff = 0.0;
    let nv = problem.voyages.len() as f64;
    for (v, run) in problem.voyages.iter().zip(runs) {
        let keep: Vec<usize> = (0..v.fixes.len())
            .filter(|&i| {
                v.fixes[i].distance_m >= problem.threshold_m
                    && v.fixes[i].distance_m > 0.0
                    && i < run.errors_ne.len()
            })
            .collect();
        if keep.is_empty() {
            continue;
        }
        let times: Vec<f64> = keep
            .iter()
            .map(|&i| v.fixes[i].time_ns as f64 * 1e-9)
            .collect();
        let s = position_sensitivity(&run.epochs, &times, x, idx, steps);
        let w = 1.0 / (nv * keep.len() as f64).sqrt();
        let mut series = [Vec::new(), Vec::new()];
        for (r, &i) in keep.iter().enumerate() {
            let d = v.fixes[i].distance_m;
            for axis in 0..2 {
                let e = run.errors_ne[i][axis] / d;
                series[axis].push(e);
                rows_e.push(e * w);
                rows_j.push(
                    (0..idx.len())
                        .map(|c| s[(2 * r + axis, c)] / d * w)
                        .collect(),
                );
            }
        }
        for s in &series {
            m_eff += effective_count(s);
        }
    }
    let m = rows_e.len();
    let mut j = DMatrix::zeros(m, idx.len());
    for (r, row) in rows_j.iter().enumerate() {
        for (c, v) in row.iter().enumerate() {
            j[(r, c)] = *v;
        }
    }
    Linearisation {
        e: DVector::from_vec(rows_e),
        j,
        m_eff,
    }
}

/// `N (1 − ρ) / (1 + ρ)` with the lag-one autocorrelation ρ (clamped to 0..1), at least 1.
/// ρ is taken about zero, not about the mean, so an error common to a voyage's fixes (a
/// dead-reckoning offset seen by every end fix) counts once, not once per fix.
fn effective_count(s: &[f64]) -> f64 {
    let n = s.len();
    if n < 3 {
        return n as f64;
    }
    let var: f64 = s.iter().map(|x| x * x).sum();
    if var <= 0.0 {
        return 1.0;
    }
    let cov: f64 = s.windows(2).map(|w| w[0] * w[1]).sum();
    let rho = (cov / var).clamp(0.0, 0.999);
    (n as f64 * (1.0 - rho) / (1.0 + rho)).max(1.0)
}

/// Sum of squares of the weighted residuals of full-replay runs (the quantity Gauss–Newton
/// minimises).
fn sum_of_squares(problem: &Problem, runs: &[VoyageRun]) -> f64 {
    let nv = problem.voyages.len() as f64;
    problem
        .voyages
        .iter()
        .zip(runs)
        .map(|(v, r)| {
            let pts = r.scored(&v.fixes, problem.threshold_m);
            if pts.is_empty() {
                return 0.0;
            }
            pts.iter().map(|(e, d)| (e / d).powi(2)).sum::<f64>() / (pts.len() as f64 * nv)
        })
        .sum()
}

/// A MAP Gauss–Newton step and the posterior covariance of the parameters it moves.
struct Step {
    delta: DVector<f64>,
    covariance: DMatrix<f64>,
}

/// One MAP Gauss–Newton step on the parameters `sel` (positions in `idx`), in units scaled by
/// the prior std, with residual variance `sigma2`.
fn map_step(
    lin: &Linearisation,
    sel: &[usize],
    x: &[f64; 8],
    idx: &[usize],
    params: &ParameterSet,
    sigma2: f64,
) -> Option<Step> {
    let n = sel.len();
    let mut jt = DMatrix::zeros(lin.j.nrows(), n);
    let mut prior_std = DVector::zeros(n);
    let mut offset = DVector::zeros(n);
    for (c, &s) in sel.iter().enumerate() {
        let p = &params.all[idx[s]];
        prior_std[c] = p.prior_std;
        offset[c] = (x[idx[s]] - p.prior) / p.prior_std;
        jt.set_column(c, &(lin.j.column(s) * p.prior_std));
    }
    let info = jt.transpose() * &jt / sigma2 + DMatrix::identity(n, n);
    let grad = jt.transpose() * &lin.e / sigma2 + &offset;
    let chol = info.clone().cholesky()?;
    let delta_scaled = -chol.solve(&grad);
    let cov_scaled = chol.inverse();
    let delta = delta_scaled.component_mul(&prior_std);
    let d = DMatrix::from_diagonal(&prior_std);
    Some(Step {
        delta,
        covariance: &d * cov_scaled * &d,
    })
}

/// The residual variance a full least-squares fit of `p` parameters would leave (linear
/// prediction, singular directions truncated) per effective independent residual:
/// `SSR / (m_eff - p)`, so that `sigma2 (J^T J)^-1` is the parameter covariance.
fn predicted_sigma2(lin: &Linearisation, p: usize) -> f64 {
    let svd = lin.j.clone().svd(true, true);
    let fitted = svd
        .solve(&lin.e, 1e-9 * svd.singular_values.max())
        .map(|d| &lin.e - &lin.j * d)
        .unwrap_or_else(|_| lin.e.clone());
    let dof = (lin.m_eff - p as f64).max(1.0);
    (fitted.norm_squared() / dof).max(1e-30)
}

/// Standard deviations, observability and inseparable pairs of the estimated parameters at `x`.
#[derive(Debug, Clone, Default)]
pub struct Analysis {
    pub std: Vec<(usize, f64)>,
    pub determined: Vec<(usize, bool)>,
    pub inseparable: Vec<(String, String, f64)>,
}

fn analysis_of(params: &ParameterSet, idx: &[usize], cov: &DMatrix<f64>) -> Analysis {
    let stds: Vec<f64> = (0..idx.len()).map(|c| cov[(c, c)].sqrt()).collect();
    let mut inseparable = Vec::new();
    for a in 0..idx.len() {
        for b in a + 1..idx.len() {
            let r = cov[(a, b)] / (stds[a] * stds[b]);
            if r.abs() > INSEPARABLE_CORRELATION {
                inseparable.push((
                    params.all[idx[a]].name.to_string(),
                    params.all[idx[b]].name.to_string(),
                    r,
                ));
            }
        }
    }
    Analysis {
        std: idx.iter().zip(&stds).map(|(&i, &s)| (i, s)).collect(),
        determined: idx
            .iter()
            .zip(&stds)
            .map(|(&i, &s)| (i, s < DETERMINED_RATIO * params.all[i].prior_std))
            .collect(),
        inseparable,
    }
}

/// The observability analysis at `x` from runs recorded with their DVL epochs (used for the
/// results of the other methods).
pub fn analyse(
    problem: &Problem,
    params: &ParameterSet,
    runs: &[VoyageRun],
    x: &[f64; 8],
) -> anyhow::Result<Analysis> {
    let idx = params.estimated();
    let steps: Vec<f64> = idx.iter().map(|&i| params.all[i].step).collect();
    let lin = linearise(problem, runs, x, &idx, &steps);
    if lin.e.is_empty() {
        anyhow::bail!("no fix beyond the distance threshold in any voyage");
    }
    let sigma2 = predicted_sigma2(&lin, idx.len());
    let all: Vec<usize> = (0..idx.len()).collect();
    let step = map_step(&lin, &all, x, &idx, params, sigma2)
        .ok_or_else(|| anyhow::anyhow!("the normal equations are singular"))?;
    Ok(analysis_of(params, &idx, &step.covariance))
}

/// Runs the fast method from the priors.
pub fn calibrate(
    problem: &Problem,
    params: &ParameterSet,
    progress: &mut dyn FnMut(&str, usize, usize),
) -> anyhow::Result<MethodResult> {
    let idx = params.estimated();
    let steps: Vec<f64> = idx.iter().map(|&i| params.all[i].step).collect();
    let mut x = params.prior_vector();
    let record = Record {
        track: false,
        epochs: true,
    };
    let mut eval = problem.evaluate(&x, record)?;
    let mut history = vec![(problem.full_replays(), eval.objective)];
    let mut sse = sum_of_squares(problem, &eval.runs);
    let mut notes = Vec::new();
    let mut determined: Vec<bool> = vec![true; idx.len()];
    let mut last_cov = DMatrix::zeros(idx.len(), idx.len());
    let mut surrogate_jacobians = 0usize;
    for iteration in 0..MAX_ITERATIONS {
        progress("fast: Gauss-Newton", iteration, MAX_ITERATIONS);
        let lin = linearise(problem, &eval.runs, &x, &idx, &steps);
        surrogate_jacobians += 1;
        if lin.e.is_empty() {
            anyhow::bail!("no fix beyond the distance threshold in any voyage");
        }
        let sigma2 = predicted_sigma2(&lin, idx.len());
        // Observability with every estimated parameter free.
        let all: Vec<usize> = (0..idx.len()).collect();
        let full = map_step(&lin, &all, &x, &idx, params, sigma2)
            .ok_or_else(|| anyhow::anyhow!("the normal equations are singular"))?;
        for (c, d) in determined.iter_mut().enumerate() {
            *d = full.covariance[(c, c)].sqrt() < DETERMINED_RATIO * params.all[idx[c]].prior_std;
        }
        let sel: Vec<usize> = (0..idx.len()).filter(|&c| determined[c]).collect();
        last_cov = full.covariance.clone();
        // Held parameters go back to their prior.
        let mut candidate = x;
        for (c, &i) in idx.iter().enumerate() {
            if !determined[c] {
                candidate[i] = params.all[i].prior;
            }
        }
        if sel.is_empty() {
            notes.push("the voyages determine none of the estimated parameters".into());
            x = candidate;
            break;
        }
        let Some(step) = map_step(&lin, &sel, &candidate, &idx, params, sigma2) else {
            anyhow::bail!("the normal equations are singular");
        };
        // Accept the step if the full replay agrees; otherwise halve it (twice at most).
        let mut accepted = false;
        let mut scale = 1.0;
        let mut small = true;
        for _ in 0..3 {
            let mut trial = candidate;
            for (c, &s) in sel.iter().enumerate() {
                let i = idx[s];
                let p = &params.all[i];
                trial[i] = (candidate[i] + scale * step.delta[c]).clamp(p.min, p.max);
                if (scale * step.delta[c]).abs() > 0.05 * step.covariance[(c, c)].sqrt() {
                    small = false;
                }
            }
            let e = problem.evaluate(&trial, record)?;
            let s = sum_of_squares(problem, &e.runs);
            history.push((problem.full_replays(), e.objective));
            if s <= sse * (1.0 + 1e-9) {
                x = trial;
                eval = e;
                sse = s;
                accepted = true;
                break;
            }
            scale *= 0.5;
        }
        if !accepted {
            notes.push(format!(
                "iteration {}: no step lowered the full-replay residuals; stopped",
                iteration + 1
            ));
            break;
        }
        if small {
            break;
        }
    }
    progress("fast: Gauss-Newton", MAX_ITERATIONS, MAX_ITERATIONS);
    let a = analysis_of(params, &idx, &last_cov);
    let mut r = MethodResult::new(x);
    r.std = a.std;
    r.determined = idx.iter().zip(&determined).map(|(&i, &d)| (i, d)).collect();
    r.inseparable = a.inseparable;
    r.history = history;
    r.surrogate_evaluations = surrogate_jacobians;
    r.notes = notes;
    Ok(r)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn effective_count_falls_with_correlation() {
        let white: Vec<f64> = (0..100)
            .map(|i| if i % 2 == 0 { 1.0 } else { -1.0 })
            .collect();
        assert_eq!(effective_count(&white), 100.0);
        let walk: Vec<f64> = (0..100).map(|i| i as f64).collect();
        assert!(effective_count(&walk) < 2.0);
    }

    #[test]
    fn yaw_sensitivity_is_the_cross_track_distance() {
        // 100 s east at 2 m/s, level: a mounting yaw of +1 deg turns the implied body
        // velocity by +1 deg to starboard, which is south when heading east: 200 m * pi/180
        // south per degree.
        let epochs: Vec<DvlEpoch> = (0..=100)
            .map(|k| DvlEpoch {
                t_s: k as f64,
                z: Vector3::new(2.0, 0.0, 0.0),
                c_body_to_ned: Rotation3::from_euler_angles(0.0, 0.0, std::f64::consts::FRAC_PI_2)
                    .into_inner(),
                omega_body: Vector3::zeros(),
                v_body: Vector3::new(2.0, 0.0, 0.0),
            })
            .collect();
        let x = [0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0];
        let s = position_sensitivity(&epochs, &[100.0], &x, &[2, 3], &[0.01, 1e-5]);
        let per_deg = 200.0 * std::f64::consts::PI / 180.0;
        assert!(
            (s[(0, 0)] + per_deg).abs() < 1e-3,
            "north per deg {}",
            s[(0, 0)]
        );
        assert!(s[(1, 0)].abs() < 1e-6);
        // Scale: v / s, so d(east)/ds = -200 m per unit scale.
        assert!((s[(1, 1)] + 200.0).abs() < 1e-3, "{}", s[(1, 1)]);
    }
}
