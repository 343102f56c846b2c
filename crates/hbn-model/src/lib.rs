//! # hbn-model
//!
//! The Hysteresis Bayesian Network (thesis Proposition 1, Eq. 16): a transition GP
//! `x_k = H_D(x_{k-1}, x_{k-2}, u_{k-1}, u_{k-2})` and a sensor GP
//! `y_k = H_S(x_{k-1}, y_{k-1}, x_k)` learned from logged `(u, x, y)`, driving the
//! allocation-free EKF / EKF+BLR step of [`hbn_core`] to estimate `x` from `u` and `y` alone.
//!
//! - [`HbnParams`]: the training parameters, their defaults and their one check
//!   ([`HbnParams::check`] gives [`CheckedHbnParams`]; errors name the [`Param`]);
//! - [`HysteresisModel`]: fit, save, load; [`HysteresisModel::estimate`] over a whole sequence;
//! - [`explore::Explorer`]: which input to apply next while collecting training data
//!   (thesis Sec. 3.4);
//! - [`Filter`]: the owned streaming estimator (model, state and scratch in one value), whose
//!   per-sample step batch estimation loops over;
//! - [`smooth`]: offline smoothing ([`HysteresisModel::smooth`]), each state estimated from the
//!   whole sequence.
//!
//! ```
//! use hbn_model::{Filter, HysteresisModel, HbnParams, Sequence, metrics::nrmse};
//! use hbn_sim::{SimConfig, SystemKind, simulate_random};
//! use hbn_core::Mode;
//! let cfg = SimConfig { noise_gain: 1.0, ..SimConfig::new(SystemKind::Duhem) };
//! let train = simulate_random(&cfg, 400).unwrap();
//! let params = HbnParams { max_points: 150, n_starts: 1, ..HbnParams::default() };
//! let model = HysteresisModel::fit(&[Sequence::new(&train.u, &train.x, &train.y)], &params).unwrap();
//! let test = simulate_random(&SimConfig { seed: 7, ..cfg }, 300).unwrap();
//! let est = model.estimate(&test.u, &test.y, Mode::Ekf).unwrap();
//! assert!(nrmse(&est.x, &test.x) < 0.2);
//! // Streaming gives the same numbers, one sample at a time.
//! let mut filter = Filter::new(model, Mode::Ekf).unwrap();
//! let first = filter.step(test.u[0], test.y[0]);
//! assert_eq!(first.x, est.x[0]);
//! ```
#![forbid(unsafe_code)]
#![deny(missing_docs)]
#![cfg_attr(
    not(test),
    deny(clippy::unwrap_used, clippy::expect_used, clippy::panic)
)]

pub mod dataset;
mod error;
mod estimate;
mod evidence;
pub mod explore;
mod filter;
pub mod firmware;
pub mod latent;
mod local;
pub mod metrics;
mod model;
mod parallel;
mod params;
pub mod smooth;
pub mod tuning;
pub mod vector;
mod vector_filter;
pub mod vector_latent;
mod vector_smooth;

pub use dataset::{Dataset, MIN_SAMPLES, Memory, Sequence, Table, build_dataset};
pub use error::{DataError, ModelError, ModelFileProblem, Signal};
pub use estimate::{Estimate, NEAR_UNOBSERVABLE, OBSERVABILITY_WINDOW, ObservabilitySummary};
pub use evidence::KernelEvidence;
pub use filter::{Filter, FilterOutput};
/// A GP's prior mean ([`HbnParams::linear_mean`]).
pub use hbn_gp::MeanFunction;
pub use latent::{EmRound, LatentReport, LatentRun, PartialState, observed_mask};
pub use local::LocalData;
#[allow(deprecated)]
pub use model::HbnModel;
pub use model::{
    GpRole, HysteresisModel, INIT_NEIGHBOURS, MODEL_FORMAT, MODEL_FORMAT_VERSION, SignalStats,
    StartSummary, TrainingSummary,
};
pub use params::{
    Candidate, CheckedHbnParams, ConfigError, DEFAULT_EVIDENCE_KERNELS, DEFAULT_INDUCING,
    DEFAULT_LAGS, DEFAULT_MEMORY, DEFAULT_SENSOR_INPUTS, FIRMWARE_INDUCING_LADDER, HbnParams,
    KernelChoice, LinearMean, MIN_FIRMWARE_BUDGET, Param, ParamValue, Problem, SENSOR_MEMORY,
    Selection, SensorInputs, SignalInfo, Signals, UnknownKernel, VECTOR_DEFAULT_LAGS, parse_bytes,
};
pub use smooth::{Smoothing, StateFrame};
pub use tuning::{CandidateRow, FilterTuning, NoiseScales, ValidationReport};
pub use vector::{
    SignalNames, VectorCandidateRow, VectorEstimate, VectorKernelRow, VectorModel, VectorSequence,
    VectorSummary, VectorValidationRow,
};
pub use vector_filter::VectorFilter;
pub use vector_latent::VectorLatentRun;
pub use vector_smooth::VectorSmoothing;
