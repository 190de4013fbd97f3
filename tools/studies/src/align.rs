//! `auvnav align`: Monte Carlo comparison of the fine-alignment error models of S-ALIGN
//! (`auvnav_core::align::fine`) on simulated voyages (`align_moored`, `align_straight`,
//! `align_turning`: 2 m/s, 1200 s). Every run simulates the voyage once with the seed's sensors
//! and a random DVL installation, then runs each selected model on the same data from the same
//! perturbed initial state. Runs are spread over the available cores; each run depends only on
//! its seed, so the result does not depend on the number of threads.

use crate::StudyError;
use crate::error::usage;
use anyhow::Context;
use auvnav_core::align::fine::{ErrorModel, FineAlignConfig};
use auvnav_core::earth::{Geodetic, ned_offset, offset_position};
use auvnav_core::session::{Session, SessionConfig};
use auvnav_core::strapdown::NavState;
use auvnav_log::LogMessage;
use auvnav_shm_schema::TruthStateV1;
use auvnav_sim::rng::Rng;
use auvnav_sim::{self as sim, SimConfig, effects::Effects, scenario::Scenario};
use nalgebra::{UnitQuaternion, Vector3};
use serde::Serialize;

#[derive(Debug, Clone)]
#[cfg_attr(feature = "clap", derive(clap::Args))]
pub struct AlignOptions {
    /// Error model(s): 1 (body-frame velocity), 2 (navigation frame + mounting states),
    /// 3 (navigation frame); repeatable; default all three.
    #[cfg_attr(feature = "clap", arg(long = "model"))]
    pub models: Vec<u8>,
    /// moored, straight or turning.
    #[cfg_attr(feature = "clap", arg(long, default_value = "turning"))]
    pub scenario: String,
    /// Monte Carlo runs.
    #[cfg_attr(feature = "clap", arg(long, default_value_t = 220))]
    pub runs: usize,
    /// Initial heading error (deg).
    #[cfg_attr(feature = "clap", arg(long, default_value_t = 10.0))]
    pub heading_error: f64,
    /// DVL mounting angles roll,pitch,yaw (deg), or "random" (1σ = 1° per axis).
    #[cfg_attr(feature = "clap", arg(long, default_value = "random"))]
    pub mount: String,
    /// Seed of the first run (run k uses seed + k).
    #[cfg_attr(feature = "clap", arg(long, default_value_t = 1))]
    pub seed: u64,
    /// Seconds of alignment (checkpoints beyond it are left out).
    #[cfg_attr(feature = "clap", arg(long, default_value_t = 1200.0))]
    pub seconds: f64,
    /// A run has converged when its final heading error is below this (deg).
    #[cfg_attr(feature = "clap", arg(long, default_value_t = 1.0))]
    pub converged_deg: f64,
    /// Worker threads (default: the available cores).
    #[cfg_attr(feature = "clap", arg(long))]
    pub threads: Option<usize>,
    /// Include every run's errors in the report (`per_run`).
    #[cfg_attr(feature = "clap", arg(long))]
    pub per_run: bool,
    #[cfg_attr(feature = "clap", arg(long))]
    pub json: bool,
}

/// Measured data: fine alignment on every Snapir segment from the reference attitude with its
/// heading offset, per model.
#[derive(Debug, Clone)]
#[cfg_attr(feature = "clap", derive(clap::Args))]
pub struct AlignMeasuredOptions {
    /// The Snapir data set directory (../shared/data/snapir-auv).
    pub dir: std::path::PathBuf,
    /// Heading offsets of the start (deg; repeatable; default +20 and -45).
    #[cfg_attr(
        feature = "clap",
        arg(long = "heading-offset", allow_negative_numbers = true)
    )]
    pub heading_offsets: Vec<f64>,
    /// Segments (default 1..=13).
    #[cfg_attr(feature = "clap", arg(long = "segment"))]
    pub segments: Vec<u32>,
    #[cfg_attr(feature = "clap", arg(long))]
    pub json: bool,
}

/// Heading error against the reference at 100, 200 and 400 s for one segment, offset and model.
#[derive(Debug, Clone, Serialize)]
pub struct MeasuredRow {
    pub segment: u32,
    pub heading_offset_deg: f64,
    pub model: u8,
    /// (seconds, heading error in deg); checkpoints beyond the segment are left out.
    pub heading_error_deg: Vec<(f64, f64)>,
}

