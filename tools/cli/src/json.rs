//! The JSON documents the tools print with `--json` (the versioned form is `auvnav_replay::json`,
//! shared with the libraries that write `report.json`).

pub use auvnav_replay::json::to_string_pretty;
use serde::Serialize;

/// Prints `value` as a versioned document on standard output.
pub fn print<T: Serialize>(value: &T) -> serde_json::Result<()> {
    println!("{}", to_string_pretty(value)?);
    Ok(())
}
