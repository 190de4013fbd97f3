//! The IMU against the reference motion: over each interval between reference samples at least
//! [`IMU_INTERVAL_S`] apart, the gyro's rotation and the accelerometer's velocity increment
//! (rotated into the local level frame with the reference attitude at each sample) are
//! integrated and compared with the reference's own change of attitude and velocity, gravity and
//! the Coriolis term taken out. Integrating over the interval keeps the comparison exact for a
//! perfect IMU (no coning or sculling approximation in the nominal residual) and averages the
//! IMU noise; the effects act on the interval-mean rate and specific force as the simulator's
//! `ImuModel::gyro_reading` and `accel_reading` do.

use super::{Channel, ChannelKind, Reference};
use auvnav_core::earth;
use auvnav_sim::sensors::{DEG_PER_H, MICRO_G};
use nalgebra::{Rotation3, UnitQuaternion, Vector3};

/// Shortest interval the IMU is integrated over (s).
pub const IMU_INTERVAL_S: f64 = 1.0;

/// Fraction of an interval the IMU samples must cover for it to be compared.
const COVERAGE: f64 = 0.98;

/// One IMU sample: the end of its interval, its length, and the rate and specific force it
/// averages over it (None where the sample flags them not valid).
#[derive(Debug, Clone, Copy)]
pub struct ImuSample {
    pub t_end_s: f64,
    pub dt_s: f64,
    pub rate: Option<Vector3<f64>>,
    pub force: Option<Vector3<f64>>,
}

/// The gyro and accelerometer channels of `samples` (sorted by time) against `reference`:
/// per interval, the value is the reference's mean rate (deg/h) or specific force (µg) in body
/// axes at the interval's middle plus the integrated measurement error, and the channel's
/// `auxiliary` holds the reference's mean alone (what the effects act on).
pub fn imu_channels(samples: &[ImuSample], reference: &Reference) -> (Channel, Channel) {
    let mut gyro = Channel::new(ChannelKind::Gyro);
    let mut accel = Channel::new(ChannelKind::Accelerometer);
    let times = reference.times();
    if samples.is_empty() || times.len() < 2 {
        return (gyro, accel);
    }
    let mut first = 0; // first sample that may overlap the current interval
    let mut a = 0;
    while a + 1 < times.len() {
        let ta = times[a];
        let mut b = a + 1;
        while b < times.len() && times[b] - ta < IMU_INTERVAL_S && times[b] - times[b - 1] <= 1.0 {
            b += 1;
        }
        if b >= times.len() {
            break;
        }
        if times[b] - times[b - 1] > 1.0 {
            // A gap in the reference: start again after it.
            a = b;
            continue;
        }
        let tb = times[b];
        while first < samples.len() && samples[first].t_end_s <= ta {
            first += 1;
        }
        match increment(&samples[first..], reference, ta, tb) {
            Some((g, f)) => {
                let t = 0.5 * (ta + tb);
                match g {
                    Some((z, r)) => gyro.push_imu(t, z, r),
                    None => gyro.skipped += 1,
                }
                match f {
                    Some((z, r)) => accel.push_imu(t, z, r),
                    None => accel.skipped += 1,
                }
            }
            None => {
                gyro.skipped += 1;
                accel.skipped += 1;
            }
        }
        a = b;
    }
    (gyro, accel)
}

type Pair = (Vector3<f64>, Vector3<f64>);

