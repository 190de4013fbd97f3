//! The forward–backward smoother: a Rauch–Tung–Striebel pass over the navigation filter's
//! epochs, so that a recorded voyage gets the best trajectory its data allow, every state of the
//! filter (navigation, IMU biases, DVL installation, USBL errors) with its smoothed covariance.
//!
//! It runs over the same feed path as everything else (`Session::feed`), twice: the first run
//! records what the backward pass needs at each covariance epoch ([`SmootherLog`], fed by the
//! filter's trace, `crate::ekf::trace`); [`SmootherLog::smooth`] runs the backward pass
//! ([`rts`]); the second run, identical to the first (the core is deterministic), maps each
//! solution through the smoothed error states ([`SmoothedTrack`]) at IMU rate. Nothing of the
//! forward run is kept at IMU rate, so a long voyage costs the epochs' records (spilled to disk
//! beyond a budget) and 0.6 kB per epoch of smoothed errors.
//!
//! Between two epochs the smoothed error is interpolated linearly from the one after the first
//! epoch's corrections to the one before the second's: the solutions in between were
//! propagated from the first and are those of the second just before its updates.

mod cholesky;
pub mod log;
pub mod rts;

pub use log::{LogError, SmootherLog};
pub use rts::{Backward, BackwardRecord, SmoothError, SmoothedEpochs};

use crate::aid::dvl::DvlParameters;
use crate::ekf::{self, N};
use auvnav_shm_schema::NavSolutionV1;
use nalgebra::{Rotation3, UnitQuaternion, Vector3};

/// The nominal values of the states that are not in the solution: the DVL installation and the
/// Gauss–Markov parameter states' means, at the start or the end of a chain.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct NominalParameters {
    pub time_ns: u64,
    pub dvl: DvlParameters,
    pub markov_means: [f64; ekf::PARAMS],
}

/// The smoothed track: the smoothed error states at the epochs, applied to solutions in time
/// order.
#[derive(Debug, Clone)]
pub struct SmoothedTrack {
    pub epochs: SmoothedEpochs,
    /// Epochs whose smoothed variance exceeded the filtered one (should be none).
    pub larger_than_filtered: u64,
    /// The nominal parameters at each chain's start and end.
    pub chains: Vec<(NominalParameters, NominalParameters)>,
    cursor: usize,
    /// Solutions mapped through a smoothed error.
    pub solutions_smoothed: u64,
    /// Solutions outside every chain (before the filter started: alignment), passed unchanged.
    pub solutions_outside: u64,
}

impl SmoothedTrack {
    pub fn new(
        epochs: SmoothedEpochs,
        larger_than_filtered: u64,
        chains: Vec<(NominalParameters, NominalParameters)>,
    ) -> SmoothedTrack {
        SmoothedTrack {
            epochs,
            larger_than_filtered,
            chains,
            cursor: 0,
            solutions_smoothed: 0,
            solutions_outside: 0,
        }
    }

    /// The last chain's smoothed parameters at its first epoch (after that epoch's corrections)
    /// and at its last, with the indices of those epochs; `None` when nothing was smoothed.
    pub fn last_chain_parameters(&self) -> Option<[(usize, SmoothedParameters); 2]> {
        let e = &self.epochs;
        let (start, end) = self.chains.last()?;
        let last_i = e.len().checked_sub(1)?;
        let first_i = (0..=last_i).rev().find(|&i| e.chain_start[i])?;
        let nominal_first = nominal_after_start(start, e, first_i);
        Some([
            (first_i, parameters_at(e, first_i, &nominal_first)),
            (last_i, parameters_at(e, last_i, end)),
        ])
    }

