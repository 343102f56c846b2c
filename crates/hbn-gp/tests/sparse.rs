//! Sparse GP (SGPR/VFE) tests: equality with the exact GP when `Z = X`, parity with an
//! independent numpy implementation of Titsias' formulas, gradients against finite
//! differences, the bound below the exact LML, determinism, persistence and bad input.

use hbn_core::rng::Rng;
use hbn_core::{KernelSpec, Metric, Profile, Want};
use hbn_gp::likelihood::LikelihoodData;
use hbn_gp::sparse::{SparseBound, greedy_variance_selection};
use hbn_gp::{
    GaussianProcess, GpError, GpParams, Hyperparameters, MeanFunction, SparseParams, fit,
};

fn fixture(name: &str) -> String {
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../fixtures")
        .join(name);
    std::fs::read_to_string(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display()))
}

fn vecf(v: &serde_json::Value) -> Vec<f64> {
    v.as_array()
        .unwrap()
        .iter()
        .map(|x| x.as_f64().unwrap())
        .collect()
}

fn rel(a: f64, b: f64) -> f64 {
    (a - b).abs() / b.abs().max(1e-12)
}

fn data(n: usize, d: usize, seed: u64) -> (Vec<f64>, Vec<f64>) {
    let mut rng = Rng::new(seed);
    let x: Vec<f64> = (0..n * d).map(|_| rng.uniform_in(-2.0, 2.0)).collect();
    let y = x
        .chunks_exact(d)
        .map(|r| r.iter().map(|v| v.sin()).sum::<f64>() + 0.05 * rng.normal())
        .collect();
    (x, y)
}

fn kernels(d: usize) -> Vec<KernelSpec> {
    vec![
        KernelSpec::se_ard(d),
        KernelSpec {
            profile: Profile::Matern52,
            ..KernelSpec::se_ard(d)
        },
        KernelSpec {
            metric: Metric::Isotropic,
            ..KernelSpec::se_ard(d)
        },
        KernelSpec {
            metric: Metric::Mahalanobis,
            warp_units: 2,
            direction: Some([0, 1]),
            ..KernelSpec::se_ard(d)
        },
    ]
}

fn fixed(spec: KernelSpec, noise: f64) -> GpParams {
    let mut theta = vec![0.0; spec.n_params()];
    spec.default_theta(&mut theta).unwrap();
    theta[0] = 0.3;
    for t in theta.iter_mut().take(1 + spec.n_metric()).skip(1) {
        *t = 0.2;
    }
    let mut p = GpParams::new(spec);
    p.optimize = false;
    p.init = Some(Hyperparameters {
        theta,
        noise_variance: noise,
    });
    p
}

/// With the inducing inputs equal to the training inputs, the bound is the exact LML
/// (`Q_nn = K_nn`, no trace term) and the predictions are the exact GP's.
#[test]
fn equals_the_exact_gp_when_z_is_x() {
    let (x, y) = data(40, 3, 1);
    let xs: Vec<f64> = [0.3, -0.2, 1.1, -1.0, 0.5, 0.0, 1.9, 1.2, -1.7]
        .into_iter()
        .collect();
    let mut worst: f64 = 0.0;
    for (spec, mean) in kernels(3)
        .into_iter()
        .flat_map(|s| MeanFunction::ALL.map(|m| (s, m)))
    {
        let exact = fit(
            &GpParams {
                mean,
                ..fixed(spec, 0.05)
            },
            &x,
            &y,
        )
        .unwrap();
        let mut params = GpParams {
            mean,
            ..fixed(spec, 0.05)
        };
        params.sparse = Some(SparseParams {
            inducing_inputs: Some(x.clone()),
            ..SparseParams::new(40)
        });
        let sparse = fit(&params, &x, &y).unwrap();
        assert!(sparse.is_sparse() && !exact.is_sparse());
        assert_eq!(sparse.report().final_jitter, 0.0, "{spec:?}");
        worst = worst.max(rel(
            sparse.log_marginal_likelihood(),
            exact.log_marginal_likelihood(),
        ));
        let pe = exact.predict_many(&xs, Want::ALL).unwrap();
        let ps = sparse.predict_many(&xs, Want::ALL).unwrap();
        for (a, b) in pe.iter().zip(&ps) {
            worst = worst.max(rel(b.mean, a.mean));
            worst = worst.max(rel(b.variance, a.variance));
            for j in 0..3 {
                worst = worst
                    .max((b.grad_mean[j] - a.grad_mean[j]).abs() / (1.0 + a.grad_mean[j].abs()));
            }
        }
    }
    assert!(worst < 1e-8, "worst relative difference {worst:e}");
}

