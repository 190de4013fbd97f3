//! Top-level record framing of an MCAP file, for a reader that survives corruption.
//!
//! A parser that stops at the first record it cannot use would lose everything after one
//! flipped byte in the middle of a log. The framer reads the file record by record (opcode,
//! length, body) and hands whole records to the log reader; when the reader refuses one (a chunk
//! whose CRC fails, or that does not decompress), it drops that record and goes on with the next.
//! When the framing itself is lost (an opcode that does not exist, a length beyond the record
//! limit), the framer scans forward for the next chunk record: opcode 0x06 followed by a length,
//! a chunk header whose compression is one MCAP names and whose records length agrees with the
//! record's length.

use std::io::Read;

/// The MCAP magic at both ends of a file.
pub const MAGIC: [u8; 8] = [0x89, b'M', b'C', b'A', b'P', b'0', b'\r', b'\n'];
const OP_CHUNK: u8 = 0x06;
const OP_FOOTER: u8 = 0x02;
/// The opcodes MCAP defines (0x01 header … 0x0F data end).
const OPCODES: std::ops::RangeInclusive<u8> = 0x01..=0x0F;

/// What the framer found next.
#[derive(Debug, PartialEq)]
pub enum Frame {
    /// A whole record at `offset` (opcode, length and body), `len` bytes from the buffer start.
    Record { opcode: u8, offset: u64, len: usize },
    /// The footer's trailing magic: the end of a finished file.
    EndMagic,
    /// The file ends here, on a record boundary or inside a record.
    Eof { inside_record: bool },
    /// The framing was lost at `offset`: `skipped` bytes were passed over to the next chunk
    /// record.
    Resynchronised { offset: u64, skipped: u64 },
}

/// Buffered top-level framing over a byte source.
pub struct Framer<R> {
    source: R,
    buf: Vec<u8>,
    /// Start of the unconsumed bytes in `buf`.
    start: usize,
    /// File offset of `buf[start]`.
    offset: u64,
    eof: bool,
    limit: usize,
    after_footer: bool,
}

impl<R: Read> Framer<R> {
    pub fn new(source: R, record_length_limit: usize) -> Self {
        Framer {
            source,
            buf: Vec::new(),
            start: 0,
            offset: 0,
            eof: false,
            limit: record_length_limit,
            after_footer: false,
        }
    }

    /// Makes at least `n` unconsumed bytes available unless the file ends first; the number
    /// available.
    fn fill(&mut self, n: usize) -> std::io::Result<usize> {
        while self.buf.len() - self.start < n && !self.eof {
            if self.start > 0 && self.start >= self.buf.len() / 2 {
                self.buf.drain(..self.start);
                self.start = 0;
            }
            let have = self.buf.len();
            let want = (n - (have - self.start)).max(1 << 20);
            self.buf.resize(have + want, 0);
            let got = loop {
                match self.source.read(&mut self.buf[have..]) {
                    Ok(k) => break k,
                    Err(e) if e.kind() == std::io::ErrorKind::Interrupted => continue,
                    Err(e) => {
                        self.buf.truncate(have);
                        return Err(e);
                    }
                }
            };
            self.buf.truncate(have + got);
            if got == 0 {
                self.eof = true;
            }
        }
        Ok(self.buf.len() - self.start)
    }

    /// The unconsumed bytes.
    pub fn bytes(&self) -> &[u8] {
        &self.buf[self.start..]
    }

    /// Marks `n` bytes consumed.
    pub fn consume(&mut self, n: usize) {
        self.start += n;
        self.offset += n as u64;
    }

    /// Reads and checks the leading magic; false when the file does not start with it.
    pub fn start_magic(&mut self) -> std::io::Result<bool> {
        if self.fill(MAGIC.len())? < MAGIC.len() || self.bytes()[..8] != MAGIC {
            return Ok(false);
        }
        self.consume(MAGIC.len());
        Ok(true)
    }

    /// The record length field at `at` (past the opcode) of the unconsumed bytes.
    fn length_at(&self, at: usize) -> u64 {
        let b = &self.bytes()[at + 1..at + 9];
        u64::from_le_bytes(b.try_into().unwrap_or([0; 8]))
    }

