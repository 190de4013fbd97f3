//! `auvnavd`: the fusion daemon. Subscribes to the sensor topics in shared memory, runs the
//! navigation session in real time, publishes the solution, per-aid diagnostics and its health.
//!
//! Processing order (what makes a recording replay bit for bit): IMU samples are processed as
//! they arrive; an aid message stamped t is applied just before the first IMU sample stamped later
//! than t + `aid_delay_s` (see `auvnav_core::session`). An aid message that arrives after that IMU
//! sample was processed is late: counted and applied at the next one.

use auvnav_core::config::DaemonConfig;
use auvnav_core::csv;
use auvnav_core::feed::SensorMessage;
use auvnav_core::session::{Session, SessionOutput};
use auvnav_shm_schema::bus::{Bus, BusError, BusPublisher, BusSubscriber};
use auvnav_shm_schema::clock::monotonic_ns;
use auvnav_shm_schema::stage_times::StageTimes;
use auvnav_shm_schema::{
    AidDiagnosticsV1, DepthV1, DvlVelocityV1, GnssFixV1, ImuSampleV1, LateAidV1, MagnetometerV1,
    NavSolutionV1, ProcessHealthV1, ProcessState, SoundVelocityV1, UsblFixV1, qos, topic,
};
use iceoryx2::prelude::*;
use iceoryx2::waitset::WaitSetRunResult;
use std::io::Write;
use std::process::ExitCode;
use std::time::Duration;

use auvnavd::{Args, checkpoint};

/// A watched sensor: last arrival and whether it is reported lost.
struct Watch {
    name: &'static str,
    deadline_ns: u64,
    last_ns: u64,
    lost: bool,
}

impl Watch {
    fn new(name: &'static str, deadline_s: f64, now: u64) -> Watch {
        Watch {
            name,
            deadline_ns: (deadline_s * 1e9) as u64,
            last_ns: now,
            lost: false,
        }
    }
    fn seen(&mut self, now: u64) {
        if self.lost {
            tracing::info!(sensor = self.name, "auvnavd: {} back", self.name);
            self.lost = false;
        }
        self.last_ns = now;
    }
    /// True when the sensor just became lost.
    fn check(&mut self, now: u64) -> bool {
        if self.deadline_ns > 0 && !self.lost && now.saturating_sub(self.last_ns) > self.deadline_ns
        {
            self.lost = true;
            tracing::warn!(
                sensor = self.name,
                "auvnavd: {} lost (nothing for {:.2} s)",
                self.name,
                self.deadline_ns as f64 * 1e-9
            );
            return true;
        }
        false
    }
}

struct Csv {
    w: std::io::BufWriter<std::fs::File>,
}

impl Csv {
    fn create(path: &str, header: &str) -> Result<Option<Csv>, String> {
        if path.is_empty() {
            return Ok(None);
        }
        let f = std::fs::File::create(path).map_err(|e| format!("creating {path}: {e}"))?;
        let mut w = std::io::BufWriter::new(f);
        writeln!(w, "{header}").map_err(|e| format!("writing {path}: {e}"))?;
        Ok(Some(Csv { w }))
    }
}

struct Outputs {
    solution: BusPublisher<NavSolutionV1>,
    diagnostics: BusPublisher<AidDiagnosticsV1>,
    late_aids: BusPublisher<LateAidV1>,
    late_aids_applied: u64,
    nav_csv: Option<Csv>,
    diag_csv: Option<Csv>,
    stage_times: Option<StageTimes>,
    /// Host times of this wake-up and of the sensor topics drained (for the stage times).
    woke_ns: u64,
    received_ns: u64,
    decimation: u64,
    solutions: u64,
    published: u64,
    errors: u64,
}

