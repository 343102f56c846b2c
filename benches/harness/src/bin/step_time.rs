//! The estimator step of trained models, timed over whole passes of a log: for each model file
//! and mode, `--passes` runs of a fresh estimator over every sample of the log's `u` and `y`
//! (read at the model's rate, at the model's message paths), one JSON object per line with the
//! fastest and the median pass in microseconds per step. On a shared machine whose speed drifts,
//! the fastest pass is the step's own cost and the median says how much the machine took.
//! Vector models (`hbn-vector-model` files) are stepped by `hbn_core::vector::VectorEkf` over
//! the signals they record, in their modes (ekf, ukf).
//!
//! ```text
//! step_time --model exact.hbn --model m64.hbn --log test.mcap [--modes ekf,ekf-blr,ukf] \
//!     [--passes 15]
//! ```
//!
//! Each pass is also timed by the thread's time on a CPU (Linux `/proc/thread-self/schedstat`,
//! nanoseconds): `fastest_cpu_us` and `median_cpu_us` leave out the time other processes held
//! the CPU, so builds compared on a busy machine keep their ratio.
//!
//! For a profile, run it under `perf record` with one mode and many passes
//! (`--modes ekf --passes 1000`): the model is loaded, not trained, so nearly all samples fall
//! in the step.
use clap::Parser;
use hbn_core::{Estimator, Mode};
use hbn_harness::parse;
use hbn_model::{HysteresisModel, VectorModel};
use hbn_pipeline::{
    LogOption, LogOptions, SignalChoice, estimate_vector_log, model_signals, read_at_model_rate,
};
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

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args = Args::parse();
    let passes = args.passes.max(1);
    for path in &args.model {
        let model = match HysteresisModel::load(path) {
            Ok(m) => m,
            Err(scalar_err) => match VectorModel::load(path) {
                Ok(v) => {
                    time_vector(&v, path, &args, passes)?;
                    continue;
                }
                Err(_) => return Err(scalar_err.into()),
            },
        };
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
            let mut times = Times::default();
            for _ in 0..passes {
                let mut scratch = vec![0.0; Estimator::scratch_len(&view)];
                let mut est = Estimator::new(view, model.ekf_config(mode), &mut scratch)?;
                let t = Clock::start();
                for (&u, &y) in u.iter().zip(y) {
                    black_box(est.step(black_box(u), black_box(y)));
                }
                times.push(t, u.len());
            }
            times.print(serde_json::json!({
                "model": path.display().to_string(),
                "mode": mode.name(),
                "transition_points": model.transition().n_support(),
                "sensor_points": model.sensor().n_support(),
                "sparse": model.transition().is_sparse(),
                "steps": u.len(),
                "passes": passes,
            }));
        }
    }
    Ok(())
}

