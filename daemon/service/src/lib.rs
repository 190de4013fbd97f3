//! The command line of `auvnavd` (the daemon itself is the binary), shared with `auvnav man` and
//! `auvnav completions`.

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

pub mod checkpoint;
