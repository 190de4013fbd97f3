//! The navigation core against physics: Jacobians against finite differences, the Schuler period
//! of a pure-inertial run with an initial tilt error.

use auvnav_core::aid::depth::depth_model;
use auvnav_core::aid::dvl::{DvlParameters, dvl_model};
use auvnav_core::aid::gnss::gnss_model;
use auvnav_core::earth::{self, Geodetic};
use auvnav_core::ekf as filter;
use auvnav_core::strapdown::{ImuIncrement, NavState, Strapdown};
use nalgebra::{Matrix3, Rotation3, SMatrix, UnitQuaternion, Vector3};

fn state() -> NavState {
    NavState {
        time_s: 0.0,
        position: Geodetic {
            latitude_rad: 31f64.to_radians(),
            longitude_rad: 120f64.to_radians(),
            height_m: -25.0,
        },
        velocity_ned: Vector3::new(1.2, -0.7, 0.15),
        q_body_to_ned: UnitQuaternion::from_euler_angles(0.05, -0.08, 2.1),
    }
}

fn dvl_parameters() -> DvlParameters {
    DvlParameters {
        c_dvl_to_body: Rotation3::from_euler_angles(0.01, -0.02, 0.03).into_inner(),
        scale: 1.003,
        lever_arm_m: Vector3::new(0.8, -0.1, 0.3),
        time_offset_s: 0.12,
    }
}

fn column(h: &SMatrix<f64, 3, { filter::N }>, j: usize) -> Vector3<f64> {
    h.fixed_view::<3, 1>(0, j).into()
}

/// `s` with its position moved by `eps` metres along NED axis `k`, and with its attitude turned
/// by `eps` milliradians about that axis (the filter's attitude error convention): the two
/// states a measurement model's position and attitude Jacobian columns are differenced against.
fn perturbed(s: &NavState, k: usize, eps: f64) -> (NavState, NavState) {
    let mut unit = Vector3::zeros();
    unit[k] = eps;
    let mut sp = *s;
    sp.position = earth::offset_position(&s.position, &unit);
    let mut sa = *s;
    sa.q_body_to_ned = UnitQuaternion::from_scaled_axis(-unit * 1e-3) * s.q_body_to_ned;
    (sp, sa)
}

#[test]
fn dvl_jacobian_matches_finite_differences() {
    let s = state();
    let w = Vector3::new(0.01, -0.02, 0.05);
    let f = Vector3::new(0.3, 0.1, -9.7);
    let p = dvl_parameters();
    let (h0, h) = dvl_model(&s, &w, &f, &p);
    let eps = 1e-6;
    let fd = |s: &NavState, p: &DvlParameters| (dvl_model(s, &w, &f, p).0 - h0) / eps;
    for k in 0..3 {
        let mut unit = Vector3::zeros();
        unit[k] = eps;
        // Velocity error: v_est = v + dv.
        let mut sv = s;
        sv.velocity_ned[k] += eps;
        let (col, analytic) = (fd(&sv, &p), column(&h, filter::VEL + k));
        assert!((col - analytic).norm() < 1e-6, "dv{k}: {col} vs {analytic}");
        // Attitude error: C_est = (I - [phi x]) C, i.e. q_est = exp(-phi) q.
        let mut sa = s;
        sa.q_body_to_ned = UnitQuaternion::from_scaled_axis(-unit) * s.q_body_to_ned;
        let (col, analytic) = (fd(&sa, &p), column(&h, filter::ATT + k));
        // The Earth-rate part of the lever-arm term's attitude dependence is neglected.
        assert!(
            (col - analytic).norm() < 1e-4,
            "phi{k}: {col} vs {analytic}"
        );
        // Mounting error: C_dvl->body(est) = C_dvl->body(true) (I + [dm x]).
        let mut pm = p;
        pm.c_dvl_to_body = p.c_dvl_to_body * Rotation3::from_scaled_axis(unit).into_inner();
        let (col, analytic) = (fd(&s, &pm), column(&h, filter::DVL_MOUNT + k));
        assert!((col - analytic).norm() < 1e-6, "dm{k}: {col} vs {analytic}");
        // Lever-arm error: l_est = l + dl.
        let mut pl = p;
        pl.lever_arm_m[k] += eps;
        let (col, analytic) = (fd(&s, &pl), column(&h, filter::DVL_LEVER + k));
        assert!((col - analytic).norm() < 1e-6, "dl{k}: {col} vs {analytic}");
    }
    let mut ps = p;
    ps.scale += eps;
    let (col, analytic) = (fd(&s, &ps), column(&h, filter::DVL_SCALE));
    assert!((col - analytic).norm() < 1e-6, "ds: {col} vs {analytic}");
    let mut pt = p;
    pt.time_offset_s += eps;
    let (col, analytic) = (fd(&s, &pt), column(&h, filter::DVL_TIME));
    assert!((col - analytic).norm() < 1e-6, "dtau: {col} vs {analytic}");
}

