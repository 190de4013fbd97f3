//! The inertial core of the navigator: strapdown mechanisation, the error filter and its
//! covariance propagation, the IMU bias estimates, the correction of the core states, and what the
//! aid sources need from the last IMU sample. The aid sources (`crate::aid`) work on it; the
//! navigator (`crate::navigator`) owns it together with the aids and applies their corrections.

use crate::earth;
use crate::ekf::{self, DynamicsInputs, ErrorFilter, ProcessNoise, StateVector};
use crate::strapdown::{ImuIncrement, NavState, Strapdown};
use auvnav_shm_schema::{AidDiagnosticsV1, AidSource, ImuSampleV1};
use nalgebra::{UnitQuaternion, Vector3};

/// How IMU samples are integrated (see `NavConfig`): covariance propagation interval (s), the
/// longest gap bridged (nominal intervals), and whether the device's time stamps give the interval.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ImuTiming {
    pub covariance_interval_s: f64,
    pub imu_max_gap_intervals: f64,
    pub imu_dt_from_device_time: bool,
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
    imu_max_gap_intervals: f64,
    imu_dt_from_device_time: bool,
    /// IMU and lateness counters (the aids count the rest).
    pub counters: CoreCounters,
}

/// What the inertial core counted.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct CoreCounters {
    pub imu_samples: u64,
    pub imu_out_of_order: u64,
    pub imu_invalid: u64,
    pub imu_gaps: u64,
    pub aid_late: u64,
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
            imu_max_gap_intervals: timing.imu_max_gap_intervals,
            imu_dt_from_device_time: timing.imu_dt_from_device_time,
            counters: CoreCounters::default(),
        }
    }

    /// The navigation state.
    pub fn state(&self) -> &NavState {
        &self.sd.state
    }

    /// Integrates one IMU sample; false when it was skipped (invalid, out of order; counted).
    pub(crate) fn integrate(&mut self, m: &ImuSampleV1) -> bool {
        let t_ns = m.host_time_ns;
        let finite = m
            .angular
            .iter()
            .chain(m.specific.iter())
            .all(|x| x.is_finite());
        let valid_bits = ImuSampleV1::STATUS_GYRO_VALID | ImuSampleV1::STATUS_ACCEL_VALID;
        if !finite
            || m.status & valid_bits != valid_bits
            || !(m.interval_s > 0.0 && m.interval_s < 1.0)
        {
            self.counters.imu_invalid += 1;
            return false;
        }
        let state_ns = (self.sd.state.time_s * 1e9).round() as u64;
        let last = self.last_imu_ns.unwrap_or(state_ns);
        let device_ns =
            (m.status & ImuSampleV1::STATUS_DEVICE_TIME_VALID != 0).then_some(m.device_time_ns);
        // With device time, samples completed by one read (same host time) are still ordered
        // and integrated over their own intervals.
        let device_dt = match (
            self.imu_dt_from_device_time,
            device_ns,
            self.last_imu_device_ns,
        ) {
            (true, Some(now), Some(prev)) if now > prev && now - prev < 1_000_000_000 => {
                Some((now - prev) as f64 * 1e-9)
            }
            _ => None,
        };
        if (device_dt.is_none() && t_ns <= last) || t_ns < last {
            self.counters.imu_out_of_order += 1;
            return false;
        }
        let mut dt = device_dt.unwrap_or((t_ns - last) as f64 * 1e-9);
        self.last_imu_device_ns = device_ns;
        if dt > self.imu_max_gap_intervals * m.interval_s {
            self.counters.imu_gaps += 1;
            // Bridge the gap with the sample's own rates over its nominal interval only; the
            // missing time still passes (the state time follows the message time).
            dt = dt.min(1.0);
        }
        self.last_imu_ns = Some(t_ns);
        self.counters.imu_samples += 1;
        let increments = m.status & ImuSampleV1::STATUS_INCREMENTS != 0;
        let (w, f) = if increments {
            (
                Vector3::from(m.angular) / m.interval_s,
                Vector3::from(m.specific) / m.interval_s,
            )
        } else {
            (Vector3::from(m.angular), Vector3::from(m.specific))
        };
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
        true
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
        self.kf
            .predict(&f, &inputs.c_body_to_ned, &self.noise, self.pending_dt);
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
