//! # hbn-gp
//!
//! Exact Gaussian-process training (std): faer's Cholesky of `K + s_n^2 I` with jitter retries
//! that are reported, the log marginal likelihood (thesis Eq. 7) with its analytic gradient
//! for every hyperparameter (noise included), multi-start L-BFGS on log-parameters with a noise
//! floor, standardisation on by default, and a reported subset policy for large data sets.
//!
//! Prediction runs through [`hbn_core::GpView`], allocation-free.
//!
//! ```
//! use hbn_gp::{fit, GpParams};
//! use hbn_core::{KernelSpec, Want};
//! let x: Vec<f64> = (0..40).map(|i| i as f64 / 8.0).collect();
//! let y: Vec<f64> = x.iter().map(|v| v.sin()).collect();
//! let gp = fit(&GpParams::new(KernelSpec::se_ard(1)), &x, &y).unwrap();
//! let p = gp.predict(&[1.0], Want::EKF).unwrap();
//! assert!((p.mean - 1f64.sin()).abs() < 1e-2);
//! ```
#![forbid(unsafe_code)]
#![deny(missing_docs)]
#![allow(clippy::needless_range_loop)] // index loops read like the matrix algebra they implement

mod data;
mod error;
pub mod factor;
pub mod likelihood;
mod model;
mod params;
pub mod sparse;
mod train;

pub use data::{column_stats, select_subset, whitening};
pub use error::GpError;
pub use model::{
    GP_FORMAT, GP_FORMAT_OLDEST, GP_FORMAT_VERSION, GaussianProcess, SparseFactors, StartReport,
    TrainingReport,
};
pub use params::{
    GpParams, Hyperparameters, MeanFunction, RawHyperparameters, SparseParams, SubsetPolicy,
};
pub use train::{FitProgress, StartFailure, Termination, fit, fit_observed};

/// Fewest support points a GP keeps (`GpParams::max_points` must be at least this).
pub const MIN_POINTS: usize = 2;
/// Largest number of support points of an exact GP (`max_points`): its `n x n` kernel matrix
/// (800 MB at this size) is factorised when a model is trained and again when it is loaded.
/// Longer logs are what the sparse GP (`n_inducing`) is for.
pub const MAX_EXACT_POINTS: usize = 10_000;

/// Writes `bytes` to `path` atomically: the one writer of [`hbn_fs`] (temporary file in the
/// same directory, fsync, rename, directory fsync). A failure leaves no partial file behind.
pub fn write_atomic(path: &std::path::Path, bytes: &[u8]) -> Result<(), GpError> {
    Ok(hbn_fs::write_atomic(path, bytes)?)
}
