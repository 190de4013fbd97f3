//! `auvnav-bridge`: see the library's documentation (`auvnav_bridge`).
#![forbid(unsafe_code)]

use auvnav_bridge::ros2::{self, Ros2Config, RosType};
use auvnav_bridge::{
    BridgeConfig, ExportPort, ImportPort, RateLimit, Rejected, TOPICS, TopicKind, ZenohConfig,
    check_type, matches,
};
use auvnav_shm_schema::bus::{Bus, BusError, BusSubscriber};
use auvnav_shm_schema::clock::monotonic_ns;
use auvnav_shm_schema::{DvlVelocityV1, ImuSampleV1, NavMode, NavSolutionV1};
use auvnav_shm_schema::{ProcessHealthV1, ProcessState, qos, topic};
use clap::Parser;
use std::collections::HashMap;
use std::process::ExitCode;
use std::time::Duration;
use zenoh::Wait;

#[derive(Parser)]
#[command(
    name = "auvnav-bridge",
    about = "Carries selected bus topics between hosts over Zenoh",
    version = auvnav_version::LONG
)]
struct Args {
    /// `--config FILE`, `--check-config [FILE]`.
    #[command(flatten)]
    config: auvnav_version::cli::ConfigArgs,
}

/// One exported topic.
struct Export {
    kind: &'static TopicKind,
    port: Box<dyn ExportPort>,
    publisher: zenoh::pubsub::Publisher<'static>,
    limit: RateLimit,
    sent: u64,
    rate_limited: u64,
    failed: u64,
}

/// One `[[import]]`: a Zenoh subscriber and the local publishers it feeds.
struct Import {
    key_prefix: String,
    topics: String,
    bus: Bus,
    subscriber:
        zenoh::pubsub::Subscriber<zenoh::handlers::RingChannelHandler<zenoh::sample::Sample>>,
    ports: HashMap<&'static str, Box<dyn ImportPort>>,
    received: u64,
    published: u64,
    unknown_topic: u64,
    wrong_type: u64,
    wrong_size: u64,
    failed: u64,
}

/// One ROS 2 topic: its Zenoh publisher, its publisher id and sequence.
struct RosPublisher {
    publisher: zenoh::pubsub::Publisher<'static>,
    gid: [u8; 16],
    sequence: i64,
}

impl RosPublisher {
    fn put(&mut self, payload: Vec<u8>, utc_ns: i64) -> Result<(), String> {
        self.sequence += 1;
        self.publisher
            .put(payload)
            .attachment(ros2::attachment(self.sequence, utc_ns, &self.gid))
            .wait()
            .map_err(|x| x.to_string())
    }
}

/// The ROS 2 side of the bridge (`[ros2]`): liveliness tokens kept for as long as it runs, the
/// bus subscribers it reads (polled on the bridge's tick: no notification listener, so the
/// daemon's and drivers' 1 kHz publishing costs nothing more) and the ROS publishers.
struct Ros2Out {
    cfg: Ros2Config,
    _tokens: Vec<zenoh::liveliness::LivelinessToken>,
    solutions: BusSubscriber<NavSolutionV1>,
    imu: Option<(BusSubscriber<ImuSampleV1>, RosPublisher)>,
    dvl: Option<(BusSubscriber<DvlVelocityV1>, RosPublisher)>,
    health: Option<(BusSubscriber<ProcessHealthV1>, RosPublisher)>,
    odometry: RosPublisher,
    fix: RosPublisher,
    limit: RateLimit,
    /// The first aligned solution (lat, lon, height): the origin of `odometry`.
    origin: Option<[f64; 3]>,
    sent: u64,
    failed: u64,
}

