//! The serial driver process (`auvnav-dvl`, `auvnav-imu`, `auvnav-usbl`, `auvnav-gnss`): owns one
//! serial port,
//! stamps every frame with the host clock at its first byte's arrival (an IMU's samples with its
//! own clock translated to the host's: `auvnav_protocols::line_time`), decodes the device's
//! protocol and publishes the messages on the bus, reports its health, and survives the line: garbage is
//! counted and dropped by the decoder, a silent device is reported, a device that disappears is
//! reopened with exponential back-off, and the process stops cleanly on SIGTERM/SIGINT.
//!
//! A GNSS receiver's driver also listens to the depth topic: with `settings.gnss.surface_only`
//! it publishes a fix only while the latest depth says the vehicle is at the surface, since a
//! receiver whose antenna is awash or just under water reports multipath positions as fixes.
//!
//! Long on purpose: one driver process: its settings, the port's reconnection, the loop and the
//! health report share the port's state; the protocols are in auvnav-protocols.

use crate::clock::monotonic_ns;
use crate::device::{DeviceClass, DeviceDecoder, Output, Protocol, ProtocolSettings};
use auvnav_shm_schema::bus::{Bus, BusError, BusPublisher};
use auvnav_shm_schema::stage_times::StageTimes;
use auvnav_shm_schema::{
    AcousticRangesV1, DepthV1, DvlVelocityV1, GnssFixV1, ImuSampleV1, MagnetometerV1,
    ProcessHealthV1, ProcessState, RAW_CHUNK, RawBytesV1, UsblFixV1, qos, topic,
};
use serde::{Deserialize, Serialize};
use std::io::Read;
use std::time::Duration;

/// Parity of the serial line.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "lowercase")]
pub enum Parity {
    #[default]
    None,
    Odd,
    Even,
}

/// The serial line (`[serial]`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SerialConfig {
    /// Device path, e.g. `/dev/ttyUSB0` or a stable link such as `/dev/serial/by-id/...`.
    pub port: String,
    /// Baud rate (bit/s, default 115200).
    #[serde(default = "default_baud")]
    pub baud: u32,
    /// Data bits (5..8, default 8).
    #[serde(default = "default_data_bits")]
    pub data_bits: u8,
    /// Parity (`none`, `odd`, `even`; default none).
    #[serde(default)]
    pub parity: Parity,
    /// Stop bits (1 or 2, default 1).
    #[serde(default = "default_stop_bits")]
    pub stop_bits: u8,
}

fn default_baud() -> u32 {
    115_200
}
fn default_data_bits() -> u8 {
    8
}
fn default_stop_bits() -> u8 {
    1
}

/// Timing of reads, health and reconnection (`[timing]`).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct TimingConfig {
    /// Longest a read waits for bytes (s, 0.001..1, default 0.05).
    pub read_timeout_s: f64,
    /// No byte for this long and the device is reported silent: health state `reconnecting`,
    /// `timeouts` + 1 (s, > read_timeout_s, default 2).
    pub silence_timeout_s: f64,
    /// First wait before reopening a lost port (s, default 0.1); doubles per failed attempt…
    pub reconnect_initial_s: f64,
    /// …up to this (s, default 5).
    pub reconnect_max_s: f64,
    /// Period of the health message (s, 0.05..60, default 1).
    pub health_period_s: f64,
}

impl Default for TimingConfig {
    fn default() -> Self {
        TimingConfig {
            read_timeout_s: 0.05,
            silence_timeout_s: 2.0,
            reconnect_initial_s: 0.1,
            reconnect_max_s: 5.0,
            health_period_s: 1.0,
        }
    }
}

/// A device's TCP service (`[tcp]`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TcpConfig {
    /// `host:port`, e.g. `192.168.194.95:16171` (a Water Linked DVL's default).
    pub address: String,
}

/// How the device is installed on the vehicle (`[mounting]`): metadata for the navigation
/// configuration and the log, not applied by the driver (messages stay in the device frame).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize, Default)]
#[serde(deny_unknown_fields, default)]
pub struct MountingConfig {
    /// Device frame to body frame rotation as roll, pitch, yaw (deg).
    pub rotation_rpy_deg: [f64; 3],
    /// Device origin in the body frame (m, FRD).
    pub lever_arm_m: [f64; 3],
}

