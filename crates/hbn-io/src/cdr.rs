//! Dynamic CDR (XCDR1, as written by ROS 2 Fast-DDS / Cyclone and `mcap-ros2-support`) decoding
//! guided by a [`Ros2Schema`]: walks a message to the value at a path, skipping everything
//! before it. Never allocates according to lengths read from the data.

use crate::path::PathElem;
use crate::ros2msg::{ArrayKind, FieldType, Prim, Ros2Schema};

/// What a path points at.
#[derive(Clone, Debug, PartialEq)]
pub(crate) enum Leaf {
    /// A number (bools are 0/1).
    Num(f64),
    /// A string.
    Str(String),
    /// A nested message / object with these fields.
    Struct(Vec<String>),
    /// An array of this length.
    Array(usize),
    /// A JSON null.
    Null,
}

impl Leaf {
    /// Describes a non-numeric leaf for [`crate::IoError::NonNumeric`].
    pub(crate) fn describe(&self) -> String {
        match self {
            Leaf::Num(v) => format!("the number {v}"),
            Leaf::Str(s) => {
                let short: String = s.chars().take(40).collect();
                format!("a string \"{short}\"")
            }
            Leaf::Struct(f) => format!("a message with fields [{}]", f.join(", ")),
            Leaf::Array(n) => format!("an array of {n} elements; index it, e.g. [0]"),
            Leaf::Null => "null".to_owned(),
        }
    }
}

/// Why a walk failed.
#[derive(Clone, Debug, PartialEq)]
pub(crate) enum WalkError {
    /// `path[at]` does not exist; `available` lists what exists at that level.
    Missing {
        /// Index of the missing element in the path.
        at: usize,
        /// What exists there.
        available: Vec<String>,
    },
    /// The bytes do not decode.
    Decode(String),
}

pub(crate) fn index_range(n: usize) -> Vec<String> {
    if n == 0 {
        vec!["(empty array)".to_owned()]
    } else {
        vec![format!("[0]..[{}] (or [-1]..[-{n}])", n - 1)]
    }
}

/// Resolves a possibly negative index against a length.
pub(crate) fn resolve_index(i: i64, n: usize) -> Option<usize> {
    let n_i = i64::try_from(n).ok()?;
    let j = if i < 0 { n_i.checked_add(i)? } else { i };
    if j >= 0 && j < n_i {
        usize::try_from(j).ok()
    } else {
        None
    }
}

struct Cursor<'a> {
    buf: &'a [u8],
    pos: usize,
    le: bool,
    max_align: usize,
}

fn eof(what: &str) -> WalkError {
    WalkError::Decode(format!("message ends in the middle of {what}"))
}

impl<'a> Cursor<'a> {
    fn align(&mut self, n: usize) -> Result<(), WalkError> {
        let n = n.min(self.max_align);
        if n > 1 {
            let rem = self.pos % n;
            if rem != 0 {
                self.pos = self
                    .pos
                    .checked_add(n - rem)
                    .ok_or_else(|| eof("padding"))?;
            }
        }
        if self.pos > self.buf.len() {
            return Err(eof("padding"));
        }
        Ok(())
    }