#[test]
fn dvl_time_offset_term_is_the_velocity_change_over_the_offset() {
    // Propagate a state with a constant body acceleration and check that the model's time-offset
    // term predicts the body velocity tau earlier.
    let s = state();
    let lat = s.position.latitude_rad;
    let c_nb: Matrix3<f64> = s.c_body_to_ned().transpose();
    let w = c_nb * earth::earth_rate_ned(lat) + Vector3::new(0.0, 0.0, 0.02);
    let accel_ned = Vector3::new(0.2, -0.1, 0.05);
    let f = c_nb * (accel_ned - earth::gravity_ned(lat, s.position.height_m));
    let tau = 0.05;
    let p = DvlParameters {
        c_dvl_to_body: Matrix3::identity(),
        scale: 1.0,
        lever_arm_m: Vector3::zeros(),
        time_offset_s: tau,
    };
    let (predicted, _) = dvl_model(&s, &w, &f, &p);
    // Body velocity at t - tau, integrated backwards with the same IMU output.
    let mut sd = Strapdown::new(s);
    let n = 200;
    let dt = -tau / n as f64;
    for _ in 0..n {
        sd.propagate(&ImuIncrement {
            dtheta: w * dt,
            dv: f * dt,
            dt,
        });
    }
    let earlier = sd.state.c_body_to_ned().transpose() * sd.state.velocity_ned;
    // The term itself is tau |a_b| = 1.2e-2 m/s here; what remains is second order in tau and
    // the neglected Coriolis acceleration.
    let term = (predicted - (c_nb * s.velocity_ned)).norm();
    assert!(term > 1e-2, "{term}");
    assert!(
        (predicted - earlier).norm() < 5e-5,
        "{predicted} vs {earlier}"
    );
}

#[test]
fn gnss_jacobian_matches_finite_differences() {
    let s = state();
    let arm = Vector3::new(-1.5, 0.2, -2.0);
    let fix = earth::offset_position(&s.position, &Vector3::new(3.0, -4.0, 0.5));
    let (y0, h) = gnss_model(&s, &arm, &fix);
    // Millimetres: smaller steps drown in the rounding of the latitude in radians.
    let eps = 1e-3;
    for k in 0..3 {
        let (sp, sa) = perturbed(&s, k, eps);
        let col = (gnss_model(&sp, &arm, &fix).0 - y0) / eps;
        let analytic = column(&h, filter::POS + k);
        assert!((col - analytic).norm() < 1e-5, "dp{k}: {col} vs {analytic}");
        let col = (gnss_model(&sa, &arm, &fix).0 - y0) / (eps * 1e-3);
        let analytic = column(&h, filter::ATT + k);
        assert!(
            (col - analytic).norm() < 1e-5,
            "phi{k}: {col} vs {analytic}"
        );
    }
}

#[test]
fn depth_jacobian_matches_finite_differences() {
    let s = state();
    let arm = Vector3::new(1.7, -0.3, 0.4);
    let (z0, h) = depth_model(&s, &arm);
    // The sensor's point below the IMU: −x sin θ + y sin φ cos θ + z cos φ cos θ (a nose-down
    // pitch of 0.08 rad puts the forward arm 0.14 m deeper).
    let (roll, pitch) = (0.05f64, -0.08f64);
    let down = -1.7 * pitch.sin() - 0.3 * roll.sin() * pitch.cos() + 0.4 * roll.cos() * pitch.cos();
    assert!(
        (z0 - (25.0 + down)).abs() < 1e-12,
        "{z0} against {}",
        25.0 + down
    );
    let eps = 1e-3;
    for k in 0..3 {
        let (sp, sa) = perturbed(&s, k, eps);
        let col = (depth_model(&sp, &arm).0 - z0) / eps;
        // The state's position error is NED; depth is down.
        let analytic = h[(0, filter::POS + k)];
        assert!((col - analytic).abs() < 1e-5, "dp{k}: {col} vs {analytic}");
        let col = (depth_model(&sa, &arm).0 - z0) / (eps * 1e-3);
        let analytic = h[(0, filter::ATT + k)];
        assert!((col - analytic).abs() < 1e-5, "phi{k}: {col} vs {analytic}");
    }
}