/// A serial driver's configuration file.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SerialDriverConfig {
    /// Process name in the health message and the raw-capture topic `raw/<name>` (default: the
    /// device class, `dvl`, `imu` or `usbl`; at most 32 bytes).
    #[serde(default)]
    pub name: Option<String>,
    /// Service-name prefix of the deployment (default `auvnav`).
    #[serde(default = "default_prefix")]
    pub prefix: String,
    /// The device's protocol (`pd0`, `wldvl`, `wldvl-json`, `nortek`, `kvh1750`, `xsens`, `seatrac`,
    /// `nmea`, `ubx`).
    pub protocol: Protocol,
    /// Publish every byte read on `raw/<name>` for the recorder (default false).
    #[serde(default)]
    pub raw_capture: bool,
    /// The serial line (every protocol but `wldvl-json`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub serial: Option<SerialConfig>,
    /// The device's TCP service (`wldvl-json`: a Water Linked DVL on Ethernet).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub tcp: Option<TcpConfig>,
    #[serde(default)]
    pub settings: ProtocolSettings,
    #[serde(default)]
    pub timing: TimingConfig,
    #[serde(default)]
    pub mounting: MountingConfig,
    /// Write the host time of each message's read, decode and publish to this CSV file (ns,
    /// `read_ns,decoded_ns,published_ns`), for latency breakdowns; empty for none (default).
    #[serde(default)]
    pub stage_times_csv: String,
}

fn default_prefix() -> String {
    topic::DEFAULT_PREFIX.to_string()
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
    #[error("{path}: {key} = {value}: {expected}")]
    Range {
        path: String,
        key: &'static str,
        value: String,
        expected: String,
    },
}

impl SerialDriverConfig {
    /// Reads and checks a configuration file for a driver of `class`.
    pub fn load(path: &str, class: DeviceClass) -> Result<SerialDriverConfig, ConfigError> {
        let text = std::fs::read_to_string(path).map_err(|source| ConfigError::Read {
            path: path.to_string(),
            source,
        })?;
        let cfg: SerialDriverConfig = toml::from_str(&text).map_err(|e| ConfigError::Parse {
            path: path.to_string(),
            message: e.to_string(),
        })?;
        cfg.check(path, class)?;
        Ok(cfg)
    }

