//! The PD0 decoder on real files: the samples in ../shared/protocols/rdi_pd0 against the values
//! their sources give, and the files in ../shared/data/rdi-pd0/raw against the independent
//! decoder dolfyn 1.3.0 (`decoded_by_dolfyn/*.csv`). Outside CI a missing ../shared is a skip
//! with a message; under CI it is a failure.
//!
//! Long on purpose: measured PD0 files against the vendor's export, field by field; the field
//! tables are most of it.

use auvnav_drivers::pd0::{self, Ensemble, NmeaBlock};
use std::collections::HashMap;
use std::path::PathBuf;

mod common;
use common::shared;

fn decode(path: &PathBuf) -> (Vec<Ensemble>, auvnav_drivers::framing::DecoderStats) {
    pd0::decode_all(&std::fs::read(path).expect("read"))
}

#[test]
fn whoi_sentry_samples_decode_to_the_values_of_their_upstream_test() {
    let Some(dir) = shared("protocols/rdi_pd0") else {
        return;
    };
    let (ens, stats) = decode(&dir.join("whoi_ds_sensors_pass.bin"));
    assert_eq!(ens.len(), 4, "{stats:?}");
    assert_eq!(stats.checksum_errors, 0);
    // ds_sensors test_rdidvl_parsing.cpp validParses: ensemble, heading, pitch, roll, temperature,
    // range beam 2, BT velocity x y z (mm/s in PD0).
    let expected = [
        (
            60493,
            349.30,
            1.53,
            0.46,
            2.17,
            223.01,
            [0.539, -0.465, 0.338],
        ),
        (
            60494,
            349.40,
            1.41,
            0.55,
            2.14,
            217.66,
            [0.542, -0.478, 0.343],
        ),
        (
            60495,
            349.56,
            1.16,
            0.58,
            2.16,
            220.33,
            [0.532, -0.484, 0.340],
        ),
        (
            60496,
            349.66,
            1.05,
            0.51,
            2.19,
            217.66,
            [0.537, -0.483, 0.339],
        ),
    ];
    for (e, x) in ens.iter().zip(expected) {
        let v = e.variable.as_ref().expect("variable leader");
        let bt = e.bottom_track.as_ref().expect("bottom track");
        assert_eq!(v.ensemble_number, x.0);
        assert!((v.heading_deg - x.1).abs() < 1e-9 && (v.pitch_deg - x.2).abs() < 1e-9);
        assert!((v.roll_deg - x.3).abs() < 1e-9 && (v.temperature_c - x.4).abs() < 1e-9);
        assert!((bt.range_m[1].expect("range") - x.5).abs() < 1e-9);
        assert_eq!(bt.range_m[2], None, "range 0 is no value");
        assert_eq!(
            bt.velocity_m_s[3], None,
            "-32768 is no value (3-beam solution)"
        );
        for i in 0..3 {
            assert!((bt.velocity_m_s[i].expect("velocity") - x.6[i]).abs() < 1e-12);
        }
        // The vehicle moves opposite to the recorded bottom velocity (ds_sensors negates too).
        let vv = bt.vehicle_velocity_m_s().expect("3 valid axes");
        assert!((vv[0] + x.6[0]).abs() < 1e-12);
    }
    let f = ens[0].fixed.as_ref().expect("fixed leader");
    assert_eq!((f.firmware_version, f.firmware_revision), (9, 23));
    assert_eq!(f.frequency_khz, Some(300));
    assert_eq!(f.beam_angle_deg, Some(30.0));
    assert_eq!(f.coordinate_system, pd0::CoordinateSystem::Instrument);
    let r = ens[0].bottom_track.as_ref().expect("bt").range_m;
    assert!((r[0].expect("r") - 182.92).abs() < 1e-9 && (r[3].expect("r") - 165.55).abs() < 1e-9);
}

