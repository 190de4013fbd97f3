//! What the Monte Carlo studies (`auvnav montecarlo nees`, `auvnav usbl`, `auvnav montecarlo
//! ranges`) share besides the parallel runner (`crate::parallel`): how a run's navigation starts
//! and the run's own sensor errors. The runs themselves feed the navigation session
//! (`auvnav_core::feed`), as the daemon does.

use auvnav_core::earth;
use auvnav_core::navigator::{NavConfig, initial_state};
use auvnav_core::strapdown::NavState;
use auvnav_core::strapdown::truth_position;
use auvnav_sim::rng::Rng;
use nalgebra::{UnitQuaternion, Vector3};

const DEG: f64 = std::f64::consts::PI / 180.0;

/// The truth perturbed by a draw from the initial covariance of `cfg`: where a run starts.
pub fn perturbed_start(
    cfg: &NavConfig,
    t: &auvnav_shm_schema::TruthStateV1,
    rng: &mut Rng,
) -> NavState {
    let dp = Vector3::new(
        rng.gauss(cfg.initial_position_std_m),
        rng.gauss(cfg.initial_position_std_m),
        rng.gauss(cfg.initial_position_std_m),
    );
    let dv = Vector3::new(
        rng.gauss(cfg.initial_velocity_std_m_s),
        rng.gauss(cfg.initial_velocity_std_m_s),
        rng.gauss(cfg.initial_velocity_std_m_s),
    );
    let tilt = cfg.initial_tilt_std_deg * DEG;
    let phi = Vector3::new(
        rng.gauss(tilt),
        rng.gauss(tilt),
        rng.gauss(cfg.initial_heading_std_deg * DEG),
    );
    let truth_pos = truth_position(t);
    let mut s = initial_state(
        t.host_time_ns as f64 * 1e-9,
        earth::offset_position(&truth_pos, &dp),
        (Vector3::from(t.velocity_ned_m_s) + dv).into(),
        t.euler_rad,
    );
    s.q_body_to_ned = UnitQuaternion::from_scaled_axis(-phi) * s.q_body_to_ned;
    s
}

/// A run's own sensor errors, drawn from `cfg`'s initial uncertainty into `effects`: a gyro and an
/// accelerometer bias per axis and a DVL scale-factor error (0.5 %), in that order from `rng`.
pub fn draw_sensor_errors(
    effects: &mut auvnav_sim::effects::Effects,
    cfg: &NavConfig,
    rng: &mut Rng,
) -> Result<(), auvnav_sim::effects::EffectError> {
    let mut draw3 = |s: f64| [rng.gauss(s), rng.gauss(s), rng.gauss(s)];
    let gyro = draw3(cfg.initial_gyro_bias_std_deg_h);
    let accel = draw3(cfg.initial_accel_bias_std_ug);
    effects.set("imu.gyro_bias", &gyro)?;
    effects.set("imu.accel_bias", &accel)?;
    effects.set("dvl.scale_factor", &[1.0 + rng.gauss(0.005)])
}
