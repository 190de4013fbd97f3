//! Water track and currents: a survey in a 0.3 m/s current whose DVL loses bottom lock for about
//! 30 % of the time in 60 s blocks and reports water track with every ping. With the
//! water-current states (`water_current_std_m_s`) the filter learns the current while both
//! tracks arrive and navigates on the water when bottom lock is lost; without them it coasts on
//! the IMU. Run in process through the same `Session` the daemon and replay use. The current is
//! judged while bottom lock holds, from 10 s after each recovery (and after the first 10 s).

use auvnav_core::earth::{self, Geodetic};
use auvnav_core::feed::SensorMessage;
use auvnav_core::session::{Session, SessionOutput};
use auvnav_log::LogMessage;
use auvnav_shm_schema::{DvlVelocityV1, NavSolutionV1, TruthStateV1};
use auvnav_sim::{SimConfig, scenario::Scenario};
use auvnav_tests::grade::{self, MEMS, TACTICAL};

/// The IMU a run carries: the lawnmower's own navigation-grade FOG, a tactical unit, or an
/// industrial MEMS unit (with the magnetometer for its heading).
#[derive(Debug, Clone, Copy, PartialEq)]
enum Imu {
    Fog,
    Tactical,
    Mems,
}
use auvnav_tools::demo::{DemoStart, session_config};

/// North and east of the simulated current (|c| = 0.3 m/s).
const CURRENT: [f64; 2] = [0.18, -0.24];

fn voyage(seed: u64, imu: Imu) -> (SimConfig, Vec<LogMessage>) {
    voyage_with(seed, imu, 0.3 / (0.7 * 60.0))
}

fn voyage_with(seed: u64, imu: Imu, loss_rate: f64) -> (SimConfig, Vec<LogMessage>) {
    let scenario = Scenario::load("lawnmower").expect("scenario");
    let mut effects = scenario.effects().expect("effects");
    match imu {
        Imu::Fog => {}
        Imu::Tactical => TACTICAL.set_imu(&mut effects),
        Imu::Mems => MEMS.set_imu(&mut effects),
    }
    effects
        .set("water.current", &CURRENT)
        .expect("water.current");
    effects
        .set("dvl.water_track_noise", &[0.01])
        .expect("water track noise");
    // Losses of 60 s at a rate that keeps lock lost about 30 % of the time:
    // r D / (1 + r D) = 0.3 with D = 60 s.
    effects
        .set("dvl.bottom_lock_loss_rate", &[loss_rate])
        .expect("loss rate");
    effects
        .set("dvl.bottom_lock_loss_duration", &[60.0])
        .expect("loss duration");
    let cfg = SimConfig {
        scenario,
        effects,
        seed,
        duration_s: Some(900.0),
    };
    let messages = grade::simulate(&cfg);
    (cfg, messages)
}

/// What one navigation run gives: horizontal errors at the truth epochs, the current estimate
/// while bottom lock held, and the position steps when lock came back (in σ of the horizontal
/// position before).
#[derive(Debug, Default)]
struct Run {
    errors_m: Vec<f64>,
    /// Horizontal error at each loss of bottom lock and at its recovery (m).
    loss_errors_m: Vec<(f64, f64)>,
    current_error_while_locked: Vec<f64>,
    recovery_steps_sigma: Vec<f64>,
    locked_fraction: f64,
    water_track_fused: u64,
    lock_lost: u64,
    lock_regained: u64,
}

fn horizontal(a: &Geodetic, b: &Geodetic) -> f64 {
    let d = earth::ned_offset(a, b);
    d.x.hypot(d.y)
}

fn position(s: &NavSolutionV1) -> Geodetic {
    Geodetic {
        latitude_rad: s.latitude_rad,
        longitude_rad: s.longitude_rad,
        height_m: s.height_m,
    }
}

