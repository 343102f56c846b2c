//! Reading signals from MCAP logs (JSON and ROS 2 CDR messages).

use std::cell::Cell;
use std::collections::{BTreeMap, HashMap};
use std::fs::File;
use std::io::{BufReader, Read};
use std::path::{Path, PathBuf};
use std::rc::Rc;

use mcap::sans_io::LinearReaderOptions;
use serde_json::Value;

use crate::IoError;
use crate::cdr::{CdrWalker, Leaf, WalkError, index_range, resolve_index};
use crate::path::{PathElem, SignalPath};
use crate::ros2msg::Ros2Schema;

/// Which clock a sample is placed at.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum TimeSource {
    /// The MCAP message's log time (when the recorder received it).
    #[default]
    LogTime,
    /// `header.stamp` in the message: `{sec, nanosec}` (ROS 2) or `{sec, nsec}` (Foxglove).
    HeaderStamp,
}

impl TimeSource {
    /// Every clock, in the order of their names.
    pub const ALL: [TimeSource; 2] = [TimeSource::LogTime, TimeSource::HeaderStamp];

    /// `log` or `header` (what [`std::str::FromStr`] accepts).
    pub const fn name(self) -> &'static str {
        match self {
            TimeSource::LogTime => "log",
            TimeSource::HeaderStamp => "header",
        }
    }
}

impl std::fmt::Display for TimeSource {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

/// A clock name other than `log` and `header`.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
#[error("unknown time source {given:?}; choose \"log\" or \"header\"")]
pub struct UnknownTimeSource {
    /// The text given.
    pub given: String,
}

impl std::str::FromStr for TimeSource {
    type Err = UnknownTimeSource;
    /// Parses `log` or `header` (case-insensitive).
    fn from_str(s: &str) -> Result<Self, UnknownTimeSource> {
        let t = s.trim();
        TimeSource::ALL
            .into_iter()
            .find(|ts| t.eq_ignore_ascii_case(ts.name()))
            .ok_or_else(|| UnknownTimeSource {
                given: s.to_owned(),
            })
    }
}

/// Options for reading.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct ReadOptions {
    /// Which clock samples are placed at.
    pub time_source: TimeSource,
}

/// How far a read has come, for a progress display the caller renders
/// ([`read_signals_observed`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct ReadProgress {
    /// Bytes of the file read so far.
    pub bytes_read: u64,
    /// Size of the file.
    pub total_bytes: u64,
    /// The pass is over (the last report of a read).
    pub done: bool,
}

/// One signal as recorded.
///
/// `t_ns` are nanoseconds (`u64`: the MCAP log time, or `header.stamp` as
/// `sec * 1e9 + nanosec`), strictly increasing: when two samples of a signal have the same time
/// the later one in the file replaces the earlier one.
#[derive(Clone, Debug, PartialEq)]
pub struct RawSignal {
    /// The path the values were read from.
    pub path: SignalPath,
    /// Sample times (ns), strictly increasing.
    pub t_ns: Vec<u64>,
    /// Sample values, finite.
    pub value: Vec<f64>,
}

/// One channel of a log, as listed by [`list_topics`].
#[derive(Clone, Debug, PartialEq, Eq, serde::Serialize)]
pub struct TopicInfo {
    /// The topic name.
    pub topic: String,
    /// Number of messages on this channel.
    pub message_count: u64,
    /// The channel's message encoding (`json`, `cdr`, `protobuf`, ...).
    pub message_encoding: String,
    /// The schema name, if the channel has a schema.
    pub schema_name: Option<String>,
    /// The schema encoding (`jsonschema`, `ros2msg`, ...), if the channel has a schema.
    pub schema_encoding: Option<String>,
}

/// Counts the bytes read, for the progress bar.
struct Counting {
    inner: File,
    count: Rc<Cell<u64>>,
}

impl Read for Counting {
    fn read(&mut self, buf: &mut [u8]) -> std::io::Result<usize> {
        let n = self.inner.read(buf)?;
        self.count.set(self.count.get().saturating_add(n as u64));
        Ok(n)
    }
}

