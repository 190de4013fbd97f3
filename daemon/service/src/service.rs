//! The daemon's loop, apart from the bus: each wake-up takes the messages that arrived
//! ([`Inputs`]), feeds them to the navigation session (aids first, then the IMU samples, as the
//! session orders them), and hands the solutions, diagnostics, late-aid records and health to
//! [`Outputs`]. `auvnavd` wires it to iceoryx2 (`crate::bus_io`); a test drives it with canned
//! messages and a clock of its own.
//!
//! Processing order (what makes a recording replay bit for bit): IMU samples are processed as
//! they arrive; an aid message stamped t is applied just before the first IMU sample stamped later
//! than t + `aid_delay_s` (see `auvnav_core::session`). An aid message that arrives after that IMU
//! sample was processed is late: counted and applied at the next one.

use crate::checkpoint;
use crate::csv_out::Csv;
use crate::stop_summary::sensors_summary;
use auvnav_core::config::DaemonConfig;
use auvnav_core::csv;
use auvnav_core::feed::SensorMessage;
use auvnav_core::session::{Session, SessionOutput};
use auvnav_shm_schema::clock::monotonic_ns;
use auvnav_shm_schema::stage_times::StageTimes;
use auvnav_shm_schema::{
    AcousticArrayPoseV1, AcousticRangesV1, AidDiagnosticsV1, DepthV1, DvlVelocityV1, GnssFixV1,
    ImuSampleV1, LateAidV1, MagnetometerV1, NavSolutionV1, ProcessHealthV1, ProcessState,
    SessionEventV1, SoundVelocityV1, UsblFixV1, topic,
};
use std::io::Write;

/// The messages of one wake-up, per topic in arrival order.
#[derive(Debug, Default, Clone)]
pub struct Batch {
    pub imu: Vec<ImuSampleV1>,
    pub dvl: Vec<DvlVelocityV1>,
    pub depth: Vec<DepthV1>,
    pub gnss: Vec<GnssFixV1>,
    pub usbl: Vec<UsblFixV1>,
    pub magnetometer: Vec<MagnetometerV1>,
    pub sound_velocity: Vec<SoundVelocityV1>,
    pub acoustic_ranges: Vec<AcousticRangesV1>,
    pub acoustic_array_pose: Vec<AcousticArrayPoseV1>,
}

impl Batch {
    /// Aid messages first (they wait in the session for their turn), then the IMU samples.
    fn drain(&mut self) -> impl Iterator<Item = SensorMessage> + '_ {
        (self.dvl.drain(..).map(SensorMessage::Dvl))
            .chain(self.depth.drain(..).map(SensorMessage::Depth))
            .chain(self.gnss.drain(..).map(SensorMessage::Gnss))
            .chain(self.usbl.drain(..).map(SensorMessage::Usbl))
            .chain(self.magnetometer.drain(..).map(SensorMessage::Magnetometer))
            .chain(
                self.sound_velocity
                    .drain(..)
                    .map(SensorMessage::SoundVelocity),
            )
            .chain(
                self.acoustic_array_pose
                    .drain(..)
                    .map(SensorMessage::AcousticArrayPose),
            )
            .chain(
                self.acoustic_ranges
                    .drain(..)
                    .map(SensorMessage::AcousticRanges),
            )
            .chain(self.imu.drain(..).map(SensorMessage::Imu))
    }
}

/// Why the loop woke up.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Wake {
    /// Messages arrived, or the periodic tick (the batch may be empty).
    Run,
    /// Stop: finish the session, write the last checkpoint and health, return.
    Stop,
}

/// Where the loop's messages come from.
pub trait Inputs {
    /// Waits for the next wake-up.
    fn wait(&mut self) -> Result<Wake, String>;
    /// Appends what arrived since the last call to `batch`.
    fn take(&mut self, batch: &mut Batch) -> Result<(), String>;
    /// The host clock (ns), for deadlines, health and checkpoint periods.
    fn now_ns(&self) -> u64;
    /// Messages lost on the way (sequence gaps).
    fn gaps(&self) -> u64;
    /// Once a second: the transport's housekeeping (the bus removes dead nodes).
    fn housekeeping(&mut self) {}
    /// Every turn of the loop (the service manager's keep-alive), with what the daemon is doing
    /// at each health period.
    fn supervise(&mut self, _status: Option<&str>) {}
}

