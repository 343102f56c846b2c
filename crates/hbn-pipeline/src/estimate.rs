//! A log to estimates: read `u` and `y` at the model's rate, run the filter, write the
//! estimate as CSV or MCAP on the log's clock. The one implementation behind `hbn estimate`,
//! `hbn eval` and Python's `HysteresisModel.estimate_log`.

use std::path::{Path, PathBuf};

use hbn_core::{Flags, Mode};
use hbn_io::SignalPath;
use hbn_model::{Estimate, HysteresisModel};
use serde_json::{Value, json};

use crate::error::{LogOption, PipelineError};
use crate::log::{LogData, LogOptions, Observer, join_pieces, load_log, parse_signal};
use crate::train::{DEFAULT_INPUT, DEFAULT_OUTPUT, DEFAULT_STATE};

/// Topic of the estimate in an output MCAP.
pub const ESTIMATE_TOPIC: &str = "/hbn/estimate";
/// Schema name of the estimate messages.
pub const ESTIMATE_SCHEMA: &str = "hbn/Estimate";
/// CSV header: `t` in seconds from the first grid sample; `u` and `y` the input and sensor
/// samples the filter ran on (the log on the model's grid), so a program that reads them from
/// the CSV gets the same bits (every number is written as the shortest text that reads back to
/// the same `f64`); then the estimate; `flags` the guard flags as a bit mask, `flag_names` the
/// same as names joined by `|`, see [`hbn_core::Flags::names`].
pub const CSV_HEADER: &str = "t,u,y,x,x_std,y_pred,innovation,nis,flags,flag_names";

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
    pub fn resolve(
        &self,
        model: &HysteresisModel,
        which: LogOption,
    ) -> Result<SignalPath, PipelineError> {
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
    /// The rate each signal of `log` was recorded at in the training logs (Hz), as the model
    /// records it; `None` where it does not.
    pub trained_rates: Vec<Option<f64>>,
    /// Grid times (s) where the filter restarted after a gap longer than the largest allowed
    /// (each such sample carries the flag `initialised`).
    pub restarts: Vec<f64>,
}

/// Share of samples flagged [`hbn_core::Flags::EXTRAPOLATION`] above which an estimate
/// carries an [`EstimateWarning::Extrapolation`].
pub const EXTRAPOLATION_WARNING: f64 = 0.05;

/// Share of measurements down-weighted by the outlier gate ([`hbn_core::Flags::OUTLIER_REJECTED`])
/// above which an estimate carries an [`EstimateWarning::Outliers`]. A calibrated filter gates
/// about one sample in a million (the gate is 5 standard deviations); a quarter of the log is a
/// sensor that disagrees with the model (a broken sensor, another unit, another robot).
pub const OUTLIER_WARNING: f64 = 0.25;

/// Something about an estimate a user should know before trusting it.
#[derive(Clone, Debug, PartialEq)]
pub enum EstimateWarning {
    /// Many samples were outside the training data (either GP's uncertainty as large as its
    /// signal).
    Extrapolation {
        /// Samples flagged.
        samples: usize,
        /// Samples in all.
        total: usize,
    },
    /// Many measurements disagreed with the model's prediction by more than the outlier gate
    /// and were down-weighted (more than [`OUTLIER_WARNING`] of the samples).
    Outliers {
        /// Samples down-weighted.
        samples: usize,
        /// Samples in all.
        total: usize,
    },
    /// The filter lost the state and re-started from the measurement
    /// ([`hbn_core::Flags::RELOCALISED`]: the model's prediction from its estimate left the
    /// training range for [`hbn_core::LOST_AFTER`] samples in a row).
    Lost {
        /// Re-starts.
        times: usize,
        /// Samples in all.
        total: usize,
    },
    /// The log has gaps longer than the largest allowed: the filter restarted after each.
    Restarted {
        /// Grid times (s) of the restarts.
        at_s: Vec<f64>,
    },
    /// A signal is recorded at another rate than in the training logs (or, where the model
    /// does not record those, than the model's rate): the log is resampled differently from
    /// the training logs, and the model sees other interpolation than it learned from.
    RateMismatch {
        /// The signal.
        path: String,
        /// Its native rate in this log (Hz).
        native_hz: f64,
        /// Its native rate in the training logs (Hz), if the model records it.
        trained_hz: Option<f64>,
        /// The model's rate (Hz).
        model_hz: f64,
    },
}

