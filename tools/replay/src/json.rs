//! The JSON documents the tools print with `--json` and write as `report.json`: the versioned
//! form every one of them takes.
//!
//! One vocabulary (docs/json.md): every document is an object whose first field is
//! `format_version` ([`auvnav_version::JSON_FORMAT_VERSION`]); a list is given as `rows`;
//! quantities carry their unit in the name (`_s`, `_m`, `_deg`, `_hz`, ...), wall-clock time is
//! `wall_s`, and the same quantity has the same name in every document.

use serde::Serialize;

#[derive(Serialize)]
struct Versioned<'a, T: Serialize> {
    format_version: u32,
    #[serde(flatten)]
    body: &'a T,
}

#[derive(Serialize)]
struct VersionedRows<'a, T: Serialize> {
    format_version: u32,
    rows: &'a T,
}

/// `value` as a versioned document: its fields after `format_version`, or, when it is not an
/// object (a list of rows), `{"format_version": 1, "rows": value}`.
pub fn to_string_pretty<T: Serialize>(value: &T) -> serde_json::Result<String> {
    let format_version = auvnav_version::JSON_FORMAT_VERSION;
    if serde_json::to_value(value)?.is_object() {
        serde_json::to_string_pretty(&Versioned {
            format_version,
            body: value,
        })
    } else {
        serde_json::to_string_pretty(&VersionedRows {
            format_version,
            rows: value,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[derive(Serialize)]
    struct R {
        wall_s: f64,
        name: &'static str,
    }

    #[test]
    fn objects_get_format_version_first_and_keep_their_field_order() {
        let s = to_string_pretty(&R {
            wall_s: 1.5,
            name: "x",
        })
        .expect("json");
        let v: serde_json::Value = serde_json::from_str(&s).expect("parse");
        assert_eq!(v["format_version"], auvnav_version::JSON_FORMAT_VERSION);
        let fv = s.find("format_version").expect("field");
        let w = s.find("wall_s").expect("field");
        let n = s.find("name").expect("field");
        assert!(fv < w && w < n, "{s}");
    }

    #[test]
    fn lists_become_rows() {
        let s = to_string_pretty(&vec![1, 2, 3]).expect("json");
        let v: serde_json::Value = serde_json::from_str(&s).expect("parse");
        assert_eq!(v["rows"], serde_json::json!([1, 2, 3]));
        assert_eq!(v["format_version"], auvnav_version::JSON_FORMAT_VERSION);
    }
}
