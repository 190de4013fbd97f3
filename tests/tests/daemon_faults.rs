//! Faults of the on-board chain, as real processes: a driver killed with SIGKILL is reported lost
//! by the daemon, which keeps navigating (degraded) and fuses again when the driver is restarted;
//! SIGCONT (and a SIGSTOP/SIGCONT pair) stops none of the processes; a killed daemon is replaced by
//! a new one that continues from the checkpoint (not from `[initial]`) with its covariance grown,
//! while the drivers and the recorder keep running.

use auvnav_log::{LogMessage, LogReader};
use auvnav_shm_schema::bus::Bus;
use auvnav_shm_schema::{NavMode, NavSolutionV1, ProcessHealthV1, ProcessState, qos, topic};
use auvnav_tests::processes::{Proc, TempDir, binary, signal, unique};
use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::{Duration, Instant};

/// Horizontal distance between two solutions (m).
fn distance(a: &NavSolutionV1, b: &NavSolutionV1) -> f64 {
    let g = |s: &NavSolutionV1| auvnav_core::earth::Geodetic {
        latitude_rad: s.latitude_rad,
        longitude_rad: s.longitude_rad,
        height_m: s.height_m,
    };
    let e = auvnav_core::earth::ned_offset(&g(a), &g(b));
    e.x.hypot(e.y)
}

fn driver_config(dir: &Path, prefix: &str, class: &str, protocol: &str) -> PathBuf {
    let p = dir.join(format!("{class}.toml"));
    std::fs::write(
        &p,
        format!(
            "prefix = \"{prefix}\"\nprotocol = \"{protocol}\"\n[serial]\nport = \"{}\"\n\
             [settings.kvh]\nincrements = false\ndegrees = false\nrate_hz = 200.0\ntemperature_centi = false\n\
             [timing]\nreconnect_initial_s = 0.02\nreconnect_max_s = 0.2\nhealth_period_s = 0.2\n",
            dir.join("dev").join(class).display()
        ),
    )
    .expect("config");
    p
}

fn spawn(dir: &Path, name: &str, bin: &str, args: &[&str]) -> Proc {
    let err = std::fs::File::create(dir.join(format!("{name}.err"))).expect("stderr");
    Proc::spawn(name, Command::new(binary(bin)).args(args).stderr(err)).expect("spawn")
}

struct Watch {
    solutions: Vec<(Instant, NavSolutionV1)>,
    health: Vec<(Instant, ProcessHealthV1)>,
}

impl Watch {
    fn poll(
        &mut self,
        sol: &mut auvnav_shm_schema::bus::BusSubscriber<NavSolutionV1>,
        health: &mut auvnav_shm_schema::bus::BusSubscriber<ProcessHealthV1>,
        for_: Duration,
    ) {
        let end = Instant::now() + for_;
        while Instant::now() < end {
            while let Some(m) = sol.receive().expect("receive") {
                self.solutions.push((Instant::now(), m));
            }
            while let Some(h) = health.receive().expect("receive") {
                self.health.push((Instant::now(), h));
            }
            std::thread::sleep(Duration::from_millis(2));
        }
    }
    fn solutions_since(&self, t: Instant) -> Vec<&NavSolutionV1> {
        self.solutions
            .iter()
            .filter(|(at, _)| *at >= t)
            .map(|(_, s)| s)
            .collect()
    }
    fn health_since(&self, t: Instant, name: &str) -> Vec<&ProcessHealthV1> {
        self.health
            .iter()
            .filter(|(at, h)| *at >= t && h.name() == name)
            .map(|(_, h)| h)
            .collect()
    }
}

