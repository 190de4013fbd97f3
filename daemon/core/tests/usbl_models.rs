//! USBL measurement models against geometry computed independently, and the unscented update
//! against the Kalman update on a linear measurement.

use auvnav_core::aid::usbl::{
    UnscentedParams, UsblArray, fix_position_ned, predict_tight, range_differences_from_angles,
    unscented_update,
};
use auvnav_core::earth::{A, E2, Geodetic, to_ecef};
use nalgebra::{DMatrix, DVector, Matrix3, Rotation3, Vector3};

/// A small deterministic generator for test values (xorshift).
struct Gen(u64);
impl Gen {
    fn uniform(&mut self) -> f64 {
        self.0 ^= self.0 << 13;
        self.0 ^= self.0 >> 7;
        self.0 ^= self.0 << 17;
        (self.0 >> 11) as f64 / (1u64 << 53) as f64
    }
    fn range(&mut self, lo: f64, hi: f64) -> f64 {
        lo + (hi - lo) * self.uniform()
    }
}

/// ECEF → geodetic by fixed-point iteration on the latitude (independent of the core's code).
fn ecef_to_geodetic(p: &Vector3<f64>) -> Geodetic {
    let lon = p.y.atan2(p.x);
    let rho = (p.x * p.x + p.y * p.y).sqrt();
    let mut lat = p.z.atan2(rho * (1.0 - E2));
    let mut h = 0.0;
    for _ in 0..20 {
        let n = A / (1.0 - E2 * lat.sin().powi(2)).sqrt();
        h = rho / lat.cos() - n;
        lat = p.z.atan2(rho * (1.0 - E2 * n / (n + h)));
    }
    Geodetic {
        latitude_rad: lat,
        longitude_rad: lon,
        height_m: h,
    }
}

/// NED → ECEF rotation at (lat, lon), written out here rather than taken from the core.
fn c_ned_to_ecef(lat: f64, lon: f64) -> Matrix3<f64> {
    let (sl, cl, so, co) = (lat.sin(), lat.cos(), lon.sin(), lon.cos());
    Matrix3::new(
        -sl * co,
        -so,
        -cl * co,
        -sl * so,
        co,
        -cl * so,
        cl,
        0.0,
        -sl,
    )
}

#[test]
fn tight_model_matches_geometry_computed_in_ecef() {
    let mut g = Gen(0x5eed_1234_abcd_9876);
    for _ in 0..200 {
        let array_pos = Geodetic {
            latitude_rad: g.range(-60.0, 60.0).to_radians(),
            longitude_rad: g.range(-180.0, 180.0).to_radians(),
            height_m: g.range(-100.0, 0.0),
        };
        let yaw = g.range(-3.1, 3.1);
        let b = g.range(0.2, 1.0);
        let array = UsblArray::level(array_pos, yaw, b);
        // The responder somewhere within 2 km, below the array.
        let p_a_true = Vector3::new(
            g.range(-2000.0, 2000.0),
            g.range(-2000.0, 2000.0),
            g.range(1.0, 200.0),
        );
        // Independent route: array-frame point → NED (yaw only) → ECEF → geodetic.
        let c_a_n = Rotation3::from_euler_angles(0.0, 0.0, yaw).into_inner();
        let ecef_array = to_ecef(&array_pos);
        let c = c_ned_to_ecef(array_pos.latitude_rad, array_pos.longitude_rad);
        let responder = ecef_to_geodetic(&(ecef_array + c * (c_a_n * p_a_true)));
        // Vehicle: responder minus a lever arm in some attitude.
        let att = Rotation3::from_euler_angles(
            g.range(-0.2, 0.2),
            g.range(-0.2, 0.2),
            g.range(-3.0, 3.0),
        )
        .into_inner();
        let lever = Vector3::new(g.range(-2.0, 2.0), g.range(-1.0, 1.0), g.range(-1.0, 1.0));
        let resp_ecef = to_ecef(&responder);
        let c_resp = c_ned_to_ecef(responder.latitude_rad, responder.longitude_rad);
        let vehicle = ecef_to_geodetic(&(resp_ecef - c_resp * (att * lever)));
        let p_a = array.responder_in_array(&vehicle, &att, &lever);
        assert!((p_a - p_a_true).norm() < 1e-6, "{p_a} vs {p_a_true}");
        // Ranges from each hydrophone, in ECEF.
        let hyd = |i: usize| ecef_array + c * (c_a_n * array.hydrophones[i]);
        let range = |x: &Vector3<f64>| (resp_ecef - x).norm();
        let expected = Vector3::new(
            (resp_ecef - ecef_array).norm(),
            range(&hyd(0)) - range(&hyd(2)),
            range(&hyd(1)) - range(&hyd(3)),
        );
        let got = predict_tight(&array, &p_a);
        assert!((got - expected).norm() < 1e-6, "{got} vs {expected}");
    }
}

