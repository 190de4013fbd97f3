//! Blueprint Subsea SeaTrac: schema messages encoded in its protocol (emulation).

use crate::seatrac::{self, AcoFix, FixRange, FixUsbl};
use auvnav_shm_schema::{AcousticRangesV1, UsblFixV1};

/// A USBL message as a SeaTrac `CID_XCVR_FIX` line (the inverse of
/// [`super::to_schema::seatrac_fix`]; `position_array_m` is `[northing, easting, depth]`).
pub fn seatrac_from_usbl(m: &UsblFixV1, local_id: u8) -> Vec<u8> {
    let c = if m.validity & UsblFixV1::VALID_SOUND_SPEED != 0 {
        m.sound_speed_m_s
    } else {
        1500.0
    };
    let mut flags = 0;
    let range = (m.validity & UsblFixV1::VALID_RANGE != 0).then(|| {
        flags |= AcoFix::RANGE_VALID;
        let two_way = 2.0 * m.slant_range_m / c;
        FixRange {
            count: (two_way * 16_000.0).round() as u32,
            travel_time_s: two_way,
            distance_m: m.slant_range_m,
        }
    });
    let usbl = (m.validity & UsblFixV1::VALID_ANGLES != 0).then(|| {
        flags |= AcoFix::USBL_VALID;
        FixUsbl {
            channel_rssi_db: if m.validity & UsblFixV1::VALID_RSSI != 0 {
                m.rssi_db.iter().map(|&r| f64::from(r)).collect()
            } else {
                Vec::new()
            },
            azimuth_deg: m.azimuth_rad.to_degrees(),
            elevation_deg: m.elevation_rad.to_degrees(),
            fit_error: f64::from(m.fit_error_m),
        }
    });
    let position_m = (m.validity & UsblFixV1::VALID_POSITION != 0).then(|| {
        flags |= AcoFix::POSITION_VALID;
        let [n, e, d] = m.position_array_m;
        [e, n, d]
    });
    let fix = AcoFix {
        destination_id: local_id,
        source_id: m.beacon_id.min(255) as u8,
        flags,
        message_type: 0,
        attitude_deg: [0.0; 3],
        local_depth_m: 0.0,
        sound_speed_m_s: c,
        rssi_db: 0.0,
        range,
        usbl,
        position_m,
    };
    seatrac::encode_line(seatrac::CID_XCVR_FIX, &seatrac::encode_aco_fix(&fix))
}

/// An LBL ping's ranges as SeaTrac `CID_PING_RESP` lines, one per valid range of receiver k
/// below `beacons.len()`, from beacon `beacons[k]` (the inverse of
/// [`super::to_schema::seatrac_range`] with the driver's `range_beacons`); ranges beyond the
/// wire's 6 553.5 m are left out. Empty when no range is sent.
pub fn seatrac_pings_from_ranges(m: &AcousticRangesV1, beacons: &[u8], local_id: u8) -> Vec<u8> {
    let mut out = Vec::new();
    for (k, &beacon) in beacons.iter().enumerate().take(4) {
        let d = m.range_m[k];
        if !(m.range_valid(k) && d > 0.0 && d <= 6553.5) {
            continue;
        }
        let two_way = 2.0 * d / 1500.0;
        let fix = AcoFix {
            destination_id: local_id,
            source_id: beacon,
            flags: AcoFix::RANGE_VALID,
            message_type: 0,
            attitude_deg: [0.0; 3],
            local_depth_m: 0.0,
            sound_speed_m_s: 1500.0,
            rssi_db: 0.0,
            range: Some(FixRange {
                count: (two_way * 16_000.0).round() as u32,
                travel_time_s: two_way,
                distance_m: d,
            }),
            usbl: None,
            position_m: None,
        };
        out.extend(seatrac::encode_line(
            seatrac::CID_PING_RESP,
            &seatrac::encode_aco_fix(&fix),
        ));
    }
    out
}
