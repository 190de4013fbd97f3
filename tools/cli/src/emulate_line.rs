//! The timing of an emulated device's serial line: a frame's bytes go out at the line's baud rate
//! (a frame starts when it is due or when the line is free of the one before), delivered to the
//! pseudo-terminal in pieces of about a millisecond as they would have arrived, optionally each
//! piece late by a random delay (a USB adapter's latency timer, a busy host) in order. The
//! emulator records, per frame, when its first byte was on the line and when it was written,
//! so that a test can measure a driver's time stamps against them.

use auvnav_sim::rng::Rng;
use std::collections::BinaryHeap;
use std::io::Write;

/// A piece is about this long on the line (ns).
const PIECE_NS: f64 = 1e6;

/// One piece of a frame waiting to be written.
#[derive(Debug)]
struct Piece {
    due_ns: u64,
    /// Order of queuing: pieces due at the same time go out in it.
    order: u64,
    device: usize,
    /// The frame's number (from 1) among all frames queued.
    frame: u64,
    bytes: Vec<u8>,
    /// For a frame's first piece: the frame's record for the send-time file.
    first_of: Option<SendRecord>,
}

impl PartialEq for Piece {
    fn eq(&self, o: &Self) -> bool {
        (self.due_ns, self.order) == (o.due_ns, o.order)
    }
}
impl Eq for Piece {}
impl PartialOrd for Piece {
    fn partial_cmp(&self, o: &Self) -> Option<std::cmp::Ordering> {
        Some(self.cmp(o))
    }
}
impl Ord for Piece {
    // The earliest first out of the (max-)heap.
    fn cmp(&self, o: &Self) -> std::cmp::Ordering {
        (o.due_ns, o.order).cmp(&(self.due_ns, self.order))
    }
}

/// When a frame was sent: on the line and into the terminal.
#[derive(Debug, Clone)]
pub struct SendRecord {
    pub device: &'static str,
    /// The log message it carries: imu, mag, dvl, usbl, ranges (SeaTrac LBL ping responses) or gnss.
    pub kind: &'static str,
    /// Its number among the device's frames of that kind (from 0).
    pub index: u64,
    /// When its first byte was on the line (CLOCK_MONOTONIC ns).
    pub line_ns: u64,
}

/// The lines of every emulated device, their queued pieces, and the send-time file.
pub struct Lines {
    /// One character's time on the line (ns); 0: a frame goes out whole when due.
    character_ns: f64,
    jitter_ns: f64,
    /// Per device: when its line is free, and when its last piece is delivered.
    free_ns: Vec<u64>,
    delivered_ns: Vec<u64>,
    queue: BinaryHeap<Piece>,
    order: u64,
    frames: u64,
    send_times: Option<std::io::BufWriter<std::fs::File>>,
    rng: Rng,
}

impl Lines {
    /// Lines for `devices` devices at `baud` (8N1; `None`: no pacing), pieces late by up to
    /// `jitter_ms`, send times written to `send_times` when given.
    pub fn new(
        devices: usize,
        baud: Option<u32>,
        jitter_ms: f64,
        send_times: Option<&std::path::Path>,
        seed: u64,
    ) -> anyhow::Result<Self> {
        let send_times = match send_times {
            Some(p) => {
                let mut w = std::io::BufWriter::new(
                    std::fs::File::create(p)
                        .map_err(|e| anyhow::anyhow!("creating {}: {e}", p.display()))?,
                );
                writeln!(w, "device,kind,index,line_ns,due_ns,written_ns")?;
                Some(w)
            }
            None => None,
        };
        Ok(Lines {
            character_ns: baud.map_or(0.0, |b| {
                auvnav_drivers::line_time::character_time_ns(b, 8, false, 1)
            }),
            jitter_ns: jitter_ms * 1e6,
            free_ns: vec![0; devices],
            delivered_ns: vec![0; devices],
            queue: BinaryHeap::new(),
            order: 0,
            frames: 0,
            send_times,
            rng: Rng::new(seed, "emulate-line"),
        })
    }

