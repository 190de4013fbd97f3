//! One feed path: the same simulated log through `auvnav replay`'s path, through a study's path
//! (a session started by the caller and fed message by message), and in the daemon's batching
//! (per wake-up: the aid messages that arrived, then the IMU samples) gives identical solutions
//! and diagnostics, bit for bit.

use auvnav_core::feed::SensorMessage;
use auvnav_core::session::{Session, SessionConfig, SessionOutput};
use auvnav_core::strapdown::NavState;
use auvnav_log::LogMessage;
use auvnav_shm_schema::{AidDiagnosticsV1, LateAidV1, NavSolutionV1};
use auvnav_sim::{self as sim, SimConfig, scenario::Scenario};
use auvnav_tools::replay::{Output, Replay};

type Outputs = (Vec<NavSolutionV1>, Vec<AidDiagnosticsV1>, Vec<LateAidV1>);

fn messages(scenario: &str, seconds: f64, seed: u64) -> Vec<LogMessage> {
    let scenario = Scenario::load(scenario).expect("scenario");
    let effects = scenario.effects().expect("effects");
    let (m, _) = sim::simulate_to_vec(&SimConfig {
        scenario,
        effects,
        seed,
        duration_s: Some(seconds),
    })
    .expect("simulate");
    m
}

fn start_of(msgs: &[LogMessage]) -> NavState {
    let t = msgs
        .iter()
        .find_map(|m| match m {
            LogMessage::Truth(t) => Some(*t),
            _ => None,
        })
        .expect("truth");
    NavState::from_truth(&t)
}

fn collect(out: &mut Outputs) -> impl FnMut(SessionOutput) -> anyhow::Result<()> + '_ {
    move |o| {
        match o {
            SessionOutput::Solution(s) => out.0.push(*s),
            SessionOutput::Diagnostics(d) => out.1.push(*d),
            SessionOutput::LateAid(r) => out.2.push(*r),
            SessionOutput::Started(_) => {}
        }
        Ok(())
    }
}

/// A study's path: the caller starts the session at the first truth record and feeds every
/// sensor message after it, in log order.
fn study(msgs: &[LogMessage], cfg: &SessionConfig) -> Outputs {
    let mut out = Outputs::default();
    let mut session = Session::new(cfg);
    for m in msgs {
        match m {
            LogMessage::Truth(_) if !session.started() => session
                .start(start_of(msgs), "truth", &mut collect(&mut out))
                .expect("start"),
            m => {
                if let (Some(x), true) = (m.sensor(), session.started()) {
                    session.feed(&x, &mut collect(&mut out)).expect("feed");
                }
            }
        }
    }
    session.finish(&mut collect(&mut out)).expect("finish");
    out
}

/// The daemon's batching: each wake-up delivers the aid messages that arrived since the last one
/// first, then the IMU samples (here: one wake-up per `batch` IMU samples).
fn daemon_batches(msgs: &[LogMessage], cfg: &SessionConfig, batch: usize) -> Outputs {
    let mut out = Outputs::default();
    let mut session = Session::new(cfg);
    let (mut aids, mut imus): (Vec<SensorMessage>, Vec<SensorMessage>) = (vec![], vec![]);
    let flush = |session: &mut Session,
                 aids: &mut Vec<SensorMessage>,
                 imus: &mut Vec<SensorMessage>,
                 out: &mut Outputs| {
        for x in aids.drain(..).chain(imus.drain(..)) {
            session.feed(&x, &mut collect(out)).expect("feed");
        }
    };
    for m in msgs {
        match m {
            LogMessage::Truth(_) if !session.started() => session
                .start(start_of(msgs), "truth", &mut collect(&mut out))
                .expect("start"),
            m => {
                let Some(x) = m.sensor().filter(|_| session.started()) else {
                    continue;
                };
                match x {
                    SensorMessage::Imu(_) => imus.push(x),
                    _ => aids.push(x),
                }
                if imus.len() >= batch {
                    flush(&mut session, &mut aids, &mut imus, &mut out);
                }
            }
        }
    }
    flush(&mut session, &mut aids, &mut imus, &mut out);
    session.finish(&mut collect(&mut out)).expect("finish");
    out
}

fn replay(msgs: &[LogMessage], cfg: &SessionConfig) -> Outputs {
    let mut out = Outputs::default();
    let mut r = Replay::new(cfg, 100.0);
    let mut sink = |o: Output| {
        match o {
            Output::Solution(s) => out.0.push(*s),
            Output::Diagnostics(d) => out.1.push(*d),
            Output::LateAid(r) => out.2.push(*r),
            Output::Truth(_) => {}
        }
        Ok(())
    };
    for m in msgs {
        r.process(m, &mut sink).expect("replay");
    }
    r.finish(&mut sink).expect("finish");
    out
}

