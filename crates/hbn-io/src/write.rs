//! Writing logs and other files atomically.

use std::collections::BTreeMap;
use std::io::BufWriter;
use std::path::Path;

use serde_json::{Value, json};

use crate::IoError;

/// Message encoding for [`write_scalar_log`].
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Encoding {
    /// `json` messages with a `jsonschema` schema.
    Json,
    /// ROS 2 `cdr` messages with a `ros2msg` schema.
    Ros2,
}

/// One scalar series to write as its own topic.
#[derive(Clone, Copy, Debug)]
pub struct ScalarTopic<'a> {
    /// The topic name (e.g. `/input`).
    pub topic: &'a str,
    /// One value per time stamp.
    pub values: &'a [f64],
}

/// Schema name of the messages [`write_scalar_log`] writes.
pub const STAMPED_SCALAR_NAME: &str = "hbn_msgs/msg/StampedScalar";

const SEP: &str =
    "================================================================================\n";

/// The `ros2msg` text of `hbn_msgs/msg/StampedScalar`, with its dependencies, in the
/// concatenated format ROS 2 and `mcap-ros2-support` use.
pub fn stamped_scalar_ros2msg() -> String {
    format!(
        "std_msgs/Header header\nfloat64 data\n{SEP}MSG: std_msgs/Header\n\
         builtin_interfaces/Time stamp\nstring frame_id\n{SEP}MSG: builtin_interfaces/Time\n\
         int32 sec\nuint32 nanosec\n"
    )
}

/// The JSON schema of the JSON `StampedScalar` messages.
pub fn stamped_scalar_jsonschema() -> Value {
    json!({
        "$schema": "https://json-schema.org/draft/2020-12/schema",
        "title": STAMPED_SCALAR_NAME,
        "type": "object",
        "properties": {
            "header": {
                "type": "object",
                "properties": {
                    "stamp": {
                        "type": "object",
                        "properties": {
                            "sec": {"type": "integer"},
                            "nanosec": {"type": "integer", "minimum": 0, "maximum": 999_999_999}
                        },
                        "required": ["sec", "nanosec"]
                    },
                    "frame_id": {"type": "string"}
                },
                "required": ["stamp", "frame_id"]
            },
            "data": {"type": "number"}
        },
        "required": ["header", "data"]
    })
}

/// Serializes one StampedScalar as CDR little-endian with the encapsulation header.
pub fn stamped_scalar_cdr(sec: i32, nanosec: u32, frame_id: &str, data: f64) -> Vec<u8> {
    let mut b = Vec::with_capacity(32 + frame_id.len());
    b.extend_from_slice(&[0x00, 0x01, 0x00, 0x00]);
    b.extend_from_slice(&sec.to_le_bytes());
    b.extend_from_slice(&nanosec.to_le_bytes());
    let len = u32::try_from(frame_id.len() + 1).unwrap_or(u32::MAX);
    b.extend_from_slice(&len.to_le_bytes());
    b.extend_from_slice(frame_id.as_bytes());
    b.push(0);
    while (b.len() - 4) % 8 != 0 {
        b.push(0);
    }
    b.extend_from_slice(&data.to_le_bytes());
    b
}

fn mcap_err(file: &Path, e: mcap::McapError) -> IoError {
    match e {
        mcap::McapError::Io(source) => IoError::Open {
            file: file.to_owned(),
            op: "write",
            source,
        },
        other => IoError::InvalidInput {
            file: file.to_owned(),
            reason: other.to_string(),
        },
    }
}

fn invalid(file: &Path, reason: String) -> IoError {
    IoError::InvalidInput {
        file: file.to_owned(),
        reason,
    }
}

fn check_times(file: &Path, t_ns: &[u64]) -> Result<(), IoError> {
    for w in t_ns.windows(2) {
        if w[1] < w[0] {
            return Err(invalid(
                file,
                format!("times must not decrease ({} ns then {} ns)", w[0], w[1]),
            ));
        }
    }
    Ok(())
}

fn split_stamp(file: &Path, t: u64) -> Result<(i32, u32), IoError> {
    let sec = i32::try_from(t / 1_000_000_000).map_err(|_| {
        invalid(
            file,
            format!("time {t} ns does not fit a ROS 2 stamp (int32 seconds)"),
        )
    })?;
    // < 1e9 always fits.
    let nsec = u32::try_from(t % 1_000_000_000).unwrap_or(0);
    Ok((sec, nsec))
}

/// Lets `f` fill a temporary file next to `file` and moves it over `file` atomically (the one
/// writer of `hbn-fs`).
fn atomic<F>(file: &Path, f: F) -> Result<(), IoError>
where
    F: FnOnce(&mut BufWriter<std::fs::File>) -> Result<(), IoError>,
{
    hbn_fs::write_atomic_with(file, f)
}

/// Writes `bytes` to `file` atomically: a temp file in the target's directory, fsync, rename,
/// directory fsync ([`hbn_fs::write_atomic`]).
pub fn write_atomic(file: &Path, bytes: &[u8]) -> Result<(), IoError> {
    Ok(hbn_fs::write_atomic(file, bytes)?)
}

