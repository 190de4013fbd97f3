//! Several logs are several voyages: each is compared with its own reference, and the
//! installation the voyages share is fitted on all of them with each voyage held out in turn.
//! Simulated voyages of different seeds given together must give the answer one long voyage
//! gives; two logs whose time stamps overlap must not be mixed (read as one series they compare
//! one voyage's DVL with the other's motion); voyages that disagree on an installation effect
//! must report it as inconsistent, not as a finding, unless a few depart from what the rest agree
//! on (the rest share it, the few are named). Seeds and magnitudes are the tests' own.

use auvnav_log::LogMessage;
use auvnav_sim::{SimConfig, scenario::Scenario};
use auvnav_tests::grade;
use auvnav_tools::discover::command::{Collector, DiscoverReport, values_of};
use auvnav_tools::discover::fit::Selection;
use auvnav_tools::discover::voyages::{VoyageData, discover_voyages};

fn simulate(seed: u64, scenario: &str, seconds: f64, hidden: &[(&str, &[f64])]) -> Vec<LogMessage> {
    let scenario = Scenario::load(scenario).expect("scenario");
    let mut effects = scenario.effects().expect("effects");
    effects.set("dvl.noise", &[0.005]).expect("noise");
    for (name, value) in hidden {
        effects.set(name, value).expect("hidden effect");
    }
    grade::simulate(&SimConfig {
        scenario,
        effects,
        seed,
        duration_s: Some(seconds),
    })
}

fn voyage(log: &str, messages: &[LogMessage]) -> VoyageData {
    let mut c = Collector::new();
    for m in messages {
        c.add(m);
    }
    let (channels, reference) = c.finish();
    VoyageData {
        log: log.into(),
        channels,
        reference,
    }
}

fn together(voyages: &[VoyageData]) -> DiscoverReport {
    discover_voyages(voyages, &Default::default(), 0.7, &Selection::default())
}

/// (value, std) of a DVL effect the report names.
fn named(r: &DiscoverReport, name: &str) -> Option<(f64, f64)> {
    r.effects.iter().find(|e| e.name == name).map(|e| {
        (
            values_of(&e.value).expect("value")[0],
            values_of(&e.std).expect("std")[0],
        )
    })
}

fn dvl_names(r: &DiscoverReport) -> Vec<String> {
    let mut n: Vec<String> = r
        .effects
        .iter()
        .filter(|e| e.name.starts_with("dvl."))
        .map(|e| e.name.clone())
        .collect();
    n.sort();
    n
}

const YAW: f64 = 1.2;
const SCALE: f64 = 0.995;

#[test]
fn voyages_of_different_seeds_give_the_answer_of_one_long_voyage() {
    let hidden: &[(&str, &[f64])] = &[("dvl.mount_yaw", &[YAW]), ("dvl.scale_factor", &[SCALE])];
    let voyages: Vec<VoyageData> = [7101u64, 7102, 7103]
        .iter()
        .map(|&seed| {
            voyage(
                &format!("seed {seed}"),
                &simulate(seed, "lawnmower", 400.0, hidden),
            )
        })
        .collect();
    let three = together(&voyages);
    let long = {
        let v = voyage("seed 7104", &simulate(7104, "lawnmower", 1200.0, hidden));
        auvnav_tools::discover::command::discover(
            &v.channels,
            &v.reference,
            &Default::default(),
            0.7,
            &Selection::default(),
        )
    };
    println!("three voyages: {:?}", dvl_names(&three));
    println!("one voyage: {:?}", dvl_names(&long));
    assert_eq!(
        dvl_names(&three),
        ["dvl.mount_yaw", "dvl.scale_factor"],
        "{:#?}",
        three.effects
    );
    assert_eq!(dvl_names(&long), dvl_names(&three));
    let v = three.voyages.as_ref().expect("voyages");
    assert!(v.inconsistent.is_empty(), "{:#?}", v.inconsistent);
    for s in &v.shared {
        assert!(s.chi2 <= s.chi2_limit, "{s:#?}");
        assert_eq!(s.voyages.len(), 3);
    }
    for (name, hidden) in [("dvl.mount_yaw", YAW), ("dvl.scale_factor", SCALE)] {
        let (a, sa) = named(&three, name).expect("named by the voyages");
        let (b, sb) = named(&long, name).expect("named by the long voyage");
        println!("{name}: voyages {a:.5} ± {sa:.5}, one voyage {b:.5} ± {sb:.5}, hidden {hidden}");
        let change = |x: f64| {
            if name == "dvl.scale_factor" {
                x - 1.0
            } else {
                x
            }
        };
        assert!(
            (change(a) - change(hidden)).abs() <= 0.1 * change(hidden).abs(),
            "{name}: {a} for {hidden}"
        );
        assert!(
            (a - b).abs() <= 3.0 * sa.hypot(sb),
            "{name}: voyages {a} ± {sa}, one voyage {b} ± {sb}"
        );
    }
    // Each voyage's held-out model carries the installation fitted on the other two.
    for m in &v.held_out_models {
        assert!(
            (m.dvl_mount_yaw - YAW).abs() < 0.1 * YAW,
            "{}",
            m.dvl_mount_yaw
        );
    }
}

