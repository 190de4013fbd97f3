//! `auvnav`: the offline tools. `main` only parses arguments and dispatches; the work is done by
//! library functions that tests drive directly.
//!
//! Long on purpose: the command line's definition: every subcommand's arguments and their dispatch,
//! which clap takes as one tree.
#![forbid(unsafe_code)]

use anyhow::{Context, bail};
use auvnav_sim::{self as sim, SimConfig, effects, scenario::Scenario};
use clap::{Parser, Subcommand};
use std::path::PathBuf;

#[derive(Parser)]
#[command(
    name = "auvnav",
    version = auvnav_version::LONG,
    about = "AUV navigation: simulator, logs, replay and offline tools"
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Simulate a voyage and its sensors into a log (MCAP).
    Sim(SimArgs),
    /// Simulate a voyage and run it through the on-board chain (real processes, or the core in
    /// process): in-motion alignment from no heading, USBL homing, figures against the truth.
    Demo(auvnav_tools::demo::DemoArgs),
    /// What a log holds: header, channels with counts and rates, duration, configuration.
    Info(auvnav_tools::log_info::InfoArgs),
    /// Run a log through the navigation core; with a truth channel, report the accuracy.
    Replay(auvnav_tools::replay::ReplayArgs),
    /// Post-process logs: forward-backward (RTS) smoothing with fixes from the log and a fix
    /// file; smoothed track (CSV, MCAP, GeoJSON, KML, plain CSV), parameters and a report.
    Smooth(auvnav_tools::smooth::SmoothOptions),
    /// Decode a captured device byte stream (one JSON object per frame with --json).
    Decode(auvnav_tools::decode::DecodeArgs),
    /// Play a log's sensor messages into pseudo-terminals in the devices' protocols.
    Emulate(auvnav_tools::emulate_ptys::EmulateArgs),
    /// The IMU and DVL of ArduPilot SITL's vehicle, from its true state through the simulator's
    /// sensor models, into pseudo-terminals: the sensor side of a closed loop with an autopilot.
    SitlSensors(auvnav_tools::sitl_sensors::SitlSensorsArgs),
    /// Record every topic of a deployment to a log (MCAP); or recover a killed recorder's log.
    Record(auvnav_recorder::RecordArgs),
    /// S-ALIGN fine-alignment Monte Carlo: error models 1/2/3 on moored, straight, turning runs.
    Align(auvnav_tools::align::AlignOptions),
    /// S-ALIGN fine alignment on the Snapir segments from the reference heading plus an offset.
    AlignMeasured(auvnav_tools::align::AlignMeasuredOptions),
    /// S-USBL Monte Carlo on the docking scenario: loose or tight USBL coupling, ukf/akf/aukf,
    /// with multipath outliers and array orientation errors.
    Usbl(auvnav_tools::usbl::UsblOptions),
    /// Calibrate an installation from recorded voyages by replaying them through the core.
    Calibrate {
        #[command(subcommand)]
        what: CalibrateWhat,
    },
    /// Apply named simulator effects (see `auvnav sim --list-effects`) to the sensor messages
    /// of a recorded log, simulated or measured; the output's header says what was applied.
    Perturb(PerturbArgs),
    /// Find where the simulator's sensor models disagree with a log, name the cause from the
    /// effect vocabulary, and measure the gain on held-out data.
    Discover(auvnav_tools::discover::command::DiscoverOptions),
    /// Turn a measured data set into a log.
    Import {
        #[command(subcommand)]
        what: ImportWhat,
    },
    /// Monte Carlo studies of the navigation filter.
    Montecarlo {
        #[command(subcommand)]
        what: MonteCarloWhat,
    },
    /// Shell completions for auvnav (standard output), or for every auvnav program (--out DIR).
    Completions {
        /// The shell.
        shell: clap_complete::Shell,
        /// Write one file per program (auvnav, auvnavd, auvnav-dvl, -imu, -usbl, -can) here.
        #[arg(long)]
        out: Option<PathBuf>,
    },
    /// Manual pages (roff) of every auvnav program and auvnav's subcommands, into a folder.
    Man {
        /// The folder (created if missing); install into e.g. /usr/local/share/man/man1.
        #[arg(long)]
        out: PathBuf,
    },
    /// Throughput benchmarks, printed as JSON with --json.
    Bench {
        #[command(subcommand)]
        what: BenchWhat,
    },
}

#[derive(Subcommand)]
enum MonteCarloWhat {
    /// Filter consistency: normalised estimation error squared of position, velocity and attitude.
    Nees(auvnav_tools::montecarlo::NeesOptions),
    /// Smoother consistency and gain: runs with matched sensor errors, a start and an end fix,
    /// smoothed; per-axis NEES of the forward and the smoothed position, and their errors.
    Smoother(auvnav_tools::smooth::montecarlo::SmootherMonteCarloOptions),
    /// Tight acoustic ranges against the device's fixes fused loosely: a boat's four-receiver
    /// array, three LBL beacons, a single transducer on a ship; 20-minute surveys with IMU, DVL
    /// and depth, with multipath outliers
    Ranges(auvnav_tools::ranges::RangesOptions),
}

