//! `auvnav discover LOG… [--reference truth] [--effect NAME=VALUE…] [--json]`.

pub use super::analysis::*;
use super::fit::Selection;
use super::{Channel, ChannelKind, Reference};
use crate::{DiscoverError, Source};
use auvnav_replay::write_atomically;
use auvnav_sim::effects::{Effects, parse_setting};
use std::path::PathBuf;

#[derive(Debug, Clone)]
#[cfg_attr(feature = "clap", derive(clap::Args))]
pub struct DiscoverOptions {
    /// Logs (MCAP, as written by `auvnav sim` or the recorder) with the sensor channels and the
    /// reference motion.
    #[cfg_attr(feature = "clap", arg(required = true))]
    pub logs: Vec<PathBuf>,
    /// The reference motion: `truth` (the log's truth topic: simulated truth or an imported
    /// reference solution) or `smoothed` (each log smoothed with `auvnav smooth`, the DVL
    /// installation as filter states: the vehicle's own motion, so that an effect describes the
    /// sensor against the IMU; the IMU channels are then not compared, and a log's own reference
    /// is compared with the smoothed motion to say what separates them; where a depth sensor's
    /// lever arm is found, the logs are smoothed again with the depth fused there, until the
    /// lever arm found is the one smoothed at).
    #[cfg_attr(feature = "clap", arg(long, default_value = "truth", value_parser = ["truth", "smoothed"]))]
    pub reference: String,
    /// The nominal model's effects, NAME=VALUE (repeatable; default: every effect off, the
    /// simulator's defaults).
    #[cfg_attr(feature = "clap", arg(long = "effect", value_name = "NAME=VALUE", value_parser = auvnav_studies::args::effect_setting))]
    pub effects: Vec<String>,
    /// Start from the effects a previous `auvnav discover --json` report found (what the data
    /// already contain), or from an effect set file (`.toml`, e.g. `--write-effects`), so that
    /// this run reports what changed on top of them; `--effect` settings apply after it.
    #[cfg_attr(feature = "clap", arg(long, value_name = "REPORT.json|EFFECTS.toml"))]
    pub nominal_from: Option<PathBuf>,
    /// Fraction of each channel (in time order) the held-out gain is fitted on; the rest scores it.
    #[cfg_attr(feature = "clap", arg(long, default_value_t = 0.7))]
    pub fit_fraction: f64,
    /// Print the report as JSON.
    #[cfg_attr(feature = "clap", arg(long))]
    pub json: bool,
    /// Write a report directory: report.md with plots (SVG), report.json, effects.toml and
    /// navigation.toml.
    #[cfg_attr(feature = "clap", arg(long, value_name = "DIR"))]
    pub report: Option<PathBuf>,
    /// Write the extended model as an effect set (`auvnav sim --effects-from FILE`): the nominal
    /// effects, the effects found and each channel's residual noise.
    #[cfg_attr(feature = "clap", arg(long, value_name = "FILE"))]
    pub write_effects: Option<PathBuf>,
    /// Write the navigator configuration of the effects found (`[navigation.dvl]`,
    /// `[navigation.magnetometer]`, the depth sensor's lever arm), less those with which the
    /// replayed navigation of some log gets worse, each named in a comment (with
    /// `--no-navigation` nothing is replayed and every effect found is written).
    #[cfg_attr(feature = "clap", arg(long, value_name = "FILE"))]
    pub write_config: Option<PathBuf>,
    /// Do not replay the logs through the navigator to compare the navigation error before and
    /// after.
    #[cfg_attr(feature = "clap", arg(long))]
    pub no_navigation: bool,
    /// Compare the DVL's four beam velocities with the reference instead of its velocity (the
    /// `dvl_beams` channel; readings that carry all four beams): finds each beam's own scale and
    /// angle error (`dvl.beam_scale_factor`, `dvl.beam_angle_error`) besides the installation.
    #[cfg_attr(feature = "clap", arg(long))]
    pub dvl_beams: bool,
    /// The logs are pieces of one voyage (one recording split into files): read them as one
    /// series against one reference. By default each log is a voyage of its own: its own
    /// reference, time base and held-out blocks, with the installation effects shared by the
    /// voyages and tested for agreement (a few voyages that depart from what the rest agree on
    /// are named and fit their own value).
    #[cfg_attr(feature = "clap", arg(long))]
    pub one_voyage: bool,
    /// The DVL's bottom track may see a moving bed (a river, soft sediment that the current
    /// carries): add `dvl.bed_velocity` (the bed's north and east velocity, fitted per voyage)
    /// to the candidates; on surface runs the GNSS evidence fits each fold's bed velocity as a
    /// nuisance too.
    #[cfg_attr(feature = "clap", arg(long))]
    pub moving_bed: bool,
    /// Surface runs (a compass, a DVL and GNSS throughout, no IMU): the distance along the GNSS
    /// track over which the dead reckoning is compared with the GNSS positions, the evidence that
    /// decides the DVL installation there (default: a quarter of the shortest fold's track,
    /// 20 m to 5000 m).
    #[cfg_attr(feature = "clap", arg(long, value_name = "METRES"))]
    pub gnss_threshold: Option<f64>,
    /// Effects never selected (not a command-line option): the refit of what `--write-config`
    /// keeps once effects are withheld ([`crate::gnss_written::refit`]).
    #[cfg_attr(feature = "clap", arg(skip))]
    pub never_select: Vec<String>,
}

