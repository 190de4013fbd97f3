//! The Snapir AUV data set.

#[allow(unused_imports)]
use super::*;

/// Command-line arguments of `auvnav import snapir`.
#[derive(Debug, Clone)]
#[cfg_attr(feature = "clap", derive(clap::Args))]
pub struct SnapirOptions {
    /// The data set folder (with imu_NN.csv, dvl_NN.csv, ref_NN.csv).
    pub dir: PathBuf,
    /// Segment number (1..13).
    #[cfg_attr(feature = "clap", arg(long))]
    pub segment: u32,
    /// Output log (MCAP).
    #[cfg_attr(feature = "clap", arg(long))]
    pub out: PathBuf,
    /// Time stamps: `nominal` (sample index at 100 Hz IMU / 1 Hz DVL and reference) or `file`
    /// (the files' time column, which spreads each file evenly over 0..400 s).
    #[cfg_attr(feature = "clap", arg(long, value_enum, default_value_t = TimeBase::Nominal))]
    pub time_base: TimeBase,
    /// Keep the reference on its own clock instead of aligning it to the IMU clock (see
    /// [`estimate_reference_offset`]).
    #[cfg_attr(feature = "clap", arg(long))]
    pub no_align: bool,
    /// Print the summary as JSON.
    #[cfg_attr(feature = "clap", arg(long))]
    pub json: bool,
}

/// How the imported samples are stamped.
///
/// The files' time columns are `linspace(0, 400, rows)` (IMU step 400/39999 s, DVL and reference
/// step 400/399 s), so the 1 Hz streams are stretched by 1 s over a segment against the 100 Hz
/// IMU. Stamping by sample index at the nominal rates makes the integrated gyro heading agree with
/// the reference far better (docs/measured-data.md), so it is the default.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[cfg_attr(feature = "clap", derive(clap::ValueEnum))]
#[serde(rename_all = "snake_case")]
pub enum TimeBase {
    Nominal,
    File,
}

/// IMU rate of the data set (Hz).
pub const SNAPIR_IMU_HZ: f64 = 100.0;
/// DVL and reference rate of the data set (Hz).
pub const SNAPIR_DVL_HZ: f64 = 1.0;

/// Rows read and skipped per file.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize)]
pub struct FileCounts {
    pub rows: u64,
    /// Rows with a wrong field count, a field that is not a number, or a non-finite value.
    pub malformed: u64,
    /// Rows whose time does not increase (duplicates or out of order).
    pub out_of_order: u64,
}

#[derive(Debug, Clone, Serialize)]
pub struct SnapirSummary {
    pub segment: u32,
    pub time_base: TimeBase,
    /// The reference-to-IMU clock alignment, when done.
    pub alignment: Option<ClockAlignment>,
    /// Reference rows that fall before the first IMU sample after alignment (dropped).
    pub reference_before_imu: u64,
    pub imu: FileCounts,
    pub dvl: FileCounts,
    pub reference: FileCounts,
    pub duration_s: f64,
    pub messages: u64,
}

/// The clock offset between a reference attitude series and a gyro.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct ClockAlignment {
    /// Add this to a reference time to get the IMU time of the same instant (s).
    pub offset_s: f64,
    /// RMS over the reference intervals of the angle between the reference's and the gyro's
    /// rotation over the interval, at the chosen offset (deg).
    pub residual_deg: f64,
    /// The same at zero offset (deg).
    pub residual_at_zero_deg: f64,
}

/// Search range of the clock alignment (s).
pub const ALIGNMENT_SEARCH_S: f64 = 2.0;
/// Step of the clock alignment search (s).
pub const ALIGNMENT_STEP_S: f64 = 0.01;

