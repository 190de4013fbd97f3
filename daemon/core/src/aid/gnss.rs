//! GNSS position aid: `h(x) = p + C_b^n l` (antenna lever arm `l`), compared in local NED metres
//! around the fix; χ² gate.

use super::{AidCounters, AidUpdate, NavCore};
use crate::earth::{self, Geodetic};
use crate::ekf::{self, skew};
use crate::strapdown::NavState;
use auvnav_shm_schema::{AidSource, GnssFixV1};
use nalgebra::{Matrix3, SMatrix, Vector3};

/// The GNSS receiver's parameters and counters.
#[derive(Debug, Clone)]
pub struct GnssAid {
    /// Antenna position in the body frame (m).
    pub lever_arm_m: Vector3<f64>,
    /// Smallest one-sigma used, whatever the receiver reports (m).
    pub min_std_m: f64,
    /// χ² gate (3 dof).
    pub gate_chi2: f64,
    pub counters: AidCounters,
}

impl GnssAid {
    /// Antenna at `lever_arm_m` (body, m), smallest one-sigma `min_std_m` (m), χ² gate
    /// `gate_chi2` (3 dof).
    pub fn new(lever_arm_m: [f64; 3], min_std_m: f64, gate_chi2: f64) -> GnssAid {
        GnssAid {
            lever_arm_m: Vector3::from(lever_arm_m),
            min_std_m,
            gate_chi2,
            counters: AidCounters::default(),
        }
    }

    /// Should we fuse: position and height valid and within range, not older than the state.
    fn usable(&mut self, core: &mut NavCore, m: &GnssFixV1) -> bool {
        let need = GnssFixV1::VALID_POSITION | GnssFixV1::VALID_HEIGHT;
        if m.validity & need != need
            || !(m.latitude_rad.abs() <= std::f64::consts::FRAC_PI_2
                && m.longitude_rad.abs() <= std::f64::consts::PI
                && (-1000.0..=10000.0).contains(&m.height_m)
                && (0.0..=1000.0).contains(&m.horizontal_std_m)
                && (0.0..=1000.0).contains(&m.vertical_std_m))
        {
            self.counters.invalid += 1;
            return false;
        }
        !core.aid_is_late(m.host_time_ns)
    }

    /// Fuses a GNSS position fix.
    pub fn fuse(&mut self, core: &mut NavCore, m: &GnssFixV1) -> AidUpdate {
        let t_ns = m.host_time_ns;
        let mut d = core.diagnostics(t_ns, AidSource::GnssPosition);
        d.dimension = 3;
        if !self.usable(core, m) {
            return AidUpdate::rejected(d);
        }
        let fix = Geodetic {
            latitude_rad: m.latitude_rad,
            longitude_rad: m.longitude_rad,
            height_m: m.height_m,
        };
        core.propagate_covariance();
        let (y, h) = gnss_model(core.state(), &self.lever_arm_m, &fix);
        let sh = m.horizontal_std_m.max(self.min_std_m);
        let sv = m.vertical_std_m.max(self.min_std_m);
        let r = Matrix3::from_diagonal(&Vector3::new(sh * sh, sh * sh, sv * sv));
        d.observation = [m.latitude_rad, m.longitude_rad, m.height_m];
        d.observation_variance = r.diagonal().into();
        let result = core.kf.update(&y, &h, &r, self.gate_chi2);
        let correction = NavCore::report(result, &mut d);
        AidUpdate::counted(d, correction, &mut self.counters)
    }
}

/// The GNSS position model: the innovation `y = (p + C_b^n l) - fix` in NED metres and its
/// Jacobian (`dy/d dp = I`, `dy/d phi = [(C_b^n l) x]`).
pub fn gnss_model(
    s: &NavState,
    lever_arm_body: &Vector3<f64>,
    fix: &Geodetic,
) -> (Vector3<f64>, SMatrix<f64, 3, { ekf::N }>) {
    let arm_ned = s.c_body_to_ned() * lever_arm_body;
    let y = earth::ned_offset(fix, &s.position) + arm_ned;
    let mut h = SMatrix::<f64, 3, { ekf::N }>::zeros();
    h.fixed_view_mut::<3, 3>(0, ekf::POS)
        .copy_from(&Matrix3::identity());
    h.fixed_view_mut::<3, 3>(0, ekf::ATT)
        .copy_from(&skew(&arm_ned));
    (y, h)
}