impl DiscoverOptions {
    /// `auvnav discover LOG…` with the command line's defaults: against the logs' truth, from
    /// the simulator's nominal model, nothing written, the navigation replayed.
    pub fn new(logs: Vec<PathBuf>) -> DiscoverOptions {
        DiscoverOptions {
            logs,
            reference: "truth".into(),
            effects: Vec::new(),
            nominal_from: None,
            fit_fraction: 0.7,
            json: false,
            report: None,
            write_effects: None,
            write_config: None,
            no_navigation: false,
            dvl_beams: false,
            one_voyage: false,
            moving_bed: false,
            gnss_threshold: None,
            never_select: Vec::new(),
        }
    }
}

/// Sets the effects a discover JSON report found, or those of an effect set file (`.toml`).
pub fn nominal_from_report(
    nominal: &mut Effects,
    path: &std::path::Path,
) -> Result<(), DiscoverError> {
    let bad = |e: Source| DiscoverError::Nominal {
        path: path.to_path_buf(),
        source: e,
    };
    let text = std::fs::read_to_string(path).map_err(|e| bad(e.into()))?;
    if path.extension().is_some_and(|x| x == "toml") {
        let settings = auvnav_sim::effects::set::parse(&text).map_err(|e| bad(e.into()))?;
        return auvnav_sim::effects::set::apply(nominal, &settings).map_err(|e| bad(e.into()));
    }
    let v: serde_json::Value = serde_json::from_str(&text)
        .map_err(|e| bad(format!("not a discover JSON report: {e}").into()))?;
    let Some(effects) = v.get("effects").and_then(|e| e.as_array()) else {
        return Err(bad("no `effects` list (not a discover report)".into()));
    };
    for e in effects {
        let name = e.get("name").and_then(|n| n.as_str()).unwrap_or_default();
        let Some(values) = e.get("value").and_then(values_of) else {
            return Err(bad(format!("effect {name:?} has no numeric value").into()));
        };
        nominal
            .set(name, &values)
            .map_err(|e| bad(format!("effect {name:?}: {e}").into()))?;
    }
    Ok(())
}

