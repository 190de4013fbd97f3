//! The surface calibration's report: its types, its text, its verdict and the
//! `[navigation.dvl]` table it writes.

use super::{Candidate, FittedParam, SurfaceScore};
use auvnav_core::config::DvlInstallation;
use serde::Serialize;

/// The surface calibration's report.
#[derive(Debug, Clone, Serialize)]
pub struct SurfaceReport {
    pub runs: Vec<String>,
    pub threshold_m: f64,
    /// Whether each run's bed velocity was fitted as a nuisance (`--moving-bed`).
    pub moving_bed: bool,
    pub params: Vec<FittedParam>,
    /// The installation and deviation card written (the starting ones with the written
    /// parameters).
    pub installation: Candidate,
    /// On all runs (in-sample): the starting installation, the two-point one and the fitted one.
    pub in_sample: ScoreSet,
    /// Leave-one-run-out, when there are at least two runs: each run scored with what the others
    /// give.
    pub held_out: Vec<HeldOut>,
    pub verdict: String,
    /// Each magnetic compass's declination not applied ([`super::compass`]).
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub compass: Vec<super::compass::CompassDeclination>,
    /// What the report adds about the runs (the compasses' declinations).
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub notes: Vec<String>,
}

#[derive(Debug, Clone, Serialize)]
pub struct ScoreSet {
    pub nominal: SurfaceScore,
    pub two_point: SurfaceScore,
    pub calibrated: SurfaceScore,
}

#[derive(Debug, Clone, Serialize)]
pub struct HeldOut {
    pub run: String,
    pub scores: ScoreSet,
    /// Parameters the fit on the other runs wrote.
    pub written: Vec<String>,
}

pub(super) fn verdict(
    params: &[FittedParam],
    in_sample: &ScoreSet,
    held_out: &[HeldOut],
) -> String {
    let written: Vec<&str> = params
        .iter()
        .filter(|p| p.written)
        .map(|p| p.name.as_str())
        .collect();
    let mut s = if written.is_empty() {
        "These runs write nothing: no parameter stands five deviations from its starting value."
            .to_string()
    } else {
        format!(
            "Written: {}; in-sample error/distance (median) {:.3} % nominal, {:.3} % two-point, {:.3} % calibrated.",
            written.join(", "),
            in_sample.nominal.median_error_per_distance_percent,
            in_sample.two_point.median_error_per_distance_percent,
            in_sample.calibrated.median_error_per_distance_percent
        )
    };
    if !held_out.is_empty() {
        let writing: Vec<&HeldOut> = held_out.iter().filter(|h| !h.written.is_empty()).collect();
        let better = writing
            .iter()
            .filter(|h| h.scores.calibrated.rms_error_m < h.scores.nominal.rms_error_m)
            .count();
        s.push_str(&format!(
            " Held out (each run scored with what the others write): {better} of {} runs where something is written navigate better than nominal.",
            writing.len()
        ));
    }
    s
}

/// The report as text.
pub fn text(r: &SurfaceReport) -> String {
    use std::fmt::Write;
    let mut s = String::new();
    let _ = writeln!(
        s,
        "auvnav calibrate dvl (surface runs: compass + DVL dead reckoning against GNSS, windows of {} m{}): {}",
        r.threshold_m,
        if r.moving_bed {
            ", each run's bed velocity fitted"
        } else {
            ""
        },
        r.runs.join(", ")
    );
    for p in &r.params {
        let _ = writeln!(
            s,
            "  {} = {:.4} ± {:.4} {} (start {:.4}): {}",
            p.name, p.estimate, p.std, p.unit, p.start, p.verdict
        );
    }
    let line = |label: &str, x: &SurfaceScore| {
        format!(
            "{label}: {} windows, rms {:.2} m, error/distance median {:.3} %, mean {:.3} %",
            x.windows,
            x.rms_error_m,
            x.median_error_per_distance_percent,
            x.mean_error_per_distance_percent
        )
    };
    let _ = writeln!(s, "  in sample:");
    let _ = writeln!(s, "    {}", line("nominal", &r.in_sample.nominal));
    let _ = writeln!(s, "    {}", line("two-point", &r.in_sample.two_point));
    let _ = writeln!(s, "    {}", line("calibrated", &r.in_sample.calibrated));
    for h in &r.held_out {
        let _ = writeln!(
            s,
            "  held out {} (written by the others: {:?}):",
            h.run, h.written
        );
        let _ = writeln!(s, "    {}", line("nominal", &h.scores.nominal));
        let _ = writeln!(s, "    {}", line("two-point", &h.scores.two_point));
        let _ = writeln!(s, "    {}", line("calibrated", &h.scores.calibrated));
    }
    for n in &r.notes {
        let _ = writeln!(s, "  note: {n}");
    }
    let _ = writeln!(s, "{}", r.verdict);
    s
}

/// The `[navigation]` `compass_deviation_deg` and `[navigation.dvl]` table of what is written.
pub fn config_toml(r: &SurfaceReport) -> anyhow::Result<String> {
    #[derive(Serialize)]
    struct Navigation {
        compass_deviation_deg: [f64; 5],
        dvl: DvlInstallation,
    }
    #[derive(Serialize)]
    struct File {
        navigation: Navigation,
    }
    let mut dvl = r.installation.dvl.clone();
    dvl.source = format!("auvnav calibrate dvl, surface runs {}", r.runs.join(", "));
    let body = toml::to_string(&File {
        navigation: Navigation {
            compass_deviation_deg: r.installation.compass_deviation_deg,
            dvl,
        },
    })?;
    let written: Vec<&str> = r
        .params
        .iter()
        .filter(|p| p.written)
        .map(|p| p.name.as_str())
        .collect();
    Ok(format!(
        "# DVL installation from `auvnav calibrate dvl` on surface runs (written: {}; error/distance median {:.3} % -> {:.3} %).\n{body}",
        if written.is_empty() {
            "nothing".to_string()
        } else {
            written.join(", ")
        },
        r.in_sample.nominal.median_error_per_distance_percent,
        r.in_sample.calibrated.median_error_per_distance_percent
    ))
}

/// Writes [`config_toml`] to `path` atomically.
pub fn write_config(path: &std::path::Path, r: &SurfaceReport) -> anyhow::Result<()> {
    Ok(auvnav_replay::write_atomically(path, &config_toml(r)?)?)
}
