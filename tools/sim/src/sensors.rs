//! Sensor models: each turns the true state into one message, applying its named effects.
//!
//! Long on purpose: every sensor model of the simulator, each applying its named effects, so that
//! what an effect means for every sensor is read in one place.

use super::effects::Effects;
use super::rng::Rng;
use super::scenario::Station;
use super::trajectory::TruthSample;
use auvnav_core::aid::magnetometer::MagnetometerConfig;
use auvnav_core::earth::{self, Geodetic};
use auvnav_core::ekf::skew;
use auvnav_shm_schema::{
    DepthV1, DvlVelocityV1, GnssFixV1, ImuSampleV1, MagnetometerV1, UsblFixV1,
};
use nalgebra::{Matrix3, Matrix3x4, Rotation3, Vector3};

/// One degree per hour in rad/s (the unit of the gyro effects).
pub const DEG_PER_H: f64 = std::f64::consts::PI / 180.0 / 3600.0;
/// One micro-g in m/s² (the unit of the accelerometer effects).
pub const MICRO_G: f64 = 9.806_65e-6;
/// Sound speed the acoustic devices assume (m/s).
pub const ASSUMED_SOUND_SPEED: f64 = 1500.0;
/// Water density the depth sensor assumes (kg/m^3).
pub const ASSUMED_DENSITY: f64 = 1025.0;
/// Standard gravity used by the depth sensor to convert pressure (m/s^2).
const STANDARD_GRAVITY: f64 = 9.806_65;

fn ns(t: f64) -> u64 {
    (t * 1e9).round().max(0.0) as u64
}

/// The IMU: biases (constant and Gauss-Markov), white noise, scale factor, misalignment and
/// quantisation of the increments. Outputs rates (interval averages) stamped at the interval end.
pub struct ImuModel {
    rng: Rng,
    dt: f64,
    gyro_error: Matrix3<f64>,
    accel_error: Matrix3<f64>,
    gyro_bias: Vector3<f64>,
    accel_bias: Vector3<f64>,
    gyro_gm: Vector3<f64>,
    accel_gm: Vector3<f64>,
    gm_decay: f64,
    gyro_gm_drive: f64,
    accel_gm_drive: f64,
    gyro_white: f64,
    accel_white: f64,
    gyro_quantum: f64,
    accel_quantum: f64,
    gyro_residual: Vector3<f64>,
    accel_residual: Vector3<f64>,
    sequence: u64,
}

/// Scale factor (ppm per axis) times misalignment (mrad, small rotation) of an IMU triad.
fn triad_error(scale_ppm: [f64; 3], misalignment_mrad: [f64; 3]) -> Matrix3<f64> {
    Matrix3::from_diagonal(&Vector3::from(scale_ppm).map(|x| 1.0 + x * 1e-6))
        * (Matrix3::identity() - skew(&(Vector3::from(misalignment_mrad) * 1e-3)))
}

impl ImuModel {
    /// The gyro reading (rad/s) of the true rate `omega_ib` under the constant effects: scale
    /// factor and misalignment, then the bias (no noise, no Gauss-Markov bias, no quantisation).
    pub fn gyro_reading(e: &Effects, omega_ib: &Vector3<f64>) -> Vector3<f64> {
        triad_error(e.imu_gyro_scale_factor, e.imu_gyro_misalignment) * omega_ib
            + Vector3::from(e.imu_gyro_bias) * DEG_PER_H
    }

    /// The accelerometer reading (m/s²) of the true specific force, as [`Self::gyro_reading`].
    pub fn accel_reading(e: &Effects, f_b: &Vector3<f64>) -> Vector3<f64> {
        triad_error(e.imu_accel_scale_factor, e.imu_accel_misalignment) * f_b
            + Vector3::from(e.imu_accel_bias) * MICRO_G
    }

    pub fn new(e: &Effects, seed: u64, rate_hz: f64) -> ImuModel {
        let dt = 1.0 / rate_hz;
        let tau = e.imu_bias_correlation_time;
        let decay = (-dt / tau).exp();
        let drive = (1.0 - decay * decay).sqrt();
        let mut rng = Rng::new(seed, "imu");
        let g_gm = e.imu_gyro_bias_instability * DEG_PER_H;
        let a_gm = e.imu_accel_bias_instability * MICRO_G;
        // The Gauss-Markov biases start in their stationary distribution.
        let gyro_gm = Vector3::new(rng.gauss(g_gm), rng.gauss(g_gm), rng.gauss(g_gm));
        let accel_gm = Vector3::new(rng.gauss(a_gm), rng.gauss(a_gm), rng.gauss(a_gm));
        ImuModel {
            rng,
            dt,
            gyro_error: triad_error(e.imu_gyro_scale_factor, e.imu_gyro_misalignment),
            accel_error: triad_error(e.imu_accel_scale_factor, e.imu_accel_misalignment),
            gyro_bias: Vector3::from(e.imu_gyro_bias) * DEG_PER_H,
            accel_bias: Vector3::from(e.imu_accel_bias) * MICRO_G,
            gyro_gm,
            accel_gm,
            gm_decay: decay,
            gyro_gm_drive: g_gm * drive,
            accel_gm_drive: a_gm * drive,
            // ARW deg/sqrt(h) -> rad/sqrt(s); per-sample rate sigma = N / sqrt(dt).
            gyro_white: e.imu_angle_random_walk * std::f64::consts::PI / 180.0 / 60.0 / dt.sqrt(),
            accel_white: e.imu_velocity_random_walk / 60.0 / dt.sqrt(),
            gyro_quantum: e.imu_gyro_quantum,
            accel_quantum: e.imu_accel_quantum,
            gyro_residual: Vector3::zeros(),
            accel_residual: Vector3::zeros(),
            sequence: 0,
        }
    }

