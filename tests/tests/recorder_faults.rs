//! The recorder under faults, as a real process: killed with SIGKILL, its log is readable up to
//! its last flush and `--recover` makes it a complete log; on a write error (the file size limit
//! standing in for a full disk) it reports, stops, and what it flushed stays readable.

use auvnav_log::{LogError, LogMessage, LogReader};
use auvnav_shm_schema::bus::Bus;
use auvnav_shm_schema::{ImuSampleV1, qos, topic};
use auvnav_tests::processes::{Proc, TempDir, binary, unique};
use std::path::Path;
use std::process::Command;
use std::time::{Duration, Instant};

/// Publishes IMU samples at about `rate_hz` for `seconds`; returns (host time, sequence) of each.
fn publish(bus: &Bus, rate_hz: f64, seconds: f64) -> Vec<(Instant, u64)> {
    let mut p = bus
        .publisher::<ImuSampleV1>(topic::IMU, qos::SENSOR)
        .expect("publisher");
    let start = Instant::now();
    let mut sent = Vec::new();
    let mut i = 0u64;
    while start.elapsed().as_secs_f64() < seconds {
        let due = start + Duration::from_secs_f64(i as f64 / rate_hz);
        if let Some(d) = due.checked_duration_since(Instant::now()) {
            std::thread::sleep(d);
        }
        let m = ImuSampleV1 {
            host_time_ns: auvnav_shm_schema::clock::monotonic_ns(),
            // Incompressible enough that the log grows like a real one.
            angular: [i as f64, (i as f64 * 0.731).sin(), (i as f64 * 1.37).cos()],
            specific: [(i as f64 * 0.19).sin(), (i as f64 * 2.3).cos(), -9.8],
            interval_s: 1.0 / rate_hz,
            ..Default::default()
        };
        let seq = p.publish(m).expect("publish");
        sent.push((Instant::now(), seq));
        i += 1;
    }
    sent
}

/// Reads every IMU message a (possibly unfinished) log holds; the second value says whether it
/// ended early.
fn read_imu(path: &Path) -> (Vec<ImuSampleV1>, bool) {
    let mut r = LogReader::open(path).expect("open");
    r.read_header().expect("the header is at the start");
    let mut out = Vec::new();
    loop {
        match r.next_message() {
            Ok(Some(m)) => {
                if let Ok(LogMessage::Imu(x)) = m.decode_any() {
                    out.push(x);
                }
            }
            Ok(None) => return (out, false),
            Err(LogError::Truncated | LogError::Mcap(_)) => return (out, true),
            Err(e) => panic!("{e}"),
        }
    }
}

fn start_recorder(out: &Path, prefix: &str, shell_prefix: &str) -> Proc {
    let cmd = format!(
        "{shell_prefix} exec '{}' record --out '{}' --prefix {prefix} --flush-s 0.5",
        binary("auvnav").display(),
        out.display()
    );
    Proc::spawn(
        "record",
        Command::new("bash")
            .arg("-c")
            .arg(cmd)
            .stderr(std::fs::File::create(out.with_extension("err")).expect("stderr")),
    )
    .expect("spawn")
}

#[test]
fn a_killed_recorder_leaves_a_log_readable_to_its_last_flush() {
    let dir = TempDir::new("reckill");
    let prefix = unique("reck");
    let bus = Bus::new(&unique("recpub"), &prefix).expect("bus");
    let out = dir.path().join("killed.mcap");
    let mut rec = start_recorder(&out, &prefix, "");
    std::thread::sleep(Duration::from_millis(700));
    let sent = publish(&bus, 1000.0, 2.5);
    rec.kill();
    let killed_at = Instant::now();
    let (got, truncated) = read_imu(&out);
    assert!(truncated, "a killed writer leaves no summary");
    // Everything published more than a flush period (0.5 s) plus margin before the kill is there,
    // in order, without gaps.
    let must = sent
        .iter()
        .filter(|(t, _)| killed_at.duration_since(*t) > Duration::from_millis(1200))
        .count();
    assert!(
        got.len() >= must && must > 500,
        "{} read, {must} expected",
        got.len()
    );
    for (k, m) in got.iter().enumerate() {
        assert_eq!(m.angular[0], k as f64, "message {k}");
    }
    // --recover writes a complete, indexed log with the same messages.
    let fixed = dir.path().join("fixed.mcap");
    let o = Command::new(binary("auvnav"))
        .args(["record", "--recover"])
        .arg(&out)
        .arg("--out")
        .arg(&fixed)
        .output()
        .expect("recover");
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let (again, truncated) = read_imu(&fixed);
    assert!(!truncated);
    assert_eq!(again.len(), got.len());
    let summary = mcap::read::Summary::read(&std::fs::read(&fixed).expect("read"))
        .expect("summary")
        .expect("an indexed file has a summary");
    assert!(
        summary
            .stats
            .is_some_and(|s| s.message_count >= got.len() as u64)
    );
}

#[test]
fn a_full_disk_stops_the_recorder_with_a_report_and_keeps_what_was_flushed() {
    let dir = TempDir::new("recfull");
    let prefix = unique("recf");
    let bus = Bus::new(&unique("recpub"), &prefix).expect("bus");
    let out = dir.path().join("full.mcap");
    // 64 KiB file size limit (ulimit -f counts KiB in bash); writes beyond it fail with EFBIG,
    // as they would with ENOSPC on a full disk (the signal is ignored, so the write reports it).
    let mut rec = start_recorder(&out, &prefix, "ulimit -f 64; trap '' XFSZ;");
    std::thread::sleep(Duration::from_millis(700));
    publish(&bus, 2000.0, 4.0);
    let status = rec
        .wait_for(Duration::from_secs(10))
        .expect("the recorder stopped by itself");
    assert!(!status.success());
    let err = std::fs::read_to_string(out.with_extension("err")).expect("stderr");
    assert!(
        err.contains("File too large") && err.contains("readable up to its last flush"),
        "{err}"
    );
    let size = std::fs::metadata(&out).expect("file").len();
    assert!(size <= 64 * 1024, "{size}");
    let (got, _) = read_imu(&out);
    assert!(got.len() > 100, "{} messages readable", got.len());
    for (k, m) in got.iter().enumerate() {
        assert_eq!(m.angular[0], k as f64, "message {k}");
    }
}
