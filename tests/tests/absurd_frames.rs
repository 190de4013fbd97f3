//! Absurd but well-formed device frames on a real pseudo-terminal: KVH 1750 frames with a valid
//! CRC and values of 1e30, then a stream in which one frame in eight carries arbitrary bits (NaN,
//! infinities, huge and tiny values, random validity flags, sequence numbers and device clocks),
//! read by the real IMU driver and fused by the real daemon through shared memory. The daemon must
//! never publish a solution holding NaN, the driver must count the out-of-range samples, and both
//! must stop cleanly. `AUVNAV_FUZZ_SECONDS` sets how long the random stream plays (default 15: 3 000
//! frames at 200 Hz, one in eight arbitrary; a longer soak sets it higher).

use auvnav_drivers::kvh::{KvhSample, encode};
use auvnav_shm_schema::bus::Bus;
use auvnav_shm_schema::{NavSolutionV1, ProcessHealthV1, qos, topic};
use auvnav_tests::Bits;
use auvnav_tests::processes::{Proc, TempDir, binary, unique};
use serialport::SerialPort;
use std::io::Write;
use std::process::Command;
use std::time::{Duration, Instant};

/// A vehicle at rest, level, heading north at 45° N: the Earth's rate and gravity (rad/s, g).
fn at_rest(sequence: u8, t_us: u32) -> KvhSample {
    let w = 7.292_115e-5_f32;
    let lat = 45f32.to_radians();
    KvhSample {
        gyro: [w * lat.cos(), 0.0, -w * lat.sin()],
        accel: [0.0, 0.0, -1.0],
        status: 0x77,
        sequence,
        temperature_raw: 25,
        timestamp_us: Some(t_us),
    }
}

