//! The inertial core of the navigator: strapdown mechanisation, the error filter and its
//! covariance propagation, the IMU bias estimates, the correction of the core states, and what the
//! aid sources need from the last IMU sample. The aid sources (`crate::aid`) work on it; the
//! navigator (`crate::navigator`) owns it together with the aids and applies their corrections.

use crate::earth;
use crate::ekf::{self, DynamicsInputs, ErrorFilter, ProcessNoise, StateVector};
use crate::strapdown::{ImuIncrement, NavState, Strapdown};
use auvnav_shm_schema::{AidDiagnosticsV1, AidSource, ImuSampleV1};
use nalgebra::{UnitQuaternion, Vector3};

/// How IMU samples are checked and integrated (see `NavConfig`): covariance propagation interval
/// (s), the gap threshold (nominal intervals), whether the device's time stamps give the interval
/// and how far they may run ahead of the host's (s), the plausible range of a sample (rad/s,
/// m/s²), and the unknown motion assumed over a gap (m/s², rad/s).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ImuTiming {
    pub covariance_interval_s: f64,
    pub imu_max_gap_intervals: f64,
    pub imu_dt_from_device_time: bool,
    pub clock_tolerance_s: f64,
    pub max_rate_rad_s: f64,
    pub max_specific_force_m_s2: f64,
    pub gap_accel_std_m_s2: f64,
    pub gap_rate_std_rad_s: f64,
}

/// The inertial core of the navigator: the strapdown solution, the error filter, the IMU bias
/// estimates and what the aids' models need from the last IMU sample. Aid sources work on it
/// (`crate::aid`); the navigator applies their corrections.
#[derive(Debug, Clone)]
pub struct NavCore {
    noise: ProcessNoise,
    pub(crate) sd: Strapdown,
    /// The error filter (its covariance is what the aids update).
    pub kf: ErrorFilter,
    pub(crate) gyro_bias: Vector3<f64>,
    pub(crate) accel_bias: Vector3<f64>,
    /// Estimates of the parameter states that have a process (Gauss–Markov, e.g. the USBL
    /// errors): their mean decays between updates; constant parameter states keep theirs in the
    /// aid that owns them.
    pub markov_means: nalgebra::SVector<f64, { ekf::PARAMS }>,
    pub(crate) last_imu_ns: Option<u64>,
    pub(crate) last_imu_device_ns: Option<u64>,
    /// The last bias-corrected angular rate (rad/s, body).
    pub last_omega_ib: Vector3<f64>,
    /// The last bias-corrected specific force (m/s², body).
    pub last_f_body: Vector3<f64>,
    pub(crate) pending_dt: f64,
    pending_f_ned: Vector3<f64>,
    diagnostics_sequence: u64,
    pub(crate) covariance_interval_s: f64,
    timing: ImuTiming,
    /// IMU and lateness counters (the aids count the rest).
    pub counters: CoreCounters,
    /// Epochs and corrections for a smoother (`None`: not asked for).
    pub(crate) trace: Option<ekf::trace::Trace>,
}

/// What the inertial core counted.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct CoreCounters {
    pub imu_samples: u64,
    pub imu_out_of_order: u64,
    pub imu_invalid: u64,
    pub imu_gaps: u64,
    /// Samples whose device-time step disagreed with the host's (a jump ahead or a stall): the
    /// host's step was integrated instead.
    pub imu_clock_jumps: u64,
    pub aid_late: u64,
}

/// Angular rate and specific force of a sample (increments divided by the interval), or `None`
/// when it is flagged invalid, its interval is not in (0, 1) s, or a value is not finite or
/// beyond `max_rate_rad_s` / `max_specific_force_m_s2` (per axis).
pub fn plausible_rates(
    m: &ImuSampleV1,
    max_rate_rad_s: f64,
    max_specific_force_m_s2: f64,
) -> Option<(Vector3<f64>, Vector3<f64>)> {
    let valid = ImuSampleV1::STATUS_GYRO_VALID | ImuSampleV1::STATUS_ACCEL_VALID;
    if m.status & valid != valid || !(m.interval_s > 0.0 && m.interval_s < 1.0) {
        return None;
    }
    let (w, f) = (Vector3::from(m.angular), Vector3::from(m.specific));
    let (w, f) = if m.status & ImuSampleV1::STATUS_INCREMENTS != 0 {
        (w / m.interval_s, f / m.interval_s)
    } else {
        (w, f)
    };
    // `!(x <= max)` also refuses NaN.
    let within = |v: &Vector3<f64>, max: f64| v.iter().all(|x| x.abs() <= max);
    (within(&w, max_rate_rad_s) && within(&f, max_specific_force_m_s2)).then_some((w, f))
}

