//! The S-CAL two-point method: the dead-reckoned displacement from the start fix A to the end
//! point C against the fixes' displacement A → B, per voyage.
//!
//! Conventions settled against simulations with known truth (test `calibrate_dvl.rs`), with
//! D = (north, east) displacements, course χ = atan2(east, north) and our effects' convention
//! (the DVL reads `s` times the true velocity; `dvl.mount_yaw` ψ turns the velocity in the DVL
//! frame by −ψ, so the dead reckoning with ψ unknown runs on course χ_true − ψ):
//!
//! - formula (a), plane geometry: the seed's `1 + k = |D_GPS| / |D_DVL|` is the correction that
//!   multiplies the DVL velocity, so `s = s0 / (1 + k_a) = s0 |D_DVL| / |D_GPS|`; the seed's
//!   `ε = atan(D_L,GPS / D_λ,GPS) − atan(D_L,DVL / D_λ,DVL)` (angles from east) equals
//!   χ_DVL − χ_GPS, so `ψ = ψ0 − ε_a`. We evaluate both angles with atan2, which the printed
//!   `atan` of a ratio gets wrong by 180° on courses between south-west and north-west.
//! - formula (b), landmark-aided: `1 + k = |D_DVL|² / (D_DVL · D_GPS)` is the DVL's own scale
//!   error (opposite sense to (a)): `s = s0 (1 + k_b) cos ε_b`; `ε_b` (cross over dot of the two
//!   displacements) is tan(χ_DVL − χ_GPS), so `ψ = ψ0 − atan(ε_b)`.
//!
//! Per-voyage values are averaged with the voyages' distances as weights. The two formulas agree
//! to second order; (a) sets the parameters, (b) is reported beside it.

use super::objective::VoyageRun;
use super::voyage::Voyage;
use auvnav_core::earth;
use auvnav_replay::accuracy::wrap;
use serde::Serialize;

/// The two formulas on one voyage, in the seed's terms and ours.
#[derive(Debug, Clone, Serialize)]
pub struct TwoPointVoyage {
    pub voyage: String,
    /// Displacements A → B (fixes) and A → C (dead reckoning), north and east (m).
    pub fixes_ne_m: [f64; 2],
    pub dead_reckoning_ne_m: [f64; 2],
    /// The seed's k and ε (rad) by formula (a) and (b).
    pub seed_k_a: f64,
    pub seed_epsilon_a_rad: f64,
    pub seed_k_b: f64,
    pub seed_epsilon_b: f64,
    /// Our mounting yaw (deg) and scale factor by (a) and by (b).
    pub mount_yaw_deg_a: f64,
    pub scale_factor_a: f64,
    pub mount_yaw_deg_b: f64,
    pub scale_factor_b: f64,
}

/// The two-point estimate of each voyage from its start-installation run (`yaw0` deg, `s0`).
pub fn per_voyage(
    voyage: &Voyage,
    run: &VoyageRun,
    yaw0_deg: f64,
    s0: f64,
) -> Option<TwoPointVoyage> {
    let (a, b) = (voyage.fixes.first()?, voyage.fixes.last()?);
    let c = run.positions.last()?;
    let g = earth::ned_offset(&a.position, &b.position);
    let d = earth::ned_offset(&a.position, c);
    let (gn, ge, dn, de) = (g.x, g.y, d.x, d.y);
    let g_len = gn.hypot(ge);
    let d_len = dn.hypot(de);
    if g_len < 1.0 || d_len < 1.0 {
        return None;
    }
    // (a): angles from east as printed, evaluated with atan2.
    let seed_k_a = g_len / d_len - 1.0;
    let seed_epsilon_a_rad = wrap(gn.atan2(ge) - dn.atan2(de));
    // (b)
    let dot = dn * gn + de * ge;
    let cross = -ge * dn + gn * de;
    let seed_k_b = d_len * d_len / dot - 1.0;
    let seed_epsilon_b = cross / dot;
    Some(TwoPointVoyage {
        voyage: voyage.name.clone(),
        fixes_ne_m: [gn, ge],
        dead_reckoning_ne_m: [dn, de],
        seed_k_a,
        seed_epsilon_a_rad,
        seed_k_b,
        seed_epsilon_b,
        mount_yaw_deg_a: yaw0_deg - seed_epsilon_a_rad.to_degrees(),
        scale_factor_a: s0 / (1.0 + seed_k_a),
        mount_yaw_deg_b: yaw0_deg - seed_epsilon_b.atan().to_degrees(),
        scale_factor_b: s0 * (1.0 + seed_k_b) * seed_epsilon_b.atan().cos(),
    })
}

/// Distance-weighted means of (a) over voyages: (mount yaw deg, scale factor).
pub fn combine(per: &[TwoPointVoyage]) -> Option<(f64, f64)> {
    let w: Vec<f64> = per
        .iter()
        .map(|p| p.fixes_ne_m[0].hypot(p.fixes_ne_m[1]))
        .collect();
    let total: f64 = w.iter().sum();
    if total <= 0.0 {
        return None;
    }
    let weighted = |f: fn(&TwoPointVoyage) -> f64| {
        per.iter().zip(&w).map(|(p, w)| f(p) * w).sum::<f64>() / total
    };
    Some((
        weighted(|p| p.mount_yaw_deg_a),
        weighted(|p| p.scale_factor_a),
    ))
}

/// The two-point method on the voyages of `baseline` (the runs with the starting installation):
/// mounting yaw and scale factor set, every other parameter at its prior.
pub fn calibrate(
    problem: &super::Problem,
    params: &super::params::ParameterSet,
    baseline: &super::Evaluation,
) -> anyhow::Result<(super::MethodResult, Vec<TwoPointVoyage>)> {
    let mut x = params.prior_vector();
    let per: Vec<TwoPointVoyage> = problem
        .voyages
        .iter()
        .zip(&baseline.runs)
        .filter_map(|(v, r)| per_voyage(v, r, x[2], x[3]))
        .collect();
    let (yaw, scale) = combine(&per).ok_or_else(|| {
        anyhow::anyhow!(
            "two-point: no voyage has a start and an end fix at least 1 m apart along its track"
        )
    })?;
    let (y, s) = (&params.all[2], &params.all[3]);
    x[2] = yaw.clamp(y.min, y.max);
    x[3] = scale.clamp(s.min, s.max);
    let mut r = super::MethodResult::new(x);
    r.notes.push(
        "two-point estimates the mounting yaw and the scale factor only (formula (a)); the other parameters stay at their prior"
            .into(),
    );
    if x[2] != yaw || x[3] != scale {
        r.notes
            .push("the two-point values were clipped to the parameter bounds".into());
    }
    Ok((r, per))
}
