//! The version every auvnav binary reports (`--version`) and writes into the logs it records:
//! the workspace version and the commit it was built from.

/// The workspace version, e.g. `0.1.0`.
pub const VERSION: &str = env!("CARGO_PKG_VERSION");

/// The commit the binaries were built from (12 hex digits), `AUVNAV_COMMIT` when the build set
/// it, or `unknown` when neither git nor the variable was available.
pub const COMMIT: &str = env!("AUVNAV_COMMIT");

/// `0.1.0 (commit 0123456789ab)`: what `--version` prints after the program name.
pub const LONG: &str = concat!(
    env!("CARGO_PKG_VERSION"),
    " (commit ",
    env!("AUVNAV_COMMIT"),
    ")"
);

#[cfg(test)]
mod tests {
    #[test]
    fn long_version_names_version_and_commit() {
        assert!(super::LONG.starts_with(super::VERSION));
        assert!(super::LONG.contains(super::COMMIT));
        assert!(!super::COMMIT.is_empty());
    }
}
