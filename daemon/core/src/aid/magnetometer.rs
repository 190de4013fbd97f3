//! Magnetic heading aid: the calibrated field, rotated to NED with the navigator's attitude,
//! must point at the declination of the world magnetic model.
//!
//! Model: a reading is `h = S·B + b` (the simulator's `mag.soft_iron` S and `mag.hard_iron` b,
//! µT), so the body field is `B = S⁻¹(h − b)`. With `m = Ĉ_b^n B` the predicted field direction,
//! the innovation is `y = atan2(m_E, m_N) − D` (D the declination), which is the heading error
//! of the navigator as seen by the magnetometer. Its Jacobian follows the attitude-error
//! convention of the filter (C = (I + [φ×]) Ĉ): `m̂ = m − φ × m`, so `H_φ = ∂α/∂m · [m×]`, which
//! includes the tilt coupling (a tilt error moves the vertical field into the horizontal one:
//! the familiar tan(dip) sensitivity of compass heading). One dimension, χ² gate.
//!
//! *Should we fuse*: a valid, finite reading; a calibrated magnitude within `field_tolerance` of
//! the model's intensity (otherwise the environment is disturbed — a nearby mass, a motor — and
//! the reading is counted as disturbed, not fused); not older than the state; at most one
//! update per `min_interval_s`. The declination, intensity and dip come from the model at the
//! navigator's position, re-evaluated after each kilometre moved.

use super::{AidCounters, AidUpdate, NavCore};
use crate::ekf;
use crate::wmm::WorldMagneticModel;
use auvnav_shm_schema::{AidSource, MagnetometerV1};
use nalgebra::{Matrix3, SMatrix, SVector, Vector3};
use serde::{Deserialize, Serialize};

/// The magnetometer (`[navigation.magnetometer]`): calibration in the simulator's vocabulary,
/// the field model, noise and gate.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct MagnetometerConfig {
    /// Hard iron (`mag.hard_iron`, µT, sensor axes). Default 0.
    pub hard_iron_ut: [f64; 3],
    /// Soft-iron matrix S (`mag.soft_iron`, row-major; the reading is S·B + hard iron). Default
    /// identity.
    pub soft_iron: [f64; 9],
    /// Heading noise of one reading (deg). Default 2.
    pub heading_std_deg: f64,
    /// χ² gate (1 dof). Default 10.83 (99.9 %).
    pub gate_chi2: f64,
    /// Largest relative difference of the calibrated magnitude from the model's intensity before
    /// a reading counts as disturbed (fraction). Default 0.15.
    pub field_tolerance: f64,
    /// Fuse at most one reading per this interval (s). Default 0.1.
    pub min_interval_s: f64,
    /// Declination (deg east) to use instead of the field model. Default none (the model).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub declination_deg: Option<f64>,
    /// Total intensity (µT) to use instead of the field model. Default none (the model).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub intensity_ut: Option<f64>,
    /// Date of the mission for the field model (decimal year, e.g. 2026.9). Needed unless both
    /// `declination_deg` and `intensity_ut` are given.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub model_date: Option<f64>,
    /// A `WMM.COF` coefficient file for dates outside the built-in WMM2025 (2025–2030).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub field_model_file: Option<std::path::PathBuf>,
    /// Where the calibration comes from (free text, e.g. the `auvnav calibrate mag` run).
    #[serde(skip_serializing_if = "String::is_empty")]
    pub source: String,
}

impl Default for MagnetometerConfig {
    fn default() -> Self {
        MagnetometerConfig {
            hard_iron_ut: [0.0; 3],
            soft_iron: [1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0],
            heading_std_deg: 2.0,
            gate_chi2: ekf::gate::CHI2_1DOF_999,
            field_tolerance: 0.15,
            min_interval_s: 0.1,
            declination_deg: None,
            intensity_ut: None,
            model_date: None,
            field_model_file: None,
            source: String::new(),
        }
    }
}

