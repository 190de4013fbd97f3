//! Adaptive measurement noise (Sage–Husa with a fading factor) with per-component innovation
//! gating, as the S-USBL adaptive filters use it.

use crate::ekf::gate;
use nalgebra::{DMatrix, DVector};

/// On-line estimate of a diagonal measurement-noise covariance from the innovations (Sage–Husa
/// with a fading factor), with innovation gating so that outliers (multipath jumps) neither enter
/// the state nor the noise estimate.
///
/// With innovation ε and predicted measurement covariance H P⁻ Hᵀ, per component i:
/// R_i ← b R_i + (1 − b) (ε_i² − (H P⁻ Hᵀ)_ii), kept within [r_min, r_max]. The weight is
/// constant: the starting value counts as a full memory of measurements. (The bias-corrected
/// weights d_k = (1 − b) / (1 − b^(k+1)) of the textbook form give the first innovation weight 1:
/// one small innovation then set R far below the truth, the gate became too narrow and R could
/// not grow back while H P⁻ Hᵀ exceeded it — seen in the docking Monte Carlo.) R_i is only
/// learnt while (H P⁻ Hᵀ)_ii < R_i: while the state's own uncertainty dominates, ε_i² says little about the noise and an undetected outlier would inflate it (seen in
/// the test: one 20 m jump at the start raised σ to 6 m). A component whose ε_i² / (H P⁻ Hᵀ + R)_ii
/// exceeds `gate_chi2` rejects the
/// whole measurement. After `reopen_after` consecutive rejections the noise is assumed to have
/// changed: the next measurement is accepted and its innovation taken as the new noise (counted),
/// so a real change of the noise cannot lock the gate shut for ever.
#[derive(Debug, Clone)]
pub struct AdaptiveNoise {
    r: DVector<f64>,
    /// Fading factor b (0.9..1): the memory is about 1 / (1 − b) measurements.
    pub fading: f64,
    pub r_min: f64,
    pub r_max: f64,
    /// Gate on the normalised squared innovation per component (χ², 1 degree of freedom).
    pub gate_chi2: f64,
    pub reopen_after: u32,
    /// Learn the noise from the innovations (false: fixed noise, gating only).
    pub learn: bool,
    consecutive: u32,
    /// Measurements rejected by the gate.
    pub rejected: u64,
    /// Times the gate was reopened after a run of rejections.
    pub reopened: u64,
}

impl AdaptiveNoise {
    /// Starts from the diagonal `r0` (variances).
    pub fn new(r0: DVector<f64>, fading: f64, r_min: f64, r_max: f64, gate_chi2: f64) -> Self {
        AdaptiveNoise {
            r: r0,
            fading,
            r_min,
            r_max,
            gate_chi2,
            reopen_after: 20,
            learn: true,
            consecutive: 0,
            rejected: 0,
            reopened: 0,
        }
    }

    /// The current noise covariance (diagonal).
    pub fn covariance(&self) -> DMatrix<f64> {
        DMatrix::from_diagonal(&self.r)
    }

    /// Replaces the variances (a fixed-noise filter whose noise follows the geometry).
    pub fn set_variances(&mut self, r: &DVector<f64>) {
        self.r.copy_from(r);
    }

    /// The current variances.
    pub fn variances(&self) -> &DVector<f64> {
        &self.r
    }

    /// The gate on the innovation `eps` (predicted measurement covariance without noise `hph`)
    /// with the current noise: per component against `gate_chi2` ([`gate::per_component`]).
    pub fn gate(&self, eps: &DVector<f64>, hph: &DMatrix<f64>) -> gate::GateOutcome {
        gate::per_component(eps.as_slice(), |i| hph[(i, i)] + self.r[i], self.gate_chi2)
    }

    /// Gates the innovation `eps` (predicted measurement covariance without noise `hph`) and, if
    /// it passes, updates the estimate. Returns whether the measurement is to be used.
    pub fn observe(&mut self, eps: &DVector<f64>, hph: &DMatrix<f64>) -> bool {
        let outlier = !self.gate(eps, hph).passed;
        if outlier && self.consecutive < self.reopen_after {
            self.consecutive += 1;
            self.rejected += 1;
            return false;
        }
        self.consecutive = 0;
        if outlier {
            self.reopened += 1;
            // The noise has changed (or the state is off): restart from this innovation.
            for i in 0..eps.len() {
                let sample = eps[i] * eps[i] - hph[(i, i)];
                self.r[i] = self.r[i].max(sample).clamp(self.r_min, self.r_max);
            }
            return true;
        }
        if !self.learn {
            return true;
        }
        let d = 1.0 - self.fading;
        for i in 0..eps.len() {
            if hph[(i, i)] >= self.r[i] {
                continue;
            }
            let sample = eps[i] * eps[i] - hph[(i, i)];
            let v = (1.0 - d) * self.r[i] + d * sample;
            self.r[i] = v.clamp(self.r_min, self.r_max);
        }
        true
    }
}
