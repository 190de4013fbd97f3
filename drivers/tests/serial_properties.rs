//! Properties of the Water Linked, KVH and Xsens decoders: encode -> decode is the identity,
//! chunking does not change the frames, garbage between frames is counted and never decoded.

use auvnav_drivers::kvh::{self, KvhDecoder, KvhSample};
use auvnav_drivers::wldvl::{self, Transducer, Velocity, WlDecoder, WlFrame};
use auvnav_drivers::xsens::{self, MtData2, XbusDecoder, XbusMessage};
use proptest::prelude::*;

/// Values that survive the fixed decimal printing of the Water Linked format.
fn milli(x: i32) -> f64 {
    f64::from(x) / 1000.0
}

prop_compose! {
    fn wl_frame()(
        kind in 0u8..2,
        v in proptest::array::uniform3(-5000i32..5000),
        valid in any::<bool>(),
        alt in 0i32..20000,
        cov in proptest::array::uniform9(0u32..1000),
        tov in any::<u32>(),
        id in 0u8..4,
        rssi in -120i32..0,
    ) -> WlFrame {
        if kind == 0 {
            WlFrame::Velocity(Velocity {
                velocity_m_s: v.map(milli),
                valid,
                altitude_m: f64::from(alt / 10) / 100.0,
                figure_of_merit_m_s: milli(v[0].abs()),
                covariance: cov.map(|c| f64::from(c) * 1e-4),
                time_of_validity_us: u64::from(tov),
                time_of_transmission_us: u64::from(tov) + 7,
                time_since_last_ms: f64::from(alt / 100),
                status: u32::from(valid),
            })
        } else {
            WlFrame::Transducer(Transducer {
                id,
                velocity_m_s: milli(v[1]),
                distance_m: f64::from(alt / 10) / 100.0,
                rssi_dbm: f64::from(rssi),
                noise_dbm: f64::from(rssi - 30),
            })
        }
    }
}

prop_compose! {
    fn kvh_sample()(
        g in proptest::array::uniform3(-1.0f32..1.0),
        a in proptest::array::uniform3(-3.0f32..3.0),
        status in any::<u8>(),
        seq in 0u8..128,
        temp in any::<i16>(),
        ts in proptest::option::of(any::<u32>()),
    ) -> KvhSample {
        KvhSample { gyro: g, accel: a, status, sequence: seq, temperature_raw: temp, timestamp_us: ts }
    }
}

prop_compose! {
    fn mtdata2()(
        c in any::<u16>(),
        t in any::<u32>(),
        s in any::<u32>(),
        a in proptest::array::uniform3(-100.0f32..100.0),
        w in proptest::array::uniform3(-10.0f32..10.0),
        dv in proptest::array::uniform3(-1.0f32..1.0),
        dq in proptest::array::uniform4(-1.0f32..1.0),
    ) -> MtData2 {
        MtData2 {
            packet_counter: Some(c),
            sample_time_fine: Some(t),
            status_word: Some(s),
            acceleration: Some(a.map(f64::from)),
            rate_of_turn: Some(w.map(f64::from)),
            delta_v: Some(dv.map(f64::from)),
            delta_q: Some(dq.map(f64::from)),
            ..Default::default()
        }
    }
}

fn feed<D, T>(
    bytes: &[u8],
    chunks: &[usize],
    d: &mut D,
    push: impl Fn(&mut D, &[u8]),
    pull: impl Fn(&mut D) -> Option<T>,
) -> Vec<T> {
    let mut out = Vec::new();
    let (mut at, mut k) = (0, 0);
    while at < bytes.len() {
        let n = chunks[k % chunks.len()].max(1).min(bytes.len() - at);
        push(d, &bytes[at..at + n]);
        at += n;
        k += 1;
        while let Some(f) = pull(d) {
            out.push(f);
        }
    }
    out
}

