//! Scoring a model on a log that also records the state: every EKF mode and the open-loop GP
//! simulation against the logged reference (what `hbn eval` prints and plots).

use std::path::Path;

use hbn_core::Mode;
use hbn_model::metrics::{Calibration, calibration, nrmse, rmse};
use hbn_model::{Estimate, HysteresisModel};
use serde_json::{Map, Value, json};

use crate::error::{LogOption, PipelineError};
use crate::estimate::{SignalChoice, estimate_pieces, read_pieces_at_model_rate};
use crate::log::join_pieces;
use crate::log::{LogData, LogOptions, Observer};

/// A method scored by [`evaluate_log`].
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Method {
    /// A filter mode.
    Filter(Mode),
    /// Open-loop GP simulation from `u` alone.
    OpenLoop,
}

impl Method {
    /// `ekf`, `ekf_blr`, `ukf` or `open_loop` (keys of the JSON result).
    pub const fn key(self) -> &'static str {
        match self {
            Method::Filter(Mode::Ekf) => "ekf",
            Method::Filter(Mode::EkfBlr) => "ekf_blr",
            Method::Filter(Mode::Ukf) => "ukf",
            Method::OpenLoop => "open_loop",
        }
    }
}

impl Method {
    /// The name a user reads in tables and flags: `ekf`, `ekf-blr`, `ukf` (the mode names) or
    /// `open-loop`.
    pub const fn name(self) -> &'static str {
        match self {
            Method::Filter(m) => m.name(),
            Method::OpenLoop => "open-loop",
        }
    }
}

/// Scores of one method.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Score {
    /// The method.
    pub method: Method,
    /// RMSE against the logged state.
    pub rmse: f64,
    /// RMSE / range of the logged state.
    pub nrmse: f64,
    /// Calibration of the estimate's standard deviation (`None` for the open loop, which has
    /// none).
    pub calibration: Option<Calibration>,
}

/// An evaluation: the log on the model's grid, the estimates and the scores.
#[derive(Clone, Debug)]
pub struct Evaluation {
    /// `u`, `x` (reference) and `y`, columns 0, 1, 2.
    pub log: LogData,
    /// One estimate per mode evaluated, in order.
    pub estimates: Vec<(Mode, Estimate)>,
    /// The open-loop simulation.
    pub open_loop: Vec<f64>,
    /// One score per mode, then the open loop.
    pub scores: Vec<Score>,
}

impl Evaluation {
    /// JSON: `{"rmse": {..}, "nrmse": {..}, "calibration": {method: {coverage_1sigma,
    /// coverage_2sigma, mean_nees, nlpd, samples}}, "samples": N, "rate_hz": ..,
    /// "duration_s": .., "signals": [paths], "state_frames": F}` (the samples are the span
    /// where every signal read has data; `state_frames` is the number of the state's frames
    /// scored where it is measured sparsely, `null` where every sample is).
    pub fn to_json(&self) -> Value {
        let mut v = scores_json(&self.scores);
        let signals: Vec<String> = self.log.paths.iter().map(|p| p.to_string()).collect();
        let frames = self.log.state_frames().map(<[_]>::len);
        v["samples"] = json!(self.log.len());
        v["rate_hz"] = json!(self.log.rate_hz());
        v["duration_s"] = json!(self.log.duration_s());
        v["signals"] = json!(signals);
        v["state_frames"] = json!(frames);
        v
    }
}

/// Scores as JSON: `{"rmse": {method: ..}, "nrmse": {..}, "calibration": {method:
/// {coverage_1sigma, coverage_2sigma, mean_nees, nlpd, samples}}}`, keyed by
/// [`Method::key`] (the open loop has no calibration).
pub fn scores_json(scores: &[Score]) -> Value {
    let mut r = Map::new();
    let mut n = Map::new();
    let mut c = Map::new();
    for s in scores {
        r.insert(s.method.key().into(), json!(s.rmse));
        n.insert(s.method.key().into(), json!(s.nrmse));
        if let Some(cal) = &s.calibration {
            c.insert(s.method.key().into(), json!(cal));
        }
    }
    json!({"rmse": r, "nrmse": n, "calibration": c})
}

/// `series` (one value per grid sample) at the time of each frame, interpolated between the
/// grid samples around it; NaN past the series' end.
pub(crate) fn at_frames(series: &[f64], frames: &[hbn_io::GridSample]) -> Vec<f64> {
    frames.iter().map(|f| at_frame(series, f)).collect()
}

fn at_frame(series: &[f64], frame: &hbn_io::GridSample) -> f64 {
    let after = series.get(frame.k).copied().unwrap_or(f64::NAN);
    match frame.k.checked_sub(1).and_then(|k| series.get(k)) {
        Some(&before) if frame.weight < 1.0 => frame.weight * after + (1.0 - frame.weight) * before,
        _ => after,
    }
}

