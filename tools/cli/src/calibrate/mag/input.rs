//! Magnetometer samples from recorded logs (the magnetometer topic, with the IMU's specific force
//! averaged over each magnetometer interval and, in simulated logs, the true attitude) and from
//! CSV files (columns named by options or recognised from the header).

use super::fit::MagSample;
use anyhow::{Context, bail};
use auvnav_drivers::convert;
use auvnav_log::{LogMessage, LogReader};
use auvnav_shm_schema::{ImuSampleV1, MagnetometerV1};
use nalgebra::Vector3;
use std::path::Path;

/// Where a recording was made, when it says so (first GNSS fix or truth record).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Whereabouts {
    pub latitude_deg: Option<f64>,
    pub longitude_deg: Option<f64>,
    /// Decimal year of the first sample, when the time column is a calendar time.
    pub date: Option<f64>,
}

/// What was read, with counts of what was skipped.
#[derive(Debug, Clone, Default)]
pub struct Recording {
    pub samples: Vec<MagSample>,
    pub whereabouts: Whereabouts,
    /// Magnetometer messages or rows skipped (flagged invalid, not finite, unparsable).
    pub skipped: usize,
    /// How the field unit was decided.
    pub unit_note: String,
}

/// Reads the magnetometer channel of an auvnav log.
pub fn read_log(path: &Path) -> anyhow::Result<Recording> {
    let mut reader = LogReader::open(path)?;
    reader
        .read_header()
        .with_context(|| format!("{}: reading the log header", path.display()))?;
    let mut out = Recording {
        unit_note: "tesla (the log's unit), shown in µT".into(),
        ..Default::default()
    };
    let mut force_sum = Vector3::zeros();
    let mut force_n = 0usize;
    let mut last_force: Option<Vector3<f64>> = None;
    let mut truth: Option<Vector3<f64>> = None;
    let mut imu_seen = false;
    while let Some(raw) = reader
        .next_message()
        .with_context(|| format!("reading {}", path.display()))?
    {
        let Ok(m) = raw.decode_any() else {
            continue;
        };
        match m {
            LogMessage::Imu(x) => {
                imu_seen = true;
                if let Some(f) = specific_force(&x) {
                    force_sum += f;
                    force_n += 1;
                }
            }
            LogMessage::Truth(x) => {
                truth = Some(Vector3::from(x.euler_rad));
                if out.whereabouts.latitude_deg.is_none() {
                    out.whereabouts.latitude_deg = Some(x.latitude_rad.to_degrees());
                    out.whereabouts.longitude_deg = Some(x.longitude_rad.to_degrees());
                }
            }
            LogMessage::Gnss(x)
                if out.whereabouts.latitude_deg.is_none() && x.latitude_rad.is_finite() =>
            {
                out.whereabouts.latitude_deg = Some(x.latitude_rad.to_degrees());
                out.whereabouts.longitude_deg = Some(x.longitude_rad.to_degrees());
            }
            LogMessage::Magnetometer(x) => {
                let Some(field) = field_ut(&x) else {
                    out.skipped += 1;
                    continue;
                };
                if force_n > 0 {
                    last_force = Some(force_sum / force_n as f64);
                }
                force_sum = Vector3::zeros();
                force_n = 0;
                out.samples.push(MagSample {
                    time_s: x.host_time_ns as f64 * 1e-9,
                    field_ut: field,
                    specific_force: last_force,
                    truth_rpy: truth,
                });
            }
            _ => {}
        }
    }
    if out.samples.is_empty() {
        bail!(
            "{}: no valid magnetometer messages (topic `magnetometer`){}",
            path.display(),
            if out.skipped > 0 {
                format!("; {} flagged invalid or not finite", out.skipped)
            } else {
                String::new()
            }
        );
    }
    if !imu_seen {
        // Calibration still works (magnitude constraint only); the report says so.
        for s in &mut out.samples {
            s.specific_force = None;
        }
    }
    Ok(out)
}

/// The specific force of an IMU sample (rates or increments), None when not valid.
pub fn specific_force(x: &ImuSampleV1) -> Option<Vector3<f64>> {
    if x.status & ImuSampleV1::STATUS_ACCEL_VALID == 0
        || x.interval_s.is_nan()
        || x.interval_s <= 0.0
    {
        return None;
    }
    let f = Vector3::from(x.specific);
    let f = if x.status & ImuSampleV1::STATUS_INCREMENTS != 0 {
        f / x.interval_s
    } else {
        f
    };
    f.iter().all(|v| v.is_finite()).then_some(f)
}

fn field_ut(x: &MagnetometerV1) -> Option<Vector3<f64>> {
    if x.validity & MagnetometerV1::VALID_FIELD == 0 {
        return None;
    }
    let b = Vector3::from(x.field_t) * 1e6;
    (b.iter().all(|v| v.is_finite()) && b.norm() < 1e4).then_some(b)
}

