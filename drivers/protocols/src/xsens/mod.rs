//! Xsens MTi XBus framing and the MTData2 message.
//!
//! Frame: `FA` preamble, bus ID (`FF`), message ID (`36` = MTData2), length (u8; `FF` means a
//! 2-byte big-endian extended length follows), payload, checksum such that the sum of every byte
//! after the preamble, checksum included, is 0 mod 256. MTData2 payload: packets of
//! {data identifier u16 BE, size u8, data BE}. The identifier's low nibble gives the precision of
//! floating-point data (bits 0–1: f32, fixed 12.20, fixed 16.32, f64) and the frame (bits 2–3:
//! ENU, NED, NWU).

pub mod to_device;
pub mod to_schema;

use crate::framing::{DecoderStats, FrameBuffer};
use serde::Serialize;

pub const PREAMBLE: u8 = 0xfa;
pub const BUS_ID: u8 = 0xff;
pub const MID_MTDATA2: u8 = 0x36;
/// Largest payload accepted (the extended length allows 2047 bytes in practice).
pub const MAX_PAYLOAD: usize = 2048;

/// Identifier groups (the identifier with its low nibble cleared).
pub mod xdi {
    pub const TEMPERATURE: u16 = 0x0810;
    pub const UTC_TIME: u16 = 0x1010;
    pub const PACKET_COUNTER: u16 = 0x1020;
    pub const SAMPLE_TIME_FINE: u16 = 0x1060;
    pub const QUATERNION: u16 = 0x2010;
    pub const EULER_ANGLES: u16 = 0x2030;
    pub const DELTA_V: u16 = 0x4010;
    pub const ACCELERATION: u16 = 0x4020;
    pub const FREE_ACCELERATION: u16 = 0x4030;
    pub const RATE_OF_TURN: u16 = 0x8020;
    pub const DELTA_Q: u16 = 0x8030;
    pub const MAGNETIC_FIELD: u16 = 0xc020;
    pub const STATUS_BYTE: u16 = 0xe010;
    pub const STATUS_WORD: u16 = 0xe020;
}

/// Coordinate frame of a vector quantity (identifier bits 2–3).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum XsensFrame {
    Enu,
    Ned,
    Nwu,
}

#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct UtcTime {
    pub nanoseconds: u32,
    pub year: u16,
    pub month: u8,
    pub day: u8,
    pub hour: u8,
    pub minute: u8,
    pub second: u8,
    pub flags: u8,
}

/// One MTData2 message: the fields present.
#[derive(Debug, Clone, Default, PartialEq, Serialize)]
pub struct MtData2 {
    pub packet_counter: Option<u16>,
    /// Sample time in units of 100 us.
    pub sample_time_fine: Option<u32>,
    pub utc_time: Option<UtcTime>,
    pub status_word: Option<u32>,
    pub status_byte: Option<u8>,
    pub temperature_c: Option<f64>,
    /// m/s^2, body frame.
    pub acceleration: Option<[f64; 3]>,
    pub free_acceleration: Option<[f64; 3]>,
    /// Velocity increment over the output interval (m/s).
    pub delta_v: Option<[f64; 3]>,
    /// rad/s, body frame.
    pub rate_of_turn: Option<[f64; 3]>,
    /// Orientation increment over the output interval (unit quaternion w x y z).
    pub delta_q: Option<[f64; 4]>,
    pub quaternion: Option<[f64; 4]>,
    /// Roll, pitch, yaw (deg) in `orientation_frame`.
    pub euler_deg: Option<[f64; 3]>,
    pub orientation_frame: Option<XsensFrame>,
    /// Normalised magnetic field (arbitrary units).
    pub magnetic_field: Option<[f64; 3]>,
    /// Identifiers present that this decoder does not interpret.
    pub other_ids: Vec<u16>,
}

/// A frame with another message ID (acknowledgements, errors, configuration replies).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct OtherMessage {
    pub message_id: u8,
    pub payload: Vec<u8>,
}

/// An XBus message. The MTData2 variant is large but arrives at up to 1 kHz: kept inline so
/// decoding allocates nothing per sample.
#[allow(clippy::large_enum_variant)]
#[derive(Debug, Clone, PartialEq, Serialize)]
#[serde(tag = "message", rename_all = "snake_case")]
pub enum XbusMessage {
    MtData2(MtData2),
    Other(OtherMessage),
}

