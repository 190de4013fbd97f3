//! `auvnav usbl`: the command line around `auvnav_studies::usbl`, whose items are re-exported
//! here; the report printed for people.

pub use auvnav_studies::usbl::*;
use serde::Serialize;

/// The filter's column: the USBL aid's filter, or the range aid.
fn filter_name(r: &UsblReport) -> String {
    if r.range_aid {
        "range aid".to_owned()
    } else {
        name(&r.filter)
    }
}

fn name<T: Serialize>(x: &T) -> String {
    serde_json::to_value(x)
        .ok()
        .and_then(|v| v.as_str().map(str::to_owned))
        .unwrap_or_default()
}

/// Prints reports as a Markdown table.
pub fn print_table(reports: &[UsblReport]) {
    println!(
        "| case | coupling | filter | horiz. RMS (m) | horiz. max (m) | worst run RMS (m) | vert. RMS (m) | vel. RMS (m/s) | runs > {} m | outliers accepted / injected | clean fixes rejected | wall (s) |",
        reports.first().map_or(5.0, |r| r.divergence_m)
    );
    println!("|---|---|---|---|---|---|---|---|---|---|---|---|");
    for r in reports {
        let case = if r.outlier_fraction > 0.0 {
            format!("{:.0} % outliers", r.outlier_fraction * 100.0)
        } else if r.array_yaw_error_deg != 0.0 {
            format!("{}° array yaw error", r.array_yaw_error_deg)
        } else {
            "clean".to_owned()
        };
        println!(
            "| {case} | {} | {} | {:.3} | {:.2} | {:.3} | {:.3} | {:.4} | {}/{} | {}/{} | {} | {:.0} |",
            name(&r.coupling),
            filter_name(r),
            r.horizontal_error_rms_m,
            r.horizontal_error_max_m,
            r.worst_run_horizontal_error_rms_m,
            r.vertical_rms_m,
            r.velocity_rms_m_s,
            r.divergent_runs,
            r.runs,
            r.accepted_outliers,
            r.injected_outliers,
            r.rejected_clean,
            r.wall_s,
        );
    }
}

/// Prints one report as text.
pub fn print(r: &UsblReport) {
    println!(
        "{} {} on {} ({} runs of {:.0} s, seed {}; outliers {:.0} %, array yaw error {}°):",
        name(&r.coupling),
        filter_name(r),
        r.scenario,
        r.runs,
        r.wall_s_per_run,
        r.seed,
        r.outlier_fraction * 100.0,
        r.array_yaw_error_deg
    );
    println!(
        "  horizontal position error RMS {:.3} m (worst run {:.3} m), max {:.2} m; vertical RMS {:.3} m, max {:.2} m; velocity RMS {:.4} m/s",
        r.horizontal_error_rms_m,
        r.worst_run_horizontal_error_rms_m,
        r.horizontal_error_max_m,
        r.vertical_rms_m,
        r.vertical_max_m,
        r.velocity_rms_m_s
    );
    println!(
        "  runs above {} m: {}; USBL fixes {}, rejected {} (clean {}), gate reopened {}; outliers injected {}, accepted {}; {:.1} s",
        r.divergence_m,
        r.divergent_runs,
        r.fixes,
        r.rejected,
        r.rejected_clean,
        r.reopened,
        r.injected_outliers,
        r.accepted_outliers,
        r.wall_s
    );
}
