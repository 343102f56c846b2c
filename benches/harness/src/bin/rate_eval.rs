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
//! [`hbn_pipeline::train_from_logs`] at the default rate (no rate given), at the input's and
//! the sensor's rates, at half the sensor's and at every rate of `--rates`, once per distinct
//! rate. Each estimates the test log through [`hbn_pipeline::estimate_log`] in its default
//! mode; the estimate, interpolated linearly at the simulator's samples inside its grid, is
//! scored by nRMSE against the true state there.
//!
//! Each rule of the grid rate picks one of the models trained:
//! - `input`: the input's native rate;
//! - `sensor`: the sensor's native rate;
//! - `slowest`: the slower of the input's and the sensor's;
//! - `held-out (input, sensor)`: of the input's and the sensor's rates, the one whose model has
//!   the lower held-out nRMSE in training (both trained);
//! - `held-out (sensor, sensor / 2)`: the same between the sensor's rate and half of it;
//! - `default`: what `train_from_logs` chooses with no rate given;
//! - `N Hz`: the rate forced.
//!
//! One JSON object per line (per case and setup), then per setup a table: per rule the rates it
//! chose, the geometric-mean nRMSE, its geometric-mean ratio to the best model of each case,
//! the worst such ratio, and the mean training time the rule costs (the held-out rules: both
//! trainings). `--tables FILE...` prints the tables of saved JSON lines (several runs' output
//! together) without running.
//!
//! ```text
//! rate_eval --systems bouc-wen,duhem,preisach --gains 0,1,10 --seeds 1,2,3 > rates.jsonl
//! rate_eval --tables rates.jsonl
//! ```
use hbn_harness::parse;
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
    #[arg(long, value_delimiter = ',', required_unless_present = "tables", value_parser = parse::<SystemKind>)]
    systems: Vec<SystemKind>,
    /// Noise gains (comma-separated).
    #[arg(long, value_delimiter = ',', required_unless_present = "tables")]
    gains: Vec<f64>,
    /// Seeds (comma-separated).
    #[arg(long, value_delimiter = ',', required_unless_present = "tables")]
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
    /// Print the tables of these files of JSON lines (earlier runs' output, concatenated)
    /// instead of running.
    #[arg(long, num_args = 1..)]
    tables: Vec<PathBuf>,
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

/// One case in one setup: the models trained, the default's first.
struct Row {
    setup: String,
    trials: Vec<Trial>,
}

impl Row {
    /// The trial at `rate`, if one was trained there.
    fn at(&self, rate: f64) -> Option<&Trial> {
        self.trials.iter().find(|t| t.rate == rate)
    }

    /// Of the trials at `rates`, the one with the lowest held-out nRMSE, and the seconds
    /// training at all of them took.
    fn held_out(&self, rates: &[f64]) -> Option<(Trial, f64)> {
        let mut rates = rates.to_vec();
        rates.sort_by(f64::total_cmp);
        rates.dedup();
        let trials: Vec<&Trial> = rates.iter().map(|&r| self.at(r)).collect::<Option<_>>()?;
        let best = trials
            .iter()
            .min_by(|a, b| a.held_out.total_cmp(&b.held_out))?;
        Some((**best, trials.iter().map(|t| t.seconds).sum()))
    }

    /// The trial rule `rule` picks and the training seconds the rule costs.
    fn pick(&self, rule: &Rule, setup: &Setup) -> Option<(Trial, f64)> {
        let (u, y) = (setup.input_hz, setup.sensor_hz);
        let one = |rate: f64| self.at(rate).map(|t| (*t, t.seconds));
        match rule {
            Rule::Input => one(u),
            Rule::Sensor => one(y),
            Rule::Slowest => one(u.min(y)),
            Rule::HeldOut => self.held_out(&[u, y]),
            Rule::HeldOutHalf => self.held_out(&[y, y / 2.0]),
            Rule::Default => self.trials.first().map(|t| (*t, t.seconds)),
            Rule::Forced(r) => one(*r),
        }
    }

    fn json(&self, system: &str, gain: f64, seed: u64) -> serde_json::Value {
        serde_json::json!({
            "system": system,
            "gain": gain,
            "seed": seed,
            "setup": self.setup,
            "default_rate_hz": self.trials.first().map(|t| t.rate),
            "trials": self.trials.iter().map(|t| serde_json::json!({
                "rate_hz": t.rate,
                "nrmse": t.nrmse,
                "held_out_nrmse": t.held_out,
                "seconds": t.seconds,
            })).collect::<Vec<_>>(),
        })
    }

