//! `auvnav-dvl` reading a Water Linked DVL's TCP service (`protocol = "wldvl-json"`, `[tcp]`) as a
//! real process against a loopback server that plays the documented velocity report and broken
//! lines: the reports are published, the broken lines counted and never published, and when the
//! server drops the connection the driver reconnects and publishes again.

use auvnav_shm_schema::bus::Bus;
use auvnav_shm_schema::{DvlVelocityV1, ProcessHealthV1, qos, topic};
use auvnav_tests::processes::{Proc, TempDir, binary, unique};
use std::io::Write;
use std::net::TcpListener;
use std::process::Command;
use std::time::{Duration, Instant};

#[test]
fn the_tcp_reports_are_published_broken_lines_counted_and_a_dropped_connection_reopened() {
    let Some(dir) = auvnav_tests::shared::shared("protocols/waterlinked_dvl") else {
        return;
    };
    let example = std::fs::read_to_string(dir.join("doc_example_tcp_velocity.json"))
        .expect("the documented reports");
    let velocity_line = example
        .lines()
        .next()
        .expect("a velocity report")
        .to_string();
    let position_line = example
        .lines()
        .nth(1)
        .expect("a position report")
        .to_string();

    let tmp = TempDir::new("tcpdvl");
    let listener = TcpListener::bind("127.0.0.1:0").expect("loopback listener");
    let address = listener.local_addr().expect("address");
    let prefix = unique("tcp");
    let cfg = tmp.path().join("dvl.toml");
    std::fs::write(
        &cfg,
        format!(
            "prefix = \"{prefix}\"\nprotocol = \"wldvl-json\"\n[tcp]\naddress = \"{address}\"\n\
             [timing]\nread_timeout_s = 0.02\nsilence_timeout_s = 0.5\nreconnect_initial_s = 0.02\n\
             reconnect_max_s = 0.2\nhealth_period_s = 0.05\n"
        ),
    )
    .expect("config");
    let check = Command::new(binary("auvnav-dvl"))
        .args(["--config", &cfg.display().to_string(), "--check-config"])
        .output()
        .expect("check");
    assert!(
        check.status.success(),
        "{}",
        String::from_utf8_lossy(&check.stderr)
    );

    let bus = Bus::new(&unique("tcptest"), &prefix).expect("bus");
    let mut dvl = bus
        .subscriber::<DvlVelocityV1>(topic::DVL, qos::SENSOR)
        .expect("dvl");
    let mut health = bus
        .subscriber::<ProcessHealthV1>(topic::HEALTH, qos::HEALTH)
        .expect("health");
    let err = std::fs::File::create(tmp.path().join("dvl.err")).expect("stderr");
    let mut driver = Proc::spawn(
        "dvl",
        Command::new(binary("auvnav-dvl"))
            .arg("--config")
            .arg(&cfg)
            .stderr(err),
    )
    .expect("spawn");

    let (mut got, mut healths) = (Vec::new(), Vec::new());
    let mut drain = |got: &mut Vec<DvlVelocityV1>, healths: &mut Vec<ProcessHealthV1>| {
        while let Some(m) = dvl.receive().expect("receive") {
            got.push(m);
        }
        while let Some(h) = health.receive().expect("receive") {
            healths.push(h);
        }
    };
    let deadline = Instant::now() + Duration::from_secs(30);
    // First connection: three reports, a position report and two broken lines; then close.
    {
        let (mut conn, _) = listener.accept().expect("the driver connects");
        let text = format!(
            "{velocity_line}\nnot json at all\n{velocity_line}\n{position_line}\n{{\"type\": \"velocity\"}}\n{velocity_line}\n"
        );
        conn.write_all(text.as_bytes()).expect("send");
        while got.len() < 3 {
            assert!(
                Instant::now() < deadline,
                "only {} reports arrived",
                got.len()
            );
            drain(&mut got, &mut healths);
            std::thread::sleep(Duration::from_millis(5));
        }
    }
    // The server dropped the connection: the driver reconnects and reads on.
    {
        let (mut conn, _) = listener.accept().expect("the driver reconnects");
        conn.write_all(format!("{velocity_line}\n").as_bytes())
            .expect("send");
        while got.len() < 4 {
            assert!(
                Instant::now() < deadline,
                "no report after the reconnection"
            );
            drain(&mut got, &mut healths);
            std::thread::sleep(Duration::from_millis(5));
        }
        std::thread::sleep(Duration::from_millis(200));
    }
    let status = driver.terminate(Duration::from_secs(10));
    assert!(status.is_some_and(|s| s.success()), "{status:?}");
    std::thread::sleep(Duration::from_millis(50));
    drain(&mut got, &mut healths);

    assert_eq!(got.len(), 4, "exactly the four velocity reports");
    for m in &got {
        assert_ne!(m.validity & DvlVelocityV1::VALID_VELOCITY, 0);
        assert_eq!(m.velocity_dvl_m_s[0], -3.713480691658333e-05);
        assert_eq!(m.altitude_m, 0.4949815273284912);
        // The report's transmission delay (189.319 ms) comes off the read time.
        assert_eq!(m.host_time_ns - m.validity_time_ns, 189_319_000);
    }
    let last = healths
        .iter()
        .rev()
        .find(|h| h.name() == "dvl")
        .expect("health");
    assert_eq!(last.frames, 4);
    assert_eq!(last.invalid, 2, "the two broken lines");
    assert!(last.reconnects >= 1, "{last:?}");
}
