//! A navigation that never lies: absurd but finite IMU values, device-clock jumps, IMU gaps and a
//! filter whose state stops being sound must never give NaN, and the published standard deviation
//! must cover the error that remains. Each case runs a simulated straight run through the one feed
//! path (`Session::feed`) with the fault injected into the sensor stream, and compares with the
//! truth.

use auvnav_core::config::NavConfig;
use auvnav_core::earth;
use auvnav_core::feed::SensorMessage;
use auvnav_core::session::{Session, SessionConfig, SessionOutput};
use auvnav_core::strapdown::{NavState, truth_position};
use auvnav_log::LogMessage;
use auvnav_shm_schema::{ImuSampleV1, NavMode, NavSolutionV1, TruthStateV1};
use auvnav_sim::{self as sim, SimConfig, scenario::Scenario};

fn straight(seconds: f64, seed: u64) -> Vec<LogMessage> {
    let scenario = Scenario::load("straight").expect("scenario");
    let effects = scenario.effects().expect("effects");
    sim::simulate_to_vec(&SimConfig {
        scenario,
        effects,
        seed,
        duration_s: Some(seconds),
    })
    .expect("simulate")
    .0
}

fn truths(msgs: &[LogMessage]) -> Vec<TruthStateV1> {
    msgs.iter()
        .filter_map(|m| match m {
            LogMessage::Truth(t) => Some(*t),
            _ => None,
        })
        .collect()
}

/// The truth record nearest in time to `t_ns`.
fn truth_at(truths: &[TruthStateV1], t_ns: u64) -> &TruthStateV1 {
    let i = truths.partition_point(|t| t.host_time_ns < t_ns);
    let candidates = [i.saturating_sub(1), i.min(truths.len() - 1)];
    let best = candidates
        .into_iter()
        .min_by_key(|&k| truths[k].host_time_ns.abs_diff(t_ns))
        .expect("a truth record");
    &truths[best]
}

struct Run {
    solutions: Vec<NavSolutionV1>,
    session: Session,
}

/// Starts at the first truth record and feeds every sensor message after `edit` has changed it
/// (or dropped it: `None`).
fn run(
    msgs: &[LogMessage],
    nav: NavConfig,
    mut edit: impl FnMut(SensorMessage) -> Option<SensorMessage>,
    mut poke: impl FnMut(&mut Session, u64),
) -> Run {
    let cfg = SessionConfig {
        navigation: nav,
        ..Default::default()
    };
    let mut session = Session::new(&cfg);
    let mut solutions = Vec::new();
    let mut collect = |o: SessionOutput| -> Result<(), ()> {
        if let SessionOutput::Solution(s) = o {
            solutions.push(*s);
        }
        Ok(())
    };
    for m in msgs {
        match m {
            LogMessage::Truth(t) if !session.started() => session
                .start(NavState::from_truth(t), "truth", &mut collect)
                .expect("start"),
            m => {
                if let (Some(x), true) = (m.sensor(), session.started())
                    && let Some(x) = edit(x)
                {
                    poke(&mut session, x.host_time_ns());
                    session.feed(&x, &mut collect).expect("feed");
                }
            }
        }
    }
    session.finish(&mut collect).expect("finish");
    Run { solutions, session }
}

fn all_finite(s: &NavSolutionV1) -> bool {
    s.all_finite()
}

/// Horizontal error (m) and the published horizontal standard deviation (m, the larger axis) of
/// a solution.
fn horizontal(truths: &[TruthStateV1], s: &NavSolutionV1) -> (f64, f64) {
    let t = truth_at(truths, s.host_time_ns);
    let est = earth::Geodetic {
        latitude_rad: s.latitude_rad,
        longitude_rad: s.longitude_rad,
        height_m: s.height_m,
    };
    let e = earth::ned_offset(&truth_position(t), &est);
    let std = s.position_std_ned_m[0].max(s.position_std_ned_m[1]);
    (e.x.hypot(e.y), std)
}

