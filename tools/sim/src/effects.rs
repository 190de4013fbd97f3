//! The simulator's error effects. Each has a stable dotted name (the same names model discovery
//! reports), a unit, a neutral default (the effect is off), an allowed range per component and a
//! description. They are set from a scenario file's `[effects]` table or from the command line
//! (`--effect dvl.scale_factor=1.004`, vectors as `--effect dvl.lever_arm=0.5,0,0.2`).

use std::fmt::Write as _;

/// The description of one effect.
#[derive(Debug, Clone, Copy)]
pub struct EffectSpec {
    pub name: &'static str,
    pub unit: &'static str,
    pub components: usize,
    pub min: f64,
    pub max: f64,
    pub default: &'static [f64],
    pub doc: &'static str,
}

#[derive(Debug, thiserror::Error, PartialEq)]
pub enum EffectError {
    #[error("unknown effect {name:?}; `auvnav sim --list-effects` lists the known ones")]
    Unknown { name: String },
    #[error("effect {name}: expected {expected} comma-separated number(s), got {got:?}")]
    Arity {
        name: String,
        expected: usize,
        got: String,
    },
    #[error("effect {name}: {value} is outside the allowed range {min}..={max} ({unit})")]
    OutOfRange {
        name: String,
        value: f64,
        min: f64,
        max: f64,
        unit: &'static str,
    },
    #[error("effect setting {0:?} is not NAME=VALUE")]
    Syntax(String),
}

/// A field type an effect can have.
pub trait EffectField: Sized {
    fn from_values(v: &[f64]) -> Option<Self>;
    fn to_values(&self) -> Vec<f64>;
    /// Builds the default value; components missing from `v` are zero (the spec test checks arity).
    fn from_defaults(v: &[f64]) -> Self;
}

impl EffectField for f64 {
    fn from_values(v: &[f64]) -> Option<Self> {
        (v.len() == 1).then(|| v[0])
    }
    fn to_values(&self) -> Vec<f64> {
        vec![*self]
    }
    fn from_defaults(v: &[f64]) -> Self {
        v.first().copied().unwrap_or(0.0)
    }
}

impl<const N: usize> EffectField for [f64; N] {
    fn from_values(v: &[f64]) -> Option<Self> {
        v.try_into().ok()
    }
    fn to_values(&self) -> Vec<f64> {
        self.to_vec()
    }
    fn from_defaults(v: &[f64]) -> Self {
        let mut out = [0.0; N];
        for (o, x) in out.iter_mut().zip(v) {
            *o = *x;
        }
        out
    }
}

