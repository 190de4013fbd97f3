//! The navigation solution to an autopilot over MAVLink (`auvnav-mavlink`): what ArduSub's EKF3
//! takes from an external navigation source, at a limited rate, with the filter's uncertainty
//! and its health.
//!
//! **Messages** (`message` in the configuration):
//! - `odometry` (default): `ODOMETRY` in ArduPilot's external-navigation frames (`frame_id`
//!   `MAV_FRAME_LOCAL_FRD`, `child_frame_id` `MAV_FRAME_BODY_FRD`, the only pair ArduPilot
//!   accepts): position north/east/down from the navigation origin, the body-to-NED quaternion,
//!   velocity in the body frame, the position, attitude and velocity covariances, a reset counter
//!   that steps when the filter restarts, and a quality. With `EK3_SRC1_POSXY/VELXY/POSZ/YAW = 6`
//!   (ExternalNav) and `VISO_TYPE = 1` ArduSub navigates on it, and `SET_GPS_GLOBAL_ORIGIN` (the
//!   navigation's origin) lets it fly global waypoints. It carries the whole state with its
//!   covariance, which `VISION_POSITION_DELTA` (velocity as position deltas, what a DVL alone
//!   sends) and `GLOBAL_VISION_POSITION_ESTIMATE` (no velocity, no quality) do not.
//! - `gps_input`: `GPS_INPUT`, for an autopilot configured to take auvnav as a GPS
//!   (`GPS_TYPE = 14`), as acoustic positioning systems integrate: latitude, longitude, altitude,
//!   NED velocity and the accuracies; the fix type says whether the solution is usable.
//!
//! **Health.** The solution's mode sets the quality (`ODOMETRY`: navigating 100, degraded 50,
//! position unknown 1, invalid −1; aligning or initialising: nothing is sent) and the fix type
//! (`GPS_INPUT`: 3-D while navigating or degraded, no fix otherwise, sent so the autopilot sees
//! the source). Every change of mode and of the fused sensors is one `STATUSTEXT` (e.g.
//! `auvnav: degraded, DVL lost`). `HEARTBEAT` once a second (an onboard controller, system
//! status standby, active, critical or emergency by the same mode).
//!
//! Long on purpose: the last 280 lines are the unit tests, beside the code they test; the code is
//! 645 lines.
#![forbid(unsafe_code)]

pub mod source;

use auvnav_core::earth::{self, Geodetic};
use auvnav_shm_schema::{NavMode, NavSolutionV1};
use mavlink::dialects::ardupilotmega as mav;
use nalgebra::{Matrix3, UnitQuaternion, Vector3};
use serde::{Deserialize, Serialize};

/// Which message carries the solution.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "snake_case")]
pub enum SolutionMessage {
    #[default]
    Odometry,
    GpsInput,
}

/// A fixed navigation origin (`[origin]`).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct OriginConfig {
    pub latitude_deg: f64,
    pub longitude_deg: f64,
    /// Altitude of the origin (m, above mean sea level; a vehicle's navigation height is minus
    /// its depth below the surface).
    #[serde(default)]
    pub altitude_m: f64,
}

/// `auvnav-mavlink`'s configuration file.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct MavlinkConfig {
    /// Service-name prefix of the deployment (default `auvnav`).
    #[serde(default = "default_prefix")]
    pub prefix: String,
    /// The autopilot's link: `udpout:HOST:PORT` (BlueOS's MAVLink router, e.g.
    /// `udpout:192.168.2.1:14550`), `udpin:ADDRESS:PORT`, `tcpout:HOST:PORT` (ArduPilot SITL's
    /// `tcp:127.0.0.1:5760`, a router's TCP server), `tcpin:ADDRESS:PORT`, or
    /// `serial:DEVICE:BAUD`.
    pub address: String,
    /// The vehicle's system id (the autopilot's `SYSID_THISMAV`, default 1).
    #[serde(default = "default_system_id")]
    pub system_id: u8,
    /// This component's id (default 197, `MAV_COMP_ID_VISUAL_INERTIAL_ODOMETRY`, which
    /// ArduPilot's external navigation listens to).
    #[serde(default = "default_component_id")]
    pub component_id: u8,
    /// `odometry` (default) or `gps_input`.
    #[serde(default)]
    pub message: SolutionMessage,
    /// Solutions sent per second (Hz, 1..=50, default 10).
    #[serde(default = "default_rate")]
    pub rate_hz: f64,
    /// Period of `HEARTBEAT` and of `SET_GPS_GLOBAL_ORIGIN` repeats (s, 0.1..=10, default 1).
    #[serde(default = "default_heartbeat")]
    pub heartbeat_period_s: f64,
    /// A fixed origin for `ODOMETRY` positions and `SET_GPS_GLOBAL_ORIGIN`; default: the first
    /// solution in mode navigating.
    #[serde(default)]
    pub origin: Option<OriginConfig>,
    /// The autopilot's sensors onto the bus ([`source`]); none without the table.
    #[serde(default)]
    pub source: Option<source::SourceConfig>,
}

fn default_prefix() -> String {
    auvnav_shm_schema::topic::DEFAULT_PREFIX.to_string()
}
fn default_system_id() -> u8 {
    1
}
fn default_component_id() -> u8 {
    197
}
fn default_rate() -> f64 {
    10.0
}
fn default_heartbeat() -> f64 {
    1.0
}

