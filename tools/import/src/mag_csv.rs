//! A magnetometer CSV recording.

#[allow(unused_imports)]
use super::*;

/// Command-line arguments of `auvnav import mag-csv`.
#[derive(Debug, Clone)]
#[cfg_attr(feature = "clap", derive(clap::Args))]
pub struct MagCsvOptions {
    /// A CSV file with magnetometer and accelerometer columns (a header line names them; lines
    /// starting with `#` are comments).
    pub file: PathBuf,
    /// Output log (written atomically).
    #[cfg_attr(feature = "clap", arg(long))]
    pub out: PathBuf,
    #[cfg_attr(feature = "clap", command(flatten))]
    pub columns: crate::mag::CsvColumnOptions,
    /// Print the summary as JSON.
    #[cfg_attr(feature = "clap", arg(long))]
    pub json: bool,
}

/// What `auvnav import mag-csv` read and wrote.
#[derive(Debug, Clone, Default, Serialize)]
pub struct MagCsvSummary {
    /// Rows written (a magnetometer reading, with the accelerometer's when the row has one).
    pub readings: usize,
    /// Of them, rows with an accelerometer reading.
    pub with_accelerometer: usize,
    /// Of them, rows with a gyro reading (rad/s in the log).
    pub with_gyro: usize,
    /// Rows left out (a magnetometer value missing or not a number, a bad time).
    pub skipped: usize,
    /// Rows whose time does not increase (left out).
    pub out_of_order: usize,
    pub duration_s: f64,
    pub field_unit: String,
    pub accelerometer_unit: String,
    /// Decimal year of the first row, when the time column is a calendar time.
    pub date: Option<f64>,
}

/// Standard gravity (m/s²): accelerometer readings in g are converted with it.
const STANDARD_GRAVITY: f64 = 9.80665;

/// The messages of a magnetometer CSV recording (an IMU sample with the specific force, then the
/// magnetometer reading, per row; time 0 = first row) and the summary.
pub fn mag_csv_messages(
    a: &MagCsvOptions,
) -> Result<(Vec<(&'static str, LogMessage)>, MagCsvSummary)> {
    use auvnav_shm_schema::MagnetometerV1;
    let cols = a.columns.columns()?;
    let rec = crate::mag::read_csv(&a.file, &cols)?;
    let mut s = MagCsvSummary {
        skipped: rec.skipped,
        field_unit: rec.unit_note.clone(),
        date: rec.whereabouts.date,
        ..Default::default()
    };
    // Accelerometer unit: g when the median magnitude is near 1, m/s² when near 9.8.
    let mut norms: Vec<f64> = rec
        .samples
        .iter()
        .filter_map(|x| x.specific_force.map(|f| f.norm()))
        .collect();
    norms.sort_by(f64::total_cmp);
    let accel_scale = match norms.get(norms.len() / 2) {
        Some(&m) if m < 3.0 => {
            s.accelerometer_unit = format!("g (median magnitude {m:.3}), converted to m/s²");
            STANDARD_GRAVITY
        }
        Some(&m) => {
            s.accelerometer_unit = format!("m/s² (median magnitude {m:.3})");
            1.0
        }
        None => {
            s.accelerometer_unit = "none (no accelerometer columns)".into();
            1.0
        }
    };
    let Some(t0) = rec.samples.first().map(|x| x.time_s) else {
        malformed!("{}: no magnetometer rows", a.file.display());
    };
    let mut out = Vec::with_capacity(2 * rec.samples.len());
    let mut last_ns: Option<u64> = None;
    let mut last_t = t0;
    let mut imu_sequence = 0u64;
    for x in &rec.samples {
        let dt = x.time_s - t0;
        if dt.is_nan() || dt < 0.0 || last_ns.is_some_and(|l| ns_of(dt) <= l) {
            s.out_of_order += 1;
            continue;
        }
        let host = ns_of(dt);
        let interval = (x.time_s - last_t).clamp(1e-3, 0.999);
        last_t = x.time_s;
        last_ns = Some(host);
        s.readings += 1;
        if x.specific_force.is_some() || x.angular_rate.is_some() {
            let mut status = 0;
            if x.specific_force.is_some() {
                s.with_accelerometer += 1;
                status |= ImuSampleV1::STATUS_ACCEL_VALID;
            }
            if x.angular_rate.is_some() {
                s.with_gyro += 1;
                status |= ImuSampleV1::STATUS_GYRO_VALID;
            }
            imu_sequence += 1;
            out.push((
                topic::IMU,
                LogMessage::Imu(ImuSampleV1 {
                    host_time_ns: host,
                    device_time_ns: host,
                    sequence: imu_sequence,
                    // Rates (rad/s, m/s²): the increments flag is not set.
                    angular: x.angular_rate.unwrap_or_default().into(),
                    specific: (x.specific_force.unwrap_or_default() * accel_scale).into(),
                    interval_s: interval,
                    temperature_c: 0.0,
                    status,
                }),
            ));
        }
        out.push((
            topic::MAGNETOMETER,
            LogMessage::Magnetometer(MagnetometerV1 {
                host_time_ns: host,
                device_time_ns: host,
                sequence: s.readings as u64,
                field_t: (x.field_ut * 1e-6).into(),
                temperature_c: 0.0,
                validity: MagnetometerV1::VALID_FIELD,
            }),
        ));
        s.duration_s = dt;
    }
    Ok((out, s))
}

/// Imports a magnetometer CSV recording into a log at `out` (written atomically).
pub fn mag_csv(a: &MagCsvOptions) -> Result<MagCsvSummary> {
    use auvnav_shm_schema::MagnetometerV1;
    let (messages, summary) = mag_csv_messages(a)?;
    let header = import_header(
        "auvnav import mag-csv",
        a.file.display().to_string(),
        format!(
            "magnetometer CSV: field {}, accelerometer {}; time 0 = first row{}",
            summary.field_unit,
            summary.accelerometer_unit,
            summary
                .date
                .map_or(String::new(), |d| format!(" (decimal year {d:.4})"))
        ),
        &summary,
    );
    write_log_atomically(&a.out, &header, |w: &mut LogWriter<_>| {
        w.declare::<ImuSampleV1>(
            topic::IMU,
            &note(&[(
                "source",
                "the CSV's accelerometer columns as specific force in the sensor's axes (no gyro: angular rate not valid)",
            )]),
        )?;
        w.declare::<MagnetometerV1>(
            topic::MAGNETOMETER,
            &note(&[("source", "the CSV's magnetometer columns, in the sensor's axes")]),
        )?;
        for (t, m) in &messages {
            match m {
                LogMessage::Imu(x) => w.write(t, x)?,
                LogMessage::Magnetometer(x) => w.write(t, x)?,
                _ => {}
            }
        }
        Ok(())
    })
    .map_err(crate::error::output(&a.out))?;
    Ok(summary)
}
