//! The `auvnav calibrate mag` command: inputs, reference field, fit on one part of the
//! recording and evaluation on the rest, verdict.

use super::fit::{self, Calibration, MagSample, Model, SwarmSettings};
use super::input::{self, CsvColumnOptions, Recording};
use super::{Coverage, MagMethod, ReferenceField, Spreads, Thresholds};
use crate::CalibrationError;
use crate::error::{unusable, usage};
use serde::Serialize;
use std::path::PathBuf;

/// Model choice of the `lm` method.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "clap", derive(clap::ValueEnum))]
pub enum ModelChoice {
    /// The richest model the attitude coverage determines.
    Auto,
    Full,
    Diagonal,
    HardIron,
    Plane,
}

#[derive(Debug, Clone)]
#[cfg_attr(feature = "clap", derive(clap::Args))]
pub struct CalibrateMagOptions {
    /// Recordings: auvnav logs (.mcap; the magnetometer topic, the IMU for gravity) or CSV files.
    #[cfg_attr(feature = "clap", arg(required = true))]
    pub inputs: Vec<PathBuf>,
    #[cfg_attr(feature = "clap", arg(long, value_enum, default_value_t = MagMethod::Auto))]
    pub method: MagMethod,
    /// Model of the lm method (with the auto method, a model other than auto means lm in it).
    #[cfg_attr(feature = "clap", arg(long, value_enum, default_value_t = ModelChoice::Auto))]
    pub model: ModelChoice,
    /// Fraction of each recording (from its start) used for the fit; the rest evaluates it.
    #[cfg_attr(feature = "clap", arg(long, default_value_t = 0.5))]
    pub fit_fraction: f64,
    /// Local field intensity (µT), instead of the field model.
    #[cfg_attr(feature = "clap", arg(long))]
    pub field_ut: Option<f64>,
    /// Local inclination (deg, positive down), instead of the field model.
    #[cfg_attr(feature = "clap", arg(long))]
    pub dip_deg: Option<f64>,
    /// Position for the field model (deg), when the recording does not carry one.
    #[cfg_attr(feature = "clap", arg(long, allow_hyphen_values = true))]
    pub latitude: Option<f64>,
    #[cfg_attr(feature = "clap", arg(long, allow_hyphen_values = true))]
    pub longitude: Option<f64>,
    /// Date for the field model (decimal year, e.g. 2026.9), when the recording has none.
    #[cfg_attr(feature = "clap", arg(long))]
    pub date: Option<f64>,
    /// Seed of the particle swarm (seed method).
    #[cfg_attr(feature = "clap", arg(long, default_value_t = 1))]
    pub seed: u64,
    /// Swarm iterations (seed method; 100 particles).
    #[cfg_attr(feature = "clap", arg(long, default_value_t = 150))]
    pub iterations: usize,
    #[cfg_attr(feature = "clap", command(flatten))]
    pub columns: CsvColumnOptions,
    /// Print the report as JSON.
    #[cfg_attr(feature = "clap", arg(long))]
    pub json: bool,
    /// Write the `[navigation.magnetometer]` table (atomically) to this file.
    #[cfg_attr(feature = "clap", arg(long))]
    pub write_config: Option<PathBuf>,
    /// Write report.md, report.json, calibration.toml and SVG plots into this directory.
    #[cfg_attr(feature = "clap", arg(long))]
    pub report: Option<PathBuf>,
}

impl CalibrateMagOptions {
    /// The defaults, on `inputs`.
    pub fn new(inputs: Vec<PathBuf>) -> Self {
        CalibrateMagOptions {
            inputs,
            method: MagMethod::Auto,
            model: ModelChoice::Auto,
            fit_fraction: 0.5,
            field_ut: None,
            dip_deg: None,
            latitude: None,
            longitude: None,
            date: None,
            seed: 1,
            iterations: 150,
            columns: CsvColumnOptions::default(),
            json: false,
            write_config: None,
            report: None,
        }
    }
}

/// One effect in the simulator's vocabulary.
#[derive(Debug, Clone, Serialize)]
pub struct EffectValue {
    pub name: &'static str,
    pub value: Vec<f64>,
    /// One-sigma per element (null where not determined or not estimated by the method).
    pub std: Vec<Option<f64>>,
    pub unit: &'static str,
}

