//! The magnetic heading aid on simulated runs with a MEMS-grade IMU whose gyros cannot find
//! north: with a calibrated magnetometer the coarse alignment takes its heading from the field
//! (within 2° of the truth) and the filter's heading error stays within its 3σ; a magnetometer
//! with its hard iron left in is rejected (gate or magnitude check, counted) instead of pulling
//! the heading.

use auvnav_core::aid::magnetometer::MagnetometerConfig;
use auvnav_core::config::{AlignmentConfig, HeadingSource, InitialState};
use auvnav_log::LogMessage;
use auvnav_shm_schema::{NavSolutionV1, TruthStateV1};
use auvnav_sim::{self as sim, SimConfig, scenario::Scenario};
use auvnav_tools::replay::{Output, Replay, ReplayConfig};

const HARD_IRON: [f64; 3] = [10.0, -10.0, 5.0];
const SOFT_IRON: [f64; 9] = [1.04, 0.03, -0.02, 0.03, 0.97, 0.01, -0.02, 0.01, 1.02];

fn simulate(seed: u64) -> Vec<LogMessage> {
    let scenario = Scenario::load("turns").expect("scenario");
    let mut effects = scenario.effects().expect("effects");
    // A MEMS-grade IMU: tens of deg/h of gyro bias hide the Earth's rotation (15 deg/h).
    effects.imu_gyro_bias = [20.0, -15.0, 10.0];
    effects.imu_angle_random_walk = 0.05;
    effects.imu_gyro_bias_instability = 0.0;
    effects.imu_accel_bias = [200.0, -150.0, 250.0];
    effects.imu_velocity_random_walk = 0.01;
    effects.mag_hard_iron = HARD_IRON;
    effects.mag_soft_iron = SOFT_IRON;
    effects.mag_noise = 0.2;
    effects.mag_declination = 4.2;
    effects.mag_inclination = 48.0;
    effects.mag_intensity = 50.0;
    let cfg = SimConfig {
        scenario,
        effects,
        seed,
        duration_s: Some(600.0),
    };
    sim::simulate_to_vec(&cfg).expect("simulate").0
}

fn session(calibrated: bool, initial: Option<InitialState>) -> ReplayConfig {
    let mut cfg = ReplayConfig::default();
    let n = &mut cfg.navigation;
    n.gyro_angle_random_walk_deg_sqrt_h = 0.06;
    n.accel_velocity_random_walk_m_s_sqrt_h = 0.012;
    n.gyro_bias_walk_deg_h_sqrt_h = 0.5;
    n.initial_gyro_bias_std_deg_h = 40.0;
    n.initial_accel_bias_std_ug = 500.0;
    n.magnetometer = Some(MagnetometerConfig {
        hard_iron_ut: if calibrated { HARD_IRON } else { [0.0; 3] },
        soft_iron: if calibrated {
            SOFT_IRON
        } else {
            MagnetometerConfig::default().soft_iron
        },
        heading_std_deg: 1.0,
        declination_deg: Some(4.2),
        intensity_ut: Some(50.0),
        ..Default::default()
    });
    match initial {
        Some(i) => cfg.initial = Some(i),
        None => {
            cfg.alignment = Some(AlignmentConfig {
                latitude_deg: 31.0,
                longitude_deg: 120.0,
                height_m: -20.0,
                coarse_s: 60.0,
                moored: false,
                coarse_heading_std_deg: 3.0,
                coarse_tilt_std_deg: 0.3,
                aligned_heading_std_deg: 1.0,
                fine_model: 0,
                heading_source: HeadingSource::Magnetometer,
            })
        }
    }
    cfg.validate().expect("valid configuration");
    cfg
}

/// Heading errors (deg) and 3σ (deg) of every solution at a truth record after the start.
fn run(
    messages: &[LogMessage],
    cfg: &ReplayConfig,
) -> (Replay, Vec<(f64, f64, f64)>, Option<NavSolutionV1>) {
    let mut replay = Replay::new(cfg, 100.0);
    let mut last: Option<NavSolutionV1> = None;
    let mut first: Option<NavSolutionV1> = None;
    let mut out = Vec::new();
    for m in messages {
        replay
            .process(m, &mut |o| {
                if let Output::Solution(s) = o {
                    last = Some(*s);
                }
                Ok(())
            })
            .expect("replay");
        if first.is_none() && replay.initial().is_some() {
            first = last;
        }
        if let (LogMessage::Truth(t), Some(s)) = (m, last)
            && s.host_time_ns == t.host_time_ns
            && replay.initial().is_some()
        {
            out.push(heading_error(&s, t));
        }
    }
    (replay, out, first)
}

