//! Measurement updates of an error state for nonlinear measurements: the unscented update (sigma
//! points, parameters named in [`UnscentedParams`]), which equals the Kalman update when the
//! measurement is linear, and the linearised update (numerical Jacobian, Joseph form) with the
//! same interface. Used by the USBL aid over every state with non-zero variance.

use nalgebra::{DMatrix, DVector};

/// Sigma-point parameters of the unscented transform: spread α (0 < α ≤ 1), prior-knowledge β
/// (2 is optimal for Gaussians), secondary scaling κ (usually 0).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct UnscentedParams {
    pub alpha: f64,
    pub beta: f64,
    pub kappa: f64,
}

impl Default for UnscentedParams {
    fn default() -> Self {
        UnscentedParams {
            alpha: 0.5,
            beta: 2.0,
            kappa: 0.0,
        }
    }
}

/// The result of a measurement update (unscented or linearised).
#[derive(Debug, Clone)]
pub struct MeasurementUpdate {
    /// The estimated error state (to feed back).
    pub dx: DVector<f64>,
    /// The updated covariance.
    pub p: DMatrix<f64>,
    /// Innovation z − ẑ and its covariance.
    pub innovation: DVector<f64>,
    pub innovation_cov: DMatrix<f64>,
}

/// Updates an error state (mean zero, covariance `p`) with measurement `z` (noise covariance
/// `r`), where `h(δx)` predicts the measurement for the nominal state corrected by δx. `None` when
/// a covariance is not positive definite.
pub fn unscented_update(
    p: &DMatrix<f64>,
    z: &DVector<f64>,
    r: &DMatrix<f64>,
    h: &dyn Fn(&DVector<f64>) -> DVector<f64>,
    params: UnscentedParams,
) -> Option<MeasurementUpdate> {
    let n = p.nrows();
    let m = z.len();
    let nf = n as f64;
    let lambda = params.alpha * params.alpha * (nf + params.kappa) - nf;
    let scaled = p * (nf + lambda);
    let l = scaled.cholesky()?.l();
    let wm0 = lambda / (nf + lambda);
    let wc0 = wm0 + 1.0 - params.alpha * params.alpha + params.beta;
    let wi = 1.0 / (2.0 * (nf + lambda));
    // Sigma points: 0, +columns, −columns.
    let mut points = Vec::with_capacity(2 * n + 1);
    points.push(DVector::zeros(n));
    for i in 0..n {
        points.push(l.column(i).into_owned());
    }
    for i in 0..n {
        points.push(-l.column(i).into_owned());
    }
    let zs: Vec<DVector<f64>> = points.iter().map(h).collect();
    let weight_m = |k: usize| if k == 0 { wm0 } else { wi };
    let weight_c = |k: usize| if k == 0 { wc0 } else { wi };
    let mut z_mean = DVector::zeros(m);
    for (k, zk) in zs.iter().enumerate() {
        z_mean += zk * weight_m(k);
    }
    let mut s = r.clone();
    let mut pxz = DMatrix::zeros(n, m);
    for (k, (xk, zk)) in points.iter().zip(&zs).enumerate() {
        let dz = zk - &z_mean;
        s += &dz * dz.transpose() * weight_c(k);
        pxz += xk * dz.transpose() * weight_c(k);
    }
    let s_inv = s.clone().try_inverse()?;
    let k = &pxz * &s_inv;
    let innovation = z - &z_mean;
    let dx = &k * &innovation;
    let mut p_new = p - &k * &s * k.transpose();
    p_new = (&p_new + p_new.transpose()) * 0.5;
    Some(MeasurementUpdate {
        dx,
        p: p_new,
        innovation,
        innovation_cov: s,
    })
}

/// Numerical Jacobian of `h` at δx = 0 (central differences of `step`), for the linearised
/// (adaptive KF) update.
pub fn jacobian(
    n: usize,
    m: usize,
    h: &dyn Fn(&DVector<f64>) -> DVector<f64>,
    step: f64,
) -> DMatrix<f64> {
    let mut jac = DMatrix::zeros(m, n);
    let mut dx = DVector::zeros(n);
    for j in 0..n {
        dx[j] = step;
        let plus = h(&dx);
        dx[j] = -step;
        let minus = h(&dx);
        dx[j] = 0.0;
        jac.set_column(j, &((plus - minus) / (2.0 * step)));
    }
    jac
}

/// The linearised Kalman update with the same interface as [`unscented_update`]: `h` is
/// linearised at δx = 0 by [`jacobian`]; Joseph form.
pub fn linearized_update(
    p: &DMatrix<f64>,
    z: &DVector<f64>,
    r: &DMatrix<f64>,
    h: &dyn Fn(&DVector<f64>) -> DVector<f64>,
) -> Option<MeasurementUpdate> {
    let n = p.nrows();
    let m = z.len();
    let hj = jacobian(n, m, h, 1e-3);
    let s = &hj * p * hj.transpose() + r;
    let s_inv = s.clone().try_inverse()?;
    // The innovation is z − h(0); h(δx) ≈ h(0) + H δx, so the gain maps it with the sign of H.
    let k = p * hj.transpose() * &s_inv;
    let innovation = z - h(&DVector::zeros(n));
    let dx = &k * &innovation;
    let ikh = DMatrix::identity(n, n) - &k * &hj;
    let mut p_new = &ikh * p * ikh.transpose() + &k * r * k.transpose();
    p_new = (&p_new + p_new.transpose()) * 0.5;
    Some(MeasurementUpdate {
        dx,
        p: p_new,
        innovation,
        innovation_cov: s,
    })
}