#[derive(Subcommand)]
enum CalibrateWhat {
    /// S-CAL: DVL mounting, scale factor, lever arm and time offset that minimise the dead
    /// reckoning's error at the fixes (CEP50 of error/distance), with standard deviations,
    /// observability, hold-out evaluation, a [navigation.dvl] table and a report.
    Dvl(auvnav_tools::calibrate::CalibrateDvlOptions),
    /// S-MAG: magnetometer hard and soft iron from recordings with the attitude the vehicle
    /// reached (ellipsoid, the seed's particle swarm, or Levenberg–Marquardt with constrained
    /// fallbacks), checked on held-out readings, with a [navigation.magnetometer] table, plots
    /// and a verdict.
    Mag(auvnav_tools::calibrate::mag::CalibrateMagOptions),
}

#[derive(clap::Args)]
struct PerturbArgs {
    /// The log to perturb.
    log: PathBuf,
    /// An effect: NAME=VALUE or NAME=V1,V2,V3 (repeatable).
    #[arg(
        long = "effect",
        value_name = "NAME=VALUE",
        value_parser = auvnav_tools::args::effect_setting,
        required_unless_present = "effects_from"
    )]
    effects: Vec<String>,
    /// Effects from an effect set file (`[effects]` table), applied before `--effect`.
    #[arg(long, value_name = "FILE")]
    effects_from: Option<PathBuf>,
    /// Seed of the noise effects.
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Output log (written atomically).
    #[arg(long)]
    out: PathBuf,
    /// Print what was done as JSON.
    #[arg(long)]
    json: bool,
}

fn run_perturb(a: &PerturbArgs) -> anyhow::Result<()> {
    let mut settings = Vec::new();
    if let Some(p) = &a.effects_from {
        for (name, v) in read_effect_set(p)? {
            let v: Vec<String> = v.iter().map(|x| x.to_string()).collect();
            settings.push(format!("{name}={}", v.join(",")));
        }
    }
    settings.extend(a.effects.iter().cloned());
    let p = sim::perturb::Perturbation::parse(&settings, a.seed)?;
    let counts = sim::perturb::perturb_log(&a.log, &a.out, &p)?;
    if a.json {
        auvnav_tools::json::print(&serde_json::json!({
            "input": a.log,
            "output": a.out,
            "effects": p.describe(),
            "seed": a.seed,
            "counts": counts,
        }))?;
    } else {
        eprintln!(
            "{}: {} applied to {} messages ({} IMU, {} DVL, {} depth, {} attitude changed; {} DVL moved by the time offset, {} moved before time zero and left out)",
            a.out.display(),
            p.describe(),
            counts.messages,
            counts.imu_changed,
            counts.dvl_changed,
            counts.depth_changed,
            counts.attitude_changed,
            counts.dvl_restamped,
            counts.dvl_dropped
        );
    }
    Ok(())
}

fn run_calibrate_mag(a: &auvnav_tools::calibrate::mag::CalibrateMagOptions) -> anyhow::Result<()> {
    use auvnav_tools::calibrate::mag::report;
    let r = auvnav_tools::calibrate::mag::run(a)?;
    if a.json {
        auvnav_tools::json::print(&r)?;
    } else {
        print!("{}", report::text(&r));
    }
    Ok(())
}

fn run_calibrate_dvl(a: &auvnav_tools::calibrate::CalibrateDvlOptions) -> anyhow::Result<()> {
    if let Some(r) = auvnav_tools::calibrate::calibrate_dvl_surface(a)? {
        if a.json {
            auvnav_tools::json::print(&r)?;
        } else {
            print!("{}", auvnav_tools::calibrate::surface::text(&r));
        }
        return Ok(());
    }
    let r = auvnav_tools::calibrate::calibrate_dvl(a)?;
    if a.json {
        auvnav_tools::json::print(&r)?;
    } else {
        print!("{}", auvnav_tools::calibrate::report::text(&r));
    }
    Ok(())
}

