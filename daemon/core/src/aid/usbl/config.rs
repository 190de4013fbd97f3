//! The `[navigation.usbl]` configuration.

use crate::ekf::unscented::UnscentedParams;
use serde::{Deserialize, Serialize};

/// How USBL measurements enter the filter.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Coupling {
    /// The device's position fix (conventional).
    Loose,
    /// Slant range and the two range differences, with Gauss–Markov error states (S-USBL).
    #[default]
    Tight,
}

/// Which filter fuses the USBL measurements.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum UsblFilter {
    /// Unscented update with the configured (fixed) noise and innovation gating.
    Ukf,
    /// Adaptive linearised Kalman update: Jacobian of the same model, the noise learnt on line
    /// (Sage–Husa) and the same gating.
    Akf,
    /// Adaptive unscented update: unscented update, noise learnt on line, gating.
    #[default]
    Aukf,
}

impl Coupling {
    /// The names in configuration files and on command lines.
    pub const NAMES: &'static [&'static str] = &["loose", "tight"];
}

impl std::str::FromStr for Coupling {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        match s {
            "loose" => Ok(Coupling::Loose),
            "tight" => Ok(Coupling::Tight),
            _ => Err(format!("unknown USBL coupling {s:?} (loose or tight)")),
        }
    }
}

impl UsblFilter {
    /// The names in configuration files and on command lines.
    pub const NAMES: &'static [&'static str] = &["ukf", "akf", "aukf"];
}

impl std::str::FromStr for UsblFilter {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        match s {
            "ukf" => Ok(UsblFilter::Ukf),
            "akf" => Ok(UsblFilter::Akf),
            "aukf" => Ok(UsblFilter::Aukf),
            _ => Err(format!("unknown USBL filter {s:?} (ukf, akf or aukf)")),
        }
    }
}

/// The `[navigation.usbl]` configuration: the station's array as surveyed, the responder on the
/// vehicle, the measurement noise and error processes, the coupling and the filter.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct UsblConfig {
    /// Loose (position fix) or tight (slant range and range differences). Default tight.
    pub coupling: Coupling,
    /// ukf, akf or aukf. Default aukf.
    pub filter: UsblFilter,
    /// Surveyed position of the central transducer (deg, deg, m above the ellipsoid).
    pub array_latitude_deg: f64,
    pub array_longitude_deg: f64,
    pub array_height_m: f64,
    /// Surveyed yaw of the array x axis (hydrophones 1 → 3 on −x… +x) from north (deg).
    pub array_yaw_deg: f64,
    /// Distance between opposite hydrophones (m). Default 0.5.
    pub baseline_m: f64,
    /// Calibrated displacement of hydrophones 1..4 from their nominal places (x, y, z down in the
    /// array frame per hydrophone, m; `usbl.hydrophone_offset`). Default 0.
    pub hydrophone_offset_m: [f64; 12],
    /// Responder position in the vehicle body frame (m). Default 0.
    pub responder_lever_arm_m: [f64; 3],
    /// Slant-range noise (m). Default 0.1.
    pub range_std_m: f64,
    /// Range-difference noise (m). Default 0.002.
    pub range_difference_std_m: f64,
    /// Azimuth/elevation noise of devices that report angles (deg). Default 0.2.
    pub angle_std_deg: f64,
    /// Slant-range error process (sound speed, timing): stationary one-sigma (m). Default 0.2.
    pub range_error_std_m: f64,
    /// Its correlation time (s). Default 300.
    pub range_error_correlation_s: f64,
    /// Range-difference error process (array orientation, phase calibration): stationary
    /// one-sigma (m; about baseline × orientation uncertainty in rad). Default 0.01.
    pub range_difference_error_std_m: f64,
    /// Its correlation time (s). Default 3600 (an orientation error is constant; its effect on
    /// the range differences changes with the direction to the vehicle).
    pub range_difference_error_correlation_s: f64,
    /// Gate on each component's squared normalised innovation (chi-square, 1 dof). Default
    /// 10.83 (99.9 %).
    pub gate_chi2: f64,
    /// Fading factor of the noise estimate (akf, aukf; memory about 1 / (1 − b) fixes). Default
    /// 0.98.
    pub fading: f64,
    /// Consecutive rejections after which the gate reopens. Default 20.
    pub reopen_after: u32,
    /// Longest slant range accepted (m). Default 5000.
    pub max_range_m: f64,
    /// Oldest fix accepted, by its time of validity against the navigation state (s). A fix
    /// is evaluated against the vehicle's position and attitude at its time of validity (kept
    /// for this long) and corrects the current state: the navigation errors change little over
    /// a few seconds. Default 3.
    pub max_latency_s: f64,
    /// Sigma-point spread α. Default 0.5.
    pub unscented_alpha: f64,
    /// Sigma-point prior-knowledge β. Default 2.
    pub unscented_beta: f64,
    /// Sigma-point secondary scaling κ. Default 0.
    pub unscented_kappa: f64,
}