    /// Queues a frame of `device` due on its line at `due_ns`.
    pub fn send(&mut self, device: usize, due_ns: u64, bytes: Vec<u8>, mut record: SendRecord) {
        let start = due_ns.max(self.free_ns[device]);
        let tau = self.character_ns;
        self.free_ns[device] = start + (bytes.len() as f64 * tau).round() as u64;
        record.line_ns = start;
        let per_piece = if tau > 0.0 {
            ((PIECE_NS / tau).floor() as usize).max(1)
        } else {
            bytes.len().max(1)
        };
        self.frames += 1;
        let mut first = Some(record);
        let mut end = 0usize;
        for chunk in bytes.chunks(per_piece) {
            end += chunk.len();
            let arrived = start + (end as f64 * tau).round() as u64;
            let late = if self.jitter_ns > 0.0 {
                (self.rng.uniform() * self.jitter_ns) as u64
            } else {
                0
            };
            let due = (arrived + late).max(self.delivered_ns[device]);
            self.delivered_ns[device] = due;
            self.order += 1;
            self.queue.push(Piece {
                due_ns: due,
                order: self.order,
                device,
                frame: self.frames,
                bytes: chunk.to_vec(),
                first_of: first.take(),
            });
        }
    }

    /// Writes every piece due by `until_ns` (all with `None`), sleeping until each is due;
    /// `write(device, frame, bytes)` writes a piece of a frame and says whether the terminal took
    /// it.
    pub fn deliver(
        &mut self,
        until_ns: Option<u64>,
        mut write: impl FnMut(usize, u64, &[u8]) -> bool,
    ) -> anyhow::Result<()> {
        while let Some(p) = self.queue.peek() {
            if until_ns.is_some_and(|u| p.due_ns > u) {
                break;
            }
            let Some(p) = self.queue.pop() else { break };
            let now = auvnav_drivers::clock::monotonic_ns();
            if p.due_ns > now {
                std::thread::sleep(std::time::Duration::from_nanos(p.due_ns - now));
            }
            let written_ns = auvnav_drivers::clock::monotonic_ns();
            let ok = write(p.device, p.frame, &p.bytes);
            if let (Some(r), Some(w)) = (p.first_of, self.send_times.as_mut())
                && ok
            {
                writeln!(
                    w,
                    "{},{},{},{},{},{written_ns}",
                    r.device, r.kind, r.index, r.line_ns, p.due_ns
                )?;
            }
        }
        Ok(())
    }

    /// Flushes the send-time file.
    pub fn finish(&mut self) -> anyhow::Result<()> {
        if let Some(w) = self.send_times.as_mut() {
            w.flush()?;
        }
        Ok(())
    }
}

/// One frame's send times, read back from a send-time file.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct SentFrame {
    pub device: String,
    pub kind: String,
    pub index: u64,
    pub line_ns: u64,
    /// When its first piece was due in the terminal (its bytes arrived, plus the jitter).
    pub due_ns: u64,
    pub written_ns: u64,
}

/// Reads a send-time file written by `auvnav emulate --send-times`.
pub fn read_send_times(path: &std::path::Path) -> anyhow::Result<Vec<SentFrame>> {
    let text = std::fs::read_to_string(path)
        .map_err(|e| anyhow::anyhow!("reading {}: {e}", path.display()))?;
    let mut out = Vec::new();
    for (i, line) in text.lines().enumerate().skip(1) {
        let f: Vec<&str> = line.split(',').collect();
        let bad = || anyhow::anyhow!("{} line {}: {line:?}", path.display(), i + 1);
        let [device, kind, index, line_ns, due_ns, written_ns] = f[..] else {
            return Err(bad());
        };
        out.push(SentFrame {
            device: device.to_string(),
            kind: kind.to_string(),
            index: index.parse().map_err(|_| bad())?,
            line_ns: line_ns.parse().map_err(|_| bad())?,
            due_ns: due_ns.parse().map_err(|_| bad())?,
            written_ns: written_ns.parse().map_err(|_| bad())?,
        });
    }
    Ok(out)
}

