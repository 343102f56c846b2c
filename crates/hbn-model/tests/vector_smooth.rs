//! Smoothing a vector model (the multi-chamber finger): the smoothed augmented states are
//! consistent with one another and never less certain than the filter's, the band holds the
//! truth, and in a stretch where every sensor dropped out the samples after it correct the
//! component the sensors pin best.

use hbn_core::Mode;
use hbn_core::vector::Dims;
use hbn_model::{HbnParams, Selection, VectorModel, VectorSequence};
use hbn_sim::{MultiConfig, MultiKind, simulate_multi_random};

/// Row-major `(T, d)` from component-major signals.
fn rows(signals: &[Vec<f64>]) -> Vec<f64> {
    let t = signals[0].len();
    (0..t)
        .flat_map(|k| signals.iter().map(move |s| s[k]))
        .collect()
}

fn run(gain: f64, seed: u64, steps: usize) -> (Vec<f64>, Vec<f64>, Vec<f64>) {
    let mut cfg = MultiConfig::new(MultiKind::Finger);
    cfg.noise_gain = gain;
    cfg.seed = seed;
    let t = simulate_multi_random(&cfg, steps).unwrap();
    (rows(&t.u), rows(&t.x), rows(&t.y))
}

/// Root mean squared error of component `i` over the samples in `range`, over the truth's span
/// on the whole run.
fn nrmse(est: &[f64], truth: &[f64], dx: usize, i: usize, range: std::ops::Range<usize>) -> f64 {
    let all: Vec<f64> = truth.iter().skip(i).step_by(dx).copied().collect();
    let span = all.iter().cloned().fold(f64::NEG_INFINITY, f64::max)
        - all.iter().cloned().fold(f64::INFINITY, f64::min);
    let n = range.len() as f64;
    let sq: f64 = range
        .map(|k| (est[k * dx + i] - truth[k * dx + i]).powi(2))
        .sum();
    (sq / n).sqrt() / span
}

#[test]
fn the_smoother_is_consistent_and_bridges_a_sensor_dropout() {
    let kind = MultiKind::Finger;
    let dims = Dims::new(kind.inputs(), kind.states(), kind.sensors()).unwrap();
    let (u, x, y) = run(3.0, 1, 1500);
    // The model without lags (one candidate): the test is about the smoother, and the
    // dropout is bridged by what the samples after it tell about the state.
    let d = HbnParams::default();
    let params = HbnParams {
        max_points: 200,
        n_starts: 1,
        select: Selection {
            lags: Vec::new(),
            ..d.select.clone()
        },
        ..d
    };
    let model = VectorModel::fit(&[VectorSequence::new(&u, &x, &y, dims)], &params).unwrap();
    let (ut, xt, mut yt) = run(3.0, 5, 1200);
    // Every sensor drops out for 80 samples.
    let gap = 600..680;
    for k in gap.clone() {
        for j in 0..dims.sensors {
            yt[k * dims.sensors + j] = f64::NAN;
        }
    }
    let (dx, n) = (dims.states, dims.augmented());
    for mode in [Mode::Ekf, Mode::Ukf] {
        let s = model.smooth_with(&ut, &yt, mode).unwrap();
        let t = ut.len() / dims.inputs;
        assert_eq!((s.estimate.len(), s.augmented, s.mean.len()), (t, n, t * n));
        assert_eq!(
            s.filtered,
            model.estimate(&ut, &yt, mode).unwrap(),
            "{mode:?}"
        );
        assert!(
            s.estimate
                .x
                .iter()
                .chain(&s.estimate.x_std)
                .all(|v| v.is_finite())
        );
        // The last sample's smoothed state is its filtered one (to the rounding of the pass's
        // scaling by the box spans).
        for k in (t - 1) * dx..t * dx {
            let close = |a: f64, b: f64| (a - b).abs() <= 1e-12 * a.abs().max(b.abs());
            assert!(close(s.estimate.x[k], s.filtered.x[k]), "{mode:?}");
            assert!(close(s.estimate.x_std[k], s.filtered.x_std[k]), "{mode:?}");
        }
        // `x_k` is in `z_k` (first block) and again in `z_{k+1}` (second block): one random
        // variable, one smoothed mean and variance.
        for k in 0..t - 1 {
            for i in 0..dx {
                let (a, b) = (s.mean[k * n + i], s.mean[(k + 1) * n + dx + i]);
                assert!(
                    (a - b).abs() < 1e-7 * (1.0 + a.abs()),
                    "{mode:?} {k}: {a} vs {b}"
                );
                let va = s.cov[k * n * n + i * n + i];
                let vb = s.cov[(k + 1) * n * n + (dx + i) * n + dx + i];
                assert!(
                    (va - vb).abs() < 1e-6 * va.abs() + 1e-15,
                    "{mode:?} {k}: {va} vs {vb}"
                );
            }
        }
        // Smoothing adds information: no smoothed deviation above the filtered one.
        let wider = s
            .estimate
            .x_std
            .iter()
            .zip(&s.filtered.x_std)
            .filter(|(a, b)| **a > **b * (1.0 + 1e-9))
            .count();
        assert_eq!(
            wider, 0,
            "{mode:?}: {wider} smoothed deviations above the filter's"
        );
        // In the dropout the filter runs open loop; the smoother also has the samples after
        // it, and they tell it about the reach (`x0`), the component the sensors pin best.
        // Over the whole run the smoothed estimate is about as accurate as the filtered one
        // (the model's own error dominates at this noise) and its band holds the truth.
        for i in 0..dx {
            let filt = nrmse(&s.filtered.x, &xt, dx, i, gap.clone());
            let smooth = nrmse(&s.estimate.x, &xt, dx, i, gap.clone());
            let whole_f = nrmse(&s.filtered.x, &xt, dx, i, 0..t);
            let whole_s = nrmse(&s.estimate.x, &xt, dx, i, 0..t);
            let covered = (0..t)
                .filter(|k| {
                    let j = k * dx + i;
                    (s.estimate.x[j] - xt[j]).abs() <= 2.0 * s.estimate.x_std[j]
                })
                .count() as f64
                / t as f64;
            eprintln!(
                "{mode:?} x{i}: dropout {filt:.4} -> {smooth:.4}, whole run {whole_f:.4} -> \
                 {whole_s:.4}, smoothed 2-sigma coverage {covered:.3}"
            );
            if i == 0 {
                assert!(
                    smooth < 0.95 * filt,
                    "{mode:?}: {smooth} vs {filt} in the dropout"
                );
            }
            assert!(
                whole_s < 1.1 * whole_f,
                "{mode:?} x{i}: {whole_s} vs {whole_f}"
            );
            assert!(covered > 0.85, "{mode:?} x{i}: coverage {covered}");
        }
    }
}
