//! Logs of several inputs, state components and sensors to a vector model, and a vector
//! model's estimate of a log: the one implementation behind `hbn train` and `hbn estimate`
//! with repeated `--input`, `--state` and `--output` flags.

use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use hbn_core::vector::Dims;
use hbn_core::{Flags, Mode};
use hbn_io::SignalPath;
use hbn_model::metrics::{Calibration, calibration, nrmse, rmse};
use hbn_model::{
    HbnParams, Problem, SensorInputs, SignalNames, StateFrame, VectorEstimate, VectorLatentRun,
    VectorModel, VectorSequence,
};
use serde_json::{Value, json};

use crate::error::{LogOption, OptionError, PipelineError};
use crate::eval::Compared;
use crate::log::{Event, GridRate, LogData, LogOptions, Observer, load_log};
use crate::train::load_training_logs;
use crate::train::{DEFAULT_INPUT, DEFAULT_OUTPUT, DEFAULT_STATE, column_frames, state_frames};

/// Where the signals of a vector system are in the logs, in order.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct VectorSignals {
    /// One path per input.
    pub inputs: Vec<SignalPath>,
    /// One path per state component.
    pub states: Vec<SignalPath>,
    /// One path per sensor.
    pub outputs: Vec<SignalPath>,
}

impl VectorSignals {
    /// The sizes, checked against the vector model's limits.
    pub fn dims(&self) -> Result<Dims, PipelineError> {
        Dims::new(self.inputs.len(), self.states.len(), self.outputs.len()).map_err(|_| {
            OptionError {
                option: LogOption::Input,
                problem: Problem::Invalid {
                    reason: "a model takes 1 to 4 --input, 1 to 3 --state and 1 to 4 --output \
                             signals",
                },
            }
            .into()
        })
    }

    /// Whether this is one of each (a scalar model's signals).
    pub fn is_scalar(&self) -> bool {
        self.inputs.len() == 1 && self.states.len() == 1 && self.outputs.len() == 1
    }

    /// Every path, inputs then states then outputs.
    fn all(&self) -> Vec<SignalPath> {
        self.inputs
            .iter()
            .chain(&self.states)
            .chain(&self.outputs)
            .cloned()
            .collect()
    }

    /// The names a model records.
    fn names(&self) -> SignalNames {
        let s = |v: &[SignalPath]| v.iter().map(|p| p.to_string()).collect();
        SignalNames {
            inputs: s(&self.inputs),
            states: s(&self.states),
            outputs: s(&self.outputs),
        }
    }
}

fn parse(text: &str, option: LogOption) -> Result<SignalPath, PipelineError> {
    crate::log::parse_signal(option, text)
}

/// The signals of a log written by `hbn simulate`: `/input.data`, `/state.data` and
/// `/sensor.data` for a scalar system; for a multi-signal one (no `/input` topic) the topics
/// `/input0`, `/input1`, ..., `/sensor0`, ... present in the log and the state fields `x0`,
/// `x1`, ... of `/state` that it can read.
pub fn default_signals(
    log: &Path,
    opts: LogOptions,
    observe: &mut Observer<'_>,
) -> Result<VectorSignals, PipelineError> {
    let topics = hbn_io::list_topics(log).map_err(|source| PipelineError::Read {
        file: log.to_owned(),
        source,
    })?;
    let has = |t: &str| topics.iter().any(|i| i.topic == t);
    if has("/input") || !has(&crate::multi_input_topic(0)) {
        return Ok(VectorSignals {
            inputs: vec![parse(DEFAULT_INPUT, LogOption::Input)?],
            states: vec![parse(DEFAULT_STATE, LogOption::State)?],
            outputs: vec![parse(DEFAULT_OUTPUT, LogOption::Output)?],
        });
    }
    let count = |topic: fn(usize) -> String| (0..8).take_while(|&i| has(&topic(i))).count();
    let inputs = (0..count(crate::multi_input_topic))
        .map(|i| parse(&crate::multi_input_path(i), LogOption::Input))
        .collect::<Result<Vec<_>, _>>()?;
    let outputs = (0..count(crate::multi_output_topic))
        .map(|j| parse(&crate::multi_output_path(j), LogOption::Output))
        .collect::<Result<Vec<_>, _>>()?;
    // The state's fields: the most of x0, x1, x2 the log has.
    let checked = opts.check()?;
    for dx in (1..=hbn_core::vector::MAX_STATES).rev() {
        let states = (0..dx)
            .map(|i| parse(&crate::multi_state_path(i), LogOption::State))
            .collect::<Result<Vec<_>, _>>()?;
        let probe = vec![inputs.first().cloned(), states.last().cloned()]
            .into_iter()
            .flatten()
            .collect::<Vec<_>>();
        match load_log(log, &probe, GridRate::SlowestOf(&[0]), &checked, observe) {
            Ok(_) => {
                return Ok(VectorSignals {
                    inputs,
                    states,
                    outputs,
                });
            }
            Err(e) if dx == 1 => return Err(e),
            Err(_) => {}
        }
    }
    Err(PipelineError::NoModes)
}

