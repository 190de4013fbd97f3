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
//! other side is the reference workload, a program of its own (`auvnav-guard-reference`,
//! `tools/guard-reference`): a frozen mix of what the replay does (a strapdown step with its sines
//! and square roots per sample, a sparse covariance propagation at 20 Hz, a checksum over the
//! log's bytes), whose time tracks the machine but never the project's code.

use super::*;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::Instant;

pub use super::guard_baseline::{Baseline, GuardBaseline};
pub use super::guard_judge::{GuardReport, GuardWorkload};
use super::guard_judge::{cpu_model, judge_against, merge, profile};

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
    #[arg(long)]
    pub json: bool,
}

/// The workloads a baseline keeps and judges. The whole smoothing command is reported but not
/// judged: most of its time is writing some 200 MB per hour of log, whose ratio to the reference
/// moved by up to 14 % between runs of one build on the build VM.
const JUDGED: [&str; 3] = ["replay core", "replay from the log", "smoothing"];

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

/// The reference workload for `hours`, run by `program` (its own timing, s).
fn reference_time(program: &Path, hours: f64) -> anyhow::Result<f64> {
    let h = hours.to_string();
    let args = ["--hours", &h];
    let os: Vec<&std::ffi::OsStr> = args.iter().map(std::ffi::OsStr::new).collect();
    let (v, _) = run_json(program, &os)?;
    number(&v, "wall_s")
}

/// The reference workload's program: `auvnav-guard-reference` beside this `auvnav` (the
/// workspace's programs are built into one folder).
fn reference_program(exe: &Path) -> anyhow::Result<PathBuf> {
    let p = exe.with_file_name(format!(
        "auvnav-guard-reference{}",
        std::env::consts::EXE_SUFFIX
    ));
    anyhow::ensure!(
        p.is_file(),
        "{} is missing: the guard's reference workload is a program of its own (build it with \
         `cargo build --workspace --bins`, or `-p auvnav-guard-reference`)",
        p.display()
    );
    Ok(p)
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
        out.push(GuardWorkload::of_runs(name, this_wall_s, other_wall_s));
    }
    Ok(out)
}

/// The groups of workloads, each run by one [`alternate`] call.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Group {
    Replay,
    Smooth,
    Decode,
}

impl Group {
    /// The group a workload's runs belong to.
    fn of(workload: &str) -> Option<Group> {
        match workload {
            "replay core" | "replay from the log" => Some(Group::Replay),
            "smoothing" | "smooth command" => Some(Group::Smooth),
            "decode" => Some(Group::Decode),
            _ => None,
        }
    }
}

/// This build and the other side (a base build, or the reference workload), with the log and
/// the output folder the runs use.
struct Sides<'a> {
    exe: &'a Path,
    /// The reference workload's program (without a base build).
    reference: Option<&'a Path>,
    a: &'a GuardArgs,
    log: &'a Path,
    out: &'a Path,
}

impl Sides<'_> {
    /// `pairs` alternating pairs of each group.
    fn run(&self, groups: &[Group], pairs: usize) -> anyhow::Result<Vec<GuardWorkload>> {
        let (exe, hours, log, out) = (self.exe, self.a.hours, self.log, self.out);
        let reference = || -> anyhow::Result<Vec<(&'static str, f64)>> {
            let program = self.reference.context("no reference workload program")?;
            Ok(vec![("reference", reference_time(program, hours)?)])
        };
        let mut workloads = Vec::new();
        for g in groups {
            workloads.extend(match (g, &self.a.base) {
                (Group::Replay, Some(base)) => alternate(
                    "replay",
                    pairs,
                    || replay_times(exe, hours),
                    || replay_times(base, hours),
                )?,
                (Group::Smooth, Some(base)) => alternate(
                    "smooth",
                    pairs,
                    || smooth_times(exe, log, out),
                    || smooth_times(base, log, out),
                )?,
                (Group::Decode, Some(base)) => {
                    alternate("decode", pairs, || decode_times(exe), || decode_times(base))?
                }
                (Group::Replay, None) => {
                    alternate("replay", pairs, || replay_times(exe, hours), reference)?
                }
                (Group::Smooth, None) => {
                    alternate("smooth", pairs, || smooth_times(exe, log, out), reference)?
                }
                // The reference workload has no decoder.
                (Group::Decode, None) => Vec::new(),
            });
        }
        Ok(workloads)
    }
}

/// `auvnav bench guard`: fails (exit status 3) when a judged workload slowed down.
pub fn guard(a: &GuardArgs) -> anyhow::Result<()> {
    anyhow::ensure!(
        a.hours > 0.0 && a.hours.is_finite() && a.pairs >= 1,
        "--hours must be > 0 and --pairs at least 1"
    );
    anyhow::ensure!(
        a.base.is_none() || (a.baseline.is_none() && a.write_baseline.is_none()),
        "--baseline and --write-baseline are ratios to the reference workload: leave out --base"
    );
    let exe = std::env::current_exe().context("finding the auvnav executable")?;
    let reference = match a.base {
        None => Some(reference_program(&exe)?),
        Some(_) => None,
    };
    let cpu = pin(a.cpu);
    let dir = std::env::temp_dir().join(format!("auvnav-bench-guard-{}", std::process::id()));
    std::fs::create_dir_all(&dir).with_context(|| format!("creating {}", dir.display()))?;
    let result = (|| -> anyhow::Result<GuardReport> {
        let log = dir.join("guard.mcap");
        eprintln!("bench guard: simulating {} h ...", a.hours);
        sim::simulate_to_log(&super::throughput::replay_log_config(a.hours)?, &log)?;
        let sides = Sides {
            exe: &exe,
            reference: reference.as_deref(),
            a,
            log: &log,
            out: &dir.join("smoothed"),
        };
        let mut groups = vec![Group::Replay, Group::Smooth];
        if a.decode && a.base.is_some() {
            groups.push(Group::Decode);
        }
        let mut report = GuardReport {
            this: exe.display().to_string(),
            other: a.base.as_ref().map_or_else(
                || "the reference workload".into(),
                |b| b.display().to_string(),
            ),
            profile: profile().into(),
            cpu,
            log_hours: a.hours,
            pairs: a.pairs,
            workloads: sides.run(&groups, a.pairs)?,
            passed: true,
            confirmed: Vec::new(),
        };
        if let Some(path) = &a.baseline {
            judge_against(&mut report, path, a.limit_percent)?;
            // A slowdown is confirmed before it fails: the groups that failed run as many
            // pairs again and are judged on all their pairs (noise that hit the first round
            // passes, a slower build fails again).
            let failed: Vec<Group> = groups
                .iter()
                .copied()
                .filter(|g| {
                    report
                        .workloads
                        .iter()
                        .any(|w| w.failed() && Group::of(&w.name) == Some(*g))
                })
                .collect();
            if !failed.is_empty() {
                eprintln!(
                    "bench guard: slower than the baseline; confirming with {} more pairs",
                    a.pairs
                );
                let more = sides.run(&failed, a.pairs)?;
                report.confirmed = more.iter().map(|w| w.name.clone()).collect();
                merge(&mut report.workloads, more);
                report.passed = true;
                judge_against(&mut report, path, a.limit_percent)?;
            }
        }
        Ok(report)
    })();
    let _ = std::fs::remove_dir_all(&dir);
    let report = result?;
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
    if !report.confirmed.is_empty() {
        println!(
            "  slower than the baseline after {} pairs: {} ran {} more, judged on all of them",
            report.pairs,
            report.confirmed.join(", "),
            report.pairs
        );
    }
}
