//! What the backward pass needs of the forward run, kept compactly: one record per covariance
//! epoch with the updated and predicted covariances (the upper triangle of the states that have a
//! variance), the transition's navigation rows and parameter factors, and the sum of the
//! corrections applied at the epoch. A record is about 7 kB with all 26 states and 3 kB with the
//! 15 core states; at the default 20 Hz propagation an hour is 72 000 records. Beyond a memory
//! budget the records spill to a file in a folder the caller names, in chunks that the backward
//! pass reads from the last to the first.
//!
//! Word layout of a record (u64 words; floats by their bits): kind, time (ns), mask of the
//! states stored, then by kind — Start: the correction; Step: updated covariance, transition
//! (9 × 15 navigation rows, 11 parameter factors), predicted covariance, correction; End: the
//! updated covariance — and last the record's length in words, so the records can be read back
//! to front.

use super::rts::{Backward, BackwardRecord, SmoothError, SmoothedEpochs};
use crate::ekf::trace::{NAV_ROWS, Propagation, TraceEvent, transition_matrix};
use crate::ekf::{CORE, Covariance, N, PARAMS, StateVector};
use nalgebra::{DMatrix, DVector, SMatrix, SVector};
use std::io::{Read, Seek, SeekFrom, Write};
use std::path::{Path, PathBuf};

const START: u64 = 1;
const STEP: u64 = 2;
const END: u64 = 3;

/// Why the log could not be kept or read back.
#[derive(Debug, thiserror::Error)]
pub enum LogError {
    #[error("smoother spill file in {dir}: {source}")]
    Spill {
        dir: PathBuf,
        source: std::io::Error,
    },
    #[error("smoother log record {index} is malformed")]
    Malformed { index: u64 },
    #[error(transparent)]
    Smooth(#[from] SmoothError),
}

/// The open record: the epoch whose corrections are still being summed.
#[derive(Debug)]
enum Open {
    Start { time_ns: u64 },
    Step(Box<Propagation>),
}

struct Spill {
    dir: PathBuf,
    file: std::fs::File,
    /// (offset in bytes, length in words) of each chunk written.
    chunks: Vec<(u64, usize)>,
    written: u64,
}

/// The forward run's epochs for the backward pass.
pub struct SmootherLog {
    words: Vec<u64>,
    memory_budget_words: usize,
    spill: Option<Spill>,
    spill_dir: Option<PathBuf>,
    open: Option<(Open, StateVector)>,
    /// The last covariance known (the predicted one of the open epoch, or the start's), for a
    /// chain cut off by a restart.
    last_p: Covariance,
    pub records: u64,
    /// Chains (the forward filter started or restarted) begun.
    pub chains: u64,
    /// Non-finite corrections dropped (a diverging filter's last update).
    pub corrections_dropped: u64,
    error: Option<LogError>,
}

impl std::fmt::Debug for SmootherLog {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("SmootherLog")
            .field("records", &self.records)
            .field("chains", &self.chains)
            .field("memory_words", &self.words.len())
            .field(
                "spilled_chunks",
                &self.spill.as_ref().map(|s| s.chunks.len()),
            )
            .finish()
    }
}

impl Default for SmootherLog {
    fn default() -> Self {
        SmootherLog::in_memory()
    }
}

fn mask_of(diagonals: &[&Covariance]) -> u64 {
    (0..N)
        .filter(|&i| diagonals.iter().any(|p| p[(i, i)] > 0.0))
        .fold(0u64, |m, i| m | (1 << i))
}

fn indices(mask: u64) -> impl Iterator<Item = usize> + Clone {
    (0..N).filter(move |i| mask & (1 << i) != 0)
}

fn pack_symmetric(words: &mut Vec<u64>, p: &Covariance, mask: u64) {
    for j in indices(mask) {
        for i in indices(mask).take_while(|&i| i <= j) {
            words.push(p[(i, j)].to_bits());
        }
    }
}

fn pack_vector(words: &mut Vec<u64>, v: &StateVector, mask: u64) {
    words.extend(indices(mask).map(|i| v[i].to_bits()));
}

/// Reads words of one record from the front.
struct Reader<'a> {
    w: &'a [u64],
    at: usize,
}

