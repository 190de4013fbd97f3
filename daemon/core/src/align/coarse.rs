//! Coarse initial alignment: the attitude from the IMU (and the DVL when moving), with no prior
//! heading, good enough for the fine-alignment filter to start from.
//!
//! * [`static_alignment`] — moored: the mean specific force is −g and the mean angular rate the
//!   Earth rate, both in body axes; TRIAD on (f, ω, f × ω) gives the body-to-NED rotation.
//! * [`InMotionAligner`] — moving, DVL-aided, optimisation-based ("inertial-frame") alignment.
//!   With n0 the navigation frame frozen in inertial space at the start and b0 the body frame
//!   likewise, C_b^n(t) = C_n0^n(t) · q · C_b^b0(t), where q = C_b^n(0) is the unknown constant,
//!   C_b^b0 comes from the gyros and C_n^n0 from the Earth rate. Writing u = C_n^n0 v^n =
//!   q C_b^b0 v^b and integrating the velocity equation u̇ = q C_b^b0 f^b − C_n^n0 (ω_ie × v^n) +
//!   C_n^n0 g^n from 0 to t_k gives, at every DVL epoch, a vector pair
//!   q α_k = β_k with α_k = C_b^b0(t_k) v^b(t_k) − v^b(0) − ∫ C_b^b0 f^b dτ (IMU and DVL only) and
//!   β_k = ∫ C_n^n0 (g^n − ω_ie × v^n) dτ. q is the rotation that best maps the α onto the β
//!   (Wahba's problem, solved by SVD). The Coriolis term needs v^n = C_b^n v^b, i.e. the answer:
//!   the solution is iterated with the previous estimate (the term is 1e-5 of gravity, but heading
//!   rests on the Earth's rotation of gravity, itself only Ω·t of it). For the same reason C_n^n0
//!   includes the transport rate v/R: at 2 m/s east it is 0.5 % of the horizontal Earth rate and,
//!   ignored, turns the heading by about 0.3°. The moored case is the same problem with v^b = 0, so
//!   the aligner also works at rest (without the DVL).
//!
//! Heading becomes observable as gravity turns with the Earth in n0: after t seconds the useful
//! signal is about g·Ω·t·cos L, so the accuracy improves with time; manoeuvres do not help the coarse
//! stage (they do help the fine stage). DVL mounting angles and scale are not modelled here: they
//! bias the coarse attitude by about their own size.

use crate::earth::{earth_rate_ned, gravity_ned, transport_rate_ned};
use nalgebra::{Matrix3, Rotation3, UnitQuaternion, Vector3};

/// Body-to-NED rotation from mean specific force and mean angular rate at rest, at latitude `lat`
/// (rad). `None` when the vectors are degenerate (no gravity, or rate parallel to it).
pub fn static_alignment(
    mean_f_body: &Vector3<f64>,
    mean_w_body: &Vector3<f64>,
    lat: f64,
    height_m: f64,
) -> Option<Matrix3<f64>> {
    let g_n = gravity_ned(lat, height_m);
    let f_n = -g_n;
    let w_n = earth_rate_ned(lat);
    triad(mean_f_body, mean_w_body, &f_n, &w_n)
}

/// The rotation C with C·a1 ∥ b1 exactly and C·a2 as close to b2 as possible.
fn triad(
    a1: &Vector3<f64>,
    a2: &Vector3<f64>,
    b1: &Vector3<f64>,
    b2: &Vector3<f64>,
) -> Option<Matrix3<f64>> {
    let frame = |v1: &Vector3<f64>, v2: &Vector3<f64>| -> Option<Matrix3<f64>> {
        let e1 = v1.try_normalize(1e-12)?;
        let e2 = v1.cross(v2).try_normalize(1e-12)?;
        let e3 = e1.cross(&e2);
        Some(Matrix3::from_columns(&[e1, e2, e3]))
    };
    let ma = frame(a1, a2)?;
    let mb = frame(b1, b2)?;
    Some(mb * ma.transpose())
}

