//! The grid rate `hbn train` uses when no rate is given: for every system x noise gain x seed,
//! runs simulated at `--sim-hz` (three 10 s training runs, each with its own random-ramp
//! input, and a fresh 10 s test run) are written as MCAP logs whose topics each have their own
//! rate, as a rig records them, in three setups:
//! - `a`: valve (input) 200 Hz, sensor 100 Hz, camera (state) 30 Hz;
//! - `b`: valve 50 Hz, sensor 100 Hz, camera 30 Hz;
//! - `c`: everything 100 Hz.
//!
//! The camera records the state as [`hbn_pipeline::StateCamera`] does (frames at their own
//! times, the true state interpolated between the simulator's samples); the test log holds the
//! state at every simulator sample instead. A default model (seeded) is trained through
//! [`hbn_pipeline::train_from_logs`] at every rate of `--rates` and at the default rate (no rate
//! given; the first trained), and estimates the test log through [`hbn_pipeline::estimate_log`] in its default
//! mode; the estimate, interpolated linearly at the simulator's samples inside its grid, is
//! scored by nRMSE against the true state there.
//!
//! Each rule of the grid rate picks one of the models trained:
//! - `input`: the input's native rate;
//! - `sensor`: the sensor's native rate;
//! - `slowest`: the slower of the input's and the sensor's;
//! - `held-out`: of the input's and the sensor's rates, the one whose model has the lower
//!   held-out nRMSE in training (two trainings);
//! - `default`: what `train_from_logs` chooses with no rate given;
//! - `N Hz`: the rate forced.
//!
//! One JSON object per line (per case and setup), then per setup a table: per rule the rates it
//! chose, the geometric-mean nRMSE, its geometric-mean ratio to the best rule of each case, the
//! worst such ratio, and the mean training time of the model chosen.
//!
//! ```text
//! rate_eval --systems bouc-wen,duhem,preisach --gains 0,1,10 --seeds 1,2,3
//! ```
use std::path::{Path, PathBuf};
use std::time::Instant;

use clap::Parser;
use hbn_io::{Encoding, TimedTopic};
use hbn_model::HbnParams;
use hbn_model::metrics::nrmse;
use hbn_pipeline::{
    LogOptions, Outputs, SignalChoice, StateCamera, TrainSignals, estimate_log, log_times,
    train_from_logs,
};
use hbn_sim::{InputKind, SimConfig, SystemKind, Trajectory};

/// Training at candidate grid rates from logs with topics at their own rates, one JSON line per
/// case and setup.
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
    /// Setups (comma-separated): `a` valve 200 Hz, sensor 100 Hz, camera 30 Hz; `b` valve
    /// 50 Hz, sensor 100 Hz, camera 30 Hz; `c` everything 100 Hz.
    #[arg(long, value_delimiter = ',', default_value = "a,b,c")]
    setups: Vec<String>,
    /// Grid rates to train at (Hz, comma-separated); each divides `--sim-hz`.
    #[arg(long, value_delimiter = ',', default_value = "50,100,200")]
    rates: Vec<f64>,
    /// The simulator's rate (Hz): every topic's rate divides it.
    #[arg(long, default_value_t = 200.0)]
    sim_hz: f64,
    /// Training runs (each its own input and noise).
    #[arg(long, default_value_t = 3)]
    runs: usize,
    /// Length of each training run (s).
    #[arg(long, default_value_t = 10.0)]
    train_s: f64,
    /// Length of the test run (s).
    #[arg(long, default_value_t = 10.0)]
    test_s: f64,
    /// Fraction of the camera's frames dropped.
    #[arg(long, default_value_t = 0.0)]
    camera_drop: f64,
    /// Directory for the logs (default: a temporary one, removed at the end).
    #[arg(long)]
    dir: Option<PathBuf>,
}

/// A value of `T` by its `FromStr`, the error as text (for clap).
fn parse<T: std::str::FromStr>(s: &str) -> Result<T, String>
where
    T::Err: std::fmt::Display,
{
    s.parse().map_err(|e: T::Err| e.to_string())
}

/// How a rig records: each topic's rate (Hz).
#[derive(Clone, Copy, Debug)]
struct Setup {
    name: &'static str,
    input_hz: f64,
    sensor_hz: f64,
    camera_hz: f64,
}