impl Reader<'_> {
    fn next(&mut self) -> Option<u64> {
        let v = *self.w.get(self.at)?;
        self.at += 1;
        Some(v)
    }
    fn float(&mut self) -> Option<f64> {
        self.next().map(f64::from_bits)
    }
    fn symmetric(&mut self, mask: u64) -> Option<DMatrix<f64>> {
        let mut p = DMatrix::zeros(N, N);
        for j in indices(mask) {
            for i in indices(mask).take_while(|&i| i <= j) {
                let v = self.float()?;
                p[(i, j)] = v;
                p[(j, i)] = v;
            }
        }
        Some(p)
    }
    fn vector(&mut self, mask: u64) -> Option<DVector<f64>> {
        let mut v = DVector::zeros(N);
        for i in indices(mask) {
            v[i] = self.float()?;
        }
        Some(v)
    }
}

fn decode(w: &[u64]) -> Option<BackwardRecord> {
    let mut r = Reader { w, at: 0 };
    let kind = r.next()?;
    let time_ns = r.next()?;
    let mask = r.next()?;
    let rec = match kind {
        START => BackwardRecord::Start {
            time_ns,
            correction: r.vector(mask)?,
        },
        STEP => {
            let p_updated = r.symmetric(mask)?;
            let mut nav = SMatrix::<f64, NAV_ROWS, CORE>::zeros();
            for j in 0..CORE {
                for i in 0..NAV_ROWS {
                    nav[(i, j)] = r.float()?;
                }
            }
            let mut a = SVector::<f64, PARAMS>::zeros();
            for i in 0..PARAMS {
                a[i] = r.float()?;
            }
            let phi = transition_matrix(&nav, &a);
            BackwardRecord::Step {
                time_ns,
                p_updated,
                transition: DMatrix::from_iterator(N, N, phi.iter().copied()),
                p_predicted: r.symmetric(mask)?,
                correction: r.vector(mask)?,
            }
        }
        END => BackwardRecord::End {
            p_updated: r.symmetric(mask)?,
        },
        _ => return None,
    };
    // The length word follows.
    (r.at + 1 == w.len()).then_some(rec)
}

impl SmootherLog {
    /// A log kept in memory.
    pub fn in_memory() -> SmootherLog {
        SmootherLog {
            words: Vec::new(),
            memory_budget_words: usize::MAX,
            spill: None,
            spill_dir: None,
            open: None,
            last_p: Covariance::zeros(),
            records: 0,
            chains: 0,
            corrections_dropped: 0,
            error: None,
        }
    }

    /// A log that keeps at most `memory_budget_bytes` in memory and writes the rest to an
    /// unnamed temporary file in `dir` (removed when the log is dropped).
    pub fn spilling(dir: &Path, memory_budget_bytes: usize) -> SmootherLog {
        SmootherLog {
            memory_budget_words: (memory_budget_bytes / 8).max(1 << 16),
            spill_dir: Some(dir.to_path_buf()),
            ..SmootherLog::in_memory()
        }
    }

    /// Bytes written to the spill file so far.
    pub fn spilled_bytes(&self) -> u64 {
        self.spill.as_ref().map_or(0, |s| s.written)
    }

    /// Bytes held in memory.
    pub fn memory_bytes(&self) -> usize {
        self.words.capacity() * 8
    }

    /// A chain begins at `time_ns` with covariance `p` (the filter started or restarted). A
    /// chain still open is closed with the last covariance known.
    pub fn begin_chain(&mut self, time_ns: u64, p: &Covariance) {
        if self.open.is_some() {
            let last = self.last_p;
            self.end_chain(&last);
        }
        self.last_p = *p;
        self.chains += 1;
        self.open = Some((Open::Start { time_ns }, StateVector::zeros()));
    }

    /// Takes the filter's trace events (in order).
    pub fn take(&mut self, events: impl IntoIterator<Item = TraceEvent>) {
        for e in events {
            match e {
                TraceEvent::Correction(dx) => {
                    if let Some((_, sum)) = self.open.as_mut() {
                        if dx.iter().all(|v| v.is_finite()) {
                            *sum += *dx;
                        } else {
                            self.corrections_dropped += 1;
                        }
                    }
                }
                TraceEvent::Propagation(p) => {
                    if self.open.is_none() {
                        // A propagation without a chain: the filter's start was not seen.
                        continue;
                    }
                    self.flush_open();
                    self.last_p = p.p_predicted;
                    self.open = Some((Open::Step(p), StateVector::zeros()));
                }
            }
        }
    }

