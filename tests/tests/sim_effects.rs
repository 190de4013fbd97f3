//! The simulator's effects checked against analytic expectations.

use auvnav_core::earth;
use auvnav_core::strapdown::truth_position;
use auvnav_log::LogMessage;
use auvnav_shm_schema::{DvlVelocityV1, ImuSampleV1, TruthStateV1, UsblFixV1};
use auvnav_sim::effects::Effects;
use auvnav_sim::scenario::Scenario;
use auvnav_sim::{SimConfig, StationGeometry, simulate_to_vec};
use nalgebra::{UnitQuaternion, Vector3};

fn run(scenario: &str, settings: &[(&str, &[f64])], duration: Option<f64>) -> Vec<LogMessage> {
    let scenario = Scenario::load(scenario).expect("scenario");
    let mut effects = Effects::default();
    for (name, v) in settings {
        effects.set(name, v).expect("effect");
    }
    let cfg = SimConfig {
        scenario,
        effects,
        seed: 42,
        duration_s: duration,
    };
    simulate_to_vec(&cfg).expect("simulate").0
}

fn c_body_to_ned(t: &TruthStateV1) -> nalgebra::Matrix3<f64> {
    let [w, x, y, z] = t.quaternion_body_to_ned;
    *UnitQuaternion::from_quaternion(nalgebra::Quaternion::new(w, x, y, z))
        .to_rotation_matrix()
        .matrix()
}

#[test]
fn static_imu_measures_gravity_and_earth_rate_within_the_configured_noise() {
    let arw_deg_sqrt_h = 0.01;
    let vrw_m_s_sqrt_h = 0.002;
    let duration = 300.0;
    let msgs = run(
        "moored",
        &[
            ("imu.angle_random_walk", &[arw_deg_sqrt_h]),
            ("imu.velocity_random_walk", &[vrw_m_s_sqrt_h]),
        ],
        Some(duration),
    );
    let s = Scenario::load("moored").expect("scenario");
    let lat = s.start.latitude_deg.to_radians();
    let c_nb = UnitQuaternion::from_euler_angles(0.0, 0.0, s.start.heading_deg.to_radians())
        .to_rotation_matrix()
        .matrix()
        .transpose();
    let w_expected = c_nb * earth::earth_rate_ned(lat);
    let f_expected = -(c_nb * earth::gravity_ned(lat, -s.start.depth_m));
    let imu: Vec<ImuSampleV1> = msgs
        .iter()
        .filter_map(|m| match m {
            LogMessage::Imu(x) => Some(*x),
            _ => None,
        })
        .collect();
    let n = imu.len() as f64;
    let dt = imu[0].interval_s;
    let mean =
        |f: &dyn Fn(&ImuSampleV1) -> Vector3<f64>| imu.iter().map(f).sum::<Vector3<f64>>() / n;
    let w_mean = mean(&|x| Vector3::from(x.angular));
    let f_mean = mean(&|x| Vector3::from(x.specific));
    // Standard deviation of a mean over T seconds of white noise with density N: N / sqrt(T).
    let sigma_w = arw_deg_sqrt_h.to_radians() / 60.0 / duration.sqrt();
    let sigma_f = vrw_m_s_sqrt_h / 60.0 / duration.sqrt();
    for i in 0..3 {
        assert!(
            (w_mean[i] - w_expected[i]).abs() < 4.0 * sigma_w,
            "gyro axis {i}: {} vs {}",
            w_mean[i],
            w_expected[i]
        );
        assert!(
            (f_mean[i] - f_expected[i]).abs() < 4.0 * sigma_f,
            "accel axis {i}: {} vs {}",
            f_mean[i],
            f_expected[i]
        );
    }
    // The per-sample spread is the configured density over sqrt(dt).
    let var_w = imu
        .iter()
        .map(|x| (x.angular[0] - w_mean[0]).powi(2))
        .sum::<f64>()
        / n;
    let expected_sd = arw_deg_sqrt_h.to_radians() / 60.0 / dt.sqrt();
    assert!(
        (var_w.sqrt() / expected_sd - 1.0).abs() < 0.02,
        "{} vs {}",
        var_w.sqrt(),
        expected_sd
    );
    // The Earth rate is resolved: its magnitude is 15.04 deg/h.
    assert!((w_mean.norm() / earth::OMEGA_IE - 1.0).abs() < 0.01);
}

