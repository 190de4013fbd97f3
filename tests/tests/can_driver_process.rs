//! `auvnav-can` as a real process: frames from a candump log through the DBC to depth messages
//! on the bus; and, on a machine without SocketCAN, a clear refusal instead of a silent run.

use auvnav_drivers::can::DbcDecoder;
use auvnav_drivers::can_driver::SAMPLE_DBC;
use auvnav_shm_schema::bus::Bus;
use auvnav_shm_schema::{DepthV1, ProcessHealthV1, ProcessState, qos, topic};
use auvnav_tests::processes::{Proc, TempDir, binary, unique};
use std::fmt::Write;
use std::process::Command;
use std::time::{Duration, Instant};

fn config(dir: &std::path::Path, prefix: &str, interface: &str) -> std::path::PathBuf {
    let p = dir.join("can.toml");
    std::fs::write(
        &p,
        format!("prefix = \"{prefix}\"\ninterface = \"{interface}\"\nhealth_period_s = 0.05\n"),
    )
    .expect("config");
    p
}

#[test]
fn candump_frames_become_depth_messages_on_the_bus() {
    let dir = TempDir::new("canproc");
    let prefix = unique("can");
    let dbc = DbcDecoder::from_dbc(SAMPLE_DBC).expect("dbc");
    // 100 pressure frames from 0 to 49.5 m, an altimeter frame and two bad lines between them.
    let mut log = String::new();
    let depth_of = |i: usize| i as f64 * 0.5;
    for i in 0..100 {
        let bar = (101_325.0 + 1025.0 * 9.806_65 * depth_of(i)) / 1e5;
        let f = dbc
            .encode(
                "PressureSensor",
                &[
                    ("Pressure", bar),
                    ("Temperature", 8.0),
                    ("Counter", (i % 256) as f64),
                ],
            )
            .expect("frame");
        let hex: String = f.data.iter().map(|b| format!("{b:02X}")).collect();
        writeln!(
            log,
            "({}.{:06}) can0 {:03X}#{hex}",
            1000 + i / 10,
            (i % 10) * 100_000,
            f.id
        )
        .expect("write");
        if i == 50 {
            log.push_str(
                "(1005.050000) can0 2A0#0102030405060708\ngarbage line\n(1005.06) can0 181#00\n",
            );
        }
    }
    let candump = dir.path().join("bus.log");
    std::fs::write(&candump, log).expect("candump");
    let bus = Bus::new(&unique("cantest"), &prefix).expect("bus");
    let mut sub = bus
        .subscriber::<DepthV1>(topic::DEPTH, qos::SENSOR)
        .expect("sub");
    let mut health = bus
        .subscriber::<ProcessHealthV1>(topic::HEALTH, qos::HEALTH)
        .expect("health");
    let cfg = config(dir.path(), &prefix, "can0");
    let mut p = Proc::spawn(
        "auvnav-can",
        Command::new(binary("auvnav-can"))
            .arg("--config")
            .arg(&cfg)
            .arg("--candump")
            .arg(&candump)
            .args(["--speed", "20"]),
    )
    .expect("spawn");
    // 10 s of frames at 20x: about half a second; the watchdog allows 30 s.
    let mut got = Vec::new();
    let mut last = None;
    let end = Instant::now() + Duration::from_secs(30);
    let status = loop {
        while let Some(m) = sub.receive().expect("receive") {
            got.push(m);
        }
        while let Some(h) = health.receive().expect("receive") {
            last = Some(h);
        }
        if let Ok(Some(s)) = p.child.try_wait() {
            break s;
        }
        assert!(Instant::now() < end, "auvnav-can did not finish");
        std::thread::sleep(Duration::from_millis(2));
    };
    assert!(status.success());
    assert_eq!(got.len(), 100, "one depth message per pressure frame");
    for (i, m) in got.iter().enumerate() {
        assert!((m.depth_m - depth_of(i)).abs() < 2e-3, "{i}: {}", m.depth_m);
        assert_eq!(m.sequence, i as u64);
    }
    let h = last.expect("health");
    assert_eq!(h.state, ProcessState::Stopping as u32);
    assert_eq!(h.frames, 100);
    // The altimeter frame is not depth, the short pressure frame is invalid; the garbage line
    // never became a frame (reported on stderr).
    assert_eq!(h.invalid, 1);
    assert_eq!(h.drops, 0);
}

#[test]
fn without_a_can_interface_the_driver_says_so_and_exits() {
    let dir = TempDir::new("cannone");
    let cfg = config(dir.path(), &unique("can"), "auvnavcan9");
    let out = Command::new(binary("auvnav-can"))
        .arg("--config")
        .arg(&cfg)
        .output()
        .expect("run");
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(3), "{err}");
    assert!(
        err.contains("auvnavcan9") && err.contains("not available"),
        "{err}"
    );
    // A configuration error is status 2 and names the key.
    std::fs::write(&cfg, "interface = \"can0\"\nhealth_period_s = 0\n").expect("config");
    let out = Command::new(binary("auvnav-can"))
        .arg("--config")
        .arg(&cfg)
        .output()
        .expect("run");
    assert_eq!(out.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&out.stderr).contains("health_period_s"));
}