/// A vector model trained from logs, with the logs as read.
#[derive(Clone, Debug)]
pub struct TrainedVector {
    /// The model.
    pub model: VectorModel,
    /// The logs on their grid (pieces between gaps), one trajectory each.
    pub logs: Vec<LogData>,
}

/// Row-major `(T, d)` of columns `first..first + d` of a log.
fn rows(log: &LogData, first: usize, d: usize) -> Vec<f64> {
    let t = log.len();
    let mut out = Vec::with_capacity(t * d);
    for k in 0..t {
        for c in first..first + d {
            out.push(log.column(c).get(k).copied().unwrap_or(f64::NAN));
        }
    }
    out
}

/// Trains a vector model from MCAP logs, each log (piece between gaps) one trajectory; as
/// [`crate::train_from_logs`] for a scalar one, the grid at the given rate or at the slowest
/// sensor's native rate in the first log. `sensor_inputs`: each sensor's inputs, none
/// (chosen on held-out data), one for all sensors or one per sensor.
pub fn train_vector_from_logs(
    logs: &[PathBuf],
    signals: &VectorSignals,
    log_options: LogOptions,
    params: HbnParams,
    sensor_inputs: &[SensorInputs],
    observe: &mut Observer<'_>,
) -> Result<TrainedVector, PipelineError> {
    if logs.is_empty() {
        return Err(OptionError {
            option: LogOption::Logs,
            problem: Problem::TooSmall { value: 0, min: 1 },
        }
        .into());
    }
    let dims = signals.dims()?;
    let opts = log_options.check()?;
    let params = params.check()?;
    let paths = signals.all();
    // Without a rate, the slowest sensor sets the grid; later logs take the first's.
    let sensors: Vec<usize> = (dims.inputs + dims.states..paths.len()).collect();
    let state_col = dims.inputs;
    let data = load_training_logs(
        logs,
        &paths,
        state_col..state_col + dims.states,
        &sensors,
        &opts,
        observe,
    )?;
    let rate = data.first().map(LogData::rate_hz).or(opts.rate_hz);
    let state_samples: usize = data
        .iter()
        .map(|d| d.samples_in_grid.get(state_col).copied().unwrap_or(0))
        .sum();
    if state_samples < opts.min_state_samples {
        return Err(PipelineError::TooFewStateSamples {
            path: signals
                .states
                .first()
                .map(|p| p.to_string())
                .unwrap_or_default(),
            samples: state_samples,
            logs: data.len(),
            min: opts.min_state_samples,
            shortest: None,
        });
    }
    observe(Event::LogsRead {
        logs: data.len(),
        samples: data.iter().map(LogData::len).sum(),
    });
    let params = match rate {
        Some(r) => params.with_rate(r)?,
        None => params,
    };
    let arrays: Vec<(Vec<f64>, Vec<f64>, Vec<f64>)> = data
        .iter()
        .map(|d| {
            (
                rows(d, 0, dims.inputs),
                rows(d, dims.inputs, dims.states),
                rows(d, dims.inputs + dims.states, dims.sensors),
            )
        })
        .collect();
    let seqs: Vec<VectorSequence<'_>> = arrays
        .iter()
        .map(|(u, x, y)| VectorSequence::new(u, x, y, dims))
        .collect();
    // A state measured sparsely (a camera slower than the grid, or dropping frames) is latent
    // between its frames: expectation-maximisation.
    let sparse = data
        .iter()
        .any(|d| (state_col..state_col + dims.states).any(|c| state_frames(d, c).is_some()));
    let mut model = if sparse {
        let frames: Vec<Vec<Vec<StateFrame>>> = data
            .iter()
            .map(|d| {
                (state_col..state_col + dims.states)
                    .map(|c| column_frames(d, c))
                    .collect()
            })
            .collect();
        let runs: Vec<VectorLatentRun<'_>> = seqs
            .iter()
            .zip(&frames)
            .map(|(seq, frames)| VectorLatentRun { seq: *seq, frames })
            .collect();
        VectorModel::fit_latent(&runs, &params, signals.names(), sensor_inputs)?
    } else {
        VectorModel::fit_with_sensors(&seqs, &params, signals.names(), sensor_inputs)?
    };
    model.set_read_options(opts.time_source.name(), opts.max_gap_s);
    Ok(TrainedVector { model, logs: data })
}