#[test]
fn angles_and_fixes_agree_with_the_geometry() {
    let mut g = Gen(42);
    let array = UsblArray::level(
        Geodetic {
            latitude_rad: 0.54,
            longitude_rad: 2.09,
            height_m: -30.0,
        },
        0.7,
        0.5,
    );
    for _ in 0..500 {
        let range = g.range(10.0, 3000.0);
        let az = g.range(-3.1, 3.1);
        let el = g.range(-1.5, 0.2);
        let u = Vector3::new(el.cos() * az.cos(), el.cos() * az.sin(), -el.sin());
        let p_a = range * u;
        let exact = predict_tight(&array, &p_a);
        let [d13, d24] = range_differences_from_angles(0.5, az, el);
        // Far field: error below b²/R.
        let bound = 0.5 * 0.5 / range;
        assert!((exact.y - d13).abs() < bound && (exact.z - d24).abs() < bound);
        // The loose fix is the same point, in NED.
        let ned = fix_position_ned(&array, range, az, el);
        assert!((array.c_ned_to_array * ned - p_a).norm() < 1e-9 * range);
    }
}

#[test]
fn unscented_update_equals_the_kalman_update_on_a_linear_measurement() {
    let mut g = Gen(7);
    for n in [3usize, 9, 18] {
        for m in [1usize, 3] {
            let a = DMatrix::from_fn(n, n, |_, _| g.range(-1.0, 1.0));
            let p = &a * a.transpose() + DMatrix::identity(n, n) * 0.1;
            let h = DMatrix::from_fn(m, n, |_, _| g.range(-2.0, 2.0));
            let c = DVector::from_fn(m, |_, _| g.range(-5.0, 5.0));
            let r = DMatrix::from_diagonal(&DVector::from_fn(m, |_, _| g.range(0.01, 1.0)));
            let z = DVector::from_fn(m, |_, _| g.range(-5.0, 5.0));
            let f = |x: &DVector<f64>| &h * x + &c;
            for params in [
                UnscentedParams::default(),
                UnscentedParams {
                    alpha: 1e-3,
                    beta: 2.0,
                    kappa: 0.0,
                },
            ] {
                let u = unscented_update(&p, &z, &r, &f, params).expect("update");
                let s = &h * &p * h.transpose() + &r;
                let k = &p * h.transpose() * s.clone().try_inverse().expect("inverse");
                let dx = &k * (&z - &c);
                let p_kf = &p - &k * &s * k.transpose();
                let scale = p.norm();
                assert!(
                    (&u.dx - &dx).norm() < 1e-8 * (1.0 + dx.norm()),
                    "n {n} m {m}"
                );
                assert!((u.p - p_kf).norm() < 1e-8 * scale, "n {n} m {m}");
            }
        }
    }
}

/// Gaussian samples for the adaptive-noise test (Box–Muller on the test generator).
fn normal(g: &mut Gen) -> f64 {
    let u1 = g.uniform().max(1e-300);
    let u2 = g.uniform();
    (-2.0 * u1.ln()).sqrt() * (std::f64::consts::TAU * u2).cos()
}

#[test]
fn adaptive_noise_converges_to_the_true_variance_and_rejects_outliers() {
    for seed in [2024, 7, 99] {
        adaptive_run(seed);
    }
}