/// A configuration problem, naming the key.
#[derive(Debug, thiserror::Error)]
pub enum ConfigError {
    #[error("reading {path}: {source}")]
    Read {
        path: String,
        source: std::io::Error,
    },
    #[error("{path}: {message}")]
    Parse { path: String, message: String },
    #[error("{path}: {key} = {value}: expected {expected}")]
    Range {
        path: String,
        key: &'static str,
        value: String,
        expected: &'static str,
    },
}

impl MavlinkConfig {
    pub fn load(path: &str) -> Result<MavlinkConfig, ConfigError> {
        let text = std::fs::read_to_string(path).map_err(|source| ConfigError::Read {
            path: path.to_string(),
            source,
        })?;
        let cfg: MavlinkConfig = toml::from_str(&text).map_err(|e| ConfigError::Parse {
            path: path.to_string(),
            message: e.to_string(),
        })?;
        cfg.check(path)?;
        Ok(cfg)
    }

    pub fn check(&self, path: &str) -> Result<(), ConfigError> {
        let range = |key, value: String, expected| ConfigError::Range {
            path: path.to_string(),
            key,
            value,
            expected,
        };
        let scheme = self.address.split(':').next().unwrap_or_default();
        if !matches!(scheme, "udpout" | "udpin" | "tcpout" | "tcpin" | "serial")
            || self.address.split(':').count() < 3
        {
            return Err(range(
                "address",
                format!("{:?}", self.address),
                "udpout:HOST:PORT, udpin:ADDRESS:PORT, tcpout:HOST:PORT, tcpin:ADDRESS:PORT or serial:DEVICE:BAUD",
            ));
        }
        if !(self.rate_hz.is_finite() && (1.0..=50.0).contains(&self.rate_hz)) {
            return Err(range("rate_hz", self.rate_hz.to_string(), "1..=50 Hz"));
        }
        if !(self.heartbeat_period_s.is_finite() && (0.1..=10.0).contains(&self.heartbeat_period_s))
        {
            return Err(range(
                "heartbeat_period_s",
                self.heartbeat_period_s.to_string(),
                "0.1..=10 s",
            ));
        }
        if self.system_id == 0 {
            return Err(range("system_id", "0".into(), "1..=255"));
        }
        if let Some((key, value, expected)) = self.source.as_ref().and_then(|s| s.problem()) {
            return Err(range(key, value, expected));
        }
        if self.component_id == 0 {
            return Err(range("component_id", "0".into(), "1..=255"));
        }
        if let Some(o) = &self.origin
            && !(o.latitude_deg.abs() <= 90.0
                && o.longitude_deg.abs() <= 180.0
                && o.altitude_m.is_finite()
                && o.altitude_m.abs() <= 11_000.0)
        {
            return Err(range(
                "origin",
                format!("{o:?}"),
                "latitude within ±90, longitude within ±180, altitude within ±11000 m",
            ));
        }
        Ok(())
    }
}

/// What was sent, for the stop line.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize)]
pub struct Counters {
    pub solutions: u64,
    pub heartbeats: u64,
    pub origins: u64,
    pub status_texts: u64,
    /// Solutions not sent: before alignment, or above the rate.
    pub withheld: u64,
}

/// Turns solutions and the passing of time into MAVLink messages (pure: no I/O, no clock).
pub struct Link {
    cfg: MavlinkConfig,
    origin: Option<Geodetic>,
    /// When the solution message is next due: a grid of the configured period, so that the rate
    /// kept is the configured one whatever the solutions' spacing (a send at the first solution
    /// after each due time, not a period after the last send).
    next_due_ns: Option<u64>,
    /// The mode and fused sensors last reported in a STATUSTEXT.
    last_status: Option<(u32, u32)>,
    last_mode: Option<u32>,
    /// The last solution's sequence number: a new session of the daemon starts it again.
    last_sequence: Option<u64>,
    reset_counter: u8,
    /// The origin the autopilot reported (its `GPS_GLOBAL_ORIGIN`), once it has.
    autopilot_origin: Option<Geodetic>,
    /// Until when positions wait for the autopilot's origin (the wall clock of
    /// [`Link::on_tick`]): set when the link opens and when the autopilot is first heard,
    /// [`ORIGIN_WAIT_NS`] later.
    origin_wait_until_ns: Option<u64>,
    /// The wall clock at the last [`Link::on_tick`].
    now_ns: u64,
    autopilot_heard: bool,
    next_heartbeat_ns: u64,
    pub counters: Counters,
}

fn mode_of(m: u32) -> Option<NavMode> {
    NavMode::try_from(m).ok()
}

impl Link {
    pub fn new(cfg: &MavlinkConfig) -> Link {
        Link {
            cfg: cfg.clone(),
            origin: cfg.origin.map(|o| Geodetic {
                latitude_rad: o.latitude_deg.to_radians(),
                longitude_rad: o.longitude_deg.to_radians(),
                height_m: o.altitude_m,
            }),
            next_due_ns: None,
            last_status: None,
            last_mode: None,
            last_sequence: None,
            reset_counter: 0,
            autopilot_origin: None,
            origin_wait_until_ns: None,
            now_ns: 0,
            autopilot_heard: false,
            next_heartbeat_ns: 0,
            counters: Counters::default(),
        }
    }

    /// The header of every message this component sends.
    pub fn header(&self, sequence: u8) -> mavlink::MavHeader {
        mavlink::MavHeader {
            system_id: u32::from(self.cfg.system_id),
            component_id: self.cfg.component_id,
            sequence,
        }
    }

