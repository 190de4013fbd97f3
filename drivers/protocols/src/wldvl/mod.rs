//! Water Linked DVL (A50/A125) serial protocol, version 2.x: ASCII lines
//! `w<type>,<fields>*<crc>\r\n`, where `crc` is CRC-8 (poly 0x07, init 0, no reflection) over the
//! bytes from `w` up to, not including, `*`, printed as two lower-case hex digits.
//!
//! Reports decoded: `wrz` velocity (with covariance and time of validity), `wru` per-transducer,
//! `wrp` dead reckoning, and the deprecated `wrx` velocity / `wrt` transducer-distance reports.
//! Other `w` lines with a good checksum (command responses such as `wrc`, `wrv`) are returned as
//! [`WlFrame::Other`]. The DVL frame is x forward, y right, z down, velocities of the vehicle.

pub mod json;
pub mod to_device;
pub mod to_schema;

use crate::framing::{DecoderStats, FrameBuffer};
use serde::Serialize;

/// Longest line accepted; a longer run without a newline is discarded and counted.
pub const MAX_LINE: usize = 512;

/// CRC-8, polynomial 0x07, initial value 0 (CRC-8/SMBUS, the `crc` crate's catalogue entry).
pub fn crc8(bytes: &[u8]) -> u8 {
    const CRC: crc::Crc<u8> = crc::Crc::<u8>::new(&crc::CRC_8_SMBUS);
    CRC.checksum(bytes)
}

/// `wrz`: velocity report.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Velocity {
    pub velocity_m_s: [f64; 3],
    pub valid: bool,
    pub altitude_m: f64,
    pub figure_of_merit_m_s: f64,
    /// Row-major 3x3 velocity covariance (m^2/s^2).
    pub covariance: [f64; 9],
    /// Time of validity (us, DVL clock).
    pub time_of_validity_us: u64,
    /// Time of transmission (us, DVL clock).
    pub time_of_transmission_us: u64,
    /// Time since the previous velocity report (ms).
    pub time_since_last_ms: f64,
    /// 0 = normal, 1 = high temperature warning.
    pub status: u32,
}

/// `wru`: one transducer.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Transducer {
    pub id: u8,
    pub velocity_m_s: f64,
    pub distance_m: f64,
    pub rssi_dbm: f64,
    pub noise_dbm: f64,
}

/// `wrp`: dead-reckoning position.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct DeadReckoning {
    pub time_s: f64,
    pub position_m: [f64; 3],
    pub position_std_m: f64,
    pub roll_deg: f64,
    pub pitch_deg: f64,
    pub yaw_deg: f64,
    pub status: u32,
}

/// `wrx` (deprecated): velocity report.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct VelocityOld {
    pub time_since_last_ms: f64,
    pub velocity_m_s: [f64; 3],
    pub figure_of_merit_m_s: f64,
    pub altitude_m: f64,
    pub valid: bool,
    pub status: u32,
}

#[derive(Debug, Clone, PartialEq, Serialize)]
#[serde(tag = "report", rename_all = "snake_case")]
pub enum WlFrame {
    Velocity(Velocity),
    Transducer(Transducer),
    DeadReckoning(DeadReckoning),
    VelocityOld(VelocityOld),
    /// `wrt` (deprecated): distance per transducer (m); -1 = no value.
    TransducerDistances {
        distance_m: [f64; 4],
    },
    /// Another `w` line with a good checksum: its type and fields.
    Other {
        kind: String,
        fields: Vec<String>,
    },
}

fn num(s: &str) -> Option<f64> {
    s.trim().parse::<f64>().ok().filter(|v| v.is_finite())
}

fn flag(s: &str) -> Option<bool> {
    match s.trim() {
        "y" => Some(true),
        "n" => Some(false),
        _ => None,
    }
}

