//! An estimated DVL time offset, smoothed again with the readings retimed at the estimate.
//!
//! The filter's DVL model takes a time offset τ to first order: the reading stamped t is
//! `v_b(t) − τ a_b(t)`, with `a_b` from the IMU sample at t. Over a second that is a poor
//! description of an AUV's velocity change: the acceleration of one instant is not the mean
//! over the second that follows, so an offset estimated from zero comes out short. On the
//! Snapir AUV's segments the smoother gave −0.39 to −0.55 s while the readings' residuals
//! against the smoothed motion, and against the imported reference, both say −1.0 s; on
//! simulated docking voyages with a −1.0 s offset it gave −0.90 to −0.96 s (± 0.035). A
//! configured negative offset is applied exactly instead, by holding each reading until the
//! filter reaches the moment it describes (`auvnav_core::navigator::dvl_retime_s`), and the
//! first-order term is left with the rest. So the smoother runs again with the readings
//! retimed at its estimate until the estimate and the retiming agree: on Snapir segment 4 it
//! retimes at −0.46, −0.83, −1.00 and −1.03 s and ends at −1.034 ± 0.007 s, and the lever arm
//! it estimates beside it then agrees with discovery's (docs/postprocessing.md).

use auvnav_core::config::NavConfig;
use auvnav_core::smoother::SmoothedParameters;

/// Runs after the first at most (each a forward and a backward pass).
pub const MAX_RETIMINGS: usize = 6;

/// The retiming stops when the estimate is this close to it (s): the first-order term is exact
/// enough over a few hundredths of a second. Not the estimate's standard deviation: the runs
/// see the same data, so the estimate is a function of the retiming and the runs look for its
/// fixed point; how surely the data determine that point is another matter (on simulated
/// voyages the estimate stood 1.4σ short of the hidden offset after one retiming at 2σ).
pub const TOLERANCE_S: f64 = 0.02;

/// The offset to retime the DVL readings at for the next run, or `None` when the time offset is
/// not estimated, the estimate is not negative (a reading describing the past stays in the
/// first-order model), or it agrees with the offset the readings are already retimed at.
pub fn next_offset(
    n: &NavConfig,
    estimate: Option<&[(usize, SmoothedParameters); 2]>,
) -> Option<f64> {
    if !n.estimate_dvl_time_offset {
        return None;
    }
    let tau = estimate?[0].1.dvl_time_offset_s?;
    let retimed = auvnav_core::navigator::dvl_retime_s(n);
    let target = tau.value.min(0.0);
    (tau.value.is_finite() && (target - retimed).abs() > TOLERANCE_S).then_some(target)
}

/// Sets the configured DVL time offset (s), in the `[navigation.dvl]` table when the
/// configuration has one, else in `dvl_time_offset_s`.
pub fn set_dvl_time_offset(n: &mut NavConfig, offset_s: f64) {
    match n.dvl.as_mut() {
        Some(d) => d.time_offset_s = offset_s,
        None => n.dvl_time_offset_s = offset_s,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use auvnav_core::smoother::SmoothedValue;

    fn estimate(value: f64, std: f64) -> [(usize, SmoothedParameters); 2] {
        let p = SmoothedParameters {
            time_s: 0.0,
            dvl_mount_deg: None,
            dvl_scale_factor: None,
            dvl_lever_arm_m: None,
            dvl_time_offset_s: Some(SmoothedValue { value, std }),
            usbl_errors_m: None,
        };
        [(0, p.clone()), (1, p)]
    }

    #[test]
    fn a_negative_estimate_away_from_the_retiming_is_retimed_at() {
        let mut n = NavConfig {
            estimate_dvl_time_offset: true,
            ..Default::default()
        };
        assert_eq!(next_offset(&n, Some(&estimate(-0.46, 0.01))), Some(-0.46));
        set_dvl_time_offset(&mut n, -0.46);
        assert_eq!(next_offset(&n, Some(&estimate(-0.86, 0.01))), Some(-0.86));
        set_dvl_time_offset(&mut n, -0.86);
        // Within the tolerance: done, however wide the estimate.
        assert_eq!(next_offset(&n, Some(&estimate(-0.875, 0.01))), None);
        assert_eq!(next_offset(&n, Some(&estimate(-0.95, 0.05))), Some(-0.95));
        // A positive estimate takes the retiming back to none.
        assert_eq!(next_offset(&n, Some(&estimate(0.2, 0.01))), Some(0.0));
        set_dvl_time_offset(&mut n, 0.0);
        assert_eq!(next_offset(&n, Some(&estimate(0.2, 0.01))), None);
        // Not estimated: nothing to follow.
        n.estimate_dvl_time_offset = false;
        assert_eq!(next_offset(&n, Some(&estimate(-1.0, 0.01))), None);
    }
}
