//! Profiling harness (not shipped): fits the bench's sparse m = 64 model, then runs the EKF step
//! for a fixed number of samples so `perf record -D` can attach after the fit:
//! `perf record -D 7000 target/release/examples/step_profile [ekf|ekf-blr]`.
use hbn_core::{Estimator, Mode};
use hbn_model::{HbnParams, HysteresisModel};
use hbn_pipeline::experiment::{ExperimentConfig, test_trajectory, training_set};
use hbn_pipeline::sequences;
use hbn_sim::SystemKind;
use std::hint::black_box;

fn main() {
    let system = SystemKind::BoucWen;
    let cfg = ExperimentConfig {
        train_steps: 1000,
        repeats: 3,
        test_steps: 5000,
        ..ExperimentConfig::default()
    };
    let runs = training_set(system, 1.0, 1, &cfg).unwrap();
    let seqs = sequences(&runs);
    let test = test_trajectory(system, 1.0, 9, &cfg).unwrap();
    let params = HbnParams {
        n_inducing: Some(64),
        n_starts: 1,
        max_iters: 50,
        ..HbnParams::default()
    };
    let model = HysteresisModel::fit(&seqs, &params).unwrap();
    let view = model.view().unwrap();
    let mut scratch = vec![0.0; Estimator::scratch_len(&view)];
    let mode = match std::env::args().nth(1).as_deref() {
        Some("ekf-blr") => Mode::EkfBlr,
        _ => Mode::Ekf,
    };
    let mut est = Estimator::new(view, model.ekf_config(mode), &mut scratch).unwrap();
    eprintln!("fitted");
    let t = std::time::Instant::now();
    let n = 4_000_000;
    for k in 0..n {
        let i = k % test.u.len();
        black_box(est.step(black_box(test.u[i]), black_box(test.y[i])));
    }
    eprintln!("{:.3} us/step", t.elapsed().as_secs_f64() * 1e6 / n as f64);
}
