//! A million steps with a noisy input and outliers in y: no NaN ever leaves the filter, and
//! P stays within its bounds (eigenvalues in [p_min, p_max]) in both modes.

mod common;

use hbn::core::rng::Rng;
use hbn::core::{Estimator, Flags, Mode};
use hbn::sim::SystemKind;
use nalgebra::SymmetricEigen;

#[test]
fn a_million_noisy_steps_stay_finite_and_bounded() {
    let (model, _) = common::train_model(SystemKind::GeneralizedPi, 2.0, 80, 5);
    let test = common::test_run(SystemKind::GeneralizedPi, 2.0, 10_000, 5);
    let view = model.view().unwrap();
    let (_, _, y_stats) = model.stats();
    for mode in [Mode::Ekf, Mode::EkfBlr] {
        let cfg = model.ekf_config(mode);
        let mut scratch = vec![0.0; Estimator::scratch_len(&view)];
        let mut est = Estimator::new(view, cfg, &mut scratch).unwrap();
        let mut rng = Rng::new(11);
        let mut outliers_seen = 0usize;
        let steps = 1_000_000;
        for k in 0..steps {
            let i = k % test.u.len();
            // Input noise beyond anything seen in training.
            let u = test.u[i] + 0.05 * (rng.uniform() - 0.5);
            let mut y = test.y[i];
            if k % 997 == 0 {
                y += 50.0 * y_stats.span() * (rng.uniform() - 0.3);
            }
            if k % 100_003 == 0 {
                y = f64::INFINITY;
            }
            let out = est.step(u, y);
            assert!(
                out.x.is_finite() && out.x_std.is_finite() && out.y_pred.is_finite(),
                "{mode:?} step {k}: {out:?}"
            );
            assert!(
                out.nis.is_finite()
                    && out.innovation.is_finite()
                    && out.q_x.is_finite()
                    && out.r.is_finite()
            );
            // The shipped outlier gate rejects most outliers; the others reach the state box.
            if out.flags.has(Flags::STATE_CLAMPED) || out.flags.has(Flags::OUTLIER_REJECTED) {
                outliers_seen += 1;
            }
            if k % 1000 == 0 {
                let p = est.state().unwrap().p;
                assert!((p - p.transpose()).abs().max() <= 1e-12 * p.abs().max());
                let eig = SymmetricEigen::new(p).eigenvalues;
                // Recomposing Q diag(clamped) Q^T rounds at ~eps * lambda_max, which is large
                // relative to p_min: compare with that absolute tolerance.
                let tol = 1e-12 * eig.amax();
                for &e in eig.iter() {
                    assert!(
                        e >= cfg.p_min - tol && e <= cfg.p_max * (1.0 + 1e-9),
                        "{mode:?} step {k}: eigenvalue {e}"
                    );
                }
            }
        }
        // The outliers really were extreme enough to reach the guards.
        assert!(
            outliers_seen > 0,
            "{mode:?}: no outlier was rejected or reached the state box"
        );
    }
}

/// Samples in a row the error must stay within its bound to count as recovered.
const SETTLED: usize = 50;
/// The stated recovery: within this many samples after `y` returns, the error is back within 3
/// times the RMS error before the dropout (and stays there for `SETTLED` samples).
const RECOVERY_LIMIT: usize = 100;