fn imu_time_s(x: &SensorMessage) -> Option<f64> {
    match x {
        SensorMessage::Imu(m) => Some(m.host_time_ns as f64 * 1e-9),
        _ => None,
    }
}

#[test]
fn absurd_but_finite_imu_values_are_refused_and_counted() {
    let msgs = straight(120.0, 11);
    let truths = truths(&msgs);
    let t0 = truths[0].host_time_ns as f64 * 1e-9;
    let mut poisoned = 0;
    let r = run(
        &msgs,
        NavConfig::default(),
        |x| match x {
            SensorMessage::Imu(mut m) => {
                let t = m.host_time_ns as f64 * 1e-9 - t0;
                if (40.0..41.0).contains(&t) && poisoned < 10 {
                    // Ten samples of 1e30 (a valid checksum carries them as well).
                    poisoned += 1;
                    m.angular = [1e30; 3];
                    m.specific = [-1e30; 3];
                } else if (60.0..60.01).contains(&t) {
                    // Finite, but far beyond any navigation IMU's range (1 000 rad/s).
                    m.angular[2] = 1000.0 * m.interval_s.max(1e-3);
                    m.specific[0] = 5000.0;
                }
                Some(SensorMessage::Imu(m))
            }
            other => Some(other),
        },
        |_, _| {},
    );
    let c = r.session.navigator().expect("navigating").counters();
    assert_eq!(poisoned, 10);
    assert!(
        c.imu_invalid >= 11,
        "the absurd samples are counted invalid: {c:?}"
    );
    assert!(r.solutions.iter().all(all_finite), "a solution holds NaN");
    let worst = r
        .solutions
        .iter()
        .map(|s| horizontal(&truths, s).0)
        .fold(0.0, f64::max);
    assert!(worst < 1.0, "worst horizontal error {worst:.2} m");
}

#[test]
fn a_device_clock_jump_falls_back_to_host_time() {
    let msgs = straight(120.0, 12);
    let truths = truths(&msgs);
    let t0 = truths[0].host_time_ns as f64 * 1e-9;
    let nav = NavConfig {
        imu_dt_from_device_time: true,
        ..NavConfig::default()
    };
    // From 50 s to 51 s the device clock jumps 0.9 s ahead at every frame (and stays ahead).
    let mut ahead_ns = 0u64;
    let mut jumped = 0u64;
    let r = run(
        &msgs,
        nav.clone(),
        |x| match x {
            SensorMessage::Imu(mut m) => {
                let t = m.host_time_ns as f64 * 1e-9 - t0;
                if (50.0..51.0).contains(&t) {
                    ahead_ns += 900_000_000;
                    jumped += 1;
                }
                m.device_time_ns += ahead_ns;
                Some(SensorMessage::Imu(m))
            }
            other => Some(other),
        },
        |_, _| {},
    );
    let c = r.session.navigator().expect("navigating").counters();
    assert_eq!(
        c.imu_clock_jumps, jumped,
        "every jumped frame is counted: {c:?}"
    );
    let worst = r
        .solutions
        .iter()
        .map(|s| horizontal(&truths, s).0)
        .fold(0.0, f64::max);
    assert!(
        worst < 1.0,
        "worst horizontal error {worst:.2} m after the clock jumps"
    );
    // A stall (the device clock stops for a second) is refused the same way.
    let r = run(
        &msgs,
        nav,
        |x| match x {
            SensorMessage::Imu(mut m) => {
                let t = m.host_time_ns as f64 * 1e-9 - t0;
                if (30.0..31.0).contains(&t) {
                    m.device_time_ns = (t0 + 30.0) as u64 * 1_000_000_000;
                }
                Some(SensorMessage::Imu(m))
            }
            other => Some(other),
        },
        |_, _| {},
    );
    let c = r.session.navigator().expect("navigating").counters();
    assert!(c.imu_clock_jumps > 50, "the stall is counted: {c:?}");
    assert!(r.solutions.iter().all(all_finite));
}

