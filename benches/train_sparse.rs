//! Training time of a sparse HBN on many samples: both GPs (d = 4 and 3) with `m` inducing
//! points on every sample of simulated logs.
//!
//! `cargo bench --bench train_sparse -- [SAMPLES] [M] [LINEAR_MEAN] [MAX_SIGNAL_VARIANCE]`
//! (defaults 100000, 128, the default linear mean and no bound; LINEAR_MEAN is `none`,
//! `transition` or `both`, [`HbnParams::linear_mean`]; MAX_SIGNAL_VARIANCE is a number,
//! [`HbnParams::max_signal_variance`]). Prints one line per run: samples, m, seconds for both
//! GPs, and the training report's figures, after a timeline: when each GP's search starts ended
//! (the refinement on every sample, the held-out refits and the filter tuning follow).

use hbn::model::{HbnParams, HysteresisModel, Selection, Sequence};
use hbn::sim::{InputKind, SimConfig, SystemKind, generate_input, simulate};
use std::time::Instant;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    // `cargo bench` passes `--bench`; keep the positional arguments.
    let args: Vec<String> = std::env::args()
        .skip(1)
        .filter(|a| !a.starts_with("--"))
        .collect();
    let samples: usize = args.first().map_or(Ok(100_000), |a| a.parse())?;
    let m: usize = args.get(1).map_or(Ok(128), |a| a.parse())?;
    let linear_mean: hbn::model::LinearMean = match args.get(2) {
        Some(v) => v.parse()?,
        None => hbn::model::LinearMean::default(),
    };
    let max_signal_variance: Option<f64> = args.get(3).map(|v| v.parse()).transpose()?;
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
        .map(|t| Sequence::new(&t.u, &t.x, &t.y))
        .collect();
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
