//! Replay as a library, without the command line: a simulated log replayed with options, a typed
//! report, and the outputs written atomically.

use auvnav_replay::{ReplayOptions, replay};
use auvnav_sim::{SimConfig, scenario::Scenario};

/// `seconds` of the straight scenario simulated into `dir/name`.
fn simulated(dir: &std::path::Path, name: &str, seed: u64, seconds: f64) -> std::path::PathBuf {
    let log = dir.join(name);
    let scenario = Scenario::load("straight").expect("scenario");
    let effects = scenario.effects().expect("effects");
    auvnav_sim::simulate_to_log(
        &SimConfig {
            scenario,
            effects,
            seed,
            duration_s: Some(seconds),
        },
        &log,
    )
    .expect("simulation");
    log
}

#[test]
fn a_log_replays_through_the_library_with_a_typed_report() {
    let dir = std::env::temp_dir().join(format!("auvnav-replay-lib-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("scratch folder");
    let log = simulated(&dir, "straight.mcap", 4501, 60.0);

    let csv = dir.join("nav.csv");
    let report = replay(&ReplayOptions {
        out: Some(csv.clone()),
        decimate: 10,
        ..ReplayOptions::new(&log)
    })
    .expect("replay");
    assert_eq!(report.configuration, "defaults");
    assert!(report.samples_processed > 5000, "{report:?}");
    let accuracy = report.accuracy.expect("the log has a truth channel");
    assert!(accuracy.horizontal_error_final_m < 5.0, "{accuracy:?}");
    assert!(report.log_error.is_none());
    let rows = std::fs::read_to_string(&csv).expect("CSV").lines().count() - 1;
    // Every tenth solution (one per IMU sample, and the initial state's).
    let expected = report.samples_processed.div_ceil(10);
    assert!(
        (expected..=expected + 1).contains(&(rows as u64)),
        "{rows} rows for {} samples",
        report.samples_processed
    );
    assert!(dir.join("nav.diagnostics.csv").exists());
    assert!(!auvnav_replay::partial_path(&csv).exists());

    // A configuration that does not parse is an error naming the file, not a panic.
    let bad = dir.join("bad.toml");
    auvnav_replay::write_atomically(&bad, "[navigation]\ngyro = 'fast'\n").expect("write");
    let e = replay(&ReplayOptions {
        config: Some(bad.clone()),
        ..ReplayOptions::new(&log)
    })
    .expect_err("a bad configuration");
    assert!(format!("{e:#}").contains("bad.toml"), "{e:#}");
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn failures_are_typed_the_callers_apart_from_the_environments() {
    use auvnav_replay::ReplayError;
    let dir = std::env::temp_dir().join(format!("auvnav-replay-errors-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("scratch folder");
    let log = simulated(&dir, "short.mcap", 4502, 20.0);

    // An option out of range: the caller's.
    let e = replay(&ReplayOptions {
        min_distance: -1.0,
        ..ReplayOptions::new(&log)
    })
    .expect_err("negative distance");
    assert!(
        matches!(e, ReplayError::Options(_)) && e.is_usage(),
        "{e:?}"
    );

    // A configuration that does not parse, and one that fails validation: the caller's, with
    // the parser's or the check's error as the source.
    let bad = dir.join("bad.toml");
    std::fs::write(&bad, "[navigation\n").expect("write");
    let e = replay(&ReplayOptions {
        config: Some(bad.clone()),
        ..ReplayOptions::new(&log)
    })
    .expect_err("unparsable configuration");
    assert!(matches!(&e, ReplayError::Config { path, .. } if *path == bad) && e.is_usage());
    let source = std::error::Error::source(&e).expect("the parser's error");
    assert!(
        source.downcast_ref::<toml::de::Error>().is_some(),
        "{source:?}"
    );
    std::fs::write(&bad, "[navigation]\ncovariance_interval_s = -1.0\n").expect("write");
    let e = auvnav_replay::load_config(&bad).expect_err("invalid configuration");
    assert!(
        matches!(e, ReplayError::Config { .. }) && e.is_usage(),
        "{e:?}"
    );

    // A log that is not one, and an output that cannot be written: the environment's.
    let junk = dir.join("junk.mcap");
    std::fs::write(&junk, b"not a log").expect("write");
    let e = replay(&ReplayOptions::new(&junk)).expect_err("not a log");
    assert!(matches!(&e, ReplayError::Log { path, .. } if *path == junk) && !e.is_usage());
    let out = dir.join("missing-folder").join("nav.csv");
    let e = replay(&ReplayOptions {
        out: Some(out.clone()),
        ..ReplayOptions::new(&log)
    })
    .expect_err("unwritable output");
    assert!(
        matches!(&e, ReplayError::Output { path, .. } if *path == out),
        "{e:?}"
    );
    assert!(!out.exists());
    std::fs::remove_dir_all(&dir).ok();
}

/// A reference that describes another point of the vehicle (2 m forward, 0.3 m down) scores the
/// navigation as if it had drifted by the lever arm's turn; moved back to the IMU
/// (`reference_lever_arm`), it scores it as the IMU's own truth does.
#[test]
fn a_reference_at_another_point_is_moved_to_the_imu() {
    use auvnav_log::{LogMessage, write_log_atomically};
    use auvnav_shm_schema::topic;
    use nalgebra::{Quaternion, UnitQuaternion, Vector3};
    let dir = std::env::temp_dir().join(format!("auvnav-replay-lever-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("scratch folder");
    let scenario = Scenario::load("lawnmower").expect("scenario");
    let cfg = SimConfig {
        effects: scenario.effects().expect("effects"),
        scenario,
        seed: 4511,
        duration_s: Some(600.0),
    };
    let (messages, _) = auvnav_sim::simulate_to_vec(&cfg).expect("simulation");
    let lever = [2.0, 0.0, 0.3];
    let at_imu = dir.join("imu.mcap");
    let at_point = dir.join("point.mcap");
    for (path, moved) in [(&at_imu, false), (&at_point, true)] {
        write_log_atomically(path, &auvnav_sim::log_header(&cfg), |w| {
            for m in &messages {
                match m {
                    LogMessage::Truth(t) if moved => {
                        let [qw, qx, qy, qz] = t.quaternion_body_to_ned;
                        let q = UnitQuaternion::from_quaternion(Quaternion::new(qw, qx, qy, qz));
                        let p = auvnav_core::earth::offset_position(
                            &auvnav_core::strapdown::truth_position(t),
                            &(q * Vector3::from(lever)),
                        );
                        let mut x = *t;
                        (x.latitude_rad, x.longitude_rad, x.height_m) =
                            (p.latitude_rad, p.longitude_rad, p.height_m);
                        let omega = Vector3::from(t.angular_rate_rad_s);
                        let v = Vector3::from(t.velocity_ned_m_s)
                            + q * omega.cross(&Vector3::from(lever));
                        x.velocity_ned_m_s = [v.x, v.y, v.z];
                        w.write(topic::TRUTH, &x)?;
                    }
                    LogMessage::Truth(x) => w.write(topic::TRUTH, x)?,
                    LogMessage::Imu(x) => w.write(topic::IMU, x)?,
                    LogMessage::Dvl(x) => w.write(topic::DVL, x)?,
                    LogMessage::Depth(x) => w.write(topic::DEPTH, x)?,
                    _ => {}
                }
            }
            Ok(())
        })
        .expect("log");
    }
    let rms = |log: &std::path::Path, lever: Option<[f64; 3]>| {
        let r = replay(&ReplayOptions {
            reference_lever_arm: lever,
            ..ReplayOptions::new(log)
        })
        .expect("replay");
        r.accuracy.expect("truth").horizontal_error_rms_m
    };
    let own = rms(&at_imu, None);
    let unmoved = rms(&at_point, None);
    let moved = rms(&at_point, Some(lever));
    assert!(
        (moved - own).abs() < 0.02 * own.max(0.5),
        "IMU truth {own:.3} m, moved reference {moved:.3} m"
    );
    assert!(
        unmoved > own + 1.0,
        "a reference 2 m forward, not moved: {unmoved:.3} m against {own:.3} m"
    );
    let e = replay(&ReplayOptions {
        reference_lever_arm: Some([f64::NAN, 0.0, 0.0]),
        ..ReplayOptions::new(&at_point)
    })
    .expect_err("not a lever arm");
    assert!(e.is_usage(), "{e:?}");
    let _ = std::fs::remove_dir_all(&dir);
}
