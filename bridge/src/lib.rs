//! `auvnav-bridge`: carries selected topics of one host's shared-memory bus to other hosts over
//! Zenoh, and brings other hosts' topics onto this host's bus.
//!
//! No release of iceoryx2's own tunnel (`iceoryx2-tunnel-zenoh`, last published for iceoryx2
//! 0.8) matches the iceoryx2 0.10 the processes use, so this is a small bridge on the `zenoh`
//! crate that keeps the bus's message types:
//!
//! - **export**: a topic of the local bus (by name pattern) is published on the Zenoh key
//!   `<key_prefix>/<topic>`, the payload being the message's bytes (its `#[repr(C)]` layout,
//!   which is also its little-endian CDR body) and the attachment its versioned type name
//!   (`auvnav/NavSolution/v1`); a per-topic rate limit thins it for slow links;
//! - **import**: keys under a remote `<key_prefix>` are published on this host's bus under a
//!   local prefix (`[[import]] prefix`), so `auvnav record --prefix <that>` and the tools work on
//!   the far side as on the vehicle. A sample whose type name or size does not match the topic's
//!   type is counted and dropped; messages keep their original sequence numbers.
//!
//! The bridge only reads the local bus for export and only publishes imported topics under
//! their own prefix: nothing from the network reaches the daemon's inputs unless an operator
//! imports under the vehicle's own prefix, which the configuration refuses.
#![forbid(unsafe_code)]

use auvnav_shm_schema::bus::{Bus, BusError, BusPublisher, BusSubscriber, Sequenced};
use auvnav_shm_schema::qos::{self, ServiceQos};
use auvnav_shm_schema::{
    AcousticRangesV1, AidDiagnosticsV1, DepthV1, DvlVelocityV1, GnssFixV1, ImuSampleV1, LateAidV1,
    MagnetometerV1, Message, NavSolutionV1, ProcessHealthV1, SessionEventV1, SoundVelocityV1,
    UsblFixV1, topic,
};
use serde::{Deserialize, Serialize};

pub mod gate;
#[cfg(feature = "live")]
pub mod live;
pub mod live_client;
pub mod ros2;

/// The bridge's configuration file.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct BridgeConfig {
    /// Process name in the health message (default `bridge`).
    #[serde(default = "default_name")]
    pub name: String,
    /// Service-name prefix of this host's bus (default `auvnav`).
    #[serde(default = "default_prefix")]
    pub prefix: String,
    #[serde(default)]
    pub zenoh: ZenohConfig,
    /// Topics of this host's bus published over Zenoh.
    #[serde(default)]
    pub export: Vec<ExportConfig>,
    /// Remote topics published on this host's bus.
    #[serde(default)]
    pub import: Vec<ImportConfig>,
    /// The solution, IMU, DVL and health as ROS 2 topics, the way rmw_zenoh publishes them
    /// (see `auvnav_bridge::ros2`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub ros2: Option<ros2::Ros2Config>,
    /// Period of the health message and of the counters in the log (s, 0.05..60, default 1).
    #[serde(default = "default_health_period")]
    pub health_period_s: f64,
}

fn default_name() -> String {
    "bridge".into()
}
pub(crate) fn default_prefix() -> String {
    topic::DEFAULT_PREFIX.into()
}
pub(crate) fn default_health_period() -> f64 {
    1.0
}

/// The Zenoh session (`[zenoh]`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct ZenohConfig {
    /// `peer` (default) or `client`.
    pub mode: String,
    /// Endpoints to listen on (default `tcp/127.0.0.1:7447`: loopback only). To serve a
    /// tether or a ship's network, name that interface's address (`tcp/192.168.1.10:7447`),
    /// never `0.0.0.0` unless every interface is trusted.
    pub listen: Vec<String>,
    /// Endpoints of other bridges or Zenoh routers to connect to.
    pub connect: Vec<String>,
    /// Find peers by multicast scouting (default false: only the endpoints above).
    pub multicast_scouting: bool,
}

impl Default for ZenohConfig {
    fn default() -> Self {
        ZenohConfig {
            mode: "peer".into(),
            listen: vec!["tcp/127.0.0.1:7447".into()],
            connect: Vec::new(),
            multicast_scouting: false,
        }
    }
}

