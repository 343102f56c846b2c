//! Export of a vector model (several inputs, state components and sensors,
//! [`hbn_model::VectorModel`]): its tables ([`hbn_core::tables::encode_vector`]) as C or Rust
//! source, and their sizes.
//!
//! The generated files have the scalar export's names and shape: `hbn_model.h` /
//! `hbn_model.c` with an `HbnModelData hbn_model` (for `hbn_vector_filter_init` of the
//! `hbn-ffi` library) and the sizes `HBN_MODEL_INPUTS`, `HBN_MODEL_STATES`,
//! `HBN_MODEL_SENSORS`; or `hbn_model.rs` with `HBN_INPUTS`, `HBN_STATES`, `HBN_SENSORS` and
//! `hbn_model(work)`, which returns a [`hbn_core::tables::VectorTableModel`]. With
//! [`Precision::F64`] the step on the tables equals [`hbn_model::VectorModel::estimate`] bit for
//! bit.

use std::fmt::Write as _;

use hbn_core::tables::{self, VectorInitParts, VectorTables};
use hbn_core::vector::{Dims, VectorView};
use hbn_core::{CoreError, GpView, Mode};
use hbn_model::VectorModel;
use hbn_model::firmware::{F32_VARIANCE_TOLERANCE, f32_variance_error};

use crate::{
    ExportError, Format, GeneratedFile, ModeSize, ModelTables, Precision, c_source, f32_text,
    f64_text, list,
};

/// The modes a vector model runs in (EKF+BLR is for scalar models).
pub const VECTOR_MODES: [Mode; 2] = [Mode::Ekf, Mode::Ukf];

/// A vector model's GP views: transitions, then sensors.
struct Views<'a> {
    transitions: Vec<GpView<'a>>,
    sensors: Vec<GpView<'a>>,
}

impl<'a> Views<'a> {
    fn of(model: &'a VectorModel) -> Result<Self, ExportError> {
        let d = model.dims();
        let missing = || {
            ExportError::Model(hbn_model::ModelError::Core(CoreError::InvalidSpec(
                "the vector model lacks a GP",
            )))
        };
        let mut transitions = Vec::with_capacity(d.states);
        for i in 0..d.states {
            let gp = model.transition(i).ok_or_else(missing)?;
            transitions.push(gp.view().map_err(hbn_model::ModelError::Core)?);
        }
        let mut sensors = Vec::with_capacity(d.sensors);
        for j in 0..d.sensors {
            let gp = model.sensor(j).ok_or_else(missing)?;
            sensors.push(gp.view().map_err(hbn_model::ModelError::Core)?);
        }
        Ok(Self {
            transitions,
            sensors,
        })
    }

    fn view(&self, model: &VectorModel) -> Result<VectorView<'_>, ExportError> {
        Ok(VectorView {
            dims: model.dims(),
            transitions: &self.transitions,
            sensors: &self.sensors,
            plays: model.plays()?,
            init: None,
        })
    }
}

/// Which variance factors the tables keep in two `f32` parts, transitions then sensors: those
/// whose latent variance rounding to `f32` would move by more than [`F32_VARIANCE_TOLERANCE`]
/// of what the filter adds it to ([`f32_variance_error`]; a transition's variance enters the
/// process noise with its noise variance, a sensor's alone, as in a scalar model).
pub fn vector_factors_in_two_parts(view: &VectorView<'_>) -> Vec<bool> {
    vector_f32_variance_errors(view)
        .into_iter()
        .map(|e| e > F32_VARIANCE_TOLERANCE)
        .collect()
}

/// [`f32_variance_error`] of each transition GP (with its noise) and each sensor GP (without).
pub fn vector_f32_variance_errors(view: &VectorView<'_>) -> Vec<f64> {
    view.transitions
        .iter()
        .map(|gp| f32_variance_error(gp, true))
        .chain(view.sensors.iter().map(|gp| f32_variance_error(gp, false)))
        .collect()
}

/// The prior of `x_0` as exported: the training rows, thinned.
struct InitRows {
    rows: Vec<f64>,
    y_scale: Vec<f64>,
    neighbours: usize,
    var_floor: Vec<f64>,
}

impl InitRows {
    fn parts(&self) -> VectorInitParts<'_> {
        VectorInitParts {
            rows: &self.rows,
            y_scale: &self.y_scale,
            neighbours: self.neighbours,
            var_floor: &self.var_floor,
        }
    }
}

