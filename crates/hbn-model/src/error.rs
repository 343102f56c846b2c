//! Errors of the model layer, typed so callers can match them; each message says what would
//! fix it.

use crate::params::ConfigError;

/// One of the three signals of the HBN.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Signal {
    /// The input `u`.
    Input,
    /// The state `x`.
    State,
    /// The sensor output `y`.
    Output,
}

impl Signal {
    /// `u`, `x` or `y`.
    pub const fn symbol(self) -> &'static str {
        match self {
            Signal::Input => "u",
            Signal::State => "x",
            Signal::Output => "y",
        }
    }
}

impl std::fmt::Display for Signal {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.symbol())
    }
}

/// Bad training or estimation data.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum DataError {
    /// No trajectories at all.
    #[error("no trajectories given; train from at least one")]
    NoTrajectories,
    /// No trajectory has a measured state: nothing to learn it from
    /// ([`crate::HysteresisModel::fit_partial`], [`crate::HysteresisModel::fit_latent`]).
    /// Trajectories without one join training only beside trajectories with one.
    #[error(
        "no trajectory has a measured state (x is NaN at every sample of every one); NaN marks \
         a sample without a measurement, and at least one trajectory needs measured samples"
    )]
    NoStateMeasured,
    /// The mask of measured states ([`crate::Sequence::observed`]) is not as long as the
    /// trajectory.
    #[error(
        "trajectory {trajectory}: the mask of measured states has {observed} entries for {samples} samples"
    )]
    ObservedLength {
        /// Index of the trajectory.
        trajectory: usize,
        /// Entries of the mask.
        observed: usize,
        /// Samples of the trajectory.
        samples: usize,
    },
    /// `u`, `x` and `y` of a trajectory differ in length.
    #[error("trajectory {trajectory}: u, x and y must have equal lengths (got {u}, {x}, {y})")]
    LengthMismatch {
        /// Index of the trajectory.
        trajectory: usize,
        /// Length of `u`.
        u: usize,
        /// Length of `x`.
        x: usize,
        /// Length of `y`.
        y: usize,
    },
    /// Too few samples in a trajectory.
    #[error(
        "trajectory {trajectory}: needs at least {min} samples, got {len}; record a longer log"
    )]
    TooShort {
        /// Index of the trajectory.
        trajectory: usize,
        /// Samples given.
        len: usize,
        /// Samples needed.
        min: usize,
    },
    /// A NaN or infinite training sample.
    #[error("trajectory {trajectory}: {signal}[{index}] is {value}; clean or cut the log")]
    NonFinite {
        /// Index of the trajectory.
        trajectory: usize,
        /// Which signal.
        signal: Signal,
        /// Sample index.
        index: usize,
        /// The value.
        value: f64,
    },
    /// `u` and `y` given to the filter differ in length.
    #[error("u and y must have equal lengths (got {u} and {y})")]
    InputOutputLength {
        /// Length of `u`.
        u: usize,
        /// Length of `y`.
        y: usize,
    },
}

/// What is wrong with a model file.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum ModelFileProblem {
    /// Binary data or not JSON.
    #[error("not an hbn model file (it is not JSON text); train one with `hbn train`")]
    NotJson,
    /// JSON, but with another format tag.
    #[error(
        "not an hbn model file (format tag {tag:?}, expected {:?})",
        crate::MODEL_FORMAT
    )]
    WrongFormat {
        /// The tag found.
        tag: String,
    },
    /// A format version this build does not read.
    #[error(
        "model format version {version} is not the version this hbn reads ({}): retrain the \
         model with this hbn (`hbn train` or `HysteresisModel.fit`), or load it with the hbn \
         that wrote it",
        crate::MODEL_FORMAT_VERSION
    )]
    UnsupportedVersion {
        /// The version found.
        version: u64,
    },
    /// A field is missing or has the wrong type (serde's description).
    #[error("malformed model: {detail}")]
    Malformed {
        /// What serde reported.
        detail: String,
    },
    /// The arrays do not fit together.
    #[error("inconsistent model: {0}")]
    Inconsistent(hbn_core::CoreError),
}

/// Errors of the model layer.
#[derive(Debug, thiserror::Error)]
pub enum ModelError {
    /// Bad training or estimation data.
    #[error(transparent)]
    Data(#[from] DataError),
    /// A parameter failed its check.
    #[error(transparent)]
    Config(#[from] ConfigError),
    /// One of the GPs failed to train.
    #[error("{which} GP: {source}")]
    Gp {
        /// Which GP.
        which: crate::GpRole,
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
    /// No configuration a flash budget allows fits it ([`crate::HbnParams::firmware_budget`]).
    #[error(
        "no model fits a firmware budget of {budget} bytes: the smallest trained ({inducing} \
         inducing points per GP) needs {flash} bytes of flash in f32; give a larger budget"
    )]
    FirmwareBudget {
        /// The budget (bytes).
        budget: u64,
        /// Inducing points of the smallest configuration trained.
        inducing: usize,
        /// Its smallest `f32` flash over the modes (bytes).
        flash: usize,
    },
    /// A file that is not a model of a supported version.
    #[error("{path}: {problem}")]
    ModelFile {
        /// The file (or `<string>`).
        path: String,
        /// What is wrong.
        problem: ModelFileProblem,
    },
}

impl From<hbn_fs::WriteError> for ModelError {
    fn from(e: hbn_fs::WriteError) -> Self {
        ModelError::Io {
            path: e.path.display().to_string(),
            source: e.source,
        }
    }
}
