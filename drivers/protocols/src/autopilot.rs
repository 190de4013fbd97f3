//! An autopilot's sensor messages over MAVLink (ArduPilot, ArduSub) as the schema's sensor
//! messages: `SCALED_IMU` (or the first IMU's `RAW_IMU`, which ArduPilot sends in the same units)
//! as an IMU sample and a magnetometer reading, a `SCALED_PRESSURE` instance as depth, `ATTITUDE`
//! (the autopilot's own estimate) as an attitude, `GPS_RAW_INT` 3D fixes as GNSS fixes and
//! `VISION_POSITION_DELTA` — what the Water Linked DVL extension of BlueOS sends: the DVL's
//! velocity times the ping interval, in the vehicle's frame — as a DVL velocity. Used
//! on telemetry logs (`auvnav import tlog`) and on the live link (`auvnav-mavlink`'s source).
//! Host times are the caller's: a reading carries the autopilot's clock where the message has it.

use auvnav_shm_schema::{
    AttitudeV1, DepthV1, DvlVelocityV1, GnssFixV1, ImuSampleV1, MagnetometerV1, topic,
};
use mavlink::dialects::ardupilotmega::{self as mav, MavMessage};

/// Standard gravity, the unit ArduPilot's milli-g are of (m/s²).
pub const G0: f64 = 9.80665;
/// The range error of GNSS taken when a fix gives only its dilution of precision (m per unit).
pub const UERE_M: f64 = 2.5;

/// A sensor reading of the autopilot, host time not yet set.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum AutopilotReading {
    Imu(ImuSampleV1),
    Magnetometer(MagnetometerV1),
    Depth(DepthV1),
    Attitude(AttitudeV1),
    Gnss(GnssFixV1),
    Dvl(DvlVelocityV1),
}

/// The figure of merit a `VISION_POSITION_DELTA` confidence of 0 % stands for (m/s): the Water
/// Linked extension sends 100 × (1 − min(fom, 0.4) / 0.4).
pub const DVL_FOM_AT_ZERO_CONFIDENCE: f64 = 0.4;

impl AutopilotReading {
    /// The topic the reading goes to.
    pub fn topic(&self) -> &'static str {
        match self {
            AutopilotReading::Imu(_) => topic::IMU,
            AutopilotReading::Magnetometer(_) => topic::MAGNETOMETER,
            AutopilotReading::Depth(_) => topic::DEPTH,
            AutopilotReading::Attitude(_) => topic::ATTITUDE,
            AutopilotReading::Gnss(_) => topic::GNSS,
            AutopilotReading::Dvl(_) => topic::DVL,
        }
    }

    /// Sets the host time, the device time (when the autopilot's clock stamped it) and the
    /// sequence number.
    pub fn set_times(&mut self, host_ns: u64, device_ns: Option<u64>, sequence: u64) {
        let dev = device_ns.unwrap_or(0);
        match self {
            AutopilotReading::Imu(x) => {
                (x.host_time_ns, x.device_time_ns, x.sequence) = (host_ns, dev, sequence)
            }
            AutopilotReading::Magnetometer(x) => {
                (x.host_time_ns, x.device_time_ns, x.sequence) = (host_ns, dev, sequence)
            }
            AutopilotReading::Depth(x) => {
                (x.host_time_ns, x.device_time_ns, x.sequence) = (host_ns, dev, sequence)
            }
            AutopilotReading::Attitude(x) => {
                (x.host_time_ns, x.device_time_ns, x.sequence) = (host_ns, dev, sequence)
            }
            AutopilotReading::Gnss(x) => (x.host_time_ns, x.sequence) = (host_ns, sequence),
            AutopilotReading::Dvl(x) => {
                (x.host_time_ns, x.validity_time_ns, x.sequence) = (host_ns, host_ns, sequence)
            }
        }
    }
}

/// What became of one message.
#[derive(Debug, Clone, PartialEq)]
pub enum Converted {
    /// Readings (one or two: an IMU message also carries the compass), with the autopilot's
    /// clock (ns since its boot) when the message has it.
    Readings {
        device_ns: Option<u64>,
        readings: Vec<AutopilotReading>,
    },
    /// A sensor message with a value that is not finite or out of range.
    Implausible,
    /// A GPS message without a 3D fix.
    NoFix,
    /// Not a message (or not the instance) taken.
    NotTaken,
}

/// Which IMU message is the IMU.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ImuMessage {
    ScaledImu,
    /// The first IMU's `RAW_IMU` (`id` 0), for autopilots that stream no `SCALED_IMU`.
    RawImu,
}

/// How the messages are converted.
#[derive(Debug, Clone, PartialEq)]
pub struct AutopilotConversion {
    pub imu: ImuMessage,
    /// Which SCALED_PRESSURE message is the water pressure: 1, 2 (ArduSub's external sensor) or 3.
    pub pressure_instance: u8,
    pub water_density_kg_m3: f64,
    /// The absolute pressure at the surface (hPa); taken from the first reading when not given,
    /// as ArduSub takes it at boot.
    pub surface_pressure_hpa: Option<f64>,
}

