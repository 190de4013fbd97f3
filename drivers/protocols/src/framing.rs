//! What every stream decoder shares: a bounded input buffer and the counters a driver reports in
//! its health message.

use serde::Serialize;

/// Counters of a stream decoder.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize)]
pub struct DecoderStats {
    /// Bytes pushed in.
    pub bytes: u64,
    /// Frames decoded (checksum good).
    pub frames: u64,
    /// Frames whose checksum failed (the decoder resynchronises after them).
    pub checksum_errors: u64,
    /// Times the decoder had to search for the next frame start.
    pub resyncs: u64,
    /// Bytes thrown away while searching for a frame start (including failed frames).
    pub bytes_skipped: u64,
    /// Frames with a good checksum whose content could not be used (bad lengths, offsets).
    pub malformed: u64,
    /// Bytes dropped because the buffer was full (the reader fell behind).
    pub overflow_bytes: u64,
}

/// Room every decoder buffer keeps for one read on top of its largest frame: a driver reading
/// up to this many bytes at a time never overflows a decoder it drains after each read.
pub const READ_ALLOWANCE: usize = 64 * 1024;

/// Buffer capacity for a protocol whose frames are at most `max_frame` bytes.
pub fn capacity_for(max_frame: usize) -> usize {
    2 * max_frame + READ_ALLOWANCE
}

/// A byte buffer with a hard capacity; the oldest bytes go first when it overflows.
#[derive(Debug, Clone)]
pub struct BoundedBuffer {
    data: Vec<u8>,
    start: usize,
    capacity: usize,
}

impl BoundedBuffer {
    pub fn new(capacity: usize) -> Self {
        BoundedBuffer {
            data: Vec::with_capacity(capacity.min(1 << 16)),
            start: 0,
            capacity,
        }
    }

    /// Appends `bytes`, dropping the oldest bytes beyond the capacity; returns how many were
    /// dropped.
    pub fn push(&mut self, bytes: &[u8]) -> u64 {
        self.compact();
        self.data.extend_from_slice(bytes);
        let excess = self.len().saturating_sub(self.capacity);
        self.start += excess;
        excess as u64
    }

    /// The bytes not yet consumed.
    pub fn as_slice(&self) -> &[u8] {
        &self.data[self.start..]
    }

    pub fn len(&self) -> usize {
        self.data.len() - self.start
    }

    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Drops `n` bytes from the front.
    pub fn consume(&mut self, n: usize) {
        self.start += n.min(self.len());
    }

    fn compact(&mut self) {
        if self.start > 0 && (self.start >= self.data.len() / 2 || self.start > 1 << 16) {
            self.data.drain(..self.start);
            self.start = 0;
        }
    }
}

/// Little-endian readers that return `None` instead of panicking past the end.
pub(crate) trait ReadLe {
    fn u8_at(&self, i: usize) -> Option<u8>;
    fn u16_at(&self, i: usize) -> Option<u16>;
    fn i16_at(&self, i: usize) -> Option<i16>;
    fn u32_at(&self, i: usize) -> Option<u32>;
    fn i32_at(&self, i: usize) -> Option<i32>;
    fn f32_at(&self, i: usize) -> Option<f32>;
    fn f64_at(&self, i: usize) -> Option<f64>;
}

impl ReadLe for [u8] {
    fn u8_at(&self, i: usize) -> Option<u8> {
        self.get(i).copied()
    }
    fn u16_at(&self, i: usize) -> Option<u16> {
        Some(u16::from_le_bytes(self.get(i..i + 2)?.try_into().ok()?))
    }
    fn i16_at(&self, i: usize) -> Option<i16> {
        Some(i16::from_le_bytes(self.get(i..i + 2)?.try_into().ok()?))
    }
    fn u32_at(&self, i: usize) -> Option<u32> {
        Some(u32::from_le_bytes(self.get(i..i + 4)?.try_into().ok()?))
    }
    fn i32_at(&self, i: usize) -> Option<i32> {
        Some(i32::from_le_bytes(self.get(i..i + 4)?.try_into().ok()?))
    }
    fn f32_at(&self, i: usize) -> Option<f32> {
        Some(f32::from_le_bytes(self.get(i..i + 4)?.try_into().ok()?))
    }
    fn f64_at(&self, i: usize) -> Option<f64> {
        Some(f64::from_le_bytes(self.get(i..i + 8)?.try_into().ok()?))
    }
}

