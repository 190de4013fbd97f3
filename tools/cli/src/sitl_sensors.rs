//! `auvnav sitl-sensors`: the IMU and DVL of a vehicle whose motion is ArduPilot SITL's.
//!
//! For a closed loop with an autopilot: SITL's physics moves the vehicle, this command reads its
//! true state (`SIM_STATE`, asked for with `MAV_CMD_SET_MESSAGE_INTERVAL`) and plays what auvnav's
//! simulator says an IMU and a DVL on that vehicle would send — with the simulator's named effects
//! (`--effect imu_gyro_bias=…`, the vocabulary of `auvnav sim --list-effects`) — into
//! pseudo-terminals in the devices' own protocols, for the drivers to read. The navigation that
//! results goes back to the autopilot through `auvnav-mavlink`.
//!
//! SITL's world is flat and does not rotate. Its motion is turned into what an IMU on auvnav's
//! Earth reads: the gyros get the Earth's rotation and the transport rate, the accelerometers
//! the Coriolis term and the local normal gravity, so that auvnav's strapdown, integrating them,
//! follows SITL's motion. Heights are SITL's altitude
//! less the surface's: ArduSub's SITL puts the water surface at altitude 0 (its pressure sensor
//! reads depth as −altitude), so a home altitude of 0 keeps the two in step.
//!
//! Every state gives one IMU sample: the interval's average specific force from the change of
//! SITL's velocity and its average rate from the change of its attitude, so that the strapdown
//! reproduces SITL's velocity and attitude exactly, whatever SITL's accelerometer model does
//! between states. The interval is the states' measured spacing (SIM_STATE carries no time),
//! averaged over the last seconds of arrivals: the IMU's device time runs at SITL's rate. The
//! frames go out on that clock, a fixed 50 ms after their state, as a device's would, not in the
//! bursts SITL's link delivers them in.

use crate::emulate_ptys::open_terminal;
use anyhow::{Context, bail};
use auvnav_core::earth::{self, Geodetic};
use auvnav_drivers::device::{DeviceClass, Protocol};
use auvnav_drivers::to_device as enc;
use auvnav_sim::effects::{Effects, parse_setting};
use auvnav_sim::sensors::{DvlModel, ImuModel};
use auvnav_sim::trajectory::{Kinematics, TruthSample};
use mavlink::MavConnection;
use mavlink::dialects::ardupilotmega as mav;
use nalgebra::{Quaternion, UnitQuaternion, Vector3};
use serde::Serialize;
use std::io::Write;
use std::path::PathBuf;
use std::sync::Arc;
use std::time::{Duration, Instant};

/// A gap between states longer than this is a pause: the next state starts a new interval.
const PAUSE_S: f64 = 0.5;
/// How long after its state each frame goes out (s): SITL's states come over its link in bursts,
/// devices send at a steady rate. Frames leave on the states' own clock this much later, so that
/// the drivers stamp them as they would a device's, the IMU's and the DVL's alike.
const PLAYOUT_DELAY_S: f64 = 0.05;
/// The window over which the states' spacing is averaged (states).
const SPACING_WINDOW: usize = 1000;

#[derive(Debug, clap::Args)]
pub struct SitlSensorsArgs {
    /// SITL's MAVLink endpoint: a serial port of SITL that nothing else uses (tcp 5762 is
    /// SERIAL1, 5763 SERIAL2).
    #[arg(long, default_value = "tcpout:127.0.0.1:5762")]
    pub mavlink: String,
    /// Folder for the devices' stable links: DIR/imu and DIR/dvl point at the terminals.
    #[arg(long)]
    pub link_dir: PathBuf,
    /// The IMU's protocol (xsens or kvh1750).
    #[arg(long, default_value = "xsens", value_parser = ["xsens", "kvh1750"])]
    pub imu: String,
    /// The DVL's protocol (wldvl: Water Linked's A50/A125, as on a BlueROV2; or pd0).
    #[arg(long, default_value = "wldvl", value_parser = ["wldvl", "pd0"])]
    pub dvl: String,
    /// The rate asked of SITL's SIM_STATE, which is the IMU's (Hz).
    #[arg(long, default_value_t = 200)]
    pub imu_hz: u32,
    #[arg(long, default_value_t = 5)]
    pub dvl_hz: u32,
    /// A simulator effect, NAME=VALUE[,VALUE…] in the units `auvnav sim --list-effects` gives
    /// (repeatable).
    #[arg(long = "effect", value_name = "NAME=VALUE")]
    pub effects: Vec<String>,
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Water depth under the vehicle's start (m): the DVL's bottom lock and altitude.
    #[arg(long, default_value_t = 60.0)]
    pub seabed_depth_m: f64,
    /// SITL's altitude of the water surface (m): 0 in ArduSub's SITL, whose pressure sensor
    /// reads the depth below altitude 0.
    #[arg(long, default_value_t = 0.0)]
    pub surface_altitude_m: f64,
    /// Stop after this many seconds of output (default: until SITL's link closes).
    #[arg(long)]
    pub duration_s: Option<f64>,
    /// One JSON line per event (ready, summary) instead of text.
    #[arg(long)]
    pub json: bool,
}