/// The daemon's state in a line for the service manager: the mode and which sensors it hears.
fn status_line(state: ProcessState, session: &Session, watches: &[Watch]) -> String {
    let imu_heard = watches
        .iter()
        .any(|w| w.name == "imu" && w.heard && !w.lost);
    let mode = if session.aligning() {
        "aligning"
    } else if state == ProcessState::Running {
        "navigating"
    } else if imu_heard {
        "starting"
    } else {
        "waiting for the IMU"
    };
    let heard: Vec<&str> = watches
        .iter()
        .filter(|w| w.heard && !w.lost)
        .map(|w| w.name)
        .collect();
    let lost: Vec<&str> = watches.iter().filter(|w| w.lost).map(|w| w.name).collect();
    let mut s = format!(
        "{mode}; hearing {}",
        if heard.is_empty() {
            "nothing".into()
        } else {
            heard.join(", ")
        }
    );
    if !lost.is_empty() {
        s.push_str(&format!("; lost {}", lost.join(", ")));
    }
    s
}

/// Where the loop's results go. A publication that fails returns false (counted).
pub trait Outputs {
    fn solution(&mut self, s: &NavSolutionV1) -> bool;
    fn diagnostics(&mut self, d: &AidDiagnosticsV1) -> bool;
    fn late_aid(&mut self, r: &LateAidV1) -> bool;
    /// A session start or checkpoint, recorded so that a replay starts its sessions where this
    /// daemon did.
    fn session_event(&mut self, e: &SessionEventV1) -> bool;
    fn health(&mut self, h: &ProcessHealthV1) -> Result<(), String>;
}

/// A watched sensor: last arrival and whether it is reported lost.
struct Watch {
    name: &'static str,
    deadline_ns: u64,
    last_ns: u64,
    lost: bool,
    /// Whether the sensor has been heard from at all.
    heard: bool,
}

impl Watch {
    fn new(name: &'static str, deadline_s: f64, now: u64) -> Watch {
        Watch {
            name,
            deadline_ns: (deadline_s * 1e9) as u64,
            last_ns: now,
            lost: false,
            heard: false,
        }
    }
    fn seen(&mut self, now: u64) {
        self.heard = true;
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

/// What the loop counts, and returns when it stops.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Summary {
    /// Solutions computed, and those handed to the outputs (every `solution_decimation`-th).
    pub solutions: u64,
    pub published: u64,
    /// Publications that failed.
    pub errors: u64,
    pub late_aids_applied: u64,
    pub missed_deadlines: u64,
    pub reinitialisations: u64,
    pub checkpoint_errors: u64,
}

/// The session's outputs: CSV files, the stage times, and the publications.
struct Sink<'a, O: Outputs> {
    out: &'a mut O,
    nav_csv: Option<Csv>,
    diag_csv: Option<Csv>,
    stage_times: Option<StageTimes>,
    /// Host times of this wake-up and of the messages taken (for the stage times).
    woke_ns: u64,
    received_ns: u64,
    decimation: u64,
    summary: Summary,
}

