//! `auvnav import tlog` on a telemetry log written by pymavlink (PyPI), an encoder and a tlog
//! writer independent of the one the import's unit tests use: every reading the script wrote is
//! imported (the damaged frame counted), `auvnav info` lists the channels, `auvnav replay`
//! navigates on the autopilot's IMU with the depth from its pressure sensor, and `auvnav calibrate
//! dvl` takes the DVL extension's velocities.

use auvnav_tests::processes::{TempDir, auvnav_json, python_modules_or_skip};
use std::process::Command;

#[test]
fn a_pymavlink_telemetry_log_is_imported_and_replayed() {
    if !python_modules_or_skip("pymavlink", "pymavlink") {
        return;
    }
    let tmp = TempDir::new("tlog");
    let tlog = tmp.path().join("dive.tlog");
    let script = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("python/write_tlog.py");
    let o = Command::new("python3")
        .arg(&script)
        .arg(&tlog)
        .arg("60")
        .output()
        .expect("python3");
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let wrote: serde_json::Value = serde_json::from_slice(&o.stdout).expect("the script's counts");

    let log = tmp.path().join("dive.mcap");
    let (tlog_s, log_s) = (tlog.display().to_string(), log.display().to_string());
    let s = auvnav_json(&["import", "tlog", &tlog_s, "--out", &log_s, "--json"]);
    assert_eq!(s["imu"], wrote["imu"], "{s}");
    assert_eq!(s["magnetometer"], wrote["imu"]);
    assert_eq!(s["depth"], wrote["pressure"]);
    assert_eq!(s["attitude"], wrote["attitude"]);
    assert_eq!(s["gnss"], wrote["gps"]);
    assert_eq!(s["dvl"], wrote["dvl"]);
    assert_eq!(s["bad_checksum"], wrote["damaged"]);
    assert_eq!(
        (s["bytes_skipped"].as_u64(), s["unknown"].as_u64()),
        (Some(0), Some(0))
    );
    assert_eq!(s["imu_source"], "SCALED_IMU");
    assert_eq!(s["autopilot_boots"], 1);

    let info = auvnav_json(&["info", &log_s, "--json"]);
    let text = info.to_string();
    for topic in ["imu", "magnetometer", "depth", "attitude", "gnss", "dvl"] {
        assert!(text.contains(&format!("\"{topic}\"")), "{topic} in {text}");
    }

    // The vehicle runs 5 m deep at 0.5 m/s on 30°: the depth from the pressure holds the height
    // at -5 m.
    let config = tmp.path().join("initial.toml");
    std::fs::write(
        &config,
        "[initial]\nlatitude_deg = 47.5\nlongitude_deg = -122.3\nheight_m = -5.0\n\
         velocity_ned_m_s = [0.4330127, 0.25, 0.0]\neuler_deg = [0.0, 0.0, 30.0]\n",
    )
    .expect("configuration");
    let out = tmp.path().join("solution.csv");
    let r = auvnav_json(&[
        "replay",
        &log_s,
        "--config",
        &config.display().to_string(),
        "--out",
        &out.display().to_string(),
        "--json",
    ]);
    assert_eq!(r["samples_processed"], wrote["imu"], "{r}");
    let csv = std::fs::read_to_string(&out).expect("solutions");
    let header: Vec<&str> = csv.lines().next().expect("header").split(',').collect();
    let h = header
        .iter()
        .position(|c| *c == "height_m")
        .expect("height");
    let last: Vec<f64> = csv
        .lines()
        .last()
        .expect("a solution")
        .split(',')
        .map(|v| v.parse().unwrap_or(f64::NAN))
        .collect();
    assert!((last[h] + 5.0).abs() < 0.1, "height {}", last[h]);

    // The DVL extension's velocities against the GPS fixes of the 30 m track: a calibration.
    let c = auvnav_json(&[
        "calibrate",
        "dvl",
        &log_s,
        "--config",
        &config.display().to_string(),
        "--threshold",
        "20",
        "--json",
    ]);
    let voyage = &c["voyages"][0];
    assert_eq!(voyage["fixes"], wrote["gps"], "{c}");
    assert!(voyage["dvl_fused_after"].as_u64() > Some(200), "{c}");
    assert!(voyage["distance_m"].as_f64() > Some(25.0), "{c}");
}
