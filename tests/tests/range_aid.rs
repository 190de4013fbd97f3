//! The range aid's measurement model against the simulator's acoustic systems: on the truth, the
//! model predicts every range the simulated device measured (no noise, no outliers) to within
//! millimetres, for the three geometries — a boat's four-receiver array, LBL beacons, a single
//! transducer on a circling ship — with the motion during the ping, the water's sound speed and
//! the boat's heading. The simulator and the aid are written apart; a difference in where either
//! places an end of the path shows here.

use auvnav_core::aid::ranges::RangeAid;
use auvnav_core::earth::Geodetic;
use auvnav_core::ekf::{ErrorFilter, StateVector};
use auvnav_core::strapdown::NavState;
use auvnav_log::LogMessage;
use auvnav_sim::{SimConfig, scenario::Scenario};

fn residuals(scenario: &str, effects: &[(&str, &[f64])]) -> Vec<f64> {
    let scenario = Scenario::load(scenario).expect("scenario");
    let mut e = scenario.effects().expect("effects");
    // Noise-free: only the geometry and the timing.
    for name in [
        "usbl.range_noise",
        "usbl.outlier_fraction",
        "imu.gyro_bias",
        "imu.accel_bias",
    ] {
        let n = e.get(name).expect("effect").len();
        e.set(name, &vec![0.0; n]).expect("set");
    }
    e.set("usbl.array_pose_noise", &[0.0, 0.0]).expect("set");
    for (name, v) in effects {
        e.set(name, v).expect("set");
    }
    let start = Geodetic {
        latitude_rad: scenario.start.latitude_deg.to_radians(),
        longitude_rad: scenario.start.longitude_deg.to_radians(),
        height_m: 0.0,
    };
    let mut cfg = scenario
        .acoustic
        .as_ref()
        .expect("[acoustic]")
        .ranges_config(&start);
    cfg.sound_speed_m_s = e.usbl_sound_speed;
    let (messages, summary) = auvnav_sim::simulate_to_vec(&SimConfig {
        scenario,
        effects: e,
        seed: 7,
        duration_s: Some(240.0),
    })
    .expect("simulation");
    assert!(summary.acoustic_pings > 200);
    let mut kf = ErrorFilter::new(&StateVector::zeros());
    let mut aid = RangeAid::new(Some(&cfg), &mut kf);
    let mut out = Vec::new();
    // A ping waits for the truth record of its time (the simulator writes the truth after the
    // sensors of the same instant), so that the track covers the whole acoustic path.
    let mut waiting = Vec::new();
    for m in &messages {
        match m {
            LogMessage::Truth(t) => {
                let s = NavState::from_truth(t);
                aid.after_imu(&s);
                for r in waiting.drain(..) {
                    for k in 0..4 {
                        if let Some(p) = aid.predicted_range(&s, &r, k, (0.0, 0.0)) {
                            out.push(r.range_m[k] - p);
                        }
                    }
                }
            }
            LogMessage::AcousticArrayPose(p) => aid.on_array_pose(p),
            LogMessage::AcousticRanges(r) if r.host_time_ns >= 5_000_000_000 => waiting.push(*r),
            _ => {}
        }
    }
    out
}

fn check(scenario: &str, effects: &[(&str, &[f64])], receivers: usize) {
    let r = residuals(scenario, effects);
    assert!(r.len() > 200 * receivers, "{scenario}: {} ranges", r.len());
    let worst = r.iter().fold(0.0f64, |m, x| m.max(x.abs()));
    let mean = r.iter().sum::<f64>() / r.len() as f64;
    println!(
        "{scenario} {effects:?}: {} ranges, worst {worst:.4} m, mean {mean:.5} m",
        r.len()
    );
    assert!(worst < 5e-3, "{scenario}: worst residual {worst} m");
}

#[test]
fn the_model_predicts_a_moving_arrays_ranges() {
    check("ranges_array", &[], 4);
}

#[test]
fn the_model_predicts_lbl_ranges() {
    check("ranges_lbl", &[], 3);
}

#[test]
fn the_model_predicts_a_ships_single_beacon_ranges_in_slower_water() {
    check("ranges_single", &[("usbl.sound_speed", &[1480.0])], 1);
}

/// The study, small: in a field of three LBL beacons in water 20 m/s faster than the device
/// assumes (a 1.3 % range scale error), with 5 % multipath outliers, the tight ranges with their
/// sound-speed state keep the vehicle within decimetres, where the device's fixes fused loosely
/// carry the scale error into the position; neither diverges, and the IMU and DVL alone drift.
#[test]
fn tight_lbl_ranges_take_a_sound_speed_error_the_devices_fixes_carry() {
    use auvnav_tools::ranges::{RangesOptions, run};
    let reports = run(&RangesOptions {
        geometry: "lbl".into(),
        outliers: 0.05,
        effects: vec!["usbl.sound_speed=1520".into()],
        settings: vec![],
        runs: 2,
        seed: 3,
        seconds: Some(400.0),
        settle_s: 60.0,
        divergence_m: 20.0,
        threads: Some(2),
        json: true,
    })
    .expect("study");
    let r = &reports[0];
    let loose = r.loose.as_ref().expect("three beacons give fixes");
    println!(
        "tight {:.3} m, loose {:.3} m, none {:.3} m",
        r.tight.horizontal_error_rms_m, loose.horizontal_error_rms_m, r.none.horizontal_error_rms_m
    );
    assert!(r.tight.horizontal_error_rms_m < 0.5 * loose.horizontal_error_rms_m);
    assert!(r.tight.horizontal_error_rms_m < 1.0);
    assert_eq!(r.tight.divergent_runs + loose.divergent_runs, 0);
    assert!(
        r.tight.fused > 2 * 340 * 3 * 8 / 10,
        "{} ranges fused",
        r.tight.fused
    );
    assert!(r.tight.rejected > 0, "the outliers are refused");
}

