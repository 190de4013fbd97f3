//! The simulator's failures as a typed [`SimError`]: the caller's (options, effects, a scenario
//! the trajectory cannot fly) apart from the environment's (an unreadable log, an unwritable
//! output), with the underlying error kept as the source.

use auvnav_sim::perturb::{Perturbation, perturb_log};
use auvnav_sim::scenario::Scenario;
use auvnav_sim::{SimConfig, SimError, campaign::CampaignKind, effects::Effects, simulate_to_log};
use std::error::Error;

fn scratch(name: &str) -> std::path::PathBuf {
    let dir = std::env::temp_dir().join(format!("auvnav-sim-{name}-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("scratch folder");
    dir
}

#[test]
fn failures_are_typed_the_callers_apart_from_the_environments() {
    let dir = scratch("errors");

    let e = CampaignKind::parse("atlantic").expect_err("no such campaign");
    assert!(matches!(e, SimError::Options(_)) && e.is_usage(), "{e:?}");

    let e = Perturbation::parse(&["dvl.no_such_thing=1".into()], 1).expect_err("unknown effect");
    assert!(matches!(e, SimError::Effect(_)) && e.is_usage(), "{e:?}");
    let e = Perturbation::parse(&[], 1).expect_err("no effect");
    assert!(matches!(e, SimError::Options(_)), "{e:?}");

    // A log that is not there: a read error naming it, with the log reader's error as source.
    let p = Perturbation::parse(&["dvl.mount_yaw=0.01".into()], 1).expect("a perturbation");
    let missing = dir.join("missing.mcap");
    let e = perturb_log(&missing, &dir.join("out.mcap"), &p).expect_err("no input");
    assert!(
        matches!(&e, SimError::Log { path, .. } if path == &missing) && !e.is_usage(),
        "{e:?}"
    );
    assert!(e.source().is_some(), "{e:?}");

    // An output in a folder that does not exist: an output error, and nothing left behind.
    let cfg = SimConfig {
        scenario: Scenario::load("straight").expect("built-in scenario"),
        effects: Effects::default(),
        seed: 1,
        duration_s: Some(2.0),
    };
    let out = dir.join("no-such-folder").join("sim.mcap");
    let e = simulate_to_log(&cfg, &out).expect_err("unwritable");
    assert!(
        matches!(&e, SimError::Output { path, .. } if path == &out) && !e.is_usage(),
        "{e:?}"
    );
    assert!(!out.exists());

    // A scenario the trajectory cannot fly (a depth change while stopped): the caller's, and no
    // file.
    let mut stopped = cfg.clone();
    stopped.scenario.start.speed_m_s = 0.0;
    stopped.scenario.legs = vec![auvnav_sim::scenario::Leg::Depth {
        change_m: 5.0,
        pitch_deg: 10.0,
    }];
    let flown = dir.join("stopped.mcap");
    let e = simulate_to_log(&stopped, &flown).expect_err("cannot fly");
    assert!(
        matches!(e, SimError::Trajectory(_)) && e.is_usage(),
        "{e:?}"
    );
    assert!(!flown.exists());

    // The same simulation into a writable place succeeds and perturbs.
    let good = dir.join("sim.mcap");
    let summary = simulate_to_log(&cfg, &good).expect("simulate");
    assert!(summary.imu > 0, "{summary:?}");
    let e = perturb_log(&good, &good, &p).expect_err("output equal to input");
    assert!(matches!(e, SimError::Options(_)), "{e:?}");
    let counts = perturb_log(&good, &dir.join("perturbed.mcap"), &p).expect("perturb");
    assert!(counts.dvl_changed > 0, "{counts:?}");
    let _ = std::fs::remove_dir_all(&dir);
}
