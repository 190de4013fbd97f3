//! The live view (`auvnav-live`) during `auvnav demo --live-view`: a WebSocket client speaking
//! Foxglove's protocol subscribes as Foxglove does, decodes the solution messages with the log's
//! CDR layout and finds the live CSV's positions, bit for bit, with no solution missing after the
//! first; the map channel carries the same positions in degrees. A second client that subscribes
//! to everything and never reads, and a client that tries to publish, change nothing: the demo's
//! solution is complete, its recording replays byte-identically, every process stops cleanly.

use auvnav_bridge::live_client::LiveClient;
use auvnav_shm_schema::{NavSolutionV1, topic};
use auvnav_tests::processes::{TempDir, binary};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

fn free_port() -> u16 {
    std::net::TcpListener::bind("127.0.0.1:0")
        .and_then(|l| l.local_addr())
        .expect("a free loopback port")
        .port()
}

/// The demo's chain and the 40 MB burst below each load both cores: run one at a time, so the
/// reading client's share measures the server, not the other test.
static ONE_AT_A_TIME: std::sync::Mutex<()> = std::sync::Mutex::new(());

#[test]
// Long on purpose: one scenario with real processes read top to bottom: each step depends on the
// state the previous one left.
fn a_foxglove_client_sees_the_live_solution_of_the_demo() {
    let _one = ONE_AT_A_TIME.lock().unwrap_or_else(|e| e.into_inner());
    let dir = TempDir::new("liveview");
    let out = dir.path().join("run");
    let addr = format!("127.0.0.1:{}", free_port());
    let mut demo = Command::new(binary("auvnav"))
        .args(["demo", "--scenario", "lawnmower", "--start", "known"])
        .args(["--seconds", "30", "--speed", "4", "--json"])
        .args(["--live-view", &addr, "--out"])
        .arg(&out)
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("auvnav demo");

    // The server starts once the voyage is simulated and the daemon runs.
    let mut client = LiveClient::connect_retrying(&addr, Duration::from_secs(90))
        .expect("connecting to the live view");
    client
        .wait_for_channels(
            &[
                topic::NAV_SOLUTION,
                "nav/location",
                topic::HEALTH,
                topic::IMU,
            ],
            Duration::from_secs(10),
        )
        .expect("channels");
    let sol = &client.channels[topic::NAV_SOLUTION];
    assert_eq!(sol.encoding, "cdr");
    assert_eq!(sol.schema_name, "auvnav_msgs/msg/NavSolutionV1");
    assert_eq!(sol.schema_encoding.as_deref(), Some("ros2msg"));
    assert!(
        sol.schema.contains("float64 latitude_rad"),
        "{}",
        sol.schema
    );
    client
        .subscribe(&[topic::NAV_SOLUTION, "nav/location"])
        .expect("subscribe");

    // A client that subscribes to everything and never reads again.
    let mut stalled = LiveClient::connect(&addr, Duration::from_secs(5)).expect("second client");
    stalled
        .wait_for_channels(&[topic::IMU], Duration::from_secs(10))
        .expect("channels");
    let all: Vec<String> = stalled.channels.keys().cloned().collect();
    stalled
        .subscribe(&all.iter().map(String::as_str).collect::<Vec<_>>())
        .expect("subscribe");

    // A client that tries to publish: refused by the server, nothing reaches the bus.
    let mut publisher = LiveClient::connect(&addr, Duration::from_secs(5)).expect("third client");
    publisher
        .send_text(
            r#"{"op":"advertise","channels":[{"id":1,"topic":"nav/solution","encoding":"cdr","schemaName":"auvnav_msgs/msg/NavSolutionV1"}]}"#,
        )
        .expect("send");
    let mut forged = vec![0x01, 1, 0, 0, 0];
    forged.extend_from_slice(&[0u8; 4 + 256]);
    publisher.send_binary(forged).expect("send");
    publisher
        .set_read_timeout(Duration::from_millis(200))
        .expect("timeout");
    let t0 = Instant::now();
    while publisher.other_text.is_empty() && t0.elapsed() < Duration::from_secs(10) {
        publisher.read().expect("read");
    }
    assert!(
        publisher
            .other_text
            .iter()
            .any(|t| t.contains("does not support clientPublish")),
        "{:?}",
        publisher.other_text
    );
    publisher.close();

    let (mut solutions, mut locations) = (Vec::new(), Vec::new());
    client
        .set_read_timeout(Duration::from_millis(200))
        .expect("timeout");
    let end = Instant::now() + Duration::from_secs(120);
    while demo.try_wait().expect("demo").is_none() && Instant::now() < end {
        match client.read() {
            Ok(Some(m)) if m.topic == topic::NAV_SOLUTION => {
                let s: NavSolutionV1 =
                    auvnav_log::decode_pod(topic::NAV_SOLUTION, &m.data).expect("CDR solution");
                solutions.push((s, m.log_time_ns));
            }
            Ok(Some(m)) => locations.push(m),
            Ok(None) => {}
            // The server closes the connection when the demo stops it.
            Err(_) => break,
        }
    }
    let o = demo.wait_with_output().expect("demo");
    let stdout = String::from_utf8_lossy(&o.stdout);
    assert!(
        o.status.success(),
        "{stdout}\n{}",
        String::from_utf8_lossy(&o.stderr)
    );
    drop(stalled);
    let v: serde_json::Value = serde_json::from_str(&stdout).expect("json");
    assert_eq!(v["replay_identical"], true, "{v}");
    assert_eq!(v["clean_stop"], true, "{v}");
    assert_eq!(v["solutions"], 6000, "{v}");

    let csv =
        auvnav_tools::demo_processes::read_nav_csv(&out.join("live_nav.csv")).expect("live CSV");
    assert!(
        solutions.len() > 5000,
        "{} of {} solutions reached the client",
        solutions.len(),
        csv.len()
    );
    let first = solutions[0].0.sequence;
    for (k, (s, log_time_ns)) in solutions.iter().enumerate() {
        // No gap after the first one received (the bus's own sequence numbers).
        assert_eq!(s.sequence, first + k as u64);
        // The daemon numbers its CSV rows from 1, the bus its messages from 0.
        let row = csv
            .iter()
            .find(|r| r.sequence == s.sequence + 1)
            .unwrap_or_else(|| panic!("no CSV row for bus sequence {}", s.sequence));
        assert_eq!(s.host_time_ns, row.host_time_ns);
        assert_eq!(
            (s.latitude_rad, s.longitude_rad, s.height_m),
            (row.latitude_rad, row.longitude_rad, row.height_m)
        );
        assert_eq!(s.velocity_ned_m_s, row.velocity_ned_m_s);
        assert_eq!(s.euler_rad, row.euler_rad);
        // Log times are wall-clock (Unix) times: after 2020.
        assert!(*log_time_ns > 1_577_836_800_000_000_000);
    }
    assert_eq!(
        csv.last().map(|r| r.host_time_ns),
        solutions.last().map(|s| s.0.host_time_ns),
        "the last solution did not reach the client"
    );
    // The map channel: one LocationFix per solution, protobuf-encoded, its latitude in degrees.
    assert_eq!(locations.len(), solutions.len());
    let lat_deg = solutions[0].0.latitude_rad.to_degrees();
    let bits = lat_deg.to_le_bytes();
    assert!(
        locations[0].data.windows(8).any(|w| w == bits),
        "the first location does not carry latitude {lat_deg} degrees"
    );

    // The live view's stop line: what it served and its count of slow-client reports.
    let live = v["process_reports"]
        .as_array()
        .and_then(|a| a.iter().find(|p| p[0] == "auvnav-live"))
        .and_then(|p| p[1].as_str())
        .unwrap_or_default()
        .to_string();
    assert!(live.contains("messages served"), "{live}");
    assert!(
        live.contains("reports of a client not keeping up"),
        "{live}"
    );
}

