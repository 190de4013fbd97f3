//! Several logs as several voyages. Each log is analysed alone, against its own reference, time
//! base and held-out blocks (its own discovery, as for one log). The installation effects are the
//! vehicle's and shared by its voyages: they are selected on all voyages together, with each
//! voyage left out in turn as the held-out test (the shared values fitted on the other voyages
//! predict the one left out), and combined as the information-weighted mean of each voyage's
//! estimate. A cross-voyage χ² tests whether the voyages agree within their own uncertainties
//! (Newey–West, so correlated residuals widen them): an effect on which they disagree is reported
//! as inconsistent, never as a finding — unless a few voyages (at most a quarter, with at least
//! three left) depart from what the rest agree on: the rest share it, and the few are named and
//! fit their own value, so that one odd voyage neither stops the vehicle's installation from
//! being shared nor pulls its value. The effects of one voyage — an IMU bias realisation, the
//! water's density, the sound speed of the acoustic link, the local field — stay each voyage's
//! own, fitted in every voyage where its own discovery named them.
//!
//! Long on purpose: several voyages' discovery (per-voyage analyses, shared selection with voyages
//! left out, combination, agreement test), in the order of the module's text.

use super::analysis::{
    DiscoverReport, FoundEffect, NoiseEstimate, Unseparable, discover, json_of, screen_outliers,
};
use super::fit::{self, Fit, Problem, Selection};
use super::{CANDIDATES, Channel, ChannelKind, Reference, spec};
use auvnav_sim::effects::Effects;
use nalgebra::{DMatrix, DVector};

/// The standard normal quantile of the agreement test (one-sided 1 %): voyages whose spread
/// exceeds the χ² quantile at this level disagree.
pub const AGREEMENT_Z: f64 = 2.326_348;

/// Effects that belong to one voyage rather than to the vehicle's installation: a turn-on bias,
/// the water, the acoustic path, the place.
pub fn per_voyage(name: &str) -> bool {
    matches!(
        name,
        "imu.gyro_bias"
            | "imu.accel_bias"
            | "depth.density"
            | "dvl.sound_speed"
            | "dvl.bed_velocity"
            | "dvl.periodic_velocity_error"
            | "usbl.sound_speed"
            | "mag.declination"
            | "mag.inclination"
            | "mag.intensity"
    )
}

/// Per-voyage effects fitted in every voyage of the shared selection, named alone or not: an
/// IMU has a bias in every run (its turn-on bias, and a drifting bias's mean over the voyage),
/// so that a shared scale factor or misalignment does not take up the bias of a voyage whose
/// own discovery left it below the test. The other per-voyage effects are fitted in the voyages
/// that named them.
pub fn in_every_voyage(name: &str) -> bool {
    matches!(name, "imu.gyro_bias" | "imu.accel_bias")
}

/// One log: its channels and its reference motion.
pub struct VoyageData {
    pub log: String,
    pub channels: Vec<Channel>,
    pub reference: Reference,
}

pub use super::findings::{
    Agreeing, NamedAlone, SharedEffect, VoyageEstimate, VoyageScore, Voyages,
};
use super::findings::{Undetermined, values_of};

/// An estimate in deviations from nominal with its information (pseudo-inverse of the
/// covariance; a component without a finite variance carries none).
#[derive(Clone)]
struct Estimate {
    delta: DVector<f64>,
    info: DMatrix<f64>,
    rank: usize,
    /// The degrees of freedom of its deviations ([`Fit::deviation_dof`]; infinite when known).
    dof: f64,
}

fn pseudo_inverse(m: &DMatrix<f64>) -> (DMatrix<f64>, usize) {
    let n = m.nrows();
    if n == 0 {
        return (DMatrix::zeros(0, 0), 0);
    }
    let sym = (m + m.transpose()) * 0.5;
    let e = sym.symmetric_eigen();
    let max = e.eigenvalues.iter().fold(0.0f64, |a, b| a.max(b.abs()));
    let mut inv = DMatrix::zeros(n, n);
    let mut rank = 0;
    for k in 0..n {
        let l = e.eigenvalues[k];
        if max > 0.0 && l > 1e-10 * max {
            let v = e.eigenvectors.column(k);
            inv += (v * v.transpose()) / l;
            rank += 1;
        }
    }
    (inv, rank)
}

impl Estimate {
    fn new(theta: &[f64], nominal: &[f64], cov: &DMatrix<f64>, dof: f64) -> Estimate {
        let n = theta.len();
        let finite: Vec<usize> = (0..n)
            .filter(|&i| {
                cov[(i, i)].is_finite()
                    && cov[(i, i)] > 0.0
                    && (0..n).all(|j| cov[(i, j)].is_finite())
            })
            .collect();
        let sub = DMatrix::from_fn(finite.len(), finite.len(), |i, j| {
            cov[(finite[i], finite[j])]
        });
        let (inv, rank) = pseudo_inverse(&sub);
        let mut info = DMatrix::zeros(n, n);
        for (a, &i) in finite.iter().enumerate() {
            for (b, &j) in finite.iter().enumerate() {
                info[(i, j)] = inv[(a, b)];
            }
        }
        let delta = DVector::from_iterator(n, theta.iter().zip(nominal).map(|(t, n)| t - n));
        Estimate {
            delta,
            info,
            rank,
            dof,
        }
    }

    fn block(&self, off: usize, len: usize) -> Estimate {
        self.pick(&(off..off + len).map(Some).collect::<Vec<_>>())
    }

    /// The marginal of the components `rows` names, in that order; `None` is a component this
    /// estimate does not determine (infinite variance, no information).
    fn pick(&self, rows: &[Option<usize>]) -> Estimate {
        // Invert the information back to a covariance first.
        let (cov, _) = pseudo_inverse(&self.info);
        let det = |r: Option<usize>| r.filter(|&i| self.info[(i, i)] > 0.0);
        let sub = DMatrix::from_fn(rows.len(), rows.len(), |a, b| {
            match (det(rows[a]), det(rows[b])) {
                (Some(i), Some(j)) => cov[(i, j)],
                _ if a == b => f64::INFINITY,
                _ => 0.0,
            }
        });
        let zero = vec![0.0; rows.len()];
        let theta: Vec<f64> = rows
            .iter()
            .map(|r| r.map_or(0.0, |i| self.delta[i]))
            .collect();
        Estimate::new(&theta, &zero, &sub, self.dof)
    }
}