/// Before/after on the fit and evaluation parts.
#[derive(Debug, Clone, Serialize)]
pub struct SpreadTable {
    pub fit_before: Spreads,
    pub fit_after: Spreads,
    pub evaluation_before: Option<Spreads>,
    pub evaluation_after: Option<Spreads>,
}

/// Heading error against a reference attitude (simulated truth), deg RMS.
#[derive(Debug, Clone, Serialize)]
pub struct HeadingCheck {
    pub before_rms_deg: f64,
    pub after_rms_deg: f64,
    pub samples: usize,
}

/// The report (`--json` and `report.json`; `format_version` in docs/json.md).
#[derive(Debug, Clone, Serialize)]
pub struct MagReport {
    pub inputs: Vec<String>,
    pub unit: String,
    pub samples_fit: usize,
    pub samples_evaluation: usize,
    pub samples_skipped: usize,
    pub with_specific_force: bool,
    pub reference: ReferenceField,
    pub method: MagMethod,
    pub model: Model,
    pub reasons: Vec<String>,
    pub effects: Vec<EffectValue>,
    /// Fitted dip from λ (deg), when estimated.
    pub fitted_dip_deg: Option<f64>,
    pub condition_number: Option<f64>,
    pub residual_rms: Option<f64>,
    pub swarm_evaluations: Option<usize>,
    /// The constraint weights' estimated noise model (weighted fits).
    pub noise_model: Option<super::weights::NoiseModel>,
    /// Every candidate scored on held-out blocks of the fit part (auto method).
    pub selection: Option<super::select::Selection>,
    pub coverage_raw: Coverage,
    pub coverage_calibrated: Coverage,
    pub spreads: SpreadTable,
    pub heading: Option<HeadingCheck>,
    pub thresholds: Thresholds,
    pub wall_s: f64,
    /// "calibrated", "constrained", "disturbed" or "undetermined".
    pub status: &'static str,
    pub verdict: Vec<String>,
    #[serde(skip)]
    pub calibration: Calibration,
    /// Every sample read (fit part first), for the plots.
    #[serde(skip)]
    pub samples: Vec<MagSample>,
}

fn reference_field(
    a: &CalibrateMagOptions,
    rec: &Recording,
    radius_ut: f64,
) -> Result<ReferenceField, CalibrationError> {
    let lat = a.latitude.or(rec.whereabouts.latitude_deg);
    let lon = a.longitude.or(rec.whereabouts.longitude_deg);
    let date = a.date.or(rec.whereabouts.date);
    let model = match (lat, lon, date) {
        (Some(lat), Some(lon), Some(date)) if a.field_ut.is_none() || a.dip_deg.is_none() => {
            use auvnav_core::wmm::WorldMagneticModel;
            let m =
                WorldMagneticModel::builtin_for(date).unwrap_or_else(WorldMagneticModel::builtin);
            match m.field(lat, lon, 0.0, date) {
                Ok(f) => Some(f),
                Err(e) => unusable!("field model at {lat:.4}°, {lon:.4}° on {date:.3}: {e}"),
            }
        }
        _ => None,
    };
    Ok(match (a.field_ut, model) {
        (Some(f), m) => ReferenceField {
            intensity_ut: f,
            inclination_deg: a.dip_deg.or(m.map(|m| m.inclination_deg())),
            declination_deg: m.map(|m| m.declination_deg()),
            source: "--field-ut",
        },
        (None, Some(m)) => ReferenceField {
            intensity_ut: m.intensity_nt() * 1e-3,
            inclination_deg: a.dip_deg.or(Some(m.inclination_deg())),
            declination_deg: Some(m.declination_deg()),
            source: "WMM-2025 at the recording's position and date",
        },
        (None, None) => ReferenceField {
            intensity_ut: radius_ut,
            inclination_deg: a.dip_deg,
            declination_deg: None,
            source: "the readings' sphere fit (no position and date for the field model, no \
                     --field-ut): the scale is the data's, the field magnitude cannot be checked",
        },
    })
}

