//! Range aid: each range of an acoustic system to a transponder whose position is known at the
//! time of the ping — surveyed LBL beacons, a docking station's array, the receivers of an
//! underwater GPS hung from a boat, a single transducer on a ship — fused alone as a slant range
//! from the vehicle's transducer (lever arm) to that receiver, gated alone (χ², 1 dof).
//!
//! * **Where each end was.** A range's time is the arrival of the sound that closed it. The
//!   vehicle's transducer is taken where it was when it replied (one travel time before, for a
//!   ping from the array) or where it pinged and heard the reply (LBL); the receiver where it was
//!   when it sent and when it heard (a moving array: from the `acoustic_array_pose` topic,
//!   interpolated). A two-way range is half of the two legs.
//! * **Sound speed.** The device turned travel times into ranges with its own sound speed; the
//!   ranges are scaled to the water's (configured, or from the `sound_velocity` topic), and a
//!   Gauss–Markov scale state takes what is left.
//! * **Errors.** A Gauss–Markov range bias (timing, turnaround: S-USBL's δR), shared by the
//!   receivers or one per receiver, and with a docking station's fixes one per range difference
//!   (S-USBL's δΔR): they take the filter's acoustic error slots ([`config::ErrorStates`]), which
//!   the tight USBL uses too, so the two are not configured together. A receiver's position
//!   error is found offline (`auvnav discover`), not tracked.
//! * **A docking station** ([`RangesConfig::docking_station`], `usbl_fixes`): its fixes' slant
//!   range and range differences, each fused alone through the station's geometry ([`station`]).
//! * **A moving array's own errors** (its GNSS position and heading) are added to each range's
//!   noise, projected on the line of sight.

pub mod config;
mod station;

pub use config::{ArrayKind, ErrorStates, Interrogator, RangesConfig};

use super::pose_history::PoseHistory;
use super::{AidUpdate, NavCore};
use crate::earth::{Geodetic, ned_offset, offset_position};
use crate::ekf::{self, ErrorFilter, skew};
use crate::strapdown::NavState;
use auvnav_shm_schema::{
    AcousticArrayPoseV1, AcousticRangesV1, AidDiagnosticsV1, AidSource, SoundVelocityV1,
};
use nalgebra::{Matrix3, Rotation3, SMatrix, SVector, UnitQuaternion, Vector3};

/// Counts of what became of the ranges (one per receiver's range) and the array poses.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct RangeCounters {
    pub fused: u64,
    /// Rejected by the innovation gate (or a failed update).
    pub rejected: u64,
    /// Out of range, not finite, or from a receiver the configuration does not place.
    pub invalid: u64,
    /// Range messages received without a `[navigation.ranges]` configuration.
    pub unconfigured: u64,
    /// Ranges of a moving array without its pose at the time (no pose, or a gap between poses
    /// longer than `array_pose_max_gap_s`).
    pub no_array_pose: u64,
    /// Range messages older than `max_latency_s`.
    pub late: u64,
    /// Times the position's covariance was reopened after `reopen_after` rejections in a row.
    pub reopened: u64,
    /// Array poses taken, and refused (invalid or out of range).
    pub array_poses: u64,
    pub array_poses_invalid: u64,
}

/// The range aid: the fusion state when configured, and its counters.
#[derive(Debug, Clone)]
pub struct RangeAid {
    fusion: Option<RangeFusion>,
    pub counters: RangeCounters,
}

#[derive(Debug, Clone)]
struct RangeFusion {
    cfg: RangesConfig,
    receivers: Vec<Vector3<f64>>,
    lever_arm_b: Vector3<f64>,
    /// Fixed array: its origin and frame (array → NED).
    origin: Geodetic,
    c_array_to_ned: Matrix3<f64>,
    vehicle: PoseHistory,
    array: PoseHistory,
    /// The moving array's position (m) and heading (rad) one-sigma.
    array_std: (f64, f64),
    /// The water's sound speed in use (m/s).
    sound_speed_m_s: f64,
    states: ErrorStates,
    last_fused_s: Option<f64>,
    /// Measurements rejected in a row: each receiver's ranges, then each range difference's.
    rejected_in_a_row: [u32; 7],
}