/// Garbage that contains no frame start of any of the three protocols.
fn garbage() -> impl Strategy<Value = Vec<u8>> {
    proptest::collection::vec(any::<u8>(), 0..40).prop_map(|v| {
        v.into_iter()
            .filter(|b| ![b'w', 0xfe, 0xfa].contains(b))
            .collect()
    })
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(256))]

    #[test]
    fn water_linked_round_trip_any_chunking(
        frames in proptest::collection::vec(wl_frame(), 1..10),
        junk in garbage(),
        chunks in proptest::collection::vec(1usize..64, 1..6),
    ) {
        let mut bytes = junk.clone();
        bytes.push(b'\n');
        for f in &frames {
            bytes.extend(wldvl::encode(f));
        }
        let mut d = WlDecoder::new();
        let out = feed(&bytes, &chunks, &mut d, |d, b| d.push(b), |d| d.next_frame());
        let out: Vec<WlFrame> = out.into_iter().filter_map(Result::ok).collect();
        prop_assert_eq!(&out, &frames);
        prop_assert_eq!(d.stats().frames, frames.len() as u64);
    }

    #[test]
    fn kvh_round_trip_any_chunking(
        samples in proptest::collection::vec(kvh_sample(), 1..10),
        junk in garbage(),
        chunks in proptest::collection::vec(1usize..64, 1..6),
    ) {
        let mut bytes = junk.clone();
        for s in &samples {
            bytes.extend(kvh::encode(s));
        }
        let mut d = KvhDecoder::new();
        let out = feed(&bytes, &chunks, &mut d, |d, b| d.push(b), |d| d.next_sample());
        prop_assert_eq!(&out, &samples);
        prop_assert_eq!(d.stats().bytes_skipped, junk.len() as u64);
    }

    #[test]
    fn xsens_round_trip_any_chunking_and_a_corrupted_frame_is_dropped(
        msgs in proptest::collection::vec(mtdata2(), 2..10),
        victim in 0usize..10,
        junk in garbage(),
        chunks in proptest::collection::vec(1usize..64, 1..6),
    ) {
        let victim = victim % msgs.len();
        let mut bytes = junk.clone();
        for (i, m) in msgs.iter().enumerate() {
            let mut f = xsens::encode_mtdata2(m);
            if i == victim {
                let k = f.len() - 2;
                f[k] ^= 0x10;
            }
            bytes.extend(f);
        }
        // The stream goes on after the frames (zeros: no preamble). A valid frame's data can
        // hold a preamble and bus id (a sample time of 0xFAFF74A0): once the corrupted frame
        // before it is refused, the decoder resynchronises there and waits for the length that
        // false start declares, which only the bytes that follow can refuse.
        bytes.extend(std::iter::repeat_n(0u8, xsens::MAX_PAYLOAD + 7));
        let mut d = XbusDecoder::new();
        let out = feed(&bytes, &chunks, &mut d, |d, b| d.push(b), |d| d.next_message());
        let expected: Vec<XbusMessage> = msgs
            .iter()
            .enumerate()
            .filter(|(i, _)| *i != victim)
            .map(|(_, m)| XbusMessage::MtData2(m.clone()))
            .collect();
        prop_assert_eq!(out, expected);
        prop_assert!(d.stats().checksum_errors >= 1);
    }
}

