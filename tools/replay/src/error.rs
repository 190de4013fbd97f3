//! Why a replay (or what the offline tools share with it: a configuration file, an atomic output)
//! failed, as a type a program can act on: a usage or configuration error is the caller's to fix
//! (the command line exits with status 2), an unreadable log or an unwritable output is the
//! environment's (status 1). The underlying error stays reachable as the source.

use std::path::PathBuf;

/// A boxed underlying error (a TOML parse error, a configuration check, a log or I/O error).
pub type Source = Box<dyn std::error::Error + Send + Sync + 'static>;

/// Why a replay failed.
#[derive(Debug, thiserror::Error)]
pub enum ReplayError {
    /// An option is out of range (`min_distance` negative, `decimate` zero).
    #[error("{0}")]
    Options(String),
    /// The configuration file cannot be read, parsed or passes no validation.
    #[error("configuration {}", path.display())]
    Config {
        path: PathBuf,
        #[source]
        source: Source,
    },
    /// The configuration a recording carries in its header is not a valid one.
    #[error("the configuration embedded in {}", log.display())]
    EmbeddedConfig {
        log: PathBuf,
        #[source]
        source: Source,
    },
    /// The log cannot be read (not an auvnav log, too new, unreadable).
    #[error("reading {}", path.display())]
    Log {
        path: PathBuf,
        #[source]
        source: Source,
    },
    /// The log lacks what the replay needs: a start (truth channel or `[initial]`), a station
    /// survey for USBL.
    #[error("{0}")]
    Input(String),
    /// An output cannot be written (nothing is left behind at its path).
    #[error("writing {}", path.display())]
    Output {
        path: PathBuf,
        #[source]
        source: Source,
    },
}

impl ReplayError {
    /// A usage or configuration error: the caller's to fix.
    pub fn is_usage(&self) -> bool {
        matches!(
            self,
            ReplayError::Options(_)
                | ReplayError::Config { .. }
                | ReplayError::EmbeddedConfig { .. }
        )
    }
}

/// `anyhow`'s error as a source (keeps its chain for `{:#}`).
pub(crate) fn boxed(e: anyhow::Error) -> Source {
    e.into()
}