/// Parses the content between `w` and `*` (checksum already verified).
fn parse(body: &str) -> Option<WlFrame> {
    let mut parts = body.split(',');
    let kind = parts.next()?;
    let f: Vec<&str> = parts.collect();
    Some(match kind {
        "wrz" if f.len() >= 11 => {
            let cov: Vec<f64> = f[6].split(';').map(num).collect::<Option<Vec<_>>>()?;
            Velocity {
                velocity_m_s: [num(f[0])?, num(f[1])?, num(f[2])?],
                valid: flag(f[3])?,
                altitude_m: num(f[4])?,
                figure_of_merit_m_s: num(f[5])?,
                covariance: cov.try_into().ok()?,
                time_of_validity_us: f[7].trim().parse().ok()?,
                time_of_transmission_us: f[8].trim().parse().ok()?,
                time_since_last_ms: num(f[9])?,
                status: f[10].trim().parse().ok()?,
            }
            .into()
        }
        "wru" if f.len() >= 5 => WlFrame::Transducer(Transducer {
            id: f[0].trim().parse().ok()?,
            velocity_m_s: num(f[1])?,
            distance_m: num(f[2])?,
            rssi_dbm: num(f[3])?,
            noise_dbm: num(f[4])?,
        }),
        "wrp" if f.len() >= 9 => WlFrame::DeadReckoning(DeadReckoning {
            time_s: num(f[0])?,
            position_m: [num(f[1])?, num(f[2])?, num(f[3])?],
            position_std_m: num(f[4])?,
            roll_deg: num(f[5])?,
            pitch_deg: num(f[6])?,
            yaw_deg: num(f[7])?,
            status: f[8].trim().parse().ok()?,
        }),
        "wrx" if f.len() >= 7 => WlFrame::VelocityOld(VelocityOld {
            time_since_last_ms: num(f[0])?,
            velocity_m_s: [num(f[1])?, num(f[2])?, num(f[3])?],
            figure_of_merit_m_s: num(f[4])?,
            altitude_m: num(f[5])?,
            valid: flag(f[6])?,
            status: f.get(7).and_then(|s| s.trim().parse().ok()).unwrap_or(0),
        }),
        "wrt" if f.len() >= 4 => WlFrame::TransducerDistances {
            distance_m: [num(f[0])?, num(f[1])?, num(f[2])?, num(f[3])?],
        },
        "wrz" | "wru" | "wrp" | "wrx" | "wrt" => return None,
        _ => WlFrame::Other {
            kind: kind.to_string(),
            fields: f.iter().map(|s| s.to_string()).collect(),
        },
    })
}

impl From<Velocity> for WlFrame {
    fn from(v: Velocity) -> Self {
        WlFrame::Velocity(v)
    }
}

/// Why a line was not a frame.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum WlError {
    #[error("checksum {found:02x}, computed {computed:02x}")]
    Checksum { found: u8, computed: u8 },
    #[error("malformed {0} report")]
    Malformed(String),
}

/// Incremental line decoder.
#[derive(Debug, Clone)]
pub struct WlDecoder {
    input: FrameBuffer,
}

impl Default for WlDecoder {
    fn default() -> Self {
        Self::new()
    }
}

