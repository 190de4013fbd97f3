//! Water Linked Underwater GPS: the topside's responses as the schema messages the driver
//! publishes — an acoustic reading as [`AcousticRangesV1`], the topside's position and heading
//! as [`AcousticArrayPoseV1`] (the array frame the receivers and the fix are given in).
//!
//! A value outside its physical range is left out of the message (its validity bit clear) and
//! counted in the returned number, so that the driver reports it; the rest of the reading is
//! kept. The API's "no data" markers (a distance of −1 on an invalid receiver, an orientation
//! of −1, a fix quality of 0) are not errors: they only clear the bit.

use crate::ugps::{AcousticRaw, MasterPosition, Receiver};
use auvnav_shm_schema::{AcousticArrayPoseV1, AcousticRangesV1};

/// Longest range accepted (m), as the schema bounds it.
const MAX_RANGE_M: f64 = 10_000.0;

/// An acoustic reading as a ranges message, and how many of its values were out of range.
/// `receivers` (the topside's configured receiver positions, ordered as the reading's arrays)
/// fill `receiver_position_m` when there is one per receiver of the reading.
pub fn ugps_ranges(
    raw: &AcousticRaw,
    receivers: Option<&[Receiver]>,
    host_time_ns: u64,
    sequence: u64,
) -> (AcousticRangesV1, u32) {
    let mut m = AcousticRangesV1 {
        host_time_ns,
        sequence,
        ..Default::default()
    };
    let mut out_of_range = 0;
    let mut signal_ok = true;
    for (k, r) in raw.receivers.iter().enumerate() {
        let d = r.distance_m;
        if r.valid {
            if d.is_finite() && d > 0.0 && d <= MAX_RANGE_M {
                m.range_m[k] = d;
                m.validity |= AcousticRangesV1::VALID_RANGE << k;
            } else {
                out_of_range += 1;
            }
        }
        let level = |x: f64| x.is_finite() && x.abs() <= 300.0;
        if level(r.nsd_db) && level(r.rssi_db) {
            m.noise_db[k] = r.nsd_db as f32;
            m.rssi_db[k] = r.rssi_db as f32;
        } else {
            signal_ok = false;
        }
    }
    if signal_ok && !raw.receivers.is_empty() {
        m.validity |= AcousticRangesV1::VALID_SIGNAL;
    } else if !signal_ok {
        out_of_range += 1;
    }
    if raw.position_valid {
        let [x, y, z] = raw.position_m;
        let inside = x.is_finite()
            && y.is_finite()
            && z.is_finite()
            && x.abs() <= MAX_RANGE_M
            && y.abs() <= MAX_RANGE_M
            && (-100.0..=MAX_RANGE_M).contains(&z);
        if inside {
            m.position_array_m = raw.position_m;
            m.validity |= AcousticRangesV1::VALID_POSITION;
            if raw.std_m.is_finite() && (0.0..=1000.0).contains(&raw.std_m) {
                m.position_std_m = raw.std_m as f32;
                m.validity |= AcousticRangesV1::VALID_POSITION_STD;
            } else {
                out_of_range += 1;
            }
        } else {
            out_of_range += 1;
        }
    }
    if let Some(rs) = receivers
        && !rs.is_empty()
        && rs.len() == raw.receivers.len()
        && rs.iter().all(|r| {
            [r.x, r.y, r.z]
                .iter()
                .all(|v| v.is_finite() && v.abs() <= 1000.0)
        })
    {
        for (k, r) in rs.iter().enumerate() {
            m.receiver_position_m[3 * k..3 * k + 3].copy_from_slice(&[r.x, r.y, r.z]);
        }
        m.validity |= AcousticRangesV1::VALID_RECEIVER_POSITIONS;
    }
    (m, out_of_range)
}