    /// Ends the open chain: `p` is the covariance after the last epoch's updates.
    pub fn end_chain(&mut self, p: &Covariance) {
        if self.open.is_none() {
            return;
        }
        self.flush_open();
        let mask = mask_of(&[p]);
        let mut w = vec![END, 0, mask];
        pack_symmetric(&mut w, p, mask);
        self.push_record(w);
    }

    fn flush_open(&mut self) {
        let Some((open, sum)) = self.open.take() else {
            return;
        };
        let w = match open {
            Open::Start { time_ns } => {
                let mask = (0..N).fold(0u64, |m, i| m | (1 << i));
                let mut w = vec![START, time_ns, mask];
                pack_vector(&mut w, &sum, mask);
                w
            }
            Open::Step(p) => {
                let mask = mask_of(&[&p.p_updated, &p.p_predicted]);
                let mut w = vec![STEP, p.time_ns, mask];
                pack_symmetric(&mut w, &p.p_updated, mask);
                w.extend(p.transition_nav.iter().map(|v| v.to_bits()));
                w.extend(p.transition_params.iter().map(|v| v.to_bits()));
                pack_symmetric(&mut w, &p.p_predicted, mask);
                pack_vector(&mut w, &sum, mask);
                w
            }
        };
        self.push_record(w);
    }

    fn push_record(&mut self, mut w: Vec<u64>) {
        w.push(w.len() as u64 + 1);
        self.words.extend_from_slice(&w);
        self.records += 1;
        if self.words.len() >= self.memory_budget_words
            && let Some(dir) = self.spill_dir.clone()
            && let Err(source) = self.spill_words()
        {
            // Memory keeps the records; the error is reported when the log is read back.
            self.spill_dir = None;
            self.error.get_or_insert(LogError::Spill { dir, source });
        }
    }

    fn spill_words(&mut self) -> std::io::Result<()> {
        if self.spill.is_none() {
            let dir = self.spill_dir.clone().unwrap_or_default();
            let file = tempfile_in(&dir)?;
            self.spill = Some(Spill {
                dir,
                file,
                chunks: Vec::new(),
                written: 0,
            });
        }
        let Some(s) = self.spill.as_mut() else {
            return Ok(());
        };
        // In pieces, so that spilling costs no second copy of the budget.
        let mut bytes = Vec::with_capacity(SPILL_PIECE_WORDS * 8);
        for piece in self.words.chunks(SPILL_PIECE_WORDS) {
            bytes.clear();
            bytes.extend(piece.iter().flat_map(|w| w.to_le_bytes()));
            s.file.write_all(&bytes)?;
        }
        s.chunks.push((s.written, self.words.len()));
        s.written += self.words.len() as u64 * 8;
        self.words.clear();
        Ok(())
    }

    /// Runs the backward pass over the whole log (the chains must have been ended).
    pub fn smooth(mut self) -> Result<(SmoothedEpochs, u64), LogError> {
        if let Some(e) = self.error.take() {
            return Err(e);
        }
        let mut back = Backward::new(N);
        let mut index = self.records;
        let mut walk = |w: &[u64], back: &mut Backward| -> Result<(), LogError> {
            let mut end = w.len();
            while end > 0 {
                let len = w[end - 1] as usize;
                index = index.saturating_sub(1);
                if len == 0 || len > end {
                    return Err(LogError::Malformed { index });
                }
                let rec = decode(&w[end - len..end]).ok_or(LogError::Malformed { index })?;
                back.push(rec)?;
                end -= len;
            }
            Ok(())
        };
        // The records in memory first (the latest), then each spilled chunk, read back into one
        // buffer in pieces: at most one chunk (the memory budget) is in memory at a time.
        let mut words = std::mem::take(&mut self.words);
        walk(&words, &mut back)?;
        if let Some(s) = self.spill.as_mut() {
            let err = |source| LogError::Spill {
                dir: s.dir.clone(),
                source,
            };
            let mut bytes = vec![0u8; SPILL_PIECE_WORDS * 8];
            for &(offset, len) in s.chunks.iter().rev() {
                words.clear();
                words.reserve(len);
                s.file.seek(SeekFrom::Start(offset)).map_err(err)?;
                let mut left = len;
                while left > 0 {
                    let n = left.min(SPILL_PIECE_WORDS);
                    let piece = &mut bytes[..n * 8];
                    s.file.read_exact(piece).map_err(err)?;
                    words.extend(piece.chunks_exact(8).map(|b| {
                        let mut w = [0u8; 8];
                        w.copy_from_slice(b);
                        u64::from_le_bytes(w)
                    }));
                    left -= n;
                }
                walk(&words, &mut back)?;
            }
        }
        let larger = back.larger_than_filtered;
        Ok((back.finish(), larger))
    }
}

