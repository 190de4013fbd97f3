//! `auvnav usbl`: Monte Carlo of the S-USBL fusion on the docking scenario (600 s of straight
//! runs, turns, climb and descent from 120° E, 31° N to a seabed USBL station).
//!
//! Every run simulates the voyage with the scenario's sensor suite (FOG-class INS, DVL, pressure
//! depth, SeaTrac-class USBL) plus, per run, a random gyro and accelerometer bias and a random DVL
//! scale-factor error (0.5 %), starts the navigator from the truth perturbed by a draw of its
//! initial covariance, and feeds IMU, DVL, depth and USBL through `Navigator` — the code the
//! daemon runs. USBL multipath outliers (`--outliers`, 10–50 m added to the slant range) and an
//! error of the array's surveyed yaw (`--array-yaw-error`) are effects of the simulated device;
//! the filter knows the array as surveyed. Each run depends only on its seed.

use crate::StudyError;
use crate::error::usage;
use anyhow::Context;
use auvnav_core::aid::ranges::RangesConfig;
use auvnav_core::aid::usbl::{Coupling, UsblConfig, UsblFilter};
use auvnav_core::earth::{ned_offset, offset_position};
use auvnav_core::feed::SensorMessage;
use auvnav_core::navigator::NavConfig;
use auvnav_core::session::{Session, SessionConfig, SessionOutput};
use auvnav_core::strapdown::truth_position;
use auvnav_log::LogMessage;
use auvnav_shm_schema::{AidDiagnosticsV1, AidSource};
use auvnav_sim::rng::Rng;
use auvnav_sim::{self as sim, SimConfig, StationGeometry, scenario::Scenario};
use nalgebra::{UnitQuaternion, Vector3};
use serde::Serialize;

#[derive(Debug, Clone)]
#[cfg_attr(feature = "clap", derive(clap::Args))]
pub struct UsblOptions {
    /// loose (the device's position fix) or tight (slant range and range differences).
    #[cfg_attr(feature = "clap", arg(long, default_value = "tight", value_parser = crate::args::config_enum::<Coupling>(Coupling::NAMES)))]
    pub coupling: Coupling,
    /// ukf (fixed noise), akf (adaptive, linearised) or aukf (adaptive unscented).
    #[cfg_attr(feature = "clap", arg(long, default_value = "aukf", value_parser = crate::args::config_enum::<UsblFilter>(UsblFilter::NAMES)))]
    pub filter: UsblFilter,
    /// Fraction of USBL fixes hit by a multipath outlier (10–50 m added to the range).
    #[cfg_attr(feature = "clap", arg(long, default_value_t = 0.0))]
    pub outliers: f64,
    /// Error of the array's surveyed yaw (deg): the true array is turned by this much.
    #[cfg_attr(
        feature = "clap",
        arg(long, default_value_t = 0.0, allow_negative_numbers = true)
    )]
    pub array_yaw_error: f64,
    /// USBL latency (s): fixes are delivered this long after their time of validity, and
    /// stamped with it as the driver's `settings.latency_s` does.
    #[cfg_attr(feature = "clap", arg(long, default_value_t = 0.0))]
    pub latency: f64,
    /// Monte Carlo runs.
    #[cfg_attr(feature = "clap", arg(long, default_value_t = 50))]
    pub runs: usize,
    /// Seed of the first run (run k uses seed + k).
    #[cfg_attr(feature = "clap", arg(long, default_value_t = 1))]
    pub seed: u64,
    /// Scenario (must have a station).
    #[cfg_attr(feature = "clap", arg(long, default_value = "docking"))]
    pub scenario: String,
    /// Seconds to simulate (default: the whole scenario).
    #[cfg_attr(feature = "clap", arg(long))]
    pub seconds: Option<f64>,
    /// Statistics start this long after the start (s): what is measured is the navigation once
    /// the filter has had the geometry to correct the initial position error (3 m per axis); the
    /// first leg runs 80 s almost straight at the station, and its first turn is what makes the
    /// cross-range error observable to a filter that allows for array orientation errors.
    #[cfg_attr(feature = "clap", arg(long, default_value_t = 120.0))]
    pub settle_s: f64,
    /// A run whose horizontal error exceeds this after the settling time has diverged (m).
    #[cfg_attr(feature = "clap", arg(long, default_value_t = 5.0))]
    pub divergence_m: f64,
    /// Fuse the station's fixes through the range aid configured as the station
    /// (`RangesConfig::docking_station`): the slant range and each range difference gated and
    /// fused alone by the linearised update, with the same geometry, noise and error processes
    /// (tight coupling; `--filter` does not apply).
    #[cfg_attr(feature = "clap", arg(long))]
    pub range_aid: bool,
    /// Override a `[navigation.usbl]` setting, e.g. `--set range_difference_error_std_m=0.005`
    /// (repeatable; TOML values).
    #[cfg_attr(feature = "clap", arg(long = "set", value_name = "KEY=VALUE", value_parser = crate::args::key_value))]
    pub settings: Vec<String>,
    /// Worker threads (default: the available cores).
    #[cfg_attr(feature = "clap", arg(long))]
    pub threads: Option<usize>,
    /// Run the whole comparison table ({loose, tight} × {ukf, akf, aukf} × {clean, 5 % outliers, 1°
    /// array yaw error}) and print it as Markdown (JSON with --json).
    #[cfg_attr(feature = "clap", arg(long))]
    pub table: bool,
    #[cfg_attr(feature = "clap", arg(long))]
    pub json: bool,
}

