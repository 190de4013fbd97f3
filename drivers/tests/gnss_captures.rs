//! Real GNSS receivers' output (gpsd's regression captures, `captures/gpsd/SOURCE.md`) through
//! the GNSS driver's decoder: every fix gpsd decodes from the same bytes comes out with the same
//! time, position and height, and nothing is counted as damaged.

use auvnav_drivers::device::{DeviceDecoder, Output, Protocol, ProtocolSettings};
use auvnav_drivers::gnss::{GPS_EPOCH_UNIX_S, GPS_MINUS_UTC_S};
use auvnav_shm_schema::GnssFixV1;
use std::path::PathBuf;

fn capture(name: &str) -> Vec<u8> {
    let path = PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("tests/captures/gpsd")
        .join(name);
    let bytes = std::fs::read(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    // gpsd's logs open with `#` comment lines; the device's bytes follow.
    let mut start = 0;
    while bytes[start..].starts_with(b"#") {
        start += bytes[start..]
            .iter()
            .position(|&b| b == b'\n')
            .expect("a value")
            + 1;
    }
    bytes[start..].to_vec()
}

/// The fixes of a capture, read in pieces of `read` bytes 0.1 s apart.
fn fixes(protocol: Protocol, bytes: &[u8], read: usize) -> (Vec<GnssFixV1>, DeviceDecoder) {
    let mut d = DeviceDecoder::new(protocol, ProtocolSettings::default());
    let mut out = Vec::new();
    for (i, chunk) in bytes.chunks(read).enumerate() {
        d.push(chunk);
        while let Some(o) = d.next_output(1_000_000_000 + i as u64 * 100_000_000) {
            match o {
                Output::Gnss(f) => out.push(f),
                other => panic!("{other:?}"),
            }
        }
    }
    (out, d)
}

struct Reference {
    utc: String,
    latitude_deg: f64,
    longitude_deg: f64,
    height_m: Option<f64>,
}

fn reference(name: &str) -> Vec<Reference> {
    let path = PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("tests/captures/gpsd")
        .join(name);
    std::fs::read_to_string(path)
        .expect("a value")
        .lines()
        .skip(1)
        .map(|l| {
            let f: Vec<&str> = l.split(',').collect();
            Reference {
                utc: f[0].to_string(),
                latitude_deg: f[1].parse().expect("a value"),
                longitude_deg: f[2].parse().expect("a value"),
                height_m: f[3].parse().ok(),
            }
        })
        .collect()
}

fn utc(f: &GnssFixV1) -> String {
    assert_ne!(f.validity & GnssFixV1::VALID_DEVICE_TIME, 0, "{f:?}");
    let unix_ns = f.device_time_ns as i64 + GPS_EPOCH_UNIX_S * 1_000_000_000
        - i64::from(GPS_MINUS_UTC_S) * 1_000_000_000;
    chrono::DateTime::from_timestamp_nanos(unix_ns)
        .to_rfc3339_opts(chrono::SecondsFormat::Millis, true)
}

/// Every fix gpsd reports is among ours, at the same time; ours may have more at the ends of
/// the capture (`extra_at_ends`), where gpsd waits for a reporting cycle to complete.
fn compare(ours: &[GnssFixV1], gpsd: &[Reference], extra_at_ends: usize) {
    let times: Vec<String> = ours.iter().map(utc).collect();
    let first = times
        .iter()
        .position(|t| *t == gpsd[0].utc)
        .expect("gpsd's first fix");
    assert!(first + gpsd.len() <= ours.len(), "{times:?}");
    assert_eq!(ours.len() - gpsd.len(), extra_at_ends, "{times:?}");
    for (f, r) in ours[first..].iter().zip(gpsd) {
        assert_eq!(utc(f), r.utc);
        assert!(
            (f.latitude_rad.to_degrees() - r.latitude_deg).abs() < 1e-8,
            "{}",
            r.utc
        );
        assert!(
            (f.longitude_rad.to_degrees() - r.longitude_deg).abs() < 1e-8,
            "{}",
            r.utc
        );
        if let Some(h) = r.height_m {
            assert_ne!(f.validity & GnssFixV1::VALID_HEIGHT, 0);
            assert!(
                (f.height_m - h).abs() < 1e-6,
                "{} {} {h}",
                r.utc,
                f.height_m
            );
        }
    }
}

#[test]
fn a_u_blox_neo_m8n_in_ubx_gives_gpsds_fixes() {
    let bytes = capture("ublox-neo-m8n.log");
    let gpsd = reference("ublox-neo-m8n.gpsd-tpv.csv");
    for read in [1, 61, 4096] {
        let (ours, d) = fixes(Protocol::Ubx, &bytes, read);
        // gpsd reports one fix per time; the capture repeats no NAV-PVT time.
        // gpsd starts one NAV-PVT late and ends one early.
        compare(&ours, &gpsd, 2);
        for f in &ours {
            assert!(
                f.horizontal_std_m > 0.5 && f.horizontal_std_m < 5.0,
                "{f:?}"
            );
            assert!(f.satellites >= 4);
        }
        let s = d.stats();
        // The capture starts with a line end and the last two bytes of a message cut by its
        // start (the line end counts with them when one read brings both).
        assert_eq!((s.checksum_errors, s.malformed), (0, 0));
        assert!((2..=3).contains(&s.bytes_skipped), "read {read}: {s:?}");
        assert_eq!(ours.len(), 24);
        assert_eq!(d.counters().no_fix, 0);
    }
}

#[test]
fn a_u_blox_zed_f9p_in_nmea_gives_gpsds_fixes_with_gst_deviations() {
    let bytes = capture("ublox-zed-f9p-nmea.log");
    let gpsd = reference("ublox-zed-f9p-nmea.gpsd-tpv.csv");
    for read in [1, 100, 65536] {
        let (mut ours, mut d) = fixes(Protocol::Nmea, &bytes, read);
        // The last epoch ends with the capture: one more sentence of another time closes it.
        d.push(b"$GNGGA,235959.00,,,,,0,00,99.99,,,,,,*79\r\n");
        while let Some(Output::Gnss(f)) = d.next_output(0) {
            ours.push(f);
        }
        compare(&ours, &gpsd, 0);
        // GST 2.3 m and 3.5 m in latitude and longitude, 4.0 m in altitude.
        let first = &ours[0];
        assert!(
            (first.horizontal_std_m - ((2.3f64.powi(2) + 3.5f64.powi(2)) / 2.0).sqrt()).abs()
                < 1e-9
        );
        assert_eq!(first.vertical_std_m, 4.0);
        assert_eq!(first.satellites, 12);
        let s = d.stats();
        assert_eq!((s.checksum_errors, s.malformed, s.bytes_skipped), (0, 0, 0));
    }
}

#[test]
fn a_2d_fix_has_no_height_and_its_large_deviations_are_kept() {
    let bytes = capture("polarx2.log");
    let (ours, d) = fixes(Protocol::Nmea, &bytes, 37);
    // Five epochs; from the second on, the receiver's sentence set is known and an epoch ends
    // at its last sentence.
    assert_eq!(ours.len(), 5);
    let f = &ours[0];
    assert_eq!(f.validity & GnssFixV1::VALID_HEIGHT, 0);
    assert!((f.latitude_rad.to_degrees() - 38.737_335_167).abs() < 1e-8);
    assert!((f.longitude_rad.to_degrees() + 9.140_638).abs() < 1e-8);
    assert!(
        (f.horizontal_std_m - ((317.563f64.powi(2) + 10.659f64.powi(2)) / 2.0).sqrt()).abs() < 1e-9
    );
    assert_eq!(utc(f), "2012-03-22T11:22:57.000Z");
    // Speed 0.1 kn on course 339.1 deg.
    assert_ne!(f.validity & GnssFixV1::VALID_VELOCITY, 0);
    assert_eq!(d.stats().checksum_errors, 0);
}
