//! Only SIGTERM and SIGINT stop a process: SIGCONT alone, and a SIGSTOP/SIGCONT pair (a job
//! control `fg`, a debugger, a container runtime), leave the bridge and the live view running;
//! SIGTERM then stops them cleanly (status 0). The daemon, drivers and recorder are tried the same
//! way in `daemon_faults`.

use auvnav_tests::processes::{Proc, TempDir, binary, unique};
use std::process::Command;
use std::time::Duration;

fn signal(p: &Proc, sig: &str) {
    let ok = Command::new("kill")
        .args([sig, &p.pid().to_string()])
        .status()
        .expect("kill");
    assert!(ok.success(), "kill {sig} {}", p.pid());
}

fn survives_sigcont_and_stops_on_sigterm(mut p: Proc) {
    std::thread::sleep(Duration::from_millis(1500));
    assert!(
        matches!(p.child.try_wait(), Ok(None)),
        "{} did not start",
        p.name
    );
    signal(&p, "-CONT");
    std::thread::sleep(Duration::from_millis(300));
    signal(&p, "-STOP");
    std::thread::sleep(Duration::from_millis(300));
    signal(&p, "-CONT");
    std::thread::sleep(Duration::from_millis(700));
    assert!(
        matches!(p.child.try_wait(), Ok(None)),
        "{} stopped on SIGCONT",
        p.name
    );
    let status = p.terminate(Duration::from_secs(10));
    assert!(
        status.is_some_and(|s| s.success()),
        "{} did not stop cleanly on SIGTERM: {status:?}",
        p.name
    );
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
