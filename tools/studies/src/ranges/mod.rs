//! `auvnav montecarlo ranges`: tight acoustic ranges against the device's own fixes fused
//! loosely, for the three geometries of the range aid (`auvnav_core::aid::ranges`): a survey
//! under a boat's four-receiver array (an underwater GPS), in a field of three LBL beacons, and
//! ranged from one transducer on a circling ship, each with IMU, DVL and depth.
//!
//! Every run simulates the geometry's scenario (`ranges_array`, `ranges_lbl`, `ranges_single`:
//! a 20-minute survey at 1 m/s with a tactical MEMS IMU) with, per run, a random gyro and
//! accelerometer bias and DVL scale-factor error, the asked fraction of multipath outliers, and
//! navigates the same messages three ways from the same perturbed start, through the session the
//! daemon runs:
//! - **tight**: each receiver's range fused alone (`[navigation.ranges]`);
//! - **loose**: the device's fix (least squares from the ranges, no account of the motion during
//!   the ping) placed through the boat's reported pose and fused as a position with the
//!   device's one-sigma — what a navigator that takes the device's output does; a single
//!   receiver gives no fix, so there it is the same as none;
//! - **none**: IMU, DVL and depth alone (the drift the acoustic system bounds).

use crate::StudyError;
use crate::error::usage;
use auvnav_core::aid::ranges::RangesConfig;
use auvnav_core::earth::{Geodetic, ned_offset};
use auvnav_core::feed::SensorMessage;
use auvnav_core::navigator::NavConfig;
use auvnav_core::session::{Session, SessionConfig};
use auvnav_core::strapdown::truth_position;
use auvnav_log::LogMessage;
use auvnav_shm_schema::{AcousticArrayPoseV1, GnssFixV1};
use auvnav_sim::rng::Rng;
use auvnav_sim::{self as sim, SimConfig, acoustic, scenario::Scenario};
use serde::{Deserialize, Serialize};

mod fix_model;
mod measured;
pub use fix_model::*;
pub use measured::*;

/// The geometries, by the name of their scenario.
pub const GEOMETRIES: [&str; 3] = ["array", "lbl", "single"];

#[derive(Debug, Clone)]
#[cfg_attr(feature = "clap", derive(clap::Args))]
pub struct RangesOptions {
    /// array (a boat's four receivers), lbl (three seabed beacons), single (one transducer on a
    /// ship), or all.
    #[cfg_attr(feature = "clap", arg(long, default_value = "all"))]
    pub geometry: String,
    /// Fraction of ranges hit by a multipath outlier (5–30 m too long).
    #[cfg_attr(feature = "clap", arg(long, default_value_t = 0.05))]
    pub outliers: f64,
    /// A simulator effect on every run, over the scenario's (repeatable; `auvnav sim
    /// --list-effects`), e.g. `usbl.sound_speed=1520` (the water's; the device and the navigator
    /// assume 1500 m/s), `usbl.array_yaw=1`, `usbl.hydrophone_offset=…`.
    #[cfg_attr(feature = "clap", arg(long = "effect", value_name = "NAME=VALUE", value_parser = crate::args::effect_setting))]
    pub effects: Vec<String>,
    /// Override a `[navigation.ranges]` setting of the tight aid, e.g. `--set bias_std_m=0`
    /// (repeatable; TOML values).
    #[cfg_attr(feature = "clap", arg(long = "set", value_name = "KEY=VALUE", value_parser = crate::args::key_value))]
    pub settings: Vec<String>,
    /// Monte Carlo runs per geometry.
    #[cfg_attr(feature = "clap", arg(long, default_value_t = 100))]
    pub runs: usize,
    /// Seed of the first run (run k uses seed + k).
    #[cfg_attr(feature = "clap", arg(long, default_value_t = 1))]
    pub seed: u64,
    /// Seconds to simulate (default: the whole 20-minute survey).
    #[cfg_attr(feature = "clap", arg(long))]
    pub seconds: Option<f64>,
    /// Statistics start this long after the start (s).
    #[cfg_attr(feature = "clap", arg(long, default_value_t = 60.0))]
    pub settle_s: f64,
    /// A run whose horizontal error exceeds this after the settling time has diverged (m).
    #[cfg_attr(feature = "clap", arg(long, default_value_t = 20.0))]
    pub divergence_m: f64,
    /// Worker threads (default: the available cores).
    #[cfg_attr(feature = "clap", arg(long))]
    pub threads: Option<usize>,
    #[cfg_attr(feature = "clap", arg(long))]
    pub json: bool,
}

