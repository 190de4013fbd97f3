//! The records of an MCAP chunk: the chunk record checked, its records decompressed in one call
//! into a buffer kept from chunk to chunk, and then handed out one at a time in place.
//!
//! A chunk is used whole or not at all: its length fields must agree, its compression must be
//! one this reader has (none or zstd), its records must decompress to exactly the size it states
//! (at most [`RECORD_LENGTH_LIMIT`](crate::RECORD_LENGTH_LIMIT)) and, when it carries a CRC, their
//! CRC must match before any of its records is handed out.

use std::ops::Range;

/// Why a chunk record was refused.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ChunkError {
    /// A length field points past the record (or the uncompressed size is beyond the limit).
    Framing,
    /// A compression other than none and zstd.
    Compression,
    /// The records do not decompress, or not to the size the chunk states.
    Decompression,
    /// The CRC of the uncompressed records does not match the chunk's.
    Crc,
}

/// The decompressed records of the chunk being read, and where the next one starts.
#[derive(Default)]
pub struct ChunkRecords {
    buf: Vec<u8>,
    pos: usize,
    decompressor: Option<zstd::bulk::Decompressor<'static>>,
}

/// An inner record: its opcode and where its body is in [`ChunkRecords::bytes`].
pub type InnerRecord = (u8, Range<usize>);

fn u32_at(b: &[u8], at: usize) -> Option<u32> {
    Some(u32::from_le_bytes(b.get(at..at + 4)?.try_into().ok()?))
}

fn u64_at(b: &[u8], at: usize) -> Option<u64> {
    Some(u64::from_le_bytes(b.get(at..at + 8)?.try_into().ok()?))
}

impl ChunkRecords {
    /// Takes a chunk record's body (what follows its opcode and length): message start and end
    /// time, uncompressed size and CRC, compression, records. On error nothing of it is kept.
    pub fn load(&mut self, body: &[u8], limit: usize) -> Result<(), ChunkError> {
        self.clear();
        let size = u64_at(body, 16).ok_or(ChunkError::Framing)?;
        let crc = u32_at(body, 24).ok_or(ChunkError::Framing)?;
        let name_len = u32_at(body, 28).ok_or(ChunkError::Framing)? as usize;
        let name = body
            .get(32..32usize.saturating_add(name_len))
            .ok_or(ChunkError::Framing)?;
        let at = 32 + name_len;
        let records_len = u64_at(body, at).ok_or(ChunkError::Framing)?;
        let records = usize::try_from(records_len)
            .ok()
            .and_then(|n| body.get(at + 8..(at + 8).checked_add(n)?))
            .ok_or(ChunkError::Framing)?;
        let size = usize::try_from(size)
            .ok()
            .filter(|s| *s <= limit)
            .ok_or(ChunkError::Framing)?;
        match name {
            b"" if records.len() == size => self.buf.extend_from_slice(records),
            b"" => return Err(ChunkError::Framing),
            b"zstd" => {
                self.buf.reserve(size);
                let d = match &mut self.decompressor {
                    Some(d) => d,
                    None => self.decompressor.insert(
                        zstd::bulk::Decompressor::new().map_err(|_| ChunkError::Decompression)?,
                    ),
                };
                let n = d
                    .decompress_to_buffer(records, &mut self.buf)
                    .map_err(|_| ChunkError::Decompression);
                if n != Ok(size) {
                    self.clear();
                    return Err(ChunkError::Decompression);
                }
            }
            _ => return Err(ChunkError::Compression),
        }
        // MCAP: a CRC of zero means none was computed.
        if crc != 0 && crc32fast::hash(&self.buf) != crc {
            self.clear();
            return Err(ChunkError::Crc);
        }
        Ok(())
    }

    /// Forgets the chunk being read.
    pub fn clear(&mut self) {
        self.buf.clear();
        self.pos = 0;
    }

    /// The decompressed records (for the ranges [`ChunkRecords::next_record`] hands out).
    pub fn bytes(&self) -> &[u8] {
        &self.buf
    }

