//! A docking station's fixes through the range aid (`usbl_fixes`): the slant range from the
//! station's transducer (receiver 0) and the range differences ΔR13 and ΔR24 between its
//! hydrophones (receivers 1..4), each gated and fused alone through the station's geometry, at
//! the fix's time of validity (the device gives where the vehicle was then), with the range
//! aid's errors: the range bias (S-USBL's δR) and one error per difference (δΔR13, δΔR24).

use super::{AidUpdate, Geometric, Leg, NavCore, RangeAid};
use auvnav_shm_schema::{AidSource, UsblFixV1};
use nalgebra::Vector3;

/// The receivers of each range difference of a fix: ΔR13, ΔR24.
const PAIRS: [(usize, usize); 2] = [(1, 3), (2, 4)];

impl RangeAid {
    /// Whether the range aid takes a docking station's fixes (`usbl_fixes`).
    pub fn takes_usbl_fixes(&self) -> bool {
        self.fusion.as_ref().is_some_and(|f| f.cfg.usbl_fixes)
    }

    /// Whether a fix is to be fused at all (not too old); counted as late when not.
    pub fn accepts_usbl_fix(&mut self, core: &NavCore, m: &UsblFixV1) -> bool {
        self.in_time(core, m.validity_time_ns)
    }

    /// Fuses part `part` of a station's fix: 0 the slant range, 1 and 2 the range differences
    /// ΔR13 and ΔR24 (none when the fix does not carry that part).
    pub fn fuse_usbl_part(
        &mut self,
        core: &mut NavCore,
        m: &UsblFixV1,
        part: usize,
    ) -> Option<AidUpdate> {
        let f = self.fusion.as_ref().filter(|f| f.cfg.usbl_fixes)?;
        let flag = if part == 0 {
            UsblFixV1::VALID_RANGE
        } else {
            UsblFixV1::VALID_RANGE_DIFFERENCES
        };
        if m.validity & flag == 0 || part > PAIRS.len() {
            return None;
        }
        let t_ns = m.validity_time_ns;
        let t = t_ns as f64 * 1e-9;
        let source = if part == 0 {
            AidSource::AcousticRange
        } else {
            AidSource::AcousticRangeDifference
        };
        let mut d = core.diagnostics(t_ns, source);
        d.dimension = 1;
        // The geometry at the time of validity, for the vehicle and the (still) receivers.
        let at = [Leg {
            vehicle_s: t,
            receiver_s: t,
        }];
        let s = *core.state();
        if part == 0 {
            let z = m.slant_range_m;
            d.observation = [z, 0.0, 0.0];
            let p = f.predict_legs(&s, 0, &at);
            let (Some(p), true) = (p, z.is_finite() && z > 0.0 && z <= f.cfg.max_range_m) else {
                self.counters.invalid += 1;
                return Some(AidUpdate::rejected(d));
            };
            core.propagate_covariance();
            let a = p.at(&Vector3::zeros());
            let scalar = f.range_measurement(core, &a, 0, z, 0.0);
            return Some(self.update(core, d, scalar, 0));
        }
        let (i, j) = PAIRS[part - 1];
        let z = m.range_difference_m[part - 1];
        d.observation = [z, i as f64, j as f64];
        let baseline = (f.receivers[i] - f.receivers[j]).norm();
        let predicted = f.predict_legs(&s, i, &at).zip(f.predict_legs(&s, j, &at));
        let (Some((pi, pj)), true) = (
            predicted,
            z.is_finite() && z.abs() <= 1.05 * baseline + 0.01,
        ) else {
            self.counters.invalid += 1;
            return Some(AidUpdate::rejected(d));
        };
        core.propagate_covariance();
        let (a, b) = (pi.at(&Vector3::zeros()), pj.at(&Vector3::zeros()));
        let scalar = f.scalar(
            core,
            Geometric {
                length_m: a.range_m - b.range_m,
                line_of_sight: a.line_of_sight - b.line_of_sight,
                lever_ned: a.lever_ned,
            },
            f.states.difference[part - 1],
            z,
            f.cfg.difference_std_m.powi(2),
        );
        Some(self.update(core, d, scalar, 4 + part))
    }
}
