//! Teledyne RDI PD0: ensembles of the Workhorse, Pioneer/Pathfinder, Ocean Surveyor, Rio Grande,
//! Sentinel and their relatives.
//!
//! Long on purpose: PD0 is one format whose leaders, bottom track and
//! vendor blocks share one ensemble layout, one table of block IDs and one checksum; split, the
//! offsets of one ensemble would live in several places.
//!
//! Framing: `7F 7F`, u16 number of bytes `n` (header to the end of the last block, without the
//! checksum), a spare byte, the number of data types, one u16 offset per data type (from the
//! `7F`), the data blocks (each starting with its u16 ID), then a u16 checksum: the sum of the
//! `n` bytes modulo 65536. All little-endian.
//!
//! Decoded blocks: fixed leader (0x0000), variable leader (0x0080), bottom track (0x0600, with the
//! high byte of the range), Pioneer-class high-resolution bottom track (0x5803) and bottom-track
//! range (0x5804), WinRiver II NMEA (0x2022: GGA, VTG, DBT, HDT) and the VmDas navigation block
//! (0x2000). Every other ID (profile data 0x0100–0x0500, 5th-beam, Sentinel V blocks, ...) is
//! skipped by its offset and listed in [`Ensemble::other_ids`]. A block shorter than a field
//! leaves that field out; nothing panics on any input.
//!
//! **Bottom-track sign convention**: PD0 reports the velocity of the *bottom relative to the
//! instrument* (beam, instrument, ship or earth axes as the EX command says). The vehicle's
//! velocity over the ground is the negative: [`BottomTrack::vehicle_velocity_m_s`] returns it.
//! Raw values are kept as recorded; -32768 (velocity) and 0 (range) mean "no value" and are `None`.

pub mod to_device;
pub mod to_schema;

use crate::framing::{DecoderStats, FrameBuffer, ReadLe};
use serde::Serialize;

pub const SYNC: [u8; 2] = [0x7f, 0x7f];
pub const ID_FIXED_LEADER: u16 = 0x0000;
pub const ID_VARIABLE_LEADER: u16 = 0x0080;
pub const ID_BOTTOM_TRACK: u16 = 0x0600;
pub const ID_VMDAS_NAVIGATION: u16 = 0x2000;
pub const ID_WINRIVER2_NMEA: u16 = 0x2022;
pub const ID_HIGH_RES_BOTTOM_TRACK: u16 = 0x5803;
pub const ID_BOTTOM_TRACK_RANGE: u16 = 0x5804;
/// The PD0 "no velocity" value.
pub const BAD_VELOCITY: i16 = -32768;
/// Largest ensemble the decoder buffers (the length field is a u16).
pub const MAX_ENSEMBLE: usize = 65535 + 2;

/// Coordinate system of velocities (EX command bits 4–3).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum CoordinateSystem {
    Beam,
    Instrument,
    Ship,
    Earth,
}

#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct FixedLeader {
    pub firmware_version: u8,
    pub firmware_revision: u8,
    /// System configuration word (frequency, beam pattern, orientation, beam angle bits).
    pub system_configuration: u16,
    pub beams: u8,
    pub cells: u8,
    pub pings_per_ensemble: u16,
    pub cell_size_m: f64,
    pub blank_m: f64,
    /// EX command byte.
    pub coordinate_transform: u8,
    pub coordinate_system: CoordinateSystem,
    /// EA heading alignment (deg).
    pub heading_alignment_deg: f64,
    /// EB heading bias (deg).
    pub heading_bias_deg: f64,
    pub sensor_source: u8,
    pub sensors_available: u8,
    pub bin1_distance_m: f64,
    pub transmit_pulse_m: f64,
    /// Instrument serial number (absent in old firmware).
    pub serial_number: Option<u32>,
    /// Beam angle from the system configuration word (deg).
    pub beam_angle_deg: Option<f64>,
    /// Transducer faces up (system configuration bit 7).
    pub upward_looking: bool,
    pub frequency_khz: Option<u32>,
}

#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct VariableLeader {
    /// Ensemble number including the most significant byte.
    pub ensemble_number: u32,
    /// Real-time clock: year (two digits), month, day, hour, minute, second, hundredths.
    pub rtc: [u8; 7],
    /// Y2K clock when present: century, year, month, day, hour, minute, second, hundredths.
    pub rtc_y2k: Option<[u8; 8]>,
    pub bit_result: u16,
    pub sound_speed_m_s: f64,
    /// Depth of the transducer (m).
    pub depth_m: f64,
    pub heading_deg: f64,
    pub pitch_deg: f64,
    pub roll_deg: f64,
    pub salinity_ppt: f64,
    pub temperature_c: f64,
    /// Pressure (Pa) when the block has it (signed: slightly negative at the surface).
    pub pressure_pa: Option<f64>,
}

