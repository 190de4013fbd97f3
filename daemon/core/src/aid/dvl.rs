//! DVL velocity aid: `h(x) = s C_b^d (C_n^b v^n + omega_eb^b x l)` minus the time-offset term
//! ([`dvl_model`]), χ² gate, with the DVL installation (mounting, scale factor, lever arm, time
//! offset) as optional parameter states, and the re-opening of the velocity covariance after a
//! run of rejections (`dvl_reset_after_s`).
//!
//! **Water track.** A velocity flagged `TRACK_WATER` is relative to the water: with the
//! water-current states on (`water_current_std_m_s`) it is fused with `v − c` in place of `v`
//! ([`water_track_model`]), which is how the filter learns the current while bottom and water
//! track arrive together and navigates on the water when bottom lock is lost; without them it is
//! counted and never fused (it is not the vehicle's velocity over the ground). Bottom-lock losses
//! and recoveries (a bottom-track reading turning invalid, then valid again) are counted.
//!
//! **Beams.** A reading without an instrument velocity but with beam (radial) velocities — one
//! beam blocked, a beam-coordinate reading the device could not solve — is fused beam by beam
//! when the beam geometry is configured (`dvl_beam_fusion`): beam `i` measures `b_i · h` with
//! `b_i` its unit direction in the DVL frame and `h` the velocity model above; each beam is gated
//! alone (χ², 1 dof), so one bad beam is refused by itself, and the accepted ones are fused
//! together.
//!
//! **Per-beam corrections.** With a beam's scale or angle error configured
//! (`[navigation.dvl]` `beam_scale_factor_ppm`, `beam_angle_error_deg`, as `auvnav discover
//! --dvl-beams` finds them), a reading that carries its four beams gets its velocity solved again
//! from the beams divided by their scales along their true directions, in place of the device's
//! solution, which averages one beam's error into all three axes; beam fusion uses the corrected
//! beams too.
//!
//! Long on purpose: the last 33 lines are the unit tests, beside the code they test; the code is
//! 599 lines.

use super::{AidCounters, AidUpdate, NavCore};
use crate::earth;
use crate::ekf::{self, StateVector, skew};
use crate::strapdown::NavState;
use auvnav_shm_schema::{AidDiagnosticsV1, AidSource, DvlVelocityV1};
use nalgebra::{Matrix3, Rotation3, SMatrix, Vector3};

const DEG: f64 = std::f64::consts::PI / 180.0;

/// Which installation parameters are estimated (parameter states), with their initial
/// one-sigma values; `None` = not estimated.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct DvlEstimation {
    /// Roll, pitch, yaw (deg).
    pub mounting_std_deg: Option<[f64; 3]>,
    pub scale_std: Option<f64>,
    pub lever_arm_std_m: Option<f64>,
    pub time_offset_std_s: Option<f64>,
}

/// The DVL's parameters, installation estimate, state and counters.
#[derive(Debug, Clone)]
pub struct DvlAid {
    /// The installation (estimated when its parameter states are switched on).
    pub params: DvlParameters,
    /// The part of the time offset applied by holding each reading until the filter reaches the
    /// moment it describes (a negative configured offset: the reading is stamped before its
    /// motion; `Session` delays it); only the rest is modelled to first order. 0: none.
    pub retimed_s: f64,
    /// Velocity noise per axis when the device gives none (m/s).
    pub velocity_std_m_s: f64,
    /// χ² gate (3 dof).
    pub gate_chi2: f64,
    /// Re-open the velocity covariance after rejections for this long (s; 0 = never).
    pub reset_after_s: f64,
    /// Time of the last fused velocity (s).
    pub last_fused_s: f64,
    rejected_since_s: Option<f64>,
    pub counters: AidCounters,
    /// Velocity covariance re-opened after a run of rejections.
    pub resets: u64,
    /// The true sound speed (m/s) the velocity is corrected to, and the one assumed by a DVL
    /// that reports none; `None`: no correction.
    pub sound_speed: Option<SoundSpeed>,
    /// Velocities corrected for the sound speed.
    pub sound_speed_corrected: u64,
    /// The water-current states are on: water-track velocities are fused.
    pub water_current: bool,
    /// Water-track velocities fused, rejected by the gate, invalid.
    pub water_track: AidCounters,
    /// Water-track velocities received without the water-current states (not fused).
    pub water_track_unused: u64,
    /// Bottom lock lost (a valid bottom-track reading followed by an invalid one) and regained.
    pub bottom_lock_lost: u64,
    pub bottom_lock_regained: u64,
    bottom_locked: Option<bool>,
    /// Beam fusion (`dvl_beam_fusion`): the beams' unit directions in the DVL frame and a beam
    /// velocity's one-sigma (m/s).
    pub beams: Option<([Vector3<f64>; 4], f64)>,
    /// Readings fused from their beams, and beams refused by their own gate.
    pub beam_readings_fused: u64,
    pub beams_rejected: u64,
    /// Per-beam corrections (`[navigation.dvl]` `beam_scale_factor_ppm`, `beam_angle_error_deg`).
    pub beam_correction: Option<BeamCorrection>,
    /// Readings whose velocity was solved again from their corrected beams.
    pub beam_corrected: u64,
}

