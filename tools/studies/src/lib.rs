//! auvnav's Monte Carlo studies as a library: options in, typed reports out; the printing is the
//! command line's. With the `clap` feature, the option structs are also the command line's.
//!
//! - [`nees`]: filter consistency (`auvnav montecarlo nees`), and the sensor errors drawn from
//!   the filter's own model that the smoother's study shares;
//! - [`usbl`]: loose against tight USBL coupling on the docking scenario (S-USBL);
//! - [`ranges`]: tight acoustic ranges against the device's fixes, for a moving array, LBL and a
//!   single beacon;
//! - [`align`]: the fine-alignment error models of S-ALIGN, simulated and on the Snapir segments;
//! - [`perturbed_start`]: how a run's navigation starts (the truth perturbed by a draw of the initial
//!   covariance), [`parallel`]: the one runner (each run depends only on its seed, so results do
//!   not depend on the number of threads), [`progress`]: the progress bars (standard error, a
//!   terminal only), [`runs`]: a study as independent runs (plan, run by index, report) that the
//!   local runner and a distributed engine share, [`args`]: value parsers shared by the command
//!   lines.
#![forbid(unsafe_code)]

pub mod align;
pub mod args;
mod error;
pub mod nees;
pub mod parallel;
pub mod perturbed_start;
pub mod progress;
pub mod ranges;
pub mod runs;
pub mod usbl;

pub use error::{Source, StudyError};
