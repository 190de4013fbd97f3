//! An installation chosen elsewhere, scored on one surface run as the calibration scores its own.

use super::{Candidate, SurfaceScore, score, windows};
use crate::voyage::VoyageSpec;
use crate::{CalibrationError, error::unusable};
use auvnav_replay::surface::read_surface_run;

/// The window errors of `inst` on the run `spec` (S-CAL's windows of `threshold_m` along its
/// GNSS track; with `moving_bed` the run's bed velocity profiled out), as [`super::calibrate_surface`]
/// scores each held-out run: what `auvnav discover --write-config` writes from other runs is
/// judged on this one against the same nominal and two-point figures.
pub fn score_installation(
    spec: &VoyageSpec,
    inst: &Candidate,
    threshold_m: f64,
    moving_bed: bool,
) -> Result<SurfaceScore, CalibrationError> {
    let run = read_surface_run(&spec.path, &spec.name(), spec.window_s)?;
    let w = windows(&run, threshold_m);
    if w.is_empty() {
        unusable!(
            "surface run {}: no two fixes {threshold_m} m apart along the track",
            run.name
        );
    }
    Ok(score(&[(&run, w)], inst, moving_bed))
}
