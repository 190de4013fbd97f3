//! The DVL installation parameters a calibration can estimate: their names (the simulator's
//! effect names, a lever-arm component as `dvl.lever_arm.x|y|z`), units, bounds and priors.
//! Defaults: the S-CAL seed's four parameters (mounting roll, pitch, yaw and scale factor) with
//! its bounds (angles ±0.875 rad, scale 0.99..1.01); the lever arm and time offset are off.

use crate::CalibrationError;
use crate::error::usage;
use auvnav_core::config::DvlInstallation;
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;

/// One installation parameter.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Parameter {
    /// The effect name (`dvl.mount_yaw`, `dvl.lever_arm.x`, …).
    pub name: &'static str,
    pub unit: &'static str,
    pub estimate: bool,
    pub min: f64,
    pub max: f64,
    /// Prior mean (default: the starting configuration's value).
    pub prior: f64,
    /// Prior one-sigma: what is known about the parameter before the voyages.
    pub prior_std: f64,
    /// Finite-difference step for sensitivities.
    #[serde(skip)]
    pub step: f64,
}

/// Names in vector order.
pub const NAMES: [&str; 8] = [
    "dvl.mount_roll",
    "dvl.mount_pitch",
    "dvl.mount_yaw",
    "dvl.scale_factor",
    "dvl.lever_arm.x",
    "dvl.lever_arm.y",
    "dvl.lever_arm.z",
    "dvl.time_offset",
];

/// The S-CAL bounds of the mounting angles: ±0.875 rad.
pub const SEED_ANGLE_BOUND_DEG: f64 = 0.875 * 180.0 / std::f64::consts::PI;

/// Every parameter, with the estimated set, bounds and priors.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct ParameterSet {
    pub all: Vec<Parameter>,
}

/// A parameter's settings in a `--limits` TOML file (`["dvl.mount_yaw"]` tables).
#[derive(Debug, Clone, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ParameterLimits {
    pub estimate: Option<bool>,
    pub min: Option<f64>,
    pub max: Option<f64>,
    pub prior: Option<f64>,
    pub prior_std: Option<f64>,
}

impl ParameterSet {
    /// The defaults around the starting installation `base`.
    pub fn new(base: &DvlInstallation) -> ParameterSet {
        let x = installation_vector(base);
        let a = SEED_ANGLE_BOUND_DEG;
        let p = |i: usize, unit, estimate, min, max, prior_std, step| Parameter {
            name: NAMES[i],
            unit,
            estimate,
            min,
            max,
            prior: x[i],
            prior_std,
            step,
        };
        ParameterSet {
            all: vec![
                p(0, "deg", true, -a, a, 1.0, 0.01),
                p(1, "deg", true, -a, a, 1.0, 0.01),
                p(2, "deg", true, -a, a, 5.0, 0.01),
                p(3, "1", true, 0.99, 1.01, 0.005, 1e-5),
                p(4, "m", false, -5.0, 5.0, 0.5, 0.01),
                p(5, "m", false, -5.0, 5.0, 0.5, 0.01),
                p(6, "m", false, -5.0, 5.0, 0.5, 0.01),
                p(7, "s", false, -2.0, 2.0, 0.5, 0.01),
            ],
        }
    }

    fn index(name: &str) -> Result<Vec<usize>, CalibrationError> {
        if name == "dvl.lever_arm" {
            return Ok(vec![4, 5, 6]);
        }
        if name == "dvl.mounting" {
            return Ok(vec![0, 1, 2]);
        }
        match NAMES.iter().position(|n| *n == name) {
            Some(i) => Ok(vec![i]),
            None => usage!(
                "unknown parameter {name:?}; known: {}, dvl.lever_arm (all three), dvl.mounting (all three)",
                NAMES.join(", ")
            ),
        }
    }

    /// Estimates exactly the listed parameters (`--params`).
    pub fn select(&mut self, list: &[String]) -> Result<(), CalibrationError> {
        let mut on = [false; 8];
        for name in list {
            for i in Self::index(name.trim())? {
                on[i] = true;
            }
        }
        if !on.iter().any(|x| *x) {
            usage!("--params selects no parameter");
        }
        for (p, on) in self.all.iter_mut().zip(on) {
            p.estimate = on;
        }
        Ok(())
    }

    /// `--bound NAME=MIN,MAX`.
    pub fn set_bound(&mut self, setting: &str) -> Result<(), CalibrationError> {
        let (name, v) = two_numbers(setting, "--bound", "MIN,MAX")?;
        for i in Self::index(name)? {
            self.all[i].min = v.0;
            self.all[i].max = v.1;
        }
        Ok(())
    }

    /// `--prior NAME=MEAN,STD`.
    pub fn set_prior(&mut self, setting: &str) -> Result<(), CalibrationError> {
        let (name, v) = two_numbers(setting, "--prior", "MEAN,STD")?;
        for i in Self::index(name)? {
            self.all[i].prior = v.0;
            self.all[i].prior_std = v.1;
        }
        Ok(())
    }

