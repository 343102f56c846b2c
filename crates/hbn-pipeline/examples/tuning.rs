//! Filter-aware training measured (docs/results.md, "Filter-aware training"): on each
//! simulator, noise gain and seed, the same data trained twice, without tuning
//! (`validation = 0`) and with it (the default), scored on a fresh test run by nRMSE and the
//! calibration of the 2-sigma band, NEES and NLPD, for both modes and the model's default mode.
//!
//! `cargo run --release -p hbn-pipeline --example tuning -- OUT.json [systems] [gains] [seeds]
//! [protocol]`, protocol `repeat` (the thesis: one training input repeated 10 times with fresh
//! noise) or `varied` (10 runs, each with its own input, as logs of a robot would be).
use hbn_core::Mode;
use hbn_model::metrics::{calibration, nrmse};
use hbn_model::{HbnParams, HysteresisModel};
use hbn_pipeline::experiment::{ExperimentConfig, test_trajectory, training_set};
use hbn_pipeline::sequences;
use hbn_sim::SystemKind;
use serde_json::json;

fn list<T: std::str::FromStr>(arg: Option<&String>, default: Vec<T>) -> Vec<T> {
    arg.map(|s| s.split(',').filter_map(|v| v.parse().ok()).collect())
        .unwrap_or(default)
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().collect();
    let out = args
        .get(1)
        .ok_or("usage: tuning OUT.json [systems] [gains] [seeds] [protocol]")?;
    let systems: Vec<SystemKind> = list(args.get(2), SystemKind::ALL.to_vec());
    let gains: Vec<f64> = list(args.get(3), vec![1.0]);
    let seeds: Vec<u64> = list(args.get(4), vec![1, 2]);
    let varied = args.get(5).is_some_and(|p| p == "varied");
    let cfg = ExperimentConfig::default();
    let mut rows = Vec::new();
    for &system in &systems {
        for &gain in &gains {
            for &seed in &seeds {
                let train = if varied {
                    // Each run its own input: the training sets of seeds seed*100 + r, one run each.
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
                for validation in [0.0, HbnParams::default().validation] {
                    let params = HbnParams {
                        seed,
                        validation,
                        ..cfg.params.clone()
                    };
                    let t0 = std::time::Instant::now();
                    let model = HysteresisModel::fit(&sequences(&train), &params)?;
                    let seconds = t0.elapsed().as_secs_f64();
                    let mut row = json!({
                        "system": system.name(), "gain": gain, "seed": seed,
                        "protocol": if varied { "varied" } else { "repeat" },
                        "validation": validation, "seconds": seconds,
                        "default_mode": model.default_mode().name(),
                        "tuning": model.tuning(),
                    });
                    for mode in Mode::ALL {
                        let est = model.estimate(&test.u, &test.y, mode)?;
                        let c = calibration(&est.x, &est.x_std, &test.x);
                        row[mode.name()] =
                            json!({"nrmse": nrmse(&est.x, &test.x), "calibration": c});
                    }
                    let d = row[model.default_mode().name()].clone();
                    row["default"] = d;
                    println!(
                        "{:<14} g{gain} s{seed} val {validation:.2} ({seconds:5.1} s) default {:<7} \
                         nRMSE {:.4} in2sd {:5.1}% NEES {:7.2} NLPD {:7.3} | ekf {:.4} blr {:.4}",
                        system.name(),
                        model.default_mode().name(),
                        row["default"]["nrmse"].as_f64().unwrap_or(f64::NAN),
                        100.0
                            * row["default"]["calibration"]["coverage_2sigma"]
                                .as_f64()
                                .unwrap_or(f64::NAN),
                        row["default"]["calibration"]["mean_nees"]
                            .as_f64()
                            .unwrap_or(f64::NAN),
                        row["default"]["calibration"]["nlpd"]
                            .as_f64()
                            .unwrap_or(f64::NAN),
                        row["ekf"]["nrmse"].as_f64().unwrap_or(f64::NAN),
                        row["ekf-blr"]["nrmse"].as_f64().unwrap_or(f64::NAN),
                    );
                    rows.push(row);
                }
            }
        }
    }
    std::fs::write(out, serde_json::to_string_pretty(&rows)?)?;
    Ok(())
}
