//! The host clock (`CLOCK_MONOTONIC` in ns): [`auvnav_shm_schema::clock`], re-exported.

pub use auvnav_shm_schema::clock::monotonic_ns;
