//! Serial drivers as real processes against emulated devices on pseudo-terminals:
//! `auvnav emulate` → pty → `auvnav-dvl`/`-imu`/`-usbl` → iceoryx2 → this test's subscribers.
//! Checks that values and counts match what was played, that garbage and corrupted frames are
//! counted and never published, and that an unplugged device is reported and reconnected.
//!
//! Long on purpose: the drivers against real pseudo-terminals, one test per device and failure,
//! sharing the harness at the top.

use auvnav_log::{LogMessage, LogReader};
use auvnav_shm_schema::bus::Bus;
use auvnav_shm_schema::{
    DvlVelocityV1, ImuSampleV1, MagnetometerV1, ProcessHealthV1, ProcessState, UsblFixV1, qos,
    topic,
};
use auvnav_tests::processes::{Proc, TempDir, binary, unique};
use serde_json::Value;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

/// Seconds of simulated voyage played per test.
const SECONDS: f64 = 8.0;
/// Playback speed.
const SPEED: f64 = 4.0;

#[derive(Default)]
struct Collected {
    imu: Vec<ImuSampleV1>,
    dvl: Vec<DvlVelocityV1>,
    usbl: Vec<UsblFixV1>,
    magnetometer: Vec<MagnetometerV1>,
    health: Vec<ProcessHealthV1>,
}

struct Played {
    /// Every message of the log, in order.
    messages: Vec<LogMessage>,
    imu: Vec<ImuSampleV1>,
    dvl: Vec<DvlVelocityV1>,
    usbl: Vec<UsblFixV1>,
    magnetometer: Vec<MagnetometerV1>,
}

fn simulate(dir: &Path) -> (PathBuf, Played) {
    simulate_for(dir, SECONDS)
}

/// `seconds` of the docking scenario.
fn simulate_for(dir: &Path, seconds: f64) -> (PathBuf, Played) {
    let log = dir.join("voyage.mcap");
    let out = Command::new(binary("auvnav"))
        .args(["sim", "--scenario", "docking", "--duration"])
        .arg(seconds.to_string())
        .arg("--out")
        .arg(&log)
        .output()
        .expect("running auvnav sim");
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let mut reader = LogReader::open(&log).expect("opening the log");
    let mut played = Played {
        messages: vec![],
        imu: vec![],
        dvl: vec![],
        usbl: vec![],
        magnetometer: vec![],
    };
    while let Some(raw) = reader.next_message().expect("reading the log") {
        let m = raw.decode_any().expect("decoding");
        played.messages.push(m);
        match m {
            LogMessage::Imu(m) => played.imu.push(m),
            LogMessage::Dvl(m) => played.dvl.push(m),
            LogMessage::Usbl(m) => played.usbl.push(m),
            LogMessage::Magnetometer(m) => played.magnetometer.push(m),
            _ => {}
        }
    }
    (log, played)
}

fn write_config(dir: &Path, prefix: &str, class: &str, protocol: &str) -> PathBuf {
    let path = dir.join(format!("{class}.toml"));
    let text = format!(
        r#"prefix = "{prefix}"
protocol = "{protocol}"
[serial]
port = "{port}"
baud = 921600
[settings]
xsens_rate_hz = 200.0
[settings.kvh]
increments = false
degrees = false
rate_hz = 200.0
temperature_centi = false
[timing]
read_timeout_s = 0.02
silence_timeout_s = 0.5
reconnect_initial_s = 0.02
reconnect_max_s = 0.2
health_period_s = 0.1
"#,
        port = dir.join("links").join(class).display()
    );
    std::fs::write(&path, text).expect("writing a driver config");
    path
}

struct Outcome {
    got: Collected,
    summary: Vec<Value>,
    events: Vec<Value>,
    stderr: String,
}

/// Starts the drivers, then the emulator with `faults`, collects everything published until the
/// emulator has finished, stops the drivers with SIGTERM and checks they exit cleanly.
fn play(dir: &Path, log: &Path, devices: &[(&str, &str)], faults: &[&str]) -> Outcome {
    play_at(dir, log, devices, faults, SPEED)
}

