//! When a frame was on the line: the arrival of its first byte, estimated from when the reads
//! returned and how many bytes followed it at the line's baud rate ([`ArrivalClock`]), and a
//! device's own clock translated to host time ([`DeviceClock`]). Pure: the caller passes the
//! host times.
//!
//! A read returns after its last byte arrived, and bytes cannot arrive faster than the line
//! carries them, so a read of `n` bytes that returned at `t` says the byte `i` of it (0-based)
//! was in by `t − (n − 1 − i)·τ`, τ being one character's time on the line. Every later read
//! gives such a bound too; the earliest bound is the estimate. A driver that was late to read
//! several frames at once gives each its own time, no later than the truth, instead of one late
//! time for all — as far as the line was busy: bytes that waited in the port's buffer while the
//! line was idle cannot be placed by their count alone. A device with its own clock can: the
//! [`DeviceClock`] fits host time to device time along the lower envelope of the first-byte
//! times (the reads that came soonest after the bytes), which late reads cannot pull up.

use std::collections::VecDeque;

/// One character's time on a serial line (ns): start bit, data bits, parity bit, stop bits.
pub fn character_time_ns(baud: u32, data_bits: u8, parity: bool, stop_bits: u8) -> f64 {
    let bits = 1 + u32::from(data_bits) + u32::from(parity) + u32::from(stop_bits);
    f64::from(bits) / f64::from(baud.max(1)) * 1e9
}

/// Reads remembered: enough to place the first byte of the largest frame a decoder can hold,
/// at one byte per read.
const READS_KEPT: usize = 512;

/// The arrival times of a byte stream's bytes, from the reads that returned them.
#[derive(Debug, Clone)]
pub struct ArrivalClock {
    character_ns: f64,
    /// (stream offset just past the read's last byte, host time at read return), oldest first.
    reads: VecDeque<(u64, u64)>,
    /// Bytes read so far (the stream offset of the next byte).
    offset: u64,
    /// The last frame stamped: its first byte's stream offset and its stamp.
    last_frame: Option<(u64, u64)>,
}

impl ArrivalClock {
    /// A clock for a line that carries one character every `character_ns` (see
    /// [`character_time_ns`]; 0 for a link without a line rate, where each byte is placed at the
    /// return of the read that brought it).
    pub fn new(character_ns: f64) -> Self {
        ArrivalClock {
            character_ns: if character_ns.is_finite() {
                character_ns.max(0.0)
            } else {
                0.0
            },
            reads: VecDeque::with_capacity(READS_KEPT),
            offset: 0,
            last_frame: None,
        }
    }

    /// Records a read of `n` bytes that returned at `host_ns`.
    pub fn read(&mut self, n: usize, host_ns: u64) {
        if n == 0 {
            return;
        }
        self.offset += n as u64;
        if self.reads.len() == READS_KEPT {
            self.reads.pop_front();
        }
        self.reads.push_back((self.offset, host_ns));
    }

    /// The stream offset of the next byte to be read.
    pub fn offset(&self) -> u64 {
        self.offset
    }

    /// Forgets the reads (a reopened port: the bytes before it came over another connection).
    pub fn restart(&mut self) {
        self.reads.clear();
        self.last_frame = None;
    }

    /// The stamp of a frame whose first byte is at stream `offset`: its arrival bound
    /// ([`ArrivalClock::arrival_ns`]), but never before the previous frame's stamp plus the
    /// characters between the two first bytes at the line rate (the line cannot carry them
    /// faster), and always after it. A read that brings several frames bounds the later ones
    /// more tightly than an earlier read bounded the first, so the bounds alone can go back.
    /// The same frame asked again gets the same stamp.
    pub fn frame_ns(&mut self, offset: u64) -> Option<u64> {
        if let Some((o, t)) = self.last_frame
            && o == offset
        {
            return Some(t);
        }
        let mut stamp = self.arrival_ns(offset)?;
        if let Some((o, t)) = self.last_frame
            && offset > o
        {
            // Not after the read that brought the first byte: the previous stamp may have been
            // a loose bound.
            let line = ((offset - o) as f64 * self.character_ns).round() as u64;
            let brought = self.returned_ns(offset).unwrap_or(u64::MAX);
            stamp = stamp.max((t + line).min(brought)).max(t + 1);
        }
        self.last_frame = Some((offset, stamp));
        Some(stamp)
    }

