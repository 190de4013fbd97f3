//! Why an import (or a read of fixes or magnetometer recordings) failed, as a type a program can
//! act on: an option the input cannot satisfy is the caller's to fix (the command line exits
//! with status 2), an unreadable or unusable input and an unwritable log are not. The underlying
//! error stays reachable as the source.

use std::path::PathBuf;

/// A boxed underlying error (I/O, CSV, log).
pub type Source = Box<dyn std::error::Error + Send + Sync + 'static>;

/// Why an import failed.
#[derive(Debug, thiserror::Error)]
pub enum ImportError {
    /// An option out of range, or one the input cannot satisfy (a segment number, a velocity
    /// source the file lacks, column names).
    #[error("{0}")]
    Options(String),
    /// A file cannot be read; the message says which and what was being read.
    #[error("{context}")]
    Read {
        context: String,
        #[source]
        source: Source,
    },
    /// The input is not in the expected form or holds nothing usable.
    #[error("{0}")]
    Malformed(String),
    /// The log cannot be written (nothing is left at its path).
    #[error("writing {}", path.display())]
    Output {
        path: PathBuf,
        #[source]
        source: Source,
    },
}

impl ImportError {
    /// An option the caller gave wrong.
    pub fn is_usage(&self) -> bool {
        matches!(self, ImportError::Options(_))
    }
}

/// `Result<T, E>` of a read into [`ImportError::Read`] with what was being read.
pub(crate) trait ReadContext<T> {
    fn read_context(self, context: impl FnOnce() -> String) -> Result<T, ImportError>;
}

impl<T, E: Into<Source>> ReadContext<T> for Result<T, E> {
    fn read_context(self, context: impl FnOnce() -> String) -> Result<T, ImportError> {
        self.map_err(|e| ImportError::Read {
            context: context(),
            source: e.into(),
        })
    }
}

/// A failed write of the log at `path`.
pub(crate) fn output(path: &std::path::Path) -> impl FnOnce(anyhow::Error) -> ImportError + '_ {
    move |e| ImportError::Output {
        path: path.to_path_buf(),
        source: e.into(),
    }
}
