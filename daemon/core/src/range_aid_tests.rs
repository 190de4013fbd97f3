//! The range aid through the navigator: corrections along the line of sight, gating alone, a
//! moving array placed from its pose, the water's sound speed, each range of a ping on the track
//! the one before corrected, and the configuration's checks.

use crate::aid::ranges::tests::{LAT, LON, beacon_config, origin, ranges};
use crate::aid::ranges::{ArrayKind, RangesConfig};
use crate::earth::{Geodetic, ned_offset, offset_position};
use crate::navigator::{NavConfig, Navigator};
use crate::strapdown::initial_state;
use auvnav_shm_schema::{AcousticArrayPoseV1, AidSource};
use nalgebra::Vector3;

/// A beacon's range pulls the position along the line of sight only: a vehicle believed 3 m
/// north of where a range from a beacon due south puts it moves north-south, not east-west.
#[test]
fn a_beacons_range_corrects_along_its_line_of_sight() {
    let cfg = NavConfig {
        ranges: Some(RangesConfig {
            bias_std_m: 0.0,
            scale_std: 0.0,
            ..beacon_config()
        }),
        initial_position_std_m: 10.0,
        ..Default::default()
    };
    let believed = offset_position(&origin(), &Vector3::new(103.0, 0.0, 0.0));
    let mut nav = Navigator::new(cfg, initial_state(10.0, believed, [0.0; 3], [0.0; 3]));
    let d = nav.on_acoustic_ranges(&ranges(10.0, &[(0, 100.0)]));
    let d0 = d[0].expect("receiver 0's diagnostics");
    assert!(d[1].is_none() && d[2].is_none());
    assert_eq!(d0.source, AidSource::AcousticRange as u32);
    assert!(d0.flags & auvnav_shm_schema::AidDiagnosticsV1::FLAG_FUSED != 0);
    assert!(
        (d0.innovation[0] + 3.0).abs() < 1e-4,
        "{}",
        d0.innovation[0]
    );
    let now = ned_offset(&origin(), &nav.state().position);
    assert!(now.x < 100.5 && now.x > 99.5, "north {}", now.x);
    assert!(now.y.abs() < 1e-6, "east {}", now.y);
    assert_eq!(nav.counters().ranges_fused, 1);
    // An outlier is gated alone: receiver 1's absurd range is refused, receiver 0's taken.
    let d = nav.on_acoustic_ranges(&ranges(10.0, &[(0, 100.0), (1, 400.0)]));
    assert!(d[0].is_some_and(|d| d.flags & auvnav_shm_schema::AidDiagnosticsV1::FLAG_FUSED != 0));
    assert!(d[1].is_some_and(|d| d.test_ratio > 1.0));
    let c = nav.counters();
    assert_eq!((c.ranges_fused, c.ranges_rejected), (2, 1));
    // A receiver the configuration does not place, and a range beyond the longest: invalid.
    nav.on_acoustic_ranges(&ranges(10.0, &[(3, 100.0), (0, 9000.0)]));
    assert_eq!(nav.counters().ranges_invalid, 2);
}

/// A moving array's one-way ranges without bias, scale or pose errors.
fn moving_array() -> RangesConfig {
    RangesConfig {
        array: ArrayKind::Moving,
        two_way: false,
        bias_std_m: 0.0,
        scale_std: 0.0,
        array_position_std_m: 0.0,
        array_heading_std_deg: 0.0,
        ..Default::default()
    }
}

/// A navigator with `ranges` at t = 5 s, 40 m below a boat's antenna (returned).
fn under_a_boat(ranges: RangesConfig) -> (Navigator, Geodetic) {
    let boat = Geodetic {
        latitude_rad: LAT.to_radians(),
        longitude_rad: LON.to_radians(),
        height_m: 0.0,
    };
    let vehicle = offset_position(&boat, &Vector3::new(0.0, 0.0, 40.0));
    let cfg = NavConfig {
        ranges: Some(ranges),
        ..Default::default()
    };
    let nav = Navigator::new(cfg, initial_state(5.0, vehicle, [0.0; 3], [0.0; 3]));
    (nav, boat)
}

/// The boat's pose at `t` with its heading.
fn boat_pose(boat: &Geodetic, t: f64, heading_deg: f64) -> AcousticArrayPoseV1 {
    AcousticArrayPoseV1 {
        host_time_ns: (t * 1e9) as u64,
        latitude_rad: boat.latitude_rad,
        longitude_rad: boat.longitude_rad,
        euler_rad: [0.0, 0.0, heading_deg.to_radians()],
        validity: AcousticArrayPoseV1::VALID_POSITION | AcousticArrayPoseV1::VALID_HEADING,
        ..Default::default()
    }
}

/// A moving array's ranges need its pose at the time: without one they are counted, with one
/// the receiver is placed from the boat's position and heading.
#[test]
fn a_moving_arrays_receivers_are_placed_from_its_pose() {
    // A receiver 2 m to starboard of the antenna, 10 m down.
    let (mut nav, boat) = under_a_boat(RangesConfig {
        receivers_m: vec![[0.0, 2.0, 10.0]],
        ..moving_array()
    });
    nav.on_acoustic_ranges(&ranges(5.0, &[(0, 30.0)]));
    assert_eq!(nav.counters().ranges_without_array_pose, 1);
    let pose = |t: f64, heading_deg: f64| boat_pose(&boat, t, heading_deg);
    // Heading east: the receiver is 2 m south of the antenna, 10 m down.
    nav.on_acoustic_array_pose(&pose(4.0, 90.0));
    nav.on_acoustic_array_pose(&pose(5.5, 90.0));
    nav.on_acoustic_array_pose(&AcousticArrayPoseV1 {
        validity: 0,
        ..pose(5.6, 0.0)
    });
    let expected = (2.0f64 * 2.0 + 30.0 * 30.0).sqrt();
    let d = nav.on_acoustic_ranges(&ranges(5.0, &[(0, expected)]))[0].expect("diagnostics");
    assert!(d.innovation[0].abs() < 1e-3, "{}", d.innovation[0]);
    let c = nav.counters();
    assert_eq!(
        (c.array_poses, c.array_poses_invalid, c.ranges_fused),
        (2, 1, 1)
    );
}

