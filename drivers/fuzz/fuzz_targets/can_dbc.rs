//! Any frame (identifier, flags and payload from the input) through the sample DBC: decoding
//! must not panic and every frame must be counted exactly once.
#![no_main]

use auvnav_drivers::can::{CanFrame, DbcDecoder};
use libfuzzer_sys::fuzz_target;

const SAMPLE: &str = include_str!("../../dbc/auvnav_sensors.dbc");

fuzz_target!(|data: &[u8]| {
    let Ok(mut dec) = DbcDecoder::from_dbc(SAMPLE) else { return };
    for chunk in data.chunks(13) {
        if chunk.len() < 5 {
            break;
        }
        let id = u32::from_le_bytes([chunk[0], chunk[1], chunk[2], chunk[3]]);
        let pick = [0x181, 0x2a0, 0x18ff_0102, id & 0x1fff_ffff];
        let frame = CanFrame {
            id: pick[usize::from(chunk[4] & 3)],
            extended: chunk[4] & 4 != 0,
            data: chunk[5..].to_vec(),
        };
        let _ = dec.decode(&frame);
    }
    let s = dec.stats;
    assert_eq!(s.frames, s.decoded + s.unknown_id + s.short_frames);
});