pub fn heading_check(samples: &[MagSample], c: &Calibration) -> Option<HeadingCheck> {
    let mut before = 0.0;
    let mut after = 0.0;
    let mut n = 0usize;
    // The declination is the same for both: measure the heading relative to the mean offset.
    let mut offs_b = Vec::new();
    let mut offs_a = Vec::new();
    for s in samples {
        let t = s.truth_rpy?;
        let hb = fit::magnetic_heading(&s.field_ut, t.x, t.y);
        let ha = fit::magnetic_heading(&c.apply(&s.field_ut), t.x, t.y);
        offs_b.push(auvnav_replay::accuracy::wrap(hb - t.z));
        offs_a.push(auvnav_replay::accuracy::wrap(ha - t.z));
        n += 1;
    }
    if n == 0 {
        return None;
    }
    let circ_mean = |v: &[f64]| {
        let (s, c) = v
            .iter()
            .fold((0.0, 0.0), |(s, c), a| (s + a.sin(), c + a.cos()));
        s.atan2(c)
    };
    let (mb, ma) = (circ_mean(&offs_b), circ_mean(&offs_a));
    for (b, a) in offs_b.iter().zip(&offs_a) {
        before += auvnav_replay::accuracy::wrap(b - mb).powi(2);
        after += auvnav_replay::accuracy::wrap(a - ma).powi(2);
    }
    Some(HeadingCheck {
        before_rms_deg: (before / n as f64).sqrt().to_degrees(),
        after_rms_deg: (after / n as f64).sqrt().to_degrees(),
        samples: n,
    })
}

/// The effects of a calibration: `mag.hard_iron` (µT) and `mag.soft_iron` (S = K⁻¹), with the
/// block-to-block spread as the standard deviation when the selection measured one (it holds
/// what coloured residuals do to the estimate), else the fit's own.
fn effects(
    c: &Calibration,
    lm: Option<&fit::LmFit>,
    model: Model,
    spread: Option<&super::select::ParameterSpread>,
) -> Vec<EffectValue> {
    if let Some(p) = spread {
        let s = c.soft_iron().unwrap_or_else(nalgebra::Matrix3::identity);
        let fixed = |i: usize| match model {
            Model::Full => false,
            Model::Diagonal => !i.is_multiple_of(4),
            _ => true,
        };
        return vec![
            EffectValue {
                name: "mag.hard_iron",
                value: c.hard_iron_ut.iter().copied().collect(),
                std: p.hard_iron_ut.iter().map(|v| Some(*v)).collect(),
                unit: "uT",
            },
            EffectValue {
                name: "mag.soft_iron",
                value: s.transpose().iter().copied().collect(),
                std: (0..9)
                    .map(|i| (!fixed(i)).then_some(p.soft_iron[i]))
                    .collect(),
                unit: "1",
            },
        ];
    }
    let s = c.soft_iron().unwrap_or_else(nalgebra::Matrix3::identity);
    let names = lm.map(|f| fit::parameter_names(f.model));
    let std_of = |name: &str| -> Option<f64> {
        let (f, names) = (lm?, names?);
        let i = names.iter().position(|n| *n == name)?;
        f.std.get(i).copied().filter(|v| v.is_finite())
    };
    let b_std: Vec<Option<f64>> = ["bx", "by", "bz"].iter().map(|n| std_of(n)).collect();
    // First order: δS = −S δK S, and S ≈ I, so the std of S_ij is about that of K_ij.
    let k_name = |i: usize, j: usize| -> &'static str {
        match (i.min(j), i.max(j)) {
            (0, 0) => "k11",
            (1, 1) => "k22",
            (2, 2) => "k33",
            (0, 1) => "k12",
            (0, 2) => "k13",
            _ => "k23",
        }
    };
    let mut s_std = Vec::with_capacity(9);
    for i in 0..3 {
        for j in 0..3 {
            let v = if model == Model::HardIron && i == j {
                std_of("scale")
            } else {
                std_of(k_name(i, j))
            };
            s_std.push(v.map(|v| v * s[(i, i)] * s[(j, j)]));
        }
    }
    vec![
        EffectValue {
            name: "mag.hard_iron",
            value: c.hard_iron_ut.iter().copied().collect(),
            std: b_std,
            unit: "uT",
        },
        EffectValue {
            name: "mag.soft_iron",
            value: s.transpose().iter().copied().collect(),
            std: s_std,
            unit: "1",
        },
    ]
}

