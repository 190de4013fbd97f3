//! `auvnav-mavlink`: sends the navigation solution (`nav/solution`) to an autopilot over MAVLink
//! (UDP or serial), with heartbeat, origin and status texts. See `auvnav_mavlink`.
//!
//! The solution topic is polled at four times the output rate, without a listener: the daemon's
//! publish then costs no notification for this process, and only the latest solution matters.
//! With `[source]` the autopilot's IMU, pressure and attitude messages are published on the bus
//! (`auvnav_mavlink::source`), and the link is polled at four times the IMU rate.
#![forbid(unsafe_code)]

use auvnav_mavlink::source::Source;
use auvnav_mavlink::{Link, MavlinkConfig};
use auvnav_protocols::autopilot::AutopilotReading;
use auvnav_shm_schema::bus::{Bus, BusPublisher};
use auvnav_shm_schema::{
    AttitudeV1, DepthV1, DvlVelocityV1, ImuSampleV1, MagnetometerV1, NavSolutionV1, qos, topic,
};
use mavlink::MavConnection;
use mavlink::dialects::ardupilotmega::MavMessage;
use std::time::Duration;

#[derive(Debug, clap::Parser)]
#[command(
    name = "auvnav-mavlink",
    version = auvnav_version::LONG,
    about = "The navigation solution to an autopilot (ArduSub) over MAVLink: ODOMETRY or GPS_INPUT, origin, heartbeat, status"
)]
struct Args {
    /// `--config FILE` (see docs/operations.md and deploy/auvnav-mavlink.toml),
    /// `--check-config [FILE]`.
    #[command(flatten)]
    config: auvnav_version::cli::ConfigArgs,
}

/// Nanoseconds since the process started (the heartbeat's clock).
fn elapsed_ns() -> u64 {
    use std::sync::OnceLock;
    static START: OnceLock<std::time::Instant> = OnceLock::new();
    START
        .get_or_init(std::time::Instant::now)
        .elapsed()
        .as_nanos() as u64
}

fn utc_now_ns() -> i64 {
    std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0, |d| d.as_nanos() as i64)
}

/// The autopilot's component id (`MAV_COMP_ID_AUTOPILOT1`).
const AUTOPILOT_COMPONENT: u8 = 1;

/// What the other end sent: counted, the autopilot's identity and status texts logged.
#[derive(Default)]
struct Heard {
    messages: u64,
    heartbeats: u64,
    status_texts: u64,
    unparsed: u64,
    /// The systems whose heartbeat was seen (logged once each).
    systems: Vec<u32>,
    /// Messages to send back: the stream requests of the source, the origin request.
    replies: Vec<MavMessage>,
    /// The autopilot's origin (`GPS_GLOBAL_ORIGIN`), when one came since the last look.
    origin: Option<auvnav_core::earth::Geodetic>,
    /// Whether the autopilot has reported its origin; until it has, every fifth of its
    /// heartbeats asks for it.
    origin_known: bool,
    autopilot_heartbeats: u64,
    /// The autopilot's heartbeat came since the link last looked.
    autopilot_heard: bool,
}

/// `MAV_CMD_REQUEST_MESSAGE` for the autopilot's `GPS_GLOBAL_ORIGIN` (answered once it has one).
fn origin_request(system: u8) -> MavMessage {
    MavMessage::COMMAND_LONG(mavlink::dialects::ardupilotmega::COMMAND_LONG_DATA {
        target_system: system,
        target_component: AUTOPILOT_COMPONENT,
        command: mavlink::dialects::ardupilotmega::MavCmd::MAV_CMD_REQUEST_MESSAGE,
        param1: 49.0, // GPS_GLOBAL_ORIGIN
        ..Default::default()
    })
}