#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct BottomTrack {
    pub pings_per_ensemble: u16,
    /// Vertical range to the bottom per beam (m), with the high byte; `None` when 0.
    pub range_m: [Option<f64>; 4],
    /// Bottom velocity relative to the instrument as recorded (m/s): beams 1–4 in beam
    /// coordinates, or x, y, z, error velocity otherwise; `None` for -32768.
    pub velocity_m_s: [Option<f64>; 4],
    pub correlation: [u8; 4],
    pub evaluation_amplitude: [u8; 4],
    pub percent_good: [u8; 4],
    /// Maximum tracking depth (m).
    pub max_depth_m: f64,
    /// The water-mass reference layer's velocity relative to the instrument (m/s), in the same
    /// coordinates and sign convention as `velocity_m_s`; `None` for -32768 or a beam whose
    /// reference-layer percent good is 0 (a layer not computed).
    pub reference_layer_velocity_m_s: [Option<f64>; 4],
    /// Reference-layer percent good per beam.
    pub reference_layer_percent_good: [u8; 4],
}

/// RDI's instrument-to-earth rotation `M` for heading `H`, pitch `P` and roll `R` (deg):
/// `(E, N, U) = M (x, y, z)` with rows `[cH cR + sH sP sR, sH cP, cH sR − sH sP cR]`,
/// `[−sH cR + cH sP sR, cH cP, −sH sR − cH sP cR]`, `[−cP sR, sP, cP cR]` (the coordinate
/// transformation of RDI's manuals; it is the aerospace yaw–pitch–roll rotation of the
/// instrument, y forward, x starboard, z up). The pitch used is the gimbal pitch computed from the
/// recorded tilt, `P = atan(tan(tilt1) cos(tilt2))`; with the "tilts used" bit of EX clear, pitch
/// and roll are 0; an upward-looking head adds 180° to the roll.
pub fn instrument_to_earth_matrix(
    heading_deg: f64,
    tilt1_deg: f64,
    tilt2_deg: f64,
    tilts_used: bool,
    upward_looking: bool,
) -> [[f64; 3]; 3] {
    let (mut p, mut r) = if tilts_used {
        let r = tilt2_deg.to_radians();
        ((tilt1_deg.to_radians().tan() * r.cos()).atan(), r)
    } else {
        (0.0, 0.0)
    };
    if upward_looking {
        r += std::f64::consts::PI;
    }
    if !p.is_finite() {
        p = 0.0;
    }
    let (sh, ch) = heading_deg.to_radians().sin_cos();
    let (sp, cp) = p.sin_cos();
    let (sr, cr) = r.sin_cos();
    [
        [ch * cr + sh * sp * sr, sh * cp, ch * sr - sh * sp * cr],
        [-sh * cr + ch * sp * sr, ch * cp, -sh * sr - ch * sp * cr],
        [-cp * sr, sp, cp * cr],
    ]
}

/// EX bit 2: the device used its tilts in the coordinate transformation.
pub const EX_TILTS_USED: u8 = 0x04;

/// An earth-coordinate velocity (east, north, up) back in instrument coordinates, `Mᵀ v`, with
/// the ensemble's own heading, pitch and roll and EX bits ([`instrument_to_earth_matrix`]);
/// `None` without the leaders.
pub fn earth_to_instrument(e: &Ensemble, enu: [f64; 3]) -> Option<[f64; 3]> {
    let (f, v) = (e.fixed.as_ref()?, e.variable.as_ref()?);
    let m = instrument_to_earth_matrix(
        v.heading_deg,
        v.pitch_deg,
        v.roll_deg,
        f.coordinate_transform & EX_TILTS_USED != 0,
        f.upward_looking,
    );
    Some(std::array::from_fn(|j| {
        (0..3).map(|i| m[i][j] * enu[i]).sum::<f64>()
    }))
}

/// Bottom velocity relative to the instrument in instrument coordinates from beam velocities:
/// RDI's transformation for a four-beam Janus head with beams `beam_angle_deg` from the
/// vertical, convex or concave (`x = ±a (b1 − b2)`, `y = ±a (b4 − b3)`, `z = b Σ bᵢ`, error
/// velocity `d (b1 + b2 − b3 − b4)`, `a = 1/(2 sin θ)`, `b = 1/(4 cos θ)`, `d = a/√2`). With one
/// beam bad, the three-beam solution: the missing beam is the one that makes the error velocity
/// zero (returned as `None`). `None` with fewer than three beams or a beam angle outside
/// (0°, 60°).
pub fn beam_to_instrument(
    beams: &[Option<f64>; 4],
    beam_angle_deg: f64,
    convex: bool,
) -> Option<([f64; 3], Option<f64>)> {
    if !(beam_angle_deg > 0.0 && beam_angle_deg < 60.0) {
        return None;
    }
    let mut b = [0.0; 4];
    let missing: Vec<usize> = (0..4).filter(|&i| beams[i].is_none()).collect();
    for (i, v) in beams.iter().enumerate() {
        b[i] = v.unwrap_or(0.0);
    }
    match missing.as_slice() {
        [] => {}
        // b1 + b2 = b3 + b4 solved for the missing beam.
        [0] => b[0] = b[2] + b[3] - b[1],
        [1] => b[1] = b[2] + b[3] - b[0],
        [2] => b[2] = b[0] + b[1] - b[3],
        [3] => b[3] = b[0] + b[1] - b[2],
        _ => return None,
    }
    let th = beam_angle_deg.to_radians();
    let a = 1.0 / (2.0 * th.sin());
    let bz = 1.0 / (4.0 * th.cos());
    let d = a / std::f64::consts::SQRT_2;
    let c = if convex { 1.0 } else { -1.0 };
    let xyz = [
        c * a * (b[0] - b[1]),
        c * a * (b[3] - b[2]),
        bz * (b[0] + b[1] + b[2] + b[3]),
    ];
    let error = missing.is_empty().then(|| d * (b[0] + b[1] - b[2] - b[3]));
    Some((xyz, error))
}

