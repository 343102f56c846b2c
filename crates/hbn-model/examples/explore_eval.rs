//! The exploration study of docs/exploration.md: nRMSE of the default model against the amount
//! of training data, for random-ramp inputs (what `hbn simulate` and `hbn.simulate` give) and
//! for the explorer (default ramps strategy, and the thesis' per-sample rule), per simulator
//! and seed, scored on a fresh random-ramp test run (1500 samples, another seed) that no
//! training or validation saw.
//!
//! Usage: cargo run --release -p hbn-model --example explore_eval -- SYSTEMS SIZES SEEDS [METHODS]
//! e.g. `-- bouc-wen,preisach,soft-actuator 500,1000,2000 1,2,3`; prints one CSV line per run.
//! METHODS (default all): random-ramps, random-ramps-b (a second, independent draw of random
//! ramps, simulator seed 2000 + SEED: random ramps against themselves, an A/A comparison),
//! random-walk (the thesis' random inputs: a bounded
//! random walk, `hbn_sim::InputKind::RandomWalk`), explore-ramps, explore-steps, and
//! explore-ramps-poolN (the ramps strategy with a pool of N random ramps instead of the
//! default's `ExploreParams::pool`), explore-ramps-lagN (the default with its refits beside
//! the loop, `ExploreParams::lag` = N), explore-ramps-reduction and explore-ramps-variance (the
//! default with `ExploreParams::criterion` = `Criterion::Reduction` or `Criterion::Variance`;
//! explore-ramps is the library's default: `Reduction` since session 21, `Variance` before), and
//! explore-ramps-alphaA (the default with the seeking weight's end `ExploreParams::alpha_end` =
//! A, and its start at most A).
use hbn_model::explore::{Criterion, ExploreParams, Explorer, Strategy};
use hbn_model::{HbnParams, HysteresisModel, Sequence, metrics::nrmse};
use hbn_sim::{
    InputKind, SimConfig, Simulator, SystemKind, generate_input, simulate, simulate_random,
};

fn list<T: std::str::FromStr>(s: &str) -> Vec<T> {
    s.split(',').filter_map(|v| v.parse().ok()).collect()
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().collect();
    let (Some(systems), Some(sizes), Some(seeds)) = (args.get(1), args.get(2), args.get(3)) else {
        return Err("usage: explore_eval SYSTEMS SIZES SEEDS".into());
    };
    let systems: Vec<SystemKind> = list(systems);
    let sizes: Vec<usize> = list(sizes);
    let seeds: Vec<u64> = list(seeds);
    let all = "random-ramps,random-walk,explore-ramps,explore-steps";
    let methods: Vec<String> = list(args.get(4).map_or(all, |s| s.as_str()));
    println!("system,seed,samples,method,nrmse,seconds");
    for &system in &systems {
        for &seed in &seeds {
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
            for &n in &sizes {
                for method in &methods {
                    let t0 = std::time::Instant::now();
                    let choice = match method.as_str() {
                        "random-ramps" | "random-ramps-b" => {
                            // `-b`: a second, independent draw (another input and noise seed):
                            // random ramps against themselves, the comparison's own spread.
                            let draw = if method == "random-ramps-b" {
                                SimConfig {
                                    seed: 2000 + seed,
                                    ..cfg.clone()
                                }
                            } else {
                                cfg.clone()
                            };
                            let tr = simulate_random(&draw, n)?;
                            let seqs = [Sequence::new(&tr.u, &tr.x, &tr.y)];
                            let s = score(&HysteresisModel::fit(&seqs, &HbnParams::default())?)?;
                            let t = t0.elapsed().as_secs_f64();
                            println!("{system},{seed},{n},{method},{s},{t:.1}");
                            continue;
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
                            let s = score(&HysteresisModel::fit(&seqs, &HbnParams::default())?)?;
                            let t = t0.elapsed().as_secs_f64();
                            println!("{system},{seed},{n},{method},{s},{t:.1}");
                            continue;
                        }
                        "explore-steps" => (Strategy::Steps, None, 0),
                        "explore-ramps" | "explore-ramps-reduction" | "explore-ramps-variance" => {
                            (Strategy::Ramps, None, 0)
                        }
                        other if other.starts_with("explore-ramps-alpha") => {
                            (Strategy::Ramps, None, 0)
                        }
                        other => match (
                            other.strip_prefix("explore-ramps-pool"),
                            other.strip_prefix("explore-ramps-lag"),
                        ) {
                            (Some(size), _) => (Strategy::Ramps, Some(size.parse()?), 0),
                            (_, Some(lag)) => (Strategy::Ramps, None, lag.parse()?),
                            _ => return Err(format!("unknown method {other}").into()),
                        },
                    };
                    let mut p = ExploreParams::new(0.0, 1.0, hbn_sim::DEFAULT_MAX_INCREMENT);
                    p.seed = seed;
                    (p.strategy, p.pool) = (choice.0, choice.1.unwrap_or(p.pool));
                    p.lag = choice.2;
                    if let Some(a) = method.strip_prefix("explore-ramps-alpha") {
                        p.alpha_end = a.parse()?;
                        p.alpha_start = p.alpha_start.min(p.alpha_end);
                    } else if let Some(c) = method.strip_prefix("explore-ramps-") {
                        p.criterion = c.parse::<Criterion>().unwrap_or(p.criterion);
                    }
                    let mut explorer = Explorer::new(p)?;
                    let mut robot = Simulator::new(&cfg)?;
                    for _ in 0..n {
                        let u = explorer.propose();
                        let (x, y) = robot.step(u)?;
                        explorer.observe(u, x, y)?;
                    }
                    let s = score(&explorer.model()?)?;
                    let t = t0.elapsed().as_secs_f64();
                    println!("{system},{seed},{n},{method},{s},{t:.1}");
                }
            }
        }
    }
    Ok(())
}