/// Dead reckoning with the true attitude and the DVL velocity taken as body velocity.
fn dead_reckon(msgs: &[LogMessage]) -> (Vector3<f64>, f64, Vector3<f64>) {
    let mut attitude = None;
    let mut last_t = None;
    let mut p = Vector3::zeros();
    let mut path = 0.0;
    let mut first_truth: Option<TruthStateV1> = None;
    let mut last_truth: Option<TruthStateV1> = None;
    for m in msgs {
        match m {
            LogMessage::Truth(t) => {
                attitude = Some((t.host_time_ns, c_body_to_ned(t)));
                first_truth.get_or_insert(*t);
                last_truth = Some(*t);
            }
            LogMessage::Dvl(d) if d.validity & DvlVelocityV1::VALID_VELOCITY != 0 => {
                // The DVL ping and the truth record share the time stamp (5 Hz divides 20 Hz);
                // the truth record is written after the ping, so look for the previous one.
                if let (Some((_, c)), Some(t0)) = (attitude, last_t) {
                    let dt = (d.host_time_ns - t0) as f64 * 1e-9;
                    let step = c * Vector3::from(d.velocity_dvl_m_s) * dt;
                    p += step;
                    path += step.norm();
                }
                last_t = Some(d.host_time_ns);
            }
            _ => {}
        }
    }
    let (a, b) = (first_truth.expect("truth"), last_truth.expect("truth"));
    (
        p,
        path,
        earth::ned_offset(&truth_position(&a), &truth_position(&b)),
    )
}

#[test]
fn dvl_scale_factor_lengthens_the_dead_reckoned_distance() {
    let (_, base, _) = dead_reckon(&run("turns", &[], None));
    let (_, scaled, _) = dead_reckon(&run("turns", &[("dvl.scale_factor", &[1.005])], None));
    let ratio = scaled / base;
    assert!((ratio - 1.005).abs() < 1e-6, "ratio {ratio}");
    assert!(base > 800.0, "{base}");
}

#[test]
fn dvl_mount_yaw_turns_the_dead_reckoned_track() {
    let (dr, _, truth) = dead_reckon(&run("straight", &[("dvl.mount_yaw", &[1.0])], None));
    let turn = (dr.y.atan2(dr.x) - truth.y.atan2(truth.x)).to_degrees();
    // The DVL frame is yawed +1 deg from the body, so body velocity appears rotated by -1 deg.
    assert!((turn + 1.0).abs() < 0.01, "track turned by {turn} deg");
    let (dr0, _, truth0) = dead_reckon(&run("straight", &[], None));
    let turn0 = (dr0.y.atan2(dr0.x) - truth0.y.atan2(truth0.x)).to_degrees();
    assert!(turn0.abs() < 0.01, "without the effect: {turn0} deg");
}

#[test]
fn usbl_range_differences_match_the_array_geometry() {
    let scenario = Scenario::load("docking").expect("scenario");
    let station = StationGeometry::from_scenario(&scenario).expect("station");
    let b = station.baseline_m;
    let check = |yaw_error_deg: f64| {
        let msgs = run("docking", &[("usbl.array_yaw", &[yaw_error_deg])], None);
        let mut fixes = 0;
        let mut pending: Option<UsblFixV1> = None;
        for m in &msgs {
            match m {
                LogMessage::Usbl(f) => pending = Some(*f),
                LogMessage::Truth(t) => {
                    let Some(f) = pending.take() else { continue };
                    assert_eq!(f.host_time_ns, t.host_time_ns);
                    let pos = truth_position(t);
                    let r_ned = earth::ned_offset(&station.position, &pos)
                        + c_body_to_ned(t) * Vector3::from(station.responder_lever_arm_m);
                    // The true array is yawed by the error; express the direction in its frame.
                    let yaw = station.yaw_rad + yaw_error_deg.to_radians();
                    let (s, c) = yaw.sin_cos();
                    let r_a = Vector3::new(
                        c * r_ned.x + s * r_ned.y,
                        -s * r_ned.x + c * r_ned.y,
                        r_ned.z,
                    );
                    let range = r_a.norm();
                    let u = r_a / range;
                    // Far field: R1 - R3 = -(h1 - h3) . u = -b u_x, error below b^2 / range.
                    let tol = b * b / range + 1e-9;
                    assert!(
                        (f.slant_range_m - range).abs() < 1e-6,
                        "{} vs {range}",
                        f.slant_range_m
                    );
                    assert!(
                        (f.range_difference_m[0] + b * u.x).abs() < tol,
                        "{:?} vs {}",
                        f.range_difference_m,
                        -b * u.x
                    );
                    assert!(
                        (f.range_difference_m[1] + b * u.y).abs() < tol,
                        "{:?} vs {}",
                        f.range_difference_m,
                        -b * u.y
                    );
                    fixes += 1;
                }
                _ => {}
            }
        }
        assert!(fixes > 500, "{fixes} fixes");
    };
    check(0.0);
    check(1.0);
}