/// What a score compares, sample by sample: an estimate, its standard deviation (if it has
/// one) and the logged state. Where the state is measured sparsely ([`LogData::frames_of`])
/// only its frames count, each against the estimate interpolated to the frame's time: the
/// grid's values between frames are interpolations, not measurements. Otherwise every grid
/// sample counts. Series of several logs joined ([`Compared::join`]) are scored as one: the
/// RMSE and the calibration over all their samples, the nRMSE over the range of the state
/// over all of them.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Compared {
    /// The estimate.
    pub x: Vec<f64>,
    /// Its standard deviation (`None` for the open loop, which has none).
    pub x_std: Option<Vec<f64>>,
    /// The logged state.
    pub reference: Vec<f64>,
}

impl Compared {
    /// The estimate `x` (with standard deviation `x_std`) against column `column` of `log`.
    pub fn against(x: &[f64], x_std: Option<&[f64]>, log: &LogData, column: usize) -> Self {
        match log.frames_of(column) {
            Some(frames) => Self {
                x: at_frames(x, frames),
                x_std: x_std.map(|s| at_frames(s, frames)),
                reference: frames.iter().map(|f| f.value).collect(),
            },
            None => Self {
                x: x.to_vec(),
                x_std: x_std.map(<[f64]>::to_vec),
                reference: log.column(column).to_vec(),
            },
        }
    }

    /// The samples of every one of `parts`, in order; a standard deviation only if every part
    /// has one.
    pub fn join(parts: impl IntoIterator<Item = Self>) -> Self {
        let mut out = Self {
            x_std: Some(Vec::new()),
            ..Self::default()
        };
        for p in parts {
            out.x.extend(p.x);
            out.reference.extend(p.reference);
            out.x_std = match (out.x_std, p.x_std) {
                (Some(mut a), Some(b)) => {
                    a.extend(b);
                    Some(a)
                }
                _ => None,
            };
        }
        out
    }

    /// RMSE, nRMSE and, with a standard deviation, the calibration.
    pub fn score(&self, method: Method) -> Score {
        Score {
            method,
            rmse: rmse(&self.x, &self.reference),
            nrmse: nrmse(&self.x, &self.reference),
            calibration: self
                .x_std
                .as_ref()
                .map(|sd| calibration(&self.x, sd, &self.reference)),
        }
    }
}

/// Scores `method`'s estimate `x` (with standard deviation `x_std`, if it has one) against the
/// state logged in `log` (column 1), at the state's frames only where it is measured sparsely
/// ([`Compared`]).
pub fn score_against_log(method: Method, x: &[f64], x_std: Option<&[f64]>, log: &LogData) -> Score {
    Compared::against(x, x_std, log, 1).score(method)
}

/// The scores of several evaluations of one model with the same modes (one per log), pooled
/// sample by sample ([`Compared::join`]): one per method of the first, in its order. Empty
/// when `evaluations` is.
pub fn pool_evaluations(evaluations: &[Evaluation]) -> Vec<Score> {
    let Some(first) = evaluations.first() else {
        return Vec::new();
    };
    first
        .scores
        .iter()
        .map(|s| {
            let parts = evaluations.iter().map(|ev| match s.method {
                Method::Filter(mode) => {
                    let est = ev
                        .estimates
                        .iter()
                        .find(|(m, _)| *m == mode)
                        .map(|(_, e)| e);
                    match est {
                        Some(e) => Compared::against(&e.x, Some(&e.x_std), &ev.log, 1),
                        None => Compared::default(),
                    }
                }
                Method::OpenLoop => Compared::against(&ev.open_loop, None, &ev.log, 1),
            });
            Compared::join(parts).score(s.method)
        })
        .collect()
}

