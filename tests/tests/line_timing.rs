//! A driver's time stamps against a line's timing: `auvnav emulate --baud` paces the devices'
//! bytes on pseudo-terminals and writes when each frame's first byte was on the line
//! (`--send-times`); the real drivers stamp what they read, and this test compares.
//!
//! - A slow line (SeaTrac at 9600 baud, about 100 ms a fix): each fix is stamped at its first
//!   byte, not when the read that completed it returned.
//! - A late reader (the IMU driver stopped for 0.4 s with SIGSTOP, then continued): the samples
//!   it reads at once are stamped from the IMU's own clock, each at its own time, not all at the
//!   late read.

use auvnav_shm_schema::bus::Bus;
use auvnav_shm_schema::clock::monotonic_ns;
use auvnav_shm_schema::{ImuSampleV1, UsblFixV1, qos, topic};
use auvnav_tests::processes::{Proc, TempDir, binary, signal, unique};
use auvnav_tools::emulate_line::{SentFrame, read_send_times};
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

fn simulate(dir: &Path, seconds: f64) -> PathBuf {
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
    log
}

fn driver_config(dir: &Path, prefix: &str, class: &str, protocol: &str, baud: u32) -> PathBuf {
    let path = dir.join(format!("{class}.toml"));
    std::fs::write(
        &path,
        format!(
            "prefix = \"{prefix}\"\nprotocol = \"{protocol}\"\n[serial]\nport = \"{}\"\nbaud = {baud}\n\
             [settings.kvh]\nincrements = false\ndegrees = false\nrate_hz = 200.0\ntemperature_centi = false\n\
             [timing]\nread_timeout_s = 0.02\nreconnect_initial_s = 0.02\nreconnect_max_s = 0.2\n",
            dir.join("links").join(class).display()
        ),
    )
    .expect("writing a driver configuration");
    path
}

/// Plays `log`'s `class` device in `protocol` at `baud` into a real driver, calling `during`
/// with the driver once the emulator has started; returns what the driver published (its host
/// time stamps and when this test received each, in order) and the emulator's send times of
/// that kind.
fn play(
    dir: &Path,
    log: &Path,
    (class, protocol, kind): (&str, &str, &str),
    baud: u32,
    during: impl FnOnce(&Proc),
) -> (Vec<(u64, u64)>, Vec<SentFrame>) {
    let prefix = unique("line");
    let bus = Bus::new(&unique("linetest"), &prefix).expect("bus");
    let mut imu = bus
        .subscriber::<ImuSampleV1>(topic::IMU, qos::SENSOR)
        .expect("imu");
    let mut usbl = bus
        .subscriber::<UsblFixV1>(topic::USBL, qos::SENSOR)
        .expect("usbl");
    let cfg = driver_config(dir, &prefix, class, protocol, baud);
    let mut driver = Proc::spawn_logged(
        class,
        dir,
        Command::new(binary(&format!("auvnav-{class}")))
            .arg("--config")
            .arg(cfg),
    )
    .expect("spawn the driver");
    let send_times = dir.join("send.csv");
    let mut emulator = Proc::spawn(
        "emulate",
        Command::new(binary("auvnav"))
            .arg("emulate")
            .arg(log)
            .arg(format!("--{class}"))
            .arg(protocol)
            .args(["--baud", &baud.to_string(), "--start-delay", "1.0"])
            .arg("--send-times")
            .arg(&send_times)
            .arg("--link-dir")
            .arg(dir.join("links"))
            .stdout(Stdio::null())
            .stderr(Stdio::null()),
    )
    .expect("spawn the emulator");
    during(&driver);
    let mut stamps = Vec::new();
    let deadline = Instant::now() + Duration::from_secs(60);
    let mut finished_at = None;
    loop {
        while let Some(m) = imu.receive().expect("receive") {
            stamps.push((m.host_time_ns, monotonic_ns()));
        }
        while let Some(m) = usbl.receive().expect("receive") {
            stamps.push((m.host_time_ns, monotonic_ns()));
        }
        if finished_at.is_none()
            && let Ok(Some(status)) = emulator.child.try_wait()
        {
            assert!(status.success(), "the emulator failed: {status}");
            finished_at = Some(Instant::now());
        }
        if finished_at.is_some_and(|t| t.elapsed() > Duration::from_millis(500)) {
            break;
        }
        assert!(Instant::now() < deadline, "the run did not finish in 60 s");
        std::thread::sleep(Duration::from_millis(2));
    }
    assert!(driver.stop(Duration::from_secs(10)), "the driver stopped");
    let sent: Vec<SentFrame> = read_send_times(&send_times)
        .expect("send times")
        .into_iter()
        .filter(|f| f.kind == kind)
        .collect();
    assert_eq!(
        stamps.len(),
        sent.len(),
        "every frame played was published once"
    );
    (stamps, sent)
}

