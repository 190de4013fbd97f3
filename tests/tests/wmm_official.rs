//! The world magnetic model against the official NOAA test values of WMM2015, WMM2020 and
//! WMM2025 (`../shared/data/wmm`), each value to its published precision (half a unit of the last
//! printed digit: 0.1 nT → 0.05 nT, 0.01° → 0.005°). The built-in model must equal the WMM2025
//! file. Outside CI the test is skipped with a message when the data is absent.

use auvnav_core::wmm::{MagneticField, WorldMagneticModel};
use std::path::Path;

/// One official test row: date, height (km), lat, lon (deg), and the published values.
struct Row {
    date: f64,
    height_km: f64,
    lat: f64,
    lon: f64,
    /// (name, published, decimals)
    values: Vec<(&'static str, f64, u32)>,
}

fn computed(f: &MagneticField, name: &str) -> f64 {
    match name {
        "X" => f.ned_nt.x,
        "Y" => f.ned_nt.y,
        "Z" => f.ned_nt.z,
        "H" => f.horizontal_nt(),
        "F" => f.intensity_nt(),
        "I" => f.inclination_deg(),
        "D" => f.declination_deg(),
        "Xdot" => f.ned_rate_nt_per_year.x,
        "Ydot" => f.ned_rate_nt_per_year.y,
        "Zdot" => f.ned_rate_nt_per_year.z,
        _ => unreachable!("{name}"),
    }
}

fn decimals(s: &str) -> u32 {
    s.split_once('.').map_or(0, |(_, d)| d.len() as u32)
}

/// Rows of a whitespace- or semicolon-separated file whose columns are named by `columns`
/// (`None` for a column not checked).
fn read(path: &Path, sep: Option<char>, columns: &[Option<&'static str>]) -> Vec<Row> {
    let text = std::fs::read_to_string(path).expect("test values");
    let mut rows = Vec::new();
    for line in text.lines() {
        let t = line.trim();
        if t.is_empty() || t.starts_with('#') || t.starts_with("Date") {
            continue;
        }
        let words: Vec<&str> = match sep {
            Some(c) => t.split(c).map(str::trim).collect(),
            None => t.split_whitespace().collect(),
        };
        let num = |i: usize| words[i].parse::<f64>().expect("number");
        let mut values = Vec::new();
        for (i, c) in columns.iter().enumerate() {
            if let Some(name) = c
                && let Ok(v) = words[i].parse::<f64>()
                && v.is_finite()
            {
                values.push((*name, v, decimals(words[i])));
            }
        }
        rows.push(Row {
            date: num(0),
            height_km: num(1),
            lat: num(2),
            lon: num(3),
            values,
        });
    }
    rows
}

fn check(model: &WorldMagneticModel, rows: &[Row]) -> usize {
    let mut checked = 0;
    let mut failures = Vec::new();
    for r in rows {
        let f = model
            .field(r.lat, r.lon, r.height_km * 1e3, r.date)
            .unwrap_or_else(|e| panic!("{e}"));
        for &(name, published, dec) in &r.values {
            let mut c = computed(&f, name);
            if name == "D" && (c - published).abs() > 180.0 {
                c -= 360.0 * (c - published).signum();
            }
            // Half a unit of the last printed digit, plus a little for the published rounding.
            let tol = 0.5 * 10f64.powi(-(dec as i32)) + 1e-9;
            if (c - published).abs() > tol {
                failures.push(format!(
                    "{} {} {} {} {name}: computed {c:.4}, published {published} (±{tol})",
                    r.date, r.height_km, r.lat, r.lon
                ));
            }
            checked += 1;
        }
    }
    assert!(failures.is_empty(), "{}", failures.join("\n"));
    checked
}

#[test]
fn every_official_test_value_is_reproduced_to_its_precision() {
    let Some(dir) = auvnav_tests::measured_data("wmm", "WMM2025/WMM.COF") else {
        return;
    };
    let load = |y: &str| {
        let text = std::fs::read_to_string(dir.join(y).join("WMM.COF")).expect("cof");
        WorldMagneticModel::from_cof(&text).expect("parses")
    };
    let wmm2025 = load("WMM2025");
    assert_eq!(
        wmm2025,
        WorldMagneticModel::builtin(),
        "the built-in model is WMM2025"
    );
    // 2025: date h lat lon X Y Z H F I D GV Xdot Ydot Zdot Hdot Fdot Idot Ddot
    let c2025 = [
        None,
        None,
        None,
        None,
        Some("X"),
        Some("Y"),
        Some("Z"),
        Some("H"),
        Some("F"),
        Some("I"),
        Some("D"),
        None,
        Some("Xdot"),
        Some("Ydot"),
        Some("Zdot"),
    ];
    let n2025 = check(
        &wmm2025,
        &read(&dir.join("WMM2025/WMM2025_TEST_VALUES.txt"), None, &c2025),
    );
    // 2015: same columns, semicolon separated.
    let n2015 = check(
        &load("WMM2015"),
        &read(
            &dir.join("WMM2015/WMM2015_test_values.csv"),
            Some(';'),
            &c2025,
        ),
    );
    // 2020: date h lat lon D I H X Y Z F dD dI dH dX dY dZ dF
    let c2020 = [
        None,
        None,
        None,
        None,
        Some("D"),
        Some("I"),
        Some("H"),
        Some("X"),
        Some("Y"),
        Some("Z"),
        Some("F"),
        None,
        None,
        None,
        Some("Xdot"),
        Some("Ydot"),
        Some("Zdot"),
    ];
    assert_eq!(
        Some(load("WMM2020")),
        WorldMagneticModel::builtin_for(2022.0),
        "the built-in model for 2020–2025 is WMM2020"
    );
    let n2020 = check(
        &load("WMM2020"),
        &read(&dir.join("WMM2020/WMM2020_TEST_VALUES.txt"), None, &c2020),
    );
    eprintln!("checked {n2015} (WMM2015) + {n2020} (WMM2020) + {n2025} (WMM2025) values");
    assert!(n2015 >= 100 && n2020 >= 1000 && n2025 >= 100);
}
