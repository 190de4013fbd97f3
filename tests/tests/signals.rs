//! Only SIGTERM and SIGINT stop a process: SIGCONT alone, SIGHUP (no configuration reload is
//! offered), and a SIGSTOP/SIGCONT pair (a job control `fg`, a debugger, a container runtime),
//! leave the bridge and the live view running;
//! SIGTERM then stops them cleanly (status 0). The daemon, drivers and recorder are tried the same
//! way in `daemon_faults`. A SIGTERM followed at once by SIGCONT — what `systemctl stop` sends —
//! still stops every process (iceoryx2 keeps only the last signal it saw, and a process that
//! catches SIGCONT would forget the SIGTERM).

use auvnav_tests::processes::{
    Proc, TempDir, binary, feed_still_imu, signal, still_daemon_config, unique,
};
use std::process::Command;
use std::time::Duration;

fn survives_sigcont_and_stops_on_sigterm(mut p: Proc) {
    std::thread::sleep(Duration::from_millis(1500));
    assert!(
        matches!(p.child.try_wait(), Ok(None)),
        "{} did not start",
        p.name
    );
    signal(&p, "-CONT");
    std::thread::sleep(Duration::from_millis(300));
    signal(&p, "-HUP");
    std::thread::sleep(Duration::from_millis(300));
    signal(&p, "-STOP");
    std::thread::sleep(Duration::from_millis(300));
    signal(&p, "-CONT");
    std::thread::sleep(Duration::from_millis(700));
    assert!(
        matches!(p.child.try_wait(), Ok(None)),
        "{} stopped on SIGCONT or SIGHUP",
        p.name
    );
    let status = p.terminate(Duration::from_secs(10));
    assert!(
        status.is_some_and(|s| s.success()),
        "{} did not stop cleanly on SIGTERM: {status:?}",
        p.name
    );
}

/// systemd's stop: SIGTERM, then SIGCONT a moment later — the SIGCONT is handled after the
/// SIGTERM and before the process looks for it.
fn stops_on_sigterm_followed_by_sigcont(mut p: Proc) {
    std::thread::sleep(Duration::from_millis(1500));
    assert!(
        matches!(p.child.try_wait(), Ok(None)),
        "{} did not start",
        p.name
    );
    signal(&p, "-TERM");
    std::thread::sleep(Duration::from_millis(2));
    signal(&p, "-CONT");
    let status = p.wait_for(Duration::from_secs(10));
    assert!(
        status.is_some_and(|s| s.success()),
        "{} lost the SIGTERM that SIGCONT followed: {status:?}",
        p.name
    );
}

fn live_view(tag: &str) -> Proc {
    let prefix = unique(tag);
    Proc::spawn(
        "auvnav-live",
        Command::new(binary("auvnav-live")).args(["--prefix", &prefix, "--port", "0"]),
    )
    .expect("spawn")
}

#[test]
fn the_live_view_stops_on_sigterm_then_sigcont() {
    stops_on_sigterm_followed_by_sigcont(live_view("sigtc"));
}

#[test]
fn the_daemon_stops_on_sigterm_then_sigcont() {
    let dir = TempDir::new("sigtcd");
    let prefix = unique("sigtcd");
    let cfg = still_daemon_config(dir.path(), &prefix);
    let p = Proc::spawn(
        "auvnavd",
        Command::new(binary("auvnavd")).arg("--config").arg(&cfg),
    )
    .expect("spawn");
    stops_on_sigterm_followed_by_sigcont(p);
}

#[test]
fn the_recorder_stops_on_sigterm_then_sigcont() {
    let dir = TempDir::new("sigtcr");
    let prefix = unique("sigtcr");
    let out = dir.path().join("record.mcap");
    let p = Proc::spawn(
        "auvnav record",
        Command::new(binary("auvnav"))
            .args(["record", "--prefix", &prefix, "--out"])
            .arg(&out),
    )
    .expect("spawn");
    stops_on_sigterm_followed_by_sigcont(p);
}

/// A serial driver whose device does not exist: it retries opening it, and stops on request.
#[test]
fn a_driver_stops_on_sigterm_then_sigcont() {
    let dir = TempDir::new("sigtcv");
    let prefix = unique("sigtcv");
    let cfg = dir.path().join("imu.toml");
    std::fs::write(
        &cfg,
        format!(
            "prefix = \"{prefix}\"\nprotocol = \"kvh1750\"\n[serial]\nport = \"{}\"\n",
            dir.path().join("no-such-tty").display()
        ),
    )
    .expect("config");
    let p = Proc::spawn(
        "auvnav-imu",
        Command::new(binary("auvnav-imu")).arg("--config").arg(&cfg),
    )
    .expect("spawn");
    stops_on_sigterm_followed_by_sigcont(p);
}

#[test]
fn the_live_view_survives_sigcont() {
    let prefix = unique("sigl");
    let p = Proc::spawn(
        "auvnav-live",
        Command::new(binary("auvnav-live")).args(["--prefix", &prefix, "--port", "0"]),
    )
    .expect("spawn");
    survives_sigcont_and_stops_on_sigterm(p);
}

