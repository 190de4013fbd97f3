//! Scenario files: where the voyage starts, the legs it flies, sensor rates, the USBL station and
//! the effects. Built-in scenarios are TOML files embedded in the program (`scenarios/*.toml`);
//! a user's scenario file has the same format. Unknown keys are errors.

use super::effects::{EffectError, Effects};
use auvnav_core::aid::ranges::{ArrayKind, Interrogator, RangesConfig};
use auvnav_core::earth::Geodetic;
use nalgebra::Vector3;
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Scenario {
    /// Short name.
    pub name: String,
    /// One line on what the voyage is for.
    #[serde(default)]
    pub description: String,
    pub start: Start,
    #[serde(default)]
    pub rates: Rates,
    /// The manoeuvres, flown in order.
    pub legs: Vec<Leg>,
    /// The USBL docking station (no USBL data without it).
    #[serde(default)]
    pub station: Option<Station>,
    /// An acoustic positioning system ranged per receiver: LBL beacons, a boat's array, or a
    /// single transducer on a ship (`crate::acoustic`; no range data without it).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub acoustic: Option<AcousticSetup>,
    /// Sea floor depth below the surface (m, positive), for DVL altitude and bottom lock.
    #[serde(default = "default_seabed_depth")]
    pub seabed_depth_m: f64,
    /// Effects (dotted name → number or list of numbers).
    #[serde(default)]
    pub effects: BTreeMap<String, EffectValue>,
}

fn default_seabed_depth() -> f64 {
    100.0
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(untagged)]
pub enum EffectValue {
    Scalar(f64),
    Vector(Vec<f64>),
}