impl BottomTrack {
    /// The vehicle's velocity over the bottom (the negative of what PD0 records), first three
    /// components, when all three are valid.
    pub fn vehicle_velocity_m_s(&self) -> Option<[f64; 3]> {
        Some([
            -self.velocity_m_s[0]?,
            -self.velocity_m_s[1]?,
            -self.velocity_m_s[2]?,
        ])
    }
}

/// Pioneer/Pathfinder 0x5803: bottom-track velocity at 0.01 mm/s and distance made good.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct HighResBottomTrack {
    /// The instrument's velocity over the bottom: same axes as [`BottomTrack::velocity_m_s`]
    /// but the *opposite sign* (the Pioneer sample in ../shared/protocols shows 0x0600 at
    /// -0.023 m/s and 0x5803 at +0.02295 m/s for beam 1); `None` for i32::MIN.
    pub instrument_velocity_m_s: [Option<f64>; 4],
    /// Distance made good (m).
    pub distance_made_good_m: [Option<f64>; 4],
    pub water_mass_velocity_m_s: [Option<f64>; 4],
    pub water_mass_distance_made_good_m: [Option<f64>; 4],
    pub sound_speed_m_s: Option<f64>,
}

/// Pioneer/Pathfinder 0x5804: bottom-track ranges at 0.1 mm.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct BottomTrackRange {
    pub slant_range_m: f64,
    pub axis_delta_range_m: f64,
    pub vertical_range_m: f64,
    pub percent_good_4_beam: u8,
    pub percent_good_beams_1_2: u8,
    pub percent_good_beams_3_4: u8,
    pub raw_range_m: [f64; 4],
}

/// One WinRiver II NMEA block (0x2022), as WinRiver re-encodes the sentence.
#[derive(Debug, Clone, PartialEq, Serialize)]
#[serde(tag = "sentence", rename_all = "snake_case")]
pub enum NmeaBlock {
    Gga {
        /// Seconds between the sentence and the ensemble as WinRiver recorded it.
        delta_time_s: f64,
        utc: String,
        latitude_deg: f64,
        longitude_deg: f64,
        fix_quality: u8,
        satellites: u8,
        hdop: f32,
        altitude_m: f32,
    },
    Vtg {
        delta_time_s: f64,
        true_track_deg: f32,
        speed_over_ground_m_s: f64,
    },
    Dbt {
        delta_time_s: f64,
        depth_m: f32,
    },
    Hdt {
        delta_time_s: f64,
        heading_deg: f64,
    },
    /// A block without a sentence (the GPS had nothing) or of another kind.
    Empty {
        specific_id: u16,
    },
}

/// VmDas navigation block (0x2000): the last fix before the ping.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct VmdasNavigation {
    pub latitude_deg: f64,
    pub longitude_deg: f64,
    pub first_latitude_deg: f64,
    pub first_longitude_deg: f64,
    pub average_speed_m_s: f64,
    pub average_track_deg: f64,
}

/// One decoded ensemble.
#[derive(Debug, Clone, Default, PartialEq, Serialize)]
pub struct Ensemble {
    pub fixed: Option<FixedLeader>,
    pub variable: Option<VariableLeader>,
    pub bottom_track: Option<BottomTrack>,
    pub high_res_bottom_track: Option<HighResBottomTrack>,
    pub bottom_track_range: Option<BottomTrackRange>,
    pub nmea: Vec<NmeaBlock>,
    pub vmdas: Option<VmdasNavigation>,
    /// IDs of the blocks skipped by offset.
    pub other_ids: Vec<u16>,
    /// Size of the ensemble on the wire (bytes, with the checksum).
    pub size: usize,
}

/// Why a checksum-valid ensemble could not be decoded.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum Pd0Error {
    #[error("header too short for {types} data types in {bytes} bytes")]
    BadHeader { types: usize, bytes: usize },
    #[error("data type offset {offset} outside the ensemble of {bytes} bytes")]
    BadOffset { offset: usize, bytes: usize },
}

fn checksum(bytes: &[u8]) -> u16 {
    bytes
        .iter()
        .fold(0u16, |acc, &b| acc.wrapping_add(u16::from(b)))
}

fn scaled_i16(v: Option<i16>, scale: f64) -> Option<f64> {
    v.filter(|&x| x != BAD_VELOCITY)
        .map(|x| f64::from(x) * scale)
}

fn scaled_i32(v: Option<i32>, scale: f64) -> Option<f64> {
    v.filter(|&x| x != i32::MIN).map(|x| f64::from(x) * scale)
}

