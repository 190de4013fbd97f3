//! `auvnavd`: the fusion daemon. Subscribes to the sensor topics in shared memory, runs the
//! navigation session in real time, publishes the solution, per-aid diagnostics and its health.
//! The loop is `auvnavd::service` (on the bus: `auvnavd::bus_io`); this file reads the command
//! line and the configuration and wires them.
#![forbid(unsafe_code)]

use auvnav_core::config::DaemonConfig;
use auvnavd::Args;
use std::process::ExitCode;

/// Reads and validates the configuration file; errors name the file.
fn load(path: &str) -> Result<DaemonConfig, String> {
    let text = std::fs::read_to_string(path).map_err(|e| format!("reading {path}: {e}"))?;
    let cfg = DaemonConfig::from_toml(&text).map_err(|e| format!("{path}: {e}"))?;
    let problems = cfg.path_problems();
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
    if let Some(path) = &args.check_config {
        return match load(path) {
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
    let Some(path) = &args.config else {
        tracing::error!("auvnavd: --config FILE is required (or --check-config FILE)");
        return ExitCode::from(2);
    };
    let cfg = match load(path) {
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