    pub fn origin(&self) -> Option<Geodetic> {
        self.origin
    }

    /// The messages a new solution calls for; `utc_ns` is the wall clock (UTC, ns since 1970),
    /// for `GPS_INPUT`'s GPS time.
    pub fn on_solution(&mut self, s: &NavSolutionV1, utc_ns: i64) -> Vec<mav::MavMessage> {
        let mut out = Vec::new();
        let mode = mode_of(s.mode);
        // The filter restarted, or the daemon did (a new session numbers its solutions from 1
        // again, from its checkpoint or its configuration): the autopilot must take the jump,
        // not filter it away.
        let new_session = self.last_sequence.is_some_and(|q| s.sequence < q);
        if (matches!(mode, Some(NavMode::Invalid | NavMode::PositionUnknown))
            && self.last_mode != Some(s.mode))
            || (new_session && self.counters.solutions > 0)
        {
            self.reset_counter = self.reset_counter.wrapping_add(1);
        }
        self.last_sequence = Some(s.sequence);
        self.last_mode = Some(s.mode);
        if self.last_status != Some((s.mode, s.sensor_health)) {
            let previous = self.last_status.map(|(_, h)| h);
            self.last_status = Some((s.mode, s.sensor_health));
            out.push(status_text(s, previous));
            self.counters.status_texts += 1;
        }
        let usable = matches!(
            mode,
            Some(
                NavMode::Navigating
                    | NavMode::Degraded
                    | NavMode::PositionUnknown
                    | NavMode::Invalid
            )
        );
        let aligned = matches!(mode, Some(NavMode::Navigating | NavMode::Degraded));
        if self.origin.is_none() && aligned && self.cfg.message == SolutionMessage::Odometry {
            self.origin = Some(Geodetic {
                latitude_rad: s.latitude_rad,
                longitude_rad: s.longitude_rad,
                height_m: s.height_m,
            });
            // Sent at once; the heartbeat repeats it.
            if let Some(m) = self.origin_message() {
                out.push(m);
                self.counters.origins += 1;
            }
        }
        let period_ns = (1e9 / self.cfg.rate_hz) as u64;
        let t = s.host_time_ns;
        // Due at or after the grid's time; a clock that went back (a restart) starts it again.
        let due = self
            .next_due_ns
            .is_none_or(|d| t >= d || t.saturating_add(period_ns) < d);
        // A restarted link must not send positions from an origin of its own to an autopilot
        // that has one already: they wait (briefly) for the autopilot to say which.
        let waiting = self
            .origin_wait_until_ns
            .is_some_and(|until| self.now_ns < until);
        let send = match self.cfg.message {
            SolutionMessage::Odometry => usable && self.origin.is_some() && !waiting,
            SolutionMessage::GpsInput => true,
        };
        if !(due && send) {
            self.counters.withheld += 1;
            return out;
        }
        // The next due time on the grid: a send late by less than a period is made up on the
        // next solution; after a longer gap (or a clock that went back) the grid starts again
        // from this solution rather than catching up in a burst.
        let next = self.next_due_ns.map_or(t, |d| d).saturating_add(period_ns);
        self.next_due_ns = Some(
            if next.saturating_add(period_ns) < t || next > t.saturating_add(period_ns) {
                t.saturating_add(period_ns)
            } else {
                next
            },
        );
        self.counters.solutions += 1;
        out.push(match self.cfg.message {
            SolutionMessage::Odometry => {
                let origin = self.origin.unwrap_or(Geodetic {
                    latitude_rad: s.latitude_rad,
                    longitude_rad: s.longitude_rad,
                    height_m: s.height_m,
                });
                odometry(s, &origin, self.reset_counter)
            }
            SolutionMessage::GpsInput => gps_input(s, utc_ns),
        });
        out
    }

    /// The link to the autopilot opened at wall time `now_ns`: positions wait up to
    /// [`ORIGIN_WAIT_NS`] for the autopilot to be heard and say its origin.
    pub fn on_link_open(&mut self, now_ns: u64) {
        if self.autopilot_origin.is_none() {
            self.origin_wait_until_ns = Some(now_ns.saturating_add(ORIGIN_WAIT_NS));
        }
    }

    /// The autopilot's heartbeat came at wall time `now_ns`: the first one gives it
    /// [`ORIGIN_WAIT_NS`] to answer the origin request.
    pub fn on_autopilot_heard(&mut self, now_ns: u64) {
        if !self.autopilot_heard && self.autopilot_origin.is_none() {
            self.origin_wait_until_ns = Some(now_ns.saturating_add(ORIGIN_WAIT_NS));
        }
        self.autopilot_heard = true;
    }