#[derive(Subcommand)]
enum ImportWhat {
    /// A segment of the Snapir AUV data set (IMU, DVL, reference solution as truth, depth from
    /// the reference).
    Snapir(auvnav_tools::import::SnapirOptions),
    /// A Teledyne RDI PD0 file with GPS (WinRiver NMEA blocks): the bottom track as the DVL
    /// channel, the GPS velocity over ground with the DVL's own attitude as the reference
    Pd0(auvnav_tools::import::Pd0Options),
    /// A SonTek RiverSurveyor (M9, S5) MATLAB export from RiverSurveyor Live: the bottom track
    /// as the DVL channel (rotated back into the instrument frame), the compass on the attitude
    /// channel, every GGA fix as a GNSS fix, and the GPS velocity over ground with the compass
    /// attitude as the reference (a surface run: `auvnav replay` and `calibrate dvl` take it).
    Riversurveyor(auvnav_tools::import::RiverSurveyorOptions),
    /// A magnetometer recording in CSV (magnetometer and accelerometer columns, as
    /// `auvnav calibrate mag` reads them): the magnetometer channel and the specific force, for
    /// `auvnav discover` without a reference attitude.
    MagCsv(auvnav_tools::import::MagCsvOptions),
    /// A Water Linked Underwater GPS G2 acoustic log (CSV): per-receiver ranges with the
    /// system's own fixes, for `auvnav discover` (receiver geometry, range noise, outliers).
    UgpsG2(auvnav_tools::import::UgpsOptions),
    /// A MAVLink telemetry log (`.tlog`, as QGroundControl, BlueOS and pymavlink write it): the
    /// autopilot's IMU and compass, pressure sensor (depth), attitude estimate and GPS, for
    /// `auvnav info`, `replay`, `smooth` and `calibrate` on what an ArduSub vehicle recorded.
    Tlog(auvnav_tools::import::TlogOptions),
}

