//! The smoother method: each voyage is replayed once through the navigation session with the
//! selected DVL installation states switched on in the filter and its fixes fed as position
//! aids; the forward–backward smoother (`auvnav_core::smoother`) gives the installation the whole
//! voyage determines, with its standard deviation. The voyages share one installation: their
//! estimates are fused by information (the filter's own prior counted once, the parameter set's
//! prior added), and the voyages are replayed again around the fused value until it settles.
//!
//! The fusion keeps each parameter's smoothed variance only (the cross-correlations between
//! parameters are dropped), so the reported standard deviations are those of each parameter
//! with the others estimated alongside it in the filter.

use super::gauss_newton::DETERMINED_RATIO;
use super::params::{NAMES, ParameterSet, installation};
use super::voyage::{DistanceSource, Voyage};
use super::{MethodResult, Problem};
use anyhow::{Context, bail};
use auvnav_core::config::NavConfig;
use auvnav_core::feed::SensorMessage;
use auvnav_core::session::{Session, SessionConfig, SessionOutput};
use auvnav_core::smoother::{SmoothedParameters, SmoothedValue, SmootherLog};
use auvnav_shm_schema::GnssFixV1;
use auvnav_studies::nees::chi2_quantile;
use auvnav_studies::parallel::map_runs;
use std::sync::atomic::Ordering;

/// Re-linearisations at most (one replay of every voyage each).
const MAX_PASSES: usize = 4;
/// The passes stop when no estimate moved by more than this fraction of its standard deviation.
const SETTLED_FRACTION: f64 = 0.05;
/// Reference fixes (truth channel) are fed at most this often, so that the voyage still
/// dead-reckons between them (s).
const REFERENCE_FIX_SPACING_S: f64 = 10.0;
/// The one-sigma a reference fix is fed with (its recorded one is 0) (m).
const REFERENCE_FIX_STD_M: f64 = 1.0;

/// One voyage's smoothed estimate of the eight parameters: (value, std) for those the filter
/// estimated.
type VoyageEstimate = [Option<SmoothedValue>; 8];

/// The navigation configuration of a smoothing run around the installation `x`: the installation
/// states of the estimated parameters switched on with their prior std. A mounting angle not
/// estimated but switched on with the others gets a hundredth of its prior std; the lever arm
/// takes one std, the largest of its estimated components, for all three. Returns the filter's
/// prior std per parameter (0 when off).
fn filter_config(nav: &NavConfig, params: &ParameterSet, x: &[f64; 8]) -> (NavConfig, [f64; 8]) {
    let mut n = nav.clone();
    n.set_dvl_installation(installation(x));
    let std: [f64; 8] = std::array::from_fn(|i| {
        let p = &params.all[i];
        if p.estimate { p.prior_std } else { 0.0 }
    });
    let on = |idx: std::ops::Range<usize>| idx.clone().any(|i| std[i] > 0.0);
    // Members of a switched-on group that are not estimated: a hundredth of their prior, so
    // that the filter holds them where they are.
    let member = |i: usize| {
        if std[i] > 0.0 {
            std[i]
        } else {
            0.01 * params.all[i].prior_std
        }
    };
    let mut prior = [0.0; 8];
    if on(0..3) {
        n.estimate_dvl_mounting = true;
        n.initial_dvl_mounting_axis_std_deg = Some([member(0), member(1), member(2)]);
        prior[..3].copy_from_slice(&[member(0), member(1), member(2)]);
    }
    if on(4..7) {
        // The filter takes one lever-arm std for the three components.
        let s = (4..7).map(|i| std[i]).fold(0.0f64, f64::max);
        n.estimate_dvl_lever_arm = true;
        n.initial_dvl_lever_arm_std_m = s;
        prior[4..7].copy_from_slice(&[s; 3]);
    }
    n.estimate_dvl_scale = std[3] > 0.0;
    if n.estimate_dvl_scale {
        n.initial_dvl_scale_std = std[3];
        prior[3] = std[3];
    }
    n.estimate_dvl_time_offset = std[7] > 0.0;
    if n.estimate_dvl_time_offset {
        n.initial_dvl_time_offset_std_s = std[7];
        prior[7] = std[7];
    }
    (n, prior)
}

