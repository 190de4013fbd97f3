//! Blueprint Subsea SeaTrac (X110/X150) serial command interface.
//!
//! Framing: `$` (beacon to host) or `#` (host to beacon), the message as upper-case ASCII hex —
//! command ID (CID) byte, payload bytes, then a CRC-16/ARC of the binary CID and payload, low
//! byte first — and CR LF. Decoded: `CID_STATUS` (0x10; environment, attitude, magnetometer
//! calibration fields as the output flags select), `CID_SYS_INFO` (0x02; uptime, section,
//! hardware part, revision and serial), and the position-fix record `ACOFIX_T` carried by
//! `CID_PING_RESP` (0x42) and `CID_XCVR_FIX` (0x39): attitude, depth, sound speed, RSSI, then the
//! range, USBL (per-channel RSSI, azimuth, elevation, fit error) and position blocks its flags
//! announce. Other CIDs are returned with their raw payload.

pub mod settings;
pub mod to_device;
pub mod to_schema;

use crate::framing::{DecoderStats, FrameBuffer, ReadLe};
use serde::Serialize;

pub const CID_SYS_INFO: u8 = 0x02;
pub const CID_STATUS: u8 = 0x10;
pub const CID_XCVR_USBL: u8 = 0x38;
pub const CID_XCVR_FIX: u8 = 0x39;
pub const CID_PING_RESP: u8 = 0x42;
/// Longest line accepted: the USBL diagnostic message carries its correlation samples (typically
/// 140 f32) and is the largest, about 600 binary bytes = 1 200 hex characters.
pub const MAX_LINE: usize = 4096;

/// CRC-16/ARC: polynomial 0x8005 reflected (0xA001), initial 0, no final xor (the `crc`
/// crate's catalogue entry, table-driven).
pub fn crc16_arc(bytes: &[u8]) -> u16 {
    const CRC: crc::Crc<u16> = crc::Crc::<u16>::new(&crc::CRC_16_ARC);
    CRC.checksum(bytes)
}

#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Environment {
    pub supply_v: f64,
    pub temperature_c: f64,
    /// Pressure (bar).
    pub pressure_bar: f64,
    pub depth_m: f64,
    pub sound_speed_m_s: f64,
}

#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Status {
    pub output_flags: u8,
    /// Beacon time stamp (ms since power-up).
    pub timestamp_ms: u64,
    pub environment: Option<Environment>,
    /// Yaw, pitch, roll (deg).
    pub attitude_deg: Option<[f64; 3]>,
}

#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct SysInfo {
    pub uptime_s: u32,
    pub section: u8,
    pub hardware_part: u16,
    pub hardware_revision: u8,
    pub serial_number: u32,
}

#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct FixRange {
    /// 16 kHz timer counts between request and response.
    pub count: u32,
    /// Two-way travel time with internal offsets removed (s).
    pub travel_time_s: f64,
    /// Slant range (m).
    pub distance_m: f64,
}

#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct FixUsbl {
    /// Received signal strength per receiver channel (dB).
    pub channel_rssi_db: Vec<f64>,
    pub azimuth_deg: f64,
    pub elevation_deg: f64,
    pub fit_error: f64,
}

/// `ACOFIX_T`: an acoustic range/position fix.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct AcoFix {
    pub destination_id: u8,
    pub source_id: u8,
    pub flags: u8,
    pub message_type: u8,
    /// Local beacon yaw (magnetic), pitch, roll (deg).
    pub attitude_deg: [f64; 3],
    pub local_depth_m: f64,
    pub sound_speed_m_s: f64,
    pub rssi_db: f64,
    pub range: Option<FixRange>,
    pub usbl: Option<FixUsbl>,
    /// Easting, northing, depth of the remote beacon relative to the local one (m).
    pub position_m: Option<[f64; 3]>,
}

impl AcoFix {
    pub const RANGE_VALID: u8 = 1 << 0;
    pub const USBL_VALID: u8 = 1 << 1;
    pub const POSITION_VALID: u8 = 1 << 2;
    pub const POSITION_ENHANCED: u8 = 1 << 3;
    pub const POSITION_FILTER_ERROR: u8 = 1 << 4;
}