/// A vector model's estimate of one log.
#[derive(Clone, Debug)]
pub struct VectorLogEstimate {
    /// The inputs then the outputs at the model's rate.
    pub log: LogData,
    /// The estimate.
    pub estimate: VectorEstimate,
}

/// The signals to read for `model`: given ones (an empty list keeps the model's), in order.
pub fn model_signals(
    model: &VectorModel,
    inputs: &[SignalPath],
    outputs: &[SignalPath],
) -> Result<VectorSignals, PipelineError> {
    let names = model.signal_names();
    let pick = |given: &[SignalPath], stored: &[String], option: LogOption, n: usize| {
        if !given.is_empty() {
            if given.len() != n {
                return Err(PipelineError::from(OptionError {
                    option,
                    problem: Problem::Invalid {
                        reason: "give one path per signal of the model, in the model's order \
                                 (`hbn inspect` lists them), or none to read the model's",
                    },
                }));
            }
            return Ok(given.to_vec());
        }
        stored.iter().map(|s| parse(s, option)).collect()
    };
    let d = model.dims();
    Ok(VectorSignals {
        inputs: pick(inputs, &names.inputs, LogOption::Input, d.inputs)?,
        states: names
            .states
            .iter()
            .map(|s| parse(s, LogOption::State))
            .collect::<Result<_, _>>()?,
        outputs: pick(outputs, &names.outputs, LogOption::Output, d.sensors)?,
    })
}

/// Runs `model` over a log: its inputs and outputs read at the model's rate (a non-finite or
/// missing sample of a sensor is left out of that step's update).
pub fn estimate_vector_log(
    model: &VectorModel,
    file: &Path,
    signals: &VectorSignals,
    mode: Mode,
    log_options: LogOptions,
    observe: &mut Observer<'_>,
) -> Result<VectorLogEstimate, PipelineError> {
    let (log, u, y) = read_for_estimate(model, file, signals, log_options, observe)?;
    let estimate = model.estimate(&u, &y, mode)?;
    Ok(VectorLogEstimate { log, estimate })
}

/// [`estimate_vector_log`] smoothed ([`VectorModel::smooth`]): each sample estimated from the
/// whole log. The estimate's `x`, `x_std` and `x_cov` are the smoothed ones, its other fields
/// the filter's.
pub fn smooth_vector_log(
    model: &VectorModel,
    file: &Path,
    signals: &VectorSignals,
    mode: Mode,
    log_options: LogOptions,
    observe: &mut Observer<'_>,
) -> Result<VectorLogEstimate, PipelineError> {
    let (log, u, y) = read_for_estimate(model, file, signals, log_options, observe)?;
    let estimate = model.smooth(&u, &y, mode)?;
    Ok(VectorLogEstimate { log, estimate })
}