impl MagnetometerConfig {
    /// Every value that makes no sense, as `magnetometer.key = value: expected …`.
    pub fn problems(&self) -> Vec<String> {
        let mut out = Vec::new();
        let mut range = |key: &str, v: f64, lo: f64, hi: f64| {
            if !(v.is_finite() && v >= lo && v <= hi) {
                out.push(format!("magnetometer.{key} = {v}: expected {lo}..={hi}"));
            }
        };
        for (i, v) in self.hard_iron_ut.iter().enumerate() {
            range(&format!("hard_iron_ut[{i}]"), *v, -1000.0, 1000.0);
        }
        for (i, v) in self.soft_iron.iter().enumerate() {
            range(&format!("soft_iron[{i}]"), *v, -2.0, 2.0);
        }
        range("heading_std_deg", self.heading_std_deg, 0.01, 90.0);
        range("gate_chi2", self.gate_chi2, 0.1, 1e6);
        range("field_tolerance", self.field_tolerance, 0.01, 1.0);
        range("min_interval_s", self.min_interval_s, 0.0, 3600.0);
        if let Some(d) = self.declination_deg {
            range("declination_deg", d, -180.0, 180.0);
        }
        if let Some(f) = self.intensity_ut {
            range("intensity_ut", f, 1.0, 100.0);
        }
        if let Some(y) = self.model_date {
            range("model_date", y, 1900.0, 2100.0);
        }
        if self.soft_matrix().try_inverse().is_none() {
            out.push("magnetometer.soft_iron: the matrix is singular".into());
        }
        let model_needed = self.declination_deg.is_none() || self.intensity_ut.is_none();
        if model_needed {
            match (self.model_date, self.field_model()) {
                (None, _) => out.push(
                    "magnetometer.model_date: give the mission date (decimal year) for the field \
                     model, or both declination_deg and intensity_ut"
                        .into(),
                ),
                (Some(_), Err(e)) => out.push(format!("magnetometer.field_model_file: {e}")),
                (Some(y), Ok(m)) => {
                    let (a, b) = m.validity();
                    if !(a..=b).contains(&y) {
                        out.push(format!(
                            "magnetometer.model_date = {y}: outside the validity of {} ({a} to \
                             {b}); give field_model_file",
                            m.name
                        ));
                    }
                }
            }
        }
        out
    }

    /// S as a matrix.
    pub fn soft_matrix(&self) -> Matrix3<f64> {
        Matrix3::from_row_slice(&self.soft_iron)
    }

    /// The field model: the file's when given, else the built-in one for `model_date` (WMM2010,
    /// WMM2020 or WMM2025; WMM2025 where none covers it, which the check then refuses).
    pub fn field_model(&self) -> Result<WorldMagneticModel, String> {
        match &self.field_model_file {
            Some(p) => {
                let text = std::fs::read_to_string(p)
                    .map_err(|e| format!("reading {}: {e}", p.display()))?;
                WorldMagneticModel::from_cof(&text).map_err(|e| format!("{}: {e}", p.display()))
            }
            None => Ok(self
                .model_date
                .and_then(WorldMagneticModel::builtin_for)
                .unwrap_or_else(WorldMagneticModel::builtin)),
        }
    }
}

/// The local field: declination (rad), intensity (µT), and where it was evaluated.
#[derive(Debug, Clone, Copy)]
struct LocalField {
    declination_rad: f64,
    intensity_ut: f64,
    at: (f64, f64),
}

/// Counters beyond fused/rejected/invalid.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct MagnetometerCounters {
    pub common: AidCounters,
    /// Readings whose calibrated magnitude is far from the model (not fused).
    pub disturbed: u64,
    /// Readings skipped by `min_interval_s`.
    pub thinned: u64,
}

/// The magnetometer aid.
#[derive(Debug, Clone)]
pub struct MagnetometerAid {
    cfg: MagnetometerConfig,
    k: Matrix3<f64>,
    model: Option<WorldMagneticModel>,
    local: Option<LocalField>,
    last_fused_ns: Option<u64>,
    pub counters: MagnetometerCounters,
}

impl MagnetometerAid {
    /// The aid of a configuration (which `problems` has accepted).
    pub fn new(cfg: &MagnetometerConfig) -> MagnetometerAid {
        let k = cfg
            .soft_matrix()
            .try_inverse()
            .unwrap_or_else(Matrix3::identity);
        let model = (cfg.declination_deg.is_none() || cfg.intensity_ut.is_none())
            .then(|| cfg.field_model().ok())
            .flatten();
        MagnetometerAid {
            cfg: cfg.clone(),
            k,
            model,
            local: None,
            last_fused_ns: None,
            counters: MagnetometerCounters::default(),
        }
    }

    /// When a reading was last fused (ns).
    pub fn last_fused_ns(&self) -> Option<u64> {
        self.last_fused_ns
    }

    /// The calibrated body field of a reading (µT), if the reading is valid and finite.
    pub fn calibrated(&self, m: &MagnetometerV1) -> Option<Vector3<f64>> {
        if m.validity & MagnetometerV1::VALID_FIELD == 0 {
            return None;
        }
        let h = Vector3::from(m.field_t) * 1e6;
        if !h.iter().all(|v| v.is_finite()) || h.norm() > 1e4 {
            return None;
        }
        Some(self.k * (h - Vector3::from(self.cfg.hard_iron_ut)))
    }

