//! `auvnav replay`: runs a log through the navigation core as fast as it can.
//!
//! The log's sensor messages go through the navigation session's feed (`Session::feed`), the
//! path the daemon runs, in time-stamp order ([`order`]: the log's write order can differ from the
//! order in which the daemon met the messages); the session orders the aids against the IMU stream
//! as the daemon does, and aids the daemon applied late are applied where its late-aid records
//! say. The initial state comes from the configuration's `[initial]` table when it has one, otherwise from
//! the first record of the log's truth channel (simulated truth, or the reference solution of an
//! imported data set); sensor messages before that are counted and skipped. When the log has a
//! truth channel, the solution is compared with it at every truth epoch (linear interpolation
//! between the two solutions around the epoch).
//!
//! A recording that spans a restart of the daemon is replayed across it ([`restarts`]).
//!
//! The crate is the replay itself ([`Replay`]), its feed order ([`order`]), the accuracy against
//! a truth or reference channel ([`accuracy`]), a whole replay as one call ([`replay`]), and what
//! the other offline tools share: [`load_config`], [`interpolate`], [`run_log`], atomic outputs
//! ([`partial_path`], [`write_atomically`]), the reports' SVG plots ([`svg`]). It neither parses
//! arguments nor prints.
// Long on purpose: the replay state machine and the outputs and counts it reports; its feed
// order, restarts and accuracy are modules of their own.
#![forbid(unsafe_code)]

pub mod accuracy;
mod error;
pub mod json;
pub mod order;
mod recorded;
pub use recorded::RecordedComparison;
pub mod restarts;
mod run;
pub mod surface;
pub mod svg;
pub use error::{ReplayError, Source};
pub use run::*;

use crate::accuracy::{Accuracy, AccuracyTracker, SolutionPoint};
use anyhow::Context;
use auvnav_core::feed::SensorMessage;
use auvnav_core::navigator::{NavCounters, Navigator};
use auvnav_core::session::{Session, SessionOutput};
use auvnav_core::strapdown::NavState;
use auvnav_log::{LogError, LogHeader, LogMessage, LogReader, write_log_atomically};
use auvnav_shm_schema::{AidDiagnosticsV1, LateAidV1, NavSolutionV1, TruthStateV1, topic};
use serde::Serialize;
use std::io::Write;
use std::path::{Path, PathBuf};

pub use auvnav_core::session::{InitialReport, InitialState};

/// Why an offline tool failed, for the `auvnav` exit status (docs/operations.md): 0 success, 1 a runtime failure
/// (I/O, a device, the bus), 2 a usage or configuration error (clap's own errors are 2 as well),
/// 3 a check that ran and failed (a replay that does not reproduce, a demo that did not).
#[derive(Debug, thiserror::Error)]
pub enum Failure {
    #[error("{0}")]
    Usage(String),
    #[error("{0}")]
    CheckFailed(String),
}

/// The replay configuration file: `[navigation]` (the core's `NavConfig`) and an optional
/// `[initial]` state — the same file the daemon's `[navigation]`/`[initial]` tables hold.
pub type ReplayConfig = auvnav_core::session::SessionConfig;

/// Reads a replay configuration file and validates it as the daemon does.
pub fn load_config(path: &Path) -> Result<ReplayConfig, ReplayError> {
    let config = |source: Source| ReplayError::Config {
        path: path.to_path_buf(),
        source,
    };
    let text = std::fs::read_to_string(path).map_err(|e| config(e.into()))?;
    let cfg: ReplayConfig = toml::from_str(&text).map_err(|e| config(e.into()))?;
    cfg.validate().map_err(|e| config(e.into()))?;
    Ok(cfg)
}

/// The `[navigation]` table of the configuration file at `path`, or the defaults without one
/// (the studies' `--config`).
pub fn load_navigation(
    path: Option<&Path>,
) -> Result<auvnav_core::navigator::NavConfig, ReplayError> {
    Ok(match path {
        Some(p) => load_config(p)?.navigation,
        None => auvnav_core::navigator::NavConfig::default(),
    })
}

