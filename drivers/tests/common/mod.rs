//! Shared by the tests that read ../shared.

use std::path::PathBuf;

/// `../shared/<rel>`, or `None` with a message when it is absent outside CI; under CI
/// (`CI=true`) its absence is a failure.
pub fn shared(rel: &str) -> Option<PathBuf> {
    let p = PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("../../shared")
        .join(rel);
    if p.exists() {
        return Some(p);
    }
    if std::env::var("CI").is_ok_and(|v| v == "true") {
        panic!(
            "{} is missing: measured data is required under CI",
            p.display()
        );
    }
    eprintln!("SKIPPED: {} is absent", p.display());
    None
}
