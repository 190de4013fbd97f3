//! Why a simulation or a perturbation failed, as a type a program can act on: a bad option, an
//! effect setting or a scenario the trajectory cannot fly is the caller's to fix
//! ([`SimError::is_usage`]; the command line exits with status 2), an unreadable input log or an
//! unwritable output is the environment's. The underlying error stays reachable as the source.

use crate::effects::EffectError;
use crate::scenario::ScenarioError;
use crate::trajectory::TrajectoryError;
use std::path::PathBuf;

/// A boxed underlying error (a log reader's or writer's error).
pub type Source = Box<dyn std::error::Error + Send + Sync + 'static>;

/// Why a simulation or a perturbation failed.
#[derive(Debug, thiserror::Error)]
pub enum SimError {
    /// An option is not one the tool accepts (an unknown campaign, no effect given, an output
    /// path equal to the input, an effect that cannot be applied to a recorded log).
    #[error("{0}")]
    Options(String),
    /// An effect setting names no effect, has the wrong arity or lies outside its range.
    #[error(transparent)]
    Effect(#[from] EffectError),
    /// A scenario fails its checks.
    #[error(transparent)]
    Scenario(#[from] ScenarioError),
    /// The scenario's legs describe a motion the trajectory cannot fly.
    #[error(transparent)]
    Trajectory(#[from] TrajectoryError),
    /// The input log cannot be read.
    #[error("reading {}", path.display())]
    Log {
        path: PathBuf,
        #[source]
        source: Source,
    },
    /// An output cannot be written (nothing is left behind at its path).
    #[error("writing {}", path.display())]
    Output {
        path: PathBuf,
        #[source]
        source: Source,
    },
}

impl SimError {
    /// A usage error: the caller's to fix.
    pub fn is_usage(&self) -> bool {
        matches!(
            self,
            SimError::Options(_)
                | SimError::Effect(_)
                | SimError::Scenario(_)
                | SimError::Trajectory(_)
        )
    }
}