/// One way of navigating a run, scored against the truth after the settling time.
#[derive(Debug, Clone, Copy, Default, Serialize, Deserialize)]
pub struct ModeResult {
    pub horizontal_error_rms_m: f64,
    pub horizontal_error_max_m: f64,
    pub horizontal_error_final_m: f64,
    /// Acoustic measurements fused and refused (tight: ranges; loose: fixes).
    pub fused: u64,
    pub rejected: u64,
    /// Tight: the range aid's common bias (m) and sound-speed scale error at the end of the run
    /// (0 where their states are off).
    pub range_bias_m: f64,
    pub range_scale: f64,
    /// Tight: each receiver's range bias at the end of the run (m; the shared one repeated, 0
    /// where off or beyond the receivers).
    #[serde(default)]
    pub receiver_biases_m: [f64; 4],
}

/// One run: the three ways.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct RangesRun {
    pub seed: u64,
    pub tight: ModeResult,
    pub loose: ModeResult,
    pub none: ModeResult,
    /// Ranges the simulator made outliers, and pings.
    pub outliers: u64,
    pub pings: u64,
}

/// A way of navigating over every run.
#[derive(Debug, Clone, Serialize)]
pub struct ModeSummary {
    /// Horizontal error RMS pooled over every epoch of every run (m).
    pub horizontal_error_rms_m: f64,
    /// The worst run's RMS and the largest error of any run at any time (m).
    pub worst_run_horizontal_error_rms_m: f64,
    pub horizontal_error_max_m: f64,
    /// Runs whose error exceeded `divergence_m`.
    pub divergent_runs: usize,
    pub fused: u64,
    pub rejected: u64,
    /// Mean and spread over the runs of the final bias (m) and scale estimates.
    pub range_bias_mean_m: f64,
    pub range_bias_std_m: f64,
    pub range_scale_mean: f64,
    pub range_scale_std: f64,
    /// Mean and spread over the runs of each receiver's final bias (m).
    pub receiver_bias_mean_m: [f64; 4],
    pub receiver_bias_std_m: [f64; 4],
}

/// One geometry's Monte Carlo.
#[derive(Debug, Clone, Serialize)]
pub struct RangesReport {
    pub geometry: String,
    pub scenario: String,
    pub runs: usize,
    pub seed: u64,
    pub outlier_fraction: f64,
    /// The effects given on top of the scenario's.
    pub effects: Vec<String>,
    /// The tight aid's configuration.
    pub ranges: RangesConfig,
    pub settle_s: f64,
    pub divergence_m: f64,
    pub tight: ModeSummary,
    /// None where the device gives no fix (a single receiver).
    pub loose: Option<ModeSummary>,
    pub none: ModeSummary,
    /// Tight RMS over loose RMS (the target: at most 0.5).
    pub tight_over_loose: Option<f64>,
    pub pings: u64,
    pub outliers: u64,
    pub wall_s: f64,
    pub per_run: Vec<RangesRun>,
}

/// The navigation configuration matched to the range scenarios' sensors (a tactical MEMS IMU, a
/// small DVL, depth), without an acoustic aid.
pub fn navigation_config() -> NavConfig {
    NavConfig {
        gyro_angle_random_walk_deg_sqrt_h: 0.05,
        accel_velocity_random_walk_m_s_sqrt_h: 0.02,
        gyro_bias_walk_deg_h_sqrt_h: 0.2,
        accel_bias_walk_ug_sqrt_h: 20.0,
        initial_position_std_m: 3.0,
        initial_velocity_std_m_s: 0.05,
        initial_tilt_std_deg: 0.1,
        initial_heading_std_deg: 1.0,
        initial_gyro_bias_std_deg_h: 1.0,
        initial_accel_bias_std_ug: 100.0,
        dvl_velocity_std_m_s: 0.02,
        depth_std_m: 0.05,
        estimate_dvl_scale: true,
        initial_dvl_scale_std: 0.01,
        gnss_min_std_m: 0.1,
        ..NavConfig::default()
    }
}

