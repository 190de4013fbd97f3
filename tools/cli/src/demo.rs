//! `auvnav demo`: simulates a voyage and runs it through the on-board chain as real processes
//! (emulated devices on pseudo-terminals, drivers, daemon, recorder; see [`crate::live`]), or,
//! with `--in-process`, straight through the navigation core (the same
//! [`auvnav_core::navigator::Navigator`] the daemon and replay use); then prints the accuracy
//! against the simulated truth.

use crate::accuracy::Accuracy;
use crate::replay::{Output, Replay, ReplayConfig};
use anyhow::Context;
use auvnav_core::navigator::{NavConfig, NavCounters};
use auvnav_sim::{self as sim, SimConfig, SimSummary, scenario::Scenario};
use serde::Serialize;
use std::path::PathBuf;

#[derive(clap::Args, Debug, Clone)]
pub struct DemoArgs {
    /// Simulated seconds (default: 120 with processes, the whole scenario in process).
    #[arg(long)]
    pub seconds: Option<f64>,
    /// Play the voyage this many times faster than real time (processes only).
    #[arg(long, default_value_t = 4.0)]
    pub speed: f64,
    /// Run the voyage through the navigation core in this process (no drivers, daemon or
    /// shared memory): fast, for the whole scenario.
    #[arg(long)]
    pub in_process: bool,
    /// Built-in scenario or scenario file.
    #[arg(long, default_value = "lawnmower")]
    pub scenario: String,
    /// Random seed.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// The emulated IMU's protocol (processes only): `xsens` (an MTi sending its magnetic field
    /// too, which the daemon fuses as a heading aid) or `kvh1750`.
    #[arg(long, default_value = "xsens", value_parser = ["xsens", "kvh1750"])]
    pub imu: String,
    /// Write the logs and solutions here (processes: voyage.mcap, record.mcap, live_nav.csv,
    /// replay_nav.csv and each process's log; in process: sim.mcap and nav.csv).
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// Also run the live view (`auvnav-live`, processes only) on this address, e.g.
    /// `127.0.0.1:8765`: open it in Foxglove with `deploy/foxglove-layout.json`.
    #[arg(long, value_name = "ADDRESS:PORT")]
    pub live_view: Option<std::net::SocketAddr>,
    /// Print the result as JSON.
    #[arg(long)]
    pub json: bool,
}

#[derive(Debug, Serialize)]
pub struct DemoResult {
    pub scenario: String,
    pub seed: u64,
    pub simulated: SimSummary,
    pub accuracy: Accuracy,
    pub counters: NavCounters,
    pub wall_s: f64,
}

/// Runs a simulated voyage through the navigator (the same [`Replay`] as `auvnav replay`, fed
/// from memory); optionally writes the solution as CSV rows.
pub fn run_voyage(
    cfg: &SimConfig,
    nav_cfg: NavConfig,
    mut csv: Option<&mut dyn std::io::Write>,
) -> anyhow::Result<(SimSummary, Accuracy, NavCounters)> {
    let mut replay = Replay::new(
        &ReplayConfig {
            navigation: nav_cfg,
            ..Default::default()
        },
        100.0,
    );
    if let Some(w) = csv.as_deref_mut() {
        writeln!(w, "{}", crate::csv::NAV_HEADER)?;
    }
    // Each simulated message goes straight into the navigator: nothing is held in memory.
    let mut write = |o: Output| {
        if let (Output::Solution(s), Some(w)) = (o, csv.as_deref_mut()) {
            crate::csv::write_nav_row(w, s)?;
        }
        Ok(())
    };
    let summary = sim::simulate(cfg, |m| replay.process(m, &mut write))?;
    replay.finish(&mut write)?;
    Ok((
        summary,
        replay.accuracy().unwrap_or_default(),
        replay.nav_counters(),
    ))
}

