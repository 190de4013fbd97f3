//! The GNSS evidence's place in the report: what the GNSS positions of surface runs decide of
//! the DVL installation (the types; [`crate::gnss`] fills them).

use auvnav_calibrate::surface::{FittedParam, HeldOut, ScoreSet, SurfaceScore};
use auvnav_calibrate::voyage::VoyageSpec;
use serde::Serialize;

/// What the GNSS positions of surface runs say of the DVL installation.
#[derive(Debug, Clone, Serialize)]
pub struct GnssEvidence {
    /// The folds (logs, or a log's halves as `LOG@START..END`).
    pub folds: Vec<String>,
    /// The same folds as the position fit read them (for the held-out check of what is written).
    #[serde(skip)]
    pub fold_specs: Vec<VoyageSpec>,
    /// The windows' distance along the GNSS track (m).
    pub threshold_m: f64,
    /// Whether each fold's bed velocity was fitted as a nuisance (`--moving-bed`).
    pub moving_bed: bool,
    /// The position fit on all folds, per parameter.
    pub params: Vec<FittedParam>,
    /// Window errors on all folds: nominal, S-CAL's two-point installation, the fitted one.
    pub in_sample: ScoreSet,
    /// Each fold scored with what the other folds write.
    pub held_out: Vec<HeldOut>,
    /// The decision per parameter of the vocabulary.
    pub decisions: Vec<GnssDecision>,
    /// Each fold scored with what `--write-config` writes from the other folds alone (the whole
    /// of discovery run on them), beside `held_out`'s nominal and two-point figures.
    pub written_held_out: Vec<WrittenHeldOut>,
}

/// One fold navigated with the navigator configuration `auvnav discover --write-config` writes
/// from the other folds.
#[derive(Debug, Clone, Serialize)]
pub struct WrittenHeldOut {
    /// The fold scored (`LOG` or `LOG@START..END`).
    pub fold: String,
    /// The effects written (installation and compass effects; empty when nothing is).
    pub written: Vec<HeldOutEffect>,
    /// The fold's window errors with it (`None` when the other folds could not be discovered
    /// on: `error` says why).
    pub score: Option<SurfaceScore>,
    pub error: Option<String>,
}

/// The decision on one installation parameter.
#[derive(Debug, Clone, Serialize)]
pub struct GnssDecision {
    /// The parameter's name in the position fit (`dvl.lever_arm.x`, `heading.deviation.b`…).
    pub parameter: String,
    /// The effect of the vocabulary it belongs to.
    pub effect: String,
    /// `named`, `not determined`, `consistent with nominal`, `not excited`, or `disagrees`.
    pub verdict: String,
    pub note: String,
}

/// An effect the other folds write, and the held-out fold without it.
#[derive(Debug, Clone, Serialize)]
pub struct HeldOutEffect {
    pub name: String,
    pub value: serde_json::Value,
    /// The fold's window RMS (m) with the rest of what is written and this effect at its nominal
    /// value: above the fold's score with everything, the effect helps the fold.
    pub rms_without_m: Option<f64>,
}