/// Receivers whose ranges each carry their own constant error (detection delay, cable): a bias
/// per receiver (`bias_per_receiver`) navigates at most half as far off as the shared one, and
/// finds each receiver's bias relative to the others (their common part trades against the
/// sound-speed scale) to 0.15 m, under LBL beacons and a boat's array, 10-minute runs.
#[test]
fn a_bias_per_receiver_takes_what_a_shared_bias_cannot() {
    use auvnav_tools::ranges::{RangesOptions, run};
    for (geometry, truth) in [
        ("lbl", [0.8, -0.5, 0.3, 1.0]),
        ("array", [-0.6, 0.4, 0.9, 0.0]),
    ] {
        let study = |per_receiver: bool| {
            let effect = format!(
                "usbl.receiver_range_bias={}",
                truth.map(|b| b.to_string()).join(",")
            );
            run(&RangesOptions {
                geometry: geometry.into(),
                outliers: 0.05,
                effects: vec![effect],
                settings: vec![format!("bias_per_receiver={per_receiver}")],
                runs: 3,
                seed: 9001,
                seconds: Some(600.0),
                settle_s: 60.0,
                divergence_m: 20.0,
                threads: Some(2),
                json: true,
            })
            .expect("study")
            .remove(0)
        };
        let (shared, each) = (study(false), study(true));
        println!(
            "{geometry}: shared {:.2} m, per receiver {:.2} m, biases {:?}",
            shared.tight.horizontal_error_rms_m,
            each.tight.horizontal_error_rms_m,
            each.tight.receiver_bias_mean_m
        );
        assert!(
            each.tight.horizontal_error_rms_m <= 0.5 * shared.tight.horizontal_error_rms_m,
            "{geometry}: per receiver {:.2} m, shared {:.2} m",
            each.tight.horizontal_error_rms_m,
            shared.tight.horizontal_error_rms_m
        );
        assert_eq!(each.tight.divergent_runs, 0, "{geometry}");
        let n = each.ranges.receivers_m.len();
        let centred = |b: &[f64]| {
            let mean = b[..n].iter().sum::<f64>() / n as f64;
            b[..n].iter().map(|x| x - mean).collect::<Vec<f64>>()
        };
        let (found, truth) = (centred(&each.tight.receiver_bias_mean_m), centred(&truth));
        for k in 0..n {
            assert!(
                (found[k] - truth[k]).abs() < 0.15,
                "{geometry}: receiver {k} relative bias {:.2} m, truth {:.2} m",
                found[k],
                truth[k]
            );
        }
    }
}

/// The measured G2 dive: the range aid's model, with the receivers at the places discovery finds
/// and the array placed from the topside's GNSS and heading, predicts every receiver's range
/// from the device's own fix to within a decimetre RMS, with the multipath outliers counted.
/// (The fixes come from the same ranges: this checks the model and the receivers' places
/// against the device's solution, not the vehicle's position.)
#[test]
fn the_measured_dives_ranges_agree_with_the_model_at_the_devices_fixes() {
    use auvnav_core::aid::ranges::{ArrayKind, RangesConfig};
    let Some(dir) = auvnav_tests::measured_data("ugps-g2", "2024-12-05_22-12-34_g2_acoustic.csv")
    else {
        return;
    };
    let (messages, s) = auvnav_tools::import::ugps_messages(&dir).expect("import");
    assert!(s.array_poses > 2000, "{s:?}");
    let messages: Vec<LogMessage> = messages.into_iter().map(|(_, m)| m).collect();
    use auvnav_tools::discover::command::{discover_messages, values_of};
    let r = discover_messages(messages.iter());
    let h = r
        .effects
        .iter()
        .find(|e| e.name == "usbl.hydrophone_offset")
        .and_then(|e| values_of(&e.value))
        .expect("the receivers' places are found");
    let cfg = RangesConfig {
        array: ArrayKind::Moving,
        receivers_m: (0..4)
            .map(|k| [h[3 * k], h[3 * k + 1], h[3 * k + 2]])
            .collect(),
        ..Default::default()
    };
    let m = auvnav_tools::ranges::measured_residuals(&messages, &cfg);
    println!("{}", serde_json::to_string_pretty(&m).expect("json"));
    assert!(m.fixes > 1500 && m.without_pose < m.fixes / 20, "{m:?}");
    for r in &m.receivers {
        assert!(r.ranges > 1200, "{r:?}");
        assert!(r.rms_m < 0.1, "{r:?}");
        assert!(r.outliers * 20 < r.ranges, "{r:?}");
    }
    // The device's own fix is not a per-ping solution: it scatters far less across the line of
    // sight than per-ping fixes from its ranges, and follows them smoothed by a filter of a few
    // seconds (docs/ranges.md, "The device's fix").
    let f = &m.device_fix;
    assert!(f.ping_fixes > 1200, "{f:?}");
    assert!(
        f.scatter_tangential_m < 0.5 * f.ping_scatter_tangential_m,
        "{f:?}"
    );
    assert!((1.0..=4.0).contains(&f.best_time_constant_s), "{f:?}");
}
