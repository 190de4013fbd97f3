//! Simulated calibration campaigns: a family of voyages by seed, shaped like a published trial.
//!
//! `scal` is the S-CAL sea trial (../shared/design/SEEDS.md): four straight voyages of 5.8–6.9 km,
//! each starting and ending at the surface with GNSS fixes (3 m), diving to 30 m in between, with a
//! 0.01 deg/h fibre-optic gyro, 10 ug accelerometers and a 0.5 %-class DVL. `scal-turns` is the
//! same with a few turns and speed changes on every voyage, the motion that makes the DVL's
//! mounting pitch and roll, lever arm and time offset visible in the track. The seed draws the
//! headings, lengths, turn angles and the sign of the sensor biases; the installation errors to
//! be found are added by the caller (`--effect`). IMU 100 Hz, DVL 1 Hz, depth 1 Hz, GNSS 1 Hz at
//! the surface, truth 1 Hz.

use crate::effects::Effects;
use crate::rng::Rng;
use crate::scenario::{EffectValue, Leg, Rates, Scenario, Start};
use crate::{SimConfig, SimError};
use std::collections::BTreeMap;

/// The campaign families.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum CampaignKind {
    /// Four straight voyages (the S-CAL trial).
    Scal,
    /// Four voyages with turns and speed changes.
    ScalTurns,
}

impl CampaignKind {
    pub const NAMES: &[&str] = &["scal", "scal-turns"];

    pub fn parse(name: &str) -> Result<CampaignKind, SimError> {
        match name {
            "scal" => Ok(CampaignKind::Scal),
            "scal-turns" => Ok(CampaignKind::ScalTurns),
            _ => Err(SimError::Options(format!(
                "unknown campaign {name:?}; known: {}",
                CampaignKind::NAMES.join(", ")
            ))),
        }
    }

    pub fn name(self) -> &'static str {
        match self {
            CampaignKind::Scal => "scal",
            CampaignKind::ScalTurns => "scal-turns",
        }
    }
}

/// Cruise speed (m/s).
const SPEED: f64 = 2.5;
/// Dive depth (m).
const DEPTH: f64 = 30.0;
/// Time at the surface before the dive and after surfacing (s).
const SURFACE_S: f64 = 60.0;

/// The sensor suite of the trial, with bias signs drawn from `rng`.
fn sensor_effects(rng: &mut Rng) -> BTreeMap<String, EffectValue> {
    let mut sign = || if rng.uniform() < 0.5 { -1.0 } else { 1.0 };
    let gyro = [0.01 * sign(), 0.01 * sign(), 0.01 * sign()];
    let accel = [10.0 * sign(), 10.0 * sign(), 10.0 * sign()];
    let mut e = BTreeMap::new();
    e.insert("imu.gyro_bias".into(), EffectValue::Vector(gyro.to_vec()));
    e.insert(
        "imu.gyro_bias_instability".into(),
        EffectValue::Scalar(0.003),
    );
    e.insert("imu.angle_random_walk".into(), EffectValue::Scalar(0.002));
    e.insert("imu.accel_bias".into(), EffectValue::Vector(accel.to_vec()));
    e.insert(
        "imu.accel_bias_instability".into(),
        EffectValue::Scalar(2.0),
    );
    e.insert(
        "imu.velocity_random_walk".into(),
        EffectValue::Scalar(0.0005),
    );
    e.insert("dvl.noise".into(), EffectValue::Scalar(0.01));
    e.insert("depth.noise".into(), EffectValue::Scalar(0.05));
    e.insert("gnss.noise".into(), EffectValue::Scalar(3.0));
    e
}