/// One exported set of topics (`[[export]]`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ExportConfig {
    /// Topic name or pattern (`nav/solution`, `nav/*`, `*`); `*` matches any run of characters.
    pub topics: String,
    /// Zenoh key prefix (`auvnav/vehicle1`): a topic is published on `<key_prefix>/<topic>`.
    pub key_prefix: String,
    /// At most this many messages per second per topic (Hz; 0 = every message).
    #[serde(default)]
    pub max_rate_hz: f64,
}

/// One imported set of topics (`[[import]]`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ImportConfig {
    /// The remote key prefix (as the far side's `[[export]] key_prefix`).
    pub key_prefix: String,
    /// Topic name or pattern to take (default `*`).
    #[serde(default = "default_all")]
    pub topics: String,
    /// Prefix of this host's bus under which the topics appear (`vehicle1`: its solution is
    /// `vehicle1/nav/solution`). Must differ from `prefix`.
    pub prefix: String,
}

fn default_all() -> String {
    "*".into()
}

/// A configuration problem, naming the file and the key.
#[derive(Debug, thiserror::Error)]
#[error("{0}")]
pub struct ConfigError(pub String);

impl BridgeConfig {
    /// Reads and checks a configuration file.
    pub fn load(path: &str) -> Result<BridgeConfig, ConfigError> {
        let text = std::fs::read_to_string(path)
            .map_err(|e| ConfigError(format!("reading {path}: {e}")))?;
        let cfg: BridgeConfig =
            toml::from_str(&text).map_err(|e| ConfigError(format!("{path}: {e}")))?;
        cfg.check()
            .map_err(|e| ConfigError(format!("{path}: {e}")))?;
        Ok(cfg)
    }

    /// The problems of the configuration, if any.
    pub fn check(&self) -> Result<(), String> {
        if !(self.health_period_s.is_finite() && (0.05..=60.0).contains(&self.health_period_s)) {
            return Err(format!(
                "health_period_s = {}: expected 0.05..=60",
                self.health_period_s
            ));
        }
        if !["peer", "client"].contains(&self.zenoh.mode.as_str()) {
            return Err(format!(
                "zenoh.mode = {:?}: expected \"peer\" or \"client\"",
                self.zenoh.mode
            ));
        }
        for (key, list) in [
            ("zenoh.listen", &self.zenoh.listen),
            ("zenoh.connect", &self.zenoh.connect),
        ] {
            for e in list.iter() {
                check_endpoint(e).map_err(|why| format!("{key}: {e:?}: {why}"))?;
            }
        }
        if self.export.is_empty() && self.import.is_empty() && self.ros2.is_none() {
            return Err("nothing to do: no [[export]], no [[import]] and no [ros2]".into());
        }
        if let Some(r) = &self.ros2 {
            r.check()?;
        }
        for e in &self.export {
            check_key_prefix(&e.key_prefix)?;
            if !(e.max_rate_hz.is_finite() && (0.0..=100_000.0).contains(&e.max_rate_hz)) {
                return Err(format!(
                    "export {:?}: max_rate_hz = {}: expected 0..=100000 (0 = every message)",
                    e.topics, e.max_rate_hz
                ));
            }
            if TOPICS.iter().all(|t| !matches(&e.topics, t.name)) {
                return Err(format!(
                    "export topics = {:?} matches no topic (known: {})",
                    e.topics,
                    known_topics()
                ));
            }
        }
        for i in &self.import {
            check_key_prefix(&i.key_prefix)?;
            if i.prefix == self.prefix || i.prefix.is_empty() {
                return Err(format!(
                    "import prefix = {:?}: must be set and differ from this bus's prefix {:?} \
                     (imported messages never reach this host's own topics)",
                    i.prefix, self.prefix
                ));
            }
            if TOPICS.iter().all(|t| !matches(&i.topics, t.name)) {
                return Err(format!(
                    "import topics = {:?} matches no topic (known: {})",
                    i.topics,
                    known_topics()
                ));
            }
        }
        Ok(())
    }
}

/// A Zenoh endpoint as the bridge uses them: `tcp/HOST:PORT` or `udp/HOST:PORT` (an IP address
/// or a host name, a port 0..=65535; `#`-options and `?`-metadata after it are left to Zenoh).
fn check_endpoint(e: &str) -> Result<(), String> {
    let core = e.split(['#', '?']).next().unwrap_or_default();
    let Some((proto, addr)) = core.split_once('/') else {
        return Err("expected PROTOCOL/HOST:PORT, e.g. tcp/127.0.0.1:7447".into());
    };
    if !["tcp", "udp", "tls", "quic"].contains(&proto) {
        return Err(format!(
            "protocol {proto:?}: expected tcp, udp, tls or quic"
        ));
    }
    if addr.parse::<std::net::SocketAddr>().is_ok() {
        return Ok(());
    }
    let Some((host, port)) = addr.rsplit_once(':') else {
        return Err("expected HOST:PORT after the protocol".into());
    };
    let host_ok = !host.is_empty()
        && host
            .chars()
            .all(|c| c.is_ascii_alphanumeric() || c == '-' || c == '.');
    if !host_ok || port.parse::<u16>().is_err() {
        return Err("expected an IP address or a host name, then :PORT (0..=65535)".into());
    }
    Ok(())
}

