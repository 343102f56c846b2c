//! hbn's estimator step on an exported model, in a `no_std` crate with no allocation.
//!
//! The model is the file `hbn export --format rust` writes, included at build time from the
//! path in the `HBN_MODEL_RS` environment variable: `static` arrays and `hbn_model()`, which
//! returns the model view over them. A firmware keeps [`WORK_LEN`] doubles of work memory (a
//! `static` or a stack array) and calls [`estimate`] (or builds its own
//! [`hbn_core::Estimator`] the same way and steps it per sample).
#![no_std]
#![forbid(unsafe_code)]

/// The exported model: `HBN_LAYOUT`, `HBN_KEYS`, `HBN_REALS`, `hbn_model()` and sizes.
pub mod model {
    include!(env!("HBN_MODEL_RS"));
}

use hbn_core::{CoreError, Estimator};

/// Doubles of work memory [`estimate`] needs: the widened reals of an `f32` export and the
/// step's scratch.
pub const WORK_LEN: usize = model::HBN_WIDEN_LEN + model::HBN_SCRATCH_LEN;

/// One sample's estimate.
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