fn adaptive_run(seed: u64) {
    use auvnav_core::aid::usbl::AdaptiveNoise;
    // A slant range to a slowly moving target, a two-state (range, rate) Kalman filter, noise
    // σ = 0.3 m while the filter starts believing 1 m; 5 % of the fixes are multipath outliers
    // of 10–50 m.
    let sigma = 0.3;
    let mut g = Gen(seed);
    let dt = 1.0;
    let f = DMatrix::from_row_slice(2, 2, &[1.0, dt, 0.0, 1.0]);
    let q = DMatrix::from_row_slice(2, 2, &[1e-4, 0.0, 0.0, 1e-4]);
    let h = DMatrix::from_row_slice(1, 2, &[1.0, 0.0]);
    let mut x = DVector::from_vec(vec![100.0, 0.5]);
    let mut p = DMatrix::identity(2, 2) * 10.0;
    let mut truth = DVector::from_vec(vec![100.0, 0.5]);
    let mut noise = AdaptiveNoise::new(DVector::from_element(1, 1.0), 0.995, 1e-4, 1e4, 16.0);
    let (mut injected, mut accepted_outliers) = (0, 0);
    for _ in 0..10_000 {
        truth[0] += truth[1] * dt + 0.01 * normal(&mut g);
        x = &f * &x;
        p = &f * &p * f.transpose() + &q;
        let outlier = g.uniform() < 0.05;
        let z = truth[0] + sigma * normal(&mut g) + if outlier { g.range(10.0, 50.0) } else { 0.0 };
        injected += usize::from(outlier);
        let eps = DVector::from_element(1, z - x[0]);
        let hph = &h * &p * h.transpose();
        if noise.observe(&eps, &hph) {
            accepted_outliers += usize::from(outlier);
            let s = &hph + noise.covariance();
            let k = &p * h.transpose() / s[(0, 0)];
            x += &k * eps[0];
            p = (DMatrix::identity(2, 2) - &k * &h) * &p;
        }
    }
    let r = noise.variances()[0];
    eprintln!(
        "seed {seed}: estimated σ {:.4} m (true {sigma}), {} rejected, {injected} outliers injected, {accepted_outliers} accepted",
        r.sqrt(),
        noise.rejected
    );
    assert!((r.sqrt() - sigma).abs() < 0.1 * sigma, "σ {}", r.sqrt());
    assert_eq!(accepted_outliers, 0);
    // Every outlier rejected, and few good fixes with them (false alarms of a χ² gate at 16).
    assert!(
        noise.rejected as usize >= injected && (noise.rejected as usize) < injected + injected / 5
    );
    assert_eq!(noise.reopened, 0);
}

mod fusion {
    use auvnav_core::aid::usbl::{
        Coupling, UsblConfig, UsblInputError, measurement, predict_tight,
        range_differences_from_angles,
    };
    use auvnav_core::earth::Geodetic;
    use auvnav_core::ekf::{self as filter, CoreMatrix, ErrorFilter, ProcessNoise, StateVector};
    use auvnav_core::navigator::{NavConfig, Navigator, initial_state};
    use auvnav_shm_schema::UsblFixV1;
    use nalgebra::Vector3;

    #[test]
    fn gauss_markov_states_keep_their_stationary_variance_and_decorrelate() {
        let mut p0 = StateVector::zeros();
        p0[filter::POS] = 1.0;
        let mut kf = ErrorFilter::new(&p0);
        let (tau, std) = (200.0, 0.3);
        kf.set_gauss_markov(filter::USBL, tau, std);
        // Correlate the error state with a position state, then propagate with no dynamics.
        let c = 0.5 * std;
        kf.p[(filter::POS, filter::USBL)] = c;
        kf.p[(filter::USBL, filter::POS)] = c;
        let quiet = ProcessNoise {
            gyro_noise: 0.0,
            accel_noise: 0.0,
            gyro_bias_walk: 0.0,
            accel_bias_walk: 0.0,
        };
        let dt = 0.05;
        let steps = 4000; // 200 s = one correlation time
        for _ in 0..steps {
            kf.predict(
                &CoreMatrix::zeros(),
                &nalgebra::Matrix3::identity(),
                &quiet,
                dt,
            );
        }
        let t = dt * steps as f64;
        let var = kf.p[(filter::USBL, filter::USBL)];
        assert!((var - std * std).abs() < 1e-9 * std * std, "variance {var}");
        let cross = kf.p[(filter::POS, filter::USBL)];
        assert!(
            (cross - c * (-t / tau).exp()).abs() < 1e-9,
            "cross-covariance {cross}"
        );
        // A constant parameter state is untouched.
        assert_eq!(
            kf.param_transition(dt)[filter::DVL_SCALE - filter::CORE],
            1.0
        );
    }

    fn station() -> UsblConfig {
        UsblConfig {
            array_latitude_deg: 31.0,
            array_longitude_deg: 120.0,
            array_height_m: -55.0,
            array_yaw_deg: 25.0,
            baseline_m: 0.5,
            ..UsblConfig::default()
        }
    }

    fn fix(range: f64, d: [f64; 2], az: f64, el: f64, validity: u32) -> UsblFixV1 {
        UsblFixV1 {
            host_time_ns: 1_000_000_000,
            validity_time_ns: 1_000_000_000,
            slant_range_m: range,
            range_difference_m: d,
            azimuth_rad: az,
            elevation_rad: el,
            validity,
            ..Default::default()
        }
    }

