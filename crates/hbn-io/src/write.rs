//! Writing logs and other files atomically.

use std::collections::BTreeMap;
use std::io::BufWriter;
use std::path::Path;

use serde_json::{Value, json};

use crate::IoError;

/// Message encoding for [`write_log`] and [`write_scalar_log`].
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Encoding {
    /// `json` messages with a `jsonschema` schema.
    Json,
    /// ROS 2 `cdr` messages with a `ros2msg` schema.
    Ros2,
}

/// One scalar series to write as its own topic (a message with the one field `data`).
#[derive(Clone, Copy, Debug)]
pub struct ScalarTopic<'a> {
    /// The topic name (e.g. `/input`).
    pub topic: &'a str,
    /// One value per time stamp.
    pub values: &'a [f64],
}

/// One topic of stamped messages with several `float64` fields, for [`write_log`]: the signal
/// path of field `f` is `topic.f` (e.g. `/state.x0`).
#[derive(Clone, Copy, Debug)]
pub struct Topic<'a> {
    /// The topic name (e.g. `/state`).
    pub topic: &'a str,
    /// The message's fields in order: a name (lower-case letters, digits and single
    /// underscores, starting with a letter, not ending with `_`, not `header`) and one value
    /// per time stamp.
    pub fields: &'a [(&'a str, &'a [f64])],
}

/// One topic of stamped messages with its own time stamps, for [`write_timed_log`]: a topic
/// recorded at its own rate (a camera slower than the other sensors, a topic with dropped
/// messages).
#[derive(Clone, Copy, Debug)]
pub struct TimedTopic<'a> {
    /// The topic name (e.g. `/state`).
    pub topic: &'a str,
    /// The log time of each message (ns), not decreasing.
    pub t_ns: &'a [u64],
    /// The message's fields in order, as in [`Topic::fields`]: one value per time stamp of
    /// this topic.
    pub fields: &'a [(&'a str, &'a [f64])],
}

/// Schema name of the messages [`write_scalar_log`] writes.
pub const STAMPED_SCALAR_NAME: &str = "hbn_msgs/msg/StampedScalar";

const SEP: &str =
    "================================================================================\n";

/// Schema name of stamped messages with the `float64` fields `fields`: [`STAMPED_SCALAR_NAME`]
/// for the one field `data`, otherwise `hbn_msgs/msg/Stamped` followed by each field's name in
/// upper camel case (`["x0", "x1"]` gives `hbn_msgs/msg/StampedX0X1`).
pub fn stamped_schema_name(fields: &[&str]) -> String {
    if fields == ["data"] {
        return STAMPED_SCALAR_NAME.to_owned();
    }
    let mut name = String::from("hbn_msgs/msg/Stamped");
    for f in fields {
        for part in f.split('_') {
            let mut chars = part.chars();
            if let Some(first) = chars.next() {
                name.push(first.to_ascii_uppercase());
                name.extend(chars);
            }
        }
    }
    name
}

/// The `ros2msg` text of a stamped message with the `float64` fields `fields` (a
/// `std_msgs/Header header` first), with its dependencies, in the concatenated format ROS 2
/// and `mcap-ros2-support` use.
pub fn stamped_ros2msg(fields: &[&str]) -> String {
    let mut text = String::from("std_msgs/Header header\n");
    for f in fields {
        text.push_str("float64 ");
        text.push_str(f);
        text.push('\n');
    }
    text.push_str(&format!(
        "{SEP}MSG: std_msgs/Header\nbuiltin_interfaces/Time stamp\nstring frame_id\n\
         {SEP}MSG: builtin_interfaces/Time\nint32 sec\nuint32 nanosec\n"
    ));
    text
}

/// The `ros2msg` text of `hbn_msgs/msg/StampedScalar`, with its dependencies, in the
/// concatenated format ROS 2 and `mcap-ros2-support` use.
pub fn stamped_scalar_ros2msg() -> String {
    stamped_ros2msg(&["data"])
}

