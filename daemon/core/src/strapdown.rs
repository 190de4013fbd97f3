//! Strapdown mechanisation in the local NED frame at the IMU rate.
//!
//! Frames: body b = IMU frame (FRD), navigation n = local NED, Earth e, inertial i.
//! Order per IMU interval [t_{k-1}, t_k] with increments (dtheta, dv) in body axes:
//! 1. coning-corrected rotation vector: `phi = dtheta + (dtheta_prev x dtheta) / 12`;
//! 2. sculling-corrected velocity increment: `dv_b = dv + (dtheta x dv) / 2
//!    + (dtheta_prev x dv + dv_prev x dtheta) / 12` (single-sample, previous-interval form);
//! 3. velocity: `v += C_b^n(t_{k-1}) dv_b - (zeta x C_b^n(t_{k-1}) dv) / 2 + (g^n - (2 omega_ie^n
//!    plus omega_en^n) x v) dt`; the second term accounts for the rotation of the navigation frame
//!    during the interval (zeta below); Coriolis and gravity are taken at the interval start;
//! 4. attitude: `q_b^n(t_k) = exp(-zeta) * q_b^n(t_{k-1}) * exp(phi)`, `zeta = (omega_ie^n +
//!    omega_en^n) dt` (rotation of the navigation frame);
//! 5. position: latitude, longitude, height from the mean of the old and new velocity.

use crate::earth::{self, Geodetic};
use nalgebra::{Matrix3, UnitQuaternion, Vector3};

/// The navigation state the mechanisation carries.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct NavState {
    /// Time of validity (s, host clock domain).
    pub time_s: f64,
    pub position: Geodetic,
    /// Velocity w.r.t. the Earth, NED (m/s).
    pub velocity_ned: Vector3<f64>,
    /// Attitude: rotation body → NED.
    pub q_body_to_ned: UnitQuaternion<f64>,
}

impl NavState {
    pub fn c_body_to_ned(&self) -> Matrix3<f64> {
        *self.q_body_to_ned.to_rotation_matrix().matrix()
    }

    /// Roll, pitch, yaw (rad), the ZYX angles of `q_body_to_ned`: the angles nalgebra's
    /// `euler_angles` gives (away from pitch ±90°), from two arctangents and an arcsine of the
    /// rotation matrix's elements without dividing them by cos(pitch) first (a positive factor
    /// common to both arguments of an arctangent does not change it).
    pub fn euler(&self) -> [f64; 3] {
        let m = self.c_body_to_ned();
        if m[(2, 0)].abs() < 1.0 {
            [
                m[(2, 1)].atan2(m[(2, 2)]),
                -m[(2, 0)].asin(),
                m[(1, 0)].atan2(m[(0, 0)]),
            ]
        } else {
            // Pitch at ±90°: roll and yaw are one angle; nalgebra's convention for it.
            let (r, p, y) = self.q_body_to_ned.euler_angles();
            [r, p, y]
        }
    }
}

/// Below this rotation angle (rad) [`rotation_quaternion`] uses its series: their truncation
/// error there is below 1e-19, far under the rounding of the sine and cosine themselves.
const SERIES_MAX_ANGLE_RAD: f64 = 0.1;

/// The unit quaternion of the rotation vector `v` (rad): `UnitQuaternion::from_scaled_axis`,
/// with cos(θ/2) and sin(θ/2)/θ from their Taylor series to the fifth term for the small angles
/// of one IMU interval (a sine and cosine per call were a tenth of the replay's time).
pub fn rotation_quaternion(v: &Vector3<f64>) -> UnitQuaternion<f64> {
    let theta2 = v.norm_squared();
    if theta2 >= SERIES_MAX_ANGLE_RAD * SERIES_MAX_ANGLE_RAD {
        return UnitQuaternion::from_scaled_axis(*v);
    }
    // h = θ/2: cos h = 1 - h²/2! + h⁴/4! - …, sin h / h = 1 - h²/3! + h⁴/5! - …
    let x = 0.25 * theta2;
    let cos_h = 1.0 - x / 2.0 * (1.0 - x / 12.0 * (1.0 - x / 30.0 * (1.0 - x / 56.0)));
    let sinc_h = 1.0 - x / 6.0 * (1.0 - x / 20.0 * (1.0 - x / 42.0 * (1.0 - x / 72.0)));
    UnitQuaternion::new_unchecked(nalgebra::Quaternion::from_parts(cos_h, v * (0.5 * sinc_h)))
}