    /// Range checks; `path` names the file in the error.
    pub fn check(&self, path: &str, class: DeviceClass) -> Result<(), ConfigError> {
        let range = |key: &'static str, value: String, expected: String| ConfigError::Range {
            path: path.to_string(),
            key,
            value,
            expected,
        };
        if self.protocol.class() != class {
            let allowed: Vec<_> = Protocol::ALL
                .iter()
                .filter(|p| p.class() == class)
                .map(|p| p.name())
                .collect();
            return Err(range(
                "protocol",
                self.protocol.name().to_string(),
                format!("a {} driver speaks {}", class.name(), allowed.join(" or ")),
            ));
        }
        let tcp_protocol = self.protocol == Protocol::WldvlJson;
        match (&self.serial, &self.tcp, tcp_protocol) {
            (None, Some(t), true) => {
                if t.address.parse::<std::net::SocketAddr>().is_err()
                    && !t.address.rsplit_once(':').is_some_and(|(h, p)| {
                        !h.is_empty() && p.parse::<u16>().is_ok_and(|p| p > 0)
                    })
                {
                    return Err(range(
                        "tcp.address",
                        format!("{:?}", t.address),
                        "host:port".into(),
                    ));
                }
            }
            (Some(_), None, false) => {}
            (_, _, true) => {
                return Err(range(
                    "tcp",
                    "missing or beside [serial]".into(),
                    "protocol wldvl-json reads a [tcp] address (and no [serial])".into(),
                ));
            }
            (_, _, false) => {
                return Err(range(
                    "serial",
                    "missing or beside [tcp]".into(),
                    format!("protocol {} reads a [serial] line", self.protocol.name()),
                ));
            }
        }
        if let Some(s) = &self.serial {
            self.check_serial(s, path)?;
        }
        self.check_rest(path)
    }

    fn check_serial(&self, s: &SerialConfig, path: &str) -> Result<(), ConfigError> {
        let range = |key: &'static str, value: String, expected: String| ConfigError::Range {
            path: path.to_string(),
            key,
            value,
            expected,
        };
        if s.port.is_empty() {
            return Err(range("serial.port", "\"\"".into(), "a device path".into()));
        }
        if !(50..=4_000_000).contains(&s.baud) {
            return Err(range(
                "serial.baud",
                s.baud.to_string(),
                "50..=4000000".into(),
            ));
        }
        if !(5..=8).contains(&s.data_bits) {
            return Err(range(
                "serial.data_bits",
                s.data_bits.to_string(),
                "5..=8".into(),
            ));
        }
        if !(1..=2).contains(&s.stop_bits) {
            return Err(range(
                "serial.stop_bits",
                s.stop_bits.to_string(),
                "1 or 2".into(),
            ));
        }
        Ok(())
    }

    fn check_rest(&self, path: &str) -> Result<(), ConfigError> {
        let range = |key: &'static str, value: String, expected: String| ConfigError::Range {
            path: path.to_string(),
            key,
            value,
            expected,
        };
        let t = &self.timing;
        let checks: [(&'static str, f64, f64, f64); 5] = [
            ("timing.read_timeout_s", t.read_timeout_s, 0.001, 1.0),
            (
                "timing.silence_timeout_s",
                t.silence_timeout_s,
                t.read_timeout_s,
                3600.0,
            ),
            (
                "timing.reconnect_initial_s",
                t.reconnect_initial_s,
                0.001,
                60.0,
            ),
            (
                "timing.reconnect_max_s",
                t.reconnect_max_s,
                t.reconnect_initial_s,
                600.0,
            ),
            ("timing.health_period_s", t.health_period_s, 0.05, 60.0),
        ];
        for (key, v, lo, hi) in checks {
            if !(v.is_finite() && v >= lo && v <= hi) {
                return Err(range(key, v.to_string(), format!("{lo}..={hi} s")));
            }
        }
        let st = &self.settings;
        if !(st.latency_s.is_finite() && (0.0..=10.0).contains(&st.latency_s)) {
            return Err(range(
                "settings.latency_s",
                st.latency_s.to_string(),
                "0..=10 s".into(),
            ));
        }
        if !(st.xsens_rate_hz.is_finite() && st.xsens_rate_hz > 0.0 && st.xsens_rate_hz <= 4000.0) {
            return Err(range(
                "settings.xsens_rate_hz",
                st.xsens_rate_hz.to_string(),
                "0 < x <= 4000 Hz".into(),
            ));
        }
        if !(st.xsens_field_unit_ut.is_finite()
            && st.xsens_field_unit_ut > 0.0
            && st.xsens_field_unit_ut <= 1000.0)
        {
            return Err(range(
                "settings.xsens_field_unit_ut",
                st.xsens_field_unit_ut.to_string(),
                "0 < x <= 1000 uT".into(),
            ));
        }
        let g = &st.gnss;
        for (key, v, lo, hi) in [
            ("settings.gnss.uere_m", g.uere_m, 0.01, 100.0),
            (
                "settings.gnss.surface_depth_m",
                g.surface_depth_m,
                0.0,
                10.0,
            ),
            (
                "settings.gnss.depth_timeout_s",
                g.depth_timeout_s,
                0.1,
                60.0,
            ),
        ] {
            if !(v.is_finite() && v >= lo && v <= hi) {
                return Err(range(key, v.to_string(), format!("{lo}..={hi}")));
            }
        }
        if !(0..=100).contains(&g.leap_seconds) {
            return Err(range(
                "settings.gnss.leap_seconds",
                g.leap_seconds.to_string(),
                "0..=100 s".into(),
            ));
        }
        if !(st.kvh.rate_hz.is_finite() && st.kvh.rate_hz > 0.0 && st.kvh.rate_hz <= 10_000.0) {
            return Err(range(
                "settings.kvh.rate_hz",
                st.kvh.rate_hz.to_string(),
                "0 < x <= 10000 Hz".into(),
            ));
        }
        if let Some(p) = st.seatrac.range_beacons.problem() {
            return Err(range(
                "settings.seatrac.range_beacons",
                format!("{:?}", st.seatrac.range_beacons.ids()),
                p,
            ));
        }
        if !st.seatrac.range_beacons.ids().is_empty() && self.protocol != Protocol::Seatrac {
            return Err(range(
                "settings.seatrac.range_beacons",
                format!("{:?}", st.seatrac.range_beacons.ids()),
                "for protocol seatrac only".into(),
            ));
        }
        let m = &self.mounting;
        for (key, v, lim) in [
            ("mounting.rotation_rpy_deg", m.rotation_rpy_deg, 360.0),
            ("mounting.lever_arm_m", m.lever_arm_m, 50.0),
        ] {
            if !v.iter().all(|x| x.abs() <= lim) {
                return Err(range(
                    key,
                    format!("{v:?}"),
                    format!("each component within ±{lim}"),
                ));
            }
        }
        if let Some((key, value, expected)) =
            prefix_and_name_problem(&self.prefix, self.name.as_deref())
        {
            return Err(range(key, value, expected));
        }
        if let Some(p) = auvnav_shm_schema::stage_times::output_path_problem(&self.stage_times_csv)
        {
            return Err(range(
                "stage_times_csv",
                format!("{:?}", self.stage_times_csv),
                p,
            ));
        }
        Ok(())
    }

    /// Where the bytes come from: the serial device path, or `tcp://host:port`.
    pub fn source(&self) -> String {
        match (&self.serial, &self.tcp) {
            (Some(s), _) => s.port.clone(),
            (None, Some(t)) => format!("tcp://{}", t.address),
            (None, None) => String::new(),
        }
    }

    /// The process name.
    pub fn process_name(&self) -> String {
        self.name
            .clone()
            .unwrap_or_else(|| self.protocol.class().name().to_string())
    }
}

