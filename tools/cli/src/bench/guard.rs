//! `auvnav bench guard`: the replay and smoothing of this build against another build (a base
//! commit's `auvnav`) or against a fixed reference workload compiled into this binary, run
//! alternately on one core, judged as ratios: the machine's speed and its drift over the run
//! cancel, which absolute times on a noisy machine never do.
//!
//! Each workload runs in a child process of the binary under test and is timed by that binary
//! itself, so any two builds that have these commands compare alike: `auvnav bench replay
//! --repeat 1 --json` (the navigation core on messages in memory, and the whole replay from the
//! log file), `auvnav smooth LOG --out DIR --json` writing every solution (its forward and
//! backward passes, and the whole command), `auvnav bench decode --pty-seconds 0 --json`. Without a base build the
//! other side is [`reference_workload`]: a frozen mix of what the replay does (a strapdown step
//! with its sines and square roots per sample, a sparse covariance propagation at 20 Hz, a
//! checksum over the log's bytes), whose time tracks the machine but never the project's code.

use super::*;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::Instant;

pub use super::guard_baseline::{Baseline, GuardBaseline};
pub use super::reference_workload::reference_workload;

/// What `auvnav bench guard` is asked to do (its command line).
#[derive(clap::Args, Debug, Clone)]
pub struct GuardArgs {
    /// The other build's `auvnav` (e.g. a base commit built in a worktree); without it, the
    /// reference workload.
    #[arg(long)]
    pub base: Option<PathBuf>,
    /// Alternating pairs of runs per workload.
    #[arg(long, default_value_t = 5)]
    pub pairs: usize,
    /// Log hours (200 Hz IMU, 1 Hz DVL and depth).
    #[arg(long, default_value_t = 1.0)]
    pub hours: f64,
    /// Also the decoders' throughput (with --base: the reference has no decoder).
    #[arg(long)]
    pub decode: bool,
    /// Judge the ratios to the reference workload against this baseline file.
    #[arg(long)]
    pub baseline: Option<PathBuf>,
    /// Write the ratios measured as this build profile's baseline into this file.
    #[arg(long)]
    pub write_baseline: Option<PathBuf>,
    /// A slowdown beyond this (%, and beyond the run's noise) fails.
    #[arg(long, default_value_t = 10.0)]
    pub limit_percent: f64,
    /// The CPU to run on (default: the last one this process may use).
    #[arg(long)]
    pub cpu: Option<usize>,
    /// Run the reference workload for --hours, print its wall time as JSON and exit (what the
    /// guard times).
    #[arg(long, hide = true)]
    pub reference_workload: bool,
    #[arg(long)]
    pub json: bool,
}

/// One workload's alternating runs.
#[derive(Debug, Clone, Serialize)]
pub struct GuardWorkload {
    pub name: String,
    /// Wall time of each run of this build (s), in the order run.
    pub this_wall_s: Vec<f64>,
    /// Wall time of each run of the other side (the base build or the reference workload).
    pub other_wall_s: Vec<f64>,
    /// This build's time over the other's, pair by pair (> 1: this build is slower).
    pub pair_ratios: Vec<f64>,
    pub median_ratio: f64,
    /// Half the spread of the middle half of the pair ratios, relative to their median (%): how
    /// far one ratio strays from the median on this machine now.
    pub noise_percent: f64,
    /// Against the baseline (reference mode with a baseline): the baseline's ratio, the
    /// slowdown (%; negative: faster) and the verdict.
    pub baseline_ratio: Option<f64>,
    pub slowdown_percent: Option<f64>,
    pub verdict: Option<String>,
}

/// The guard's report.
#[derive(Debug, Clone, Serialize)]
pub struct GuardReport {
    pub this: String,
    /// The other side: a base build's path, or "the reference workload".
    pub other: String,
    /// The build profile of this binary ("release" or "dev"): baselines are kept per profile.
    pub profile: String,
    pub cpu: Option<usize>,
    pub log_hours: f64,
    pub pairs: usize,
    pub workloads: Vec<GuardWorkload>,
    /// Whether every judged workload passed (true when nothing was judged).
    pub passed: bool,
}

/// The workloads a baseline keeps and judges. The whole smoothing command is reported but not
/// judged: most of its time is writing some 200 MB per hour of log, whose ratio to the reference
/// moved by up to 14 % between runs of one build on the build VM.
const JUDGED: [&str; 3] = ["replay core", "replay from the log", "smoothing"];

