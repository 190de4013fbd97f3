//! The one feed path: every program that runs the navigation core over sensor messages — the
//! daemon on the bus, `auvnav replay` on a log, the Monte Carlo studies, the benchmarks and the
//! tests — hands each message to `Session::feed` (`crate::session`) as a [`SensorMessage`]. The
//! session decides the order in which aids meet the IMU stream (time stamp + aid delay, then
//! kind, then sequence), so a figure measured by any of them measures the code the daemon runs.
pub use auvnav_shm_schema::sensor::SensorMessage;