/// A driver's time stamps of one kind of frame against the emulator's send times (µs; positive:
/// the stamp is later).
#[derive(Debug, Clone, serde::Serialize)]
pub struct StampErrors {
    /// The log message the frames carried: imu or usbl.
    pub kind: String,
    pub frames: u64,
    /// Stamp − when the frame's first byte was on the line (the device's own time).
    pub against_line_us: crate::percentiles::Percentiles,
    /// Stamp − when the emulator wrote the frame's first piece into the terminal.
    pub against_written_us: crate::percentiles::Percentiles,
    /// How late the emulator itself wrote the first piece (written − due): the test rig's own lag,
    /// which no driver can see.
    pub emulator_late_us: crate::percentiles::Percentiles,
}

/// The stamps (host ns, in the order published) of the frames of `kind` against their send
/// times; `None` when the counts differ (a frame lost on the way: no one-to-one match).
pub fn stamp_errors(sent: &[SentFrame], kind: &str, stamps: &[u64]) -> Option<StampErrors> {
    let mut frames: Vec<&SentFrame> = sent.iter().filter(|f| f.kind == kind).collect();
    frames.sort_by_key(|f| f.index);
    if frames.len() != stamps.len() || frames.is_empty() {
        return None;
    }
    let us = |a: u64, b: u64| (a as f64 - b as f64) * 1e-3;
    let list = |f: &dyn Fn(&SentFrame, u64) -> f64| {
        crate::percentiles::percentiles(frames.iter().zip(stamps).map(|(x, &t)| f(x, t)).collect())
    };
    Some(StampErrors {
        kind: kind.to_string(),
        frames: frames.len() as u64,
        against_line_us: list(&|x, t| us(t, x.line_ns)),
        against_written_us: list(&|x, t| us(t, x.written_ns)),
        emulator_late_us: list(&|x, _| us(x.written_ns, x.due_ns)),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// At 9600 baud a 96-byte frame takes 100 ms: it goes out in 1 ms pieces, the next frame waits
    /// for the line, and the send times say when each first byte was on it.
    #[test]
    fn frames_go_out_at_the_line_rate_and_wait_for_the_line() {
        let dir = std::env::temp_dir().join(format!("auvnav-line-{}", std::process::id()));
        std::fs::create_dir_all(&dir).expect("dir");
        let file = dir.join("send.csv");
        let mut lines = Lines::new(1, Some(9_600), 0.0, Some(&file), 1).expect("lines");
        let t0 = auvnav_drivers::clock::monotonic_ns() + 1_000_000;
        let record = |index| SendRecord {
            device: "usbl",
            kind: "usbl",
            index,
            line_ns: 0,
        };
        lines.send(0, t0, vec![b'a'; 96], record(0));
        lines.send(0, t0 + 10_000_000, vec![b'b'; 10], record(1));
        let mut writes: Vec<(u64, usize)> = Vec::new();
        lines
            .deliver(None, |_, _, b| {
                writes.push((auvnav_drivers::clock::monotonic_ns(), b.len()));
                true
            })
            .expect("deliver");
        lines.finish().expect("flush");
        // One character every 1.04 ms: one byte per piece, none before its time on the line
        // (the last of the frame 95 characters after its start; measured from the start, not
        // from the first write, which a loaded machine may make late).
        assert_eq!(writes.len(), 106);
        let span = writes[95].0 - t0;
        assert!(span >= 98_000_000, "the frame took {span} ns on the line");
        let sent = read_send_times(&file).expect("read");
        assert_eq!(sent.len(), 2);
        assert_eq!(sent[0].line_ns, t0);
        // The second frame was due 10 ms after the first but the line was busy for 100 ms.
        assert_eq!(sent[1].line_ns, t0 + 100_000_000);
        assert!(
            sent.iter()
                .all(|s| s.written_ns >= s.due_ns && s.due_ns > s.line_ns)
        );
        std::fs::remove_dir_all(&dir).ok();
    }
}
