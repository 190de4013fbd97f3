//! Estimating candidate effects on one channel, choosing them by held-out score, and checking
//! which ones the motion can tell apart.
//!
//! The residual is measured − predicted (the simulator's sensor model under the effects) over
//! the channel's epochs. A set of effects is fitted by Gauss–Newton with numerical derivatives
//! (each effect's step in its own unit), started from the nominal values. The held-out score is
//! the mean squared residual over five contiguous time blocks, each predicted by a fit on the
//! other four. Forward selection adds, one at a time, the candidate that lowers the held-out score
//! most, and keeps it only when the score drops by at least [`Selection::min_gain`] and the
//! estimate lies at least [`Selection::min_sigma`] standard deviations from its nominal value.
//!
//! Long on purpose: the fit, the held-out selection and the separability check share the channel's
//! epochs, design and prior: three steps of one estimator.

use super::noise::{GaussMarkov, restricted_gauss_markov_from, restricted_gauss_markov_shared};
use super::{CANDIDATES, Candidate, Channel, ChannelKind, Reference, spec};
use auvnav_sim::effects::Effects;
use nalgebra::{DMatrix, DVector};

/// The data one channel's fits run on.
pub struct Problem<'a> {
    pub channel: &'a Channel,
    /// The reference as given, or with its velocity smoothed where the DVL channel's reference
    /// carries noise of its own ([`Reference::with_smoothed_velocity`]).
    pub reference: std::borrow::Cow<'a, Reference>,
    /// The nominal model (what the simulation assumes before discovery).
    pub nominal: Effects,
    /// Epochs the nominal model can predict (indices into the channel).
    pub epochs: Vec<usize>,
    /// Readings over which the channel's noise stays correlated: of the residual with every
    /// candidate fitted, so that an effect a set leaves out is not taken for correlated noise
    /// (which would widen the deviations of the effects in the set and stop the selection).
    pub noise_lags: usize,
    /// Per component, the Gauss–Markov error and white noise of the same residual (its
    /// variance, the white variance and φ per reading; None where it shows no correlated part):
    /// by [`restricted_gauss_markov`] with the candidates' design and the drift nuisance's.
    pub noise_model: Vec<Option<(f64, f64, f64)>>,
    /// An IMU whose residual drifts: a slowly varying bias per axis (piecewise linear in time,
    /// knots this many seconds apart) is taken out of every residual as a nuisance, its
    /// constant part left to the bias candidate ([`remove_drift`]).
    pub drift_knot_s: Option<f64>,
    /// The DVL channel's reference velocity noise from sample to sample, summed over its
    /// components ((m/s)²; [`crate::reference_noise`]), which the time offset's fit gives back
    /// what interpolation takes of; 0 elsewhere.
    pub reference_noise: f64,
}

/// Knot spacing of the drifting IMU bias taken out as a nuisance (s).
pub const DRIFT_KNOT_S: f64 = 90.0;