/// The voyage's fixes as position aids: every GNSS fix, or the reference every
/// [`REFERENCE_FIX_SPACING_S`] with [`REFERENCE_FIX_STD_M`].
fn fix_messages(voyage: &Voyage) -> Vec<GnssFixV1> {
    let reference = voyage.fixes.iter().all(|f| f.std_m == 0.0);
    let mut out = Vec::new();
    let mut last_ns: Option<u64> = None;
    for (k, f) in voyage.fixes.iter().enumerate() {
        let is_last = k + 1 == voyage.fixes.len();
        if reference
            && !is_last
            && last_ns.is_some_and(|t| (f.time_ns - t) as f64 * 1e-9 < REFERENCE_FIX_SPACING_S)
        {
            continue;
        }
        last_ns = Some(f.time_ns);
        let std = if reference {
            REFERENCE_FIX_STD_M
        } else {
            f.std_m
        };
        out.push(GnssFixV1 {
            host_time_ns: f.time_ns,
            sequence: out.len() as u64,
            latitude_rad: f.position.latitude_rad,
            longitude_rad: f.position.longitude_rad,
            height_m: f.position.height_m,
            horizontal_std_m: std,
            vertical_std_m: std,
            validity: GnssFixV1::VALID_POSITION | GnssFixV1::VALID_HEIGHT,
            ..Default::default()
        });
    }
    out
}

fn estimate_of(p: &SmoothedParameters) -> VoyageEstimate {
    let mut e: VoyageEstimate = [None; 8];
    if let Some(m) = p.dvl_mount_deg {
        e[0] = Some(m[0]);
        e[1] = Some(m[1]);
        e[2] = Some(m[2]);
    }
    e[3] = p.dvl_scale_factor;
    if let Some(l) = p.dvl_lever_arm_m {
        e[4] = Some(l[0]);
        e[5] = Some(l[1]);
        e[6] = Some(l[2]);
    }
    e[7] = p.dvl_time_offset_s;
    e
}

/// Smooths one voyage with the filter configured by `nav`: the installation at the voyage's
/// start (the smoothed constant states carry the whole voyage's information there).
pub fn smooth_voyage(voyage: &Voyage, nav: &NavConfig) -> anyhow::Result<VoyageEstimate> {
    let cfg = SessionConfig {
        navigation: nav.clone(),
        ..Default::default()
    };
    let mut session = Session::new(&cfg);
    session.record_for_smoothing(SmootherLog::in_memory());
    let mut ignore = |_: SessionOutput| Ok::<(), std::convert::Infallible>(());
    let Ok(()) = session.start(voyage.start, "voyage start", &mut ignore);
    let fixes = fix_messages(voyage);
    let mut next_fix = fixes.iter().peekable();
    for m in &voyage.inputs {
        while let Some(f) = next_fix.next_if(|f| f.host_time_ns <= m.host_time_ns()) {
            let Ok(()) = session.feed(&SensorMessage::Gnss(*f), &mut ignore);
        }
        let Ok(()) = session.feed(m, &mut ignore);
    }
    for f in next_fix {
        let Ok(()) = session.feed(&SensorMessage::Gnss(*f), &mut ignore);
    }
    let Ok(()) = session.finish(&mut ignore);
    let run = session
        .finish_recording()
        .with_context(|| format!("voyage {}: the session recorded nothing", voyage.name))?;
    let track = run
        .smooth()
        .with_context(|| format!("voyage {}: smoothing", voyage.name))?;
    let [(_, first), _] = track.last_chain_parameters().with_context(|| {
        format!(
            "voyage {}: the filter never ran, nothing to smooth",
            voyage.name
        )
    })?;
    Ok(estimate_of(&first))
}

/// The installation the voyages share, fused from their smoothed estimates around `x_lin`.
/// Returns the fused values (the prior for parameters not estimated) and their std.
fn fuse(
    params: &ParameterSet,
    x_lin: &[f64; 8],
    filter_prior: &[f64; 8],
    per_voyage: &[VoyageEstimate],
) -> ([f64; 8], [f64; 8]) {
    let mut x = params.prior_vector();
    let mut std = [f64::NAN; 8];
    for i in params.estimated() {
        let p = &params.all[i];
        let i0 = 1.0 / (p.prior_std * p.prior_std);
        let i_f = 1.0 / (filter_prior[i] * filter_prior[i]);
        // What the voyages' data add, each voyage's posterior less the filter's prior.
        let (mut info, mut info_x) = (0.0, 0.0);
        for e in per_voyage {
            let Some(v) = e[i] else { continue };
            let ik = 1.0 / (v.std * v.std);
            // A constant state's smoothed variance never exceeds its prior; at equality the
            // voyage says nothing about it.
            if ik <= i_f {
                continue;
            }
            info += ik - i_f;
            info_x += ik * v.value - i_f * x_lin[i];
        }
        let total = i0 + info;
        x[i] = ((i0 * p.prior + info_x) / total).clamp(p.min, p.max);
        std[i] = total.sqrt().recip();
    }
    (x, std)
}

