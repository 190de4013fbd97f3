//! The range aid's own model (the navigator's use of it: `crate::range_aid_tests`), and the
//! helpers both share.

use super::*;
use crate::ekf::StateVector;
use crate::strapdown::initial_state;

pub(crate) const LAT: f64 = 31.0;
pub(crate) const LON: f64 = 120.0;

pub(crate) fn origin() -> Geodetic {
    Geodetic {
        latitude_rad: LAT.to_radians(),
        longitude_rad: LON.to_radians(),
        height_m: -50.0,
    }
}

pub(crate) fn beacon_config() -> RangesConfig {
    RangesConfig {
        origin_latitude_deg: LAT,
        origin_longitude_deg: LON,
        origin_height_m: -50.0,
        receivers_m: vec![[0.0; 3], [0.0, 200.0, 0.0]],
        interrogator: Interrogator::Vehicle,
        ..Default::default()
    }
}

pub(crate) fn ranges(t_s: f64, r: &[(usize, f64)]) -> AcousticRangesV1 {
    let mut m = AcousticRangesV1 {
        host_time_ns: (t_s * 1e9) as u64,
        ..Default::default()
    };
    for &(k, x) in r {
        m.range_m[k] = x;
        m.validity |= AcousticRangesV1::VALID_RANGE << k;
    }
    m
}

/// The range of a vehicle moving during the ping is the two legs' mean, each where the ends were
/// when the sound left and arrived, for either interrogator.
#[test]
fn the_ping_is_evaluated_where_each_end_was() {
    let speed = Vector3::new(0.0, 3.0, 0.0); // east, m/s
    let start = offset_position(&origin(), &Vector3::new(-750.0, 0.0, 0.0));
    let at = |t: f64| offset_position(&start, &(speed * t));
    for interrogator in [Interrogator::Vehicle, Interrogator::Array] {
        let cfg = RangesConfig {
            interrogator,
            turnaround_s: 0.05,
            device_sound_speed_m_s: 1500.0,
            sound_speed_m_s: 1500.0,
            ..beacon_config()
        };
        let mut kf = ErrorFilter::new(&StateVector::zeros());
        let mut aid = RangeAid::new(Some(&cfg), &mut kf);
        for i in 0..=300 {
            let t = i as f64 * 0.01;
            aid.after_imu(&initial_state(t, at(t), speed.into(), [0.0; 3]));
        }
        let f = aid.fusion.as_ref().expect("configured");
        // The exact two-way path for a range closed at t = 2.5 s, by fixed-point iteration on
        // the travel time.
        let beacon = origin();
        let t = 2.5;
        let dist = |a: &Geodetic| ned_offset(&beacon, a).norm();
        let mut z: f64 = 750.0;
        for _ in 0..20 {
            let tau = z / 1500.0;
            z = match interrogator {
                Interrogator::Vehicle => 0.5 * (dist(&at(t)) + dist(&at(t - 2.0 * tau - 0.05))),
                Interrogator::Array => dist(&at(t - tau)),
            };
        }
        let p = f
            .predict(&initial_state(t, at(t), [0.0; 3], [0.0; 3]), 0, t, z)
            .expect("prediction")
            .at(&Vector3::zeros());
        assert!(
            (p.range_m - z).abs() < 2e-4,
            "{interrogator:?}: predicted {} against {z}",
            p.range_m
        );
        // Where the vehicle is at the range's time is not where the sound met it: evaluated
        // there, the range is off by centimetres.
        let naive = dist(&at(t));
        assert!(
            (naive - z).abs() > 5e-3,
            "{interrogator:?}: {naive} against {z}"
        );
    }
}
