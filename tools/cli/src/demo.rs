//! `auvnav demo`: simulates a voyage and runs it through the on-board chain as real processes
//! (emulated devices on pseudo-terminals, drivers, daemon, recorder; see [`crate::live`]), or,
//! with `--in-process`, straight through the navigation core (the same
//! [`auvnav_core::navigator::Navigator`] the daemon and replay use); then prints what happened
//! phase by phase against the simulated truth: the in-motion alignment, the navigation before
//! the USBL fixes and the USBL homing ([`crate::phases`]).

use crate::accuracy::Accuracy;
use crate::phases::{PhaseFigures, PhaseRecorder};
use crate::replay::{Output, Replay, ReplayConfig};
use anyhow::Context;
use auvnav_core::config::NavConfig;
use auvnav_core::navigator::NavCounters;
use auvnav_shm_schema::TruthStateV1;
use auvnav_sim::{self as sim, SimConfig, SimSummary, scenario::Scenario};
use serde::Serialize;
use std::path::PathBuf;

pub use crate::demo_start::{
    ALIGNED_HEADING_STD_DEG, COARSE_ALIGNMENT_S, DemoStart, session_config,
};

#[derive(clap::Args, Debug, Clone)]
pub struct DemoArgs {
    /// Simulated seconds (default: the whole scenario).
    #[arg(long)]
    pub seconds: Option<f64>,
    /// Play the voyage this many times faster than real time (processes only).
    #[arg(long, default_value_t = 8.0)]
    pub speed: f64,
    /// Run the voyage through the navigation core in this process (no drivers, daemon or
    /// shared memory): fast, for the whole scenario.
    #[arg(long)]
    pub in_process: bool,
    /// Built-in scenario or scenario file (`homing`: alignment, then USBL homing to the docking
    /// station; `lawnmower`: a survey without USBL; `dive`: from the surface and back, with GNSS
    /// fixes at the surface). Default: `homing`, or `dive` with `--gnss`.
    #[arg(long)]
    pub scenario: Option<String>,
    /// How the navigator starts: `align` (the launch position only) or `known` (the true
    /// initial state).
    #[arg(long, value_enum, default_value_t = DemoStart::Align)]
    pub start: DemoStart,
    /// Random seed.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// The emulated IMU's protocol (processes only): `xsens` (an MTi sending its magnetic field
    /// too, which the daemon fuses as a heading aid) or `kvh1750`.
    #[arg(long, default_value = "xsens", value_parser = ["xsens", "kvh1750"])]
    pub imu: String,
    /// Also emulate a GNSS receiver in this protocol (`nmea`, the default, or `ubx`) and run
    /// `auvnav-gnss` on it (processes only): the surface fixes, passed by the driver while the
    /// depth on the bus says the vehicle is at the surface, reach the daemon and the recording.
    #[arg(long, value_name = "PROTOCOL", num_args = 0..=1, default_missing_value = "nmea",
          value_parser = ["nmea", "ubx"])]
    pub gnss: Option<String>,
    /// The coordinate system the emulated PD0 DVL records its bottom track in (processes only):
    /// instrument (x, y, z), beam (the four radial velocities) or earth (east, north, up with
    /// the attitude in the ensemble); `auvnav-dvl` converts each back.
    #[arg(long, value_enum, default_value_t = crate::emulate_ptys::Pd0Coordinates::Instrument)]
    pub pd0_coordinates: crate::emulate_ptys::Pd0Coordinates,
    /// Write the logs and solutions here (processes: voyage.mcap, record.mcap, live_nav.csv,
    /// replay_nav.csv and each process's log; in process: sim.mcap and nav.csv).
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// Also run the live view (`auvnav-live`, processes only) on this address, e.g.
    /// `127.0.0.1:8765`: open it in Foxglove with `deploy/foxglove-layout.json`.
    #[arg(long, value_name = "ADDRESS:PORT")]
    pub live_view: Option<std::net::SocketAddr>,
    /// How the processes are scheduled (processes only): `unit`, as the units run them
    /// (drivers SCHED_FIFO 60, daemon 50, the emulated devices 70; normal where SCHED_FIFO is
    /// not permitted, and the report says so), or `normal` (everything under the normal
    /// scheduler: the time stamps alone against the load).
    #[arg(long, value_enum, default_value_t = crate::process::Scheduling::Unit)]
    pub scheduling: crate::process::Scheduling,
    /// Kill the daemon (SIGKILL) this many simulated seconds into the run and start it again,
    /// as systemd would (processes only): it continues from its checkpoint, and the replay of
    /// the recording must reproduce every recorded solution, before and after the restart.
    #[arg(long, value_name = "SECONDS")]
    pub restart_daemon_at: Option<f64>,
    /// Print the result as JSON.
    #[arg(long)]
    pub json: bool,
}

