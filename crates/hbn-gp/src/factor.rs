//! Cholesky factorisation of `K + s_n^2 I` with reported jitter retries.

use crate::GpError;
use faer::linalg::solvers::DenseSolveCore;
use faer::{Mat, Side};

/// A successful factorisation and how much jitter it needed.
pub struct Factor {
    /// `faer`'s factorisation (lower factor `L`, `L L^T = K + (s_n^2 + jitter) I`).
    pub llt: faer::linalg::solvers::Llt<f64>,
    /// Jitter added to the diagonal (0 when none was needed).
    pub jitter: f64,
    /// Retries made (0 when the first attempt succeeded).
    pub retries: usize,
}

impl Factor {
    /// The jitter relative to the matrix's mean diagonal (`1e-10 * 10^(retries - 1)`, 0 when
    /// none was needed): comparable across matrices and hyperparameters, where the absolute
    /// jitter scales with the matrix (a line-search trial at a tiny noise makes the sparse
    /// bound's `B` huge, and its jitter with it).
    pub fn relative_jitter(&self) -> f64 {
        if self.retries == 0 {
            0.0
        } else {
            1e-10 * 10f64.powi(self.retries as i32 - 1)
        }
    }

    /// `K^{-1}` from the factor (`O(n^3)`).
    pub fn inverse(&self) -> Mat<f64> {
        self.llt.inverse()
    }

    /// `log |K|` from the factor.
    pub fn log_det(&self) -> f64 {
        let l = self.llt.L();
        (0..l.nrows()).map(|i| l[(i, i)].ln()).sum::<f64>() * 2.0
    }
}

/// Factorises `k` (its lower triangle is read), adding jitter `mean(diag) * 1e-10 * 10^r` on
/// retry `r` when the factorisation fails. `k` is restored on return.
pub fn factor_with_jitter(k: &mut Mat<f64>, max_retries: usize) -> Result<Factor, GpError> {
    let n = k.nrows();
    let mean_diag = (0..n).map(|i| k[(i, i)]).sum::<f64>() / n.max(1) as f64;
    let base = if mean_diag.is_finite() && mean_diag > 0.0 {
        mean_diag * 1e-10
    } else {
        1e-10
    };
    let mut jitter = 0.0;
    for retry in 0..=max_retries {
        if retry > 0 {
            let next = base * 10f64.powi(retry as i32 - 1);
            for i in 0..n {
                k[(i, i)] += next - jitter;
            }
            jitter = next;
        }
        if let Ok(llt) = faer::linalg::solvers::Llt::new(k.as_ref(), Side::Lower) {
            let l = llt.L();
            if (0..n).all(|i| l[(i, i)].is_finite() && l[(i, i)] > 0.0) {
                for i in 0..n {
                    k[(i, i)] -= jitter;
                }
                return Ok(Factor {
                    llt,
                    jitter,
                    retries: retry,
                });
            }
        }
    }
    for i in 0..n {
        k[(i, i)] -= jitter;
    }
    Err(GpError::NotPositiveDefinite {
        jitter,
        retries: max_retries,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A singular matrix is factored with jitter, and the relative jitter is the absolute one
    /// over the mean diagonal, whatever the matrix's scale.
    #[test]
    fn relative_jitter_does_not_scale_with_the_matrix() {
        for scale in [1.0, 1e120] {
            // Rank one: [1 1; 1 1] times scale.
            let mut k = Mat::from_fn(2, 2, |_, _| scale);
            let f = factor_with_jitter(&mut k, 8).expect("factored with jitter");
            assert!(f.retries > 0 && f.jitter > 0.0);
            let rel = f.relative_jitter();
            assert!(
                (f.jitter / scale - rel).abs() <= 1e-12 * rel,
                "{} {rel}",
                f.jitter
            );
            assert!(rel <= 1e-3, "{rel}");
            // The matrix is given back unchanged.
            assert_eq!(k[(0, 0)], scale);
        }
        let mut k = Mat::from_fn(2, 2, |i, j| if i == j { 2.0 } else { 0.5 });
        let f = factor_with_jitter(&mut k, 8).expect("positive definite");
        assert_eq!((f.retries, f.jitter, f.relative_jitter()), (0, 0.0, 0.0));
    }
}
