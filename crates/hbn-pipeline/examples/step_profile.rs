//! Profiling aid for the estimator step: `train OUT.hbn [M]` fits a Bouc-Wen model (sparse with
//! `M` inducing points, default 64) and saves it; `step MODEL.hbn N [MODE]` loads it and runs
//! `N` steps of one mode (for `valgrind --tool=callgrind --toggle-collect='*Estimator*step*'`).
//!
//!     cargo run --release -p hbn-pipeline --example step_profile -- train /tmp/m64.hbn 64
//!     valgrind --tool=callgrind --toggle-collect='*Estimator*step*' \
//!         target/release/examples/step_profile step /tmp/m64.hbn 20000 ekf

use hbn_core::{Estimator, Mode};
use hbn_model::{HbnModel, HbnParams};
use hbn_pipeline::experiment::{ExperimentConfig, test_trajectory, training_set};
use hbn_pipeline::sequences;
use hbn_sim::SystemKind;
use std::hint::black_box;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().collect();
    let cfg = ExperimentConfig {
        train_steps: 1000,
        repeats: 3,
        test_steps: 5000,
        ..ExperimentConfig::default()
    };
    let system = SystemKind::BoucWen;
    match args.get(1).map(String::as_str) {
        Some("train") => {
            let m: usize = args.get(3).map_or(Ok(64), |s| s.parse())?;
            let runs = training_set(system, 1.0, 1, &cfg)?;
            let params = HbnParams {
                n_inducing: Some(m),
                n_starts: 1,
                max_iters: 50,
                ..HbnParams::default()
            };
            let model = HbnModel::fit(&sequences(&runs), &params)?;
            model.save(std::path::Path::new(&args[2]))?;
        }
        Some("step") => {
            let model = HbnModel::load(std::path::Path::new(&args[2]))?;
            let n: usize = args[3].parse()?;
            let mode = match args.get(4).map(String::as_str) {
                Some("ekf-blr") => Mode::EkfBlr,
                Some("ukf") => Mode::Ukf,
                _ => Mode::Ekf,
            };
            let test = test_trajectory(system, 1.0, 9, &cfg)?;
            let view = model.view()?;
            let mut scratch = vec![0.0; Estimator::scratch_len(&view)];
            let mut est = Estimator::new(view, model.ekf_config(mode), &mut scratch)?;
            let t0 = std::time::Instant::now();
            let mut acc = 0.0;
            for k in 0..n {
                let i = k % test.u.len();
                acc += est.step(black_box(test.u[i]), black_box(test.y[i])).x;
            }
            let dt = t0.elapsed().as_secs_f64();
            println!("{:.3} us/step ({acc:.3})", dt / n as f64 * 1e6);
        }
        _ => eprintln!("usage: step_profile train OUT [M] | step MODEL N [MODE]"),
    }
    Ok(())
}
