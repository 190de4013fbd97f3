//! The studies' cost: `auvnav bench align` (the alignment Monte Carlo) and `auvnav bench usbl` (one USBL update).

#[allow(unused_imports)]
use super::*;

/// Wall time of the alignment Monte Carlo for one model.
#[derive(Debug, Clone, Serialize)]
pub struct AlignBench {
    pub model: u8,
    pub runs: usize,
    pub simulated_s_per_run: f64,
    pub threads: usize,
    pub wall_s: f64,
}

/// `auvnav bench align`: the seed's Monte Carlo (turning, 30° heading error, random mounting),
/// one model at a time (each includes simulating the runs).
pub fn align(runs: usize, json: bool) -> anyhow::Result<()> {
    let threads = std::thread::available_parallelism().map_or(1, |n| n.get());
    let mut out = Vec::new();
    for model in [1u8, 2, 3] {
        let a = crate::align::AlignOptions {
            models: vec![model],
            scenario: "turning".into(),
            runs,
            heading_error: 30.0,
            mount: "random".into(),
            seed: 1,
            seconds: 1200.0,
            converged_deg: 1.0,
            threads: None,
            per_run: false,
            json: false,
        };
        let r = crate::align::run(&a)?;
        out.push(AlignBench {
            model,
            runs,
            simulated_s_per_run: 1200.0,
            threads,
            wall_s: r.wall_s,
        });
    }
    if json {
        crate::json::print(&out)?;
    } else {
        for b in &out {
            println!(
                "align model {}: {} runs x {:.0} s in {:.1} s on {} threads",
                b.model, b.runs, b.simulated_s_per_run, b.wall_s, b.threads
            );
        }
    }
    Ok(())
}

/// Cost of one USBL update per coupling and filter.
#[derive(Debug, Clone, Serialize)]
pub struct UsblBench {
    pub coupling: auvnav_core::aid::usbl::Coupling,
    pub filter: auvnav_core::aid::usbl::UsblFilter,
    /// States the update runs over (every state with non-zero variance).
    pub states: usize,
    pub updates: usize,
    pub median_us: f64,
    pub p90_us: f64,
    pub max_us: f64,
}

/// `auvnav bench usbl`: the wall time of `Navigator::on_usbl` on the docking scenario, each
/// update timed alone on a copy of the navigator taken just before it (the copy is not timed). An
/// update includes the covariance propagation pending since the last one (at most one
/// `covariance_interval_s`, 50 ms). One thread.
pub fn usbl(seconds: f64, json: bool) -> anyhow::Result<()> {
    use anyhow::bail;
    use auvnav_core::aid::usbl::{Coupling, UsblFilter};
    use auvnav_core::feed::SensorMessage;
    use auvnav_core::session::{Session, SessionConfig};
    use auvnav_core::strapdown::NavState;
    use auvnav_log::LogMessage;
    use auvnav_sim::StationGeometry;
    use std::time::Instant;
    let scenario = Scenario::load("docking")?;
    let station =
        StationGeometry::from_scenario(&scenario).context("the docking scenario has no station")?;
    let (messages, _) = auvnav_sim::simulate_to_vec(&SimConfig {
        scenario: scenario.clone(),
        effects: scenario.effects()?,
        seed: 1,
        duration_s: Some(seconds),
    })?;
    let mut out = Vec::new();
    let cases = [Coupling::Loose, Coupling::Tight]
        .into_iter()
        .flat_map(|c| [UsblFilter::Ukf, UsblFilter::Akf, UsblFilter::Aukf].map(|f| (c, f, false)))
        .chain([(Coupling::Tight, UsblFilter::Aukf, true)]);
    for (coupling, filter, all_states) in cases {
        {
            let mut cfg = crate::usbl::navigation_config(&station, coupling, filter);
            if all_states {
                // Every DVL parameter state switched on as well: all 26 error states.
                cfg.estimate_dvl_mounting = true;
                cfg.estimate_dvl_lever_arm = true;
                cfg.estimate_dvl_time_offset = true;
            }
            // The state is reached through the daemon's feed path; each fix's update is timed on
            // a copy of the navigator as it stands when the fix arrives.
            let mut session = Session::new(&SessionConfig {
                navigation: cfg.clone(),
                ..Default::default()
            });
            let mut times = Vec::new();
            for m in &messages {
                match m {
                    LogMessage::Truth(t) if !session.started() => {
                        let s = NavState::from_truth(t);
                        session.start(s, "truth", &mut |_| Ok::<(), anyhow::Error>(()))?;
                    }
                    other if session.started() => {
                        let Some(x) = other.sensor() else { continue };
                        if let (SensorMessage::Usbl(fix), Some(n)) = (&x, session.navigator()) {
                            let mut copy = n.clone();
                            let t0 = Instant::now();
                            std::hint::black_box(copy.on_usbl(std::hint::black_box(fix)));
                            times.push(t0.elapsed().as_secs_f64() * 1e6);
                        }
                        session.feed(&x, &mut |_| Ok::<(), anyhow::Error>(()))?;
                    }
                    _ => {}
                }
            }
            let n = session
                .navigator()
                .context("the simulation produced no truth")?;
            if times.is_empty() {
                bail!("no USBL fix in {seconds} s of the docking scenario");
            }
            let states = (0..auvnav_core::ekf::N)
                .filter(|&i| n.covariance()[(i, i)] > 0.0)
                .count();
            let mut sorted = times.clone();
            sorted.sort_by(f64::total_cmp);
            out.push(UsblBench {
                coupling,
                filter,
                states,
                updates: times.len(),
                median_us: median(&times),
                p90_us: sorted[sorted.len() * 9 / 10],
                max_us: sorted[sorted.len() - 1],
            });
        }
    }
    if json {
        crate::json::print(&out)?;
    } else {
        for b in &out {
            println!(
                "usbl {:?} {:?}: {} updates over {} states: median {:.1} us, p90 {:.1} us, max {:.1} us",
                b.coupling, b.filter, b.updates, b.states, b.median_us, b.p90_us, b.max_us
            );
        }
    }
    Ok(())
}