/// What is wrong with a driver's service-name `prefix` (ASCII letters, digits, `_-./`) or its
/// process `name` (1..=32 bytes), as (key, value, expected).
pub(crate) fn prefix_and_name_problem(
    prefix: &str,
    name: Option<&str>,
) -> Option<(&'static str, String, String)> {
    if prefix.is_empty()
        || !prefix
            .chars()
            .all(|c| c.is_ascii_alphanumeric() || "_-./".contains(c))
    {
        return Some((
            "prefix",
            format!("{prefix:?}"),
            "ASCII letters, digits, '_', '-', '.', '/'".into(),
        ));
    }
    if name.is_some_and(|n| n.is_empty() || n.len() > 32) {
        return Some(("name", format!("{name:?}"), "1..=32 bytes".into()));
    }
    None
}

/// Where a driver reads its bytes: a serial line or a TCP connection.
pub enum Link {
    Serial(serialport::TTYPort),
    Tcp(std::net::TcpStream),
}

impl std::io::Read for Link {
    fn read(&mut self, buf: &mut [u8]) -> std::io::Result<usize> {
        match self {
            Link::Serial(p) => p.read(buf),
            Link::Tcp(t) => t.read(buf),
        }
    }
}

/// Opens the configured link: the serial port, or a TCP connection (connect timeout 1 s) with
/// `read_timeout` on reads.
pub fn open_link(cfg: &SerialDriverConfig, read_timeout: Duration) -> Result<Link, String> {
    if let Some(s) = &cfg.serial {
        return open_port(s, read_timeout)
            .map(Link::Serial)
            .map_err(|e| e.to_string());
    }
    let Some(t) = &cfg.tcp else {
        return Err("no [serial] or [tcp] in the configuration".into());
    };
    use std::net::ToSocketAddrs;
    let addr = t
        .address
        .to_socket_addrs()
        .map_err(|e| format!("resolving {}: {e}", t.address))?
        .next()
        .ok_or_else(|| format!("{} resolves to no address", t.address))?;
    let stream = std::net::TcpStream::connect_timeout(&addr, Duration::from_secs(1))
        .map_err(|e| e.to_string())?;
    stream
        .set_read_timeout(Some(read_timeout))
        .map_err(|e| e.to_string())?;
    Ok(Link::Tcp(stream))
}

/// Opens the serial port in raw mode (serialport configures termios raw) with the line settings
/// and read timeout, exclusively.
pub fn open_port(
    s: &SerialConfig,
    read_timeout: Duration,
) -> Result<serialport::TTYPort, serialport::Error> {
    use serialport::{DataBits, FlowControl, StopBits};
    let data_bits = match s.data_bits {
        5 => DataBits::Five,
        6 => DataBits::Six,
        7 => DataBits::Seven,
        _ => DataBits::Eight,
    };
    let parity = match s.parity {
        Parity::None => serialport::Parity::None,
        Parity::Odd => serialport::Parity::Odd,
        Parity::Even => serialport::Parity::Even,
    };
    let stop_bits = if s.stop_bits == 2 {
        StopBits::Two
    } else {
        StopBits::One
    };
    serialport::new(&s.port, s.baud)
        .data_bits(data_bits)
        .parity(parity)
        .stop_bits(stop_bits)
        .flow_control(FlowControl::None)
        .timeout(read_timeout)
        .open_native()
}

/// The publishers of the driver: its device class's topic, and the magnetometer topic for an
/// IMU whose protocol carries the magnetic field (Xsens).
struct DataPublisher {
    class: ClassPublisher,
    magnetometer: Option<BusPublisher<MagnetometerV1>>,
    /// A SeaTrac's ranges to the beacons it ranges as transponders.
    ranges: Option<BusPublisher<AcousticRangesV1>>,
}

