//! Smoothing as a library, without the command line: its failures come as a typed
//! [`SmoothError`], the caller's (options) apart from the inputs' (a missing log, a log with
//! nothing to smooth).

use auvnav_smooth::{SmoothError, SmoothOptions, run};
use std::path::{Path, PathBuf};

fn options(out: &Path, logs: Vec<PathBuf>) -> SmoothOptions {
    SmoothOptions {
        memory_budget_mib: 64,
        json: true,
        ..SmoothOptions::new(logs, out)
    }
}

#[test]
fn failures_are_typed_the_callers_apart_from_the_inputs() {
    let dir = std::env::temp_dir().join(format!("auvnav-smooth-errors-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("scratch folder");

    let mut o = options(&dir, Vec::new());
    o.export_rate = 0.0;
    let e = run(&o).expect_err("export rate 0");
    assert!(
        matches!(e, SmoothError::Options(_)) && e.is_usage(),
        "{e:?}"
    );

    let missing = dir.join("missing.mcap");
    let e = run(&options(&dir, vec![missing])).expect_err("no log");
    assert!(!e.is_usage(), "{e:?}");
    assert!(format!("{e:#}").contains("missing.mcap"), "{e:#}");

    // A log that holds only a header: nothing to smooth.
    let empty = dir.join("empty.mcap");
    auvnav_log::write_log_atomically(&empty, &auvnav_log::LogHeader::new("test", ""), |_| Ok(()))
        .expect("an empty log");
    let e = run(&options(&dir, vec![empty])).expect_err("empty log");
    assert!(
        matches!(&e, SmoothError::Input(m) if m.contains("no IMU samples")) && !e.is_usage(),
        "{e:?}"
    );
    let _ = std::fs::remove_dir_all(&dir);
}
