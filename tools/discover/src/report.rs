//! `auvnav discover --report DIR`: `report.md` with the findings and plots (residuals before and
//! after, their spectra, the held-out evidence), `report.json`, `effects.toml` and
//! `navigation.toml`.

use super::ChannelKind;
use super::findings::{DiscoverReport, NavigationGain, ResidualSeries};
use super::outputs;
use super::residuals::{periodogram_nyquist, periodogram_up_to};
use anyhow::Context;
use auvnav_replay::svg::{PALETTE, Series, plot};
use auvnav_replay::write_atomically;
use std::fmt::Write as _;
use std::path::Path;

fn component_name(kind: ChannelKind, k: usize) -> String {
    kind.component_label(k)
}

fn line(name: String, points: Vec<(f64, f64)>, color: &'static str, markers: bool) -> Series {
    Series {
        name,
        points,
        color,
        markers,
        dashed: false,
    }
}

/// Per component: residual against time, nominal and with the effects found.
fn residual_plots(s: &ResidualSeries) -> Vec<(String, String)> {
    let d = s.channel.dims();
    let t0 = s.times.first().copied().unwrap_or(0.0);
    (0..d)
        .map(|k| {
            let pick = |r: &[f64]| -> Vec<(f64, f64)> {
                s.times
                    .iter()
                    .zip(r.iter().skip(k).step_by(d))
                    .filter(|(_, v)| v.is_finite())
                    .map(|(t, v)| (t - t0, *v))
                    .collect()
            };
            let svg = plot(
                &format!("{} residual", component_name(s.channel, k)),
                "time since the first reading (s)",
                &format!("measured - predicted ({})", s.channel.unit()),
                &[
                    line("nominal model".into(), pick(&s.nominal), PALETTE[1], true),
                    line("effects found".into(), pick(&s.selected), PALETTE[0], true),
                ],
                false,
            );
            (format!("residual_{}_{}.svg", s.channel.name(), k), svg)
        })
        .collect()
}

/// The periodogram of each residual (summed over components), nominal and with the effects.
fn spectrum_plot(s: &ResidualSeries) -> (String, String) {
    let d = s.channel.dims();
    let summed = |r: &[f64]| -> Vec<(f64, f64)> {
        let mut total: Vec<(f64, f64)> = Vec::new();
        // One frequency grid for every component, though a component may miss readings.
        let nyquist = periodogram_nyquist(&s.times);
        for k in 0..d {
            let (t, c): (Vec<f64>, Vec<f64>) = s
                .times
                .iter()
                .zip(r.iter().skip(k).step_by(d))
                .filter(|(_, v)| v.is_finite())
                .map(|(t, v)| (*t, *v))
                .unzip();
            for (i, (f, p)) in periodogram_up_to(&t, &c, nyquist).into_iter().enumerate() {
                match total.get_mut(i) {
                    Some(x) => x.1 += p,
                    None => total.push((f, p)),
                }
            }
        }
        // Power in decibels (relative), so that lines and floor are both visible.
        total
            .into_iter()
            .map(|(f, p)| (f, 10.0 * p.max(1e-30).log10()))
            .collect()
    };
    let svg = plot(
        &format!("{} residual spectrum", s.channel.name()),
        "frequency (Hz)",
        &format!("power (dB, {}^2 per bin, relative)", s.channel.unit()),
        &[
            line(
                "nominal model".into(),
                summed(&s.nominal),
                PALETTE[1],
                false,
            ),
            line(
                "effects found".into(),
                summed(&s.selected),
                PALETTE[0],
                false,
            ),
        ],
        false,
    );
    (format!("spectrum_{}.svg", s.channel.name()), svg)
}

