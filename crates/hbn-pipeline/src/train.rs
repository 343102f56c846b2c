//! Logs to a trained model: the one implementation behind `hbn train` and Python's
//! `HysteresisModel.from_logs`, so the same logs and parameters give the same model file.

use std::path::PathBuf;

use hbn_io::SignalPath;
use hbn_model::{
    HbnParams, HysteresisModel, LatentRun, Problem, Sequence, StateFrame, observed_mask,
};

use crate::error::{LogOption, OptionError, PipelineError};
use crate::log::{Event, GridRate, LogData, LogOptions, Observer, load_log_pieces};

/// Default message path of the input `u` (what `hbn simulate` writes).
pub const DEFAULT_INPUT: &str = "/input.data";
/// Default message path of the state `x`.
pub const DEFAULT_STATE: &str = "/state.data";
/// Default message path of the sensor output `y`.
pub const DEFAULT_OUTPUT: &str = "/sensor.data";

/// Fewest grid samples a training log must have.
pub const MIN_LOG_SAMPLES: usize = 10;

/// Fewest grid samples a piece between two gaps of a log needs to be trained on (each piece is
/// a trajectory of its own, with its own held-out blocks: [`hbn_model::tuning::MIN_TUNING_SAMPLES`]
/// is the shortest block tuning scores). Shorter pieces are left out and counted.
pub const MIN_PIECE_SAMPLES: usize = hbn_model::tuning::MIN_TUNING_SAMPLES;

/// Where the three signals are in the logs (Foxglove message paths).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct TrainSignals {
    /// The input `u`.
    pub input: SignalPath,
    /// The state `x`.
    pub state: SignalPath,
    /// The sensor output `y`.
    pub output: SignalPath,
}

fn default_path(text: &str) -> SignalPath {
    // The defaults are plain `/topic.field` paths; a parse failure would be a bug caught by
    // the test below, and falls back to the topic alone.
    text.parse().unwrap_or_else(|_| SignalPath {
        topic: text.to_owned(),
        fields: Vec::new(),
    })
}

impl Default for TrainSignals {
    fn default() -> Self {
        Self {
            input: default_path(DEFAULT_INPUT),
            state: default_path(DEFAULT_STATE),
            output: default_path(DEFAULT_OUTPUT),
        }
    }
}

/// A model trained from logs, with the logs as read.
#[derive(Clone, Debug)]
pub struct Trained {
    /// The model (its rate is the logs' grid rate, its signals the paths read).
    pub model: HysteresisModel,
    /// The logs on their grid, one trajectory each.
    pub logs: Vec<LogData>,
}

impl Trained {
    /// Grid samples over all logs.
    pub fn samples(&self) -> usize {
        self.logs.iter().map(LogData::len).sum()
    }
}

