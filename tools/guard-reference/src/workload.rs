//! The guard's reference workload ([`reference_workload`]): fixed code whose time follows the
//! machine, never the project's, so that a build's time divided by it can be compared across
//! runs and days. Frozen: the baselines in `tools/cli/guard-baseline.json` are ratios to it, and
//! any change here (or to this program's build) needs every baseline measured again (`auvnav
//! bench guard --write-baseline`).

/// The fixed reference workload for `hours` of a 200 Hz log. Frozen: the guard's baselines are
/// ratios to it, so any change to it (or to its constants) needs every baseline measured again.
/// Returns a value that depends on every step, so that nothing is optimised away.
pub fn reference_workload(hours: f64) -> f64 {
    // Written with `while` loops over indices and fixed-size arrays only: no iterator, no
    // collection, no generic function of another crate in the loop, so that how the dev build
    // splits and shares generic code (which changes with what other crates instantiate, and
    // made this workload's time change 5-fold between two builds of the same source) cannot
    // change its speed.
    let samples = (hours * 3600.0 * 200.0) as usize;
    // Strapdown: a quaternion advanced by a small rotation per sample.
    let mut q = [1.0f64, 0.0, 0.0, 0.0];
    let mut v = [0.0f64; 3];
    let mut p = [0.0f64; 3];
    // Covariance: 28 states, the 9 navigation rows of the transition differing from identity.
    const N: usize = 28;
    let mut cov = [[0.0f64; N]; N];
    let mut i = 0;
    while i < N {
        cov[i][i] = 1.0 + i as f64 * 0.01;
        i += 1;
    }
    let mut phi = [[0.0f64; N]; 9];
    let mut i = 0;
    while i < 9 {
        let mut j = 0;
        while j < N {
            phi[i][j] = if i == j {
                1.0
            } else {
                1e-3 / (1.0 + (i + j) as f64)
            };
            j += 1;
        }
        i += 1;
    }
    // Bytes: a checksum over 50 bytes per sample, as reading a log does.
    const BYTES: usize = 4096;
    let mut bytes = [0u8; BYTES];
    let mut i = 0;
    while i < BYTES {
        bytes[i] = ((i as u32).wrapping_mul(2_654_435_761) >> 24) as u8;
        i += 1;
    }
    let mut crc = 0xffff_ffffu32;
    let mut at = 0usize;
    let mut k = 0;
    while k < samples {
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
        q = [q[0] / n, q[1] / n, q[2] / n, q[3] / n];
        let lat = 0.6 + p[0] * 1.6e-7;
        let sl = lat.sin();
        let g = 9.780_325 * (1.0 + 0.001_93 * sl * sl) / (1.0 - 0.006_69 * sl * sl).sqrt();
        let mut i = 0;
        while i < 3 {
            v[i] += (q[i + 1] * 0.1 - if i == 2 { g - 9.8 } else { 0.0 }) * 0.005;
            p[i] += v[i] * 0.005;
            i += 1;
        }
        let mut b = 0;
        while b < 50 {
            crc ^= bytes[at] as u32;
            at = (at + 1) % BYTES;
            let mut bit = 0;
            while bit < 8 {
                crc = if crc & 1 != 0 {
                    (crc >> 1) ^ 0xedb8_8320
                } else {
                    crc >> 1
                };
                bit += 1;
            }
            b += 1;
        }
        if k % 10 == 9 {
            // P ← Φ P Φᵀ + Q on the 9 rows and columns Φ changes.
            let mut fp = [[0.0f64; N]; 9];
            let mut i = 0;
            while i < 9 {
                let mut j = 0;
                while j < N {
                    let mut acc = 0.0;
                    let mut m = 0;
                    while m < N {
                        acc += phi[i][m] * cov[m][j];
                        m += 1;
                    }
                    fp[i][j] = acc;
                    j += 1;
                }
                i += 1;
            }
            let mut i = 0;
            while i < 9 {
                let mut j = 0;
                while j < N {
                    let mut acc = 0.0;
                    let mut m = 0;
                    while m < N {
                        acc += fp[i][m]
                            * if j < 9 {
                                phi[j][m]
                            } else if m == j {
                                1.0
                            } else {
                                0.0
                            };
                        m += 1;
                    }
                    cov[i][j] = acc + if i == j { 1e-9 } else { 0.0 };
                    cov[j][i] = cov[i][j];
                    j += 1;
                }
                i += 1;
            }
        }
        k += 1;
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
