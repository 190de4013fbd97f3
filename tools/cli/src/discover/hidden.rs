//! Hidden-effect trials: an effect drawn from the vocabulary with a random magnitude (seeded) is
//! hidden in a simulated voyage, discovery runs on it, and the trial records whether the right
//! name came back with its value within 10 %. Null trials hide nothing. The tests run a few; the
//! benchmark (`auvnav bench discover`) runs many and reports the rates and the confusion table.

use super::command::{DiscoverReport, discover, read_logs};
use super::fit::Selection;
use anyhow::Context;
use auvnav_sim::effects::Effects;
use auvnav_sim::rng::Rng;
use auvnav_sim::scenario::Scenario;
use auvnav_sim::{SimConfig, simulate_to_log};
use serde::Serialize;
use std::path::Path;

/// The voyage of the trials: turns, speed and depth changes (what excites the DVL, depth and
/// magnetometer effects), with realistic sensor noise.
pub const SCENARIO: &str = r#"
name = "discovery"
description = "turns, speed and depth changes with sensor noise: the hidden-effect trials"
seabed_depth_m = 80.0

[start]
latitude_deg = 31.0
longitude_deg = 120.0
depth_m = 20.0
heading_deg = 0.0
speed_m_s = 1.5

[[legs]]
kind = "straight"
duration_s = 30.0

[[legs]]
kind = "turn"
angle_deg = 120.0
rate_deg_s = 4.0
bank_deg = 6.0

[[legs]]
kind = "speed"
target_m_s = 2.5
accel_m_s2 = 0.05

[[legs]]
kind = "depth"
change_m = 15.0
pitch_deg = 10.0

[[legs]]
kind = "turn"
angle_deg = -200.0
rate_deg_s = 5.0
bank_deg = -8.0

[[legs]]
kind = "speed"
target_m_s = 1.0
accel_m_s2 = 0.05

[[legs]]
kind = "depth"
change_m = -10.0
pitch_deg = 8.0

[[legs]]
kind = "turn"
angle_deg = 150.0
rate_deg_s = 3.0
bank_deg = 5.0

[[legs]]
kind = "straight"
duration_s = 30.0

[effects]
"dvl.noise" = 0.01
"depth.noise" = 0.05
"mag.noise" = 0.1
"#;

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
];

/// One hidden effect.
#[derive(Debug, Clone, Serialize)]
pub struct Hidden {
    pub name: String,
    pub value: Vec<f64>,
}

/// Draws an effect and its magnitude for trial `seed`.
pub fn draw(seed: u64) -> Hidden {
    let mut rng = Rng::new(seed, "discover.hidden");
    let k = (rng.next_u64() % HIDDEN.len() as u64) as usize;
    let (name, lo, hi) = HIDDEN[k];
    let nominal = Effects::default().get(name).unwrap_or_default();
    let value = nominal
        .iter()
        .map(|x| {
            let m = lo + rng.uniform() * (hi - lo);
            if rng.uniform() < 0.5 { x - m } else { x + m }
        })
        .collect();
    Hidden {
        name: name.into(),
        value,
    }
}

/// What one trial gave.
#[derive(Debug, Clone, Serialize)]
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
}

/// Runs one trial in `dir`: simulate with the hidden effect (or none), discover, score.
pub fn trial(
    seed: u64,
    hidden: Option<Hidden>,
    dir: &Path,
) -> anyhow::Result<(Trial, DiscoverReport)> {
    let scenario = Scenario::parse(SCENARIO, "discovery trials")?;
    let mut effects = scenario.effects()?;
    if let Some(h) = &hidden {
        effects.set(&h.name, &h.value)?;
    }
    let cfg = SimConfig {
        scenario,
        effects,
        seed,
        duration_s: None,
    };
    let log = dir.join(format!("trial-{seed}.mcap"));
    simulate_to_log(&cfg, &log).context("simulating the trial")?;
    let (channels, reference) = read_logs(std::slice::from_ref(&log))?;
    let _ = std::fs::remove_file(&log);
    let report = discover(
        &channels,
        &reference,
        &Effects::default(),
        0.7,
        &Selection::default(),
    );
    let found: Vec<String> = report.effects.iter().map(|e| e.name.clone()).collect();
    let (mut estimate, mut relative_error, mut correct) = (None, None, false);
    if let Some(h) = &hidden
        && let Some(e) = report.effects.iter().find(|e| e.name == h.name)
    {
        let est: Vec<f64> = match &e.value {
            serde_json::Value::Array(a) => {
                a.iter().map(|x| x.as_f64().unwrap_or(f64::NAN)).collect()
            }
            v => vec![v.as_f64().unwrap_or(f64::NAN)],
        };
        let nominal = Effects::default().get(&h.name).unwrap_or_default();
        let err: f64 = est
            .iter()
            .zip(&h.value)
            .map(|(a, b)| (a - b).powi(2))
            .sum::<f64>()
            .sqrt();
        let size: f64 = h
            .value
            .iter()
            .zip(&nominal)
            .map(|(a, b)| (a - b).powi(2))
            .sum::<f64>()
            .sqrt();
        let rel = err / size;
        correct = rel <= 0.1 && found.len() == 1;
        relative_error = Some(rel);
        estimate = Some(est);
    }
    let false_discovery = found
        .iter()
        .any(|n| hidden.as_ref().is_none_or(|h| &h.name != n));
    if hidden.is_none() {
        correct = found.is_empty();
    }
    Ok((
        Trial {
            seed,
            hidden,
            found,
            estimate,
            relative_error,
            correct,
            false_discovery,
        },
        report,
    ))
}
