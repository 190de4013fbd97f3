//! Nortek DVL (DVL1000, DVL500) binary data records.
//!
//! A record is a 10-byte header — sync `A5`, header size (10), record id, family (`10`), data
//! size (u16), data checksum (u16), header checksum (u16) — followed by the data. Both checksums
//! are `0xB58C` plus the sum of the little-endian u16 words of what they cover (a last odd byte
//! counts as its value shifted left by 8), modulo 2^16; the header checksum covers the header's
//! first 8 bytes. Everything is little-endian.
//!
//! The bottom-track record (id `1B`) is decoded: version, offset of the velocity data, serial
//! number, the ping's date and time (years since 1900, month from 0, as C's `struct tm`, and units
//! of 100 µs), beams, error and status words, sound speed (m/s), temperature (°C), pressure
//! (dbar), then per beam velocity, vertical distance, figure of merit, two time differences and
//! the time of the velocity estimate, then the same five for X, Y, Z1 and Z2. A velocity of
//! −32.768 m/s and a figure of merit of 10 m/s mark an invalid value (what the device sends
//! without bottom lock). Other records with good checksums (water track, current profiles,
//! configuration replies) are returned as [`NortekFrame::Other`].

pub mod to_device;
pub mod to_schema;

use crate::framing::{DecoderStats, FrameBuffer, ReadLe};
use serde::Serialize;

pub const SYNC: u8 = 0xa5;
pub const HEADER_LEN: usize = 10;
pub const FAMILY_DVL: u8 = 0x10;
pub const ID_BOTTOM_TRACK: u8 = 0x1b;
/// Longest data part accepted (the bottom-track record is 212 bytes; profiles are longer).
pub const MAX_DATA: usize = 4096;
/// Bytes of the bottom-track record's data part.
pub const BOTTOM_TRACK_LEN: usize = 212;
/// The invalid-velocity sentinel (m/s).
pub const INVALID_VELOCITY: f32 = -32.768;
/// The invalid figure of merit (m/s).
pub const INVALID_FOM: f32 = 10.0;

/// The checksum of a Nortek record part.
pub fn checksum(bytes: &[u8]) -> u16 {
    let mut sum: u16 = 0xb58c;
    let mut words = bytes.chunks_exact(2);
    for w in &mut words {
        sum = sum.wrapping_add(u16::from_le_bytes([w[0], w[1]]));
    }
    if let [last] = words.remainder() {
        sum = sum.wrapping_add(u16::from(*last) << 8);
    }
    sum
}

/// The five values the record gives per beam or axis.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize)]
pub struct Estimate {
    /// Velocity (m/s; [`INVALID_VELOCITY`] when invalid).
    pub velocity_m_s: f32,
    /// Figure of merit (m/s; [`INVALID_FOM`] when invalid).
    pub figure_of_merit_m_s: f32,
    pub time_difference_1_s: f32,
    pub time_difference_2_s: f32,
    /// Time of the velocity estimate (s).
    pub time_of_estimate_s: f32,
}

impl Estimate {
    /// Both the velocity and its figure of merit are valid.
    pub fn valid(&self) -> bool {
        self.velocity_m_s != INVALID_VELOCITY
            && self.figure_of_merit_m_s != INVALID_FOM
            && self.velocity_m_s.is_finite()
            && self.figure_of_merit_m_s.is_finite()
    }
}

/// A bottom-track record.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct BottomTrack {
    pub version: u8,
    /// Bytes from the start of the data to the velocity data (36).
    pub offset_of_data: u8,
    pub serial_number: u32,
    /// Years since 1900, month 0..11, day, hour, minute, second.
    pub date_time: [u8; 6],
    /// Sub-second part of the ping time (units of 100 µs).
    pub time_100us: u16,
    pub beams: u16,
    pub error: u32,
    pub status: u32,
    pub sound_speed_m_s: f32,
    pub temperature_c: f32,
    pub pressure_dbar: f32,
    pub beam: [Estimate; 4],
    /// Vertical distance to the bottom along each beam (m; 0 when none).
    pub beam_distance_m: [f32; 4],
    /// X, Y, Z1, Z2 in the instrument frame.
    pub xyz: [Estimate; 4],
}

impl BottomTrack {
    /// The ping time as seconds since 1970-01-01 (UTC as the device's clock keeps it), or `None`
    /// when the date is not a calendar date.
    pub fn unix_time_s(&self) -> Option<f64> {
        let [y, mo, d, h, mi, s] = self.date_time;
        let t =
            chrono::NaiveDate::from_ymd_opt(1900 + i32::from(y), u32::from(mo) + 1, u32::from(d))?
                .and_hms_opt(u32::from(h), u32::from(mi), u32::from(s))?;
        Some(t.and_utc().timestamp() as f64 + f64::from(self.time_100us) * 1e-4)
    }

