//! Surface runs: a DVL installation calibrated and judged against GNSS fixes taken throughout,
//! with a compass (or an AHRS) for attitude instead of an IMU — a boat's ADCP, a vehicle on the
//! surface, the trials S-CAL itself was published on. The GNSS does not come from the DVL, so
//! the gain it measures is independent of the DVL.
//!
//! Each run is dead-reckoned ([`auvnav_core::dead_reckoning`]) with a candidate installation;
//! the score is S-CAL's: from every fix A (one a second), the first fix B at least the distance
//! threshold further along the GNSS track, and the dead-reckoned displacement A → B against the
//! fixes' — its error in metres and as a fraction of the distance. The installation is fitted by
//! Gauss–Newton (numerical derivatives) on the squared window errors; its standard deviations
//! are widened by the windows' overlap (the windows of one stretch share their errors). A
//! parameter is written when it stands five deviations from its starting value; the others are
//! held at their starting values (the least determined first, the rest fitted again) and
//! reported as consistent with it (deviation within the parameter's engineering tolerance) or as
//! not determined. Beside it, the
//! S-CAL two-point formulas (yaw and scale from the first and last fix of each run) are scored
//! the same way.

use crate::voyage::VoyageSpec;
use crate::{CalibrationError, error::unusable};
use auvnav_replay::surface::{DVL_GAP_S, read_surface_run};
pub use auvnav_replay::surface::{SurfaceRun, is_surface_run};
use nalgebra::{DMatrix, DVector};
use serde::Serialize;

pub mod compass;
mod params;
mod report;
mod score;
pub use params::Candidate;
use params::{PARAMS, get, set};
pub use report::*;
pub use score::score_installation;

/// One scoring window: the fixes A and B (indices) and the GNSS distance along the track.
#[derive(Debug, Clone, Copy)]
struct Window {
    a: usize,
    b: usize,
    distance_m: f64,
}

/// Deviations from its starting value below which a parameter determined to its tolerance but not
/// written reads as consistent with it; between this and the five that write it, the runs point
/// at a change without confirming it.
const CONSISTENT_SIGMAS: f64 = 3.0;

/// Margin at both ends of a run within which no window starts or ends (s): the largest time
/// offset a candidate may take without changing the windows scored.
const COVER_S: f64 = 3.0;

/// Windows from a fix each second to the first fix `threshold_m` further along the track.
fn windows(run: &SurfaceRun, threshold_m: f64) -> Vec<Window> {
    // Along-track distance over fixes a second apart (10 Hz noise would add up otherwise).
    let mut along = vec![0.0; run.fixes.len()];
    let mut last = 0usize;
    for i in 1..run.fixes.len() {
        along[i] = along[last];
        if run.fixes[i].0 - run.fixes[last].0 >= 1.0 {
            let (p, q) = (run.fixes[last], run.fixes[i]);
            along[i] += (q.1 - p.1).hypot(q.2 - p.2);
            last = i;
        }
    }
    // Fixes the dead reckoning covers whatever time offset within ±COVER_S is tried, so
    // that every candidate is scored on the same windows.
    let (first, last) = match (run.dvl.first(), run.dvl.last()) {
        (Some(a), Some(b)) => (a.t_s + COVER_S, b.t_s - COVER_S),
        _ => return Vec::new(),
    };
    let covered = |i: usize| (first..=last).contains(&run.fixes[i].0);
    // DVL gaps longer than the dead reckoning's gap limit: across one the track is a straight
    // line between the readings on either side, so a window that spans it scores the gap, not
    // the installation.
    let gaps: Vec<(f64, f64)> = run
        .dvl
        .windows(2)
        .filter(|p| p[1].t_s - p[0].t_s > DVL_GAP_S)
        .map(|p| (p[0].t_s, p[1].t_s))
        .collect();
    let spans_gap = |a: usize, b: usize| {
        let (ta, tb) = (run.fixes[a].0, run.fixes[b].0);
        gaps.iter().any(|g| g.0 < tb && g.1 > ta)
    };
    let mut out = Vec::new();
    let mut next_start = f64::NEG_INFINITY;
    for a in 0..run.fixes.len() {
        if run.fixes[a].0 < next_start || !covered(a) {
            continue;
        }
        next_start = run.fixes[a].0 + 1.0;
        let Some(b) = (a + 1..run.fixes.len()).find(|&b| along[b] - along[a] >= threshold_m) else {
            break;
        };
        if !covered(b) {
            break;
        }
        if spans_gap(a, b) {
            continue;
        }
        out.push(Window {
            a,
            b,
            distance_m: along[b] - along[a],
        });
    }
    out
}

