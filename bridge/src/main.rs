//! `auvnav-bridge`: see the library's documentation (`auvnav_bridge`).

use auvnav_bridge::{
    BridgeConfig, ExportPort, ImportPort, RateLimit, Rejected, TOPICS, TopicKind, ZenohConfig,
    check_type, matches,
};
use auvnav_shm_schema::bus::{Bus, BusError};
use auvnav_shm_schema::clock::monotonic_ns;
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
    /// The bridge's TOML configuration.
    #[arg(long)]
    config: Option<String>,
    /// Check the configuration, print it with defaults filled in, and exit.
    #[arg(long, value_name = "FILE")]
    check_config: Option<String>,
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
    let mut health_pub = bus
        .publisher::<ProcessHealthV1>(topic::HEALTH, qos::HEALTH)
        .map_err(e)?;
    // Imports arrive on Zenoh's threads: collected every millisecond.
    let tick = if imports.is_empty() { 50 } else { 1 };
    let health_ns = (cfg.health_period_s * 1e9) as u64;
    let mut next_health = 0;
    let mut warned = 0u32;
    let result = auvnav_bridge::wake_loop(&listeners, Duration::from_millis(tick), |now| {
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
    if let Some(path) = &args.check_config {
        return match BridgeConfig::load(path) {
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
    let Some(path) = &args.config else {
        tracing::error!("auvnav-bridge: --config FILE is required (or --check-config FILE)");
        return ExitCode::from(2);
    };
    let cfg = match BridgeConfig::load(path) {
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