/// One IMU interval: angle and velocity increments in body axes over `dt`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ImuIncrement {
    pub dtheta: Vector3<f64>,
    pub dv: Vector3<f64>,
    pub dt: f64,
}

/// The strapdown integrator: the state plus the previous increments for coning and sculling.
#[derive(Debug, Clone)]
pub struct Strapdown {
    pub state: NavState,
    prev: Option<ImuIncrement>,
}

impl Strapdown {
    pub fn new(state: NavState) -> Self {
        Strapdown { state, prev: None }
    }

    /// Integrates one interval ending at `state.time_s + inc.dt`; returns the attitude matrix
    /// body → NED at the interval start.
    pub fn propagate(&mut self, inc: &ImuIncrement) -> Matrix3<f64> {
        let s = &mut self.state;
        let dt = inc.dt;
        let (dth_prev, dv_prev) = match self.prev {
            Some(p) => (p.dtheta, p.dv),
            None => (Vector3::zeros(), Vector3::zeros()),
        };
        let phi = inc.dtheta + dth_prev.cross(&inc.dtheta) / 12.0;
        let dv_b = inc.dv
            + 0.5 * inc.dtheta.cross(&inc.dv)
            + (dth_prev.cross(&inc.dv) + dv_prev.cross(&inc.dtheta)) / 12.0;

        // The Earth model at the interval start (one sine/cosine for the whole step).
        let local = earth::LocalEarth::at(s.position.latitude_rad, s.position.height_m);
        let v_old = s.velocity_ned;
        let w_ie = local.earth_rate();
        let w_en = local.transport_rate(&v_old);
        let g = Vector3::new(0.0, 0.0, local.gravity);
        let c_bn = s.c_body_to_ned();
        let zeta = (w_ie + w_en) * dt;
        let dv_n = c_bn * dv_b - 0.5 * zeta.cross(&(c_bn * inc.dv));
        let v_new = v_old + dv_n + (g - (2.0 * w_ie + w_en).cross(&v_old)) * dt;

        s.q_body_to_ned = rotation_quaternion(&-zeta) * s.q_body_to_ned * rotation_quaternion(&phi);
        s.q_body_to_ned.renormalize_fast();

        let v_mean = 0.5 * (v_old + v_new);
        let rates = local.position_rates(&v_mean);
        s.position.latitude_rad += rates.x * dt;
        s.position.longitude_rad += rates.y * dt;
        s.position.height_m += rates.z * dt;
        s.velocity_ned = v_new;
        s.time_s += dt;
        self.prev = Some(*inc);
        c_bn
    }
}

/// The initial state from a geodetic position, NED velocity and Euler angles.
pub fn initial_state(
    time_s: f64,
    position: Geodetic,
    velocity_ned: [f64; 3],
    euler_rad: [f64; 3],
) -> NavState {
    NavState {
        time_s,
        position,
        velocity_ned: Vector3::from(velocity_ned),
        q_body_to_ned: UnitQuaternion::from_euler_angles(euler_rad[0], euler_rad[1], euler_rad[2]),
    }
}

impl NavState {
    /// The state a truth or reference record describes (simulated truth, or an imported data
    /// set's reference solution): where replay and the studies start from.
    pub fn from_truth(t: &auvnav_shm_schema::TruthStateV1) -> NavState {
        initial_state(
            t.host_time_ns as f64 * 1e-9,
            truth_position(t),
            t.velocity_ned_m_s,
            t.euler_rad,
        )
    }
}

