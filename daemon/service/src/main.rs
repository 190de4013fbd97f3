//! `auvnavd`: the fusion daemon. Subscribes to the sensor topics in shared memory, runs the
//! navigation session in real time, publishes the solution, per-aid diagnostics and its health.
//! The loop is `auvnavd::service` (on the bus: `auvnavd::bus_io`); this file reads the command
//! line and the configuration and wires them.
#![forbid(unsafe_code)]

use auvnav_core::config::DaemonConfig;
use auvnavd::Args;
use std::process::ExitCode;

/// The state folder the daemon's unit creates (`StateDirectory=auvnav`).
const STATE_DIRECTORY: &str = "/var/lib/auvnav/";

/// Reads and validates the configuration file; errors name the file. A check (`check`) of a
/// file whose outputs go to the unit's state folder passes on a machine where that folder does
/// not exist yet (the unit creates it), with a note.
fn load(path: &str, check: bool) -> Result<DaemonConfig, String> {
    let text = std::fs::read_to_string(path).map_err(|e| format!("reading {path}: {e}"))?;
    let cfg = DaemonConfig::from_toml(&text).map_err(|e| format!("{path}: {e}"))?;
    let mut problems = cfg.path_problems();
    if check && !std::path::Path::new(STATE_DIRECTORY).is_dir() {
        problems.retain(|p| {
            let in_state = p.contains(&format!("\"{STATE_DIRECTORY}"));
            if in_state {
                tracing::warn!(
                    "auvnavd: {path}: {STATE_DIRECTORY} does not exist here; the unit creates it \
                     (StateDirectory=auvnav)"
                );
            }
            !in_state
        });
    }
    if problems.is_empty() {
        Ok(cfg)
    } else {
        Err(format!("{path}: {}", problems.join("; ")))
    }
}

fn main() -> ExitCode {
    use clap::Parser;
    let args = Args::parse();
    auvnav_shm_schema::logging::init();
    let (path, check) = match args.config.required() {
        Ok(x) => x,
        Err(x) => {
            tracing::error!("auvnavd: {x}");
            return ExitCode::from(2);
        }
    };
    if check {
        return match load(&path, true) {
            Ok(cfg) => {
                match toml::to_string_pretty(&cfg) {
                    Ok(s) => print!("{s}"),
                    Err(x) => tracing::error!("auvnavd: {x}"),
                }
                ExitCode::SUCCESS
            }
            Err(x) => {
                tracing::error!("auvnavd: {x}");
                ExitCode::from(2)
            }
        };
    }
    let cfg = match load(&path, false) {
        Ok(c) => c,
        Err(x) => {
            tracing::error!("auvnavd: {x}");
            return ExitCode::from(2);
        }
    };
    match auvnavd::bus_io::run(&cfg) {
        Ok(_) => ExitCode::SUCCESS,
        Err(x) => {
            tracing::error!("auvnavd: {x}");
            ExitCode::from(1)
        }
    }
}