fn profile() -> &'static str {
    if cfg!(debug_assertions) {
        "dev"
    } else {
        "release"
    }
}

/// The processor's model name and this machine's CPU count: where a baseline was measured.
fn cpu_model() -> String {
    let info = std::fs::read_to_string("/proc/cpuinfo").unwrap_or_default();
    let model = info
        .lines()
        .find(|l| l.starts_with("model name"))
        .and_then(|l| l.split(':').nth(1))
        .map_or("unknown processor", str::trim);
    // Counted from /proc/cpuinfo: this process may already be pinned to one of them.
    let n = info.lines().filter(|l| l.starts_with("processor")).count();
    format!("{model}, {n} CPUs")
}

/// Pins this process (and so the children it starts) to `cpu`, or to the last CPU it may use.
fn pin(cpu: Option<usize>) -> Option<usize> {
    use nix::sched::{CpuSet, sched_getaffinity, sched_setaffinity};
    use nix::unistd::Pid;
    let allowed = sched_getaffinity(Pid::from_raw(0)).ok()?;
    let cpu = cpu.or_else(|| {
        (0..CpuSet::count())
            .rev()
            .find(|&c| allowed.is_set(c).unwrap_or(false))
    })?;
    let mut set = CpuSet::new();
    set.set(cpu).ok()?;
    sched_setaffinity(Pid::from_raw(0), &set).ok()?;
    Some(cpu)
}

/// Runs `exe ARGS` and returns its standard output as JSON and its wall time.
fn run_json(exe: &Path, args: &[&std::ffi::OsStr]) -> anyhow::Result<(serde_json::Value, f64)> {
    let t = Instant::now();
    let out = Command::new(exe)
        .args(args)
        .stderr(Stdio::piped())
        .output()
        .with_context(|| format!("running {}", exe.display()))?;
    let wall = t.elapsed().as_secs_f64();
    if !out.status.success() {
        anyhow::bail!(
            "{} {:?} failed ({}): {}",
            exe.display(),
            args,
            out.status,
            String::from_utf8_lossy(&out.stderr).trim()
        );
    }
    let v = serde_json::from_slice(&out.stdout)
        .with_context(|| format!("reading the JSON of {} {:?}", exe.display(), args))?;
    Ok((v, wall))
}

/// A number of a JSON report, or an error naming it.
fn number(v: &serde_json::Value, key: &str) -> anyhow::Result<f64> {
    v[key]
        .as_f64()
        .with_context(|| format!("the report has no number {key:?}"))
}

/// `auvnav bench replay --hours H --repeat 1 --json` of `exe`: the core on messages in memory
/// and the whole replay from the log file (s).
fn replay_times(exe: &Path, hours: f64) -> anyhow::Result<Vec<(&'static str, f64)>> {
    let h = hours.to_string();
    let args = ["bench", "replay", "--hours", &h, "--repeat", "1", "--json"];
    let os: Vec<&std::ffi::OsStr> = args.iter().map(std::ffi::OsStr::new).collect();
    let (v, _) = run_json(exe, &os)?;
    Ok(vec![
        ("replay core", number(&v, "core_median_wall_s")?),
        ("replay from the log", number(&v, "median_wall_s")?),
    ])
}

/// `auvnav smooth LOG --out OUT --json` of `exe`, every solution written: its forward and
/// backward passes, and the whole command (s).
fn smooth_times(exe: &Path, log: &Path, out: &Path) -> anyhow::Result<Vec<(&'static str, f64)>> {
    let args: [&std::ffi::OsStr; 5] = [
        "smooth".as_ref(),
        log.as_os_str(),
        "--out".as_ref(),
        out.as_os_str(),
        "--json".as_ref(),
    ];
    let r = run_json(exe, &args);
    let _ = std::fs::remove_dir_all(out);
    let (v, wall) = r?;
    let l = &v["logs"][0];
    Ok(vec![
        (
            "smoothing",
            number(l, "forward_wall_s")? + number(l, "backward_wall_s")?,
        ),
        ("smooth command", wall),
    ])
}