/// [`play`] at `speed` times real time.
fn play_at(
    dir: &Path,
    log: &Path,
    devices: &[(&str, &str)],
    faults: &[&str],
    speed: f64,
) -> Outcome {
    let prefix = unique("pty");
    let bus = Bus::new(&unique("ptytest"), &prefix).expect("bus");
    let mut imu = bus
        .subscriber::<ImuSampleV1>(topic::IMU, qos::SENSOR)
        .expect("imu");
    let mut dvl = bus
        .subscriber::<DvlVelocityV1>(topic::DVL, qos::SENSOR)
        .expect("dvl");
    let mut usbl = bus
        .subscriber::<UsblFixV1>(topic::USBL, qos::SENSOR)
        .expect("usbl");
    let mut magnetometer = bus
        .subscriber::<MagnetometerV1>(topic::MAGNETOMETER, qos::SENSOR)
        .expect("magnetometer");
    let mut health = bus
        .subscriber::<ProcessHealthV1>(topic::HEALTH, qos::HEALTH)
        .expect("health");
    let mut drivers: Vec<Proc> = devices
        .iter()
        .map(|(class, protocol)| {
            let cfg = write_config(dir, &prefix, class, protocol);
            let err = std::fs::File::create(dir.join(format!("{class}.err"))).expect("stderr");
            Proc::spawn(
                class,
                Command::new(binary(&format!("auvnav-{class}")))
                    .arg("--config")
                    .arg(cfg)
                    .stderr(err),
            )
            .expect("spawn")
        })
        .collect();
    let mut emulate = Command::new(binary("auvnav"));
    emulate
        .arg("emulate")
        .arg(log)
        .args([
            "--speed",
            &speed.to_string(),
            "--start-delay",
            "1.0",
            "--json",
        ])
        .arg("--link-dir")
        .arg(dir.join("links"))
        .args(faults)
        .stdout(Stdio::from(
            std::fs::File::create(dir.join("emulate.out")).expect("stdout"),
        ))
        .stderr(Stdio::from(
            std::fs::File::create(dir.join("emulate.err")).expect("stderr"),
        ));
    for (class, protocol) in devices {
        emulate.arg(format!("--{class}")).arg(protocol);
    }
    let mut emulator = Proc::spawn("emulate", &mut emulate).expect("spawn");
    let mut got = Collected::default();
    let mut drain = |got: &mut Collected| {
        while let Some(m) = imu.receive().expect("receive") {
            got.imu.push(m);
        }
        while let Some(m) = dvl.receive().expect("receive") {
            got.dvl.push(m);
        }
        while let Some(m) = usbl.receive().expect("receive") {
            got.usbl.push(m);
        }
        while let Some(m) = magnetometer.receive().expect("receive") {
            got.magnetometer.push(m);
        }
        while let Some(m) = health.receive().expect("receive") {
            got.health.push(m);
        }
    };
    // Watchdog: the whole run takes SECONDS / SPEED plus start-up; give it ample margin.
    let deadline = Instant::now() + Duration::from_secs(60);
    let mut finished_at = None;
    loop {
        drain(&mut got);
        if finished_at.is_none()
            && let Ok(Some(status)) = emulator.child.try_wait()
        {
            assert!(
                status.success(),
                "emulator failed: {}",
                std::fs::read_to_string(dir.join("emulate.err")).unwrap_or_default()
            );
            finished_at = Some(Instant::now());
        }
        if finished_at.is_some_and(|t| t.elapsed() > Duration::from_millis(500)) {
            break;
        }
        assert!(Instant::now() < deadline, "the run did not finish in 60 s");
        std::thread::sleep(Duration::from_millis(2));
    }
    for d in &mut drivers {
        let status = d.terminate(Duration::from_secs(10));
        assert!(
            status.is_some_and(|s| s.success()),
            "{} did not stop cleanly on SIGTERM: {status:?}",
            d.name
        );
    }
    std::thread::sleep(Duration::from_millis(50));
    drain(&mut got);
    let out = std::fs::read_to_string(dir.join("emulate.out")).expect("emulator output");
    let lines: Vec<Value> = out
        .lines()
        .map(|l| serde_json::from_str(l).expect("emulator JSON line"))
        .collect();
    let summary = lines
        .iter()
        .find(|l| l["event"] == "summary")
        .expect("summary line")["devices"]
        .as_array()
        .expect("devices")
        .clone();
    let stderr = devices
        .iter()
        .map(|(c, _)| std::fs::read_to_string(dir.join(format!("{c}.err"))).unwrap_or_default())
        .collect::<Vec<_>>()
        .join("");
    Outcome {
        got,
        summary,
        events: lines,
        stderr,
    }
}