/// The rotation R minimising Σ w |R a − b|² (Wahba), by SVD with the determinant fixed to +1.
pub fn wahba(pairs: &[(Vector3<f64>, Vector3<f64>, f64)]) -> Option<Matrix3<f64>> {
    let mut b = Matrix3::zeros();
    for (a, t, w) in pairs {
        b += *w * t * a.transpose();
    }
    let svd = b.svd(true, true);
    let (u, vt) = (svd.u?, svd.v_t?);
    let d = (u * vt).determinant().signum();
    let m = Matrix3::from_diagonal(&Vector3::new(1.0, 1.0, d));
    let r = u * m * vt;
    r.iter().all(|x| x.is_finite()).then_some(r)
}

/// One DVL epoch as the aligner keeps it.
#[derive(Debug, Clone, Copy)]
struct Epoch {
    t: f64,
    /// C_b^b0 at the epoch.
    c_b_b0: Matrix3<f64>,
    /// DVL velocity in body axes (m/s).
    v_b: Vector3<f64>,
    /// ∫ C_b^b0 f^b dτ up to the epoch.
    int_f: Vector3<f64>,
}

/// DVL-aided in-motion coarse alignment (also valid at rest).
#[derive(Debug, Clone)]
pub struct InMotionAligner {
    lat: f64,
    height_m: f64,
    t0: Option<f64>,
    t: f64,
    c_b_b0: Matrix3<f64>,
    int_f: Vector3<f64>,
    epochs: Vec<Epoch>,
    /// Latest velocity (body axes), held between DVL measurements.
    v_hold: Vector3<f64>,
    /// ∫ C_b^b0 v^b dτ: the path in b0 axes.
    int_v: Vector3<f64>,
    /// Epochs used as vector pairs (every one by default; more only cost time).
    pub min_epoch_spacing_s: f64,
}

impl InMotionAligner {
    /// Starts at latitude `lat` (rad) and height; the start time is the first IMU sample's.
    pub fn new(lat: f64, height_m: f64) -> Self {
        InMotionAligner {
            lat,
            height_m,
            t0: None,
            t: 0.0,
            c_b_b0: Matrix3::identity(),
            int_f: Vector3::zeros(),
            epochs: Vec::new(),
            v_hold: Vector3::zeros(),
            int_v: Vector3::zeros(),
            min_epoch_spacing_s: 1.0,
        }
    }

    /// C_b^b0: the body attitude at the latest IMU time relative to the start.
    pub fn body_to_start(&self) -> &Matrix3<f64> {
        &self.c_b_b0
    }

    /// Velocity epochs kept so far.
    pub fn epochs(&self) -> usize {
        self.epochs.len()
    }

    /// Seconds of data so far.
    pub fn elapsed_s(&self) -> f64 {
        self.t0.map_or(0.0, |t0| self.t - t0)
    }

    /// The time of the latest IMU sample (s).
    pub fn time_s(&self) -> f64 {
        self.t
    }

    /// One IMU interval ending at `t` (s): angular rate (rad/s) and specific force (m/s²) in
    /// body axes, held over `dt`.
    pub fn on_imu(&mut self, t: f64, w: &Vector3<f64>, f: &Vector3<f64>, dt: f64) {
        if self.t0.is_none() {
            self.t0 = Some(t - dt);
            self.t = t - dt;
        }
        // Midpoint rule: f rotated by half the interval's rotation.
        let half = Rotation3::new(w * (0.5 * dt)).into_inner();
        self.int_f += self.c_b_b0 * half * f * dt;
        self.int_v += self.c_b_b0 * half * self.v_hold * dt;
        self.c_b_b0 *= Rotation3::new(w * dt).into_inner();
        // Keep it orthonormal.
        self.c_b_b0 = UnitQuaternion::from_matrix(&self.c_b_b0)
            .to_rotation_matrix()
            .into_inner();
        self.t = t;
    }

    /// A velocity in body axes (the DVL's, rotated by its nominal mounting and lever-arm
    /// corrected) valid at the time of the last IMU sample; `None` (at rest without a DVL) is a
    /// zero velocity.
    pub fn on_velocity(&mut self, v_b: Option<Vector3<f64>>) {
        if self.t0.is_none() {
            return;
        }
        self.v_hold = v_b.unwrap_or_else(Vector3::zeros);
        if let Some(last) = self.epochs.last()
            && self.t - last.t < self.min_epoch_spacing_s
        {
            return;
        }
        self.epochs.push(Epoch {
            t: self.t,
            c_b_b0: self.c_b_b0,
            v_b: v_b.unwrap_or_else(Vector3::zeros),
            int_f: self.int_f,
        });
    }

