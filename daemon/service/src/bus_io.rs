//! The daemon's loop on the iceoryx2 bus: a subscriber and a listener per sensor topic, one
//! WaitSet with a 50 ms tick, and the publishers of the solution, diagnostics, late-aid records
//! and health (`crate::service` is the loop itself).

use crate::service::{Batch, Inputs, Outputs, Wake};
use auvnav_shm_schema::bus::{
    Bus, BusError, BusPublisher, BusSubscriber, Sequenced, termination_signalled,
};
use auvnav_shm_schema::clock::monotonic_ns;
use auvnav_shm_schema::{
    AcousticArrayPoseV1, AcousticRangesV1, AidDiagnosticsV1, DepthV1, DvlVelocityV1, GnssFixV1,
    ImuSampleV1, LateAidV1, MagnetometerV1, Message, NavSolutionV1, ProcessHealthV1,
    SessionEventV1, SoundVelocityV1, UsblFixV1, qos, topic,
};
use iceoryx2::port::listener::Listener;
use iceoryx2::prelude::*;
use iceoryx2::waitset::{WaitSet, WaitSetGuard, WaitSetRunResult};
use std::time::Duration;

/// The sensor topics, in the order of the listeners.
const TOPICS: [&str; 9] = [
    topic::IMU,
    topic::DVL,
    topic::DEPTH,
    topic::GNSS,
    topic::USBL,
    topic::MAGNETOMETER,
    topic::SOUND_VELOCITY,
    topic::ACOUSTIC_RANGES,
    topic::ACOUSTIC_ARRAY_POSE,
];

fn drain<T: Message + Sequenced>(
    sub: &mut BusSubscriber<T>,
    into: &mut Vec<T>,
) -> Result<(), BusError> {
    while let Some(m) = sub.receive()? {
        into.push(m);
    }
    Ok(())
}

/// The sensor subscribers.
struct Subscribers {
    imu: BusSubscriber<ImuSampleV1>,
    dvl: BusSubscriber<DvlVelocityV1>,
    depth: BusSubscriber<DepthV1>,
    gnss: BusSubscriber<GnssFixV1>,
    usbl: BusSubscriber<UsblFixV1>,
    magnetometer: BusSubscriber<MagnetometerV1>,
    sound_velocity: BusSubscriber<SoundVelocityV1>,
    acoustic_ranges: BusSubscriber<AcousticRangesV1>,
    acoustic_array_pose: BusSubscriber<AcousticArrayPoseV1>,
}

/// Runs the daemon's loop on the bus of `cfg` until SIGTERM or SIGINT.
pub fn run(cfg: &auvnav_core::config::DaemonConfig) -> Result<crate::service::Summary, String> {
    let e = |x: BusError| x.to_string();
    let bus = Bus::new(&cfg.name, &cfg.prefix).map_err(e)?;
    // Resources left by a killed predecessor (or killed drivers) are removed before opening.
    bus.cleanup_dead_nodes();
    let subs = Subscribers {
        imu: bus.subscriber(topic::IMU, qos::SENSOR).map_err(e)?,
        dvl: bus.subscriber(topic::DVL, qos::SENSOR).map_err(e)?,
        depth: bus.subscriber(topic::DEPTH, qos::SENSOR).map_err(e)?,
        gnss: bus.subscriber(topic::GNSS, qos::SENSOR).map_err(e)?,
        usbl: bus.subscriber(topic::USBL, qos::SENSOR).map_err(e)?,
        magnetometer: bus
            .subscriber(topic::MAGNETOMETER, qos::SENSOR)
            .map_err(e)?,
        sound_velocity: bus
            .subscriber(topic::SOUND_VELOCITY, qos::SENSOR)
            .map_err(e)?,
        acoustic_ranges: bus
            .subscriber(topic::ACOUSTIC_RANGES, qos::SENSOR)
            .map_err(e)?,
        acoustic_array_pose: bus
            .subscriber(topic::ACOUSTIC_ARRAY_POSE, qos::SENSOR)
            .map_err(e)?,
    };
    // Every subscriber is connected from here on: a message stamped later was published later
    // (a stamp is never after its publication) and reaches the daemon. The session starts at an
    // IMU sample stamped after this, so that it has every aid stamped after its start, as a
    // replay of the recording does (a subscriber opened before another could otherwise start
    // the session on a sample whose neighbours on the later topic were never received).
    let opened_ns = monotonic_ns();
    let listeners = TOPICS
        .iter()
        .map(|t| bus.listener(t))
        .collect::<Result<Vec<_>, _>>()
        .map_err(e)?;
    let mut outputs = BusOutputs {
        solution: bus
            .publisher(topic::NAV_SOLUTION, qos::NAVIGATION)
            .map_err(e)?,
        diagnostics: bus
            .publisher(topic::NAV_AID_DIAGNOSTICS, qos::NAVIGATION)
            .map_err(e)?,
        late_aids: bus
            .publisher(topic::NAV_LATE_AIDS, qos::NAVIGATION)
            .map_err(e)?,
        session_events: bus
            .publisher(topic::NAV_SESSION_EVENTS, qos::NAVIGATION)
            .map_err(e)?,
        health: bus.publisher(topic::HEALTH, qos::HEALTH).map_err(e)?,
    };
    let waitset = WaitSetBuilder::new()
        .create::<ipc::Service>()
        .map_err(|x| format!("creating the WaitSet: {x:?}"))?;
    let guards = listeners
        .iter()
        .map(|l| waitset.attach_notification(l))
        .collect::<Result<Vec<_>, _>>()
        .map_err(|x| format!("attaching a listener: {x:?}"))?;
    let _tick = waitset
        .attach_interval(Duration::from_millis(50))
        .map_err(|x| format!("attaching the tick: {x:?}"))?;
    let mut inputs = BusInputs {
        bus: &bus,
        subs,
        listeners: &listeners,
        waitset: &waitset,
        guards: &guards,
        notified: [false; TOPICS.len()],
        opened_ns,
    };
    // Ready for the service manager: the configuration was read and the bus is open (STOPPING
    // is sent when the bus is dropped).
    bus.ready(&format!(
        "on the bus under {}/; waiting for the IMU",
        cfg.prefix
    ));
    crate::service::run(cfg, &mut inputs, &mut outputs)
}