#[test]
fn corrupted_and_invalid_samples_are_counted_not_published() {
    let Some(dir) = shared("protocols/rdi_pd0") else {
        return;
    };
    // The deliberately corrupted stream: nothing valid comes out, the errors are counted.
    let (ens, stats) = decode(&dir.join("whoi_ds_sensors_fail.bin"));
    // One of its ensembles has a valid checksum but a data-type offset outside the ensemble:
    // counted as malformed.
    assert!(ens.is_empty(), "{ens:?}");
    assert_eq!(stats.frames, 0, "{stats:?}");
    assert!(
        stats.checksum_errors >= 1 && stats.malformed == 1,
        "{stats:?}"
    );
    assert!(stats.resyncs >= 1 && stats.bytes_skipped > 0, "{stats:?}");
    // Bad sound speed: five checksum-valid ensembles, bottom track all invalid.
    let (ens, stats) = decode(&dir.join("whoi_ds_sensors_badsoundspeed.bin"));
    assert_eq!(ens.len(), 5, "{stats:?}");
    for e in &ens {
        if let Some(bt) = &e.bottom_track {
            assert!(bt.velocity_m_s.iter().all(Option::is_none));
            assert!(bt.range_m.iter().all(Option::is_none));
            assert!(bt.vehicle_velocity_m_s().is_none());
        }
    }
    // Glider: bottom track present but invalid.
    let (ens, _) = decode(&dir.join("ooi_ND072022.PD0"));
    let bt = ens[0].bottom_track.as_ref().expect("bt");
    assert!(bt.velocity_m_s.iter().all(Option::is_none) && bt.range_m.iter().all(Option::is_none));
    // Two good ensembles around a corrupted one.
    let (ens, stats) = decode(&dir.join("ooi_LB180210_3_corrupted.PD0"));
    assert_eq!(ens.len(), 2);
    assert_eq!(stats.checksum_errors, 1, "{stats:?}");
}

#[test]
fn pioneer_blocks_agree_with_the_standard_bottom_track() {
    let Some(dir) = shared("protocols/rdi_pd0") else {
        return;
    };
    let (ens, _) = decode(&dir.join("whoi_ds_sensors_pioneer.bin"));
    assert_eq!(ens.len(), 1);
    let e = &ens[0];
    let bt = e.bottom_track.as_ref().expect("0x0600");
    let hr = e.high_res_bottom_track.as_ref().expect("0x5803");
    let rng = e.bottom_track_range.as_ref().expect("0x5804");
    for i in 0..4 {
        // 0x5803 at 0.01 mm/s is the instrument's velocity: the negative of 0x0600 at 1 mm/s.
        let (lo, hi) = (
            bt.velocity_m_s[i].expect("v"),
            hr.instrument_velocity_m_s[i].expect("v"),
        );
        assert!((lo + hi).abs() <= 0.0005 + 1e-12, "beam {i}: {lo} vs {hi}");
        let (r0, r1) = (bt.range_m[i].expect("r"), rng.raw_range_m[i]);
        assert!((r0 - r1).abs() <= 0.005 + 1e-12, "beam {i}: {r0} vs {r1}");
    }
    assert_eq!(hr.sound_speed_m_s, Some(1500.0));
    assert!(
        e.other_ids.contains(&0x2013),
        "nav parameters skipped by offset"
    );
}

#[test]
fn ooi_auv_samples_decode_with_bottom_track_in_ship_coordinates() {
    let Some(dir) = shared("protocols/rdi_pd0") else {
        return;
    };
    for (file, n) in [("ooi_adcp_auv_3.pd0", 3), ("ooi_adcp_auv_51.pd0", 51)] {
        let (ens, stats) = decode(&dir.join(file));
        assert_eq!(ens.len(), n, "{file}: {stats:?}");
        for e in &ens {
            let f = e.fixed.as_ref().expect("fixed");
            assert_eq!(f.coordinate_system, pd0::CoordinateSystem::Ship, "{file}");
            assert_eq!((f.firmware_version, f.firmware_revision), (19, 13));
            assert!(e.bottom_track.is_some());
        }
    }
}

/// dolfyn's CSV: a comment line, a header, rows.
fn read_dolfyn(path: &PathBuf) -> Vec<HashMap<String, String>> {
    let text = std::fs::read_to_string(path).expect("csv");
    let mut lines = text.lines().filter(|l| !l.starts_with('#'));
    let header: Vec<String> = lines
        .next()
        .expect("header")
        .split(',')
        .map(String::from)
        .collect();
    lines
        .map(|l| {
            header
                .iter()
                .cloned()
                .zip(l.split(',').map(String::from))
                .collect()
        })
        .collect()
}

fn days_from_civil(y: i64, m: i64, d: i64) -> i64 {
    let y = if m <= 2 { y - 1 } else { y };
    let era = y.div_euclid(400);
    let yoe = y - era * 400;
    let doy = (153 * (m + if m > 2 { -3 } else { 9 }) + 2) / 5 + d - 1;
    let doe = yoe * 365 + yoe / 4 - yoe / 100 + doy;
    era * 146_097 + doe - 719_468
}

