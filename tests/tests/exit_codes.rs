//! The exit status of each failure class (docs/operations.md): 0 success, 1 a runtime failure,
//! 2 a usage or configuration error, 3 a check that ran and failed; and the on-board processes'
//! log lines under systemd (journald priorities, iceoryx2's own warnings visible).

use auvnav_log::{LogHeader, LogMessage, LogWriter};
use auvnav_shm_schema::topic;
use auvnav_sim::{self as sim, SimConfig, scenario::Scenario};
use auvnav_tests::processes::{Proc, TempDir, binary, unique};
use auvnav_tools::replay::{Output, Replay, ReplayConfig};
use std::path::Path;
use std::process::{Command, Stdio};
use std::time::Duration;

fn status(args: &[&str]) -> (Option<i32>, String) {
    let o = Command::new(binary("auvnav"))
        .args(args)
        .output()
        .expect("auvnav");
    (
        o.status.code(),
        String::from_utf8_lossy(&o.stderr).into_owned(),
    )
}

/// A simulated log with the solutions of its own replay recorded on `nav/solution`, as the
/// recorder writes the daemon's; `tamper` changes one recorded solution.
fn log_with_recorded_solutions(path: &Path, tamper: bool) {
    let scenario = Scenario::load("straight").expect("scenario");
    let effects = scenario.effects().expect("effects");
    let (msgs, _) = sim::simulate_to_vec(&SimConfig {
        scenario,
        effects,
        seed: 3,
        duration_s: Some(20.0),
    })
    .expect("simulate");
    let mut solutions = Vec::new();
    let mut replay = Replay::new(&ReplayConfig::default(), 100.0);
    let mut keep = |o: Output| {
        if let Output::Solution(s) = o {
            solutions.push(*s);
        }
        Ok(())
    };
    for m in &msgs {
        replay.process(m, &mut keep).expect("replay");
    }
    replay.finish(&mut keep).expect("finish");
    assert!(solutions.len() > 1000);
    if tamper {
        solutions[500].latitude_rad += 1e-9;
    }
    let mut w = LogWriter::create(path, &LogHeader::new("test", "")).expect("log");
    let mut next = solutions.iter().peekable();
    for m in &msgs {
        match m {
            LogMessage::Imu(x) => w.write(topic::IMU, x),
            LogMessage::Dvl(x) => w.write(topic::DVL, x),
            LogMessage::Depth(x) => w.write(topic::DEPTH, x),
            LogMessage::Truth(x) => w.write(topic::TRUTH, x),
            _ => Ok(()),
        }
        .expect("write");
        let t = m.sensor().map(|s| s.host_time_ns()).unwrap_or(0);
        while let Some(s) = next.next_if(|s| s.host_time_ns <= t) {
            w.write(topic::NAV_SOLUTION, s).expect("write");
        }
    }
    for s in next {
        w.write(topic::NAV_SOLUTION, s).expect("write");
    }
    w.finish().expect("finish");
}

#[test]
fn auvnav_exit_status_names_the_failure_class() {
    let dir = TempDir::new("exitcodes");
    // Usage: an unknown option (clap), a bad value.
    assert_eq!(status(&["replay", "--no-such-option"]).0, Some(2));
    assert_eq!(status(&["demo", "--imu", "gyrocompass"]).0, Some(2));
    // Values checked by clap's value parsers, before anything runs: an effect not in the
    // vocabulary, one with the wrong number of values, a malformed bound.
    let (code, err) = status(&[
        "perturb",
        "x.mcap",
        "--out",
        "y.mcap",
        "--effect",
        "dvl.scale_factr=1",
    ]);
    assert_eq!(code, Some(2), "{err}");
    assert!(err.contains("dvl.scale_factr"), "{err}");
    let (code, err) = status(&["sim", "--effect", "dvl.lever_arm=1,2", "--out", "y.mcap"]);
    assert_eq!(code, Some(2), "{err}");
    let (code, err) = status(&["calibrate", "dvl", "x.mcap", "--bound", "dvl.mount_yaw=5"]);
    assert_eq!(code, Some(2), "{err}");
    // Runtime: the log does not exist.
    let missing = dir.path().join("missing.mcap");
    let (code, err) = status(&["replay", missing.to_str().expect("utf-8")]);
    assert_eq!(code, Some(1), "{err}");
    assert!(err.contains("missing.mcap"), "{err}");
    assert_eq!(
        err.matches("No such file or directory").count(),
        1,
        "the OS message once: {err}"
    );
    // Usage: the recorder refuses to replace a file, which stays as it was.
    let existing = dir.path().join("existing.mcap");
    std::fs::write(&existing, b"keep me").expect("file");
    let e = existing.to_str().expect("utf-8");
    let (code, err) = status(&["record", "--out", e, "--seconds", "0.1"]);
    assert_eq!(code, Some(2), "{err}");
    assert!(err.contains("--force"), "{err}");
    let (code, err) = status(&["record", "--recover", e, "--out", e]);
    assert_eq!(code, Some(2), "{err}");
    assert_eq!(std::fs::read(&existing).expect("file"), b"keep me");
    // Configuration: a value out of range.
    let good = dir.path().join("good.mcap");
    log_with_recorded_solutions(&good, false);
    let cfg = dir.path().join("bad.toml");
    std::fs::write(&cfg, "aid_delay_s = 7\n").expect("config");
    let g = good.to_str().expect("utf-8");
    let (code, err) = status(&["replay", g, "--config", cfg.to_str().expect("utf-8")]);
    assert_eq!(code, Some(2), "{err}");
    assert!(err.contains("aid_delay_s"), "{err}");
    // A check: the replay reproduces the recorded solutions (0), or not (3, naming where).
    let (code, err) = status(&["replay", g, "--compare-recorded"]);
    assert_eq!(code, Some(0), "{err}");
    let bad = dir.path().join("tampered.mcap");
    log_with_recorded_solutions(&bad, true);
    let o = Command::new(binary("auvnav"))
        .args(["replay", "--compare-recorded", "--json"])
        .arg(&bad)
        .output()
        .expect("auvnav");
    assert_eq!(o.status.code(), Some(3));
    let v: serde_json::Value = serde_json::from_slice(&o.stdout).expect("json");
    let c = &v["recorded_comparison"];
    assert_eq!(c["differing"], 1, "{c}");
    assert!(c["compared"].as_u64().expect("compared") > 1000, "{c}");
}

