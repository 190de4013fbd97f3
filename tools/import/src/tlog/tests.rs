//! Tests of the tlog import on telemetry written here with the `mavlink` crate's encoder (the
//! Python package's own writer is the integration test's).

use super::*;
use auvnav_protocols::autopilot::G0;
use mavlink::dialects::ardupilotmega as mav;
use mavlink::{MavHeader, MavlinkVersion};

/// A tlog being written: records of a receive time and a frame.
struct Tlog(Vec<u8>);

impl Tlog {
    fn record(&mut self, received_us: u64, version: MavlinkVersion, m: &MavMessage) {
        self.0.extend(received_us.to_be_bytes());
        let header = MavHeader {
            system_id: 1,
            component_id: 1,
            sequence: 0,
        };
        mavlink::write_versioned_msg(&mut self.0, version, header, m).expect("encode");
    }
}

const UNIX0_US: u64 = 1_733_436_754_000_000;
const DEPTH_M: f64 = 5.0;

/// 20 s of a vehicle at rest, level and heading north, 5 m deep: IMU at 50 Hz, pressure and
/// attitude at 10 Hz, GPS at 5 Hz, each frame received 3–22 ms after the autopilot's clock; the
/// autopilot boots again after 10 s. With a v1 frame, a damaged checksum and garbage between
/// records.
fn telemetry() -> (Vec<u8>, usize) {
    let mut t = Tlog(Vec::new());
    let mut garbage = 0;
    for k in 0..1000u32 {
        // Boot clock (ms): 60 s at the start, 0.5 s after the reboot at k = 500.
        let boot_ms = if k < 500 {
            60_000 + 20 * k
        } else {
            500 + 20 * (k - 500)
        };
        let delay_us = 3_000 + u64::from(k * 7919 % 19) * 1000;
        let received = UNIX0_US + u64::from(20 * k) * 1000 + delay_us;
        let imu = MavMessage::SCALED_IMU(mav::SCALED_IMU_DATA {
            time_boot_ms: boot_ms,
            zacc: -1000,
            xmag: 200,
            zmag: 450,
            ..Default::default()
        });
        let version = if k == 7 {
            MavlinkVersion::V1
        } else {
            MavlinkVersion::V2
        };
        if k == 100 {
            // A damaged frame: the checksum's last byte changed.
            let start = t.0.len();
            t.record(received, version, &imu);
            let last = t.0.len() - 1;
            t.0[last] ^= 0x5a;
            assert!(t.0.len() > start);
            continue;
        }
        t.record(received, version, &imu);
        if k == 300 {
            t.0.extend([0xFD, 0x01, 0x02, 0xFE, 0x00]);
            garbage += 5;
        }
        if k % 5 == 0 {
            let press_abs = 1013.25 + DEPTH_M * 1025.0 * G0 / 100.0;
            t.record(
                received + 100,
                MavlinkVersion::V2,
                &MavMessage::SCALED_PRESSURE2(mav::SCALED_PRESSURE2_DATA {
                    time_boot_ms: boot_ms,
                    press_abs: if k == 0 { 1013.25 } else { press_abs as f32 },
                    temperature: 1250,
                    ..Default::default()
                }),
            );
            t.record(
                received + 200,
                MavlinkVersion::V2,
                &MavMessage::ATTITUDE(mav::ATTITUDE_DATA {
                    time_boot_ms: boot_ms,
                    yaw: if k == 40 { f32::NAN } else { 0.1 },
                    ..Default::default()
                }),
            );
        }
        if k % 10 == 0 {
            t.record(
                received + 300,
                MavlinkVersion::V2,
                &MavMessage::GPS_RAW_INT(mav::GPS_RAW_INT_DATA {
                    time_usec: UNIX0_US + u64::from(20 * k) * 1000,
                    fix_type: if k == 20 {
                        mav::GpsFixType::GPS_FIX_TYPE_2D_FIX
                    } else {
                        mav::GpsFixType::GPS_FIX_TYPE_3D_FIX
                    },
                    lat: 475_000_000,
                    lon: -1_223_000_000,
                    alt_ellipsoid: -20_000,
                    eph: 120,
                    epv: 200,
                    satellites_visible: 11,
                    ..Default::default()
                }),
            );
        }
    }
    (t.0, garbage)
}

