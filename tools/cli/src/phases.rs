//! What a demo run did, phase by phase, against the simulated truth: the in-motion alignment
//! (the first heading the navigator published, when it declared itself aligned and how wrong its
//! heading was then), the navigation between alignment and the first USBL fix, and the USBL
//! homing (fixes fused and rejected, the largest range innovation fused, the horizontal error).
//!
//! Every time here is on the simulator's axis (s): an in-process run stamps its messages with it;
//! a live run's host times are mapped onto it by the caller (see `crate::live`).

use auvnav_core::earth::{Geodetic, ned_offset, wrap_pi};
use auvnav_shm_schema::{AidDiagnosticsV1, AidSource, NavMode, NavSolutionV1, TruthStateV1};
use serde::Serialize;

/// What the phase figures keep of a solution.
#[derive(Debug, Clone, Copy)]
struct TrackPoint {
    t_s: f64,
    position: Geodetic,
    heading_rad: f64,
    mode: u32,
}

/// What they keep of a truth record.
#[derive(Debug, Clone, Copy)]
struct TruthPoint {
    t_s: f64,
    position: Geodetic,
    heading_rad: f64,
}

/// What they keep of a USBL diagnostic.
#[derive(Debug, Clone, Copy)]
struct UsblOutcome {
    t_s: f64,
    fused: bool,
    range_innovation_m: f64,
}

/// Time the USBL phase's error figures leave the filter to take in the first fixes (s).
pub const USBL_SETTLE_S: f64 = 30.0;

/// Collects solutions, truth and USBL diagnostics as a run produces them.
#[derive(Debug, Default)]
pub struct PhaseRecorder {
    track: Vec<TrackPoint>,
    truth: Vec<TruthPoint>,
    usbl: Vec<UsblOutcome>,
    first_imu_s: Option<f64>,
    /// The heading (rad) and horizontal position (m) standard deviations of the first aligned
    /// solution.
    aligned_std: Option<(f64, f64)>,
}

/// The alignment as the navigator reported it.
#[derive(Debug, Clone, Serialize, PartialEq)]
pub struct AlignmentFigures {
    /// Heading error of the first solution published (the coarse stage's first estimate: the
    /// navigator starts without a heading) (deg).
    pub first_heading_error_deg: f64,
    /// Time from the first IMU sample to the first solution in a navigating mode, i.e. when the
    /// navigator declared itself aligned (s); `None` when it never did.
    pub aligned_after_s: Option<f64>,
    /// Heading error of that solution (deg).
    pub heading_error_at_aligned_deg: Option<f64>,
    /// Heading standard deviation the navigator reported with it (deg).
    pub heading_std_at_aligned_deg: Option<f64>,
    /// Horizontal position error of that solution (m), and the standard deviation the navigator
    /// reported with it (m, the root sum of the north and east variances).
    pub horizontal_error_at_aligned_m: Option<f64>,
    pub horizontal_std_at_aligned_m: Option<f64>,
}

/// Horizontal position error over a time window, at the truth records inside it.
#[derive(Debug, Clone, Serialize, PartialEq)]
pub struct ErrorFigures {
    pub from_s: f64,
    pub to_s: f64,
    pub horizontal_error_rms_m: f64,
    pub horizontal_error_max_m: f64,
    pub horizontal_error_final_m: f64,
    pub epochs: usize,
}

/// The USBL homing.
#[derive(Debug, Clone, Serialize, PartialEq)]
pub struct UsblFigures {
    /// Time of the first USBL fix the navigator used or refused (s after the first IMU sample).
    pub first_fix_after_s: f64,
    /// Fixes the navigator fused and those it rejected (its gate: innovation test).
    pub fused: u64,
    pub rejected: u64,
    /// Multipath outliers in the simulated fixes (known to the simulator, not to the navigator).
    pub outliers_simulated: u64,
    /// The largest slant-range innovation among the fused fixes (m): an outlier (10 m or more of
    /// extra path) fused would show here.
    pub largest_fused_range_innovation_m: f64,
    /// Horizontal error at the first fix: what the navigation before it left.
    pub horizontal_error_at_first_fix_m: Option<f64>,
    /// Horizontal error once the filter has taken in the fixes, from `USBL_SETTLE_S` after the
    /// first one to the end.
    pub error: Option<ErrorFigures>,
}