fn navigate(cfg: &SimConfig, messages: &[LogMessage], current_std: f64, imu: Imu) -> Run {
    let first: TruthStateV1 = messages
        .iter()
        .find_map(|m| match m {
            LogMessage::Truth(t) => Some(*t),
            _ => None,
        })
        .expect("truth");
    let mut session_cfg = session_config(cfg, DemoStart::Known, imu == Imu::Mems, &first);
    session_cfg.navigation.water_current_std_m_s = current_std;
    match imu {
        Imu::Fog => {}
        Imu::Tactical => TACTICAL.configure(&mut session_cfg.navigation),
        Imu::Mems => MEMS.configure(&mut session_cfg.navigation),
    }
    let mut session = Session::new(&session_cfg);
    let mut run = Run::default();
    let mut last: Option<NavSolutionV1> = None;
    let mut locked = true;
    // Time of the last bottom-lock recovery (ns): the current is judged once lock has held 10 s.
    let mut locked_since_ns = 0u64;
    let mut loss_start_error: Option<f64> = None;
    let (mut locked_epochs, mut epochs) = (0u64, 0u64);
    // A recovery: the solution before the first valid bottom track after a loss, and that
    // reading's time of validity.
    let mut recovery: Option<(NavSolutionV1, u64)> = None;
    for m in messages {
        match m {
            LogMessage::Truth(t) => {
                let Some(s) = last else { continue };
                let truth = Geodetic {
                    latitude_rad: t.latitude_rad,
                    longitude_rad: t.longitude_rad,
                    height_m: t.height_m,
                };
                let e = horizontal(&truth, &position(&s));
                run.errors_m.push(e);
                epochs += 1;
                if !locked && loss_start_error.is_none() {
                    loss_start_error = Some(e);
                }
                if locked && let Some(e0) = loss_start_error.take() {
                    run.loss_errors_m.push((e0, e));
                }
                if locked {
                    locked_epochs += 1;
                    if let Some(n) = session.navigator()
                        && let Some((c, _)) = n.water_current()
                        && t.host_time_ns > locked_since_ns + 10_000_000_000
                    {
                        run.current_error_while_locked
                            .push((c[0] - CURRENT[0]).hypot(c[1] - CURRENT[1]));
                    }
                }
            }
            other => {
                let Some(sensor) = other.sensor() else {
                    continue;
                };
                if let SensorMessage::Dvl(d) = &sensor
                    && !d.is_water_track()
                {
                    let valid = d.validity & DvlVelocityV1::VALID_VELOCITY != 0;
                    if valid && !locked {
                        locked_since_ns = d.validity_time_ns;
                        if let Some(b) = last {
                            recovery = Some((b, d.validity_time_ns));
                        }
                    }
                    locked = valid;
                }
                let mut out = |o: SessionOutput| -> Result<(), ()> {
                    if let SessionOutput::Solution(s) = o {
                        last = Some(*s);
                    }
                    Ok(())
                };
                session.feed(&sensor, &mut out).expect("feed");
                // The first solution with the recovering bottom track applied (an aid is
                // applied before the first IMU sample after its time): its position against
                // the one before, carried forward by the velocity over the interval.
                if let (Some((b, t_ns)), Some(a)) = (recovery, last)
                    && a.host_time_ns > t_ns
                {
                    let dt = (a.host_time_ns - b.host_time_ns) as f64 * 1e-9;
                    let d = earth::ned_offset(&position(&b), &position(&a));
                    let (n, e) = (
                        d.x - b.velocity_ned_m_s[0] * dt,
                        d.y - b.velocity_ned_m_s[1] * dt,
                    );
                    let sigma = b.position_std_ned_m[0].hypot(b.position_std_ned_m[1]);
                    run.recovery_steps_sigma.push(n.hypot(e) / sigma.max(1e-6));
                    recovery = None;
                }
            }
        }
    }
    let n = session.navigator().expect("navigating").counters();
    run.water_track_fused = n.dvl_water_track_fused;
    run.lock_lost = n.dvl_bottom_lock_lost;
    run.lock_regained = n.dvl_bottom_lock_regained;
    run.locked_fraction = locked_epochs as f64 / epochs.max(1) as f64;
    run
}

