//! `hbn explore`'s workflow: an input schedule for a robot that cannot run the explorer in its
//! loop, planned by [`hbn_model::explore::Explorer::plan`] from a model trained on a first
//! batch of logs and those logs (read with the model's signal paths, at its rate).
//!
//! The schedule continues the last log: its first input is within `max_step` of that log's
//! last input. Bounds not given are taken from the logs: the range of `u` and the largest
//! increment between two samples.

use std::path::{Path, PathBuf};

use hbn_io::{Encoding, ScalarTopic};
use hbn_model::explore::{ExploreError, ExploreParams, Explorer};
use hbn_model::{HysteresisModel, Sequence};

use crate::error::{LogOption, PipelineError};
use crate::estimate::{SignalChoice, read_at_model_rate};
use crate::log::{LogOptions, Observer};
use crate::sim::log_times;

/// Topic of the planned input in a schedule MCAP (field `data`).
pub const SCHEDULE_INPUT_TOPIC: &str = "/explore/u";
/// Topic of the state the model predicts along the schedule (field `data`).
pub const SCHEDULE_STATE_TOPIC: &str = "/explore/x_pred";
/// CSV header of a schedule (`t` in seconds from the first planned sample).
pub const SCHEDULE_CSV_HEADER: &str = "t,u,x_pred";

/// Input bounds of the plan; `None` takes the value from the logs.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Bounds {
    /// Lowest input.
    pub u_min: Option<f64>,
    /// Highest input.
    pub u_max: Option<f64>,
    /// Largest increment per sample.
    pub max_step: Option<f64>,
}

/// A planned input schedule.
#[derive(Clone, Debug, PartialEq)]
pub struct Schedule {
    /// The inputs, one per sample at `rate_hz`.
    pub u: Vec<f64>,
    /// The state the model's transition GP predicts for each sample (its mean).
    pub x_pred: Vec<f64>,
    /// Sample rate (the model's).
    pub rate_hz: f64,
    /// The parameters the plan used (bounds resolved).
    pub params: ExploreParams,
    /// The input the last log ended at (the schedule's first input is within `max_step`).
    pub last_input: f64,
    /// Samples of the first batch the plan stands on.
    pub history_samples: usize,
}

/// Fills the bounds the user left out from the logs: the range of `u` and its largest
/// increment (a zero increment, a constant log, leaves `max_step` for the check to reject).
fn resolve_bounds(bounds: Bounds, runs: &[Vec<f64>]) -> (f64, f64, f64) {
    let all = runs.iter().flatten().copied();
    let lo = all.clone().fold(f64::INFINITY, f64::min);
    let hi = all.fold(f64::NEG_INFINITY, f64::max);
    let step = runs
        .iter()
        .flat_map(|u| u.windows(2).map(|w| (w[1] - w[0]).abs()))
        .fold(0.0, f64::max);
    (
        bounds.u_min.unwrap_or(lo),
        bounds.u_max.unwrap_or(hi),
        bounds.max_step.unwrap_or(step),
    )
}

/// What to plan from: the first batch and how to read it, the bounds and the explorer's
/// parameters.
#[derive(Clone, Debug)]
pub struct PlanRequest {
    /// The logs of the first batch (the model was trained on them); the plan continues the
    /// last one.
    pub logs: Vec<PathBuf>,
    /// Signal paths (default: the model's).
    pub signals: SignalChoice,
    /// Log reading options (the rate must be unset: the model's is used).
    pub log_options: LogOptions,
    /// Input bounds; those left out come from the logs.
    pub bounds: Bounds,
    /// The explorer's parameters: its bounds are replaced by `bounds` resolved against the
    /// logs, its training parameters by the model's.
    pub params: ExploreParams,
    /// Samples to plan.
    pub steps: usize,
}