    /// The smoothed error (estimate minus truth) and variances at `t_ns`, or `None` before the
    /// first epoch.
    pub fn error_at(&mut self, t_ns: u64) -> Option<([f64; N], [f64; N])> {
        let e = &self.epochs;
        if e.is_empty() || t_ns < e.time_ns[0] {
            return None;
        }
        if self.cursor >= e.len() || e.time_ns[self.cursor] >= t_ns {
            // Out of order: search (the cursor only moves forward otherwise).
            self.cursor = e.time_ns.partition_point(|&t| t < t_ns).saturating_sub(1);
        }
        while self.cursor + 1 < e.len() && e.time_ns[self.cursor + 1] < t_ns {
            self.cursor += 1;
        }
        let j = self.cursor;
        let mut err = [0.0; N];
        let mut var = [0.0; N];
        if e.time_ns[j] == t_ns {
            // At the first epoch (a solution before its corrections).
            err.copy_from_slice(e.before(j));
            var.copy_from_slice(e.variance(j));
            return Some((err, var));
        }
        if j + 1 < e.len() && e.chain_start[j + 1] && e.time_ns[j + 1] == t_ns {
            // At a restart's first epoch.
            err.copy_from_slice(e.before(j + 1));
            var.copy_from_slice(e.variance(j + 1));
            return Some((err, var));
        }
        if j + 1 >= e.len() || e.chain_start[j + 1] {
            // After the chain's last epoch: propagated from it.
            err.copy_from_slice(e.after(j));
            var.copy_from_slice(e.variance(j));
            return Some((err, var));
        }
        let (t0, t1) = (e.time_ns[j] as f64, e.time_ns[j + 1] as f64);
        let w = if t1 > t0 {
            ((t_ns as f64 - t0) / (t1 - t0)).clamp(0.0, 1.0)
        } else {
            1.0
        };
        let (a, b) = (e.after(j), e.before(j + 1));
        let (va, vb) = (e.variance(j), e.variance(j + 1));
        for i in 0..N {
            err[i] = a[i] + (b[i] - a[i]) * w;
            var[i] = va[i] + (vb[i] - va[i]) * w;
        }
        Some((err, var))
    }

    /// The smoothed solution for the forward solution `sol`: its error removed (position,
    /// velocity, attitude, IMU biases) and the smoothed standard deviations in place of the
    /// filtered ones. Solutions before the filter started are returned unchanged.
    pub fn apply(&mut self, sol: &NavSolutionV1) -> NavSolutionV1 {
        let Some((e, var)) = self.error_at(sol.host_time_ns) else {
            self.solutions_outside += 1;
            return *sol;
        };
        self.solutions_smoothed += 1;
        apply_error(sol, &e, &var)
    }
}

/// `sol` with the error `e` (estimate minus truth, the filter's error state) removed, and the
/// standard deviations of the variances `var`.
pub fn apply_error(sol: &NavSolutionV1, e: &[f64; N], var: &[f64; N]) -> NavSolutionV1 {
    let v3 = |i: usize| Vector3::new(e[i], e[i + 1], e[i + 2]);
    let std3 = |i: usize| [var[i].sqrt(), var[i + 1].sqrt(), var[i + 2].sqrt()];
    let mut s = *sol;
    let pos = crate::earth::offset_position(
        &crate::earth::Geodetic {
            latitude_rad: sol.latitude_rad,
            longitude_rad: sol.longitude_rad,
            height_m: sol.height_m,
        },
        &(-v3(ekf::POS)),
    );
    s.latitude_rad = pos.latitude_rad;
    s.longitude_rad = pos.longitude_rad;
    s.height_m = pos.height_m;
    s.velocity_ned_m_s = (Vector3::from(sol.velocity_ned_m_s) - v3(ekf::VEL)).into();
    let [w, x, y, z] = sol.quaternion_body_to_ned;
    let q = UnitQuaternion::from_quaternion(nalgebra::Quaternion::new(w, x, y, z));
    let q = UnitQuaternion::from_scaled_axis(v3(ekf::ATT)) * q;
    s.quaternion_body_to_ned = [q.w, q.i, q.j, q.k];
    let (r, p, yaw) = q.euler_angles();
    s.euler_rad = [r, p, yaw];
    s.gyro_bias_rad_s = (Vector3::from(sol.gyro_bias_rad_s) + v3(ekf::BG)).into();
    s.accel_bias_m_s2 = (Vector3::from(sol.accel_bias_m_s2) + v3(ekf::BA)).into();
    s.position_std_ned_m = std3(ekf::POS);
    s.velocity_std_ned_m_s = std3(ekf::VEL);
    s.attitude_std_rad = std3(ekf::ATT);
    s
}

/// What the first run of a smoothing recorded: the epochs and each chain's nominal parameters
/// at its start and end.
#[derive(Debug)]
pub struct SmoothingRun {
    pub log: SmootherLog,
    pub chains: Vec<(NominalParameters, NominalParameters)>,
}

impl SmoothingRun {
    /// The backward pass: the smoothed track for the second run.
    pub fn smooth(self) -> Result<SmoothedTrack, LogError> {
        let (epochs, larger) = self.log.smooth()?;
        Ok(SmoothedTrack::new(epochs, larger, self.chains))
    }
}

/// A parameter state's smoothed value and standard deviation.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct SmoothedValue {
    pub value: f64,
    pub std: f64,
}

