//! Frames that pass every checksum but carry arbitrary values: Xsens MTData2 messages with every
//! field drawn from random bits (NaN, infinities, huge and tiny values), SeaTrac lines with random
//! command ids and payloads, KVH samples with random values, counters and time stamps. The
//! decoders and conversions never panic (debug builds check integer overflow), and an IMU sample
//! they publish as valid is finite and within its device's measurement range.

use auvnav_drivers::device::{DeviceDecoder, Output, Protocol, ProtocolSettings};
use auvnav_drivers::kvh::{KvhSample, encode as encode_kvh};
use auvnav_drivers::seatrac::{CID_PING_RESP, CID_XCVR_FIX, CID_XCVR_USBL, encode_line};
use auvnav_drivers::to_schema::{KVH_RANGE, XSENS_RANGE};
use auvnav_drivers::xsens::{MtData2, encode_mtdata2};
use auvnav_shm_schema::ImuSampleV1;

struct Bits(u64);

impl Bits {
    fn next(&mut self) -> u64 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        self.0.wrapping_mul(0x2545_f491_4f6c_dd1d)
    }
    fn f64(&mut self) -> f64 {
        match self.next() % 4 {
            0 => f64::from_bits(self.next()),
            1 => [f64::NAN, f64::INFINITY, -1e300, 1e-300, 0.0][self.next() as usize % 5],
            _ => (self.next() % 2001) as f64 / 100.0 - 10.0,
        }
    }
    fn some<T>(&mut self, f: impl FnOnce(&mut Self) -> T) -> Option<T> {
        (!self.next().is_multiple_of(3)).then(|| f(self))
    }
}

/// Checks what a decoder published; the number of IMU samples published as valid.
fn check(outputs: &[Output], max_rate: f64, max_force: f64) -> usize {
    let mut valid = 0;
    for o in outputs {
        if let Output::Imu(m) = o {
            let per_s = if m.status & ImuSampleV1::STATUS_INCREMENTS != 0 {
                1.0 / m.interval_s
            } else {
                1.0
            };
            if m.status & ImuSampleV1::STATUS_GYRO_VALID != 0 {
                assert!(
                    m.angular.iter().all(|x| (x * per_s).abs() <= max_rate),
                    "a gyro triad beyond the range published as valid: {m:?}"
                );
            }
            if m.status & ImuSampleV1::STATUS_ACCEL_VALID != 0 {
                assert!(
                    m.specific.iter().all(|x| (x * per_s).abs() <= max_force),
                    "an accelerometer triad beyond the range published as valid: {m:?}"
                );
                valid += 1;
            }
        }
    }
    valid
}

fn drain(d: &mut DeviceDecoder, t: u64) -> Vec<Output> {
    let mut out = Vec::new();
    while let Some(o) = d.next_output(t) {
        out.push(o);
    }
    out
}

#[test]
fn xsens_messages_with_arbitrary_values() {
    let mut b = Bits(0x1234_5678_9abc_def1);
    let mut d = DeviceDecoder::new(Protocol::Xsens, ProtocolSettings::default());
    let mut valid = 0;
    for k in 0..20_000u64 {
        let m = MtData2 {
            packet_counter: b.some(|b| b.next() as u16),
            sample_time_fine: b.some(|b| b.next() as u32),
            temperature_c: b.some(|b| b.f64()),
            acceleration: b.some(|b| [b.f64(), b.f64(), b.f64()]),
            delta_v: b.some(|b| [b.f64(), b.f64(), b.f64()]),
            rate_of_turn: b.some(|b| [b.f64(), b.f64(), b.f64()]),
            delta_q: b.some(|b| [b.f64(), b.f64(), b.f64(), b.f64()]),
            magnetic_field: b.some(|b| [b.f64(), b.f64(), b.f64()]),
            ..Default::default()
        };
        d.push(&encode_mtdata2(&m));
        valid += check(
            &drain(&mut d, k * 5_000_000),
            XSENS_RANGE.max_rate_rad_s,
            XSENS_RANGE.max_specific_force_m_s2,
        );
    }
    assert!(valid > 100, "{valid} valid samples");
}

