//! The second pass's outputs written on threads of their own: the smoothed track's MCAP log
//! (each solution as the filter had it and smoothed, the diagnostics, truth and late-aid records)
//! and its CSV rows, in the order the pass produces them. The pass (the replay and the smoothed
//! track) hands them over in batches. A batch goes to the log's thread, then to the CSV's, then
//! back to the pass to be filled again: encoding, compressing, formatting and writing, most of the
//! second pass's work when every 200 Hz solution is written, run beside the pass, and the machine
//! shares the three threads among its cores.

use auvnav_log::LogWriter;
use auvnav_shm_schema::{AidDiagnosticsV1, LateAidV1, NavSolutionV1, TruthStateV1, topic};
use std::io::Write;
use std::sync::mpsc::{Receiver, SyncSender, sync_channel};

/// Items per batch: few enough to keep the writer busy early, many enough that the handing over
/// costs nothing beside them.
const BATCH: usize = 1024;
/// Batches in flight: the pass runs ahead of the writer by at most this many.
const BATCHES_IN_FLIGHT: usize = 8;

/// One thing for the outputs.
// Most items are solutions: boxing the large variant would allocate for nearly every item.
#[allow(clippy::large_enum_variant)]
pub(crate) enum Item {
    /// A solution as the filter had it and smoothed, into the log and the CSV.
    Solution {
        filtered: NavSolutionV1,
        smoothed: NavSolutionV1,
    },
    Diagnostics(AidDiagnosticsV1),
    Truth(TruthStateV1),
    LateAid(LateAidV1),
}

/// The pass's side: collects items and hands them over a batch at a time.
pub(crate) struct Batches {
    tx: SyncSender<Vec<Item>>,
    /// Batches the writer has emptied, to be filled again: a new one each time would be mapped
    /// and unmapped by the allocator (600 kB), page faults and all.
    emptied: Receiver<Vec<Item>>,
    batch: Vec<Item>,
}

impl Batches {
    /// Queues `item`; an error when the writer has stopped (its own error says why).
    pub(crate) fn push(&mut self, item: Item) -> anyhow::Result<()> {
        self.batch.push(item);
        if self.batch.len() == BATCH {
            self.hand_over()?;
        }
        Ok(())
    }

    fn hand_over(&mut self) -> anyhow::Result<()> {
        let next = self
            .emptied
            .try_recv()
            .unwrap_or_else(|_| Vec::with_capacity(BATCH));
        let full = std::mem::replace(&mut self.batch, next);
        self.tx
            .send(full)
            .map_err(|_| anyhow::anyhow!("the output writer stopped"))
    }
}

/// Writes one item's records into the log.
fn log_item(
    log: &mut LogWriter<std::io::BufWriter<std::fs::File>>,
    item: &Item,
) -> anyhow::Result<()> {
    match item {
        Item::Solution { filtered, smoothed } => {
            log.write(topic::NAV_SOLUTION, filtered)?;
            log.write(crate::NAV_SOLUTION_SMOOTHED, smoothed)?;
        }
        Item::Diagnostics(d) => log.write(topic::NAV_AID_DIAGNOSTICS, d)?,
        Item::Truth(t) => log.write(topic::TRUTH, t)?,
        Item::LateAid(r) => log.write(topic::NAV_LATE_AIDS, r)?,
    }
    Ok(())
}

