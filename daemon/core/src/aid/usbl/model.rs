//! USBL measurement models (S-USBL).
//!
//! The docking station carries the USBL array: a central transducer at the surveyed position and
//! four hydrophones in the array frame a (x, y horizontal, z down; yaw surveyed from north),
//! 1 and 3 on ±x, 2 and 4 on ±y, at half the baseline from the centre. The vehicle carries the
//! responder at lever arm l^b from the IMU.
//!
//! * **Tight** ([`predict_tight`]): slant range R = |p_a| from the central transducer and the range
//!   differences ΔR13 = |p_a − h1| − |p_a − h3|, ΔR24 = |p_a − h2| − |p_a − h4|, with
//!   p_a = C_n^a (r_auv − r_array + C_b^n l^b) — exact geometry (the NED offset is exact, through
//!   ECEF, and the lever arm is turned from the vehicle's NED into the array's).
//! * **Loose** ([`fix_position_ned`]): the device's own fix from slant range and angles, as a
//!   position of the responder in the array's NED frame.
//! * **Angles to range differences** ([`range_differences_from_angles`]): for devices that report
//!   azimuth/elevation instead of range differences, the far-field relation ΔR13 ≈ −b·u_x,
//!   ΔR24 ≈ −b·u_y (u the unit direction to the responder); its error is below b²/R.
//!
//! The measurements are nonlinear in the state; they are fused by the unscented or linearised
//! update of [`crate::ekf::unscented`] (see [`super`]).

use super::config::{Coupling, UsblConfig};
use crate::earth::{Geodetic, c_ecef_to_ned, ned_offset};
use nalgebra::{Matrix3, Rotation3, Vector3};

/// The station's USBL array as surveyed.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct UsblArray {
    /// Position of the central transducer.
    pub position: Geodetic,
    /// Rotation NED → array frame (from the surveyed yaw, and roll/pitch when known).
    pub c_ned_to_array: Matrix3<f64>,
    /// Hydrophone positions in the array frame (m).
    pub hydrophones: [Vector3<f64>; 4],
}

impl UsblArray {
    /// A level array at `position`, its x axis `yaw_rad` from north, hydrophones at ±b/2 on x (1,
    /// 3) and y (2, 4).
    pub fn level(position: Geodetic, yaw_rad: f64, baseline_m: f64) -> UsblArray {
        let h = baseline_m / 2.0;
        UsblArray {
            position,
            c_ned_to_array: Rotation3::from_euler_angles(0.0, 0.0, yaw_rad)
                .inverse()
                .into_inner(),
            hydrophones: [
                Vector3::new(h, 0.0, 0.0),
                Vector3::new(0.0, h, 0.0),
                Vector3::new(-h, 0.0, 0.0),
                Vector3::new(0.0, -h, 0.0),
            ],
        }
    }

    /// The responder in the array frame (m): vehicle (IMU) position, attitude C_b^n (the
    /// vehicle's local NED), lever arm. The lever arm is turned from the vehicle's NED into the
    /// array's (they differ by the arc between them: 0.3 mrad at 2 km).
    pub fn responder_in_array(
        &self,
        vehicle: &Geodetic,
        c_body_to_ned: &Matrix3<f64>,
        lever_arm_b: &Vector3<f64>,
    ) -> Vector3<f64> {
        let c_vehicle_ned_to_array_ned =
            c_ecef_to_ned(self.position.latitude_rad, self.position.longitude_rad)
                * c_ecef_to_ned(vehicle.latitude_rad, vehicle.longitude_rad).transpose();
        self.c_ned_to_array
            * (ned_offset(&self.position, vehicle)
                + c_vehicle_ned_to_array_ned * c_body_to_ned * lever_arm_b)
    }
}

/// The tight measurement [R, ΔR13, ΔR24] (m) predicted for a responder at `p_a` (array frame).
pub fn predict_tight(array: &UsblArray, p_a: &Vector3<f64>) -> Vector3<f64> {
    let r = array.hydrophones.map(|h| (p_a - h).norm());
    Vector3::new(p_a.norm(), r[0] - r[2], r[1] - r[3])
}

