//! A navigation session: the navigator together with how it starts, fed sensor messages one at a
//! time through [`crate::feed`]. The daemon runs it on live messages and `auvnav replay` on a
//! log's, in the same order, so that the same messages give the same solutions bit for bit.
//!
//! Long on purpose: how a session starts (initial state, coarse and fine alignment) and its feed
//! with the late-aid ordering are one state machine over the same fields.

use crate::aid::magnetometer::MagnetometerAid;
use crate::align::coarse::InMotionAligner;
use crate::align::fine::{ErrorModel, FineAlignConfig, FineAligner};
pub use crate::config::{AlignmentConfig, InitialState, SessionConfig};
use crate::config::{HeadingSource, NavConfig};
use crate::earth::Geodetic;
use crate::feed::SensorMessage;
use crate::navigator::{Checkpoint, Navigator, sound_speed_correction};
use crate::smoother::{NominalParameters, SmootherLog, SmoothingRun};
use crate::strapdown::NavState;
use auvnav_shm_schema::{
    AidDiagnosticsV1, DvlVelocityV1, ImuSampleV1, LateAidV1, NavMode, NavSolutionV1, SessionEventV1,
};
use nalgebra::{Matrix3, Rotation3, UnitQuaternion, Vector3};
use serde::Serialize;

