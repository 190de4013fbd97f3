//! `seed`: the S-CAL optimisation as published — a Latin hypercube over the bounds, a quadratic
//! response surface fitted to it, its optimum as the start of a particle swarm. Every candidate
//! is scored by full replay. Deterministic for a given `--seed` (the random streams are the
//! simulator's, seeded by name), whatever the number of threads.

use super::params::ParameterSet;
use super::{MethodResult, Problem};
use auvnav_sim::rng::Rng;
use nalgebra::{DMatrix, DVector};
use serde::Serialize;

/// Settings of the seed method.
#[derive(Debug, Clone, Copy, Serialize)]
pub struct SeedSettings {
    pub lhs_samples: usize,
    pub particles: usize,
    pub iterations: usize,
    /// Inertia weight and acceleration constants (c1, c2 in the seed's [1, 2]).
    pub inertia: f64,
    pub c1: f64,
    pub c2: f64,
    pub seed: u64,
}

impl Default for SeedSettings {
    fn default() -> Self {
        SeedSettings {
            lhs_samples: 100,
            particles: 20,
            iterations: 20,
            inertia: 0.72,
            c1: 1.49,
            c2: 1.49,
            seed: 1,
        }
    }
}

/// `n` Latin-hypercube points in the unit cube of dimension `d`.
pub fn latin_hypercube(n: usize, d: usize, rng: &mut Rng) -> Vec<Vec<f64>> {
    let mut columns = Vec::with_capacity(d);
    for _ in 0..d {
        let mut perm: Vec<usize> = (0..n).collect();
        for i in (1..n).rev() {
            let j = (rng.uniform() * (i + 1) as f64) as usize;
            perm.swap(i, j.min(i));
        }
        let column: Vec<f64> = perm
            .iter()
            .map(|p| (*p as f64 + rng.uniform()) / n as f64)
            .collect();
        columns.push(column);
    }
    (0..n)
        .map(|i| columns.iter().map(|c| c[i]).collect())
        .collect()
}

/// Terms of a full quadratic in `d` variables: 1, u_i, u_i u_j (i <= j).
fn quadratic_terms(u: &[f64]) -> Vec<f64> {
    let mut t = vec![1.0];
    t.extend_from_slice(u);
    for i in 0..u.len() {
        for j in i..u.len() {
            t.push(u[i] * u[j]);
        }
    }
    t
}

/// The least-squares quadratic response surface through (u, f) and its minimiser in the box
/// [-1, 1]^d: the stationary point when the surface is convex (clipped to the box), else `None`.
pub fn response_surface_optimum(points: &[Vec<f64>], values: &[f64]) -> Option<Vec<f64>> {
    let d = points.first()?.len();
    let rows: Vec<Vec<f64>> = points.iter().map(|u| quadratic_terms(u)).collect();
    let nt = rows[0].len();
    if rows.len() < nt {
        return None;
    }
    let a = DMatrix::from_fn(rows.len(), nt, |r, c| rows[r][c]);
    let b = DVector::from_column_slice(values);
    let coef = a.svd(true, true).solve(&b, 1e-12).ok()?;
    // f = c0 + g.u + u^T H u / 2
    let g = DVector::from_fn(d, |i, _| coef[1 + i]);
    let mut h = DMatrix::zeros(d, d);
    let mut k = 1 + d;
    for i in 0..d {
        for j in i..d {
            if i == j {
                h[(i, i)] = 2.0 * coef[k];
            } else {
                h[(i, j)] = coef[k];
                h[(j, i)] = coef[k];
            }
            k += 1;
        }
    }
    let chol = h.cholesky()?;
    let u = -chol.solve(&g);
    Some(u.iter().map(|x| x.clamp(-1.0, 1.0)).collect())
}