impl Default for UsblConfig {
    fn default() -> Self {
        let u = UnscentedParams::default();
        UsblConfig {
            coupling: Coupling::Tight,
            filter: UsblFilter::Aukf,
            array_latitude_deg: 0.0,
            array_longitude_deg: 0.0,
            array_height_m: 0.0,
            array_yaw_deg: 0.0,
            baseline_m: 0.5,
            hydrophone_offset_m: [0.0; 12],
            responder_lever_arm_m: [0.0; 3],
            range_std_m: 0.1,
            range_difference_std_m: 0.002,
            angle_std_deg: 0.2,
            range_error_std_m: 0.2,
            range_error_correlation_s: 300.0,
            range_difference_error_std_m: 0.01,
            range_difference_error_correlation_s: 3600.0,
            gate_chi2: 10.83,
            fading: 0.98,
            reopen_after: 20,
            max_range_m: 5000.0,
            max_latency_s: 3.0,
            unscented_alpha: u.alpha,
            unscented_beta: u.beta,
            unscented_kappa: u.kappa,
        }
    }
}

impl UsblConfig {
    pub fn unscented(&self) -> UnscentedParams {
        UnscentedParams {
            alpha: self.unscented_alpha,
            beta: self.unscented_beta,
            kappa: self.unscented_kappa,
        }
    }

    /// Every value that makes no sense, as `key: problem`.
    pub fn problems(&self) -> Vec<String> {
        let mut out = Vec::new();
        let mut need = |key: &str, ok: bool, what: &str| {
            if !ok {
                out.push(format!("usbl.{key}: {what}"));
            }
        };
        need(
            "array_latitude_deg",
            self.array_latitude_deg.abs() <= 90.0,
            "must be within ±90",
        );
        need(
            "array_longitude_deg",
            self.array_longitude_deg.abs() <= 180.0,
            "must be within ±180",
        );
        need(
            "array_height_m",
            (-11000.0..=1000.0).contains(&self.array_height_m),
            "must be within -11000..1000",
        );
        need(
            "baseline_m",
            self.baseline_m > 0.0 && self.baseline_m <= 10.0,
            "must be in (0, 10]",
        );
        need(
            "hydrophone_offset_m",
            self.hydrophone_offset_m
                .iter()
                .all(|x| x.abs() <= 0.5 * self.baseline_m.max(0.0) + 10.0),
            "each component must be finite and within baseline/2 + 10 m",
        );
        need(
            "array_yaw_deg",
            self.array_yaw_deg.abs() <= 360.0,
            "must be within ±360",
        );
        need(
            "responder_lever_arm_m",
            self.responder_lever_arm_m.iter().all(|x| x.abs() <= 50.0),
            "each component must be finite and within ±50 m",
        );
        for (key, v, hi) in [
            ("range_std_m", self.range_std_m, 1000.0),
            ("range_difference_std_m", self.range_difference_std_m, 100.0),
            ("angle_std_deg", self.angle_std_deg, 180.0),
            (
                "range_error_correlation_s",
                self.range_error_correlation_s,
                1e6,
            ),
            (
                "range_difference_error_correlation_s",
                self.range_difference_error_correlation_s,
                1e6,
            ),
            ("gate_chi2", self.gate_chi2, 1e6),
            ("max_range_m", self.max_range_m, 100_000.0),
        ] {
            need(
                key,
                v > 0.0 && v <= hi,
                &format!("must be positive, at most {hi}"),
            );
        }
        need(
            "max_latency_s",
            (0.0..=30.0).contains(&self.max_latency_s),
            "must be within 0..30",
        );
        for (key, v) in [
            ("range_error_std_m", self.range_error_std_m),
            (
                "range_difference_error_std_m",
                self.range_difference_error_std_m,
            ),
        ] {
            need(key, (0.0..=1000.0).contains(&v), "must be within 0..1000");
        }
        need(
            "unscented_beta",
            (0.0..=10.0).contains(&self.unscented_beta),
            "must be within 0..10 (2 for Gaussian errors)",
        );
        need(
            "unscented_kappa",
            (-100.0..=100.0).contains(&self.unscented_kappa),
            "must be within -100..100",
        );
        need(
            "fading",
            self.fading > 0.0 && self.fading < 1.0,
            "must be in (0, 1)",
        );
        need(
            "unscented_alpha",
            self.unscented_alpha > 0.0 && self.unscented_alpha <= 1.0,
            "must be in (0, 1]",
        );
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The command-line names are the configuration file's (serde) names, both ways.
    #[test]
    fn names_parse_to_what_the_configuration_spells() {
        fn check<T>(names: &[&str])
        where
            T: std::str::FromStr + Serialize + PartialEq + std::fmt::Debug,
            T::Err: std::fmt::Debug,
        {
            for name in names {
                let v: T = name.parse().expect("listed name");
                assert_eq!(
                    toml::Value::try_from(&v).expect("serialise"),
                    toml::Value::String(name.to_string())
                );
            }
            assert!("nonsense".parse::<T>().is_err());
        }
        check::<Coupling>(Coupling::NAMES);
        check::<UsblFilter>(UsblFilter::NAMES);
    }
}
