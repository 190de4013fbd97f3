//! The Rauch–Tung–Striebel backward pass over an error-state filter with resets, for any state
//! dimension (the navigation filter's 26 states, or a small linear problem in the tests).
//!
//! The forward filter keeps its error state at zero: after each update the estimate `δ` is
//! removed from the nominal state. In the error coordinates of epoch `k` after its updates the
//! filtered mean is 0 with covariance `P⁺_k`; the propagation gives mean 0 with covariance
//! `P⁻_{k+1} = Φ_k P⁺_k Φ_kᵀ + Q_k` relative to the predicted nominal state of `k+1`, whose
//! updates then estimate `δ_{k+1}` (the sum of the corrections applied there). With `s⁻_{k+1}` the
//! smoothed error relative to the predicted nominal state and `Pˢ_{k+1}` its covariance:
//!
//! `G_k = P⁺_k Φ_kᵀ (P⁻_{k+1})⁻¹`, `s⁺_k = G_k s⁻_{k+1}`,
//! `Pˢ_k = P⁺_k + G_k (Pˢ_{k+1} − P⁻_{k+1}) G_kᵀ`, `s⁻_k = s⁺_k + δ_k`,
//!
//! starting from `s⁺_n = 0`, `Pˢ_n = P⁺_n` at the last epoch. States with zero predicted variance
//! (switched off) are left out of the inverse: their gain columns are zero.

use nalgebra::{DMatrix, DVector};

/// Why a backward step could not be taken.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum SmoothError {
    #[error("a record came before the end of its chain (the log is not a sequence of chains)")]
    NoChain,
    #[error("the predicted covariance at {time_ns} ns is not positive definite")]
    NotPositiveDefinite { time_ns: u64 },
    #[error("the matrices of a record do not have the state dimension {expected}")]
    Dimension { expected: usize },
}

/// One record of the forward run, read from the last to the first.
#[derive(Debug, Clone)]
pub enum BackwardRecord {
    /// The end of a chain: the covariance after the last epoch's updates.
    End { p_updated: DMatrix<f64> },
    /// A propagation from the previous epoch to the epoch at `time_ns`, with the covariance
    /// before it (`p_updated`, the previous epoch's after its updates), the transition, the
    /// predicted covariance and the sum of the corrections applied at `time_ns`.
    Step {
        time_ns: u64,
        p_updated: DMatrix<f64>,
        transition: DMatrix<f64>,
        p_predicted: DMatrix<f64>,
        correction: DVector<f64>,
    },
    /// The first epoch of a chain, with the corrections applied at it.
    Start {
        time_ns: u64,
        correction: DVector<f64>,
    },
}

/// The smoothed error states at the epochs, in the order the backward pass met them (last
/// first); [`SmoothedEpochs::reverse`] puts them in time order.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct SmoothedEpochs {
    /// State dimension.
    pub dim: usize,
    pub time_ns: Vec<u64>,
    /// The epoch begins a chain (the forward filter started or restarted there).
    pub chain_start: Vec<bool>,
    /// Smoothed error relative to the nominal state after the epoch's corrections (`dim` each).
    pub after_correction: Vec<f64>,
    /// Smoothed error relative to the nominal state before them (`dim` each).
    pub before_correction: Vec<f64>,
    /// Smoothed variances (`dim` each).
    pub variances: Vec<f64>,
    /// Forward (filtered, after the updates) variances (`dim` each).
    pub filtered_variances: Vec<f64>,
}

impl SmoothedEpochs {
    pub fn len(&self) -> usize {
        self.time_ns.len()
    }

    pub fn is_empty(&self) -> bool {
        self.time_ns.is_empty()
    }

    fn row(v: &[f64], dim: usize, i: usize) -> &[f64] {
        &v[i * dim..(i + 1) * dim]
    }

    pub fn after(&self, i: usize) -> &[f64] {
        Self::row(&self.after_correction, self.dim, i)
    }

    pub fn before(&self, i: usize) -> &[f64] {
        Self::row(&self.before_correction, self.dim, i)
    }

    pub fn variance(&self, i: usize) -> &[f64] {
        Self::row(&self.variances, self.dim, i)
    }

    pub fn filtered_variance(&self, i: usize) -> &[f64] {
        Self::row(&self.filtered_variances, self.dim, i)
    }