fn heading_error(s: &NavSolutionV1, t: &TruthStateV1) -> (f64, f64, f64) {
    let e = auvnav_tools::accuracy::wrap(s.euler_rad[2] - t.euler_rad[2]).to_degrees();
    (
        s.host_time_ns as f64 * 1e-9,
        e,
        3.0 * s.attitude_std_rad[2].to_degrees(),
    )
}

#[test]
fn a_calibrated_magnetometer_aligns_and_holds_the_heading() {
    for seed in [21, 22] {
        let messages = simulate(seed);
        let (replay, errors, _) = run(&messages, &session(true, None));
        let initial = replay.initial().expect("aligned");
        let truth_at_start = messages
            .iter()
            .rev()
            .find_map(|m| match m {
                LogMessage::Truth(t) if (t.host_time_ns as f64 * 1e-9) <= initial.time_s => {
                    Some(*t)
                }
                _ => None,
            })
            .expect("truth");
        let start_error = auvnav_tools::accuracy::wrap(
            initial.euler_deg[2].to_radians() - truth_at_start.euler_rad[2],
        )
        .to_degrees();
        let counters = replay.navigator().expect("navigator").counters();
        let worst = errors
            .iter()
            .map(|(_, e, s3)| e.abs() / s3)
            .fold(0.0f64, f64::max);
        let rms = (errors.iter().map(|(_, e, _)| e * e).sum::<f64>() / errors.len() as f64).sqrt();
        eprintln!(
            "seed {seed}: coarse heading error {start_error:.3} deg at {:.0} s; heading error RMS \
             {rms:.3} deg, worst |error|/3σ {worst:.2}; magnetometer fused {}, rejected {}, \
             disturbed {}",
            initial.time_s,
            counters.magnetometer_fused,
            counters.magnetometer_rejected,
            counters.magnetometer_disturbed
        );
        assert!(
            start_error.abs() < 2.0,
            "coarse heading error {start_error}"
        );
        assert!(worst <= 1.0, "heading error beyond 3σ: worst ratio {worst}");
        assert!(counters.magnetometer_fused > 1000, "{counters:?}");
    }
}

#[test]
fn a_magnetometer_with_its_hard_iron_left_in_is_rejected() {
    let messages = simulate(23);
    let t0 = messages
        .iter()
        .find_map(|m| match m {
            LogMessage::Truth(t) => Some(*t),
            _ => None,
        })
        .expect("truth");
    let initial = InitialState {
        latitude_deg: t0.latitude_rad.to_degrees(),
        longitude_deg: t0.longitude_rad.to_degrees(),
        height_m: t0.height_m,
        velocity_ned_m_s: t0.velocity_ned_m_s,
        euler_deg: t0.euler_rad.map(f64::to_degrees),
    };
    let mut cfg = session(false, Some(initial.clone()));
    cfg.navigation.initial_heading_std_deg = 0.5;
    let (replay, errors, _) = run(&messages, &cfg);
    let c = replay.navigator().expect("navigator").counters();
    let readings = c.magnetometer_fused + c.magnetometer_rejected + c.magnetometer_disturbed;
    let worst = errors
        .iter()
        .map(|(_, e, s3)| e.abs() / s3)
        .fold(0.0f64, f64::max);
    let max_error = errors
        .iter()
        .map(|(_, e, _)| e.abs())
        .fold(0.0f64, f64::max);
    eprintln!(
        "uncalibrated: fused {}, rejected {}, disturbed {} of {readings}; largest heading error \
         {max_error:.3} deg, worst |error|/3σ {worst:.2}",
        c.magnetometer_fused, c.magnetometer_rejected, c.magnetometer_disturbed
    );
    assert!(
        (c.magnetometer_rejected + c.magnetometer_disturbed) as f64 >= 0.9 * readings as f64,
        "{c:?}"
    );
    assert!(worst <= 1.0, "the heading was pulled: worst ratio {worst}");
    // The same run without the magnetometer: the heading error is the IMU's alone.
    let mut plain = cfg.clone();
    plain.navigation.magnetometer = None;
    let (_, plain_errors, _) = run(&messages, &plain);
    let plain_max = plain_errors
        .iter()
        .map(|(_, e, _)| e.abs())
        .fold(0.0f64, f64::max);
    eprintln!("without the magnetometer: largest heading error {plain_max:.3} deg");
    assert!(max_error < plain_max + 1.0, "{max_error} vs {plain_max}");
}
