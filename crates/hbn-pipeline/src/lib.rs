//! # hbn-pipeline — the hbn workflows as a library
//!
//! A sample's way from MCAP bytes to an estimate file, in library code only:
//!
//! 1. [`load_log`] reads the signals by Foxglove message path ([`hbn_io::read_signals_observed`]),
//!    chooses the grid rate (given, the model's, or a signal's native rate: [`GridRate`]), resamples
//!    and checks gaps ([`hbn_io::resample`]) under [`LogOptions`] (time source, largest gap,
//!    rate), checked once ([`LogOptions::check`]);
//! 2. [`train_from_logs`] trains the HBN on the grid and keeps the rate in the model
//!    ([`hbn_model::HysteresisModel::fit_checked`]);
//! 3. [`estimate_log`] runs the filter over a log at the model's rate and writes the estimate
//!    as CSV or MCAP ([`Outputs`], atomically through [`hbn_fs`]); [`evaluate_log`] scores it
//!    against a logged state.
//!
//! The `hbn` CLI and the Python package are thin shells over these functions, with the same
//! options and the same defaults. Workflows report progress as [`Event`]s to an observer the
//! front end renders. [`experiment`] runs the thesis' simulation study; [`sequences`] turns
//! simulated runs into training sequences. [`explore`] plans an input schedule that seeks
//! where the model is uncertain (`hbn explore`).
#![forbid(unsafe_code)]
#![deny(missing_docs)]
#![cfg_attr(
    not(test),
    deny(clippy::unwrap_used, clippy::expect_used, clippy::panic)
)]

mod error;
mod estimate;
mod eval;
pub mod experiment;
pub mod explore;
mod log;
mod sim;
mod train;
mod vector;

pub use error::{LogOption, OptionError, PipelineError, Setting};
pub use estimate::{
    CSV_HEADER, ESTIMATE_SCHEMA, ESTIMATE_TOPIC, EXTRAPOLATION_WARNING, EstimateWarning,
    LogEstimate, OUTLIER_WARNING, Outputs, SignalChoice, estimate_log, estimate_log_modes,
    estimate_schema, file_for_mode, read_at_model_rate, read_pieces_at_model_rate, smooth_pieces,
};
pub use eval::{
    Compared, Evaluation, Method, Score, evaluate_log, pool_evaluations, score_against_log,
    scores_json,
};
pub use log::{
    CheckedLogOptions, DEFAULT_MIN_COVERAGE, DEFAULT_MIN_STATE_SAMPLES, DROPOUT_FACTOR, Event,
    GridRate, LogData, LogOptions, LogPieces, Observer, RATE_NOTICE_TOLERANCE, SPARSE_BELOW,
    join_pieces, load_log, load_log_pieces, model_log_options, parse_signal, parse_time_source,
    round_rate,
};
pub use sim::{
    CameraFrames, MULTI_STATE_TOPIC, MultiSimLog, START_NS, SimLog, StateCamera, log_times,
    multi_input_path, multi_input_topic, multi_output_path, multi_output_topic, multi_state_field,
    multi_state_path, sequences, simulate_camera_log, simulate_log, simulate_multi_camera_log,
    simulate_multi_log,
};
pub use train::{
    DEFAULT_INPUT, DEFAULT_OUTPUT, DEFAULT_STATE, MIN_LOG_SAMPLES, MIN_PIECE_SAMPLES, TrainSignals,
    Trained, train_from_logs,
};
pub use vector::{
    ComponentScore, PooledRun, TrainedVector, VECTOR_ESTIMATE_SCHEMA, VectorEvaluation,
    VectorLogEstimate, VectorModeRun, VectorSignals, default_signals, estimate_vector_log,
    evaluate_vector_log, model_signals, pool_vector_evaluations, smooth_vector_log,
    train_vector_from_logs, vector_csv, vector_estimate_schema,
};
