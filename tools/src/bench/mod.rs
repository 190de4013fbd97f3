//! `auvnav bench`: throughput, latency and cost figures, one module per kind
//! ([`throughput`], [`decode`], [`latency`], [`studies`]).

use crate::sim::{self, SimConfig, scenario::Scenario};
use anyhow::Context;
use serde::Serialize;

mod decode;
mod latency;
mod studies;
mod throughput;

pub use decode::*;
pub use latency::*;
pub use studies::*;
pub use throughput::*;