#[test]
fn after_a_three_second_imu_gap_the_error_is_small_or_inside_three_sigma() {
    for seed in [13, 14] {
        let msgs = straight(120.0, seed);
        let truths = truths(&msgs);
        let t0 = truths[0].host_time_ns as f64 * 1e-9;
        let (gap_start, gap_end) = (t0 + 60.0, t0 + 63.0);
        let r = run(
            &msgs,
            NavConfig::default(),
            |x| match imu_time_s(&x) {
                Some(t) if t >= gap_start && t < gap_end => None,
                _ => Some(x),
            },
            |_, _| {},
        );
        let c = r.session.navigator().expect("navigating").counters();
        assert_eq!(c.imu_gaps, 1, "{c:?}");
        // From the first solution after the gap, for ten seconds.
        let after: Vec<_> = r
            .solutions
            .iter()
            .filter(|s| {
                let t = s.host_time_ns as f64 * 1e-9;
                t >= gap_end && t < gap_end + 10.0
            })
            .collect();
        assert!(!after.is_empty());
        for s in after {
            let (e, std) = horizontal(&truths, s);
            assert!(
                e <= 0.5 || e <= 3.0 * std,
                "seed {seed}: horizontal error {e:.2} m with a published sigma of {std:.2} m at {:.2} s",
                s.host_time_ns as f64 * 1e-9 - t0
            );
        }
        let first = r
            .solutions
            .iter()
            .find(|s| s.host_time_ns as f64 * 1e-9 >= gap_end)
            .expect("a solution after the gap");
        let (e, std) = horizontal(&truths, first);
        eprintln!("seed {seed}: just after the gap: error {e:.3} m, sigma {std:.3} m");
    }
}

#[test]
fn a_filter_that_stops_being_sound_restarts_from_its_last_sound_state() {
    let msgs = straight(120.0, 15);
    let truths = truths(&msgs);
    let t0 = truths[0].host_time_ns;
    let at = t0 + 70_000_000_000;
    let mut done = false;
    let r = run(&msgs, NavConfig::default(), Some, |session, t_ns| {
        if !done && t_ns >= at {
            done = true;
            session.poison_covariance_for_tests();
        }
    });
    assert_eq!(r.session.reinitialisations, 1);
    assert!(
        r.solutions.iter().all(all_finite),
        "NaN published after the fault"
    );
    let invalid: Vec<_> = r
        .solutions
        .iter()
        .filter(|s| s.nav_mode() == Ok(NavMode::Invalid))
        .collect();
    assert_eq!(invalid.len(), 1, "one solution says invalid");
    // The sequence numbers keep increasing through the restart.
    assert!(
        r.solutions
            .windows(2)
            .all(|w| w[1].sequence == w[0].sequence + 1)
    );
    // Navigation goes on, and its error is covered by what it publishes.
    for s in r
        .solutions
        .iter()
        .filter(|s| s.host_time_ns >= invalid[0].host_time_ns)
    {
        let (e, std) = horizontal(&truths, s);
        assert!(
            e <= 0.5 || e <= 3.0 * std,
            "error {e:.2} m, sigma {std:.2} m"
        );
    }
    let last = r.solutions.last().expect("solutions");
    assert_eq!(last.nav_mode(), Ok(NavMode::Navigating));
}

