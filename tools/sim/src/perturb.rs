//! `auvnav perturb`: applies named simulator effects to the sensor messages of a recorded log
//! (simulated or measured), so that calibration and model discovery can be tested by hiding a
//! known error in real data. The effect names, units and sign conventions are the simulator's
//! (`auvnav sim --list-effects`); the perturbation acts on top of whatever the recording already
//! contains, treating the recorded value as the ideal sensor's:
//!
//! - DVL (`dvl.scale_factor`, `dvl.mount_roll|pitch|yaw`, `dvl.lever_arm`, `dvl.time_offset`,
//!   `dvl.periodic_velocity_error` with its period and phase, `dvl.noise`):
//!   `z'(t) = s C_b^d (z(t - tau) + omega(t - tau) x l) + a sin(2 pi t / P + phi) + noise`, with
//!   the recorded velocity `z` and the IMU angular rate interpolated linearly at `t - tau`. A message whose
//!   `t - tau` has no valid recorded neighbour within three DVL intervals is marked invalid and
//!   counted. The noise is added per velocity axis (the simulator adds it per beam). Recorded beam
//!   velocities no longer match the perturbed velocity and are marked invalid.
//! - IMU (`imu.gyro_bias`, `imu.accel_bias`): constant biases added to every sample (to the
//!   increments times the interval in increment mode).
//! - Depth (`depth.bias`, `depth.noise`).
//! - Compass (`heading.deviation`): the heading of every attitude message (a compass or AHRS)
//!   becomes the one a compass with that deviation shows (the recorded heading taken as true).
//!
//! Other effects (the trajectory-level ones: USBL geometry, magnetometer, GNSS, bias
//! instabilities, and `depth.lever_arm`, which needs the attitude a recorded log does not carry
//! beside its sensors) are rejected with the list of the ones that can be applied. The output log
//! carries the input's header plus notes saying what was applied (`perturb.effects`,
//! `perturb.seed`, `perturb.source`, `perturb.counts`).

use crate::SimError;
use crate::effects::{self, Effects};
use crate::rng::Rng;
use auvnav_log::{LogMessage, LogReader, RawLogMessage, write_log_atomically};
use auvnav_shm_schema::{DepthV1, DvlVelocityV1, ImuSampleV1};
use nalgebra::Vector3;
use serde::Serialize;
use std::path::Path;

/// The effects `perturb` can apply to a recorded log.
pub const APPLICABLE: &[&str] = &[
    "dvl.scale_factor",
    "dvl.mount_roll",
    "dvl.mount_pitch",
    "dvl.mount_yaw",
    "dvl.lever_arm",
    "dvl.time_offset",
    "dvl.noise",
    "dvl.periodic_velocity_error",
    "dvl.periodic_velocity_error_period",
    "dvl.periodic_velocity_error_phase",
    "imu.gyro_bias",
    "imu.accel_bias",
    "depth.bias",
    "depth.noise",
    "heading.deviation",
];

/// What a perturbation did.
#[derive(Debug, Clone, Default, PartialEq, Serialize)]
pub struct PerturbCounts {
    pub messages: u64,
    pub imu_changed: u64,
    pub dvl_changed: u64,
    /// DVL messages marked invalid: no recorded neighbour at `t - dvl.time_offset`.
    pub dvl_invalidated: u64,
    pub depth_changed: u64,
    /// Attitude messages whose heading was given the compass deviation.
    pub attitude_changed: u64,
    /// Messages that could not be decoded (copied unchanged).
    pub undecodable: u64,
}

/// A set of effects to apply, with the seed for the noise.
#[derive(Debug, Clone)]
pub struct Perturbation {
    pub settings: Vec<(String, Vec<f64>)>,
    pub effects: Effects,
    pub seed: u64,
}

impl Perturbation {
    /// Parses `NAME=VALUE` settings, checking names, arity, ranges and applicability.
    pub fn parse(settings: &[String], seed: u64) -> Result<Perturbation, SimError> {
        let mut effects = Effects::default();
        let mut parsed = Vec::new();
        for s in settings {
            let (name, values) = effects::parse_setting(s)?;
            if !APPLICABLE.contains(&name.as_str()) {
                return Err(SimError::Options(format!(
                    "effect {name} cannot be applied to a recorded log; perturb applies: {}",
                    APPLICABLE.join(", ")
                )));
            }
            effects.set(&name, &values)?;
            parsed.push((name, values));
        }
        if parsed.is_empty() {
            return Err(SimError::Options(
                "no effect given (--effect NAME=VALUE; see `auvnav sim --list-effects`)".into(),
            ));
        }
        Ok(Perturbation {
            settings: parsed,
            effects,
            seed,
        })
    }

