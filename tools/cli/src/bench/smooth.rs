//! `auvnav bench smooth`: wall time, real-time factor and peak memory of `auvnav smooth` on the
//! replay benchmark's log (lawnmower, 200 Hz IMU, 1 Hz DVL, depth and truth; one hour by default)
//! and on a long voyage (ten hours by default). Each run is a child `auvnav smooth` process, so
//! its peak memory is its own (`VmHWM`, reported by the child).

#[allow(unused_imports)]
use super::*;

/// One `auvnav smooth` run.
#[derive(Debug, Clone, Serialize)]
pub struct SmoothRun {
    pub forward_wall_s: f64,
    pub backward_wall_s: f64,
    pub second_pass_wall_s: f64,
    /// The three passes.
    pub total_wall_s: f64,
    /// The child process's whole life (start, read, passes, outputs).
    pub process_wall_s: f64,
    pub peak_memory_mib: Option<f64>,
    pub spilled_bytes: u64,
}

/// One log's figures.
#[derive(Debug, Clone, Serialize)]
pub struct SmoothLogBench {
    pub log_hours: f64,
    pub imu_hz: u32,
    pub imu_samples: u64,
    pub covariance_epochs: u64,
    pub log_bytes: u64,
    pub runs: Vec<SmoothRun>,
    /// Median of the runs' three passes.
    pub median_total_wall_s: f64,
    /// Log time over that median.
    pub real_time_factor: f64,
    /// Log time over the median of forward + backward alone (the smoothing, without the
    /// second pass that maps and writes every solution).
    pub smoothing_real_time_factor: f64,
    /// The largest peak memory of the runs (MiB).
    pub peak_memory_mib: Option<f64>,
    pub memory_budget_mib: usize,
    /// `auvnav smooth --solution-rate` of the runs (none: every solution written).
    pub solution_rate_hz: Option<f64>,
}

/// The benchmark's output.
#[derive(Debug, Clone, Serialize)]
pub struct SmoothBenchReport {
    pub version: u32,
    pub hour_log: SmoothLogBench,
    pub long_voyage: Option<SmoothLogBench>,
    /// The targets: 2000x real time on the hour-long log, 4 GiB for the long voyage.
    pub target_real_time_factor: f64,
    pub target_peak_memory_mib: f64,
}

/// Runs `auvnav smooth --json` on `log` in a child process.
fn smooth_child(
    exe: &std::path::Path,
    log: &std::path::Path,
    out: &std::path::Path,
    memory_budget_mib: usize,
    solution_rate: Option<f64>,
) -> anyhow::Result<(LogFigures, SmoothRun)> {
    let started = std::time::Instant::now();
    let mut command = std::process::Command::new(exe);
    command
        .arg("smooth")
        .arg(log)
        .arg("--out")
        .arg(out)
        .arg("--memory-budget-mib")
        .arg(memory_budget_mib.to_string())
        .arg("--json");
    if let Some(hz) = solution_rate {
        command.arg("--solution-rate").arg(hz.to_string());
    }
    let output = command
        .output()
        .with_context(|| format!("running {} smooth", exe.display()))?;
    let process_wall_s = started.elapsed().as_secs_f64();
    if !output.status.success() {
        anyhow::bail!(
            "auvnav smooth failed ({}): {}",
            output.status,
            String::from_utf8_lossy(&output.stderr).trim()
        );
    }
    let report: serde_json::Value =
        serde_json::from_slice(&output.stdout).context("reading auvnav smooth --json")?;
    let peak_memory_mib = report["peak_memory_mib"].as_f64();
    let log: serde_json::Value = report["logs"][0].clone();
    let num = |k: &str| log[k].as_f64().unwrap_or(f64::NAN);
    let run = SmoothRun {
        forward_wall_s: num("forward_wall_s"),
        backward_wall_s: num("backward_wall_s"),
        second_pass_wall_s: num("second_pass_wall_s"),
        total_wall_s: num("forward_wall_s") + num("backward_wall_s") + num("second_pass_wall_s"),
        process_wall_s,
        peak_memory_mib,
        spilled_bytes: log["spilled_bytes"].as_u64().unwrap_or(0),
    };
    Ok((
        LogFigures {
            log_duration_s: num("log_duration_s"),
            epochs: log["epochs"].as_u64().unwrap_or(0),
        },
        run,
    ))
}

/// What the benchmark takes from a run's report besides the times.
struct LogFigures {
    log_duration_s: f64,
    epochs: u64,
}

