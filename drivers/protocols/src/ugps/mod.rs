//! Water Linked Underwater GPS (G2 and earlier kits): the topside's HTTP API responses.
//!
//! The topside serves JSON on `http://<topside>/api/v1/…` (the API's OpenAPI description, "The
//! Water Linked Underwater GPS API", v1). Three responses carry what the navigator fuses:
//!
//! - `GET /api/v1/position/acoustic/raw` ([`AcousticRaw`]): the locator's unfiltered fix
//!   relative to the topside (`x`, `y`, `z` depth, m; `std`, m; `position_valid`) and, per
//!   receiver, the measured distance (`receiver_distance`, m; −1 when none), noise
//!   (`receiver_nsd`), signal strength (`receiver_rssi`) and validity (`receiver_valid`). The API
//!   updates it at about 4 Hz and repeats the last reading until the next.
//! - `GET /api/v1/position/master` ([`MasterPosition`]): the topside's GNSS position (`lat`,
//!   `lon`, deg) and heading (`orientation`, deg), with `fix_quality` (0: no data), `hdop`,
//!   `numsats`, `cog` and `sog` (−1: no data). About 1 Hz.
//! - `GET /api/v1/config/receivers/` ([`Receiver`] list): each receiver's configured position
//!   relative to the topside (`x`, `y`, `z`, m) and its `id`.
//!
//! A body that is not JSON, lacks a required field or has a field of the wrong type is refused
//! with a [`UgpsError`] naming it; values out of their physical range are kept out of the
//! message by the conversion ([`to_schema`]), which counts them.

pub mod to_schema;

use serde::Deserialize;

/// Most receivers a reading may carry (the schema's slots).
pub const MAX_RECEIVERS: usize = 4;

/// The paths of the three responses.
pub mod path {
    pub const ACOUSTIC_RAW: &str = "/api/v1/position/acoustic/raw";
    pub const MASTER: &str = "/api/v1/position/master";
    pub const RECEIVERS: &str = "/api/v1/config/receivers/";
}

/// Why a response was not used.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum UgpsError {
    #[error("not a JSON document: {0}")]
    NotJson(String),
    #[error("no field {0:?}")]
    Missing(&'static str),
    #[error("field {field:?}: {why}")]
    Field { field: &'static str, why: String },
}

/// One receiver's part of an acoustic reading.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ReceiverReading {
    /// Measured distance to the locator (m; the API's −1 when none).
    pub distance_m: f64,
    /// Noise spectral density (dB).
    pub nsd_db: f64,
    /// Signal strength (dB).
    pub rssi_db: f64,
    /// The topside's verdict on the signal.
    pub valid: bool,
}

/// `GET /api/v1/position/acoustic/raw`.
#[derive(Debug, Clone, PartialEq)]
pub struct AcousticRaw {
    pub position_valid: bool,
    /// Locator position relative to the topside: x, y, z (depth, down) (m).
    pub position_m: [f64; 3],
    /// The topside's one-sigma of the fix (m).
    pub std_m: f64,
    /// Per receiver, in the order of the API's arrays.
    pub receivers: Vec<ReceiverReading>,
}

/// `GET /api/v1/position/master`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MasterPosition {
    pub lat_deg: f64,
    pub lon_deg: f64,
    /// Heading of the topside (deg; −1: no data).
    pub orientation_deg: f64,
    /// GNSS fix quality (0: no data); absent from the response: `None`.
    pub fix_quality: Option<f64>,
    /// Horizontal dilution of precision (−1: no data).
    pub hdop: Option<f64>,
    pub numsats: Option<f64>,
    /// Course (deg) and speed over ground (km/h) (−1: no data).
    pub cog_deg: Option<f64>,
    pub sog_km_h: Option<f64>,
}

/// One entry of `GET /api/v1/config/receivers/`.
#[derive(Debug, Clone, Copy, PartialEq, Deserialize)]
pub struct Receiver {
    pub id: i64,
    pub x: f64,
    pub y: f64,
    pub z: f64,
}

fn object(body: &[u8]) -> Result<serde_json::Map<String, serde_json::Value>, UgpsError> {
    match serde_json::from_slice::<serde_json::Value>(body) {
        Ok(serde_json::Value::Object(m)) => Ok(m),
        Ok(_) => Err(UgpsError::NotJson("not an object".into())),
        Err(e) => Err(UgpsError::NotJson(e.to_string())),
    }
}

type Map = serde_json::Map<String, serde_json::Value>;

fn number(m: &Map, field: &'static str) -> Result<f64, UgpsError> {
    match m.get(field) {
        None | Some(serde_json::Value::Null) => Err(UgpsError::Missing(field)),
        Some(v) => v.as_f64().ok_or_else(|| UgpsError::Field {
            field,
            why: format!("{v} is not a number"),
        }),
    }
}