/// The combination of several estimates of the same parameters.
struct Combined {
    delta: DVector<f64>,
    /// Per component: its standard deviation (infinite where no voyage determines it).
    std: Vec<f64>,
    chi2: f64,
    dof: usize,
    /// The voyages that determine some component.
    voyages: usize,
    /// Welch's Σ (1 − hᵢ)² / νᵢ over those voyages, hᵢ a voyage's share of the combined
    /// information and νᵢ its deviations' degrees of freedom (0 when every deviation is known).
    welch: f64,
}

fn combine(es: &[&Estimate], n: usize) -> Combined {
    let mut info = DMatrix::zeros(n, n);
    let mut b = DVector::zeros(n);
    let mut ranks = 0;
    for e in es {
        info += &e.info;
        b += &e.info * &e.delta;
        ranks += e.rank;
    }
    let (cov, rank) = pseudo_inverse(&info);
    let delta = &cov * b;
    let std = (0..n)
        .map(|k| {
            if info[(k, k)] > 0.0 {
                cov[(k, k)].max(0.0).sqrt()
            } else {
                f64::INFINITY
            }
        })
        .collect();
    let chi2 = es
        .iter()
        .map(|e| {
            let d = &e.delta - &delta;
            (d.transpose() * &e.info * &d)[(0, 0)]
        })
        .sum();
    // Each voyage's share of the combined information, tr(Iᵢ I⁺) / rank (wᵢ / W for one
    // component).
    let determining: Vec<&&Estimate> = es.iter().filter(|e| e.rank > 0).collect();
    let welch = determining
        .iter()
        .map(|e| {
            let share = (&e.info * &cov).trace() / rank.max(1) as f64;
            (1.0 - share).powi(2) / e.dof
        })
        .sum();
    Combined {
        delta,
        std,
        chi2,
        dof: ranks.saturating_sub(rank),
        voyages: determining.len(),
        welch,
    }
}

impl Combined {
    /// The χ² above which the estimates disagree (1 %, [`AGREEMENT_Z`]). Each voyage's deviation
    /// is itself estimated, from a few correlation times of a slowly varying error, so the spread
    /// of estimates that agree is wider than their deviations say: Welch's (1951) test of means
    /// with estimated variances takes χ² / dof, divided by 1 + 2(k − 2) A / (k² − 1), as an F
    /// with dof and (k² − 1) / 3A degrees of freedom, for k voyages and A = [`Combined::welch`].
    /// With known deviations (white residuals, A = 0) it is the χ² quantile. An effect of several
    /// components takes each voyage's share over them together (an approximation: Welch's test
    /// is for one).
    fn limit(&self) -> f64 {
        let dof = self.dof.max(1) as f64;
        let k = self.voyages.max(2) as f64;
        let a = self.welch;
        if !(a.is_finite() && a > 0.0) {
            return auvnav_studies::nees::chi2_quantile(dof, AGREEMENT_Z);
        }
        let denominator_dof = (k * k - 1.0) / (3.0 * a);
        let correction = 1.0 + 2.0 * (k - 2.0) * a / (k * k - 1.0);
        dof * correction * auvnav_studies::nees::f_quantile(dof, denominator_dof, AGREEMENT_Z)
    }

    /// The estimates disagree beyond their uncertainties.
    fn disagrees(&self) -> bool {
        self.dof > 0 && self.chi2 > self.limit()
    }
}

/// Each voyage's marginal estimate of the block `off..off + len` and their combination.
fn agreement_of(ests: &[Estimate], off: usize, len: usize) -> (Vec<Estimate>, Combined) {
    let alone: Vec<Estimate> = ests.iter().map(|e| e.block(off, len)).collect();
    let c = combine(&alone.iter().collect::<Vec<_>>(), len);
    (alone, c)
}

/// One voyage's data for one channel.
struct ChannelVoyage<'a> {
    voyage: usize,
    p: Problem<'a>,
    /// The per-voyage effects this voyage's own discovery named on the channel, and the
    /// installation effects the voyages disagree on (each voyage's own value).
    own: Vec<usize>,
}

fn offset_in(set: &[usize], c: usize) -> (usize, usize) {
    fit::offset_of(set, c)
}

fn components(set: &[usize]) -> usize {
    set.iter()
        .map(|&c| spec(CANDIDATES[c].name).map_or(1, |s| s.components))
        .sum()
}

/// A voyage's set (the shared effects first, then its own) and its fit.
type VoyageFit = (Vec<usize>, Fit);

/// Each voyage's fit of the shared set with its own effects (the shared effects it shares first;
/// a voyage set aside as departing from a shared effect fits that effect as its own).
fn fit_voyages(cv: &[ChannelVoyage], shared: &[usize]) -> Vec<VoyageFit> {
    cv.iter()
        .map(|v| {
            let mut set: Vec<usize> = shared
                .iter()
                .copied()
                .filter(|c| !v.own.contains(c))
                .collect();
            set.extend(v.own.iter().copied());
            let f = v.p.fit(&set, &v.p.epochs);
            (set, f)
        })
        .collect()
}

/// Each voyage's estimate of the shared set; a shared effect the voyage fits as its own (it
/// departs from it) carries no information there.
fn shared_estimates(cv: &[ChannelVoyage], shared: &[usize], fits: &[VoyageFit]) -> Vec<Estimate> {
    fits.iter()
        .zip(cv)
        .map(|((set, f), v)| {
            let n = components(shared);
            let shares: Vec<usize> = shared
                .iter()
                .copied()
                .filter(|c| !v.own.contains(c))
                .collect();
            let mut nominal = v.p.nominal_theta(&shares);
            nominal.resize(f.theta.len(), 0.0);
            let full = Estimate::new(&f.theta, &nominal, &f.cov, f.deviation_dof());
            let mut rows = Vec::with_capacity(n);
            for &c in shared {
                let (off, len) = offset_in(set, c);
                let mine = !v.own.contains(&c);
                rows.extend((0..len).map(|k| mine.then_some(off + k)));
            }
            full.pick(&rows)
        })
        .collect()
}

