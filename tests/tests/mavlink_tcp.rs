//! `auvnav-mavlink` as a MAVLink TCP client, the way it connects to ArduPilot SITL's TCP port or a
//! router's TCP server: a server here (the `mavlink` crate's codec on a loopback socket) plays the
//! autopilot. It receives the heartbeats at their period, what it sends back (a heartbeat and a
//! status text) is read and logged, and a link the server closes is opened again. With
//! `[source]`, the autopilot's IMU and pressure sensor stream over the link, and the daemon
//! navigates on them.

use auvnav_shm_schema::bus::Bus;
use auvnav_shm_schema::{
    AidDiagnosticsV1, AidSource, DepthV1, ImuSampleV1, NavSolutionV1, qos, topic,
};
use auvnav_tests::processes::{Proc, TempDir, binary, still_daemon_config, unique};
use mavlink::dialects::ardupilotmega as mav;
use mavlink::{MavHeader, MavlinkReader, MavlinkVersion};
use std::net::{TcpListener, TcpStream};
use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::{Duration, Instant};

/// Accepts one connection within `timeout`.
fn accept(server: &TcpListener, timeout: Duration) -> Option<TcpStream> {
    server.set_nonblocking(true).expect("nonblocking");
    let start = Instant::now();
    while start.elapsed() < timeout {
        if let Ok((s, _)) = server.accept() {
            s.set_nonblocking(false).expect("blocking");
            return Some(s);
        }
        std::thread::sleep(Duration::from_millis(20));
    }
    None
}

/// The heartbeats from (system, component) read from `stream` over `seconds`.
fn heartbeats_from(stream: &TcpStream, source: (u32, u8), seconds: f64) -> usize {
    stream
        .set_read_timeout(Some(Duration::from_millis(200)))
        .expect("timeout");
    let mut reader = MavlinkReader::new(stream.try_clone().expect("clone"));
    let start = Instant::now();
    let mut n = 0;
    while start.elapsed().as_secs_f64() < seconds {
        if let Ok((h, mav::MavMessage::HEARTBEAT(_))) = reader.read_any_message::<mav::MavMessage>()
            && (h.system_id, h.component_id) == source
        {
            n += 1;
        }
    }
    n
}

/// A loopback server playing the autopilot, and an `auvnav-mavlink` configuration in `dir` on
/// `prefix` that connects to it as a TCP client, with `more` appended.
fn server_and_config(dir: &Path, prefix: &str, more: &str) -> (TcpListener, u16, PathBuf) {
    let server = TcpListener::bind("127.0.0.1:0").expect("a free port");
    let port = server.local_addr().expect("address").port();
    let cfg = dir.join("mavlink.toml");
    std::fs::write(
        &cfg,
        format!("prefix = \"{prefix}\"\naddress = \"tcpout:127.0.0.1:{port}\"\n{more}"),
    )
    .expect("config");
    (server, port, cfg)
}

#[test]
fn a_tcp_link_carries_heartbeats_both_ways_and_is_opened_again_when_closed() {
    let tmp = TempDir::new("mavtcp");
    let exe = binary("auvnav-mavlink");
    let (server, port, cfg) = server_and_config(
        tmp.path(),
        &unique("mavtcp"),
        "system_id = 1\ncomponent_id = 197\nmessage = \"odometry\"\nrate_hz = 10.0\n\
         heartbeat_period_s = 0.2\n",
    );
    let log = tmp.path().join("mavlink.err");
    let err = std::fs::File::create(&log).expect("stderr");
    let mut sender = Proc::spawn(
        "mavlink",
        Command::new(&exe).arg("--config").arg(&cfg).stderr(err),
    )
    .expect("spawn");

    let stream = accept(&server, Duration::from_secs(10)).expect("auvnav-mavlink connects");
    // The autopilot's side: a heartbeat and a status text, as ArduSub sends them.
    let heartbeat = mav::MavMessage::HEARTBEAT(mav::HEARTBEAT_DATA {
        mavtype: mav::MavType::MAV_TYPE_SUBMARINE,
        autopilot: mav::MavAutopilot::MAV_AUTOPILOT_ARDUPILOTMEGA,
        ..Default::default()
    });
    let text = mav::MavMessage::STATUSTEXT(mav::STATUSTEXT_DATA {
        severity: mav::MavSeverity::MAV_SEVERITY_INFO,
        text: "EKF3 IMU0 is using external nav data".into(),
        ..Default::default()
    });
    let mut w = stream.try_clone().expect("clone");
    for m in [&heartbeat, &text] {
        send_as_autopilot(&mut w, m);
    }
    // 2 s at a heartbeat every 0.2 s.
    let n = heartbeats_from(&stream, (1, 197), 2.0);
    assert!((8..=12).contains(&n), "{n} heartbeats in 2 s");

    // The server closes the link: auvnav-mavlink opens it again.
    drop(w);
    stream.shutdown(std::net::Shutdown::Both).expect("shutdown");
    drop(stream);
    let again = accept(&server, Duration::from_secs(10)).expect("reconnected");
    assert!(heartbeats_from(&again, (1, 197), 1.0) >= 3);

    let status = sender.terminate(Duration::from_secs(10));
    assert!(status.is_some_and(|s| s.success()), "{status:?}");
    let text = std::fs::read_to_string(&log).unwrap_or_default();
    assert!(
        text.contains(&format!("system 1 component 1 on tcpout:127.0.0.1:{port}"))
            && text.contains("MAV_TYPE_SUBMARINE"),
        "{text}"
    );
    assert!(
        text.contains("EKF3 IMU0 is using external nav data"),
        "{text}"
    );
    assert!(
        text.contains("1 heartbeats of the autopilot, 1 status texts"),
        "{text}"
    );
    assert!(
        text.contains("closed") && text.contains("reconnecting"),
        "{text}"
    );
}

