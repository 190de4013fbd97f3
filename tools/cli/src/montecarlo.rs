//! `auvnav montecarlo nees`: the command line around `auvnav_studies::nees`, whose items are
//! re-exported here.

pub use auvnav_studies::nees::*;

/// Runs `auvnav montecarlo nees` and prints the report.
pub fn run_nees(a: &NeesOptions) -> anyhow::Result<()> {
    let cfg = auvnav_replay::load_navigation(a.config.as_deref())?;
    let start = std::time::Instant::now();
    let r = nees_monte_carlo(a, &cfg)?;
    if let Some(path) = &a.series {
        write_series(path, &r)?;
    }
    if a.json {
        crate::json::print(&r)?;
    } else {
        println!(
            "NEES Monte Carlo: scenario {}, {} runs of {:.0} s, {} epochs; 95 % bounds of the run-averaged NEES [{:.3}, {:.3}] ({:.1} s wall)",
            r.scenario,
            r.runs,
            r.wall_s_per_run,
            r.epochs,
            r.lower_bound,
            r.upper_bound,
            start.elapsed().as_secs_f64()
        );
        for (name, b) in [
            ("position", &r.position),
            ("velocity", &r.velocity),
            ("attitude", &r.attitude),
        ] {
            println!(
                "  {name:9} mean ANEES {:.3} (3 expected), inside {:.1} % of epochs, above {:.1} %, below {:.1} %",
                b.mean_anees,
                100.0 * b.fraction_inside,
                100.0 * b.fraction_above,
                100.0 * b.fraction_below
            );
        }
    }
    Ok(())
}
