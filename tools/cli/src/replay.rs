//! `auvnav replay`: the command line around the replay library (`auvnav_replay`), whose items
//! are re-exported here for the other commands.

pub use auvnav_replay::*;
use std::path::PathBuf;

/// Command-line arguments of `auvnav replay`.
#[derive(clap::Args, Debug, Clone)]
pub struct ReplayArgs {
    /// The log to replay (MCAP written by auvnav).
    pub log: PathBuf,
    /// Configuration TOML: `[navigation]` (filter settings) and an optional `[initial]` state.
    #[arg(long)]
    pub config: Option<PathBuf>,
    /// Write the solution and the diagnostics: MCAP, or CSV when the name ends in .csv (the
    /// diagnostics then go to NAME.diagnostics.csv).
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// Write every Nth solution (diagnostics are always all written).
    #[arg(long, default_value_t = 1)]
    pub decimate: u64,
    /// Distance travelled beyond which points enter the error/distance figure (m).
    #[arg(long, default_value_t = 100.0)]
    pub min_distance: f64,
    /// Fuse the USBL fixes with this coupling (loose or tight; adaptive unscented filter): the
    /// configuration's `[navigation.usbl]`, or else the station survey in the log header of a
    /// simulated voyage.
    #[arg(long, value_parser = crate::args::config_enum::<auvnav_core::aid::usbl::Coupling>(auvnav_core::aid::usbl::Coupling::NAMES))]
    pub usbl: Option<auvnav_core::aid::usbl::Coupling>,
    /// Compare the solutions with those the log recorded on `nav/solution` (the daemon's live
    /// output in a recording): report the first that differs, exit with status 3 unless every
    /// recorded solution is reproduced.
    #[arg(long)]
    pub compare_recorded: bool,
    /// Where the log's truth / reference channel sits from the IMU, X,Y,Z in body axes (forward,
    /// starboard, down; m): a post-processed reference is often another sensor's position. The
    /// reference is moved to the IMU before it starts the navigation and is compared with it
    /// (`auvnav discover --reference smoothed` reports this lever arm).
    #[arg(long, value_name = "X,Y,Z", value_parser = three_numbers)]
    pub reference_lever_arm: Option<[f64; 3]>,
    /// Print the result as JSON.
    #[arg(long)]
    pub json: bool,
}

impl ReplayArgs {
    /// The library's options.
    pub fn options(&self) -> ReplayOptions {
        ReplayOptions {
            log: self.log.clone(),
            config: self.config.clone(),
            out: self.out.clone(),
            decimate: self.decimate,
            min_distance: self.min_distance,
            usbl: self.usbl,
            compare_recorded: self.compare_recorded,
            reference_lever_arm: self.reference_lever_arm,
        }
    }
}

/// `X,Y,Z` as three numbers.
fn three_numbers(s: &str) -> Result<[f64; 3], String> {
    let v: Vec<f64> = s
        .split(',')
        .map(|x| x.trim().parse::<f64>())
        .collect::<Result<_, _>>()
        .map_err(|e| format!("{s:?}: {e}"))?;
    <[f64; 3]>::try_from(v).map_err(|_| format!("{s:?}: expected X,Y,Z"))
}

/// Runs `auvnav replay` (the library's [`replay`]); a negative `--min-distance` is a usage error.
pub fn run(a: &ReplayArgs) -> anyhow::Result<ReplayReport> {
    if !(a.min_distance.is_finite() && a.min_distance >= 0.0) {
        return Err(crate::Failure::Usage(format!(
            "--min-distance {}: must be >= 0 m",
            a.min_distance
        ))
        .into());
    }
    Ok(replay(&a.options())?)
}

/// What became of the USBL fixes, the acoustic ranges and the magnetometer readings, when the log
/// has them.
fn print_aid_counts(n: &auvnav_core::navigator::NavCounters, counts: &auvnav_replay::ReplayCounts) {
    if n.usbl_unconfigured > 0 {
        println!(
            "  {} USBL fixes not used (no [navigation.usbl]; --usbl tight uses a simulated log's station)",
            n.usbl_unconfigured
        );
    } else if counts.usbl > 0 {
        println!(
            "  USBL: {} fused, {} rejected by the gate ({} reopenings), {} invalid, {} late",
            n.usbl_fused, n.usbl_rejected, n.usbl_reopened, n.usbl_invalid, n.aid_late
        );
    }
    if n.ranges_unconfigured > 0 {
        println!(
            "  {} acoustic range messages not used (no [navigation.ranges]: docs/ranges.md)",
            n.ranges_unconfigured
        );
    } else if counts.acoustic_ranges > 0 {
        println!(
            "  acoustic ranges: {} fused, {} rejected by the gate ({} reopenings), {} invalid, {} without the array's pose, {} late; {} array poses ({} refused)",
            n.ranges_fused,
            n.ranges_rejected,
            n.ranges_reopened,
            n.ranges_invalid,
            n.ranges_without_array_pose,
            n.ranges_late,
            n.array_poses,
            n.array_poses_invalid
        );
    }
    if n.magnetometer_unconfigured > 0 {
        println!(
            "  {} magnetometer readings not used (no [navigation.magnetometer])",
            n.magnetometer_unconfigured
        );
    } else if counts.magnetometer > 0 {
        println!(
            "  magnetometer heading: {} fused, {} rejected by the gate, {} disturbed, {} invalid",
            n.magnetometer_fused,
            n.magnetometer_rejected,
            n.magnetometer_disturbed,
            n.magnetometer_invalid
        );
    }
}

