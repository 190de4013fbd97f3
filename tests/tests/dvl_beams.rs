//! Beam-level DVL fusion: one beam blocked for 40 % of a survey (30 s spells), during which the
//! DVL reports only its three other beams and no instrument velocity. With the beam geometry
//! configured (`dvl_beam_fusion`) the three beams still aid and the navigation stays within 20 %
//! of the four-beam run's; without it the INS coasts through every spell. A tactical-grade IMU,
//! on which half a minute without the DVL shows. Run in process through `Session`.

use auvnav_core::earth::{self, Geodetic};
use auvnav_core::session::{Session, SessionOutput};
use auvnav_log::LogMessage;
use auvnav_shm_schema::{NavSolutionV1, TruthStateV1};
use auvnav_sim::{SimConfig, scenario::Scenario};
use auvnav_tests::grade::{self, TACTICAL};
use auvnav_tools::demo::{DemoStart, session_config};

fn voyage(seed: u64, blocked_fraction: f64) -> (SimConfig, Vec<LogMessage>) {
    if blocked_fraction > 0.0 {
        voyage_with(
            seed,
            900.0,
            &[
                ("dvl.beam_blocked", &[2.0]),
                ("dvl.beam_blocked_fraction", &[blocked_fraction]),
            ],
        )
    } else {
        voyage_with(seed, 900.0, &[])
    }
}

/// The lawnmower with the tactical IMU and `effects`, `seconds` long.
fn voyage_with(
    seed: u64,
    seconds: f64,
    effects: &[(&str, &[f64])],
) -> (SimConfig, Vec<LogMessage>) {
    let scenario = Scenario::load("lawnmower").expect("scenario");
    let mut e = scenario.effects().expect("effects");
    TACTICAL.set_imu(&mut e);
    for (name, value) in effects {
        e.set(name, value).expect("effect");
    }
    let cfg = SimConfig {
        scenario,
        effects: e,
        seed,
        duration_s: Some(seconds),
    };
    let messages = grade::simulate(&cfg);
    (cfg, messages)
}

/// What a run gives: RMS horizontal error at the truth epochs, readings fused from beams, beams
/// refused by their gate, and the share of DVL readings that had no instrument velocity.
struct Outcome {
    rms_m: f64,
    fused: u64,
    beams_rejected: u64,
    share_without_velocity: f64,
    /// Readings solved again from their corrected beams.
    corrected: u64,
}

fn navigate(cfg: &SimConfig, messages: &[LogMessage], beam_fusion: bool) -> Outcome {
    navigate_with(cfg, messages, |n| n.dvl_beam_fusion = beam_fusion)
}

fn navigate_with(
    cfg: &SimConfig,
    messages: &[LogMessage],
    configure: impl FnOnce(&mut auvnav_core::config::NavConfig),
) -> Outcome {
    let first: TruthStateV1 = messages
        .iter()
        .find_map(|m| match m {
            LogMessage::Truth(t) => Some(*t),
            _ => None,
        })
        .expect("truth");
    let mut c = session_config(cfg, DemoStart::Known, false, &first);
    TACTICAL.configure(&mut c.navigation);
    configure(&mut c.navigation);
    let mut session = Session::new(&c);
    let mut last: Option<NavSolutionV1> = None;
    let (mut sum, mut epochs) = (0.0, 0u64);
    let (mut dvl, mut without_velocity) = (0u64, 0u64);
    for m in messages {
        match m {
            LogMessage::Truth(t) => {
                let Some(s) = last else { continue };
                let d = earth::ned_offset(
                    &Geodetic {
                        latitude_rad: t.latitude_rad,
                        longitude_rad: t.longitude_rad,
                        height_m: t.height_m,
                    },
                    &Geodetic {
                        latitude_rad: s.latitude_rad,
                        longitude_rad: s.longitude_rad,
                        height_m: s.height_m,
                    },
                );
                sum += d.x * d.x + d.y * d.y;
                epochs += 1;
            }
            other => {
                let Some(sensor) = other.sensor() else {
                    continue;
                };
                if let LogMessage::Dvl(d) = other {
                    dvl += 1;
                    without_velocity += u64::from(
                        d.validity & auvnav_shm_schema::DvlVelocityV1::VALID_VELOCITY == 0,
                    );
                }
                let mut out = |o: SessionOutput| -> Result<(), ()> {
                    if let SessionOutput::Solution(s) = o {
                        last = Some(*s);
                    }
                    Ok(())
                };
                session.feed(&sensor, &mut out).expect("feed");
            }
        }
    }
    let c = session.navigator().expect("navigating").counters();
    Outcome {
        rms_m: (sum / epochs.max(1) as f64).sqrt(),
        fused: c.dvl_beam_readings_fused,
        beams_rejected: c.dvl_beams_rejected,
        share_without_velocity: without_velocity as f64 / dvl.max(1) as f64,
        corrected: c.dvl_beam_corrected,
    }
}