/// Writes scalar series as separate topics, atomically.
///
/// Each message is `{header: {stamp: {sec, nanosec}, frame_id: ""}, data: f64}` at log time (and
/// publish time and stamp) `t_ns[k]`. [`Encoding::Json`]: message encoding `json`, schema
/// [`STAMPED_SCALAR_NAME`] encoded `jsonschema`. [`Encoding::Ros2`]: message encoding `cdr`
/// (little-endian), schema encoding `ros2msg` ([`stamped_scalar_ros2msg`]), profile `ros2`.
/// Chunked and zstd-compressed. Values must be finite; times must not decrease and must fit
/// int32 seconds.
pub fn write_scalar_log(
    file: &Path,
    t_ns: &[u64],
    topics: &[ScalarTopic<'_>],
    encoding: Encoding,
) -> Result<(), IoError> {
    check_times(file, t_ns)?;
    for tp in topics {
        if tp.topic.is_empty() {
            return Err(invalid(file, "a topic name is empty".into()));
        }
        if tp.values.len() != t_ns.len() {
            return Err(invalid(
                file,
                format!(
                    "topic `{}` has {} values for {} time stamps",
                    tp.topic,
                    tp.values.len(),
                    t_ns.len()
                ),
            ));
        }
        if let Some(k) = tp.values.iter().position(|v| !v.is_finite()) {
            return Err(IoError::NonFinite {
                path: tp.topic.to_owned(),
                t: t_ns[k],
            });
        }
    }
    let stamps = t_ns
        .iter()
        .map(|&t| split_stamp(file, t))
        .collect::<Result<Vec<_>, _>>()?;
    atomic(file, |w| {
        let opts = mcap::WriteOptions::new()
            .compression(Some(mcap::Compression::Zstd))
            .profile(match encoding {
                Encoding::Json => "",
                Encoding::Ros2 => "ros2",
            })
            .library(concat!("hbn-io/", env!("CARGO_PKG_VERSION")))
            .compression_threads(0);
        let mut out = opts.create(w).map_err(|e| mcap_err(file, e))?;
        let (schema_enc, schema_data, msg_enc) = match encoding {
            Encoding::Json => (
                "jsonschema",
                stamped_scalar_jsonschema().to_string().into_bytes(),
                "json",
            ),
            Encoding::Ros2 => ("ros2msg", stamped_scalar_ros2msg().into_bytes(), "cdr"),
        };
        let schema_id = out
            .add_schema(STAMPED_SCALAR_NAME, schema_enc, &schema_data)
            .map_err(|e| mcap_err(file, e))?;
        let mut ids = Vec::with_capacity(topics.len());
        for tp in topics {
            ids.push(
                out.add_channel(schema_id, tp.topic, msg_enc, &BTreeMap::new())
                    .map_err(|e| mcap_err(file, e))?,
            );
        }
        let mut seq = vec![0u32; topics.len()];
        let mut buf = Vec::new();
        for (k, &t) in t_ns.iter().enumerate() {
            let (sec, nsec) = stamps[k];
            for (c, tp) in topics.iter().enumerate() {
                let v = tp.values[k];
                let data: &[u8] = match encoding {
                    Encoding::Json => {
                        buf.clear();
                        let msg = json!({
                            "header": {"stamp": {"sec": sec, "nanosec": nsec}, "frame_id": ""},
                            "data": v
                        });
                        serde_json::to_writer(&mut buf, &msg)
                            .map_err(|e| invalid(file, e.to_string()))?;
                        &buf
                    }
                    Encoding::Ros2 => {
                        buf = stamped_scalar_cdr(sec, nsec, "", v);
                        &buf
                    }
                };
                out.write_to_known_channel(
                    &mcap::records::MessageHeader {
                        channel_id: ids[c],
                        sequence: seq[c],
                        log_time: t,
                        publish_time: t,
                    },
                    data,
                )
                .map_err(|e| mcap_err(file, e))?;
                seq[c] = seq[c].wrapping_add(1);
            }
        }
        out.finish().map_err(|e| mcap_err(file, e))?;
        drop(out);
        Ok(())
    })
}

/// Writes JSON `records` on one channel `topic` (message encoding `json`, schema `schema_name`
/// encoded `jsonschema` with `json_schema`), at log times `t_ns`, atomically.
pub fn write_json_log(
    file: &Path,
    topic: &str,
    schema_name: &str,
    json_schema: &Value,
    t_ns: &[u64],
    records: &[Value],
) -> Result<(), IoError> {
    check_times(file, t_ns)?;
    if topic.is_empty() {
        return Err(invalid(file, "the topic name is empty".into()));
    }
    if records.len() != t_ns.len() {
        return Err(invalid(
            file,
            format!("{} records for {} time stamps", records.len(), t_ns.len()),
        ));
    }
    atomic(file, |w| {
        let opts = mcap::WriteOptions::new()
            .compression(Some(mcap::Compression::Zstd))
            .library(concat!("hbn-io/", env!("CARGO_PKG_VERSION")))
            .compression_threads(0);
        let mut out = opts.create(w).map_err(|e| mcap_err(file, e))?;
        let schema_id = out
            .add_schema(
                schema_name,
                "jsonschema",
                json_schema.to_string().as_bytes(),
            )
            .map_err(|e| mcap_err(file, e))?;
        let id = out
            .add_channel(schema_id, topic, "json", &BTreeMap::new())
            .map_err(|e| mcap_err(file, e))?;
        let mut buf = Vec::new();
        for (k, (t, r)) in t_ns.iter().zip(records).enumerate() {
            buf.clear();
            serde_json::to_writer(&mut buf, r).map_err(|e| invalid(file, e.to_string()))?;
            out.write_to_known_channel(
                &mcap::records::MessageHeader {
                    channel_id: id,
                    sequence: u32::try_from(k).unwrap_or(u32::MAX),
                    log_time: *t,
                    publish_time: *t,
                },
                &buf,
            )
            .map_err(|e| mcap_err(file, e))?;
        }
        out.finish().map_err(|e| mcap_err(file, e))?;
        drop(out);
        Ok(())
    })
}
