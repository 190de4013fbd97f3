//! GNSS position and zero-velocity updates through the navigator, on simulated voyages.

use auvnav_core::earth;
use auvnav_core::navigator::{NavConfig, Navigator, initial_state};
use auvnav_core::strapdown::truth_position;
use auvnav_log::LogMessage;
use auvnav_sim::{self as sim, SimConfig, scenario::Scenario};
use nalgebra::Vector3;

fn simulate(scenario: Scenario) -> Vec<LogMessage> {
    let effects = scenario.effects().expect("effects");
    let cfg = SimConfig {
        scenario,
        effects,
        seed: 11,
        duration_s: None,
    };
    sim::simulate_to_vec(&cfg).expect("simulate").0
}

/// Runs IMU plus the aids `use_aid` accepts, starting `offset` metres (NED) off the truth;
/// returns the final horizontal error, the final speed error and the navigator.
fn run(
    msgs: &[LogMessage],
    offset: Vector3<f64>,
    zero_velocity_hz: Option<f64>,
    use_gnss: bool,
) -> (f64, f64, Navigator) {
    let mut nav: Option<Navigator> = None;
    let mut last_truth = None;
    let mut next_zupt = 0.0;
    for m in msgs {
        match m {
            LogMessage::Truth(t) => {
                if nav.is_none() {
                    let p = earth::offset_position(&truth_position(t), &offset);
                    let s = initial_state(
                        t.host_time_ns as f64 * 1e-9,
                        p,
                        t.velocity_ned_m_s,
                        t.euler_rad,
                    );
                    nav = Some(Navigator::new(NavConfig::default(), s));
                }
                last_truth = Some(*t);
            }
            LogMessage::Imu(x) => {
                let n = nav.as_mut().expect("started");
                n.on_imu(x);
                let t = x.host_time_ns as f64 * 1e-9;
                if let Some(hz) = zero_velocity_hz
                    && t >= next_zupt
                {
                    n.on_zero_velocity(x.host_time_ns);
                    next_zupt = t + 1.0 / hz;
                }
            }
            LogMessage::Gnss(x) if use_gnss => {
                nav.as_mut().expect("started").on_gnss(x);
            }
            _ => {}
        }
    }
    let n = nav.expect("started");
    let t = last_truth.expect("truth");
    let e = earth::ned_offset(&truth_position(&t), &n.state().position);
    let dv = n.state().velocity_ned - Vector3::from(t.velocity_ned_m_s);
    (e.xy().norm(), dv.norm(), n)
}

#[test]
fn zero_velocity_updates_hold_a_moored_vehicle() {
    let msgs = simulate(Scenario::load("moored").expect("scenario"));
    let (free, free_v, _) = run(&msgs, Vector3::zeros(), None, false);
    let (held, held_v, n) = run(&msgs, Vector3::zeros(), Some(1.0), false);
    eprintln!(
        "pure inertial: {free:.2} m, {free_v:.3} m/s; with ZUPT: {held:.3} m, {held_v:.4} m/s"
    );
    assert_eq!(n.counters().zero_velocity_fused, 600, "{:?}", n.counters());
    assert!(held_v < 0.01, "{held_v}");
    assert!(held < 0.5 && held < free / 5.0, "{held} vs {free}");
}

#[test]
fn gnss_fixes_pull_a_wrong_start_onto_the_track() {
    let text = r#"
name = "surface"
description = "straight at the surface, 2 m/s, 600 s"
seabed_depth_m = 50.0
[start]
latitude_deg = 43.0
longitude_deg = 5.0
depth_m = 0.0
heading_deg = 100.0
speed_m_s = 2.0
[[legs]]
kind = "straight"
duration_s = 600.0
[effects]
"imu.gyro_bias" = [0.01, -0.008, 0.012]
"imu.angle_random_walk" = 0.002
"imu.accel_bias" = [20.0, -15.0, 25.0]
"imu.velocity_random_walk" = 0.0005
"gnss.noise" = 2.0
"#;
    let path = std::env::temp_dir().join(format!("auvnav-surface-{}.toml", std::process::id()));
    std::fs::write(&path, text).expect("scenario file");
    let scenario = Scenario::load(&path.to_string_lossy()).expect("scenario");
    let _ = std::fs::remove_file(&path);
    let msgs = simulate(scenario);
    let offset = Vector3::new(15.0, -10.0, 0.0);
    let (without, _, _) = run(&msgs, offset, None, false);
    let (with, _, n) = run(&msgs, offset, None, true);
    eprintln!(
        "start 18 m off: without GNSS {without:.1} m, with GNSS {with:.2} m; {:?}",
        n.counters()
    );
    assert!(n.counters().gnss_fused > 500, "{:?}", n.counters());
    assert!(without > 15.0, "{without}");
    assert!(with < 3.0, "{with}");
}
