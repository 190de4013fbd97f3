//! USBL aid (S-USBL): the docking station's fixes, tight (slant range and range differences
//! through the array geometry, with Gauss–Markov error states) or loose (the device's fix), by a
//! fixed-noise unscented (ukf), adaptive linearised (akf) or adaptive unscented (aukf) update
//! over every state with non-zero variance, with per-component innovation gating and fixes
//! evaluated at their time of validity ([`model`], [`config`]; the updates and the adaptive noise
//! are in [`crate::ekf`]).

pub mod config;
pub mod model;

pub use config::{Coupling, UsblConfig, UsblFilter};
pub use model::*;
// The generic pieces the USBL update is built from, under the names the tools know them by.
pub use crate::ekf::adaptive_noise::AdaptiveNoise;
pub use crate::ekf::unscented::{
    MeasurementUpdate, UnscentedParams, jacobian, linearized_update, unscented_update,
};

use super::pose_history::PoseHistory;
use super::{AidUpdate, NavCore};
use crate::ekf::{self, ErrorFilter, StateVector};
use crate::strapdown::NavState;
use auvnav_shm_schema::{AidDiagnosticsV1, AidSource, UsblFixV1};
use nalgebra::{DMatrix, DVector, Vector3};

/// Counts of what became of the USBL fixes.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct UsblCounters {
    pub fused: u64,
    /// Rejected by the innovation gate.
    pub rejected: u64,
    /// Without the fields the coupling needs, or with values out of range.
    pub invalid: u64,
    /// Received without a `[navigation.usbl]` configuration.
    pub unconfigured: u64,
    /// Times the gate reopened after a run of rejections.
    pub reopened: u64,
    /// Updates that failed numerically (covariance not positive definite).
    pub failed: u64,
}

/// The USBL aid: the fusion state when configured, and its counters.
#[derive(Debug, Clone)]
pub struct UsblAid {
    pub fusion: Option<UsblFusion>,
    pub counters: UsblCounters,
}

/// The USBL fusion state: the surveyed array, the current estimate of the USBL measurement errors
/// (Gauss–Markov, tight coupling) and the noise estimator.
#[derive(Debug, Clone)]
pub struct UsblFusion {
    cfg: UsblConfig,
    array: UsblArray,
    lever_arm_b: Vector3<f64>,
    /// Started at the first usable fix (the loose noise depends on its geometry).
    noise: Option<AdaptiveNoise>,
    last_fused_s: Option<f64>,
    /// The vehicle's recent poses, for fixes whose time of validity lies in the past;
    /// `max_latency_s` of them.
    poses: PoseHistory,
}

impl UsblAid {
    /// The aid for `cfg` (none: fixes are counted as unconfigured); tight coupling sets the
    /// Gauss–Markov error states' processes in `kf`.
    pub fn new(cfg: Option<&UsblConfig>, kf: &mut ErrorFilter) -> UsblAid {
        let fusion = cfg.map(|u| {
            if u.coupling == Coupling::Tight {
                kf.set_gauss_markov(ekf::USBL, u.range_error_correlation_s, u.range_error_std_m);
                for i in 1..3 {
                    kf.set_gauss_markov(
                        ekf::USBL + i,
                        u.range_difference_error_correlation_s,
                        u.range_difference_error_std_m,
                    );
                }
            }
            UsblFusion {
                array: u.array(),
                lever_arm_b: Vector3::from(u.responder_lever_arm_m),
                noise: None,
                last_fused_s: None,
                poses: PoseHistory::new(u.max_latency_s + 0.1),
                cfg: u.clone(),
            }
        });
        UsblAid {
            fusion,
            counters: UsblCounters::default(),
        }
    }

    /// Keeps the vehicle's pose for fixes whose time of validity lies in the past.
    pub fn after_imu(&mut self, s: &NavState) {
        if let Some(u) = self.fusion.as_mut() {
            u.poses.push(s.time_s, s.position, s.q_body_to_ned);
        }
    }

    /// Time of the last fused fix (s).
    pub fn last_fused_s(&self) -> Option<f64> {
        self.fusion.as_ref().and_then(|u| u.last_fused_s)
    }

    /// The estimated USBL measurement errors [δR, δΔR13, δΔR24] (m) and the noise variances in
    /// use, when USBL fusion is configured and has seen a fix.
    pub fn estimates(&self, core: &NavCore) -> Option<(Vector3<f64>, Vector3<f64>)> {
        let u = self.fusion.as_ref()?;
        let v = u.noise.as_ref()?.variances();
        Some((errors(core), Vector3::new(v[0], v[1], v[2])))
    }