fn import(bytes: &[u8], name: &str) -> (Vec<(&'static str, LogMessage)>, TlogSummary) {
    let dir = std::env::temp_dir().join(format!("auvnav-tlog-{}-{name}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("dir");
    let path = dir.join("t.tlog");
    std::fs::write(&path, bytes).expect("write");
    let r = tlog_messages(&TlogOptions::new(path, dir.join("t.mcap")));
    let _ = std::fs::remove_dir_all(&dir);
    r.expect("import")
}

#[test]
fn telemetry_becomes_sensor_channels_on_the_autopilots_clock() {
    let (bytes, garbage) = telemetry();
    let (messages, s) = import(&bytes, "good");
    assert_eq!(s.bad_checksum, 1);
    assert_eq!(s.bytes_skipped, garbage);
    assert_eq!(s.autopilot_boots, 2);
    assert_eq!(s.imu_source, "SCALED_IMU");
    assert_eq!((s.imu, s.magnetometer), (999, 999));
    // Of 200 pressure and attitude readings, those of the damaged record's cycle were not
    // written; the first pressure reading is the surface; an attitude with a NaN yaw is left out.
    assert_eq!((s.depth, s.attitude, s.implausible), (199, 198, 1));
    assert_eq!((s.gnss, s.gnss_without_fix), (98, 1));
    assert_eq!(s.by_message.get("SCALED_IMU"), Some(&999));
    assert!((s.surface_pressure_hpa - 1013.25).abs() < 1e-4);
    // From the first IMU sample to the last, 20 ms apart across the reboot.
    assert!((s.duration_s - 19.98).abs() < 1e-3, "{}", s.duration_s);
    assert!((s.start_unix_s - (UNIX0_US + 3000) as f64 * 1e-6).abs() < 1e-6);

    let imu: Vec<ImuSampleV1> = messages
        .iter()
        .filter_map(|(_, m)| match m {
            LogMessage::Imu(x) => Some(*x),
            _ => None,
        })
        .collect();
    let x = imu[10];
    assert_eq!(x.specific, [0.0, 0.0, -G0]);
    assert_eq!(x.angular, [0.0; 3]);
    assert_eq!(x.device_time_ns, 60_200_000_000);
    // Within a boot the samples keep the autopilot's spacing (20 ms), not the link's jitter;
    // the smallest delay (3 ms) places them.
    for w in imu[..450].windows(2) {
        let dt = w[1].host_time_ns - w[0].host_time_ns;
        assert!(dt == 20_000_000 || dt == 40_000_000, "{dt}");
        assert!((w[1].interval_s - dt as f64 * 1e-9).abs() < 1e-12);
    }
    assert_eq!(imu[0].host_time_ns, 0);
    assert!(imu.windows(2).all(|w| w[1].sequence == w[0].sequence + 1));
    // After the reboot, placed by its own delay: still 20 ms after the last sample before it.
    let reboot = imu.iter().position(|x| x.device_time_ns < 1_000_000_000);
    let r = reboot.expect("a sample after the reboot");
    assert_eq!(imu[r].host_time_ns - imu[r - 1].host_time_ns, 20_000_000);

    let depth: Vec<f64> = messages
        .iter()
        .filter_map(|(_, m)| match m {
            LogMessage::Depth(x) => Some(x.depth_m),
            _ => None,
        })
        .collect();
    assert_eq!(depth[0], 0.0);
    assert!(
        depth[1..].iter().all(|d| (d - DEPTH_M).abs() < 2e-3),
        "{depth:?}"
    );
    let g = messages
        .iter()
        .find_map(|(_, m)| match m {
            LogMessage::Gnss(x) => Some(*x),
            _ => None,
        })
        .expect("a fix");
    assert!((g.latitude_rad.to_degrees() - 47.5).abs() < 1e-9);
    assert!((g.longitude_rad.to_degrees() + 122.3).abs() < 1e-9);
    assert_eq!(g.height_m, -20.0);
    assert!((g.horizontal_std_m - 3.0).abs() < 1e-12 && (g.vertical_std_m - 5.0).abs() < 1e-12);
    let mag = messages.iter().find_map(|(_, m)| match m {
        LogMessage::Magnetometer(x) => Some(x.field_t),
        _ => None,
    });
    assert_eq!(mag, Some([200e-7, 0.0, 450e-7]));
}

#[test]
fn damage_anywhere_is_skipped_and_counted_never_fatal() {
    let (bytes, _) = telemetry();
    // Every 997th byte flipped, and the file cut in the middle of a record.
    let mut damaged = bytes.clone();
    for i in (500..damaged.len()).step_by(997) {
        damaged[i] ^= 0xff;
    }
    damaged.truncate(damaged.len() - 17);
    let (messages, s) = import(&damaged, "damaged");
    assert!(s.bad_checksum + s.bytes_skipped > 0);
    assert!(s.imu > 900, "{s:?}");
    assert!(!messages.is_empty());
    // Nothing but garbage is an error naming the file, not a panic.
    let dir = std::env::temp_dir().join(format!("auvnav-tlog-{}-garbage", std::process::id()));
    std::fs::create_dir_all(&dir).expect("dir");
    let path = dir.join("g.tlog");
    std::fs::write(&path, vec![0xFDu8; 4000]).expect("write");
    let e = tlog_messages(&TlogOptions::new(path, dir.join("g.mcap")));
    let _ = std::fs::remove_dir_all(&dir);
    assert!(e.expect_err("an error").to_string().contains("g.tlog"));
    // A wrong option is refused before reading.
    let mut o = TlogOptions::new("x.tlog".into(), "x.mcap".into());
    o.pressure_instance = 4;
    assert!(tlog_messages(&o).is_err());
}