/// True when every element of `p` is finite, its variances are non-negative and every
/// correlation is within ±1 (up to a relative rounding margin).
pub fn covariance_is_sound(p: &ekf::Covariance) -> bool {
    let d: [f64; ekf::N] = std::array::from_fn(|i| p[(i, i)]);
    if !d.iter().all(|v| v.is_finite() && *v >= 0.0) {
        return false;
    }
    // Without a branch per element, over the columns' contiguous slices below the diagonal: an
    // infinite correlation is beyond the bound, a NaN is refused on its own.
    let mut unsound = 0u32;
    for (j, col) in p.data.0.iter().enumerate() {
        let djj = d[j] * (1.0 + 1e-6);
        for (pij, dii) in col[j + 1..].iter().zip(&d[j + 1..]) {
            unsound |= u32::from((pij * pij > dii * djj + 1e-300) | pij.is_nan());
        }
    }
    unsound == 0
}

impl NavCore {
    /// The core at `initial` with initial variances `p0`, the IMU's process noise and its
    /// timing.
    pub fn new(
        initial: NavState,
        p0: &StateVector,
        noise: ProcessNoise,
        timing: ImuTiming,
    ) -> NavCore {
        NavCore {
            noise,
            sd: Strapdown::new(initial),
            kf: ErrorFilter::new(p0),
            gyro_bias: Vector3::zeros(),
            accel_bias: Vector3::zeros(),
            markov_means: nalgebra::SVector::zeros(),
            last_imu_ns: None,
            last_imu_device_ns: None,
            last_omega_ib: Vector3::zeros(),
            last_f_body: Vector3::zeros(),
            pending_dt: 0.0,
            pending_f_ned: Vector3::zeros(),
            diagnostics_sequence: 0,
            covariance_interval_s: timing.covariance_interval_s,
            timing,
            counters: CoreCounters::default(),
            trace: None,
        }
    }

    /// The navigation state.
    pub fn state(&self) -> &NavState {
        &self.sd.state
    }

    /// The sample's angular rate and specific force (rad/s, m/s², body), increments divided by
    /// the interval; `None` when it is flagged invalid, its interval is not in (0, 1) s, or a value
    /// is not finite or beyond the configured plausible range (a device cannot measure it).
    pub fn plausible_rates(&self, m: &ImuSampleV1) -> Option<(Vector3<f64>, Vector3<f64>)> {
        plausible_rates(
            m,
            self.timing.max_rate_rad_s,
            self.timing.max_specific_force_m_s2,
        )
    }

