//! `auvnav sim`: a trajectory-and-sensor simulator with named error effects.
//!
//! The simulation is a pure function of (scenario, effects, seed): it reads no clock, draws from
//! seeded per-sensor random streams, and writes messages in time order, so the same inputs give
//! the same log bytes.
#![forbid(unsafe_code)]

pub mod acoustic;
pub mod campaign;
pub mod effects;
pub mod error;
pub mod perturb;
pub mod rng;
pub mod scenario;
pub mod sensors;
pub mod trajectory;

use auvnav_core::earth::{self, Geodetic};
use auvnav_log::{LogHeader, LogMessage, write_log_atomically};
use auvnav_shm_schema::{AttitudeV1, SoundVelocityV1, TruthStateV1, topic};
use effects::Effects;
pub use error::SimError;
use nalgebra::Vector3;
use scenario::Scenario;
use sensors::*;
use std::collections::{BTreeMap, VecDeque};
use std::path::Path;
use trajectory::{Trajectory, TruthSample};

/// Everything a simulation run depends on.
#[derive(Debug, Clone)]
pub struct SimConfig {
    pub scenario: Scenario,
    pub effects: Effects,
    pub seed: u64,
    /// Stop after this many seconds (default: the scenario's own length).
    pub duration_s: Option<f64>,
}

impl SimConfig {
    /// The configuration as TOML text: the scenario with the effects that differ from neutral.
    pub fn to_toml(&self) -> String {
        let mut s = self.scenario.clone();
        s.effects.clear();
        let neutral = Effects::default();
        for spec in effects::SPECS {
            let v = self.effects.get(spec.name).unwrap_or_default();
            if Some(&v) != neutral.get(spec.name).as_ref() {
                let value = if v.len() == 1 {
                    scenario::EffectValue::Scalar(v[0])
                } else {
                    scenario::EffectValue::Vector(v)
                };
                s.effects.insert(spec.name.to_string(), value);
            }
        }
        format!(
            "seed = {}\nduration_s = {}\n{}",
            self.seed,
            self.duration_s
                .map(|d| d.to_string())
                .unwrap_or_else(|| "\"scenario\"".into()),
            s.to_toml()
        )
    }
}

/// The surveyed USBL station as the navigation filter must know it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StationGeometry {
    /// Surveyed position of the central transducer.
    pub position: Geodetic,
    /// Surveyed yaw of the array x axis from north (rad).
    pub yaw_rad: f64,
    /// Distance between opposite hydrophones (m).
    pub baseline_m: f64,
    /// Responder position in the vehicle body frame (m).
    pub responder_lever_arm_m: [f64; 3],
}

impl StationGeometry {
    pub fn from_scenario(s: &Scenario) -> Option<StationGeometry> {
        let st = s.station.as_ref()?;
        let start = Geodetic {
            latitude_rad: s.start.latitude_deg.to_radians(),
            longitude_rad: s.start.longitude_deg.to_radians(),
            height_m: 0.0,
        };
        let mut position =
            earth::offset_position(&start, &Vector3::new(st.north_m, st.east_m, 0.0));
        position.height_m = -st.depth_m;
        Some(StationGeometry {
            position,
            yaw_rad: st.yaw_deg.to_radians(),
            baseline_m: st.baseline_m,
            responder_lever_arm_m: st.responder_lever_arm_m,
        })
    }

    /// Header notes describing the station (read back by [`StationGeometry::from_notes`]).
    /// The station as the navigator's `[navigation.usbl]` array (as surveyed; default noise,
    /// coupling and filter).
    pub fn usbl_config(&self) -> auvnav_core::aid::usbl::UsblConfig {
        auvnav_core::aid::usbl::UsblConfig {
            array_latitude_deg: self.position.latitude_rad.to_degrees(),
            array_longitude_deg: self.position.longitude_rad.to_degrees(),
            array_height_m: self.position.height_m,
            array_yaw_deg: self.yaw_rad.to_degrees(),
            baseline_m: self.baseline_m,
            responder_lever_arm_m: self.responder_lever_arm_m,
            ..Default::default()
        }
    }