/// One leg of the sound's path: the vehicle's time and the receiver's time.
#[derive(Debug, Clone, Copy)]
struct Leg {
    vehicle_s: f64,
    receiver_s: f64,
}

/// What one range predicts: each leg's vector from the receiver to the vehicle's transducer
/// (NED, m) and the lever arm in NED then, and the line of sight's projection of the array's own
/// errors (m², added to the noise).
#[derive(Debug, Clone, Copy)]
pub struct RangePrediction {
    legs: [(Vector3<f64>, Vector3<f64>); 2],
    n: usize,
    pub array_variance_m2: f64,
}

/// A range predicted at one state: the geometric range (mean of the legs, m), its gradient with
/// respect to the transducer's position (NED) and the lever arm in NED (for the attitude).
#[derive(Debug, Clone, Copy)]
pub struct RangeAt {
    pub range_m: f64,
    pub line_of_sight: Vector3<f64>,
    pub lever_ned: Vector3<f64>,
}

impl RangePrediction {
    /// The range with the transducer moved by `-e` (NED, m: the transducer's position error a
    /// candidate correction removes).
    pub fn at(&self, e: &Vector3<f64>) -> RangeAt {
        let mut r = RangeAt {
            range_m: 0.0,
            line_of_sight: Vector3::zeros(),
            lever_ned: Vector3::zeros(),
        };
        for (d, lever) in &self.legs[..self.n] {
            let d = d - e;
            let norm = d.norm().max(1e-3);
            r.range_m += norm;
            r.line_of_sight += d / norm;
            r.lever_ned += lever;
        }
        let w = 1.0 / self.n as f64;
        r.range_m *= w;
        r.line_of_sight *= w;
        r.lever_ned *= w;
        r
    }
}

impl RangeAid {
    /// The aid for `cfg` (none: range messages are counted as unconfigured); switches on the
    /// bias and scale states in `kf`.
    pub fn new(cfg: Option<&RangesConfig>, kf: &mut ErrorFilter) -> RangeAid {
        let fusion = cfg.map(|c| {
            let states = ErrorStates::of(c);
            let mut bias_slots: Vec<usize> = states.bias.iter().flatten().copied().collect();
            bias_slots.dedup();
            for slot in bias_slots {
                kf.set_gauss_markov(ekf::USBL + slot, c.bias_correlation_s, c.bias_std_m);
            }
            for slot in states.difference.iter().flatten() {
                kf.set_gauss_markov(
                    ekf::USBL + slot,
                    c.difference_bias_correlation_s,
                    c.difference_bias_std_m,
                );
            }
            if let Some(slot) = states.scale {
                kf.set_gauss_markov(ekf::USBL + slot, c.scale_correlation_s, c.scale_std);
            }
            // Poses are kept for the longest acoustic path (two travel times at the longest
            // range) behind the oldest range accepted.
            let keep_s = c.max_latency_s + 2.0 * c.max_range_m / c.device_sound_speed_m_s + 1.0;
            RangeFusion {
                receivers: if c.receivers_from_device {
                    Vec::new()
                } else {
                    c.receivers_m.iter().map(|r| Vector3::from(*r)).collect()
                },
                lever_arm_b: Vector3::from(c.transducer_lever_arm_m),
                origin: Geodetic {
                    latitude_rad: c.origin_latitude_deg.to_radians(),
                    longitude_rad: c.origin_longitude_deg.to_radians(),
                    height_m: c.origin_height_m,
                },
                c_array_to_ned: *Rotation3::from_euler_angles(
                    0.0,
                    0.0,
                    c.origin_yaw_deg.to_radians(),
                )
                .matrix(),
                vehicle: PoseHistory::new(keep_s),
                array: PoseHistory::new(keep_s + c.array_pose_max_gap_s),
                array_std: (c.array_position_std_m, c.array_heading_std_deg.to_radians()),
                sound_speed_m_s: c.sound_speed_m_s,
                states,
                last_fused_s: None,
                rejected_in_a_row: [0; 7],
                cfg: c.clone(),
            }
        });
        RangeAid {
            fusion,
            counters: RangeCounters::default(),
        }
    }

