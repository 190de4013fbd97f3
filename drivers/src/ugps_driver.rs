//! `auvnav-ugps`: the Water Linked Underwater GPS driver process. It polls the topside's HTTP
//! API on the vehicle's (or the boat's) network and publishes:
//!
//! - each new acoustic reading (`/api/v1/position/acoustic/raw`: the per-receiver ranges, the
//!   locator's fix and its one-sigma, the receivers' configured positions from
//!   `/api/v1/config/receivers/`) on `acoustic_ranges`;
//! - each new topside position and heading (`/api/v1/position/master`) on
//!   `acoustic_array_pose`, the moving array's pose the range aid places the receivers with.
//!
//! The API repeats its last reading until the next: a reading equal to the previous one is not
//! published again (counted as repeated), so a message's host time is when the reading was
//! first seen — within one poll period of its arrival at the topside. Poll faster than the
//! API updates (about 4 Hz acoustic, 1–5 Hz position) to keep that delay small.
//!
//! Nothing in a response stops the driver: a body that is not JSON or lacks a field is counted
//! (health `invalid`) and skipped, a value out of range is left out of its message and counted,
//! an HTTP error status is counted (health `drops`), and a topside that does not answer is
//! retried with exponential back-off (health `reconnects` when it answers again).

use crate::clock::monotonic_ns;
use crate::http::{self, HttpBase, HttpError};
use auvnav_protocols::ugps::{self, Receiver, UgpsError, to_schema};
use auvnav_shm_schema::bus::{Bus, BusError, BusPublisher};
use auvnav_shm_schema::{
    AcousticArrayPoseV1, AcousticRangesV1, ProcessHealthV1, ProcessState, qos, topic,
};
use serde::{Deserialize, Serialize};
use std::time::Duration;

/// Largest response body read (bytes; an acoustic reading is about 400).
const MAX_BODY: usize = 256 * 1024;

/// How often each endpoint is asked (`[poll]`).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct PollConfig {
    /// The acoustic reading (Hz, 0.1..=50, default 10: the API updates it at about 4 Hz).
    pub acoustic_hz: f64,
    /// The topside's position and heading (Hz, 0.1..=50, default 5).
    pub master_hz: f64,
    /// The receivers' configured positions: read at the start and again every this many
    /// seconds (0..=3600, default 60; 0: never, the navigator's configuration places them).
    pub receivers_period_s: f64,
    /// Longest a request may take, connection included (s, 0.01..=2, default 0.5; the loop
    /// waits on it, and the service manager's watchdog allows 5 s).
    pub request_timeout_s: f64,
}

impl Default for PollConfig {
    fn default() -> Self {
        PollConfig {
            acoustic_hz: 10.0,
            master_hz: 5.0,
            receivers_period_s: 60.0,
            request_timeout_s: 0.5,
        }
    }
}

/// Health and reconnection (`[timing]`).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct UgpsTiming {
    /// No new acoustic reading for this long while the topside answers: reported (health
    /// `timeouts` + 1; the locator may be out of reach) (s, 0.1..=3600, default 5).
    pub silence_timeout_s: f64,
    /// First wait after a request the topside did not answer (s, 0.001..=60, default 0.1);
    /// doubles per failure…
    pub reconnect_initial_s: f64,
    /// …up to this (s, reconnect_initial_s..=600, default 5).
    pub reconnect_max_s: f64,
    /// Period of the health message (s, 0.05..=60, default 1).
    pub health_period_s: f64,
}

impl Default for UgpsTiming {
    fn default() -> Self {
        UgpsTiming {
            silence_timeout_s: 5.0,
            reconnect_initial_s: 0.1,
            reconnect_max_s: 5.0,
            health_period_s: 1.0,
        }
    }
}

/// The driver's configuration file.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct UgpsDriverConfig {
    /// Process name in the health message (default `ugps`; at most 32 bytes).
    #[serde(default)]
    pub name: Option<String>,
    /// Service-name prefix of the deployment (default `auvnav`).
    #[serde(default = "default_prefix")]
    pub prefix: String,
    /// The topside's address, `http://host[:port]` (a G2's default is `http://192.168.2.94`).
    pub url: String,
    #[serde(default)]
    pub poll: PollConfig,
    #[serde(default)]
    pub timing: UgpsTiming,
}