#[test]
fn the_bridge_survives_sigcont() {
    let dir = TempDir::new("sigb");
    let prefix = unique("sigb");
    let cfg = dir.path().join("bridge.toml");
    std::fs::write(
        &cfg,
        format!(
            "prefix = \"{prefix}\"\nname = \"bridge\"\n[zenoh]\nmode = \"peer\"\n\
             listen = [\"tcp/127.0.0.1:0\"]\nconnect = []\nmulticast_scouting = false\n\
             [[export]]\ntopics = \"nav/solution\"\nkey_prefix = \"{prefix}/v\"\nmax_rate_hz = 0.0\n"
        ),
    )
    .expect("config");
    let p = Proc::spawn(
        "auvnav-bridge",
        Command::new(binary("auvnav-bridge"))
            .arg("--config")
            .arg(&cfg),
    )
    .expect("spawn");
    survives_sigcont_and_stops_on_sigterm(p);
}

/// The daemon needs no network: run in a network namespace with no interface up (as the unit's
/// `PrivateNetwork=yes` runs it), it navigates from IMU samples on the shared-memory bus.
#[test]
fn the_daemon_navigates_in_a_network_namespace_without_interfaces() {
    use auvnav_shm_schema::bus::Bus;
    let unshare = Command::new("unshare")
        .args(["-n", "true"])
        .status()
        .is_ok_and(|s| s.success());
    if !unshare {
        assert!(
            std::env::var("CI").is_err(),
            "unshare -n is needed under CI (root, util-linux)"
        );
        eprintln!("skipped: `unshare -n` is not available here (needs root)");
        return;
    }
    let dir = TempDir::new("netns");
    let prefix = unique("netns");
    let cfg = still_daemon_config(dir.path(), &prefix);
    let bus = Bus::new(&unique("netnstest"), &prefix).expect("bus");
    let mut daemon = Proc::spawn(
        "auvnavd",
        Command::new("unshare")
            .arg("-n")
            .arg(binary("auvnavd"))
            .arg("--config")
            .arg(&cfg),
    )
    .expect("spawn");
    std::thread::sleep(Duration::from_millis(500));
    let ours = std::fs::read_link("/proc/self/ns/net").expect("our namespace");
    let theirs = std::fs::read_link(format!("/proc/{}/ns/net", daemon.pid())).expect("its");
    assert_ne!(
        ours, theirs,
        "the daemon runs in the host's network namespace"
    );
    let got = feed_still_imu(&bus, 300);
    assert!(
        got > 200,
        "{got} solutions from the daemon in its namespace"
    );
    assert!(dir.path().join("cp.json").exists(), "no checkpoint written");
    let status = daemon.terminate(Duration::from_secs(10));
    assert!(status.is_some_and(|s| s.success()), "{status:?}");
}

/// The live view's gate: a WebSocket upgrade from a web page of another origin is refused (403),
/// one without an origin (the desktop app) or from an allowed origin is served (101), and
/// connections beyond `max_connections` are refused (503).
#[test]
fn the_live_view_checks_origins_and_limits_connections() {
    use std::io::{Read, Write};
    use std::net::TcpStream;
    let dir = TempDir::new("gate");
    let prefix = unique("gate");
    let port = std::net::TcpListener::bind("127.0.0.1:0")
        .and_then(|l| l.local_addr())
        .expect("a free port")
        .port();
    let cfg = dir.path().join("live.toml");
    std::fs::write(
        &cfg,
        format!(
            "prefix = \"{prefix}\"\nport = {port}\nmax_connections = 2\n\
             allowed_origins = [\"https://app.foxglove.dev\"]\n"
        ),
    )
    .expect("config");
    let mut live = Proc::spawn(
        "auvnav-live",
        Command::new(binary("auvnav-live"))
            .arg("--config")
            .arg(&cfg),
    )
    .expect("spawn");
    let upgrade = |origin: Option<&str>| -> (String, TcpStream) {
        let mut s = None;
        for _ in 0..100 {
            match TcpStream::connect(("127.0.0.1", port)) {
                Ok(c) => {
                    s = Some(c);
                    break;
                }
                Err(_) => std::thread::sleep(Duration::from_millis(50)),
            }
        }
        let mut s = s.expect("the live view listens");
        let origin = origin.map_or(String::new(), |o| format!("Origin: {o}\r\n"));
        write!(
            s,
            "GET / HTTP/1.1\r\nHost: 127.0.0.1:{port}\r\nUpgrade: websocket\r\nConnection: Upgrade\r\n\
             Sec-WebSocket-Key: dGhlIHNhbXBsZSBub25jZQ==\r\nSec-WebSocket-Version: 13\r\n\
             Sec-WebSocket-Protocol: foxglove.sdk.v1\r\n{origin}\r\n"
        )
        .expect("request");
        s.set_read_timeout(Some(Duration::from_secs(5)))
            .expect("timeout");
        let mut b = [0u8; 12];
        s.read_exact(&mut b).expect("a response");
        (String::from_utf8_lossy(&b).into_owned(), s)
    };
    let (evil, _) = upgrade(Some("https://evil.example"));
    assert!(evil.starts_with("HTTP/1.1 403"), "{evil}");
    let (desktop, _a) = upgrade(None);
    assert!(desktop.starts_with("HTTP/1.1 101"), "{desktop}");
    let (browser, _b) = upgrade(Some("https://app.foxglove.dev"));
    assert!(browser.starts_with("HTTP/1.1 101"), "{browser}");
    let (third, _) = upgrade(None);
    assert!(third.starts_with("HTTP/1.1 503"), "{third}");
    let status = live.terminate(Duration::from_secs(10));
    assert!(status.is_some_and(|s| s.success()), "{status:?}");
}