    /// Puts the epochs in time order (they are collected last first).
    pub fn reverse(&mut self) {
        let (n, d) = (self.len(), self.dim);
        self.time_ns.reverse();
        self.chain_start.reverse();
        for v in [
            &mut self.after_correction,
            &mut self.before_correction,
            &mut self.variances,
            &mut self.filtered_variances,
        ] {
            let mut out = Vec::with_capacity(n * d);
            for i in (0..n).rev() {
                out.extend_from_slice(&v[i * d..(i + 1) * d]);
            }
            *v = out;
        }
    }
}

/// The backward pass, fed the forward run's records from the last to the first.
#[derive(Debug, Clone)]
pub struct Backward {
    dim: usize,
    /// Smoothed error after the corrections of the epoch reached last, and its covariance.
    s_after: DVector<f64>,
    p_smoothed: DMatrix<f64>,
    /// The filtered covariance of that epoch (after its updates).
    p_filtered: DMatrix<f64>,
    in_chain: bool,
    pub epochs: SmoothedEpochs,
    /// Epochs at which a smoothed variance exceeded the filtered one (beyond rounding).
    pub larger_than_filtered: u64,
}

impl Backward {
    pub fn new(dim: usize) -> Backward {
        Backward {
            dim,
            s_after: DVector::zeros(dim),
            p_smoothed: DMatrix::zeros(dim, dim),
            p_filtered: DMatrix::zeros(dim, dim),
            in_chain: false,
            epochs: SmoothedEpochs {
                dim,
                ..Default::default()
            },
            larger_than_filtered: 0,
        }
    }

    /// The smoothed covariance of the epoch reached last (after its corrections).
    pub fn covariance(&self) -> &DMatrix<f64> {
        &self.p_smoothed
    }

    /// The smoothed error of the epoch reached last, after its corrections.
    pub fn error_after_correction(&self) -> &DVector<f64> {
        &self.s_after
    }

    fn emit(&mut self, time_ns: u64, correction: &DVector<f64>, chain_start: bool) {
        let e = &mut self.epochs;
        e.time_ns.push(time_ns);
        e.chain_start.push(chain_start);
        e.after_correction.extend(self.s_after.iter());
        e.before_correction.extend(
            self.s_after
                .iter()
                .zip(correction.iter())
                .map(|(s, d)| s + d),
        );
        e.variances.extend(self.p_smoothed.diagonal().iter());
        e.filtered_variances
            .extend(self.p_filtered.diagonal().iter());
        let larger = (0..self.dim).any(|i| {
            let (s, f) = (self.p_smoothed[(i, i)], self.p_filtered[(i, i)]);
            s > f * (1.0 + 1e-9) + 1e-300
        });
        if larger {
            self.larger_than_filtered += 1;
        }
    }

    fn check(&self, m: &DMatrix<f64>) -> Result<(), SmoothError> {
        if m.nrows() == self.dim && m.ncols() == self.dim {
            Ok(())
        } else {
            Err(SmoothError::Dimension { expected: self.dim })
        }
    }

    /// Takes the next record (going back in time).
    pub fn push(&mut self, r: BackwardRecord) -> Result<(), SmoothError> {
        match r {
            BackwardRecord::End { p_updated } => {
                self.check(&p_updated)?;
                self.s_after = DVector::zeros(self.dim);
                self.p_smoothed = p_updated.clone();
                self.p_filtered = p_updated;
                self.in_chain = true;
            }
            BackwardRecord::Step {
                time_ns,
                p_updated,
                transition,
                p_predicted,
                correction,
            } => {
                if !self.in_chain {
                    return Err(SmoothError::NoChain);
                }
                for m in [&p_updated, &transition, &p_predicted] {
                    self.check(m)?;
                }
                self.emit(time_ns, &correction, false);
                let s_before: DVector<f64> = &self.s_after + &correction;
                let (s, p) = rts_step(
                    &p_updated,
                    &transition,
                    &p_predicted,
                    &s_before,
                    &self.p_smoothed,
                )
                .ok_or(SmoothError::NotPositiveDefinite { time_ns })?;
                self.s_after = s;
                self.p_smoothed = p;
                self.p_filtered = p_updated;
            }
            BackwardRecord::Start {
                time_ns,
                correction,
            } => {
                if !self.in_chain {
                    return Err(SmoothError::NoChain);
                }
                self.emit(time_ns, &correction, true);
                self.in_chain = false;
            }
        }
        Ok(())
    }

    /// The epochs in time order.
    pub fn finish(mut self) -> SmoothedEpochs {
        self.epochs.reverse();
        self.epochs
    }
}