/// Fixed hyperparameters and inducing inputs: the bound, means and variances equal a direct
/// numpy implementation (dense `Q_nn`, no Cholesky tricks; `fixtures/make_sparse_gp.py`).
#[test]
fn matches_numpy_titsias_formulae() {
    let doc: serde_json::Value = serde_json::from_str(&fixture("sparse_gp_parity.json")).unwrap();
    let mut worst: f64 = 0.0;
    for case in doc["cases"].as_array().unwrap() {
        let d = case["d"].as_u64().unwrap() as usize;
        let m = case["m"].as_u64().unwrap() as usize;
        let ls = vecf(&case["length_scales"]);
        let mut theta = vec![case["signal_variance"].as_f64().unwrap().ln()];
        theta.extend(ls.iter().map(|l| l.ln()));
        let mut params = GpParams::new(KernelSpec::se_ard(d));
        params.optimize = false;
        params.normalize = false;
        params.init = Some(Hyperparameters {
            theta,
            noise_variance: case["noise"].as_f64().unwrap(),
        });
        params.sparse = Some(SparseParams {
            inducing_inputs: Some(vecf(&case["z"])),
            ..SparseParams::new(m)
        });
        let gp = fit(&params, &vecf(&case["x"]), &vecf(&case["y"])).unwrap();
        worst = worst.max(rel(
            gp.log_marginal_likelihood(),
            case["bound"].as_f64().unwrap(),
        ));
        let preds = gp.predict_many(&vecf(&case["x_test"]), Want::EKF).unwrap();
        for ((p, mean), var) in preds
            .iter()
            .zip(vecf(&case["mean"]))
            .zip(vecf(&case["var"]))
        {
            worst = worst.max(rel(p.mean, mean));
            worst = worst.max(rel(p.variance, var));
        }
    }
    assert!(worst < 1e-8, "worst relative difference {worst:e}");
}

/// Asserts that `bound`'s analytic gradient at `p` agrees with central differences of step
/// `h`: `|fd - analytic| < rel * (floor + |fd|)` for every parameter. The trial points must
/// need the same relative jitter as `p` (a difference across a change of jitter measures the
/// jitter, not the bound).
fn assert_gradient_matches(bound: &SparseBound<'_>, p: &[f64], h: f64, rel: f64, floor: f64) {
    let ev = bound.evaluate(p).unwrap();
    assert_eq!(ev.grad.len(), bound.n_params());
    for i in 0..p.len() {
        let (mut a, mut b) = (p.to_vec(), p.to_vec());
        a[i] += h;
        b[i] -= h;
        let (ea, eb) = (bound.evaluate(&a).unwrap(), bound.evaluate(&b).unwrap());
        assert_eq!(ea.relative_jitter, ev.relative_jitter, "parameter {i}");
        assert_eq!(eb.relative_jitter, ev.relative_jitter, "parameter {i}");
        let fd = (ea.lml - eb.lml) / (2.0 * h);
        assert!(
            (fd - ev.grad[i]).abs() < rel * (floor + fd.abs()),
            "parameter {i}: finite difference {fd} vs analytic {}",
            ev.grad[i]
        );
    }
}

