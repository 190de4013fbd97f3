//! `auvnavd`'s loop (`auvnavd::service::run`) driven by canned messages and a clock of the
//! test's own, without the bus: the wake-ups of a live run (50 ms of messages each) give the same
//! solutions as the messages fed straight to a session, the decimation, deadlines and health
//! behave as configured, and the last health message says the daemon stopped.

use auvnav_core::config::{DaemonConfig, InitialState};
use auvnav_core::session::{Session, SessionOutput};
use auvnav_log::LogMessage;
use auvnav_shm_schema::{
    AidDiagnosticsV1, LateAidV1, NavSolutionV1, ProcessHealthV1, ProcessState,
};
use auvnav_sim::{SimConfig, scenario::Scenario};
use auvnavd::service::{Batch, Inputs, Outputs, Wake, run};

/// Wake-ups of 50 ms of messages each, the clock at each wake-up's end, then stop.
struct Canned {
    batches: std::collections::VecDeque<(u64, Batch)>,
    now_ns: u64,
    pending: Option<Batch>,
}

impl Inputs for Canned {
    fn wait(&mut self) -> Result<Wake, String> {
        match self.batches.pop_front() {
            Some((now, b)) => {
                self.now_ns = now;
                self.pending = Some(b);
                Ok(Wake::Run)
            }
            None => Ok(Wake::Stop),
        }
    }
    fn take(&mut self, batch: &mut Batch) -> Result<(), String> {
        if let Some(b) = self.pending.take() {
            *batch = b;
        }
        Ok(())
    }
    fn now_ns(&self) -> u64 {
        self.now_ns
    }
    fn gaps(&self) -> u64 {
        0
    }
}

#[derive(Default)]
struct Collected {
    solutions: Vec<NavSolutionV1>,
    diagnostics: usize,
    late: usize,
    health: Vec<ProcessHealthV1>,
}

impl Outputs for Collected {
    fn solution(&mut self, s: &NavSolutionV1) -> bool {
        self.solutions.push(*s);
        true
    }
    fn diagnostics(&mut self, _: &AidDiagnosticsV1) -> bool {
        self.diagnostics += 1;
        true
    }
    fn late_aid(&mut self, _: &LateAidV1) -> bool {
        self.late += 1;
        true
    }
    fn session_event(&mut self, _: &auvnav_shm_schema::SessionEventV1) -> bool {
        true
    }
    fn health(&mut self, h: &ProcessHealthV1) -> Result<(), String> {
        self.health.push(*h);
        Ok(())
    }
}