#[test]
fn a_restart_continues_from_the_checkpoint_with_the_covariance_grown() {
    let msgs = straight(120.0, 16);
    let truths = truths(&msgs);
    let t0 = truths[0].host_time_ns;
    // The first run: navigate 60 s and take the checkpoint.
    let cut = t0 + 60_000_000_000;
    let first: Vec<_> = msgs
        .iter()
        .filter(|m| match m {
            LogMessage::Truth(t) => t.host_time_ns <= cut,
            m => m.sensor().is_none_or(|x| x.host_time_ns() <= cut),
        })
        .cloned()
        .collect();
    let r = run(&first, NavConfig::default(), Some, |_, _| {});
    let cp = r.session.checkpoint().expect("a checkpoint");
    // The process is down for 5 s; the next one starts from the checkpoint.
    let resume_at = cut + 5_000_000_000;
    let cfg = SessionConfig::default();
    let mut session = Session::new(&cfg);
    session.resume_from(cp, 5.0, 2.5);
    let mut solutions = Vec::new();
    for m in &msgs {
        if let Some(x) = m.sensor()
            && x.host_time_ns() >= resume_at
        {
            session
                .feed(&x, &mut |o| {
                    if let SessionOutput::Solution(s) = o {
                        solutions.push(*s);
                    }
                    Ok::<(), ()>(())
                })
                .expect("feed");
        }
    }
    assert!(session.resumed);
    let first = solutions.first().expect("a solution after the restart");
    let (e, std) = horizontal(&truths, first);
    assert!(
        std >= 2.5 * 5.0 * 0.9,
        "the covariance grew by the drift over the time down: sigma {std:.2} m"
    );
    assert!(e <= 3.0 * std, "error {e:.2} m, sigma {std:.2} m");
    for s in &solutions {
        let (e, std) = horizontal(&truths, s);
        assert!(
            e <= 0.5 || e <= 3.0 * std,
            "error {e:.2} m, sigma {std:.2} m"
        );
        assert!(all_finite(s));
    }
}

#[test]
fn a_large_position_uncertainty_is_published_as_position_unknown() {
    let msgs = straight(30.0, 17);
    let nav = NavConfig {
        initial_position_std_m: 5000.0,
        ..NavConfig::default()
    };
    let r = run(&msgs, nav, Some, |_, _| {});
    assert!(
        r.solutions
            .iter()
            .skip(1)
            .all(|s| s.nav_mode() == Ok(NavMode::PositionUnknown)),
        "without a position aid the position stays unknown"
    );
}

/// IMU samples in increment mode carry the same checks (the range applies to the rate).
#[test]
fn plausibility_applies_to_increments_as_rates() {
    let m = ImuSampleV1 {
        angular: [0.0, 0.0, 0.1],
        specific: [0.0, 0.0, -0.098],
        interval_s: 0.01,
        status: ImuSampleV1::STATUS_GYRO_VALID
            | ImuSampleV1::STATUS_ACCEL_VALID
            | ImuSampleV1::STATUS_INCREMENTS,
        ..Default::default()
    };
    // 0.1 rad in 10 ms is 10 rad/s: within 2000 deg/s, beyond 500 deg/s.
    assert!(auvnav_core::nav_core::plausible_rates(&m, 2000f64.to_radians(), 300.0).is_some());
    assert!(auvnav_core::nav_core::plausible_rates(&m, 500f64.to_radians(), 300.0).is_none());
    let nan = ImuSampleV1 {
        specific: [f64::NAN, 0.0, 0.0],
        ..m
    };
    assert!(auvnav_core::nav_core::plausible_rates(&nan, 1e9, 1e9).is_none());
}