    /// The body-to-NED rotation at the latest IMU time, or `None` before three epochs.
    pub fn solve(&self) -> Option<Matrix3<f64>> {
        self.solve_with_frame().map(|(c, _)| c)
    }

    /// The attitude and the distance travelled since the start (m, NED at the latest time) from
    /// the velocities given, or `None` before three epochs.
    pub fn solve_with_displacement(&self) -> Option<(Matrix3<f64>, Vector3<f64>)> {
        let (c_b_n, c_n_n0) = self.solve_with_frame()?;
        // q = C_b0^n0 = C_n^n0 · C_b^n · (C_b^b0)^T at the latest time.
        let q = c_n_n0 * c_b_n * self.c_b_b0.transpose();
        Some((c_b_n, c_n_n0.transpose() * q * self.int_v))
    }

    /// The solution and C_n^n0 at the latest epoch.
    fn solve_with_frame(&self) -> Option<(Matrix3<f64>, Matrix3<f64>)> {
        self.t0?;
        if self.epochs.len() < 3 {
            return None;
        }
        let first = self.epochs[0];
        let g_n = gravity_ned(self.lat, self.height_m);
        let w_ie = earth_rate_ned(self.lat);
        let mut q: Option<Matrix3<f64>> = None;
        let mut c_last = Matrix3::identity();
        // Three passes: the first ignores the terms that need v^n (Coriolis, and the transport
        // rate that turns the navigation frame); the later ones take v^n from the previous pass.
        for _ in 0..3 {
            let mut pairs = Vec::with_capacity(self.epochs.len());
            // C_n^n0 at the current epoch, chained from epoch to epoch.
            let mut c_n_n0 = Matrix3::<f64>::identity();
            let mut beta = Vector3::zeros();
            let mut prev: Option<(f64, Vector3<f64>, Vector3<f64>)> = None;
            for e in &self.epochs {
                let v_n = match q {
                    Some(q) => c_n_n0.transpose() * q * e.c_b_b0 * e.v_b,
                    None => Vector3::zeros(),
                };
                if let Some((tp, wp, _)) = prev {
                    // Turn the frame over the interval with the mean rate.
                    let w_in = w_ie + transport_rate_ned(self.lat, self.height_m, &v_n);
                    c_n_n0 *= Rotation3::new(0.5 * (w_in + wp) * (e.t - tp)).into_inner();
                }
                let w_in = w_ie + transport_rate_ned(self.lat, self.height_m, &v_n);
                let integrand = c_n_n0 * (g_n - w_ie.cross(&v_n));
                if let Some((tp, _, ip)) = prev {
                    beta += 0.5 * (integrand + ip) * (e.t - tp);
                }
                prev = Some((e.t, w_in, integrand));
                let alpha = e.c_b_b0 * e.v_b - first.c_b_b0 * first.v_b - (e.int_f - first.int_f);
                if alpha.norm() > 0.0 {
                    pairs.push((alpha, beta, 1.0));
                }
            }
            // The vectors all lie near −g·τ; the heading comes from their slow rotation.
            q = Some(wahba(&pairs)?);
            c_last = c_n_n0;
        }
        let q = q?;
        // From the last epoch to the last IMU sample the frame turns by less than 1e-4 rad.
        Some((c_last.transpose() * q * self.c_b_b0, c_last))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn wahba_recovers_a_rotation_and_triad_agrees() {
        let r = Rotation3::from_euler_angles(0.3, -0.2, 2.5).into_inner();
        let a = [
            Vector3::new(1.0, 0.2, -0.3),
            Vector3::new(-0.4, 1.0, 0.1),
            Vector3::new(0.3, 0.3, 1.0),
        ];
        let pairs: Vec<_> = a.iter().map(|v| (*v, r * v, 1.0)).collect();
        let w = wahba(&pairs).expect("solution");
        assert!((w - r).norm() < 1e-12);
        let t = triad(&a[0], &a[1], &(r * a[0]), &(r * a[1])).expect("triad");
        assert!((t - r).norm() < 1e-12);
    }
}
