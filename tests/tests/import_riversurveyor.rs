//! `auvnav import riversurveyor` on the measured SonTek RiverSurveyor M9 lake runs: the MAT reader
//! against an independent reader's decode of the same files (scipy), the import's frames against
//! that decode (the bottom track rotated into the instrument frame and back gives the file's
//! earth-frame velocity), and the import's time base against the GPS (the bottom track and the
//! GPS velocity over ground agree to the centimetre per second only if the two clocks and the
//! sign are right).

use auvnav_log::{LogMessage, LogReader};
use auvnav_tests::processes::{TempDir, binary};
use auvnav_tools::import::mat5::{self, MatValue};
use nalgebra::{UnitQuaternion, Vector3};
use std::path::Path;
use std::process::Command;

const RUNS: [&str; 2] = ["20250117160335.mat", "20250117160238.mat"];

/// scipy's decode of `file` (tests/python/read_mat.py), or why it is not available.
fn scipy_decode(file: &Path) -> Result<serde_json::Value, String> {
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("python/read_mat.py");
    let o = Command::new("python3")
        .arg(&script)
        .arg(file)
        .output()
        .map_err(|e| format!("python3 not runnable: {e}"))?;
    if !o.status.success() {
        return Err(format!(
            "read_mat.py failed (is scipy installed?): {}",
            String::from_utf8_lossy(&o.stderr)
        ));
    }
    serde_json::from_slice(&o.stdout).map_err(|e| format!("read_mat.py output: {e}"))
}

fn scipy_or_skip(file: &Path) -> Option<serde_json::Value> {
    match scipy_decode(file) {
        Ok(v) => Some(v),
        Err(why) if std::env::var("CI").is_ok_and(|v| v == "true") => {
            panic!("under CI the independent reader must run: {why}")
        }
        Err(why) => {
            eprintln!("SKIPPED: {why} (pip install scipy)");
            None
        }
    }
}

/// Every numeric and character array of the file's structs, by dotted path, as our reader
/// decodes it.
fn ours(
    value: &MatValue,
    path: &str,
    numeric: &mut Vec<(String, Vec<usize>, Vec<f64>)>,
    chars: &mut Vec<(String, String)>,
) {
    match value {
        MatValue::Struct {
            fields, elements, ..
        } if elements.len() == 1 => {
            for (f, v) in fields.iter().zip(&elements[0]) {
                ours(v, &format!("{path}.{f}"), numeric, chars);
            }
        }
        MatValue::Numeric { dims, data, .. } => {
            numeric.push((path.to_string(), dims.clone(), data.clone()))
        }
        MatValue::Char { text, .. } => chars.push((path.to_string(), text.clone())),
        other => panic!("{path}: {other:?} is not read by the reference decode"),
    }
}

#[test]
fn the_mat_reader_agrees_with_scipy_on_every_array_of_the_measured_exports() {
    let Some(dir) = auvnav_tests::measured_data("riversurveyor-m9", RUNS[0]) else {
        return;
    };
    for run in RUNS {
        let file = dir.join(run);
        let Some(reference) = scipy_or_skip(&file) else {
            return;
        };
        let bytes = std::fs::read(&file).expect("read");
        let m = mat5::parse(&bytes).expect("parse");
        assert_eq!(
            m.header,
            reference["header"].as_str().expect("header").trim_end()
        );
        let (mut numeric, mut chars) = (Vec::new(), Vec::new());
        for (name, v) in &m.variables {
            ours(v, name, &mut numeric, &mut chars);
        }
        let theirs = reference["numeric"].as_object().expect("numeric");
        assert_eq!(
            numeric.len(),
            theirs.len(),
            "{run}: number of numeric arrays"
        );
        let mut values = 0usize;
        for (path, dims, data) in &numeric {
            let t = &theirs[path.as_str()];
            let t_dims: Vec<usize> = serde_json::from_value(t["dims"].clone()).expect("dims");
            assert_eq!(dims, &t_dims, "{run}: {path} dimensions");
            let t_values = t["values"].as_array().expect("values");
            assert_eq!(data.len(), t_values.len(), "{run}: {path}");
            for (i, (a, b)) in data.iter().zip(t_values).enumerate() {
                match b.as_f64() {
                    Some(b) => assert_eq!(
                        a.to_bits(),
                        b.to_bits(),
                        "{run}: {path}[{i}]: {a} against {b}"
                    ),
                    None => assert!(a.is_nan(), "{run}: {path}[{i}]: {a} against NaN"),
                }
                values += 1;
            }
        }
        let t_chars = reference["char"].as_object().expect("char");
        assert_eq!(
            chars.len(),
            t_chars.len(),
            "{run}: number of character arrays"
        );
        for (path, text) in &chars {
            assert_eq!(
                Some(text.as_str()),
                t_chars[path.as_str()].as_str(),
                "{run}: {path}"
            );
        }
        assert!(values > 10_000, "{run}: {values} values compared");
    }
}

