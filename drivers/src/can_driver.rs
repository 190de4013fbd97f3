//! The CAN driver process (`auvnav-can`): frames from a SocketCAN interface (or, for tests and
//! bench replays, a candump log) are decoded with a DBC file and mapped to schema messages — the
//! pressure sensor to [`DepthV1`] — and published on the bus with a health message. Where the
//! kernel has no CAN support or the interface does not exist, the driver says so and exits with
//! status 3; it does not pretend to run.
//!
//! Long on purpose: the last 78 lines are the unit tests, beside the code they test; the code is
//! 532 lines.

use crate::can::{CanFrame, DbcDecoder, FrameSource, SocketCanSource, SourceError};
use crate::clock::monotonic_ns;
use auvnav_shm_schema::bus::{Bus, BusError, BusPublisher};
use auvnav_shm_schema::{DepthV1, ProcessHealthV1, ProcessState, qos, topic};
use serde::{Deserialize, Serialize};
use std::time::Duration;

/// The sample DBC shipped with the drivers (pressure sensor, altimeter, battery).
pub const SAMPLE_DBC: &str = include_str!("../dbc/auvnav_sensors.dbc");

/// How the pressure sensor's signals become a depth (`[depth]`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct DepthMapping {
    /// DBC message carrying the pressure (default `PressureSensor`).
    pub message: String,
    /// Pressure signal (default `Pressure`).
    pub pressure_signal: String,
    /// Pascal per unit of the pressure signal (default 1e5: the signal is in bar).
    pub pressure_scale_pa: f64,
    /// The sensor reports absolute pressure; atmospheric pressure is subtracted (default true).
    pub absolute: bool,
    /// Atmospheric pressure at the surface (Pa, default 101325).
    pub atmospheric_pa: f64,
    /// Water density for depth = gauge pressure / (density · g) (kg/m^3, 990..1050, default
    /// 1025).
    pub water_density_kg_m3: f64,
    /// Gravity for the conversion (m/s^2, default 9.80665).
    pub gravity_m_s2: f64,
    /// Temperature signal in degC, or empty for none (default `Temperature`).
    pub temperature_signal: String,
    /// Rolling counter signal whose gaps count lost frames, or empty (default `Counter`).
    pub counter_signal: String,
    /// Modulus of the counter (default 256).
    pub counter_modulus: u32,
}

impl Default for DepthMapping {
    fn default() -> Self {
        DepthMapping {
            message: "PressureSensor".into(),
            pressure_signal: "Pressure".into(),
            pressure_scale_pa: 1e5,
            absolute: true,
            atmospheric_pa: 101_325.0,
            water_density_kg_m3: 1025.0,
            gravity_m_s2: 9.806_65,
            temperature_signal: "Temperature".into(),
            counter_signal: "Counter".into(),
            counter_modulus: 256,
        }
    }
}

/// `auvnav-can`'s configuration file.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CanDriverConfig {
    /// Process name in the health message (default `can`).
    #[serde(default = "default_name")]
    pub name: String,
    /// Service-name prefix of the deployment (default `auvnav`).
    #[serde(default = "default_prefix")]
    pub prefix: String,
    /// SocketCAN interface (default `can0`).
    #[serde(default = "default_interface")]
    pub interface: String,
    /// DBC file; empty for the sample DBC shipped with the drivers (default empty).
    #[serde(default)]
    pub dbc: String,
    #[serde(default)]
    pub depth: DepthMapping,
    /// Longest a read waits (s, 0.001..1, default 0.05).
    #[serde(default = "default_read_timeout")]
    pub read_timeout_s: f64,
    /// Period of the health message (s, 0.05..60, default 1).
    #[serde(default = "default_health_period")]
    pub health_period_s: f64,
}

fn default_name() -> String {
    "can".into()
}
fn default_prefix() -> String {
    topic::DEFAULT_PREFIX.into()
}
fn default_interface() -> String {
    "can0".into()
}
fn default_read_timeout() -> f64 {
    0.05
}
fn default_health_period() -> f64 {
    1.0
}

/// Counters of the CAN driver.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize)]
pub struct CanCounters {
    pub frames: u64,
    pub published: u64,
    /// Frames with an identifier the DBC does not define.
    pub unknown_id: u64,
    /// Frames shorter than their signals, or values out of range.
    pub invalid: u64,
    /// Frames the rolling counter says were lost.
    pub counter_gaps: u64,
}