/// Runs the seed method.
pub fn calibrate(
    problem: &Problem,
    params: &ParameterSet,
    settings: &SeedSettings,
    progress: &mut dyn FnMut(&str, usize, usize),
) -> anyhow::Result<MethodResult> {
    let idx = params.estimated();
    let d = idx.len();
    let base = params.prior_vector();
    let to_x = |u: &[f64]| -> [f64; 8] {
        let mut x = base;
        for (k, &i) in idx.iter().enumerate() {
            let p = &params.all[i];
            x[i] = p.min + (u[k].clamp(-1.0, 1.0) + 1.0) * 0.5 * (p.max - p.min);
        }
        x
    };
    let total = settings.lhs_samples + 1 + settings.particles * settings.iterations;
    let mut history = Vec::new();
    let mut best = (f64::INFINITY, base);
    let note =
        |f: f64, x: [f64; 8], best: &mut (f64, [f64; 8]), history: &mut Vec<(usize, f64)>| {
            if f < best.0 {
                *best = (f, x);
            }
            history.push((problem.full_replays(), best.0));
        };

    // 1. Latin hypercube.
    let mut rng = Rng::new(settings.seed, "calibrate.lhs");
    let lhs: Vec<Vec<f64>> = latin_hypercube(settings.lhs_samples, d, &mut rng)
        .into_iter()
        .map(|p| p.iter().map(|v| 2.0 * v - 1.0).collect())
        .collect();
    progress("seed: Latin hypercube", 0, total);
    let xs: Vec<[f64; 8]> = lhs.iter().map(|u| to_x(u)).collect();
    let values = problem.objectives(&xs)?;
    for (x, f) in xs.iter().zip(&values) {
        note(*f, *x, &mut best, &mut history);
    }
    // 2. Response surface (on the finite values).
    let (pts, vals): (Vec<Vec<f64>>, Vec<f64>) = lhs
        .iter()
        .zip(&values)
        .filter(|(_, f)| f.is_finite())
        .map(|(u, f)| (u.clone(), *f))
        .unzip();
    let surface = response_surface_optimum(&pts, &vals);
    let mut notes = Vec::new();
    let start_u = match &surface {
        Some(u) => u.clone(),
        None => {
            notes.push(
                "the quadratic response surface is not convex; the swarm starts from the best Latin-hypercube sample"
                    .to_string(),
            );
            let k = (0..values.len())
                .min_by(|&a, &b| values[a].total_cmp(&values[b]))
                .unwrap_or(0);
            lhs[k].clone()
        }
    };
    let start_x = to_x(&start_u);
    let start_f = problem.objectives(&[start_x])?[0];
    note(start_f, start_x, &mut best, &mut history);
    let surface_optimum = (start_x, start_f);
    progress("seed: particle swarm", settings.lhs_samples + 1, total);

    // 3. Particle swarm from that start.
    let mut rng = Rng::new(settings.seed, "calibrate.pso");
    let n = settings.particles.max(1);
    let mut pos: Vec<Vec<f64>> = (0..n)
        .map(|k| {
            if k == 0 {
                start_u.clone()
            } else {
                (0..d).map(|_| 2.0 * rng.uniform() - 1.0).collect()
            }
        })
        .collect();
    let mut vel: Vec<Vec<f64>> = (0..n)
        .map(|_| (0..d).map(|_| 0.2 * (2.0 * rng.uniform() - 1.0)).collect())
        .collect();
    let xs: Vec<[f64; 8]> = pos.iter().map(|u| to_x(u)).collect();
    let mut f = problem.objectives(&xs[1..])?;
    f.insert(0, start_f);
    for (x, v) in xs.iter().zip(&f).skip(1) {
        note(*v, *x, &mut best, &mut history);
    }
    let mut pbest = pos.clone();
    let mut pbest_f = f.clone();
    let g = (0..n)
        .min_by(|&a, &b| pbest_f[a].total_cmp(&pbest_f[b]))
        .unwrap_or(0);
    let mut gbest = pbest[g].clone();
    let mut gbest_f = pbest_f[g];
    let mut stalled = 0;
    for it in 1..settings.iterations {
        for k in 0..n {
            for j in 0..d {
                let (r1, r2) = (rng.uniform(), rng.uniform());
                vel[k][j] = settings.inertia * vel[k][j]
                    + settings.c1 * r1 * (pbest[k][j] - pos[k][j])
                    + settings.c2 * r2 * (gbest[j] - pos[k][j]);
                vel[k][j] = vel[k][j].clamp(-1.0, 1.0);
                pos[k][j] = (pos[k][j] + vel[k][j]).clamp(-1.0, 1.0);
            }
        }
        let xs: Vec<[f64; 8]> = pos.iter().map(|u| to_x(u)).collect();
        let f = problem.objectives(&xs)?;
        let before = gbest_f;
        for k in 0..n {
            note(f[k], xs[k], &mut best, &mut history);
            if f[k] < pbest_f[k] {
                pbest_f[k] = f[k];
                pbest[k] = pos[k].clone();
                if f[k] < gbest_f {
                    gbest_f = f[k];
                    gbest = pos[k].clone();
                }
            }
        }
        let iterations_run = it + 1;
        progress(
            "seed: particle swarm",
            settings.lhs_samples + 1 + (it + 1) * n,
            total,
        );
        // Stop when, past half the iterations, five in a row improve the best by less than 0.1 %.
        if gbest_f > before * (1.0 - 1e-3) {
            stalled += 1;
            if stalled >= 5 && 2 * iterations_run >= settings.iterations {
                notes.push(format!(
                    "swarm stopped after {iterations_run} iterations: no 0.1 % improvement in five"
                ));
                break;
            }
        } else {
            stalled = 0;
        }
    }
    progress("seed: particle swarm", total, total);
    let mut r = MethodResult::new(best.1);
    r.history = history;
    r.notes = notes;
    r.surface_optimum = Some(surface_optimum);
    Ok(r)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn latin_hypercube_is_stratified_and_deterministic() {
        let a = latin_hypercube(10, 3, &mut Rng::new(7, "x"));
        let b = latin_hypercube(10, 3, &mut Rng::new(7, "x"));
        let c = latin_hypercube(10, 3, &mut Rng::new(8, "x"));
        assert_eq!(a, b);
        assert_ne!(a, c);
        for k in 0..3 {
            let mut bins: Vec<usize> = a.iter().map(|p| (p[k] * 10.0) as usize).collect();
            bins.sort();
            assert_eq!(bins, (0..10).collect::<Vec<_>>(), "one point per stratum");
        }
    }

    #[test]
    fn response_surface_finds_the_minimum_of_a_quadratic() {
        let pts = latin_hypercube(30, 2, &mut Rng::new(1, "rsm"));
        let pts: Vec<Vec<f64>> = pts
            .iter()
            .map(|p| vec![2.0 * p[0] - 1.0, 2.0 * p[1] - 1.0])
            .collect();
        let f: Vec<f64> = pts
            .iter()
            .map(|u| 3.0 + (u[0] - 0.3).powi(2) + 2.0 * (u[1] + 0.2).powi(2) + 0.5 * u[0] * u[1])
            .collect();
        let u = response_surface_optimum(&pts, &f).expect("convex");
        // Gradient zero: 2(u0 - 0.3) + 0.5 u1 = 0, 4(u1 + 0.2) + 0.5 u0 = 0.
        assert!((2.0 * (u[0] - 0.3) + 0.5 * u[1]).abs() < 1e-9);
        assert!((4.0 * (u[1] + 0.2) + 0.5 * u[0]).abs() < 1e-9);
        let concave: Vec<f64> = pts.iter().map(|u| -(u[0] * u[0])).collect();
        assert!(response_surface_optimum(&pts, &concave).is_none());
    }
}