/// The log's inputs and outputs at the model's rate, and `u` (`T x du`) and `y` (`T x dy`,
/// NaN inside a sensor's dropout) row-major.
fn read_for_estimate(
    model: &VectorModel,
    file: &Path,
    signals: &VectorSignals,
    log_options: LogOptions,
    observe: &mut Observer<'_>,
) -> Result<(LogData, Vec<f64>, Vec<f64>), PipelineError> {
    let d = model.dims();
    let opts = log_options.check()?;
    let paths: Vec<SignalPath> = signals
        .inputs
        .iter()
        .chain(&signals.outputs)
        .cloned()
        .collect();
    let log = load_log(file, &paths, Some(model.rate_hz()), &opts, observe)?;
    let u = rows(&log, 0, d.inputs);
    let y = measured_rows(&log, d.inputs, d.sensors);
    Ok((log, u, y))
}

/// Columns `first..first + count` of the log as rows, with the samples inside each column's
/// dropout (interpolated, not measured) NaN: left out of the filter's update.
fn measured_rows(log: &LogData, first: usize, count: usize) -> Vec<f64> {
    let mut y = rows(log, first, count);
    for (j, drop) in log.dropouts.iter().skip(first).take(count).enumerate() {
        for (k, dropped) in drop.iter().enumerate() {
            if *dropped && let Some(v) = y.get_mut(k * count + j) {
                *v = f64::NAN;
            }
        }
    }
    y
}

/// The CSV of a vector estimate: `t`, then per state component `x{i}`, `x{i}_std`; with
/// `covariance` the off-diagonals `cov_x{i}_x{j}` (`i < j`); per sensor `y{j}_pred`,
/// `innovation{j}`; then `nis`, `flags`, `flag_names`. Numbers are the shortest text that
/// reads back to the same `f64`.
pub fn vector_csv(e: &VectorLogEstimate, covariance: bool) -> String {
    let d = e.estimate.dims;
    let mut header = vec!["t".to_owned()];
    for i in 0..d.states {
        header.push(format!("x{i}"));
        header.push(format!("x{i}_std"));
    }
    if covariance {
        for i in 0..d.states {
            for j in i + 1..d.states {
                header.push(format!("cov_x{i}_x{j}"));
            }
        }
    }
    for j in 0..d.sensors {
        header.push(format!("y{j}_pred"));
        header.push(format!("innovation{j}"));
    }
    header.extend(["nis".into(), "flags".into(), "flag_names".into()]);
    let mut out = header.join(",");
    out.push('\n');
    let t0 = e.log.aligned.t_s.first().copied().unwrap_or(0.0);
    for k in 0..e.estimate.len() {
        let t = e.log.aligned.t_s.get(k).copied().unwrap_or(f64::NAN) - t0;
        let _ = write!(out, "{t}");
        for i in 0..d.states {
            let _ = write!(
                out,
                ",{},{}",
                e.estimate.x[k * d.states + i],
                e.estimate.x_std[k * d.states + i]
            );
        }
        if covariance {
            for i in 0..d.states {
                for j in i + 1..d.states {
                    let _ = write!(
                        out,
                        ",{}",
                        e.estimate.x_cov[k * d.states * d.states + i * d.states + j]
                    );
                }
            }
        }
        for j in 0..d.sensors {
            let _ = write!(
                out,
                ",{},{}",
                e.estimate.y_pred[k * d.sensors + j],
                e.estimate.innovation[k * d.sensors + j]
            );
        }
        let flags = Flags(e.estimate.flags[k]);
        let names: Vec<&str> = flags.names().collect();
        let _ = writeln!(
            out,
            ",{},{},{}",
            e.estimate.nis[k],
            flags.0,
            names.join("|")
        );
    }
    out
}

/// Schema name of a vector model's estimate messages.
pub const VECTOR_ESTIMATE_SCHEMA: &str = "hbn/VectorEstimate";

/// JSON schema of a vector model's estimate messages.
pub fn vector_estimate_schema() -> Value {
    let numbers =
        |what: &str| json!({"type": "array", "items": {"type": "number"}, "description": what});
    let names =
        |what: &str| json!({"type": "array", "items": {"type": "string"}, "description": what});
    json!({
        "title": VECTOR_ESTIMATE_SCHEMA,
        "description": "State estimate of a vector hbn model, one message per resampled sample",
        "type": "object",
        "properties": {
            "x": numbers("estimate of each state component, in the order of `states`"),
            "x_std": numbers("standard deviation of each component"),
            "y_pred": numbers("predicted output of each sensor before the update, in the order of `outputs`"),
            "innovation": numbers("y - y_pred per sensor (0 where a sensor was not updated)"),
            "nis": {"type": "number", "description": "normalised innovation squared of the update"},
            "flags": {"type": "integer", "description": "guard flags (bitset)"},
            "flag_names": names("names of the set flags"),
            "states": names("the state signals (message paths)"),
            "outputs": names("the sensor signals (message paths)")
        },
        "required": ["x", "x_std", "y_pred", "innovation", "nis", "flags", "flag_names", "states", "outputs"]
    })
}