/// The next message of `reader`, `None` at the end. The mcap crate (0.26) indexes slices with
/// lengths read from the file (`read.rs`, attachment records: a crafted file makes it panic
/// with "slice index starts at 50 but ends at 49", a case the `mcap_ingest` fuzz target
/// reaches), so a panic inside it is caught here and reported as a corrupt file, like its
/// errors.
fn next_message(
    file: &Path,
    reader: &mut Messages,
) -> Result<Option<mcap::Message<'static>>, IoError> {
    match std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| reader.next())) {
        Ok(None) => Ok(None),
        Ok(Some(Ok(m))) => Ok(Some(m)),
        Ok(Some(Err(e))) => Err(corrupt(file, &e)),
        Err(_) => Err(IoError::Corrupt {
            file: file.to_owned(),
            reason: "the MCAP reader failed on a malformed record".to_owned(),
        }),
    }
}

fn corrupt(file: &Path, e: &mcap::McapError) -> IoError {
    let mut reason = plain(&e.to_string());
    let mut src = std::error::Error::source(e);
    while let Some(s) = src {
        reason.push_str(": ");
        reason.push_str(&plain(&s.to_string()));
        src = s.source();
    }
    IoError::Corrupt {
        file: file.to_owned(),
        reason,
    }
}

/// The MCAP reader's parse errors (binrw's) come as a multi-line, coloured "backtrace" box with
/// source locations of the parser: keeps the words on one line ("not enough bytes in reader;
/// While parsing field 'library' in Header"), without terminal escapes, box lines or `at
/// file:line` lines.
fn plain(text: &str) -> String {
    // Drop ANSI escape sequences (ESC [ ... letter).
    let mut clean = String::with_capacity(text.len());
    let mut chars = text.chars().peekable();
    while let Some(c) = chars.next() {
        if c == '\u{1b}' {
            if chars.peek() == Some(&'[') {
                chars.next();
                for d in chars.by_ref() {
                    if d.is_ascii_alphabetic() {
                        break;
                    }
                }
            }
            continue;
        }
        clean.push(c);
    }
    let parts: Vec<&str> = clean
        .lines()
        .map(str::trim)
        .filter(|l| !l.is_empty() && !l.contains('\u{2501}') && !l.starts_with("at "))
        .map(|l| {
            // "0: Error: what" -> "what"
            let l = match l.split_once(": ") {
                Some((n, rest)) if n.chars().all(|c| c.is_ascii_digit()) => rest,
                _ => l,
            };
            l.strip_prefix("Error: ").unwrap_or(l).trim()
        })
        .filter(|l| !l.is_empty())
        .collect();
    parts.join("; ").replace(":;", ":")
}

type Messages = mcap::io::MessageReader<BufReader<Counting>>;

/// Opens a log for one linear pass; checks the magic for a clear error message.
fn open(file: &Path) -> Result<(Messages, u64, Rc<Cell<u64>>), IoError> {
    let open_err = |op, source| IoError::Open {
        file: file.to_owned(),
        op,
        source,
    };
    let mut f = File::open(file).map_err(|e| open_err("open", e))?;
    let len = f.metadata().map_err(|e| open_err("read", e))?.len();
    if len == 0 {
        return Err(IoError::Corrupt {
            file: file.to_owned(),
            reason: "the file is empty".into(),
        });
    }
    let mut magic = [0u8; 8];
    let n = read_up_to(&mut f, &mut magic).map_err(|e| open_err("read", e))?;
    if n < magic.len() || magic != mcap::MAGIC {
        return Err(IoError::Corrupt {
            file: file.to_owned(),
            reason: "it does not start with the MCAP magic bytes".into(),
        });
    }
    let f = File::open(file).map_err(|e| open_err("open", e))?;
    let count = Rc::new(Cell::new(0));
    // A corrupt record length must not make the reader allocate without bound; real records
    // are never larger than the file (chunks are decompressed incrementally).
    let limit = usize::try_from(len.max(256 << 20)).unwrap_or(usize::MAX);
    let reader = mcap::io::MessageReader::new_with_options(
        BufReader::with_capacity(
            1 << 20,
            Counting {
                inner: f,
                count: count.clone(),
            },
        ),
        LinearReaderOptions::default().with_record_length_limit(limit),
    );
    Ok((reader, len, count))
}