/// The dead-reckoned displacement error of each window (north, east, m), `None` for a window
/// the track does not cover. With `moving_bed`, the run's bed velocity (north, east) that best
/// explains the errors is taken off: the bottom track measures the boat against a bed the
/// current carries, so the dead reckoning lags the GNSS by the bed's velocity times the window's
/// duration — a nuisance of each run, fitted in closed form for every candidate.
fn window_errors(
    run: &SurfaceRun,
    c: &Candidate,
    windows: &[Window],
    moving_bed: bool,
) -> Vec<Option<[f64; 2]>> {
    let track = run.dead_reckon(&c.dvl, &c.compass_deviation_deg);
    let mut errors: Vec<Option<[f64; 2]>> = windows
        .iter()
        .map(|w| {
            let (fa, fb) = (run.fixes[w.a], run.fixes[w.b]);
            let (ta, tb) = (track.at(fa.0)?, track.at(fb.0)?);
            Some([
                (tb[0] - ta[0]) - (fb.1 - fa.1),
                (tb[1] - ta[1]) - (fb.2 - fa.2),
            ])
        })
        .collect();
    if moving_bed {
        let duration = |w: &Window| run.fixes[w.b].0 - run.fixes[w.a].0;
        let (mut ed, mut dd) = ([0.0; 2], 0.0);
        for (e, w) in errors.iter().zip(windows) {
            if let Some(e) = e {
                let d = duration(w);
                ed = [ed[0] + e[0] * d, ed[1] + e[1] * d];
                dd += d * d;
            }
        }
        if dd > 0.0 {
            let bed = [ed[0] / dd, ed[1] / dd];
            for (e, w) in errors.iter_mut().zip(windows) {
                if let Some(e) = e {
                    let d = duration(w);
                    *e = [e[0] - bed[0] * d, e[1] - bed[1] * d];
                }
            }
        }
    }
    errors
}

/// The score of an installation on runs: per run and over all.
#[derive(Debug, Clone, Serialize)]
pub struct SurfaceScore {
    pub windows: usize,
    /// RMS of the window errors (m).
    pub rms_error_m: f64,
    /// Median and mean of error / distance over the windows (%).
    pub median_error_per_distance_percent: f64,
    pub mean_error_per_distance_percent: f64,
}

fn score(runs: &[(&SurfaceRun, Vec<Window>)], inst: &Candidate, moving_bed: bool) -> SurfaceScore {
    let (mut sq, mut ratios) = (0.0, Vec::new());
    for (run, windows) in runs {
        for (e, w) in window_errors(run, inst, windows, moving_bed)
            .iter()
            .zip(windows)
        {
            if let Some(e) = e {
                let m = e[0].hypot(e[1]);
                sq += m * m;
                ratios.push(100.0 * m / w.distance_m.max(1e-9));
            }
        }
    }
    let n = ratios.len();
    let mean = ratios.iter().sum::<f64>() / n.max(1) as f64;
    ratios.sort_by(f64::total_cmp);
    SurfaceScore {
        windows: n,
        rms_error_m: (sq / n.max(1) as f64).sqrt(),
        median_error_per_distance_percent: ratios.get(n / 2).copied().unwrap_or(f64::NAN),
        mean_error_per_distance_percent: mean,
    }
}

