//! A log as tables: one per channel, one row per message, one column per scalar value, with the
//! unit in every column name (`velocity_north_m_s`, `roll_rad`, `host_time_ns`). The Python
//! package's `read_log` and any export build on it.
//!
//! Column names come from the schema's field names, which end in their unit (`_m_s`, `_rad`,
//! `_ns`, ...): an array field becomes one column per component, the component named between the
//! quantity and the unit (north/east/down for `_ned` fields, roll/pitch/yaw for Euler angles,
//! w/x/y/z for quaternions, x/y/z for other 3-vectors, 0.. otherwise). Byte arrays become text
//! (a process name) and are left out when they are raw frames. Every table starts with `time_s`,
//! the message's host time in seconds.

use crate::{LogError, LogReader, RawLogMessage};
use auvnav_shm_schema::{FieldValues, Message};
use std::collections::BTreeMap;
use std::path::Path;

/// One column's values.
#[derive(Debug, Clone, PartialEq)]
pub enum ColumnValues {
    F64(Vec<f64>),
    U64(Vec<u64>),
    Text(Vec<String>),
}

impl ColumnValues {
    pub fn len(&self) -> usize {
        match self {
            ColumnValues::F64(v) => v.len(),
            ColumnValues::U64(v) => v.len(),
            ColumnValues::Text(v) => v.len(),
        }
    }

    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }
}

/// A named column.
#[derive(Debug, Clone, PartialEq)]
pub struct Column {
    pub name: String,
    pub values: ColumnValues,
}

/// One channel's messages as columns of equal length.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Table {
    /// The channel's schema (`auvnav_msgs/msg/ImuSampleV1`).
    pub schema: String,
    pub columns: Vec<Column>,
    pub rows: usize,
}

/// Every channel of a log as a table, by topic, and what the reader passed over.
#[derive(Debug, Clone, Default)]
pub struct Tables {
    pub tables: BTreeMap<String, Table>,
    /// Messages on channels of a schema this program does not know (not tabled).
    pub unknown_messages: u64,
    /// Messages whose bytes did not match their schema (not tabled).
    pub bad_messages: u64,
    /// Why the log ended early, when it did (a truncated or damaged tail).
    pub log_error: Option<String>,
}

/// Units the schema's field names end in, longest first (so `_m_s2` wins over `_m_s` and `_s`).
const UNITS: [&str; 16] = [
    "_kg_m3", "_m_s2", "_rad_s", "_m_s", "_psu", "_rad", "_deg", "_ns", "_pa", "_db", "_hz", "_m",
    "_s", "_c", "_t", "_v",
];

/// `(quantity, unit)`: `velocity_ned_m_s` → (`velocity_ned`, `_m_s`); no unit → (`name`, ``).
fn split_unit(field: &str) -> (&str, &str) {
    for u in UNITS {
        if let Some(q) = field.strip_suffix(u)
            && !q.is_empty()
        {
            return (q, u);
        }
    }
    (field, "")
}

/// The column names of an array field of `n` components.
pub fn component_names(field: &str, n: usize) -> Vec<String> {
    if n == 1 {
        return vec![field.to_string()];
    }
    let (quantity, unit) = split_unit(field);
    let (quantity, names): (&str, Option<&[&str]>) = match (quantity, n) {
        ("euler", 3) => ("", Some(&["roll", "pitch", "yaw"])),
        (q, 3) if q.ends_with("_ned") => (&q[..q.len() - 4], Some(&["north", "east", "down"])),
        (q, 3) if q.contains("_ned_") => (q, Some(&["north", "east", "down"])),
        (q, 4) if q.starts_with("quaternion") => (q, Some(&["w", "x", "y", "z"])),
        (q, 3) => (q, Some(&["x", "y", "z"])),
        (q, _) => (q, None),
    };
    (0..n)
        .map(|k| {
            let c = names.map_or_else(|| k.to_string(), |v| v[k].to_string());
            if quantity.is_empty() {
                format!("{c}{unit}")
            } else {
                format!("{quantity}_{c}{unit}")
            }
        })
        .collect()
}

/// Builds a table message by message.
#[derive(Debug, Default)]
struct Builder {
    table: Table,
}

/// One scalar value of a message.
enum Cell {
    F64(f64),
    U64(u64),
    Text(String),
}

