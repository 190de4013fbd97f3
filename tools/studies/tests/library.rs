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