/// The figures of a run, phase by phase.
#[derive(Debug, Clone, Serialize, PartialEq)]
pub struct PhaseFigures {
    pub alignment: Option<AlignmentFigures>,
    /// Horizontal error from the moment of alignment (or the start) to the first USBL fix (or
    /// the end).
    pub before_usbl: Option<ErrorFigures>,
    pub usbl: Option<UsblFigures>,
}

impl PhaseRecorder {
    pub fn new() -> PhaseRecorder {
        PhaseRecorder::default()
    }

    /// The time of the first IMU sample (the start of the run).
    pub fn imu(&mut self, t_s: f64) {
        self.first_imu_s.get_or_insert(t_s);
    }

    pub fn solution(&mut self, t_s: f64, s: &NavSolutionV1) {
        if !s.all_finite() {
            return;
        }
        self.track.push(TrackPoint {
            t_s,
            position: Geodetic {
                latitude_rad: s.latitude_rad,
                longitude_rad: s.longitude_rad,
                height_m: s.height_m,
            },
            heading_rad: s.euler_rad[2],
            mode: s.mode,
        });
        // The standard deviation at the moment of alignment, kept once.
        if self.aligned_std.is_none() && aligned(s.mode) {
            let [n, e, _] = s.position_std_ned_m;
            self.aligned_std = Some((s.attitude_std_rad[2], n.hypot(e)));
        }
    }

    pub fn truth(&mut self, t_s: f64, t: &TruthStateV1) {
        self.truth.push(TruthPoint {
            t_s,
            position: Geodetic {
                latitude_rad: t.latitude_rad,
                longitude_rad: t.longitude_rad,
                height_m: t.height_m,
            },
            heading_rad: t.euler_rad[2],
        });
    }

    /// Keeps the USBL diagnostics (position or slant range); the other aids are not phase
    /// figures.
    pub fn diagnostics(&mut self, t_s: f64, d: &AidDiagnosticsV1) {
        let usbl = d.source == AidSource::UsblSlantRange as u32
            || d.source == AidSource::UsblPosition as u32;
        if usbl {
            self.usbl.push(UsblOutcome {
                t_s,
                fused: d.flags & AidDiagnosticsV1::FLAG_FUSED != 0,
                range_innovation_m: d.innovation[0],
            });
        }
    }

    /// The solution track's position at time `t_s`, interpolated between the two solutions
    /// around it.
    fn track_at(&self, t_s: f64) -> Option<Geodetic> {
        let (a, b, w) = around(&self.track, t_s, |p| p.t_s)?;
        let lerp = |x: f64, y: f64| x + w * (y - x);
        Some(Geodetic {
            latitude_rad: lerp(a.position.latitude_rad, b.position.latitude_rad),
            longitude_rad: lerp(a.position.longitude_rad, b.position.longitude_rad),
            height_m: lerp(a.position.height_m, b.position.height_m),
        })
    }

    /// The true heading at `t_s`, interpolated between the truth records around it.
    fn true_heading_at(&self, t_s: f64) -> Option<f64> {
        let (a, b, w) = around(&self.truth, t_s, |p| p.t_s)?;
        Some(a.heading_rad + w * wrap_pi(b.heading_rad - a.heading_rad))
    }

    /// The horizontal position error of a solution (m), against the truth interpolated at its
    /// time.
    fn position_error(&self, p: &TrackPoint) -> Option<f64> {
        let (a, b, w) = around(&self.truth, p.t_s, |t| t.t_s)?;
        let d = ned_offset(&a.position, &b.position) * w - ned_offset(&a.position, &p.position);
        Some(d.x.hypot(d.y))
    }

    /// The heading error of a solution (rad).
    fn heading_error(&self, p: &TrackPoint) -> Option<f64> {
        Some(wrap_pi(p.heading_rad - self.true_heading_at(p.t_s)?))
    }

