//! # hbn-model
//!
//! The Hysteresis Bayesian Network (thesis Proposition 1, Eq. 16): a transition GP
//! `x_k = H_D(x_{k-1}, x_{k-2}, u_{k-1}, u_{k-2})` and a sensor GP
//! `y_k = H_S(x_{k-1}, y_{k-1}, x_k)` learned from logged `(u, x, y)`, driving the
//! allocation-free EKF / EKF+BLR step of [`hbn_core`] to estimate `x` from `u` and `y` alone.
//!
//! ```
//! use hbn_model::{HbnModel, HbnParams, Sequence, metrics::nrmse};
//! use hbn_sim::{SimConfig, SystemKind, simulate_random};
//! use hbn_core::Mode;
//! let cfg = SimConfig { noise_gain: 1.0, ..SimConfig::new(SystemKind::Duhem) };
//! let train = simulate_random(&cfg, 400).unwrap();
//! let params = HbnParams { max_points: 150, n_starts: 1, ..HbnParams::default() };
//! let model = HbnModel::fit(&[Sequence { u: &train.u, x: &train.x, y: &train.y }], &params).unwrap();
//! let test = simulate_random(&SimConfig { seed: 7, ..cfg }, 300).unwrap();
//! let est = model.estimate(&test.u, &test.y, Mode::Ekf).unwrap();
//! assert!(nrmse(&est.x, &test.x) < 0.2);
//! ```
#![forbid(unsafe_code)]
#![deny(missing_docs)]

pub mod dataset;
mod estimate;
pub mod experiment;
mod local;
pub mod metrics;
mod model;

pub use dataset::{Dataset, Sequence, Table, build_dataset};
pub use estimate::{Estimate, NEAR_UNOBSERVABLE, OBSERVABILITY_WINDOW, ObservabilitySummary};
pub use local::LocalData;
pub use model::{
    DEFAULT_INDUCING, HbnModel, HbnParams, INIT_NEIGHBOURS, KernelChoice, KernelFamily,
    MODEL_FORMAT, MODEL_FORMAT_VERSION, SignalInfo, SignalStats, Signals, TrainingSummary,
};

/// Errors of the model layer; each says what would fix it.
#[derive(Debug, thiserror::Error)]
pub enum ModelError {
    /// Bad training or estimation data.
    #[error("data: {0}")]
    Data(String),
    /// A bad setting.
    #[error("configuration: {0}")]
    Config(String),
    /// One of the GPs failed to train.
    #[error("{which} GP: {source}")]
    Gp {
        /// `transition` or `sensor`.
        which: &'static str,
        /// The GP error.
        #[source]
        source: hbn_gp::GpError,
    },
    /// The allocation-free core rejected the model or settings.
    #[error("core: {0}")]
    Core(#[from] hbn_core::CoreError),
    /// Reading or writing a file.
    #[error("{path}: {source}")]
    Io {
        /// The file.
        path: String,
        /// The OS error.
        #[source]
        source: std::io::Error,
    },
    /// A file that is not a model of a supported version.
    #[error("{path}: {reason}")]
    Format {
        /// The file.
        path: String,
        /// What is wrong.
        reason: String,
    },
    /// A simulator error.
    #[error("simulator: {0}")]
    Sim(#[from] hbn_sim::SimError),
}