impl Default for AutopilotConversion {
    fn default() -> Self {
        AutopilotConversion {
            imu: ImuMessage::ScaledImu,
            pressure_instance: 2,
            water_density_kg_m3: 1025.0,
            surface_pressure_hpa: None,
        }
    }
}

/// 1, 2 or 3 for the SCALED_PRESSURE messages, 0 for any other.
fn pressure_instance(m: &MavMessage) -> u8 {
    match m {
        MavMessage::SCALED_PRESSURE(_) => 1,
        MavMessage::SCALED_PRESSURE2(_) => 2,
        MavMessage::SCALED_PRESSURE3(_) => 3,
        _ => 0,
    }
}

fn ms(time_boot_ms: u32) -> Option<u64> {
    Some(u64::from(time_boot_ms) * 1_000_000)
}

impl AutopilotConversion {
    /// The readings of `m`.
    pub fn convert(&mut self, m: &MavMessage) -> Converted {
        let one = |device_ns, r| Converted::Readings {
            device_ns,
            readings: vec![r],
        };
        match m {
            MavMessage::SCALED_IMU(d) if self.imu == ImuMessage::ScaledImu => imu_and_field(
                ms(d.time_boot_ms),
                [d.xacc, d.yacc, d.zacc],
                [d.xgyro, d.ygyro, d.zgyro],
                [d.xmag, d.ymag, d.zmag],
            ),
            MavMessage::RAW_IMU(d) if self.imu == ImuMessage::RawImu && d.id == 0 => imu_and_field(
                Some(d.time_usec.saturating_mul(1000)),
                [d.xacc, d.yacc, d.zacc],
                [d.xgyro, d.ygyro, d.zgyro],
                [d.xmag, d.ymag, d.zmag],
            ),
            MavMessage::SCALED_PRESSURE(mav::SCALED_PRESSURE_DATA {
                time_boot_ms,
                press_abs,
                temperature,
                ..
            })
            | MavMessage::SCALED_PRESSURE2(mav::SCALED_PRESSURE2_DATA {
                time_boot_ms,
                press_abs,
                temperature,
                ..
            })
            | MavMessage::SCALED_PRESSURE3(mav::SCALED_PRESSURE3_DATA {
                time_boot_ms,
                press_abs,
                temperature,
                ..
            }) if pressure_instance(m) == self.pressure_instance => {
                let p = f64::from(*press_abs);
                if !(p.is_finite() && p > 0.0) {
                    return Converted::Implausible;
                }
                let surface = *self.surface_pressure_hpa.get_or_insert(p);
                let gauge_pa = (p - surface) * 100.0;
                let depth_m = gauge_pa / (self.water_density_kg_m3 * G0);
                if !(-10.0..=11_000.0).contains(&depth_m) {
                    return Converted::Implausible;
                }
                one(
                    ms(*time_boot_ms),
                    AutopilotReading::Depth(DepthV1 {
                        depth_m,
                        pressure_pa: gauge_pa,
                        water_density_kg_m3: self.water_density_kg_m3,
                        temperature_c: f32::from(*temperature) / 100.0,
                        validity: DepthV1::VALID_DEPTH
                            | DepthV1::VALID_PRESSURE
                            | DepthV1::VALID_TEMPERATURE
                            | DepthV1::VALID_DEVICE_TIME,
                        ..Default::default()
                    }),
                )
            }
            MavMessage::ATTITUDE(d) => {
                let e = [d.roll, d.pitch, d.yaw].map(f64::from);
                if !e
                    .iter()
                    .all(|x| x.is_finite() && x.abs() <= 2.0 * std::f64::consts::PI)
                {
                    return Converted::Implausible;
                }
                one(
                    ms(d.time_boot_ms),
                    AutopilotReading::Attitude(AttitudeV1 {
                        euler_rad: e,
                        validity: AttitudeV1::VALID_ATTITUDE
                            | AttitudeV1::VALID_DEVICE_TIME
                            | AttitudeV1::HEADING_TRUE,
                        ..Default::default()
                    }),
                )
            }
            // The sender's clock (the extension's), not the autopilot's: placed at reception.
            MavMessage::VISION_POSITION_DELTA(d) => match dvl_velocity(d) {
                Some(v) => one(None, AutopilotReading::Dvl(v)),
                None => Converted::Implausible,
            },
            MavMessage::GPS_RAW_INT(d) => match gnss_fix(d) {
                Some(g) => one(None, AutopilotReading::Gnss(g)),
                None => Converted::NoFix,
            },
            _ => Converted::NotTaken,
        }
    }
}