    pub fn to_notes(&self) -> BTreeMap<String, String> {
        let mut m = BTreeMap::new();
        m.insert(
            "station.latitude_rad".into(),
            format!("{:e}", self.position.latitude_rad),
        );
        m.insert(
            "station.longitude_rad".into(),
            format!("{:e}", self.position.longitude_rad),
        );
        m.insert(
            "station.height_m".into(),
            format!("{:e}", self.position.height_m),
        );
        m.insert("station.yaw_rad".into(), format!("{:e}", self.yaw_rad));
        m.insert(
            "station.baseline_m".into(),
            format!("{:e}", self.baseline_m),
        );
        let l = self.responder_lever_arm_m;
        m.insert(
            "station.responder_lever_arm_m".into(),
            format!("{:e},{:e},{:e}", l[0], l[1], l[2]),
        );
        m
    }

    pub fn from_notes(m: &BTreeMap<String, String>) -> Option<StationGeometry> {
        let f = |k: &str| m.get(k)?.parse::<f64>().ok();
        let l: Vec<f64> = m
            .get("station.responder_lever_arm_m")?
            .split(',')
            .filter_map(|x| x.parse().ok())
            .collect();
        Some(StationGeometry {
            position: Geodetic {
                latitude_rad: f("station.latitude_rad")?,
                longitude_rad: f("station.longitude_rad")?,
                height_m: f("station.height_m")?,
            },
            yaw_rad: f("station.yaw_rad")?,
            baseline_m: f("station.baseline_m")?,
            responder_lever_arm_m: l.try_into().ok()?,
        })
    }
}

/// Counts of what a run produced.
#[derive(Debug, Clone, Default, PartialEq, serde::Serialize)]
pub struct SimSummary {
    pub duration_s: f64,
    pub imu: u64,
    pub dvl: u64,
    pub dvl_valid: u64,
    /// DVL water-track velocities (`dvl.water_track_noise` above 0).
    pub dvl_water_track: u64,
    pub usbl: u64,
    pub usbl_outliers: u64,
    /// Pings of the acoustic system of `[acoustic]` (one range message each), ranges hit by an
    /// outlier, and its boat's pose messages.
    pub acoustic_pings: u64,
    pub acoustic_outliers: u64,
    pub acoustic_array_poses: u64,
    pub depth: u64,
    pub magnetometer: u64,
    pub gnss: u64,
    /// Compass samples on the attitude channel (`rates.compass_hz`).
    pub attitude: u64,
    /// CTD sound-velocity readings (`rates.ctd_hz`).
    pub sound_velocity: u64,
    pub truth: u64,
    /// Distance travelled over ground (m).
    pub distance_m: f64,
}

fn truth_message(seq: u64, s: &TruthSample) -> TruthStateV1 {
    let q = s.kin.quaternion_body_to_ned();
    TruthStateV1 {
        host_time_ns: (s.time_s * 1e9).round() as u64,
        sequence: seq,
        latitude_rad: s.position.latitude_rad,
        longitude_rad: s.position.longitude_rad,
        height_m: s.position.height_m,
        velocity_ned_m_s: s.velocity_ned.into(),
        quaternion_body_to_ned: [q.w, q.i, q.j, q.k],
        euler_rad: s.kin.euler_rad,
        angular_rate_rad_s: s.omega_ib_body.into(),
        specific_force_m_s2: s.specific_force_body.into(),
    }
}

/// The compass's attitude: the true roll and pitch, the heading shown with `heading.deviation`.
fn compass_message(seq: u64, s: &TruthSample, e: &Effects) -> AttitudeV1 {
    let [roll, pitch, heading] = s.kin.euler_rad;
    let shown = auvnav_core::dead_reckoning::compass_reading_rad(heading, &e.heading_deviation);
    AttitudeV1 {
        host_time_ns: (s.time_s * 1e9).round() as u64,
        sequence: seq,
        euler_rad: [roll, pitch, shown],
        validity: AttitudeV1::VALID_ATTITUDE | AttitudeV1::HEADING_TRUE,
        ..Default::default()
    }
}