/// Estimates the clock offset between the IMU and the reference by comparing, over every
/// reference interval, the body rotation the reference attitude shows with the rotation the gyro
/// integrates over the same interval shifted by the offset; returns the offset with the smallest
/// RMS angle on a grid of `ALIGNMENT_STEP_S` over `±ALIGNMENT_SEARCH_S`. Earth rate is ignored
/// (0.004 deg per second). The reference attitude comes from an INS that shares nothing with this
/// clock, so the estimate uses the reference only to align clocks, never to correct the sensors.
pub fn estimate_reference_offset(imu: &[[f64; 7]], reference: &[[f64; 10]]) -> ClockAlignment {
    // Cumulative gyro attitude at each IMU time (body rotation from the first sample).
    let mut q = UnitQuaternion::identity();
    let mut cumulative = Vec::with_capacity(imu.len());
    cumulative.push(q);
    for w in imu.windows(2) {
        let dt = w[1][0] - w[0][0];
        let rate = nalgebra::Vector3::new(w[1][4], w[1][5], w[1][6]);
        q *= UnitQuaternion::from_scaled_axis(rate * dt);
        cumulative.push(q);
    }
    let times: Vec<f64> = imu.iter().map(|r| r[0]).collect();
    let at = |t: f64| -> Option<UnitQuaternion<f64>> {
        if !(times[0]..=times[times.len() - 1]).contains(&t) {
            return None;
        }
        let i = times.partition_point(|&x| x <= t).clamp(1, times.len() - 1);
        let w = (t - times[i - 1]) / (times[i] - times[i - 1]);
        Some(cumulative[i - 1].nlerp(&cumulative[i], w))
    };
    let attitude = |r: &[f64; 10]| UnitQuaternion::from_euler_angles(r[7], r[8], r[9]);
    let residual = |offset: f64| -> f64 {
        let (mut sum, mut n) = (0.0, 0usize);
        for pair in reference.windows(2) {
            let (Some(a), Some(b)) = (at(pair[0][0] + offset), at(pair[1][0] + offset)) else {
                continue;
            };
            let gyro = a.inverse() * b;
            let truth = attitude(&pair[0]).inverse() * attitude(&pair[1]);
            sum += (truth.inverse() * gyro).angle().powi(2);
            n += 1;
        }
        if n == 0 {
            f64::INFINITY
        } else {
            (sum / n as f64).sqrt()
        }
    };
    let steps = (ALIGNMENT_SEARCH_S / ALIGNMENT_STEP_S).round() as i64;
    let mut best = (f64::INFINITY, 0.0);
    for k in -steps..=steps {
        let offset = k as f64 * ALIGNMENT_STEP_S;
        let r = residual(offset);
        if r < best.0 {
            best = (r, offset);
        }
    }
    ClockAlignment {
        offset_s: best.1,
        residual_deg: best.0.to_degrees(),
        residual_at_zero_deg: residual(0.0).to_degrees(),
    }
}

/// The reference's angular rate w.r.t. inertial space in body axes (rad/s) at each of its rows:
/// the rotation between the neighbouring rows' attitudes (central differences, one-sided at the
/// ends) plus the Earth rate. The data set gives the attitude only; a truth record carries the
/// rate so that a reference at another point of the vehicle can be moved to the IMU in velocity
/// as well as in position (`auvnav replay --reference-lever-arm`). NaN where the neighbours are
/// more than 2 s apart.
fn reference_rates(rows: &[[f64; 10]]) -> Vec<[f64; 3]> {
    let attitude = |r: &[f64; 10]| UnitQuaternion::from_euler_angles(r[7], r[8], r[9]);
    let n = rows.len();
    (0..n)
        .map(|i| {
            let (a, b) = (i.saturating_sub(1), (i + 1).min(n.saturating_sub(1)));
            let dt = rows[b][0] - rows[a][0];
            if a == b || !(dt > 0.0 && dt <= 2.0) {
                return [f64::NAN; 3];
            }
            let (qa, qb) = (attitude(&rows[a]), attitude(&rows[b]));
            let w_eb = (qa.inverse() * qb).scaled_axis() / dt;
            let q = attitude(&rows[i]);
            let w_ie = q.inverse() * auvnav_core::earth::earth_rate_ned(rows[i][2]);
            (w_eb + w_ie).into()
        })
        .collect()
}

