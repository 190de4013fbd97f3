//! Nortek DVL: schema messages encoded in its protocol (emulation).

use crate::nortek;
use crate::schema_rules::*;
use auvnav_shm_schema::DvlVelocityV1;

/// Beam angle of the emulated Nortek DVL (deg, the DVL1000's).
pub const NORTEK_BEAM_ANGLE_DEG: f64 = 25.0;

/// A DVL message as a Nortek bottom-track record of a down-looking DVL with beam 1 forward (see
/// [`super::to_schema::nortek_velocity`]): X, Y, Z1 = Z2 the velocity, beam velocities its
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