/// The outcome of one run.
#[derive(Debug, Clone, Serialize, serde::Deserialize)]
pub struct RunResult {
    pub seed: u64,
    pub horizontal_error_rms_m: f64,
    pub horizontal_error_max_m: f64,
    pub vertical_rms_m: f64,
    pub vertical_max_m: f64,
    pub velocity_rms_m_s: f64,
    pub horizontal_error_final_m: f64,
    pub fixes: u64,
    pub fused: u64,
    pub rejected: u64,
    pub reopened: u64,
    pub injected_outliers: u64,
    pub accepted_outliers: u64,
    /// Fixes without an outlier that the gate rejected.
    pub rejected_clean: u64,
}

/// The Monte Carlo summary (RMS pooled over every epoch of every run).
#[derive(Debug, Clone, Serialize)]
pub struct UsblReport {
    pub scenario: String,
    pub coupling: Coupling,
    pub filter: UsblFilter,
    /// Fused by the range aid configured as the station (`--range-aid`).
    pub range_aid: bool,
    pub outlier_fraction: f64,
    pub array_yaw_error_deg: f64,
    pub runs: usize,
    pub seed: u64,
    pub wall_s_per_run: f64,
    /// Statistics start this long after the start (s).
    pub settle_s: f64,
    pub horizontal_error_rms_m: f64,
    /// The largest horizontal error of any run at any time.
    pub horizontal_error_max_m: f64,
    /// The worst run's horizontal RMS.
    pub worst_run_horizontal_error_rms_m: f64,
    pub vertical_rms_m: f64,
    pub vertical_max_m: f64,
    pub velocity_rms_m_s: f64,
    /// Runs whose horizontal error exceeded `divergence_m`.
    pub divergent_runs: usize,
    pub divergence_m: f64,
    pub fixes: u64,
    pub rejected: u64,
    pub reopened: u64,
    pub injected_outliers: u64,
    pub accepted_outliers: u64,
    pub rejected_clean: u64,
    pub wall_s: f64,
    pub per_run: Vec<RunResult>,
}

/// The navigation configuration matched to the docking scenario's sensors, with the station's
/// array as surveyed.
pub fn navigation_config(
    station: &StationGeometry,
    coupling: Coupling,
    filter: UsblFilter,
) -> NavConfig {
    NavConfig {
        gyro_angle_random_walk_deg_sqrt_h: 0.002,
        accel_velocity_random_walk_m_s_sqrt_h: 0.0005,
        gyro_bias_walk_deg_h_sqrt_h: 0.002,
        accel_bias_walk_ug_sqrt_h: 5.0,
        initial_position_std_m: 3.0,
        initial_velocity_std_m_s: 0.05,
        initial_tilt_std_deg: 0.02,
        initial_heading_std_deg: 0.05,
        initial_gyro_bias_std_deg_h: 0.01,
        initial_accel_bias_std_ug: 30.0,
        dvl_velocity_std_m_s: 0.01,
        depth_std_m: 0.05,
        estimate_dvl_scale: true,
        initial_dvl_scale_std: 0.01,
        usbl: Some(UsblConfig {
            coupling,
            filter,
            ..station.usbl_config()
        }),
        ..NavConfig::default()
    }
}

/// A fix waiting for the truth at its time to tell whether it was an outlier.
struct PendingFix {
    t_ns: u64,
    slant_m: f64,
    /// Fused or not, once the session has applied it.
    fused: Option<bool>,
}

/// The USBL configuration with `settings` (`key=value`, TOML values) applied.
pub fn apply_settings(base: &UsblConfig, settings: &[String]) -> Result<UsblConfig, StudyError> {
    let cfg: UsblConfig = crate::args::apply_settings(base, settings, "USBL")?;
    let problems = cfg.problems();
    if !problems.is_empty() {
        usage!("{}", problems.join("; "));
    }
    Ok(cfg)
}