/// Frame → depth message, pure.
pub struct CanDepth {
    decoder: DbcDecoder,
    mapping: DepthMapping,
    last_counter: Option<u32>,
    pub counters: CanCounters,
}

impl CanDepth {
    /// Checks that the mapping's message and signals exist in the DBC.
    pub fn new(dbc_text: &str, mapping: DepthMapping) -> Result<CanDepth, String> {
        let decoder = DbcDecoder::from_dbc(dbc_text).map_err(|e| e.to_string())?;
        let m = decoder
            .message_by_name(&mapping.message)
            .ok_or_else(|| format!("depth.message: no message {:?} in the DBC", mapping.message))?;
        for (key, signal) in [
            ("depth.pressure_signal", &mapping.pressure_signal),
            ("depth.temperature_signal", &mapping.temperature_signal),
            ("depth.counter_signal", &mapping.counter_signal),
        ] {
            if (key == "depth.pressure_signal" || !signal.is_empty())
                && !m.signals.iter().any(|s| &s.name == signal)
            {
                return Err(format!(
                    "{key}: message {:?} has no signal {signal:?}",
                    mapping.message
                ));
            }
        }
        if !(990.0..=1050.0).contains(&mapping.water_density_kg_m3) {
            return Err(format!(
                "depth.water_density_kg_m3 = {}: expected 990..=1050",
                mapping.water_density_kg_m3
            ));
        }
        if !(mapping.pressure_scale_pa.is_finite() && mapping.pressure_scale_pa > 0.0) {
            return Err("depth.pressure_scale_pa: expected a positive number".into());
        }
        if !(9.7..=9.9).contains(&mapping.gravity_m_s2) {
            return Err(format!(
                "depth.gravity_m_s2 = {}: expected 9.7..=9.9",
                mapping.gravity_m_s2
            ));
        }
        Ok(CanDepth {
            decoder,
            mapping,
            last_counter: None,
            counters: CanCounters::default(),
        })
    }

    /// The depth message of a pressure frame received at `host_time_ns`; `None` for other
    /// frames and for frames that cannot be used (counted).
    pub fn on_frame(&mut self, f: &CanFrame, host_time_ns: u64) -> Option<DepthV1> {
        self.counters.frames += 1;
        let decoded = match self.decoder.decode(f) {
            Ok(d) => d,
            Err(crate::can::CanError::UnknownId { .. }) => {
                self.counters.unknown_id += 1;
                return None;
            }
            Err(_) => {
                self.counters.invalid += 1;
                return None;
            }
        };
        if decoded.message != self.mapping.message {
            return None;
        }
        let signal = |name: &str| {
            decoded
                .signals
                .iter()
                .find(|(n, _, _)| n == name)
                .map(|(_, v, _)| *v)
        };
        let map = &self.mapping;
        if !map.counter_signal.is_empty()
            && let Some(c) = signal(&map.counter_signal)
        {
            let c = c.max(0.0) as u32 % map.counter_modulus.max(1);
            if let Some(last) = self.last_counter {
                let step = (c + map.counter_modulus - last) % map.counter_modulus.max(1);
                if step > 1 {
                    self.counters.counter_gaps += u64::from(step - 1);
                }
            }
            self.last_counter = Some(c);
        }
        let mut m = DepthV1 {
            host_time_ns,
            water_density_kg_m3: map.water_density_kg_m3,
            ..Default::default()
        };
        if let Some(p) = signal(&map.pressure_signal) {
            let pa = p * map.pressure_scale_pa;
            let gauge = if map.absolute {
                pa - map.atmospheric_pa
            } else {
                pa
            };
            if gauge.is_finite() && (-1e5..=1.2e8).contains(&gauge) {
                m.pressure_pa = gauge;
                m.depth_m = gauge / (map.water_density_kg_m3 * map.gravity_m_s2);
                m.validity |= DepthV1::VALID_PRESSURE | DepthV1::VALID_DEPTH;
            }
        }
        if !map.temperature_signal.is_empty()
            && let Some(t) = signal(&map.temperature_signal)
            && (-5.0..=50.0).contains(&t)
        {
            m.temperature_c = t as f32;
            m.validity |= DepthV1::VALID_TEMPERATURE;
        }
        if m.validity & DepthV1::VALID_DEPTH == 0 {
            self.counters.invalid += 1;
        }
        Some(m)
    }
}

