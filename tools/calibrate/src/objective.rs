//! The S-CAL objective by full replay: a voyage is dead-reckoned (INS/DVL/depth through the
//! navigation session's feed, the daemon's code) with a candidate installation, and its position
//! error at every fix beyond the distance threshold is scored as
//! `p_CEP50 = 0.8326 sqrt(sum_i (dD_i / D_i)^2 / N)`, averaged over voyages.

use super::params::installation;
use super::voyage::{Fix, Voyage};
use auvnav_core::config::NavConfig;
use auvnav_core::earth::{self, Geodetic};
use auvnav_core::feed::SensorMessage;
use auvnav_core::session::{Session, SessionConfig, SessionOutput};
use auvnav_shm_schema::{DvlVelocityV1, NavSolutionV1};
use nalgebra::{Matrix3, UnitQuaternion, Vector3};

/// The S-CAL CEP50 factor.
pub const CEP50_FACTOR: f64 = 0.8326;

/// `0.8326 sqrt(mean((error_i / distance_i)^2))` over the pairs (error m, distance m).
pub fn cep50(points: &[(f64, f64)]) -> f64 {
    if points.is_empty() {
        return f64::NAN;
    }
    let s: f64 = points.iter().map(|(e, d)| (e / d).powi(2)).sum();
    CEP50_FACTOR * (s / points.len() as f64).sqrt()
}

/// What a run records besides the errors at the fixes.
#[derive(Debug, Clone, Copy, Default)]
pub struct Record {
    /// The dead-reckoned track (1 sample per second) for plots and distances.
    pub track: bool,
    /// The DVL epochs with attitude and rates for the sensitivities of the fast method.
    pub epochs: bool,
}

/// A DVL epoch as the navigator met it: the measurement and the state around it.
#[derive(Debug, Clone, Copy)]
pub struct DvlEpoch {
    pub t_s: f64,
    pub z: Vector3<f64>,
    pub c_body_to_ned: Matrix3<f64>,
    pub omega_body: Vector3<f64>,
    pub v_body: Vector3<f64>,
}

/// One voyage dead-reckoned with one installation.
#[derive(Debug, Clone, Default)]
pub struct VoyageRun {
    /// Horizontal error (north, east; m) of the dead reckoning at each fix, in fix order.
    pub errors_ne: Vec<[f64; 2]>,
    /// Dead-reckoned position at each fix.
    pub positions: Vec<Geodetic>,
    pub track: Vec<(u64, Geodetic)>,
    pub epochs: Vec<DvlEpoch>,
    pub dvl_fused: u64,
    pub dvl_rejected: u64,
}

impl VoyageRun {
    /// The (error, distance) pairs of the fixes at or beyond `threshold_m`.
    pub fn scored(&self, fixes: &[Fix], threshold_m: f64) -> Vec<(f64, f64)> {
        self.errors_ne
            .iter()
            .zip(fixes)
            .filter(|(_, f)| f.distance_m >= threshold_m && f.distance_m > 0.0)
            .map(|(e, f)| (e[0].hypot(e[1]), f.distance_m))
            .collect()
    }

    pub fn cep50(&self, fixes: &[Fix], threshold_m: f64) -> f64 {
        cep50(&self.scored(fixes, threshold_m))
    }
}

fn position(s: &NavSolutionV1) -> Geodetic {
    Geodetic {
        latitude_rad: s.latitude_rad,
        longitude_rad: s.longitude_rad,
        height_m: s.height_m,
    }
}

/// Follows the solutions: positions at the fixes (interpolated), the 1 Hz track.
struct Tracker<'a> {
    fixes: &'a [Fix],
    next_fix: usize,
    prev: Option<NavSolutionV1>,
    next_track_ns: u64,
    record: Record,
}

impl Tracker<'_> {
    fn on_solution(&mut self, sol: &NavSolutionV1, run: &mut VoyageRun) {
        if let Some(p) = self.prev {
            while self.next_fix < self.fixes.len()
                && self.fixes[self.next_fix].time_ns <= sol.host_time_ns
            {
                let f = &self.fixes[self.next_fix];
                let pos = if f.time_ns <= p.host_time_ns {
                    position(&p)
                } else {
                    position(&auvnav_replay::interpolate(&p, sol, f.time_ns))
                };
                let o = earth::ned_offset(&f.position, &pos);
                run.errors_ne.push([o.x, o.y]);
                run.positions.push(pos);
                self.next_fix += 1;
            }
        }
        if self.record.track && sol.host_time_ns >= self.next_track_ns {
            run.track.push((sol.host_time_ns, position(sol)));
            self.next_track_ns = sol.host_time_ns + 1_000_000_000;
        }
        self.prev = Some(*sol);
    }
}