    /// The next frame. A record stays unconsumed until the caller calls [`Framer::consume`] with
    /// its length.
    pub fn next(&mut self) -> std::io::Result<Frame> {
        if self.after_footer {
            let n = self.fill(MAGIC.len())?;
            if n >= MAGIC.len() && self.bytes()[..8] == MAGIC {
                self.consume(MAGIC.len());
                return Ok(Frame::EndMagic);
            }
            self.after_footer = false;
        }
        let avail = self.fill(9)?;
        if avail == 0 {
            return Ok(Frame::Eof {
                inside_record: false,
            });
        }
        if avail < 9 {
            return Ok(Frame::Eof {
                inside_record: true,
            });
        }
        let opcode = self.bytes()[0];
        let len = self.length_at(0);
        if !OPCODES.contains(&opcode) || len > self.limit as u64 {
            return self.resynchronise(1);
        }
        let total = 9 + len as usize;
        if self.fill(total)? < total {
            return Ok(Frame::Eof {
                inside_record: true,
            });
        }
        if opcode == OP_FOOTER {
            self.after_footer = true;
        }
        Ok(Frame::Record {
            opcode,
            offset: self.offset,
            len: total,
        })
    }

    /// Scans from `from` bytes past the front for the next chunk record; consumes what it passes
    /// over.
    fn resynchronise(&mut self, from: usize) -> std::io::Result<Frame> {
        let offset = self.offset;
        let mut skipped = 0u64;
        let mut i = from;
        loop {
            // A chunk record's fixed part: opcode, length, start, end, size, CRC, compression
            // length (45 bytes), then the compression name and the records length.
            let avail = self.fill(i + 64)?;
            if avail < i + 45 {
                // No chunk follows: the file ends inside the damaged record, as a killed
                // writer's does (its last chunk's length is patched in only when it is done).
                self.consume(avail);
                return Ok(Frame::Eof {
                    inside_record: true,
                });
            }
            if self.bytes()[i] == OP_CHUNK && self.chunk_header_at(i) {
                self.consume(i);
                return Ok(Frame::Resynchronised {
                    offset,
                    skipped: skipped + i as u64,
                });
            }
            i += 1;
            if i > 1 << 20 {
                // Keep the buffer bounded while passing over a long damaged stretch.
                self.consume(i - 64);
                skipped += (i - 64) as u64;
                i = 64;
            }
        }
    }

    /// Whether a chunk record's header starts at `i`: a length within the limit, a compression
    /// MCAP names, and a records length that agrees with the record's length.
    fn chunk_header_at(&self, i: usize) -> bool {
        let b = self.bytes();
        let len = self.length_at(i);
        if len > self.limit as u64 || len < 36 {
            return false;
        }
        let c = i + 9 + 28;
        let Some(clen) = b
            .get(c..c + 4)
            .map(|x| u32::from_le_bytes(x.try_into().unwrap_or([0; 4])) as usize)
        else {
            return false;
        };
        if !matches!(clen, 0 | 3 | 4) {
            return false;
        }
        let Some(name) = b.get(c + 4..c + 4 + clen) else {
            return false;
        };
        if !matches!(name, b"" | b"lz4" | b"zstd") {
            return false;
        }
        let r = c + 4 + clen;
        let Some(records_len) = b
            .get(r..r + 8)
            .map(|x| u64::from_le_bytes(x.try_into().unwrap_or([0; 8])))
        else {
            return false;
        };
        records_len.checked_add((28 + 4 + clen + 8) as u64) == Some(len)
    }

    /// A chunk record's message time span (log time, ns), from its header at the front.
    pub fn chunk_span(&self) -> Option<(u64, u64)> {
        let b = self.bytes();
        let u = |k: usize| {
            b.get(9 + k..9 + k + 8)
                .map(|x| u64::from_le_bytes(x.try_into().unwrap_or([0; 8])))
        };
        Some((u(0)?, u(8)?))
    }
}
