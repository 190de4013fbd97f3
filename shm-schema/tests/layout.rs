//! Pins the memory layout of every message type (a change here is a wire-format change and needs a
//! new type version) and round-trips each type through its bytes (through iceoryx2: `bus.rs`).

use auvnav_shm_schema::*;
use std::mem::{align_of, size_of};

#[test]
fn layouts_are_pinned() {
    let layouts = [
        (
            "ImuSampleV1",
            size_of::<ImuSampleV1>(),
            align_of::<ImuSampleV1>(),
        ),
        (
            "DvlVelocityV1",
            size_of::<DvlVelocityV1>(),
            align_of::<DvlVelocityV1>(),
        ),
        ("UsblFixV1", size_of::<UsblFixV1>(), align_of::<UsblFixV1>()),
        ("DepthV1", size_of::<DepthV1>(), align_of::<DepthV1>()),
        (
            "MagnetometerV1",
            size_of::<MagnetometerV1>(),
            align_of::<MagnetometerV1>(),
        ),
        (
            "AcousticRangesV1",
            size_of::<AcousticRangesV1>(),
            align_of::<AcousticRangesV1>(),
        ),
        (
            "AcousticArrayPoseV1",
            size_of::<AcousticArrayPoseV1>(),
            align_of::<AcousticArrayPoseV1>(),
        ),
        ("GnssFixV1", size_of::<GnssFixV1>(), align_of::<GnssFixV1>()),
        (
            "SoundVelocityV1",
            size_of::<SoundVelocityV1>(),
            align_of::<SoundVelocityV1>(),
        ),
        (
            "AttitudeV1",
            size_of::<AttitudeV1>(),
            align_of::<AttitudeV1>(),
        ),
        (
            "NavSolutionV1",
            size_of::<NavSolutionV1>(),
            align_of::<NavSolutionV1>(),
        ),
        (
            "AidDiagnosticsV1",
            size_of::<AidDiagnosticsV1>(),
            align_of::<AidDiagnosticsV1>(),
        ),
        (
            "ProcessHealthV1",
            size_of::<ProcessHealthV1>(),
            align_of::<ProcessHealthV1>(),
        ),
        ("LateAidV1", size_of::<LateAidV1>(), align_of::<LateAidV1>()),
        (
            "TruthStateV1",
            size_of::<TruthStateV1>(),
            align_of::<TruthStateV1>(),
        ),
    ];
    println!("{layouts:?}");
    let expected = [
        ("ImuSampleV1", 88, 8),
        ("DvlVelocityV1", 176, 8),
        ("UsblFixV1", 144, 8),
        ("DepthV1", 56, 8),
        ("MagnetometerV1", 56, 8),
        ("AcousticRangesV1", 224, 8),
        ("AcousticArrayPoseV1", 88, 8),
        ("GnssFixV1", 96, 8),
        ("SoundVelocityV1", 56, 8),
        ("AttitudeV1", 72, 8),
        ("NavSolutionV1", 248, 8),
        ("AidDiagnosticsV1", 136, 8),
        ("ProcessHealthV1", 120, 8),
        ("LateAidV1", 48, 8),
        ("TruthStateV1", 168, 8),
    ];
    assert_eq!(layouts, expected);
}

/// The ros2msg definition lists exactly the fields whose sizes add up to the struct size.
fn schema_size(def: &str) -> usize {
    def.lines()
        .filter(|l| !l.starts_with('#') && !l.trim().is_empty())
        .map(|l| {
            let ty = l.split_whitespace().next().unwrap_or_default();
            let (base, count) = match ty.find('[') {
                Some(i) => (
                    &ty[..i],
                    ty[i + 1..ty.len() - 1].parse::<usize>().unwrap_or(0),
                ),
                None => (ty, 1),
            };
            let size = match base {
                "float64" | "uint64" | "int64" => 8,
                "float32" | "uint32" | "int32" => 4,
                "uint16" | "int16" => 2,
                "uint8" | "int8" => 1,
                other => panic!("unexpected type {other}"),
            };
            size * count
        })
        .sum()
}

#[test]
fn schemas_describe_the_whole_struct() {
    let sizes = [
        size_of::<ImuSampleV1>(),
        size_of::<DvlVelocityV1>(),
        size_of::<UsblFixV1>(),
        size_of::<DepthV1>(),
        size_of::<MagnetometerV1>(),
        size_of::<AcousticRangesV1>(),
        size_of::<AcousticArrayPoseV1>(),
        size_of::<GnssFixV1>(),
        size_of::<NavSolutionV1>(),
        size_of::<SoundVelocityV1>(),
        size_of::<AttitudeV1>(),
        size_of::<AidDiagnosticsV1>(),
        size_of::<ProcessHealthV1>(),
        size_of::<LateAidV1>(),
        size_of::<SessionEventV1>(),
        size_of::<TruthStateV1>(),
    ];
    for ((type_name, schema_name, def), size) in all_schemas().into_iter().zip(sizes) {
        assert!(
            type_name.starts_with("auvnav/") && type_name.ends_with("/v1"),
            "{type_name}"
        );
        assert!(schema_name.starts_with("auvnav_msgs/msg/"), "{schema_name}");
        assert_eq!(schema_size(&def), size, "{schema_name}:\n{def}");
    }
}

fn filled<T: Message>(seed: u8) -> T {
    let mut v = T::default();
    for (i, b) in bytemuck::bytes_of_mut(&mut v).iter_mut().enumerate() {
        // Bytes that make finite floats: keep every 8th byte (the f64 exponent's high byte) small.
        *b = seed.wrapping_add(i as u8) & 0x3f;
    }
    v
}

fn roundtrip_bytes<T: Message>() {
    let v: T = filled(7);
    let bytes = bytemuck::bytes_of(&v).to_vec();
    let back: T = bytemuck::pod_read_unaligned(&bytes);
    assert_eq!(bytemuck::bytes_of(&back), bytemuck::bytes_of(&v));
}

#[test]
fn every_type_roundtrips_through_bytes() {
    roundtrip_bytes::<ImuSampleV1>();
    roundtrip_bytes::<DvlVelocityV1>();
    roundtrip_bytes::<UsblFixV1>();
    roundtrip_bytes::<DepthV1>();
    roundtrip_bytes::<MagnetometerV1>();
    roundtrip_bytes::<SoundVelocityV1>();
    roundtrip_bytes::<AttitudeV1>();
    roundtrip_bytes::<AcousticRangesV1>();
    roundtrip_bytes::<GnssFixV1>();
    roundtrip_bytes::<NavSolutionV1>();
    roundtrip_bytes::<AidDiagnosticsV1>();
    roundtrip_bytes::<ProcessHealthV1>();
    roundtrip_bytes::<LateAidV1>();
    roundtrip_bytes::<TruthStateV1>();
}

#[test]
fn process_name_is_truncated_at_a_char_boundary() {
    let mut h = ProcessHealthV1::default();
    h.set_name("auvnav-dvl");
    assert_eq!(h.name(), "auvnav-dvl");
    h.set_name(&"é".repeat(20)); // 40 bytes: 16 whole characters fit in 32 bytes
    assert_eq!(h.name(), "é".repeat(16));
}

#[test]
fn modes_convert_and_reject_unknown_values() {
    assert_eq!(NavMode::try_from(2), Ok(NavMode::Navigating));
    assert_eq!(NavMode::try_from(9), Err(9));
    assert_eq!(AidSource::try_from(5), Ok(AidSource::UsblSlantRange));
    assert_eq!(AidSource::try_from(0), Err(0));
}