/// The legs of one voyage of about `length_m` metres.
fn legs(kind: CampaignKind, length_m: f64, rng: &mut Rng) -> Vec<Leg> {
    let straight = |d: f64| Leg::Straight {
        duration_s: d.max(1.0),
    };
    // The dive and the ascent (pitch 10 deg) cover about 170 m each.
    let dive = Leg::Depth {
        change_m: DEPTH,
        pitch_deg: 10.0,
    };
    let ascent = Leg::Depth {
        change_m: -DEPTH,
        pitch_deg: 10.0,
    };
    let underway = length_m - 2.0 * SURFACE_S * SPEED - 2.0 * 170.0;
    let mut out = vec![straight(SURFACE_S), dive];
    match kind {
        CampaignKind::Scal => out.push(straight(underway / SPEED)),
        CampaignKind::ScalTurns => {
            let a1 = 45.0 + 75.0 * rng.uniform();
            let a2 = -(45.0 + 75.0 * rng.uniform());
            let turn = |angle: f64| Leg::Turn {
                angle_deg: angle,
                rate_deg_s: 3.0,
                bank_deg: 8.0 * angle.signum(),
            };
            // Turns at 3 deg/s cover speed * angle / rate metres; one slow stretch at 1.5 m/s.
            let turning = (a1.abs() + a2.abs()) / 3.0 * SPEED;
            let slow = 400.0;
            let rest = (underway - turning - slow).max(300.0);
            out.extend([
                straight(0.3 * rest / SPEED),
                turn(a1),
                straight(0.2 * rest / SPEED),
                Leg::Speed {
                    target_m_s: 1.5,
                    accel_m_s2: 0.05,
                },
                straight(slow / 1.5),
                Leg::Speed {
                    target_m_s: SPEED,
                    accel_m_s2: 0.05,
                },
                turn(a2),
                straight(0.5 * rest / SPEED),
            ]);
        }
    }
    out.extend([ascent, straight(SURFACE_S)]);
    out
}

/// The campaign's voyages for `seed`, with `installation` (effects such as `dvl.mount_yaw`) added
/// to every voyage's sensor effects.
pub fn campaign(
    kind: CampaignKind,
    seed: u64,
    installation: &[(String, Vec<f64>)],
) -> Result<Vec<SimConfig>, SimError> {
    let mut rng = Rng::new(seed, "campaign");
    let mut effects_table = sensor_effects(&mut rng);
    for (name, v) in installation {
        let value = if v.len() == 1 {
            EffectValue::Scalar(v[0])
        } else {
            EffectValue::Vector(v.clone())
        };
        effects_table.insert(name.clone(), value);
    }
    let mut out = Vec::new();
    for i in 0..4 {
        let length_m = 5800.0 + 1100.0 * rng.uniform();
        let heading_deg = 360.0 * rng.uniform();
        let scenario = Scenario {
            name: format!("{}-{}", kind.name(), i + 1),
            description: format!(
                "{} campaign voyage {} of 4 (seed {seed}): about {:.0} m from the surface, 30 m deep, back to the surface",
                kind.name(),
                i + 1,
                length_m
            ),
            start: Start {
                latitude_deg: 31.0 + 0.05 * i as f64,
                longitude_deg: 120.0,
                depth_m: 0.0,
                heading_deg,
                speed_m_s: SPEED,
            },
            rates: Rates {
                imu_hz: 100,
                dvl_hz: 1,
                usbl_hz: 0,
                depth_hz: 1,
                magnetometer_hz: 0,
                gnss_hz: 1,
                truth_hz: 1,
                ctd_hz: 0,
                compass_hz: 0,
            },
            legs: legs(kind, length_m, &mut rng),
            station: None,
            acoustic: None,
            seabed_depth_m: 100.0,
            effects: effects_table.clone(),
        };
        scenario.validate()?;
        let effects: Effects = scenario.effects()?;
        out.push(SimConfig {
            scenario,
            effects,
            seed: seed.wrapping_mul(16).wrapping_add(i),
            duration_s: None,
        });
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn campaigns_are_valid_and_depend_on_the_seed() {
        for kind in [CampaignKind::Scal, CampaignKind::ScalTurns] {
            let a = campaign(kind, 1, &[]).expect("campaign");
            let b = campaign(kind, 2, &[]).expect("campaign");
            assert_eq!(a.len(), 4);
            assert_ne!(
                a[0].scenario.start.heading_deg,
                b[0].scenario.start.heading_deg
            );
            let again = campaign(kind, 1, &[]).expect("campaign");
            assert_eq!(a[3].scenario, again[3].scenario);
        }
        let err = campaign(
            CampaignKind::Scal,
            1,
            &[("dvl.mount_yaw".into(), vec![500.0])],
        )
        .expect_err("out of range");
        assert!(err.to_string().contains("dvl.mount_yaw"), "{err}");
    }
}