/// One fitted parameter.
#[derive(Debug, Clone, Serialize)]
pub struct FittedParam {
    pub name: String,
    pub unit: String,
    pub start: f64,
    pub estimate: f64,
    /// Standard deviation, widened by the windows' overlap.
    pub std: f64,
    /// `written`, `consistent with its starting value`, or `not determined (…)`.
    pub verdict: String,
    pub written: bool,
}

/// A Gauss–Newton fit of `which` parameters on the runs' window errors, from `start`.
fn fit(
    runs: &[(&SurfaceRun, Vec<Window>)],
    start: &Candidate,
    which: &[usize],
    moving_bed: bool,
) -> (Candidate, Vec<f64>) {
    let residuals = |inst: &Candidate| -> Vec<f64> {
        let mut r = Vec::new();
        for (run, windows) in runs {
            for e in window_errors(run, inst, windows, moving_bed) {
                // A window the track stops covering counts as it did at the start: zero change.
                let e = e.unwrap_or([0.0, 0.0]);
                r.extend(e);
            }
        }
        r
    };
    let mut inst = start.clone();
    let mut r = residuals(&inst);
    let mut cost: f64 = r.iter().map(|x| x * x).sum();
    let mut lambda = 1e-3;
    let mut j = DMatrix::zeros(r.len(), which.len());
    for _ in 0..30 {
        for (c, &k) in which.iter().enumerate() {
            let mut moved = inst.clone();
            set(&mut moved, k, get(&inst, k) + PARAMS[k].step);
            let rp = residuals(&moved);
            for (row, (a, b)) in rp.iter().zip(&r).enumerate() {
                j[(row, c)] = (a - b) / PARAMS[k].step;
            }
        }
        let jtj = j.transpose() * &j;
        let g = j.transpose() * DVector::from_column_slice(&r);
        let mut improved = false;
        for _ in 0..8 {
            let mut a = jtj.clone();
            for d in 0..which.len() {
                a[(d, d)] *= 1.0 + lambda;
            }
            let Some(step) = a.lu().solve(&(-&g)) else {
                lambda *= 10.0;
                continue;
            };
            let mut trial = inst.clone();
            for (c, &k) in which.iter().enumerate() {
                set(&mut trial, k, get(&inst, k) + step[c]);
            }
            let rt = residuals(&trial);
            let ct: f64 = rt.iter().map(|x| x * x).sum();
            if ct < cost {
                let small = (cost - ct) < 1e-10 * cost.max(1e-12);
                (inst, r, cost) = (trial, rt, ct);
                lambda = (lambda / 10.0).max(1e-9);
                improved = !small;
                break;
            }
            lambda *= 10.0;
        }
        if !improved {
            break;
        }
    }
    // Deviations: σ² (JᵀJ)⁻¹, σ² from the residual, widened by the overlap of the windows (each
    // stretch of the track appears in `overlap` windows).
    // Each run's bed velocity is two more parameters.
    let nuisance = if moving_bed { 2 * runs.len() } else { 0 };
    let dof = (r.len() as f64 - (which.len() + nuisance) as f64).max(1.0);
    let s2 = cost / dof;
    let windows: usize = runs.iter().map(|(_, w)| w.len()).sum();
    let span: f64 = runs
        .iter()
        .filter_map(|(run, w)| {
            let (first, last) = (w.first()?, w.last()?);
            Some(run.fixes[last.b].0 - run.fixes[first.a].0)
        })
        .sum();
    let window_s: f64 = runs
        .iter()
        .flat_map(|(run, w)| w.iter().map(|x| run.fixes[x.b].0 - run.fixes[x.a].0))
        .sum::<f64>()
        / windows.max(1) as f64;
    let independent = (span / window_s.max(1e-9)).max(1.0);
    let overlap = (windows as f64 / independent).max(1.0);
    let cov = (j.transpose() * &j)
        .try_inverse()
        .unwrap_or_else(|| DMatrix::from_element(which.len(), which.len(), f64::INFINITY));
    // As many residuals as parameters or fewer leave nothing to estimate the scatter from: the
    // fit passes through them and determines nothing.
    let determined = r.len() > which.len() + nuisance;
    let std = (0..which.len())
        .map(|d| {
            if determined {
                (s2 * overlap * cov[(d, d)]).max(0.0).sqrt()
            } else {
                f64::INFINITY
            }
        })
        .collect();
    (inst, std)
}

