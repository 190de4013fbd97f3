//! Magnetometer samples from recorded logs (the magnetometer topic, with the IMU's specific force
//! averaged over each magnetometer interval and, in simulated logs, the true attitude) and from
//! CSV files (columns named by options or recognised from the header).

use crate::ReadContext;
use crate::Result;
use auvnav_log::{LogMessage, LogReader};
use auvnav_shm_schema::{DvlVelocityV1, ImuSampleV1, MagnetometerV1};
use nalgebra::Vector3;
use std::path::Path;

/// One magnetometer sample: the reading (µT, sensor axes) and, when recorded, the specific force
/// at the same time (any unit: only its direction is used).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MagSample {
    pub time_s: f64,
    pub field_ut: Vector3<f64>,
    pub specific_force: Option<Vector3<f64>>,
    /// The gyro's mean rate (rad/s, the same axes) since the previous reading, when recorded.
    pub angular_rate: Option<Vector3<f64>>,
    /// The true roll, pitch, yaw (rad) when the recording has a reference attitude (simulated
    /// truth): used only to measure heading errors, never by a fit.
    pub truth_rpy: Option<Vector3<f64>>,
}

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

/// How old a bottom-track velocity may be for the centripetal term of
/// [`VerticalBetweenReadings`] (s).
pub const CENTRIPETAL_DVL_AGE_S: f64 = 2.0;

/// The vertical a magnetometer reading is compared with: the IMU's mean specific force since
/// the previous reading, less the centripetal acceleration of a turn, ω × v (the gyro's mean
/// rate over the same samples and the last bottom-track velocity, in the DVL's frame taken as
/// the body's, when it is at most [`CENTRIPETAL_DVL_AGE_S`] old). A 4°/s turn at 2 m/s leans
/// the specific force by 0.8°, a dip error of 0.7 µT that follows the turns; without a DVL the
/// specific force is taken as it is.
#[derive(Debug, Clone, Default)]
pub struct VerticalBetweenReadings {
    force_sum: Vector3<f64>,
    force_n: usize,
    rate_sum: Vector3<f64>,
    rate_n: usize,
    last_dvl: Option<(f64, Vector3<f64>)>,
    last_rate: Option<Vector3<f64>>,
}

impl VerticalBetweenReadings {
    pub fn add_imu(&mut self, x: &ImuSampleV1) {
        self.add(
            x.specific_force().map(Vector3::from),
            x.angular_rate().map(Vector3::from),
        );
    }

    /// An IMU sample's specific force and angular rate, as read by the caller (non-finite
    /// values are left out).
    pub fn add(&mut self, force: Option<Vector3<f64>>, rate: Option<Vector3<f64>>) {
        if let Some(f) = force.filter(|f| f.iter().all(|v| v.is_finite())) {
            self.force_sum += f;
            self.force_n += 1;
        }
        if let Some(w) = rate.filter(|w| w.iter().all(|v| v.is_finite())) {
            self.rate_sum += w;
            self.rate_n += 1;
        }
    }

    /// A valid bottom-track velocity (water track and invalid readings are left out).
    pub fn add_dvl(&mut self, d: &DvlVelocityV1) {
        if d.validity & DvlVelocityV1::VALID_VELOCITY != 0
            && !d.is_water_track()
            && d.velocity_dvl_m_s.iter().all(|x| x.is_finite())
        {
            self.last_dvl = Some((d.host_time_ns as f64 * 1e-9, d.velocity_dvl_m_s.into()));
        }
    }

    /// The gyro's mean rate over the interval the last [`Self::take`] closed (rad/s).
    pub fn last_rate(&self) -> Option<Vector3<f64>> {
        self.last_rate
    }

