//! Acoustic positioning ranged per receiver: LBL beacons on the seabed (the vehicle pings, each
//! beacon replies), an array of receivers hung from a boat that follows the vehicle (an
//! underwater GPS: the array pings, the vehicle's transponder replies), or a single transducer
//! on a ship (the same, one receiver). Each ping gives one range per receiver, measured over the
//! true acoustic path (each end where it was when the sound left and arrived) at the true sound
//! speed and reported at the device's 1500 m/s, with the `usbl.*` effects: range noise,
//! multipath outliers, dropouts, a constant range error per receiver (`usbl.receiver_range_bias`),
//! receivers displaced from their configured places
//! (`usbl.hydrophone_offset`), the array turned and displaced from where its boat says it is
//! (`usbl.array_yaw`, `usbl.array_offset`), and the boat's reported pose noise
//! (`usbl.array_pose_noise`).
//!
//! The device's own fix — what a loosely coupled navigator takes — is computed as such devices
//! do: a least-squares position in the array frame from three ranges or more with the
//! configured receiver places, the vehicle's depth from its depth sensor, and no account of the
//! motion during the ping; its one-sigma through the geometry.

use crate::effects::Effects;
use crate::rng::Rng;
pub use crate::scenario::{AcousticKind, AcousticSetup};
use crate::sensors::ASSUMED_SOUND_SPEED;
use crate::trajectory::TruthSample;
use auvnav_core::earth::{Geodetic, ned_offset, offset_position};
use auvnav_shm_schema::{AcousticArrayPoseV1, AcousticRangesV1};
use nalgebra::{Matrix2, Matrix3, Rotation3, UnitQuaternion, Vector2, Vector3};

/// Where the boat is and heads (array and single).
#[derive(Debug, Clone, Copy)]
struct Boat {
    /// Horizontal place, north and east of the start (m), without the circle.
    centre: Vector2<f64>,
    heading_rad: f64,
}

/// The simulated acoustic system.
#[derive(Debug, Clone)]
pub struct AcousticModel {
    setup: AcousticSetup,
    e: Effects,
    start: Geodetic,
    /// The receivers where they truly are (array frame).
    true_receivers: Vec<Vector3<f64>>,
    configured: Vec<Vector3<f64>>,
    boat: Boat,
    /// Recent poses: the vehicle (its transducer) and the array frame (true, with the array's
    /// own rotation and offset).
    vehicle: auvnav_core::aid::pose_history::PoseHistory,
    array: auvnav_core::aid::pose_history::PoseHistory,
    rng: Rng,
    pose_rng: Rng,
    /// The device's smoothed fix and its time (`usbl.fix_time_constant`).
    smoothed_fix: Option<(f64, Vector3<f64>)>,
    /// Pings and how many of the ranges were outliers.
    pub pings: u64,
    pub outliers: u64,
    pub poses: u64,
}

impl AcousticModel {
    pub fn new(setup: &AcousticSetup, e: &Effects, seed: u64, start: &Geodetic) -> AcousticModel {
        let configured = setup.receivers();
        let o = &e.usbl_hydrophone_offset;
        let true_receivers = configured
            .iter()
            .enumerate()
            .map(|(k, r)| r + Vector3::new(o[3 * k], o[3 * k + 1], o[3 * k + 2]))
            .collect();
        let start = Geodetic {
            height_m: 0.0,
            ..*start
        };
        AcousticModel {
            setup: setup.clone(),
            e: e.clone(),
            start,
            true_receivers,
            configured,
            boat: Boat {
                centre: Vector2::from(setup.boat_offset_m),
                heading_rad: 0.0,
            },
            vehicle: auvnav_core::aid::pose_history::PoseHistory::new(30.0),
            array: auvnav_core::aid::pose_history::PoseHistory::new(30.0),
            rng: Rng::new(seed, "acoustic"),
            pose_rng: Rng::new(seed, "acoustic pose"),
            smoothed_fix: None,
            pings: 0,
            outliers: 0,
            poses: 0,
        }
    }

    /// The boat's GNSS antenna and heading at `t` (array and single; LBL: the start point).
    fn boat_pose(&self, t: f64) -> (Geodetic, f64) {
        if self.setup.kind == AcousticKind::Lbl {
            return (self.start, 0.0);
        }
        let w = 2.0 * std::f64::consts::PI / self.setup.boat_circle_period_s;
        let r = self.setup.boat_circle_radius_m;
        let ne = self.boat.centre + r * Vector2::new((w * t).cos(), (w * t).sin());
        (
            offset_position(&self.start, &Vector3::new(ne.x, ne.y, 0.0)),
            self.boat.heading_rad,
        )
    }