/// Reads the logs of `request` (u, x, y) on the model's grid and plans `request.steps`
/// inputs continuing the last log.
pub fn plan_from_logs(
    model: &HysteresisModel,
    request: &PlanRequest,
    observe: &mut Observer<'_>,
) -> Result<Schedule, PipelineError> {
    let logs = &request.logs;
    let mut params = request.params.clone();
    if logs.is_empty() {
        return Err(crate::error::OptionError {
            option: LogOption::Logs,
            problem: hbn_model::Problem::Invalid {
                reason: "give the logs of the first batch the model was trained on",
            },
        }
        .into());
    }
    let which = [LogOption::Input, LogOption::State, LogOption::Output];
    let mut data = Vec::with_capacity(logs.len());
    for file in logs {
        data.push(read_at_model_rate(
            model,
            file,
            &request.signals,
            &which,
            request.log_options,
            observe,
        )?);
    }
    let us: Vec<Vec<f64>> = data.iter().map(|d| d.column(0).to_vec()).collect();
    (params.u_min, params.u_max, params.max_step) = resolve_bounds(request.bounds, &us);
    let seqs: Vec<Sequence<'_>> = data
        .iter()
        .map(|d| Sequence::new(d.column(0), d.column(1), d.column(2)))
        .collect();
    let explorer = Explorer::resume(params, model, &seqs).map_err(explore_error)?;
    let (u, x_pred) = explorer.plan(request.steps);
    Ok(Schedule {
        u,
        x_pred,
        rate_hz: model.rate_hz(),
        params: explorer.params().clone(),
        last_input: us
            .last()
            .and_then(|u| u.last())
            .copied()
            .unwrap_or(f64::NAN),
        history_samples: explorer.n_observed(),
    })
}

fn explore_error(e: ExploreError) -> PipelineError {
    match e {
        ExploreError::Model(m) => PipelineError::Model(m),
        other => PipelineError::Explore(other),
    }
}

impl Schedule {
    /// The schedule as CSV text ([`SCHEDULE_CSV_HEADER`]).
    pub fn csv_text(&self) -> String {
        use std::fmt::Write as _;
        let mut s = String::with_capacity(40 * self.u.len() + 16);
        s.push_str(SCHEDULE_CSV_HEADER);
        s.push('\n');
        for (k, (u, x)) in self.u.iter().zip(&self.x_pred).enumerate() {
            let _ = writeln!(s, "{},{u},{x}", k as f64 / self.rate_hz);
        }
        s
    }

    /// Writes the schedule as MCAP (topics [`SCHEDULE_INPUT_TOPIC`] and
    /// [`SCHEDULE_STATE_TOPIC`], JSON `{header, data}` messages, the first at 1 s) or, for a
    /// file ending in `.csv`, as CSV; atomically.
    pub fn write(&self, file: &Path) -> Result<(), PipelineError> {
        let write_err = |source| PipelineError::Write {
            file: file.to_owned(),
            source,
        };
        let is_csv = file
            .extension()
            .is_some_and(|e| e.eq_ignore_ascii_case("csv"));
        if is_csv {
            return hbn_fs::write_atomic(file, self.csv_text().as_bytes())
                .map_err(|e| write_err(e.into()));
        }
        let t = log_times(self.u.len(), self.rate_hz);
        let topics = [
            ScalarTopic {
                topic: SCHEDULE_INPUT_TOPIC,
                values: &self.u,
            },
            ScalarTopic {
                topic: SCHEDULE_STATE_TOPIC,
                values: &self.x_pred,
            },
        ];
        hbn_io::write_scalar_log(file, &t, &topics, Encoding::Json).map_err(write_err)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bounds_left_out_come_from_the_logs() {
        let runs = vec![vec![0.2, 0.25, 0.22], vec![0.1, 0.4]];
        let (lo, hi, step) = resolve_bounds(Bounds::default(), &runs);
        assert_eq!((lo, hi), (0.1, 0.4));
        assert!((step - 0.3).abs() < 1e-12);
        let given = Bounds {
            u_min: Some(0.0),
            u_max: None,
            max_step: Some(0.01),
        };
        assert_eq!(resolve_bounds(given, &runs), (0.0, 0.4, 0.01));
    }
}
