//! Trajectory generation on the WGS-84 rotating Earth.
//!
//! The vehicle flies without sideslip or angle of attack: its velocity is `u` along body x, so
//! `v_ned = u [cos(pitch) cos(yaw), cos(pitch) sin(yaw), -sin(pitch)]`. Speed, yaw, pitch and roll
//! follow closed-form functions of time: each manoeuvre is a set of raised-cosine rate pulses
//! (`rate = total/T (1 - cos(2 pi s))`, `s = (t - t0)/T`), so angles, speed and their rates are
//! exact and continuous at any time. Position is integrated from the velocity with RK4 at the IMU
//! rate. The ideal IMU outputs follow from the kinematics by inverse strapdown:
//! `omega_ib^b = omega_nb^b + C_n^b (omega_ie^n + omega_en^n)` and
//! `f^b = C_n^b (dv/dt + (2 omega_ie^n + omega_en^n) x v - g^n)`.

use super::scenario::{Leg, Scenario};
use auvnav_core::earth::{self, Geodetic};
use nalgebra::{Matrix3, UnitQuaternion, Vector3};
use std::f64::consts::TAU;

#[derive(Debug, Clone, Copy, PartialEq)]
enum Channel {
    Speed,
    Roll,
    Pitch,
    Yaw,
}

#[derive(Debug, Clone, Copy)]
struct Pulse {
    channel: Channel,
    t0: f64,
    duration: f64,
    total: f64,
}

impl Pulse {
    /// (integral since t0, rate) at time t.
    fn eval(&self, t: f64) -> (f64, f64) {
        if t <= self.t0 {
            return (0.0, 0.0);
        }
        if t >= self.t0 + self.duration {
            return (self.total, 0.0);
        }
        let s = (t - self.t0) / self.duration;
        let integral = self.total * (s - (TAU * s).sin() / TAU);
        let rate = self.total / self.duration * (1.0 - (TAU * s).cos());
        (integral, rate)
    }
}

/// Speed, attitude and their rates at one instant.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Kinematics {
    pub speed_m_s: f64,
    pub speed_rate_m_s2: f64,
    /// Roll, pitch, yaw (rad).
    pub euler_rad: [f64; 3],
    /// Their time derivatives (rad/s).
    pub euler_rate_rad_s: [f64; 3],
}

impl Kinematics {
    /// Rotation body FRD → NED.
    pub fn c_body_to_ned(&self) -> Matrix3<f64> {
        let [r, p, y] = self.euler_rad;
        *UnitQuaternion::from_euler_angles(r, p, y)
            .to_rotation_matrix()
            .matrix()
    }

    pub fn quaternion_body_to_ned(&self) -> UnitQuaternion<f64> {
        let [r, p, y] = self.euler_rad;
        UnitQuaternion::from_euler_angles(r, p, y)
    }

    /// Velocity w.r.t. the Earth in NED (m/s).
    pub fn velocity_ned(&self) -> Vector3<f64> {
        let [_, p, y] = self.euler_rad;
        self.speed_m_s * Vector3::new(p.cos() * y.cos(), p.cos() * y.sin(), -p.sin())
    }

    /// Time derivative of the NED velocity (m/s^2).
    pub fn acceleration_ned(&self) -> Vector3<f64> {
        let [_, p, y] = self.euler_rad;
        let [_, pd, yd] = self.euler_rate_rad_s;
        let d = Vector3::new(p.cos() * y.cos(), p.cos() * y.sin(), -p.sin());
        let dd = Vector3::new(
            -p.sin() * pd * y.cos() - p.cos() * y.sin() * yd,
            -p.sin() * pd * y.sin() + p.cos() * y.cos() * yd,
            -p.cos() * pd,
        );
        self.speed_rate_m_s2 * d + self.speed_m_s * dd
    }

    /// Angular rate of the body w.r.t. NED, in body axes (rad/s), from the ZYX Euler rates.
    pub fn omega_nb_body(&self) -> Vector3<f64> {
        let [r, p, _] = self.euler_rad;
        let [rd, pd, yd] = self.euler_rate_rad_s;
        Vector3::new(
            rd - yd * p.sin(),
            pd * r.cos() + yd * r.sin() * p.cos(),
            -pd * r.sin() + yd * r.cos() * p.cos(),
        )
    }
}