impl<'a> Problem<'a> {
    pub fn new(channel: &'a Channel, reference: &'a Reference, nominal: Effects) -> Problem<'a> {
        let mut nominal = nominal;
        if let Some(line) = channel.periodic_line.filter(|l| l.stands_out()) {
            // The line's period and phase: the candidate's amplitudes are fitted at them.
            nominal.dvl_periodic_velocity_error_period = line.period_s;
            nominal.dvl_periodic_velocity_error_phase = line.phase_deg;
        }
        let d = channel.kind.dims();
        let predicted = |reference: &Reference, i: usize| {
            channel.residual(&nominal, reference, i).is_some_and(|r| {
                if channel.kind.partial() {
                    r[..d].iter().any(|x| x.is_finite())
                } else {
                    r[..d].iter().all(|x| x.is_finite())
                }
            })
        };
        let mut epochs: Vec<usize> = (0..channel.len())
            .filter(|&i| predicted(reference, i))
            .collect();
        let mut reference = std::borrow::Cow::Borrowed(reference);
        let mut reference_noise = 0.0;
        if channel.kind == ChannelKind::Dvl {
            reference_noise =
                super::reference_noise::velocity_noise(channel, &reference, &nominal, &epochs);
            if reference_noise > 0.0 {
                reference = std::borrow::Cow::Owned(reference.with_smoothed_velocity());
                epochs.retain(|&i| predicted(&reference, i));
            }
        }
        let mut p = Problem {
            channel,
            reference,
            nominal,
            epochs,
            noise_lags: 0,
            noise_model: vec![None; d],
            drift_knot_s: None,
            reference_noise,
        };
        let all = p.candidates();
        if !all.is_empty() && p.epochs.len() >= 8 {
            p.fit_noise(&all);
            // An IMU's bias drifts (its datasheet's bias instability): where the residual shows
            // a correlated part, the drift is a nuisance of the fit rather than noise whose
            // long-run variance a few minutes of data cannot pin down, so that a scale factor
            // or a misalignment is named only for what a slowly varying bias cannot explain.
            if matches!(
                p.channel.kind,
                ChannelKind::Gyro | ChannelKind::Accelerometer
            ) && p.noise_model.iter().any(Option::is_some)
            {
                p.drift_knot_s = Some(DRIFT_KNOT_S);
                p.fit_noise(&all);
            }
        }
        p
    }

    /// The noise model ([`Problem::noise_lags`], [`Problem::noise_model`]) of the residual with
    /// the candidates `all` fitted.
    fn fit_noise(&mut self, all: &[usize]) {
        let (lags, model) = self.noise_of(all, 1);
        (self.noise_lags, self.noise_model) = (lags, model);
    }

    /// The correlation lags and, per component, the Gauss–Markov error and white noise of the
    /// residual with the set `set` fitted (as [`Problem::noise_model`]), the likelihood searched
    /// from `starts` points ([`super::noise::restricted_gauss_markov_from`]). With every
    /// candidate the noise is what no effect can take; with the effects found, it is the noise
    /// of the extended model, read with fewer directions absorbed.
    pub fn noise_of(&self, set: &[usize], starts: usize) -> (usize, Vec<Option<GaussMarkov>>) {
        let d = self.channel.kind.dims();
        let f = self.fit(set, &self.epochs);
        let r = self.residuals(&self.effects(set, &f.theta), &self.epochs);
        let lags = correlation_lags(&r, d);
        let m = r.len() / d.max(1);
        // The noise is read with what the candidates (and an IMU's drift nuisance) took from it
        // counted (the restricted likelihood with their design): a slow sensor error on a
        // voyage a few of its correlation times long is otherwise mostly absorbed by the
        // installation effects and read short.
        let jac = if f.theta.is_empty() {
            DMatrix::zeros(r.len(), 0)
        } else {
            self.jacobian(set, &f.theta, &self.epochs, &r)
        };
        let drift = match self.drift_knot_s {
            Some(knot) => {
                let times: Vec<f64> = self.epochs.iter().map(|&i| self.channel.times[i]).collect();
                drift_basis(&times, knot)
            }
            None => DMatrix::zeros(m, 0),
        };
        let (p, q) = (jac.ncols(), drift.ncols());
        let series: Vec<(Vec<f64>, DMatrix<f64>)> = (0..d)
            .map(|k| {
                let x: Vec<f64> = (0..m).map(|t| r[t * d + k]).collect();
                let design = DMatrix::from_fn(m, p + q, |t, c| {
                    if c < p {
                        jac[(t * d + k, c)]
                    } else {
                        drift[(t, c - p)]
                    }
                });
                (x, design)
            })
            .collect();
        // Components alike in their noise are read together ([`Problem::alike_components`]):
        // read alone, a DVL's horizontal axis's long-run variance varies from voyage to voyage
        // by a factor of several, and an axis read low makes the deviations of the effects it
        // carries too small (a hidden mounting yaw named 4–6σ from its value on one voyage in
        // ten).
        let mut model: Vec<Option<GaussMarkov>> = vec![None; d];
        for group in self.alike_components() {
            if let [k] = group[..] {
                model[k] = restricted_gauss_markov_from(&series[k].0, &series[k].1, starts);
                continue;
            }
            let parts: Vec<(&[f64], &DMatrix<f64>)> = group
                .iter()
                .map(|&k| (series[k].0.as_slice(), &series[k].1))
                .collect();
            if let Some(v) = restricted_gauss_markov_shared(&parts, starts) {
                for (&k, g) in group.iter().zip(v) {
                    model[k] = Some(g);
                }
            }
        }
        (lags, model)
    }

    /// The channel's components grouped by the noise they share in shape (one correlation time,
    /// one ratio of correlated to white noise, each its own level), read together by
    /// [`super::noise::restricted_gauss_markov_shared`]. A Janus DVL's two horizontal axes see
    /// its beams alike, its vertical axis its own; every other channel's components alone (read
    /// together, a gyro triad's three axes gave a misalignment's deviations no closer to their
    /// scatter over noise realisations).
    fn alike_components(&self) -> Vec<Vec<usize>> {
        let d = self.channel.kind.dims();
        match self.channel.kind {
            ChannelKind::Dvl if d == 3 => vec![vec![0, 1], vec![2]],
            _ => (0..d).map(|k| vec![k]).collect(),
        }
    }

    /// This channel's candidates (indices into [`CANDIDATES`]).
    pub fn candidates(&self) -> Vec<usize> {
        (0..CANDIDATES.len())
            .filter(|&i| CANDIDATES[i].channel == self.channel.kind)
            .filter(|&i| CANDIDATES[i].name != "dvl.bed_velocity" || self.channel.moving_bed)
            .filter(|&i| {
                CANDIDATES[i].name != "dvl.periodic_velocity_error"
                    || self.channel.periodic_line.is_some_and(|l| l.stands_out())
            })
            .collect()
    }

    /// The nominal parameter vector of a set of candidates.
    pub fn nominal_theta(&self, set: &[usize]) -> Vec<f64> {
        set.iter()
            .flat_map(|&c| self.nominal.get(CANDIDATES[c].name).unwrap_or_default())
            .collect()
    }

    /// The effects with the set's parameters, each component clamped to the effect's range.
    pub fn effects(&self, set: &[usize], theta: &[f64]) -> Effects {
        let mut e = self.nominal.clone();
        let mut k = 0;
        for &c in set {
            let name = CANDIDATES[c].name;
            let Some(s) = spec(name) else { continue };
            let v: Vec<f64> = theta[k..k + s.components]
                .iter()
                .map(|x| x.clamp(s.min, s.max))
                .collect();
            k += s.components;
            // In range by construction.
            let _ = e.set(name, &v);
        }
        e
    }

    /// Residuals (measured − predicted) over `epochs`, flattened per component; an epoch the
    /// effects move outside the reference contributes zeros.
    pub fn residuals(&self, e: &Effects, epochs: &[usize]) -> Vec<f64> {
        let d = self.channel.kind.dims();
        let mut r = Vec::with_capacity(epochs.len() * d);
        for &i in epochs {
            match self.channel.residual(e, &self.reference, i) {
                Some(x) => r.extend(x[..d].iter().map(|v| if v.is_finite() { *v } else { 0.0 })),
                None => r.extend(std::iter::repeat_n(0.0, d)),
            }
        }
        if let Some(knot) = self.drift_knot_s {
            let times: Vec<f64> = epochs.iter().map(|&i| self.channel.times[i]).collect();
            remove_drift(&mut r, &times, d, knot);
        }
        r
    }

    /// Numerical Jacobian of the residuals with respect to the set's parameters at `theta`.
    fn jacobian(&self, set: &[usize], theta: &[f64], epochs: &[usize], r0: &[f64]) -> DMatrix<f64> {
        let steps = steps(set);
        let mut j = DMatrix::zeros(r0.len(), theta.len());
        for (k, h) in steps.iter().enumerate() {
            let mut t = theta.to_vec();
            t[k] += h;
            let r = self.residuals(&self.effects(set, &t), epochs);
            for (row, (a, b)) in r.iter().zip(r0).enumerate() {
                j[(row, k)] = (a - b) / h;
            }
        }
        j
    }

    /// Fits the set on `epochs` by Gauss–Newton, with each effect held by a weak prior at its
    /// nominal value whose standard deviation is half the effect's documented range: where the
    /// readings excite an effect the prior is negligible; where they hardly do (a time offset
    /// on a stretch without accelerations) the estimate stays plausible instead of wandering
    /// outside the range and spoiling a held-out prediction.
    // Long on purpose: Gauss–Newton with a prior and numerical derivatives: step, damping and
    // convergence test share the Jacobian and the normal equations.
    pub fn fit(&self, set: &[usize], epochs: &[usize]) -> Fit {
        let theta0 = self.nominal_theta(set);
        let prior_sd: Vec<f64> = set
            .iter()
            .flat_map(|&c| {
                let s = spec(CANDIDATES[c].name);
                let n = s.map_or(1, |s| s.components);
                let sd = s.map_or(f64::INFINITY, |s| 0.5 * (s.max - s.min));
                std::iter::repeat_n(sd, n)
            })
            .collect();
        let mut theta = theta0.clone();
        let mut r = self.residuals(&self.effects(set, &theta), epochs);
        let mut sse: f64 = r.iter().map(|x| x * x).sum();
        let n = r.len();
        // The prior's weight in Σr² units: the residual variance per reading over the prior's.
        let weights = |sse: f64| -> Vec<f64> {
            let s2 = sse / n.max(1) as f64;
            prior_sd
                .iter()
                .map(|sd| {
                    if sd.is_finite() && *sd > 0.0 {
                        s2 / (sd * sd)
                    } else {
                        0.0
                    }
                })
                .collect()
        };
        let penalty = |theta: &[f64], w: &[f64]| -> f64 {
            theta
                .iter()
                .zip(&theta0)
                .zip(w)
                .map(|((t, t0), w)| w * (t - t0).powi(2))
                .sum()
        };
        // What interpolating a noisy reference takes from the residual at a time offset, given
        // back ([`crate::reference_noise`]): its value, slope and curvature in the offset.
        let tau_at = self.time_offset_index(set);
        let loss = |theta: &[f64]| -> [f64; 3] {
            tau_at.map_or([0.0; 3], |k| self.interpolation_loss(epochs, theta[k]))
        };
        let mut jac = DMatrix::zeros(n, theta.len());
        for _ in 0..8 {
            if theta.is_empty() {
                break;
            }
            jac = self.jacobian(set, &theta, epochs, &r);
            let w = weights(sse);
            let jtj = jac.transpose() * &jac;
            let mut jtr = jac.transpose() * DVector::from_column_slice(&r);
            let mut a = jtj.clone();
            for i in 0..theta.len() {
                a[(i, i)] += w[i] + 1e-9 * jtj[(i, i)].max(1e-12) + 1e-12;
                jtr[i] += w[i] * (theta[i] - theta0[i]);
            }
            if let Some(k) = tau_at {
                let l = loss(&theta);
                a[(k, k)] = curvature_given_back(a[(k, k)], l[2]);
                jtr[k] += 0.5 * l[1];
            }
            let Some(step) = a.cholesky().map(|c| c.solve(&jtr)) else {
                break;
            };
            // r = z − h: the Gauss–Newton step is +(JᵀJ)⁻¹Jᵀr with J = ∂r/∂θ = −∂h/∂θ, so −.
            let trial: Vec<f64> = theta.iter().zip(step.iter()).map(|(t, s)| t - s).collect();
            let rt = self.residuals(&self.effects(set, &trial), epochs);
            let st: f64 = rt.iter().map(|x| x * x).sum();
            let (objective, objective_trial) = (
                sse + penalty(&theta, &w) + loss(&theta)[0],
                st + penalty(&trial, &w) + loss(&trial)[0],
            );
            if !(st.is_finite() && objective_trial <= objective) {
                break;
            }
            let done = objective - objective_trial <= 1e-10 * objective.max(1e-300);
            theta = trial;
            r = rt;
            sse = st;
            if done {
                break;
            }
        }
        // Parameter covariance at the solution: the sandwich (JᵀJ)⁻¹ S (JᵀJ)⁻¹ with S the
        // Newey–West estimate of the scores' long-run covariance, which is σ²JᵀJ for white
        // residuals and widens the deviations as much as the residuals' correlation in time
        // (a slowly varying sensor error, a drifting bias) makes the readings fewer than they
        // are.
        let d = self.channel.kind.dims();
        let (std, std_white, widening, lags, cov) = if theta.is_empty() {
            (Vec::new(), Vec::new(), 1.0, 0, DMatrix::zeros(0, 0))
        } else {
            let mut jtj = jac.transpose() * &jac;
            if let Some(k) = tau_at {
                jtj[(k, k)] = curvature_given_back(jtj[(k, k)], loss(&theta)[2]);
            }
            match jtj.clone().try_inverse() {
                Some(inv) => {
                    let dof = n.saturating_sub(theta.len()).max(1) as f64;
                    let white: Vec<f64> = (0..theta.len())
                        .map(|i| (sse / dof * inv[(i, i)]).max(0.0).sqrt())
                        .collect();
                    let lags = self.noise_lags;
                    let s = long_run_scores(&jac, &r, d, lags) * (n as f64 / dof);
                    let b = fixed_b_factor(lags, n / d.max(1));
                    let cov = &inv * s * &inv * (b * b);
                    // A slowly varying error correlated beyond the Newey–West window (a
                    // Gauss–Markov error of a minute on a few minutes of data) is what that
                    // window underestimates: its parametric long-run covariance, where the
                    // residual shows one, is taken where it is the larger. On an IMU channel,
                    // whose drifting bias is taken out as a nuisance, each deviation is the
                    // larger of the two: on a simulated voyage with a drifting gyro bias the
                    // window gave a gyro misalignment's x and y deviations half their scatter
                    // over noise realisations and the parametric covariance nearly all of it,
                    // but the window's z deviation, larger than either, made its matrix the one
                    // taken whole. On the DVL the whole matrix is kept: parameter by parameter,
                    // the six perturbed Snapir segments no longer pointed at their hidden scale.
                    let parametric = parametric_scores(&jac, &r, d, &self.noise_model)
                        .map(|sp| &inv * sp * &inv);
                    let per_parameter = self.drift_knot_s.is_some();
                    let parametric_whole = parametric
                        .as_ref()
                        .is_some_and(|cp| cp.trace() > cov.trace());
                    let std: Vec<f64> = (0..theta.len())
                        .map(|i| {
                            let p = parametric.as_ref().map_or(0.0, |c| c[(i, i)]);
                            let w = cov[(i, i)];
                            let v = if per_parameter {
                                w.max(p)
                            } else if parametric_whole {
                                p
                            } else {
                                w
                            };
                            v.max(0.0).sqrt().max(white[i])
                        })
                        .collect();
                    let cov = match parametric {
                        Some(cp) if parametric_whole => cp,
                        _ => cov,
                    };
                    let widening = std
                        .iter()
                        .zip(&white)
                        .filter(|(_, w)| **w > 0.0 && w.is_finite())
                        .map(|(s, w)| s / w)
                        .fold(1.0, f64::max);
                    // The covariance with its diagonal raised to the deviations (the
                    // correlations of the sandwich kept).
                    let scale: Vec<f64> = (0..theta.len())
                        .map(|i| {
                            let c = cov[(i, i)].max(0.0).sqrt();
                            if c > 0.0 { std[i] / c } else { 0.0 }
                        })
                        .collect();
                    let cov = DMatrix::from_fn(theta.len(), theta.len(), |i, j| {
                        if i == j {
                            std[i] * std[i]
                        } else {
                            cov[(i, j)] * scale[i] * scale[j]
                        }
                    });
                    (std, white, widening, lags, cov)
                }
                None => (
                    vec![f64::INFINITY; theta.len()],
                    vec![f64::INFINITY; theta.len()],
                    1.0,
                    0,
                    DMatrix::from_diagonal_element(theta.len(), theta.len(), f64::INFINITY),
                ),
            }
        };
        // The reference's own uncertainty of an effect (a smoothed motion's installation states).
        let (mut std, mut cov) = (std, cov);
        let mut k = 0;
        for &c in set {
            let name = CANDIDATES[c].name;
            let n = spec(name).map_or(1, |s| s.components);
            if let Some((_, floor)) = self.reference.effect_std.iter().find(|(e, _)| e == name) {
                for (j, f) in floor.iter().enumerate().take(n) {
                    if f.is_finite() && *f > 0.0 && k + j < std.len() {
                        std[k + j] = std[k + j].hypot(*f);
                        cov[(k + j, k + j)] += f * f;
                    }
                }
            }
            k += n;
        }
        Fit {
            theta,
            std,
            std_white,
            sse,
            n,
            widening,
            lags,
            readings: n / d.max(1),
            cov,
        }
    }

    /// The held-out score of a set: mean squared residual over the five time blocks, each
    /// predicted with a fit on the other four.
    pub fn held_out_mse(&self, set: &[usize]) -> f64 {
        let blocks = blocks(&self.epochs, FOLDS);
        let (mut sum, mut count) = (0.0, 0usize);
        for (k, test) in blocks.iter().enumerate() {
            let train: Vec<usize> = blocks
                .iter()
                .enumerate()
                .filter(|(j, _)| *j != k)
                .flat_map(|(_, b)| b.iter().copied())
                .collect();
            let f = self.fit(set, &train);
            let e = self.effects(set, &f.theta);
            let r = self.residuals(&e, test);
            sum += r.iter().map(|x| x * x).sum::<f64>() + self.given_back(&e, test);
            count += r.len();
        }
        sum / count.max(1) as f64
    }
}