impl std::fmt::Display for EstimateWarning {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            EstimateWarning::Extrapolation { samples, total } => write!(
                f,
                "{samples} of {total} samples ({:.1}%) are outside the training data \
                 (flag `extrapolation`): the estimate there is mostly the model's prior; \
                 train with data that cover these inputs and states",
                100.0 * *samples as f64 / (*total).max(1) as f64
            ),
            EstimateWarning::Outliers { samples, total } => write!(
                f,
                "{samples} of {total} measurements ({:.1}%) were more than 5 standard deviations \
                 from the model's prediction (flag `outlier_rejected`) and were down-weighted: \
                 check the sensor and that the log's signals and units match the training logs; \
                 if they do, the model's noise is too small for this log (train on logs like it)",
                100.0 * *samples as f64 / (*total).max(1) as f64
            ),
            EstimateWarning::Lost { times, total } => write!(
                f,
                "the filter lost the state {times} time{} in {total} samples (flag \
                 `relocalised`: the model's prediction from the estimate left the training range \
                 for {} samples in a row) and re-started from the measurement; the estimate around \
                 those samples is unreliable: check that the log's signals and units match the \
                 training logs, or train with data that cover these inputs and states",
                if *times == 1 { "" } else { "s" },
                hbn_core::LOST_AFTER
            ),
            EstimateWarning::Restarted { at_s } => write!(
                f,
                "the log has {} gap{} longer than the largest gap allowed (--max-gap): the \
                 filter restarted after each (flag `initialised`), at t = {}",
                at_s.len(),
                if at_s.len() == 1 { "" } else { "s" },
                at_s.iter()
                    .map(|t| format!("{t:.3} s"))
                    .collect::<Vec<_>>()
                    .join(", ")
            ),
            EstimateWarning::RateMismatch {
                path,
                native_hz,
                trained_hz: Some(trained_hz),
                model_hz,
            } => write!(
                f,
                "{path} is recorded at {native_hz:.1} Hz here but at {trained_hz:.1} Hz in the \
                 training logs (the model runs at {model_hz:.1} Hz): the log is resampled \
                 differently from the training logs; record it at the training rate, or train \
                 on logs recorded like this one"
            ),
            EstimateWarning::RateMismatch {
                path,
                native_hz,
                trained_hz: None,
                model_hz,
            } => write!(
                f,
                "{path} is recorded at {native_hz:.1} Hz but the model was trained at \
                 {model_hz:.1} Hz: the log was resampled to the model's rate; train a model \
                 at this log's rate for best results"
            ),
        }
    }
}

impl LogEstimate {
    /// What a user should know about this estimate: many samples outside the training data
    /// (more than [`EXTRAPOLATION_WARNING`]), many measurements down-weighted as outliers (more
    /// than [`OUTLIER_WARNING`]), any re-start of a lost filter, signals recorded at another rate than the
    /// model's (by more than [`crate::RATE_NOTICE_TOLERANCE`]).
    pub fn warnings(&self) -> Vec<EstimateWarning> {
        let mut out = Vec::new();
        let total = self.estimate.len();
        let samples = self
            .estimate
            .flags
            .iter()
            .filter(|&&f| hbn_core::Flags(f).has(hbn_core::Flags::EXTRAPOLATION))
            .count();
        if samples as f64 > EXTRAPOLATION_WARNING * total as f64 {
            out.push(EstimateWarning::Extrapolation { samples, total });
        }
        let count = |bit: u32| {
            self.estimate
                .flags
                .iter()
                .filter(|&&f| hbn_core::Flags(f).has(bit))
                .count()
        };
        let samples = count(hbn_core::Flags::OUTLIER_REJECTED);
        if samples as f64 > OUTLIER_WARNING * total as f64 {
            out.push(EstimateWarning::Outliers { samples, total });
        }
        let times = count(hbn_core::Flags::RELOCALISED);
        if times > 0 {
            out.push(EstimateWarning::Lost { times, total });
        }
        if !self.restarts.is_empty() {
            out.push(EstimateWarning::Restarted {
                at_s: self.restarts.clone(),
            });
        }
        // A signal recorded at another rate than in the training logs (or, for a model that does
        // not record those rates, than the model's grid).
        let model_hz = self.log.rate_hz();
        for (i, (path, native)) in self
            .log
            .paths
            .iter()
            .zip(&self.log.native_rates)
            .enumerate()
        {
            let trained_hz = self.trained_rates.get(i).copied().flatten();
            let reference = trained_hz.unwrap_or(model_hz);
            if let Some(native_hz) = *native
                && (native_hz - reference).abs() > crate::RATE_NOTICE_TOLERANCE * reference
            {
                out.push(EstimateWarning::RateMismatch {
                    path: path.to_string(),
                    native_hz,
                    trained_hz,
                    model_hz,
                });
            }
        }
        out
    }
}

