//! `auvnav discover --reference smoothed`: the log's own IMU, DVL and depth, smoothed with the
//! DVL installation as filter states, are the motion the sensors are compared with. A DVL lever
//! arm and time offset hidden in a simulated docking voyage (turns, climbs and descents excite
//! them) must come out against that motion as they do against the simulated truth, with nothing
//! else named (the smoothed motion's own heading and scale uncertainty is the smoother's, and
//! counts in the deviations), and the truth, read as a DVL on the vehicle against the smoothed
//! motion, must show no installation of its own (it is the IMU's motion). Seeds and magnitudes
//! are the tests' own.

use auvnav_tests::processes::TempDir;

use auvnav_tests::processes::auvnav_json as auvnav;

fn effect(r: &serde_json::Value, name: &str) -> Option<(Vec<f64>, Vec<f64>)> {
    let e = r["effects"]
        .as_array()?
        .iter()
        .find(|e| e["name"] == name)?
        .clone();
    let nums = |v: &serde_json::Value| -> Vec<f64> {
        match v {
            serde_json::Value::Array(a) => a.iter().filter_map(|x| x.as_f64()).collect(),
            x => x.as_f64().into_iter().collect(),
        }
    };
    Some((nums(&e["value"]), nums(&e["std"])))
}

#[test]
fn a_hidden_dvl_installation_is_found_against_the_smoothed_motion() {
    let tmp = TempDir::new("discover-smoothed");
    let log = tmp.path().join("hidden.mcap").display().to_string();
    let (lever, offset) = ([-1.2, 0.0, 0.4], 0.3);
    let sim = auvnav(&[
        "sim",
        "--scenario",
        "docking",
        "--seed",
        "7401",
        "--effect",
        "dvl.lever_arm=-1.2,0.0,0.4",
        "--effect",
        "dvl.time_offset=0.3",
        "--out",
        &log,
        "--json",
    ]);
    assert!(!sim.is_null());
    let truth = auvnav(&["discover", &log, "--no-navigation", "--json"]);
    let smoothed = auvnav(&[
        "discover",
        &log,
        "--reference",
        "smoothed",
        "--no-navigation",
        "--json",
    ]);
    for (name, r) in [("truth", &truth), ("smoothed", &smoothed)] {
        let names: Vec<&str> = r["effects"]
            .as_array()
            .expect("effects")
            .iter()
            .filter_map(|e| e["name"].as_str())
            .collect();
        println!(
            "against {name}: {names:?}; lever arm {:?}; time offset {:?}",
            effect(r, "dvl.lever_arm"),
            effect(r, "dvl.time_offset")
        );
    }
    let dvl = |r: &serde_json::Value| -> Vec<String> {
        let mut n: Vec<String> = r["effects"]
            .as_array()
            .expect("effects")
            .iter()
            .filter_map(|e| e["name"].as_str())
            .filter(|n| n.starts_with("dvl."))
            .map(String::from)
            .collect();
        n.sort();
        n
    };
    assert_eq!(dvl(&smoothed), ["dvl.lever_arm", "dvl.time_offset"]);
    assert_eq!(dvl(&truth), dvl(&smoothed));
    let (l, ls) =
        effect(&smoothed, "dvl.lever_arm").expect("lever arm against the smoothed motion");
    for k in 0..3 {
        assert!(
            (l[k] - lever[k]).abs() <= 0.1 * lever[k].abs() + 3.0 * ls[k],
            "lever arm {k}: {} ± {} for {}",
            l[k],
            ls[k],
            lever[k]
        );
    }
    let (t, ts) =
        effect(&smoothed, "dvl.time_offset").expect("time offset against the smoothed motion");
    assert!(
        (t[0] - offset).abs() <= 0.1 * offset + 3.0 * ts[0],
        "time offset {} ± {} for {offset}",
        t[0],
        ts[0]
    );
    // No IMU channel against the IMU's own motion.
    let channels: Vec<&str> = smoothed["channels"]
        .as_array()
        .expect("channels")
        .iter()
        .filter_map(|c| c["channel"].as_str())
        .collect();
    assert!(
        !channels.contains(&"gyro") && !channels.contains(&"accelerometer"),
        "{channels:?}"
    );
    // The simulated truth is the IMU's motion: read as a DVL, it has no lever arm or lag.
    let against = &smoothed["reference_against_imu"][0];
    println!("truth against the smoothed motion: {against}");
    let found = against["effects"].as_array().expect("effects");
    assert!(
        !found
            .iter()
            .any(|e| e[0] == "dvl.lever_arm" || e[0] == "dvl.time_offset"),
        "{found:?}"
    );
}