fn read_up_to(f: &mut File, buf: &mut [u8]) -> std::io::Result<usize> {
    let mut n = 0;
    while n < buf.len() {
        match f.read(&mut buf[n..]) {
            Ok(0) => break,
            Ok(k) => n += k,
            Err(e) if e.kind() == std::io::ErrorKind::Interrupted => {}
            Err(e) => return Err(e),
        }
    }
    Ok(n)
}

/// Reports progress every 4096 messages and once at the end.
struct Progress<'o> {
    observe: &'o mut dyn FnMut(ReadProgress),
    count: Rc<Cell<u64>>,
    total: u64,
    n: u64,
}

impl Progress<'_> {
    fn tick(&mut self) {
        self.n += 1;
        if self.n.is_multiple_of(4096) {
            self.report(false);
        }
    }

    fn report(&mut self, done: bool) {
        (self.observe)(ReadProgress {
            bytes_read: self.count.get().min(self.total),
            total_bytes: self.total,
            done,
        });
    }
}

/// All channels' topics, after a pass.
fn channel_list(reader: &Messages) -> Vec<mcap::Channel<'static>> {
    (0..=u16::MAX)
        .filter_map(|id| reader.get_channel(id))
        .map(|c| (*c).clone())
        .collect()
}

fn topics_of(reader: &Messages) -> Vec<String> {
    let mut t: Vec<String> = channel_list(reader).into_iter().map(|c| c.topic).collect();
    t.sort();
    t.dedup();
    t
}

/// Lists the log's channels (topic, message count, encoding, schema), sorted by topic.
///
/// Reads the whole file once; channels without messages are listed with a count of 0.
pub fn list_topics(file: &Path) -> Result<Vec<TopicInfo>, IoError> {
    let (mut reader, _, _) = open(file)?;
    let mut counts: HashMap<u16, u64> = HashMap::new();
    while let Some(m) = next_message(file, &mut reader)? {
        *counts.entry(m.channel.id).or_default() += 1;
    }
    let mut out: Vec<TopicInfo> = channel_list(&reader)
        .into_iter()
        .map(|c| TopicInfo {
            message_count: counts.get(&c.id).copied().unwrap_or(0),
            message_encoding: c.message_encoding.clone(),
            schema_name: c.schema.as_ref().map(|s| s.name.clone()),
            schema_encoding: c.schema.as_ref().map(|s| s.encoding.clone()),
            topic: c.topic,
        })
        .collect();
    out.sort_by(|a, b| a.topic.cmp(&b.topic));
    Ok(out)
}

enum Decoder {
    Json,
    Cdr(Box<Ros2Schema>),
}

struct Plan {
    decoder: Decoder,
    sigs: Vec<usize>,
}

fn make_plan(channel: &mcap::Channel<'_>, sigs: Vec<usize>) -> Result<Plan, IoError> {
    let topic = &channel.topic;
    let unsupported = |encoding: String| IoError::UnsupportedEncoding {
        topic: topic.clone(),
        encoding,
    };
    let decoder = match channel.message_encoding.as_str() {
        "json" => Decoder::Json,
        "cdr" => match &channel.schema {
            Some(s) if s.encoding == "ros2msg" => {
                let text = std::str::from_utf8(&s.data).map_err(|_| IoError::BadSchema {
                    schema: s.name.clone(),
                    reason: "the ros2msg schema text is not UTF-8".into(),
                })?;
                Decoder::Cdr(Box::new(Ros2Schema::parse(&s.name, text)?))
            }
            Some(s) => return Err(unsupported(format!("cdr with a `{}` schema", s.encoding))),
            None => return Err(unsupported("cdr without a schema".into())),
        },
        "protobuf" => return Err(unsupported("protobuf".into())),
        other => return Err(unsupported(other.to_owned())),
    };
    Ok(Plan { decoder, sigs })
}

/// Path text up to and including element `at`.
fn prefix(path: &SignalPath, at: usize) -> String {
    let p = SignalPath {
        topic: path.topic.clone(),
        fields: path
            .fields
            .iter()
            .take(at.saturating_add(1))
            .cloned()
            .collect(),
    };
    p.to_string()
}