    /// Integrates one IMU sample; false when it was skipped (invalid, implausible, out of order;
    /// counted).
    pub(crate) fn integrate(&mut self, m: &ImuSampleV1) -> bool {
        let t_ns = m.host_time_ns;
        let Some((w, f)) = self.plausible_rates(m) else {
            self.counters.imu_invalid += 1;
            return false;
        };
        let state_ns = (self.sd.state.time_s * 1e9).round() as u64;
        let last = self.last_imu_ns.unwrap_or(state_ns);
        let device_ns =
            (m.status & ImuSampleV1::STATUS_DEVICE_TIME_VALID != 0).then_some(m.device_time_ns);
        let host_dt = t_ns.saturating_sub(last) as f64 * 1e-9;
        // With device time, samples completed by one read (same host time) are still ordered
        // and integrated over their own intervals. A device step that runs ahead of the host's
        // by more than the tolerance (a clock jump), or does not advance (a stall or a step
        // back), is not believed: the host's step is integrated instead (counted).
        let device_dt = match (
            self.timing.imu_dt_from_device_time,
            device_ns,
            self.last_imu_device_ns,
        ) {
            (true, Some(now), Some(prev)) => {
                let d = now.wrapping_sub(prev) as i64 as f64 * 1e-9;
                if d > 0.0 && d <= host_dt + self.timing.clock_tolerance_s {
                    Some(d)
                } else {
                    self.counters.imu_clock_jumps += 1;
                    None
                }
            }
            _ => None,
        };
        if (device_dt.is_none() && t_ns <= last) || t_ns < last {
            self.counters.imu_out_of_order += 1;
            return false;
        }
        let dt = device_dt.unwrap_or(host_dt);
        self.last_imu_device_ns = device_ns;
        let gap = dt > self.timing.imu_max_gap_intervals * m.interval_s;
        if gap {
            // The gap is integrated over its real length with this sample's rates; the motion
            // nobody measured is added to the covariance below.
            self.counters.imu_gaps += 1;
        }
        self.last_imu_ns = Some(t_ns);
        self.counters.imu_samples += 1;
        let w = w - self.gyro_bias;
        let f = f - self.accel_bias;
        self.last_omega_ib = w;
        self.last_f_body = f;
        let c_before = self.sd.propagate(&ImuIncrement {
            dtheta: w * dt,
            dv: f * dt,
            dt,
        });
        self.sd.state.time_s = t_ns as f64 * 1e-9;
        self.pending_f_ned += c_before * f * dt;
        self.pending_dt += dt;
        if gap {
            self.propagate_covariance();
            self.grow_for_unobserved_motion(dt);
        }
        true
    }

    /// Adds to the covariance what an interval of `dt` seconds without (trusted) IMU data
    /// leaves unknown: an acceleration of `gap_accel_std_m_s2` and a rotation rate of
    /// `gap_rate_std_rad_s` held over the interval (velocity `a dt`, position `a dt² / 2`,
    /// attitude `w dt`, at most π).
    pub(crate) fn grow_for_unobserved_motion(&mut self, dt: f64) {
        let a = self.timing.gap_accel_std_m_s2;
        let dv = a * dt;
        let dp = 0.5 * a * dt * dt;
        let da = (self.timing.gap_rate_std_rad_s * dt).min(std::f64::consts::PI);
        self.add_variances(dp * dp, dv * dv, da * da);
    }

    /// Adds to the variances of every position (m²), velocity ((m/s)²) and attitude (rad²) axis.
    pub(crate) fn add_variances(
        &mut self,
        position_m2: f64,
        velocity_m2_s2: f64,
        attitude_rad2: f64,
    ) {
        let mut added = StateVector::zeros();
        for i in 0..3 {
            added[ekf::POS + i] = position_m2;
            added[ekf::VEL + i] = velocity_m2_s2;
            added[ekf::ATT + i] = attitude_rad2;
        }
        for i in 0..ekf::N {
            self.kf.p[(i, i)] += added[i];
        }
        if let Some(t) = self.trace.as_mut() {
            t.grow(&added);
        }
    }

    /// Re-opens a block of three navigation states (`ekf::reopen_block`). For a smoother this
    /// is a step of its own at the same time: the block's rows of the transition are zero and
    /// their new variances the process noise, so that the backward pass sees a model step, not
    /// an update that added variance.
    pub(crate) fn reopen(&mut self, first: usize, extra_variances: [f64; 3]) {
        let before = self.covariance_for_trace();
        ekf::reopen_block(&mut self.kf.p, first, extra_variances);
        if let Some(p_updated) = before {
            let mut nav =
                nalgebra::SMatrix::<f64, { ekf::trace::NAV_ROWS }, { ekf::CORE }>::zeros();
            for i in 0..ekf::trace::NAV_ROWS {
                nav[(i, i)] = if (first..first + 3).contains(&i) {
                    0.0
                } else {
                    1.0
                };
            }
            self.trace_step(p_updated, nav, nalgebra::SVector::repeat(1.0));
        }
    }

    /// The covariance now, when a smoother asked for the trace (copied only then).
    fn covariance_for_trace(&self) -> Option<ekf::Covariance> {
        self.trace.as_ref().map(|_| self.kf.p)
    }

