//! Hidden-effect trials: an effect drawn from the vocabulary with a random magnitude (seeded) is
//! hidden in a simulated voyage, discovery runs on it, and the trial records whether the right
//! name came back with its value within 10 %. Null trials hide nothing. The tests run a few; the
//! benchmark (`auvnav bench discover`) runs many and reports the rates and the confusion table.

use super::analysis::{DiscoverReport, discover, read_logs, values_of};
use super::fit::Selection;
use anyhow::Context;
use auvnav_sim::effects::Effects;
use auvnav_sim::rng::Rng;
use auvnav_sim::scenario::Scenario;
use auvnav_sim::{SimConfig, simulate_to_log};
use serde::Serialize;
use std::path::Path;

/// The voyage of trial `seed`: turns, speed and depth changes (what excites the DVL, depth and
/// magnetometer effects) in a fixed order, with their angles, rates, banks, speeds and depths
/// drawn per seed, and realistic sensor noise.
pub fn scenario(seed: u64) -> String {
    let mut rng = Rng::new(seed, "discover.trajectory");
    let mut u = |lo: f64, hi: f64| lo + rng.uniform() * (hi - lo);
    let sign = |x: f64, s: f64| if s < 0.5 { -x } else { x };
    let mut legs = String::new();
    let turn = |legs: &mut String, u: &mut dyn FnMut(f64, f64) -> f64| {
        let s = u(0.0, 1.0);
        legs.push_str(&format!(
            "[[legs]]\nkind = \"turn\"\nangle_deg = {}\nrate_deg_s = {}\nbank_deg = {}\n\n",
            sign(u(90.0, 220.0), s),
            u(2.0, 6.0),
            sign(u(3.0, 10.0), s)
        ));
    };
    legs.push_str(&format!(
        "[[legs]]\nkind = \"straight\"\nduration_s = {}\n\n",
        u(20.0, 40.0)
    ));
    turn(&mut legs, &mut u);
    legs.push_str(&format!(
        "[[legs]]\nkind = \"speed\"\ntarget_m_s = {}\naccel_m_s2 = {}\n\n",
        u(2.0, 2.8),
        u(0.03, 0.08)
    ));
    legs.push_str(&format!(
        "[[legs]]\nkind = \"depth\"\nchange_m = {}\npitch_deg = {}\n\n",
        u(5.0, 15.0),
        u(6.0, 12.0)
    ));
    turn(&mut legs, &mut u);
    legs.push_str(&format!(
        "[[legs]]\nkind = \"speed\"\ntarget_m_s = {}\naccel_m_s2 = {}\n\n",
        u(0.8, 1.4),
        u(0.03, 0.08)
    ));
    legs.push_str(&format!(
        "[[legs]]\nkind = \"depth\"\nchange_m = {}\npitch_deg = {}\n\n",
        -u(4.0, 10.0),
        u(6.0, 12.0)
    ));
    turn(&mut legs, &mut u);
    legs.push_str(&format!(
        "[[legs]]\nkind = \"straight\"\nduration_s = {}\n\n",
        u(20.0, 40.0)
    ));
    format!(
        "name = \"discovery\"\n\
         description = \"turns, speed and depth changes with sensor noise: hidden-effect trial\"\n\
         seabed_depth_m = 80.0\n\n\
         [start]\nlatitude_deg = {}\nlongitude_deg = {}\ndepth_m = {}\nheading_deg = {}\nspeed_m_s = {}\n\n\
         {legs}\
         [effects]\n\"dvl.noise\" = 0.01\n\"depth.noise\" = 0.05\n\"mag.noise\" = 0.1\n\
         \"imu.angle_random_walk\" = 0.01\n\"imu.velocity_random_walk\" = 0.01\n",
        u(-60.0, 60.0),
        u(-180.0, 180.0),
        u(20.0, 30.0),
        u(0.0, 360.0),
        u(1.2, 1.8),
    )
}