fn divider(imu_hz: u32, hz: u32) -> u64 {
    imu_hz.checked_div(hz).map(u64::from).unwrap_or(0)
}

/// Runs the simulation and keeps every message in memory, in time order.
pub fn simulate_to_vec(cfg: &SimConfig) -> Result<(Vec<LogMessage>, SimSummary), SimError> {
    let mut out = Vec::new();
    let summary = simulate(cfg, |m| {
        out.push(*m);
        Ok::<(), SimError>(())
    })?;
    Ok((out, summary))
}

/// Runs the simulation, handing every message to `sink` in time order (truth on [`LogMessage::Truth`]).
/// The first error of `sink` ends the run and is returned; a scenario the trajectory cannot fly
/// is returned as `E` from [`SimError::Trajectory`].
// Long on purpose: one loop over the IMU epochs in which every sensor is sampled at its own
// divider from the same truth, in the order the log receives them.
pub fn simulate<F, E>(cfg: &SimConfig, mut sink: F) -> Result<SimSummary, E>
where
    F: FnMut(&LogMessage) -> Result<(), E>,
    E: From<SimError>,
{
    let s = &cfg.scenario;
    let e = &cfg.effects;
    let traj = Trajectory::from_scenario(s).map_err(SimError::from)?;
    let duration = cfg.duration_s.unwrap_or(traj.duration_s);
    let rates = &s.rates;
    let imu_hz = f64::from(rates.imu_hz);
    let dt = 1.0 / imu_hz;
    let n = (duration * imu_hz).floor() as u64;
    let (dvl_div, usbl_div, depth_div, mag_div, gnss_div, truth_div) = (
        divider(rates.imu_hz, rates.dvl_hz),
        divider(rates.imu_hz, rates.usbl_hz),
        divider(rates.imu_hz, rates.depth_hz),
        divider(rates.imu_hz, rates.magnetometer_hz),
        divider(rates.imu_hz, rates.gnss_hz),
        divider(rates.imu_hz, rates.truth_hz),
    );
    let ctd_div = divider(rates.imu_hz, rates.ctd_hz);
    let compass_div = divider(rates.imu_hz, rates.compass_hz);

    let mut imu = ImuModel::new(e, cfg.seed, imu_hz);
    let mut dvl = DvlModel::new(e, cfg.seed, s.seabed_depth_m);
    let mut current = WaterCurrent::new(e, cfg.seed);
    let station = StationGeometry::from_scenario(s);
    let mut usbl = match (&s.station, &station) {
        (Some(st), Some(geo)) => Some(UsblModel::new(e, cfg.seed, st, &geo.position)),
        _ => None,
    };
    let mut acoustic = s
        .acoustic
        .as_ref()
        .map(|a| acoustic::AcousticModel::new(a, e, cfg.seed, &traj.start));
    let pose_div = s
        .acoustic
        .as_ref()
        .map_or(0, |a| divider(rates.imu_hz, a.pose_hz));
    let mut depth = DepthModel::new(e, cfg.seed);
    let mut mag = MagnetometerModel::new(e, cfg.seed);
    let mut gnss = GnssModel::new(e, cfg.seed);
    let mut summary = SimSummary {
        duration_s: n as f64 * dt,
        ..Default::default()
    };

    let mut pos = traj.start;
    let mut prev = traj.truth(0.0, pos);
    // Positions of the last seconds, for sensors whose time of validity lies in the past.
    let history_len = (e.usbl_latency * imu_hz).ceil() as usize + 2;
    let mut history: VecDeque<(f64, Geodetic)> = VecDeque::with_capacity(history_len + 1);
    history.push_back((0.0, pos));
    if truth_div > 0 {
        summary.truth += 1;
        sink(&LogMessage::Truth(truth_message(summary.truth, &prev)))?;
    }
    for k in 1..=n {
        let t = k as f64 * dt;
        let new_pos = traj.step_position(pos, t - dt, dt);
        let mid_pos = Geodetic {
            latitude_rad: 0.5 * (pos.latitude_rad + new_pos.latitude_rad),
            longitude_rad: 0.5 * (pos.longitude_rad + new_pos.longitude_rad),
            height_m: 0.5 * (pos.height_m + new_pos.height_m),
        };
        let mid = traj.truth(t - 0.5 * dt, mid_pos);
        let now = traj.truth(t, new_pos);
        summary.distance_m += 0.5 * (prev.velocity_ned + now.velocity_ned).norm() * dt;
        // Interval averages by Simpson's rule: the IMU integrates over its sample interval.
        let w = (prev.omega_ib_body + 4.0 * mid.omega_ib_body + now.omega_ib_body) / 6.0;
        let f =
            (prev.specific_force_body + 4.0 * mid.specific_force_body + now.specific_force_body)
                / 6.0;
        sink(&LogMessage::Imu(imu.sample(t, &w, &f)))?;
        summary.imu += 1;
        history.push_back((t, new_pos));
        while history.len() > history_len {
            history.pop_front();
        }

        // Before the DVL: a reading at the same time as a ping is known when the ping arrives.
        if ctd_div > 0 && k % ctd_div == 0 {
            summary.sound_velocity += 1;
            sink(&LogMessage::SoundVelocity(SoundVelocityV1 {
                host_time_ns: (t * 1e9).round() as u64,
                device_time_ns: (t * 1e9).round() as u64,
                sequence: summary.sound_velocity,
                sound_speed_m_s: e.dvl_sound_speed,
                validity: SoundVelocityV1::VALID_SOUND_SPEED | SoundVelocityV1::VALID_DEVICE_TIME,
                ..Default::default()
            }))?;
        }
        if dvl_div > 0 && k % dvl_div == 0 {
            let tv = t - dvl.time_offset;
            let truth = if dvl.time_offset == 0.0 {
                now
            } else {
                traj.truth(tv, new_pos)
            };
            let m = dvl.sample(t, dvl_div as f64 * dt, &truth);
            summary.dvl += 1;
            if m.validity & auvnav_shm_schema::DvlVelocityV1::VALID_VELOCITY != 0 {
                summary.dvl_valid += 1;
            }
            sink(&LogMessage::Dvl(m))?;
            if dvl.reports_water_track() {
                let c = current.step(dvl_div as f64 * dt, -truth.position.height_m);
                summary.dvl_water_track += 1;
                sink(&LogMessage::Dvl(dvl.sample_water_track(t, &truth, &c)))?;
            }
        }
        if let Some(u) = usbl.as_mut().filter(|_| usbl_div > 0 && k % usbl_div == 0) {
            let tv = t - e.usbl_latency;
            if tv >= 0.0 {
                let p = interpolate(&history, tv);
                let truth = if e.usbl_latency == 0.0 {
                    now
                } else {
                    traj.truth(tv, p)
                };
                if let Some((fix, info)) = u.sample(t, &truth) {
                    summary.usbl += 1;
                    if info.outlier_m > 0.0 {
                        summary.usbl_outliers += 1;
                    }
                    sink(&LogMessage::Usbl(fix))?;
                }
            }
        }
        if let Some(a) = acoustic.as_mut() {
            a.step(dt, &now);
            if pose_div > 0
                && k % pose_div == 0
                && let Some(p) = a.pose_message(t)
            {
                summary.acoustic_array_poses += 1;
                sink(&LogMessage::AcousticArrayPose(p))?;
            }
            if usbl_div > 0 && k % usbl_div == 0 {
                let m = a.ping(t, -now.position.height_m);
                summary.acoustic_pings += 1;
                summary.acoustic_outliers = a.outliers;
                sink(&LogMessage::AcousticRanges(m))?;
            }
        }
        if depth_div > 0 && k % depth_div == 0 {
            summary.depth += 1;
            sink(&LogMessage::Depth(depth.sample(t, &now)))?;
        }
        if mag_div > 0 && k % mag_div == 0 {
            summary.magnetometer += 1;
            sink(&LogMessage::Magnetometer(mag.sample(t, &now)))?;
        }
        if gnss_div > 0
            && k % gnss_div == 0
            && let Some(fix) = gnss.sample(t, &now)
        {
            summary.gnss += 1;
            sink(&LogMessage::Gnss(fix))?;
        }
        if compass_div > 0 && k % compass_div == 0 {
            summary.attitude += 1;
            sink(&LogMessage::Attitude(compass_message(
                summary.attitude,
                &now,
                e,
            )))?;
        }
        if truth_div > 0 && k % truth_div == 0 {
            summary.truth += 1;
            sink(&LogMessage::Truth(truth_message(summary.truth, &now)))?;
        }
        pos = new_pos;
        prev = now;
    }
    Ok(summary)
}

