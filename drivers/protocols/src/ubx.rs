//! u-blox UBX binary messages: sync `B5 62`, class, id, payload length (u16), payload, and the
//! 8-bit Fletcher checksum `CK_A CK_B` over class, id, length and payload. Little-endian.
//!
//! Decoded: `NAV-PVT` (class 01, id 07, 92 bytes: time, fix type and flags, position, heights,
//! accuracies, NED velocity). Other messages with a good checksum come back as
//! [`UbxFrame::Other`]. NMEA sentences interleaved on the same port (a u-blox receiver's default
//! output) are passed over whole as [`UbxFrame::Nmea`], not counted as garbage.

use crate::framing::{DecoderStats, FrameBuffer, ReadLe};
use serde::Serialize;

pub const SYNC: [u8; 2] = [0xb5, 0x62];
pub const CLASS_NAV: u8 = 0x01;
pub const ID_NAV_PVT: u8 = 0x07;
pub const NAV_PVT_LEN: usize = 92;
/// Longest payload accepted (`NAV-SAT` with every signal of four constellations stays below).
pub const MAX_PAYLOAD: usize = 4096;

/// The 8-bit Fletcher checksum of class, id, length and payload.
pub fn checksum(bytes: &[u8]) -> [u8; 2] {
    let (mut a, mut b) = (0u8, 0u8);
    for &x in bytes {
        a = a.wrapping_add(x);
        b = b.wrapping_add(a);
    }
    [a, b]
}

/// `NAV-PVT`: navigation position, velocity and time solution.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct NavPvt {
    /// GPS time of week of the epoch (ms).
    pub itow_ms: u32,
    pub year: u16,
    pub month: u8,
    pub day: u8,
    pub hour: u8,
    pub minute: u8,
    pub second: u8,
    /// Bit 0 validDate, bit 1 validTime, bit 2 fullyResolved, bit 3 validMag.
    pub valid: u8,
    /// Time accuracy estimate (ns).
    pub time_accuracy_ns: u32,
    /// Fraction of the second (ns, −1e9..1e9), added to the seconds above.
    pub nano_ns: i32,
    /// 0 no fix, 1 dead reckoning only, 2 2D, 3 3D, 4 GNSS + dead reckoning, 5 time only.
    pub fix_type: u8,
    /// Bit 0 gnssFixOK, bit 1 diffSoln, bits 6..7 carrier solution (1 float, 2 fixed).
    pub flags: u8,
    pub satellites: u8,
    pub longitude_deg: f64,
    pub latitude_deg: f64,
    /// Height above the ellipsoid (m).
    pub height_m: f64,
    /// Height above mean sea level (m).
    pub height_msl_m: f64,
    /// Horizontal and vertical accuracy estimates (m).
    pub horizontal_accuracy_m: f64,
    pub vertical_accuracy_m: f64,
    /// NED velocity (m/s).
    pub velocity_ned_m_s: [f64; 3],
    /// Speed accuracy estimate (m/s).
    pub speed_accuracy_m_s: f64,
    pub pdop: f64,
}

impl NavPvt {
    pub const VALID_DATE: u8 = 1 << 0;
    pub const VALID_TIME: u8 = 1 << 1;
    pub const FULLY_RESOLVED: u8 = 1 << 2;
    pub const GNSS_FIX_OK: u8 = 1 << 0;
    pub const DIFF_SOLN: u8 = 1 << 1;

    /// The carrier-phase solution: 0 none, 1 float, 2 fixed.
    pub fn carrier_solution(&self) -> u8 {
        (self.flags >> 6) & 0x3
    }

    /// UTC of the epoch (ns since 1970), when the receiver marks date and time valid and fully
    /// resolved.
    pub fn utc_ns(&self) -> Option<i64> {
        let need = Self::VALID_DATE | Self::VALID_TIME | Self::FULLY_RESOLVED;
        if self.valid & need != need {
            return None;
        }
        let d = chrono::NaiveDate::from_ymd_opt(
            i32::from(self.year),
            u32::from(self.month),
            u32::from(self.day),
        )?;
        let t = d.and_hms_opt(
            u32::from(self.hour),
            u32::from(self.minute),
            u32::from(self.second.min(59)),
        )?;
        let s = t.and_utc().timestamp() + i64::from(self.second.saturating_sub(59));
        Some(s * 1_000_000_000 + i64::from(self.nano_ns))
    }
}