#[derive(Subcommand)]
enum BenchWhat {
    /// Model discovery: hidden-effect trials (seeded draws of an effect and a magnitude) and
    /// null trials; rates of right names and false discoveries, confusion table, time per trial.
    Discover {
        /// Trials with a hidden effect.
        #[arg(long, default_value_t = 200)]
        hidden: usize,
        /// Trials with nothing hidden.
        #[arg(long, default_value_t = 100)]
        null: usize,
        /// Trials with two different effects hidden at once.
        #[arg(long, default_value_t = 100)]
        pairs: usize,
        /// Detection floor: trials per effect at each fraction (1, 1/2, 1/4, 1/8) of the drawn
        /// magnitudes (0: skip; at most 100).
        #[arg(long, default_value_t = 5, value_parser = clap::value_parser!(u64).range(0..=100))]
        floor: u64,
        /// Trials with coloured DVL noise (a Gauss–Markov velocity error): half with nothing
        /// hidden, half with one effect hidden.
        #[arg(long, default_value_t = 200)]
        coloured: usize,
        /// Trials of three voyages with coloured DVL noise discovered together: half with
        /// nothing hidden, half with one installation effect hidden in all three (a rate of
        /// false discoveries near 5 % needs fifty null trials to be told from 10 %).
        #[arg(long, default_value_t = 100)]
        coloured_voyages: usize,
        /// Trials on surface runs (a boat with a compass, a DVL and GNSS, no IMU; discovered
        /// with --moving-bed, the GNSS positions deciding): half with white noise, half with a
        /// Gauss–Markov DVL error, each half null and one effect hidden (the compass deviation
        /// and the moving bed among them).
        #[arg(long, default_value_t = 200)]
        surface: usize,
        /// Shift every trial's seed by this much (0 to 49 999; each kind keeps its block of
        /// seeds): the same benchmark on draws the defaults have not seen.
        #[arg(long, default_value_t = 0, value_parser = clap::value_parser!(u64).range(0..50_000))]
        seed_offset: u64,
        /// The measured data directory (`../shared/data`): also time discovery on each data set.
        #[arg(long, value_name = "DIR")]
        data: Option<PathBuf>,
        #[arg(long)]
        json: bool,
    },
    /// Latency and throughput of two `auvnav-bridge` processes over loopback Zenoh (IMU
    /// samples at 200 Hz and 1 kHz, vehicle bus → topside bus).
    Bridge {
        /// Seconds per rate.
        #[arg(long, default_value_t = 10.0)]
        seconds: f64,
        #[arg(long)]
        json: bool,
    },
    /// Cost of one USBL update (loose/tight × ukf/akf/aukf) on the docking scenario.
    Usbl {
        /// Seconds of the docking scenario (one fix per second).
        #[arg(long, default_value_t = 600.0)]
        seconds: f64,
        #[arg(long)]
        json: bool,
    },
    /// Wall time of the S-ALIGN Monte Carlo (220 runs, 1200 s, turning) per error model.
    Align {
        #[arg(long, default_value_t = 220)]
        runs: usize,
        #[arg(long)]
        json: bool,
    },
    /// End-to-end latency of the on-board chain with real processes: IMU frame on a
    /// pseudo-terminal to navigation solution, at 200 Hz and 1 kHz, with DVL, USBL and the
    /// recorder running; daemon and recorder CPU use.
    E2e {
        /// Seconds per IMU rate.
        #[arg(long, default_value_t = 10.0)]
        seconds: f64,
        /// Also run the vehicle's outputs: auvnav-mavlink (ODOMETRY at 10 Hz) and auvnav-bridge
        /// (the solution exported at 10 Hz and the ROS 2 topics).
        #[arg(long)]
        outputs: bool,
        /// `unit`: the processes scheduled as the units run them (drivers SCHED_FIFO 60, daemon
        /// 50), where permitted, and the report says which it got; `normal`: the normal scheduler.
        #[arg(long, value_enum, default_value_t = auvnav_tools::process::Scheduling::Unit)]
        scheduling: auvnav_tools::process::Scheduling,
        #[arg(long)]
        json: bool,
    },
    /// Decoder throughput per protocol (MB/s).
    Decode {
        #[arg(long, default_value_t = 5)]
        repeat: usize,
        /// Seconds of frames per rate (200 Hz, 1 kHz) for the pseudo-terminal → driver →
        /// subscriber latency; 0 skips it.
        #[arg(long, default_value_t = 10.0)]
        pty_seconds: f64,
        #[arg(long)]
        json: bool,
    },
    /// INS/DVL/depth accuracy on a simulated scenario (default: the 6 km survey) over seeds.
    Accuracy {
        #[arg(long, default_value = "survey")]
        scenario: String,
        /// Seeds 1..=N.
        #[arg(long, default_value_t = 10)]
        seeds: u64,
        #[arg(long)]
        json: bool,
    },
    /// Wall time, real-time factor and peak memory of `auvnav smooth` on the replay log (one hour
    /// of 200 Hz IMU, 1 Hz DVL and depth) and on a long voyage, each in a child process.
    Smooth {
        /// Hours of the timed log.
        #[arg(long, default_value_t = 1.0)]
        hours: f64,
        /// Runs on it (the median is reported).
        #[arg(long, default_value_t = 3)]
        repeat: usize,
        /// Hours of the long voyage, smoothed once for its peak memory (0: skip).
        #[arg(long, default_value_t = 10.0)]
        long_hours: f64,
        /// `auvnav smooth --memory-budget-mib` for the runs.
        #[arg(long, default_value_t = 1024)]
        memory_budget_mib: usize,
        /// `auvnav smooth --solution-rate` for the runs (default: every solution written).
        #[arg(long)]
        solution_rate: Option<f64>,
        #[arg(long)]
        json: bool,
    },
    /// Regression guard: this build's replay and smoothing against a base build's, or against a
    /// fixed reference workload compiled in, run alternately on one core and judged as ratios;
    /// with --baseline, exit status 3 when slower beyond the limit and the run's noise.
    Guard(auvnav_tools::bench::GuardArgs),
    /// Real-time factor of INS/DVL/depth replay: one hour of 200 Hz IMU, 1 Hz DVL, 1 Hz depth.
    Replay {
        /// Log hours.
        #[arg(long, default_value_t = 1.0)]
        hours: f64,
        /// Repetitions (the median is reported).
        #[arg(long, default_value_t = 5)]
        repeat: usize,
        #[arg(long)]
        json: bool,
    },
    /// Wall time and full replays of the DVL calibration methods (fast, seed, smoother, two-point) on the
    /// simulated S-CAL campaign (four voyages of 5.8–6.9 km) on all cores.
    Calibrate {
        /// Campaign seed.
        #[arg(long, default_value_t = 1)]
        seed: u64,
        /// Methods to time (default: all three).
        #[arg(long, value_enum, value_delimiter = ',')]
        methods: Vec<auvnav_tools::calibrate::Method>,
        #[arg(long)]
        json: bool,
    },
    /// Wall time of the magnetometer calibration methods (auto, lm, sphere, ellipsoid, seed) on
    /// 10 000 simulated samples, full and AUV-like attitude coverage, with their errors; with
    /// --recording, every method on measured recordings, scored on the held-out rest.
    Mag {
        #[arg(long, default_value_t = 10_000)]
        samples: usize,
        /// Repetitions (the median is reported).
        #[arg(long, default_value_t = 3)]
        repeat: usize,
        /// Measured recordings (CSV or .mcap, as `calibrate mag` reads them); repeatable.
        #[arg(long)]
        recording: Vec<std::path::PathBuf>,
        /// Fit fractions of each recording (the rest is held out).
        #[arg(long, value_delimiter = ',', default_values_t = [0.3, 0.5, 0.7])]
        fit_fraction: Vec<f64>,
        #[arg(long)]
        json: bool,
    },
    /// Time to simulate and write one hour of 200 Hz IMU, 5 Hz DVL, 1 Hz USBL and 1 Hz depth.
    Sim {
        /// Simulated hours.
        #[arg(long, default_value_t = 1.0)]
        hours: f64,
        /// Repetitions (the median is reported).
        #[arg(long, default_value_t = 3)]
        repeat: usize,
        #[arg(long)]
        json: bool,
    },
}

