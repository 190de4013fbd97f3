//! Golden outputs: the bytes that `auvnav sim`, `auvnav replay` (simulated and measured logs, with
//! and without USBL and alignment) and `auvnav decode` produce, hashed and compared with
//! `tests/golden/hashes.txt`, plus known-answer values of the simulator's random streams.
//!
//! These pin behaviour across refactorings: a restructure must leave every hash as it was, and a
//! change of output that is a bug fix updates the file in the same commit that names the fix.
//! `AUVNAV_BLESS_GOLDEN=1 cargo test -p auvnav-tests --test golden` rewrites the file from the
//! current outputs (review the diff: every changed line is a changed output).
//!
//! The programs run as a user runs them (the workspace's `auvnav` binary), each under a watchdog.

use auvnav_tests::processes::{Proc, TempDir, binary};
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::Duration;

/// 64-bit FNV-1a: small, dependency-free, and enough to tell outputs apart.
fn fnv1a(bytes: &[u8]) -> u64 {
    let mut h: u64 = 0xcbf2_9ce4_8422_2325;
    for b in bytes {
        h ^= u64::from(*b);
        h = h.wrapping_mul(0x0000_0100_0000_01b3);
    }
    h
}

fn file_hash(p: &Path) -> String {
    let bytes = std::fs::read(p).unwrap_or_else(|e| panic!("reading {}: {e}", p.display()));
    format!("{:016x} {}", fnv1a(&bytes), bytes.len())
}

/// Runs `auvnav ARGS` to completion (at most five minutes); panics with its stderr on failure.
fn auvnav(args: &[&str]) -> Vec<u8> {
    let dir = TempDir::new("golden-out");
    let stdout = dir.path().join("stdout");
    let stderr = dir.path().join("stderr");
    let mut cmd = Command::new(binary("auvnav"));
    cmd.args(args)
        .stdout(std::fs::File::create(&stdout).expect("stdout file"))
        .stderr(std::fs::File::create(&stderr).expect("stderr file"));
    let mut p = Proc::spawn("auvnav", &mut cmd).expect("spawn");
    let status = p.wait_for(Duration::from_secs(300));
    let err = std::fs::read_to_string(&stderr).unwrap_or_default();
    match status {
        Some(s) if s.success() => std::fs::read(&stdout).expect("stdout"),
        Some(s) => panic!("auvnav {args:?} failed ({s}): {err}"),
        None => {
            p.kill();
            panic!("auvnav {args:?} did not finish within 300 s: {err}")
        }
    }
}

fn s(p: &Path) -> &str {
    p.to_str().expect("utf-8 path")
}

/// Simulates `scenario` for `seconds` into `dir/name.mcap`.
fn sim(dir: &Path, name: &str, scenario: &str, seed: u64, seconds: f64, extra: &[&str]) -> PathBuf {
    let out = dir.join(format!("{name}.mcap"));
    let seed = seed.to_string();
    let seconds = seconds.to_string();
    let mut args = vec![
        "sim",
        "--scenario",
        scenario,
        "--seed",
        &seed,
        "--duration",
        &seconds,
        "--out",
        s(&out),
    ];
    args.extend_from_slice(extra);
    auvnav(&args);
    out
}

/// Replays `log` into CSV; the hashes of the solution and the diagnostics files.
fn replay(dir: &Path, name: &str, log: &Path, extra: &[&str]) -> [(String, String); 2] {
    let out = dir.join(format!("{name}.csv"));
    let mut args = vec!["replay", s(log), "--out", s(&out)];
    args.extend_from_slice(extra);
    auvnav(&args);
    let diag = dir.join(format!("{name}.diagnostics.csv"));
    [
        (format!("replay.{name}.nav"), file_hash(&out)),
        (format!("replay.{name}.diagnostics"), file_hash(&diag)),
    ]
}

const SCENARIOS: [&str; 11] = [
    "straight",
    "turns",
    "depth_changes",
    "lawnmower",
    "docking",
    "homing",
    "moored",
    "survey",
    "align_moored",
    "align_straight",
    "align_turning",
];

fn golden_file() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("golden/hashes.txt")
}

fn read_golden() -> BTreeMap<String, String> {
    let text = std::fs::read_to_string(golden_file()).unwrap_or_default();
    text.lines()
        .filter(|l| !l.starts_with('#') && !l.trim().is_empty())
        .filter_map(|l| {
            let (k, v) = l.split_once(' ')?;
            Some((k.to_string(), v.trim().to_string()))
        })
        .collect()
}