    fn errors(&self, from_s: f64, to_s: f64) -> Option<ErrorFigures> {
        let mut sum = 0.0;
        let mut max: f64 = 0.0;
        let mut last = None;
        let mut n = 0;
        for t in self
            .truth
            .iter()
            .filter(|t| t.t_s >= from_s && t.t_s <= to_s)
        {
            let Some(p) = self.track_at(t.t_s) else {
                continue;
            };
            let d = ned_offset(&t.position, &p);
            let e = d.x.hypot(d.y);
            sum += e * e;
            max = max.max(e);
            last = Some(e);
            n += 1;
        }
        Some(ErrorFigures {
            from_s: from_s - self.start_s(),
            to_s: to_s - self.start_s(),
            horizontal_error_rms_m: (sum / n as f64).sqrt(),
            horizontal_error_max_m: max,
            horizontal_error_final_m: last?,
            epochs: n,
        })
    }

    fn start_s(&self) -> f64 {
        self.first_imu_s
            .or(self.track.first().map(|p| p.t_s))
            .unwrap_or(0.0)
    }

    /// The figures; `outliers_simulated` is the simulator's count of multipath outliers.
    pub fn figures(&self, outliers_simulated: u64) -> PhaseFigures {
        let start = self.start_s();
        let end = self.track.last().map_or(start, |p| p.t_s);
        let aligned_point = self.track.iter().find(|p| aligned(p.mode));
        let aligned_at = aligned_point.map(|p| p.t_s);
        let alignment = self
            .track
            .first()
            .filter(|p| !aligned(p.mode))
            .map(|first| AlignmentFigures {
                first_heading_error_deg: self
                    .heading_error(first)
                    .map_or(f64::NAN, f64::to_degrees),
                aligned_after_s: aligned_at.map(|t| t - start),
                heading_error_at_aligned_deg: aligned_point
                    .and_then(|p| self.heading_error(p))
                    .map(f64::to_degrees),
                heading_std_at_aligned_deg: self.aligned_std.map(|s| s.0.to_degrees()),
                horizontal_error_at_aligned_m: aligned_point.and_then(|p| self.position_error(p)),
                horizontal_std_at_aligned_m: self.aligned_std.map(|s| s.1),
            });
        let first_fix = self.usbl.first().map(|u| u.t_s);
        let before_usbl = self.errors(aligned_at.unwrap_or(start), first_fix.unwrap_or(end));
        let usbl = first_fix.map(|first| UsblFigures {
            first_fix_after_s: first - start,
            fused: self.usbl.iter().filter(|u| u.fused).count() as u64,
            rejected: self.usbl.iter().filter(|u| !u.fused).count() as u64,
            outliers_simulated,
            largest_fused_range_innovation_m: self
                .usbl
                .iter()
                .filter(|u| u.fused)
                .map(|u| u.range_innovation_m.abs())
                .fold(0.0, f64::max),
            horizontal_error_at_first_fix_m: self
                .errors(first, first + 1.0)
                .map(|e| e.horizontal_error_max_m),
            error: self.errors(first + USBL_SETTLE_S, end),
        });
        PhaseFigures {
            alignment,
            before_usbl,
            usbl,
        }
    }
}

/// The two records of a time-ordered series around `t_s` and the weight of the second for a
/// linear interpolation (an exact hit: the record twice, weight 0); none outside the series or
/// across a gap of over a second.
fn around<T>(v: &[T], t_s: f64, time: impl Fn(&T) -> f64) -> Option<(&T, &T, f64)> {
    let k = v.partition_point(|p| time(p) < t_s);
    let b = v.get(k)?;
    if time(b) == t_s {
        return Some((b, b, 0.0));
    }
    let a = v.get(k.checked_sub(1)?)?;
    let span = time(b) - time(a);
    (span <= 1.0).then(|| (a, b, (t_s - time(a)) / span))
}

/// A mode in which the navigator has declared itself aligned.
fn aligned(mode: u32) -> bool {
    mode == NavMode::Navigating as u32 || mode == NavMode::Degraded as u32
}

#[cfg(test)]
mod tests {
    use super::*;

    fn solution(t_s: f64, north_m: f64, heading_deg: f64, mode: NavMode) -> NavSolutionV1 {
        NavSolutionV1 {
            host_time_ns: (t_s * 1e9) as u64,
            latitude_rad: 0.5 + north_m / 6_356_752.0,
            longitude_rad: 2.0,
            euler_rad: [0.0, 0.0, heading_deg.to_radians()],
            attitude_std_rad: [0.0, 0.0, 0.2f64.to_radians()],
            position_std_ned_m: [3.0, 4.0, 1.0],
            mode: mode as u32,
            ..Default::default()
        }
    }

