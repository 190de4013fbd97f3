//! `auvnav-usbl` ranging LBL beacons with a SeaTrac (`[settings.seatrac] range_beacons`), as a
//! real process on a pseudo-terminal: the `CID_PING_RESP` fixes of the listed beacons are
//! published as ranges on `acoustic_ranges` (beacon `range_beacons[k]` as receiver k, stamped at
//! the reply's arrival: the frame's time less the configured latency), another beacon's fix stays
//! a USBL fix on `usbl`, and a fix whose range is unusable is counted and not published.

use auvnav_drivers::seatrac::{self, AcoFix, FixRange};
use auvnav_shm_schema::bus::Bus;
use auvnav_shm_schema::{AcousticRangesV1, ProcessHealthV1, UsblFixV1, qos, topic};
use auvnav_tests::processes::{Proc, TempDir, binary, unique};
use serialport::SerialPort;
use std::io::Write;
use std::process::Command;
use std::time::{Duration, Instant};

/// A ping response from `beacon` at `distance_m` (0: a range of zero, which no beacon is at).
fn ping_response(beacon: u8, distance_m: f64) -> Vec<u8> {
    let two_way = 2.0 * distance_m / 1500.0;
    let fix = AcoFix {
        destination_id: 0,
        source_id: beacon,
        flags: AcoFix::RANGE_VALID,
        message_type: 0,
        attitude_deg: [0.0; 3],
        local_depth_m: 20.0,
        sound_speed_m_s: 1500.0,
        rssi_db: -40.0,
        range: Some(FixRange {
            count: (two_way * 16_000.0).round() as u32,
            travel_time_s: two_way,
            distance_m,
        }),
        usbl: None,
        position_m: None,
    };
    seatrac::encode_line(seatrac::CID_PING_RESP, &seatrac::encode_aco_fix(&fix))
}

#[test]
fn ranged_beacons_are_published_as_ranges_and_others_as_usbl_fixes() {
    let tmp = TempDir::new("seatrac-lbl");
    let prefix = unique("lbl");
    let (mut master, slave) = serialport::TTYPort::pair().expect("pty");
    let port = slave.name().expect("slave path");
    let cfg = tmp.path().join("usbl.toml");
    std::fs::write(
        &cfg,
        format!(
            "prefix = \"{prefix}\"\nprotocol = \"seatrac\"\n[serial]\nport = \"{port}\"\n\
             [settings]\nlatency_s = 0.25\n[settings.seatrac]\nrange_beacons = [3, 1, 2]\n\
             [timing]\nread_timeout_s = 0.01\nhealth_period_s = 0.05\n"
        ),
    )
    .expect("config");
    let bus = Bus::new(&unique("lbltest"), &prefix).expect("bus");
    let mut ranges = bus
        .subscriber::<AcousticRangesV1>(topic::ACOUSTIC_RANGES, qos::SENSOR)
        .expect("ranges");
    let mut usbl = bus
        .subscriber::<UsblFixV1>(topic::USBL, qos::SENSOR)
        .expect("usbl");
    let mut health = bus
        .subscriber::<ProcessHealthV1>(topic::HEALTH, qos::HEALTH)
        .expect("health");
    let err_path = tmp.path().join("usbl.err");
    let mut driver = Proc::spawn(
        "usbl",
        Command::new(binary("auvnav-usbl"))
            .arg("--config")
            .arg(&cfg)
            .stderr(std::fs::File::create(&err_path).expect("stderr")),
    )
    .expect("spawn");
    std::thread::sleep(Duration::from_millis(500));

    // Beacons 3, 1 and 2 in turn (receivers 0, 1, 2), beacon 7 (not ranged: a USBL fix), and
    // beacon 1 at a range of zero (unusable).
    let pings = [
        (3, 812.4),
        (1, 655.1),
        (7, 120.0),
        (2, 1034.9),
        (1, 0.0),
        (1, 650.3),
    ];
    let mut sent_ns = Vec::new();
    for (beacon, d) in pings {
        sent_ns.push(auvnav_shm_schema::clock::monotonic_ns());
        master.write_all(&ping_response(beacon, d)).expect("write");
        std::thread::sleep(Duration::from_millis(100));
    }
    let (mut got, mut fixes, mut last) = (Vec::new(), Vec::new(), None);
    let deadline = Instant::now() + Duration::from_secs(10);
    while got.len() < 4 && Instant::now() < deadline {
        while let Some(m) = ranges.receive().expect("receive") {
            got.push(m);
        }
        while let Some(m) = usbl.receive().expect("receive") {
            fixes.push(m);
        }
        std::thread::sleep(Duration::from_millis(10));
    }
    std::thread::sleep(Duration::from_millis(200));
    while let Some(h) = health.receive().expect("receive") {
        if h.name() == "usbl" {
            last = Some(h);
        }
    }
    let status = driver.terminate(Duration::from_secs(10));
    assert!(status.is_some_and(|s| s.success()), "{status:?}");
    let log = std::fs::read_to_string(&err_path).unwrap_or_default();

    let want = [(0, 812.4, 0), (1, 655.1, 1), (2, 1034.9, 3), (1, 650.3, 5)];
    assert_eq!(got.len(), want.len(), "{log}");
    for (m, (slot, d, ping)) in got.iter().zip(want) {
        assert_eq!(m.validity, AcousticRangesV1::VALID_RANGE << slot, "{m:?}");
        assert!((m.range_m[slot] - d).abs() < 1e-9, "{m:?}");
        // Stamped at the frame's first byte less the 0.25 s latency.
        let stamp_s = (m.host_time_ns as f64 - sent_ns[ping] as f64) * 1e-9;
        assert!((-0.26..-0.2).contains(&stamp_s), "ping {ping}: {stamp_s} s");
    }
    assert_eq!(fixes.len(), 1, "beacon 7 as a USBL fix: {log}");
    assert_eq!(fixes[0].beacon_id, 7);
    let h = last.expect("health");
    assert_eq!(h.frames, 5, "{h:?}");
    assert_eq!(h.invalid, 1, "the range of zero: {h:?}");
    assert!(log.contains("acoustic_ranges (beacons [3, 1, 2]"), "{log}");
}

