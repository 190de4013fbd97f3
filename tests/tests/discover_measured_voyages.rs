//! Model discovery on measured data analysed as several voyages: an installation hidden with
//! `perturb` in six Snapir segments is found from what the recorded segments contain. Under CI
//! the data must be present.

use auvnav_tests::processes::import_snapir;
use auvnav_tools::discover::command::values_of;
use auvnav_tools::discover::fit::Selection;

/// Hidden in measured data, several voyages at once: six Snapir segments, each with the same
/// mounting yaw and velocity scale added (`perturb`), discovered together as voyages and
/// compared with the same six segments as recorded, both without `--nominal-from`. The change
/// of the shared yaw from what the recorded six contain (named, or fitted with every DVL
/// candidate where it is below the test) must be the hidden one within 10 %. The scale: the recorded segments
/// disagree on it (segment 6 by about 0.8 %, beyond the deviations), so it must be either named
/// in both runs with the hidden change, or reported as inconsistent in both with the same
/// voyages set aside and the hidden change between what the others agree on, or, where no set
/// of voyages agrees, the change between fits of every DVL candidate on each segment.
#[test]
fn a_hidden_installation_is_found_across_measured_voyages() {
    use auvnav_sim::perturb::{Perturbation, perturb_log};
    use auvnav_tests::processes::TempDir;
    use auvnav_tools::discover::command::read_logs;
    use auvnav_tools::discover::voyages::{VoyageData, discover_voyages};
    let Some(dir) = auvnav_tests::measured_data("snapir-auv", "imu_01.csv") else {
        return;
    };
    let tmp = TempDir::new("discover-voyages-measured");
    let (yaw, scale) = (1.1, 0.996);
    let p = Perturbation::parse(
        &[
            format!("dvl.mount_yaw={yaw}"),
            format!("dvl.scale_factor={scale}"),
        ],
        1,
    )
    .expect("perturbation");
    let (mut recorded, mut perturbed) = (Vec::new(), Vec::new());
    for segment in [1u32, 3, 4, 6, 8, 9] {
        let base = tmp.path().join(format!("s{segment}.mcap"));
        import_snapir(&dir, segment, &base);
        let hidden = tmp.path().join(format!("p{segment}.mcap"));
        perturb_log(&base, &hidden, &p).expect("perturb");
        for (path, to) in [(base, &mut recorded), (hidden, &mut perturbed)] {
            let (channels, reference, _) = read_logs(std::slice::from_ref(&path)).expect("read");
            to.push(VoyageData {
                log: format!("segment {segment}"),
                channels,
                reference,
            });
        }
    }
    let run =
        |v: &[VoyageData]| discover_voyages(v, &Default::default(), 0.7, &Selection::default());
    let (a, b) = (run(&recorded), run(&perturbed));
    let first = |v: &serde_json::Value| values_of(v).expect("numeric")[0];
    let named = |r: &auvnav_tools::discover::command::DiscoverReport, name: &str| {
        r.effects
            .iter()
            .find(|e| e.name == name)
            .map(|e| first(&e.value))
    };
    // The recorded segments' own yaw (about −0.14°) may be below the test: then what they
    // contain is taken from a fit of every DVL candidate on each (information-weighted over
    // the six), as on one segment, so that the change is measured from what the data hold.
    let contained_in = |voyages: &[VoyageData], name: &str| {
        use auvnav_tools::discover::{ChannelKind, fit::Problem};
        let (mut sum, mut weight) = (0.0, 0.0);
        for v in voyages {
            let dvl = v
                .channels
                .iter()
                .find(|c| c.kind == ChannelKind::Dvl)
                .expect("DVL channel");
            let p = Problem::new(dvl, &v.reference, Default::default());
            let all = p.candidates();
            let f = p.fit(&all, &p.epochs);
            let k = all
                .iter()
                .position(|&c| auvnav_tools::discover::fit::name(c) == name)
                .map(|i| auvnav_tools::discover::fit::offset_of(&all, all[i]).0)
                .expect("a DVL candidate");
            let w = 1.0 / (f.std[k] * f.std[k]);
            sum += w * f.theta[k];
            weight += w;
        }
        sum / weight
    };
    let (y0, y1) = (
        named(&a, "dvl.mount_yaw").unwrap_or_else(|| contained_in(&recorded, "dvl.mount_yaw")),
        named(&b, "dvl.mount_yaw").expect("the hidden yaw found"),
    );
    eprintln!("yaw {y0:.4} -> {y1:.4} deg (hidden +{yaw})");
    assert!(
        ((y1 - y0) - yaw).abs() <= 0.1 * yaw,
        "yaw change {}",
        y1 - y0
    );
    // What the voyages that agree on the scale agree on, when it is not named: the voyages
    // disagree (inconsistent), or a few depart and the rest do not confirm it (not confirmed).
    let agreeing = |r: &auvnav_tools::discover::command::DiscoverReport| {
        let v = r.voyages.as_ref().expect("voyages");
        let of = |name: &str| name == "dvl.scale_factor";
        v.inconsistent
            .iter()
            .find(|s| of(&s.name))
            .and_then(|s| s.agreeing.clone())
            .or_else(|| {
                v.not_confirmed
                    .iter()
                    .find(|s| of(&s.name))
                    .and_then(|s| s.agreeing.clone())
            })
    };
    match (named(&a, "dvl.scale_factor"), named(&b, "dvl.scale_factor")) {
        (Some(s0), Some(s1)) => {
            eprintln!("scale {s0:.5} -> {s1:.5} (hidden x{scale})");
            assert!(((s1 / s0 - 1.0) - (scale - 1.0)).abs() <= 0.1 * (1.0 - scale));
        }
        (s0, s1) if agreeing(&a).is_none() || agreeing(&b).is_none() => {
            // Not named on one side and no set of voyages agreeing on it: the change measured
            // from what the data hold, a fit of every DVL candidate on each segment
            // (information-weighted over the six), the same on both sides.
            let (s0, s1) = (
                s0.unwrap_or_else(|| contained_in(&recorded, "dvl.scale_factor")),
                s1.unwrap_or_else(|| contained_in(&perturbed, "dvl.scale_factor")),
            );
            eprintln!("scale {s0:.5} -> {s1:.5} (hidden x{scale}, fitted where not named)");
            assert!(
                ((s1 / s0 - 1.0) - (scale - 1.0)).abs() <= 0.1 * (1.0 - scale),
                "scale change {}",
                s1 / s0 - 1.0
            );
        }
        _ => {
            let (g0, g1) = (
                agreeing(&a).expect("the scale named, or what the voyages agree on"),
                agreeing(&b).expect("the scale named, or what the voyages agree on"),
            );
            eprintln!(
                "scale not named; without {:?}: {} -> {} (hidden x{scale})",
                g1.left_out, g0.value, g1.value
            );
            assert_eq!(g0.left_out, g1.left_out);
            let (s0, s1) = (first(&g0.value), first(&g1.value));
            assert!(
                ((s1 / s0 - 1.0) - (scale - 1.0)).abs() <= 0.1 * (1.0 - scale),
                "scale change {}",
                s1 / s0 - 1.0
            );
        }
    }
}
