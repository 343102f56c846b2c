//! One estimator step with 500 support points in each GP, variances included, in both modes.
//!
//! `cargo bench --bench ekf`. The numpy comparison is `python3 benches/numpy_filter.py`.

use criterion::{Criterion, criterion_group, criterion_main};
use hbn::core::{Estimator, Mode};
use hbn::model::{HbnModel, HbnParams};
use hbn::pipeline::experiment::{ExperimentConfig, test_trajectory, training_set};
use hbn::pipeline::sequences;
use hbn::sim::SystemKind;
use std::hint::black_box;

fn bench_step(c: &mut Criterion) {
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
    for n in [500usize, 150] {
        let params = HbnParams {
            max_points: n,
            n_starts: 1,
            max_iters: 50,
            ..HbnParams::default()
        };
        let model = HbnModel::fit(&seqs, &params).unwrap();
        assert_eq!(model.transition().n_support(), n);
        assert_eq!(model.sensor().n_support(), n);
        let view = model.view().unwrap();
        let mut g = c.benchmark_group(format!("ekf_step_n{n}"));
        for (name, mode) in [("ekf", Mode::Ekf), ("ekf_blr", Mode::EkfBlr)] {
            let mut scratch = vec![0.0; Estimator::scratch_len(&view)];
            let mut est = Estimator::new(view, model.ekf_config(mode), &mut scratch).unwrap();
            let mut k = 0usize;
            g.bench_function(name, |b| {
                b.iter(|| {
                    let out = est.step(black_box(test.u[k]), black_box(test.y[k]));
                    k = (k + 1) % test.u.len();
                    out
                })
            });
        }
        g.finish();
    }
}

criterion_group!(benches, bench_step);
criterion_main!(benches);