#[test]
fn dynamics_matrix_velocity_and_attitude_blocks_match_finite_differences() {
    // Propagate a perturbed and a nominal state over a short interval with the same IMU output
    // and compare the change of the error with F dt.
    let s = state();
    let dt = 0.01;
    let c_nb: Matrix3<f64> = s.c_body_to_ned().transpose();
    let f_ned = Vector3::new(0.3, -0.2, -9.79);
    let imu = ImuIncrement {
        dtheta: Vector3::new(0.002, -0.001, 0.004) * dt,
        dv: c_nb * f_ned * dt,
        dt,
    };
    let inputs = filter::DynamicsInputs {
        c_body_to_ned: s.c_body_to_ned(),
        specific_force_ned: f_ned,
        velocity_ned: s.velocity_ned,
        latitude_rad: s.position.latitude_rad,
        height_m: s.position.height_m,
    };
    let f = filter::dynamics_matrix(&inputs);
    let run = |st: NavState| {
        let mut sd = Strapdown::new(st);
        sd.propagate(&imu);
        sd.state
    };
    let nominal = run(s);
    let eps = 1e-4;
    for k in 0..3 {
        // Attitude error column: d(dv)/dt = f^n x phi.
        let mut sa = s;
        let mut phi = Vector3::zeros();
        phi[k] = eps;
        sa.q_body_to_ned = UnitQuaternion::from_scaled_axis(-phi) * s.q_body_to_ned;
        let pert = run(sa);
        let dv_rate = (pert.velocity_ned - nominal.velocity_ned) / (eps * dt);
        let analytic: Vector3<f64> = f.fixed_view::<3, 1>(filter::VEL, filter::ATT + k).into();
        assert!(
            (dv_rate - analytic).norm() < 1e-3 * analytic.norm().max(1.0),
            "phi{k}: {dv_rate} vs {analytic}"
        );
        // Velocity error column of the position block: d(dp)/dt = dv.
        let mut sv = s;
        sv.velocity_ned[k] += eps;
        let pert = run(sv);
        let dp = earth::ned_offset(&nominal.position, &pert.position) / (eps * dt);
        let analytic: Vector3<f64> = f.fixed_view::<3, 1>(filter::POS, filter::VEL + k).into();
        // The trapezoidal position update moves by half the velocity-change plus the error.
        assert!((dp - analytic).norm() < 0.02, "dv{k}: {dp} vs {analytic}");
    }
}

#[test]
fn pure_inertial_run_with_a_tilt_error_oscillates_with_the_schuler_period() {
    let lat = 31f64.to_radians();
    let pos = Geodetic {
        latitude_rad: lat,
        longitude_rad: 0.0,
        height_m: 0.0,
    };
    let q_true = UnitQuaternion::identity();
    let c_nb = q_true.to_rotation_matrix().matrix().transpose();
    let dt = 0.1;
    let w = c_nb * earth::earth_rate_ned(lat);
    let f = -(c_nb * earth::gravity_ned(lat, 0.0));
    // 0.1 mrad roll error: a tilt about north, so the east velocity error oscillates.
    let q0 = UnitQuaternion::from_euler_angles(1e-4, 0.0, 0.0);
    let mut sd = Strapdown::new(NavState {
        time_s: 0.0,
        position: pos,
        velocity_ned: Vector3::zeros(),
        q_body_to_ned: q0,
    });
    let mut crossings = Vec::new();
    let mut prev_ve = 0.0f64;
    let steps = (3.0 * 3600.0 / dt) as usize;
    for k in 1..=steps {
        sd.propagate(&ImuIncrement {
            dtheta: w * dt,
            dv: f * dt,
            dt,
        });
        // Hold the vertical channel (it is unstable without a depth aid).
        sd.state.position.height_m = 0.0;
        sd.state.velocity_ned.z = 0.0;
        let ve = sd.state.velocity_ned.y;
        if k > 1 && prev_ve.signum() != ve.signum() && ve != 0.0 {
            crossings.push(k as f64 * dt);
        }
        prev_ve = ve;
    }
    assert!(crossings.len() >= 4, "{crossings:?}");
    let half_periods: Vec<f64> = crossings.windows(2).map(|p| p[1] - p[0]).collect();
    let period_min = 2.0 * half_periods.iter().sum::<f64>() / half_periods.len() as f64 / 60.0;
    let r = (earth::meridian_radius(lat) * earth::prime_vertical_radius(lat)).sqrt();
    let expected = std::f64::consts::TAU * (r / earth::normal_gravity(lat, 0.0)).sqrt() / 60.0;
    eprintln!(
        "Schuler period {period_min:.2} min (expected {expected:.2}), {} crossings",
        crossings.len()
    );
    assert!((expected - 84.4).abs() < 0.3, "{expected}");
    assert!(
        (period_min - expected).abs() < 0.5,
        "Schuler period {period_min} min, expected {expected}"
    );
}
