//! NMEA 0183 sentences from a GNSS receiver: `$<talker><type>,<fields>*<hh>\r\n`, where `hh` is
//! the XOR of the bytes between `$` and `*` in two hexadecimal digits.
//!
//! Decoded, from any talker (`GP`, `GN`, `GL`, `GA`, `GB`, `IN`, ...): `GGA` (fix, quality,
//! satellites, HDOP, altitude and geoid separation), `RMC` (fix, status, speed and course, date),
//! `VTG` (course and speed), `GST` (standard deviations of latitude, longitude and altitude),
//! `ZDA` (date) and `HDT` (true heading). Other sentences with a good checksum come back as
//! [`NmeaSentence::Other`]; sentences without a checksum are refused (every receiver sends one,
//! and without it a damaged line cannot be told from a good one). Empty fields are `None`: a
//! receiver without a fix sends its sentences with the position fields empty.

use crate::framing::{DecoderStats, FrameBuffer};
use serde::Serialize;

/// Longest sentence accepted (the standard says 82 bytes; receivers send longer ones, e.g.
/// high-precision GGA and `GSV` with signal ids).
pub const MAX_LINE: usize = 256;

/// The checksum of the bytes between `$` and `*`.
pub fn checksum(body: &[u8]) -> u8 {
    body.iter().fold(0, |a, b| a ^ b)
}

/// A time of day (UTC), as the sentences give it.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Serialize)]
pub struct TimeOfDay {
    /// Milliseconds since midnight UTC (0..86 400 999; a leap second's 60 is accepted).
    pub ms: u32,
}

/// A calendar date (UTC).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
pub struct Date {
    pub year: i32,
    pub month: u32,
    pub day: u32,
}

/// `GGA`: the fix.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Gga {
    pub time: Option<TimeOfDay>,
    pub latitude_deg: Option<f64>,
    pub longitude_deg: Option<f64>,
    /// 0 no fix, 1 autonomous, 2 differential, 4 RTK fixed, 5 RTK float, 6 dead reckoning,
    /// 7 manual input, 8 simulator, 9 SBAS (some receivers).
    pub quality: u8,
    pub satellites: Option<u32>,
    pub hdop: Option<f64>,
    /// Altitude above mean sea level (m).
    pub altitude_msl_m: Option<f64>,
    /// Geoid separation: ellipsoid height minus mean-sea-level altitude (m).
    pub geoid_separation_m: Option<f64>,
}

/// `RMC`: recommended minimum data.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Rmc {
    pub time: Option<TimeOfDay>,
    /// `A` valid, `V` warning.
    pub valid: bool,
    pub latitude_deg: Option<f64>,
    pub longitude_deg: Option<f64>,
    pub speed_knots: Option<f64>,
    /// Course over ground, true (deg).
    pub course_deg: Option<f64>,
    pub date: Option<Date>,
}

/// `VTG`: course and speed over ground.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Vtg {
    pub course_deg: Option<f64>,
    pub speed_knots: Option<f64>,
}

/// `GST`: pseudorange error statistics (one-sigma, m).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Gst {
    pub time: Option<TimeOfDay>,
    pub rms_m: Option<f64>,
    pub latitude_std_m: Option<f64>,
    pub longitude_std_m: Option<f64>,
    pub altitude_std_m: Option<f64>,
}

/// `ZDA`: time and date.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Zda {
    pub time: Option<TimeOfDay>,
    pub date: Option<Date>,
}

/// One decoded sentence.
#[derive(Debug, Clone, PartialEq, Serialize)]
#[serde(tag = "sentence")]
pub enum NmeaSentence {
    #[serde(rename = "GGA")]
    Gga(Gga),
    #[serde(rename = "RMC")]
    Rmc(Rmc),
    #[serde(rename = "VTG")]
    Vtg(Vtg),
    #[serde(rename = "GST")]
    Gst(Gst),
    #[serde(rename = "ZDA")]
    Zda(Zda),
    /// True heading (deg), from a dual-antenna receiver or a gyrocompass.
    #[serde(rename = "HDT")]
    Hdt { heading_deg: Option<f64> },
    /// Any other sentence with a good checksum: its address (`GPGSV`, `PUBX`, ...).
    #[serde(rename = "other")]
    Other { address: String },
}

impl NmeaSentence {
    /// The time of day the sentence is stamped with, for those that carry one.
    pub fn time(&self) -> Option<TimeOfDay> {
        match self {
            NmeaSentence::Gga(s) => s.time,
            NmeaSentence::Rmc(s) => s.time,
            NmeaSentence::Gst(s) => s.time,
            NmeaSentence::Zda(s) => s.time,
            _ => None,
        }
    }
}

