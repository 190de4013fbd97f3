//! A recording that spans a restart of the daemon: the daemon records where each of its sessions
//! started (its first IMU sample, and for a restart the checkpoint it continued from) and each
//! checkpoint it took ([`SessionEventV1`]). The replay takes the same checkpoints of its own
//! session, and at each recorded start hands over to a new session started the way the daemon's
//! was, so that it reproduces the live solution before and after the restart.

use auvnav_core::navigator::Checkpoint;
use auvnav_core::session::{Session, SessionConfig};
use auvnav_shm_schema::SessionEventV1;
use serde::Serialize;
use std::collections::{BTreeSet, VecDeque};

/// Checkpoints kept for a later restart: a restart continues from one of the last few.
const CHECKPOINTS_KEPT: usize = 16;

/// What a replay found of the daemon's session starts.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize)]
pub struct RestartCounts {
    /// Session starts the recording holds (one per daemon process that navigated).
    pub session_starts: u64,
    /// Of them, restarts that continued from a checkpoint.
    pub continued: u64,
    /// Continued starts whose checkpoint the replay had not taken (the recording began after it,
    /// or lost its record): the replay started that session from the configuration instead, and
    /// differs from the live solution from there.
    pub checkpoint_missing: u64,
}

/// The recorded session events not yet reached, and the replay's own checkpoints.
#[derive(Debug, Default)]
pub struct Restarts {
    /// Host times of the IMU samples after which the daemon took a checkpoint.
    checkpoint_at: BTreeSet<u64>,
    /// The replay's checkpoints taken there, with the time of their last IMU sample.
    checkpoints: VecDeque<(u64, Checkpoint)>,
    /// Recorded starts not yet reached, in the order recorded.
    starts: VecDeque<SessionEventV1>,
    pub counts: RestartCounts,
}

impl Restarts {
    /// Takes in a recorded session event.
    pub fn record(&mut self, e: &SessionEventV1) {
        match e.kind {
            SessionEventV1::KIND_CHECKPOINT => {
                self.checkpoint_at.insert(e.host_time_ns);
            }
            SessionEventV1::KIND_STARTED | SessionEventV1::KIND_CONTINUED => {
                self.starts.push_back(*e);
            }
            _ => {}
        }
    }

    /// Before the IMU sample stamped `t_ns` is fed: hands `session` over to a new one when a
    /// daemon started its session at this sample.
    #[inline]
    pub fn before_imu(&mut self, t_ns: u64, session: &mut Session, cfg: &SessionConfig) {
        // Starts the replay has passed without meeting their sample (it was lost) are dropped.
        while self.starts.front().is_some_and(|e| e.host_time_ns < t_ns) {
            self.starts.pop_front();
        }
        if let Some(e) = self.starts.front().filter(|e| e.host_time_ns == t_ns) {
            let e = *e;
            self.starts.pop_front();
            self.start_session(&e, session, cfg);
        }
    }

    /// Hands `session` over to one started as the recorded start `e` says. Out of line: a new
    /// session is built on the stack (tens of kilobytes), which would otherwise make every IMU
    /// sample's call probe that much stack.
    #[cold]
    #[inline(never)]
    fn start_session(&mut self, e: &SessionEventV1, session: &mut Session, cfg: &SessionConfig) {
        self.counts.session_starts += 1;
        let mut cfg = cfg.clone();
        cfg.navigation.initial_position_std_m = e.initial_position_std_m;
        let mut next = Session::new(&cfg);
        if e.kind == SessionEventV1::KIND_CONTINUED {
            self.counts.continued += 1;
            match self
                .checkpoints
                .iter()
                .rev()
                .find(|(t, _)| *t == e.checkpoint_time_ns)
            {
                Some((_, cp)) => next.resume_from(cp.clone(), e.elapsed_s, e.drift_m_s),
                None => self.counts.checkpoint_missing += 1,
            }
        }
        session.hand_over(next);
    }

    /// After the IMU sample stamped `t_ns` was fed: takes the session's checkpoint when the
    /// daemon took one there.
    #[inline]
    pub fn after_imu(&mut self, t_ns: u64, session: &Session) {
        if self.checkpoint_at.first().is_some_and(|&t| t <= t_ns) {
            self.take_checkpoint(t_ns, session);
        }
    }

    /// Takes the session's checkpoint if the daemon took one at `t_ns` (out of line, as
    /// [`Restarts::start_session`]).
    #[cold]
    #[inline(never)]
    fn take_checkpoint(&mut self, t_ns: u64, session: &Session) {
        // Checkpoints at samples the replay has passed cannot be taken any more.
        let take = self.checkpoint_at.remove(&t_ns);
        self.checkpoint_at = self.checkpoint_at.split_off(&(t_ns + 1));
        // Through JSON, as the daemon writes and reads its checkpoint file: the restarted
        // daemon continued from the values as read back.
        let as_read = |cp: Checkpoint| {
            serde_json::to_vec(&cp)
                .ok()
                .and_then(|b| serde_json::from_slice::<Checkpoint>(&b).ok())
        };
        if take && let Some(cp) = session.checkpoint().and_then(as_read) {
            if self.checkpoints.len() == CHECKPOINTS_KEPT {
                self.checkpoints.pop_front();
            }
            self.checkpoints.push_back((t_ns, cp));
        }
    }
}