impl Problem<'_> {
    /// Per component of candidate `c` (fitted with `set`): the departure from nominal at which
    /// the held-out score would fall by `min_gain`. Linearised: a departure `m` adds `J_c m` to
    /// the residual; the fit on four blocks recovers the share of `m` those blocks determine
    /// (their signal energy against the prior's weight), and the gain is the recovered signal's
    /// energy in the held-out block, so an effect whose signature sits in one block (a time
    /// offset seen only while the vehicle accelerates) gains little however significant it is.
    pub fn gain_floor(&self, set: &[usize], c: usize, min_gain: f64) -> Vec<f64> {
        let mut with = set.to_vec();
        with.push(c);
        let f = self.fit(&with, &self.epochs);
        let r0 = self.residuals(&self.effects(&with, &f.theta), &self.epochs);
        let j = self.jacobian(&with, &f.theta, &self.epochs, &r0);
        let (off, len) = offset_of(&with, c);
        let d = self.channel.kind.dims();
        let m = self.epochs.len();
        let s2 = f.sse / f.n.max(1) as f64;
        let sd = spec(CANDIDATES[c].name).map_or(f64::INFINITY, |s| 0.5 * (s.max - s.min));
        let w = if sd.is_finite() && sd > 0.0 {
            s2 / (sd * sd)
        } else {
            0.0
        };
        (0..len)
            .map(|k| {
                let col = j.column(off + k);
                let energy: Vec<f64> = (0..FOLDS)
                    .map(|b| {
                        (b * m / FOLDS * d..(b + 1) * m / FOLDS * d)
                            .map(|row| col[row] * col[row])
                            .sum()
                    })
                    .collect();
                let total: f64 = energy.iter().sum();
                let explained: f64 = energy
                    .iter()
                    .map(|e| {
                        let train = total - e;
                        if train + w > 0.0 {
                            e * train / (train + w)
                        } else {
                            0.0
                        }
                    })
                    .sum();
                if explained > 0.0 {
                    (min_gain * f.sse / explained).sqrt()
                } else {
                    f64::INFINITY
                }
            })
            .collect()
    }
}