    /// The vertical at a reading at `t_s` (None without a specific force since the previous
    /// reading); starts the next interval.
    pub fn take(&mut self, t_s: f64) -> Option<Vector3<f64>> {
        let f = (self.force_n > 0).then(|| self.force_sum / self.force_n as f64);
        let centripetal = match self.last_dvl {
            Some((tv, v)) if self.rate_n > 0 && (t_s - tv).abs() <= CENTRIPETAL_DVL_AGE_S => {
                (self.rate_sum / self.rate_n as f64).cross(&v)
            }
            _ => Vector3::zeros(),
        };
        self.last_rate = (self.rate_n > 0).then(|| self.rate_sum / self.rate_n as f64);
        (self.force_sum, self.force_n) = (Vector3::zeros(), 0);
        (self.rate_sum, self.rate_n) = (Vector3::zeros(), 0);
        f.map(|f| f - centripetal)
    }
}

/// Reads the magnetometer channel of an auvnav log.
pub fn read_log(path: &Path) -> Result<Recording> {
    let mut reader =
        LogReader::open(path).read_context(|| format!("reading {}", path.display()))?;
    reader
        .read_header()
        .read_context(|| format!("{}: reading the log header", path.display()))?;
    let mut out = Recording {
        unit_note: "tesla (the log's unit), shown in µT".into(),
        ..Default::default()
    };
    let mut vertical = VerticalBetweenReadings::default();
    let mut last_force: Option<Vector3<f64>> = None;
    let mut truth: Option<Vector3<f64>> = None;
    let mut imu_seen = false;
    while let Some(raw) = reader
        .next_message()
        .read_context(|| format!("reading {}", path.display()))?
    {
        let Ok(m) = raw.decode_any() else {
            continue;
        };
        match m {
            LogMessage::Imu(x) => {
                imu_seen = true;
                vertical.add_imu(&x);
            }
            LogMessage::Dvl(x) => vertical.add_dvl(&x),
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
                if let Some(f) = vertical.take(x.host_time_ns as f64 * 1e-9) {
                    last_force = Some(f);
                }
                out.samples.push(MagSample {
                    time_s: x.host_time_ns as f64 * 1e-9,
                    field_ut: field,
                    specific_force: last_force,
                    angular_rate: vertical.last_rate(),
                    truth_rpy: truth,
                });
            }
            _ => {}
        }
    }
    if out.samples.is_empty() {
        malformed!(
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
    /// The three gyro columns; default: the first three whose names contain "gyr".
    pub gyro: Option<[String; 3]>,
    /// Gyro unit: "rad/s" or "deg/s"; None: deg/s when the column name says "deg", else rad/s.
    pub gyro_unit: Option<String>,
}

/// The command-line options that choose a CSV file's columns (`auvnav calibrate mag`,
/// `auvnav import mag-csv`).
#[derive(Debug, Clone, Default)]
#[cfg_attr(feature = "clap", derive(clap::Args))]
pub struct CsvColumnOptions {
    /// CSV: the time column (seconds or ISO-8601 UTC); default: the first column named `time…`.
    #[cfg_attr(feature = "clap", arg(long))]
    pub time_column: Option<String>,
    /// CSV: the three magnetometer columns X,Y,Z; default: the first three named `…mag…`.
    #[cfg_attr(feature = "clap", arg(long, value_delimiter = ','))]
    pub mag_columns: Option<Vec<String>>,
    /// CSV: the three accelerometer columns X,Y,Z; default: the first three named `…acc…`.
    #[cfg_attr(feature = "clap", arg(long, value_delimiter = ','))]
    pub accel_columns: Option<Vec<String>>,
    /// CSV: the field unit (T, uT, nT, gauss); default: decided from the readings' magnitude.
    #[cfg_attr(feature = "clap", arg(long, ignore_case = true, value_parser = ["T", "uT", "nT", "gauss"]))]
    pub mag_unit: Option<String>,
    /// CSV: the three gyro columns X,Y,Z; default: the first three named `…gyr…`.
    #[cfg_attr(feature = "clap", arg(long, value_delimiter = ','))]
    pub gyro_columns: Option<Vec<String>>,
    /// CSV: the gyro unit; default: deg/s when the column name says "deg", else rad/s.
    #[cfg_attr(feature = "clap", arg(long, value_parser = ["rad/s", "deg/s"]))]
    pub gyro_unit: Option<String>,
}

impl CsvColumnOptions {
    /// The column choice, refusing a column list that does not name three columns.
    pub fn columns(&self) -> Result<CsvColumns> {
        let three = |v: &Option<Vec<String>>, what: &str| -> Result<Option<[String; 3]>> {
            match v {
                None => Ok(None),
                Some(v) => <[String; 3]>::try_from(v.clone()).map(Some).map_err(|v| {
                    crate::ImportError::Options(format!(
                        "--{what}-columns takes three names X,Y,Z, got {v:?}"
                    ))
                }),
            }
        };
        Ok(CsvColumns {
            time: self.time_column.clone(),
            mag: three(&self.mag_columns, "mag")?,
            accel: three(&self.accel_columns, "accel")?,
            mag_unit: self.mag_unit.clone(),
            gyro: three(&self.gyro_columns, "gyro")?,
            gyro_unit: match self.gyro_unit.as_deref() {
                None | Some("rad/s" | "deg/s") => self.gyro_unit.clone(),
                Some(u) => bad_option!("--gyro-unit {u:?}: give rad/s or deg/s"),
            },
        })
    }
}

/// Seconds since the Unix epoch of an ISO-8601 time: RFC 3339 with any offset, or a UTC time
/// "YYYY-MM-DD[T ]HH:MM[:SS[.fff]][Z]"; `None` for an impossible date or time (chrono's calendar).
fn iso_seconds(s: &str) -> Option<f64> {
    let s = s.trim();
    let utc = match chrono::DateTime::parse_from_rfc3339(s) {
        Ok(t) => t.to_utc(),
        Err(_) => {
            let bare = s.trim_end_matches('Z');
            [
                "%Y-%m-%dT%H:%M:%S%.f",
                "%Y-%m-%d %H:%M:%S%.f",
                "%Y-%m-%dT%H:%M",
                "%Y-%m-%d %H:%M",
            ]
            .iter()
            .find_map(|f| chrono::NaiveDateTime::parse_from_str(bare, f).ok())?
            .and_utc()
        }
    };
    Some(utc.timestamp() as f64 + f64::from(utc.timestamp_subsec_nanos()) * 1e-9)
}

/// The decimal year of a time in seconds since the Unix epoch (UTC, leap seconds ignored).
fn decimal_year_from_unix(seconds: f64) -> Option<f64> {
    use chrono::Datelike;
    if !seconds.is_finite() {
        return None;
    }
    let whole = seconds.floor();
    let day_start = (whole / 86_400.0).floor() * 86_400.0;
    let date = chrono::DateTime::from_timestamp(day_start as i64, 0)?.date_naive();
    auvnav_core::wmm::decimal_year(date.year(), date.month(), date.day(), seconds - day_start)
}

/// Reads magnetometer (and accelerometer) columns of a CSV file. Lines starting with `#` are
/// comments; the first other line names the columns.
// Long on purpose: a parser over one file's state: header, column lookup, units and rows, each
// error counted.
pub fn read_csv(path: &Path, cols: &CsvColumns) -> Result<Recording> {
    // The `csv` crate: quoted fields, CRLF line ends; `#` lines are comments, rows may have
    // fewer or more fields than the header (counted as skipped when a needed one is missing).
    let mut reader = csv::ReaderBuilder::new()
        .has_headers(false)
        .comment(Some(b'#'))
        .flexible(true)
        .trim(csv::Trim::All)
        .from_path(path)
        .read_context(|| format!("opening {}", path.display()))?;
    let mut lines = reader.records().filter_map(|r| match r {
        // Line index from 0, as the time of a row when there is no time column.
        Ok(rec) if !(rec.len() == 1 && rec[0].is_empty()) => {
            let line = rec
                .position()
                .map_or(0, |p| p.line().saturating_sub(1) as usize);
            Some((line, Some(rec)))
        }
        Ok(_) => None,
        // A row that is not UTF-8 is skipped and counted.
        Err(e) => Some((e.position().map_or(0, |p| p.line() as usize), None)),
    });
    let header = loop {
        match lines.next() {
            Some((_, Some(h))) => break h,
            Some((_, None)) => continue,
            None => malformed!("{}: no header line", path.display()),
        }
    };
    let names: Vec<String> = header.iter().map(str::to_string).collect();
    let find = |want: &str| -> Result<usize> {
        names.iter().position(|n| n == want).ok_or_else(|| {
            crate::ImportError::Options(format!(
                "{}: no column {want:?}; the columns are {}",
                path.display(),
                names.join(", ")
            ))
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
        None => guess3("mag").ok_or_else(|| {
            crate::ImportError::Malformed(format!(
                "{}: no three magnetometer columns (names containing \"mag\"); name them with \
                 --mag-columns X,Y,Z. The columns are {}",
                path.display(),
                names.join(", ")
            ))
        })?,
    };
    let accel = match &cols.accel {
        Some([a, b, c]) => Some([find(a)?, find(b)?, find(c)?]),
        None => guess3("acc"),
    };
    let gyro = match &cols.gyro {
        Some([a, b, c]) => Some([find(a)?, find(b)?, find(c)?]),
        None => guess3("gyr"),
    };
    let in_degrees = match cols.gyro_unit.as_deref() {
        Some(u) => u == "deg/s",
        None => gyro.is_some_and(|g| names[g[0]].to_lowercase().contains("deg")),
    };
    let gyro_scale = if in_degrees { 1f64.to_radians() } else { 1.0 };
    let time = match &cols.time {
        Some(t) => Some(find(t)?),
        None => names
            .iter()
            .position(|n| n.to_lowercase().starts_with("time")),
    };
    let mut out = Recording::default();
    let mut raw = Vec::new();
    for (i, record) in lines {
        let Some(f) = record else {
            out.skipped += 1;
            continue;
        };
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
        let w = gyro.and_then(|g| {
            let v = Vector3::new(num(g[0])?, num(g[1])?, num(g[2])?) * gyro_scale;
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
        raw.push((t, h, a, w));
    }
    if raw.is_empty() {
        malformed!(
            "{}: no row with three numeric magnetometer values ({} skipped)",
            path.display(),
            out.skipped
        );
    }
    let mut norms: Vec<f64> = raw.iter().map(|(_, h, _, _)| h.norm()).collect();
    norms.sort_by(f64::total_cmp);
    let median = norms[norms.len() / 2];
    let (scale, note) = match cols.mag_unit.as_deref().map(str::to_lowercase).as_deref() {
        Some("t") => (1e6, "T (given)".to_string()),
        Some("ut") | Some("µt") => (1.0, "µT (given)".to_string()),
        Some("nt") => (1e-3, "nT (given)".to_string()),
        Some("gauss") | Some("g") => (100.0, "gauss (given)".to_string()),
        Some(other) => bad_option!("unknown field unit {other:?}: give T, uT, nT or gauss"),
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
    // A row's gyro is the rate at its time; a sample's angular rate is the mean since the
    // previous reading (as a log's is): the trapezoid of the two rows.
    let mut previous_rate = None;
    out.samples = raw
        .into_iter()
        .map(|(t, h, a, w)| {
            let mean = match (previous_rate, w) {
                (Some(p), Some(w)) => Some((p + w) / 2.0),
                _ => w,
            };
            previous_rate = w;
            MagSample {
                time_s: t,
                field_ut: h * scale,
                specific_force: a,
                angular_rate: mean,
                truth_rpy: None,
            }
        })
        .collect();
    Ok(out)
}

#[cfg(test)]
mod tests {

    #[test]
    fn a_turns_centripetal_acceleration_comes_off_the_vertical() {
        // A steady 4°/s turn at 2 m/s: the specific force leans by ω × v (0.14 m/s² to
        // starboard); with the bottom-track velocity the vertical is straight down again.
        let (w, v) = (Vector3::new(0.0, 0.0, 0.07), Vector3::new(2.0, 0.0, 0.0));
        let f = w.cross(&v) - Vector3::new(0.0, 0.0, 9.8);
        let imu = |k: u64| ImuSampleV1 {
            host_time_ns: k * 10_000_000,
            angular: w.into(),
            specific: f.into(),
            interval_s: 0.01,
            status: ImuSampleV1::STATUS_GYRO_VALID | ImuSampleV1::STATUS_ACCEL_VALID,
            ..Default::default()
        };
        let dvl = |t_s: f64, validity: u32| DvlVelocityV1 {
            host_time_ns: (t_s * 1e9) as u64,
            velocity_dvl_m_s: v.into(),
            validity,
            ..Default::default()
        };
        let run = |dvl_at: Option<(f64, u32)>| {
            let mut vert = VerticalBetweenReadings::default();
            if let Some((t, flags)) = dvl_at {
                vert.add_dvl(&dvl(t, flags));
            }
            for k in 0..100 {
                vert.add_imu(&imu(k));
            }
            let at = vert.take(1.0).expect("specific force");
            assert!(
                vert.take(1.1).is_none(),
                "a reading without samples since has none"
            );
            at
        };
        let down = run(Some((0.5, DvlVelocityV1::VALID_VELOCITY)));
        assert!(
            (down - Vector3::new(0.0, 0.0, -9.8)).norm() < 1e-12,
            "{down}"
        );
        // Without a DVL, with a stale one or with water track: the specific force as it is.
        for dvl_at in [
            None,
            Some((3.5, DvlVelocityV1::VALID_VELOCITY)),
            Some((
                0.5,
                DvlVelocityV1::VALID_VELOCITY | DvlVelocityV1::TRACK_WATER,
            )),
        ] {
            let as_is = run(dvl_at);
            assert!((as_is - f).norm() < 1e-12, "{dvl_at:?}: {as_is}");
        }
    }

    use super::*;

    #[test]
    fn csv_with_quotes_crlf_comments_and_bad_rows() {
        let dir = std::env::temp_dir().join(format!("auvnav-magcsv-{}", std::process::id()));
        std::fs::create_dir_all(&dir).expect("dir");
        let p = dir.join("m.csv");
        let mut bytes =
            b"# exported by a logger\r\n\"time s\",\"mag x, uT\",mag_y,mag_z\r\n".to_vec();
        bytes.extend_from_slice(b"0.0,20.5,1.0,-40.0\r\n\r\n0.1,\"21.0\",1.5,-39.5\r\n");
        bytes.extend_from_slice(b"0.2,abc,1.5,-39.5\r\n0.3,\xff,1,2\r\n0.4,22.0,2.0\r\n");
        std::fs::write(&p, &bytes).expect("write");
        let cols = CsvColumns {
            time: None,
            mag: None,
            accel: None,
            mag_unit: None,
            gyro: None,
            gyro_unit: None,
        };
        let r = read_csv(&p, &cols).expect("read");
        assert_eq!(r.samples.len(), 2, "two good rows");
        assert_eq!(r.skipped, 3, "not a number, not UTF-8, a missing field");
        std::fs::remove_dir_all(&dir).expect("cleanup");
    }

    #[test]
    fn iso_times() {
        assert_eq!(iso_seconds("1970-01-01T00:00:00"), Some(0.0));
        assert_eq!(iso_seconds("2012-06-12T12:00:02.5"), Some(1_339_502_402.5));
        assert_eq!(iso_seconds("2012-13-12T12:00:00"), None);
        assert_eq!(iso_seconds("yesterday"), None);
        assert_eq!(iso_seconds("2023-02-31T00:00:00"), None, "31 February");
        assert_eq!(iso_seconds("2023-02-28T24:00:00"), None, "hour 24");
        assert_eq!(iso_seconds("2024-02-29T00:00:00Z"), Some(1_709_164_800.0));
        assert_eq!(
            iso_seconds("2024-02-29T02:00:00+02:00"),
            Some(1_709_164_800.0)
        );
        assert_eq!(iso_seconds("2024-02-29 00:00"), Some(1_709_164_800.0));
        let y = decimal_year_from_unix(1_339_502_400.0).expect("date");
        let want = auvnav_core::wmm::decimal_year(2012, 6, 12, 43_200.0).expect("date");
        assert!((y - want).abs() < 1e-12);
        assert_eq!(decimal_year_from_unix(0.0), Some(1970.0));
    }
}