fn interpolate(history: &VecDeque<(f64, Geodetic)>, t: f64) -> Geodetic {
    let mut before = history.front().copied();
    for &(ti, p) in history {
        if ti >= t {
            if let Some((t0, p0)) = before
                && ti > t0
            {
                let a = (t - t0) / (ti - t0);
                return Geodetic {
                    latitude_rad: p0.latitude_rad + a * (p.latitude_rad - p0.latitude_rad),
                    longitude_rad: p0.longitude_rad + a * (p.longitude_rad - p0.longitude_rad),
                    height_m: p0.height_m + a * (p.height_m - p0.height_m),
                };
            }
            return p;
        }
        before = Some((ti, p));
    }
    before.map(|(_, p)| p).unwrap_or(Geodetic {
        latitude_rad: 0.0,
        longitude_rad: 0.0,
        height_m: 0.0,
    })
}

/// The log header of a simulated voyage.
pub fn log_header(cfg: &SimConfig) -> LogHeader {
    let mut h = LogHeader::new("auvnav sim", &cfg.to_toml());
    h.notes.insert("scenario".into(), cfg.scenario.name.clone());
    h.notes.insert("seed".into(), cfg.seed.to_string());
    if let Some(st) = StationGeometry::from_scenario(&cfg.scenario) {
        h.notes.extend(st.to_notes());
    }
    h
}