/// The Allan deviation of an IMU channel's residual with the effects found, per component, on
/// logarithmic axes (None for channels without one).
fn allan_plot(c: &super::findings::ChannelReport) -> Option<(String, String)> {
    if c.allan.is_empty() {
        return None;
    }
    let series: Vec<Series> = (0..c.channel.dims())
        .map(|k| {
            let points = c
                .allan
                .iter()
                .filter(|a| a.deviation[k] > 0.0)
                .map(|a| (a.tau_s.log10(), a.deviation[k].log10()))
                .collect();
            line(
                component_name(c.channel, k),
                points,
                PALETTE[k % PALETTE.len()],
                true,
            )
        })
        .collect();
    let svg = plot(
        &format!("{} residual Allan deviation", c.channel.name()),
        "log10 cluster time (s)",
        &format!("log10 Allan deviation ({})", c.channel.unit()),
        &series,
        false,
    );
    Some((format!("allan_{}.svg", c.channel.name()), svg))
}

/// An effect value or standard deviation for a table: five significant digits.
fn short(v: &serde_json::Value) -> String {
    let one = |x: &serde_json::Value| match x.as_f64() {
        Some(x) if x != 0.0 && (x.abs() < 1e-3 || x.abs() >= 1e5) => format!("{x:.4e}"),
        Some(x) => {
            // Zero (log10 = -inf) and non-finite values get no decimals rather than overflow.
            let magnitude = x.abs().log10().floor();
            let digits = if magnitude.is_finite() {
                (4 - magnitude as i32).clamp(0, 8) as usize
            } else {
                0
            };
            format!("{x:.digits$}")
        }
        None => "–".into(),
    };
    match v {
        serde_json::Value::Array(a) => {
            format!("[{}]", a.iter().map(one).collect::<Vec<_>>().join(", "))
        }
        x => one(x),
    }
}

