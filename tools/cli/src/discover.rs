//! `auvnav discover`: the command line around `auvnav_discover`, whose items are re-exported
//! here; the report printed for people.

pub use auvnav_discover::*;

/// `auvnav discover`: the library's run, then the report printed (or as JSON).
pub mod command {
    pub use auvnav_discover::command::*;

    /// Runs `auvnav discover` and prints the report.
    pub fn run(a: &DiscoverOptions) -> anyhow::Result<DiscoverReport> {
        let r = auvnav_discover::command::run(a)?;
        if a.json {
            crate::json::print(&r)?;
        } else {
            print_text(&r);
        }
        Ok(r)
    }

    // Long on purpose: prints every section of the discovery report in order: a list of print
    // statements.
    fn print_text(r: &DiscoverReport) {
        println!(
            "auvnav discover: {} (reference: {})",
            r.inputs.join(", "),
            r.reference
        );
        for c in &r.channels {
            println!(
                "  {}: {} readings ({} compared, {} skipped); held-out mean squared residual {:.4e} nominal, {:.4e} with the effects found",
                c.channel.name(),
                c.epochs,
                c.compared,
                c.skipped,
                c.held_out_mse_nominal,
                c.held_out_mse_selected
            );
        }
        if let Some(v) = &r.voyages {
            println!("  {} voyages, each analysed alone:", v.voyages.len());
            for x in &v.voyages {
                let named: Vec<String> = x
                    .effects
                    .iter()
                    .map(|e| format!("{} = {}", e.name, e.value))
                    .collect();
                println!(
                    "    {}: {}",
                    x.inputs.join(", "),
                    if named.is_empty() {
                        "nothing named".into()
                    } else {
                        named.join("; ")
                    }
                );
            }
            for s in &v.scores {
                println!(
                    "  {} over {} voyages, each predicted from the others: mean squared residual \
                     {:.4e} nominal, {:.4e} with the shared effects",
                    s.channel.name(),
                    s.voyages,
                    s.mse_nominal,
                    s.mse_shared
                );
            }
            for s in &v.inconsistent {
                println!(
                    "  inconsistent: {} ({}): χ² {:.1} > {:.1} ({} dof) across the voyages: {}",
                    s.name,
                    s.channel.name(),
                    s.chi2,
                    s.chi2_limit,
                    s.dof,
                    s.verdict
                );
                for e in &s.voyages {
                    println!("      {}: {} ± {} {}", e.log, e.value, e.std, s.unit);
                }
            }
            for p in &v.per_voyage {
                println!(
                    "  per voyage: {} ({}) named in {} voyages: {}",
                    p.name,
                    p.channel.name(),
                    p.voyages.len(),
                    p.voyages
                        .iter()
                        .map(|e| format!("{} {}", e.log, e.value))
                        .collect::<Vec<_>>()
                        .join("; ")
                );
            }
        }
        if r.channels.is_empty() && r.voyages.is_none() {
            println!("  nothing analysed (see the notes)");
        } else if r.effects.is_empty() {
            println!("  effects found: none (the nominal model explains the data)");
        } else {
            println!("  effects found:");
            for e in &r.effects {
                println!(
                    "    {} = {} ± {} {} (nominal {})  ({})",
                    e.name, e.value, e.std, e.unit, e.nominal, e.evidence
                );
                if let Some(q) = &e.equivalent {
                    println!(
                        "      or {} = {:.1} ± {:.1} {}: {}",
                        q.name, q.value, q.std, q.unit, q.note
                    );
                }
            }
        }
        for u in &r.unseparable {
            println!(
                "  unseparable: {} (correlation {:.3}): {}",
                u.effects.join(" and "),
                u.correlation,
                u.note
            );
        }
        for u in &r.unobservable {
            println!(
                "  not excited by this motion: {} components {:?}",
                u.name, u.components
            );
        }
        for u in &r.undetermined {
            println!("  undetermined: {}", u.note);
        }
        if let Some(g) = &r.gnss {
            super::print_gnss(g);
        }
        for f in &r.floors {
            println!("  not named: {}", f.describe());
        }
        for u in &r.unexplained {
            println!(
                "  unexplained: {}: {}",
                u.channel.component_label(u.component),
                u.note
            );
        }
        for g in &r.gain {
            println!(
                "  held-out gain {} (fit on the first {:.0} %): rms {:?} -> {:?} {}",
                g.channel.name(),
                100.0 * g.fit_fraction,
                g.rms_before
                    .iter()
                    .map(|x| format!("{x:.4}"))
                    .collect::<Vec<_>>(),
                g.rms_after
                    .iter()
                    .map(|x| format!("{x:.4}"))
                    .collect::<Vec<_>>(),
                r.channels
                    .iter()
                    .find(|c| c.channel == g.channel)
                    .map_or("", |c| c.unit.as_str())
            );
        }
        for n in &r.noise {
            println!(
                "  noise with the effects found: {} = {:.5} {}",
                n.name, n.value, n.unit
            );
        }
        for n in &r.navigation {
            println!(
                "  navigation {}: end error {:.2} m -> {:.2} m, CEP50 {:.3} % -> {:.3} %, heading RMS {:.3} -> {:.3} deg, DVL rejected {} -> {}",
                n.log,
                n.before.horizontal_error_final_m,
                n.after.horizontal_error_final_m,
                n.before.error_per_distance_cep50_percent,
                n.after.error_per_distance_cep50_percent,
                n.before.heading_error_rms_deg,
                n.after.heading_error_rms_deg,
                n.dvl_rejected_before,
                n.dvl_rejected_after
            );
        }
        for n in &r.navigation {
            println!("  navigation {}: {}", n.log, n.verdict);
        }
        for w in &r.withheld {
            println!(
                "  not in the navigator configuration: {}: {}",
                w.name, w.note
            );
        }
        for n in &r.navigation_written {
            println!(
                "  navigation {} with the effects kept: {}",
                n.log, n.verdict
            );
        }
        for n in &r.notes {
            println!("  note: {n}");
        }
        println!("  {:.2} s", r.wall_s);
    }
}

