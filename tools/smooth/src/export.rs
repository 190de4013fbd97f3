//! Exports of a smoothed track for the people downstream: GeoJSON (QGIS, ArcGIS, web maps), KML
//! (Google Earth) and a plain CSV with UTC time, latitude, longitude, depth and heading — the
//! column layout the generic ASCII navigation importers of sonar processing packages (SonarWiz,
//! Qimera, CARIS HIPS) and QGIS's delimited-text layer read with a column mapping.
//!
//! Points are taken at most at `rate_hz` (a track at IMU rate is far denser than any of them
//! needs); the last point is always kept.

use auvnav_shm_schema::NavSolutionV1;
use std::fmt::Write as _;

/// One exported point.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TrackPoint {
    pub time_s: f64,
    pub latitude_deg: f64,
    pub longitude_deg: f64,
    pub depth_m: f64,
    pub heading_deg: f64,
    /// Horizontal one-sigma (m): the larger of north and east.
    pub horizontal_std_m: f64,
}

impl TrackPoint {
    pub fn of(s: &NavSolutionV1) -> TrackPoint {
        TrackPoint {
            time_s: s.host_time_ns as f64 * 1e-9,
            latitude_deg: s.latitude_rad.to_degrees(),
            longitude_deg: s.longitude_rad.to_degrees(),
            depth_m: -s.height_m,
            heading_deg: s.euler_rad[2].to_degrees().rem_euclid(360.0),
            horizontal_std_m: s.position_std_ned_m[0].max(s.position_std_ned_m[1]),
        }
    }
}

/// Keeps points at most at `rate_hz`.
#[derive(Debug, Clone, Default)]
pub struct Decimator {
    period_s: f64,
    last_kept_s: Option<f64>,
    pub points: Vec<TrackPoint>,
    pending_last: Option<TrackPoint>,
}

impl Decimator {
    pub fn new(rate_hz: f64) -> Decimator {
        Decimator {
            period_s: if rate_hz > 0.0 { 1.0 / rate_hz } else { 0.0 },
            ..Default::default()
        }
    }

    pub fn push(&mut self, p: TrackPoint) {
        if self
            .last_kept_s
            .is_none_or(|t| p.time_s - t >= self.period_s - 1e-9)
        {
            self.points.push(p);
            self.last_kept_s = Some(p.time_s);
            self.pending_last = None;
        } else {
            self.pending_last = Some(p);
        }
    }

    pub fn finish(mut self) -> Vec<TrackPoint> {
        if let Some(p) = self.pending_last.take() {
            self.points.push(p);
        }
        self.points
    }
}

/// An ISO 8601 UTC time from Unix seconds (millisecond resolution).
pub fn iso_utc(unix_s: f64) -> String {
    let ms = (unix_s * 1e3).round() as i64;
    match chrono::DateTime::from_timestamp_millis(ms) {
        Some(t) => t.format("%Y-%m-%dT%H:%M:%S%.3fZ").to_string(),
        None => String::new(),
    }
}

/// The GeoJSON feature collection: the track as a LineString (longitude, latitude, height =
/// −depth) with its name and time span, following RFC 7946.
pub fn geojson(name: &str, points: &[TrackPoint], unix_offset_s: Option<f64>) -> String {
    let coords: Vec<serde_json::Value> = points
        .iter()
        .map(|p| serde_json::json!([p.longitude_deg, p.latitude_deg, -p.depth_m]))
        .collect();
    let span = |p: Option<&TrackPoint>| {
        p.map(|p| match unix_offset_s {
            Some(o) => serde_json::Value::String(iso_utc(p.time_s + o)),
            None => serde_json::json!(p.time_s),
        })
    };
    let v = serde_json::json!({
        "type": "FeatureCollection",
        "features": [{
            "type": "Feature",
            "properties": {
                "name": name,
                "start": span(points.first()),
                "end": span(points.last()),
                "points": points.len(),
            },
            "geometry": { "type": "LineString", "coordinates": coords },
        }],
    });
    serde_json::to_string_pretty(&v).unwrap_or_default()
}

fn xml_escape(s: &str) -> String {
    s.replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
        .replace('"', "&quot;")
}

/// The KML document: the track as a LineString at its depth (absolute altitude = −depth).
pub fn kml(name: &str, points: &[TrackPoint]) -> String {
    let mut s = String::new();
    let name = xml_escape(name);
    let _ = writeln!(
        s,
        "<?xml version=\"1.0\" encoding=\"UTF-8\"?>\n<kml xmlns=\"http://www.opengis.net/kml/2.2\">\n<Document>\n<name>{name}</name>\n<Placemark>\n<name>{name}</name>\n<LineString>\n<altitudeMode>absolute</altitudeMode>\n<coordinates>"
    );
    for p in points {
        let _ = writeln!(
            s,
            "{:.8},{:.8},{:.2}",
            p.longitude_deg, p.latitude_deg, -p.depth_m
        );
    }
    s.push_str("</coordinates>\n</LineString>\n</Placemark>\n</Document>\n</kml>\n");
    s
}

pub const PLAIN_CSV_HEADER: &str =
    "utc,time_s,latitude_deg,longitude_deg,depth_m,heading_deg,horizontal_std_m";

/// The plain CSV: UTC (empty when the log has no UTC anchor), log time, position, depth,
/// heading and the horizontal one-sigma.
pub fn plain_csv(points: &[TrackPoint], unix_offset_s: Option<f64>) -> String {
    let mut s = String::new();
    let _ = writeln!(s, "{PLAIN_CSV_HEADER}");
    for p in points {
        let utc = unix_offset_s
            .map(|o| iso_utc(p.time_s + o))
            .unwrap_or_default();
        let _ = writeln!(
            s,
            "{utc},{:.3},{:.8},{:.8},{:.3},{:.3},{:.3}",
            p.time_s, p.latitude_deg, p.longitude_deg, p.depth_m, p.heading_deg, p.horizontal_std_m
        );
    }
    s
}

#[cfg(test)]
mod tests {
    use super::*;

    fn point(t: f64) -> TrackPoint {
        TrackPoint {
            time_s: t,
            latitude_deg: 31.0 + t * 1e-5,
            longitude_deg: 120.0,
            depth_m: 30.0,
            heading_deg: 45.0,
            horizontal_std_m: 1.5,
        }
    }

    #[test]
    fn decimation_keeps_the_rate_and_the_last_point() {
        let mut d = Decimator::new(1.0);
        for i in 0..=250 {
            d.push(point(i as f64 * 0.01));
        }
        let p = d.finish();
        assert_eq!(p.len(), 4);
        assert_eq!(p.last().map(|x| x.time_s), Some(2.5));
    }

    #[test]
    fn exports_parse_as_what_they_claim() {
        let pts: Vec<_> = (0..5).map(|i| point(i as f64)).collect();
        let g: serde_json::Value =
            serde_json::from_str(&geojson("a & b", &pts, Some(1.7e9))).expect("GeoJSON is JSON");
        assert_eq!(g["features"][0]["geometry"]["coordinates"][4][2], -30.0);
        assert_eq!(
            g["features"][0]["properties"]["start"],
            "2023-11-14T22:13:20.000Z"
        );
        let k = kml("a & b", &pts);
        assert!(
            k.contains("<name>a &amp; b</name>") && k.contains("120.00000000,31.00004000,-30.00")
        );
        let c = plain_csv(&pts, None);
        assert_eq!(c.lines().count(), 6);
        assert!(
            c.lines()
                .nth(1)
                .is_some_and(|l| l.starts_with(",0.000,31."))
        );
    }
}