/// Every analytic derivative (hyperparameters, noise, inducing inputs) agrees with central
/// finite differences, for every kernel family.
#[test]
fn gradients_match_finite_differences() {
    let (x, y) = data(150, 3, 2);
    let (mean, scale) = hbn_gp::column_stats(&x, 3);
    let xs: Vec<f64> = x
        .chunks_exact(3)
        .flat_map(|r| {
            (0..3)
                .map(|j| (r[j] - mean[j]) / scale[j])
                .collect::<Vec<_>>()
        })
        .collect();
    let ys: Vec<f64> = y.iter().map(|v| v * 0.8 - 0.1).collect();
    for spec in kernels(3) {
        let dirs: Vec<f64> = x.chunks_exact(3).map(|r| spec.direction_of(r)).collect();
        let whiten = if spec.metric == Metric::Mahalanobis {
            hbn_gp::whitening(&xs, 3)
        } else {
            Vec::new()
        };
        let m = 12;
        let z: Vec<f64> = xs[..m * 3].iter().map(|v| v + 0.05).collect();
        let zd = dirs[..m].to_vec();
        let bound = SparseBound::new(
            LikelihoodData {
                spec,
                whiten: &whiten,
                x: &xs,
                directions: &dirs,
                y: &ys,
            },
            z.clone(),
            zd,
            true,
            1e-6,
            8,
        );
        let mut p = vec![0.0; spec.n_params()];
        spec.default_theta(&mut p).unwrap();
        for (i, v) in p.iter_mut().enumerate() {
            *v += 0.1 * ((i as f64) * 1.7).sin();
        }
        p.push((0.05f64).ln());
        p.extend_from_slice(&z);
        assert_gradient_matches(&bound, &p, 1e-5, 1e-5, 1.0);
    }
}

/// On many samples, little noise and an ill-conditioned `K_mm` (greedily selected inducing
/// points under long length scales, the situation of a 10,000-sample search), the analytic
/// gradient still agrees with finite differences. Forming `K_mm^{-1} - Sigma` and
/// `W K_mn + beta y^T` as differences of large terms gives length-scale derivatives off by
/// hundreds there, where the true ones are a few units.
#[test]
fn gradients_stay_accurate_with_many_samples_and_an_ill_conditioned_k_mm() {
    let (n, d, m) = (20_000, 2, 64);
    let mut rng = Rng::new(7);
    let x: Vec<f64> = (0..n * d).map(|_| rng.uniform_in(-1.7, 1.7)).collect();
    let y: Vec<f64> = x
        .chunks_exact(d)
        .map(|r| (1.3 * r[0]).sin() + 0.5 * (0.8 * r[1]).cos() + 0.01 * rng.normal())
        .collect();
    let spec = KernelSpec::se_ard(d);
    let dirs = vec![0.0; n];
    let p = vec![0.5, 0.4, 0.6, (1e-4f64).ln()];
    let kernel = hbn_core::Kernel::new(spec, &p[..spec.n_params()], &[]).unwrap();
    let idx = greedy_variance_selection(&kernel, &x, &dirs, m);
    let z: Vec<f64> = idx
        .iter()
        .flat_map(|&i| x[i * d..i * d + d].iter().copied())
        .collect();
    let bound = SparseBound::new(
        LikelihoodData {
            spec,
            whiten: &[],
            x: &x,
            directions: &dirs,
            y: &y,
        },
        z,
        vec![0.0; idx.len()],
        false,
        1e-6,
        8,
    );
    assert_gradient_matches(&bound, &p, 1e-4, 1e-3, 10.0);
}

/// With duplicated inducing inputs `K_mm` is singular and is factorised with jitter (relative
/// to its mean diagonal, so it scales with the signal variance but not with the length
/// scales): the gradient still agrees with finite differences of the bound as evaluated.
#[test]
fn gradients_match_finite_differences_with_jitter_on_k_mm() {
    let (x, y) = data(300, 2, 5);
    let spec = KernelSpec::se_ard(2);
    let dirs = vec![0.0; 300];
    let mut z: Vec<f64> = x[..16].to_vec();
    z.extend_from_slice(&x[..4]); // two points repeated
    let bound = SparseBound::new(
        LikelihoodData {
            spec,
            whiten: &[],
            x: &x,
            directions: &dirs,
            y: &y,
        },
        z,
        vec![0.0; 10],
        false,
        1e-6,
        8,
    );
    let p = vec![0.3, 0.2, -0.1, (0.01f64).ln()];
    let ev = bound.evaluate(&p).unwrap();
    assert!(ev.jitter > 0.0, "the repeated points need jitter");
    assert_gradient_matches(&bound, &p, 1e-5, 1e-4, 1.0);
}