/// Why a line was not a sentence.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum NmeaError {
    #[error("checksum {found:02X}, computed {computed:02X}")]
    Checksum { found: u8, computed: u8 },
    #[error("sentence without a checksum")]
    NoChecksum,
    #[error("malformed {0} sentence")]
    Malformed(String),
}

fn num(s: &str) -> Result<Option<f64>, ()> {
    let s = s.trim();
    if s.is_empty() {
        return Ok(None);
    }
    s.parse::<f64>()
        .ok()
        .filter(|v| v.is_finite())
        .map(Some)
        .ok_or(())
}

fn time_of_day(s: &str) -> Result<Option<TimeOfDay>, ()> {
    let s = s.trim();
    if s.is_empty() {
        return Ok(None);
    }
    let (hms, frac) = s.split_once('.').unwrap_or((s, ""));
    if hms.len() != 6 || !hms.bytes().all(|b| b.is_ascii_digit()) {
        return Err(());
    }
    let n = |r: std::ops::Range<usize>| hms[r].parse::<u32>().map_err(|_| ());
    let (h, m, sec) = (n(0..2)?, n(2..4)?, n(4..6)?);
    if h > 23 || m > 59 || sec > 60 || !frac.bytes().all(|b| b.is_ascii_digit()) {
        return Err(());
    }
    let ms = if frac.is_empty() {
        0
    } else {
        let digits: String = frac.chars().chain("000".chars()).take(3).collect();
        digits.parse::<u32>().map_err(|_| ())?
    };
    Ok(Some(TimeOfDay {
        ms: ((h * 60 + m) * 60 + sec) * 1000 + ms,
    }))
}

/// `ddmm.mmmm` / `dddmm.mmmm` and the hemisphere letter.
fn angle(value: &str, hemisphere: &str, max_deg: f64) -> Result<Option<f64>, ()> {
    let Some(v) = num(value)? else {
        return Ok(None);
    };
    let deg = (v / 100.0).trunc();
    let minutes = v - deg * 100.0;
    if v < 0.0 || minutes >= 60.0 {
        return Err(());
    }
    let a = deg + minutes / 60.0;
    let signed = match hemisphere.trim() {
        "N" | "E" => a,
        "S" | "W" => -a,
        _ => return Err(()),
    };
    if signed.abs() > max_deg {
        return Err(());
    }
    Ok(Some(signed))
}

fn date(day: u32, month: u32, year: i32) -> Result<Option<Date>, ()> {
    chrono::NaiveDate::from_ymd_opt(year, month, day)
        .map(|_| Some(Date { year, month, day }))
        .ok_or(())
}

/// Parses the fields after the address; `Err` when a field that is present is unreadable.
fn parse(kind: &str, address: &str, f: &[&str]) -> Result<NmeaSentence, ()> {
    let field = |i: usize| f.get(i).copied().unwrap_or("");
    Ok(match kind {
        "GGA" => {
            if f.len() < 11 {
                return Err(());
            }
            NmeaSentence::Gga(Gga {
                time: time_of_day(field(0))?,
                latitude_deg: angle(field(1), field(2), 90.0)?,
                longitude_deg: angle(field(3), field(4), 180.0)?,
                quality: match field(5).trim() {
                    "" => 0,
                    q => q.parse().map_err(|_| ())?,
                },
                satellites: match field(6).trim() {
                    "" => None,
                    n => Some(n.parse().map_err(|_| ())?),
                },
                hdop: num(field(7))?,
                altitude_msl_m: num(field(8))?,
                geoid_separation_m: num(field(10))?,
            })
        }
        "RMC" => {
            if f.len() < 9 {
                return Err(());
            }
            let d = field(8).trim();
            let date = if d.is_empty() {
                None
            } else {
                if d.len() != 6 || !d.bytes().all(|b| b.is_ascii_digit()) {
                    return Err(());
                }
                let n = |r: std::ops::Range<usize>| d[r].parse::<u32>().map_err(|_| ());
                // Two-digit years: 80..99 are 1980..1999 (GPS began in 1980), the rest 20xx.
                let yy = n(4..6)? as i32;
                date(
                    n(0..2)?,
                    n(2..4)?,
                    if yy >= 80 { 1900 + yy } else { 2000 + yy },
                )?
            };
            NmeaSentence::Rmc(Rmc {
                time: time_of_day(field(0))?,
                valid: field(1).trim() == "A",
                latitude_deg: angle(field(2), field(3), 90.0)?,
                longitude_deg: angle(field(4), field(5), 180.0)?,
                speed_knots: num(field(6))?,
                course_deg: num(field(7))?,
                date,
            })
        }
        "VTG" => {
            // Old form: course, magnetic course, knots, km/h without unit letters.
            let (course, knots) = if f.len() >= 8 {
                (field(0), field(4))
            } else if f.len() >= 4 {
                (field(0), field(2))
            } else {
                return Err(());
            };
            NmeaSentence::Vtg(Vtg {
                course_deg: num(course)?,
                speed_knots: num(knots)?,
            })
        }
        "GST" => {
            if f.len() < 8 {
                return Err(());
            }
            NmeaSentence::Gst(Gst {
                time: time_of_day(field(0))?,
                rms_m: num(field(1))?,
                latitude_std_m: num(field(5))?,
                longitude_std_m: num(field(6))?,
                altitude_std_m: num(field(7))?,
            })
        }
        "ZDA" => {
            if f.len() < 4 {
                return Err(());
            }
            let n = |s: &str| s.trim().parse::<u32>().map_err(|_| ());
            let date = if field(1).trim().is_empty() || field(3).trim().is_empty() {
                None
            } else {
                date(n(field(1))?, n(field(2))?, n(field(3))? as i32)?
            };
            NmeaSentence::Zda(Zda {
                time: time_of_day(field(0))?,
                date,
            })
        }
        "HDT" => {
            if f.is_empty() {
                return Err(());
            }
            NmeaSentence::Hdt {
                heading_deg: num(field(0))?,
            }
        }
        _ => NmeaSentence::Other {
            address: address.to_string(),
        },
    })
}

