//! `auvnav demo` with real processes: simulates a voyage, then runs the on-board chain on it —
//! device emulators on pseudo-terminals, the serial drivers, the CAN driver fed from a candump
//! log, the fusion daemon and the recorder, each its own process talking through shared memory —
//! stops them cleanly and reports the live navigation against the simulated truth, phase by phase
//! ([`crate::phases`]). It then replays the recording through `auvnav replay` and says whether the
//! replayed solution is byte-identical to the live one.
//!
//! Long on purpose: the last 47 lines are the unit tests, beside the code they test; the code is
//! 572 lines.

use crate::accuracy::{Accuracy, AccuracyTracker};
use crate::demo_start::{DemoStart, session_config};
use crate::phases::{PhaseFigures, PhaseRecorder};
use crate::process::{ChildProcess, Scheduling, scheduled_command, sibling};
use crate::replay::interpolate;
use anyhow::{Context, bail};
use auvnav_drivers::can::DbcDecoder;
use auvnav_drivers::can_driver::SAMPLE_DBC;
use auvnav_drivers::device::Protocol;
use auvnav_log::{LogMessage, LogReader};
use auvnav_shm_schema::{NavSolutionV1, TruthStateV1};
use auvnav_sim::{self as sim, SimConfig, scenario::Scenario};
use serde::Serialize;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

/// The line rate of the demo's emulated devices and drivers (bit/s).
const DEMO_BAUD: u32 = 921_600;

/// What the live demo reports.
#[derive(Debug, Serialize)]
pub struct LiveResult {
    pub scenario: String,
    pub seed: u64,
    pub start: DemoStart,
    pub simulated_s: f64,
    pub speed: f64,
    /// The emulated IMU's protocol (`xsens` also sends the magnetic field).
    pub imu: String,
    /// The emulated GNSS receiver's protocol (`--gnss`), when one ran.
    pub gnss: Option<String>,
    /// The coordinate system of the emulated PD0 DVL's bottom track.
    pub pd0_coordinates: String,
    /// GNSS fixes the simulator made (at the surface) and fixes the recording holds (published
    /// by `auvnav-gnss` while the depth on the bus said the vehicle was at the surface).
    pub gnss_fixes_simulated: u64,
    pub gnss_fixes_recorded: u64,
    pub directory: String,
    pub record: String,
    pub live_nav_csv: String,
    /// The live view's address (`--live-view`), when it ran.
    pub live_view: Option<String>,
    pub solutions: u64,
    pub accuracy: Accuracy,
    /// The live run phase by phase: alignment, navigation before the USBL fixes, USBL homing.
    pub phases: PhaseFigures,
    /// Every IMU sample of the voyage reached the recording (the host-to-simulator time map is
    /// exact; otherwise samples after a lost one are mapped one interval early).
    pub imu_samples_complete: bool,
    /// The recorded IMU samples' and USBL fixes' time stamps against when the emulator sent them
    /// (its lines paced at the drivers' 921 600 baud); a kind is left out when a frame was lost.
    pub stamp_errors: Vec<crate::emulate_line::StampErrors>,
    /// How the processes were scheduled (`--scheduling`), and whether SCHED_FIFO was permitted.
    pub scheduling: String,
    /// With `--restart-daemon-at`: when (simulated s) the daemon was killed (SIGKILL) and
    /// started again, to continue from its checkpoint; the replay is then checked against every
    /// solution the recording holds, before and after the restart.
    pub daemon_restarted_at_s: Option<f64>,
    /// `auvnav replay DIR/record.mcap --out DIR/replay_nav.csv` gave a byte-identical file.
    pub replay_identical: bool,
    /// Every process stopped cleanly (exit status 0 after SIGTERM).
    pub clean_stop: bool,
    pub wall_s: f64,
    /// Per-process last lines of standard error (their summaries).
    pub process_reports: Vec<(String, String)>,
}