/// Compares `got` with the golden file's entries of the same names (or rewrites those entries
/// when blessing); every mismatch is listed.
fn check(got: Vec<(String, String)>) {
    let mut golden = read_golden();
    if std::env::var("AUVNAV_BLESS_GOLDEN").is_ok_and(|v| v == "1") {
        // Each test blesses its own entries; the lock keeps concurrent tests from losing writes.
        static LOCK: std::sync::Mutex<()> = std::sync::Mutex::new(());
        let _guard = LOCK.lock().unwrap_or_else(|e| e.into_inner());
        golden = read_golden();
        for (k, v) in got {
            golden.insert(k, v);
        }
        let mut text = String::from(
            "# Golden outputs (FNV-1a 64 of the bytes, then their length): see tests/tests/golden.rs.\n",
        );
        for (k, v) in &golden {
            text.push_str(&format!("{k} {v}\n"));
        }
        std::fs::write(golden_file(), text).expect("writing the golden file");
        return;
    }
    let mut problems = Vec::new();
    for (k, v) in &got {
        match golden.get(k) {
            Some(g) if g == v => {}
            Some(g) => problems.push(format!("{k}: expected {g}, got {v}")),
            None => problems.push(format!("{k}: not in the golden file (got {v})")),
        }
    }
    assert!(
        problems.is_empty(),
        "outputs differ from tests/golden/hashes.txt:\n  {}",
        problems.join("\n  ")
    );
}

#[test]
fn random_streams_give_their_known_values() {
    use auvnav_sim::rng::Rng;
    let mut r = Rng::new(1, "imu");
    let ints: Vec<String> = (0..3).map(|_| format!("{:016x}", r.next_u64())).collect();
    let mut r = Rng::new(42, "dvl.beam_noise");
    let normals: Vec<String> = (0..3).map(|_| format!("{:.12}", r.normal())).collect();
    let mut r = Rng::new(7, "montecarlo.nees");
    let uniforms: Vec<String> = (0..3).map(|_| format!("{:.12}", r.uniform())).collect();
    check(vec![
        ("rng.u64.seed1.imu".into(), ints.join(",")),
        ("rng.normal.seed42.dvl_beam_noise".into(), normals.join(",")),
        (
            "rng.uniform.seed7.montecarlo_nees".into(),
            uniforms.join(","),
        ),
    ]);
}

#[test]
fn sim_output_is_unchanged_for_every_scenario() {
    let dir = TempDir::new("golden-sim");
    let mut got = Vec::new();
    for sc in SCENARIOS {
        let log = sim(dir.path(), sc, sc, 5, 90.0, &[]);
        got.push((format!("sim.{sc}.seed5.90s"), file_hash(&log)));
    }
    let log = sim(
        dir.path(),
        "effects",
        "straight",
        9,
        60.0,
        &[
            "--clean",
            "--effect",
            "dvl.scale_factor=1.005",
            "--effect",
            "dvl.lever_arm=0.5,0,0.2",
            "--effect",
            "dvl.time_offset=0.05",
        ],
    );
    got.push((
        "sim.straight.clean_effects.seed9.60s".into(),
        file_hash(&log),
    ));
    check(got);
}

#[test]
fn replay_output_is_unchanged_on_simulated_logs() {
    let dir = TempDir::new("golden-replay");
    let d = dir.path();
    let mut got = Vec::new();
    let log = sim(d, "lawnmower", "lawnmower", 2, 300.0, &[]);
    got.extend(replay(d, "lawnmower.seed2.300s", &log, &[]));
    let log = sim(d, "docking", "docking", 3, 300.0, &[]);
    got.extend(replay(
        d,
        "docking.seed3.300s.tight",
        &log,
        &["--usbl", "tight"],
    ));
    got.extend(replay(
        d,
        "docking.seed3.300s.loose",
        &log,
        &["--usbl", "loose"],
    ));
    got.extend(replay(d, "docking.seed3.300s.no_usbl", &log, &[]));
    // Alignment (coarse in motion, then the model-1 fine filter) instead of a known start.
    let log = sim(d, "turns", "turns", 4, 600.0, &[]);
    let cfg = d.join("align.toml");
    std::fs::write(
        &cfg,
        "[alignment]\nlatitude_deg = 31.0\nlongitude_deg = 120.0\nheight_m = -20.0\n",
    )
    .expect("config");
    got.extend(replay(
        d,
        "turns.seed4.600s.align",
        &log,
        &["--config", s(&cfg)],
    ));
    check(got);
}

#[test]
fn replay_output_is_unchanged_on_measured_data() {
    let Some(data) = auvnav_tests::measured_data("snapir-auv", "imu_03.csv") else {
        return;
    };
    let dir = TempDir::new("golden-measured");
    let d = dir.path();
    let log = d.join("seg3.mcap");
    auvnav_tests::processes::import_snapir(&data, 3, &log);
    let got = replay(d, "snapir.segment3", &log, &[]).to_vec();
    check(got);
}

#[test]
fn decode_output_is_unchanged_on_a_measured_pd0_file() {
    let Some(data) = auvnav_tests::measured_data("rdi-pd0", "raw/winriver02.PD0") else {
        return;
    };
    let json = auvnav(&[
        "decode",
        "--protocol",
        "pd0",
        s(&data.join("raw/winriver02.PD0")),
        "--json",
    ]);
    // The report names the input file: hash the rest, so the location of ../shared does not
    // matter.
    let text = String::from_utf8(json).expect("utf-8");
    let kept: String = text
        .lines()
        .filter(|l| !l.contains("winriver02.PD0"))
        .collect::<Vec<_>>()
        .join("\n");
    check(vec![(
        "decode.pd0.winriver02".into(),
        format!("{:016x} {}", fnv1a(kept.as_bytes()), kept.len()),
    )]);
}
