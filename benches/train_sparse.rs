//! Training time of the default (sparse) HBN on many samples: both GPs (d = 4 and 3) with
//! `m` inducing points on every sample of simulated logs.
//!
//! `cargo bench --bench train_sparse -- [SAMPLES] [M]` (defaults 100000 and 128). Prints one
//! line per run: samples, m, seconds for both GPs, and the training report's figures, after
//! a timeline: when each GP's search starts ended (the refinement on every sample, the
//! held-out refits and the filter tuning follow). `LINEAR_MEAN=none|transition|both` and
//! `MAX_SIGNAL_VARIANCE=v` in the environment set [`HbnParams::linear_mean`] and
//! [`HbnParams::max_signal_variance`].

use hbn::model::{HbnParams, HysteresisModel, Selection, Sequence};
use hbn::sim::{InputKind, SimConfig, SystemKind, generate_input, simulate};
use std::time::Instant;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    // `cargo bench` passes `--bench`; keep only the numbers.
    let nums: Vec<usize> = std::env::args()
        .skip(1)
        .filter_map(|a| a.parse().ok())
        .collect();
    let samples = nums.first().copied().unwrap_or(100_000);
    let m = nums.get(1).copied().unwrap_or(128);
    // Ten logs of a soft actuator driven by different random inputs.
    let logs = 10;
    let per_log = samples / logs;
    let runs = (0..logs as u64)
        .map(|i| {
            let u = generate_input(
                InputKind::RandomRamps,
                per_log,
                hbn::sim::DEFAULT_MAX_INCREMENT,
                100 + i,
            )?;
            let sim = SimConfig {
                system: SystemKind::SoftActuator,
                noise_gain: 1.0,
                rate_hz: 100.0,
                seed: 200 + i,
            };
            Ok(simulate(&sim, &u)?)
        })
        .collect::<Result<Vec<_>, Box<dyn std::error::Error>>>()?;
    let seqs: Vec<Sequence<'_>> = runs
        .iter()
        .map(|t| Sequence {
            u: &t.u,
            x: &t.x,
            y: &t.y,
        })
        .collect();
    let linear_mean = match std::env::var("LINEAR_MEAN") {
        Ok(v) => v.parse()?,
        Err(_) => hbn::model::LinearMean::default(),
    };
    let max_signal_variance = match std::env::var("MAX_SIGNAL_VARIANCE") {
        Ok(v) => Some(v.parse()?),
        Err(_) => None,
    };
    let params = HbnParams {
        n_inducing: Some(m),
        linear_mean,
        max_signal_variance,
        // The m of the command line alone: the default's held-out choice would also train
        // the exact GPs' candidate (500 points) and tune its filter.
        select: Selection::default(),
        ..HbnParams::default()
    };
    let checked = params.check()?;
    let t0 = Instant::now();
    let model = HysteresisModel::fit_checked(&seqs, &checked, &mut |role, progress| {
        println!(
            "  {:6.2} s: {role} GP, search start {} of {} ended",
            t0.elapsed().as_secs_f64(),
            progress.start + 1,
            progress.n_starts
        );
    })?;
    let secs = t0.elapsed().as_secs_f64();
    for (name, gp) in [
        ("transition", model.transition()),
        ("sensor", model.sensor()),
    ] {
        let r = gp.report();
        println!(
            "{name}: {} samples, m = {}, {} evaluations, search iterations {:?} on {:?}, refinement {:?}, theta {:?}",
            r.n_samples,
            r.n_support,
            r.evaluations,
            r.starts.iter().map(|s| s.iterations).collect::<Vec<_>>(),
            r.search_samples,
            r.refinement,
            gp.theta()
        );
    }
    println!(
        "train_sparse: {} samples per GP, m = {m}, both GPs and the model: {secs:.2} s on {} threads",
        model.summary().rows,
        rayon_threads()
    );
    Ok(())
}

fn rayon_threads() -> usize {
    std::thread::available_parallelism().map_or(1, |n| n.get())
}