/// Effects the trials hide, with the magnitude range drawn from (per component, either sign, as
/// an offset from the nominal value). `dvl.mount_roll` is left out: with the velocity along the
/// body x axis (no sideslip, no heave) a roll of the DVL changes its reading only to second
/// order, and discovery reports it as not excited.
pub const HIDDEN: &[(&str, f64, f64)] = &[
    ("dvl.scale_factor", 0.003, 0.01),
    ("dvl.mount_pitch", 0.5, 3.0),
    ("dvl.mount_yaw", 0.5, 3.0),
    ("dvl.lever_arm", 0.3, 1.0),
    ("dvl.time_offset", 0.2, 0.5),
    ("depth.bias", 0.2, 1.0),
    ("depth.density", 8.0, 20.0),
    ("mag.hard_iron", 2.0, 20.0),
    ("mag.declination", 1.0, 10.0),
    ("mag.inclination", 1.0, 5.0),
    ("mag.intensity", 1.0, 5.0),
    ("imu.gyro_bias", 2.0, 20.0),
    ("imu.accel_bias", 200.0, 2000.0),
    ("imu.gyro_scale_factor", 500.0, 5000.0),
    ("imu.accel_scale_factor", 500.0, 5000.0),
    ("imu.gyro_misalignment", 0.5, 3.0),
    ("imu.accel_misalignment", 0.5, 3.0),
    ("dvl.periodic_velocity_error", 0.005, 0.02),
];

/// Period range (s) of a hidden `dvl.periodic_velocity_error`: at least four cycles on the
/// shortest trial voyage (about 290 s), and well above its DVL's rate.
pub const PERIODIC_PERIOD_S: (f64, f64) = (6.0, 60.0);

/// One hidden effect.
#[derive(Debug, Clone, Serialize, serde::Deserialize)]
pub struct Hidden {
    pub name: String,
    pub value: Vec<f64>,
    /// Settings the effect needs beside its value that are not estimated as effects of their own:
    /// the periodic DVL error's period and phase. Always written (a trial's result travels
    /// between processes in postcard, which has no field names to skip by).
    #[serde(default)]
    pub with: Vec<(String, Vec<f64>)>,
}

impl Hidden {
    /// An effect hidden at `value`, with nothing beside it.
    pub fn new(name: &str, value: Vec<f64>) -> Hidden {
        Hidden {
            name: name.into(),
            value,
            with: Vec::new(),
        }
    }
}

/// Draws an effect and its magnitude for trial `seed`.
pub fn draw(seed: u64) -> Hidden {
    let mut rng = Rng::new(seed, "discover.hidden");
    let k = (rng.next_u64() % HIDDEN.len() as u64) as usize;
    magnitude(&mut rng, k)
}

/// Draws a magnitude of effect `HIDDEN[k]` for trial `seed`.
pub fn draw_of(seed: u64, k: usize) -> Hidden {
    magnitude(&mut Rng::new(seed, "discover.hidden.of"), k % HIDDEN.len())
}

fn magnitude(rng: &mut Rng, k: usize) -> Hidden {
    let (name, lo, hi) = HIDDEN[k];
    let nominal = Effects::default().get(name).unwrap_or_default();
    let value = nominal
        .iter()
        .map(|x| {
            let m = lo + rng.uniform() * (hi - lo);
            if rng.uniform() < 0.5 { x - m } else { x + m }
        })
        .collect();
    let with = if name == "dvl.periodic_velocity_error" {
        let (lo, hi) = PERIODIC_PERIOD_S;
        let period = lo + rng.uniform() * (hi - lo);
        let phase = -180.0 + 360.0 * rng.uniform();
        vec![
            ("dvl.periodic_velocity_error_period".into(), vec![period]),
            ("dvl.periodic_velocity_error_phase".into(), vec![phase]),
        ]
    } else {
        Vec::new()
    };
    Hidden {
        name: name.into(),
        value,
        with,
    }
}

/// Two different effects for trial `seed`, each with a magnitude drawn as in [`draw`].
pub fn draw_pair(seed: u64) -> [Hidden; 2] {
    let first = draw(seed);
    let mut k = 0;
    loop {
        let second = draw(seed.wrapping_mul(7919).wrapping_add(1_000_003 + k));
        if second.name != first.name {
            return [first, second];
        }
        k += 1;
    }
}