pub fn run(a: &DemoArgs) -> anyhow::Result<()> {
    if !a.in_process {
        return run_processes(a);
    }
    let scenario = Scenario::load(&a.scenario)?;
    let effects = scenario.effects()?;
    let cfg = SimConfig {
        scenario,
        effects,
        seed: a.seed,
        duration_s: a.seconds,
    };
    let start = std::time::Instant::now();
    let mut csv_file = None;
    if let Some(dir) = &a.out {
        std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
        sim::simulate_to_log(&cfg, &dir.join("sim.mcap"))?;
        let f = std::fs::File::create(dir.join("nav.csv")).context("creating nav.csv")?;
        csv_file = Some(std::io::BufWriter::new(f));
    }
    // With a USBL station in the scenario, its fixes are fused (tight, AUKF).
    let usbl = auvnav_sim::StationGeometry::from_scenario(&cfg.scenario).map(|st| st.usbl_config());
    let has_usbl = usbl.is_some();
    // With a magnetometer in the scenario, its heading is fused (calibrated as simulated).
    let magnetometer = (cfg.scenario.rates.magnetometer_hz > 0)
        .then(|| sim::sensors::MagnetometerModel::navigator_config(&cfg.effects));
    let (simulated, accuracy, counters) = run_voyage(
        &cfg,
        NavConfig {
            usbl,
            magnetometer,
            ..NavConfig::default()
        },
        csv_file.as_mut().map(|w| w as &mut dyn std::io::Write),
    )?;
    if let Some(mut w) = csv_file {
        std::io::Write::flush(&mut w)?;
    }
    let result = DemoResult {
        scenario: cfg.scenario.name.clone(),
        seed: cfg.seed,
        simulated,
        accuracy,
        counters,
        wall_s: start.elapsed().as_secs_f64(),
    };
    if a.json {
        crate::json::print(&result)?;
    } else {
        let acc = &result.accuracy;
        println!(
            "auvnav demo: scenario {} (seed {}), {:.0} s simulated, {:.0} m travelled",
            result.scenario, result.seed, result.simulated.duration_s, acc.distance_travelled_m
        );
        println!(
            "  INS + DVL + depth{} through the navigation core:",
            if has_usbl {
                " + USBL (tight, adaptive unscented)"
            } else {
                ""
            }
        );
        println!(
            "  horizontal error: final {:.2} m, max {:.2} m, CEP50 {:.2} m",
            acc.horizontal_error_final_m, acc.horizontal_error_max_m, acc.horizontal_error_cep50_m
        );
        println!(
            "  error/distance CEP50 {:.3} %, heading error RMS {:.4} deg",
            acc.error_per_distance_cep50_percent, acc.heading_error_rms_deg
        );
        println!(
            "  fused: {} DVL ({} rejected), {} depth ({} rejected); {:.2} s wall",
            result.counters.dvl_fused,
            result.counters.dvl_rejected,
            result.counters.depth_fused,
            result.counters.depth_rejected,
            result.wall_s
        );
        if has_usbl {
            println!(
                "  USBL: {} fused, {} rejected by the gate ({} outliers simulated)",
                result.counters.usbl_fused,
                result.counters.usbl_rejected,
                result.simulated.usbl_outliers
            );
        }
        if result.simulated.magnetometer > 0 {
            let c = &result.counters;
            println!(
                "  magnetometer heading: {} fused, {} rejected by the gate, {} disturbed",
                c.magnetometer_fused, c.magnetometer_rejected, c.magnetometer_disturbed
            );
        }
        if let Some(dir) = &a.out {
            println!(
                "  log: {}  solution: {}",
                dir.join("sim.mcap").display(),
                dir.join("nav.csv").display()
            );
        }
    }
    Ok(())
}

fn run_processes(a: &DemoArgs) -> anyhow::Result<()> {
    let imu = match auvnav_drivers::device::Protocol::from_name(&a.imu) {
        Some(
            p @ (auvnav_drivers::device::Protocol::Xsens
            | auvnav_drivers::device::Protocol::Kvh1750),
        ) => p,
        _ => {
            return Err(crate::Failure::Usage(format!(
                "--imu {:?}: expected xsens or kvh1750",
                a.imu
            ))
            .into());
        }
    };
    let r = crate::live::run_live(
        &a.scenario,
        imu,
        a.seed,
        a.seconds.unwrap_or(120.0),
        a.speed,
        a.out.as_deref(),
        a.live_view,
    )?;
    if a.json {
        crate::json::print(&r)?;
    } else {
        let acc = &r.accuracy;
        println!(
            "auvnav demo: scenario {} (seed {}), {:.0} s simulated at {}x, {:.0} m travelled",
            r.scenario, r.seed, r.simulated_s, r.speed, acc.distance_travelled_m
        );
        println!(
            "  processes: emulated PD0 DVL, {} IMU, SeaTrac USBL on pseudo-terminals; \
             auvnav-dvl, -imu, -usbl, -can (depth); auvnavd; auvnav record{}",
            r.imu,
            r.live_view
                .as_ref()
                .map(|a| format!("; live view on ws://{a}"))
                .unwrap_or_default()
        );
        println!(
            "  live solution: {} rows; horizontal error final {:.2} m, max {:.2} m, CEP50 {:.2} m; heading RMS {:.3} deg",
            r.solutions,
            acc.horizontal_error_final_m,
            acc.horizontal_error_max_m,
            acc.horizontal_error_cep50_m,
            acc.heading_error_rms_deg
        );
        println!(
            "  replay of the recording byte-identical to the live solution: {}",
            if r.replay_identical { "yes" } else { "NO" }
        );
        println!(
            "  clean stop of every process: {}; {:.1} s wall",
            if r.clean_stop { "yes" } else { "NO" },
            r.wall_s
        );
        println!("  log: {}  live solution: {}", r.record, r.live_nav_csv);
        for (name, line) in &r.process_reports {
            println!("    {name}: {line}");
        }
    }
    if !r.replay_identical || !r.clean_stop {
        return Err(crate::Failure::CheckFailed(
            "the live run did not reproduce or did not stop cleanly (see above)".into(),
        )
        .into());
    }
    Ok(())
}
