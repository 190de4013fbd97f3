//! `auvnav align` and `auvnav align-measured`: the command line around `auvnav_studies::align`,
//! whose items are re-exported here; the reports printed for people.

pub use auvnav_studies::align::*;

/// `auvnav align-measured`: every segment, every offset, every model, printed (or as JSON).
pub fn run_measured(a: &AlignMeasuredOptions) -> anyhow::Result<Vec<MeasuredRow>> {
    let rows = measured_rows(a)?;
    if a.json {
        crate::json::print(&rows)?;
    } else {
        println!("segment  offset  model  heading error at 100 / 200 / 400 s (deg)");
        for r in &rows {
            let e: Vec<String> = r
                .heading_error_deg
                .iter()
                .map(|(_, v)| format!("{v:8.3}"))
                .collect();
            println!(
                "{:7}  {:6.0}  {:5}  {}",
                r.segment,
                r.heading_offset_deg,
                r.model,
                e.join(" ")
            );
        }
    }
    Ok(rows)
}

/// Prints the report for people.
pub fn print(r: &AlignReport) {
    println!(
        "auvnav align: {} runs, scenario {}, initial heading error {} deg, mounting {}, {:.0} s",
        r.runs, r.scenario, r.heading_error_deg, r.mount, r.seconds
    );
    for m in &r.models {
        let h: Vec<String> = m
            .heading_rms_deg
            .iter()
            .map(|(t, v)| format!("{t:.0} s {v:.3}"))
            .collect();
        println!(
            "  model {}: heading RMS {}; position RMS {:.1} m; mounting error RMS {}; not converged {}",
            m.model,
            h.join(", "),
            m.position_rms_m,
            m.mount_error_rms_deg
                .map(|x| format!("{:.2}/{:.2}/{:.2} deg", x[0], x[1], x[2]))
                .unwrap_or_else(|| "-".into()),
            m.not_converged
        );
    }
    println!("  {:.1} s wall", r.wall_s);
}