/// Words per write or read of the spill file (8 MiB; 8 KiB in the unit tests, so that their
/// small chunks are read back in several pieces).
const SPILL_PIECE_WORDS: usize = if cfg!(test) { 1 << 10 } else { 1 << 20 };

/// A file in `dir` that no other process can open and that disappears when closed: created
/// under a unique name, then unlinked at once.
fn tempfile_in(dir: &Path) -> std::io::Result<std::fs::File> {
    let pid = std::process::id();
    for attempt in 0..1000u32 {
        let path = dir.join(format!(".auvnav-smoother-{pid}-{attempt}.spill"));
        match std::fs::OpenOptions::new()
            .read(true)
            .write(true)
            .create_new(true)
            .open(&path)
        {
            Ok(f) => {
                std::fs::remove_file(&path)?;
                return Ok(f);
            }
            Err(e) if e.kind() == std::io::ErrorKind::AlreadyExists => continue,
            Err(e) => return Err(e),
        }
    }
    Err(std::io::Error::other("no free spill file name"))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn dense(seed: f64) -> Covariance {
        let mut x = seed;
        let m = Covariance::from_fn(|_, _| {
            x = (x * 3.7 + 0.13).fract();
            x - 0.5
        });
        let mut p = m * m.transpose() + Covariance::identity() * 0.1;
        // Switch the lever-arm states off.
        for i in crate::ekf::DVL_LEVER..crate::ekf::DVL_LEVER + 3 {
            p.row_mut(i).fill(0.0);
            p.column_mut(i).fill(0.0);
        }
        p
    }

    fn propagation(t: u64, seed: f64) -> Box<Propagation> {
        let pu = dense(seed);
        let mut nav = SMatrix::<f64, NAV_ROWS, CORE>::zeros();
        for i in 0..NAV_ROWS {
            nav[(i, i)] = 1.0;
            nav[(i, (i + 3) % CORE)] = 0.05;
        }
        let a = SVector::<f64, PARAMS>::repeat(1.0);
        let phi = transition_matrix(&nav, &a);
        let pp = phi * pu * phi.transpose() + Covariance::identity() * 1e-3;
        let mut pp = pp;
        for i in crate::ekf::DVL_LEVER..crate::ekf::DVL_LEVER + 3 {
            pp.row_mut(i).fill(0.0);
            pp.column_mut(i).fill(0.0);
        }
        Box::new(Propagation {
            time_ns: t,
            p_updated: pu,
            transition_nav: nav,
            transition_params: a,
            p_predicted: pp,
        })
    }

    fn run(mut log: SmootherLog) -> SmoothedEpochs {
        log.begin_chain(0, &dense(0.3));
        for k in 1..200u64 {
            log.take([
                TraceEvent::Propagation(propagation(k * 50_000_000, 0.01 * k as f64)),
                TraceEvent::Correction(Box::new(StateVector::repeat(1e-3))),
            ]);
        }
        log.end_chain(&dense(0.9));
        let (epochs, _) = log.smooth().expect("smooth");
        epochs
    }

    #[test]
    fn records_spilled_to_a_file_give_the_same_epochs_as_in_memory() {
        let memory = run(SmootherLog::in_memory());
        let dir = std::env::temp_dir();
        let mut log = SmootherLog::spilling(&dir, 1);
        log.memory_budget_words = 3000; // a few records per chunk
        let spilled = run(log);
        assert_eq!(memory.len(), 200);
        assert_eq!(memory, spilled);
        assert!(memory.time_ns.windows(2).all(|w| w[0] < w[1]));
        assert!(memory.chain_start[0] && !memory.chain_start[1]);
    }

    #[test]
    fn a_cut_log_is_refused_not_misread() {
        let mut log = SmootherLog::in_memory();
        log.begin_chain(0, &dense(0.3));
        log.take([TraceEvent::Propagation(propagation(1, 0.2))]);
        log.end_chain(&dense(0.4));
        log.words.truncate(log.words.len() - 5);
        assert!(matches!(log.smooth(), Err(LogError::Malformed { .. })));
    }
}