/// The report's Markdown.
// Long on purpose: writes every section of the Markdown report in order.
fn markdown(r: &DiscoverReport, figures: &[(ChannelKind, Vec<String>)]) -> String {
    let mut m = String::new();
    let _ = writeln!(m, "# Model discovery\n");
    let _ = writeln!(
        m,
        "Inputs: {}  \nReference: {}  \nWall time: {:.2} s\n",
        r.inputs.join(", "),
        r.reference,
        r.wall_s
    );
    let _ = writeln!(m, "## Effects found\n");
    if r.effects.is_empty() {
        let _ = writeln!(
            m,
            "None: the nominal model explains the data within the selection thresholds.\n"
        );
    } else {
        let _ = writeln!(
            m,
            "| effect | value | std | nominal | unit | channel | held-out gain | evidence |\n|---|---|---|---|---|---|---|---|"
        );
        for e in &r.effects {
            let _ = writeln!(
                m,
                "| `{}` | {} | {} | {} | {} | {} | {:.1} % | {} |",
                e.name,
                short(&e.value),
                short(&e.std),
                short(&e.nominal),
                e.unit,
                e.channel.name(),
                100.0 * e.gain,
                e.evidence
            );
        }
        let _ = writeln!(m);
    }
    if !r.unseparable.is_empty() {
        let _ = writeln!(m, "## Not separable on this motion\n");
        for u in &r.unseparable {
            let _ = writeln!(
                m,
                "- {} (correlation {:.3}): {}",
                u.effects
                    .iter()
                    .map(|e| format!("`{e}`"))
                    .collect::<Vec<_>>()
                    .join(" and "),
                u.correlation,
                u.note
            );
        }
        let _ = writeln!(m);
    }
    if !r.unobservable.is_empty() {
        let _ = writeln!(m, "## Not excited by this motion\n");
        for u in &r.unobservable {
            let _ = writeln!(m, "- `{}` components {:?}", u.name, u.components);
        }
        let _ = writeln!(m);
    }
    if !r.undetermined.is_empty() {
        let _ = writeln!(
            m,
            "## Pointed at, not determined\n\nCandidates that lower the held-out score but do not \
             stand out from nominal once the residual's correlation in time is allowed for: not \
             named, not written into the model.\n"
        );
        for u in &r.undetermined {
            let _ = writeln!(m, "- {}", u.note);
        }
        let _ = writeln!(m);
    }
    if let Some(g) = &r.gnss {
        m.push_str(&super::gnss::markdown(g));
    }
    if let Some(f) = &r.refit {
        let _ = writeln!(
            m,
            "### Fitted again without what is withheld\n\n`navigation.toml` is written from \
             discovery run again with {} never selected: {}.\n",
            f.without.join(", "),
            f.changes.join("; ")
        );
    }
    if !r.floors.is_empty() {
        let _ = writeln!(
            m,
            "## What these logs cannot show\n\nEvery candidate not named, with the size it would need \
             to be named on this motion (linearised): below it an effect is neither found nor \
             excluded.\n"
        );
        for f in &r.floors {
            let _ = writeln!(m, "- {}", f.describe());
        }
        let _ = writeln!(m);
    }
    let _ = writeln!(m, "## Held-out gain\n");
    let _ = writeln!(
        m,
        "Effects fitted on the first part of each channel, residual RMS on the rest.\n\n| channel | fit on | component | RMS nominal | RMS with the effects |\n|---|---|---|---|---|"
    );
    for g in &r.gain {
        for (k, (b, a)) in g.rms_before.iter().zip(&g.rms_after).enumerate() {
            let _ = writeln!(
                m,
                "| {} | {:.0} % | {} | {:.4} {u} | {:.4} {u} |",
                g.channel.name(),
                100.0 * g.fit_fraction,
                component_name(g.channel, k),
                b,
                a,
                u = g.channel.unit()
            );
        }
    }
    let _ = writeln!(m);
    if !r.navigation.is_empty() {
        let _ = writeln!(
            m,
            "## Navigation error\n\nEach log replayed with the nominal installation and with the \
             effects found (held out: fitted on the other voyages, or on the first part of the \
             readings; the rest of the configuration: the log's own or the defaults). Errors \
             against the log's reference; *reference's own* is the RMS by which the reference's \
             position departs from the integral of its own velocity (a reference that merges \
             position fixes: metres), the scale of what it can tell apart in position.\n\n\
             {NAVIGATION_HEAD}"
        );
        navigation_rows(&mut m, &r.navigation);
        let _ = writeln!(m);
        if !r.withheld.is_empty() {
            let _ = writeln!(
                m,
                "### What the navigator configuration carries\n\nWith every effect found some \
                 log navigated worse; `navigation.toml` carries the largest set of them with \
                 which none does. Left out, with the logs that navigate worse when each is \
                 added to that set:\n"
            );
            for w in &r.withheld {
                let _ = writeln!(m, "- `{}`: {}", w.name, w.note);
            }
            let _ = writeln!(m);
            if r.navigation_written.is_empty() {
                let _ = writeln!(
                    m,
                    "Every effect was withheld: `navigation.toml` keeps the nominal installation."
                );
            } else {
                let _ = writeln!(m, "Each log with the effects kept:\n\n{NAVIGATION_HEAD}");
                navigation_rows(&mut m, &r.navigation_written);
            }
        }
        let _ = writeln!(m);
    }
    let _ = writeln!(m, "## Unexplained structure\n");
    if r.unexplained.is_empty() {
        let _ = writeln!(m, "None: every residual is white with the effects found.\n");
    } else {
        for u in &r.unexplained {
            let _ = writeln!(
                m,
                "- {}: {}",
                component_name(u.channel, u.component),
                u.note
            );
        }
        let _ = writeln!(m);
    }
    for c in r.channels.iter().filter(|c| !c.allan.is_empty()) {
        let _ = writeln!(
            m,
            "## Allan deviation: {} residual ({})\n\nWith the effects found; at 1 s it \
             includes the reference's own noise.\n",
            c.channel.name(),
            c.unit
        );
        let names: Vec<String> = (0..c.channel.dims())
            .map(|k| component_name(c.channel, k))
            .collect();
        let _ = writeln!(m, "| tau (s) | {} |", names.join(" | "));
        let _ = writeln!(m, "|---|{}", "---|".repeat(names.len()));
        for a in &c.allan {
            let v: Vec<String> = a.deviation.iter().map(|x| format!("{x:.4}")).collect();
            let _ = writeln!(m, "| {:.0} | {} |", a.tau_s, v.join(" | "));
        }
        let _ = writeln!(m);
    }
    if !r.noise.is_empty() {
        let _ = writeln!(m, "## Noise with the effects found\n");
        for n in &r.noise {
            let _ = writeln!(m, "- `{}` = {:.5} {} ({})", n.name, n.value, n.unit, n.note);
        }
        let _ = writeln!(m);
    }
    let _ = writeln!(
        m,
        "## Files\n\n- `effects.toml`: the extended model for `auvnav sim --effects-from`\n- `navigation.toml`: the installation for the navigator (`auvnav replay --config`, the daemon)\n- `report.json`: this report for scripts\n"
    );
    for (kind, files) in figures {
        let _ = writeln!(m, "## Residuals: {}\n", kind.name());
        for f in files {
            let _ = writeln!(m, "![{f}]({f})\n");
        }
    }
    if !r.notes.is_empty() {
        let _ = writeln!(m, "## Notes\n");
        for n in &r.notes {
            let _ = writeln!(m, "- {n}");
        }
    }
    m
}