impl VectorLogEstimate {
    /// One JSON record per grid sample (the MCAP messages): arrays in the order of the model's
    /// `--state` and `--output` signals, with their names.
    pub fn records(&self, names: &SignalNames) -> Vec<Value> {
        let e = &self.estimate;
        let d = e.dims;
        (0..e.len())
            .map(|k| {
                let f = e.flags.get(k).copied().unwrap_or(0);
                let row = |v: &[f64], w: usize| v.get(k * w..(k + 1) * w).unwrap_or(&[]).to_vec();
                json!({
                    "x": row(&e.x, d.states),
                    "x_std": row(&e.x_std, d.states),
                    "y_pred": row(&e.y_pred, d.sensors),
                    "innovation": row(&e.innovation, d.sensors),
                    "nis": e.nis.get(k).copied().unwrap_or(f64::NAN),
                    "flags": f,
                    "flag_names": Flags(f).names().collect::<Vec<_>>(),
                    "states": names.states,
                    "outputs": names.outputs,
                })
            })
            .collect()
    }

    /// Writes the estimate as an MCAP log on [`crate::ESTIMATE_TOPIC`] at the log's times,
    /// atomically.
    pub fn write_mcap(&self, file: &Path, names: &SignalNames) -> Result<(), PipelineError> {
        hbn_io::write_json_log(
            file,
            crate::ESTIMATE_TOPIC,
            VECTOR_ESTIMATE_SCHEMA,
            &vector_estimate_schema(),
            &self.log.times_ns(),
            &self.records(names),
        )
        .map_err(|source| PipelineError::Write {
            file: file.to_owned(),
            source,
        })
    }
}

/// One state component's scores in one mode.
#[derive(Clone, Debug, PartialEq)]
pub struct ComponentScore {
    /// Root-mean-square error.
    pub rmse: f64,
    /// RMSE over the logged component's range.
    pub nrmse: f64,
    /// How well the standard deviation describes the error.
    pub calibration: Calibration,
}

impl ComponentScore {
    /// The scores of a compared series (its standard deviation missing counts as no sample
    /// scored).
    fn of(c: &Compared) -> Self {
        let calibration = calibration(&c.x, c.x_std.as_deref().unwrap_or(&[]), &c.reference);
        Self {
            rmse: rmse(&c.x, &c.reference),
            nrmse: nrmse(&c.x, &c.reference),
            calibration,
        }
    }
}

/// State component `i` of `estimate` against the one logged in `log` ([`Compared::against`]).
fn compared(estimate: &VectorEstimate, log: &LogData, d: Dims, i: usize) -> Compared {
    Compared::against(
        &estimate.component(i),
        Some(&estimate.component_std(i)),
        log,
        d.inputs + i,
    )
}

/// The scores of one mode's runs (filtered or smoothed) over several logs, pooled sample by
/// sample ([`Compared::join`]).
#[derive(Clone, Debug, PartialEq)]
pub struct PooledRun {
    /// The mode.
    pub mode: Mode,
    /// Whether the runs are smoothed.
    pub smoothed: bool,
    /// One score per state component.
    pub scores: Vec<ComponentScore>,
}

impl PooledRun {
    /// The mode's name, followed by ` smoothed` for smoothed runs.
    pub fn label(&self) -> String {
        run_label(self.mode, self.smoothed)
    }
}

/// `ekf`, `ukf smoothed`: a mode's name, followed by ` smoothed` for a smoothed run.
fn run_label(mode: Mode, smoothed: bool) -> String {
    if smoothed {
        format!("{} smoothed", mode.name())
    } else {
        mode.name().to_owned()
    }
}

