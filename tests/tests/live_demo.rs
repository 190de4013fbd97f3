//! The on-board chain as real processes (`auvnav demo`): emulated devices on pseudo-terminals,
//! the drivers, the daemon and the recorder; the live solution is accurate, every process stops
//! cleanly on SIGTERM, and replaying the recording reproduces the live solution byte for byte.

use auvnav_tests::processes::{TempDir, binary};
use std::process::Command;

/// Each test runs the whole chain on both cores: one at a time, so that each measures the chain
/// and not the other tests.
static ONE_AT_A_TIME: std::sync::Mutex<()> = std::sync::Mutex::new(());

/// Runs `auvnav demo ARGS --json --out OUT` and returns its JSON document (the run must succeed).
fn demo(args: &[&str], out: &std::path::Path) -> serde_json::Value {
    let o = Command::new(binary("auvnav"))
        .arg("demo")
        .args(args)
        .args(["--json", "--out"])
        .arg(out)
        .output()
        .expect("auvnav demo");
    let stdout = String::from_utf8_lossy(&o.stdout);
    assert!(
        o.status.success(),
        "{stdout}\n{}",
        String::from_utf8_lossy(&o.stderr)
    );
    serde_json::from_str(&stdout).expect("json")
}

#[test]
fn live_demo_reproduces_bit_for_bit_from_its_recording() {
    let _one = ONE_AT_A_TIME.lock().unwrap_or_else(|e| e.into_inner());
    let dir = TempDir::new("livedemo");
    let out = dir.path().join("run");
    let args = [
        "--scenario",
        "lawnmower",
        "--start",
        "known",
        "--seconds",
        "30",
        "--speed",
        "4",
    ];
    let v = demo(&args, &out);
    assert_eq!(v["replay_identical"], true, "{v}");
    assert_eq!(v["clean_stop"], true, "{v}");
    // 30 s of a 200 Hz IMU: one solution per sample (the first is the initial state).
    assert_eq!(v["solutions"], 6000, "{v}");
    let acc = &v["accuracy"];
    let travelled = acc["distance_travelled_m"].as_f64().expect("distance");
    let final_err = acc["horizontal_error_final_m"].as_f64().expect("error");
    assert!(travelled > 50.0 && final_err < 0.01 * travelled, "{v}");
    // The files the demo names, compared here as well.
    let live = std::fs::read(out.join("live_nav.csv")).expect("live_nav.csv");
    let replayed = std::fs::read(out.join("replay_nav.csv")).expect("replay_nav.csv");
    assert!(live.len() > 1000);
    assert_eq!(live, replayed);
    // The recording has the sensors, the daemon's outputs and its configuration.
    let r = replay_json(&out.join("record.mcap"));
    assert!(
        r["configuration"]
            .as_str()
            .unwrap_or_default()
            .contains("log header"),
        "{r}"
    );
    assert_eq!(r["counts"]["imu"], 6000, "{r}");
    assert_eq!(r["navigator"]["imu_out_of_order"], 0, "{r}");
}

#[test]
fn live_daemon_fuses_usbl_fixes_from_a_seatrac_on_a_pseudo_terminal() {
    let _one = ONE_AT_A_TIME.lock().unwrap_or_else(|e| e.into_inner());
    // The docking scenario has a station: the emulated SeaTrac reports range and angles, the
    // USBL driver publishes them, the daemon fuses them (tight: range differences from the angles
    // through the baseline) and the replay of the recording does the same.
    let dir = TempDir::new("livedock");
    let out = dir.path().join("run");
    let args = [
        "--scenario",
        "docking",
        "--start",
        "known",
        "--seconds",
        "30",
        "--speed",
        "4",
    ];
    let v = demo(&args, &out);
    assert_eq!(v["replay_identical"], true, "{v}");
    let daemon = v["process_reports"]
        .as_array()
        .and_then(|a| a.iter().find(|p| p[0] == "auvnavd"))
        .and_then(|p| p[1].as_str())
        .expect("daemon report")
        .to_owned();
    let fused: u64 = daemon
        .split("USBL fixes: ")
        .nth(1)
        .and_then(|s| s.split(' ').next())
        .and_then(|n| n.parse().ok())
        .unwrap_or_else(|| panic!("no USBL count in {daemon:?}"));
    // One fix per second for 30 s (the first may precede the daemon's first IMU sample).
    assert!(fused >= 28, "{daemon}");
    let r = replay_json(&out.join("record.mcap"));
    assert_eq!(r["navigator"]["usbl_fused"], fused, "{r}");
    assert_eq!(r["navigator"]["usbl_invalid"], 0, "{r}");
}