/// Each beam's scale (`1 + s`) and true direction, and the least-squares solution of a velocity
/// from four beams along those directions.
#[derive(Debug, Clone)]
pub struct BeamCorrection {
    pub scale: [f64; 4],
    pub directions: [Vector3<f64>; 4],
    solve: nalgebra::Matrix3x4<f64>,
}

impl BeamCorrection {
    /// From the configured geometry (Janus angle and azimuths, deg) and each beam's scale error
    /// (ppm) and angle error (deg); `None` when the four directions do not determine a velocity.
    pub fn new(
        angle_deg: f64,
        azimuths_deg: [f64; 4],
        scale_ppm: [f64; 4],
        angle_error_deg: [f64; 4],
    ) -> Option<BeamCorrection> {
        let directions: [Vector3<f64>; 4] = std::array::from_fn(|i| {
            let (s, c) = ((angle_deg + angle_error_deg[i]) * DEG).sin_cos();
            let (sa, ca) = (azimuths_deg[i] * DEG).sin_cos();
            Vector3::new(s * ca, s * sa, c)
        });
        let b = nalgebra::Matrix4x3::from_rows(&directions.map(|v| v.transpose()));
        let solve = (b.transpose() * b).try_inverse()? * b.transpose();
        Some(BeamCorrection {
            scale: scale_ppm.map(|s| 1.0 + s * 1e-6),
            directions,
            solve,
        })
    }

    /// The reading with its velocity solved again from its four corrected beams; `None` when it
    /// does not carry all four.
    pub fn apply(&self, m: &DvlVelocityV1) -> Option<DvlVelocityV1> {
        let mut z = nalgebra::Vector4::zeros();
        for i in 0..4 {
            let v = m.beam_velocity_m_s[i];
            if m.validity & (DvlVelocityV1::VALID_BEAM_VELOCITY << i) == 0 || !v.is_finite() {
                return None;
            }
            z[i] = v / self.scale[i];
        }
        let mut out = *m;
        out.velocity_dvl_m_s = (self.solve * z).into();
        Some(out)
    }
}

/// The unit direction of each beam in the DVL frame: `angle_deg` from z, azimuths from x about z.
pub fn beam_directions(angle_deg: f64, azimuths_deg: [f64; 4]) -> [Vector3<f64>; 4] {
    let (s, c) = (angle_deg * DEG).sin_cos();
    azimuths_deg.map(|az| Vector3::new(s * (az * DEG).cos(), s * (az * DEG).sin(), c))
}

/// χ² at 99.9 % for 1 to 4 degrees of freedom.
const CHI2_999: [f64; 4] = [10.83, 13.82, 16.27, 18.47];

/// The sound-speed correction of the DVL velocity: true / assumed.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SoundSpeed {
    pub true_m_s: f64,
    /// What a DVL that reports no sound speed assumed (m/s).
    pub assumed_default_m_s: f64,
}

impl SoundSpeed {
    /// True over assumed for a reading: the DVL's reported sound speed when valid, else the
    /// default.
    pub fn ratio(&self, m: &DvlVelocityV1) -> f64 {
        let reported = m.sound_speed_m_s;
        let assumed = if m.validity & DvlVelocityV1::VALID_SOUND_SPEED != 0
            && (1375.0..=1650.0).contains(&reported)
        {
            reported
        } else {
            self.assumed_default_m_s
        };
        self.true_m_s / assumed
    }
}