#[test]
fn reads_of_64_kib_never_overflow_a_decoder_drained_after_each_read() {
    use auvnav_drivers::framing::READ_ALLOWANCE;
    let n = 20_000;
    let wl: Vec<u8> = (0..n)
        .flat_map(|k| {
            wldvl::encode(&WlFrame::Transducer(Transducer {
                id: (k % 4) as u8,
                velocity_m_s: 0.5,
                distance_m: 10.0,
                rssi_dbm: -40.0,
                noise_dbm: -90.0,
            }))
        })
        .collect();
    let mut d = WlDecoder::new();
    let out = feed(
        &wl,
        &[READ_ALLOWANCE],
        &mut d,
        |d, b| d.push(b),
        |d| d.next_frame(),
    );
    assert_eq!((out.len(), d.stats().overflow_bytes), (n, 0));
    let sample = KvhSample {
        gyro: [0.0; 3],
        accel: [0.0, 0.0, 1.0],
        status: 0x77,
        sequence: 1,
        temperature_raw: 20,
        timestamp_us: Some(5),
    };
    let kv: Vec<u8> = (0..n).flat_map(|_| kvh::encode(&sample)).collect();
    let mut d = KvhDecoder::new();
    let out = feed(
        &kv,
        &[READ_ALLOWANCE],
        &mut d,
        |d, b| d.push(b),
        |d| d.next_sample(),
    );
    assert_eq!((out.len(), d.stats().overflow_bytes), (n, 0));
    let m = MtData2 {
        packet_counter: Some(1),
        ..Default::default()
    };
    let xs: Vec<u8> = (0..n).flat_map(|_| xsens::encode_mtdata2(&m)).collect();
    let mut d = XbusDecoder::new();
    let out = feed(
        &xs,
        &[READ_ALLOWANCE],
        &mut d,
        |d, b| d.push(b),
        |d| d.next_message(),
    );
    assert_eq!((out.len(), d.stats().overflow_bytes), (n, 0));
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(256))]

    /// Nortek records (bottom track with arbitrary finite values, and records of other ids)
    /// after garbage without a sync byte, in any chunking: every record comes back, the garbage
    /// is counted as skipped, and random bytes fed the same way never panic and are all
    /// accounted for.
    #[test]
    fn nortek_round_trip_any_chunking_and_random_bytes_never_panic(
        velocities in proptest::collection::vec(-5.0f32..5.0, 1..8),
        junk in proptest::collection::vec(any::<u8>(), 0..40),
        random in proptest::collection::vec(any::<u8>(), 0..600),
        chunks in proptest::collection::vec(1usize..64, 1..6),
    ) {
        use auvnav_drivers::nortek::{self, BottomTrack, Estimate, NortekDecoder, NortekFrame};
        let junk: Vec<u8> = junk.into_iter().filter(|b| *b != nortek::SYNC).collect();
        let mut bytes = junk.clone();
        let mut expected = Vec::new();
        for (k, v) in velocities.iter().enumerate() {
            let e = Estimate { velocity_m_s: *v, figure_of_merit_m_s: 0.003, ..Default::default() };
            let bt = BottomTrack {
                version: 1,
                offset_of_data: 36,
                serial_number: k as u32,
                date_time: [126, 10, 25, 12, 0, k as u8],
                time_100us: 7,
                beams: 4,
                error: 0,
                status: 0,
                sound_speed_m_s: 1500.0,
                temperature_c: 9.0,
                pressure_dbar: 30.0,
                beam: [e; 4],
                beam_distance_m: [20.0; 4],
                xyz: [e; 4],
            };
            bytes.extend(nortek::encode_bottom_track(&bt));
            expected.push(NortekFrame::BottomTrack(Box::new(bt)));
            if k % 3 == 2 {
                bytes.extend(nortek::record(0xbe, &[k as u8; 5]));
                expected.push(NortekFrame::Other(nortek::OtherRecord {
                    id: 0xbe,
                    family: nortek::FAMILY_DVL,
                    data_len: 5,
                }));
            }
        }
        let mut d = NortekDecoder::new();
        let out = feed(&bytes, &chunks, &mut d, |d, b| d.push(b), |d| d.next_frame());
        let out: Vec<NortekFrame> = out.into_iter().filter_map(Result::ok).collect();
        prop_assert_eq!(&out, &expected);
        prop_assert_eq!(d.stats().bytes_skipped, junk.len() as u64);

        let mut d = NortekDecoder::new();
        let _ = feed(&random, &chunks, &mut d, |d, b| d.push(b), |d| d.next_frame());
        prop_assert_eq!(d.stats().bytes, random.len() as u64);
        prop_assert!(d.stats().bytes_skipped <= d.stats().bytes);
    }
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(256))]

    /// Water Linked TCP reports: random bytes (and random bytes between braces) in any chunking
    /// never panic, and every byte is accounted for.
    #[test]
    fn water_linked_json_random_bytes_never_panic(
        random in proptest::collection::vec(any::<u8>(), 0..600),
        chunks in proptest::collection::vec(1usize..64, 1..6),
    ) {
        use auvnav_drivers::wldvl_json::JsonDecoder;
        for bytes in [random.clone(), [b"{".as_slice(), &random, b"}\n"].concat()] {
            let mut d = JsonDecoder::new();
            let _ = feed(&bytes, &chunks, &mut d, |d, b| d.push(b), |d| d.next_frame());
            prop_assert_eq!(d.stats().bytes, bytes.len() as u64);
            prop_assert!(d.stats().bytes_skipped <= d.stats().bytes);
        }
    }
}