/// Where to write an estimate.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct Outputs {
    /// CSV file ([`CSV_HEADER`]).
    pub csv: Option<PathBuf>,
    /// MCAP file (one JSON channel [`ESTIMATE_TOPIC`] on the log's clock).
    pub mcap: Option<PathBuf>,
}

/// `file` with `-{mode}` added to its name before the extension: `est.csv` ->
/// `est-ekf-blr.csv`, `est` -> `est-ekf-blr`.
pub fn file_for_mode(file: &Path, mode: Mode) -> PathBuf {
    let stem = file.file_stem().map(|s| s.to_string_lossy().into_owned());
    let name = match (stem, file.extension()) {
        (Some(stem), Some(ext)) => format!("{stem}-{}.{}", mode.name(), ext.to_string_lossy()),
        (Some(stem), None) => format!("{stem}-{}", mode.name()),
        (None, _) => format!("{}-{}", file.to_string_lossy(), mode.name()),
    };
    file.with_file_name(name)
}

impl Outputs {
    /// The files of one mode when several modes are estimated at once: the mode's name added
    /// to each file name ([`file_for_mode`]).
    pub fn for_mode(&self, mode: Mode) -> Outputs {
        Outputs {
            csv: self.csv.as_deref().map(|f| file_for_mode(f, mode)),
            mcap: self.mcap.as_deref().map(|f| file_for_mode(f, mode)),
        }
    }

    /// The files to write, in order (MCAP, then CSV).
    pub fn files(&self) -> impl Iterator<Item = &Path> {
        self.mcap.iter().chain(&self.csv).map(PathBuf::as_path)
    }
}

/// Reads `u` and `y` from `file` at the model's rate and runs the filter in `mode` over them
/// ([`HysteresisModel::estimate`]); then writes `outputs` (everything is rendered first, so an error
/// leaves no file behind). `log_options.rate_hz` must be unset or the model's rate: a model
/// only estimates on its own grid.
pub fn estimate_log(
    model: &HysteresisModel,
    file: &Path,
    signals: &SignalChoice,
    mode: Mode,
    log_options: LogOptions,
    outputs: &Outputs,
    observe: &mut Observer<'_>,
) -> Result<LogEstimate, PipelineError> {
    let mut all = estimate_log_modes(model, file, signals, &[mode], log_options, outputs, observe)?;
    all.pop().ok_or(PipelineError::NoModes)
}