fn check_key_prefix(k: &str) -> Result<(), String> {
    let ok = !k.is_empty()
        && !k.starts_with('/')
        && !k.ends_with('/')
        && !k.contains("//")
        && !k.contains(['*', '$', '?', '#']);
    if ok {
        Ok(())
    } else {
        Err(format!(
            "key_prefix = {k:?}: expected chunks separated by '/' (auvnav/vehicle1), without \
             wildcards"
        ))
    }
}

/// Whether `topic` matches `pattern`, where `*` stands for any run of characters (also `/`).
pub fn matches(pattern: &str, topic: &str) -> bool {
    let Some((head, rest)) = pattern.split_once('*') else {
        return pattern == topic;
    };
    let Some(tail) = topic.strip_prefix(head) else {
        return false;
    };
    (0..=tail.len())
        .filter(|&k| tail.is_char_boundary(k))
        .any(|k| matches(rest, &tail[k..]))
}

/// Opens the local side of an exported topic on a bus.
type OpenExport = fn(&Bus, &str) -> Result<Box<dyn ExportPort>, BusError>;
/// Opens the local side of an imported topic on a bus.
type OpenImport = fn(&Bus, &str) -> Result<Box<dyn ImportPort>, BusError>;

/// A topic the bridge can carry: its name, quality of service and message type.
pub struct TopicKind {
    pub name: &'static str,
    pub qos: ServiceQos,
    /// The bus's versioned type name (`auvnav/NavSolution/v1`).
    pub type_name: &'static str,
    /// The log's schema name (`auvnav_msgs/msg/NavSolutionV1`).
    pub schema_name: &'static str,
    /// The log's `ros2msg` schema text.
    pub ros2msg: fn() -> String,
    pub size: usize,
    export: OpenExport,
    import: OpenImport,
}

macro_rules! topics {
    ($($name:expr => $t:ty, $qos:expr;)*) => {
        /// Every topic the bridge can carry (the raw byte captures stay on board).
        pub const TOPICS: &[TopicKind] = &[$(TopicKind {
            name: $name,
            qos: $qos,
            type_name: <$t as Message>::TYPE_NAME,
            schema_name: <$t as Message>::SCHEMA_NAME,
            ros2msg: <$t as Message>::ros2msg_definition,
            size: std::mem::size_of::<$t>(),
            export: |bus, name| Ok(Box::new(bus.subscriber::<$t>(name, $qos)?)),
            import: |bus, name| Ok(Box::new(bus.publisher::<$t>(name, $qos)?)),
        }),*];
    };
}

topics! {
    topic::NAV_SOLUTION => NavSolutionV1, qos::NAVIGATION;
    topic::NAV_AID_DIAGNOSTICS => AidDiagnosticsV1, qos::NAVIGATION;
    topic::NAV_LATE_AIDS => LateAidV1, qos::NAVIGATION;
    topic::NAV_SESSION_EVENTS => SessionEventV1, qos::NAVIGATION;
    topic::HEALTH => ProcessHealthV1, qos::HEALTH;
    topic::IMU => ImuSampleV1, qos::SENSOR;
    topic::DVL => DvlVelocityV1, qos::SENSOR;
    topic::USBL => UsblFixV1, qos::SENSOR;
    topic::DEPTH => DepthV1, qos::SENSOR;
    topic::MAGNETOMETER => MagnetometerV1, qos::SENSOR;
    topic::ACOUSTIC_RANGES => AcousticRangesV1, qos::SENSOR;
    topic::GNSS => GnssFixV1, qos::SENSOR;
    topic::SOUND_VELOCITY => SoundVelocityV1, qos::SENSOR;
}

pub(crate) fn known_topics() -> String {
    TOPICS.iter().map(|t| t.name).collect::<Vec<_>>().join(", ")
}