    /// Advances the boat and records the vehicle's and the array's poses (every IMU step).
    pub fn step(&mut self, dt: f64, truth: &TruthSample) {
        let t = truth.time_s;
        if self.setup.kind != AcousticKind::Lbl {
            let v = ned_offset(&self.start, &truth.position);
            let target = Vector2::new(v.x, v.y) + Vector2::from(self.setup.boat_offset_m);
            let step = (target - self.boat.centre) * (dt / self.setup.boat_follow_s);
            if step.norm() > 1e-6 * dt {
                self.boat.heading_rad = step.y.atan2(step.x);
            }
            self.boat.centre += step;
        }
        self.vehicle.push(
            t,
            truth.position,
            UnitQuaternion::from_matrix(&truth.c_body_to_ned),
        );
        let (antenna, heading) = self.boat_pose(t);
        // The array truly sits `usbl.array_offset` (NED) from where its boat says, turned by
        // `usbl.array_yaw`.
        let origin = offset_position(&antenna, &Vector3::from(self.e.usbl_array_offset));
        let yaw = heading + self.e.usbl_array_yaw.to_radians();
        self.array
            .push(t, origin, UnitQuaternion::from_euler_angles(0.0, 0.0, yaw));
    }

    /// The boat's pose message at `t`, as its GNSS and heading report it.
    pub fn pose_message(&mut self, t: f64) -> Option<AcousticArrayPoseV1> {
        if self.setup.kind == AcousticKind::Lbl {
            return None;
        }
        let (antenna, heading) = self.boat_pose(t);
        let [sp, sh] = self.e.usbl_array_pose_noise;
        let r = &mut self.pose_rng;
        let noisy = offset_position(&antenna, &Vector3::new(r.gauss(sp), r.gauss(sp), 0.0));
        let heading = heading + r.gauss(sh).to_radians();
        self.poses += 1;
        Some(AcousticArrayPoseV1 {
            host_time_ns: (t * 1e9).round() as u64,
            device_time_ns: (t * 1e9).round() as u64,
            sequence: self.poses,
            latitude_rad: noisy.latitude_rad,
            longitude_rad: noisy.longitude_rad,
            height_m: 0.0,
            euler_rad: [0.0, 0.0, heading],
            horizontal_std_m: sp.max(0.05) as f32,
            heading_std_rad: sh.max(0.1).to_radians() as f32,
            validity: AcousticArrayPoseV1::VALID_POSITION
                | AcousticArrayPoseV1::VALID_HEADING
                | AcousticArrayPoseV1::VALID_STD
                | AcousticArrayPoseV1::VALID_DEVICE_TIME,
            ..Default::default()
        })
    }

    /// Receiver `k`'s true place at `t`.
    fn receiver_at(&self, k: usize, t: f64) -> Option<Geodetic> {
        let p = self.array.at(t)?;
        Some(offset_position(
            &p.position,
            &(p.attitude * self.true_receivers[k]),
        ))
    }

    /// The vehicle's transducer at `t`.
    fn transducer_at(&self, t: f64) -> Option<Geodetic> {
        let p = self.vehicle.at(t)?;
        Some(offset_position(
            &p.position,
            &(p.attitude * Vector3::from(self.setup.transducer_lever_arm_m)),
        ))
    }

    /// The true two-way range of receiver `k` for a ping closed at `t` (m, at the true sound
    /// speed), by fixed-point iteration on the travel time.
    fn true_range(&self, k: usize, t: f64, c: f64) -> Option<f64> {
        let mut z = ned_offset(&self.receiver_at(k, t)?, &self.transducer_at(t)?).norm();
        for _ in 0..6 {
            let tau = z / c;
            let d = |v: f64, r: f64| -> Option<f64> {
                Some(ned_offset(&self.receiver_at(k, r)?, &self.transducer_at(v)?).norm())
            };
            z = match self.setup.kind {
                AcousticKind::Lbl => 0.5 * (d(t, t - tau)? + d(t - 2.0 * tau, t - tau)?),
                _ => 0.5 * (d(t - tau, t)? + d(t - tau, t - 2.0 * tau)?),
            };
        }
        Some(z)
    }

