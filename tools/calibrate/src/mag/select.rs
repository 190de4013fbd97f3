//! The model and method chosen on held-out readings (`--method auto`, the default).
//!
//! The fit part of the recording is cut into contiguous blocks; every candidate (no calibration,
//! the sphere fit, the rotation constraint when the readings carry the gyro, the ellipsoid, the
//! weighted two-constraint fit with one scale, a diagonal or a full symmetric soft iron) is fitted on all blocks but one and scored on the block left out,
//! each block in turn. A block is long against the time the readings' errors stay correlated (a
//! tenth or more of the recording), so a candidate that fits what the environment did at one time
//! gains nothing on another block. The scores are the held-out field-norm spread (standard
//! deviation over mean: free of each fit's scale) and the gravity–field angle's spread.
//!
//! The rule: the sphere fit is the baseline. A candidate can replace it only when it scores at or
//! below the sphere on both spreads; among those, the one with the smallest product of the two
//! ratios to the sphere wins (ties go to the simpler). Whatever is chosen must not raise the
//! held-out dip spread above the raw readings'; if every fit does, the readings are left
//! uncalibrated and the report says why. The spread of each parameter over the blocks (the
//! delete-one-block jackknife) is how well the recording determines it.

use super::fit::{self, Calibration, FitError, LmFit, MagSample, Model};
use super::weights::NoiseModel;
use super::{ReferenceField, weighted_lm};
use nalgebra::Matrix3;
use serde::Serialize;

/// Blocks of the blocked cross-validation.
pub const BLOCKS: usize = 5;
/// Fewest readings per block for the selection to run.
pub const MIN_BLOCK: usize = 20;

/// A calibration candidate.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum Candidate {
    /// The readings as they are.
    Raw,
    /// Hard iron and one scale by the linear sphere fit.
    Sphere,
    /// The 10-coefficient ellipsoid.
    Ellipsoid,
    /// The weighted two-constraint Levenberg–Marquardt fit in one model.
    Lm(Model),
    /// Hard iron from the rotation constraint (gyro), one scale from the field's magnitude.
    Gyro,
}

impl Candidate {
    /// Every candidate, simplest first (ties go to the earlier); the gyro's only when the
    /// readings carry angular rates.
    pub fn all(samples: &[MagSample]) -> Vec<Candidate> {
        let mut v = vec![
            Candidate::Raw,
            Candidate::Sphere,
            Candidate::Lm(Model::HardIron),
            Candidate::Lm(Model::Diagonal),
            Candidate::Lm(Model::Full),
            Candidate::Ellipsoid,
        ];
        if super::gyro::has_rates(samples) {
            v.insert(2, Candidate::Gyro);
        }
        v
    }

    pub fn name(self) -> String {
        match self {
            Candidate::Raw => "no calibration".into(),
            Candidate::Sphere => "sphere fit (hard iron, one scale)".into(),
            Candidate::Ellipsoid => "ellipsoid (10 coefficients)".into(),
            Candidate::Lm(m) => format!("weighted norm + dip, {}", m.name()),
            Candidate::Gyro => "rotation constraint (gyro): hard iron, one scale".into(),
        }
    }

    /// The model a candidate's calibration is in.
    pub fn model(self) -> Model {
        match self {
            Candidate::Raw => Model::None,
            Candidate::Sphere | Candidate::Gyro => Model::HardIron,
            Candidate::Ellipsoid => Model::Full,
            Candidate::Lm(m) => m,
        }
    }
}

/// A candidate fitted: the calibration, the Levenberg–Marquardt fit and noise model behind it.
#[derive(Debug, Clone)]
pub struct Fitted {
    pub calibration: Calibration,
    pub lm: Option<LmFit>,
    pub noise: Option<NoiseModel>,
}

/// Fits one candidate on `samples` (scaled to the reference field's intensity).
pub fn fit_candidate(
    c: Candidate,
    samples: &[MagSample],
    reference: &ReferenceField,
) -> Result<Fitted, FitError> {
    let r = reference.intensity_ut;
    let plain = |calibration| Fitted {
        calibration,
        lm: None,
        noise: None,
    };
    let sphere = || -> Result<Calibration, FitError> {
        let (centre, radius) = fit::sphere(samples)?;
        Ok(Calibration {
            k: Matrix3::identity() * (r / radius),
            hard_iron_ut: centre,
            lambda: None,
        })
    };
    match c {
        Candidate::Raw => Ok(plain(Calibration::identity())),
        Candidate::Sphere => Ok(plain(sphere()?)),
        Candidate::Ellipsoid => Ok(plain(fit::ellipsoid(samples, r)?)),
        Candidate::Gyro => Ok(plain(super::gyro::hard_iron(samples, r)?)),
        Candidate::Lm(model) => {
            let start = match model {
                Model::Full => fit::ellipsoid(samples, r).or_else(|_| sphere())?,
                _ => sphere()?,
            };
            let horizontal = reference
                .inclination_deg
                .map_or(r, |i| r * i.to_radians().cos());
            let (f, noise) = weighted_lm(samples, r, horizontal, model, &start)?;
            Ok(Fitted {
                calibration: f.calibration,
                lm: Some(f),
                noise,
            })
        }
    }
}

