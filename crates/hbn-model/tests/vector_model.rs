//! The vector model end to end on a simulated multi-chamber finger: training, estimation on a
//! fresh run (accuracy and calibration per component), the model file round trip, and the
//! observability diagnostic.

use hbn_core::Mode;
use hbn_core::vector::Dims;
use hbn_model::{HbnParams, VectorModel, VectorSequence};
use hbn_sim::{MultiConfig, MultiKind, MultiTrajectory, simulate_multi_random};

/// Row-major `(T, d)` from component-major signals.
fn rows(signals: &[Vec<f64>]) -> Vec<f64> {
    let t = signals[0].len();
    (0..t)
        .flat_map(|k| signals.iter().map(move |s| s[k]))
        .collect()
}

fn run(
    kind: MultiKind,
    gain: f64,
    seed: u64,
    steps: usize,
) -> (MultiTrajectory, Vec<f64>, Vec<f64>, Vec<f64>) {
    let mut cfg = MultiConfig::new(kind);
    cfg.noise_gain = gain;
    cfg.seed = seed;
    let t = simulate_multi_random(&cfg, steps).unwrap();
    let (u, x, y) = (rows(&t.u), rows(&t.x), rows(&t.y));
    (t, u, x, y)
}

fn params() -> HbnParams {
    HbnParams {
        max_points: 300,
        n_starts: 1,
        ..HbnParams::default()
    }
}

#[test]
fn a_finger_model_estimates_each_component_of_a_fresh_run() {
    let kind = MultiKind::Finger;
    let dims = Dims::new(kind.inputs(), kind.states(), kind.sensors()).unwrap();
    let (_, u, x, y) = run(kind, 1.0, 1, 2000);
    let seq = VectorSequence::new(&u, &x, &y, dims);
    let model = VectorModel::fit(&[seq], &params()).unwrap();
    eprintln!("{:#?}", model.summary().validation);
    let (_, ut, xt, yt) = run(kind, 1.0, 7, 1500);
    let est = model.estimate(&ut, &yt, model.default_mode()).unwrap();
    for i in 0..dims.states {
        let truth: Vec<f64> = xt.iter().skip(i).step_by(dims.states).copied().collect();
        let (xi, si) = (est.component(i), est.component_std(i));
        let n = truth.len() as f64;
        let rmse = (truth
            .iter()
            .zip(&xi)
            .map(|(a, b)| (a - b).powi(2))
            .sum::<f64>()
            / n)
            .sqrt();
        let span = truth.iter().cloned().fold(f64::NEG_INFINITY, f64::max)
            - truth.iter().cloned().fold(f64::INFINITY, f64::min);
        let cover = truth
            .iter()
            .zip(xi.iter().zip(&si))
            .filter(|(t, (x, s))| (*t - *x).abs() <= 2.0 * *s)
            .count() as f64
            / n;
        eprintln!(
            "component {i}: nRMSE {:.4}, 2-sigma coverage {cover:.3}",
            rmse / span
        );
        assert!(rmse / span < 0.08, "component {i}: nRMSE {}", rmse / span);
        assert!(cover > 0.8, "component {i}: coverage {cover}");
    }
    // One candidate per inducing setting (exact, m = 64) and lag set (none, 0.1 s, 1 s),
    // trained side by side; the model is the chosen one's, its plays carry its lags, its GPs
    // are sparse when the sparse candidate was chosen, and the file keeps both.
    let rows = &model.summary().candidates;
    let shapes: Vec<(&[f64], Option<usize>)> = rows
        .iter()
        .map(|r| (r.lags.as_slice(), r.n_inducing))
        .collect();
    let sets = [&[][..], &[0.1][..], &[1.0][..]];
    let expected: Vec<(&[f64], Option<usize>)> = [None, Some(64)]
        .into_iter()
        .flat_map(|m| sets.iter().map(move |l| (*l, m)))
        .collect();
    assert_eq!(shapes, expected);
    let chosen: Vec<&hbn_model::VectorCandidateRow> = rows.iter().filter(|r| r.chosen).collect();
    assert_eq!(chosen.len(), 1, "{rows:#?}");
    assert_eq!(model.lags(), chosen[0].lags.as_slice());
    assert_eq!(model.params().n_inducing, chosen[0].n_inducing);
    for i in 0..dims.states {
        let gp = model.transition(i).unwrap();
        assert_eq!(gp.is_sparse(), chosen[0].n_inducing.is_some());
    }
    assert_eq!(model.plays().unwrap().lags().len(), model.lags().len());
    assert!(rows.iter().all(|r| r.nlpd.is_some() && r.error.is_none()));
    // The model file round-trips to the same estimates, bit for bit.
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("finger.json");
    model.save(&path).unwrap();
    let back = VectorModel::load(&path).unwrap();
    let again = back.estimate(&ut, &yt, model.default_mode()).unwrap();
    assert_eq!(est, again);
    assert_eq!(back.lags(), model.lags());
    assert_eq!(back.params().n_inducing, model.params().n_inducing);
    assert!(VectorModel::load(&dir.path().join("missing.json")).is_err());
    for mode in [Mode::Ekf, Mode::Ukf] {
        let e = model.estimate(&ut, &yt, mode).unwrap();
        assert!(e.x.iter().all(|v| v.is_finite()));
    }
}

