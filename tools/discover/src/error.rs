//! Why a discovery failed, as a type a program can act on: an option, an effect setting or a
//! nominal model the caller gave is theirs to fix ([`DiscoverError::is_usage`]; the command line
//! exits with status 2); a log that cannot be read, a smoothing that fails and an output that
//! cannot be written are not. The underlying error stays reachable as the source.

use std::path::PathBuf;

/// A boxed underlying error.
pub type Source = Box<dyn std::error::Error + Send + Sync + 'static>;

/// Why a discovery failed.
#[derive(Debug, thiserror::Error)]
pub enum DiscoverError {
    /// An option is out of range or conflicts with another.
    #[error("{0}")]
    Options(String),
    /// An effect setting names no effect, has the wrong arity or lies outside its range.
    #[error(transparent)]
    Effect(#[from] auvnav_sim::effects::EffectError),
    /// The nominal model (`nominal_from`: a discover report or an effect set) cannot be read or
    /// is not one.
    #[error("the nominal model {}", path.display())]
    Nominal {
        path: PathBuf,
        #[source]
        source: Source,
    },
    /// A log cannot be read.
    #[error("reading {}", path.display())]
    Read {
        path: PathBuf,
        #[source]
        source: Source,
    },
    /// Smoothing a log for `--reference smoothed` failed.
    #[error(transparent)]
    Smoothing(#[from] auvnav_smooth::SmoothError),
    /// An output cannot be written.
    #[error(transparent)]
    Output(#[from] auvnav_replay::ReplayError),
}

impl DiscoverError {
    /// A usage error: the caller's to fix.
    pub fn is_usage(&self) -> bool {
        match self {
            DiscoverError::Options(_)
            | DiscoverError::Effect(_)
            | DiscoverError::Nominal { .. } => true,
            DiscoverError::Smoothing(e) => e.is_usage(),
            DiscoverError::Output(e) => e.is_usage(),
            DiscoverError::Read { .. } => false,
        }
    }

    /// Reading `path` failed with `e`.
    pub(crate) fn read(path: &std::path::Path, e: impl Into<Source>) -> DiscoverError {
        DiscoverError::Read {
            path: path.to_path_buf(),
            source: e.into(),
        }
    }
}
