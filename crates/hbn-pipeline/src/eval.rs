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
    /// "duration_s": .., "signals": [paths]}` (the samples are the span where every signal read
    /// has data).
    pub fn to_json(&self) -> Value {
        let mut r = Map::new();
        let mut n = Map::new();
        let mut c = Map::new();
        for s in &self.scores {
            r.insert(s.method.key().into(), json!(s.rmse));
            n.insert(s.method.key().into(), json!(s.nrmse));
            if let Some(cal) = &s.calibration {
                c.insert(s.method.key().into(), json!(cal));
            }
        }
        let signals: Vec<String> = self.log.paths.iter().map(|p| p.to_string()).collect();
        json!({"rmse": r, "nrmse": n, "calibration": c, "samples": self.log.len(),
               "rate_hz": self.log.rate_hz(), "duration_s": self.log.duration_s(),
               "signals": signals})
    }
}

/// Reads `u`, `x`, `y` from `file` at the model's rate, runs each of `modes` and the open-loop
/// simulation, and scores them against the logged `x`.
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
    let (u, x_ref) = (log.column(0), log.column(1));
    let mut scores = Vec::new();
    let mut estimates = Vec::new();
    for &mode in modes {
        // The filter reads u and y (columns 0 and 2); each piece between long gaps restarts it.
        let est = estimate_pieces(model, &split.pieces, 0, 2, mode)?;
        scores.push(Score {
            method: Method::Filter(mode),
            rmse: rmse(&est.x, x_ref),
            nrmse: nrmse(&est.x, x_ref),
            calibration: Some(calibration(&est.x, &est.x_std, x_ref)),
        });
        estimates.push((mode, est));
    }
    let mut open_loop = Vec::with_capacity(u.len());
    for piece in &split.pieces {
        open_loop.extend(model.simulate_open_loop(piece.column(0))?);
    }
    scores.push(Score {
        method: Method::OpenLoop,
        rmse: rmse(&open_loop, x_ref),
        nrmse: nrmse(&open_loop, x_ref),
        calibration: None,
    });
    Ok(Evaluation {
        log,
        estimates,
        open_loop,
        scores,
    })
}