/// A simulated LBL survey (`auvnav sim --scenario ranges_lbl`) played through an emulated SeaTrac
/// (`auvnav emulate --usbl seatrac --lbl-beacons 1,2,3`) into the real driver: every range of
/// the log comes out on `acoustic_ranges` in its receiver's slot, in order, to the wire's 0.1 m.
#[test]
fn an_emulated_lbl_survey_reaches_the_bus_range_by_range() {
    use auvnav_log::{LogMessage, LogReader};
    let tmp = TempDir::new("seatrac-emulated");
    let log = tmp.path().join("lbl.mcap");
    let sim = Command::new(binary("auvnav"))
        .args([
            "sim",
            "--scenario",
            "ranges_lbl",
            "--duration",
            "30",
            "--out",
        ])
        .arg(&log)
        .output()
        .expect("auvnav sim");
    assert!(
        sim.status.success(),
        "{}",
        String::from_utf8_lossy(&sim.stderr)
    );
    let mut want: Vec<(usize, f64)> = Vec::new();
    let mut reader = LogReader::open(&log).expect("log");
    while let Some(raw) = reader.next_message().expect("read") {
        if let LogMessage::AcousticRanges(r) = raw.decode_any().expect("decode") {
            for k in 0..4 {
                if r.range_valid(k) {
                    want.push((k, r.range_m[k]));
                }
            }
        }
    }
    assert!(want.len() > 60, "{} ranges", want.len());

    let prefix = unique("lblemu");
    let links = tmp.path().join("links");
    let cfg = tmp.path().join("usbl.toml");
    std::fs::write(
        &cfg,
        format!(
            "prefix = \"{prefix}\"\nprotocol = \"seatrac\"\n[serial]\nport = \"{}\"\n\
             [settings.seatrac]\nrange_beacons = [1, 2, 3]\n\
             [timing]\nread_timeout_s = 0.01\nreconnect_initial_s = 0.02\nreconnect_max_s = 0.1\n",
            links.join("usbl").display()
        ),
    )
    .expect("config");
    let bus = Bus::new(&unique("lblemutest"), &prefix).expect("bus");
    let mut ranges = bus
        .subscriber::<AcousticRangesV1>(topic::ACOUSTIC_RANGES, qos::SENSOR)
        .expect("ranges");
    let mut driver = Proc::spawn(
        "usbl",
        Command::new(binary("auvnav-usbl"))
            .arg("--config")
            .arg(&cfg)
            .stderr(std::fs::File::create(tmp.path().join("usbl.err")).expect("stderr")),
    )
    .expect("spawn");
    let mut emulator = Proc::spawn(
        "emulate",
        Command::new(binary("auvnav"))
            .arg("emulate")
            .arg(&log)
            .args([
                "--usbl",
                "seatrac",
                "--lbl-beacons",
                "1,2,3",
                "--speed",
                "5",
            ])
            .args(["--start-delay", "1.0", "--link-dir"])
            .arg(&links)
            .stdout(std::process::Stdio::null())
            .stderr(std::fs::File::create(tmp.path().join("emulate.err")).expect("stderr")),
    )
    .expect("spawn");
    let mut got = Vec::new();
    let deadline = Instant::now() + Duration::from_secs(60);
    let mut finished = None;
    loop {
        while let Some(m) = ranges.receive().expect("receive") {
            got.push(m);
        }
        if finished.is_none()
            && let Ok(Some(status)) = emulator.child.try_wait()
        {
            assert!(status.success(), "the emulator failed");
            finished = Some(Instant::now());
        }
        if finished.is_some_and(|t| t.elapsed() > Duration::from_millis(500)) {
            break;
        }
        assert!(Instant::now() < deadline, "the run did not finish in 60 s");
        std::thread::sleep(Duration::from_millis(5));
    }
    let status = driver.terminate(Duration::from_secs(10));
    assert!(status.is_some_and(|s| s.success()), "{status:?}");
    let err = std::fs::read_to_string(tmp.path().join("usbl.err")).unwrap_or_default();
    assert_eq!(got.len(), want.len(), "{err}");
    for (m, (k, d)) in got.iter().zip(&want) {
        assert_eq!(m.validity, AcousticRangesV1::VALID_RANGE << k, "{m:?}");
        assert!(
            (m.range_m[*k] - d).abs() <= 0.05 + 1e-9,
            "{} against {d}",
            m.range_m[*k]
        );
    }
}