fn default_prefix() -> String {
    topic::DEFAULT_PREFIX.to_string()
}

impl UgpsDriverConfig {
    /// Reads and checks a configuration file.
    pub fn load(path: &str) -> Result<UgpsDriverConfig, String> {
        let text = std::fs::read_to_string(path).map_err(|e| format!("reading {path}: {e}"))?;
        let cfg: UgpsDriverConfig = toml::from_str(&text).map_err(|e| format!("{path}: {e}"))?;
        cfg.check().map_err(|e| format!("{path}: {e}"))?;
        Ok(cfg)
    }

    /// Range checks; the error names the key.
    pub fn check(&self) -> Result<(), String> {
        HttpBase::parse(&self.url).map_err(|e| format!("url = {e}"))?;
        let (p, t) = (&self.poll, &self.timing);
        let checks: [(&str, f64, f64, f64); 8] = [
            ("poll.acoustic_hz", p.acoustic_hz, 0.1, 50.0),
            ("poll.master_hz", p.master_hz, 0.1, 50.0),
            ("poll.receivers_period_s", p.receivers_period_s, 0.0, 3600.0),
            ("poll.request_timeout_s", p.request_timeout_s, 0.01, 2.0),
            ("timing.silence_timeout_s", t.silence_timeout_s, 0.1, 3600.0),
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
                return Err(format!("{key} = {v}: {lo}..={hi}"));
            }
        }
        if let Some((key, value, expected)) =
            crate::serial_driver::prefix_and_name_problem(&self.prefix, self.name.as_deref())
        {
            return Err(format!("{key} = {value}: {expected}"));
        }
        Ok(())
    }

    /// The process name.
    pub fn process_name(&self) -> String {
        self.name.clone().unwrap_or_else(|| "ugps".to_string())
    }
}

/// What the driver counted.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize)]
pub struct UgpsCounters {
    /// Messages published on `acoustic_ranges` and on `acoustic_array_pose`.
    pub ranges_published: u64,
    pub poses_published: u64,
    /// Readings equal to the previous one (not published again).
    pub repeated: u64,
    /// Requests the topside did not answer (refused, reset, timed out) and, of those, timeouts.
    pub unanswered: u64,
    pub timed_out: u64,
    /// Answers with an HTTP status other than 200.
    pub http_errors: u64,
    /// Bodies refused: not JSON or not an HTTP answer, a required field missing, a field of the
    /// wrong type or length.
    pub not_json: u64,
    pub missing_fields: u64,
    pub wrong_fields: u64,
    /// Values out of their physical range, left out of the messages.
    pub out_of_range: u64,
    /// Master positions with neither a usable position nor a heading (nothing published).
    pub poses_unusable: u64,
    /// Receiver configurations read.
    pub receiver_reads: u64,
    /// Stretches without a new acoustic reading longer than the silence timeout.
    pub silences: u64,
    pub reconnects: u64,
    pub publish_errors: u64,
}

impl UgpsCounters {
    fn refused(&mut self, e: &UgpsError) {
        match e {
            UgpsError::NotJson(_) => self.not_json += 1,
            UgpsError::Missing(_) => self.missing_fields += 1,
            UgpsError::Field { .. } => self.wrong_fields += 1,
        }
    }

    /// The health message's view: `frames` published, `invalid` bodies refused and values out
    /// of range, `drops` HTTP errors and failed publications, `timeouts` requests timed out and
    /// silences.
    fn health(&self, name: &str, state: ProcessState) -> ProcessHealthV1 {
        let mut m = ProcessHealthV1 {
            host_time_ns: monotonic_ns(),
            frames: self.ranges_published + self.poses_published,
            timeouts: self.timed_out + self.silences,
            reconnects: self.reconnects,
            drops: self.http_errors + self.publish_errors,
            invalid: self.not_json + self.missing_fields + self.wrong_fields + self.out_of_range,
            pid: std::process::id(),
            state: state as u32,
            ..Default::default()
        };
        m.set_name(name);
        m
    }
}