struct BusInputs<'a, 'g> {
    bus: &'a Bus,
    subs: Subscribers,
    listeners: &'a [Listener<ipc::Service>],
    waitset: &'a WaitSet<ipc::Service>,
    guards: &'g [WaitSetGuard<'a, 'a, ipc::Service>],
    /// Which topics notified at the last wake-up.
    notified: [bool; TOPICS.len()],
    /// When the last subscriber was connected (host ns): IMU samples stamped earlier are not
    /// used.
    opened_ns: u64,
}

impl Inputs for BusInputs<'_, '_> {
    fn supervise(&mut self, status: Option<&str>) {
        self.bus.keep_alive();
        if let Some(s) = status {
            self.bus.status(s);
        }
    }

    fn wait(&mut self) -> Result<Wake, String> {
        loop {
            // Which topics notified: only their listeners are read (one system call each, plus
            // the one that finds them empty), not all of them on every wake-up.
            let mut notified = [false; TOPICS.len()];
            let r = self.waitset.wait_and_process_once(|id| {
                for (n, g) in notified.iter_mut().zip(self.guards) {
                    *n |= id.has_event_from(g);
                }
                CallbackProgression::Continue
            });
            self.notified = notified;
            return match r {
                Ok(WaitSetRunResult::TerminationRequest) => Ok(Wake::Stop),
                // Another signal interrupted the wait: a stop only if SIGTERM or SIGINT came
                // before it (systemd sends SIGCONT right after SIGTERM).
                Ok(WaitSetRunResult::Interrupt) if termination_signalled() => Ok(Wake::Stop),
                // SIGCONT after a stop, a debugger's: not a request to stop.
                Ok(WaitSetRunResult::Interrupt) => continue,
                Ok(_) if termination_signalled() => Ok(Wake::Stop),
                Ok(_) => Ok(Wake::Run),
                Err(x) => Err(format!("waiting: {x:?}")),
            };
        }
    }

    fn take(&mut self, batch: &mut Batch) -> Result<(), String> {
        for (l, _) in self.listeners.iter().zip(self.notified).filter(|(_, n)| *n) {
            let _ = l.try_wait(|_| {});
        }
        // Aids first, so that IMU samples arriving in the same wake-up find them queued.
        let s = &mut self.subs;
        (|| -> Result<(), BusError> {
            drain(&mut s.dvl, &mut batch.dvl)?;
            drain(&mut s.depth, &mut batch.depth)?;
            drain(&mut s.gnss, &mut batch.gnss)?;
            drain(&mut s.usbl, &mut batch.usbl)?;
            drain(&mut s.magnetometer, &mut batch.magnetometer)?;
            drain(&mut s.sound_velocity, &mut batch.sound_velocity)?;
            drain(&mut s.acoustic_ranges, &mut batch.acoustic_ranges)?;
            drain(&mut s.acoustic_array_pose, &mut batch.acoustic_array_pose)?;
            drain(&mut s.imu, &mut batch.imu)?;
            Ok(())
        })()
        .map_err(|x| x.to_string())?;
        let n = batch.imu.len();
        batch.imu.retain(|m| m.host_time_ns >= self.opened_ns);
        if batch.imu.len() < n {
            tracing::info!(
                "auvnavd: {} IMU samples stamped before every topic was subscribed not used",
                n - batch.imu.len()
            );
        }
        Ok(())
    }

    fn now_ns(&self) -> u64 {
        monotonic_ns()
    }

    fn gaps(&self) -> u64 {
        let s = &self.subs;
        s.imu.gaps() + s.dvl.gaps() + s.depth.gaps() + s.gnss.gaps()
    }

    fn housekeeping(&mut self) {
        self.bus.cleanup_dead_nodes();
    }
}

struct BusOutputs {
    solution: BusPublisher<NavSolutionV1>,
    diagnostics: BusPublisher<AidDiagnosticsV1>,
    late_aids: BusPublisher<LateAidV1>,
    session_events: BusPublisher<SessionEventV1>,
    health: BusPublisher<ProcessHealthV1>,
}

impl Outputs for BusOutputs {
    fn solution(&mut self, s: &NavSolutionV1) -> bool {
        self.solution.publish(*s).is_ok()
    }
    fn diagnostics(&mut self, d: &AidDiagnosticsV1) -> bool {
        self.diagnostics.publish(*d).is_ok()
    }
    fn late_aid(&mut self, r: &LateAidV1) -> bool {
        self.late_aids.publish(*r).is_ok()
    }
    fn session_event(&mut self, e: &SessionEventV1) -> bool {
        self.session_events.publish(*e).is_ok()
    }
    fn health(&mut self, h: &ProcessHealthV1) -> Result<(), String> {
        self.health
            .publish(*h)
            .map(|_| ())
            .map_err(|x| x.to_string())
    }
}
