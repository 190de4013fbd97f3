//! Independent Monte Carlo runs spread over worker threads (rayon). Each run depends only on its
//! index, so the results do not depend on the number of threads.

/// The default number of workers: the available cores.
pub fn default_threads() -> usize {
    std::thread::available_parallelism().map_or(1, |n| n.get())
}

/// Runs `f(0) .. f(runs - 1)` on `threads` workers and returns the results in index order, or the
/// first error by index.
pub fn map_runs<T, E, F>(runs: usize, threads: usize, f: F) -> Result<Vec<T>, E>
where
    T: Send,
    E: Send,
    F: Fn(usize) -> Result<T, E> + Sync,
{
    map_runs_with_progress(runs, threads, &indicatif::ProgressBar::hidden(), f)
}

/// [`map_runs`], advancing `bar` by one as each run finishes. Where no worker thread can be
/// started, the runs go one after the other on the calling thread (the results are the same:
/// each run depends only on its index).
pub fn map_runs_with_progress<T, E, F>(
    runs: usize,
    threads: usize,
    bar: &indicatif::ProgressBar,
    f: F,
) -> Result<Vec<T>, E>
where
    T: Send,
    E: Send,
    F: Fn(usize) -> Result<T, E> + Sync,
{
    use rayon::prelude::*;
    let one = |k| {
        let r = f(k);
        bar.inc(1);
        r
    };
    let results: Vec<Result<T, E>> = match rayon::ThreadPoolBuilder::new()
        .num_threads(threads.clamp(1, 64))
        .build()
    {
        Ok(pool) => pool.install(|| (0..runs).into_par_iter().map(one).collect()),
        Err(_) => (0..runs).map(one).collect(),
    };
    bar.finish();
    results.into_iter().collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn results_come_in_index_order_whatever_the_threads() {
        for threads in [1, 2, 7] {
            let r = map_runs(100, threads, |k| Ok::<_, String>(k * k)).expect("runs");
            assert_eq!(r, (0..100).map(|k| k * k).collect::<Vec<_>>());
        }
    }

    #[test]
    fn the_first_error_by_index_is_returned() {
        let r = map_runs(50, 3, |k| {
            if k == 30 || k == 10 {
                anyhow::bail!("run {k}")
            }
            Ok(k)
        });
        assert_eq!(r.expect_err("fails").to_string(), "run 10");
    }
}
