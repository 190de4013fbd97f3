//! Dead reckoning without an IMU: a compass's (or an AHRS's) heading, pitch and roll and the DVL's
//! velocity, through the DVL installation the filter uses ([`DvlParameters`]: mounting, scale
//! factor, lever arm, time offset), integrated into a track of the reference point. This is how a
//! boat's ADCP or a small vehicle without an inertial unit navigates, and what a surface run with
//! GNSS throughout scores a DVL installation on, independently of the DVL.
//!
//! A reading stamped `t` describes the velocity at `t − τ` (τ the time offset). At that moment the
//! reference point's velocity in the body frame is `v_b = C_d^b v_dvl / s − ω_eb × l`, with the
//! body rate `ω_eb` from the attitude series (its change between the samples around the moment)
//! and `l` the DVL's position in the body frame; the attitude there, interpolated, turns it to
//! north-east-down. Positions follow by the trapezoidal rule between readings, on a local plane
//! around the start (the runs are kilometres, not hundreds).

use crate::aid::dvl::DvlParameters;
use nalgebra::{UnitQuaternion, Vector3};

/// A compass's deviation (rad) at the heading it shows, `psi_c` (rad), from the classical
/// coefficients `[A, B, C, D, E]` (deg): `A + B sin ψc + C cos ψc + D sin 2ψc + E cos 2ψc` (the
/// simulator's `heading.deviation`; a deviation card is drawn up against the compass heading).
/// The compass shows `ψc` with `ψc − δ(ψc) = ψ`, the heading it should show.
pub fn compass_deviation_rad(psi_c: f64, coefficients_deg: &[f64; 5]) -> f64 {
    let [a, b, c, d, e] = coefficients_deg.map(f64::to_radians);
    a + b * psi_c.sin() + c * psi_c.cos() + d * (2.0 * psi_c).sin() + e * (2.0 * psi_c).cos()
}

/// The heading a compass with deviation `coefficients_deg` shows when the heading is `psi`
/// (rad): the solution of `ψc − δ(ψc) = ψ`, by fixed-point iteration (a contraction for
/// deviations below 57°/(|B|+|C|+2|D|+2|E|) rad⁻¹, far beyond any compass).
pub fn compass_reading_rad(psi: f64, coefficients_deg: &[f64; 5]) -> f64 {
    let mut psi_c = psi;
    for _ in 0..20 {
        psi_c = psi + compass_deviation_rad(psi_c, coefficients_deg);
    }
    psi_c
}

/// Attitude samples with a compass deviation taken out of their heading.
pub fn without_deviation(
    samples: &[AttitudeSample],
    coefficients_deg: &[f64; 5],
) -> Vec<AttitudeSample> {
    if coefficients_deg.iter().all(|c| *c == 0.0) {
        return samples.to_vec();
    }
    samples
        .iter()
        .map(|s| {
            let (r, p, y) = s.attitude.euler_angles();
            AttitudeSample::from_euler(
                s.t_s,
                [r, p, y - compass_deviation_rad(y, coefficients_deg)],
            )
        })
        .collect()
}

/// One attitude sample: time (s) and body-to-NED attitude.
#[derive(Debug, Clone, Copy)]
pub struct AttitudeSample {
    pub t_s: f64,
    pub attitude: UnitQuaternion<f64>,
}

impl AttitudeSample {
    /// From roll, pitch and heading (rad, ZYX).
    pub fn from_euler(t_s: f64, euler_rad: [f64; 3]) -> AttitudeSample {
        AttitudeSample {
            t_s,
            attitude: UnitQuaternion::from_euler_angles(euler_rad[0], euler_rad[1], euler_rad[2]),
        }
    }
}

/// One DVL reading: its time stamp (s) and velocity in the DVL frame (m/s).
#[derive(Debug, Clone, Copy)]
pub struct DvlReading {
    pub t_s: f64,
    pub velocity_dvl: Vector3<f64>,
}

/// A dead-reckoned track: times (s) and north, east (m) from the start position.
#[derive(Debug, Clone, Default)]
pub struct Track {
    pub t_s: Vec<f64>,
    pub north_east_m: Vec<[f64; 2]>,
    /// Readings left out: no attitude around their moment (a gap longer than the limit, or
    /// outside the attitude series).
    pub without_attitude: u64,
    /// Gaps between consecutive readings longer than the bridging limit (the track holds the
    /// velocity across them by the trapezoidal rule and counts them).
    pub long_gaps: u64,
}