    /// One sample from the true interval-average rate and specific force, stamped at `t`.
    pub fn sample(&mut self, t: f64, omega_ib: &Vector3<f64>, f_b: &Vector3<f64>) -> ImuSampleV1 {
        let r = &mut self.rng;
        let gyro_noise = Vector3::new(
            r.gauss(self.gyro_white),
            r.gauss(self.gyro_white),
            r.gauss(self.gyro_white),
        );
        let accel_noise = Vector3::new(
            r.gauss(self.accel_white),
            r.gauss(self.accel_white),
            r.gauss(self.accel_white),
        );
        let mut w = self.gyro_error * omega_ib + self.gyro_bias + self.gyro_gm + gyro_noise;
        let mut f = self.accel_error * f_b + self.accel_bias + self.accel_gm + accel_noise;
        for i in 0..3 {
            self.gyro_gm[i] = self.gm_decay * self.gyro_gm[i] + r.gauss(self.gyro_gm_drive);
            self.accel_gm[i] = self.gm_decay * self.accel_gm[i] + r.gauss(self.accel_gm_drive);
        }
        w = quantise(w, self.dt, self.gyro_quantum, &mut self.gyro_residual);
        f = quantise(f, self.dt, self.accel_quantum, &mut self.accel_residual);
        self.sequence += 1;
        ImuSampleV1 {
            host_time_ns: ns(t),
            device_time_ns: ns(t),
            sequence: self.sequence,
            angular: w.into(),
            specific: f.into(),
            interval_s: self.dt,
            temperature_c: 20.0,
            status: ImuSampleV1::STATUS_GYRO_VALID
                | ImuSampleV1::STATUS_ACCEL_VALID
                | ImuSampleV1::STATUS_TEMPERATURE_VALID
                | ImuSampleV1::STATUS_DEVICE_TIME_VALID,
        }
    }
}

/// Quantises the increment `rate * dt` to `quantum`, carrying the residual; returns the rate.
fn quantise(
    rate: Vector3<f64>,
    dt: f64,
    quantum: f64,
    residual: &mut Vector3<f64>,
) -> Vector3<f64> {
    if quantum <= 0.0 {
        return rate;
    }
    let inc = rate * dt + *residual;
    let q = inc.map(|x| (x / quantum).round() * quantum);
    *residual = inc - q;
    q / dt
}

/// Half-angle of the DVL beams from the instrument z axis (rad).
pub const DVL_BEAM_ANGLE: f64 = 30.0 * std::f64::consts::PI / 180.0;

/// Unit vectors of the four Janus beams in the DVL frame (pointing from the transducer to the
/// bottom): beam i at azimuth 45 + 90 i deg from DVL x, 30 deg from DVL z.
pub fn dvl_beam_directions() -> [Vector3<f64>; 4] {
    let (s, c) = DVL_BEAM_ANGLE.sin_cos();
    std::array::from_fn(|i| {
        let az = (45.0 + 90.0 * i as f64).to_radians();
        Vector3::new(s * az.cos(), s * az.sin(), c)
    })
}

/// The four beams' radial velocities (m/s, along each beam from the transducer to the bottom)
/// for the DVL-frame velocity `v_dvl`, with each beam's scale-factor error
/// (`dvl.beam_scale_factor`) and angle error (`dvl.beam_angle_error`: the beam's true direction
/// is that much further from z at the same azimuth), without noise. With both zero it is
/// `dvl_beam_directions()[i] · v_dvl`.
pub fn dvl_beam_readings(e: &Effects, v_dvl: &Vector3<f64>) -> [f64; 4] {
    std::array::from_fn(|i| {
        let (s, c) = (DVL_BEAM_ANGLE + e.dvl_beam_angle_error[i].to_radians()).sin_cos();
        let az = (45.0 + 90.0 * i as f64).to_radians();
        let b = Vector3::new(s * az.cos(), s * az.sin(), c);
        b.dot(v_dvl) * (1.0 + e.dvl_beam_scale_factor[i] * 1e-6)
    })
}