struct Imported {
    summary: serde_json::Value,
    /// (time ns, instrument-frame velocity)
    dvl: Vec<(u64, [f64; 3])>,
    /// (time ns, body-to-NED attitude, NED velocity over ground)
    truth: Vec<(u64, UnitQuaternion<f64>, [f64; 3])>,
    gnss: usize,
}

fn import(file: &Path, out: &Path, velocity: &str) -> Imported {
    let o = Command::new(binary("auvnav"))
        .args(["import", "riversurveyor"])
        .arg(file)
        .arg("--out")
        .arg(out)
        .args(["--velocity", velocity, "--json"])
        .output()
        .expect("running auvnav import riversurveyor");
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let summary: serde_json::Value = serde_json::from_slice(&o.stdout).expect("JSON");
    let mut r = LogReader::open(out).expect("open");
    r.read_header().expect("header");
    let mut imported = Imported {
        summary,
        dvl: Vec::new(),
        truth: Vec::new(),
        gnss: 0,
    };
    let mut last = 0u64;
    while let Some(raw) = r.next_message().expect("read") {
        let t = match raw.decode_any().expect("decode") {
            LogMessage::Dvl(d) => {
                imported.dvl.push((d.validity_time_ns, d.velocity_dvl_m_s));
                d.host_time_ns
            }
            LogMessage::Truth(x) => {
                let [w, i, j, k] = x.quaternion_body_to_ned;
                let q = UnitQuaternion::from_quaternion(nalgebra::Quaternion::new(w, i, j, k));
                imported.truth.push((x.host_time_ns, q, x.velocity_ned_m_s));
                x.host_time_ns
            }
            LogMessage::Gnss(g) => {
                imported.gnss += 1;
                g.host_time_ns
            }
            _ => continue,
        };
        assert!(t >= last, "messages out of time order");
        last = t;
    }
    imported
}

fn column(reference: &serde_json::Value, path: &str) -> Vec<f64> {
    reference["numeric"][path]["values"]
        .as_array()
        .unwrap_or_else(|| panic!("{path} in the reference decode"))
        .iter()
        .map(|v| v.as_f64().unwrap_or(f64::NAN))
        .collect()
}