/// `CID_XCVR_USBL` (0x38): the signal's cross-correlation, per-channel signal strength and the
/// phase angles across the array's baselines from which the beacon computed the direction.
///
/// Layout (little-endian): xcor_sig_peak f32, xcor_threshold f32, xcor_cross_point u16,
/// xcor_cross_mag f32, xcor_detect u16, xcor_length u16, xcor_data f32[xcor_length], channels
/// u8, channel_rssi i16[channels] (0.1 dB), baselines u8, phase_angle f32[baselines],
/// signal_azimuth i16 (0.1°), signal_elevation i16 (0.1°), signal_fit_error f32. Taken from the
/// open decoders, which agree with one another; no captured frame is public, so the tests use
/// synthetic frames. The phase angles are reported as the beacon gives them (units not stated).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct UsblDiagnostic {
    pub xcor_signal_peak: f32,
    pub xcor_threshold: f32,
    pub xcor_cross_point: u16,
    pub xcor_cross_magnitude: f32,
    pub xcor_detect: u16,
    pub xcor_data: Vec<f32>,
    /// Received signal strength per receiver channel (dB).
    pub channel_rssi_db: Vec<f64>,
    /// Phase angle per hydrophone baseline.
    pub phase_angle: Vec<f32>,
    pub azimuth_deg: f64,
    pub elevation_deg: f64,
    pub fit_error: f32,
}

/// Decodes a `CID_XCVR_USBL` payload; `None` when it is shorter than its counts announce or
/// longer than they account for.
pub fn usbl_diagnostic(p: &[u8]) -> Option<UsblDiagnostic> {
    let n = usize::from(p.u16_at(16)?);
    let mut at = 18;
    let xcor_data = (0..n)
        .map(|i| p.f32_at(at + 4 * i))
        .collect::<Option<Vec<_>>>()?;
    at += 4 * n;
    let channels = usize::from(p.u8_at(at)?);
    let channel_rssi_db = (0..channels)
        .map(|i| p.i16_at(at + 1 + 2 * i).map(deci))
        .collect::<Option<Vec<_>>>()?;
    at += 1 + 2 * channels;
    let baselines = usize::from(p.u8_at(at)?);
    let phase_angle = (0..baselines)
        .map(|i| p.f32_at(at + 1 + 4 * i))
        .collect::<Option<Vec<_>>>()?;
    at += 1 + 4 * baselines;
    let d = UsblDiagnostic {
        xcor_signal_peak: p.f32_at(0)?,
        xcor_threshold: p.f32_at(4)?,
        xcor_cross_point: p.u16_at(8)?,
        xcor_cross_magnitude: p.f32_at(10)?,
        xcor_detect: p.u16_at(14)?,
        xcor_data,
        channel_rssi_db,
        phase_angle,
        azimuth_deg: deci(p.i16_at(at)?),
        elevation_deg: deci(p.i16_at(at + 2)?),
        fit_error: p.f32_at(at + 4)?,
    };
    (p.len() == at + 8).then_some(d)
}

/// Encodes a `CID_XCVR_USBL` payload (the inverse of [`usbl_diagnostic`]).
pub fn encode_usbl_diagnostic(d: &UsblDiagnostic) -> Vec<u8> {
    let deci = |x: f64| ((x * 10.0).round() as i16).to_le_bytes();
    let mut p = Vec::new();
    p.extend_from_slice(&d.xcor_signal_peak.to_le_bytes());
    p.extend_from_slice(&d.xcor_threshold.to_le_bytes());
    p.extend_from_slice(&d.xcor_cross_point.to_le_bytes());
    p.extend_from_slice(&d.xcor_cross_magnitude.to_le_bytes());
    p.extend_from_slice(&d.xcor_detect.to_le_bytes());
    p.extend_from_slice(&(d.xcor_data.len() as u16).to_le_bytes());
    for x in &d.xcor_data {
        p.extend_from_slice(&x.to_le_bytes());
    }
    p.push(d.channel_rssi_db.len() as u8);
    for r in &d.channel_rssi_db {
        p.extend_from_slice(&deci(*r));
    }
    p.push(d.phase_angle.len() as u8);
    for a in &d.phase_angle {
        p.extend_from_slice(&a.to_le_bytes());
    }
    p.extend_from_slice(&deci(d.azimuth_deg));
    p.extend_from_slice(&deci(d.elevation_deg));
    p.extend_from_slice(&d.fit_error.to_le_bytes());
    p
}

