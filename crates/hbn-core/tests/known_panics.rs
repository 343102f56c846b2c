//! Two inputs that could make `hbn-core`'s public API panic: both return values or errors.

use hbn_core::CoreError;
use hbn_core::blr::{BLR_MAX_NEIGHBOURS, LocalRegression, Neighbourhood, NeighbourhoodParts};
use hbn_core::gp::{back_substitute_packed, forward_substitute_packed};

/// 100 one-dimensional samples in one grid cell, so a query around them caps.
struct Samples {
    inputs: Vec<f64>,
    targets: Vec<f64>,
}

fn samples() -> Samples {
    let inputs: Vec<f64> = (0..100).map(|i| i as f64 * 1e-3).collect();
    let targets = inputs.iter().map(|x| 2.0 * x + 0.1).collect();
    Samples { inputs, targets }
}

fn neighbourhood(s: &Samples) -> Neighbourhood<'_> {
    Neighbourhood::new(
        1,
        NeighbourhoodParts {
            inputs: &s.inputs,
            targets: &s.targets,
            cell_keys: &[0],
            cell_start: &[0, 100],
            origin: &[0.0],
            half_window: &[1.0],
            input_var: &[1.0],
        },
    )
    .expect("valid index")
}

/// `LocalRegression::posterior` with `max_neighbours = 64` (above the buffer's 48) and
/// `validate()` skipped used to panic slicing the neighbour buffer; it now uses the buffer's
/// capacity, exactly as `max_neighbours = 48` does.
#[test]
fn posterior_with_too_many_neighbours_does_not_panic() {
    let s = samples();
    let nb = neighbourhood(&s);
    let big = LocalRegression {
        max_neighbours: 64,
        ..LocalRegression::default()
    };
    assert!(
        big.validate().is_err(),
        "64 is still rejected by validate()"
    );
    let at_cap = LocalRegression {
        max_neighbours: BLR_MAX_NEIGHBOURS,
        ..LocalRegression::default()
    };
    let p = big.posterior(&nb, &[0.05], 0.2, &[2.0], 1e-4, 1e-4);
    let q = at_cap.posterior(&nb, &[0.05], 0.2, &[2.0], 1e-4, 1e-4);
    assert_eq!(p, q);
    assert_eq!(p.n, BLR_MAX_NEIGHBOURS);
    assert!(p.capped);
    // Zero neighbours (also rejected by validate) is the prior, not a panic.
    let zero = LocalRegression {
        max_neighbours: 0,
        ..LocalRegression::default()
    };
    let z = zero.posterior(&nb, &[0.05], 0.2, &[2.0], 1e-4, 1e-4);
    assert_eq!(z.n, 0);
    for m in [usize::MAX, 49, 1000] {
        let r = LocalRegression {
            max_neighbours: m,
            ..LocalRegression::default()
        };
        assert_eq!(r.posterior(&nb, &[0.05], 0.2, &[2.0], 1e-4, 1e-4), q);
    }
    // Short slices for the operating point and gradient: no panic.
    let _ = big.posterior(&nb, &[], 0.2, &[], 1e-4, 1e-4);
}

/// `forward_substitute_packed` with a factor shorter than `n (n + 1) / 2` used to panic
/// slicing the factor; it (and `back_substitute_packed`) now return an error.
#[test]
fn substitution_with_short_factor_is_an_error() {
    // L = [[2], [1, 4], [0.5, 1, 8]] packed by rows: 6 values for n = 3.
    let l = [2.0, 1.0, 4.0, 0.5, 1.0, 8.0];
    let k = [2.0, 5.0, 9.5];
    let mut v = [0.0; 3];
    forward_substitute_packed(&l, &k, &mut v).expect("full factor");
    assert_eq!(v, [1.0, 1.0, 1.0]);
    back_substitute_packed(&l, &mut v).expect("full factor");
    for short in [&l[..5], &l[..3], &l[..0]] {
        let mut v = [0.0; 3];
        assert_eq!(
            forward_substitute_packed(short, &k, &mut v),
            Err(CoreError::DimensionMismatch {
                expected: 6,
                got: short.len()
            })
        );
        let mut w = [1.0; 3];
        assert_eq!(
            back_substitute_packed(short, &mut w),
            Err(CoreError::DimensionMismatch {
                expected: 6,
                got: short.len()
            })
        );
        assert_eq!(w, [1.0; 3], "an error leaves v unchanged");
    }
    // Mismatched k / v lengths solve the common prefix (unchanged behaviour).
    let mut v2 = [0.0; 2];
    forward_substitute_packed(&l, &k, &mut v2).expect("prefix");
    assert_eq!(v2, [1.0, 1.0]);
}

/// Found by the link-time check (`crates/hbn-core/nopanic`): `f64::clamp` panics when its
/// lower bound exceeds the upper one, and `posterior` clamped the intercept's prior weight to
/// `[kappa, 1e12]`, so a `kappa` above 1e12 (which `validate()` accepts) or NaN panicked in
/// the EKF+BLR step. The weight now saturates at 1e12.
#[test]
fn posterior_with_huge_or_nan_kappa_does_not_panic() {
    let s = samples();
    let nb = neighbourhood(&s);
    for kappa in [1e13, 1e300, f64::INFINITY, f64::NAN, -1.0] {
        let r = LocalRegression {
            kappa,
            ..LocalRegression::default()
        };
        let _ = r.posterior(&nb, &[0.05], 0.2, &[2.0], 1e-4, 1e-4);
    }
    let big = LocalRegression {
        kappa: 1e13,
        ..LocalRegression::default()
    };
    assert!(big.validate().is_ok(), "validate() accepts kappa = 1e13");
    let p = big.posterior(&nb, &[0.05], 0.2, &[2.0], 1e-4, 1e-4);
    assert!(p.noise.is_finite() && p.intercept.is_finite());
}