/// Writes the report directory.
pub fn write_report_dir(dir: &Path, r: &DiscoverReport) -> anyhow::Result<()> {
    std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    write_atomically(
        &dir.join("report.json"),
        &auvnav_replay::json::to_string_pretty(r)?,
    )?;
    write_atomically(&dir.join("effects.toml"), &outputs::effect_set_toml(r))?;
    write_atomically(&dir.join("navigation.toml"), &outputs::navigator_toml(r)?)?;
    let mut figures = Vec::new();
    for s in &r.residuals {
        let mut files = Vec::new();
        let allan = r
            .channels
            .iter()
            .find(|c| c.channel == s.channel)
            .and_then(allan_plot);
        for (name, svg) in residual_plots(s)
            .into_iter()
            .chain(std::iter::once(spectrum_plot(s)))
            .chain(allan)
        {
            write_atomically(&dir.join(&name), &svg)?;
            files.push(name);
        }
        figures.push((s.channel, files));
    }
    let mut md = markdown(r, &figures);
    if let Some(v) = &r.voyages {
        md.push_str(&voyages_markdown(dir, v)?);
        for (i, x) in v.voyages.iter().enumerate() {
            write_report_dir(&dir.join(format!("voyage-{:02}", i + 1)), x)?;
        }
    }
    write_atomically(&dir.join("report.md"), &md)?;
    Ok(())
}