    /// Declination (rad) and intensity (µT) at a position (rad), from the configuration or the
    /// model (cached within about a kilometre).
    pub fn local_field(&mut self, lat: f64, lon: f64) -> Option<(f64, f64)> {
        if let (Some(d), Some(f)) = (self.cfg.declination_deg, self.cfg.intensity_ut) {
            return Some((d.to_radians(), f));
        }
        if let Some(l) = self.local
            && (l.at.0 - lat).abs() < 1e-4 * 1.6
            && (l.at.1 - lon).abs() * lat.cos() < 1e-4 * 1.6
        {
            return Some((l.declination_rad, l.intensity_ut));
        }
        let field = self.model.as_ref()?.field(
            lat.to_degrees(),
            lon.to_degrees(),
            0.0,
            self.cfg.model_date?,
        );
        let field = field.ok()?;
        let l = LocalField {
            declination_rad: self
                .cfg
                .declination_deg
                .map_or(field.declination_deg().to_radians(), f64::to_radians),
            intensity_ut: self.cfg.intensity_ut.unwrap_or(field.intensity_nt() * 1e-3),
            at: (lat, lon),
        };
        self.local = Some(l);
        Some((l.declination_rad, l.intensity_ut))
    }

    /// Fuses a magnetometer reading as a heading measurement.
    pub fn fuse(&mut self, core: &mut NavCore, m: &MagnetometerV1) -> AidUpdate {
        let t_ns = m.host_time_ns;
        let mut d = core.diagnostics(t_ns, AidSource::Magnetometer);
        d.dimension = 1;
        let Some(b) = self.calibrated(m) else {
            self.counters.common.invalid += 1;
            return AidUpdate::rejected(d);
        };
        if core.aid_is_late(t_ns) {
            return AidUpdate::rejected(d);
        }
        if let Some(last) = self.last_fused_ns
            && t_ns < last.saturating_add((self.cfg.min_interval_s * 1e9) as u64)
        {
            self.counters.thinned += 1;
            return AidUpdate::rejected(d);
        }
        let p = core.state().position;
        let Some((declination, intensity)) = self.local_field(p.latitude_rad, p.longitude_rad)
        else {
            self.counters.common.invalid += 1;
            return AidUpdate::rejected(d);
        };
        let norm = b.norm();
        let within = (norm - intensity).abs() <= self.cfg.field_tolerance * intensity;
        if !within {
            self.counters.disturbed += 1;
            d.observation[0] = norm;
            return AidUpdate::rejected(d);
        }
        core.propagate_covariance();
        let c = core.state().c_body_to_ned();
        let mn = c * b;
        let horizontal2 = mn.x * mn.x + mn.y * mn.y;
        if horizontal2 < 1e-6 * norm * norm {
            // The field is vertical (at a magnetic pole): no heading.
            self.counters.common.invalid += 1;
            return AidUpdate::rejected(d);
        }
        let alpha = mn.y.atan2(mn.x);
        let y = SVector::<f64, 1>::new(crate::earth::wrap_pi(alpha - declination));
        // ∂α/∂m = [−m_E, m_N, 0]/(m_N² + m_E²); δm = [m×] φ.
        let dalpha = Vector3::new(-mn.y, mn.x, 0.0) / horizontal2;
        let h_phi = dalpha.transpose() * ekf::skew(&mn);
        let mut h = SMatrix::<f64, 1, { ekf::N }>::zeros();
        for i in 0..3 {
            h[(0, ekf::ATT + i)] = h_phi[i];
        }
        let r = SMatrix::<f64, 1, 1>::new(self.cfg.heading_std_deg.to_radians().powi(2));
        d.observation[0] = crate::earth::wrap_pi(core.state().euler()[2] - y[0]);
        d.observation_variance[0] = r[(0, 0)];
        let result = core.kf.update(&y, &h, &r, self.cfg.gate_chi2);
        let correction = NavCore::report(result, &mut d);
        if correction.is_some() {
            self.last_fused_ns = Some(t_ns);
        }
        AidUpdate::counted(d, correction, &mut self.counters.common)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn configuration_needs_a_date_or_fixed_values() {
        let c = MagnetometerConfig::default();
        assert!(c.problems().iter().any(|p| p.contains("model_date")));
        let c = MagnetometerConfig {
            model_date: Some(2026.9),
            ..Default::default()
        };
        assert!(c.problems().is_empty(), "{:?}", c.problems());
        let c = MagnetometerConfig {
            model_date: Some(2040.0),
            ..Default::default()
        };
        assert!(
            c.problems()
                .iter()
                .any(|p| p.contains("outside the validity"))
        );
        // An older mission's date takes the built-in model of its epoch.
        for (date, model) in [(2012.3, "WMM-2010"), (2022.6, "WMM-2020")] {
            let c = MagnetometerConfig {
                model_date: Some(date),
                ..Default::default()
            };
            assert!(c.problems().is_empty(), "{date}: {:?}", c.problems());
            assert_eq!(c.field_model().map(|m| m.name), Ok(model.to_string()));
        }
        let c = MagnetometerConfig {
            model_date: Some(2018.0),
            ..Default::default()
        };
        assert!(
            c.problems()
                .iter()
                .any(|p| p.contains("outside the validity of WMM-2025"))
        );
        let c = MagnetometerConfig {
            declination_deg: Some(3.0),
            intensity_ut: Some(48.0),
            soft_iron: [0.0; 9],
            ..Default::default()
        };
        assert!(c.problems().iter().any(|p| p.contains("singular")));
    }
}