/// The responder position (array NED frame: north, east, down from the transducer, m) from a slant
/// range and the array-frame azimuth (from x towards y) and elevation (positive towards −z, up).
pub fn fix_position_ned(
    array: &UsblArray,
    range_m: f64,
    azimuth: f64,
    elevation: f64,
) -> Vector3<f64> {
    let p_a = range_m
        * Vector3::new(
            elevation.cos() * azimuth.cos(),
            elevation.cos() * azimuth.sin(),
            -elevation.sin(),
        );
    array.c_ned_to_array.transpose() * p_a
}

/// Far-field range differences [ΔR13, ΔR24] from angles (for devices that report angles): the
/// direction u = (cos el cos az, cos el sin az, −sin el) and ΔR13 ≈ −b u_x, ΔR24 ≈ −b u_y for a
/// cross array of baseline b. The approximation error is below b²/R.
pub fn range_differences_from_angles(baseline_m: f64, azimuth: f64, elevation: f64) -> [f64; 2] {
    [
        -baseline_m * elevation.cos() * azimuth.cos(),
        -baseline_m * elevation.cos() * azimuth.sin(),
    ]
}

/// A USBL measurement ready for the filter.
#[derive(Debug, Clone, PartialEq)]
pub struct UsblMeasurement {
    /// Tight: [R, ΔR13, ΔR24] (m). Loose: the responder's position from the array in
    /// line-of-sight coordinates [along the line of sight, across it horizontally (azimuth),
    /// across it vertically (elevation)] (m), in which the fix's noise is uncorrelated.
    pub z: Vector3<f64>,
    /// Nominal noise covariance (diagonal).
    pub r: Matrix3<f64>,
    /// Loose: rotation from the array's NED frame to the line-of-sight coordinates (so the
    /// adaptive estimate and the gate work on independent components); tight: identity.
    pub frame: Matrix3<f64>,
}

/// Why a fix cannot be used.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
pub enum UsblInputError {
    #[error("no slant range")]
    NoRange,
    #[error("slant range missing, non-finite or out of range")]
    BadRange,
    #[error("neither range differences nor angles")]
    NoDirection,
    #[error("range differences or angles non-finite or out of range")]
    BadDirection,
}

/// The measurement the configured coupling uses from a device fix. Range differences are taken
/// as reported, or derived from azimuth/elevation through the baseline (far field); the loose fix
/// is the device's position, or computed from range and angles, turned into the array's NED frame
/// through the surveyed orientation.
pub fn measurement(
    cfg: &UsblConfig,
    array: &UsblArray,
    m: &auvnav_shm_schema::UsblFixV1,
) -> Result<UsblMeasurement, UsblInputError> {
    use auvnav_shm_schema::UsblFixV1 as F;
    if m.validity & F::VALID_RANGE == 0 {
        return Err(UsblInputError::NoRange);
    }
    let range = m.slant_range_m;
    if !(range.is_finite() && range > 0.0 && range <= cfg.max_range_m) {
        return Err(UsblInputError::BadRange);
    }
    let angles = m.validity & F::VALID_ANGLES != 0;
    let angles_ok = m.azimuth_rad.is_finite()
        && m.azimuth_rad.abs() <= 2.0 * std::f64::consts::PI
        && m.elevation_rad.abs() <= std::f64::consts::FRAC_PI_2;
    let sr = cfg.range_std_m;
    let sa = cfg.angle_std_deg.to_radians();
    match cfg.coupling {
        Coupling::Tight => {
            let (d, sd) = if m.validity & F::VALID_RANGE_DIFFERENCES != 0 {
                let d = m.range_difference_m;
                if !d
                    .iter()
                    .all(|x| x.is_finite() && x.abs() <= cfg.baseline_m * 1.05)
                {
                    return Err(UsblInputError::BadDirection);
                }
                (d, cfg.range_difference_std_m)
            } else if angles {
                if !angles_ok {
                    return Err(UsblInputError::BadDirection);
                }
                (
                    range_differences_from_angles(cfg.baseline_m, m.azimuth_rad, m.elevation_rad),
                    cfg.baseline_m * sa,
                )
            } else {
                return Err(UsblInputError::NoDirection);
            };
            Ok(UsblMeasurement {
                z: Vector3::new(range, d[0], d[1]),
                r: Matrix3::from_diagonal(&Vector3::new(sr * sr, sd * sd, sd * sd)),
                frame: Matrix3::identity(),
            })
        }
        Coupling::Loose => {
            if !angles || !angles_ok {
                return Err(if angles {
                    UsblInputError::BadDirection
                } else {
                    UsblInputError::NoDirection
                });
            }
            let (az, el) = (m.azimuth_rad, m.elevation_rad);
            let z = if m.validity & F::VALID_POSITION != 0
                && m.position_array_m.iter().all(|x| x.is_finite())
            {
                array.c_ned_to_array.transpose() * Vector3::from(m.position_array_m)
            } else {
                fix_position_ned(array, range, az, el)
            };
            // Line-of-sight coordinates (array frame): along it, and the directions in which
            // the azimuth and the elevation move the fix; their noise: range, R cos(el) σ_az,
            // R σ_el.
            let u = Vector3::new(el.cos() * az.cos(), el.cos() * az.sin(), -el.sin());
            let e_az = Vector3::new(-az.sin(), az.cos(), 0.0);
            let e_el = u.cross(&e_az);
            let rows = Matrix3::from_rows(&[u.transpose(), e_az.transpose(), e_el.transpose()]);
            let frame = rows * array.c_ned_to_array;
            let across_az = (range * el.cos() * sa).max(1e-3);
            let across_el = (range * sa).max(1e-3);
            Ok(UsblMeasurement {
                z: frame * z,
                r: Matrix3::from_diagonal(&Vector3::new(
                    sr * sr,
                    across_az * across_az,
                    across_el * across_el,
                )),
                frame,
            })
        }
    }
}