/// Standard deviation of each DVL-frame velocity component per unit of beam noise
/// (`dvl.noise`): the square roots of the diagonal of (BᵀB)⁻¹ of the least-squares solution.
pub fn dvl_velocity_std_per_beam_noise() -> Vector3<f64> {
    let b = nalgebra::Matrix4x3::from_rows(&dvl_beam_directions().map(|v| v.transpose()));
    (b.transpose() * b)
        .try_inverse()
        .unwrap_or_else(Matrix3::identity)
        .diagonal()
        .map(f64::sqrt)
}

/// The DVL's installation as the simulator models it (`dvl.mount_*`, `dvl.lever_arm`,
/// `dvl.scale_factor`, `dvl.sound_speed`): what a locked, noise-free DVL reads for a body motion.
/// Model discovery predicts DVL readings with the same code.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DvlInstallation {
    pub c_body_to_dvl: Matrix3<f64>,
    pub lever_arm: Vector3<f64>,
    /// Velocity scale: `dvl.scale_factor` × assumed / true sound speed.
    pub scale: f64,
    /// The bed's velocity under bottom track (NED; `dvl.bed_velocity`, no vertical part).
    pub bed_velocity_ned: Vector3<f64>,
    /// The periodic velocity error (`dvl.periodic_velocity_error`): amplitude per DVL axis
    /// (m/s), angular frequency (rad/s) and phase (rad).
    pub periodic: Option<(Vector3<f64>, f64, f64)>,
}

impl DvlInstallation {
    pub fn from_effects(e: &Effects) -> DvlInstallation {
        let c_dvl_to_body = Rotation3::from_euler_angles(
            e.dvl_mount_roll.to_radians(),
            e.dvl_mount_pitch.to_radians(),
            e.dvl_mount_yaw.to_radians(),
        );
        DvlInstallation {
            c_body_to_dvl: c_dvl_to_body.inverse().into_inner(),
            lever_arm: Vector3::from(e.dvl_lever_arm),
            scale: e.dvl_scale_factor * ASSUMED_SOUND_SPEED / e.dvl_sound_speed,
            bed_velocity_ned: Vector3::new(e.dvl_bed_velocity[0], e.dvl_bed_velocity[1], 0.0),
            periodic: e
                .dvl_periodic_velocity_error
                .iter()
                .any(|a| *a != 0.0)
                .then(|| {
                    (
                        Vector3::from(e.dvl_periodic_velocity_error),
                        std::f64::consts::TAU / e.dvl_periodic_velocity_error_period,
                        e.dvl_periodic_velocity_error_phase.to_radians(),
                    )
                }),
        }
    }

    /// The periodic velocity error (`dvl.periodic_velocity_error`) in the DVL frame at stamp
    /// `t_s` (zero when the effect is off).
    pub fn periodic_error(&self, t_s: f64) -> Vector3<f64> {
        match self.periodic {
            Some((a, w, phase)) => a * (w * t_s + phase).sin(),
            None => Vector3::zeros(),
        }
    }

    /// [`DvlInstallation::bottom_track_velocity`] plus the periodic error at stamp `t_s`: what a
    /// locked, noise-free DVL stamps at `t_s` (the motion given at its time of validity).
    pub fn bottom_track_reading(
        &self,
        t_s: f64,
        c_body_to_ned: &Matrix3<f64>,
        velocity_ned: &Vector3<f64>,
        omega_eb_body: &Vector3<f64>,
    ) -> Vector3<f64> {
        let v = self.bottom_track_velocity(c_body_to_ned, velocity_ned, omega_eb_body);
        match self.periodic {
            // Off: the velocity as it is (adding zeros would turn a −0.0 into 0.0).
            None => v,
            Some(_) => v + self.periodic_error(t_s),
        }
    }

    /// The bottom-track velocity in the DVL frame: [`DvlInstallation::velocity`] relative to the
    /// bed (`dvl.bed_velocity`).
    pub fn bottom_track_velocity(
        &self,
        c_body_to_ned: &Matrix3<f64>,
        velocity_ned: &Vector3<f64>,
        omega_eb_body: &Vector3<f64>,
    ) -> Vector3<f64> {
        self.velocity(
            c_body_to_ned,
            &(velocity_ned - self.bed_velocity_ned),
            omega_eb_body,
        )
    }

    /// The velocity in the DVL frame for the body's attitude, velocity w.r.t. the Earth (NED) and
    /// angular rate w.r.t. the Earth (body axes), at the time of validity.
    pub fn velocity(
        &self,
        c_body_to_ned: &Matrix3<f64>,
        velocity_ned: &Vector3<f64>,
        omega_eb_body: &Vector3<f64>,
    ) -> Vector3<f64> {
        let v_body =
            c_body_to_ned.transpose() * velocity_ned + omega_eb_body.cross(&self.lever_arm);
        self.c_body_to_dvl * v_body * self.scale
    }
}