/// The scores of several evaluations of the vector model with dimensions `dims` (one per log,
/// with the same modes), pooled sample by sample per state component: one [`PooledRun`] per
/// run of the first evaluation, in its order. Empty when `evaluations` is.
pub fn pool_vector_evaluations(evaluations: &[VectorEvaluation], dims: Dims) -> Vec<PooledRun> {
    let Some(first) = evaluations.first() else {
        return Vec::new();
    };
    first
        .runs
        .iter()
        .map(|run| {
            let scores = (0..dims.states)
                .map(|i| {
                    let parts = evaluations.iter().map(|ev| {
                        ev.runs
                            .iter()
                            .find(|r| r.mode == run.mode && r.smoothed == run.smoothed)
                            .map_or_else(Compared::default, |r| {
                                compared(&r.estimate, &ev.log, dims, i)
                            })
                    });
                    ComponentScore::of(&Compared::join(parts))
                })
                .collect();
            PooledRun {
                mode: run.mode,
                smoothed: run.smoothed,
                scores,
            }
        })
        .collect()
}

/// A vector model evaluated on a log in one mode.
#[derive(Clone, Debug)]
pub struct VectorModeRun {
    /// The mode.
    pub mode: Mode,
    /// Whether the estimate is the smoothed one ([`VectorModel::smooth`]) rather than the
    /// filter's.
    pub smoothed: bool,
    /// The estimate.
    pub estimate: VectorEstimate,
    /// One score per state component.
    pub scores: Vec<ComponentScore>,
}

impl VectorModeRun {
    /// The mode's name, followed by ` smoothed` for a smoothed run (`ekf`, `ukf smoothed`).
    pub fn label(&self) -> String {
        run_label(self.mode, self.smoothed)
    }
}

/// A vector model evaluated on a log: the logged state and each mode's run.
#[derive(Clone, Debug)]
pub struct VectorEvaluation {
    /// The log at the model's rate: inputs, states, outputs.
    pub log: LogData,
    /// Each mode's run, in the order asked.
    pub runs: Vec<VectorModeRun>,
}

impl VectorEvaluation {
    /// The logged state component `i`.
    pub fn state(&self, dims: Dims, i: usize) -> &[f64] {
        self.log.column(dims.inputs + i)
    }
}

/// Runs `model` over a log in each of `modes` and scores every state component against the
/// logged state (`signals.states`): at every grid sample, or where the state is measured
/// sparsely (a camera, [`LogData::frames_of`]) at its frames only, each against the estimate
/// interpolated to the frame's time. With `smooth`, each mode's run is followed by its
/// smoothed run ([`VectorModel::smooth`]).
pub fn evaluate_vector_log(
    model: &VectorModel,
    file: &Path,
    signals: &VectorSignals,
    modes: &[Mode],
    smooth: bool,
    log_options: LogOptions,
    observe: &mut Observer<'_>,
) -> Result<VectorEvaluation, PipelineError> {
    if modes.is_empty() {
        return Err(PipelineError::NoModes);
    }
    let d = model.dims();
    let opts = log_options.check()?;
    let log = load_log(file, &signals.all(), Some(model.rate_hz()), &opts, observe)?;
    let u = rows(&log, 0, d.inputs);
    let y = measured_rows(&log, d.inputs + d.states, d.sensors);
    let score = |estimate: &VectorEstimate| -> Vec<ComponentScore> {
        (0..d.states)
            .map(|i| ComponentScore::of(&compared(estimate, &log, d, i)))
            .collect()
    };
    let mut runs = Vec::with_capacity(modes.len() * (1 + usize::from(smooth)));
    for &mode in modes {
        if smooth {
            let both = model.smooth_with(&u, &y, mode)?;
            for (smoothed, estimate) in [(false, both.filtered), (true, both.estimate)] {
                let scores = score(&estimate);
                runs.push(VectorModeRun {
                    mode,
                    smoothed,
                    estimate,
                    scores,
                });
            }
        } else {
            let estimate = model.estimate(&u, &y, mode)?;
            let scores = score(&estimate);
            runs.push(VectorModeRun {
                mode,
                smoothed: false,
                estimate,
                scores,
            });
        }
    }
    Ok(VectorEvaluation { log, runs })
}