impl Track {
    /// North and east at `t` (linear between the track's points), `None` outside the track.
    pub fn at(&self, t: f64) -> Option<[f64; 2]> {
        let i = self.t_s.partition_point(|x| *x <= t);
        if i == 0 {
            return (self.t_s.first() == Some(&t)).then(|| self.north_east_m[0]);
        }
        if i == self.t_s.len() {
            return (self.t_s.last() == Some(&t)).then(|| self.north_east_m[i - 1]);
        }
        let (a, b) = (self.t_s[i - 1], self.t_s[i]);
        let f = (t - a) / (b - a);
        let (p, q) = (self.north_east_m[i - 1], self.north_east_m[i]);
        Some([p[0] + (q[0] - p[0]) * f, p[1] + (q[1] - p[1]) * f])
    }
}

/// The attitude series, interpolated and differentiated.
pub struct AttitudeSeries<'a> {
    samples: &'a [AttitudeSample],
    /// The longest interval between two samples bridged by interpolation (s).
    pub max_gap_s: f64,
}

impl<'a> AttitudeSeries<'a> {
    /// `samples` in increasing time.
    pub fn new(samples: &'a [AttitudeSample], max_gap_s: f64) -> AttitudeSeries<'a> {
        AttitudeSeries { samples, max_gap_s }
    }

    fn bracket(&self, t: f64) -> Option<(&AttitudeSample, &AttitudeSample)> {
        let i = self.samples.partition_point(|s| s.t_s < t);
        let (a, b) = if i == 0 {
            // At the first sample exactly: it and the next.
            let first = self.samples.first()?;
            if first.t_s != t {
                return None;
            }
            (first, self.samples.get(1)?)
        } else {
            (&self.samples[i - 1], self.samples.get(i)?)
        };
        (b.t_s > a.t_s && b.t_s - a.t_s <= self.max_gap_s).then_some((a, b))
    }

    /// The attitude at `t` and the body rate relative to the Earth (rad/s, body frame) over the
    /// interval around it.
    pub fn at(&self, t: f64) -> Option<(UnitQuaternion<f64>, Vector3<f64>)> {
        let (a, b) = self.bracket(t)?;
        let f = (t - a.t_s) / (b.t_s - a.t_s);
        let q = a
            .attitude
            .try_slerp(&b.attitude, f, 1e-12)
            .unwrap_or(a.attitude);
        // C_b(a)→b(b) = q_a⁻¹ q_b: the rotation the body turned through, in the body frame.
        let turn = (a.attitude.inverse() * b.attitude).scaled_axis();
        Some((q, turn / (b.t_s - a.t_s)))
    }
}

/// The reference point's north-east-down velocity that DVL reading `r` describes, and the moment
/// it describes (`t − τ`); `None` without attitude there.
pub fn reference_velocity(
    r: &DvlReading,
    attitude: &AttitudeSeries,
    p: &DvlParameters,
) -> Option<(f64, Vector3<f64>)> {
    let t = r.t_s - p.time_offset_s;
    let (q, omega) = attitude.at(t)?;
    let v_b = p.c_dvl_to_body * r.velocity_dvl / p.scale - omega.cross(&p.lever_arm_m);
    Some((t, q * v_b))
}

/// Dead reckoning of `readings` (increasing time) from `start_ne` (m) at the first usable
/// reading's moment. Consecutive readings further apart than `max_gap_s` are counted as long
/// gaps (the trapezoid bridges them).
pub fn dead_reckon(
    readings: &[DvlReading],
    attitude: &AttitudeSeries,
    p: &DvlParameters,
    start_ne: [f64; 2],
    max_gap_s: f64,
) -> Track {
    let mut track = Track::default();
    let mut last: Option<(f64, Vector3<f64>)> = None;
    let mut position = start_ne;
    for r in readings {
        let Some((t, v)) = reference_velocity(r, attitude, p) else {
            track.without_attitude += 1;
            continue;
        };
        if let Some((t0, v0)) = last {
            if t <= t0 {
                continue;
            }
            let dt = t - t0;
            if dt > max_gap_s {
                track.long_gaps += 1;
            }
            position[0] += 0.5 * (v0.x + v.x) * dt;
            position[1] += 0.5 * (v0.y + v.y) * dt;
        }
        track.t_s.push(t);
        track.north_east_m.push(position);
        last = Some((t, v));
    }
    track
}

#[cfg(test)]
mod tests {
    use super::*;

    const DEG: f64 = std::f64::consts::PI / 180.0;