enum ClassPublisher {
    Imu(BusPublisher<ImuSampleV1>),
    Dvl(BusPublisher<DvlVelocityV1>),
    Usbl(BusPublisher<UsblFixV1>),
    Gnss(BusPublisher<GnssFixV1>),
}

impl DataPublisher {
    fn new(bus: &Bus, protocol: Protocol, settings: &ProtocolSettings) -> Result<Self, BusError> {
        let class = match protocol.class() {
            DeviceClass::Imu => ClassPublisher::Imu(bus.publisher(topic::IMU, qos::SENSOR)?),
            DeviceClass::Dvl => ClassPublisher::Dvl(bus.publisher(topic::DVL, qos::SENSOR)?),
            DeviceClass::Usbl => ClassPublisher::Usbl(bus.publisher(topic::USBL, qos::SENSOR)?),
            DeviceClass::Gnss => ClassPublisher::Gnss(bus.publisher(topic::GNSS, qos::SENSOR)?),
        };
        let magnetometer = if protocol.carries_magnetic_field() {
            Some(bus.publisher(topic::MAGNETOMETER, qos::SENSOR)?)
        } else {
            None
        };
        let ranges =
            if protocol == Protocol::Seatrac && !settings.seatrac.range_beacons.ids().is_empty() {
                Some(bus.publisher(topic::ACOUSTIC_RANGES, qos::SENSOR)?)
            } else {
                None
            };
        Ok(DataPublisher {
            class,
            magnetometer,
            ranges,
        })
    }

    /// Publishes `out`; false when the driver has no publisher for it (never, by construction).
    fn publish(&mut self, out: Output) -> Result<bool, BusError> {
        if let Output::AcousticRanges(m) = out {
            return match self.ranges.as_mut() {
                Some(p) => p.publish(m).map(|_| true),
                None => Ok(false),
            };
        }
        match (&mut self.class, &mut self.magnetometer, out) {
            (ClassPublisher::Imu(p), _, Output::Imu(m)) => p.publish(m).map(|_| true),
            (ClassPublisher::Dvl(p), _, Output::Dvl(m)) => p.publish(m).map(|_| true),
            (ClassPublisher::Usbl(p), _, Output::Usbl(m)) => p.publish(m).map(|_| true),
            (ClassPublisher::Gnss(p), _, Output::Gnss(m)) => p.publish(m).map(|_| true),
            (_, Some(p), Output::Magnetometer(m)) => p.publish(m).map(|_| true),
            _ => Ok(false),
        }
    }
}

/// The surface gate of a GNSS receiver's fixes: the latest depth on the bus.
struct SurfaceGate {
    depth: auvnav_shm_schema::bus::BusSubscriber<DepthV1>,
    max_depth_m: f64,
    timeout_ns: u64,
    /// The latest valid depth and its time (ns).
    latest: Option<(f64, u64)>,
    /// Fixes withheld, and whether the last one was.
    withheld: u64,
    closed: bool,
}

impl SurfaceGate {
    fn new(bus: &Bus, s: &crate::gnss::GnssSettings) -> Result<Self, BusError> {
        Ok(SurfaceGate {
            depth: bus.subscriber(topic::DEPTH, qos::SENSOR)?,
            max_depth_m: s.surface_depth_m,
            timeout_ns: (s.depth_timeout_s * 1e9) as u64,
            latest: None,
            withheld: 0,
            closed: false,
        })
    }

    /// Takes in the depths published since the last call.
    fn update(&mut self) {
        while let Ok(Some(d)) = self.depth.receive() {
            if d.validity & DepthV1::VALID_DEPTH != 0 && d.depth_m.is_finite() {
                self.latest = Some((d.depth_m, d.host_time_ns));
            }
        }
    }

    /// Whether a fix valid at `t_ns` may be published; says so when that changes.
    fn pass(&mut self, name: &str, t_ns: u64) -> bool {
        self.update();
        let verdict = match self.latest {
            None => Err("no depth on the bus yet".to_string()),
            Some((_, at)) if t_ns.abs_diff(at) > self.timeout_ns => Err(format!(
                "the latest depth is {:.1} s old",
                t_ns.abs_diff(at) as f64 * 1e-9
            )),
            Some((d, _)) if d > self.max_depth_m => Err(format!(
                "depth {d:.2} m is below the surface limit {} m",
                self.max_depth_m
            )),
            Some(_) => Ok(()),
        };
        match verdict {
            Ok(()) => {
                if self.closed {
                    tracing::info!("{name}: at the surface again: publishing fixes");
                    self.closed = false;
                }
                true
            }
            Err(why) => {
                if !self.closed {
                    tracing::info!("{name}: withholding fixes: {why}");
                    self.closed = true;
                }
                self.withheld += 1;
                false
            }
        }
    }
}

