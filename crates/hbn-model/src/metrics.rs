//! Accuracy metrics (thesis Sec. 5.1).

/// Root-mean-squared error over the pairs where both values are finite; `NaN` if none.
pub fn rmse(estimate: &[f64], reference: &[f64]) -> f64 {
    let (mut s, mut n) = (0.0, 0usize);
    for (e, r) in estimate.iter().zip(reference) {
        if e.is_finite() && r.is_finite() {
            s += (e - r) * (e - r);
            n += 1;
        }
    }
    if n == 0 {
        f64::NAN
    } else {
        (s / n as f64).sqrt()
    }
}

/// `RMSE / (max(ref) - min(ref))`.
pub fn nrmse(estimate: &[f64], reference: &[f64]) -> f64 {
    let (lo, hi) = reference
        .iter()
        .filter(|v| v.is_finite())
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(l, h), &v| {
            (l.min(v), h.max(v))
        });
    let span = hi - lo;
    if span > 0.0 {
        rmse(estimate, reference) / span
    } else {
        f64::NAN
    }
}

/// Pearson correlation of two series (`NaN` if either is constant).
pub fn correlation(a: &[f64], b: &[f64]) -> f64 {
    let n = a.len().min(b.len());
    if n < 2 {
        return f64::NAN;
    }
    let ma = a[..n].iter().sum::<f64>() / n as f64;
    let mb = b[..n].iter().sum::<f64>() / n as f64;
    let (mut sab, mut saa, mut sbb) = (0.0, 0.0, 0.0);
    for i in 0..n {
        sab += (a[i] - ma) * (b[i] - mb);
        saa += (a[i] - ma) * (a[i] - ma);
        sbb += (b[i] - mb) * (b[i] - mb);
    }
    sab / (saa * sbb).sqrt()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn known_values() {
        assert!((rmse(&[1.0, 2.0], &[1.0, 4.0]) - 2f64.sqrt()).abs() < 1e-15);
        assert!((nrmse(&[1.0, 2.0], &[1.0, 4.0]) - 2f64.sqrt() / 3.0).abs() < 1e-15);
        assert!(nrmse(&[1.0], &[1.0]).is_nan());
        assert!((correlation(&[1.0, 2.0, 3.0], &[2.0, 4.0, 6.5]) - 0.9986).abs() < 1e-3);
    }
}