/// Why the driver stopped.
#[derive(Debug, thiserror::Error)]
pub enum UgpsDriverError {
    #[error("shared memory: {0}")]
    Bus(#[from] BusError),
    #[error("{0}")]
    Config(String),
}

/// The three requests, in the order they are served when due at once.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Endpoint {
    Receivers,
    Acoustic,
    Master,
}

impl Endpoint {
    fn path(self) -> &'static str {
        match self {
            Endpoint::Receivers => ugps::path::RECEIVERS,
            Endpoint::Acoustic => ugps::path::ACOUSTIC_RAW,
            Endpoint::Master => ugps::path::MASTER,
        }
    }
}

/// The driver's state between requests.
struct Driver {
    name: String,
    counters: UgpsCounters,
    ranges: BusPublisher<AcousticRangesV1>,
    poses: BusPublisher<AcousticArrayPoseV1>,
    receivers: Option<Vec<Receiver>>,
    last_reading: Option<Vec<u64>>,
    last_pose: Option<[u64; 3]>,
    /// When the latest new acoustic reading was seen, and whether a silence was reported.
    last_new_ns: u64,
    silent: bool,
}

impl Driver {
    fn on_body(&mut self, endpoint: Endpoint, body: &[u8], host_ns: u64) {
        match endpoint {
            Endpoint::Receivers => match ugps::receivers(body) {
                Ok(r) => {
                    if self.receivers.as_ref() != Some(&r) {
                        tracing::info!(
                            "{}: receivers at {:?} m (x, y, z from the topside)",
                            self.name,
                            r.iter().map(|r| [r.x, r.y, r.z]).collect::<Vec<_>>()
                        );
                    }
                    self.counters.receiver_reads += 1;
                    self.receivers = Some(r);
                }
                Err(e) => {
                    tracing::warn!("{}: receiver configuration refused: {e}", self.name);
                    self.counters.refused(&e);
                }
            },
            Endpoint::Acoustic => match ugps::acoustic_raw(body) {
                Ok(raw) => self.on_reading(&raw, host_ns),
                Err(e) => {
                    tracing::debug!("{}: acoustic reading refused: {e}", self.name);
                    self.counters.refused(&e);
                }
            },
            Endpoint::Master => match ugps::master_position(body) {
                Ok(p) => self.on_master(&p, host_ns),
                Err(e) => {
                    tracing::debug!("{}: topside position refused: {e}", self.name);
                    self.counters.refused(&e);
                }
            },
        }
    }

    fn on_reading(&mut self, raw: &ugps::AcousticRaw, host_ns: u64) {
        let mut key: Vec<u64> = raw.position_m.iter().map(|x| x.to_bits()).collect();
        key.push(u64::from(raw.position_valid));
        for r in &raw.receivers {
            key.extend([r.distance_m.to_bits(), u64::from(r.valid)]);
        }
        if self.last_reading.as_ref() == Some(&key) {
            self.counters.repeated += 1;
            return;
        }
        self.last_reading = Some(key);
        self.last_new_ns = host_ns;
        if self.silent {
            tracing::info!("{}: acoustic readings again", self.name);
            self.silent = false;
        }
        // The publisher numbers the messages.
        let (m, bad) = to_schema::ugps_ranges(raw, self.receivers.as_deref(), host_ns, 0);
        self.counters.out_of_range += u64::from(bad);
        match self.ranges.publish(m) {
            Ok(_) => self.counters.ranges_published += 1,
            Err(_) => self.counters.publish_errors += 1,
        }
    }

    fn on_master(&mut self, p: &ugps::MasterPosition, host_ns: u64) {
        let key = [
            p.lat_deg.to_bits(),
            p.lon_deg.to_bits(),
            p.orientation_deg.to_bits(),
        ];
        if self.last_pose == Some(key) {
            self.counters.repeated += 1;
            return;
        }
        self.last_pose = Some(key);
        let (m, bad) = to_schema::ugps_array_pose(p, host_ns, 0);
        self.counters.out_of_range += u64::from(bad);
        let Some(m) = m else {
            self.counters.poses_unusable += 1;
            return;
        };
        match self.poses.publish(m) {
            Ok(_) => self.counters.poses_published += 1,
            Err(_) => self.counters.publish_errors += 1,
        }
    }
}

