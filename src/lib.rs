//! # hbn — the Hysteresis Bayesian Network
//!
//! One dependency for the whole engine. This facade re-exports the workspace crates:
//!
//! - [`core`] (`hbn-core`): `no_std`, allocation-free kernels, GP prediction and the EKF step
//!   (the borrowing [`core::Estimator`] for firmware);
//! - [`gp`] (`hbn-gp`): exact GP training (faer Cholesky, multi-start L-BFGS);
//! - [`sim`] (`hbn-sim`): hysteretic simulators;
//! - [`model`] (`hbn-model`): dataset builder, the two-GP HBN model, checked parameters, the
//!   owned streaming [`Filter`], metrics;
//! - [`io`] (`hbn-io`): MCAP logs (JSON, ROS 2 CDR), signal paths and time alignment;
//! - [`pipeline`] (`hbn-pipeline`): logs to a model, logs to estimate files, evaluation, the
//!   simulation experiment (what the CLI and Python call);
//! - [`fs`] (`hbn-fs`): the atomic file writer every output goes through.
//!
//! The README's examples run as doctests of this crate.
#![forbid(unsafe_code)]

pub use hbn_core as core;
pub use hbn_fs as fs;
pub use hbn_gp as gp;
pub use hbn_io as io;
pub use hbn_model as model;
pub use hbn_pipeline as pipeline;
pub use hbn_sim as sim;

pub use hbn_model::{Filter, FilterOutput};

#[doc = include_str!("../README.md")]
#[cfg(doctest)]
pub struct ReadmeDoctests;