#[test]
fn every_binary_reports_its_version_and_commit() {
    for b in [
        "auvnav",
        "auvnavd",
        "auvnav-dvl",
        "auvnav-imu",
        "auvnav-usbl",
        "auvnav-gnss",
        "auvnav-mavlink",
        "auvnav-can",
        "auvnav-bridge",
        "auvnav-live",
    ] {
        let o = Command::new(binary(b))
            .arg("--version")
            .output()
            .expect("binary");
        assert!(o.status.success(), "{b}");
        let out = String::from_utf8_lossy(&o.stdout);
        assert_eq!(
            out.trim(),
            format!("{b} {}", auvnav_version::LONG),
            "{b} --version"
        );
    }
}

#[test]
fn daemon_configuration_errors_are_status_2() {
    let dir = TempDir::new("exitcodes-daemon");
    let o = Command::new(binary("auvnavd"))
        .arg("--config")
        .arg(dir.path().join("absent.toml"))
        .output()
        .expect("auvnavd");
    assert_eq!(o.status.code(), Some(2));
    let cfg = dir.path().join("bad.toml");
    std::fs::write(&cfg, "health_period_s = 0\n").expect("config");
    let o = Command::new(binary("auvnavd"))
        .arg("--config")
        .arg(&cfg)
        .output()
        .expect("auvnavd");
    assert_eq!(o.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&o.stderr).contains("health_period_s"));
}

#[test]
fn under_systemd_log_lines_carry_journal_priorities_and_iceoryx2_warnings() {
    let dir = TempDir::new("journal");
    let cfg = dir.path().join("auvnavd.toml");
    std::fs::write(
        &cfg,
        format!(
            "prefix = \"{}\"\n[initial]\nlatitude_deg = 31.0\nlongitude_deg = 120.0\n\
             height_m = -30.0\nvelocity_ned_m_s = [0.0, 0.0, 0.0]\neuler_deg = [0.0, 0.0, 0.0]\n",
            unique("journal")
        ),
    )
    .expect("config");
    let err_path = dir.path().join("auvnavd.err");
    let mut cmd = Command::new(binary("auvnavd"));
    cmd.arg("--config")
        .arg(&cfg)
        .env("JOURNAL_STREAM", "8:12345")
        .env("RUST_LOG", "info")
        // No iceoryx2 configuration file: iceoryx2 warns that it uses its defaults.
        .env_remove("IOX2_LOG_LEVEL")
        .stdout(Stdio::null())
        .stderr(std::fs::File::create(&err_path).expect("stderr"));
    let mut p = Proc::spawn("auvnavd", &mut cmd).expect("spawn");
    std::thread::sleep(Duration::from_millis(800));
    let st = p
        .terminate(Duration::from_secs(10))
        .expect("auvnavd stops on SIGTERM");
    assert!(st.success(), "{st}");
    let log = std::fs::read_to_string(&err_path).expect("log");
    let lines: Vec<&str> = log.lines().collect();
    assert!(
        lines.iter().all(|l| l.starts_with('<')),
        "every line starts with a priority:\n{log}"
    );
    assert!(
        lines
            .iter()
            .any(|l| l.starts_with("<6>auvnavd: running under")),
        "{log}"
    );
    assert!(
        lines.iter().any(|l| l.starts_with("<6>auvnavd: stopping;")),
        "{log}"
    );
    assert!(
        lines
            .iter()
            .any(|l| l.starts_with("<4>iceoryx2") && l.contains("config")),
        "iceoryx2's warning is visible:\n{log}"
    );
    // The lost-sensor warning carries its field.
    assert!(
        lines
            .iter()
            .any(|l| l.starts_with("<4>auvnavd: imu lost") && l.contains("sensor=\"imu\"")),
        "{log}"
    );
}
