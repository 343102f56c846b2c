//! Accuracy levers measured on the same data (docs/results.md, "Levers"): for each simulator,
//! noise gain and seed, the model is trained once per variant of the parameters and scored on a
//! fresh test run (never used in training or validation) by the default mode's nRMSE and the
//! calibration of its band, and every mode's nRMSE.
//!
//! `cargo run --release -p hbn-pipeline --example levers -- OUT.json LEVER [systems] [gains]
//! [seeds] [protocol]`, LEVER `increments` (none / transition / both); protocol `repeat` (the
//! thesis: one training input repeated 10 times) or `varied` (10 runs with their own inputs).
use hbn_core::Mode;
use hbn_model::metrics::{calibration, nrmse};
use hbn_model::{HbnParams, HysteresisModel, Increments};
use hbn_pipeline::experiment::{ExperimentConfig, test_trajectory, training_set};
use hbn_pipeline::sequences;
use hbn_sim::SystemKind;
use serde_json::json;

fn list<T: std::str::FromStr>(arg: Option<&String>, default: Vec<T>) -> Vec<T> {
    arg.map(|s| s.split(',').filter_map(|v| v.parse().ok()).collect())
        .unwrap_or(default)
}

fn variants(lever: &str, base: &HbnParams) -> Result<Vec<(String, HbnParams)>, String> {
    match lever {
        "increments" => Ok(Increments::ALL
            .iter()
            .map(|&increments| {
                (
                    increments.name().to_owned(),
                    HbnParams {
                        increments,
                        ..base.clone()
                    },
                )
            })
            .collect()),
        other => Err(format!("unknown lever `{other}`")),
    }
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().collect();
    let usage = "usage: levers OUT.json LEVER [systems] [gains] [seeds] [protocol]";
    let out = args.get(1).ok_or(usage)?;
    let lever = args.get(2).ok_or(usage)?;
    let systems: Vec<SystemKind> = list(args.get(3), SystemKind::ALL.to_vec());
    let gains: Vec<f64> = list(args.get(4), vec![1.0]);
    let seeds: Vec<u64> = list(args.get(5), vec![1, 2]);
    let varied = args.get(6).is_some_and(|p| p == "varied");
    let cfg = ExperimentConfig::default();
    let mut rows = Vec::new();
    for &system in &systems {
        for &gain in &gains {
            for &seed in &seeds {
                let train = if varied {
                    let one = ExperimentConfig {
                        repeats: 1,
                        ..cfg.clone()
                    };
                    let mut runs = Vec::new();
                    for r in 0..cfg.repeats as u64 {
                        runs.extend(training_set(system, gain, seed * 100 + r, &one)?);
                    }
                    runs
                } else {
                    training_set(system, gain, seed, &cfg)?
                };
                let test = test_trajectory(system, gain, seed, &cfg)?;
                let base = HbnParams {
                    seed,
                    ..cfg.params.clone()
                };
                for (name, params) in variants(lever, &base)? {
                    let t0 = std::time::Instant::now();
                    let model = HysteresisModel::fit(&sequences(&train), &params)?;
                    let seconds = t0.elapsed().as_secs_f64();
                    let mut row = json!({
                        "system": system.name(), "gain": gain, "seed": seed,
                        "protocol": if varied { "varied" } else { "repeat" },
                        "variant": name, "seconds": seconds,
                        "default_mode": model.default_mode().name(),
                    });
                    let mut line = String::new();
                    for mode in Mode::ALL {
                        let est = model.estimate(&test.u, &test.y, mode)?;
                        let c = calibration(&est.x, &est.x_std, &test.x);
                        let e = nrmse(&est.x, &test.x);
                        line.push_str(&format!(" {} {e:.4}", mode.name()));
                        row[mode.name()] = json!({"nrmse": e, "calibration": c});
                    }
                    let d = row[model.default_mode().name()].clone();
                    let num = |v: &serde_json::Value| v.as_f64().unwrap_or(f64::NAN);
                    println!(
                        "{:<14} g{gain} s{seed} {name:<11} ({seconds:5.1} s) default {:<7} nRMSE \
                         {:.4} in2sd {:5.1}% NEES {:6.2} |{line}",
                        system.name(),
                        model.default_mode().name(),
                        num(&d["nrmse"]),
                        100.0 * num(&d["calibration"]["coverage_2sigma"]),
                        num(&d["calibration"]["mean_nees"]),
                    );
                    row["default"] = d;
                    rows.push(row);
                }
            }
        }
    }
    std::fs::write(out, serde_json::to_string_pretty(&rows)?)?;
    Ok(())
}