    #[test]
    fn a_device_that_reports_angles_gives_range_differences_through_the_baseline() {
        let cfg = station();
        let array = cfg.array();
        // A responder 300 m out, 40 m above the array: exact range differences against the ones
        // derived from its exact angles (error below b²/R) and the noise they are given.
        let p_a: Vector3<f64> = Vector3::new(180.0, -230.0, -40.0);
        let (az, el) = (p_a.y.atan2(p_a.x), (-p_a.z).atan2(p_a.x.hypot(p_a.y)));
        let exact = predict_tight(&array, &p_a);
        let m = measurement(
            &cfg,
            &array,
            &fix(
                p_a.norm(),
                [0.0; 2],
                az,
                el,
                UsblFixV1::VALID_RANGE | UsblFixV1::VALID_ANGLES,
            ),
        )
        .expect("angles are enough for the tight model");
        let bound = cfg.baseline_m.powi(2) / p_a.norm();
        assert!((m.z[1] - exact[1]).abs() < bound && (m.z[2] - exact[2]).abs() < bound);
        assert_eq!(
            [m.z[1], m.z[2]],
            range_differences_from_angles(cfg.baseline_m, az, el)
        );
        let sd = cfg.baseline_m * cfg.angle_std_deg.to_radians();
        assert!((m.r[(1, 1)] - sd * sd).abs() < 1e-15);
        // Loose: the fix is turned into the array's NED frame by the surveyed yaw.
        let loose = UsblConfig {
            coupling: Coupling::Loose,
            ..cfg.clone()
        };
        let m = measurement(
            &loose,
            &array,
            &fix(
                p_a.norm(),
                [0.0; 2],
                az,
                el,
                UsblFixV1::VALID_RANGE | UsblFixV1::VALID_ANGLES,
            ),
        )
        .expect("loose fix");
        // In line-of-sight coordinates: the fix turned back into NED is the responder there; the
        // first axis is the range, and the noise is range along it, angles across it.
        assert!((m.frame.transpose() * m.z - array.c_ned_to_array.transpose() * p_a).norm() < 1e-9);
        assert!((m.z[0] - p_a.norm()).abs() < 1e-9 && m.z[1].abs() < 1e-9 && m.z[2].abs() < 1e-9);
        assert!((m.frame * m.frame.transpose() - nalgebra::Matrix3::identity()).norm() < 1e-12);
        let across = p_a.norm() * cfg.angle_std_deg.to_radians();
        assert!((m.r[(2, 2)] - across * across).abs() < 1e-12);
        assert!((m.r[(1, 1)] - (across * el.cos()).powi(2)).abs() < 1e-12);
    }

    #[test]
    fn unusable_fixes_are_refused_and_counted_without_touching_the_state() {
        let cfg = station();
        let array = cfg.array();
        let all = UsblFixV1::VALID_RANGE | UsblFixV1::VALID_RANGE_DIFFERENCES;
        for (f, why) in [
            (fix(100.0, [0.1, 0.1], 0.0, 0.0, 0), UsblInputError::NoRange),
            (
                fix(f64::NAN, [0.1, 0.1], 0.0, 0.0, all),
                UsblInputError::BadRange,
            ),
            (
                fix(-3.0, [0.1, 0.1], 0.0, 0.0, all),
                UsblInputError::BadRange,
            ),
            (
                fix(9000.0, [0.1, 0.1], 0.0, 0.0, all),
                UsblInputError::BadRange,
            ),
            (
                fix(100.0, [0.9, 0.1], 0.0, 0.0, all),
                UsblInputError::BadDirection,
            ),
            (
                fix(100.0, [0.1, f64::INFINITY], 0.0, 0.0, all),
                UsblInputError::BadDirection,
            ),
            (
                fix(100.0, [0.1, 0.1], 0.0, 0.0, UsblFixV1::VALID_RANGE),
                UsblInputError::NoDirection,
            ),
        ] {
            assert_eq!(measurement(&cfg, &array, &f), Err(why), "{f:?}");
        }
        let start = initial_state(
            1.0,
            Geodetic {
                latitude_rad: 31.0f64.to_radians(),
                longitude_rad: 120.0f64.to_radians(),
                height_m: -20.0,
            },
            [0.0; 3],
            [0.0; 3],
        );
        let mut nav = Navigator::new(
            NavConfig {
                usbl: Some(cfg),
                ..NavConfig::default()
            },
            start,
        );
        let before = *nav.state();
        nav.on_usbl(&fix(f64::NAN, [0.0; 2], 0.0, 0.0, all));
        nav.on_usbl(&fix(100.0, [0.0; 2], 0.0, 0.0, UsblFixV1::VALID_RANGE));
        assert_eq!(nav.counters().usbl_invalid, 2);
        assert_eq!(nav.counters().usbl_fused, 0);
        assert_eq!(nav.state().position, before.position);
        // Without a [navigation.usbl] configuration fixes are counted as unused.
        let mut plain = Navigator::new(NavConfig::default(), start);
        plain.on_usbl(&fix(100.0, [0.0; 2], 0.0, 0.0, all));
        assert_eq!(plain.counters().usbl_unconfigured, 1);
    }