/// The true state at one instant, with the ideal IMU outputs.
#[derive(Debug, Clone, Copy)]
pub struct TruthSample {
    pub time_s: f64,
    pub position: Geodetic,
    pub kin: Kinematics,
    pub c_body_to_ned: Matrix3<f64>,
    pub velocity_ned: Vector3<f64>,
    /// Angular rate w.r.t. inertial space, body axes (rad/s).
    pub omega_ib_body: Vector3<f64>,
    /// Angular rate w.r.t. the Earth, body axes (rad/s).
    pub omega_eb_body: Vector3<f64>,
    /// Specific force, body axes (m/s^2).
    pub specific_force_body: Vector3<f64>,
}

#[derive(Debug, thiserror::Error)]
pub enum TrajectoryError {
    #[error("legs[{leg}]: a depth change needs forward speed (the vehicle is stopped)")]
    DepthChangeWhileStopped { leg: usize },
}

/// A compiled scenario trajectory.
#[derive(Debug, Clone)]
pub struct Trajectory {
    pulses: Vec<Pulse>,
    initial_speed: f64,
    initial_euler: [f64; 3],
    pub start: Geodetic,
    pub duration_s: f64,
}

/// Average pitch rate while pitching into and out of a depth change (rad/s).
const PITCH_RAMP_RATE: f64 = 2.0 * std::f64::consts::PI / 180.0;
/// Minimum duration of a pitch ramp (s).
const MIN_PITCH_RAMP_S: f64 = 2.0;

impl Trajectory {
    pub fn from_scenario(s: &Scenario) -> Result<Trajectory, TrajectoryError> {
        let start = Geodetic {
            latitude_rad: s.start.latitude_deg.to_radians(),
            longitude_rad: s.start.longitude_deg.to_radians(),
            height_m: -s.start.depth_m,
        };
        let mut pulses = Vec::new();
        let mut t = 0.0;
        let mut speed = s.start.speed_m_s;
        for (i, leg) in s.legs.iter().enumerate() {
            match *leg {
                Leg::Straight { duration_s } => t += duration_s,
                Leg::Turn {
                    angle_deg,
                    rate_deg_s,
                    bank_deg,
                } => {
                    let dur = angle_deg.abs() / rate_deg_s;
                    pulses.push(Pulse {
                        channel: Channel::Yaw,
                        t0: t,
                        duration: dur,
                        total: angle_deg.to_radians(),
                    });
                    if bank_deg != 0.0 {
                        pulses.push(Pulse {
                            channel: Channel::Roll,
                            t0: t,
                            duration: dur / 4.0,
                            total: bank_deg.to_radians(),
                        });
                        pulses.push(Pulse {
                            channel: Channel::Roll,
                            t0: t + 0.75 * dur,
                            duration: dur / 4.0,
                            total: -bank_deg.to_radians(),
                        });
                    }
                    t += dur;
                }
                Leg::Depth {
                    change_m,
                    pitch_deg,
                } => {
                    if speed <= 0.0 {
                        return Err(TrajectoryError::DepthChangeWhileStopped { leg: i });
                    }
                    if change_m == 0.0 {
                        continue;
                    }
                    // Diving (positive change) needs nose down: negative pitch.
                    let mut pitch = -change_m.signum() * pitch_deg.to_radians();
                    let ramp = (pitch.abs() / PITCH_RAMP_RATE).max(MIN_PITCH_RAMP_S);
                    let ramp_depth = |pitch: f64| {
                        let p = Pulse {
                            channel: Channel::Pitch,
                            t0: 0.0,
                            duration: ramp,
                            total: pitch,
                        };
                        // Simpson's rule over the ramp of the depth rate -u sin(theta).
                        let n = 200;
                        let h = ramp / n as f64;
                        let mut acc = 0.0;
                        for k in 0..=n {
                            let w = if k == 0 || k == n {
                                1.0
                            } else if k % 2 == 1 {
                                4.0
                            } else {
                                2.0
                            };
                            acc += w * (-speed * p.eval(k as f64 * h).0.sin());
                        }
                        acc * h / 3.0
                    };
                    let mut ramps = 2.0 * ramp_depth(pitch);
                    if ramps.abs() > change_m.abs() {
                        // The ramps alone overshoot: lower the pitch so they make the change.
                        pitch *= change_m.abs() / ramps.abs();
                        ramps = 2.0 * ramp_depth(pitch);
                    }
                    let hold = ((change_m - ramps) / (-speed * pitch.sin())).max(0.0);
                    pulses.push(Pulse {
                        channel: Channel::Pitch,
                        t0: t,
                        duration: ramp,
                        total: pitch,
                    });
                    pulses.push(Pulse {
                        channel: Channel::Pitch,
                        t0: t + ramp + hold,
                        duration: ramp,
                        total: -pitch,
                    });
                    t += 2.0 * ramp + hold;
                }
                Leg::Speed {
                    target_m_s,
                    accel_m_s2,
                } => {
                    let dv = target_m_s - speed;
                    if dv != 0.0 {
                        let dur = dv.abs() / accel_m_s2;
                        pulses.push(Pulse {
                            channel: Channel::Speed,
                            t0: t,
                            duration: dur,
                            total: dv,
                        });
                        t += dur;
                    }
                    speed = target_m_s;
                }
            }
        }
        Ok(Trajectory {
            pulses,
            initial_speed: s.start.speed_m_s,
            initial_euler: [0.0, 0.0, s.start.heading_deg.to_radians()],
            start,
            duration_s: t,
        })
    }