/// Takes out of each of the `d` components of `r` (readings at `times`, in time order) its
/// projection on a piecewise-linear function of time with knots about `knot` seconds apart (a
/// straight line over a shorter stretch, such as a held-out block), less its mean: what varies
/// slowly goes, the constant stays (for a bias candidate to take).
pub fn remove_drift(r: &mut [f64], times: &[f64], d: usize, knot: f64) {
    let m = times.len();
    if r.len() < m * d {
        return;
    }
    let Some((hats, q)) = drift_hats(times, knot) else {
        return;
    };
    let mut btb = DMatrix::<f64>::zeros(q, q);
    for &(j, w) in &hats {
        let (a, b) = (1.0 - w, w);
        btb[(j, j)] += a * a;
        btb[(j, j + 1)] += a * b;
        btb[(j + 1, j)] += a * b;
        btb[(j + 1, j + 1)] += b * b;
    }
    // A knot interval without readings (a gap in the record) leaves its hat function without
    // support: a tiny ridge keeps the system solvable, that hat's coefficient zero.
    let ridge = 1e-9 * (0..q).map(|i| btb[(i, i)]).fold(0.0, f64::max).max(1e-300);
    for i in 0..q {
        btb[(i, i)] += ridge;
    }
    let Some(chol) = btb.cholesky() else {
        return;
    };
    for k in 0..d {
        let mut btr = DVector::<f64>::zeros(q);
        for (t, &(j, w)) in hats.iter().enumerate() {
            let x = r[t * d + k];
            btr[j] += (1.0 - w) * x;
            btr[j + 1] += w * x;
        }
        let c = chol.solve(&btr);
        let fitted: Vec<f64> = hats
            .iter()
            .map(|&(j, w)| (1.0 - w) * c[j] + w * c[j + 1])
            .collect();
        // The fitted drift less its own mean: the constant stays exactly.
        let fitted_mean = fitted.iter().sum::<f64>() / m as f64;
        for (t, f) in fitted.iter().enumerate() {
            r[t * d + k] -= f - fitted_mean;
        }
    }
}

/// The hat functions of [`remove_drift`]'s piecewise-linear drift (knots about `knot` seconds
/// apart) at each of `times`: (index of the left knot, weight of the right) per reading, and the
/// number of knots. None for fewer than four readings or no time span.
fn drift_hats(times: &[f64], knot: f64) -> Option<(Vec<(usize, f64)>, usize)> {
    let m = times.len();
    if m < 4 {
        return None;
    }
    let (t0, t1) = (times[0], times[m - 1]);
    let span = t1 - t0;
    if !(span > 0.0 && knot > 0.0) {
        return None;
    }
    let intervals = (span / knot).round().max(1.0) as usize;
    let h = span / intervals as f64;
    // Each reading lies on two hat functions.
    let hats = times
        .iter()
        .map(|t| {
            let u = ((t - t0) / h).clamp(0.0, intervals as f64);
            let j = (u.floor() as usize).min(intervals - 1);
            (j, u - j as f64)
        })
        .collect();
    Some((hats, intervals + 1))
}

/// The drift [`remove_drift`] can take out, as a design: one column per knot's hat function,
/// one row per reading (none when it takes nothing out).
fn drift_basis(times: &[f64], knot: f64) -> DMatrix<f64> {
    let Some((hats, q)) = drift_hats(times, knot) else {
        return DMatrix::zeros(times.len(), 0);
    };
    let mut b = DMatrix::zeros(times.len(), q);
    for (t, &(j, w)) in hats.iter().enumerate() {
        b[(t, j)] = 1.0 - w;
        b[(t, j + 1)] = w;
    }
    b
}

impl Problem<'_> {
    /// The time offset's index among the parameters of `set`, where the channel is the DVL's
    /// velocity and the reference velocity carries noise of its own (see
    /// [`crate::reference_noise`]).
    fn time_offset_index(&self, set: &[usize]) -> Option<usize> {
        if self.reference_noise <= 0.0 {
            return None;
        }
        let c = set
            .iter()
            .position(|&c| CANDIDATES[c].name == "dvl.time_offset")?;
        Some(offset_of(set, set[c]).0)
    }

    /// What interpolating the reference at the time offset of `e` takes from the squared
    /// residuals of `epochs`, given back to a score (0 without reference noise).
    pub fn given_back(&self, e: &Effects, epochs: &[usize]) -> f64 {
        if self.reference_noise <= 0.0 || e.dvl_time_offset == 0.0 {
            return 0.0;
        }
        self.interpolation_loss(epochs, e.dvl_time_offset)[0]
    }

    /// [`Reference::interpolation_loss`] over the readings `epochs` at offset `tau`.
    fn interpolation_loss(&self, epochs: &[usize], tau: f64) -> [f64; 3] {
        let times = epochs.iter().map(|&i| self.channel.times[i]);
        self.reference
            .interpolation_loss(times, tau, self.reference_noise)
    }
}

/// The curvature `a` of the fit's objective in the time offset with half the interpolation
/// loss's `second` derivative added (negative: the loss is concave in the offset, the noise the
/// regressor carries makes `a` that much larger); never below a tenth of `a`, so that a reading
/// dominated by the reference's noise cannot turn the step around.
fn curvature_given_back(a: f64, second: f64) -> f64 {
    (a + 0.5 * second).max(0.1 * a)
}

/// Number of time blocks of the held-out score.
pub const FOLDS: usize = 5;

/// Splits `epochs` into `k` contiguous blocks.
pub fn blocks(epochs: &[usize], k: usize) -> Vec<Vec<usize>> {
    let n = epochs.len();
    (0..k)
        .map(|b| epochs[b * n / k..(b + 1) * n / k].to_vec())
        .collect()
}

fn steps(set: &[usize]) -> Vec<f64> {
    set.iter()
        .flat_map(|&c| {
            let n = spec(CANDIDATES[c].name).map_or(1, |s| s.components);
            std::iter::repeat_n(CANDIDATES[c].step, n)
        })
        .collect()
}

