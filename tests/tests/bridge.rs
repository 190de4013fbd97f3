//! `auvnav-bridge` between two bus domains on one machine, over Zenoh on loopback: on the
//! "vehicle" bus (prefix A) the daemon navigates from IMU samples the test publishes, and the
//! vehicle bridge exports its solution, its health and the IMU (rate-limited); the "topside"
//! bridge imports them onto its bus under prefix B. Nothing but the bridges connects the two
//! prefixes: with the topside bridge stopped nothing arrives. Checked: the daemon's solutions
//! arrive byte for byte as published on the vehicle's bus, its health arrives, the rate-limited
//! topic arrives at its limit, a restart of either bridge recovers while the daemon keeps running,
//! and malformed samples from the network are counted and dropped.

use auvnav_shm_schema::bus::{Bus, BusPublisher, BusSubscriber};
use auvnav_shm_schema::{ImuSampleV1, NavMode, NavSolutionV1, ProcessHealthV1, qos, topic};
use auvnav_tests::processes::{Proc, TempDir, binary, unique};
use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::{Duration, Instant};
use zenoh::Wait;

fn free_port() -> u16 {
    std::net::TcpListener::bind("127.0.0.1:0")
        .and_then(|l| l.local_addr())
        .expect("a free loopback port")
        .port()
}

fn write(dir: &Path, name: &str, text: &str) -> PathBuf {
    let p = dir.join(name);
    std::fs::write(&p, text).expect("config");
    p
}

fn start(dir: &Path, name: &str, cfg: &Path) -> Proc {
    Proc::spawn_logged(
        name,
        dir,
        Command::new(binary("auvnav-bridge"))
            .arg("--config")
            .arg(cfg),
    )
    .expect("bridge")
}

/// The vehicle: the test plays the IMU driver on bus A, the daemon navigates from it and
/// publishes its solution and health there.
struct Vehicle {
    imu: BusPublisher<ImuSampleV1>,
    /// The daemon's solutions as seen on the vehicle's own bus.
    local: BusSubscriber<NavSolutionV1>,
    seen_locally: Vec<NavSolutionV1>,
    k: u64,
}

impl Vehicle {
    /// Publishes one IMU sample (a vehicle at rest: gravity and the Earth's rotation).
    fn step(&mut self) {
        self.k += 1;
        let m = ImuSampleV1 {
            host_time_ns: auvnav_shm_schema::clock::monotonic_ns(),
            device_time_ns: self.k * 10_000_000,
            angular: [1e-5, 0.0, 7.3e-5],
            specific: [0.0, 0.0, -9.79],
            interval_s: 0.01,
            status: ImuSampleV1::STATUS_GYRO_VALID
                | ImuSampleV1::STATUS_ACCEL_VALID
                | ImuSampleV1::STATUS_DEVICE_TIME_VALID,
            ..Default::default()
        };
        self.imu.publish(m).expect("publish");
        while let Some(s) = self.local.receive().expect("receive") {
            self.seen_locally.push(s);
        }
    }
}

/// Plays the IMU at 100 Hz for `for_` and collects what the topside receives: solutions and the
/// number of (rate-limited) IMU samples.
fn run_for(
    v: &mut Vehicle,
    sol: &mut BusSubscriber<NavSolutionV1>,
    imu: &mut BusSubscriber<ImuSampleV1>,
    for_: Duration,
) -> (Vec<NavSolutionV1>, usize) {
    let (mut got, mut imus) = (Vec::new(), 0);
    let end = Instant::now() + for_;
    while Instant::now() < end {
        v.step();
        std::thread::sleep(Duration::from_millis(10));
        while let Some(m) = sol.receive().expect("receive") {
            got.push(m);
        }
        while imu.receive().expect("receive").is_some() {
            imus += 1;
        }
    }
    // What the vehicle's bus carried up to now (it may lag the topside by one wake-up).
    while let Some(s) = v.local.receive().expect("receive") {
        v.seen_locally.push(s);
    }
    (got, imus)
}