/// [`estimate_log`] for several modes: reads the log once and runs each mode over it. With one
/// mode the estimate goes to `outputs`; with several, each mode's to
/// [`Outputs::for_mode`] (`est.csv` -> `est-ekf.csv`, `est-ekf-blr.csv`, ...). Every estimate
/// is computed before a file is written, and an error while writing removes the files this
/// call already wrote.
pub fn estimate_log_modes(
    model: &HysteresisModel,
    file: &Path,
    signals: &SignalChoice,
    modes: &[Mode],
    log_options: LogOptions,
    outputs: &Outputs,
    observe: &mut Observer<'_>,
) -> Result<Vec<LogEstimate>, PipelineError> {
    if modes.is_empty() {
        return Err(PipelineError::NoModes);
    }
    let which = [LogOption::Input, LogOption::Output];
    let pieces = read_pieces_at_model_rate(model, file, signals, &which, log_options, observe)?;
    let log = join_pieces(&pieces.pieces).ok_or(PipelineError::NoModes)?;
    let restarts = restart_times(&pieces.pieces, &log);
    let s = model.signals();
    let trained_rates = vec![s.input.native_rate_hz, s.output.native_rate_hz];
    let mut out = Vec::with_capacity(modes.len());
    for &mode in modes {
        let estimate = estimate_pieces(model, &pieces.pieces, 0, 1, mode)?;
        out.push(LogEstimate {
            log: log.clone(),
            estimate,
            mode,
            trained_rates: trained_rates.clone(),
            restarts: restarts.clone(),
        });
    }
    let mut written: Vec<PathBuf> = Vec::new();
    for e in &out {
        let files = if modes.len() == 1 {
            outputs.clone()
        } else {
            outputs.for_mode(e.mode)
        };
        if let Err(err) = e.write(&files) {
            for f in &written {
                let _ = std::fs::remove_file(f);
            }
            return Err(err);
        }
        written.extend(files.files().map(Path::to_path_buf));
    }
    Ok(out)
}

/// Reads the signals `which` (in that order) of `file` for `model`, on the model's grid.
/// `log_options.rate_hz` must be unset or the model's rate.
pub fn read_at_model_rate(
    model: &HysteresisModel,
    file: &Path,
    signals: &SignalChoice,
    which: &[LogOption],
    log_options: LogOptions,
    observe: &mut Observer<'_>,
) -> Result<LogData, PipelineError> {
    let (paths, opts) = model_read(model, signals, which, log_options)?;
    load_log(file, &paths, Some(model.rate_hz()), &opts, observe)
}

/// [`read_at_model_rate`] split at the gaps longer than the largest allowed
/// ([`crate::load_log_pieces`]): every piece of at least 2 grid samples.
pub fn read_pieces_at_model_rate(
    model: &HysteresisModel,
    file: &Path,
    signals: &SignalChoice,
    which: &[LogOption],
    log_options: LogOptions,
    observe: &mut Observer<'_>,
) -> Result<crate::LogPieces, PipelineError> {
    let (paths, opts) = model_read(model, signals, which, log_options)?;
    crate::load_log_pieces(file, &paths, Some(model.rate_hz()), &opts, 2, observe)
}

/// The paths of `which` for `model` and the checked options, whose rate must be unset or the
/// model's: a model estimates only on its own grid.
fn model_read(
    model: &HysteresisModel,
    signals: &SignalChoice,
    which: &[LogOption],
    log_options: LogOptions,
) -> Result<(Vec<SignalPath>, crate::CheckedLogOptions), PipelineError> {
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
    Ok((paths, opts))
}

/// The filter over each piece of a log (`u` and `y` in columns `u_col` and `y_col`), restarted
/// at each piece, the estimates one after the other. Sensor values inside a dropout
/// ([`LogData::dropouts`]) are not fed to the filter (NaN: it predicts through them).
pub(crate) fn estimate_pieces(
    model: &HysteresisModel,
    pieces: &[LogData],
    u_col: usize,
    y_col: usize,
    mode: Mode,
) -> Result<Estimate, PipelineError> {
    over_pieces(pieces, u_col, y_col, |u, y| model.estimate(u, y, mode))
}

/// The smoother ([`HysteresisModel::smooth`]) over each piece of a log (`u` and `y` in columns
/// `u_col` and `y_col`), as [`estimate_log`] runs the filter: restarted at each piece, sensor
/// values inside a dropout left out, the estimates one after the other.
pub fn smooth_pieces(
    model: &HysteresisModel,
    pieces: &[LogData],
    u_col: usize,
    y_col: usize,
    mode: Mode,
) -> Result<Estimate, PipelineError> {
    over_pieces(pieces, u_col, y_col, |u, y| model.smooth(u, y, mode))
}