/// Every kind of sensor message with arbitrary values (random bits in every field, or one field
/// set to an extreme: NaN, ±infinity, ±1e30, 1e-300), mixed into a docking run with tight USBL
/// fusion (AUKF), the magnetometer aid and the DVL parameter states switched on: the session never
/// panics and never gives a solution holding NaN. (Debug builds also check every integer
/// operation for overflow here.)
#[test]
fn arbitrary_sensor_values_never_give_a_nan_solution() {
    use auvnav_sim::StationGeometry;
    use auvnav_tools::usbl::navigation_config;
    let scenario = Scenario::load("docking").expect("scenario");
    let station = StationGeometry::from_scenario(&scenario).expect("station");
    let msgs = sim::simulate_to_vec(&SimConfig {
        effects: scenario.effects().expect("effects"),
        scenario,
        seed: 33,
        duration_s: Some(200.0),
    })
    .expect("simulate")
    .0;
    let mut nav = navigation_config(
        &station,
        auvnav_core::aid::usbl::Coupling::Tight,
        auvnav_core::aid::usbl::UsblFilter::Aukf,
    );
    nav.magnetometer = Some(auvnav_core::aid::magnetometer::MagnetometerConfig {
        model_date: Some(2026.5),
        ..Default::default()
    });
    nav.estimate_dvl_mounting = true;
    nav.estimate_dvl_scale = true;
    nav.estimate_dvl_lever_arm = true;
    nav.imu_dt_from_device_time = true;
    let extremes = [
        f64::NAN,
        f64::INFINITY,
        f64::NEG_INFINITY,
        1e30,
        -1e30,
        1e-300,
        0.0,
    ];
    let mut bits = auvnav_tests::Bits(0x853c_49e6_748f_ea9b);
    let mut next = move || bits.next_u64();
    // Randomises every byte of a message after its host time (its first 8 bytes: the driver's
    // clock, not the device's), device time and sequence included, or sets one f64 field after
    // the first 24 bytes to an extreme.
    fn scramble<T: bytemuck::Pod>(m: &mut T, r: u64, r2: u64, extremes: &[f64]) {
        let bytes = bytemuck::bytes_of_mut(m);
        let n = bytes.len();
        if r.is_multiple_of(2) {
            for (i, b) in bytes[8..].iter_mut().enumerate() {
                *b = (r2.rotate_left((i % 64) as u32) >> (i % 8)) as u8 ^ (i as u8);
            }
        } else {
            let slots = (n - 24) / 8;
            let k = 24 + 8 * (r2 as usize % slots.max(1));
            let v = extremes[(r >> 8) as usize % extremes.len()];
            bytes[k..k + 8].copy_from_slice(&v.to_le_bytes());
        }
    }
    let mut scrambled = 0u64;
    let r = run(
        &msgs,
        nav,
        |m| {
            let roll = next();
            if !roll.is_multiple_of(10) {
                return Some(m);
            }
            scrambled += 1;
            let (a, b) = (next(), next());
            Some(match m {
                SensorMessage::Imu(mut v) => {
                    scramble(&mut v, a, b, &extremes);
                    SensorMessage::Imu(v)
                }
                SensorMessage::Dvl(mut v) => {
                    scramble(&mut v, a, b, &extremes);
                    SensorMessage::Dvl(v)
                }
                SensorMessage::Depth(mut v) => {
                    scramble(&mut v, a, b, &extremes);
                    SensorMessage::Depth(v)
                }
                SensorMessage::Gnss(mut v) => {
                    scramble(&mut v, a, b, &extremes);
                    SensorMessage::Gnss(v)
                }
                SensorMessage::Usbl(mut v) => {
                    scramble(&mut v, a, b, &extremes);
                    SensorMessage::Usbl(v)
                }
                SensorMessage::Magnetometer(mut v) => {
                    scramble(&mut v, a, b, &extremes);
                    SensorMessage::Magnetometer(v)
                }
                SensorMessage::SoundVelocity(mut v) => {
                    scramble(&mut v, a, b, &extremes);
                    SensorMessage::SoundVelocity(v)
                }
                SensorMessage::AcousticRanges(mut v) => {
                    scramble(&mut v, a, b, &extremes);
                    SensorMessage::AcousticRanges(v)
                }
                SensorMessage::AcousticArrayPose(mut v) => {
                    scramble(&mut v, a, b, &extremes);
                    SensorMessage::AcousticArrayPose(v)
                }
            })
        },
        |_, _| {},
    );
    assert!(scrambled > 1000, "{scrambled} messages scrambled");
    let bad = r.solutions.iter().filter(|s| !all_finite(s)).count();
    assert_eq!(bad, 0, "{bad} of {} solutions hold NaN", r.solutions.len());
    assert!(r.solutions.len() > 10_000);
    let c = r.session.navigator().expect("navigating").counters();
    eprintln!(
        "{scrambled} scrambled; {} solutions; invalid: imu {} dvl {} depth {} usbl {} magnetometer {}; clock jumps {}; reinitialisations {}",
        r.solutions.len(),
        c.imu_invalid,
        c.dvl_invalid,
        c.depth_invalid,
        c.usbl_invalid,
        c.magnetometer_invalid,
        c.imu_clock_jumps,
        r.session.reinitialisations
    );
}