/// The DVL: beam velocities with noise, least-squares instrument velocity, mounting rotation,
/// lever arm, scale factor, sound speed, time offset and loss of bottom lock.
pub struct DvlModel {
    rng: Rng,
    beams: [Vector3<f64>; 4],
    pinv: Matrix3x4<f64>,
    install: DvlInstallation,
    noise: f64,
    velocity_std: Vector3<f64>,
    loss_rate: f64,
    loss_duration: f64,
    max_altitude: f64,
    seabed_depth: f64,
    lost_until: f64,
    pub time_offset: f64,
    sequence: u64,
    water_noise: f64,
    water_rng: Rng,
    /// The blocked beam (index 0..4) and the fraction of the time it is blocked.
    blocked_beam: Option<(usize, f64)>,
    blocked_until: f64,
    blocked_rng: Rng,
    /// The per-beam effects (`dvl.beam_scale_factor`, `dvl.beam_angle_error`).
    beam_effects: Effects,
    /// The time-correlated velocity error (`dvl.velocity_error_instability`, DVL frame), its
    /// one-sigma, correlation time and random stream (drawn from only when the sigma is above 0).
    correlated: Option<Vector3<f64>>,
    correlated_std: f64,
    correlated_time: f64,
    correlated_rng: Rng,
}

/// Length of one spell of a blocked beam (s).
pub const BEAM_BLOCKED_SPELL_S: f64 = 30.0;

impl DvlModel {
    pub fn new(e: &Effects, seed: u64, seabed_depth_m: f64) -> DvlModel {
        let beams = dvl_beam_directions();
        let b = nalgebra::Matrix4x3::from_rows(&beams.map(|v| v.transpose()));
        let btb_inv = (b.transpose() * b)
            .try_inverse()
            .unwrap_or_else(Matrix3::identity);
        let pinv = btb_inv * b.transpose();
        DvlModel {
            rng: Rng::new(seed, "dvl"),
            beams,
            pinv,
            install: DvlInstallation::from_effects(e),
            noise: e.dvl_noise,
            velocity_std: dvl_velocity_std_per_beam_noise() * e.dvl_noise,
            loss_rate: e.dvl_bottom_lock_loss_rate,
            loss_duration: e.dvl_bottom_lock_loss_duration,
            max_altitude: e.dvl_max_altitude,
            seabed_depth: seabed_depth_m,
            lost_until: f64::NEG_INFINITY,
            time_offset: e.dvl_time_offset,
            sequence: 0,
            water_noise: e.dvl_water_track_noise,
            water_rng: Rng::new(seed, "dvl-water-track"),
            blocked_beam: (e.dvl_beam_blocked >= 1.0 && e.dvl_beam_blocked_fraction > 0.0).then(
                || {
                    (
                        (e.dvl_beam_blocked.round() as usize - 1).min(3),
                        e.dvl_beam_blocked_fraction,
                    )
                },
            ),
            blocked_until: f64::NEG_INFINITY,
            blocked_rng: Rng::new(seed, "dvl-beam-blocked"),
            beam_effects: e.clone(),
            correlated: None,
            correlated_std: e.dvl_velocity_error_instability,
            correlated_time: e.dvl_velocity_error_correlation_time,
            correlated_rng: Rng::new(seed, "dvl-velocity-error"),
        }
    }

    /// Whether the blocked beam is blocked at `t`: spells of [`BEAM_BLOCKED_SPELL_S`] starting at
    /// the rate that keeps the beam blocked for its fraction of the time.
    fn beam_blocked(&mut self, t: f64, interval: f64) -> Option<usize> {
        let (beam, fraction) = self.blocked_beam?;
        if t >= self.blocked_until {
            let rate = fraction / ((1.0 - fraction) * BEAM_BLOCKED_SPELL_S);
            if self.blocked_rng.uniform() < rate * interval {
                self.blocked_until = t + BEAM_BLOCKED_SPELL_S;
            }
        }
        (t < self.blocked_until).then_some(beam)
    }

    /// Whether the DVL reports water track (`dvl.water_track_noise` above 0).
    pub fn reports_water_track(&self) -> bool {
        self.water_noise > 0.0
    }

