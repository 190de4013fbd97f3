//! Measured data sets into auvnav logs, as a library: options in, the messages and a summary out
//! (or a log written atomically); it neither parses arguments nor prints. With the `clap`
//! feature, the option structs are also the `auvnav import` command line's.
//!
//! - [`snapir`]: the Snapir AUV data set (13 segments of 400 s: `imu_NN.csv` 100 Hz specific
//!   force and angular rate, `dvl_NN.csv` 1 Hz body-frame bottom-track velocity, `ref_NN.csv` the
//!   post-processed INS reference at the DVL epochs). The IMU and the DVL become sensor channels,
//!   the reference becomes the truth channel, and the reference depth (`-alt_m`) becomes a depth
//!   channel whose metadata says it is derived from the reference, not an independent sensor.
//!   Times are the files' own (0 at the segment start) in nanoseconds.
//! - [`pd0`]: a PD0 file with GPS, [`riversurveyor`]: a SonTek RiverSurveyor MATLAB export
//!   (bottom track, compass and GPS; read by [`mat5`]), [`mag_csv`]: a magnetometer CSV recording, [`ugps`]: a UGPS
//!   G2 acoustic log, [`tlog`]: a MAVLink telemetry log (an autopilot's IMU, pressure, attitude
//!   and GPS).
//! - [`fixes`]: position fixes from a CSV file; [`mag`]: magnetometer recordings (a log or a CSV
//!   file) as samples for calibration.
#![forbid(unsafe_code)]

/// Returns [`ImportError::Malformed`] with a formatted message.
macro_rules! malformed {
    ($($t:tt)*) => {
        return Err($crate::ImportError::Malformed(format!($($t)*)))
    };
}

/// Returns [`ImportError::Options`] with a formatted message.
macro_rules! bad_option {
    ($($t:tt)*) => {
        return Err($crate::ImportError::Options(format!($($t)*)))
    };
}

use auvnav_log::{LogHeader, LogMessage, LogWriter, write_log_atomically};
use auvnav_shm_schema::{
    AttitudeV1, DepthV1, DvlVelocityV1, GnssFixV1, ImuSampleV1, TruthStateV1, topic,
};
use nalgebra::UnitQuaternion;
use serde::Serialize;
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

/// The result of an import.
pub type Result<T> = std::result::Result<T, ImportError>;

mod error;
pub mod fixes;
pub mod gps_reference;
pub mod mag;
mod mag_csv;
pub mod mat5;
mod pd0;
mod riversurveyor;
mod snapir;
mod tlog;
mod ugps;
use error::ReadContext;
pub use error::{ImportError, Source};
use gps_reference::{
    GpsSample, interpolate_gps, north_east_of, surface_reference, velocity_from_positions,
};
pub use mag_csv::*;
pub use pd0::*;
pub use riversurveyor::*;
pub use snapir::*;
pub use tlog::*;
pub use ugps::*;

/// One parsed CSV file: rows of `N` numbers with an increasing first column.
struct Table<const N: usize> {
    rows: Vec<[f64; N]>,
    counts: FileCounts,
}

/// A reader of a CSV file as the import tools want it: fields trimmed, rows of any length
/// accepted (a row of the wrong length is the caller's to count, not a fatal error).
fn csv_reader(path: &Path) -> Result<csv::Reader<std::fs::File>> {
    csv::ReaderBuilder::new()
        .flexible(true)
        .trim(csv::Trim::All)
        .from_path(path)
        .read_context(|| format!("reading {}", path.display()))
}

/// The next record of `reader`: `Ok(None)` at the end, `Ok(Some(Err(())))` for a row the CSV
/// reader rejects (invalid UTF-8), an error for an I/O failure.
fn next_record(
    reader: &mut csv::Reader<std::fs::File>,
    record: &mut csv::StringRecord,
    path: &Path,
) -> Result<Option<std::result::Result<(), ()>>> {
    match reader.read_record(record) {
        Ok(true) => Ok(Some(Ok(()))),
        Ok(false) => Ok(None),
        Err(e) if matches!(e.kind(), csv::ErrorKind::Io(_)) => {
            Err(e).read_context(|| format!("reading {}", path.display()))
        }
        Err(_) => Ok(Some(Err(()))),
    }
}

fn read_table<const N: usize>(path: &Path, header: &str) -> Result<Table<N>> {
    let mut reader = csv_reader(path)?;
    let found = reader
        .headers()
        .read_context(|| format!("reading the header of {}", path.display()))?
        .iter()
        .collect::<Vec<_>>()
        .join(",");
    if found != header {
        malformed!(
            "{}: header is {found:?}, expected {header:?}",
            path.display()
        );
    }
    let mut t = Table {
        rows: Vec::new(),
        counts: FileCounts::default(),
    };
    let mut record = csv::StringRecord::new();
    while let Some(read) = next_record(&mut reader, &mut record, path)? {
        // A line of blanks only (a trailing line with spaces) is no row.
        if read.is_ok() && record.iter().all(str::is_empty) {
            continue;
        }
        t.counts.rows += 1;
        let mut row = [0.0; N];
        let ok = read.is_ok()
            && record.len() == N
            && record
                .iter()
                .zip(row.iter_mut())
                .all(|(field, v)| match field.parse::<f64>() {
                    Ok(x) if x.is_finite() => {
                        *v = x;
                        true
                    }
                    _ => false,
                });
        if !ok {
            t.counts.malformed += 1;
            continue;
        }
        if t.rows.last().is_some_and(|p| row[0] <= p[0]) || row[0] < 0.0 {
            t.counts.out_of_order += 1;
            continue;
        }
        t.rows.push(row);
    }
    if t.rows.is_empty() {
        malformed!("{}: no usable rows", path.display());
    }
    Ok(t)
}