/// The input side every stream decoder shares: a bounded buffer sized for the protocol, the
/// counters, and whether it is searching for a frame start (a resync counts once per search).
#[derive(Debug, Clone)]
pub struct FrameBuffer {
    pub(crate) buf: BoundedBuffer,
    pub stats: DecoderStats,
    searching: bool,
    /// Stream offset of the first byte not yet consumed (bytes pushed before it were consumed or
    /// dropped).
    offset: u64,
    /// Stream offset of the first byte of the last frame taken.
    frame_start: u64,
}

impl FrameBuffer {
    /// A buffer for frames of at most `max_frame` bytes (see [`capacity_for`]).
    pub fn new(max_frame: usize) -> Self {
        FrameBuffer {
            buf: BoundedBuffer::new(capacity_for(max_frame)),
            stats: DecoderStats::default(),
            searching: false,
            offset: 0,
            frame_start: 0,
        }
    }

    pub fn push(&mut self, bytes: &[u8]) {
        self.stats.bytes += bytes.len() as u64;
        let dropped = self.buf.push(bytes);
        self.stats.overflow_bytes += dropped;
        self.offset += dropped;
    }

    /// Stream offset (bytes pushed before it) of the first byte of the last frame taken: where
    /// the line's timing places the frame.
    pub fn frame_start(&self) -> u64 {
        self.frame_start
    }

    /// Drops `n` bytes from the front, keeping the stream offset.
    fn advance(&mut self, n: usize) {
        let n = n.min(self.buf.len());
        self.buf.consume(n);
        self.offset += n as u64;
    }

    /// The bytes not yet consumed.
    pub fn data(&self) -> &[u8] {
        self.buf.as_slice()
    }

    /// Throws away `n` bytes that belong to no frame.
    pub fn skip(&mut self, n: usize) {
        if !self.searching {
            self.searching = true;
            self.stats.resyncs += 1;
        }
        self.stats.bytes_skipped += n as u64;
        self.advance(n);
    }

    /// Consumes a frame of `n` bytes that decoded.
    pub fn take_frame(&mut self, n: usize) {
        self.frame_start = self.offset;
        self.advance(n);
        self.searching = false;
        self.stats.frames += 1;
    }

    /// Consumes a delimited frame of `n` bytes that failed its checks (the caller counts why).
    pub fn reject_frame(&mut self, n: usize) {
        self.stats.bytes_skipped += n as u64;
        self.advance(n);
        self.searching = false;
    }

    /// Consumes `n` bytes that need no accounting (line ends between frames).
    pub fn consume(&mut self, n: usize) {
        self.advance(n);
    }
}

/// What a driver, `auvnav decode` and the benchmarks need from any stream decoder: push bytes,
/// pull complete frames (frames that fail their checks are counted in the stats and skipped).
pub trait StreamDecoder {
    type Frame: serde::Serialize;
    fn push(&mut self, bytes: &[u8]);
    fn next_good_frame(&mut self) -> Option<Self::Frame>;
    /// At the end of a finite capture: frames still recoverable from the buffered bytes.
    fn finish_capture(&mut self) -> Vec<Self::Frame> {
        Vec::new()
    }
    fn stats(&self) -> &DecoderStats;
    /// Stream offset of the first byte of the last frame returned (see
    /// [`FrameBuffer::frame_start`]).
    fn frame_start(&self) -> u64;
}

/// Feeds `bytes` in reads of `read_size` and hands every frame to `frame`.
pub fn decode_stream<D: StreamDecoder>(
    d: &mut D,
    bytes: &[u8],
    read_size: usize,
    mut frame: impl FnMut(D::Frame),
) {
    for chunk in bytes.chunks(read_size.max(1)) {
        d.push(chunk);
        while let Some(f) = d.next_good_frame() {
            frame(f);
        }
    }
    for f in d.finish_capture() {
        frame(f);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bounded_buffer_keeps_the_newest_bytes() {
        let mut b = BoundedBuffer::new(4);
        assert_eq!(b.push(&[1, 2, 3]), 0);
        assert_eq!(b.push(&[4, 5, 6]), 2);
        assert_eq!(b.as_slice(), &[3, 4, 5, 6]);
        b.consume(3);
        assert_eq!(b.as_slice(), &[6]);
        b.consume(10);
        assert!(b.is_empty());
    }
}