/// One output of the session.
#[derive(Debug, Clone, Copy)]
pub enum SessionOutput<'a> {
    Solution(&'a NavSolutionV1),
    Diagnostics(&'a AidDiagnosticsV1),
    /// An aid message that came after the IMU stream had passed its due point, applied just
    /// before the IMU sample this record names (the daemon publishes it for replay).
    LateAid(&'a LateAidV1),
    /// The session started (at its first IMU sample), from the configuration or continued from a
    /// checkpoint (the daemon publishes it, so that a replay starts a session where it did).
    Started(&'a SessionEventV1),
}

/// Where the initial state came from, stated in the outputs of the tools.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct InitialReport {
    pub source: &'static str,
    pub time_s: f64,
    pub latitude_deg: f64,
    pub longitude_deg: f64,
    pub height_m: f64,
    pub velocity_ned_m_s: [f64; 3],
    pub euler_deg: [f64; 3],
}

/// Order in which queued aid messages are applied: time stamp, then kind (`LateAidV1::TOPIC_*`),
/// then the publisher's sequence number. A USBL fix is queued by delivery like the others; the navigator evaluates it
/// against the vehicle's pose at its (earlier) time of validity.
fn aid_key(m: &SensorMessage) -> (u64, u32, u64) {
    // IMU samples are never queued (processed as they come): last. A sound-velocity reading is
    // not an aid but what corrects the DVL: first among messages of the same time.
    let order = match m {
        SensorMessage::SoundVelocity(_) | SensorMessage::AcousticArrayPose(_) => 0,
        other => other.aid_topic().unwrap_or(u32::MAX),
    };
    (m.host_time_ns(), order, m.sequence())
}

/// The time an aid message was stamped with (a DVL reading's before the session retimed it by
/// `dvl_retime_ns`): whether it came before the session's start is judged on it, because only
/// messages stamped after the start were surely published after the daemon subscribed.
fn stamped_ns(m: &SensorMessage, dvl_retime_ns: u64) -> u64 {
    match m {
        SensorMessage::Dvl(d) => d.host_time_ns.saturating_sub(dvl_retime_ns),
        other => other.host_time_ns(),
    }
}

/// An aid message waiting for its turn; `late` when it came after the IMU had passed its due
/// point.
struct Pending(SensorMessage, bool);

impl PartialEq for Pending {
    fn eq(&self, o: &Self) -> bool {
        aid_key(&self.0) == aid_key(&o.0)
    }
}
impl Eq for Pending {}
impl PartialOrd for Pending {
    fn partial_cmp(&self, o: &Self) -> Option<std::cmp::Ordering> {
        Some(self.cmp(o))
    }
}
impl Ord for Pending {
    fn cmp(&self, o: &Self) -> std::cmp::Ordering {
        // Reversed: the heap pops the earliest first.
        aid_key(&o.0).cmp(&aid_key(&self.0))
    }
}

/// What the session does for a smoother (`crate::smoother`).
enum Smoothing {
    Off,
    /// The first run: the navigator's epochs go to the log; each chain's nominal parameters
    /// at its start (and end, once known).
    Record {
        log: Box<SmootherLog>,
        chains: Vec<(NominalParameters, Option<NominalParameters>)>,
    },
}

/// The navigator, its start and the order in which aid messages meet the IMU stream.
pub struct Session {
    smoothing: Smoothing,
    cfg: NavConfig,
    configured_initial: Option<InitialState>,
    nav: Option<Navigator>,
    initial: Option<InitialReport>,
    aid_delay_ns: u64,
    /// DVL readings are held this long (their stamp moved to the moment they describe): a
    /// negative configured DVL time offset (`navigator::dvl_retime_s`).
    dvl_retime_ns: u64,
    pending: std::collections::BinaryHeap<Pending>,
    last_imu_ns: u64,
    /// Sensor messages before the initial state was known (skipped).
    pub before_start: u64,
    /// Aid messages that arrived after the IMU had passed their time + delay (applied at the
    /// next IMU sample, and reported as [`SessionOutput::LateAid`] so that a recording carries
    /// where).
    pub late_aids: u64,
    late_sequence: u64,
    alignment: Option<AlignmentConfig>,
    aligner: Option<InMotionAligner>,
    last_omega: Vector3<f64>,
    last_velocity_body: Option<Vector3<f64>>,
    aligning_epochs: usize,
    aligned: bool,
    align_sequence: u64,
    fine: Option<FineAligner>,
    /// The fine stage hands over to the navigator when its heading meets the criterion (false:
    /// a study runs the alignment filter for its whole length).
    fine_hands_over: bool,
    /// The fine stage integrates IMU samples stamped after this (ns).
    fine_start_ns: u64,
    /// Coarse heading from the magnetometer (`heading_source = "magnetometer"`): its
    /// calibration and field model, and the sum of the calibrated readings in start-body axes.
    align_magnetometer: Option<MagnetometerAid>,
    mag_sum_b0: Vector3<f64>,
    mag_count: usize,
    /// The last navigator found sound (taken at most once per second of state time): where the
    /// filter restarts when its state or covariance stops being sound.
    last_sound: Option<Navigator>,
    /// Times the filter refused its state or covariance and restarted from `last_sound`.
    pub reinitialisations: u64,
    /// A checkpoint to continue from at the first IMU sample (a restart), with the time elapsed
    /// since it was written (s) and the speed the vehicle may have drifted at meanwhile (m/s).
    resume: Option<(Checkpoint, f64, f64)>,
    /// Restarts that continued from a checkpoint.
    pub resumed: bool,
    /// The session's first IMU sample (ns): aid messages stamped before it are not used.
    first_imu_ns: Option<u64>,
}

impl Session {
    pub fn new(cfg: &SessionConfig) -> Session {
        Session {
            smoothing: Smoothing::Off,
            cfg: cfg.navigation.clone(),
            configured_initial: cfg.initial.clone(),
            nav: None,
            initial: None,
            aid_delay_ns: (cfg.aid_delay_s.clamp(0.0, 1.0) * 1e9).round() as u64,
            dvl_retime_ns: (-crate::navigator::dvl_retime_s(&cfg.navigation) * 1e9).round() as u64,
            pending: std::collections::BinaryHeap::new(),
            last_imu_ns: 0,
            before_start: 0,
            late_aids: 0,
            late_sequence: 0,
            alignment: cfg.alignment.clone(),
            aligner: None,
            last_omega: Vector3::zeros(),
            last_velocity_body: None,
            aligning_epochs: 0,
            aligned: cfg.alignment.is_none(),
            align_sequence: 0,
            fine: None,
            fine_hands_over: true,
            fine_start_ns: 0,
            align_magnetometer: match (&cfg.alignment, &cfg.navigation.magnetometer) {
                (Some(a), Some(m)) if a.heading_source == HeadingSource::Magnetometer => {
                    Some(MagnetometerAid::new(m))
                }
                _ => None,
            },
            mag_sum_b0: Vector3::zeros(),
            mag_count: 0,
            last_sound: None,
            reinitialisations: 0,
            resume: None,
            resumed: false,
            first_imu_ns: None,
        }
    }

    /// Continues, at the first IMU sample, from `checkpoint` instead of the configured start: the
    /// state coasts over the time since it was written plus `elapsed_s` (the wall-clock time the
    /// process was down, measured by the caller), and the position and velocity variances grow
    /// as if the vehicle had drifted at `drift_m_s` (one sigma) for that long.
    pub fn resume_from(&mut self, checkpoint: Checkpoint, elapsed_s: f64, drift_m_s: f64) {
        self.resume = Some((checkpoint, elapsed_s.max(0.0), drift_m_s.max(0.0)));
    }

    /// Hands over to `next`, the session of a daemon process that started after this one (a
    /// replay of a recording that spans a restart): the smoother's record and the counters
    /// carry over; the rest is `next`'s.
    pub fn hand_over(&mut self, mut next: Session) {
        next.smoothing = std::mem::replace(&mut self.smoothing, Smoothing::Off);
        next.before_start += self.before_start;
        next.late_aids += self.late_aids;
        next.reinitialisations += self.reinitialisations;
        *self = next;
    }

    /// Makes the navigator's covariance not finite, as a numerical failure would: for tests of
    /// what follows (the next IMU sample finds it and reinitialises).
    #[doc(hidden)]
    pub fn poison_covariance_for_tests(&mut self) {
        if let Some(nav) = self.nav.as_mut() {
            nav.poison_covariance_for_tests();
        }
    }

    /// The navigator's checkpoint (`None` before navigation starts or while aligning).
    pub fn checkpoint(&self) -> Option<Checkpoint> {
        self.nav
            .as_ref()
            .filter(|_| self.aligned)
            .map(Navigator::checkpoint)
    }

    /// The coarse attitude with its heading replaced by the magnetic one: the mean calibrated
    /// field, rotated to NED with the aligner's attitude, must point at the declination; the
    /// attitude (and the distance moved) turn about the vertical by the difference. `None`
    /// without readings or a local field.
    fn magnetic_heading_correction(
        &mut self,
        c_b_n: &Matrix3<f64>,
        c_b_b0: &Matrix3<f64>,
        lat: f64,
        lon: f64,
    ) -> Option<Matrix3<f64>> {
        let aid = self.align_magnetometer.as_mut()?;
        if self.mag_count == 0 {
            return None;
        }
        let (declination, _) = aid.local_field(lat, lon)?;
        let mean_body = c_b_b0.transpose() * (self.mag_sum_b0 / self.mag_count as f64);
        let m = c_b_n * mean_body;
        if m.x.hypot(m.y) < 1e-6 * m.norm() {
            return None;
        }
        let delta = crate::earth::wrap_pi(m.y.atan2(m.x) - declination);
        Some(*Rotation3::from_axis_angle(&Vector3::z_axis(), -delta).matrix())
    }

    /// Starts the fine-alignment filter of `model` from `state` (the attitude found elsewhere),
    /// without a hand-over to the navigator: the alignment studies run the filter this way over
    /// the same feed path as the daemon, and read it with [`Session::fine_aligner`].
    pub fn start_fine_alignment(
        &mut self,
        model: ErrorModel,
        cfg: FineAlignConfig,
        state: NavState,
    ) {
        self.fine_start_ns = (state.time_s * 1e9).round() as u64;
        self.fine = Some(FineAligner::new(model, cfg, state));
        self.fine_hands_over = false;
        self.aligned = false;
    }

    /// The fine-alignment filter while it runs.
    pub fn fine_aligner(&self) -> Option<&FineAligner> {
        self.fine.as_ref()
    }

    /// True while the attitude is being found (coarse or fine stage).
    pub fn aligning(&self) -> bool {
        !self.aligned
    }

    /// Aid messages queued and not yet applied.
    pub fn pending_aids(&self) -> usize {
        self.pending.len()
    }

    pub fn navigator(&self) -> Option<&Navigator> {
        self.nav.as_ref()
    }

    pub fn initial(&self) -> Option<&InitialReport> {
        self.initial.as_ref()
    }

    /// The configuration gives the initial state (otherwise the caller starts the session).
    pub fn has_configured_initial(&self) -> bool {
        self.configured_initial.is_some()
    }

    /// The configuration asks for an initial alignment (no `[initial]`).
    pub fn has_alignment(&self) -> bool {
        self.configured_initial.is_none() && self.alignment.is_some()
    }

    pub fn started(&self) -> bool {
        self.nav.is_some()
    }

    /// Starts navigating from `state`; the initial solution goes to `out`.
    pub fn start<E>(
        &mut self,
        state: NavState,
        source: &'static str,
        out: &mut dyn FnMut(SessionOutput) -> Result<(), E>,
    ) -> Result<(), E> {
        self.with_outputs(out, |s, out| s.start_navigator(state, source, out))
    }

    /// Records, from now on, what a smoother's backward pass needs (the first run of
    /// `crate::smoother`); [`Session::finish_recording`] hands it over.
    pub fn record_for_smoothing(&mut self, log: SmootherLog) {
        self.smoothing = Smoothing::Record {
            log: Box::new(log),
            chains: Vec::new(),
        };
        self.begin_smoothing_chain();
    }

    /// Ends the recording started by [`Session::record_for_smoothing`]: the log with each chain's
    /// nominal parameters. `None` when the session was not recording.
    pub fn finish_recording(&mut self) -> Option<SmoothingRun> {
        self.drain_trace();
        let Smoothing::Record { mut log, chains } =
            std::mem::replace(&mut self.smoothing, Smoothing::Off)
        else {
            return None;
        };
        let mut chains = chains;
        if let Some(nav) = self.nav.as_ref()
            && let Some(last) = chains.last_mut()
        {
            log.end_chain(nav.covariance());
            last.1 = Some(nav.nominal_parameters());
        }
        Some(SmoothingRun {
            log: *log,
            chains: chains
                .into_iter()
                .map(|(start, end)| (start, end.unwrap_or(start)))
                .collect(),
        })
    }

    /// A new navigator took over (start, restart, resume): a new chain of the smoother's
    /// record begins with its state.
    fn begin_smoothing_chain(&mut self) {
        let Smoothing::Record { log, chains } = &mut self.smoothing else {
            return;
        };
        let Some(nav) = self.nav.as_mut() else {
            return;
        };
        nav.start_trace();
        if let Some(last) = chains.last_mut()
            && last.1.is_none()
        {
            // The previous navigator was replaced without an end (a restart after it failed):
            // its start values stand for its end.
            last.1 = Some(last.0);
        }
        log.begin_chain(nav.state_time_ns(), nav.covariance());
        chains.push((nav.nominal_parameters(), None));
    }

    /// Moves the navigator's trace events into the smoother's record.
    fn drain_trace(&mut self) {
        if let (Smoothing::Record { log, .. }, Some(nav)) = (&mut self.smoothing, self.nav.as_mut())
        {
            log.take(nav.take_trace());
        }
    }

    /// Runs `f` with `out` and moves the trace into the smoother's record afterwards.
    fn with_outputs<E>(
        &mut self,
        out: &mut dyn FnMut(SessionOutput) -> Result<(), E>,
        f: impl FnOnce(&mut Self, &mut dyn FnMut(SessionOutput) -> Result<(), E>) -> Result<(), E>,
    ) -> Result<(), E> {
        let r = f(self, out);
        self.drain_trace();
        r
    }

    fn start_navigator<E>(
        &mut self,
        state: NavState,
        source: &'static str,
        out: &mut dyn FnMut(SessionOutput) -> Result<(), E>,
    ) -> Result<(), E> {
        let e = state.euler();
        self.initial = Some(InitialReport {
            source,
            time_s: state.time_s,
            latitude_deg: state.position.latitude_rad.to_degrees(),
            longitude_deg: state.position.longitude_rad.to_degrees(),
            height_m: state.position.height_m,
            velocity_ned_m_s: state.velocity_ned.into(),
            euler_deg: e.map(f64::to_degrees),
        });
        let mut nav = Navigator::new(self.cfg.clone(), state);
        let t_ns = (state.time_s * 1e9).round() as u64;
        let sol = nav.solution(t_ns);
        out(SessionOutput::Solution(&sol))?;
        self.nav = Some(nav);
        self.begin_smoothing_chain();
        Ok(())
    }

    /// An IMU sample. Aid messages due before it are applied first. With a configured initial
    /// state, the first sample starts the session at its time (and is not integrated: there is
    /// no interval before it).
    fn on_imu<E>(
        &mut self,
        x: &ImuSampleV1,
        out: &mut dyn FnMut(SessionOutput) -> Result<(), E>,
    ) -> Result<(), E> {
        if self.first_imu_ns.is_none() {
            self.start_at(x, out)?;
        }
        while let Some(p) = self.pending.peek() {
            if aid_key(&p.0).0.saturating_add(self.aid_delay_ns) >= x.host_time_ns {
                break;
            }
            let Some(Pending(aid, late)) = self.pending.pop() else {
                break;
            };
            if late {
                self.late_sequence += 1;
                let (aid_host_time_ns, aid_topic, aid_sequence) = aid_key(&aid);
                let record = LateAidV1 {
                    host_time_ns: x.host_time_ns,
                    sequence: self.late_sequence,
                    imu_sequence: x.sequence,
                    aid_host_time_ns,
                    aid_sequence,
                    aid_topic,
                    reserved: 0,
                };
                out(SessionOutput::LateAid(&record))?;
            }
            self.apply(aid, out)?;
        }
        self.last_imu_ns = self.last_imu_ns.max(x.host_time_ns);
        if self.nav.is_none()
            && let Some((cp, elapsed_s, drift_m_s)) = self.resume.take()
            && let Some(mut nav) = Navigator::from_checkpoint(self.cfg.clone(), &cp)
        {
            // A restart, before any alignment the mission began with: the checkpoint's state,
            // coasted to this sample over the time the process was down, with what the vehicle
            // may have done meanwhile in the covariance.
            nav.coast(elapsed_s, x);
            let drift = drift_m_s * elapsed_s;
            nav.grow_variances(drift * drift, drift_m_s * drift_m_s);
            self.initial = Some(InitialReport {
                source: "checkpoint of the previous run",
                time_s: x.host_time_ns as f64 * 1e-9,
                latitude_deg: cp.latitude_rad.to_degrees(),
                longitude_deg: cp.longitude_rad.to_degrees(),
                height_m: cp.height_m,
                velocity_ned_m_s: cp.velocity_ned_m_s,
                euler_deg: nav.state().euler().map(f64::to_degrees),
            });
            self.aligned = true;
            self.fine = None;
            self.aligner = None;
            self.resumed = true;
            let sol = nav.solution(x.host_time_ns);
            self.nav = Some(nav);
            self.begin_smoothing_chain();
            return out(SessionOutput::Solution(&sol));
        }
        if self.nav.is_none() && self.fine.is_some() {
            return self.fine_step(x, out);
        }
        if self.nav.is_none() && self.configured_initial.is_none() && self.alignment.is_some() {
            return self.coarse(x, out);
        }
        if self.nav.is_none()
            && let Some(i) = self.configured_initial.clone()
        {
            let state = i.state(x.host_time_ns as f64 * 1e-9);
            self.start_navigator(state, "[initial] table of the configuration", out)?;
            if let Some(nav) = self.nav.as_mut() {
                nav.start_at_imu(x);
            }
            return Ok(());
        }
        let Some(nav) = self.nav.as_mut() else {
            self.before_start += 1;
            return Ok(());
        };
        if let Some(mut sol) = nav.on_imu(x) {
            if !nav.still_sound(&sol) {
                return self.reinitialise(x, out);
            }
            if self.aligned
                && self
                    .last_sound
                    .as_ref()
                    .is_none_or(|s| nav.state().time_s - s.state().time_s >= 1.0)
                && nav.is_sound()
            {
                self.last_sound = Some(nav.clone());
            }
            if !self.aligned {
                // Fine alignment until the heading meets the convergence criterion.
                let criterion = self
                    .alignment
                    .as_ref()
                    .map_or(0.0, |a| a.aligned_heading_std_deg.to_radians());
                if sol.attitude_std_rad[2] < criterion {
                    self.aligned = true;
                } else {
                    sol.mode = NavMode::Aligning as u32;
                }
            }
            out(SessionOutput::Solution(&sol))?;
        }
        Ok(())
    }

    /// The filter's state or covariance is not sound (not finite, not a covariance): it restarts
    /// from the last sound navigator, coasted to this sample with its covariance grown over the
    /// time since, and this sample's solution is published as invalid. Without a sound navigator
    /// yet, the session starts over as at the beginning.
    fn reinitialise<E>(
        &mut self,
        x: &ImuSampleV1,
        out: &mut dyn FnMut(SessionOutput) -> Result<(), E>,
    ) -> Result<(), E> {
        self.reinitialisations += 1;
        let broken = self.nav.take();
        let Some(mut nav) = self.last_sound.clone() else {
            // Nothing sound to go back to (the first solution was not): align or start again
            // from the configuration, with the position flagged unknown.
            self.cfg.initial_position_std_m = 10.0 * self.cfg.position_unknown_std_m;
            self.aligned = self.alignment.is_none() || self.configured_initial.is_some();
            self.aligner = None;
            self.fine = None;
            return Ok(());
        };
        if let Some(b) = &broken {
            // Its last solution (the one found unsound) was not published.
            nav.continue_numbering(b.last_sequence().saturating_sub(1));
        }
        let dt = x.host_time_ns as f64 * 1e-9 - nav.state().time_s;
        nav.coast(dt, x);
        let mut sol = nav.solution(x.host_time_ns);
        sol.mode = NavMode::Invalid as u32;
        self.nav = Some(nav);
        self.begin_smoothing_chain();
        out(SessionOutput::Solution(&sol))
    }

    /// Rate and specific force of a sample (increments divided by the interval), or `None` for a
    /// sample the alignment cannot use (flagged invalid, bad interval, not finite or beyond the
    /// configured plausible range).
    fn usable_rates(&self, x: &ImuSampleV1) -> Option<(Vector3<f64>, Vector3<f64>)> {
        crate::nav_core::plausible_rates(
            x,
            self.cfg.imu_max_rate_deg_s.to_radians(),
            self.cfg.imu_max_specific_force_m_s2,
        )
    }

    /// The coarse stage: feeds the aligner; at the end hands over to the navigation filter.
    fn coarse<E>(
        &mut self,
        x: &ImuSampleV1,
        out: &mut dyn FnMut(SessionOutput) -> Result<(), E>,
    ) -> Result<(), E> {
        let Some(a) = self.alignment.clone() else {
            return Ok(());
        };
        let Some((w, f)) = self.usable_rates(x) else {
            self.before_start += 1;
            return Ok(());
        };
        let t = x.host_time_ns as f64 * 1e-9;
        // The aligner runs on the IMU's own time, its intervals from the first sample on: the
        // Earth turns between its epochs by what the gyros saw, also where the host clock runs
        // otherwise (a log played faster than real time turned 8x less Earth rate in host time
        // and the coarse stage never ended).
        let clock = self
            .aligner
            .as_ref()
            .map_or(t, |al| al.time_s() + x.interval_s);
        let aligner = self
            .aligner
            .get_or_insert_with(|| InMotionAligner::new(a.latitude_deg.to_radians(), a.height_m));
        aligner.on_imu(clock, &w, &f, x.interval_s);
        self.last_omega = w;
        if a.moored {
            aligner.on_velocity(None);
        } else if let Some(v) = self.last_velocity_body {
            aligner.on_velocity(Some(v));
        }
        let elapsed = aligner.elapsed_s();
        let epochs = aligner.epochs();
        let due = elapsed >= a.coarse_s;
        // Solve at the hand-over and once per new epoch (1 Hz) for the aligning solution.
        if !due && epochs <= self.aligning_epochs {
            return Ok(());
        }
        let Some((c_b_n, moved)) = aligner.solve_with_displacement() else {
            return Ok(());
        };
        let c_b_b0 = *aligner.body_to_start();
        let (c_b_n, moved) = match self.magnetic_heading_correction(
            &c_b_n,
            &c_b_b0,
            a.latitude_deg.to_radians(),
            a.longitude_deg.to_radians(),
        ) {
            Some(turn) => (turn * c_b_n, turn * moved),
            None if self.align_magnetometer.is_some() => {
                // No magnetic heading yet: keep aligning (the hand-over waits for one).
                if due {
                    self.before_start += 1;
                }
                return Ok(());
            }
            None => (c_b_n, moved),
        };
        let start = Geodetic {
            latitude_rad: a.latitude_deg.to_radians(),
            longitude_rad: a.longitude_deg.to_radians(),
            height_m: a.height_m,
        };
        // The vehicle moved while aligning: dead reckoning with the found attitude.
        let position = crate::earth::offset_position(&start, &moved);
        let v_b = if a.moored {
            Vector3::zeros()
        } else {
            self.last_velocity_body.unwrap_or_else(Vector3::zeros)
        };
        let state = NavState {
            time_s: t,
            position,
            velocity_ned: c_b_n * v_b,
            q_body_to_ned: UnitQuaternion::from_matrix(&c_b_n),
        };
        // The dead-reckoned displacement turns with the found heading: its error grows with
        // the distance made good and goes into the position uncertainty handed on (with the
        // configured one alone, a 5 deg coarse heading after 90 m left 7 m of error under a
        // reported 1.7 m).
        let dr_std = a.coarse_heading_std_deg.to_radians() * moved.xy().norm();
        let position_std_m = self.cfg.initial_position_std_m.hypot(dr_std);
        if due && let Some(model) = ErrorModel::from_number(a.fine_model) {
            // Coarse → fine: the alignment filter of the chosen error model.
            let cfg = FineAlignConfig {
                dvl_std_m_s: self.cfg.dvl_velocity_std_m_s,
                gyro_arw_deg_sqrt_h: self.cfg.gyro_angle_random_walk_deg_sqrt_h,
                accel_vrw_m_s_sqrt_h: self.cfg.accel_velocity_random_walk_m_s_sqrt_h,
                initial_tilt_std_deg: a.coarse_tilt_std_deg,
                initial_heading_std_deg: a.coarse_heading_std_deg,
                initial_velocity_std_m_s: self.cfg.initial_velocity_std_m_s,
                initial_position_std_m: position_std_m,
                initial_gyro_bias_std_deg_h: self.cfg.initial_gyro_bias_std_deg_h,
                initial_accel_bias_std_ug: self.cfg.initial_accel_bias_std_ug,
                initial_mounting_std_deg: self.cfg.initial_dvl_mounting_std_deg,
                covariance_interval_s: self.cfg.covariance_interval_s,
            };
            self.fine = Some(FineAligner::new(model, cfg, state));
            self.aligner = None;
            return Ok(());
        }
        if due {
            // Hand over: the filter starts from the coarse attitude with its uncertainty.
            let mut cfg = self.cfg.clone();
            cfg.initial_heading_std_deg = a.coarse_heading_std_deg;
            cfg.initial_tilt_std_deg = a.coarse_tilt_std_deg;
            cfg.initial_position_std_m = position_std_m;
            let saved = std::mem::replace(&mut self.cfg, cfg);
            let r = self.start_navigator(state, "in-motion coarse alignment", &mut |o| match o {
                SessionOutput::Solution(s) => {
                    let mut s = *s;
                    s.mode = NavMode::Aligning as u32;
                    out(SessionOutput::Solution(&s))
                }
                other => out(other),
            });
            self.cfg = saved;
            r?;
            if let Some(nav) = self.nav.as_mut() {
                nav.start_at_imu(x);
            }
            self.aligner = None;
            return Ok(());
        }
        {
            // One aligning solution per new epoch (1 Hz): the attitude and position so far.
            self.aligning_epochs = epochs;
            self.align_sequence += 1;
            let e = state.euler();
            let sol = NavSolutionV1 {
                host_time_ns: x.host_time_ns,
                sequence: self.align_sequence,
                latitude_rad: position.latitude_rad,
                longitude_rad: position.longitude_rad,
                height_m: position.height_m,
                velocity_ned_m_s: state.velocity_ned.into(),
                quaternion_body_to_ned: {
                    let q = state.q_body_to_ned;
                    [q.w, q.i, q.j, q.k]
                },
                euler_rad: e,
                mode: NavMode::Aligning as u32,
                sensor_health: NavSolutionV1::HEALTH_IMU,
                ..Default::default()
            };
            out(SessionOutput::Solution(&sol))?;
        }
        Ok(())
    }

    /// The fine stage: the alignment filter runs until its heading σ meets the criterion, then the
    /// navigation filter starts from its state.
    fn fine_step<E>(
        &mut self,
        x: &ImuSampleV1,
        out: &mut dyn FnMut(SessionOutput) -> Result<(), E>,
    ) -> Result<(), E> {
        let criterion = self
            .alignment
            .as_ref()
            .filter(|_| self.fine_hands_over)
            .map(|a| a.aligned_heading_std_deg.to_radians());
        if self.fine.is_none() || x.host_time_ns <= self.fine_start_ns {
            // At or before the start state: nothing to integrate.
            return Ok(());
        }
        let Some((w, f)) = self.usable_rates(x) else {
            self.before_start += 1;
            return Ok(());
        };
        let Some(fine) = self.fine.as_mut() else {
            return Ok(());
        };
        fine.on_imu(&w, &f, x.interval_s);
        self.last_omega = w;
        let mut state = *fine.state();
        state.time_s = x.host_time_ns as f64 * 1e-9;
        let [att, vel, pos, gyro, accel] = fine.std_devs();
        if criterion.is_some_and(|c| fine.heading_std() < c) {
            // Hand over to the navigation filter with the alignment filter's estimates.
            let deg = 180.0 / std::f64::consts::PI;
            let mut cfg = self.cfg.clone();
            cfg.initial_tilt_std_deg = att.x.max(att.y) * deg;
            cfg.initial_heading_std_deg = att.z * deg;
            cfg.initial_velocity_std_m_s = vel.max();
            cfg.initial_position_std_m = pos.x.max(pos.y);
            cfg.initial_gyro_bias_std_deg_h = gyro.max() * deg * 3600.0;
            cfg.initial_accel_bias_std_ug = accel.max() / 9.806_65e-6;
            if let (true, Some(m_std)) = (fine.model != ErrorModel::Navigation, fine.mounting_std())
            {
                // The mounting estimate goes on with its uncertainty: the navigation filter keeps
                // estimating it. Handed over as exact, an angle the alignment could not observe
                // (pitch, without depth) turned the DVL's velocity and pulled the vertical
                // channel away from the depth sensor, whose fixes the gate then refused.
                let m = fine.mounting();
                let mut d = cfg.dvl_installation();
                d.mount_deg = [m.x * deg, m.y * deg, m.z * deg];
                cfg.set_dvl_installation(d);
                cfg.estimate_dvl_mounting = true;
                cfg.initial_dvl_mounting_std_deg = m_std.max() * deg;
            }
            let (bg, ba) = fine.imu_biases();
            self.fine = None;
            self.aligned = true;
            let saved = std::mem::replace(&mut self.cfg, cfg);
            let r = self.start_navigator(state, "in-motion alignment (coarse, then fine)", out);
            self.cfg = saved;
            r?;
            if let Some(nav) = self.nav.as_mut() {
                nav.set_imu_biases(bg, ba);
                nav.start_at_imu(x);
            }
            return Ok(());
        }
        self.align_sequence += 1;
        let q = state.q_body_to_ned;
        let sol = NavSolutionV1 {
            host_time_ns: x.host_time_ns,
            sequence: self.align_sequence,
            latitude_rad: state.position.latitude_rad,
            longitude_rad: state.position.longitude_rad,
            height_m: state.position.height_m,
            velocity_ned_m_s: state.velocity_ned.into(),
            quaternion_body_to_ned: [q.w, q.i, q.j, q.k],
            euler_rad: state.euler(),
            position_std_ned_m: pos.into(),
            attitude_std_rad: att.into(),
            mode: NavMode::Aligning as u32,
            sensor_health: NavSolutionV1::HEALTH_IMU,
            ..Default::default()
        };
        out(SessionOutput::Solution(&sol))
    }

    /// The DVL velocity in body axes during coarse alignment: mounting, scale and lever arm of
    /// the configuration applied.
    fn dvl_body_velocity(&self, m: &DvlVelocityV1) -> Option<Vector3<f64>> {
        if m.validity & DvlVelocityV1::VALID_VELOCITY == 0 {
            return None;
        }
        let ratio = sound_speed_correction(&self.cfg).map_or(1.0, |c| c.ratio(m));
        let v = Vector3::from(m.velocity_dvl_m_s) * ratio;
        if !v.iter().all(|x| x.is_finite()) {
            return None;
        }
        let d = self.cfg.dvl_installation();
        let [r, p, y] = d.mount_deg.map(f64::to_radians);
        let c: Matrix3<f64> = Rotation3::from_euler_angles(r, p, y).into_inner();
        let scale = if d.scale_factor > 0.0 {
            d.scale_factor
        } else {
            1.0
        };
        let lever = Vector3::from(d.lever_arm_m);
        Some(c * v / scale - self.last_omega.cross(&lever))
    }

    fn apply<E>(
        &mut self,
        aid: SensorMessage,
        out: &mut dyn FnMut(SessionOutput) -> Result<(), E>,
    ) -> Result<(), E> {
        if self.nav.is_none()
            && let Some(fine) = self.fine.as_mut()
            && let SensorMessage::Dvl(m) = aid
        {
            // Alignment takes the velocity over the ground: bottom track only.
            if m.validity & DvlVelocityV1::VALID_VELOCITY != 0
                && !m.is_water_track()
                && m.host_time_ns > self.fine_start_ns
            {
                let ratio = sound_speed_correction(&self.cfg).map_or(1.0, |c| c.ratio(&m));
                let v = Vector3::from(m.velocity_dvl_m_s) * ratio;
                if v.iter().all(|x| x.is_finite()) {
                    fine.on_dvl(&v);
                }
            }
            return Ok(());
        }
        if self.nav.is_none()
            && let Some(aligner) = self.aligner.as_ref()
            && let Some(mag) = self.align_magnetometer.as_ref()
            && let SensorMessage::Magnetometer(m) = aid
        {
            // Coarse alignment sums the calibrated field in start-body axes.
            if let Some(b) = mag.calibrated(&m) {
                self.mag_sum_b0 += aligner.body_to_start() * b;
                self.mag_count += 1;
            }
            return Ok(());
        }
        if self.nav.is_none()
            && self.aligner.is_some()
            && let SensorMessage::Dvl(m) = aid
        {
            // Coarse alignment takes the DVL's velocity over the ground at the next IMU sample.
            if !m.is_water_track() {
                self.last_velocity_body = self.dvl_body_velocity(&m);
            }
            return Ok(());
        }
        let Some(nav) = self.nav.as_mut() else {
            self.before_start += 1;
            return Ok(());
        };
        let d = match aid {
            SensorMessage::Dvl(m) => nav.on_dvl(&m),
            SensorMessage::Depth(m) => nav.on_depth(&m),
            SensorMessage::Gnss(m) => nav.on_gnss(&m),
            SensorMessage::Usbl(m) => match nav.on_usbl_as_ranges(&m) {
                // The range aid configured as the docking station: one diagnostics per part.
                Some(parts) => {
                    for d in parts.iter().flatten() {
                        out(SessionOutput::Diagnostics(d))?;
                    }
                    return Ok(());
                }
                None => nav.on_usbl(&m),
            },
            SensorMessage::Magnetometer(m) => match nav.on_magnetometer(&m) {
                Some(d) => d,
                // Without [navigation.magnetometer] the readings are counted, not reported.
                None => return Ok(()),
            },
            // Not an aid: it sets the DVL's sound-speed correction.
            SensorMessage::SoundVelocity(m) => {
                nav.on_sound_velocity(&m);
                return Ok(());
            }
            // Not an aid: where a moving acoustic array is.
            SensorMessage::AcousticArrayPose(m) => {
                nav.on_acoustic_array_pose(&m);
                return Ok(());
            }
            // One diagnostics per receiver's range.
            SensorMessage::AcousticRanges(m) => {
                for d in nav.on_acoustic_ranges(&m).iter().flatten() {
                    out(SessionOutput::Diagnostics(d))?;
                }
                return Ok(());
            }
            // Not an aid (the feed never queues IMU samples).
            SensorMessage::Imu(_) => return Ok(()),
        };
        out(SessionOutput::Diagnostics(&d))
    }

    /// Applies the aid messages still queued (at the end of a log, or when the daemon stops).
    pub fn finish<E>(
        &mut self,
        out: &mut dyn FnMut(SessionOutput) -> Result<(), E>,
    ) -> Result<(), E> {
        self.with_outputs(out, |s, out| {
            while let Some(Pending(aid, _)) = s.pending.pop() {
                s.apply(aid, out)?;
            }
            Ok(())
        })
    }

    /// Feeds one sensor message. IMU samples are processed at once (after the aid messages due
    /// before them); aid messages wait for their turn. Outputs go to `out`.
    pub fn feed<E>(
        &mut self,
        m: &SensorMessage,
        out: &mut dyn FnMut(SessionOutput) -> Result<(), E>,
    ) -> Result<(), E> {
        match m {
            SensorMessage::Imu(x) => self.with_outputs(out, |s, out| s.on_imu(x, out)),
            aid => {
                self.queue(*aid);
                Ok(())
            }
        }
    }

    /// The session's first IMU sample: says how it starts ([`SessionOutput::Started`]) and drops
    /// the aid messages stamped before it. A daemon that starts (or restarts) mid-stream sees
    /// only the aids published after it subscribed, a replay every aid of the recording: from the
    /// session's first sample on, both use the same ones.
    fn start_at<E>(
        &mut self,
        x: &ImuSampleV1,
        out: &mut dyn FnMut(SessionOutput) -> Result<(), E>,
    ) -> Result<(), E> {
        self.first_imu_ns = Some(x.host_time_ns);
        let pending = std::mem::take(&mut self.pending);
        let total = pending.len();
        let retime_ns = self.dvl_retime_ns;
        self.pending = pending
            .into_iter()
            .filter(|p| stamped_ns(&p.0, retime_ns) >= x.host_time_ns)
            .collect();
        self.before_start += (total - self.pending.len()) as u64;
        let mut event = SessionEventV1 {
            host_time_ns: x.host_time_ns,
            kind: SessionEventV1::KIND_STARTED,
            initial_position_std_m: self.cfg.initial_position_std_m,
            ..Default::default()
        };
        if let Some((cp, elapsed_s, drift_m_s)) = &self.resume {
            event.kind = SessionEventV1::KIND_CONTINUED;
            event.checkpoint_time_ns = (cp.time_s * 1e9).round() as u64;
            event.elapsed_s = *elapsed_s;
            event.drift_m_s = *drift_m_s;
        }
        out(SessionOutput::Started(&event))
    }

    /// Queues an aid message (applied before the first IMU sample stamped after its time + the
    /// aid delay); counted as late when the IMU has already passed that point. One stamped
    /// before the session's first IMU sample is not used (counted before the start).
    fn queue(&mut self, aid: SensorMessage) {
        let aid = match aid {
            SensorMessage::Dvl(mut m) if self.dvl_retime_ns > 0 => {
                m.host_time_ns = m.host_time_ns.saturating_add(self.dvl_retime_ns);
                m.validity_time_ns = m.validity_time_ns.saturating_add(self.dvl_retime_ns);
                SensorMessage::Dvl(m)
            }
            other => other,
        };
        if self
            .first_imu_ns
            .is_some_and(|t| stamped_ns(&aid, self.dvl_retime_ns) < t)
        {
            self.before_start += 1;
            return;
        }
        let late = aid_key(&aid).0.saturating_add(self.aid_delay_ns) < self.last_imu_ns;
        if late {
            self.late_aids += 1;
        }
        self.pending.push(Pending(aid, late));
    }
}
