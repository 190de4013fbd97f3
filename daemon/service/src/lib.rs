//! `auvnavd`, the fusion daemon, as a library: its loop apart from the bus (`service`, driven
//! by a test from canned messages), the loop on iceoryx2 (`bus_io`), checkpoints, and the
//! command line (shared with `auvnav man` and `auvnav completions`). `main.rs` only wires them.
#![forbid(unsafe_code)]

#[derive(clap::Parser)]
#[command(name = "auvnavd", about = "auvnav fusion daemon", version = auvnav_version::LONG)]
pub struct Args {
    /// The daemon's TOML configuration.
    #[arg(long)]
    pub config: Option<String>,
    /// Check the configuration, print it with defaults filled in, and exit.
    #[arg(long, value_name = "FILE")]
    pub check_config: Option<String>,
}

pub mod bus_io;
pub mod checkpoint;
pub mod service;
