//! One configuration type and one validation: a configuration the daemon rejects is rejected by
//! replay too, with the same key named; the daemon's `--check-config` prints a file that reads
//! back to the same configuration.

use auvnav_core::config::DaemonConfig;
use auvnav_tests::processes::{TempDir, binary};
use std::process::Command;

const BAD: &str =
    "[alignment]\nlatitude_deg = 31.0\nlongitude_deg = 120.0\nheight_m = -20.0\nfine_model = 7\n";

#[test]
fn daemon_and_replay_reject_the_same_configuration() {
    let dir = TempDir::new("cfgval");
    let cfg = dir.path().join("bad.toml");
    std::fs::write(&cfg, BAD).expect("write");
    let daemon = Command::new(binary("auvnavd"))
        .args(["--check-config", cfg.to_str().expect("utf-8")])
        .output()
        .expect("auvnavd");
    let err = String::from_utf8_lossy(&daemon.stderr);
    assert!(
        !daemon.status.success() && err.contains("alignment.fine_model"),
        "{err}"
    );
    let log = dir.path().join("x.mcap");
    let sim = Command::new(binary("auvnav"))
        .args(["sim", "--scenario", "straight", "--duration", "5", "--out"])
        .arg(&log)
        .output()
        .expect("auvnav sim");
    assert!(sim.status.success());
    let replay = Command::new(binary("auvnav"))
        .arg("replay")
        .arg(&log)
        .arg("--config")
        .arg(&cfg)
        .output()
        .expect("auvnav replay");
    let err = String::from_utf8_lossy(&replay.stderr);
    assert!(
        !replay.status.success() && err.contains("alignment.fine_model"),
        "{err}"
    );
}

#[test]
fn check_config_prints_a_file_that_reads_back_the_same() {
    let dir = TempDir::new("cfgrt");
    let cfg = dir.path().join("ok.toml");
    std::fs::write(
        &cfg,
        "[initial]\nlatitude_deg = 31.0\nlongitude_deg = 120.0\nheight_m = -20.0\neuler_deg = [0.0, 0.0, 45.0]\n\
         [navigation]\ndvl_scale_factor = 1.002\n",
    )
    .expect("write");
    let out = Command::new(binary("auvnavd"))
        .args(["--check-config", cfg.to_str().expect("utf-8")])
        .output()
        .expect("auvnavd");
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let printed = String::from_utf8(out.stdout).expect("utf-8");
    let a = DaemonConfig::from_toml(&printed).expect("printed configuration reads back");
    let b = DaemonConfig::from_toml(&std::fs::read_to_string(&cfg).expect("read")).expect("file");
    assert_eq!(a, b);
    assert_eq!(a.navigation.dvl_scale_factor, 1.002);
}

#[test]
fn the_dvl_installation_is_given_once_as_a_table_or_as_flat_keys() {
    let start = "[initial]\nlatitude_deg = 31.0\nlongitude_deg = 120.0\nheight_m = -20.0\neuler_deg = [0.0, 0.0, 45.0]\n";
    let table = format!(
        "{start}[navigation.dvl]\nmount_deg = [0.0, 0.2, 1.5]\nscale_factor = 0.998\nlever_arm_m = [-1.8, 0.0, 0.2]\ntime_offset_s = 0.1\n"
    );
    let cfg = DaemonConfig::from_toml(&table).expect("table");
    let d = cfg.navigation.dvl_installation();
    assert_eq!(d.mount_deg, [0.0, 0.2, 1.5]);
    assert_eq!((d.scale_factor, d.time_offset_s), (0.998, 0.1));
    let both = format!(
        "{start}[navigation]\ndvl_scale_factor = 1.002\n[navigation.dvl]\nscale_factor = 0.998\n"
    );
    let err = DaemonConfig::from_toml(&both)
        .expect_err("given twice")
        .to_string();
    assert!(
        err.contains("navigation.dvl") && err.contains("twice"),
        "{err}"
    );
    let bad = format!("{start}[navigation.dvl]\nscale_factor = 7.0\n");
    let err = DaemonConfig::from_toml(&bad)
        .expect_err("range")
        .to_string();
    assert!(err.contains("navigation.dvl.scale_factor"), "{err}");
    // Per-beam corrections: read, and refused out of the simulator's ranges.
    let beams = format!(
        "{start}[navigation.dvl]\nbeam_scale_factor_ppm = [0.0, 20000.0, 0.0, 0.0]\nbeam_angle_error_deg = [0.0, 0.0, 0.5, 0.0]\n"
    );
    let d = DaemonConfig::from_toml(&beams)
        .expect("beams")
        .navigation
        .dvl_installation();
    assert_eq!(d.beam_scale_factor_ppm, [0.0, 20000.0, 0.0, 0.0]);
    assert!(d.corrects_beams());
    let bad = format!("{start}[navigation.dvl]\nbeam_angle_error_deg = [0.0, 9.0, 0.0, 0.0]\n");
    let err = DaemonConfig::from_toml(&bad)
        .expect_err("range")
        .to_string();
    assert!(err.contains("navigation.dvl.beam_angle_error_deg"), "{err}");
}