/// Runs `pass` with a [`Batches`] whose items are written into `log` and `csv`, in order, by
/// two threads; returns the pass's result once everything it handed over is written. A writer's
/// error stops the pass at its next hand-over and is the error returned.
pub(crate) fn write_beside<R>(
    log: &mut LogWriter<std::io::BufWriter<std::fs::File>>,
    csv: &mut (dyn Write + Send),
    pass: impl FnOnce(&mut Batches) -> anyhow::Result<R>,
) -> anyhow::Result<R> {
    std::thread::scope(|scope| {
        let (tx, to_log) = sync_channel::<Vec<Item>>(BATCHES_IN_FLIGHT);
        let (log_done, to_csv) = sync_channel::<Vec<Item>>(BATCHES_IN_FLIGHT);
        let (give_back, emptied) = sync_channel::<Vec<Item>>(2 * BATCHES_IN_FLIGHT + 2);
        let log_writer = scope.spawn(move || -> anyhow::Result<()> {
            for batch in to_log {
                for item in &batch {
                    log_item(log, item)?;
                }
                if log_done.send(batch).is_err() {
                    // The CSV's writer stopped: its error is the one to report.
                    break;
                }
            }
            Ok(())
        });
        let csv_writer = scope.spawn(move || -> anyhow::Result<()> {
            for mut batch in to_csv {
                for item in &batch {
                    if let Item::Solution { smoothed, .. } = item {
                        auvnav_core::csv::write_nav_row(csv, smoothed)?;
                    }
                }
                batch.clear();
                // The pass may have ended; a batch nobody takes is dropped.
                let _ = give_back.try_send(batch);
            }
            Ok(())
        });
        let mut batches = Batches {
            tx,
            emptied,
            batch: Vec::with_capacity(BATCH),
        };
        let result = pass(&mut batches).and_then(|r| {
            batches.hand_over()?;
            Ok(r)
        });
        drop(batches);
        let logged = log_writer
            .join()
            .map_err(|_| anyhow::anyhow!("the log writer panicked"))?;
        let rows = csv_writer
            .join()
            .map_err(|_| anyhow::anyhow!("the CSV writer panicked"))?;
        logged?;
        rows?;
        result
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn log_writer(dir: &std::path::Path) -> LogWriter<std::io::BufWriter<std::fs::File>> {
        let header = auvnav_log::LogHeader::new("writer test", "");
        LogWriter::create(&dir.join("out.mcap"), &header).expect("log")
    }

    fn solution(k: u64) -> Item {
        let s = NavSolutionV1 {
            host_time_ns: k,
            ..Default::default()
        };
        Item::Solution {
            filtered: s,
            smoothed: s,
        }
    }

    /// Every item handed over is written, in order, before the call returns.
    #[test]
    fn every_item_is_written_in_order() {
        let dir = std::env::temp_dir().join(format!("auvnav-writer-{}", std::process::id()));
        std::fs::create_dir_all(&dir).expect("dir");
        let mut log = log_writer(&dir);
        let mut csv = Vec::new();
        let n = write_beside(&mut log, &mut csv, |out| {
            for k in 0..3000 {
                out.push(solution(k))?;
            }
            Ok(3000)
        })
        .expect("written");
        assert_eq!(n, 3000);
        assert_eq!(log.messages(), 6000);
        let text = String::from_utf8(csv).expect("utf-8");
        let times: Vec<&str> = text
            .lines()
            .map(|l| l.split(',').next().unwrap_or(""))
            .collect();
        assert_eq!(times.len(), 3000);
        assert_eq!(times[0], "0");
        assert_eq!(times[2999], "2999");
        let _ = std::fs::remove_dir_all(&dir);
    }

    /// A full disk under the CSV stops the pass and is the error returned.
    #[test]
    fn a_write_error_stops_the_pass_and_is_returned() {
        let Ok(mut full) = std::fs::OpenOptions::new().write(true).open("/dev/full") else {
            return;
        };
        let dir = std::env::temp_dir().join(format!("auvnav-writer-full-{}", std::process::id()));
        std::fs::create_dir_all(&dir).expect("dir");
        let mut log = log_writer(&dir);
        let mut pushed = 0;
        let e = write_beside(&mut log, &mut full, |out| {
            for k in 0..1_000_000 {
                out.push(solution(k))?;
                pushed += 1;
            }
            Ok(())
        })
        .expect_err("no space");
        assert!(format!("{e:#}").contains("No space"), "{e:#}");
        assert!(pushed < 1_000_000, "the pass went on to the end");
        let _ = std::fs::remove_dir_all(&dir);
    }
}
