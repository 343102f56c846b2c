//! Parser for ROS 2 `.msg` schemas as stored in MCAP (`ros2msg` schema encoding): the main
//! definition, then `MSG: pkg/Type` sections separated by lines of `=`.

use std::collections::HashMap;

use crate::IoError;

/// A primitive ROS 2 type.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Prim {
    /// `bool` (1 byte).
    Bool,
    /// `byte` (1 byte, unsigned).
    Byte,
    /// `char` (1 byte).
    Char,
    /// `int8`.
    I8,
    /// `uint8`.
    U8,
    /// `int16`.
    I16,
    /// `uint16`.
    U16,
    /// `int32`.
    I32,
    /// `uint32`.
    U32,
    /// `int64`.
    I64,
    /// `uint64`.
    U64,
    /// `float32`.
    F32,
    /// `float64`.
    F64,
    /// `string` (possibly bounded).
    String,
    /// `wstring` (rejected when a message walk reaches it).
    WString,
}

impl Prim {
    fn parse(s: &str) -> Option<Prim> {
        Some(match s {
            "bool" => Prim::Bool,
            "byte" => Prim::Byte,
            "char" => Prim::Char,
            "int8" => Prim::I8,
            "uint8" => Prim::U8,
            "int16" => Prim::I16,
            "uint16" => Prim::U16,
            "int32" => Prim::I32,
            "uint32" => Prim::U32,
            "int64" => Prim::I64,
            "uint64" => Prim::U64,
            "float32" => Prim::F32,
            "float64" => Prim::F64,
            "string" => Prim::String,
            "wstring" => Prim::WString,
            _ => return None,
        })
    }

    /// Size in bytes of a fixed-size primitive (None for strings).
    pub fn size(self) -> Option<usize> {
        Some(match self {
            Prim::Bool | Prim::Byte | Prim::Char | Prim::I8 | Prim::U8 => 1,
            Prim::I16 | Prim::U16 => 2,
            Prim::I32 | Prim::U32 | Prim::F32 => 4,
            Prim::I64 | Prim::U64 | Prim::F64 => 8,
            Prim::String | Prim::WString => return None,
        })
    }

    /// The ROS name of the type.
    pub fn name(self) -> &'static str {
        match self {
            Prim::Bool => "bool",
            Prim::Byte => "byte",
            Prim::Char => "char",
            Prim::I8 => "int8",
            Prim::U8 => "uint8",
            Prim::I16 => "int16",
            Prim::U16 => "uint16",
            Prim::I32 => "int32",
            Prim::U32 => "uint32",
            Prim::I64 => "int64",
            Prim::U64 => "uint64",
            Prim::F32 => "float32",
            Prim::F64 => "float64",
            Prim::String => "string",
            Prim::WString => "wstring",
        }
    }
}

/// The element type of a field.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum FieldType {
    /// A primitive.
    Prim(Prim),
    /// A message type: index into [`Ros2Schema::types`].
    Msg(usize),
}

/// Whether (and how) a field is an array.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ArrayKind {
    /// A single value.
    Single,
    /// `T[N]`: no length prefix.
    Fixed(usize),
    /// `T[<=N]`: length-prefixed like `T[]`.
    Bounded(usize),
    /// `T[]`: length-prefixed.
    Unbounded,
}

/// One field of a message type.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Field {
    /// Field name.
    pub name: String,
    /// Element type.
    pub ty: FieldType,
    /// Array kind.
    pub array: ArrayKind,
}

/// One message type.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct MsgType {
    /// Full name `pkg/Type`.
    pub name: String,
    /// Fields in order (constants removed).
    pub fields: Vec<Field>,
}

/// A parsed, fully resolved ROS 2 message definition.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Ros2Schema {
    /// All types; `types[root]` is the message itself.
    pub types: Vec<MsgType>,
    /// Index of the top-level type.
    pub root: usize,
}

/// Maximum nesting depth of message types (guards against hostile schemas).
const MAX_DEPTH: usize = 64;

const BUILTIN_TIME: &str = "int32 sec\nuint32 nanosec\n";
const BUILTIN_HEADER: &str = "builtin_interfaces/Time stamp\nstring frame_id\n";

fn normalize(name: &str) -> String {
    // `pkg/msg/Type` -> `pkg/Type`
    let parts: Vec<&str> = name.split('/').collect();
    if parts.len() == 3 {
        format!("{}/{}", parts[0], parts[2])
    } else {
        name.to_owned()
    }
}