#[derive(clap::Args)]
struct SimArgs {
    /// Built-in scenario name (see --list-scenarios) or a scenario TOML file.
    #[arg(long, default_value = "docking")]
    scenario: String,
    /// Random seed; the same seed gives the same bytes.
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Output log file (written atomically: nothing is left behind on error).
    #[arg(long)]
    out: Option<PathBuf>,
    /// Switch an effect on: NAME=VALUE or NAME=V1,V2,V3 (repeatable; see --list-effects).
    #[arg(long = "effect", value_name = "NAME=VALUE", value_parser = auvnav_tools::args::effect_setting)]
    effects: Vec<String>,
    /// Effects from a file: the `[effects]` table of an effect set (`auvnav discover
    /// --write-effects`, a report directory's `effects.toml`) or of a scenario file; applied on
    /// top of the scenario's effects, before `--effect`.
    #[arg(long, value_name = "FILE")]
    effects_from: Option<PathBuf>,
    /// Drop the scenario's own effects and start from ideal sensors.
    #[arg(long)]
    clean: bool,
    /// Simulate only this many seconds.
    #[arg(long)]
    duration: Option<f64>,
    /// List the effects with unit, allowed range and default, then exit.
    #[arg(long)]
    list_effects: bool,
    /// List the built-in scenarios, then exit.
    #[arg(long)]
    list_scenarios: bool,
    /// Print the run summary as JSON.
    #[arg(long)]
    json: bool,
    /// Simulate a calibration campaign instead of one scenario (scal: the S-CAL trial's four
    /// straight voyages; scal-turns: with turns and speed changes); --out is then a directory
    /// that receives voyage_1.mcap … voyage_4.mcap, and --effect adds installation errors.
    #[arg(long, value_name = "NAME")]
    campaign: Option<String>,
}

fn run_campaign(a: &SimArgs, name: &str) -> anyhow::Result<()> {
    let kind = sim::campaign::CampaignKind::parse(name)?;
    let Some(dir) = a.out.as_ref() else {
        bail!("--out DIR is required with --campaign (the directory for the voyages)");
    };
    let mut installation = match &a.effects_from {
        Some(p) => read_effect_set(p)?,
        None => Vec::new(),
    };
    for setting in &a.effects {
        installation.push(effects::parse_setting(setting)?);
    }
    let voyages = sim::campaign::campaign(kind, a.seed, &installation)?;
    std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    let mut summaries = Vec::new();
    for (i, cfg) in voyages.iter().enumerate() {
        let out = dir.join(format!("voyage_{}.mcap", i + 1));
        let s = sim::simulate_to_log(cfg, &out)
            .with_context(|| format!("simulating into {}", out.display()))?;
        if !a.json {
            eprintln!(
                "{}: {} s, {:.0} m, {} GNSS fixes",
                out.display(),
                s.duration_s,
                s.distance_m,
                s.gnss
            );
        }
        summaries.push(s);
    }
    if a.json {
        auvnav_tools::json::print(&serde_json::json!({ "voyages": summaries }))?;
    }
    Ok(())
}

/// The settings of an effect set file (`[effects]` table).
fn read_effect_set(path: &std::path::Path) -> anyhow::Result<Vec<(String, Vec<f64>)>> {
    let text =
        std::fs::read_to_string(path).with_context(|| format!("reading {}", path.display()))?;
    effects::set::parse(&text).with_context(|| format!("effect set {}", path.display()))
}

fn sim_config(a: &SimArgs) -> anyhow::Result<SimConfig> {
    let scenario = Scenario::load(&a.scenario)?;
    let mut fx = if a.clean {
        effects::Effects::default()
    } else {
        scenario.effects()?
    };
    if let Some(p) = &a.effects_from {
        effects::set::apply(&mut fx, &read_effect_set(p)?)?;
    }
    for setting in &a.effects {
        let (name, values) = effects::parse_setting(setting)?;
        fx.set(&name, &values)?;
    }
    if let Some(d) = a.duration
        && !(d.is_finite() && d > 0.0 && d <= 1.0e6)
    {
        bail!("--duration {d}: allowed range is 0 < duration <= 1e6 s");
    }
    Ok(SimConfig {
        scenario,
        effects: fx,
        seed: a.seed,
        duration_s: a.duration,
    })
}

fn run_sim(a: SimArgs) -> anyhow::Result<()> {
    if a.list_effects {
        print!("{}", effects::listing());
        return Ok(());
    }
    if a.list_scenarios {
        print!("{}", sim::scenario::listing());
        return Ok(());
    }
    if let Some(name) = &a.campaign {
        return run_campaign(&a, name);
    }
    let cfg = sim_config(&a)?;
    let Some(out) = a.out.as_ref() else {
        bail!("--out FILE is required (the log to write)");
    };
    let summary = sim::simulate_to_log(&cfg, out)
        .with_context(|| format!("simulating into {}", out.display()))?;
    if a.json {
        auvnav_tools::json::print(&summary)?;
    } else {
        eprintln!(
            "{}: {} s of scenario {} (seed {}): {} IMU, {} DVL ({} with bottom lock), {} USBL ({} outliers), {} depth, {} truth; {:.0} m travelled",
            out.display(),
            summary.duration_s,
            cfg.scenario.name,
            cfg.seed,
            summary.imu,
            summary.dvl,
            summary.dvl_valid,
            summary.usbl,
            summary.usbl_outliers,
            summary.depth,
            summary.truth,
            summary.distance_m
        );
    }
    Ok(())
}