/// The model's prior of `x_0` with at most `keep` rows (`None`: all of them; `Some(0)`: no
/// prior). Thinning keeps evenly spaced rows and scales the neighbours averaged by the same
/// factor, as the scalar export thins its pairs. `None` also where the model's prior cannot be
/// built (as [`VectorModel::estimate`] then runs without one).
fn init_rows(model: &VectorModel, keep: Option<usize>) -> Option<InitRows> {
    let d = model.dims();
    let (rows, y_scale, neighbours, var_floor) = model.init_prior_parts();
    VectorInitParts {
        rows,
        y_scale: &y_scale,
        neighbours,
        var_floor: &var_floor,
    }
    .prior(d)
    .ok()?;
    let width = d.sensors + d.states;
    let n = rows.len() / width;
    let keep = keep.unwrap_or(n).min(n);
    if keep == 0 {
        return None;
    }
    let (rows, neighbours) = if keep == n {
        (rows.to_vec(), neighbours)
    } else {
        let picked = (0..keep)
            .filter_map(|i| rows.chunks_exact(width).nth((2 * i + 1) * n / (2 * keep)))
            .flatten()
            .copied()
            .collect();
        (picked, ((neighbours * keep + n / 2) / n).max(1))
    };
    Some(InitRows {
        rows,
        y_scale,
        neighbours,
        var_floor,
    })
}

fn encode(
    view: &VectorView<'_>,
    init: Option<&InitRows>,
    model: &VectorModel,
    mode: Mode,
    split: &[bool],
    precision: Precision,
) -> Result<ModelTables, ExportError> {
    let mut t = ModelTables::default();
    let parts = init.map(InitRows::parts);
    tables::encode_vector(view, parts.as_ref(), &model.config(mode), split, &mut t).map_err(
        |source| ExportError::Tables {
            mode,
            precision: precision.name(),
            source,
        },
    )?;
    Ok(t)
}

/// The tables of the vector `model` in `mode` (EKF or UKF), with the model's settings of that
/// mode ([`VectorModel::config`]) and its whole prior of `x_0`: the step on them is
/// [`VectorModel::estimate`]'s.
pub fn vector_model_tables(model: &VectorModel, mode: Mode) -> Result<ModelTables, ExportError> {
    let views = Views::of(model)?;
    let view = views.view(model)?;
    let init = init_rows(model, None);
    encode(
        &view,
        init.as_ref(),
        model,
        mode,
        &vector_factors_in_two_parts(&view),
        Precision::F64,
    )
}

impl ModelTables {
    /// The borrowed form the core reads, for a vector model's tables.
    pub fn vector_tables(&self) -> VectorTables<'_> {
        VectorTables {
            layout: &self.layout,
            reals: &self.reals,
        }
    }
}

/// The vector tables at `precision`, checked to read back into a valid model; the `f32`
/// reals for an `f32` export.
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
            t.vector_tables().model().map_err(err)?;
            Ok(None)
        }
        Precision::F32 => {
            let r32 = t.reals_f32()?;
            let mut wide = vec![0.0; tables::widen_scratch(&t.layout, r32.len()).map_err(err)?];
            let reals = tables::widen(&t.layout, &r32, &mut wide).map_err(err)?;
            VectorTables {
                layout: &t.layout,
                reals,
            }
            .model()
            .map_err(err)?;
            Ok(Some(r32))
        }
    }
}

/// Bytes of model data and work memory of a vector model's export in each of its modes
/// ([`VECTOR_MODES`]) at `precision`, with at most `init_rows` training rows in the prior of
/// `x_0` (as [`export_vector`]). `local_bytes` is 0 (no local regression).
pub fn vector_size_report(
    model: &VectorModel,
    precision: Precision,
    init_rows_kept: Option<usize>,
) -> Result<Vec<ModeSize>, ExportError> {
    let views = Views::of(model)?;
    let view = views.view(model)?;
    let init = init_rows(model, init_rows_kept);
    let split = vector_factors_in_two_parts(&view);
    let scratch_bytes = 8 * view.scratch_len();
    VECTOR_MODES
        .into_iter()
        .map(|mode| {
            let full = encode(&view, init.as_ref(), model, mode, &split, precision)?;
            let bare = encode(&view, None, model, mode, &split, precision)?;
            let (model_bytes, gp_bytes) = (full.bytes(precision), bare.bytes(precision));
            Ok(ModeSize {
                mode,
                precision,
                gp_bytes,
                init_bytes: model_bytes - gp_bytes,
                local_bytes: 0,
                model_bytes,
                widen_bytes: match precision {
                    Precision::F64 => 0,
                    // One widened value per real of the f64 tables.
                    Precision::F32 => 8 * full.reals.len(),
                },
                scratch_bytes,
            })
        })
        .collect()
}

