//! `auvnav bench bridge`: latency and throughput of two `auvnav-bridge` processes on loopback
//! (vehicle bus → Zenoh → topside bus).

use super::latency::{Percentiles, cpu_seconds, percentiles};
#[allow(unused_imports)]
use super::*;

/// One rate through the bridge.
#[derive(Debug, Clone, Serialize)]
pub struct BridgeRun {
    pub topic: &'static str,
    pub rate_hz: f64,
    pub duration_s: f64,
    pub published: u64,
    pub received: u64,
    /// Published on the vehicle bus → received by a subscriber on the topside bus (µs): the
    /// vehicle bridge's wake-up, Zenoh over loopback TCP, the topside bridge's collection
    /// (every millisecond) and publication.
    pub latency_us: Percentiles,
    /// Messages received per second.
    pub throughput_hz: f64,
    /// CPU of the vehicle and topside bridges over the run (% of one core).
    pub vehicle_bridge_cpu_percent: f64,
    pub topside_bridge_cpu_percent: f64,
}

/// Runs the two bridges and publishes IMU samples at `rate_hz` for `seconds`.
pub fn bridge_run(rate_hz: f64, seconds: f64) -> anyhow::Result<BridgeRun> {
    use auvnav_shm_schema::bus::Bus;
    use auvnav_shm_schema::clock::monotonic_ns;
    use auvnav_shm_schema::{ImuSampleV1, qos, topic};
    use std::sync::atomic::{AtomicBool, Ordering};
    use std::time::{Duration, Instant};

    let tag = format!("benchbr{}r{}", std::process::id(), rate_hz as u64);
    let dir = std::env::temp_dir().join(&tag);
    std::fs::create_dir_all(&dir)?;
    let port = std::net::TcpListener::bind("127.0.0.1:0")?
        .local_addr()?
        .port();
    let (vehicle, topside, imported) = (format!("{tag}v"), format!("{tag}t"), format!("{tag}i"));
    let key = format!("auvnavbench/{tag}");
    let vehicle_cfg = dir.join("vehicle.toml");
    std::fs::write(
        &vehicle_cfg,
        format!(
            "prefix = \"{vehicle}\"\nname = \"bridgev\"\n[zenoh]\nlisten = [\"tcp/127.0.0.1:{port}\"]\n\
             [[export]]\ntopics = \"{}\"\nkey_prefix = \"{key}\"\n",
            topic::IMU
        ),
    )?;
    let topside_cfg = dir.join("topside.toml");
    std::fs::write(
        &topside_cfg,
        format!(
            "prefix = \"{topside}\"\nname = \"bridget\"\n[zenoh]\nlisten = []\nconnect = [\"tcp/127.0.0.1:{port}\"]\n\
             [[import]]\nkey_prefix = \"{key}\"\nprefix = \"{imported}\"\n"
        ),
    )?;
    let done = std::sync::Arc::new(AtomicBool::new(false));
    let ready = std::sync::Arc::new(AtomicBool::new(false));
    let seen = std::sync::Arc::new(std::sync::atomic::AtomicU64::new(0));
    let watcher = {
        let (done, ready, seen, imported) =
            (done.clone(), ready.clone(), seen.clone(), imported.clone());
        std::thread::spawn(move || -> anyhow::Result<Vec<(u64, u64)>> {
            let bus = Bus::new(&format!("{imported}sub"), &imported)?;
            let mut sub = bus.subscriber::<ImuSampleV1>(topic::IMU, qos::SENSOR)?;
            let wake = bus.listener(topic::IMU)?;
            ready.store(true, Ordering::SeqCst);
            let mut got = Vec::new();
            while !done.load(Ordering::SeqCst) {
                auvnav_shm_schema::bus::wait(&wake, Duration::from_millis(20))?;
                while let Some(m) = sub.receive()? {
                    got.push((m.host_time_ns, monotonic_ns()));
                    seen.fetch_add(1, Ordering::SeqCst);
                }
            }
            Ok(got)
        })
    };
    while !ready.load(Ordering::SeqCst) {
        std::thread::sleep(Duration::from_millis(5));
    }
    let bin = crate::process::sibling("auvnav-bridge")?;
    let mut bridges = [
        crate::process::ChildProcess::spawn_logged(
            "bridge-vehicle",
            &dir,
            std::process::Command::new(&bin)
                .arg("--config")
                .arg(&vehicle_cfg),
        )?,
        crate::process::ChildProcess::spawn_logged(
            "bridge-topside",
            &dir,
            std::process::Command::new(&bin)
                .arg("--config")
                .arg(&topside_cfg),
        )?,
    ];
    let bus = Bus::new(&format!("{tag}pub"), &vehicle)?;
    let mut imu = bus.publisher::<ImuSampleV1>(topic::IMU, qos::SENSOR)?;
    // Connection: warm-up samples (time stamp 0) until one crosses (at most 20 s).
    let warm = Instant::now();
    while seen.load(Ordering::SeqCst) == 0 {
        if warm.elapsed() > Duration::from_secs(20) {
            for b in bridges.iter_mut() {
                b.stop(Duration::from_secs(5));
            }
            done.store(true, Ordering::SeqCst);
            anyhow::bail!(
                "nothing crossed the bridge in 20 s (logs in {}: {} / {})",
                dir.display(),
                bridges[0].last_log_line(),
                bridges[1].last_log_line()
            );
        }
        imu.publish(ImuSampleV1::default())?;
        std::thread::sleep(Duration::from_millis(50));
    }
    std::thread::sleep(Duration::from_millis(200));
    let cpu = |p: &crate::process::ChildProcess| cpu_seconds(p.pid());
    let cpu0 = (cpu(&bridges[0]), cpu(&bridges[1]));
    let n = (rate_hz * seconds).round() as u64;
    let start = Instant::now();
    for i in 0..n {
        let due = start + Duration::from_secs_f64(i as f64 / rate_hz);
        if let Some(d) = due.checked_duration_since(Instant::now()) {
            std::thread::sleep(d);
        }
        imu.publish(ImuSampleV1 {
            host_time_ns: monotonic_ns(),
            ..Default::default()
        })?;
    }
    let wall = start.elapsed().as_secs_f64();
    std::thread::sleep(Duration::from_millis(300));
    let cpu1 = (cpu(&bridges[0]), cpu(&bridges[1]));
    for b in bridges.iter_mut().rev() {
        b.stop(Duration::from_secs(10));
    }
    done.store(true, Ordering::SeqCst);
    let got = watcher
        .join()
        .map_err(|_| anyhow::anyhow!("subscriber thread panicked"))??;
    let _ = std::fs::remove_dir_all(&dir);
    let lat: Vec<f64> = got
        .iter()
        .filter(|(sent, _)| *sent > 0)
        .map(|(sent, recv)| recv.saturating_sub(*sent) as f64 * 1e-3)
        .collect();
    let pct = |a: Option<f64>, b: Option<f64>| match (a, b) {
        (Some(a), Some(b)) if wall > 0.0 => 100.0 * (b - a) / wall,
        _ => f64::NAN,
    };
    Ok(BridgeRun {
        topic: topic::IMU,
        rate_hz,
        duration_s: seconds,
        published: n,
        received: lat.len() as u64,
        throughput_hz: lat.len() as f64 / wall,
        latency_us: percentiles(lat),
        vehicle_bridge_cpu_percent: pct(cpu0.0, cpu1.0),
        topside_bridge_cpu_percent: pct(cpu0.1, cpu1.1),
    })
}

