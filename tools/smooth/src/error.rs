//! Why a smoothing failed, as a type a program can act on: an option out of range or a bad
//! configuration is the caller's to fix ([`SmoothError::is_usage`]; the command line exits with
//! status 2), a log without what smoothing needs, an unreadable log or fix file and an unwritable
//! output are not. The underlying error stays reachable as the source.

use std::path::PathBuf;

/// A boxed underlying error (a log, I/O or serialisation error).
pub type Source = Box<dyn std::error::Error + Send + Sync + 'static>;

/// Why a smoothing (or the smoother's Monte Carlo) failed.
#[derive(Debug, thiserror::Error)]
pub enum SmoothError {
    /// An option is out of range (`export_rate`, `solution_rate`, `runs`, `end_fix_std`).
    #[error("{0}")]
    Options(String),
    /// The replay behind the forward pass cannot be set up or run (its configuration, the log).
    #[error(transparent)]
    Replay(#[from] auvnav_replay::ReplayError),
    /// The fix file cannot be read.
    #[error(transparent)]
    Fixes(#[from] auvnav_import::ImportError),
    /// The Monte Carlo's scenario or simulation failed.
    #[error(transparent)]
    Simulation(#[from] auvnav_sim::SimError),
    /// A log cannot be read.
    #[error("reading {}", path.display())]
    Log {
        path: PathBuf,
        #[source]
        source: Source,
    },
    /// The log lacks what smoothing needs (IMU samples, an initial state, a started filter).
    #[error("{0}")]
    Input(String),
    /// The backward pass failed (its record of the forward pass could not be read back).
    #[error("smoothing {}", log.display())]
    Backward {
        log: PathBuf,
        #[source]
        source: Source,
    },
    /// The second forward pass did not repeat the first, so the smoothed track would not match.
    #[error("{0}")]
    NotRepeatable(String),
    /// An output cannot be written (nothing is left behind at its path).
    #[error("writing {}", path.display())]
    Output {
        path: PathBuf,
        #[source]
        source: Source,
    },
    /// A Monte Carlo run failed.
    #[error("run {index}")]
    Run {
        index: usize,
        #[source]
        source: Source,
    },
}

impl SmoothError {
    /// A usage or configuration error: the caller's to fix.
    pub fn is_usage(&self) -> bool {
        match self {
            SmoothError::Options(_) => true,
            SmoothError::Replay(e) => e.is_usage(),
            SmoothError::Fixes(e) => e.is_usage(),
            SmoothError::Simulation(e) => e.is_usage(),
            _ => false,
        }
    }

    /// An output error at `path`.
    pub(crate) fn output(path: &std::path::Path, e: impl Into<Source>) -> SmoothError {
        SmoothError::Output {
            path: path.to_path_buf(),
            source: e.into(),
        }
    }
}
