//! A surface run's magnetic compass against true north: the importers record the recording's
//! date and the declination already applied to the heading, and `auvnav discover` gives the
//! declination the World Magnetic Model has at the run's GNSS positions beside the heading offset
//! it estimates (`auvnav_discover::compass`).

use auvnav_tests::processes::{TempDir, auvnav_json, import_lake_run, import_pd0};

/// `auvnav discover LOG --json --no-navigation`.
fn discover(log: &std::path::Path) -> serde_json::Value {
    auvnav_json(&[
        "discover",
        &log.display().to_string(),
        "--json",
        "--no-navigation",
    ])
}

/// The report's compass entry of its only log.
fn compass(report: &serde_json::Value) -> &serde_json::Value {
    let c = report["compass"].as_array().expect("a compass entry");
    assert_eq!(c.len(), 1, "{c:?}");
    &c[0]
}

fn note(report: &serde_json::Value) -> String {
    report["notes"]
        .as_array()
        .expect("notes")
        .iter()
        .filter_map(|n| n.as_str())
        .find(|n| n.contains("magnetic compass"))
        .unwrap_or_else(|| panic!("a compass note in {}", report["notes"]))
        .to_string()
}

/// The RDI river crossing (Tanana River, Alaska, 2010-09-23): a Rio Grande's own compass with no
/// heading bias set. WMM2010 gives about 20° east there (its report's test values are the
/// core's unit test); the heading offset the data point at, about 17 ± 4°, is compared with it.
/// The RiverPro run from the same river in 2022 has WMM2020's declination.
#[test]
fn a_magnetic_compass_without_declination_is_compared_with_the_world_magnetic_model() {
    let Some(dir) = auvnav_tests::measured_data("rdi-pd0", "raw/winriver02_transect.PD0") else {
        return;
    };
    let tmp = TempDir::new("discover-compass");
    let log = tmp.path().join("wr.mcap");
    import_pd0(&dir.join("raw/winriver02_transect.PD0"), &log);
    let r = discover(&log);
    let c = compass(&r);
    assert_eq!(c["date"], "2010-09-23", "{c}");
    assert_eq!(c["model"], "WMM-2010", "{c}");
    assert_eq!(c["applied_deg"], 0.0, "{c}");
    let d = c["declination_deg"].as_f64().expect("declination");
    assert!((19.0..21.0).contains(&d), "{c}");
    assert_eq!(c["expected_mount_yaw_deg"].as_f64(), Some(d));
    assert!(
        (c["latitude_deg"].as_f64().expect("lat") - 64.56).abs() < 0.05,
        "{c}"
    );
    let n = note(&r);
    assert!(
        n.contains("pointed at here") && n.contains("from none"),
        "{n}"
    );

    let rp = tmp.path().join("rp.mcap");
    import_pd0(&dir.join("raw/RiverPro_test01.PD0"), &rp);
    let r = discover(&rp);
    let c = compass(&r);
    assert_eq!(c["model"], "WMM-2020", "{c}");
    let d = c["declination_deg"].as_f64().expect("declination");
    assert!((14.0..17.0).contains(&d), "{c}");
}

/// The SonTek M9 lake run (2025-01-17): the export added 4.49° of declination; WMM2025 gives
/// about 4.8° there, so the compass should be a third of a degree short of true north, which the
/// GNSS positions' heading offset (0.24 ± 0.14°) agrees with.
#[test]
fn a_corrected_compass_is_left_the_declination_not_applied() {
    let tmp = TempDir::new("discover-compass-lake");
    let Some(log) = import_lake_run(&tmp.path().join("lake.mcap"), &[]) else {
        return;
    };
    let r = discover(&log);
    let c = compass(&r);
    assert_eq!(c["model"], "WMM-2025", "{c}");
    let applied = c["applied_deg"].as_f64().expect("applied");
    assert!((applied - 4.49).abs() < 0.01, "{c}");
    let expected = c["expected_mount_yaw_deg"].as_f64().expect("expected");
    assert!((0.0..1.0).contains(&expected), "{c}");
    let n = note(&r);
    assert!(n.contains("estimated on the GNSS positions"), "{n}");
}
