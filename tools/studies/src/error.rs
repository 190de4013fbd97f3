//! Why a study failed, as a type a program can act on: an option out of range is the caller's to
//! fix ([`StudyError::is_usage`]; the command line exits with status 2), a run that fails, a data
//! set that cannot be read or an output that cannot be written are not. The underlying error
//! stays reachable as the source.

use std::path::PathBuf;

/// A boxed underlying error.
pub type Source = Box<dyn std::error::Error + Send + Sync + 'static>;

/// Why a study failed.
#[derive(Debug, thiserror::Error)]
pub enum StudyError {
    /// An option is out of range or names nothing (`runs` 0, an unknown model or scenario, a
    /// setting that is not one, a configuration the study cannot simulate).
    #[error("{0}")]
    Options(String),
    /// The study's scenario or effects are not valid ones.
    #[error(transparent)]
    Simulation(#[from] auvnav_sim::SimError),
    /// A measured data set cannot be imported.
    #[error(transparent)]
    Import(#[from] auvnav_import::ImportError),
    /// A measured log lacks what the study needs (a reference channel).
    #[error("{0}")]
    Input(String),
    /// One run failed.
    #[error("run {index}")]
    Run {
        index: usize,
        #[source]
        source: Source,
    },
    /// The run results handed to the report do not belong to the study's options, or leave
    /// nothing to evaluate.
    #[error("{0}")]
    Results(String),
    /// A run's result does not convert to or from its bytes.
    #[error("a run's result does not convert to or from its bytes")]
    RunBytes(#[source] postcard::Error),
    /// An output cannot be written.
    #[error("writing {}", path.display())]
    Output {
        path: PathBuf,
        #[source]
        source: Source,
    },
}

impl StudyError {
    /// A usage error: the caller's to fix.
    pub fn is_usage(&self) -> bool {
        match self {
            StudyError::Options(_) => true,
            StudyError::Simulation(e) => e.is_usage(),
            StudyError::Import(e) => e.is_usage(),
            _ => false,
        }
    }

    /// Run `index` failed with `e`.
    pub fn run(index: usize, e: impl Into<Source>) -> StudyError {
        StudyError::Run {
            index,
            source: e.into(),
        }
    }
}

impl From<auvnav_sim::effects::EffectError> for StudyError {
    fn from(e: auvnav_sim::effects::EffectError) -> StudyError {
        StudyError::Simulation(e.into())
    }
}

impl From<auvnav_sim::scenario::ScenarioError> for StudyError {
    fn from(e: auvnav_sim::scenario::ScenarioError) -> StudyError {
        StudyError::Simulation(e.into())
    }
}

/// Returns [`StudyError::Options`] with a formatted message.
macro_rules! usage {
    ($($arg:tt)*) => {
        return Err($crate::StudyError::Options(format!($($arg)*)))
    };
}
pub(crate) use usage;