fn bench_log(
    hours: f64,
    repeat: usize,
    memory_budget_mib: usize,
    solution_rate: Option<f64>,
    dir: &std::path::Path,
    label: &str,
) -> anyhow::Result<SmoothLogBench> {
    let cfg = super::throughput::replay_log_config(hours)?;
    let path = dir.join(format!("{label}.mcap"));
    eprintln!("bench smooth: simulating {hours} h ({label}) ...");
    let summary = sim::simulate_to_log(&cfg, &path)?;
    let log_bytes = std::fs::metadata(&path).map(|m| m.len()).unwrap_or(0);
    let exe = std::env::current_exe().context("finding the auvnav executable")?;
    let out = dir.join(format!("{label}-out"));
    let mut runs = Vec::new();
    let mut info = None;
    for k in 0..repeat.max(1) {
        eprintln!(
            "bench smooth: smoothing {label}, run {} of {}",
            k + 1,
            repeat.max(1)
        );
        let (l, r) = smooth_child(&exe, &path, &out, memory_budget_mib, solution_rate)?;
        info = Some(l);
        runs.push(r);
        let _ = std::fs::remove_dir_all(&out);
    }
    let _ = std::fs::remove_file(&path);
    let info = info.expect("at least one run");
    let totals: Vec<f64> = runs.iter().map(|r| r.total_wall_s).collect();
    let smoothing: Vec<f64> = runs
        .iter()
        .map(|r| r.forward_wall_s + r.backward_wall_s)
        .collect();
    let m = median(&totals);
    Ok(SmoothLogBench {
        log_hours: info.log_duration_s / 3600.0,
        imu_hz: cfg.scenario.rates.imu_hz,
        imu_samples: summary.imu,
        covariance_epochs: info.epochs,
        log_bytes,
        median_total_wall_s: m,
        real_time_factor: info.log_duration_s / m,
        smoothing_real_time_factor: info.log_duration_s / median(&smoothing),
        peak_memory_mib: runs
            .iter()
            .filter_map(|r| r.peak_memory_mib)
            .reduce(f64::max),
        memory_budget_mib,
        solution_rate_hz: solution_rate,
        runs,
    })
}

/// Times `auvnav smooth` on an `hours`-long log (`repeat` runs, the median reported) and once on
/// a `long_hours` voyage (0: skipped) with `memory_budget_mib` of epochs kept in memory.
pub fn smooth(
    hours: f64,
    repeat: usize,
    long_hours: f64,
    memory_budget_mib: usize,
    solution_rate: Option<f64>,
    json: bool,
) -> anyhow::Result<()> {
    if !(hours > 0.0 && hours.is_finite() && long_hours >= 0.0 && long_hours.is_finite()) {
        anyhow::bail!("--hours must be > 0 and --long-hours >= 0");
    }
    let dir = std::env::temp_dir().join(format!("auvnav-bench-smooth-{}", std::process::id()));
    std::fs::create_dir_all(&dir).with_context(|| format!("creating {}", dir.display()))?;
    let result = (|| -> anyhow::Result<SmoothBenchReport> {
        let hour_log = bench_log(
            hours,
            repeat,
            memory_budget_mib,
            solution_rate,
            &dir,
            "hour",
        )?;
        let long_voyage = if long_hours > 0.0 {
            Some(bench_log(
                long_hours,
                1,
                memory_budget_mib,
                solution_rate,
                &dir,
                "long",
            )?)
        } else {
            None
        };
        Ok(SmoothBenchReport {
            version: 1,
            hour_log,
            long_voyage,
            target_real_time_factor: 2000.0,
            target_peak_memory_mib: 4096.0,
        })
    })();
    let _ = std::fs::remove_dir_all(&dir);
    let r = result?;
    if json {
        crate::json::print(&r)?;
    } else {
        for (name, b) in [
            ("hour log", Some(&r.hour_log)),
            ("long voyage", r.long_voyage.as_ref()),
        ] {
            let Some(b) = b else { continue };
            println!(
                "smooth, {name}: {:.2} h of {} Hz IMU ({} covariance epochs): median {:.2} s for the three passes (real-time factor {:.0}; forward + backward alone {:.0}), peak memory {} with a {} MiB budget, {} MiB spilled; solutions written {}; {} run(s)",
                b.log_hours,
                b.imu_hz,
                b.covariance_epochs,
                b.median_total_wall_s,
                b.real_time_factor,
                b.smoothing_real_time_factor,
                b.peak_memory_mib
                    .map(|m| format!("{m:.0} MiB"))
                    .unwrap_or_else(|| "unknown".into()),
                b.memory_budget_mib,
                b.runs.iter().map(|r| r.spilled_bytes).max().unwrap_or(0) / (1 << 20),
                b.solution_rate_hz
                    .map(|hz| format!("at {hz} Hz"))
                    .unwrap_or_else(|| "all".into()),
                b.runs.len()
            );
        }
    }
    Ok(())
}