/// Parses the solution CSV written by the daemon or the replay (`auvnav_core::csv::NAV_HEADER`).
pub fn read_nav_csv(path: &Path) -> anyhow::Result<Vec<NavSolutionV1>> {
    type Row = (
        u64,
        u64,
        f64,
        f64,
        f64,
        f64,
        f64,
        f64,
        f64,
        f64,
        f64,
        f64,
        f64,
        f64,
        u32,
        u32,
    );
    let mut reader =
        csv::Reader::from_path(path).with_context(|| format!("reading {}", path.display()))?;
    let header = reader
        .headers()
        .with_context(|| format!("reading the header of {}", path.display()))?
        .iter()
        .collect::<Vec<_>>()
        .join(",");
    if header != auvnav_core::csv::NAV_HEADER {
        bail!(
            "{}: not a solution CSV (header {header:?}, expected {:?})",
            path.display(),
            auvnav_core::csv::NAV_HEADER
        );
    }
    let mut out = Vec::new();
    for row in reader.deserialize::<Row>() {
        let (t, seq, lat, lon, h, vn, ve, vd, r, p, y, sn, se, sd, mode, health) =
            row.with_context(|| format!("reading {}", path.display()))?;
        out.push(NavSolutionV1 {
            host_time_ns: t,
            sequence: seq,
            latitude_rad: lat,
            longitude_rad: lon,
            height_m: h,
            velocity_ned_m_s: [vn, ve, vd],
            euler_rad: [r, p, y],
            position_std_ned_m: [sn, se, sd],
            mode,
            sensor_health: health,
            ..Default::default()
        });
    }
    Ok(out)
}

/// Maps the daemon's host times onto the simulator's: the k-th IMU sample in the recording is the
/// voyage's k-th, and every solution is stamped with the host time of the IMU sample it
/// integrated, so solutions map exactly; other times (aid diagnostics) are interpolated between
/// the samples around them.
pub struct HostToSim {
    host_ns: Vec<u64>,
    sim_ns: Vec<u64>,
}

impl HostToSim {
    /// From the voyage's IMU times and the recorded ones, in order (the shorter length is used).
    pub fn new(sim_ns: Vec<u64>, host_ns: Vec<u64>) -> HostToSim {
        let n = sim_ns.len().min(host_ns.len());
        HostToSim {
            host_ns: host_ns[..n].to_vec(),
            sim_ns: sim_ns[..n].to_vec(),
        }
    }

    /// The simulator's time of host time `h` (ns); none outside the recorded IMU samples.
    pub fn sim_ns(&self, h: u64) -> Option<u64> {
        let k = self.host_ns.partition_point(|&x| x < h);
        let b = *self.host_ns.get(k)?;
        if b == h {
            return Some(self.sim_ns[k]);
        }
        let a = *self.host_ns.get(k.checked_sub(1)?)?;
        let w = (h - a) as f64 / (b - a) as f64;
        let (sa, sb) = (self.sim_ns[k - 1], self.sim_ns[k]);
        Some(sa + (w * (sb - sa) as f64) as u64)
    }
}

/// Compares solutions with the simulated truth on the simulator's time axis: each solution's
/// time is mapped by `map` first.
pub fn live_accuracy(nav: &[NavSolutionV1], truth: &[TruthStateV1], map: &HostToSim) -> Accuracy {
    let mut tracker = AccuracyTracker::new(100.0);
    let nav: Vec<NavSolutionV1> = nav
        .iter()
        .filter_map(|s| {
            map.sim_ns(s.host_time_ns).map(|t| NavSolutionV1 {
                host_time_ns: t,
                ..*s
            })
        })
        .collect();
    let mut k = 0;
    for t in truth {
        while k + 1 < nav.len() && nav[k + 1].host_time_ns < t.host_time_ns {
            k += 1;
        }
        if k + 1 >= nav.len() {
            break;
        }
        if nav[k].host_time_ns > t.host_time_ns {
            continue;
        }
        let sol = interpolate(&nav[k], &nav[k + 1], t.host_time_ns);
        tracker.add(&sol, t);
    }
    tracker.result()
}

/// What the recording holds for the phase figures and the summary.
struct Recording {
    /// The recorded IMU times and USBL fix times.
    imu_ns: Vec<u64>,
    usbl_ns: Vec<u64>,
    /// The daemon's solutions and aid diagnostics.
    nav: Vec<NavSolutionV1>,
    diagnostics: Vec<auvnav_shm_schema::AidDiagnosticsV1>,
    gnss_fixes: u64,
}

