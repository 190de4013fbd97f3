//! `auvnav montecarlo ranges`: the command line around `auvnav_studies::ranges`, whose items are
//! re-exported here; the report printed for people.

pub use auvnav_studies::ranges::*;

/// The reports as a Markdown table.
pub fn print(reports: &[RangesReport]) {
    println!(
        "| geometry | runs | outliers | tight RMS (m) | loose RMS (m) | none RMS (m) | tight/loose | \
         tight max (m) | divergent (tight/loose/none) | bias (m) | scale (ppm) |"
    );
    println!("|---|---|---|---|---|---|---|---|---|---|---|");
    for r in reports {
        let loose = r.loose.as_ref().map_or("no fix".to_string(), |l| {
            format!("{:.2}", l.horizontal_error_rms_m)
        });
        let ratio = r
            .tight_over_loose
            .map_or("—".to_string(), |x| format!("{x:.2}"));
        println!(
            "| {} | {} | {:.0} % | {:.2} | {} | {:.2} | {} | {:.2} | {}/{}/{} | {:.2} ± {:.2} | {:.0} ± {:.0} |",
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
            r.tight.range_bias_mean_m,
            r.tight.range_bias_std_m,
            1e6 * r.tight.range_scale_mean,
            1e6 * r.tight.range_scale_std,
        );
    }
    for r in reports.iter().filter(|r| r.ranges.bias_per_receiver) {
        let each: Vec<String> = (0..r.ranges.receivers_m.len().min(4))
            .map(|k| {
                format!(
                    "{k}: {:.2} ± {:.2}",
                    r.tight.receiver_bias_mean_m[k], r.tight.receiver_bias_std_m[k]
                )
            })
            .collect();
        println!(
            "\n{}: each receiver's range bias at the end (m, mean ± spread over the runs): {}",
            r.geometry,
            each.join(", ")
        );
    }
}
