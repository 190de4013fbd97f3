//! Device emulation: schema messages encoded in the devices' own protocols, the inverse of
//! [`crate::to_schema`]. The emulator (`auvnav emulate`) plays a log's messages through these into
//! pseudo-terminals; decoding the bytes with the driver's conversion gives the message back up to
//! the protocol's resolution (PD0 1 mm/s, SeaTrac 0.1 m and 0.1°, KVH and Xsens f32).
//!
//! Long on purpose: the last 493 lines are the unit tests, beside the code they test; the code is
//! 520 lines.

use crate::kvh::{self, KvhSample};
use crate::nortek;
use crate::pd0::{self, BottomTrack, CoordinateSystem, Ensemble, FixedLeader, VariableLeader};
use crate::seatrac::{self, AcoFix, FixRange, FixUsbl};
use crate::to_schema::{KvhConfig, STANDARD_GRAVITY};
use crate::wldvl::{self, Velocity, WlFrame};
use crate::xsens::{self, MtData2};
use auvnav_shm_schema::{DvlVelocityV1, GnssFixV1, ImuSampleV1, MagnetometerV1, UsblFixV1};

/// System configuration word of the emulated PD0 DVL: 600 kHz, convex, 30° beams, down-looking,
/// 4-beam Janus.
pub const PD0_SYSTEM_CONFIGURATION: u16 = 0x4000 | 0x0200 | 0x0008 | 0x0003;
/// EX command byte of the emulated PD0 DVL: instrument coordinates.
pub const PD0_COORDINATE_TRANSFORM: u8 = 0x08;
/// Beam angle of the emulated PD0 DVL (deg).
pub const PD0_BEAM_ANGLE_DEG: f64 = 30.0;

/// The device time of a DVL message in ns (its own, or the time of validity).
fn dvl_device_time_ns(m: &DvlVelocityV1) -> u64 {
    if m.validity & DvlVelocityV1::VALID_DEVICE_TIME != 0 {
        m.device_time_ns
    } else {
        m.validity_time_ns
    }
}

pub use crate::to_schema::pd0_rtc;

/// Beam angle of the emulated Nortek DVL (deg, the DVL1000's).
pub const NORTEK_BEAM_ANGLE_DEG: f64 = 25.0;

/// A DVL message as a Nortek bottom-track record of a down-looking DVL with beam 1 forward (see
/// [`crate::to_schema::nortek_velocity`]): X, Y, Z1 = Z2 the velocity, beam velocities its
/// projection on the four beams (azimuths 45°, −45°, −135°, 135° from X, 25° from Z), every beam's
/// vertical distance the altitude, the device time as the ping's date. Invalid values are written
/// as the device writes them (−32.768 m/s, figure of merit 10).
pub fn nortek_from_dvl(m: &DvlVelocityV1) -> Vec<u8> {
    let valid = m.validity & DvlVelocityV1::VALID_VELOCITY != 0;
    let v = m.velocity_dvl_m_s;
    let fom = if m.validity & DvlVelocityV1::VALID_FOM != 0 {
        m.figure_of_merit_m_s as f32
    } else {
        0.002
    };
    let estimate = |velocity: f64| nortek::Estimate {
        velocity_m_s: if valid {
            velocity as f32
        } else {
            nortek::INVALID_VELOCITY
        },
        figure_of_merit_m_s: if valid { fom } else { nortek::INVALID_FOM },
        ..Default::default()
    };
    let a = NORTEK_BEAM_ANGLE_DEG.to_radians();
    let beam = std::array::from_fn(|i| {
        let az = [45.0f64, -45.0, -135.0, 135.0][i].to_radians();
        let u = [a.sin() * az.cos(), a.sin() * az.sin(), a.cos()];
        estimate(v[0] * u[0] + v[1] * u[1] + v[2] * u[2])
    });
    let altitude = if m.validity & DvlVelocityV1::VALID_ALTITUDE != 0 {
        m.altitude_m as f32
    } else {
        0.0
    };
    let (date_time, time_100us) = nortek::BottomTrack::date_time_of(dvl_device_time_ns(m))
        .unwrap_or(([70, 0, 1, 0, 0, 0], 0));
    let bt = nortek::BottomTrack {
        version: 1,
        offset_of_data: 36,
        serial_number: 100_000,
        date_time,
        time_100us,
        beams: 4,
        error: 0,
        status: 0,
        sound_speed_m_s: if m.validity & DvlVelocityV1::VALID_SOUND_SPEED != 0 {
            m.sound_speed_m_s as f32
        } else {
            1500.0
        },
        temperature_c: 10.0,
        pressure_dbar: 0.0,
        beam,
        beam_distance_m: [altitude; 4],
        xyz: [
            estimate(v[0]),
            estimate(v[1]),
            estimate(v[2]),
            estimate(v[2]),
        ],
    };
    nortek::encode_bottom_track(&bt)
}

/// A DVL message as a PD0 ensemble (fixed leader, variable leader, bottom track) of an
/// instrument-coordinate 4-beam DVL. Invalid velocity is written as PD0's -32768.
pub fn pd0_from_dvl(m: &DvlVelocityV1, ensemble_number: u32) -> Vec<u8> {
    pd0_from_dvl_in(m, ensemble_number, CoordinateSystem::Instrument, None)
}

/// EX command byte of the emulated PD0 DVL in earth coordinates: earth, tilts used.
pub const PD0_EARTH_COORDINATE_TRANSFORM: u8 = 0x18 | pd0::EX_TILTS_USED;

