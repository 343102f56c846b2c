//! Errors of the workflows, typed so front ends can match them and name what to change.

use std::path::PathBuf;

use hbn_io::IoError;
use hbn_model::{ConfigError, ModelError, Problem};

/// An option of reading logs ([`crate::LogOptions`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum LogOption {
    /// [`crate::LogOptions::rate_hz`].
    Rate,
    /// [`crate::LogOptions::max_gap_s`].
    MaxGap,
    /// [`crate::LogOptions::time_source`].
    TimeSource,
    /// The list of logs.
    Logs,
    /// The input signal path.
    Input,
    /// The state signal path.
    State,
    /// The output signal path.
    Output,
    /// The estimation mode.
    Mode,
    /// [`crate::LogOptions::min_coverage`].
    MinCoverage,
    /// [`crate::LogOptions::min_state_samples`].
    MinStateSamples,
}

impl LogOption {
    /// Every option.
    pub const ALL: [LogOption; 10] = [
        LogOption::Rate,
        LogOption::MaxGap,
        LogOption::TimeSource,
        LogOption::Logs,
        LogOption::Input,
        LogOption::State,
        LogOption::Output,
        LogOption::Mode,
        LogOption::MinCoverage,
        LogOption::MinStateSamples,
    ];

    /// The Rust name.
    pub const fn name(self) -> &'static str {
        match self {
            LogOption::Rate => "rate_hz",
            LogOption::MaxGap => "max_gap_s",
            LogOption::TimeSource => "time_source",
            LogOption::Logs => "logs",
            LogOption::Input => "input",
            LogOption::State => "state",
            LogOption::Output => "output",
            LogOption::Mode => "mode",
            LogOption::MinCoverage => "min_coverage",
            LogOption::MinStateSamples => "min_state_samples",
        }
    }
}

impl std::fmt::Display for LogOption {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

/// A workflow option that failed its check.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
#[error("invalid option `{option}`: {problem}")]
pub struct OptionError {
    /// The option to change.
    pub option: LogOption,
    /// What is wrong with its value.
    pub problem: Problem,
}

/// Everything that can go wrong in a workflow.
#[derive(Debug, thiserror::Error)]
pub enum PipelineError {
    /// A workflow option is invalid.
    #[error(transparent)]
    Option(#[from] OptionError),
    /// A training parameter is invalid.
    #[error(transparent)]
    Config(#[from] ConfigError),
    /// A log could not be read or its signals not aligned.
    #[error("cannot read signals from `{}`: {source}", file.display())]
    Read {
        /// The log.
        file: PathBuf,
        /// What went wrong.
        #[source]
        source: IoError,
    },
    /// The grid rate could not be taken from the log.
    #[error(
        "cannot determine the sample rate of `{path}` in `{}` (it has fewer than 2 samples at \
         distinct times); give the rate",
        file.display()
    )]
    UnknownRate {
        /// The log.
        file: PathBuf,
        /// The signal whose native rate was to be used.
        path: String,
    },
    /// A log with too few samples on the grid to train from.
    #[error(
        "`{}` has only {samples} aligned samples at {rate_hz:.1} Hz (at least {min} needed); \
         record a longer log",
        file.display()
    )]
    ShortLog {
        /// The log.
        file: PathBuf,
        /// Samples on the grid.
        samples: usize,
        /// The grid rate.
        rate_hz: f64,
        /// Samples needed.
        min: usize,
    },
    /// Too few samples of the state where all signals overlap, over all logs, to train on
    /// ([`crate::LogOptions::min_state_samples`]).
    #[error(
        "the state `{path}` has only {samples} samples where all signals overlap, in {logs} \
         log(s) (at least {min} needed to train): record the state for as long as the input \
         and the sensor, or lower the threshold (`--min-state-samples`, Python \
         `min_state_samples=`){}",
        shortest.as_ref().map_or_else(String::new, |(file, covered)| format!(
            "; in `{}` it has {covered}", file.display()
        ))
    )]
    TooFewStateSamples {
        /// The state's path.
        path: String,
        /// Its samples inside the grids, all logs together.
        samples: usize,
        /// Logs read.
        logs: usize,
        /// Samples needed.
        min: usize,
        /// The log where the state covers the least of the others' span, and how much (text).
        shortest: Option<(PathBuf, String)>,
    },
    /// A signal path (given, or stored in a model) that does not parse.
    #[error("the {option} signal path: {source}")]
    SignalPath {
        /// Which signal.
        option: LogOption,
        /// The text.
        text: String,
        /// The parse error (it names the text and the expected form).
        #[source]
        source: IoError,
    },
    /// Training, estimation or a model file failed.
    #[error(transparent)]
    Model(#[from] ModelError),
    /// No estimation mode was given.
    #[error("no estimation mode given; give at least one")]
    NoModes,
    /// Writing an output failed.
    #[error("cannot write `{}`: {source}", file.display())]
    Write {
        /// The output.
        file: PathBuf,
        /// What went wrong.
        #[source]
        source: IoError,
    },
    /// A simulation failed.
    #[error("simulation: {0}")]
    Sim(#[from] hbn_sim::SimError),
    /// An exploration parameter is invalid ([`hbn_model::explore::ExploreError`]; training
    /// errors arrive as [`PipelineError::Model`]).
    #[error(transparent)]
    Explore(hbn_model::explore::ExploreError),
}

impl PipelineError {
    /// The log option or training parameter to change, if the error is about one.
    pub fn setting(&self) -> Option<Setting> {
        match self {
            PipelineError::Option(e) => Some(Setting::Log(e.option)),
            PipelineError::Config(e) => Some(Setting::Param(e.param)),
            PipelineError::Model(ModelError::Config(e)) => Some(Setting::Param(e.param)),
            _ => None,
        }
    }
}

/// A setting a user changes: a log option or a training parameter.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Setting {
    /// A log option.
    Log(LogOption),
    /// A training parameter.
    Param(hbn_model::Param),
}