/// The position of a truth / reference record.
pub fn truth_position(t: &auvnav_shm_schema::TruthStateV1) -> Geodetic {
    Geodetic {
        latitude_rad: t.latitude_rad,
        longitude_rad: t.longitude_rad,
        height_m: t.height_m,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::f64::consts::FRAC_PI_2;

    #[test]
    fn static_level_imu_stays_at_rest() {
        let lat = 31f64.to_radians();
        let pos = Geodetic {
            latitude_rad: lat,
            longitude_rad: 2.0,
            height_m: -10.0,
        };
        let q = UnitQuaternion::from_euler_angles(0.0, 0.0, 0.7);
        let c_nb = q.to_rotation_matrix().matrix().transpose();
        let dt = 0.005;
        let w = c_nb * earth::earth_rate_ned(lat);
        let f = -(c_nb * earth::gravity_ned(lat, -10.0));
        let mut sd = Strapdown::new(NavState {
            time_s: 0.0,
            position: pos,
            velocity_ned: Vector3::zeros(),
            q_body_to_ned: q,
        });
        for _ in 0..(600.0 / dt) as usize {
            sd.propagate(&ImuIncrement {
                dtheta: w * dt,
                dv: f * dt,
                dt,
            });
        }
        let s = sd.state;
        assert!(s.velocity_ned.norm() < 1e-6, "{}", s.velocity_ned);
        let d = earth::ned_offset(&pos, &s.position);
        assert!(d.norm() < 1e-4, "{d}");
        assert!(s.q_body_to_ned.angle_to(&q) < 1e-9);
    }

    /// A small deterministic generator for the checks below.
    fn uniform(state: &mut u64) -> f64 {
        *state = state
            .wrapping_mul(6_364_136_223_846_793_005)
            .wrapping_add(1_442_695_040_888_963_407);
        (*state >> 11) as f64 / (1u64 << 53) as f64 * 2.0 - 1.0
    }

    #[test]
    fn rotation_quaternion_is_the_exponential_map() {
        let mut rng = 7u64;
        // Angles from 1e-12 rad to a full turn, across the series threshold.
        for k in 0..4000 {
            let angle = 10f64.powf(-12.0 + 12.8 * (k as f64 / 4000.0)).min(6.2);
            let axis = Vector3::new(uniform(&mut rng), uniform(&mut rng), uniform(&mut rng));
            let v = axis.normalize() * angle;
            let ours = rotation_quaternion(&v);
            let reference = UnitQuaternion::from_scaled_axis(v);
            let d = (ours.coords - reference.coords).amax();
            assert!(
                d < 4e-16,
                "angle {angle}: {ours:?} against {reference:?} ({d:e})"
            );
            assert!((ours.norm() - 1.0).abs() < 4e-16);
        }
        assert_eq!(
            rotation_quaternion(&Vector3::zeros()),
            UnitQuaternion::identity()
        );
    }

    const ORIGIN: Geodetic = Geodetic {
        latitude_rad: 0.5,
        longitude_rad: 0.0,
        height_m: 0.0,
    };

    #[test]
    fn euler_angles_are_nalgebras() {
        let mut rng = 11u64;
        for _ in 0..4000 {
            let e = [
                std::f64::consts::PI * uniform(&mut rng),
                0.5 * std::f64::consts::PI * uniform(&mut rng) * 0.999,
                std::f64::consts::PI * uniform(&mut rng),
            ];
            let s = initial_state(0.0, ORIGIN, [0.0; 3], e);
            let (r, p, y) = s.q_body_to_ned.euler_angles();
            let ours = s.euler();
            for (a, b) in ours.iter().zip([r, p, y]) {
                // Both from the same matrix; the arctangents' arguments differ by a common
                // positive factor only.
                assert!((a - b).abs() < 1e-12, "{ours:?} against {:?}", [r, p, y]);
            }
        }
        // At pitch ±90° the angles are nalgebra's.
        let s = initial_state(0.0, ORIGIN, [0.0; 3], [0.3, FRAC_PI_2, 0.2]);
        let (r, p, y) = s.q_body_to_ned.euler_angles();
        assert_eq!(s.euler(), [r, p, y]);
    }
}