impl EffectValue {
    pub fn values(&self) -> Vec<f64> {
        match self {
            EffectValue::Scalar(v) => vec![*v],
            EffectValue::Vector(v) => v.clone(),
        }
    }
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Start {
    /// Geodetic latitude (deg, -80..80).
    pub latitude_deg: f64,
    /// Longitude (deg, -180..180).
    pub longitude_deg: f64,
    /// Depth below the surface (m, 0..6000).
    pub depth_m: f64,
    /// Heading, clockwise from true north (deg).
    pub heading_deg: f64,
    /// Speed through the water along body x (m/s, 0..10).
    pub speed_m_s: f64,
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Rates {
    /// IMU rate (Hz, 10..2000). Every other rate must divide it.
    pub imu_hz: u32,
    pub dvl_hz: u32,
    pub usbl_hz: u32,
    pub depth_hz: u32,
    pub magnetometer_hz: u32,
    pub gnss_hz: u32,
    /// Rate of the truth channel (Hz).
    pub truth_hz: u32,
    /// Rate of a CTD's sound-velocity readings (Hz; 0, the default: no CTD). The reading is the
    /// true sound speed (`dvl.sound_speed`).
    #[serde(default, skip_serializing_if = "is_zero")]
    pub ctd_hz: u32,
    /// Rate of a compass's (or AHRS's) heading, pitch and roll on the attitude channel (Hz; 0,
    /// the default: none). Roll and pitch are the true ones, the heading is shown with
    /// `heading.deviation`.
    #[serde(default, skip_serializing_if = "is_zero")]
    pub compass_hz: u32,
}

fn is_zero(v: &u32) -> bool {
    *v == 0
}

impl Default for Rates {
    fn default() -> Self {
        Rates {
            imu_hz: 200,
            dvl_hz: 5,
            usbl_hz: 1,
            depth_hz: 1,
            magnetometer_hz: 10,
            gnss_hz: 1,
            truth_hz: 20,
            ctd_hz: 0,
            compass_hz: 0,
        }
    }
}

/// One manoeuvre. Attitude and speed change smoothly (raised-cosine rate profiles), so the IMU
/// sees continuous angular rates.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case", deny_unknown_fields)]
pub enum Leg {
    /// Hold heading, pitch and speed.
    Straight { duration_s: f64 },
    /// Change heading by `angle_deg` (positive = starboard) at an average `rate_deg_s`, banking
    /// by `bank_deg` during the turn.
    Turn {
        angle_deg: f64,
        rate_deg_s: f64,
        #[serde(default)]
        bank_deg: f64,
    },
    /// Change depth by `change_m` (positive = deeper) with a pitch of `pitch_deg` magnitude.
    Depth { change_m: f64, pitch_deg: f64 },
    /// Change speed to `target_m_s` at `accel_m_s2`.
    Speed { target_m_s: f64, accel_m_s2: f64 },
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Station {
    /// Surveyed position of the central transducer: north and east of the start point (m) and
    /// depth (m).
    pub north_m: f64,
    pub east_m: f64,
    pub depth_m: f64,
    /// Surveyed yaw of the array x axis from north (deg).
    #[serde(default)]
    pub yaw_deg: f64,
    /// Distance between opposite hydrophones (m, 0.01..10).
    pub baseline_m: f64,
    /// Position of the vehicle's responder in the body frame (m).
    #[serde(default)]
    pub responder_lever_arm_m: [f64; 3],
}

#[derive(Debug, thiserror::Error)]
pub enum ScenarioError {
    #[error("unknown scenario {0:?}; `auvnav sim --list-scenarios` lists the built-in ones")]
    Unknown(String),
    #[error("scenario file {path}: {message}")]
    Parse { path: String, message: String },
    #[error("scenario {scenario}: {key} = {value} is outside the allowed range {range}")]
    OutOfRange {
        scenario: String,
        key: String,
        value: String,
        range: String,
    },
    #[error("scenario {scenario}: {source}")]
    Effect {
        scenario: String,
        source: EffectError,
    },
}

/// Built-in scenarios: (name, TOML text).
pub const BUILTIN: &[(&str, &str)] = &[
    ("straight", include_str!("scenarios/straight.toml")),
    ("turns", include_str!("scenarios/turns.toml")),
    (
        "depth_changes",
        include_str!("scenarios/depth_changes.toml"),
    ),
    ("lawnmower", include_str!("scenarios/lawnmower.toml")),
    ("docking", include_str!("scenarios/docking.toml")),
    ("homing", include_str!("scenarios/homing.toml")),
    ("dive", include_str!("scenarios/dive.toml")),
    ("moored", include_str!("scenarios/moored.toml")),
    ("survey", include_str!("scenarios/survey.toml")),
    ("ranges_array", include_str!("scenarios/ranges_array.toml")),
    ("ranges_lbl", include_str!("scenarios/ranges_lbl.toml")),
    (
        "ranges_single",
        include_str!("scenarios/ranges_single.toml"),
    ),
    ("align_moored", include_str!("scenarios/align_moored.toml")),
    (
        "align_straight",
        include_str!("scenarios/align_straight.toml"),
    ),
    (
        "align_turning",
        include_str!("scenarios/align_turning.toml"),
    ),
];

impl Scenario {
    /// A built-in scenario by name, or a scenario file by path.
    pub fn load(name_or_path: &str) -> Result<Scenario, ScenarioError> {
        if let Some((_, text)) = BUILTIN.iter().find(|(n, _)| *n == name_or_path) {
            return Scenario::parse(text, name_or_path);
        }
        let path = std::path::Path::new(name_or_path);
        if path.extension().is_some_and(|e| e == "toml") || path.exists() {
            let text = std::fs::read_to_string(path).map_err(|e| ScenarioError::Parse {
                path: name_or_path.into(),
                message: e.to_string(),
            })?;
            return Scenario::parse(&text, name_or_path);
        }
        Err(ScenarioError::Unknown(name_or_path.into()))
    }

    /// Parses and validates a scenario's TOML text; `origin` names it in errors.
    pub fn parse(text: &str, origin: &str) -> Result<Scenario, ScenarioError> {
        let s: Scenario = toml::from_str(text).map_err(|e| ScenarioError::Parse {
            path: origin.into(),
            message: e.to_string(),
        })?;
        s.validate()?;
        Ok(s)
    }

    fn range_check(&self, key: &str, v: f64, lo: f64, hi: f64) -> Result<(), ScenarioError> {
        if v.is_finite() && v >= lo && v <= hi {
            Ok(())
        } else {
            Err(ScenarioError::OutOfRange {
                scenario: self.name.clone(),
                key: key.into(),
                value: v.to_string(),
                range: format!("{lo}..={hi}"),
            })
        }
    }

    /// Checks every value against its allowed range and the rates against each other.
    pub fn validate(&self) -> Result<(), ScenarioError> {
        self.range_check("start.latitude_deg", self.start.latitude_deg, -80.0, 80.0)?;
        self.range_check(
            "start.longitude_deg",
            self.start.longitude_deg,
            -180.0,
            180.0,
        )?;
        self.range_check("start.depth_m", self.start.depth_m, 0.0, 6000.0)?;
        self.range_check("start.heading_deg", self.start.heading_deg, -360.0, 360.0)?;
        self.range_check("start.speed_m_s", self.start.speed_m_s, 0.0, 10.0)?;
        self.range_check("seabed_depth_m", self.seabed_depth_m, 0.0, 11000.0)?;
        let r = &self.rates;
        self.range_check("rates.imu_hz", r.imu_hz as f64, 10.0, 2000.0)?;
        for (key, hz) in [
            ("rates.dvl_hz", r.dvl_hz),
            ("rates.usbl_hz", r.usbl_hz),
            ("rates.depth_hz", r.depth_hz),
            ("rates.magnetometer_hz", r.magnetometer_hz),
            ("rates.gnss_hz", r.gnss_hz),
            ("rates.truth_hz", r.truth_hz),
            ("rates.ctd_hz", r.ctd_hz),
        ] {
            self.range_check(key, hz as f64, 0.0, r.imu_hz as f64)?;
            if hz != 0 && !r.imu_hz.is_multiple_of(hz) {
                return Err(ScenarioError::OutOfRange {
                    scenario: self.name.clone(),
                    key: key.into(),
                    value: hz.to_string(),
                    range: format!("0 or a divisor of rates.imu_hz = {}", r.imu_hz),
                });
            }
        }
        if self.legs.is_empty() {
            return Err(ScenarioError::OutOfRange {
                scenario: self.name.clone(),
                key: "legs".into(),
                value: "[]".into(),
                range: "at least one leg".into(),
            });
        }
        for (i, leg) in self.legs.iter().enumerate() {
            let k = |f: &str| format!("legs[{i}].{f}");
            match leg {
                Leg::Straight { duration_s } => {
                    self.range_check(&k("duration_s"), *duration_s, 0.0, 1.0e6)?
                }
                Leg::Turn {
                    angle_deg,
                    rate_deg_s,
                    bank_deg,
                } => {
                    self.range_check(&k("angle_deg"), *angle_deg, -3600.0, 3600.0)?;
                    self.range_check(&k("rate_deg_s"), *rate_deg_s, 0.01, 30.0)?;
                    self.range_check(&k("bank_deg"), *bank_deg, -30.0, 30.0)?;
                }
                Leg::Depth {
                    change_m,
                    pitch_deg,
                } => {
                    self.range_check(&k("change_m"), *change_m, -6000.0, 6000.0)?;
                    self.range_check(&k("pitch_deg"), *pitch_deg, 1.0, 45.0)?;
                }
                Leg::Speed {
                    target_m_s,
                    accel_m_s2,
                } => {
                    self.range_check(&k("target_m_s"), *target_m_s, 0.0, 10.0)?;
                    self.range_check(&k("accel_m_s2"), *accel_m_s2, 0.001, 5.0)?;
                }
            }
        }
        if let Some(a) = &self.acoustic {
            for (key, v, lo, hi) in a.checks() {
                self.range_check(&key, v, lo, hi)?;
            }
        }
        if let Some(st) = &self.station {
            self.range_check("station.baseline_m", st.baseline_m, 0.01, 10.0)?;
            self.range_check("station.depth_m", st.depth_m, 0.0, 11000.0)?;
            self.range_check("station.north_m", st.north_m, -1.0e5, 1.0e5)?;
            self.range_check("station.east_m", st.east_m, -1.0e5, 1.0e5)?;
            self.range_check("station.yaw_deg", st.yaw_deg, -360.0, 360.0)?;
        }
        self.effects()?;
        Ok(())
    }

    /// The scenario's effects applied on top of the neutral defaults.
    pub fn effects(&self) -> Result<Effects, ScenarioError> {
        let mut e = Effects::default();
        for (name, value) in &self.effects {
            e.set(name, &value.values())
                .map_err(|source| ScenarioError::Effect {
                    scenario: self.name.clone(),
                    source,
                })?;
        }
        Ok(e)
    }

    /// The scenario as TOML text (written into the log header).
    pub fn to_toml(&self) -> String {
        toml::to_string(self).unwrap_or_default()
    }
}

/// The list printed by `auvnav sim --list-scenarios`.
pub fn listing() -> String {
    let mut s = String::new();
    for (name, text) in BUILTIN {
        let desc = Scenario::parse(text, name)
            .map(|s| s.description)
            .unwrap_or_else(|e| format!("(invalid: {e})"));
        s.push_str(&format!("{name:<16} {desc}\n"));
    }
    s
}

/// The geometry of an acoustic positioning system (`[acoustic]`; simulated in `crate::acoustic`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum AcousticKind {
    /// Beacons on the seabed at surveyed places; the vehicle pings.
    Lbl,
    /// A boat's array of receivers; the array pings.
    Array,
    /// One transducer on a ship; the ship pings.
    Single,
}

/// The scenario's `[acoustic]` table.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct AcousticSetup {
    pub kind: AcousticKind,
    /// LBL: each beacon's place (north and east of the start point, depth; m).
    #[serde(default)]
    pub beacons_m: Vec<[f64; 3]>,
    /// Array and single: each receiver's place in the boat's frame (x forward, y starboard, z
    /// down from its GNSS antenna; m).
    #[serde(default)]
    pub receivers_m: Vec<[f64; 3]>,
    /// The boat follows the vehicle: it closes on the vehicle's horizontal position with this
    /// time constant (s).
    #[serde(default = "default_follow")]
    pub boat_follow_s: f64,
    /// …kept this far (north, east; m) from it…
    #[serde(default)]
    pub boat_offset_m: [f64; 2],
    /// …and circling on this radius (m; 0: no circle) with this period (s).
    #[serde(default)]
    pub boat_circle_radius_m: f64,
    #[serde(default = "default_circle_period")]
    pub boat_circle_period_s: f64,
    /// Rate of the boat's pose messages (Hz).
    #[serde(default = "default_pose_hz")]
    pub pose_hz: u32,
    /// The vehicle's transducer in its body frame (m).
    #[serde(default)]
    pub transducer_lever_arm_m: [f64; 3],
}

fn default_follow() -> f64 {
    60.0
}
fn default_circle_period() -> f64 {
    600.0
}
fn default_pose_hz() -> u32 {
    5
}

impl AcousticSetup {
    /// The receivers in the array frame as configured (LBL: the beacons' offsets from the start
    /// point at the surface, which is the array frame's origin).
    pub fn receivers(&self) -> Vec<Vector3<f64>> {
        match self.kind {
            AcousticKind::Lbl => &self.beacons_m,
            AcousticKind::Array | AcousticKind::Single => &self.receivers_m,
        }
        .iter()
        .map(|r| Vector3::from(*r))
        .collect()
    }