/// Why the driver stopped.
#[derive(Debug, thiserror::Error)]
pub enum DriverError {
    #[error("shared memory: {0}")]
    Bus(#[from] BusError),
    #[error("{0}")]
    Output(String),
}

/// Health counters and state, published as [`ProcessHealthV1`].
#[derive(Debug, Clone, Copy, Default)]
struct Health {
    published: u64,
    timeouts: u64,
    reconnects: u64,
    publish_errors: u64,
    open_failures: u64,
}

/// Runs the driver until SIGTERM/SIGINT. Progress and problems go to stderr, one line each.
// Long on purpose: the driver's one loop (open with back-off, read, decode, publish, health,
// signals) over one port's state; decoding and health are functions of their own.
pub fn run(cfg: &SerialDriverConfig) -> Result<(), DriverError> {
    let name = cfg.process_name();
    let class = cfg.protocol.class();
    let bus = Bus::new(&name, &cfg.prefix)?;
    let mut data = DataPublisher::new(&bus, cfg.protocol, &cfg.settings)?;
    let mut surface_gate = if class == DeviceClass::Gnss && cfg.settings.gnss.surface_only {
        Some(SurfaceGate::new(&bus, &cfg.settings.gnss)?)
    } else {
        None
    };
    let mut health_pub = bus.publisher::<ProcessHealthV1>(topic::HEALTH, qos::HEALTH)?;
    let mut raw_pub = if cfg.raw_capture {
        Some(bus.publisher::<RawBytesV1>(&topic::raw(&name), qos::RAW)?)
    } else {
        None
    };
    let t = cfg.timing;
    let read_timeout = Duration::from_secs_f64(t.read_timeout_s);
    let silence_ns = (t.silence_timeout_s * 1e9) as u64;
    let health_ns = (t.health_period_s * 1e9) as u64;
    let mut decoder = DeviceDecoder::new(cfg.protocol, cfg.settings);
    decoder.time_the_line(cfg.serial.as_ref().map_or(0.0, |s| {
        auvnav_protocols::line_time::character_time_ns(
            s.baud,
            s.data_bits,
            s.parity != Parity::None,
            s.stop_bits,
        )
    }));
    let mut health = Health::default();
    let mut port: Option<Link> = None;
    let mut state = ProcessState::Starting;
    let mut ever_open = false;
    let mut backoff_s = t.reconnect_initial_s;
    let mut next_attempt = 0u64;
    let mut last_bytes = monotonic_ns();
    let mut silent = false;
    let mut next_health = 0u64;
    let mut last_open_error = String::new();
    let mut buf = vec![0u8; 64 * 1024];
    let mut stage_times = StageTimes::create(
        &cfg.stage_times_csv,
        "stamp_ns,read_ns,decoded_ns,published_ns",
    )
    .map_err(|e| DriverError::Output(format!("creating {}: {e}", cfg.stage_times_csv)))?;
    let source = cfg.source();
    tracing::info!(
        "{name}: {} on {}{}, publishing on {}/{}{} (mounting rpy {:?} deg, lever arm {:?} m)",
        cfg.protocol.name(),
        source,
        cfg.serial
            .as_ref()
            .map(|s| format!(" at {} baud", s.baud))
            .unwrap_or_default(),
        cfg.prefix,
        class.name(),
        if cfg.protocol.carries_magnetic_field() {
            format!(" and {}/{}", cfg.prefix, topic::MAGNETOMETER)
        } else if data.ranges.is_some() {
            format!(
                " and {}/{} (beacons {:?} ranged as receivers 0..)",
                cfg.prefix,
                topic::ACOUSTIC_RANGES,
                cfg.settings.seatrac.range_beacons.ids()
            )
        } else {
            String::new()
        },
        cfg.mounting.rotation_rpy_deg,
        cfg.mounting.lever_arm_m,
    );
    let publish_health = |hp: &mut BusPublisher<ProcessHealthV1>,
                          h: &Health,
                          d: &DeviceDecoder,
                          state: ProcessState| {
        let s = d.stats();
        let c = d.counters();
        let mut m = ProcessHealthV1 {
            host_time_ns: monotonic_ns(),
            frames: h.published,
            checksum_errors: s.checksum_errors,
            resyncs: s.resyncs,
            bytes_skipped: s.bytes_skipped + s.overflow_bytes,
            timeouts: h.timeouts,
            reconnects: h.reconnects,
            drops: c.device_gaps + h.publish_errors,
            invalid: s.malformed + c.out_of_range,
            pid: std::process::id(),
            state: state as u32,
            ..Default::default()
        };
        m.set_name(&name);
        hp.publish(m)
    };
    bus.ready(&format!("{name}: reading {:?}", cfg.protocol));
    loop {
        if bus.termination_requested() {
            break;
        }
        let now = monotonic_ns();
        if let Some(g) = surface_gate.as_mut() {
            g.update();
        }
        if now >= next_health {
            publish_health(&mut health_pub, &health, &decoder, state)?;
            next_health = now + health_ns;
        }
        let Some(p) = port.as_mut() else {
            if now < next_attempt {
                std::thread::sleep(Duration::from_nanos((next_attempt - now).min(20_000_000)));
                continue;
            }
            match open_link(cfg, read_timeout) {
                Ok(p) => {
                    if ever_open {
                        health.reconnects += 1;
                        tracing::info!("{name}: {source} reopened");
                    }
                    ever_open = true;
                    decoder.restart_line();
                    port = Some(p);
                    backoff_s = t.reconnect_initial_s;
                    last_bytes = monotonic_ns();
                    silent = false;
                    last_open_error.clear();
                }
                Err(e) => {
                    health.open_failures += 1;
                    let msg = e.to_string();
                    if msg != last_open_error {
                        tracing::warn!(
                            "{name}: cannot open {source}: {msg}; retrying with back-off up to {} s",
                            t.reconnect_max_s
                        );
                        last_open_error = msg;
                    }
                    state = ProcessState::Reconnecting;
                    next_attempt = now + (backoff_s * 1e9) as u64;
                    backoff_s = (backoff_s * 2.0).min(t.reconnect_max_s);
                }
            }
            continue;
        };
        match p.read(&mut buf) {
            Ok(0) => {
                tracing::warn!("{name}: {source} hung up");
                port = None;
                state = ProcessState::Reconnecting;
                next_attempt = monotonic_ns();
            }
            Ok(n) => {
                let host_ns = monotonic_ns();
                last_bytes = host_ns;
                if silent {
                    tracing::info!("{name}: data again on {source}");
                    silent = false;
                }
                if let Some(rp) = raw_pub.as_mut() {
                    for chunk in buf[..n].chunks(RAW_CHUNK) {
                        let mut m = RawBytesV1 {
                            host_time_ns: host_ns,
                            length: chunk.len() as u32,
                            ..Default::default()
                        };
                        m.data[..chunk.len()].copy_from_slice(chunk);
                        if rp.publish(m).is_err() {
                            health.publish_errors += 1;
                        }
                    }
                }
                decoder.push_read(&buf[..n], host_ns);
                while let Some(out) = decoder.next_output(host_ns) {
                    if let (Output::Gnss(f), Some(gate)) = (&out, surface_gate.as_mut())
                        && !gate.pass(&name, f.host_time_ns)
                    {
                        continue;
                    }
                    let decoded_ns = stage_times.as_ref().map(|_| monotonic_ns());
                    let stamp_ns = out.host_time_ns();
                    match data.publish(out) {
                        Ok(true) => health.published += 1,
                        Ok(false) | Err(_) => health.publish_errors += 1,
                    }
                    if let (Some(s), Some(decoded_ns)) = (stage_times.as_mut(), decoded_ns) {
                        s.row(&[stamp_ns, host_ns, decoded_ns, monotonic_ns()]);
                    }
                }
                state = ProcessState::Running;
            }
            Err(e)
                if matches!(
                    e.kind(),
                    std::io::ErrorKind::TimedOut
                        | std::io::ErrorKind::WouldBlock
                        | std::io::ErrorKind::Interrupted
                ) =>
            {
                if !silent && monotonic_ns().saturating_sub(last_bytes) > silence_ns {
                    silent = true;
                    health.timeouts += 1;
                    state = ProcessState::Reconnecting;
                    tracing::warn!("{name}: no data on {source} for {} s", t.silence_timeout_s);
                }
            }
            Err(e) => {
                tracing::warn!(device = %source, error = %e, "{name}: {source} lost: {e}");
                port = None;
                state = ProcessState::Reconnecting;
                next_attempt = monotonic_ns() + (backoff_s * 1e9) as u64;
            }
        }
    }
    if class == DeviceClass::Gnss {
        tracing::info!(
            "{name}: {} epochs without a usable position; {} fixes withheld below the surface",
            decoder.counters().no_fix,
            surface_gate.as_ref().map_or(0, |g| g.withheld)
        );
    }
    let clock = match decoder.device_clock_rate() {
        Some(rate) => format!(
            "; the device's clock runs {} the host's, {} resets",
            if (1.0 / rate - 1.0).abs() < 0.01 {
                format!("{:+.1} ppm against", (1.0 / rate - 1.0) * 1e6)
            } else {
                format!("{:.4} times as fast as", 1.0 / rate)
            },
            decoder.counters().clock_resets
        ),
        None if class == DeviceClass::Imu => format!(
            "; no model of the device's clock ({} resets)",
            decoder.counters().clock_resets
        ),
        None => String::new(),
    };
    tracing::info!(
        published = health.published,
        checksum_errors = decoder.stats().checksum_errors,
        reconnects = health.reconnects,
        "{name}: stopping; {} messages published, {} checksum errors, {} reconnects{clock}",
        health.published,
        decoder.stats().checksum_errors,
        health.reconnects
    );
    publish_health(&mut health_pub, &health, &decoder, ProcessState::Stopping)?;
    Ok(())
}

/// Command line of the serial drivers (named for each device class by [`serial_driver_command`]).
#[derive(Debug, clap::Parser)]
#[command(version = auvnav_version::LONG)]
pub struct SerialDriverArgs {
    /// `--config FILE` (see docs/drivers.md), `--check-config [FILE]`.
    #[command(flatten)]
    pub config: auvnav_version::cli::ConfigArgs,
}

/// The command line of the serial driver for `class`: `auvnav-dvl`, `auvnav-imu`, `auvnav-usbl`
/// or `auvnav-gnss`.
pub fn serial_driver_command(class: DeviceClass) -> clap::Command {
    use clap::CommandFactory;
    let (name, about) = match class {
        DeviceClass::Dvl => (
            "auvnav-dvl",
            "DVL driver: Teledyne PD0, Nortek or Water Linked DVL (serial or TCP) to shared memory",
        ),
        DeviceClass::Imu => (
            "auvnav-imu",
            "IMU serial driver: KVH 1750 or Xsens MTData2 packets to shared memory",
        ),
        DeviceClass::Usbl => (
            "auvnav-usbl",
            "USBL serial driver: Blueprint SeaTrac fixes to shared memory",
        ),
        DeviceClass::Gnss => (
            "auvnav-gnss",
            "GNSS receiver driver: NMEA 0183 or u-blox UBX fixes to shared memory, at the surface",
        ),
    };
    SerialDriverArgs::command()
        .name(name)
        .bin_name(name)
        .about(about)
}

/// `main` of `auvnav-dvl`, `auvnav-imu`, `auvnav-usbl` and `auvnav-gnss`: exit 0 after a clean stop, 2 for a
/// configuration error, 1 for a shared-memory failure.
pub fn main_for(class: DeviceClass) -> std::process::ExitCode {
    use clap::FromArgMatches;
    let args = match SerialDriverArgs::from_arg_matches(&serial_driver_command(class).get_matches())
    {
        Ok(a) => a,
        Err(e) => e.exit(),
    };
    auvnav_shm_schema::logging::init();
    let (path, check) = match args.config.required() {
        Ok(x) => x,
        Err(e) => {
            tracing::error!("auvnav-{}: {e}", class.name());
            return std::process::ExitCode::from(2);
        }
    };
    let cfg = match SerialDriverConfig::load(&path, class) {
        Ok(c) => c,
        Err(e) => {
            tracing::error!("auvnav-{}: {e}", class.name());
            return std::process::ExitCode::from(2);
        }
    };
    if check {
        match toml::to_string_pretty(&cfg) {
            Ok(s) => print!("{s}"),
            Err(e) => tracing::error!("auvnav-{}: {e}", class.name()),
        }
        return std::process::ExitCode::SUCCESS;
    }
    match run(&cfg) {
        Ok(()) => std::process::ExitCode::SUCCESS,
        Err(e) => {
            tracing::error!("auvnav-{}: {e}", class.name());
            std::process::ExitCode::from(1)
        }
    }
}
