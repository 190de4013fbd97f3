//! Discovery as a library, without the command line: a DVL scale factor hidden in a simulated
//! voyage is named, with its value, in a typed report.

use auvnav_discover::command::discover_messages;
use auvnav_sim::{SimConfig, scenario::Scenario};

#[test]
fn a_hidden_dvl_scale_is_discovered_through_the_library() {
    let scenario = Scenario::load("lawnmower").expect("scenario");
    let mut effects = scenario.effects().expect("effects");
    effects
        .set("dvl.scale_factor", &[1.008])
        .expect("a DVL scale factor of 1.008");
    let (messages, _) = auvnav_sim::simulate_to_vec(&SimConfig {
        scenario,
        effects,
        seed: 4701,
        duration_s: Some(600.0),
    })
    .expect("simulation");
    let r = discover_messages(&messages);
    let scale = r
        .effects
        .iter()
        .find(|e| e.name == "dvl.scale_factor")
        .unwrap_or_else(|| {
            panic!(
                "not named; found {:?}",
                r.effects.iter().map(|e| &e.name).collect::<Vec<_>>()
            )
        });
    let value = scale.value.as_f64().expect("a number");
    assert!((value - 1.008).abs() < 0.0005, "{value}");
}
