//! `auvnav bench`: throughput, latency and cost figures, one module per kind
//! ([`throughput`], [`decode`], [`latency`], [`wake`], [`bridge`], [`studies`], [`calibrate`],
//! [`smooth`], and the regression guard [`guard`]).

use anyhow::Context;
use auvnav_sim::{self as sim, SimConfig, scenario::Scenario};
use serde::Serialize;

mod bridge;
mod calibrate;
mod decode;
mod discover;
mod discover_measured;
mod discover_misses;
mod discover_surface;
mod guard;
mod guard_baseline;
mod guard_judge;
mod latency;
mod mag;
mod smooth;
mod studies;
mod throughput;
mod wake;

pub use bridge::*;
pub use calibrate::*;
pub use decode::*;
pub use discover::*;
pub use guard::*;
pub use latency::*;
pub use mag::*;
pub use smooth::*;
pub use studies::*;
pub use throughput::*;
pub use wake::*;
