//! The estimator step of trained models, timed over whole passes of a log: for each model file
//! and mode, `--passes` runs of a fresh estimator over every sample of the log's `u` and `y`
//! (read at the model's rate, at the model's message paths), one JSON object per line with the
//! fastest and the median pass in microseconds per step. On a shared machine whose speed drifts,
//! the fastest pass is the step's own cost and the median says how much the machine took.
//!
//! ```text
//! step_time --model exact.hbn --model m64.hbn --log test.mcap [--modes ekf,ekf-blr,ukf] \
//!     [--passes 15]
//! ```
//!
//! For a profile, run it under `perf record` with one mode and many passes
//! (`--modes ekf --passes 1000`): the model is loaded, not trained, so nearly all samples fall
//! in the step.
use clap::Parser;
use hbn_core::{Estimator, Mode};
use hbn_model::HysteresisModel;
use hbn_pipeline::{LogOption, LogOptions, SignalChoice, read_at_model_rate};
use std::hint::black_box;
use std::path::PathBuf;
use std::time::Instant;

/// Microseconds per estimator step of model files on a log, one JSON line per model and mode.
#[derive(Parser)]
struct Args {
    /// Model file from `hbn train` (repeat for several).
    #[arg(long, required = true)]
    model: Vec<PathBuf>,
    /// MCAP log with the model's input and sensor signals.
    #[arg(long)]
    log: PathBuf,
    /// Modes (comma-separated): ekf, ekf-blr, ukf.
    #[arg(long, value_delimiter = ',', default_value = "ekf,ekf-blr,ukf", value_parser = parse::<Mode>)]
    modes: Vec<Mode>,
    /// Passes over the log per model and mode.
    #[arg(long, default_value_t = 15)]
    passes: usize,
}

/// A value of `T` by its `FromStr`, the error as text (for clap).
fn parse<T: std::str::FromStr>(s: &str) -> Result<T, String>
where
    T::Err: std::fmt::Display,
{
    s.parse().map_err(|e: T::Err| e.to_string())
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args = Args::parse();
    let passes = args.passes.max(1);
    for path in &args.model {
        let model = HysteresisModel::load(path)?;
        let log = read_at_model_rate(
            &model,
            &args.log,
            &SignalChoice::default(),
            &[LogOption::Input, LogOption::Output],
            LogOptions::default(),
            &mut |_| {},
        )?;
        let (u, y) = (log.column(0), log.column(1));
        let view = model.view()?;
        for &mode in &args.modes {
            let mut times = Vec::with_capacity(passes);
            for _ in 0..passes {
                let mut scratch = vec![0.0; Estimator::scratch_len(&view)];
                let mut est = Estimator::new(view, model.ekf_config(mode), &mut scratch)?;
                let t = Instant::now();
                for (&u, &y) in u.iter().zip(y) {
                    black_box(est.step(black_box(u), black_box(y)));
                }
                times.push(t.elapsed().as_secs_f64() * 1e6 / u.len().max(1) as f64);
            }
            times.sort_by(f64::total_cmp);
            println!(
                "{}",
                serde_json::json!({
                    "model": path.display().to_string(),
                    "mode": mode.name(),
                    "transition_points": model.transition().n_support(),
                    "sensor_points": model.sensor().n_support(),
                    "sparse": model.transition().is_sparse(),
                    "steps": u.len(),
                    "passes": passes,
                    "fastest_us": times[0],
                    "median_us": times[times.len() / 2],
                })
            );
        }
    }
    Ok(())
}
