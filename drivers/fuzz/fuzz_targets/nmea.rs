//! Fuzz target: see common.rs.
#![no_main]

#[path = "common.rs"]
mod common;

libfuzzer_sys::fuzz_target!(|data: &[u8]| {
    common::any_bytes_in_any_chunks(auvnav_drivers::nmea::NmeaDecoder::new(), data);
});