    fn take(&mut self, n: usize, what: &str) -> Result<&'a [u8], WalkError> {
        let end = self.pos.checked_add(n).ok_or_else(|| eof(what))?;
        let s = self.buf.get(self.pos..end).ok_or_else(|| eof(what))?;
        self.pos = end;
        Ok(s)
    }

    fn advance(&mut self, n: usize, what: &str) -> Result<(), WalkError> {
        let end = self.pos.checked_add(n).ok_or_else(|| eof(what))?;
        if end > self.buf.len() {
            return Err(eof(what));
        }
        self.pos = end;
        Ok(())
    }

    fn bytes<const N: usize>(&mut self, what: &str) -> Result<[u8; N], WalkError> {
        self.align(N)?;
        let s = self.take(N, what)?;
        let mut a = [0u8; N];
        a.copy_from_slice(s);
        if !self.le {
            a.reverse();
        }
        // `a` is now little-endian
        Ok(a)
    }

    fn u32(&mut self, what: &str) -> Result<u32, WalkError> {
        Ok(u32::from_le_bytes(self.bytes::<4>(what)?))
    }

    fn len(&mut self, what: &str) -> Result<usize, WalkError> {
        let n = self.u32(what)?;
        usize::try_from(n).map_err(|_| WalkError::Decode(format!("length {n} too large")))
    }

    fn read_prim(&mut self, p: Prim) -> Result<Leaf, WalkError> {
        let w = p.name();
        Ok(match p {
            Prim::Bool => Leaf::Num(if self.take(1, w)?[0] != 0 { 1.0 } else { 0.0 }),
            Prim::Byte | Prim::U8 | Prim::Char => Leaf::Num(f64::from(self.take(1, w)?[0])),
            Prim::I8 => Leaf::Num(f64::from(self.take(1, w)?[0] as i8)),
            Prim::I16 => Leaf::Num(f64::from(i16::from_le_bytes(self.bytes::<2>(w)?))),
            Prim::U16 => Leaf::Num(f64::from(u16::from_le_bytes(self.bytes::<2>(w)?))),
            Prim::I32 => Leaf::Num(f64::from(i32::from_le_bytes(self.bytes::<4>(w)?))),
            Prim::U32 => Leaf::Num(f64::from(u32::from_le_bytes(self.bytes::<4>(w)?))),
            Prim::I64 => Leaf::Num(i64::from_le_bytes(self.bytes::<8>(w)?) as f64),
            Prim::U64 => Leaf::Num(u64::from_le_bytes(self.bytes::<8>(w)?) as f64),
            Prim::F32 => Leaf::Num(f64::from(f32::from_le_bytes(self.bytes::<4>(w)?))),
            Prim::F64 => Leaf::Num(f64::from_le_bytes(self.bytes::<8>(w)?)),
            Prim::String => {
                let n = self.len("a string length")?;
                let s = self.take(n, "a string")?;
                let s = s.strip_suffix(&[0]).unwrap_or(s);
                Leaf::Str(String::from_utf8_lossy(s).into_owned())
            }
            Prim::WString => return Err(wstring()),
        })
    }

    /// Reads the exact integer value of an integer primitive (for time stamps).
    fn read_int(&mut self, p: Prim) -> Result<Option<i128>, WalkError> {
        let w = p.name();
        Ok(Some(match p {
            Prim::Byte | Prim::U8 | Prim::Char => i128::from(self.take(1, w)?[0]),
            Prim::I8 => i128::from(self.take(1, w)?[0] as i8),
            Prim::I16 => i128::from(i16::from_le_bytes(self.bytes::<2>(w)?)),
            Prim::U16 => i128::from(u16::from_le_bytes(self.bytes::<2>(w)?)),
            Prim::I32 => i128::from(i32::from_le_bytes(self.bytes::<4>(w)?)),
            Prim::U32 => i128::from(u32::from_le_bytes(self.bytes::<4>(w)?)),
            Prim::I64 => i128::from(i64::from_le_bytes(self.bytes::<8>(w)?)),
            Prim::U64 => i128::from(u64::from_le_bytes(self.bytes::<8>(w)?)),
            _ => return Ok(None),
        }))
    }

    fn skip_prims(&mut self, p: Prim, n: usize) -> Result<(), WalkError> {
        if n == 0 {
            return Ok(());
        }
        match p.size() {
            Some(sz) => {
                self.align(sz)?;
                let total = sz
                    .checked_mul(n)
                    .ok_or_else(|| eof("an array of primitives"))?;
                self.advance(total, p.name())
            }
            None => {
                if p == Prim::WString {
                    return Err(wstring());
                }
                for _ in 0..n {
                    let len = self.len("a string length")?;
                    self.advance(len, "a string")?;
                }
                Ok(())
            }
        }
    }
}

fn wstring() -> WalkError {
    WalkError::Decode("wstring fields are not supported".to_owned())
}