#[test]
// Long on purpose: one scenario with real processes read top to bottom: each step depends on the
// state the previous one left.
fn topics_cross_the_bridge_with_their_values_at_their_rate_and_survive_restarts() {
    let dir = TempDir::new("bridge");
    let d = dir.path();
    let (a, b) = (unique("brA"), unique("brB"));
    let imported = format!("{b}veh");
    let key = unique("auvnavtest/veh");
    let port = free_port();
    let port_b = free_port();
    let vehicle_cfg = write(
        d,
        "vehicle.toml",
        &format!(
            "prefix = \"{a}\"\nname = \"bridgeA\"\nhealth_period_s = 0.2\n[zenoh]\nlisten = [\"tcp/127.0.0.1:{port}\"]\n\
             [[export]]\ntopics = \"nav/solution\"\nkey_prefix = \"{key}\"\n\
             [[export]]\ntopics = \"imu\"\nkey_prefix = \"{key}\"\nmax_rate_hz = 10.0\n\
             [[export]]\ntopics = \"health\"\nkey_prefix = \"{key}\"\n"
        ),
    );
    let topside_cfg = write(
        d,
        "topside.toml",
        &format!(
            "prefix = \"{b}\"\nname = \"bridgeB\"\nhealth_period_s = 0.2\n[zenoh]\nlisten = [\"tcp/127.0.0.1:{port_b}\"]\nconnect = [\"tcp/127.0.0.1:{port}\"]\n\
             [[import]]\nkey_prefix = \"{key}\"\nprefix = \"{imported}\"\n"
        ),
    );
    let bus_a = Bus::new(&unique("brtestA"), &a).expect("bus");
    let mut v = Vehicle {
        imu: bus_a.publisher(topic::IMU, qos::SENSOR).expect("pub"),
        local: bus_a
            .subscriber(topic::NAV_SOLUTION, qos::NAVIGATION)
            .expect("sub"),
        seen_locally: Vec::new(),
        k: 0,
    };
    let daemon_cfg = d.join("auvnavd.toml");
    let daemon = auvnav_core::config::DaemonConfig {
        prefix: a.clone(),
        health_period_s: 0.2,
        navigation: auvnav_core::config::NavConfig {
            imu_dt_from_device_time: true,
            ..Default::default()
        },
        initial: Some(auvnav_core::config::InitialState {
            latitude_deg: 31.0,
            longitude_deg: 120.0,
            height_m: -20.0,
            velocity_ned_m_s: [0.0; 3],
            euler_deg: [0.0; 3],
        }),
        ..Default::default()
    };
    std::fs::write(&daemon_cfg, daemon.to_toml().expect("toml")).expect("write");
    let mut daemon_p = Proc::spawn_logged(
        "auvnavd",
        d,
        Command::new(binary("auvnavd"))
            .arg("--config")
            .arg(&daemon_cfg),
    )
    .expect("auvnavd");
    let bus_b = Bus::new(&unique("brtestB"), &imported).expect("bus");
    let mut sol = bus_b
        .subscriber::<NavSolutionV1>(topic::NAV_SOLUTION, qos::NAVIGATION)
        .expect("sub");
    let mut diag = bus_b
        .subscriber::<ImuSampleV1>(topic::IMU, qos::SENSOR)
        .expect("sub");
    let mut health = bus_b
        .subscriber::<ProcessHealthV1>(topic::HEALTH, qos::HEALTH)
        .expect("sub");
    let local_b = Bus::new(&unique("brtestBl"), &b).expect("bus");
    let mut topside_health = local_b
        .subscriber::<ProcessHealthV1>(topic::HEALTH, qos::HEALTH)
        .expect("sub");

    // Nothing crosses without the bridges.
    let (none, _) = run_for(&mut v, &mut sol, &mut diag, Duration::from_millis(300));
    assert!(none.is_empty());

    let mut vehicle = start(d, "bridgeA", &vehicle_cfg);
    let mut topside = start(d, "bridgeB", &topside_cfg);
    // Connection and discovery.
    let t0 = Instant::now();
    loop {
        let (got, _) = run_for(&mut v, &mut sol, &mut diag, Duration::from_millis(100));
        if !got.is_empty() {
            break;
        }
        assert!(
            t0.elapsed() < Duration::from_secs(20),
            "no solution crossed in 20 s ({} published on the vehicle's bus; daemon: {}); bridge logs: {} / {}",
            v.seen_locally.len(),
            std::fs::read_to_string(d.join("auvnavd.log")).unwrap_or_default(),
            vehicle.last_log_line(),
            topside.last_log_line()
        );
    }

    // Values and rates over 3 s at 100 Hz: the daemon's solutions arrive as the daemon published
    // them on the vehicle's bus, byte for byte, sequence numbers included.
    let (got, diags) = run_for(&mut v, &mut sol, &mut diag, Duration::from_secs(3));
    let window: Vec<&NavSolutionV1> = v
        .seen_locally
        .iter()
        .filter(|s| {
            got.first().is_some_and(|g| s.sequence >= g.sequence)
                && got.last().is_some_and(|g| s.sequence <= g.sequence)
        })
        .collect();
    assert!(got.len() > 200, "{} solutions crossed in 3 s", got.len());
    assert!(
        got.len() * 100 >= window.len() * 99,
        "{} of the {} solutions published in the window crossed",
        got.len(),
        window.len()
    );
    for m in &got {
        let local = v
            .seen_locally
            .iter()
            .find(|s| s.sequence == m.sequence)
            .expect("published on the vehicle's bus");
        assert_eq!(bytemuck::bytes_of(m), bytemuck::bytes_of(local));
        assert_ne!(m.mode, NavMode::Initialising as u32);
    }
    // 10 Hz limit over 3 s: 30 (one either way for the window's edges).
    assert!(
        (27..=33).contains(&diags),
        "{diags} rate-limited IMU samples in 3 s"
    );
    // The vehicle bridge's own health crosses too.
    let (mut seen_health, mut seen_daemon) = (false, false);
    while let Some(h) = health.receive().expect("receive") {
        seen_health |= h.name() == "bridgeA" && h.frames > 0;
        seen_daemon |= h.name() == "auvnavd" && h.frames > 0;
    }
    assert!(seen_health, "the vehicle bridge's health did not cross");
    assert!(seen_daemon, "the daemon's health did not cross");

    // A restart of either side recovers.
    for (which, restart) in [("topside", true), ("vehicle", false)] {
        if restart {
            assert!(topside.stop(Duration::from_secs(10)), "topside stop");
            let (gap, _) = run_for(&mut v, &mut sol, &mut diag, Duration::from_millis(500));
            assert!(
                gap.len() <= 2,
                "{} solutions crossed without the topside",
                gap.len()
            );
            topside = start(d, "bridgeB2", &topside_cfg);
        } else {
            assert!(vehicle.stop(Duration::from_secs(10)), "vehicle stop");
            vehicle = start(d, "bridgeA2", &vehicle_cfg);
        }
        let t0 = Instant::now();
        loop {
            let (got, _) = run_for(&mut v, &mut sol, &mut diag, Duration::from_millis(200));
            if got.len() >= 10 {
                break;
            }
            assert!(
                t0.elapsed() < Duration::from_secs(30),
                "no recovery 30 s after the {which} bridge restarted: {} / {}",
                vehicle.last_log_line(),
                topside.last_log_line()
            );
        }
    }

    // Malformed samples from the network: another type's name, a short payload, an unknown
    // topic, sent straight to the topside bridge. Counted as invalid in its health, never
    // published.
    let session = zenoh::open({
        let mut c = zenoh::Config::default();
        c.insert_json5(
            "connect/endpoints",
            &format!("[\"tcp/127.0.0.1:{port_b}\"]"),
        )
        .expect("config");
        c.insert_json5("listen/endpoints", "[]").expect("config");
        c.insert_json5("scouting/multicast/enabled", "false")
            .expect("config");
        c
    })
    .wait()
    .expect("zenoh session");
    std::thread::sleep(Duration::from_secs(1));
    while sol.receive().expect("receive").is_some() {}
    let sol_key = format!("{key}/{}", topic::NAV_SOLUTION);
    let good = NavSolutionV1::default();
    let bytes = bytemuck::bytes_of(&good);
    for _ in 0..5 {
        session
            .put(&sol_key, bytes.to_vec())
            .attachment("auvnav/ImuSample/v1")
            .wait()
            .expect("put");
        session
            .put(&sol_key, bytes[..100].to_vec())
            .attachment("auvnav/NavSolution/v1")
            .wait()
            .expect("put");
        session
            .put(format!("{key}/no/such/topic"), bytes.to_vec())
            .attachment("auvnav/NavSolution/v1")
            .wait()
            .expect("put");
    }
    std::thread::sleep(Duration::from_millis(800));
    let mut invalid = 0;
    while let Some(h) = topside_health.receive().expect("receive") {
        if h.name() == "bridgeB" {
            invalid = invalid.max(h.invalid);
        }
    }
    assert_eq!(invalid, 15, "malformed samples counted");
    let mut crossed = Vec::new();
    while let Some(m) = sol.receive().expect("receive") {
        crossed.push(m);
    }
    assert!(crossed.is_empty(), "malformed samples were published");
    let _ = session.close().wait();
    assert!(vehicle.stop(Duration::from_secs(10)));
    assert!(topside.stop(Duration::from_secs(10)));
    // The daemon ran through both restarts.
    assert!(
        daemon_p.wait_for(Duration::ZERO).is_none(),
        "the daemon stopped: {}",
        daemon_p.last_log_line()
    );
    assert!(daemon_p.stop(Duration::from_secs(10)));
}