/// Column choice for a CSV file.
#[derive(Debug, Clone, Default)]
pub struct CsvColumns {
    /// Time column (seconds, or an ISO-8601 UTC time); default: the first column whose name
    /// starts with "time".
    pub time: Option<String>,
    /// The three magnetometer columns; default: the first three whose names contain "mag".
    pub mag: Option<[String; 3]>,
    /// The three accelerometer columns; default: the first three whose names contain "acc".
    pub accel: Option<[String; 3]>,
    /// Field unit: "T", "uT", "nT", "gauss", or None to decide from the magnitude.
    pub mag_unit: Option<String>,
}

/// The command-line options that choose a CSV file's columns (`auvnav calibrate mag`,
/// `auvnav import mag-csv`).
#[derive(clap::Args, Debug, Clone, Default)]
pub struct CsvColumnArgs {
    /// CSV: the time column (seconds or ISO-8601 UTC); default: the first column named `time…`.
    #[arg(long)]
    pub time_column: Option<String>,
    /// CSV: the three magnetometer columns X,Y,Z; default: the first three named `…mag…`.
    #[arg(long, value_delimiter = ',')]
    pub mag_columns: Option<Vec<String>>,
    /// CSV: the three accelerometer columns X,Y,Z; default: the first three named `…acc…`.
    #[arg(long, value_delimiter = ',')]
    pub accel_columns: Option<Vec<String>>,
    /// CSV: the field unit (T, uT, nT, gauss); default: decided from the readings' magnitude.
    #[arg(long, ignore_case = true, value_parser = ["T", "uT", "nT", "gauss"])]
    pub mag_unit: Option<String>,
}

impl CsvColumnArgs {
    /// The column choice, refusing a column list that does not name three columns.
    pub fn columns(&self) -> anyhow::Result<CsvColumns> {
        let three = |v: &Option<Vec<String>>, what: &str| -> anyhow::Result<Option<[String; 3]>> {
            match v {
                None => Ok(None),
                Some(v) => <[String; 3]>::try_from(v.clone()).map(Some).map_err(|v| {
                    anyhow::anyhow!("--{what}-columns takes three names X,Y,Z, got {v:?}")
                }),
            }
        };
        Ok(CsvColumns {
            time: self.time_column.clone(),
            mag: three(&self.mag_columns, "mag")?,
            accel: three(&self.accel_columns, "accel")?,
            mag_unit: self.mag_unit.clone(),
        })
    }
}

/// Seconds since the Unix epoch of an ISO-8601 UTC time "YYYY-MM-DDTHH:MM:SS[.fff][Z]".
fn iso_seconds(s: &str) -> Option<f64> {
    let s = s.trim().trim_end_matches('Z');
    let (date, time) = s.split_once(['T', ' '])?;
    let mut d = date.split('-');
    let y: i64 = d.next()?.parse().ok()?;
    let mo: u32 = d.next()?.parse().ok()?;
    let da: u32 = d.next()?.parse().ok()?;
    let mut t = time.split(':');
    let (h, mi): (f64, f64) = (t.next()?.parse().ok()?, t.next()?.parse().ok()?);
    let sec: f64 = t.next().unwrap_or("0").parse().ok()?;
    if !(1..=12).contains(&mo) || !(1..=31).contains(&da) {
        return None;
    }
    let days = convert::days_from_civil(y, mo, da);
    Some(days as f64 * 86_400.0 + h * 3600.0 + mi * 60.0 + sec)
}

/// The decimal year of a time in seconds since the Unix epoch (UTC, leap seconds ignored).
fn decimal_year_from_unix(seconds: f64) -> Option<f64> {
    if !seconds.is_finite() {
        return None;
    }
    let days = (seconds / 86_400.0).floor();
    let (y, m, d) = convert::civil_from_days(days as i64);
    auvnav_core::wmm::decimal_year(i32::try_from(y).ok()?, m, d, seconds - days * 86_400.0)
}