fn ensemble_time(e: &Ensemble) -> Option<f64> {
    let v = e.variable.as_ref()?;
    let [y, mo, d, h, mi, s, hs] = match v.rtc_y2k {
        Some(r) if r[0] >= 19 => [
            i64::from(r[0]) * 100 + i64::from(r[1]),
            r[2].into(),
            r[3].into(),
            r[4].into(),
            r[5].into(),
            r[6].into(),
            r[7].into(),
        ],
        _ => {
            let r = v.rtc;
            [
                2000 + i64::from(r[0]),
                r[1].into(),
                r[2].into(),
                r[3].into(),
                r[4].into(),
                r[5].into(),
                r[6].into(),
            ]
        }
    };
    Some((days_from_civil(y, mo, d) * 86400 + h * 3600 + mi * 60 + s) as f64 + hs as f64 * 0.01)
}

fn csv_time(s: &str) -> Option<f64> {
    // 2010-09-23T13:09:30.789
    let (date, time) = s.split_once('T')?;
    let mut d = date.split('-').map(|x| x.parse::<i64>().ok());
    let (y, m, dd) = (d.next()??, d.next()??, d.next()??);
    let mut t = time.split(':');
    let (h, mi): (i64, i64) = (t.next()?.parse().ok()?, t.next()?.parse().ok()?);
    let sec: f64 = t.next()?.parse().ok()?;
    Some((days_from_civil(y, m, dd) * 86400 + h * 3600 + mi * 60) as f64 + sec)
}

struct Comparison {
    rows: usize,
    matched: usize,
    fields: HashMap<&'static str, (usize, usize, f64)>, // compared, mismatched, worst diff
}

impl Comparison {
    /// Compares with `tol` plus the rounding of dolfyn's float32 output (one unit in the last
    /// place of a float32, 2^-23 relative).
    fn check(&mut self, name: &'static str, ours: Option<f64>, theirs: Option<&String>, tol: f64) {
        let Some(t) = theirs.and_then(|s| s.parse::<f64>().ok()) else {
            return;
        };
        let tol = tol + t.abs() * 2f64.powi(-23);
        let entry = self.fields.entry(name).or_insert((0, 0, 0.0));
        entry.0 += 1;
        let diff = match ours {
            Some(o) if t.is_nan() && o.is_nan() => 0.0,
            Some(_) if t.is_nan() => f64::INFINITY,
            Some(o) => (o - t).abs(),
            None if t.is_nan() => 0.0,
            None => f64::INFINITY,
        };
        if diff > tol {
            entry.1 += 1;
        }
        if diff.is_finite() {
            entry.2 = entry.2.max(diff);
        } else if diff.is_infinite() {
            entry.2 = f64::INFINITY;
        }
    }
}

/// The last GGA / VTG of an ensemble (dolfyn keeps the last one it reads).
fn last_gga(e: &Ensemble) -> Option<&NmeaBlock> {
    e.nmea
        .iter()
        .rev()
        .find(|b| matches!(b, NmeaBlock::Gga { .. }))
}
fn last_vtg(e: &Ensemble) -> Option<&NmeaBlock> {
    e.nmea
        .iter()
        .rev()
        .find(|b| matches!(b, NmeaBlock::Vtg { .. }))
}

