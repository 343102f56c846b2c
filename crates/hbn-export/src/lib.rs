//! # hbn-export
//!
//! Turns a trained [`HysteresisModel`] into firmware source: the model's constant tables
//! ([`hbn_core::tables`]) as
//!
//! - [`Format::Rust`]: one file, `hbn_model.rs`, of `static` arrays and a function returning
//!   the model view, to `include!` into a `no_std` crate that depends on `hbn-core`;
//! - [`Format::C`]: `hbn_model.h` / `hbn_model.c`, the arrays as `const` data and an
//!   `HbnModelData` for the C ABI of the `hbn-ffi` static library (`hbn.h`).
//!
//! The tables are encoded from the loaded model's view (the exact GP's Cholesky factor is
//! recomputed at load, never read from the file), so the step on the tables is the step of
//! `hbn estimate`: bit for bit with [`Precision::F64`]. [`Precision::F32`] halves the real
//! numbers' size; the firmware widens them into `f64` work memory at start.
//!
//! [`size_report`] gives, per mode, the bytes of model data (flash) and of work memory (RAM).
//!
//! ```
//! use hbn_export::{Format, Precision, export};
//! use hbn_model::{HysteresisModel, HbnParams, Sequence};
//! # let u: Vec<f64> = (0..300).map(|k| (k as f64 * 0.05).sin()).collect();
//! # let x: Vec<f64> = u.iter().map(|v| 0.8 * v).collect();
//! # let y: Vec<f64> = x.iter().map(|v| v + 0.1 * v * v).collect();
//! let params = HbnParams { n_inducing: Some(16), n_starts: 1, ..HbnParams::default() };
//! let model = HysteresisModel::fit(&[Sequence::new(&u, &x, &y)], &params)?;
//! let files = export(&model, model.default_mode(), Format::C, Precision::F32, None, "model.hbn")?;
//! assert_eq!(files.iter().map(|f| f.name).collect::<Vec<_>>(), ["hbn_model.h", "hbn_model.c"]);
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```
#![forbid(unsafe_code)]
#![deny(missing_docs)]
#![cfg_attr(
    not(test),
    deny(clippy::unwrap_used, clippy::expect_used, clippy::panic)
)]

use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use hbn_core::tables::{self, TableSink, Tables};
use hbn_core::{CoreError, EkfConfig, Estimator, HbnView, InitPrior, Mode};
use hbn_model::{HysteresisModel, ModelError};

mod vector;
pub use vector::{
    VECTOR_MODES, export_vector, vector_f32_variance_errors, vector_factors_in_two_parts,
    vector_model_tables, vector_size_report, vector_size_table,
};

/// What the exported source is for.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Format {
    /// `hbn_model.rs`, for `include!` into a `no_std` Rust crate.
    Rust,
    /// `hbn_model.h` and `hbn_model.c`, for the `hbn-ffi` static library.
    C,
}

impl Format {
    /// `rust` or `c`.
    pub const fn name(self) -> &'static str {
        match self {
            Format::Rust => "rust",
            Format::C => "c",
        }
    }
}

/// How real numbers are stored in the tables.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Default)]
pub enum Precision {
    /// `f64`: the step reproduces `hbn estimate` bit for bit.
    #[default]
    F64,
    /// `f32`: half the model data; widened to `f64` in work memory at start.
    F32,
}

impl Precision {
    /// `f64` or `f32`.
    pub const fn name(self) -> &'static str {
        match self {
            Precision::F64 => "f64",
            Precision::F32 => "f32",
        }
    }

    /// Bytes per real number.
    pub const fn bytes(self) -> usize {
        match self {
            Precision::F64 => 8,
            Precision::F32 => 4,
        }
    }
}

/// Why an export failed.
#[derive(Debug, thiserror::Error)]
pub enum ExportError {
    /// The model's view or settings could not be built.
    #[error(transparent)]
    Model(#[from] ModelError),
    /// The tables could not be encoded, or do not read back (e.g. after rounding to `f32`).
    #[error("the {mode} model does not export as {precision} tables: {source}")]
    Tables {
        /// The mode exported.
        mode: Mode,
        /// The precision asked for.
        precision: &'static str,
        /// What the core reported.
        #[source]
        source: CoreError,
    },
    /// The tables' layout does not read (tables built by hand, not by [`ModelTables::encode`]).
    #[error("the model tables' layout is corrupt: {0}")]
    Layout(#[source] CoreError),
    /// A real number does not fit in `f32` (it would become infinite).
    #[error("the model holds {value:e}, which f32 cannot represent: export with --precision f64")]
    F32Range {
        /// The value.
        value: f64,
    },
    /// The output directory could not be created.
    #[error("cannot create the output directory {path}: {source}")]
    CreateDir {
        /// The directory.
        path: PathBuf,
        /// The OS error.
        #[source]
        source: std::io::Error,
    },
    /// `--out` exists and is not a directory.
    #[error("{path} is not a directory: give --out a directory (new or existing)")]
    NotADirectory {
        /// The path.
        path: PathBuf,
    },
    /// Writing a file failed (the files written before it were removed again).
    #[error(transparent)]
    Write(#[from] hbn_fs::WriteError),
}

/// A model's constant tables, as the exporter holds them (`f64` reals).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct ModelTables {
    /// Structural integers ([`Tables::layout`]).
    pub layout: Vec<u32>,
    /// Cell keys ([`Tables::keys`]).
    pub keys: Vec<u64>,
    /// Real numbers ([`Tables::reals`]).
    pub reals: Vec<f64>,
}

impl TableSink for ModelTables {
    fn int(&mut self, v: u32) {
        self.layout.push(v);
    }
    fn key(&mut self, v: u64) {
        self.keys.push(v);
    }
    fn real(&mut self, v: f64) {
        self.reals.push(v);
    }
}

pub use hbn_model::firmware::{
    F32_VARIANCE_TOLERANCE, f32_variance_error, f32_variance_errors, factors_in_two_parts,
};

impl ModelTables {
    /// Encodes `view` with `config` ([`tables::encode_with`]), the variance factors that
    /// [`factors_in_two_parts`] names in the split ranges.
    pub fn encode(view: &HbnView<'_>, config: &EkfConfig) -> Result<Self, CoreError> {
        Self::encode_with(view, config, factors_in_two_parts(view))
    }

    /// Encodes `view` with `config`, the variance factors named by `split_factors`
    /// (transition, sensor) in the split ranges ([`tables::encode_with`]).
    pub fn encode_with(
        view: &HbnView<'_>,
        config: &EkfConfig,
        split_factors: [bool; 2],
    ) -> Result<Self, CoreError> {
        let mut t = Self::default();
        tables::encode_with(view, config, split_factors, &mut t)?;
        Ok(t)
    }

    /// The borrowed form the core reads.
    pub fn tables(&self) -> Tables<'_> {
        Tables {
            layout: &self.layout,
            keys: &self.keys,
            reals: &self.reals,
        }
    }

    /// The reals as an `f32` export stores them: each rounded to `f32`, then the low parts
    /// (`v - f32(v)`, rounded) of the reals in the split ranges ([`tables::split_ranges`]), in
    /// order. Fails on a value outside `f32`'s range.
    pub fn reals_f32(&self) -> Result<Vec<f32>, ExportError> {
        let split = tables::split_ranges(&self.layout).map_err(ExportError::Layout)?;
        let to_f32 = |v: f64| {
            let s = v as f32;
            if s.is_finite() {
                Ok(s)
            } else {
                Err(ExportError::F32Range { value: v })
            }
        };
        let high = self.reals.iter().map(|&v| to_f32(v));
        let low = split.iter().flat_map(|range| {
            self.reals
                .get(range)
                .unwrap_or_default()
                .iter()
                .map(|&v| to_f32(tables::split_f32(v).1))
        });
        high.chain(low).collect()
    }

    /// Bytes of the three arrays with reals stored at `precision` (an `f32` export holds the
    /// low parts of the split ranges too).
    pub fn bytes(&self, precision: Precision) -> usize {
        let reals = match precision {
            Precision::F64 => self.reals.len(),
            Precision::F32 => {
                self.reals.len() + tables::split_ranges(&self.layout).map_or(0, |s| s.total())
            }
        };
        4 * self.layout.len() + 8 * self.keys.len() + precision.bytes() * reals
    }
}

/// The tables of `model` in `mode`, with the model's tuned settings of that mode
/// ([`HysteresisModel::ekf_config`]).
pub fn model_tables(model: &HysteresisModel, mode: Mode) -> Result<ModelTables, ExportError> {
    let view = model.view()?;
    let config = model.ekf_config(mode);
    encode(&view, &config, factors_in_two_parts(&view), Precision::F64)
}

fn encode(
    view: &HbnView<'_>,
    config: &EkfConfig,
    split_factors: [bool; 2],
    precision: Precision,
) -> Result<ModelTables, ExportError> {
    ModelTables::encode_with(view, config, split_factors).map_err(|source| ExportError::Tables {
        mode: config.mode,
        precision: precision.name(),
        source,
    })
}

/// The tables at `precision`, checked to read back into a valid view (`f32` rounding can in
/// principle break a check, e.g. a factor's positive diagonal).
fn checked(
    t: &ModelTables,
    mode: Mode,
    precision: Precision,
) -> Result<Option<Vec<f32>>, ExportError> {
    let err = |source| ExportError::Tables {
        mode,
        precision: precision.name(),
        source,
    };
    match precision {
        Precision::F64 => {
            t.tables().model().map_err(err)?;
            Ok(None)
        }
        Precision::F32 => {
            let r32 = t.reals_f32()?;
            let mut wide = vec![0.0; tables::widen_scratch(&t.layout, r32.len()).map_err(err)?];
            let reals = tables::widen(&t.layout, &r32, &mut wide).map_err(err)?;
            Tables {
                layout: &t.layout,
                keys: &t.keys,
                reals,
            }
            .model()
            .map_err(err)?;
            Ok(Some(r32))
        }
    }
}

/// The prior of `x_0` as exported: the training `(y, x)` pairs, thinned.
struct InitTable {
    pairs: Vec<[f64; 2]>,
    neighbours: usize,
    var_floor: f64,
}

/// The view's prior of `x_0` with at most `keep` pairs (`None`: all of them; `Some(0)`: no
/// prior). Thinning keeps evenly spaced pairs of the `y`-sorted table and scales the number of
/// neighbours averaged by the same factor, so the prior spans about the same range of `y`.
fn init_table(view: &HbnView<'_>, keep: Option<usize>) -> Option<InitTable> {
    let init = view.init?;
    let pairs = init.pairs();
    let n = pairs.len();
    let keep = keep.unwrap_or(n).min(n);
    if keep == 0 {
        return None;
    }
    let picked = (0..keep)
        .filter_map(|i| pairs.get((2 * i + 1) * n / (2 * keep)))
        .copied()
        .collect();
    let neighbours = if keep == n {
        init.neighbours()
    } else {
        ((init.neighbours() * keep + n / 2) / n).max(1)
    };
    Some(InitTable {
        pairs: picked,
        neighbours,
        var_floor: init.var_floor(),
    })
}

/// `view` with the prior of `x_0` replaced by `table`.
fn with_init<'a>(
    view: HbnView<'a>,
    table: &'a Option<InitTable>,
) -> Result<HbnView<'a>, CoreError> {
    let init = match table {
        Some(t) => Some(InitPrior::new(&t.pairs, t.neighbours, t.var_floor)?),
        None => None,
    };
    Ok(HbnView { init, ..view })
}

/// Sizes of one mode's export (see [`size_report`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct ModeSize {
    /// The mode.
    pub mode: Mode,
    /// The precision of the reals.
    pub precision: Precision,
    /// Bytes of the two GPs and the filter settings (part of `model_bytes`).
    pub gp_bytes: usize,
    /// Bytes of the prior of `x_0`: the training `(y, x)` pairs (part of `model_bytes`).
    pub init_bytes: usize,
    /// Bytes of the local training data (EKF+BLR only; part of `model_bytes`).
    pub local_bytes: usize,
    /// All model data: the constant tables (flash).
    pub model_bytes: usize,
    /// Work memory for widening `f32` reals to `f64` (RAM; 0 for `f64`).
    pub widen_bytes: usize,
    /// Scratch memory of the step (RAM).
    pub scratch_bytes: usize,
}

impl ModeSize {
    /// RAM the caller provides: widened reals and the step's scratch (the filter's own state,
    /// `HbnFilter` in C, comes on top).
    pub fn work_bytes(&self) -> usize {
        self.widen_bytes + self.scratch_bytes
    }
}

/// Bytes of model data and work memory of every mode at `precision`, with at most
/// `init_pairs` pairs in the prior of `x_0` (as [`export`]).
pub fn size_report(
    model: &HysteresisModel,
    precision: Precision,
    init_pairs: Option<usize>,
) -> Result<Vec<ModeSize>, ExportError> {
    let view = model.view()?;
    let table = init_table(&view, init_pairs);
    let view = with_init(view, &table).map_err(|source| ExportError::Tables {
        mode: model.default_mode(),
        precision: precision.name(),
        source,
    })?;
    let scratch_bytes = 8 * Estimator::scratch_len(&view);
    let bare = HbnView { init: None, ..view };
    let split = factors_in_two_parts(&view);
    Mode::ALL
        .into_iter()
        .map(|mode| {
            let config = model.ekf_config(mode);
            let tables = encode(&view, &config, split, precision)?;
            let full = tables.bytes(precision);
            let without_init = encode(&bare, &config, split, precision)?.bytes(precision);
            let gp_config = model.ekf_config(Mode::Ekf);
            let gp_only = encode(&bare, &gp_config, split, precision)?.bytes(precision);
            let reals = tables.reals.len();
            Ok(ModeSize {
                mode,
                precision,
                gp_bytes: gp_only,
                init_bytes: full - without_init,
                local_bytes: without_init - gp_only,
                model_bytes: full,
                widen_bytes: match precision {
                    Precision::F64 => 0,
                    // One widened value per real of the f64 tables.
                    Precision::F32 => 8 * reals,
                },
                scratch_bytes,
            })
        })
        .collect()
}

/// The size report as a table: one row per mode (`*` marks `default`).
pub fn size_table(sizes: &[ModeSize], default: Mode) -> String {
    let mut s = String::new();
    let kb = |b: usize| format!("{:.1} KB", b as f64 / 1024.0);
    let _ = writeln!(
        s,
        "{:<10} {:>4} {:>10} {:>10} {:>10} {:>10} {:>10} {:>10}",
        "mode", "real", "model", "GPs", "x0 prior", "BLR data", "widen", "scratch"
    );
    for m in sizes {
        let star = if m.mode == default { "*" } else { "" };
        let _ = writeln!(
            s,
            "{:<10} {:>4} {:>10} {:>10} {:>10} {:>10} {:>10} {:>10}",
            format!("{}{star}", m.mode),
            m.precision.name(),
            kb(m.model_bytes),
            kb(m.gp_bytes),
            kb(m.init_bytes),
            kb(m.local_bytes),
            kb(m.widen_bytes),
            kb(m.scratch_bytes),
        );
    }
    let _ = writeln!(
        s,
        "model = constant data (flash) = GPs and settings + x0 prior + BLR data; widen + scratch = work memory (RAM); * the model's default mode"
    );
    s
}

/// One generated file.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct GeneratedFile {
    /// File name (no directory).
    pub name: &'static str,
    /// Its text.
    pub text: String,
}

/// Generates the source of `model` in `mode` (what [`write()`] writes). `init_pairs` keeps at
/// most that many training `(y, x)` pairs for the prior of `x_0` (`None`: all, and the export
/// reproduces `hbn estimate` exactly; `Some(0)`: no prior, the filter starts from the training
/// mean; fewer pairs change the first estimates only). `origin` (e.g. the model file) is named
/// in the generated header comment.
pub fn export(
    model: &HysteresisModel,
    mode: Mode,
    format: Format,
    precision: Precision,
    init_pairs: Option<usize>,
    origin: &str,
) -> Result<Vec<GeneratedFile>, ExportError> {
    let view = model.view()?;
    let config = model.ekf_config(mode);
    let table = init_table(&view, init_pairs);
    let view = with_init(view, &table).map_err(|source| ExportError::Tables {
        mode,
        precision: precision.name(),
        source,
    })?;
    let t = encode(&view, &config, factors_in_two_parts(&view), precision)?;
    let r32 = checked(&t, mode, precision)?;
    let scratch = tables::scratch_len(&t.layout).map_err(|source| ExportError::Tables {
        mode,
        precision: precision.name(),
        source,
    })?;
    let info = Info {
        origin,
        mode,
        precision,
        scratch,
        widen: match precision {
            Precision::F64 => 0,
            // One widened value per real of the f64 tables.
            Precision::F32 => t.reals.len(),
        },
        reals: r32.as_ref().map_or(t.reals.len(), Vec::len),
        kind: [view.transition.is_sparse(), view.sensor.is_sparse()],
        points: [view.transition.len(), view.sensor.len()],
        bytes: t.bytes(precision),
    };
    Ok(match format {
        Format::Rust => vec![GeneratedFile {
            name: "hbn_model.rs",
            text: rust_source(&t, r32.as_deref(), &info),
        }],
        Format::C => vec![
            GeneratedFile {
                name: "hbn_model.h",
                text: c_header(&t, &info),
            },
            GeneratedFile {
                name: "hbn_model.c",
                text: c_source(&t, r32.as_deref(), &info.describe()),
            },
        ],
    })
}

struct Info<'a> {
    origin: &'a str,
    mode: Mode,
    precision: Precision,
    scratch: usize,
    widen: usize,
    /// Reals stored (an `f32` export adds the low parts of the split ranges).
    reals: usize,
    kind: [bool; 2],
    points: [usize; 2],
    bytes: usize,
}

impl Info<'_> {
    fn describe(&self) -> String {
        let kind = |sparse: bool, n: usize| {
            if sparse {
                format!("sparse GP, {n} inducing points")
            } else {
                format!("exact GP, {n} support points")
            }
        };
        format!(
            "hbn model exported by `hbn export` from {}\nmode {}, {} reals, {} bytes of model data\ntransition: {}; sensor: {}\nGenerated file: do not edit; export the model again instead.",
            self.origin.replace("*/", "* /"),
            self.mode,
            self.precision.name(),
            self.bytes,
            kind(self.kind[0], self.points[0]),
            kind(self.kind[1], self.points[1]),
        )
    }
}

/// Shortest round-trip text of an `f64` (Rust's `{:?}`), valid in Rust and C.
fn f64_text(v: f64) -> String {
    format!("{v:?}")
}

fn f32_text(v: f32) -> String {
    format!("{v:?}")
}

fn list<T>(items: &[T], per_line: usize, indent: &str, text: impl Fn(&T) -> String) -> String {
    let mut s = String::new();
    for chunk in items.chunks(per_line.max(1)) {
        s.push_str(indent);
        let parts: Vec<String> = chunk.iter().map(&text).collect();
        s.push_str(&parts.join(", "));
        s.push_str(",\n");
    }
    s
}

fn rust_source(t: &ModelTables, r32: Option<&[f32]>, info: &Info<'_>) -> String {
    let mut s = String::new();
    for line in info.describe().lines() {
        let _ = writeln!(s, "// {line}");
    }
    let (real, reals) = match r32 {
        Some(r) => ("f32", list(r, 6, "    ", |v| f32_text(*v))),
        None => ("f64", list(&t.reals, 4, "    ", |v| f64_text(*v))),
    };
    let _ = write!(
        s,
        r#"
/// The estimation mode the tables were exported for.
pub const HBN_MODE: &str = "{mode}";
/// `f64` values of work memory [`hbn_model`] needs: the widened reals (0 for an `f64` export).
pub const HBN_WIDEN_LEN: usize = {widen};
/// `f64` values of scratch memory the step needs (`hbn_core::Estimator::scratch_len`).
pub const HBN_SCRATCH_LEN: usize = {scratch};

/// Structural integers of the model (`hbn_core::tables`).
pub static HBN_LAYOUT: [u32; {nl}] = [
{layout}];

/// Cell keys of the local regression (EKF+BLR only).
pub static HBN_KEYS: [u64; {nk}] = [
{keys}];

/// Real numbers of the model.
pub static HBN_REALS: [{real}; {nr}] = [
{reals}];

/// The model view and filter settings over the tables above, checked once. `work` must hold
/// [`HBN_WIDEN_LEN`] values (it may be empty for an `f64` export); the view borrows it.
#[allow(dead_code)]
pub fn hbn_model(
    work: &mut [f64],
) -> Result<hbn_core::tables::TableModel<'_>, hbn_core::CoreError> {{
{body}
}}
"#,
        mode = info.mode,
        widen = info.widen,
        scratch = info.scratch,
        nl = t.layout.len(),
        layout = list(&t.layout, 8, "    ", |v| v.to_string()),
        nk = t.keys.len(),
        keys = list(&t.keys, 4, "    ", |v| v.to_string()),
        nr = info.reals,
        body = match r32 {
            Some(_) =>
                "    let reals = hbn_core::tables::widen(&HBN_LAYOUT, &HBN_REALS, work)?;
    hbn_core::tables::Tables {
        layout: &HBN_LAYOUT,
        keys: &HBN_KEYS,
        reals,
    }
    .model()",
            None =>
                "    let _ = work;
    hbn_core::tables::Tables {
        layout: &HBN_LAYOUT,
        keys: &HBN_KEYS,
        reals: &HBN_REALS,
    }
    .model()",
        },
    );
    s
}

fn c_comment(info: &Info<'_>) -> String {
    c_comment_text(&info.describe())
}

/// `describe` as a C block comment.
fn c_comment_text(describe: &str) -> String {
    let mut s = String::from("/*\n");
    for line in describe.lines() {
        let _ = writeln!(s, " * {line}");
    }
    s.push_str(" */\n");
    s
}

fn c_header(t: &ModelTables, info: &Info<'_>) -> String {
    let real = match info.precision {
        Precision::F64 => "double",
        Precision::F32 => "float",
    };
    format!(
        r#"{comment}#ifndef HBN_MODEL_H
#define HBN_MODEL_H

#include <stdint.h>
#include "hbn.h"

#ifdef __cplusplus
extern "C" {{
#endif

/* The estimation mode the tables were exported for. */
#define HBN_MODEL_MODE "{mode}"
/* Precision of the real numbers: 64 (double) or 32 (float). */
#define HBN_MODEL_REAL_BITS {bits}
#define HBN_MODEL_LAYOUT_LEN {nl}u
#define HBN_MODEL_KEYS_LEN {nk}u
#define HBN_MODEL_REALS_LEN {nr}u
/* Doubles of work memory hbn_filter_init needs (hbn_work_len(&hbn_model) at run time). */
#define HBN_MODEL_WORK_LEN {work}u

extern const uint32_t hbn_model_layout[];
extern const uint64_t hbn_model_keys[];
extern const {real} hbn_model_reals[];

/* The model for hbn_filter_init. */
extern const HbnModelData hbn_model;

#ifdef __cplusplus
}}
#endif

#endif /* HBN_MODEL_H */
"#,
        comment = c_comment(info),
        mode = info.mode,
        bits = 8 * info.precision.bytes(),
        nl = t.layout.len(),
        nk = t.keys.len(),
        nr = info.reals,
        work = info.widen + info.scratch,
    )
}

/// `hbn_model.c`: the tables as `const` data and `hbn_model`, headed by `describe`.
fn c_source(t: &ModelTables, r32: Option<&[f32]>, describe: &str) -> String {
    let reals_len = r32.map_or(t.reals.len(), <[f32]>::len);
    // C has no empty arrays: an empty table gets one unused element (its length stays 0).
    let keys = if t.keys.is_empty() {
        "    0,\n".to_owned()
    } else {
        list(&t.keys, 4, "    ", |v| format!("{v}u"))
    };
    let (real, reals, f64_ptr, f32_ptr) = match r32 {
        Some(r) => (
            "float",
            list(r, 6, "    ", |v| {
                let t = f32_text(*v);
                format!("{t}f")
            }),
            "NULL",
            "hbn_model_reals",
        ),
        None => (
            "double",
            list(&t.reals, 4, "    ", |v| f64_text(*v)),
            "hbn_model_reals",
            "NULL",
        ),
    };
    format!(
        r#"{comment}#include <stddef.h>
#include <stdint.h>
#include "hbn_model.h"

const uint32_t hbn_model_layout[{nl}] = {{
{layout}}};

const uint64_t hbn_model_keys[{nk_alloc}] = {{
{keys}}};

const {real} hbn_model_reals[{nr}] = {{
{reals}}};

const HbnModelData hbn_model = {{
    hbn_model_layout, {nl}u,
    hbn_model_keys, {nk}u,
    {f64_ptr}, {f32_ptr}, {nr}u,
}};
"#,
        comment = c_comment_text(describe),
        nl = t.layout.len(),
        layout = list(&t.layout, 8, "    ", |v| format!("{v}u")),
        nk_alloc = t.keys.len().max(1),
        nk = t.keys.len(),
        nr = reals_len,
    )
}

/// Writes `files` into `dir` (created if missing), each atomically through `hbn-fs`. If one
/// write fails, the files this call wrote before it are removed again, so a failed export
/// leaves no new file behind.
pub fn write(dir: &Path, files: &[GeneratedFile]) -> Result<Vec<PathBuf>, ExportError> {
    if dir.exists() && !dir.is_dir() {
        return Err(ExportError::NotADirectory {
            path: dir.to_owned(),
        });
    }
    let created_dir = !dir.exists();
    if created_dir {
        std::fs::create_dir_all(dir).map_err(|source| ExportError::CreateDir {
            path: dir.to_owned(),
            source,
        })?;
    }
    let mut written: Vec<(PathBuf, bool)> = Vec::new();
    for f in files {
        let path = dir.join(f.name);
        let existed = path.exists();
        if let Err(e) = hbn_fs::write_atomic(&path, f.text.as_bytes()) {
            for (p, existed) in &written {
                if !existed {
                    let _ = std::fs::remove_file(p);
                }
            }
            if created_dir {
                let _ = std::fs::remove_dir(dir);
            }
            return Err(e.into());
        }
        written.push((path, existed));
    }
    Ok(written.into_iter().map(|(p, _)| p).collect())
}

#[cfg(test)]
mod tests {
    use super::*;
    use hbn_model::{HbnParams, Sequence};
    use hbn_sim::{SimConfig, SystemKind, simulate_random};

    /// The f32 tables of `t` as a firmware reads them: rounded to f32, widened back to f64.
    fn widened(t: &ModelTables) -> Vec<f64> {
        let r32 = t.reals_f32().unwrap();
        let mut wide = vec![0.0; tables::widen_scratch(&t.layout, r32.len()).unwrap()];
        tables::widen(&t.layout, &r32, &mut wide).unwrap();
        wide
    }

    /// The model a firmware reads from `t`'s layout and keys with the widened reals `wide`.
    fn read_widened<'a>(t: &'a ModelTables, wide: &'a [f64]) -> tables::TableModel<'a> {
        Tables {
            reals: wide,
            ..t.tables()
        }
        .model()
        .unwrap()
    }

    fn model(inducing: Option<usize>) -> HysteresisModel {
        model_with(inducing, hbn_model::SensorInputs::Thesis)
    }

    /// [`model`] with the sensor's inputs (no model selection of them).
    fn model_with(
        inducing: Option<usize>,
        sensor_inputs: hbn_model::SensorInputs,
    ) -> HysteresisModel {
        let cfg = SimConfig {
            noise_gain: 1.0,
            ..SimConfig::new(SystemKind::BoucWen)
        };
        let log = simulate_random(&cfg, 400).unwrap();
        let params = HbnParams {
            max_points: 80,
            n_inducing: inducing,
            n_starts: 1,
            max_iters: 40,
            sensor_inputs,
            ..HbnParams::default()
        };
        let mut params = params;
        params.select.sensor_inputs.clear();
        HysteresisModel::fit(&[Sequence::new(&log.u, &log.x, &log.y)], &params).unwrap()
    }

    /// The step on the f64 tables equals the model's own estimate bit for bit, every mode,
    /// exact and sparse, with the thesis' sensor, a sensor of the state only and a sensor with
    /// memory of the state; the f32 tables read back (how close they stay depends on the model's
    /// conditioning: `f32_tables_stay_close` and tests/firmware.rs measure it on trained
    /// models; this small one is poorly conditioned).
    #[test]
    fn tables_reproduce_the_model() {
        let test = simulate_random(
            &SimConfig {
                noise_gain: 1.0,
                seed: 9,
                ..SimConfig::new(SystemKind::BoucWen)
            },
            300,
        )
        .unwrap();
        let state = model_with(None, hbn_model::SensorInputs::State);
        assert_eq!(state.sensor().kernel().dim, 2);
        let memory = model_with(Some(16), hbn_model::SensorInputs::Memory);
        assert_eq!(memory.sensor_memory().unwrap().len(), 2);
        for m in [model(None), model(Some(16)), state, memory] {
            for mode in Mode::ALL {
                let est = m.estimate(&test.u, &test.y, mode).unwrap();
                let t = model_tables(&m, mode).unwrap();
                let tm = t.tables().model().unwrap();
                assert_eq!(tm.config, m.ekf_config(mode));
                assert_eq!(tm.view.sensor_memory, m.sensor_memory().unwrap());
                let mut scratch = vec![0.0; tables::scratch_len(&t.layout).unwrap()];
                let mut e = Estimator::new(tm.view, tm.config, &mut scratch).unwrap();
                for (k, (&u, &y)) in test.u.iter().zip(&test.y).enumerate() {
                    let o = e.step(u, y);
                    assert_eq!(o.x.to_bits(), est.x[k].to_bits(), "{mode} k={k}");
                    assert_eq!(o.x_std.to_bits(), est.x_std[k].to_bits(), "{mode} k={k}");
                }
                // f32
                let wide = widened(&t);
                let tm = read_widened(&t, &wide);
                let mut e = Estimator::new(tm.view, tm.config, &mut scratch).unwrap();
                for (&u, &y) in test.u.iter().zip(&test.y) {
                    let o = e.step(u, y);
                    assert!(o.x.is_finite() && o.x_std.is_finite());
                }
            }
        }
    }

    /// Tables of format versions 3 (no linear mean), 4 (no lags) and 5 (no split ranges) read,
    /// as a firmware may hold them: the same tables with the split ranges removed (version 5),
    /// the lags' count too (version 4), and each GP's linear-slope count too (version 3), give
    /// the same view, scratch size and steps as the current tables.
    #[test]
    fn version_3_to_6_tables_read_as_the_current_ones() {
        let m = model(Some(16));
        let t = model_tables(&m, Mode::Ekf).unwrap();
        assert_eq!(t.layout[1], tables::VERSION);
        // Version 7 ends with the count of the sensor's plays of the state, here 0, and END.
        let n = t.layout.len();
        assert_eq!(t.layout[n - 2], 0);
        let mut v6 = t.layout.clone();
        v6.remove(n - 2);
        v6[1] = 6;
        // Version 6 lists the split ranges after the version: their count, then two values
        // each.
        let ranges = v6[2] as usize;
        assert!(ranges >= 3, "settings and two GPs: {ranges}");
        let mut v5 = v6.clone();
        v5.drain(2..3 + 2 * ranges);
        v5[1] = 5;
        // The layout ends with the plays' count, (version 5) the lags' count, here 0, and END.
        let n = v5.len();
        assert_eq!(v5[n - 2], 0);
        let mut v4 = v5.clone();
        v4.remove(n - 2);
        v4[1] = 4;
        // Layout: magic, version, mode, has_init, has_local, max_neighbours, then per GP
        // profile, metric, dim, warp units, direction (2), n, sparse, mean input, whitening
        // length and (version 4) the slope count, here 0.
        let (first, second) = (6 + 10, 6 + 11 + 10);
        assert_eq!((v4[first], v4[second]), (0, 0));
        let mut v3 = v4.clone();
        v3.remove(second);
        v3.remove(first);
        v3[1] = 3;
        for old in [v6, v5, v4, v3] {
            check_lower_version_tables(&t, &old);
        }
    }

    /// `old` (a layout of a lower format version of `t`'s tables) reads as the same model as
    /// `t`.
    fn check_lower_version_tables(t: &ModelTables, old: &[u32]) {
        let version = old[1];
        assert_eq!(
            tables::scratch_len(old).unwrap(),
            tables::scratch_len(&t.layout).unwrap(),
            "version {version}"
        );
        let (new_model, old_model) = (
            t.tables().model().unwrap(),
            Tables {
                layout: old,
                ..t.tables()
            }
            .model()
            .unwrap(),
        );
        assert_eq!(old_model.config, new_model.config);
        let mut s1 = vec![0.0; tables::scratch_len(old).unwrap()];
        let mut s2 = s1.clone();
        let mut e_old = Estimator::new(old_model.view, old_model.config, &mut s1).unwrap();
        let mut e_new = Estimator::new(new_model.view, new_model.config, &mut s2).unwrap();
        for k in 0..200 {
            let u = 0.5 + 0.4 * (0.05 * k as f64).sin();
            let (a, b) = (e_old.step(u, u), e_new.step(u, u));
            assert_eq!(a.x.to_bits(), b.x.to_bits(), "version {version}, k={k}");
        }
    }

    /// A sparse model (m = 32) trained on 1200 samples: the step on its f32 tables stays
    /// within 2% of the range of x of the f64 step (on this model: 0.2% EKF, 1.3% EKF+BLR).
    /// The mean `k^T alpha` cancels, so f32 tables keep each weight as two f32 parts: read back,
    /// the weights agree with the model's to about 48 bits (one f32 part alone gives 24, and
    /// moves a sparse model's estimate by 5% of the range of x), exact and sparse.
    #[test]
    fn f32_tables_keep_the_mean_weights_to_48_bits() {
        for m in [model(Some(16)), model(None)] {
            let t = model_tables(&m, Mode::Ekf).unwrap();
            let wide = widened(&t);
            let tm = read_widened(&t, &wide);
            for (gp, read) in [
                (m.transition(), tm.view.transition),
                (m.sensor(), tm.view.sensor),
            ] {
                let want = gp.view().unwrap().parts().alpha.to_vec();
                let p = read.parts();
                assert_eq!(p.alpha_lo.len(), want.len());
                let scale = want.iter().fold(0.0f64, |a, w| a.max(w.abs()));
                for ((hi, lo), w) in p.alpha.iter().zip(p.alpha_lo).zip(&want) {
                    assert!((hi + lo - w).abs() <= 1e-13 * scale, "{hi} + {lo} vs {w}");
                }
            }
        }
    }

    /// A sparse model (m = 32) trained on 1200 samples, with each kernel: the step on its f32
    /// tables stays within 2% of the range of x of the f64 step (on these models: about 1e-7
    /// of it). With the squared exponential the sensor GP rides a near-linear ridge (signal
    /// variance e^10 and more); with every real rounded to f32 its estimate is off by 13-23% of
    /// the range, and by 3% with the hyperparameters and inputs in two parts but the variance
    /// factors in one.
    #[test]
    fn f32_tables_stay_close() {
        let cfg = SimConfig {
            noise_gain: 1.0,
            ..SimConfig::new(SystemKind::BoucWen)
        };
        let log = simulate_random(&cfg, 1200).unwrap();
        let test = simulate_random(&SimConfig { seed: 9, ..cfg }, 400).unwrap();
        let span = test.x.iter().cloned().fold(f64::MIN, f64::max)
            - test.x.iter().cloned().fold(f64::MAX, f64::min);
        for kernel in ["matern52", "se-ard"] {
            let kernel: hbn_model::KernelChoice = kernel.parse().unwrap();
            let params = HbnParams {
                n_inducing: Some(32),
                n_starts: 1,
                max_iters: 60,
                transition_kernel: kernel,
                sensor_kernel: kernel,
                ..HbnParams::default()
            };
            let m =
                HysteresisModel::fit(&[Sequence::new(&log.u, &log.x, &log.y)], &params).unwrap();
            let view = m.view().unwrap();
            let factors = [view.transition.len(), view.sensor.len()].map(|n| n * (n + 1) / 2);
            for mode in Mode::ALL {
                let base = m.estimate(&test.u, &test.y, mode).unwrap();
                let t = model_tables(&m, mode).unwrap();
                // The factors whose variance f32 would move by more than the tolerance are
                // in the split ranges; a sparse sensor GP's always is (in one f32 part its
                // latent variance, a millionth of its signal variance, is lost).
                let errors = f32_variance_errors(&view);
                assert!(errors[1] > F32_VARIANCE_TOLERANCE, "{errors:?}");
                let mut plain = ModelTables::default();
                tables::encode(&view, &m.ekf_config(mode), &mut plain).unwrap();
                let split = |t: &ModelTables| tables::split_ranges(&t.layout).unwrap().total();
                let kept: usize = (0..2)
                    .filter(|&i| errors[i] > F32_VARIANCE_TOLERANCE)
                    .map(|i| factors[i])
                    .sum();
                assert_eq!(split(&t) - split(&plain), kept, "{errors:?}");
                let wide = widened(&t);
                let tm = read_widened(&t, &wide);
                let mut scratch = vec![0.0; Estimator::scratch_len(&tm.view)];
                let mut e = Estimator::new(tm.view, tm.config, &mut scratch).unwrap();
                let worst = test
                    .u
                    .iter()
                    .zip(&test.y)
                    .enumerate()
                    .map(|(k, (&u, &y))| (e.step(u, y).x - base.x[k]).abs())
                    .fold(0.0, f64::max);
                eprintln!(
                    "{kernel:?} {mode}: f32 off by {:.2e} of the range",
                    worst / span
                );
                assert!(
                    worst < 0.02 * span,
                    "{kernel:?} {mode}: f32 off by {worst} of {span}"
                );
            }
        }
    }

    /// The split ranges hold each GP's hyperparameters and inputs, and widen back to f64 to
    /// about 48 bits (one f32 part keeps 24).
    #[test]
    fn split_ranges_widen_to_48_bits() {
        let m = model(Some(16));
        let t = model_tables(&m, Mode::Ekf).unwrap();
        let split = tables::split_ranges(&t.layout).unwrap();
        let features = m.transition().view().unwrap().parts().features.len();
        assert!(split.total() > 2 * features, "{}", split.total());
        let wide = widened(&t);
        let mut inside = 0;
        for range in split.iter() {
            for i in range {
                let (v, w) = (t.reals[i], wide[i]);
                assert!((v - w).abs() <= 1e-13 * v.abs(), "{i}: {w} vs {v}");
                inside += 1;
            }
        }
        assert_eq!(inside, split.total());
        // Outside the ranges a real keeps f32's 24 bits, so the ranges do matter.
        let rounded = (0..t.reals.len())
            .filter(|i| !split.iter().any(|r| r.contains(i)))
            .filter(|&i| wide[i] != t.reals[i])
            .count();
        assert!(rounded > 0);
    }

    #[test]
    fn corrupt_tables_are_rejected() {
        let m = model(Some(8));
        let t = model_tables(&m, Mode::Ekf).unwrap();
        let mut bad = t.clone();
        bad.layout[0] ^= 1;
        assert!(bad.tables().model().is_err());
        let mut short = t.clone();
        short.reals.pop();
        assert!(short.tables().model().is_err());
        let mut long = t.clone();
        long.reals.push(0.0);
        assert!(long.tables().model().is_err());
        let r32 = t.reals_f32().unwrap();
        let mut wide = vec![0.0; t.reals.len()];
        assert!(tables::widen(&t.layout, &r32, &mut wide[1..]).is_err());
        // A truncated f32 array does not widen into tables that read.
        let short = tables::widen(&t.layout, &r32[1..], &mut wide);
        assert!(
            short.is_err()
                || Tables {
                    reals: short.unwrap(),
                    ..t.tables()
                }
                .model()
                .is_err()
        );
        assert!(tables::widen(&t.layout, &r32[..3], &mut wide).is_err());
    }

    #[test]
    fn sizes_add_up_and_files_are_generated() {
        let m = model(Some(16));
        let sizes = size_report(&m, Precision::F32, None).unwrap();
        for s in &sizes {
            assert_eq!(s.model_bytes, s.gp_bytes + s.init_bytes + s.local_bytes);
            assert_eq!(s.local_bytes == 0, s.mode != Mode::EkfBlr);
        }
        let table = size_table(&sizes, m.default_mode());
        assert!(table.contains("ekf-blr"), "{table}");
        // The sizes a flash budget is trained against (hbn_model::firmware) are these.
        for model in [&m, &model(None)] {
            for (p, f32) in [(Precision::F32, true), (Precision::F64, false)] {
                let here = size_report(model, p, None).unwrap();
                let there = model.firmware_sizes(f32).unwrap();
                for (a, b) in here.iter().zip(&there) {
                    assert_eq!(
                        (a.mode, a.model_bytes, a.work_bytes()),
                        (b.mode, b.flash, b.ram)
                    );
                }
            }
        }
        for (format, names) in [
            (Format::Rust, &["hbn_model.rs"][..]),
            (Format::C, &["hbn_model.h", "hbn_model.c"][..]),
        ] {
            for p in [Precision::F64, Precision::F32] {
                let files = export(&m, Mode::EkfBlr, format, p, None, "m.hbn").unwrap();
                let got: Vec<_> = files.iter().map(|f| f.name).collect();
                assert_eq!(got, names);
            }
        }
        let dir = tempfile::tempdir().unwrap();
        let files = export(&m, Mode::Ekf, Format::C, Precision::F64, None, "m.hbn").unwrap();
        // Thinning the prior of x_0 shrinks the model data; 0 pairs drop it.
        let full = size_report(&m, Precision::F32, None).unwrap()[0];
        let thin = size_report(&m, Precision::F32, Some(50)).unwrap()[0];
        let none = size_report(&m, Precision::F32, Some(0)).unwrap()[0];
        assert!(thin.init_bytes < full.init_bytes && none.init_bytes == 0);
        assert_eq!(thin.gp_bytes, full.gp_bytes);
        for keep in [Some(0), Some(1), Some(50), Some(1_000_000)] {
            export(&m, Mode::Ekf, Format::Rust, Precision::F32, keep, "m.hbn").unwrap();
        }
        let out = dir.path().join("new");
        let paths = write(&out, &files).unwrap();
        assert_eq!(paths.len(), 2);
        // --out naming a file is an error and writes nothing.
        let file = dir.path().join("plain");
        std::fs::write(&file, "x").unwrap();
        assert!(matches!(
            write(&file, &files),
            Err(ExportError::NotADirectory { .. })
        ));
    }
}