/// A vector model's size report as a table: one row per mode (`*` marks `default`).
pub fn vector_size_table(sizes: &[ModeSize], default: Mode) -> String {
    let mut s = String::new();
    let kb = |b: usize| format!("{:.1} KB", b as f64 / 1024.0);
    let _ = writeln!(
        s,
        "{:<10} {:>4} {:>10} {:>10} {:>10} {:>10} {:>10}",
        "mode", "real", "model", "GPs", "x0 prior", "widen", "scratch"
    );
    for m in sizes {
        let star = if m.mode == default { "*" } else { "" };
        let _ = writeln!(
            s,
            "{:<10} {:>4} {:>10} {:>10} {:>10} {:>10} {:>10}",
            format!("{}{star}", m.mode),
            m.precision.name(),
            kb(m.model_bytes),
            kb(m.gp_bytes),
            kb(m.init_bytes),
            kb(m.widen_bytes),
            kb(m.scratch_bytes),
        );
    }
    let _ = writeln!(
        s,
        "model = constant data (flash) = GPs and settings + x0 prior; widen + scratch = work memory (RAM); * the model's default mode"
    );
    s
}

/// Generates the source of the vector `model` in `mode` (EKF or UKF), as [`crate::export`]
/// does for a scalar model: `init_rows` keeps at most that many training rows for the prior of
/// `x_0` (`None`: all, and the export reproduces [`VectorModel::estimate`] exactly; `Some(0)`:
/// no prior, the filter starts from the training mean); `origin` is named in the header
/// comment.
pub fn export_vector(
    model: &VectorModel,
    mode: Mode,
    format: Format,
    precision: Precision,
    init_rows_kept: Option<usize>,
    origin: &str,
) -> Result<Vec<GeneratedFile>, ExportError> {
    let views = Views::of(model)?;
    let view = views.view(model)?;
    let init = init_rows(model, init_rows_kept);
    let split = vector_factors_in_two_parts(&view);
    let t = encode(&view, init.as_ref(), model, mode, &split, precision)?;
    let r32 = checked(&t, mode, precision)?;
    let scratch = tables::vector_scratch_len(&t.layout).map_err(|source| ExportError::Tables {
        mode,
        precision: precision.name(),
        source,
    })?;
    let info = VectorInfo {
        origin,
        mode,
        precision,
        dims: model.dims(),
        scratch,
        widen: match precision {
            Precision::F64 => 0,
            Precision::F32 => t.reals.len(),
        },
        reals: r32.as_ref().map_or(t.reals.len(), Vec::len),
        gps: view
            .transitions
            .iter()
            .chain(view.sensors)
            .map(|g| (g.is_sparse(), g.len()))
            .collect(),
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

struct VectorInfo<'a> {
    origin: &'a str,
    mode: Mode,
    precision: Precision,
    dims: Dims,
    scratch: usize,
    widen: usize,
    reals: usize,
    /// (sparse, points) of each GP, transitions then sensors.
    gps: Vec<(bool, usize)>,
    bytes: usize,
}

impl VectorInfo<'_> {
    fn describe(&self) -> String {
        let d = self.dims;
        let kinds: Vec<String> = self
            .gps
            .iter()
            .map(|&(sparse, n)| {
                if sparse {
                    format!("sparse {n}")
                } else {
                    format!("exact {n}")
                }
            })
            .collect();
        let (t, s) = kinds.split_at(d.states.min(kinds.len()));
        format!(
            "hbn vector model exported by `hbn export` from {}\n{} inputs, {} state components, {} sensors; mode {}, {} reals, {} bytes of model data\ntransition GPs: {} points; sensor GPs: {} points\nGenerated file: do not edit; export the model again instead.",
            self.origin.replace("*/", "* /"),
            d.inputs,
            d.states,
            d.sensors,
            self.mode,
            self.precision.name(),
            self.bytes,
            t.join(", "),
            s.join(", "),
        )
    }
}

