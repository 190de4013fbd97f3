#![forbid(unsafe_code)]
pub use auvnav_replay::accuracy;
pub mod align;
pub use auvnav_studies::args;
pub mod bench;
pub use auvnav_calibrate as calibrate;
pub mod csv;
pub mod decode;
pub mod demo;
pub mod demo_start;
pub mod discover;
pub mod emulate_line;
pub mod emulate_ptys;
pub use auvnav_import as import;
pub mod demo_processes;
pub mod json;
pub mod log_info;
pub mod montecarlo;
pub use auvnav_studies::parallel;
pub mod percentiles;
pub mod phases;
pub mod process;
pub use auvnav_studies::progress;
pub mod ranges;
pub mod replay;
pub mod sitl_sensors;
pub mod smooth;
pub use auvnav_studies::perturbed_start;
pub mod usbl;

pub use auvnav_replay::Failure;

/// The exit status for an error: the first [`Failure`] in its chain, a usage error of a library
/// (its typed error's `is_usage`), a configuration file that does not parse (2), otherwise a
/// runtime failure (1).
pub fn exit_status(e: &anyhow::Error) -> u8 {
    for cause in e.chain() {
        match cause.downcast_ref::<Failure>() {
            Some(Failure::Usage(_)) => return 2,
            Some(Failure::CheckFailed(_)) => return 3,
            None => {}
        }
        if is_usage(cause)
            || cause.downcast_ref::<toml::de::Error>().is_some()
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

/// Whether `cause` is one of the libraries' typed errors that is the caller's to fix.
fn is_usage(cause: &(dyn std::error::Error + 'static)) -> bool {
    macro_rules! usage_of {
        ($($error:ty),+) => {
            $(
                if let Some(e) = cause.downcast_ref::<$error>() {
                    return e.is_usage();
                }
            )+
        };
    }
    usage_of!(
        auvnav_replay::ReplayError,
        auvnav_import::ImportError,
        auvnav_sim::SimError,
        auvnav_smooth::SmoothError,
        auvnav_studies::StudyError,
        auvnav_calibrate::CalibrationError,
        auvnav_discover::DiscoverError
    );
    false
}