/// What was played, for the summary line.
#[derive(Debug, Default, Clone, Serialize)]
pub struct SitlSensorsSummary {
    pub states: u64,
    pub imu_samples: u64,
    pub dvl_readings: u64,
    /// Pauses longer than half a second between SITL's states (SITL paused or slow).
    pub pauses: u64,
    /// The states' mean spacing at the end (s).
    pub interval_s: f64,
    /// Frames dropped because a terminal's queue was full (its driver not reading).
    pub dropped_frames: u64,
    pub seconds: f64,
}

/// SITL's true state at one instant, in SITL's conventions (flat, non-rotating world).
#[derive(Debug, Clone, Copy)]
struct SitlState {
    received: Instant,
    latitude_deg: f64,
    longitude_deg: f64,
    altitude_m: f64,
    velocity_ned: Vector3<f64>,
    body_to_ned: UnitQuaternion<f64>,
}

fn from_sim_state(m: &mav::SIM_STATE_DATA, received: Instant) -> Option<SitlState> {
    let q = Quaternion::new(
        f64::from(m.q1),
        f64::from(m.q2),
        f64::from(m.q3),
        f64::from(m.q4),
    );
    let values = [m.q1, m.q2, m.q3, m.q4, m.alt, m.vn, m.ve, m.vd];
    if values.iter().any(|v| !v.is_finite()) || q.norm() < 0.5 {
        return None;
    }
    // lat_int/lon_int (1e-7°) are exact; the float fields carry the same scaled by 1e7 in f32.
    let (latitude_deg, longitude_deg) = if m.lat_int != 0 || m.lon_int != 0 {
        (f64::from(m.lat_int) * 1e-7, f64::from(m.lon_int) * 1e-7)
    } else {
        (f64::from(m.lat) * 1e-7, f64::from(m.lon) * 1e-7)
    };
    Some(SitlState {
        received,
        latitude_deg,
        longitude_deg,
        altitude_m: f64::from(m.alt),
        velocity_ned: Vector3::new(f64::from(m.vn), f64::from(m.ve), f64::from(m.vd)),
        body_to_ned: UnitQuaternion::from_quaternion(q),
    })
}

/// The interval from SITL's state `prev` to `cur` (`dt` s apart) as auvnav's simulator's truth at
/// `cur`, with the interval's average rate and specific force (what an IMU integrating over the
/// interval reads): the rotating, ellipsoidal Earth's terms added to SITL's flat, still world.
fn interval_truth(
    prev: &SitlState,
    cur: &SitlState,
    dt: f64,
    t: f64,
    surface_altitude_m: f64,
) -> TruthSample {
    let position = Geodetic {
        latitude_rad: cur.latitude_deg.to_radians(),
        longitude_rad: cur.longitude_deg.to_radians(),
        height_m: cur.altitude_m - surface_altitude_m,
    };
    let v = cur.velocity_ned;
    let v_mid = 0.5 * (prev.velocity_ned + v);
    let lat = position.latitude_rad;
    let w_ie = earth::earth_rate_ned(lat);
    let w_en = earth::transport_rate_ned(lat, position.height_m, &v_mid);
    // The body's rotation over the interval, and its attitude halfway.
    let turn = prev.body_to_ned.inverse() * cur.body_to_ned;
    let omega_nb = turn.scaled_axis() / dt;
    let mid = prev.body_to_ned * UnitQuaternion::from_scaled_axis(0.5 * turn.scaled_axis());
    // f = a + (2ω_ie + ω_en) × v − g, with a the velocity's change over the interval.
    let f_n = (v - prev.velocity_ned) / dt + (2.0 * w_ie + w_en).cross(&v_mid)
        - earth::gravity_ned(lat, position.height_m);
    let c_bn = *cur.body_to_ned.to_rotation_matrix().matrix();
    let (roll, pitch, yaw) = cur.body_to_ned.euler_angles();
    TruthSample {
        time_s: t,
        position,
        kin: Kinematics {
            speed_m_s: v.norm(),
            speed_rate_m_s2: 0.0,
            euler_rad: [roll, pitch, yaw],
            euler_rate_rad_s: [0.0; 3],
        },
        c_body_to_ned: c_bn,
        velocity_ned: v,
        omega_ib_body: omega_nb + mid.inverse() * (w_ie + w_en),
        omega_eb_body: omega_nb + mid.inverse() * w_en,
        specific_force_body: mid.inverse() * f_n,
    }
}

