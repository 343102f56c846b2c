//! `#[no_panic]` wrappers around hbn-core's run-time entry points, for the link-time check in
//! `tests/link.rs`. `no_panic` makes a function fail to link when the optimiser cannot prove
//! that it never unwinds; it needs optimisation (run the test with `--release`) and concrete
//! types, so these are thin, monomorphic wrappers.
#![no_std]
#![forbid(unsafe_code)]

use hbn_core::blr::{LocalRegression, Neighbourhood, Posterior};
use hbn_core::gp::{GpView, Prediction, Want};
use hbn_core::vector::{VectorEstimator, VectorStepOutput};
use hbn_core::{CoreError, Estimator, StepOutput};
use no_panic::no_panic;

/// The estimator step: `Estimator::step`, the function this crate proves panic-free.
#[no_panic]
pub fn step(est: &mut Estimator<'_, '_>, u: f64, y: f64) -> StepOutput {
    est.step(u, y)
}

/// The vector estimator step, with slices of any length.
#[no_panic]
pub fn vector_step(est: &mut VectorEstimator<'_, '_>, u: &[f64], y: &[f64]) -> VectorStepOutput {
    est.step(u, y)
}

/// Forgetting the state (the next step initialises).
#[no_panic]
pub fn reset(est: &mut Estimator<'_, '_>) {
    est.reset()
}

/// One GP prediction (what the step calls twice).
#[no_panic]
pub fn predict(
    gp: &GpView<'_>,
    x: &[f64],
    want: Want,
    scratch: &mut [f64],
) -> Result<Prediction, CoreError> {
    gp.predict(x, want, scratch)
}

/// The whitened cross-covariance of one input (the explorer's covariances), with any lengths.
#[no_panic]
pub fn whiten(
    gp: &GpView<'_>,
    x: &[f64],
    w: &mut [f64],
    scratch: &mut [f64],
) -> Result<f64, CoreError> {
    gp.whiten(x, w, scratch)
}

/// The latent posterior covariance of two inputs from their whitened vectors, any lengths.
#[no_panic]
pub fn posterior_covariance(
    gp: &GpView<'_>,
    a: &[f64],
    w_a: &[f64],
    b: &[f64],
    w_b: &[f64],
) -> Result<f64, CoreError> {
    gp.posterior_covariance(a, w_a, b, w_b)
}

/// The local regression of EKF+BLR, with any `max_neighbours` (validated or not).
#[no_panic]
pub fn posterior(
    blr: &LocalRegression,
    nb: &Neighbourhood<'_>,
    z: &[f64],
    mean: f64,
    grad: &[f64],
    latent: f64,
    noise: f64,
) -> Posterior {
    blr.posterior(nb, z, mean, grad, latent, noise)
}

/// The packed triangular solves, with arbitrary lengths.
#[no_panic]
pub fn substitute(l: &[f64], k: &[f64], v: &mut [f64]) -> Result<(), CoreError> {
    hbn_core::gp::forward_substitute_packed(l, k, v)?;
    hbn_core::gp::back_substitute_packed(l, v)
}

/// Widening `f32` tables into work memory (the firmware's initialisation), with any lengths.
#[no_panic]
pub fn widen<'w>(
    layout: &[u32],
    reals: &[f32],
    out: &'w mut [f64],
) -> Result<&'w [f64], CoreError> {
    hbn_core::tables::widen(layout, reals, out)
}