/// The JSON schema of JSON stamped messages with the number fields `fields`, titled `name`.
pub fn stamped_jsonschema(name: &str, fields: &[&str]) -> Value {
    let mut properties = serde_json::Map::new();
    properties.insert(
        "header".into(),
        json!({
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
        }),
    );
    let mut required = vec![Value::from("header")];
    for f in fields {
        properties.insert((*f).to_owned(), json!({"type": "number"}));
        required.push(Value::from(*f));
    }
    json!({
        "$schema": "https://json-schema.org/draft/2020-12/schema",
        "title": name,
        "type": "object",
        "properties": properties,
        "required": required
    })
}

/// The JSON schema of the JSON `StampedScalar` messages.
pub fn stamped_scalar_jsonschema() -> Value {
    stamped_jsonschema(STAMPED_SCALAR_NAME, &["data"])
}

/// Serializes one stamped message with the `float64` fields `values` (in order) as CDR
/// little-endian with the encapsulation header.
pub fn stamped_cdr(sec: i32, nanosec: u32, frame_id: &str, values: &[f64]) -> Vec<u8> {
    let mut b = Vec::with_capacity(32 + frame_id.len() + 8 * values.len());
    b.extend_from_slice(&[0x00, 0x01, 0x00, 0x00]);
    b.extend_from_slice(&sec.to_le_bytes());
    b.extend_from_slice(&nanosec.to_le_bytes());
    let len = u32::try_from(frame_id.len() + 1).unwrap_or(u32::MAX);
    b.extend_from_slice(&len.to_le_bytes());
    b.extend_from_slice(frame_id.as_bytes());
    b.push(0);
    if !values.is_empty() {
        while (b.len() - 4) % 8 != 0 {
            b.push(0);
        }
    }
    for v in values {
        b.extend_from_slice(&v.to_le_bytes());
    }
    b
}

/// Serializes one StampedScalar as CDR little-endian with the encapsulation header.
pub fn stamped_scalar_cdr(sec: i32, nanosec: u32, frame_id: &str, data: f64) -> Vec<u8> {
    stamped_cdr(sec, nanosec, frame_id, &[data])
}

/// Whether `name` is a valid ROS 2 field name other than `header`: lower-case letters,
/// digits and single underscores, starting with a letter, not ending with an underscore.
fn valid_field_name(name: &str) -> bool {
    let b = name.as_bytes();
    name != "header"
        && b.first().is_some_and(u8::is_ascii_lowercase)
        && b.last() != Some(&b'_')
        && !name.contains("__")
        && b.iter()
            .all(|c| c.is_ascii_lowercase() || c.is_ascii_digit() || *c == b'_')
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
    check_topic_times(file, None, t_ns)
}