/// Checkpoints on measured data (s).
pub const MEASURED_CHECKPOINTS: [f64; 3] = [100.0, 200.0, 400.0];

/// Per model: (model number, [(seconds, heading error in deg)]).
pub type MeasuredErrors = Vec<(u8, Vec<(f64, f64)>)>;

/// Runs the three models on one measured log (messages in time order, truth = reference).
pub fn align_measured(
    messages: &[LogMessage],
    heading_offset_deg: f64,
) -> Result<MeasuredErrors, StudyError> {
    let t0 = messages
        .iter()
        .find_map(|m| match m {
            LogMessage::Truth(t) => Some(*t),
            _ => None,
        })
        .ok_or_else(|| StudyError::Input("the log has no reference (truth) channel".into()))?;
    let cfg = FineAlignConfig {
        initial_heading_std_deg: heading_offset_deg.abs().max(1.0),
        ..FineAlignConfig::default()
    };
    let euler = [
        t0.euler_rad[0],
        t0.euler_rad[1],
        t0.euler_rad[2] + heading_offset_deg.to_radians(),
    ];
    let initial = NavState {
        time_s: t0.host_time_ns as f64 * 1e-9,
        position: Geodetic {
            latitude_rad: t0.latitude_rad,
            longitude_rad: t0.longitude_rad,
            height_m: t0.height_m,
        },
        velocity_ned: Vector3::from(t0.velocity_ned_m_s),
        q_body_to_ned: UnitQuaternion::from_euler_angles(euler[0], euler[1], euler[2]),
    };
    let mut out = Vec::new();
    for model in [
        ErrorModel::BodyVelocity,
        ErrorModel::NavigationWithMounting,
        ErrorModel::Navigation,
    ] {
        // The daemon's feed path: the session runs the alignment filter of `model`.
        let mut session = Session::new(&SessionConfig::default());
        session.start_fine_alignment(model, cfg, initial);
        let mut next = 0;
        let mut errs = Vec::new();
        for m in messages {
            if let LogMessage::Truth(t) = m {
                let el = (t.host_time_ns - t0.host_time_ns) as f64 * 1e-9;
                // The reference is 1 Hz and a segment's last record is at 399 s: a checkpoint
                // is taken at the first record within one second of it.
                while next < MEASURED_CHECKPOINTS.len() && el >= MEASURED_CHECKPOINTS[next] - 1.0 {
                    let f = session
                        .fine_aligner()
                        .ok_or_else(|| StudyError::Input("the alignment filter stopped".into()))?;
                    errs.push((MEASURED_CHECKPOINTS[next], attitude_errors(f.state(), t)[2]));
                    next += 1;
                }
            } else if let Some(x) = m.sensor() {
                let Ok(()) = session.feed(&x, &mut |_| Ok::<(), std::convert::Infallible>(()));
            }
        }
        out.push((model.number(), errs));
    }
    Ok(out)
}

/// `auvnav align-measured`: every segment, every offset, every model.
pub fn measured_rows(a: &AlignMeasuredOptions) -> Result<Vec<MeasuredRow>, StudyError> {
    let offsets = if a.heading_offsets.is_empty() {
        vec![20.0, -45.0]
    } else {
        a.heading_offsets.clone()
    };
    let segments = if a.segments.is_empty() {
        (1..=13).collect()
    } else {
        a.segments.clone()
    };
    let mut rows = Vec::new();
    for &segment in &segments {
        let (tagged, _) = auvnav_import::snapir_messages(
            &a.dir,
            segment,
            auvnav_import::TimeBase::Nominal,
            true,
        )?;
        let messages: Vec<LogMessage> = tagged.into_iter().map(|(_, m)| m).collect();
        for &offset in &offsets {
            for (model, errs) in align_measured(&messages, offset)? {
                rows.push(MeasuredRow {
                    segment,
                    heading_offset_deg: offset,
                    model,
                    heading_error_deg: errs,
                });
            }
        }
    }
    Ok(rows)
}

/// Checkpoints (s).
pub const CHECKPOINTS: [f64; 4] = [60.0, 300.0, 600.0, 1200.0];

