//! Shared helpers of the end-to-end tests.
#![allow(dead_code)]

use hbn::model::{HbnModel, HbnParams, Sequence};
use hbn::sim::{InputKind, SimConfig, SystemKind, Trajectory, generate_input, simulate};

/// The thesis protocol in small: one training input repeated with fresh noise.
pub fn train_model(
    system: SystemKind,
    noise_gain: f64,
    max_points: usize,
    seed: u64,
) -> (HbnModel, Vec<Trajectory>) {
    let u = generate_input(InputKind::RandomRamps, 600, 0.02, seed).unwrap();
    let runs: Vec<Trajectory> = (0..3)
        .map(|r| {
            simulate(
                &SimConfig {
                    system,
                    noise_gain,
                    rate_hz: 100.0,
                    seed: seed * 100 + r,
                },
                &u,
            )
            .unwrap()
        })
        .collect();
    let seqs: Vec<Sequence<'_>> = runs
        .iter()
        .map(|t| Sequence {
            u: &t.u,
            x: &t.x,
            y: &t.y,
        })
        .collect();
    let params = HbnParams {
        max_points,
        n_starts: 1,
        max_iters: 60,
        seed,
        ..HbnParams::default()
    };
    (HbnModel::fit(&seqs, &params).unwrap(), runs)
}

/// A fresh test run of `steps` samples.
pub fn test_run(system: SystemKind, noise_gain: f64, steps: usize, seed: u64) -> Trajectory {
    let u = generate_input(InputKind::RandomRamps, steps, 0.02, seed + 1000).unwrap();
    simulate(
        &SimConfig {
            system,
            noise_gain,
            rate_hz: 100.0,
            seed: seed + 2000,
        },
        &u,
    )
    .unwrap()
}
