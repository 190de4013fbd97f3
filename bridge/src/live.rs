//! The live view (`auvnav-live`): a read-only Foxglove WebSocket server fed from this host's bus.
//!
//! Every carried topic keeps the channel name, the `ros2msg` schema (name and text) and the CDR
//! encoding of the MCAP log (`auvnav_log`): a panel set up on a recording shows the same fields
//! live. One channel is added for the map: [`LOCATION_TOPIC`], a `foxglove.LocationFix` made from
//! each solution (degrees, ENU covariance, heading and velocity), which the log does not carry.
//!
//! Time stamps: bus messages carry the host's monotonic clock; the live view adds the offset of
//! the real-time clock read at its start, so Foxglove shows wall-clock times.
//!
//! Read-only: the server is started with no capability (no client publishing, no services, no
//! parameters), so a client can subscribe and nothing else; the process has no publisher on the
//! bus but its own health.

use crate::{TOPICS, TopicKind, matches};
use foxglove::schemas::{LocationFix, Timestamp, Vector3, location_fix::PositionCovarianceType};
use serde::{Deserialize, Serialize};
use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};

/// The map panel's channel: a `foxglove.LocationFix` per navigation solution.
pub const LOCATION_TOPIC: &str = "nav/location";

/// The live view's configuration file.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct LiveConfig {
    /// Process name in the health message (default `live`).
    #[serde(default = "default_name")]
    pub name: String,
    /// Service-name prefix of this host's bus (default `auvnav`).
    #[serde(default = "crate::default_prefix")]
    pub prefix: String,
    /// Address to listen on (default `127.0.0.1`: loopback only). To serve the tether or the
    /// ship's network, name that interface's address; `0.0.0.0` serves every interface.
    #[serde(default = "default_host")]
    pub listen_address: String,
    /// TCP port (default 8765, Foxglove's; 0: any free port, named in the log).
    #[serde(default = "default_port")]
    pub port: u16,
    /// Topic names or patterns to serve (default every topic; `*` matches any run of characters).
    #[serde(default = "default_topics")]
    pub topics: Vec<String>,
    /// Rate limits for thin links or slow browsers (`[[rate_limit]]`).
    #[serde(default)]
    pub rate_limit: Vec<LiveRateLimit>,
    /// Messages queued per client before the oldest are dropped (16..=1000000, default 1024).
    #[serde(default = "default_backlog")]
    pub backlog: usize,
    /// Period of the health message (s, 0.05..60, default 1).
    #[serde(default = "crate::default_health_period")]
    pub health_period_s: f64,
    /// Web origins allowed to open the stream (`scheme://host[:port]`, `*` for any). A browser
    /// sends the page's origin with the WebSocket upgrade; any other page open in the operator's
    /// browser is refused (403). Clients that send no origin (the Foxglove desktop app, scripts)
    /// are let through. Default `["https://app.foxglove.dev"]`.
    #[serde(default = "default_origins")]
    pub allowed_origins: Vec<String>,
    /// Clients served at once (1..=1000); more are refused (503). Default 8.
    #[serde(default = "default_max_connections")]
    pub max_connections: usize,
}

fn default_origins() -> Vec<String> {
    vec!["https://app.foxglove.dev".into()]
}

fn default_max_connections() -> usize {
    8
}

/// One `[[rate_limit]]`: at most `max_rate_hz` messages per second on each matching topic.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct LiveRateLimit {
    pub topics: String,
    pub max_rate_hz: f64,
}

fn default_name() -> String {
    "live".into()
}
fn default_host() -> String {
    "127.0.0.1".into()
}
fn default_port() -> u16 {
    8765
}
fn default_topics() -> Vec<String> {
    vec!["*".into()]
}
fn default_backlog() -> usize {
    1024
}

impl Default for LiveConfig {
    fn default() -> Self {
        LiveConfig {
            name: default_name(),
            prefix: crate::default_prefix(),
            listen_address: default_host(),
            port: default_port(),
            topics: default_topics(),
            rate_limit: Vec::new(),
            backlog: default_backlog(),
            health_period_s: crate::default_health_period(),
            allowed_origins: default_origins(),
            max_connections: default_max_connections(),
        }
    }
}

impl LiveConfig {
    /// Reads and checks a configuration file.
    pub fn load(path: &str) -> Result<LiveConfig, crate::ConfigError> {
        let text = std::fs::read_to_string(path)
            .map_err(|e| crate::ConfigError(format!("reading {path}: {e}")))?;
        let cfg: LiveConfig =
            toml::from_str(&text).map_err(|e| crate::ConfigError(format!("{path}: {e}")))?;
        cfg.check()
            .map_err(|e| crate::ConfigError(format!("{path}: {e}")))?;
        Ok(cfg)
    }