fn device<'a>(summary: &'a [Value], name: &str) -> &'a Value {
    summary
        .iter()
        .find(|d| d["device"] == name)
        .unwrap_or_else(|| panic!("{name} in the summary"))
}

fn count(v: &Value, key: &str) -> usize {
    v[key].as_u64().unwrap_or_else(|| panic!("{key}")) as usize
}

fn last_health(got: &Collected, name: &str) -> ProcessHealthV1 {
    *got.health
        .iter()
        .rev()
        .find(|h| h.name() == name)
        .unwrap_or_else(|| panic!("no health from {name}"))
}

fn close(a: f64, b: f64, tol: f64) -> bool {
    (a - b).abs() <= tol
}

#[test]
fn drivers_publish_what_the_emulated_devices_played() {
    let dir = TempDir::new("ptyvalues");
    let (log, played) = simulate(dir.path());
    let o = play(
        dir.path(),
        &log,
        &[("dvl", "wldvl"), ("imu", "kvh1750"), ("usbl", "seatrac")],
        &[],
    );
    let now = auvnav_drivers::clock::monotonic_ns();
    // Every message played arrives once, in order, with its values.
    for (name, n_got, n_played) in [
        ("imu", o.got.imu.len(), played.imu.len()),
        ("dvl", o.got.dvl.len(), played.dvl.len()),
        ("usbl", o.got.usbl.len(), played.usbl.len()),
    ] {
        let d = device(&o.summary, name);
        assert_eq!(count(d, "written"), n_played, "{name}: all played");
        assert_eq!(n_got, n_played, "{name}: received\n{}", o.stderr);
        let h = last_health(&o.got, name);
        assert_eq!(h.frames as usize, n_played, "{name}: health frames");
        assert_eq!(h.checksum_errors + h.invalid + h.bytes_skipped, 0, "{name}");
        assert_eq!(
            h.state,
            ProcessState::Stopping as u32,
            "{name}: final state"
        );
    }
    for (g, p) in o.got.imu.iter().zip(&played.imu) {
        assert_eq!(g.device_time_ns, p.device_time_ns);
        for i in 0..3 {
            assert!(close(
                g.angular[i],
                p.angular[i],
                1e-7 * p.angular[i].abs() + 1e-12
            ));
            assert!(close(
                g.specific[i],
                p.specific[i],
                1e-6 * p.specific[i].abs()
            ));
        }
        assert_eq!(g.interval_s, 1.0 / 200.0);
        // Stamped by the host clock at read return: recent, not the log's time.
        assert!(g.host_time_ns <= now && now - g.host_time_ns < 60_000_000_000);
    }
    for w in o.got.imu.windows(2) {
        assert_eq!(w[1].sequence, w[0].sequence + 1, "publisher sequence");
        assert!(w[1].host_time_ns >= w[0].host_time_ns);
    }
    for (g, p) in o.got.dvl.iter().zip(&played.dvl) {
        assert_eq!(
            g.validity & DvlVelocityV1::VALID_VELOCITY,
            p.validity & DvlVelocityV1::VALID_VELOCITY
        );
        for i in 0..3 {
            assert!(close(
                g.velocity_dvl_m_s[i],
                p.velocity_dvl_m_s[i],
                0.0005 + 1e-9
            ));
        }
        assert!(close(g.altitude_m, p.altitude_m, 0.005 + 1e-9));
    }
    for (g, p) in o.got.usbl.iter().zip(&played.usbl) {
        assert!(close(g.slant_range_m, p.slant_range_m, 0.05 + 1e-9));
        assert!(close(
            g.azimuth_rad,
            p.azimuth_rad,
            0.05f64.to_radians() + 1e-9
        ));
        assert!(close(
            g.elevation_rad,
            p.elevation_rad,
            0.05f64.to_radians() + 1e-9
        ));
    }
}