/// Decodes one line between `$` and the line end (checksum not yet checked).
pub fn decode_line(line: &[u8]) -> Result<NmeaSentence, NmeaError> {
    let body_end = line
        .iter()
        .rposition(|&b| b == b'*')
        .ok_or(NmeaError::NoChecksum)?;
    let (body, tail) = (&line[..body_end], &line[body_end + 1..]);
    let found = std::str::from_utf8(tail)
        .ok()
        .filter(|h| h.len() == 2)
        .and_then(|h| u8::from_str_radix(h, 16).ok())
        .ok_or_else(|| NmeaError::Malformed("checksum field".into()))?;
    let computed = checksum(body);
    if found != computed {
        return Err(NmeaError::Checksum { found, computed });
    }
    let text = std::str::from_utf8(body).map_err(|_| NmeaError::Malformed("text".into()))?;
    let mut parts = text.split(',');
    let address = parts.next().unwrap_or("");
    let fields: Vec<&str> = parts.collect();
    // Standard sentences: two talker letters and three type letters. Proprietary ones (`P...`)
    // are returned whole.
    let kind = if address.len() == 5 && !address.starts_with('P') {
        &address[2..]
    } else {
        ""
    };
    parse(kind, address, &fields).map_err(|()| NmeaError::Malformed(address.to_string()))
}

/// Incremental sentence decoder.
#[derive(Debug, Clone)]
pub struct NmeaDecoder {
    input: FrameBuffer,
}

impl Default for NmeaDecoder {
    fn default() -> Self {
        Self::new()
    }
}