#[test]
fn logs_whose_times_overlap_are_not_mixed() {
    // Two voyages over the same clock (both start at zero), on different tracks.
    let hidden: &[(&str, &[f64])] = &[("dvl.mount_yaw", &[YAW])];
    let a = simulate(7201, "lawnmower", 400.0, hidden);
    let b = simulate(7202, "docking", 400.0, hidden);
    let r = together(&[voyage("lawnmower", &a), voyage("docking", &b)]);
    println!(
        "voyages: {:?} {:?}",
        dvl_names(&r),
        named(&r, "dvl.mount_yaw")
    );
    assert_eq!(dvl_names(&r), ["dvl.mount_yaw"], "{:#?}", r.effects);
    let (yaw, std) = named(&r, "dvl.mount_yaw").expect("yaw");
    assert!((yaw - YAW).abs() <= 0.1 * YAW, "{yaw} ± {std}");
    // Read as one series, each voyage's DVL meets the other's motion where their times
    // overlap: the residual is the difference of two tracks, not a sensor error.
    let pooled = {
        let mut c = Collector::new();
        for m in a.iter().chain(&b) {
            c.add(m);
        }
        let (channels, reference) = c.finish();
        auvnav_tools::discover::command::discover(
            &channels,
            &reference,
            &Default::default(),
            0.7,
            &Selection::default(),
        )
    };
    let mse = |r: &DiscoverReport| {
        r.channels
            .iter()
            .find(|c| c.channel.name() == "dvl")
            .map(|c| c.held_out_mse_selected)
            .expect("dvl analysed")
    };
    let alone = r.voyages.as_ref().expect("voyages").voyages[0].clone();
    println!(
        "pooled: {:?}, DVL held-out mean square {:.3e} against {:.3e} for a voyage alone",
        dvl_names(&pooled),
        mse(&pooled),
        mse(&alone)
    );
    assert!(mse(&pooled) > 100.0 * mse(&alone));
}

#[test]
fn voyages_that_disagree_are_reported_inconsistent() {
    let voyages = [
        voyage(
            "yaw +1",
            &simulate(7301, "lawnmower", 400.0, &[("dvl.mount_yaw", &[1.0])]),
        ),
        voyage(
            "yaw -1",
            &simulate(7302, "lawnmower", 400.0, &[("dvl.mount_yaw", &[-1.0])]),
        ),
    ];
    let r = together(&voyages);
    let v = r.voyages.as_ref().expect("voyages");
    println!(
        "named {:?}; inconsistent {:?}",
        dvl_names(&r),
        v.inconsistent
            .iter()
            .map(|s| (&s.name, s.chi2, s.chi2_limit))
            .collect::<Vec<_>>()
    );
    assert!(named(&r, "dvl.mount_yaw").is_none(), "{:#?}", r.effects);
    let yaw = v
        .inconsistent
        .iter()
        .find(|s| s.name == "dvl.mount_yaw")
        .expect("the yaw reported as inconsistent");
    assert!(yaw.chi2 > yaw.chi2_limit);
    // Each voyage alone names its own yaw.
    for (x, hidden) in v.voyages.iter().zip([1.0, -1.0]) {
        let (y, _) = named(x, "dvl.mount_yaw").expect("named alone");
        assert!((y - hidden).abs() < 0.1, "{y} for {hidden}");
    }
}

