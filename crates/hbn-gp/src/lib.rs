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
pub use params::{GpParams, Hyperparameters, RawHyperparameters, SparseParams, SubsetPolicy};
pub use train::{FitProgress, fit, fit_observed};

/// Writes `bytes` to `path` atomically: a temporary file in the same directory, flushed, then
/// renamed over the target. A failure leaves no partial file behind.
pub fn write_atomic(path: &std::path::Path, bytes: &[u8]) -> Result<(), GpError> {
    use std::io::Write;
    let io = |source| GpError::Io {
        path: path.display().to_string(),
        source,
    };
    let dir = match path.parent() {
        Some(p) if !p.as_os_str().is_empty() => p,
        _ => std::path::Path::new("."),
    };
    let mut builder = tempfile::Builder::new();
    builder.prefix(".hbn-tmp-");
    // Outputs are ordinary files (0644), not the owner-only mode of temporary files.
    #[cfg(unix)]
    {
        use std::os::unix::fs::PermissionsExt;
        builder.permissions(std::fs::Permissions::from_mode(0o644));
    }
    let mut tmp = builder.tempfile_in(dir).map_err(io)?;
    tmp.write_all(bytes).map_err(io)?;
    tmp.as_file().sync_all().map_err(io)?;
    tmp.persist(path).map_err(|e| io(e.error))?;
    Ok(())
}
