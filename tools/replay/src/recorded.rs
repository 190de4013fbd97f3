//! The replay's solutions against those the daemon published live and the log recorded.

use auvnav_shm_schema::NavSolutionV1;
use serde::Serialize;

/// The replay's solutions against the solutions a log recorded (the daemon's live output, on
/// `nav/solution`): matched by time stamp, compared byte for byte but for the sequence number
/// (the bus numbers what it carries).
#[derive(Debug, Clone, Default, Serialize)]
pub struct RecordedComparison {
    /// Recorded solutions compared with the replay's solution of the same time.
    pub compared: u64,
    /// Of those, how many differ.
    pub differing: u64,
    /// Recorded solutions for which the replay produced none at that time.
    pub unmatched_recorded: u64,
    /// The first recorded solution that differs or has no match: its time stamp (ns) and what.
    pub first_difference: Option<(u64, String)>,
    #[serde(skip)]
    queue: std::collections::VecDeque<NavSolutionV1>,
}

impl RecordedComparison {
    /// True when every recorded solution was reproduced.
    pub fn identical(&self) -> bool {
        self.compared > 0 && self.differing == 0 && self.unmatched_recorded == 0
    }

    fn note(&mut self, t_ns: u64, what: String) {
        self.first_difference.get_or_insert((t_ns, what));
    }

    /// A solution the log recorded, in the log's order.
    pub(crate) fn push_recorded(&mut self, s: NavSolutionV1) {
        self.queue.push_back(s);
    }

    /// A recorded solution the replay has no solution for.
    fn unmatched(&mut self, r: &NavSolutionV1) {
        self.unmatched_recorded += 1;
        self.note(r.host_time_ns, "no replayed solution at this time".into());
    }

    /// Compares a replayed solution with the first recorded solution of its time not yet
    /// compared (two solutions may share a time stamp: each is compared with its own).
    pub(crate) fn check(&mut self, sol: &NavSolutionV1) {
        while let Some(r) = self.queue.front().copied() {
            if r.host_time_ns > sol.host_time_ns {
                break;
            }
            self.queue.pop_front();
            if r.host_time_ns < sol.host_time_ns {
                self.unmatched(&r);
                continue;
            }
            self.compared += 1;
            let (mut a, mut b) = (r, *sol);
            a.sequence = 0;
            b.sequence = 0;
            if bytemuck::bytes_of(&a) != bytemuck::bytes_of(&b) {
                self.differing += 1;
                let geo = |x: &NavSolutionV1| auvnav_core::earth::Geodetic {
                    latitude_rad: x.latitude_rad,
                    longitude_rad: x.longitude_rad,
                    height_m: x.height_m,
                };
                let d = auvnav_core::earth::ned_offset(&geo(&a), &geo(&b)).norm();
                self.note(
                    r.host_time_ns,
                    format!(
                        "differs (positions {d:.3e} m apart, modes {} / {})",
                        a.mode, b.mode
                    ),
                );
            }
            break;
        }
    }

    pub(crate) fn finish(&mut self) {
        while let Some(r) = self.queue.pop_front() {
            self.unmatched(&r);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn solution(t_ns: u64, latitude_rad: f64) -> NavSolutionV1 {
        NavSolutionV1 {
            host_time_ns: t_ns,
            latitude_rad,
            ..bytemuck::Zeroable::zeroed()
        }
    }

    /// The comparison of `replayed` against `recorded`, fed as a replay feeds it.
    fn compare(recorded: &[NavSolutionV1], replayed: &[NavSolutionV1]) -> RecordedComparison {
        let mut c = RecordedComparison::default();
        for s in recorded {
            c.push_recorded(*s);
        }
        for s in replayed {
            c.check(s);
        }
        c.finish();
        c
    }

    /// Two solutions of one time stamp (two IMU samples stamped alike) are each compared with
    /// their own recorded twin; a replay that lacks one is reported.
    #[test]
    fn solutions_that_share_a_time_are_compared_in_order() {
        let recorded = [
            solution(1, 0.1),
            solution(2, 0.2),
            solution(2, 0.3),
            solution(3, 0.4),
        ];
        let c = compare(&recorded, &recorded);
        assert!(c.identical(), "{c:?}");
        assert_eq!(c.compared, 4);

        let c = compare(&recorded, &[recorded[0], recorded[1], recorded[3]]);
        assert_eq!(
            (c.compared, c.differing, c.unmatched_recorded),
            (3, 0, 1),
            "{c:?}"
        );
    }
}