fn protocol(name: &str) -> anyhow::Result<Protocol> {
    Protocol::from_name(name).with_context(|| format!("unknown protocol {name}"))
}

/// A read that found nothing yet (the transport's timeout), not a closed link.
fn quiet(e: &std::io::Error) -> bool {
    use std::io::ErrorKind::{Interrupted, TimedOut, WouldBlock};
    matches!(e.kind(), WouldBlock | TimedOut | Interrupted)
}

/// Reads SITL's link on its own thread: hands every state on, asks for SIM_STATE whenever the
/// autopilot's heartbeat comes and no state has for a second. Returns why it ended.
fn spawn_reader(
    conn: Arc<mavlink::Connection<mav::MavMessage>>,
    state_hz: f64,
    states: std::sync::mpsc::Sender<SitlState>,
) -> std::thread::JoinHandle<String> {
    std::thread::spawn(move || {
        let mut last_request: Option<Instant> = None;
        let mut last_state: Option<Instant> = None;
        loop {
            let (header, msg) = match conn.recv() {
                Ok(m) => m,
                // The TCP transport's read timeout: nothing this moment, the link is open.
                Err(mavlink::error::MessageReadError::Io(e)) if quiet(&e) => continue,
                Err(mavlink::error::MessageReadError::Io(e)) => {
                    return format!("SITL's link closed: {e}");
                }
                Err(_) => continue, // a damaged frame: the next one will do
            };
            match msg {
                mav::MavMessage::SIM_STATE(m) => {
                    if let Some(s) = from_sim_state(&m, Instant::now()) {
                        last_state = Some(s.received);
                        if states.send(s).is_err() {
                            return "the output ended".to_string();
                        }
                    }
                }
                mav::MavMessage::HEARTBEAT(_) if header.component_id == 1 => {
                    let fresh = last_state.is_some_and(|t| t.elapsed().as_secs_f64() < 1.0);
                    if !fresh && last_request.is_none_or(|t| t.elapsed().as_secs_f64() > 1.0) {
                        last_request = Some(Instant::now());
                        let ask = mav::MavMessage::COMMAND_LONG(mav::COMMAND_LONG_DATA {
                            target_system: u8::try_from(header.system_id).unwrap_or(1),
                            target_component: 1,
                            command: mav::MavCmd::MAV_CMD_SET_MESSAGE_INTERVAL,
                            param1: 108.0, // SIM_STATE
                            param2: (1e6 / state_hz) as f32,
                            ..Default::default()
                        });
                        let me = mavlink::MavHeader {
                            system_id: 255,
                            component_id: 190,
                            sequence: 0,
                        };
                        if let Err(e) = conn.send(&me, &ask) {
                            return format!("SITL's link closed: {e}");
                        }
                    }
                }
                _ => {}
            }
        }
    })
}

/// The states' mean spacing over the last [`SPACING_WINDOW`] arrivals (s), restarted by a pause.
struct Spacing {
    arrivals: std::collections::VecDeque<Instant>,
    nominal_s: f64,
}

impl Spacing {
    fn push(&mut self, t: Instant) -> f64 {
        if self
            .arrivals
            .back()
            .is_some_and(|last| t.duration_since(*last).as_secs_f64() > PAUSE_S)
        {
            self.arrivals.clear();
        }
        self.arrivals.push_back(t);
        if self.arrivals.len() > SPACING_WINDOW {
            self.arrivals.pop_front();
        }
        self.interval_s()
    }

