//! Independent Monte Carlo runs spread over worker threads. Each run depends only on its index,
//! so the results do not depend on the number of threads.

use anyhow::Context;
use std::sync::Mutex;
use std::sync::atomic::{AtomicUsize, Ordering};

/// The default number of workers: the available cores.
pub fn default_threads() -> usize {
    std::thread::available_parallelism().map_or(1, |n| n.get())
}

/// Runs `f(0) .. f(runs - 1)` on `threads` workers and returns the results in index order, or the
/// first error by index.
pub fn map_runs<T, F>(runs: usize, threads: usize, f: F) -> anyhow::Result<Vec<T>>
where
    T: Send,
    F: Fn(usize) -> anyhow::Result<T> + Sync,
{
    let next = AtomicUsize::new(0);
    let results: Vec<Mutex<Option<anyhow::Result<T>>>> =
        (0..runs).map(|_| Mutex::new(None)).collect();
    std::thread::scope(|s| {
        for _ in 0..threads.clamp(1, 64) {
            s.spawn(|| {
                loop {
                    let k = next.fetch_add(1, Ordering::Relaxed);
                    if k >= runs {
                        break;
                    }
                    let r = f(k);
                    if let Ok(mut slot) = results[k].lock() {
                        *slot = Some(r);
                    }
                }
            });
        }
    });
    results
        .into_iter()
        .map(|slot| {
            slot.into_inner()
                .map_err(|_| anyhow::anyhow!("a worker panicked"))?
                .context("a run was not done")?
        })
        .collect()
}