fn run_replay(a: &auvnav_tools::replay::ReplayArgs) -> anyhow::Result<()> {
    let report = auvnav_tools::replay::run(a)?;
    if a.json {
        auvnav_tools::json::print(&report)?;
    } else {
        auvnav_tools::replay::print_report(&report);
    }
    if let Some(c) = report
        .recorded_comparison
        .as_ref()
        .filter(|c| !c.identical())
    {
        return Err(auvnav_tools::Failure::CheckFailed(format!(
            "the replay does not reproduce the recorded solutions ({} compared, {} differ, {} \
             without a replayed solution)",
            c.compared, c.differing, c.unmatched_recorded
        ))
        .into());
    }
    Ok(())
}

fn run_import_pd0(a: &auvnav_tools::import::Pd0Options) -> anyhow::Result<()> {
    let s = auvnav_tools::import::pd0(a)?;
    if a.json {
        auvnav_tools::json::print(&s)?;
    } else {
        eprintln!(
            "{}: {} ensembles ({} coordinates, {:.0} s): {} with a bottom-track velocity, {} reference records from {} GGA fixes and {} VTG ({:?} velocity); {} without a fix, {} with a bad time, {} decoder errors",
            a.out.display(),
            s.ensembles,
            s.coordinate_system,
            s.duration_s,
            s.bottom_track_velocity,
            s.reference,
            s.gga,
            s.vtg,
            s.velocity,
            s.gga_no_fix,
            s.bad_time,
            s.decoder_errors
        );
        if a.fixes.is_some() {
            eprintln!(
                "  fixes from --fixes: {} written as GNSS fixes, {} outside the file's time span, {} lines that did not parse",
                s.fixes_written, s.fixes_outside, s.fixes_unparsable_lines
            );
        }
    }
    Ok(())
}

fn run_import_riversurveyor(a: &auvnav_tools::import::RiverSurveyorOptions) -> anyhow::Result<()> {
    let s = auvnav_tools::import::riversurveyor(a)?;
    if a.json {
        auvnav_tools::json::print(&s)?;
    } else {
        eprintln!(
            "{}: RiverSurveyor {}, {} samples of {:.1} s ({:.0} s): {} with a bottom-track velocity ({} invalid, {} with a bad time), {} reference records ({:?} velocity), {} without GPS around them",
            a.out.display(),
            s.serial_number,
            s.samples,
            s.interval_s,
            s.duration_s,
            s.bottom_track_velocity,
            s.bottom_track_invalid,
            s.bad_time,
            s.reference,
            s.velocity,
            s.no_reference,
        );
        eprintln!(
            "  GPS: {} GGA fixes ({} without a fix, {} with a bad time, {} repeated), {} VTG; ADCP clock = UTC {:+.3} s (GGA delay spread {:.3} s); declination applied by the export {:.2} deg",
            s.gga,
            s.gga_no_fix,
            s.gga_bad_time,
            s.gga_repeated,
            s.vtg,
            s.adcp_clock_minus_utc_s,
            s.gga_delay_spread_s,
            s.magnetic_declination_deg,
        );
    }
    Ok(())
}

fn run_import_mag_csv(a: &auvnav_tools::import::MagCsvOptions) -> anyhow::Result<()> {
    let s = auvnav_tools::import::mag_csv(a)?;
    if a.json {
        auvnav_tools::json::print(&s)?;
    } else {
        eprintln!(
            "{}: {} magnetometer readings ({:.0} s), {} with an accelerometer reading, {} with a gyro reading; field {}, accelerometer {}; {} rows skipped, {} out of order",
            a.out.display(),
            s.readings,
            s.duration_s,
            s.with_accelerometer,
            s.with_gyro,
            s.field_unit,
            s.accelerometer_unit,
            s.skipped,
            s.out_of_order
        );
    }
    Ok(())
}

fn run_import_tlog(a: &auvnav_tools::import::TlogOptions) -> anyhow::Result<()> {
    let s = auvnav_tools::import::tlog(a)?;
    if a.json {
        auvnav_tools::json::print(&s)?;
    } else {
        eprintln!(
            "{}: {:.0} s of telemetry from {} MAVLink frames: {} IMU samples ({}), {} magnetometer, {} depth, {} attitude, {} GNSS fixes ({} without a 3D fix left out), {} DVL velocities; {} bad checksums, {} unknown messages, {} bytes skipped, {} implausible and {} out-of-order readings left out; {} boot(s) of the autopilot",
            a.out.display(),
            s.duration_s,
            s.frames,
            s.imu,
            s.imu_source,
            s.magnetometer,
            s.depth,
            s.attitude,
            s.gnss,
            s.gnss_without_fix,
            s.dvl,
            s.bad_checksum,
            s.unknown,
            s.bytes_skipped,
            s.implausible,
            s.out_of_order,
            s.autopilot_boots
        );
    }
    Ok(())
}