    /// The nominal spacing until a second of states has come, then the measured mean.
    fn interval_s(&self) -> f64 {
        let n = self.arrivals.len();
        match (self.arrivals.front(), self.arrivals.back()) {
            (Some(first), Some(last)) if n as f64 * self.nominal_s >= 1.0 => {
                last.duration_since(*first).as_secs_f64() / (n - 1) as f64
            }
            _ => self.nominal_s,
        }
    }
}

/// A device's terminal, written from its own thread so that a driver that stops reading never
/// holds up the other device: a frame that finds the queue full is dropped and counted.
struct Terminal {
    queue: std::sync::mpsc::SyncSender<Vec<u8>>,
    dropped: u64,
}

impl Terminal {
    fn open(link: &std::path::Path) -> anyhow::Result<(Terminal, String)> {
        let (mut master, slave, path) = open_terminal(Some(link))?;
        let (queue, frames) = std::sync::mpsc::sync_channel::<Vec<u8>>(64);
        std::thread::spawn(move || {
            let _slave = slave; // the terminal exists while no driver has it open
            for frame in frames {
                let _ = master.write_all(&frame);
            }
        });
        Ok((Terminal { queue, dropped: 0 }, path))
    }

    fn write(&mut self, frame: Vec<u8>) {
        if self.queue.try_send(frame).is_err() {
            self.dropped += 1;
        }
    }
}

/// Runs until SITL's link closes or `--duration-s` has passed; returns the summary (also printed).
pub fn run(a: &SitlSensorsArgs) -> anyhow::Result<SitlSensorsSummary> {
    if a.imu_hz == 0 || a.imu_hz > 400 || a.dvl_hz == 0 || !a.imu_hz.is_multiple_of(a.dvl_hz) {
        bail!(
            "--imu-hz {} and --dvl-hz {}: expected an IMU rate of 1..=400 Hz that the DVL's divides",
            a.imu_hz,
            a.dvl_hz
        );
    }
    let mut effects = Effects::default();
    for spec in &a.effects {
        let (name, values) =
            parse_setting(spec).map_err(|e| anyhow::anyhow!("--effect {spec}: {e}"))?;
        effects
            .set(&name, &values)
            .map_err(|e| anyhow::anyhow!("--effect {spec}: {e}"))?;
    }
    let imu_protocol = protocol(&a.imu)?;
    let dvl_protocol = protocol(&a.dvl)?;
    std::fs::create_dir_all(&a.link_dir)
        .with_context(|| format!("creating {}", a.link_dir.display()))?;

    let conn = mavlink::connect::<mav::MavMessage>(&a.mavlink)
        .with_context(|| format!("connecting to SITL at {}", a.mavlink))?;
    let imu_hz = f64::from(a.imu_hz);
    let (to_output, states) = std::sync::mpsc::channel();
    let reader = spawn_reader(Arc::new(conn), imu_hz, to_output);
    let first = states
        .recv_timeout(Duration::from_secs(60))
        .map_err(|_| anyhow::anyhow!("no SIM_STATE from SITL at {} in 60 s", a.mavlink))?;

    let (mut imu_tty, imu_path) = Terminal::open(&a.link_dir.join(DeviceClass::Imu.name()))?;
    let (mut dvl_tty, dvl_path) = Terminal::open(&a.link_dir.join(DeviceClass::Dvl.name()))?;
    say(
        a.json,
        &serde_json::json!({
            "event": "ready", "imu": imu_path, "dvl": dvl_path,
            "latitude_deg": first.latitude_deg, "longitude_deg": first.longitude_deg,
            "height_m": first.altitude_m - a.surface_altitude_m,
        }),
    );

    let dvl_div = u64::from(a.imu_hz / a.dvl_hz);
    let mut imu = ImuModel::new(&effects, a.seed, imu_hz);
    let mut dvl = DvlModel::new(&effects, a.seed, a.seabed_depth_m);
    let kvh = auvnav_drivers::to_schema::KvhConfig {
        increments: false,
        degrees: false,
        rate_hz: imu_hz,
        temperature_centi: false,
    };
    let mut summary = SitlSensorsSummary::default();
    let mut spacing = Spacing {
        arrivals: [first.received].into(),
        nominal_s: 1.0 / imu_hz,
    };
    let start = Instant::now();
    // When the states' clock (t) reads zero on the host's; moved on after a pause of SITL's.
    let mut anchor = first.received;
    let mut prev = first;
    let mut t = 0.0;
    let mut k: u64 = 0;
    let outcome = loop {
        if a.duration_s.is_some_and(|d| t >= d) {
            break "the duration ended".to_string();
        }
        let cur = match states.recv_timeout(Duration::from_secs(5)) {
            Ok(s) => s,
            Err(std::sync::mpsc::RecvTimeoutError::Timeout) => continue,
            Err(std::sync::mpsc::RecvTimeoutError::Disconnected) => {
                break reader.join().unwrap_or_default();
            }
        };
        summary.states += 1;
        let dt = spacing.push(cur.received);
        t += dt;
        k += 1;
        if cur.received.duration_since(prev.received).as_secs_f64() > PAUSE_S {
            summary.pauses += 1;
            anchor = cur.received - Duration::from_secs_f64(t);
        }
        let due = anchor + Duration::from_secs_f64(t + PLAYOUT_DELAY_S);
        if let Some(wait) = due.checked_duration_since(Instant::now()) {
            std::thread::sleep(wait);
        }
        let tr = interval_truth(&prev, &cur, dt, t, a.surface_altitude_m);
        prev = cur;
        let sample = imu.sample(t, &tr.omega_ib_body, &tr.specific_force_body);
        imu_tty.write(match imu_protocol {
            Protocol::Kvh1750 => enc::kvh_from_imu(&sample, &kvh, (k % 128) as u8),
            _ => enc::xsens_from_imu(&sample, (k % 65_536) as u16),
        });
        summary.imu_samples += 1;
        if k.is_multiple_of(dvl_div) {
            let d = dvl.sample(t, dvl_div as f64 * dt, &tr);
            dvl_tty.write(match dvl_protocol {
                Protocol::Pd0 => enc::pd0_from_dvl(&d, summary.dvl_readings as u32),
                _ => enc::wrz_from_dvl(&d, 0.0),
            });
            summary.dvl_readings += 1;
        }
    };
    summary.seconds = start.elapsed().as_secs_f64();
    summary.interval_s = spacing.interval_s();
    summary.dropped_frames = imu_tty.dropped + dvl_tty.dropped;
    if a.json {
        say(
            true,
            &serde_json::json!({ "event": "summary", "why": outcome, "summary": summary }),
        );
    } else {
        println!(
            "sitl-sensors: {} ({:.1} s): {} SITL states {:.2} ms apart, {} IMU samples, {} DVL readings, {} pauses, {} frames dropped",
            outcome,
            summary.seconds,
            summary.states,
            summary.interval_s * 1e3,
            summary.imu_samples,
            summary.dvl_readings,
            summary.pauses,
            summary.dropped_frames
        );
    }
    // Give the drivers time to read the last bytes before the terminals close.
    std::thread::sleep(Duration::from_millis(200));
    Ok(summary)
}

