//! From MCAP bytes to signals on one grid: reading the signals a model needs by Foxglove path,
//! choosing the rate, resampling and checking gaps. The one implementation behind `hbn train`,
//! `hbn estimate`, `hbn eval` and Python's `read_mcap` / `HysteresisModel.from_logs`.

use std::path::{Path, PathBuf};

use hbn_io::{Aligned, ReadOptions, ReadProgress, ResampleOptions, SignalPath, TimeSource};

use crate::error::{LogOption, OptionError, PipelineError};
use hbn_model::Problem;

/// How logs are read and put on one grid. [`LogOptions::default`] holds the defaults every
/// front end shows.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LogOptions {
    /// Clock the samples are placed at.
    pub time_source: TimeSource,
    /// Largest allowed gap between two samples of a signal inside the grid's span (s).
    pub max_gap_s: f64,
    /// Grid rate (Hz); `None`: the native rate of the first signal of the first log, rounded to
    /// 0.1 Hz (training), or the model's rate (estimation).
    pub rate_hz: Option<f64>,
}

impl Default for LogOptions {
    fn default() -> Self {
        Self {
            time_source: TimeSource::LogTime,
            max_gap_s: ResampleOptions::DEFAULT_MAX_GAP_S,
            rate_hz: None,
        }
    }
}

/// [`LogOptions`] that passed [`LogOptions::check`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CheckedLogOptions(LogOptions);

impl std::ops::Deref for CheckedLogOptions {
    type Target = LogOptions;
    fn deref(&self) -> &LogOptions {
        &self.0
    }
}

impl LogOptions {
    /// Checks every option once, before any file is opened; errors name the [`LogOption`].
    pub fn check(self) -> Result<CheckedLogOptions, OptionError> {
        let positive = |option, value: f64| {
            if value.is_finite() && value > 0.0 {
                Ok(())
            } else {
                Err(OptionError {
                    option,
                    problem: Problem::NotPositive { value },
                })
            }
        };
        positive(LogOption::MaxGap, self.max_gap_s)?;
        if let Some(r) = self.rate_hz {
            positive(LogOption::Rate, r)?;
        }
        Ok(CheckedLogOptions(self))
    }
}

/// Parses a time source name (`log`, `header`), naming the option in the error.
pub fn parse_time_source(text: &str) -> Result<TimeSource, OptionError> {
    text.parse().map_err(|_| OptionError {
        option: LogOption::TimeSource,
        problem: Problem::Unknown {
            given: text.to_owned(),
            choices: "log, header",
        },
    })
}

/// Parses a signal path, naming which signal in the error.
pub fn parse_signal(option: LogOption, text: &str) -> Result<SignalPath, PipelineError> {
    text.parse().map_err(|source| PipelineError::SignalPath {
        option,
        text: text.to_owned(),
        source,
    })
}

/// What a workflow reports while it runs; front ends render it (the CLI as notices and
/// progress bars) or ignore it.
#[derive(Clone, Copy, Debug)]
pub enum Event<'a> {
    /// Bytes of a log read so far.
    Reading {
        /// The log.
        file: &'a Path,
        /// How far.
        progress: ReadProgress,
    },
    /// No rate was given: the grid uses the native rate of a signal.
    NativeRate {
        /// The log.
        file: &'a Path,
        /// The signal.
        path: &'a SignalPath,
        /// The rate chosen (rounded to 0.1 Hz).
        rate_hz: f64,
    },
    /// A signal's native rate differs from the grid's by more than
    /// [`RATE_NOTICE_TOLERANCE`]: it is interpolated.
    Resampling {
        /// The log.
        file: &'a Path,
        /// The signal.
        path: &'a SignalPath,
        /// Its native rate.
        native_hz: f64,
        /// The grid rate.
        rate_hz: f64,
    },
    /// An optimiser start of one GP finished.
    Training {
        /// Which GP.
        gp: hbn_model::GpRole,
        /// The start's report.
        progress: &'a hbn_gp::FitProgress,
    },
    /// A case of the simulation experiment finished.
    ExperimentCase {
        /// Its scores.
        row: &'a crate::experiment::ExperimentRow,
        /// Cases done.
        done: usize,
        /// Cases in all.
        total: usize,
    },
}