/// The topside's position and heading as the array's pose (level: the API gives no tilt), and
/// how many of its values were out of range; `None` when neither the position nor the heading
/// is usable. No one-sigma is set: the navigator's configured ones apply.
pub fn ugps_array_pose(
    p: &MasterPosition,
    host_time_ns: u64,
    sequence: u64,
) -> (Option<AcousticArrayPoseV1>, u32) {
    let mut m = AcousticArrayPoseV1 {
        host_time_ns,
        sequence,
        ..Default::default()
    };
    let mut out_of_range = 0;
    let has_fix = p.fix_quality.is_none_or(|q| q > 0.0);
    if has_fix {
        if p.lat_deg.is_finite()
            && p.lon_deg.is_finite()
            && p.lat_deg.abs() <= 90.0
            && p.lon_deg.abs() <= 180.0
        {
            m.latitude_rad = p.lat_deg.to_radians();
            m.longitude_rad = p.lon_deg.to_radians();
            m.validity |= AcousticArrayPoseV1::VALID_POSITION;
        } else {
            out_of_range += 1;
        }
    }
    let h = p.orientation_deg;
    if h != -1.0 {
        if h.is_finite() && (0.0..=360.0).contains(&h) {
            m.euler_rad = [0.0, 0.0, h.to_radians()];
            m.validity |= AcousticArrayPoseV1::VALID_HEADING;
        } else {
            out_of_range += 1;
        }
    }
    let usable = m.validity
        & (AcousticArrayPoseV1::VALID_POSITION | AcousticArrayPoseV1::VALID_HEADING)
        != 0;
    (usable.then_some(m), out_of_range)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::ugps::{ReceiverReading, acoustic_raw};

    fn reading() -> AcousticRaw {
        acoustic_raw(
            br#"{"position_valid": true, "receiver_distance": [24.81, 24.9, -1, 25.02],
            "receiver_nsd": [-55.1, -56.0, -60.2, -54.9], "receiver_rssi": [-20.5, -21.0, -70.1, -19.8],
            "receiver_valid": [true, true, false, true], "std": 0.41, "x": 3.2, "y": -11.7, "z": 21.4}"#,
        )
        .expect("decodes")
    }

    #[test]
    fn a_reading_becomes_its_valid_ranges_and_fix() {
        let rs = [
            Receiver {
                id: 1,
                x: 0.5,
                y: 1.0,
                z: 3.0,
            },
            Receiver {
                id: 2,
                x: -0.5,
                y: 1.0,
                z: 3.0,
            },
            Receiver {
                id: 3,
                x: -0.5,
                y: -1.0,
                z: 3.0,
            },
            Receiver {
                id: 4,
                x: 0.5,
                y: -1.0,
                z: 3.0,
            },
        ];
        let (m, bad) = ugps_ranges(&reading(), Some(&rs), 7, 3);
        assert_eq!(bad, 0);
        assert!(m.range_valid(0) && m.range_valid(1) && !m.range_valid(2) && m.range_valid(3));
        assert_eq!(m.range_m[3], 25.02);
        assert_eq!(m.position_array_m, [3.2, -11.7, 21.4]);
        assert_eq!(m.position_std_m, 0.41f32);
        assert_ne!(m.validity & AcousticRangesV1::VALID_RECEIVER_POSITIONS, 0);
        assert_eq!(m.receiver_position_m[9..12], [0.5, -1.0, 3.0]);
        // Receivers that do not match the reading's count are not attached.
        let (m, _) = ugps_ranges(&reading(), Some(&rs[..2]), 7, 3);
        assert_eq!(m.validity & AcousticRangesV1::VALID_RECEIVER_POSITIONS, 0);
    }

    #[test]
    fn values_out_of_range_are_left_out_and_counted() {
        let mut r = reading();
        r.receivers[0] = ReceiverReading {
            distance_m: 1e9,
            ..r.receivers[0]
        };
        r.receivers[1].distance_m = f64::NAN;
        r.std_m = -2.0;
        let (m, bad) = ugps_ranges(&r, None, 0, 0);
        assert_eq!(bad, 3);
        assert!(!m.range_valid(0) && !m.range_valid(1) && m.range_valid(3));
        assert_ne!(m.validity & AcousticRangesV1::VALID_POSITION, 0);
        assert_eq!(m.validity & AcousticRangesV1::VALID_POSITION_STD, 0);
    }

    #[test]
    fn the_topsides_no_data_markers_clear_bits_without_counting() {
        let p = MasterPosition {
            lat_deg: 47.6,
            lon_deg: -122.3,
            orientation_deg: -1.0,
            fix_quality: Some(0.0),
            hdop: None,
            numsats: None,
            cog_deg: None,
            sog_km_h: None,
        };
        assert_eq!(ugps_array_pose(&p, 0, 0), (None, 0));
        let (m, bad) = ugps_array_pose(
            &MasterPosition {
                fix_quality: Some(1.0),
                orientation_deg: 400.0,
                ..p
            },
            5,
            1,
        );
        assert_eq!(bad, 1);
        let m = m.expect("the position alone");
        assert_eq!(m.validity, AcousticArrayPoseV1::VALID_POSITION);
        assert!((m.latitude_rad - 47.6f64.to_radians()).abs() < 1e-15);
    }
}