impl<'a, O: Outputs> Sink<'a, O> {
    fn on(&mut self, o: SessionOutput) -> Result<(), std::io::Error> {
        match o {
            SessionOutput::Solution(s) => {
                if let Some(c) = self.nav_csv.as_mut() {
                    csv::write_nav_row(&mut c.w, s)?;
                }
                if self.summary.solutions.is_multiple_of(self.decimation) {
                    let computed_ns = self.stage_times.as_ref().map(|_| monotonic_ns());
                    if self.out.solution(s) {
                        self.summary.published += 1;
                    } else {
                        self.summary.errors += 1;
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
                self.summary.solutions += 1;
            }
            SessionOutput::Diagnostics(d) => {
                if let Some(c) = self.diag_csv.as_mut() {
                    csv::write_diagnostics_row(&mut c.w, d)?;
                }
                if !self.out.diagnostics(d) {
                    self.summary.errors += 1;
                }
            }
            SessionOutput::Started(e) => {
                if !self.out.session_event(e) {
                    self.summary.errors += 1;
                }
            }
            SessionOutput::LateAid(r) => {
                self.summary.late_aids_applied += 1;
                if self.summary.late_aids_applied <= 10 {
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
                if !self.out.late_aid(r) {
                    self.summary.errors += 1;
                }
            }
        }
        Ok(())
    }

    /// The outputs of a daemon with `cfg`: its files created, or continued after a restart that
    /// continues from the checkpoint.
    fn new(cfg: &DaemonConfig, out: &'a mut O, continuing: bool) -> Result<Self, String> {
        Ok(Sink {
            out,
            nav_csv: Csv::create(&cfg.output.nav_csv, csv::NAV_HEADER, continuing)?,
            diag_csv: Csv::create(
                &cfg.output.diagnostics_csv,
                csv::DIAGNOSTICS_HEADER,
                continuing,
            )?,
            stage_times: StageTimes::create(
                &cfg.output.stage_times_csv,
                "imu_host_time_ns,woke_ns,received_ns,computed_ns,published_ns",
            )
            .map_err(|x| format!("creating {}: {x}", cfg.output.stage_times_csv))?,
            woke_ns: 0,
            received_ns: 0,
            decimation: u64::from(cfg.output.solution_decimation.max(1)),
            summary: Summary::default(),
        })
    }

    /// Records that a checkpoint was taken, so that a replay takes the same one for a restart
    /// that continues from it.
    fn checkpoint_taken(&mut self, cp: &auvnav_core::navigator::Checkpoint) {
        let event = SessionEventV1 {
            host_time_ns: (cp.time_s * 1e9).round() as u64,
            kind: SessionEventV1::KIND_CHECKPOINT,
            ..Default::default()
        };
        if !self.out.session_event(&event) {
            self.summary.errors += 1;
        }
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

/// The daemon's health message now.
fn health(
    cfg: &DaemonConfig,
    now_ns: u64,
    summary: &Summary,
    session: &Session,
    gaps: u64,
    state: ProcessState,
) -> ProcessHealthV1 {
    let mut m = ProcessHealthV1 {
        host_time_ns: now_ns,
        frames: summary.published,
        // Sensors that missed their deadline, and IMU gaps bridged.
        timeouts: summary.missed_deadlines
            + session.navigator().map_or(0, |n| n.counters().imu_gaps),
        drops: gaps + session.late_aids + summary.errors,
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
    m
}

/// Logs the end of in-motion alignment (once) and each filter reinitialisation.
struct Reporter {
    was_aligning: bool,
    reinitialisations: u64,
}

impl Reporter {
    fn after_wake(&mut self, session: &Session) {
        if self.was_aligning
            && !session.aligning()
            && let Some(nav) = session.navigator()
        {
            self.was_aligning = false;
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
        if session.reinitialisations > self.reinitialisations {
            self.reinitialisations = session.reinitialisations;
            tracing::error!(
                reinitialisations = session.reinitialisations,
                "auvnavd: the filter's state or covariance was not finite or not a covariance; \
                 restarted from the last sound state with its covariance grown (solution \
                 published as invalid)"
            );
        }
    }
}

/// Runs the daemon's loop until the inputs say stop (or fail); the counts at the end.
pub fn run<I: Inputs, O: Outputs>(
    cfg: &DaemonConfig,
    inputs: &mut I,
    outputs: &mut O,
) -> Result<Summary, String> {
    let (mut session, continuing) = checkpoint::start_session(cfg);
    let mut sink = Sink::new(cfg, outputs, continuing)?;
    let mut checkpoints = checkpoint::Writer::start(cfg);
    let checkpoint_ns = (cfg.checkpoint.interval_s * 1e9) as u64;
    let mut next_checkpoint = 0u64;
    let mut reporter = Reporter {
        was_aligning: session.aligning(),
        reinitialisations: 0,
    };
    let now = inputs.now_ns();
    let d = &cfg.deadlines;
    let mut watches = [
        Watch::new("imu", d.imu_s, now),
        Watch::new("dvl", d.dvl_s, now),
        Watch::new("depth", d.depth_s, now),
        Watch::new("usbl", d.usbl_s, now),
        Watch::new("gnss", d.gnss_s, now),
    ];
    let health_ns = (cfg.health_period_s * 1e9) as u64;
    let mut next_health = 0u64;
    let mut next_flush = now + 1_000_000_000;
    let mut batch = Batch::default();
    let mut state = ProcessState::Starting;
    tracing::info!(
        "auvnavd: running under {}/ (aid delay {} s, solution every {} IMU samples)",
        cfg.prefix,
        cfg.aid_delay_s,
        cfg.output.solution_decimation
    );
    let result = loop {
        match inputs.wait() {
            Ok(Wake::Stop) => break Ok(()),
            Ok(Wake::Run) => {}
            Err(x) => break Err(x),
        }
        let now = inputs.now_ns();
        sink.woke_ns = now;
        inputs.supervise(None);
        if let Err(x) = inputs.take(&mut batch) {
            break Err(x);
        }
        if sink.stage_times.is_some() {
            sink.received_ns = monotonic_ns();
        }
        for (w, n) in watches.iter_mut().zip([
            batch.imu.len(),
            batch.dvl.len(),
            batch.depth.len(),
            batch.usbl.len(),
            batch.gnss.len(),
        ]) {
            if n > 0 {
                w.seen(now);
            }
            if w.check(now) {
                sink.summary.missed_deadlines += 1;
            }
        }
        let mut io_error = None;
        for m in batch.drain() {
            if let Err(x) = session.feed(&m, &mut |o| sink.on(o)) {
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
        reporter.after_wake(&session);
        if let Some(w) = checkpoints.as_mut()
            && now >= next_checkpoint
            && let Some(cp) = session.checkpoint()
        {
            sink.checkpoint_taken(&cp);
            w.submit(cp);
            next_checkpoint = now + checkpoint_ns;
        }
        if now >= next_flush {
            if let Err(x) = sink.flush() {
                break Err(format!("flushing the CSV output: {x}"));
            }
            inputs.housekeeping();
            next_flush = now + 1_000_000_000;
        }
        if now >= next_health {
            inputs.supervise(Some(&status_line(state, &session, &watches)));
            let h = health(cfg, now, &sink.summary, &session, inputs.gaps(), state);
            if let Err(x) = sink.out.health(&h) {
                break Err(x);
            }
            next_health = now + health_ns;
        }
    };
    let _ = session.finish(&mut |o| sink.on(o));
    if let Some(w) = checkpoints.as_mut()
        && let Some(cp) = session.checkpoint()
    {
        sink.checkpoint_taken(&cp);
        w.submit(cp);
    }
    sink.summary.checkpoint_errors = checkpoints.map_or(0, checkpoint::Writer::finish);
    sink.summary.reinitialisations = session.reinitialisations;
    let flushed = sink.flush();
    let gaps = inputs.gaps();
    let h = health(
        cfg,
        inputs.now_ns(),
        &sink.summary,
        &session,
        gaps,
        ProcessState::Stopping,
    );
    let _ = sink.out.health(&h);
    let s = sink.summary;
    tracing::info!(
        "auvnavd: stopping; {} solutions ({} published), {} late aid messages, {} lost on the bus, {} missed deadlines, {} filter reinitialisations, {} checkpoint write errors; {}",
        s.solutions,
        s.published,
        session.late_aids,
        gaps,
        s.missed_deadlines,
        session.reinitialisations,
        s.checkpoint_errors,
        sensors_summary(&session)
    );
    result?;
    flushed.map_err(|x| format!("flushing the CSV output: {x}"))?;
    Ok(s)
}