    /// Applies a `--limits` TOML file: one table per parameter name.
    pub fn apply_limits(&mut self, text: &str, origin: &str) -> Result<(), CalibrationError> {
        let table: BTreeMap<String, ParameterLimits> = match toml::from_str(text) {
            Ok(t) => t,
            Err(e) => usage!("limits file {origin}: {e}"),
        };
        for (name, l) in table {
            let indices = match Self::index(&name) {
                Ok(i) => i,
                Err(e) => usage!("limits file {origin}: {e}"),
            };
            for i in indices {
                let p = &mut self.all[i];
                if let Some(x) = l.estimate {
                    p.estimate = x;
                }
                p.min = l.min.unwrap_or(p.min);
                p.max = l.max.unwrap_or(p.max);
                p.prior = l.prior.unwrap_or(p.prior);
                p.prior_std = l.prior_std.unwrap_or(p.prior_std);
            }
        }
        Ok(())
    }

    /// Checks bounds and priors; errors name the parameter and the option.
    pub fn validate(&self) -> Result<(), CalibrationError> {
        for p in &self.all {
            if !(p.min.is_finite() && p.max.is_finite() && p.min < p.max) {
                usage!(
                    "parameter {}: bounds {}..{} are inverted or empty (--bound {}=MIN,MAX with MIN < MAX)",
                    p.name,
                    p.min,
                    p.max,
                    p.name
                );
            }
            if !(p.prior_std.is_finite() && p.prior_std > 0.0) {
                usage!(
                    "parameter {}: prior standard deviation {} must be positive (--prior {}=MEAN,STD)",
                    p.name,
                    p.prior_std,
                    p.name
                );
            }
            if !(p.prior >= p.min && p.prior <= p.max) {
                usage!(
                    "parameter {}: the prior / starting value {} is outside its bounds {}..{}",
                    p.name,
                    p.prior,
                    p.min,
                    p.max
                );
            }
        }
        if p_estimated(self).is_empty() {
            usage!("no parameter is estimated");
        }
        Ok(())
    }

    /// Indices of the estimated parameters.
    pub fn estimated(&self) -> Vec<usize> {
        p_estimated(self)
    }

    /// The prior means of all eight parameters.
    pub fn prior_vector(&self) -> [f64; 8] {
        std::array::from_fn(|i| self.all[i].prior)
    }
}

fn p_estimated(s: &ParameterSet) -> Vec<usize> {
    (0..8).filter(|&i| s.all[i].estimate).collect()
}

fn two_numbers<'a>(
    s: &'a str,
    option: &str,
    form: &str,
) -> Result<(&'a str, (f64, f64)), CalibrationError> {
    let Some((name, v)) = s.split_once('=') else {
        usage!("{option} {s:?}: expected NAME={form}")
    };
    let Ok(nums) = v
        .split(',')
        .map(|x| x.trim().parse::<f64>())
        .collect::<Result<Vec<f64>, _>>()
    else {
        usage!("{option} {s:?}: expected NAME={form}")
    };
    if nums.len() != 2 {
        usage!("{option} {s:?}: expected NAME={form}");
    }
    Ok((name.trim(), (nums[0], nums[1])))
}

/// The eight parameters of an installation, in [`NAMES`] order.
pub fn installation_vector(d: &DvlInstallation) -> [f64; 8] {
    [
        d.mount_deg[0],
        d.mount_deg[1],
        d.mount_deg[2],
        d.scale_factor,
        d.lever_arm_m[0],
        d.lever_arm_m[1],
        d.lever_arm_m[2],
        d.time_offset_s,
    ]
}

/// The installation of a parameter vector.
pub fn installation(x: &[f64; 8]) -> DvlInstallation {
    DvlInstallation {
        mount_deg: [x[0], x[1], x[2]],
        scale_factor: x[3],
        lever_arm_m: [x[4], x[5], x[6]],
        time_offset_s: x[7],
        ..DvlInstallation::default()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn options_select_bound_and_reject_bad_settings() {
        let mut s = ParameterSet::new(&DvlInstallation::default());
        assert_eq!(s.estimated(), vec![0, 1, 2, 3]);
        s.select(&["dvl.mount_yaw".into(), "dvl.lever_arm".into()])
            .expect("select");
        assert_eq!(s.estimated(), vec![2, 4, 5, 6]);
        s.set_bound("dvl.mount_yaw=-3,3").expect("bound");
        assert_eq!((s.all[2].min, s.all[2].max), (-3.0, 3.0));
        s.validate().expect("valid");
        s.set_bound("dvl.mount_yaw=3,-3").expect("parsed");
        let err = s.validate().expect_err("inverted").to_string();
        assert!(
            err.contains("dvl.mount_yaw") && err.contains("inverted"),
            "{err}"
        );
        assert!(s.select(&["dvl.yaw".into()]).is_err());
        assert!(s.set_prior("dvl.scale_factor=1").is_err());
        let mut s = ParameterSet::new(&DvlInstallation::default());
        s.apply_limits(
            "[\"dvl.time_offset\"]\nestimate = true\nprior_std = 0.2\n",
            "x",
        )
        .expect("limits");
        assert!(s.all[7].estimate && s.all[7].prior_std == 0.2);
        assert!(
            s.apply_limits("[\"dvl.bogus\"]\nestimate = true\n", "x")
                .is_err()
        );
    }
}