/// An LBL survey as real processes: the emulated SeaTrac ranges the scenario's three seabed
/// beacons (`auvnav emulate --lbl-beacons`), `auvnav-usbl` publishes each ping response as a
/// range (`range_beacons`), the daemon fuses them one by one (`[navigation.ranges]`), the recorder
/// keeps them, and the replay of the recording fuses the same ranges to the same solution.
#[test]
fn live_daemon_fuses_lbl_ranges_from_a_seatrac_ranging_seabed_beacons() {
    let _one = ONE_AT_A_TIME.lock().unwrap_or_else(|e| e.into_inner());
    let dir = TempDir::new("livelbl");
    let out = dir.path().join("run");
    let args = [
        "--scenario",
        "ranges_lbl",
        "--start",
        "known",
        "--seconds",
        "30",
        // In real time: the daemon's clock is the host's, and sound takes its physical time.
        "--speed",
        "1",
    ];
    let v = demo(&args, &out);
    assert_eq!(v["replay_identical"], true, "{v}");
    assert_eq!(v["clean_stop"], true, "{v}");
    let r = replay_json(&out.join("record.mcap"));
    // One ping a second to three beacons: a range message per beacon and ping (the first pings
    // may precede the daemon's first IMU sample), 5 % of them multipath outliers the gate takes
    // out.
    let recorded = r["counts"]["acoustic_ranges"]
        .as_u64()
        .expect("ranges counted");
    assert!(recorded >= 84, "{r}");
    let n = &r["navigator"];
    let fused = n["ranges_fused"].as_u64().expect("fused");
    assert!(fused >= 78, "{r}");
    assert_eq!(n["ranges_reopened"], 0, "{r}");
    assert_eq!(n["ranges_invalid"], 0, "{r}");
    let acc = &v["accuracy"];
    assert!(
        acc["horizontal_error_final_m"].as_f64().expect("error") < 0.5,
        "{v}"
    );
}

/// `auvnav demo --gnss`: a u-blox receiver emulated on a pseudo-terminal, `auvnav-gnss` gating
/// its fixes on the depth from `auvnav-can`; the surface fixes reach the daemon and the
/// recording, the replay reproduces the live solution, and `auvnav calibrate dvl` runs on the
/// recording with its GNSS fixes (the daemon's configuration taken from the recording's header).
#[test]
fn live_demo_with_a_gnss_receiver_records_the_surface_fixes_for_calibration() {
    let _one = ONE_AT_A_TIME.lock().unwrap_or_else(|e| e.into_inner());
    let dir = TempDir::new("livegnss");
    let out = dir.path().join("run");
    let args = [
        "--gnss",
        "ubx",
        "--start",
        "known",
        "--seconds",
        "80",
        "--speed",
        "8",
    ];
    let v = demo(&args, &out);
    assert_eq!(v["scenario"], "dive", "{v}");
    assert_eq!(v["gnss"], "ubx", "{v}");
    assert_eq!(v["replay_identical"], true, "{v}");
    assert_eq!(v["clean_stop"], true, "{v}");
    let simulated = v["gnss_fixes_simulated"].as_u64().expect("simulated");
    let recorded = v["gnss_fixes_recorded"].as_u64().expect("recorded");
    // 60 s at the surface and the start of the dive, one fix per second; the first may come
    // before the depth sensor's first reading, which the driver waits for.
    assert!(simulated >= 60, "{v}");
    assert!(recorded + 2 >= simulated && recorded <= simulated, "{v}");
    let r = replay_json(&out.join("record.mcap"));
    let fused = r["navigator"]["gnss_fused"].as_u64().expect("gnss_fused");
    assert!(fused + 3 >= recorded, "{r}");
    let o = Command::new(binary("auvnav"))
        .args(["calibrate", "dvl"])
        .arg(out.join("record.mcap"))
        .args(["--threshold", "40", "--json"])
        .output()
        .expect("calibrate");
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let c: serde_json::Value = serde_json::from_slice(&o.stdout).expect("json");
    let voyage = &c["voyages"][0];
    assert_eq!(
        voyage["start"], "the configuration's [initial] state",
        "{voyage}"
    );
    assert!(
        voyage["fixes"].as_u64().expect("fixes") + 3 >= recorded,
        "{voyage}"
    );
}