fn package_of(name: &str) -> &str {
    name.split('/').next().unwrap_or("")
}

fn short_of(name: &str) -> &str {
    name.rsplit('/').next().unwrap_or(name)
}

fn is_separator(line: &str) -> bool {
    let t = line.trim();
    t.len() >= 3 && t.chars().all(|c| c == '=')
}

/// A field as written, before type resolution.
struct RawField {
    name: String,
    base: String,
    array: ArrayKind,
}

fn parse_fields(text: &str, schema: &str, type_name: &str) -> Result<Vec<RawField>, IoError> {
    let bad = |reason: String| IoError::BadSchema {
        schema: schema.to_owned(),
        reason: format!("in `{type_name}`: {reason}"),
    };
    let mut out = Vec::new();
    for raw_line in text.lines() {
        let line = raw_line.trim();
        if line.is_empty() || line.starts_with('#') {
            continue;
        }
        let (ty, rest) = match line.split_once(char::is_whitespace) {
            Some((t, r)) => (t, r.trim_start()),
            None => return Err(bad(format!("line `{line}` has a type but no field name"))),
        };
        let name_end = rest
            .find(|c: char| !(c.is_alphanumeric() || c == '_'))
            .unwrap_or(rest.len());
        let name = &rest[..name_end];
        let after = rest[name_end..].trim_start();
        if name.is_empty() {
            return Err(bad(format!("line `{line}` has no valid field name")));
        }
        if after.starts_with('=') {
            continue; // constant
        }
        // Anything else after the name is a default value or a comment: ignored.
        let (base, array) = if let Some(open) = ty.find('[') {
            let Some(inner) = ty[open + 1..].strip_suffix(']') else {
                return Err(bad(format!("malformed array type `{ty}`")));
            };
            let array = if inner.is_empty() {
                ArrayKind::Unbounded
            } else if let Some(n) = inner.strip_prefix("<=") {
                ArrayKind::Bounded(
                    n.trim()
                        .parse()
                        .map_err(|_| bad(format!("bad array bound in `{ty}`")))?,
                )
            } else {
                ArrayKind::Fixed(
                    inner
                        .trim()
                        .parse()
                        .map_err(|_| bad(format!("bad array size in `{ty}`")))?,
                )
            };
            (&ty[..open], array)
        } else {
            (ty, ArrayKind::Single)
        };
        // bounded strings: string<=N
        let base = match base.split_once("<=") {
            Some((b, n)) if b == "string" || b == "wstring" => {
                if n.parse::<usize>().is_err() {
                    return Err(bad(format!("bad string bound in `{ty}`")));
                }
                b
            }
            _ => base,
        };
        if base.is_empty() {
            return Err(bad(format!("empty type in line `{line}`")));
        }
        out.push(RawField {
            name: name.to_owned(),
            base: base.to_owned(),
            array,
        });
    }
    Ok(out)
}

impl Ros2Schema {
    /// Parses a `ros2msg` schema named `name` (e.g. `pkg/msg/Type`) from its text.
    pub fn parse(name: &str, text: &str) -> Result<Ros2Schema, IoError> {
        let bad = |reason: String| IoError::BadSchema {
            schema: name.to_owned(),
            reason,
        };
        let root_name = normalize(name);
        // Split into sections.
        let mut sections: Vec<(String, String)> = Vec::new();
        let mut cur_name = root_name.clone();
        let mut cur_text = String::new();
        let mut in_header = false; // just after a separator, waiting for `MSG:`
        for line in text.lines() {
            if is_separator(line) {
                sections.push((std::mem::take(&mut cur_name), std::mem::take(&mut cur_text)));
                in_header = true;
                continue;
            }
            if in_header {
                let t = line.trim();
                if t.is_empty() || t.starts_with('#') {
                    continue;
                }
                match t.strip_prefix("MSG:") {
                    Some(n) => {
                        cur_name = normalize(n.trim());
                        in_header = false;
                        continue;
                    }
                    None => {
                        return Err(bad(format!(
                            "a section after a `===` separator must start with `MSG: pkg/Type`, \
                             found `{t}`"
                        )));
                    }
                }
            }
            cur_text.push_str(line);
            cur_text.push('\n');
        }
        if in_header {
            return Err(bad(
                "the schema ends with a separator but no `MSG:` section".into(),
            ));
        }
        sections.push((cur_name, cur_text));

        let mut texts: HashMap<String, String> = HashMap::new();
        for (n, t) in sections.iter().skip(1) {
            texts.entry(n.clone()).or_insert_with(|| t.clone());
        }
        let root_text = sections.first().map(|(_, t)| t.clone()).unwrap_or_default();

        let mut b = Builder {
            schema: name,
            texts,
            types: Vec::new(),
            index: HashMap::new(),
            in_progress: Vec::new(),
        };
        let root = b.build(&root_name, &root_text)?;
        Ok(Ros2Schema {
            types: b.types,
            root,
        })
    }

