//! GP engine benchmarks: fitting (n = 1000, 2000; 4 inputs; ARD SE + noise; one optimiser
//! start), prediction with 500 support points (mean + variance + mean gradient), and the sparse
//! GP's variance kernels: the row-packed triangular products `T k` and `T^T v` for m = 64 and
//! 128 (`triangular_m64`, `triangular_m128`).
//!
//! `cargo bench --bench gp`. The scikit-learn comparison on the same data in the same run is
//! `python3 benches/compare_sklearn.py` (its figures are in docs/performance.md).

use criterion::{Criterion, criterion_group, criterion_main};
use hbn::core::rng::Rng;
use hbn::core::{KernelSpec, Want};
use hbn::gp::{GpParams, fit};
use std::hint::black_box;

fn data(n: usize, d: usize, seed: u64) -> (Vec<f64>, Vec<f64>) {
    let mut rng = Rng::new(seed);
    let x: Vec<f64> = (0..n * d).map(|_| rng.uniform_in(-2.0, 2.0)).collect();
    let y = x
        .chunks_exact(d)
        .map(|r| {
            r.iter()
                .enumerate()
                .map(|(j, v)| (v * (0.5 + 0.4 * j as f64)).sin())
                .sum::<f64>()
                + 0.1 * rng.normal()
        })
        .collect();
    (x, y)
}

fn params(n: usize) -> GpParams {
    let mut p = GpParams::new(KernelSpec::se_ard(4));
    p.n_starts = 1;
    p.max_points = n;
    p
}

fn bench_fit(c: &mut Criterion) {
    let mut g = c.benchmark_group("gp_fit_ard4");
    g.sample_size(10);
    for n in [1000usize, 2000] {
        let (x, y) = data(n, 4, 1);
        let p = params(n);
        g.bench_function(format!("n{n}"), |b| {
            b.iter(|| fit(black_box(&p), &x, &y).unwrap())
        });
    }
    g.finish();
}

fn bench_predict(c: &mut Criterion) {
    let (x, y) = data(500, 4, 2);
    let gp = fit(&params(500), &x, &y).unwrap();
    let view = gp.view().unwrap();
    let mut scratch = vec![0.0; view.predict_scratch(Want::ALL)];
    let probe = [0.3, -0.5, 1.1, 0.2];
    let mut g = c.benchmark_group("gp_predict_n500_d4");
    g.bench_function("mean", |b| {
        b.iter(|| {
            view.predict(black_box(&probe), Want::default(), &mut scratch)
                .unwrap()
        })
    });
    g.bench_function("mean_var_grad", |b| {
        b.iter(|| {
            view.predict(black_box(&probe), Want::EKF, &mut scratch)
                .unwrap()
        })
    });
    g.bench_function("all_incl_var_grad", |b| {
        b.iter(|| {
            view.predict(black_box(&probe), Want::ALL, &mut scratch)
                .unwrap()
        })
    });
    g.finish();
}

/// The two triangular products of the sparse GP's variance (`var = k** - |T k|^2`, and
/// `T^T (T k)` for its gradient), on a random row-packed factor.
fn bench_triangular(c: &mut Criterion) {
    for m in [64usize, 128] {
        let mut rng = Rng::new(7);
        let packed: Vec<f64> = (0..m * (m + 1) / 2).map(|_| rng.normal()).collect();
        let k: Vec<f64> = (0..m).map(|_| rng.normal()).collect();
        let mut out = vec![0.0; m];
        let mut g = c.benchmark_group(format!("triangular_m{m}"));
        g.bench_function("lower_packed_times", |b| {
            b.iter(|| {
                hbn::core::gp::lower_packed_times(black_box(&packed), black_box(&k), &mut out);
                out[m - 1]
            })
        });
        g.bench_function("lower_packed_transpose_times", |b| {
            b.iter(|| {
                hbn::core::gp::lower_packed_transpose_times(
                    black_box(&packed),
                    black_box(&k),
                    &mut out,
                );
                out[0]
            })
        });
        g.finish();
    }
}

criterion_group!(benches, bench_predict, bench_fit, bench_triangular);
criterion_main!(benches);