/// A fitted set: parameters, their standard deviations, Σr² and the residual count.
#[derive(Debug, Clone)]
pub struct Fit {
    pub theta: Vec<f64>,
    /// Standard deviations allowing for the residuals' correlation in time (never below the
    /// white-residual ones).
    pub std: Vec<f64>,
    /// The standard deviations white residuals would give, σ²(JᵀJ)⁻¹.
    pub std_white: Vec<f64>,
    pub sse: f64,
    pub n: usize,
    /// The largest ratio of a standard deviation to the one white residuals would give.
    pub widening: f64,
    /// Readings over which the residuals are correlated (the Newey–West bandwidth).
    pub lags: usize,
    /// Readings in the fit (residual rows over the channel's components).
    pub readings: usize,
    /// The parameters' covariance: the sandwich's, with its diagonal the squares of `std`.
    pub cov: DMatrix<f64>,
}

impl Fit {
    /// The degrees of freedom of the deviations, taken as estimated rather than known: a
    /// long-run variance read through a Bartlett window of `lags` readings over `m` has
    /// variance (4/3)(lags/m) of its square (Andrews 1991), so 1.5 m / lags degrees of freedom;
    /// infinite for white residuals. On three simulated voyages with a coloured DVL error
    /// (window 0.31 of the series) this gives about 5, and the normalised errors of a mounting
    /// yaw over noise realisations scattered as a Student t of about that many (RMS 1.03–1.54,
    /// largest 3.7 in 90).
    pub fn deviation_dof(&self) -> f64 {
        if self.lags == 0 || self.readings == 0 {
            f64::INFINITY
        } else {
            1.5 * self.readings as f64 / self.lags as f64
        }
    }
}

/// The residuals' correlation length in readings: twice the first lag at which the mean
/// autocorrelation of the `d` components (readings in time order) falls below its 95 % bound for
/// white noise (2/√m), at most a quarter of the readings; 0 for white residuals.
pub fn correlation_lags(r: &[f64], d: usize) -> usize {
    let m = r.len() / d.max(1);
    if m < 8 {
        return 0;
    }
    let var: Vec<f64> = (0..d)
        .map(|k| (0..m).map(|t| r[t * d + k].powi(2)).sum::<f64>())
        .collect();
    let bound = 2.0 / (m as f64).sqrt();
    let max = m / 4;
    for lag in 1..=max {
        let (mut sum, mut used) = (0.0, 0);
        for k in 0..d {
            if var[k] <= 0.0 {
                continue;
            }
            let c: f64 = (lag..m).map(|t| r[t * d + k] * r[(t - lag) * d + k]).sum();
            sum += c / var[k];
            used += 1;
        }
        if used == 0 || sum / used as f64 <= bound {
            return if lag == 1 { 0 } else { (2 * lag).min(max) };
        }
    }
    max
}

/// How much wider a Newey–West deviation must be taken when its window is a sizeable fraction
/// of the series (`lags` of `m` readings): with few independent stretches of a slowly varying
/// error the estimate of its long-run variance is itself uncertain, and the test statistic has
/// heavier tails than a normal one. Fixed-b asymptotics (Kiefer & Vogelsang 2005, Bartlett
/// kernel) give the two-sided 5 % critical value 1.96 + 2.9694 b + 0.4160 b² − 0.5324 b³ for
/// b = lags / m; the factor is its ratio to 1.96 (1 for white residuals).
pub fn fixed_b_factor(lags: usize, m: usize) -> f64 {
    if lags == 0 || m == 0 {
        return 1.0;
    }
    let b = (lags as f64 / m as f64).min(1.0);
    (1.96 + 2.9694 * b + 0.4160 * b * b - 0.5324 * b * b * b) / 1.96
}

/// The scores' long-run covariance `Jᵀ Σ J` under a Gauss–Markov-plus-white model of each
/// residual component, `Σ` Toeplitz with `σ²_gm φ^|t−s|` off the diagonal, applied by a forward
/// and a backward exponential filter. The Gauss–Markov part is `model`'s (fitted on the residual
/// with every candidate, so that an effect the set leaves out is not taken for correlated
/// noise), the white part what the residual `r` has besides, at least the model's. None when no
/// component has a correlated part.
fn parametric_scores(
    j: &DMatrix<f64>,
    r: &[f64],
    d: usize,
    model: &[Option<(f64, f64, f64)>],
) -> Option<DMatrix<f64>> {
    let p = j.ncols();
    let m = r.len() / d.max(1);
    let mut s = DMatrix::zeros(p, p);
    let mut any = false;
    for k in 0..d {
        let Some(&Some((gm, white, phi))) = model.get(k) else {
            continue;
        };
        let g0 = (0..m).map(|t| r[t * d + k].powi(2)).sum::<f64>() / m.max(1) as f64;
        let white = (g0 - gm).max(white);
        any = true;
        let cols: Vec<Vec<f64>> = (0..p)
            .map(|c| (0..m).map(|t| j[(t * d + k, c)]).collect())
            .collect();
        let filtered: Vec<Vec<f64>> = cols
            .iter()
            .map(|y| {
                let mut f = vec![0.0; m];
                let mut b = vec![0.0; m];
                for t in 0..m {
                    f[t] = y[t] + if t > 0 { phi * f[t - 1] } else { 0.0 };
                }
                for t in (0..m).rev() {
                    b[t] = y[t] + if t + 1 < m { phi * b[t + 1] } else { 0.0 };
                }
                (0..m).map(|t| f[t] + b[t] - y[t]).collect()
            })
            .collect();
        for a in 0..p {
            for c in 0..p {
                let correlated: f64 = cols[a].iter().zip(&filtered[c]).map(|(u, v)| u * v).sum();
                let plain: f64 = cols[a].iter().zip(&cols[c]).map(|(u, v)| u * v).sum();
                s[(a, c)] += gm * correlated + white * plain;
            }
        }
    }
    any.then_some(s)
}

/// Newey–West long-run covariance of the scores `g_t = Σ_k J[t·d+k]ᵀ r[t·d+k]` with Bartlett
/// weights over `lags` readings.
fn long_run_scores(j: &DMatrix<f64>, r: &[f64], d: usize, lags: usize) -> DMatrix<f64> {
    let p = j.ncols();
    let m = r.len() / d.max(1);
    let g = DMatrix::from_fn(m, p, |t, c| {
        (0..d).map(|k| j[(t * d + k, c)] * r[t * d + k]).sum()
    });
    let mut s = g.transpose() * &g;
    for lag in 1..=lags.min(m.saturating_sub(1)) {
        let w = 1.0 - lag as f64 / (lags as f64 + 1.0);
        let a = g.rows(lag, m - lag).transpose() * g.rows(0, m - lag);
        s += (&a + a.transpose()) * w;
    }
    s
}

/// Thresholds of the forward selection.
#[derive(Debug, Clone, Copy)]
pub struct Selection {
    /// Smallest relative drop of the held-out score for an effect to be kept.
    pub min_gain: f64,
    /// Smallest distance of the estimate from its nominal value, in standard deviations.
    pub min_sigma: f64,
    /// Canonical correlation above which two candidates count as not separable on the motion.
    pub max_correlation: f64,
    /// Candidates never selected, one bit per index into [`CANDIDATES`]: the refit of what
    /// `--write-config` keeps once effects are withheld (`crate::gnss_written::refit`).
    pub excluded: u64,
}