/// The autopilot as a source: the conversion and its publishers.
struct SourceIo {
    source: Source,
    imu: BusPublisher<ImuSampleV1>,
    magnetometer: BusPublisher<MagnetometerV1>,
    depth: BusPublisher<DepthV1>,
    attitude: BusPublisher<AttitudeV1>,
    dvl: BusPublisher<DvlVelocityV1>,
    publish_errors: u64,
}

impl SourceIo {
    fn new(bus: &Bus, cfg: &auvnav_mavlink::source::SourceConfig) -> Result<SourceIo, String> {
        let e = |e: auvnav_shm_schema::bus::BusError| e.to_string();
        Ok(SourceIo {
            source: Source::new(cfg),
            imu: bus.publisher(topic::IMU, qos::SENSOR).map_err(e)?,
            magnetometer: bus.publisher(topic::MAGNETOMETER, qos::SENSOR).map_err(e)?,
            depth: bus.publisher(topic::DEPTH, qos::SENSOR).map_err(e)?,
            attitude: bus.publisher(topic::ATTITUDE, qos::SENSOR).map_err(e)?,
            dvl: bus.publisher(topic::DVL, qos::SENSOR).map_err(e)?,
            publish_errors: 0,
        })
    }

    fn on_message(&mut self, m: &MavMessage) {
        let now = auvnav_shm_schema::clock::monotonic_ns();
        for r in self.source.on_message(m, now) {
            let sent = match r {
                AutopilotReading::Imu(x) => self.imu.publish(x),
                AutopilotReading::Magnetometer(x) => self.magnetometer.publish(x),
                AutopilotReading::Depth(x) => self.depth.publish(x),
                AutopilotReading::Attitude(x) => self.attitude.publish(x),
                AutopilotReading::Dvl(x) => self.dvl.publish(x),
                AutopilotReading::Gnss(_) => Ok(0),
            };
            if sent.is_err() {
                self.publish_errors += 1;
            }
        }
    }
}

/// Reads what has arrived without waiting; an I/O error other than "nothing more now" (the
/// peer closed a TCP link) is returned for the caller to reconnect.
fn receive(
    c: &mavlink::Connection<MavMessage>,
    cfg: &MavlinkConfig,
    heard: &mut Heard,
    mut source: Option<&mut SourceIo>,
) -> std::io::Result<()> {
    // Bounded: a flood cannot keep the solutions from going out.
    for _ in 0..256 {
        let (header, m) = match c.try_recv() {
            Ok(x) => x,
            Err(mavlink::error::MessageReadError::Io(e))
                if matches!(
                    e.kind(),
                    std::io::ErrorKind::WouldBlock | std::io::ErrorKind::TimedOut
                ) =>
            {
                return Ok(());
            }
            Err(mavlink::error::MessageReadError::Io(e)) => return Err(e),
            Err(mavlink::error::MessageReadError::Parse(_)) => {
                heard.unparsed += 1;
                continue;
            }
        };
        heard.messages += 1;
        if header.system_id == u32::from(cfg.system_id) && header.component_id == cfg.component_id {
            continue;
        }
        // The source takes the autopilot's own messages only: the vehicle's system, component
        // MAV_COMP_ID_AUTOPILOT1 (a router also forwards other components' and stations').
        // A DVL extension's VISION_POSITION_DELTA comes from its own component.
        let vehicle = header.system_id == u32::from(cfg.system_id);
        let from_autopilot = vehicle && header.component_id == AUTOPILOT_COMPONENT;
        let dvl = vehicle && matches!(m, MavMessage::VISION_POSITION_DELTA(_));
        if let Some(s) = source.as_deref_mut()
            && (from_autopilot || dvl)
        {
            s.on_message(&m);
        }
        match m {
            MavMessage::GPS_GLOBAL_ORIGIN(o) if from_autopilot => {
                heard.origin_known = true;
                heard.origin = Some(auvnav_core::earth::Geodetic {
                    latitude_rad: (f64::from(o.latitude) * 1e-7).to_radians(),
                    longitude_rad: (f64::from(o.longitude) * 1e-7).to_radians(),
                    height_m: f64::from(o.altitude) * 1e-3,
                });
            }
            MavMessage::HEARTBEAT(h) => {
                heard.heartbeats += 1;
                if from_autopilot {
                    heard.autopilot_heard = true;
                }
                if from_autopilot && cfg.message == auvnav_mavlink::SolutionMessage::Odometry {
                    if !heard.origin_known
                        && heard.autopilot_heartbeats.is_multiple_of(5)
                        && let Ok(system) = u8::try_from(header.system_id)
                    {
                        heard.replies.push(origin_request(system));
                    }
                    heard.autopilot_heartbeats += 1;
                }
                if !heard.systems.contains(&header.system_id) {
                    heard.systems.push(header.system_id);
                    let autopilot = header.system_id == u32::from(cfg.system_id)
                        && header.component_id == AUTOPILOT_COMPONENT
                        && h.autopilot
                            != mavlink::dialects::ardupilotmega::MavAutopilot::MAV_AUTOPILOT_INVALID;
                    if let (true, Some(s), Ok(system)) =
                        (autopilot, source.as_deref(), u8::try_from(header.system_id))
                    {
                        heard
                            .replies
                            .extend(s.source.stream_requests(system, header.component_id));
                    }
                    tracing::info!(
                        "auvnav-mavlink: system {} component {} on {}: {:?} {:?}",
                        header.system_id,
                        header.component_id,
                        cfg.address,
                        h.mavtype,
                        h.autopilot
                    );
                }
            }
            MavMessage::STATUSTEXT(t) => {
                heard.status_texts += 1;
                tracing::info!(
                    "auvnav-mavlink: system {} says ({:?}): {}",
                    header.system_id,
                    t.severity,
                    t.text.to_str().unwrap_or("(not UTF-8)")
                );
            }
            _ => {}
        }
    }
    Ok(())
}

