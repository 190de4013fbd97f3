//! Where the tests find `../shared` (measured data, device captures): the one helper every test
//! crate uses (`tests/src/lib.rs` re-exports it; `drivers/tests/common` includes this file).
//!
//! The directory is `$AUVNAV_SHARED` when set, otherwise `shared/` beside the checkout. Outside
//! CI an absent directory is a skip that says so on stderr; under CI (`CI=true`) it is a failure.

use std::path::PathBuf;

/// The `shared` directory: `$AUVNAV_SHARED`, or `../shared` relative to the workspace root.
pub fn shared_root() -> PathBuf {
    match std::env::var_os("AUVNAV_SHARED") {
        Some(p) if !p.is_empty() => PathBuf::from(p),
        _ => {
            // CARGO_MANIFEST_DIR is a package directory one level below the workspace root.
            PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../shared")
        }
    }
}

/// `<shared>/<rel>`, or `None` (with a SKIPPED line on stderr) when it is absent outside CI;
/// under CI its absence panics.
pub fn shared(rel: &str) -> Option<PathBuf> {
    let p = shared_root().join(rel);
    if p.exists() {
        return Some(p);
    }
    if std::env::var("CI").is_ok_and(|v| v == "true") {
        panic!(
            "{} is missing: the shared data is required under CI (set AUVNAV_SHARED to move it)",
            p.display()
        );
    }
    eprintln!(
        "SKIPPED: {} is absent (set AUVNAV_SHARED or put shared/ beside the checkout)",
        p.display()
    );
    None
}
