//! `auvnav montecarlo ranges`: the command line around `auvnav_studies::ranges`, whose items are
//! re-exported here; the report printed for people.

pub use auvnav_studies::ranges::*;

/// The reports as a Markdown table.
pub fn print(reports: &[RangesReport]) {
    println!(
        "| geometry | runs | outliers | tight RMS (m) | loose RMS (m) | none RMS (m) | tight/loose | \
         tight max (m) | divergent (tight/loose/none) |"
    );
    println!("|---|---|---|---|---|---|---|---|---|");
    for r in reports {
        let loose = r.loose.as_ref().map_or("no fix".to_string(), |l| {
            format!("{:.2}", l.horizontal_error_rms_m)
        });
        let ratio = r
            .tight_over_loose
            .map_or("—".to_string(), |x| format!("{x:.2}"));
        println!(
            "| {} | {} | {:.0} % | {:.2} | {} | {:.2} | {} | {:.2} | {}/{}/{} |",
            r.geometry,
            r.runs,
            100.0 * r.outlier_fraction,
            r.tight.horizontal_error_rms_m,
            loose,
            r.none.horizontal_error_rms_m,
            ratio,
            r.tight.horizontal_error_max_m,
            r.tight.divergent_runs,
            r.loose.as_ref().map_or(0, |l| l.divergent_runs),
            r.none.divergent_runs,
        );
    }
}