#[derive(Debug, Clone, PartialEq, Serialize)]
#[serde(tag = "message", rename_all = "snake_case")]
pub enum SeatracMessage {
    Status(Status),
    SysInfo(SysInfo),
    /// `CID_XCVR_USBL`: the USBL receiver's diagnostic for one signal.
    UsblDiagnostic(UsblDiagnostic),
    /// `CID_PING_RESP` or `CID_XCVR_FIX`.
    Fix {
        cid: u8,
        fix: AcoFix,
    },
    /// Another CID: its payload bytes.
    Other {
        cid: u8,
        payload: Vec<u8>,
    },
}

/// One decoded line: direction and message.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct SeatracFrame {
    /// True for `$` (beacon to host), false for `#` (host to beacon).
    pub from_beacon: bool,
    pub message: SeatracMessage,
}

/// A value in tenths (divided, not multiplied by 0.1, so that -608 reads as the nearest double
/// to -60.8).
fn deci(v: i16) -> f64 {
    f64::from(v) / 10.0
}

/// Three consecutive i16 values in tenths.
fn deci3(p: &[u8], at: usize) -> Option<[f64; 3]> {
    Some([
        deci(p.i16_at(at)?),
        deci(p.i16_at(at + 2)?),
        deci(p.i16_at(at + 4)?),
    ])
}

fn status(p: &[u8]) -> Option<Status> {
    let flags = p.u8_at(0)?;
    let timestamp_ms = u64::from(p.u32_at(1)?) | (u64::from(p.u32_at(5)?) << 32);
    let mut at = 9;
    let environment = if flags & 1 != 0 {
        let e = Environment {
            supply_v: f64::from(p.u16_at(at)?) * 1e-3,
            temperature_c: deci(p.i16_at(at + 2)?),
            pressure_bar: f64::from(p.i32_at(at + 4)?) * 1e-3,
            depth_m: f64::from(p.i32_at(at + 8)?) * 0.1,
            sound_speed_m_s: f64::from(p.u16_at(at + 12)?) * 0.1,
        };
        at += 14;
        Some(e)
    } else {
        None
    };
    let attitude_deg = if flags & 2 != 0 {
        Some(deci3(p, at)?)
    } else {
        None
    };
    Some(Status {
        output_flags: flags,
        timestamp_ms,
        environment,
        attitude_deg,
    })
}

fn sys_info(p: &[u8]) -> Option<SysInfo> {
    Some(SysInfo {
        uptime_s: p.u32_at(0)?,
        section: p.u8_at(4)?,
        hardware_part: p.u16_at(5)?,
        hardware_revision: p.u8_at(7)?,
        serial_number: p.u32_at(8)?,
    })
}

/// Decodes an `ACOFIX_T` record; `None` when a block its flags announce is missing.
pub fn aco_fix(p: &[u8]) -> Option<AcoFix> {
    let flags = p.u8_at(2)?;
    let mut at = 16;
    let range = if flags & AcoFix::RANGE_VALID != 0 {
        let r = FixRange {
            count: p.u32_at(at)?,
            travel_time_s: f64::from(p.i32_at(at + 4)?) * 1e-7,
            distance_m: f64::from(p.u16_at(at + 8)?) * 0.1,
        };
        at += 10;
        Some(r)
    } else {
        None
    };
    let usbl = if flags & AcoFix::USBL_VALID != 0 {
        let n = usize::from(p.u8_at(at)?);
        if n > 4 {
            return None;
        }
        let channel_rssi_db = (0..n)
            .map(|i| p.i16_at(at + 1 + 2 * i).map(deci))
            .collect::<Option<Vec<_>>>()?;
        let b = at + 1 + 2 * n;
        let u = FixUsbl {
            channel_rssi_db,
            azimuth_deg: deci(p.i16_at(b)?),
            elevation_deg: deci(p.i16_at(b + 2)?),
            fit_error: f64::from(p.i16_at(b + 4)?) * 0.01,
        };
        at = b + 6;
        Some(u)
    } else {
        None
    };
    let position_m = if flags & AcoFix::POSITION_VALID != 0 {
        Some(deci3(p, at)?)
    } else {
        None
    };
    Some(AcoFix {
        destination_id: p.u8_at(0)?,
        source_id: p.u8_at(1)?,
        flags,
        message_type: p.u8_at(3)?,
        attitude_deg: deci3(p, 4)?,
        local_depth_m: f64::from(p.u16_at(10)?) * 0.1,
        sound_speed_m_s: f64::from(p.u16_at(12)?) * 0.1,
        rssi_db: deci(p.i16_at(14)?),
        range,
        usbl,
        position_m,
    })
}