impl TopicKind {
    /// The topic of this name.
    pub fn by_name(name: &str) -> Option<&'static TopicKind> {
        TOPICS.iter().find(|t| t.name == name)
    }
    pub fn exporter(&self, bus: &Bus) -> Result<Box<dyn ExportPort>, BusError> {
        (self.export)(bus, self.name)
    }
    pub fn importer(&self, bus: &Bus) -> Result<Box<dyn ImportPort>, BusError> {
        (self.import)(bus, self.name)
    }
}

/// The local side of an exported topic: the next message's host time (ns) and bytes.
pub trait ExportPort {
    fn next_bytes(&mut self) -> Result<Option<(u64, Vec<u8>)>, BusError>;
}

impl<T: Message + Sequenced> ExportPort for BusSubscriber<T> {
    fn next_bytes(&mut self) -> Result<Option<(u64, Vec<u8>)>, BusError> {
        Ok(self
            .receive()?
            .map(|m| (m.host_time().0, bytemuck::bytes_of(&m).to_vec())))
    }
}

/// A listener on a topic's event service (`Bus::listener`).
pub type TopicListener = iceoryx2::port::listener::Listener<iceoryx2::prelude::ipc::Service>;

/// The loop of the bridge and the live view: calls `step` with the monotonic time each time one
/// of `listeners` is notified or `tick` has passed, until SIGTERM or SIGINT (`Ok`) or until `step`
/// fails (its error).
pub fn wake_loop(
    listeners: &[TopicListener],
    tick: std::time::Duration,
    mut step: impl FnMut(u64) -> Result<(), String>,
) -> Result<(), String> {
    use iceoryx2::prelude::{CallbackProgression, WaitSetBuilder, ipc};
    use iceoryx2::waitset::WaitSetRunResult;
    let waitset = WaitSetBuilder::new()
        .create::<ipc::Service>()
        .map_err(|x| format!("creating the WaitSet: {x:?}"))?;
    let _guards = listeners
        .iter()
        .map(|l| waitset.attach_notification(l))
        .collect::<Result<Vec<_>, _>>()
        .map_err(|x| format!("attaching a listener: {x:?}"))?;
    let _tick = waitset
        .attach_interval(tick)
        .map_err(|x| format!("attaching the tick: {x:?}"))?;
    loop {
        match waitset.wait_and_process_once(|_| CallbackProgression::Continue) {
            Ok(WaitSetRunResult::TerminationRequest) => return Ok(()),
            // SIGTERM or SIGINT came, perhaps followed by another signal (systemd's SIGCONT).
            Ok(_) if auvnav_shm_schema::bus::termination_signalled() => return Ok(()),
            // Another signal (SIGCONT after a stop, a debugger's) interrupted the wait.
            Ok(WaitSetRunResult::Interrupt) => continue,
            Ok(_) => {}
            Err(x) => return Err(format!("waiting: {x:?}")),
        }
        for l in listeners {
            let _ = l.try_wait(|_| {});
        }
        step(auvnav_shm_schema::clock::monotonic_ns())?;
    }
}

/// Why an imported sample was dropped.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Rejected {
    /// The attachment names another type than the topic's (or none).
    WrongType,
    /// The payload is not one message of the topic's type.
    WrongSize,
    /// The bytes are not a valid message (a NaN where a number must be finite is kept: the
    /// receivers validate values as they do for local messages).
    Bus(String),
}

/// The local side of an imported topic: publishes a message given as bytes.
pub trait ImportPort {
    fn publish_bytes(&mut self, bytes: &[u8]) -> Result<(), Rejected>;
}

impl<T: Message + Sequenced> ImportPort for BusPublisher<T> {
    fn publish_bytes(&mut self, bytes: &[u8]) -> Result<(), Rejected> {
        let m: T = bytemuck::try_pod_read_unaligned(bytes).map_err(|_| Rejected::WrongSize)?;
        self.forward(m).map_err(|e| Rejected::Bus(e.to_string()))
    }
}

/// Checks an imported sample's type name against the topic's; then its size is checked by
/// [`ImportPort::publish_bytes`].
pub fn check_type(kind: &TopicKind, attachment: Option<&[u8]>) -> Result<(), Rejected> {
    match attachment {
        Some(a) if a == kind.type_name.as_bytes() => Ok(()),
        _ => Err(Rejected::WrongType),
    }
}

/// Lets at most one message through per `1 / max_rate_hz` (no limit at 0 Hz).
#[derive(Debug, Clone)]
pub struct RateLimit {
    period_ns: u64,
    next_ns: u64,
}