    /// `name=v1,v2;…` as written into the log header.
    pub fn describe(&self) -> String {
        self.settings
            .iter()
            .map(|(n, v)| {
                let v: Vec<String> = v.iter().map(|x| x.to_string()).collect();
                format!("{n}={}", v.join(","))
            })
            .collect::<Vec<_>>()
            .join(";")
    }
}

/// One DVL epoch of the input: the recorded velocity and the IMU rate at it.
#[derive(Debug, Clone, Copy)]
struct DvlEpoch {
    t: f64,
    valid: bool,
    z: Vector3<f64>,
    omega: Vector3<f64>,
}

/// The recorded velocity and IMU rate at `t` (linear between the two valid epochs around it,
/// at most `max_gap` apart), or `None`.
fn at_time(epochs: &[DvlEpoch], t: f64, max_gap: f64) -> Option<(Vector3<f64>, Vector3<f64>)> {
    let k = epochs.partition_point(|e| e.t <= t);
    let after = epochs.get(k).filter(|e| e.valid);
    let before = k
        .checked_sub(1)
        .and_then(|i| epochs.get(i))
        .filter(|e| e.valid);
    match (before, after) {
        (Some(b), _) if (b.t - t).abs() < 1e-9 => Some((b.z, b.omega)),
        (Some(b), Some(a)) if a.t - b.t <= max_gap => {
            let w = (t - b.t) / (a.t - b.t);
            Some((b.z + (a.z - b.z) * w, b.omega + (a.omega - b.omega) * w))
        }
        _ => None,
    }
}

fn read_all(input: &Path) -> Result<(auvnav_log::LogHeader, Vec<RawLogMessage>), SimError> {
    let failed = |e: auvnav_log::LogError| SimError::Log {
        path: input.to_path_buf(),
        source: e.into(),
    };
    let mut r = LogReader::open(input).map_err(failed)?;
    let header = r.read_header().map_err(failed)?;
    let mut out = Vec::new();
    while let Some(m) = r.next_message().map_err(failed)? {
        out.push(m);
    }
    Ok((header, out))
}