fn four<T: Copy + Default>(f: impl Fn(usize) -> Option<T>) -> Option<[T; 4]> {
    Some([f(0)?, f(1)?, f(2)?, f(3)?])
}

fn fixed_leader(b: &[u8]) -> Option<FixedLeader> {
    let config = b.u16_at(4)?;
    let ex = b.u8_at(25)?;
    let coordinate_system = match (ex >> 3) & 3 {
        0 => CoordinateSystem::Beam,
        1 => CoordinateSystem::Instrument,
        2 => CoordinateSystem::Ship,
        _ => CoordinateSystem::Earth,
    };
    let frequency_khz = [75, 150, 300, 600, 1200, 2400]
        .get(usize::from(config & 7))
        .copied();
    let beam_angle_deg = match (config >> 8) & 3 {
        0 => Some(15.0),
        1 => Some(20.0),
        2 => Some(30.0),
        _ => b.u8_at(58).map(f64::from),
    };
    Some(FixedLeader {
        firmware_version: b.u8_at(2)?,
        firmware_revision: b.u8_at(3)?,
        system_configuration: config,
        beams: b.u8_at(8)?,
        cells: b.u8_at(9)?,
        pings_per_ensemble: b.u16_at(10)?,
        cell_size_m: f64::from(b.u16_at(12)?) * 0.01,
        blank_m: f64::from(b.u16_at(14)?) * 0.01,
        coordinate_transform: ex,
        coordinate_system,
        heading_alignment_deg: f64::from(b.i16_at(26)?) * 0.01,
        heading_bias_deg: f64::from(b.i16_at(28)?) * 0.01,
        sensor_source: b.u8_at(30)?,
        sensors_available: b.u8_at(31)?,
        bin1_distance_m: f64::from(b.u16_at(32)?) * 0.01,
        transmit_pulse_m: f64::from(b.u16_at(34)?) * 0.01,
        serial_number: b.u32_at(54),
        beam_angle_deg,
        upward_looking: config & 0x80 != 0,
        frequency_khz,
    })
}

fn variable_leader(b: &[u8]) -> Option<VariableLeader> {
    let rtc = [
        b.u8_at(4)?,
        b.u8_at(5)?,
        b.u8_at(6)?,
        b.u8_at(7)?,
        b.u8_at(8)?,
        b.u8_at(9)?,
        b.u8_at(10)?,
    ];
    let rtc_y2k = (|| {
        let mut r = [0u8; 8];
        for (i, v) in r.iter_mut().enumerate() {
            *v = b.u8_at(57 + i)?;
        }
        Some(r)
    })();
    Some(VariableLeader {
        ensemble_number: u32::from(b.u16_at(2)?) + (u32::from(b.u8_at(11)?) << 16),
        rtc,
        rtc_y2k,
        bit_result: b.u16_at(12)?,
        sound_speed_m_s: f64::from(b.u16_at(14)?),
        depth_m: f64::from(b.u16_at(16)?) * 0.1,
        heading_deg: f64::from(b.u16_at(18)?) * 0.01,
        pitch_deg: f64::from(b.i16_at(20)?) * 0.01,
        roll_deg: f64::from(b.i16_at(22)?) * 0.01,
        salinity_ppt: f64::from(b.u16_at(24)?),
        temperature_c: f64::from(b.i16_at(26)?) * 0.01,
        // Pressure in deca-pascals. The manual calls it unsigned, but instruments at the surface
        // record small negative readings as 0xFFFFFFFF, 0xFFFFFFFE, ...: read as signed.
        pressure_pa: b.i32_at(48).map(|p| f64::from(p) * 10.0),
    })
}

fn bottom_track(b: &[u8]) -> Option<BottomTrack> {
    let range = |i: usize| -> Option<Option<f64>> {
        let lsb = b.u16_at(16 + 2 * i)?;
        let msb = b.u8_at(77 + i).unwrap_or(0);
        let cm = u32::from(lsb) + (u32::from(msb) << 16);
        Some((cm != 0).then_some(f64::from(cm) * 0.01))
    };
    Some(BottomTrack {
        pings_per_ensemble: b.u16_at(2)?,
        range_m: four(range)?,
        velocity_m_s: four(|i| Some(scaled_i16(Some(b.i16_at(24 + 2 * i)?), 0.001)))?,
        correlation: four(|i| b.u8_at(32 + i))?,
        evaluation_amplitude: four(|i| b.u8_at(36 + i))?,
        percent_good: four(|i| b.u8_at(40 + i))?,
        max_depth_m: b.u16_at(70).map(|d| f64::from(d) * 0.1).unwrap_or(f64::NAN),
        reference_layer_velocity_m_s: four(|i| {
            let good = b.u8_at(66 + i).unwrap_or(0) > 0;
            Some(scaled_i16(b.i16_at(50 + 2 * i), 0.001).filter(|_| good))
        })?,
        reference_layer_percent_good: four(|i| Some(b.u8_at(66 + i).unwrap_or(0)))?,
    })
}