/// What `auvnav discover` finds and decides, before the surface runs' held-out check of what it
/// writes ([`super::gnss_written`]) and before anything is written.
pub fn findings(a: &DiscoverOptions) -> Result<DiscoverReport, DiscoverError> {
    let smoothed = a.reference == "smoothed";
    if smoothed && a.one_voyage && a.logs.len() > 1 {
        return Err(DiscoverError::Options(
            "--reference smoothed smooths each log on its own: give the pieces of one voyage as \
             one log, or leave out --one-voyage"
                .into(),
        ));
    }
    if !(a.fit_fraction > 0.0 && a.fit_fraction < 1.0) {
        return Err(DiscoverError::Options(format!(
            "--fit-fraction {}: expected 0 < f < 1",
            a.fit_fraction
        )));
    }
    if let Some(t) = a.gnss_threshold
        && !(t.is_finite() && t > 0.0)
    {
        return Err(DiscoverError::Options(format!(
            "--gnss-threshold {t}: expected a distance in metres > 0"
        )));
    }
    let mut nominal = Effects::default();
    if let Some(p) = &a.nominal_from {
        nominal_from_report(&mut nominal, p)?;
    }
    for s in &a.effects {
        let (name, values) = parse_setting(s)?;
        nominal.set(&name, &values)?;
    }
    // With --reference smoothed, each log is smoothed with the depth sensor fused at its
    // nominal lever arm; where discovery finds another, the logs are smoothed again with it and
    // discovered again: a depth sensor far from the IMU on a pitching vehicle otherwise has its
    // readings refused by the smoother's gate, and the smoothed depth drifts (Snapir segment 9,
    // pitching up to 20° with the depth taken 1.7 m ahead: up to 5.9 m). The smoothed motion
    // moves with the lever arm it is given, so the passes go on until the lever arm found is the
    // one smoothed at (within SETTLED_M) or MAX_PASSES have run.
    let (mut r, undecodable, mut against) = analyse(a, &nominal, nominal.depth_lever_arm)?;
    let mut smoothed_at = nominal.depth_lever_arm;
    let mut passes = 1;
    while smoothed
        && passes < MAX_PASSES
        && r.model.depth_lever_arm != nominal.depth_lever_arm
        && !settled(r.model.depth_lever_arm, smoothed_at)
    {
        let (lever, earlier_wall) = (r.model.depth_lever_arm, r.wall_s);
        (r, _, against) = analyse(a, &nominal, lever)?;
        r.wall_s += earlier_wall;
        smoothed_at = lever;
        passes += 1;
    }
    let smoothed_again = (passes > 1).then_some(smoothed_at);
    if undecodable > 0 {
        r.notes.push(format!(
            "{undecodable} messages in the logs did not decode and were left out"
        ));
    }
    r.inputs = a.logs.iter().map(|p| p.display().to_string()).collect();
    r.reference = a.reference.clone();
    if !smoothed && super::gnss::all_surface_runs(&a.logs) == Some(true) {
        super::gnss::decide(&a.logs, a.gnss_threshold, a.moving_bed, &mut r);
    }
    if smoothed {
        r.notes.push(
            "reference: each log's smoothed motion (IMU, DVL with its installation as filter \
             states, depth, fixes): the effects describe the sensors against the IMU; the IMU \
             channels are not compared with their own motion"
                .into(),
        );
        if let Some(l) = smoothed_again {
            let found = r.model.depth_lever_arm;
            let settled_note = if found == nominal.depth_lever_arm {
                "the last pass names no depth lever arm".to_string()
            } else if settled(found, l) {
                format!("the lever arm found is the one smoothed at (within {SETTLED_M} m)")
            } else {
                format!(
                    "the lever arm found, ({:.3}, {:.3}, {:.3}) m, still differs from it by more \
                     than {SETTLED_M} m after {passes} passes",
                    found[0], found[1], found[2]
                )
            };
            r.notes.push(format!(
                "each log smoothed again with the depth sensor's lever arm the previous pass \
                 found, {passes} passes in all, the last at ({:.3}, {:.3}, {:.3}) m: these are \
                 the last pass's findings; {settled_note}",
                l[0], l[1], l[2]
            ));
        }
        for x in &against {
            r.notes.push(super::smoothed::describe(x));
        }
        r.reference_against_imu = against;
    }
    if !smoothed {
        super::outputs::reference_caveats(&a.logs, &mut r);
    }
    if !a.no_navigation {
        let start = std::time::Instant::now();
        super::navigation::navigation_gain(&a.logs, &mut r);
        r.wall_s += start.elapsed().as_secs_f64();
    }
    Ok(r)
}

/// `auvnav discover`.
pub fn run(a: &DiscoverOptions) -> Result<DiscoverReport, DiscoverError> {
    let mut r = findings(a)?;
    if r.gnss.is_some() {
        let start = std::time::Instant::now();
        // Discovery as this run makes it, on other logs or with effects never selected, writing
        // nothing.
        let inner = |logs, never_select| {
            findings(&DiscoverOptions {
                logs,
                report: None,
                write_effects: None,
                write_config: None,
                never_select,
                ..a.clone()
            })
        };
        let discover = |logs| Ok(inner(logs, a.never_select.clone())?);
        super::gnss_written::held_out(&mut r, &discover);
        let without = |never_select| Ok(inner(a.logs.clone(), never_select)?);
        super::gnss_written::refit(&mut r, &without);
        r.wall_s += start.elapsed().as_secs_f64();
    }
    super::outputs::compass_declinations(&a.logs, &mut r);
    if let Some(p) = &a.write_effects {
        write_atomically(p, &super::outputs::effect_set_toml(&r))?;
    }
    if let Some(p) = &a.write_config {
        let text =
            super::outputs::navigator_toml(&r).map_err(|e| auvnav_replay::ReplayError::Output {
                path: p.clone(),
                source: e.into(),
            })?;
        write_atomically(p, &text)?;
    }
    if let Some(dir) = &a.report {
        super::report::write_report_dir(dir, &r).map_err(|e| {
            auvnav_replay::ReplayError::Output {
                path: dir.clone(),
                source: e.into(),
            }
        })?;
    }
    Ok(r)
}

