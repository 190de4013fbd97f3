//! `auvnav smooth` and `auvnav montecarlo smoother`: the command line around `auvnav_smooth`,
//! whose items are re-exported here; the reports printed for people.

pub use auvnav_smooth::*;

/// `auvnav montecarlo smoother`.
pub mod montecarlo {
    use anyhow::Context;
    pub use auvnav_smooth::montecarlo::*;

    /// Runs `auvnav montecarlo smoother` and prints the report.
    pub fn run(a: &SmootherMonteCarloOptions) -> anyhow::Result<()> {
        let cfg = auvnav_replay::load_navigation(a.config.as_deref())?;
        let r = smoother_monte_carlo(a, &cfg)?;
        if let Some(path) = &a.series {
            let mut text = String::from(
                "time_s,forward_anees_north,forward_anees_east,forward_anees_down,smoothed_anees_north,smoothed_anees_east,smoothed_anees_down,forward_horizontal_error_sq_m2,smoothed_horizontal_error_sq_m2\n",
            );
            for row in &r.series {
                let cells: Vec<String> = row.iter().map(|v| v.to_string()).collect();
                text.push_str(&cells.join(","));
                text.push('\n');
            }
            std::fs::write(path, text).with_context(|| format!("writing {}", path.display()))?;
        }
        if a.json {
            crate::json::print(&r)?;
            return Ok(());
        }
        println!(
            "smoother Monte Carlo: scenario {}, {} runs of {:.0} s, {} truth epochs, end fix {} m ({} runs refused it); 95 % bounds of the run-averaged per-axis NEES [{:.3}, {:.3}] ({:.1} s wall)",
            r.scenario,
            r.runs,
            r.run_duration_s,
            r.epochs,
            r.end_fix_std_m,
            r.runs_end_fix_rejected,
            r.lower_bound,
            r.upper_bound,
            r.wall_s
        );
        for (name, f) in [("forward", &r.forward), ("smoothed", &r.smoothed)] {
            let axis = |a: &AxisConsistency| {
                format!(
                    "{:.2} [{:.2}, {:.2}] / {:.0} % ({})",
                    a.mean_anees,
                    a.run_interval_95[0],
                    a.run_interval_95[1],
                    100.0 * a.fraction_inside,
                    if a.consistent() {
                        "consistent"
                    } else {
                        "NOT consistent"
                    }
                )
            };
            println!(
                "  {name:8} horizontal RMS {:.2} m; per-axis mean ANEES (1 expected) [95 % interval over runs] / epochs inside the bounds: north {}, east {}, down {}",
                f.horizontal_error_rms_m,
                axis(&f.north),
                axis(&f.east),
                axis(&f.down)
            );
        }
        println!("  smoothed / forward horizontal RMS: {:.2}", r.rms_ratio);
        Ok(())
    }
}

/// Prints a smoothing report for people.
pub fn print_report(r: &SmoothReport) {
    if let Some(f) = &r.fix_file {
        println!(
            "auvnav smooth: {} fixes from {}{}",
            f.fixes.len(),
            f.path,
            match &f.first_unparsable {
                Some((line, why)) => format!(
                    "; {} lines not used (first: line {line}, {why})",
                    f.unparsable_lines
                ),
                None => String::new(),
            }
        );
    }
    for l in &r.logs {
        println!("auvnav smooth: {}", l.log);
        println!(
            "  {:.0} s of log, {} IMU samples, {} covariance epochs in {} chain(s); forward {:.2} s, backward {:.2} s, second pass {:.2} s (real-time factor {:.0})",
            l.log_duration_s,
            l.imu_samples,
            l.epochs,
            l.chains,
            l.forward_wall_s,
            l.backward_wall_s,
            l.second_pass_wall_s,
            l.real_time_factor
        );
        if !l.dvl_retimed_s.is_empty() {
            let offsets: Vec<String> = l.dvl_retimed_s.iter().map(|t| format!("{t:.3}")).collect();
            println!(
                "  DVL time offset estimated to first order, then smoothed again with the readings retimed at it: {} s",
                offsets.join(" -> ")
            );
        }
        let f = &l.fixes;
        println!(
            "  fixes: {} from the file ({} outside the log, not used); GNSS {} fused / {} rejected; USBL {} fused / {} rejected",
            f.from_file,
            f.from_file_outside_log,
            f.gnss_fused,
            f.gnss_rejected,
            f.usbl_fused,
            f.usbl_rejected
        );
        if let Some(c) = &l.against_reference {
            println!(
                "  against the reference ({} epochs): forward RMS {:.2} m, max {:.2} m, final {:.2} m; smoothed RMS {:.2} m, max {:.2} m, final {:.2} m",
                c.epochs,
                c.forward.horizontal_error_rms_m,
                c.forward.horizontal_error_max_m,
                c.forward.horizontal_error_final_m,
                c.smoothed.horizontal_error_rms_m,
                c.smoothed.horizontal_error_max_m,
                c.smoothed.horizontal_error_final_m
            );
            println!(
                "  horizontal NEES (2 when honest): forward {:.2}, smoothed {:.2}",
                c.forward_nees_horizontal_mean, c.smoothed_nees_horizontal_mean
            );
        }
        if l.epochs_smoothed_variance_above_filtered > 0 {
            println!(
                "  warning: {} epochs with a smoothed variance above the filtered one",
                l.epochs_smoothed_variance_above_filtered
            );
        }
        if let Some(e) = &l.log_error {
            println!("  the log was not read whole: {e}");
        }
        println!(
            "  smoothed track: {} (and .mcap, .geojson, .kml, .track.csv, .parameters.json); UTC: {}",
            l.outputs.smoothed_csv, l.utc_source
        );
    }
}