/// Declares the node and one publisher per ROS topic on `session`.
fn ros2_out(session: &zenoh::Session, bus: &Bus, cfg: &Ros2Config) -> Result<Ros2Out, String> {
    let zid = session.zid().to_string();
    let node_id = 0;
    let mut tokens = vec![
        session
            .liveliness()
            .declare_token(ros2::node_token(cfg, &zid, node_id))
            .wait()
            .map_err(|x| format!("declaring the ROS 2 node's liveliness token: {x}"))?,
    ];
    let mut next_id = node_id;
    let mut declare = |topic: &str, t: &RosType| -> Result<RosPublisher, String> {
        next_id += 1;
        let name = cfg.topic(topic);
        let key = ros2::data_key(cfg.domain_id, &name, t);
        let token = ros2::publisher_token(cfg, &zid, node_id, next_id, &name, t, 10);
        tokens.push(
            session
                .liveliness()
                .declare_token(token.clone())
                .wait()
                .map_err(|x| format!("declaring the liveliness token of {name}: {x}"))?,
        );
        let publisher = session
            .declare_publisher(key.clone())
            .congestion_control(zenoh::qos::CongestionControl::Drop)
            .wait()
            .map_err(|x| format!("declaring the Zenoh publisher {key}: {x}"))?;
        tracing::info!("ROS 2: publishing {name} ({}) as {key}", t.name);
        Ok(RosPublisher {
            publisher,
            gid: ros2::gid(&token),
            sequence: 0,
        })
    };
    let e = |x: BusError| x.to_string();
    let odometry = declare("odometry", &ros2::ODOMETRY)?;
    let fix = declare("fix", &ros2::NAV_SAT_FIX)?;
    let imu = if cfg.imu {
        Some((
            bus.subscriber(topic::IMU, qos::SENSOR).map_err(e)?,
            declare("imu/data_raw", &ros2::IMU)?,
        ))
    } else {
        None
    };
    let dvl = if cfg.dvl {
        Some((
            bus.subscriber(topic::DVL, qos::SENSOR).map_err(e)?,
            declare("dvl/twist", &ros2::TWIST_WITH_COVARIANCE_STAMPED)?,
        ))
    } else {
        None
    };
    let health = if cfg.diagnostics {
        Some((
            bus.subscriber(topic::HEALTH, qos::HEALTH).map_err(e)?,
            declare("/diagnostics", &ros2::DIAGNOSTIC_ARRAY)?,
        ))
    } else {
        None
    };
    Ok(Ros2Out {
        cfg: cfg.clone(),
        _tokens: tokens,
        solutions: bus
            .subscriber(topic::NAV_SOLUTION, qos::NAVIGATION)
            .map_err(e)?,
        imu,
        dvl,
        health,
        odometry,
        fix,
        limit: RateLimit::new(cfg.solution_rate_hz),
        origin: None,
        sent: 0,
        failed: 0,
    })
}

impl Ros2Out {
    /// Publishes what arrived on the bus since the last call.
    fn step(&mut self) {
        // Host (monotonic) time stamps become UTC, as ROS time stamps are.
        let utc_now = std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .map_or(0, |d| d.as_nanos() as i64);
        let offset = utc_now - monotonic_ns() as i64;
        let stamp = |host_ns: u64| host_ns as i64 + offset;
        let mut results = Vec::new();
        while let Ok(Some(s)) = self.solutions.receive() {
            if !self.limit.admit(s.host_time_ns) {
                continue;
            }
            let here = [s.latitude_rad, s.longitude_rad, s.height_m];
            let aligned = matches!(
                NavMode::try_from(s.mode),
                Ok(NavMode::Navigating | NavMode::Degraded)
            );
            if self.origin.is_none() && aligned {
                self.origin = Some(here);
            }
            if let Some(origin) = self.origin {
                let ned = ros2::ned_offset(origin, here);
                let payload = ros2::odometry(&self.cfg, &s, ned, stamp(s.host_time_ns));
                results.push(self.odometry.put(payload, utc_now));
            }
            let payload = ros2::nav_sat_fix(&self.cfg, &s, stamp(s.host_time_ns));
            results.push(self.fix.put(payload, utc_now));
        }
        if let Some((sub, p)) = self.imu.as_mut() {
            while let Ok(Some(m)) = sub.receive() {
                results.push(p.put(ros2::imu(&self.cfg, &m, stamp(m.host_time_ns)), utc_now));
            }
        }
        if let Some((sub, p)) = self.dvl.as_mut() {
            while let Ok(Some(m)) = sub.receive() {
                let t = stamp(m.validity_time_ns.max(1));
                results.push(p.put(ros2::dvl_twist(&self.cfg, &m, t), utc_now));
            }
        }
        if let Some((sub, p)) = self.health.as_mut() {
            while let Ok(Some(h)) = sub.receive() {
                results.push(p.put(ros2::diagnostics(&h, stamp(h.host_time_ns)), utc_now));
            }
        }
        for r in results {
            match r {
                Ok(()) => self.sent += 1,
                Err(_) => self.failed += 1,
            }
        }
    }
}

fn zenoh_config(z: &ZenohConfig) -> Result<zenoh::Config, String> {
    let mut c = zenoh::Config::default();
    let mut set = |key: &str, value: String| {
        c.insert_json5(key, &value)
            .map_err(|e| format!("zenoh setting {key} = {value}: {e}"))
    };
    let json = |v: serde_json::Value| v.to_string();
    set("mode", json(z.mode.clone().into()))?;
    set("listen/endpoints", json(z.listen.clone().into()))?;
    set("connect/endpoints", json(z.connect.clone().into()))?;
    set(
        "scouting/multicast/enabled",
        z.multicast_scouting.to_string(),
    )?;
    Ok(c)
}

