//! Smoothed against filtered estimates ([`hbn_model::HysteresisModel::smooth`]): for every
//! system x noise gain x seed, a default model is trained on the protocol's training set
//! (`hbn_pipeline::experiment`: one random-ramp input repeated with fresh noise) and each mode's
//! filtered and smoothed estimates of a fresh test log are scored: nRMSE, the ratio smoothed /
//! filtered, and the 2-sigma coverage of each. One JSON object per line, then a table of the
//! means per system, gain and mode.
//!
//! ```text
//! smooth_eval --systems bouc-wen,preisach,soft-actuator --gains 0,1,10 --seeds 1,2,3
//! ```
use clap::Parser;
use hbn_core::Mode;
use hbn_model::metrics::{calibration, nrmse};
use hbn_model::{HbnParams, HysteresisModel};
use hbn_pipeline::experiment::{ExperimentConfig, test_trajectory, training_set};
use hbn_pipeline::sequences;
use hbn_sim::SystemKind;

/// Smoothed and filtered nRMSE and coverage, one JSON line per (system, gain, seed, mode).
#[derive(Parser)]
struct Args {
    /// Simulators (comma-separated).
    #[arg(long, value_delimiter = ',', required = true, value_parser = parse::<SystemKind>)]
    systems: Vec<SystemKind>,
    /// Noise gains (comma-separated).
    #[arg(long, value_delimiter = ',', required = true)]
    gains: Vec<f64>,
    /// Seeds (comma-separated).
    #[arg(long, value_delimiter = ',', required = true)]
    seeds: Vec<u64>,
    /// Samples of each training log.
    #[arg(long, default_value_t = 1000)]
    train_steps: usize,
    /// Training logs (the same input, fresh noise).
    #[arg(long, default_value_t = 3)]
    repeats: usize,
    /// Samples of the test log.
    #[arg(long, default_value_t = 1000)]
    test_steps: usize,
}

/// A value of `T` by its `FromStr`, the error as text (for clap).
fn parse<T: std::str::FromStr>(s: &str) -> Result<T, String>
where
    T::Err: std::fmt::Display,
{
    s.parse().map_err(|e: T::Err| e.to_string())
}

/// One scored case.
struct Row {
    system: SystemKind,
    gain: f64,
    mode: Mode,
    filtered: f64,
    smoothed: f64,
    cover_filtered: f64,
    cover_smoothed: f64,
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args = Args::parse();
    let mut rows = Vec::new();
    for &system in &args.systems {
        for &gain in &args.gains {
            for &seed in &args.seeds {
                let cfg = ExperimentConfig {
                    train_steps: args.train_steps,
                    repeats: args.repeats,
                    test_steps: args.test_steps,
                    ..ExperimentConfig::default()
                };
                let train = training_set(system, gain, seed, &cfg)?;
                let params = HbnParams {
                    seed,
                    ..HbnParams::default()
                };
                let model = HysteresisModel::fit(&sequences(&train), &params)?;
                let test = test_trajectory(system, gain, seed, &cfg)?;
                for mode in Mode::ALL {
                    let s = model.smooth_with(&test.u, &test.y, &model.ekf_config(mode))?;
                    let (f, sm) = (&s.filtered, &s.estimate);
                    let row = Row {
                        system,
                        gain,
                        mode,
                        filtered: nrmse(&f.x, &test.x),
                        smoothed: nrmse(&sm.x, &test.x),
                        cover_filtered: calibration(&f.x, &f.x_std, &test.x).coverage_2sigma,
                        cover_smoothed: calibration(&sm.x, &sm.x_std, &test.x).coverage_2sigma,
                    };
                    println!(
                        "{}",
                        serde_json::json!({
                            "system": system.name(),
                            "gain": gain,
                            "seed": seed,
                            "mode": mode.name(),
                            "default_mode": mode == model.default_mode(),
                            "nrmse_filtered": row.filtered,
                            "nrmse_smoothed": row.smoothed,
                            "ratio": row.smoothed / row.filtered,
                            "coverage_filtered": row.cover_filtered,
                            "coverage_smoothed": row.cover_smoothed,
                            "jitter_retries": s.states.jitter_retries,
                            "unlinked": s.states.unlinked,
                            "clamped": s.states.clamped,
                        })
                    );
                    rows.push(row);
                }
            }
        }
    }
    println!();
    println!(
        "| system | gain | mode | nRMSE filtered | nRMSE smoothed | ratio | in 2 sd filtered | in 2 sd smoothed |"
    );
    println!("|---|---|---|---|---|---|---|---|");
    for &system in &args.systems {
        for &gain in &args.gains {
            for mode in Mode::ALL {
                let group: Vec<&Row> = rows
                    .iter()
                    .filter(|r| r.system == system && r.gain == gain && r.mode == mode)
                    .collect();
                if group.is_empty() {
                    continue;
                }
                let mean = |f: &dyn Fn(&Row) -> f64| {
                    group.iter().map(|r| f(r)).sum::<f64>() / group.len() as f64
                };
                println!(
                    "| {} | {gain} | {} | {:.4} | {:.4} | {:.2} | {:.1}% | {:.1}% |",
                    system.name(),
                    mode.name(),
                    mean(&|r| r.filtered),
                    mean(&|r| r.smoothed),
                    mean(&|r| r.smoothed / r.filtered),
                    100.0 * mean(&|r| r.cover_filtered),
                    100.0 * mean(&|r| r.cover_smoothed),
                );
            }
        }
    }
    Ok(())
}