/// A sensor dropout of 3 s (300 samples of `y` missing): the filter predicts through it with a
/// growing standard deviation and, once `y` returns, its error is back within 3 times the RMS
/// error of the 500 samples before the dropout within `RECOVERY_LIMIT` samples, in every mode
/// (the same measure as `benches/soak.rs`, whose 10^7-step figures are in
/// docs/reliability.md).
#[test]
fn a_sensor_dropout_is_recovered_within_100_samples() {
    // Without play operators: the generalised Prandtl-Ishlinskii system is a sum of plays, so
    // with them the transition predicts x from u alone as well as the filter does with y
    // (measured: RMS 0.0169 without y against 0.0172 with), and the sensor's part in the
    // recovery, which this test checks, would not show.
    let (model, _) =
        common::train_model_with(SystemKind::GeneralizedPi, 1.0, 100, 6, |p| p.memory.clear());
    let test = common::test_run(SystemKind::GeneralizedPi, 1.0, 3_000, 6);
    let (start, len) = (1_500, 300);
    let end = start + len;
    for mode in Mode::ALL {
        let view = model.view().unwrap();
        let mut scratch = vec![0.0; Estimator::scratch_len(&view)];
        let mut est = Estimator::new(view, model.ekf_config(mode), &mut scratch).unwrap();
        // The same run with `y` never returning: what the filter does without the sensor.
        let mut open_scratch = vec![0.0; Estimator::scratch_len(&view)];
        let mut open = Estimator::new(view, model.ekf_config(mode), &mut open_scratch).unwrap();
        let mut open_errors = Vec::new();
        let (mut before, mut errors) = (Vec::new(), Vec::new());
        let (mut std_before, mut std_at_end, mut peak) = (0.0, 0.0, 0.0f64);
        for k in 0..test.u.len() {
            let dropped = (start..end).contains(&k);
            let out = est.step(test.u[k], if dropped { f64::NAN } else { test.y[k] });
            assert!(
                out.x.is_finite() && out.x_std.is_finite(),
                "{mode} step {k}"
            );
            let err = (out.x - test.x[k]).abs();
            let open_out = open.step(test.u[k], if k >= start { f64::NAN } else { test.y[k] });
            if k >= end {
                open_errors.push((open_out.x - test.x[k]).abs());
            }
            if (start - 500..start).contains(&k) {
                before.push(err * err);
                std_before = out.x_std;
            }
            if dropped {
                peak = peak.max(err);
            }
            if k == end - 1 {
                std_at_end = out.x_std;
            }
            if k >= end {
                errors.push(err);
            }
        }
        let rms = (before.iter().sum::<f64>() / before.len() as f64).sqrt();
        assert!(
            std_at_end > std_before,
            "{mode}: the standard deviation grows while y is missing ({std_before} -> {std_at_end})"
        );
        // Samples after `y` returns until the error stays within 3 RMS for SETTLED samples.
        let bound = 3.0 * rms;
        let recovery = (0..errors.len().saturating_sub(SETTLED))
            .find(|&i| errors[i..i + SETTLED].iter().all(|&e| e <= bound))
            .expect("the error never settles after the dropout");
        eprintln!(
            "{mode}: RMS error before {rms:.3e}, largest during the dropout {:.1} RMS, \
             recovered after {recovery} samples",
            peak / rms
        );
        assert!(
            recovery <= RECOVERY_LIMIT,
            "{mode}: recovered after {recovery} samples (limit {RECOVERY_LIMIT})"
        );
        // Recovery is the sensor's doing: over the 500 samples after the dropout the error is
        // smaller than that of the same filter without `y`.
        let rms_of = |e: &[f64]| (e.iter().map(|v| v * v).sum::<f64>() / e.len() as f64).sqrt();
        let (closed, open_loop) = (rms_of(&errors[..500]), rms_of(&open_errors[..500]));
        eprintln!("{mode}: RMS error after the dropout {closed:.3e}, without y {open_loop:.3e}");
        assert!(
            closed < 0.8 * open_loop,
            "{mode}: RMS error after the dropout {closed} vs {open_loop} without y"
        );
        // And it stays recovered: the worst error of the 300 samples after that.
        let later = &errors[recovery..(recovery + 300).min(errors.len())];
        let worst = later.iter().fold(0.0f64, |m, e| m.max(*e));
        assert!(
            worst <= 5.0 * rms,
            "{mode}: error {worst} after recovering vs RMS {rms} before"
        );
    }
}
