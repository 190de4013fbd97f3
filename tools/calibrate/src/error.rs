//! Why a calibration failed, as a type a program can act on: an option, a parameter limit or a
//! configuration the caller gave is theirs to fix ([`CalibrationError::is_usage`]; the command
//! line exits with status 2); a recording that cannot be read, data that cannot determine a
//! calibration, a method that fails and an output that cannot be written are not. The
//! underlying error stays reachable as the source.

use std::path::PathBuf;

/// A boxed underlying error.
pub type Source = Box<dyn std::error::Error + Send + Sync + 'static>;

/// Why a DVL or magnetometer calibration failed.
#[derive(Debug, thiserror::Error)]
pub enum CalibrationError {
    /// An option, a parameter selection, bound, prior or limits file is not a valid one.
    #[error("{0}")]
    Options(String),
    /// The navigation configuration (a file, or the one a recording carries) is not a valid one,
    /// or an output written through the replay library failed.
    #[error(transparent)]
    Replay(#[from] auvnav_replay::ReplayError),
    /// A magnetometer recording (a CSV or a log) cannot be read, or its columns are not valid.
    #[error(transparent)]
    Import(#[from] auvnav_import::ImportError),
    /// A voyage's log cannot be read.
    #[error("reading {}", path.display())]
    Read {
        path: PathBuf,
        #[source]
        source: Source,
    },
    /// The data cannot be calibrated: no DVL velocity, no start state, no fix beyond the
    /// distance threshold, too few magnetometer samples.
    #[error("{0}")]
    Input(String),
    /// Replaying the voyages with a candidate installation failed.
    #[error("replaying the voyages")]
    Navigation(#[source] Source),
    /// The calibration method failed (singular normal equations, a fit that does not converge).
    #[error(transparent)]
    Method(Source),
    /// An output cannot be written.
    #[error("writing {}", path.display())]
    Output {
        path: PathBuf,
        #[source]
        source: Source,
    },
}

impl CalibrationError {
    /// A usage or configuration error: the caller's to fix.
    pub fn is_usage(&self) -> bool {
        match self {
            CalibrationError::Options(_) => true,
            CalibrationError::Replay(e) => e.is_usage(),
            CalibrationError::Import(e) => e.is_usage(),
            _ => false,
        }
    }

    /// Replaying the voyages failed with `e`.
    pub(crate) fn navigation(e: impl Into<Source>) -> CalibrationError {
        CalibrationError::Navigation(e.into())
    }

    /// The method failed with `e`.
    pub(crate) fn method(e: impl Into<Source>) -> CalibrationError {
        CalibrationError::Method(e.into())
    }

    /// Writing `path` failed with `e`.
    pub(crate) fn output(path: &std::path::Path, e: impl Into<Source>) -> CalibrationError {
        CalibrationError::Output {
            path: path.to_path_buf(),
            source: e.into(),
        }
    }
}

/// Returns [`CalibrationError::Options`] with a formatted message.
macro_rules! usage {
    ($($arg:tt)*) => {
        return Err($crate::CalibrationError::Options(format!($($arg)*)))
    };
}
pub(crate) use usage;

/// Returns [`CalibrationError::Input`] with a formatted message.
macro_rules! unusable {
    ($($arg:tt)*) => {
        return Err($crate::CalibrationError::Input(format!($($arg)*)))
    };
}
pub(crate) use unusable;
