//! Smoothed against filtered estimates of a vector model ([`hbn_model::VectorModel::smooth`])
//! on the multi-signal simulators (`hbn_sim::MultiKind`): for every system x noise gain x seed,
//! a default model is trained on one simulated run (`--train-steps`, that seed) and the EKF's
//! and the UKF's filtered and smoothed estimates of a fresh run (seed `1000 + seed`) are scored
//! per state component: nRMSE, the ratio smoothed / filtered, and the 2-sigma coverage of each.
//! One JSON object per line, then a table of the means per system, gain, mode and component.
//!
//! ```text
//! vector_smooth_eval --systems finger,arm --gains 1,10 --seeds 1,2,3
//! ```
use clap::Parser;
use hbn_core::Mode;
use hbn_core::vector::Dims;
use hbn_harness::{parse, rows};
use hbn_model::metrics::{calibration, nrmse};
use hbn_model::{HbnParams, VectorModel, VectorSequence};
use hbn_sim::{MultiConfig, MultiKind, simulate_multi_random};

/// Smoothed and filtered nRMSE and coverage per component, one JSON line per (system, gain,
/// seed, mode).
#[derive(Parser)]
struct Args {
    /// Multi-signal simulators (comma-separated).
    #[arg(long, value_delimiter = ',', required = true, value_parser = parse::<MultiKind>)]
    systems: Vec<MultiKind>,
    /// Noise gains (comma-separated).
    #[arg(long, value_delimiter = ',', required = true)]
    gains: Vec<f64>,
    /// Seeds (comma-separated).
    #[arg(long, value_delimiter = ',', required = true)]
    seeds: Vec<u64>,
    /// Samples of the training run.
    #[arg(long, default_value_t = 3000)]
    train_steps: usize,
    /// Samples of the test run.
    #[arg(long, default_value_t = 3000)]
    test_steps: usize,
}

/// Column `i` of a row-major `(T, d)` array.
fn column(a: &[f64], d: usize, i: usize) -> Vec<f64> {
    a.iter().skip(i).step_by(d).copied().collect()
}

/// One scored (system, gain, seed, mode, component).
struct Row {
    system: MultiKind,
    gain: f64,
    mode: Mode,
    component: usize,
    filtered: f64,
    smoothed: f64,
    cover_filtered: f64,
    cover_smoothed: f64,
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args = Args::parse();
    let mut out = Vec::new();
    for &system in &args.systems {
        let dims = Dims::new(system.inputs(), system.states(), system.sensors())?;
        for &gain in &args.gains {
            for &seed in &args.seeds {
                let cfg = MultiConfig {
                    noise_gain: gain,
                    seed,
                    ..MultiConfig::new(system)
                };
                let train = simulate_multi_random(&cfg, args.train_steps)?;
                let test_cfg = MultiConfig {
                    seed: 1000 + seed,
                    ..cfg
                };
                let test = simulate_multi_random(&test_cfg, args.test_steps)?;
                let (u, x, y) = (rows(&train.u), rows(&train.x), rows(&train.y));
                let params = HbnParams {
                    seed,
                    ..HbnParams::default()
                };
                let model = VectorModel::fit(&[VectorSequence::new(&u, &x, &y, dims)], &params)?;
                let (ut, xt, yt) = (rows(&test.u), rows(&test.x), rows(&test.y));
                for mode in [Mode::Ekf, Mode::Ukf] {
                    let s = model.smooth_with(&ut, &yt, mode)?;
                    let mut json_rows = Vec::new();
                    for i in 0..dims.states {
                        let truth = column(&xt, dims.states, i);
                        let (f, sm) = (&s.filtered, &s.estimate);
                        let (fx, fs) = (f.component(i), f.component_std(i));
                        let (sx, ss) = (sm.component(i), sm.component_std(i));
                        let row = Row {
                            system,
                            gain,
                            mode,
                            component: i,
                            filtered: nrmse(&fx, &truth),
                            smoothed: nrmse(&sx, &truth),
                            cover_filtered: calibration(&fx, &fs, &truth).coverage_2sigma,
                            cover_smoothed: calibration(&sx, &ss, &truth).coverage_2sigma,
                        };
                        json_rows.push(serde_json::json!({
                            "component": i,
                            "nrmse_filtered": row.filtered,
                            "nrmse_smoothed": row.smoothed,
                            "ratio": row.smoothed / row.filtered,
                            "coverage_filtered": row.cover_filtered,
                            "coverage_smoothed": row.cover_smoothed,
                        }));
                        out.push(row);
                    }
                    println!(
                        "{}",
                        serde_json::json!({
                            "system": system.name(),
                            "gain": gain,
                            "seed": seed,
                            "mode": mode.name(),
                            "default_mode": mode == model.default_mode(),
                            "components": json_rows,
                            "gated": s.gated,
                            "unlinked": s.unlinked,
                            "clamped": s.clamped,
                            "jitter_retries": s.jitter_retries,
                        })
                    );
                }
            }
        }
    }
    println!();
    println!(
        "| system | gain | mode | component | nRMSE filtered | nRMSE smoothed | smoothed / filtered | in 2 sd filtered | in 2 sd smoothed |"
    );
    println!("|---|---|---|---|---|---|---|---|---|");
    for &system in &args.systems {
        for &gain in &args.gains {
            for mode in [Mode::Ekf, Mode::Ukf] {
                for i in 0..system.states() {
                    let group: Vec<&Row> = out
                        .iter()
                        .filter(|r| {
                            r.system == system
                                && r.gain == gain
                                && r.mode == mode
                                && r.component == i
                        })
                        .collect();
                    if group.is_empty() {
                        continue;
                    }
                    let mean = |f: &dyn Fn(&Row) -> f64| {
                        group.iter().map(|r| f(r)).sum::<f64>() / group.len() as f64
                    };
                    let geo = (group
                        .iter()
                        .map(|r| (r.smoothed / r.filtered).ln())
                        .sum::<f64>()
                        / group.len() as f64)
                        .exp();
                    println!(
                        "| {} | {gain} | {} | x{i} | {:.4} | {:.4} | {geo:.3} | {:.3} | {:.3} |",
                        system.name(),
                        mode.name(),
                        mean(&|r| r.filtered),
                        mean(&|r| r.smoothed),
                        mean(&|r| r.cover_filtered),
                        mean(&|r| r.cover_smoothed),
                    );
                }
            }
        }
    }
    Ok(())
}
