//! # hbn-core
//!
//! The `no_std`, allocation-free core of hbn. Everything here works on borrowed slices and
//! nalgebra fixed-size matrices, so a firmware can hold a trained model in a `static` and run
//! the estimator step with bounded time and no heap.
#![cfg_attr(not(feature = "std"), no_std)]
#![forbid(unsafe_code)]
#![deny(missing_docs)]

pub mod rng;