    /// A boat turning at a constant rate at constant speed, with a DVL mounted at a yaw, a scale
    /// factor, a lever arm and a time offset: the installation undoes it and the track follows
    /// the circle the reference point describes.
    #[test]
    fn the_installation_undoes_what_it_describes_on_a_turning_boat() {
        let (speed, rate) = (1.5, 3.0 * DEG);
        let p = DvlParameters::new([0.0, 0.0, 4.0], 1.01, [0.5, -0.3, 0.8], 0.4);
        let heading = |t: f64| 0.3 + rate * t;
        // The reference point moves along its heading; its position on the circle.
        let position = |t: f64| {
            let r = speed / rate;
            [
                r * (heading(t).sin() - 0.3f64.sin()),
                -r * (heading(t).cos() - 0.3f64.cos()),
            ]
        };
        let samples: Vec<AttitudeSample> = (0..=2400)
            .map(|k| {
                let t = k as f64 * 0.1;
                AttitudeSample::from_euler(t, [0.0, 0.0, heading(t)])
            })
            .collect();
        let series = AttitudeSeries::new(&samples, 1.0);
        let omega = Vector3::new(0.0, 0.0, rate);
        let readings: Vec<DvlReading> = (1..=235)
            .map(|k| {
                let t = k as f64;
                // What the DVL reads at t: the velocity of its own point at t − τ, scaled, in
                // its frame.
                let v_b = Vector3::new(speed, 0.0, 0.0) + omega.cross(&p.lever_arm_m);
                DvlReading {
                    t_s: t,
                    velocity_dvl: p.c_dvl_to_body.transpose() * v_b * p.scale,
                }
            })
            .collect();
        let start_t = 1.0 - p.time_offset_s;
        let track = dead_reckon(&readings, &series, &p, position(start_t), 5.0);
        assert_eq!(track.without_attitude, 0);
        for (t, ne) in track.t_s.iter().zip(&track.north_east_m) {
            let truth = position(*t);
            let e = (ne[0] - truth[0]).hypot(ne[1] - truth[1]);
            // The trapezoid on a circle of 28.6 m at 1 s steps: millimetres.
            assert!(e < 0.02, "t {t}: {ne:?} against {truth:?}");
        }
        // Without the installation the same readings wander off by metres.
        let nominal = DvlParameters::new([0.0; 3], 1.0, [0.0; 3], 0.0);
        let wrong = dead_reckon(&readings, &series, &nominal, position(1.0), 5.0);
        let worst = wrong
            .t_s
            .iter()
            .zip(&wrong.north_east_m)
            .map(|(t, ne)| {
                let truth = position(*t);
                (ne[0] - truth[0]).hypot(ne[1] - truth[1])
            })
            .fold(0.0, f64::max);
        assert!(worst > 1.0, "{worst}");
    }

    #[test]
    fn a_compass_reading_gives_back_its_heading_once_the_deviation_is_taken_out() {
        let c = [1.5, 3.0, -2.0, 0.8, -0.5];
        for k in 0..72 {
            let psi = (k as f64 * 5.0 - 180.0) * DEG;
            let shown = compass_reading_rad(psi, &c);
            let back = shown - compass_deviation_rad(shown, &c);
            assert!((back - psi).abs() < 1e-10, "{psi}: {back}");
            // Two-cycle and one-cycle parts as the card says, at the heading shown.
            assert!((shown - psi).abs() <= (1.5 + 3.0 + 2.0 + 0.8 + 0.5) * DEG);
        }
        let samples = [AttitudeSample::from_euler(
            0.0,
            [0.01, -0.02, compass_reading_rad(1.0, &c)],
        )];
        let (r, p, y) = without_deviation(&samples, &c)[0].attitude.euler_angles();
        assert!((r - 0.01).abs() < 1e-12 && (p + 0.02).abs() < 1e-12 && (y - 1.0).abs() < 1e-9);
    }

    #[test]
    fn readings_outside_the_attitude_series_are_counted_not_guessed() {
        let samples = [
            AttitudeSample::from_euler(0.0, [0.0; 3]),
            AttitudeSample::from_euler(1.0, [0.0; 3]),
            AttitudeSample::from_euler(10.0, [0.0; 3]),
        ];
        let series = AttitudeSeries::new(&samples, 2.0);
        let p = DvlParameters::new([0.0; 3], 1.0, [0.0; 3], 0.0);
        let readings: Vec<DvlReading> = [0.5, 1.0, 5.0, 12.0]
            .iter()
            .map(|&t| DvlReading {
                t_s: t,
                velocity_dvl: Vector3::new(1.0, 0.0, 0.0),
            })
            .collect();
        let track = dead_reckon(&readings, &series, &p, [0.0, 0.0], 5.0);
        assert_eq!(track.t_s, vec![0.5, 1.0]);
        assert_eq!(track.without_attitude, 2);
        assert_eq!(track.at(0.75), Some([0.25, 0.0]));
        assert_eq!(track.at(2.0), None);
    }
}