impl DvlAid {
    /// The installation as the measurement model takes it: the time offset less the part the
    /// readings' retiming already applies.
    pub fn model_params(&self) -> DvlParameters {
        DvlParameters {
            time_offset_s: self.params.time_offset_s - self.retimed_s,
            ..self.params
        }
    }

    /// The aid with the installation `params`, velocity noise `velocity_std_m_s` (m/s) when the
    /// device gives none, χ² gate `gate_chi2` (3 dof), covariance re-opening after
    /// `reset_after_s` (s, 0 = never), and `start_s` as the time of the last fused velocity.
    pub fn new(
        params: DvlParameters,
        velocity_std_m_s: f64,
        gate_chi2: f64,
        reset_after_s: f64,
        start_s: f64,
    ) -> DvlAid {
        DvlAid {
            params,
            retimed_s: 0.0,
            velocity_std_m_s,
            gate_chi2,
            reset_after_s,
            last_fused_s: start_s,
            rejected_since_s: None,
            counters: AidCounters::default(),
            resets: 0,
            sound_speed: None,
            sound_speed_corrected: 0,
            water_current: false,
            water_track: AidCounters::default(),
            water_track_unused: 0,
            bottom_lock_lost: 0,
            bottom_lock_regained: 0,
            bottom_locked: None,
            beams: None,
            beam_readings_fused: 0,
            beams_rejected: 0,
            beam_correction: None,
            beam_corrected: 0,
        }
    }

    /// The beams of a reading that carries no instrument velocity, fused (see the module's
    /// documentation); `None` when beam fusion is off or the reading has no valid beam.
    fn fuse_beams(&mut self, core: &mut NavCore, m: &DvlVelocityV1) -> Option<AidUpdate> {
        let (mut dirs, std) = self.beams?;
        let ratio = self.sound_speed.map_or(1.0, |c| c.ratio(m));
        let mut scale = [1.0; 4];
        if let Some(c) = &self.beam_correction {
            dirs = c.directions;
            scale = c.scale;
        }
        let beams: Vec<(usize, f64)> = (0..4)
            .filter(|i| m.validity & (DvlVelocityV1::VALID_BEAM_VELOCITY << i) != 0)
            .map(|i| (i, m.beam_velocity_m_s[i] * ratio / scale[i]))
            .filter(|(_, v)| v.is_finite() && v.abs() < 20.0)
            .collect();
        if beams.is_empty() {
            return None;
        }
        let mut d = core.diagnostics(m.validity_time_ns, AidSource::DvlVelocity);
        d.flags |= AidDiagnosticsV1::FLAG_BEAMS;
        if core.aid_is_late(m.validity_time_ns) {
            return Some(AidUpdate::rejected(d));
        }
        if ratio != 1.0 {
            self.sound_speed_corrected += 1;
            d.flags |= AidDiagnosticsV1::FLAG_SOUND_SPEED_CORRECTED;
        }
        core.propagate_covariance();
        let (predicted, h) = dvl_model(
            core.state(),
            &core.last_omega_ib,
            &core.last_f_body,
            &self.model_params(),
        );
        // Each beam against its own gate.
        let mut accepted: Vec<(f64, f64, SMatrix<f64, 1, { ekf::N }>)> = Vec::new();
        for (i, z) in beams {
            let hi = dirs[i].transpose() * h;
            let y = dirs[i].dot(&predicted) - z;
            let s = (hi * core.kf.p * hi.transpose())[(0, 0)] + std * std;
            if s > 0.0 && y * y / s <= CHI2_999[0] {
                accepted.push((z, y, hi));
            } else {
                self.beams_rejected += 1;
            }
        }
        for (k, (z, _, _)) in accepted.iter().take(3).enumerate() {
            d.observation[k] = *z;
            d.observation_variance[k] = std * std;
        }
        d.dimension = accepted.len() as u32;
        let kept = d.flags;
        let correction = match accepted.len() {
            1 => self.joint::<1>(core, &accepted, std, &mut d),
            2 => self.joint::<2>(core, &accepted, std, &mut d),
            3 => self.joint::<3>(core, &accepted, std, &mut d),
            4 => self.joint::<4>(core, &accepted, std, &mut d),
            _ => {
                d.flags |= AidDiagnosticsV1::FLAG_REJECTED;
                None
            }
        };
        d.flags |= kept & !AidDiagnosticsV1::FLAG_REJECTED;
        if correction.is_some() {
            self.beam_readings_fused += 1;
            self.last_fused_s = m.validity_time_ns as f64 * 1e-9;
        }
        Some(AidUpdate::counted(d, correction, &mut self.counters))
    }