    /// The water-track velocity of the same ping as the last [`DvlModel::sample`]: the vehicle's
    /// velocity relative to the water (`truth` at the time of validity, `current_ned` the water's
    /// velocity) through the installation, with white noise on each axis.
    pub fn sample_water_track(
        &mut self,
        t: f64,
        truth: &TruthSample,
        current_ned: &Vector3<f64>,
    ) -> DvlVelocityV1 {
        self.sequence += 1;
        let relative = truth.velocity_ned - current_ned;
        let v = self
            .install
            .velocity(&truth.c_body_to_ned, &relative, &truth.omega_eb_body);
        let noise = self.water_noise;
        DvlVelocityV1 {
            host_time_ns: ns(t),
            device_time_ns: ns(t),
            sequence: self.sequence,
            validity_time_ns: ns(t),
            velocity_dvl_m_s: v.map(|x| x + self.water_rng.gauss(noise)).into(),
            velocity_std_m_s: [noise; 3],
            sound_speed_m_s: ASSUMED_SOUND_SPEED,
            validity: DvlVelocityV1::VALID_VELOCITY
                | DvlVelocityV1::TRACK_WATER
                | DvlVelocityV1::VALID_STD
                | DvlVelocityV1::VALID_SOUND_SPEED
                | DvlVelocityV1::VALID_DEVICE_TIME,
            ..Default::default()
        }
    }

    /// One ping stamped at `t`; `truth` is the state at the time of validity `t - time_offset`.
    pub fn sample(&mut self, t: f64, interval: f64, truth: &TruthSample) -> DvlVelocityV1 {
        self.sequence += 1;
        let mut m = DvlVelocityV1 {
            host_time_ns: ns(t),
            device_time_ns: ns(t),
            sequence: self.sequence,
            validity_time_ns: ns(t),
            sound_speed_m_s: ASSUMED_SOUND_SPEED,
            validity: DvlVelocityV1::VALID_SOUND_SPEED | DvlVelocityV1::VALID_DEVICE_TIME,
            ..Default::default()
        };
        let altitude = self.seabed_depth + truth.position.height_m;
        if self.loss_rate > 0.0
            && t >= self.lost_until
            && self.rng.uniform() < self.loss_rate * interval
        {
            self.lost_until = t + self.loss_duration;
        }
        if self.correlated_std > 0.0 {
            // First-order Gauss-Markov, stationary from the first ping.
            let s = self.correlated_std;
            let next = match self.correlated {
                None => Vector3::from_fn(|_, _| self.correlated_rng.gauss(s)),
                Some(e) => {
                    let phi = (-interval.max(0.0) / self.correlated_time).exp();
                    let q = s * (1.0 - phi * phi).sqrt();
                    e.map(|x| phi * x + self.correlated_rng.gauss(q))
                }
            };
            self.correlated = Some(next);
        }
        let locked = t >= self.lost_until && altitude > 0.5 && altitude <= self.max_altitude;
        if !locked {
            return m;
        }
        let blocked = self.beam_blocked(t, interval);
        let mut v_dvl = self.install.bottom_track_reading(
            t,
            &truth.c_body_to_ned,
            &truth.velocity_ned,
            &truth.omega_eb_body,
        );
        if let Some(e) = self.correlated {
            v_dvl += e;
        }
        let c_dvl_to_ned = truth.c_body_to_ned * self.install.c_body_to_dvl.transpose();
        let mut y = nalgebra::Vector4::zeros();
        let radial = dvl_beam_readings(&self.beam_effects, &v_dvl);
        for (i, b) in self.beams.iter().enumerate() {
            y[i] = radial[i] + self.rng.gauss(self.noise);
            m.beam_velocity_m_s[i] = y[i];
            let down = (c_dvl_to_ned * b).z;
            m.validity |= DvlVelocityV1::VALID_BEAM_VELOCITY << i;
            if down > 0.1 {
                m.beam_range_m[i] = altitude / down;
                m.validity |= DvlVelocityV1::VALID_BEAM_RANGE << i;
            }
        }
        if let Some(b) = blocked {
            // Three beams: no instrument velocity from this DVL, the other beams as they are.
            m.beam_velocity_m_s[b] = 0.0;
            m.beam_range_m[b] = 0.0;
            m.validity &=
                !((DvlVelocityV1::VALID_BEAM_VELOCITY | DvlVelocityV1::VALID_BEAM_RANGE) << b);
            m.altitude_m = altitude;
            m.beams_used = 3;
            m.validity |= DvlVelocityV1::VALID_ALTITUDE;
            return m;
        }
        let v = self.pinv * y;
        m.velocity_dvl_m_s = v.into();
        m.altitude_m = altitude;
        m.beams_used = 4;
        m.validity |= DvlVelocityV1::VALID_VELOCITY | DvlVelocityV1::VALID_ALTITUDE;
        if self.noise > 0.0 {
            m.velocity_std_m_s = self.velocity_std.into();
            m.validity |= DvlVelocityV1::VALID_STD;
        }
        m
    }
}

/// The water current at the vehicle: the surface current (`water.current`), a slowly varying
/// part (`water.current_variation`, first-order Gauss–Markov with a 600 s correlation time) and a
/// linear decrease with depth (`water.current_shear`). Its random stream is its own: a run
/// without a varying current draws nothing from it.
pub struct WaterCurrent {
    rng: Rng,
    surface: [f64; 2],
    variation_std: f64,
    shear: f64,
    varying: [f64; 2],
}