/// Reads `count` floating-point values of `precision` (0 f32, 1 fixed 12.20, 2 fixed 16.32,
/// 3 f64) from `d`.
fn floats(d: &[u8], precision: u16, count: usize) -> Option<Vec<f64>> {
    let width = [4, 4, 6, 8][usize::from(precision & 3)];
    if d.len() != width * count {
        return None;
    }
    Some(
        d.chunks(width)
            .map(|c| match precision & 3 {
                0 => f64::from(f32::from_be_bytes([c[0], c[1], c[2], c[3]])),
                1 => f64::from(i32::from_be_bytes([c[0], c[1], c[2], c[3]])) / f64::from(1 << 20),
                2 => {
                    // 32-bit fraction, then 16-bit signed integer part.
                    let frac = u32::from_be_bytes([c[0], c[1], c[2], c[3]]);
                    let int = i16::from_be_bytes([c[4], c[5]]);
                    f64::from(int) + f64::from(frac) / 2f64.powi(32)
                }
                _ => f64::from_be_bytes([c[0], c[1], c[2], c[3], c[4], c[5], c[6], c[7]]),
            })
            .collect(),
    )
}

fn v3(d: &[u8], p: u16) -> Option<[f64; 3]> {
    floats(d, p, 3)?.try_into().ok()
}

fn v4(d: &[u8], p: u16) -> Option<[f64; 4]> {
    floats(d, p, 4)?.try_into().ok()
}

/// Decodes an MTData2 payload. Packets that do not fit their declared size end the decoding
/// (the rest is reported as malformed by returning `None`).
pub fn decode_mtdata2(payload: &[u8]) -> Option<MtData2> {
    let mut m = MtData2::default();
    let mut at = 0;
    while at < payload.len() {
        let id = u16::from_be_bytes([*payload.get(at)?, *payload.get(at + 1)?]);
        let size = usize::from(*payload.get(at + 2)?);
        let d = payload.get(at + 3..at + 3 + size)?;
        at += 3 + size;
        let group = id & 0xfff0;
        let precision = id & 0x3;
        let frame = match (id >> 2) & 3 {
            0 => XsensFrame::Enu,
            1 => XsensFrame::Ned,
            _ => XsensFrame::Nwu,
        };
        let ok = match group {
            xdi::PACKET_COUNTER if size == 2 => {
                m.packet_counter = Some(u16::from_be_bytes([d[0], d[1]]));
                true
            }
            xdi::SAMPLE_TIME_FINE if size == 4 => {
                m.sample_time_fine = Some(u32::from_be_bytes([d[0], d[1], d[2], d[3]]));
                true
            }
            xdi::UTC_TIME if size == 12 => {
                m.utc_time = Some(UtcTime {
                    nanoseconds: u32::from_be_bytes([d[0], d[1], d[2], d[3]]),
                    year: u16::from_be_bytes([d[4], d[5]]),
                    month: d[6],
                    day: d[7],
                    hour: d[8],
                    minute: d[9],
                    second: d[10],
                    flags: d[11],
                });
                true
            }
            xdi::STATUS_WORD if size == 4 => {
                m.status_word = Some(u32::from_be_bytes([d[0], d[1], d[2], d[3]]));
                true
            }
            xdi::STATUS_BYTE if size == 1 => {
                m.status_byte = Some(d[0]);
                true
            }
            xdi::TEMPERATURE => {
                m.temperature_c = floats(d, precision, 1).map(|v| v[0]);
                m.temperature_c.is_some()
            }
            xdi::ACCELERATION => {
                m.acceleration = v3(d, precision);
                m.acceleration.is_some()
            }
            xdi::FREE_ACCELERATION => {
                m.free_acceleration = v3(d, precision);
                m.free_acceleration.is_some()
            }
            xdi::DELTA_V => {
                m.delta_v = v3(d, precision);
                m.delta_v.is_some()
            }
            xdi::RATE_OF_TURN => {
                m.rate_of_turn = v3(d, precision);
                m.rate_of_turn.is_some()
            }
            xdi::DELTA_Q => {
                m.delta_q = v4(d, precision);
                m.delta_q.is_some()
            }
            xdi::QUATERNION => {
                m.quaternion = v4(d, precision);
                m.orientation_frame = Some(frame);
                m.quaternion.is_some()
            }
            xdi::EULER_ANGLES => {
                m.euler_deg = v3(d, precision);
                m.orientation_frame = Some(frame);
                m.euler_deg.is_some()
            }
            xdi::MAGNETIC_FIELD => {
                m.magnetic_field = v3(d, precision);
                m.magnetic_field.is_some()
            }
            _ => {
                m.other_ids.push(id);
                true
            }
        };
        if !ok {
            return None;
        }
    }
    Some(m)
}

fn checksum_ok(frame_without_preamble: &[u8]) -> bool {
    frame_without_preamble
        .iter()
        .fold(0u8, |a, &b| a.wrapping_add(b))
        == 0
}