/// `h` with its offset from the nominal value scaled by `fraction` (for the detection floor).
pub fn scaled(h: &Hidden, fraction: f64) -> Hidden {
    let nominal = Effects::default().get(&h.name).unwrap_or_default();
    Hidden {
        name: h.name.clone(),
        value: h
            .value
            .iter()
            .zip(&nominal)
            .map(|(v, n)| n + (v - n) * fraction)
            .collect(),
        with: h.with.clone(),
    }
}

/// What a trial with several hidden effects gave.
#[derive(Debug, Clone, Serialize)]
pub struct SetTrial {
    pub seed: u64,
    pub hidden: Vec<Hidden>,
    /// Names discovery reported, in order.
    pub found: Vec<String>,
    /// Per hidden effect: its estimate and |estimate − hidden| / |hidden − nominal| when found.
    pub estimates: Vec<Option<Vec<f64>>>,
    pub relative_errors: Vec<Option<f64>>,
    /// Every hidden effect named with its value within 10 %, and nothing else.
    pub correct: bool,
    /// Some effect reported that was not hidden.
    pub false_discovery: bool,
    /// Every hidden effect named (whatever its value), and nothing else.
    pub named_right: bool,
    /// Per hidden effect that was not named: what the report says of it at the hidden size
    /// ([`Miss`]); None where it was named.
    pub misses: Vec<Option<Miss>>,
    /// Per hidden effect not named: its size over the report's detection floor (the largest
    /// over the excited components; a miss at 1.0–1.4 is the test's chance near its floor, far
    /// above it a floor that promised too much).
    pub sizes_over_floor: Vec<Option<f64>>,
    /// Per hidden effect named: its estimate within three of its reported standard deviations
    /// of the hidden value, on every component the motion determines.
    pub within_3_sigma: Vec<Option<bool>>,
}

/// How a report accounts for a hidden effect it does not name.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Miss {
    /// The report says the motion does not excite it.
    NotExcited,
    /// The report's detection floor is above the hidden size on every excited component.
    BelowTheFloor,
    /// Several voyages disagree on it beyond their uncertainties (reported as inconsistent).
    Inconsistent,
    /// Above the floor, not named, but listed as pointed at without being determined (the
    /// residual's correlation, or the voyages' scatter, widened its deviation below the test).
    Undetermined,
    /// The report's floor says an effect of the hidden size would have been named, yet it was
    /// not: a miss the report does not account for.
    Silent,
}

/// What `report` says of the hidden effect `h` it did not name: an effect several voyages
/// disagree on is reported as such; otherwise its detection floors against the hidden departure
/// from nominal (over several voyages, the voyages' floors combined as their information adds).
fn miss_of(h: &Hidden, report: &DiscoverReport) -> (Miss, Option<f64>) {
    if let Some(v) = &report.voyages
        && v.inconsistent.iter().any(|e| e.name == h.name)
    {
        return (Miss::Inconsistent, None);
    }
    let nominal = Effects::default().get(&h.name).unwrap_or_default();
    let floors = match &report.voyages {
        Some(v) => {
            let each: Vec<Vec<Option<f64>>> =
                v.voyages.iter().map(|r| floors_of(&h.name, r)).collect();
            (0..nominal.len())
                .map(|i| {
                    let info: f64 = each
                        .iter()
                        .filter_map(|f| f.get(i).copied().flatten())
                        .map(|f| 1.0 / (f * f))
                        .sum();
                    (info > 0.0).then(|| 1.0 / info.sqrt())
                })
                .collect()
        }
        None => floors_of(&h.name, report),
    };
    let ratio = size_over_floor(h, &nominal, &floors);
    let miss = match ratio {
        None => Miss::NotExcited,
        Some(x) if x >= 1.0 && report.undetermined.iter().any(|u| u.name == h.name) => {
            Miss::Undetermined
        }
        Some(x) if x >= 1.0 => Miss::Silent,
        Some(_) => Miss::BelowTheFloor,
    };
    (miss, ratio)
}