/// The first truth record of a simulated voyage (simulates its first second).
pub fn first_truth(cfg: &SimConfig) -> anyhow::Result<TruthStateV1> {
    let short = SimConfig {
        duration_s: Some(1.0),
        ..cfg.clone()
    };
    let mut first = None;
    sim::simulate(&short, |m| -> anyhow::Result<()> {
        if let (None, auvnav_log::LogMessage::Truth(t)) = (&first, m) {
            first = Some(*t);
        }
        Ok(())
    })?;
    first.context("the simulation wrote no truth")
}

#[derive(Debug, Serialize)]
pub struct DemoResult {
    pub scenario: String,
    pub seed: u64,
    pub start: DemoStart,
    pub simulated: SimSummary,
    pub accuracy: Accuracy,
    pub phases: PhaseFigures,
    pub counters: NavCounters,
    pub wall_s: f64,
}

/// Runs a simulated voyage through the navigator (the same [`Replay`] as `auvnav replay`, fed
/// from memory) from the true initial state; optionally writes the solution as CSV rows.
pub fn run_voyage(
    cfg: &SimConfig,
    nav_cfg: NavConfig,
    csv: Option<&mut dyn std::io::Write>,
) -> anyhow::Result<(SimSummary, Accuracy, NavCounters)> {
    let session = ReplayConfig {
        navigation: nav_cfg,
        ..Default::default()
    };
    run_session_voyage(cfg, &session, csv, None)
}

/// [`run_voyage`] with a whole session configuration (`[initial]` or `[alignment]`), and the
/// phase figures collected into `phases` when given.
pub fn run_session_voyage(
    cfg: &SimConfig,
    session: &ReplayConfig,
    mut csv: Option<&mut dyn std::io::Write>,
    mut phases: Option<&mut PhaseRecorder>,
) -> anyhow::Result<(SimSummary, Accuracy, NavCounters)> {
    let mut replay = Replay::new(session, 100.0);
    if let Some(w) = csv.as_deref_mut() {
        writeln!(w, "{}", crate::csv::NAV_HEADER)?;
    }
    // Each simulated message goes straight into the navigator: nothing is held in memory but
    // what the phase figures keep.
    let mut write = |o: Output| {
        let s = |ns: u64| ns as f64 * 1e-9;
        match (o, phases.as_deref_mut()) {
            (Output::Solution(sol), p) => {
                if let Some(p) = p {
                    p.solution(s(sol.host_time_ns), sol);
                }
                if let Some(w) = csv.as_deref_mut() {
                    crate::csv::write_nav_row(w, sol)?;
                }
            }
            (Output::Truth(t), Some(p)) => p.truth(s(t.host_time_ns), t),
            (Output::Diagnostics(d), Some(p)) => p.diagnostics(s(d.host_time_ns), d),
            _ => {}
        }
        Ok(())
    };
    let mut first_imu_ns = None;
    let summary = sim::simulate(cfg, |m| -> anyhow::Result<()> {
        if let auvnav_log::LogMessage::Imu(x) = m {
            first_imu_ns.get_or_insert(x.host_time_ns);
        }
        replay.process(m, &mut write)
    })?;
    replay.finish(&mut write)?;
    if let (Some(p), Some(t)) = (phases, first_imu_ns) {
        p.imu(t as f64 * 1e-9);
    }
    Ok((
        summary,
        replay.accuracy().unwrap_or_default(),
        replay.nav_counters(),
    ))
}

impl DemoArgs {
    /// The scenario: the one named, or `dive` with `--gnss` (fixes need a surface) and `homing`
    /// without.
    pub fn scenario_name(&self) -> &str {
        match (&self.scenario, &self.gnss) {
            (Some(s), _) => s,
            (None, Some(_)) => "dive",
            (None, None) => "homing",
        }
    }
}

