//! Accuracy metrics (thesis Sec. 5.1) and the calibration of an estimate's uncertainty.

use serde::{Deserialize, Serialize};

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

/// How well a Gaussian estimate `N(estimate, std^2)` describes the reference: for a calibrated
/// estimate the 1- and 2-sigma coverages are about 0.683 and 0.954 and the mean NEES about 1.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Calibration {
    /// Fraction of samples with `|reference - estimate| <= std`.
    pub coverage_1sigma: f64,
    /// Fraction of samples with `|reference - estimate| <= 2 std`.
    pub coverage_2sigma: f64,
    /// Mean normalised estimation error squared, `mean(((reference - estimate) / std)^2)`.
    pub mean_nees: f64,
    /// Mean negative log predictive density of the reference,
    /// `mean(ln(2 pi std^2) / 2 + ((reference - estimate) / std)^2 / 2)` (lower is better).
    pub nlpd: f64,
    /// Samples scored: those where all three values are finite and `std > 0`.
    pub samples: usize,
}

/// Calibration of `estimate +- std` against `reference`; every field is `NaN` (and `samples`
/// 0) when no sample can be scored.
pub fn calibration(estimate: &[f64], std: &[f64], reference: &[f64]) -> Calibration {
    let (mut in1, mut in2, mut nees, mut nlpd, mut n) = (0usize, 0usize, 0.0, 0.0, 0usize);
    for ((&e, &s), &r) in estimate.iter().zip(std).zip(reference) {
        if !(e.is_finite() && s.is_finite() && r.is_finite() && s > 0.0) {
            continue;
        }
        let z = (r - e) / s;
        in1 += usize::from(z.abs() <= 1.0);
        in2 += usize::from(z.abs() <= 2.0);
        nees += z * z;
        nlpd += 0.5 * (2.0 * std::f64::consts::PI * s * s).ln() + 0.5 * z * z;
        n += 1;
    }
    if n == 0 {
        return Calibration {
            coverage_1sigma: f64::NAN,
            coverage_2sigma: f64::NAN,
            mean_nees: f64::NAN,
            nlpd: f64::NAN,
            samples: 0,
        };
    }
    let nf = n as f64;
    Calibration {
        coverage_1sigma: in1 as f64 / nf,
        coverage_2sigma: in2 as f64 / nf,
        mean_nees: nees / nf,
        nlpd: nlpd / nf,
        samples: n,
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

    #[test]
    fn calibration_of_hand_made_cases() {
        // Errors of 0.5, 1.5 and 3 standard deviations (std 2), plus unscorable samples.
        let est = [0.0, 0.0, 0.0, f64::NAN, 0.0];
        let std = [2.0, 2.0, 2.0, 1.0, 0.0];
        let truth = [1.0, -3.0, 6.0, 0.0, 0.0];
        let c = calibration(&est, &std, &truth);
        assert_eq!(c.samples, 3);
        assert!((c.coverage_1sigma - 1.0 / 3.0).abs() < 1e-15);
        assert!((c.coverage_2sigma - 2.0 / 3.0).abs() < 1e-15);
        assert!((c.mean_nees - (0.25 + 2.25 + 9.0) / 3.0).abs() < 1e-15);
        let want_nlpd =
            0.5 * (2.0 * std::f64::consts::PI * 4.0).ln() + 0.5 * (0.25 + 2.25 + 9.0) / 3.0;
        assert!((c.nlpd - want_nlpd).abs() < 1e-12);
        assert!(calibration(&[1.0], &[0.0], &[1.0]).mean_nees.is_nan());
    }

    #[test]
    fn calibrated_gaussian_errors_score_as_calibrated() {
        // Errors drawn from N(0, std^2) with a portable generator: coverage ~ 0.683 / 0.954 and
        // NEES ~ 1; an overconfident band (std / 3) fails all three.
        let mut rng = hbn_core::rng::Rng::new(5);
        let n = 20_000;
        let std: Vec<f64> = (0..n).map(|i| 0.1 + 0.01 * (i % 7) as f64).collect();
        let truth: Vec<f64> = std.iter().map(|s| s * rng.normal()).collect();
        let c = calibration(&vec![0.0; n], &std, &truth);
        assert!((c.coverage_1sigma - 0.683).abs() < 0.015, "{c:?}");
        assert!((c.coverage_2sigma - 0.954).abs() < 0.01, "{c:?}");
        assert!((c.mean_nees - 1.0).abs() < 0.05, "{c:?}");
        let narrow: Vec<f64> = std.iter().map(|s| s / 3.0).collect();
        let o = calibration(&vec![0.0; n], &narrow, &truth);
        assert!(
            o.coverage_2sigma < 0.6 && o.mean_nees > 5.0 && o.nlpd > c.nlpd,
            "{o:?}"
        );
    }
}
