//! Where the exact GP's hyperparameter search stops on smooth data: the optimum lies at the end
//! of a near-flat ridge of long length scales, and a start ends once an iteration gains less
//! than the tolerance instead of creeping along it (docs/tuning.md, "Scheduling and cost").
//! The sparse GP's stopping rule is tested beside the model selection that uses it
//! (`hbn_model::model`'s unit tests).

use hbn_model::{HbnParams, HysteresisModel, Sequence};
use hbn_sim::{SimConfig, SystemKind, simulate_random};

#[test]
fn the_exact_search_ends_on_the_ridge_of_smooth_data() {
    // A tolerance of 1e-8 nats per iteration takes this log's transition GP about 480
    // likelihood evaluations along the ridge; 1e-5 about 180, to the same likelihood within
    // three decimals.
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
