//! Accuracy of a navigation solution against a truth trajectory.

use auvnav_core::earth::{self, Geodetic};
use auvnav_shm_schema::{NavSolutionV1, TruthStateV1};
use serde::Serialize;

/// S-CAL's factor from the RMS of the relative error to its 50 % circular error probable.
pub const SCAL_CEP50_FACTOR: f64 = 0.8326;

/// Accumulates the errors at the epochs where a solution and the truth coincide.
#[derive(Debug, Clone, Default)]
pub struct AccuracyTracker {
    /// Points beyond this distance travelled enter the error/distance figure (m).
    pub min_distance_m: f64,
    errors: Vec<f64>,
    relative_sq: Vec<f64>,
    heading_sq: Vec<f64>,
    velocity_sq: Vec<f64>,
    distance_m: f64,
    last_truth: Option<Geodetic>,
    /// The truth's own position against the integral of its velocity: the first truth point,
    /// the last truth record (time s, horizontal NED velocity), the integral so far (m, N and
    /// E from the first point) and the squared departures.
    own: Option<(Geodetic, f64, [f64; 2], [f64; 2])>,
    own_sq: Vec<f64>,
}

#[derive(Debug, Clone, Default, PartialEq, Serialize)]
pub struct Accuracy {
    pub horizontal_error_final_m: f64,
    pub horizontal_error_max_m: f64,
    pub horizontal_error_rms_m: f64,
    pub horizontal_error_cep50_m: f64,
    /// 0.8326 sqrt(mean((dD/D)^2)) over the points beyond `min_distance_m`, in percent.
    pub error_per_distance_cep50_percent: f64,
    pub heading_error_rms_deg: f64,
    /// RMS of the horizontal velocity error at the truth epochs with a finite truth velocity
    /// (m/s; 0 without one).
    pub horizontal_velocity_error_rms_m_s: f64,
    /// The truth's own consistency: the RMS over its epochs of the horizontal distance between
    /// its position and the integral of its velocity from the first epoch (trapezoids; m). A
    /// simulated truth gives millimetres; a post-processed reference that merges position
    /// fixes gives its own position error against its velocity, and a difference between two
    /// navigation runs smaller than this is not resolved by the reference's position.
    pub truth_position_against_velocity_rms_m: f64,
    pub distance_travelled_m: f64,
    pub epochs: usize,
}

/// An angle wrapped to -pi..pi (rad).
pub use auvnav_core::earth::wrap_pi as wrap;

/// What the accuracy figures read of a solution: its time, position and heading (a replay keeps
/// the last one of these, not the whole 248-byte solution, for the comparison with the truth).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SolutionPoint {
    pub host_time_ns: u64,
    pub position: Geodetic,
    pub heading_rad: f64,
    /// North and east velocity (m/s).
    pub velocity_ne_m_s: [f64; 2],
}

impl SolutionPoint {
    pub fn of(s: &NavSolutionV1) -> SolutionPoint {
        SolutionPoint {
            host_time_ns: s.host_time_ns,
            position: Geodetic {
                latitude_rad: s.latitude_rad,
                longitude_rad: s.longitude_rad,
                height_m: s.height_m,
            },
            heading_rad: s.euler_rad[2],
            velocity_ne_m_s: [s.velocity_ned_m_s[0], s.velocity_ned_m_s[1]],
        }
    }

    /// The point at `t_ns` between `a` and `b`, by the rule of [`crate::replay::interpolate`]
    /// (position and heading linear in time).
    pub fn interpolate(a: &SolutionPoint, b: &SolutionPoint, t_ns: u64) -> SolutionPoint {
        let span = b.host_time_ns.saturating_sub(a.host_time_ns);
        if span == 0 {
            return *b;
        }
        let w = t_ns.saturating_sub(a.host_time_ns) as f64 / span as f64;
        let lerp = |x: f64, y: f64| x + (y - x) * w;
        let (pa, pb) = (&a.position, &b.position);
        SolutionPoint {
            host_time_ns: t_ns,
            position: Geodetic {
                latitude_rad: lerp(pa.latitude_rad, pb.latitude_rad),
                longitude_rad: lerp(pa.longitude_rad, pb.longitude_rad),
                height_m: lerp(pa.height_m, pb.height_m),
            },
            heading_rad: a.heading_rad + wrap(b.heading_rad - a.heading_rad) * w,
            velocity_ne_m_s: [0, 1].map(|k| lerp(a.velocity_ne_m_s[k], b.velocity_ne_m_s[k])),
        }
    }
}

impl AccuracyTracker {
    pub fn new(min_distance_m: f64) -> Self {
        AccuracyTracker {
            min_distance_m,
            ..Default::default()
        }
    }

    /// Adds one epoch; `nav` and `truth` must refer to the same time.
    pub fn add(&mut self, nav: &NavSolutionV1, truth: &TruthStateV1) {
        self.add_point(&SolutionPoint::of(nav), truth);
    }

