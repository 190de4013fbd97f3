//! The bus in a directory of the operator's choosing (`AUVNAV_BUS_ROOT`, as the units set it to
//! `/run/auvnav/iceoryx2/` so that every unit can keep a private `/tmp`): a daemon started with it
//! navigates from IMU samples published by a process with the same root, and its node and the
//! services' files are under that root; a relative root is refused by name.
//! One test per file: the root is this process's environment.

use auvnav_shm_schema::bus::{BUS_ROOT_ENV, Bus};
use auvnav_tests::processes::{Proc, TempDir, binary, feed_still_imu, still_daemon_config, unique};
use std::process::Command;
use std::time::Duration;

fn files_under(dir: &std::path::Path, needle: &str) -> usize {
    // Regular files below `dir` whose path contains `needle`.
    let mut n = 0;
    let mut stack = vec![dir.to_path_buf()];
    while let Some(d) = stack.pop() {
        let Ok(entries) = std::fs::read_dir(&d) else {
            continue;
        };
        for e in entries.flatten() {
            let p = e.path();
            if p.is_dir() {
                stack.push(p);
            } else if p.to_string_lossy().contains(needle) {
                n += 1;
            }
        }
    }
    n
}

#[test]
fn the_bus_lives_under_the_configured_root() {
    let dir = TempDir::new("busroot");
    let root = dir.path().join("run").join("iceoryx2");
    let prefix = unique("busroot");
    // SAFETY: the only test of this binary; no other thread reads the environment yet.
    unsafe { std::env::set_var(BUS_ROOT_ENV, &root) };
    let cfg = still_daemon_config(dir.path(), &prefix);
    let bus = Bus::new(&unique("busroottest"), &prefix).expect("bus");
    let mut daemon = Proc::spawn(
        "auvnavd",
        Command::new(binary("auvnavd")).arg("--config").arg(&cfg),
    )
    .expect("spawn");
    std::thread::sleep(Duration::from_millis(500));
    let got = feed_still_imu(&bus, 300);
    assert!(got > 200, "{got} solutions through the bus under {root:?}");
    // iceoryx2 names its files by hashes: the daemon's node and ours are two node directories
    // under the root, and the services' files are there too.
    let nodes = std::fs::read_dir(root.join("nodes"))
        .map(|d| d.flatten().count())
        .unwrap_or(0);
    assert!(nodes >= 2, "{nodes} node directories under {root:?}");
    assert!(
        files_under(&root.join("services"), "") > 0,
        "no service file under {root:?}"
    );
    let status = daemon.terminate(Duration::from_secs(10));
    assert!(status.is_some_and(|s| s.success()), "{status:?}");

    // A relative root names the variable.
    let o = Command::new(binary("auvnavd"))
        .arg("--config")
        .arg(&cfg)
        .env(BUS_ROOT_ENV, "run/iceoryx2")
        .output()
        .expect("run");
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success() && err.contains(BUS_ROOT_ENV), "{err}");
}