fn say(json: bool, v: &serde_json::Value) {
    if json {
        let mut v = v.clone();
        v["format_version"] = auvnav_version::JSON_FORMAT_VERSION.into();
        println!("{v}");
    } else {
        let fields: Vec<String> = v
            .as_object()
            .map(|o| {
                o.iter()
                    .filter(|(k, _)| k.as_str() != "event")
                    .map(|(k, x)| format!("{k} {x}"))
                    .collect()
            })
            .unwrap_or_default();
        println!(
            "sitl-sensors: {}: {}",
            v["event"].as_str().unwrap_or(""),
            fields.join(", ")
        );
    }
    let _ = std::io::stdout().flush();
}

#[cfg(test)]
mod tests {
    use super::*;
    use auvnav_core::strapdown::{ImuIncrement, NavState, Strapdown};

    /// SITL's state on a manoeuvre: heading, pitch and roll swinging, accelerating north-east and
    /// diving, in SITL's flat world (positions integrated from its velocity).
    fn manoeuvre(t: f64) -> SitlState {
        let q = UnitQuaternion::from_euler_angles(
            0.2 * (0.7 * t).sin(),
            0.1 * (0.5 * t).cos(),
            0.8 * t,
        );
        let v = Vector3::new(1.0 + 0.3 * t, 0.5 * (0.4 * t).sin(), 0.1 * t);
        // ∫v dt: positions north, east, down.
        let north = t + 0.15 * t * t;
        let east = 1.25 * (1.0 - (0.4 * t).cos());
        let down = 0.05 * t * t;
        SitlState {
            received: Instant::now(),
            latitude_deg: 47.0 + (north / 6_371_000.0).to_degrees(),
            longitude_deg: 8.0 + (east / (6_371_000.0 * 47f64.to_radians().cos())).to_degrees(),
            altitude_m: -down,
            velocity_ned: v,
            body_to_ned: q,
        }
    }