    /// The ping time in ns since 1970-01-01, exact; `None` before 1970 or when the date is not
    /// a calendar date.
    pub fn unix_time_ns(&self) -> Option<u64> {
        let [y, mo, d, h, mi, s] = self.date_time;
        let t =
            chrono::NaiveDate::from_ymd_opt(1900 + i32::from(y), u32::from(mo) + 1, u32::from(d))?
                .and_hms_opt(u32::from(h), u32::from(mi), u32::from(s))?;
        let secs = u64::try_from(t.and_utc().timestamp()).ok()?;
        Some(secs * 1_000_000_000 + u64::from(self.time_100us) * 100_000)
    }

    /// The date and time fields for a time in ns since 1970-01-01 (the inverse of
    /// [`BottomTrack::unix_time_s`] to 100 µs; `None` outside the years 1900–2155 the record
    /// can hold).
    pub fn date_time_of(unix_ns: u64) -> Option<([u8; 6], u16)> {
        use chrono::{Datelike, Timelike};
        let t = chrono::DateTime::from_timestamp((unix_ns / 1_000_000_000) as i64, 0)?;
        let year = u8::try_from(t.year() - 1900).ok()?;
        let fields = [
            year,
            (t.month() - 1) as u8,
            t.day() as u8,
            t.hour() as u8,
            t.minute() as u8,
            t.second() as u8,
        ];
        Some((fields, ((unix_ns % 1_000_000_000) / 100_000) as u16))
    }
}

/// A record with a good checksum the driver does not publish.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct OtherRecord {
    pub id: u8,
    pub family: u8,
    pub data_len: usize,
}

#[derive(Debug, Clone, PartialEq, Serialize)]
pub enum NortekFrame {
    BottomTrack(Box<BottomTrack>),
    Other(OtherRecord),
}

/// Decodes a bottom-track data part (checksum already verified); `None` when it is too short
/// or its offset to the velocity data is not where the record's layout puts it.
pub fn decode_bottom_track(d: &[u8]) -> Option<BottomTrack> {
    if d.len() < BOTTOM_TRACK_LEN {
        return None;
    }
    let offset = d.u8_at(1)?;
    if usize::from(offset) != 36 {
        return None;
    }
    let f = |i: usize| d.f32_at(i);
    let floats = |start: usize| -> Option<[f32; 4]> {
        Some([f(start)?, f(start + 4)?, f(start + 8)?, f(start + 12)?])
    };
    // Per beam: velocity, distance, FOM, dt1, dt2, time of estimate (16 bytes each group).
    let o = usize::from(offset);
    let (bv, bd, bf, b1, b2, bt) = (
        floats(o)?,
        floats(o + 16)?,
        floats(o + 32)?,
        floats(o + 48)?,
        floats(o + 64)?,
        floats(o + 80)?,
    );
    let x = o + 96;
    let (xv, xf, x1, x2, xt) = (
        floats(x)?,
        floats(x + 16)?,
        floats(x + 32)?,
        floats(x + 48)?,
        floats(x + 64)?,
    );
    let est = |v: [f32; 4], fom: [f32; 4], t1: [f32; 4], t2: [f32; 4], te: [f32; 4]| {
        std::array::from_fn(|k| Estimate {
            velocity_m_s: v[k],
            figure_of_merit_m_s: fom[k],
            time_difference_1_s: t1[k],
            time_difference_2_s: t2[k],
            time_of_estimate_s: te[k],
        })
    };
    Some(BottomTrack {
        version: d.u8_at(0)?,
        offset_of_data: offset,
        serial_number: d.u32_at(2)?,
        date_time: [
            d.u8_at(6)?,
            d.u8_at(7)?,
            d.u8_at(8)?,
            d.u8_at(9)?,
            d.u8_at(10)?,
            d.u8_at(11)?,
        ],
        time_100us: d.u16_at(12)?,
        beams: d.u16_at(14)?,
        error: d.u32_at(16)?,
        status: d.u32_at(20)?,
        sound_speed_m_s: f(24)?,
        temperature_c: f(28)?,
        pressure_dbar: f(32)?,
        beam: est(bv, bf, b1, b2, bt),
        beam_distance_m: bd,
        xyz: est(xv, xf, x1, x2, xt),
    })
}