/// One model's errors in one run.
#[derive(Debug, Clone, Default, Serialize, serde::Deserialize)]
pub struct RunResult {
    /// Roll, pitch, heading errors (deg) at each checkpoint reached.
    pub attitude_error_deg: Vec<[f64; 3]>,
    /// Horizontal position error at the end (m).
    pub position_error_m: f64,
    /// Mounting-angle estimation error per axis at the end (deg); models 1 and 2.
    pub mount_error_deg: Option<[f64; 3]>,
}

/// One model's statistics over the runs.
#[derive(Debug, Clone, Serialize)]
pub struct ModelReport {
    pub model: u8,
    /// RMS of the heading error at each checkpoint (deg).
    pub heading_rms_deg: Vec<(f64, f64)>,
    pub pitch_rms_deg: Vec<(f64, f64)>,
    pub roll_rms_deg: Vec<(f64, f64)>,
    /// RMS horizontal position error at the end (m).
    pub position_rms_m: f64,
    /// RMS mounting-angle estimation error per axis at the end (deg); models 1 and 2.
    pub mount_error_rms_deg: Option<[f64; 3]>,
    /// Runs whose final heading error exceeds --converged-deg.
    pub not_converged: usize,
}

#[derive(Debug, Clone, Serialize)]
pub struct AlignReport {
    pub scenario: String,
    pub runs: usize,
    pub seconds: f64,
    pub heading_error_deg: f64,
    pub mount: String,
    pub seed: u64,
    pub models: Vec<ModelReport>,
    /// With `--per-run`: each run's results, one per model in the order of `models`.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub per_run: Option<Vec<Vec<RunResult>>>,
    pub wall_s: f64,
}

fn scenario_name(s: &str) -> Result<&'static str, StudyError> {
    Ok(match s {
        "moored" => "align_moored",
        "straight" => "align_straight",
        "turning" => "align_turning",
        _ => usage!("--scenario {s:?}: expected moored, straight or turning"),
    })
}

fn parse_mount(s: &str) -> Result<Option<[f64; 3]>, StudyError> {
    if s == "random" {
        return Ok(None);
    }
    let Ok(v) = s
        .split(',')
        .map(|x| x.trim().parse::<f64>())
        .collect::<Result<Vec<f64>, _>>()
    else {
        usage!("--mount {s:?}: expected DEG,DEG,DEG or random")
    };
    match v[..] {
        [r, p, y] if v.iter().all(|x| x.is_finite() && x.abs() <= 10.0) => Ok(Some([r, p, y])),
        _ => usage!("--mount {s:?}: expected three angles within ±10 deg, or random"),
    }
}

fn wrap_deg(a: f64) -> f64 {
    (a + 180.0).rem_euclid(360.0) - 180.0
}

fn attitude_errors(state: &NavState, t: &TruthStateV1) -> [f64; 3] {
    let e = state.euler();
    [0, 1, 2].map(|i| wrap_deg((e[i] - t.euler_rad[i]).to_degrees()))
}

