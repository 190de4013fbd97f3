//! `auvnav bench`: throughput, latency and cost figures, one module per kind
//! ([`throughput`], [`decode`], [`latency`], [`studies`]).

use anyhow::Context;
use auvnav_sim::{self as sim, SimConfig, scenario::Scenario};
use serde::Serialize;

mod decode;
mod latency;
mod studies;
mod throughput;

pub use decode::*;
pub use latency::*;
pub use studies::*;
pub use throughput::*;