#[test]
fn garbage_is_counted_never_published_and_an_unplugged_device_comes_back() {
    let dir = TempDir::new("ptyfaults");
    let (log, played) = simulate(dir.path());
    let o = play(
        dir.path(),
        &log,
        &[("dvl", "pd0"), ("imu", "xsens")],
        &[
            "--corrupt",
            "0.02",
            "--garbage",
            "0.05",
            "--seed",
            "7",
            "--unplug",
            "dvl,3,1.5",
            "--pause",
            "imu,4,3",
        ],
    );
    let dvl = device(&o.summary, "dvl");
    let imu = device(&o.summary, "imu");
    assert!(count(imu, "corrupted") > 0 && count(imu, "garbage_bytes") > 0);
    assert!(count(dvl, "unplugged") > 0 && count(imu, "paused") > 0);
    // Exactly the intact frames are published: corrupted ones and garbage never are. The Xsens
    // sends the magnetic field in packets of its own, published on the magnetometer topic.
    assert!(!played.magnetometer.is_empty() && !o.got.magnetometer.is_empty());
    assert_eq!(
        o.got.imu.len() + o.got.magnetometer.len(),
        count(imu, "written"),
        "{}",
        o.stderr
    );
    assert_eq!(o.got.dvl.len(), count(dvl, "written"), "{}", o.stderr);
    // And each published message is one that was played (matched by the device clock).
    for g in &o.got.imu {
        let p = played
            .imu
            .iter()
            .find(|p| p.device_time_ns / 100_000 == g.device_time_ns / 100_000)
            .expect("an IMU message that was played");
        for i in 0..3 {
            assert!(close(
                g.specific[i],
                p.specific[i],
                1e-6 * p.specific[i].abs()
            ));
        }
    }
    for g in &o.got.dvl {
        let p = played
            .dvl
            .iter()
            .find(|p| p.device_time_ns / 10_000_000 == g.device_time_ns / 10_000_000)
            .expect("a DVL message that was played");
        for i in 0..3 {
            assert!(close(
                g.velocity_dvl_m_s[i],
                p.velocity_dvl_m_s[i],
                0.0005 + 1e-9
            ));
        }
    }
    for g in &o.got.magnetometer {
        let p = played
            .magnetometer
            .iter()
            .find(|p| p.device_time_ns / 100_000 == g.device_time_ns / 100_000)
            .expect("a magnetometer message that was played");
        assert_eq!(g.validity, p.validity);
        for i in 0..3 {
            assert!(
                close(g.field_t[i], p.field_t[i], 1e-6 * 60e-6),
                "{g:?} {p:?}"
            );
        }
    }
    // The corrupted frames are counted as checksum errors; garbage as skipped bytes.
    let hi = last_health(&o.got, "imu");
    assert!(
        hi.checksum_errors as usize >= count(imu, "corrupted"),
        "{hi:?}"
    );
    assert!(hi.bytes_skipped > 0);
    assert_eq!(
        hi.frames as usize,
        o.got.imu.len() + o.got.magnetometer.len()
    );
    // The pause (3 s of log = 0.75 s at 4x, beyond the 0.5 s silence timeout) is reported as a
    // timeout and the reconnecting state while data had been flowing, then running again. (The
    // drivers also see a silence before the emulator starts playing.)
    let reported_then_recovered = |name: &str, key: fn(&ProcessHealthV1) -> u64| {
        let h: Vec<_> = o.got.health.iter().filter(|h| h.name() == name).collect();
        let running = ProcessState::Running as u32;
        let reconnecting = ProcessState::Reconnecting as u32;
        h.windows(3)
            .any(|w| w[0].state == running && w[1].state == reconnecting && key(w[1]) > key(w[0]))
            && h.iter()
                .any(|x| x.state == running && key(x) > 0 && x.frames > 0)
    };
    assert!(
        reported_then_recovered("imu", |h| h.timeouts),
        "imu silence not reported"
    );
    // The unplug: the driver lost the port, reported it, and reopened it when it came back.
    let hd = last_health(&o.got, "dvl");
    assert!(hd.reconnects >= 1, "{hd:?}\n{}", o.stderr);
    let dvl_health: Vec<_> = o.got.health.iter().filter(|h| h.name() == "dvl").collect();
    let lost = dvl_health
        .iter()
        .position(|h| h.state == ProcessState::Reconnecting as u32 && h.frames > 0)
        .expect("the unplug reported as reconnecting");
    assert!(
        dvl_health[lost..]
            .iter()
            .any(|h| h.state == ProcessState::Running as u32 && h.reconnects >= 1),
        "the DVL driver did not come back"
    );
    assert!(
        o.events
            .iter()
            .any(|e| e["event"] == "replugged" && e["device"] == "dvl")
    );
    // Messages after the replug arrived (the emulator stamps log time; 3 + 1.5 s).
    assert!(o.got.dvl.iter().any(|g| {
        played.dvl.iter().any(|p| {
            p.device_time_ns / 10_000_000 == g.device_time_ns / 10_000_000
                && p.host_time_ns - played.dvl[0].host_time_ns > 4_600_000_000
        })
    }));
}

