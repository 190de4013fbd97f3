//! `auvnav perturb`: applies named simulator effects to the sensor messages of a recorded log
//! (simulated or measured), so that calibration and model discovery can be tested by hiding a
//! known error in real data. The effect names, units and sign conventions are the simulator's
//! (`auvnav sim --list-effects`); the perturbation acts on top of whatever the recording already
//! contains, treating the recorded value as the ideal sensor's:
//!
//! - DVL (`dvl.scale_factor`, `dvl.mount_roll|pitch|yaw`, `dvl.lever_arm`, `dvl.time_offset`,
//!   `dvl.periodic_velocity_error` with its period and phase, `dvl.noise`): a reading recorded at
//!   `t` with velocity `z` becomes one stamped `t + tau` with
//!   `z' = s C_b^d (z + omega x l) + a sin(2 pi (t + tau) / P + phi) + noise`, the IMU angular rate
//!   `omega` the last one recorded before the reading. The time offset moves the reading (its
//!   host, validity and device times) rather than interpolating the recorded velocities at
//!   `t - tau`: the result is what a DVL late by `tau` records, with the recorded motion and noise
//!   untouched (interpolating a 1 Hz DVL smoothed both), and the messages are written in the order
//!   of their new times. A reading moved before time zero is left out and counted. The noise is
//!   added per velocity axis (the simulator adds it per beam). Recorded beam velocities no longer
//!   match a changed velocity and are marked invalid (a time offset alone keeps them).
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
use auvnav_shm_schema::{AttitudeV1, DepthV1, DvlVelocityV1, ImuSampleV1};
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
    /// DVL messages moved by `dvl.time_offset` (every DVL message, valid or not, when it is set).
    pub dvl_restamped: u64,
    /// DVL messages left out: `dvl.time_offset` moved them before time zero.
    pub dvl_dropped: u64,
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
    // A time offset moves the DVL's readings in time, so the output is put in time order before
    // it is written (a 1 Hz DVL moved by a second passes other sensors' messages).
    let tau_ns = (e.dvl_time_offset * 1e9).round() as i64;
    let restamp = tau_ns != 0;
    let velocity_changed = p
        .settings
        .iter()
        .any(|(n, _)| n.starts_with("dvl.") && n != "dvl.time_offset");
    let mut last_rate = Vector3::zeros();
    let mut out: Vec<(u64, Out)> = Vec::with_capacity(raw.len());
    for m in &raw {
        counts.messages += 1;
        let decoded = match m.decode_any() {
            Ok(d) => d,
            Err(_) => {
                counts.undecodable += 1;
                out.push((m.log_time_ns, Out::Raw(m)));
                continue;
            }
        };
        if let LogMessage::Imu(x) = &decoded
            && let Some(w) = x.angular_rate()
        {
            last_rate = Vector3::from(w);
        }
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
                out.push((m.log_time_ns, Out::Imu(m, x)));
            }
            LogMessage::Dvl(mut x) if dvl_on => {
                if restamp {
                    let moved = |t: u64| t.checked_add_signed(tau_ns);
                    let (Some(host), Some(validity)) =
                        (moved(x.host_time_ns), moved(x.validity_time_ns))
                    else {
                        counts.dvl_dropped += 1;
                        continue;
                    };
                    x.host_time_ns = host;
                    x.validity_time_ns = validity;
                    if x.device_time_ns != 0 {
                        x.device_time_ns = moved(x.device_time_ns).unwrap_or(0);
                    }
                    counts.dvl_restamped += 1;
                }
                if velocity_changed && x.validity & DvlVelocityV1::VALID_VELOCITY != 0 {
                    let stamp = x.validity_time_ns as f64 * 1e-9;
                    let z = Vector3::from(x.velocity_dvl_m_s);
                    let noise = Vector3::from_fn(|_, _| dvl_rng.gauss(e.dvl_noise));
                    let v = c_body_to_dvl * (z + last_rate.cross(&lever)) * e.dvl_scale_factor
                        + install.periodic_error(stamp)
                        + noise;
                    x.velocity_dvl_m_s = v.into();
                    x.validity &= !(0xf * DvlVelocityV1::VALID_BEAM_VELOCITY);
                    counts.dvl_changed += 1;
                }
                out.push((x.host_time_ns, Out::Dvl(m, x)));
            }
            LogMessage::Depth(mut x) if depth_on && x.validity & DepthV1::VALID_DEPTH != 0 => {
                x.depth_m += e.depth_bias + depth_rng.gauss(e.depth_noise);
                counts.depth_changed += 1;
                out.push((m.log_time_ns, Out::Depth(m, x)));
            }
            LogMessage::Attitude(mut x) if compass_on => {
                x.euler_rad[2] = auvnav_core::dead_reckoning::compass_reading_rad(
                    x.euler_rad[2],
                    &e.heading_deviation,
                );
                counts.attitude_changed += 1;
                out.push((m.log_time_ns, Out::Attitude(m, x)));
            }
            _ => out.push((m.log_time_ns, Out::Raw(m))),
        }
    }
    if restamp {
        out.sort_by_key(|(t, _)| *t);
    }
    write_log_atomically(output, &header, |w| {
        for (_, o) in &out {
            match o {
                Out::Raw(m) => w.write_raw(m)?,
                Out::Imu(m, x) => w.write(&m.topic, x)?,
                Out::Dvl(m, x) => w.write(&m.topic, x)?,
                Out::Depth(m, x) => w.write(&m.topic, x)?,
                Out::Attitude(m, x) => w.write(&m.topic, x)?,
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

/// A message of the output: copied as recorded, or changed.
enum Out<'a> {
    Raw(&'a RawLogMessage),
    Imu(&'a RawLogMessage, ImuSampleV1),
    Dvl(&'a RawLogMessage, DvlVelocityV1),
    Depth(&'a RawLogMessage, DepthV1),
    Attitude(&'a RawLogMessage, AttitudeV1),
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

    /// A log of 2 s: IMU at 10 Hz turning about z at 0.1 rad/s, DVL at 1 Hz with beams.
    fn small_log(path: &Path) {
        let header = auvnav_log::LogHeader::new("perturb test", "");
        write_log_atomically(path, &header, |w| {
            for k in 1..=20u64 {
                let t = k * 100_000_000;
                let imu = ImuSampleV1 {
                    host_time_ns: t,
                    sequence: k,
                    angular: [0.0, 0.0, 0.1],
                    specific: [0.0, 0.0, -9.8],
                    interval_s: 0.1,
                    ..Default::default()
                };
                w.write("imu", &imu)?;
                if k % 10 == 0 {
                    let dvl = DvlVelocityV1 {
                        host_time_ns: t,
                        validity_time_ns: t,
                        sequence: k / 10,
                        velocity_dvl_m_s: [1.0 + k as f64 * 0.01, 0.2, 0.0],
                        validity: DvlVelocityV1::VALID_VELOCITY
                            | (0xf * DvlVelocityV1::VALID_BEAM_VELOCITY),
                        ..Default::default()
                    };
                    w.write("dvl", &dvl)?;
                }
            }
            Ok(())
        })
        .expect("write");
    }

    fn read_back(path: &Path) -> Vec<LogMessage> {
        let (_, raw) = read_all(path).expect("read");
        raw.iter()
            .map(|m| m.decode_any().expect("decode"))
            .collect()
    }

    fn dvl_of(messages: &[LogMessage]) -> Vec<DvlVelocityV1> {
        messages
            .iter()
            .filter_map(|m| match m {
                LogMessage::Dvl(x) => Some(*x),
                _ => None,
            })
            .collect()
    }

    #[test]
    fn a_time_offset_moves_the_readings_and_keeps_what_they_recorded() {
        let dir = std::env::temp_dir().join(format!("perturb-restamp-{}", std::process::id()));
        std::fs::create_dir_all(&dir).expect("dir");
        let (input, output) = (dir.join("in.mcap"), dir.join("out.mcap"));
        small_log(&input);
        let before = dvl_of(&read_back(&input));

        // Late by 0.35 s: the same velocities, beams still valid, stamped later, in time order.
        let p = Perturbation::parse(&["dvl.time_offset=0.35".into()], 1).expect("parse");
        let counts = perturb_log(&input, &output, &p).expect("perturb");
        assert_eq!((counts.dvl_restamped, counts.dvl_changed), (2, 0));
        let after = read_back(&output);
        let times: Vec<u64> = after
            .iter()
            .map(|m| match m {
                LogMessage::Imu(x) => x.host_time_ns,
                LogMessage::Dvl(x) => x.host_time_ns,
                _ => panic!("unexpected message"),
            })
            .collect();
        assert!(times.windows(2).all(|w| w[0] <= w[1]), "{times:?}");
        let dvl = dvl_of(&after);
        assert_eq!(dvl.len(), 2);
        for (a, b) in dvl.iter().zip(&before) {
            assert_eq!(a.validity_time_ns, b.validity_time_ns + 350_000_000);
            assert_eq!(a.host_time_ns, b.host_time_ns + 350_000_000);
            assert_eq!(a.velocity_dvl_m_s, b.velocity_dvl_m_s);
            assert_eq!(a.validity, b.validity);
        }

        // Early by 1.5 s: the first reading (at 1 s) would fall before zero and is left out;
        // a scale changes the velocity and the beams no longer match it.
        let p = Perturbation::parse(
            &[
                "dvl.time_offset=-1.5".into(),
                "dvl.scale_factor=1.01".into(),
            ],
            1,
        )
        .expect("parse");
        let counts = perturb_log(&input, &output, &p).expect("perturb");
        assert_eq!(
            (counts.dvl_restamped, counts.dvl_dropped, counts.dvl_changed),
            (1, 1, 1)
        );
        let dvl = dvl_of(&read_back(&output));
        assert_eq!(dvl.len(), 1);
        assert_eq!(dvl[0].validity_time_ns, 500_000_000);
        assert!((dvl[0].velocity_dvl_m_s[0] - 1.2 * 1.01).abs() < 1e-12);
        assert_eq!(
            dvl[0].validity & (0xf * DvlVelocityV1::VALID_BEAM_VELOCITY),
            0
        );
        std::fs::remove_dir_all(&dir).ok();
    }
}
