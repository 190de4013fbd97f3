//! Coarse alignment on simulated voyages: static (moored) and DVL-aided in motion, without any
//! prior heading. Tolerances follow from the simulated sensors (see each test).

use auvnav_core::align::coarse::{InMotionAligner, static_alignment};
use auvnav_log::LogMessage;
use auvnav_shm_schema::{DvlVelocityV1, ImuSampleV1, TruthStateV1};
use auvnav_sim::{self as sim, SimConfig, scenario::Scenario};
use nalgebra::{Matrix3, Rotation3, Vector3};

fn simulate(name: &str, seconds: f64, seed: u64, ideal: bool) -> Vec<LogMessage> {
    let scenario = Scenario::load(name).expect("scenario");
    let effects = if ideal {
        Default::default()
    } else {
        scenario.effects().expect("effects")
    };
    let cfg = SimConfig {
        scenario,
        effects,
        seed,
        duration_s: Some(seconds),
    };
    sim::simulate_to_vec(&cfg).expect("simulate").0
}

/// Roll, pitch, heading errors (deg) of `c` against the truth's attitude.
fn errors_deg(c: &Matrix3<f64>, t: &TruthStateV1) -> [f64; 3] {
    let q = t.quaternion_body_to_ned;
    let truth = nalgebra::UnitQuaternion::from_quaternion(nalgebra::Quaternion::new(
        q[0], q[1], q[2], q[3],
    ))
    .to_rotation_matrix();
    let (r, p, y) = Rotation3::from_matrix_unchecked(*c).euler_angles();
    let (tr, tp, ty) = truth.euler_angles();
    let wrap = |a: f64| {
        (a + std::f64::consts::PI).rem_euclid(std::f64::consts::TAU) - std::f64::consts::PI
    };
    [wrap(r - tr), wrap(p - tp), wrap(y - ty)].map(f64::to_degrees)
}

fn rates(m: &ImuSampleV1) -> (Vector3<f64>, Vector3<f64>) {
    (Vector3::from(m.angular), Vector3::from(m.specific))
}

/// Runs the in-motion aligner over the messages; returns the attitude errors at the end.
fn in_motion(messages: &[LogMessage], use_dvl: bool) -> [f64; 3] {
    let first_truth = messages
        .iter()
        .find_map(|m| match m {
            LogMessage::Truth(t) => Some(*t),
            _ => None,
        })
        .expect("truth");
    let mut a = InMotionAligner::new(first_truth.latitude_rad, first_truth.height_m);
    let mut last_truth = first_truth;
    let mut last_dvl: Option<DvlVelocityV1> = None;
    let mut t_imu = 0;
    // Stop at the last truth record, so that the attitude is compared at the same time (in a
    // turn the heading moves 0.15° between two truth records).
    let end = messages
        .iter()
        .rposition(|m| matches!(m, LogMessage::Truth(_)))
        .expect("truth");
    for m in &messages[..=end] {
        match m {
            LogMessage::Imu(x) => {
                let (w, f) = rates(x);
                a.on_imu(x.host_time_ns as f64 * 1e-9, &w, &f, x.interval_s);
                t_imu = x.host_time_ns;
                if !use_dvl {
                    a.on_velocity(None);
                } else if let Some(d) = last_dvl.take() {
                    a.on_velocity(Some(Vector3::from(d.velocity_dvl_m_s)));
                }
            }
            LogMessage::Dvl(d) if d.validity & DvlVelocityV1::VALID_VELOCITY != 0 => {
                last_dvl = Some(*d);
            }
            LogMessage::Truth(t) => last_truth = *t,
            _ => {}
        }
    }
    assert_eq!(t_imu, last_truth.host_time_ns, "compared at the same time");
    let c = a.solve().expect("alignment");
    errors_deg(&c, &last_truth)
}

#[test]
fn static_alignment_when_moored() {
    let messages = simulate("moored", 600.0, 3, false);
    let (mut w, mut f, mut n) = (Vector3::zeros(), Vector3::zeros(), 0.0);
    let mut truth = None;
    for m in &messages {
        match m {
            LogMessage::Imu(x) => {
                let (wi, fi) = rates(x);
                w += wi;
                f += fi;
                n += 1.0;
            }
            LogMessage::Truth(t) => truth = Some(*t),
            _ => {}
        }
    }
    let t = truth.expect("truth");
    let c = static_alignment(&(f / n), &(w / n), t.latitude_rad, t.height_m).expect("aligned");
    let e = errors_deg(&c, &t);
    eprintln!(
        "static: roll {:.4} pitch {:.4} heading {:.4} deg",
        e[0], e[1], e[2]
    );
    // Gyro bias ≤ 0.012 °/h and 0.002 °/√h ARW over 600 s give ≈ 0.02° of heading (east
    // rate error / horizontal Earth rate 12.9 °/h); accelerometer bias ≤ 25 µg gives 0.0015° tilt.
    assert!(e[2].abs() < 0.1, "{e:?}");
    assert!(e[0].abs() < 0.01 && e[1].abs() < 0.01, "{e:?}");
}