/// The gyro and accelerometer comparison over [ta, tb]: (measured, reference) mean rate in
/// deg/h and mean specific force in µg, body axes at the middle. None without the reference at
/// both ends; a component is None when its samples do not cover the interval.
#[allow(clippy::type_complexity)]
fn increment(
    samples: &[ImuSample],
    reference: &Reference,
    ta: f64,
    tb: f64,
) -> Option<(Option<Pair>, Option<Pair>)> {
    let ra = reference.at(ta)?;
    let rb = reference.at(tb)?;
    let rm = reference.at(0.5 * (ta + tb))?;
    let span = tb - ta;
    // Gyro: the body's rotation w.r.t. the local level frame, integrated from the rates with
    // the frame's own rotation taken out, against the reference's.
    let mut q = UnitQuaternion::identity();
    let (mut gyro_cover, mut accel_cover) = (0.0, 0.0);
    // Accelerometer: the specific force integrated in the local level frame.
    let mut f_ned = Vector3::zeros();
    let mut gravity = Vector3::zeros();
    let mut coriolis = Vector3::zeros();
    for s in samples {
        let start = s.t_end_s - s.dt_s;
        if start >= tb {
            break;
        }
        let (lo, hi) = (start.max(ta), s.t_end_s.min(tb));
        let w = hi - lo;
        if w <= 0.0 {
            continue;
        }
        let r = reference.at(0.5 * (lo + hi))?;
        let w_ie = earth::earth_rate_ned(r.latitude_rad);
        let w_en = earth::transport_rate_ned(r.latitude_rad, r.height_m, &r.velocity_ned);
        let c_nb = r.c_body_to_ned.transpose();
        if let Some(rate) = s.rate {
            q *= UnitQuaternion::from_scaled_axis((rate - c_nb * (w_ie + w_en)) * w);
            gyro_cover += w;
        }
        if let Some(f) = s.force {
            f_ned += r.c_body_to_ned * f * w;
            gravity += earth::gravity_ned(r.latitude_rad, r.height_m) * w;
            coriolis += (2.0 * w_ie + w_en).cross(&r.velocity_ned) * w;
            accel_cover += w;
        }
    }
    let c_mid_nb = rm.c_body_to_ned.transpose();
    let gyro = (gyro_cover >= COVERAGE * span).then(|| {
        let rot_ref =
            Rotation3::from_matrix_unchecked(ra.c_body_to_ned.transpose() * rb.c_body_to_ned);
        let q_ref = UnitQuaternion::from_rotation_matrix(&rot_ref);
        // The integrated error is in the body axes at the end of the interval; in the axes at
        // its middle, errors accumulated before and after the middle rotate by opposite angles,
        // so a bias does not leak into the other axes in proportion to the turn rate.
        let error = c_mid_nb * rb.c_body_to_ned * (q_ref.inverse() * q).scaled_axis() / span;
        let w_ie = earth::earth_rate_ned(rm.latitude_rad);
        let w_en = earth::transport_rate_ned(rm.latitude_rad, rm.height_m, &rm.velocity_ned);
        let reference_rate = q_ref.scaled_axis() / span + c_mid_nb * (w_ie + w_en);
        (
            (reference_rate + error) / DEG_PER_H,
            reference_rate / DEG_PER_H,
        )
    });
    let accel = (accel_cover >= COVERAGE * span).then(|| {
        // Scale the level-frame terms to the covered time (a sample short at an edge).
        let k = span / accel_cover;
        let expected = rb.velocity_ned - ra.velocity_ned - gravity * k + coriolis * k;
        let measured = f_ned * k;
        (
            c_mid_nb * measured / span / MICRO_G,
            c_mid_nb * expected / span / MICRO_G,
        )
    });
    Some((gyro, accel))
}

/// Allan deviation of evenly spaced values `y` (spacing `tau0_s`), overlapping estimator, at
/// cluster times tau0 × 1, 2, 4 … while at least 9 clusters fit.
pub fn allan_deviation(y: &[f64], tau0_s: f64) -> Vec<(f64, f64)> {
    let n = y.len();
    let mut cumulative = Vec::with_capacity(n + 1);
    cumulative.push(0.0);
    for v in y {
        cumulative.push(cumulative.last().copied().unwrap_or(0.0) + v);
    }
    let mut out = Vec::new();
    let mut m = 1;
    while n >= 9 * m {
        let mean = |k: usize| (cumulative[k + m] - cumulative[k]) / m as f64;
        let count = n - 2 * m + 1;
        let sum: f64 = (0..count).map(|k| (mean(k + m) - mean(k)).powi(2)).sum();
        out.push((m as f64 * tau0_s, (sum / (2.0 * count as f64)).sqrt()));
        m *= 2;
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn allan_deviation_of_white_noise_falls_as_one_over_root_tau() {
        let mut rng = auvnav_sim::rng::Rng::new(5, "allan");
        let y: Vec<f64> = (0..20_000).map(|_| rng.gauss(1.0)).collect();
        let a = allan_deviation(&y, 1.0);
        for (tau, s) in &a[..6] {
            let expected = 1.0 / tau.sqrt();
            assert!(
                (s / expected - 1.0).abs() < 0.15,
                "tau {tau}: {s} vs {expected}"
            );
        }
        // A constant offset does not show; a ramp does at long clusters.
        let ramp: Vec<f64> = (0..4096).map(|k| 1e-3 * k as f64).collect();
        let a = allan_deviation(&ramp, 1.0);
        assert!(a[0].1 < a[a.len() - 1].1);
    }
}