    /// One update with the `M` accepted beams (innovation and Jacobian row each).
    fn joint<const M: usize>(
        &self,
        core: &mut NavCore,
        beams: &[(f64, f64, SMatrix<f64, 1, { ekf::N }>)],
        std: f64,
        d: &mut AidDiagnosticsV1,
    ) -> Option<StateVector> {
        let mut y = nalgebra::SVector::<f64, M>::zeros();
        let mut h = SMatrix::<f64, M, { ekf::N }>::zeros();
        for (k, (_, yk, hk)) in beams.iter().enumerate().take(M) {
            y[k] = *yk;
            h.set_row(k, hk);
        }
        let r = SMatrix::<f64, M, M>::from_diagonal_element(std * std);
        let result = core.kf.update(&y, &h, &r, CHI2_999[M - 1]);
        NavCore::report(result, d)
    }

    /// Switches the installation states on in `p0` with their initial one-sigma values
    /// (`None`: the state stays off): mounting (deg), scale factor (1), lever arm (m), time
    /// offset (s).
    pub fn initial_variances(p0: &mut StateVector, estimate: &DvlEstimation) {
        for i in 0..3 {
            if let Some(s) = estimate.mounting_std_deg {
                p0[ekf::DVL_MOUNT + i] = (s[i] * DEG).powi(2);
            }
            if let Some(s) = estimate.lever_arm_std_m {
                p0[ekf::DVL_LEVER + i] = s.powi(2);
            }
        }
        if let Some(s) = estimate.scale_std {
            p0[ekf::DVL_SCALE] = s.powi(2);
        }
        if let Some(s) = estimate.time_offset_std_s {
            p0[ekf::DVL_TIME] = s.powi(2);
        }
    }

    /// Applies a correction to the installation states.
    pub fn correct(&mut self, dx: &StateVector) {
        let dm = Vector3::new(
            dx[ekf::DVL_MOUNT],
            dx[ekf::DVL_MOUNT + 1],
            dx[ekf::DVL_MOUNT + 2],
        );
        self.params.c_dvl_to_body *= Rotation3::from_scaled_axis(-dm).into_inner();
        self.params.scale -= dx[ekf::DVL_SCALE];
        self.params.lever_arm_m -= Vector3::new(
            dx[ekf::DVL_LEVER],
            dx[ekf::DVL_LEVER + 1],
            dx[ekf::DVL_LEVER + 2],
        );
        self.params.time_offset_s -= dx[ekf::DVL_TIME];
    }

    /// Should we fuse: a valid, finite velocity below 20 m/s, not older than the state.
    fn usable(&mut self, core: &mut NavCore, m: &DvlVelocityV1) -> bool {
        let z = Vector3::from(m.velocity_dvl_m_s);
        if m.validity & DvlVelocityV1::VALID_VELOCITY == 0
            || !z.iter().all(|x| x.is_finite())
            || z.norm() > 20.0
        {
            self.counters.invalid += 1;
            return false;
        }
        !core.aid_is_late(m.validity_time_ns)
    }

    /// The measured velocity corrected for the sound speed and its noise covariance (the
    /// device's deviations, corrected too, or the configured one), written into `d`.
    fn measurement(
        &mut self,
        m: &DvlVelocityV1,
        d: &mut AidDiagnosticsV1,
    ) -> (Vector3<f64>, Matrix3<f64>) {
        let ratio = self.sound_speed.map_or(1.0, |c| c.ratio(m));
        let z = Vector3::from(m.velocity_dvl_m_s) * ratio;
        if ratio != 1.0 {
            self.sound_speed_corrected += 1;
            d.flags |= AidDiagnosticsV1::FLAG_SOUND_SPEED_CORRECTED;
        }
        let sigma = if m.validity & DvlVelocityV1::VALID_STD != 0 {
            Vector3::from(m.velocity_std_m_s).map(|x| (x * ratio).max(1e-3))
        } else {
            Vector3::repeat(self.velocity_std_m_s)
        };
        let r = Matrix3::from_diagonal(&sigma.map(|x| x * x));
        d.observation = z.into();
        d.observation_variance = r.diagonal().into();
        (z, r)
    }

