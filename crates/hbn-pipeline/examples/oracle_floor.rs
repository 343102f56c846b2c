//! The floor under causal estimation on the judged grid's test logs ([`hbn_sim::oracle_estimate`]):
//! for every system x noise gain x seed `S`, the protocol's test log (`benches/baselines/run.py`:
//! input seed `S + 1`, noise seed `10 S + 11`, random ramps) is simulated and the oracle's nRMSE
//! (`hbn_model::metrics::nrmse`, which `benches/baselines/common.py` matches) printed as one JSON
//! object per line, beside the clean state's (the model simulated from `u` alone, exactly) and
//! the oracle's mean NEES.
//!
//!     cargo run --release -p hbn-pipeline --example oracle_floor -- \
//!         bouc-wen,duhem,preisach,soft-actuator 1,3,10 10,11,12 [STEPS]

use hbn_model::metrics::{calibration, nrmse};
use hbn_sim::{DEFAULT_MAX_INCREMENT, InputKind, SimConfig, SystemKind, generate_input};

fn list<T: std::str::FromStr>(arg: Option<String>, what: &str) -> Vec<T> {
    let arg = arg.unwrap_or_else(|| panic!("missing {what}"));
    arg.split(',')
        .map(|s| s.parse().unwrap_or_else(|_| panic!("bad {what} `{s}`")))
        .collect()
}

fn main() {
    let mut args = std::env::args().skip(1);
    let systems: Vec<SystemKind> = list(args.next(), "systems");
    let gains: Vec<f64> = list(args.next(), "gains");
    let seeds: Vec<u64> = list(args.next(), "seeds");
    let steps: usize = args.next().map_or(1000, |s| s.parse().expect("bad steps"));
    for &system in &systems {
        for &gain in &gains {
            for &seed in &seeds {
                let config = SimConfig {
                    noise_gain: gain,
                    seed: 10 * seed + 11,
                    ..SimConfig::new(system)
                };
                let u = generate_input(
                    InputKind::RandomRamps,
                    steps,
                    DEFAULT_MAX_INCREMENT,
                    seed + 1,
                )
                .expect("input");
                let traj = hbn_sim::simulate(&config, &u).expect("simulation");
                let est = hbn_sim::oracle_estimate(&config, &traj).expect("oracle");
                let clean = SimConfig {
                    noise_gain: 0.0,
                    ..config.clone()
                };
                let clean = hbn_sim::simulate(&clean, &u).expect("simulation");
                let nees = calibration(&est.mean, &est.std, &traj.x).mean_nees;
                println!(
                    "{{\"system\": \"{system}\", \"gain\": {gain}, \"seed\": {seed}, \"nrmse_oracle\": {:.6e}, \
                     \"nrmse_clean\": {:.6e}, \"mean_nees\": {nees:.4}, \"unresolved\": {}}}",
                    nrmse(&est.mean, &traj.x),
                    nrmse(&clean.x, &traj.x),
                    est.unresolved
                );
            }
        }
    }
}
