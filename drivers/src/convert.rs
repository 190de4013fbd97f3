//! From decoded device frames to the schema messages the drivers publish. Pure: the caller
//! passes the host time at read return and the sequence number.

use crate::kvh::KvhSample;
use crate::wldvl::Velocity;
use auvnav_shm_schema::{DvlVelocityV1, ImuSampleV1};
use serde::{Deserialize, Serialize};

/// Standard gravity, for accelerometers that report in g (m/s^2).
pub const STANDARD_GRAVITY: f64 = 9.806_65;

/// A Water Linked `wrz` velocity report as a DVL message. The Water Linked frame (x forward,
/// y right, z down, vehicle velocity) is the schema's DVL frame. The time of validity is the host
/// read time minus the device's own latency (time of transmission minus time of validity).
/// The velocity is marked valid only when the device says so and it is finite.
pub fn water_linked_velocity(v: &Velocity, host_time_ns: u64, sequence: u64) -> DvlVelocityV1 {
    let latency_ns = v
        .time_of_transmission_us
        .saturating_sub(v.time_of_validity_us)
        .saturating_mul(1000);
    let mut m = DvlVelocityV1 {
        host_time_ns,
        device_time_ns: v.time_of_validity_us.saturating_mul(1000),
        sequence,
        validity_time_ns: host_time_ns.saturating_sub(latency_ns),
        velocity_dvl_m_s: v.velocity_m_s,
        velocity_std_m_s: [
            v.covariance[0].max(0.0).sqrt(),
            v.covariance[4].max(0.0).sqrt(),
            v.covariance[8].max(0.0).sqrt(),
        ],
        beam_velocity_m_s: [f64::NAN; 4],
        beam_range_m: [f64::NAN; 4],
        altitude_m: v.altitude_m,
        figure_of_merit_m_s: v.figure_of_merit_m_s,
        sound_speed_m_s: f64::NAN,
        validity: DvlVelocityV1::VALID_DEVICE_TIME,
        beams_used: 0,
    };
    let finite = v
        .velocity_m_s
        .iter()
        .all(|x| x.is_finite() && x.abs() < 20.0);
    if v.valid && finite {
        m.validity |= DvlVelocityV1::VALID_VELOCITY | DvlVelocityV1::VALID_FOM;
        if m.velocity_std_m_s
            .iter()
            .all(|s| s.is_finite() && *s <= 10.0)
        {
            m.validity |= DvlVelocityV1::VALID_STD;
        }
    }
    if v.altitude_m.is_finite() && (0.0..=1000.0).contains(&v.altitude_m) {
        m.validity |= DvlVelocityV1::VALID_ALTITUDE;
    }
    m
}

/// How a KVH 1750/1775 is configured (=ROTFMT, =ROTUNITS, =TEMPUNITS, data rate): the messages
/// do not say.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct KvhConfig {
    /// Gyro fields are angle increments (=ROTFMT DELTA) rather than rates (=ROTFMT RATE).
    pub increments: bool,
    /// Gyro fields are in degrees (=ROTUNITS DEG) rather than radians.
    pub degrees: bool,
    /// Output rate (Hz).
    pub rate_hz: f64,
    /// Temperature field in hundredths of a degree rather than degrees (=TEMPUNITS).
    pub temperature_centi: bool,
}

