//! One step of the vector filter on the simulated finger (2 inputs, 2 state components,
//! 3 sensors): sparse GPs with 64 inducing points and exact GPs with 500 support points, in
//! the EKF and the UKF (EKF+BLR is for scalar models), and the same model's scalar counterpart
//! is `benches/ekf.rs`.
//!
//! `cargo bench --bench vector_step`.

use criterion::{Criterion, criterion_group, criterion_main};
use hbn::core::Mode;
use hbn::core::vector::{Dims, VectorEstimator, VectorView};
use hbn::model::{HbnParams, VectorModel, VectorSequence};
use hbn::sim::{MultiConfig, MultiKind, simulate_multi_random};
use std::hint::black_box;

/// Row-major `(T, d)` from component-major signals.
fn rows(signals: &[Vec<f64>]) -> Vec<f64> {
    let t = signals[0].len();
    (0..t)
        .flat_map(|k| signals.iter().map(move |s| s[k]))
        .collect()
}

fn bench_vector_step(c: &mut Criterion) {
    let kind = MultiKind::Finger;
    let dims = Dims::new(kind.inputs(), kind.states(), kind.sensors()).unwrap();
    let cfg = MultiConfig {
        noise_gain: 1.0,
        seed: 1,
        ..MultiConfig::new(kind)
    };
    let train = simulate_multi_random(&cfg, 3000).unwrap();
    let test = simulate_multi_random(&MultiConfig { seed: 9, ..cfg }, 5000).unwrap();
    let (u, x, y) = (rows(&train.u), rows(&train.x), rows(&train.y));
    let (ut, yt) = (rows(&test.u), rows(&test.y));
    for (label, n_inducing) in [("sparse_m64", Some(64usize)), ("exact_n500", None)] {
        let params = HbnParams {
            n_inducing,
            n_starts: 1,
            max_iters: 50,
            ..HbnParams::default()
        };
        let model = VectorModel::fit(&[VectorSequence::new(&u, &x, &y, dims)], &params).unwrap();
        let transitions: Vec<_> = (0..dims.states)
            .map(|i| model.transition(i).unwrap().view().unwrap())
            .collect();
        let sensors: Vec<_> = (0..dims.sensors)
            .map(|j| model.sensor(j).unwrap().view().unwrap())
            .collect();
        let view = VectorView {
            dims,
            transitions: &transitions,
            sensors: &sensors,
            plays: model.plays().unwrap(),
            init: None,
        };
        let mut g = c.benchmark_group(format!("vector_step_finger_{label}"));
        for (name, mode) in [("ekf", Mode::Ekf), ("ukf", Mode::Ukf)] {
            let mut scratch = vec![0.0; view.scratch_len()];
            let mut est = VectorEstimator::new(view, model.config(mode), &mut scratch).unwrap();
            let n = ut.len() / dims.inputs;
            let mut k = 0usize;
            g.bench_function(name, |b| {
                b.iter(|| {
                    let out = est.step(
                        black_box(&ut[k * dims.inputs..(k + 1) * dims.inputs]),
                        black_box(&yt[k * dims.sensors..(k + 1) * dims.sensors]),
                    );
                    k = (k + 1) % n;
                    out
                })
            });
        }
        g.finish();
    }
}

criterion_group!(benches, bench_vector_step);
criterion_main!(benches);