/// The leave-one-voyage-out mean squared residual of a shared set, and each voyage's held-out
/// shared parameters.
fn held_out(
    cv: &[ChannelVoyage],
    shared: &[usize],
    estimates: &[Estimate],
) -> (f64, Vec<Vec<f64>>) {
    let n = components(shared);
    let (mut sse, mut count) = (0.0, 0usize);
    let mut thetas = Vec::with_capacity(cv.len());
    for (k, v) in cv.iter().enumerate() {
        let others: Vec<&Estimate> = estimates
            .iter()
            .enumerate()
            .filter(|(j, _)| *j != k)
            .map(|(_, e)| e)
            .collect();
        let c = combine(&others, n);
        let theta: Vec<f64> =
            v.p.nominal_theta(shared)
                .iter()
                .zip(c.delta.iter())
                .map(|(a, b)| a + b)
                .collect();
        let q = Problem {
            channel: v.p.channel,
            reference: std::borrow::Cow::Borrowed(&*v.p.reference),
            nominal: v.p.effects(shared, &theta),
            epochs: v.p.epochs.clone(),
            noise_lags: v.p.noise_lags,
            noise_model: v.p.noise_model.clone(),
            drift_knot_s: v.p.drift_knot_s,
            reference_noise: v.p.reference_noise,
        };
        let e = if v.own.is_empty() {
            q.nominal.clone()
        } else {
            let f = q.fit(&v.own, &q.epochs);
            q.effects(&v.own, &f.theta)
        };
        let r = q.residuals(&e, &q.epochs);
        sse += r.iter().map(|x| x * x).sum::<f64>() + q.given_back(&e, &q.epochs);
        count += r.len();
        thetas.push(theta);
    }
    (sse / count.max(1) as f64, thetas)
}

/// Discovery on several voyages (see the module's text): each voyage's own report, the shared
/// installation effects and their agreement, in one report whose `effects` are the shared
/// effects the voyages agree on.
pub fn discover_voyages(
    data: &[VoyageData],
    nominal: &Effects,
    fit_fraction: f64,
    sel: &Selection,
) -> DiscoverReport {
    let start = std::time::Instant::now();
    let reports: Vec<DiscoverReport> = data
        .iter()
        .map(|d| {
            let mut r = discover(&d.channels, &d.reference, nominal, fit_fraction, sel);
            r.inputs = vec![d.log.clone()];
            r
        })
        .collect();
    let mut out = DiscoverReport::new(nominal);
    out.inputs = data.iter().map(|d| d.log.clone()).collect();
    let mut v = Voyages {
        voyages: Vec::new(),
        shared: Vec::new(),
        inconsistent: Vec::new(),
        per_voyage: Vec::new(),
        not_confirmed: Vec::new(),
        scores: Vec::new(),
        held_out_models: vec![nominal.clone(); data.len()],
    };
    let mut model = nominal.clone();
    for kind in ChannelKind::ALL {
        let analysed: Vec<usize> = (0..data.len())
            .filter(|&i| reports[i].channels.iter().any(|c| c.channel == kind))
            .collect();
        if analysed.is_empty() {
            continue;
        }
        // Per-voyage effects named by each voyage alone.
        let named = |i: usize, name: &str| named_alone(&reports, i, kind, name);
        let candidates: Vec<usize> = (0..CANDIDATES.len())
            .filter(|&c| CANDIDATES[c].channel == kind && sel.allows(c))
            .collect();
        for &c in &candidates {
            let name = CANDIDATES[c].name;
            let by: Vec<VoyageEstimate> = analysed
                .iter()
                .filter_map(|&i| {
                    named(i, name).map(|e| VoyageEstimate {
                        log: data[i].log.clone(),
                        value: e.value.clone(),
                        std: e.std.clone(),
                    })
                })
                .collect();
            if per_voyage(name) && !by.is_empty() {
                v.per_voyage.push(NamedAlone {
                    agreeing: None,
                    name: name.into(),
                    channel: kind,
                    unit: spec(name).map_or("", |s| s.unit).into(),
                    voyages: by,
                });
            }
        }
        if analysed.len() < 2 {
            out.notes.push(format!(
                "{}: analysed in one voyage only ({}): its effects are that voyage's own",
                kind.name(),
                data[analysed[0]].log
            ));
            continue;
        }
        // The notes of the outlier screening are in each voyage's own report.
        let mut scratch = DiscoverReport::new(nominal);
        let prepared: Vec<(usize, Channel)> = analysed
            .iter()
            .filter_map(|&i| {
                let ch = data[i].channels.iter().find(|c| c.kind == kind)?;
                let ch = if kind.partial() {
                    screen_outliers(ch, &data[i].reference, nominal, &mut scratch)
                } else {
                    crate::periodic::lined(ch, &data[i].reference, nominal)
                };
                Some((i, ch))
            })
            .collect();
        let mut cv: Vec<ChannelVoyage> = prepared
            .iter()
            .map(|(i, ch)| {
                let p = Problem::new(ch, &data[*i].reference, nominal.clone());
                let own = candidates
                    .iter()
                    .copied()
                    .filter(|&c| {
                        let name = CANDIDATES[c].name;
                        per_voyage(name) && (named(*i, name).is_some() || in_every_voyage(name))
                    })
                    .collect();
                ChannelVoyage { voyage: *i, p, own }
            })
            .filter(|c| c.p.epochs.len() >= 10 * fit::FOLDS)
            .collect();
        if cv.len() < 2 {
            continue;
        }
        let installation: Vec<usize> = candidates
            .iter()
            .copied()
            .filter(|&c| !per_voyage(CANDIDATES[c].name))
            .collect();
        // Forward selection with the voyages as the held-out folds.
        let out_of = (&mut v.inconsistent, &mut out.undetermined);
        let (shared, gains) = select_shared(&mut cv, data, &installation, sel, out_of);
        record_shared(
            &cv,
            data,
            nominal,
            kind,
            &shared,
            &gains,
            &mut v,
            &mut model,
            &mut out.effects,
        );
        // Installation effects voyages named alone that the voyages together do not confirm:
        // disagreement or too little held-out gain.
        not_confirmed(
            &cv,
            data,
            &reports,
            kind,
            &installation,
            &shared,
            &mut v,
            &mut out.notes,
        );
        // Pairs no voyage's motion separates.
        out.unseparable
            .extend(unseparable_pairs(&cv, &reports, kind));
    }
    out.noise = pooled_noise(&reports);
    for r in &reports {
        for n in &r.notes {
            out.notes.push(format!("{}: {n}", r.inputs.join(", ")));
        }
    }
    out.model = model;
    out.held_out_model = nominal.clone();
    v.voyages = reports;
    out.voyages = Some(Box::new(v));
    out.wall_s = start.elapsed().as_secs_f64();
    out
}