    /// Keeps the vehicle's pose for ranges whose sound left or arrived in the past.
    pub fn after_imu(&mut self, s: &NavState) {
        if let Some(f) = self.fusion.as_mut() {
            f.vehicle.push(s.time_s, s.position, s.q_body_to_ned);
        }
    }

    /// Moves the vehicle's recent track by a correction the filter applied to the state (any
    /// aid's), so that the next range is evaluated on the corrected track.
    pub fn correct(&mut self, dx: &crate::ekf::StateVector) {
        if let Some(f) = self.fusion.as_mut() {
            let v = |i: usize| Vector3::new(dx[i], dx[i + 1], dx[i + 2]);
            f.vehicle.correct(&v(ekf::POS), &v(ekf::ATT));
        }
    }

    /// Time of the last fused range (s).
    pub fn last_fused_s(&self) -> Option<f64> {
        self.fusion.as_ref().and_then(|f| f.last_fused_s)
    }

    /// The estimated range bias (m; receiver 0's when each has its own) and sound-speed scale
    /// error, when configured (0 for a state switched off).
    pub fn estimates(&self, core: &NavCore) -> Option<(f64, f64)> {
        let f = self.fusion.as_ref()?;
        Some((
            error_mean(core, f.states.bias[0]),
            error_mean(core, f.states.scale),
        ))
    }

    /// Each receiver's estimated range bias (m; the shared one repeated, 0 where off), when
    /// configured.
    pub fn receiver_biases(&self, core: &NavCore) -> Option<Vec<f64>> {
        let f = self.fusion.as_ref()?;
        Some(
            (0..f.receivers.len().min(5))
                .map(|k| error_mean(core, f.states.bias[k]))
                .collect(),
        )
    }

    /// Takes a moving array's pose (its boat's GNSS and heading); counted and ignored when
    /// invalid, or when the array is fixed.
    pub fn on_array_pose(&mut self, m: &AcousticArrayPoseV1) {
        let Some(f) = self.fusion.as_mut() else {
            return;
        };
        let need = AcousticArrayPoseV1::VALID_POSITION | AcousticArrayPoseV1::VALID_HEADING;
        let e = m.euler_rad;
        let ok = m.validity & need == need
            && m.latitude_rad.abs() <= std::f64::consts::FRAC_PI_2
            && m.longitude_rad.abs() <= std::f64::consts::PI
            && e.iter()
                .all(|x| x.is_finite() && x.abs() <= 2.0 * std::f64::consts::PI)
            && (m.validity & AcousticArrayPoseV1::VALID_HEIGHT == 0
                || (-1000.0..=10000.0).contains(&m.height_m))
            && (m.validity & AcousticArrayPoseV1::VALID_STD == 0
                || ((0.0..=1000.0).contains(&m.horizontal_std_m)
                    && (0.0..=std::f32::consts::PI).contains(&m.heading_std_rad)));
        if f.cfg.array != ArrayKind::Moving || !ok {
            self.counters.array_poses_invalid += 1;
            return;
        }
        let height = if m.validity & AcousticArrayPoseV1::VALID_HEIGHT != 0 {
            m.height_m
        } else {
            0.0
        };
        let (roll, pitch) = if m.validity & AcousticArrayPoseV1::VALID_TILT != 0 {
            (e[0], e[1])
        } else {
            (0.0, 0.0)
        };
        // The pose's own one-sigma when it gives one, else the configured.
        f.array_std = if m.validity & AcousticArrayPoseV1::VALID_STD != 0 {
            (f64::from(m.horizontal_std_m), f64::from(m.heading_std_rad))
        } else {
            (
                f.cfg.array_position_std_m,
                f.cfg.array_heading_std_deg.to_radians(),
            )
        };
        f.array.push(
            m.host_time_ns as f64 * 1e-9,
            Geodetic {
                latitude_rad: m.latitude_rad,
                longitude_rad: m.longitude_rad,
                height_m: height,
            },
            UnitQuaternion::from_euler_angles(roll, pitch, e[2]),
        );
        self.counters.array_poses += 1;
    }