/// Parses a candump log (`candump -l` format: `(SECONDS) IFACE ID#DATA`, `###` marks an extended
/// identifier by its 8 hex digits). Lines that do not parse are counted, not fatal.
pub fn parse_candump(text: &str) -> (Vec<(f64, CanFrame)>, u64) {
    let mut frames = Vec::new();
    let mut bad = 0;
    for line in text.lines() {
        let line = line.trim();
        if line.is_empty() {
            continue;
        }
        let parsed = (|| {
            let mut parts = line.split_whitespace();
            let t: f64 = parts
                .next()?
                .strip_prefix('(')?
                .strip_suffix(')')?
                .parse()
                .ok()?;
            let _iface = parts.next()?;
            let (id, data) = parts.next()?.split_once('#')?;
            let id_value = u32::from_str_radix(id, 16).ok()?;
            let extended = id.len() == 8;
            if data.len() % 2 != 0 || data.len() > 128 {
                return None;
            }
            let bytes = (0..data.len())
                .step_by(2)
                .map(|i| u8::from_str_radix(&data[i..i + 2], 16).ok())
                .collect::<Option<Vec<u8>>>()?;
            Some((
                t,
                CanFrame {
                    id: id_value & 0x1fff_ffff,
                    extended,
                    data: bytes,
                },
            ))
        })();
        match parsed {
            Some(f) => frames.push(f),
            None => bad += 1,
        }
    }
    (frames, bad)
}

/// Why the CAN driver stopped.
#[derive(Debug, thiserror::Error)]
pub enum CanDriverError {
    #[error("{0}")]
    Source(#[from] SourceError),
    #[error("shared memory: {0}")]
    Bus(#[from] BusError),
    #[error("{0}")]
    Config(String),
}

fn publish_health(
    hp: &mut BusPublisher<ProcessHealthV1>,
    name: &str,
    c: &CanCounters,
    timeouts: u64,
    state: ProcessState,
) -> Result<(), BusError> {
    let mut m = ProcessHealthV1 {
        host_time_ns: monotonic_ns(),
        frames: c.published,
        drops: c.counter_gaps,
        invalid: c.invalid + c.unknown_id,
        timeouts,
        pid: std::process::id(),
        state: state as u32,
        ..Default::default()
    };
    m.set_name(name);
    hp.publish(m).map(|_| ())
}

/// Runs the driver on `source` until SIGTERM/SIGINT or, for a finite source, its end.
pub fn run_with_source(
    cfg: &CanDriverConfig,
    depth: &mut CanDepth,
    source: &mut dyn FrameSource,
    finite: bool,
) -> Result<(), CanDriverError> {
    let bus = Bus::new(&cfg.name, &cfg.prefix)?;
    let mut depth_pub = bus.publisher::<DepthV1>(topic::DEPTH, qos::SENSOR)?;
    let mut health_pub = bus.publisher::<ProcessHealthV1>(topic::HEALTH, qos::HEALTH)?;
    let health_ns = (cfg.health_period_s * 1e9) as u64;
    let mut next_health = 0;
    let mut timeouts = 0;
    let mut state = ProcessState::Starting;
    bus.ready(&format!("{}: reading CAN frames", cfg.name));
    loop {
        if bus.termination_requested() {
            break;
        }
        let now = monotonic_ns();
        if now >= next_health {
            publish_health(&mut health_pub, &cfg.name, &depth.counters, timeouts, state)?;
            next_health = now + health_ns;
        }
        match source.next_frame()? {
            Some(f) => {
                let host_ns = monotonic_ns();
                state = ProcessState::Running;
                if let Some(m) = depth.on_frame(&f, host_ns)
                    && depth_pub.publish(m).is_ok()
                {
                    depth.counters.published += 1;
                }
            }
            None if finite => break,
            None => timeouts += 1,
        }
    }
    tracing::info!(
        frames = depth.counters.frames,
        published = depth.counters.published,
        "{}: stopping; {} frames, {} depth messages published, {} unknown identifiers, {} invalid",
        cfg.name,
        depth.counters.frames,
        depth.counters.published,
        depth.counters.unknown_id,
        depth.counters.invalid
    );
    publish_health(
        &mut health_pub,
        &cfg.name,
        &depth.counters,
        timeouts,
        ProcessState::Stopping,
    )?;
    Ok(())
}

/// Command line of `auvnav-can`.
#[derive(Debug, clap::Parser)]
#[command(
    name = "auvnav-can",
    version = auvnav_version::LONG,
    about = "CAN sensor driver: SocketCAN + DBC to shared memory"
)]
pub struct CanDriverArgs {
    /// `--config FILE`; `--check-config [FILE]` also checks the DBC mapping.
    #[command(flatten)]
    pub config: auvnav_version::cli::ConfigArgs,
    /// Read frames from a candump log (`candump -l` format) instead of the interface, at the
    /// log's pace (see --speed), then exit.
    #[arg(long)]
    pub candump: Option<String>,
    /// With --candump: play this many times faster than recorded (0.01..10000).
    #[arg(long, default_value_t = 1.0)]
    pub speed: f64,
}