    #[test]
    fn the_usbl_section_parses_from_toml_and_reports_nonsense() {
        let cfg: NavConfig = toml::from_str(
            "[usbl]\ncoupling = \"loose\"\nfilter = \"akf\"\narray_latitude_deg = 31.0\nbaseline_m = 0.3\n",
        )
        .expect("parse");
        let u = cfg.usbl.expect("usbl section");
        assert_eq!(u.coupling, Coupling::Loose);
        assert_eq!(u.baseline_m, 0.3);
        assert!(u.problems().is_empty());
        let bad = UsblConfig {
            baseline_m: 0.0,
            fading: 1.0,
            ..u
        };
        let p = bad.problems();
        assert!(p.iter().any(|x| x.starts_with("usbl.baseline_m")), "{p:?}");
        assert!(p.iter().any(|x| x.starts_with("usbl.fading")), "{p:?}");
        assert!(toml::from_str::<NavConfig>("[usbl]\nbaseline = 0.3\n").is_err());
    }
}

/// Fixes with random bytes in every field: never a panic, every one counted once, the state
/// stays finite.
#[test]
fn random_fixes_never_break_the_navigator() {
    use auvnav_core::aid::usbl::{Coupling, UsblConfig, UsblFilter};
    use auvnav_core::earth::Geodetic;
    use auvnav_core::navigator::{NavConfig, Navigator, initial_state};
    use auvnav_shm_schema::UsblFixV1;
    let mut g = Gen(0x5eed_1234_abcd_0001);
    let bits = |g: &mut Gen| -> f64 {
        // Half plausible values, half arbitrary bit patterns (NaN, infinities, huge, tiny).
        if g.uniform() < 0.5 {
            g.range(-2000.0, 2000.0)
        } else {
            f64::from_bits(((g.uniform() * u32::MAX as f64) as u64) << 32 | g.0 & 0xffff_ffff)
        }
    };
    for coupling in [Coupling::Tight, Coupling::Loose] {
        for filter in [UsblFilter::Ukf, UsblFilter::Akf, UsblFilter::Aukf] {
            let start = initial_state(
                1.0,
                Geodetic {
                    latitude_rad: 31.0f64.to_radians(),
                    longitude_rad: 120.0f64.to_radians(),
                    height_m: -20.0,
                },
                [1.0, 0.5, 0.0],
                [0.0, 0.0, 0.3],
            );
            let cfg = UsblConfig {
                coupling,
                filter,
                array_latitude_deg: 31.001,
                array_longitude_deg: 120.001,
                array_height_m: -50.0,
                ..UsblConfig::default()
            };
            let mut nav = Navigator::new(
                NavConfig {
                    usbl: Some(cfg),
                    ..NavConfig::default()
                },
                start,
            );
            let n = 3000u64;
            for k in 0..n {
                let f = UsblFixV1 {
                    host_time_ns: 1_000_000_000,
                    validity_time_ns: if k % 7 == 0 { 0 } else { 1_000_000_000 },
                    slant_range_m: bits(&mut g),
                    range_difference_m: [bits(&mut g) * 1e-3, bits(&mut g) * 1e-3],
                    azimuth_rad: bits(&mut g) * 1e-3,
                    elevation_rad: bits(&mut g) * 1e-3,
                    position_array_m: [bits(&mut g), bits(&mut g), bits(&mut g)],
                    validity: if k % 2 == 0 {
                        0xff
                    } else {
                        (g.uniform() * 256.0) as u32
                    },
                    ..Default::default()
                };
                nav.on_usbl(&f);
            }
            let c = nav.counters();
            assert_eq!(
                c.usbl_fused + c.usbl_rejected + c.usbl_invalid + c.usbl_failed + c.aid_late,
                n,
                "{coupling:?} {filter:?}: {c:?}"
            );
            let s = nav.state();
            assert!(
                s.position.latitude_rad.is_finite()
                    && s.position.height_m.is_finite()
                    && s.velocity_ned.iter().all(|x| x.is_finite()),
                "{coupling:?} {filter:?}"
            );
            assert!(nav.covariance().iter().all(|x| x.is_finite()));
        }
    }
}