/// The messages of one segment in time order, and the summary.
pub fn snapir_messages(
    dir: &Path,
    segment: u32,
    time_base: TimeBase,
    align: bool,
) -> Result<(Vec<(&'static str, LogMessage)>, SnapirSummary)> {
    if !(1..=99).contains(&segment) {
        bad_option!("--segment {segment}: segments are numbered 1..13");
    }
    let file = |kind: &str| dir.join(format!("{kind}_{segment:02}.csv"));
    let imu = read_table::<7>(
        &file("imu"),
        "time_s,f_x_m_s2,f_y_m_s2,f_z_m_s2,w_x_rad_s,w_y_rad_s,w_z_rad_s",
    )?;
    let dvl = read_table::<4>(&file("dvl"), "time_s,v_x_m_s,v_y_m_s,v_z_m_s")?;
    let reference = read_table::<10>(
        &file("ref"),
        "time_s,lon_rad,lat_rad,alt_m,v_n_m_s,v_e_m_s,v_d_m_s,roll_rad,pitch_rad,yaw_rad",
    )?;
    // Re-stamp by row index when asked (rows skipped as malformed keep their slot).
    let (mut imu, mut dvl, mut reference) = (imu, dvl, reference);
    if time_base == TimeBase::Nominal {
        restamp(&mut imu.rows, SNAPIR_IMU_HZ);
        restamp(&mut dvl.rows, SNAPIR_DVL_HZ);
        restamp(&mut reference.rows, SNAPIR_DVL_HZ);
    }
    let alignment = align.then(|| estimate_reference_offset(&imu.rows, &reference.rows));
    let mut reference_before_imu = 0;
    if let Some(a) = alignment {
        let t0 = imu.rows[0][0];
        reference.rows.retain_mut(|r| {
            r[0] += a.offset_s;
            let keep = r[0] >= t0;
            reference_before_imu += u64::from(!keep);
            keep
        });
        if reference.rows.is_empty() {
            malformed!("segment {segment}: no reference row is left after the clock alignment");
        }
    }
    let mut out: Vec<(u64, u8, &'static str, LogMessage)> = Vec::new();
    // The nominal interval: the median spacing of the IMU times.
    let mut spacing: Vec<f64> = imu.rows.windows(2).map(|w| w[1][0] - w[0][0]).collect();
    spacing.sort_by(f64::total_cmp);
    let nominal = spacing.get(spacing.len() / 2).copied().unwrap_or(0.01);
    let mut prev_t: Option<f64> = None;
    for (i, r) in imu.rows.iter().enumerate() {
        let interval = prev_t.map(|p| r[0] - p).unwrap_or(nominal);
        prev_t = Some(r[0]);
        let m = ImuSampleV1 {
            host_time_ns: ns(r[0]),
            device_time_ns: ns(r[0]),
            sequence: i as u64,
            angular: [r[4], r[5], r[6]],
            specific: [r[1], r[2], r[3]],
            interval_s: interval,
            temperature_c: f32::NAN,
            status: ImuSampleV1::STATUS_GYRO_VALID
                | ImuSampleV1::STATUS_ACCEL_VALID
                | ImuSampleV1::STATUS_DEVICE_TIME_VALID,
        };
        // Order within one time stamp: truth, then IMU, then aids.
        out.push((m.host_time_ns, 1, topic::IMU, LogMessage::Imu(m)));
    }
    for (i, r) in dvl.rows.iter().enumerate() {
        let m = DvlVelocityV1 {
            host_time_ns: ns(r[0]),
            device_time_ns: ns(r[0]),
            sequence: i as u64,
            validity_time_ns: ns(r[0]),
            velocity_dvl_m_s: [r[1], r[2], r[3]],
            velocity_std_m_s: [f64::NAN; 3],
            beam_velocity_m_s: [f64::NAN; 4],
            beam_range_m: [f64::NAN; 4],
            altitude_m: f64::NAN,
            figure_of_merit_m_s: f64::NAN,
            sound_speed_m_s: f64::NAN,
            validity: DvlVelocityV1::VALID_VELOCITY | DvlVelocityV1::VALID_DEVICE_TIME,
            beams_used: 0,
        };
        out.push((m.host_time_ns, 2, topic::DVL, LogMessage::Dvl(m)));
    }
    let rates = reference_rates(&reference.rows);
    for (i, r) in reference.rows.iter().enumerate() {
        let (lon, lat, alt) = (r[1], r[2], r[3]);
        let euler = [r[7], r[8], r[9]];
        let q = UnitQuaternion::from_euler_angles(euler[0], euler[1], euler[2]);
        let truth = TruthStateV1 {
            host_time_ns: ns(r[0]),
            sequence: i as u64,
            latitude_rad: lat,
            longitude_rad: lon,
            height_m: alt,
            velocity_ned_m_s: [r[4], r[5], r[6]],
            quaternion_body_to_ned: [q.w, q.i, q.j, q.k],
            euler_rad: euler,
            angular_rate_rad_s: rates[i],
            specific_force_m_s2: [f64::NAN; 3],
        };
        out.push((
            truth.host_time_ns,
            0,
            topic::TRUTH,
            LogMessage::Truth(truth),
        ));
        let depth = DepthV1 {
            host_time_ns: ns(r[0]),
            device_time_ns: ns(r[0]),
            sequence: i as u64,
            depth_m: -alt,
            pressure_pa: f64::NAN,
            water_density_kg_m3: f64::NAN,
            temperature_c: f32::NAN,
            validity: DepthV1::VALID_DEPTH,
        };
        out.push((
            depth.host_time_ns,
            3,
            topic::DEPTH,
            LogMessage::Depth(depth),
        ));
    }
    out.sort_by_key(|&(t, order, _, _)| (t, order));
    let first = out.first().map(|m| m.0).unwrap_or(0);
    let last = out.last().map(|m| m.0).unwrap_or(0);
    let summary = SnapirSummary {
        segment,
        time_base,
        alignment,
        reference_before_imu,
        imu: imu.counts,
        dvl: dvl.counts,
        reference: reference.counts,
        duration_s: (last - first) as f64 * 1e-9,
        messages: out.len() as u64,
    };
    Ok((
        out.into_iter().map(|(_, _, t, m)| (t, m)).collect(),
        summary,
    ))
}

/// Imports one segment into a log at `out` (written atomically).
pub fn snapir(a: &SnapirOptions) -> Result<SnapirSummary> {
    let (messages, summary) = snapir_messages(&a.dir, a.segment, a.time_base, !a.no_align)?;
    let mut header = LogHeader::new("auvnav import snapir", "");
    header
        .notes
        .insert("source".into(), a.dir.display().to_string());
    header
        .notes
        .insert("source.segment".into(), a.segment.to_string());
    header.notes.insert(
        "source.description".into(),
        "Snapir AUV (ECA A18-D), Phins FOG INS 100 Hz, RDI Workhorse DVL 1 Hz, Delph post-processed reference; time 0 = segment start".into(),
    );
    header.notes.insert(
        auvnav_log::REFERENCE_AIDED_BY.into(),
        "imu,dvl: the Delph post-processing of the vehicle's own INS with this DVL".into(),
    );
    header.notes.insert(
        "replay.initial_state".into(),
        "from the reference (truth channel) at the segment start".into(),
    );
    let counts = serde_json::to_string(&summary).unwrap_or_default();
    header.notes.insert("import.counts".into(), counts);
    write_log_atomically(&a.out, &header, |w: &mut LogWriter<_>| {
        w.declare::<ImuSampleV1>(
            topic::IMU,
            &note(&[(
                "source",
                "imu_NN.csv: body frame x forward, y starboard, z down; angular rate and specific force (not increments)",
            )]),
        )?;
        w.declare::<DvlVelocityV1>(
            topic::DVL,
            &note(&[(
                "source",
                "dvl_NN.csv: bottom-track velocity already in the vehicle body frame (mounting unknown, treated as identity)",
            )]),
        )?;
        w.declare::<TruthStateV1>(
            topic::TRUTH,
            &note(&[(
                "source",
                "ref_NN.csv: post-processed INS/DVL reference solution (not independent of the DVL); angular rate from its attitude (central differences) plus the Earth rate; specific force unknown (NaN)",
            )]),
        )?;
        w.declare::<DepthV1>(
            topic::DEPTH,
            &note(&[(
                "source",
                "derived from the reference solution: depth = -alt_m of ref_NN.csv; not an independent pressure sensor",
            )]),
        )?;
        for (t, m) in &messages {
            match m {
                LogMessage::Imu(x) => w.write(t, x)?,
                LogMessage::Dvl(x) => w.write(t, x)?,
                LogMessage::Truth(x) => w.write(t, x)?,
                LogMessage::Depth(x) => w.write(t, x)?,
                _ => {}
            }
        }
        Ok(())
    })
    .map_err(crate::error::output(&a.out))?;
    Ok(summary)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_reference_rate_is_its_attitude_turning_plus_the_earth_rate() {
        // A reference turning at 0.1 rad/s in yaw, rolled 10°, at 0.5 rad latitude, 1 Hz.
        let (roll, lat) = (10f64.to_radians(), 0.5);
        let rows: Vec<[f64; 10]> = (0..5)
            .map(|k| {
                let t = k as f64;
                [t, 0.6, lat, -10.0, 1.0, 0.0, 0.0, roll, 0.0, 0.1 * t]
            })
            .collect();
        let rates = reference_rates(&rows);
        for (r, w) in rows.iter().zip(&rates) {
            let q = UnitQuaternion::from_euler_angles(r[7], r[8], r[9]);
            // A yaw rate about the vertical, seen in the rolled body axes.
            let w_eb = q.inverse() * nalgebra::Vector3::new(0.0, 0.0, 0.1);
            let w_ie = q.inverse() * auvnav_core::earth::earth_rate_ned(lat);
            let want = w_eb + w_ie;
            for k in 0..3 {
                assert!((w[k] - want[k]).abs() < 1e-9, "{w:?} against {want:?}");
            }
        }
        // Rows more than 2 s apart give no rate.
        let gap = [
            rows[0],
            [10.0, 0.6, lat, -10.0, 1.0, 0.0, 0.0, roll, 0.0, 1.0],
        ];
        assert!(reference_rates(&gap).iter().all(|w| w[0].is_nan()));
    }
}