/// An IMU sample from ArduPilot's milli-g and milli-rad/s (body FRD), and the magnetometer
/// reading (milli-gauss) when the message has one.
fn imu_and_field(
    device_ns: Option<u64>,
    acc: [i16; 3],
    gyro: [i16; 3],
    mag: [i16; 3],
) -> Converted {
    let mut readings = vec![AutopilotReading::Imu(ImuSampleV1 {
        angular: gyro.map(|x| f64::from(x) / 1e3),
        specific: acc.map(|x| f64::from(x) / 1e3 * G0),
        status: ImuSampleV1::STATUS_GYRO_VALID
            | ImuSampleV1::STATUS_ACCEL_VALID
            | ImuSampleV1::STATUS_DEVICE_TIME_VALID,
        ..Default::default()
    })];
    if mag != [0; 3] {
        readings.push(AutopilotReading::Magnetometer(MagnetometerV1 {
            // 1 mG = 1e-7 T.
            field_t: mag.map(|x| f64::from(x) / 1e7),
            validity: MagnetometerV1::VALID_FIELD | MagnetometerV1::VALID_DEVICE_TIME,
            ..Default::default()
        }));
    }
    Converted::Readings {
        device_ns,
        readings,
    }
}

/// The DVL velocity of a `VISION_POSITION_DELTA`: the position change over its interval, in the
/// vehicle's frame; the confidence back to the DVL's figure of merit. None for an interval that
/// is not 1 ms to 10 s, a value that is not finite, or a speed above 20 m/s.
fn dvl_velocity(d: &mav::VISION_POSITION_DELTA_DATA) -> Option<DvlVelocityV1> {
    let dt = d.time_delta_usec as f64 * 1e-6;
    let v = d.position_delta.map(|x| f64::from(x) / dt);
    let confidence = f64::from(d.confidence);
    if !(1e-3..=10.0).contains(&dt)
        || !v.iter().all(|x| x.is_finite())
        || v.iter().map(|x| x * x).sum::<f64>() > 400.0
        || !(0.0..=100.0).contains(&confidence)
    {
        return None;
    }
    Some(DvlVelocityV1 {
        velocity_dvl_m_s: v,
        figure_of_merit_m_s: DVL_FOM_AT_ZERO_CONFIDENCE * (1.0 - confidence / 100.0),
        // The message does not say how many beams the DVL used: 0, as for a Water Linked report.
        validity: DvlVelocityV1::VALID_VELOCITY | DvlVelocityV1::VALID_FOM,
        ..Default::default()
    })
}

/// A GNSS fix from GPS_RAW_INT when it is a 3D fix; its accuracy from `h_acc`/`v_acc`, else
/// from the dilutions with [`UERE_M`].
fn gnss_fix(d: &mav::GPS_RAW_INT_DATA) -> Option<GnssFixV1> {
    if (d.fix_type as u32) < mav::GpsFixType::GPS_FIX_TYPE_3D_FIX as u32 {
        return None;
    }
    let accuracy = |acc_mm: u32, dop: u16| {
        if acc_mm > 0 {
            f64::from(acc_mm) * 1e-3
        } else if dop != u16::MAX {
            f64::from(dop) * 1e-2 * UERE_M
        } else {
            100.0
        }
    };
    let (height_m, height_valid) = if d.alt_ellipsoid != 0 {
        (f64::from(d.alt_ellipsoid) * 1e-3, GnssFixV1::VALID_HEIGHT)
    } else {
        (f64::from(d.alt) * 1e-3, 0)
    };
    let differential = if (d.fix_type as u32) >= mav::GpsFixType::GPS_FIX_TYPE_DGPS as u32 {
        GnssFixV1::DIFFERENTIAL
    } else {
        0
    };
    Some(GnssFixV1 {
        latitude_rad: (f64::from(d.lat) * 1e-7).to_radians(),
        longitude_rad: (f64::from(d.lon) * 1e-7).to_radians(),
        height_m,
        horizontal_std_m: accuracy(d.h_acc, d.eph).min(1000.0),
        vertical_std_m: accuracy(d.v_acc, d.epv).min(1000.0),
        satellites: u32::from(d.satellites_visible),
        validity: GnssFixV1::VALID_POSITION | height_valid | differential,
        ..Default::default()
    })
}

/// Places an autopilot's clock on the host's, live: host time = the autopilot's time plus the
/// smallest receive delay seen since its boot (a reading is never placed after its arrival). A
/// clock going back by more than a second is a new boot.
#[derive(Debug, Clone, Default)]
pub struct AutopilotClock {
    /// The smallest (arrival − autopilot time) of this boot (ns), and the last autopilot time.
    offset_ns: Option<i128>,
    last_device_ns: u64,
    pub boots: u64,
}

impl AutopilotClock {
    /// The host time of a reading stamped `device_ns` by the autopilot that arrived at
    /// `arrival_ns` (host clock).
    pub fn host_ns(&mut self, device_ns: u64, arrival_ns: u64) -> u64 {
        if self.offset_ns.is_none() || device_ns.saturating_add(1_000_000_000) < self.last_device_ns
        {
            self.offset_ns = None;
            self.boots += 1;
        }
        self.last_device_ns = device_ns;
        let delay = i128::from(arrival_ns) - i128::from(device_ns);
        let offset = self.offset_ns.map_or(delay, |o| o.min(delay));
        self.offset_ns = Some(offset);
        (i128::from(device_ns) + offset).clamp(0, i128::from(arrival_ns)) as u64
    }
}
