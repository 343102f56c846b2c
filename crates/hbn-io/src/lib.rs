//! # hbn-io — MCAP logs for hbn
//!
//! Reads numeric signals from MCAP robot logs recorded with ROS 2 (CDR messages with `ros2msg`
//! schemas) or the Foxglove SDK (JSON messages), addressed by Foxglove-style message paths
//! ([`SignalPath`], e.g. `/joint_states.position[1]`); aligns them on one uniform time grid
//! ([`resample`]); and writes logs and other files atomically ([`write_log`],
//! [`write_timed_log`], [`write_scalar_log`], [`write_json_log`], [`write_atomic`]).
//!
//! All times are `u64` nanoseconds. Nothing here panics on any input bytes: malformed files,
//! schemas and messages are [`IoError`]s whose messages name the file, topic or field and say
//! what would fix them.
//!
//! Not supported: protobuf, ROS 1 and `ros2idl` channels ([`IoError::UnsupportedEncoding`]),
//! `wstring` fields, CDR parameter lists (XCDR1 PL_CDR / XCDR2 delimited).
#![forbid(unsafe_code)]
#![deny(missing_docs)]
#![cfg_attr(
    not(test),
    deny(clippy::unwrap_used, clippy::expect_used, clippy::panic)
)]

mod cdr;
mod error;
mod path;
mod read;
mod resample;
pub mod ros2msg;
mod write;

pub use error::IoError;
pub use path::{PathElem, SignalPath};
pub use read::{
    RawSignal, ReadOptions, ReadProgress, TimeSource, TopicInfo, UnknownTimeSource, list_topics,
    read_signals, read_signals_observed,
};
pub use resample::{
    Aligned, GridSample, ResampleOptions, SignalGap, dropouts_on_grid, native_rate_hz, resample,
    samples_on_grid, split_at_gaps, window,
};
pub use write::{
    Encoding, STAMPED_SCALAR_NAME, ScalarTopic, TimedTopic, Topic, stamped_cdr, stamped_jsonschema,
    stamped_ros2msg, stamped_scalar_cdr, stamped_scalar_jsonschema, stamped_scalar_ros2msg,
    stamped_schema_name, write_atomic, write_json_log, write_log, write_scalar_log,
    write_timed_log,
};

/// Decodes the value at `path` (fields inside the message, no topic) of one CDR message with a
/// `ros2msg` schema, for tests and tools. Returns the number, or an error naming `topic`.
pub fn decode_cdr_field(
    schema: &ros2msg::Ros2Schema,
    data: &[u8],
    topic: &str,
    path: &[PathElem],
) -> Result<f64, IoError> {
    let sp = SignalPath {
        topic: topic.to_owned(),
        fields: path.to_vec(),
    };
    let leaf = cdr::CdrWalker::new(schema)
        .get(data, path)
        .map_err(|e| read::walk_err_pub(&sp, 0, e))?;
    read::leaf_value_pub(&sp, leaf)
}
