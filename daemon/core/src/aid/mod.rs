//! Aid sources: one module per aiding sensor, each holding what the sensor needs and nothing
//! else — its parameters (read from the configuration), its measurement model, its state (for
//! example the DVL installation or the USBL error estimates), its counters, and two parts: a
//! *should we fuse* part (validity, range and latency checks, counted as invalid or late) and a
//! *fuse* part (model, update, gate through [`crate::ekf::gate`], diagnostics with the same
//! meaning of `test_ratio` for every aid: above 1 = rejected).
//!
//! A fuse part works on the navigator's [`NavCore`] and returns an [`AidUpdate`]: the
//! diagnostics and, when fused, the error-state correction, which the navigator applies to the
//! core and to every aid's parameter states ([`crate::navigator::Navigator`] lists the aids).
//!
//! Adding an aid: a module here with its parameters, model, counters and fuse part; a field in
//! the navigator's list of aids (with its `correct` line when it has parameter states); an
//! `on_<aid>` entry; and its message in [`crate::feed::SensorMessage`]. `docs/architecture.md`
//! walks through it.

pub mod depth;
pub mod dvl;
pub mod gnss;
pub mod magnetometer;
pub mod pose_history;
pub mod ranges;
pub mod usbl;
pub mod zero_velocity;

use crate::ekf::StateVector;
pub use crate::nav_core::NavCore;
use auvnav_shm_schema::AidDiagnosticsV1;

/// What one aid message did: its diagnostics and, when it was fused, the correction to apply.
#[derive(Debug, Clone, Copy)]
pub struct AidUpdate {
    pub diagnostics: AidDiagnosticsV1,
    pub correction: Option<StateVector>,
}

impl AidUpdate {
    /// Not fused (invalid, late or rejected): diagnostics only.
    pub fn rejected(mut diagnostics: AidDiagnosticsV1) -> AidUpdate {
        diagnostics.flags |= AidDiagnosticsV1::FLAG_REJECTED;
        AidUpdate {
            diagnostics,
            correction: None,
        }
    }
}

impl AidUpdate {
    /// The outcome of a gated update: the diagnostics and the correction when fused; counted.
    pub fn counted(
        diagnostics: AidDiagnosticsV1,
        correction: Option<StateVector>,
        counters: &mut AidCounters,
    ) -> AidUpdate {
        if correction.is_some() {
            counters.fused += 1;
        } else {
            counters.rejected += 1;
        }
        AidUpdate {
            diagnostics,
            correction,
        }
    }
}

/// Counts of what became of an aid's messages.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct AidCounters {
    pub fused: u64,
    /// Rejected by the innovation gate (or a failed update).
    pub rejected: u64,
    /// Flagged invalid, missing fields, or values out of range.
    pub invalid: u64,
}
