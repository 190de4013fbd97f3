//! `auvnav-gnss` as a real process on a pseudo-terminal.
//!
//! 1. A real receiver's NMEA (u-blox ZED-F9P, gpsd's capture) played epoch by epoch while this
//!    test publishes the depth: fixes are published while the depth is at the surface, withheld
//!    while it is 10 m, published again when it returns; a damaged sentence is counted.
//! 2. Simulated surface fixes emulated as u-blox `NAV-PVT` (`auvnav emulate --gnss ubx`) reach
//!    the bus as they were, for a surface vessel (no gate).

use auvnav_log::{LogMessage, LogReader};
use auvnav_shm_schema::bus::Bus;
use auvnav_shm_schema::{DepthV1, GnssFixV1, ProcessHealthV1, qos, topic};
use auvnav_tests::processes::{Proc, TempDir, binary, unique};
use serialport::SerialPort;
use std::io::Write;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

fn capture_dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../drivers/tests/captures/gpsd")
}

fn monotonic_ns() -> u64 {
    let t = nix::time::clock_gettime(nix::time::ClockId::CLOCK_MONOTONIC).expect("clock");
    t.tv_sec() as u64 * 1_000_000_000 + t.tv_nsec() as u64
}

fn config(dir: &Path, prefix: &str, protocol: &str, port: &str, gnss: &str) -> PathBuf {
    let cfg = dir.join("gnss.toml");
    std::fs::write(
        &cfg,
        format!(
            "prefix = \"{prefix}\"\nprotocol = \"{protocol}\"\n[serial]\nport = \"{port}\"\n\
             [settings.gnss]\n{gnss}\n\
             [timing]\nread_timeout_s = 0.01\nreconnect_initial_s = 0.02\nreconnect_max_s = 0.1\n\
             health_period_s = 0.05\n"
        ),
    )
    .expect("config");
    cfg
}

#[test]
fn real_nmea_is_published_at_the_surface_and_withheld_below_it() {
    // The capture's epochs: each starts with its RMC.
    let text =
        std::fs::read_to_string(capture_dir().join("ublox-zed-f9p-nmea.log")).expect("a value");
    let mut epochs: Vec<String> = Vec::new();
    for line in text.lines().filter(|l| l.starts_with('$')) {
        if line.starts_with("$GNRMC") || epochs.is_empty() {
            epochs.push(String::new());
        }
        let e = epochs.last_mut().expect("a value");
        e.push_str(line);
        e.push_str("\r\n");
    }
    assert_eq!(epochs.len(), 29);
    let reference: Vec<(f64, f64)> =
        std::fs::read_to_string(capture_dir().join("ublox-zed-f9p-nmea.gpsd-tpv.csv"))
            .expect("a value")
            .lines()
            .skip(1)
            .map(|l| {
                let f: Vec<&str> = l.split(',').collect();
                (
                    f[1].parse().expect("a value"),
                    f[2].parse().expect("a value"),
                )
            })
            .collect();

    let tmp = TempDir::new("gnss-nmea");
    let prefix = unique("gnss");
    let (mut master, slave) = serialport::TTYPort::pair().expect("pty");
    let port = slave.name().expect("slave path");
    let cfg = config(
        tmp.path(),
        &prefix,
        "nmea",
        &port,
        "surface_only = true\nsurface_depth_m = 0.5\ndepth_timeout_s = 3.0",
    );
    let bus = Bus::new(&unique("gnsstest"), &prefix).expect("bus");
    let mut depth = bus
        .publisher::<DepthV1>(topic::DEPTH, qos::SENSOR)
        .expect("depth");
    let mut fixes = bus
        .subscriber::<GnssFixV1>(topic::GNSS, qos::SENSOR)
        .expect("gnss");
    let mut health = bus
        .subscriber::<ProcessHealthV1>(topic::HEALTH, qos::HEALTH)
        .expect("health");
    let err_path = tmp.path().join("gnss.err");
    let mut driver = Proc::spawn(
        "gnss",
        Command::new(binary("auvnav-gnss"))
            .arg("--config")
            .arg(&cfg)
            .stderr(std::fs::File::create(&err_path).expect("stderr")),
    )
    .expect("spawn");
    std::thread::sleep(Duration::from_millis(500));

    // Epochs 0..8 at the surface, 8..16 at 10 m, 16..24 at the surface again. The depth goes out
    // before the epoch whose fix it gates.
    let depth_of = |k: usize| if (8..16).contains(&k) { 10.0 } else { 0.2 };
    let mut got = Vec::new();
    let mut last = None;
    let mut drain_health = |last: &mut Option<ProcessHealthV1>| {
        while let Some(h) = health.receive().expect("receive") {
            if h.name() == "gnss" {
                *last = Some(h);
            }
        }
    };
    for (k, e) in epochs.iter().take(24).enumerate() {
        depth
            .publish(DepthV1 {
                host_time_ns: monotonic_ns(),
                depth_m: depth_of(k),
                validity: DepthV1::VALID_DEPTH,
                ..Default::default()
            })
            .expect("publish depth");
        let mut bytes = e.clone().into_bytes();
        if k == 18 {
            // One GSV sentence with a damaged byte: counted, the fix unaffected.
            let at = e.find("$GPGSV").expect("a GSV") + 10;
            bytes[at] ^= 0x01;
        }
        master.write_all(&bytes).expect("write");
        std::thread::sleep(Duration::from_millis(60));
        while let Some(f) = fixes.receive().expect("receive") {
            got.push(f);
        }
        drain_health(&mut last);
    }
    let deadline = Instant::now() + Duration::from_secs(5);
    while got.len() < 16 && Instant::now() < deadline {
        std::thread::sleep(Duration::from_millis(20));
        while let Some(f) = fixes.receive().expect("receive") {
            got.push(f);
        }
    }
    std::thread::sleep(Duration::from_millis(200));
    let status = driver.terminate(Duration::from_secs(10));
    assert!(status.is_some_and(|s| s.success()), "{status:?}");
    while let Some(f) = fixes.receive().expect("receive") {
        got.push(f);
    }
    drain_health(&mut last);
    let log = std::fs::read_to_string(&err_path).unwrap_or_default();

    let expected: Vec<(f64, f64)> = (0..24)
        .filter(|k| depth_of(*k) < 0.5)
        .map(|k| reference[k])
        .collect();
    assert_eq!(got.len(), expected.len(), "{log}");
    for (f, (lat, lon)) in got.iter().zip(&expected) {
        assert!((f.latitude_rad.to_degrees() - lat).abs() < 1e-8);
        assert!((f.longitude_rad.to_degrees() - lon).abs() < 1e-8);
        let need =
            GnssFixV1::VALID_POSITION | GnssFixV1::VALID_HEIGHT | GnssFixV1::VALID_DEVICE_TIME;
        assert_eq!(f.validity & need, need);
    }
    assert!(log.contains("withholding fixes: depth 10.00 m"), "{log}");
    assert!(log.contains("at the surface again"), "{log}");
    assert!(log.contains("8 fixes withheld below the surface"), "{log}");
    let last = last.expect("health");
    assert_eq!(last.frames, 16);
    assert_eq!(last.checksum_errors, 1);
}