/// A moving bed under bottom track: dead reckoning on the bottom-track velocity drifts against
/// the bed's motion (the DVL measures the vehicle relative to the bed), whatever the turns, by
/// the bed's velocity times the time; water track does not see it.
#[test]
fn dvl_bed_velocity_drifts_bottom_track_dead_reckoning_against_the_bed() {
    let bed = [0.02, -0.03];
    let base = run("turns", &[], None);
    let moved = run("turns", &[("dvl.bed_velocity", &bed)], None);
    let (dr0, _, _) = dead_reckon(&base);
    let (dr1, _, _) = dead_reckon(&moved);
    let seconds = moved
        .iter()
        .filter_map(|m| match m {
            LogMessage::Dvl(d) => Some(d.host_time_ns as f64 * 1e-9),
            _ => None,
        })
        .fold((f64::INFINITY, 0.0f64), |(a, b), t| (a.min(t), b.max(t)));
    let span = seconds.1 - seconds.0;
    let drift = dr1 - dr0;
    for (axis, want) in [(0, -bed[0] * span), (1, -bed[1] * span)] {
        assert!(
            (drift[axis] - want).abs() < 0.01 * want.abs() + 0.05,
            "axis {axis}: drift {:.3} m, expected {want:.3} m over {span:.0} s",
            drift[axis]
        );
    }
    assert!(drift.z.abs() < 0.05, "vertical drift {:.3} m", drift.z);
    // Water track (the vehicle against the water) is not affected.
    let water = |msgs: &[LogMessage]| -> Vec<[f64; 3]> {
        msgs.iter()
            .filter_map(|m| match m {
                LogMessage::Dvl(d) if d.is_water_track() => Some(d.velocity_dvl_m_s),
                _ => None,
            })
            .collect()
    };
    let settings: &[(&str, &[f64])] = &[("dvl.water_track_noise", &[0.01])];
    let with_bed: Vec<(&str, &[f64])> = settings
        .iter()
        .copied()
        .chain([("dvl.bed_velocity", &bed[..])])
        .collect();
    let (a, b) = (
        water(&run("turns", settings, Some(60.0))),
        water(&run("turns", &with_bed, Some(60.0))),
    );
    assert!(!a.is_empty());
    assert_eq!(a, b);
}

/// `usbl.fix_time_constant`: the device's reported fix is its per-ping fix smoothed
/// exponentially (the same seed gives the same per-ping fixes), the ranges untouched.
#[test]
fn usbl_fix_time_constant_smooths_the_devices_fixes_and_nothing_else() {
    use auvnav_shm_schema::AcousticRangesV1;
    let fixes = |tau: f64| -> Vec<AcousticRangesV1> {
        run(
            "ranges_array",
            &[("usbl.fix_time_constant", &[tau])],
            Some(120.0),
        )
        .into_iter()
        .filter_map(|m| match m {
            LogMessage::AcousticRanges(r) => Some(r),
            _ => None,
        })
        .collect()
    };
    let (raw, smoothed) = (fixes(0.0), fixes(2.0));
    assert_eq!(raw.len(), smoothed.len());
    assert!(raw.len() > 100);
    let mut state: Option<(f64, [f64; 3])> = None;
    let mut moved = 0.0f64;
    for (a, b) in raw.iter().zip(&smoothed) {
        assert_eq!(
            a.range_m, b.range_m,
            "the ranges are the device's, unsmoothed"
        );
        assert_eq!(a.validity, b.validity);
        if a.validity & AcousticRangesV1::VALID_POSITION == 0 {
            continue;
        }
        let t = a.host_time_ns as f64 * 1e-9;
        let p = a.position_array_m;
        let want = match state {
            Some((t0, s)) if t - t0 < 10.0 => {
                let k = 1.0 - (-(t - t0) / 2.0).exp();
                [0, 1, 2].map(|i| s[i] + k * (p[i] - s[i]))
            }
            _ => p,
        };
        state = Some((t, want));
        for i in 0..3 {
            assert!(
                (b.position_array_m[i] - want[i]).abs() < 1e-9,
                "{b:?} {want:?}"
            );
            moved = moved.max((b.position_array_m[i] - p[i]).abs());
        }
        assert_eq!(a.position_std_m, b.position_std_m);
    }
    assert!(moved > 0.1, "the smoothing changed the fixes ({moved} m)");
}