// Long on purpose: compares every field of one measured PD0 file with the vendor's export, field by
// field in the file's order.
fn compare(file: &str) -> Comparison {
    let dir = shared("data/rdi-pd0").expect("checked by the caller");
    let (ens, _) = decode(&dir.join("raw").join(file));
    let rows = read_dolfyn(&dir.join("decoded_by_dolfyn").join(format!("{file}.csv")));
    // The declination dolfyn applied, from the comment line of its CSV when its userdata
    // side-car set one and the file is not in earth coordinates.
    let text = std::fs::read_to_string(dir.join("decoded_by_dolfyn").join(format!("{file}.csv")))
        .expect("csv");
    let first = text.lines().next().unwrap_or_default();
    let side_car = dir
        .join("raw")
        .join(std::path::Path::new(file).with_extension("userdata.json"));
    let heading_declination = (side_car.exists() && !first.contains("coord_sys=earth"))
        .then(|| {
            first
                .split("declination=")
                .nth(1)
                .and_then(|s| s.split_whitespace().next())
                .and_then(|s| s.parse::<f64>().ok())
        })
        .flatten();
    let mut c = Comparison {
        rows: rows.len(),
        matched: 0,
        fields: HashMap::new(),
    };
    let mut k = 0;
    for row in &rows {
        let Some(t) = row.get("time_utc").and_then(|s| csv_time(s)) else {
            continue;
        };
        while k < ens.len() && ensemble_time(&ens[k]).is_some_and(|x| x < t - 0.006) {
            k += 1;
        }
        let Some(e) = ens.get(k) else { break };
        if ensemble_time(e).is_none_or(|x| (x - t).abs() > 0.006) {
            continue;
        }
        c.matched += 1;
        let v = e.variable.as_ref();
        // dolfyn adds the declination of the userdata.json side-car to the heading of
        // files whose velocities are not in earth coordinates (not a PD0 field).
        let declination = heading_declination.unwrap_or(0.0);
        let heading = v.map(|v| (v.heading_deg + declination).rem_euclid(360.0));
        c.check("heading", heading, row.get("heading"), 1e-4);
        c.check("pitch", v.map(|v| v.pitch_deg), row.get("pitch"), 1e-4);
        c.check("roll", v.map(|v| v.roll_deg), row.get("roll"), 1e-4);
        c.check("depth", v.map(|v| v.depth_m), row.get("depth"), 1e-4);
        c.check("temp", v.map(|v| v.temperature_c), row.get("temp"), 1e-4);
        c.check(
            "c_sound",
            v.map(|v| v.sound_speed_m_s),
            row.get("c_sound"),
            1e-4,
        );
        // dolfyn reads the pressure as unsigned: a reading of -1 daPa at the surface becomes
        // 4294967.295 dbar there. We read it signed; compare modulo 2^32 daPa, within what
        // dolfyn's float32 arithmetic resolves at 4.3e6 (two units in the last place, 0.5 dbar).
        let wrap = 4_294_967.296;
        let raw = row.get("pressure").and_then(|s| s.parse::<f64>().ok());
        let wrapped = raw.is_some_and(|p| p > wrap / 2.0);
        let theirs = raw.map(|p| if wrapped { p - wrap } else { p });
        c.check(
            "pressure",
            v.and_then(|v| v.pressure_pa).map(|p| p * 1e-4),
            theirs.map(|p| p.to_string()).as_ref(),
            1e-4 + if wrapped { wrap * 2f64.powi(-22) } else { 0.0 },
        );

        if let Some(bt) = &e.bottom_track {
            let vel_cols: Vec<&String> = row.keys().filter(|k| k.starts_with("vel_bt_")).collect();
            let mut vel_cols: Vec<String> = vel_cols.into_iter().cloned().collect();
            // Column order as in the file: E N U err / X Y Z err / 1 2 3 4.
            vel_cols.sort_by_key(|c| {
                [
                    "_E_", "_X_", "_1_", "_N_", "_Y_", "_2_", "_U_", "_Z_", "_3_", "_err_", "_4_",
                ]
                .iter()
                .position(|p| c.contains(p))
                .map(|p| [0, 0, 0, 1, 1, 1, 2, 2, 2, 3, 3][p])
                .unwrap_or(9)
            });
            for (i, col) in vel_cols.iter().enumerate().take(4) {
                // dolfyn keeps -32.768 for "no value"; we return None.
                let ours = Some(bt.velocity_m_s[i].unwrap_or(-32.768));
                c.check("vel_bt", ours, row.get(col), 1e-4);
            }
            for i in 0..4 {
                let col = format!("dist_bt_beam{}_m", i + 1);
                c.check(
                    "dist_bt",
                    Some(bt.range_m[i].unwrap_or(0.0)),
                    row.get(&col),
                    1e-3,
                );
            }
        }
        if let Some(NmeaBlock::Gga {
            latitude_deg,
            longitude_deg,
            satellites,
            hdop,
            fix_quality,
            ..
        }) = last_gga(e)
        {
            c.check(
                "latitude_gps",
                Some(*latitude_deg),
                row.get("latitude_gps"),
                1e-6,
            );
            c.check(
                "longitude_gps",
                Some(*longitude_deg),
                row.get("longitude_gps"),
                1e-6,
            );
            c.check(
                "n_sat_gps",
                Some(f64::from(*satellites)),
                row.get("n_sat_gps"),
                0.0,
            );
            c.check(
                "hdop_gps",
                Some(f64::from(*hdop)),
                row.get("hdop_gps"),
                1e-6,
            );
            c.check(
                "fix_gps",
                Some(f64::from(*fix_quality)),
                row.get("fix_gps"),
                0.0,
            );
        }
        if let Some(NmeaBlock::Vtg {
            speed_over_ground_m_s,
            true_track_deg,
            ..
        }) = last_vtg(e)
        {
            // dolfyn divides knots by 1.944; we use 1852/3600 m/s per knot exactly (0.03 % apart).
            c.check(
                "speed_over_grnd_gps",
                Some(*speed_over_ground_m_s),
                row.get("speed_over_grnd_gps"),
                3e-4 * speed_over_ground_m_s.abs() + 1e-6,
            );
            c.check(
                "dir_over_grnd_gps",
                Some(f64::from(*true_track_deg)),
                row.get("dir_over_grnd_gps"),
                1e-4,
            );
        }
        if let Some(n) = &e.vmdas {
            c.check(
                "latitude_gps",
                Some(n.latitude_deg),
                row.get("latitude_gps"),
                1e-6,
            );
            c.check(
                "longitude_gps",
                Some(n.longitude_deg),
                row.get("longitude_gps"),
                1e-6,
            );
        }
        k += 1;
    }
    c
}

