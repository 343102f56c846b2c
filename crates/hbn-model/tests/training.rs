//! The exact GP's search on smooth data: the optimum lies at the end of a near-flat ridge of
//! long length scales, and a start ends once an iteration gains less than the tolerance
//! instead of creeping along it (docs/tuning.md, "Cost", session 21).

use hbn_model::{HbnModel, HbnParams, Sequence};
use hbn_sim::{SimConfig, SystemKind, simulate_random};

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
    let model = HbnModel::fit(&[Sequence::new(&train.u, &train.x, &train.y)], &params).unwrap();
    let report = model.transition().report();
    assert!(
        report.evaluations < 300,
        "{} evaluations: the search crept along the ridge",
        report.evaluations
    );
}
