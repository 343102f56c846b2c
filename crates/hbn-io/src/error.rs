//! The error type of every fallible function in this crate.

use std::path::PathBuf;

/// Formats a list of names for an error message, shortening very long lists.
pub(crate) fn list(names: &[String]) -> String {
    const MAX: usize = 40;
    if names.is_empty() {
        return "(none)".to_owned();
    }
    let mut s = names
        .iter()
        .take(MAX)
        .map(String::as_str)
        .collect::<Vec<_>>()
        .join(", ");
    if names.len() > MAX {
        s.push_str(&format!(", ... ({} more)", names.len() - MAX));
    }
    s
}

fn secs(t_ns: u64) -> f64 {
    t_ns as f64 * 1e-9
}

/// Where a gap starts, in words: seconds after the start of the signals' common time span, or
/// before it (a gap that begins before every signal has started).
fn gap_start(at_s: f64) -> String {
    if at_s >= 0.0 {
        format!("starting {at_s:.3} s after the start of the signals' common time span")
    } else {
        format!(
            "starting {:.3} s before the signals' common time span begins",
            -at_s
        )
    }
}

/// Everything that can go wrong reading, resampling or writing logs.
///
/// Every message names the file, topic or field involved and says what would fix it.
/// Times `t`, `t_prev` are in nanoseconds on the clock the signal was read with
/// ([`crate::TimeSource`]); `at_s` and `gap_s` are seconds.
#[derive(Debug, thiserror::Error)]
pub enum IoError {
    /// The file could not be opened, read, created or renamed.
    #[error("cannot {op} `{}`: {source}; check that the path exists and is accessible", file.display())]
    Open {
        /// The file.
        file: PathBuf,
        /// What was being done ("open", "read", "write", ...).
        op: &'static str,
        /// The OS error.
        #[source]
        source: std::io::Error,
    },
    /// The file is not a valid MCAP file (wrong magic, truncated, corrupt record or chunk).
    #[error(
        "`{}` is not a readable MCAP file: {reason}; the file may be truncated or corrupt \
         (try `mcap doctor` / `mcap recover`) or not be an MCAP log at all",
        file.display()
    )]
    Corrupt {
        /// The file.
        file: PathBuf,
        /// What the MCAP reader reported.
        reason: String,
    },
    /// A requested topic is not in the log.
    #[error(
        "topic `{topic}` is not in `{}`; available topics: {}; fix the signal path's topic \
         (quote topics containing dots: \"/a.b\".field)",
        file.display(), list(available)
    )]
    MissingTopic {
        /// The file.
        file: PathBuf,
        /// The requested topic.
        topic: String,
        /// Topics the log has.
        available: Vec<String>,
    },
    /// A requested field is not in a message.
    #[error(
        "`{path}`: topic `{topic}` has no `{missing}` there; fields available at that level: {}; \
         fix the signal path",
        list(available)
    )]
    MissingField {
        /// The topic.
        topic: String,
        /// The full signal path that was requested.
        path: String,
        /// The path element that was not found (`field` or `[i]`), with the path up to it.
        missing: String,
        /// The fields (or index range) present at that level.
        available: Vec<String>,
    },
    /// The value at a path is not a number or bool.
    #[error("`{path}` is not numeric (found {found}); point the path at a number or bool field")]
    NonNumeric {
        /// The signal path.
        path: String,
        /// What was found instead.
        found: String,
    },
    /// A sample is NaN or infinite.
    #[error(
        "`{path}` has a non-finite value (NaN or infinity) at t = {} s ({t} ns); \
         clean the log or choose another signal", secs(*t)
    )]
    NonFinite {
        /// The signal path (or topic when writing).
        path: String,
        /// The sample time in nanoseconds.
        t: u64,
    },
    /// A signal's times decrease.
    #[error(
        "`{path}` goes back in time from t = {} s to t = {} s ({t_prev} ns -> {t} ns); \
         if the header stamps are unreliable read with the log time (`--time-source log`, \
         Python `time_source=\"log\"`), or sort the log", secs(*t_prev), secs(*t)
    )]
    TimeBackwards {
        /// The signal path.
        path: String,
        /// The previous sample time (ns).
        t_prev: u64,
        /// The offending sample time (ns).
        t: u64,
    },
    /// A gap between consecutive samples inside the resampling window is too long.
    #[error(
        "`{path}` has a gap of {gap_s:.3} s {}, longer than the largest gap allowed \
         ({max_gap_s} s); raise it (`--max-gap`, Python `max_gap_s=`) or cut the log around the gap",
        gap_start(*at_s)
    )]
    Gap {
        /// The signal path.
        path: String,
        /// Start of the gap, seconds since the aligned grid's t0 (may be negative).
        at_s: f64,
        /// Length of the gap in seconds.
        gap_s: f64,
        /// The allowed maximum.
        max_gap_s: f64,
    },
    /// The signals' time spans do not overlap.
    #[error(
        "the signals' time spans do not overlap ({spans}); choose signals recorded at the same time"
    )]
    NoOverlap {
        /// Each signal's span, for the message.
        spans: String,
    },
    /// Too few samples to resample or estimate a rate.
    #[error(
        "`{what}` has {n} samples, at least {need} are needed; use a longer log or a higher rate"
    )]
    TooFewSamples {
        /// The signal path (or "aligned grid").
        what: String,
        /// Number of samples found.
        n: usize,
        /// Number needed.
        need: usize,
    },
    /// A topic's message or schema encoding is not supported.
    #[error(
        "topic `{topic}` uses encoding `{encoding}`, which hbn cannot decode; supported: \
         `json` messages and `cdr` messages with `ros2msg` schemas (protobuf, ros1 and ros2idl are \
         not supported yet): re-record or convert the topic"
    )]
    UnsupportedEncoding {
        /// The topic.
        topic: String,
        /// The encoding (message encoding / schema encoding).
        encoding: String,
    },
    /// A schema could not be parsed or resolved.
    #[error("schema `{schema}` cannot be used: {reason}; fix the message definition in the log")]
    BadSchema {
        /// The schema name.
        schema: String,
        /// What is wrong.
        reason: String,
    },
    /// A message could not be decoded.
    #[error(
        "a message on topic `{topic}` at log time {} s cannot be decoded: {reason}; \
         the log may be corrupt or its schema may not match the data", secs(*t_ns)
    )]
    BadMessage {
        /// The topic.
        topic: String,
        /// Log time of the message (ns).
        t_ns: u64,
        /// What is wrong.
        reason: String,
    },
    /// A message's `header.stamp` is not a valid time.
    #[error(
        "topic `{topic}`: header.stamp is invalid ({reason}); read with the log time \
         (`--time-source log`, Python `time_source=\"log\"`) instead"
    )]
    BadStamp {
        /// The topic.
        topic: String,
        /// What is wrong.
        reason: String,
    },
    /// A signal path is malformed.
    #[error(
        "bad signal path `{path}`: {reason}; expected `/topic.field.sub[2].x` \
         (quote topics containing dots: \"/a.b\".field)"
    )]
    BadPath {
        /// The text given.
        path: String,
        /// What is wrong.
        reason: String,
    },
    /// An option has an invalid value.
    #[error("bad option {name} = {value}: {requirement}")]
    BadOption {
        /// Option name (`rate_hz`, `max_gap_s`).
        name: &'static str,
        /// The value given.
        value: f64,
        /// What is required.
        requirement: &'static str,
    },
    /// The grid would have more points than hbn resamples to.
    #[error(
        "{span_s:.3} s of overlap at {rate_hz} Hz gives more than 1e9 grid points; lower the rate"
    )]
    GridTooLarge {
        /// Seconds the signals overlap.
        span_s: f64,
        /// The requested rate.
        rate_hz: f64,
    },
    /// Inputs to a writer are inconsistent.
    #[error("cannot write `{}`: {reason}", file.display())]
    InvalidInput {
        /// The file that was to be written.
        file: PathBuf,
        /// What is wrong.
        reason: String,
    },
}

impl From<hbn_fs::WriteError> for IoError {
    fn from(e: hbn_fs::WriteError) -> Self {
        IoError::Open {
            file: e.path,
            op: e.op,
            source: e.source,
        }
    }
}
