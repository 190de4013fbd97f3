//! Water Linked DVL (A50/A125) Ethernet reports: newline-delimited JSON on TCP port 16171.
//!
//! Decoded: the velocity report (`"type": "velocity"`, formats `json_v2` and `json_v3`: velocity,
//! figure of merit, 3×3 covariance, altitude, validity, status, the time of validity and of
//! transmission in µs, the transducers) into the same [`Velocity`] the serial `wrz` report gives,
//! so that one conversion (`to_schema::water_linked_velocity`) serves both; the dead-reckoning
//! report (`"type": "position_local"`) into [`DeadReckoning`]. Other report types are returned
//! by name. A line that is not JSON, or a velocity report without its fields, is counted as
//! malformed and skipped; a line longer than [`MAX_LINE`] without a newline is dropped.

use crate::framing::{DecoderStats, FrameBuffer};
use crate::wldvl::{DeadReckoning, Velocity};
use serde::{Deserialize, Serialize};

/// Longest report accepted (a velocity report with four transducers is about 1.2 kB).
pub const MAX_LINE: usize = 16 * 1024;

/// One transducer of a velocity report.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct JsonTransducer {
    pub id: u8,
    pub velocity: f64,
    pub distance: f64,
    pub rssi: f64,
    pub nsd: f64,
    pub beam_valid: bool,
}

#[derive(Deserialize)]
struct VelocityReport {
    vx: f64,
    vy: f64,
    vz: f64,
    fom: f64,
    covariance: [[f64; 3]; 3],
    altitude: f64,
    velocity_valid: bool,
    status: u32,
    time_of_validity: u64,
    time_of_transmission: u64,
    /// Time since the previous report (ms).
    #[serde(default)]
    time: f64,
    #[serde(default)]
    transducers: Vec<JsonTransducer>,
}

#[derive(Deserialize)]
struct PositionReport {
    ts: f64,
    x: f64,
    y: f64,
    z: f64,
    std: f64,
    roll: f64,
    pitch: f64,
    yaw: f64,
    status: u32,
}

/// A report from the DVL's TCP service.
#[derive(Debug, Clone, PartialEq, Serialize)]
#[serde(tag = "report", rename_all = "snake_case")]
pub enum JsonFrame {
    Velocity {
        velocity: Velocity,
        transducers: Vec<JsonTransducer>,
    },
    DeadReckoning(DeadReckoning),
    /// A report of another type (its `type` field), or without one.
    Other {
        kind: String,
    },
}

/// Why a line was not used.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum JsonError {
    #[error("not a JSON object: {0}")]
    NotJson(String),
    #[error("{kind} report without its fields: {why}")]
    Fields { kind: String, why: String },
}

/// Parses one line (without its newline).
pub fn parse_line(line: &[u8]) -> Result<JsonFrame, JsonError> {
    let value: serde_json::Value =
        serde_json::from_slice(line).map_err(|e| JsonError::NotJson(e.to_string()))?;
    if !value.is_object() {
        return Err(JsonError::NotJson("not an object".into()));
    }
    let kind = value
        .get("type")
        .and_then(|t| t.as_str())
        .unwrap_or_default()
        .to_string();
    let fields = |e: serde_json::Error| JsonError::Fields {
        kind: kind.clone(),
        why: e.to_string(),
    };
    match kind.as_str() {
        "velocity" => {
            let r: VelocityReport = serde_json::from_value(value).map_err(fields)?;
            let c = r.covariance;
            Ok(JsonFrame::Velocity {
                velocity: Velocity {
                    velocity_m_s: [r.vx, r.vy, r.vz],
                    valid: r.velocity_valid,
                    altitude_m: r.altitude,
                    figure_of_merit_m_s: r.fom,
                    covariance: [
                        c[0][0], c[0][1], c[0][2], c[1][0], c[1][1], c[1][2], c[2][0], c[2][1],
                        c[2][2],
                    ],
                    time_of_validity_us: r.time_of_validity,
                    time_of_transmission_us: r.time_of_transmission,
                    time_since_last_ms: r.time,
                    status: r.status,
                },
                transducers: r.transducers,
            })
        }
        "position_local" => {
            let r: PositionReport = serde_json::from_value(value).map_err(fields)?;
            Ok(JsonFrame::DeadReckoning(DeadReckoning {
                time_s: r.ts,
                position_m: [r.x, r.y, r.z],
                position_std_m: r.std,
                roll_deg: r.roll,
                pitch_deg: r.pitch,
                yaw_deg: r.yaw,
                status: r.status,
            }))
        }
        _ => Ok(JsonFrame::Other { kind }),
    }
}

