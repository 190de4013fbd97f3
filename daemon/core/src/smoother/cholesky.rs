//! The smoother's Cholesky solve with many right-hand sides, bit for bit what nalgebra's
//! `Cholesky::solve` gives, several times faster.
//!
//! nalgebra solves one right-hand side at a time: per column an axpy per row going down and a dot
//! product per row coming back up, each a call over a short strided view. The backward pass solves
//! with as many columns as the error state has (30) at every epoch, and those calls were half of
//! its time. Here the right-hand sides are rows of one array, so every step runs along all of them
//! at once, and every element goes through the same operations in the same order as in nalgebra
//! (its forward axpy `y ← (−c)·l + y`; its dot product's eight partial sums, added in its order):
//! the same bits, which a test checks.

use nalgebra::DMatrix;

/// Largest system solved here (the error state's dimension bounds it).
pub const MAX: usize = 32;

/// Solves `L Lᵀ X = B` in place. `l` holds the factor in its lower triangle (the upper triangle
/// is not read); `b` holds `B` row by row, `cols` right-hand sides per row. `None` when the
/// system is larger than [`MAX`].
pub fn solve_rows(l: &DMatrix<f64>, b: &mut [[f64; MAX]], cols: usize) -> Option<()> {
    let n = l.nrows();
    if n > MAX || cols > MAX || b.len() < n {
        return None;
    }
    let b = &mut b[..n];
    // Down: L Y = B.
    for i in 0..n {
        let diag = l[(i, i)];
        for v in &mut b[i][..cols] {
            *v /= diag;
        }
        let (done, below) = b.split_at_mut(i + 1);
        let coeff = &done[i];
        for (k, row) in below.iter_mut().enumerate() {
            let lji = l[(i + 1 + k, i)];
            for (y, &c) in row[..cols].iter_mut().zip(&coeff[..cols]) {
                *y += -c * lji;
            }
        }
    }
    // Up: Lᵀ X = Y, each row's dot product summed as nalgebra sums it.
    for i in (0..n).rev() {
        let len = n - i - 1;
        let mut acc = [[0.0f64; MAX]; 8];
        let mut k = 0;
        while len - k >= 8 {
            for (q, a) in acc.iter_mut().enumerate() {
                let row = i + 1 + k + q;
                let lk = l[(row, i)];
                for (s, &y) in a[..cols].iter_mut().zip(&b[row][..cols]) {
                    *s += lk * y;
                }
            }
            k += 8;
        }
        let mut res = [0.0f64; MAX];
        for (c, r) in res[..cols].iter_mut().enumerate() {
            *r += acc[0][c] + acc[4][c];
            *r += acc[1][c] + acc[5][c];
            *r += acc[2][c] + acc[6][c];
            *r += acc[3][c] + acc[7][c];
        }
        for kk in k..len {
            let row = i + 1 + kk;
            let lk = l[(row, i)];
            for (r, &y) in res[..cols].iter_mut().zip(&b[row][..cols]) {
                *r += lk * y;
            }
        }
        let diag = l[(i, i)];
        for (x, &r) in b[i][..cols].iter_mut().zip(&res[..cols]) {
            *x = (*x - r) / diag;
        }
    }
    Some(())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every size up to 30, with one to thirty right-hand sides: the same bits as nalgebra.
    #[test]
    fn gives_nalgebras_bits() {
        let mut state = 0x2545_f491_4f6c_dd1du64;
        let mut next = || {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            (state >> 11) as f64 / (1u64 << 53) as f64 - 0.5
        };
        for n in 1..=30 {
            for cols in [1, 2, 7, n, 30] {
                let a = DMatrix::from_fn(n, n, |_, _| next());
                // Scales over many orders of magnitude, as the error state's variances have.
                let scale = DMatrix::from_fn(n, 1, |i, _| 10f64.powi(i as i32 % 7 - 3));
                let spd = DMatrix::from_fn(n, n, |i, j| {
                    (0..n).map(|k| a[(i, k)] * a[(j, k)]).sum::<f64>() * scale[i] * scale[j]
                }) + DMatrix::from_diagonal_element(n, n, 1e-3);
                let rhs = DMatrix::from_fn(n, cols, |_, _| next());
                let ch = spd.clone().cholesky().expect("positive definite");
                let theirs = ch.solve(&rhs);
                let mut rows = vec![[0.0; MAX]; n];
                for i in 0..n {
                    for c in 0..cols {
                        rows[i][c] = rhs[(i, c)];
                    }
                }
                solve_rows(ch.l_dirty(), &mut rows, cols).expect("fits");
                for i in 0..n {
                    for c in 0..cols {
                        assert_eq!(
                            rows[i][c].to_bits(),
                            theirs[(i, c)].to_bits(),
                            "n {n}, cols {cols}, ({i}, {c}): {} against {}",
                            rows[i][c],
                            theirs[(i, c)]
                        );
                    }
                }
            }
        }
    }

    #[test]
    fn refuses_what_does_not_fit() {
        let l = DMatrix::<f64>::identity(MAX + 1, MAX + 1);
        let mut rows = vec![[0.0; MAX]; MAX + 1];
        assert!(solve_rows(&l, &mut rows, 1).is_none());
    }
}
