//! `auvnavd`, the fusion daemon, as a library: its loop apart from the bus (`service`, driven
//! by a test from canned messages), the loop on iceoryx2 (`bus_io`), checkpoints, and the
//! command line (shared with `auvnav man` and `auvnav completions`). `main.rs` only wires them.
#![forbid(unsafe_code)]

#[derive(clap::Parser)]
#[command(name = "auvnavd", about = "auvnav fusion daemon", version = auvnav_version::LONG)]
pub struct Args {
    /// `--config FILE`, `--check-config [FILE]`.
    #[command(flatten)]
    pub config: auvnav_version::cli::ConfigArgs,
}

pub mod bus_io;
pub mod checkpoint;
mod csv_out;
pub mod service;
mod stop_summary;
