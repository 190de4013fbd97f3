//! A DVL whose readings are stamped before the motion they describe (a negative
//! `dvl_time_offset_s`, as measured on the Snapir AUV: about −1 s) is retimed by the session: each
//! reading is held until the filter reaches the moment it describes, instead of extrapolating the
//! velocity over the offset with one IMU sample's acceleration. On simulated docking voyages
//! (turns, climbs, speed changes) with a hidden −1.0 s offset, configuring it must lower the
//! horizontal RMS error and the DVL rejections against leaving it out. Seeds are the test's own.

use auvnav_tests::processes::TempDir;

use auvnav_tests::processes::auvnav_json as auvnav;

#[test]
fn a_dvl_stamped_a_second_early_is_retimed_not_extrapolated() {
    let tmp = TempDir::new("dvl-lag");
    let config = tmp.path().join("lag.toml");
    std::fs::write(&config, "[navigation]\ndvl_time_offset_s = -1.0\n").expect("config");
    let config = config.display().to_string();
    for seed in ["7501", "7502"] {
        let log = tmp
            .path()
            .join(format!("lag-{seed}.mcap"))
            .display()
            .to_string();
        auvnav(&[
            "sim",
            "--scenario",
            "docking",
            "--seed",
            seed,
            "--effect",
            "dvl.time_offset=-1.0",
            "--out",
            &log,
            "--json",
        ]);
        let figures = |r: &serde_json::Value| {
            (
                r["accuracy"]["horizontal_error_rms_m"]
                    .as_f64()
                    .expect("rms"),
                r["navigator"]["dvl_rejected"].as_u64().expect("rejected"),
                r["navigator"]["dvl_fused"].as_u64().expect("fused"),
            )
        };
        let (rms0, rej0, _) = figures(&auvnav(&["replay", &log, "--json"]));
        let (rms1, rej1, fused1) =
            figures(&auvnav(&["replay", &log, "--config", &config, "--json"]));
        println!(
            "seed {seed}: without the offset {rms0:.3} m RMS, {rej0} DVL rejected; retimed \
             {rms1:.3} m, {rej1} rejected, {fused1} fused"
        );
        assert!(rms1 < rms0, "seed {seed}: {rms1} against {rms0}");
        assert!(rej1 <= rej0, "seed {seed}: {rej1} rejected against {rej0}");
        assert!(fused1 >= 2990, "seed {seed}: {fused1} fused");
    }
}
