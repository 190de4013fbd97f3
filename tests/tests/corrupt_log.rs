//! A log with damage in the middle: five flipped bytes in one chunk, and two hundred spread over
//! the file. `auvnav info` and `auvnav replay` read on past every damaged chunk and say what was
//! lost; `auvnav record --recover` rebuilds every intact chunk, reports the loss and exits
//! non-zero, and what it wrote reads whole.

use auvnav_tests::processes::{TempDir, binary};
use serde_json::Value;
use std::path::Path;
use std::process::Command;

fn auvnav(args: &[&str]) -> (Option<i32>, Value, String) {
    let o = Command::new(binary("auvnav"))
        .args(args)
        .output()
        .expect("auvnav");
    let out = String::from_utf8_lossy(&o.stdout);
    let v = serde_json::from_str(&out).unwrap_or(Value::Null);
    (
        o.status.code(),
        v,
        String::from_utf8_lossy(&o.stderr).into_owned(),
    )
}

fn s(p: &Path) -> &str {
    p.to_str().expect("utf-8")
}

/// `n` fixed pseudo-random positions in `lo..hi`.
fn positions(n: usize, lo: usize, hi: usize, seed: u64) -> Vec<usize> {
    let mut bits = auvnav_tests::Bits(seed);
    (0..n)
        .map(|_| lo + (bits.next_u64() as usize) % (hi - lo))
        .collect()
}

fn damage(src: &Path, dst: &Path, at: &[usize]) {
    let mut b = std::fs::read(src).expect("read");
    for &i in at {
        b[i] ^= 0x5a;
    }
    std::fs::write(dst, b).expect("write");
}

#[test]
fn damaged_chunks_are_skipped_counted_and_recovery_keeps_the_rest() {
    let dir = TempDir::new("corrupt");
    let d = dir.path();
    let log = d.join("voyage.mcap");
    let (code, _, err) = auvnav(&[
        "sim",
        "--scenario",
        "straight",
        "--duration",
        "300",
        "--out",
        s(&log),
    ]);
    assert_eq!(code, Some(0), "{err}");
    let (_, whole, _) = auvnav(&["info", s(&log), "--json"]);
    let total = whole["messages"].as_u64().expect("messages");
    assert!(whole["damaged"].is_null());
    let len = std::fs::metadata(&log).expect("size").len() as usize;

    // Five flipped bytes in the middle: one chunk lost, the rest read.
    let five = d.join("five.mcap");
    let mid = len / 2;
    damage(
        &log,
        &five,
        &[mid, mid + 7, mid + 100, mid + 1000, mid + 2000],
    );
    let (code, info, err) = auvnav(&["info", s(&five), "--json"]);
    assert_eq!(code, Some(0), "{err}");
    let read = info["messages"].as_u64().expect("messages");
    let chunks = info["damaged"]["chunks_skipped"].as_u64().unwrap_or(0);
    assert!(
        (1..=2).contains(&chunks),
        "damaged chunks reported: {}",
        info["damaged"]
    );
    // Every message record is over 100 bytes, so a chunk holds at most CHUNK_SIZE / 100.
    let per_chunk = auvnav_log::CHUNK_SIZE / 100;
    assert!(
        read + chunks * per_chunk >= total && read < total,
        "{read} of {total} messages read past {chunks} damaged chunks"
    );
    let spans = info["damaged"]["spans_ns"]
        .as_array()
        .expect("time spans of the lost chunks");
    assert_eq!(spans.len() as u64, chunks);

    let (code, replay, err) = auvnav(&["replay", s(&five), "--json"]);
    assert_eq!(code, Some(0), "{err}");
    let why = replay["log_error"].as_str().unwrap_or_default();
    assert!(why.contains("corrupt chunks skipped"), "{replay}");

    let recovered = d.join("five.recovered.mcap");
    let (code, _, err) = auvnav(&["record", "--recover", s(&five), "--out", s(&recovered)]);
    assert_ne!(code, Some(0), "a recovery that lost data exits non-zero");
    assert!(err.contains("lost"), "{err}");
    let (code, again, err) = auvnav(&["info", s(&recovered), "--json"]);
    assert_eq!(code, Some(0), "{err}");
    assert_eq!(again["messages"].as_u64(), Some(read));
    assert!(again["damaged"].is_null() && again["stopped"].is_null());

    // Two hundred flips over the whole file damage every chunk of this short log: nothing can
    // be recovered, and the recovery says so (status non-zero).
    let all = d.join("all.mcap");
    damage(&log, &all, &positions(200, 4096, len - 4096, 7));
    let (code, _, err) = auvnav(&[
        "record",
        "--recover",
        s(&all),
        "--out",
        s(&d.join("all.recovered.mcap")),
    ]);
    assert_ne!(code, Some(0));
    assert!(err.contains("lost") || err.contains("no message"), "{err}");
    // Two hundred flips over the second half: the first half is read and recovered, the loss
    // said.
    let many = d.join("many.mcap");
    damage(&log, &many, &positions(200, len / 2, len - 4096, 7));
    let (code, info, err) = auvnav(&["info", s(&many), "--json"]);
    assert_eq!(code, Some(0), "{err}");
    let read_many = info["messages"].as_u64().unwrap_or(0);
    assert!(read_many > 0, "nothing read: {info}");
    assert!(!info["damaged"].is_null());
    let recovered = d.join("many.recovered.mcap");
    let (code, _, err) = auvnav(&["record", "--recover", s(&many), "--out", s(&recovered)]);
    assert_ne!(code, Some(0));
    assert!(err.contains("lost"), "{err}");
    let (_, again, _) = auvnav(&["info", s(&recovered), "--json"]);
    assert_eq!(again["messages"].as_u64(), Some(read_many));
    eprintln!(
        "{total} messages; five flips: {read} read, {chunks} chunks lost; 200 flips: {read_many} read, {} chunks lost",
        info["damaged"]["chunks_skipped"]
    );
}