const _: () = assert!(CANDIDATES.len() <= 64, "one bit per candidate");

impl Default for Selection {
    fn default() -> Self {
        Selection {
            min_gain: 0.01,
            min_sigma: 5.0,
            max_correlation: 0.98,
            excluded: 0,
        }
    }
}

impl Selection {
    /// The default thresholds, the effects `names` never selected (names outside the candidates
    /// are ignored).
    pub fn excluding(names: &[String]) -> Selection {
        let excluded = CANDIDATES
            .iter()
            .enumerate()
            .filter(|(_, c)| names.iter().any(|n| n == c.name))
            .fold(0u64, |m, (i, _)| m | 1 << i);
        Selection {
            excluded,
            ..Selection::default()
        }
    }

    /// Whether candidate `c` may be selected.
    pub fn allows(&self, c: usize) -> bool {
        self.excluded & (1 << c) == 0
    }

    /// The channel's candidates ([`Problem::candidates`]) that may be selected.
    pub fn candidates(&self, p: &Problem) -> Vec<usize> {
        p.candidates()
            .into_iter()
            .filter(|&c| self.allows(c))
            .collect()
    }
}

/// One step of the selection: the candidate, the held-out score before and after.
#[derive(Debug, Clone)]
pub struct Step {
    pub candidate: usize,
    pub mse_before: f64,
    pub mse_after: f64,
    /// Other candidates whose addition scored within 2 % of this one and that the motion cannot
    /// separate from it.
    pub rivals: Vec<(usize, f64)>,
}

/// Greedy forward selection on one channel. Returns the kept steps and the held-out score of
/// the empty set.
pub fn select(p: &Problem, sel: &Selection, separability: &Separability) -> Selected {
    let mut chosen: Vec<usize> = Vec::new();
    let mut undetermined = None;
    let base = p.held_out_mse(&chosen);
    let mut current = base;
    let mut steps = Vec::new();
    let mut remaining = sel.candidates(p);
    let mut preferred = Vec::new();
    while !remaining.is_empty() {
        let scores: Vec<(usize, f64)> = remaining
            .iter()
            .map(|&c| {
                let mut s = chosen.clone();
                s.push(c);
                (c, p.held_out_mse(&s))
            })
            .collect();
        let Some(&(mut best, mut score)) = scores.iter().min_by(|a, b| a.1.total_cmp(&b.1)) else {
            break;
        };
        // An IMU's bias is in every run (its turn-on bias): where the motion cannot tell the
        // best candidate from the bias (level motion couples gravity through a misalignment
        // as through a horizontal accelerometer bias), the bias is taken first; the other must
        // then explain what the bias leaves.
        if let Some(&(b, s)) = scores.iter().find(|(c, _)| {
            *c != best
                && matches!(CANDIDATES[*c].name, "imu.gyro_bias" | "imu.accel_bias")
                && separability.correlation(best, *c) > sel.max_correlation
        }) {
            (best, score) = (b, s);
            preferred.push(b);
        }
        if score.is_nan() || score >= current * (1.0 - sel.min_gain) {
            break;
        }
        let mut set = chosen.clone();
        set.push(best);
        let f = p.fit(&set, &p.epochs);
        if !stands_out(&f, &p.nominal_theta(&set), &set, best, sel.min_sigma) {
            undetermined = Some(Undetermined {
                candidate: best,
                set,
                fit: f,
                mse_before: current,
                mse_after: score,
            });
            break;
        }
        let rivals = scores
            .iter()
            .filter(|(c, s)| {
                *c != best
                    && *s <= score * 1.02
                    && separability.correlation(best, *c) > sel.max_correlation
            })
            .map(|&(c, _)| (c, separability.correlation(best, c)))
            .collect();
        steps.push(Step {
            candidate: best,
            mse_before: current,
            mse_after: score,
            rivals,
        });
        chosen = set;
        current = score;
        remaining.retain(|&c| c != best);
    }
    // A bias taken first by preference that the effects selected after it leave insignificant
    // (a misalignment that explains the whole of it) was the wrong explanation: it goes, and the
    // steps' scores are those of the set without it.
    let f = p.fit(&chosen, &p.epochs);
    let nominal = p.nominal_theta(&chosen);
    let weak: Vec<usize> = preferred
        .into_iter()
        .filter(|&b| !stands_out(&f, &nominal, &chosen, b, sel.min_sigma))
        .collect();
    if !weak.is_empty() && chosen.len() > weak.len() {
        steps = without(p, steps, base, &weak);
    }
    Selected {
        steps,
        base,
        undetermined,
    }
}

/// What a selection chose.
pub struct Selected {
    pub steps: Vec<Step>,
    /// The held-out score of the nominal model.
    pub base: f64,
    /// The candidate that lowered the held-out score enough but did not stand out from its
    /// nominal value by the significance test, where the selection stopped.
    pub undetermined: Option<Undetermined>,
}

/// A candidate the held-out score asks for and the significance test refuses: the data point at
/// it without determining it (a slowly varying error the residual carries leaves its estimate
/// a few deviations from nominal).
pub struct Undetermined {
    pub candidate: usize,
    /// The set it was fitted in (the effects selected before it, then it).
    pub set: Vec<usize>,
    pub fit: Fit,
    pub mse_before: f64,
    pub mse_after: f64,
}

/// `steps` without the candidates `drop`, each remaining step's scores those of the set without
/// them (`base`: the empty set's held-out score).
pub fn without(p: &Problem, steps: Vec<Step>, base: f64, drop: &[usize]) -> Vec<Step> {
    let (mut set, mut before) = (Vec::new(), base);
    steps
        .into_iter()
        .filter(|s| !drop.contains(&s.candidate))
        .map(|mut s| {
            set.push(s.candidate);
            s.mse_before = before;
            s.mse_after = p.held_out_mse(&set);
            before = s.mse_after;
            s
        })
        .collect()
}

/// Most candidates [`select_parsimonious`] combines.
pub const MAX_SUBSET: usize = 3;

/// Channels whose candidates alias each other on common motion, selected by best subset with
/// the fewest parameters ([`select_parsimonious`]): the DVL's beams, and the depth, where a
/// bias, a density error at a steady depth and the down component of the sensor's lever arm
/// move the reading alike (a hidden depth bias came out as a lever arm with its three numbers).
pub fn parsimonious(kind: ChannelKind) -> bool {
    matches!(kind, ChannelKind::DvlBeams | ChannelKind::Depth)
}

/// The number of parameters of candidate `c` (its components).
pub fn parameters(c: usize) -> usize {
    spec(CANDIDATES[c].name).map_or(1, |s| s.components)
}