/// On noise-free data the bound over many samples pulls the signal variance toward the box
/// edge (a near-polynomial fit); `max_signal_variance` holds it at the value asked (in the
/// targets' variance), and the fit stays accurate. The sparse GP here; the exact GP below.
#[test]
fn max_signal_variance_holds_on_noise_free_data() {
    max_signal_variance_holds(Some(SparseParams::new(16)), 4000);
}

/// [`max_signal_variance_holds_on_noise_free_data`] for the exact GP.
#[test]
fn max_signal_variance_holds_for_the_exact_gp() {
    max_signal_variance_holds(None, 300);
}

fn max_signal_variance_holds(sparse: Option<SparseParams>, n: usize) {
    let mut rng = Rng::new(11);
    let x: Vec<f64> = (0..n).map(|_| rng.uniform_in(-2.0, 2.0)).collect();
    let y: Vec<f64> = x.iter().map(|v| v * v * v - v).collect();
    let fit_with = |max: Option<f64>| {
        let mut params = GpParams::new(KernelSpec::se_ard(1));
        params.n_starts = 1;
        params.max_signal_variance = max;
        params.sparse = sparse.clone();
        fit(&params, &x, &y).unwrap()
    };
    let free = fit_with(None);
    let bounded = fit_with(Some(100.0));
    assert!(
        free.theta()[0] > 100f64.ln() + 1.0,
        "free: {:?}",
        free.theta()
    );
    assert!(
        bounded.theta()[0] < 100f64.ln() + 0.01,
        "bounded: {:?}",
        bounded.theta()
    );
    // The report says so (and only then).
    assert_eq!(
        bounded.report().signal_variance_at_bound,
        Some(100f64.ln().exp())
    );
    assert!(
        bounded
            .report()
            .warnings()
            .iter()
            .any(|w| w.contains("signal variance ended at its upper bound"))
    );
    assert_eq!(free.report().signal_variance_at_bound, None);
    // Still an accurate fit inside the data.
    for i in 0..41 {
        let xv = -1.9 + 0.095 * i as f64;
        let m = bounded.predict(&[xv], Want::default()).unwrap().mean;
        let truth = xv * xv * xv - xv;
        assert!((m - truth).abs() < 1e-2, "at {xv}: {m} vs {truth}");
    }
}

/// The bound never exceeds the exact log marginal likelihood, and grows toward it as
/// inducing points are added.
#[test]
fn bound_is_below_the_exact_lml() {
    let (x, y) = data(120, 2, 3);
    for spec in kernels(2) {
        let exact = fit(&fixed(spec, 0.02), &x, &y).unwrap();
        let mut last = f64::NEG_INFINITY;
        for m in [4, 16, 60] {
            let mut params = fixed(spec, 0.02);
            params.sparse = Some(SparseParams::new(m));
            let sparse = fit(&params, &x, &y).unwrap();
            let b = sparse.log_marginal_likelihood();
            assert!(
                b <= exact.log_marginal_likelihood() + 1e-9,
                "{spec:?} m={m}: bound {b} > exact {}",
                exact.log_marginal_likelihood()
            );
            assert!(
                b >= last - 1e-6,
                "{spec:?}: bound fell from {last} to {b} at m={m}"
            );
            last = b;
        }
    }
}