#[test]
fn every_raw_file_agrees_with_dolfyn() {
    let Some(_) = shared("data/rdi-pd0") else {
        return;
    };
    let files = [
        "RDI_7f79.000",
        "RDI_test01.000",
        "RDI_withBT.000",
        "RiverPro_test01.PD0",
        "vmdas01_wh.ENX",
        "vmdas02_os.ENR",
        "winriver01.PD0",
        "winriver02.PD0",
        "winriver02_transect.PD0",
    ];
    let mut failures = Vec::new();
    for f in files {
        let c = compare(f);
        let mut names: Vec<_> = c.fields.keys().copied().collect();
        names.sort();
        eprintln!(
            "{f}: {} of {} dolfyn rows matched by time",
            c.matched, c.rows
        );
        for n in names {
            let (total, bad, worst) = c.fields[n];
            eprintln!("    {n:20} {total:6} compared, {bad:4} differ, worst {worst:.3e}");
            if bad > 0 {
                failures.push(format!("{f} {n}: {bad} of {total} differ (worst {worst})"));
            }
        }
        if c.matched != c.rows {
            failures.push(format!(
                "{f}: only {} of {} rows matched",
                c.matched, c.rows
            ));
        }
    }
    assert!(failures.is_empty(), "{failures:#?}");
}

#[test]
fn newer_and_odd_files_are_handled_without_error() {
    let Some(dir) = shared("data/rdi-pd0/raw") else {
        return;
    };
    // Sentinel V with block IDs dolfyn 1.3.0 fails on: all skipped by offset.
    let (ens, stats) = decode(&dir.join("sentinelv_b5.pd0"));
    assert_eq!(ens.len(), 50, "{stats:?}");
    assert_eq!(stats.checksum_errors, 0);
    assert!(
        ens.iter()
            .all(|e| e.variable.is_some() && e.other_ids.contains(&0x7000))
    );
    // Files that start with a non-standard 7F 79 header: skipped until the first 7F 7F.
    let (ens, stats) = decode(&dir.join("RDI_7f79_2.000"));
    assert_eq!(ens.len(), 2, "{stats:?}");
    assert!(stats.bytes_skipped > 0);
    let (ens, _) = decode(&dir.join("RDI_7f79.000"));
    assert_eq!(ens.len(), 60);
}

/// A body-frame (forward, starboard, down) vector in north-east-down for roll, pitch, yaw (rad):
/// `Rz(yaw) Ry(pitch) Rx(roll) v`.
fn body_to_ned(v: [f64; 3], roll: f64, pitch: f64, yaw: f64) -> [f64; 3] {
    let (sr, cr) = roll.sin_cos();
    let (sp, cp) = pitch.sin_cos();
    let (sy, cy) = yaw.sin_cos();
    let [x, y, z] = v;
    let (y1, z1) = (cr * y - sr * z, sr * y + cr * z);
    let (x2, z2) = (cp * x + sp * z1, -sp * x + cp * z1);
    [cy * x2 - sy * y1, sy * x2 + cy * y1, z2]
}

