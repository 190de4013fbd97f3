//! KVH 1750/1775 IMU binary messages.
//!
//! Format A (`FE 81 FF 55`, 36 bytes): header, gyro x y z (f32), accelerometer x y z (f32, g),
//! status (bits 0–2 gyro x y z valid, bits 4–6 accelerometer x y z valid), sequence 0–127,
//! temperature i16, CRC-32/MPEG-2 over bytes 0..32. Format B (`FE 81 FF 56`, 40 bytes) inserts a
//! u32 time stamp (us) after the temperature. Everything big-endian. Whether the gyro fields are
//! rates or angle increments, in radians or degrees, is the unit's configuration (=ROTFMT,
//! =ROTUNITS), not part of the message: the driver configuration says which.

pub mod to_device;
pub mod to_schema;

use crate::framing::{DecoderStats, FrameBuffer};
use serde::Serialize;

pub const HEADER_A: [u8; 4] = [0xfe, 0x81, 0xff, 0x55];
pub const HEADER_B: [u8; 4] = [0xfe, 0x81, 0xff, 0x56];
pub const LEN_A: usize = 36;
pub const LEN_B: usize = 40;

/// CRC-32/MPEG-2: polynomial 0x04C11DB7, initial 0xFFFFFFFF, no reflection, no final xor (the
/// `crc` crate's catalogue entry, table-driven).
pub fn crc32_mpeg2(bytes: &[u8]) -> u32 {
    const CRC: crc::Crc<u32> = crc::Crc::<u32>::new(&crc::CRC_32_MPEG_2);
    CRC.checksum(bytes)
}

#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct KvhSample {
    /// Gyro outputs as configured (rate or increment; rad or deg).
    pub gyro: [f32; 3],
    /// Accelerometer outputs (g, or g*s for increments).
    pub accel: [f32; 3],
    pub status: u8,
    pub sequence: u8,
    /// Temperature as configured (degrees C or F, 1 or 1/100 resolution).
    pub temperature_raw: i16,
    /// Format B time stamp (us).
    pub timestamp_us: Option<u32>,
}

impl KvhSample {
    pub fn gyro_valid(&self) -> [bool; 3] {
        [0, 1, 2].map(|i| self.status & (1 << i) != 0)
    }
    pub fn accel_valid(&self) -> [bool; 3] {
        [4, 5, 6].map(|i| self.status & (1 << i) != 0)
    }
}

fn f32_be(b: &[u8], i: usize) -> f32 {
    f32::from_be_bytes([b[i], b[i + 1], b[i + 2], b[i + 3]])
}

/// Decodes one message of known length (checksum already verified).
fn decode(m: &[u8]) -> KvhSample {
    let b_format = m.len() == LEN_B;
    KvhSample {
        gyro: [f32_be(m, 4), f32_be(m, 8), f32_be(m, 12)],
        accel: [f32_be(m, 16), f32_be(m, 20), f32_be(m, 24)],
        status: m[28],
        sequence: m[29],
        temperature_raw: i16::from_be_bytes([m[30], m[31]]),
        timestamp_us: b_format.then(|| u32::from_be_bytes([m[32], m[33], m[34], m[35]])),
    }
}

/// Encodes a sample as format A, or format B when it has a time stamp.
pub fn encode(s: &KvhSample) -> Vec<u8> {
    let mut m = Vec::with_capacity(LEN_B);
    m.extend_from_slice(if s.timestamp_us.is_some() {
        &HEADER_B
    } else {
        &HEADER_A
    });
    for v in s.gyro.iter().chain(s.accel.iter()) {
        m.extend_from_slice(&v.to_be_bytes());
    }
    m.push(s.status);
    m.push(s.sequence);
    m.extend_from_slice(&s.temperature_raw.to_be_bytes());
    if let Some(t) = s.timestamp_us {
        m.extend_from_slice(&t.to_be_bytes());
    }
    let crc = crc32_mpeg2(&m);
    m.extend_from_slice(&crc.to_be_bytes());
    m
}

/// Incremental decoder for formats A and B.
#[derive(Debug, Clone)]
pub struct KvhDecoder {
    input: FrameBuffer,
}

impl Default for KvhDecoder {
    fn default() -> Self {
        Self::new()
    }
}

impl KvhDecoder {
    pub fn new() -> Self {
        KvhDecoder {
            input: FrameBuffer::new(LEN_B),
        }
    }

    pub fn push(&mut self, bytes: &[u8]) {
        self.input.push(bytes);
    }

    pub fn stats(&self) -> &DecoderStats {
        &self.input.stats
    }

    /// Stream offset of the first byte of the last frame returned.
    pub fn frame_start(&self) -> u64 {
        self.input.frame_start()
    }

    pub fn next_sample(&mut self) -> Option<KvhSample> {
        loop {
            let data = self.input.data();
            let pos = data.windows(4).position(|w| w == HEADER_A || w == HEADER_B);
            let Some(pos) = pos else {
                // Keep up to three bytes that may start a header.
                let n = data.len().saturating_sub(3);
                if n > 0 {
                    self.input.skip(n);
                }
                return None;
            };
            if pos > 0 {
                self.input.skip(pos);
                continue;
            }
            let len = if data[3] == HEADER_B[3] { LEN_B } else { LEN_A };
            if data.len() < len {
                return None;
            }
            let stored =
                u32::from_be_bytes([data[len - 4], data[len - 3], data[len - 2], data[len - 1]]);
            if crc32_mpeg2(&data[..len - 4]) != stored {
                self.input.stats.checksum_errors += 1;
                self.input.skip(1);
                continue;
            }
            let s = decode(&data[..len]);
            self.input.take_frame(len);
            return Some(s);
        }
    }
}

impl crate::framing::StreamDecoder for KvhDecoder {
    type Frame = KvhSample;
    fn push(&mut self, bytes: &[u8]) {
        KvhDecoder::push(self, bytes);
    }
    fn next_good_frame(&mut self) -> Option<KvhSample> {
        self.next_sample()
    }
    fn stats(&self) -> &DecoderStats {
        &self.input.stats
    }
    fn frame_start(&self) -> u64 {
        self.input.frame_start()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn crc32_mpeg2_check_value() {
        assert_eq!(crc32_mpeg2(b"123456789"), 0x0376_e6e7);
    }
}