/// Trains the HBN from MCAP logs, each log one trajectory.
///
/// Every option and parameter is checked before a file is opened. The grid rate is
/// `log_options.rate_hz`, or the native rate of the sensor output in the first log (rounded to
/// 0.1 Hz; [`GridRate`]: the filter updates once per measurement); every log is resampled to
/// it, and the model keeps it as its rate. The model's signals record the paths read.
pub fn train_from_logs(
    logs: &[PathBuf],
    signals: &TrainSignals,
    log_options: LogOptions,
    params: HbnParams,
    observe: &mut Observer<'_>,
) -> Result<Trained, PipelineError> {
    if logs.is_empty() {
        return Err(OptionError {
            option: LogOption::Logs,
            problem: Problem::TooSmall { value: 0, min: 1 },
        }
        .into());
    }
    let opts = log_options.check()?;
    let params = params.check()?;
    let paths = [
        signals.input.clone(),
        signals.state.clone(),
        signals.output.clone(),
    ];
    // Without a rate, the sensor's (position 2) sets the grid; later logs take the first's.
    let data = load_training_logs(logs, &paths, 1..2, &[2], &opts, observe)?;
    let rate = data.first().map(LogData::rate_hz).or(opts.rate_hz);
    // The state is what the model learns from: refuse to train on a sliver of it.
    let state_samples: usize = data
        .iter()
        .map(|d| d.samples_in_grid.get(1).copied().unwrap_or(0))
        .sum();
    if state_samples < opts.min_state_samples {
        let shortest = data
            .iter()
            .min_by_key(|d| d.samples_in_grid.get(1).copied().unwrap_or(0))
            .map(|d| {
                (
                    d.file.clone(),
                    format!(
                        "{} of its {} samples over the {:.2} s where all signals overlap",
                        d.samples_in_grid.get(1).copied().unwrap_or(0),
                        d.samples_recorded.get(1).copied().unwrap_or(0),
                        d.duration_s()
                    ),
                )
            });
        return Err(PipelineError::TooFewStateSamples {
            path: signals.state.to_string(),
            samples: state_samples,
            logs: data.len(),
            min: opts.min_state_samples,
            shortest,
        });
    }
    if let Some(log) = data.iter().find(|d| d.len() < MIN_LOG_SAMPLES) {
        return Err(PipelineError::ShortLog {
            file: log.file.clone(),
            samples: log.len(),
            rate_hz: log.rate_hz(),
            min: MIN_LOG_SAMPLES,
        });
    }
    observe(Event::LogsRead {
        logs: data.len(),
        samples: data.iter().map(LogData::len).sum(),
    });
    let mut described = params.signals.clone();
    for (i, (info, path)) in [
        (&mut described.input, &signals.input),
        (&mut described.state, &signals.state),
        (&mut described.output, &signals.output),
    ]
    .into_iter()
    .enumerate()
    {
        info.path = Some(path.to_string());
        info.native_rate_hz = data
            .first()
            .and_then(|d| d.native_rates.get(i).copied().flatten());
    }
    // How the logs were read, so that estimation reads its logs the same way by default.
    described.time_source = Some(opts.time_source.name().to_owned());
    described.max_gap_s = Some(opts.max_gap_s);
    let params = match rate {
        Some(r) => params.with_rate(r)?,
        None => params,
    }
    .with_signals(described);
    let mut on_training =
        |gp, progress: &hbn_gp::FitProgress| observe(Event::Training { gp, progress });
    let model = if data.iter().any(|d| state_frames(d, 1).is_some()) {
        // The state is latent between its measurements: expectation-maximisation.
        let measured: Vec<(Vec<StateFrame>, Option<Vec<bool>>)> = data
            .iter()
            .map(|d| {
                let frames = column_frames(d, 1);
                let mask = state_frames(d, 1)
                    .is_some()
                    .then(|| observed_mask(&frames, d.len()));
                (frames, mask)
            })
            .collect();
        let runs: Vec<LatentRun<'_>> = data
            .iter()
            .zip(&measured)
            .map(|(d, (frames, mask))| {
                let seq = Sequence::new(d.column(0), d.column(1), d.column(2));
                LatentRun {
                    seq: match mask {
                        Some(m) => seq.with_observed(m),
                        None => seq,
                    },
                    frames,
                }
            })
            .collect();
        HysteresisModel::fit_latent(&runs, &params, &mut on_training)?
    } else {
        let seqs: Vec<Sequence<'_>> = data
            .iter()
            .map(|d| Sequence::new(d.column(0), d.column(1), d.column(2)))
            .collect();
        HysteresisModel::fit_checked(&seqs, &params, &mut on_training)?
    };
    Ok(Trained { model, logs: data })
}

