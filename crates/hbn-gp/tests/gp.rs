//! GP engine tests: scikit-learn parity, analytic gradients, optimisation, jitter, persistence
//! and bad input.

use hbn_core::rng::Rng;
use hbn_core::{KernelSpec, Metric, Profile, Want};
use hbn_gp::likelihood::{Likelihood, LikelihoodData};
use hbn_gp::{
    GaussianProcess, GpError, GpParams, Hyperparameters, MeanFunction, SparseParams, SubsetPolicy,
    fit,
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

/// Fixed hyperparameters: mean, std and LML equal scikit-learn's to 1e-6 relative or better.
#[test]
fn matches_scikit_learn_with_fixed_hyperparameters() {
    let doc: serde_json::Value = serde_json::from_str(&fixture("sklearn_gp_parity.json")).unwrap();
    let mut worst: f64 = 0.0;
    for case in doc["cases"].as_array().unwrap() {
        let d = case["d"].as_u64().unwrap() as usize;
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
        let gp = fit(&params, &vecf(&case["x"]), &vecf(&case["y"])).unwrap();
        assert_eq!(gp.report().final_jitter, 0.0);
        let lml = case["lml"].as_f64().unwrap();
        worst = worst.max(rel(gp.log_marginal_likelihood(), lml));
        let preds = gp.predict_many(&vecf(&case["x_test"]), Want::ALL).unwrap();
        for ((p, m), s) in preds
            .iter()
            .zip(vecf(&case["mean"]))
            .zip(vecf(&case["std"]))
        {
            worst = worst.max(rel(p.mean, m));
            worst = worst.max(rel(p.variance.sqrt(), s));
        }
    }
    assert!(
        worst < 1e-9,
        "worst relative error vs scikit-learn: {worst:e}"
    );
}

fn toy(n: usize, d: usize, seed: u64) -> (Vec<f64>, Vec<f64>) {
    let mut rng = Rng::new(seed);
    let x: Vec<f64> = (0..n * d).map(|_| rng.uniform_in(-2.0, 2.0)).collect();
    let y = x
        .chunks_exact(d)
        .map(|r| {
            r.iter()
                .enumerate()
                .map(|(j, v)| (v * (1.0 + 0.3 * j as f64)).sin())
                .sum::<f64>()
                + 0.05 * rng.normal()
        })
        .collect();
    (x, y)
}

fn kernels(d: usize) -> Vec<KernelSpec> {
    vec![
        KernelSpec::se_ard(d),
        KernelSpec {
            metric: Metric::Isotropic,
            ..KernelSpec::se_ard(d)
        },
        KernelSpec {
            profile: Profile::Matern52,
            ..KernelSpec::se_ard(d)
        },
        KernelSpec {
            metric: Metric::Mahalanobis,
            warp_units: 2,
            direction: Some([0, 1]),
            ..KernelSpec::se_ard(d)
        },
        KernelSpec {
            warp_units: 1,
            profile: Profile::Matern52,
            direction: Some([2, 0]),
            ..KernelSpec::se_ard(d)
        },
    ]
}

/// The analytic LML gradient (every kernel hyperparameter and the noise) agrees with central
/// finite differences.
#[test]
fn likelihood_gradient_matches_finite_differences() {
    let d = 3;
    let (x, y) = toy(40, d, 1);
    for spec in kernels(d) {
        let dirs: Vec<f64> = x.chunks_exact(d).map(|r| spec.direction_of(r)).collect();
        let whiten = if spec.metric == Metric::Mahalanobis {
            hbn_gp::whitening(&x, d)
        } else {
            vec![]
        };
        let lik = Likelihood::new(
            LikelihoodData {
                spec,
                whiten: &whiten,
                x: &x,
                directions: &dirs,
                y: &y,
            },
            1e-6,
            4,
        );
        let mut p: Vec<f64> = (0..lik.n_params())
            .map(|i| 0.3 * (1.3 * i as f64).sin())
            .collect();
        let last = p.len() - 1;
        p[last] = (0.05f64).ln();
        let ev = lik.evaluate(&p).unwrap();
        for i in 0..p.len() {
            let h = 1e-5;
            let (mut a, mut b) = (p.clone(), p.clone());
            a[i] += h;
            b[i] -= h;
            let fd = (lik.evaluate(&a).unwrap().lml - lik.evaluate(&b).unwrap().lml) / (2.0 * h);
            assert!(
                (fd - ev.grad[i]).abs() < 1e-5 * (1.0 + fd.abs()),
                "{spec:?} param {i}: fd {fd} analytic {}",
                ev.grad[i]
            );
        }
    }
}

#[test]
fn optimisation_raises_the_likelihood_and_fits_the_function() {
    let (x, y) = toy(150, 2, 2);
    for spec in kernels(2).into_iter().take(3) {
        let mut params = GpParams::new(spec);
        params.n_starts = 2;
        let gp = fit(&params, &x, &y).unwrap();
        let r = gp.report();
        assert_eq!(r.starts.len(), 2);
        for s in &r.starts {
            if let (Some(a), Some(b)) = (s.initial_lml, s.final_lml) {
                assert!(b >= a - 1e-9, "{spec:?}: start went from {a} to {b}");
            }
        }
        let best = r
            .starts
            .iter()
            .filter_map(|s| s.final_lml)
            .fold(f64::NEG_INFINITY, f64::max);
        assert!((gp.log_marginal_likelihood() - best).abs() < 1e-6 * best.abs().max(1.0));
        // Noise level recovered roughly (true sd 0.05 in raw units).
        let sd = gp.noise_variance().sqrt();
        assert!(sd > 0.02 && sd < 0.12, "{spec:?}: noise sd {sd}");
        let p = gp.predict(&[0.5, -1.0], Want::EKF).unwrap();
        let truth = 0.5f64.sin() + (-1.3f64).sin();
        assert!(
            (p.mean - truth).abs() < 0.1,
            "{spec:?}: {} vs {truth}",
            p.mean
        );
    }
}

#[test]
fn duplicate_inputs_with_zero_noise_use_reported_jitter() {
    let x = vec![0.0, 0.0, 1.0, 1.0, 2.0];
    let y = vec![0.0, 0.0, 1.0, 1.0, 0.5];
    let mut params = GpParams::new(KernelSpec::se_ard(1));
    params.optimize = false;
    params.init = Some(Hyperparameters {
        theta: vec![0.0, 0.0],
        noise_variance: 0.0,
    });
    let gp = fit(&params, &x, &y).unwrap();
    assert!(gp.report().final_jitter > 0.0);
    assert!(!gp.report().warnings().is_empty());
    assert!(gp.predict(&[0.5], Want::ALL).unwrap().mean.is_finite());
    // With no retries allowed the same problem is a typed error.
    params.max_jitter_retries = 0;
    assert!(matches!(
        fit(&params, &x, &y),
        Err(GpError::NotPositiveDefinite { .. })
    ));
}

#[test]
fn save_and_load_predict_bit_identically() {
    let (x, y) = toy(80, 3, 3);
    let spec = KernelSpec {
        metric: Metric::Mahalanobis,
        warp_units: 1,
        direction: Some([0, 1]),
        ..KernelSpec::se_ard(3)
    };
    let mut params = GpParams::new(spec);
    params.n_starts = 1;
    params.max_iters = 30;
    let gp = fit(&params, &x, &y).unwrap();
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("gp.json");
    gp.save(&path).unwrap();
    let back = GaussianProcess::load(&path).unwrap();
    assert_eq!(gp, back);
    let probe: Vec<f64> = (0..30).map(|i| (i as f64 * 0.37).sin() * 2.0).collect();
    let a = gp.predict_many(&probe, Want::ALL).unwrap();
    let b = back.predict_many(&probe, Want::ALL).unwrap();
    for (p, q) in a.iter().zip(&b) {
        assert_eq!(p.mean.to_bits(), q.mean.to_bits());
        assert_eq!(p.variance.to_bits(), q.variance.to_bits());
        assert_eq!(p.grad_mean, q.grad_mean);
    }
    // Wrong format tag and wrong version are typed errors naming the file.
    std::fs::write(&path, "{\"format\":\"other\",\"version\":1}").unwrap();
    let e = GaussianProcess::load(&path).unwrap_err().to_string();
    assert!(e.contains("gp.json") && e.contains("not an hbn GP"), "{e}");
    let text = gp.to_json().unwrap().replacen(
        &format!("\"version\":{}", hbn_gp::GP_FORMAT_VERSION),
        "\"version\":99",
        1,
    );
    std::fs::write(&path, text).unwrap();
    assert!(
        GaussianProcess::load(&path)
            .unwrap_err()
            .to_string()
            .contains("version 99")
    );
    std::fs::write(&path, "garbage").unwrap();
    assert!(matches!(
        GaussianProcess::load(&path),
        Err(GpError::Format { .. })
    ));
}

#[test]
fn large_data_use_a_reported_subset() {
    let (x, y) = toy(300, 2, 4);
    for policy in [SubsetPolicy::FarthestPoint, SubsetPolicy::Random] {
        let mut params = GpParams::new(KernelSpec::se_ard(2));
        params.max_points = 100;
        params.subset_policy = policy;
        params.n_starts = 1;
        let gp = fit(&params, &x, &y).unwrap();
        assert_eq!(gp.n_support(), 100);
        assert_eq!(gp.report().n_samples, 300);
        assert_eq!(gp.report().subset_policy, Some(policy));
        // A subset is normal for the exact GP on a long log: a note, not a warning.
        let note = gp.report().subset_note().expect("the subset is reported");
        assert!(note.contains("from 300 samples"), "{note}");
        assert!(
            gp.report().warnings().is_empty(),
            "{:?}",
            gp.report().warnings()
        );
    }
}

#[test]
fn bad_input_gives_typed_errors() {
    let p = GpParams::new(KernelSpec::se_ard(2));
    assert!(matches!(
        fit(&p, &[], &[]),
        Err(GpError::TooFewSamples { .. })
    ));
    assert!(matches!(
        fit(&p, &[1.0, 2.0, 3.0], &[1.0, 2.0]),
        Err(GpError::Shape { .. })
    ));
    assert!(matches!(
        fit(&p, &[1.0, 2.0, f64::NAN, 0.0], &[1.0, 2.0]),
        Err(GpError::NonFinite { row: 1, .. })
    ));
    assert!(matches!(
        fit(&p, &[1.0, 2.0, 3.0, 0.0], &[1.0, 1.0]),
        Err(GpError::ConstantTargets { .. })
    ));
    let mut bad = p.clone();
    bad.noise_floor = 0.0;
    assert!(matches!(
        fit(&bad, &[1.0, 2.0, 3.0, 0.0], &[1.0, 2.0]),
        Err(GpError::InvalidParameter {
            name: "noise_floor",
            ..
        })
    ));
    let mut bad = p.clone();
    bad.init = Some(Hyperparameters {
        theta: vec![0.0],
        noise_variance: 0.1,
    });
    assert!(matches!(
        fit(&bad, &[1.0, 2.0, 3.0, 0.0], &[1.0, 2.0]),
        Err(GpError::InvalidParameter { .. })
    ));
    let bad = GpParams::new(KernelSpec::se_ard(0));
    assert!(matches!(
        fit(&bad, &[1.0, 2.0], &[1.0, 2.0]),
        Err(GpError::Core(_))
    ));
}

/// The optimiser keeps log-hyperparameters inside the soft bounds even on data that push a
/// Matern kernel towards huge length scales (smooth data, tiny noise).
#[test]
fn hyperparameters_stay_bounded() {
    let x: Vec<f64> = (0..120).map(|i| i as f64 / 119.0).collect();
    let y: Vec<f64> = x.iter().map(|v| 2.0 * v + 0.5).collect();
    let mut params = GpParams::new(KernelSpec {
        profile: Profile::Matern52,
        ..KernelSpec::se_ard(1)
    });
    params.n_starts = 3;
    let gp = fit(&params, &x, &y).unwrap();
    let bound = hbn_gp::likelihood::LOG_BOUND + 0.5;
    assert!(
        gp.theta().iter().all(|t| t.abs() <= bound),
        "theta {:?}",
        gp.theta()
    );
    let p = gp.predict(&[0.37], Want::ALL).unwrap();
    assert!((p.mean - 1.24).abs() < 1e-3, "{}", p.mean);
}

/// Training is bit-for-bit reproducible (parallel reductions have a fixed order).
#[test]
fn training_is_deterministic() {
    let (x, y) = toy(200, 3, 8);
    let mut params = GpParams::new(KernelSpec::se_ard(3));
    params.n_starts = 2;
    let a = fit(&params, &x, &y).unwrap();
    let b = fit(&params, &x, &y).unwrap();
    assert_eq!(a.theta(), b.theta());
    assert_eq!(
        a.log_marginal_likelihood().to_bits(),
        b.log_marginal_likelihood().to_bits()
    );
}

/// Saved models are ordinary readable files (0644), not owner-only temporaries.
#[cfg(unix)]
#[test]
fn saved_files_are_world_readable() {
    use std::os::unix::fs::PermissionsExt;
    let (x, y) = toy(20, 1, 9);
    let mut params = GpParams::new(KernelSpec::se_ard(1));
    params.n_starts = 1;
    let gp = fit(&params, &x, &y).unwrap();
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("gp.json");
    gp.save(&path).unwrap();
    assert_eq!(
        std::fs::metadata(&path).unwrap().permissions().mode() & 0o777,
        0o644
    );
}

/// Each optimiser start reports why it stopped: the iteration limit when it is tiny, and
/// convergence when the limit is generous.
#[test]
fn termination_is_reported_per_start() {
    let x: Vec<f64> = (0..40).map(|i| i as f64 / 8.0).collect();
    let y: Vec<f64> = x.iter().map(|v| v.sin()).collect();
    let mut p = GpParams::new(KernelSpec::se_ard(1));
    for (max_iters, want) in [
        (1, hbn_gp::Termination::MaxIters),
        (500, hbn_gp::Termination::Converged),
    ] {
        p.n_starts = 2;
        p.max_iters = max_iters;
        let mut seen = Vec::new();
        hbn_gp::fit_observed(&p, &x, &y, &mut |prog| {
            seen.push((prog.start, prog.termination.clone()))
        })
        .unwrap();
        assert_eq!(seen.len(), 2);
        assert_eq!(seen[0].0, 0);
        assert_eq!(seen[0].1, want, "max_iters {max_iters}");
    }
}

/// A linear prior mean: on a plane plus a small wiggle, the fitted slopes are the plane's, the
/// kernel sees only the wiggle (its output scale is the wiggle's, not the plane's), and far
/// outside the data the prediction follows the plane, where a constant-mean GP falls back to
/// the targets' mean. Exact and sparse alike; a constant mean has no slopes.
#[test]
fn linear_mean_follows_the_plane_outside_the_data() {
    let mut rng = Rng::new(5);
    let n = 400;
    let x: Vec<f64> = (0..2 * n).map(|_| rng.uniform_in(-1.0, 1.0)).collect();
    let plane = |r: &[f64]| 2.0 * r[0] - 3.0 * r[1] + 0.5;
    let y: Vec<f64> = x
        .chunks_exact(2)
        .map(|r| plane(r) + 0.1 * (4.0 * r[0]).sin() + 0.01 * rng.normal())
        .collect();
    let far = [6.0, -4.0];
    for sparse in [None, Some(SparseParams::new(32))] {
        let base = GpParams {
            sparse: sparse.clone(),
            n_starts: 1,
            ..GpParams::new(KernelSpec::se_ard(2))
        };
        let constant = fit(&base, &x, &y).unwrap();
        assert!(constant.linear_mean().is_empty());
        let linear = fit(
            &GpParams {
                mean: MeanFunction::Linear,
                ..base
            },
            &x,
            &y,
        )
        .unwrap();
        let slopes = linear.linear_mean();
        assert!(
            (slopes[0] - 2.0).abs() < 0.1 && (slopes[1] + 3.0).abs() < 0.05,
            "{slopes:?}"
        );
        let (_, scale) = linear.output_standardisation();
        assert!(
            scale < 0.15,
            "the kernel models the wiggle only: scale {scale}"
        );
        let p = linear.predict(&far, Want::EKF).unwrap();
        assert!(
            (p.mean - plane(&far)).abs() < 1.5,
            "{} vs {}",
            p.mean,
            plane(&far)
        );
        assert!((p.grad_mean[0] - slopes[0]).abs() < 1e-6);
        let q = constant.predict(&far, Want::EKF).unwrap();
        assert!((q.mean - plane(&far)).abs() > 10.0, "{}", q.mean);
        // Inside the data both fit.
        for r in x.chunks_exact(2).take(20) {
            let m = linear.predict(r, Want::MEAN).unwrap().mean;
            assert!((m - plane(r) - 0.1 * (4.0 * r[0]).sin()).abs() < 0.03);
        }
    }
}