/// The daemon beside the live view: the same run of the on-board chain without and with it.
#[derive(Debug, Clone, Serialize)]
pub struct LiveViewImpact {
    pub imu_rate_hz: f64,
    pub without_live_view: super::E2eLatency,
    pub with_live_view: super::E2eLatency,
}

/// What `auvnav bench bridge` reports.
#[derive(Debug, Clone, Serialize)]
pub struct BridgeBench {
    /// IMU samples through two bridges (vehicle bus → Zenoh on loopback → topside bus).
    pub bridge: Vec<BridgeRun>,
    /// The on-board chain at 1 kHz IMU (`auvnav bench e2e`'s run) without and with the live
    /// view serving every topic, unthinned, to one subscribed WebSocket client.
    pub live_view: LiveViewImpact,
}

/// `auvnav bench bridge`.
pub fn bridge_bench(seconds: f64, json: bool) -> anyhow::Result<()> {
    let mut bridge = Vec::new();
    for rate in [200.0, 1000.0] {
        bridge.push(bridge_run(rate, seconds)?);
    }
    let imu_rate_hz = 1000.0;
    let live_view = LiveViewImpact {
        imu_rate_hz,
        without_live_view: super::e2e(
            imu_rate_hz,
            seconds,
            false,
            false,
            crate::process::Scheduling::Normal,
        )?,
        with_live_view: super::e2e(
            imu_rate_hz,
            seconds,
            true,
            false,
            crate::process::Scheduling::Normal,
        )?,
    };
    let r = BridgeBench { bridge, live_view };
    if json {
        crate::json::print(&r)?;
    } else {
        for r in &r.bridge {
            println!(
                "bridge, {} at {} Hz over loopback: {}/{} received ({:.0} per s); latency p50 {:.0} us, p99 {:.0} us, max {:.0} us; CPU vehicle bridge {:.1} %, topside bridge {:.1} %",
                r.topic,
                r.rate_hz,
                r.received,
                r.published,
                r.throughput_hz,
                r.latency_us.p50,
                r.latency_us.p99,
                r.latency_us.max,
                r.vehicle_bridge_cpu_percent,
                r.topside_bridge_cpu_percent
            );
        }
        let lv = &r.live_view;
        for (label, e) in [
            ("without the live view", &lv.without_live_view),
            ("with the live view   ", &lv.with_live_view),
        ] {
            println!(
                "daemon at {} Hz IMU {label}: frame -> solution p50 {:.0} us, p99 {:.0} us, max {:.0} us; CPU daemon {:.1} %{}",
                lv.imu_rate_hz,
                e.frame_to_solution_us.p50,
                e.frame_to_solution_us.p99,
                e.frame_to_solution_us.max,
                e.daemon_cpu_percent,
                e.live_view
                    .as_ref()
                    .map(|l| format!(
                        ", live view {:.1} % ({} messages, {} solutions to one client on {} channels)",
                        l.live_view_cpu_percent,
                        l.messages_received,
                        l.solutions_received,
                        l.channels
                    ))
                    .unwrap_or_default()
            );
        }
    }
    Ok(())
}