/// The hidden departure from nominal over the detection floor, the largest over the excited
/// components (None where none is excited). The floor is the size whose expected estimate
/// stands at the test's threshold: one just above it is named about half of the time.
fn size_over_floor(h: &Hidden, nominal: &[f64], floors: &[Option<f64>]) -> Option<f64> {
    floors
        .iter()
        .enumerate()
        .filter_map(|(i, f)| {
            let offset = (h.value.get(i).copied().unwrap_or(0.0)
                - nominal.get(i).copied().unwrap_or(0.0))
            .abs();
            f.filter(|f| *f > 0.0).map(|f| offset / f)
        })
        .reduce(f64::max)
}

/// Per component, the smallest detection floor `report` gives effect `name` over its channels
/// (None where no channel's motion excites the component).
fn floors_of(name: &str, report: &DiscoverReport) -> Vec<Option<f64>> {
    let mut out: Vec<Option<f64>> = Vec::new();
    for f in report.floors.iter().filter(|f| f.name == name) {
        if out.len() < f.floor.len() {
            out.resize(f.floor.len(), None);
        }
        for (o, x) in out.iter_mut().zip(&f.floor) {
            if let Some(x) = x {
                *o = Some(o.map_or(*x, |v| v.min(*x)));
            }
        }
    }
    out
}

/// Names a noise setting puts into the data without their being hidden: a slowly drifting IMU
/// bias has, over one voyage, a mean that is a bias like any other (a per-voyage effect), so
/// naming it is describing the data, not a false discovery.
pub fn realised_by(noise: &[(String, Vec<f64>)]) -> Vec<String> {
    let on = |name: &str| {
        noise
            .iter()
            .any(|(n, v)| n == name && v.iter().any(|x| *x != 0.0))
    };
    let mut out = Vec::new();
    if on("imu.gyro_bias_instability") {
        out.push("imu.gyro_bias".to_string());
    }
    if on("imu.accel_bias_instability") {
        out.push("imu.accel_bias".to_string());
    }
    out
}

/// Coloured noise for trial `seed`, on top of the trial's white noise: a Gauss–Markov DVL
/// velocity error (instability 5–15 mm/s per axis, correlation time 30–120 s, drawn per seed) —
/// the slowly varying disagreement between a DVL and the vehicle's motion that measured logs show
/// and white-noise trials do not — and a slowly drifting IMU bias (Gauss–Markov, gyro 0.5–5
/// deg/h and accelerometer 20–200 µg per axis, correlation time 120–900 s), which makes the
/// gyro and accelerometer residuals coloured the same way.
pub fn coloured(seed: u64) -> Vec<(String, Vec<f64>)> {
    let mut rng = Rng::new(seed, "discover.coloured");
    let instability = 0.005 + 0.01 * rng.uniform();
    let tau = 30.0 + 90.0 * rng.uniform();
    let gyro = 0.5 + 4.5 * rng.uniform();
    let accel = 20.0 + 180.0 * rng.uniform();
    let bias_tau = 120.0 + 780.0 * rng.uniform();
    vec![
        ("dvl.velocity_error_instability".into(), vec![instability]),
        ("dvl.velocity_error_correlation_time".into(), vec![tau]),
        ("imu.gyro_bias_instability".into(), vec![gyro]),
        ("imu.accel_bias_instability".into(), vec![accel]),
        ("imu.bias_correlation_time".into(), vec![bias_tau]),
    ]
}

/// Runs one trial with the effects `hidden` (none: a null trial) in `dir`.
pub fn trial_set(
    seed: u64,
    hidden: &[Hidden],
    dir: &Path,
) -> anyhow::Result<(SetTrial, DiscoverReport)> {
    trial_set_with(seed, hidden, &[], dir)
}

/// [`trial_set`] with further noise settings (e.g. [`coloured`]) that are not effects to find.
pub fn trial_set_with(
    seed: u64,
    hidden: &[Hidden],
    noise: &[(String, Vec<f64>)],
    dir: &Path,
) -> anyhow::Result<(SetTrial, DiscoverReport)> {
    let mut settings: Vec<(String, Vec<f64>)> = noise.to_vec();
    for h in hidden {
        settings.push((h.name.clone(), h.value.clone()));
        settings.extend(h.with.iter().cloned());
    }
    let log = simulate(seed, &settings, dir)?;
    let read = read_logs(std::slice::from_ref(&log));
    let _ = std::fs::remove_file(&log);
    let (channels, reference, _) = read?;
    let report = discover(
        &channels,
        &reference,
        &Effects::default(),
        0.7,
        &Selection::default(),
    );
    let found: Vec<String> = report.effects.iter().map(|e| e.name.clone()).collect();
    Ok((
        score(seed, hidden, found, &realised_by(noise), &report),
        report,
    ))
}