impl NmeaDecoder {
    pub fn new() -> Self {
        NmeaDecoder {
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

    /// The next sentence, or `None` when no complete line is buffered.
    pub fn next_sentence(&mut self) -> Option<Result<NmeaSentence, NmeaError>> {
        loop {
            let data = self.input.data();
            let is_end = |b: &u8| *b == b'\r' || *b == b'\n';
            let Some(start) = data.iter().position(|&b| b == b'$') else {
                let n = data.len();
                if data.iter().all(is_end) {
                    self.input.consume(n);
                } else {
                    self.input.skip(n);
                }
                return None;
            };
            if start > 0 {
                if data[..start].iter().all(is_end) {
                    self.input.consume(start);
                } else {
                    self.input.skip(start);
                }
                continue;
            }
            // A `$` inside the line starts a new sentence: the one before it was cut short.
            let end = data[1..]
                .iter()
                .position(|&b| b == b'\r' || b == b'\n' || b == b'$')
                .map(|i| i + 1);
            let Some(end) = end else {
                if data.len() > MAX_LINE {
                    self.input.skip(data.len());
                }
                return None;
            };
            if data[end] == b'$' {
                self.input.skip(end);
                continue;
            }
            let result = decode_line(&data[1..end]);
            match &result {
                Ok(_) => self.input.take_frame(end),
                Err(e) => {
                    match e {
                        NmeaError::Checksum { .. } => self.input.stats.checksum_errors += 1,
                        _ => self.input.stats.malformed += 1,
                    }
                    self.input.reject_frame(end);
                }
            }
            return Some(result);
        }
    }
}

impl crate::framing::StreamDecoder for NmeaDecoder {
    type Frame = NmeaSentence;
    fn push(&mut self, bytes: &[u8]) {
        NmeaDecoder::push(self, bytes)
    }
    fn next_good_frame(&mut self) -> Option<NmeaSentence> {
        loop {
            if let Ok(s) = self.next_sentence()? {
                return Some(s);
            }
        }
    }
    fn stats(&self) -> &DecoderStats {
        NmeaDecoder::stats(self)
    }
    fn frame_start(&self) -> u64 {
        self.input.frame_start()
    }
}

/// Writes a sentence with its checksum and line end: `body` is what goes between `$` and `*`.
pub fn sentence(body: &str) -> Vec<u8> {
    format!("${body}*{:02X}\r\n", checksum(body.as_bytes())).into_bytes()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn one(line: &str) -> NmeaSentence {
        let mut d = NmeaDecoder::new();
        d.push(line.as_bytes());
        d.push(b"\r\n");
        d.next_sentence().expect("a line").expect("a sentence")
    }

    #[test]
    fn the_published_examples_decode() {
        // pynmea2's test_types.py (MIT).
        let NmeaSentence::Gga(g) =
            one("$GPGGA,184353.07,1929.045,S,02410.506,E,1,04,2.6,100.00,M,-33.9,M,,0000*6D")
        else {
            panic!("GGA");
        };
        assert_eq!(g.time, Some(TimeOfDay { ms: 67_433_070 }));
        assert!((g.latitude_deg.expect("a value") + (19.0 + 29.045 / 60.0)).abs() < 1e-12);
        assert!((g.longitude_deg.expect("a value") - (24.0 + 10.506 / 60.0)).abs() < 1e-12);
        assert_eq!((g.quality, g.satellites, g.hdop), (1, Some(4), Some(2.6)));
        assert_eq!(
            (g.altitude_msl_m, g.geoid_separation_m),
            (Some(100.0), Some(-33.9))
        );
        let NmeaSentence::Gst(s) =
            one("$GPGST,172814.0,0.006,0.023,0.020,273.6,0.023,0.020,0.031*6A")
        else {
            panic!("GST");
        };
        assert_eq!(
            (s.latitude_std_m, s.longitude_std_m, s.altitude_std_m),
            (Some(0.023), Some(0.020), Some(0.031))
        );
        let NmeaSentence::Rmc(r) =
            one("$GPRMC,225446,A,4916.45,N,12311.12,W,000.5,054.7,191194,020.3,E*68")
        else {
            panic!("RMC");
        };
        assert!(r.valid);
        assert_eq!(
            r.date,
            Some(Date {
                year: 1994,
                month: 11,
                day: 19
            })
        );
        assert_eq!((r.speed_knots, r.course_deg), (Some(0.5), Some(54.7)));
    }

    #[test]
    fn a_receiver_without_a_fix_sends_empty_fields() {
        let NmeaSentence::Gga(g) = one(std::str::from_utf8(&sentence(
            "GPGGA,120000.00,,,,,0,00,99.99,,,,,,",
        ))
        .expect("a value")
        .trim()) else {
            panic!("GGA");
        };
        assert_eq!((g.latitude_deg, g.quality, g.hdop), (None, 0, Some(99.99)));
    }

    #[test]
    fn damaged_lines_are_counted_and_the_next_one_decodes() {
        let good = "$GPHDT,274.07,T*03\r\n";
        let mut bytes = b"\x00\xffnoise$GPHDT,274.07,T*04\r\n$GPGGA,12$GPHDT,1,T\r\n".to_vec();
        bytes.extend_from_slice(good.as_bytes());
        let mut d = NmeaDecoder::new();
        d.push(&bytes);
        let mut got = Vec::new();
        while let Some(s) = d.next_sentence() {
            got.push(s);
        }
        assert_eq!(got.len(), 3, "{got:?}");
        assert!(matches!(got[0], Err(NmeaError::Checksum { .. })));
        assert_eq!(got[1], Err(NmeaError::NoChecksum));
        assert_eq!(
            got[2],
            Ok(NmeaSentence::Hdt {
                heading_deg: Some(274.07)
            })
        );
        let s = d.stats();
        assert_eq!((s.frames, s.checksum_errors, s.malformed), (1, 1, 1));
        assert!(s.bytes_skipped > 7);
    }

    #[test]
    fn impossible_values_are_malformed_not_decoded() {
        for body in [
            "GPGGA,250000.00,4916.45,N,12311.12,W,1,08,1.0,10.0,M,0.0,M,,",
            "GPGGA,120000.00,9116.45,N,12311.12,W,1,08,1.0,10.0,M,0.0,M,,",
            "GPGGA,120000.00,4966.45,N,12311.12,W,1,08,1.0,10.0,M,0.0,M,,",
            "GPGGA,120000.00,4916.45,X,12311.12,W,1,08,1.0,10.0,M,0.0,M,,",
            "GPRMC,120000,A,4916.45,N,12311.12,W,000.5,054.7,311194,,",
            "GPZDA,120000.00,xx,11,2026,,",
        ] {
            let mut d = NmeaDecoder::new();
            d.push(&sentence(body));
            assert!(
                matches!(d.next_sentence(), Some(Err(NmeaError::Malformed(_)))),
                "{body}"
            );
        }
    }
}