/// Simulates into a log file, atomically (no file at `out` on error).
pub fn simulate_to_log(cfg: &SimConfig, out: &Path) -> Result<SimSummary, SimError> {
    let mut summary = SimSummary::default();
    write_log_atomically(out, &log_header(cfg), |w| {
        summary = simulate(cfg, |m| -> anyhow::Result<()> {
            match m {
                LogMessage::Imu(x) => w.write(topic::IMU, x)?,
                LogMessage::Dvl(x) => w.write(topic::DVL, x)?,
                LogMessage::Usbl(x) => w.write(topic::USBL, x)?,
                LogMessage::Depth(x) => w.write(topic::DEPTH, x)?,
                LogMessage::Magnetometer(x) => w.write(topic::MAGNETOMETER, x)?,
                LogMessage::Gnss(x) => w.write(topic::GNSS, x)?,
                LogMessage::SoundVelocity(x) => w.write(topic::SOUND_VELOCITY, x)?,
                LogMessage::Attitude(x) => w.write(topic::ATTITUDE, x)?,
                LogMessage::AcousticRanges(x) => w.write(topic::ACOUSTIC_RANGES, x)?,
                LogMessage::AcousticArrayPose(x) => w.write(topic::ACOUSTIC_ARRAY_POSE, x)?,
                LogMessage::Truth(x) => w.write(topic::TRUTH, x)?,
                _ => {}
            }
            Ok(())
        })?;
        Ok(())
    })
    // The simulation's own error (a scenario the trajectory cannot fly) comes back as itself;
    // anything else is the output's.
    .map_err(|e| {
        e.downcast::<SimError>()
            .unwrap_or_else(|e| SimError::Output {
                path: out.to_path_buf(),
                source: e.into(),
            })
    })?;
    Ok(summary)
}
