//! The DBC-driven CAN decoder on the sample DBC, through the in-memory frame source; the live
//! SocketCAN path must say clearly when no interface exists.

use auvnav_drivers::can::{
    BitOrder, CanError, CanFrame, DbcDecoder, FrameSource, InMemoryFrames, SignalSpec,
    SocketCanSource, SourceError,
};
use proptest::prelude::*;

const SAMPLE: &str = include_str!("../dbc/auvnav_sensors.dbc");

fn value(d: &auvnav_drivers::can::DecodedMessage, name: &str) -> f64 {
    d.signals
        .iter()
        .find(|(n, _, _)| n == name)
        .map(|(_, v, _)| *v)
        .unwrap_or_else(|| panic!("{name} missing"))
}

#[test]
fn bit_layouts_match_the_dbc_conventions() {
    // Motorola 39|16@0+ is a big-endian u16 in bytes 4-5; Intel 0|16@1+ little-endian in 0-1.
    let moto = SignalSpec {
        name: "m".into(),
        start_bit: 39,
        size: 16,
        order: BitOrder::Motorola,
        signed: false,
        factor: 1.0,
        offset: 0.0,
        unit: String::new(),
    };
    let intel = SignalSpec {
        start_bit: 0,
        order: BitOrder::Intel,
        ..moto.clone()
    };
    let data = [0x34, 0x12, 0, 0, 0x12, 0x34, 0, 0];
    assert_eq!(moto.decode(&data), f64::from(0x1234));
    assert_eq!(intel.decode(&data), f64::from(0x1234));
    // A signed 12-bit Motorola field starting at bit 31 spans byte 3 and the high nibble of 4.
    let pitch = SignalSpec {
        start_bit: 31,
        size: 12,
        signed: true,
        factor: 0.1,
        ..moto
    };
    let mut d = [0u8; 8];
    pitch.encode(&mut d, -12.3);
    assert_eq!(d[3], 0xf8);
    assert_eq!(d[4] & 0xf0, 0x50);
    assert!((pitch.decode(&d) + 12.3).abs() < 1e-9);
}

#[test]
fn sample_dbc_frames_decode_through_the_in_memory_source() {
    let mut dec = DbcDecoder::from_dbc(SAMPLE).expect("sample DBC");
    let p = dec
        .encode(
            "PressureSensor",
            &[
                ("Pressure", 3.04567),
                ("Temperature", 11.25),
                ("Status", 1.0),
                ("Counter", 7.0),
            ],
        )
        .expect("encode");
    assert_eq!((p.id, p.extended), (0x181, false));
    let a = dec
        .encode(
            "Altimeter",
            &[("Range", 12.345), ("Quality", 200.0), ("Pitch", -3.5)],
        )
        .expect("encode");
    let b = dec
        .encode(
            "BatteryStatus",
            &[
                ("Voltage", 48.12),
                ("Current", -3.25),
                ("StateOfCharge", 87.5),
            ],
        )
        .expect("encode");
    assert!(b.extended && b.id == 0x18ff_0102, "{b:?}");
    let unknown = CanFrame {
        id: 0x7ff,
        extended: false,
        data: vec![0; 8],
    };
    let short = CanFrame {
        data: vec![1, 2],
        ..p.clone()
    };
    let mut src = InMemoryFrames::new([p, unknown, a, short, b]);
    let mut decoded = Vec::new();
    let mut errors = Vec::new();
    while let Some(f) = src.next_frame().expect("memory never fails") {
        match dec.decode(&f) {
            Ok(d) => decoded.push(d),
            Err(e) => errors.push(e),
        }
    }
    assert_eq!(decoded.len(), 3);
    assert!((value(&decoded[0], "Pressure") - 3.04567).abs() < 1e-9);
    assert!((value(&decoded[0], "Temperature") - 11.25).abs() < 1e-9);
    assert_eq!(value(&decoded[0], "Counter"), 7.0);
    assert!((value(&decoded[1], "Range") - 12.345).abs() < 1e-9);
    assert!((value(&decoded[1], "Pitch") + 3.5).abs() < 1e-9);
    assert!((value(&decoded[2], "Current") + 3.25).abs() < 1e-9);
    assert_eq!(value(&decoded[2], "StateOfCharge"), 87.5);
    assert!(matches!(errors[0], CanError::UnknownId { id: 0x7ff }));
    assert!(matches!(errors[1], CanError::ShortFrame { .. }));
    let s = dec.stats;
    assert_eq!(
        (s.frames, s.decoded, s.unknown_id, s.short_frames),
        (5, 3, 1, 1)
    );
}

#[test]
fn a_bad_dbc_is_a_clear_error() {
    let e = DbcDecoder::from_dbc("BO_ 1 X: 8 N\n SG_ Y : 600|16@1+ (1,0) [0|1] \"\" N\n")
        .expect_err("signal beyond 64 bytes");
    assert!(e.to_string().contains("does not fit"), "{e}");
    assert!(DbcDecoder::from_dbc("this is not a DBC").is_err());
}

#[test]
fn the_live_path_reports_a_missing_interface() {
    match SocketCanSource::open("auvnavtest0", std::time::Duration::from_millis(10)) {
        Err(e @ SourceError::NoInterface { .. }) => {
            let text = e.to_string();
            assert!(
                text.contains("auvnavtest0") && text.contains("not available"),
                "{text}"
            );
        }
        Err(e) => panic!("unexpected error kind: {e}"),
        Ok(_) => panic!("an interface named auvnavtest0 exists?"),
    }
}

proptest! {
    #[test]
    fn encode_then_decode_returns_the_value(
        start in 0u32..56,
        size in 1u32..=16,
        motorola in any::<bool>(),
        signed in any::<bool>(),
        raw in any::<i32>(),
    ) {
        let spec = SignalSpec {
            name: "s".into(),
            // Motorola start bits name the MSB: keep the field inside 8 bytes.
            start_bit: if motorola { (start / 8) * 8 + 7 } else { start.min(64 - size) },
            size,
            order: if motorola { BitOrder::Motorola } else { BitOrder::Intel },
            signed,
            factor: 0.5,
            offset: -3.0,
            unit: String::new(),
        };
        let bits = 1i64 << size;
        let r = if signed {
            i64::from(raw).rem_euclid(bits) - bits / 2
        } else {
            i64::from(raw).rem_euclid(bits)
        };
        let v = r as f64 * 0.5 - 3.0;
        let mut data = [0u8; 8];
        spec.encode(&mut data, v);
        prop_assert_eq!(spec.decode(&data), v);
    }
}