/// The same DVL in earth coordinates (EX 0x1C): the instrument-frame bottom velocity rotated to
/// east, north, up with RDI's transformation ([`pd0::instrument_to_earth_matrix`]) for the
/// instrument attitude `euler_rad` (roll, pitch, yaw; the vehicle's when the DVL is mounted along
/// its axes), which the variable leader records as heading, tilt 1 and tilt 2 (tilt 1 is the
/// recorded pitch whose gimbal pitch `atan(tan(tilt1) cos(tilt2))` is the attitude's pitch). The
/// rotation uses the angles as recorded (0.01°), so decoding gives back the instrument velocity
/// to the velocity's 1 mm/s resolution.
pub fn pd0_earth_from_dvl(m: &DvlVelocityV1, ensemble_number: u32, euler_rad: [f64; 3]) -> Vec<u8> {
    pd0_from_dvl_in(m, ensemble_number, CoordinateSystem::Earth, Some(euler_rad))
}

/// The same DVL in beam coordinates (EX 0x00): each beam's radial velocity of the bottom, the
/// inverse of RDI's beam-to-instrument transformation for the 30° convex head with zero error
/// velocity.
pub fn pd0_beam_from_dvl(m: &DvlVelocityV1, ensemble_number: u32) -> Vec<u8> {
    pd0_from_dvl_in(m, ensemble_number, CoordinateSystem::Beam, None)
}

/// Beam velocities for an instrument-frame bottom velocity (x, y, z) with zero error velocity
/// (the inverse of [`pd0::beam_to_instrument`] for a convex head).
fn pd0_beams(xyz: [f64; 3], beam_angle_deg: f64) -> [f64; 4] {
    let th = beam_angle_deg.to_radians();
    let a = 1.0 / (2.0 * th.sin());
    let s = xyz[2] * 4.0 * th.cos();
    [
        s / 4.0 + xyz[0] / (2.0 * a),
        s / 4.0 - xyz[0] / (2.0 * a),
        s / 4.0 - xyz[1] / (2.0 * a),
        s / 4.0 + xyz[1] / (2.0 * a),
    ]
}

/// Heading, tilt 1 and tilt 2 (deg, at the leader's 0.01° resolution) as an RDI head records an
/// attitude (roll, pitch, yaw in rad).
fn pd0_recorded_attitude(euler_rad: [f64; 3]) -> (f64, f64, f64) {
    let q = |deg: f64| (deg * 100.0).round() / 100.0;
    let roll = euler_rad[0].to_degrees().clamp(-179.99, 179.99);
    let pitch = euler_rad[1];
    let tilt1 = (pitch.tan() / roll.to_radians().cos())
        .atan()
        .to_degrees()
        .clamp(-89.99, 89.99);
    let heading = q(euler_rad[2].to_degrees().rem_euclid(360.0));
    (
        if heading >= 360.0 { 0.0 } else { heading },
        q(tilt1),
        q(roll),
    )
}

fn pd0_from_dvl_in(
    m: &DvlVelocityV1,
    ensemble_number: u32,
    system: CoordinateSystem,
    euler_rad: Option<[f64; 3]>,
) -> Vec<u8> {
    let valid = m.validity & DvlVelocityV1::VALID_VELOCITY != 0;
    let v = m.velocity_dvl_m_s;
    // Schema [x fwd, y stbd, z down] (vehicle) -> RDI [x stbd, y fwd, z up] (bottom).
    let mut rdi = [-v[1], -v[0], v[2]];
    let (heading_deg, pitch_deg, roll_deg) =
        euler_rad.map_or((0.0, 0.0, 0.0), pd0_recorded_attitude);
    if system == CoordinateSystem::Earth {
        let mm = pd0::instrument_to_earth_matrix(heading_deg, pitch_deg, roll_deg, true, false);
        rdi = std::array::from_fn(|i| (0..3).map(|j| mm[i][j] * rdi[j]).sum::<f64>());
    }
    let mut velocity = [None; 4];
    if valid && system == CoordinateSystem::Beam {
        velocity = pd0_beams(rdi, PD0_BEAM_ANGLE_DEG).map(Some);
    } else if valid {
        for i in 0..3 {
            velocity[i] = Some(rdi[i]);
        }
        velocity[3] = Some(if m.validity & DvlVelocityV1::VALID_FOM != 0 {
            m.figure_of_merit_m_s
        } else {
            0.0
        });
    }
    let cos = PD0_BEAM_ANGLE_DEG.to_radians().cos();
    let range_m = std::array::from_fn(|i| {
        if m.validity & (DvlVelocityV1::VALID_BEAM_RANGE << i) != 0 {
            Some(m.beam_range_m[i] * cos)
        } else if m.validity & DvlVelocityV1::VALID_ALTITUDE != 0 {
            Some(m.altitude_m)
        } else {
            None
        }
    });
    let e = Ensemble {
        fixed: Some(FixedLeader {
            firmware_version: 51,
            firmware_revision: 1,
            system_configuration: PD0_SYSTEM_CONFIGURATION,
            beams: 4,
            cells: 0,
            pings_per_ensemble: 1,
            cell_size_m: 1.0,
            blank_m: 0.5,
            coordinate_transform: match system {
                CoordinateSystem::Beam => 0x00,
                CoordinateSystem::Earth => PD0_EARTH_COORDINATE_TRANSFORM,
                _ => PD0_COORDINATE_TRANSFORM,
            },
            coordinate_system: system,
            heading_alignment_deg: 0.0,
            heading_bias_deg: 0.0,
            sensor_source: 0,
            sensors_available: 0,
            bin1_distance_m: 1.0,
            transmit_pulse_m: 1.0,
            serial_number: Some(1),
            beam_angle_deg: Some(PD0_BEAM_ANGLE_DEG),
            upward_looking: false,
            frequency_khz: Some(600),
        }),
        variable: Some(VariableLeader {
            ensemble_number,
            rtc: pd0_rtc(dvl_device_time_ns(m)),
            rtc_y2k: None,
            bit_result: 0,
            sound_speed_m_s: if m.validity & DvlVelocityV1::VALID_SOUND_SPEED != 0 {
                m.sound_speed_m_s
            } else {
                1500.0
            },
            depth_m: 0.0,
            heading_deg,
            pitch_deg,
            roll_deg,
            salinity_ppt: 35.0,
            temperature_c: 10.0,
            pressure_pa: None,
        }),
        bottom_track: Some(BottomTrack {
            pings_per_ensemble: 1,
            range_m,
            velocity_m_s: velocity,
            correlation: [200; 4],
            evaluation_amplitude: [100; 4],
            percent_good: [if valid { 100 } else { 0 }; 4],
            max_depth_m: 200.0,
            reference_layer_velocity_m_s: [None; 4],
            reference_layer_percent_good: [0; 4],
        }),
        ..Default::default()
    };
    pd0::encode_ensemble(&e)
}

