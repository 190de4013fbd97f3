//! `auvnav-live`: the live view, a read-only Foxglove WebSocket server fed from this host's bus
//! (see `auvnav_bridge::live`).
#![forbid(unsafe_code)]

use auvnav_bridge::live::{LOCATION_TOPIC, LiveConfig, SlowClientReports, WallClock};
use auvnav_bridge::{ExportPort, RateLimit, TopicKind};
use auvnav_shm_schema::bus::{Bus, BusError};
use auvnav_shm_schema::clock::monotonic_ns;
use auvnav_shm_schema::{NavSolutionV1, ProcessHealthV1, ProcessState, qos, topic};
use clap::Parser;
use foxglove::{ChannelBuilder, Context, PartialMetadata, RawChannel, Schema, WebSocketServer};
use std::process::ExitCode;
use std::sync::Arc;
use std::sync::atomic::Ordering;
use std::time::Duration;

#[derive(Parser)]
#[command(
    name = "auvnav-live",
    about = "Live view: serves this host's bus topics to Foxglove over WebSocket (read-only)",
    version = auvnav_version::LONG
)]
struct Args {
    /// `--config FILE` (without one: the defaults, loopback port 8765), `--check-config [FILE]`.
    #[command(flatten)]
    config: auvnav_version::cli::ConfigArgs,
    /// Bus prefix (overrides the configuration's `prefix`).
    #[arg(long)]
    prefix: Option<String>,
    /// TCP port (overrides the configuration's `port`; 0: any free port).
    #[arg(long)]
    port: Option<u16>,
}

/// One served topic.
struct Served {
    kind: &'static TopicKind,
    port: Box<dyn ExportPort>,
    channel: Arc<RawChannel>,
    limit: RateLimit,
    logged: u64,
    rate_limited: u64,
    failed: u64,
}

// Long on purpose: the live view's one loop: subscribers, the WebSocket server, rate limits and the
// slow-client accounting share its locals.
fn run(cfg: &LiveConfig, slow: &SlowClientReports) -> Result<(), String> {
    let e = |x: BusError| x.to_string();
    let bus = Bus::new(&cfg.name, &cfg.prefix).map_err(e)?;
    bus.cleanup_dead_nodes();
    let ctx = Context::new();
    let mut served = Vec::new();
    let mut listeners = Vec::new();
    for kind in cfg.served() {
        let channel = ChannelBuilder::new(kind.name)
            .message_encoding("cdr")
            .schema(Schema::new(
                kind.schema_name,
                "ros2msg",
                (kind.ros2msg)().into_bytes(),
            ))
            .add_metadata("type_name", kind.type_name)
            .context(&ctx)
            .build_raw()
            .map_err(|x| format!("channel {}: {x}", kind.name))?;
        served.push(Served {
            kind,
            port: kind.exporter(&bus).map_err(e)?,
            channel,
            limit: RateLimit::new(cfg.max_rate_hz(kind.name)),
            logged: 0,
            rate_limited: 0,
            failed: 0,
        });
        listeners.push(bus.listener(kind.name).map_err(e)?);
    }
    let location = served
        .iter()
        .any(|s| s.kind.name == topic::NAV_SOLUTION)
        .then(|| {
            ChannelBuilder::new(LOCATION_TOPIC)
                .context(&ctx)
                .build::<foxglove::schemas::LocationFix>()
        });
    // The SDK's server listens on loopback only; clients reach it through the gate
    // (`auvnav_bridge::gate`: origin check and connection limit) on the configured address.
    let server = WebSocketServer::new()
        .name(format!("auvnav {} ({})", cfg.name, cfg.prefix))
        .bind("127.0.0.1", 0)
        .context(&ctx)
        .message_backlog_size(cfg.backlog)
        // Read-only: no client publishing, services, parameters or assets.
        .capabilities([])
        .start_blocking()
        .map_err(|x| {
            format!(
                "starting the WebSocket server on {}:{}: {x}",
                cfg.listen_address, cfg.port
            )
        })?;
    let gate = auvnav_bridge::gate::Gate::start(
        &cfg.listen_address,
        cfg.port,
        std::net::SocketAddr::from(([127, 0, 0, 1], server.port())),
        cfg.allowed_origins.clone(),
        cfg.max_connections,
    )
    .map_err(|x| format!("listening on {}:{}: {x}", cfg.listen_address, cfg.port))?;
    let gate_counters = gate.counters.clone();
    tracing::info!(
        address = %cfg.listen_address,
        port = gate.port,
        topics = served.len(),
        "{}: live view on ws://{}:{} ({} topics of {}/)",
        cfg.name,
        cfg.listen_address,
        gate.port,
        served.len(),
        cfg.prefix
    );
    let clock = WallClock::now();
    let mut health_pub = bus
        .publisher::<ProcessHealthV1>(topic::HEALTH, qos::HEALTH)
        .map_err(e)?;
    let health_ns = (cfg.health_period_s * 1e9) as u64;
    let mut next_health = 0;
    let mut warned = 0u32;
    let mut solutions_mapped = 0u64;
    bus.ready(&format!("{}: live view on port {}", cfg.name, gate.port));
    let result = auvnav_bridge::wake_loop(&listeners, Duration::from_millis(100), |now| {
        bus.keep_alive();
        for s in &mut served {
            loop {
                let (host_ns, bytes) = match s.port.next_bytes() {
                    Ok(Some(m)) => m,
                    Ok(None) => break,
                    Err(x) => {
                        s.failed += 1;
                        if warned < 10 {
                            warned += 1;
                            tracing::warn!(topic = s.kind.name, "{}: {x}", cfg.name);
                        }
                        break;
                    }
                };
                if !s.limit.admit(now) {
                    s.rate_limited += 1;
                    continue;
                }
                let unix_ns = clock.unix_ns(host_ns);
                let meta = PartialMetadata {
                    log_time: Some(unix_ns),
                };
                s.channel
                    .log_with_meta(&auvnav_bridge::live::cdr_payload(&bytes), meta);
                s.logged += 1;
                if let Some(loc) = &location
                    && s.kind.name == topic::NAV_SOLUTION
                    && let Ok(sol) = bytemuck::try_pod_read_unaligned::<NavSolutionV1>(&bytes)
                {
                    loc.log_with_meta(&auvnav_bridge::live::location_fix(&sol, unix_ns), meta);
                    solutions_mapped += 1;
                }
            }
        }
        if now >= next_health {
            let mut m = health(cfg, &served, slow, ProcessState::Running);
            m.invalid += refused(&gate_counters);
            health_pub.publish(m).map_err(|x| x.to_string())?;
            next_health = now + health_ns;
        }
        Ok(())
    });
    let mut last = health(cfg, &served, slow, ProcessState::Stopping);
    last.invalid += refused(&gate_counters);
    let _ = health_pub.publish(last);
    let clients = server.client_count();
    gate.stop();
    server.stop().wait_blocking();
    let sum = |f: fn(&Served) -> u64| served.iter().map(f).sum::<u64>();
    tracing::info!(
        logged = sum(|s| s.logged),
        rate_limited = sum(|s| s.rate_limited),
        failed = sum(|s| s.failed),
        slow_client_reports = slow.count(),
        clients,
        "{}: stopped: {} messages served ({} solutions on {LOCATION_TOPIC}), {} held back by \
         rate limits, {} failed, {} reports of a client not keeping up, {} clients connected at \
         the end, {} connections accepted, {} refused for their origin, {} refused over \
         max_connections",
        cfg.name,
        sum(|s| s.logged),
        solutions_mapped,
        sum(|s| s.rate_limited),
        sum(|s| s.failed),
        slow.count(),
        clients,
        gate_counters.accepted.load(Ordering::Relaxed),
        gate_counters.refused_origin.load(Ordering::Relaxed),
        gate_counters.refused_limit.load(Ordering::Relaxed)
    );
    result
}