#[test]
fn a_nortek_dvl_on_a_pty_publishes_what_was_played() {
    let dir = TempDir::new("ptynortek");
    let (log, played) = simulate(dir.path());
    let o = play(dir.path(), &log, &[("dvl", "nortek")], &[]);
    let d = device(&o.summary, "dvl");
    assert_eq!(count(d, "written"), played.dvl.len(), "all played");
    assert_eq!(o.got.dvl.len(), played.dvl.len(), "received\n{}", o.stderr);
    let h = last_health(&o.got, "dvl");
    assert_eq!(h.frames as usize, played.dvl.len(), "health frames");
    assert_eq!(h.checksum_errors + h.invalid + h.bytes_skipped, 0);
    for (g, p) in o.got.dvl.iter().zip(&played.dvl) {
        assert_eq!(
            g.validity & DvlVelocityV1::VALID_VELOCITY,
            p.validity & DvlVelocityV1::VALID_VELOCITY
        );
        // Nortek records carry f32 values.
        for i in 0..3 {
            assert!(close(
                g.velocity_dvl_m_s[i],
                p.velocity_dvl_m_s[i],
                1e-6 * p.velocity_dvl_m_s[i].abs() + 1e-9
            ));
        }
        if p.validity & DvlVelocityV1::VALID_ALTITUDE != 0 {
            assert!(close(
                g.altitude_m,
                p.altitude_m,
                1e-5 * p.altitude_m + 1e-9
            ));
        }
        assert_ne!(g.validity & DvlVelocityV1::VALID_SOUND_SPEED, 0);
        assert_ne!(g.validity & DvlVelocityV1::VALID_DEVICE_TIME, 0);
    }
}

/// Seconds of the voyage played in every PD0 coordinate system: a straight leg at 60°, a turn
/// and a depth change (heading, pitch and roll all move).
const COORDINATE_SECONDS: f64 = 150.0;
/// Its playback speed.
const COORDINATE_SPEED: f64 = 25.0;

/// The same voyage from an emulated PD0 DVL in instrument, beam and earth coordinates, through the
/// real driver: the velocities from the beams (RDI's beam transformation) and from east, north,
/// up (rotated back with the heading, pitch and roll the ensemble records) equal the
/// instrument-coordinate ones within the 1 mm/s resolution and equal what was played; and the
/// voyage navigated on each (through the same `Session` the daemon runs, with the played IMU)
/// ends where the instrument-coordinate one does, within what that resolution allows over the
/// run.
#[test]
fn pd0_in_beam_and_earth_coordinates_navigates_as_instrument_coordinates_do() {
    let dir = TempDir::new("ptypd0coords");
    let (log, played) = simulate_for(dir.path(), COORDINATE_SECONDS);
    let runs: Vec<(&str, Outcome)> = ["instrument", "beam", "earth"]
        .into_iter()
        .map(|c| {
            let o = play_at(
                dir.path(),
                &log,
                &[("dvl", "pd0")],
                &["--pd0-coordinates", c],
                COORDINATE_SPEED,
            );
            (c, o)
        })
        .collect();
    for (name, o) in &runs {
        assert_eq!(o.got.dvl.len(), played.dvl.len(), "{name}\n{}", o.stderr);
        let h = last_health(&o.got, "dvl");
        assert_eq!(h.checksum_errors + h.invalid + h.bytes_skipped, 0, "{name}");
    }
    let instrument = &runs[0].1;
    let flag = DvlVelocityV1::VALID_VELOCITY;
    for (name, o) in &runs[1..] {
        let mut valid = 0;
        for ((i, g), p) in instrument.got.dvl.iter().zip(&o.got.dvl).zip(&played.dvl) {
            assert_eq!(g.validity & flag, p.validity & flag, "{name}");
            assert_eq!(i.validity & flag, p.validity & flag);
            if p.validity & flag == 0 {
                continue;
            }
            valid += 1;
            for k in 0..3 {
                assert!(
                    close(g.velocity_dvl_m_s[k], i.velocity_dvl_m_s[k], 0.002),
                    "{name} {:?} against instrument {:?}",
                    g.velocity_dvl_m_s,
                    i.velocity_dvl_m_s
                );
                assert!(close(g.velocity_dvl_m_s[k], p.velocity_dvl_m_s[k], 0.002));
            }
        }
        assert!(valid > 100, "{name}: {valid}");
    }
    // Navigation on each: final position against the instrument-coordinate run's.
    let ends: Vec<(&str, [f64; 3], f64)> = runs
        .iter()
        .map(|(name, o)| {
            let (end, rms) = navigate(&played, &o.got.dvl);
            eprintln!("{name}: end {end:?}, horizontal RMS error {rms:.3} m");
            (*name, end, rms)
        })
        .collect();
    // 1 mm/s of resolution over the run, on each of the two.
    let bound = 2.0 * 0.001 * COORDINATE_SECONDS;
    for (name, end, rms) in &ends[1..] {
        let d = auvnav_core::earth::ned_offset(&geodetic(ends[0].1), &geodetic(*end));
        let horizontal = d.x.hypot(d.y);
        eprintln!("{name}: end {horizontal:.4} m from the instrument-coordinate run's");
        assert!(
            horizontal < bound,
            "{name}: {horizontal} m (bound {bound} m)"
        );
        assert!(
            (rms - ends[0].2).abs() < bound,
            "{name}: RMS {rms} against {}",
            ends[0].2
        );
    }
}