    /// The next inner record; `None` at the end of the chunk, `Some(Err(()))` when a record's
    /// length runs past the chunk's end (the chunk is then done).
    pub fn next_record(&mut self) -> Option<Result<InnerRecord, ()>> {
        let rest = self.buf.len() - self.pos;
        if rest == 0 {
            return None;
        }
        let start = self.pos + 9;
        let record = (rest >= 9)
            .then(|| u64_at(&self.buf, self.pos + 1))
            .flatten()
            .and_then(|len| usize::try_from(len).ok())
            .and_then(|len| start.checked_add(len))
            .filter(|end| *end <= self.buf.len())
            .map(|end| (self.buf[self.pos], start..end));
        match record {
            Some((opcode, body)) => {
                self.pos = body.end;
                Some(Ok((opcode, body)))
            }
            None => {
                self.clear();
                Some(Err(()))
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A chunk body around `records`, compressed with zstd or not, with its CRC or none.
    fn chunk_body(records: &[u8], zstd: bool, crc: bool) -> Vec<u8> {
        let data = if zstd {
            zstd::bulk::compress(records, 1).expect("compress")
        } else {
            records.to_vec()
        };
        let name: &[u8] = if zstd { b"zstd" } else { b"" };
        let mut b = Vec::new();
        b.extend_from_slice(&1u64.to_le_bytes());
        b.extend_from_slice(&2u64.to_le_bytes());
        b.extend_from_slice(&(records.len() as u64).to_le_bytes());
        let c = if crc { crc32fast::hash(records) } else { 0 };
        b.extend_from_slice(&c.to_le_bytes());
        b.extend_from_slice(&(name.len() as u32).to_le_bytes());
        b.extend_from_slice(name);
        b.extend_from_slice(&(data.len() as u64).to_le_bytes());
        b.extend_from_slice(&data);
        b
    }

    fn record(opcode: u8, body: &[u8]) -> Vec<u8> {
        let mut r = vec![opcode];
        r.extend_from_slice(&(body.len() as u64).to_le_bytes());
        r.extend_from_slice(body);
        r
    }

    fn all(c: &mut ChunkRecords) -> Vec<Result<(u8, Vec<u8>), ()>> {
        let mut out = Vec::new();
        while let Some(r) = c.next_record() {
            out.push(r.map(|(op, range)| (op, c.bytes()[range].to_vec())));
        }
        out
    }

    #[test]
    fn records_come_out_as_they_went_in_with_either_compression() {
        let mut records = record(0x05, b"first message");
        records.extend(record(0x03, b""));
        records.extend(record(0x05, &[7u8; 3000]));
        let want = vec![
            Ok((0x05, b"first message".to_vec())),
            Ok((0x03, Vec::new())),
            Ok((0x05, vec![7u8; 3000])),
        ];
        let mut c = ChunkRecords::default();
        for (zstd, crc) in [(true, true), (true, false), (false, true), (false, false)] {
            c.load(&chunk_body(&records, zstd, crc), 1 << 20)
                .expect("a sound chunk");
            assert_eq!(all(&mut c), want, "zstd {zstd}, crc {crc}");
            assert_eq!(c.next_record(), None);
        }
    }

    #[test]
    fn a_damaged_chunk_is_refused_whole() {
        let records = record(0x05, &[1u8; 500]);
        let good = chunk_body(&records, true, true);
        let mut c = ChunkRecords::default();
        // A flipped byte in the compressed records: zstd refuses it or the CRC does.
        let mut flipped = good.clone();
        let last = flipped.len() - 20;
        flipped[last] ^= 0x40;
        let e = c.load(&flipped, 1 << 20).expect_err("damaged");
        assert!(
            matches!(e, ChunkError::Decompression | ChunkError::Crc),
            "{e:?}"
        );
        assert_eq!(c.next_record(), None, "nothing of a refused chunk is kept");
        // The CRC of other records.
        let mut wrong_crc = good.clone();
        wrong_crc[24] ^= 1;
        assert_eq!(c.load(&wrong_crc, 1 << 20), Err(ChunkError::Crc));
        // An uncompressed size that does not match what decompresses.
        let mut wrong_size = good.clone();
        wrong_size[16] ^= 1;
        assert_eq!(c.load(&wrong_size, 1 << 20), Err(ChunkError::Decompression));
        // Beyond the limit.
        assert_eq!(c.load(&good, 100), Err(ChunkError::Framing));
        // Cut short, and a compression this reader does not have.
        assert_eq!(
            c.load(&good[..good.len() - 1], 1 << 20),
            Err(ChunkError::Framing)
        );
        let mut lz4 = chunk_body(&records, false, true);
        lz4.splice(28..32, 3u32.to_le_bytes());
        lz4.splice(32..32, b"lz4".iter().copied());
        assert_eq!(c.load(&lz4, 1 << 20), Err(ChunkError::Compression));
        // Every prefix of a chunk is refused without a panic.
        for n in 0..good.len() {
            assert!(c.load(&good[..n], 1 << 20).is_err(), "prefix {n}");
        }
    }

    #[test]
    fn an_inner_record_running_past_the_chunk_ends_it() {
        let mut records = record(0x05, b"whole");
        let mut cut = record(0x05, b"cut short");
        cut.truncate(cut.len() - 3);
        records.extend(cut);
        let mut c = ChunkRecords::default();
        c.load(&chunk_body(&records, false, true), 1 << 20)
            .expect("the chunk itself is sound");
        assert_eq!(all(&mut c), vec![Ok((0x05, b"whole".to_vec())), Err(())]);
        // A length field too large for any buffer.
        let mut huge = vec![0x05];
        huge.extend_from_slice(&u64::MAX.to_le_bytes());
        c.load(&chunk_body(&huge, true, true), 1 << 20)
            .expect("sound chunk");
        assert_eq!(all(&mut c), vec![Err(())]);
    }
}
