//! The exploration study of docs/exploration.md: nRMSE of the default model against the amount
//! of training data, for random-ramp inputs (what `hbn simulate` and `hbn.simulate` give) and
//! for the explorer, per simulator and seed, scored on a fresh random-ramp test run (1500
//! samples, simulator seed 1000 + SEED) that no training or validation saw. Prints one CSV line
//! per run (`system,seed,samples,method,nrmse,seconds`); `benches/explore/table.py` summarises
//! the lines.
//!
//! ```text
//! explore_eval --systems bouc-wen,preisach --sizes 500,1000 --seeds 1,2,3 \
//!     [--methods random-ramps,explore-ramps]
//! ```
//!
//! Methods:
//! - `random-ramps`: the default model on random ramps (simulator seed SEED);
//! - `random-ramps-b`: a second, independent draw of random ramps (simulator seed 2000 + SEED),
//!   for an A/A comparison: random ramps against themselves;
//! - `random-walk`: the thesis' random inputs, a bounded random walk
//!   (`hbn_sim::InputKind::RandomWalk`);
//! - `explore-ramps`: the explorer with the library's defaults (`ExploreParams`);
//! - `explore-steps`: the explorer with the thesis' per-sample rule (`Strategy::Steps`);
//! - variants of `explore-ramps`, one setting changed: `explore-ramps-poolN` (a pool of N random
//!   ramps, `ExploreParams::pool`), `explore-ramps-lagN` (refits beside the loop,
//!   `ExploreParams::lag` = N), `explore-ramps-reduction` and `explore-ramps-variance`
//!   (`ExploreParams::criterion`), `explore-ramps-alphaA` (the seeking weight's end
//!   `ExploreParams::alpha_end` = A, its start at most A).
use clap::Parser;
use hbn_harness::parse;
use hbn_model::explore::{Criterion, ExploreParams, Explorer, Strategy};
use hbn_model::{HbnParams, HysteresisModel, Sequence, metrics::nrmse};
use hbn_sim::{
    InputKind, SimConfig, Simulator, SystemKind, generate_input, simulate, simulate_random,
};

/// nRMSE of the default model after random inputs and after the explorer, one CSV line per run.
#[derive(Parser)]
struct Args {
    /// Simulators (comma-separated).
    #[arg(long, value_delimiter = ',', required = true, value_parser = parse::<SystemKind>)]
    systems: Vec<SystemKind>,
    /// Amounts of training data in samples (comma-separated).
    #[arg(long, value_delimiter = ',', required = true)]
    sizes: Vec<usize>,
    /// Seeds (comma-separated).
    #[arg(long, value_delimiter = ',', required = true)]
    seeds: Vec<u64>,
    /// Methods (comma-separated; see the program's documentation).
    #[arg(
        long,
        value_delimiter = ',',
        default_value = "random-ramps,random-walk,explore-ramps,explore-steps"
    )]
    methods: Vec<String>,
}

/// The explorer's settings for `method` and `seed`.
fn explore_params(method: &str, seed: u64) -> Result<ExploreParams, Box<dyn std::error::Error>> {
    let mut p = ExploreParams::new(0.0, 1.0, hbn_sim::DEFAULT_MAX_INCREMENT);
    p.seed = seed;
    match method {
        "explore-ramps" => p.strategy = Strategy::Ramps,
        "explore-steps" => p.strategy = Strategy::Steps,
        other => {
            let variant = other
                .strip_prefix("explore-ramps-")
                .ok_or_else(|| format!("unknown method `{other}`"))?;
            p.strategy = Strategy::Ramps;
            if let Some(n) = variant.strip_prefix("pool") {
                p.pool = n.parse()?;
            } else if let Some(n) = variant.strip_prefix("lag") {
                p.lag = n.parse()?;
            } else if let Some(a) = variant.strip_prefix("alpha") {
                p.alpha_end = a.parse()?;
                p.alpha_start = p.alpha_start.min(p.alpha_end);
            } else {
                p.criterion = variant.parse::<Criterion>()?;
            }
        }
    }
    Ok(p)
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args = Args::parse();
    println!("system,seed,samples,method,nrmse,seconds");
    for &system in &args.systems {
        for &seed in &args.seeds {
            let cfg = SimConfig {
                noise_gain: 1.0,
                seed,
                ..SimConfig::new(system)
            };
            let test = simulate_random(
                &SimConfig {
                    seed: 1000 + seed,
                    ..cfg.clone()
                },
                1500,
            )?;
            let score = |m: &HysteresisModel| -> Result<f64, Box<dyn std::error::Error>> {
                let e = m.estimate(&test.u, &test.y, m.default_mode())?;
                Ok(nrmse(&e.x, &test.x))
            };
            for &n in &args.sizes {
                for method in &args.methods {
                    let t0 = std::time::Instant::now();
                    let s = match method.as_str() {
                        "random-ramps" | "random-ramps-b" => {
                            let draw = SimConfig {
                                seed: if method == "random-ramps-b" {
                                    2000 + seed
                                } else {
                                    seed
                                },
                                ..cfg.clone()
                            };
                            let tr = simulate_random(&draw, n)?;
                            let seqs = [Sequence::new(&tr.u, &tr.x, &tr.y)];
                            score(&HysteresisModel::fit(&seqs, &HbnParams::default())?)?
                        }
                        "random-walk" => {
                            let u = generate_input(
                                InputKind::RandomWalk,
                                n,
                                hbn_sim::DEFAULT_MAX_INCREMENT,
                                seed,
                            )?;
                            let tr = simulate(&cfg, &u)?;
                            let seqs = [Sequence::new(&tr.u, &tr.x, &tr.y)];
                            score(&HysteresisModel::fit(&seqs, &HbnParams::default())?)?
                        }
                        other => {
                            let mut explorer = Explorer::new(explore_params(other, seed)?)?;
                            let mut robot = Simulator::new(&cfg)?;
                            for _ in 0..n {
                                let u = explorer.propose();
                                let (x, y) = robot.step(u)?;
                                explorer.observe(u, x, y)?;
                            }
                            score(&explorer.model()?)?
                        }
                    };
                    let t = t0.elapsed().as_secs_f64();
                    println!("{system},{seed},{n},{method},{s},{t:.1}");
                }
            }
        }
    }
    Ok(())
}