pub(crate) fn walk_err_pub(path: &SignalPath, t_ns: u64, e: WalkError) -> IoError {
    match e {
        WalkError::Missing { at, available } => IoError::MissingField {
            topic: path.topic.clone(),
            path: path.to_string(),
            missing: prefix(path, at),
            available,
        },
        WalkError::Decode(reason) => IoError::BadMessage {
            topic: path.topic.clone(),
            t_ns,
            reason,
        },
    }
}

/// Follows `path` in a JSON value.
pub(crate) fn json_get(v: &Value, path: &[PathElem]) -> Result<Leaf, WalkError> {
    let mut cur = v;
    for (i, e) in path.iter().enumerate() {
        cur = match (e, cur) {
            (PathElem::Field(name), Value::Object(m)) => match m.get(name) {
                Some(x) => x,
                None => {
                    return Err(WalkError::Missing {
                        at: i,
                        available: m.keys().cloned().collect(),
                    });
                }
            },
            (PathElem::Index(k), Value::Array(a)) => match resolve_index(*k, a.len()) {
                Some(j) => &a[j],
                None => {
                    return Err(WalkError::Missing {
                        at: i,
                        available: index_range(a.len()),
                    });
                }
            },
            (PathElem::Index(_), Value::Object(m)) => {
                return Err(WalkError::Missing {
                    at: i,
                    available: m.keys().cloned().collect(),
                });
            }
            (PathElem::Field(_), Value::Array(a)) => {
                return Err(WalkError::Missing {
                    at: i,
                    available: index_range(a.len()),
                });
            }
            (_, other) => {
                return Err(WalkError::Missing {
                    at: i,
                    available: vec![format!("(none: it is {})", json_leaf(other).describe())],
                });
            }
        };
    }
    Ok(json_leaf(cur))
}

fn json_leaf(v: &Value) -> Leaf {
    match v {
        Value::Null => Leaf::Null,
        Value::Bool(b) => Leaf::Num(if *b { 1.0 } else { 0.0 }),
        Value::Number(n) => Leaf::Num(n.as_f64().unwrap_or(f64::NAN)),
        Value::String(s) => Leaf::Str(s.clone()),
        Value::Array(a) => Leaf::Array(a.len()),
        Value::Object(m) => Leaf::Struct(m.keys().cloned().collect()),
    }
}

fn field(name: &str) -> PathElem {
    PathElem::Field(name.to_owned())
}

/// Builds a stamp from (sec, nanosec).
fn stamp(topic: &str, sec: i128, nsec: i128) -> Result<u64, IoError> {
    let bad = |reason: String| IoError::BadStamp {
        topic: topic.to_owned(),
        reason,
    };
    if !(0..1_000_000_000).contains(&nsec) {
        return Err(bad(format!("nanoseconds {nsec} out of range 0..1e9")));
    }
    let t = sec
        .checked_mul(1_000_000_000)
        .and_then(|s| s.checked_add(nsec))
        .ok_or_else(|| bad(format!("sec = {sec} overflows")))?;
    u64::try_from(t).map_err(|_| bad(format!("negative time sec = {sec}, nanosec = {nsec}")))
}

fn stamp_missing(topic: &str, e: WalkError, t_ns: u64) -> IoError {
    match e {
        WalkError::Missing { available, .. } => IoError::MissingField {
            topic: topic.to_owned(),
            path: format!("{topic}.header.stamp"),
            missing: "header.stamp.{sec,nanosec|nsec} (needed to read header stamps; read \
                      messages without a header with the log time: `--time-source log`, \
                      Python `time_source=\"log\"`)"
                .to_owned(),
            available,
        },
        WalkError::Decode(reason) => IoError::BadMessage {
            topic: topic.to_owned(),
            t_ns,
            reason,
        },
    }
}

fn json_int(v: &Value, path: &[PathElem]) -> Result<Option<i128>, WalkError> {
    match json_get(v, path)? {
        Leaf::Num(x) if x.fract() == 0.0 && x.abs() < 1e30 => Ok(Some(x as i128)),
        _ => Ok(None),
    }
}