/// Where the responder is, given the navigation state: the responder in the array frame for the
/// nominal state, and how position and attitude errors move it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ResponderGeometry {
    /// Responder in the array frame for the nominal state (m).
    pub nominal_a: Vector3<f64>,
    /// Rotation vehicle NED → array frame.
    pub c_ned_to_array: Matrix3<f64>,
    /// Lever arm in the vehicle's NED frame (m).
    pub lever_ned: Vector3<f64>,
}

impl ResponderGeometry {
    pub fn new(
        array: &UsblArray,
        vehicle: &Geodetic,
        c_body_to_ned: &Matrix3<f64>,
        lever_arm_b: &Vector3<f64>,
    ) -> Self {
        let c_vehicle_ned_to_array_ned =
            c_ecef_to_ned(array.position.latitude_rad, array.position.longitude_rad)
                * c_ecef_to_ned(vehicle.latitude_rad, vehicle.longitude_rad).transpose();
        ResponderGeometry {
            nominal_a: array.responder_in_array(vehicle, c_body_to_ned, lever_arm_b),
            c_ned_to_array: array.c_ned_to_array * c_vehicle_ned_to_array_ned,
            lever_ned: c_body_to_ned * lever_arm_b,
        }
    }

    /// The true responder (array frame) if the navigation state is in error by `dp` (NED, m,
    /// estimate minus truth) and `phi` (attitude error, C_est = (I − [φ×]) C_true).
    pub fn responder_given_error(&self, dp: &Vector3<f64>, phi: &Vector3<f64>) -> Vector3<f64> {
        self.nominal_a + self.c_ned_to_array * (phi.cross(&self.lever_ned) - dp)
    }
}

impl UsblConfig {
    /// The surveyed array, with the hydrophones displaced by the calibrated offsets.
    pub fn array(&self) -> UsblArray {
        let mut a = UsblArray::level(
            Geodetic {
                latitude_rad: self.array_latitude_deg.to_radians(),
                longitude_rad: self.array_longitude_deg.to_radians(),
                height_m: self.array_height_m,
            },
            self.array_yaw_deg.to_radians(),
            self.baseline_m,
        );
        let o = &self.hydrophone_offset_m;
        for (k, h) in a.hydrophones.iter_mut().enumerate() {
            *h += Vector3::new(o[3 * k], o[3 * k + 1], o[3 * k + 2]);
        }
        a
    }
}