    /// The autopilot's own origin, from its `GPS_GLOBAL_ORIGIN`. EKF3 keeps the first origin it
    /// is given — from a GPS, its `ORIGIN_*` parameters, or an earlier run of this link — and
    /// reads ODOMETRY's positions from it; so once the autopilot has one, positions go out from
    /// it, whatever this link took from its first solution or was configured with. A change
    /// after solutions went out steps the reset counter, so that the autopilot takes the jump.
    /// Returns a line to log when the origin in use changed.
    pub fn on_autopilot_origin(&mut self, o: Geodetic) -> Option<String> {
        if self.cfg.message != SolutionMessage::Odometry || self.autopilot_origin == Some(o) {
            return None;
        }
        self.autopilot_origin = Some(o);
        self.origin_wait_until_ns = None;
        let ours = self.origin.replace(o);
        let place = format!(
            "{:.7}° {:.7}° {:.2} m",
            o.latitude_rad.to_degrees(),
            o.longitude_rad.to_degrees(),
            o.height_m
        );
        let Some(ours) = ours else {
            return Some(format!("taking the autopilot's origin {place}"));
        };
        let (d, dh) = origin_distance(&ours, &o);
        // SET_GPS_GLOBAL_ORIGIN's 1e-7° and millimetres: the autopilot's copy of ours.
        if d < 0.05 && dh.abs() < 0.05 {
            self.origin = Some(ours);
            return None;
        }
        if self.counters.solutions > 0 {
            self.reset_counter = self.reset_counter.wrapping_add(1);
        }
        let whose = if self.cfg.origin.is_some() {
            "the configured [origin]"
        } else {
            "the first solution's"
        };
        Some(format!(
            "the autopilot's origin {place} is {d:.2} m ({dh:+.2} m in height) from {whose}: \
             positions now go out from the autopilot's (reset counter {})",
            self.reset_counter
        ))
    }

    /// The messages due at wall time `now_ns`: the heartbeat and, with it, the origin.
    pub fn on_tick(&mut self, now_ns: u64) -> Vec<mav::MavMessage> {
        self.now_ns = now_ns;
        if now_ns < self.next_heartbeat_ns {
            return Vec::new();
        }
        self.next_heartbeat_ns = now_ns + (self.cfg.heartbeat_period_s * 1e9) as u64;
        self.counters.heartbeats += 1;
        let mut out = vec![heartbeat(self.last_mode.and_then(mode_of))];
        if self.cfg.message == SolutionMessage::Odometry
            && let Some(m) = self.origin_message()
        {
            out.push(m);
            self.counters.origins += 1;
        }
        out
    }

    /// `SET_GPS_GLOBAL_ORIGIN`: what ArduSub takes, from 4.1 to 4.7-dev (checked in SITL). MAVLink
    /// marks it superseded by `MAV_CMD_DO_SET_GLOBAL_ORIGIN` (2025), which 4.7-dev handles too but
    /// the 4.1–4.5 releases on BlueOS vehicles do not.
    #[allow(deprecated)]
    fn origin_message(&self) -> Option<mav::MavMessage> {
        let o = self.origin?;
        Some(mav::MavMessage::SET_GPS_GLOBAL_ORIGIN(
            mav::SET_GPS_GLOBAL_ORIGIN_DATA {
                latitude: (o.latitude_rad.to_degrees() * 1e7).round() as i32,
                longitude: (o.longitude_rad.to_degrees() * 1e7).round() as i32,
                altitude: (o.height_m * 1000.0).round() as i32,
                target_system: self.cfg.system_id,
                ..Default::default()
            },
        ))
    }
}

/// The sensors named in the status text, by their health bits.
const SENSORS: [(u32, &str); 4] = [
    (NavSolutionV1::HEALTH_IMU, "IMU"),
    (NavSolutionV1::HEALTH_DVL, "DVL"),
    (NavSolutionV1::HEALTH_USBL, "USBL"),
    (NavSolutionV1::HEALTH_DEPTH, "depth"),
];

fn status_text(s: &NavSolutionV1, previous_health: Option<u32>) -> mav::MavMessage {
    use mav::MavSeverity::*;
    let (severity, what) = match mode_of(s.mode) {
        Some(NavMode::Initialising) => (MAV_SEVERITY_INFO, "initialising"),
        Some(NavMode::Aligning) => (MAV_SEVERITY_INFO, "aligning"),
        Some(NavMode::Navigating) => (MAV_SEVERITY_INFO, "navigating"),
        Some(NavMode::Degraded) => (MAV_SEVERITY_WARNING, "degraded"),
        Some(NavMode::Invalid) => (MAV_SEVERITY_CRITICAL, "invalid, restarting"),
        Some(NavMode::PositionUnknown) => (MAV_SEVERITY_CRITICAL, "position unknown"),
        None => (MAV_SEVERITY_ERROR, "unknown mode"),
    };
    let mut text = format!("auvnav: {what}");
    if let Some(before) = previous_health {
        let lost: Vec<&str> = SENSORS
            .iter()
            .filter(|(bit, _)| before & bit != 0 && s.sensor_health & bit == 0)
            .map(|(_, n)| *n)
            .collect();
        let back: Vec<&str> = SENSORS
            .iter()
            .filter(|(bit, _)| before & bit == 0 && s.sensor_health & bit != 0)
            .map(|(_, n)| *n)
            .collect();
        if !lost.is_empty() {
            text.push_str(&format!(", {} lost", lost.join(" ")));
        }
        if !back.is_empty() {
            text.push_str(&format!(", {} back", back.join(" ")));
        }
    }
    let mut bytes = [0u8; 50];
    let n = text.len().min(50);
    bytes[..n].copy_from_slice(&text.as_bytes()[..n]);
    mav::MavMessage::STATUSTEXT(mav::STATUSTEXT_DATA {
        severity,
        text: bytes.into(),
        ..Default::default()
    })
}