/// `(L Lᵀ)⁻¹ X` for a Cholesky factor `l`: nalgebra's `Cholesky::solve`, bit for bit, with all
/// the columns at once ([`super::cholesky`]).
fn solve_rows_of(l: &DMatrix<f64>, x: &DMatrix<f64>) -> DMatrix<f64> {
    use super::cholesky::{MAX, solve_rows};
    let (n, m) = x.shape();
    let mut rows = [[0.0; MAX]; MAX];
    if n > MAX || m > MAX {
        return nalgebra::Cholesky::pack_dirty(l.clone()).solve(x);
    }
    for (i, row) in rows[..n].iter_mut().enumerate() {
        for (c, v) in row[..m].iter_mut().enumerate() {
            *v = x[(i, c)];
        }
    }
    solve_rows(l, &mut rows[..n], m).expect("sizes checked above");
    DMatrix::from_fn(n, m, |i, c| rows[i][c])
}

fn sub(m: &DMatrix<f64>, rows: &[usize], cols: &[usize]) -> DMatrix<f64> {
    DMatrix::from_fn(rows.len(), cols.len(), |i, j| m[(rows[i], cols[j])])
}

/// One backward step: from the smoothed error `s_next` (relative to the predicted nominal state
/// of the next epoch) and its covariance, the smoothed error after this epoch's corrections and
/// its covariance. `None` when the predicted covariance of the states it has cannot be inverted.
pub fn rts_step(
    p_updated: &DMatrix<f64>,
    transition: &DMatrix<f64>,
    p_predicted: &DMatrix<f64>,
    s_next: &DVector<f64>,
    p_smoothed_next: &DMatrix<f64>,
) -> Option<(DVector<f64>, DMatrix<f64>)> {
    let n = p_updated.nrows();
    // The states with a variance: rows of the gain (`r`, this epoch) and the predicted states
    // it is taken against (`a`, the next).
    let r: Vec<usize> = (0..n).filter(|&i| p_updated[(i, i)] > 0.0).collect();
    let a: Vec<usize> = (0..n).filter(|&i| p_predicted[(i, i)] > 0.0).collect();
    let mut s = DVector::zeros(n);
    let mut p = DMatrix::zeros(n, n);
    if r.is_empty() {
        return Some((s, p));
    }
    if a.is_empty() {
        for &i in &r {
            for &j in &r {
                p[(i, j)] = p_updated[(i, j)];
            }
        }
        return Some((s, p));
    }
    // X = P⁺ Φᵀ restricted: rows r, columns a. Rows of P⁺ outside r are zero.
    let pu_rr = sub(p_updated, &r, &r);
    let phi_ar = sub(transition, &a, &r);
    let x_t = &phi_ar * &pu_rr; // (a × r) = (P⁺ Φᵀ)ᵀ
    let pm_aa = sub(p_predicted, &a, &a);
    // Solved on the correlation matrix `D P⁻ D` (`D` = diag(P⁻)^-1/2): the variances span twenty
    // orders of magnitude (position in m², gyro bias in (rad/s)²), which the unscaled
    // factorisation loses to rounding.
    let d = DVector::from_iterator(a.len(), (0..a.len()).map(|i| 1.0 / pm_aa[(i, i)].sqrt()));
    let scaled = DMatrix::from_fn(a.len(), a.len(), |i, j| pm_aa[(i, j)] * d[i] * d[j]);
    let x_scaled = DMatrix::from_fn(x_t.nrows(), x_t.ncols(), |i, j| x_t[(i, j)] * d[i]);
    let solved = match scaled.clone().cholesky() {
        Some(ch) => solve_rows_of(ch.l_dirty(), &x_scaled),
        None => {
            // Positive semi-definite only: the pseudo-inverse.
            let eig = scaled.symmetric_eigen();
            let max = eig.eigenvalues.amax();
            if !(max.is_finite() && max > 0.0) {
                return None;
            }
            let inv = DVector::from_iterator(
                eig.eigenvalues.len(),
                eig.eigenvalues
                    .iter()
                    .map(|&l| if l > max * 1e-12 { 1.0 / l } else { 0.0 }),
            );
            let v = &eig.eigenvectors;
            v * DMatrix::from_diagonal(&inv) * v.transpose() * &x_scaled
        }
    };
    let g_t = DMatrix::from_fn(solved.nrows(), solved.ncols(), |i, j| solved[(i, j)] * d[i]);
    let g = g_t.transpose(); // r × a
    let s_a = DVector::from_iterator(a.len(), a.iter().map(|&i| s_next[i]));
    let s_r = &g * s_a;
    let d = sub(p_smoothed_next, &a, &a) - &pm_aa;
    let mut p_rr = &pu_rr + &g * d * &g_t;
    // Symmetric by construction up to rounding.
    p_rr = 0.5 * (&p_rr + p_rr.transpose());
    if !p_rr.iter().all(|v| v.is_finite()) || !s_r.iter().all(|v| v.is_finite()) {
        return None;
    }
    for (ii, &i) in r.iter().enumerate() {
        s[i] = s_r[ii];
        for (jj, &j) in r.iter().enumerate() {
            p[(i, j)] = p_rr[(ii, jj)];
        }
    }
    Some((s, p))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A deterministic stream of numbers in (-0.5, 0.5).
    struct Numbers(u64);
    impl Numbers {
        fn next(&mut self) -> f64 {
            self.0 ^= self.0 << 13;
            self.0 ^= self.0 >> 7;
            self.0 ^= self.0 << 17;
            (self.0 >> 11) as f64 / (1u64 << 53) as f64 - 0.5
        }
        fn gauss(&mut self) -> f64 {
            (0..12).map(|_| self.next()).sum()
        }
    }

    /// A linear-Gaussian problem: constant velocity in two axes with a constant bias state that
    /// only the measurements of the first axis see, a state switched off (zero variance), and
    /// measurements missing at some epochs. The forward filter removes its estimate from the
    /// nominal state after each update, as the navigation filter does; the backward pass must give
    /// the batch weighted least-squares solution of the whole problem.
    #[test]
    // Long on purpose: one worked example: the problem, its batch least-squares solution and the
    // smoother's, compared.
    fn smoother_equals_batch_weighted_least_squares() {
        const N: usize = 6;
        const K: usize = 40;
        let dt = 0.5;
        let mut phi = DMatrix::<f64>::identity(N, N);
        phi[(0, 1)] = dt;
        phi[(2, 3)] = dt;
        phi[(4, 4)] = 0.98;
        let mut q = DMatrix::<f64>::zeros(N, N);
        q[(1, 1)] = 0.01;
        q[(3, 3)] = 0.02;
        q[(0, 0)] = 1e-4;
        q[(2, 2)] = 1e-4;
        q[(4, 4)] = 0.003;
        // State 5 is switched off: zero variance, never moved.
        let mut h = DMatrix::<f64>::zeros(2, N);
        h[(0, 0)] = 1.0;
        h[(0, 4)] = 1.0;
        h[(1, 2)] = 1.0;
        h[(1, 1)] = 0.3;
        let r = DMatrix::from_diagonal(&DVector::from_vec(vec![0.2, 0.5]));
        let p0 = DMatrix::from_diagonal(&DVector::from_vec(vec![4.0, 1.0, 4.0, 1.0, 0.5, 0.0]));
        let x0 = DVector::from_vec(vec![1.0, 0.5, -2.0, 0.1, 0.3, 0.0]);
        let mut rng = Numbers(0x9e37_79b9_7f4a_7c15);
        let mut ys = Vec::new();
        for k in 0..K {
            let y = DVector::from_vec(vec![rng.gauss() * 3.0, rng.gauss() * 3.0 + k as f64]);
            ys.push((k % 7 != 3).then_some(y));
        }

        // Forward: nominal state and covariance; the filter's error estimate is removed at once.
        let mut nominal = x0.clone();
        let mut p = p0.clone();
        let mut records = Vec::new();
        let mut filtered = Vec::new();
        let update = |nominal: &mut DVector<f64>, p: &mut DMatrix<f64>, y: &DVector<f64>| {
            // Error = nominal - truth; innovation y - h(nominal) = -H e + v.
            let s = &h * &*p * h.transpose() + &r;
            let k = &*p * h.transpose() * s.try_inverse().expect("S");
            let e = -(&k * (y - &h * &*nominal));
            *nominal -= &e;
            let ikh = DMatrix::identity(N, N) - &k * &h;
            *p = &ikh * &*p * ikh.transpose() + &k * &r * k.transpose();
            e
        };
        let mut delta0 = DVector::zeros(N);
        if let Some(y) = &ys[0] {
            delta0 = update(&mut nominal, &mut p, y);
        }
        filtered.push(nominal.clone());
        records.push(BackwardRecord::Start {
            time_ns: 0,
            correction: delta0,
        });
        for (k, y) in ys.iter().enumerate().skip(1) {
            let p_updated = p.clone();
            nominal = &phi * &nominal;
            p = &phi * &p * phi.transpose() + &q;
            let p_predicted = p.clone();
            let mut delta = DVector::zeros(N);
            if let Some(y) = y {
                delta = update(&mut nominal, &mut p, y);
            }
            filtered.push(nominal.clone());
            records.push(BackwardRecord::Step {
                time_ns: k as u64,
                p_updated,
                transition: phi.clone(),
                p_predicted,
                correction: delta,
            });
        }
        records.push(BackwardRecord::End { p_updated: p });
        let mut back = Backward::new(N);
        for rec in records.into_iter().rev() {
            back.push(rec).expect("step");
        }
        assert_eq!(
            back.larger_than_filtered, 0,
            "smoothed variance above the filtered"
        );
        let epochs = back.finish();
        assert_eq!(epochs.len(), K);

        // Batch: the active states (0..5) of all epochs, weighted least squares through the
        // normal equations.
        const M: usize = 5;
        let dim = M * K;
        let mut info = DMatrix::<f64>::zeros(dim, dim);
        let mut rhs = DVector::<f64>::zeros(dim);
        let add = |info: &mut DMatrix<f64>, r: usize, c: usize, b: &DMatrix<f64>| {
            for i in 0..M {
                for j in 0..M {
                    info[(r * M + i, c * M + j)] += b[(i, j)];
                }
            }
        };
        let phi_a = phi.view((0, 0), (M, M)).clone_owned();
        let q_inv = q
            .view((0, 0), (M, M))
            .clone_owned()
            .try_inverse()
            .expect("Q");
        let p0_inv = p0
            .view((0, 0), (M, M))
            .clone_owned()
            .try_inverse()
            .expect("P0");
        let h_a = h.view((0, 0), (2, M)).clone_owned();
        let r_inv = r.clone().try_inverse().expect("R");
        let x0_a = x0.rows(0, M).clone_owned();
        add(&mut info, 0, 0, &p0_inv);
        let prior = &p0_inv * &x0_a;
        for i in 0..M {
            rhs[i] += prior[i];
        }
        for (k, y) in ys.iter().enumerate() {
            if let Some(y) = y {
                add(&mut info, k, k, &(h_a.transpose() * &r_inv * &h_a));
                let b = h_a.transpose() * &r_inv * y;
                for i in 0..M {
                    rhs[k * M + i] += b[i];
                }
            }
            if k + 1 < K {
                // x_{k+1} - Phi x_k ~ N(0, Q).
                let b = -(phi_a.transpose() * &q_inv);
                add(&mut info, k, k, &(phi_a.transpose() * &q_inv * &phi_a));
                add(&mut info, k, k + 1, &b);
                add(&mut info, k + 1, k, &b.transpose());
                add(&mut info, k + 1, k + 1, &q_inv);
            }
        }
        let cov = info.clone().try_inverse().expect("information");
        let batch = &cov * rhs;
        let mut worst_x: f64 = 0.0;
        let mut worst_p: f64 = 0.0;
        for (k, nominal) in filtered.iter().enumerate() {
            let s = epochs.after(k);
            for i in 0..M {
                worst_x = worst_x.max((nominal[i] - s[i] - batch[k * M + i]).abs());
                worst_p = worst_p.max((epochs.variance(k)[i] - cov[(k * M + i, k * M + i)]).abs());
            }
            assert_eq!(
                epochs.variance(k)[5],
                0.0,
                "the switched-off state stays off"
            );
            assert_eq!(s[5], 0.0);
        }
        assert!(worst_x < 1e-9, "state difference {worst_x:e}");
        assert!(worst_p < 1e-9, "covariance difference {worst_p:e}");
        // The smoothed estimate is not the filtered one (the test would pass vacuously).
        let moved = (0..K - 1).any(|k| epochs.after(k)[0].abs() > 1e-3);
        assert!(moved);
    }

    #[test]
    fn a_step_before_an_end_is_refused() {
        let mut b = Backward::new(2);
        let r = BackwardRecord::Start {
            time_ns: 0,
            correction: DVector::zeros(2),
        };
        assert_eq!(b.push(r), Err(SmoothError::NoChain));
    }
}