    /// The problems of the configuration, if any.
    pub fn check(&self) -> Result<(), String> {
        if self.listen_address.parse::<std::net::IpAddr>().is_err() {
            return Err(format!(
                "listen_address = {:?}: expected an IP address (127.0.0.1, an interface's \
                 address, or 0.0.0.0 for every interface)",
                self.listen_address
            ));
        }
        if !(self.health_period_s.is_finite() && (0.05..=60.0).contains(&self.health_period_s)) {
            return Err(format!(
                "health_period_s = {}: expected 0.05..=60",
                self.health_period_s
            ));
        }
        if let Some(o) = self
            .allowed_origins
            .iter()
            .find(|o| !crate::gate::is_origin(o))
        {
            return Err(format!(
                "allowed_origins: {o:?}: expected an origin, scheme://host[:port] \
                 (https://app.foxglove.dev), or \"*\""
            ));
        }
        if !(1..=1000).contains(&self.max_connections) {
            return Err(format!(
                "max_connections = {}: expected 1..=1000",
                self.max_connections
            ));
        }
        if !(16..=1_000_000).contains(&self.backlog) {
            return Err(format!("backlog = {}: expected 16..=1000000", self.backlog));
        }
        if self.topics.is_empty() {
            return Err("topics = []: nothing to serve".into());
        }
        for t in &self.topics {
            if TOPICS.iter().all(|k| !matches(t, k.name)) {
                return Err(format!(
                    "topics: {t:?} matches no topic (known: {})",
                    crate::known_topics()
                ));
            }
        }
        for l in &self.rate_limit {
            if !(l.max_rate_hz.is_finite() && l.max_rate_hz > 0.0 && l.max_rate_hz <= 100_000.0) {
                return Err(format!(
                    "rate_limit {:?}: max_rate_hz = {}: expected 0 < x <= 100000",
                    l.topics, l.max_rate_hz
                ));
            }
            if TOPICS.iter().all(|k| !matches(&l.topics, k.name)) {
                return Err(format!(
                    "rate_limit topics = {:?} matches no topic",
                    l.topics
                ));
            }
        }
        Ok(())
    }

    /// The topics served, in the bridge's table order.
    pub fn served(&self) -> Vec<&'static TopicKind> {
        TOPICS
            .iter()
            .filter(|k| self.topics.iter().any(|t| matches(t, k.name)))
            .collect()
    }

    /// The rate limit of a topic (Hz; 0 = none): the first `[[rate_limit]]` that matches.
    pub fn max_rate_hz(&self, topic: &str) -> f64 {
        self.rate_limit
            .iter()
            .find(|l| matches(&l.topics, topic))
            .map_or(0.0, |l| l.max_rate_hz)
    }
}

/// Real-time clock = monotonic clock + offset, read once.
#[derive(Debug, Clone, Copy)]
pub struct WallClock {
    offset_ns: i128,
}

impl WallClock {
    pub fn now() -> WallClock {
        let before = auvnav_shm_schema::clock::monotonic_ns() as i128;
        let unix = std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .map_or(0, |d| d.as_nanos() as i128);
        let after = auvnav_shm_schema::clock::monotonic_ns() as i128;
        WallClock {
            offset_ns: unix - (before + after) / 2,
        }
    }
    /// Unix time (ns) of a monotonic time stamp.
    pub fn unix_ns(&self, monotonic_ns: u64) -> u64 {
        (monotonic_ns as i128 + self.offset_ns).clamp(0, u64::MAX as i128) as u64
    }
}

/// The map's position of a solution: degrees, height as altitude, the position's one-sigma
/// uncertainty as a diagonal ENU covariance, heading (yaw, clockwise from north) and velocity
/// in ENU.
pub fn location_fix(s: &auvnav_shm_schema::NavSolutionV1, unix_ns: u64) -> LocationFix {
    let [sn, se, sd] = s.position_std_ned_m;
    let [vn, ve, vd] = s.velocity_ned_m_s;
    LocationFix {
        timestamp: Some(Timestamp::new(
            (unix_ns / 1_000_000_000) as u32,
            (unix_ns % 1_000_000_000) as u32,
        )),
        frame_id: "vehicle".into(),
        latitude: s.latitude_rad.to_degrees(),
        longitude: s.longitude_rad.to_degrees(),
        altitude: s.height_m,
        position_covariance: vec![se * se, 0.0, 0.0, 0.0, sn * sn, 0.0, 0.0, 0.0, sd * sd],
        position_covariance_type: PositionCovarianceType::DiagonalKnown as i32,
        heading: Some(s.euler_rad[2]),
        velocity: Some(Vector3 {
            x: ve,
            y: vn,
            z: -vd,
        }),
        color: None,
        metadata: Vec::new(),
    }
}

