//! The core's error type: small, `Copy`, and free of allocation.

use core::fmt;

/// Errors of the `no_std` core. They carry no heap data, so firmware can match on them.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum CoreError {
    /// A slice had the wrong length.
    DimensionMismatch {
        /// Length required.
        expected: usize,
        /// Length given.
        got: usize,
    },
    /// A value that must be finite was NaN or infinite.
    NonFinite,
    /// A structural setting is invalid; the text says which and why.
    InvalidSpec(&'static str),
    /// The caller's scratch buffer is too small.
    ScratchTooSmall {
        /// Values required.
        needed: usize,
        /// Values given.
        got: usize,
    },
    /// A model with no support points.
    Empty,
}

impl fmt::Display for CoreError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            CoreError::DimensionMismatch { expected, got } => {
                write!(
                    f,
                    "dimension mismatch: expected {expected} values, got {got}"
                )
            }
            CoreError::NonFinite => write!(f, "a value is NaN or infinite"),
            CoreError::InvalidSpec(why) => write!(f, "invalid specification: {why}"),
            CoreError::ScratchTooSmall { needed, got } => {
                write!(
                    f,
                    "scratch buffer too small: need {needed} values, got {got}"
                )
            }
            CoreError::Empty => write!(f, "the model has no support points"),
        }
    }
}

impl core::error::Error for CoreError {}
