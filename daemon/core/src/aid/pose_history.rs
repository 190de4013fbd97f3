//! Recent poses (time, position, attitude) of a moving thing — the vehicle, or a boat carrying an
//! acoustic array — so that an acoustic measurement can be evaluated where each end was when the
//! sound left or arrived.

use crate::earth::Geodetic;
use nalgebra::UnitQuaternion;
use std::collections::VecDeque;

/// A pose: time (s), position, attitude (body or array frame → NED).
pub type Pose = (f64, Geodetic, UnitQuaternion<f64>);

/// Poses in time order, kept for `keep_s` behind the newest.
#[derive(Debug, Clone, Default)]
pub struct PoseHistory {
    poses: VecDeque<Pose>,
    keep_s: f64,
}

/// A pose looked up at a time, and how far that time lies outside the recorded span (s; 0
/// inside it).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PoseAt {
    pub position: Geodetic,
    pub attitude: UnitQuaternion<f64>,
    pub outside_s: f64,
}

impl PoseHistory {
    /// Keeps poses for `keep_s` behind the newest.
    pub fn new(keep_s: f64) -> PoseHistory {
        PoseHistory {
            poses: VecDeque::new(),
            keep_s,
        }
    }

    /// Adds the newest pose (one older than the newest is ignored) and drops the expired ones.
    pub fn push(&mut self, t: f64, position: Geodetic, attitude: UnitQuaternion<f64>) {
        if self.poses.back().is_some_and(|p| p.0 >= t) {
            return;
        }
        self.poses.push_back((t, position, attitude));
        while self.poses.front().is_some_and(|p| t - p.0 > self.keep_s) {
            self.poses.pop_front();
        }
    }

    /// Applies a navigation correction to every pose kept: the position moved by `-dp` (NED, m;
    /// the error estimate, estimate minus truth) and the attitude turned by `phi` (the attitude
    /// error estimate), as the filter corrects the current state. The errors change little over
    /// the seconds kept, so the whole recent track takes the correction: a range evaluated on the
    /// track just after another range corrected the state sees that correction.
    pub fn correct(&mut self, dp: &nalgebra::Vector3<f64>, phi: &nalgebra::Vector3<f64>) {
        let turn = UnitQuaternion::from_scaled_axis(*phi);
        for p in self.poses.iter_mut() {
            p.1 = crate::earth::offset_position(&p.1, &(-dp));
            p.2 = turn * p.2;
        }
    }

    /// The newest pose's time.
    pub fn newest_s(&self) -> Option<f64> {
        self.poses.back().map(|p| p.0)
    }

    /// The pose at `t`: linear between the recorded poses (position) and spherical (attitude);
    /// the oldest or newest one outside them, with how far outside.
    pub fn at(&self, t: f64) -> Option<PoseAt> {
        let after = self.poses.partition_point(|p| p.0 < t);
        let pose = |p: &Pose, outside_s: f64| PoseAt {
            position: p.1,
            attitude: p.2,
            outside_s,
        };
        match (
            after.checked_sub(1).and_then(|i| self.poses.get(i)),
            self.poses.get(after),
        ) {
            (Some(a), Some(b)) if b.0 > a.0 => {
                let w = (t - a.0) / (b.0 - a.0);
                Some(PoseAt {
                    position: Geodetic {
                        latitude_rad: a.1.latitude_rad + w * (b.1.latitude_rad - a.1.latitude_rad),
                        longitude_rad: a.1.longitude_rad
                            + w * (b.1.longitude_rad - a.1.longitude_rad),
                        height_m: a.1.height_m + w * (b.1.height_m - a.1.height_m),
                    },
                    attitude: a.2.slerp(&b.2, w),
                    outside_s: 0.0,
                })
            }
            (_, Some(p)) => Some(pose(p, (p.0 - t).max(0.0))),
            (Some(p), None) => Some(pose(p, (t - p.0).max(0.0))),
            (None, None) => None,
        }
    }

    /// The gap (s) between the recorded poses around `t` (∞ outside them).
    pub fn gap_around(&self, t: f64) -> f64 {
        let after = self.poses.partition_point(|p| p.0 < t);
        match (
            after.checked_sub(1).and_then(|i| self.poses.get(i)),
            self.poses.get(after),
        ) {
            (Some(a), Some(b)) => b.0 - a.0,
            (None, Some(b)) if b.0 == t => 0.0,
            _ => f64::INFINITY,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn at(lat: f64) -> Geodetic {
        Geodetic {
            latitude_rad: lat,
            longitude_rad: 0.0,
            height_m: 0.0,
        }
    }

    #[test]
    fn poses_are_interpolated_inside_and_held_outside() {
        let mut h = PoseHistory::new(10.0);
        h.push(1.0, at(0.1), UnitQuaternion::identity());
        h.push(
            2.0,
            at(0.2),
            UnitQuaternion::from_euler_angles(0.0, 0.0, 0.2),
        );
        h.push(1.5, at(9.0), UnitQuaternion::identity()); // older than the newest: ignored
        let p = h.at(1.25).expect("pose");
        assert!((p.position.latitude_rad - 0.125).abs() < 1e-12 && p.outside_s == 0.0);
        assert!((p.attitude.euler_angles().2 - 0.05).abs() < 1e-12);
        let p = h.at(2.5).expect("pose");
        assert!((p.position.latitude_rad - 0.2).abs() < 1e-12 && (p.outside_s - 0.5).abs() < 1e-12);
        let p = h.at(0.0).expect("pose");
        assert!((p.position.latitude_rad - 0.1).abs() < 1e-12 && (p.outside_s - 1.0).abs() < 1e-12);
        assert_eq!(h.gap_around(1.7), 1.0);
        assert!(h.gap_around(3.0).is_infinite());
        h.push(20.0, at(0.3), UnitQuaternion::identity());
        assert!(
            h.at(1.5).is_some_and(|p| p.outside_s > 10.0),
            "expired poses dropped"
        );
    }
}