fn run(cfg: &MavlinkConfig) -> Result<(), String> {
    let bus = Bus::new("mavlink", &cfg.prefix).map_err(|e| e.to_string())?;
    let mut solutions = bus
        .subscriber::<NavSolutionV1>(topic::NAV_SOLUTION, qos::NAVIGATION)
        .map_err(|e| e.to_string())?;
    let mut link = Link::new(cfg);
    let mut heard = Heard::default();
    let mut source = match &cfg.source {
        Some(s) => Some(SourceIo::new(&bus, s)?),
        None => None,
    };
    let mut connection: Option<mavlink::Connection<MavMessage>> = None;
    let mut sequence: u8 = 0;
    let mut send_errors = 0u64;
    let mut last_error = String::new();
    let mut next_attempt = 0u64;
    let fastest_hz = cfg
        .source
        .as_ref()
        .map_or(cfg.rate_hz, |s| cfg.rate_hz.max(s.imu_hz));
    let poll = Duration::from_secs_f64(0.25 / fastest_hz);
    tracing::info!(
        "auvnav-mavlink: {} at {} Hz to {} as system {} component {}",
        match cfg.message {
            auvnav_mavlink::SolutionMessage::Odometry => "ODOMETRY",
            auvnav_mavlink::SolutionMessage::GpsInput => "GPS_INPUT",
        },
        cfg.rate_hz,
        cfg.address,
        cfg.system_id,
        cfg.component_id
    );
    bus.ready(&format!("sending to {}", cfg.address));
    while !bus.termination_requested() {
        let now = elapsed_ns();
        if connection.is_none() && now >= next_attempt {
            match mavlink::connect::<MavMessage>(&cfg.address) {
                Ok(mut c) => {
                    c.set_protocol_version(mavlink::MavlinkVersion::V2);
                    c.set_allow_recv_any_version(true);
                    tracing::info!("auvnav-mavlink: {} open", cfg.address);
                    link.on_link_open(now);
                    connection = Some(c);
                    last_error.clear();
                }
                Err(e) => {
                    let msg = e.to_string();
                    if msg != last_error {
                        tracing::warn!(
                            "auvnav-mavlink: cannot open {}: {msg}; retrying every 1 s",
                            cfg.address
                        );
                        last_error = msg;
                    }
                    next_attempt = now + 1_000_000_000;
                }
            }
        }
        let mut latest = None;
        while let Ok(Some(s)) = solutions.receive() {
            latest = Some(s);
        }
        if std::mem::take(&mut heard.autopilot_heard) {
            link.on_autopilot_heard(now);
        }
        if let Some(o) = heard.origin.take()
            && let Some(change) = link.on_autopilot_origin(o)
        {
            tracing::warn!("auvnav-mavlink: {change}");
        }
        let mut out = link.on_tick(now);
        out.append(&mut heard.replies);
        if let Some(s) = latest {
            out.extend(link.on_solution(&s, utc_now_ns()));
        }
        if let Some(c) = connection.as_ref() {
            for m in &out {
                if let Err(e) = c.send(&link.header(sequence), m) {
                    send_errors += 1;
                    let msg = e.to_string();
                    if msg != last_error {
                        tracing::warn!("auvnav-mavlink: sending to {}: {msg}", cfg.address);
                        last_error = msg;
                    }
                }
                sequence = sequence.wrapping_add(1);
            }
        }
        if let Some(c) = connection.as_ref()
            && let Err(e) = receive(c, cfg, &mut heard, source.as_mut())
        {
            tracing::warn!(
                "auvnav-mavlink: {} closed ({e}); reconnecting in 1 s",
                cfg.address
            );
            connection = None;
            next_attempt = now + 1_000_000_000;
        }
        std::thread::sleep(poll);
    }
    tracing::info!(
        "auvnav-mavlink: received {} messages ({} heartbeats of the autopilot, {} status texts, {} that did not parse)",
        heard.messages,
        heard.heartbeats,
        heard.status_texts,
        heard.unparsed
    );
    if let Some(s) = &source {
        let c = s.source.counters;
        tracing::info!(
            "auvnav-mavlink: from the autopilot, published {} IMU samples, {} magnetometer, {} depth, {} attitude and {} DVL readings; {} implausible and {} out-of-order readings left out, {} publish errors, {} boot(s) of the autopilot",
            c.imu,
            c.magnetometer,
            c.depth,
            c.attitude,
            c.dvl,
            c.implausible,
            c.out_of_order,
            s.publish_errors,
            s.source.autopilot_boots()
        );
    }
    let c = link.counters;
    tracing::info!(
        "auvnav-mavlink: stopping; {} solutions, {} heartbeats, {} origins, {} status texts sent, {} solutions withheld (before alignment or above the rate), {} send errors",
        c.solutions,
        c.heartbeats,
        c.origins,
        c.status_texts,
        c.withheld,
        send_errors
    );
    Ok(())
}

fn main() -> std::process::ExitCode {
    use clap::Parser;
    let args = Args::parse();
    auvnav_shm_schema::logging::init();
    let (path, check) = match args.config.required() {
        Ok(x) => x,
        Err(e) => {
            tracing::error!("auvnav-mavlink: {e}");
            return std::process::ExitCode::from(2);
        }
    };
    let cfg = match MavlinkConfig::load(&path) {
        Ok(c) => c,
        Err(e) => {
            tracing::error!("auvnav-mavlink: {e}");
            return std::process::ExitCode::from(2);
        }
    };
    if check {
        match toml::to_string_pretty(&cfg) {
            Ok(s) => print!("{s}"),
            Err(e) => tracing::error!("auvnav-mavlink: {e}"),
        }
        return std::process::ExitCode::SUCCESS;
    }
    match run(&cfg) {
        Ok(()) => std::process::ExitCode::SUCCESS,
        Err(e) => {
            tracing::error!("auvnav-mavlink: {e}");
            std::process::ExitCode::from(1)
        }
    }
}