impl Outputs {
    fn on(&mut self, o: SessionOutput) -> Result<(), std::io::Error> {
        match o {
            SessionOutput::Solution(s) => {
                if let Some(c) = self.nav_csv.as_mut() {
                    csv::write_nav_row(&mut c.w, s)?;
                }
                if self.solutions.is_multiple_of(self.decimation) {
                    let computed_ns = self.stage_times.as_ref().map(|_| monotonic_ns());
                    match self.solution.publish(*s) {
                        Ok(_) => self.published += 1,
                        Err(_) => self.errors += 1,
                    }
                    if let (Some(t), Some(computed_ns)) = (self.stage_times.as_mut(), computed_ns) {
                        t.row(&[
                            s.host_time_ns,
                            self.woke_ns,
                            self.received_ns,
                            computed_ns,
                            monotonic_ns(),
                        ]);
                    }
                }
                self.solutions += 1;
            }
            SessionOutput::Diagnostics(d) => {
                if let Some(c) = self.diag_csv.as_mut() {
                    csv::write_diagnostics_row(&mut c.w, d)?;
                }
                if self.diagnostics.publish(*d).is_err() {
                    self.errors += 1;
                }
            }
            SessionOutput::LateAid(r) => {
                self.late_aids_applied += 1;
                if self.late_aids_applied <= 10 {
                    tracing::warn!(
                        aid_topic = r.aid_topic,
                        aid_sequence = r.aid_sequence,
                        aid_host_time_ns = r.aid_host_time_ns,
                        imu_sequence = r.imu_sequence,
                        "auvnavd: an aid message came after the IMU had passed its time + aid delay; \
                         applied before the next IMU sample and recorded on {} (further ones are \
                         counted, not logged)",
                        topic::NAV_LATE_AIDS
                    );
                }
                // Recorded, so that a replay applies the aid where this daemon did.
                if self.late_aids.publish(*r).is_err() {
                    self.errors += 1;
                }
            }
        }
        Ok(())
    }

    fn flush(&mut self) -> std::io::Result<()> {
        if let Some(c) = self.nav_csv.as_mut() {
            c.w.flush()?;
        }
        if let Some(c) = self.diag_csv.as_mut() {
            c.w.flush()?;
        }
        if let Some(t) = self.stage_times.as_mut() {
            t.flush();
        }
        Ok(())
    }
}

fn drain<T: auvnav_shm_schema::Message + auvnav_shm_schema::bus::Sequenced>(
    sub: &mut BusSubscriber<T>,
    into: &mut Vec<T>,
) -> Result<(), BusError> {
    while let Some(m) = sub.receive()? {
        into.push(m);
    }
    Ok(())
}

