//! Teledyne RDI PD0: schema messages encoded in its protocol (emulation).

use super::to_schema::pd0_rtc;
use crate::pd0::{self, BottomTrack, CoordinateSystem, Ensemble, FixedLeader, VariableLeader};
use crate::schema_rules::*;
use auvnav_shm_schema::DvlVelocityV1;

/// System configuration word of the emulated PD0 DVL: 600 kHz, convex, 30° beams, down-looking,
/// 4-beam Janus.
pub const PD0_SYSTEM_CONFIGURATION: u16 = 0x4000 | 0x0200 | 0x0008 | 0x0003;

/// EX command byte of the emulated PD0 DVL: instrument coordinates.
pub const PD0_COORDINATE_TRANSFORM: u8 = 0x08;

/// Beam angle of the emulated PD0 DVL (deg).
pub const PD0_BEAM_ANGLE_DEG: f64 = 30.0;

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