    /// Takes the water's sound speed from a CTD, with `sound_speed_from_topic`.
    pub fn on_sound_velocity(&mut self, m: &SoundVelocityV1) {
        if let Some(f) = self
            .fusion
            .as_mut()
            .filter(|f| f.cfg.sound_speed_from_topic)
            && m.validity & SoundVelocityV1::VALID_SOUND_SPEED != 0
            && (1375.0..=1650.0).contains(&m.sound_speed_m_s)
        {
            f.sound_speed_m_s = m.sound_speed_m_s;
        }
    }

    /// The range receiver `k` of `m` should have measured (m, at the device's sound speed, with
    /// the estimated bias and scale `errors`) for a vehicle whose recent track is the one kept
    /// and whose state now is `s`: the aid's measurement model, for checks against data.
    pub fn predicted_range(
        &self,
        s: &NavState,
        m: &AcousticRangesV1,
        k: usize,
        errors: (f64, f64),
    ) -> Option<f64> {
        let f = self.fusion.as_ref()?;
        if k >= f.receivers.len() || !m.range_valid(k) {
            return None;
        }
        let p = f.predict(s, k, m.host_time_ns as f64 * 1e-9, m.range_m[k])?;
        let ratio = f.cfg.device_sound_speed_m_s / f.sound_speed_m_s;
        Some(p.at(&Vector3::zeros()).range_m * ratio * (1.0 + errors.1) + errors.0)
    }

    /// Whether a range message is to be fused at all (configured, not too old); counted when
    /// not.
    pub fn accepts(&mut self, core: &NavCore, m: &AcousticRangesV1) -> bool {
        let Some(f) = self.fusion.as_mut() else {
            self.counters.unconfigured += 1;
            return false;
        };
        if f.cfg.receivers_from_device
            && m.validity & AcousticRangesV1::VALID_RECEIVER_POSITIONS != 0
        {
            let given: Vec<Vector3<f64>> = m
                .receiver_position_m
                .chunks_exact(3)
                .map(Vector3::from_column_slice)
                .collect();
            if given
                .iter()
                .all(|r| r.iter().all(|x| x.is_finite() && x.abs() <= 20_000.0))
            {
                f.receivers = given;
            }
        }
        self.in_time(core, m.host_time_ns)
    }

    /// Whether a measurement of time `t_ns` is recent enough against the state
    /// (`max_latency_s`); counted as late when not.
    fn in_time(&mut self, core: &NavCore, t_ns: u64) -> bool {
        let Some(f) = self.fusion.as_ref() else {
            return false;
        };
        if core.state().time_s - t_ns as f64 * 1e-9 > f.cfg.max_latency_s {
            self.counters.late += 1;
            return false;
        }
        true
    }

    /// Fuses receiver `k`'s range of `m` (none when that receiver has no valid range).
    pub fn fuse_one(
        &mut self,
        core: &mut NavCore,
        m: &AcousticRangesV1,
        k: usize,
    ) -> Option<AidUpdate> {
        let f = self.fusion.as_ref()?;
        if !m.range_valid(k) {
            return None;
        }
        let t_ns = m.host_time_ns;
        let mut d = core.diagnostics(t_ns, AidSource::AcousticRange);
        d.dimension = 1;
        let z = m.range_m[k];
        d.observation = [z, k as f64, 0.0];
        if !(z.is_finite() && z > 0.0 && z <= f.cfg.max_range_m) || k >= f.receivers.len() {
            self.counters.invalid += 1;
            return Some(AidUpdate::rejected(d));
        }
        let Some(p) = f.predict(core.state(), k, t_ns as f64 * 1e-9, z) else {
            self.counters.no_array_pose += 1;
            return Some(AidUpdate::rejected(d));
        };
        core.propagate_covariance();
        // The prediction and its Jacobian at the state (an iterated update, linearised again
        // where the correction leaves the state, was tried: no gain on the range studies).
        let a = p.at(&Vector3::zeros());
        let scalar = f.range_measurement(core, &a, k, z, p.array_variance_m2);
        Some(self.update(core, d, scalar, k))
    }