const CASES: [(&str, bool); 3] = [("moored", false), ("straight", true), ("turns", true)];

#[test]
fn in_motion_alignment_with_ideal_sensors_is_exact() {
    // Only the algorithm's own approximations remain (integration steps, 1 s epochs).
    for (scenario, dvl) in CASES {
        let e = in_motion(&simulate(scenario, 300.0, 1, true), dvl);
        eprintln!(
            "ideal {scenario}: roll {:.4} pitch {:.4} heading {:.4} deg",
            e[0], e[1], e[2]
        );
        assert!(e.iter().all(|x| x.abs() < 0.01), "{scenario}: {e:?}");
    }
}

#[test]
fn in_motion_alignment_without_a_prior_heading() {
    // Navigation-grade sensors (the scenarios' effects). Heading rests on gravity turning with the
    // Earth in the inertial frame: after τ = 300 s the signal is g·Ω·cos L·τ²/2; an accelerometer
    // bias ∇ that the body's motion carries out of the vertical competes with ∇·τ, i.e. a heading
    // error up to 2∇/(g·Ω·cos L·τ) ≈ 0.15° for 25 µg. Bound: 0.5°; tilt: 0.02°.
    for seed in 1..=3 {
        for (scenario, dvl) in CASES {
            let e = in_motion(&simulate(scenario, 300.0, seed, false), dvl);
            eprintln!(
                "seed {seed} {scenario}: roll {:.4} pitch {:.4} heading {:.4} deg",
                e[0], e[1], e[2]
            );
            assert!(
                e[2].abs() < 0.5 && e[0].abs() < 0.02 && e[1].abs() < 0.02,
                "seed {seed} {scenario}: {e:?}"
            );
        }
    }
}

/// The session aligns itself: coarse (in motion, DVL-aided) then fine (the navigation filter),
/// with the mode showing aligning until the heading meets the criterion, then navigating.
#[test]
fn session_aligns_in_motion_and_hands_over_to_navigation() {
    use auvnav_core::session::AlignmentConfig;
    use auvnav_shm_schema::NavMode;
    use auvnav_tools::replay::{Output, Replay, ReplayConfig};
    let messages = simulate("turns", 600.0, 4, false);
    // Fine stage by the model-1 alignment filter (the default), and by the navigation filter.
    for fine_model in [1u8, 0] {
        let cfg = ReplayConfig {
            alignment: Some(AlignmentConfig {
                latitude_deg: 31.0,
                longitude_deg: 120.0,
                height_m: -20.0,
                coarse_s: 120.0,
                moored: false,
                coarse_heading_std_deg: 2.0,
                coarse_tilt_std_deg: 0.05,
                aligned_heading_std_deg: 0.1,
                fine_model,
                heading_source: Default::default(),
            }),
            ..Default::default()
        };
        let mut replay = Replay::new(&cfg, 100.0);
        let mut modes: Vec<(u64, u32)> = Vec::new();
        let mut last = None;
        let mut last_truth = None;
        for m in &messages {
            replay
                .process(m, &mut |o| {
                    if let Output::Solution(s) = o {
                        if modes.last().is_none_or(|(_, md)| *md != s.mode) {
                            modes.push((s.host_time_ns, s.mode));
                        }
                        last = Some(*s);
                    }
                    Ok(())
                })
                .expect("replay");
            if let LogMessage::Truth(t) = m {
                last_truth = Some(*t);
            }
        }
        let aligning = NavMode::Aligning as u32;
        let navigating = NavMode::Navigating as u32;
        // Aligning until the criterion is met, then navigating: one switch.
        assert_eq!(
            modes.iter().map(|m| m.1).collect::<Vec<_>>(),
            vec![aligning, navigating],
            "fine model {fine_model}: {modes:?}"
        );
        let initial = replay.initial().expect("started");
        assert!(initial.source.contains("alignment"), "{initial:?}");
        let (s, t) = (last.expect("solution"), last_truth.expect("truth"));
        let c = nalgebra::UnitQuaternion::from_quaternion(nalgebra::Quaternion::new(
            s.quaternion_body_to_ned[0],
            s.quaternion_body_to_ned[1],
            s.quaternion_body_to_ned[2],
            s.quaternion_body_to_ned[3],
        ))
        .to_rotation_matrix()
        .into_inner();
        let e = errors_deg(&c, &t);
        let acc = replay.accuracy().expect("truth");
        eprintln!(
            "fine model {fine_model}: navigating from {:.0} s; final errors roll {:.4} pitch {:.4} heading {:.4} deg, position {:.2} m",
            modes[1].0 as f64 * 1e-9,
            e[0],
            e[1],
            e[2],
            acc.horizontal_error_final_m
        );
        // The mode says navigating when the heading σ < 0.1°: the error agrees (3σ).
        assert!(
            e[2].abs() < 0.3 && e[0].abs() < 0.02 && e[1].abs() < 0.02,
            "{e:?}"
        );
        // Dead reckoning through the alignment, then the filter: no jump left at the end.
        assert!(acc.horizontal_error_final_m < 3.0, "{acc:?}");
    }
}