fn header_stamp_json(topic: &str, v: &Value, t_ns: u64) -> Result<u64, IoError> {
    let base = [field("header"), field("stamp")];
    let sec_p = [base[0].clone(), base[1].clone(), field("sec")];
    let sec = json_int(v, &sec_p).map_err(|e| stamp_missing(topic, e, t_ns))?;
    let mut ns_p = sec_p.clone();
    ns_p[2] = field("nanosec");
    let nsec = match json_int(v, &ns_p) {
        Ok(n) => n,
        Err(_) => {
            ns_p[2] = field("nsec");
            json_int(v, &ns_p).map_err(|e| stamp_missing(topic, e, t_ns))?
        }
    };
    match (sec, nsec) {
        (Some(s), Some(n)) => stamp(topic, s, n),
        _ => Err(IoError::BadStamp {
            topic: topic.to_owned(),
            reason: "header.stamp.sec / nanosec are not integers".into(),
        }),
    }
}

fn header_stamp_cdr(
    topic: &str,
    w: &CdrWalker<'_>,
    data: &[u8],
    t_ns: u64,
) -> Result<u64, IoError> {
    let sec_p = [field("header"), field("stamp"), field("sec")];
    let sec = w
        .get_int(data, &sec_p)
        .map_err(|e| stamp_missing(topic, e, t_ns))?;
    let mut ns_p = sec_p.clone();
    ns_p[2] = field("nanosec");
    let nsec = match w.get_int(data, &ns_p) {
        Ok(n) => n,
        Err(_) => {
            ns_p[2] = field("nsec");
            w.get_int(data, &ns_p)
                .map_err(|e| stamp_missing(topic, e, t_ns))?
        }
    };
    match (sec, nsec) {
        (Some(s), Some(n)) => stamp(topic, s, n),
        _ => Err(IoError::BadStamp {
            topic: topic.to_owned(),
            reason: "header.stamp.sec / nanosec are not integers".into(),
        }),
    }
}

fn push_sample(sig: &mut RawSignal, t: u64, v: f64) -> Result<(), IoError> {
    if !v.is_finite() {
        return Err(IoError::NonFinite {
            path: sig.path.to_string(),
            t,
        });
    }
    match sig.t_ns.last() {
        Some(&prev) if t < prev => Err(IoError::TimeBackwards {
            path: sig.path.to_string(),
            t_prev: prev,
            t,
        }),
        Some(&prev) if t == prev => {
            if let Some(last) = sig.value.last_mut() {
                *last = v;
            }
            Ok(())
        }
        _ => {
            sig.t_ns.push(t);
            sig.value.push(v);
            Ok(())
        }
    }
}

pub(crate) fn leaf_value_pub(path: &SignalPath, leaf: Leaf) -> Result<f64, IoError> {
    match leaf {
        Leaf::Num(v) => Ok(v),
        other => Err(IoError::NonNumeric {
            path: path.to_string(),
            found: other.describe(),
        }),
    }
}

/// Reads every requested signal from one MCAP file in one pass over the messages.
///
/// Supports JSON messages (with a `jsonschema` schema or none) and ROS 2 CDR messages with
/// `ros2msg` schemas, in chunked or unchunked, compressed (zstd, lz4) or uncompressed, indexed
/// or unindexed files. Numbers and bools (0/1) are numeric. The result has one [`RawSignal`]
/// per requested path, in the same order; several paths may share a topic.
///
/// Errors: see [`IoError`]; in particular a requested topic absent from the log is
/// [`IoError::MissingTopic`] (listing the log's topics), a NaN / infinite sample is
/// [`IoError::NonFinite`] and decreasing times are [`IoError::TimeBackwards`] (equal times keep
/// the later value).
pub fn read_signals(
    file: &Path,
    signals: &[SignalPath],
    opts: &ReadOptions,
) -> Result<Vec<RawSignal>, IoError> {
    read_signals_observed(file, signals, opts, &mut |_| {})
}

