//! Zero-velocity aid: `h(x) = v^n`, for a vehicle known to be still (moored alongside, on the
//! seabed). The caller decides when this holds; the IMU alone cannot tell rest from uniform
//! motion. Its own gate (`zero_velocity_gate_chi2`; it used to borrow the DVL's).

use super::{AidCounters, AidUpdate, NavCore};
use crate::ekf;
use auvnav_shm_schema::AidSource;
use nalgebra::{Matrix3, SMatrix};

/// The zero-velocity update's parameters and counters.
#[derive(Debug, Clone)]
pub struct ZeroVelocityAid {
    /// One-sigma per axis (m/s).
    pub std_m_s: f64,
    /// χ² gate (3 dof).
    pub gate_chi2: f64,
    pub counters: AidCounters,
}

impl ZeroVelocityAid {
    /// One-sigma per axis `std_m_s` (m/s), χ² gate `gate_chi2` (3 dof).
    pub fn new(std_m_s: f64, gate_chi2: f64) -> ZeroVelocityAid {
        ZeroVelocityAid {
            std_m_s,
            gate_chi2,
            counters: AidCounters::default(),
        }
    }

    /// Fuses "the vehicle is at rest at `t_ns`".
    pub fn fuse(&mut self, core: &mut NavCore, t_ns: u64) -> AidUpdate {
        let mut d = core.diagnostics(t_ns, AidSource::ZeroVelocity);
        d.dimension = 3;
        if core.aid_is_late(t_ns) {
            return AidUpdate::rejected(d);
        }
        core.propagate_covariance();
        let y = core.state().velocity_ned;
        let mut h = SMatrix::<f64, 3, { ekf::N }>::zeros();
        h.fixed_view_mut::<3, 3>(0, ekf::VEL)
            .copy_from(&Matrix3::identity());
        let r = Matrix3::identity() * self.std_m_s.powi(2);
        d.observation_variance = r.diagonal().into();
        let result = core.kf.update(&y, &h, &r, self.gate_chi2);
        let correction = NavCore::report(result, &mut d);
        AidUpdate::counted(d, correction, &mut self.counters)
    }
}
