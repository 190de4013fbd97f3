//! `auvnav-mavlink` as a real process, received by a real MAVLink client: pymavlink (PyPI),
//! listening on loopback UDP, decodes every message. This test publishes the daemon's solutions
//! (aligning, navigating along a known track, degraded with the DVL lost, then a filter restart)
//! and checks the rate, the values against the solutions, the origin, the heartbeat and the
//! status texts.

use auvnav_core::earth::{self, Geodetic};
use auvnav_shm_schema::bus::Bus;
use auvnav_shm_schema::{NavMode, NavSolutionV1, qos, topic};
use auvnav_tests::processes::{Proc, TempDir, binary, python_modules_or_skip, unique};
use nalgebra::{UnitQuaternion, Vector3};
use std::io::BufRead;
use std::path::Path;
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

fn origin() -> Geodetic {
    Geodetic {
        latitude_rad: 31f64.to_radians(),
        longitude_rad: 120f64.to_radians(),
        height_m: -10.0,
    }
}

/// The solution at `t` s: 1.5 m/s east (heading east) from 1 s on, `mode` as given.
fn solution(t: f64, mode: NavMode, health: u32) -> NavSolutionV1 {
    let east = 1.5 * (t - 1.0).max(0.0);
    let p = earth::offset_position(&origin(), &Vector3::new(0.0, east, 0.0));
    let q = UnitQuaternion::from_euler_angles(0.0, 0.0, std::f64::consts::FRAC_PI_2);
    NavSolutionV1 {
        host_time_ns: 5_000_000_000 + (t * 1e9) as u64,
        latitude_rad: p.latitude_rad,
        longitude_rad: p.longitude_rad,
        height_m: p.height_m,
        velocity_ned_m_s: [0.0, 1.5, 0.0],
        quaternion_body_to_ned: [q.w, q.i, q.j, q.k],
        euler_rad: [0.0, 0.0, std::f64::consts::FRAC_PI_2],
        position_std_ned_m: [1.0, 2.0, 0.1],
        velocity_std_ned_m_s: [0.02, 0.02, 0.01],
        attitude_std_rad: [0.001, 0.001, 0.003],
        mode: mode as u32,
        sensor_health: health,
        ..Default::default()
    }
}