/// Why EKF+BLR is for scalar models. Its neighbourhood is a box of +-2.5% of each input's
/// training range around the query. Queried at the transition inputs of a fresh run, that box
/// over a vector model's inputs (8 for the finger without memory, 12 for the arm) holds no
/// training row at all for almost every query, so the local regression would silently fall
/// back to the GP; over the scalar model's 4 inputs it is empty for fewer than 1 in 5. Run with
/// `--nocapture` for the shares.
#[test]
fn the_local_regression_box_is_empty_for_a_vector_transition() {
    for kind in [MultiKind::Finger, MultiKind::Arm] {
        let dims = Dims::new(kind.inputs(), kind.states(), kind.sensors()).unwrap();
        let plays = hbn_core::Plays::NONE;
        let (_, u, x, y) = run(kind, 1.0, 1, 3000);
        let (_, ut, xt, yt) = run(kind, 1.0, 9, 1000);
        let (train, _) =
            hbn_model::vector::transition_rows(&[VectorSequence::new(&u, &x, &y, dims)], &plays);
        let (test, _) =
            hbn_model::vector::transition_rows(&[VectorSequence::new(&ut, &xt, &yt, dims)], &plays);
        let d = dims.transition_dim(0);
        let scalar_cols = [
            0,
            dims.states,
            2 * dims.states,
            2 * dims.states + dims.inputs,
        ];
        let empty_share = |cols: &[usize]| {
            let pick = |r: &[f64]| cols.iter().map(|&c| r[c]).collect::<Vec<f64>>();
            let tr: Vec<Vec<f64>> = train.chunks_exact(d).map(pick).collect();
            let (mut lo, mut hi) = (vec![f64::MAX; cols.len()], vec![f64::MIN; cols.len()]);
            for r in &tr {
                for c in 0..cols.len() {
                    lo[c] = lo[c].min(r[c]);
                    hi[c] = hi[c].max(r[c]);
                }
            }
            let half: Vec<f64> = lo.iter().zip(&hi).map(|(l, h)| 0.025 * (h - l)).collect();
            let queries: Vec<Vec<f64>> = test.chunks_exact(d).step_by(5).map(pick).collect();
            let empty = queries
                .iter()
                .filter(|q| {
                    !tr.iter().any(|r| {
                        r.iter()
                            .zip(q.iter())
                            .zip(&half)
                            .all(|((a, b), h)| (a - b).abs() <= *h)
                    })
                })
                .count();
            empty as f64 / queries.len() as f64
        };
        let all: Vec<usize> = (0..d).collect();
        let (vector, scalar) = (empty_share(&all), empty_share(&scalar_cols));
        eprintln!(
            "{kind:?}: box empty for {:.1}% of queries over all {d} inputs, {:.1}% over 4",
            100.0 * vector,
            100.0 * scalar
        );
        assert!(vector > 0.8 && scalar < 0.2, "{kind:?}: {vector}, {scalar}");
    }
}