// Long on purpose: one S-USBL run: the voyage simulated, outliers and array error injected, the
// filter fed and scored at every epoch, in one loop over the run's messages.
fn run_one(
    a: &UsblOptions,
    scenario: &Scenario,
    station: &StationGeometry,
    cfg: &NavConfig,
    seed: u64,
) -> anyhow::Result<RunResult> {
    let mut rng = Rng::new(seed, "montecarlo.usbl");
    let mut effects = scenario.effects()?;
    crate::perturbed_start::draw_sensor_errors(&mut effects, cfg, &mut rng)?;
    effects.set("usbl.outlier_fraction", &[a.outliers])?;
    effects.set("usbl.array_yaw", &[a.array_yaw_error])?;
    effects.set("usbl.latency", &[a.latency])?;
    let latency_ns = (a.latency * 1e9).round() as u64;
    let true_array = offset_position(&station.position, &Vector3::from(effects.usbl_array_offset));
    let lever = Vector3::from(station.responder_lever_arm_m);
    let sim_cfg = SimConfig {
        scenario: scenario.clone(),
        effects,
        seed,
        duration_s: a.seconds,
    };
    // The daemon's feed path: messages go through the session (aid delay 0, as replay).
    let mut session = Session::new(&SessionConfig {
        navigation: cfg.clone(),
        ..Default::default()
    });
    // Fixes waiting for the truth at their time of validity, and the recent true ranges.
    let mut pending: std::collections::VecDeque<PendingFix> = Default::default();
    let mut true_ranges: std::collections::VecDeque<(u64, f64)> = Default::default();
    let mut r = RunResult {
        seed,
        horizontal_error_rms_m: 0.0,
        horizontal_error_max_m: 0.0,
        vertical_rms_m: 0.0,
        vertical_max_m: 0.0,
        velocity_rms_m_s: 0.0,
        horizontal_error_final_m: 0.0,
        fixes: 0,
        fused: 0,
        rejected: 0,
        reopened: 0,
        injected_outliers: 0,
        accepted_outliers: 0,
        rejected_clean: 0,
    };
    let (mut sh, mut sv, mut svel, mut n) = (0.0, 0.0, 0.0, 0usize);
    // Slant ranges fused and refused by the range aid (`--range-aid`).
    let (mut slant_fused, mut slant_refused) = (0u64, 0u64);
    sim::simulate(&sim_cfg, |m| -> anyhow::Result<()> {
        match m {
            LogMessage::Truth(t) => {
                let truth_pos = truth_position(t);
                let Some(nv) = session.navigator() else {
                    let start = crate::perturbed_start::perturbed_start(cfg, t, &mut rng);
                    session.start(start, "truth perturbed by a draw of P0", &mut |_| {
                        Ok::<(), anyhow::Error>(())
                    })?;
                    return Ok(());
                };
                let q = t.quaternion_body_to_ned;
                let c = UnitQuaternion::from_quaternion(nalgebra::Quaternion::new(
                    q[0], q[1], q[2], q[3],
                ))
                .to_rotation_matrix()
                .into_inner();
                true_ranges.push_back((
                    t.host_time_ns,
                    (ned_offset(&true_array, &truth_pos) + c * lever).norm(),
                ));
                while true_ranges.len() > 400 {
                    true_ranges.pop_front();
                }
                // Fixes the session has applied (in order), once the truth has passed them.
                while pending
                    .front()
                    .is_some_and(|f| f.fused.is_some() && f.t_ns <= t.host_time_ns)
                {
                    let Some(f) = pending.pop_front() else { break };
                    let fused = f.fused.unwrap_or(false);
                    // The true range at the fix's time of validity (nearest truth record).
                    let true_range = true_ranges
                        .iter()
                        .min_by_key(|(tt, _)| tt.abs_diff(f.t_ns))
                        .map_or(f64::NAN, |x| x.1);
                    if (f.slant_m - true_range).abs() > 5.0 {
                        r.injected_outliers += 1;
                        r.accepted_outliers += u64::from(fused);
                    } else if !fused {
                        r.rejected_clean += 1;
                    }
                }
                if (t.host_time_ns as f64) * 1e-9 < a.settle_s {
                    return Ok(());
                }
                let s = nv.state();
                let dp = ned_offset(&truth_pos, &s.position);
                let dv = s.velocity_ned - Vector3::from(t.velocity_ned_m_s);
                let h = dp.xy().norm();
                sh += h * h;
                sv += dp.z * dp.z;
                svel += dv.norm_squared();
                n += 1;
                r.horizontal_error_max_m = r.horizontal_error_max_m.max(h);
                r.vertical_max_m = r.vertical_max_m.max(dp.z.abs());
                r.horizontal_error_final_m = h;
            }
            LogMessage::Usbl(x) if session.started() => {
                let mut x = *x;
                x.validity_time_ns = x.host_time_ns.saturating_sub(latency_ns);
                r.fixes += 1;
                pending.push_back(PendingFix {
                    t_ns: x.validity_time_ns,
                    slant_m: x.slant_range_m,
                    fused: None,
                });
                session.feed(
                    &SensorMessage::Usbl(x),
                    &mut |_| Ok::<(), anyhow::Error>(()),
                )?;
            }
            other if session.started() => {
                if let Some(x) = other.sensor() {
                    session.feed(&x, &mut |o| {
                        // A USBL fix's outcome, when the session applies it (in order of
                        // delivery: the oldest fix still undecided).
                        // Through the range aid: the slant range's outcome.
                        if let SessionOutput::Diagnostics(d) = o
                            && (d.source == AidSource::UsblSlantRange as u32
                                || d.source == AidSource::UsblPosition as u32
                                || d.source == AidSource::AcousticRange as u32)
                            && let Some(f) = pending.iter_mut().find(|f| f.fused.is_none())
                        {
                            let fused = d.flags & AidDiagnosticsV1::FLAG_FUSED != 0;
                            f.fused = Some(fused);
                            if d.source == AidSource::AcousticRange as u32 {
                                *if fused {
                                    &mut slant_fused
                                } else {
                                    &mut slant_refused
                                } += 1;
                            }
                        }
                        Ok::<(), anyhow::Error>(())
                    })?;
                }
            }
            _ => {}
        }
        Ok(())
    })?;
    let nv = session
        .navigator()
        .context("the simulation produced no truth")?;
    let c = nv.counters();
    if cfg.ranges.is_some() {
        (r.fused, r.rejected, r.reopened) = (slant_fused, slant_refused, c.ranges_reopened);
    } else {
        r.fused = c.usbl_fused;
        r.rejected = c.usbl_rejected + c.usbl_invalid + c.usbl_failed;
        r.reopened = c.usbl_reopened;
    }
    let nf = n.max(1) as f64;
    r.horizontal_error_rms_m = (sh / nf).sqrt();
    r.vertical_rms_m = (sv / nf).sqrt();
    r.velocity_rms_m_s = (svel / nf).sqrt();
    Ok(r)
}