/// Correlation time of the current's slowly varying part (s).
pub const CURRENT_CORRELATION_S: f64 = 600.0;

impl WaterCurrent {
    pub fn new(e: &Effects, seed: u64) -> WaterCurrent {
        WaterCurrent {
            rng: Rng::new(seed, "water-current"),
            surface: e.water_current,
            variation_std: e.water_current_variation,
            shear: e.water_current_shear,
            varying: [0.0; 2],
        }
    }

    /// Steps the varying part by `dt` (s) and returns the current (NED, m/s, down 0) at
    /// `depth_m`.
    pub fn step(&mut self, dt: f64, depth_m: f64) -> Vector3<f64> {
        if self.variation_std > 0.0 {
            let a = (-dt / CURRENT_CORRELATION_S).exp();
            let q = self.variation_std * (1.0 - a * a).sqrt();
            for v in &mut self.varying {
                *v = a * *v + self.rng.gauss(q);
            }
        }
        let k = (1.0 - self.shear * depth_m.max(0.0)).max(0.0);
        Vector3::new(
            k * (self.surface[0] + self.varying[0]),
            k * (self.surface[1] + self.varying[1]),
            0.0,
        )
    }
}

/// Array-frame positions of the four hydrophones: 1 and 3 on array x, 2 and 4 on array y.
pub fn hydrophone_positions(baseline_m: f64) -> [Vector3<f64>; 4] {
    let h = baseline_m / 2.0;
    [
        Vector3::new(h, 0.0, 0.0),
        Vector3::new(0.0, h, 0.0),
        Vector3::new(-h, 0.0, 0.0),
        Vector3::new(0.0, -h, 0.0),
    ]
}

/// The true hydrophone (receiver) positions in the array frame: the nominal ones displaced by
/// `usbl.hydrophone_offset`.
pub fn true_hydrophones(e: &Effects, nominal: &[Vector3<f64>; 4]) -> [Vector3<f64>; 4] {
    let o = &e.usbl_hydrophone_offset;
    std::array::from_fn(|k| nominal[k] + Vector3::new(o[3 * k], o[3 * k + 1], o[3 * k + 2]))
}

/// The range (m) from each hydrophone to a responder at `p` (array frame) that a device measures
/// with the assumed sound speed: the true geometry (the effects' hydrophone offsets) scaled by
/// the sound-speed error. Model discovery predicts per-receiver ranges with the same code.
pub fn hydrophone_ranges(e: &Effects, nominal: &[Vector3<f64>; 4], p: &Vector3<f64>) -> [f64; 4] {
    let scale = ASSUMED_SOUND_SPEED / e.usbl_sound_speed;
    true_hydrophones(e, nominal).map(|h| (p - h).norm() * scale)
}

/// The docking-station USBL: slant range from the central transducer, range differences across
/// the hydrophone baselines, angles and the device's own position fix, from the true geometry
/// (true array position and yaw = surveyed + the offset and yaw effects).
pub struct UsblModel {
    rng: Rng,
    true_array: Geodetic,
    c_ned_to_array: Matrix3<f64>,
    hydrophones: [Vector3<f64>; 4],
    responder: Vector3<f64>,
    range_scale: f64,
    e: Effects,
    sequence: u64,
}

/// Outlier indicator for tests and diagnostics: which fixes got a multipath error.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct UsblTruth {
    pub outlier_m: f64,
}

impl UsblModel {
    /// `surveyed`: the array position as surveyed (the filter's belief).
    pub fn new(e: &Effects, seed: u64, station: &Station, surveyed: &Geodetic) -> UsblModel {
        let true_array = earth::offset_position(surveyed, &Vector3::from(e.usbl_array_offset));
        let yaw = (station.yaw_deg + e.usbl_array_yaw).to_radians();
        let c_array_to_ned = Rotation3::from_euler_angles(0.0, 0.0, yaw);
        UsblModel {
            rng: Rng::new(seed, "usbl"),
            true_array,
            c_ned_to_array: c_array_to_ned.inverse().into_inner(),
            hydrophones: true_hydrophones(e, &hydrophone_positions(station.baseline_m)),
            responder: Vector3::from(station.responder_lever_arm_m),
            range_scale: ASSUMED_SOUND_SPEED / e.usbl_sound_speed,
            e: e.clone(),
            sequence: 0,
        }
    }

    /// The true responder position in the true array frame (m).
    pub fn responder_in_array(&self, truth: &TruthSample) -> Vector3<f64> {
        let to_auv = earth::ned_offset(&self.true_array, &truth.position);
        self.c_ned_to_array * (to_auv + truth.c_body_to_ned * self.responder)
    }

