//! How the demo's navigator starts, and the navigation part of its configuration: shared by the
//! in-process demo (`demo`) and the demo with real processes (`live`).

use crate::replay::ReplayConfig;
use auvnav_core::config::{AlignmentConfig, HeadingSource, InitialState, NavConfig};
use auvnav_shm_schema::TruthStateV1;
use auvnav_sim::{self as sim, SimConfig};
use serde::Serialize;

/// How the navigator starts.
#[derive(clap::ValueEnum, Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum DemoStart {
    /// Only the launch position is known: the attitude comes from in-motion alignment (coarse,
    /// then DVL-aided fine alignment, model 1), as the daemon's `[alignment]` does it.
    Align,
    /// The whole initial state is known (`[initial]` from the simulated truth).
    Known,
}

/// The heading standard deviation at which the demo's navigator declares itself aligned (deg).
/// The daemon's default (0.1°) is the filter's floor on this motion with the default gyro bias
/// uncertainty and is met only after about ten minutes; 0.2° is met after about four.
pub const ALIGNED_HEADING_STD_DEG: f64 = 0.2;

/// Coarse alignment time of the demo (s): the coarse heading is within about 0.5° after a minute
/// of this motion, and the fine stage takes it from there.
pub const COARSE_ALIGNMENT_S: f64 = 60.0;

/// The range aid for a scenario with seabed LBL beacons (`ranges_lbl`): the beacons where the
/// scenario surveyed them, the range noise its device has. `None` for other scenarios (a moving
/// array's pose has no emulated device).
pub fn lbl_ranges_config(cfg: &SimConfig) -> Option<auvnav_core::aid::ranges::RangesConfig> {
    let setup = cfg.scenario.acoustic.as_ref()?;
    if setup.kind != sim::scenario::AcousticKind::Lbl {
        return None;
    }
    let start = auvnav_core::earth::Geodetic {
        latitude_rad: cfg.scenario.start.latitude_deg.to_radians(),
        longitude_rad: cfg.scenario.start.longitude_deg.to_radians(),
        height_m: 0.0,
    };
    Some(auvnav_core::aid::ranges::RangesConfig {
        range_std_m: cfg.effects.usbl_range_noise.max(0.05),
        ..setup.ranges_config(&start)
    })
}

/// The navigation part of the demo's configuration: the scenario's USBL station (tight, AUKF)
/// and magnetometer when there are any, and the start. `first_truth` is the voyage's first truth
/// record (the `[initial]` state of `DemoStart::Known`, the launch position of `Align`).
pub fn session_config(
    cfg: &SimConfig,
    start: DemoStart,
    magnetometer: bool,
    first_truth: &TruthStateV1,
) -> ReplayConfig {
    let navigation = NavConfig {
        usbl: sim::StationGeometry::from_scenario(&cfg.scenario).map(|st| st.usbl_config()),
        ranges: lbl_ranges_config(cfg),
        magnetometer: (magnetometer && cfg.scenario.rates.magnetometer_hz > 0)
            .then(|| sim::sensors::MagnetometerModel::navigator_config(&cfg.effects)),
        ..NavConfig::default()
    };
    let t = first_truth;
    let (initial, alignment) = match start {
        DemoStart::Known => (
            Some(InitialState {
                latitude_deg: t.latitude_rad.to_degrees(),
                longitude_deg: t.longitude_rad.to_degrees(),
                height_m: t.height_m,
                velocity_ned_m_s: t.velocity_ned_m_s,
                euler_deg: t.euler_rad.map(f64::to_degrees),
            }),
            None,
        ),
        DemoStart::Align => (
            None,
            Some(AlignmentConfig {
                latitude_deg: t.latitude_rad.to_degrees(),
                longitude_deg: t.longitude_rad.to_degrees(),
                height_m: t.height_m,
                coarse_s: COARSE_ALIGNMENT_S,
                moored: false,
                coarse_heading_std_deg: 2.0,
                coarse_tilt_std_deg: 0.05,
                aligned_heading_std_deg: ALIGNED_HEADING_STD_DEG,
                fine_model: 1,
                heading_source: HeadingSource::Gyrocompass,
            }),
        ),
    };
    ReplayConfig {
        navigation,
        initial,
        alignment,
        ..Default::default()
    }
}