/// The two-point installation (S-CAL's formulas (a)): yaw and scale from the displacement between
/// the first and last fix of each run against the dead reckoning with `start`, averaged with the
/// runs' distances as weights.
fn two_point(runs: &[&SurfaceRun], start: &Candidate) -> Candidate {
    let (mut yaw, mut scale, mut weight) = (0.0, 0.0, 0.0);
    for run in runs {
        let track = run.dead_reckon(&start.dvl, &start.compass_deviation_deg);
        // The first and last fixes the track covers.
        let covered: Vec<&(f64, f64, f64)> = run
            .fixes
            .iter()
            .filter(|f| track.at(f.0).is_some())
            .collect();
        let (Some(a), Some(b)) = (covered.first(), covered.last()) else {
            continue;
        };
        let (Some(ta), Some(tb)) = (track.at(a.0), track.at(b.0)) else {
            continue;
        };
        let (gn, ge) = (b.1 - a.1, b.2 - a.2);
        let (dn, de) = (tb[0] - ta[0], tb[1] - ta[1]);
        let (g_len, d_len) = (gn.hypot(ge), dn.hypot(de));
        if g_len < 1.0 || d_len < 1.0 {
            continue;
        }
        // χ_DVL − χ_GPS; the yaw that turns the dead reckoning onto the fixes' course.
        let eps = auvnav_replay::accuracy::wrap(de.atan2(dn) - ge.atan2(gn));
        yaw += g_len * (start.dvl.mount_deg[2] - eps.to_degrees());
        scale += g_len * (start.dvl.scale_factor * d_len / g_len);
        weight += g_len;
    }
    let mut out = start.clone();
    if weight > 0.0 {
        out.dvl.mount_deg[2] = yaw / weight;
        out.dvl.scale_factor = scale / weight;
    }
    out
}

/// The distance from its starting value, in deviations, at which an estimate is written: the
/// significance discovery asks of an effect (the deviations are first-order and widened only by
/// the windows' overlap, so they understate slowly varying errors).
const MIN_SIGMA: f64 = 5.0;

/// Whether an estimate is worth writing: at least [`MIN_SIGMA`] deviations from its start.
fn kept(start: f64, estimate: f64, sd: f64) -> bool {
    sd.is_finite() && (estimate - start).abs() >= MIN_SIGMA * sd
}