/// What one trial gave.
#[derive(Debug, Clone, Serialize, serde::Deserialize)]
pub struct Trial {
    pub seed: u64,
    /// None for a null trial.
    pub hidden: Option<Hidden>,
    /// Names discovery reported, in order.
    pub found: Vec<String>,
    /// The hidden effect's estimate, when found.
    pub estimate: Option<Vec<f64>>,
    /// |estimate − hidden| / |hidden − nominal| (vector norms).
    pub relative_error: Option<f64>,
    /// Right name, value within 10 %, nothing else found.
    pub correct: bool,
    /// Some effect reported that was not hidden.
    pub false_discovery: bool,
    /// What the report says of the hidden effect when it does not name it.
    #[serde(default)]
    pub miss: Option<Miss>,
}

/// Simulates the voyage of trial `seed` with its scenario's noise and `settings` on top, into
/// `dir/trial-SEED.mcap`.
pub fn simulate(
    seed: u64,
    settings: &[(String, Vec<f64>)],
    dir: &Path,
) -> anyhow::Result<std::path::PathBuf> {
    let scenario = Scenario::parse(&scenario(seed), "discovery trial")?;
    let mut effects = scenario.effects()?;
    auvnav_sim::effects::set::apply(&mut effects, settings)?;
    let cfg = SimConfig {
        scenario,
        effects,
        seed,
        duration_s: None,
    };
    let log = dir.join(format!("trial-{seed}.mcap"));
    simulate_to_log(&cfg, &log).context("simulating the trial")?;
    Ok(log)
}

/// Runs one trial in `dir`: simulate with the hidden effect (or none), discover, score.
pub fn trial(
    seed: u64,
    hidden: Option<Hidden>,
    dir: &Path,
) -> anyhow::Result<(Trial, DiscoverReport)> {
    let (t, report) = trial_set(seed, hidden.as_slice(), dir)?;
    Ok((
        Trial {
            seed,
            estimate: t.estimates.first().cloned().flatten(),
            relative_error: t.relative_errors.first().copied().flatten(),
            hidden,
            found: t.found,
            correct: t.correct,
            false_discovery: t.false_discovery,
            miss: t.misses.first().copied().flatten(),
        },
        report,
    ))
}

/// Installation effects of [`HIDDEN`] (shared by a vehicle's voyages; see
/// `voyages::per_voyage`), for the trials over several voyages.
pub fn installation_effects() -> Vec<usize> {
    (0..HIDDEN.len())
        .filter(|&k| !super::voyages::per_voyage(HIDDEN[k].0))
        .collect()
}

/// A trial over `voyages` voyages of the same vehicle (trajectories and noise of seeds
/// `seed × 16 + i`), each with its own coloured DVL noise ([`coloured`]) and the same hidden
/// installation (none: a null trial), discovered together as voyages. Correct: every hidden
/// effect named as shared within 10 %, and nothing else named (shared or per voyage).
pub fn trial_voyages(
    seed: u64,
    hidden: &[Hidden],
    voyages: usize,
    dir: &Path,
) -> anyhow::Result<SetTrial> {
    let settings: Vec<(String, Vec<f64>)> = hidden
        .iter()
        .flat_map(|h| std::iter::once((h.name.clone(), h.value.clone())).chain(h.with.clone()))
        .collect();
    let mut data = Vec::with_capacity(voyages);
    let mut realised = Vec::new();
    for i in 0..voyages {
        let s = seed * 16 + i as u64;
        let mut all = coloured(s);
        for name in realised_by(&all) {
            if !realised.contains(&name) {
                realised.push(name.clone());
                realised.push(format!("{name} (per voyage)"));
            }
        }
        all.extend(settings.iter().cloned());
        let log = simulate(s, &all, dir)?;
        let read = read_logs(std::slice::from_ref(&log));
        let _ = std::fs::remove_file(&log);
        let (channels, reference, _) = read?;
        data.push(super::voyages::VoyageData {
            log: format!("voyage {}", i + 1),
            channels,
            reference,
        });
    }
    let report =
        super::voyages::discover_voyages(&data, &Effects::default(), 0.7, &Selection::default());
    let mut found: Vec<String> = report.effects.iter().map(|e| e.name.clone()).collect();
    if let Some(v) = &report.voyages {
        for p in &v.per_voyage {
            found.push(format!("{} (per voyage)", p.name));
        }
    }
    Ok(score(seed, hidden, found, &realised, &report))
}