    /// A row from its JSON line; the default's trial (at `default_rate_hz`) first.
    fn from_json(v: &serde_json::Value) -> Option<Row> {
        let num = |t: &serde_json::Value, k: &str| t.get(k).and_then(|x| x.as_f64());
        let mut trials: Vec<Trial> = v
            .get("trials")?
            .as_array()?
            .iter()
            .map(|t| {
                Some(Trial {
                    rate: num(t, "rate_hz")?,
                    nrmse: num(t, "nrmse")?,
                    held_out: num(t, "held_out_nrmse").unwrap_or(f64::NAN),
                    seconds: num(t, "seconds")?,
                })
            })
            .collect::<Option<_>>()?;
        let default = num(v, "default_rate_hz")?;
        let i = trials.iter().position(|t| t.rate == default)?;
        trials.swap(0, i);
        Some(Row {
            setup: v.get("setup")?.as_str()?.to_owned(),
            trials,
        })
    }
}

/// A rule of the grid rate.
#[derive(Clone, Copy, Debug)]
enum Rule {
    Input,
    Sensor,
    Slowest,
    HeldOut,
    HeldOutHalf,
    Default,
    Forced(f64),
}

impl Rule {
    fn name(&self) -> String {
        match self {
            Rule::Input => "input".into(),
            Rule::Sensor => "sensor".into(),
            Rule::Slowest => "slowest".into(),
            Rule::HeldOut => "held-out (input, sensor)".into(),
            Rule::HeldOutHalf => "held-out (sensor, sensor / 2)".into(),
            Rule::Default => "default".into(),
            Rule::Forced(r) => format!("{r} Hz"),
        }
    }
}

/// Per setup, the table of the rules over `rows`.
fn tables(rows: &[Row], setups: &[Setup], rates: &[f64]) {
    let mut rules = vec![
        Rule::Input,
        Rule::Sensor,
        Rule::Slowest,
        Rule::HeldOut,
        Rule::HeldOutHalf,
        Rule::Default,
    ];
    rules.extend(rates.iter().map(|&r| Rule::Forced(r)));
    let geo = |v: &[f64]| {
        let logs: Vec<f64> = v.iter().map(|x| x.ln()).filter(|x| x.is_finite()).collect();
        (logs.iter().sum::<f64>() / logs.len().max(1) as f64).exp()
    };
    for setup in setups {
        let group: Vec<&Row> = rows.iter().filter(|r| r.setup == setup.name).collect();
        if group.is_empty() {
            continue;
        }
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
        for rule in &rules {
            let picks: Vec<(Trial, f64, f64)> = group
                .iter()
                .filter_map(|r| {
                    let (t, secs) = r.pick(rule, setup)?;
                    let best = r
                        .trials
                        .iter()
                        .map(|t| t.nrmse)
                        .fold(f64::INFINITY, f64::min);
                    Some((t, secs, t.nrmse / best))
                })
                .collect();
            if picks.len() < group.len() {
                continue;
            }
            let mut chosen: Vec<f64> = picks.iter().map(|p| p.0.rate).collect();
            chosen.sort_by(f64::total_cmp);
            chosen.dedup();
            let nr: Vec<f64> = picks.iter().map(|p| p.0.nrmse).collect();
            let ratios: Vec<f64> = picks.iter().map(|p| p.2).collect();
            println!(
                "| {} | {} | {:.4} | {:.3} | {:.3} | {:.1} |",
                rule.name(),
                chosen
                    .iter()
                    .map(|r| format!("{r}"))
                    .collect::<Vec<_>>()
                    .join(", "),
                geo(&nr),
                geo(&ratios),
                ratios.iter().copied().fold(f64::NAN, f64::max),
                picks.iter().map(|p| p.1).sum::<f64>() / picks.len() as f64,
            );
        }
    }
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
    if !args.tables.is_empty() {
        let mut rows = Vec::new();
        for file in &args.tables {
            for line in std::fs::read_to_string(file)?.lines() {
                if !line.starts_with('{') {
                    continue;
                }
                let v: serde_json::Value = serde_json::from_str(line)?;
                rows.push(
                    Row::from_json(&v)
                        .ok_or_else(|| format!("{}: not a line of rate_eval", file.display()))?,
                );
            }
        }
        tables(&rows, &setups, &args.rates);
        return Ok(());
    }
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
                for setup in &setups {
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
                    let mut trials = vec![trial(&logs, &test_file, &test, None, seed)?];
                    let wanted = [setup.input_hz, setup.sensor_hz, setup.sensor_hz / 2.0];
                    for &rate in wanted.iter().chain(&args.rates) {
                        if !trials.iter().any(|t| t.rate == rate) {
                            trials.push(trial(&logs, &test_file, &test, Some(rate), seed)?);
                        }
                    }
                    let row = Row {
                        setup: setup.name.to_owned(),
                        trials,
                    };
                    println!("{}", row.json(system.name(), gain, seed));
                    rows.push(row);
                }
            }
        }
    }
    if args.dir.is_none() {
        let _ = std::fs::remove_dir_all(&dir);
    }
    tables(&rows, &setups, &args.rates);
    Ok(())
}
