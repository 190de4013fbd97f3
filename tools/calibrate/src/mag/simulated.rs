//! Magnetometer calibration data from the simulator's own magnetometer model (`mag.*` effects)
//! over drawn attitudes: full coverage (any attitude) or AUV-like (roll and pitch within a
//! limit, any heading). Used by the tests and `auvnav bench mag`.

use super::fit::MagSample;
use auvnav_core::earth::Geodetic;
use auvnav_sim::effects::Effects;
use auvnav_sim::rng::Rng;
use auvnav_sim::sensors::MagnetometerModel;
use auvnav_sim::trajectory::{Kinematics, TruthSample};
use nalgebra::{Rotation3, Vector3};

/// Which attitudes the samples cover.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Attitudes {
    /// Uniformly random rotations.
    Full,
    /// Roll and pitch uniform within ±limit (deg), heading uniform.
    Limited { tilt_deg: f64 },
}

/// `n` samples of the simulator's magnetometer with `effects`, at attitudes drawn per `seed`,
/// with the specific force at rest (plus `accel_noise` m/s² white noise) and the true attitude.
pub fn samples(
    effects: &Effects,
    attitudes: Attitudes,
    n: usize,
    accel_noise: f64,
    seed: u64,
) -> Vec<MagSample> {
    let mut model = MagnetometerModel::new(effects, seed);
    let mut rng = Rng::new(seed, "calibrate.mag.attitudes");
    let g = 9.80665;
    (0..n)
        .map(|i| {
            let (roll, pitch, yaw) = match attitudes {
                Attitudes::Full => {
                    // Uniform rotation: a random unit quaternion.
                    let q = nalgebra::UnitQuaternion::from_quaternion(nalgebra::Quaternion::new(
                        rng.gauss(1.0),
                        rng.gauss(1.0),
                        rng.gauss(1.0),
                        rng.gauss(1.0),
                    ));
                    q.euler_angles()
                }
                Attitudes::Limited { tilt_deg } => {
                    let t = tilt_deg.to_radians();
                    (
                        t * (2.0 * rng.uniform() - 1.0),
                        t * (2.0 * rng.uniform() - 1.0),
                        std::f64::consts::PI * (2.0 * rng.uniform() - 1.0),
                    )
                }
            };
            let c = *Rotation3::from_euler_angles(roll, pitch, yaw).matrix();
            let f = c.transpose() * Vector3::new(0.0, 0.0, -g)
                + Vector3::new(
                    rng.gauss(accel_noise),
                    rng.gauss(accel_noise),
                    rng.gauss(accel_noise),
                );
            let t = i as f64 * 0.01;
            let truth = TruthSample {
                time_s: t,
                position: Geodetic {
                    latitude_rad: 0.5,
                    longitude_rad: 2.0,
                    height_m: 0.0,
                },
                kin: Kinematics {
                    speed_m_s: 0.0,
                    speed_rate_m_s2: 0.0,
                    euler_rad: [roll, pitch, yaw],
                    euler_rate_rad_s: [0.0; 3],
                },
                c_body_to_ned: c,
                velocity_ned: Vector3::zeros(),
                omega_ib_body: Vector3::zeros(),
                omega_eb_body: Vector3::zeros(),
                specific_force_body: f,
            };
            let m = model.sample(t, &truth);
            MagSample {
                time_s: t,
                field_ut: Vector3::from(m.field_t) * 1e6,
                specific_force: Some(f),
                angular_rate: None,
                truth_rpy: Some(Vector3::new(roll, pitch, yaw)),
            }
        })
        .collect()
}
