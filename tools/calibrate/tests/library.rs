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