/// Runs the calibration (no file written).
// Long on purpose: reads the recordings, splits fit and held-out samples, runs the method and every
// comparison the report shows; the steps share the sample sets.
pub fn calibrate_mag(a: &CalibrateMagOptions) -> Result<MagReport, CalibrationError> {
    if !(a.fit_fraction > 0.0 && a.fit_fraction <= 1.0) {
        usage!("--fit-fraction {}: expected 0 < f <= 1", a.fit_fraction);
    }
    let cols = a.columns.columns()?;
    let mut fit_set = Vec::new();
    let mut eval_set = Vec::new();
    let mut first: Option<Recording> = None;
    let mut skipped = 0;
    let mut units = Vec::new();
    for p in &a.inputs {
        let is_csv = p.extension().is_some_and(|e| e.eq_ignore_ascii_case("csv"));
        let rec = if is_csv {
            input::read_csv(p, &cols)?
        } else {
            input::read_log(p)?
        };
        skipped += rec.skipped;
        units.push(rec.unit_note.clone());
        let k = ((rec.samples.len() as f64) * a.fit_fraction).round() as usize;
        fit_set.extend_from_slice(&rec.samples[..k]);
        eval_set.extend_from_slice(&rec.samples[k..]);
        if first.is_none() {
            first = Some(rec);
        }
    }
    let Some(first) = first else {
        usage!("no input recording")
    };
    if fit_set.len() < 20 {
        unusable!(
            "too few samples to fit: {} (at least 20; the fit uses --fit-fraction {} of each \
             recording)",
            fit_set.len(),
            a.fit_fraction
        );
    }
    let started = std::time::Instant::now();
    let (_, radius) = fit::sphere(&fit_set).map_err(CalibrationError::method)?;
    let reference = reference_field(a, &first, radius)?;
    let limits = Thresholds::default();
    let forced = match a.model {
        ModelChoice::Auto => None,
        ModelChoice::Full => Some(Model::Full),
        ModelChoice::Diagonal => Some(Model::Diagonal),
        ModelChoice::HardIron => Some(Model::HardIron),
        ModelChoice::Plane => Some(Model::Plane),
    };
    let outcome = super::run_method(
        a.method,
        &fit_set,
        &reference,
        &limits,
        SwarmSettings {
            particles: 100,
            iterations: a.iterations,
            seed: a.seed,
        },
        forced,
    )
    .map_err(CalibrationError::method)?;
    let wall = started.elapsed().as_secs_f64();
    let c = outcome.calibration;
    let id = Calibration::identity();
    let r = reference.intensity_ut;
    let spreads = SpreadTable {
        fit_before: super::spreads(&fit_set, &id, radius),
        fit_after: super::spreads(&fit_set, &c, r),
        evaluation_before: (!eval_set.is_empty()).then(|| super::spreads(&eval_set, &id, radius)),
        evaluation_after: (!eval_set.is_empty()).then(|| super::spreads(&eval_set, &c, r)),
    };
    let with_force = fit_set.iter().any(|s| s.specific_force.is_some());
    let all: Vec<MagSample> = fit_set.iter().chain(&eval_set).copied().collect();
    let heading = heading_check(&eval_set, &c).or_else(|| heading_check(&fit_set, &c));
    let lm = outcome.lm.as_ref();
    let fitted_dip = c.lambda.map(|l| (-l).clamp(-1.0, 1.0).asin().to_degrees());
    let mut verdict = Vec::new();
    let mut status = match outcome.model {
        Model::Full => "calibrated",
        Model::None => "undetermined",
        _ => "constrained",
    };
    if outcome.model == Model::None {
        verdict.push(
            "no calibration: no fit scored better on held-out blocks of the recording than the \
             readings as they are (see the selection table); nothing is written"
                .into(),
        );
    }
    let spread = outcome
        .selection
        .as_ref()
        .and_then(|s| s.parameter_spread.as_ref());
    let undetermined = spread
        .map(|p| {
            super::select::undetermined_parameters(
                p,
                outcome.model,
                limits.hard_iron_std_fraction * reference.intensity_ut,
                limits.soft_iron_std,
            )
        })
        .unwrap_or_default();
    if outcome
        .reasons
        .iter()
        .any(|r| r.contains("kept as the last resort"))
    {
        status = "undetermined";
        verdict.push(
            "even the most constrained model is not determined by these readings: more attitude \
             change (turns, some roll and pitch) is needed"
                .into(),
        );
    }
    let check = spreads.evaluation_after.unwrap_or(spreads.fit_after);
    if reference.source.starts_with("WMM") || reference.source == "--field-ut" {
        let ratio = radius / r;
        let k_scale = c.k.determinant().abs().cbrt();
        if (k_scale - 1.0).abs() > limits.model_difference {
            status = "disturbed";
            verdict.push(format!(
                "disturbed: the readings' field magnitude (about {:.1} µT) is {:.0} % from the \
                 reference {:.1} µT ({}): a local anomaly, a disturbing mass, or a wrong unit",
                radius,
                (ratio - 1.0) * 100.0,
                r,
                reference.source
            ));
        }
    }
    if check.norm_std_fraction > limits.norm_spread {
        status = "disturbed";
        verdict.push(format!(
            "disturbed: after calibration the field norm still varies by {:.1} % (limit {:.0} %) \
             on the {} samples: the environment changes during the recording (or the errors are \
             not the model's)",
            check.norm_std_fraction * 100.0,
            limits.norm_spread * 100.0,
            if spreads.evaluation_after.is_some() {
                "held-out"
            } else {
                "fitted"
            }
        ));
    }
    if let Some(d) = check.dip_std_deg
        && d > limits.dip_spread_deg
    {
        status = "disturbed";
        verdict.push(format!(
            "disturbed: the dip varies by {d:.2}° (limit {}°) after calibration",
            limits.dip_spread_deg
        ));
    }
    if let (Some(fd), Some(md)) = (fitted_dip, reference.inclination_deg)
        && (fd - md).abs() > 5.0
        && with_force
    {
        verdict.push(format!(
            "the fitted dip {fd:.1}° differs from the reference {md:.1}° by more than 5°"
        ));
    }
    if !with_force {
        verdict.push(
            "no accelerometer channel: only the magnitude constraint was used (the gravity–field \
             angle needs the specific force)"
                .into(),
        );
    }
    let cov_raw = super::coverage(&all, &id);
    let cov_cal = super::coverage(&all, &c);
    if cov_cal.sphere_fraction < limits.coverage && outcome.model == Model::Full {
        verdict.push(format!(
            "sphere coverage {:.0} % (of 26 directions) is below {:.0} %: the full soft iron rests \
             on the gravity–field constraint",
            cov_cal.sphere_fraction * 100.0,
            limits.coverage * 100.0
        ));
    }
    verdict.extend(undetermined);
    if status == "calibrated" || status == "constrained" {
        verdict.insert(
            0,
            format!(
                "{}: {}; field-norm spread {:.2} % → {:.2} % on the {} samples",
                status,
                outcome.model.name(),
                spreads
                    .evaluation_before
                    .unwrap_or(spreads.fit_before)
                    .norm_std_fraction
                    * 100.0,
                check.norm_std_fraction * 100.0,
                if spreads.evaluation_after.is_some() {
                    "held-out"
                } else {
                    "fitted"
                }
            ),
        );
    }
    Ok(MagReport {
        inputs: a.inputs.iter().map(|p| p.display().to_string()).collect(),
        unit: units.join("; "),
        samples_fit: fit_set.len(),
        samples_evaluation: eval_set.len(),
        samples_skipped: skipped,
        with_specific_force: with_force,
        reference,
        method: a.method,
        model: outcome.model,
        reasons: outcome.reasons.clone(),
        effects: effects(&c, lm, outcome.model, spread),
        fitted_dip_deg: fitted_dip,
        condition_number: lm.map(|f| f.condition),
        residual_rms: lm.map(|f| f.residual_rms),
        swarm_evaluations: outcome.evaluations,
        noise_model: outcome.noise,
        selection: outcome.selection.clone(),
        coverage_raw: cov_raw,
        coverage_calibrated: cov_cal,
        spreads,
        heading,
        thresholds: limits,
        wall_s: wall,
        status,
        verdict,
        calibration: c,
        samples: all,
    })
}