#[test]
// Long on purpose: one scenario with real processes read top to bottom: each step depends on the
// state the previous one left.
fn absurd_valid_checksum_frames_never_give_a_nan_solution() {
    let seconds: f64 = std::env::var("AUVNAV_FUZZ_SECONDS")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(15.0);
    let dir = TempDir::new("absurd");
    let d = dir.path();
    let prefix = unique("absurd");
    let (mut master, slave) = serialport::TTYPort::pair().expect("a pseudo-terminal pair");
    let port = slave.name().expect("the slave's path");
    let imu_cfg = d.join("imu.toml");
    std::fs::write(
        &imu_cfg,
        format!(
            "prefix = \"{prefix}\"\nprotocol = \"kvh1750\"\n[serial]\nport = \"{port}\"\nbaud = 921600\n\
             [settings.kvh]\nincrements = false\ndegrees = false\nrate_hz = 200.0\ntemperature_centi = false\n\
             [timing]\nhealth_period_s = 0.2\n"
        ),
    )
    .expect("driver config");
    let daemon_cfg = d.join("auvnavd.toml");
    std::fs::write(
        &daemon_cfg,
        format!(
            "prefix = \"{prefix}\"\nhealth_period_s = 0.2\n[navigation]\nimu_dt_from_device_time = true\n\
             [initial]\nlatitude_deg = 45.0\nlongitude_deg = 10.0\nheight_m = -10.0\neuler_deg = [0.0, 0.0, 0.0]\n\
             [deadlines]\ndvl_s = 0.0\ndepth_s = 0.0\n"
        ),
    )
    .expect("daemon config");
    let bus = Bus::new(&unique("absurdtest"), &prefix).expect("bus");
    let mut solutions = bus
        .subscriber::<NavSolutionV1>(topic::NAV_SOLUTION, qos::NAVIGATION)
        .expect("sub");
    let mut health = bus
        .subscriber::<ProcessHealthV1>(topic::HEALTH, qos::HEALTH)
        .expect("sub");
    let spawn = |name: &str, bin: &str, cfg: &std::path::Path| {
        let err = std::fs::File::create(d.join(format!("{name}.err"))).expect("stderr");
        Proc::spawn(
            name,
            Command::new(binary(bin))
                .arg("--config")
                .arg(cfg)
                .stderr(err),
        )
        .expect("spawn")
    };
    let mut daemon = spawn("auvnavd", "auvnavd", &daemon_cfg);
    let mut imu = spawn("imu", "auvnav-imu", &imu_cfg);
    std::thread::sleep(Duration::from_millis(500));

    let (mut received, mut with_nan) = (0u64, 0u64);
    let mut last_health: Option<ProcessHealthV1> = None;
    let mut poll = |received: &mut u64, with_nan: &mut u64| {
        while let Some(s) = solutions.receive().expect("receive") {
            *received += 1;
            if !s.all_finite() {
                *with_nan += 1;
            }
        }
        while let Some(h) = health.receive().expect("receive") {
            if h.name() == "imu" {
                last_health = Some(h);
            }
        }
    };
    let mut bits = Bits(0x9e37_79b9_7f4a_7c15);
    let (mut seq, mut t_us) = (0u8, 1_000_000u32);
    let mut frame = |k: u64, bits: &mut Bits| -> Vec<u8> {
        seq = seq.wrapping_add(1) & 0x7f;
        t_us = t_us.wrapping_add(5000);
        let mut s = at_rest(seq, t_us);
        if k < 400 {
            // Two seconds at rest.
        } else if k < 410 {
            // Ten frames of 1e30.
            s.gyro = [1e30; 3];
            s.accel = [-1e30; 3];
        } else if bits.next_u64().is_multiple_of(8) {
            // Arbitrary bits in every field the CRC covers.
            for v in s.gyro.iter_mut().chain(s.accel.iter_mut()) {
                *v = f32::from_bits(bits.next_u64() as u32);
            }
            s.status = bits.next_u64() as u8;
            s.sequence = bits.next_u64() as u8;
            s.temperature_raw = bits.next_u64() as i16;
            if bits.next_u64().is_multiple_of(4) {
                s.timestamp_us = Some(bits.next_u64() as u32);
            }
        }
        encode(&s)
    };
    let start = Instant::now();
    let mut k = 0u64;
    let total = 410.0 / 200.0 + seconds;
    while start.elapsed().as_secs_f64() < total {
        let due = k as f64 / 200.0;
        let now = start.elapsed().as_secs_f64();
        if now < due {
            std::thread::sleep(Duration::from_secs_f64((due - now).min(0.005)));
            poll(&mut received, &mut with_nan);
            continue;
        }
        if let Err(e) = master.write_all(&frame(k, &mut bits)) {
            let tail = |name: &str| std::fs::read_to_string(d.join(format!("{name}.err")));
            panic!(
                "writing to the pty after {k} frames: {e} (the driver stopped reading?)\n\
                 driver {:?}: {:?}\ndaemon {:?}: {:?}",
                imu.child.try_wait(),
                tail("imu"),
                daemon.child.try_wait(),
                tail("auvnavd")
            );
        }
        k += 1;
    }
    std::thread::sleep(Duration::from_millis(500));
    poll(&mut received, &mut with_nan);
    assert!(
        matches!(daemon.child.try_wait(), Ok(None)),
        "the daemon stopped"
    );
    assert!(
        matches!(imu.child.try_wait(), Ok(None)),
        "the driver stopped"
    );
    let h = last_health.expect("driver health");
    let daemon_status = daemon.terminate(Duration::from_secs(10));
    let imu_status = imu.terminate(Duration::from_secs(10));
    drop(slave);
    let log = std::fs::read_to_string(d.join("auvnavd.err")).unwrap_or_default();
    eprintln!(
        "{k} frames written, {received} solutions, driver health: invalid {}",
        h.invalid
    );
    assert_eq!(with_nan, 0, "{with_nan} of {received} solutions hold NaN");
    assert!(
        received as f64 > 100.0 * seconds,
        "only {received} solutions in {seconds} s: {log}"
    );
    assert!(
        h.invalid >= 10,
        "the driver counted {} out-of-range samples",
        h.invalid
    );
    assert!(
        daemon_status.is_some_and(|s| s.success()),
        "the daemon did not stop cleanly: {log}"
    );
    assert!(
        imu_status.is_some_and(|s| s.success()),
        "the driver did not stop cleanly"
    );
    assert!(
        log.contains("invalid or implausible"),
        "the daemon's stop line has no IMU summary: {log}"
    );
}
