//! The guard's reference workload ([`reference_workload`]): fixed code whose time follows the
//! machine, never the project's, so that a build's time divided by it can be compared across
//! runs and days. Frozen: the baselines in `tools/cli/guard-baseline.json` are ratios to it, and
//! any change here needs every baseline measured again (`auvnav bench guard --write-baseline`).

/// The fixed reference workload for `hours` of a 200 Hz log. Frozen: the guard's baselines are
/// ratios to it, so any change to it (or to its constants) needs every baseline measured again.
/// Returns a value that depends on every step, so that nothing is optimised away.
pub fn reference_workload(hours: f64) -> f64 {
    let samples = (hours * 3600.0 * 200.0) as usize;
    // Strapdown: a quaternion advanced by a small rotation per sample.
    let mut q = [1.0f64, 0.0, 0.0, 0.0];
    let mut v = [0.0f64; 3];
    let mut p = [0.0f64; 3];
    // Covariance: 28 states, the 9 navigation rows of the transition differing from identity.
    const N: usize = 28;
    let mut cov = [[0.0f64; N]; N];
    for (i, row) in cov.iter_mut().enumerate() {
        row[i] = 1.0 + i as f64 * 0.01;
    }
    let mut phi = [[0.0f64; N]; 9];
    for (i, row) in phi.iter_mut().enumerate() {
        for (j, x) in row.iter_mut().enumerate() {
            *x = if i == j {
                1.0
            } else {
                1e-3 / (1.0 + (i + j) as f64)
            };
        }
    }
    // Bytes: a checksum over 50 bytes per sample, as reading a log does.
    let bytes: Vec<u8> = (0..4096u32)
        .map(|i| (i.wrapping_mul(2_654_435_761) >> 24) as u8)
        .collect();
    let mut crc = 0xffff_ffffu32;
    let mut at = 0usize;
    for k in 0..samples {
        let t = k as f64 * 0.005;
        let w = [0.01 * (0.1 * t).sin(), 0.02 * (0.07 * t).cos(), 0.005];
        let angle = (w[0] * w[0] + w[1] * w[1] + w[2] * w[2]).sqrt() * 0.005;
        let (s, c) = (angle * 0.5).sin_cos();
        let axis = if angle > 0.0 {
            s / (angle / 0.005)
        } else {
            0.0
        };
        let d = [c, w[0] * axis, w[1] * axis, w[2] * axis];
        q = [
            q[0] * d[0] - q[1] * d[1] - q[2] * d[2] - q[3] * d[3],
            q[0] * d[1] + q[1] * d[0] + q[2] * d[3] - q[3] * d[2],
            q[0] * d[2] - q[1] * d[3] + q[2] * d[0] + q[3] * d[1],
            q[0] * d[3] + q[1] * d[2] - q[2] * d[1] + q[3] * d[0],
        ];
        let n = (q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3]).sqrt();
        q.iter_mut().for_each(|x| *x /= n);
        let lat = 0.6 + p[0] * 1.6e-7;
        let g = 9.780_325 * (1.0 + 0.001_93 * lat.sin().powi(2))
            / (1.0 - 0.006_69 * lat.sin().powi(2)).sqrt();
        for i in 0..3 {
            v[i] += (q[i + 1] * 0.1 - if i == 2 { g - 9.8 } else { 0.0 }) * 0.005;
            p[i] += v[i] * 0.005;
        }
        for _ in 0..50 {
            crc ^= u32::from(bytes[at]);
            at = (at + 1) % bytes.len();
            for _ in 0..8 {
                crc = if crc & 1 != 0 {
                    (crc >> 1) ^ 0xedb8_8320
                } else {
                    crc >> 1
                };
            }
        }
        if k % 10 == 9 {
            // P ← Φ P Φᵀ + Q on the 9 rows and columns Φ changes.
            let mut fp = [[0.0f64; N]; 9];
            for i in 0..9 {
                for j in 0..N {
                    let mut acc = 0.0;
                    for (m, row) in cov.iter().enumerate() {
                        acc += phi[i][m] * row[j];
                    }
                    fp[i][j] = acc;
                }
            }
            for i in 0..9 {
                for j in 0..N {
                    let mut acc = 0.0;
                    for m in 0..N {
                        acc += fp[i][m]
                            * if j < 9 {
                                phi[j][m]
                            } else if m == j {
                                1.0
                            } else {
                                0.0
                            };
                    }
                    cov[i][j] = acc + if i == j { 1e-9 } else { 0.0 };
                    cov[j][i] = cov[i][j];
                }
            }
        }
    }
    q[0] + v[0] + p[1] + cov[3][5] + f64::from(crc)
}

#[cfg(test)]
mod tests {
    #[test]
    fn the_reference_workload_is_deterministic() {
        let a = super::reference_workload(0.001);
        assert!(a.is_finite());
        assert_eq!(a.to_bits(), super::reference_workload(0.001).to_bits());
    }
}
