//! Calibration as a library, without the command line (and without clap): a magnetometer turned
//! through many attitudes with a hard-iron offset gives that offset back in a typed report.

use auvnav_calibrate::mag::command::{CalibrateMagOptions, calibrate_mag};
use nalgebra::{Rotation3, Vector3};

#[test]
fn a_magnetometer_recording_calibrates_through_the_library() {
    let dir = std::env::temp_dir().join(format!("auvnav-calibrate-lib-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("scratch folder");
    let field = Vector3::new(20.0, 0.0, 45.0); // µT, NED
    let gravity = Vector3::new(0.0, 0.0, -9.81); // specific force at rest, NED
    let hard_iron = Vector3::new(5.0, -3.0, 2.0);
    let mut text = String::from("time_s,mag_x,mag_y,mag_z,acc_x,acc_y,acc_z\n");
    for k in 0..2000 {
        let t = k as f64 * 0.1;
        let r = Rotation3::from_euler_angles(
            0.6 * (0.011 * t).sin(),
            0.5 * (0.007 * t).cos(),
            0.05 * t,
        );
        let h = r.inverse() * field + hard_iron;
        let f = r.inverse() * gravity;
        text.push_str(&format!(
            "{t:.1},{},{},{},{},{},{}\n",
            h.x, h.y, h.z, f.x, f.y, f.z
        ));
    }
    let csv = dir.join("turns.csv");
    std::fs::write(&csv, text).expect("CSV");
    let mut a = CalibrateMagOptions::new(vec![csv]);
    a.field_ut = Some(field.norm());
    a.dip_deg = Some(field.z.atan2(field.x).to_degrees());
    let r = calibrate_mag(&a).expect("calibration");
    let b = r
        .effects
        .iter()
        .find(|e| e.name == "mag.hard_iron")
        .unwrap_or_else(|| panic!("no hard iron in {:?}", r.effects));
    for (got, want) in b.value.iter().zip(hard_iron.iter()) {
        assert!((got - want).abs() < 0.05, "hard iron {:?}", b.value);
    }
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn failures_are_typed_the_callers_apart_from_the_data() {
    use auvnav_calibrate::voyage::VoyageSpec;
    use auvnav_calibrate::{CalibrateDvlOptions, CalibrationError, calibrate_dvl};
    let dir = std::env::temp_dir().join(format!("auvnav-calibrate-errors-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("scratch folder");
    let spec = |name: &str| VoyageSpec {
        path: dir.join(name),
        window_s: None,
    };

    // A log with a header and no message.
    auvnav_log::write_log_atomically(
        &dir.join("empty.mcap"),
        &auvnav_log::LogHeader::new("test", ""),
        |_| Ok(()),
    )
    .expect("an empty log");

    // The caller's: a negative threshold, an unknown parameter, inverted bounds.
    let mut a = CalibrateDvlOptions::new(vec![spec("empty.mcap")]);
    a.threshold = -1.0;
    let e = calibrate_dvl(&a).expect_err("negative threshold");
    assert!(
        matches!(e, CalibrationError::Options(_)) && e.is_usage(),
        "{e:?}"
    );
    let mut a = CalibrateDvlOptions::new(vec![spec("empty.mcap")]);
    a.params = vec!["dvl.colour".into()];
    let e = calibrate_dvl(&a).expect_err("unknown parameter");
    assert!(matches!(e, CalibrationError::Options(_)), "{e:?}");
    let mut a = CalibrateDvlOptions::new(vec![spec("empty.mcap")]);
    a.bounds = vec!["dvl.mount_yaw=2,-2".into()];
    let e = calibrate_dvl(&a).expect_err("inverted bounds");
    assert!(matches!(e, CalibrationError::Options(_)), "{e:?}");

    // The data's: a voyage log that is not there, a log without any DVL message.
    let e =
        calibrate_dvl(&CalibrateDvlOptions::new(vec![spec("missing.mcap")])).expect_err("no log");
    assert!(
        matches!(&e, CalibrationError::Read { path, .. } if path.ends_with("missing.mcap"))
            && !e.is_usage(),
        "{e:?}"
    );
    let e = calibrate_dvl(&CalibrateDvlOptions::new(vec![spec("empty.mcap")])).expect_err("no DVL");
    assert!(
        matches!(&e, CalibrationError::Input(m) if m.contains("no DVL messages")),
        "{e:?}"
    );

    // The magnetometer: a recording that is not there, one too short to fit.
    let e = calibrate_mag(&CalibrateMagOptions::new(vec![dir.join("missing.csv")]))
        .expect_err("no CSV");
    assert!(
        matches!(e, CalibrationError::Import(_)) && !e.is_usage(),
        "{e:?}"
    );
    let short = dir.join("short.csv");
    std::fs::write(
        &short,
        "time_s,mag_x,mag_y,mag_z\n0.0,20,0,45\n0.1,20,1,45\n",
    )
    .expect("CSV");
    let e = calibrate_mag(&CalibrateMagOptions::new(vec![short])).expect_err("too short");
    assert!(
        matches!(&e, CalibrationError::Input(m) if m.contains("too few samples")),
        "{e:?}"
    );
    let _ = std::fs::remove_dir_all(&dir);
}