    /// Gates and fuses one scalar measurement (a range, or a range difference: `channel` counts
    /// its rejections in a row, ranges 0..5, differences 5 and 6), reopening the position after
    /// `reopen_after` of them; counted.
    fn update(
        &mut self,
        core: &mut NavCore,
        mut d: AidDiagnosticsV1,
        s: Scalar,
        channel: usize,
    ) -> AidUpdate {
        let Some(f) = self.fusion.as_mut() else {
            return AidUpdate::rejected(d);
        };
        d.observation_variance[0] = s.variance;
        let (gate, reopen_after, max_range) =
            (f.cfg.gate_chi2, f.cfg.reopen_after, f.cfg.max_range_m);
        let y = SVector::<f64, 1>::new(s.predicted - s.measured);
        let r = SMatrix::<f64, 1, 1>::new(s.variance);
        let mut result = core.kf.update(&y, &s.h, &r, gate);
        let gated = matches!(&result, Ok((_, rep)) if !rep.fused);
        let in_a_row = &mut f.rejected_in_a_row[channel];
        *in_a_row = if gated { *in_a_row + 1 } else { 0 };
        if gated && *in_a_row >= reopen_after {
            // The ranges agree with one another, not with the state: the position is what is
            // wrong. Its covariance is reopened by this innovation (bounded by the longest
            // range) and the measurement fused again.
            *in_a_row = 0;
            self.counters.reopened += 1;
            d.flags |= AidDiagnosticsV1::FLAG_RESET;
            let by = y[0].abs().min(max_range);
            core.reopen(ekf::POS, [by * by; 3]);
            result = core.kf.update(&y, &s.h, &r, gate);
        }
        let reset = d.flags & AidDiagnosticsV1::FLAG_RESET;
        let correction = NavCore::report(result, &mut d);
        d.flags |= reset;
        if correction.is_some() {
            self.counters.fused += 1;
            f.last_fused_s = Some(d.host_time_ns as f64 * 1e-9);
        } else {
            self.counters.rejected += 1;
        }
        AidUpdate {
            diagnostics: d,
            correction,
        }
    }
}

/// One scalar acoustic measurement ready for the update: measured and predicted (m), its
/// Jacobian and noise variance (m²).
struct Scalar {
    measured: f64,
    predicted: f64,
    h: SMatrix<f64, 1, { ekf::N }>,
    variance: f64,
}

/// An acoustic length predicted at the state (m): its gradient with respect to the
/// transducer's position (NED) and the lever arm in NED.
struct Geometric {
    length_m: f64,
    line_of_sight: Vector3<f64>,
    lever_ned: Vector3<f64>,
}

/// The mean of acoustic error slot `slot` (0 when the state is off).
fn error_mean(core: &NavCore, slot: Option<usize>) -> f64 {
    slot.map_or(0.0, |i| core.markov_means[ekf::USBL - ekf::CORE + i])
}

impl RangeFusion {
    /// Receiver `k`'s range `z` as a scalar measurement, its geometry `a` from the state: the
    /// range at the water's sound speed, the scale and receiver `k`'s bias.
    fn range_measurement(
        &self,
        core: &NavCore,
        a: &RangeAt,
        k: usize,
        z: f64,
        extra_variance_m2: f64,
    ) -> Scalar {
        self.scalar(
            core,
            Geometric {
                length_m: a.range_m,
                line_of_sight: a.line_of_sight,
                lever_ned: a.lever_ned,
            },
            self.states.bias[k],
            z,
            self.cfg.range_std_m.powi(2) + extra_variance_m2,
        )
    }

    /// An acoustic length (a range, or a difference of two) measured as `z`, its geometric
    /// value and gradient `g` from the state: scaled to the water's sound speed and by the scale
    /// state, plus the error state in `bias_slot`; the Jacobian over position, attitude (through
    /// the lever arm), that error and the scale.
    fn scalar(
        &self,
        core: &NavCore,
        g: Geometric,
        bias_slot: Option<usize>,
        z: f64,
        variance: f64,
    ) -> Scalar {
        let ratio = self.cfg.device_sound_speed_m_s / self.sound_speed_m_s;
        let (bias, scale) = (
            error_mean(core, bias_slot),
            error_mean(core, self.states.scale),
        );
        let mut h = SMatrix::<f64, 1, { ekf::N }>::zeros();
        let u = g.line_of_sight.transpose();
        h.fixed_view_mut::<1, 3>(0, ekf::POS).copy_from(&u);
        h.fixed_view_mut::<1, 3>(0, ekf::ATT)
            .copy_from(&(u * skew(&g.lever_ned)));
        if let Some(slot) = bias_slot {
            h[(0, ekf::USBL + slot)] = 1.0;
        }
        if let Some(slot) = self.states.scale {
            h[(0, ekf::USBL + slot)] = g.length_m * ratio;
        }
        Scalar {
            measured: z,
            predicted: g.length_m * ratio * (1.0 + scale) + bias,
            h,
            variance,
        }
    }