/// The study of one geometry.
pub struct RangesStudy {
    args: RangesOptions,
    geometry: String,
    scenario: Scenario,
    /// The scenario's effects with `--effect` applied.
    effects: auvnav_sim::effects::Effects,
    ranges: RangesConfig,
}

impl RangesStudy {
    pub fn new(a: &RangesOptions, geometry: &str) -> Result<RangesStudy, StudyError> {
        if a.runs == 0 {
            usage!("--runs must be at least 1");
        }
        if !(0.0..=0.5).contains(&a.outliers) {
            usage!("--outliers {}: expected a fraction 0..=0.5", a.outliers);
        }
        if !(a.settle_s.is_finite() && a.settle_s >= 0.0) {
            usage!("--settle-s {}: expected zero or more", a.settle_s);
        }
        if let Some(s) = a.seconds
            && !(s.is_finite() && s >= a.settle_s + 10.0)
        {
            usage!("--seconds {s}: expected at least --settle-s + 10");
        }
        if !GEOMETRIES.contains(&geometry) {
            usage!("--geometry {geometry:?}: expected array, lbl, single or all");
        }
        let scenario = Scenario::load(&format!("ranges_{geometry}"))?;
        let Some(setup) = scenario.acoustic.as_ref() else {
            usage!("scenario {} has no [acoustic] table", scenario.name)
        };
        let start = Geodetic {
            latitude_rad: scenario.start.latitude_deg.to_radians(),
            longitude_rad: scenario.start.longitude_deg.to_radians(),
            height_m: 0.0,
        };
        // The range noise the simulated device has; the bias and sound-speed states at their
        // defaults (the simulated water and timing have no error: what they cost is measured).
        let ranges = RangesConfig {
            range_std_m: scenario.effects()?.usbl_range_noise.max(0.05),
            ..setup.ranges_config(&start)
        };
        let ranges: RangesConfig = crate::args::apply_settings(&ranges, &a.settings, "ranges")?;
        let problems = ranges.problems();
        if !problems.is_empty() {
            usage!("{}", problems.join("; "));
        }
        let mut effects = scenario.effects()?;
        for spec in &a.effects {
            let (name, values) = match auvnav_sim::effects::parse_setting(spec) {
                Ok(x) => x,
                Err(e) => usage!("--effect {spec}: {e}"),
            };
            if let Err(e) = effects.set(&name, &values) {
                usage!("--effect {spec}: {e}");
            }
        }
        Ok(RangesStudy {
            args: a.clone(),
            geometry: geometry.to_string(),
            scenario,
            effects,
            ranges,
        })
    }