    /// The return time of the read that brought the byte at stream `offset`, if remembered.
    fn returned_ns(&self, offset: u64) -> Option<u64> {
        // From the newest, as `arrival_ns` walks them: the frame's byte is in a recent read.
        self.reads
            .iter()
            .rev()
            .take_while(|&&(end, _)| end > offset)
            .last()
            .map(|&(_, t)| t)
    }

    /// The latest time (host ns) the byte at stream `offset` can have arrived: the earliest of the
    /// bounds the reads that returned it and every later read give. `None` for a byte not read
    /// yet, or read before the last restart.
    pub fn arrival_ns(&self, offset: u64) -> Option<u64> {
        if offset >= self.offset {
            return None;
        }
        let mut best: Option<u64> = None;
        for &(end, t) in self.reads.iter().rev() {
            if end <= offset {
                break;
            }
            let after = (end - 1 - offset) as f64 * self.character_ns;
            let bound = t.saturating_sub(after.round() as u64);
            best = Some(best.map_or(bound, |b| b.min(bound)));
        }
        // A byte older than every read remembered: the oldest read's bound.
        best.or_else(|| self.reads.front().map(|&(_, t)| t))
    }
}

/// Block length of the clock model's minima (s of device time).
const BLOCK_S: f64 = 1.0;
/// Blocks the model fits (the newest): half a minute of device time.
const BLOCKS_KEPT: usize = 32;
/// Blocks needed before the model is used.
const BLOCKS_NEEDED: usize = 4;
/// A step of the device clock this far from the host's (s) is a jump: the model starts again.
const JUMP_S: f64 = 0.5;

/// A device's clock translated to host time: `host = origin + device + offset(device)`, the
/// offset a straight line (the clock's offset and its rate against the host's) fitted along the
/// lower envelope of first-byte times against device times. Each point's delay above the
/// envelope is the line, the port and the scheduler; the envelope is where the delay was least,
/// so a late read moves no stamp. The fitted line is the one under every block minimum that
/// lies closest to them on average (an edge of their lower convex hull), which needs no
/// threshold and follows a drift; a device clock stepping back, or away from the host's by more
/// than half a second, starts the model again (counted).
#[derive(Debug, Clone)]
pub struct DeviceClock {
    /// The device clock's wrap-around (ns), when it has one.
    modulus_ns: Option<u64>,
    /// The first point: (device ns, host ns); times below are relative to it.
    origin: Option<(u64, u64)>,
    /// The last point: raw device ns, unwrapped device ns since the origin, host ns.
    last: Option<(u64, u64, u64)>,
    /// Completed blocks' minima (device s since the origin, host − device ns since the origin).
    blocks: VecDeque<(f64, f64)>,
    /// The current block: its index and its minimum so far.
    current: Option<(i64, f64, f64)>,
    /// Intercept (ns) and slope (ns per s of device time) of the offset.
    fit: Option<(f64, f64)>,
    /// The last stamp given: stamps increase.
    last_stamp: Option<u64>,
    resets: u64,
}

impl DeviceClock {
    /// A model of a device clock that wraps around at `modulus_ns` (or never).
    pub fn new(modulus_ns: Option<u64>) -> Self {
        DeviceClock {
            modulus_ns,
            origin: None,
            last: None,
            blocks: VecDeque::with_capacity(BLOCKS_KEPT + 1),
            current: None,
            fit: None,
            last_stamp: None,
            resets: 0,
        }
    }

    /// Times the model started again after a jump of the device clock.
    pub fn resets(&self) -> u64 {
        self.resets
    }

    /// Whether the model has enough of the clock's history to translate it.
    pub fn established(&self) -> bool {
        self.fit.is_some()
    }

    /// The clock's rate against the host's (host s per device s), once established.
    pub fn rate(&self) -> Option<f64> {
        self.fit.map(|(_, b)| 1.0 + b * 1e-9)
    }

    /// Forgets the history (a reopened port: the device may have restarted).
    pub fn restart(&mut self) {
        self.origin = None;
        self.last = None;
        self.blocks.clear();
        self.current = None;
        self.fit = None;
    }

