//! Fuzz target: see common.rs; and the ensemble parser on raw bytes, since the checksum keeps
//! most fuzzed streams from reaching it.
#![no_main]

#[path = "common.rs"]
mod common;

libfuzzer_sys::fuzz_target!(|data: &[u8]| {
    common::any_bytes_in_any_chunks(auvnav_drivers::pd0::Pd0Decoder::new(), data);
    let _ = auvnav_drivers::pd0::decode_ensemble(data);
});