    /// Navigates `messages` one way (`ranges`: the tight aid; `loose`: the device's fixes as
    /// positions) from the start `start`, scored against the truth.
    fn navigate(
        &self,
        messages: &[LogMessage],
        cfg: &NavConfig,
        loose: bool,
        rng_seed: u64,
    ) -> anyhow::Result<ModeResult> {
        let mut rng = Rng::new(rng_seed, "montecarlo.ranges.start");
        let mut session = Session::new(&SessionConfig {
            navigation: cfg.clone(),
            ..Default::default()
        });
        let mut r = ModeResult::default();
        let (mut sum, mut n) = (0.0, 0usize);
        let setup = self.scenario.acoustic.as_ref();
        let lbl = setup.is_some_and(|s| s.kind == acoustic::AcousticKind::Lbl);
        let origin = Geodetic {
            latitude_rad: self.ranges.origin_latitude_deg.to_radians(),
            longitude_rad: self.ranges.origin_longitude_deg.to_radians(),
            height_m: self.ranges.origin_height_m,
        };
        let mut pose: Option<AcousticArrayPoseV1> = None;
        let mut ignore = |_: auvnav_core::session::SessionOutput<'_>| Ok::<(), anyhow::Error>(());
        for m in messages {
            match m {
                LogMessage::Truth(t) => {
                    let Some(nv) = session.navigator() else {
                        let start = crate::perturbed_start::perturbed_start(cfg, t, &mut rng);
                        session.start(start, "truth perturbed by a draw of P0", &mut ignore)?;
                        continue;
                    };
                    if (t.host_time_ns as f64) * 1e-9 < self.args.settle_s {
                        continue;
                    }
                    let h = ned_offset(&truth_position(t), &nv.state().position)
                        .xy()
                        .norm();
                    sum += h * h;
                    n += 1;
                    r.horizontal_error_max_m = r.horizontal_error_max_m.max(h);
                    r.horizontal_error_final_m = h;
                }
                LogMessage::AcousticArrayPose(p) => {
                    pose = Some(*p);
                    if !loose {
                        session.feed(&SensorMessage::AcousticArrayPose(*p), &mut ignore)?;
                    }
                }
                LogMessage::AcousticRanges(x) if loose => {
                    // The device's fix through the pose its boat reports (LBL: the beacons'
                    // surveyed frame).
                    let placed = if lbl {
                        acoustic::fix_position(x, &origin, 0.0)
                    } else {
                        pose.and_then(|p| {
                            let o = Geodetic {
                                latitude_rad: p.latitude_rad,
                                longitude_rad: p.longitude_rad,
                                height_m: p.height_m,
                            };
                            acoustic::fix_position(x, &o, p.euler_rad[2])
                        })
                    };
                    if let Some(g) = placed {
                        let std = f64::from(x.position_std_m)
                            + pose.map_or(0.0, |p| f64::from(p.horizontal_std_m));
                        let fix = GnssFixV1 {
                            host_time_ns: x.host_time_ns,
                            sequence: x.sequence,
                            latitude_rad: g.latitude_rad,
                            longitude_rad: g.longitude_rad,
                            height_m: g.height_m,
                            horizontal_std_m: std,
                            vertical_std_m: std.max(0.5),
                            validity: GnssFixV1::VALID_POSITION | GnssFixV1::VALID_HEIGHT,
                            ..Default::default()
                        };
                        session.feed(&SensorMessage::Gnss(fix), &mut ignore)?;
                    }
                }
                other => {
                    if let Some(x) = other.sensor() {
                        session.feed(&x, &mut ignore)?;
                    }
                }
            }
        }
        let nv = session
            .navigator()
            .ok_or_else(|| anyhow::anyhow!("the simulation produced no truth"))?;
        let c = nv.counters();
        (r.fused, r.rejected) = if loose {
            (c.gnss_fused, c.gnss_rejected + c.gnss_invalid)
        } else {
            (c.ranges_fused, c.ranges_rejected + c.ranges_invalid)
        };
        if let Some((bias, scale)) = nv.range_estimates() {
            (r.range_bias_m, r.range_scale) = (bias, scale);
        }
        for (k, b) in nv
            .receiver_biases()
            .unwrap_or_default()
            .iter()
            .take(4)
            .enumerate()
        {
            r.receiver_biases_m[k] = *b;
        }
        r.horizontal_error_rms_m = (sum / n.max(1) as f64).sqrt();
        Ok(r)
    }

    fn run_one(&self, seed: u64) -> anyhow::Result<RangesRun> {
        let base = navigation_config();
        let mut rng = Rng::new(seed, "montecarlo.ranges");
        let mut effects = self.effects.clone();
        crate::perturbed_start::draw_sensor_errors(&mut effects, &base, &mut rng)?;
        effects.set("usbl.outlier_fraction", &[self.args.outliers])?;
        let (messages, summary) = sim::simulate_to_vec(&SimConfig {
            scenario: self.scenario.clone(),
            effects,
            seed,
            duration_s: self.args.seconds,
        })?;
        let tight_cfg = NavConfig {
            ranges: Some(self.ranges.clone()),
            ..base.clone()
        };
        let loose_cfg = NavConfig {
            gnss_lever_arm_m: self.ranges.transducer_lever_arm_m,
            ..base.clone()
        };
        // The same start for every way (the same draw of P0).
        let start_seed = seed ^ 0x5eed;
        Ok(RangesRun {
            seed,
            tight: self.navigate(&messages, &tight_cfg, false, start_seed)?,
            loose: self.navigate(&messages, &loose_cfg, true, start_seed)?,
            none: self.navigate(&messages, &base, false, start_seed)?,
            outliers: summary.acoustic_outliers,
            pings: summary.acoustic_pings,
        })
    }