    /// Records a step of the trace to the state's time: from `p_updated` by the transition's
    /// navigation rows and parameter factors to the covariance now.
    fn trace_step(
        &mut self,
        p_updated: ekf::Covariance,
        transition_nav: nalgebra::SMatrix<f64, { ekf::trace::NAV_ROWS }, { ekf::CORE }>,
        transition_params: nalgebra::SVector<f64, { ekf::PARAMS }>,
    ) {
        let event = ekf::trace::Propagation {
            time_ns: self.state_time_ns(),
            p_updated,
            transition_nav,
            transition_params,
            p_predicted: self.kf.p,
        };
        if let Some(t) = self.trace.as_mut() {
            t.events
                .push(ekf::trace::TraceEvent::Propagation(Box::new(event)));
        }
    }

    /// The time of the state (ns): the time stamp of the IMU sample integrated last.
    pub(crate) fn state_time_ns(&self) -> u64 {
        self.last_imu_ns
            .unwrap_or_else(|| (self.sd.state.time_s * 1e9).round() as u64)
    }

    /// True when the state, the biases and the covariance are finite and the covariance looks
    /// like one: non-negative variances and correlations within ±1 (every 2×2 principal minor
    /// non-negative, with a relative margin for rounding).
    pub fn is_sound(&self) -> bool {
        self.state_is_finite() && covariance_is_sound(&self.kf.p)
    }

    /// True when the state and the biases are finite and every variance is finite and
    /// non-negative: [`NavCore::is_sound`] without the correlations (O(N) instead of O(N²)).
    pub fn variances_are_sound(&self) -> bool {
        self.state_is_finite()
            && (0..ekf::N).all(|i| {
                let v = self.kf.p[(i, i)];
                v.is_finite() && v >= 0.0
            })
    }

    fn state_is_finite(&self) -> bool {
        let s = &self.sd.state;
        let position = [
            s.time_s,
            s.position.latitude_rad,
            s.position.longitude_rad,
            s.position.height_m,
        ];
        auvnav_shm_schema::all_finite(&[
            &position,
            s.velocity_ned.as_slice(),
            s.q_body_to_ned.coords.as_slice(),
            self.gyro_bias.as_slice(),
            self.accel_bias.as_slice(),
            self.markov_means.as_slice(),
        ])
    }

    /// Propagates the covariance over the pending interval (no-op when none is pending); the
    /// interval propagated, for the aids' own processes.
    pub fn propagate_covariance(&mut self) -> Option<f64> {
        if self.pending_dt <= 0.0 {
            return None;
        }
        let s = &self.sd.state;
        let inputs = DynamicsInputs {
            c_body_to_ned: s.c_body_to_ned(),
            specific_force_ned: self.pending_f_ned / self.pending_dt,
            velocity_ned: s.velocity_ned,
            latitude_rad: s.position.latitude_rad,
            height_m: s.position.height_m,
        };
        let f = ekf::dynamics_matrix(&inputs);
        let before = self.covariance_for_trace();
        self.kf
            .predict(&f, &inputs.c_body_to_ned, &self.noise, self.pending_dt);
        if let Some(p_updated) = before {
            // The same transition the propagation used (its navigation rows).
            let fdt =
                f.fixed_view::<{ ekf::trace::NAV_ROWS }, { ekf::CORE }>(0, 0) * self.pending_dt;
            let half_nn =
                0.5 * fdt.fixed_view::<{ ekf::trace::NAV_ROWS }, { ekf::trace::NAV_ROWS }>(0, 0);
            let mut nav = fdt + half_nn * fdt;
            for i in 0..ekf::trace::NAV_ROWS {
                nav[(i, i)] += 1.0;
            }
            let params = self.kf.param_transition(self.pending_dt);
            self.trace_step(p_updated, nav, params);
        }
        // The expected value of a Gauss-Markov parameter state decays with its correlation
        // time (constants: a = 1).
        let a = self.kf.param_transition(self.pending_dt);
        for i in 0..ekf::PARAMS {
            self.markov_means[i] *= a[i];
        }
        let dt = self.pending_dt;
        self.pending_dt = 0.0;
        self.pending_f_ned = Vector3::zeros();
        Some(dt)
    }