/// Runs the driver until SIGTERM/SIGINT; returns what it counted.
// Long on purpose: the driver's one loop (schedule, request, back-off, health, signals) over
// the topside's state; decoding is in auvnav-protocols and the bodies in `Driver`.
pub fn run(cfg: &UgpsDriverConfig) -> Result<UgpsCounters, UgpsDriverError> {
    let name = cfg.process_name();
    let base =
        HttpBase::parse(&cfg.url).map_err(|e| UgpsDriverError::Config(format!("url = {e}")))?;
    let bus = Bus::new(&name, &cfg.prefix)?;
    let mut d = Driver {
        name: name.clone(),
        counters: UgpsCounters::default(),
        ranges: bus.publisher(topic::ACOUSTIC_RANGES, qos::SENSOR)?,
        poses: bus.publisher(topic::ACOUSTIC_ARRAY_POSE, qos::SENSOR)?,
        receivers: None,
        last_reading: None,
        last_pose: None,
        last_new_ns: monotonic_ns(),
        silent: false,
    };
    let mut health_pub = bus.publisher::<ProcessHealthV1>(topic::HEALTH, qos::HEALTH)?;
    let (p, t) = (cfg.poll, cfg.timing);
    let timeout = Duration::from_secs_f64(p.request_timeout_s);
    let period_ns = |hz: f64| (1e9 / hz) as u64;
    let health_ns = (t.health_period_s * 1e9) as u64;
    let silence_ns = (t.silence_timeout_s * 1e9) as u64;
    let start = monotonic_ns();
    let mut next = [
        (
            Endpoint::Receivers,
            (p.receivers_period_s > 0.0).then_some(start),
        ),
        (Endpoint::Acoustic, Some(start)),
        (Endpoint::Master, Some(start)),
    ];
    let mut next_health = 0u64;
    let mut state = ProcessState::Starting;
    let mut answering = true;
    let mut backoff_s = t.reconnect_initial_s;
    let mut retry_at = 0u64;
    let mut last_failure = String::new();
    tracing::info!(
        "{name}: Water Linked Underwater GPS at {}, acoustic {} Hz, position {} Hz, publishing on {}/{} and {}/{}",
        base.url,
        p.acoustic_hz,
        p.master_hz,
        cfg.prefix,
        topic::ACOUSTIC_RANGES,
        cfg.prefix,
        topic::ACOUSTIC_ARRAY_POSE
    );
    bus.ready(&format!("{name}: polling {}", base.url));
    loop {
        if bus.termination_requested() {
            break;
        }
        let now = monotonic_ns();
        if now >= next_health {
            if health_pub.publish(d.counters.health(&name, state)).is_err() {
                d.counters.publish_errors += 1;
            }
            next_health = now + health_ns;
        }
        if answering && !d.silent && now.saturating_sub(d.last_new_ns) > silence_ns {
            d.silent = true;
            d.counters.silences += 1;
            tracing::warn!(
                "{name}: no new acoustic reading for {} s (the locator out of reach?)",
                t.silence_timeout_s
            );
        }
        let due = next
            .iter()
            .filter_map(|(e, at)| at.map(|a| (a, *e)))
            .min_by_key(|(a, _)| *a);
        let Some((at, endpoint)) = due else {
            break;
        };
        let at = at.max(retry_at);
        if now < at {
            std::thread::sleep(Duration::from_nanos((at - now).min(20_000_000)));
            continue;
        }
        let result = http::get(&base, endpoint.path(), timeout, MAX_BODY);
        let host_ns = monotonic_ns();
        let step = match endpoint {
            Endpoint::Receivers => (p.receivers_period_s * 1e9) as u64,
            Endpoint::Acoustic => period_ns(p.acoustic_hz),
            Endpoint::Master => period_ns(p.master_hz),
        };
        match result {
            Err(e) if e.unreachable() => {
                d.counters.unanswered += 1;
                if matches!(e, HttpError::Timeout(_)) {
                    d.counters.timed_out += 1;
                }
                let msg = e.to_string();
                if answering || msg != last_failure {
                    tracing::warn!(
                        "{name}: {} does not answer: {msg}; retrying with back-off up to {} s",
                        base.url,
                        t.reconnect_max_s
                    );
                    last_failure = msg;
                }
                answering = false;
                state = ProcessState::Reconnecting;
                retry_at = host_ns + (backoff_s * 1e9) as u64;
                backoff_s = (backoff_s * 2.0).min(t.reconnect_max_s);
                continue;
            }
            result => {
                if !answering {
                    d.counters.reconnects += 1;
                    tracing::info!("{name}: {} answers again", base.url);
                    d.last_new_ns = host_ns;
                    if endpoint != Endpoint::Receivers && p.receivers_period_s > 0.0 {
                        // The topside may have restarted with other receivers.
                        next[0].1 = Some(host_ns);
                    }
                }
                answering = true;
                last_failure.clear();
                backoff_s = t.reconnect_initial_s;
                retry_at = 0;
                state = ProcessState::Running;
                match result {
                    Ok(body) => d.on_body(endpoint, &body, host_ns),
                    Err(HttpError::Status(s)) => {
                        d.counters.http_errors += 1;
                        tracing::debug!("{name}: {} answered {s}", endpoint.path());
                    }
                    Err(e) => {
                        d.counters.not_json += 1;
                        tracing::debug!("{name}: {}: {e}", endpoint.path());
                    }
                }
            }
        }
        for (e, at) in next.iter_mut() {
            if *e == endpoint {
                *at = at.map(|a| {
                    if a + step <= host_ns {
                        host_ns + step
                    } else {
                        a + step
                    }
                });
            }
        }
    }
    let c = d.counters;
    tracing::info!(
        "{name}: stopping; {} range messages and {} array poses published, {} repeated readings, \
         {} unanswered requests ({} timed out), {} HTTP errors, {} bodies not JSON, {} with a \
         field missing, {} with a wrong field, {} values out of range, {} reconnects",
        c.ranges_published,
        c.poses_published,
        c.repeated,
        c.unanswered,
        c.timed_out,
        c.http_errors,
        c.not_json,
        c.missing_fields,
        c.wrong_fields,
        c.out_of_range,
        c.reconnects
    );
    health_pub.publish(c.health(&name, ProcessState::Stopping))?;
    Ok(c)
}