/// `auvnav bench decode --pty-seconds 0 --json` of `exe`: seconds per megabyte of each protocol, summed (the
/// decoders' time for one megabyte of each).
fn decode_times(exe: &Path) -> anyhow::Result<Vec<(&'static str, f64)>> {
    let args = [
        "bench",
        "decode",
        "--repeat",
        "3",
        "--pty-seconds",
        "0",
        "--json",
    ];
    let os: Vec<&std::ffi::OsStr> = args.iter().map(std::ffi::OsStr::new).collect();
    let (v, _) = run_json(exe, &os)?;
    let items = v["throughput"]
        .as_array()
        .context("bench decode --json: no throughput list")?;
    let s: f64 = items
        .iter()
        .filter_map(|p| p["megabytes_per_second"].as_f64())
        .filter(|r| *r > 0.0)
        .map(|r| 1.0 / r)
        .sum();
    anyhow::ensure!(s > 0.0, "bench decode --json: no throughput");
    Ok(vec![("decode", s)])
}

/// The reference workload for `hours`, run by `exe` (its own timing, s).
fn reference_time(exe: &Path, hours: f64) -> anyhow::Result<f64> {
    let h = hours.to_string();
    let args = ["bench", "guard", "--reference-workload", "--hours", &h];
    let os: Vec<&std::ffi::OsStr> = args.iter().map(std::ffi::OsStr::new).collect();
    let (v, _) = run_json(exe, &os)?;
    number(&v, "wall_s")
}

/// `auvnav bench guard --reference-workload`: runs it and prints its wall time as JSON.
fn run_reference_workload(hours: f64) -> anyhow::Result<()> {
    let t = Instant::now();
    std::hint::black_box(reference_workload(hours));
    crate::json::print(&serde_json::json!({ "wall_s": t.elapsed().as_secs_f64() }))?;
    Ok(())
}

/// Median and noise (half the interquartile range over the median, %) of `ratios`.
fn median_and_noise(ratios: &[f64]) -> (f64, f64) {
    let mut s = ratios.to_vec();
    s.sort_by(f64::total_cmp);
    let q = |p: f64| {
        let x = p * (s.len() - 1) as f64;
        let (i, f) = (x.floor() as usize, x - x.floor());
        s[i] + (s[(i + 1).min(s.len() - 1)] - s[i]) * f
    };
    let m = q(0.5);
    (m, 50.0 * (q(0.75) - q(0.25)) / m)
}

