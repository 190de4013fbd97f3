//! The parameters a surface calibration adjusts: their names in the vocabulary, units,
//! tolerances and derivative steps, and the candidate they are set in.

use auvnav_core::config::DvlInstallation;
use serde::Serialize;

/// A parameter of the surface calibration: its vocabulary name, unit, engineering tolerance (the
/// deviation below which it counts as determined) and derivative step.
#[derive(Debug, Clone, Copy)]
pub(super) struct Param {
    pub name: &'static str,
    pub unit: &'static str,
    pub tolerance: f64,
    pub step: f64,
}

pub(super) const PARAMS: [Param; 9] = [
    Param {
        name: "dvl.mount_yaw",
        unit: "deg",
        tolerance: 0.5,
        step: 0.05,
    },
    Param {
        name: "dvl.scale_factor",
        unit: "1",
        tolerance: 0.003,
        step: 1e-4,
    },
    Param {
        name: "dvl.time_offset",
        unit: "s",
        tolerance: 0.1,
        step: 0.02,
    },
    Param {
        name: "dvl.lever_arm.x",
        unit: "m",
        tolerance: 0.1,
        step: 0.02,
    },
    Param {
        name: "dvl.lever_arm.y",
        unit: "m",
        tolerance: 0.1,
        step: 0.02,
    },
    Param {
        name: "heading.deviation.b",
        unit: "deg",
        tolerance: 0.5,
        step: 0.05,
    },
    Param {
        name: "heading.deviation.c",
        unit: "deg",
        tolerance: 0.5,
        step: 0.05,
    },
    Param {
        name: "heading.deviation.d",
        unit: "deg",
        tolerance: 0.5,
        step: 0.05,
    },
    Param {
        name: "heading.deviation.e",
        unit: "deg",
        tolerance: 0.5,
        step: 0.05,
    },
];

/// What a surface calibration adjusts: the DVL installation and the compass's deviation card
/// (`[A, B, C, D, E]`, deg; A, a constant heading offset, is the mounting yaw's on a dead
/// reckoning and is left to it).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Candidate {
    pub dvl: DvlInstallation,
    pub compass_deviation_deg: [f64; 5],
}

/// The candidate with parameter `k` set to `v`.
pub(super) fn set(i: &mut Candidate, k: usize, v: f64) {
    match k {
        0 => i.dvl.mount_deg[2] = v,
        1 => i.dvl.scale_factor = v,
        2 => i.dvl.time_offset_s = v,
        3 => i.dvl.lever_arm_m[0] = v,
        4 => i.dvl.lever_arm_m[1] = v,
        k => i.compass_deviation_deg[k - 4] = v,
    }
}

pub(super) fn get(i: &Candidate, k: usize) -> f64 {
    match k {
        0 => i.dvl.mount_deg[2],
        1 => i.dvl.scale_factor,
        2 => i.dvl.time_offset_s,
        3 => i.dvl.lever_arm_m[0],
        4 => i.dvl.lever_arm_m[1],
        k => i.compass_deviation_deg[k - 4],
    }
}
