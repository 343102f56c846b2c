//! The floor under causal estimation ([`hbn_sim::oracle_estimate`]) on the test logs of
//! `benches/baselines/run.py`: for every system x noise gain x seed `S`, the protocol's test log
//! (input seed `S + 1`, noise seed `10 S + 11`, random ramps) is simulated, and one JSON object
//! per line gives the oracle's nRMSE (`hbn_model::metrics::nrmse`, which
//! `benches/baselines/common.py` matches), the nRMSE of the clean state (the simulator run from
//! `u` alone, without noise) and the oracle's mean NEES. A system whose disturbance propagates
//! (`soft-actuator-load`) has no exact floor: its lines say so in `note` instead.
//!
//! ```text
//! oracle_floor --systems bouc-wen,duhem --gains 0,1,10 --seeds 1,2,3 [--steps 1000]
//! ```
use clap::Parser;
use hbn_harness::parse;
use hbn_model::metrics::{calibration, nrmse};
use hbn_sim::{DEFAULT_MAX_INCREMENT, InputKind, SimConfig, SimError, SystemKind, generate_input};

/// The oracle's nRMSE on the baselines' simulated test logs, one JSON line per log.
#[derive(Parser)]
struct Args {
    /// Simulators (comma-separated).
    #[arg(long, value_delimiter = ',', required = true, value_parser = parse::<SystemKind>)]
    systems: Vec<SystemKind>,
    /// Noise gains (comma-separated).
    #[arg(long, value_delimiter = ',', required = true)]
    gains: Vec<f64>,
    /// Run seeds S (comma-separated), as `run.py --seeds`.
    #[arg(long, value_delimiter = ',', required = true)]
    seeds: Vec<u64>,
    /// Samples of each test log.
    #[arg(long, default_value_t = 1000)]
    steps: usize,
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args = Args::parse();
    for &system in &args.systems {
        for &gain in &args.gains {
            for &seed in &args.seeds {
                let config = SimConfig {
                    noise_gain: gain,
                    seed: 10 * seed + 11,
                    ..SimConfig::new(system)
                };
                let u = generate_input(
                    InputKind::RandomRamps,
                    args.steps,
                    DEFAULT_MAX_INCREMENT,
                    seed + 1,
                )?;
                let traj = hbn_sim::simulate(&config, &u)?;
                let est = match hbn_sim::oracle_estimate(&config, &traj) {
                    Ok(est) => est,
                    Err(e @ SimError::NoExactOracle { .. }) => {
                        eprintln!("{}: no floor: {e}", system.name());
                        println!(
                            "{}",
                            serde_json::json!({
                                "system": system.name(),
                                "gain": gain,
                                "seed": seed,
                                "note": e.to_string(),
                            })
                        );
                        continue;
                    }
                    Err(e) => return Err(e.into()),
                };
                let clean = SimConfig {
                    noise_gain: 0.0,
                    ..config.clone()
                };
                let clean = hbn_sim::simulate(&clean, &u)?;
                let nees = calibration(&est.mean, &est.std, &traj.x).mean_nees;
                println!(
                    "{}",
                    serde_json::json!({
                        "system": system.name(),
                        "gain": gain,
                        "seed": seed,
                        "nrmse_oracle": nrmse(&est.mean, &traj.x),
                        "nrmse_clean": nrmse(&clean.x, &traj.x),
                        "mean_nees": nees,
                        "unresolved": est.unresolved,
                    })
                );
            }
        }
    }
    Ok(())
}
