//! `auvnav bench`: throughput figures.

use crate::sim::{self, SimConfig, scenario::Scenario};
use serde::Serialize;

#[derive(Debug, Serialize)]
pub struct SimBench {
    pub simulated_hours: f64,
    pub imu_hz: u32,
    pub dvl_hz: u32,
    pub usbl_hz: u32,
    pub depth_hz: u32,
    pub truth_hz: u32,
    pub messages: u64,
    pub file_bytes: u64,
    pub runs_wall_s: Vec<f64>,
    pub median_wall_s: f64,
    pub simulated_seconds_per_wall_second: f64,
}

/// Simulates `hours` of the docking scenario (200 Hz IMU, 5 Hz DVL, 1 Hz USBL, 1 Hz depth, plus
/// the 20 Hz truth channel; no magnetometer) into a temporary log, `repeat` times.
pub fn sim(hours: f64, repeat: usize, json: bool) -> anyhow::Result<()> {
    let mut scenario = Scenario::load("docking")?;
    scenario.rates.magnetometer_hz = 0;
    scenario.rates.gnss_hz = 0;
    let mut effects = scenario.effects()?;
    effects.set("usbl.max_range", &[10000.0])?;
    let cfg = SimConfig {
        scenario,
        effects,
        seed: 1,
        duration_s: Some(hours * 3600.0),
    };
    let dir = std::env::temp_dir().join(format!("auvnav-bench-sim-{}", std::process::id()));
    std::fs::create_dir_all(&dir)?;
    let path = dir.join("bench.mcap");
    let mut runs = Vec::new();
    let mut messages = 0;
    for _ in 0..repeat.max(1) {
        let t = std::time::Instant::now();
        let s = sim::simulate_to_log(&cfg, &path)?;
        runs.push(t.elapsed().as_secs_f64());
        messages = s.imu + s.dvl + s.usbl + s.depth + s.truth;
    }
    let file_bytes = std::fs::metadata(&path).map(|m| m.len()).unwrap_or(0);
    let _ = std::fs::remove_dir_all(&dir);
    let mut sorted = runs.clone();
    sorted.sort_by(f64::total_cmp);
    let median = sorted[sorted.len() / 2];
    let r = &cfg.scenario.rates;
    let out = SimBench {
        simulated_hours: hours,
        imu_hz: r.imu_hz,
        dvl_hz: r.dvl_hz,
        usbl_hz: r.usbl_hz,
        depth_hz: r.depth_hz,
        truth_hz: r.truth_hz,
        messages,
        file_bytes,
        runs_wall_s: runs,
        median_wall_s: median,
        simulated_seconds_per_wall_second: hours * 3600.0 / median,
    };
    if json {
        println!("{}", serde_json::to_string_pretty(&out)?);
    } else {
        println!(
            "sim: {} h in {:.3} s (median of {}), {} messages, {} bytes",
            hours,
            median,
            out.runs_wall_s.len(),
            messages,
            file_bytes
        );
    }
    Ok(())
}