/// Stamp − first byte on the line, and reception by this test − first byte on the line (ms),
/// frame by frame.
fn errors_ms(stamps: &[(u64, u64)], sent: &[SentFrame]) -> (Vec<f64>, Vec<f64>) {
    let ms = |a: u64, b: u64| (a as f64 - b as f64) * 1e-6;
    stamps
        .iter()
        .zip(sent)
        .map(|(&(t, r), f)| (ms(t, f.line_ns), ms(r, f.line_ns)))
        .unzip()
}

#[test]
fn a_fix_on_a_slow_line_is_stamped_at_its_first_byte() {
    let dir = TempDir::new("line-usbl");
    let log = simulate(dir.path(), 8.0);
    let (stamps, sent) = play(dir.path(), &log, ("usbl", "seatrac", "usbl"), 9_600, |_| {});
    assert!(sent.len() >= 5, "{} fixes played", sent.len());
    let (errors, received) = errors_ms(&stamps, &sent);
    // A fix's frame is tens of characters, each 1.04 ms on a 9600 baud line: the driver can
    // publish it only after its last byte, so a stamp taken at that read would be as late.
    assert!(
        received.iter().all(|&r| r > 40.0),
        "every fix arrived whole more than 40 ms after its first byte: {received:?}"
    );
    for (i, e) in errors.iter().enumerate() {
        assert!(
            (-2.0..20.0).contains(e),
            "fix {i}: stamped {e:+.1} ms from its first byte on the line (every error: {errors:?})"
        );
    }
}

#[test]
fn samples_read_late_keep_the_times_of_the_imus_clock() {
    let dir = TempDir::new("line-imu");
    let log = simulate(dir.path(), 9.0);
    let stop_at = Duration::from_secs(7);
    let stopped_for = Duration::from_millis(400);
    let (stamps, sent) = play(
        dir.path(),
        &log,
        ("imu", "kvh1750", "imu"),
        921_600,
        |driver| {
            // The emulator plays after its 1 s start delay; 6 s into the voyage the model of the
            // IMU's clock has its 4 s.
            std::thread::sleep(stop_at);
            signal(driver, "-STOP");
            std::thread::sleep(stopped_for);
            signal(driver, "-CONT");
        },
    );
    let (errors, received) = errors_ms(&stamps, &sent);
    // The samples that waited in the terminal while the driver was stopped reached this test
    // hundreds of milliseconds after they were on the line.
    let waited = received.iter().filter(|&&r| r > 200.0).count();
    assert!(
        waited >= 40,
        "{waited} samples waited more than 200 ms for the stopped driver"
    );
    let worst = errors
        .iter()
        .copied()
        .fold(0.0f64, |a, e| if e.abs() > a.abs() { e } else { a });
    assert!(
        worst.abs() < 20.0,
        "the worst stamp is {worst:+.1} ms from its sample's first byte, with the driver stopped \
         for {} ms",
        stopped_for.as_millis()
    );
    let log_text = std::fs::read_to_string(dir.path().join("imu.log")).unwrap_or_default();
    assert!(
        log_text.contains("the device's clock runs"),
        "the driver modelled the IMU's clock: {log_text}"
    );
}