#[test]
fn the_live_view_refuses_a_bad_configuration_and_prints_a_good_one() {
    let dir = TempDir::new("livecfg");
    let bad = dir.path().join("bad.toml");
    std::fs::write(&bad, "listen_address = \"everywhere\"\n").expect("write");
    let o = Command::new(binary("auvnav-live"))
        .arg("--config")
        .arg(&bad)
        .output()
        .expect("auvnav-live");
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(2), "{err}");
    assert!(
        err.contains("bad.toml") && err.contains("listen_address"),
        "{err}"
    );
    let example = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("..")
        .join("deploy")
        .join("auvnav-live.toml");
    let o = Command::new(binary("auvnav-live"))
        .arg("--check-config")
        .arg(&example)
        .output()
        .expect("auvnav-live");
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let printed = String::from_utf8_lossy(&o.stdout);
    assert!(
        printed.contains("listen_address = \"127.0.0.1\""),
        "{printed}"
    );
}

#[test]
fn a_client_that_does_not_keep_up_is_counted_and_the_others_still_receive() {
    let _one = ONE_AT_A_TIME.lock().unwrap_or_else(|e| e.into_inner());
    use auvnav_shm_schema::bus::Bus;
    use auvnav_shm_schema::{ImuSampleV1, ProcessHealthV1, qos};
    use auvnav_tests::processes::{Proc, unique};
    use std::sync::Arc;
    use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};

    let dir = TempDir::new("liveslow");
    let prefix = unique("lvslow");
    let port = free_port();
    let cfg = dir.path().join("live.toml");
    std::fs::write(
        &cfg,
        format!(
            "prefix = \"{prefix}\"\nname = \"liveslow\"\nport = {port}\nbacklog = 16\nhealth_period_s = 0.2\n"
        ),
    )
    .expect("config");
    let bus = Bus::new(&unique("lvslowpub"), &prefix).expect("bus");
    let mut imu = bus
        .publisher::<ImuSampleV1>(topic::IMU, qos::SENSOR)
        .expect("publisher");
    let mut health = bus
        .subscriber::<ProcessHealthV1>(topic::HEALTH, qos::HEALTH)
        .expect("subscriber");
    let mut live = Proc::spawn_logged(
        "auvnav-live",
        dir.path(),
        Command::new(binary("auvnav-live"))
            .arg("--config")
            .arg(&cfg),
    )
    .expect("auvnav-live");
    let addr = format!("127.0.0.1:{port}");

    // A client that reads everything, on its own thread.
    let received = Arc::new(AtomicU64::new(0));
    let done = Arc::new(AtomicBool::new(false));
    let reader = {
        let (received, done, addr) = (received.clone(), done.clone(), addr.clone());
        let mut c = LiveClient::connect_retrying(&addr, Duration::from_secs(20)).expect("client");
        c.wait_for_channels(&[topic::IMU], Duration::from_secs(10))
            .expect("channels");
        c.subscribe(&[topic::IMU]).expect("subscribe");
        c.set_read_timeout(Duration::from_millis(100))
            .expect("timeout");
        std::thread::spawn(move || {
            while !done.load(Ordering::SeqCst) {
                if let Ok(Some(_)) = c.read() {
                    received.fetch_add(1, Ordering::SeqCst);
                }
            }
        })
    };
    // A client that subscribes and never reads.
    let mut stalled = LiveClient::connect(&addr, Duration::from_secs(5)).expect("client");
    stalled
        .wait_for_channels(&[topic::IMU], Duration::from_secs(10))
        .expect("channels");
    stalled.subscribe(&[topic::IMU]).expect("subscribe");

    // 40 MB of IMU samples at about 40 kHz: far more than the stalled client's socket buffers
    // and backlog hold.
    let before = received.load(Ordering::SeqCst);
    for burst in 0..300u64 {
        for k in 0..500u64 {
            imu.publish(ImuSampleV1 {
                host_time_ns: (burst * 500 + k) * 25_000,
                ..Default::default()
            })
            .expect("publish");
        }
        std::thread::sleep(Duration::from_millis(12));
    }
    std::thread::sleep(Duration::from_millis(800));
    let fast = received.load(Ordering::SeqCst) - before;
    let mut reported = 0;
    while let Some(h) = health.receive().expect("health") {
        if h.name() == "liveslow" {
            reported = reported.max(h.drops);
        }
    }
    done.store(true, Ordering::SeqCst);
    reader.join().expect("reader");
    drop(stalled);
    assert!(
        reported >= 1,
        "the stalled client was not reported: {}",
        live.last_log_line()
    );
    // The reading client kept receiving while the other stalled (the server thins a client only
    // when its own outbox is full).
    assert!(fast > 10_000, "the reading client got {fast} of 150000");
    assert!(
        live.stop(Duration::from_secs(10)),
        "{}",
        live.last_log_line()
    );
    assert!(
        live.last_log_line()
            .contains("reports of a client not keeping up"),
        "{}",
        live.last_log_line()
    );
}