/// The USBL study of one configuration: its options checked, its scenario and station loaded.
pub struct UsblStudy {
    args: UsblOptions,
    scenario: Scenario,
    station: StationGeometry,
    /// The filter's configuration (the station's, the coupling and filter, `--set` applied).
    navigation: NavConfig,
}

impl UsblStudy {
    /// Checks the options and loads the scenario.
    pub fn new(a: &UsblOptions) -> Result<UsblStudy, StudyError> {
        if a.runs == 0 {
            usage!("--runs must be at least 1");
        }
        if !(0.0..=0.5).contains(&a.outliers) {
            usage!("--outliers {}: expected a fraction 0..=0.5", a.outliers);
        }
        if !(a.array_yaw_error.is_finite() && a.array_yaw_error.abs() <= 30.0) {
            usage!(
                "--array-yaw-error {}: expected -30..=30 deg",
                a.array_yaw_error
            );
        }
        if let Some(s) = a.seconds
            && !(s.is_finite() && s >= 10.0 + a.settle_s)
        {
            usage!("--seconds {s}: expected at least --settle-s + 10");
        }
        if !(0.0..=5.0).contains(&a.latency) {
            usage!("--latency {}: expected 0..=5 s", a.latency);
        }
        if !(a.settle_s.is_finite() && a.settle_s >= 0.0) {
            usage!("--settle-s {}: expected zero or more", a.settle_s);
        }
        let scenario = Scenario::load(&a.scenario)?;
        let Some(station) = StationGeometry::from_scenario(&scenario) else {
            usage!(
                "scenario {} has no [station]: the USBL Monte Carlo needs one",
                scenario.name
            )
        };
        // The filter's configuration, the same for every run (`--set` checked once, here).
        let mut navigation = navigation_config(&station, a.coupling, a.filter);
        if let Some(u) = navigation.usbl.as_mut() {
            *u = apply_settings(u, &a.settings)?;
        }
        if a.range_aid {
            if a.coupling != Coupling::Tight {
                usage!("--range-aid fuses the station's ranges: it needs --coupling tight");
            }
            navigation.ranges = navigation
                .usbl
                .take()
                .map(|u| RangesConfig::docking_station(&u));
        }
        Ok(UsblStudy {
            args: a.clone(),
            scenario,
            station,
            navigation,
        })
    }
}