const SETUPS: [Setup; 3] = [
    Setup {
        name: "a",
        input_hz: 200.0,
        sensor_hz: 100.0,
        camera_hz: 30.0,
    },
    Setup {
        name: "b",
        input_hz: 50.0,
        sensor_hz: 100.0,
        camera_hz: 30.0,
    },
    Setup {
        name: "c",
        input_hz: 100.0,
        sensor_hz: 100.0,
        camera_hz: 100.0,
    },
];

/// The rules compared, in table order.
const RULES: [&str; 5] = ["input", "sensor", "slowest", "held-out", "default"];

/// Every `step`-th of `values`.
fn every(values: &[f64], step: usize) -> Vec<f64> {
    values.iter().step_by(step).copied().collect()
}

/// Every `step`-th of `times`.
fn every_t(times: &[u64], step: usize) -> Vec<u64> {
    times.iter().step_by(step).copied().collect()
}

/// Samples of the simulator per sample of a topic at `hz`.
fn step_of(sim_hz: f64, hz: f64) -> Result<usize, String> {
    let step = sim_hz / hz;
    if step >= 1.0 && (step - step.round()).abs() < 1e-9 {
        Ok(step.round() as usize)
    } else {
        Err(format!(
            "{hz} Hz does not divide the simulator's {sim_hz} Hz"
        ))
    }
}

/// Writes `run` as a rig in `setup` records it: input and sensor every few simulator samples,
/// the state as a camera sees it (`camera`), or at every simulator sample (`None`).
fn write_run(
    file: &Path,
    run: &Trajectory,
    setup: &Setup,
    camera: Option<&StateCamera>,
) -> Result<(), Box<dyn std::error::Error>> {
    let t = log_times(run.u.len(), run.rate_hz);
    let ui = step_of(run.rate_hz, setup.input_hz)?;
    let yi = step_of(run.rate_hz, setup.sensor_hz)?;
    let (u_t, u) = (every_t(&t, ui), every(&run.u, ui));
    let (y_t, y) = (every_t(&t, yi), every(&run.y, yi));
    let (x_t, x) = match camera {
        Some(c) => {
            let frames = c.observe(run.rate_hz, &[&run.x])?;
            let x = frames.x.into_iter().next().unwrap_or_default();
            (frames.t_ns, x)
        }
        None => (t.clone(), run.x.clone()),
    };
    let topics = [
        TimedTopic {
            topic: "/input",
            t_ns: &u_t,
            fields: &[("data", &u)],
        },
        TimedTopic {
            topic: "/state",
            t_ns: &x_t,
            fields: &[("data", &x)],
        },
        TimedTopic {
            topic: "/sensor",
            t_ns: &y_t,
            fields: &[("data", &y)],
        },
    ];
    hbn_io::write_timed_log(file, &topics, Encoding::Json)?;
    Ok(())
}

/// A run of `steps` samples with a random-ramp input of seed `input_seed`, noise seed
/// `noise_seed`; the input's largest increment scaled so that it moves as fast per second as
/// the default's at 100 Hz.
fn run(
    system: SystemKind,
    gain: f64,
    sim_hz: f64,
    steps: usize,
    input_seed: u64,
    noise_seed: u64,
) -> Result<Trajectory, Box<dyn std::error::Error>> {
    let inc = hbn_sim::DEFAULT_MAX_INCREMENT * 100.0 / sim_hz;
    let u = hbn_sim::generate_input(InputKind::RandomRamps, steps, inc, input_seed)?;
    let cfg = SimConfig {
        system,
        noise_gain: gain,
        rate_hz: sim_hz,
        seed: noise_seed,
    };
    Ok(hbn_sim::simulate(&cfg, &u)?)
}

/// `estimate` (at grid times `grid_s`, seconds from `grid_t0_ns`) interpolated linearly at the
/// simulator's sample times `truth_t` (ns) inside the grid, and the truth there.
fn on_truth(
    grid_t0_ns: u64,
    grid_s: &[f64],
    estimate: &[f64],
    truth_t: &[u64],
    truth: &[f64],
) -> (Vec<f64>, Vec<f64>) {
    let mut est = Vec::new();
    let mut tru = Vec::new();
    let (Some(&first), Some(&last)) = (grid_s.first(), grid_s.last()) else {
        return (est, tru);
    };
    for (&t, &x) in truth_t.iter().zip(truth) {
        let s = (t as f64 - grid_t0_ns as f64) * 1e-9;
        if s < first - 1e-9 || s > last + 1e-9 {
            continue;
        }
        let i = grid_s.partition_point(|&g| g <= s);
        let v = match i {
            0 => estimate[0],
            i if i >= grid_s.len() => estimate[grid_s.len() - 1],
            i => {
                let (a, b) = (grid_s[i - 1], grid_s[i]);
                let w = if b > a { (s - a) / (b - a) } else { 0.0 };
                (1.0 - w) * estimate[i - 1] + w * estimate[i]
            }
        };
        est.push(v);
        tru.push(x);
    }
    (est, tru)
}

