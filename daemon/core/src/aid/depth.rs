//! Depth aid: `h(x) = -height + (C_b^n l)_down` (the sensor at `l` from the IMU), one
//! dimension, χ² gate.

use super::{AidCounters, AidUpdate, NavCore};
use crate::ekf::{self, skew};
use crate::strapdown::NavState;
use auvnav_shm_schema::{AidSource, DepthV1};
use nalgebra::{SMatrix, SVector, Vector3};

/// The depth sensor's parameters and counters.
#[derive(Debug, Clone)]
pub struct DepthAid {
    /// Noise (m).
    pub std_m: f64,
    /// χ² gate (1 dof).
    pub gate_chi2: f64,
    /// The sensor's position in the body frame (m).
    pub lever_arm_m: Vector3<f64>,
    pub counters: AidCounters,
}

impl DepthAid {
    /// Noise `std_m` (m), χ² gate `gate_chi2` (1 dof), the sensor at `lever_arm_m` (m, body).
    pub fn new(std_m: f64, gate_chi2: f64, lever_arm_m: Vector3<f64>) -> DepthAid {
        DepthAid {
            std_m,
            gate_chi2,
            lever_arm_m,
            counters: AidCounters::default(),
        }
    }

    /// Should we fuse: a valid, finite depth within −10..11 000 m, not older than the state.
    fn usable(&mut self, core: &mut NavCore, m: &DepthV1) -> bool {
        if m.validity & DepthV1::VALID_DEPTH == 0
            || !m.depth_m.is_finite()
            || !(-10.0..=11000.0).contains(&m.depth_m)
        {
            self.counters.invalid += 1;
            return false;
        }
        !core.aid_is_late(m.host_time_ns)
    }

    /// Fuses a depth measurement.
    pub fn fuse(&mut self, core: &mut NavCore, m: &DepthV1) -> AidUpdate {
        let t_ns = m.host_time_ns;
        let mut d = core.diagnostics(t_ns, AidSource::Depth);
        d.dimension = 1;
        if !self.usable(core, m) {
            return AidUpdate::rejected(d);
        }
        core.propagate_covariance();
        let (predicted, h) = depth_model(core.state(), &self.lever_arm_m);
        let y = SVector::<f64, 1>::new(predicted - m.depth_m);
        let r = SMatrix::<f64, 1, 1>::new(self.std_m.powi(2));
        d.observation[0] = m.depth_m;
        d.observation_variance[0] = r[(0, 0)];
        let result = core.kf.update(&y, &h, &r, self.gate_chi2);
        let correction = NavCore::report(result, &mut d);
        AidUpdate::counted(d, correction, &mut self.counters)
    }
}

/// The depth model: the depth of the sensor's point, `-height + (C_b^n l)_down`, and its
/// Jacobian (`d/d dp_down = 1`, `d/d phi = [(C_b^n l) x]`'s down row, as the GNSS lever arm).
pub fn depth_model(
    s: &NavState,
    lever_arm_body: &Vector3<f64>,
) -> (f64, SMatrix<f64, 1, { ekf::N }>) {
    let arm_ned = s.c_body_to_ned() * lever_arm_body;
    let mut h = SMatrix::<f64, 1, { ekf::N }>::zeros();
    h[(0, ekf::POS + 2)] = 1.0;
    let row = skew(&arm_ned).row(2).into_owned();
    for k in 0..3 {
        h[(0, ekf::ATT + k)] = row[k];
    }
    (-s.position.height_m + arm_ned.z, h)
}