    /// Fuses a water-track velocity (relative to the water, DVL frame) with the current states.
    fn fuse_water_track(&mut self, core: &mut NavCore, m: &DvlVelocityV1) -> AidUpdate {
        let mut d = core.diagnostics(m.validity_time_ns, AidSource::DvlVelocity);
        d.dimension = 3;
        d.flags |= AidDiagnosticsV1::FLAG_WATER_TRACK;
        if !self.water_current {
            self.water_track_unused += 1;
            return AidUpdate::rejected(d);
        }
        let before = self.counters.invalid;
        if !self.usable(core, m) {
            // Counted as the water track's, not the bottom track's.
            self.counters.invalid = before;
            self.water_track.invalid += 1;
            return AidUpdate::rejected(d);
        }
        let (z, r) = self.measurement(m, &mut d);
        core.propagate_covariance();
        let k = ekf::CURRENT - ekf::CORE;
        let current = [core.markov_means[k], core.markov_means[k + 1]];
        let (predicted, h) = water_track_model(
            core.state(),
            &core.last_omega_ib,
            &core.last_f_body,
            &self.model_params(),
            current,
        );
        let result = core.kf.update(&(predicted - z), &h, &r, self.gate_chi2);
        let kept = d.flags;
        let correction = NavCore::report(result, &mut d);
        d.flags |= kept & !AidDiagnosticsV1::FLAG_REJECTED;
        AidUpdate::counted(d, correction, &mut self.water_track)
    }

    /// Fuses a DVL velocity (in the DVL frame, at its time of validity): bottom track, or water
    /// track (see the module's documentation).
    pub fn fuse(&mut self, core: &mut NavCore, m: &DvlVelocityV1) -> AidUpdate {
        if m.is_water_track() {
            return self.fuse_water_track(core, m);
        }
        let any_beam = (0..4).any(|i| m.validity & (DvlVelocityV1::VALID_BEAM_VELOCITY << i) != 0);
        let locked = m.validity & DvlVelocityV1::VALID_VELOCITY != 0 || any_beam;
        match (self.bottom_locked, locked) {
            (Some(true), false) => self.bottom_lock_lost += 1,
            (Some(false), true) => self.bottom_lock_regained += 1,
            _ => {}
        }
        self.bottom_locked = Some(locked);
        // Per-beam corrections: the velocity solved again from the four corrected beams.
        let corrected = self
            .beam_correction
            .as_ref()
            .filter(|_| m.validity & DvlVelocityV1::VALID_VELOCITY != 0)
            .and_then(|c| c.apply(m));
        if corrected.is_some() {
            self.beam_corrected += 1;
        }
        let m = corrected.as_ref().unwrap_or(m);
        if m.validity & DvlVelocityV1::VALID_VELOCITY == 0
            && let Some(u) = self.fuse_beams(core, m)
        {
            return u;
        }
        let t_ns = m.validity_time_ns;
        let mut d = core.diagnostics(t_ns, AidSource::DvlVelocity);
        d.dimension = 3;
        if !self.usable(core, m) {
            return AidUpdate::rejected(d);
        }
        let (z, r) = self.measurement(m, &mut d);
        core.propagate_covariance();
        let (predicted, h) = dvl_model(
            core.state(),
            &core.last_omega_ib,
            &core.last_f_body,
            &self.model_params(),
        );
        let y = predicted - z;
        let t = t_ns as f64 * 1e-9;
        let mut result = core.kf.update(&y, &h, &r, self.gate_chi2);
        let rejected = matches!(result, Ok((_, ref rep)) if !rep.fused);
        let since = *self.rejected_since_s.get_or_insert(t);
        if rejected && self.reset_after_s > 0.0 && t - since >= self.reset_after_s {
            let innovation_ned = core.state().c_body_to_ned() * y;
            core.reopen(ekf::VEL, innovation_ned.map(|x| x * x).into());
            self.resets += 1;
            d.flags |= AidDiagnosticsV1::FLAG_RESET;
            let (predicted, h) = dvl_model(
                core.state(),
                &core.last_omega_ib,
                &core.last_f_body,
                &self.model_params(),
            );
            result = core.kf.update(&(predicted - z), &h, &r, f64::INFINITY);
        }
        let kept =
            d.flags & (AidDiagnosticsV1::FLAG_RESET | AidDiagnosticsV1::FLAG_SOUND_SPEED_CORRECTED);
        let correction = NavCore::report(result, &mut d);
        if correction.is_some() {
            self.counters.fused += 1;
            self.last_fused_s = t;
            self.rejected_since_s = None;
        } else {
            self.counters.rejected += 1;
        }
        d.flags |= kept;
        AidUpdate {
            diagnostics: d,
            correction,
        }
    }
}