    fn summary(&self, per_run: &[RangesRun], f: fn(&RangesRun) -> &ModeResult) -> ModeSummary {
        let n = per_run.len().max(1) as f64;
        ModeSummary {
            horizontal_error_rms_m: (per_run
                .iter()
                .map(|r| f(r).horizontal_error_rms_m.powi(2))
                .sum::<f64>()
                / n)
                .sqrt(),
            worst_run_horizontal_error_rms_m: per_run
                .iter()
                .map(|r| f(r).horizontal_error_rms_m)
                .fold(0.0, f64::max),
            horizontal_error_max_m: per_run
                .iter()
                .map(|r| f(r).horizontal_error_max_m)
                .fold(0.0, f64::max),
            divergent_runs: per_run
                .iter()
                .filter(|r| {
                    let max = f(r).horizontal_error_max_m;
                    max.is_nan() || max > self.args.divergence_m
                })
                .count(),
            fused: per_run.iter().map(|r| f(r).fused).sum(),
            rejected: per_run.iter().map(|r| f(r).rejected).sum(),
            range_bias_mean_m: mean_std(per_run.iter().map(|r| f(r).range_bias_m)).0,
            range_bias_std_m: mean_std(per_run.iter().map(|r| f(r).range_bias_m)).1,
            range_scale_mean: mean_std(per_run.iter().map(|r| f(r).range_scale)).0,
            range_scale_std: mean_std(per_run.iter().map(|r| f(r).range_scale)).1,
            receiver_bias_mean_m: std::array::from_fn(|k| {
                mean_std(per_run.iter().map(|r| f(r).receiver_biases_m[k])).0
            }),
            receiver_bias_std_m: std::array::from_fn(|k| {
                mean_std(per_run.iter().map(|r| f(r).receiver_biases_m[k])).1
            }),
        }
    }
}

/// Mean and standard deviation of `v` (0, 0 when empty).
fn mean_std(v: impl Iterator<Item = f64> + Clone) -> (f64, f64) {
    let n = v.clone().count().max(1) as f64;
    let mean = v.clone().sum::<f64>() / n;
    let var = v.map(|x| (x - mean).powi(2)).sum::<f64>() / n;
    (mean, var.sqrt())
}

impl crate::runs::RunStudy for RangesStudy {
    type Run = RangesRun;
    type Report = RangesReport;

    fn runs(&self) -> usize {
        self.args.runs
    }

    fn run(&self, k: usize) -> Result<RangesRun, StudyError> {
        self.run_one(self.args.seed.wrapping_add(k as u64))
            .map_err(|e| StudyError::run(k, e))
    }

    fn report(&self, per_run: Vec<RangesRun>, wall_s: f64) -> Result<RangesReport, StudyError> {
        let tight = self.summary(&per_run, |r| &r.tight);
        let none = self.summary(&per_run, |r| &r.none);
        let loose =
            (self.ranges.receivers_m.len() > 1).then(|| self.summary(&per_run, |r| &r.loose));
        let tight_over_loose = loose
            .as_ref()
            .map(|l| tight.horizontal_error_rms_m / l.horizontal_error_rms_m);
        Ok(RangesReport {
            geometry: self.geometry.clone(),
            scenario: self.scenario.name.clone(),
            runs: self.args.runs,
            seed: self.args.seed,
            outlier_fraction: self.args.outliers,
            effects: self.args.effects.clone(),
            ranges: self.ranges.clone(),
            settle_s: self.args.settle_s,
            divergence_m: self.args.divergence_m,
            tight,
            loose,
            none,
            tight_over_loose,
            pings: per_run.iter().map(|r| r.pings).sum(),
            outliers: per_run.iter().map(|r| r.outliers).sum(),
            wall_s,
            per_run,
        })
    }
}

/// Runs the study for the asked geometries on this machine's cores.
pub fn run(a: &RangesOptions) -> Result<Vec<RangesReport>, StudyError> {
    let geometries: Vec<&str> = if a.geometry == "all" {
        GEOMETRIES.to_vec()
    } else {
        vec![a.geometry.as_str()]
    };
    let threads = a.threads.unwrap_or_else(crate::parallel::default_threads);
    let mut out = Vec::new();
    for g in geometries {
        let study = RangesStudy::new(a, g)?;
        let bar = crate::progress::Progress::new(!a.json).runs(&format!("ranges: {g}"), a.runs);
        out.push(crate::runs::run_local(&study, threads, &bar)?);
    }
    Ok(out)
}