/// A DVL message as a Water Linked `wrz` line. The device clock is the message's device time (or
/// time of validity) in microseconds; time of transmission = validity + `latency_s`.
pub fn wrz_from_dvl(m: &DvlVelocityV1, latency_s: f64) -> Vec<u8> {
    let tov_us = dvl_device_time_ns(m) / 1000;
    let var = |i: usize| {
        if m.validity & DvlVelocityV1::VALID_STD != 0 {
            m.velocity_std_m_s[i] * m.velocity_std_m_s[i]
        } else {
            0.0
        }
    };
    let v = Velocity {
        velocity_m_s: m.velocity_dvl_m_s,
        valid: m.validity & DvlVelocityV1::VALID_VELOCITY != 0,
        altitude_m: if m.validity & DvlVelocityV1::VALID_ALTITUDE != 0 {
            m.altitude_m
        } else {
            -1.0
        },
        figure_of_merit_m_s: m.figure_of_merit_m_s,
        covariance: [var(0), 0.0, 0.0, 0.0, var(1), 0.0, 0.0, 0.0, var(2)],
        time_of_validity_us: tov_us,
        time_of_transmission_us: tov_us + (latency_s.max(0.0) * 1e6).round() as u64,
        time_since_last_ms: 0.0,
        status: 0,
    };
    wldvl::encode(&WlFrame::Velocity(v))
}

/// An IMU message as a KVH 1750 message (format B when the sample has a device time) in the
/// units `cfg` describes; `counter` is the unit's 8-bit sequence.
pub fn kvh_from_imu(m: &ImuSampleV1, cfg: &KvhConfig, counter: u8) -> Vec<u8> {
    let angle_scale = if cfg.degrees {
        180.0 / std::f64::consts::PI
    } else {
        1.0
    };
    let mut status = 0u8;
    if m.status & ImuSampleV1::STATUS_GYRO_VALID != 0 {
        status |= 0x07;
    }
    if m.status & ImuSampleV1::STATUS_ACCEL_VALID != 0 {
        status |= 0x70;
    }
    let temperature = if cfg.temperature_centi {
        f64::from(m.temperature_c) * 100.0
    } else {
        f64::from(m.temperature_c)
    };
    let s = KvhSample {
        gyro: m.angular.map(|g| (g * angle_scale) as f32),
        accel: m.specific.map(|a| (a / STANDARD_GRAVITY) as f32),
        status,
        sequence: counter,
        temperature_raw: temperature.round().clamp(-32768.0, 32767.0) as i16,
        timestamp_us: (m.status & ImuSampleV1::STATUS_DEVICE_TIME_VALID != 0)
            .then_some((m.device_time_ns / 1000) as u32),
    };
    kvh::encode(&s)
}

/// An IMU message as an Xsens MTData2 message: delta-q/delta-v in increment mode, rate of turn
/// and acceleration otherwise, with packet counter, sample time fine and temperature.
pub fn xsens_from_imu(m: &ImuSampleV1, packet_counter: u16) -> Vec<u8> {
    let mut d = MtData2 {
        packet_counter: Some(packet_counter),
        sample_time_fine: (m.status & ImuSampleV1::STATUS_DEVICE_TIME_VALID != 0)
            .then_some((m.device_time_ns / 100_000) as u32),
        temperature_c: (m.status & ImuSampleV1::STATUS_TEMPERATURE_VALID != 0)
            .then_some(f64::from(m.temperature_c)),
        ..Default::default()
    };
    if m.status & ImuSampleV1::STATUS_INCREMENTS != 0 {
        let a = m.angular;
        let angle = (a[0] * a[0] + a[1] * a[1] + a[2] * a[2]).sqrt();
        let (w, k) = if angle > 1e-15 {
            ((angle / 2.0).cos(), (angle / 2.0).sin() / angle)
        } else {
            (1.0, 0.5)
        };
        d.delta_q = Some([w, a[0] * k, a[1] * k, a[2] * k]);
        d.delta_v = Some(m.specific);
    } else {
        d.rate_of_turn = Some(m.angular);
        d.acceleration = Some(m.specific);
    }
    xsens::encode_mtdata2(&d)
}

