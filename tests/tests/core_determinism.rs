//! The navigation core is deterministic: the same ordered inputs give bit-identical outputs.

use auvnav_core::navigator::NavConfig;
use auvnav_sim::SimConfig;
use auvnav_sim::scenario::Scenario;
use auvnav_tools::demo::run_voyage;

fn solution_csv(seed: u64) -> Vec<u8> {
    let scenario = Scenario::load("turns").expect("scenario");
    let effects = scenario.effects().expect("effects");
    let cfg = SimConfig {
        scenario,
        effects,
        seed,
        duration_s: Some(200.0),
    };
    let mut out = Vec::new();
    run_voyage(&cfg, NavConfig::default(), Some(&mut out)).expect("voyage");
    out
}

#[test]
fn same_inputs_give_bit_identical_solutions() {
    let a = solution_csv(3);
    let b = solution_csv(3);
    assert!(a.len() > 100_000, "{} bytes", a.len());
    assert_eq!(a, b);
    assert_ne!(
        a,
        solution_csv(4),
        "another seed must give another solution"
    );
}