fn read_recording(record: &Path) -> anyhow::Result<Recording> {
    let mut r = Recording {
        imu_ns: Vec::new(),
        usbl_ns: Vec::new(),
        nav: Vec::new(),
        diagnostics: Vec::new(),
        gnss_fixes: 0,
    };
    let mut reader = LogReader::open(record)?;
    while let Some(raw) = reader.next_message()? {
        match raw.decode_any()? {
            LogMessage::Imu(x) => r.imu_ns.push(x.host_time_ns),
            LogMessage::Usbl(x) => r.usbl_ns.push(x.host_time_ns),
            LogMessage::NavSolution(s) => r.nav.push(s),
            LogMessage::AidDiagnostics(d) => r.diagnostics.push(d),
            LogMessage::Gnss(_) => r.gnss_fixes += 1,
            _ => {}
        }
    }
    Ok(r)
}

fn write_candump(path: &Path, depths: &[auvnav_shm_schema::DepthV1]) -> anyhow::Result<()> {
    let dbc = DbcDecoder::from_dbc(SAMPLE_DBC)?;
    let mut text = String::new();
    for (i, d) in depths.iter().enumerate() {
        let bar = (101_325.0 + 1025.0 * 9.806_65 * d.depth_m) / 1e5;
        let f = dbc
            .encode(
                "PressureSensor",
                &[
                    ("Pressure", bar),
                    ("Temperature", 10.0),
                    ("Counter", (i % 256) as f64),
                ],
            )
            .context("encoding a pressure frame")?;
        let hex: String = f.data.iter().map(|b| format!("{b:02X}")).collect();
        let t = d.host_time_ns as f64 * 1e-9;
        writeln!(text, "({t:.6}) can0 {:03X}#{hex}", f.id)?;
    }
    std::fs::write(path, text)?;
    Ok(())
}