/// A decoded message.
#[derive(Debug, Clone, PartialEq, Serialize)]
#[serde(tag = "message", rename_all = "snake_case")]
pub enum UbxFrame {
    NavPvt(Box<NavPvt>),
    Other {
        class: u8,
        id: u8,
        length: usize,
    },
    /// An NMEA sentence on the same line (its address, e.g. `GNGGA`).
    Nmea {
        address: String,
    },
}

/// Why a frame was not decoded.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum UbxError {
    #[error("checksum {found:02x?}, computed {computed:02x?}")]
    Checksum { found: [u8; 2], computed: [u8; 2] },
    #[error("malformed message {class:02x} {id:02x} of {length} bytes")]
    Malformed { class: u8, id: u8, length: usize },
}

fn decode_nav_pvt(p: &[u8]) -> Option<NavPvt> {
    if p.len() < NAV_PVT_LEN {
        return None;
    }
    let deg = |i: usize| p.i32_at(i).map(|v| f64::from(v) * 1e-7);
    let m = |i: usize| p.i32_at(i).map(|v| f64::from(v) * 1e-3);
    let um = |i: usize| p.u32_at(i).map(|v| f64::from(v) * 1e-3);
    let pvt = NavPvt {
        itow_ms: p.u32_at(0)?,
        year: p.u16_at(4)?,
        month: p.u8_at(6)?,
        day: p.u8_at(7)?,
        hour: p.u8_at(8)?,
        minute: p.u8_at(9)?,
        second: p.u8_at(10)?,
        valid: p.u8_at(11)?,
        time_accuracy_ns: p.u32_at(12)?,
        nano_ns: p.i32_at(16)?,
        fix_type: p.u8_at(20)?,
        flags: p.u8_at(21)?,
        satellites: p.u8_at(23)?,
        longitude_deg: deg(24)?,
        latitude_deg: deg(28)?,
        height_m: m(32)?,
        height_msl_m: m(36)?,
        horizontal_accuracy_m: um(40)?,
        vertical_accuracy_m: um(44)?,
        velocity_ned_m_s: [m(48)?, m(52)?, m(56)?],
        speed_accuracy_m_s: um(68)?,
        pdop: f64::from(p.u16_at(76)?) * 0.01,
    };
    (pvt.latitude_deg.abs() <= 90.0 && pvt.longitude_deg.abs() <= 180.0 && pvt.fix_type <= 5)
        .then_some(pvt)
}

/// Incremental UBX decoder.
#[derive(Debug, Clone)]
pub struct UbxDecoder {
    input: FrameBuffer,
}

impl Default for UbxDecoder {
    fn default() -> Self {
        Self::new()
    }
}