#[test]
fn the_imported_bottom_track_is_the_files_velocity_and_agrees_with_the_gps_over_ground() {
    let Some(dir) = auvnav_tests::measured_data("riversurveyor-m9", RUNS[0]) else {
        return;
    };
    let tmp = TempDir::new("riversurveyor");
    let mut offsets = Vec::new();
    for run in RUNS {
        let file = dir.join(run);
        let Some(reference) = scipy_or_skip(&file) else {
            return;
        };
        let n = column(&reference, "System.Time").len();
        let bt = column(&reference, "BottomTrack.BT_Vel");
        let out = tmp.path().join(run.replace(".mat", ".mcap"));
        let imp = import(&file, &out, "gga");
        let s = &imp.summary;
        assert_eq!(s["samples"], n as u64, "{s}");
        assert_eq!(imp.dvl.len(), n, "{s}");
        assert!(
            imp.gnss > 9 * n / 2,
            "{run}: {} GNSS fixes for {n} samples",
            imp.gnss
        );
        offsets.push(s["adcp_clock_minus_utc_s"].as_f64().expect("offset"));
        // Instrument frame and back with the reference's attitude: the file's earth-frame
        // velocity, negated (the boat's), to rounding.
        let mut paired = 0;
        let (mut sum, mut count) = (0.0, 0usize);
        for (row, (t, v)) in imp.dvl.iter().enumerate() {
            let Some((_, q, over_ground)) = imp.truth.iter().find(|x| x.0 == *t) else {
                continue;
            };
            let ned = q * Vector3::from(*v);
            let file_enu = [bt[row], bt[row + n], bt[row + 2 * n]];
            assert!(
                (ned.y + file_enu[0]).abs() < 1e-9
                    && (ned.x + file_enu[1]).abs() < 1e-9
                    && (ned.z - file_enu[2]).abs() < 1e-9,
                "{run} sample {row}: {ned:?} against the file's {file_enu:?}"
            );
            paired += 1;
            sum += (ned.x - over_ground[0]).powi(2) + (ned.y - over_ground[1]).powi(2);
            count += 2;
        }
        assert!(
            paired * 10 > n * 8,
            "{run}: {paired} of {n} samples have a reference"
        );
        let rms = (sum / count as f64).sqrt();
        eprintln!(
            "{run}: bottom track against GPS over ground, rms {rms:.4} m/s per axis ({paired} samples)"
        );
        // Measured 0.021 (zig-zag run) and 0.006 m/s (drifting); a sign error gives the boat's
        // speed twice over (1.7 m/s), a clock off by one sample interval 0.04 m/s.
        assert!(rms < 0.03, "{run}: rms {rms} m/s");
    }
    // A third-party MCAP reader decodes the new attitude channel with the others.
    let last = tmp.path().join(RUNS[1].replace(".mat", ".mcap"));
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("python/read_log.py");
    match Command::new("python3").arg(&script).arg(&last).output() {
        Ok(o) if o.status.success() => {
            // Python writes the reference's unknown rates as NaN, which JSON has no word for.
            let text = String::from_utf8_lossy(&o.stdout).replace("NaN", "null");
            let v: serde_json::Value = serde_json::from_str(&text).expect("JSON");
            for topic in ["attitude", "dvl", "gnss", "truth"] {
                assert!(
                    v["messages"][topic].as_u64().unwrap_or(0) > 0,
                    "{topic}: {v}"
                );
            }
            assert!(v["first"]["attitude"]["euler_rad"].is_array(), "{v}");
        }
        o if std::env::var("CI").is_ok_and(|v| v == "true") => {
            panic!("under CI the Python MCAP reader must run: {o:?}")
        }
        _ => eprintln!("SKIPPED: the Python MCAP reader (pip install mcap mcap-ros2-support)"),
    }
    // The two runs, a minute apart on one ADCP, find the same clock relation.
    assert!(
        (offsets[0] - offsets[1]).abs() < 0.05,
        "ADCP clock minus UTC: {offsets:?}"
    );
}

#[test]
fn a_truncated_or_foreign_file_is_refused_with_the_reason() {
    let Some(dir) = auvnav_tests::measured_data("riversurveyor-m9", RUNS[1]) else {
        return;
    };
    let tmp = TempDir::new("riversurveyor-bad");
    let bytes = std::fs::read(dir.join(RUNS[1])).expect("read");
    let cases: [(&str, Vec<u8>, &str); 3] = [
        ("cut.mat", bytes[..bytes.len() / 2].to_vec(), "claims"),
        ("text.mat", b"time,lat,lon\n1,2,3\n".repeat(20), "MAT"),
        (
            "otherdata.mat",
            {
                // A valid MAT file without the RiverSurveyor structs: the header and the first
                // variable (Setup) only, cut at a variable boundary.
                let m = mat5::parse(&bytes).expect("parse");
                assert!(m.get("Setup").is_some());
                bytes[..128].to_vec()
            },
            "coordinateSystem",
        ),
    ];
    for (name, data, expected) in cases {
        let p = tmp.path().join(name);
        std::fs::write(&p, data).expect("write");
        let out = tmp.path().join("x.mcap");
        let o = Command::new(binary("auvnav"))
            .args(["import", "riversurveyor"])
            .arg(&p)
            .arg("--out")
            .arg(&out)
            .output()
            .expect("run");
        let err = String::from_utf8_lossy(&o.stderr);
        assert!(!o.status.success(), "{name}: accepted");
        assert!(err.contains(expected), "{name}: {err}");
        assert!(!err.contains("panicked"), "{name}: {err}");
        assert!(!out.exists(), "{name}: a log was left behind");
    }
    // Bytes changed anywhere in the file: read or refused, never a panic.
    let mut bits = auvnav_tests::Bits(0x005e_ed0f_5047);
    for _ in 0..300 {
        let mut b = bytes.clone();
        for _ in 0..1 + bits.next_u64() % 4 {
            let i = (bits.next_u64() % b.len() as u64) as usize;
            b[i] = bits.next_u64() as u8;
        }
        if let Ok(m) = mat5::parse(&b) {
            let _ = auvnav_tools::import::riversurveyor_messages(
                &m,
                auvnav_tools::import::GpsVelocity::Auto,
                1.0,
            );
        }
    }
}