/// Held-out spreads of one calibration on `samples`: the field norm's standard deviation over its
/// mean, and the gravity–field angle's standard deviation (deg).
pub fn held_out(samples: &[MagSample], c: &Calibration) -> (f64, Option<f64>) {
    let s = super::spreads(samples, c, 1.0);
    let mean = s.norm_mean_ut.max(1e-12);
    (s.norm_std_fraction / mean, s.dip_std_deg)
}

/// One candidate's blocked cross-validation.
#[derive(Debug, Clone, Serialize)]
pub struct CandidateScore {
    pub candidate: Candidate,
    pub name: String,
    /// Mean over the held-out blocks of the field norm's spread (fraction of its mean).
    pub norm_spread: Option<f64>,
    /// Mean over the held-out blocks of the dip's standard deviation (deg).
    pub dip_std_deg: Option<f64>,
    /// Why the candidate could not be fitted on some block's complement.
    pub failed: Option<String>,
}

/// How well the recording determines each parameter of the chosen candidate: the
/// delete-one-block jackknife standard deviation.
#[derive(Debug, Clone, Serialize)]
pub struct ParameterSpread {
    /// Hard iron x, y, z (µT).
    pub hard_iron_ut: [f64; 3],
    /// Soft iron S = K⁻¹ row-major (1); S is scaled to unit determinant first (the field's scale
    /// is the reference's, not a parameter).
    pub soft_iron: [f64; 9],
}

/// The selection.
#[derive(Debug, Clone, Serialize)]
pub struct Selection {
    pub blocks: usize,
    pub block_samples: usize,
    pub scores: Vec<CandidateScore>,
    pub chosen: Candidate,
    pub reason: String,
    pub parameter_spread: Option<ParameterSpread>,
}

fn mean(v: &[f64]) -> f64 {
    v.iter().sum::<f64>() / v.len().max(1) as f64
}

/// The jackknife standard deviation of values from delete-one-block fits.
fn jackknife(v: &[f64]) -> f64 {
    let k = v.len() as f64;
    if v.len() < 2 {
        return f64::NAN;
    }
    let m = mean(v);
    ((k - 1.0) / k * v.iter().map(|x| (x - m).powi(2)).sum::<f64>()).sqrt()
}

/// Soft iron normalised to unit determinant (row-major), or NaN when singular.
fn unit_soft_iron(c: &Calibration) -> [f64; 9] {
    match c.soft_iron() {
        Some(s) if s.determinant().abs() > 1e-300 => {
            let s = s / s.determinant().abs().cbrt();
            std::array::from_fn(|i| s[(i / 3, i % 3)])
        }
        _ => [f64::NAN; 9],
    }
}

/// One candidate fitted on every block's complement and scored on the block: its score and the
/// fold calibrations.
fn cross_validate(
    c: Candidate,
    samples: &[MagSample],
    reference: &ReferenceField,
    bounds: &[(usize, usize)],
) -> (CandidateScore, Vec<Calibration>) {
    let (mut norms, mut dips, mut fits) = (Vec::new(), Vec::new(), Vec::new());
    let mut failed = None;
    for &(lo, hi) in bounds {
        let train: Vec<MagSample> = samples[..lo]
            .iter()
            .chain(&samples[hi..])
            .copied()
            .collect();
        match fit_candidate(c, &train, reference) {
            Ok(f) => {
                let (ns, ds) = held_out(&samples[lo..hi], &f.calibration);
                norms.push(ns);
                if let Some(d) = ds {
                    dips.push(d);
                }
                fits.push(f.calibration);
            }
            Err(e) => {
                failed = Some(format!("block {lo}..{hi}: {e}"));
                break;
            }
        }
    }
    let ok = failed.is_none() && norms.iter().all(|v| v.is_finite());
    let score = CandidateScore {
        candidate: c,
        name: c.name(),
        norm_spread: ok.then(|| mean(&norms)),
        dip_std_deg: (ok && dips.len() == bounds.len()).then(|| mean(&dips)),
        failed: failed.or_else(|| (!ok).then(|| "a held-out spread is not finite".into())),
    };
    (score, fits)
}