/// Forward selection of the installation effects with the voyages as the held-out folds: the
/// shared set and each one's held-out gain. An effect on which a few voyages depart from what
/// the others agree is tried with those voyages set aside ([`departing_from`]); an effect the
/// voyages disagree on otherwise goes to `inconsistent` and stays in the data as each voyage's
/// own, so that it does not bias the effects the voyages do share. The shared set is then
/// settled so that it still agrees at the end ([`settle_agreement`]).
fn select_shared(
    cv: &mut [ChannelVoyage],
    data: &[VoyageData],
    installation: &[usize],
    sel: &Selection,
    (inconsistent, undetermined): (&mut Vec<SharedEffect>, &mut Vec<Undetermined>),
) -> (Vec<usize>, Vec<f64>) {
    let mut shared: Vec<usize> = Vec::new();
    let mut gains: Vec<f64> = Vec::new();
    let mut current = held_out_score(cv, &shared);
    let mut rejected: Vec<usize> = Vec::new();
    loop {
        let mut trials: Vec<Trial> = installation
            .iter()
            .copied()
            .filter(|c| !shared.contains(c) && !rejected.contains(c))
            .map(|c| trial(cv, &shared, c, current))
            .collect();
        trials.sort_by(|a, b| b.gain.total_cmp(&a.gain));
        prefer_fewer_parameters(&mut trials, sel.min_gain);
        let mut added = false;
        // The candidate of this round with the most held-out gain that the test does not name.
        let mut pointed: Option<Undetermined> = None;
        for t in trials {
            if !(t.gain.is_finite() && t.gain >= sel.min_gain) {
                break;
            }
            let c = t.candidate;
            let mut set = shared.clone();
            set.push(c);
            let (off, len) = offset_in(&set, c);
            set_aside(cv, c, &t.departing);
            let ests = shared_estimates(cv, &set, &t.fits);
            let joint = combine(&ests.iter().collect::<Vec<_>>(), components(&set));
            let (_, agreement) = agreement_of(&ests, off, len);
            if !significant(&joint, &agreement, &ests, (off, len), sel) {
                if pointed.is_none() && !agreement.disagrees() {
                    pointed = pointed_at(cv, c, &joint, &agreement, (off, len), &t, sel);
                }
                restore(cv, c, &t.departing);
                continue;
            }
            if agreement.disagrees() {
                restore(cv, c, &t.departing);
                let fits = fit_voyages(cv, &set);
                let ests = shared_estimates(cv, &set, &fits);
                let (alone, agreement) = agreement_of(&ests, off, len);
                let (verdict, agreeing) = disagreement(cv, data, c, &alone, &agreement);
                inconsistent.push(SharedEffect {
                    agreeing,
                    ..shared_effect(cv, data, c, &fits, &agreement, t.gain, verdict)
                });
                // Still in the data: each voyage fits its own value, so that it does not
                // bias the effects the voyages do share.
                rejected.push(c);
                own_in_every_voyage(cv, c);
                current = held_out_score(cv, &shared);
                added = true;
                break;
            }
            shared.push(c);
            gains.push(t.gain);
            current = t.score;
            added = true;
            break;
        }
        if !added {
            undetermined.extend(pointed);
            break;
        }
    }
    settle_agreement(cv, data, &mut shared, &mut gains, inconsistent);
    (shared, gains)
}

/// On a channel whose candidates alias each other ([`fit::parsimonious`]), the best trial gives
/// way to one of the same channel with fewer parameters whose gain is within `min_gain` of it,
/// as the one-voyage selection keeps the smallest subset within `min_gain` of the best.
fn prefer_fewer_parameters(trials: &mut [Trial], min_gain: f64) {
    let Some(best) = trials.first() else { return };
    let kind = CANDIDATES[best.candidate].channel;
    if !fit::parsimonious(kind) {
        return;
    }
    let top = best.gain;
    let simplest = (0..trials.len())
        .filter(|&i| {
            CANDIDATES[trials[i].candidate].channel == kind && trials[i].gain >= top - min_gain
        })
        .min_by_key(|&i| (fit::parameters(trials[i].candidate), i));
    if let Some(i) = simplest {
        trials[..=i].rotate_right(1);
    }
}

/// A shared candidate the voyages agree on and that lowers the leave-one-voyage-out score, but
/// whose combined estimate (widened by the voyages' scatter) the test does not name.
#[allow(clippy::too_many_arguments)]
fn pointed_at(
    cv: &[ChannelVoyage],
    c: usize,
    joint: &Combined,
    agreement: &Combined,
    (off, len): (usize, usize),
    t: &Trial,
    sel: &Selection,
) -> Option<Undetermined> {
    // The score without it, with the same voyages set aside.
    let before = t.score / (1.0 - t.gain);
    let name = CANDIDATES[c].name;
    let birge = birge_ratio(agreement);
    let std: Vec<f64> = (0..len).map(|k| joint.std[off + k] * birge).collect();
    if std.iter().all(|s| !s.is_finite()) {
        return None;
    }
    let nominal = cv[0].p.nominal.get(name).unwrap_or_default();
    let value: Vec<f64> = (0..len)
        .map(|k| nominal[k] + joint.delta[off + k])
        .collect();
    let sigmas = (0..len)
        .filter(|&k| std[k].is_finite() && std[k] > 0.0)
        .map(|k| joint.delta[off + k].abs() / std[k])
        .fold(0.0, f64::max);
    let unit = spec(name).map_or("", |s| s.unit);
    let sharing = cv.len() - t.departing.len();
    let scatter = if birge > 1.0 {
        format!(
            "; the voyages' estimates scatter {birge:.2}× more than their deviations say, which \
             widens it"
        )
    } else {
        String::new()
    };
    let note = format!(
        "{name} ({}): {} {unit} over {sharing} voyages, {sigmas:.1}σ from nominal where the test \
         asks {}σ; it lowers the leave-one-voyage-out score {before:.3e} → {:.3e}{scatter}: \
         these voyages point at it without determining it (not named)",
        CANDIDATES[c].channel.name(),
        super::analysis::with_deviation(&value, &std),
        sel.min_sigma,
        t.score,
    );
    Some(Undetermined {
        name: name.into(),
        channel: CANDIDATES[c].channel,
        value: json_of(&value),
        std: json_of(&std),
        nominal: json_of(&nominal),
        unit: unit.into(),
        sigmas,
        widening: birge,
        held_out_before: before,
        held_out_after: t.score,
        note,
    })
}