/// Prints a replay report for people.
pub fn print_report(r: &ReplayReport) {
    println!("auvnav replay: {}", r.log);
    if let Some(i) = &r.initial_state {
        println!(
            "  initial state from the {} at t = {:.3} s: {:.7} deg N, {:.7} deg E, height {:.2} m, \
             v_ned [{:.3}, {:.3}, {:.3}] m/s, roll/pitch/yaw [{:.3}, {:.3}, {:.3}] deg",
            i.source,
            i.time_s,
            i.latitude_deg,
            i.longitude_deg,
            i.height_m,
            i.velocity_ned_m_s[0],
            i.velocity_ned_m_s[1],
            i.velocity_ned_m_s[2],
            i.euler_deg[0],
            i.euler_deg[1],
            i.euler_deg[2]
        );
    }
    if let Some(acc) = &r.accuracy {
        println!(
            "  horizontal error: final {:.2} m, max {:.2} m, CEP50 {:.2} m over {:.0} m travelled",
            acc.horizontal_error_final_m,
            acc.horizontal_error_max_m,
            acc.horizontal_error_cep50_m,
            acc.distance_travelled_m
        );
        println!(
            "  error/distance CEP50 {:.3} %, heading error RMS {:.4} deg",
            acc.error_per_distance_cep50_percent, acc.heading_error_rms_deg
        );
        if acc.horizontal_velocity_error_rms_m_s > 0.0 {
            println!(
                "  horizontal velocity error RMS {:.4} m/s; the reference's own position departs from the integral of its velocity by {:.2} m RMS",
                acc.horizontal_velocity_error_rms_m_s, acc.truth_position_against_velocity_rms_m
            );
        }
    }
    if let Some(d) = &r.dead_reckoning {
        println!(
            "  surface run without an IMU: dead reckoning from the compass and the DVL against {} GNSS fixes over {:.0} s and {:.0} m: horizontal error final {:.2} m ({:.3} % of the distance), max {:.2} m, RMS {:.2} m, CEP50 {:.2} m",
            d.fixes_compared,
            d.duration_s,
            d.distance_travelled_m,
            d.horizontal_error_final_m,
            d.final_error_per_distance_percent,
            d.horizontal_error_max_m,
            d.horizontal_error_rms_m,
            d.horizontal_error_cep50_m
        );
        if d.readings_without_attitude > 0 || d.long_dvl_gaps > 0 {
            println!(
                "  {} DVL readings without an attitude around them, {} gaps between readings longer than {} s",
                d.readings_without_attitude,
                d.long_dvl_gaps,
                auvnav_replay::surface::DVL_GAP_S
            );
        }
    } else if r.samples_processed == 0 {
        println!(
            "  no IMU sample and no compass (attitude channel): nothing navigated, no accuracy reported"
        );
    }
    let n = &r.navigator;
    println!(
        "  {} IMU samples, {:.0} s of log in {:.3} s (real-time factor {:.0}); fused {} DVL ({} rejected, {} invalid), {} depth ({} rejected), {} GNSS ({} rejected)",
        r.samples_processed,
        r.log_duration_s,
        r.wall_s,
        r.real_time_factor,
        n.dvl_fused,
        n.dvl_rejected,
        n.dvl_invalid,
        n.depth_fused,
        n.depth_rejected,
        n.gnss_fused,
        n.gnss_rejected
    );
    print_aid_counts(n, &r.counts);
    let skipped = n.imu_out_of_order + n.imu_invalid + n.aid_late + r.counts.before_start;
    if skipped > 0 || n.imu_gaps > 0 {
        println!(
            "  skipped: {} IMU out of order, {} IMU invalid, {} late aids, {} before the initial state; {} IMU gaps bridged",
            n.imu_out_of_order, n.imu_invalid, n.aid_late, r.counts.before_start, n.imu_gaps
        );
    }
    let c = &r.counts;
    if c.written_out_of_order > 0 || c.late_aid_records > 0 || c.late_aids > 0 {
        println!(
            "  order: {} messages written out of time order put in their place ({} beyond the {:.0} s window); \
             {} aids applied late as the daemon's {} late-aid records say ({} records unmatched)",
            c.written_out_of_order,
            c.beyond_reorder_window,
            auvnav_replay::order::REORDER_WINDOW_NS as f64 * 1e-9,
            c.late_aids,
            c.late_aid_records,
            c.late_aid_records_unmatched
        );
    }
    if let Some(e) = &r.log_error {
        println!("  the log was not read whole: {e}");
    }
    if let Some(c) = &r.recorded_comparison {
        println!(
            "  against the recorded solutions: {} compared, {} differ, {} without a replayed solution{}",
            c.compared,
            c.differing,
            c.unmatched_recorded,
            match &c.first_difference {
                Some((t, what)) => format!("; first at t = {:.6} s: {what}", *t as f64 * 1e-9),
                None => String::new(),
            }
        );
    }
}