/// One Monte Carlo run: simulate, then run each model.
fn run_one(
    a: &AlignOptions,
    scenario: &Scenario,
    models: &[ErrorModel],
    mount: Option<[f64; 3]>,
    seed: u64,
) -> anyhow::Result<Vec<RunResult>> {
    let mut rng = Rng::new(seed, "align");
    let sign = |r: &mut Rng| if r.uniform() < 0.5 { -1.0 } else { 1.0 };
    let mut effects = Effects::default();
    let gb = [
        0.01 * sign(&mut rng),
        0.01 * sign(&mut rng),
        0.01 * sign(&mut rng),
    ];
    let ab = [
        100.0 * sign(&mut rng),
        100.0 * sign(&mut rng),
        100.0 * sign(&mut rng),
    ];
    let mount_deg = mount.unwrap_or_else(|| [rng.gauss(1.0), rng.gauss(1.0), rng.gauss(1.0)]);
    let cfg = FineAlignConfig {
        initial_heading_std_deg: a.heading_error.abs().max(0.1),
        ..FineAlignConfig::default()
    };
    for (name, v) in [
        ("imu.gyro_bias", gb.to_vec()),
        ("imu.accel_bias", ab.to_vec()),
        ("imu.angle_random_walk", vec![cfg.gyro_arw_deg_sqrt_h]),
        ("imu.velocity_random_walk", vec![cfg.accel_vrw_m_s_sqrt_h]),
        // Per-beam noise giving about 0.1 m/s on the horizontal velocity (30° beams).
        ("dvl.noise", vec![0.1]),
        ("dvl.mount_roll", vec![mount_deg[0]]),
        ("dvl.mount_pitch", vec![mount_deg[1]]),
        ("dvl.mount_yaw", vec![mount_deg[2]]),
    ] {
        effects.set(name, &v)?;
    }
    let sim_cfg = SimConfig {
        scenario: scenario.clone(),
        effects,
        seed,
        duration_s: Some(a.seconds),
    };
    let (messages, _) = sim::simulate_to_vec(&sim_cfg)?;
    let t0 = messages
        .iter()
        .find_map(|m| match m {
            LogMessage::Truth(t) => Some(*t),
            _ => None,
        })
        .context("no truth")?;
    // The seed's initial errors: 10 m position (random direction), 0.1 m/s velocity per axis,
    // the given heading error, small tilt errors.
    let dir = rng.uniform() * std::f64::consts::TAU;
    let start_truth = Geodetic {
        latitude_rad: t0.latitude_rad,
        longitude_rad: t0.longitude_rad,
        height_m: t0.height_m,
    };
    let position = offset_position(
        &start_truth,
        &Vector3::new(10.0 * dir.cos(), 10.0 * dir.sin(), 0.0),
    );
    let velocity = Vector3::from(t0.velocity_ned_m_s)
        + Vector3::new(rng.gauss(0.1), rng.gauss(0.1), rng.gauss(0.1));
    let tilt = (cfg.initial_tilt_std_deg).to_radians();
    let euler = [
        t0.euler_rad[0] + rng.gauss(tilt),
        t0.euler_rad[1] + rng.gauss(tilt),
        t0.euler_rad[2] + a.heading_error.to_radians(),
    ];
    let t_start = t0.host_time_ns as f64 * 1e-9;
    let initial = NavState {
        time_s: t_start,
        position,
        velocity_ned: velocity,
        q_body_to_ned: UnitQuaternion::from_euler_angles(euler[0], euler[1], euler[2]),
    };
    let true_mount = Vector3::from(mount_deg.map(f64::to_radians));
    let mut out = Vec::new();
    for &model in models {
        // The daemon's feed path: the session runs the alignment filter of `model`.
        let mut session = Session::new(&SessionConfig::default());
        session.start_fine_alignment(model, cfg, initial);
        let mut result = RunResult::default();
        let mut next = 0;
        let mut last_truth = t0;
        for m in &messages {
            if let LogMessage::Truth(t) = m {
                last_truth = *t;
                let el = (t.host_time_ns - t0.host_time_ns) as f64 * 1e-9;
                while next < CHECKPOINTS.len() && el >= CHECKPOINTS[next] - 1e-9 {
                    let f = session
                        .fine_aligner()
                        .context("the alignment filter stopped")?;
                    result
                        .attitude_error_deg
                        .push(attitude_errors(f.state(), t));
                    next += 1;
                }
            } else if let Some(x) = m.sensor() {
                session.feed(&x, &mut |_| Ok::<(), anyhow::Error>(()))?;
            }
        }
        let f = session
            .fine_aligner()
            .context("the alignment filter stopped")?;
        let end = Geodetic {
            latitude_rad: last_truth.latitude_rad,
            longitude_rad: last_truth.longitude_rad,
            height_m: last_truth.height_m,
        };
        let d = ned_offset(&end, &f.state().position);
        result.position_error_m = (d.x * d.x + d.y * d.y).sqrt();
        if model != ErrorModel::Navigation {
            let e = f.mounting() - true_mount;
            result.mount_error_deg = Some([e.x, e.y, e.z].map(f64::to_degrees));
        }
        out.push(result);
    }
    Ok(out)
}

fn rms(v: impl Iterator<Item = f64>) -> f64 {
    let (mut s, mut n) = (0.0, 0.0);
    for x in v {
        s += x * x;
        n += 1.0;
    }
    if n > 0.0 { (s / n).sqrt() } else { f64::NAN }
}