/// Runs the live demo.
#[allow(clippy::too_many_arguments)]
// Long on purpose: the live demo: processes started in order, phases followed as they happen,
// checks at each phase and teardown; the processes it owns are its locals.
pub fn run_live(
    scenario_name: &str,
    start_mode: DemoStart,
    imu: Protocol,
    gnss: Option<Protocol>,
    pd0_coordinates: crate::emulate_ptys::Pd0Coordinates,
    seed: u64,
    seconds: Option<f64>,
    speed: f64,
    out: Option<&Path>,
    live_view: Option<std::net::SocketAddr>,
    scheduling: Scheduling,
    restart_daemon_at_s: Option<f64>,
) -> anyhow::Result<LiveResult> {
    if !(speed.is_finite() && (0.1..=20.0).contains(&speed)) {
        bail!("--speed {speed}: expected 0.1..=20");
    }
    if let Some(s) = seconds
        && !(s.is_finite() && s > 1.0)
    {
        bail!("--seconds {s}: expected more than 1 s");
    }
    let binaries = [
        "auvnavd",
        "auvnav-dvl",
        "auvnav-imu",
        "auvnav-usbl",
        "auvnav-can",
    ]
    .iter()
    .map(|b| sibling(b).context("or run `auvnav demo --in-process`"))
    .collect::<anyhow::Result<Vec<_>>>()?;
    let [daemon, dvl_bin, imu_bin, usbl_bin, can_bin] = &binaries[..] else {
        bail!("binaries");
    };
    let gnss_bin = match gnss {
        Some(_) => Some(sibling("auvnav-gnss").context("or run `auvnav demo --in-process`")?),
        None => None,
    };
    let me = std::env::current_exe()?;
    // The units' priorities, where SCHED_FIFO is permitted.
    let (fifo, scheduled) = match scheduling {
        Scheduling::Normal => (false, "normal".to_string()),
        Scheduling::Unit => match crate::process::realtime_permitted() {
            Ok(()) => (
                true,
                "as the units: drivers SCHED_FIFO 60, daemon 50, emulator 70".to_string(),
            ),
            Err(why) => (false, format!("normal (SCHED_FIFO not permitted: {why})")),
        },
    };
    let priority = |p: u8| fifo.then_some(p);
    let start = Instant::now();
    let dir = match out {
        Some(d) => d.to_path_buf(),
        None => std::env::temp_dir().join(format!("auvnav-demo-{}", std::process::id())),
    };
    std::fs::create_dir_all(&dir).with_context(|| format!("creating {}", dir.display()))?;
    let prefix = format!("demo{}", std::process::id());

    // 1. The voyage.
    let scenario = Scenario::load(scenario_name)?;
    let effects = scenario.effects()?;
    let rates = scenario.rates.clone();
    let cfg = SimConfig {
        scenario,
        effects,
        seed,
        duration_s: seconds,
    };
    let voyage = dir.join("voyage.mcap");
    let simulated = sim::simulate_to_log(&cfg, &voyage)?;
    let seconds = simulated.duration_s;
    if let Some(at) = restart_daemon_at_s
        && !(at.is_finite() && at > 0.0 && at < seconds)
    {
        bail!("--restart-daemon-at {at}: expected a time within the run's {seconds:.0} s");
    }
    let mut truth = Vec::new();
    let mut depths = Vec::new();
    let mut imu_sim_ns = Vec::new();
    let mut reader = LogReader::open(&voyage)?;
    while let Some(raw) = reader.next_message()? {
        match raw.decode_any()? {
            LogMessage::Truth(t) => truth.push(t),
            LogMessage::Depth(d) => depths.push(d),
            LogMessage::Imu(i) => imu_sim_ns.push(i.host_time_ns),
            _ => {}
        }
    }
    let t0 = truth.first().context("the simulation wrote no truth")?;
    write_candump(&dir.join("depth.candump"), &depths)?;

    // 2. Configurations: the demo's session (USBL station, magnetometer when the IMU carries
    // the field, the start), with the IMU's device clock for the intervals.
    let mut session = session_config(&cfg, start_mode, imu.carries_magnetic_field(), t0);
    session.navigation.imu_dt_from_device_time = true;
    let daemon_config = auvnav_core::config::DaemonConfig {
        prefix: prefix.to_string(),
        aid_delay_s: 0.02,
        health_period_s: 0.5,
        navigation: session.navigation,
        initial: session.initial,
        alignment: session.alignment,
        output: auvnav_core::config::OutputConfig {
            nav_csv: dir.join("live_nav.csv").display().to_string(),
            ..Default::default()
        },
        // As deployed: a checkpoint every 2 s, which a restarted daemon continues from.
        checkpoint: auvnav_core::config::CheckpointConfig {
            path: dir.join("auvnavd.checkpoint.json").display().to_string(),
            ..Default::default()
        },
        ..Default::default()
    };
    // A checkpoint of an earlier run in the same folder is not this run's.
    let _ = std::fs::remove_file(dir.join("auvnavd.checkpoint.json"));
    daemon_config.validate()?;
    let daemon_cfg = dir.join("auvnavd.toml");
    std::fs::write(&daemon_cfg, daemon_config.to_toml()?)?;
    let dev = dir.join("dev");
    let driver_cfg = |class: &str, protocol: &str, extra: &str| -> anyhow::Result<PathBuf> {
        let p = dir.join(format!("{class}.toml"));
        std::fs::write(
            &p,
            format!(
                "prefix = \"{prefix}\"\nprotocol = \"{protocol}\"\n[serial]\nport = \"{}\"\nbaud = {DEMO_BAUD}\n{extra}\
                 [timing]\nreconnect_initial_s = 0.02\nreconnect_max_s = 0.5\nhealth_period_s = 0.5\n",
                dev.join(class).display()
            ),
        )?;
        Ok(p)
    };
    let dvl_cfg = driver_cfg("dvl", "pd0", "")?;
    let imu_settings = match imu {
        Protocol::Xsens => format!("[settings]\nxsens_rate_hz = {}\n", rates.imu_hz),
        _ => format!(
            "[settings.kvh]\nincrements = false\ndegrees = false\nrate_hz = {}\ntemperature_centi = false\n",
            rates.imu_hz
        ),
    };
    let imu_cfg = driver_cfg("imu", imu.name(), &imu_settings)?;
    // An LBL survey: the SeaTrac ranges the scenario's beacons, IDs 1, 2, … as receivers 0, 1, ….
    let lbl_beacons: Vec<String> = match &cfg.scenario.acoustic {
        Some(a) if a.kind == sim::scenario::AcousticKind::Lbl => (1..=a.beacons_m.len().min(4))
            .map(|k| k.to_string())
            .collect(),
        _ => Vec::new(),
    };
    let usbl_cfg = driver_cfg(
        "usbl",
        "seatrac",
        &if lbl_beacons.is_empty() {
            String::new()
        } else {
            format!(
                "[settings.seatrac]\nrange_beacons = [{}]\n",
                lbl_beacons.join(", ")
            )
        },
    )?;
    // A vehicle's receiver: fixes only while the depth on the bus says it is at the surface.
    let gnss_cfg = match gnss {
        Some(p) => Some(driver_cfg(
            "gnss",
            p.name(),
            "[settings.gnss]\nsurface_only = true\nsurface_depth_m = 0.5\n",
        )?),
        None => None,
    };
    let can_cfg = dir.join("can.toml");
    std::fs::write(
        &can_cfg,
        format!("prefix = \"{prefix}\"\nhealth_period_s = 0.5\n"),
    )?;

    // 3. Processes: recorder and daemon first, so they see every message; then the drivers.
    let record = dir.join("record.mcap");
    let mut recorder = ChildProcess::spawn_logged(
        "record",
        &dir,
        Command::new(&me)
            .arg("record")
            // The demo's folder is its own: a second run with the same --out replaces it.
            .arg("--force")
            .arg("--out")
            .arg(&record)
            .args(["--prefix", &prefix])
            .arg("--embed-config")
            .arg(&daemon_cfg),
    )?;
    let mut daemon_p = ChildProcess::spawn_logged(
        "auvnavd",
        &dir,
        scheduled_command(daemon, priority(50))
            .arg("--config")
            .arg(&daemon_cfg),
    )?;
    let mut live_p = match live_view {
        Some(addr) => {
            let cfg = dir.join("live.toml");
            std::fs::write(
                &cfg,
                format!(
                    "prefix = \"{prefix}\"\nlisten_address = \"{}\"\nport = {}\nhealth_period_s = 0.5\n",
                    addr.ip(),
                    addr.port()
                ),
            )?;
            Some(ChildProcess::spawn_logged(
                "auvnav-live",
                &dir,
                Command::new(sibling("auvnav-live")?)
                    .arg("--config")
                    .arg(&cfg),
            )?)
        }
        None => None,
    };
    let mut drivers = vec![
        ChildProcess::spawn_logged(
            "auvnav-dvl",
            &dir,
            scheduled_command(dvl_bin, priority(60))
                .arg("--config")
                .arg(&dvl_cfg),
        )?,
        ChildProcess::spawn_logged(
            "auvnav-imu",
            &dir,
            scheduled_command(imu_bin, priority(60))
                .arg("--config")
                .arg(&imu_cfg),
        )?,
        ChildProcess::spawn_logged(
            "auvnav-usbl",
            &dir,
            scheduled_command(usbl_bin, priority(60))
                .arg("--config")
                .arg(&usbl_cfg),
        )?,
    ];
    if let (Some(bin), Some(cfg)) = (&gnss_bin, &gnss_cfg) {
        drivers.push(ChildProcess::spawn_logged(
            "auvnav-gnss",
            &dir,
            scheduled_command(bin, priority(60))
                .arg("--config")
                .arg(cfg),
        )?);
    }
    std::thread::sleep(Duration::from_millis(500));
    let start_delay = 1.5;
    let mut emulated = vec![
        "--dvl",
        "pd0",
        "--pd0-coordinates",
        pd0_coordinates.name(),
        "--imu",
        imu.name(),
        "--usbl",
        "seatrac",
    ];
    if let Some(p) = gnss {
        emulated.extend(["--gnss", p.name()]);
    }
    let lbl_list = lbl_beacons.join(",");
    if !lbl_beacons.is_empty() {
        emulated.extend(["--lbl-beacons", lbl_list.as_str()]);
    }
    let mut emulator = ChildProcess::spawn_logged(
        "emulate",
        &dir,
        scheduled_command(&me, priority(70))
            .arg("emulate")
            .arg(&voyage)
            .args(&emulated)
            .args(["--speed", &speed.to_string()])
            .args(["--baud", &DEMO_BAUD.to_string()])
            .arg("--send-times")
            .arg(dir.join("send_times.csv"))
            .arg("--link-dir")
            .arg(&dev)
            .args(["--start-delay", &start_delay.to_string()]),
    )?;
    // The depth sensor's frames start with the other devices' (the emulator's start delay).
    std::thread::sleep(Duration::from_secs_f64(start_delay));
    drivers.push(ChildProcess::spawn_logged(
        "auvnav-can",
        &dir,
        scheduled_command(can_bin, priority(60))
            .arg("--config")
            .arg(&can_cfg)
            .arg("--candump")
            .arg(dir.join("depth.candump"))
            .args(["--speed", &speed.to_string()]),
    )?);
    let play = Duration::from_secs_f64(seconds / speed + 30.0);
    // A crash of the daemon mid-run (SIGKILL) and its restart, as systemd would restart it.
    let mut killed_daemon = None;
    if let Some(at) = restart_daemon_at_s {
        std::thread::sleep(Duration::from_secs_f64(at / speed));
        daemon_p.kill();
        std::thread::sleep(Duration::from_millis(500));
        let restarted = ChildProcess::spawn_logged(
            "auvnavd-restarted",
            &dir,
            scheduled_command(daemon, priority(50))
                .arg("--config")
                .arg(&daemon_cfg),
        )?;
        killed_daemon = Some(std::mem::replace(&mut daemon_p, restarted));
    }
    let mut clean = emulator.wait_clean(play);
    std::thread::sleep(Duration::from_millis(500));
    // 4. Stop: drivers (the CAN replay ends by itself), then the daemon, then the recorder.
    for d in &mut drivers {
        let ok = if d.name == "auvnav-can" {
            d.wait_clean(Duration::from_secs(10))
        } else {
            d.stop(Duration::from_secs(10))
        };
        clean &= ok;
    }
    std::thread::sleep(Duration::from_millis(200));
    clean &= daemon_p.stop(Duration::from_secs(10));
    std::thread::sleep(Duration::from_millis(200));
    clean &= recorder.stop(Duration::from_secs(10));
    if let Some(p) = live_p.as_mut() {
        clean &= p.stop(Duration::from_secs(10));
    }
    let mut process_reports: Vec<(String, String)> = Vec::new();
    for p in drivers
        .iter()
        .chain(killed_daemon.as_ref())
        .chain([&daemon_p, &recorder, &emulator])
        .chain(live_p.as_ref())
    {
        process_reports.push((p.name.clone(), p.last_log_line()));
    }

    // 5. The live solution against the truth, on the simulator's time axis.
    let live_csv = dir.join("live_nav.csv");
    let nav = read_nav_csv(&live_csv)?;
    let Recording {
        imu_ns: recorded_imu,
        usbl_ns: recorded_usbl,
        nav: recorded_nav,
        diagnostics,
        gnss_fixes: gnss_fixes_recorded,
    } = read_recording(&record)?;
    let imu_samples_complete = recorded_imu.len() == imu_sim_ns.len();
    let sent = crate::emulate_line::read_send_times(&dir.join("send_times.csv"))?;
    let stamp_errors = [("imu", &recorded_imu), ("usbl", &recorded_usbl)]
        .into_iter()
        .filter_map(|(kind, stamps)| crate::emulate_line::stamp_errors(&sent, kind, stamps))
        .collect();
    let map = HostToSim::new(imu_sim_ns, recorded_imu);
    let accuracy = live_accuracy(&nav, &truth, &map);
    let s = |ns: u64| ns as f64 * 1e-9;
    let mut phases = PhaseRecorder::new();
    if let Some(&first) = map.sim_ns.first() {
        phases.imu(s(first));
    }
    for sol in &recorded_nav {
        if let Some(t) = map.sim_ns(sol.host_time_ns) {
            phases.solution(s(t), sol);
        }
    }
    for t in &truth {
        phases.truth(s(t.host_time_ns), t);
    }
    for d in &diagnostics {
        if let Some(t) = map.sim_ns(d.host_time_ns) {
            phases.diagnostics(s(t), d);
        }
    }
    let phases = phases.figures(simulated.usbl_outliers);
    let replay_csv = dir.join("replay_nav.csv");
    let mut replay = Command::new(&me);
    replay
        .arg("replay")
        .arg(&record)
        .arg("--out")
        .arg(&replay_csv);
    if restart_daemon_at_s.is_some() {
        // Two daemons wrote the live solution file; the recording holds every solution either
        // published: the replay is checked against those (exit status 3 on the first that
        // differs).
        replay.arg("--compare-recorded");
    }
    let status = replay
        .stdout(Stdio::null())
        .status()
        .context("running auvnav replay")?;
    let replay_identical = status.success()
        && (restart_daemon_at_s.is_some()
            || std::fs::read(&live_csv).ok() == std::fs::read(&replay_csv).ok());
    Ok(LiveResult {
        scenario: cfg.scenario.name.clone(),
        seed,
        start: start_mode,
        simulated_s: seconds,
        speed,
        imu: imu.name().to_string(),
        gnss: gnss.map(|p| p.name().to_string()),
        pd0_coordinates: pd0_coordinates.name().to_string(),
        gnss_fixes_simulated: simulated.gnss,
        gnss_fixes_recorded,
        directory: dir.display().to_string(),
        record: record.display().to_string(),
        live_nav_csv: live_csv.display().to_string(),
        live_view: live_view.map(|a| a.to_string()),
        solutions: nav.len() as u64,
        accuracy,
        phases,
        imu_samples_complete,
        stamp_errors,
        scheduling: scheduled,
        daemon_restarted_at_s: restart_daemon_at_s,
        replay_identical,
        clean_stop: clean,
        wall_s: start.elapsed().as_secs_f64(),
        process_reports,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_solution_csv_reads_back_what_was_written_and_a_foreign_file_is_refused() {
        let dir = std::env::temp_dir().join(format!("nav-csv-{}", std::process::id()));
        std::fs::create_dir_all(&dir).expect("directory");
        let path = dir.join("nav.csv");
        let s = NavSolutionV1 {
            host_time_ns: 123_456_789,
            sequence: 7,
            latitude_rad: 0.5,
            longitude_rad: -2.0,
            height_m: -30.25,
            velocity_ned_m_s: [1.0, -0.5, 0.125],
            euler_rad: [0.01, -0.02, 3.0],
            position_std_ned_m: [0.1, 0.2, 0.3],
            mode: 2,
            sensor_health: 11,
            ..Default::default()
        };
        let mut text = Vec::new();
        use std::io::Write;
        writeln!(text, "{}", auvnav_core::csv::NAV_HEADER).expect("header");
        auvnav_core::csv::write_nav_row(&mut text, &s).expect("row");
        std::fs::write(&path, &text).expect("write");
        let back = read_nav_csv(&path).expect("read");
        assert_eq!(back.len(), 1);
        let b = &back[0];
        assert_eq!(
            (b.host_time_ns, b.sequence, b.mode, b.sensor_health),
            (123_456_789, 7, 2, 11)
        );
        assert_eq!(b.velocity_ned_m_s, s.velocity_ned_m_s);
        assert!((b.latitude_rad - s.latitude_rad).abs() < 1e-12);
        std::fs::write(&path, "a,b\n1,2\n").expect("write");
        let e = read_nav_csv(&path).expect_err("refused");
        assert!(e.to_string().contains("not a solution CSV"), "{e}");
        let mut short = text.clone();
        short.extend_from_slice(b"1,2,3\n");
        std::fs::write(&path, &short).expect("write");
        assert!(read_nav_csv(&path).is_err());
        std::fs::remove_dir_all(&dir).expect("cleanup");
    }
}