/// The messages in the order they would reach a process whose deliveries are each delayed by a
/// random time up to `max_delay_s` (stable for equal arrival times). IMU samples keep their order
/// (one driver publishes them in turn); truth records (not a process's input) arrive at once.
fn arrival_order(msgs: &[LogMessage], max_delay_s: f64, seed: u64) -> Vec<(u64, LogMessage)> {
    let mut rng = sim::rng::Rng::new(seed, "arrival");
    let mut last_imu = 0;
    let mut arrived: Vec<(u64, LogMessage)> = msgs
        .iter()
        .map(|m| {
            let delay_ns = (rng.uniform() * max_delay_s * 1e9) as u64;
            match m {
                LogMessage::Truth(t) => (t.host_time_ns, *m),
                LogMessage::Imu(x) => {
                    last_imu = (x.host_time_ns + delay_ns).max(last_imu);
                    (last_imu, *m)
                }
                m => (m.sensor().map_or(0, |x| x.host_time_ns()) + delay_ns, *m),
            }
        })
        .collect();
    arrived.sort_by_key(|(t, _)| *t);
    arrived
}

fn assert_same(a: &Outputs, b: &Outputs, what: &str) {
    assert!(a.0.len() > 1000, "{what}: {} solutions", a.0.len());
    assert_eq!(a.0.len(), b.0.len(), "{what}: number of solutions");
    assert_eq!(a.1.len(), b.1.len(), "{what}: number of diagnostics");
    assert_eq!(a.2.len(), b.2.len(), "{what}: number of late aids");
    if let Some((i, (x, y))) = a.2.iter().zip(&b.2).enumerate().find(|(_, (x, y))| x != y) {
        panic!("{what}: late aid {i} differs: {x:?} vs {y:?}");
    }
    for (i, (x, y)) in a.0.iter().zip(&b.0).enumerate() {
        assert!(
            bytemuck::bytes_of(x) == bytemuck::bytes_of(y),
            "{what}: solution {i} differs: {x:?} vs {y:?}"
        );
    }
    for (i, (x, y)) in a.1.iter().zip(&b.1).enumerate() {
        assert!(
            bytemuck::bytes_of(x) == bytemuck::bytes_of(y),
            "{what}: diagnostics {i} differ: {x:?} vs {y:?}"
        );
    }
}

#[test]
fn replay_study_and_daemon_batches_give_identical_solutions() {
    let msgs = messages("docking", 240.0, 11);
    let mut cfg = SessionConfig::default();
    let station = sim::StationGeometry::from_scenario(&Scenario::load("docking").expect("s"))
        .expect("the docking scenario has a station");
    cfg.navigation.usbl = Some(station.usbl_config());
    let via_replay = replay(&msgs, &cfg);
    let via_study = study(&msgs, &cfg);
    assert!(
        via_replay.1.iter().any(|d| d.source
            == auvnav_shm_schema::AidSource::UsblSlantRange as u32
            && d.flags & AidDiagnosticsV1::FLAG_FUSED != 0),
        "USBL fixes are fused"
    );
    assert_same(&via_replay, &via_study, "replay vs study");
    // The daemon's aid delay makes the order independent of how messages are batched.
    cfg.aid_delay_s = 0.02;
    let in_log_order = study(&msgs, &cfg);
    for batch in [1, 3, 10] {
        let batched = daemon_batches(&msgs, &cfg, batch);
        assert_same(
            &in_log_order,
            &batched,
            &format!("daemon batches of {batch}"),
        );
    }
}

/// Every aid's `test_ratio` means the same: above 1 = rejected by the gate (a fused message with
/// a ratio above 1 is one the gate let through on purpose, flagged `FLAG_RESET`).
#[test]
fn test_ratio_above_one_means_rejected_for_every_aid() {
    let scenario = Scenario::load("docking").expect("scenario");
    let station = sim::StationGeometry::from_scenario(&scenario).expect("station");
    let mut effects = scenario.effects().expect("effects");
    effects
        .set("usbl.outlier_fraction", &[0.1])
        .expect("outliers");
    let (msgs, _) = sim::simulate_to_vec(&SimConfig {
        scenario,
        effects,
        seed: 12,
        duration_s: Some(240.0),
    })
    .expect("simulate");
    let mut cfg = SessionConfig::default();
    cfg.navigation.usbl = Some(station.usbl_config());
    let (_, diagnostics, _) = replay(&msgs, &cfg);
    let mut rejected_usbl = 0;
    for d in &diagnostics {
        let rejected = d.flags & AidDiagnosticsV1::FLAG_REJECTED != 0;
        let fused = d.flags & AidDiagnosticsV1::FLAG_FUSED != 0;
        let reset = d.flags & AidDiagnosticsV1::FLAG_RESET != 0;
        let gated_out = d.test_ratio > 1.0;
        // Never gated (invalid or late): no innovation variance.
        let gated = d.innovation_variance.iter().any(|v| *v > 0.0);
        assert!(fused != rejected, "source {}: flags {}", d.source, d.flags);
        assert!(
            !(fused && gated_out) || reset,
            "source {}: fused with test ratio {} and no reset flag",
            d.source,
            d.test_ratio
        );
        assert!(
            !(rejected && gated && !gated_out),
            "source {}: rejected by the gate with test ratio {}",
            d.source,
            d.test_ratio
        );
        if rejected && d.source == auvnav_shm_schema::AidSource::UsblSlantRange as u32 {
            rejected_usbl += 1;
        }
    }
    assert!(rejected_usbl > 5, "{rejected_usbl} USBL outliers rejected");
}