/// One candidate tried as a shared effect.
struct Trial {
    candidate: usize,
    /// The leave-one-voyage-out mean squared residual with it shared.
    score: f64,
    /// Its relative drop against the shared set without it (with the same voyages set aside).
    gain: f64,
    fits: Vec<VoyageFit>,
    /// The voyages (indices into the channel's voyages) set aside as departing from it.
    departing: Vec<usize>,
}

/// Candidate `c` added to the shared set: shared by every voyage, or, when a few voyages depart
/// from what the others agree on, by the others with those few fitting their own value.
fn trial(cv: &mut [ChannelVoyage], shared: &[usize], c: usize, current: f64) -> Trial {
    let mut set = shared.to_vec();
    set.push(c);
    let (off, len) = offset_in(&set, c);
    let fits = fit_voyages(cv, &set);
    let ests = shared_estimates(cv, &set, &fits);
    let score = held_out(cv, &set, &ests).0;
    let (alone, agreement) = agreement_of(&ests, off, len);
    let all = Trial {
        candidate: c,
        score,
        gain: 1.0 - score / current,
        fits,
        departing: Vec::new(),
    };
    let Some(departing) = agreement
        .disagrees()
        .then(|| departing_from(cv, c, &alone, len))
        .flatten()
    else {
        return all;
    };
    set_aside(cv, c, &departing);
    let before = held_out_score(cv, shared);
    let fits = fit_voyages(cv, &set);
    let score = held_out(cv, &set, &shared_estimates(cv, &set, &fits)).0;
    restore(cv, c, &departing);
    let aside = Trial {
        candidate: c,
        score,
        gain: 1.0 - score / before,
        fits,
        departing,
    };
    // With every voyage sharing it the voyages disagree, so that trial could only end as
    // inconsistent; the departing voyages set aside, the rest agree. The two gains are not
    // comparable: a departing voyage's own value is fitted in the baseline of the second, so a
    // voyage the effect helps most (the one that departs) counts in the first only.
    if aside.gain.is_finite() { aside } else { all }
}

/// Voyages `which` fit effect `c` as their own.
fn set_aside(cv: &mut [ChannelVoyage], c: usize, which: &[usize]) {
    for &k in which {
        if !cv[k].own.contains(&c) {
            cv[k].own.push(c);
        }
    }
}

/// Voyages `which` share effect `c` again.
fn restore(cv: &mut [ChannelVoyage], c: usize, which: &[usize]) {
    for &k in which {
        cv[k].own.retain(|&x| x != c);
    }
}

/// The leave-one-voyage-out mean squared residual of a shared set.
fn held_out_score(cv: &[ChannelVoyage], shared: &[usize]) -> f64 {
    let fits = fit_voyages(cv, shared);
    held_out(cv, shared, &shared_estimates(cv, shared, &fits)).0
}

/// Whether a shared effect (components `off..off + len` of the joint estimate) departs from
/// nominal by the selection's σ. The voyages' own scatter, when larger than their deviations
/// say (the Birge ratio), widens the combined deviation: a slowly varying error gives each
/// voyage an estimate of its own sign that its deviation does not cover.
///
/// Each component's deviation is also taken no smaller than that of the voyages' own deviations
/// of it combined alone. The joint combination adds each voyage's information over all the
/// components, and where a voyage's components are strongly correlated the sum is narrow along
/// directions no voyage determines by itself: it leans on the correlations of the deviations,
/// which a slowly varying error read from a few of its correlation times makes uncertain. On
/// three simulated voyages with a coloured DVL error and nothing hidden in the DVL, a lever arm
/// came out 5.4σ in y jointly while each voyage's own y lay within 1σ of zero (1.6σ combined).
fn significant(
    joint: &Combined,
    agreement: &Combined,
    ests: &[Estimate],
    (off, len): (usize, usize),
    sel: &Selection,
) -> bool {
    let birge = birge_ratio(agreement);
    (0..len).any(|k| {
        let (_, alone) = agreement_of(ests, off + k, 1);
        let s = joint.std[off + k].max(alone.std[0]) * birge;
        s.is_finite() && joint.delta[off + k].abs() >= sel.min_sigma * s
    })
}

/// An effect the voyages disagree on becomes every voyage's own.
fn own_in_every_voyage(cv: &mut [ChannelVoyage], c: usize) {
    let all: Vec<usize> = (0..cv.len()).collect();
    set_aside(cv, c, &all);
}

/// Effects set aside as each voyage's own change the others' estimates: the shared set must
/// still agree at the end. The effect that departs most has its departing voyages set aside when
/// the rest still share it ([`departing_from`]), or else goes to `inconsistent`, until the rest
/// agree.
fn settle_agreement(
    cv: &mut [ChannelVoyage],
    data: &[VoyageData],
    shared: &mut Vec<usize>,
    gains: &mut Vec<f64>,
    inconsistent: &mut Vec<SharedEffect>,
) {
    loop {
        let fits = fit_voyages(cv, shared);
        let ests = shared_estimates(cv, shared, &fits);
        let worst = shared
            .iter()
            .enumerate()
            .map(|(n, &c)| {
                let (off, len) = offset_in(shared, c);
                let (alone, a) = agreement_of(&ests, off, len);
                let ratio = if a.dof > 0 { a.chi2 / a.limit() } else { 0.0 };
                (n, c, ratio, a, alone, len)
            })
            .filter(|x| x.2 > 1.0)
            .max_by(|a, b| a.2.total_cmp(&b.2));
        let Some((n, c, _, agreement, alone, len)) = worst else {
            break;
        };
        if let Some(left) = departing_from(cv, c, &alone, len) {
            set_aside(cv, c, &left);
            continue;
        }
        let (verdict, agreeing) = disagreement(cv, data, c, &alone, &agreement);
        inconsistent.push(SharedEffect {
            agreeing,
            ..shared_effect(
                cv,
                data,
                c,
                &fits,
                &agreement,
                gains[n],
                format!(
                    "{verdict} (once the effects the voyages disagree on are each voyage's own)"
                ),
            )
        });
        shared.remove(n);
        gains.remove(n);
        own_in_every_voyage(cv, c);
    }
}