#[test]
// Long on purpose: one scenario with real processes read top to bottom: each step depends on the
// state the previous one left.
fn killed_driver_degrades_and_recovers_and_a_killed_daemon_is_replaced() {
    let dir = TempDir::new("daemonfault");
    let d = dir.path();
    let prefix = unique("dfault");
    // 60 s of voyage at 2x: 30 s of playing, more than the scenario below needs.
    let voyage = d.join("voyage.mcap");
    let o = Command::new(binary("auvnav"))
        .args([
            "sim",
            "--scenario",
            "lawnmower",
            "--duration",
            "60",
            "--out",
        ])
        .arg(&voyage)
        .output()
        .expect("sim");
    assert!(o.status.success());
    let mut r = LogReader::open(&voyage).expect("log");
    let t0 = loop {
        if let LogMessage::Truth(t) = r
            .next_message()
            .expect("read")
            .expect("truth")
            .decode_any()
            .expect("decode")
        {
            break t;
        }
    };
    let [roll, pitch, yaw] = t0.euler_rad.map(f64::to_degrees);
    let daemon_cfg = d.join("auvnavd.toml");
    std::fs::write(
        &daemon_cfg,
        format!(
            "prefix = \"{prefix}\"\nhealth_period_s = 0.2\n[navigation]\nimu_dt_from_device_time = true\n\
             dvl_timeout_s = 1.0\n[initial]\nlatitude_deg = {:?}\nlongitude_deg = {:?}\nheight_m = {:?}\n\
             velocity_ned_m_s = {:?}\neuler_deg = [{roll:?}, {pitch:?}, {yaw:?}]\n[deadlines]\ndvl_s = 0.5\n\
             [checkpoint]\npath = \"{}\"\ninterval_s = 0.5\n",
            t0.latitude_rad.to_degrees(),
            t0.longitude_rad.to_degrees(),
            t0.height_m,
            t0.velocity_ned_m_s,
            d.join("auvnavd.checkpoint.json").display()
        ),
    )
    .expect("daemon config");
    let dvl_cfg = driver_config(d, &prefix, "dvl", "wldvl");
    let imu_cfg = driver_config(d, &prefix, "imu", "kvh1750");
    let bus = Bus::new(&unique("dfaulttest"), &prefix).expect("bus");
    let mut sol = bus
        .subscriber::<NavSolutionV1>(topic::NAV_SOLUTION, qos::NAVIGATION)
        .expect("sub");
    let mut health = bus
        .subscriber::<ProcessHealthV1>(topic::HEALTH, qos::HEALTH)
        .expect("sub");
    let record = d.join("record.mcap");
    let mut recorder = spawn(
        d,
        "record",
        "auvnav",
        &[
            "record",
            "--out",
            record.to_str().expect("utf-8"),
            "--prefix",
            &prefix,
        ],
    );
    let cfg = daemon_cfg.to_str().expect("utf-8");
    let mut daemon = spawn(d, "auvnavd", "auvnavd", &["--config", cfg]);
    let mut dvl = spawn(
        d,
        "dvl",
        "auvnav-dvl",
        &["--config", dvl_cfg.to_str().expect("utf-8")],
    );
    let mut imu = spawn(
        d,
        "imu",
        "auvnav-imu",
        &["--config", imu_cfg.to_str().expect("utf-8")],
    );
    let mut emulator = spawn(
        d,
        "emulate",
        "auvnav",
        &[
            "emulate",
            voyage.to_str().expect("utf-8"),
            "--dvl",
            "wldvl",
            "--imu",
            "kvh1750",
            "--speed",
            "2",
            "--start-delay",
            "1",
            "--link-dir",
            d.join("dev").to_str().expect("utf-8"),
        ],
    );
    let mut w = Watch {
        solutions: vec![],
        health: vec![],
    };
    let mode = |s: &NavSolutionV1| s.nav_mode().ok();
    // Running and aided.
    w.poll(&mut sol, &mut health, Duration::from_secs(4));
    assert!(
        w.solutions
            .iter()
            .any(|(_, s)| mode(s) == Some(NavMode::Navigating)),
        "no aided solution in the first seconds"
    );
    // 1. Kill the DVL driver.
    dvl.kill();
    let killed = Instant::now();
    w.poll(&mut sol, &mut health, Duration::from_secs(3));
    let after = w.solutions_since(killed);
    assert!(
        after.len() > 500,
        "the daemon stopped navigating: {} solutions",
        after.len()
    );
    assert!(
        after.iter().any(|s| mode(s) == Some(NavMode::Degraded)),
        "the daemon did not degrade without DVL"
    );
    let dh = w.health_since(killed, "auvnavd");
    let before_timeouts = w
        .health
        .iter()
        .filter(|(t, h)| *t < killed && h.name() == "auvnavd")
        .map(|(_, h)| h.timeouts)
        .max()
        .unwrap_or(0);
    assert!(
        dh.iter().any(|h| h.timeouts > before_timeouts),
        "the daemon did not report the DVL lost"
    );
    // 2. Restart it: the daemon fuses DVL again.
    let restarted = Instant::now();
    let mut dvl2 = spawn(
        d,
        "dvl2",
        "auvnav-dvl",
        &["--config", dvl_cfg.to_str().expect("utf-8")],
    );
    w.poll(&mut sol, &mut health, Duration::from_secs(3));
    let back = w.solutions_since(restarted);
    assert_eq!(
        back.last().and_then(|s| mode(s)),
        Some(NavMode::Navigating),
        "not navigating again after the DVL driver came back"
    );
    // 3. SIGCONT alone, and a SIGSTOP/SIGCONT pair, stop nothing.
    for p in [&daemon, &imu, &dvl2, &recorder] {
        signal(p, "-CONT");
        signal(p, "-HUP");
    }
    signal(&daemon, "-STOP");
    std::thread::sleep(Duration::from_millis(200));
    signal(&daemon, "-CONT");
    let continued = Instant::now();
    w.poll(&mut sol, &mut health, Duration::from_secs(1));
    for p in [&mut daemon, &mut imu, &mut dvl2, &mut recorder] {
        let st = p.child.try_wait();
        assert!(
            matches!(st, Ok(None)),
            "{} stopped after SIGCONT and SIGHUP ({st:?}): {}",
            p.name,
            std::fs::read_to_string(d.join(format!("{}.err", p.name))).unwrap_or_default()
        );
    }
    assert!(
        w.solutions_since(continued).len() > 100,
        "the daemon does not publish after SIGCONT"
    );
    // 4. Kill the daemon; a new one continues from the checkpoint while the drivers and the
    // recorder run on.
    let last_before = w.solutions.last().expect("solutions").1;
    daemon.kill();
    let daemon_killed = Instant::now();
    w.poll(&mut sol, &mut health, Duration::from_millis(500));
    let mut daemon2 = spawn(d, "auvnavd2", "auvnavd", &["--config", cfg]);
    let started = Instant::now();
    w.poll(&mut sol, &mut health, Duration::from_secs(2));
    let resumed = w.solutions_since(started);
    assert!(resumed.len() > 100, "the new daemon does not publish");
    let first = resumed[0];
    let sigma = first.position_std_ned_m[0].max(first.position_std_ned_m[1]);
    // Down for about 0.5 s at a drift of 2.5 m/s (the default), plus up to 0.5 s since the
    // checkpoint: the covariance grew by at least that.
    assert!(
        sigma >= 1.0,
        "the restarted daemon publishes a sigma of {sigma:.2} m"
    );
    let moved = distance(first, &last_before);
    assert!(
        moved <= 3.0 * sigma,
        "the restarted daemon starts {moved:.1} m from where the killed one was (sigma {sigma:.2} m)"
    );
    let initial = {
        let mut s = *first;
        s.latitude_rad = t0.latitude_rad;
        s.longitude_rad = t0.longitude_rad;
        s
    };
    assert!(
        distance(first, &initial) > 10.0,
        "the restarted daemon started from [initial]"
    );
    let log = std::fs::read_to_string(d.join("auvnavd2.err")).unwrap_or_default();
    assert!(
        log.contains("continuing from the checkpoint"),
        "the restarted daemon does not say it continues from the checkpoint: {log}"
    );
    assert!(
        w.health_since(started, "auvnavd")
            .iter()
            .any(|h| h.state == ProcessState::Running as u32),
        "the new daemon is not running"
    );
    for name in ["imu", "dvl"] {
        assert!(
            w.health_since(daemon_killed, name)
                .iter()
                .any(|h| h.state == ProcessState::Running as u32),
            "{name} driver did not keep running"
        );
    }
    assert!(
        matches!(recorder.child.try_wait(), Ok(None)),
        "the recorder stopped"
    );
    // 5. Clean stop of everything still running.
    let _ = emulator.terminate(Duration::from_secs(5));
    for p in [&mut dvl2, &mut imu, &mut daemon2, &mut recorder] {
        let status = p.terminate(Duration::from_secs(10));
        assert!(
            status.is_some_and(|s| s.success()),
            "{} did not stop cleanly",
            p.name
        );
    }
    // The recording spans the faults and is complete.
    let mut r = LogReader::open(&record).expect("record");
    r.read_header().expect("header");
    let mut n = 0;
    while r.next_message().expect("complete log").is_some() {
        n += 1;
    }
    assert!(n > 2000, "{n} messages recorded");
}