    #[test]
    fn the_figures_of_a_known_run_are_its_own() {
        let mut r = PhaseRecorder::new();
        r.imu(0.0);
        // Truth: at rest at the origin, heading 10 deg, 20 Hz for 100 s.
        for k in 0..=2000 {
            let t = TruthStateV1 {
                host_time_ns: k * 50_000_000,
                latitude_rad: 0.5,
                longitude_rad: 2.0,
                euler_rad: [0.0, 0.0, 10f64.to_radians()],
                ..Default::default()
            };
            r.truth(k as f64 * 0.05, &t);
        }
        // The navigator: 40 deg off first, aligned at 30 s with 0.3 deg of error and 2 m north;
        // the first fix at 50 s pulls it to 0.5 m north.
        for k in 1..=1000 {
            let t = k as f64 * 0.1;
            let s = match t {
                t if t < 30.0 => solution(t, 2.0, 50.0, NavMode::Aligning),
                t if t < 50.0 => solution(t, 2.0, 10.3, NavMode::Navigating),
                t => solution(t, 0.5, 10.3, NavMode::Navigating),
            };
            r.solution(t, &s);
        }
        for (k, (fused, innovation)) in [(true, 1.5), (false, 30.0), (true, -0.2)]
            .into_iter()
            .enumerate()
        {
            let d = AidDiagnosticsV1 {
                source: AidSource::UsblSlantRange as u32,
                flags: if fused {
                    AidDiagnosticsV1::FLAG_FUSED
                } else {
                    AidDiagnosticsV1::FLAG_REJECTED
                },
                innovation: [innovation, 0.0, 0.0],
                ..Default::default()
            };
            r.diagnostics(50.0 + k as f64, &d);
        }
        let f = r.figures(1);
        let al = f.alignment.expect("alignment");
        assert!((al.first_heading_error_deg - 40.0).abs() < 1e-9, "{al:?}");
        assert!((al.aligned_after_s.expect("aligned") - 30.0).abs() < 1e-9);
        let e = al.heading_error_at_aligned_deg.expect("heading");
        assert!((e - 0.3).abs() < 1e-9, "{e}");
        assert!((al.heading_std_at_aligned_deg.expect("std") - 0.2).abs() < 1e-9);
        assert!((al.horizontal_error_at_aligned_m.expect("error") - 2.0).abs() < 0.01);
        assert!((al.horizontal_std_at_aligned_m.expect("std") - 5.0).abs() < 1e-9);
        let b = f.before_usbl.expect("before");
        assert!((b.from_s - 30.0).abs() < 1e-9 && (b.to_s - 50.0).abs() < 1e-9);
        assert!((b.horizontal_error_rms_m - 2.0).abs() < 0.01, "{b:?}");
        let u = f.usbl.expect("usbl");
        assert_eq!((u.fused, u.rejected, u.outliers_simulated), (2, 1, 1));
        assert_eq!(u.largest_fused_range_innovation_m, 1.5);
        let after = u.error.expect("after");
        assert!((after.from_s - (50.0 + USBL_SETTLE_S)).abs() < 1e-9);
        assert!(
            (after.horizontal_error_max_m - 0.5).abs() < 0.01,
            "{after:?}"
        );
        assert!(
            (after.horizontal_error_final_m - 0.5).abs() < 0.01,
            "{after:?}"
        );
    }

    #[test]
    fn a_run_that_never_aligns_says_so_and_one_started_aligned_has_no_alignment() {
        let mut r = PhaseRecorder::new();
        for k in 0..100 {
            let t = k as f64 * 0.1;
            r.truth(t, &TruthStateV1::default());
            r.solution(t, &solution(t, 0.0, 0.0, NavMode::Aligning));
        }
        let al = r.figures(0).alignment.expect("alignment");
        assert_eq!(al.aligned_after_s, None);
        assert_eq!(al.heading_error_at_aligned_deg, None);
        let mut r = PhaseRecorder::new();
        r.solution(0.0, &solution(0.0, 0.0, 0.0, NavMode::Navigating));
        let f = r.figures(0);
        assert!(f.alignment.is_none() && f.usbl.is_none());
    }
}
