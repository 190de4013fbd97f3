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

#[test]
fn failures_are_typed_the_callers_apart_from_the_logs() {
    use auvnav_discover::DiscoverError;
    use auvnav_discover::command::{DiscoverOptions, run};
    let dir = std::env::temp_dir().join(format!("auvnav-discover-errors-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("scratch folder");
    let options = |logs: Vec<std::path::PathBuf>| DiscoverOptions {
        json: true,
        no_navigation: true,
        ..DiscoverOptions::new(logs)
    };
    let missing = dir.join("missing.mcap");

    let mut a = options(vec![missing.clone()]);
    a.fit_fraction = 1.0;
    let e = run(&a).expect_err("fit fraction 1");
    assert!(
        matches!(e, DiscoverError::Options(_)) && e.is_usage(),
        "{e:?}"
    );

    let mut a = options(vec![missing.clone()]);
    a.effects = vec!["dvl.no_such_effect=1".into()];
    let e = run(&a).expect_err("unknown effect");
    assert!(
        matches!(e, DiscoverError::Effect(_)) && e.is_usage(),
        "{e:?}"
    );

    let not_a_report = dir.join("not-a-report.json");
    std::fs::write(&not_a_report, "{\"colour\": 1}").expect("JSON");
    let mut a = options(vec![missing.clone()]);
    a.nominal_from = Some(not_a_report.clone());
    let e = run(&a).expect_err("not a report");
    assert!(
        matches!(&e, DiscoverError::Nominal { path, .. } if path == &not_a_report) && e.is_usage(),
        "{e:?}"
    );

    let e = run(&options(vec![missing.clone()])).expect_err("no log");
    assert!(
        matches!(&e, DiscoverError::Read { path, .. } if path == &missing) && !e.is_usage(),
        "{e:?}"
    );
    let _ = std::fs::remove_dir_all(&dir);
}
