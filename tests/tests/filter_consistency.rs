//! Filter consistency on simulation: with sensor errors drawn from the statistics the filter
//! assumes, the run-averaged NEES of position, velocity and attitude stays inside its 95 % bounds.
//! A small Monte Carlo here (the tool's default is 50 runs of the whole scenario:
//! `auvnav montecarlo nees`).

use auvnav_core::navigator::NavConfig;
use auvnav_tools::montecarlo::{NeesOptions, nees_monte_carlo};

fn args(runs: usize, seconds: f64, seed: u64) -> NeesOptions {
    NeesOptions {
        runs,
        scenario: "lawnmower".into(),
        seconds: Some(seconds),
        seed,
        dvl_beam_noise: 0.01,
        skip_seconds: 10.0,
        config: None,
        series: None,
        json: false,
    }
}

#[test]
fn nees_stays_inside_its_95_percent_bounds() {
    let r = nees_monte_carlo(&args(16, 240.0, 3001), &NavConfig::default()).expect("monte carlo");
    eprintln!(
        "bounds [{:.3}, {:.3}] position {:?} velocity {:?} attitude {:?}",
        r.lower_bound, r.upper_bound, r.position, r.velocity, r.attitude
    );
    for (name, b) in [
        ("position", &r.position),
        ("velocity", &r.velocity),
        ("attitude", &r.attitude),
    ] {
        assert!(
            (r.lower_bound..=r.upper_bound).contains(&b.mean_anees),
            "{name}: mean ANEES {} outside [{}, {}]",
            b.mean_anees,
            r.lower_bound,
            r.upper_bound
        );
        // Epochs are strongly correlated, so a few independent draws decide this fraction; 90 %
        // leaves room for that and still fails a filter that is over- or under-confident by 30 %.
        assert!(b.fraction_inside >= 0.9, "{name}: {b:?}");
    }
}

#[test]
fn an_overconfident_filter_fails_the_nees_check() {
    // The same runs with the filter told that the IMU is 3x quieter than the simulated one.
    let mut cfg = NavConfig::default();
    let r_true = nees_monte_carlo(&args(8, 240.0, 3001), &cfg).expect("monte carlo");
    cfg.gyro_angle_random_walk_deg_sqrt_h /= 3.0;
    cfg.accel_velocity_random_walk_m_s_sqrt_h /= 3.0;
    cfg.dvl_velocity_std_m_s /= 3.0;
    cfg.initial_heading_std_deg /= 3.0;
    // The simulated errors follow the configuration, so build them from the honest one and run
    // the filter with the overconfident one.
    let r = auvnav_tools::montecarlo::nees_monte_carlo_with(
        &args(8, 240.0, 3001),
        &NavConfig::default(),
        &cfg,
    )
    .expect("monte carlo");
    assert!(
        r.attitude.mean_anees > 2.0 * r_true.attitude.mean_anees,
        "{:?} vs {:?}",
        r.attitude,
        r_true.attitude
    );
    assert!(r.attitude.fraction_inside < 0.5, "{:?}", r.attitude);
}