/// Connections the gate refused (origin or limit): counted as invalid in the health.
fn refused(c: &auvnav_bridge::gate::GateCounters) -> u64 {
    c.refused_origin.load(Ordering::Relaxed) + c.refused_limit.load(Ordering::Relaxed)
}

/// The live view's health: `frames` messages served, `drops` held back by a rate limit or
/// reports of a client not keeping up (the server then drops that client's oldest messages),
/// `invalid` bus messages that could not be read.
fn health(
    cfg: &LiveConfig,
    served: &[Served],
    slow: &SlowClientReports,
    state: ProcessState,
) -> ProcessHealthV1 {
    let mut m = ProcessHealthV1 {
        host_time_ns: monotonic_ns(),
        frames: served.iter().map(|s| s.logged).sum(),
        drops: served.iter().map(|s| s.rate_limited).sum::<u64>() + slow.count(),
        invalid: served.iter().map(|s| s.failed).sum(),
        pid: std::process::id(),
        state: state as u32,
        ..Default::default()
    };
    m.set_name(&cfg.name);
    m
}

fn main() -> ExitCode {
    let args = Args::parse();
    let slow = SlowClientReports::default();
    {
        use tracing_subscriber::Layer;
        let foxglove_info = tracing_subscriber::filter::Targets::new()
            .with_target("foxglove", tracing::Level::INFO);
        auvnav_shm_schema::logging::init_with(Some(
            slow.clone().with_filter(foxglove_info).boxed(),
        ));
    }
    use auvnav_version::cli::ConfigRequest;
    let request = match args.config.request() {
        Ok(r) => r,
        Err(x) => {
            tracing::error!("auvnav-live: {x}");
            return ExitCode::from(2);
        }
    };
    let (loaded, check) = match &request {
        ConfigRequest::Run(path) => (LiveConfig::load(path), false),
        ConfigRequest::Check(path) => (LiveConfig::load(path), true),
        ConfigRequest::Defaults { check } => (Ok(LiveConfig::default()), *check),
    };
    let mut cfg = match loaded {
        Ok(c) => c,
        Err(x) => {
            tracing::error!("auvnav-live: {x}");
            return ExitCode::from(2);
        }
    };
    if let Some(p) = args.prefix {
        cfg.prefix = p;
    }
    if let Some(p) = args.port {
        cfg.port = p;
    }
    if check {
        match toml::to_string_pretty(&cfg) {
            Ok(s) => print!("{s}"),
            Err(x) => tracing::error!("auvnav-live: {x}"),
        }
        return ExitCode::SUCCESS;
    }
    match run(&cfg, &slow) {
        Ok(()) => ExitCode::SUCCESS,
        Err(x) => {
            tracing::error!("auvnav-live: {x}");
            ExitCode::from(1)
        }
    }
}