/// Frames of a candump log, released at their recorded times scaled by a speed factor.
pub struct PacedFrames {
    frames: std::collections::VecDeque<(f64, CanFrame)>,
    speed: f64,
    start: Option<(std::time::Instant, f64)>,
}

impl PacedFrames {
    pub fn new(frames: Vec<(f64, CanFrame)>, speed: f64) -> Self {
        PacedFrames {
            frames: frames.into(),
            speed,
            start: None,
        }
    }
}

impl FrameSource for PacedFrames {
    fn next_frame(&mut self) -> Result<Option<CanFrame>, SourceError> {
        let Some((t, f)) = self.frames.pop_front() else {
            return Ok(None);
        };
        let (t0_wall, t0_log) = *self.start.get_or_insert((std::time::Instant::now(), t));
        let due = t0_wall + Duration::from_secs_f64(((t - t0_log) / self.speed).max(0.0));
        let now = std::time::Instant::now();
        if due > now {
            std::thread::sleep(due - now);
        }
        Ok(Some(f))
    }
}

/// Loads the configuration and the DBC, and builds the frame mapping.
pub fn load(path: &str) -> Result<(CanDriverConfig, CanDepth), CanDriverError> {
    let text = std::fs::read_to_string(path)
        .map_err(|e| CanDriverError::Config(format!("reading {path}: {e}")))?;
    let cfg: CanDriverConfig =
        toml::from_str(&text).map_err(|e| CanDriverError::Config(format!("{path}: {e}")))?;
    if !(0.001..=1.0).contains(&cfg.read_timeout_s) {
        return Err(CanDriverError::Config(format!(
            "{path}: read_timeout_s = {}: expected 0.001..=1 s",
            cfg.read_timeout_s
        )));
    }
    for (key, v, lo, hi) in [
        (
            "depth.pressure_scale_pa",
            cfg.depth.pressure_scale_pa,
            1e-6,
            1e9,
        ),
        ("depth.atmospheric_pa", cfg.depth.atmospheric_pa, 0.0, 2e5),
    ] {
        if !(v.is_finite() && v >= lo && v <= hi) {
            return Err(CanDriverError::Config(format!(
                "{path}: {key} = {v}: expected {lo}..={hi}"
            )));
        }
    }
    if !(0.05..=60.0).contains(&cfg.health_period_s) {
        return Err(CanDriverError::Config(format!(
            "{path}: health_period_s = {}: expected 0.05..=60 s",
            cfg.health_period_s
        )));
    }
    let dbc = if cfg.dbc.is_empty() {
        SAMPLE_DBC.to_string()
    } else {
        std::fs::read_to_string(&cfg.dbc)
            .map_err(|e| CanDriverError::Config(format!("reading DBC {}: {e}", cfg.dbc)))?
    };
    let depth = CanDepth::new(&dbc, cfg.depth.clone())
        .map_err(|e| CanDriverError::Config(format!("{path}: {e}")))?;
    Ok((cfg, depth))
}