/// Encodes a bottom-track record (header and data, both checksums).
pub fn encode_bottom_track(bt: &BottomTrack) -> Vec<u8> {
    let mut d = Vec::with_capacity(BOTTOM_TRACK_LEN);
    d.push(bt.version);
    d.push(36);
    d.extend_from_slice(&bt.serial_number.to_le_bytes());
    d.extend_from_slice(&bt.date_time);
    d.extend_from_slice(&bt.time_100us.to_le_bytes());
    d.extend_from_slice(&bt.beams.to_le_bytes());
    d.extend_from_slice(&bt.error.to_le_bytes());
    d.extend_from_slice(&bt.status.to_le_bytes());
    for v in [bt.sound_speed_m_s, bt.temperature_c, bt.pressure_dbar] {
        d.extend_from_slice(&v.to_le_bytes());
    }
    let put = |d: &mut Vec<u8>, vals: [f32; 4]| {
        for v in vals {
            d.extend_from_slice(&v.to_le_bytes());
        }
    };
    let col = |e: &[Estimate; 4], g: fn(&Estimate) -> f32| -> [f32; 4] {
        std::array::from_fn(|k| g(&e[k]))
    };
    put(&mut d, col(&bt.beam, |e| e.velocity_m_s));
    put(&mut d, bt.beam_distance_m);
    put(&mut d, col(&bt.beam, |e| e.figure_of_merit_m_s));
    put(&mut d, col(&bt.beam, |e| e.time_difference_1_s));
    put(&mut d, col(&bt.beam, |e| e.time_difference_2_s));
    put(&mut d, col(&bt.beam, |e| e.time_of_estimate_s));
    put(&mut d, col(&bt.xyz, |e| e.velocity_m_s));
    put(&mut d, col(&bt.xyz, |e| e.figure_of_merit_m_s));
    put(&mut d, col(&bt.xyz, |e| e.time_difference_1_s));
    put(&mut d, col(&bt.xyz, |e| e.time_difference_2_s));
    put(&mut d, col(&bt.xyz, |e| e.time_of_estimate_s));
    record(ID_BOTTOM_TRACK, &d)
}

/// A record of `id` around the data part `data`.
pub fn record(id: u8, data: &[u8]) -> Vec<u8> {
    let mut r = Vec::with_capacity(HEADER_LEN + data.len());
    r.extend_from_slice(&[SYNC, HEADER_LEN as u8, id, FAMILY_DVL]);
    r.extend_from_slice(&(data.len() as u16).to_le_bytes());
    r.extend_from_slice(&checksum(data).to_le_bytes());
    let h = checksum(&r);
    r.extend_from_slice(&h.to_le_bytes());
    r.extend_from_slice(data);
    r
}

/// Why a delimited record was not used.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum NortekError {
    #[error("data checksum {found:#06x}, computed {computed:#06x}")]
    DataChecksum { found: u16, computed: u16 },
    #[error("bottom-track record of {0} bytes does not decode")]
    Malformed(usize),
}

/// Incremental decoder of Nortek DVL records.
#[derive(Debug, Clone)]
pub struct NortekDecoder {
    input: FrameBuffer,
}

impl Default for NortekDecoder {
    fn default() -> Self {
        Self::new()
    }
}