/// `usbl.receiver_range_bias`: each receiver's range is longer by its own bias (the same seed
/// gives the same noise and outliers), which receivers range is unchanged.
#[test]
fn usbl_receiver_range_bias_adds_each_receivers_own_error() {
    use auvnav_shm_schema::AcousticRangesV1;
    let bias = [0.7, -0.4, 0.0, 1.3];
    let pings = |b: &[f64]| -> Vec<AcousticRangesV1> {
        run(
            "ranges_array",
            &[("usbl.receiver_range_bias", b)],
            Some(60.0),
        )
        .into_iter()
        .filter_map(|m| match m {
            LogMessage::AcousticRanges(r) => Some(r),
            _ => None,
        })
        .collect()
    };
    let (plain, biased) = (pings(&[0.0; 4]), pings(&bias));
    assert_eq!(plain.len(), biased.len());
    assert!(plain.len() > 50);
    let mut seen = [0usize; 4];
    for (a, b) in plain.iter().zip(&biased) {
        assert_eq!(a.validity, b.validity);
        for (k, n) in seen.iter_mut().enumerate() {
            if a.range_valid(k) {
                let d = b.range_m[k] - a.range_m[k];
                assert!((d - bias[k]).abs() < 1e-9, "receiver {k}: {d} m");
                *n += 1;
            }
        }
    }
    assert!(seen.iter().all(|&n| n > 40), "{seen:?}");
}

/// A periodic DVL velocity error: each bottom-track velocity differs from the run without it by
/// the amplitude on each DVL axis times sin(2π t / period + phase) at its stamp, to 1e-9 m/s
/// (same seed, so the same noise); every other message is the same.
#[test]
fn dvl_periodic_velocity_error_adds_a_sine_at_each_stamp() {
    let amplitude = [0.03, -0.01, 0.005];
    let (period, phase_deg) = (23.0, 65.0);
    let base = run("turns", &[], Some(120.0));
    let periodic = run(
        "turns",
        &[
            ("dvl.periodic_velocity_error", &amplitude),
            ("dvl.periodic_velocity_error_period", &[period]),
            ("dvl.periodic_velocity_error_phase", &[phase_deg]),
        ],
        Some(120.0),
    );
    assert_eq!(base.len(), periodic.len());
    let mut compared = 0;
    for (a, b) in base.iter().zip(&periodic) {
        match (a, b) {
            (LogMessage::Dvl(a), LogMessage::Dvl(b)) if !a.is_water_track() => {
                assert_eq!(a.validity, b.validity);
                if a.validity & DvlVelocityV1::VALID_VELOCITY == 0 {
                    continue;
                }
                let t = b.validity_time_ns as f64 * 1e-9;
                let s = (std::f64::consts::TAU * t / period + phase_deg.to_radians()).sin();
                for (k, amp) in amplitude.iter().enumerate() {
                    let got = b.velocity_dvl_m_s[k] - a.velocity_dvl_m_s[k];
                    assert!(
                        (got - amp * s).abs() < 1e-9,
                        "t {t}: axis {k}: {got} against {}",
                        amp * s
                    );
                }
                compared += 1;
            }
            (a, b) => assert_eq!(format!("{a:?}"), format!("{b:?}")),
        }
    }
    assert!(compared > 100, "{compared} velocities compared");
}
