//! A surface run's magnetic compass against true north: where a log's header says its heading is
//! a magnetic compass's ([`auvnav_log::HEADING_DECLINATION_APPLIED`], written by `auvnav import
//! pd0` and `auvnav import riversurveyor`) and when it was recorded
//! ([`auvnav_log::RECORDED_DATE`]), the declination at the run's GNSS positions on that date
//! (the World Magnetic Model) less the declination already applied is the heading offset the
//! compass shows against true north before any deviation of its own: the `dvl.mount_yaw` a
//! surface run's calibration and discovery estimate. `auvnav calibrate dvl` and `auvnav
//! discover` give it beside their estimate, so a heading offset has its likely cause named, and
//! a compass that was corrected can be told from one that was not.

use auvnav_core::wmm::{WorldMagneticModel, decimal_year};
use auvnav_log::{LogMessage, LogReader};
use auvnav_shm_schema::GnssFixV1;
use serde::Serialize;
use std::path::Path;

/// The declination a log's magnetic compass has not had applied, at its GNSS positions.
#[derive(Debug, Clone, Serialize)]
pub struct CompassDeclination {
    pub log: String,
    /// The recording's date (the instrument's clock).
    pub date: String,
    /// The mean of the log's GNSS positions (deg).
    pub latitude_deg: f64,
    pub longitude_deg: f64,
    /// The World Magnetic Model used, and its declination there (deg, east positive).
    pub model: String,
    pub declination_deg: f64,
    /// The declination the instrument or its export already added to the heading (deg).
    pub applied_deg: f64,
    /// The declination not applied (`declination_deg − applied_deg`): the `dvl.mount_yaw` the
    /// compass shows against true north before its own deviation (deg).
    pub expected_mount_yaw_deg: f64,
}

/// The compass's declination for `log`, or why it cannot be given (None: the header does not say
/// the heading is a magnetic compass's).
pub fn declination_of(log: &Path) -> Option<Result<CompassDeclination, String>> {
    let mut reader = LogReader::open(log).ok()?;
    let header = reader.read_header().ok()?;
    let applied: f64 = header
        .notes
        .get(auvnav_log::HEADING_DECLINATION_APPLIED)?
        .trim()
        .parse()
        .ok()
        .filter(|d: &f64| d.is_finite())?;
    Some(declination_with(log, &mut reader, &header.notes, applied))
}

fn declination_with(
    log: &Path,
    reader: &mut LogReader<std::io::BufReader<std::fs::File>>,
    notes: &std::collections::BTreeMap<String, String>,
    applied: f64,
) -> Result<CompassDeclination, String> {
    let date = notes
        .get(auvnav_log::RECORDED_DATE)
        .ok_or("the log does not say when it was recorded")?
        .clone();
    let year = parse_date(&date).ok_or(format!("its recording date {date:?} does not parse"))?;
    // The mean position; longitudes as offsets from the first fix's, wrapped, so that a run
    // across the antimeridian does not average to the other side of the Earth.
    let (mut n, mut lat, mut dlon, mut lon0) = (0usize, 0.0, 0.0, None);
    while let Ok(Some(raw)) = reader.next_message() {
        if let Ok(LogMessage::Gnss(f)) = raw.decode_any()
            && f.validity & GnssFixV1::VALID_POSITION != 0
            && f.latitude_rad.is_finite()
            && f.longitude_rad.is_finite()
        {
            let lon = f.longitude_rad.to_degrees();
            let first = *lon0.get_or_insert(lon);
            n += 1;
            lat += f.latitude_rad.to_degrees();
            dlon += (lon - first + 540.0).rem_euclid(360.0) - 180.0;
        }
    }
    let Some(lon0) = lon0 else {
        return Err("it has no GNSS position".into());
    };
    let lat = lat / n as f64;
    let lon = (lon0 + dlon / n as f64 + 540.0).rem_euclid(360.0) - 180.0;
    let model = WorldMagneticModel::builtin_for(year).ok_or(format!(
        "no built-in World Magnetic Model covers {date} (WMM2010 covers 2010–2015, WMM2020 and \
         WMM2025 2020–2030)"
    ))?;
    let declination = model
        .field(lat, lon, 0.0, year)
        .map_err(|e| e.to_string())?
        .declination_deg();
    Ok(CompassDeclination {
        log: log.display().to_string(),
        date,
        latitude_deg: lat,
        longitude_deg: lon,
        model: model.name,
        declination_deg: declination,
        applied_deg: applied,
        expected_mount_yaw_deg: declination - applied,
    })
}

