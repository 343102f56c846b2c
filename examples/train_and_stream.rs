//! Train a model from MCAP logs, then stream a log through the filter one sample at a time, as
//! a robot's control loop would.
//!
//! ```text
//! cargo run --release --example train_and_stream -- --test TEST.mcap TRAIN.mcap [TRAIN.mcap ...]
//! cargo run --release --example train_and_stream            # simulates its own logs first
//! ```
//!
//! The logs carry the input, state and sensor at the message paths of `hbn simulate`'s logs
//! (`/input.data`, `/state.data`, `/sensor.data`); `hbn train --input/--state/--output` and
//! [`TrainSignals`] name others. Without arguments the example writes three Bouc-Wen logs (two
//! to train on, one to test) into a temporary directory.

use hbn::pipeline::{LogOption, SignalChoice, SimLog, read_at_model_rate, simulate_log};
use hbn::prelude::*;
use hbn::sim::{SimConfig, SystemKind};
use std::path::PathBuf;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let mut args = std::env::args().skip(1);
    let mut test = None;
    let mut train = Vec::new();
    while let Some(arg) = args.next() {
        if arg == "--test" {
            test = Some(PathBuf::from(args.next().ok_or("--test needs a log")?));
        } else {
            train.push(PathBuf::from(arg));
        }
    }
    let scratch = std::env::temp_dir().join(format!("hbn-example-{}", std::process::id()));
    let test = match test {
        Some(test) if !train.is_empty() => test,
        Some(_) => return Err("give at least one training log besides --test".into()),
        None => {
            std::fs::create_dir_all(&scratch)?;
            for (i, input_seed) in [1, 1, 2].into_iter().enumerate() {
                let spec = SimLog {
                    config: SimConfig {
                        seed: 11 + i as u64,
                        ..SimConfig::new(SystemKind::BoucWen)
                    },
                    steps: 800,
                    input_seed,
                    max_increment: hbn::sim::DEFAULT_MAX_INCREMENT,
                    encoding: hbn::io::Encoding::Json,
                };
                let file = scratch.join(format!("log{i}.mcap"));
                simulate_log(&spec, &file)?;
                train.push(file);
            }
            train.pop().ok_or("no test log")?
        }
    };

    // Training: every option at its default (the CLI's `hbn train` and Python's
    // `HysteresisModel.from_logs` run exactly this).
    let trained = train_from_logs(
        &train,
        &TrainSignals::default(),
        LogOptions::default(),
        HbnParams::default(),
        &mut |_| {},
    )?;
    let model = trained.model;
    let mode = model.default_mode();
    println!(
        "trained on {} logs at {} Hz; default mode {mode}",
        train.len(),
        model.rate_hz()
    );

    // The test log on the model's grid: u and y drive the filter, x only scores it.
    let which = [LogOption::Input, LogOption::Output, LogOption::State];
    let log = read_at_model_rate(
        &model,
        &test,
        &SignalChoice::default(),
        &which,
        LogOptions::default(),
        &mut |_| {},
    )?;
    let (u, y, x_true) = (log.column(0), log.column(1), log.column(2));

    // Streaming: one `step` per sample, no allocation inside it.
    let mut filter = Filter::new(model, mode)?;
    let mut x_est = Vec::with_capacity(u.len());
    let mut x_std = Vec::with_capacity(u.len());
    for (&u_k, &y_k) in u.iter().zip(y) {
        let out = filter.step(u_k, y_k);
        x_est.push(out.step.x);
        x_std.push(out.step.x_std);
    }
    let calibrated = calibration(&x_est, &x_std, x_true);
    println!(
        "{} samples: nRMSE {:.4}, {:.1}% of the true state within 2 sd",
        x_est.len(),
        nrmse(&x_est, x_true),
        100.0 * calibrated.coverage_2sigma,
    );
    let _ = std::fs::remove_dir_all(&scratch);
    Ok(())
}
