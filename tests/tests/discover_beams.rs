//! `auvnav discover --dvl-beams`: the DVL compared through its four beam velocities. A 2 % scale
//! error hidden on one beam is found as that beam's `dvl.beam_scale_factor`, not averaged into
//! the installation; a mounting yaw and a velocity scale factor are named as such, not as four
//! beam scales (on a vehicle moving straight ahead the beam scales reproduce any change of the
//! four readings, so the selection keeps the set with the fewest parameters that explains the
//! data); a clean voyage gives no DVL effect. Seeds and magnitudes are the tests' own.

use auvnav_sim::{SimConfig, scenario::Scenario};
use auvnav_tests::grade;
use auvnav_tools::discover::command::{Collector, DiscoverReport, discover_messages_with};

fn run(seed: u64, scenario: &str, hidden: &[(&str, &[f64])]) -> DiscoverReport {
    let scenario = Scenario::load(scenario).expect("scenario");
    let mut effects = scenario.effects().expect("effects");
    effects.set("dvl.noise", &[0.005]).expect("noise");
    for (name, value) in hidden {
        effects.set(name, value).expect("hidden effect");
    }
    let cfg = SimConfig {
        scenario,
        effects,
        seed,
        duration_s: Some(500.0),
    };
    let messages = grade::simulate(&cfg);
    discover_messages_with(Collector::new().with_dvl_beams(true), &messages)
}

fn dvl_effects(r: &DiscoverReport) -> Vec<(String, Vec<f64>, Vec<f64>)> {
    r.effects
        .iter()
        .filter(|e| e.name.starts_with("dvl."))
        .map(|e| {
            let v = auvnav_tools::discover::command::values_of(&e.value).expect("value");
            let s = auvnav_tools::discover::command::values_of(&e.std).expect("std");
            (e.name.clone(), v, s)
        })
        .collect()
}

#[test]
fn one_beams_scale_error_is_found_on_that_beam() {
    for (seed, beam) in [(4101u64, 1usize), (4102, 3)] {
        let mut hidden = [0.0; 4];
        hidden[beam] = 20_000.0;
        let r = run(seed, "lawnmower", &[("dvl.beam_scale_factor", &hidden)]);
        let found = dvl_effects(&r);
        println!("seed {seed}, beam {}: {found:?}", beam + 1);
        assert_eq!(found.len(), 1, "{found:?}");
        let (name, v, s) = &found[0];
        assert_eq!(name, "dvl.beam_scale_factor");
        for k in 0..4 {
            assert!(
                (v[k] - hidden[k]).abs() < 5.0 * s[k],
                "beam {}: {} ± {} for {}",
                k + 1,
                v[k],
                s[k],
                hidden[k]
            );
        }
        assert!(
            r.channels.iter().any(|c| c.channel.name() == "dvl_beams"),
            "the beams were analysed"
        );
    }
}

#[test]
fn an_installation_error_is_named_as_the_installation() {
    let r = run(
        4201,
        "lawnmower",
        &[("dvl.mount_yaw", &[-1.2]), ("dvl.scale_factor", &[0.995])],
    );
    let found = dvl_effects(&r);
    println!("{found:?}");
    let names: Vec<&str> = found.iter().map(|f| f.0.as_str()).collect();
    assert_eq!(names.len(), 2, "{found:?}");
    assert!(names.contains(&"dvl.mount_yaw") && names.contains(&"dvl.scale_factor"));
    for (name, v, s) in &found {
        let truth = if name == "dvl.mount_yaw" { -1.2 } else { 0.995 };
        assert!(
            (v[0] - truth).abs() < 5.0 * s[0],
            "{name}: {} ± {}",
            v[0],
            s[0]
        );
    }
    // The aliasing is said.
    assert!(
        r.unseparable
            .iter()
            .any(|u| u.effects.iter().any(|e| e == "dvl.beam_scale_factor")),
        "{:#?}",
        r.unseparable
    );
}

#[test]
fn a_clean_voyage_gives_no_dvl_effect() {
    let r = run(4301, "lawnmower", &[]);
    let found = dvl_effects(&r);
    assert!(found.is_empty(), "{found:?}");
}