/// The simulation of the demo's scenario.
fn sim_config(a: &DemoArgs) -> anyhow::Result<SimConfig> {
    let scenario = Scenario::load(a.scenario_name())?;
    let effects = scenario.effects()?;
    Ok(SimConfig {
        scenario,
        effects,
        seed: a.seed,
        duration_s: a.seconds,
    })
}

pub fn run(a: &DemoArgs) -> anyhow::Result<()> {
    if let Some(s) = a.seconds
        && !(s.is_finite() && s > 1.0)
    {
        return Err(crate::Failure::Usage(format!("--seconds {s}: expected more than 1 s")).into());
    }
    if !a.in_process {
        return run_processes(a);
    }
    let cfg = sim_config(a)?;
    let start = std::time::Instant::now();
    let mut csv_file = None;
    if let Some(dir) = &a.out {
        std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
        sim::simulate_to_log(&cfg, &dir.join("sim.mcap"))?;
        let f = std::fs::File::create(dir.join("nav.csv")).context("creating nav.csv")?;
        csv_file = Some(std::io::BufWriter::new(f));
    }
    let session = session_config(&cfg, a.start, true, &first_truth(&cfg)?);
    let has_usbl = session.navigation.usbl.is_some();
    let has_ranges = session.navigation.ranges.is_some();
    let mut recorder = PhaseRecorder::new();
    let (simulated, accuracy, counters) = run_session_voyage(
        &cfg,
        &session,
        csv_file.as_mut().map(|w| w as &mut dyn std::io::Write),
        Some(&mut recorder),
    )?;
    if let Some(mut w) = csv_file {
        std::io::Write::flush(&mut w)?;
    }
    let result = DemoResult {
        scenario: cfg.scenario.name.clone(),
        seed: cfg.seed,
        start: a.start,
        phases: recorder.figures(simulated.usbl_outliers),
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
            } else if has_ranges {
                " + LBL ranges (tight)"
            } else {
                ""
            }
        );
        print_phases(&result.phases, has_ranges);
        println!(
            "  over the whole run (alignment included): horizontal error final {:.2} m, max {:.2} m, CEP50 {:.2} m; heading error RMS {:.4} deg",
            acc.horizontal_error_final_m,
            acc.horizontal_error_max_m,
            acc.horizontal_error_cep50_m,
            acc.heading_error_rms_deg
        );
        println!(
            "  fused: {} DVL ({} rejected), {} depth ({} rejected); {:.2} s wall",
            result.counters.dvl_fused,
            result.counters.dvl_rejected,
            result.counters.depth_fused,
            result.counters.depth_rejected,
            result.wall_s
        );
        if has_ranges {
            let c = &result.counters;
            println!(
                "  acoustic ranges: {} fused, {} rejected by the gate, {} invalid",
                c.ranges_fused, c.ranges_rejected, c.ranges_invalid
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

/// The phase lines of the summary (`ranges`: the navigator fuses LBL ranges).
pub fn print_phases(p: &PhaseFigures, ranges: bool) {
    if let Some(al) = &p.alignment {
        println!(
            "  alignment: started with no heading (first estimate {:+.1} deg off); coarse {:.0} s, then DVL-aided fine alignment",
            al.first_heading_error_deg, COARSE_ALIGNMENT_S
        );
        match (al.aligned_after_s, al.heading_error_at_aligned_deg) {
            (Some(t), Some(e)) => println!(
                "    aligned after {t:.1} s: heading error {e:+.3} deg (reported sigma {:.3} deg), position error {:.2} m (sigma {:.2} m)",
                al.heading_std_at_aligned_deg.unwrap_or(f64::NAN),
                al.horizontal_error_at_aligned_m.unwrap_or(f64::NAN),
                al.horizontal_std_at_aligned_m.unwrap_or(f64::NAN),
            ),
            _ => println!("    NOT aligned by the end of the run"),
        }
    }
    if let Some(e) = &p.before_usbl {
        println!(
            "  navigation {:.0}-{:.0} s (INS + DVL + depth{}): horizontal error RMS {:.2} m, max {:.2} m, at the end {:.2} m",
            e.from_s,
            e.to_s,
            if ranges { " + LBL ranges" } else { "" },
            e.horizontal_error_rms_m,
            e.horizontal_error_max_m,
            e.horizontal_error_final_m
        );
    }
    if let Some(u) = &p.usbl {
        println!(
            "  USBL homing from {:.0} s: {} fixes fused, {} rejected by the gate ({} multipath outliers simulated); largest fused range innovation {:.2} m",
            u.first_fix_after_s,
            u.fused,
            u.rejected,
            u.outliers_simulated,
            u.largest_fused_range_innovation_m
        );
        if let Some(e) = &u.error {
            println!(
                "    horizontal error {:.2} m at the first fix; from {:.0} s on: RMS {:.2} m, max {:.2} m, at the end {:.2} m",
                u.horizontal_error_at_first_fix_m.unwrap_or(f64::NAN),
                e.from_s,
                e.horizontal_error_rms_m,
                e.horizontal_error_max_m,
                e.horizontal_error_final_m
            );
        }
    }
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
    let gnss = a
        .gnss
        .as_deref()
        .and_then(auvnav_drivers::device::Protocol::from_name);
    let r = crate::demo_processes::run_live(
        a.scenario_name(),
        a.start,
        imu,
        gnss,
        a.pd0_coordinates,
        a.seed,
        a.seconds,
        a.speed,
        a.out.as_deref(),
        a.live_view,
        a.scheduling,
        a.restart_daemon_at,
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
            "  processes: emulated PD0 DVL, {} IMU, SeaTrac USBL{} on pseudo-terminals; \
             auvnav-dvl, -imu, -usbl{}, -can (depth); auvnavd; auvnav record{}",
            r.imu,
            r.gnss
                .as_ref()
                .map(|g| format!(", {} GNSS receiver", g.to_uppercase()))
                .unwrap_or_default(),
            if r.gnss.is_some() { ", -gnss" } else { "" },
            r.live_view
                .as_ref()
                .map(|a| format!("; live view on ws://{a}"))
                .unwrap_or_default()
        );
        println!("  scheduling: {}", r.scheduling);
        let ranges = auvnav_sim::scenario::Scenario::load(&r.scenario)
            .ok()
            .and_then(|s| s.acoustic)
            .is_some_and(|a| a.kind == auvnav_sim::scenario::AcousticKind::Lbl);
        if ranges {
            println!(
                "  LBL: the SeaTrac emulated as ranging the scenario's seabed beacons (auvnav-usbl's range_beacons), their ranges fused tight"
            );
            if r.speed != 1.0 {
                println!(
                    "  NOTE: played at {}x, the daemon's clock runs {}x the voyage's while sound keeps its travel time: the ranges' motion compensation spans {}x the true interval (--speed 1 gives the on-board figure)",
                    r.speed, r.speed, r.speed
                );
            }
        }
        print_phases(&r.phases, ranges);
        if r.gnss.is_some() {
            println!(
                "  GNSS: {} surface fixes simulated, {} recorded (the driver passes fixes while the depth on the bus is at most 0.5 m)",
                r.gnss_fixes_simulated, r.gnss_fixes_recorded
            );
        }
        println!(
            "  live solution: {} rows; horizontal error over the whole run (alignment included): final {:.2} m, max {:.2} m, CEP50 {:.2} m",
            r.solutions,
            acc.horizontal_error_final_m,
            acc.horizontal_error_max_m,
            acc.horizontal_error_cep50_m,
        );
        for e in &r.stamp_errors {
            println!(
                "  {} time stamps against the line (µs, p50 / p99 / max): {:+.0} / {:+.0} / {:+.0} ({} frames; the emulator wrote {:.0} / {:.0} / {:.0} late)",
                e.kind.to_uppercase(),
                e.against_line_us.p50,
                e.against_line_us.p99,
                e.against_line_us.max,
                e.frames,
                e.emulator_late_us.p50,
                e.emulator_late_us.p99,
                e.emulator_late_us.max,
            );
        }
        match r.daemon_restarted_at_s {
            Some(at) => println!(
                "  daemon killed at {at:.0} s and restarted from its checkpoint; replay of the recording reproduces every recorded solution: {}",
                if r.replay_identical { "yes" } else { "NO" }
            ),
            None => println!(
                "  replay of the recording byte-identical to the live solution: {}",
                if r.replay_identical { "yes" } else { "NO" }
            ),
        }
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