    /// The legs of a range closed at `t` of measured length `z` (m).
    fn legs(&self, t: f64, z: f64) -> ([Leg; 2], usize) {
        let tau = z / self.cfg.device_sound_speed_m_s;
        let back = t - 2.0 * tau - self.cfg.turnaround_s;
        let leg = |vehicle_s, receiver_s| Leg {
            vehicle_s,
            receiver_s,
        };
        match (self.cfg.two_way, self.cfg.interrogator) {
            (false, _) => ([leg(t - tau, t), leg(t - tau, t)], 1),
            (true, Interrogator::Array) => ([leg(t - tau, t), leg(t - tau, back)], 2),
            (true, Interrogator::Vehicle) => ([leg(t, t - tau), leg(back, t - tau)], 2),
        }
    }

    /// Receiver `k`'s position at `t`, with the array's frame (array → NED) then; `None` for a
    /// moving array without a pose around `t`.
    fn receiver_at(&self, k: usize, t: f64) -> Option<(Geodetic, Matrix3<f64>)> {
        let (origin, c) = match self.cfg.array {
            ArrayKind::Fixed => (self.origin, self.c_array_to_ned),
            ArrayKind::Moving => {
                let gap = self.array.gap_around(t);
                let p = self.array.at(t)?;
                let held = p.outside_s <= 0.5 * self.cfg.array_pose_max_gap_s;
                if !(gap <= self.cfg.array_pose_max_gap_s || held) {
                    return None;
                }
                (p.position, *p.attitude.to_rotation_matrix().matrix())
            }
        };
        Some((offset_position(&origin, &(c * self.receivers[k])), c))
    }

    /// What receiver `k`'s range closed at `t` (measured `z`) predicts for the vehicle's state
    /// `s` (its past poses from the history, else the state's own).
    fn predict(&self, s: &NavState, k: usize, t: f64, z: f64) -> Option<RangePrediction> {
        let (legs, n) = self.legs(t, z);
        self.predict_legs(s, k, &legs[..n])
    }

    /// What receiver `k`'s range along `legs` (one or two) predicts for the vehicle's state `s`.
    fn predict_legs(&self, s: &NavState, k: usize, legs: &[Leg]) -> Option<RangePrediction> {
        let n = legs.len();
        let mut out = RangePrediction {
            legs: [(Vector3::zeros(), Vector3::zeros()); 2],
            n,
            array_variance_m2: 0.0,
        };
        for (i, leg) in legs.iter().enumerate() {
            let (position, attitude) = match self.vehicle.at(leg.vehicle_s) {
                Some(p) => (p.position, p.attitude),
                None => (s.position, s.q_body_to_ned),
            };
            let lever_ned = attitude * self.lever_arm_b;
            let transducer = offset_position(&position, &lever_ned);
            let (receiver, c) = self.receiver_at(k, leg.receiver_s)?;
            let d = ned_offset(&receiver, &transducer);
            out.legs[i] = (d, lever_ned);
            if self.cfg.array == ArrayKind::Moving {
                // The array's horizontal position error and its heading error (which swings
                // the receiver about the origin) along the line of sight.
                let u = d / d.norm().max(1e-3);
                let (sp, sh) = self.array_std;
                let swing = Vector3::z().cross(&(c * self.receivers[k]));
                out.array_variance_m2 +=
                    (sp * sp * (u.x * u.x + u.y * u.y) + (sh * u.dot(&swing)).powi(2)) / n as f64;
            }
        }
        Some(out)
    }
}

#[cfg(test)]
pub(crate) mod tests;
