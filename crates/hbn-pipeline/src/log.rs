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
    /// Grid rate (Hz); `None`: in training, the slowest native rate of the sensor outputs in
    /// the first log, rounded to 0.1 Hz (the filter updates once per measurement; see
    /// [`GridRate`]); in estimation, the model's rate.
    pub rate_hz: Option<f64>,
    /// A signal whose samples span less than this fraction of the log's span (from the first
    /// sample of any signal to the last) is reported ([`Event::PartialCoverage`]): the grid
    /// covers only the span all signals share, so such a signal leaves most of the log unused.
    pub min_coverage: f64,
    /// Training only: the fewest samples of the state signal, over all logs, where all signals
    /// overlap (the state is what the model learns from). Fewer is
    /// [`PipelineError::TooFewStateSamples`].
    pub min_state_samples: usize,
}

/// An interval between two samples of a signal longer than this many times its median
/// interval is a dropout ([`LogData::dropouts`]): one missing sample (twice the interval) is
/// interpolated over as measured, two or more are not.
pub const DROPOUT_FACTOR: f64 = 2.5;

/// Default [`LogOptions::min_coverage`]: a signal that spans less than half of its log.
pub const DEFAULT_MIN_COVERAGE: f64 = 0.5;

/// Default [`LogOptions::min_state_samples`]. It refuses what cannot be a model (a camera that
/// stopped after a few frames) and leaves small experiments possible. Filter tuning needs more:
/// each held-out block needs [`hbn_model::tuning::MIN_TUNING_SAMPLES`] samples, so with the
/// default `validation = 0.25` a model trained on fewer than 200 samples keeps untuned noise
/// scales, and the training summary says so.
pub const DEFAULT_MIN_STATE_SAMPLES: usize = 100;