    /// Values to range-check: (key, value, low, high).
    pub fn checks(&self) -> Vec<(String, f64, f64, f64)> {
        let mut out = vec![
            (
                "acoustic.boat_follow_s".into(),
                self.boat_follow_s,
                1.0,
                1e5,
            ),
            (
                "acoustic.boat_circle_radius_m".into(),
                self.boat_circle_radius_m,
                0.0,
                1e4,
            ),
            (
                "acoustic.boat_circle_period_s".into(),
                self.boat_circle_period_s,
                10.0,
                1e5,
            ),
            (
                "acoustic.pose_hz".into(),
                f64::from(self.pose_hz),
                1.0,
                100.0,
            ),
            (
                "acoustic.receivers (count)".into(),
                self.receivers().len() as f64,
                1.0,
                4.0,
            ),
        ];
        for (k, r) in self.receivers().iter().enumerate() {
            for i in 0..3 {
                out.push((format!("acoustic.receiver[{k}][{i}]"), r[i], -2e4, 2e4));
            }
        }
        for i in 0..2 {
            out.push((
                format!("acoustic.boat_offset_m[{i}]"),
                self.boat_offset_m[i],
                -1e4,
                1e4,
            ));
        }
        for i in 0..3 {
            out.push((
                format!("acoustic.transducer_lever_arm_m[{i}]"),
                self.transducer_lever_arm_m[i],
                -50.0,
                50.0,
            ));
        }
        out
    }

