//! From decoded device frames to the schema messages the drivers publish. Pure: the caller
//! passes the host time at read return and the sequence number.
//!
//! Each device's conversion lives in its folder (`pd0/to_schema.rs`, ...), with the rules they
//! share in [`crate::schema_rules`]; this module gathers them under one name.

pub use crate::kvh::to_schema::*;
pub use crate::nortek::to_schema::*;
pub use crate::pd0::to_schema::*;
pub use crate::seatrac::to_schema::*;
pub use crate::ugps::to_schema::*;
pub use crate::wldvl::to_schema::*;
pub use crate::xsens::to_schema::*;

pub use crate::schema_rules::{ImuRange, STANDARD_GRAVITY};

#[cfg(test)]
mod tests {
    use super::*;
    use crate::kvh::KvhSample;
    use crate::wldvl::Velocity;
    use auvnav_shm_schema::{DvlVelocityV1, ImuSampleV1};

    #[test]
    fn pd0_clock_dates_follow_the_calendar() {
        // 2000-01-01 00:00:00.00 is the epoch; 2024-02-29 exists, 2023-02-29 and 31 February not.
        assert_eq!(pd0_rtc_ns(&[0, 1, 1, 0, 0, 0, 0]), Some(0));
        assert_eq!(
            pd0_rtc_ns(&[0, 1, 2, 0, 0, 1, 50]),
            Some(86_401_500_000_000)
        );
        assert!(pd0_rtc_ns(&[24, 2, 29, 12, 0, 0, 0]).is_some());
        assert_eq!(pd0_rtc_ns(&[23, 2, 29, 12, 0, 0, 0]), None);
        assert_eq!(pd0_rtc_ns(&[23, 2, 31, 12, 0, 0, 0]), None);
        assert_eq!(pd0_rtc_ns(&[23, 4, 31, 12, 0, 0, 0]), None);
        assert_eq!(pd0_rtc_ns(&[23, 4, 30, 24, 0, 0, 0]), None);
        assert_eq!(pd0_rtc_ns(&[23, 4, 30, 23, 59, 59, 100]), None);
        for ns in [
            0,
            86_401_500_000_000,
            762_000_123_450_000_000,
            3_155_759_999_990_000_000,
        ] {
            assert_eq!(pd0_rtc_ns(&pd0_rtc(ns)), Some(ns - ns % 10_000_000), "{ns}");
        }
    }

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
        // An empty covariance is none given, not a perfect velocity: the navigator's noise then.
        let unknown = water_linked_velocity(
            &Velocity {
                covariance: [0.0; 9],
                ..v
            },
            0,
            9,
        );
        assert_eq!(unknown.validity & DvlVelocityV1::VALID_STD, 0);
        assert_ne!(unknown.validity & DvlVelocityV1::VALID_VELOCITY, 0);
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