/// Best-subset selection on one channel, for candidates that alias each other on common motion
/// (the DVL's beams: on a vehicle moving straight ahead, four per-beam scales reproduce any
/// change of the four beam readings, a mounting error too). Every set of up to [`MAX_SUBSET`]
/// candidates is scored held out; among the sets whose score is within `min_gain` of the best,
/// the one with the fewest parameters is kept (then the lowest score), so that a mounting yaw and
/// a scale factor (two numbers) are not reported as four beam scales, while a single beam's
/// error, which no installation effect reproduces, still is. Members whose estimate is not
/// `min_sigma` from nominal are dropped. The kept set is reported in steps of decreasing gain.
pub fn select_parsimonious(p: &Problem, sel: &Selection, separability: &Separability) -> Selected {
    let candidates = sel.candidates(p);
    let base = p.held_out_mse(&[]);
    let mut sets: Vec<Vec<usize>> = vec![Vec::new()];
    for size in 1..=MAX_SUBSET.min(candidates.len()) {
        let mut idx: Vec<usize> = (0..size).collect();
        loop {
            sets.push(idx.iter().map(|&i| candidates[i]).collect());
            // Next combination of `size` indices out of candidates.len().
            let n = candidates.len();
            let Some(k) = (0..size).rev().find(|&k| idx[k] < n - size + k) else {
                break;
            };
            idx[k] += 1;
            for j in k + 1..size {
                idx[j] = idx[j - 1] + 1;
            }
        }
    }
    let params = |set: &[usize]| steps(set).len();
    let scored: Vec<(Vec<usize>, f64)> = sets
        .into_iter()
        .map(|s| {
            let score = if s.is_empty() {
                base
            } else {
                p.held_out_mse(&s)
            };
            (s, score)
        })
        .filter(|(_, score)| score.is_finite())
        .collect();
    let best = scored.iter().map(|(_, s)| *s).fold(base, f64::min);
    let Some((mut chosen, _)) = scored
        .iter()
        .filter(|(_, s)| *s <= best * (1.0 + sel.min_gain))
        .min_by(|a, b| params(&a.0).cmp(&params(&b.0)).then(a.1.total_cmp(&b.1)))
        .cloned()
    else {
        return Selected {
            steps: Vec::new(),
            base,
            undetermined: None,
        };
    };
    // On the depth, a member the motion cannot separate from a simpler candidate gives way to it
    // when, fitted together, it does not stand out beyond it: what it explains is the simpler
    // one's (a depth bias read as the down component of a lever arm, whose forward and
    // starboard components sit within their deviations). The held-out score alone is too noisy
    // to decide between near-aliases by a percent. Not on the beams: fitted beside the DVL's
    // scale, four beam scales lose their sum, and a single beam's real error would not stand
    // out there either. The significance test below then applies to what stays.
    if p.channel.kind == ChannelKind::Depth {
        for k in 0..chosen.len() {
            let c = chosen[k];
            let simpler = candidates.iter().copied().find(|&r| {
                !chosen.contains(&r)
                    && parameters(r) < parameters(c)
                    && separability.correlation(c, r) > sel.max_correlation
            });
            let Some(r) = simpler else { continue };
            let mut both = chosen.clone();
            both.push(r);
            let f = p.fit(&both, &p.epochs);
            if !stands_out(&f, &p.nominal_theta(&both), &both, c, sel.min_sigma) {
                chosen[k] = r;
            }
        }
    }
    // Drop members the data do not put min_sigma from nominal.
    loop {
        let f = p.fit(&chosen, &p.epochs);
        let nominal = p.nominal_theta(&chosen);
        let weak = chosen
            .iter()
            .copied()
            .find(|&c| !stands_out(&f, &nominal, &chosen, c, sel.min_sigma));
        match weak {
            Some(c) => chosen.retain(|&x| x != c),
            None => break,
        }
    }
    // Report in steps: each time the member whose addition lowers the score most.
    let score_of = |set: &[usize]| {
        let mut sorted = set.to_vec();
        sorted.sort_unstable();
        scored
            .iter()
            .find(|(s, _)| {
                let mut t = s.clone();
                t.sort_unstable();
                t == sorted
            })
            .map_or_else(|| p.held_out_mse(set), |(_, v)| *v)
    };
    let (mut steps_out, mut so_far, mut current) = (Vec::new(), Vec::<usize>::new(), base);
    let mut left = chosen;
    while !left.is_empty() {
        let options: Vec<(usize, f64)> = left
            .iter()
            .map(|&c| {
                let mut s = so_far.clone();
                s.push(c);
                (c, score_of(&s))
            })
            .collect();
        let Some(&(c, score)) = options.iter().min_by(|a, b| a.1.total_cmp(&b.1)) else {
            break;
        };
        // Rivals: candidates outside the set that, in its place, score within 2 % and that the
        // motion cannot separate from it.
        let rivals = candidates
            .iter()
            .copied()
            .filter(|&r| r != c && !so_far.contains(&r) && !left.contains(&r))
            .filter_map(|r| {
                let mut s = so_far.clone();
                s.push(r);
                let v = score_of(&s);
                (v <= score * 1.02 && separability.correlation(c, r) > sel.max_correlation)
                    .then(|| (r, separability.correlation(c, r)))
            })
            .collect();
        steps_out.push(Step {
            candidate: c,
            mse_before: current,
            mse_after: score,
            rivals,
        });
        so_far.push(c);
        left.retain(|&x| x != c);
        current = score;
    }
    Selected {
        steps: steps_out,
        base,
        undetermined: None,
    }
}

/// Candidate `c` of the fitted `set` lies `min_sigma` of its deviations from its nominal value
/// (`nominal`: the set's) on some component: the significance test of the selection.
fn stands_out(f: &Fit, nominal: &[f64], set: &[usize], c: usize, min_sigma: f64) -> bool {
    departure_sigmas(f, nominal, set, c) >= min_sigma
}

/// How far candidate `c`'s estimate in a fitted set lies from its nominal value, in its own
/// standard deviations (the largest over its components with a finite deviation; 0 without).
pub fn departure_sigmas(f: &Fit, nominal: &[f64], set: &[usize], c: usize) -> f64 {
    let (off, len) = offset_of(set, c);
    (off..off + len)
        .filter(|&k| f.std[k].is_finite() && f.std[k] > 0.0)
        .map(|k| (f.theta[k] - nominal[k]).abs() / f.std[k])
        .fold(0.0, f64::max)
}

/// Where a candidate's parameters sit in a set's vector: (offset, length).
pub fn offset_of(set: &[usize], candidate: usize) -> (usize, usize) {
    let mut off = 0;
    for &c in set {
        let n = spec(CANDIDATES[c].name).map_or(1, |s| s.components);
        if c == candidate {
            return (off, n);
        }
        off += n;
    }
    (off, 0)
}

/// Which candidates the motion excites and which it cannot tell apart, from the Jacobian of the
/// residuals at the nominal model.
#[derive(Debug, Clone)]
pub struct Separability {
    /// Candidates of the channel.
    pub candidates: Vec<usize>,
    /// Largest canonical correlation between two candidates' columns (symmetric).
    pub pairs: Vec<(usize, usize, f64)>,
    /// Per candidate: components the motion does not excite (the whole range of the effect would
    /// move the residual by less than a tenth of its RMS).
    pub unexcited: Vec<(usize, Vec<usize>)>,
    /// The residuals' Jacobian over all candidates (columns in candidate order) and which of its
    /// columns the motion excites.
    pub jacobian: DMatrix<f64>,
    pub excited: Vec<bool>,
}

impl Separability {
    pub fn correlation(&self, a: usize, b: usize) -> f64 {
        self.pairs
            .iter()
            .find(|(x, y, _)| (*x == a && *y == b) || (*x == b && *y == a))
            .map_or(0.0, |p| p.2)
    }
}