    /// Speed, attitude and rates at time t (s), exact.
    pub fn kinematics(&self, t: f64) -> Kinematics {
        let mut k = Kinematics {
            speed_m_s: self.initial_speed,
            speed_rate_m_s2: 0.0,
            euler_rad: self.initial_euler,
            euler_rate_rad_s: [0.0; 3],
        };
        for p in &self.pulses {
            if t <= p.t0 {
                continue;
            }
            let (integral, rate) = p.eval(t);
            match p.channel {
                Channel::Speed => {
                    k.speed_m_s += integral;
                    k.speed_rate_m_s2 += rate;
                }
                Channel::Roll => {
                    k.euler_rad[0] += integral;
                    k.euler_rate_rad_s[0] += rate;
                }
                Channel::Pitch => {
                    k.euler_rad[1] += integral;
                    k.euler_rate_rad_s[1] += rate;
                }
                Channel::Yaw => {
                    k.euler_rad[2] += integral;
                    k.euler_rate_rad_s[2] += rate;
                }
            }
        }
        // Rounding can leave a stopped vehicle at -1e-17 m/s.
        if k.speed_m_s.abs() < 1e-12 {
            k.speed_m_s = 0.0;
        }
        k
    }

    /// The full truth at time t for a given position.
    pub fn truth(&self, t: f64, position: Geodetic) -> TruthSample {
        let kin = self.kinematics(t);
        let c_bn = kin.c_body_to_ned();
        let c_nb = c_bn.transpose();
        let v = kin.velocity_ned();
        let lat = position.latitude_rad;
        let w_ie = earth::earth_rate_ned(lat);
        let w_en = earth::transport_rate_ned(lat, position.height_m, &v);
        let w_nb_b = kin.omega_nb_body();
        let f_n = kin.acceleration_ned() + (2.0 * w_ie + w_en).cross(&v)
            - earth::gravity_ned(lat, position.height_m);
        TruthSample {
            time_s: t,
            position,
            kin,
            c_body_to_ned: c_bn,
            velocity_ned: v,
            omega_ib_body: w_nb_b + c_nb * (w_ie + w_en),
            omega_eb_body: w_nb_b + c_nb * w_en,
            specific_force_body: c_nb * f_n,
        }
    }

    /// Advances a position by one RK4 step from t to t + dt.
    pub fn step_position(&self, p: Geodetic, t: f64, dt: f64) -> Geodetic {
        let rates = |p: &Geodetic, t: f64| {
            earth::position_rates(
                p.latitude_rad,
                p.height_m,
                &self.kinematics(t).velocity_ned(),
            )
        };
        let add = |p: &Geodetic, d: &Vector3<f64>, s: f64| Geodetic {
            latitude_rad: p.latitude_rad + d.x * s,
            longitude_rad: p.longitude_rad + d.y * s,
            height_m: p.height_m + d.z * s,
        };
        let k1 = rates(&p, t);
        let k2 = rates(&add(&p, &k1, dt / 2.0), t + dt / 2.0);
        let k3 = rates(&add(&p, &k2, dt / 2.0), t + dt / 2.0);
        let k4 = rates(&add(&p, &k3, dt), t + dt);
        let d = (k1 + 2.0 * k2 + 2.0 * k3 + k4) / 6.0;
        add(&p, &d, dt)
    }
}
