//! `auvnav-bridge` with `[ros2]`, received as a ROS 2 graph would: a Zenoh client (the
//! `eclipse-zenoh` Python package) subscribing with rmw_zenoh's key expressions, decoding every
//! payload with a third-party ROS 2 CDR decoder (`rosbags`), comparing the type hashes in the
//! keys with rosbags' own, and reading the liveliness tokens. This test publishes the daemon's
//! solutions, IMU samples, DVL velocities and a driver's health on the bus.

use auvnav_shm_schema::bus::Bus;
use auvnav_shm_schema::{
    DvlVelocityV1, ImuSampleV1, NavMode, NavSolutionV1, ProcessHealthV1, ProcessState, qos, topic,
};
use auvnav_tests::processes::{Proc, TempDir, binary, python_modules_or_skip, unique};
use std::io::BufRead;
use std::path::Path;
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

fn monotonic_ns() -> u64 {
    auvnav_shm_schema::clock::monotonic_ns()
}

#[test]
// Long on purpose: one scenario with real processes read top to bottom: each step depends on the
// state the previous one left.
fn a_ros_2_client_decodes_the_bridge_topics_with_rmw_zenoh_keys_tokens_and_hashes() {
    if !python_modules_or_skip("zenoh, rosbags", "eclipse-zenoh rosbags") {
        return;
    }
    let tmp = TempDir::new("ros2");
    let exe = binary("auvnav-bridge");
    let port = std::net::TcpListener::bind("127.0.0.1:0")
        .and_then(|s| s.local_addr())
        .expect("a free port")
        .port();
    let prefix = unique("ros");
    let cfg = tmp.path().join("bridge.toml");
    std::fs::write(
        &cfg,
        format!(
            "prefix = \"{prefix}\"\nname = \"bridge\"\nhealth_period_s = 0.2\n\
             [zenoh]\nlisten = [\"tcp/127.0.0.1:{port}\"]\n\
             [ros2]\ndomain_id = 0\nnamespace = \"/auvnav\"\nsolution_rate_hz = 20.0\n"
        ),
    )
    .expect("config");
    let bus = Bus::new(&unique("rostest"), &prefix).expect("bus");
    let mut nav = bus
        .publisher::<NavSolutionV1>(topic::NAV_SOLUTION, qos::NAVIGATION)
        .expect("nav");
    let mut imu = bus
        .publisher::<ImuSampleV1>(topic::IMU, qos::SENSOR)
        .expect("imu");
    let mut dvl = bus
        .publisher::<DvlVelocityV1>(topic::DVL, qos::SENSOR)
        .expect("dvl");
    let mut health = bus
        .publisher::<ProcessHealthV1>(topic::HEALTH, qos::HEALTH)
        .expect("health");
    let err = std::fs::File::create(tmp.path().join("bridge.err")).expect("stderr");
    let mut bridge = Proc::spawn(
        "bridge",
        Command::new(&exe).arg("--config").arg(&cfg).stderr(err),
    )
    .expect("spawn");
    std::thread::sleep(Duration::from_millis(500));
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("python/ros2_listener.py");
    let mut listener = Command::new("python3")
        .arg(&script)
        .arg(format!("tcp/127.0.0.1:{port}"))
        .arg("4")
        .stdout(Stdio::piped())
        .spawn()
        .expect("python3");
    let mut lines = std::io::BufReader::new(listener.stdout.take().expect("stdout")).lines();
    assert_eq!(lines.next().and_then(Result::ok).as_deref(), Some("ready"));
    std::thread::sleep(Duration::from_millis(500));

    // 2 s at 100 Hz: the vehicle heads east at 1.5 m/s, level; aligning for the first 0.5 s.
    let origin = (31f64.to_radians(), 120f64.to_radians(), -10.0);
    let (sin45, cos45) = (
        std::f64::consts::FRAC_PI_4.sin(),
        std::f64::consts::FRAC_PI_4.cos(),
    );
    let start = Instant::now();
    for k in 0..200 {
        let t = k as f64 * 0.01;
        let east = 1.5 * t;
        // Small-distance east offset (the bridge's own conversion is checked against it).
        let lon = origin.1 + east / (6_378_137.0 * origin.0.cos());
        let now = monotonic_ns();
        nav.publish(NavSolutionV1 {
            host_time_ns: now,
            latitude_rad: origin.0,
            longitude_rad: lon,
            height_m: origin.2,
            velocity_ned_m_s: [0.0, 1.5, 0.0],
            // Yaw 90 deg (east): w = cos 45, z = sin 45.
            quaternion_body_to_ned: [cos45, 0.0, 0.0, sin45],
            position_std_ned_m: [1.0, 2.0, 0.1],
            velocity_std_ned_m_s: [0.02, 0.03, 0.01],
            attitude_std_rad: [0.001, 0.002, 0.003],
            mode: if t < 0.5 {
                NavMode::Aligning as u32
            } else {
                NavMode::Navigating as u32
            },
            ..Default::default()
        })
        .expect("publish");
        imu.publish(ImuSampleV1 {
            host_time_ns: now,
            angular: [0.01, 0.02, 0.03],
            specific: [0.1, 0.2, -9.8],
            interval_s: 0.01,
            status: ImuSampleV1::STATUS_GYRO_VALID | ImuSampleV1::STATUS_ACCEL_VALID,
            ..Default::default()
        })
        .expect("publish");
        if k % 10 == 0 {
            dvl.publish(DvlVelocityV1 {
                host_time_ns: now,
                validity_time_ns: now,
                velocity_dvl_m_s: [1.5, 0.1, 0.05],
                velocity_std_m_s: [0.01, 0.01, 0.02],
                validity: DvlVelocityV1::VALID_VELOCITY | DvlVelocityV1::VALID_STD,
                ..Default::default()
            })
            .expect("publish");
        }
        if k % 50 == 0 {
            let mut h = ProcessHealthV1 {
                host_time_ns: now,
                frames: 42,
                checksum_errors: 3,
                state: ProcessState::Reconnecting as u32,
                ..Default::default()
            };
            h.set_name("dvl");
            health.publish(h).expect("publish");
        }
        let due = start + Duration::from_secs_f64(t + 0.01);
        if let Some(w) = due.checked_duration_since(Instant::now()) {
            std::thread::sleep(w);
        }
    }
    let json = lines
        .next()
        .and_then(Result::ok)
        .expect("the listener's report");
    let _ = listener.wait();
    let status = bridge.terminate(Duration::from_secs(10));
    assert!(status.is_some_and(|s| s.success()), "{status:?}");
    let v: serde_json::Value = serde_json::from_str(&json).expect("json");
    assert_eq!(v["errors"], serde_json::json!([]), "{}", v["errors"]);
    let topics = &v["topics"];
    for (name, ty) in [
        ("/auvnav/odometry", "nav_msgs/msg/Odometry"),
        ("/auvnav/fix", "sensor_msgs/msg/NavSatFix"),
        ("/auvnav/imu/data_raw", "sensor_msgs/msg/Imu"),
        (
            "/auvnav/dvl/twist",
            "geometry_msgs/msg/TwistWithCovarianceStamped",
        ),
        ("/diagnostics", "diagnostic_msgs/msg/DiagnosticArray"),
    ] {
        let t = &topics[name];
        assert_eq!(t["type"], ty, "{name}: {t}");
        // The hash in the key expression is the one rosbags computes from the type.
        assert_eq!(t["key_hash"], t["rosbags_hash"], "{name}");
        assert!(t["count"].as_u64().unwrap_or(0) > 0, "{name}: {t}");
        let a = &t["attachments"][0];
        assert_eq!(a["trailing"], 0, "{name}: {a}");
        assert!(
            a["sequence_number"].as_i64().unwrap_or(0) >= 1,
            "{name}: {a}"
        );
        assert!(a["source_timestamp"].as_i64().unwrap_or(0) > 1_700_000_000_000_000_000);
    }
    // Odometry: only once aligned (1.5 s at 20 Hz), map -> base_link, ENU/FLU.
    let odo = &topics["/auvnav/odometry"];
    let n = odo["count"].as_u64().expect("count");
    assert!((25..=32).contains(&n), "{n} odometry messages");
    let last = &odo["last"];
    assert_eq!(last["header"]["frame_id"], "map");
    assert_eq!(last["child_frame_id"], "base_link");
    let x = last["pose"]["pose"]["position"]["x"].as_f64().expect("x");
    let y = last["pose"]["pose"]["position"]["y"].as_f64().expect("y");
    assert!((x - 1.5 * 1.5).abs() < 0.1, "east {x}");
    assert!(y.abs() < 1e-6, "north {y}");
    // Heading east is yaw 0 in ENU: the identity quaternion.
    let q = &last["pose"]["pose"]["orientation"];
    assert!(
        (q["w"].as_f64().expect("w").abs() - 1.0).abs() < 1e-9,
        "{q}"
    );
    let twist = &last["twist"]["twist"]["linear"];
    assert!(
        (twist["x"].as_f64().expect("x") - 1.5).abs() < 1e-9,
        "{twist}"
    );
    assert!(twist["y"].as_f64().expect("y").abs() < 1e-9, "{twist}");
    let cov = last["pose"]["covariance"].as_array().expect("covariance");
    assert_eq!(cov[0].as_f64(), Some(4.0), "east variance");
    assert_eq!(cov[7].as_f64(), Some(1.0), "north variance");
    // The time stamp is UTC.
    let sec = last["header"]["stamp"]["sec"].as_i64().expect("sec");
    assert!(sec > 1_700_000_000, "{sec}");
    // NavSatFix: no fix while aligning, a fix once aligned.
    let fix = &topics["/auvnav/fix"];
    assert_eq!(fix["first"]["status"]["status"], -1, "{}", fix["first"]);
    assert_eq!(fix["last"]["status"]["status"], 0);
    assert!((fix["last"]["latitude"].as_f64().expect("lat") - 31.0).abs() < 1e-9);
    assert_eq!(fix["last"]["position_covariance_type"], 2);
    // IMU and DVL: FRD -> FLU.
    let imu = &topics["/auvnav/imu/data_raw"]["last"];
    assert_eq!(imu["header"]["frame_id"], "imu_link");
    assert_eq!(imu["orientation_covariance"][0].as_f64(), Some(-1.0));
    assert_eq!(imu["angular_velocity"]["y"].as_f64(), Some(-0.02));
    assert_eq!(imu["linear_acceleration"]["z"].as_f64(), Some(9.8));
    assert!(
        topics["/auvnav/imu/data_raw"]["count"]
            .as_u64()
            .unwrap_or(0)
            >= 150
    );
    let d = &topics["/auvnav/dvl/twist"]["last"];
    assert_eq!(d["twist"]["twist"]["linear"]["y"].as_f64(), Some(-0.1));
    assert_eq!(d["twist"]["twist"]["linear"]["z"].as_f64(), Some(-0.05));
    // Diagnostics: the DVL driver reconnecting is a warning with its counters.
    let diag = &topics["/diagnostics"];
    let dvl_status = diag["diagnostics"]
        .as_array()
        .expect("statuses")
        .iter()
        .find(|s| s["name"] == "auvnav: dvl")
        .cloned();
    let dvl_status = dvl_status.expect("the DVL driver's status");
    assert_eq!(dvl_status["level"], 1, "{dvl_status}");
    assert_eq!(dvl_status["message"], "reconnecting");
    assert!(
        dvl_status["values"]
            .as_array()
            .expect("values")
            .iter()
            .any(|kv| kv["key"] == "checksum_errors" && kv["value"] == "3"),
        "{dvl_status}"
    );
    // Liveliness: the node and its five publishers, in rmw_zenoh's format.
    let tokens: Vec<&str> = v["tokens"]
        .as_array()
        .expect("tokens")
        .iter()
        .filter_map(|t| t.as_str())
        .collect();
    assert!(
        tokens
            .iter()
            .any(|t| t.starts_with("@ros2_lv/0/") && t.ends_with("/NN/%/%auvnav/auvnav_bridge")),
        "{tokens:?}"
    );
    let publishers: Vec<&&str> = tokens.iter().filter(|t| t.contains("/MP/")).collect();
    assert_eq!(publishers.len(), 5, "{tokens:?}");
    for p in publishers {
        let parts: Vec<&str> = p.split('/').collect();
        assert_eq!(parts.len(), 13, "{p}");
        assert!(parts[11].starts_with("RIHS01_"), "{p}");
        assert_eq!(parts[12], ":2:,10:,:,:,,", "{p}");
    }
}