/// Writes `m` to the link as the autopilot (system 1, component 1).
fn send_as_autopilot(w: &mut TcpStream, m: &mav::MavMessage) {
    let header = MavHeader {
        system_id: 1,
        component_id: 1,
        sequence: 0,
    };
    mavlink::write_versioned_msg(w, MavlinkVersion::V2, header, m).expect("send");
}

#[test]
// Long on purpose: one scenario with real processes read top to bottom: each step depends on the
// state the previous one left.
fn the_autopilots_imu_and_pressure_reach_the_daemon_which_navigates_on_them() {
    let tmp = TempDir::new("mavsource");
    let prefix = unique("mavsource");
    let (server, _, cfg) = server_and_config(
        tmp.path(),
        &prefix,
        "[source]\nimu_hz = 50.0\ndepth_hz = 10.0\nsurface_pressure_hpa = 1013.25\n",
    );
    let bus = Bus::new(&unique("mavsourcetest"), &prefix).expect("bus");
    let mut imu = bus
        .subscriber::<ImuSampleV1>(topic::IMU, qos::SENSOR)
        .expect("imu subscriber");
    let mut depth = bus
        .subscriber::<DepthV1>(topic::DEPTH, qos::SENSOR)
        .expect("depth subscriber");
    let mut solutions = bus
        .subscriber::<NavSolutionV1>(topic::NAV_SOLUTION, qos::NAVIGATION)
        .expect("solution subscriber");
    // The vehicle rests 3 m deep (the daemon's smallest configuration, started there).
    let daemon_cfg = still_daemon_config(tmp.path(), &prefix);
    let text = std::fs::read_to_string(&daemon_cfg).expect("configuration");
    std::fs::write(
        &daemon_cfg,
        text.replace("height_m = 0.0", "height_m = -3.0"),
    )
    .expect("configuration");
    let mut diagnostics = bus
        .subscriber::<AidDiagnosticsV1>(topic::NAV_AID_DIAGNOSTICS, qos::NAVIGATION)
        .expect("diagnostics subscriber");
    let mut daemon = Proc::spawn(
        "auvnavd",
        Command::new(binary("auvnavd"))
            .arg("--config")
            .arg(&daemon_cfg)
            .stderr(std::fs::File::create(tmp.path().join("auvnavd.err")).expect("log")),
    )
    .expect("spawn");
    let log = tmp.path().join("mavlink.err");
    let mut sender = Proc::spawn(
        "mavlink",
        Command::new(binary("auvnav-mavlink"))
            .arg("--config")
            .arg(&cfg)
            .stderr(std::fs::File::create(&log).expect("log")),
    )
    .expect("spawn");
    let stream = accept(&server, Duration::from_secs(10)).expect("auvnav-mavlink connects");
    let mut w = stream.try_clone().expect("clone");
    send_as_autopilot(
        &mut w,
        &mav::MavMessage::HEARTBEAT(mav::HEARTBEAT_DATA {
            mavtype: mav::MavType::MAV_TYPE_SUBMARINE,
            autopilot: mav::MavAutopilot::MAV_AUTOPILOT_ARDUPILOTMEGA,
            ..Default::default()
        }),
    );
    // It asks for the IMU and pressure streams.
    stream
        .set_read_timeout(Some(Duration::from_millis(200)))
        .expect("timeout");
    let mut reader = MavlinkReader::new(stream.try_clone().expect("clone"));
    let mut asked = Vec::new();
    let start = Instant::now();
    while asked.len() < 2 && start.elapsed() < Duration::from_secs(5) {
        if let Ok((_, mav::MavMessage::COMMAND_LONG(c))) =
            reader.read_any_message::<mav::MavMessage>()
            && c.command == mav::MavCmd::MAV_CMD_SET_MESSAGE_INTERVAL
        {
            asked.push((c.param1, c.param2));
        }
    }
    assert_eq!(asked, vec![(26.0, 20_000.0), (137.0, 100_000.0)]);

    // 8 s of the vehicle at rest, 3 m deep: SCALED_IMU at 50 Hz, SCALED_PRESSURE2 at 10 Hz,
    // written in bursts of two to four messages, as a serial link or router delivers them.
    let surface_hpa = 1013.25f32;
    let deep_hpa = surface_hpa + (3.0 * 1025.0 * 9.80665 / 100.0) as f32;
    let (mut imu_got, mut depths, mut solved) = (Vec::new(), Vec::new(), Vec::new());
    let mut depth_flags = Vec::new();
    let t0 = Instant::now();
    for k in 0..400u32 {
        let boot_ms = 60_000 + 20 * k;
        send_as_autopilot(
            &mut w,
            &mav::MavMessage::SCALED_IMU(mav::SCALED_IMU_DATA {
                time_boot_ms: boot_ms,
                zacc: -1000,
                xmag: 180,
                zmag: 430,
                ..Default::default()
            }),
        );
        if k % 5 == 0 {
            send_as_autopilot(
                &mut w,
                &mav::MavMessage::SCALED_PRESSURE2(mav::SCALED_PRESSURE2_DATA {
                    time_boot_ms: boot_ms,
                    press_abs: deep_hpa,
                    temperature: 1100,
                    ..Default::default()
                }),
            );
        }
        if k % (2 + k % 3) == 0 {
            let due = t0 + Duration::from_millis(u64::from(20 * (k + 1)));
            if let Some(wait) = due.checked_duration_since(Instant::now()) {
                std::thread::sleep(wait);
            }
        }
        while let Ok(Some(x)) = imu.receive() {
            imu_got.push(x);
        }
        while let Ok(Some(x)) = depth.receive() {
            depths.push(x.depth_m);
        }
        while let Ok(Some(x)) = solutions.receive() {
            solved.push(x);
        }
        while let Ok(Some(x)) = diagnostics.receive() {
            if x.source == AidSource::Depth as u32 {
                depth_flags.push(x.flags);
            }
        }
    }
    std::thread::sleep(Duration::from_millis(300));
    while let Ok(Some(x)) = solutions.receive() {
        solved.push(x);
    }
    let status = sender.terminate(Duration::from_secs(10));
    assert!(status.is_some_and(|s| s.success()), "{status:?}");
    let _ = daemon.terminate(Duration::from_secs(10));
    let text = std::fs::read_to_string(&log).unwrap_or_default();

    // Every sample on the bus, 20 ms apart by the autopilot's clock (which the daemon
    // integrates), and on the host's clock too once the smallest delay of the link has been
    // seen: each new smallest delay shortens one step, whatever the bursts.
    assert!(
        imu_got.len() >= 390,
        "{} IMU samples\n{text}",
        imu_got.len()
    );
    let mut exact = 0;
    for pair in imu_got.windows(2) {
        assert_eq!(pair[1].device_time_ns - pair[0].device_time_ns, 20_000_000);
        let dt = pair[1].host_time_ns - pair[0].host_time_ns;
        assert!(dt > 0 && dt <= 20_000_000, "samples {pair:?}");
        exact += usize::from(dt == 20_000_000);
    }
    assert!(
        exact * 100 >= 95 * (imu_got.len() - 1),
        "{exact} of {} steps exact",
        imu_got.len()
    );
    assert_eq!(imu_got[5].specific, [0.0, 0.0, -9.80665]);
    assert!(depths.len() >= 75, "{} depths", depths.len());
    assert!(
        depths[1..].iter().all(|d| (d - 3.0).abs() < 1e-3),
        "{depths:?}"
    );
    assert!(
        text.contains("published") && text.contains("IMU samples"),
        "{text}"
    );
    // The daemon navigates on them: a solution for nearly every sample, the depths fused.
    assert!(solved.len() > 300, "{} solutions", solved.len());
    let fused = depth_flags
        .iter()
        .filter(|f| **f & AidDiagnosticsV1::FLAG_FUSED != 0)
        .count();
    assert!(fused >= 70, "{fused} of {} depths fused", depth_flags.len());
    let last = solved.last().expect("a solution");
    assert!(
        (last.height_m + 3.0).abs() < 0.3,
        "height {}",
        last.height_m
    );
}