#[test]
fn the_daemon_loop_on_canned_messages_navigates_as_the_session_does() {
    let scenario = Scenario::load("lawnmower").expect("scenario");
    let effects = scenario.effects().expect("effects");
    let (messages, _) = auvnav_sim::simulate_to_vec(&SimConfig {
        scenario,
        effects,
        seed: 4401,
        duration_s: Some(120.0),
    })
    .expect("simulation");
    let first = messages
        .iter()
        .find_map(|m| match m {
            LogMessage::Truth(t) => Some(*t),
            _ => None,
        })
        .expect("truth");
    let start = auvnav_core::strapdown::truth_position(&first);
    let mut cfg = DaemonConfig {
        initial: Some(InitialState {
            latitude_deg: start.latitude_rad.to_degrees(),
            longitude_deg: start.longitude_rad.to_degrees(),
            height_m: start.height_m,
            velocity_ned_m_s: first.velocity_ned_m_s,
            euler_deg: first.euler_rad.map(f64::to_degrees),
        }),
        ..Default::default()
    };
    cfg.output.solution_decimation = 4;
    let sensors: Vec<_> = messages
        .iter()
        .filter_map(LogMessage::sensor)
        .filter(|m| m.host_time_ns() >= first.host_time_ns)
        .collect();

    // The session fed straight, in the messages' order.
    let mut straight = Vec::new();
    let mut session = Session::new(&cfg.session());
    for m in &sensors {
        let Ok(()) = session.feed(m, &mut |o| {
            if let SessionOutput::Solution(s) = o {
                straight.push(*s);
            }
            Ok::<(), std::convert::Infallible>(())
        });
    }
    let Ok(()) = session.finish(&mut |o| {
        if let SessionOutput::Solution(s) = o {
            straight.push(*s);
        }
        Ok::<(), std::convert::Infallible>(())
    });

    // The same messages as a live daemon takes them: 50 ms wake-ups; the DVL falls silent from
    // 60 to 70 s (longer than its 3 s deadline) and comes back.
    const WAKE_NS: u64 = 50_000_000;
    let silent = (first.host_time_ns + 60_000_000_000)..(first.host_time_ns + 70_000_000_000);
    let mut batches = std::collections::VecDeque::new();
    let mut batch = Batch::default();
    let mut end = first.host_time_ns + WAKE_NS;
    for m in &sensors {
        while m.host_time_ns() >= end {
            batches.push_back((end, std::mem::take(&mut batch)));
            end += WAKE_NS;
        }
        use auvnav_core::feed::SensorMessage as S;
        match *m {
            S::Imu(x) => batch.imu.push(x),
            S::Dvl(x) if !silent.contains(&x.host_time_ns) => batch.dvl.push(x),
            S::Dvl(_) => {}
            S::Depth(x) => batch.depth.push(x),
            S::Gnss(x) => batch.gnss.push(x),
            S::Usbl(x) => batch.usbl.push(x),
            S::Magnetometer(x) => batch.magnetometer.push(x),
            S::SoundVelocity(x) => batch.sound_velocity.push(x),
            S::AcousticRanges(x) => batch.acoustic_ranges.push(x),
            S::AcousticArrayPose(x) => batch.acoustic_array_pose.push(x),
        }
    }
    batches.push_back((end, batch));
    let wakeups = batches.len();
    let mut inputs = Canned {
        batches,
        now_ns: first.host_time_ns,
        pending: None,
    };
    let mut out = Collected::default();
    let summary = run(&cfg, &mut inputs, &mut out).expect("the loop");

    assert!(straight.len() > 20_000, "{} solutions", straight.len());
    // The DVL's silence changes the navigation from 60 s on; before it, wake-ups or not, the
    // daemon computes what the session fed straight computes, bit for bit.
    let before_silence = straight
        .iter()
        .filter(|s| s.host_time_ns < silent.start)
        .count();
    let published_before = out
        .solutions
        .iter()
        .filter(|s| s.host_time_ns < silent.start)
        .count();
    assert_eq!(published_before, before_silence.div_ceil(4));
    for (k, s) in out.solutions[..published_before].iter().enumerate() {
        assert_eq!(
            bytemuck::bytes_of(s),
            bytemuck::bytes_of(&straight[4 * k]),
            "solution {k} differs from the session's"
        );
    }
    assert_eq!(summary.solutions as usize, straight.len());
    assert_eq!(summary.published as usize, out.solutions.len());
    assert_eq!(summary.published, summary.solutions.div_ceil(4));
    assert_eq!(summary.errors, 0);
    assert_eq!(
        out.late, 0,
        "50 ms wake-ups with aids first make no late aid"
    );
    assert!(out.diagnostics > 100);
    // One deadline missed: the DVL's silence (and nothing else).
    assert_eq!(summary.missed_deadlines, 1);
    // Health once a second of the test's clock, then the stop.
    let last = out.health.last().expect("health");
    assert_eq!(last.state, ProcessState::Stopping as u32);
    assert_eq!(last.frames, summary.published);
    assert!(last.timeouts >= 1, "{last:?}");
    let running = out
        .health
        .iter()
        .filter(|h| h.state == ProcessState::Running as u32)
        .count();
    let seconds = wakeups as f64 * 0.05;
    assert!(
        (running as f64 - seconds).abs() <= 2.0,
        "{running} health messages over {seconds} s"
    );
}