/// [`main`]'s passes for a vector model: its recorded signals, read as `hbn estimate` reads them.
fn time_vector(
    model: &VectorModel,
    path: &std::path::Path,
    args: &Args,
    passes: usize,
) -> Result<(), Box<dyn std::error::Error>> {
    use hbn_core::vector::{VectorEkf, VectorView};
    let d = model.dims();
    let signals = model_signals(model, &[], &[])?;
    // One estimate reads the log as the CLI does (rows of u and y at the model's rate).
    let read = estimate_vector_log(
        model,
        &args.log,
        &signals,
        model.default_mode(),
        LogOptions::default(),
        &mut |_| {},
    )?;
    let n = read.log.len();
    let col = |i: usize, k: usize| read.log.column(i).get(k).copied().unwrap_or(f64::NAN);
    let u: Vec<f64> = (0..n)
        .flat_map(|k| (0..d.inputs).map(move |a| (a, k)))
        .map(|(a, k)| col(a, k))
        .collect();
    let y: Vec<f64> = (0..n)
        .flat_map(|k| (0..d.sensors).map(move |j| (j, k)))
        .map(|(j, k)| col(d.inputs + j, k))
        .collect();
    let transitions = (0..d.states)
        .map(|i| {
            model
                .transition(i)
                .ok_or("missing transition GP")?
                .view()
                .map_err(Into::into)
        })
        .collect::<Result<Vec<_>, Box<dyn std::error::Error>>>()?;
    let sensors = (0..d.sensors)
        .map(|j| {
            model
                .sensor(j)
                .ok_or("missing sensor GP")?
                .view()
                .map_err(Into::into)
        })
        .collect::<Result<Vec<_>, Box<dyn std::error::Error>>>()?;
    let view = VectorView {
        dims: d,
        transitions: &transitions,
        sensors: &sensors,
        plays: model.plays()?,
        init: model.init_prior(),
    };
    for &mode in args.modes.iter().filter(|m| **m != Mode::EkfBlr) {
        let ekf = VectorEkf::new(view, model.config(mode))?;
        let mut scratch = vec![0.0; ekf.scratch_len()];
        let mut times = Times::default();
        for _ in 0..passes {
            let mut state = None;
            let t = Clock::start();
            for k in 0..n {
                black_box(ekf.step(
                    &mut state,
                    &mut scratch,
                    black_box(&u[k * d.inputs..(k + 1) * d.inputs]),
                    black_box(&y[k * d.sensors..(k + 1) * d.sensors]),
                ));
            }
            times.push(t, n);
        }
        times.print(serde_json::json!({
            "model": path.display().to_string(),
            "mode": mode.name(),
            "inputs": d.inputs,
            "states": d.states,
            "sensors": d.sensors,
            "transition_points": model.transition(0).map(|g| g.n_support()),
            "sparse": model.transition(0).is_some_and(|g| g.is_sparse()),
            "steps": n,
            "passes": passes,
        }));
    }
    Ok(())
}

/// This thread's time on a CPU in nanoseconds (`None` where Linux's schedstat is missing).
fn thread_cpu_ns() -> Option<u64> {
    std::fs::read_to_string("/proc/thread-self/schedstat")
        .ok()?
        .split_whitespace()
        .next()?
        .parse()
        .ok()
}

/// The start of a timed pass: the wall clock and the thread's CPU time.
struct Clock {
    wall: Instant,
    cpu_ns: Option<u64>,
}

impl Clock {
    fn start() -> Self {
        Self {
            cpu_ns: thread_cpu_ns(),
            wall: Instant::now(),
        }
    }
}

/// Microseconds per step of every pass, by the wall clock and by the thread's CPU time.
#[derive(Default)]
struct Times {
    wall: Vec<f64>,
    cpu: Vec<f64>,
}

impl Times {
    fn push(&mut self, start: Clock, steps: usize) {
        let wall = start.wall.elapsed().as_secs_f64();
        let per_step = 1e6 / steps.max(1) as f64;
        self.wall.push(wall * per_step);
        if let (Some(a), Some(b)) = (start.cpu_ns, thread_cpu_ns()) {
            self.cpu.push(b.saturating_sub(a) as f64 * 1e-9 * per_step);
        }
    }

    /// Prints `fields` as one JSON line with the fastest and median pass of each clock.
    fn print(&self, mut fields: serde_json::Value) {
        let pick = |v: &[f64], median: bool| {
            let mut v = v.to_vec();
            v.sort_by(f64::total_cmp);
            v.get(if median { v.len() / 2 } else { 0 }).copied()
        };
        if let Some(o) = fields.as_object_mut() {
            for (key, v, median) in [
                ("fastest_us", &self.wall, false),
                ("median_us", &self.wall, true),
                ("fastest_cpu_us", &self.cpu, false),
                ("median_cpu_us", &self.cpu, true),
            ] {
                o.insert(key.to_owned(), serde_json::json!(pick(v, median)));
            }
        }
        println!("{fields}");
    }
}
