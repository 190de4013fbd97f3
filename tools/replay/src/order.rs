//! The order in which a replay hands a log's messages to the navigation session: by time stamp,
//! not by the log's write order.
//!
//! A recorder writes messages as they reach it; under a scheduling hiccup an aid message can be
//! written after IMU samples stamped later than its due point (time stamp + aid delay), although
//! the daemon had it in time. Fed in write order, the session would apply it later than the daemon
//! did. So the replay holds messages for a window of log time and releases them sorted: each aid
//! at its own time stamp (before IMU samples of the same stamp; an aid fed early waits in the
//! session's queue, so this is exactly the daemon's rule), IMU samples by time stamp and write
//! order, truth records after both. Messages that come more than the window behind the newest
//! stamp seen are released at once (the session then counts a late aid).
//!
//! When the daemon itself applied an aid late, it published a [`LateAidV1`] record naming the IMU
//! sample it applied the aid before. The record moves the held aid to just before that sample, so
//! the replay applies it where the daemon did. A record that finds no held aid (it came more than
//! the window after the aid) is counted as unmatched: the replay may then differ from the live
//! solution from that sample on.

use auvnav_log::LogMessage;
use auvnav_shm_schema::{ImuSampleV1, LateAidV1};
use std::collections::VecDeque;

/// How far behind the newest time stamp a message may be written and still be put in its place
/// (ns of log time).
pub const REORDER_WINDOW_NS: u64 = 2_000_000_000;

/// Where a message goes in the feed order: time stamp, class (aids, then IMU, then truth), then
/// the order of writing.
type Key = (u64, u8, u64);

const CLASS_AID: u8 = 0;
const CLASS_IMU: u8 = 1;
const CLASS_TRUTH: u8 = 2;

/// The feed-order key of a message the replay uses; `None` for the others.
fn key_of(m: &LogMessage, index: u64) -> Option<Key> {
    let (t, class) = match m {
        LogMessage::Imu(x) => (x.host_time_ns, CLASS_IMU),
        LogMessage::Truth(x) => (x.host_time_ns, CLASS_TRUTH),
        other => (other.sensor()?.host_time_ns(), CLASS_AID),
    };
    Some((t, class, index))
}

/// A message held in the window. IMU samples, nearly all of the stream, are held as they are
/// (88 bytes); the others (a few a second) in a box, so that a `LogMessage` (256 bytes) is not
/// copied in and out of the window for each sample.
#[derive(Debug, Clone)]
pub enum Held {
    Imu(ImuSampleV1),
    Other(Box<LogMessage>),
}

impl Held {
    fn new(m: &LogMessage) -> Held {
        match m {
            LogMessage::Imu(x) => Held::Imu(*x),
            other => Held::Other(Box::new(*other)),
        }
    }

    fn names(&self, r: &LateAidV1) -> bool {
        match self {
            Held::Imu(_) => false,
            Held::Other(m) => names(r, m),
        }
    }
}

/// Messages held for the window, sorted by [`Key`].
#[derive(Default)]
pub struct FeedOrder {
    held: VecDeque<(Key, Held)>,
    /// Late-aid records whose aid has not been written yet.
    waiting: Vec<LateAidV1>,
    written: u64,
    newest_ns: u64,
    /// Messages written after a message with a later time stamp (put in their place).
    pub out_of_order: u64,
    /// Messages written more than the window behind the newest time stamp (fed as they came).
    pub beyond_window: u64,
    /// Late-aid records that moved a held aid.
    pub late_records_applied: u64,
    /// Late-aid records that found no held aid to move.
    pub late_records_unmatched: u64,
}

impl FeedOrder {
    /// Takes a message the replay uses (`false`: not one of them, left to the caller).
    pub fn push(&mut self, m: &LogMessage) -> bool {
        let Some(key) = key_of(m, self.written) else {
            return false;
        };
        self.written += 1;
        if key.0 < self.newest_ns {
            self.out_of_order += 1;
            if key.0 + REORDER_WINDOW_NS < self.newest_ns {
                self.beyond_window += 1;
            }
        }
        self.newest_ns = self.newest_ns.max(key.0);
        let mut key = key;
        if key.1 == CLASS_AID
            && !self.waiting.is_empty()
            && let Some(i) = self.waiting.iter().position(|r| names(r, m))
        {
            let r = self.waiting.swap_remove(i);
            self.late_records_applied += 1;
            key.0 = key.0.max(r.host_time_ns);
        }
        self.insert(key, Held::new(m));
        // Records that met no aid within the window.
        let newest = self.newest_ns;
        let before = self.waiting.len();
        self.waiting
            .retain(|r| r.host_time_ns.saturating_add(2 * REORDER_WINDOW_NS) >= newest);
        self.late_records_unmatched += (before - self.waiting.len()) as u64;
        true
    }

    fn insert(&mut self, key: Key, m: Held) {
        // Nearly always at the end: search from the back.
        let mut i = self.held.len();
        while i > 0 && self.held[i - 1].0 > key {
            i -= 1;
        }
        if i == self.held.len() {
            self.held.push_back((key, m));
        } else {
            self.held.insert(i, (key, m));
        }
    }