// Long on purpose: the bridge's one loop: a subscriber and a Zenoh publisher per topic, restarts
// and counters over the same state.
fn run(cfg: &BridgeConfig) -> Result<(), String> {
    let e = |x: BusError| x.to_string();
    let bus = Bus::new(&cfg.name, &cfg.prefix).map_err(e)?;
    bus.cleanup_dead_nodes();
    let session = zenoh::open(zenoh_config(&cfg.zenoh)?)
        .wait()
        .map_err(|x| format!("opening the Zenoh session: {x}"))?;
    let mut exports = Vec::new();
    let mut listeners = Vec::new();
    for ex in &cfg.export {
        for kind in TOPICS.iter().filter(|t| matches(&ex.topics, t.name)) {
            let key = format!("{}/{}", ex.key_prefix, kind.name);
            let publisher = session
                .declare_publisher(key.clone())
                .congestion_control(zenoh::qos::CongestionControl::Drop)
                .wait()
                .map_err(|x| format!("declaring the Zenoh publisher {key}: {x}"))?;
            exports.push(Export {
                kind,
                port: kind.exporter(&bus).map_err(e)?,
                publisher,
                limit: RateLimit::new(ex.max_rate_hz),
                sent: 0,
                rate_limited: 0,
                failed: 0,
            });
            listeners.push(bus.listener(kind.name).map_err(e)?);
            tracing::info!(
                topic = kind.name,
                key = %key,
                max_rate_hz = ex.max_rate_hz,
                "{}: exporting {}/{} as {key}",
                cfg.name,
                cfg.prefix,
                kind.name
            );
        }
    }
    let mut imports = Vec::new();
    for im in &cfg.import {
        let key = format!("{}/**", im.key_prefix);
        let subscriber = session
            .declare_subscriber(key.clone())
            .with(zenoh::handlers::RingChannel::new(4096))
            .wait()
            .map_err(|x| format!("declaring the Zenoh subscriber {key}: {x}"))?;
        tracing::info!(
            key = %key,
            prefix = %im.prefix,
            "{}: importing {key} ({}) onto {}/",
            cfg.name,
            im.topics,
            im.prefix
        );
        imports.push(Import {
            key_prefix: format!("{}/", im.key_prefix),
            topics: im.topics.clone(),
            bus: Bus::new(&format!("{}import{}", cfg.name, imports.len()), &im.prefix)
                .map_err(e)?,
            subscriber,
            ports: HashMap::new(),
            received: 0,
            published: 0,
            unknown_topic: 0,
            wrong_type: 0,
            wrong_size: 0,
            failed: 0,
        });
    }
    let mut ros = match &cfg.ros2 {
        Some(r) => Some(ros2_out(&session, &bus, r)?),
        None => None,
    };
    let mut health_pub = bus
        .publisher::<ProcessHealthV1>(topic::HEALTH, qos::HEALTH)
        .map_err(e)?;
    // Imports arrive on Zenoh's threads: collected every millisecond; the ROS 2 side polls the
    // bus every 5 ms.
    let tick = if !imports.is_empty() {
        1
    } else if ros.is_some() {
        5
    } else {
        50
    };
    let health_ns = (cfg.health_period_s * 1e9) as u64;
    let mut next_health = 0;
    let mut warned = 0u32;
    bus.ready(&format!(
        "{}: {} exports, {} imports",
        cfg.name,
        exports.len(),
        imports.len()
    ));
    let result = auvnav_bridge::wake_loop(&listeners, Duration::from_millis(tick), |now| {
        bus.keep_alive();
        for ex in &mut exports {
            loop {
                let bytes = match ex.port.next_bytes() {
                    Ok(Some((_, b))) => b,
                    Ok(None) => break,
                    Err(x) => {
                        ex.failed += 1;
                        if warned < 10 {
                            warned += 1;
                            tracing::warn!(topic = ex.kind.name, "{}: {x}", cfg.name);
                        }
                        break;
                    }
                };
                if !ex.limit.admit(now) {
                    ex.rate_limited += 1;
                    continue;
                }
                match ex.publisher.put(bytes).attachment(ex.kind.type_name).wait() {
                    Ok(()) => ex.sent += 1,
                    Err(x) => {
                        ex.failed += 1;
                        if warned < 10 {
                            warned += 1;
                            tracing::warn!(topic = ex.kind.name, "{}: sending: {x}", cfg.name);
                        }
                    }
                }
            }
        }
        for im in &mut imports {
            while let Ok(Some(sample)) = im.subscriber.try_recv() {
                im.received += 1;
                let key = sample.key_expr().as_str();
                let kind = key
                    .strip_prefix(&im.key_prefix)
                    .and_then(TopicKind::by_name)
                    .filter(|k| matches(&im.topics, k.name));
                let Some(kind) = kind else {
                    im.unknown_topic += 1;
                    continue;
                };
                let attachment = sample.attachment().map(|a| a.to_bytes());
                let checked = check_type(kind, attachment.as_deref()).and_then(|()| {
                    let port = match im.ports.get_mut(kind.name) {
                        Some(p) => p,
                        None => {
                            let p = kind
                                .importer(&im.bus)
                                .map_err(|x| Rejected::Bus(x.to_string()))?;
                            im.ports.entry(kind.name).or_insert(p)
                        }
                    };
                    port.publish_bytes(&sample.payload().to_bytes())
                });
                match checked {
                    Ok(()) => im.published += 1,
                    Err(r) => {
                        match &r {
                            Rejected::WrongType => im.wrong_type += 1,
                            Rejected::WrongSize => im.wrong_size += 1,
                            Rejected::Bus(_) => im.failed += 1,
                        }
                        if warned < 10 {
                            warned += 1;
                            tracing::warn!(
                                key,
                                "{}: dropped a sample on {key}: {r:?} (further ones are counted)",
                                cfg.name
                            );
                        }
                    }
                }
            }
        }
        if let Some(r) = ros.as_mut() {
            r.step();
        }
        if now >= next_health {
            let m = health(cfg, &exports, &imports, ProcessState::Running);
            health_pub.publish(m).map_err(|x| x.to_string())?;
            next_health = now + health_ns;
        }
        Ok(())
    });
    let _ = health_pub.publish(health(cfg, &exports, &imports, ProcessState::Stopping));
    for ex in &exports {
        tracing::info!(
            topic = ex.kind.name,
            sent = ex.sent,
            rate_limited = ex.rate_limited,
            failed = ex.failed,
            "{}: {}: {} sent, {} held back by the rate limit, {} failed",
            cfg.name,
            ex.kind.name,
            ex.sent,
            ex.rate_limited,
            ex.failed
        );
    }
    for im in &imports {
        tracing::info!(
            received = im.received,
            published = im.published,
            unknown_topic = im.unknown_topic,
            wrong_type = im.wrong_type,
            wrong_size = im.wrong_size,
            "{}: {}**: {} received, {} published, dropped: {} unknown topic, {} wrong type, {} wrong size, {} failed",
            cfg.name,
            im.key_prefix,
            im.received,
            im.published,
            im.unknown_topic,
            im.wrong_type,
            im.wrong_size,
            im.failed
        );
    }
    if let Some(r) = &ros {
        tracing::info!(
            sent = r.sent,
            failed = r.failed,
            "{}: ROS 2: {} messages sent, {} failed",
            cfg.name,
            r.sent,
            r.failed
        );
    }
    drop(ros);
    let _ = session.close().wait();
    result
}