/// The training logs' pieces on one grid: `opts`' rate, or the slowest of the signals at
/// `sensors` (positions in `paths`) in the first log, which the later logs take. A log without
/// the topic of the state's signals (`paths[states]`: only `u` and `y` were recorded) joins
/// with its state latent throughout ([`LogData::with_unrecorded`], [`Event::NoState`]); when
/// no log has the state, the error is the first log's missing topic. A missing field of a
/// topic that is there stays an error (a typo).
pub(crate) fn load_training_logs(
    logs: &[PathBuf],
    paths: &[SignalPath],
    states: std::ops::Range<usize>,
    sensors: &[usize],
    opts: &crate::CheckedLogOptions,
    observe: &mut Observer<'_>,
) -> Result<Vec<LogData>, PipelineError> {
    let mut rate = opts.rate_hz;
    let mut data = Vec::with_capacity(logs.len());
    // The first log without the state's topic, reported if no log has it.
    let mut missing_state = None;
    let state_paths = paths.get(states.clone()).unwrap_or(&[]);
    // Without the state, the sensors sit `states.len()` positions earlier.
    let io_sensors: Vec<usize> = sensors
        .iter()
        .map(|&i| if i >= states.end { i - states.len() } else { i })
        .collect();
    for file in logs {
        let grid = rate.map_or(GridRate::SlowestOf(sensors), GridRate::Given);
        let split = match load_log_pieces(file, paths, grid, opts, MIN_PIECE_SAMPLES, observe) {
            Err(e) if state_paths.iter().any(|p| lacks_topic(&e, &p.topic)) => {
                missing_state.get_or_insert(e);
                // Once per topic: a vector state's components are fields of one topic.
                for (i, path) in state_paths.iter().enumerate() {
                    if !state_paths[..i].iter().any(|p| p.topic == path.topic) {
                        observe(Event::NoState { file, path });
                    }
                }
                let io_paths: Vec<SignalPath> = paths
                    .iter()
                    .enumerate()
                    .filter(|(i, _)| !states.contains(i))
                    .map(|(_, p)| p.clone())
                    .collect();
                let grid = rate.map_or(GridRate::SlowestOf(&io_sensors), GridRate::Given);
                let mut split =
                    load_log_pieces(file, &io_paths, grid, opts, MIN_PIECE_SAMPLES, observe)?;
                split.pieces = split
                    .pieces
                    .into_iter()
                    .map(|p| {
                        state_paths
                            .iter()
                            .zip(states.clone())
                            .fold(p, |p, (path, at)| p.with_unrecorded(at, path))
                    })
                    .collect();
                split
            }
            other => other?,
        };
        for piece in split.pieces {
            rate = Some(piece.rate_hz());
            data.push(piece);
        }
    }
    if let Some(e) = missing_state
        && data.iter().all(|d| {
            states
                .clone()
                .all(|c| d.samples_recorded.get(c).is_none_or(|&n| n == 0))
        })
    {
        return Err(e);
    }
    Ok(data)
}

/// Whether `e` is a log's lack of `topic`.
fn lacks_topic(e: &PipelineError, topic: &str) -> bool {
    matches!(e, PipelineError::Read {
        source: hbn_io::IoError::MissingTopic { topic: t, .. },
        ..
    } if t == topic)
}

/// The measurements of column `col` (a state) of a log whose state is measured sparsely
/// ([`LogData::sparse`]), as frames of the smoother; `None` when it is measured about as often
/// as the grid runs.
pub(crate) fn state_frames(log: &LogData, col: usize) -> Option<Vec<StateFrame>> {
    let samples = log.sparse.get(col)?.as_ref()?;
    Some(
        samples
            .iter()
            .map(|g| StateFrame {
                k: g.k,
                weight: g.weight,
                value: g.value,
            })
            .collect(),
    )
}

/// The frames of column `col` (a state): its measurements where it is measured sparsely
/// ([`state_frames`]), else every grid sample's value.
pub(crate) fn column_frames(log: &LogData, col: usize) -> Vec<StateFrame> {
    state_frames(log, col).unwrap_or_else(|| {
        log.column(col)
            .iter()
            .enumerate()
            .map(|(k, &value)| StateFrame {
                k,
                weight: 1.0,
                value,
            })
            .collect()
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn default_paths_parse() {
        for text in [DEFAULT_INPUT, DEFAULT_STATE, DEFAULT_OUTPUT] {
            let p: SignalPath = text.parse().unwrap();
            assert_eq!(p.to_string(), text);
        }
        assert_eq!(TrainSignals::default().state.to_string(), DEFAULT_STATE);
    }
}