/// The voyages' section: each installation effect tested together, the voyages' own estimates
/// (plotted with ±2σ), and where each voyage's own report is.
fn voyages_markdown(dir: &Path, v: &super::voyages::Voyages) -> anyhow::Result<String> {
    use super::analysis::values_of;
    let mut m = String::new();
    let _ = writeln!(
        m,
        "## Voyages

Each log is a voyage of its own, analysed against its own reference \
         (`voyage-NN/report.md`). Installation effects are tested on all voyages together, each \
         voyage predicted from the others; an effect on which the voyages disagree beyond their \
         uncertainties (χ² at 1 %) is inconsistent, not a finding.\n"
    );
    let _ = writeln!(m, "| voyage | report | named alone |\n|---|---|---|");
    for (i, x) in v.voyages.iter().enumerate() {
        let named: Vec<String> = x.effects.iter().map(|e| format!("`{}`", e.name)).collect();
        let _ = writeln!(
            m,
            "| {} | [voyage-{:02}](voyage-{:02}/report.md) | {} |",
            x.inputs.join(", "),
            i + 1,
            i + 1,
            if named.is_empty() {
                "nothing".into()
            } else {
                named.join(", ")
            }
        );
    }
    let _ = writeln!(
        m,
        "\n| channel | voyages | held-out mean square, nominal | with the shared effects |\n|---|---|---|---|"
    );
    for s in &v.scores {
        let _ = writeln!(
            m,
            "| {} | {} | {:.4e} | {:.4e} |",
            s.channel.name(),
            s.voyages,
            s.mse_nominal,
            s.mse_shared
        );
    }
    let _ = writeln!(
        m,
        "\n| effect | verdict | value | std | χ² / limit (dof) | per voyage |\n|---|---|---|---|---|---|"
    );
    for (s, shared) in v
        .shared
        .iter()
        .map(|s| (s, true))
        .chain(v.inconsistent.iter().map(|s| (s, false)))
    {
        let file = format!(
            "voyages_{}_{}.svg",
            s.channel.name(),
            s.name.replace('.', "_")
        );
        let values: Vec<Vec<f64>> = s
            .voyages
            .iter()
            .map(|e| values_of(&e.value).unwrap_or_default())
            .collect();
        let stds: Vec<Vec<f64>> = s
            .voyages
            .iter()
            .map(|e| values_of(&e.std).unwrap_or_default())
            .collect();
        let dims = values.first().map_or(0, Vec::len);
        let mut series = Vec::new();
        for k in 0..dims {
            let pts = |f: f64| -> Vec<(f64, f64)> {
                values
                    .iter()
                    .zip(&stds)
                    .enumerate()
                    .filter_map(|(i, (v, sd))| {
                        let (x, e) = (*v.get(k)?, *sd.get(k)?);
                        (x + f * e)
                            .is_finite()
                            .then_some(((i + 1) as f64, x + f * e))
                    })
                    .collect()
            };
            let color = PALETTE[k % PALETTE.len()];
            let label = if dims > 1 {
                format!(" [{k}]")
            } else {
                String::new()
            };
            series.push(line(format!("estimate{label}"), pts(0.0), color, true));
            let mut band = line(format!("±2σ{label}"), pts(2.0), color, true);
            band.dashed = true;
            series.push(band);
            let mut low = line(String::new(), pts(-2.0), color, true);
            low.dashed = true;
            series.push(low);
        }
        let svg = plot(
            &format!("{}: each voyage's estimate", s.name),
            "voyage",
            &format!("{} ({})", s.name, s.unit),
            &series,
            false,
        );
        write_atomically(&dir.join(&file), &svg)?;
        let _ = writeln!(
            m,
            "| `{}` | {} | {} | {} | {:.1} / {:.1} ({}) | ![]({file}) |",
            s.name,
            if shared {
                "shared".to_string()
            } else {
                format!("**inconsistent**: {}", s.verdict)
            },
            short(&s.value),
            short(&s.std),
            s.chi2,
            s.chi2_limit,
            s.dof
        );
    }
    for p in &v.per_voyage {
        let _ = writeln!(
            m,
            "\nPer voyage, `{}` ({}) named in {} of {} voyages: {}",
            p.name,
            p.channel.name(),
            p.voyages.len(),
            v.voyages.len(),
            p.voyages
                .iter()
                .map(|e| format!("{} {}", e.log, short(&e.value)))
                .collect::<Vec<_>>()
                .join("; ")
        );
    }
    Ok(m)
}

/// The header of a navigation table ([`navigation_rows`]).
const NAVIGATION_HEAD: &str = "| log | RMS before | after | end before | after | velocity RMS \
     before | after | reference's own | DVL rejected before | after | verdict |\n\
     |---|---|---|---|---|---|---|---|---|---|---|";

/// One row per log: its navigation error before and after.
fn navigation_rows(m: &mut String, gains: &[NavigationGain]) {
    for n in gains {
        let (b, a) = (&n.before, &n.after);
        let _ = writeln!(
            m,
            "| {} | {:.2} m | {:.2} m | {:.2} m | {:.2} m | {:.1} mm/s | {:.1} mm/s | {:.2} m | {} | {} | {} |",
            n.log,
            b.horizontal_error_rms_m,
            a.horizontal_error_rms_m,
            b.horizontal_error_final_m,
            a.horizontal_error_final_m,
            1e3 * b.horizontal_velocity_error_rms_m_s,
            1e3 * a.horizontal_velocity_error_rms_m_s,
            b.truth_position_against_velocity_rms_m,
            n.dvl_rejected_before,
            n.dvl_rejected_after,
            n.verdict.split(':').next().unwrap_or_default()
        );
    }
}