/// The log's CDR payload of a bus message's bytes: the encapsulation header, then the bytes.
pub fn cdr_payload(bytes: &[u8]) -> Vec<u8> {
    let mut v = Vec::with_capacity(auvnav_log::CDR_HEADER.len() + bytes.len());
    v.extend_from_slice(&auvnav_log::CDR_HEADER);
    v.extend_from_slice(bytes);
    v
}

/// Counts the Foxglove server's reports that a client's outbox was full (the client does not
/// keep up and its oldest messages are being dropped). The SDK reports at most one such event
/// every 30 s and does not count the messages it drops for that client.
#[derive(Debug, Clone, Default)]
pub struct SlowClientReports(pub Arc<AtomicU64>);

impl SlowClientReports {
    pub fn count(&self) -> u64 {
        self.0.load(Ordering::Relaxed)
    }
}

struct MessageText(String);

impl tracing::field::Visit for MessageText {
    fn record_debug(&mut self, field: &tracing::field::Field, value: &dyn std::fmt::Debug) {
        if field.name() == "message" {
            self.0 = format!("{value:?}");
        }
    }
    fn record_str(&mut self, field: &tracing::field::Field, value: &str) {
        if field.name() == "message" {
            self.0 = value.to_string();
        }
    }
}

impl<S: tracing::Subscriber> tracing_subscriber::Layer<S> for SlowClientReports {
    fn on_event(
        &self,
        event: &tracing::Event<'_>,
        _ctx: tracing_subscriber::layer::Context<'_, S>,
    ) {
        if !event.metadata().target().starts_with("foxglove") {
            return;
        }
        let mut text = MessageText(String::new());
        event.record(&mut text);
        if is_slow_client_report(&text.0) {
            self.0.fetch_add(1, Ordering::Relaxed);
        }
    }
}

/// Whether a Foxglove SDK log line reports a client whose outbox is full.
pub fn is_slow_client_report(message: &str) -> bool {
    message.contains("outbox for client") && message.ends_with("full")
}

#[cfg(test)]
mod tests {
    use super::*;
    use auvnav_shm_schema::NavSolutionV1;

    #[test]
    fn a_solution_becomes_a_map_position_in_degrees_with_enu_covariance() {
        let s = NavSolutionV1 {
            latitude_rad: 31.5f64.to_radians(),
            longitude_rad: (-120.25f64).to_radians(),
            height_m: -42.0,
            position_std_ned_m: [1.0, 2.0, 0.5],
            velocity_ned_m_s: [1.5, -0.5, 0.1],
            euler_rad: [0.0, 0.0, 0.75],
            ..Default::default()
        };
        let f = location_fix(&s, 1_700_000_000_250_000_000);
        assert!((f.latitude - 31.5).abs() < 1e-12);
        assert!((f.longitude + 120.25).abs() < 1e-12);
        assert_eq!(f.altitude, -42.0);
        // ENU: east variance first, then north, then up.
        assert_eq!(f.position_covariance[0], 4.0);
        assert_eq!(f.position_covariance[4], 1.0);
        assert_eq!(f.position_covariance[8], 0.25);
        let v = f.velocity.expect("velocity");
        assert_eq!((v.x, v.y, v.z), (-0.5, 1.5, -0.1));
        assert_eq!(f.heading, Some(0.75));
        let t = f.timestamp.expect("time");
        assert_eq!((t.sec(), t.nsec()), (1_700_000_000, 250_000_000));
    }

    #[test]
    fn the_payload_is_the_logs_cdr_message() {
        let m = NavSolutionV1 {
            sequence: 9,
            height_m: -1.0,
            ..Default::default()
        };
        let p = cdr_payload(bytemuck::bytes_of(&m));
        let back: NavSolutionV1 = auvnav_log::decode_pod("nav/solution", &p).expect("decodes");
        assert_eq!((back.sequence, back.height_m), (9, -1.0));
    }