/// A magnetometer message as an Xsens MTData2 message carrying the magnetic field in normalised
/// units of `unit_ut` µT (the inverse of [`crate::to_schema::xsens_magnetometer`]), with packet
/// counter, sample time fine and temperature. An invalid field is sent as NaN.
pub fn xsens_from_magnetometer(m: &MagnetometerV1, unit_ut: f64, packet_counter: u16) -> Vec<u8> {
    let field = if m.validity & MagnetometerV1::VALID_FIELD != 0 {
        m.field_t.map(|b| b * 1e6 / unit_ut)
    } else {
        [f64::NAN; 3]
    };
    xsens::encode_mtdata2(&MtData2 {
        packet_counter: Some(packet_counter),
        sample_time_fine: (m.validity & MagnetometerV1::VALID_DEVICE_TIME != 0)
            .then_some((m.device_time_ns / 100_000) as u32),
        temperature_c: (m.validity & MagnetometerV1::VALID_TEMPERATURE != 0)
            .then_some(f64::from(m.temperature_c)),
        magnetic_field: Some(field),
        ..Default::default()
    })
}

/// A USBL message as a SeaTrac `CID_XCVR_FIX` line (the inverse of
/// [`crate::to_schema::seatrac_fix`]; `position_array_m` is `[northing, easting, depth]`).
/// `ddmm.mmmmmmm,N` / `dddmm.mmmmmmm,E`.
fn nmea_angle(deg: f64, width: usize, pos: char, neg: char) -> String {
    let a = deg.abs();
    let mut d = a.trunc();
    let mut minutes = ((a - d) * 60.0 * 1e7).round() / 1e7;
    if minutes >= 60.0 {
        d += 1.0;
        minutes -= 60.0;
    }
    format!(
        "{:0width$}{:010.7},{}",
        d as u32,
        minutes,
        if deg < 0.0 { neg } else { pos }
    )
}

/// A GNSS fix as a receiver's NMEA epoch — `RMC`, `GGA`, `GST`, `ZDA` — stamped with the UTC
/// `utc_unix_ns` (the emulator's wall clock, as a live receiver's). The height goes out as the
/// altitude with a zero geoid separation; GST carries the fix's standard deviations.
pub fn nmea_from_gnss(m: &GnssFixV1, utc_unix_ns: i64) -> Vec<u8> {
    let t = chrono::DateTime::from_timestamp_nanos(utc_unix_ns);
    let time = format!(
        "{}{:02}",
        t.format("%H%M%S."),
        t.timestamp_subsec_millis() / 10
    );
    let lat = nmea_angle(m.latitude_rad.to_degrees(), 2, 'N', 'S');
    let lon = nmea_angle(m.longitude_rad.to_degrees(), 3, 'E', 'W');
    let [vn, ve, _] = m.velocity_ned_m_s;
    let knots = vn.hypot(ve) * 3600.0 / 1852.0;
    let course = ve.atan2(vn).to_degrees().rem_euclid(360.0);
    let quality = if m.validity & GnssFixV1::DIFFERENTIAL != 0 {
        2
    } else {
        1
    };
    let hdop = (m.horizontal_std_m / crate::gnss::GnssSettings::default().uere_m).max(0.5);
    let mut out = Vec::new();
    for body in [
        format!(
            "GNRMC,{time},A,{lat},{lon},{knots:.3},{course:.2},{},,,A",
            t.format("%d%m%y")
        ),
        format!(
            "GNGGA,{time},{lat},{lon},{quality},{:02},{hdop:.2},{:.3},M,0.000,M,,",
            m.satellites.min(99),
            m.height_m
        ),
        format!(
            "GNGST,{time},{h:.3},{h:.3},{h:.3},0.0,{h:.3},{h:.3},{:.3}",
            m.vertical_std_m,
            h = m.horizontal_std_m
        ),
        format!("GNZDA,{time},{},00,00", t.format("%d,%m,%Y")),
    ] {
        out.extend(crate::nmea::sentence(&body));
    }
    out
}

