//! hbn's estimator step on an exported model, in a `no_std` crate with no allocation.
//!
//! The model is the file `hbn export --format rust` writes, included at build time from the
//! path in the `HBN_MODEL_RS` environment variable: `static` arrays and `hbn_model()`, which
//! returns the model view over them. A firmware keeps [`WORK_LEN`] doubles of work memory (a
//! `static` or a stack array) and calls [`estimate`] (or builds its own
//! [`hbn_core::Estimator`] the same way and steps it per sample). A vector model's export
//! builds with the `vector` feature: [`vector::estimate`] runs it.
#![no_std]
#![forbid(unsafe_code)]

/// The exported model: `HBN_LAYOUT`, `HBN_KEYS`, `HBN_REALS`, `hbn_model()` and sizes.
pub mod model {
    include!(env!("HBN_MODEL_RS"));
}

use hbn_core::CoreError;
#[cfg(not(feature = "vector"))]
use hbn_core::Estimator;

/// Doubles of work memory [`estimate`] needs: the widened reals of an `f32` export and the
/// step's scratch.
pub const WORK_LEN: usize = model::HBN_WIDEN_LEN + model::HBN_SCRATCH_LEN;

/// One sample's estimate.
#[cfg(not(feature = "vector"))]
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Sample {
    /// Estimate of the state.
    pub x: f64,
    /// Its standard deviation.
    pub x_std: f64,
    /// Guard flags (`hbn_core::Flags`).
    pub flags: u32,
}

/// Runs the filter from a fresh start over the samples `u`, `y`, writing one [`Sample`] per
/// input into `out`; returns how many were written (the shortest of the three slices).
/// `work` must hold [`WORK_LEN`] doubles.
#[cfg(not(feature = "vector"))]
pub fn estimate(
    u: &[f64],
    y: &[f64],
    out: &mut [Sample],
    work: &mut [f64],
) -> Result<usize, CoreError> {
    let got = work.len();
    let (wide, scratch) =
        work.split_at_mut_checked(model::HBN_WIDEN_LEN)
            .ok_or(CoreError::ScratchTooSmall {
                needed: WORK_LEN,
                got,
            })?;
    let m = model::hbn_model(wide)?;
    let mut est = Estimator::new(m.view, m.config, scratch)?;
    let mut n = 0;
    for ((o, &u_k), &y_k) in out.iter_mut().zip(u).zip(y) {
        let s = est.step(u_k, y_k);
        *o = Sample {
            x: s.x,
            x_std: s.x_std,
            flags: s.flags.0,
        };
        n += 1;
    }
    Ok(n)
}

/// A vector model's export (the `vector` feature): `HBN_INPUTS` inputs and `HBN_SENSORS`
/// sensors per sample, `HBN_STATES` state components estimated.
#[cfg(feature = "vector")]
pub mod vector {
    use super::{CoreError, WORK_LEN, model};
    use hbn_core::vector::{MAX_STATES, VectorEstimator};

    /// One sample's estimate (entries past `HBN_STATES` are 0).
    #[derive(Clone, Copy, Debug, Default, PartialEq)]
    pub struct Sample {
        /// Estimate of each state component.
        pub x: [f64; MAX_STATES],
        /// Their standard deviations.
        pub x_std: [f64; MAX_STATES],
        /// Guard flags (`hbn_core::Flags`).
        pub flags: u32,
    }

    /// Runs the filter from a fresh start over the samples `u` (`HBN_INPUTS` values each,
    /// row-major) and `y` (`HBN_SENSORS` each; NaN is a missing sample), writing one
    /// [`Sample`] per sample into `out`; returns how many were written. `work` must hold
    /// [`WORK_LEN`] doubles.
    pub fn estimate(
        u: &[f64],
        y: &[f64],
        out: &mut [Sample],
        work: &mut [f64],
    ) -> Result<usize, CoreError> {
        let got = work.len();
        let (wide, scratch) =
            work.split_at_mut_checked(model::HBN_WIDEN_LEN)
                .ok_or(CoreError::ScratchTooSmall {
                    needed: WORK_LEN,
                    got,
                })?;
        let m = model::hbn_model(wide)?;
        let mut est = VectorEstimator::new(m.view(), m.config, scratch)?;
        let mut n = 0;
        let samples = u
            .chunks_exact(model::HBN_INPUTS)
            .zip(y.chunks_exact(model::HBN_SENSORS));
        for (o, (u_k, y_k)) in out.iter_mut().zip(samples) {
            let s = est.step(u_k, y_k);
            *o = Sample {
                x: s.x,
                x_std: s.x_std,
                flags: s.flags.0,
            };
            n += 1;
        }
        Ok(n)
    }
}