/// Command line of `auvnav-ugps`.
#[derive(Debug, clap::Parser)]
#[command(
    name = "auvnav-ugps",
    version = auvnav_version::LONG,
    about = "Water Linked Underwater GPS driver: the topside's HTTP API (per-receiver ranges, \
             the locator's fix, the topside's GNSS and heading) to shared memory"
)]
pub struct UgpsArgs {
    /// `--config FILE` (see docs/drivers.md), `--check-config [FILE]`.
    #[command(flatten)]
    pub config: auvnav_version::cli::ConfigArgs,
}

/// `main` of `auvnav-ugps`: exit 0 after a clean stop, 2 for a configuration error, 1 for a
/// shared-memory failure.
pub fn main() -> std::process::ExitCode {
    use clap::Parser;
    let args = UgpsArgs::parse();
    auvnav_shm_schema::logging::init();
    let (path, check) = match args.config.required() {
        Ok(x) => x,
        Err(e) => {
            tracing::error!("auvnav-ugps: {e}");
            return std::process::ExitCode::from(2);
        }
    };
    let cfg = match UgpsDriverConfig::load(&path) {
        Ok(c) => c,
        Err(e) => {
            tracing::error!("auvnav-ugps: {e}");
            return std::process::ExitCode::from(2);
        }
    };
    if check {
        match toml::to_string_pretty(&cfg) {
            Ok(s) => print!("{s}"),
            Err(e) => tracing::error!("auvnav-ugps: {e}"),
        }
        return std::process::ExitCode::SUCCESS;
    }
    match run(&cfg) {
        Ok(_) => std::process::ExitCode::SUCCESS,
        Err(e) => {
            tracing::error!("auvnav-ugps: {e}");
            std::process::ExitCode::from(1)
        }
    }
}