fn high_res_bottom_track(b: &[u8]) -> Option<HighResBottomTrack> {
    let q =
        |base: usize, scale: f64| four(|i| Some(scaled_i32(Some(b.i32_at(base + 4 * i)?), scale)));
    Some(HighResBottomTrack {
        instrument_velocity_m_s: q(2, 1e-5)?,
        distance_made_good_m: q(18, 1e-4)?,
        water_mass_velocity_m_s: q(34, 1e-5)?,
        water_mass_distance_made_good_m: q(50, 1e-4)?,
        sound_speed_m_s: b.u32_at(66).map(|s| f64::from(s) * 1e-6),
    })
}

fn bottom_track_range(b: &[u8]) -> Option<BottomTrackRange> {
    Some(BottomTrackRange {
        slant_range_m: f64::from(b.i32_at(2)?) * 1e-4,
        axis_delta_range_m: f64::from(b.i32_at(6)?) * 1e-4,
        vertical_range_m: f64::from(b.i32_at(10)?) * 1e-4,
        percent_good_4_beam: b.u8_at(14)?,
        percent_good_beams_1_2: b.u8_at(15)?,
        percent_good_beams_3_4: b.u8_at(16)?,
        raw_range_m: four(|i| Some(f64::from(b.u32_at(17 + 4 * i)?) * 1e-4))?,
    })
}

fn ascii(b: &[u8], at: usize, n: usize) -> Option<String> {
    let s = b.get(at..at + n)?;
    s.iter().all(|c| c.is_ascii()).then(|| {
        String::from_utf8_lossy(s)
            .trim_end_matches('\0')
            .to_string()
    })
}

/// WinRiver II NMEA block: ID, u16 specific ID (GGA 4/104, VTG 5/105, DBT 6/106, HDT 7/107),
/// u16 size, f64 delta time, then the sentence re-encoded as binary fields after its 6-character
/// talker/formatter and a separator (an empty block carries no sentence).
fn winriver2_nmea(b: &[u8]) -> Option<NmeaBlock> {
    let specific_id = b.u16_at(2)?;
    let size = usize::from(b.u16_at(4)?);
    let delta_time_s = b.f64_at(6)?;
    let body = 14; // first byte of the sentence
    let empty = NmeaBlock::Empty { specific_id };
    let has = |min: usize| size > min && b.get(body..body + 6).is_some_and(|s| s[0] == b'$');
    Some(match specific_id {
        4 | 104 if has(43) => {
            // "$GPGGA" + sep, 9-char UTC + sep, f64 lat, N/S, f64 lon, E/W, u8 fix, u8 sats,
            // f32 hdop, f32 altitude, 'M', f32 geoid, 'M', f32 age, u16 station.
            let utc = ascii(b, body + 7, 9)?;
            let mut lat = b.f64_at(body + 17)?;
            if b.u8_at(body + 25)? == b'S' {
                lat = -lat;
            }
            let mut lon = b.f64_at(body + 26)?;
            if b.u8_at(body + 34)? == b'W' {
                lon = -lon;
            }
            NmeaBlock::Gga {
                delta_time_s,
                utc,
                latitude_deg: lat,
                longitude_deg: lon,
                fix_quality: b.u8_at(body + 35)?,
                satellites: b.u8_at(body + 36)?,
                hdop: b.f32_at(body + 37)?,
                altitude_m: b.f32_at(body + 41)?,
            }
        }
        5 | 105 if has(22) => {
            // "$GPVTG" + sep, f32 true track, 'T', f32 magnetic track, 'M', f32 knots, 'N',
            // f32 km/h, 'K', mode.
            let knots = b.f32_at(body + 17)?;
            NmeaBlock::Vtg {
                delta_time_s,
                true_track_deg: b.f32_at(body + 7)?,
                speed_over_ground_m_s: f64::from(knots) * 1852.0 / 3600.0,
            }
        }
        6 | 106 if has(20) => NmeaBlock::Dbt {
            delta_time_s,
            // f32 feet, 'f', f32 metres, 'M', f32 fathoms, 'F'
            depth_m: b.f32_at(body + 12)?,
        },
        7 | 107 if has(14) => NmeaBlock::Hdt {
            delta_time_s,
            heading_deg: b.f64_at(body + 7)?,
        },
        _ => empty,
    })
}

fn vmdas_navigation(b: &[u8]) -> Option<VmdasNavigation> {
    // Binary angle measurement: i32 * 180 / 2^31 degrees.
    let bam32 = |i: usize| b.i32_at(i).map(|v| f64::from(v) * 180.0 / 2f64.powi(31));
    let bam16 = |i: usize| b.u16_at(i).map(|v| f64::from(v) * 180.0 / 2f64.powi(15));
    Some(VmdasNavigation {
        first_latitude_deg: bam32(14)?,
        first_longitude_deg: bam32(18)?,
        latitude_deg: bam32(26)?,
        longitude_deg: bam32(30)?,
        average_speed_m_s: f64::from(b.u16_at(34)?) * 1e-3,
        average_track_deg: bam16(36)?,
    })
}