impl UbxDecoder {
    pub fn new() -> Self {
        UbxDecoder {
            input: FrameBuffer::new(MAX_PAYLOAD + 8),
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

    /// The next message, or `None` when no complete one is buffered.
    pub fn next_frame(&mut self) -> Option<Result<UbxFrame, UbxError>> {
        loop {
            let data = self.input.data();
            let Some(start) = data.iter().position(|&b| b == SYNC[0] || b == b'$') else {
                let n = data.len();
                if data.iter().all(|&b| b == b'\r' || b == b'\n') {
                    self.input.consume(n);
                } else {
                    self.input.skip(n);
                }
                return None;
            };
            if start > 0 {
                if data[..start].iter().all(|&b| b == b'\r' || b == b'\n') {
                    self.input.consume(start);
                } else {
                    self.input.skip(start);
                }
                continue;
            }
            if data[0] == b'$' {
                // An NMEA sentence: whole lines with a good checksum are passed over.
                let Some(end) = data.iter().position(|&b| b == b'\n') else {
                    if data.len() > crate::nmea::MAX_LINE {
                        self.input.skip(1);
                        continue;
                    }
                    return None;
                };
                let line = data[1..end].strip_suffix(b"\r").unwrap_or(&data[1..end]);
                match crate::nmea::decode_line(line) {
                    Ok(s) => {
                        let address = String::from_utf8_lossy(
                            line.split(|&b| b == b',').next().unwrap_or_default(),
                        )
                        .to_string();
                        drop(s);
                        self.input.take_frame(end + 1);
                        return Some(Ok(UbxFrame::Nmea { address }));
                    }
                    Err(_) => {
                        self.input.skip(1);
                        continue;
                    }
                }
            }
            if data.len() < 6 {
                return None;
            }
            if data[1] != SYNC[1] {
                self.input.skip(1);
                continue;
            }
            let (class, id) = (data[2], data[3]);
            let length = usize::from(data.u16_at(4).unwrap_or(0));
            if length > MAX_PAYLOAD {
                self.input.skip(1);
                continue;
            }
            let total = 6 + length + 2;
            if data.len() < total {
                return None;
            }
            let computed = checksum(&data[2..6 + length]);
            let found = [data[6 + length], data[7 + length]];
            if found != computed {
                // The length may be what was damaged: search again from the next byte.
                self.input.stats.checksum_errors += 1;
                self.input.skip(1);
                return Some(Err(UbxError::Checksum { found, computed }));
            }
            let payload = &data[6..6 + length];
            if (class, id) == (CLASS_NAV, ID_NAV_PVT) {
                return match decode_nav_pvt(payload) {
                    Some(p) => {
                        self.input.take_frame(total);
                        Some(Ok(UbxFrame::NavPvt(Box::new(p))))
                    }
                    None => {
                        self.input.stats.malformed += 1;
                        self.input.reject_frame(total);
                        Some(Err(UbxError::Malformed { class, id, length }))
                    }
                };
            }
            self.input.take_frame(total);
            return Some(Ok(UbxFrame::Other { class, id, length }));
        }
    }
}

impl crate::framing::StreamDecoder for UbxDecoder {
    type Frame = UbxFrame;
    fn push(&mut self, bytes: &[u8]) {
        UbxDecoder::push(self, bytes)
    }
    fn next_good_frame(&mut self) -> Option<UbxFrame> {
        loop {
            if let Ok(f) = self.next_frame()? {
                return Some(f);
            }
        }
    }
    fn stats(&self) -> &DecoderStats {
        UbxDecoder::stats(self)
    }
    fn frame_start(&self) -> u64 {
        self.input.frame_start()
    }
}

/// A UBX frame around `payload`.
pub fn frame(class: u8, id: u8, payload: &[u8]) -> Vec<u8> {
    let mut out = Vec::with_capacity(payload.len() + 8);
    out.extend_from_slice(&SYNC);
    out.extend_from_slice(&[class, id]);
    out.extend_from_slice(&(payload.len() as u16).to_le_bytes());
    out.extend_from_slice(payload);
    let ck = checksum(&out[2..]);
    out.extend_from_slice(&ck);
    out
}

/// Encodes a `NAV-PVT` (the fields [`NavPvt`] keeps; the others zero).
pub fn encode_nav_pvt(p: &NavPvt) -> Vec<u8> {
    let mut b = [0u8; NAV_PVT_LEN];
    let put = |b: &mut [u8; NAV_PVT_LEN], i: usize, v: &[u8]| b[i..i + v.len()].copy_from_slice(v);
    let deg = |v: f64| ((v * 1e7).round() as i32).to_le_bytes();
    let mm = |v: f64| ((v * 1e3).round() as i32).to_le_bytes();
    let umm = |v: f64| ((v.max(0.0) * 1e3).round() as u32).to_le_bytes();
    put(&mut b, 0, &p.itow_ms.to_le_bytes());
    put(&mut b, 4, &p.year.to_le_bytes());
    put(
        &mut b,
        6,
        &[p.month, p.day, p.hour, p.minute, p.second, p.valid],
    );
    put(&mut b, 12, &p.time_accuracy_ns.to_le_bytes());
    put(&mut b, 16, &p.nano_ns.to_le_bytes());
    put(&mut b, 20, &[p.fix_type, p.flags, 0, p.satellites]);
    put(&mut b, 24, &deg(p.longitude_deg));
    put(&mut b, 28, &deg(p.latitude_deg));
    put(&mut b, 32, &mm(p.height_m));
    put(&mut b, 36, &mm(p.height_msl_m));
    put(&mut b, 40, &umm(p.horizontal_accuracy_m));
    put(&mut b, 44, &umm(p.vertical_accuracy_m));
    for (k, v) in p.velocity_ned_m_s.iter().enumerate() {
        put(&mut b, 48 + 4 * k, &mm(*v));
    }
    put(&mut b, 68, &umm(p.speed_accuracy_m_s));
    put(&mut b, 76, &((p.pdop * 100.0).round() as u16).to_le_bytes());
    frame(CLASS_NAV, ID_NAV_PVT, &b)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sample() -> NavPvt {
        NavPvt {
            itow_ms: 377_419_000,
            year: 2026,
            month: 11,
            day: 25,
            hour: 8,
            minute: 50,
            second: 1,
            valid: 0x37,
            time_accuracy_ns: 25,
            nano_ns: -120_000,
            fix_type: 3,
            flags: 0x81,
            satellites: 14,
            longitude_deg: 138.608_119_9,
            latitude_deg: -34.906_226_6,
            height_m: 25.378,
            height_msl_m: 28.849,
            horizontal_accuracy_m: 1.133,
            vertical_accuracy_m: 1.603,
            velocity_ned_m_s: [0.012, -0.004, 0.23],
            speed_accuracy_m_s: 0.17,
            pdop: 1.52,
        }
    }

    #[test]
    fn encode_then_decode_gives_the_message_back_in_any_split_between_nmea_lines() {
        let p = sample();
        let mut bytes = b"$GPHDT,274.07,T*03\r\n".to_vec();
        bytes.extend(encode_nav_pvt(&p));
        bytes.extend(frame(0x01, 0x35, &[1, 2, 3, 4]));
        for split in [1, 5, 6, 40, bytes.len()] {
            let mut d = UbxDecoder::new();
            let mut got = Vec::new();
            for c in bytes.chunks(split) {
                d.push(c);
                while let Some(f) = d.next_frame() {
                    got.push(f.expect("good frame"));
                }
            }
            assert_eq!(
                got,
                vec![
                    UbxFrame::Nmea {
                        address: "GPHDT".into()
                    },
                    UbxFrame::NavPvt(Box::new(p.clone())),
                    UbxFrame::Other {
                        class: 1,
                        id: 0x35,
                        length: 4
                    }
                ],
                "split {split}"
            );
            assert_eq!(d.stats().bytes_skipped, 0);
            assert_eq!(p.carrier_solution(), 2);
        }
    }

    #[test]
    fn a_damaged_frame_is_counted_and_the_next_one_decodes() {
        let mut bad = encode_nav_pvt(&sample());
        bad[30] ^= 0x10;
        let mut bytes = vec![0xb5, 0x00, 0xb5];
        bytes.extend(bad);
        bytes.extend(encode_nav_pvt(&sample()));
        let mut d = UbxDecoder::new();
        d.push(&bytes);
        let mut good = 0;
        while let Some(f) = d.next_frame() {
            good += usize::from(f.is_ok());
        }
        assert_eq!(good, 1);
        assert_eq!(d.stats().checksum_errors, 1);
    }

    #[test]
    fn utc_needs_a_valid_fully_resolved_date_and_time() {
        let p = sample();
        let t = p.utc_ns().expect("valid");
        assert_eq!(t, 1_795_596_601_000_000_000 - 120_000);
        let mut q = p.clone();
        q.valid = NavPvt::VALID_DATE | NavPvt::VALID_TIME;
        assert_eq!(q.utc_ns(), None);
    }
}