impl RateLimit {
    pub fn new(max_rate_hz: f64) -> RateLimit {
        RateLimit {
            period_ns: if max_rate_hz > 0.0 {
                (1e9 / max_rate_hz) as u64
            } else {
                0
            },
            next_ns: 0,
        }
    }
    /// Whether a message at host time `now_ns` goes through.
    pub fn admit(&mut self, now_ns: u64) -> bool {
        if self.period_ns == 0 {
            return true;
        }
        if now_ns < self.next_ns {
            return false;
        }
        // The next slot follows this one's, not the arrival: the rate holds on average however
        // the messages arrive (but no burst after a pause).
        self.next_ns =
            (self.next_ns + self.period_ns).max(now_ns.saturating_sub(self.period_ns / 2));
        if self.next_ns <= now_ns {
            self.next_ns = now_ns + self.period_ns;
        }
        true
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn patterns_match_whole_topic_names() {
        assert!(matches("nav/*", "nav/solution"));
        assert!(matches("*", "nav/aid_diagnostics"));
        assert!(matches("nav/solution", "nav/solution"));
        assert!(!matches("nav/solution", "nav/solutions"));
        assert!(!matches("nav/*", "imu"));
        assert!(matches("*a*", "nav/late_aids"));
        assert!(matches("*h", "health"));
        assert!(!matches("*x", "health"));
    }

    #[test]
    fn a_rate_limit_passes_its_rate_whatever_the_input_rate() {
        for input_hz in [200u64, 1000, 33] {
            let mut r = RateLimit::new(10.0);
            let n = (0..input_hz * 10)
                .filter(|k| r.admit(k * 1_000_000_000 / input_hz))
                .count();
            // 10 s at 10 Hz: 100 messages, or every message when the input is slower.
            assert!((99..=101).contains(&n), "{input_hz} Hz in: {n} out");
        }
        let mut unlimited = RateLimit::new(0.0);
        assert!((0..1000).all(|k| unlimited.admit(k)));
    }

    #[test]
    fn configuration_problems_are_named() {
        let base = |extra: &str| -> Result<(), String> {
            let text = format!(
                "prefix = \"auvnav\"\n[[export]]\ntopics = \"nav/*\"\nkey_prefix = \"auvnav/v1\"\n{extra}"
            );
            let cfg: BridgeConfig = toml::from_str(&text).map_err(|e| e.to_string())?;
            cfg.check()
        };
        assert_eq!(base(""), Ok(()));
        let bad = [
            (
                "[[import]]\nkey_prefix = \"x\"\nprefix = \"auvnav\"\n",
                "must be set and differ",
            ),
            (
                "[[import]]\nkey_prefix = \"x/*\"\nprefix = \"v\"\n",
                "without wildcards",
            ),
            (
                "[[import]]\nkey_prefix = \"x\"\nprefix = \"v\"\ntopics = \"nope\"\n",
                "matches no topic",
            ),
            (
                "[zenoh]\nmode = \"router\"\n",
                "expected \"peer\" or \"client\"",
            ),
            ("health_period_s = 0.0\n", "health_period_s"),
            ("bogus = 1\n", "unknown field"),
        ];
        for (extra, expected) in bad {
            let e = base(extra).expect_err(extra);
            assert!(e.contains(expected), "{extra}: {e}");
        }
    }

    #[test]
    fn only_the_topics_type_and_size_are_imported() {
        let kind = TopicKind::by_name(topic::NAV_SOLUTION).expect("topic");
        assert!(check_type(kind, Some(b"auvnav/NavSolution/v1")).is_ok());
        assert_eq!(
            check_type(kind, Some(b"auvnav/ImuSample/v1")),
            Err(Rejected::WrongType)
        );
        assert_eq!(check_type(kind, None), Err(Rejected::WrongType));
        let m = NavSolutionV1 {
            sequence: 5,
            height_m: -3.5,
            ..Default::default()
        };
        let bytes = bytemuck::bytes_of(&m);
        assert_eq!(bytes.len(), kind.size);
        let back: Option<NavSolutionV1> = bytemuck::try_pod_read_unaligned(bytes).ok();
        assert_eq!(back.map(|b| (b.sequence, b.height_m)), Some((5, -3.5)));
        assert!(
            bytemuck::try_pod_read_unaligned::<NavSolutionV1>(&bytes[1..])
                .ok()
                .is_none()
        );
    }
}