/// The alignment study: its options checked, its scenario and models resolved.
pub struct AlignStudy {
    args: AlignOptions,
    scenario: Scenario,
    models: Vec<ErrorModel>,
    mount: Option<[f64; 3]>,
}

impl AlignStudy {
    /// Checks the options and loads the scenario.
    pub fn new(a: &AlignOptions) -> Result<AlignStudy, StudyError> {
        if a.runs == 0 {
            usage!("--runs must be at least 1");
        }
        if !(a.heading_error.is_finite() && a.heading_error.abs() <= 90.0) {
            usage!("--heading-error {}: expected -90..=90 deg", a.heading_error);
        }
        if !(a.seconds.is_finite() && (60.0..=1200.0).contains(&a.seconds)) {
            usage!("--seconds {}: expected 60..=1200", a.seconds);
        }
        let mut models = Vec::new();
        for n in if a.models.is_empty() {
            vec![1, 2, 3]
        } else {
            a.models.clone()
        } {
            let Some(model) = ErrorModel::from_number(n) else {
                usage!("--model {n}: expected 1, 2 or 3")
            };
            models.push(model);
        }
        Ok(AlignStudy {
            scenario: Scenario::load(scenario_name(&a.scenario)?)?,
            mount: parse_mount(&a.mount)?,
            models,
            args: a.clone(),
        })
    }
}

impl crate::runs::RunStudy for AlignStudy {
    type Run = Vec<RunResult>;
    type Report = AlignReport;

    fn runs(&self) -> usize {
        self.args.runs
    }

    fn run(&self, k: usize) -> Result<Vec<RunResult>, StudyError> {
        let seed = self.args.seed.wrapping_add(k as u64);
        run_one(&self.args, &self.scenario, &self.models, self.mount, seed)
            .map_err(|e| StudyError::run(k, e))
    }

    fn report(&self, runs: Vec<Vec<RunResult>>, wall_s: f64) -> Result<AlignReport, StudyError> {
        let a = &self.args;
        if runs.len() != a.runs || runs.iter().any(|r| r.len() != self.models.len()) {
            return Err(StudyError::Results(format!(
                "{} run results for {} runs of {} models",
                runs.len(),
                a.runs,
                self.models.len()
            )));
        }
        let mut reports = Vec::new();
        for (mi, model) in self.models.iter().enumerate() {
            let per = |axis: usize| -> Vec<(f64, f64)> {
                CHECKPOINTS
                    .iter()
                    .enumerate()
                    .filter(|(c, _)| runs.iter().all(|r| r[mi].attitude_error_deg.len() > *c))
                    .map(|(c, t)| {
                        let errors = runs.iter().map(|r| r[mi].attitude_error_deg[c][axis]);
                        (*t, rms(errors))
                    })
                    .collect()
            };
            let mount_error_rms_deg = (model.number() != 3).then(|| {
                [0, 1, 2].map(|i| {
                    rms(runs
                        .iter()
                        .filter_map(|r| r[mi].mount_error_deg.map(|m| m[i])))
                })
            });
            reports.push(ModelReport {
                model: model.number(),
                heading_rms_deg: per(2),
                pitch_rms_deg: per(1),
                roll_rms_deg: per(0),
                position_rms_m: rms(runs.iter().map(|r| r[mi].position_error_m)),
                mount_error_rms_deg,
                not_converged: runs
                    .iter()
                    .filter(|r| {
                        r[mi]
                            .attitude_error_deg
                            .last()
                            .is_none_or(|e| e[2].abs() >= a.converged_deg || e[2].is_nan())
                    })
                    .count(),
            });
        }
        Ok(AlignReport {
            scenario: a.scenario.clone(),
            runs: a.runs,
            seconds: a.seconds,
            heading_error_deg: a.heading_error,
            mount: a.mount.clone(),
            seed: a.seed,
            models: reports,
            per_run: a.per_run.then_some(runs),
            wall_s,
        })
    }
}

/// Runs the Monte Carlo study on this machine's cores.
pub fn run(a: &AlignOptions) -> Result<AlignReport, StudyError> {
    let study = AlignStudy::new(a)?;
    let threads = a.threads.unwrap_or_else(crate::parallel::default_threads);
    let bar = crate::progress::Progress::new(!a.json).runs("alignment Monte Carlo", a.runs);
    crate::runs::run_local(&study, threads, &bar)
}