/// The GNSS positions' decisions on a surface run's DVL installation.
fn print_gnss(g: &auvnav_discover::gnss::GnssEvidence) {
    println!(
        "  GNSS positions (independent of the DVL; windows of {:.0} m{} over {}):",
        g.threshold_m,
        if g.moving_bed {
            ", each fold's bed velocity fitted"
        } else {
            ""
        },
        g.folds.join(", ")
    );
    for d in &g.decisions {
        println!("    {}: {}: {}", d.parameter, d.verdict, d.note);
    }
    let s = &g.in_sample;
    println!(
        "    window RMS on all folds: {:.2} m nominal, {:.2} m two-point, {:.2} m fitted ({} windows)",
        s.nominal.rms_error_m, s.two_point.rms_error_m, s.calibrated.rms_error_m, s.nominal.windows
    );
    for h in &g.held_out {
        println!(
            "    held out {} (the others write {}): window RMS {:.2} m nominal, {:.2} m two-point, {:.2} m with what they write",
            h.run,
            if h.written.is_empty() {
                "nothing".to_string()
            } else {
                h.written.join(", ")
            },
            h.scores.nominal.rms_error_m,
            h.scores.two_point.rms_error_m,
            h.scores.calibrated.rms_error_m
        );
    }
    for w in &g.written_held_out {
        match (&w.score, &w.error) {
            (Some(s), _) => println!(
                "    held out {}, navigated with what `--write-config` writes from the other folds ({}): window RMS {:.2} m",
                w.fold,
                if w.written.is_empty() {
                    "nothing".to_string()
                } else {
                    w.written
                        .iter()
                        .map(|e| match e.rms_without_m {
                            Some(m) => format!("{} = {} ({m:.2} m without it)", e.name, e.value),
                            None => format!("{} = {}", e.name, e.value),
                        })
                        .collect::<Vec<_>>()
                        .join("; ")
                },
                s.rms_error_m
            ),
            (None, e) => println!(
                "    held out {}: the other folds give no configuration ({})",
                w.fold,
                e.as_deref().unwrap_or("no reason given")
            ),
        }
    }
}