/// Builds a frame around `payload`.
pub fn frame(message_id: u8, payload: &[u8]) -> Vec<u8> {
    let mut f = vec![PREAMBLE, BUS_ID, message_id];
    if payload.len() >= 0xff {
        f.push(0xff);
        f.extend_from_slice(&(payload.len() as u16).to_be_bytes());
    } else {
        f.push(payload.len() as u8);
    }
    f.extend_from_slice(payload);
    let sum = f[1..].iter().fold(0u8, |a, &b| a.wrapping_add(b));
    f.push(0u8.wrapping_sub(sum));
    f
}

/// Encodes the fields of `m` that an IMU emulator needs (packet counter, sample time, status,
/// temperature, acceleration, rate of turn, delta-v, delta-q) as f32 packets in an MTData2 frame.
pub fn encode_mtdata2(m: &MtData2) -> Vec<u8> {
    let mut p = Vec::new();
    let mut put = |id: u16, data: &[u8]| {
        p.extend_from_slice(&id.to_be_bytes());
        p.push(data.len() as u8);
        p.extend_from_slice(data);
    };
    let f32s =
        |v: &[f64]| -> Vec<u8> { v.iter().flat_map(|x| (*x as f32).to_be_bytes()).collect() };
    if let Some(c) = m.packet_counter {
        put(xdi::PACKET_COUNTER, &c.to_be_bytes());
    }
    if let Some(t) = m.sample_time_fine {
        put(xdi::SAMPLE_TIME_FINE, &t.to_be_bytes());
    }
    if let Some(s) = m.status_word {
        put(xdi::STATUS_WORD, &s.to_be_bytes());
    }
    if let Some(t) = m.temperature_c {
        put(xdi::TEMPERATURE, &f32s(&[t]));
    }
    if let Some(a) = m.acceleration {
        put(xdi::ACCELERATION, &f32s(&a));
    }
    if let Some(v) = m.delta_v {
        put(xdi::DELTA_V, &f32s(&v));
    }
    if let Some(w) = m.rate_of_turn {
        put(xdi::RATE_OF_TURN, &f32s(&w));
    }
    if let Some(q) = m.delta_q {
        put(xdi::DELTA_Q, &f32s(&q));
    }
    if let Some(b) = m.magnetic_field {
        put(xdi::MAGNETIC_FIELD, &f32s(&b));
    }
    frame(MID_MTDATA2, &p)
}

/// Incremental XBus decoder.
#[derive(Debug, Clone)]
pub struct XbusDecoder {
    input: FrameBuffer,
}

impl Default for XbusDecoder {
    fn default() -> Self {
        Self::new()
    }
}

impl XbusDecoder {
    pub fn new() -> Self {
        XbusDecoder {
            input: FrameBuffer::new(MAX_PAYLOAD + 7),
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

    /// The next message; `None` when more bytes are needed. MTData2 payloads that do not parse
    /// are counted as malformed and skipped.
    pub fn next_message(&mut self) -> Option<XbusMessage> {
        loop {
            let data = self.input.data();
            let Some(pos) = data
                .windows(2)
                .position(|w| w[0] == PREAMBLE && w[1] == BUS_ID)
            else {
                let keep = usize::from(data.last() == Some(&PREAMBLE));
                let n = data.len() - keep;
                if n > 0 {
                    self.input.skip(n);
                }
                return None;
            };
            if pos > 0 {
                self.input.skip(pos);
                continue;
            }
            if data.len() < 4 {
                return None;
            }
            let (len, head) = if data[3] == 0xff {
                if data.len() < 6 {
                    return None;
                }
                (usize::from(u16::from_be_bytes([data[4], data[5]])), 6)
            } else {
                (usize::from(data[3]), 4)
            };
            if len > MAX_PAYLOAD {
                self.input.skip(1);
                continue;
            }
            let total = head + len + 1;
            if data.len() < total {
                return None;
            }
            if !checksum_ok(&data[1..total]) {
                self.input.stats.checksum_errors += 1;
                self.input.skip(1);
                continue;
            }
            let mid = data[2];
            let payload = data[head..head + len].to_vec();
            if mid == MID_MTDATA2 {
                match decode_mtdata2(&payload) {
                    Some(m) => {
                        self.input.take_frame(total);
                        return Some(XbusMessage::MtData2(m));
                    }
                    None => {
                        self.input.stats.malformed += 1;
                        self.input.reject_frame(total);
                        continue;
                    }
                }
            }
            self.input.take_frame(total);
            return Some(XbusMessage::Other(OtherMessage {
                message_id: mid,
                payload,
            }));
        }
    }
}

impl crate::framing::StreamDecoder for XbusDecoder {
    type Frame = XbusMessage;
    fn push(&mut self, bytes: &[u8]) {
        XbusDecoder::push(self, bytes);
    }
    fn next_good_frame(&mut self) -> Option<XbusMessage> {
        self.next_message()
    }
    fn stats(&self) -> &DecoderStats {
        &self.input.stats
    }
    fn frame_start(&self) -> u64 {
        self.input.frame_start()
    }
}