fn run_import_ugps(a: &auvnav_tools::import::UgpsOptions) -> anyhow::Result<()> {
    let s = auvnav_tools::import::ugps(a)?;
    if a.json {
        auvnav_tools::json::print(&s)?;
    } else {
        eprintln!(
            "{}: {} acoustic updates ({:.0} s) from {} rows, {} with a position fix; valid ranges per receiver {:?}; {} repeated rows and {} malformed left out",
            a.out.display(),
            s.updates,
            s.duration_s,
            s.rows,
            s.with_position,
            s.ranges,
            s.repeated,
            s.malformed
        );
        match &s.position_file {
            Some(f) => eprintln!(
                "  the array's pose (the topside's GNSS and heading) from {f}: {} poses; {} repeated rows and {} unusable left out",
                s.array_poses, s.array_poses_repeated, s.array_poses_left_out
            ),
            None => eprintln!(
                "  no *_g2_position.csv beside it: no array pose (the fixes stay relative to the topside)"
            ),
        }
    }
    Ok(())
}

fn run_import_snapir(a: &auvnav_tools::import::SnapirOptions) -> anyhow::Result<()> {
    let s = auvnav_tools::import::snapir(a)?;
    if a.json {
        auvnav_tools::json::print(&s)?;
    } else {
        eprintln!(
            "{}: segment {} ({:.0} s, {} messages): {} IMU, {} DVL, {} reference rows; skipped {} malformed, {} out of order",
            a.out.display(),
            s.segment,
            s.duration_s,
            s.messages,
            s.imu.rows,
            s.dvl.rows,
            s.reference.rows,
            s.imu.malformed + s.dvl.malformed + s.reference.malformed,
            s.imu.out_of_order + s.dvl.out_of_order + s.reference.out_of_order,
        );
        if let Some(al) = s.alignment {
            eprintln!(
                "  reference clock aligned to the IMU: offset {:+.2} s (rotation residual {:.3} deg per interval, {:.3} deg without; {} reference rows before the IMU dropped)",
                al.offset_s, al.residual_deg, al.residual_at_zero_deg, s.reference_before_imu
            );
        }
        eprintln!(
            "  replay starts from the reference at the segment start; depth is derived from the reference"
        );
    }
    Ok(())
}

/// A library's report printed as JSON or, for people, as text.
fn print_report<R, E>(r: Result<R, E>, json: bool, text: fn(&R)) -> anyhow::Result<()>
where
    R: serde::Serialize,
    E: Into<anyhow::Error>,
{
    let r = r.map_err(Into::into)?;
    if json {
        auvnav_tools::json::print(&r)?;
    } else {
        text(&r);
    }
    Ok(())
}