/// `main` of `auvnav-can`: 0 after a clean stop, 2 configuration error, 3 no CAN interface,
/// 1 other failures.
pub fn main() -> std::process::ExitCode {
    use clap::Parser;
    use std::process::ExitCode;
    let args = CanDriverArgs::parse();
    auvnav_shm_schema::logging::init();
    let (path, check) = match args.config.required() {
        Ok(x) => x,
        Err(e) => {
            tracing::error!("auvnav-can: {e}");
            return ExitCode::from(2);
        }
    };
    let (cfg, mut depth) = match load(&path) {
        Ok(x) => x,
        Err(e) => {
            tracing::error!("auvnav-can: {e}");
            return ExitCode::from(2);
        }
    };
    if check {
        match toml::to_string_pretty(&cfg) {
            Ok(s) => print!("{s}"),
            Err(e) => tracing::error!("auvnav-can: {e}"),
        }
        return ExitCode::SUCCESS;
    }
    let result = if let Some(path) = &args.candump {
        let text = match std::fs::read_to_string(path) {
            Ok(t) => t,
            Err(e) => {
                tracing::error!("auvnav-can: reading {path}: {e}");
                return ExitCode::from(2);
            }
        };
        let (frames, bad) = parse_candump(&text);
        if bad > 0 {
            tracing::warn!("auvnav-can: {path}: {bad} lines are not candump frames (skipped)");
        }
        if !(args.speed.is_finite() && (0.01..=10_000.0).contains(&args.speed)) {
            tracing::error!("auvnav-can: --speed {}: expected 0.01..=10000", args.speed);
            return ExitCode::from(2);
        }
        let mut source = PacedFrames::new(frames, args.speed);
        let r = run_with_source(&cfg, &mut depth, &mut source, true);
        // A publisher's samples vanish with its process: give subscribers a moment to take the
        // last ones before exiting.
        std::thread::sleep(Duration::from_millis(500));
        r
    } else {
        match SocketCanSource::open(&cfg.interface, Duration::from_secs_f64(cfg.read_timeout_s)) {
            Ok(mut source) => run_with_source(&cfg, &mut depth, &mut source, false),
            Err(e) => {
                tracing::error!("auvnav-can: {e}");
                return ExitCode::from(3);
            }
        }
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            tracing::error!("auvnav-can: {e}");
            ExitCode::from(1)
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn pressure_frame(d: &CanDepth, bar: f64, temp: f64, counter: f64) -> CanFrame {
        d.decoder
            .encode(
                "PressureSensor",
                &[
                    ("Pressure", bar),
                    ("Temperature", temp),
                    ("Counter", counter),
                ],
            )
            .expect("frame")
    }

    #[test]
    fn pressure_frames_become_depth_and_gaps_are_counted() {
        let mut d = CanDepth::new(SAMPLE_DBC, DepthMapping::default()).expect("mapping");
        // 10 m of sea water: 1025 * 9.80665 * 10 Pa above one atmosphere.
        let bar = (101_325.0 + 1025.0 * 9.806_65 * 10.0) / 1e5;
        let f = pressure_frame(&d, bar, 12.5, 254.0);
        let m = d.on_frame(&f, 42).expect("depth");
        assert!((m.depth_m - 10.0).abs() < 1e-3, "{}", m.depth_m);
        assert!((m.temperature_c - 12.5).abs() < 0.01);
        assert_eq!(m.host_time_ns, 42);
        assert_eq!(
            m.validity,
            DepthV1::VALID_DEPTH | DepthV1::VALID_PRESSURE | DepthV1::VALID_TEMPERATURE
        );
        // Counter 254 -> 255 -> (lost 0, 1) -> 2: two frames lost across the wrap.
        d.on_frame(&pressure_frame(&d, bar, 12.5, 255.0), 43);
        d.on_frame(&pressure_frame(&d, bar, 12.5, 2.0), 44);
        assert_eq!(d.counters.counter_gaps, 2);
        // Other identifiers and short frames are counted, never published.
        let unknown = CanFrame {
            id: 0x7ff,
            extended: false,
            data: vec![0; 8],
        };
        assert!(d.on_frame(&unknown, 45).is_none());
        let short = CanFrame {
            data: f.data[..3].to_vec(),
            ..f.clone()
        };
        assert!(d.on_frame(&short, 46).is_none());
        assert_eq!((d.counters.unknown_id, d.counters.invalid), (1, 1));
    }

    #[test]
    fn a_mapping_that_does_not_fit_the_dbc_is_refused() {
        let bad = DepthMapping {
            pressure_signal: "Presure".into(),
            ..Default::default()
        };
        let e = CanDepth::new(SAMPLE_DBC, bad).err().expect("refused");
        assert!(
            e.contains("depth.pressure_signal") && e.contains("Presure"),
            "{e}"
        );
    }

    #[test]
    fn candump_lines_parse_and_bad_lines_are_counted() {
        let text = "(1436509052.249713) vcan0 181#A08601001405002A\n\
                    (1436509052.250000) vcan0 18FF0102#0102\n\
                    not a frame\n\
                    (1.0) vcan0 181#ABC\n";
        let (frames, bad) = parse_candump(text);
        assert_eq!(bad, 2);
        assert_eq!(frames.len(), 2);
        assert_eq!(frames[0].1.id, 0x181);
        assert!(!frames[0].1.extended && frames[1].1.extended);
        assert_eq!(frames[1].1.data, vec![1, 2]);
    }
}