/// [`read_signals`], reporting how many bytes have been read to `observe` (every 4096
/// messages, and once at the end with `done`). The caller renders it (the CLI draws a progress
/// bar); this crate prints nothing.
pub fn read_signals_observed(
    file: &Path,
    signals: &[SignalPath],
    opts: &ReadOptions,
    observe: &mut dyn FnMut(ReadProgress),
) -> Result<Vec<RawSignal>, IoError> {
    let (mut reader, len, count) = open(file)?;
    let mut out: Vec<RawSignal> = signals
        .iter()
        .map(|p| RawSignal {
            path: p.clone(),
            t_ns: Vec::new(),
            value: Vec::new(),
        })
        .collect();
    let mut by_topic: BTreeMap<&str, Vec<usize>> = BTreeMap::new();
    for (i, p) in signals.iter().enumerate() {
        by_topic.entry(p.topic.as_str()).or_default().push(i);
    }
    let mut plans: HashMap<u16, Option<Plan>> = HashMap::new();
    let mut progress = Progress {
        observe,
        count,
        total: len,
        n: 0,
    };

    while let Some(m) = next_message(file, &mut reader)? {
        progress.tick();
        let cid = m.channel.id;
        if let std::collections::hash_map::Entry::Vacant(slot) = plans.entry(cid) {
            let plan = match by_topic.get(m.channel.topic.as_str()) {
                Some(sigs) => Some(make_plan(&m.channel, sigs.clone())?),
                None => None,
            };
            slot.insert(plan);
        }
        let Some(Some(plan)) = plans.get(&cid) else {
            continue;
        };
        let topic = &m.channel.topic;
        let data: &[u8] = &m.data;
        match &plan.decoder {
            Decoder::Json => {
                let v: Value = serde_json::from_slice(data).map_err(|e| IoError::BadMessage {
                    topic: topic.clone(),
                    t_ns: m.log_time,
                    reason: format!("invalid JSON: {e}"),
                })?;
                let t = match opts.time_source {
                    TimeSource::LogTime => m.log_time,
                    TimeSource::HeaderStamp => header_stamp_json(topic, &v, m.log_time)?,
                };
                for &i in &plan.sigs {
                    let sig = &mut out[i];
                    let leaf = json_get(&v, &sig.path.fields)
                        .map_err(|e| walk_err_pub(&sig.path, m.log_time, e))?;
                    let x = leaf_value_pub(&sig.path, leaf)?;
                    push_sample(sig, t, x)?;
                }
            }
            Decoder::Cdr(schema) => {
                let w = CdrWalker::new(schema);
                let t = match opts.time_source {
                    TimeSource::LogTime => m.log_time,
                    TimeSource::HeaderStamp => header_stamp_cdr(topic, &w, data, m.log_time)?,
                };
                for &i in &plan.sigs {
                    let sig = &mut out[i];
                    let leaf = w
                        .get(data, &sig.path.fields)
                        .map_err(|e| walk_err_pub(&sig.path, m.log_time, e))?;
                    let x = leaf_value_pub(&sig.path, leaf)?;
                    push_sample(sig, t, x)?;
                }
            }
        }
    }
    progress.report(true);

    let available = topics_of(&reader);
    for p in signals {
        if !available.iter().any(|t| t == &p.topic) {
            return Err(IoError::MissingTopic {
                file: PathBuf::from(file),
                topic: p.topic.clone(),
                available,
            });
        }
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A Header record whose `library` string claims 2.3 GB in a 24-byte record (a case of the
    /// `mcap_ingest` fuzz target; read unchecked, it runs out of memory under libFuzzer): a
    /// short, plain error.
    #[test]
    fn a_string_longer_than_its_record_is_a_plain_error() {
        let file = Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("../../fuzz/regressions/mcap_ingest/oom-header-string-length-2GiB");
        let e = list_topics(&file).expect_err("corrupt");
        let msg = e.to_string();
        assert!(msg.contains("oom-header-string-length-2GiB"), "{msg}");
        assert!(msg.contains("not enough bytes"), "{msg}");
        assert!(
            !msg.contains('\u{1b}') && !msg.contains('\n') && !msg.contains("Backtrace"),
            "{msg}"
        );
    }

    #[test]
    fn plain_keeps_the_words_of_a_parse_backtrace() {
        let text = "Record parse failed: \n \u{1b}[1m\u{2501}\u{2501} Backtrace \u{2501}\u{2501}\u{1b}[0m\n\n 0: \u{1b}[1mError: not enough bytes in reader\u{1b}[22m\n     While parsing field 'inner' in McapString\n     at /x/records.rs:151\n 1: While parsing field 'library' in Header\n     at /x/records.rs:202\n";
        assert_eq!(
            plain(text),
            "Record parse failed: not enough bytes in reader; While parsing field 'inner' in \
             McapString; While parsing field 'library' in Header"
        );
        assert_eq!(plain("invalid magic"), "invalid magic");
    }
}