/// A GNSS fix a driver publishes is within the schema's documented ranges.
fn check_fix(f: &auvnav_shm_schema::GnssFixV1) -> Result<(), TestCaseError> {
    use auvnav_shm_schema::GnssFixV1;
    prop_assert!(f.latitude_rad.abs() <= std::f64::consts::FRAC_PI_2);
    prop_assert!(f.longitude_rad.abs() <= std::f64::consts::PI);
    prop_assert!((0.01..=1000.0).contains(&f.horizontal_std_m), "{f:?}");
    prop_assert!((0.01..=1000.0).contains(&f.vertical_std_m), "{f:?}");
    if f.validity & GnssFixV1::VALID_HEIGHT != 0 {
        prop_assert!((-1000.0..=10000.0).contains(&f.height_m), "{f:?}");
    }
    if f.validity & GnssFixV1::VALID_VELOCITY != 0 {
        prop_assert!(f.velocity_ned_m_s.iter().all(|v| v.abs() < 100.0), "{f:?}");
    }
    Ok(())
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(256))]

    /// GNSS receivers: random bytes, and well-framed NMEA sentences and UBX NAV-PVT messages
    /// (good checksums) carrying random fields, in any chunking, never panic; every byte is
    /// accounted for and every fix published is within the schema's ranges.
    #[test]
    fn gnss_random_bytes_and_well_framed_random_fields_never_panic(
        random in proptest::collection::vec(any::<u8>(), 0..600),
        sentences in proptest::collection::vec(
            (0usize..7, proptest::collection::vec("[-0-9.]{0,12}|[NSEWAVTM]|", 0..16)),
            1..12,
        ),
        payloads in proptest::collection::vec(proptest::collection::vec(any::<u8>(), 92), 1..6),
        chunks in proptest::collection::vec(1usize..64, 1..6),
    ) {
        use auvnav_drivers::device::{DeviceDecoder, Output, Protocol, ProtocolSettings};
        use auvnav_drivers::{nmea, ubx};
        let kinds = ["GGA", "RMC", "VTG", "GST", "ZDA", "HDT", "GSV"];
        let mut nmea_bytes = random.clone();
        for (k, fields) in &sentences {
            nmea_bytes.extend(nmea::sentence(&format!("GN{},{}", kinds[*k], fields.join(","))));
        }
        let mut ubx_bytes = random.clone();
        for p in &payloads {
            ubx_bytes.extend(ubx::frame(ubx::CLASS_NAV, ubx::ID_NAV_PVT, p));
        }
        for (protocol, bytes) in [(Protocol::Nmea, &nmea_bytes), (Protocol::Ubx, &ubx_bytes)] {
            let mut d = DeviceDecoder::new(protocol, ProtocolSettings::default());
            let mut at = 0;
            for (i, n) in chunks.iter().cycle().enumerate() {
                if at >= bytes.len() {
                    break;
                }
                let end = (at + n).min(bytes.len());
                d.push(&bytes[at..end]);
                at = end;
                while let Some(o) = d.next_output(i as u64) {
                    match o {
                        Output::Gnss(f) => check_fix(&f)?,
                        other => prop_assert!(false, "{other:?}"),
                    }
                }
            }
            prop_assert_eq!(d.stats().bytes, bytes.len() as u64);
            prop_assert!(d.stats().bytes_skipped <= d.stats().bytes);
        }
    }
}

/// The case the property above found: the corrupted first frame's sample time, 0xFAFF74A0, holds
/// a preamble and bus id declaring a 160-byte payload; the frame after it still comes out once
/// the stream goes on.
#[test]
fn a_false_frame_start_inside_a_corrupted_frame_does_not_swallow_the_next() {
    let first = MtData2 {
        packet_counter: Some(0),
        sample_time_fine: Some(0xFAFF_74A0),
        status_word: Some(0),
        acceleration: Some([0.0; 3]),
        delta_v: Some([0.0; 3]),
        rate_of_turn: Some([0.0; 3]),
        delta_q: Some([0.0; 4]),
        ..Default::default()
    };
    let second = MtData2 {
        sample_time_fine: Some(0),
        ..first.clone()
    };
    let mut bytes = xsens::encode_mtdata2(&first);
    let k = bytes.len() - 2;
    bytes[k] ^= 0x10;
    bytes.extend(xsens::encode_mtdata2(&second));
    let mut d = XbusDecoder::new();
    d.push(&bytes);
    assert_eq!(
        d.next_message(),
        None,
        "the false start waits for its length"
    );
    d.push(&vec![0u8; xsens::MAX_PAYLOAD + 7]);
    assert_eq!(d.next_message(), Some(XbusMessage::MtData2(second)));
    assert!(d.stats().checksum_errors >= 1);
}