/// `run` on each piece's `u` and `y` (NaN inside a sensor dropout), the estimates joined.
fn over_pieces(
    pieces: &[LogData],
    u_col: usize,
    y_col: usize,
    run: impl Fn(&[f64], &[f64]) -> Result<Estimate, hbn_model::ModelError>,
) -> Result<Estimate, PipelineError> {
    let mut all = Estimate::default();
    for piece in pieces {
        let mut y = piece.column(y_col).to_vec();
        if let Some(mask) = piece.dropouts.get(y_col) {
            for (v, &dropped) in y.iter_mut().zip(mask) {
                if dropped {
                    *v = f64::NAN;
                }
            }
        }
        let e = run(piece.column(u_col), &y)?;
        for (to, from) in [
            (&mut all.x, e.x),
            (&mut all.x_std, e.x_std),
            (&mut all.y_pred, e.y_pred),
            (&mut all.innovation, e.innovation),
            (&mut all.nis, e.nis),
            (&mut all.q_x, e.q_x),
            (&mut all.r, e.r),
            (&mut all.obs_min, e.obs_min),
            (&mut all.obs_max, e.obs_max),
            (&mut all.obs_x, e.obs_x),
        ] {
            to.extend(from);
        }
        all.flags.extend(e.flags);
    }
    Ok(all)
}

/// The grid times of `joined` ([`join_pieces`]) where pieces after the first begin.
pub(crate) fn restart_times(pieces: &[LogData], joined: &LogData) -> Vec<f64> {
    let mut k = 0;
    let mut out = Vec::new();
    for (i, piece) in pieces.iter().enumerate() {
        if i > 0
            && let Some(&t) = joined.aligned.t_s.get(k)
        {
            out.push(t);
        }
        k += piece.len();
    }
    out
}