impl DvlParameters {
    /// The installation from mounting roll, pitch, yaw of the DVL frame w.r.t. the body (deg),
    /// scale factor, lever arm (body, m) and time offset (s).
    pub fn new(mount_deg: [f64; 3], scale: f64, lever_arm_m: [f64; 3], time_offset_s: f64) -> Self {
        let [r, p, y] = mount_deg;
        DvlParameters {
            c_dvl_to_body: Rotation3::from_euler_angles(r * DEG, p * DEG, y * DEG).into_inner(),
            scale,
            lever_arm_m: Vector3::from(lever_arm_m),
            time_offset_s,
        }
    }

    /// The mounting roll, pitch, yaw of the DVL frame w.r.t. the body (deg): the inverse of
    /// [`DvlParameters::new`]'s.
    pub fn mount_deg(&self) -> [f64; 3] {
        let (r, p, y) = Rotation3::from_matrix_unchecked(self.c_dvl_to_body).euler_angles();
        [r / DEG, p / DEG, y / DEG]
    }
}

/// The DVL installation: mounting, scale factor, lever arm and time offset.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DvlParameters {
    /// Rotation DVL frame -> body frame.
    pub c_dvl_to_body: Matrix3<f64>,
    /// Scale factor (1 = none).
    pub scale: f64,
    /// DVL position in the body frame (m).
    pub lever_arm_m: Vector3<f64>,
    /// The velocity stamped at t is the vehicle's at t - offset (s).
    pub time_offset_s: f64,
}

/// The water-track model: [`dvl_model`] with the velocity relative to the water, `v − c` (the
/// current `c` north and east, m/s), and `dh/d dc = −dh/d dv` for the current's states. (The
/// time-offset term needs the water-relative velocity's rate in the body frame, which for a
/// current constant in NED is what [`dvl_model`] computes from `v − c`.)
pub fn water_track_model(
    s: &NavState,
    omega_ib_body: &Vector3<f64>,
    f_body: &Vector3<f64>,
    p: &DvlParameters,
    current_ne: [f64; 2],
) -> (Vector3<f64>, SMatrix<f64, 3, { ekf::N }>) {
    let mut relative = *s;
    relative.velocity_ned -= Vector3::new(current_ne[0], current_ne[1], 0.0);
    let (predicted, mut h) = dvl_model(&relative, omega_ib_body, f_body, p);
    for i in 0..3 {
        for k in 0..2 {
            h[(i, ekf::CURRENT + k)] = -h[(i, ekf::VEL + k)];
        }
    }
    (predicted, h)
}