fn geodetic(p: [f64; 3]) -> auvnav_core::earth::Geodetic {
    auvnav_core::earth::Geodetic {
        latitude_rad: p[0],
        longitude_rad: p[1],
        height_m: p[2],
    }
}

/// The played voyage navigated with its DVL readings replaced by what the driver published (at
/// the played times, so that only the conversion differs): the final position (rad, rad, m) and
/// the horizontal RMS error against the truth.
fn navigate(played: &Played, dvl: &[DvlVelocityV1]) -> ([f64; 3], f64) {
    use auvnav_core::feed::SensorMessage;
    use auvnav_core::session::{Session, SessionOutput};
    use auvnav_sim::{SimConfig, scenario::Scenario};
    use auvnav_tools::demo::{DemoStart, session_config};
    let first = played
        .messages
        .iter()
        .find_map(|m| match m {
            LogMessage::Truth(t) => Some(*t),
            _ => None,
        })
        .expect("truth");
    let scenario = Scenario::load("docking").expect("scenario");
    let cfg = SimConfig {
        effects: scenario.effects().expect("effects"),
        scenario,
        seed: 0,
        duration_s: None,
    };
    let mut session = Session::new(&session_config(&cfg, DemoStart::Known, false, &first));
    let mut received = dvl.iter();
    let mut last = None;
    let (mut sum, mut n) = (0.0, 0usize);
    for m in &played.messages {
        if let LogMessage::Truth(t) = m {
            if let Some(s) = &last {
                let s: &auvnav_shm_schema::NavSolutionV1 = s;
                let d = auvnav_core::earth::ned_offset(
                    &geodetic([t.latitude_rad, t.longitude_rad, t.height_m]),
                    &geodetic([s.latitude_rad, s.longitude_rad, s.height_m]),
                );
                sum += d.x * d.x + d.y * d.y;
                n += 1;
            }
            continue;
        }
        let Some(mut sensor) = m.sensor() else {
            continue;
        };
        if let SensorMessage::Dvl(p) = &mut sensor {
            let got = received.next().expect("a reading per played one");
            let (host, validity) = (p.host_time_ns, p.validity_time_ns);
            *p = *got;
            p.host_time_ns = host;
            p.validity_time_ns = validity;
        }
        session
            .feed(&sensor, &mut |o: SessionOutput| -> Result<(), ()> {
                if let SessionOutput::Solution(s) = o {
                    last = Some(*s);
                }
                Ok(())
            })
            .expect("feed");
    }
    let s = last.expect("a solution");
    (
        [s.latitude_rad, s.longitude_rad, s.height_m],
        (sum / n.max(1) as f64).sqrt(),
    )
}