/// The voyages' agreement on each determined parameter: their estimates' chi-square about the
/// fused value. Beyond its 99 % quantile the voyages disagree by more than their standard
/// deviations allow (a voyage the filter did not model well); the fused std is then scaled by
/// sqrt(chi-square / dof) (the Birge ratio) and the note says so.
fn disagreement(
    params: &ParameterSet,
    x: &[f64; 8],
    std: &mut [f64; 8],
    per_voyage: &[VoyageEstimate],
    notes: &mut Vec<String>,
) {
    for i in params.estimated() {
        if !determined(params, std, i) {
            continue;
        }
        let values: Vec<SmoothedValue> = per_voyage.iter().filter_map(|e| e[i]).collect();
        if values.len() < 2 {
            continue;
        }
        let dof = (values.len() - 1) as f64;
        let chi2: f64 = values
            .iter()
            .map(|v| ((v.value - x[i]) / v.std).powi(2))
            .sum();
        if chi2 > chi2_quantile(dof, Z_99) {
            let ratio = (chi2 / dof).sqrt();
            std[i] *= ratio;
            notes.push(format!(
                "the voyages disagree on {} (chi-square {chi2:.1} over {dof} degrees of freedom): its std is scaled by {ratio:.2}",
                NAMES[i]
            ));
        }
    }
}

/// The standard normal's 99 % quantile.
const Z_99: f64 = 2.326;

fn determined(params: &ParameterSet, std: &[f64; 8], i: usize) -> bool {
    std[i] < DETERMINED_RATIO * params.all[i].prior_std
}

/// Calibrates by smoothing every voyage, re-linearising until the shared estimate settles.
pub fn calibrate(
    problem: &Problem,
    params: &ParameterSet,
    progress: &mut dyn FnMut(&str, usize, usize),
) -> anyhow::Result<MethodResult> {
    if params.estimated().is_empty() {
        bail!("the smoother method needs at least one parameter to estimate");
    }
    let nv = problem.voyages.len();
    let mut x = params.prior_vector();
    let mut std = [f64::NAN; 8];
    let mut notes = Vec::new();
    let mut last_estimates = Vec::new();
    for pass in 0..MAX_PASSES {
        progress("smoothing the voyages", pass * nv, MAX_PASSES * nv);
        let (nav, filter_prior) = filter_config(&problem.nav, params, &x);
        let estimates = map_runs(nv, problem.threads, |k| -> anyhow::Result<_> {
            smooth_voyage(&problem.voyages[k], &nav)
        })?;
        problem.replays.fetch_add(1, Ordering::Relaxed);
        let (x_new, std_new) = fuse(params, &x, &filter_prior, &estimates);
        // Parameters the voyages do not determine stay at their prior (as in the fast method)
        // and do not hold the passes up.
        let (mut x_new, mut moved) = (x_new, 0.0f64);
        for i in params.estimated() {
            if determined(params, &std_new, i) {
                moved = moved.max((x_new[i] - x[i]).abs() / std_new[i]);
            } else {
                x_new[i] = params.all[i].prior;
            }
        }
        x = x_new;
        std = std_new;
        last_estimates = estimates;
        if moved < SETTLED_FRACTION {
            notes.push(format!(
                "smoother: settled after {} pass(es) over the {nv} voyage(s)",
                pass + 1
            ));
            break;
        }
        if pass + 1 == MAX_PASSES {
            notes.push(format!(
                "smoother: still moving by {moved:.2} sigma after {MAX_PASSES} passes"
            ));
        }
    }
    progress("smoothing the voyages", 1, 1);
    for (v, e) in problem.voyages.iter().zip(&last_estimates) {
        let values: Vec<String> = params
            .estimated()
            .into_iter()
            .filter_map(|i| e[i].map(|s| format!("{} {:.5} ± {:.5}", NAMES[i], s.value, s.std)))
            .collect();
        let reference = if v.distance_source == DistanceSource::Truth {
            ""
        } else {
            " (distances from dead reckoning)"
        };
        notes.push(format!(
            "voyage {}{reference}: {}",
            v.name,
            values.join(", ")
        ));
    }
    disagreement(params, &x, &mut std, &last_estimates, &mut notes);
    let mut r = MethodResult::new(x);
    for i in params.estimated() {
        r.std.push((i, std[i]));
        r.determined.push((i, determined(params, &std, i)));
    }
    r.notes = notes;
    Ok(r)
}