/// Reads `u`, `x`, `y` from `file` at the model's rate, runs each of `modes` and the open-loop
/// simulation, and scores them against the logged `x` ([`score_against_log`]: at the state's
/// frames only where it is measured sparsely).
pub fn evaluate_log(
    model: &HysteresisModel,
    file: &Path,
    signals: &SignalChoice,
    modes: &[Mode],
    log_options: LogOptions,
    observe: &mut Observer<'_>,
) -> Result<Evaluation, PipelineError> {
    let which = [LogOption::Input, LogOption::State, LogOption::Output];
    let split = read_pieces_at_model_rate(model, file, signals, &which, log_options, observe)?;
    let log = join_pieces(&split.pieces).ok_or(PipelineError::NoModes)?;
    let u = log.column(0);
    let mut scores = Vec::new();
    let mut estimates = Vec::new();
    for &mode in modes {
        // The filter reads u and y (columns 0 and 2); each piece between long gaps restarts it.
        let est = estimate_pieces(model, &split.pieces, 0, 2, mode)?;
        scores.push(score_against_log(
            Method::Filter(mode),
            &est.x,
            Some(&est.x_std),
            &log,
        ));
        estimates.push((mode, est));
    }
    let mut open_loop = Vec::with_capacity(u.len());
    for piece in &split.pieces {
        open_loop.extend(model.simulate_open_loop(piece.column(0))?);
    }
    scores.push(score_against_log(Method::OpenLoop, &open_loop, None, &log));
    Ok(Evaluation {
        log,
        estimates,
        open_loop,
        scores,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use hbn_io::{Aligned, GridSample};

    /// A 10-sample log whose state column holds `state`, measured sparsely at `frames` if
    /// given.
    fn log(state: Vec<f64>, frames: Option<Vec<GridSample>>) -> LogData {
        let n = state.len();
        LogData {
            file: "log.mcap".into(),
            paths: ["/u.data", "/x.data", "/y.data"]
                .iter()
                .map(|p| p.parse().unwrap())
                .collect(),
            native_rates: vec![Some(100.0), Some(30.0), Some(100.0)],
            samples_in_grid: vec![n, 3, n],
            samples_recorded: vec![n, 3, n],
            dropouts: vec![vec![false; n]; 3],
            sparse: vec![None, frames, None],
            aligned: Aligned {
                rate_hz: 100.0,
                t0_ns: 0,
                t_s: (0..n).map(|k| k as f64 * 0.01).collect(),
                columns: vec![vec![0.0; n], state, vec![0.0; n]],
            },
        }
    }

    #[test]
    fn joined_logs_are_scored_as_one_series() {
        // A dense log of 10 samples, off by 0.1 everywhere, state 0..0.9; a sparse one whose
        // 2 frames are off by 0.4, state up to 2.0. Standard deviation 0.2: z = 0.5 and 2.
        let x: Vec<f64> = (0..10).map(|k| k as f64 / 10.0).collect();
        let sd = vec![0.2; 10];
        let dense = log(x.iter().map(|v| v + 0.1).collect(), None);
        let frames = vec![
            GridSample {
                k: 2,
                weight: 1.0,
                value: 0.6,
            },
            GridSample {
                k: 9,
                weight: 1.0,
                value: 1.3,
            },
        ];
        let sparse = log(vec![2.0; 10], Some(frames));
        let both = Compared::join([
            Compared::against(&x, Some(&sd), &dense, 1),
            Compared::against(&x, Some(&sd), &sparse, 1),
        ]);
        assert_eq!(both.x.len(), 12);
        let s = both.score(Method::Filter(Mode::Ukf));
        let mse = (10.0 * 0.01 + 2.0 * 0.16) / 12.0;
        assert!((s.rmse - f64::sqrt(mse)).abs() < 1e-12, "{s:?}");
        // The range of the state over both: 0.1 to 1.3.
        assert!((s.nrmse - s.rmse / 1.2).abs() < 1e-12, "{s:?}");
        let c = s.calibration.unwrap();
        assert_eq!(c.samples, 12);
        assert!((c.coverage_1sigma - 10.0 / 12.0).abs() < 1e-12, "{c:?}");
        assert!(
            (c.mean_nees - (10.0 * 0.25 + 2.0 * 4.0) / 12.0).abs() < 1e-12,
            "{c:?}"
        );
        // A part without a standard deviation leaves the joined series without one.
        let open = Compared::join([
            Compared::against(&x, Some(&sd), &dense, 1),
            Compared::against(&x, None, &dense, 1),
        ]);
        assert!(open.x_std.is_none() && open.score(Method::OpenLoop).calibration.is_none());
    }

    #[test]
    fn a_sparse_state_is_scored_at_its_frames_only() {
        // The estimate is the ramp k / 10; the frames measure it exactly, at a grid sample
        // and between two; the grid's state column holds nonsense between them.
        let x: Vec<f64> = (0..10).map(|k| k as f64 / 10.0).collect();
        let sd = vec![0.05; 10];
        let frames = vec![
            GridSample {
                k: 0,
                weight: 1.0,
                value: 0.0,
            },
            GridSample {
                k: 4,
                weight: 0.5,
                value: 0.35,
            },
            GridSample {
                k: 9,
                weight: 1.0,
                value: 0.9,
            },
        ];
        let nonsense = vec![1e3; 10];
        let sparse = log(nonsense.clone(), Some(frames));
        let s = score_against_log(Method::Filter(Mode::Ekf), &x, Some(&sd), &sparse);
        assert!(s.rmse < 1e-12, "{s:?}");
        let c = s.calibration.unwrap();
        assert_eq!(c.samples, 3);
        assert_eq!(c.coverage_2sigma, 1.0);
        // One frame off by 0.09: RMSE over the three frames.
        let mut off = sparse.clone();
        if let Some(Some(f)) = off.sparse.get_mut(1) {
            f[1].value += 0.09;
        }
        let s = score_against_log(Method::OpenLoop, &x, None, &off);
        assert!(
            (s.rmse - (0.09f64 * 0.09 / 3.0).sqrt()).abs() < 1e-12,
            "{s:?}"
        );
        assert!((s.nrmse - s.rmse / 0.9).abs() < 1e-12, "{s:?}");
        assert!(s.calibration.is_none());
        // Measured at every sample: the grid's column is the reference.
        let dense = log(nonsense, None);
        let s = score_against_log(Method::Filter(Mode::Ekf), &x, Some(&sd), &dense);
        assert!(s.rmse > 900.0, "{s:?}");
        assert_eq!(s.calibration.unwrap().samples, 10);
    }
}