/// The mean horizontal error a loss of bottom lock adds: |error at recovery − error at the loss|.
fn loss_growth(r: &Run) -> f64 {
    r.loss_errors_m
        .iter()
        .map(|(a, b)| (b - a).abs())
        .sum::<f64>()
        / r.loss_errors_m.len().max(1) as f64
}

fn rms(v: &[f64]) -> f64 {
    (v.iter().map(|x| x * x).sum::<f64>() / v.len().max(1) as f64).sqrt()
}

fn compare(seed: u64, imu: Imu) -> (Run, Run) {
    let (cfg, messages) = voyage(seed, imu);
    let with = navigate(&cfg, &messages, 0.5, imu);
    let without = navigate(&cfg, &messages, 0.0, imu);
    let (e_with, e_without) = (rms(&with.errors_m), rms(&without.errors_m));
    let current_max = with
        .current_error_while_locked
        .iter()
        .cloned()
        .fold(0.0, f64::max);
    let step_max = with
        .recovery_steps_sigma
        .iter()
        .cloned()
        .fold(0.0, f64::max);
    eprintln!(
        "{} IMU, seed {seed}: bottom lock held {:.0} % of the time ({} losses, {} recoveries); \
         horizontal error RMS {e_with:.3} m with water track, {e_without:.3} m without; error \
         added per loss {:.3} m with water track, {:.3} m without; \
         current error while locked max {current_max:.4} m/s; recovery steps max \
         {step_max:.2} sigma over {} recoveries; {} water-track velocities fused",
        match imu {
            Imu::Fog => "navigation-grade",
            Imu::Tactical => "tactical",
            Imu::Mems => "MEMS",
        },
        100.0 * with.locked_fraction,
        with.lock_lost,
        with.lock_regained,
        loss_growth(&with),
        loss_growth(&without),
        with.recovery_steps_sigma.len(),
        with.water_track_fused
    );
    assert!(
        (0.5..0.9).contains(&with.locked_fraction),
        "{}",
        with.locked_fraction
    );
    assert!(with.lock_lost >= 2 && with.lock_regained >= 2);
    assert!(with.water_track_fused > 1000);
    assert_eq!(without.water_track_fused, 0);
    assert!(!with.current_error_while_locked.is_empty());
    assert!(current_max < 0.05, "current error {current_max} m/s");
    assert!(!with.recovery_steps_sigma.is_empty());
    assert!(step_max < 3.0, "{:?}", with.recovery_steps_sigma);
    (with, without)
}

/// The error the losses add (position error is not observable afterwards without a position
/// aid, so what a loss adds stays): with water track at most a third of the IMU's alone.
#[test]
fn water_track_carries_a_tactical_ins_through_lost_bottom_lock_in_a_current() {
    let (with, without) = compare(7702, Imu::Tactical);
    let (g_with, g_without) = (loss_growth(&with), loss_growth(&without));
    assert!(with.loss_errors_m.len() >= 3, "{:?}", with.loss_errors_m);
    assert!(
        g_with <= g_without / 3.0,
        "error added per loss: with water track {g_with} m, without {g_without} m"
    );
}

/// With the lawnmower's navigation-grade INS a minute without the DVL costs little; water track
/// must not make it worse.
#[test]
fn water_track_does_not_degrade_a_navigation_grade_ins() {
    let (with, without) = compare(7703, Imu::Fog);
    let (e_with, e_without) = (rms(&with.errors_m), rms(&without.errors_m));
    assert!(
        e_with <= 1.05 * e_without,
        "with water track {e_with} m, without {e_without} m"
    );
    assert!(loss_growth(&with) <= 1.1 * loss_growth(&without) + 0.05);
}

/// With an industrial MEMS IMU (heading from the magnetometer) a minute without the DVL costs
/// metres: over the whole survey the horizontal error with water track is at most a third of the
/// error without it.
#[test]
fn water_track_keeps_a_mems_ins_within_a_third_of_its_coasting_error() {
    let (with, without) = compare(7704, Imu::Mems);
    let (e_with, e_without) = (rms(&with.errors_m), rms(&without.errors_m));
    assert!(
        e_with <= e_without / 3.0,
        "horizontal error RMS with water track {e_with} m, without {e_without} m"
    );
}