/// Encodes an `ACOFIX_T` record (the inverse of [`aco_fix`]; values rounded to the wire units).
pub fn encode_aco_fix(f: &AcoFix) -> Vec<u8> {
    let d = |x: f64| ((x * 10.0).round() as i16).to_le_bytes();
    let mut p = vec![f.destination_id, f.source_id, f.flags, f.message_type];
    for a in f.attitude_deg {
        p.extend_from_slice(&d(a));
    }
    p.extend_from_slice(&((f.local_depth_m * 10.0).round() as u16).to_le_bytes());
    p.extend_from_slice(&((f.sound_speed_m_s * 10.0).round() as u16).to_le_bytes());
    p.extend_from_slice(&d(f.rssi_db));
    if let Some(r) = &f.range {
        p.extend_from_slice(&r.count.to_le_bytes());
        p.extend_from_slice(&((r.travel_time_s * 1e7).round() as i32).to_le_bytes());
        p.extend_from_slice(&((r.distance_m * 10.0).round() as u16).to_le_bytes());
    }
    if let Some(u) = &f.usbl {
        p.push(u.channel_rssi_db.len() as u8);
        for r in &u.channel_rssi_db {
            p.extend_from_slice(&d(*r));
        }
        p.extend_from_slice(&d(u.azimuth_deg));
        p.extend_from_slice(&d(u.elevation_deg));
        p.extend_from_slice(&((u.fit_error * 100.0).round() as i16).to_le_bytes());
    }
    if let Some(pos) = f.position_m {
        for x in pos {
            p.extend_from_slice(&d(x));
        }
    }
    p
}

/// Frames `cid` + `payload` as a beacon-to-host line.
pub fn encode_line(cid: u8, payload: &[u8]) -> Vec<u8> {
    let mut bin = vec![cid];
    bin.extend_from_slice(payload);
    let crc = crc16_arc(&bin);
    bin.extend_from_slice(&crc.to_le_bytes());
    let mut line = String::from("$");
    for b in bin {
        line.push_str(&format!("{b:02X}"));
    }
    line.push_str("\r\n");
    line.into_bytes()
}

#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum SeatracError {
    #[error("CRC {found:04x}, computed {computed:04x}")]
    Checksum { found: u16, computed: u16 },
    #[error("malformed line: {0}")]
    Malformed(&'static str),
}

fn hex_value(c: u8) -> Option<u8> {
    match c {
        b'0'..=b'9' => Some(c - b'0'),
        b'A'..=b'F' => Some(c - b'A' + 10),
        b'a'..=b'f' => Some(c - b'a' + 10),
        _ => None,
    }
}

fn parse_line(line: &[u8]) -> Result<SeatracFrame, SeatracError> {
    let from_beacon = line[0] == b'$';
    let hex = &line[1..];
    if hex.len() < 6 || !hex.len().is_multiple_of(2) {
        return Err(SeatracError::Malformed("length"));
    }
    let bin = hex
        .chunks(2)
        .map(|c| Some(hex_value(c[0])? << 4 | hex_value(c[1])?))
        .collect::<Option<Vec<u8>>>()
        .ok_or(SeatracError::Malformed("not hex"))?;
    let (body, crc) = bin.split_at(bin.len() - 2);
    let found = u16::from_le_bytes([crc[0], crc[1]]);
    let computed = crc16_arc(body);
    if found != computed {
        return Err(SeatracError::Checksum { found, computed });
    }
    let (cid, payload) = (body[0], &body[1..]);
    // Host-to-beacon lines are commands: reported raw.
    let message = match cid {
        CID_STATUS if from_beacon => {
            SeatracMessage::Status(status(payload).ok_or(SeatracError::Malformed("status"))?)
        }
        CID_SYS_INFO if from_beacon && !payload.is_empty() => {
            SeatracMessage::SysInfo(sys_info(payload).ok_or(SeatracError::Malformed("sys info"))?)
        }
        CID_XCVR_USBL if from_beacon => SeatracMessage::UsblDiagnostic(
            usbl_diagnostic(payload).ok_or(SeatracError::Malformed("usbl diagnostic"))?,
        ),
        CID_PING_RESP | CID_XCVR_FIX if from_beacon => SeatracMessage::Fix {
            cid,
            fix: aco_fix(payload).ok_or(SeatracError::Malformed("fix"))?,
        },
        _ => SeatracMessage::Other {
            cid,
            payload: payload.to_vec(),
        },
    };
    Ok(SeatracFrame {
        from_beacon,
        message,
    })
}

