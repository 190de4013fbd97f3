//! Any bytes, fed in chunks whose sizes come from the input itself: the decoder must not panic,
//! must stay within its buffer bound, and must account for every byte it is given.
#![no_main]

use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let Some((&step, bytes)) = data.split_first() else { return };
    let step = usize::from(step).max(1);
    let mut d = auvnav_drivers::xsens::XbusDecoder::new();
    for chunk in bytes.chunks(step) {
        d.push(chunk);
        while let Some(frame) = d.next_message() {
            std::hint::black_box(&frame);
        }
    }
    assert_eq!(d.stats.bytes, bytes.len() as u64);
    assert!(d.stats.bytes_skipped <= d.stats.bytes);
});
