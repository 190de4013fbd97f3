//! Recent poses (time, position, attitude) of a moving thing — the vehicle, or a boat carrying an
//! acoustic array — so that an acoustic measurement can be evaluated where each end was when the
//! sound left or arrived.

use crate::earth::{Geodetic, offset_position};
use nalgebra::{UnitQuaternion, Vector3};
use std::collections::VecDeque;

/// A pose as recorded, with the corrections applied to the history up to then (so that a later
/// correction applies to it without touching every pose kept).
#[derive(Debug, Clone, Copy)]
struct Pose {
    t: f64,
    position: Geodetic,
    attitude: UnitQuaternion<f64>,
    shift_at_push: Vector3<f64>,
    turn_at_push: UnitQuaternion<f64>,
}

/// Poses in time order, kept for `keep_s` behind the newest.
#[derive(Debug, Clone)]
pub struct PoseHistory {
    poses: VecDeque<Pose>,
    keep_s: f64,
    /// The corrections applied so far: the sum of the position moves (NED, m) and the product
    /// of the attitude turns.
    shift: Vector3<f64>,
    turn: UnitQuaternion<f64>,
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
            shift: Vector3::zeros(),
            turn: UnitQuaternion::identity(),
        }
    }

    /// Adds the newest pose (one older than the newest is ignored) and drops the expired ones.
    pub fn push(&mut self, t: f64, position: Geodetic, attitude: UnitQuaternion<f64>) {
        if self.poses.back().is_some_and(|p| p.t >= t) {
            return;
        }
        self.poses.push_back(Pose {
            t,
            position,
            attitude,
            shift_at_push: self.shift,
            turn_at_push: self.turn,
        });
        while self.poses.front().is_some_and(|p| t - p.t > self.keep_s) {
            self.poses.pop_front();
        }
    }

    /// Applies a navigation correction to every pose kept: the position moved by `-dp` (NED, m;
    /// the error estimate, estimate minus truth) and the attitude turned by `phi` (the attitude
    /// error estimate), as the filter corrects the current state. The errors change little over
    /// the seconds kept, so the whole recent track takes the correction: a range evaluated on the
    /// track just after another range corrected the state sees that correction. Constant time:
    /// the corrections are summed and applied to a pose when it is looked up.
    pub fn correct(&mut self, dp: &Vector3<f64>, phi: &Vector3<f64>) {
        self.shift -= dp;
        self.turn = UnitQuaternion::from_scaled_axis(*phi) * self.turn;
    }

    /// A kept pose with the corrections applied since it was recorded.
    fn corrected(&self, p: &Pose) -> (Geodetic, UnitQuaternion<f64>) {
        let moved = self.shift - p.shift_at_push;
        let position = if moved == Vector3::zeros() {
            p.position
        } else {
            offset_position(&p.position, &moved)
        };
        (position, self.turn * p.turn_at_push.inverse() * p.attitude)
    }

    /// The newest pose's time.
    pub fn newest_s(&self) -> Option<f64> {
        self.poses.back().map(|p| p.t)
    }

    /// The pose at `t`: linear between the recorded poses (position) and spherical (attitude);
    /// the oldest or newest one outside them, with how far outside.
    pub fn at(&self, t: f64) -> Option<PoseAt> {
        let after = self.poses.partition_point(|p| p.t < t);
        let pose = |p: &Pose, outside_s: f64| {
            let (position, attitude) = self.corrected(p);
            PoseAt {
                position,
                attitude,
                outside_s,
            }
        };
        match (
            after.checked_sub(1).and_then(|i| self.poses.get(i)),
            self.poses.get(after),
        ) {
            (Some(a), Some(b)) if b.t > a.t => {
                let w = (t - a.t) / (b.t - a.t);
                let (pa, qa) = self.corrected(a);
                let (pb, qb) = self.corrected(b);
                Some(PoseAt {
                    position: Geodetic {
                        latitude_rad: pa.latitude_rad + w * (pb.latitude_rad - pa.latitude_rad),
                        longitude_rad: pa.longitude_rad + w * (pb.longitude_rad - pa.longitude_rad),
                        height_m: pa.height_m + w * (pb.height_m - pa.height_m),
                    },
                    attitude: qa.slerp(&qb, w),
                    outside_s: 0.0,
                })
            }
            (_, Some(p)) => Some(pose(p, (p.t - t).max(0.0))),
            (Some(p), None) => Some(pose(p, (t - p.t).max(0.0))),
            (None, None) => None,
        }
    }

    /// The gap (s) between the recorded poses around `t` (∞ outside them).
    pub fn gap_around(&self, t: f64) -> f64 {
        let after = self.poses.partition_point(|p| p.t < t);
        match (
            after.checked_sub(1).and_then(|i| self.poses.get(i)),
            self.poses.get(after),
        ) {
            (Some(a), Some(b)) => b.t - a.t,
            (None, Some(b)) if b.t == t => 0.0,
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
