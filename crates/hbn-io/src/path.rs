//! Foxglove-style message paths: `/topic.field.sub[2].x`.

use std::fmt;
use std::str::FromStr;

use crate::IoError;

/// Foxglove message path: `/topic.field.sub[2].x`; the topic may be quoted when it contains dots:
/// `"/a.b".field`.
///
/// Grammar: a topic (unquoted: everything up to the first `.` or `[`; or a double-quoted string
/// with `\"` and `\\` escapes), then any number of `.field` (a name without `.`, `[`, `]`, `"`,
/// `{`, `}` or whitespace, or a quoted string) and `[i]` (an integer index, negative counts from
/// the end). Filters (`{..}`) and slices (`[a:b]`) are not supported.
#[derive(Clone, Debug, PartialEq, Eq, Hash, serde::Serialize, serde::Deserialize)]
pub struct SignalPath {
    /// The topic, without quotes.
    pub topic: String,
    /// The fields and indices inside the message.
    pub fields: Vec<PathElem>,
}

/// One step of a [`SignalPath`] inside a message.
#[derive(Clone, Debug, PartialEq, Eq, Hash, serde::Serialize, serde::Deserialize)]
pub enum PathElem {
    /// A named field of a message / object.
    Field(String),
    /// An array index; negative counts from the end (`-1` is the last element).
    Index(i64),
}

impl SignalPath {
    /// A path `topic.f1.f2...` of plain fields.
    pub fn new(topic: &str, fields: &[&str]) -> Self {
        SignalPath {
            topic: topic.to_owned(),
            fields: fields
                .iter()
                .map(|f| PathElem::Field((*f).to_owned()))
                .collect(),
        }
    }

    /// The path of the fields only (`field.sub[2].x`), without the topic; empty for a bare topic.
    pub fn field_string(&self) -> String {
        let mut s = String::new();
        write_elems(&mut s, &self.fields);
        s.trim_start_matches('.').to_owned()
    }
}

fn needs_quotes(s: &str) -> bool {
    s.is_empty()
        || s.chars()
            .any(|c| matches!(c, '.' | '[' | ']' | '"' | '\\' | '{' | '}') || c.is_whitespace())
}

fn write_name(out: &mut String, s: &str) {
    if needs_quotes(s) {
        out.push('"');
        for c in s.chars() {
            if c == '"' || c == '\\' {
                out.push('\\');
            }
            out.push(c);
        }
        out.push('"');
    } else {
        out.push_str(s);
    }
}

fn write_elems(out: &mut String, elems: &[PathElem]) {
    for e in elems {
        match e {
            PathElem::Field(f) => {
                out.push('.');
                write_name(out, f);
            }
            PathElem::Index(i) => {
                out.push_str(&format!("[{i}]"));
            }
        }
    }
}

impl fmt::Display for SignalPath {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let mut s = String::new();
        write_name(&mut s, &self.topic);
        write_elems(&mut s, &self.fields);
        f.write_str(&s)
    }
}

impl fmt::Display for PathElem {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            PathElem::Field(name) => {
                let mut s = String::new();
                write_name(&mut s, name);
                f.write_str(&s)
            }
            PathElem::Index(i) => write!(f, "[{i}]"),
        }
    }
}

struct Parser<'a> {
    text: &'a str,
    chars: Vec<char>,
    pos: usize,
}

impl Parser<'_> {
    fn err(&self, reason: impl Into<String>) -> IoError {
        IoError::BadPath {
            path: self.text.to_owned(),
            reason: reason.into(),
        }
    }

    fn peek(&self) -> Option<char> {
        self.chars.get(self.pos).copied()
    }

    /// Parses a quoted string starting at the opening quote.
    fn quoted(&mut self) -> Result<String, IoError> {
        let start = self.pos;
        self.pos += 1;
        let mut s = String::new();
        loop {
            match self.peek() {
                None => {
                    return Err(self.err(format!(
                        "the quote opened at character {} is never closed",
                        start + 1
                    )));
                }
                Some('"') => {
                    self.pos += 1;
                    return Ok(s);
                }
                Some('\\') => {
                    self.pos += 1;
                    match self.peek() {
                        Some(c) => {
                            s.push(c);
                            self.pos += 1;
                        }
                        None => return Err(self.err("the path ends inside an escape (`\\`)")),
                    }
                }
                Some(c) => {
                    s.push(c);
                    self.pos += 1;
                }
            }
        }
    }

    /// Parses an unquoted name up to `.` / `[` / end.
    fn bare(&mut self, what: &str) -> Result<String, IoError> {
        let mut s = String::new();
        while let Some(c) = self.peek() {
            match c {
                '.' | '[' => break,
                ']' => return Err(self.err(format!("unexpected `]` in {what} `{s}`"))),
                '"' => {
                    return Err(self.err(format!(
                        "unexpected `\"` in {what} `{s}`; quote the whole {what}"
                    )));
                }
                '{' | '}' => {
                    return Err(self.err("filters (`{..}`) are not supported"));
                }
                c if c.is_whitespace() => {
                    return Err(self.err(format!(
                        "whitespace in {what} `{s}`; quote it if it is really part of the name"
                    )));
                }
                c => {
                    s.push(c);
                    self.pos += 1;
                }
            }
        }
        if s.is_empty() {
            return Err(self.err(format!("empty {what}")));
        }
        Ok(s)
    }

    fn name(&mut self, what: &str) -> Result<String, IoError> {
        if self.peek() == Some('"') {
            self.quoted()
        } else {
            self.bare(what)
        }
    }

    fn index(&mut self) -> Result<i64, IoError> {
        // at '['
        self.pos += 1;
        let mut s = String::new();
        loop {
            match self.peek() {
                None => return Err(self.err("`[` is never closed with `]`")),
                Some(']') => {
                    self.pos += 1;
                    break;
                }
                Some(c) => {
                    s.push(c);
                    self.pos += 1;
                }
            }
        }
        let t = s.trim();
        if t.contains(':') {
            return Err(self.err(format!("slices (`[{t}]`) are not supported; use one index")));
        }
        t.parse::<i64>().map_err(|_| {
            self.err(format!(
                "`[{s}]` is not an integer index (use e.g. [0], or [-1] for the last element)"
            ))
        })
    }
}

impl FromStr for SignalPath {
    type Err = IoError;

    fn from_str(text: &str) -> Result<Self, IoError> {
        let mut p = Parser {
            text,
            chars: text.chars().collect(),
            pos: 0,
        };
        if text.trim().is_empty() {
            return Err(p.err("the path is empty"));
        }
        let topic = p.name("topic")?;
        let mut fields = Vec::new();
        while let Some(c) = p.peek() {
            match c {
                '.' => {
                    p.pos += 1;
                    if p.peek().is_none() {
                        return Err(p.err("the path ends with `.`; name a field after it"));
                    }
                    fields.push(PathElem::Field(p.name("field")?));
                }
                '[' => fields.push(PathElem::Index(p.index()?)),
                c => {
                    return Err(p.err(format!(
                        "unexpected `{c}` at character {}; separate fields with `.`",
                        p.pos + 1
                    )));
                }
            }
        }
        Ok(SignalPath { topic, fields })
    }
}