    /// Fuses a USBL fix from the docking station by the configured coupling and filter.
    ///
    /// Tight: `z = [R, ΔR13, ΔR24]`, predicted from the state by the exact array geometry plus
    /// the Gauss–Markov error states; loose: the fix as a position, in line-of-sight coordinates.
    /// The update runs over every state with non-zero variance (unscented for ukf/aukf,
    /// linearised for akf); the innovation passes the gate of the noise estimator before anything
    /// is changed, so a rejected fix moves neither the state nor the noise estimate.
    // Long on purpose: the tight and the loose USBL updates share the gate, the adaptive noise step
    // and the bookkeeping, so the state is changed in one place.
    pub fn fuse(&mut self, core: &mut NavCore, m: &UsblFixV1) -> AidUpdate {
        let t_ns = m.validity_time_ns;
        let source = match self.fusion.as_ref().map(|u| u.cfg.coupling) {
            Some(Coupling::Loose) => AidSource::UsblPosition,
            _ => AidSource::UsblSlantRange,
        };
        let mut d = core.diagnostics(t_ns, source);
        d.dimension = 3;
        d.flags = AidDiagnosticsV1::FLAG_REJECTED;
        let Some(u) = self.fusion.as_ref() else {
            self.counters.unconfigured += 1;
            return AidUpdate::rejected(d);
        };
        let meas = match measurement(&u.cfg, &u.array, m) {
            Ok(x) => x,
            Err(_) => {
                self.counters.invalid += 1;
                return AidUpdate::rejected(d);
            }
        };
        let t_valid = t_ns as f64 * 1e-9;
        if core.state().time_s - t_valid > u.cfg.max_latency_s {
            core.counters.aid_late += 1;
            return AidUpdate::rejected(d);
        }
        core.propagate_covariance();
        let Some(u) = self.fusion.as_mut() else {
            return AidUpdate::rejected(d);
        };
        // The geometry at the fix's time of validity; the errors are those of now.
        let s = core.state();
        let (position, attitude) = if t_valid < s.time_s {
            u.poses
                .at(t_valid)
                .map_or((s.position, s.q_body_to_ned), |p| (p.position, p.attitude))
        } else {
            (s.position, s.q_body_to_ned)
        };
        let geometry = ResponderGeometry::new(
            &u.array,
            &position,
            &attitude.to_rotation_matrix().into_inner(),
            &u.lever_arm_b,
        );
        let noise = u.noise.get_or_insert_with(|| {
            let r0 = meas.r.diagonal();
            let scale = r0.max();
            let mut n = AdaptiveNoise::new(
                DVector::from_column_slice(r0.as_slice()),
                u.cfg.fading,
                (0.1f64 * 0.1) * r0.min(),
                1.0e4 * scale,
                u.cfg.gate_chi2,
            );
            n.reopen_after = u.cfg.reopen_after;
            n.learn = u.cfg.filter != UsblFilter::Ukf;
            n
        });
        // The states the update runs over: every one with non-zero variance.
        let active: Vec<usize> = (0..ekf::N).filter(|&i| core.kf.p[(i, i)] > 0.0).collect();
        let slot = |state: usize| active.iter().position(|&i| i == state);
        let pos = [0, 1, 2].map(|i| slot(ekf::POS + i));
        let att = [0, 1, 2].map(|i| slot(ekf::ATT + i));
        let err = [0, 1, 2].map(|i| slot(ekf::USBL + i));
        let pick = |dx: &DVector<f64>, idx: &[Option<usize>; 3]| {
            Vector3::from(idx.map(|k| k.map_or(0.0, |k| dx[k])))
        };
        let coupling = u.cfg.coupling;
        let max_range_m = u.cfg.max_range_m;
        let errors = errors(core);
        let array = u.array;
        // Loose: array frame → line-of-sight coordinates of this fix.
        let to_los = meas.frame * u.array.c_ned_to_array.transpose();
        let h = move |dx: &DVector<f64>| -> DVector<f64> {
            let p_a = geometry.responder_given_error(&pick(dx, &pos), &pick(dx, &att));
            let z = match coupling {
                Coupling::Tight => predict_tight(&array, &p_a) + errors - pick(dx, &err),
                Coupling::Loose => to_los * p_a,
            };
            DVector::from_column_slice(z.as_slice())
        };
        let active_p = |kf: &ErrorFilter| -> DMatrix<f64> {
            DMatrix::from_fn(active.len(), active.len(), |i, j| {
                kf.p[(active[i], active[j])]
            })
        };
        let p = active_p(&core.kf);
        let z = DVector::from_column_slice(meas.z.as_slice());
        let unscented = u.cfg.unscented();
        let kind = u.cfg.filter;
        let update = |p: &DMatrix<f64>, r: &DMatrix<f64>| match kind {
            UsblFilter::Akf => linearized_update(p, &z, r, &h),
            UsblFilter::Ukf | UsblFilter::Aukf => unscented_update(p, &z, r, &h, unscented),
        };
        // Fixed noise (ukf): this fix's configured noise (diagonal in the measurement's
        // coordinates); adaptive: the estimator's.
        if kind == UsblFilter::Ukf {
            noise.set_variances(&DVector::from_column_slice(meas.r.diagonal().as_slice()));
        }
        let r_used = noise.covariance();
        let Some(mut upd) = update(&p, &r_used) else {
            self.counters.failed += 1;
            return AidUpdate::rejected(d);
        };
        let hph = &upd.innovation_cov - &r_used;
        let reopened = noise.reopened;
        // The gate that decides (per component, χ²₁), with the noise in use: its test ratio is
        // what the diagnostics report (above 1 = rejected, unless the gate reopened: FLAG_RESET).
        let gated = noise.gate(&upd.innovation, &hph);
        let accepted = noise.observe(&upd.innovation, &hph);
        if noise.reopened != reopened {
            // A run of fixes that agree with one another but not with the state: the state is
            // what is wrong (an outlier fused at the first fix of a wide prior left the filter
            // sure of a position metres off). The position's covariance is re-opened by the
            // range innovation and the noise goes back to this fix's nominal one; taken as the
            // new noise instead, the innovation became measurement noise and the filter kept
            // its wrong position for good.
            self.counters.reopened += 1;
            d.flags |= AidDiagnosticsV1::FLAG_RESET;
            // Bounded by the acoustic range: an absurd fix must not open it without limit.
            let reopen_by = upd.innovation[0].abs();
            let reopen_by = if reopen_by.is_finite() {
                reopen_by.min(max_range_m)
            } else {
                max_range_m
            };
            core.reopen(ekf::POS, [reopen_by * reopen_by; 3]);
            noise.set_variances(&DVector::from_column_slice(meas.r.diagonal().as_slice()));
            let r = noise.covariance();
            match update(&active_p(&core.kf), &r) {
                Some(x) => upd = x,
                None => {
                    self.counters.failed += 1;
                    return AidUpdate::rejected(d);
                }
            }
        }
        for i in 0..3 {
            d.observation[i] = meas.z[i];
            d.innovation[i] = upd.innovation[i];
            d.innovation_variance[i] = upd.innovation_cov[(i, i)];
            d.observation_variance[i] = noise.variances()[i];
        }
        d.test_ratio = gated.test_ratio;
        if !accepted {
            self.counters.rejected += 1;
            return AidUpdate::rejected(d);
        }
        if (0..upd.p.nrows()).any(|i| !(upd.p[(i, i)].is_finite() && upd.p[(i, i)] >= 0.0)) {
            self.counters.failed += 1;
            return AidUpdate::rejected(d);
        }
        let mut dx = StateVector::zeros();
        for (a, &i) in active.iter().enumerate() {
            dx[i] = upd.dx[a];
            for (b, &j) in active.iter().enumerate() {
                core.kf.p[(i, j)] = upd.p[(a, b)];
            }
        }
        u.last_fused_s = Some(t_valid);
        self.counters.fused += 1;
        d.flags = AidDiagnosticsV1::FLAG_FUSED | (d.flags & AidDiagnosticsV1::FLAG_RESET);
        AidUpdate {
            diagnostics: d,
            correction: Some(dx),
        }
    }
}

/// The estimated measurement errors [δR, δΔR13, δΔR24] (m), subtracted from the measurement:
/// Gauss–Markov parameter states, whose means the core keeps and decays.
fn errors(core: &NavCore) -> Vector3<f64> {
    let i = ekf::USBL - ekf::CORE;
    Vector3::new(
        core.markov_means[i],
        core.markov_means[i + 1],
        core.markov_means[i + 2],
    )
}