#[test]
fn a_voyage_that_departs_does_not_stop_the_others_sharing_the_installation() {
    // Three voyages with one installation, one with another (a remounted DVL, a reference of
    // its own): the three share the yaw, the fourth is named as departing and fits its own.
    let mut voyages: Vec<VoyageData> = [7311u64, 7312, 7313]
        .iter()
        .map(|&seed| {
            voyage(
                &format!("seed {seed}"),
                &simulate(seed, "lawnmower", 400.0, &[("dvl.mount_yaw", &[YAW])]),
            )
        })
        .collect();
    voyages.push(voyage(
        "remounted",
        &simulate(7314, "lawnmower", 400.0, &[("dvl.mount_yaw", &[-1.0])]),
    ));
    let r = together(&voyages);
    let v = r.voyages.as_ref().expect("voyages");
    for s in v.shared.iter().chain(&v.inconsistent) {
        println!("{} {} ± {}: {}", s.name, s.value, s.std, s.verdict);
    }
    let (yaw, std) = named(&r, "dvl.mount_yaw").expect("the yaw shared by the three");
    assert!((yaw - YAW).abs() <= 0.05 * YAW, "{yaw} ± {std}");
    let shared = v
        .shared
        .iter()
        .find(|s| s.name == "dvl.mount_yaw")
        .expect("shared");
    assert_eq!(shared.departing, ["remounted"]);
    assert!(
        !v.inconsistent.iter().any(|s| s.name == "dvl.mount_yaw"),
        "{:#?}",
        v.inconsistent
    );
    // The departing voyage's own estimate is its own yaw, not the others'.
    let own = values_of(&shared.voyages[3].value).expect("value")[0];
    assert!((own + 1.0).abs() < 0.1, "{own}");
}

#[test]
fn what_the_voyages_point_at_without_determining_is_reported() {
    // A 0.4 % scale under a DVL error correlated over about a minute, in three voyages of the
    // benchmark's trial motion: the voyages agree on it and it lowers their held-out score,
    // but their combined deviation leaves it under the 5σ test. It must be listed as pointed
    // at (with a value that covers the hidden one), not named and not left unsaid.
    use auvnav_tools::discover::analysis::read_logs;
    use auvnav_tools::discover::hidden_effects::{coloured, simulate};
    let dir = tempfile_dir("pointed");
    let voyages: Vec<VoyageData> = (0..3u64)
        .map(|i| {
            let s = 7411 * 16 + i;
            let mut all = coloured(s);
            all.push(("dvl.scale_factor".into(), vec![0.996]));
            let log = simulate(s, &all, &dir).expect("simulated");
            let (channels, reference, _) = read_logs(std::slice::from_ref(&log)).expect("read");
            VoyageData {
                log: format!("voyage {}", i + 1),
                channels,
                reference,
            }
        })
        .collect();
    let r = together(&voyages);
    let _ = std::fs::remove_dir_all(&dir);
    for u in &r.undetermined {
        println!("{}", u.note);
    }
    assert!(named(&r, "dvl.scale_factor").is_none(), "{:#?}", r.effects);
    let u = r
        .undetermined
        .iter()
        .find(|u| u.name == "dvl.scale_factor")
        .expect("the scale listed as pointed at");
    let (v, s) = (
        values_of(&u.value).expect("value")[0],
        values_of(&u.std).expect("std")[0],
    );
    assert!(u.sigmas < 5.0 && u.held_out_after < u.held_out_before);
    assert!((v - 0.996).abs() <= 3.0 * s, "{v} ± {s}");
}

fn tempfile_dir(name: &str) -> std::path::PathBuf {
    let d = std::env::temp_dir().join(format!("auvnav-{name}-{}", std::process::id()));
    std::fs::create_dir_all(&d).expect("temporary directory");
    d
}