/// The bridge's health: `frames` messages carried (both ways), `drops` held back by a rate
/// limit or failed, `invalid` imported samples of an unknown topic, a wrong type or size.
fn health(
    cfg: &BridgeConfig,
    exports: &[Export],
    imports: &[Import],
    state: ProcessState,
) -> ProcessHealthV1 {
    let mut m = ProcessHealthV1 {
        host_time_ns: monotonic_ns(),
        frames: exports.iter().map(|e| e.sent).sum::<u64>()
            + imports.iter().map(|i| i.published).sum::<u64>(),
        drops: exports
            .iter()
            .map(|e| e.rate_limited + e.failed)
            .sum::<u64>()
            + imports.iter().map(|i| i.failed).sum::<u64>(),
        invalid: imports
            .iter()
            .map(|i| i.unknown_topic + i.wrong_type + i.wrong_size)
            .sum(),
        pid: std::process::id(),
        state: state as u32,
        ..Default::default()
    };
    m.set_name(&cfg.name);
    m
}

fn main() -> ExitCode {
    let args = Args::parse();
    auvnav_shm_schema::logging::init();
    let (path, check) = match args.config.required() {
        Ok(x) => x,
        Err(x) => {
            tracing::error!("auvnav-bridge: {x}");
            return ExitCode::from(2);
        }
    };
    if check {
        return match BridgeConfig::load(&path) {
            Ok(cfg) => {
                match toml::to_string_pretty(&cfg) {
                    Ok(s) => print!("{s}"),
                    Err(x) => tracing::error!("auvnav-bridge: {x}"),
                }
                ExitCode::SUCCESS
            }
            Err(x) => {
                tracing::error!("auvnav-bridge: {x}");
                ExitCode::from(2)
            }
        };
    }
    let cfg = match BridgeConfig::load(&path) {
        Ok(c) => c,
        Err(x) => {
            tracing::error!("auvnav-bridge: {x}");
            return ExitCode::from(2);
        }
    };
    match run(&cfg) {
        Ok(()) => ExitCode::SUCCESS,
        Err(x) => {
            tracing::error!("auvnav-bridge: {x}");
            ExitCode::from(1)
        }
    }
}