/// Incremental line decoder.
#[derive(Debug, Clone)]
pub struct SeatracDecoder {
    input: FrameBuffer,
}

impl Default for SeatracDecoder {
    fn default() -> Self {
        Self::new()
    }
}

impl SeatracDecoder {
    pub fn new() -> Self {
        SeatracDecoder {
            input: FrameBuffer::new(MAX_LINE),
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

    pub fn next_frame(&mut self) -> Option<Result<SeatracFrame, SeatracError>> {
        let line_end = |b: &u8| *b == b'\r' || *b == b'\n';
        loop {
            let data = self.input.data();
            let start = data.iter().position(|&b| b == b'$' || b == b'#');
            let gap = start.unwrap_or(data.len());
            if gap > 0 {
                // Line ends between frames are not garbage.
                if data[..gap].iter().all(line_end) {
                    self.input.consume(gap);
                } else {
                    self.input.skip(gap);
                }
                start?;
                continue;
            }
            // A line ends at CR/LF; a new start character inside it means the line was cut.
            let end = data[1..]
                .iter()
                .position(|&b| matches!(b, b'\r' | b'\n' | b'$' | b'#'))
                .map(|p| p + 1);
            let Some(end) = end else {
                if data.len() > MAX_LINE {
                    let n = data.len();
                    self.input.stats.malformed += 1;
                    self.input.reject_frame(n);
                }
                return None;
            };
            let result = parse_line(&data[..end]);
            match &result {
                Ok(_) => self.input.take_frame(end),
                Err(e) => {
                    match e {
                        SeatracError::Checksum { .. } => self.input.stats.checksum_errors += 1,
                        SeatracError::Malformed(_) => self.input.stats.malformed += 1,
                    }
                    self.input.reject_frame(end);
                }
            }
            return Some(result);
        }
    }
}

impl crate::framing::StreamDecoder for SeatracDecoder {
    type Frame = SeatracFrame;
    fn push(&mut self, bytes: &[u8]) {
        SeatracDecoder::push(self, bytes);
    }
    fn next_good_frame(&mut self) -> Option<SeatracFrame> {
        loop {
            if let Ok(f) = self.next_frame()? {
                return Some(f);
            }
        }
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
    fn crc16_arc_check_value() {
        assert_eq!(crc16_arc(b"123456789"), 0xbb3d);
    }

    fn diagnostic() -> UsblDiagnostic {
        UsblDiagnostic {
            xcor_signal_peak: 812.5,
            xcor_threshold: 120.0,
            xcor_cross_point: 77,
            xcor_cross_magnitude: 130.25,
            xcor_detect: 81,
            xcor_data: (0..140).map(|i| (i as f32 * 0.37).sin() * 500.0).collect(),
            channel_rssi_db: vec![-61.2, -60.8, -62.0, -61.5],
            phase_angle: vec![0.5, -1.25, 2.0, -0.75, 0.1, 3.0],
            azimuth_deg: 123.4,
            elevation_deg: -41.7,
            fit_error: 0.125,
        }
    }

    /// Synthetic: built from the layout of the open decoders (no captured frame is public).
    #[test]
    fn usbl_diagnostic_round_trips_through_a_line() {
        let d = diagnostic();
        let line = encode_line(CID_XCVR_USBL, &encode_usbl_diagnostic(&d));
        assert!(line.len() > 1024 && line.len() < MAX_LINE);
        let mut dec = SeatracDecoder::new();
        // Fed in small chunks, as a serial port delivers it.
        for chunk in line.chunks(7) {
            dec.push(chunk);
        }
        match dec.next_frame() {
            Some(Ok(SeatracFrame {
                from_beacon: true,
                message: SeatracMessage::UsblDiagnostic(got),
            })) => assert_eq!(got, d),
            other => panic!("expected the diagnostic, got {other:?}"),
        }
    }

    #[test]
    fn a_diagnostic_shorter_or_longer_than_its_counts_is_malformed() {
        let p = encode_usbl_diagnostic(&diagnostic());
        for bad in [p[..p.len() - 1].to_vec(), [p.clone(), vec![0]].concat()] {
            let mut dec = SeatracDecoder::new();
            dec.push(&encode_line(CID_XCVR_USBL, &bad));
            assert!(matches!(
                dec.next_frame(),
                Some(Err(SeatracError::Malformed(_)))
            ));
            assert_eq!(dec.stats().malformed, 1);
        }
    }
}