fn rust_source(t: &ModelTables, r32: Option<&[f32]>, info: &VectorInfo<'_>) -> String {
    let mut s = String::new();
    for line in info.describe().lines() {
        let _ = writeln!(s, "// {line}");
    }
    let (real, reals) = match r32 {
        Some(r) => ("f32", list(r, 6, "    ", |v| f32_text(*v))),
        None => ("f64", list(&t.reals, 4, "    ", |v| f64_text(*v))),
    };
    let d = info.dims;
    let _ = write!(
        s,
        r#"
/// The estimation mode the tables were exported for.
pub const HBN_MODE: &str = "{mode}";
/// Inputs `u_k` the step reads (`du`).
pub const HBN_INPUTS: usize = {inputs};
/// State components it estimates (`dx`).
pub const HBN_STATES: usize = {states};
/// Sensors `y_k` it reads (`dy`).
pub const HBN_SENSORS: usize = {sensors};
/// `f64` values of work memory [`hbn_model`] needs: the widened reals (0 for an `f64` export).
pub const HBN_WIDEN_LEN: usize = {widen};
/// `f64` values of scratch memory the step needs (`hbn_core::VectorEstimator`).
pub const HBN_SCRATCH_LEN: usize = {scratch};

/// Structural integers of the model (`hbn_core::tables`, a vector model's).
pub static HBN_LAYOUT: [u32; {nl}] = [
{layout}];

/// Real numbers of the model.
pub static HBN_REALS: [{real}; {nr}] = [
{reals}];

/// The vector model over the tables above, checked once; its `view()` is what
/// `hbn_core::VectorEstimator::new` takes. `work` must hold [`HBN_WIDEN_LEN`] values (it may
/// be empty for an `f64` export); the model borrows it.
#[allow(dead_code)]
pub fn hbn_model(
    work: &mut [f64],
) -> Result<hbn_core::tables::VectorTableModel<'_>, hbn_core::CoreError> {{
{body}
}}
"#,
        mode = info.mode,
        inputs = d.inputs,
        states = d.states,
        sensors = d.sensors,
        widen = info.widen,
        scratch = info.scratch,
        nl = t.layout.len(),
        layout = list(&t.layout, 8, "    ", |v| v.to_string()),
        nr = info.reals,
        body = match r32 {
            Some(_) =>
                "    let reals = hbn_core::tables::widen(&HBN_LAYOUT, &HBN_REALS, work)?;
    hbn_core::tables::VectorTables {
        layout: &HBN_LAYOUT,
        reals,
    }
    .model()",
            None =>
                "    let _ = work;
    hbn_core::tables::VectorTables {
        layout: &HBN_LAYOUT,
        reals: &HBN_REALS,
    }
    .model()",
        },
    );
    s
}

fn c_header(t: &ModelTables, info: &VectorInfo<'_>) -> String {
    let real = match info.precision {
        Precision::F64 => "double",
        Precision::F32 => "float",
    };
    let d = info.dims;
    format!(
        r#"{comment}#ifndef HBN_MODEL_H
#define HBN_MODEL_H

#include <stdint.h>
#include "hbn.h"

#ifdef __cplusplus
extern "C" {{
#endif

/* A vector model: run it with hbn_vector_filter_init and hbn_vector_filter_step. */
#define HBN_MODEL_VECTOR 1
/* The estimation mode the tables were exported for. */
#define HBN_MODEL_MODE "{mode}"
/* Inputs u (doubles hbn_vector_filter_step reads from u). */
#define HBN_MODEL_INPUTS {inputs}
/* State components x (entries of HbnVectorOutput.x it fills). */
#define HBN_MODEL_STATES {states}
/* Sensors y (doubles hbn_vector_filter_step reads from y; NaN marks a missing sample). */
#define HBN_MODEL_SENSORS {sensors}
/* Precision of the real numbers: 64 (double) or 32 (float). */
#define HBN_MODEL_REAL_BITS {bits}
#define HBN_MODEL_LAYOUT_LEN {nl}u
#define HBN_MODEL_KEYS_LEN {nk}u
#define HBN_MODEL_REALS_LEN {nr}u
/* Doubles of work memory hbn_vector_filter_init needs (hbn_vector_work_len(&hbn_model) at run
 * time). */
#define HBN_MODEL_WORK_LEN {work}u

extern const uint32_t hbn_model_layout[];
extern const uint64_t hbn_model_keys[];
extern const {real} hbn_model_reals[];

/* The model for hbn_vector_filter_init. */
extern const HbnModelData hbn_model;

#ifdef __cplusplus
}}
#endif

#endif /* HBN_MODEL_H */
"#,
        comment = crate::c_comment_text(&info.describe()),
        mode = info.mode,
        inputs = d.inputs,
        states = d.states,
        sensors = d.sensors,
        bits = 8 * info.precision.bytes(),
        nl = t.layout.len(),
        nk = t.keys.len(),
        nr = info.reals,
        work = info.widen + info.scratch,
    )
}