/// A log whose messages were written out of time order (each delayed by up to the aid delay, and
/// then by up to half a second) replays exactly as the log in time order.
#[test]
fn replay_of_a_shuffled_log_is_identical() {
    let msgs = messages("lawnmower", 120.0, 21);
    let cfg = SessionConfig {
        aid_delay_s: 0.02,
        ..Default::default()
    };
    let in_order = replay(&msgs, &cfg);
    assert!(in_order.2.is_empty(), "no late aids in time order");
    for (max_delay_s, seed) in [(0.02, 1), (0.5, 2)] {
        let shuffled: Vec<LogMessage> = arrival_order(&msgs, max_delay_s, seed)
            .into_iter()
            .map(|(_, m)| m)
            .collect();
        let moved = shuffled
            .windows(2)
            .filter(|w| match (w[0].sensor(), w[1].sensor()) {
                (Some(a), Some(b)) => a.host_time_ns() > b.host_time_ns(),
                _ => false,
            })
            .count();
        assert!(moved > 100, "{moved} messages out of order");
        assert_same(
            &in_order,
            &replay(&shuffled, &cfg),
            &format!("shuffled by up to {max_delay_s} s"),
        );
    }
}

/// A daemon that received some aids after the IMU had passed their due point applied them late;
/// its late-aid records in the recording make the replay apply them at the same IMU samples, even
/// though the recorder wrote the messages in yet another order.
#[test]
fn replay_applies_the_daemons_late_aids_where_the_daemon_did() {
    let msgs = messages("lawnmower", 120.0, 22);
    let cfg = SessionConfig {
        aid_delay_s: 0.02,
        ..Default::default()
    };
    // The daemon: deliveries delayed by up to 0.1 s (five times the aid delay).
    let mut live = Outputs::default();
    let mut log = Vec::new();
    let mut session = Session::new(&cfg);
    for (arrival, m) in arrival_order(&msgs, 0.1, 3) {
        if let LogMessage::Truth(_) = m {
            if !session.started() {
                session
                    .start(start_of(&msgs), "truth", &mut collect(&mut live))
                    .expect("start");
            }
            continue;
        }
        let Some(x) = m.sensor().filter(|_| session.started()) else {
            continue;
        };
        let before = live.2.len();
        session.feed(&x, &mut collect(&mut live)).expect("feed");
        // The records reach the recorder when the daemon publishes them.
        log.extend(
            live.2[before..]
                .iter()
                .map(|r| (arrival, LogMessage::LateAid(*r))),
        );
    }
    session.finish(&mut collect(&mut live)).expect("finish");
    assert!(live.2.len() > 10, "{} late aids", live.2.len());
    assert_eq!(live.2.len() as u64, session.late_aids);
    // The recorder: the same messages, in its own arrival order, with the records.
    log.extend(arrival_order(&msgs, 0.1, 4));
    log.sort_by_key(|(t, _)| *t);
    let recording: Vec<LogMessage> = log.into_iter().map(|(_, m)| m).collect();
    let replayed = replay(&recording, &cfg);
    // The replay starts at the first truth record, the live session at its start: compare from
    // the start on.
    assert_same(&live, &replayed, "live with late aids vs replay");
    // Without the records, the replay applies every aid in time and differs.
    let without: Vec<LogMessage> = recording
        .into_iter()
        .filter(|m| !matches!(m, LogMessage::LateAid(_)))
        .collect();
    let differs = replay(&without, &cfg);
    assert!(differs.2.is_empty());
    assert!(
        live.0
            .iter()
            .zip(&differs.0)
            .any(|(a, b)| bytemuck::bytes_of(a) != bytemuck::bytes_of(b)),
        "late aids change the solution"
    );
}