#[test]
fn a_bad_configuration_is_refused_with_exit_status_2_naming_the_file_and_key() {
    let dir = TempDir::new("bridgecfg");
    let d = dir.path();
    let cases = [
        ("missing.toml", None, "reading"),
        (
            "self.toml",
            Some("prefix = \"p\"\n[[import]]\nkey_prefix = \"k\"\nprefix = \"p\"\n"),
            "must be set and differ",
        ),
        (
            "rate.toml",
            Some("[[export]]\ntopics = \"nav/*\"\nkey_prefix = \"k\"\nmax_rate_hz = -1.0\n"),
            "max_rate_hz",
        ),
        ("empty.toml", Some(""), "nothing to do"),
    ];
    for (name, text, expected) in cases {
        let path = d.join(name);
        if let Some(t) = text {
            std::fs::write(&path, t).expect("write");
        }
        let o = Command::new(binary("auvnav-bridge"))
            .arg("--config")
            .arg(&path)
            .output()
            .expect("auvnav-bridge");
        let err = String::from_utf8_lossy(&o.stderr);
        assert_eq!(o.status.code(), Some(2), "{name}: {err}");
        assert!(
            err.contains(name) && err.contains(expected),
            "{name}: {err}"
        );
    }
    let o = Command::new(binary("auvnav-bridge"))
        .arg("--check-config")
        .arg(
            Path::new(env!("CARGO_MANIFEST_DIR"))
                .join("..")
                .join("deploy")
                .join("auvnav-bridge.toml"),
        )
        .output()
        .expect("auvnav-bridge");
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    assert!(String::from_utf8_lossy(&o.stdout).contains("tcp/127.0.0.1:7447"));
    // The ROS 2 example.
    let o = Command::new(binary("auvnav-bridge"))
        .arg("--check-config")
        .arg(Path::new(env!("CARGO_MANIFEST_DIR")).join("../deploy/auvnav-bridge-ros2.toml"))
        .output()
        .expect("auvnav-bridge");
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    assert!(String::from_utf8_lossy(&o.stdout).contains("[ros2]"));
}
