//! The GNSS evidence's place in the report: what the GNSS positions of surface runs decide of
//! the DVL installation (the types; [`crate::gnss`] fills them).

use auvnav_calibrate::surface::{FittedParam, HeldOut, ScoreSet};
use serde::Serialize;

/// What the GNSS positions of surface runs say of the DVL installation.
#[derive(Debug, Clone, Serialize)]
pub struct GnssEvidence {
    /// The folds (logs, or a log's halves as `LOG@START..END`).
    pub folds: Vec<String>,
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