/// Reads `input`, applies `p` and writes `output` atomically.
pub fn perturb_log(
    input: &Path,
    output: &Path,
    p: &Perturbation,
) -> Result<PerturbCounts, SimError> {
    if input == output {
        return Err(SimError::Options(format!(
            "--out must differ from the input log {}",
            input.display()
        )));
    }
    let (mut header, raw) = read_all(input)?;
    let e = &p.effects;
    let mut counts = PerturbCounts::default();

    // Pass 1: the DVL epochs with the IMU rate at each.
    let mut last_rate = Vector3::zeros();
    let mut epochs = Vec::new();
    for m in &raw {
        match m.decode_any() {
            Ok(LogMessage::Imu(x)) => {
                if let Some(w) = x.angular_rate() {
                    last_rate = Vector3::from(w);
                }
            }
            Ok(LogMessage::Dvl(x)) => epochs.push(DvlEpoch {
                t: x.validity_time_ns as f64 * 1e-9,
                valid: x.validity & DvlVelocityV1::VALID_VELOCITY != 0
                    && x.velocity_dvl_m_s.iter().all(|v| v.is_finite()),
                z: Vector3::from(x.velocity_dvl_m_s),
                omega: last_rate,
            }),
            _ => {}
        }
    }
    epochs.sort_by(|a, b| a.t.total_cmp(&b.t));
    let interval = median_interval(&epochs).unwrap_or(1.0);
    // The mounting, lever arm and periodic error as the simulator's DVL has them (its scale, which
    // folds in `dvl.sound_speed`, is not used: perturb applies `dvl.scale_factor` alone).
    let install = crate::sensors::DvlInstallation::from_effects(e);
    let (c_body_to_dvl, lever) = (install.c_body_to_dvl, install.lever_arm);
    let gyro_bias = Vector3::from(e.imu_gyro_bias).map(|b| (b / 3600.0).to_radians());
    let accel_bias = Vector3::from(e.imu_accel_bias) * 9.806_65e-6;
    let touches = |prefix: &str| p.settings.iter().any(|(n, _)| n.starts_with(prefix));
    let (dvl_on, imu_on, depth_on) = (touches("dvl."), touches("imu."), touches("depth."));
    let compass_on = touches("heading.");
    let mut dvl_rng = Rng::new(p.seed, "perturb.dvl");
    let mut depth_rng = Rng::new(p.seed, "perturb.depth");

    header.notes.insert("perturb.effects".into(), p.describe());
    header
        .notes
        .insert("perturb.seed".into(), p.seed.to_string());
    header
        .notes
        .insert("perturb.source".into(), input.display().to_string());
    write_log_atomically(output, &header, |w| {
        for m in &raw {
            counts.messages += 1;
            let decoded = match m.decode_any() {
                Ok(d) => d,
                Err(_) => {
                    counts.undecodable += 1;
                    w.write_raw(m)?;
                    continue;
                }
            };
            match decoded {
                LogMessage::Imu(mut x) if imu_on => {
                    let scale = if x.status & ImuSampleV1::STATUS_INCREMENTS != 0 {
                        x.interval_s
                    } else {
                        1.0
                    };
                    for i in 0..3 {
                        x.angular[i] += gyro_bias[i] * scale;
                        x.specific[i] += accel_bias[i] * scale;
                    }
                    counts.imu_changed += 1;
                    w.write(&m.topic, &x)?;
                }
                LogMessage::Dvl(mut x)
                    if dvl_on && x.validity & DvlVelocityV1::VALID_VELOCITY != 0 =>
                {
                    let stamp = x.validity_time_ns as f64 * 1e-9;
                    match at_time(&epochs, stamp - e.dvl_time_offset, 3.0 * interval) {
                        Some((z, omega)) => {
                            let noise = Vector3::from_fn(|_, _| dvl_rng.gauss(e.dvl_noise));
                            let v = c_body_to_dvl * (z + omega.cross(&lever)) * e.dvl_scale_factor
                                + install.periodic_error(stamp)
                                + noise;
                            x.velocity_dvl_m_s = v.into();
                            counts.dvl_changed += 1;
                        }
                        None => {
                            x.validity &= !DvlVelocityV1::VALID_VELOCITY;
                            counts.dvl_invalidated += 1;
                        }
                    }
                    x.validity &= !(0xf * DvlVelocityV1::VALID_BEAM_VELOCITY);
                    w.write(&m.topic, &x)?;
                }
                LogMessage::Depth(mut x) if depth_on && x.validity & DepthV1::VALID_DEPTH != 0 => {
                    x.depth_m += e.depth_bias + depth_rng.gauss(e.depth_noise);
                    counts.depth_changed += 1;
                    w.write(&m.topic, &x)?;
                }
                LogMessage::Attitude(mut x) if compass_on => {
                    x.euler_rad[2] = auvnav_core::dead_reckoning::compass_reading_rad(
                        x.euler_rad[2],
                        &e.heading_deviation,
                    );
                    counts.attitude_changed += 1;
                    w.write(&m.topic, &x)?;
                }
                _ => w.write_raw(m)?,
            }
        }
        Ok(())
    })
    .map_err(|e| SimError::Output {
        path: output.to_path_buf(),
        source: e.into(),
    })?;
    Ok(counts)
}

fn median_interval(epochs: &[DvlEpoch]) -> Option<f64> {
    let mut d: Vec<f64> = epochs
        .windows(2)
        .map(|w| w[1].t - w[0].t)
        .filter(|d| *d > 0.0)
        .collect();
    if d.is_empty() {
        return None;
    }
    d.sort_by(f64::total_cmp);
    Some(d[d.len() / 2])
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rejects_effects_that_need_the_trajectory() {
        let err = Perturbation::parse(&["usbl.array_yaw=2".into()], 1)
            .expect_err("not applicable")
            .to_string();
        assert!(
            err.contains("cannot be applied") && err.contains("dvl.mount_yaw"),
            "{err}"
        );
        assert!(Perturbation::parse(&[], 1).is_err());
        assert!(Perturbation::parse(&["dvl.scale_factor=3".into()], 1).is_err());
    }

    #[test]
    fn interpolates_between_valid_epochs_only() {
        let e = |t: f64, valid: bool, x: f64| DvlEpoch {
            t,
            valid,
            z: Vector3::new(x, 0.0, 0.0),
            omega: Vector3::zeros(),
        };
        let epochs = [e(0.0, true, 1.0), e(1.0, true, 3.0), e(2.0, false, 9.0)];
        let (z, _) = at_time(&epochs, 0.25, 3.0).expect("inside");
        assert!((z.x - 1.5).abs() < 1e-12);
        assert_eq!(at_time(&epochs, 1.0, 3.0).map(|v| v.0.x), Some(3.0));
        assert!(at_time(&epochs, 1.5, 3.0).is_none(), "next epoch invalid");
        assert!(at_time(&epochs, -0.5, 3.0).is_none(), "before the first");
    }
}