/// Computes [`Separability`] for a channel.
pub fn separability(p: &Problem) -> Separability {
    let candidates = p.candidates();
    let theta = p.nominal_theta(&candidates);
    let r0 = p.residuals(&p.effects(&candidates, &theta), &p.epochs);
    let j = p.jacobian(&candidates, &theta, &p.epochs, &r0);
    let norms: Vec<f64> = (0..j.ncols()).map(|k| j.column(k).norm()).collect();
    // A component is excited when the largest value its range allows would move the residual
    // by at least a tenth of its RMS at the nominal model (per reading, RMS over the epochs).
    let rows = (r0.len().max(1)) as f64;
    let noise = (r0.iter().map(|x| x * x).sum::<f64>() / rows).sqrt();
    let mut excited = vec![false; norms.len()];
    for &c in &candidates {
        let (off, len) = offset_of(&candidates, c);
        let half_range = spec(CANDIDATES[c].name).map_or(1.0, |s| 0.5 * (s.max - s.min));
        for k in off..off + len {
            excited[k] = norms[k] / rows.sqrt() * half_range >= 0.1 * noise && norms[k] > 0.0;
        }
    }
    let cols_of = |c: usize| {
        let (off, len) = offset_of(&candidates, c);
        (off..off + len).filter(|&k| excited[k]).collect::<Vec<_>>()
    };
    let mut unexcited = Vec::new();
    for &c in &candidates {
        let (off, len) = offset_of(&candidates, c);
        let dead: Vec<usize> = (0..len).filter(|&i| !excited[off + i]).collect();
        if !dead.is_empty() {
            unexcited.push((c, dead));
        }
    }
    let r2 = |k: usize, of: &[usize]| r_squared(&j, &norms, k, of);
    let mut pairs = Vec::new();
    for (ia, &a) in candidates.iter().enumerate() {
        for &b in &candidates[ia + 1..] {
            let (ca, cb) = (cols_of(a), cols_of(b));
            let mut best: f64 = 0.0;
            for &k in &cb {
                best = best.max(r2(k, &ca));
            }
            for &k in &ca {
                best = best.max(r2(k, &cb));
            }
            pairs.push((a, b, best.sqrt()));
        }
    }
    Separability {
        candidates,
        pairs,
        unexcited,
        jacobian: j,
        excited,
    }
}

/// R² of Jacobian column `k` regressed on the columns `of` (least squares, columns normalised).
fn r_squared(j: &DMatrix<f64>, norms: &[f64], k: usize, of: &[usize]) -> f64 {
    if of.is_empty() || norms[k] == 0.0 {
        return 0.0;
    }
    let a = DMatrix::from_fn(j.nrows(), of.len(), |r, c| j[(r, of[c])] / norms[of[c]]);
    let y = j.column(k) / norms[k];
    let ata = a.transpose() * &a;
    let aty = a.transpose() * &y;
    match ata.cholesky() {
        Some(ch) => {
            let x = ch.solve(&aty);
            (aty.dot(&x)).clamp(0.0, 1.0)
        }
        None => 1.0,
    }
}

/// A selected effect the motion cannot separate from a group of other candidates together
/// (though perhaps from each alone): one of its components is, to correlation `correlation`,
/// a combination of theirs, so its estimate holds only with them at their nominal values.
#[derive(Debug, Clone)]
pub struct Confounded {
    pub candidate: usize,
    pub component: usize,
    pub group: Vec<usize>,
    pub correlation: f64,
}

/// The selected candidates confounded with a group of others, from the Jacobian at the fitted
/// model (`s` computed on a problem whose nominal is the fitted model). The group is built
/// greedily: the candidate that explains most of the component first, until the correlation
/// passes `threshold`; groups of one are the pairs [`Separability::pairs`] already reports.
pub fn confounded(s: &Separability, selected: &[usize], threshold: f64) -> Vec<Confounded> {
    let j = &s.jacobian;
    let norms: Vec<f64> = (0..j.ncols()).map(|k| j.column(k).norm()).collect();
    let cols_of = |c: usize| {
        let (off, len) = offset_of(&s.candidates, c);
        (off..off + len)
            .filter(|&k| s.excited[k])
            .collect::<Vec<_>>()
    };
    let mut out = Vec::new();
    for &c in selected {
        let (off, _) = offset_of(&s.candidates, c);
        let others: Vec<usize> = s.candidates.iter().copied().filter(|&o| o != c).collect();
        for k in cols_of(c) {
            let all: Vec<usize> = others.iter().flat_map(|&o| cols_of(o)).collect();
            if r_squared(j, &norms, k, &all).sqrt() <= threshold {
                continue;
            }
            let mut group: Vec<usize> = Vec::new();
            let mut best = 0.0;
            while best <= threshold && group.len() < others.len() {
                let Some((o, r)) = others
                    .iter()
                    .filter(|o| !group.contains(o))
                    .map(|&o| {
                        let mut g = group.clone();
                        g.push(o);
                        let cols: Vec<usize> = g.iter().flat_map(|&x| cols_of(x)).collect();
                        (o, r_squared(j, &norms, k, &cols).sqrt())
                    })
                    .max_by(|a, b| a.1.total_cmp(&b.1))
                else {
                    break;
                };
                group.push(o);
                best = r;
            }
            if group.len() > 1 {
                out.push(Confounded {
                    candidate: c,
                    component: k - off,
                    group,
                    correlation: best,
                });
            }
        }
    }
    out
}

/// A candidate's name.
pub fn name(c: usize) -> &'static str {
    CANDIDATES[c].name
}

/// The candidate entry.
pub fn candidate(c: usize) -> &'static Candidate {
    &CANDIDATES[c]
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The drift taken out of an IMU residual: a slow wander (a ramp and a 400 s sine) goes, the
    /// constant stays for the bias, and a quick signal (a 20 s sine) is left nearly whole.
    #[test]
    fn a_slow_drift_goes_and_the_constant_and_quick_signals_stay() {
        let times: Vec<f64> = (0..400).map(f64::from).collect();
        let quick = |t: f64| (2.0 * std::f64::consts::PI * t / 20.0).sin();
        let slow = |t: f64| 0.01 * t + 2.0 * (2.0 * std::f64::consts::PI * t / 400.0).sin();
        let mut r: Vec<f64> = times.iter().map(|&t| 5.0 + slow(t) + quick(t)).collect();
        let mean_before = r.iter().sum::<f64>() / r.len() as f64;
        remove_drift(&mut r, &times, 1, DRIFT_KNOT_S);
        let mean_after = r.iter().sum::<f64>() / r.len() as f64;
        assert!(
            (mean_after - mean_before).abs() < 1e-9,
            "the constant stays"
        );
        let left: f64 = times
            .iter()
            .zip(&r)
            .map(|(&t, x)| (x - mean_after - quick(t)).powi(2))
            .sum::<f64>()
            / r.len() as f64;
        let slow_power: f64 = times.iter().map(|&t| slow(t).powi(2)).sum::<f64>() / 400.0;
        println!("slow part left {left:.4} of {slow_power:.4} (mean square)");
        assert!(left < 0.05 * slow_power, "{left} of {slow_power}");
    }

    /// A gap in the record (no readings over a whole knot interval) does not switch the drift
    /// removal off: the slow part still goes on either side of it.
    #[test]
    fn a_gap_in_the_record_does_not_stop_the_drift_removal() {
        let times: Vec<f64> = (0..400)
            .map(f64::from)
            .filter(|t| !(100.0..=300.0).contains(t))
            .collect();
        let slow = |t: f64| 0.02 * t;
        let mut r: Vec<f64> = times.iter().map(|&t| slow(t)).collect();
        remove_drift(&mut r, &times, 1, DRIFT_KNOT_S);
        let mean = r.iter().sum::<f64>() / r.len() as f64;
        let left = r.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / r.len() as f64;
        assert!(left < 1e-6, "mean square left {left}");
    }
}