fn heartbeat(mode: Option<NavMode>) -> mav::MavMessage {
    use mav::MavState::*;
    mav::MavMessage::HEARTBEAT(mav::HEARTBEAT_DATA {
        custom_mode: 0,
        mavtype: mav::MavType::MAV_TYPE_ONBOARD_CONTROLLER,
        autopilot: mav::MavAutopilot::MAV_AUTOPILOT_INVALID,
        base_mode: mav::MavModeFlag::empty(),
        system_status: match mode {
            Some(NavMode::Navigating) => MAV_STATE_ACTIVE,
            Some(NavMode::Degraded) => MAV_STATE_CRITICAL,
            Some(NavMode::Invalid | NavMode::PositionUnknown) => MAV_STATE_EMERGENCY,
            Some(NavMode::Initialising | NavMode::Aligning) => MAV_STATE_STANDBY,
            None => MAV_STATE_BOOT,
        },
        mavlink_version: 3,
    })
}

/// How long positions wait for the autopilot's origin after the link opens or the autopilot is
/// first heard (ns): ArduPilot answers the request within a loop; a heartbeat period and a
/// second to spare.
pub const ORIGIN_WAIT_NS: u64 = 2_000_000_000;

/// Horizontal distance and height difference of `b` from `a` (m), for origins metres apart.
fn origin_distance(a: &Geodetic, b: &Geodetic) -> (f64, f64) {
    let north =
        (b.latitude_rad - a.latitude_rad) * (earth::meridian_radius(a.latitude_rad) + a.height_m);
    let east = (b.longitude_rad - a.longitude_rad)
        * (earth::prime_vertical_radius(a.latitude_rad) + a.height_m)
        * a.latitude_rad.cos();
    (north.hypot(east), b.height_m - a.height_m)
}

/// `ODOMETRY` quality by mode (−1 failed, 1 worst, 100 best).
pub fn quality(mode: u32) -> i8 {
    match mode_of(mode) {
        Some(NavMode::Navigating) => 100,
        Some(NavMode::Degraded) => 50,
        Some(NavMode::PositionUnknown) => 1,
        Some(NavMode::Invalid) => -1,
        _ => 0,
    }
}

/// The upper triangle of a symmetric 6×6 matrix, row-major (MAVLink's 21-element covariance).
fn upper_triangle(p: &[[f64; 6]; 6]) -> [f32; 21] {
    let mut out = [0f32; 21];
    let mut k = 0;
    for (i, row) in p.iter().enumerate() {
        for v in &row[i..] {
            out[k] = *v as f32;
            k += 1;
        }
    }
    out
}

/// `ODOMETRY` of a solution around `origin`.
pub fn odometry(s: &NavSolutionV1, origin: &Geodetic, reset_counter: u8) -> mav::MavMessage {
    let here = Geodetic {
        latitude_rad: s.latitude_rad,
        longitude_rad: s.longitude_rad,
        height_m: s.height_m,
    };
    let ned = earth::ned_offset(origin, &here);
    let [w, x, y, z] = s.quaternion_body_to_ned;
    let q = UnitQuaternion::from_quaternion(nalgebra::Quaternion::new(w, x, y, z));
    let c_nb: Matrix3<f64> = *q.to_rotation_matrix().matrix();
    let v_body = c_nb.transpose() * Vector3::from(s.velocity_ned_m_s);
    let mut pose = [[0.0; 6]; 6];
    for i in 0..3 {
        pose[i][i] = s.position_std_ned_m[i].powi(2);
        pose[i + 3][i + 3] = s.attitude_std_rad[i].powi(2);
    }
    // Velocity covariance in the body frame: C_b^n' diag(σ_ned²) C_b^n. Angular rates unknown.
    let p_ned = Matrix3::from_diagonal(&Vector3::from(s.velocity_std_ned_m_s).map(|v| v * v));
    let p_body = c_nb.transpose() * p_ned * c_nb;
    let mut vel = [[0.0; 6]; 6];
    for i in 0..3 {
        for j in 0..3 {
            vel[i][j] = p_body[(i, j)];
        }
        vel[i + 3][i + 3] = f64::NAN;
    }
    mav::MavMessage::ODOMETRY(mav::ODOMETRY_DATA {
        time_usec: s.host_time_ns / 1000,
        x: ned.x as f32,
        y: ned.y as f32,
        z: ned.z as f32,
        q: [w as f32, x as f32, y as f32, z as f32],
        vx: v_body.x as f32,
        vy: v_body.y as f32,
        vz: v_body.z as f32,
        rollspeed: f32::NAN,
        pitchspeed: f32::NAN,
        yawspeed: f32::NAN,
        pose_covariance: upper_triangle(&pose),
        velocity_covariance: upper_triangle(&vel),
        frame_id: mav::MavFrame::MAV_FRAME_LOCAL_FRD,
        child_frame_id: mav::MavFrame::MAV_FRAME_BODY_FRD,
        reset_counter,
        estimator_type: mav::MavEstimatorType::MAV_ESTIMATOR_TYPE_GPS_INS,
        quality: quality(s.mode),
    })
}

/// GPS time minus UTC since 2017 (s).
const GPS_MINUS_UTC_S: i64 = 18;
const GPS_EPOCH_UNIX_S: i64 = 315_964_800;