/// Runs the blocked cross-validation of every candidate on `samples` and chooses; None when the
/// samples are too few for `BLOCKS` blocks of `MIN_BLOCK`.
// Long on purpose: the folds, the scores and the decision rule with its reasons are one
// procedure whose steps share the per-fold fits.
pub fn select(samples: &[MagSample], reference: &ReferenceField) -> Option<Selection> {
    let n = samples.len();
    if n < BLOCKS * MIN_BLOCK {
        return None;
    }
    let bounds: Vec<(usize, usize)> = (0..BLOCKS)
        .map(|b| (b * n / BLOCKS, (b + 1) * n / BLOCKS))
        .collect();
    // Every candidate on every fold, in parallel; the results in the candidates' order.
    use rayon::prelude::*;
    let candidates = Candidate::all(samples);
    let scored: Vec<(CandidateScore, Vec<Calibration>)> = candidates
        .par_iter()
        .map(|&c| cross_validate(c, samples, reference, &bounds))
        .collect();
    let (scores, fold_fits): (Vec<CandidateScore>, Vec<Vec<Calibration>>) =
        scored.into_iter().unzip();
    let score_of = |c: Candidate| scores.iter().find(|s| s.candidate == c);
    let raw = score_of(Candidate::Raw)?;
    let base = score_of(Candidate::Sphere)
        .filter(|s| s.norm_spread.is_some())
        .unwrap_or(raw);
    let (bn, bd) = (base.norm_spread?, base.dip_std_deg);
    let ratio = |s: &CandidateScore| -> Option<f64> {
        let n = s.norm_spread?;
        if n > bn {
            return None;
        }
        let mut r = (n / bn.max(1e-300)).ln();
        if let Some(bd) = bd {
            let d = s.dip_std_deg?;
            if d > bd {
                return None;
            }
            r += (d / bd.max(1e-300)).ln();
        }
        Some(r)
    };
    let mut chosen = base;
    let mut best = 0.0;
    for s in &scores {
        if let Some(r) = ratio(s)
            && r < best
        {
            best = r;
            chosen = s;
        }
    }
    let mut reason = if chosen.candidate == base.candidate {
        format!(
            "{}: no candidate scored below it on both held-out spreads ({} blocks)",
            base.name, BLOCKS
        )
    } else {
        format!(
            "{}: held-out norm spread {:.3} % and dip spread {} against the {}'s {:.3} % and {}",
            chosen.name,
            chosen.norm_spread.unwrap_or(f64::NAN) * 100.0,
            deg(chosen.dip_std_deg),
            base.name,
            bn * 100.0,
            deg(bd)
        )
    };
    // The dip guard: no calibration may spread the gravity–field angle more than the raw
    // readings do.
    if let (Some(rd), Some(cd)) = (raw.dip_std_deg, chosen.dip_std_deg)
        && cd > rd
    {
        let fallback = scores
            .iter()
            .filter(|s| s.norm_spread.is_some() && s.dip_std_deg.is_some_and(|d| d <= rd))
            .min_by(|a, b| {
                let (x, y) = (
                    a.norm_spread.unwrap_or(f64::INFINITY),
                    b.norm_spread.unwrap_or(f64::INFINITY),
                );
                x.total_cmp(&y)
            });
        let was = chosen.name.clone();
        chosen = fallback.unwrap_or(raw);
        reason = format!(
            "{}: the {} raises the held-out dip spread above the raw readings' ({} > {})",
            chosen.name,
            was,
            deg(Some(cd)),
            deg(Some(rd))
        );
    }
    let k = candidates
        .iter()
        .position(|c| *c == chosen.candidate)
        .unwrap_or(0);
    let fits = &fold_fits[k];
    let parameter_spread =
        (chosen.candidate != Candidate::Raw && fits.len() == BLOCKS).then(|| {
            let soft: Vec<[f64; 9]> = fits.iter().map(unit_soft_iron).collect();
            ParameterSpread {
                hard_iron_ut: std::array::from_fn(|i| {
                    jackknife(&fits.iter().map(|f| f.hard_iron_ut[i]).collect::<Vec<_>>())
                }),
                soft_iron: std::array::from_fn(|i| {
                    jackknife(&soft.iter().map(|s| s[i]).collect::<Vec<_>>())
                }),
            }
        });
    Some(Selection {
        blocks: BLOCKS,
        block_samples: n / BLOCKS,
        chosen: chosen.candidate,
        reason,
        scores: scores.clone(),
        parameter_spread,
    })
}

fn deg(v: Option<f64>) -> String {
    v.map_or("-".into(), |d| format!("{d:.3}°"))
}

/// Verdicts on the parameters the recording does not determine: an element whose jackknife
/// spread exceeds its limit.
pub fn undetermined_parameters(
    p: &ParameterSpread,
    model: Model,
    hard_limit_ut: f64,
    soft_limit: f64,
) -> Vec<String> {
    let mut v = Vec::new();
    for (i, axis) in ["x", "y", "z"].iter().enumerate() {
        if p.hard_iron_ut[i] > hard_limit_ut {
            v.push(format!(
                "too little attitude coverage for the {axis} hard iron: it moves by ±{:.2} µT \
                 between blocks of the recording (limit {:.2} µT); turn the vehicle through more \
                 attitudes to determine it",
                p.hard_iron_ut[i], hard_limit_ut
            ));
        }
    }
    if matches!(model, Model::Full | Model::Diagonal) {
        let worst = (0..9usize)
            .filter(|&i| model == Model::Full || i.is_multiple_of(4))
            .map(|i| (i, p.soft_iron[i]))
            .max_by(|a, b| a.1.total_cmp(&b.1));
        if let Some((i, s)) = worst
            && s > soft_limit
        {
            v.push(format!(
                "too little attitude coverage for the soft iron: S{}{} moves by ±{s:.4} between \
                 blocks (limit {soft_limit})",
                i / 3 + 1,
                i % 3 + 1
            ));
        }
    }
    v
}