/// What a fit on `runs` writes: the installation, the parameters with their verdicts. By
/// backward elimination: of the free parameters not [`kept`], the one the runs determine least
/// (its deviation against its tolerance: a parameter the motion confounds with others first) is
/// held at its starting value and the others fitted again, until every free one is kept.
fn calibrate_on(
    runs: &[(&SurfaceRun, Vec<Window>)],
    start: &Candidate,
    which: &[usize],
    moving_bed: bool,
) -> (Candidate, Vec<FittedParam>) {
    let mut free: Vec<usize> = which.to_vec();
    let mut held: Vec<(usize, f64, f64)> = Vec::new();
    let (mut fitted, mut std) = fit(runs, start, &free, moving_bed);
    while let Some(worst) = free
        .iter()
        .zip(&std)
        .filter(|(k, sd)| !kept(get(start, **k), get(&fitted, **k), **sd))
        .max_by(|a, b| (a.1 / PARAMS[*a.0].tolerance).total_cmp(&(b.1 / PARAMS[*b.0].tolerance)))
        .map(|(k, sd)| (*k, *sd))
    {
        held.push((worst.0, get(&fitted, worst.0), worst.1));
        free.retain(|k| *k != worst.0);
        if free.is_empty() {
            break;
        }
        (fitted, std) = fit(runs, start, &free, moving_bed);
    }
    let mut written = start.clone();
    let mut params = Vec::new();
    for &k in which {
        let s0 = get(start, k);
        let (est, sd, write) = match free.iter().position(|x| *x == k) {
            Some(c) => (get(&fitted, k), std[c], true),
            None => {
                let u = held.iter().find(|u| u.0 == k);
                (
                    u.map_or(s0, |u| u.1),
                    u.map_or(f64::INFINITY, |u| u.2),
                    false,
                )
            }
        };
        let sigmas = (est - s0).abs() / sd;
        let verdict = if !write && sd <= PARAMS[k].tolerance && sigmas < CONSISTENT_SIGMAS {
            format!(
                "consistent with its starting value ({sigmas:.1}σ, determined to ± {sd:.3} {}): not written",
                PARAMS[k].unit
            )
        } else if !write && sd <= PARAMS[k].tolerance {
            format!(
                "points at a change: {sigmas:.1}σ from its starting value, determined to ± {sd:.3} {}, \
                 short of the five deviations that write it (another run would confirm or refute \
                 it): not written",
                PARAMS[k].unit
            )
        } else if !write {
            let hint = if k == 2 {
                "position windows see a time offset only where the speed changes; `auvnav discover` measures it on the velocities"
            } else {
                "more turns, a longer run, or more runs would settle it"
            };
            format!(
                "not determined: ± {sd:.3} {} where {} {} is asked, {sigmas:.1}σ from its starting value ({hint}): not written",
                PARAMS[k].unit, PARAMS[k].tolerance, PARAMS[k].unit
            )
        } else if sd <= PARAMS[k].tolerance {
            format!("written: determined, {sigmas:.1}σ from its starting value")
        } else {
            format!(
                "written: {sigmas:.1}σ from its starting value, though coarser than the {} {} asked",
                PARAMS[k].tolerance, PARAMS[k].unit
            )
        };
        if write {
            set(&mut written, k, est);
        }
        params.push(FittedParam {
            name: PARAMS[k].name.into(),
            unit: PARAMS[k].unit.into(),
            start: s0,
            estimate: est,
            std: sd,
            verdict,
            written: write,
        });
    }
    (written, params)
}

/// The share of the attitude samples a 45° heading sector needs for the deviation card to be
/// fitted.
const SECTOR_SHARE: f64 = 0.02;

/// How many of the eight 45° heading sectors the runs' compass fills (each with at least
/// [`SECTOR_SHARE`] of the samples), and whether that is all of them.
fn heading_sectors(runs: &[SurfaceRun]) -> (usize, bool) {
    let mut count = [0usize; 8];
    let mut total = 0usize;
    for r in runs {
        for a in &r.attitude {
            let (_, _, y) = a.attitude.euler_angles();
            let sector = (y.to_degrees().rem_euclid(360.0) / 45.0) as usize;
            count[sector.min(7)] += 1;
            total += 1;
        }
    }
    let filled = count
        .iter()
        .filter(|c| **c as f64 >= SECTOR_SHARE * total.max(1) as f64)
        .count();
    (filled, filled == 8)
}