/// Smoothing passes at most, the first at the nominal depth lever arm.
const MAX_PASSES: usize = 4;

/// A depth lever arm that moves less than this (m, per component) from the one smoothed at is
/// settled: at the 20° a pitching vehicle reaches it moves the depth by under 7 mm, below the
/// depth residual against a smoothed motion (12–27 mm on Snapir).
const SETTLED_M: f64 = 0.02;

fn settled(found: [f64; 3], smoothed_at: [f64; 3]) -> bool {
    found
        .iter()
        .zip(&smoothed_at)
        .all(|(f, s)| (f - s).abs() <= SETTLED_M)
}

/// Reads the logs and discovers: the logs as voyages, or as one; with `--reference smoothed`,
/// each log against its smoothed motion (the depth sensor fused at `depth_lever_arm_m`). Returns
/// the report, the messages that did not decode, and each log's reference against the IMU.
fn analyse(
    a: &DiscoverOptions,
    nominal: &Effects,
    depth_lever_arm_m: [f64; 3],
) -> Result<
    (
        DiscoverReport,
        usize,
        Vec<super::smoothed::ReferenceAgainstImu>,
    ),
    DiscoverError,
> {
    let smoothed = a.reference == "smoothed";
    let voyages = a.logs.len() > 1 && !a.one_voyage;
    let mut against = Vec::new();
    let mut smoothed_logs = 0;
    // One log's channels against its reference (the smoothed motion with --reference smoothed).
    let mut read_one = |log: &PathBuf| -> Result<(Vec<Channel>, Reference, usize), DiscoverError> {
        let (mut channels, reference, u) = read_logs_with(
            std::slice::from_ref(log),
            Collector::new()
                .with_dvl_beams(a.dvl_beams)
                .with_moving_bed(a.moving_bed),
        )?;
        if !smoothed {
            return Ok((channels, reference, u));
        }
        smoothed_logs += 1;
        let work = std::env::temp_dir().join(format!(
            "auvnav-discover-smooth-{}-{smoothed_logs}",
            std::process::id()
        ));
        let s = super::smoothed::smooth(log, &work, depth_lever_arm_m);
        let _ = std::fs::remove_dir_all(&work);
        let s = s?;
        let motion = s.reference();
        if reference.len() >= 2 {
            against.push(super::smoothed::reference_against_imu(
                &log.display().to_string(),
                &reference,
                &motion,
                s.installation,
            ));
        }
        channels.retain(|c| !matches!(c.kind, ChannelKind::Gyro | ChannelKind::Accelerometer));
        Ok((channels, motion, u))
    };
    let (r, undecodable) = if voyages {
        let mut data = Vec::with_capacity(a.logs.len());
        let mut undecodable = 0;
        for log in &a.logs {
            let (channels, reference, u) = read_one(log)?;
            undecodable += u;
            data.push(super::voyages::VoyageData {
                log: log.display().to_string(),
                channels,
                reference,
            });
        }
        let r = super::voyages::discover_voyages(
            &data,
            nominal,
            a.fit_fraction,
            &Selection::excluding(&a.never_select),
        );
        (r, undecodable)
    } else {
        let (channels, reference, undecodable) = if smoothed {
            read_one(&a.logs[0])?
        } else {
            read_logs_with(
                &a.logs,
                Collector::new()
                    .with_dvl_beams(a.dvl_beams)
                    .with_moving_bed(a.moving_bed),
            )?
        };
        let r = discover(
            &channels,
            &reference,
            nominal,
            a.fit_fraction,
            &Selection::excluding(&a.never_select),
        );
        (r, undecodable)
    };
    Ok((r, undecodable, against))
}
