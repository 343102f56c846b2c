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