/// Decodes one complete ensemble (from `7F 7F` to the checksum, already verified).
pub fn decode_ensemble(e: &[u8]) -> Result<Ensemble, Pd0Error> {
    let n = usize::from(e.u16_at(2).unwrap_or(0));
    let types = usize::from(e.u8_at(5).unwrap_or(0));
    if n < 6 + 2 * types || e.len() < n + 2 {
        return Err(Pd0Error::BadHeader { types, bytes: n });
    }
    let mut offsets = Vec::with_capacity(types);
    for k in 0..types {
        let o = usize::from(e.u16_at(6 + 2 * k).unwrap_or(0));
        if o < 6 + 2 * types || o + 2 > n {
            return Err(Pd0Error::BadOffset {
                offset: o,
                bytes: n,
            });
        }
        offsets.push(o);
    }
    let mut out = Ensemble {
        size: n + 2,
        ..Default::default()
    };
    for (k, &start) in offsets.iter().enumerate() {
        // A block ends where the next one (in address order) starts, or at the checksum.
        let end = offsets
            .iter()
            .copied()
            .filter(|&o| o > start)
            .min()
            .unwrap_or(n)
            .min(n);
        let _ = k;
        let block = &e[start..end];
        let Some(id) = block.u16_at(0) else { continue };
        match id {
            ID_FIXED_LEADER => out.fixed = fixed_leader(block),
            ID_VARIABLE_LEADER => out.variable = variable_leader(block),
            ID_BOTTOM_TRACK => out.bottom_track = bottom_track(block),
            ID_HIGH_RES_BOTTOM_TRACK => out.high_res_bottom_track = high_res_bottom_track(block),
            ID_BOTTOM_TRACK_RANGE => out.bottom_track_range = bottom_track_range(block),
            ID_WINRIVER2_NMEA => out.nmea.extend(winriver2_nmea(block)),
            ID_VMDAS_NAVIGATION => out.vmdas = vmdas_navigation(block),
            other => out.other_ids.push(other),
        }
    }
    Ok(out)
}

/// Incremental PD0 decoder: push bytes as they arrive, pull ensembles.
#[derive(Debug, Clone)]
pub struct Pd0Decoder {
    input: FrameBuffer,
    /// While waiting for a long ensemble: where the search for a later complete ensemble
    /// resumes (bytes before it were already examined), so each byte is scanned about once.
    resume: usize,
}

impl Default for Pd0Decoder {
    fn default() -> Self {
        Self::new()
    }
}

impl Pd0Decoder {
    pub fn new() -> Self {
        Pd0Decoder {
            input: FrameBuffer::new(MAX_ENSEMBLE),
            resume: 1,
        }
    }

    pub fn push(&mut self, bytes: &[u8]) {
        self.input.push(bytes);
    }

    pub fn stats(&self) -> &DecoderStats {
        &self.input.stats
    }

    /// Stream offset of the first byte of the last frame returned.
    pub fn frame_start(&self) -> u64 {
        self.input.frame_start()
    }

    fn skip(&mut self, n: usize) {
        self.resume = 1;
        self.input.skip(n);
    }

    /// The next complete ensemble, or `None` when more bytes are needed.
    pub fn next_ensemble(&mut self) -> Option<Result<Ensemble, Pd0Error>> {
        loop {
            let data = self.input.data();
            let Some(pos) = data.windows(2).position(|w| w == SYNC) else {
                // Keep a trailing 0x7F: it may be the first half of a sync.
                let keep = usize::from(data.last() == Some(&SYNC[0]));
                let n = data.len() - keep;
                if n > 0 {
                    self.skip(n);
                }
                return None;
            };
            if pos > 0 {
                self.skip(pos);
                continue;
            }
            if data.len() < 6 {
                return None;
            }
            let n = usize::from(data.u16_at(2).unwrap_or(0));
            let types = usize::from(data[5]);
            if n < 6 + 2 * types {
                // Not a plausible header: a sync pattern inside data.
                self.skip(1);
                continue;
            }
            if data.len() < n + 2 {
                // Waiting for the rest. A corrupted length field could make us wait for up to
                // 64 KiB of later frames: if a complete, checksum-valid ensemble already starts
                // inside the pending bytes, this header is bogus.
                match next_valid_frame(data, self.resume) {
                    Scan::Found(at) => {
                        self.input.stats.checksum_errors += 1;
                        self.skip(at);
                        continue;
                    }
                    Scan::NotYet(resume) => {
                        self.resume = resume.max(1);
                        return None;
                    }
                }
            }
            let stored = data.u16_at(n).unwrap_or(0);
            if checksum(&data[..n]) != stored {
                self.input.stats.checksum_errors += 1;
                self.skip(1);
                continue;
            }
            let result = decode_ensemble(&data[..n + 2]);
            self.resume = 1;
            match &result {
                Ok(_) => self.input.take_frame(n + 2),
                Err(_) => {
                    self.input.stats.malformed += 1;
                    self.input.reject_frame(n + 2);
                }
            }
            return Some(result);
        }
    }
}

/// The result of looking for a later ensemble inside a pending one.
enum Scan {
    /// A complete, checksum-valid ensemble starts here.
    Found(usize),
    /// None yet; resume the search here when more bytes arrive (the first candidate whose
    /// ensemble is still incomplete, or the last byte).
    NotYet(usize),
}