/// Runs one group of workloads `pairs` times on each side, alternating which goes first; each
/// side returns a time per workload (the reference workload one time for the whole group).
fn alternate(
    group: &str,
    pairs: usize,
    mut this: impl FnMut() -> anyhow::Result<Vec<(&'static str, f64)>>,
    mut other: impl FnMut() -> anyhow::Result<Vec<(&'static str, f64)>>,
) -> anyhow::Result<Vec<GuardWorkload>> {
    let (mut a, mut b) = (Vec::new(), Vec::new());
    for k in 0..pairs {
        eprintln!("bench guard: {group}, pair {} of {pairs}", k + 1);
        if k % 2 == 0 {
            a.push(this()?);
            b.push(other()?);
        } else {
            b.push(other()?);
            a.push(this()?);
        }
    }
    let names: Vec<&str> = a[0].iter().map(|(n, _)| *n).collect();
    let mut out = Vec::new();
    for (i, name) in names.iter().enumerate() {
        let this_wall_s: Vec<f64> = a.iter().map(|r| r[i].1).collect();
        let other_wall_s: Vec<f64> = b
            .iter()
            .map(|r| r.iter().find(|(n, _)| n == name).unwrap_or(&r[0]).1)
            .collect();
        let pair_ratios: Vec<f64> = this_wall_s
            .iter()
            .zip(&other_wall_s)
            .map(|(x, y)| x / y)
            .collect();
        let (median_ratio, noise_percent) = median_and_noise(&pair_ratios);
        out.push(GuardWorkload {
            name: (*name).into(),
            this_wall_s,
            other_wall_s,
            pair_ratios,
            median_ratio,
            noise_percent,
            baseline_ratio: None,
            slowdown_percent: None,
            verdict: None,
        });
    }
    Ok(out)
}

/// Judges `w` against `baseline`: a slowdown beyond `limit_percent` and beyond twice the run's
/// noise fails; one within the limit passes; one beyond the limit but within the noise cannot be
/// told from it and fails too (the guard never passes what it cannot judge).
fn judge(w: &mut GuardWorkload, baseline: f64, limit_percent: f64) -> bool {
    let slowdown = (w.median_ratio / baseline - 1.0) * 100.0;
    w.baseline_ratio = Some(baseline);
    w.slowdown_percent = Some(slowdown);
    let (passed, verdict) = if slowdown <= limit_percent {
        (
            true,
            format!("{slowdown:+.1} % against the baseline: within the {limit_percent} % limit"),
        )
    } else if slowdown > 2.0 * w.noise_percent {
        (
            false,
            format!(
                "{slowdown:+.1} % against the baseline: slower beyond the {limit_percent} % limit and beyond this run's noise ({:.1} %)",
                w.noise_percent
            ),
        )
    } else {
        (
            false,
            format!(
                "{slowdown:+.1} % against the baseline, but this run's noise is {:.1} %: cannot be judged here; run with more --pairs on a quieter machine",
                w.noise_percent
            ),
        )
    };
    w.verdict = Some(verdict);
    passed
}

/// `auvnav bench guard`: fails (exit status 3) when a judged workload slowed down.
pub fn guard(a: &GuardArgs) -> anyhow::Result<()> {
    if a.reference_workload {
        return run_reference_workload(a.hours);
    }
    anyhow::ensure!(
        a.hours > 0.0 && a.hours.is_finite() && a.pairs >= 1,
        "--hours must be > 0 and --pairs at least 1"
    );
    anyhow::ensure!(
        a.base.is_none() || (a.baseline.is_none() && a.write_baseline.is_none()),
        "--baseline and --write-baseline are ratios to the reference workload: leave out --base"
    );
    let exe = std::env::current_exe().context("finding the auvnav executable")?;
    let cpu = pin(a.cpu);
    let dir = std::env::temp_dir().join(format!("auvnav-bench-guard-{}", std::process::id()));
    std::fs::create_dir_all(&dir).with_context(|| format!("creating {}", dir.display()))?;
    let result = (|| -> anyhow::Result<GuardReport> {
        let log = dir.join("guard.mcap");
        eprintln!("bench guard: simulating {} h ...", a.hours);
        sim::simulate_to_log(&super::throughput::replay_log_config(a.hours)?, &log)?;
        let out = dir.join("smoothed");
        let reference = || -> anyhow::Result<Vec<(&'static str, f64)>> {
            Ok(vec![("reference", reference_time(&exe, a.hours)?)])
        };
        let mut workloads = Vec::new();
        let other = match &a.base {
            Some(base) => {
                workloads.extend(alternate(
                    "replay",
                    a.pairs,
                    || replay_times(&exe, a.hours),
                    || replay_times(base, a.hours),
                )?);
                workloads.extend(alternate(
                    "smooth",
                    a.pairs,
                    || smooth_times(&exe, &log, &out),
                    || smooth_times(base, &log, &out),
                )?);
                if a.decode {
                    workloads.extend(alternate(
                        "decode",
                        a.pairs,
                        || decode_times(&exe),
                        || decode_times(base),
                    )?);
                }
                base.display().to_string()
            }
            None => {
                workloads.extend(alternate(
                    "replay",
                    a.pairs,
                    || replay_times(&exe, a.hours),
                    reference,
                )?);
                workloads.extend(alternate(
                    "smooth",
                    a.pairs,
                    || smooth_times(&exe, &log, &out),
                    reference,
                )?);
                "the reference workload".into()
            }
        };
        Ok(GuardReport {
            this: exe.display().to_string(),
            other,
            profile: profile().into(),
            cpu,
            log_hours: a.hours,
            pairs: a.pairs,
            workloads,
            passed: true,
        })
    })();
    let _ = std::fs::remove_dir_all(&dir);
    let mut report = result?;
    if let Some(path) = &a.baseline {
        judge_against(&mut report, path, a.limit_percent)?;
    }
    if let Some(path) = &a.write_baseline {
        write_baseline(&report, a, path)?;
    }
    if a.json {
        crate::json::print(&report)?;
    } else {
        print_report(&report);
    }
    if !report.passed {
        return Err(crate::Failure::CheckFailed(
            "bench guard: slower than the baseline (see above)".into(),
        )
        .into());
    }
    Ok(())
}

/// Judges every workload of `report` that the baseline file at `path` has a ratio for, on this
/// processor.
fn judge_against(report: &mut GuardReport, path: &Path, limit_percent: f64) -> anyhow::Result<()> {
    let text =
        std::fs::read_to_string(path).with_context(|| format!("reading {}", path.display()))?;
    let b = GuardBaseline::parse(&text).with_context(|| format!("reading {}", path.display()))?;
    let here = cpu_model();
    let ratios = match b.find(profile(), &here) {
        Ok(found) => &found.ratios,
        Err(elsewhere) if elsewhere.is_empty() => anyhow::bail!(
            "{} has no baseline for the {} profile",
            path.display(),
            profile()
        ),
        Err(elsewhere) => {
            for w in &mut report.workloads {
                w.verdict = Some(format!(
                    "not judged: the {} baselines were measured on {}, this is {here}; add one \
                     for it with --write-baseline",
                    profile(),
                    elsewhere.join(" and ")
                ));
            }
            return Ok(());
        }
    };
    for w in &mut report.workloads {
        if let Some(&r) = ratios.get(&w.name) {
            report.passed &= judge(w, r, limit_percent);
        }
    }
    Ok(())
}

/// Records the report's ratios as this build profile's baseline on this processor in the file at
/// `path` (the other profiles' and processors' kept).
fn write_baseline(report: &GuardReport, a: &GuardArgs, path: &Path) -> anyhow::Result<()> {
    let mut b = match std::fs::read_to_string(path) {
        Ok(text) => {
            GuardBaseline::parse(&text).with_context(|| format!("reading {}", path.display()))?
        }
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => GuardBaseline::default(),
        Err(e) => return Err(e).with_context(|| format!("reading {}", path.display())),
    };
    b.insert(Baseline {
        profile: profile().into(),
        processor: cpu_model(),
        ratios: report
            .workloads
            .iter()
            .filter(|w| JUDGED.contains(&w.name.as_str()))
            .map(|w| (w.name.clone(), w.median_ratio))
            .collect(),
        measured: format!(
            "{} pairs on {} h, version {}",
            a.pairs,
            a.hours,
            auvnav_version::LONG
        ),
    });
    std::fs::write(path, serde_json::to_string_pretty(&b)? + "\n")
        .with_context(|| format!("writing {}", path.display()))
}

fn print_report(report: &GuardReport) {
    println!(
        "bench guard: this build ({} profile) against {}, {} pairs on {} h{}",
        report.profile,
        report.other,
        report.pairs,
        report.log_hours,
        report
            .cpu
            .map_or(", not pinned".into(), |c| format!(", on CPU {c}"))
    );
    for w in &report.workloads {
        println!(
            "  {:20} ratio {:.3} (pairs {}), noise {:.1} %{}",
            w.name,
            w.median_ratio,
            w.pair_ratios
                .iter()
                .map(|r| format!("{r:.3}"))
                .collect::<Vec<_>>()
                .join(", "),
            w.noise_percent,
            w.verdict
                .as_ref()
                .map_or(String::new(), |v| format!(": {v}"))
        );
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn workload(ratios: &[f64]) -> GuardWorkload {
        let (median_ratio, noise_percent) = median_and_noise(ratios);
        GuardWorkload {
            name: "replay core".into(),
            this_wall_s: ratios.to_vec(),
            other_wall_s: vec![1.0; ratios.len()],
            pair_ratios: ratios.to_vec(),
            median_ratio,
            noise_percent,
            baseline_ratio: None,
            slowdown_percent: None,
            verdict: None,
        }
    }

    #[test]
    fn the_noise_is_half_the_middle_spread_over_the_median() {
        let (m, n) = median_and_noise(&[5.0, 1.0, 3.0, 2.0, 4.0]);
        assert_eq!(m, 3.0);
        assert!((n - 100.0 / 3.0).abs() < 1e-12, "{n}");
        assert_eq!(median_and_noise(&[2.0]), (2.0, 0.0));
    }

    /// 20 % slower with a quiet run fails; 5 % slower passes; 20 % slower in a run whose ratios
    /// scatter by more than that cannot be judged and fails too; faster passes.
    #[test]
    fn a_slowdown_beyond_the_limit_and_the_noise_fails() {
        let mut w = workload(&[1.19, 1.2, 1.21, 1.2, 1.2]);
        assert!(!judge(&mut w, 1.0, 10.0));
        assert!(
            w.verdict
                .as_deref()
                .expect("judged")
                .contains("beyond the 10 % limit")
        );
        assert!((w.slowdown_percent.expect("judged") - 20.0).abs() < 1e-9);
        let mut w = workload(&[1.04, 1.05, 1.06]);
        assert!(judge(&mut w, 1.0, 10.0));
        let mut w = workload(&[0.7, 1.2, 1.7, 1.0, 1.5]);
        assert!(!judge(&mut w, 1.0, 10.0));
        assert!(
            w.verdict
                .as_deref()
                .expect("judged")
                .contains("cannot be judged")
        );
        let mut w = workload(&[0.8, 0.8, 0.8]);
        assert!(judge(&mut w, 1.0, 10.0));
    }
}