/// The DVL installation and the USBL errors, smoothed, at a chain's first and last epochs (the
/// installation is constant: both ends carry the same value, the check that the backward pass
/// kept it so).
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct SmoothedParameters {
    pub time_s: f64,
    /// Roll, pitch, yaw of the DVL w.r.t. the body (deg), when estimated.
    pub dvl_mount_deg: Option<[SmoothedValue; 3]>,
    pub dvl_scale_factor: Option<SmoothedValue>,
    pub dvl_lever_arm_m: Option<[SmoothedValue; 3]>,
    pub dvl_time_offset_s: Option<SmoothedValue>,
    /// USBL slant-range and range-difference errors (m), when estimated.
    pub usbl_errors_m: Option<[SmoothedValue; 3]>,
}

/// The smoothed parameters at epoch `i`, from the nominal values there (after the epoch's
/// corrections).
pub fn parameters_at(
    epochs: &SmoothedEpochs,
    i: usize,
    nominal: &NominalParameters,
) -> SmoothedParameters {
    let (e, var) = (epochs.after(i), epochs.variance(i));
    let on = |k: usize, n: usize| (k..k + n).all(|j| var[j] > 0.0);
    let val = |value: f64, k: usize| SmoothedValue {
        value,
        std: var[k].sqrt(),
    };
    let d = &nominal.dvl;
    let mount = on(ekf::DVL_MOUNT, 3).then(|| {
        let dm = Vector3::new(
            e[ekf::DVL_MOUNT],
            e[ekf::DVL_MOUNT + 1],
            e[ekf::DVL_MOUNT + 2],
        );
        let c = d.c_dvl_to_body * Rotation3::from_scaled_axis(-dm).into_inner();
        let (r, p, y) = Rotation3::from_matrix_unchecked(c).euler_angles();
        let deg = |k: usize| var[ekf::DVL_MOUNT + k].sqrt().to_degrees();
        [
            SmoothedValue {
                value: r.to_degrees(),
                std: deg(0),
            },
            SmoothedValue {
                value: p.to_degrees(),
                std: deg(1),
            },
            SmoothedValue {
                value: y.to_degrees(),
                std: deg(2),
            },
        ]
    });
    let lever = on(ekf::DVL_LEVER, 3).then(|| {
        std::array::from_fn(|k| val(d.lever_arm_m[k] - e[ekf::DVL_LEVER + k], ekf::DVL_LEVER + k))
    });
    let usbl = on(ekf::USBL, 3).then(|| {
        std::array::from_fn(|k| {
            val(
                nominal.markov_means[ekf::USBL - ekf::CORE + k] - e[ekf::USBL + k],
                ekf::USBL + k,
            )
        })
    });
    SmoothedParameters {
        time_s: epochs.time_ns[i] as f64 * 1e-9,
        dvl_mount_deg: mount,
        dvl_scale_factor: on(ekf::DVL_SCALE, 1)
            .then(|| val(d.scale - e[ekf::DVL_SCALE], ekf::DVL_SCALE)),
        dvl_lever_arm_m: lever,
        dvl_time_offset_s: on(ekf::DVL_TIME, 1)
            .then(|| val(d.time_offset_s - e[ekf::DVL_TIME], ekf::DVL_TIME)),
        usbl_errors_m: usbl,
    }
}

/// The nominal parameters after the corrections of a chain's first epoch, from those before
/// them (`start`) and the corrections summed there (before minus after smoothed error).
pub fn nominal_after_start(
    start: &NominalParameters,
    epochs: &SmoothedEpochs,
    i: usize,
) -> NominalParameters {
    let (b, a) = (epochs.before(i), epochs.after(i));
    let dx: Vec<f64> = b.iter().zip(a).map(|(b, a)| b - a).collect();
    let mut n = *start;
    let dm = Vector3::new(
        dx[ekf::DVL_MOUNT],
        dx[ekf::DVL_MOUNT + 1],
        dx[ekf::DVL_MOUNT + 2],
    );
    n.dvl.c_dvl_to_body *= Rotation3::from_scaled_axis(-dm).into_inner();
    n.dvl.scale -= dx[ekf::DVL_SCALE];
    for k in 0..3 {
        n.dvl.lever_arm_m[k] -= dx[ekf::DVL_LEVER + k];
    }
    n.dvl.time_offset_s -= dx[ekf::DVL_TIME];
    for k in 0..ekf::PARAMS {
        n.markov_means[k] -= dx[ekf::CORE + k];
    }
    n
}