impl Default for LogOptions {
    fn default() -> Self {
        Self {
            time_source: TimeSource::LogTime,
            max_gap_s: ResampleOptions::DEFAULT_MAX_GAP_S,
            rate_hz: None,
            min_coverage: DEFAULT_MIN_COVERAGE,
            min_state_samples: DEFAULT_MIN_STATE_SAMPLES,
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
        if !(0.0..=1.0).contains(&self.min_coverage) {
            return Err(OptionError {
                option: LogOption::MinCoverage,
                problem: Problem::Between {
                    value: self.min_coverage,
                    min: 0.0,
                    max: 1.0,
                },
            });
        }
        if let Some(r) = self.rate_hz {
            positive(LogOption::Rate, r)?;
        }
        Ok(CheckedLogOptions(self))
    }
}

/// The log options to read a log for `model`: `time_source` and `max_gap_s` where given, else
/// those the model was trained with (else the defaults), at the model's rate.
pub fn model_log_options(
    model: &hbn_model::HysteresisModel,
    time_source: Option<TimeSource>,
    max_gap_s: Option<f64>,
) -> LogOptions {
    let d = LogOptions::default();
    let s = model.signals();
    LogOptions {
        time_source: time_source
            .or_else(|| s.time_source.as_deref().and_then(|t| t.parse().ok()))
            .unwrap_or(d.time_source),
        max_gap_s: max_gap_s.or(s.max_gap_s).unwrap_or(d.max_gap_s),
        ..d
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
    /// No rate was given: the grid uses the native rate of a signal, the slowest of those that
    /// may set it ([`GridRate::SlowestOf`]; in training, the sensor outputs).
    NativeRate {
        /// The log.
        file: &'a Path,
        /// The signal the rate came from.
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
    /// A signal spans less than [`LogOptions::min_coverage`] of its log: the grid, which
    /// covers only the span all signals share, leaves the rest of the log unused.
    PartialCoverage {
        /// The log.
        file: &'a Path,
        /// The signal.
        path: &'a SignalPath,
        /// How long the signal's samples span (s).
        covered_s: f64,
        /// How long the log's samples span, all signals together (s).
        log_s: f64,
    },
    /// A log was split at gaps longer than [`LogOptions::max_gap_s`] ([`load_log_pieces`]).
    Split {
        /// The log.
        file: &'a Path,
        /// The gaps.
        gaps: &'a [hbn_io::SignalGap],
        /// Where the signals' common span starts (ns): the gaps' times are given from there.
        overlap_start_ns: u64,
        /// Pieces kept.
        pieces: usize,
        /// Pieces left out (too short).
        dropped: usize,
        /// The largest gap allowed (s).
        max_gap_s: f64,
    },
    /// A training log has no topic of the state's path: it joins training with its state
    /// latent, from `u` and `y` alone ([`hbn_model::HysteresisModel::fit_latent`]).
    NoState {
        /// The log.
        file: &'a Path,
        /// The state's path.
        path: &'a SignalPath,
    },
    /// Every log was read and passed its checks; training starts.
    LogsRead {
        /// Trajectories (logs) to train on.
        logs: usize,
        /// Grid samples over all of them.
        samples: usize,
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

/// The rate of a log's grid: given, or the native rate of one of the signals read.
///
/// Training reads the input, the state and the sensor outputs and, without a given rate, runs
/// the grid at the slowest sensor's native rate ([`GridRate::SlowestOf`] the outputs'
/// positions): the filter then updates once per measurement, on measured values. A faster grid
/// feeds the filter interpolated sensor values as if they were measurements of their own; the
/// input's rate and the state's (a camera, latent between its frames) do not set the grid.
/// `Option<f64>` converts: `Some(rate)` is [`GridRate::Given`], `None` the first signal's
/// native rate.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum GridRate<'a> {
    /// This rate (Hz).
    Given(f64),
    /// The slowest native rate, rounded to 0.1 Hz, of the signals at these positions of the
    /// paths read (positions past the paths, and signals without a native rate, are skipped),
    /// reported as [`Event::NativeRate`] naming the signal. None of them with a native rate is
    /// [`PipelineError::UnknownRate`], naming the first.
    SlowestOf(&'a [usize]),
}

impl From<Option<f64>> for GridRate<'_> {
    fn from(rate: Option<f64>) -> Self {
        match rate {
            Some(r) => GridRate::Given(r),
            None => GridRate::SlowestOf(&[0]),
        }
    }
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
    /// Samples of each signal (as recorded, before resampling) where all signals overlap,
    /// which is the span the grid covers.
    pub samples_in_grid: Vec<usize>,
    /// Samples of each signal in the log, as recorded.
    pub samples_recorded: Vec<usize>,
    /// Per signal, the grid points inside a dropout of it (more than [`DROPOUT_FACTOR`] times
    /// its median interval without a sample, but no longer than the largest gap allowed): there
    /// its value is interpolated, not measured. Estimation does not feed such sensor values to
    /// the filter, which predicts through the dropout.
    pub dropouts: Vec<Vec<bool>>,
    /// Per signal measured at fewer than [`SPARSE_BELOW`] of the grid's points (a camera
    /// slower than the grid, or dropping many frames), its samples as recorded, placed on the
    /// grid ([`hbn_io::GridSample`]); `None` for a signal measured about as often as the grid
    /// runs. Training treats such a state as latent between its samples
    /// ([`hbn_model::HysteresisModel::fit_latent`]).
    pub sparse: Vec<Option<Vec<hbn_io::GridSample>>>,
    /// The aligned samples.
    pub aligned: Aligned,
}

impl LogData {
    /// The frames of the state (column 1) when it is measured sparsely
    /// ([`LogData::sparse`]: a camera slower than the grid, or dropping many frames); `None`
    /// when it is measured at about every grid sample.
    pub fn state_frames(&self) -> Option<&[hbn_io::GridSample]> {
        self.frames_of(1)
    }

    /// The samples of signal `col` as recorded, when it is measured sparsely
    /// ([`LogData::sparse`]); `None` when it is measured at about every grid sample. A vector
    /// state's components are its columns after the inputs.
    pub fn frames_of(&self, col: usize) -> Option<&[hbn_io::GridSample]> {
        self.sparse
            .get(col)?
            .as_deref()
            .filter(|frames| !frames.is_empty())
    }

    /// This log with a signal that was not recorded inserted at position `at` of its
    /// signals: NaN on the grid, no samples (sparse, with none; [`LogData::sparse`]), no
    /// native rate. A training log without the state's topic becomes a run whose state is
    /// latent throughout.
    pub fn with_unrecorded(mut self, at: usize, path: &SignalPath) -> Self {
        let n = self.len();
        let at = at.min(self.paths.len());
        self.paths.insert(at, path.clone());
        self.native_rates.insert(at, None);
        self.samples_in_grid.insert(at, 0);
        self.samples_recorded.insert(at, 0);
        self.dropouts.insert(at, vec![false; n]);
        self.sparse.insert(at, Some(Vec::new()));
        self.aligned
            .columns
            .insert(at.min(self.aligned.columns.len()), vec![f64::NAN; n]);
        self
    }

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

/// Reads `paths` from `file` in one pass and resamples them to the grid rate `rate`: given, or
/// a signal's native rate rounded to 0.1 Hz ([`GridRate`]; `None` is the first path's),
/// reported as [`Event::NativeRate`]. A signal whose native rate differs from the grid's by
/// more than 1% is reported as [`Event::Resampling`]. A gap longer than
/// [`LogOptions::max_gap_s`] is an error ([`load_log_pieces`] splits the log there instead).
pub fn load_log<'r>(
    file: &Path,
    paths: &[SignalPath],
    rate: impl Into<GridRate<'r>>,
    opts: &CheckedLogOptions,
    observe: &mut Observer<'_>,
) -> Result<LogData, PipelineError> {
    let RawLog {
        signals: raw,
        native,
        rate_hz: rate,
    } = read_raw(file, paths, rate.into(), opts, observe)?;
    align(file, paths, &raw, native, rate, opts)
}

/// A log split at its gaps ([`load_log_pieces`]).
#[derive(Clone, Debug, PartialEq)]
pub struct LogPieces {
    /// The pieces long enough to use, in time order, each on its own grid.
    pub pieces: Vec<LogData>,
    /// The gaps longer than [`LogOptions::max_gap_s`] the log was split at.
    pub gaps: Vec<hbn_io::SignalGap>,
    /// Pieces left out: shorter than asked for.
    pub dropped: usize,
}

/// [`load_log`] that splits the log where a signal has a gap longer than
/// [`LogOptions::max_gap_s`], instead of failing: each piece between such gaps gets its own
/// grid (an own trajectory for training, a restart of the filter for estimation). Pieces
/// between gaps with fewer than `min_samples` grid samples are left out and counted (a log
/// without such gaps is one piece, however short). A split is reported as
/// [`Event::Split`]. A log whose pieces are all too short is the gap's error.
pub fn load_log_pieces<'r>(
    file: &Path,
    paths: &[SignalPath],
    rate: impl Into<GridRate<'r>>,
    opts: &CheckedLogOptions,
    min_samples: usize,
    observe: &mut Observer<'_>,
) -> Result<LogPieces, PipelineError> {
    let RawLog {
        signals: raw,
        native,
        rate_hz: rate,
    } = read_raw(file, paths, rate.into(), opts, observe)?;
    let (windows, gaps) = hbn_io::split_at_gaps(&raw, opts.max_gap_s);
    if gaps.is_empty() {
        return Ok(LogPieces {
            pieces: vec![align(file, paths, &raw, native, rate, opts)?],
            gaps,
            dropped: 0,
        });
    }
    let mut pieces = Vec::new();
    let mut dropped = 0;
    for (start, end) in windows {
        let sliced: Vec<hbn_io::RawSignal> =
            raw.iter().map(|s| hbn_io::window(s, start, end)).collect();
        match align(file, paths, &sliced, native.clone(), rate, opts) {
            Ok(piece) if piece.len() >= min_samples.max(2) => pieces.push(piece),
            _ => dropped += 1,
        }
    }
    if pieces.is_empty() {
        // Nothing usable between the gaps: the first gap is the error.
        align(file, paths, &raw, native, rate, opts)?;
    }
    let overlap_start = raw
        .iter()
        .filter_map(|s| s.t_ns.first().copied())
        .max()
        .unwrap_or(0);
    observe(Event::Split {
        file,
        gaps: &gaps,
        overlap_start_ns: overlap_start,
        pieces: pieces.len(),
        dropped,
        max_gap_s: opts.max_gap_s,
    });
    Ok(LogPieces {
        pieces,
        gaps,
        dropped,
    })
}

/// A log's signals as recorded, before they are put on a grid.
struct RawLog {
    /// The signals, in the order of the paths.
    signals: Vec<hbn_io::RawSignal>,
    /// Each signal's native rate (Hz), if it has one.
    native: Vec<Option<f64>>,
    /// The grid rate (Hz): given, or a signal's native rate ([`GridRate`]).
    rate_hz: f64,
}

/// The raw signals, their native rates and the grid rate (reporting coverage and rates).
fn read_raw(
    file: &Path,
    paths: &[SignalPath],
    rate: GridRate<'_>,
    opts: &CheckedLogOptions,
    observe: &mut Observer<'_>,
) -> Result<RawLog, PipelineError> {
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
    // The log's span, all signals together, and the share of it each signal spans.
    let first = raw.iter().filter_map(|s| s.t_ns.first().copied()).min();
    let last = raw.iter().filter_map(|s| s.t_ns.last().copied()).max();
    if let (Some(first), Some(last)) = (first, last)
        && last > first
    {
        let log_s = (last - first) as f64 * 1e-9;
        for (path, signal) in paths.iter().zip(&raw) {
            let covered_s = match (signal.t_ns.first(), signal.t_ns.last()) {
                (Some(a), Some(b)) => b.saturating_sub(*a) as f64 * 1e-9,
                _ => 0.0,
            };
            if covered_s < opts.min_coverage * log_s {
                observe(Event::PartialCoverage {
                    file,
                    path,
                    covered_s,
                    log_s,
                });
            }
        }
    }
    let rate = match rate {
        GridRate::Given(r) => r,
        GridRate::SlowestOf(which) => {
            let Some((path, r)) = slowest(paths, &native, which) else {
                return Err(PipelineError::UnknownRate {
                    file: file.to_owned(),
                    path: which
                        .iter()
                        .chain(&[0])
                        .find_map(|&i| paths.get(i))
                        .map(|p| p.to_string())
                        .unwrap_or_default(),
                });
            };
            let r = round_rate(r);
            observe(Event::NativeRate {
                file,
                path,
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
    Ok(RawLog {
        signals: raw,
        native,
        rate_hz: rate,
    })
}

/// The signal with the slowest native rate among those at positions `which` of `paths` that
/// have one, and its rate; the first of equal ones.
fn slowest<'p>(
    paths: &'p [SignalPath],
    native: &[Option<f64>],
    which: &[usize],
) -> Option<(&'p SignalPath, f64)> {
    which
        .iter()
        .filter_map(|&i| Some((paths.get(i)?, (*native.get(i)?)?)))
        .fold(None, |best, (p, r)| match best {
            Some((_, b)) if b <= r => best,
            _ => Some((p, r)),
        })
}

/// `raw` on one grid at `rate`.
fn align(
    file: &Path,
    paths: &[SignalPath],
    raw: &[hbn_io::RawSignal],
    native: Vec<Option<f64>>,
    rate: f64,
    opts: &CheckedLogOptions,
) -> Result<LogData, PipelineError> {
    let aligned = hbn_io::resample(
        raw,
        &ResampleOptions {
            rate_hz: rate,
            max_gap_s: opts.max_gap_s,
        },
    )
    .map_err(|source| PipelineError::Read {
        file: file.to_owned(),
        source,
    })?;
    // The overlap of all signals' spans, where the grid lies.
    let overlap_start = raw
        .iter()
        .filter_map(|s| s.t_ns.first().copied())
        .max()
        .unwrap_or(0);
    let overlap_end = raw
        .iter()
        .filter_map(|s| s.t_ns.last().copied())
        .min()
        .unwrap_or(0);
    let samples_in_grid = raw
        .iter()
        .map(|s| {
            s.t_ns
                .iter()
                .filter(|&&t| (overlap_start..=overlap_end).contains(&t))
                .count()
        })
        .collect();
    let samples_recorded = raw.iter().map(|s| s.t_ns.len()).collect();
    let dropouts = raw
        .iter()
        .map(|s| hbn_io::dropouts_on_grid(s, &aligned, DROPOUT_FACTOR))
        .collect();
    let sparse = raw
        .iter()
        .map(|s| {
            let on_grid = hbn_io::samples_on_grid(s, &aligned);
            ((on_grid.len() as f64) < SPARSE_BELOW * aligned.t_s.len() as f64).then_some(on_grid)
        })
        .collect();
    Ok(LogData {
        file: file.to_owned(),
        paths: paths.to_vec(),
        native_rates: native,
        samples_in_grid,
        samples_recorded,
        dropouts,
        sparse,
        aligned,
    })
}

/// A signal with samples at fewer than this fraction of the grid's points is measured sparsely
/// ([`LogData::sparse`]): a camera at 30 Hz on a 100 Hz grid has 0.3, one at the grid's rate
/// that drops a tenth of its frames 0.9 (its gaps are a sample or two, and interpolating over
/// them is harmless).
pub const SPARSE_BELOW: f64 = 0.8;

/// Pieces of one log as one [`LogData`]: columns and grid times one after the other, the grid
/// times (seconds since the first piece's start) jumping over the gaps. `None` without pieces.
pub fn join_pieces(pieces: &[LogData]) -> Option<LogData> {
    let first = pieces.first()?;
    let mut joined = first.clone();
    for piece in pieces.iter().skip(1) {
        let offset_k = joined.len();
        for (mine, theirs) in joined.sparse.iter_mut().zip(&piece.sparse) {
            match (mine.as_mut(), theirs) {
                (Some(m), Some(t)) => m.extend(t.iter().map(|g| hbn_io::GridSample {
                    k: g.k + offset_k,
                    ..*g
                })),
                // Sparse in one piece only: interpolated where it is not.
                _ => *mine = None,
            }
        }
        let offset_s = piece.aligned.t0_ns.saturating_sub(first.aligned.t0_ns) as f64 * 1e-9;
        joined
            .aligned
            .t_s
            .extend(piece.aligned.t_s.iter().map(|t| t + offset_s));
        for (c, more) in joined
            .aligned
            .columns
            .iter_mut()
            .zip(&piece.aligned.columns)
        {
            c.extend_from_slice(more);
        }
        for (n, more) in joined
            .samples_in_grid
            .iter_mut()
            .zip(&piece.samples_in_grid)
        {
            *n += more;
        }
    }
    Some(joined)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn paths(names: &[&str]) -> Vec<SignalPath> {
        names.iter().map(|n| n.parse().unwrap()).collect()
    }

    #[test]
    fn the_slowest_of_the_signals_named_sets_the_rate() {
        let p = paths(&[
            "/input.data",
            "/state.data",
            "/sensor.data",
            "/sensor2.data",
        ]);
        let native = [Some(200.0), Some(30.0), Some(100.0), Some(50.0)];
        // The state is the slowest signal, but only the positions given count.
        let (path, rate) = slowest(&p, &native, &[2]).unwrap();
        assert_eq!((path.to_string().as_str(), rate), ("/sensor.data", 100.0));
        let (path, rate) = slowest(&p, &native, &[2, 3]).unwrap();
        assert_eq!((path.to_string().as_str(), rate), ("/sensor2.data", 50.0));
        let (path, _) = slowest(&p, &native, &[0, 2]).unwrap();
        assert_eq!(path.to_string(), "/sensor.data");
        // Equal rates: the first named.
        let same = [Some(100.0); 4];
        let (path, _) = slowest(&p, &same, &[3, 2]).unwrap();
        assert_eq!(path.to_string(), "/sensor2.data");
    }

    #[test]
    fn signals_without_a_rate_and_positions_past_the_paths_are_skipped() {
        let p = paths(&["/input.data", "/state.data", "/sensor.data"]);
        let native = [Some(200.0), Some(30.0), None];
        assert_eq!(slowest(&p, &native, &[2]), None);
        assert_eq!(slowest(&p, &native, &[5]), None);
        assert_eq!(slowest(&p, &native, &[]), None);
        let (path, rate) = slowest(&p, &native, &[2, 0, 7]).unwrap();
        assert_eq!((path.to_string().as_str(), rate), ("/input.data", 200.0));
    }

    #[test]
    fn an_optional_rate_is_given_or_the_first_signals() {
        assert_eq!(GridRate::from(Some(50.0)), GridRate::Given(50.0));
        assert_eq!(GridRate::from(None), GridRate::SlowestOf(&[0]));
    }
}