/// One trained model's scores.
#[derive(Clone, Copy, Debug)]
struct Trial {
    rate: f64,
    nrmse: f64,
    held_out: f64,
    seconds: f64,
}

/// Trains at `rate` (`None`: the default) and scores the test log.
fn trial(
    logs: &[PathBuf],
    test: &Path,
    truth: &Trajectory,
    rate: Option<f64>,
    seed: u64,
) -> Result<Trial, Box<dyn std::error::Error>> {
    let params = HbnParams {
        seed,
        ..HbnParams::default()
    };
    let opts = LogOptions {
        rate_hz: rate,
        ..LogOptions::default()
    };
    let clock = Instant::now();
    let trained = train_from_logs(logs, &TrainSignals::default(), opts, params, &mut |_| {})?;
    let seconds = clock.elapsed().as_secs_f64();
    let model = trained.model;
    let mode = model.default_mode();
    let held_out = model
        .summary()
        .validation
        .as_ref()
        .and_then(|v| v.rows.iter().find(|r| r.mode == v.default_mode))
        .map_or(f64::NAN, |r| r.tuned.nrmse);
    let est = estimate_log(
        &model,
        test,
        &SignalChoice::default(),
        mode,
        LogOptions::default(),
        &Outputs::default(),
        &mut |_| {},
    )?;
    let truth_t = log_times(truth.x.len(), truth.rate_hz);
    let (e, x) = on_truth(
        est.log.aligned.t0_ns,
        &est.log.aligned.t_s,
        &est.estimate.x,
        &truth_t,
        &truth.x,
    );
    Ok(Trial {
        rate: model.rate_hz(),
        nrmse: nrmse(&e, &x),
        held_out,
        seconds,
    })
}