    /// The navigator's `[navigation.ranges]` for this system as configured (`start`: the
    /// scenario's start point at the surface).
    pub fn ranges_config(&self, start: &Geodetic) -> RangesConfig {
        RangesConfig {
            array: match self.kind {
                AcousticKind::Lbl => ArrayKind::Fixed,
                _ => ArrayKind::Moving,
            },
            origin_latitude_deg: start.latitude_rad.to_degrees(),
            origin_longitude_deg: start.longitude_rad.to_degrees(),
            origin_height_m: 0.0,
            receivers_m: self.receivers().iter().map(|r| [r.x, r.y, r.z]).collect(),
            transducer_lever_arm_m: self.transducer_lever_arm_m,
            two_way: true,
            interrogator: match self.kind {
                AcousticKind::Lbl => Interrogator::Vehicle,
                _ => Interrogator::Array,
            },
            ..Default::default()
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn builtin_scenarios_parse() {
        for (name, text) in BUILTIN {
            let s = Scenario::parse(text, name).expect(name);
            assert_eq!(&s.name, name);
        }
    }

    #[test]
    fn errors_name_the_key_and_the_range() {
        let text = BUILTIN[0].1.replace("speed_m_s = 2.0", "speed_m_s = 20.0");
        let err = Scenario::parse(&text, "x")
            .expect_err("out of range")
            .to_string();
        assert!(
            err.contains("start.speed_m_s") && err.contains("0..=10"),
            "{err}"
        );
        let err = Scenario::parse("name = \"x\"\nbogus = 1\n", "x.toml")
            .expect_err("unknown key")
            .to_string();
        assert!(err.contains("bogus"), "{err}");
    }
}