/// A trial's score: each hidden effect's estimate and relative error |estimate − hidden| /
/// |hidden − nominal| (vector norms) where `report` names it, or what the report says of it
/// where it does not; correct when every hidden effect is named within 10 % and nothing else is
/// in `found` but the names in `realised` (what the trial's noise put into the data).
pub(crate) fn score(
    seed: u64,
    hidden: &[Hidden],
    found: Vec<String>,
    realised: &[String],
    report: &DiscoverReport,
) -> SetTrial {
    let norm = |a: &[f64], b: &[f64]| -> f64 {
        a.iter()
            .zip(b)
            .map(|(x, y)| (x - y).powi(2))
            .sum::<f64>()
            .sqrt()
    };
    let (mut estimates, mut relative_errors) = (Vec::new(), Vec::new());
    let (mut misses, mut within_3_sigma, mut sizes) = (Vec::new(), Vec::new(), Vec::new());
    for h in hidden {
        match report.effects.iter().find(|e| e.name == h.name) {
            Some(e) => {
                // A component that is not a number makes the error NaN: not correct.
                let mut est = values_of(&e.value).unwrap_or_else(|| vec![f64::NAN; h.value.len()]);
                // A periodic error is compared at the hidden phase's sign (±a at φ, φ + 180°).
                let hidden_phase = h
                    .with
                    .iter()
                    .find(|(n, _)| n == "dvl.periodic_velocity_error_phase")
                    .and_then(|(_, v)| v.first().copied());
                if let (Some(line), Some(phase)) = (e.line, hidden_phase) {
                    est = super::periodic::amplitudes_near_phase(&est, line.phase_deg, phase);
                }
                let nominal = Effects::default().get(&h.name).unwrap_or_default();
                relative_errors.push(Some(norm(&est, &h.value) / norm(&h.value, &nominal)));
                within_3_sigma.push(Some(covers(&est, &e.std, &h.value)));
                estimates.push(Some(est));
                misses.push(None);
                sizes.push(None);
            }
            None => {
                relative_errors.push(None);
                estimates.push(None);
                within_3_sigma.push(None);
                let (miss, size) = miss_of(h, report);
                misses.push(Some(miss));
                sizes.push(size);
            }
        }
    }
    let hidden_name = |n: &String| hidden.iter().any(|h| &h.name == n);
    let false_discovery = found
        .iter()
        .any(|n| !hidden_name(n) && !realised.contains(n));
    let all_named = hidden.iter().all(|h| found.contains(&h.name));
    let correct = !false_discovery
        && all_named
        && relative_errors.iter().all(|r| r.is_some_and(|r| r <= 0.1));
    SetTrial {
        seed,
        hidden: hidden.to_vec(),
        found,
        estimates,
        relative_errors,
        correct,
        false_discovery,
        named_right: !false_discovery && all_named,
        misses,
        sizes_over_floor: sizes,
        within_3_sigma,
    }
}

/// The estimate `est` within three of its standard deviations `std` (a number or an array,
/// null where the motion does not determine a component) of `hidden` on every component the
/// motion determines.
fn covers(est: &[f64], std: &serde_json::Value, hidden: &[f64]) -> bool {
    let stds = super::findings::components_of(std);
    est.iter()
        .zip(hidden)
        .zip(&stds)
        .all(|((e, h), s)| s.is_none_or(|s| (e - h).abs() <= 3.0 * s))
}