/// The pairs of `kind`'s effects that no voyage's motion separates.
fn unseparable_pairs(
    cv: &[ChannelVoyage],
    reports: &[DiscoverReport],
    kind: ChannelKind,
) -> Vec<Unseparable> {
    let mut pairs: Option<Vec<Unseparable>> = None;
    for c in cv {
        let mine: Vec<Unseparable> = reports[c.voyage]
            .unseparable
            .iter()
            .filter(|u| {
                u.effects.iter().all(|n| {
                    CANDIDATES
                        .iter()
                        .any(|x| x.channel == kind && x.name == n.as_str())
                })
            })
            .cloned()
            .collect();
        pairs = Some(match pairs {
            None => mine,
            Some(p) => p
                .into_iter()
                .filter(|u| mine.iter().any(|m| same_effects(m, u)))
                .collect(),
        });
    }
    pairs.unwrap_or_default()
}

/// Each channel's noise over the voyages: the RMS of the voyages' values.
fn pooled_noise(reports: &[DiscoverReport]) -> Vec<NoiseEstimate> {
    let mut noise: Vec<(NoiseEstimate, f64, usize)> = Vec::new();
    for r in reports {
        for n in &r.noise {
            match noise
                .iter_mut()
                .find(|(m, _, _)| m.name == n.name && m.channel == n.channel)
            {
                Some((_, sum, count)) => {
                    *sum += n.value * n.value;
                    *count += 1;
                }
                None => noise.push((n.clone(), n.value * n.value, 1)),
            }
        }
    }
    noise
        .into_iter()
        .map(|(mut n, sum, count)| {
            n.value = (sum / count as f64).sqrt();
            n.note = format!("RMS over {count} voyages of: {}", n.note);
            n
        })
        .collect()
}

/// The shared set of `kind` on all voyages: its held-out score against the nominal installation,
/// each voyage's held-out model, the combined values (widened by the voyages' scatter) into the
/// model, the found effects and `v.shared`.
#[allow(clippy::too_many_arguments)]
fn record_shared(
    cv: &[ChannelVoyage],
    data: &[VoyageData],
    nominal: &Effects,
    kind: ChannelKind,
    shared: &[usize],
    gains: &[f64],
    v: &mut Voyages,
    model: &mut Effects,
    effects: &mut Vec<FoundEffect>,
) {
    // The shared set on all voyages, and each voyage's held-out values.
    let fits = fit_voyages(cv, shared);
    let ests = shared_estimates(cv, shared, &fits);
    let joint = combine(&ests.iter().collect::<Vec<_>>(), components(shared));
    let (score, held_thetas) = held_out(cv, shared, &ests);
    // Against the nominal installation with the same per-voyage effects.
    let base = held_out(cv, &[], &shared_estimates(cv, &[], &fit_voyages(cv, &[]))).0;
    v.scores.push(VoyageScore {
        channel: kind,
        voyages: cv.len(),
        mse_nominal: base,
        mse_shared: score,
    });
    let nominal_theta = nominal_theta(nominal, shared);
    let theta_all: Vec<f64> = nominal_theta
        .iter()
        .zip(joint.delta.iter())
        .map(|(a, b)| a + b)
        .collect();
    let at = cv[0].p.effects(shared, &theta_all);
    for (k, c) in cv.iter().enumerate() {
        let e = c.p.effects(shared, &held_thetas[k]);
        set_all(&mut v.held_out_models[c.voyage], &e, shared);
    }
    // Voyages without this channel take the values of all voyages.
    for (i, m) in v.held_out_models.iter_mut().enumerate() {
        if !cv.iter().any(|c| c.voyage == i) {
            set_all(m, &at, shared);
        }
    }
    set_all(model, &at, shared);
    for (n, &c) in shared.iter().enumerate() {
        let (off, len) = offset_in(shared, c);
        let (_, agreement) = agreement_of(&ests, off, len);
        let limit = agreement.limit();
        let name = CANDIDATES[c].name;
        let value = at.get(name).unwrap_or_default();
        let std = &joint.std[off..off + len];
        let mut s = shared_effect(
            cv,
            data,
            c,
            &fits,
            &agreement,
            gains[n],
            format!(
                "shared by {} voyages; they agree (χ² {:.1} ≤ {limit:.1}, {} dof)",
                cv.len() - departing(cv, data, c).len(),
                agreement.chi2,
                agreement.dof
            ),
        );
        if !s.departing.is_empty() {
            let (verb, fits, them) = match s.departing.len() {
                1 => ("departs", "fits", "it"),
                _ => ("depart", "each fit", "them"),
            };
            s.verdict.push_str(&format!(
                "; {} {verb} from it and {fits} its own value (look at {them}: the voyages of one \
                 vehicle share its installation)",
                s.departing.join(", "),
            ));
        }
        let birge = birge_ratio(&agreement);
        let std: Vec<f64> = std.iter().map(|x| x * birge).collect();
        s.value = json_of(&value);
        s.std = json_of(&std);
        if birge > 1.0 {
            s.verdict.push_str(&format!(
                "; deviation widened ×{birge:.2} to the voyages' scatter (Birge ratio)"
            ));
        }
        effects.push(FoundEffect {
            name: name.into(),
            value: s.value.clone(),
            std: s.std.clone(),
            nominal: json_of(&nominal.get(name).unwrap_or_default()),
            unit: spec(name).map_or("", |s| s.unit).into(),
            channel: kind,
            evidence: format!(
                "{}; leave-one-voyage-out mean squared residual {:.1} % lower",
                s.verdict,
                100.0 * gains[n]
            ),
            gain: gains[n],
            equivalent: None,
            line: None,
        });
        v.shared.push(s);
    }
}

/// An effect of `kind` that voyage `i` named when analysed alone.
fn named_alone<'r>(
    reports: &'r [DiscoverReport],
    i: usize,
    kind: ChannelKind,
    name: &str,
) -> Option<&'r FoundEffect> {
    reports[i]
        .effects
        .iter()
        .find(|e| e.channel == kind && e.name == name)
}

