//! Where the hyperparameter searches stop. The exact GP's on smooth data: the optimum lies at
//! the end of a near-flat ridge of long length scales, and a start ends once an iteration
//! gains less than the tolerance instead of creeping along it (docs/tuning.md, "Cost",
//! session 21). The sparse GP's: its tolerance sits above the bound's rounding noise
//! (docs/sparse.md, session 22).

use hbn_model::{HbnParams, HysteresisModel, Sequence};
use hbn_sim::{
    DEFAULT_MAX_INCREMENT, InputKind, SimConfig, SystemKind, generate_input, simulate,
    simulate_random,
};

#[test]
fn the_exact_search_ends_on_the_ridge_of_smooth_data() {
    // With the old tolerance (1e-8 nats per iteration) the transition GP of this log took
    // 480 likelihood evaluations; with 1e-5, 179. (On the log of `hbn simulate
    // --system bouc-wen --steps 1000`: 802 against 122, the same likelihood to three decimals.)
    let cfg = SimConfig {
        noise_gain: 1.0,
        ..SimConfig::new(SystemKind::BoucWen)
    };
    let train = simulate_random(&cfg, 1000).unwrap();
    let params = HbnParams {
        validation: 0.0,
        ..HbnParams::default()
    };
    let model =
        HysteresisModel::fit(&[Sequence::new(&train.u, &train.x, &train.y)], &params).unwrap();
    let report = model.transition().report();
    assert!(
        report.evaluations < 300,
        "{} evaluations: the search crept along the ridge",
        report.evaluations
    );
}

#[test]
fn the_sparse_search_ends_above_the_bounds_rounding_noise() {
    // The README demo's data: one random-ramp input (seed 1), three logs with noise seeds 11,
    // 12 and 13. The sparse bound's value carries rounding noise of about 1e-8 of itself
    // (8e-5 nats on these 3000 samples). With a tolerance of 1e-8 nats per sample, below
    // that noise, the line searches near the optimum went on for dozens of evaluations that
    // changed the bound only in its noise (docs/sparse.md, session 22).
    let u = generate_input(InputKind::RandomRamps, 1000, DEFAULT_MAX_INCREMENT, 1).unwrap();
    let logs: Vec<_> = [11, 12, 13]
        .iter()
        .map(|&seed| {
            let cfg = SimConfig {
                seed,
                ..SimConfig::new(SystemKind::BoucWen)
            };
            simulate(&cfg, &u).unwrap()
        })
        .collect();
    let seqs: Vec<Sequence<'_>> = logs
        .iter()
        .map(|t| Sequence::new(&t.u, &t.x, &t.y))
        .collect();
    // The model selection's sparse candidate: m = 64, its search started from the exact
    // GPs' optimum.
    let params = HbnParams {
        validation: 0.0,
        n_inducing: Some(64),
        sparse_from_exact: true,
        select: hbn_model::Selection::default(),
        ..HbnParams::default()
    };
    let model = HysteresisModel::fit(&seqs, &params).unwrap();
    // The transition GP's search: 94 evaluations, 148 with the old tolerance.
    let report = model.transition().report();
    assert!(
        report.evaluations < 120,
        "{} evaluations: the search went on in the bound's rounding noise",
        report.evaluations
    );
}
