//! The driver binaries' command line: the shipped example configurations are valid, and a bad
//! configuration is a clear error (exit status 2) that names the key.

use std::process::Command;

fn run(bin: &str, args: &[&str]) -> (Option<i32>, String, String) {
    let out = Command::new(bin).args(args).output().expect("run");
    (
        out.status.code(),
        String::from_utf8_lossy(&out.stdout).into_owned(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

fn config(name: &str) -> String {
    format!("{}/config/{name}", env!("CARGO_MANIFEST_DIR"))
}

#[test]
fn example_configurations_check() {
    for (bin, file) in [
        (env!("CARGO_BIN_EXE_auvnav-dvl"), "dvl-pd0.toml"),
        (env!("CARGO_BIN_EXE_auvnav-dvl"), "dvl-wldvl.toml"),
        (env!("CARGO_BIN_EXE_auvnav-dvl"), "dvl-nortek.toml"),
        (env!("CARGO_BIN_EXE_auvnav-dvl"), "dvl-wldvl-tcp.toml"),
        (env!("CARGO_BIN_EXE_auvnav-imu"), "imu-kvh1750.toml"),
        (env!("CARGO_BIN_EXE_auvnav-imu"), "imu-xsens.toml"),
        (env!("CARGO_BIN_EXE_auvnav-usbl"), "usbl-seatrac.toml"),
        (env!("CARGO_BIN_EXE_auvnav-gnss"), "gnss-nmea.toml"),
        (env!("CARGO_BIN_EXE_auvnav-gnss"), "gnss-ubx.toml"),
        (env!("CARGO_BIN_EXE_auvnav-can"), "can.toml"),
    ] {
        let (code, out, err) = run(bin, &["--config", &config(file), "--check-config"]);
        assert_eq!(code, Some(0), "{file}: {err}");
        assert!(
            out.contains("[serial]") || out.contains("[tcp]") || out.contains("[depth]"),
            "{file}: {out}"
        );
    }
}

#[test]
fn bad_configurations_name_the_key() {
    let dir = std::env::temp_dir().join(format!("auvnav-driver-cli-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("dir");
    let cases = [
        // The wrong class of protocol for this driver.
        (
            "protocol = \"kvh1750\"\n[serial]\nport = \"/dev/null\"\n",
            "protocol",
        ),
        // Out of range.
        (
            "protocol = \"pd0\"\n[serial]\nport = \"/dev/null\"\nbaud = 7\n",
            "serial.baud",
        ),
        (
            "protocol = \"pd0\"\n[serial]\nport = \"/dev/null\"\n[timing]\nhealth_period_s = 0.0\n",
            "timing.health_period_s",
        ),
        // Unknown key and unknown protocol.
        (
            "protocol = \"pd0\"\nbaud = 9600\n[serial]\nport = \"/dev/null\"\n",
            "baud",
        ),
        (
            "protocol = \"pd9\"\n[serial]\nport = \"/dev/null\"\n",
            "pd9",
        ),
        // Missing section.
        ("protocol = \"pd0\"\n", "serial"),
    ];
    for (i, (text, key)) in cases.iter().enumerate() {
        let path = dir.join(format!("bad{i}.toml"));
        std::fs::write(&path, text).expect("write");
        let (code, _, err) = run(
            env!("CARGO_BIN_EXE_auvnav-dvl"),
            &["--config", path.to_str().expect("utf-8")],
        );
        assert_eq!(code, Some(2), "case {i}: {err}");
        assert!(err.contains(key), "case {i}: {err:?} does not name {key}");
    }
    // The beacons a SeaTrac ranges: IDs 1..15, distinct, at most 4, for SeaTrac only.
    let seatrac = "protocol = \"seatrac\"\n[serial]\nport = \"/dev/null\"\n[settings.seatrac]\n";
    for (i, (beacons, says)) in [
        ("[1, 0]", "settings.seatrac.range_beacons"),
        ("[1, 2, 1]", "settings.seatrac.range_beacons"),
        ("[1, 2, 3, 4, 5]", "range_beacons"),
    ]
    .iter()
    .enumerate()
    {
        let path = dir.join(format!("beacons{i}.toml"));
        std::fs::write(&path, format!("{seatrac}range_beacons = {beacons}\n")).expect("write");
        let (code, _, err) = run(
            env!("CARGO_BIN_EXE_auvnav-usbl"),
            &["--config", path.to_str().expect("utf-8"), "--check-config"],
        );
        assert_eq!(code, Some(2), "{beacons}: {err}");
        assert!(
            err.contains(says),
            "{beacons}: {err:?} does not name {says}"
        );
    }
    let path = dir.join("beacons-ok.toml");
    std::fs::write(&path, format!("{seatrac}range_beacons = [3, 1, 2]\n")).expect("write");
    let (code, out, err) = run(
        env!("CARGO_BIN_EXE_auvnav-usbl"),
        &["--config", path.to_str().expect("utf-8"), "--check-config"],
    );
    assert_eq!(code, Some(0), "{err}");
    assert!(out.contains("range_beacons = [\n    3,"), "{out}");
    let (code, _, err) = run(
        env!("CARGO_BIN_EXE_auvnav-imu"),
        &["--config", "/nonexistent/imu.toml"],
    );
    assert_eq!(code, Some(2));
    assert!(err.contains("/nonexistent/imu.toml"));
    let _ = std::fs::remove_dir_all(&dir);
}
