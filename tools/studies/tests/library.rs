//! A study as a library, without the command line: a short filter-consistency Monte Carlo gives a
//! typed report whose runs do not depend on the number of threads.

use auvnav_core::navigator::NavConfig;
use auvnav_studies::nees::{NeesOptions, nees_monte_carlo};

#[test]
fn a_nees_study_runs_through_the_library() {
    let args = NeesOptions {
        runs: 3,
        scenario: "lawnmower".into(),
        seconds: Some(60.0),
        seed: 4601,
        dvl_beam_noise: 0.01,
        skip_seconds: 10.0,
        config: None,
        series: None,
        json: true,
    };
    let r = nees_monte_carlo(&args, &NavConfig::default()).expect("study");
    assert_eq!(r.runs, 3);
    assert!(r.epochs > 40, "{} epochs", r.epochs);
    assert!(r.lower_bound < 3.0 && 3.0 < r.upper_bound);
    for b in [&r.position, &r.velocity, &r.attitude] {
        assert!(b.mean_anees.is_finite() && b.mean_anees > 0.0, "{b:?}");
    }
    // Each run depends only on its seed: the same arguments give the same report.
    let again = nees_monte_carlo(&args, &NavConfig::default()).expect("study");
    assert_eq!(again.position.mean_anees, r.position.mean_anees);
}

#[test]
fn failures_are_typed_the_callers_apart_from_the_runs() {
    use auvnav_studies::StudyError;
    use auvnav_studies::runs::RunStudy;
    let args = NeesOptions {
        runs: 2,
        scenario: "lawnmower".into(),
        seconds: Some(30.0),
        seed: 4602,
        dvl_beam_noise: 0.01,
        skip_seconds: 5.0,
        config: None,
        series: None,
        json: true,
    };
    let cfg = NavConfig::default();

    let e = nees_monte_carlo(
        &NeesOptions {
            runs: 0,
            ..args.clone()
        },
        &cfg,
    )
    .expect_err("0 runs");
    assert!(matches!(e, StudyError::Options(_)) && e.is_usage(), "{e:?}");

    let e = nees_monte_carlo(
        &NeesOptions {
            scenario: "no-such-scenario".into(),
            ..args.clone()
        },
        &cfg,
    )
    .expect_err("unknown scenario");
    assert!(
        matches!(e, StudyError::Simulation(_)) && e.is_usage(),
        "{e:?}"
    );

    // A filter whose bias walk cannot be simulated within its own initial uncertainty.
    let mut walking = cfg.clone();
    walking.gyro_bias_walk_deg_h_sqrt_h = 1.0e3;
    let e = nees_monte_carlo(&args, &walking).expect_err("unsimulatable");
    assert!(e.is_usage(), "{e:?}");

    // The report refuses run results that are not the study's.
    let study = auvnav_studies::nees::NeesStudy::new(&args, &cfg, &cfg).expect("study");
    let e = study.report(Vec::new(), 0.0).expect_err("no runs");
    assert!(
        matches!(e, StudyError::Results(_)) && !e.is_usage(),
        "{e:?}"
    );
    let e = auvnav_studies::runs::decode_run::<auvnav_studies::nees::NeesRun>(&[0xff; 3])
        .expect_err("not a run");
    assert!(matches!(e, StudyError::RunBytes(_)), "{e:?}");
}