/// Looks for the first complete ensemble with a valid checksum at or after `from`.
fn next_valid_frame(data: &[u8], from: usize) -> Scan {
    let mut at = from;
    let mut first_incomplete = None;
    while let Some(p) = data
        .get(at..)
        .and_then(|d| d.windows(2).position(|w| w == SYNC))
    {
        let start = at + p;
        let f = &data[start..];
        match (f.u16_at(2), f.u8_at(5)) {
            (Some(n), Some(types)) => {
                let n = usize::from(n);
                if n >= 6 + 2 * usize::from(types) {
                    if f.len() < n + 2 {
                        first_incomplete.get_or_insert(start);
                    } else if f.u16_at(n) == Some(checksum(&f[..n])) {
                        return Scan::Found(start);
                    }
                }
            }
            _ => {
                first_incomplete.get_or_insert(start);
            }
        }
        at = start + 1;
    }
    Scan::NotYet(first_incomplete.unwrap_or(data.len().saturating_sub(1)))
}

impl Pd0Decoder {
    /// At the end of a capture: the bytes still waiting can no longer complete a frame. Returns
    /// the ensembles that follow a truncated or corrupted header; the rest is counted as
    /// skipped.
    pub fn finish(&mut self) -> Vec<Ensemble> {
        let mut out = Vec::new();
        loop {
            while let Some(r) = self.next_ensemble() {
                if let Ok(e) = r {
                    out.push(e);
                }
            }
            let data = self.input.data();
            if data.is_empty() {
                return out;
            }
            match next_valid_frame(data, 1) {
                Scan::Found(at) => self.skip(at),
                Scan::NotYet(_) => {
                    let n = data.len();
                    self.skip(n);
                    return out;
                }
            }
        }
    }
}

/// Decodes a whole capture.
pub fn decode_all(bytes: &[u8]) -> (Vec<Ensemble>, DecoderStats) {
    let mut d = Pd0Decoder::new();
    let mut out = Vec::new();
    crate::framing::decode_stream(&mut d, bytes, 4096, |e| out.push(e));
    (out, d.input.stats)
}

/// Encodes the fixed leader, variable leader and bottom track of `e` (the blocks a DVL emits
/// for navigation) into one ensemble with its checksum. Fields the encoder does not carry are
/// written as zero.
pub fn encode_ensemble(e: &Ensemble) -> Vec<u8> {
    let mut blocks: Vec<Vec<u8>> = Vec::new();
    if let Some(f) = &e.fixed {
        let mut b = vec![0u8; 59];
        b[0..2].copy_from_slice(&ID_FIXED_LEADER.to_le_bytes());
        b[2] = f.firmware_version;
        b[3] = f.firmware_revision;
        b[4..6].copy_from_slice(&f.system_configuration.to_le_bytes());
        b[8] = f.beams;
        b[9] = f.cells;
        b[10..12].copy_from_slice(&f.pings_per_ensemble.to_le_bytes());
        b[12..14].copy_from_slice(&(((f.cell_size_m * 100.0).round()) as u16).to_le_bytes());
        b[14..16].copy_from_slice(&(((f.blank_m * 100.0).round()) as u16).to_le_bytes());
        b[25] = f.coordinate_transform;
        b[26..28]
            .copy_from_slice(&(((f.heading_alignment_deg * 100.0).round()) as i16).to_le_bytes());
        b[28..30].copy_from_slice(&(((f.heading_bias_deg * 100.0).round()) as i16).to_le_bytes());
        b[30] = f.sensor_source;
        b[31] = f.sensors_available;
        b[32..34].copy_from_slice(&(((f.bin1_distance_m * 100.0).round()) as u16).to_le_bytes());
        b[34..36].copy_from_slice(&(((f.transmit_pulse_m * 100.0).round()) as u16).to_le_bytes());
        b[54..58].copy_from_slice(&f.serial_number.unwrap_or(0).to_le_bytes());
        b[58] = f.beam_angle_deg.unwrap_or(0.0).round() as u8;
        blocks.push(b);
    }
    if let Some(v) = &e.variable {
        let mut b = vec![0u8; 65];
        b[0..2].copy_from_slice(&ID_VARIABLE_LEADER.to_le_bytes());
        b[2..4].copy_from_slice(&((v.ensemble_number & 0xffff) as u16).to_le_bytes());
        b[4..11].copy_from_slice(&v.rtc);
        b[11] = (v.ensemble_number >> 16) as u8;
        b[12..14].copy_from_slice(&v.bit_result.to_le_bytes());
        b[14..16].copy_from_slice(&(v.sound_speed_m_s.round() as u16).to_le_bytes());
        b[16..18].copy_from_slice(&((v.depth_m * 10.0).round() as u16).to_le_bytes());
        b[18..20].copy_from_slice(&((v.heading_deg * 100.0).round() as u16).to_le_bytes());
        b[20..22].copy_from_slice(&((v.pitch_deg * 100.0).round() as i16).to_le_bytes());
        b[22..24].copy_from_slice(&((v.roll_deg * 100.0).round() as i16).to_le_bytes());
        b[24..26].copy_from_slice(&(v.salinity_ppt.round() as u16).to_le_bytes());
        b[26..28].copy_from_slice(&((v.temperature_c * 100.0).round() as i16).to_le_bytes());
        let pressure_dapa = (v.pressure_pa.unwrap_or(0.0) / 10.0).round() as i32;
        b[48..52].copy_from_slice(&pressure_dapa.to_le_bytes());
        b[57..65].copy_from_slice(&v.rtc_y2k.unwrap_or_default());
        blocks.push(b);
    }
    if let Some(t) = &e.bottom_track {
        let mut b = vec![0u8; 85];
        b[0..2].copy_from_slice(&ID_BOTTOM_TRACK.to_le_bytes());
        b[2..4].copy_from_slice(&t.pings_per_ensemble.to_le_bytes());
        for i in 0..4 {
            let cm = t.range_m[i]
                .map(|r| (r * 100.0).round() as u32)
                .unwrap_or(0);
            b[16 + 2 * i..18 + 2 * i].copy_from_slice(&((cm & 0xffff) as u16).to_le_bytes());
            b[77 + i] = (cm >> 16) as u8;
            let v = t.velocity_m_s[i]
                .map(|v| (v * 1000.0).round().clamp(-32767.0, 32767.0) as i16)
                .unwrap_or(BAD_VELOCITY);
            b[24 + 2 * i..26 + 2 * i].copy_from_slice(&v.to_le_bytes());
            b[32 + i] = t.correlation[i];
            b[36 + i] = t.evaluation_amplitude[i];
            b[40 + i] = t.percent_good[i];
            let rl = t.reference_layer_velocity_m_s[i]
                .map(|v| (v * 1000.0).round().clamp(-32767.0, 32767.0) as i16)
                .unwrap_or(BAD_VELOCITY);
            b[50 + 2 * i..52 + 2 * i].copy_from_slice(&rl.to_le_bytes());
            b[66 + i] = t.reference_layer_percent_good[i];
        }
        let max_depth = if t.max_depth_m.is_finite() {
            (t.max_depth_m * 10.0).round() as u16
        } else {
            0
        };
        b[70..72].copy_from_slice(&max_depth.to_le_bytes());
        blocks.push(b);
    }
    let header_len = 6 + 2 * blocks.len();
    let mut out = Vec::with_capacity(header_len + blocks.iter().map(Vec::len).sum::<usize>() + 2);
    out.extend_from_slice(&SYNC);
    out.extend_from_slice(&[0, 0, 0, blocks.len() as u8]);
    let mut offset = header_len;
    for b in &blocks {
        out.extend_from_slice(&(offset as u16).to_le_bytes());
        offset += b.len();
    }
    for b in &blocks {
        out.extend_from_slice(b);
    }
    let n = out.len() as u16;
    out[2..4].copy_from_slice(&n.to_le_bytes());
    let sum = checksum(&out);
    out.extend_from_slice(&sum.to_le_bytes());
    out
}