/// The README's first command (`auvnav demo`, seed 1): alignment from no heading, then USBL
/// homing with multipath outliers, as real processes; the figures meet their targets and the
/// replay of the recording reproduces the live solution byte for byte.
#[test]
fn the_readme_demo_aligns_in_motion_then_homes_on_usbl_and_reproduces() {
    let _one = ONE_AT_A_TIME.lock().unwrap_or_else(|e| e.into_inner());
    let dir = TempDir::new("readmedemo");
    let out = dir.path().join("run");
    let v = demo(&[], &out);
    assert_eq!(v["scenario"], "homing", "{v}");
    assert_eq!(v["start"], "align", "{v}");
    assert_eq!(v["replay_identical"], true, "{v}");
    assert_eq!(v["clean_stop"], true, "{v}");
    assert_eq!(v["imu_samples_complete"], true, "{v}");
    let al = &v["phases"]["alignment"];
    let aligned = al["aligned_after_s"].as_f64().expect("aligned");
    assert!(aligned > 60.0 && aligned < 298.0, "{al}");
    let heading = al["heading_error_at_aligned_deg"]
        .as_f64()
        .expect("heading");
    assert!(heading.abs() <= 0.5, "{al}");
    let u = &v["phases"]["usbl"];
    // 192 fixes; fixes that a loaded host stamps late (read together, one stamp) are refused by
    // the gate too: under busy loops on both cores, 144-181 were fused.
    assert!(u["fused"].as_u64().expect("fused") > 96, "{u}");
    // Every multipath outlier rejected, and none fused: the outliers add 10 to 50 m of path.
    let outliers = u["outliers_simulated"].as_u64().expect("outliers");
    assert!(outliers > 0, "{u}");
    assert!(u["rejected"].as_u64().expect("rejected") >= outliers, "{u}");
    let innovation = u["largest_fused_range_innovation_m"]
        .as_f64()
        .expect("innovation");
    assert!(innovation < 10.0, "{u}");
    assert!(
        u["error"]["horizontal_error_rms_m"].as_f64().expect("rms") <= 1.0,
        "{u}"
    );
    assert!(
        u["error"]["horizontal_error_final_m"]
            .as_f64()
            .expect("final")
            <= 0.5,
        "{u}"
    );
    // The configuration the daemon ran is the deployable one: [alignment], [navigation.usbl].
    let cfg = std::fs::read_to_string(out.join("auvnavd.toml")).expect("auvnavd.toml");
    assert!(
        cfg.contains("[alignment]") && cfg.contains("[navigation.usbl]"),
        "{cfg}"
    );
    assert!(!cfg.contains("[initial]"), "{cfg}");
}