impl LogEstimate {
    /// The estimate as CSV text ([`CSV_HEADER`]), with the `u` and `y` it was computed from
    /// (`y` is `NaN` inside a sensor dropout, where the filter predicted without it).
    /// Numbers are written with Rust's `{}` (the shortest decimal that parses back to the same
    /// `f64`), so `u`, `y` fed from this file to an `f64` export reproduce `x` bit for bit.
    pub fn csv_text(&self) -> String {
        use std::fmt::Write as _;
        let est = &self.estimate;
        let mut s = String::with_capacity(100 * est.len() + 64);
        s.push_str(CSV_HEADER);
        s.push('\n');
        let mut names = String::new();
        // The y the filter read: NaN inside a sensor dropout ([`LogData::dropouts`]).
        let u = self.log.column(0);
        let mut y = self.log.column(1).to_vec();
        if let Some(mask) = self.log.dropouts.get(1) {
            for (v, &dropped) in y.iter_mut().zip(mask) {
                if dropped {
                    *v = f64::NAN;
                }
            }
        }
        let y = y.as_slice();
        for (k, t) in self.log.aligned.t_s.iter().enumerate() {
            let g = |v: &[f64]| v.get(k).copied().unwrap_or(f64::NAN);
            let flags = est.flags.get(k).copied().unwrap_or(0);
            names.clear();
            for (i, n) in Flags(flags).names().enumerate() {
                if i > 0 {
                    names.push('|');
                }
                names.push_str(n);
            }
            let _ = writeln!(
                s,
                "{t},{},{},{},{},{},{},{},{flags},{names}",
                g(u),
                g(y),
                g(&est.x),
                g(&est.x_std),
                g(&est.y_pred),
                g(&est.innovation),
                g(&est.nis),
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

#[cfg(test)]
mod tests {
    use super::*;

    /// An estimate of `n` samples whose flags are `flags(k)`, on a 100 Hz log with no signals.
    fn flagged(n: usize, flags: impl Fn(usize) -> u32) -> LogEstimate {
        LogEstimate {
            log: LogData {
                file: "log.mcap".into(),
                paths: Vec::new(),
                native_rates: Vec::new(),
                samples_in_grid: Vec::new(),
                samples_recorded: Vec::new(),
                dropouts: Vec::new(),
                sparse: Vec::new(),
                aligned: hbn_io::Aligned {
                    rate_hz: 100.0,
                    t0_ns: 0,
                    t_s: Vec::new(),
                    columns: Vec::new(),
                },
            },
            estimate: Estimate {
                x: vec![0.0; n],
                flags: (0..n).map(flags).collect(),
                ..Estimate::default()
            },
            mode: Mode::Ekf,
            trained_rates: Vec::new(),
            restarts: Vec::new(),
        }
    }

    /// A log recorded at the training logs' rates is not warned about, even where those differ
    /// from the model's grid; one recorded at other rates is, naming both.
    #[test]
    fn rates_are_compared_with_the_training_logs() {
        let mut e = flagged(10, |_| 0);
        e.log.paths = vec!["/valve.p".parse().unwrap(), "/strain.ohms".parse().unwrap()];
        e.log.aligned.rate_hz = 200.0;
        // The valve at the grid's 200 Hz, the strain sensor at 100 Hz, as in training.
        e.log.native_rates = vec![Some(200.0), Some(100.0)];
        e.trained_rates = vec![Some(200.0), Some(100.0)];
        assert!(e.warnings().is_empty(), "{:?}", e.warnings());
        // The strain sensor now at 50 Hz.
        e.log.native_rates = vec![Some(200.0), Some(50.0)];
        let w = e.warnings();
        assert_eq!(w.len(), 1, "{w:?}");
        let text = w[0].to_string();
        assert!(
            text.contains("/strain.ohms")
                && text.contains("50.0 Hz")
                && text.contains("100.0 Hz in the training logs"),
            "{text}"
        );
        // A model without recorded rates compares with its grid.
        e.trained_rates = vec![None, None];
        e.log.native_rates = vec![Some(200.0), Some(100.0)];
        assert_eq!(e.warnings().len(), 1);
    }

    /// One re-start of a lost filter is worth a warning; the share of outliers is, above
    /// OUTLIER_WARNING; routine flags are not.
    #[test]
    fn lost_filters_and_many_outliers_are_warned_about() {
        use hbn_core::Flags;
        assert!(
            flagged(100, |_| Flags::BLR_CAPPED | Flags::NOISE_FLOOR)
                .warnings()
                .is_empty()
        );
        let w = flagged(100, |k| if k == 40 { Flags::RELOCALISED } else { 0 }).warnings();
        assert_eq!(
            w,
            vec![EstimateWarning::Lost {
                times: 1,
                total: 100
            }]
        );
        assert!(
            w[0].to_string()
                .starts_with("the filter lost the state 1 time in 100 samples")
        );
        let gated = |share: usize| {
            flagged(100, move |k| {
                if k < share {
                    Flags::OUTLIER_REJECTED
                } else {
                    0
                }
            })
            .warnings()
        };
        assert!(gated(25).is_empty());
        let w = gated(26);
        assert_eq!(
            w,
            vec![EstimateWarning::Outliers {
                samples: 26,
                total: 100
            }]
        );
        assert!(
            w[0].to_string()
                .starts_with("26 of 100 measurements (26.0%)")
        );
    }

    #[test]
    fn files_for_a_mode_carry_its_name() {
        let m = Mode::EkfBlr;
        assert_eq!(
            file_for_mode(Path::new("out/est.csv"), m),
            Path::new("out/est-ekf-blr.csv")
        );
        assert_eq!(
            file_for_mode(Path::new("est.v1.mcap"), m),
            Path::new("est.v1-ekf-blr.mcap")
        );
        assert_eq!(file_for_mode(Path::new("est"), m), Path::new("est-ekf-blr"));
        let o = Outputs {
            csv: Some("a.csv".into()),
            mcap: None,
        };
        assert_eq!(o.for_mode(Mode::Ekf).csv, Some("a-ekf.csv".into()));
        assert_eq!(o.for_mode(Mode::Ekf).files().count(), 1);
        // Every mode gets its own files.
        let names: std::collections::BTreeSet<PathBuf> = Mode::ALL
            .iter()
            .filter_map(|&m| o.for_mode(m).csv)
            .collect();
        assert_eq!(names.len(), Mode::ALL.len());
    }
}