/// Incremental decoder of the newline-delimited reports.
#[derive(Debug, Clone)]
pub struct JsonDecoder {
    input: FrameBuffer,
}

impl Default for JsonDecoder {
    fn default() -> Self {
        Self::new()
    }
}

impl JsonDecoder {
    pub fn new() -> Self {
        JsonDecoder {
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

    /// The next report; `None` when more bytes are needed. Empty lines are skipped silently.
    pub fn next_frame(&mut self) -> Option<Result<JsonFrame, JsonError>> {
        loop {
            let data = self.input.data();
            let Some(end) = data.iter().position(|&b| b == b'\n') else {
                if data.len() > MAX_LINE {
                    self.input.skip(data.len());
                }
                return None;
            };
            let line = &data[..end];
            if line.iter().all(|b| b.is_ascii_whitespace()) {
                self.input.consume(end + 1);
                continue;
            }
            let result = parse_line(line);
            match &result {
                Ok(_) => self.input.take_frame(end + 1),
                Err(_) => {
                    self.input.stats.malformed += 1;
                    self.input.reject_frame(end + 1);
                }
            }
            return Some(result);
        }
    }
}

impl crate::framing::StreamDecoder for JsonDecoder {
    type Frame = JsonFrame;
    fn push(&mut self, bytes: &[u8]) {
        JsonDecoder::push(self, bytes)
    }
    fn next_good_frame(&mut self) -> Option<JsonFrame> {
        loop {
            match self.next_frame()? {
                Ok(f) => return Some(f),
                Err(_) => continue,
            }
        }
    }
    fn stats(&self) -> &DecoderStats {
        JsonDecoder::stats(self)
    }
    fn frame_start(&self) -> u64 {
        self.input.frame_start()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn broken_lines_are_counted_and_the_next_report_still_decodes() {
        let mut d = JsonDecoder::new();
        d.push(
            b"{\"type\": \"velocity\", \"vx\": 1.0}\nnot json\n\n[1, 2]\n{\"type\": \"config\"}\n",
        );
        let mut got = Vec::new();
        while let Some(f) = d.next_frame() {
            got.push(f);
        }
        assert_eq!(got.len(), 4, "{got:?}");
        assert!(matches!(&got[0], Err(JsonError::Fields { kind, .. }) if kind == "velocity"));
        assert!(matches!(&got[1], Err(JsonError::NotJson(_))));
        assert!(matches!(&got[2], Err(JsonError::NotJson(_))));
        assert_eq!(
            got[3],
            Ok(JsonFrame::Other {
                kind: "config".into()
            })
        );
        assert_eq!(d.stats().malformed, 3);
        assert_eq!(d.stats().frames, 1);
    }

    #[test]
    fn an_endless_line_is_dropped_and_counted() {
        let mut d = JsonDecoder::new();
        d.push(&vec![b'{'; MAX_LINE + 10]);
        assert!(d.next_frame().is_none());
        assert_eq!(d.stats().bytes_skipped, (MAX_LINE + 10) as u64);
        d.push(b"{\"type\": \"x\"}\n");
        assert_eq!(
            d.next_frame(),
            Some(Ok(JsonFrame::Other { kind: "x".into() }))
        );
    }
}