/// Dead-reckons `voyage` with the installation `x` (eight parameters) on top of `nav`.
pub fn run_voyage(
    voyage: &Voyage,
    nav: &NavConfig,
    x: &[f64; 8],
    record: Record,
) -> anyhow::Result<VoyageRun> {
    let mut navigation = nav.clone();
    navigation.set_dvl_installation(installation(x));
    let cfg = SessionConfig {
        navigation,
        ..Default::default()
    };
    let mut session = Session::new(&cfg);
    let mut run = VoyageRun::default();
    let mut t = Tracker {
        fixes: &voyage.fixes,
        next_fix: 0,
        prev: None,
        next_track_ns: 0,
        record,
    };
    let mut outputs: Vec<NavSolutionV1> = Vec::new();
    fn sink(
        outputs: &mut Vec<NavSolutionV1>,
    ) -> impl FnMut(SessionOutput) -> Result<(), std::convert::Infallible> + '_ {
        move |o| {
            if let SessionOutput::Solution(s) = o {
                outputs.push(*s);
            }
            Ok(())
        }
    }
    let Ok(()) = session.start(voyage.start, "voyage start", &mut sink(&mut outputs));
    for s in outputs.drain(..) {
        t.on_solution(&s, &mut run);
    }
    let mut last_rate = Vector3::zeros();
    for m in &voyage.inputs {
        if let SensorMessage::Imu(x) = m
            && let Some(w) = x.angular_rate()
        {
            last_rate = Vector3::from(w);
        }
        if record.epochs
            && let SensorMessage::Dvl(d) = m
            && d.validity & DvlVelocityV1::VALID_VELOCITY != 0
            && !d.is_water_track()
            && let Some(s) = t.prev
        {
            let q = s.quaternion_body_to_ned;
            let c =
                UnitQuaternion::from_quaternion(nalgebra::Quaternion::new(q[0], q[1], q[2], q[3]))
                    .to_rotation_matrix()
                    .into_inner();
            run.epochs.push(DvlEpoch {
                t_s: d.validity_time_ns as f64 * 1e-9,
                z: Vector3::from(d.velocity_dvl_m_s),
                c_body_to_ned: c,
                omega_body: last_rate,
                v_body: c.transpose() * Vector3::from(s.velocity_ned_m_s),
            });
        }
        let Ok(()) = session.feed(m, &mut sink(&mut outputs));
        for s in outputs.drain(..) {
            t.on_solution(&s, &mut run);
        }
    }
    let Ok(()) = session.finish(&mut sink(&mut outputs));
    for s in outputs.drain(..) {
        t.on_solution(&s, &mut run);
    }
    // Fixes after the last solution take the last position.
    if let Some(p) = t.prev {
        while t.next_fix < t.fixes.len() {
            let f = &t.fixes[t.next_fix];
            let pos = position(&p);
            let o = earth::ned_offset(&f.position, &pos);
            run.errors_ne.push([o.x, o.y]);
            run.positions.push(pos);
            t.next_fix += 1;
        }
    }
    if let Some(n) = session.navigator() {
        let c = n.counters();
        run.dvl_fused = c.dvl_fused;
        run.dvl_rejected = c.dvl_rejected;
    }
    Ok(run)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn cep50_is_the_s_cal_formula_on_a_hand_computed_case() {
        // Errors 3, 4 and 12 m at 1000, 2000 and 3000 m: ratios 0.003, 0.002, 0.004;
        // mean of squares (9 + 4 + 16) e-6 / 3 = 9.6667e-6; sqrt = 3.1091e-3; x 0.8326.
        let p = [(3.0, 1000.0), (4.0, 2000.0), (12.0, 3000.0)];
        let expected = 0.8326 * (29.0e-6f64 / 3.0).sqrt();
        assert!((cep50(&p) - expected).abs() < 1e-15);
        assert!((expected - 0.002_588_6).abs() < 1e-6);
        assert!(cep50(&[]).is_nan());
    }
}