    /// The root type.
    pub fn root_type(&self) -> Option<&MsgType> {
        self.types.get(self.root)
    }
}

struct Builder<'a> {
    schema: &'a str,
    texts: HashMap<String, String>,
    types: Vec<MsgType>,
    index: HashMap<String, usize>,
    in_progress: Vec<String>,
}

impl Builder<'_> {
    fn bad(&self, reason: String) -> IoError {
        IoError::BadSchema {
            schema: self.schema.to_owned(),
            reason,
        }
    }

    /// Resolves a referenced type name to a full name and its text.
    fn lookup(&self, base: &str, current_pkg: &str) -> Option<(String, String)> {
        let candidates: Vec<String> = if base == "Header" {
            vec!["std_msgs/Header".into()]
        } else if base == "time" {
            vec!["builtin_interfaces/Time".into()]
        } else if base == "duration" {
            vec!["builtin_interfaces/Duration".into()]
        } else if base.contains('/') {
            vec![normalize(base)]
        } else {
            vec![format!("{current_pkg}/{base}")]
        };
        for c in &candidates {
            if let Some(t) = self.texts.get(c) {
                return Some((c.clone(), t.clone()));
            }
        }
        // Unqualified name defined under another package: accept a unique short-name match.
        if !base.contains('/') {
            let matches: Vec<&String> = self.texts.keys().filter(|k| short_of(k) == base).collect();
            if let [only] = matches.as_slice() {
                return self.texts.get(*only).map(|t| ((*only).clone(), t.clone()));
            }
        }
        for c in &candidates {
            match c.as_str() {
                "builtin_interfaces/Time" | "builtin_interfaces/Duration" => {
                    return Some((c.clone(), BUILTIN_TIME.to_owned()));
                }
                "std_msgs/Header" => return Some((c.clone(), BUILTIN_HEADER.to_owned())),
                _ => {}
            }
        }
        None
    }

    fn build(&mut self, name: &str, text: &str) -> Result<usize, IoError> {
        if let Some(&i) = self.index.get(name) {
            return Ok(i);
        }
        if self.in_progress.iter().any(|n| n == name) {
            return Err(self.bad(format!(
                "type `{name}` contains itself ({} -> {name})",
                self.in_progress.join(" -> ")
            )));
        }
        if self.in_progress.len() >= MAX_DEPTH {
            return Err(self.bad(format!("types are nested deeper than {MAX_DEPTH} levels")));
        }
        self.in_progress.push(name.to_owned());
        let raw = parse_fields(text, self.schema, name)?;
        let pkg = package_of(name).to_owned();
        let mut fields = Vec::with_capacity(raw.len());
        for f in raw {
            let ty = match Prim::parse(&f.base) {
                Some(p) => FieldType::Prim(p),
                None => {
                    let Some((full, t)) = self.lookup(&f.base, &pkg) else {
                        return Err(self.bad(format!(
                            "field `{}` of `{name}` has type `{}`, which is neither a primitive nor \
                             defined in the schema (add a `MSG: {}` section)",
                            f.name,
                            f.base,
                            if f.base.contains('/') {
                                normalize(&f.base)
                            } else {
                                format!("{pkg}/{}", f.base)
                            }
                        )));
                    };
                    FieldType::Msg(self.build(&full, &t)?)
                }
            };
            fields.push(Field {
                name: f.name,
                ty,
                array: f.array,
            });
        }
        self.in_progress.pop();
        let idx = self.types.len();
        self.types.push(MsgType {
            name: name.to_owned(),
            fields,
        });
        self.index.insert(name.to_owned(), idx);
        Ok(idx)
    }
}
