//! The estimator step timed over whole passes of a test log, reported as the fastest and the
//! median of the passes: on a shared machine whose speed drifts between bursts (as this
//! project's 2-core machines do), the fastest pass is the step's own cost and the median
//! says how much the machine took from it. Criterion's `ekf` bench averages over both.
//!
//! `cargo bench --bench step_passes -- [PASSES]` (default 15): sparse GPs with m = 64
//! (Matern 5/2, the default plays), EKF and EKF+BLR, on Bouc-Wen and Preisach models trained
//! like `benches/ekf.rs`'s, over a 5000-sample test log.

use hbn::core::{Estimator, Mode};
use hbn::model::{HbnParams, HysteresisModel, Selection};
use hbn::pipeline::experiment::{ExperimentConfig, test_trajectory, training_set};
use hbn::pipeline::sequences;
use hbn::sim::SystemKind;
use std::hint::black_box;
use std::time::Instant;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let passes = std::env::args()
        .skip(1)
        .find_map(|a| a.parse::<usize>().ok())
        .unwrap_or(15)
        .max(1);
    for system in [SystemKind::BoucWen, SystemKind::Preisach] {
        let cfg = ExperimentConfig {
            train_steps: 1000,
            repeats: 3,
            test_steps: 5000,
            ..ExperimentConfig::default()
        };
        let runs = training_set(system, 1.0, 1, &cfg)?;
        let seqs = sequences(&runs);
        let test = test_trajectory(system, 1.0, 9, &cfg)?;
        let params = HbnParams {
            n_inducing: Some(64),
            n_starts: 1,
            max_iters: 50,
            select: Selection::default(),
            kernel_evidence: Vec::new(),
            ..HbnParams::default()
        };
        let model = HysteresisModel::fit(&seqs, &params)?;
        let view = model.view()?;
        let mut per_mode = Vec::new();
        for (name, mode) in [("EKF", Mode::Ekf), ("EKF+BLR", Mode::EkfBlr)] {
            let mut times = Vec::with_capacity(passes);
            for _ in 0..passes {
                let mut scratch = vec![0.0; Estimator::scratch_len(&view)];
                let mut est = Estimator::new(view, model.ekf_config(mode), &mut scratch)?;
                let t = Instant::now();
                for (&u, &y) in test.u.iter().zip(&test.y) {
                    black_box(est.step(black_box(u), black_box(y)));
                }
                times.push(t.elapsed().as_secs_f64() * 1e6 / test.u.len() as f64);
            }
            times.sort_by(f64::total_cmp);
            let (fastest, median) = (times[0], times[times.len() / 2]);
            println!(
                "{system:?} sparse m = 64, {name}: fastest pass {fastest:.2} us/step, median {median:.2} us/step ({passes} passes of {} steps)",
                test.u.len()
            );
            per_mode.push(fastest);
        }
        println!(
            "{system:?}: the BLR adds {:.2} us/step (fastest passes)",
            per_mode[1] - per_mode[0]
        );
    }
    Ok(())
}