    /// A fix for the geometry of `truth` (at validity time), delivered at `t_delivered`; `None`
    /// outside the coverage.
    pub fn sample(
        &mut self,
        t_delivered: f64,
        truth: &TruthSample,
    ) -> Option<(UsblFixV1, UsblTruth)> {
        let p = self.responder_in_array(truth);
        let range = p.norm();
        if range > self.e.usbl_max_range {
            return None;
        }
        let ranges = self.hydrophones.map(|h| (p - h).norm());
        let e = &self.e;
        let r = &mut self.rng;
        let mut outlier = 0.0;
        if e.usbl_outlier_fraction > 0.0 && r.uniform() < e.usbl_outlier_fraction {
            let [lo, hi] = e.usbl_outlier_range;
            outlier = lo + (hi - lo) * r.uniform();
        }
        let slant = range * self.range_scale + outlier + r.gauss(e.usbl_range_noise);
        let d13 =
            (ranges[0] - ranges[2]) * self.range_scale + r.gauss(e.usbl_range_difference_noise);
        let d24 =
            (ranges[1] - ranges[3]) * self.range_scale + r.gauss(e.usbl_range_difference_noise);
        let angle_noise = e.usbl_angle_noise.to_radians();
        let az = p.y.atan2(p.x) + r.gauss(angle_noise);
        let el = (-p.z).atan2(p.x.hypot(p.y)) + r.gauss(angle_noise);
        self.sequence += 1;
        let t = ns(t_delivered);
        let fix = UsblFixV1 {
            host_time_ns: t,
            device_time_ns: t,
            sequence: self.sequence,
            validity_time_ns: t,
            slant_range_m: slant,
            travel_time_s: slant / ASSUMED_SOUND_SPEED,
            range_difference_m: [d13, d24],
            azimuth_rad: az,
            elevation_rad: el,
            position_array_m: [
                slant * el.cos() * az.cos(),
                slant * el.cos() * az.sin(),
                -slant * el.sin(),
            ],
            sound_speed_m_s: ASSUMED_SOUND_SPEED,
            rssi_db: [(-60.0 - 20.0 * range.max(1.0).log10()) as f32; 4],
            fit_error_m: 0.0,
            validity: UsblFixV1::VALID_RANGE
                | UsblFixV1::VALID_RANGE_DIFFERENCES
                | UsblFixV1::VALID_ANGLES
                | UsblFixV1::VALID_POSITION
                | UsblFixV1::VALID_SOUND_SPEED
                | UsblFixV1::VALID_RSSI
                | UsblFixV1::VALID_DEVICE_TIME,
            beacon_id: 1,
            reserved: 0,
        };
        Some((fix, UsblTruth { outlier_m: outlier }))
    }
}

/// Pressure depth: density error, bias, noise.
pub struct DepthModel {
    rng: Rng,
    e: Effects,
    sequence: u64,
}

impl DepthModel {
    pub fn new(e: &Effects, seed: u64) -> DepthModel {
        DepthModel {
            rng: Rng::new(seed, "depth"),
            e: e.clone(),
            sequence: 0,
        }
    }

    /// What a noise-free depth sensor reads when the IMU is at a true depth (m) with attitude
    /// `c_body_to_ned`: the depth of the sensor's point (`depth.lever_arm` from the IMU), its
    /// pressure converted with the assumed density (`depth.density`), plus `depth.bias`. Model
    /// discovery uses the same code.
    pub fn reading(e: &Effects, depth_m: f64, c_body_to_ned: &Matrix3<f64>) -> f64 {
        let sensor_depth_m = depth_m + (c_body_to_ned * Vector3::from(e.depth_lever_arm)).z;
        let pressure = e.depth_density * STANDARD_GRAVITY * sensor_depth_m;
        pressure / (ASSUMED_DENSITY * STANDARD_GRAVITY) + e.depth_bias
    }

    pub fn sample(&mut self, t: f64, truth: &TruthSample) -> DepthV1 {
        let measured = DepthModel::reading(&self.e, -truth.position.height_m, &truth.c_body_to_ned)
            + self.rng.gauss(self.e.depth_noise);
        self.sequence += 1;
        DepthV1 {
            host_time_ns: ns(t),
            device_time_ns: ns(t),
            sequence: self.sequence,
            depth_m: measured,
            pressure_pa: measured * ASSUMED_DENSITY * STANDARD_GRAVITY,
            water_density_kg_m3: ASSUMED_DENSITY,
            temperature_c: 12.0,
            validity: DepthV1::VALID_DEPTH
                | DepthV1::VALID_PRESSURE
                | DepthV1::VALID_TEMPERATURE
                | DepthV1::VALID_DEVICE_TIME,
        }
    }
}