/// `GPS_INPUT` of a solution at wall time `utc_ns`.
pub fn gps_input(s: &NavSolutionV1, utc_ns: i64) -> mav::MavMessage {
    let [sn, se, sd] = s.position_std_ned_m;
    let horizontal = sn.hypot(se);
    let speed_accuracy = (s.velocity_std_ned_m_s.iter().map(|v| v * v).sum::<f64>()).sqrt();
    let usable = matches!(
        mode_of(s.mode),
        Some(NavMode::Navigating | NavMode::Degraded)
    );
    let gps_ms = (utc_ns / 1_000_000 + (GPS_MINUS_UTC_S - GPS_EPOCH_UNIX_S) * 1000).max(0);
    const WEEK_MS: i64 = 7 * 86_400_000;
    mav::MavMessage::GPS_INPUT(mav::GPS_INPUT_DATA {
        time_usec: s.host_time_ns / 1000,
        time_week_ms: (gps_ms % WEEK_MS) as u32,
        lat: (s.latitude_rad.to_degrees() * 1e7).round() as i32,
        lon: (s.longitude_rad.to_degrees() * 1e7).round() as i32,
        alt: s.height_m as f32,
        // Dilution of precision has no meaning for an INS: the horizontal accuracy over a 3 m
        // range error, so that the autopilot's HDOP checks follow the accuracy.
        hdop: (horizontal / 3.0).clamp(0.5, 99.0) as f32,
        vdop: (sd / 3.0).clamp(0.5, 99.0) as f32,
        vn: s.velocity_ned_m_s[0] as f32,
        ve: s.velocity_ned_m_s[1] as f32,
        vd: s.velocity_ned_m_s[2] as f32,
        speed_accuracy: speed_accuracy as f32,
        horiz_accuracy: horizontal as f32,
        vert_accuracy: sd as f32,
        ignore_flags: mav::GpsInputIgnoreFlags::empty(),
        time_week: (gps_ms / WEEK_MS) as u16,
        gps_id: 0,
        fix_type: if usable {
            mav::GpsFixType::GPS_FIX_TYPE_3D_FIX
        } else {
            mav::GpsFixType::GPS_FIX_TYPE_NO_FIX
        },
        // ArduPilot's pre-arm checks count satellites: 10 stands for "a good fix", 0 for none.
        satellites_visible: if usable { 10 } else { 0 },
        ..Default::default()
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn config(message: SolutionMessage) -> MavlinkConfig {
        MavlinkConfig {
            prefix: "auvnav".into(),
            address: "udpout:127.0.0.1:14550".into(),
            system_id: 1,
            component_id: 197,
            message,
            rate_hz: 10.0,
            heartbeat_period_s: 1.0,
            origin: None,
            source: None,
        }
    }

    fn solution(t_s: f64, mode: NavMode, north_m: f64) -> NavSolutionV1 {
        let origin = Geodetic {
            latitude_rad: 31f64.to_radians(),
            longitude_rad: 120f64.to_radians(),
            height_m: -20.0,
        };
        let p = earth::offset_position(&origin, &Vector3::new(north_m, 5.0, 0.0));
        // Heading 90 deg (east), level.
        let q = UnitQuaternion::from_euler_angles(0.0, 0.0, std::f64::consts::FRAC_PI_2);
        NavSolutionV1 {
            host_time_ns: (t_s * 1e9) as u64,
            latitude_rad: p.latitude_rad,
            longitude_rad: p.longitude_rad,
            height_m: p.height_m,
            velocity_ned_m_s: [0.0, 1.5, 0.1],
            quaternion_body_to_ned: [q.w, q.i, q.j, q.k],
            position_std_ned_m: [2.0, 3.0, 0.1],
            velocity_std_ned_m_s: [0.01, 0.02, 0.005],
            attitude_std_rad: [0.001, 0.001, 0.004],
            mode: mode as u32,
            sensor_health: NavSolutionV1::HEALTH_IMU
                | NavSolutionV1::HEALTH_DVL
                | NavSolutionV1::HEALTH_DEPTH,
            ..Default::default()
        }
    }

    #[test]
    #[allow(deprecated)]
    fn odometry_waits_for_alignment_then_goes_at_the_rate_around_the_first_aligned_position() {
        let mut link = Link::new(&config(SolutionMessage::Odometry));
        let mut sent = Vec::new();
        for k in 0..400 {
            let t = k as f64 * 0.01;
            let mode = if t < 1.0 {
                NavMode::Aligning
            } else {
                NavMode::Navigating
            };
            sent.extend(link.on_solution(&solution(t, mode, 1.5 * t), 0));
        }
        let odometry: Vec<_> = sent
            .iter()
            .filter_map(|m| match m {
                mav::MavMessage::ODOMETRY(o) => Some(o),
                _ => None,
            })
            .collect();
        // 3 s of navigating at 10 Hz.
        assert_eq!(odometry.len(), 30);
        let first = odometry[0];
        assert!(first.x.abs() < 1e-3 && first.y.abs() < 1e-3);
        let last = odometry[29];
        assert!((last.x - 1.5 * 2.9).abs() < 1e-2, "{}", last.x);
        // East at 1.5 m/s with the vehicle heading east: forward in the body frame.
        assert!((last.vx - 1.5).abs() < 1e-5 && last.vy.abs() < 1e-5);
        assert!((last.vz - 0.1).abs() < 1e-6);
        assert_eq!(last.quality, 100);
        assert_eq!(last.pose_covariance[0], 4.0);
        assert_eq!(last.pose_covariance[6], 9.0);
        // North and east variances swap into the body frame's y and x.
        assert!((last.velocity_covariance[0] - 0.0004).abs() < 1e-9);
        assert!((last.velocity_covariance[6] - 0.0001).abs() < 1e-9);
        let texts: Vec<String> = sent
            .iter()
            .filter_map(|m| match m {
                mav::MavMessage::STATUSTEXT(s) => Some(s.text.to_str().unwrap_or("").to_string()),
                _ => None,
            })
            .collect();
        assert_eq!(texts, vec!["auvnav: aligning", "auvnav: navigating"]);
        assert!(
            sent.iter()
                .any(|m| matches!(m, mav::MavMessage::SET_GPS_GLOBAL_ORIGIN(o)
                // The first aligned position: 1.5 m north of 31 deg (1e-7 deg units).
                if (o.latitude - 310_000_135).abs() <= 1))
        );
    }

    /// The ODOMETRY messages `link` sends for solutions every `step_s` from 0 to `seconds`, with
    /// the stamps jittered by up to a third of a step.
    fn odometry_sent(link: &mut Link, step_s: f64, seconds: f64) -> usize {
        let steps = (seconds / step_s).round() as u64;
        (0..steps)
            .map(|k| {
                let jitter = ((k * 7919 % 11) as f64 / 11.0 - 0.5) * step_s / 1.5;
                let t = 1.0 + k as f64 * step_s + jitter;
                link.on_solution(&solution(t, NavMode::Navigating, 0.0), 0)
                    .iter()
                    .filter(|m| matches!(m, mav::MavMessage::ODOMETRY(_)))
                    .count()
            })
            .sum()
    }

    #[test]
    fn the_configured_rate_is_kept_whatever_the_solutions_spacing() {
        // Solutions at 200, 50, 30 and 13 Hz for 60 s, sent at 10 Hz: 600 within one (the send
        // waits for a solution at or after each due time, at most one step late, never skipped).
        for step in [0.005, 0.02, 1.0 / 30.0, 1.0 / 13.0] {
            let mut link = Link::new(&config(SolutionMessage::Odometry));
            let n = odometry_sent(&mut link, step, 60.0);
            assert!((599..=601).contains(&n), "{n} for solutions every {step} s");
        }
        // Solutions slower than the rate are each sent.
        let mut link = Link::new(&config(SolutionMessage::Odometry));
        assert_eq!(odometry_sent(&mut link, 0.25, 60.0), 240);
        // A clock that goes back (a restarted daemon) starts the grid again at once.
        let mut link = Link::new(&config(SolutionMessage::Odometry));
        odometry_sent(&mut link, 0.02, 10.0);
        let again = link.on_solution(&solution(0.5, NavMode::Navigating, 0.0), 0);
        assert!(
            again
                .iter()
                .any(|m| matches!(m, mav::MavMessage::ODOMETRY(_)))
        );
    }

    #[test]
    fn a_lost_dvl_and_a_restart_are_said_and_counted() {
        let mut link = Link::new(&config(SolutionMessage::Odometry));
        let _ = link.on_solution(&solution(0.0, NavMode::Navigating, 0.0), 0);
        let mut degraded = solution(1.0, NavMode::Degraded, 1.0);
        degraded.sensor_health &= !NavSolutionV1::HEALTH_DVL;
        let out = link.on_solution(&degraded, 0);
        let text = out.iter().find_map(|m| match m {
            mav::MavMessage::STATUSTEXT(s) => {
                Some((s.severity, s.text.to_str().unwrap_or("").to_string()))
            }
            _ => None,
        });
        assert_eq!(
            text,
            Some((
                mav::MavSeverity::MAV_SEVERITY_WARNING,
                "auvnav: degraded, DVL lost".to_string()
            ))
        );
        let out = link.on_solution(&solution(2.0, NavMode::Invalid, 2.0), 0);
        let odo = out.iter().find_map(|m| match m {
            mav::MavMessage::ODOMETRY(o) => Some(o),
            _ => None,
        });
        let odo = odo.expect("an odometry message");
        assert_eq!((odo.quality, odo.reset_counter), (-1, 1));
    }

    #[test]
    fn gps_input_carries_the_accuracy_and_no_fix_before_alignment() {
        let mut link = Link::new(&config(SolutionMessage::GpsInput));
        let out = link.on_solution(
            &solution(0.0, NavMode::Aligning, 0.0),
            1_795_596_601_000_000_000,
        );
        let Some(mav::MavMessage::GPS_INPUT(g)) = out.last() else {
            panic!("{out:?}")
        };
        assert_eq!(g.fix_type, mav::GpsFixType::GPS_FIX_TYPE_NO_FIX);
        let out = link.on_solution(
            &solution(1.0, NavMode::Navigating, 0.0),
            1_795_596_601_000_000_000,
        );
        let Some(mav::MavMessage::GPS_INPUT(g)) = out.last() else {
            panic!("{out:?}")
        };
        assert_eq!(g.fix_type, mav::GpsFixType::GPS_FIX_TYPE_3D_FIX);
        assert!((g.horiz_accuracy - 13f32.sqrt()).abs() < 1e-5);
        assert_eq!(g.ve, 1.5);
        // 2026-11-25 08:50:01 UTC = GPS week 2446, Wednesday 08:50:19.
        assert_eq!(g.time_week, 2446);
        assert_eq!(g.time_week_ms, ((3 * 24 + 8) * 3600 + 50 * 60 + 19) * 1000);
    }

    #[test]
    fn heartbeats_follow_the_wall_clock_and_repeat_the_origin() {
        let mut link = Link::new(&config(SolutionMessage::Odometry));
        assert_eq!(link.on_tick(0).len(), 1, "no origin yet");
        assert!(link.on_tick(500_000_000).is_empty());
        let _ = link.on_solution(&solution(0.0, NavMode::Navigating, 0.0), 0);
        assert_eq!(link.on_tick(1_000_000_000).len(), 2);
        assert_eq!(link.counters.heartbeats, 2);
    }

    #[test]
    fn positions_go_out_from_the_autopilots_origin_and_a_change_steps_the_reset_counter() {
        let mut link = Link::new(&config(SolutionMessage::Odometry));
        let odometry = |out: Vec<mav::MavMessage>| {
            out.into_iter().find_map(|m| match m {
                mav::MavMessage::ODOMETRY(o) => Some(o),
                _ => None,
            })
        };
        // The first solution, 12 m north and 5 m east of the test origin, becomes this link's
        // origin.
        let first = odometry(link.on_solution(&solution(0.0, NavMode::Navigating, 12.0), 0))
            .expect("an ODOMETRY");
        assert!(first.x.abs() < 1e-3 && first.reset_counter == 0);
        // The autopilot repeats it (to its 1e-7° and millimetres): nothing changes.
        let ours = link.origin().expect("an origin");
        let echo = Geodetic {
            latitude_rad: ((ours.latitude_rad.to_degrees() * 1e7).round() * 1e-7).to_radians(),
            longitude_rad: ((ours.longitude_rad.to_degrees() * 1e7).round() * 1e-7).to_radians(),
            height_m: (ours.height_m * 1e3).round() * 1e-3,
        };
        assert_eq!(link.on_autopilot_origin(echo), None);
        assert_eq!(link.origin(), Some(ours));
        // The autopilot's EKF has another origin (set before this link started): positions go
        // out from it, and the jump comes with a new reset counter.
        let theirs = Geodetic {
            latitude_rad: 31f64.to_radians(),
            longitude_rad: 120f64.to_radians(),
            height_m: -20.0,
        };
        let said = link.on_autopilot_origin(theirs).expect("a change to log");
        assert!(said.contains("13.00 m"), "{said}");
        let next = odometry(link.on_solution(&solution(0.2, NavMode::Navigating, 12.0), 0))
            .expect("an ODOMETRY");
        assert!((next.x - 12.0).abs() < 1e-3 && (next.y - 5.0).abs() < 1e-3);
        assert_eq!(next.reset_counter, 1);
        // A link that has sent nothing yet takes the autopilot's origin without a reset.
        let mut fresh = Link::new(&config(SolutionMessage::Odometry));
        assert!(fresh.on_autopilot_origin(theirs).is_some());
        let o = odometry(fresh.on_solution(&solution(0.0, NavMode::Navigating, 3.0), 0))
            .expect("an ODOMETRY");
        assert!((o.x - 3.0).abs() < 1e-3 && o.reset_counter == 0);
        // GPS_INPUT carries positions of its own: the origin does not matter.
        let mut gps = Link::new(&config(SolutionMessage::GpsInput));
        assert_eq!(gps.on_autopilot_origin(theirs), None);
    }

    #[test]
    fn an_opened_link_waits_for_the_autopilots_origin_before_sending_positions() {
        let mut link = Link::new(&config(SolutionMessage::Odometry));
        let odometry = |link: &mut Link, t: f64| {
            link.on_solution(&solution(t, NavMode::Navigating, 12.0), 0)
                .into_iter()
                .find_map(|m| match m {
                    mav::MavMessage::ODOMETRY(o) => Some(o),
                    _ => None,
                })
        };
        link.on_link_open(0);
        link.on_autopilot_heard(500_000_000);
        // Heard at 0.5 s: no positions until 2.5 s by the link's clock unless the origin comes
        // (the solutions' own stamps are another clock).
        link.on_tick(1_000_000_000);
        assert!(odometry(&mut link, 1.0).is_none());
        link.on_tick(2_000_000_000);
        assert!(odometry(&mut link, 2.0).is_none());
        let theirs = Geodetic {
            latitude_rad: 31f64.to_radians(),
            longitude_rad: 120f64.to_radians(),
            height_m: -20.0,
        };
        assert!(link.on_autopilot_origin(theirs).is_some());
        let o = odometry(&mut link, 2.1).expect("positions once the origin is known");
        // From the autopilot's origin, with no reset: nothing was sent from another.
        assert!((o.x - 12.0).abs() < 1e-3 && o.reset_counter == 0);
        // An autopilot without an origin: positions go out from this link's after the wait.
        let mut lone = Link::new(&config(SolutionMessage::Odometry));
        lone.on_link_open(0);
        lone.on_tick(1_900_000_000);
        assert!(odometry(&mut lone, 1.9).is_none());
        lone.on_tick(2_000_000_000);
        assert!(odometry(&mut lone, 2.0).is_some_and(|o| o.x.abs() < 1e-3));
    }

    #[test]
    fn a_restarted_daemon_steps_the_reset_counter() {
        let mut link = Link::new(&config(SolutionMessage::Odometry));
        let mut sent = Vec::new();
        for (k, t) in (0..30).map(|k| (k, k as f64 * 0.1)) {
            let mut s = solution(t, NavMode::Navigating, 0.0);
            // The daemon restarts after 2 s: its solutions are numbered from 1 again.
            s.sequence = if k < 20 { k + 1 } else { k - 19 };
            sent.extend(link.on_solution(&s, 0));
        }
        let counters: Vec<u8> = sent
            .iter()
            .filter_map(|m| match m {
                mav::MavMessage::ODOMETRY(o) => Some(o.reset_counter),
                _ => None,
            })
            .collect();
        assert_eq!(counters.len(), 30);
        assert!(counters[..20].iter().all(|c| *c == 0), "{counters:?}");
        assert!(counters[20..].iter().all(|c| *c == 1), "{counters:?}");
    }
}