impl crate::runs::RunStudy for UsblStudy {
    type Run = RunResult;
    type Report = UsblReport;

    fn runs(&self) -> usize {
        self.args.runs
    }

    fn run(&self, k: usize) -> Result<RunResult, StudyError> {
        let seed = self.args.seed.wrapping_add(k as u64);
        run_one(
            &self.args,
            &self.scenario,
            &self.station,
            &self.navigation,
            seed,
        )
        .map_err(|e| StudyError::run(k, e))
    }

    fn report(&self, per_run: Vec<RunResult>, wall_s: f64) -> Result<UsblReport, StudyError> {
        let a = &self.args;
        if per_run.len() != a.runs {
            return Err(StudyError::Results(format!(
                "{} run results for {} runs",
                per_run.len(),
                a.runs
            )));
        }
        let pooled = |f: fn(&RunResult) -> f64| {
            (per_run.iter().map(|r| f(r).powi(2)).sum::<f64>() / per_run.len() as f64).sqrt()
        };
        let max = |f: fn(&RunResult) -> f64| per_run.iter().map(f).fold(0.0, f64::max);
        let sum = |f: fn(&RunResult) -> u64| per_run.iter().map(f).sum::<u64>();
        let seconds = match a.seconds {
            Some(s) => s,
            None => {
                auvnav_sim::trajectory::Trajectory::from_scenario(&self.scenario)
                    .map_err(auvnav_sim::SimError::from)?
                    .duration_s
            }
        };
        Ok(UsblReport {
            scenario: self.scenario.name.clone(),
            coupling: a.coupling,
            filter: a.filter,
            range_aid: a.range_aid,
            outlier_fraction: a.outliers,
            array_yaw_error_deg: a.array_yaw_error,
            runs: a.runs,
            seed: a.seed,
            wall_s_per_run: seconds,
            settle_s: a.settle_s,
            horizontal_error_rms_m: pooled(|r| r.horizontal_error_rms_m),
            horizontal_error_max_m: max(|r| r.horizontal_error_max_m),
            worst_run_horizontal_error_rms_m: max(|r| r.horizontal_error_rms_m),
            vertical_rms_m: pooled(|r| r.vertical_rms_m),
            vertical_max_m: max(|r| r.vertical_max_m),
            velocity_rms_m_s: pooled(|r| r.velocity_rms_m_s),
            divergent_runs: per_run
                .iter()
                .filter(|r| r.horizontal_error_max_m > a.divergence_m)
                .count(),
            divergence_m: a.divergence_m,
            fixes: sum(|r| r.fixes),
            rejected: sum(|r| r.rejected),
            reopened: sum(|r| r.reopened),
            injected_outliers: sum(|r| r.injected_outliers),
            accepted_outliers: sum(|r| r.accepted_outliers),
            rejected_clean: sum(|r| r.rejected_clean),
            wall_s,
            per_run,
        })
    }
}

/// Runs the Monte Carlo for one configuration on this machine's cores.
pub fn run(a: &UsblOptions) -> Result<UsblReport, StudyError> {
    let study = UsblStudy::new(a)?;
    let threads = a.threads.unwrap_or_else(crate::parallel::default_threads);
    let bar = crate::progress::Progress::new(!a.json).runs("USBL Monte Carlo", a.runs);
    crate::runs::run_local(&study, threads, &bar)
}

/// The comparison table: {loose, tight} × {ukf, akf, aukf} and tight through the range aid, ×
/// {clean, 5 % outliers, 1° array yaw error}.
pub fn run_table(a: &UsblOptions) -> Result<Vec<UsblReport>, StudyError> {
    let mut out = Vec::new();
    for (outliers, yaw) in [(0.0, 0.0), (0.05, 0.0), (0.0, 1.0)] {
        let mut ways: Vec<(Coupling, UsblFilter, bool)> = Vec::new();
        for coupling in [Coupling::Loose, Coupling::Tight] {
            for filter in [UsblFilter::Ukf, UsblFilter::Akf, UsblFilter::Aukf] {
                ways.push((coupling, filter, false));
            }
        }
        ways.push((Coupling::Tight, a.filter, true));
        for (coupling, filter, range_aid) in ways {
            out.push(run(&UsblOptions {
                coupling,
                filter,
                range_aid,
                outliers,
                array_yaw_error: yaw,
                table: false,
                ..a.clone()
            })?);
        }
    }
    Ok(out)
}
