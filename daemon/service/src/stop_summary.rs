//! The daemon's stop message: what became of each sensor's messages.

use auvnav_core::navigator::NavCounters;
use auvnav_core::session::Session;

/// What became of every sensor's messages: `IMU: …; USBL fixes: …; magnetometer: …; acoustic
/// ranges: …`, or that the daemon never navigated.
pub fn sensors_summary(session: &Session) -> String {
    let Some(c) = session.navigator().map(|n| n.counters()) else {
        return "no navigation yet".into();
    };
    format!(
        "IMU: {}; USBL fixes: {}; magnetometer: {}; acoustic ranges: {}",
        imu_summary(&c),
        usbl_summary(&c),
        magnetometer_summary(&c),
        ranges_summary(&c)
    )
}

/// What became of the IMU samples, for the stop message.
fn imu_summary(c: &NavCounters) -> String {
    format!(
        "{} integrated, {} invalid or implausible, {} out of order, {} gaps bridged, {} device clock jumps",
        c.imu_samples, c.imu_invalid, c.imu_out_of_order, c.imu_gaps, c.imu_clock_jumps
    )
}

/// What became of the USBL fixes, for the stop message.
fn usbl_summary(c: &NavCounters) -> String {
    if c.usbl_unconfigured > 0 {
        return format!(
            "{} received, not used (no [navigation.usbl] in the configuration)",
            c.usbl_unconfigured
        );
    }
    format!(
        "{} fused, {} rejected by the gate ({} gate reopenings), {} invalid, {} failed",
        c.usbl_fused, c.usbl_rejected, c.usbl_reopened, c.usbl_invalid, c.usbl_failed
    )
}

/// What became of the magnetometer readings, for the stop message.
fn magnetometer_summary(c: &NavCounters) -> String {
    if c.magnetometer_unconfigured > 0 {
        return format!(
            "{} received, not used (no [navigation.magnetometer] in the configuration)",
            c.magnetometer_unconfigured
        );
    }
    format!(
        "{} fused, {} rejected by the gate, {} disturbed (magnitude far from the field model), {} invalid",
        c.magnetometer_fused,
        c.magnetometer_rejected,
        c.magnetometer_disturbed,
        c.magnetometer_invalid
    )
}

/// What became of the acoustic ranges, for the stop message.
fn ranges_summary(c: &NavCounters) -> String {
    if c.ranges_unconfigured > 0 {
        return format!(
            "{} received, not used (no [navigation.ranges] in the configuration)",
            c.ranges_unconfigured
        );
    }
    format!(
        "{} fused, {} rejected by the gate ({} reopenings), {} invalid, {} late, {} without the array's pose",
        c.ranges_fused,
        c.ranges_rejected,
        c.ranges_reopened,
        c.ranges_invalid,
        c.ranges_late,
        c.ranges_without_array_pose
    )
}
