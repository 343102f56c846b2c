//! # hbn — the Hysteresis Bayesian Network
//!
//! One dependency for the whole engine. This facade re-exports the workspace crates:
//!
//! - [`core`] (`hbn-core`): `no_std`, allocation-free kernels, GP prediction and the EKF step;
//! - [`gp`] (`hbn-gp`): exact GP training (faer Cholesky, multi-start L-BFGS);
//! - [`sim`] (`hbn-sim`): hysteretic simulators;
//! - [`model`] (`hbn-model`): dataset builder, the two-GP HBN model, estimation drivers, metrics;
//! - [`io`] (`hbn-io`): MCAP logs (JSON, ROS 2 CDR), signal paths and time alignment.
#![forbid(unsafe_code)]

pub use hbn_core as core;
pub use hbn_gp as gp;
pub use hbn_io as io;
pub use hbn_model as model;
pub use hbn_sim as sim;