/// Magnetometer: Earth field (declination, inclination, intensity), soft and hard iron, noise.
pub struct MagnetometerModel {
    rng: Rng,
    e: Effects,
    sequence: u64,
}

impl MagnetometerModel {
    /// The Earth field (µT, NED) of `mag.declination`, `mag.inclination`, `mag.intensity`.
    pub fn field_ned_ut(e: &Effects) -> Vector3<f64> {
        let (dec, inc) = (
            e.mag_declination.to_radians(),
            e.mag_inclination.to_radians(),
        );
        e.mag_intensity * Vector3::new(inc.cos() * dec.cos(), inc.cos() * dec.sin(), inc.sin())
    }

    /// What a noise-free magnetometer reads (µT, sensor axes) in an attitude: soft iron, then
    /// hard iron, on the body field. Model discovery uses the same code.
    pub fn reading(e: &Effects, c_body_to_ned: &Matrix3<f64>) -> Vector3<f64> {
        Matrix3::from_row_slice(&e.mag_soft_iron)
            * (c_body_to_ned.transpose() * MagnetometerModel::field_ned_ut(e))
            + Vector3::from(e.mag_hard_iron)
    }

    /// The body field (µT) a reading `h` implies under the effects' soft and hard iron: the
    /// inverse of [`MagnetometerModel::reading`]; None when the soft iron is singular.
    pub fn body_field(e: &Effects, h: &Vector3<f64>) -> Option<Vector3<f64>> {
        let s = Matrix3::from_row_slice(&e.mag_soft_iron).try_inverse()?;
        Some(s * (h - Vector3::from(e.mag_hard_iron)))
    }

    pub fn new(e: &Effects, seed: u64) -> MagnetometerModel {
        MagnetometerModel {
            rng: Rng::new(seed, "magnetometer"),
            e: e.clone(),
            sequence: 0,
        }
    }

    /// The navigator's magnetometer configuration that matches these effects: the simulated
    /// hard and soft iron as a perfect calibration, and the simulated declination and intensity
    /// in place of the field model.
    pub fn navigator_config(e: &Effects) -> MagnetometerConfig {
        MagnetometerConfig {
            hard_iron_ut: e.mag_hard_iron,
            soft_iron: e.mag_soft_iron,
            declination_deg: Some(e.mag_declination),
            intensity_ut: Some(e.mag_intensity),
            source: "the simulator's magnetometer effects".into(),
            ..Default::default()
        }
    }

    pub fn sample(&mut self, t: f64, truth: &TruthSample) -> MagnetometerV1 {
        let r = &mut self.rng;
        let sigma = self.e.mag_noise;
        let noise = Vector3::new(r.gauss(sigma), r.gauss(sigma), r.gauss(sigma));
        let m = MagnetometerModel::reading(&self.e, &truth.c_body_to_ned) + noise;
        self.sequence += 1;
        MagnetometerV1 {
            host_time_ns: ns(t),
            device_time_ns: ns(t),
            sequence: self.sequence,
            field_t: (m * 1e-6).into(),
            temperature_c: 20.0,
            validity: MagnetometerV1::VALID_FIELD
                | MagnetometerV1::VALID_TEMPERATURE
                | MagnetometerV1::VALID_DEVICE_TIME,
        }
    }
}

/// Surface GNSS: fixes only while the antenna is above water (depth below 0.5 m).
pub struct GnssModel {
    rng: Rng,
    noise_m: f64,
    sequence: u64,
}

/// Depth above which the GNSS antenna is out of the water (m).
pub const GNSS_MAX_DEPTH_M: f64 = 0.5;

impl GnssModel {
    pub fn new(e: &Effects, seed: u64) -> GnssModel {
        GnssModel {
            rng: Rng::new(seed, "gnss"),
            noise_m: e.gnss_noise,
            sequence: 0,
        }
    }

    pub fn sample(&mut self, t: f64, truth: &TruthSample) -> Option<GnssFixV1> {
        if -truth.position.height_m > GNSS_MAX_DEPTH_M {
            return None;
        }
        let d = Vector3::new(
            self.rng.gauss(self.noise_m),
            self.rng.gauss(self.noise_m),
            0.0,
        );
        let p = earth::offset_position(&truth.position, &d);
        self.sequence += 1;
        Some(GnssFixV1 {
            host_time_ns: ns(t),
            device_time_ns: ns(t),
            sequence: self.sequence,
            latitude_rad: p.latitude_rad,
            longitude_rad: p.longitude_rad,
            height_m: p.height_m,
            velocity_ned_m_s: truth.velocity_ned.into(),
            horizontal_std_m: self.noise_m.max(0.01),
            vertical_std_m: 2.0 * self.noise_m.max(0.01),
            satellites: 10,
            validity: GnssFixV1::VALID_POSITION
                | GnssFixV1::VALID_HEIGHT
                | GnssFixV1::VALID_VELOCITY,
        })
    }
}