/// A GNSS fix as a u-blox `NAV-PVT` stamped with the UTC `utc_unix_ns`.
pub fn ubx_from_gnss(m: &GnssFixV1, utc_unix_ns: i64) -> Vec<u8> {
    use chrono::{Datelike, Timelike};
    let t = chrono::DateTime::from_timestamp_nanos(utc_unix_ns);
    let gps_ms = crate::gnss::gps_time_ns(utc_unix_ns, crate::gnss::GPS_MINUS_UTC_S)
        .map_or(0, |g| g / 1_000_000);
    let p = crate::ubx::NavPvt {
        itow_ms: (gps_ms % (7 * 86_400_000)) as u32,
        year: t.year() as u16,
        month: t.month() as u8,
        day: t.day() as u8,
        hour: t.hour() as u8,
        minute: t.minute() as u8,
        second: t.second() as u8,
        valid: crate::ubx::NavPvt::VALID_DATE
            | crate::ubx::NavPvt::VALID_TIME
            | crate::ubx::NavPvt::FULLY_RESOLVED,
        time_accuracy_ns: 30,
        nano_ns: t.nanosecond() as i32,
        fix_type: 3,
        flags: crate::ubx::NavPvt::GNSS_FIX_OK
            | if m.validity & GnssFixV1::DIFFERENTIAL != 0 {
                crate::ubx::NavPvt::DIFF_SOLN
            } else {
                0
            },
        satellites: m.satellites.min(255) as u8,
        longitude_deg: m.longitude_rad.to_degrees(),
        latitude_deg: m.latitude_rad.to_degrees(),
        height_m: m.height_m,
        height_msl_m: m.height_m,
        horizontal_accuracy_m: m.horizontal_std_m,
        vertical_accuracy_m: m.vertical_std_m,
        velocity_ned_m_s: m.velocity_ned_m_s,
        speed_accuracy_m_s: 0.05,
        pdop: 1.2,
    };
    crate::ubx::encode_nav_pvt(&p)
}

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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::device::{DeviceDecoder, Output, Protocol, ProtocolSettings};

    fn decode_one(protocol: Protocol, settings: ProtocolSettings, bytes: &[u8]) -> Output {
        let mut d = DeviceDecoder::new(protocol, settings);
        d.push(bytes);
        let out = d.next_output(5_000_000_000).expect("one message");
        assert!(d.next_output(0).is_none());
        let s = d.stats();
        assert_eq!(
            (s.checksum_errors, s.malformed, s.bytes_skipped),
            (0, 0, 0),
            "{s:?}"
        );
        out
    }

    fn dvl() -> DvlVelocityV1 {
        DvlVelocityV1 {
            host_time_ns: 5_000_000_000,
            device_time_ns: 812_345_670_000_000,
            validity_time_ns: 5_000_000_000,
            velocity_dvl_m_s: [1.234, -0.056, 0.011],
            velocity_std_m_s: [0.01, 0.01, 0.02],
            altitude_m: 12.5,
            figure_of_merit_m_s: 0.004,
            sound_speed_m_s: 1502.0,
            validity: DvlVelocityV1::VALID_VELOCITY
                | DvlVelocityV1::VALID_ALTITUDE
                | DvlVelocityV1::VALID_FOM
                | DvlVelocityV1::VALID_SOUND_SPEED
                | DvlVelocityV1::VALID_DEVICE_TIME
                | DvlVelocityV1::VALID_STD,
            ..Default::default()
        }
    }

    /// A PD0 ensemble whose bottom-track block carries the water-mass reference layer gives the
    /// bottom track and then the water track of the same ping: the vehicle's velocity relative
    /// to the water, flagged, in the DVL frame as bottom track is.
    #[test]
    fn a_pd0_reference_layer_is_published_as_water_track() {
        let m = dvl();
        let mut decoder = pd0::Pd0Decoder::new();
        decoder.push(&pd0_from_dvl(&m, 3));
        let mut e = decoder
            .next_ensemble()
            .expect("an ensemble")
            .expect("a good ensemble");
        let current_dvl = [0.2, -0.1, 0.0];
        let bt = e.bottom_track.as_mut().expect("bottom track");
        // The water relative to the instrument: the bottom's plus the current, in instrument
        // axes (x, y, z) = (DVL y, DVL x, -DVL z) as the encoder writes them.
        for k in 0..3 {
            let bottom = bt.velocity_m_s[k].expect("bottom velocity");
            let c = [current_dvl[1], current_dvl[0], -current_dvl[2]][k];
            bt.reference_layer_velocity_m_s[k] = Some(bottom + c);
            bt.reference_layer_percent_good[k] = 100;
        }
        bt.reference_layer_percent_good[3] = 100;
        bt.reference_layer_velocity_m_s[3] = Some(0.0);
        let mut d = DeviceDecoder::new(Protocol::Pd0, ProtocolSettings::default());
        d.push(&pd0::encode_ensemble(&e));
        let Some(Output::Dvl(bottom)) = d.next_output(5_000_000_000) else {
            panic!("no bottom track")
        };
        let Some(Output::Dvl(water)) = d.next_output(5_000_000_000) else {
            panic!("no water track")
        };
        assert!(d.next_output(5_000_000_000).is_none());
        assert!(!bottom.is_water_track() && water.is_water_track());
        for ((got, v), c) in water
            .velocity_dvl_m_s
            .iter()
            .zip(m.velocity_dvl_m_s)
            .zip(current_dvl)
        {
            assert!((got - (v - c)).abs() < 1.5e-3, "{water:?}");
        }
        assert_eq!(water.validity_time_ns, bottom.validity_time_ns);
    }

    #[test]
    fn pd0_round_trip_keeps_velocity_altitude_and_clock() {
        let m = dvl();
        let Output::Dvl(back) = decode_one(
            Protocol::Pd0,
            ProtocolSettings::default(),
            &pd0_from_dvl(&m, 77),
        ) else {
            panic!("not a DVL message")
        };
        for i in 0..3 {
            assert!((back.velocity_dvl_m_s[i] - m.velocity_dvl_m_s[i]).abs() <= 0.0005);
        }
        assert!((back.altitude_m - 12.5).abs() < 0.01);
        assert_eq!(back.device_time_ns, 812_345_670_000_000);
        assert_eq!(back.sound_speed_m_s, 1502.0);
        assert_eq!(back.beams_used, 4);
        // A slant range is the vertical one over cos 30°.
        assert!((back.beam_range_m[0] - 12.5 / 30f64.to_radians().cos()).abs() < 0.01);
        let invalid = DvlVelocityV1 {
            validity: DvlVelocityV1::VALID_ALTITUDE,
            ..m
        };
        let Output::Dvl(back) = decode_one(
            Protocol::Pd0,
            ProtocolSettings::default(),
            &pd0_from_dvl(&invalid, 78),
        ) else {
            panic!("not a DVL message")
        };
        assert_eq!(back.validity & DvlVelocityV1::VALID_VELOCITY, 0);
    }

    #[test]
    fn nortek_round_trip_keeps_velocity_altitude_sound_speed_and_clock() {
        let m = dvl();
        let settings = ProtocolSettings {
            latency_s: 0.05,
            ..Default::default()
        };
        let Output::Dvl(back) = decode_one(Protocol::Nortek, settings, &nortek_from_dvl(&m)) else {
            panic!("not a DVL message")
        };
        for i in 0..3 {
            assert!((back.velocity_dvl_m_s[i] - m.velocity_dvl_m_s[i]).abs() < 1e-6);
        }
        assert!((back.altitude_m - 12.5).abs() < 1e-6);
        assert_eq!(back.sound_speed_m_s, 1502.0);
        assert_eq!(back.device_time_ns, 812_345_670_000_000);
        assert_eq!(back.validity_time_ns, 5_000_000_000 - 50_000_000);
        assert_eq!(back.beams_used, 4);
        assert!((back.figure_of_merit_m_s - 0.004).abs() < 1e-6);
        let invalid = DvlVelocityV1 {
            validity: DvlVelocityV1::VALID_ALTITUDE,
            ..m
        };
        let Output::Dvl(back) = decode_one(Protocol::Nortek, settings, &nortek_from_dvl(&invalid))
        else {
            panic!("not a DVL message")
        };
        assert_eq!(back.validity & DvlVelocityV1::VALID_VELOCITY, 0);
        assert_eq!(back.beams_used, 0);
    }

    #[test]
    fn pd0_in_beam_coordinates_gives_the_same_velocity() {
        let m = dvl();
        let Output::Dvl(back) = decode_one(
            Protocol::Pd0,
            ProtocolSettings::default(),
            &pd0_beam_from_dvl(&m, 9),
        ) else {
            panic!("not a DVL message")
        };
        assert_ne!(back.validity & DvlVelocityV1::VALID_VELOCITY, 0);
        assert_eq!(back.beams_used, 4);
        for i in 0..3 {
            // Four beams at 1 mm/s resolution through the transformation.
            assert!((back.velocity_dvl_m_s[i] - m.velocity_dvl_m_s[i]).abs() < 0.002);
        }
    }

    /// Body FRD to NED for roll, pitch, yaw (ZYX).
    fn body_to_ned(e: [f64; 3]) -> [[f64; 3]; 3] {
        let (sr, cr) = e[0].sin_cos();
        let (sp, cp) = e[1].sin_cos();
        let (sy, cy) = e[2].sin_cos();
        [
            [cp * cy, sr * sp * cy - cr * sy, cr * sp * cy + sr * sy],
            [cp * sy, sr * sp * sy + cr * cy, cr * sp * sy - sr * cy],
            [-sp, sr * cp, cr * cp],
        ]
    }

    /// RDI's instrument-to-earth matrix is the vehicle's attitude: for a DVL along the vehicle's
    /// axes, the earth velocity the emulator writes is the body velocity rotated by the attitude
    /// (in east, north, up), and the driver rotates it back to the velocity played.
    #[test]
    fn pd0_in_earth_coordinates_is_the_attitude_and_round_trips() {
        let m = dvl();
        for euler_deg in [
            [0.0, 0.0, 90.0],
            [3.0, -7.0, 213.0],
            [-12.0, 15.0, 359.99],
            [25.0, 30.0, 45.0],
        ] {
            let euler = euler_deg.map(|d: f64| d.to_radians());
            let bytes = pd0_earth_from_dvl(&m, 4, euler);
            let mut decoder = pd0::Pd0Decoder::new();
            decoder.push(&bytes);
            let e = decoder
                .next_ensemble()
                .expect("one ensemble")
                .expect("valid");
            assert_eq!(
                e.fixed.as_ref().map(|f| f.coordinate_system),
                Some(CoordinateSystem::Earth)
            );
            // The bottom's velocity in east, north, up against the body velocity rotated by the
            // attitude (NED), negated.
            let c = body_to_ned(euler);
            let v = m.velocity_dvl_m_s;
            let ned: [f64; 3] = std::array::from_fn(|i| (0..3).map(|j| c[i][j] * v[j]).sum());
            let enu_bottom = [-ned[1], -ned[0], ned[2]];
            let got = e.bottom_track.as_ref().expect("bottom track").velocity_m_s;
            for i in 0..3 {
                let g = got[i].expect("velocity");
                // 0.01° angles and 1 mm/s.
                assert!(
                    (g - enu_bottom[i]).abs() < 0.002,
                    "{euler_deg:?} {got:?} {enu_bottom:?}"
                );
            }
            let Output::Dvl(back) = decode_one(Protocol::Pd0, ProtocolSettings::default(), &bytes)
            else {
                panic!("not a DVL message")
            };
            assert_ne!(back.validity & DvlVelocityV1::VALID_VELOCITY, 0);
            for i in 0..3 {
                assert!(
                    (back.velocity_dvl_m_s[i] - m.velocity_dvl_m_s[i]).abs() < 0.002,
                    "{euler_deg:?}: {:?} against {:?}",
                    back.velocity_dvl_m_s,
                    m.velocity_dvl_m_s
                );
            }
        }
    }

    #[test]
    fn water_linked_round_trip_keeps_latency() {
        let m = dvl();
        let Output::Dvl(back) = decode_one(
            Protocol::Wldvl,
            ProtocolSettings::default(),
            &wrz_from_dvl(&m, 0.15),
        ) else {
            panic!("not a DVL message")
        };
        assert_eq!(back.validity_time_ns, 5_000_000_000 - 150_000_000);
        for i in 0..3 {
            assert!((back.velocity_dvl_m_s[i] - m.velocity_dvl_m_s[i]).abs() <= 0.0005);
            assert!((back.velocity_std_m_s[i] - m.velocity_std_m_s[i]).abs() < 1e-6);
        }
    }

    fn imu(status: u32) -> ImuSampleV1 {
        ImuSampleV1 {
            host_time_ns: 5_000_000_000,
            device_time_ns: 123_456_700_000,
            angular: [0.01, -0.2, 0.003],
            specific: [0.1, -0.05, -9.81],
            interval_s: 0.0025,
            temperature_c: 21.5,
            status: status
                | ImuSampleV1::STATUS_GYRO_VALID
                | ImuSampleV1::STATUS_ACCEL_VALID
                | ImuSampleV1::STATUS_TEMPERATURE_VALID
                | ImuSampleV1::STATUS_DEVICE_TIME_VALID,
            ..Default::default()
        }
    }

    #[test]
    fn xsens_round_trip_in_rate_and_increment_mode() {
        for status in [0, ImuSampleV1::STATUS_INCREMENTS] {
            let mut m = imu(status);
            if status != 0 {
                m.angular = m.angular.map(|w| w * 0.0025);
                m.specific = m.specific.map(|a| a * 0.0025);
            }
            let settings = ProtocolSettings {
                xsens_rate_hz: 400.0,
                ..Default::default()
            };
            let Output::Imu(back) = decode_one(Protocol::Xsens, settings, &xsens_from_imu(&m, 9))
            else {
                panic!("not an IMU message")
            };
            assert_eq!(back.status, m.status);
            assert_eq!(back.device_time_ns, m.device_time_ns);
            assert_eq!(back.interval_s, 0.0025);
            for i in 0..3 {
                let tol = 1e-6 * m.angular[i].abs().max(1e-9);
                assert!((back.angular[i] - m.angular[i]).abs() <= tol, "{i}");
                assert!((back.specific[i] - m.specific[i]).abs() <= 1e-6 * m.specific[i].abs());
            }
        }
    }

    #[test]
    fn xsens_magnetic_field_round_trips_and_shares_a_packet_with_inertial_data() {
        let m = MagnetometerV1 {
            host_time_ns: 5_000_000_000,
            device_time_ns: 123_456_700_000,
            field_t: [21.5e-6, -3.25e-6, 41.0e-6],
            temperature_c: 12.5,
            validity: MagnetometerV1::VALID_FIELD
                | MagnetometerV1::VALID_TEMPERATURE
                | MagnetometerV1::VALID_DEVICE_TIME,
            ..Default::default()
        };
        let settings = ProtocolSettings {
            xsens_field_unit_ut: 48.0,
            ..Default::default()
        };
        let Output::Magnetometer(back) = decode_one(
            Protocol::Xsens,
            settings,
            &xsens_from_magnetometer(&m, 48.0, 3),
        ) else {
            panic!("not a magnetometer message")
        };
        assert_eq!(back.validity, m.validity);
        assert_eq!(back.device_time_ns, m.device_time_ns);
        assert_eq!(back.temperature_c, m.temperature_c);
        for i in 0..3 {
            assert!((back.field_t[i] - m.field_t[i]).abs() <= 1e-7 * m.field_t[i].abs());
        }
        // An invalid field travels as NaN and comes back without VALID_FIELD.
        let bad = MagnetometerV1 { validity: 0, ..m };
        let Output::Magnetometer(back) = decode_one(
            Protocol::Xsens,
            settings,
            &xsens_from_magnetometer(&bad, 48.0, 4),
        ) else {
            panic!("not a magnetometer message")
        };
        assert_eq!(back.validity & MagnetometerV1::VALID_FIELD, 0);
        // One packet with rate of turn, acceleration and the field: two messages, IMU first.
        let both = xsens::encode_mtdata2(&MtData2 {
            packet_counter: Some(7),
            rate_of_turn: Some([0.01, 0.02, 0.03]),
            acceleration: Some([0.0, 0.0, -9.8]),
            magnetic_field: Some([0.4, 0.1, 0.8]),
            ..Default::default()
        });
        let mut d = DeviceDecoder::new(Protocol::Xsens, settings);
        d.push(&both);
        assert!(matches!(d.next_output(1), Some(Output::Imu(_))));
        let Some(Output::Magnetometer(b)) = d.next_output(1) else {
            panic!("the field of the packet was not published")
        };
        assert!((b.field_t[2] - 0.8 * 48e-6).abs() < 1e-12);
        assert!(d.next_output(1).is_none());
        assert_eq!(d.counters().other_frames, 0);
    }

    #[test]
    fn kvh_round_trip_and_counter_gaps_are_counted() {
        let m = imu(0);
        let settings = ProtocolSettings::default();
        let mut d = DeviceDecoder::new(Protocol::Kvh1750, settings);
        for counter in [126u8, 127, 0, 3] {
            d.push(&kvh_from_imu(&m, &settings.kvh, counter));
        }
        let mut n = 0;
        while let Some(Output::Imu(back)) = d.next_output(1) {
            n += 1;
            assert_eq!(back.device_time_ns, m.device_time_ns);
            for i in 0..3 {
                assert!((back.angular[i] - m.angular[i]).abs() <= 1e-7 * m.angular[i].abs());
                assert!((back.specific[i] - m.specific[i]).abs() <= 1e-6 * m.specific[i].abs());
            }
        }
        assert_eq!(n, 4);
        assert_eq!(d.counters().device_gaps, 2);
    }

    #[test]
    fn seatrac_round_trip_at_device_resolution() {
        let m = UsblFixV1 {
            host_time_ns: 5_000_000_000,
            validity_time_ns: 5_000_000_000,
            slant_range_m: 123.4,
            azimuth_rad: (-35.2f64).to_radians(),
            elevation_rad: (12.3f64).to_radians(),
            position_array_m: [-80.1, 60.2, 55.5],
            sound_speed_m_s: 1490.5,
            rssi_db: [-60.0, -61.5, -59.0, -62.0],
            fit_error_m: 0.25,
            beacon_id: 15,
            validity: UsblFixV1::VALID_RANGE
                | UsblFixV1::VALID_ANGLES
                | UsblFixV1::VALID_POSITION
                | UsblFixV1::VALID_SOUND_SPEED
                | UsblFixV1::VALID_RSSI
                | UsblFixV1::VALID_FIT_ERROR,
            ..Default::default()
        };
        let Output::Usbl(back) = decode_one(
            Protocol::Seatrac,
            ProtocolSettings::default(),
            &seatrac_from_usbl(&m, 1),
        ) else {
            panic!("not a USBL message")
        };
        assert_eq!(back.validity, m.validity);
        assert!((back.slant_range_m - m.slant_range_m).abs() < 0.051);
        assert!((back.travel_time_s - 123.4 / 1490.5).abs() < 1e-4);
        assert!((back.azimuth_rad - m.azimuth_rad).abs() < 0.051f64.to_radians());
        assert!((back.elevation_rad - m.elevation_rad).abs() < 0.051f64.to_radians());
        for i in 0..3 {
            assert!((back.position_array_m[i] - m.position_array_m[i]).abs() < 0.051);
        }
        assert_eq!(back.beacon_id, 15);
        assert_eq!(back.rssi_db, m.rssi_db);
    }

    #[test]
    fn pd0_clock_round_trips_through_calendar_dates() {
        for ns in [
            0u64,
            86_399_990_000_000,
            1_700_000_000_120_000_000,
            2_000_000_000_990_000_000,
        ] {
            assert_eq!(crate::to_schema::pd0_rtc_ns(&pd0_rtc(ns)), Some(ns));
        }
    }

    fn gnss() -> GnssFixV1 {
        GnssFixV1 {
            host_time_ns: 5_000_000_000,
            latitude_rad: (-45.877_591_5f64).to_radians(),
            longitude_rad: 170.500_124_8f64.to_radians(),
            height_m: 16.25,
            velocity_ned_m_s: [1.2, -0.7, 0.0],
            horizontal_std_m: 1.5,
            vertical_std_m: 3.0,
            satellites: 14,
            validity: GnssFixV1::VALID_POSITION
                | GnssFixV1::VALID_HEIGHT
                | GnssFixV1::VALID_VELOCITY
                | GnssFixV1::DIFFERENTIAL,
            ..Default::default()
        }
    }

    fn same_fix(back: &GnssFixV1, m: &GnssFixV1, utc_ns: i64, velocity_tol: f64) {
        assert_eq!(back.validity, m.validity | GnssFixV1::VALID_DEVICE_TIME);
        // 1e-7 arc minute and 1e-7 degree are below 2 cm.
        assert!((back.latitude_rad - m.latitude_rad).abs() * 6.4e6 < 0.02);
        assert!((back.longitude_rad - m.longitude_rad).abs() * 6.4e6 < 0.02);
        assert!((back.height_m - m.height_m).abs() < 1e-3);
        assert!((back.horizontal_std_m - m.horizontal_std_m).abs() < 1e-3);
        assert!((back.vertical_std_m - m.vertical_std_m).abs() < 1e-3);
        for k in 0..3 {
            assert!((back.velocity_ned_m_s[k] - m.velocity_ned_m_s[k]).abs() < velocity_tol);
        }
        assert_eq!(back.satellites, m.satellites);
        let gps = crate::gnss::gps_time_ns(utc_ns, 18).expect("a value");
        assert!(back.device_time_ns.abs_diff(gps) < 10_000_000, "{back:?}");
    }

    #[test]
    fn gnss_round_trips_through_nmea_and_ubx() {
        let m = gnss();
        let utc_ns = 1_795_596_601_234_000_000;
        let Output::Gnss(back) = decode_one(
            Protocol::Ubx,
            ProtocolSettings::default(),
            &ubx_from_gnss(&m, utc_ns),
        ) else {
            panic!("not a fix")
        };
        same_fix(&back, &m, utc_ns, 1e-3);
        assert_eq!(back.host_time_ns, 5_000_000_000);
        // An NMEA epoch ends when the next one begins.
        let mut bytes = nmea_from_gnss(&m, utc_ns);
        bytes.extend(nmea_from_gnss(&m, utc_ns + 1_000_000_000));
        let mut d = DeviceDecoder::new(Protocol::Nmea, ProtocolSettings::default());
        d.push(&bytes);
        let Some(Output::Gnss(back)) = d.next_output(7_000_000_000) else {
            panic!("no fix")
        };
        same_fix(&back, &m, utc_ns, 2e-3);
        assert_eq!(back.host_time_ns, 7_000_000_000);
        // The second is complete at its last sentence: the receiver's set is known by then.
        assert!(matches!(
            d.next_output(7_000_000_000),
            Some(Output::Gnss(_))
        ));
        assert_eq!(d.next_output(7_000_000_000), None);
        assert_eq!(d.stats().frames, 8);
        assert_eq!(d.stats().bytes_skipped, 0);
    }
}
