//! Import as a library, without the command line (and without clap): a magnetometer CSV
//! recording into a log, with a typed summary, a bad row counted, and the log readable.

use auvnav_import::{MagCsvOptions, mag::CsvColumnOptions, mag_csv};

#[test]
fn a_magnetometer_csv_imports_through_the_library() {
    let dir = std::env::temp_dir().join(format!("auvnav-import-lib-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("scratch folder");
    let csv = dir.join("mag.csv");
    let mut text = String::from("time_s,mag_x,mag_y,mag_z,acc_x,acc_y,acc_z\n");
    for k in 0..50 {
        let a = k as f64 * 0.1;
        text.push_str(&format!(
            "{:.2},{:.3},{:.3},-40.0,0.0,0.0,-9.81\n",
            k as f64 * 0.1,
            20.0 * a.cos(),
            20.0 * a.sin()
        ));
    }
    text.push_str("5.00,not,a,number,0,0,-9.81\n");
    std::fs::write(&csv, text).expect("CSV");
    let out = dir.join("mag.mcap");
    let summary = mag_csv(&MagCsvOptions {
        file: csv,
        out: out.clone(),
        columns: CsvColumnOptions::default(),
        json: false,
    })
    .expect("import");
    assert_eq!(summary.readings, 50);
    assert_eq!(summary.with_accelerometer, 50);
    assert_eq!(summary.skipped, 1);
    assert!(
        summary.field_unit.starts_with("µT"),
        "{}",
        summary.field_unit
    );
    assert!((summary.duration_s - 4.9).abs() < 1e-9, "{summary:?}");
    let recording = auvnav_import::mag::read_log(&out).expect("the log reads back");
    assert_eq!(recording.samples.len(), 50);
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn failures_are_typed_the_callers_apart_from_the_inputs() {
    use auvnav_import::{ImportError, TimeBase, snapir_messages};
    let dir = std::env::temp_dir().join(format!("auvnav-import-errors-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("scratch folder");

    // A segment number no data set has: the caller's.
    let e = snapir_messages(&dir, 0, TimeBase::Nominal, true).expect_err("segment 0");
    assert!(
        matches!(e, ImportError::Options(_)) && e.is_usage(),
        "{e:?}"
    );

    // A file that is not there: a read error with the file's name and the I/O error as source.
    let e =
        snapir_messages(&dir.join("missing"), 1, TimeBase::Nominal, true).expect_err("no data set");
    assert!(
        matches!(e, ImportError::Read { .. }) && !e.is_usage(),
        "{e:?}"
    );
    assert!(std::error::Error::source(&e).is_some());

    // A file in another form: malformed, with what was expected.
    for name in ["imu_01.csv", "dvl_01.csv", "ref_01.csv"] {
        std::fs::write(dir.join(name), "a,b,c\n1,2,3\n").expect("write");
    }
    let e = snapir_messages(&dir, 1, TimeBase::Nominal, true).expect_err("wrong header");
    assert!(
        matches!(&e, ImportError::Malformed(m) if m.contains("expected")),
        "{e:?}"
    );
    std::fs::remove_dir_all(&dir).ok();
}
