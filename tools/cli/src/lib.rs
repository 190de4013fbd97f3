#![forbid(unsafe_code)]
pub use auvnav_replay::accuracy;
pub mod align;
pub use auvnav_studies::args;
pub mod bench;
pub mod calibrate;
pub mod csv;
pub mod decode;
pub mod demo;
pub mod discover;
pub mod emulate;
pub use auvnav_import as import;
pub mod info;
pub mod json;
pub mod live;
pub mod montecarlo;
pub use auvnav_studies::parallel;
pub mod phases;
pub mod process;
pub use auvnav_studies::progress;
pub mod replay;
pub mod smooth;
pub use auvnav_studies::study;
pub mod usbl;

/// Why `auvnav` failed, for its exit status (docs/operations.md): 0 success, 1 a runtime failure
/// (I/O, a device, the bus), 2 a usage or configuration error (clap's own errors are 2 as well),
/// 3 a check that ran and failed (a replay that does not reproduce, a demo that did not).
#[derive(Debug, thiserror::Error)]
pub enum Failure {
    #[error("{0}")]
    Usage(String),
    #[error("{0}")]
    CheckFailed(String),
}

/// The exit status for an error: the first [`Failure`] in its chain, a configuration file that
/// does not parse (2), otherwise a runtime failure (1).
pub fn exit_status(e: &anyhow::Error) -> u8 {
    for cause in e.chain() {
        match cause.downcast_ref::<Failure>() {
            Some(Failure::Usage(_)) => return 2,
            Some(Failure::CheckFailed(_)) => return 3,
            None => {}
        }
        if cause.downcast_ref::<toml::de::Error>().is_some()
            || cause
                .downcast_ref::<auvnav_recorder::WouldOverwrite>()
                .is_some()
            || cause
                .downcast_ref::<auvnav_core::config::ConfigError>()
                .is_some()
        {
            return 2;
        }
    }
    1
}
