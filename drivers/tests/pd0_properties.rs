//! Properties of the PD0 decoder: encode -> decode is the identity, chunking does not matter,
//! corruption is counted and the decoder resynchronises.

use auvnav_drivers::pd0::{
    self, BottomTrack, CoordinateSystem, Ensemble, FixedLeader, Pd0Decoder, VariableLeader,
};
use proptest::prelude::*;

fn centi(x: i32) -> f64 {
    f64::from(x) * 0.01
}

prop_compose! {
    fn fixed_leader()(
        fw in (0u8..=80, 0u8..=99),
        freq in 0u16..6,
        angle in 0u16..3,
        up in any::<bool>(),
        ex in 0u8..32,
        cells in 0u8..=128,
        pings in any::<u16>(),
        cell in 0i32..=6000,
        blank in 0i32..=6000,
        ea in -18000i32..=18000,
        serial in any::<u32>(),
    ) -> FixedLeader {
        let system_configuration = freq | (u16::from(up) << 7) | (angle << 8);
        FixedLeader {
            firmware_version: fw.0,
            firmware_revision: fw.1,
            system_configuration,
            beams: 4,
            cells,
            pings_per_ensemble: pings,
            cell_size_m: centi(cell),
            blank_m: centi(blank),
            coordinate_transform: ex,
            coordinate_system: [
                CoordinateSystem::Beam,
                CoordinateSystem::Instrument,
                CoordinateSystem::Ship,
                CoordinateSystem::Earth,
            ][usize::from((ex >> 3) & 3)],
            heading_alignment_deg: centi(ea),
            heading_bias_deg: centi(-ea / 2),
            sensor_source: ex,
            sensors_available: ex,
            bin1_distance_m: centi(cell / 2),
            transmit_pulse_m: centi(blank / 3),
            serial_number: Some(serial),
            beam_angle_deg: Some([15.0, 20.0, 30.0][usize::from(angle)]),
            upward_looking: up,
            frequency_khz: Some([75, 150, 300, 600, 1200, 2400][usize::from(freq)]),
        }
    }
}

prop_compose! {
    fn variable_leader()(
        number in 0u32..(1 << 24),
        rtc in proptest::array::uniform7(0u8..60),
        y2k in proptest::array::uniform8(0u8..60),
        c in 1400u16..1600,
        depth in 0i32..60000,
        heading in 0i32..36000,
        pitch in -9000i32..9000,
        roll in -18000i32..18000,
        temp in -500i32..4000,
        pressure in -100i32..1_000_000,
    ) -> VariableLeader {
        VariableLeader {
            ensemble_number: number,
            rtc,
            rtc_y2k: Some(y2k),
            bit_result: 0,
            sound_speed_m_s: f64::from(c),
            depth_m: f64::from(depth) * 0.1,
            heading_deg: centi(heading),
            pitch_deg: centi(pitch),
            roll_deg: centi(roll),
            salinity_ppt: 35.0,
            temperature_c: centi(temp),
            pressure_pa: Some(f64::from(pressure) * 10.0),
        }
    }
}

prop_compose! {
    fn bottom_track()(
        ranges in proptest::array::uniform4(proptest::option::of(1u32..(1 << 24))),
        vels in proptest::array::uniform4(proptest::option::of(-32767i16..=32767)),
        bytes in proptest::array::uniform4(any::<u8>()),
        pings in any::<u16>(),
        max_depth in 0u16..u16::MAX,
    ) -> BottomTrack {
        BottomTrack {
            pings_per_ensemble: pings,
            range_m: ranges.map(|r| r.map(|cm| f64::from(cm) * 0.01)),
            velocity_m_s: vels.map(|v| v.map(|mm| f64::from(mm) * 0.001)),
            correlation: bytes,
            evaluation_amplitude: bytes.map(|b| b / 2),
            percent_good: bytes.map(|b| b / 3),
            max_depth_m: f64::from(max_depth) * 0.1,
            reference_layer_velocity_m_s: [None; 4],
            reference_layer_percent_good: [0; 4],
        }
    }
}

prop_compose! {
    fn ensemble()(
        fixed in proptest::option::of(fixed_leader()),
        variable in proptest::option::of(variable_leader()),
        bottom_track in proptest::option::of(bottom_track()),
    ) -> Ensemble {
        let mut e = Ensemble { fixed, variable, bottom_track, ..Default::default() };
        e.size = pd0::encode_ensemble(&e).len();
        e
    }
}

fn close(a: f64, b: f64) -> bool {
    (a - b).abs() <= 1e-9 * a.abs().max(1.0)
}