#[test]
fn three_beams_still_aid_while_one_is_blocked() {
    let (clean_cfg, clean) = voyage(8811, 0.0);
    let (blocked_cfg, blocked) = voyage(8811, 0.4);
    let e_four = navigate(&clean_cfg, &clean, true).rms_m;
    let with = navigate(&blocked_cfg, &blocked, true);
    let (e_beams, fused, share) = (with.rms_m, with.fused, with.share_without_velocity);
    let coast = navigate(&blocked_cfg, &blocked, false);
    let (e_coast, none) = (coast.rms_m, coast.fused);
    // One beam gone wrong by 0.5 m/s in every tenth three-beam reading: refused alone, the
    // other beams fused.
    let mut spoiled = blocked.clone();
    let mut n_spoiled = 0u64;
    for m in &mut spoiled {
        if let LogMessage::Dvl(d) = m
            && d.validity & auvnav_shm_schema::DvlVelocityV1::VALID_VELOCITY == 0
            && d.beams_used == 3
        {
            n_spoiled += 1;
            if n_spoiled.is_multiple_of(10) {
                d.beam_velocity_m_s[2] += 0.5;
            }
        }
    }
    let bad = navigate(&blocked_cfg, &spoiled, true);
    eprintln!(
        "a 0.5 m/s error on beam 3 in {} readings: {} beams refused, {} readings fused, error RMS {:.3} m",
        n_spoiled / 10,
        bad.beams_rejected,
        bad.fused,
        bad.rms_m
    );
    assert!(
        bad.beams_rejected >= n_spoiled / 10,
        "{}",
        bad.beams_rejected
    );
    assert_eq!(
        bad.fused, fused,
        "the other beams of a spoiled reading still aid"
    );
    assert!(bad.rms_m <= 1.2 * e_four);
    eprintln!(
        "beam 2 blocked in {:.0} % of the DVL readings: horizontal error RMS {e_beams:.3} m \
         with beam fusion ({fused} readings fused from three beams), {e_coast:.3} m without; \
         four beams {e_four:.3} m",
        100.0 * share
    );
    assert!((0.25..0.55).contains(&share), "{share}");
    assert!(fused > 100);
    assert_eq!(none, 0);
    assert!(
        e_beams <= 1.2 * e_four,
        "beam fusion {e_beams} m against four beams {e_four} m"
    );
    assert!(e_coast > e_beams, "{e_coast} {e_beams}");
}

/// A 2 % scale error on beam 2 of a DVL that solves its velocity from its four beams: the device
/// averages it into all three axes and the navigation drifts. `discover --dvl-beams` on a separate
/// calibration voyage (its own seed, 500 s) estimates it; with the estimate in `[navigation.dvl]`
/// the navigator solves each reading again from the corrected beams, and the survey's error
/// returns to the clean survey's: at least 80 % of the error the beam adds is removed.
#[test]
fn a_beams_scale_error_is_estimated_and_corrected_not_averaged_in() {
    use auvnav_tools::discover::command::{Collector, discover_messages_with, values_of};
    const HIDDEN: [f64; 4] = [0.0, 20_000.0, 0.0, 0.0];
    let (_, calibration) = voyage_with(8821, 500.0, &[("dvl.beam_scale_factor", &HIDDEN)]);
    let report = discover_messages_with(Collector::new().with_dvl_beams(true), &calibration);
    let found = report
        .effects
        .iter()
        .find(|e| e.name == "dvl.beam_scale_factor")
        .expect("the beam's scale found");
    let v = values_of(&found.value).expect("values");
    let estimate: [f64; 4] = std::array::from_fn(|i| v[i]);
    let (clean_cfg, clean) = voyage_with(8822, 900.0, &[]);
    let (cfg, spoiled) = voyage_with(8822, 900.0, &[("dvl.beam_scale_factor", &HIDDEN)]);
    let e_clean = navigate(&clean_cfg, &clean, false).rms_m;
    let e_spoiled = navigate(&cfg, &spoiled, false).rms_m;
    let fixed = navigate_with(&cfg, &spoiled, |n| {
        let mut d = n.dvl_installation();
        d.beam_scale_factor_ppm = estimate;
        n.set_dvl_installation(d);
    });
    eprintln!(
        "beam 2 scale 20 000 ppm, estimated {estimate:.0?} ppm: horizontal error RMS {:.3} m \
         corrected ({} readings), {e_spoiled:.3} m as the device averages it, {e_clean:.3} m clean",
        fixed.rms_m, fixed.corrected
    );
    assert!(fixed.corrected > 1000, "{}", fixed.corrected);
    assert!(
        fixed.rms_m <= 1.2 * e_clean,
        "corrected {} m against clean {e_clean} m",
        fixed.rms_m
    );
    // On a lawnmower the legs run both ways, so much of a constant velocity error cancels in
    // position: judged on the error the beam adds over the clean survey.
    let removed = 1.0 - (fixed.rms_m - e_clean).max(0.0) / (e_spoiled - e_clean);
    eprintln!(
        "the correction removes {:.0} % of the error the beam adds",
        100.0 * removed
    );
    assert!(
        e_spoiled > 1.5 * e_clean,
        "{e_spoiled} m against clean {e_clean} m"
    );
    assert!(removed >= 0.8, "{removed}");
}