/// The installation effects of `kind` some voyages named alone that the voyages together do
/// not confirm (they disagree, or the shared effect has too little held-out gain): into
/// `v.inconsistent` and `v.not_confirmed`, with a note each.
#[allow(clippy::too_many_arguments)]
fn not_confirmed(
    cv: &[ChannelVoyage],
    data: &[VoyageData],
    reports: &[DiscoverReport],
    kind: ChannelKind,
    installation: &[usize],
    shared: &[usize],
    v: &mut Voyages,
    notes: &mut Vec<String>,
) {
    for &c in installation {
        if shared.contains(&c) {
            continue;
        }
        let name = CANDIDATES[c].name;
        let alone_count = cv
            .iter()
            .filter(|x| named_alone(reports, x.voyage, kind, name).is_some())
            .count();
        let mut agreeing = None;
        if alone_count > 0 && !v.inconsistent.iter().any(|s| s.name == name) {
            let mut set = shared.to_vec();
            set.push(c);
            let fits = fit_voyages(cv, &set);
            let (off, len) = offset_in(&set, c);
            let (alone, agreement) = agreement_of(&shared_estimates(cv, &set, &fits), off, len);
            if agreement.disagrees() {
                // A few voyages that depart do not make the rest disagree (as in the
                // selection): what the rest agree on is reported, the effect not confirmed.
                agreeing = departing_from(cv, c, &alone, len)
                    .and_then(|left| agreed_without(cv, data, c, &alone, &left));
                if agreeing.is_none() {
                    let (verdict, agreeing) = disagreement(cv, data, c, &alone, &agreement);
                    v.inconsistent.push(SharedEffect {
                        agreeing,
                        ..shared_effect(cv, data, c, &fits, &agreement, 0.0, verdict)
                    });
                }
            }
        }
        let by: Vec<VoyageEstimate> = cv
            .iter()
            .filter_map(|x| {
                named_alone(reports, x.voyage, kind, name).map(|e| VoyageEstimate {
                    log: data[x.voyage].log.clone(),
                    value: e.value.clone(),
                    std: e.std.clone(),
                })
            })
            .collect();
        if !by.is_empty() {
            let inconsistent = v.inconsistent.iter().any(|s| s.name == name);
            let why = match &agreeing {
                _ if inconsistent => "they disagree".to_string(),
                Some(a) => {
                    let (v, e) = (values_of(&a.value), values_of(&a.std));
                    let pm: Vec<String> = v
                        .unwrap_or_default()
                        .iter()
                        .zip(e.unwrap_or_default())
                        .map(|(v, e)| {
                            // Two significant digits of the deviation.
                            let d = (1.0 - e.log10().floor()).clamp(0.0, 12.0) as usize;
                            format!("{v:.d$} ± {e:.d$}")
                        })
                        .collect();
                    format!(
                        "without {} the other {} agree on [{}], but shared by them it is not \
                         significant or has too little held-out gain",
                        a.left_out.join(", "),
                        a.voyages,
                        pm.join(", ")
                    )
                }
                None => "not significant or no held-out gain across voyages".to_string(),
            };
            notes.push(format!(
                "{name} ({}): named by {} of {} voyages alone, not by the voyages together \
                 ({why})",
                kind.name(),
                by.len(),
                cv.len(),
            ));
            v.not_confirmed.push(NamedAlone {
                agreeing,
                name: name.into(),
                channel: kind,
                unit: spec(name).map_or("", |s| s.unit).into(),
                voyages: by,
            });
        }
    }
}

/// The verdict on voyages that disagree: which voyages depart most, and what the others agree
/// on when at most half of the voyages are set aside (for the engineer to look at those voyages;
/// never a finding by itself).
fn disagreement(
    cv: &[ChannelVoyage],
    data: &[VoyageData],
    c: usize,
    alone: &[Estimate],
    all: &Combined,
) -> (String, Option<Agreeing>) {
    let name = CANDIDATES[c].name;
    let len = spec(name).map_or(1, |s| s.components);
    let nominal = cv[0].p.nominal.get(name).unwrap_or_default();
    let mut text = format!(
        "the voyages disagree beyond their uncertainties (χ² {:.1}, {} dof): not a finding (an \
         effect of each voyage, or of the reference, rather than of the installation)",
        all.chi2, all.dof
    );
    if name == "dvl.scale_factor" {
        text.push_str(
            "; a velocity scale that changes between voyages is what a change of the water's \
             sound speed does (dvl.sound_speed is each voyage's own): measure it on each voyage",
        );
    }
    // At least half of all the voyages must agree; those already set aside as departing
    // (their estimates carry no information here) count as left out.
    let informative = alone.iter().filter(|e| e.rank > 0).count();
    let most = informative.saturating_sub(cv.len().div_ceil(2).max(2));
    if let Some((new, agree)) = agreeing_without(alone, len, most).filter(|(l, _)| !l.is_empty()) {
        let mut left: Vec<usize> = (0..cv.len()).filter(|&k| cv[k].own.contains(&c)).collect();
        left.extend(new);
        let value: Vec<String> = agree
            .delta
            .iter()
            .zip(&agree.std)
            .map(|(d, s)| format!("{d:+.4} ± {s:.4}"))
            .collect();
        let left_out: Vec<String> = left
            .iter()
            .map(|&k| data[cv[k].voyage].log.clone())
            .collect();
        text.push_str(&format!(
            "; without {} the other {} voyages agree on a change of [{}] from nominal",
            left_out.join(", "),
            cv.len() - left.len(),
            value.join(", ")
        ));
        let v: Vec<f64> = nominal
            .iter()
            .zip(agree.delta.iter())
            .map(|(a, b)| a + b)
            .collect();
        let agreeing = Agreeing {
            left_out,
            voyages: cv.len() - left.len(),
            value: json_of(&v),
            std: json_of(&agree.std),
        };
        return (text, Some(agreeing));
    }
    (text, None)
}

/// The voyages to set aside, at most `most` of them, for the rest to agree: the one that departs
/// most from the others' mean in turn. The set aside (indices into `alone`; the voyages without
/// information on the effect are neither counted nor set aside) and what the rest agree on.
fn agreeing_without(alone: &[Estimate], len: usize, most: usize) -> Option<(Vec<usize>, Combined)> {
    let mut kept: Vec<usize> = (0..alone.len()).filter(|&k| alone[k].rank > 0).collect();
    let mut left = Vec::new();
    loop {
        let c = combine(&kept.iter().map(|&k| &alone[k]).collect::<Vec<_>>(), len);
        if !c.disagrees() {
            return Some((left, c));
        }
        if left.len() >= most {
            return None;
        }
        let part = |k: usize| {
            let d = &alone[k].delta - &c.delta;
            (d.transpose() * &alone[k].info * &d)[(0, 0)]
        };
        let worst = kept
            .iter()
            .copied()
            .max_by(|&a, &b| part(a).total_cmp(&part(b)))?;
        kept.retain(|&k| k != worst);
        left.push(worst);
    }
}