/// Checks that `t_ns` does not decrease; the message names `topic` when given.
fn check_topic_times(file: &Path, topic: Option<&str>, t_ns: &[u64]) -> Result<(), IoError> {
    for w in t_ns.windows(2) {
        if w[1] < w[0] {
            let whose = match topic {
                Some(topic) => format!("times of topic `{topic}`"),
                None => "times".to_owned(),
            };
            return Err(invalid(
                file,
                format!("{whose} must not decrease ({} ns then {} ns)", w[0], w[1]),
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

/// Writes scalar series as separate topics, atomically: [`write_log`] with one field `data`
/// per topic.
///
/// Each message is `{header: {stamp: {sec, nanosec}, frame_id: ""}, data: f64}`, schema
/// [`STAMPED_SCALAR_NAME`]; the signal path of a topic `/t` is `/t.data`.
pub fn write_scalar_log(
    file: &Path,
    t_ns: &[u64],
    topics: &[ScalarTopic<'_>],
    encoding: Encoding,
) -> Result<(), IoError> {
    let fields: Vec<[(&str, &[f64]); 1]> = topics.iter().map(|tp| [("data", tp.values)]).collect();
    let topics: Vec<Topic<'_>> = topics
        .iter()
        .zip(&fields)
        .map(|(tp, f)| Topic {
            topic: tp.topic,
            fields: f,
        })
        .collect();
    write_log(file, t_ns, &topics, encoding)
}

/// A schema of [`write_log`]: its name and its fields.
type Schema<'a> = (String, Vec<&'a str>);

/// Checks every topic of [`write_log`] and [`write_timed_log`] against its time stamps;
/// returns each topic's schema index and the schemas, in order of first use.
fn plan_schemas<'a>(
    file: &Path,
    topics: &[TimedTopic<'a>],
) -> Result<(Vec<usize>, Vec<Schema<'a>>), IoError> {
    let mut schemas: Vec<Schema<'a>> = Vec::new();
    let mut of_topic = Vec::with_capacity(topics.len());
    for (n, tp) in topics.iter().enumerate() {
        if tp.topic.is_empty() {
            return Err(invalid(file, "a topic name is empty".into()));
        }
        if topics[..n].iter().any(|o| o.topic == tp.topic) {
            return Err(invalid(
                file,
                format!("topic `{}` is given twice", tp.topic),
            ));
        }
        if tp.fields.is_empty() {
            return Err(invalid(file, format!("topic `{}` has no fields", tp.topic)));
        }
        let t_ns = tp.t_ns;
        for (i, &(name, values)) in tp.fields.iter().enumerate() {
            if !valid_field_name(name) {
                return Err(invalid(
                    file,
                    format!(
                        "field `{name}` of topic `{}` is not a valid field name (lower-case \
                         letters, digits and single underscores, starting with a letter, not \
                         ending with `_`, not `header`)",
                        tp.topic
                    ),
                ));
            }
            if tp.fields[..i].iter().any(|(other, _)| *other == name) {
                return Err(invalid(
                    file,
                    format!("field `{name}` of topic `{}` is given twice", tp.topic),
                ));
            }
            if values.len() != t_ns.len() {
                return Err(invalid(
                    file,
                    format!(
                        "`{}.{name}` has {} values for {} time stamps",
                        tp.topic,
                        values.len(),
                        t_ns.len()
                    ),
                ));
            }
            if let Some(k) = values.iter().position(|v| !v.is_finite()) {
                return Err(IoError::NonFinite {
                    path: format!("{}.{name}", tp.topic),
                    t: t_ns[k],
                });
            }
        }
        let names: Vec<&'a str> = tp.fields.iter().map(|(name, _)| *name).collect();
        let index = match schemas.iter().position(|(_, f)| *f == names) {
            Some(index) => index,
            None => {
                // Distinct field lists whose names camel-case alike get numbered names.
                let base = stamped_schema_name(&names);
                let mut name = base.clone();
                let mut k = 2;
                while schemas.iter().any(|(taken, _)| *taken == name) {
                    name = format!("{base}{k}");
                    k += 1;
                }
                schemas.push((name, names));
                schemas.len() - 1
            }
        };
        of_topic.push(index);
    }
    Ok((of_topic, schemas))
}

/// Writes topics of stamped messages with several `float64` fields, atomically.
///
/// Each message of a topic is `{header: {stamp: {sec, nanosec}, frame_id: ""}, f1: f64,
/// f2: f64, ...}` at log time (and publish time and stamp) `t_ns[k]`, one per time stamp and
/// topic; the signal path of field `f` of topic `/t` is `/t.f`. Topics with the same fields
/// share a schema named by [`stamped_schema_name`]. [`Encoding::Json`]: message encoding
/// `json`, schema encoding `jsonschema` ([`stamped_jsonschema`]). [`Encoding::Ros2`]: message
/// encoding `cdr` (little-endian, [`stamped_cdr`]), schema encoding `ros2msg`
/// ([`stamped_ros2msg`]), profile `ros2`. Chunked and zstd-compressed. Topic names must be
/// distinct and not empty, every topic needs at least one field, field names must be valid
/// ROS 2 field names (see [`Topic::fields`]) and distinct within a topic, values must be
/// finite (one per time stamp), times must not decrease and must fit int32 seconds.
/// [`write_timed_log`] writes topics with their own time stamps.
pub fn write_log(
    file: &Path,
    t_ns: &[u64],
    topics: &[Topic<'_>],
    encoding: Encoding,
) -> Result<(), IoError> {
    check_times(file, t_ns)?;
    let timed: Vec<TimedTopic<'_>> = topics
        .iter()
        .map(|tp| TimedTopic {
            topic: tp.topic,
            t_ns,
            fields: tp.fields,
        })
        .collect();
    // Sample by sample, each topic in turn.
    let order = (0..t_ns.len()).flat_map(|k| (0..topics.len()).map(move |c| (c, k)));
    write_messages(file, &timed, order, encoding)
}

/// Writes topics of stamped messages whose time stamps differ from topic to topic, atomically.
///
/// The messages, schemas and requirements are those of [`write_log`], with each topic's
/// times its own ([`TimedTopic::t_ns`], not decreasing; a topic may hold no message). The
/// messages are written in order of time, a tie in the order the topics are given. Topics
/// sharing one set of time stamps give the same file as [`write_log`].
pub fn write_timed_log(
    file: &Path,
    topics: &[TimedTopic<'_>],
    encoding: Encoding,
) -> Result<(), IoError> {
    for tp in topics {
        check_topic_times(file, Some(tp.topic), tp.t_ns)?;
    }
    // Every (topic, message) pair, merged by time; the sort is stable, so a tie keeps the
    // topics' order, and a topic's messages keep theirs.
    let mut order: Vec<(usize, usize)> = topics
        .iter()
        .enumerate()
        .flat_map(|(c, tp)| (0..tp.t_ns.len()).map(move |k| (c, k)))
        .collect();
    order.sort_by_key(|&(c, k)| topics[c].t_ns[k]);
    write_messages(file, topics, order.into_iter(), encoding)
}

/// Writes the messages `order` names (topic index, message index), in that order, after
/// checking the topics; the one writer of [`write_log`] and [`write_timed_log`].
fn write_messages(
    file: &Path,
    topics: &[TimedTopic<'_>],
    order: impl Iterator<Item = (usize, usize)>,
    encoding: Encoding,
) -> Result<(), IoError> {
    let (of_topic, schemas) = plan_schemas(file, topics)?;
    let stamps = topics
        .iter()
        .map(|tp| {
            tp.t_ns
                .iter()
                .map(|&t| split_stamp(file, t))
                .collect::<Result<Vec<_>, _>>()
        })
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
        let msg_enc = match encoding {
            Encoding::Json => "json",
            Encoding::Ros2 => "cdr",
        };
        let mut schema_ids = Vec::with_capacity(schemas.len());
        for (name, fields) in &schemas {
            let (schema_enc, schema_data) = match encoding {
                Encoding::Json => (
                    "jsonschema",
                    stamped_jsonschema(name, fields).to_string().into_bytes(),
                ),
                Encoding::Ros2 => ("ros2msg", stamped_ros2msg(fields).into_bytes()),
            };
            schema_ids.push(
                out.add_schema(name, schema_enc, &schema_data)
                    .map_err(|e| mcap_err(file, e))?,
            );
        }
        let mut ids = Vec::with_capacity(topics.len());
        for (tp, &s) in topics.iter().zip(&of_topic) {
            ids.push(
                out.add_channel(schema_ids[s], tp.topic, msg_enc, &BTreeMap::new())
                    .map_err(|e| mcap_err(file, e))?,
            );
        }
        let mut seq = vec![0u32; topics.len()];
        let mut buf = Vec::new();
        let mut values = Vec::new();
        for (c, k) in order {
            let tp = &topics[c];
            let t = tp.t_ns[k];
            let (sec, nsec) = stamps[c][k];
            values.clear();
            values.extend(tp.fields.iter().map(|(_, v)| v[k]));
            match encoding {
                Encoding::Json => {
                    buf.clear();
                    let mut msg = serde_json::Map::new();
                    msg.insert(
                        "header".into(),
                        json!({"stamp": {"sec": sec, "nanosec": nsec}, "frame_id": ""}),
                    );
                    for ((name, _), &v) in tp.fields.iter().zip(&values) {
                        msg.insert((*name).to_owned(), json!(v));
                    }
                    serde_json::to_writer(&mut buf, &msg)
                        .map_err(|e| invalid(file, e.to_string()))?;
                }
                Encoding::Ros2 => buf = stamped_cdr(sec, nsec, "", &values),
            }
            out.write_to_known_channel(
                &mcap::records::MessageHeader {
                    channel_id: ids[c],
                    sequence: seq[c],
                    log_time: t,
                    publish_time: t,
                },
                &buf,
            )
            .map_err(|e| mcap_err(file, e))?;
            seq[c] = seq[c].wrapping_add(1);
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::ros2msg::Ros2Schema;
    use crate::{PathElem, ReadOptions, SignalPath, decode_cdr_field, list_topics, read_signals};

    const T0: u64 = 1_650_000_000_123_456_789;

    fn paths(s: &[&str]) -> Vec<SignalPath> {
        s.iter().map(|p| p.parse().unwrap()).collect()
    }

    fn series(n: usize, f: impl Fn(usize) -> f64) -> Vec<f64> {
        (0..n).map(f).collect()
    }

    #[test]
    fn a_log_of_several_fields_reads_back_by_message_path() {
        let dir = tempfile::tempdir().unwrap();
        let n = 300;
        let t: Vec<u64> = (0..n as u64).map(|k| T0 + k * 10_000_000 + k % 7).collect();
        let u0 = series(n, |k| (k as f64 * 0.1).sin() / 3.0);
        let u1 = series(n, |k| f64::from_bits(0x3FF0_0000_0000_0001 + k as u64));
        let x0 = series(n, |k| -(k as f64).sqrt() * std::f64::consts::E);
        let x1 = series(n, |k| 1e-300 * k as f64);
        let x2 = series(n, |k| -1e300 / (1.0 + k as f64));
        let y0 = series(n, |k| k as f64 / 7.0);
        for enc in [Encoding::Json, Encoding::Ros2] {
            let f = dir.path().join(format!("fields_{enc:?}.mcap"));
            let topics = [
                Topic {
                    topic: "/input0",
                    fields: &[("data", &u0)],
                },
                Topic {
                    topic: "/input1",
                    fields: &[("data", &u1)],
                },
                Topic {
                    topic: "/state",
                    fields: &[("x0", &x0), ("x1", &x1), ("x2", &x2)],
                },
                Topic {
                    topic: "/sensor0",
                    fields: &[("data", &y0)],
                },
            ];
            write_log(&f, &t, &topics, enc).unwrap();
            let s = read_signals(
                &f,
                &paths(&[
                    "/state.x0",
                    "/state.x1",
                    "/state.x2",
                    "/input0.data",
                    "/input1.data",
                    "/sensor0.data",
                ]),
                &ReadOptions::default(),
            )
            .unwrap();
            for (sig, want) in s.iter().zip([&x0, &x1, &x2, &u0, &u1, &y0]) {
                assert_eq!(sig.t_ns, t, "{enc:?} {}", sig.path);
                assert_eq!(&sig.value, want, "{enc:?} {}", sig.path);
            }
            // A field the message does not have is an error, not a silent zero.
            assert!(read_signals(&f, &paths(&["/state.x3"]), &ReadOptions::default()).is_err());
            let topics = list_topics(&f).unwrap();
            let state = topics.iter().find(|t| t.topic == "/state").unwrap();
            assert_eq!(
                state.schema_name.as_deref(),
                Some("hbn_msgs/msg/StampedX0X1X2")
            );
            assert_eq!(state.message_count, n as u64);
            let input = topics.iter().find(|t| t.topic == "/input1").unwrap();
            assert_eq!(input.schema_name.as_deref(), Some(STAMPED_SCALAR_NAME));
            assert_eq!(
                state.schema_encoding.as_deref(),
                Some(match enc {
                    Encoding::Json => "jsonschema",
                    Encoding::Ros2 => "ros2msg",
                })
            );
        }
    }

    #[test]
    fn the_scalar_writer_is_the_one_field_case() {
        let dir = tempfile::tempdir().unwrap();
        let t: Vec<u64> = (0..50).map(|k| T0 + k * 1_000_000).collect();
        let a = series(50, |k| k as f64 * 0.25);
        let b = series(50, |k| -(k as f64));
        for enc in [Encoding::Json, Encoding::Ros2] {
            let (f, g) = (dir.path().join("scalar.mcap"), dir.path().join("log.mcap"));
            let scalar = [
                ScalarTopic {
                    topic: "/a",
                    values: &a,
                },
                ScalarTopic {
                    topic: "/b",
                    values: &b,
                },
            ];
            write_scalar_log(&f, &t, &scalar, enc).unwrap();
            let general = [
                Topic {
                    topic: "/a",
                    fields: &[("data", &a)],
                },
                Topic {
                    topic: "/b",
                    fields: &[("data", &b)],
                },
            ];
            write_log(&g, &t, &general, enc).unwrap();
            assert_eq!(std::fs::read(&f).unwrap(), std::fs::read(&g).unwrap());
        }
    }

    #[test]
    fn topics_with_their_own_times_read_back_in_time_order() {
        let dir = tempfile::tempdir().unwrap();
        let fast: Vec<u64> = (0..100).map(|k| T0 + k * 10_000_000).collect();
        // A slower topic on its own clock, with gaps, and one message at a fast topic's time.
        let slow: Vec<u64> = [0u64, 1, 2, 4, 7, 9, 10, 12, 28]
            .iter()
            .map(|j| T0 + 3_333_333 + j * 33_333_333)
            .chain(std::iter::once(fast[99]))
            .collect();
        let u = series(fast.len(), |k| k as f64 * 0.5);
        let x0 = series(slow.len(), |j| -(j as f64));
        let x1 = series(slow.len(), |j| j as f64 / 3.0);
        for enc in [Encoding::Json, Encoding::Ros2] {
            let f = dir.path().join(format!("timed_{enc:?}.mcap"));
            let topics = [
                TimedTopic {
                    topic: "/input",
                    t_ns: &fast,
                    fields: &[("data", &u)],
                },
                TimedTopic {
                    topic: "/state",
                    t_ns: &slow,
                    fields: &[("x0", &x0), ("x1", &x1)],
                },
                TimedTopic {
                    topic: "/empty",
                    t_ns: &[],
                    fields: &[("data", &[])],
                },
            ];
            write_timed_log(&f, &topics, enc).unwrap();
            let s = read_signals(
                &f,
                &paths(&["/input.data", "/state.x0", "/state.x1"]),
                &ReadOptions::default(),
            )
            .unwrap();
            assert_eq!((&s[0].t_ns, &s[0].value), (&fast, &u), "{enc:?}");
            assert_eq!((&s[1].t_ns, &s[1].value), (&slow, &x0), "{enc:?}");
            assert_eq!((&s[2].t_ns, &s[2].value), (&slow, &x1), "{enc:?}");
            let counts: Vec<(String, u64)> = list_topics(&f)
                .unwrap()
                .into_iter()
                .map(|t| (t.topic, t.message_count))
                .collect();
            assert!(counts.contains(&("/state".into(), slow.len() as u64)));
            assert!(counts.contains(&("/empty".into(), 0)));
            // The file's messages are in time order; a tie keeps the topics' order.
            let bytes = std::fs::read(&f).unwrap();
            let mut seen = Vec::new();
            for m in mcap::MessageStream::new(&bytes).unwrap() {
                let m = m.unwrap();
                seen.push((m.log_time, m.channel.topic.clone()));
            }
            assert_eq!(seen.len(), fast.len() + slow.len());
            assert!(seen.windows(2).all(|w| w[0].0 <= w[1].0), "{enc:?}");
            let last: Vec<&str> = seen[seen.len() - 2..]
                .iter()
                .map(|(_, t)| t.as_str())
                .collect();
            assert_eq!(last, ["/input", "/state"]);
        }
    }

    #[test]
    fn timed_topics_on_one_clock_give_the_file_of_write_log() {
        let dir = tempfile::tempdir().unwrap();
        let t: Vec<u64> = (0..80).map(|k| T0 + k * 10_000_000).collect();
        let a = series(80, |k| (k as f64).sin());
        let b = series(80, |k| k as f64 - 40.0);
        for enc in [Encoding::Json, Encoding::Ros2] {
            let (f, g) = (dir.path().join("one.mcap"), dir.path().join("timed.mcap"));
            let topics = [
                Topic {
                    topic: "/a",
                    fields: &[("data", &a)],
                },
                Topic {
                    topic: "/s",
                    fields: &[("x0", &b), ("x1", &a)],
                },
            ];
            write_log(&f, &t, &topics, enc).unwrap();
            let timed = topics.map(|tp| TimedTopic {
                topic: tp.topic,
                t_ns: &t,
                fields: tp.fields,
            });
            write_timed_log(&g, &timed, enc).unwrap();
            assert_eq!(std::fs::read(&f).unwrap(), std::fs::read(&g).unwrap());
        }
    }

    #[test]
    fn timed_topics_that_go_back_in_time_or_miscount_are_errors() {
        let dir = tempfile::tempdir().unwrap();
        let f = dir.path().join("bad_timed.mcap");
        let v = [1.0, 2.0, 3.0];
        let back = [TimedTopic {
            topic: "/cam",
            t_ns: &[5, 7, 6],
            fields: &[("data", &v)],
        }];
        let e = write_timed_log(&f, &back, Encoding::Json).unwrap_err();
        assert!(
            e.to_string()
                .contains("times of topic `/cam` must not decrease (7 ns then 6 ns)"),
            "{e}"
        );
        let short = [TimedTopic {
            topic: "/cam",
            t_ns: &[5, 6],
            fields: &[("data", &v)],
        }];
        let e = write_timed_log(&f, &short, Encoding::Ros2).unwrap_err();
        assert!(
            e.to_string()
                .contains("`/cam.data` has 3 values for 2 time stamps"),
            "{e}"
        );
        assert!(!f.exists());
    }

    #[test]
    fn schemas_are_valid_and_name_their_fields() {
        assert_eq!(stamped_schema_name(&["data"]), STAMPED_SCALAR_NAME);
        assert_eq!(
            stamped_schema_name(&["x0", "x1"]),
            "hbn_msgs/msg/StampedX0X1"
        );
        assert_eq!(
            stamped_schema_name(&["tip_x", "tip_y"]),
            "hbn_msgs/msg/StampedTipXTipY"
        );
        let fields = ["x0", "x1", "x2"];
        let name = stamped_schema_name(&fields);
        let schema = Ros2Schema::parse(&name, &stamped_ros2msg(&fields)).unwrap();
        let root = schema.root_type().unwrap();
        assert_eq!(root.name, "hbn_msgs/StampedX0X1X2");
        let names: Vec<&str> = root.fields.iter().map(|f| f.name.as_str()).collect();
        assert_eq!(names, ["header", "x0", "x1", "x2"]);
        // The CDR message: 4-byte encapsulation, stamp, frame_id, padding to 8, the fields.
        let d = stamped_cdr(7, 8, "", &[1.5, -2.5, 3.25]);
        assert_eq!(d.len(), 4 + 16 + 24);
        let get = |field: &str| {
            decode_cdr_field(&schema, &d, "/state", &[PathElem::Field(field.into())]).unwrap()
        };
        assert_eq!((get("x0"), get("x1"), get("x2")), (1.5, -2.5, 3.25));
        assert_eq!(
            stamped_scalar_cdr(7, 8, "", 1.5),
            stamped_cdr(7, 8, "", &[1.5])
        );
        // The JSON schema requires the header and every field.
        let js = stamped_jsonschema(&name, &fields);
        assert_eq!(js["title"], name.as_str());
        assert_eq!(js["required"], json!(["header", "x0", "x1", "x2"]));
        assert_eq!(js["properties"]["x2"]["type"], "number");
        assert_eq!(
            stamped_scalar_jsonschema()["required"],
            json!(["header", "data"])
        );
    }

    #[test]
    fn field_lists_that_name_alike_get_distinct_schemas() {
        let dir = tempfile::tempdir().unwrap();
        let f = dir.path().join("alike.mcap");
        let t = [1, 2, 3];
        let (a, b) = ([1.0, 2.0, 3.0], [4.0, 5.0, 6.0]);
        let topics = [
            Topic {
                topic: "/p",
                fields: &[("a_1", &a)],
            },
            Topic {
                topic: "/q",
                fields: &[("a1", &b)],
            },
            Topic {
                topic: "/r",
                fields: &[("a_1", &b)],
            },
        ];
        write_log(&f, &t, &topics, Encoding::Ros2).unwrap();
        let names: Vec<Option<String>> = list_topics(&f)
            .unwrap()
            .into_iter()
            .map(|t| t.schema_name)
            .collect();
        let want = ["hbn_msgs/msg/StampedA1", "hbn_msgs/msg/StampedA12"];
        assert_eq!(names, [want[0], want[1], want[0]].map(|s| Some(s.into())));
        let s = read_signals(
            &f,
            &paths(&["/p.a_1", "/q.a1", "/r.a_1"]),
            &ReadOptions::default(),
        )
        .unwrap();
        assert_eq!(
            (s[0].value.as_slice(), s[1].value.as_slice()),
            (&a[..], &b[..])
        );
        assert_eq!(s[2].value, b);
    }

    #[test]
    fn bad_topics_and_fields_are_errors_and_write_nothing() {
        let dir = tempfile::tempdir().unwrap();
        let f = dir.path().join("bad.mcap");
        let t = [1, 2, 3];
        let v = [0.5; 3];
        let one = |topic: &'static str, fields: &[(&str, &[f64])]| {
            let topics = [Topic { topic, fields }];
            write_log(&f, &t, &topics, Encoding::Json)
        };
        for name in ["X0", "0x", "a__b", "a_", "header", "", "x-0", "é"] {
            let e = one("/s", &[(name, &v)]).unwrap_err();
            assert!(matches!(e, IoError::InvalidInput { .. }), "{name}: {e}");
        }
        let e = one("/s", &[("x0", &v), ("x0", &v)]).unwrap_err();
        assert!(e.to_string().contains("given twice"), "{e}");
        let e = one("/s", &[]).unwrap_err();
        assert!(e.to_string().contains("no fields"), "{e}");
        let e = one("", &[("x0", &v)]).unwrap_err();
        assert!(matches!(e, IoError::InvalidInput { .. }), "{e}");
        let e = one("/s", &[("x0", &v), ("x1", &[1.0, 2.0])]).unwrap_err();
        assert!(e.to_string().contains("`/s.x1` has 2 values"), "{e}");
        let nan = [0.0, f64::NAN, 1.0];
        match one("/s", &[("x0", &v), ("x1", &nan)]) {
            Err(IoError::NonFinite { path, t: 2 }) => assert_eq!(path, "/s.x1"),
            other => panic!("{other:?}"),
        }
        let twice = [
            Topic {
                topic: "/s",
                fields: &[("x0", &v)],
            },
            Topic {
                topic: "/s",
                fields: &[("x1", &v)],
            },
        ];
        let e = write_log(&f, &t, &twice, Encoding::Ros2).unwrap_err();
        assert!(e.to_string().contains("given twice"), "{e}");
        assert!(!f.exists());
    }
}