impl crate::framing::StreamDecoder for Pd0Decoder {
    type Frame = Ensemble;
    fn push(&mut self, bytes: &[u8]) {
        Pd0Decoder::push(self, bytes);
    }
    fn next_good_frame(&mut self) -> Option<Ensemble> {
        loop {
            match self.next_ensemble()? {
                Ok(e) => return Some(e),
                Err(_) => continue,
            }
        }
    }
    fn finish_capture(&mut self) -> Vec<Self::Frame> {
        self.finish()
    }
    fn stats(&self) -> &DecoderStats {
        &self.input.stats
    }
    fn frame_start(&self) -> u64 {
        self.input.frame_start()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn beams_give_the_instrument_velocity_with_four_or_three() {
        // Beam velocities of a known bottom velocity (x, y, z), error velocity zero.
        let (x, y, z) = (0.8, -1.3, 0.05);
        let th = 30f64.to_radians();
        let (a, b) = (1.0 / (2.0 * th.sin()), 1.0 / (4.0 * th.cos()));
        let s = z / b;
        for convex in [true, false] {
            let c = if convex { 1.0 } else { -1.0 };
            let beams = [
                s / 4.0 + x / (2.0 * c * a),
                s / 4.0 - x / (2.0 * c * a),
                s / 4.0 - y / (2.0 * c * a),
                s / 4.0 + y / (2.0 * c * a),
            ];
            let all = beams.map(Some);
            let (v, e) = beam_to_instrument(&all, 30.0, convex).expect("four beams");
            for (got, want) in v.iter().zip([x, y, z]) {
                assert!((got - want).abs() < 1e-12, "{v:?}");
            }
            assert!(e.expect("an error velocity").abs() < 1e-12);
            for k in 0..4 {
                let mut three = all;
                three[k] = None;
                let (v3, e3) = beam_to_instrument(&three, 30.0, convex).expect("three beams");
                assert_eq!(e3, None);
                for (got, want) in v3.iter().zip([x, y, z]) {
                    assert!((got - want).abs() < 1e-12, "beam {k} missing: {v3:?}");
                }
            }
            let mut two = all;
            two[0] = None;
            two[2] = None;
            assert_eq!(beam_to_instrument(&two, 30.0, convex), None);
        }
        assert_eq!(beam_to_instrument(&[Some(0.0); 4], 0.0, true), None);
    }
}
