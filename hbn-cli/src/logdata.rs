//! Reading signals from a log and aligning them on one grid: the one implementation shared by
//! `train`, `estimate` and `eval` (including the resampling notices).

use std::path::{Path, PathBuf};

use anyhow::{Context, anyhow};
use hbn_io::{Aligned, ReadOptions, ResampleOptions, SignalPath, TimeSource};

use crate::Ui;
use crate::cli::{ReadArgs, TimeSourceArg};

/// Relative rate difference above which resampling is announced.
pub const RATE_NOTICE_TOLERANCE: f64 = 0.01;

/// How to read logs.
#[derive(Clone, Copy, Debug)]
pub struct ReadSettings {
    /// Clock of the samples.
    pub time_source: TimeSource,
    /// Largest allowed gap (s).
    pub max_gap_s: f64,
}

impl From<&ReadArgs> for ReadSettings {
    fn from(a: &ReadArgs) -> Self {
        ReadSettings {
            time_source: match a.time_source {
                TimeSourceArg::Log => TimeSource::LogTime,
                TimeSourceArg::Header => TimeSource::HeaderStamp,
            },
            max_gap_s: a.max_gap,
        }
    }
}

/// Signals of one log on one uniform grid.
#[derive(Clone, Debug)]
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
    /// Column `i`.
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
}

/// Rounds a rate to 0.1 Hz.
pub fn round_rate(hz: f64) -> f64 {
    ((hz * 10.0).round() / 10.0).max(0.1)
}

/// Reads `paths` from `file` in one pass and resamples them to `rate_hz`, or (when `None`) to
/// the native rate of the first path rounded to 0.1 Hz (announced). Any signal whose native
/// rate differs from the grid rate by more than 1% is announced as resampled.
pub fn load(
    ui: &mut Ui<'_>,
    file: &Path,
    paths: &[SignalPath],
    rate_hz: Option<f64>,
    settings: &ReadSettings,
) -> anyhow::Result<LogData> {
    let opts = ReadOptions {
        time_source: settings.time_source,
        progress: !ui.quiet,
    };
    let raw = hbn_io::read_signals(file, paths, &opts).map_err(|e| {
        let hint = match (&e, settings.time_source) {
            (hbn_io::IoError::TimeBackwards { .. }, TimeSource::HeaderStamp) => {
                " (on the command line: --time-source log)"
            }
            _ => "",
        };
        anyhow::Error::new(e).context(format!(
            "cannot read signals from `{}`{hint}",
            file.display()
        ))
    })?;
    let native: Vec<Option<f64>> = raw.iter().map(hbn_io::native_rate_hz).collect();
    let rate = match rate_hz {
        Some(r) => r,
        None => {
            let first = paths
                .first()
                .ok_or_else(|| anyhow!("no signals requested from `{}`", file.display()))?;
            let r = native.first().copied().flatten().ok_or_else(|| {
                anyhow!(
                    "cannot determine the sample rate of `{first}` in `{}` (it has fewer than 2 \
                     samples at distinct times); pass --rate",
                    file.display()
                )
            })?;
            let r = round_rate(r);
            ui.notice(format!(
                "using {r:.1} Hz, the native rate of {first} in `{}` (set --rate to override)",
                file.display()
            ));
            r
        }
    };
    for (p, n) in paths.iter().zip(&native) {
        if let Some(n) = n
            && ((n - rate) / rate).abs() > RATE_NOTICE_TOLERANCE
        {
            ui.notice(format!(
                "resampling {p} from {n:.1} Hz to {rate:.1} Hz (`{}`)",
                file.display()
            ));
        }
    }
    let aligned = hbn_io::resample(
        &raw,
        &ResampleOptions {
            rate_hz: rate,
            max_gap_s: settings.max_gap_s,
        },
    )
    .with_context(|| {
        format!(
            "cannot align the signals of `{}` on a {rate:.1} Hz grid (options --max-gap, --rate)",
            file.display()
        )
    })?;
    Ok(LogData {
        file: file.to_owned(),
        paths: paths.to_vec(),
        native_rates: native,
        aligned,
    })
}

/// The model's stored path of a signal, or `default` when the model has none.
pub fn model_path(
    stored: Option<&str>,
    default: &str,
    model_file: &Path,
) -> anyhow::Result<SignalPath> {
    let text = stored.unwrap_or(default);
    text.parse::<SignalPath>().with_context(|| {
        format!(
            "model `{}` stores the signal path {text:?}, which does not parse; pass the path explicitly",
            model_file.display()
        )
    })
}