/// One output of the navigator.
#[derive(Debug, Clone, Copy)]
pub enum Output<'a> {
    Solution(&'a NavSolutionV1),
    Diagnostics(&'a AidDiagnosticsV1),
    /// A truth record of the input, passed through so outputs can be compared with it.
    Truth(&'a TruthStateV1),
    /// An aid message this replay applied late (after the IMU had passed its due point).
    LateAid(&'a LateAidV1),
}

/// What a replay skipped or could not use, per kind of input.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize)]
pub struct ReplayCounts {
    pub messages: u64,
    pub imu: u64,
    pub dvl: u64,
    pub depth: u64,
    pub gnss: u64,
    /// USBL fixes (fused when the configuration has `[navigation.usbl]`; the navigator's
    /// counters say what became of them).
    pub usbl: u64,
    /// Magnetometer readings (fused as headings with `[navigation.magnetometer]`).
    pub magnetometer: u64,
    /// Sound-velocity readings (a CTD; used with `dvl_sound_speed_source = "topic"`).
    pub sound_velocity: u64,
    /// Acoustic range messages (fused with `[navigation.ranges]`) and a moving array's poses.
    pub acoustic_ranges: u64,
    pub acoustic_array_poses: u64,
    pub truth: u64,
    /// Sensor messages before the initial state was known (skipped).
    pub before_start: u64,
    /// Messages this replay does not use (outputs of an earlier run).
    pub unused: u64,
    /// Channels with a schema this program does not know (skipped).
    pub unknown: u64,
    /// Messages whose bytes do not match their schema (skipped).
    pub malformed: u64,
    /// Truth records older than the solution they would be compared with (skipped).
    pub truth_late: u64,
    /// Messages written after a message with a later time stamp (put in their place).
    pub written_out_of_order: u64,
    /// Messages written more than the reorder window behind (fed as they came).
    pub beyond_reorder_window: u64,
    /// The daemon's records of aids it applied late, found in the log.
    pub late_aid_records: u64,
    /// Of those, records whose aid was not found in the window (the replay may differ from the
    /// live solution from there on).
    pub late_aid_records_unmatched: u64,
    /// Aid messages this replay applied late (after the IMU had passed their due point).
    pub late_aids: u64,
}

/// Estimated parameters at the end of a replay.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct FinalParameters {
    pub gyro_bias_deg_h: [f64; 3],
    pub accel_bias_ug: [f64; 3],
    /// DVL mounting roll, pitch, yaw w.r.t. the body (deg).
    pub dvl_mount_deg: [f64; 3],
    pub dvl_scale_factor: f64,
    pub dvl_lever_arm_m: [f64; 3],
    pub dvl_time_offset_s: f64,
}

impl FinalParameters {
    pub fn of(nav: &Navigator) -> FinalParameters {
        let (bg, ba) = nav.imu_biases();
        let d = nav.dvl_parameters();
        let (r, p, y) = nalgebra::Rotation3::from_matrix_unchecked(d.c_dvl_to_body).euler_angles();
        FinalParameters {
            gyro_bias_deg_h: (bg * 3600.0).map(f64::to_degrees).into(),
            accel_bias_ug: (ba / 9.806_65e-6).into(),
            dvl_mount_deg: [r.to_degrees(), p.to_degrees(), y.to_degrees()],
            dvl_scale_factor: d.scale,
            dvl_lever_arm_m: d.lever_arm_m.into(),
            dvl_time_offset_s: d.time_offset_s,
        }
    }
}

/// The replay state machine, fed one message at a time.
pub struct Replay {
    session: Session,
    order: order::FeedOrder,
    tracker: AccuracyTracker,
    has_truth: bool,
    prev_solution: Option<SolutionPoint>,
    pending_truth: Option<TruthStateV1>,
    pub counts: ReplayCounts,
    first_time_ns: Option<u64>,
    last_time_ns: u64,
    recorded: Option<RecordedComparison>,
    /// Messages from outside the log (position fixes of a file), fed in time order among the
    /// log's.
    injected: std::collections::VecDeque<LogMessage>,
    /// Where the truth channel's point sits from the IMU, body axes (m); zero: at the IMU.
    reference_lever_arm_m: [f64; 3],
    /// The daemon's recorded session starts and checkpoints, and the configuration a new
    /// session starts from.
    restarts: restarts::Restarts,
    cfg: ReplayConfig,
}

impl Replay {
    pub fn new(cfg: &ReplayConfig, min_distance_m: f64) -> Replay {
        Replay {
            session: Session::new(cfg),
            order: order::FeedOrder::default(),
            tracker: AccuracyTracker::new(min_distance_m),
            has_truth: false,
            prev_solution: None,
            pending_truth: None,
            counts: ReplayCounts::default(),
            first_time_ns: None,
            last_time_ns: 0,
            recorded: None,
            injected: std::collections::VecDeque::new(),
            reference_lever_arm_m: [0.0; 3],
            restarts: restarts::Restarts::default(),
            cfg: cfg.clone(),
        }
    }

    /// The daemon's session starts the replay met (restarts of the daemon among them).
    pub fn restart_counts(&self) -> restarts::RestartCounts {
        self.restarts.counts
    }

    /// The point of the vehicle the truth channel describes, from the IMU in body axes (m, FRD):
    /// a post-processed reference is often the position of another sensor. Each truth record is
    /// moved to the IMU (position by the record's attitude times the lever arm, velocity by the
    /// lever arm's rotation where the record has its angular rate) before it starts the
    /// navigation or is compared with it, so a heading change does not read as navigation error.
    pub fn set_reference_lever_arm(&mut self, lever_arm_m: [f64; 3]) {
        self.reference_lever_arm_m = lever_arm_m;
    }

    /// `t` moved from the reference's point to the IMU.
    fn at_imu(&self, t: &TruthStateV1) -> TruthStateV1 {
        let l = nalgebra::Vector3::from(self.reference_lever_arm_m);
        if l == nalgebra::Vector3::zeros() {
            return *t;
        }
        // The attitude the replay starts from (`NavState::from_truth` reads the Euler angles).
        let [roll, pitch, yaw] = t.euler_rad;
        let q = nalgebra::UnitQuaternion::from_euler_angles(roll, pitch, yaw);
        let mut moved = *t;
        let p = auvnav_core::earth::offset_position(
            &auvnav_core::strapdown::truth_position(t),
            &-(q * l),
        );
        (moved.latitude_rad, moved.longitude_rad, moved.height_m) =
            (p.latitude_rad, p.longitude_rad, p.height_m);
        let omega = nalgebra::Vector3::from(t.angular_rate_rad_s);
        if omega.iter().all(|x| x.is_finite()) {
            let v = nalgebra::Vector3::from(t.velocity_ned_m_s) - q * omega.cross(&l);
            moved.velocity_ned_m_s = [v.x, v.y, v.z];
        }
        moved
    }

    /// Feeds `messages` (aids from outside the log, e.g. position fixes of a file) among the
    /// log's, each before the first log message stamped at or after it.
    pub fn inject(&mut self, mut messages: Vec<LogMessage>) {
        let time = |m: &LogMessage| m.sensor().map_or(0, |s| s.host_time_ns());
        messages.sort_by_key(time);
        self.injected = messages.into();
    }

    /// Records what the smoother's backward pass needs (`auvnav_core::smoother`).
    pub fn record_for_smoothing(&mut self, log: auvnav_core::smoother::SmootherLog) {
        self.session.record_for_smoothing(log);
    }

    /// The smoother's record, at the end of the replay.
    pub fn finish_recording(&mut self) -> Option<auvnav_core::smoother::SmoothingRun> {
        self.session.finish_recording()
    }

    fn push_injected(
        &mut self,
        before_ns: Option<u64>,
        out: &mut dyn FnMut(Output) -> anyhow::Result<()>,
    ) -> anyhow::Result<()> {
        while let Some(m) = self.injected.front() {
            let t = m.sensor().map_or(0, |s| s.host_time_ns());
            if before_ns.is_some_and(|b| t > b) {
                break;
            }
            let Some(m) = self.injected.pop_front() else {
                break;
            };
            if self.order.push(&m) {
                while let Some(h) = self.order.pop_ready() {
                    self.feed(h, out)?;
                }
            }
        }
        Ok(())
    }

    /// Compares the solutions with those the log recorded (see [`RecordedComparison`]).
    pub fn compare_with_recorded(&mut self) {
        self.recorded = Some(RecordedComparison::default());
    }

    /// The comparison with the recorded solutions, when asked for.
    pub fn recorded_comparison(&self) -> Option<&RecordedComparison> {
        self.recorded.as_ref()
    }

    pub fn navigator(&self) -> Option<&Navigator> {
        self.session.navigator()
    }

    /// Passes the session's outputs on, following the solutions for the truth comparison.
    fn forward<'o>(
        prev: &'o mut Option<SolutionPoint>,
        pending: &'o mut Option<TruthStateV1>,
        tracker: &'o mut AccuracyTracker,
        recorded: &'o mut Option<RecordedComparison>,
        out: &'o mut dyn FnMut(Output) -> anyhow::Result<()>,
    ) -> impl FnMut(SessionOutput) -> anyhow::Result<()> + 'o {
        move |o| match o {
            SessionOutput::Solution(sol) => {
                out(Output::Solution(sol))?;
                if let Some(r) = recorded.as_mut() {
                    r.check(sol);
                }
                let point = SolutionPoint::of(sol);
                if let (Some(t), Some(p)) = (pending.as_ref(), prev.as_ref())
                    && sol.host_time_ns >= t.host_time_ns
                {
                    tracker.add_point(&SolutionPoint::interpolate(p, &point, t.host_time_ns), t);
                    *pending = None;
                }
                *prev = Some(point);
                Ok(())
            }
            SessionOutput::Diagnostics(d) => out(Output::Diagnostics(d)),
            SessionOutput::LateAid(r) => out(Output::LateAid(r)),
            // The replay starts its sessions from the recorded starts ([`restarts`]).
            SessionOutput::Started(_) => Ok(()),
        }
    }

    /// Takes one message in log order; the messages whose place in the time-stamp order is
    /// settled go through the session, their outputs to `out`.
    pub fn process(
        &mut self,
        m: &LogMessage,
        out: &mut dyn FnMut(Output) -> anyhow::Result<()>,
    ) -> anyhow::Result<()> {
        self.counts.messages += 1;
        if !self.injected.is_empty()
            && let Some(t) = m.sensor().map(|x| x.host_time_ns()).or(match m {
                LogMessage::Truth(t) => Some(t.host_time_ns),
                _ => None,
            })
        {
            self.push_injected(Some(t), out)?;
        }
        match m {
            LogMessage::Unknown => self.counts.unknown += 1,
            LogMessage::LateAid(r) => {
                self.counts.late_aid_records += 1;
                self.order.apply_late_record(r);
            }
            LogMessage::SessionEvent(e) => self.restarts.record(e),
            LogMessage::NavSolution(s) if self.recorded.is_some() => {
                if let Some(r) = self.recorded.as_mut() {
                    r.push_recorded(*s);
                }
            }
            m if self.order.push(m) => {
                while let Some(m) = self.order.pop_ready() {
                    self.feed(m, out)?;
                }
            }
            _ => self.counts.unused += 1,
        }
        self.note_order();
        Ok(())
    }

    fn note_order(&mut self) {
        let o = &self.order;
        self.counts.written_out_of_order = o.out_of_order;
        self.counts.beyond_reorder_window = o.beyond_window;
        self.counts.late_aid_records_unmatched = o.late_records_unmatched;
        self.counts.late_aids = self.session.late_aids;
        self.counts.before_start = self.session.before_start;
    }

    /// Feeds one message in time-stamp order.
    fn feed(
        &mut self,
        m: order::Held,
        out: &mut dyn FnMut(Output) -> anyhow::Result<()>,
    ) -> anyhow::Result<()> {
        let m = match m {
            order::Held::Imu(x) => return self.feed_sensor(&SensorMessage::Imu(x), out),
            order::Held::Other(m) => m,
        };
        match *m {
            LogMessage::Truth(ref reference) => {
                let moved = self.at_imu(reference);
                let t = &moved;
                self.counts.truth += 1;
                self.has_truth = true;
                out(Output::Truth(t))?;
                self.note_time(t.host_time_ns);
                if !self.session.started()
                    && !self.session.has_configured_initial()
                    && !self.session.has_alignment()
                {
                    let state = NavState::from_truth(t);
                    let mut fwd = Self::forward(
                        &mut self.prev_solution,
                        &mut self.pending_truth,
                        &mut self.tracker,
                        &mut self.recorded,
                        out,
                    );
                    self.session
                        .start(state, "first record of the truth channel", &mut fwd)?;
                }
                self.compare(t);
            }
            ref other => match other.sensor() {
                Some(x) => self.feed_sensor(&x, out)?,
                None => self.counts.unused += 1,
            },
        }
        Ok(())
    }

    /// Feeds one sensor message to the session.
    fn feed_sensor(
        &mut self,
        x: &SensorMessage,
        out: &mut dyn FnMut(Output) -> anyhow::Result<()>,
    ) -> anyhow::Result<()> {
        *match x {
            SensorMessage::Imu(_) => &mut self.counts.imu,
            SensorMessage::Dvl(_) => &mut self.counts.dvl,
            SensorMessage::Depth(_) => &mut self.counts.depth,
            SensorMessage::Gnss(_) => &mut self.counts.gnss,
            SensorMessage::Usbl(_) => &mut self.counts.usbl,
            SensorMessage::Magnetometer(_) => &mut self.counts.magnetometer,
            SensorMessage::SoundVelocity(_) => &mut self.counts.sound_velocity,
            SensorMessage::AcousticRanges(_) => &mut self.counts.acoustic_ranges,
            SensorMessage::AcousticArrayPose(_) => &mut self.counts.acoustic_array_poses,
        } += 1;
        if let SensorMessage::Imu(m) = x {
            self.restarts
                .before_imu(m.host_time_ns, &mut self.session, &self.cfg);
        }
        let mut fwd = Self::forward(
            &mut self.prev_solution,
            &mut self.pending_truth,
            &mut self.tracker,
            &mut self.recorded,
            out,
        );
        self.session.feed(x, &mut fwd)?;
        drop(fwd);
        if let SensorMessage::Imu(m) = x {
            self.restarts.after_imu(m.host_time_ns, &self.session);
        }
        self.note_time(x.host_time_ns());
        Ok(())
    }

    /// Applies the aid messages still waiting for an IMU sample: call at the end of the input.
    pub fn finish(
        &mut self,
        out: &mut dyn FnMut(Output) -> anyhow::Result<()>,
    ) -> anyhow::Result<()> {
        self.push_injected(None, out)?;
        while let Some(m) = self.order.pop_any() {
            self.feed(m, out)?;
        }
        let mut fwd = Self::forward(
            &mut self.prev_solution,
            &mut self.pending_truth,
            &mut self.tracker,
            &mut self.recorded,
            out,
        );
        self.session.finish(&mut fwd)?;
        drop(fwd);
        if let Some(r) = self.recorded.as_mut() {
            r.finish();
        }
        self.note_order();
        Ok(())
    }

    fn note_time(&mut self, t_ns: u64) {
        self.first_time_ns.get_or_insert(t_ns);
        self.last_time_ns = self.last_time_ns.max(t_ns);
    }

    fn compare(&mut self, t: &TruthStateV1) {
        let Some(prev) = self.prev_solution else {
            return;
        };
        if prev.host_time_ns == t.host_time_ns {
            self.tracker.add_point(&prev, t);
        } else if prev.host_time_ns > t.host_time_ns {
            self.counts.truth_late += 1;
        } else {
            // Wait for the first solution at or after the truth epoch. A newer truth record
            // replaces one still waiting (only possible when the IMU is slower than the truth).
            if self.pending_truth.replace(*t).is_some() {
                self.counts.truth_late += 1;
            }
        }
    }

    /// The accuracy against the truth channel, when the log has one.
    pub fn accuracy(&self) -> Option<Accuracy> {
        self.has_truth.then(|| self.tracker.result())
    }

    /// The configuration aligns (`[alignment]`) instead of starting from a given state.
    pub fn has_alignment(&self) -> bool {
        self.session.has_alignment()
    }

    pub fn initial(&self) -> Option<&InitialReport> {
        self.session.initial()
    }

    pub fn nav_counters(&self) -> NavCounters {
        self.session
            .navigator()
            .map(|n| n.counters())
            .unwrap_or_default()
    }

    /// Log time covered by the messages seen (s).
    pub fn duration_s(&self) -> f64 {
        self.first_time_ns
            .map(|f| (self.last_time_ns - f) as f64 * 1e-9)
            .unwrap_or(0.0)
    }
}

/// The solution at `t_ns` between `a` and `b` (position, velocity and heading interpolated
/// linearly; the rest taken from `b`).
pub fn interpolate(a: &NavSolutionV1, b: &NavSolutionV1, t_ns: u64) -> NavSolutionV1 {
    let span = b.host_time_ns.saturating_sub(a.host_time_ns);
    if span == 0 {
        return *b;
    }
    let w = t_ns.saturating_sub(a.host_time_ns) as f64 / span as f64;
    let lerp = |x: f64, y: f64| x + (y - x) * w;
    let mut s = *b;
    s.host_time_ns = t_ns;
    s.latitude_rad = lerp(a.latitude_rad, b.latitude_rad);
    s.longitude_rad = lerp(a.longitude_rad, b.longitude_rad);
    s.height_m = lerp(a.height_m, b.height_m);
    for i in 0..3 {
        s.velocity_ned_m_s[i] = lerp(a.velocity_ned_m_s[i], b.velocity_ned_m_s[i]);
    }
    let dyaw = crate::accuracy::wrap(b.euler_rad[2] - a.euler_rad[2]);
    s.euler_rad[2] = a.euler_rad[2] + dyaw * w;
    s
}