/// Walks CDR-encoded messages of one schema.
pub(crate) struct CdrWalker<'s> {
    schema: &'s Ros2Schema,
}

impl<'s> CdrWalker<'s> {
    pub(crate) fn new(schema: &'s Ros2Schema) -> Self {
        CdrWalker { schema }
    }

    fn cursor<'a>(&self, data: &'a [u8]) -> Result<Cursor<'a>, WalkError> {
        let Some(hdr) = data.get(..4) else {
            return Err(WalkError::Decode(format!(
                "{} bytes is shorter than the 4-byte CDR encapsulation header",
                data.len()
            )));
        };
        let (le, max_align) = match (hdr[0], hdr[1]) {
            (0, 0) => (false, 8),
            (0, 1) => (true, 8),
            // XCDR2 plain: 8-byte types are aligned to 4.
            (0, 6) => (false, 4),
            (0, 7) => (true, 4),
            (a, b) => {
                return Err(WalkError::Decode(format!(
                    "unsupported CDR encapsulation {a:#04x} {b:#04x} (only plain CDR_LE/CDR_BE \
                     and plain XCDR2 are supported)"
                )));
            }
        };
        Ok(Cursor {
            buf: &data[4..],
            pos: 0,
            le,
            max_align,
        })
    }

    /// Returns the value at `path` in the message `data`.
    pub(crate) fn get(&self, data: &[u8], path: &[PathElem]) -> Result<Leaf, WalkError> {
        let mut c = self.cursor(data)?;
        self.walk_struct(&mut c, self.schema.root, path, 0, 0)
    }

    /// Returns the integer at `path` exactly (for stamps); None if it is not an integer field.
    pub(crate) fn get_int(
        &self,
        data: &[u8],
        path: &[PathElem],
    ) -> Result<Option<i128>, WalkError> {
        let mut c = self.cursor(data)?;
        self.walk_struct_int(&mut c, self.schema.root, path, 0)
    }

    fn fields_of(&self, ty: usize) -> Vec<String> {
        self.schema
            .types
            .get(ty)
            .map(|t| t.fields.iter().map(|f| f.name.clone()).collect())
            .unwrap_or_default()
    }

    fn skip_value(&self, c: &mut Cursor<'_>, ty: FieldType, depth: usize) -> Result<(), WalkError> {
        match ty {
            FieldType::Prim(p) => c.skip_prims(p, 1),
            FieldType::Msg(t) => self.skip_struct(c, t, depth + 1),
        }
    }

    fn skip_struct(&self, c: &mut Cursor<'_>, ty: usize, depth: usize) -> Result<(), WalkError> {
        if depth > 128 {
            return Err(WalkError::Decode("types nested too deeply".into()));
        }
        let Some(t) = self.schema.types.get(ty) else {
            return Err(WalkError::Decode("bad type index".into()));
        };
        for f in &t.fields {
            let n = match f.array {
                ArrayKind::Single => {
                    self.skip_value(c, f.ty, depth)?;
                    continue;
                }
                ArrayKind::Fixed(n) => n,
                ArrayKind::Bounded(_) | ArrayKind::Unbounded => c.len("an array length")?,
            };
            self.skip_elems(c, f.ty, n, depth)?;
        }
        Ok(())
    }

    fn skip_elems(
        &self,
        c: &mut Cursor<'_>,
        ty: FieldType,
        n: usize,
        depth: usize,
    ) -> Result<(), WalkError> {
        match ty {
            FieldType::Prim(p) => c.skip_prims(p, n),
            FieldType::Msg(t) => {
                // Each element consumes at least 0 bytes; an empty struct would loop `n` times
                // without progress, so stop once the data is exhausted and n is absurd.
                for _ in 0..n {
                    let before = c.pos;
                    self.skip_struct(c, t, depth + 1)?;
                    if c.pos == before {
                        // empty struct: nothing more to skip
                        break;
                    }
                }
                Ok(())
            }
        }
    }

    /// Finds field `path[i]` of struct `ty`, skipping the fields before it, and returns it with
    /// `c` positioned at the field's data.
    fn find_field(
        &self,
        c: &mut Cursor<'_>,
        ty: usize,
        path: &[PathElem],
        i: usize,
        depth: usize,
    ) -> Result<&'s crate::ros2msg::Field, WalkError> {
        let Some(t) = self.schema.types.get(ty) else {
            return Err(WalkError::Decode("bad type index".into()));
        };
        let name = match path.get(i) {
            Some(PathElem::Field(name)) => name,
            Some(PathElem::Index(_)) | None => {
                return Err(WalkError::Missing {
                    at: i,
                    available: self.fields_of(ty),
                });
            }
        };
        for f in &t.fields {
            if &f.name == name {
                return Ok(f);
            }
            match f.array {
                ArrayKind::Single => self.skip_value(c, f.ty, depth)?,
                ArrayKind::Fixed(n) => self.skip_elems(c, f.ty, n, depth)?,
                _ => {
                    let n = c.len("an array length")?;
                    self.skip_elems(c, f.ty, n, depth)?
                }
            }
        }
        Err(WalkError::Missing {
            at: i,
            available: self.fields_of(ty),
        })
    }

    /// Positions `c` at array element `path[i]` of array field `f`; returns `Some(n)` (the
    /// element count) when the path ends at the array itself.
    fn enter_array(
        &self,
        c: &mut Cursor<'_>,
        f: &crate::ros2msg::Field,
        path: &[PathElem],
        i: usize,
        depth: usize,
    ) -> Result<Option<usize>, WalkError> {
        let n = match f.array {
            ArrayKind::Single => return Ok(None),
            ArrayKind::Fixed(n) => n,
            _ => c.len("an array length")?,
        };
        match path.get(i) {
            None => Ok(Some(n)),
            Some(PathElem::Index(k)) => match resolve_index(*k, n) {
                Some(k) => {
                    self.skip_elems(c, f.ty, k, depth)?;
                    Ok(None)
                }
                None => Err(WalkError::Missing {
                    at: i,
                    available: index_range(n),
                }),
            },
            Some(PathElem::Field(_)) => Err(WalkError::Missing {
                at: i,
                available: index_range(n),
            }),
        }
    }

    fn walk_struct(
        &self,
        c: &mut Cursor<'_>,
        ty: usize,
        path: &[PathElem],
        i: usize,
        depth: usize,
    ) -> Result<Leaf, WalkError> {
        if i >= path.len() {
            return Ok(Leaf::Struct(self.fields_of(ty)));
        }
        let f = self.find_field(c, ty, path, i, depth)?;
        let mut j = i + 1;
        if f.array != ArrayKind::Single {
            if let Some(n) = self.enter_array(c, f, path, j, depth)? {
                return Ok(Leaf::Array(n));
            }
            j += 1;
        }
        match f.ty {
            FieldType::Prim(p) => {
                if j < path.len() {
                    return Err(WalkError::Missing {
                        at: j,
                        available: vec![format!("(none: it is a {})", p.name())],
                    });
                }
                c.read_prim(p)
            }
            FieldType::Msg(t) => self.walk_struct(c, t, path, j, depth + 1),
        }
    }

    fn walk_struct_int(
        &self,
        c: &mut Cursor<'_>,
        ty: usize,
        path: &[PathElem],
        depth: usize,
    ) -> Result<Option<i128>, WalkError> {
        // Stamp paths contain plain fields only.
        let f = self.find_field(c, ty, path, 0, depth)?;
        if f.array != ArrayKind::Single {
            return Ok(None);
        }
        match f.ty {
            FieldType::Prim(p) if path.len() == 1 => c.read_int(p),
            FieldType::Prim(_) => Ok(None),
            FieldType::Msg(t) if path.len() > 1 => {
                self.walk_struct_int(c, t, &path[1..], depth + 1)
            }
            FieldType::Msg(_) => Ok(None),
        }
    }
}