/// Replaces each row's time with its index at `hz`, the index recovered from the file's own
/// (median) spacing so that skipped rows leave a gap.
fn restamp<const N: usize>(rows: &mut [[f64; N]], hz: f64) {
    let Some(first) = rows.first() else {
        return;
    };
    let t0 = first[0];
    let mut spacing: Vec<f64> = rows.windows(2).map(|w| w[1][0] - w[0][0]).collect();
    spacing.sort_by(f64::total_cmp);
    let step = spacing.get(spacing.len() / 2).copied().unwrap_or(1.0 / hz);
    for r in rows.iter_mut() {
        let index = ((r[0] - t0) / step).round();
        r[0] = index / hz;
    }
}

fn ns_of(seconds: f64) -> u64 {
    (seconds * 1e9).round() as u64
}

fn ns(t: f64) -> u64 {
    (t * 1e9).round() as u64
}

/// The header of an imported log: its producer, the source it was read from, what that source
/// is (`description`, with its time origin) and the import's counts as JSON.
fn import_header(
    producer: &str,
    source: String,
    description: impl Into<String>,
    counts: &impl Serialize,
) -> LogHeader {
    let mut header = LogHeader::new(producer, "");
    header.notes.insert("source".into(), source);
    header
        .notes
        .insert("source.description".into(), description.into());
    header.notes.insert(
        "import.counts".into(),
        serde_json::to_string(counts).unwrap_or_default(),
    );
    header
}

/// The date of a time in ns since 2000-01-01 (the PD0 and RiverSurveyor clocks' origin),
/// `YYYY-MM-DD`.
fn date_since_2000(ns: u64) -> String {
    chrono::NaiveDate::from_ymd_opt(2000, 1, 1)
        .and_then(|d| d.checked_add_signed(chrono::TimeDelta::seconds((ns / 1_000_000_000) as i64)))
        .map(|d| d.format("%Y-%m-%d").to_string())
        .unwrap_or_default()
}

/// The header notes a surface run's compass needs for its declination to be judged: the
/// recording's date and, where the heading is a magnetic compass's, the declination already
/// added to it ([`auvnav_log::RECORDED_DATE`], [`auvnav_log::HEADING_DECLINATION_APPLIED`]).
fn dated_compass_notes(header: &mut LogHeader, date: &str, declination_applied_deg: Option<f64>) {
    if !date.is_empty() {
        header
            .notes
            .insert(auvnav_log::RECORDED_DATE.into(), date.to_string());
    }
    if let Some(d) = declination_applied_deg.filter(|d| d.is_finite()) {
        header.notes.insert(
            auvnav_log::HEADING_DECLINATION_APPLIED.into(),
            format!("{d}"),
        );
    }
}

fn note(pairs: &[(&str, &str)]) -> BTreeMap<String, String> {
    pairs
        .iter()
        .map(|(k, v)| (k.to_string(), v.to_string()))
        .collect()
}

#[cfg(test)]
mod table_tests {
    use super::*;

    fn file(name: &str, text: &str) -> PathBuf {
        let dir = std::env::temp_dir().join(format!("import-table-{}", std::process::id()));
        std::fs::create_dir_all(&dir).expect("directory");
        let p = dir.join(name);
        std::fs::write(&p, text).expect("write");
        p
    }

    #[test]
    fn bad_rows_are_counted_by_kind_and_the_good_ones_kept() {
        let p = file(
            "t.csv",
            "time_s,a,b\r\n0.0,1,2\r\n0.1, 3 ,4\r\n0.2,5\r\n0.3,nan,1\r\n0.4,x,1\r\n   \r\n\
             0.1,9,9\r\n0.5,6,7,8\r\n0.6,6,7\r\n",
        );
        let t = read_table::<3>(&p, "time_s,a,b").expect("table");
        assert_eq!(
            t.rows,
            vec![[0.0, 1.0, 2.0], [0.1, 3.0, 4.0], [0.6, 6.0, 7.0]]
        );
        assert_eq!(t.counts.rows, 8);
        // Too few fields, NaN, text, too many fields.
        assert_eq!(t.counts.malformed, 4);
        assert_eq!(t.counts.out_of_order, 1);
    }

    #[test]
    fn a_wrong_header_or_no_usable_row_is_an_error_naming_the_file() {
        let p = file("h.csv", "time,a,b\n0,1,2\n");
        let e = read_table::<3>(&p, "time_s,a,b").err().expect("error");
        assert!(
            e.to_string().contains("h.csv") && e.to_string().contains("header"),
            "{e}"
        );
        let p = file("empty.csv", "time_s,a,b\nx,y,z\n");
        let e = read_table::<3>(&p, "time_s,a,b").err().expect("error");
        assert!(e.to_string().contains("no usable rows"), "{e}");
        let missing = std::env::temp_dir()
            .join("no-such-dir-import")
            .join("m.csv");
        assert!(read_table::<3>(&missing, "time_s,a,b").is_err());
    }
}
