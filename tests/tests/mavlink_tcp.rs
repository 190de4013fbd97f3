//! `auvnav-mavlink` as a MAVLink TCP client, the way it connects to ArduPilot SITL's TCP port or a
//! router's TCP server: a server here (the `mavlink` crate's codec on a loopback socket) plays the
//! autopilot. It receives the heartbeats at their period, what it sends back (a heartbeat and a
//! status text) is read and logged, and a link the server closes is opened again.

use auvnav_tests::processes::{Proc, TempDir, binary, unique};
use mavlink::dialects::ardupilotmega as mav;
use mavlink::{MavHeader, MavlinkReader, MavlinkVersion};
use std::net::{TcpListener, TcpStream};
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

#[test]
fn a_tcp_link_carries_heartbeats_both_ways_and_is_opened_again_when_closed() {
    let tmp = TempDir::new("mavtcp");
    let exe = binary("auvnav-mavlink");
    let server = TcpListener::bind("127.0.0.1:0").expect("a free port");
    let port = server.local_addr().expect("address").port();
    let cfg = tmp.path().join("mavlink.toml");
    std::fs::write(
        &cfg,
        format!(
            "prefix = \"{}\"\naddress = \"tcpout:127.0.0.1:{port}\"\nsystem_id = 1\n\
             component_id = 197\nmessage = \"odometry\"\nrate_hz = 10.0\nheartbeat_period_s = 0.2\n",
            unique("mavtcp")
        ),
    )
    .expect("config");
    let log = tmp.path().join("mavlink.err");
    let err = std::fs::File::create(&log).expect("stderr");
    let mut sender = Proc::spawn(
        "mavlink",
        Command::new(&exe).arg("--config").arg(&cfg).stderr(err),
    )
    .expect("spawn");

    let stream = accept(&server, Duration::from_secs(10)).expect("auvnav-mavlink connects");
    // The autopilot's side: a heartbeat and a status text, as ArduSub sends them.
    let autopilot = MavHeader {
        system_id: 1,
        component_id: 1,
        sequence: 0,
    };
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
        mavlink::write_versioned_msg(&mut w, MavlinkVersion::V2, autopilot, m).expect("send");
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