impl WlDecoder {
    pub fn new() -> Self {
        WlDecoder {
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

    /// The next line's frame, or `None` when no complete line is buffered.
    pub fn next_frame(&mut self) -> Option<Result<WlFrame, WlError>> {
        loop {
            let data = self.input.data();
            let Some(start) = data.iter().position(|&b| b == b'w') else {
                // Keep nothing: no frame can start here. Line ends are not garbage.
                let n = data.len();
                if data.iter().all(|&b| b == b'\r' || b == b'\n') {
                    self.input.consume(n);
                } else {
                    self.input.skip(n);
                }
                return None;
            };
            if start > 0 {
                // Line ends (CR, LF) between frames are not garbage.
                let junk = data[..start].iter().any(|&b| b != b'\r' && b != b'\n');
                if junk {
                    self.input.skip(start);
                } else {
                    self.input.consume(start);
                }
                continue;
            }
            let Some(end) = data.iter().position(|&b| b == b'\n' || b == b'\r') else {
                if data.len() > MAX_LINE {
                    self.input.skip(data.len());
                }
                return None;
            };
            let line = &data[..end];
            let result = match line.iter().rposition(|&b| b == b'*') {
                Some(star)
                    if line.len() == star + 3
                        && line[..star]
                            .iter()
                            .all(|b| b.is_ascii() && !b.is_ascii_control()) =>
                {
                    let found = std::str::from_utf8(&line[star + 1..])
                        .ok()
                        .and_then(|h| u8::from_str_radix(h, 16).ok());
                    let computed = crc8(&line[..star]);
                    match found {
                        Some(f) if f == computed => {
                            let body = String::from_utf8_lossy(&line[..star]).to_string();
                            match parse(&body) {
                                Some(frame) => Ok(frame),
                                None => Err(WlError::Malformed(
                                    body.split(',').next().unwrap_or_default().to_string(),
                                )),
                            }
                        }
                        Some(f) => Err(WlError::Checksum { found: f, computed }),
                        None => Err(WlError::Malformed("checksum field".into())),
                    }
                }
                _ => Err(WlError::Malformed("line".into())),
            };
            if result.is_err()
                && let Some(next) = line[1..].iter().position(|&b| b == b'w')
            {
                // Garbage that happened to contain a `w` ran into a real line: drop the garbage
                // and try again from the next start rather than losing the line.
                self.input.skip(next + 1);
                continue;
            }
            let consumed = end + 1;
            match &result {
                Ok(_) => self.input.take_frame(consumed),
                Err(e) => {
                    match e {
                        WlError::Checksum { .. } => self.input.stats.checksum_errors += 1,
                        WlError::Malformed(_) => self.input.stats.malformed += 1,
                    }
                    self.input.reject_frame(consumed);
                }
            }
            return Some(result);
        }
    }
}

/// Encodes a report as a line with its checksum (`\r\n` terminated).
pub fn encode(frame: &WlFrame) -> Vec<u8> {
    let body = match frame {
        WlFrame::Velocity(v) => format!(
            "wrz,{:.3},{:.3},{:.3},{},{:.2},{:.3},{},{},{},{:.2},{}",
            v.velocity_m_s[0],
            v.velocity_m_s[1],
            v.velocity_m_s[2],
            if v.valid { "y" } else { "n" },
            v.altitude_m,
            v.figure_of_merit_m_s,
            v.covariance
                .iter()
                .map(|c| format!("{c:e}"))
                .collect::<Vec<_>>()
                .join(";"),
            v.time_of_validity_us,
            v.time_of_transmission_us,
            v.time_since_last_ms,
            v.status
        ),
        WlFrame::Transducer(t) => format!(
            "wru,{},{:.3},{:.2},{:.0},{:.0}",
            t.id, t.velocity_m_s, t.distance_m, t.rssi_dbm, t.noise_dbm
        ),
        WlFrame::DeadReckoning(d) => format!(
            "wrp,{:.3},{:.2},{:.2},{:.2},{:.1},{:.1},{:.1},{:.1},{}",
            d.time_s,
            d.position_m[0],
            d.position_m[1],
            d.position_m[2],
            d.position_std_m,
            d.roll_deg,
            d.pitch_deg,
            d.yaw_deg,
            d.status
        ),
        WlFrame::VelocityOld(v) => format!(
            "wrx,{:.2},{:.3},{:.3},{:.3},{:.3},{:.2},{},{}",
            v.time_since_last_ms,
            v.velocity_m_s[0],
            v.velocity_m_s[1],
            v.velocity_m_s[2],
            v.figure_of_merit_m_s,
            v.altitude_m,
            if v.valid { "y" } else { "n" },
            v.status
        ),
        WlFrame::TransducerDistances { distance_m } => format!(
            "wrt,{:.2},{:.2},{:.2},{:.2}",
            distance_m[0], distance_m[1], distance_m[2], distance_m[3]
        ),
        WlFrame::Other { kind, fields } => {
            let mut s = kind.clone();
            for f in fields {
                s.push(',');
                s.push_str(f);
            }
            s
        }
    };
    format!("{body}*{:02x}\r\n", crc8(body.as_bytes())).into_bytes()
}

impl crate::framing::StreamDecoder for WlDecoder {
    type Frame = WlFrame;
    fn push(&mut self, bytes: &[u8]) {
        WlDecoder::push(self, bytes);
    }
    fn next_good_frame(&mut self) -> Option<WlFrame> {
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
    fn crc8_check_value() {
        assert_eq!(crc8(b"123456789"), 0xf4);
    }

    #[test]
    fn garbage_with_a_w_before_a_line_does_not_cost_the_line() {
        let v = Velocity {
            velocity_m_s: [1.0, 0.0, 0.1],
            valid: true,
            altitude_m: 3.0,
            figure_of_merit_m_s: 0.01,
            covariance: [0.0; 9],
            time_of_validity_us: 1,
            time_of_transmission_us: 2,
            time_since_last_ms: 100.0,
            status: 0,
        };
        let mut bytes = b"\x13w7\xffwq".to_vec();
        bytes.extend(encode(&WlFrame::Velocity(v.clone())));
        let mut d = WlDecoder::new();
        d.push(&bytes);
        match d.next_frame() {
            Some(Ok(WlFrame::Velocity(got))) => assert_eq!(got.velocity_m_s, v.velocity_m_s),
            other => panic!("expected the velocity line, got {other:?}"),
        }
        assert_eq!(d.stats().checksum_errors + d.stats().malformed, 0);
        assert_eq!(d.stats().bytes_skipped, 6);
    }
}