/// The same voyage with the emulated PD0 DVL in instrument, beam and earth coordinates, through
/// the whole chain (pty, `auvnav-dvl`, the daemon, the recorder): each navigates like the
/// instrument-coordinate run, within what the velocity's 1 mm/s resolution allows over the run,
/// and each reproduces from its recording.
#[test]
fn every_pd0_coordinate_system_navigates_alike_through_the_daemon() {
    let _one = ONE_AT_A_TIME.lock().unwrap_or_else(|e| e.into_inner());
    const SECONDS: f64 = 90.0;
    let dir = TempDir::new("livepd0");
    let runs: Vec<(&str, serde_json::Value)> = ["instrument", "beam", "earth"]
        .into_iter()
        .map(|c| {
            let seconds = SECONDS.to_string();
            let args = [
                "--scenario",
                "lawnmower",
                "--start",
                "known",
                "--seconds",
                &seconds,
                "--speed",
                "10",
                "--pd0-coordinates",
                c,
            ];
            let v = demo(&args, &dir.path().join(c));
            assert_eq!(v["pd0_coordinates"], c, "{v}");
            assert_eq!(v["replay_identical"], true, "{c}: {v}");
            assert_eq!(v["clean_stop"], true, "{c}: {v}");
            (c, v)
        })
        .collect();
    let figure = |v: &serde_json::Value, k: &str| v["accuracy"][k].as_f64().expect(k);
    let bound = 2.0 * 0.001 * SECONDS;
    let reference = &runs[0].1;
    for (c, v) in &runs {
        eprintln!(
            "{c}: final {:.3} m, RMS {:.3} m, heading RMS {:.4} deg",
            figure(v, "horizontal_error_final_m"),
            figure(v, "horizontal_error_rms_m"),
            figure(v, "heading_error_rms_deg")
        );
        for k in ["horizontal_error_final_m", "horizontal_error_rms_m"] {
            let d = (figure(v, k) - figure(reference, k)).abs();
            assert!(d < bound, "{c}: {k} differs by {d} m (bound {bound} m)");
        }
    }
}

/// A daemon killed mid-run (SIGKILL) and started again continues from its checkpoint; the
/// recording says where, and its replay reproduces every solution either daemon published.
#[test]
fn a_restarted_daemon_continues_from_its_checkpoint_and_its_recording_replays_across_it() {
    let _one = ONE_AT_A_TIME.lock().unwrap_or_else(|e| e.into_inner());
    let dir = TempDir::new("restartdemo");
    let out = dir.path().join("run");
    let args = [
        "--scenario",
        "lawnmower",
        "--start",
        "known",
        "--seconds",
        "40",
        "--speed",
        "4",
        "--restart-daemon-at",
        "20",
    ];
    let v = demo(&args, &out);
    assert_eq!(v["daemon_restarted_at_s"], 20.0, "{v}");
    assert_eq!(v["replay_identical"], true, "{v}");
    assert_eq!(v["clean_stop"], true, "{v}");
    let restarted =
        std::fs::read_to_string(out.join("auvnavd-restarted.log")).expect("the restarted log");
    assert!(
        restarted.contains("continuing from the checkpoint"),
        "{restarted}"
    );
    let o = Command::new(binary("auvnav"))
        .arg("replay")
        .arg(out.join("record.mcap"))
        .args(["--compare-recorded", "--json"])
        .output()
        .expect("auvnav replay");
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let r: serde_json::Value = serde_json::from_slice(&o.stdout).expect("json");
    assert_eq!(r["sessions"]["session_starts"], 2, "{}", r["sessions"]);
    assert_eq!(r["sessions"]["continued"], 1, "{}", r["sessions"]);
    assert_eq!(r["sessions"]["checkpoint_missing"], 0, "{}", r["sessions"]);
    let c = &r["recorded_comparison"];
    assert_eq!(c["differing"], 0, "{c}");
    assert_eq!(c["unmatched_recorded"], 0, "{c}");
    // Both daemons' solutions: nearly the 8000 samples of 40 s at 200 Hz, less the restart's gap.
    assert!(c["compared"].as_u64().expect("compared") > 7000, "{c}");
}

/// `auvnav replay LOG --json`: the replay's report of a recording.
fn replay_json(log: &std::path::Path) -> serde_json::Value {
    let o = Command::new(binary("auvnav"))
        .arg("replay")
        .arg(log)
        .arg("--json")
        .output()
        .expect("replay");
    serde_json::from_slice(&o.stdout).expect("json")
}