fn optional_number(m: &Map, field: &'static str) -> Result<Option<f64>, UgpsError> {
    match m.get(field) {
        None | Some(serde_json::Value::Null) => Ok(None),
        Some(_) => number(m, field).map(Some),
    }
}

/// A flag given as a boolean or as a number (the API's description types `receiver_valid` as
/// numbers; kits send booleans).
fn flag(v: &serde_json::Value) -> Option<bool> {
    match v {
        serde_json::Value::Bool(b) => Some(*b),
        serde_json::Value::Number(n) => n.as_f64().map(|x| x != 0.0),
        _ => None,
    }
}

fn array<'a>(m: &'a Map, field: &'static str) -> Result<&'a Vec<serde_json::Value>, UgpsError> {
    match m.get(field) {
        None | Some(serde_json::Value::Null) => Err(UgpsError::Missing(field)),
        Some(serde_json::Value::Array(a)) => Ok(a),
        Some(v) => Err(UgpsError::Field {
            field,
            why: format!("{v} is not an array"),
        }),
    }
}

fn numbers(m: &Map, field: &'static str) -> Result<Vec<f64>, UgpsError> {
    array(m, field)?
        .iter()
        .map(|v| {
            v.as_f64().ok_or_else(|| UgpsError::Field {
                field,
                why: format!("element {v} is not a number"),
            })
        })
        .collect()
}

/// Decodes `GET /api/v1/position/acoustic/raw`. The four per-receiver arrays must have one
/// length, at most [`MAX_RECEIVERS`].
pub fn acoustic_raw(body: &[u8]) -> Result<AcousticRaw, UgpsError> {
    let m = object(body)?;
    let position_valid = match m.get("position_valid") {
        None | Some(serde_json::Value::Null) => return Err(UgpsError::Missing("position_valid")),
        Some(v) => flag(v).ok_or_else(|| UgpsError::Field {
            field: "position_valid",
            why: format!("{v} is not a flag"),
        })?,
    };
    let position_m = [number(&m, "x")?, number(&m, "y")?, number(&m, "z")?];
    let std_m = number(&m, "std")?;
    let distance = numbers(&m, "receiver_distance")?;
    let nsd = numbers(&m, "receiver_nsd")?;
    let rssi = numbers(&m, "receiver_rssi")?;
    let valid = array(&m, "receiver_valid")?
        .iter()
        .map(|v| {
            flag(v).ok_or_else(|| UgpsError::Field {
                field: "receiver_valid",
                why: format!("element {v} is not a flag"),
            })
        })
        .collect::<Result<Vec<_>, _>>()?;
    let n = distance.len();
    for (field, len) in [
        ("receiver_nsd", nsd.len()),
        ("receiver_rssi", rssi.len()),
        ("receiver_valid", valid.len()),
    ] {
        if len != n {
            return Err(UgpsError::Field {
                field,
                why: format!("{len} elements against {n} distances"),
            });
        }
    }
    if n > MAX_RECEIVERS {
        return Err(UgpsError::Field {
            field: "receiver_distance",
            why: format!("{n} receivers; at most {MAX_RECEIVERS} are read"),
        });
    }
    let receivers = (0..n)
        .map(|k| ReceiverReading {
            distance_m: distance[k],
            nsd_db: nsd[k],
            rssi_db: rssi[k],
            valid: valid[k],
        })
        .collect();
    Ok(AcousticRaw {
        position_valid,
        position_m,
        std_m,
        receivers,
    })
}

/// Decodes `GET /api/v1/position/master` (`lat`, `lon` and `orientation` required).
pub fn master_position(body: &[u8]) -> Result<MasterPosition, UgpsError> {
    let m = object(body)?;
    Ok(MasterPosition {
        lat_deg: number(&m, "lat")?,
        lon_deg: number(&m, "lon")?,
        orientation_deg: number(&m, "orientation")?,
        fix_quality: optional_number(&m, "fix_quality")?,
        hdop: optional_number(&m, "hdop")?,
        numsats: optional_number(&m, "numsats")?,
        cog_deg: optional_number(&m, "cog")?,
        sog_km_h: optional_number(&m, "sog")?,
    })
}