/// A KVH sample as an IMU message. Accelerometers report g (or g*s as increments); the axes are
/// the unit's case frame, which the driver's mounting configuration relates to the body.
pub fn kvh_sample(s: &KvhSample, cfg: &KvhConfig, host_time_ns: u64, sequence: u64) -> ImuSampleV1 {
    let angle_scale = if cfg.degrees {
        std::f64::consts::PI / 180.0
    } else {
        1.0
    };
    let interval_s = if cfg.rate_hz > 0.0 {
        1.0 / cfg.rate_hz
    } else {
        f64::NAN
    };
    let mut status = 0;
    if s.gyro_valid().iter().all(|&v| v) {
        status |= ImuSampleV1::STATUS_GYRO_VALID;
    }
    if s.accel_valid().iter().all(|&v| v) {
        status |= ImuSampleV1::STATUS_ACCEL_VALID;
    }
    if cfg.increments {
        status |= ImuSampleV1::STATUS_INCREMENTS;
    }
    let temperature_c = if cfg.temperature_centi {
        f32::from(s.temperature_raw) / 100.0
    } else {
        f32::from(s.temperature_raw)
    };
    if (-60.0..=120.0).contains(&temperature_c) {
        status |= ImuSampleV1::STATUS_TEMPERATURE_VALID;
    }
    let device_time_ns = match s.timestamp_us {
        Some(t) => {
            status |= ImuSampleV1::STATUS_DEVICE_TIME_VALID;
            u64::from(t) * 1000
        }
        None => 0,
    };
    ImuSampleV1 {
        host_time_ns,
        device_time_ns,
        sequence,
        angular: s.gyro.map(|g| f64::from(g) * angle_scale),
        specific: s.accel.map(|a| f64::from(a) * STANDARD_GRAVITY),
        interval_s,
        temperature_c,
        status,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn water_linked_report_becomes_a_dvl_message_with_its_latency_removed() {
        let v = Velocity {
            velocity_m_s: [0.12, -0.4, 2.0],
            valid: true,
            altitude_m: 1.3,
            figure_of_merit_m_s: 1.855,
            covariance: [1e-4, 0.0, 0.0, 0.0, 4e-4, 0.0, 0.0, 0.0, 9e-4],
            time_of_validity_us: 1_000,
            time_of_transmission_us: 151_000,
            time_since_last_ms: 123.0,
            status: 0,
        };
        let m = water_linked_velocity(&v, 10_000_000_000, 7);
        assert_eq!(m.validity_time_ns, 10_000_000_000 - 150_000_000);
        assert_eq!(m.velocity_dvl_m_s, [0.12, -0.4, 2.0]);
        assert!((m.velocity_std_m_s[1] - 0.02).abs() < 1e-12);
        let need = DvlVelocityV1::VALID_VELOCITY
            | DvlVelocityV1::VALID_STD
            | DvlVelocityV1::VALID_ALTITUDE;
        assert_eq!(m.validity & need, need);
        let invalid = water_linked_velocity(
            &Velocity {
                valid: false,
                altitude_m: -1.0,
                ..v
            },
            0,
            8,
        );
        assert_eq!(invalid.validity & need, 0);
    }

    #[test]
    fn kvh_sample_units_follow_the_configuration() {
        let s = KvhSample {
            gyro: [1.0, -2.0, 0.5],
            accel: [0.0, 0.0, -1.0],
            status: 0x77,
            sequence: 3,
            temperature_raw: 2950,
            timestamp_us: Some(12),
        };
        let cfg = KvhConfig {
            increments: false,
            degrees: true,
            rate_hz: 1000.0,
            temperature_centi: true,
        };
        let m = kvh_sample(&s, &cfg, 5, 9);
        assert!((m.angular[0] - 1f64.to_radians()).abs() < 1e-15);
        assert!((m.specific[2] + STANDARD_GRAVITY).abs() < 1e-12);
        assert!((m.temperature_c - 29.5).abs() < 1e-6);
        assert_eq!((m.interval_s, m.device_time_ns), (0.001, 12_000));
        let ok = ImuSampleV1::STATUS_GYRO_VALID
            | ImuSampleV1::STATUS_ACCEL_VALID
            | ImuSampleV1::STATUS_TEMPERATURE_VALID
            | ImuSampleV1::STATUS_DEVICE_TIME_VALID;
        assert_eq!(m.status, ok);
        // Gyros not yet valid (the "early" capture): the message says so.
        let early = kvh_sample(&KvhSample { status: 0x70, ..s }, &cfg, 5, 10);
        assert_eq!(early.status & ImuSampleV1::STATUS_GYRO_VALID, 0);
    }
}
