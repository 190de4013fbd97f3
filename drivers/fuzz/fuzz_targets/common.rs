//! The property every stream-decoder target checks: any bytes, fed in chunks whose size the
//! input's first byte chooses, never panic, and every byte is accounted for.

use auvnav_drivers::framing::{StreamDecoder, decode_stream};

pub fn any_bytes_in_any_chunks<D: StreamDecoder>(mut d: D, data: &[u8]) {
    let Some((&step, bytes)) = data.split_first() else { return };
    decode_stream(&mut d, bytes, usize::from(step).max(1), |frame| {
        std::hint::black_box(&frame);
    });
    assert_eq!(d.stats().bytes, bytes.len() as u64);
    assert!(d.stats().bytes_skipped <= d.stats().bytes);
}