/// The declinations of the logs whose heading is a magnetic compass's, and a note for each: the
/// declination not applied beside `yaw` (the heading offset the caller estimated: value,
/// deviation, how; deg), or why it cannot be given.
pub fn declinations<'a>(
    logs: impl IntoIterator<Item = &'a Path>,
    yaw: Option<(f64, f64, &str)>,
) -> (Vec<CompassDeclination>, Vec<String>) {
    let (mut found, mut notes) = (Vec::new(), Vec::new());
    for log in logs {
        match declination_of(log) {
            None => {}
            Some(Err(why)) => notes.push(format!(
                "{}: the heading is a magnetic compass's, but its declination cannot be given: \
                 {why}",
                log.display()
            )),
            Some(Ok(c)) => {
                notes.push(note(&c, yaw));
                found.push(c);
            }
        }
    }
    (found, notes)
}

/// The decimal year of `YYYY-MM-DD` (its middle).
fn parse_date(date: &str) -> Option<f64> {
    let mut parts = date.split('-').map(str::parse::<i64>);
    let (y, m, d) = (
        parts.next()?.ok()?,
        parts.next()?.ok()?,
        parts.next()?.ok()?,
    );
    decimal_year(
        i32::try_from(y).ok()?,
        u32::try_from(m).ok()?,
        u32::try_from(d).ok()?,
        43_200.0,
    )
}

/// The report's note for `c`, with the heading offset the run gave (value, deviation, how it was
/// decided; deg) compared with it and with none.
pub fn note(c: &CompassDeclination, yaw: Option<(f64, f64, &str)>) -> String {
    let mut s = format!(
        "{}: the heading is a magnetic compass's with {:.2}° of declination applied; {} gives \
         {:.2}° east at the run ({:.3}°, {:.3}°) on {}: such a heading shows a heading offset \
         (`dvl.mount_yaw`) of {:.2}° against true north, before the compass's own deviation",
        c.log,
        c.applied_deg,
        c.model,
        c.declination_deg,
        c.latitude_deg,
        c.longitude_deg,
        c.date,
        c.expected_mount_yaw_deg
    );
    if let Some((value, std, how)) = yaw {
        let from = |x: f64| (value - x).abs() / std.max(f64::MIN_POSITIVE);
        s.push_str(&format!(
            "; the heading offset {how} here, {value:.2} ± {std:.2}°, is {:.1} deviations from \
             it and {:.1} from none",
            from(c.expected_mount_yaw_deg),
            from(0.0)
        ));
    }
    s
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn dates_parse_to_their_middle() {
        let y = parse_date("2010-09-23").expect("date");
        assert!((y - (2010.0 + (265.0 + 0.5) / 365.0)).abs() < 1e-12, "{y}");
        assert!(parse_date("2010-13-01").is_none());
        assert!(parse_date("yesterday").is_none());
    }

    #[test]
    fn the_note_compares_the_estimate_with_the_declination_and_with_none() {
        let c = CompassDeclination {
            log: "wr.mcap".into(),
            date: "2010-09-23".into(),
            latitude_deg: 64.56,
            longitude_deg: -149.06,
            model: "WMM-2010".into(),
            declination_deg: 20.0,
            applied_deg: 0.0,
            expected_mount_yaw_deg: 20.0,
        };
        let s = note(&c, Some((17.0, 4.0, "pointed at")));
        assert!(
            s.contains("0.8 deviations from it and 4.2 from none"),
            "{s}"
        );
        assert!(!note(&c, None).contains("deviations"));
    }
}
