//! A log to estimates: read `u` and `y` at the model's rate, run the filter, write the
//! estimate as CSV or MCAP on the log's clock. The one implementation behind `hbn estimate`,
//! `hbn eval` and Python's `HysteresisModel.estimate_log`.

use std::path::{Path, PathBuf};

use hbn_core::{Flags, Mode};
use hbn_io::SignalPath;
use hbn_model::{Estimate, HbnModel};
use serde_json::{Value, json};

use crate::error::{LogOption, PipelineError};
use crate::log::{LogData, LogOptions, Observer, load_log, parse_signal};
use crate::train::{DEFAULT_INPUT, DEFAULT_OUTPUT, DEFAULT_STATE};

/// Topic of the estimate in an output MCAP.
pub const ESTIMATE_TOPIC: &str = "/hbn/estimate";
/// Schema name of the estimate messages.
pub const ESTIMATE_SCHEMA: &str = "hbn/Estimate";
/// CSV header (`t` in seconds from the first grid sample).
pub const CSV_HEADER: &str = "t,x,x_std,y_pred,innovation,nis,flags";

/// The signal paths to read for a model: explicit ones, else those the model was trained
/// with, else the defaults.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct SignalChoice {
    /// Input `u`.
    pub input: Option<SignalPath>,
    /// State `x` (evaluation only).
    pub state: Option<SignalPath>,
    /// Sensor output `y`.
    pub output: Option<SignalPath>,
}

impl SignalChoice {
    /// The path of one signal for `model`.
    pub fn resolve(&self, model: &HbnModel, which: LogOption) -> Result<SignalPath, PipelineError> {
        let s = model.signals();
        let (given, stored, default) = match which {
            LogOption::Input => (&self.input, &s.input.path, DEFAULT_INPUT),
            LogOption::State => (&self.state, &s.state.path, DEFAULT_STATE),
            _ => (&self.output, &s.output.path, DEFAULT_OUTPUT),
        };
        match given {
            Some(p) => Ok(p.clone()),
            None => parse_signal(which, stored.as_deref().unwrap_or(default)),
        }
    }
}

/// Estimates of one log.
#[derive(Clone, Debug)]
pub struct LogEstimate {
    /// `u` (column 0) and `y` (column 1) at the model's rate.
    pub log: LogData,
    /// The filter's output per grid sample.
    pub estimate: Estimate,
    /// The mode it ran in.
    pub mode: Mode,
}

/// Where to write an estimate.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct Outputs {
    /// CSV file ([`CSV_HEADER`]).
    pub csv: Option<PathBuf>,
    /// MCAP file (one JSON channel [`ESTIMATE_TOPIC`] on the log's clock).
    pub mcap: Option<PathBuf>,
}

/// Reads `u` and `y` from `file` at the model's rate and runs the filter in `mode` over them
/// ([`HbnModel::estimate`]); then writes `outputs` (everything is rendered first, so an error
/// leaves no file behind). `log_options.rate_hz` must be unset or the model's rate: a model
/// only estimates on its own grid.
pub fn estimate_log(
    model: &HbnModel,
    file: &Path,
    signals: &SignalChoice,
    mode: Mode,
    log_options: LogOptions,
    outputs: &Outputs,
    observe: &mut Observer<'_>,
) -> Result<LogEstimate, PipelineError> {
    let which = [LogOption::Input, LogOption::Output];
    let log = read_at_model_rate(model, file, signals, &which, log_options, observe)?;
    let estimate = model.estimate(log.column(0), log.column(1), mode)?;
    let out = LogEstimate {
        log,
        estimate,
        mode,
    };
    out.write(outputs)?;
    Ok(out)
}