// Long on purpose: the dispatch of the `auvnav` subcommands: one arm per command.
fn main() -> std::process::ExitCode {
    let cli = Cli::parse();
    let result = match cli.command {
        Command::Sim(a) => run_sim(a),
        Command::Demo(a) => auvnav_tools::demo::run(&a),
        Command::Replay(a) => run_replay(&a),
        Command::Smooth(a) => print_report(
            auvnav_tools::smooth::run(&a),
            a.json,
            auvnav_tools::smooth::print_report,
        ),
        Command::Info(a) => auvnav_tools::log_info::run(&a).map(|_| ()),
        Command::Completions { shell, out } => completions(shell, out.as_deref()),
        Command::Man { out } => man_pages(&out),
        Command::Decode(a) => auvnav_tools::decode::run(&a).map(|_| ()),
        Command::Discover(a) => auvnav_tools::discover::command::run(&a).map(|_| ()),
        Command::Emulate(a) => auvnav_tools::emulate_ptys::run(&a).map(|_| ()),
        Command::SitlSensors(a) => auvnav_tools::sitl_sensors::run(&a).map(|_| ()),
        Command::Record(a) => auvnav_recorder::run(&a).map(|_| ()),
        Command::AlignMeasured(a) => auvnav_tools::align::run_measured(&a).map(|_| ()),
        Command::Align(a) => print_report(
            auvnav_tools::align::run(&a),
            a.json,
            auvnav_tools::align::print,
        ),
        Command::Usbl(a) if a.table => {
            print_report(auvnav_tools::usbl::run_table(&a), a.json, |r| {
                auvnav_tools::usbl::print_table(r)
            })
        }
        Command::Usbl(a) => print_report(
            auvnav_tools::usbl::run(&a),
            a.json,
            auvnav_tools::usbl::print,
        ),
        Command::Montecarlo { what } => match what {
            MonteCarloWhat::Nees(a) => auvnav_tools::montecarlo::run_nees(&a),
            MonteCarloWhat::Smoother(a) => auvnav_tools::smooth::montecarlo::run(&a),
            MonteCarloWhat::Ranges(a) => print_report(
                auvnav_tools::ranges::run(&a),
                a.json,
                |r: &Vec<auvnav_tools::ranges::RangesReport>| auvnav_tools::ranges::print(r),
            ),
        },
        Command::Calibrate { what } => match what {
            CalibrateWhat::Dvl(a) => run_calibrate_dvl(&a),
            CalibrateWhat::Mag(a) => run_calibrate_mag(&a),
        },
        Command::Perturb(a) => run_perturb(&a),
        Command::Import { what } => match what {
            ImportWhat::Snapir(a) => run_import_snapir(&a),
            ImportWhat::Pd0(a) => run_import_pd0(&a),
            ImportWhat::Riversurveyor(a) => run_import_riversurveyor(&a),
            ImportWhat::MagCsv(a) => run_import_mag_csv(&a),
            ImportWhat::UgpsG2(a) => run_import_ugps(&a),
            ImportWhat::Tlog(a) => run_import_tlog(&a),
        },
        Command::Bench { what } => match what {
            BenchWhat::Sim {
                hours,
                repeat,
                json,
            } => auvnav_tools::bench::sim(hours, repeat, json),
            BenchWhat::Calibrate {
                seed,
                methods,
                json,
            } => {
                use auvnav_tools::calibrate::Method;
                let methods = if methods.is_empty() {
                    vec![
                        Method::Fast,
                        Method::Seed,
                        Method::Smoother,
                        Method::TwoPoint,
                    ]
                } else {
                    methods
                };
                auvnav_tools::bench::calibrate(seed, &methods, json)
            }
            BenchWhat::Discover {
                hidden,
                null,
                pairs,
                floor,
                coloured,
                coloured_voyages,
                surface,
                seed_offset,
                data,
                json,
            } => auvnav_tools::bench::discover(&auvnav_tools::bench::DiscoverBench {
                hidden,
                null,
                pairs,
                floor: floor as usize,
                coloured,
                coloured_voyages,
                surface,
                seed_offset,
                data,
                json,
            }),
            BenchWhat::Mag {
                samples,
                repeat,
                recording,
                fit_fraction,
                json,
            } => auvnav_tools::bench::mag(samples, repeat, &recording, &fit_fraction, json),
            BenchWhat::Align { runs, json } => auvnav_tools::bench::align(runs, json),
            BenchWhat::Usbl { seconds, json } => auvnav_tools::bench::usbl(seconds, json),
            BenchWhat::E2e {
                seconds,
                outputs,
                scheduling,
                json,
            } => auvnav_tools::bench::e2e_bench(seconds, outputs, scheduling, json),
            BenchWhat::Bridge { seconds, json } => auvnav_tools::bench::bridge_bench(seconds, json),
            BenchWhat::Decode {
                repeat,
                pty_seconds,
                json,
            } => auvnav_tools::bench::decode(repeat, pty_seconds, json),
            BenchWhat::Accuracy {
                scenario,
                seeds,
                json,
            } => auvnav_tools::bench::accuracy(&scenario, seeds, json),
            BenchWhat::Replay {
                hours,
                repeat,
                json,
            } => auvnav_tools::bench::replay(hours, repeat, json),
            BenchWhat::Guard(args) => auvnav_tools::bench::guard(&args),
            BenchWhat::Smooth {
                hours,
                repeat,
                long_hours,
                memory_budget_mib,
                solution_rate,
                json,
            } => auvnav_tools::bench::smooth(
                hours,
                repeat,
                long_hours,
                memory_budget_mib,
                solution_rate,
                json,
            ),
        },
    };
    match result {
        Ok(()) => std::process::ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e:#}");
            std::process::ExitCode::from(auvnav_tools::exit_status(&e))
        }
    }
}

/// The command lines of every auvnav program, for completions and manual pages.
fn programs() -> Vec<clap::Command> {
    use auvnav_drivers::device::DeviceClass;
    use auvnav_drivers::serial_driver::serial_driver_command;
    use clap::CommandFactory;
    vec![
        Cli::command(),
        auvnavd::Args::command(),
        serial_driver_command(DeviceClass::Dvl),
        serial_driver_command(DeviceClass::Imu),
        serial_driver_command(DeviceClass::Usbl),
        serial_driver_command(DeviceClass::Gnss),
        auvnav_drivers::can_driver::CanDriverArgs::command(),
    ]
}

fn completions(shell: clap_complete::Shell, out: Option<&std::path::Path>) -> anyhow::Result<()> {
    use clap::CommandFactory;
    let Some(dir) = out else {
        clap_complete::generate(shell, &mut Cli::command(), "auvnav", &mut std::io::stdout());
        return Ok(());
    };
    std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    for mut cmd in programs() {
        let name = cmd.get_name().to_string();
        let path = clap_complete::generate_to(shell, &mut cmd, &name, dir)
            .with_context(|| format!("writing the {shell} completions of {name}"))?;
        println!("{}", path.display());
    }
    Ok(())
}

fn man_pages(dir: &std::path::Path) -> anyhow::Result<()> {
    std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    for cmd in programs() {
        let name = cmd.get_name().to_string();
        clap_mangen::generate_to(cmd, dir).with_context(|| {
            format!("writing the manual pages of {name} into {}", dir.display())
        })?;
    }
    let mut pages: Vec<_> = std::fs::read_dir(dir)?
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.extension().is_some_and(|x| x == "1"))
        .collect();
    pages.sort();
    for p in pages {
        println!("{}", p.display());
    }
    Ok(())
}