    /// Moves the held aid a [`LateAidV1`] record names to just before the IMU sample it names.
    pub fn apply_late_record(&mut self, r: &LateAidV1) {
        let found = self
            .held
            .iter()
            .position(|(k, m)| k.1 == CLASS_AID && m.names(r));
        match found.and_then(|i| self.held.remove(i)) {
            Some(((t, class, index), m)) => {
                self.late_records_applied += 1;
                self.insert((r.host_time_ns.max(t), class, index), m);
            }
            // The aid may still come (the recorder can get it after the record).
            None => self.waiting.push(*r),
        }
    }

    /// The next message whose place is settled (the window has passed it).
    pub fn pop_ready(&mut self) -> Option<Held> {
        let (k, _) = self.held.front()?;
        if k.0.saturating_add(REORDER_WINDOW_NS) >= self.newest_ns {
            return None;
        }
        self.held.pop_front().map(|(_, m)| m)
    }

    /// The next held message, window or not (at the end of the input; records still waiting
    /// for their aid are then counted as unmatched).
    pub fn pop_any(&mut self) -> Option<Held> {
        self.late_records_unmatched += self.waiting.len() as u64;
        self.waiting.clear();
        self.held.pop_front().map(|(_, m)| m)
    }
}

/// Whether late-aid record `r` names message `m`.
fn names(r: &LateAidV1, m: &LogMessage) -> bool {
    m.sensor().is_some_and(|s| {
        s.aid_topic() == Some(r.aid_topic)
            && s.sequence() == r.aid_sequence
            && s.host_time_ns() == r.aid_host_time_ns
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use auvnav_shm_schema::{DvlVelocityV1, ImuSampleV1};

    fn imu(t: u64, seq: u64) -> LogMessage {
        LogMessage::Imu(ImuSampleV1 {
            host_time_ns: t,
            sequence: seq,
            ..Default::default()
        })
    }
    fn dvl(t: u64, seq: u64) -> LogMessage {
        LogMessage::Dvl(DvlVelocityV1 {
            host_time_ns: t,
            sequence: seq,
            ..Default::default()
        })
    }
    fn stamp(m: &Held) -> (u64, bool) {
        match m {
            Held::Imu(x) => (x.host_time_ns, true),
            Held::Other(m) => match **m {
                LogMessage::Dvl(x) => (x.host_time_ns, false),
                _ => (0, false),
            },
        }
    }
    fn drain(o: &mut FeedOrder) -> Vec<(u64, bool)> {
        std::iter::from_fn(|| o.pop_any())
            .map(|m| stamp(&m))
            .collect()
    }

    #[test]
    fn an_aid_written_after_later_imu_samples_is_put_before_them() {
        let ms = 1_000_000;
        let mut o = FeedOrder::default();
        for m in [
            imu(5 * ms, 1),
            imu(10 * ms, 2),
            dvl(6 * ms, 1),
            imu(15 * ms, 3),
        ] {
            assert!(o.push(&m));
        }
        assert_eq!(o.out_of_order, 1);
        assert!(o.pop_ready().is_none(), "the window has not passed");
        assert_eq!(
            drain(&mut o),
            [
                (5 * ms, true),
                (6 * ms, false),
                (10 * ms, true),
                (15 * ms, true)
            ]
        );
    }

    #[test]
    fn a_late_record_moves_its_aid_before_the_named_imu_sample() {
        let ms = 1_000_000;
        let mut o = FeedOrder::default();
        for m in [
            imu(5 * ms, 1),
            dvl(6 * ms, 7),
            imu(10 * ms, 2),
            imu(15 * ms, 3),
        ] {
            o.push(&m);
        }
        o.apply_late_record(&LateAidV1 {
            host_time_ns: 15 * ms,
            imu_sequence: 3,
            aid_host_time_ns: 6 * ms,
            aid_sequence: 7,
            aid_topic: LateAidV1::TOPIC_DVL,
            ..Default::default()
        });
        // A record whose aid comes after it, and one whose aid never comes.
        o.apply_late_record(&LateAidV1 {
            host_time_ns: 15 * ms,
            aid_host_time_ns: 7 * ms,
            aid_sequence: 8,
            aid_topic: LateAidV1::TOPIC_DVL,
            ..Default::default()
        });
        o.apply_late_record(&LateAidV1 {
            aid_sequence: 9,
            aid_topic: LateAidV1::TOPIC_DVL,
            ..Default::default()
        });
        o.push(&dvl(7 * ms, 8));
        assert_eq!(
            drain(&mut o),
            [
                (5 * ms, true),
                (10 * ms, true),
                (6 * ms, false),
                (7 * ms, false),
                (15 * ms, true)
            ]
        );
        assert_eq!((o.late_records_applied, o.late_records_unmatched), (2, 1));
    }

    #[test]
    fn messages_leave_once_the_window_has_passed_them() {
        let mut o = FeedOrder::default();
        o.push(&imu(1, 1));
        o.push(&imu(REORDER_WINDOW_NS, 2));
        assert!(o.pop_ready().is_none());
        o.push(&imu(REORDER_WINDOW_NS + 2, 3));
        assert!(o.pop_ready().is_some());
        assert!(o.pop_ready().is_none());
        // Far behind the newest: counted, and released at once.
        o.push(&dvl(0, 1));
        assert_eq!(o.beyond_window, 1);
        assert!(o.pop_ready().is_some());
    }
}
