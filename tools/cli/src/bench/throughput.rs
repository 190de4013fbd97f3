//! Throughput: `auvnav bench sim`, `replay`, `accuracy`.

#[allow(unused_imports)]
use super::*;

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
    pub real_time_factor: f64,
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
    let median = median(&runs);
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
        real_time_factor: hours * 3600.0 / median,
    };
    if json {
        crate::json::print(&out)?;
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

#[derive(Debug, Serialize)]
pub struct ReplayBench {
    pub log_hours: f64,
    pub imu_hz: u32,
    pub dvl_hz: u32,
    pub depth_hz: u32,
    pub truth_hz: u32,
    pub imu_samples: u64,
    /// Wall time of each run of `auvnav replay` on the log file (read, decode, navigate).
    pub runs_wall_s: Vec<f64>,
    pub median_wall_s: f64,
    /// Log seconds per wall second of the median run.
    pub real_time_factor: f64,
    /// The same with the messages already decoded in memory: the navigation core alone.
    pub core_runs_wall_s: Vec<f64>,
    pub core_median_wall_s: f64,
    pub core_real_time_factor: f64,
    /// Reading and decoding every message of the log file, nothing else (the read stage).
    pub read_runs_wall_s: Vec<f64>,
    pub read_median_wall_s: f64,
}

pub(crate) fn median(v: &[f64]) -> f64 {
    let mut s = v.to_vec();
    s.sort_by(f64::total_cmp);
    s[s.len() / 2]
}

/// The replay benchmarks' log: `hours` of the lawnmower with a 200 Hz IMU and 1 Hz DVL, depth
/// and truth, seed 1 (also what `auvnav bench smooth` smooths).
pub(crate) fn replay_log_config(hours: f64) -> anyhow::Result<SimConfig> {
    let mut scenario = Scenario::load("lawnmower")?;
    scenario.rates.imu_hz = 200;
    scenario.rates.dvl_hz = 1;
    scenario.rates.depth_hz = 1;
    scenario.rates.truth_hz = 1;
    scenario.rates.usbl_hz = 0;
    scenario.rates.magnetometer_hz = 0;
    scenario.rates.gnss_hz = 0;
    let effects = scenario.effects()?;
    Ok(SimConfig {
        scenario,
        effects,
        seed: 1,
        duration_s: Some(hours * 3600.0),
    })
}

/// Replays `hours` of simulated INS/DVL/depth (200 Hz IMU, 1 Hz DVL, 1 Hz depth, 1 Hz truth for
/// the initial state and the accuracy) through the navigation core, `repeat` times, from the log
/// file and from memory. One thread.
pub fn replay(hours: f64, repeat: usize, json: bool) -> anyhow::Result<()> {
    use crate::replay::{Replay, ReplayArgs, ReplayConfig};
    let cfg = replay_log_config(hours)?;
    let dir = std::env::temp_dir().join(format!("auvnav-bench-replay-{}", std::process::id()));
    std::fs::create_dir_all(&dir)?;
    let path = dir.join("bench.mcap");
    let result = (|| -> anyhow::Result<ReplayBench> {
        let summary = sim::simulate_to_log(&cfg, &path)?;
        let args = ReplayArgs {
            log: path.clone(),
            config: None,
            out: None,
            decimate: 1,
            min_distance: 100.0,
            usbl: None,
            json: false,
            compare_recorded: false,
            reference_lever_arm: None,
        };
        let mut runs = Vec::new();
        let mut log_duration_s = 0.0;
        for _ in 0..repeat.max(1) {
            let t = std::time::Instant::now();
            let r = crate::replay::run(&args)?;
            runs.push(t.elapsed().as_secs_f64());
            log_duration_s = r.log_duration_s;
        }
        let (messages, _) = sim::simulate_to_vec(&cfg)?;
        let mut core_runs = Vec::new();
        for _ in 0..repeat.max(1) {
            let t = std::time::Instant::now();
            let mut replay = Replay::new(&ReplayConfig::default(), 100.0);
            for m in &messages {
                replay.process(m, &mut |_| Ok(()))?;
            }
            replay.finish(&mut |_| Ok(()))?;
            std::hint::black_box(replay.accuracy());
            core_runs.push(t.elapsed().as_secs_f64());
        }
        let mut read_runs = Vec::new();
        for _ in 0..repeat.max(1) {
            let t = std::time::Instant::now();
            let mut reader = auvnav_log::LogReader::open(&path)?;
            let mut decoded = 0u64;
            while reader
                .next_decoded_with(|d| std::hint::black_box(d).is_ok())?
                .is_some()
            {
                decoded += 1;
            }
            std::hint::black_box(decoded);
            read_runs.push(t.elapsed().as_secs_f64());
        }
        let r = &cfg.scenario.rates;
        let (m, cm) = (median(&runs), median(&core_runs));
        Ok(ReplayBench {
            log_hours: log_duration_s / 3600.0,
            imu_hz: r.imu_hz,
            dvl_hz: r.dvl_hz,
            depth_hz: r.depth_hz,
            truth_hz: r.truth_hz,
            imu_samples: summary.imu,
            runs_wall_s: runs,
            median_wall_s: m,
            real_time_factor: log_duration_s / m,
            core_runs_wall_s: core_runs,
            core_median_wall_s: cm,
            core_real_time_factor: log_duration_s / cm,
            read_median_wall_s: median(&read_runs),
            read_runs_wall_s: read_runs,
        })
    })();
    let _ = std::fs::remove_dir_all(&dir);
    let out = result?;
    if json {
        crate::json::print(&out)?;
    } else {
        println!(
            "replay: {:.2} h of {} Hz IMU / {} Hz DVL / {} Hz depth in {:.3} s from the log (real-time factor {:.0}), {:.3} s from memory ({:.0}), {:.3} s to read and decode the log alone; median of {}",
            out.log_hours,
            out.imu_hz,
            out.dvl_hz,
            out.depth_hz,
            out.median_wall_s,
            out.real_time_factor,
            out.core_median_wall_s,
            out.core_real_time_factor,
            out.read_median_wall_s,
            out.runs_wall_s.len()
        );
    }
    Ok(())
}

#[derive(Debug, Serialize)]
pub struct AccuracyBench {
    pub scenario: String,
    pub seeds: Vec<u64>,
    pub distance_m: f64,
    /// Error/distance CEP50 (S-CAL formula) per seed (%).
    pub error_per_distance_cep50_percent: Vec<f64>,
    pub median_error_per_distance_cep50_percent: f64,
    pub final_error_m: Vec<f64>,
    pub median_final_error_m: f64,
}

/// INS/DVL/depth accuracy of the navigation core on a simulated scenario over several seeds.
pub fn accuracy(scenario_name: &str, seeds: u64, json: bool) -> anyhow::Result<()> {
    let scenario = Scenario::load(scenario_name)?;
    let effects = scenario.effects()?;
    let mut out = AccuracyBench {
        scenario: scenario.name.clone(),
        seeds: (1..=seeds.max(1)).collect(),
        distance_m: 0.0,
        error_per_distance_cep50_percent: Vec::new(),
        median_error_per_distance_cep50_percent: 0.0,
        final_error_m: Vec::new(),
        median_final_error_m: 0.0,
    };
    for &seed in &out.seeds {
        let cfg = SimConfig {
            scenario: scenario.clone(),
            effects: effects.clone(),
            seed,
            duration_s: None,
        };
        let (_, acc, _) =
            crate::demo::run_voyage(&cfg, auvnav_core::navigator::NavConfig::default(), None)?;
        out.distance_m = acc.distance_travelled_m;
        out.error_per_distance_cep50_percent
            .push(acc.error_per_distance_cep50_percent);
        out.final_error_m.push(acc.horizontal_error_final_m);
    }
    out.median_error_per_distance_cep50_percent = median(&out.error_per_distance_cep50_percent);
    out.median_final_error_m = median(&out.final_error_m);
    if json {
        crate::json::print(&out)?;
    } else {
        println!(
            "accuracy: scenario {} ({:.0} m), {} seeds: error/distance CEP50 median {:.4} % (max {:.4} %), final error median {:.2} m",
            out.scenario,
            out.distance_m,
            out.seeds.len(),
            out.median_error_per_distance_cep50_percent,
            out.error_per_distance_cep50_percent
                .iter()
                .cloned()
                .fold(0.0, f64::max),
            out.median_final_error_m
        );
    }
    Ok(())
}