/// Decodes `GET /api/v1/config/receivers/`, sorted by `id` (the order of the acoustic arrays).
pub fn receivers(body: &[u8]) -> Result<Vec<Receiver>, UgpsError> {
    let v: serde_json::Value =
        serde_json::from_slice(body).map_err(|e| UgpsError::NotJson(e.to_string()))?;
    let serde_json::Value::Array(items) = v else {
        return Err(UgpsError::NotJson("not an array".into()));
    };
    let mut out = Vec::with_capacity(items.len());
    for item in items {
        let serde_json::Value::Object(m) = item else {
            return Err(UgpsError::Field {
                field: "receivers",
                why: "an element is not an object".into(),
            });
        };
        let id = match m.get("id") {
            None | Some(serde_json::Value::Null) => return Err(UgpsError::Missing("id")),
            Some(v) => v.as_i64().ok_or_else(|| UgpsError::Field {
                field: "id",
                why: format!("{v} is not an integer"),
            })?,
        };
        out.push(Receiver {
            id,
            x: number(&m, "x")?,
            y: number(&m, "y")?,
            z: number(&m, "z")?,
        });
    }
    if out.len() > MAX_RECEIVERS {
        return Err(UgpsError::Field {
            field: "receivers",
            why: format!("{} receivers; at most {MAX_RECEIVERS} are read", out.len()),
        });
    }
    out.sort_by_key(|r| r.id);
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    const RAW: &str = r#"{"position_valid": true, "receiver_distance": [24.81, 24.9, -1, 25.02],
        "receiver_nsd": [-55.1, -56.0, -60.2, -54.9], "receiver_rssi": [-20.5, -21.0, -70.1, -19.8],
        "receiver_valid": [true, true, false, true], "std": 0.41, "x": 3.2, "y": -11.7, "z": 21.4}"#;

    #[test]
    fn an_acoustic_reading_is_decoded_field_by_field() {
        let r = acoustic_raw(RAW.as_bytes()).expect("decodes");
        assert!(r.position_valid);
        assert_eq!(r.position_m, [3.2, -11.7, 21.4]);
        assert_eq!(r.std_m, 0.41);
        assert_eq!(r.receivers.len(), 4);
        assert_eq!(r.receivers[2].distance_m, -1.0);
        assert!(!r.receivers[2].valid);
        assert_eq!(r.receivers[3].rssi_db, -19.8);
        // Validity as numbers (the API description's type) reads the same.
        let numeric = RAW.replace("[true, true, false, true]", "[1, 1, 0, 1]");
        assert_eq!(acoustic_raw(numeric.as_bytes()).expect("decodes"), r);
    }

    #[test]
    fn broken_acoustic_readings_name_what_is_wrong() {
        assert!(matches!(
            acoustic_raw(b"{\"x\": "),
            Err(UgpsError::NotJson(_))
        ));
        assert!(matches!(
            acoustic_raw(b"[1, 2]"),
            Err(UgpsError::NotJson(_))
        ));
        let no_std = RAW.replace("\"std\": 0.41,", "");
        assert_eq!(
            acoustic_raw(no_std.as_bytes()),
            Err(UgpsError::Missing("std"))
        );
        let text_x = RAW.replace("\"x\": 3.2", "\"x\": \"3.2\"");
        assert!(matches!(
            acoustic_raw(text_x.as_bytes()),
            Err(UgpsError::Field { field: "x", .. })
        ));
        let short = RAW.replace("[-20.5, -21.0, -70.1, -19.8]", "[-20.5]");
        assert!(matches!(
            acoustic_raw(short.as_bytes()),
            Err(UgpsError::Field {
                field: "receiver_rssi",
                ..
            })
        ));
    }

    #[test]
    fn the_master_position_needs_its_position_and_heading_only() {
        let m = master_position(
            br#"{"cog": -1, "fix_quality": 1, "hdop": 0.9, "lat": 47.6062, "lon": -122.3421,
                 "numsats": 11, "orientation": 271.5, "sog": -1}"#,
        )
        .expect("decodes");
        assert_eq!(
            (m.lat_deg, m.lon_deg, m.orientation_deg),
            (47.6062, -122.3421, 271.5)
        );
        assert_eq!(m.fix_quality, Some(1.0));
        let bare =
            master_position(br#"{"lat": 1.0, "lon": 2.0, "orientation": 3.0}"#).expect("decodes");
        assert_eq!(bare.hdop, None);
        assert_eq!(
            master_position(br#"{"lat": 1.0, "orientation": 3.0}"#),
            Err(UgpsError::Missing("lon"))
        );
    }

    #[test]
    fn receivers_are_ordered_by_id() {
        let r = receivers(
            br#"[{"id": 2, "x": -0.5, "y": 1.0, "z": 3.0}, {"id": 1, "x": 0.5, "y": 1.0, "z": 3.0}]"#,
        )
        .expect("decodes");
        assert_eq!(r.iter().map(|r| r.id).collect::<Vec<_>>(), [1, 2]);
        assert_eq!(r[0].x, 0.5);
        assert_eq!(
            receivers(br#"[{"x": 1.0, "y": 1.0, "z": 3.0}]"#),
            Err(UgpsError::Missing("id"))
        );
    }
}