/// The DVL measurement model: predicted velocity in the DVL frame,
/// `h = s C_b^d (v_b + omega_eb^b x l) - tau s C_b^d a_b` with `v_b = C_n^b v^n` and
/// `a_b = d v_b / dt = f_b + C_n^b g^n - omega_eb^b x v_b` (so the measurement stamped at t is the
/// velocity at t - tau to first order), and its Jacobian w.r.t. the error state:
/// `dh/d dv = s C_b^d (I + tau [omega_eb x]) C_n^b`,
/// `dh/d phi = -(dh/d dv) [v x] + tau s C_b^d C_n^b [g x]`, `dh/d dm = [h x]` (mounting),
/// `dh/d ds = h / s`, `dh/d dl = s C_b^d [omega_eb x]`, `dh/d dtau = -s C_b^d a_b`. Neglected: the
/// Earth-rate part of `omega_eb` through the attitude (below 1e-4 of the lever-arm term) and the
/// dependence on the bias errors (second order).
/// `omega_ib_body` and `f_body` are the bias-corrected IMU outputs.
pub fn dvl_model(
    s: &NavState,
    omega_ib_body: &Vector3<f64>,
    f_body: &Vector3<f64>,
    p: &DvlParameters,
) -> (Vector3<f64>, SMatrix<f64, 3, { ekf::N }>) {
    let c_nb = s.c_body_to_ned().transpose();
    let c_bd = p.c_dvl_to_body.transpose();
    let lat = s.position.latitude_rad;
    let w_ie_b = c_nb * earth::earth_rate_ned(lat);
    let w_eb = omega_ib_body - w_ie_b;
    let v_b = c_nb * s.velocity_ned;
    let a_b = f_body + c_nb * earth::gravity_ned(lat, s.position.height_m) - w_eb.cross(&v_b);
    let unscaled = c_bd * (v_b + w_eb.cross(&p.lever_arm_m) - p.time_offset_s * a_b);
    let predicted = p.scale * unscaled;
    let mut h = SMatrix::<f64, 3, { ekf::N }>::zeros();
    // v_b and a_b through the velocity and the attitude: C_n^b(est) = C_n^b (I + [phi x]).
    let through_v = p.scale * c_bd * (Matrix3::identity() + p.time_offset_s * skew(&w_eb)) * c_nb;
    h.fixed_view_mut::<3, 3>(0, ekf::VEL).copy_from(&through_v);
    let g_n = earth::gravity_ned(lat, s.position.height_m);
    h.fixed_view_mut::<3, 3>(0, ekf::ATT).copy_from(
        &(-through_v * skew(&s.velocity_ned)
            + p.scale * p.time_offset_s * c_bd * c_nb * skew(&g_n)),
    );
    h.fixed_view_mut::<3, 3>(0, ekf::DVL_MOUNT)
        .copy_from(&skew(&predicted));
    h.fixed_view_mut::<3, 1>(0, ekf::DVL_SCALE)
        .copy_from(&unscaled);
    h.fixed_view_mut::<3, 3>(0, ekf::DVL_LEVER)
        .copy_from(&(p.scale * c_bd * skew(&w_eb)));
    h.fixed_view_mut::<3, 1>(0, ekf::DVL_TIME)
        .copy_from(&(-p.scale * c_bd * a_b));
    (predicted, h)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Beams read with a scale and an angle error give back the true velocity once corrected,
    /// and the reading's other fields stay.
    #[test]
    fn corrected_beams_give_back_the_velocity() {
        let azimuths = [45.0, 135.0, 225.0, 315.0];
        let (scale, angle) = ([0.0, 20_000.0, -5_000.0, 0.0], [0.0, 0.0, 0.7, -0.3]);
        let c = BeamCorrection::new(30.0, azimuths, scale, angle).expect("geometry");
        let v = Vector3::new(1.7, -0.2, 0.05);
        let mut m = DvlVelocityV1 {
            velocity_dvl_m_s: [9.0; 3],
            altitude_m: 12.0,
            validity: DvlVelocityV1::VALID_VELOCITY | DvlVelocityV1::VALID_ALTITUDE,
            ..Default::default()
        };
        for i in 0..4 {
            m.beam_velocity_m_s[i] = c.directions[i].dot(&v) * c.scale[i];
            m.validity |= DvlVelocityV1::VALID_BEAM_VELOCITY << i;
        }
        let out = c.apply(&m).expect("four beams");
        for k in 0..3 {
            assert!((out.velocity_dvl_m_s[k] - v[k]).abs() < 1e-12);
        }
        assert_eq!(out.altitude_m, 12.0);
        // Without all four beams there is nothing to solve again.
        m.validity &= !(DvlVelocityV1::VALID_BEAM_VELOCITY << 2);
        assert!(c.apply(&m).is_none());
    }
}