/// Calibrates a DVL installation on surface runs (`auvnav calibrate dvl` when the voyages carry
/// no IMU but a compass and GNSS).
pub fn calibrate_surface(
    specs: &[VoyageSpec],
    start: &Candidate,
    names: &[String],
    threshold_m: f64,
    moving_bed: bool,
) -> Result<SurfaceReport, CalibrationError> {
    let which: Vec<usize> = if names.is_empty() {
        (0..PARAMS.len()).collect()
    } else {
        let mut w = Vec::new();
        for n in names {
            let ks: Vec<usize> = match n.as_str() {
                "dvl.lever_arm" => vec![3, 4],
                "heading.deviation" => vec![5, 6, 7, 8],
                other => match PARAMS.iter().position(|p| p.name == other) {
                    Some(k) => vec![k],
                    None => crate::error::usage!(
                        "--params {other}: surface runs calibrate {} (dvl.lever_arm for both horizontal components, heading.deviation for B, C, D, E)",
                        PARAMS.iter().map(|p| p.name).collect::<Vec<_>>().join(", ")
                    ),
                },
            };
            w.extend(ks);
        }
        w.sort_unstable();
        w.dedup();
        w
    };
    let runs: Vec<SurfaceRun> = specs
        .iter()
        .map(|s| read_surface_run(&s.path, &s.name(), s.window_s))
        .collect::<Result<_, _>>()?;
    let with_windows: Vec<(&SurfaceRun, Vec<Window>)> =
        runs.iter().map(|r| (r, windows(r, threshold_m))).collect();
    for (r, w) in &with_windows {
        if w.is_empty() {
            unusable!(
                "surface run {}: no two fixes {threshold_m} m apart along the track; lower --threshold",
                r.name
            );
        }
    }
    // The deviation card needs the headings it describes: a swing through all of them.
    let (sectors, excited) = heading_sectors(&runs);
    let deviation = |k: &usize| PARAMS[*k].name.starts_with("heading.deviation");
    let unexcited: Vec<usize> = if excited {
        Vec::new()
    } else {
        which.iter().copied().filter(deviation).collect()
    };
    let which: Vec<usize> = which
        .into_iter()
        .filter(|k| !unexcited.contains(k))
        .collect();
    let (installation, mut params) = calibrate_on(&with_windows, start, &which, moving_bed);
    for k in unexcited {
        params.push(FittedParam {
            name: PARAMS[k].name.into(),
            unit: PARAMS[k].unit.into(),
            start: get(start, k),
            estimate: get(start, k),
            std: f64::INFINITY,
            verdict: format!(
                "not excited: the runs' headings fill {sectors} of the 8 sectors of 45° (a swing through all headings, each sector at least {} % of the time, would determine the card): not written",
                100.0 * SECTOR_SHARE
            ),
            written: false,
        });
    }
    let all: Vec<&SurfaceRun> = runs.iter().collect();
    let tp = two_point(&all, start);
    let in_sample = ScoreSet {
        nominal: score(&with_windows, start, moving_bed),
        two_point: score(&with_windows, &tp, moving_bed),
        calibrated: score(&with_windows, &installation, moving_bed),
    };
    let mut held_out = Vec::new();
    if runs.len() >= 2 {
        for k in 0..runs.len() {
            let others: Vec<(&SurfaceRun, Vec<Window>)> = with_windows
                .iter()
                .enumerate()
                .filter(|(j, _)| *j != k)
                .map(|(_, (r, w))| (*r, w.clone()))
                .collect();
            let (inst, p) = calibrate_on(&others, start, &which, moving_bed);
            let other_runs: Vec<&SurfaceRun> = others.iter().map(|(r, _)| *r).collect();
            let tp = two_point(&other_runs, start);
            let this = [(with_windows[k].0, with_windows[k].1.clone())];
            held_out.push(HeldOut {
                run: runs[k].name.clone(),
                scores: ScoreSet {
                    nominal: score(&this, start, moving_bed),
                    two_point: score(&this, &tp, moving_bed),
                    calibrated: score(&this, &inst, moving_bed),
                },
                written: p
                    .iter()
                    .filter(|x| x.written)
                    .map(|x| x.name.clone())
                    .collect(),
            });
        }
    }
    let verdict = verdict(&params, &in_sample, &held_out);
    Ok(SurfaceReport {
        runs: runs.iter().map(|r| r.name.clone()).collect(),
        threshold_m,
        moving_bed,
        params,
        installation,
        in_sample,
        held_out,
        verdict,
        compass: Vec::new(),
        notes: Vec::new(),
    })
}