/// One case in one setup: each rule's pick.
struct Row {
    setup: usize,
    /// Per rule of [`RULES`], then per forced rate: the trial chosen.
    picks: Vec<Trial>,
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args = Args::parse();
    let setups: Vec<Setup> = args
        .setups
        .iter()
        .map(|n| {
            SETUPS
                .iter()
                .find(|s| s.name == n.trim())
                .copied()
                .ok_or_else(|| format!("unknown setup {n}: a, b or c"))
        })
        .collect::<Result<_, _>>()?;
    let tmp;
    let dir = match &args.dir {
        Some(d) => {
            std::fs::create_dir_all(d)?;
            d.clone()
        }
        None => {
            tmp = std::env::temp_dir().join(format!("rate_eval-{}", std::process::id()));
            std::fs::create_dir_all(&tmp)?;
            tmp.clone()
        }
    };
    let train_steps = (args.train_s * args.sim_hz).round() as usize;
    let test_steps = (args.test_s * args.sim_hz).round() as usize;
    let mut rows = Vec::new();
    for &system in &args.systems {
        for &gain in &args.gains {
            for &seed in &args.seeds {
                let runs: Vec<Trajectory> = (0..args.runs as u64)
                    .map(|r| {
                        let s = seed * 1000 + r;
                        run(system, gain, args.sim_hz, train_steps, s, s)
                    })
                    .collect::<Result<_, _>>()?;
                let test = run(
                    system,
                    gain,
                    args.sim_hz,
                    test_steps,
                    seed * 1000 + 999,
                    seed * 1000 + 999,
                )?;
                for (si, setup) in setups.iter().enumerate() {
                    let camera = StateCamera {
                        rate_hz: setup.camera_hz,
                        drop: args.camera_drop,
                        seed,
                    };
                    let logs: Vec<PathBuf> = runs
                        .iter()
                        .enumerate()
                        .map(|(r, tr)| {
                            let f = dir.join(format!("train-{}-{r}.mcap", setup.name));
                            write_run(&f, tr, setup, Some(&camera)).map(|()| f)
                        })
                        .collect::<Result<_, _>>()?;
                    let test_file = dir.join(format!("test-{}.mcap", setup.name));
                    write_run(&test_file, &test, setup, None)?;
                    // One training per distinct rate, the default's (no rate given) first.
                    let default = trial(&logs, &test_file, &test, None, seed)?;
                    let mut trials: Vec<Trial> = vec![default];
                    let mut at = |rate: f64| -> Result<Trial, Box<dyn std::error::Error>> {
                        if let Some(t) = trials.iter().find(|t| t.rate == rate) {
                            return Ok(*t);
                        }
                        let t = trial(&logs, &test_file, &test, Some(rate), seed)?;
                        trials.push(t);
                        Ok(t)
                    };
                    let input = at(setup.input_hz)?;
                    let sensor = at(setup.sensor_hz)?;
                    let slowest = at(setup.input_hz.min(setup.sensor_hz))?;
                    let held_out = if input.held_out <= sensor.held_out {
                        input
                    } else {
                        sensor
                    };
                    let forced: Vec<Trial> = args
                        .rates
                        .iter()
                        .map(|&r| at(r))
                        .collect::<Result<_, _>>()?;
                    let mut picks = vec![input, sensor, slowest, held_out, default];
                    picks.extend(forced);
                    let mut line = serde_json::json!({
                        "system": system.name(),
                        "gain": gain,
                        "seed": seed,
                        "setup": setup.name,
                        "trials": trials.iter().map(|t| serde_json::json!({
                            "rate_hz": t.rate,
                            "nrmse": t.nrmse,
                            "held_out_nrmse": t.held_out,
                            "seconds": t.seconds,
                        })).collect::<Vec<_>>(),
                    });
                    if let Some(o) = line.as_object_mut() {
                        o.insert("default_rate_hz".into(), default.rate.into());
                    }
                    println!("{line}");
                    rows.push(Row { setup: si, picks });
                }
            }
        }
    }
    if args.dir.is_none() {
        let _ = std::fs::remove_dir_all(&dir);
    }
    let names: Vec<String> = RULES
        .iter()
        .map(|r| (*r).to_owned())
        .chain(args.rates.iter().map(|r| format!("{r} Hz")))
        .collect();
    for (si, setup) in setups.iter().enumerate() {
        let group: Vec<&Row> = rows.iter().filter(|r| r.setup == si).collect();
        println!();
        println!(
            "setup {}: input {} Hz, sensor {} Hz, camera {} Hz ({} cases)",
            setup.name,
            setup.input_hz,
            setup.sensor_hz,
            setup.camera_hz,
            group.len()
        );
        println!(
            "| rule | grid rates chosen (Hz) | nRMSE (geo. mean) | / best (geo. mean) | / best (worst) | training s (mean) |"
        );
        println!("|---|---|---|---|---|---|");
        let geo = |v: &[f64]| {
            let logs: Vec<f64> = v.iter().map(|x| x.ln()).filter(|x| x.is_finite()).collect();
            (logs.iter().sum::<f64>() / logs.len().max(1) as f64).exp()
        };
        for (i, name) in names.iter().enumerate() {
            let mut rates: Vec<f64> = group.iter().map(|r| r.picks[i].rate).collect();
            rates.sort_by(f64::total_cmp);
            rates.dedup();
            let nr: Vec<f64> = group.iter().map(|r| r.picks[i].nrmse).collect();
            let ratios: Vec<f64> = group
                .iter()
                .map(|r| {
                    let best = r
                        .picks
                        .iter()
                        .map(|t| t.nrmse)
                        .fold(f64::INFINITY, f64::min);
                    r.picks[i].nrmse / best
                })
                .collect();
            let worst = ratios.iter().copied().fold(f64::NAN, f64::max);
            // The held-out rule trains at both candidate rates.
            let secs: f64 = group
                .iter()
                .map(|r| {
                    if RULES.get(i) == Some(&"held-out") {
                        r.picks[0].seconds
                            + if r.picks[1].rate == r.picks[0].rate {
                                0.0
                            } else {
                                r.picks[1].seconds
                            }
                    } else {
                        r.picks[i].seconds
                    }
                })
                .sum::<f64>()
                / group.len().max(1) as f64;
            println!(
                "| {name} | {} | {:.4} | {:.3} | {:.3} | {:.1} |",
                rates
                    .iter()
                    .map(|r| format!("{r}"))
                    .collect::<Vec<_>>()
                    .join(", "),
                geo(&nr),
                geo(&ratios),
                worst,
                secs
            );
        }
    }
    Ok(())
}
