//! One estimator step, variances included, in every mode (EKF, EKF+BLR, UKF): sparse GPs with 64 and 128 inducing
//! points and exact GPs with 500 and 150 support points, all with the default play operators
//! (`memory`), and the m = 64 model without them (`sparse_m64_no_memory`).
//!
//! `cargo bench --bench ekf`. The numpy comparison is `python3 benches/numpy_filter.py`.

use criterion::{Criterion, criterion_group, criterion_main};
use hbn::core::{Estimator, Mode};
use hbn::model::{HbnParams, HysteresisModel, Selection};
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
    let memory = HbnParams::default().memory;
    let cases = [
        ("sparse_m64", Some(64usize), 500usize, memory.clone()),
        ("sparse_m64_no_memory", Some(64), 500, Vec::new()),
        ("sparse_m128", Some(128), 500, memory.clone()),
        ("exact_n500", None, 500, memory.clone()),
        ("exact_n150", None, 150, memory),
    ];
    for (label, n_inducing, max_points, memory) in cases {
        let params = HbnParams {
            n_inducing,
            max_points,
            memory,
            n_starts: 1,
            max_iters: 50,
            // One configuration: the default's held-out choice between exact and sparse GPs
            // would otherwise bench whichever it picked under this case's label.
            select: Selection::default(),
            // Matern 5/2 on both GPs, a fixed kernel for every run (the default's choice
            // by evidence could take SE-ARD, whose step costs about the same).
            kernel_evidence: Vec::new(),
            ..HbnParams::default()
        };
        let model = HysteresisModel::fit(&seqs, &params).unwrap();
        let n = n_inducing.unwrap_or(max_points);
        assert_eq!(model.transition().n_support(), n);
        assert_eq!(model.sensor().n_support(), n);
        let view = model.view().unwrap();
        let mut g = c.benchmark_group(format!("ekf_step_{label}"));
        for (name, mode) in [
            ("ekf", Mode::Ekf),
            ("ekf_blr", Mode::EkfBlr),
            ("ukf", Mode::Ukf),
        ] {
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