fn run(cfg: &DaemonConfig) -> Result<(), String> {
    let e = |x: BusError| x.to_string();
    let bus = Bus::new(&cfg.name, &cfg.prefix).map_err(e)?;
    // Resources left by a killed predecessor (or killed drivers) are removed before opening.
    bus.cleanup_dead_nodes();
    let mut imu = bus
        .subscriber::<ImuSampleV1>(topic::IMU, qos::SENSOR)
        .map_err(e)?;
    let mut dvl = bus
        .subscriber::<DvlVelocityV1>(topic::DVL, qos::SENSOR)
        .map_err(e)?;
    let mut depth = bus
        .subscriber::<DepthV1>(topic::DEPTH, qos::SENSOR)
        .map_err(e)?;
    let mut gnss = bus
        .subscriber::<GnssFixV1>(topic::GNSS, qos::SENSOR)
        .map_err(e)?;
    let mut usbl = bus
        .subscriber::<UsblFixV1>(topic::USBL, qos::SENSOR)
        .map_err(e)?;
    let mut magnetometer = bus
        .subscriber::<MagnetometerV1>(topic::MAGNETOMETER, qos::SENSOR)
        .map_err(e)?;
    let mut sound_velocity = bus
        .subscriber::<SoundVelocityV1>(topic::SOUND_VELOCITY, qos::SENSOR)
        .map_err(e)?;
    const TOPICS: [&str; 7] = [
        topic::IMU,
        topic::DVL,
        topic::DEPTH,
        topic::GNSS,
        topic::USBL,
        topic::MAGNETOMETER,
        topic::SOUND_VELOCITY,
    ];
    let listeners = TOPICS
        .iter()
        .map(|t| bus.listener(t))
        .collect::<Result<Vec<_>, _>>()
        .map_err(e)?;
    let mut out = Outputs {
        solution: bus
            .publisher::<NavSolutionV1>(topic::NAV_SOLUTION, qos::NAVIGATION)
            .map_err(e)?,
        diagnostics: bus
            .publisher::<AidDiagnosticsV1>(topic::NAV_AID_DIAGNOSTICS, qos::NAVIGATION)
            .map_err(e)?,
        late_aids: bus
            .publisher::<LateAidV1>(topic::NAV_LATE_AIDS, qos::NAVIGATION)
            .map_err(e)?,
        late_aids_applied: 0,
        nav_csv: Csv::create(&cfg.output.nav_csv, csv::NAV_HEADER)?,
        diag_csv: Csv::create(&cfg.output.diagnostics_csv, csv::DIAGNOSTICS_HEADER)?,
        stage_times: StageTimes::create(
            &cfg.output.stage_times_csv,
            "imu_host_time_ns,woke_ns,received_ns,computed_ns,published_ns",
        )
        .map_err(|x| format!("creating {}: {x}", cfg.output.stage_times_csv))?,
        woke_ns: 0,
        received_ns: 0,
        decimation: u64::from(cfg.output.solution_decimation.max(1)),
        solutions: 0,
        published: 0,
        errors: 0,
    };
    let mut health_pub = bus
        .publisher::<ProcessHealthV1>(topic::HEALTH, qos::HEALTH)
        .map_err(e)?;
    let waitset = WaitSetBuilder::new()
        .create::<ipc::Service>()
        .map_err(|x| format!("creating the WaitSet: {x:?}"))?;
    let guards = listeners
        .iter()
        .map(|l| waitset.attach_notification(l))
        .collect::<Result<Vec<_>, _>>()
        .map_err(|x| format!("attaching a listener: {x:?}"))?;
    let _tick = waitset
        .attach_interval(Duration::from_millis(50))
        .map_err(|x| format!("attaching the tick: {x:?}"))?;
    let mut session_cfg = cfg.session();
    let resume = checkpoint::load(cfg);
    if let checkpoint::Start::PositionUnknown(why) = &resume {
        tracing::warn!(
            "auvnavd: {why}: starting from the configured start with the position unknown \
             (standard deviation {} m)",
            cfg.checkpoint.unknown_position_std_m
        );
        session_cfg.navigation.initial_position_std_m = cfg.checkpoint.unknown_position_std_m;
    }
    let mut session = Session::new(&session_cfg);
    if let checkpoint::Start::Resume(cp, elapsed_s) = resume {
        tracing::warn!(
            elapsed_s,
            "auvnavd: continuing from the checkpoint {} written {:.1} s ago (covariance grown by \
             a drift of {} m/s over that time)",
            cfg.checkpoint.path,
            elapsed_s,
            cfg.checkpoint.drift_m_s
        );
        session.resume_from(*cp, elapsed_s, cfg.checkpoint.drift_m_s);
    }
    let mut checkpoints = checkpoint::Writer::start(cfg);
    let checkpoint_ns = (cfg.checkpoint.interval_s * 1e9) as u64;
    let mut next_checkpoint = 0u64;
    let mut reported_reinitialisations = 0u64;
    // The moment in-motion alignment ends is reported once (operators wait for it).
    let mut was_aligning = session.aligning();
    let now = monotonic_ns();
    let d = &cfg.deadlines;
    let mut watches = [
        Watch::new("imu", d.imu_s, now),
        Watch::new("dvl", d.dvl_s, now),
        Watch::new("depth", d.depth_s, now),
        Watch::new("usbl", d.usbl_s, now),
        Watch::new("gnss", d.gnss_s, now),
    ];
    let mut missed_deadlines = 0u64;
    let health_ns = (cfg.health_period_s * 1e9) as u64;
    let mut next_health = 0u64;
    let mut next_flush = now + 1_000_000_000;
    let (mut imus, mut dvls, mut depths, mut gnsss, mut usbls, mut mags) = (
        Vec::new(),
        Vec::new(),
        Vec::new(),
        Vec::new(),
        Vec::new(),
        Vec::new(),
    );
    let mut svs = Vec::new();
    let mut state = ProcessState::Starting;
    tracing::info!(
        "auvnavd: running under {}/ (aid delay {} s, solution every {} IMU samples)",
        cfg.prefix,
        cfg.aid_delay_s,
        cfg.output.solution_decimation
    );
    let publish_health = |hp: &mut BusPublisher<ProcessHealthV1>,
                          out: &Outputs,
                          session: &Session,
                          gaps: u64,
                          missed: u64,
                          state: ProcessState| {
        let mut m = ProcessHealthV1 {
            host_time_ns: monotonic_ns(),
            frames: out.published,
            // Sensors that missed their deadline, and IMU gaps bridged.
            timeouts: missed + session.navigator().map_or(0, |n| n.counters().imu_gaps),
            drops: gaps + session.late_aids + out.errors,
            // Messages before the start, sensor messages the navigator found malformed or out of
            // range, and IMU samples whose device clock jumped or stalled.
            invalid: session.before_start
                + session.navigator().map_or(0, |n| {
                    let c = n.counters();
                    c.imu_invalid
                        + c.imu_clock_jumps
                        + c.dvl_invalid
                        + c.depth_invalid
                        + c.gnss_invalid
                        + c.usbl_invalid
                        + c.magnetometer_invalid
                }),
            // For the daemon: times the filter refused its state and reinitialised.
            resyncs: session.reinitialisations,
            pid: std::process::id(),
            state: state as u32,
            ..Default::default()
        };
        m.set_name(&cfg.name);
        hp.publish(m).map(|_| ())
    };
    let result = loop {
        // Which topics notified: only their listeners are read (one system call each, plus
        // the one that finds them empty), not all six on every wake-up.
        let mut notified = [false; TOPICS.len()];
        let r = waitset.wait_and_process_once(|id| {
            for (n, g) in notified.iter_mut().zip(&guards) {
                *n |= id.has_event_from(g);
            }
            CallbackProgression::Continue
        });
        match r {
            Ok(WaitSetRunResult::TerminationRequest) => break Ok(()),
            // Another signal (SIGCONT after a stop, a debugger's) interrupted the wait: not a
            // request to stop (SIGTERM/SIGINT are reported by the next wait).
            Ok(WaitSetRunResult::Interrupt) => continue,
            Ok(_) => {}
            Err(x) => break Err(format!("waiting: {x:?}")),
        }
        let now = monotonic_ns();
        out.woke_ns = now;
        for (l, _) in listeners.iter().zip(notified).filter(|(_, n)| *n) {
            let _ = l.try_wait(|_| {});
        }
        // Aids first, so that IMU samples arriving in the same wake-up find them queued.
        let step = (|| -> Result<(), BusError> {
            drain(&mut dvl, &mut dvls)?;
            drain(&mut depth, &mut depths)?;
            drain(&mut gnss, &mut gnsss)?;
            drain(&mut usbl, &mut usbls)?;
            drain(&mut magnetometer, &mut mags)?;
            drain(&mut sound_velocity, &mut svs)?;
            drain(&mut imu, &mut imus)?;
            Ok(())
        })();
        if let Err(x) = step {
            break Err(x.to_string());
        }
        if out.stage_times.is_some() {
            out.received_ns = monotonic_ns();
        }
        for (w, n) in watches.iter_mut().zip([
            imus.len(),
            dvls.len(),
            depths.len(),
            usbls.len(),
            gnsss.len(),
        ]) {
            if n > 0 {
                w.seen(now);
            }
            if w.check(now) {
                missed_deadlines += 1;
            }
        }
        // Aid messages first (they wait in the session for their turn), then the IMU samples.
        let aids = (dvls.drain(..).map(SensorMessage::Dvl))
            .chain(depths.drain(..).map(SensorMessage::Depth))
            .chain(gnsss.drain(..).map(SensorMessage::Gnss))
            .chain(usbls.drain(..).map(SensorMessage::Usbl))
            .chain(mags.drain(..).map(SensorMessage::Magnetometer))
            .chain(svs.drain(..).map(SensorMessage::SoundVelocity));
        let mut io_error = None;
        for m in aids.chain(imus.drain(..).map(SensorMessage::Imu)) {
            if let Err(x) = session.feed(&m, &mut |o| out.on(o)) {
                io_error = Some(x);
                break;
            }
        }
        if let Some(x) = io_error {
            break Err(format!("writing the CSV output: {x}"));
        }
        if session.started() {
            state = ProcessState::Running;
        }
        if was_aligning
            && !session.aligning()
            && let Some(nav) = session.navigator()
        {
            was_aligning = false;
            let p = nav.covariance();
            let sigma = |i: usize| p[(i, i)].max(0.0).sqrt();
            let att = auvnav_core::ekf::ATT;
            let pos = auvnav_core::ekf::POS;
            tracing::info!(
                heading_std_deg = sigma(att + 2).to_degrees(),
                horizontal_std_m = sigma(pos).hypot(sigma(pos + 1)),
                "auvnavd: aligned (heading sigma {:.3} deg, horizontal position sigma {:.2} m); navigating",
                sigma(att + 2).to_degrees(),
                sigma(pos).hypot(sigma(pos + 1)),
            );
        }
        if session.reinitialisations > reported_reinitialisations {
            reported_reinitialisations = session.reinitialisations;
            tracing::error!(
                reinitialisations = session.reinitialisations,
                "auvnavd: the filter's state or covariance was not finite or not a covariance; \
                 restarted from the last sound state with its covariance grown (solution \
                 published as invalid)"
            );
        }
        if let Some(w) = checkpoints.as_mut()
            && now >= next_checkpoint
            && let Some(cp) = session.checkpoint()
        {
            w.submit(cp);
            next_checkpoint = now + checkpoint_ns;
        }
        if now >= next_flush {
            if let Err(x) = out.flush() {
                break Err(format!("flushing the CSV output: {x}"));
            }
            bus.cleanup_dead_nodes();
            next_flush = now + 1_000_000_000;
        }
        if now >= next_health {
            let gaps = imu.gaps() + dvl.gaps() + depth.gaps() + gnss.gaps();
            if let Err(x) = publish_health(
                &mut health_pub,
                &out,
                &session,
                gaps,
                missed_deadlines,
                state,
            ) {
                break Err(x.to_string());
            }
            next_health = now + health_ns;
        }
    };
    let _ = session.finish(&mut |o| out.on(o));
    if let Some(w) = checkpoints.as_mut()
        && let Some(cp) = session.checkpoint()
    {
        w.submit(cp);
    }
    let checkpoint_errors = checkpoints.map_or(0, checkpoint::Writer::finish);
    let flushed = out.flush();
    let gaps = imu.gaps() + dvl.gaps() + depth.gaps() + gnss.gaps();
    let _ = publish_health(
        &mut health_pub,
        &out,
        &session,
        gaps,
        missed_deadlines,
        ProcessState::Stopping,
    );
    tracing::info!(
        "auvnavd: stopping; {} solutions ({} published), {} late aid messages, {} lost on the bus, {} missed deadlines, {} filter reinitialisations, {} checkpoint write errors; IMU: {}; USBL fixes: {}; magnetometer: {}",
        out.solutions,
        out.published,
        session.late_aids,
        gaps,
        missed_deadlines,
        session.reinitialisations,
        checkpoint_errors,
        imu_summary(&session),
        usbl_summary(&session),
        magnetometer_summary(&session)
    );
    result?;
    flushed.map_err(|x| format!("flushing the CSV output: {x}"))
}

