//! The host clock every process stamps with: `CLOCK_MONOTONIC` in nanoseconds, comparable across
//! the processes of one machine (unlike `std::time::Instant`, whose value is opaque).

use nix::time::{ClockId, clock_gettime};

/// Now, in nanoseconds of `CLOCK_MONOTONIC`.
pub fn monotonic_ns() -> u64 {
    match clock_gettime(ClockId::CLOCK_MONOTONIC) {
        Ok(t) => (t.tv_sec() as u64)
            .saturating_mul(1_000_000_000)
            .saturating_add(t.tv_nsec() as u64),
        // CLOCK_MONOTONIC cannot fail on Linux; a zero time would be visible downstream.
        Err(_) => 0,
    }
}