impl NortekDecoder {
    pub fn new() -> Self {
        NortekDecoder {
            input: FrameBuffer::new(HEADER_LEN + MAX_DATA),
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

    /// The next record; `None` when more bytes are needed. A header whose checksum fails is a
    /// false sync (the search goes on one byte later); a record whose data checksum fails is
    /// counted and returned as an error, and decoding goes on after it.
    pub fn next_frame(&mut self) -> Option<Result<NortekFrame, NortekError>> {
        loop {
            let data = self.input.data();
            let Some(pos) = data.iter().position(|&b| b == SYNC) else {
                let n = data.len();
                if n > 0 {
                    self.input.skip(n);
                }
                return None;
            };
            if pos > 0 {
                self.input.skip(pos);
                continue;
            }
            if data.len() < HEADER_LEN {
                return None;
            }
            let header = &data[..HEADER_LEN];
            let header_ok = usize::from(header[1]) == HEADER_LEN
                && header.u16_at(8) == Some(checksum(&header[..8]));
            let data_len = usize::from(header.u16_at(4).unwrap_or(u16::MAX));
            if !header_ok || data_len > MAX_DATA {
                if header_ok {
                    self.input.stats.malformed += 1;
                }
                self.input.skip(1);
                continue;
            }
            let total = HEADER_LEN + data_len;
            if data.len() < total {
                return None;
            }
            let (id, family) = (header[2], header[3]);
            let found = header.u16_at(6).unwrap_or(0);
            let body = &data[HEADER_LEN..total];
            let computed = checksum(body);
            if found != computed {
                self.input.stats.checksum_errors += 1;
                // The header was good: the record's length is trusted and skipped whole.
                self.input.reject_frame(total);
                return Some(Err(NortekError::DataChecksum { found, computed }));
            }
            if id == ID_BOTTOM_TRACK {
                return match decode_bottom_track(body) {
                    Some(bt) => {
                        self.input.take_frame(total);
                        Some(Ok(NortekFrame::BottomTrack(Box::new(bt))))
                    }
                    None => {
                        self.input.stats.malformed += 1;
                        self.input.reject_frame(total);
                        Some(Err(NortekError::Malformed(data_len)))
                    }
                };
            }
            self.input.take_frame(total);
            return Some(Ok(NortekFrame::Other(OtherRecord {
                id,
                family,
                data_len,
            })));
        }
    }
}

impl crate::framing::StreamDecoder for NortekDecoder {
    type Frame = NortekFrame;
    fn push(&mut self, bytes: &[u8]) {
        NortekDecoder::push(self, bytes)
    }
    fn next_good_frame(&mut self) -> Option<NortekFrame> {
        loop {
            match self.next_frame()? {
                Ok(f) => return Some(f),
                Err(_) => continue,
            }
        }
    }
    fn stats(&self) -> &DecoderStats {
        NortekDecoder::stats(self)
    }
    fn frame_start(&self) -> u64 {
        self.input.frame_start()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sample() -> BottomTrack {
        let e = |v: f32| Estimate {
            velocity_m_s: v,
            figure_of_merit_m_s: 0.003,
            time_difference_1_s: 0.01,
            time_difference_2_s: 0.02,
            time_of_estimate_s: 0.5,
        };
        BottomTrack {
            version: 1,
            offset_of_data: 36,
            serial_number: 4242,
            date_time: [126, 10, 25, 18, 30, 5],
            time_100us: 1234,
            beams: 4,
            error: 0,
            status: 0x000f_f00f,
            sound_speed_m_s: 1500.0,
            temperature_c: 10.5,
            pressure_dbar: 40.25,
            beam: [e(0.8), e(-0.7), e(0.1), e(-0.2)],
            beam_distance_m: [12.0, 12.5, 11.9, 12.1],
            xyz: [e(1.5), e(-0.25), e(0.05), e(0.04)],
        }
    }

    #[test]
    fn encode_then_decode_gives_the_record_back_in_any_split() {
        let bt = sample();
        let bytes = encode_bottom_track(&bt);
        assert_eq!(bytes.len(), HEADER_LEN + BOTTOM_TRACK_LEN);
        for split in [1, 7, 10, 11, 100, bytes.len()] {
            let mut d = NortekDecoder::new();
            let mut got = Vec::new();
            for chunk in bytes.chunks(split) {
                d.push(chunk);
                while let Some(f) = d.next_frame() {
                    got.push(f.expect("good record"));
                }
            }
            assert_eq!(got, vec![NortekFrame::BottomTrack(Box::new(bt.clone()))]);
            assert_eq!(d.stats().frames, 1);
        }
    }

    #[test]
    fn the_ping_time_is_the_calendar_date() {
        // 2026-11-25 18:30:05.1234 UTC.
        let t = sample().unix_time_s().expect("a date");
        assert!((t - 1_795_631_405.123_4).abs() < 1e-6, "{t}");
        let mut bad = sample();
        bad.date_time[1] = 12;
        assert_eq!(bad.unix_time_s(), None);
    }

    #[test]
    fn garbage_and_false_syncs_are_skipped_and_counted() {
        let bt = sample();
        let mut bytes = vec![0xa5, 0x00, 0x13, 0xa5, 0x0a, 0x1b];
        bytes.extend(encode_bottom_track(&bt));
        let mut broken = encode_bottom_track(&bt);
        broken[40] ^= 0xff;
        bytes.extend(broken);
        bytes.extend(record(0xbe, &[1, 2, 3]));
        let mut d = NortekDecoder::new();
        d.push(&bytes);
        let mut frames = Vec::new();
        while let Some(f) = d.next_frame() {
            frames.push(f);
        }
        assert_eq!(frames.len(), 3, "{frames:?}");
        assert!(matches!(&frames[0], Ok(NortekFrame::BottomTrack(_))));
        assert!(matches!(&frames[1], Err(NortekError::DataChecksum { .. })));
        assert_eq!(
            frames[2],
            Ok(NortekFrame::Other(OtherRecord {
                id: 0xbe,
                family: FAMILY_DVL,
                data_len: 3
            }))
        );
        assert_eq!(d.stats().checksum_errors, 1);
        assert!(d.stats().bytes_skipped >= 6);
    }
}