#[test]
fn simulated_fixes_emulated_as_ubx_reach_the_bus_as_they_were() {
    let tmp = TempDir::new("gnss-ubx");
    let log = tmp.path().join("dive.mcap");
    let out = Command::new(binary("auvnav"))
        .args(["sim", "--scenario", "dive", "--duration", "12", "--out"])
        .arg(&log)
        .output()
        .expect("sim");
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let mut played = Vec::new();
    let mut reader = LogReader::open(&log).expect("log");
    while let Some(raw) = reader.next_message().expect("read") {
        if let LogMessage::Gnss(f) = raw.decode_any().expect("decode") {
            played.push(f);
        }
    }
    assert!(played.len() >= 10, "{}", played.len());

    let prefix = unique("gnssubx");
    let links = tmp.path().join("dev");
    let cfg = config(
        tmp.path(),
        &prefix,
        "ubx",
        &links.join("gnss").display().to_string(),
        "surface_only = false",
    );
    let bus = Bus::new(&unique("gnssubxtest"), &prefix).expect("bus");
    let mut fixes = bus
        .subscriber::<GnssFixV1>(topic::GNSS, qos::SENSOR)
        .expect("gnss");
    let mut driver = Proc::spawn(
        "gnss",
        Command::new(binary("auvnav-gnss"))
            .arg("--config")
            .arg(&cfg)
            .stderr(std::fs::File::create(tmp.path().join("gnss.err")).expect("stderr")),
    )
    .expect("spawn");
    let mut emulator = Command::new(binary("auvnav"))
        .arg("emulate")
        .arg(&log)
        .args([
            "--gnss",
            "ubx",
            "--speed",
            "4",
            "--start-delay",
            "1",
            "--link-dir",
        ])
        .arg(&links)
        .stdout(Stdio::null())
        .spawn()
        .expect("emulate");
    // Received while the driver runs: its samples go with it when it stops.
    let mut got = Vec::new();
    let deadline = Instant::now() + Duration::from_secs(60);
    let finished = loop {
        while let Some(f) = fixes.receive().expect("receive") {
            got.push(f);
        }
        if let Some(status) = emulator.try_wait().expect("emulator") {
            break status;
        }
        assert!(Instant::now() < deadline, "the emulator did not finish");
        std::thread::sleep(Duration::from_millis(20));
    };
    assert!(finished.success());
    std::thread::sleep(Duration::from_millis(200));
    while let Some(f) = fixes.receive().expect("receive") {
        got.push(f);
    }
    let status = driver.terminate(Duration::from_secs(10));
    assert!(status.is_some_and(|s| s.success()), "{status:?}");
    let err = std::fs::read_to_string(tmp.path().join("gnss.err")).unwrap_or_default();
    assert_eq!(got.len(), played.len(), "{err}");
    for (g, p) in got.iter().zip(&played) {
        assert!((g.latitude_rad - p.latitude_rad).abs() * 6.4e6 < 0.02);
        assert!((g.longitude_rad - p.longitude_rad).abs() * 6.4e6 < 0.02);
        assert!((g.height_m - p.height_m).abs() < 1e-3);
        assert!((g.horizontal_std_m - p.horizontal_std_m).abs() < 1e-3);
        // Stamped with the emulator's UTC: valid GPS time, after 2026.
        assert_ne!(g.validity & GnssFixV1::VALID_DEVICE_TIME, 0);
        assert!(g.device_time_ns > 1_450_000_000 * 1_000_000_000, "{g:?}");
    }
}
