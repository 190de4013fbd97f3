//! The version every auvnav binary reports (`--version`) and writes into the logs it records:
//! the workspace version and the commit it was built from; and ([`cli`]) the configuration
//! options every on-board program shares.
#![forbid(unsafe_code)]

pub mod cli;

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

/// Version of the JSON documents the tools print (`--json`) and write (`report.json`): every
/// document carries it as `format_version`. Raised when a field is renamed or removed or changes
/// its meaning or unit; new fields do not raise it.
pub const JSON_FORMAT_VERSION: u32 = 1;

#[cfg(test)]
mod tests {
    #[test]
    fn long_version_names_version_and_commit() {
        assert!(super::LONG.starts_with(super::VERSION));
        assert!(super::LONG.contains(super::COMMIT));
        assert!(!super::COMMIT.is_empty());
    }
}
