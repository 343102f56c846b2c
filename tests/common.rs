//! Shared helpers of the end-to-end tests: the thesis protocol of `hbn_pipeline::experiment`,
//! in small, and the CLI run in-process.
#![allow(dead_code)]

use hbn::model::{HbnParams, HysteresisModel, Selection};
use hbn::pipeline::experiment::{ExperimentConfig, test_trajectory, training_set};
use hbn::pipeline::sequences;
use hbn::sim::{SystemKind, Trajectory};

/// Runs `hbn ARGS` in-process; returns the error line `main` would print (if any) and stdout.
pub fn hbn(args: &[&str]) -> (Option<String>, String) {
    let mut out = Vec::new();
    let mut err = Vec::new();
    let full: Vec<&str> = std::iter::once("hbn").chain(args.iter().copied()).collect();
    let r = hbn_cli::run_with(full, &mut out, &mut err);
    (
        r.err().map(|e| hbn_cli::error_message(&e)),
        String::from_utf8_lossy(&out).into_owned(),
    )
}

fn config(max_points: usize, seed: u64, test_steps: usize) -> ExperimentConfig {
    ExperimentConfig {
        train_steps: 600,
        repeats: 3,
        test_steps,
        params: HbnParams {
            max_points,
            n_starts: 1,
            max_iters: 60,
            seed,
            ..HbnParams::default()
        },
        ..ExperimentConfig::default()
    }
}

/// One training input repeated with fresh noise, fitted with the default parameters (model
/// selection included).
pub fn train_model(
    system: SystemKind,
    noise_gain: f64,
    max_points: usize,
    seed: u64,
) -> (HysteresisModel, Vec<Trajectory>) {
    train_model_with(system, noise_gain, max_points, seed, |_| {})
}

/// [`train_model`] with the GP kind given and no model selection: `Some(m)` inducing points,
/// or `None` for exact GPs on `max_points` support points.
pub fn train_model_kind(
    system: SystemKind,
    noise_gain: f64,
    max_points: usize,
    n_inducing: Option<usize>,
    seed: u64,
) -> (HysteresisModel, Vec<Trajectory>) {
    let mut cfg = config(max_points, seed, 0);
    cfg.params.n_inducing = n_inducing;
    // This kind only: no model selection between exact and sparse GPs.
    cfg.params.select = Selection::default();
    let runs = training_set(system, noise_gain, seed, &cfg).unwrap();
    (
        HysteresisModel::fit(&sequences(&runs), &cfg.params).unwrap(),
        runs,
    )
}

/// [`train_model`] with the parameters changed by `change` first.
pub fn train_model_with(
    system: SystemKind,
    noise_gain: f64,
    max_points: usize,
    seed: u64,
    change: impl FnOnce(&mut HbnParams),
) -> (HysteresisModel, Vec<Trajectory>) {
    let mut cfg = config(max_points, seed, 0);
    change(&mut cfg.params);
    let runs = training_set(system, noise_gain, seed, &cfg).unwrap();
    (
        HysteresisModel::fit(&sequences(&runs), &cfg.params).unwrap(),
        runs,
    )
}

/// A fresh test run of `steps` samples.
pub fn test_run(system: SystemKind, noise_gain: f64, steps: usize, seed: u64) -> Trajectory {
    test_trajectory(system, noise_gain, seed, &config(0, seed, steps)).unwrap()
}