    /// Takes in a frame the device stamped `device_ns` whose first byte arrived by `arrival_ns`
    /// (host), and returns its host time: the model's translation once established, never
    /// later than the arrival (the arrival is a bound the model may only improve on), always
    /// after the previous stamp (at least 1 ns: where the model or the first bytes' bounds place
    /// a sample before the previous one, the consumer integrates the device's own step).
    pub fn stamp(&mut self, device_ns: u64, arrival_ns: u64) -> u64 {
        let unwrapped = match self.last {
            None => None,
            Some((raw, unwrapped, host)) => {
                let mut step = device_ns as i128 - raw as i128;
                if step < 0
                    && let Some(m) = self.modulus_ns
                {
                    step += i128::from(m);
                }
                let rate = self.rate().unwrap_or(1.0);
                let host_step = arrival_ns as i128 - host as i128;
                let gap_s = (host_step as f64 - step as f64 * rate) * 1e-9;
                (step >= 0 && gap_s.abs() <= JUMP_S).then_some(unwrapped + step as u64)
            }
        };
        let unwrapped = match unwrapped {
            Some(u) => u,
            None => {
                if self.last.is_some() {
                    self.resets += 1;
                    self.restart();
                }
                self.origin = Some((device_ns, arrival_ns));
                0
            }
        };
        self.last = Some((device_ns, unwrapped, arrival_ns));
        let (_, host0) = self.origin.unwrap_or((device_ns, arrival_ns));
        let x_s = unwrapped as f64 * 1e-9;
        let y = arrival_ns as f64 - host0 as f64 - unwrapped as f64;
        self.take_point(x_s, y);
        let mut stamp = arrival_ns;
        if let Some((a, b)) = self.fit {
            let predicted = host0 as f64 + unwrapped as f64 + a + b * x_s;
            if predicted.is_finite() && predicted >= 0.0 && (predicted as u64) < arrival_ns {
                stamp = predicted.round() as u64;
            }
        }
        if let Some(last) = self.last_stamp {
            stamp = stamp.max(last + 1);
        }
        self.last_stamp = Some(stamp);
        stamp
    }

    fn take_point(&mut self, x_s: f64, y: f64) {
        let block = (x_s / BLOCK_S).floor() as i64;
        match self.current {
            Some((b, bx, by)) if b == block => {
                if y < by {
                    self.current = Some((b, x_s, y));
                } else {
                    self.current = Some((b, bx, by));
                }
            }
            previous => {
                if let Some((_, bx, by)) = previous {
                    self.blocks.push_back((bx, by));
                    if self.blocks.len() > BLOCKS_KEPT {
                        self.blocks.pop_front();
                    }
                    self.refit();
                }
                self.current = Some((block, x_s, y));
            }
        }
    }

