//! `auvnav bench e2e` with real processes on pseudo-terminals: every IMU frame comes back as a
//! solution, and the stage breakdown covers every solution (the IMU driver's and the daemon's
//! stage-time rows join on the read time stamp), with the stages inside one process in their
//! order. Timing figures are not asserted (benchmarks measure them; machines here are noisy).

use auvnav_tests::processes::{Proc, TempDir, binary};
use serde_json::Value;
use std::process::{Command, Stdio};
use std::time::Duration;

#[test]
fn every_solution_has_its_stage_times_in_order() {
    let dir = TempDir::new("e2estages");
    let out = dir.path().join("e2e.json");
    let mut bench = Proc::spawn(
        "auvnav bench e2e",
        Command::new(binary("auvnav"))
            .args(["bench", "e2e", "--seconds", "2", "--json"])
            .stdout(std::fs::File::create(&out).expect("output file"))
            .stderr(Stdio::inherit()),
    )
    .expect("spawn");
    // Watchdog: two rates of 2 s plus start-up take about 8 s.
    let status = bench
        .wait_for(Duration::from_secs(120))
        .expect("auvnav bench e2e did not finish within 120 s");
    assert!(status.success(), "auvnav bench e2e failed: {status}");
    let v: Value =
        serde_json::from_str(&std::fs::read_to_string(&out).expect("read")).expect("JSON");
    let rows = v["rows"].as_array().expect("rows");
    assert_eq!(rows.len(), 2);
    for r in rows {
        let rate = r["imu_rate_hz"].as_f64().expect("rate");
        let written = r["imu_frames_written"].as_u64().expect("written");
        let received = r["solutions_received"].as_u64().expect("received");
        assert_eq!(received, written, "{rate} Hz: solutions lost");
        assert_eq!(
            r["solutions_with_stages"].as_u64(),
            Some(received),
            "{rate} Hz: solutions without stage times"
        );
        let stages = r["stages_us"].as_array().expect("stages");
        let names: Vec<&str> = stages
            .iter()
            .map(|s| s["stage"].as_str().expect("name"))
            .collect();
        assert_eq!(
            names,
            [
                "pty",
                "decode",
                "publish",
                "wake_up",
                "drain",
                "navigate",
                "publish_solution",
                "solution_hop"
            ]
        );
        for s in stages {
            let name = s["stage"].as_str().expect("name");
            let (p50, p99, max) = (
                s["p50"].as_f64().expect("p50"),
                s["p99"].as_f64().expect("p99"),
                s["max"].as_f64().expect("max"),
            );
            assert!(p50 <= p99 && p99 <= max, "{rate} Hz {name}: {s}");
            // Stages within one process are differences of one clock read in order: never
            // negative. (Across processes a stage may be: the reader can be awake before the
            // writer's call returns.)
            if ["decode", "publish", "drain", "navigate", "publish_solution"].contains(&name) {
                assert!(p50 >= 0.0, "{rate} Hz {name}: {s}");
            }
        }
    }
}