    #[test]
    fn the_strapdown_integrating_the_intervals_reproduces_sitls_velocity_and_attitude() {
        let dt = 0.005;
        let s0 = manoeuvre(0.0);
        let mut sd = Strapdown::new(NavState {
            time_s: 0.0,
            position: Geodetic {
                latitude_rad: s0.latitude_deg.to_radians(),
                longitude_rad: s0.longitude_deg.to_radians(),
                height_m: s0.altitude_m,
            },
            velocity_ned: s0.velocity_ned,
            q_body_to_ned: s0.body_to_ned,
        });
        let mut prev = s0;
        for k in 1..=6000 {
            let cur = manoeuvre(k as f64 * dt);
            let tr = interval_truth(&prev, &cur, dt, k as f64 * dt, 0.0);
            sd.propagate(&ImuIncrement {
                dtheta: tr.omega_ib_body * dt,
                dv: tr.specific_force_body * dt,
                dt,
            });
            prev = cur;
        }
        // 30 s of a turning, accelerating, diving vehicle.
        let end = manoeuvre(30.0);
        let dv = (sd.state.velocity_ned - end.velocity_ned).norm();
        let datt = (sd.state.q_body_to_ned.inverse() * end.body_to_ned).angle();
        assert!(dv < 2e-3, "velocity off by {dv} m/s");
        assert!(datt < 1e-5, "attitude off by {datt} rad");
    }

    #[test]
    fn a_vehicle_at_rest_in_sitl_reads_the_earths_rate_and_normal_gravity() {
        let q = UnitQuaternion::from_euler_angles(0.0, 0.0, 30f64.to_radians());
        let mut s = manoeuvre(0.0);
        s.velocity_ned = Vector3::zeros();
        s.body_to_ned = q;
        s.altitude_m = -5.0;
        let tr = interval_truth(&s, &s, 0.005, 0.0, 0.0);
        let lat = s.latitude_deg.to_radians();
        assert!((tr.position.height_m + 5.0).abs() < 1e-9);
        let w = tr.c_body_to_ned * tr.omega_ib_body;
        let w_ie = earth::earth_rate_ned(lat);
        assert!((w - w_ie).norm() < 1e-15, "{w} against {w_ie}");
        let f = tr.c_body_to_ned * tr.specific_force_body;
        let g = earth::gravity_ned(lat, -5.0);
        assert!((f + g).norm() < 1e-12, "{f} against {g}");
    }

    #[test]
    fn the_spacing_is_measured_after_a_second_and_restarts_after_a_pause() {
        let t0 = Instant::now();
        let mut sp = Spacing {
            arrivals: [t0].into(),
            nominal_s: 0.005,
        };
        // States 4 ms apart: the nominal 5 ms until a second's worth, then the measured 4 ms.
        let mut t = t0;
        for _ in 0..100 {
            t += Duration::from_millis(4);
            assert_eq!(sp.push(t), 0.005);
        }
        for _ in 0..200 {
            t += Duration::from_millis(4);
            sp.push(t);
        }
        assert!((sp.interval_s() - 0.004).abs() < 1e-9);
        sp.push(t + Duration::from_secs(2));
        assert_eq!(sp.interval_s(), 0.005);
    }

    #[test]
    fn a_state_with_a_non_finite_value_or_no_attitude_is_refused() {
        let good = mav::SIM_STATE_DATA {
            q1: 1.0,
            lat_int: 470_000_000,
            lon_int: 80_000_000,
            alt: 580.0,
            zacc: -9.8,
            ..Default::default()
        };
        let s = from_sim_state(&good, Instant::now()).expect("a good state");
        assert!((s.latitude_deg - 47.0).abs() < 1e-12 && (s.longitude_deg - 8.0).abs() < 1e-12);
        for bad in [
            mav::SIM_STATE_DATA {
                q1: f32::NAN,
                ..good
            },
            mav::SIM_STATE_DATA {
                vn: f32::INFINITY,
                ..good
            },
            mav::SIM_STATE_DATA { q1: 0.0, ..good },
        ] {
            assert!(from_sim_state(&bad, Instant::now()).is_none());
        }
    }
}