/// A message's fields as (field name, its values as cells), in declaration order.
fn cells<T: Message>(m: &T) -> Vec<(&'static str, Vec<Cell>)> {
    let mut out = Vec::new();
    m.for_each_field(&mut |name, values| {
        let cells: Vec<Cell> = match values {
            FieldValues::F64(v) => v.iter().map(|x| Cell::F64(*x)).collect(),
            FieldValues::F32(v) => v.iter().map(|x| Cell::F64(f64::from(*x))).collect(),
            FieldValues::U64(v) => v.iter().map(|x| Cell::U64(*x)).collect(),
            FieldValues::U32(v) => v.iter().map(|x| Cell::U64(u64::from(*x))).collect(),
            FieldValues::U16(v) => v.iter().map(|x| Cell::U64(u64::from(*x))).collect(),
            // Text up to the first NUL; raw frames (more than a name holds) are left out.
            FieldValues::U8(v) if v.len() <= 64 => {
                let end = v.iter().position(|b| *b == 0).unwrap_or(v.len());
                vec![Cell::Text(String::from_utf8_lossy(&v[..end]).into_owned())]
            }
            FieldValues::U8(_) => Vec::new(),
        };
        out.push((name, cells));
    });
    out
}

impl Builder {
    fn push<T: Message>(&mut self, m: &T) {
        let fields = cells(m);
        let cols = &mut self.table.columns;
        if self.table.rows == 0 {
            self.table.schema = T::SCHEMA_NAME.to_string();
            cols.push(Column {
                name: "time_s".into(),
                values: ColumnValues::F64(Vec::new()),
            });
            for (name, cells) in &fields {
                for (c, column) in cells.iter().zip(component_names(name, cells.len())) {
                    cols.push(Column {
                        name: column,
                        values: match c {
                            Cell::F64(_) => ColumnValues::F64(Vec::new()),
                            Cell::U64(_) => ColumnValues::U64(Vec::new()),
                            Cell::Text(_) => ColumnValues::Text(Vec::new()),
                        },
                    });
                }
            }
        }
        let time = Cell::F64(m.host_time().as_secs_f64());
        let row = std::iter::once(time).chain(fields.into_iter().flat_map(|(_, c)| c));
        for (column, cell) in cols.iter_mut().zip(row) {
            match (&mut column.values, cell) {
                (ColumnValues::F64(v), Cell::F64(x)) => v.push(x),
                (ColumnValues::U64(v), Cell::U64(x)) => v.push(x),
                (ColumnValues::Text(v), Cell::Text(x)) => v.push(x),
                // A message type's fields have one type each: unreachable.
                _ => {}
            }
        }
        self.table.rows += 1;
    }
}

fn push_raw(tables: &mut BTreeMap<String, Builder>, out: &mut Tables, raw: &RawLogMessage) {
    use crate::LogMessage as M;
    let m = match raw.decode_any() {
        Ok(M::Unknown) => {
            out.unknown_messages += 1;
            return;
        }
        Ok(m) => m,
        Err(_) => {
            out.bad_messages += 1;
            return;
        }
    };
    let b = tables.entry(raw.topic.to_string()).or_default();
    match m {
        M::Imu(x) => b.push(&x),
        M::Dvl(x) => b.push(&x),
        M::Usbl(x) => b.push(&x),
        M::Depth(x) => b.push(&x),
        M::Magnetometer(x) => b.push(&x),
        M::SoundVelocity(x) => b.push(&x),
        M::Attitude(x) => b.push(&x),
        M::AcousticRanges(x) => b.push(&x),
        M::AcousticArrayPose(x) => b.push(&x),
        M::Gnss(x) => b.push(&x),
        M::NavSolution(x) => b.push(&x),
        M::AidDiagnostics(x) => b.push(&x),
        M::Health(x) => b.push(&x),
        M::LateAid(x) => b.push(&x),
        M::SessionEvent(x) => b.push(&x),
        M::Truth(x) => b.push(&x),
        M::Unknown => {}
    }
}

