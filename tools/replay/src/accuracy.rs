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
    distance_m: f64,
    last_truth: Option<Geodetic>,
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
            distance_travelled_m: self.distance_m,
            epochs: self.errors.len(),
        }
    }
}