/// Reads the signals `which` (in that order) of `file` for `model`, on the model's grid.
/// `log_options.rate_hz` must be unset or the model's rate.
pub fn read_at_model_rate(
    model: &HbnModel,
    file: &Path,
    signals: &SignalChoice,
    which: &[LogOption],
    log_options: LogOptions,
    observe: &mut Observer<'_>,
) -> Result<LogData, PipelineError> {
    let opts = log_options.check()?;
    if let Some(r) = opts.rate_hz
        && r != model.rate_hz()
    {
        return Err(crate::error::OptionError {
            option: LogOption::Rate,
            problem: hbn_model::Problem::Invalid {
                reason: "a model estimates at the rate it was trained at; leave the rate unset",
            },
        }
        .into());
    }
    let paths = which
        .iter()
        .map(|&w| signals.resolve(model, w))
        .collect::<Result<Vec<_>, _>>()?;
    load_log(file, &paths, Some(model.rate_hz()), &opts, observe)
}

impl LogEstimate {
    /// The estimate as CSV text ([`CSV_HEADER`]).
    pub fn csv_text(&self) -> String {
        use std::fmt::Write as _;
        let est = &self.estimate;
        let mut s = String::with_capacity(64 * est.len() + 64);
        s.push_str(CSV_HEADER);
        s.push('\n');
        for (k, t) in self.log.aligned.t_s.iter().enumerate() {
            let g = |v: &Vec<f64>| v.get(k).copied().unwrap_or(f64::NAN);
            let _ = writeln!(
                s,
                "{t},{},{},{},{},{},{}",
                g(&est.x),
                g(&est.x_std),
                g(&est.y_pred),
                g(&est.innovation),
                g(&est.nis),
                est.flags.get(k).copied().unwrap_or(0)
            );
        }
        s
    }

    /// One JSON record per grid sample (the MCAP messages).
    pub fn records(&self) -> Vec<Value> {
        let est = &self.estimate;
        (0..self.log.len())
            .map(|k| {
                let f = est.flags.get(k).copied().unwrap_or(0);
                let g = |v: &Vec<f64>| v.get(k).copied().unwrap_or(f64::NAN);
                json!({
                    "x": g(&est.x),
                    "x_std": g(&est.x_std),
                    "y_pred": g(&est.y_pred),
                    "innovation": g(&est.innovation),
                    "nis": g(&est.nis),
                    "flags": f,
                    "flag_names": Flags(f).names().collect::<Vec<_>>(),
                })
            })
            .collect()
    }

    /// Writes the requested outputs atomically (CSV text is rendered before anything is
    /// written).
    pub fn write(&self, outputs: &Outputs) -> Result<(), PipelineError> {
        let csv = outputs.csv.as_ref().map(|f| (f, self.csv_text()));
        if let Some(f) = &outputs.mcap {
            hbn_io::write_json_log(
                f,
                ESTIMATE_TOPIC,
                ESTIMATE_SCHEMA,
                &estimate_schema(),
                &self.log.times_ns(),
                &self.records(),
            )
            .map_err(|source| PipelineError::Write {
                file: f.clone(),
                source,
            })?;
        }
        if let Some((f, text)) = csv {
            hbn_fs::write_atomic(f, text.as_bytes()).map_err(|e| PipelineError::Write {
                file: f.clone(),
                source: e.into(),
            })?;
        }
        Ok(())
    }
}

/// JSON schema of the estimate messages.
pub fn estimate_schema() -> Value {
    json!({
        "title": ESTIMATE_SCHEMA,
        "description": "State estimate of the hbn EKF, one message per resampled sample",
        "type": "object",
        "properties": {
            "x": {"type": "number", "description": "estimate of the state x"},
            "x_std": {"type": "number", "description": "standard deviation of the estimate"},
            "y_pred": {"type": "number", "description": "predicted sensor output before the update"},
            "innovation": {"type": "number", "description": "y - y_pred"},
            "nis": {"type": "number", "description": "normalised innovation squared"},
            "flags": {"type": "integer", "description": "guard flags (bitset)"},
            "flag_names": {"type": "array", "items": {"type": "string"}, "description": "names of the set flags"}
        },
        "required": ["x", "x_std", "y_pred", "innovation", "nis", "flags", "flag_names"]
    })
}