/// The voyages of `cv` to set aside as departing from effect `c` so that the others share it:
/// at most a quarter of the voyages in all (counting those already set aside), with at least
/// three left that agree. A vehicle's installation is one; a voyage that departs from what the
/// others agree on (a reference of its own, a bad stretch) is for the engineer to look at, and
/// should neither stop the others from sharing the effect nor pull their value.
fn departing_from(
    cv: &[ChannelVoyage],
    c: usize,
    alone: &[Estimate],
    len: usize,
) -> Option<Vec<usize>> {
    let already = cv.iter().filter(|x| x.own.contains(&c)).count();
    let most = (cv.len() / 4).saturating_sub(already);
    let informative = alone.iter().filter(|e| e.rank > 0).count();
    let (left, _) = agreeing_without(alone, len, most)?;
    (!left.is_empty() && informative - left.len() >= 3).then_some(left)
}

/// What the voyages of `cv` other than `left` (those departing from effect `c`) agree on.
fn agreed_without(
    cv: &[ChannelVoyage],
    data: &[VoyageData],
    c: usize,
    alone: &[Estimate],
    left: &[usize],
) -> Option<Agreeing> {
    let len = alone.first()?.delta.len();
    let kept: Vec<&Estimate> = (0..alone.len())
        .filter(|k| alone[*k].rank > 0 && !left.contains(k))
        .map(|k| &alone[k])
        .collect();
    let agree = combine(&kept, len);
    let nominal = cv[0].p.nominal.get(CANDIDATES[c].name).unwrap_or_default();
    let value: Vec<f64> = nominal
        .iter()
        .zip(agree.delta.iter())
        .map(|(a, b)| a + b)
        .collect();
    // Voyages already fitting their own value of it count as left out too.
    let out = (0..cv.len()).filter(|k| left.contains(k) || cv[*k].own.contains(&c));
    Some(Agreeing {
        left_out: out.map(|k| data[cv[k].voyage].log.clone()).collect(),
        voyages: kept.len(),
        value: json_of(&value),
        std: json_of(&agree.std),
    })
}

/// sqrt(χ² / dof) of the voyages' agreement, at least 1.
fn birge_ratio(a: &Combined) -> f64 {
    if a.dof == 0 {
        1.0
    } else {
        (a.chi2 / a.dof as f64).sqrt().max(1.0)
    }
}

fn same_effects(a: &Unseparable, b: &Unseparable) -> bool {
    let (mut x, mut y) = (a.effects.clone(), b.effects.clone());
    x.sort();
    y.sort();
    x == y
}

fn nominal_theta(nominal: &Effects, set: &[usize]) -> Vec<f64> {
    set.iter()
        .flat_map(|&c| nominal.get(CANDIDATES[c].name).unwrap_or_default())
        .collect()
}

/// Copies the set's effects from `from` into `to`.
fn set_all(to: &mut Effects, from: &Effects, set: &[usize]) {
    for &c in set {
        let name = CANDIDATES[c].name;
        if let Some(v) = from.get(name) {
            // In range: `Problem::effects` clamps to the effect's range.
            let _ = to.set(name, &v);
        }
    }
}

fn shared_effect(
    cv: &[ChannelVoyage],
    data: &[VoyageData],
    c: usize,
    fits: &[VoyageFit],
    agreement: &Combined,
    gain: f64,
    verdict: String,
) -> SharedEffect {
    let name = CANDIDATES[c].name;
    let nominal = cv[0].p.nominal.get(name).unwrap_or_default();
    let value: Vec<f64> = nominal
        .iter()
        .zip(agreement.delta.iter())
        .map(|(a, b)| a + b)
        .collect();
    SharedEffect {
        name: name.into(),
        channel: CANDIDATES[c].channel,
        unit: spec(name).map_or("", |s| s.unit).into(),
        value: json_of(&value),
        std: json_of(&agreement.std),
        nominal: json_of(&nominal),
        voyages: cv
            .iter()
            .zip(fits)
            .map(|(x, (set, f))| {
                let (off, len) = offset_in(set, c);
                VoyageEstimate {
                    log: data[x.voyage].log.clone(),
                    value: json_of(&f.theta[off..off + len]),
                    std: json_of(&f.std[off..off + len]),
                }
            })
            .collect(),
        chi2: agreement.chi2,
        dof: agreement.dof,
        chi2_limit: agreement.limit(),
        held_out_gain: gain,
        verdict,
        agreeing: None,
        departing: departing(cv, data, c),
    }
}

/// The voyages set aside as departing from shared effect `c` (each fits its own value).
fn departing(cv: &[ChannelVoyage], data: &[VoyageData], c: usize) -> Vec<String> {
    cv.iter()
        .filter(|x| x.own.contains(&c))
        .map(|x| data[x.voyage].log.clone())
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use auvnav_sim::rng::Rng;

    /// Three voyages whose estimates agree (drawn around one value with unit deviations) and
    /// whose deviations are themselves estimated with 5 degrees of freedom (a χ²₅ / 5 draw of
    /// each variance, as a slowly varying error read over a few correlation times gives): the χ²
    /// limit for known deviations calls them disagreeing several times more often than its 1 %;
    /// Welch's limit near its 1 %. Four thousand draws.
    #[test]
    fn estimated_deviations_disagree_at_the_tests_rate() {
        let nu = 5usize;
        let mut rng = Rng::new(1, "welch-agreement");
        let (mut welch, mut known, draws) = (0usize, 0usize, 4000usize);
        for _ in 0..draws {
            let ests: Vec<Estimate> = (0..3)
                .map(|_| {
                    let x = rng.gauss(1.0);
                    let var = (0..nu).map(|_| rng.gauss(1.0).powi(2)).sum::<f64>() / nu as f64;
                    let cov = DMatrix::from_element(1, 1, var);
                    Estimate::new(&[x], &[0.0], &cov, nu as f64)
                })
                .collect();
            let c = combine(&ests.iter().collect::<Vec<_>>(), 1);
            welch += usize::from(c.disagrees());
            let chi2_limit = auvnav_studies::nees::chi2_quantile(c.dof as f64, AGREEMENT_Z);
            known += usize::from(c.chi2 > chi2_limit);
        }
        let (welch, known) = (welch as f64 / draws as f64, known as f64 / draws as f64);
        assert!(known > 0.03, "χ² limit with estimated deviations: {known}");
        assert!((0.003..0.02).contains(&welch), "Welch's limit: {welch}");
    }
}