/// Equality up to the decimal scaling of the wire format.
fn same(a: &Ensemble, b: &Ensemble) -> bool {
    let f = match (&a.fixed, &b.fixed) {
        (Some(x), Some(y)) => {
            x.firmware_version == y.firmware_version
                && x.system_configuration == y.system_configuration
                && x.coordinate_system == y.coordinate_system
                && x.cells == y.cells
                && x.pings_per_ensemble == y.pings_per_ensemble
                && close(x.cell_size_m, y.cell_size_m)
                && close(x.heading_alignment_deg, y.heading_alignment_deg)
                && x.serial_number == y.serial_number
                && x.beam_angle_deg == y.beam_angle_deg
                && x.frequency_khz == y.frequency_khz
                && x.upward_looking == y.upward_looking
        }
        (None, None) => true,
        _ => false,
    };
    let v = match (&a.variable, &b.variable) {
        (Some(x), Some(y)) => {
            x.ensemble_number == y.ensemble_number
                && x.rtc == y.rtc
                && x.rtc_y2k == y.rtc_y2k
                && close(x.heading_deg, y.heading_deg)
                && close(x.pitch_deg, y.pitch_deg)
                && close(x.roll_deg, y.roll_deg)
                && close(x.depth_m, y.depth_m)
                && close(x.temperature_c, y.temperature_c)
                && close(x.sound_speed_m_s, y.sound_speed_m_s)
                && x.pressure_pa
                    .zip(y.pressure_pa)
                    .is_some_and(|(p, q)| close(p, q))
        }
        (None, None) => true,
        _ => false,
    };
    let t = match (&a.bottom_track, &b.bottom_track) {
        (Some(x), Some(y)) => {
            (0..4).all(|i| {
                x.range_m[i].is_some() == y.range_m[i].is_some()
                    && x.range_m[i]
                        .zip(y.range_m[i])
                        .is_none_or(|(p, q)| close(p, q))
                    && x.velocity_m_s[i].is_some() == y.velocity_m_s[i].is_some()
                    && x.velocity_m_s[i]
                        .zip(y.velocity_m_s[i])
                        .is_none_or(|(p, q)| close(p, q))
            }) && x.correlation == y.correlation
                && x.percent_good == y.percent_good
                && close(x.max_depth_m, y.max_depth_m)
        }
        (None, None) => true,
        _ => false,
    };
    f && v && t && a.size == b.size
}

fn decode_stream(
    bytes: &[u8],
    chunks: &[usize],
) -> (Vec<Ensemble>, auvnav_drivers::framing::DecoderStats) {
    let mut d = Pd0Decoder::new();
    let mut out = Vec::new();
    let mut at = 0;
    let mut k = 0;
    while at < bytes.len() {
        let n = chunks[k % chunks.len()].max(1).min(bytes.len() - at);
        d.push(&bytes[at..at + n]);
        at += n;
        k += 1;
        while let Some(r) = d.next_ensemble() {
            out.push(r.expect("checksum-valid ensembles decode"));
        }
    }
    out.extend(d.finish());
    (out, *d.stats())
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(256))]

    #[test]
    fn encode_then_decode_is_the_identity(e in ensemble()) {
        let bytes = pd0::encode_ensemble(&e);
        let (out, stats) = pd0::decode_all(&bytes);
        prop_assert_eq!(out.len(), 1);
        prop_assert!(same(&e, &out[0]), "{:?}\n!=\n{:?}", e, out[0]);
        prop_assert_eq!(stats.checksum_errors, 0);
        prop_assert_eq!(stats.bytes_skipped, 0);
    }

    #[test]
    fn chunk_sizes_do_not_change_the_frames(
        es in proptest::collection::vec(ensemble(), 1..8),
        chunks in proptest::collection::vec(1usize..300, 1..10),
    ) {
        let bytes: Vec<u8> = es.iter().flat_map(pd0::encode_ensemble).collect();
        let (whole, _) = decode_stream(&bytes, &[bytes.len()]);
        let (pieces, stats) = decode_stream(&bytes, &chunks);
        prop_assert_eq!(whole.len(), es.len());
        prop_assert_eq!(&whole, &pieces);
        prop_assert_eq!(stats.frames, es.len() as u64);
    }

    #[test]
    fn corruption_is_counted_and_the_decoder_resynchronises(
        es in proptest::collection::vec(ensemble(), 3..8),
        victim in 0usize..8,
        flip in 8usize..200,
        junk in proptest::collection::vec(any::<u8>(), 0..64),
    ) {
        let frames: Vec<Vec<u8>> = es.iter().map(pd0::encode_ensemble).collect();
        let victim = victim % frames.len();
        let mut bytes = junk.clone();
        for (i, f) in frames.iter().enumerate() {
            let mut f = f.clone();
            if i == victim {
                let at = flip % (f.len() - 2) + 2;
                f[at] ^= 0x5a;
            }
            bytes.extend_from_slice(&f);
        }
        let (out, stats) = decode_stream(&bytes, &[97]);
        // Every other frame comes through unchanged; the damaged one is not published.
        let expected: Vec<&Ensemble> = es.iter().enumerate().filter(|(i, _)| *i != victim).map(|(_, e)| e).collect();
        prop_assert!(out.len() >= expected.len());
        let mut k = 0;
        for e in &out {
            if k < expected.len() && same(expected[k], e) {
                k += 1;
            }
        }
        prop_assert_eq!(k, expected.len(), "lost a good frame: {:?}", stats);
        prop_assert!(stats.checksum_errors + stats.bytes_skipped > 0, "{:?}", stats);
    }
}