/// Optimised training: bit-identical across runs and across thread counts, and close to the
/// exact GP on held-out points.
#[test]
fn training_is_deterministic_and_accurate() {
    let (x, y) = data(3000, 2, 4);
    let mut params = GpParams::new(KernelSpec::se_ard(2));
    params.n_starts = 2;
    params.sparse = Some(SparseParams::new(40));
    let a = fit(&params, &x, &y).unwrap();
    let one_thread = rayon::ThreadPoolBuilder::new()
        .num_threads(1)
        .build()
        .unwrap();
    let b = one_thread.install(|| fit(&params, &x, &y).unwrap());
    // Timings differ; everything numerical must not.
    let numbers = |gp: &GaussianProcess| {
        let mut v: serde_json::Value = serde_json::from_str(&gp.to_json().unwrap()).unwrap();
        v["gp"]["report"]["seconds"] = 0.into();
        v
    };
    assert_eq!(numbers(&a), numbers(&b));
    let (xt, yt) = data(200, 2, 5);
    let preds = a.predict_many(&xt, Want::EKF).unwrap();
    let mse: f64 = preds
        .iter()
        .zip(&yt)
        .map(|(p, t)| (p.mean - t).powi(2))
        .sum::<f64>()
        / yt.len() as f64;
    // Noise variance 0.0025: the sparse GP on all samples should be near it.
    assert!(mse < 0.005, "held-out mse {mse}");
    assert!(a.noise_variance() < 0.005 && a.noise_variance() > 0.001);
}

/// With more samples than the search subset, the starts run on the subset and L-BFGS refines
/// the winner on every sample: the refined bound is at least the search optimum's bound on
/// all samples, and the report says what ran.
#[test]
fn large_data_search_on_a_subset_then_refine_on_all() {
    let (x, y) = data(6000, 2, 10);
    let mut params = GpParams::new(KernelSpec::se_ard(2));
    params.n_starts = 1;
    params.sparse = Some(SparseParams {
        search_samples: 1500,
        ..SparseParams::new(24)
    });
    let gp = fit(&params, &x, &y).unwrap();
    let r = gp.report();
    assert_eq!(r.search_samples, Some(1500));
    assert_eq!(r.n_samples, 6000);
    let refine = r.refinement.as_ref().expect("refinement ran");
    assert!(refine.error.is_none());
    assert!(refine.final_lml.unwrap() >= refine.initial_lml.unwrap());
    assert_eq!(gp.log_marginal_likelihood(), refine.final_lml.unwrap());
}

/// A failed trial step of the line search (a covariance that is not positive definite at an
/// absurd length scale) must not end the start: every start moves far from its initial point
/// (rather than stopping after one iteration at its initial bound).
#[test]
fn failed_trial_steps_do_not_end_the_optimisation() {
    let (x, _) = data(600, 2, 11);
    let y: Vec<f64> = x.chunks_exact(2).map(|r| r[0] * r[0] - r[1]).collect();
    let mut params = GpParams::new(KernelSpec::se_ard(2));
    params.sparse = Some(SparseParams::new(6));
    let gp = fit(&params, &x, &y).unwrap();
    for s in &gp.report().starts {
        assert!(s.iterations > 3, "{s:?}");
        assert!(
            s.final_lml.unwrap() > s.initial_lml.unwrap() + 100.0,
            "{s:?}"
        );
    }
}

/// Learning Z never lowers the bound reached with Z fixed.
#[test]
fn optimising_inducing_inputs_raises_the_bound() {
    let (x, y) = data(800, 2, 6);
    let mut params = GpParams::new(KernelSpec::se_ard(2));
    params.n_starts = 1;
    params.max_iters = 60;
    params.sparse = Some(SparseParams::new(8));
    let fixed_z = fit(&params, &x, &y).unwrap();
    params.sparse = Some(SparseParams {
        optimize_inducing: true,
        ..SparseParams::new(8)
    });
    let learned = fit(&params, &x, &y).unwrap();
    assert!(
        learned.log_marginal_likelihood() > fixed_z.log_marginal_likelihood(),
        "learned {} vs fixed {}",
        learned.log_marginal_likelihood(),
        fixed_z.log_marginal_likelihood()
    );
    assert_ne!(learned.support_inputs(), fixed_z.support_inputs());
}

