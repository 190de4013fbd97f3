//! The service manager's protocol, spoken to a real daemon process: a Unix datagram socket stands
//! in for systemd's (`NOTIFY_SOCKET`, `WATCHDOG_USEC` as systemd sets them). The daemon says READY
//! with a STATUS once its bus is up, sends WATCHDOG keep-alives from its loop, sends none while it
//! is stopped (SIGSTOP: what a hung loop looks like to systemd), resumes after SIGCONT, and says
//! STOPPING on SIGTERM.

use auvnav_tests::processes::{Proc, TempDir, binary, signal, still_daemon_config, unique};
use std::os::unix::net::UnixDatagram;
use std::process::Command;
use std::time::{Duration, Instant};

/// Every datagram received within `d`.
fn collect(sock: &UnixDatagram, d: Duration) -> Vec<String> {
    let end = Instant::now() + d;
    let mut out = Vec::new();
    let mut buf = [0u8; 4096];
    while Instant::now() < end {
        sock.set_read_timeout(Some((end - Instant::now()).max(Duration::from_millis(1))))
            .expect("timeout");
        if let Ok(n) = sock.recv(&mut buf) {
            out.push(String::from_utf8_lossy(&buf[..n]).into_owned());
        }
    }
    out
}

fn count(msgs: &[String], line: &str) -> usize {
    msgs.iter().filter(|m| m.lines().any(|l| l == line)).count()
}

#[test]
fn the_daemon_notifies_ready_keeps_alive_from_its_loop_and_stops() {
    let dir = TempDir::new("sdnotify");
    let prefix = unique("sdnotify");
    let socket = dir.path().join("notify.sock");
    let sock = UnixDatagram::bind(&socket).expect("bind");
    let cfg = still_daemon_config(dir.path(), &prefix);
    let mut p = Proc::spawn(
        "auvnavd",
        Command::new(binary("auvnavd"))
            .arg("--config")
            .arg(&cfg)
            .env("NOTIFY_SOCKET", &socket)
            // A 0.4 s watchdog: a keep-alive every 0.1 s.
            .env("WATCHDOG_USEC", "400000"),
    )
    .expect("spawn");
    // READY within 20 s (a loaded machine starts slowly), then 2 s of keep-alives.
    let mut first = Vec::new();
    let deadline = std::time::Instant::now() + Duration::from_secs(20);
    while !first
        .iter()
        .any(|m: &String| m.lines().any(|l| l == "READY=1"))
        && std::time::Instant::now() < deadline
    {
        first.extend(collect(&sock, Duration::from_millis(200)));
    }
    let ready = first
        .iter()
        .position(|m| m.lines().any(|l| l == "READY=1"))
        .expect("READY=1");
    assert!(
        first[ready].contains("STATUS=") && first[ready].contains("waiting for the IMU"),
        "READY comes with a status: {:?}",
        first[ready]
    );
    let after = collect(&sock, Duration::from_secs(2));
    let alive = count(&after, "WATCHDOG=1");
    assert!(
        alive >= 8,
        "keep-alives in 2 s at 0.1 s (about 20 expected): {alive} ({after:?})"
    );

    signal(&p, "-STOP");
    // Datagrams sent before the stop took effect are read first.
    let _ = collect(&sock, Duration::from_millis(100));
    let stopped = collect(&sock, Duration::from_millis(1200));
    assert_eq!(
        count(&stopped, "WATCHDOG=1"),
        0,
        "a stopped loop sends no keep-alive (a helper thread would): {stopped:?}"
    );
    signal(&p, "-CONT");
    let resumed = collect(&sock, Duration::from_secs(2));
    assert!(
        count(&resumed, "WATCHDOG=1") >= 3,
        "keep-alives resume: {resumed:?}"
    );

    signal(&p, "-TERM");
    let last = collect(&sock, Duration::from_secs(2));
    assert!(count(&last, "STOPPING=1") == 1, "{last:?}");
    let status = p.wait_for(Duration::from_secs(10));
    assert!(status.is_some_and(|s| s.success()), "{status:?}");
}

/// Outside systemd (no NOTIFY_SOCKET) nothing is sent and nothing fails.
#[test]
fn without_a_service_manager_the_daemon_runs_as_before() {
    let dir = TempDir::new("nonotify");
    let prefix = unique("nonotify");
    let cfg = still_daemon_config(dir.path(), &prefix);
    let mut p = Proc::spawn(
        "auvnavd",
        Command::new(binary("auvnavd"))
            .arg("--config")
            .arg(&cfg)
            .env_remove("NOTIFY_SOCKET")
            .env("WATCHDOG_USEC", "400000"),
    )
    .expect("spawn");
    std::thread::sleep(Duration::from_millis(1500));
    assert!(matches!(p.child.try_wait(), Ok(None)), "running");
    let status = p.terminate(Duration::from_secs(10));
    assert!(status.is_some_and(|s| s.success()), "{status:?}");
}
