//! # hbn-core
//!
//! The `no_std`, allocation-free core of hbn. Everything here works on borrowed slices and
//! nalgebra fixed-size matrices, so a firmware can hold a trained model in a `static` and run
//! the estimator step with bounded time and no heap.
//!
//! - [`kernel`]: the thesis' covariance functions with input and hyperparameter gradients;
//! - [`gp`]: GP prediction (mean, variance and their input gradients) from borrowed slices,
//!   exact or sparse (inducing points);
//! - [`ekf`]: the EKF / EKF+BLR step on the augmented HBN state;
//! - [`blr`]: local Bayesian linear regression with a bounded neighbourhood query;
//! - [`play`]: play operators and lags, the input's memory for the transition GP;
//! - [`vector`]: the filter step of a vector model (several inputs, state components and
//!   sensors).
//!
//! The modules `tables` (a trained model as constant tables, which exported firmware reads),
//! `rng`, `simd` and `eigen` are public for the other crates of the workspace and for the code
//! `hbn export` writes; they are not part of the supported API.
#![cfg_attr(not(feature = "std"), no_std)]
// `unsafe` only in `simd`, to call code compiled for a CPU feature the CPU was seen to have.
#![deny(unsafe_code)]
#![deny(missing_docs)]
#![allow(clippy::needless_range_loop)]
// index loops read like the matrix algebra they implement
// Panic-freedom by construction: no `unwrap`, `expect`, `panic!`, `unreachable!` or unchecked
// indexing/slicing outside tests. Lengths are checked with `get`, iterators, `zip` and
// `split_at` on checked lengths; `tests/no_panic` proves the step links with no panic path.
#![cfg_attr(
    not(test),
    deny(
        clippy::unwrap_used,
        clippy::expect_used,
        clippy::panic,
        clippy::unreachable,
        clippy::todo,
        clippy::unimplemented,
        clippy::indexing_slicing
    )
)]

pub mod blr;
pub mod ekf;
mod error;
pub mod gp;
pub mod kernel;
pub mod play;
#[doc(hidden)]
pub mod rng;
#[doc(hidden)]
pub mod simd;
#[doc(hidden)]
pub mod tables;
pub mod vector;

#[doc(hidden)]
pub mod eigen;
pub use blr::{LocalRegression, Neighbourhood, NeighbourhoodParts, Posterior};
pub use ekf::{
    EXTRAPOLATION_RATIO, Ekf, EkfConfig, EkfState, Estimator, Flags, HbnView, InitPrior,
    LOST_AFTER, MAX_SENSOR_MEMORY, Mode, SENSOR_DIM, SENSOR_STATE_DIM, StepOutput,
    observability_eigenvalues, state_information,
};
pub use error::CoreError;
pub use gp::{GpParts, GpView, Prediction, Variance, Want};
pub use kernel::{Kernel, KernelSpec, MAX_DIM, Metric, Profile};
pub use play::{MAX_PLAYS, PlayState, Plays, lag_coefficient, transition_input};
pub use vector::{
    AugMatrix, Dims, MAX_AUGMENTED, MAX_INPUTS, MAX_SENSORS, MAX_STATES, VectorConfig, VectorEkf,
    VectorEstimator, VectorInitPrior, VectorState, VectorStepOutput, VectorView,
    vector_state_information,
};
