//! Position fixes from a CSV file (`auvnav smooth --fixes`): surface fixes taken before and after
//! a dive, a ship's USBL track, a survey's control points.
//!
//! One fix per line: `time_s, latitude_deg, longitude_deg, depth_m, std_m` — the time in seconds
//! on the log's clock (the `time_ns` column of `auvnav replay --out x.csv`, divided by 1e9), WGS-84
//! degrees, depth below the surface (m, positive down), one-sigma horizontal and vertical position
//! uncertainty (m). A first line that does not start with a number is a header; `#` starts a
//! comment. A line that does not parse or holds a value out of range is not used: it is counted
//! with its line number, never guessed at.

use crate::Result;
use auvnav_shm_schema::GnssFixV1;
use serde::Serialize;
use std::path::Path;

/// What a fix file held.
#[derive(Debug, Clone, Default, Serialize)]
pub struct FixFile {
    pub path: String,
    pub fixes: Vec<Fix>,
    /// Lines that were neither a fix, a header, a comment nor empty.
    pub unparsable_lines: usize,
    /// The first of those: its line number and why.
    pub first_unparsable: Option<(usize, String)>,
}

/// One position fix.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Fix {
    pub time_s: f64,
    pub latitude_deg: f64,
    pub longitude_deg: f64,
    pub depth_m: f64,
    pub std_m: f64,
}

impl Fix {
    /// The fix as the navigator's GNSS position aid takes it.
    pub fn to_gnss(&self, sequence: u64) -> GnssFixV1 {
        GnssFixV1 {
            host_time_ns: (self.time_s * 1e9).round() as u64,
            sequence,
            latitude_rad: self.latitude_deg.to_radians(),
            longitude_rad: self.longitude_deg.to_radians(),
            height_m: -self.depth_m,
            horizontal_std_m: self.std_m,
            vertical_std_m: self.std_m,
            validity: GnssFixV1::VALID_POSITION | GnssFixV1::VALID_HEIGHT,
            ..Default::default()
        }
    }
}

fn parse_line(line: &str) -> std::result::Result<Fix, String> {
    let fields: Vec<&str> = line.split(',').map(str::trim).collect();
    if fields.len() != 5 {
        return Err(format!("{} fields, expected 5", fields.len()));
    }
    let mut v = [0.0; 5];
    for (i, f) in fields.iter().enumerate() {
        v[i] = f
            .parse::<f64>()
            .map_err(|_| format!("field {} `{f}` is not a number", i + 1))?;
        if !v[i].is_finite() {
            return Err(format!("field {} is not finite", i + 1));
        }
    }
    let [time_s, lat, lon, depth, std] = v;
    if time_s < 0.0 {
        return Err(format!("time {time_s} s is negative"));
    }
    if lat.abs() > 90.0 || lon.abs() > 180.0 {
        return Err(format!("position {lat}, {lon} deg is not on the Earth"));
    }
    if !(-1000.0..=11_000.0).contains(&depth) {
        return Err(format!("depth {depth} m is out of range"));
    }
    if !(std > 0.0 && std <= 1000.0) {
        return Err(format!("standard deviation {std} m is not in (0, 1000]"));
    }
    Ok(Fix {
        time_s,
        latitude_deg: lat,
        longitude_deg: lon,
        depth_m: depth,
        std_m: std,
    })
}

/// Parses the text of a fix file.
pub fn parse(path: &str, text: &str) -> FixFile {
    let mut out = FixFile {
        path: path.to_string(),
        ..Default::default()
    };
    let mut seen_content = false;
    for (i, raw) in text.lines().enumerate() {
        let line = raw.split('#').next().unwrap_or_default().trim();
        if line.is_empty() {
            continue;
        }
        let first = !seen_content;
        seen_content = true;
        let starts_numeric = line
            .chars()
            .next()
            .is_some_and(|c| c.is_ascii_digit() || c == '.' || c == '-' || c == '+');
        if first && !starts_numeric {
            continue; // header
        }
        match parse_line(line) {
            Ok(f) => out.fixes.push(f),
            Err(why) => {
                out.unparsable_lines += 1;
                out.first_unparsable.get_or_insert((i + 1, why));
            }
        }
    }
    out
}

/// Reads and parses a fix file.
pub fn read(path: &Path) -> Result<FixFile> {
    use crate::ReadContext;
    let text = std::fs::read_to_string(path)
        .read_context(|| format!("reading the fix file {}", path.display()))?;
    Ok(parse(&path.display().to_string(), &text))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn header_comments_and_bad_lines_are_told_apart() {
        let text = "time_s,lat,lon,depth,std\n# surface fix before the dive\n\
                    10.0, 31.0, 120.0, 0.0, 3.0\n\
                    11.0, 31.0, 120.0\n\
                    12.0, north, 120.0, 0.0, 3.0\n\
                    13.0, 95.0, 120.0, 0.0, 3.0\n\
                    14.0, 31.0, 120.0, 0.0, 0.0\n\
                    \n\
                    3000.5, 31.05, 120.01, 0.5, 3.0 # after\n";
        let f = parse("x.csv", text);
        assert_eq!(f.fixes.len(), 2);
        assert_eq!(f.unparsable_lines, 4);
        assert_eq!(f.first_unparsable.as_ref().map(|x| x.0), Some(4));
        assert_eq!(f.fixes[1].time_s, 3000.5);
        let g = f.fixes[1].to_gnss(1);
        assert_eq!(g.host_time_ns, 3_000_500_000_000);
        assert_eq!(g.height_m, -0.5);
    }

    #[test]
    fn a_file_of_garbage_gives_no_fix_and_no_panic() {
        let f = parse("x", "\u{0}\u{1}garbage\n,,,,\n-,-,-,-,-\n1e400,0,0,0,1\n");
        assert!(f.fixes.is_empty());
        assert_eq!(f.unparsable_lines, 3);
    }
}