/// Beam coordinates against GPS: the RiverPro file records bottom track per beam (20° convex
/// head, down-looking) with the boat's GPS (VTG). Each ensemble's velocity from the beams
/// (`beam_to_instrument` through the driver's conversion), rotated to north-east by the
/// ensemble's heading, pitch and roll, must give the GPS speed over ground and, within the
/// magnetic declination and the compass, its course: a wrong sign or beam order shows as a
/// course off by 90–180° or a speed off by the beam geometry.
#[test]
fn beam_coordinates_give_the_gps_speed_and_course() {
    use auvnav_drivers::to_schema::pd0_velocity;
    use auvnav_shm_schema::DvlVelocityV1;
    let Some(dir) = shared("data/rdi-pd0/raw") else {
        return;
    };
    let (ens, _) = decode(&dir.join("RiverPro_test01.PD0"));
    let (mut ratios, mut course_diffs, mut three_beam) = (Vec::new(), Vec::new(), 0);
    for e in &ens {
        let (Some(v), Some(m)) = (&e.variable, pd0_velocity(e, 0, 0.0, 0)) else {
            continue;
        };
        let Some(NmeaBlock::Vtg {
            true_track_deg,
            speed_over_ground_m_s,
            ..
        }) = last_vtg(e)
        else {
            continue;
        };
        if m.validity & DvlVelocityV1::VALID_VELOCITY == 0 || *speed_over_ground_m_s < 0.5 {
            continue;
        }
        three_beam += usize::from(m.validity & DvlVelocityV1::VALID_FOM == 0);
        let ned = body_to_ned(
            m.velocity_dvl_m_s,
            v.roll_deg.to_radians(),
            v.pitch_deg.to_radians(),
            v.heading_deg.to_radians(),
        );
        let speed = ned[0].hypot(ned[1]);
        let course = ned[1].atan2(ned[0]).to_degrees();
        ratios.push(speed / speed_over_ground_m_s);
        course_diffs.push((course - f64::from(*true_track_deg) + 540.0).rem_euclid(360.0) - 180.0);
    }
    let median = |v: &mut Vec<f64>| {
        v.sort_by(f64::total_cmp);
        v[v.len() / 2]
    };
    let n = ratios.len();
    let (r, c) = (median(&mut ratios), median(&mut course_diffs));
    eprintln!(
        "RiverPro beam coordinates: {n} ensembles above 0.5 m/s ({three_beam} three-beam): \
         speed / GPS median {r:.4}, course − GPS median {c:.1}°"
    );
    assert!(n > 150, "{n}");
    assert!((r - 1.0).abs() < 0.03, "speed ratio {r}");
    // The ADCP's magnetic heading against the GPS's true course: the median difference is the
    // declination and the compass's error (the file sets no heading bias), well inside ±30°; a
    // sign or beam-order error gives 90–180°.
    assert!(c.abs() < 30.0, "course difference {c}°");
}

/// Earth coordinates on a measured file: RDI_withBT records bottom track in east, north, up
/// (EX bits earth, tilts used). Every ensemble with a full bottom track is published, rotated back
/// to the instrument with its own heading, pitch and roll: a rotation keeps the speed, and the
/// error velocity stands as the figure of merit. (The instrument sits still in this file, so the
/// rotation's direction is tested on synthesised ensembles and through the driver on a pty.)
#[test]
fn earth_coordinates_are_rotated_back_on_a_measured_file() {
    use auvnav_drivers::pd0::CoordinateSystem;
    use auvnav_drivers::to_schema::pd0_velocity;
    use auvnav_shm_schema::DvlVelocityV1;
    let Some(dir) = shared("data/rdi-pd0/raw") else {
        return;
    };
    let (ens, _) = decode(&dir.join("RDI_withBT.000"));
    let (mut full, mut published) = (0, 0);
    for e in &ens {
        assert_eq!(
            e.fixed.as_ref().map(|f| f.coordinate_system),
            Some(CoordinateSystem::Earth)
        );
        let Some(bt) = &e.bottom_track else { continue };
        let [Some(east), Some(north), Some(up), Some(err)] = bt.velocity_m_s else {
            continue;
        };
        full += 1;
        let m = pd0_velocity(e, 0, 0.0, 0).expect("a DVL message");
        assert_ne!(m.validity & DvlVelocityV1::VALID_VELOCITY, 0);
        published += 1;
        let v = m.velocity_dvl_m_s;
        let speed = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
        let earth = (east * east + north * north + up * up).sqrt();
        assert!((speed - earth).abs() < 1e-9, "{speed} against {earth}");
        assert_eq!(m.figure_of_merit_m_s, err.abs());
    }
    eprintln!("RDI_withBT: {published} of {full} full bottom-track ensembles published");
    assert!(full > 100, "{full}");
    assert_eq!(published, full);
}
