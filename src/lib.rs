//! # hbn — the Hysteresis Bayesian Network
//!
//! One dependency for the whole engine: learn a hysteretic system (input `u`, state `x`, sensor
//! output `y`) with two Gaussian processes, then estimate `x` from `u` and `y` in real time.
//!
//! Most programs need only the [`prelude`]:
//!
//! ```no_run
//! use hbn::prelude::*;
//! # fn main() -> Result<(), Box<dyn std::error::Error>> {
//! // Train from MCAP logs (message paths of `hbn simulate`'s logs), then stream one log.
//! let logs = [std::path::PathBuf::from("train.mcap")];
//! let trained = train_from_logs(
//!     &logs,
//!     &TrainSignals::default(),
//!     LogOptions::default(),
//!     HbnParams::default(),
//!     &mut |_| {},
//! )?;
//! let mode = trained.model.default_mode();
//! let mut filter = Filter::new(trained.model, mode)?;
//! let out = filter.step(0.4, 0.1);
//! println!("x = {} +- {}", out.step.x, out.step.x_std);
//! # Ok(()) }
//! ```
//!
//! The crates behind the facade, for finer control:
//!
//! - [`core`] (`hbn-core`): `no_std`, allocation-free GP prediction and the filter step (the
//!   borrowing [`core::Estimator`] for firmware);
//! - [`gp`] (`hbn-gp`): exact and sparse GP training (faer Cholesky, multi-start L-BFGS);
//! - [`model`] (`hbn-model`): the two-GP model [`HysteresisModel`], its checked training
//!   parameters [`HbnParams`], the owned streaming [`Filter`] and the metrics;
//! - [`io`] (`hbn-io`): MCAP logs (JSON, ROS 2 CDR), signal paths and time alignment;
//! - [`pipeline`] (`hbn-pipeline`): logs to a model, logs to estimate files, evaluation (what
//!   the CLI and Python call);
//! - [`sim`] (`hbn-sim`): hysteretic simulators and the oracle floor.
#![forbid(unsafe_code)]

pub use hbn_core as core;
pub use hbn_gp as gp;
pub use hbn_io as io;
pub use hbn_model as model;
pub use hbn_pipeline as pipeline;
pub use hbn_sim as sim;

pub use hbn_model::{Filter, FilterOutput, HbnParams, HysteresisModel};

/// What most programs use, in one import: `use hbn::prelude::*;`.
pub mod prelude {
    pub use hbn_core::Mode;
    pub use hbn_model::metrics::{calibration, nrmse};
    pub use hbn_model::{
        Estimate, Filter, FilterOutput, HbnParams, HysteresisModel, KernelChoice, ModelError,
        Param, ParamValue, SensorInputs, Sequence,
    };
    pub use hbn_pipeline::{
        LogOptions, PipelineError, TrainSignals, Trained, estimate_log, evaluate_log,
        train_from_logs,
    };
}

#[doc = include_str!("../README.md")]
#[cfg(doctest)]
pub struct ReadmeDoctests;