/// With `receivers_from_device`, the receivers are where the ranges messages say: none is
/// fused before a message places them, then each range is predicted from the message's places.
#[test]
fn the_device_can_place_the_receivers() {
    let (mut nav, boat) = under_a_boat(RangesConfig {
        receivers_from_device: true,
        ..moving_array()
    });
    for t in [4.0, 5.5] {
        nav.on_acoustic_array_pose(&boat_pose(&boat, t, 0.0));
    }
    // Receiver 1 is 3 m forward of the antenna and 10 m down, receiver 0 at the antenna.
    let expected = (3.0f64 * 3.0 + 30.0 * 30.0).sqrt();
    nav.on_acoustic_ranges(&ranges(5.0, &[(1, expected)]));
    assert_eq!(nav.counters().ranges_invalid, 1, "no receiver placed yet");
    let mut m = ranges(5.0, &[(1, expected)]);
    m.receiver_position_m[3..6].copy_from_slice(&[3.0, 0.0, 10.0]);
    m.validity |= auvnav_shm_schema::AcousticRangesV1::VALID_RECEIVER_POSITIONS;
    let d = nav.on_acoustic_ranges(&m)[1].expect("diagnostics");
    assert!(d.innovation[0].abs() < 1e-3, "{}", d.innovation[0]);
    assert_eq!(nav.counters().ranges_fused, 1);
}

#[test]
fn configurations_that_make_no_sense_are_named() {
    assert!(RangesConfig::default().problems().is_empty());
    let bad = RangesConfig {
        receivers_m: vec![],
        range_std_m: 0.0,
        ..Default::default()
    };
    let p = bad.problems();
    assert!(
        p.iter().any(|x| x.starts_with("ranges.receivers_m")),
        "{p:?}"
    );
    assert!(
        p.iter().any(|x| x.starts_with("ranges.range_std_m")),
        "{p:?}"
    );
    let both = NavConfig {
        ranges: Some(RangesConfig::default()),
        usbl: Some(crate::aid::usbl::UsblConfig::default()),
        ..Default::default()
    };
    assert!(both.problems().iter().any(|x| x.contains("tight")));
}

/// The ranges of one ping are fused one after the other, each on the track the previous one
/// corrected: a vehicle believed 8 m off, ranged by three beacons at once with the ping's legs in
/// the past, ends 0.75 m from the truth (a linearised range taken from 8 m off at 42 m leaves
/// its sphere by decimetres when the next range moves the state along it); evaluated on the
/// uncorrected track, the later ranges undid the first one's correction and left it 5.3 m off.
#[test]
fn each_range_of_a_ping_sees_the_correction_of_the_one_before() {
    let cfg = NavConfig {
        ranges: Some(RangesConfig {
            receivers_m: vec![[-30.0, -30.0, 0.0], [180.0, -30.0, 0.0], [75.0, 150.0, 0.0]],
            bias_std_m: 0.0,
            scale_std: 0.0,
            range_std_m: 0.05,
            ..beacon_config()
        }),
        initial_position_std_m: 3.0,
        ..Default::default()
    };
    let truth = origin();
    let believed = offset_position(&truth, &Vector3::new(-0.4, -8.3, 0.0));
    let mut nav = Navigator::new(
        cfg.clone(),
        initial_state(0.0, believed, [0.0; 3], [0.0; 3]),
    );
    // A still vehicle's recent track (the legs of a 180 m range reach 0.24 s back).
    let mut track = initial_state(0.0, believed, [0.0; 3], [0.0; 3]);
    for i in 0..=100 {
        track.time_s = i as f64 * 0.01;
        nav.ranges.after_imu(&track);
    }
    let beacons = cfg.ranges.as_ref().expect("ranges").receivers_m.clone();
    let truth_ranges: Vec<(usize, f64)> = beacons
        .iter()
        .enumerate()
        .map(|(k, b)| {
            let at = offset_position(&origin(), &Vector3::from(*b));
            (k, ned_offset(&at, &truth).norm())
        })
        .collect();
    nav.on_acoustic_ranges(&ranges(1.0, &truth_ranges));
    let err = ned_offset(&truth, &nav.state().position);
    assert!(
        err.xy().norm() < 1.0,
        "horizontal error after one ping {err}"
    );
}

/// A device that assumed 1500 m/s in water of 1530 m/s reports 1500/1530 of the range: with the
/// water's sound speed configured, the navigator predicts exactly that.
#[test]
fn the_waters_sound_speed_scales_the_devices_ranges() {
    let cfg = NavConfig {
        ranges: Some(RangesConfig {
            sound_speed_m_s: 1530.0,
            bias_std_m: 0.0,
            scale_std: 0.0,
            ..beacon_config()
        }),
        ..Default::default()
    };
    let here = offset_position(&origin(), &Vector3::new(300.0, 0.0, 0.0));
    let mut nav = Navigator::new(cfg, initial_state(1.0, here, [0.0; 3], [0.0; 3]));
    let d = nav.on_acoustic_ranges(&ranges(1.0, &[(0, 300.0 * 1500.0 / 1530.0)]))[0]
        .expect("diagnostics");
    assert!(d.innovation[0].abs() < 1e-3, "{}", d.innovation[0]);
}