/// Greedy selection skips duplicates and reports fewer points when the data have fewer
/// distinct inputs.
#[test]
fn greedy_selection_skips_duplicates() {
    let (x, _) = data(10, 2, 7);
    let repeated: Vec<f64> = (0..5).flat_map(|_| x.iter().copied()).collect();
    let spec = KernelSpec::se_ard(2);
    let theta = vec![0.0; spec.n_params()];
    let kernel = hbn_core::Kernel::new(spec, &theta, &[]).unwrap();
    let idx = greedy_variance_selection(&kernel, &repeated, &[0.0; 50], 20);
    assert_eq!(idx.len(), 10);
    let mut firsts: Vec<usize> = idx.iter().map(|i| i % 10).collect();
    firsts.sort_unstable();
    assert_eq!(firsts, (0..10).collect::<Vec<_>>());

    let y: Vec<f64> = repeated.chunks_exact(2).map(|r| r[0] - r[1]).collect();
    let mut params = fixed(spec, 0.05);
    params.sparse = Some(SparseParams::new(20));
    let gp = fit(&params, &repeated, &y).unwrap();
    assert_eq!(gp.n_support(), 10);
    assert!(
        gp.report()
            .warnings()
            .iter()
            .any(|w| w.contains("inducing points")),
        "{:?}",
        gp.report().warnings()
    );
}

#[test]
fn persistence_round_trips_and_files_of_format_1_load() {
    let (x, y) = data(300, 2, 8);
    let mut params = fixed(KernelSpec::se_ard(2), 0.05);
    params.sparse = Some(SparseParams::new(16));
    let gp = fit(&params, &x, &y).unwrap();
    let text = gp.to_json().unwrap();
    let back = GaussianProcess::from_json(&text, "mem").unwrap();
    assert_eq!(gp, back);
    assert!(back.is_sparse());
    // A linear mean's slopes are written and read back.
    let tilted = fit(
        &GpParams {
            mean: MeanFunction::Linear,
            ..params.clone()
        },
        &x,
        &y,
    )
    .unwrap();
    assert_eq!(tilted.linear_mean().len(), 2);
    let back = GaussianProcess::from_json(&tilted.to_json().unwrap(), "mem").unwrap();
    assert_eq!(tilted, back);
    let at = [0.3, -0.7];
    assert_eq!(
        back.predict(&at, Want::ALL).unwrap(),
        tilted.predict(&at, Want::ALL).unwrap()
    );
    // A version-1 file (exact GPs only, no `sparse` field).
    let exact = fit(&fixed(KernelSpec::se_ard(2), 0.05), &x[..60], &y[..30]).unwrap();
    let mut v: serde_json::Value = serde_json::from_str(&exact.to_json().unwrap()).unwrap();
    v["version"] = 1.into();
    v["gp"].as_object_mut().unwrap().remove("sparse");
    let old = GaussianProcess::from_json(&v.to_string(), "old").unwrap();
    assert_eq!(old, exact);
    // The file carries the one folded factor, not the two of format 3.
    let value: serde_json::Value = serde_json::from_str(&text).unwrap();
    let sparse = &value["gp"]["sparse"];
    assert_eq!(
        sparse["variance_factor"].as_array().unwrap().len(),
        16 * 17 / 2
    );
    assert!(sparse.get("kmm_inv_factor").is_none() && sparse.get("sigma_factor").is_none());
    // A sparse file whose factor is cut short is refused with a format error.
    let mut bad = value.clone();
    bad["gp"]["sparse"]["variance_factor"]
        .as_array_mut()
        .unwrap()
        .pop();
    assert!(matches!(
        GaussianProcess::from_json(&bad.to_string(), "bad"),
        Err(GpError::Format { .. })
    ));
}