    /// The line under every block minimum closest to them on average: the edge of their lower
    /// convex hull over their mean abscissa.
    fn refit(&mut self) {
        if self.blocks.len() < BLOCKS_NEEDED {
            self.fit = None;
            return;
        }
        let points: Vec<(f64, f64)> = self.blocks.iter().copied().collect();
        let mut hull: Vec<(f64, f64)> = Vec::with_capacity(points.len());
        for &p in &points {
            while hull.len() >= 2 {
                let (o, a) = (hull[hull.len() - 2], hull[hull.len() - 1]);
                let cross = (a.0 - o.0) * (p.1 - o.1) - (a.1 - o.1) * (p.0 - o.0);
                if cross <= 0.0 {
                    hull.pop();
                } else {
                    break;
                }
            }
            hull.push(p);
        }
        let mean_x = points.iter().map(|p| p.0).sum::<f64>() / points.len() as f64;
        let edge = hull
            .windows(2)
            .find(|w| w[1].0 >= mean_x)
            .or_else(|| hull.windows(2).last());
        self.fit = edge.and_then(|w| {
            let (p, q) = (w[0], w[1]);
            let dx = q.0 - p.0;
            (dx > 0.0).then(|| {
                let b = (q.1 - p.1) / dx;
                (p.1 - b * p.0, b)
            })
        });
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_character_is_ten_bits_on_an_8n1_line() {
        assert!((character_time_ns(115_200, 8, false, 1) - 86_805.555).abs() < 0.01);
        assert!((character_time_ns(9_600, 7, true, 2) - 1_145_833.33).abs() < 0.01);
    }

    /// Two frames read at once, late: each gets the time its first byte came in at the line
    /// rate, the earlier read's bound kept when a later read is looser.
    #[test]
    fn a_late_read_places_each_byte_back_at_the_line_rate() {
        let mut c = ArrivalClock::new(1_000.0);
        c.read(10, 100_000);
        assert_eq!(c.arrival_ns(0), Some(91_000));
        assert_eq!(c.arrival_ns(9), Some(100_000));
        // 20 more bytes, read 50 µs late: bytes 10.. were in by 130 µs at the latest.
        c.read(20, 150_000);
        assert_eq!(c.arrival_ns(10), Some(131_000));
        assert_eq!(c.arrival_ns(5), Some(96_000));
        // A later read of a busy line tightens the bound of bytes read late before it: 30 more
        // bytes by 160 µs put byte 10 at 111 µs.
        c.read(30, 160_000);
        assert_eq!(c.arrival_ns(10), Some(111_000));
        assert_eq!(c.arrival_ns(60), None, "not read yet");
    }

    /// A frame read alone and late, then two frames brought by one read: the second frame's
    /// bound from that read lies before the first frame's looser one, yet its stamp follows it
    /// by at least the first frame's characters on the line, but never after the read that
    /// brought it; frames over a link without a line rate, read together, are 1 ns apart; a
    /// frame asked again keeps its stamp.
    #[test]
    fn frame_stamps_increase_at_least_at_the_line_rate() {
        let mut c = ArrivalClock::new(1_000.0);
        c.read(10, 200_000); // frame A: bytes 0..10, read 100 µs late
        assert_eq!(c.frame_ns(0), Some(191_000));
        c.read(40, 210_000); // frames B (10..30) and C (30..50), in by 210 µs
        assert_eq!(
            c.arrival_ns(10),
            Some(171_000),
            "B's bound is before A's stamp"
        );
        assert_eq!(
            c.frame_ns(10),
            Some(201_000),
            "A's stamp plus A's 10 characters"
        );
        assert_eq!(c.frame_ns(10), Some(201_000), "the same frame again");
        // C's bound is 191 µs and B's stamp plus B's characters 221 µs, after the read that
        // brought C returned: B's stamp was loose, and C's stamp is that read's return.
        assert_eq!(c.frame_ns(30), Some(210_000));
        let mut tcp = ArrivalClock::new(0.0);
        tcp.read(100, 5_000);
        assert_eq!(tcp.frame_ns(0), Some(5_000));
        assert_eq!(tcp.frame_ns(50), Some(5_001));
        tcp.restart();
        tcp.read(10, 4_000);
        assert_eq!(
            tcp.frame_ns(100),
            Some(4_000),
            "a new connection starts afresh"
        );
    }

    #[test]
    fn a_link_without_a_line_rate_places_bytes_at_their_read() {
        let mut c = ArrivalClock::new(0.0);
        c.read(100, 5_000);
        assert_eq!(c.arrival_ns(0), Some(5_000));
        c.restart();
        assert_eq!(c.arrival_ns(0), None);
    }

    /// A device clock running 50 ppm fast, its frames read with delays of 0.1–3 ms and now and
    /// then 80 ms late: the stamps follow the send times within the least delay.
    #[test]
    fn the_device_clock_follows_the_least_delays_and_ignores_late_reads() {
        let mut clock = DeviceClock::new(Some(1 << 32));
        let mut worst_after = 0i64;
        let mut previous = 0u64;
        let mut state = 7u64;
        for i in 0..20_000u64 {
            let send = 1_000_000_000 + i * 2_000_000; // 500 Hz
            let device = ((send as f64 * (1.0 + 50e-6)) as u64 + 123_456_789) % (1 << 32);
            state = state
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            let u = (state >> 33) as f64 / (1u64 << 31) as f64;
            let delay = if i % 97 == 0 {
                80_000_000
            } else {
                100_000 + (u * 2_900_000.0) as u64
            };
            let s = clock.stamp(device, send + delay);
            assert!(s > previous, "stamps increase: {s} after {previous} at {i}");
            previous = s;
            if i > 3_000 {
                let err = s as i64 - send as i64;
                assert!(err >= 0, "stamp before the send time at {i}: {err} ns");
                worst_after = worst_after.max(err);
            }
        }
        assert!(
            worst_after < 400_000,
            "worst {worst_after} ns after the send"
        );
        assert_eq!(clock.resets(), 0, "the wrap-around is not a jump");
        let rate = clock.rate().expect("established");
        assert!((rate - 1.0 / (1.0 + 50e-6)).abs() < 5e-6, "rate {rate}");
    }

    #[test]
    fn a_device_clock_that_steps_back_starts_the_model_again() {
        let mut clock = DeviceClock::new(None);
        for i in 0..10_000u64 {
            clock.stamp(5_000_000_000 + i * 1_000_000, 1_000_000_000 + i * 1_000_000);
        }
        assert!(clock.established());
        // The device restarts: its clock begins at zero again.
        let s = clock.stamp(0, 1_000_000_000 + 10_000 * 1_000_000 + 500);
        assert_eq!(clock.resets(), 1);
        assert!(!clock.established());
        assert_eq!(s, 11_000_000_500);
    }
}