#[test]
fn kvh_samples_with_arbitrary_values() {
    let mut b = Bits(0x0fed_cba9_8765_4321);
    let mut d = DeviceDecoder::new(Protocol::Kvh1750, ProtocolSettings::default());
    let mut valid = 0;
    for k in 0..20_000u64 {
        let f = |b: &mut Bits| b.f64() as f32;
        let s = KvhSample {
            gyro: [f(&mut b), f(&mut b), f(&mut b)],
            accel: [f(&mut b), f(&mut b), f(&mut b)],
            status: b.next() as u8,
            sequence: b.next() as u8,
            temperature_raw: b.next() as i16,
            timestamp_us: b.some(|b| b.next() as u32),
        };
        d.push(&encode_kvh(&s));
        valid += check(
            &drain(&mut d, k * 5_000_000),
            KVH_RANGE.max_rate_rad_s,
            KVH_RANGE.max_specific_force_m_s2,
        );
    }
    assert!(valid > 100, "{valid} valid samples");
}

#[test]
fn seatrac_lines_with_arbitrary_payloads() {
    let mut b = Bits(0x5555_aaaa_1234_9876);
    let mut d = DeviceDecoder::new(Protocol::Seatrac, ProtocolSettings::default());
    let cids = [CID_XCVR_FIX, CID_PING_RESP, CID_XCVR_USBL];
    for k in 0..20_000u64 {
        let cid = if b.next().is_multiple_of(4) {
            b.next() as u8
        } else {
            cids[b.next() as usize % cids.len()]
        };
        let len = (b.next() % 120) as usize;
        let payload: Vec<u8> = (0..len).map(|_| b.next() as u8).collect();
        d.push(&encode_line(cid, &payload));
        // Most random payloads are malformed (counted); what decodes is published, and the
        // core checks its values (`tests/never_lies.rs`). Here: no panic, no overflow.
        drain(&mut d, k * 1_000_000);
    }
    let s = d.stats();
    assert!(s.malformed > 1000, "malformed lines not counted: {s:?}");
}

/// Nortek bottom-track records with every float drawn from random bits and random headers,
/// ids and lengths around them: never a panic, and a velocity published as valid is finite and
/// within the schema's range.
#[test]
fn nortek_records_with_arbitrary_values() {
    use auvnav_drivers::nortek::{self, BottomTrack, Estimate};
    use auvnav_shm_schema::DvlVelocityV1;
    let mut b = Bits(0x5eed_0001);
    let mut d = DeviceDecoder::new(Protocol::Nortek, ProtocolSettings::default());
    let mut published = 0;
    for k in 0..3000u64 {
        let bytes = if k % 5 == 4 {
            // A random record around random data (any id, any length up to the limit).
            let len = (b.next() % 300) as usize;
            let data: Vec<u8> = (0..len).map(|_| b.next() as u8).collect();
            nortek::record(b.next() as u8, &data)
        } else {
            let mut f = || b.f64() as f32;
            let mut est = || Estimate {
                velocity_m_s: f(),
                figure_of_merit_m_s: f(),
                time_difference_1_s: f(),
                time_difference_2_s: f(),
                time_of_estimate_s: f(),
            };
            let (beam, xyz) = ([est(), est(), est(), est()], [est(), est(), est(), est()]);
            let mut f = || b.f64() as f32;
            let bt = BottomTrack {
                version: 1,
                offset_of_data: 36,
                serial_number: 1,
                date_time: std::array::from_fn(|_| (k * 37 % 256) as u8),
                time_100us: (k * 7919 % 65_536) as u16,
                beams: 4,
                error: k as u32,
                status: (k * 31) as u32,
                sound_speed_m_s: f(),
                temperature_c: f(),
                pressure_dbar: f(),
                beam,
                beam_distance_m: [f(), f(), f(), f()],
                xyz,
            };
            nortek::encode_bottom_track(&bt)
        };
        d.push(&bytes);
        for o in drain(&mut d, k) {
            let Output::Dvl(m) = o else {
                panic!("a DVL decoder published {o:?}")
            };
            if m.validity & DvlVelocityV1::VALID_VELOCITY != 0 {
                assert!(
                    m.velocity_dvl_m_s
                        .iter()
                        .all(|v| v.is_finite() && v.abs() < 20.0),
                    "{m:?}"
                );
                published += 1;
            }
            if m.validity & DvlVelocityV1::VALID_ALTITUDE != 0 {
                assert!((0.0..=1000.0).contains(&m.altitude_m), "{m:?}");
            }
            if m.validity & DvlVelocityV1::VALID_SOUND_SPEED != 0 {
                assert!((1375.0..=1650.0).contains(&m.sound_speed_m_s), "{m:?}");
            }
        }
    }
    assert!(
        published > 0,
        "no record was valid: the draw never tests the valid path"
    );
}
