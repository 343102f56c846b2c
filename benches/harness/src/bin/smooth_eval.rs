//! Smoothed against filtered estimates ([`hbn_model::HysteresisModel::smooth`]): for every
//! system x noise gain x seed, a default model is trained on the protocol's training set
//! (`hbn_pipeline::experiment`: one random-ramp input repeated with fresh noise) and each mode's
//! filtered and smoothed estimates of a fresh test log are scored: nRMSE, the ratio smoothed /
//! filtered, and the 2-sigma coverage of each. Beside them, on the same test log, the floors of
//! the simulator ([`hbn_sim::oracle_estimate`], causal, and [`hbn_sim::oracle_smooth_estimate`],
//! two-sided, with `--lookahead` samples of the future, the whole log by default): their
//! ratio, two-sided / causal, is the most any smoother could gain over the best filter there.
//! A system whose disturbance propagates (`soft-actuator-load`) has no exact floor; its rows
//! say so. Every row also gives the nRMSE of the noise-free simulator run from `u` alone (the
//! true model without the sensor: what the disturbance alone moves the state by); a filter far
//! above it errs by its model more than by the noise, and no smoother removes that. One JSON
//! object per line, then a table of the means per system, gain and mode.
//!
//! ```text
//! smooth_eval --systems bouc-wen,duhem,preisach,soft-actuator-load --gains 1,10 --seeds 1,2,3
//! ```
use clap::Parser;
use hbn_core::Mode;
use hbn_harness::parse;
use hbn_model::metrics::{calibration, nrmse};
use hbn_model::{HbnParams, HysteresisModel};
use hbn_pipeline::experiment::{ExperimentConfig, test_trajectory, training_set};
use hbn_pipeline::sequences;
use hbn_sim::{SimConfig, SimError, SystemKind};

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
    /// Samples of the future the two-sided floor reads (default: the whole log).
    #[arg(long)]
    lookahead: Option<usize>,
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
    /// nRMSE of the causal and of the two-sided floor (none where the system has no exact one).
    floors: Option<(f64, f64)>,
    /// nRMSE of the noise-free simulator run from `u` alone.
    clean: f64,
}

/// nRMSE of the noise-free run of `system` on the input of `test` against its logged state.
fn clean_nrmse(system: SystemKind, test: &hbn_sim::Trajectory) -> Result<f64, SimError> {
    let config = SimConfig {
        rate_hz: test.rate_hz,
        ..SimConfig::new(system)
    };
    Ok(nrmse(&hbn_sim::simulate(&config, &test.u)?.x, &test.x))
}

/// The floors' nRMSE on the test log `test` of `system` at `gain`, `(causal, two-sided)`, or
/// why there is none.
fn floors(
    system: SystemKind,
    gain: f64,
    test: &hbn_sim::Trajectory,
    lookahead: usize,
) -> Result<Result<(f64, f64), String>, SimError> {
    // The noise seed is not used by the oracles; the rate is the log's.
    let config = SimConfig {
        noise_gain: gain,
        rate_hz: test.rate_hz,
        ..SimConfig::new(system)
    };
    let causal = match hbn_sim::oracle_estimate(&config, test) {
        Ok(est) => est,
        Err(e @ SimError::NoExactOracle { .. }) => return Ok(Err(e.to_string())),
        Err(e) => return Err(e),
    };
    let two_sided = hbn_sim::oracle_smooth_estimate(&config, test, lookahead)?;
    Ok(Ok((
        nrmse(&causal.mean, &test.x),
        nrmse(&two_sided.mean, &test.x),
    )))
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
                let lookahead = args.lookahead.unwrap_or(usize::MAX);
                let floor = floors(system, gain, &test, lookahead)?;
                if let Err(note) = &floor {
                    eprintln!(
                        "{} gain {gain} seed {seed}: no floor: {note}",
                        system.name()
                    );
                }
                let floor_ok = floor.as_ref().ok().copied();
                let clean = clean_nrmse(system, &test)?;
                let floor_json = |i: usize| floor_ok.map(|f| if i == 0 { f.0 } else { f.1 });
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
                        floors: floor_ok,
                        clean,
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
                            "nrmse_floor_causal": floor_json(0),
                            "nrmse_floor_two_sided": floor_json(1),
                            "floor_ratio": floor_ok.map(|(c, t)| t / c),
                            "floor_note": floor.as_ref().err(),
                            "nrmse_clean": clean,
                            "jitter_retries": s.states.jitter_retries,
                            "unlinked": s.states.unlinked,
                            "gated": s.states.gated,
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
        "| system | gain | mode | nRMSE filtered | nRMSE smoothed | smoothed / filtered | in 2 sd filtered | in 2 sd smoothed | floor causal | floor two-sided | floor two-sided / causal | noise-free run |"
    );
    println!("|---|---|---|---|---|---|---|---|---|---|---|---|");
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
                let floor_cells = if group.iter().all(|r| r.floors.is_some()) {
                    let f = |i: usize| {
                        mean(&|r| {
                            r.floors
                                .map_or(f64::NAN, |f| if i == 0 { f.0 } else { f.1 })
                        })
                    };
                    let ratio = mean(&|r| r.floors.map_or(f64::NAN, |f| f.1 / f.0));
                    format!("{:.4} | {:.4} | {ratio:.2}", f(0), f(1))
                } else {
                    "- | - | -".to_string()
                };
                println!(
                    "| {} | {gain} | {} | {:.4} | {:.4} | {:.2} | {:.1}% | {:.1}% | {floor_cells} | {:.4} |",
                    system.name(),
                    mode.name(),
                    mean(&|r| r.filtered),
                    mean(&|r| r.smoothed),
                    mean(&|r| r.smoothed / r.filtered),
                    100.0 * mean(&|r| r.cover_filtered),
                    100.0 * mean(&|r| r.cover_smoothed),
                    mean(&|r| r.clean),
                );
            }
        }
    }
    Ok(())
}