    /// [`AccuracyTracker::add`] for the part of a solution the figures read.
    pub fn add_point(&mut self, nav: &SolutionPoint, truth: &TruthStateV1) {
        let t = Geodetic {
            latitude_rad: truth.latitude_rad,
            longitude_rad: truth.longitude_rad,
            height_m: truth.height_m,
        };
        if let Some(prev) = self.last_truth {
            self.distance_m += earth::ned_offset(&prev, &t).xy().norm();
        }
        self.last_truth = Some(t);
        let e = earth::ned_offset(&t, &nav.position).xy().norm();
        self.errors.push(e);
        if self.distance_m > self.min_distance_m {
            self.relative_sq.push((e / self.distance_m).powi(2));
        }
        self.heading_sq
            .push(wrap(nav.heading_rad - truth.euler_rad[2]).powi(2));
        let v = [truth.velocity_ned_m_s[0], truth.velocity_ned_m_s[1]];
        if v.iter().all(|x| x.is_finite()) {
            let d = [0, 1].map(|k| nav.velocity_ne_m_s[k] - v[k]);
            self.velocity_sq.push(d[0] * d[0] + d[1] * d[1]);
            self.integrate_own(&t, truth.host_time_ns as f64 * 1e-9, v);
        }
    }

    /// The truth's position against the integral of its own velocity (see
    /// [`Accuracy::truth_position_against_velocity_rms_m`]).
    fn integrate_own(&mut self, p: &Geodetic, t_s: f64, v: [f64; 2]) {
        let Some((first, last_t, last_v, sum)) = self.own.as_mut() else {
            self.own = Some((*p, t_s, v, [0.0; 2]));
            return;
        };
        let dt = t_s - *last_t;
        for k in 0..2 {
            sum[k] += 0.5 * (last_v[k] + v[k]) * dt;
        }
        (*last_t, *last_v) = (t_s, v);
        let at = earth::ned_offset(first, p);
        self.own_sq
            .push((at.x - sum[0]).powi(2) + (at.y - sum[1]).powi(2));
    }

    pub fn result(&self) -> Accuracy {
        let mut sorted = self.errors.clone();
        sorted.sort_by(f64::total_cmp);
        let median = if sorted.is_empty() {
            0.0
        } else {
            sorted[sorted.len() / 2]
        };
        let mean = |v: &[f64]| {
            if v.is_empty() {
                0.0
            } else {
                v.iter().sum::<f64>() / v.len() as f64
            }
        };
        Accuracy {
            horizontal_error_final_m: self.errors.last().copied().unwrap_or(0.0),
            horizontal_error_max_m: sorted.last().copied().unwrap_or(0.0),
            horizontal_error_rms_m: mean(&self.errors.iter().map(|e| e * e).collect::<Vec<_>>())
                .sqrt(),
            horizontal_error_cep50_m: median,
            error_per_distance_cep50_percent: 100.0
                * SCAL_CEP50_FACTOR
                * mean(&self.relative_sq).sqrt(),
            heading_error_rms_deg: mean(&self.heading_sq).sqrt().to_degrees(),
            horizontal_velocity_error_rms_m_s: mean(&self.velocity_sq).sqrt(),
            truth_position_against_velocity_rms_m: mean(&self.own_sq).sqrt(),
            distance_travelled_m: self.distance_m,
            epochs: self.errors.len(),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A truth record at `t` s going north at 2 m/s from latitude 0.6, its position moved
    /// north by `shift` m.
    fn truth(t: f64, shift: f64) -> TruthStateV1 {
        let lat0 = 0.6;
        let north = 2.0 * t + shift;
        TruthStateV1 {
            host_time_ns: (t * 1e9) as u64,
            latitude_rad: lat0 + north / earth::meridian_radius(lat0),
            longitude_rad: 0.3,
            velocity_ned_m_s: [2.0, 0.0, 0.0],
            ..Default::default()
        }
    }

    fn point(t: &TruthStateV1, v_north: f64) -> SolutionPoint {
        SolutionPoint {
            host_time_ns: t.host_time_ns,
            position: Geodetic {
                latitude_rad: t.latitude_rad,
                longitude_rad: t.longitude_rad,
                height_m: t.height_m,
            },
            heading_rad: 0.0,
            velocity_ne_m_s: [v_north, 0.0],
        }
    }

    #[test]
    fn velocity_error_and_the_truths_own_consistency() {
        // A consistent truth and a solution 0.03 m/s fast on its positions.
        let mut a = AccuracyTracker::new(0.0);
        for k in 0..100 {
            let t = truth(k as f64, 0.0);
            a.add_point(&point(&t, 2.03), &t);
        }
        let r = a.result();
        assert!(
            (r.horizontal_velocity_error_rms_m_s - 0.03).abs() < 1e-9,
            "{r:?}"
        );
        assert!(r.truth_position_against_velocity_rms_m < 1e-3, "{r:?}");
        // A reference whose position is pulled 1 m north at half time (a fix merged into it)
        // while its velocity says nothing of it: it departs from its own velocity by 1 m over
        // half its epochs, 0.71 m RMS.
        let mut b = AccuracyTracker::new(0.0);
        for k in 0..101 {
            let t = truth(k as f64, if k > 50 { 1.0 } else { 0.0 });
            b.add_point(&point(&t, 2.0), &t);
        }
        let r = b.result();
        assert!(
            (r.truth_position_against_velocity_rms_m - 0.5f64.sqrt()).abs() < 1e-2,
            "{r:?}"
        );
        assert_eq!(r.horizontal_velocity_error_rms_m_s, 0.0);
    }
}