#[test]
// Long on purpose: one scenario with real processes read top to bottom: each step depends on the
// state the previous one left.
fn pymavlink_receives_odometry_origin_heartbeat_and_status_from_auvnav_mavlink() {
    if !python_modules_or_skip("pymavlink", "pymavlink") {
        return;
    }
    let tmp = TempDir::new("mavlink");
    // Built (if need be) before the listener's clock starts.
    let exe = binary("auvnav-mavlink");
    let port = std::net::UdpSocket::bind("127.0.0.1:0")
        .and_then(|s| s.local_addr())
        .expect("a free port")
        .port();
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("python/mavlink_listener.py");
    let mut listener = Command::new("python3")
        .arg(&script)
        .arg(port.to_string())
        .arg("9")
        .stdout(Stdio::piped())
        .spawn()
        .expect("python3");
    let mut lines = std::io::BufReader::new(listener.stdout.take().expect("stdout")).lines();
    assert_eq!(lines.next().and_then(Result::ok).as_deref(), Some("ready"));

    let prefix = unique("mav");
    let cfg = tmp.path().join("mavlink.toml");
    std::fs::write(
        &cfg,
        format!(
            "prefix = \"{prefix}\"\naddress = \"udpout:127.0.0.1:{port}\"\nsystem_id = 1\n\
             component_id = 197\nmessage = \"odometry\"\nrate_hz = 10.0\nheartbeat_period_s = 1.0\n"
        ),
    )
    .expect("config");
    let bus = Bus::new(&unique("mavtest"), &prefix).expect("bus");
    let mut publisher = bus
        .publisher::<NavSolutionV1>(topic::NAV_SOLUTION, qos::NAVIGATION)
        .expect("publisher");
    let err = std::fs::File::create(tmp.path().join("mavlink.err")).expect("stderr");
    let mut sender = Proc::spawn(
        "mavlink",
        Command::new(&exe).arg("--config").arg(&cfg).stderr(err),
    )
    .expect("spawn");
    // The link holds positions for 2 s after it opens, for an autopilot to say its origin (none
    // answers here): the solutions start after that.
    std::thread::sleep(Duration::from_millis(2300));

    // 4 s of solutions at 100 Hz, in real time: aligning 0-1 s, navigating 1-2.5 s, degraded
    // without the DVL 2.5-3.5 s, invalid (a filter restart) from 3.5 s.
    let all = NavSolutionV1::HEALTH_IMU | NavSolutionV1::HEALTH_DVL | NavSolutionV1::HEALTH_DEPTH;
    let start = Instant::now();
    let mut published = Vec::new();
    for k in 0..400 {
        let t = k as f64 * 0.01;
        let (mode, health) = match t {
            t if t < 1.0 => (NavMode::Aligning, all),
            t if t < 2.5 => (NavMode::Navigating, all),
            t if t < 3.5 => (NavMode::Degraded, all & !NavSolutionV1::HEALTH_DVL),
            _ => (NavMode::Invalid, all & !NavSolutionV1::HEALTH_DVL),
        };
        let s = solution(t, mode, health);
        publisher.publish(s).expect("publish");
        published.push(s);
        let due = start + Duration::from_secs_f64(t + 0.01);
        if let Some(wait) = due.checked_duration_since(Instant::now()) {
            std::thread::sleep(wait);
        }
    }
    std::thread::sleep(Duration::from_millis(300));
    let status = sender.terminate(Duration::from_secs(10));
    assert!(status.is_some_and(|s| s.success()), "{status:?}");
    let json = lines
        .next()
        .and_then(Result::ok)
        .expect("the listener's report");
    let _ = listener.wait();
    let v: serde_json::Value = serde_json::from_str(&json).expect("json");
    let log = std::fs::read_to_string(tmp.path().join("mavlink.err")).unwrap_or_default();

    assert_eq!(v["bad"], 0, "{}", v["counts"]);
    assert_eq!(v["sources"], serde_json::json!([[1, 197]]), "{v}");
    // Aligned for 3 s at 10 Hz: ODOMETRY only once aligned, about 30 of them.
    let odometry = v["odometry"].as_array().expect("odometry");
    assert!(
        (26..=32).contains(&odometry.len()),
        "{} ODOMETRY\n{log}",
        odometry.len()
    );
    let rx: Vec<f64> = odometry
        .iter()
        .map(|o| o["rx"].as_f64().expect("rx"))
        .collect();
    let rate = (rx.len() - 1) as f64 / (rx[rx.len() - 1] - rx[0]);
    assert!((8.0..=12.0).contains(&rate), "{rate} Hz");
    for o in odometry {
        assert_eq!(
            (o["frame_id"].as_u64(), o["child_frame_id"].as_u64()),
            (Some(20), Some(12))
        );
        // The solution this message came from, by its time stamp.
        let us = o["time_usec"].as_u64().expect("time");
        let s = published
            .iter()
            .find(|s| s.host_time_ns / 1000 == us)
            .expect("a published solution");
        let origin_lat = v["origins"][0]["latitude"].as_f64().expect("origin") * 1e-7;
        let origin_lon = v["origins"][0]["longitude"].as_f64().expect("origin") * 1e-7;
        let o_geo = Geodetic {
            latitude_rad: origin_lat.to_radians(),
            longitude_rad: origin_lon.to_radians(),
            height_m: v["origins"][0]["altitude"].as_f64().expect("alt") * 1e-3,
        };
        let here = Geodetic {
            latitude_rad: s.latitude_rad,
            longitude_rad: s.longitude_rad,
            height_m: s.height_m,
        };
        let ned = earth::ned_offset(&o_geo, &here);
        assert!((o["x"].as_f64().expect("x") - ned.x).abs() < 0.05, "{o}");
        assert!((o["y"].as_f64().expect("y") - ned.y).abs() < 0.05, "{o}");
        // Heading east at 1.5 m/s: forward in the body frame.
        assert!((o["vx"].as_f64().expect("vx") - 1.5).abs() < 1e-4, "{o}");
        assert!(o["vy"].as_f64().expect("vy").abs() < 1e-4, "{o}");
        assert!((o["pose_covariance"][0].as_f64().expect("cov") - 1.0).abs() < 1e-6);
        assert!((o["pose_covariance"][6].as_f64().expect("cov") - 4.0).abs() < 1e-6);
        let expected_quality = match NavMode::try_from(s.mode) {
            Ok(NavMode::Navigating) => 100,
            Ok(NavMode::Degraded) => 50,
            _ => -1,
        };
        assert_eq!(o["quality"].as_i64(), Some(expected_quality), "{o}");
        let expected_reset = u64::from(s.mode == NavMode::Invalid as u32);
        assert_eq!(o["reset_counter"].as_u64(), Some(expected_reset), "{o}");
    }
    // The origin is the first aligned solution the sender saw (the track starts at 1 s; it
    // polls at 40 Hz, so within 4 cm, 4e-7 deg of longitude, of the start).
    let origin0 = &v["origins"][0];
    assert_eq!(origin0["latitude"].as_i64(), Some(310_000_000), "{origin0}");
    let lon = origin0["longitude"].as_i64().expect("longitude");
    assert!((0..=5).contains(&(lon - 1_200_000_000)), "{origin0}");
    assert_eq!(origin0["altitude"].as_i64(), Some(-10_000), "{v}");
    assert_eq!(origin0["target_system"].as_u64(), Some(1));
    let texts: Vec<&str> = v["status"]
        .as_array()
        .expect("status")
        .iter()
        .map(|s| s["text"].as_str().expect("text"))
        .collect();
    assert_eq!(
        texts,
        vec![
            "auvnav: aligning",
            "auvnav: navigating",
            "auvnav: degraded, DVL lost",
            "auvnav: invalid, restarting"
        ],
        "{v}"
    );
    let heartbeats = v["heartbeats"].as_array().expect("heartbeats");
    // One a second over the 6.6 s the link runs (2.3 s before the solutions, 4 s of them, 0.3 s).
    assert!((5..=8).contains(&heartbeats.len()), "{v}");
    assert!(
        heartbeats
            .iter()
            .all(|h| h["type"] == 18 && h["autopilot"] == 8)
    );
}