/// Sparse GP files of format 3 carry two factors, `L^{-1}` and `L_B^{-1} L^{-1}`; loading
/// folds them into one. `fixtures/sparse_gp_format3.json` holds two such files (SE with noise
/// 0.05 and m = 16; Matern 5/2 with noise 1e-4 and m = 32, where the two quadratic forms are
/// large and nearly cancel) and the predictions of their two-factor form at 20 points, inside
/// and outside the data. The folded GP predicts the same, to rounding.
#[test]
fn sparse_files_of_format_3_load_folded_and_predict_as_their_two_factors() {
    let text = std::fs::read_to_string(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../../fixtures/sparse_gp_format3.json"
    ))
    .unwrap();
    let cases: Vec<serde_json::Value> = serde_json::from_str(&text).unwrap();
    assert_eq!(cases.len(), 2);
    for case in &cases {
        assert_eq!(case["file"]["version"], 3);
        assert!(case["file"]["gp"]["sparse"].get("sigma_factor").is_some());
        let gp = GaussianProcess::from_json(&case["file"].to_string(), "format 3").unwrap();
        let points: Vec<f64> = case["points"]
            .as_array()
            .unwrap()
            .iter()
            .flat_map(vecf)
            .collect();
        let preds = gp.predict_many(&points, Want::EKF).unwrap();
        let (means, vars) = (vecf(&case["mean"]), vecf(&case["variance"]));
        let prior = preds.iter().map(|p| p.prior_variance).fold(0.0, f64::max);
        for ((p, m), v) in preds.iter().zip(&means).zip(&vars) {
            // The mean's formula is the two-factor form's; the kernel's exponential
            // (`exp_nonpositive`, within 2 ulp of libm's) moves it by rounding only.
            assert!(
                (p.mean - m).abs() <= 1e-13 * m.abs().max(1.0),
                "the mean does not change: {} vs {m}",
                p.mean
            );
            // The variance comes from one factor: equal to rounding, relative to the prior.
            assert!(
                (p.variance - v).abs() <= 1e-10 * prior,
                "variance {} vs {v} (prior {prior})",
                p.variance
            );
        }
        // Saved again, it is a file of the current format with the folded factor, and
        // reloads as is.
        let again = GaussianProcess::from_json(&gp.to_json().unwrap(), "again").unwrap();
        assert_eq!(again, gp);
    }
}

#[test]
fn bad_input_gives_typed_errors() {
    let (x, y) = data(50, 2, 9);
    let mut params = GpParams::new(KernelSpec::se_ard(2));
    params.sparse = Some(SparseParams::new(0));
    assert!(matches!(
        fit(&params, &x, &y),
        Err(GpError::InvalidParameter {
            name: "n_inducing",
            ..
        })
    ));
    params.sparse = Some(SparseParams {
        inducing_inputs: Some(vec![0.0; 5]),
        ..SparseParams::new(3)
    });
    assert!(matches!(
        fit(&params, &x, &y),
        Err(GpError::InvalidParameter {
            name: "inducing_inputs",
            ..
        })
    ));
    for bad in [0.0, -1.0, f64::NAN, f64::INFINITY] {
        params.sparse = Some(SparseParams::new(3));
        params.max_signal_variance = Some(bad);
        assert!(matches!(
            fit(&params, &x, &y),
            Err(GpError::InvalidParameter {
                name: "max_signal_variance",
                ..
            })
        ));
    }
    params.max_signal_variance = None;
    // An absurd number of inducing points is capped by the data, not an allocation failure.
    params.sparse = Some(SparseParams::new(usize::MAX));
    params.n_starts = 1;
    params.max_iters = 5;
    let gp = fit(&params, &x, &y).unwrap();
    assert!(gp.n_support() <= 50);
    params.sparse = Some(SparseParams::new(8));
    let mut xn = x.clone();
    xn[7] = f64::NAN;
    assert!(matches!(
        fit(&params, &xn, &y),
        Err(GpError::NonFinite { .. })
    ));
    assert!(matches!(
        fit(&params, &x, &vec![1.0; 50]),
        Err(GpError::ConstantTargets { .. })
    ));
    assert!(matches!(
        fit(&params, &x[..3], &y[..1]),
        Err(GpError::TooFewSamples { .. }) | Err(GpError::Shape { .. })
    ));
}
