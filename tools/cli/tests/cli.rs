//! The `auvnav` program driven as a user would: simulation determinism, bad input, third-party
//! readability of the logs, the demo. Every child process runs under a watchdog.

use std::path::{Path, PathBuf};
use std::process::{Command, Output, Stdio};
use std::time::{Duration, Instant};

const WATCHDOG: Duration = Duration::from_secs(300);

fn run_with_watchdog(cmd: &mut Command) -> Output {
    let mut child = cmd
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("spawn");
    let start = Instant::now();
    loop {
        if child.try_wait().expect("wait").is_some() {
            return child.wait_with_output().expect("output");
        }
        if start.elapsed() > WATCHDOG {
            let _ = child.kill();
            panic!("watchdog: {cmd:?} still running after {WATCHDOG:?}");
        }
        std::thread::sleep(Duration::from_millis(20));
    }
}

fn auvnav(args: &[&str]) -> Output {
    run_with_watchdog(Command::new(env!("CARGO_BIN_EXE_auvnav")).args(args))
}

fn temp_dir(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("auvnav-cli-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).expect("temp dir");
    d
}

fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

fn no_files_in(dir: &Path) -> bool {
    std::fs::read_dir(dir)
        .map(|mut d| d.next().is_none())
        .unwrap_or(true)
}

#[test]
fn identical_seeds_give_identical_files() {
    let dir = temp_dir("determinism");
    let p = |n: &str| dir.join(n).to_string_lossy().into_owned();
    for (name, seed) in [("a.mcap", "1"), ("b.mcap", "1"), ("c.mcap", "2")] {
        let o = auvnav(&[
            "sim",
            "--scenario",
            "docking",
            "--seed",
            seed,
            "--duration",
            "60",
            "--out",
            &p(name),
        ]);
        assert!(o.status.success(), "{}", stderr(&o));
    }
    let read = |n: &str| std::fs::read(dir.join(n)).expect("read");
    assert_eq!(read("a.mcap"), read("b.mcap"), "same seed, same bytes");
    assert_ne!(read("a.mcap"), read("c.mcap"), "another seed, other noise");
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn bad_input_gives_a_clear_error_and_no_file() {
    let dir = temp_dir("bad-input");
    let out = dir.join("x.mcap").to_string_lossy().into_owned();
    let cases: Vec<(Vec<String>, &[&str])> = vec![
        (
            vec!["--effect".into(), "dvl.scale=1.004".into()],
            &["dvl.scale", "--list-effects"],
        ),
        (
            vec!["--effect".into(), "dvl.scale_factor=1.5".into()],
            &["dvl.scale_factor", "0.9..=1.1"],
        ),
        (
            vec!["--effect".into(), "dvl.lever_arm=1,2".into()],
            &["dvl.lever_arm", "3"],
        ),
        (
            vec!["--effect".into(), "dvl.scale_factor=abc".into()],
            &["dvl.scale_factor"],
        ),
        (
            vec!["--scenario".into(), "nonexistent".into()],
            &["nonexistent", "--list-scenarios"],
        ),
        (
            vec!["--duration=-5".into()],
            &["--duration", "allowed range"],
        ),
    ];
    for (extra, needles) in cases {
        let mut args = vec!["sim".to_string(), "--out".into(), out.clone()];
        args.extend(extra.clone());
        let args: Vec<&str> = args.iter().map(String::as_str).collect();
        let o = auvnav(&args);
        assert!(!o.status.success(), "{extra:?} must fail");
        let err = stderr(&o);
        for n in needles {
            assert!(err.contains(n), "{extra:?}: {err:?} should mention {n:?}");
        }
        assert!(no_files_in(&dir), "{extra:?} left a file behind");
    }
    // Malformed and out-of-range scenario files.
    let bad_files = [
        (
            "malformed.toml",
            "name = \"x\"\n[start\nlatitude_deg = 1\n",
            "malformed.toml",
        ),
        (
            "unknown_key.toml",
            &std::fs::read_to_string(scenario_path("straight"))
                .expect("read")
                .replace("[start]", "colour = 1\n[start]"),
            "colour",
        ),
        (
            "range.toml",
            &std::fs::read_to_string(scenario_path("straight"))
                .expect("read")
                .replace("latitude_deg = 31.0", "latitude_deg = 95.0"),
            "start.latitude_deg",
        ),
    ];
    let scen_dir = temp_dir("bad-scenarios");
    for (name, text, needle) in bad_files {
        let path = scen_dir.join(name);
        std::fs::write(&path, text).expect("write");
        let o = auvnav(&["sim", "--scenario", &path.to_string_lossy(), "--out", &out]);
        assert!(!o.status.success(), "{name} must fail");
        assert!(stderr(&o).contains(needle), "{name}: {}", stderr(&o));
        assert!(no_files_in(&dir), "{name} left a file behind");
    }
    let _ = std::fs::remove_dir_all(&dir);
    let _ = std::fs::remove_dir_all(&scen_dir);
}

fn scenario_path(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join(format!("../sim/src/scenarios/{name}.toml"))
}

#[test]
fn lists_effects_and_scenarios() {
    let o = auvnav(&["sim", "--list-effects"]);
    assert!(o.status.success());
    let text = String::from_utf8_lossy(&o.stdout);
    for name in [
        "dvl.scale_factor",
        "dvl.mount_yaw",
        "dvl.lever_arm",
        "dvl.time_offset",
        "usbl.array_yaw",
        "depth.density",
        "mag.hard_iron",
    ] {
        assert!(text.contains(name), "{name} missing from --list-effects");
    }
    let o = auvnav(&["sim", "--list-scenarios"]);
    let text = String::from_utf8_lossy(&o.stdout);
    for name in [
        "straight",
        "turns",
        "depth_changes",
        "lawnmower",
        "docking",
        "moored",
    ] {
        assert!(text.contains(name), "{name} missing from --list-scenarios");
    }
}

/// `python3` with the `mcap` and `mcap-ros2-support` packages, or why not.
fn python_reader() -> Result<(), String> {
    let o = Command::new("python3")
        .args(["-c", "import mcap, mcap_ros2.decoder"])
        .output()
        .map_err(|e| format!("python3 not runnable: {e}"))?;
    if o.status.success() {
        Ok(())
    } else {
        Err(format!(
            "python packages mcap / mcap-ros2-support missing: {}",
            stderr(&o)
        ))
    }
}

#[test]
fn every_scenario_log_is_decoded_by_the_python_mcap_reader() {
    if let Err(why) = python_reader() {
        if std::env::var("CI").is_ok_and(|v| v == "true") {
            panic!("under CI the third-party reader must be installed: {why}");
        }
        eprintln!("SKIPPED: {why} (pip install mcap mcap-ros2-support)");
        return;
    }
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../tests/python/read_log.py");
    let dir = temp_dir("python");
    // Every built-in scenario, as `--list-scenarios` lists them.
    for name in auvnav_sim::scenario::BUILTIN.iter().map(|(n, _)| *n) {
        let out = dir.join(format!("{name}.mcap"));
        let o = auvnav(&[
            "sim",
            "--scenario",
            name,
            "--seed",
            "1",
            // Every channel appears within the first minutes; the whole survey would only slow
            // the pure-Python decoder down.
            "--duration",
            "300",
            "--out",
            &out.to_string_lossy(),
        ]);
        assert!(o.status.success(), "{name}: {}", stderr(&o));
        let o = run_with_watchdog(Command::new("python3").arg(&script).arg(&out));
        let report = String::from_utf8_lossy(&o.stdout);
        assert!(o.status.success(), "{name}: {report} {}", stderr(&o));
        let v: serde_json::Value = serde_json::from_str(&report).expect("json");
        let own: &[&str] = match name {
            "docking" => &["usbl"],
            "ranges_lbl" => &["acoustic_ranges"],
            "ranges_array" | "ranges_single" => &["acoustic_ranges", "acoustic_array_pose"],
            _ => &[],
        };
        for topic in ["imu", "dvl", "depth", "magnetometer", "truth"]
            .iter()
            .chain(own)
        {
            assert!(
                v["messages"][topic].as_u64().unwrap_or(0) > 0,
                "{name}: no {topic} decoded: {report}"
            );
        }
        assert_eq!(v["header"]["producer"], "auvnav sim");
        // Decoded by the third party with the field names of our schema.
        assert!(v["first"]["imu"]["angular"].is_array(), "{report}");
        std::fs::remove_file(&out).expect("remove");
    }
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn demo_runs_a_voyage_through_the_core_and_reports_accuracy() {
    let o = auvnav(&[
        "demo",
        "--in-process",
        "--scenario",
        "lawnmower",
        "--start",
        "known",
        "--seconds",
        "300",
        "--json",
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let v: serde_json::Value = serde_json::from_slice(&o.stdout).expect("json");
    let acc = &v["accuracy"];
    let travelled = acc["distance_travelled_m"].as_f64().expect("distance");
    let final_err = acc["horizontal_error_final_m"].as_f64().expect("error");
    assert!(travelled > 500.0, "{v}");
    // Navigation-grade INS with DVL: well under 1 % of distance travelled.
    assert!(final_err < 0.01 * travelled, "{v}");
    assert!(
        v["counters"]["dvl_fused"].as_u64().unwrap_or(0) > 1000,
        "{v}"
    );
}

/// The README demo's story on seeds it was not tuned on: the navigator, given only the launch
/// position, aligns in motion, declares itself aligned with a heading error under 0.5°, and the
/// USBL homing (5 % multipath outliers) keeps the horizontal error under 1 m RMS once the first
/// fixes are in; an outlier met at the first fix of a wide prior (seed 9) is recovered from by
/// the re-opened position covariance.
#[test]
fn demo_aligns_without_a_heading_and_homes_on_usbl_fixes_on_other_seeds() {
    for seed in [2, 3, 5, 7, 9, 11] {
        let o = auvnav(&[
            "demo",
            "--in-process",
            "--seed",
            &seed.to_string(),
            "--json",
        ]);
        assert!(o.status.success(), "{}", stderr(&o));
        let v: serde_json::Value = serde_json::from_slice(&o.stdout).expect("json");
        let al = &v["phases"]["alignment"];
        let t = al["aligned_after_s"].as_f64().expect("aligned");
        assert!(t > 60.0 && t < 298.0, "seed {seed}: {al}");
        let e = al["heading_error_at_aligned_deg"]
            .as_f64()
            .expect("heading");
        assert!(e.abs() <= 0.5, "seed {seed}: {al}");
        // The reported position uncertainty at hand-over covers what the alignment dead
        // reckoning left (3 sigma).
        let pe = al["horizontal_error_at_aligned_m"].as_f64().expect("error");
        let ps = al["horizontal_std_at_aligned_m"].as_f64().expect("std");
        assert!(pe <= 3.0 * ps, "seed {seed}: {al}");
        let u = &v["phases"]["usbl"];
        let rms = u["error"]["horizontal_error_rms_m"].as_f64().expect("rms");
        assert!(rms <= 1.0, "seed {seed}: {u}");
        assert!(
            u["error"]["horizontal_error_final_m"]
                .as_f64()
                .expect("final")
                < 0.5,
            "seed {seed}: {u}"
        );
        let rejected = u["rejected"].as_u64().expect("rejected");
        let outliers = u["outliers_simulated"].as_u64().expect("outliers");
        assert!(rejected >= outliers.saturating_sub(1), "seed {seed}: {u}");
        // Depth stays fused after the hand-over (the mounting estimate goes on with its
        // uncertainty).
        assert_eq!(v["counters"]["depth_rejected"], 0, "seed {seed}: {v}");
    }
}

#[test]
fn replaying_a_log_twice_gives_identical_files_and_reports_accuracy() {
    let dir = temp_dir("replay");
    let log = dir.join("turns.mcap");
    let log_s = log.to_string_lossy().to_string();
    let o = auvnav(&[
        "sim",
        "--scenario",
        "turns",
        "--seed",
        "5",
        "--duration",
        "120",
        "--out",
        &log_s,
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let mut outputs = Vec::new();
    for k in 0..2 {
        let csv = dir.join(format!("nav{k}.csv"));
        let o = auvnav(&["replay", &log_s, "--out", &csv.to_string_lossy(), "--json"]);
        assert!(o.status.success(), "{}", stderr(&o));
        let v: serde_json::Value = serde_json::from_slice(&o.stdout).expect("json");
        let acc = &v["accuracy"];
        assert!(
            acc["horizontal_error_final_m"].as_f64().expect("final") < 2.0,
            "{v}"
        );
        assert!(
            acc["distance_travelled_m"].as_f64().expect("distance") > 200.0,
            "{v}"
        );
        assert_eq!(v["samples_processed"].as_u64(), Some(24_000), "{v}");
        assert!(v["real_time_factor"].as_f64().expect("rtf") > 0.0);
        let nav = std::fs::read(&csv).expect("solution csv");
        let diag = std::fs::read(dir.join(format!("nav{k}.diagnostics.csv"))).expect("diagnostics");
        assert!(nav.len() > 1_000_000 && diag.len() > 10_000);
        outputs.push((nav, diag));
    }
    assert!(outputs[0] == outputs[1], "two replays of one log differ");
    // MCAP output carries the solution, the diagnostics and the truth.
    let out = dir.join("nav.mcap");
    let o = auvnav(&["replay", &log_s, "--out", &out.to_string_lossy()]);
    assert!(o.status.success(), "{}", stderr(&o));
    let mut reader = auvnav_log::LogReader::open(&out).expect("open");
    let mut topics = std::collections::BTreeMap::new();
    while let Some(m) = reader.next_message().expect("read") {
        *topics.entry(m.topic.to_string()).or_insert(0u64) += 1;
    }
    assert_eq!(topics.get("nav/solution"), Some(&24_001), "{topics:?}");
    assert!(topics.get("nav/aid_diagnostics").is_some_and(|&n| n > 100));
    assert!(topics.get("truth").is_some_and(|&n| n > 100));
    // A missing log is a clear error.
    let o = auvnav(&["replay", &dir.join("absent.mcap").to_string_lossy()]);
    assert!(!o.status.success());
    assert!(stderr(&o).contains("absent.mcap"), "{}", stderr(&o));
}

#[test]
fn decode_prints_one_json_object_per_frame_and_counts_garbage() {
    use auvnav_drivers::pd0::{BottomTrack, Ensemble, encode_ensemble};
    let dir = temp_dir("decode");
    let mut bytes = b"\x7f\x7fgarbage before the first frame".to_vec();
    for k in 0..3 {
        let e = Ensemble {
            bottom_track: Some(BottomTrack {
                pings_per_ensemble: 1,
                range_m: [Some(10.0 + f64::from(k)), None, Some(11.0), Some(12.0)],
                velocity_m_s: [Some(0.5), Some(-0.25), Some(0.0), None],
                correlation: [250; 4],
                evaluation_amplitude: [60; 4],
                percent_good: [100; 4],
                max_depth_m: 200.0,
                reference_layer_velocity_m_s: [None; 4],
                reference_layer_percent_good: [0; 4],
            }),
            ..Default::default()
        };
        bytes.extend(encode_ensemble(&e));
        bytes.extend_from_slice(&[0x7f, 0x00, 0x13]);
    }
    let file = dir.join("capture.pd0");
    std::fs::write(&file, &bytes).expect("write");
    let o = auvnav(&[
        "decode",
        "--protocol",
        "pd0",
        &file.to_string_lossy(),
        "--json",
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let text = String::from_utf8_lossy(&o.stdout);
    let lines: Vec<serde_json::Value> = text
        .lines()
        .map(|l| serde_json::from_str(l).expect("json line"))
        .collect();
    assert_eq!(lines.len(), 4, "{text}");
    assert_eq!(lines[1]["bottom_track"]["range_m"][0], 11.0);
    assert!(lines[0]["bottom_track"]["range_m"][1].is_null());
    let s = &lines[3]["summary"];
    assert_eq!(s["frames"], 3);
    assert!(s["bytes_skipped"].as_u64().expect("skipped") >= 30, "{s}");
    let o = auvnav(&[
        "decode",
        "--protocol",
        "pd0",
        &dir.join("absent").to_string_lossy(),
    ]);
    assert!(!o.status.success() && stderr(&o).contains("absent"));
}

#[test]
fn replay_fuses_usbl_with_the_station_of_a_simulated_log_when_asked() {
    let dir = temp_dir("replayusbl");
    let log = dir.join("docking.mcap");
    let log_s = log.to_string_lossy().to_string();
    let o = auvnav(&[
        "sim",
        "--scenario",
        "docking",
        "--seed",
        "9",
        "--duration",
        "120",
        "--out",
        &log_s,
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let o = auvnav(&["replay", &log_s, "--json"]);
    assert!(o.status.success(), "{}", stderr(&o));
    let v: serde_json::Value = serde_json::from_slice(&o.stdout).expect("json");
    assert_eq!(v["navigator"]["usbl_fused"], 0, "{v}");
    assert_eq!(v["navigator"]["usbl_unconfigured"], 120, "{v}");
    for coupling in ["tight", "loose"] {
        let o = auvnav(&["replay", &log_s, "--usbl", coupling, "--json"]);
        assert!(o.status.success(), "{}", stderr(&o));
        let v: serde_json::Value = serde_json::from_slice(&o.stdout).expect("json");
        let fused = v["navigator"]["usbl_fused"].as_u64().expect("fused");
        assert!(fused >= 115, "{coupling}: {v}");
        assert!(
            v["configuration"]
                .as_str()
                .is_some_and(|c| c.contains("station from the log header")),
            "{v}"
        );
    }
    // A log without a station survey: a clear error, not a silent replay without USBL.
    let plain = dir.join("turns.mcap");
    let plain_s = plain.to_string_lossy().to_string();
    let o = auvnav(&[
        "sim",
        "--scenario",
        "turns",
        "--duration",
        "10",
        "--out",
        &plain_s,
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let o = auvnav(&["replay", &plain_s, "--usbl", "tight"]);
    assert!(!o.status.success());
    assert!(stderr(&o).contains("no station survey"), "{}", stderr(&o));
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn info_lists_channels_counts_and_duration_of_a_log_and_of_a_cut_log() {
    let dir = temp_dir("info");
    let log = dir.join("s.mcap");
    let o = auvnav(&[
        "sim",
        "--scenario",
        "straight",
        "--duration",
        "300",
        "--out",
        log.to_str().expect("utf-8"),
        "--json",
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let sim: serde_json::Value = serde_json::from_slice(&o.stdout).expect("sim json");
    let o = auvnav(&["info", log.to_str().expect("utf-8"), "--json"]);
    assert!(o.status.success(), "{}", stderr(&o));
    let v: serde_json::Value = serde_json::from_slice(&o.stdout).expect("info json");
    assert_eq!(v["format_version"], 1, "{v}");
    assert_eq!(v["log_format_version"], 1, "{v}");
    assert_eq!(v["producer"], "auvnav sim");
    assert!(
        v["start_utc"].is_null(),
        "a simulated log has no UTC anchor"
    );
    assert!(
        (v["duration_s"].as_f64().expect("duration") - 300.0).abs() < 0.01,
        "{v}"
    );
    let channels = v["channels"].as_array().expect("channels");
    let count = |topic: &str| {
        channels
            .iter()
            .find(|c| c["topic"] == topic)
            .map(|c| c["messages"].clone())
            .unwrap_or_default()
    };
    assert_eq!(count("imu"), sim["imu"], "{v}");
    assert_eq!(count("dvl"), sim["dvl"], "{v}");
    let imu = channels
        .iter()
        .find(|c| c["topic"] == "imu")
        .expect("imu channel");
    assert!(
        (imu["rate_hz"].as_f64().expect("rate") - 200.0).abs() < 0.1,
        "{imu}"
    );
    assert!(v["stopped"].is_null());
    // A log cut in the middle (a killed writer): read to the cut, and said so.
    let bytes = std::fs::read(&log).expect("log");
    let cut = dir.join("cut.mcap");
    std::fs::write(&cut, &bytes[..bytes.len() * 3 / 4]).expect("cut");
    let o = auvnav(&["info", cut.to_str().expect("utf-8"), "--json"]);
    assert!(o.status.success(), "{}", stderr(&o));
    let v: serde_json::Value = serde_json::from_slice(&o.stdout).expect("info json");
    assert!(v["stopped"].is_string(), "{v}");
    let m = v["messages"].as_u64().expect("messages");
    assert!(m > 0 && m < sim["imu"].as_u64().expect("imu"), "{v}");
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn manual_pages_and_completions_cover_every_program() {
    let dir = temp_dir("man");
    let o = auvnav(&["man", "--out", dir.to_str().expect("utf-8")]);
    assert!(o.status.success(), "{}", stderr(&o));
    for page in [
        "auvnav.1",
        "auvnav-replay.1",
        "auvnav-calibrate-dvl.1",
        "auvnavd.1",
        "auvnav-dvl.1",
        "auvnav-imu.1",
        "auvnav-usbl.1",
        "auvnav-gnss.1",
        "auvnav-can.1",
    ] {
        let text = std::fs::read_to_string(dir.join(page)).unwrap_or_default();
        assert!(text.starts_with(".ie"), "{page}: {:.80}", text);
        assert!(text.contains(".SH NAME"), "{page}");
    }
    let comp = dir.join("completions");
    let o = auvnav(&[
        "completions",
        "bash",
        "--out",
        comp.to_str().expect("utf-8"),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    for program in ["auvnav", "auvnavd", "auvnav-dvl", "auvnav-can"] {
        let script = comp.join(format!("{program}.bash"));
        // bash accepts the script and registers the completion.
        let st = Command::new("bash")
            .arg("-c")
            .arg(format!(
                "source '{}' && complete -p {program}",
                script.display()
            ))
            .output()
            .expect("bash");
        assert!(st.status.success(), "{program}: {}", stderr(&st));
    }
    let _ = std::fs::remove_dir_all(&dir);
}