    /// Applies an error-state estimate to the navigation state and the biases.
    pub fn correct(&mut self, dx: &StateVector) {
        let s = &mut self.sd.state;
        let dp = Vector3::new(dx[ekf::POS], dx[ekf::POS + 1], dx[ekf::POS + 2]);
        s.position = earth::offset_position(&s.position, &(-dp));
        s.velocity_ned -= Vector3::new(dx[ekf::VEL], dx[ekf::VEL + 1], dx[ekf::VEL + 2]);
        let phi = Vector3::new(dx[ekf::ATT], dx[ekf::ATT + 1], dx[ekf::ATT + 2]);
        s.q_body_to_ned = UnitQuaternion::from_scaled_axis(phi) * s.q_body_to_ned;
        self.gyro_bias += Vector3::new(dx[ekf::BG], dx[ekf::BG + 1], dx[ekf::BG + 2]);
        self.accel_bias += Vector3::new(dx[ekf::BA], dx[ekf::BA + 1], dx[ekf::BA + 2]);
        for i in 0..ekf::PARAMS {
            self.markov_means[i] -= dx[ekf::CORE + i];
        }
        if let Some(t) = self.trace.as_mut() {
            t.events
                .push(ekf::trace::TraceEvent::Correction(Box::new(*dx)));
        }
    }

    /// An aid more than one covariance interval older than the state is not fused (counted).
    pub fn aid_is_late(&mut self, t_ns: u64) -> bool {
        let state_ns = (self.sd.state.time_s * 1e9).round() as i128;
        let late =
            (state_ns - i128::from(t_ns)) as f64 * 1e-9 > self.covariance_interval_s.max(0.05);
        if late {
            self.counters.aid_late += 1;
        }
        late
    }

    /// Fresh diagnostics of an aid message (numbered in processing order).
    pub fn diagnostics(&mut self, t_ns: u64, source: AidSource) -> AidDiagnosticsV1 {
        self.diagnostics_sequence += 1;
        AidDiagnosticsV1 {
            host_time_ns: t_ns,
            sequence: self.diagnostics_sequence,
            source: source as u32,
            ..Default::default()
        }
    }

    /// Copies an update's innovation into the diagnostics (as observation minus prediction) and
    /// sets the fused/rejected flag; the correction to apply when it was fused.
    pub fn report<const M: usize>(
        result: Result<(StateVector, ekf::UpdateReport<M>), ekf::FilterError>,
        d: &mut AidDiagnosticsV1,
    ) -> Option<StateVector> {
        match result {
            Ok((dx, rep)) => {
                for i in 0..M.min(3) {
                    d.innovation[i] = -rep.innovation[i];
                    d.innovation_variance[i] = rep.innovation_variance[i];
                }
                d.test_ratio = rep.test_ratio;
                if rep.fused {
                    d.flags = AidDiagnosticsV1::FLAG_FUSED;
                    Some(dx)
                } else {
                    d.flags = AidDiagnosticsV1::FLAG_REJECTED;
                    None
                }
            }
            Err(_) => {
                d.flags = AidDiagnosticsV1::FLAG_REJECTED;
                None
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_covariance_is_judged_element_by_element() {
        let mut p = ekf::Covariance::identity() * 4.0;
        p[(0, 0)] = 0.0; // a state without variance is sound
        assert!(covariance_is_sound(&p));
        let with = |i: usize, j: usize, v: f64| {
            let mut q = p;
            q[(i, j)] = v;
            q[(j, i)] = v;
            covariance_is_sound(&q)
        };
        // Correlations up to ±1 (and the rounding margin), in every place of the triangle.
        assert!(with(27, 1, 4.0) && with(1, 27, -4.0) && with(5, 4, 4.0 * (1.0 + 4e-7)));
        assert!(!with(27, 1, 4.01) && !with(2, 26, -4.01) && !with(5, 4, 4.0 * (1.0 + 1e-5)));
        // A correlation with the state that has no variance.
        assert!(!with(0, 14, 1e-3));
        // Values that are not numbers, in the triangle and on the diagonal.
        for v in [f64::NAN, f64::INFINITY, f64::NEG_INFINITY] {
            assert!(!with(20, 7, v), "{v}");
            assert!(!with(13, 13, v), "{v}");
        }
        assert!(!with(13, 13, -1e-9));
    }
}