/// Reads every message of the log at `path` into one table per channel. A truncated or damaged
/// tail ends the tables with what was read and the reason in [`Tables::log_error`]; a file that
/// cannot be read as a log at all is an error.
pub fn read_tables(path: &Path) -> Result<Tables, LogError> {
    let mut reader = LogReader::open(path)?;
    reader.read_header()?;
    let mut builders: BTreeMap<String, Builder> = BTreeMap::new();
    let mut out = Tables::default();
    loop {
        match reader.next_message() {
            Ok(Some(raw)) => push_raw(&mut builders, &mut out, &raw),
            Ok(None) => break,
            Err(e) => {
                out.log_error = Some(e.to_string());
                break;
            }
        }
    }
    out.tables = builders
        .into_iter()
        .map(|(topic, b)| (topic, b.table))
        .collect();
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn components_are_named_between_the_quantity_and_the_unit() {
        assert_eq!(
            component_names("velocity_ned_m_s", 3),
            [
                "velocity_north_m_s",
                "velocity_east_m_s",
                "velocity_down_m_s"
            ]
        );
        assert_eq!(
            component_names("euler_rad", 3),
            ["roll_rad", "pitch_rad", "yaw_rad"]
        );
        assert_eq!(
            component_names("specific_force_m_s2", 3),
            [
                "specific_force_x_m_s2",
                "specific_force_y_m_s2",
                "specific_force_z_m_s2"
            ]
        );
        assert_eq!(
            component_names("quaternion_body_to_ned", 4),
            [
                "quaternion_body_to_ned_w",
                "quaternion_body_to_ned_x",
                "quaternion_body_to_ned_y",
                "quaternion_body_to_ned_z"
            ]
        );
        assert_eq!(
            component_names("position_std_ned_m", 3),
            [
                "position_std_north_m",
                "position_std_east_m",
                "position_std_down_m"
            ]
        );
        assert_eq!(
            component_names("beam_velocity_m_s", 4),
            [
                "beam_velocity_0_m_s",
                "beam_velocity_1_m_s",
                "beam_velocity_2_m_s",
                "beam_velocity_3_m_s"
            ]
        );
        assert_eq!(
            component_names("angular_rate_rad_s", 1),
            ["angular_rate_rad_s"]
        );
        assert_eq!(
            component_names("angular", 3),
            ["angular_x", "angular_y", "angular_z"]
        );
    }

    #[test]
    fn a_written_log_reads_back_as_one_table_per_channel() {
        use crate::{LogHeader, LogWriter};
        use auvnav_shm_schema::{ImuSampleV1, ProcessHealthV1};
        let dir = std::env::temp_dir().join(format!("auvnav-table-{}", std::process::id()));
        std::fs::create_dir_all(&dir).expect("dir");
        let path = dir.join("t.mcap");
        let mut w = LogWriter::create(&path, &LogHeader::new("test", "")).expect("create");
        for k in 0..3u64 {
            let imu = ImuSampleV1 {
                host_time_ns: 1_000_000_000 + k * 10_000_000,
                sequence: k,
                angular: [0.1, 0.2, k as f64],
                specific: [0.0, 0.0, -9.81],
                interval_s: 0.01,
                ..Default::default()
            };
            w.write("sensors/imu", &imu).expect("write");
        }
        let mut health = ProcessHealthV1 {
            host_time_ns: 2_000_000_000,
            ..Default::default()
        };
        health.name[..7].copy_from_slice(b"auvnavd");
        w.write("health/auvnavd", &health).expect("write");
        w.finish().expect("finish");

        let t = read_tables(&path).expect("tables");
        assert_eq!(t.log_error, None);
        let imu = &t.tables["sensors/imu"];
        assert_eq!(imu.rows, 3);
        assert_eq!(imu.schema, ImuSampleV1::SCHEMA_NAME);
        let col = |name: &str| {
            imu.columns
                .iter()
                .find(|c| c.name == name)
                .unwrap_or_else(|| panic!("no column {name}"))
                .values
                .clone()
        };
        assert_eq!(col("time_s"), ColumnValues::F64(vec![1.0, 1.01, 1.02]));
        assert_eq!(col("angular_z"), ColumnValues::F64(vec![0.0, 1.0, 2.0]));
        assert_eq!(col("sequence"), ColumnValues::U64(vec![0, 1, 2]));
        assert!(imu.columns.iter().all(|c| c.values.len() == 3));
        let h = &t.tables["health/auvnavd"];
        let name = h.columns.iter().find(|c| c.name == "name").expect("name");
        assert_eq!(name.values, ColumnValues::Text(vec!["auvnavd".into()]));
        std::fs::remove_dir_all(&dir).ok();
    }
}