/// What became of the IMU samples, for the stop message.
fn imu_summary(session: &Session) -> String {
    let Some(c) = session.navigator().map(|n| n.counters()) else {
        return "no navigation yet".into();
    };
    format!(
        "{} integrated, {} invalid or implausible, {} out of order, {} gaps bridged, {} device clock jumps",
        c.imu_samples, c.imu_invalid, c.imu_out_of_order, c.imu_gaps, c.imu_clock_jumps
    )
}

/// What became of the USBL fixes, for the stop message.
fn usbl_summary(session: &Session) -> String {
    let Some(c) = session.navigator().map(|n| n.counters()) else {
        return "no navigation yet".into();
    };
    if c.usbl_unconfigured > 0 {
        return format!(
            "{} received, not used (no [navigation.usbl] in the configuration)",
            c.usbl_unconfigured
        );
    }
    format!(
        "{} fused, {} rejected by the gate ({} gate reopenings), {} invalid, {} failed",
        c.usbl_fused, c.usbl_rejected, c.usbl_reopened, c.usbl_invalid, c.usbl_failed
    )
}

/// What became of the magnetometer readings, for the stop message.
fn magnetometer_summary(session: &Session) -> String {
    let Some(c) = session.navigator().map(|n| n.counters()) else {
        return "no navigation yet".into();
    };
    if c.magnetometer_unconfigured > 0 {
        return format!(
            "{} received, not used (no [navigation.magnetometer] in the configuration)",
            c.magnetometer_unconfigured
        );
    }
    format!(
        "{} fused, {} rejected by the gate, {} disturbed (magnitude far from the field model), {} invalid",
        c.magnetometer_fused,
        c.magnetometer_rejected,
        c.magnetometer_disturbed,
        c.magnetometer_invalid
    )
}

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
    match run(&cfg) {
        Ok(()) => ExitCode::SUCCESS,
        Err(x) => {
            tracing::error!("auvnavd: {x}");
            ExitCode::from(1)
        }
    }
}
