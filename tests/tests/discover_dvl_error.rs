//! A time-correlated DVL velocity error (`dvl.velocity_error_instability`, a first-order
//! Gauss–Markov error on each DVL-frame axis with `dvl.velocity_error_correlation_time`) hidden
//! in simulated voyages is reported in the simulator's names, beside the white `dvl.noise`, and
//! a voyage with white noise alone reports none. Seeds and magnitudes are the test's own.

use auvnav_sim::{SimConfig, scenario::Scenario};
use auvnav_tools::discover::command::{DiscoverReport, discover_messages};

fn discovered(seed: u64, duration_s: f64, hidden: &[(&str, f64)]) -> DiscoverReport {
    let mut effects = auvnav_sim::effects::Effects::default();
    effects.set("dvl.noise", &[0.005]).expect("noise");
    for (name, value) in hidden {
        effects.set(name, &[*value]).expect("hidden effect");
    }
    let messages = auvnav_tests::grade::simulate(&SimConfig {
        scenario: Scenario::load("lawnmower").expect("scenario"),
        effects,
        seed,
        duration_s: Some(duration_s),
    });
    discover_messages(&messages)
}

fn noise(r: &DiscoverReport, name: &str) -> Option<f64> {
    r.noise.iter().find(|n| n.name == name).map(|n| n.value)
}

#[test]
fn a_time_correlated_dvl_error_is_reported_in_the_simulators_names() {
    // Seed 9414: from one start of its likelihood search one axis read 0.021 m/s over 99 s.
    for (seed, sigma, tau) in [(9411, 0.02, 60.0), (9412, 0.01, 20.0), (9414, 0.01, 20.0)] {
        let r = discovered(
            seed,
            1200.0,
            &[
                ("dvl.velocity_error_instability", sigma),
                ("dvl.velocity_error_correlation_time", tau),
            ],
        );
        let found_sigma = noise(&r, "dvl.velocity_error_instability").expect("instability");
        let found_tau = noise(&r, "dvl.velocity_error_correlation_time").expect("time");
        let white = noise(&r, "dvl.noise").expect("white noise");
        println!(
            "seed {seed}: hidden {sigma} m/s, {tau} s; found {found_sigma:.4} m/s, \
             {found_tau:.1} s, white {white:.4} m/s; effects {:?}",
            r.effects.iter().map(|e| &e.name).collect::<Vec<_>>()
        );
        // Twenty to sixty correlation times: the deviation to about a fifth, the correlation
        // time to about half (a restricted-likelihood estimate on a grid of φ).
        assert!((found_sigma / sigma - 1.0).abs() < 0.25, "{found_sigma}");
        assert!((found_tau / tau).ln().abs() < 1.5f64.ln(), "{found_tau}");
        assert!((white / 0.005 - 1.0).abs() < 0.1, "{white}");
        assert!(r.effects.is_empty(), "{:#?}", r.effects);
    }
    // White noise alone: no correlated part, and dvl.noise is the residual's RMS.
    let r = discovered(9413, 600.0, &[]);
    assert_eq!(noise(&r, "dvl.velocity_error_instability"), None);
    let white = noise(&r, "dvl.noise").expect("white noise");
    assert!((white / 0.005 - 1.0).abs() < 0.1, "{white}");
}
