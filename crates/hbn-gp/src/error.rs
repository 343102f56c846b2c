//! Typed errors of GP training and persistence.

use hbn_core::CoreError;

/// Everything that can go wrong fitting, loading or using a GP.
#[derive(Debug, thiserror::Error)]
pub enum GpError {
    /// No training data.
    #[error("no training data: need at least {min} samples, got {got}")]
    TooFewSamples {
        /// Minimum required.
        min: usize,
        /// Given.
        got: usize,
    },
    /// Inputs and targets disagree in shape.
    #[error("shape mismatch: {what} (expected {expected}, got {got})")]
    Shape {
        /// Which array.
        what: &'static str,
        /// Expected length.
        expected: usize,
        /// Actual length.
        got: usize,
    },
    /// A NaN or infinite value in the data.
    #[error(
        "{what} contains a non-finite value (NaN or Inf) at row {row}; clean or drop that sample"
    )]
    NonFinite {
        /// Inputs or targets.
        what: &'static str,
        /// Row index.
        row: usize,
    },
    /// All targets equal: nothing to learn, and standardisation would divide by zero.
    #[error(
        "the targets are constant ({value}); a GP needs varying targets (check the signal or the log)"
    )]
    ConstantTargets {
        /// The constant value.
        value: f64,
    },
    /// A parameter failed validation.
    #[error("invalid parameter `{name}`: {reason}")]
    InvalidParameter {
        /// Parameter name.
        name: &'static str,
        /// Why it is invalid.
        reason: String,
    },
    /// The covariance stayed non-positive-definite after every jitter retry.
    #[error(
        "K + noise I is not positive definite even with jitter {jitter:e} after {retries} retries; \
         increase the noise floor or remove duplicate inputs"
    )]
    NotPositiveDefinite {
        /// Largest jitter tried.
        jitter: f64,
        /// Retries made.
        retries: usize,
    },
    /// Every optimiser start failed.
    #[error("hyperparameter optimisation failed on all {starts} starts; the last: {last}")]
    OptimizationFailed {
        /// Starts tried.
        starts: usize,
        /// Why the last start failed.
        last: crate::StartFailure,
    },
    /// An error of the allocation-free core.
    #[error("core: {0}")]
    Core(#[from] CoreError),
    /// Reading or writing a model file.
    #[error("{path}: {source}")]
    Io {
        /// The file.
        path: String,
        /// The OS error.
        source: std::io::Error,
    },
    /// A file that is not a GP model of a supported format version.
    #[error("{path}: {reason}")]
    Format {
        /// The file.
        path: String,
        /// What is wrong.
        reason: String,
    },
}

impl From<hbn_fs::WriteError> for GpError {
    fn from(e: hbn_fs::WriteError) -> Self {
        GpError::Io {
            path: e.path.display().to_string(),
            source: e.source,
        }
    }
}