macro_rules! effects {
    ($(
        $(#[doc = $doc:literal])+
        $field:ident : $ty:ty = $name:literal, unit $unit:literal, range $min:literal ..= $max:literal, default [$($d:expr),+];
    )*) => {
        /// The values of every effect. Field names are the dotted names with `.` replaced by `_`.
        #[derive(Debug, Clone, PartialEq)]
        pub struct Effects {
            $( $(#[doc = $doc])+ pub $field: $ty, )*
        }

        impl Default for Effects {
            fn default() -> Self {
                Effects { $( $field: <$ty as EffectField>::from_defaults(&[$($d),+]), )* }
            }
        }

        /// Every effect, in listing order.
        pub const SPECS: &[EffectSpec] = &[
            $( EffectSpec {
                name: $name,
                unit: $unit,
                components: std::mem::size_of::<$ty>() / 8,
                min: $min,
                max: $max,
                default: &[$($d),+],
                doc: concat!($($doc),+),
            }, )*
        ];

        impl Effects {
            /// Sets one effect by name, checking the number of components and the range.
            pub fn set(&mut self, name: &str, values: &[f64]) -> Result<(), EffectError> {
                match name {
                    $( $name => {
                        let spec = spec($name).ok_or(EffectError::Unknown { name: name.into() })?;
                        check(spec, values)?;
                        self.$field = <$ty as EffectField>::from_values(values).ok_or_else(|| EffectError::Arity {
                            name: name.into(), expected: spec.components, got: format!("{values:?}"),
                        })?;
                        Ok(())
                    } )*
                    _ => Err(EffectError::Unknown { name: name.into() }),
                }
            }

            /// The current value of an effect by name.
            pub fn get(&self, name: &str) -> Option<Vec<f64>> {
                match name {
                    $( $name => Some(EffectField::to_values(&self.$field)), )*
                    _ => None,
                }
            }
        }
    };
}

fn spec(name: &str) -> Option<&'static EffectSpec> {
    SPECS.iter().find(|s| s.name == name)
}

fn check(spec: &EffectSpec, values: &[f64]) -> Result<(), EffectError> {
    if values.len() != spec.components {
        return Err(EffectError::Arity {
            name: spec.name.into(),
            expected: spec.components,
            got: format!("{values:?}"),
        });
    }
    for &v in values {
        if !(v.is_finite() && v >= spec.min && v <= spec.max) {
            return Err(EffectError::OutOfRange {
                name: spec.name.into(),
                value: v,
                min: spec.min,
                max: spec.max,
                unit: spec.unit,
            });
        }
    }
    Ok(())
}

effects! {
    /// Constant gyro bias per body axis.
    imu_gyro_bias: [f64; 3] = "imu.gyro_bias", unit "deg/h", range -1000.0..=1000.0, default [0.0, 0.0, 0.0];
    /// Constant accelerometer bias per body axis.
    imu_accel_bias: [f64; 3] = "imu.accel_bias", unit "ug", range -100000.0..=100000.0, default [0.0, 0.0, 0.0];
    /// Gyro bias instability: one-sigma of a first-order Gauss-Markov bias per axis (correlation time imu.bias_correlation_time).
    imu_gyro_bias_instability: f64 = "imu.gyro_bias_instability", unit "deg/h", range 0.0..=1000.0, default [0.0];
    /// Accelerometer bias instability: one-sigma of a first-order Gauss-Markov bias per axis.
    imu_accel_bias_instability: f64 = "imu.accel_bias_instability", unit "ug", range 0.0..=100000.0, default [0.0];
    /// Correlation time of the Gauss-Markov bias instability.
    imu_bias_correlation_time: f64 = "imu.bias_correlation_time", unit "s", range 1.0..=1.0e6, default [3600.0];
    /// Gyro angle random walk (white rate noise).
    imu_angle_random_walk: f64 = "imu.angle_random_walk", unit "deg/sqrt(h)", range 0.0..=10.0, default [0.0];
    /// Accelerometer velocity random walk (white specific-force noise).
    imu_velocity_random_walk: f64 = "imu.velocity_random_walk", unit "m/s/sqrt(h)", range 0.0..=10.0, default [0.0];
    /// Gyro scale-factor error per axis.
    imu_gyro_scale_factor: [f64; 3] = "imu.gyro_scale_factor", unit "ppm", range -100000.0..=100000.0, default [0.0, 0.0, 0.0];
    /// Accelerometer scale-factor error per axis.
    imu_accel_scale_factor: [f64; 3] = "imu.accel_scale_factor", unit "ppm", range -100000.0..=100000.0, default [0.0, 0.0, 0.0];
    /// Gyro axis misalignment: small rotation (x, y, z) of the gyro triad w.r.t. the body frame.
    imu_gyro_misalignment: [f64; 3] = "imu.gyro_misalignment", unit "mrad", range -50.0..=50.0, default [0.0, 0.0, 0.0];
    /// Accelerometer axis misalignment: small rotation (x, y, z) of the accelerometer triad w.r.t. the body frame.
    imu_accel_misalignment: [f64; 3] = "imu.accel_misalignment", unit "mrad", range -50.0..=50.0, default [0.0, 0.0, 0.0];
    /// Quantum of the gyro angle increment (0 = none); the rounding residual is carried to the next sample.
    imu_gyro_quantum: f64 = "imu.gyro_quantum", unit "rad", range 0.0..=1.0e-3, default [0.0];
    /// Quantum of the accelerometer velocity increment (0 = none); the residual is carried.
    imu_accel_quantum: f64 = "imu.accel_quantum", unit "m/s", range 0.0..=1.0e-1, default [0.0];

    /// White noise on each DVL beam velocity.
    dvl_noise: f64 = "dvl.noise", unit "m/s", range 0.0..=1.0, default [0.0];
    /// DVL velocity scale factor (1 = none); multiplies the true velocity.
    dvl_scale_factor: f64 = "dvl.scale_factor", unit "1", range 0.9..=1.1, default [1.0];
    /// DVL mounting roll: rotation of the DVL frame w.r.t. the body frame about x.
    dvl_mount_roll: f64 = "dvl.mount_roll", unit "deg", range -10.0..=10.0, default [0.0];
    /// DVL mounting pitch: rotation of the DVL frame w.r.t. the body frame about y.
    dvl_mount_pitch: f64 = "dvl.mount_pitch", unit "deg", range -10.0..=10.0, default [0.0];
    /// DVL mounting yaw: rotation of the DVL frame w.r.t. the body frame about z (velocity in the DVL frame turns by -yaw).
    dvl_mount_yaw: f64 = "dvl.mount_yaw", unit "deg", range -180.0..=180.0, default [0.0];
    /// Position of the DVL w.r.t. the IMU in the body frame (adds omega x l to the measured velocity).
    dvl_lever_arm: [f64; 3] = "dvl.lever_arm", unit "m", range -10.0..=10.0, default [0.0, 0.0, 0.0];
    /// DVL time offset: the velocity stamped at t is the vehicle's velocity at t - offset.
    dvl_time_offset: f64 = "dvl.time_offset", unit "s", range -2.0..=2.0, default [0.0];
    /// Rate at which bottom lock is lost (Poisson events), each loss lasting dvl.bottom_lock_loss_duration.
    dvl_bottom_lock_loss_rate: f64 = "dvl.bottom_lock_loss_rate", unit "1/s", range 0.0..=1.0, default [0.0];
    /// Duration of one loss of bottom lock.
    dvl_bottom_lock_loss_duration: f64 = "dvl.bottom_lock_loss_duration", unit "s", range 0.0..=3600.0, default [10.0];
    /// Maximum altitude at which the DVL holds bottom lock.
    dvl_max_altitude: f64 = "dvl.max_altitude", unit "m", range 1.0..=1000.0, default [200.0];
    /// True sound speed in the water; the DVL assumes 1500 m/s, so velocities scale by 1500/value.
    dvl_sound_speed: f64 = "dvl.sound_speed", unit "m/s", range 1375.0..=1650.0, default [1500.0];
    /// White noise on each axis of a DVL water-track velocity; above 0 the DVL also reports, with
    /// every ping, its velocity relative to the water (flagged TRACK_WATER), with or without bottom lock.
    dvl_water_track_noise: f64 = "dvl.water_track_noise", unit "m/s", range 0.0..=1.0, default [0.0];
    /// A DVL beam (1..4; 0 = none) blocked for dvl.beam_blocked_fraction of the time, in 30 s spells: its radial velocity is missing and the DVL reports no instrument velocity then, only the other three beams.
    dvl_beam_blocked: f64 = "dvl.beam_blocked", unit "1", range 0.0..=4.0, default [0.0];
    /// Fraction of the time the beam dvl.beam_blocked is blocked.
    dvl_beam_blocked_fraction: f64 = "dvl.beam_blocked_fraction", unit "1", range 0.0..=0.95, default [0.0];
    /// Scale-factor error of each DVL beam (1..4) on its radial velocity: the device computes the velocity from the beams as if they were right, so one beam's error enters the velocity in proportion to its share of the least-squares solution.
    dvl_beam_scale_factor: [f64; 4] = "dvl.beam_scale_factor", unit "ppm", range -100000.0..=100000.0, default [0.0, 0.0, 0.0, 0.0];
    /// Angle error of each DVL beam (1..4): the beam points this much further from the DVL's z axis than the 30° the device assumes (same azimuth).
    dvl_beam_angle_error: [f64; 4] = "dvl.beam_angle_error", unit "deg", range -5.0..=5.0, default [0.0, 0.0, 0.0, 0.0];
    /// Time-correlated DVL velocity error: one-sigma of a first-order Gauss-Markov error on each DVL-frame axis (correlation time dvl.velocity_error_correlation_time), as bottom returns from a patchy or moving bed, or a platform's own flow, give; it colours the residual where dvl.noise is white.
    dvl_velocity_error_instability: f64 = "dvl.velocity_error_instability", unit "m/s", range 0.0..=1.0, default [0.0];
    /// Correlation time of dvl.velocity_error_instability.
    dvl_velocity_error_correlation_time: f64 = "dvl.velocity_error_correlation_time", unit "s", range 0.1..=1.0e5, default [60.0];
    /// Velocity of the bed under bottom track, north and east: a moving bed (sediment the current carries) or a bottom track locked on something that moves. The DVL measures the vehicle's velocity relative to it, so the error is fixed on the Earth and turns with the heading in the DVL's frame; water track is not affected.
    dvl_bed_velocity: [f64; 2] = "dvl.bed_velocity", unit "m/s", range -3.0..=3.0, default [0.0, 0.0];
    /// A periodic DVL velocity error: its amplitude on each DVL-frame axis, the error at stamp t being this × sin(2π t / dvl.periodic_velocity_error_period + dvl.periodic_velocity_error_phase) (t in seconds of the recording's clock), as a platform's oscillation (a porpoising vehicle, a swell, a flapping mount) seen through an unmodelled lever arm or flow gives; the axes share one phase, a negative amplitude is an axis in antiphase.
    dvl_periodic_velocity_error: [f64; 3] = "dvl.periodic_velocity_error", unit "m/s", range -1.0..=1.0, default [0.0, 0.0, 0.0];
    /// Period of dvl.periodic_velocity_error.
    dvl_periodic_velocity_error_period: f64 = "dvl.periodic_velocity_error_period", unit "s", range 0.5..=1.0e5, default [60.0];
    /// Phase of dvl.periodic_velocity_error at t = 0.
    dvl_periodic_velocity_error_phase: f64 = "dvl.periodic_velocity_error_phase", unit "deg", range -360.0..=360.0, default [0.0];

    /// A compass's heading-dependent deviation, the classical card: the compass (the attitude channel, `rates.compass_hz`) shows ψc where ψc − δ(ψc) is the true heading, δ(ψc) = A + B sin ψc + C cos ψc + D sin 2ψc + E cos 2ψc with the coefficients A, B, C, D, E: A a constant offset (a misaligned lubber line, an uncorrected declination), B and C the one-cycle part (permanent magnetism of the vehicle), D and E the two-cycle part (induced magnetism of soft iron).
    heading_deviation: [f64; 5] = "heading.deviation", unit "deg", range -45.0..=45.0, default [0.0, 0.0, 0.0, 0.0, 0.0];

    /// The water current at the surface, north and east (the vehicle's velocity relative to the water is its velocity over the ground minus the current).
    water_current: [f64; 2] = "water.current", unit "m/s", range -5.0..=5.0, default [0.0, 0.0];
    /// Stationary one-sigma of the current's slowly varying part (first-order Gauss-Markov, 600 s correlation), per axis.
    water_current_variation: f64 = "water.current_variation", unit "m/s", range 0.0..=2.0, default [0.0];
    /// Decrease of the current with depth: the current at depth d is the surface's times max(0, 1 - shear d).
    water_current_shear: f64 = "water.current_shear", unit "1/m", range 0.0..=1.0, default [0.0];

    /// White noise on the USBL slant range.
    usbl_range_noise: f64 = "usbl.range_noise", unit "m", range 0.0..=100.0, default [0.0];
    /// White noise on each USBL range difference.
    usbl_range_difference_noise: f64 = "usbl.range_difference_noise", unit "m", range 0.0..=1.0, default [0.0];
    /// White noise on the USBL azimuth and elevation.
    usbl_angle_noise: f64 = "usbl.angle_noise", unit "deg", range 0.0..=10.0, default [0.0];
    /// Fraction of USBL fixes hit by a multipath outlier (range too long by usbl.outlier_range).
    usbl_outlier_fraction: f64 = "usbl.outlier_fraction", unit "1", range 0.0..=0.5, default [0.0];
    /// Range of multipath outlier magnitudes: minimum, maximum extra path length (uniform).
    usbl_outlier_range: [f64; 2] = "usbl.outlier_range", unit "m", range 0.0..=1000.0, default [10.0, 50.0];
    /// Error of the surveyed array yaw: the true array is rotated by this angle about down.
    usbl_array_yaw: f64 = "usbl.array_yaw", unit "deg", range -30.0..=30.0, default [0.0];
    /// Error of the surveyed array position: the true array sits this far (N, E, D) from the surveyed one.
    usbl_array_offset: [f64; 3] = "usbl.array_offset", unit "m", range -100.0..=100.0, default [0.0, 0.0, 0.0];
    /// Displacement of each hydrophone (receiver) 1..4 from its nominal place in the array frame
    /// (x, y, z down per hydrophone, row by row): an array whose geometry differs from its
    /// configuration, seen in the range differences and in per-receiver ranges.
    usbl_hydrophone_offset: [f64; 12] = "usbl.hydrophone_offset", unit "m", range -100.0..=100.0, default [0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0];
    /// Constant error of each receiver's range (receiver 0..3 of an acoustic system's ranges):
    /// its own detection delay, cable or electronics, in metres of range.
    usbl_receiver_range_bias: [f64; 4] = "usbl.receiver_range_bias", unit "m", range -100.0..=100.0, default [0.0, 0.0, 0.0, 0.0];
    /// USBL latency: a fix is delivered (and stamped) this long after its time of validity.
    usbl_latency: f64 = "usbl.latency", unit "s", range 0.0..=5.0, default [0.0];
    /// True sound speed for the acoustic ranging; the USBL assumes 1500 m/s.
    usbl_sound_speed: f64 = "usbl.sound_speed", unit "m/s", range 1375.0..=1650.0, default [1500.0];
    /// Maximum slant range at which the USBL delivers fixes.
    usbl_max_range: f64 = "usbl.max_range", unit "m", range 1.0..=10000.0, default [2000.0];
    /// Fraction of per-receiver ranges an acoustic system drops (no detection on that receiver).
    usbl_dropout: f64 = "usbl.dropout", unit "1", range 0.0..=0.95, default [0.0];
    /// Noise of a moving array's pose as its boat reports it: GNSS position (m, per horizontal
    /// axis) and heading (deg), white per pose.
    usbl_array_pose_noise: [f64; 2] = "usbl.array_pose_noise", unit "m, deg", range 0.0..=100.0, default [0.0, 0.0];
    /// Time constant of the tracking filter an acoustic system runs on its own fixes: the fix it
    /// reports is its per-ping solution smoothed exponentially in its array frame (0: per ping),
    /// its reported one-sigma the per-ping one. The measured Water Linked G2 follows per-ping
    /// fixes from its own ranges smoothed with about 2 s.
    usbl_fix_time_constant: f64 = "usbl.fix_time_constant", unit "s", range 0.0..=60.0, default [0.0];

    /// White noise on depth.
    depth_noise: f64 = "depth.noise", unit "m", range 0.0..=10.0, default [0.0];
    /// Constant depth bias (sensor offset).
    depth_bias: f64 = "depth.bias", unit "m", range -10.0..=10.0, default [0.0];
    /// True water density; the sensor converts pressure with 1025 kg/m^3, so depth scales by value/1025.
    depth_density: f64 = "depth.density", unit "kg/m^3", range 990.0..=1050.0, default [1025.0];
    /// Position of the depth (pressure) sensor from the IMU, body axes (forward, starboard, down): it reads the depth of that point, depth + (C_b^n l)_down, so pitch and roll move the reading.
    depth_lever_arm: [f64; 3] = "depth.lever_arm", unit "m", range -10.0..=10.0, default [0.0, 0.0, 0.0];

    /// Hard-iron offset added to the magnetometer reading (body axes).
    mag_hard_iron: [f64; 3] = "mag.hard_iron", unit "uT", range -1000.0..=1000.0, default [0.0, 0.0, 0.0];
    /// Soft-iron matrix (row-major 3x3) applied to the true body field before the hard iron.
    mag_soft_iron: [f64; 9] = "mag.soft_iron", unit "1", range -2.0..=2.0, default [1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0];
    /// White noise per magnetometer axis.
    mag_noise: f64 = "mag.noise", unit "uT", range 0.0..=100.0, default [0.0];
    /// Magnetic declination of the Earth field (east of true north).
    mag_declination: f64 = "mag.declination", unit "deg", range -180.0..=180.0, default [0.0];
    /// Magnetic inclination (dip, positive down).
    mag_inclination: f64 = "mag.inclination", unit "deg", range -90.0..=90.0, default [45.0];
    /// Total intensity of the Earth field.
    mag_intensity: f64 = "mag.intensity", unit "uT", range 1.0..=100.0, default [48.0];

    /// White noise on each horizontal GNSS position component (surface only).
    gnss_noise: f64 = "gnss.noise", unit "m", range 0.0..=100.0, default [0.0];
}

/// Parses `NAME=V` or `NAME=V1,V2,V3`.
pub fn parse_setting(s: &str) -> Result<(String, Vec<f64>), EffectError> {
    let (name, value) = s
        .split_once('=')
        .ok_or_else(|| EffectError::Syntax(s.into()))?;
    let name = name.trim();
    if spec(name).is_none() {
        return Err(EffectError::Unknown { name: name.into() });
    }
    let values: Result<Vec<f64>, _> = value.split(',').map(|v| v.trim().parse::<f64>()).collect();
    let values = values.map_err(|_| EffectError::Arity {
        name: name.into(),
        expected: spec(name).map(|s| s.components).unwrap_or(1),
        got: value.into(),
    })?;
    Ok((name.to_string(), values))
}

/// An effect set file: a TOML `[effects]` table (dotted name → number or list of numbers), the
/// same table a scenario file holds. `auvnav discover --write-effects` writes one;
/// `auvnav sim --effects-from`, `auvnav perturb --effects-from` and `auvnav discover
/// --nominal-from` read it. Other tables and keys in the file are left alone, so a scenario file
/// or a discover report directory's `effects.toml` serve alike.
pub mod set {
    use super::{EffectError, Effects};
    use std::fmt::Write as _;

    #[derive(Debug, thiserror::Error)]
    pub enum EffectSetError {
        #[error("not TOML: {0}")]
        Toml(#[from] toml::de::Error),
        #[error("no [effects] table")]
        NoTable,
        #[error("effect {0:?}: expected a number or a list of numbers")]
        NotNumeric(String),
        #[error(transparent)]
        Effect(#[from] EffectError),
    }

    /// Reads the `[effects]` table: the settings in file order, each checked against the
    /// vocabulary (name, number of components, range).
    pub fn parse(text: &str) -> Result<Vec<(String, Vec<f64>)>, EffectSetError> {
        let doc: toml::Table = toml::from_str(text)?;
        let Some(table) = doc.get("effects").and_then(|t| t.as_table()) else {
            return Err(EffectSetError::NoTable);
        };
        let number = |v: &toml::Value| v.as_float().or_else(|| v.as_integer().map(|i| i as f64));
        let mut out = Vec::new();
        let mut check = Effects::default();
        for (name, value) in table {
            let values = match value {
                toml::Value::Array(a) => a.iter().map(number).collect::<Option<Vec<f64>>>(),
                v => number(v).map(|x| vec![x]),
            }
            .ok_or_else(|| EffectSetError::NotNumeric(name.clone()))?;
            check.set(name, &values)?;
            out.push((name.clone(), values));
        }
        Ok(out)
    }

    /// The `[effects]` table of `settings`, after `comment` lines (each prefixed with `# `).
    /// Numbers keep all their digits, so that reading the file back gives the same values.
    pub fn to_toml(comment: &str, settings: &[(String, Vec<f64>)]) -> String {
        let mut s = String::new();
        for line in comment.lines() {
            let _ = writeln!(s, "# {line}");
        }
        let _ = writeln!(s, "[effects]");
        let num = |x: f64| {
            let t = format!("{x:?}");
            if t.contains('.') || t.contains('e') || t.contains("inf") || t.contains("NaN") {
                t
            } else {
                format!("{t}.0")
            }
        };
        for (name, v) in settings {
            let value = if v.len() == 1 {
                num(v[0])
            } else {
                format!(
                    "[{}]",
                    v.iter().map(|&x| num(x)).collect::<Vec<_>>().join(", ")
                )
            };
            let _ = writeln!(s, "\"{name}\" = {value}");
        }
        s
    }

    /// Applies the settings to `e`.
    pub fn apply(e: &mut Effects, settings: &[(String, Vec<f64>)]) -> Result<(), EffectError> {
        for (name, v) in settings {
            e.set(name, v)?;
        }
        Ok(())
    }

    /// The effects of `e` that differ from the neutral defaults, in listing order.
    pub fn differences(e: &Effects) -> Vec<(String, Vec<f64>)> {
        let d = Effects::default();
        super::SPECS
            .iter()
            .filter_map(|s| {
                let v = e.get(s.name)?;
                (Some(&v) != d.get(s.name).as_ref()).then(|| (s.name.to_string(), v))
            })
            .collect()
    }
}

/// The effect list as printed by `auvnav sim --list-effects`.
pub fn listing() -> String {
    let mut s = String::new();
    for spec in SPECS {
        let _ = writeln!(
            s,
            "{:<32} {:>2} x [{} ..= {}] {:<12} default {:?}\n    {}",
            spec.name,
            spec.components,
            spec.min,
            spec.max,
            spec.unit,
            spec.default,
            spec.doc.trim()
        );
    }
    s
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn an_effect_set_file_reads_back_what_was_written() {
        let mut e = Effects::default();
        e.set("dvl.lever_arm", &[-1.8512345678901234, 0.0, 0.25])
            .expect("valid");
        e.set("dvl.time_offset", &[-1.0]).expect("valid");
        e.set("depth.density", &[1000.0]).expect("valid");
        let diff = set::differences(&e);
        assert_eq!(
            diff.iter().map(|(n, _)| n.as_str()).collect::<Vec<_>>(),
            ["dvl.lever_arm", "dvl.time_offset", "depth.density"]
        );
        let text = set::to_toml("found by discover\nsecond line", &diff);
        assert!(text.starts_with("# found by discover\n# second line\n[effects]\n"));
        let back = set::parse(&text).expect("valid");
        let mut f = Effects::default();
        set::apply(&mut f, &back).expect("valid");
        assert_eq!(e, f);
    }

    #[test]
    fn an_effect_set_file_with_a_bad_entry_is_refused_with_its_name() {
        for (text, what) in [
            ("[effects]\n\"dvl.scale\" = 1.0\n", "unknown effect"),
            ("[effects]\n\"dvl.lever_arm\" = [1.0, 2.0]\n", "expected 3"),
            (
                "[effects]\n\"dvl.scale_factor\" = 2.0\n",
                "outside the allowed range",
            ),
            (
                "[effects]\n\"dvl.scale_factor\" = \"x\"\n",
                "a number or a list",
            ),
            ("[other]\nx = 1\n", "no [effects] table"),
            ("[effects\n", "not TOML"),
        ] {
            let err = set::parse(text).expect_err("refused").to_string();
            assert!(err.contains(what), "{text:?}: {err}");
        }
        // Integers are numbers; other tables are left alone.
        let v = set::parse("name = \"s\"\n[effects]\n\"depth.bias\" = 1\n").expect("valid");
        assert_eq!(v, vec![("depth.bias".to_string(), vec![1.0])]);
    }

    #[test]
    fn every_spec_is_settable_and_its_default_is_in_range() {
        let mut e = Effects::default();
        for spec in SPECS {
            assert_eq!(spec.default.len(), spec.components, "{}", spec.name);
            assert_eq!(
                e.get(spec.name).as_deref(),
                Some(spec.default),
                "{}",
                spec.name
            );
            e.set(spec.name, spec.default).expect(spec.name);
        }
        assert_eq!(e, Effects::default());
    }

    #[test]
    fn rejects_unknown_names_wrong_arity_and_out_of_range() {
        let mut e = Effects::default();
        assert!(matches!(
            e.set("dvl.scale", &[1.0]),
            Err(EffectError::Unknown { .. })
        ));
        assert!(matches!(
            e.set("dvl.lever_arm", &[1.0]),
            Err(EffectError::Arity { .. })
        ));
        let err = e.set("dvl.scale_factor", &[1.5]).expect_err("out of range");
        assert_eq!(
            err.to_string(),
            "effect dvl.scale_factor: 1.5 is outside the allowed range 0.9..=1.1 (1)"
        );
        assert!(e.set("dvl.scale_factor", &[f64::NAN]).is_err());
        assert_eq!(
            parse_setting("dvl.lever_arm=0.5, 0, 0.2"),
            Ok(("dvl.lever_arm".into(), vec![0.5, 0.0, 0.2]))
        );
        assert!(parse_setting("dvl.scale_factor").is_err());
    }
}