/// A sink for [`Event`]s.
pub type Observer<'o> = dyn FnMut(Event<'_>) + 'o;

/// Relative rate difference above which resampling is reported.
pub const RATE_NOTICE_TOLERANCE: f64 = 0.01;

/// Rounds a rate to 0.1 Hz (at least 0.1 Hz).
pub fn round_rate(hz: f64) -> f64 {
    ((hz * 10.0).round() / 10.0).max(0.1)
}

/// Signals of one log on one uniform grid.
#[derive(Clone, Debug, PartialEq)]
pub struct LogData {
    /// The log.
    pub file: PathBuf,
    /// The paths, in the order of `aligned.columns`.
    pub paths: Vec<SignalPath>,
    /// Native rate of each signal (median interval), if it has one.
    pub native_rates: Vec<Option<f64>>,
    /// The aligned samples.
    pub aligned: Aligned,
}

impl LogData {
    /// Column `i` (empty if there is none).
    pub fn column(&self, i: usize) -> &[f64] {
        self.aligned.columns.get(i).map_or(&[], |c| c.as_slice())
    }
    /// Number of grid samples.
    pub fn len(&self) -> usize {
        self.aligned.t_s.len()
    }
    /// Whether the grid is empty.
    pub fn is_empty(&self) -> bool {
        self.aligned.t_s.is_empty()
    }
    /// The grid rate (Hz).
    pub fn rate_hz(&self) -> f64 {
        self.aligned.rate_hz
    }
    /// The length of the grid, samples / rate (s): 1000 samples at 100 Hz last 10 s, as
    /// `hbn simulate` says of the log it writes.
    pub fn duration_s(&self) -> f64 {
        if self.rate_hz() > 0.0 {
            self.len() as f64 / self.rate_hz()
        } else {
            0.0
        }
    }
    /// Absolute grid times on the log's clock (ns): where estimates are written.
    pub fn times_ns(&self) -> Vec<u64> {
        let a = &self.aligned;
        a.t_s
            .iter()
            .map(|t| a.t0_ns.saturating_add((t * 1e9).round() as u64))
            .collect()
    }
}

/// Reads `paths` from `file` in one pass and resamples them to `rate_hz`, or (when `None`) to
/// the native rate of the first path rounded to 0.1 Hz (reported as [`Event::NativeRate`]). A
/// signal whose native rate differs from the grid's by more than 1% is reported as
/// [`Event::Resampling`].
pub fn load_log(
    file: &Path,
    paths: &[SignalPath],
    rate_hz: Option<f64>,
    opts: &CheckedLogOptions,
    observe: &mut Observer<'_>,
) -> Result<LogData, PipelineError> {
    let read_err = |source| PipelineError::Read {
        file: file.to_owned(),
        source,
    };
    let raw = hbn_io::read_signals_observed(
        file,
        paths,
        &ReadOptions {
            time_source: opts.time_source,
        },
        &mut |progress| observe(Event::Reading { file, progress }),
    )
    .map_err(read_err)?;
    let native: Vec<Option<f64>> = raw.iter().map(hbn_io::native_rate_hz).collect();
    let rate = match rate_hz {
        Some(r) => r,
        None => {
            let (Some(first), Some(Some(r))) = (paths.first(), native.first()) else {
                return Err(PipelineError::UnknownRate {
                    file: file.to_owned(),
                    path: paths.first().map(|p| p.to_string()).unwrap_or_default(),
                });
            };
            let r = round_rate(*r);
            observe(Event::NativeRate {
                file,
                path: first,
                rate_hz: r,
            });
            r
        }
    };
    for (path, n) in paths.iter().zip(&native) {
        if let Some(n) = *n
            && ((n - rate) / rate).abs() > RATE_NOTICE_TOLERANCE
        {
            observe(Event::Resampling {
                file,
                path,
                native_hz: n,
                rate_hz: rate,
            });
        }
    }
    let aligned = hbn_io::resample(
        &raw,
        &ResampleOptions {
            rate_hz: rate,
            max_gap_s: opts.max_gap_s,
        },
    )
    .map_err(read_err)?;
    Ok(LogData {
        file: file.to_owned(),
        paths: paths.to_vec(),
        native_rates: native,
        aligned,
    })
}