    #[test]
    fn configuration_defaults_to_loopback_and_names_problems() {
        let cfg: LiveConfig = toml::from_str("").expect("empty file");
        assert_eq!(cfg, LiveConfig::default());
        assert_eq!(cfg.listen_address, "127.0.0.1");
        assert!(cfg.check().is_ok());
        assert_eq!(cfg.served().len(), TOPICS.len());
        let with = |t: &str| -> Result<(), String> {
            toml::from_str::<LiveConfig>(t)
                .map_err(|e| e.to_string())
                .and_then(|c| c.check())
        };
        for (text, expected) in [
            ("listen_address = \"localhost:1\"", "expected an IP address"),
            ("topics = [\"nope\"]", "matches no topic"),
            ("topics = []", "nothing to serve"),
            ("backlog = 2", "backlog"),
            (
                "[[rate_limit]]\ntopics = \"imu\"\nmax_rate_hz = 0.0",
                "expected 0 < x",
            ),
            ("commands = true", "unknown field"),
        ] {
            let e = with(text).expect_err(text);
            assert!(e.contains(expected), "{text}: {e}");
        }
        let c: LiveConfig = toml::from_str(
            "[[rate_limit]]\ntopics = \"imu\"\nmax_rate_hz = 50.0\n[[rate_limit]]\ntopics = \"*\"\nmax_rate_hz = 5.0",
        )
        .expect("parses");
        assert_eq!(c.max_rate_hz("imu"), 50.0);
        assert_eq!(c.max_rate_hz("dvl"), 5.0);
    }

    #[test]
    fn the_sdks_full_outbox_report_is_recognised() {
        assert!(is_slow_client_report(
            "outbox for client 127.0.0.1:5555 full"
        ));
        assert!(!is_slow_client_report("client 127.0.0.1:5555 connected"));
    }
}

#[cfg(test)]
mod layout_tests {
    use super::*;

    /// Every message path of the Foxglove layout in `deploy/` names a channel the live view
    /// serves and a field of that channel's schema.
    #[test]
    fn the_layouts_panels_name_served_topics_and_their_fields() {
        let text = include_str!("../../deploy/foxglove-layout.json");
        let layout: serde_json::Value = serde_json::from_str(text).expect("layout JSON");
        let panels = layout["configById"].as_object().expect("configById");
        let mut paths = Vec::new();
        for (id, cfg) in panels {
            if let Some(list) = cfg["paths"].as_array() {
                paths.extend(list.iter().filter_map(|p| p["value"].as_str()));
            }
            for key in ["topicPath", "followTopic"] {
                if let Some(t) = cfg[key].as_str() {
                    paths.push(t);
                }
            }
            assert!(
                ["Map!", "Plot!", "Table!", "RawMessages!"]
                    .iter()
                    .any(|k| id.starts_with(k)),
                "{id}"
            );
        }
        let mut layout_ids = Vec::new();
        fn leaves<'a>(v: &'a serde_json::Value, out: &mut Vec<&'a str>) {
            match v {
                serde_json::Value::String(s) => out.push(s),
                serde_json::Value::Object(o) => {
                    for k in ["first", "second"] {
                        if let Some(c) = o.get(k) {
                            leaves(c, out);
                        }
                    }
                }
                _ => {}
            }
        }
        leaves(&layout["layout"], &mut layout_ids);
        assert_eq!(layout_ids.len(), panels.len(), "every panel is placed once");
        assert!(paths.len() >= 15);
        for path in paths {
            // `"nav/solution"{source==1}.innovation[0]` or a bare topic name.
            let (topic, rest) = match path.strip_prefix('"') {
                Some(p) => p.split_once('"').expect("closing quote"),
                None => (path, ""),
            };
            if topic == LOCATION_TOPIC {
                continue;
            }
            let kind = TopicKind::by_name(topic).unwrap_or_else(|| panic!("{path}: topic"));
            let schema = (kind.ros2msg)();
            let rest = match rest.split_once('}') {
                Some((filter, r)) => {
                    let field = filter.trim_start_matches('{').split("==").next();
                    let field = field.expect("filter field");
                    assert!(schema.contains(&format!(" {field}\n")), "{path}");
                    r
                }
                None => rest,
            };
            if let Some(field) = rest.strip_prefix('.') {
                let name = field.split('[').next().expect("field");
                assert!(
                    schema
                        .lines()
                        .any(|l| l.split_whitespace().nth(1) == Some(name)),
                    "{path}: no field {name} in {}",
                    kind.schema_name
                );
            }
        }
    }
}