/// Reads magnetometer (and accelerometer) columns of a CSV file. Lines starting with `#` are
/// comments; the first other line names the columns.
pub fn read_csv(path: &Path, cols: &CsvColumns) -> anyhow::Result<Recording> {
    let text =
        std::fs::read_to_string(path).with_context(|| format!("reading {}", path.display()))?;
    let mut lines = text
        .lines()
        .enumerate()
        .filter(|(_, l)| !l.trim_start().starts_with('#') && !l.trim().is_empty());
    let Some((_, header)) = lines.next() else {
        bail!("{}: no header line", path.display());
    };
    let names: Vec<String> = header.split(',').map(|s| s.trim().to_string()).collect();
    let find = |want: &str| -> anyhow::Result<usize> {
        names.iter().position(|n| n == want).with_context(|| {
            format!(
                "{}: no column {want:?}; the columns are {}",
                path.display(),
                names.join(", ")
            )
        })
    };
    let guess3 = |key: &str| -> Option<[usize; 3]> {
        let idx: Vec<usize> = names
            .iter()
            .enumerate()
            .filter(|(_, n)| n.to_lowercase().contains(key))
            .map(|(i, _)| i)
            .take(3)
            .collect();
        (idx.len() == 3).then(|| [idx[0], idx[1], idx[2]])
    };
    let mag = match &cols.mag {
        Some([a, b, c]) => [find(a)?, find(b)?, find(c)?],
        None => guess3("mag").with_context(|| {
            format!(
                "{}: no three magnetometer columns (names containing \"mag\"); name them with \
                 --mag-columns X,Y,Z. The columns are {}",
                path.display(),
                names.join(", ")
            )
        })?,
    };
    let accel = match &cols.accel {
        Some([a, b, c]) => Some([find(a)?, find(b)?, find(c)?]),
        None => guess3("acc"),
    };
    let time = match &cols.time {
        Some(t) => Some(find(t)?),
        None => names
            .iter()
            .position(|n| n.to_lowercase().starts_with("time")),
    };
    let mut out = Recording::default();
    let mut raw = Vec::new();
    for (i, line) in lines {
        let f: Vec<&str> = line.split(',').map(str::trim).collect();
        let num = |k: usize| f.get(k).and_then(|v| v.parse::<f64>().ok());
        let m = [num(mag[0]), num(mag[1]), num(mag[2])];
        let (Some(x), Some(y), Some(z)) = (m[0], m[1], m[2]) else {
            out.skipped += 1;
            continue;
        };
        let h = Vector3::new(x, y, z);
        if !h.iter().all(|v| v.is_finite()) {
            out.skipped += 1;
            continue;
        }
        let a = accel.and_then(|a| {
            let v = Vector3::new(num(a[0])?, num(a[1])?, num(a[2])?);
            v.iter().all(|x| x.is_finite()).then_some(v)
        });
        let t = match time.and_then(|k| f.get(k)) {
            Some(s) => match s.parse::<f64>() {
                Ok(v) => v,
                Err(_) => match iso_seconds(s) {
                    Some(v) => {
                        if out.whereabouts.date.is_none() {
                            out.whereabouts.date = decimal_year_from_unix(v);
                        }
                        v
                    }
                    None => {
                        out.skipped += 1;
                        continue;
                    }
                },
            },
            None => i as f64,
        };
        raw.push((t, h, a));
    }
    if raw.is_empty() {
        bail!(
            "{}: no row with three numeric magnetometer values ({} skipped)",
            path.display(),
            out.skipped
        );
    }
    let mut norms: Vec<f64> = raw.iter().map(|(_, h, _)| h.norm()).collect();
    norms.sort_by(f64::total_cmp);
    let median = norms[norms.len() / 2];
    let (scale, note) = match cols.mag_unit.as_deref().map(str::to_lowercase).as_deref() {
        Some("t") => (1e6, "T (given)".to_string()),
        Some("ut") | Some("µt") => (1.0, "µT (given)".to_string()),
        Some("nt") => (1e-3, "nT (given)".to_string()),
        Some("gauss") | Some("g") => (100.0, "gauss (given)".to_string()),
        Some(other) => bail!("unknown field unit {other:?}: give T, uT, nT or gauss"),
        None => {
            // The Earth's field is 22–67 µT: the unit is the one that puts the readings there.
            let (s, u) = if median < 1e-3 {
                (1e6, "T")
            } else if median < 3.0 {
                (100.0, "gauss")
            } else if median < 1000.0 {
                (1.0, "µT")
            } else {
                (1e-3, "nT")
            };
            (
                s,
                format!("{u} (decided from the median reading {median:.4}; give --mag-unit)"),
            )
        }
    };
    out.unit_note = note;
    out.samples = raw
        .into_iter()
        .map(|(t, h, a)| MagSample {
            time_s: t,
            field_ut: h * scale,
            specific_force: a,
            truth_rpy: None,
        })
        .collect();
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn iso_times() {
        assert_eq!(iso_seconds("1970-01-01T00:00:00"), Some(0.0));
        assert_eq!(iso_seconds("2012-06-12T12:00:02.5"), Some(1_339_502_402.5));
        assert_eq!(iso_seconds("2012-13-12T12:00:00"), None);
        assert_eq!(iso_seconds("yesterday"), None);
        let y = decimal_year_from_unix(1_339_502_400.0).expect("date");
        let want = auvnav_core::wmm::decimal_year(2012, 6, 12, 43_200.0).expect("date");
        assert!((y - want).abs() < 1e-12);
        assert_eq!(decimal_year_from_unix(0.0), Some(1970.0));
    }
}
