//! The floor under the chain's latencies: how long this host takes to wake a thread blocked on a
//! file descriptor when another writes to it (the pseudo-terminal, the bus's events and the
//! subscriber each cost one such wake-up). Measured at the chain's rate, under the same
//! scheduling, beside `auvnav bench e2e`.

use crate::percentiles::{Percentiles, percentiles};
use std::io::{Read, Write};
use std::time::{Duration, Instant};

/// Wakes a reader thread `rate_hz` times a second for `seconds` through a socket pair, the
/// reader under SCHED_FIFO at `priority` when given; the wake-up latencies (µs): write → the
/// reader's read returned.
pub fn wake_up_floor(
    rate_hz: f64,
    seconds: f64,
    priority: Option<u8>,
) -> anyhow::Result<Percentiles> {
    let (mut tx, mut rx) = std::os::unix::net::UnixStream::pair()?;
    let reader = std::thread::spawn(move || -> Vec<f64> {
        if priority.is_some() {
            let _ = crate::process::schedule_this_thread(priority);
        }
        let mut out = Vec::new();
        let mut buf = [0u8; 8];
        while rx.read_exact(&mut buf).is_ok() {
            let now = auvnav_drivers::clock::monotonic_ns();
            out.push((now as f64 - u64::from_le_bytes(buf) as f64) * 1e-3);
        }
        out
    });
    let n = (rate_hz * seconds).round() as u64;
    let start = Instant::now();
    for i in 0..n {
        let due = start + Duration::from_secs_f64(i as f64 / rate_hz);
        if let Some(d) = due.checked_duration_since(Instant::now()) {
            std::thread::sleep(d);
        }
        tx.write_all(&auvnav_drivers::clock::monotonic_ns().to_le_bytes())?;
    }
    drop(tx);
    let latencies = reader
        .join()
        .map_err(|_| anyhow::anyhow!("the reader thread panicked"))?;
    Ok(percentiles(latencies))
}