    /// A ping closed at `t`: each receiver's range as the device reports it, and the device's
    /// fix (`depth_m`: the vehicle's depth as its depth sensor gives it).
    pub fn ping(&mut self, t: f64, depth_m: f64) -> AcousticRangesV1 {
        let e = &self.e;
        let c = e.usbl_sound_speed;
        let scale = ASSUMED_SOUND_SPEED / c;
        let mut m = AcousticRangesV1 {
            host_time_ns: (t * 1e9).round() as u64,
            device_time_ns: (t * 1e9).round() as u64,
            validity: AcousticRangesV1::VALID_RECEIVER_POSITIONS
                | AcousticRangesV1::VALID_DEVICE_TIME,
            ..Default::default()
        };
        self.pings += 1;
        m.sequence = self.pings;
        for (k, r) in self.configured.iter().enumerate() {
            m.receiver_position_m[3 * k..3 * k + 3].copy_from_slice(r.as_slice());
        }
        for k in 0..self.true_receivers.len() {
            let Some(z) = self.true_range(k, t, c) else {
                continue;
            };
            if z > e.usbl_max_range || self.rng.uniform() < e.usbl_dropout {
                // The outlier test's and the noise's draws are taken all the same (an outlier's
                // magnitude draw is not: the stream is not aligned range by range).
                self.rng.uniform();
                self.rng.gauss(1.0);
                continue;
            }
            let outlier = if self.rng.uniform() < e.usbl_outlier_fraction {
                self.outliers += 1;
                let [lo, hi] = e.usbl_outlier_range;
                lo + (hi - lo) * self.rng.uniform()
            } else {
                0.0
            };
            let bias = e.usbl_receiver_range_bias.get(k).copied().unwrap_or(0.0);
            m.range_m[k] = z * scale + bias + outlier + self.rng.gauss(e.usbl_range_noise);
            m.validity |= AcousticRangesV1::VALID_RANGE << k;
        }
        if let Some((fix, std)) = self.device_fix(&m, depth_m, t) {
            let fix = self.smooth_fix(t, fix);
            m.position_array_m = fix.into();
            m.position_std_m = std as f32;
            m.validity |= AcousticRangesV1::VALID_POSITION | AcousticRangesV1::VALID_POSITION_STD;
        }
        m
    }

    /// The device's tracking filter on its own fixes: exponential smoothing with time constant
    /// `usbl.fix_time_constant` in the array frame (the per-ping fix when it is 0, or after a
    /// gap of five time constants).
    fn smooth_fix(&mut self, t: f64, fix: Vector3<f64>) -> Vector3<f64> {
        let tau = self.e.usbl_fix_time_constant;
        let out = match self.smoothed_fix {
            Some((t0, s)) if tau > 0.0 && t - t0 < 5.0 * tau => {
                s + (fix - s) * (1.0 - (-(t - t0) / tau).exp())
            }
            _ => fix,
        };
        self.smoothed_fix = Some((t, out));
        out
    }

    /// The device's fix in the array frame: the horizontal position that fits the ranges best
    /// (Gauss–Newton) from the configured receiver places at the vehicle's depth below the
    /// array frame's origin; its one-sigma from the range noise through the geometry (as a
    /// device's dilution of precision: metres under a boat's small array). Needs three ranges or
    /// more, as the measured underwater GPS (`../shared/data/ugps-g2`) gives a fix only from
    /// three receivers or more.
    fn device_fix(
        &self,
        m: &AcousticRangesV1,
        depth_m: f64,
        t: f64,
    ) -> Option<(Vector3<f64>, f64)> {
        let used: Vec<usize> = (0..4).filter(|&k| m.range_valid(k)).collect();
        if used.len() < 3 {
            return None;
        }
        let origin = self.array.at(t)?.position;
        let z = depth_m + origin.height_m;
        // Start below the mean of the receivers, a little off to break the symmetry.
        let mut p = used
            .iter()
            .map(|&k| self.configured[k].xy())
            .sum::<Vector2<f64>>()
            / used.len() as f64
            + Vector2::new(1.0, 1.0);
        let mut sum_sq = 0.0;
        let mut info = Matrix2::zeros();
        for _ in 0..20 {
            let mut b = Vector2::zeros();
            info = Matrix2::zeros();
            sum_sq = 0.0;
            for &k in &used {
                let d = Vector3::new(p.x, p.y, z) - self.configured[k];
                let r = d.norm().max(1e-3);
                let g = d.xy() / r;
                let res = m.range_m[k] - r;
                sum_sq += res * res;
                info += g * g.transpose();
                b += g * res;
            }
            let step = info.try_inverse()? * b;
            p += step;
            if step.norm() < 1e-4 {
                break;
            }
        }
        // The one-sigma per horizontal axis: the range noise (from the residuals when there are
        // more ranges than unknowns, never below the device's noise) through the geometry.
        let dof = used.len().saturating_sub(2).max(1) as f64;
        let sigma_range = (sum_sq / dof).sqrt().max(self.e.usbl_range_noise).max(0.05);
        let std = sigma_range * (info.try_inverse()?.trace() / 2.0).sqrt();
        Some((Vector3::new(p.x, p.y, z), std))
    }
}

/// The device's fix of `m` as a geodetic position, through the array pose `pose` (its boat's
/// GNSS and heading) or, for a fixed array, the configured origin and yaw: what a loosely coupled
/// navigator fuses.
pub fn fix_position(m: &AcousticRangesV1, origin: &Geodetic, heading_rad: f64) -> Option<Geodetic> {
    if m.validity & AcousticRangesV1::VALID_POSITION == 0 {
        return None;
    }
    let c: Matrix3<f64> = *Rotation3::from_euler_angles(0.0, 0.0, heading_rad).matrix();
    Some(offset_position(
        origin,
        &(c * Vector3::from(m.position_array_m)),
    ))
}
