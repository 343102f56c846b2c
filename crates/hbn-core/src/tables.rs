//! A trained model as constant tables: three flat arrays a firmware keeps in flash, and the
//! model view read back from them without allocation.
//!
//! [`encode`] writes a model view and its filter settings into a [`TableSink`] (the exporter's
//! growable buffers); [`Tables::model`] reads the same three arrays back as an [`HbnView`] and
//! an [`EkfConfig`] borrowing them, checked once by the usual constructors ([`GpView::new`],
//! [`Neighbourhood::new`], [`InitPrior::new`]), so the step runs on the tables exactly as on the
//! model it was exported from: bit for bit in `f64`.
//!
//! - `layout` (`u32`): a magic number, the format version, the mode, structural integers
//!   (kernel kinds, dimensions, counts) and the local regression's cell offsets;
//! - `keys` (`u64`): the local regression's cell keys (empty unless the mode is EKF+BLR);
//! - `reals` (`f64`): every real number, in the order the layout describes.
//!
//! An `f32` export stores `reals` as `f32`; [`widen`] converts them into caller-provided `f64`
//! memory ([`widen_scratch`] values) that the view then borrows. The few reals a prediction is
//! sensitive to in every digit (the settings, each GP's hyperparameters, standardisation and
//! inducing or support inputs, the plays) lie in *split ranges* that the layout lists
//! ([`split_ranges`]): an `f32` export stores each of them as two `f32` parts, the nearest
//! `f32` value in its place and the rest after all the reals, and [`widen`] adds the two back
//! (about 48 bits). Rounded to 24 bits, the inputs of a GP whose kernel rides a near-linear
//! ridge (a large signal variance and long length scales) move a model's estimate by up to
//! 23% of the range of `x`; the O(n d) values cost little next to the O(n^2) factor.
//!
//! The local training data of EKF+BLR is only written for that mode: the EKF and the UKF read
//! the two GPs, the filter settings and the prior of `x_0`.
//!
//! A vector model (several inputs, state components and sensors, [`crate::vector`]) has tables
//! of its own, with their own magic number ([`VECTOR_MAGIC`]): [`encode_vector`] writes them,
//! [`VectorTables::model`] reads them back as a [`VectorTableModel`] whose
//! [`VectorTableModel::view`] is the [`VectorView`] the vector step reads. They hold the sizes,
//! one GP per state component and per sensor in the scalar tables' GP layout, the memory
//! operators, the settings and the first-measurement prior's rows; only the model's sizes are
//! stored, never the maxima. [`split_ranges`], [`widen_scratch`] and [`widen`] read both kinds.

use crate::CoreError;
use crate::blr::{LocalRegression, Neighbourhood, NeighbourhoodParts};
use crate::ekf::{EkfConfig, HbnView, InitPrior, Mode};
use crate::gp::{GpParts, GpView, Variance};
use crate::kernel::{Kernel, KernelSpec, Metric, Profile, at};
use crate::play::Plays;
use crate::vector::{Dims, MAX_SENSORS, MAX_STATES, VectorConfig, VectorInitPrior, VectorView};

/// First value of every layout: `"HBN1"` as little-endian bytes.
pub const MAGIC: u32 = u32::from_le_bytes(*b"HBN1");
/// Format version written by [`encode`]. [`Tables::model`] reads every version from
/// [`OLDEST_VERSION`] to this one; a layout holds only the blocks its version defines, and the
/// others read as empty: the play operators after the prior of `x_0` (version 3 and above),
/// each GP's linear mean, its slope count after the whitening length and its slopes after the
/// output scalars (4 and above, else a constant mean), the lags' count and coefficients after
/// the plays (5 and above), the split ranges after the version (6, see
/// [`split_ranges`]), and the count and radii of the sensor's plays of the state after the
/// lags (7, [`HbnView::sensor_memory`]).
pub const VERSION: u32 = 7;
/// Oldest format version [`Tables::model`] reads.
pub const OLDEST_VERSION: u32 = 2;
/// Last value of every layout (catches a truncated or misaligned table).
pub const END: u32 = u32::from_le_bytes(*b"END1");
/// A `u32` standing for "none" (no mean input, no direction factor).
const NONE: u32 = u32::MAX;

const TRUNCATED: CoreError = CoreError::InvalidSpec("model tables are truncated or corrupt");
const NOT_TABLES: CoreError =
    CoreError::InvalidSpec("not hbn model tables (the magic number differs)");
const OTHER_VERSION: CoreError =
    CoreError::InvalidSpec("model tables of another format version: export the model again");

/// Where [`encode`] writes: three growable arrays (the exporter's `Vec`s).
pub trait TableSink {
    /// Appends one structural integer to the layout.
    fn int(&mut self, v: u32);
    /// Appends one cell key.
    fn key(&mut self, v: u64);
    /// Appends one real number.
    fn real(&mut self, v: f64);
}

/// A model's constant tables, borrowed (see the module docs).
#[derive(Clone, Copy, Debug)]
pub struct Tables<'a> {
    /// Structural integers.
    pub layout: &'a [u32],
    /// Cell keys of the local regression.
    pub keys: &'a [u64],
    /// Real numbers (widened to `f64` for an `f32` export, see [`widen`]).
    pub reals: &'a [f64],
}

/// What [`Tables::model`] returns: the view and the filter settings it was exported with.
#[derive(Clone, Copy, Debug)]
pub struct TableModel<'a> {
    /// The model view the step reads.
    pub view: HbnView<'a>,
    /// The filter settings (mode included).
    pub config: EkfConfig,
}

/// Most split ranges a layout lists (the encoder writes at most one per settings block, GP,
/// local regression, prior of `x_0` and play block).
pub const MAX_SPLIT_RANGES: usize = 8;

/// First value of a vector model's layout: `"HBV1"` as little-endian bytes.
pub const VECTOR_MAGIC: u32 = u32::from_le_bytes(*b"HBV1");
/// Format version of a vector model's tables ([`encode_vector`], [`VectorTables::model`]).
pub const VECTOR_VERSION: u32 = 1;
/// Most split ranges a vector layout lists: the settings, two per GP (its inputs and its
/// variance factor), the prior of `x_0` and the plays.
pub const MAX_VECTOR_SPLIT_RANGES: usize = 2 + 2 * (MAX_STATES + MAX_SENSORS) + 2;

/// The ranges of `reals` (as `start..end` indices) that an `f32` export stores in two parts,
/// in increasing order, read from a layout (none in a layout of format version 5 or lower).
#[derive(Clone, Copy, Debug)]
pub struct SplitRanges<'a> {
    pairs: &'a [[u32; 2]],
}

impl SplitRanges<'_> {
    /// How many reals the ranges hold: the length of the low parts an `f32` export appends.
    pub fn total(&self) -> usize {
        self.iter().map(|r| r.len()).sum()
    }

    /// The ranges, in order.
    pub fn iter(&self) -> impl Iterator<Item = core::ops::Range<usize>> + '_ {
        self.pairs.iter().map(|&[start, len]| {
            let (start, len) = (start as usize, len as usize);
            start..start.saturating_add(len)
        })
    }
}

/// The split ranges `layout` (a scalar or a vector model's) lists. Fails on a layout that is
/// not hbn tables of a readable version, or whose ranges are unordered, overlapping or more
/// than [`MAX_SPLIT_RANGES`] ([`MAX_VECTOR_SPLIT_RANGES`] for a vector model).
pub fn split_ranges(layout: &[u32]) -> Result<SplitRanges<'_>, CoreError> {
    let mut r = Reader {
        ints: layout,
        keys: &[],
        reals: &[],
    };
    let pairs = if layout.first() == Some(&VECTOR_MAGIC) {
        r.vector_header()?;
        r.split_pairs_upto(MAX_VECTOR_SPLIT_RANGES)?
    } else {
        let version = r.header()?;
        r.split_pairs(version)?
    };
    Ok(SplitRanges { pairs })
}

/// `f64` values [`widen`] writes for the `f32` tables with `layout` and `reals_f32` reals: one
/// per real of the `f64` tables (the low parts of the split ranges widen into the values
/// before them). Fails as [`split_ranges`] does, or when `reals_f32` is shorter than the low
/// parts.
pub fn widen_scratch(layout: &[u32], reals_f32: usize) -> Result<usize, CoreError> {
    reals_f32
        .checked_sub(split_ranges(layout)?.total())
        .ok_or(TRUNCATED)
}

/// Converts the `f32` reals of the tables with `layout` into the front of `out` (at least
/// [`widen_scratch`] values) and returns that part, for
/// [`Tables::reals`]: each value widened, and each value of a split range plus its low part
/// (the `f32` values after the widened ones, see [`split_ranges`]).
pub fn widen<'w>(
    layout: &[u32],
    reals: &[f32],
    out: &'w mut [f64],
) -> Result<&'w [f64], CoreError> {
    let split = split_ranges(layout)?;
    let n = widen_scratch(layout, reals.len())?;
    let (high, low) = reals.split_at(n);
    let got = out.len();
    let Some(dst) = out.get_mut(..n) else {
        return Err(CoreError::ScratchTooSmall { needed: n, got });
    };
    for (d, s) in dst.iter_mut().zip(high) {
        *d = f64::from(*s);
    }
    let mut low = low.iter();
    for range in split.iter() {
        let part = dst.get_mut(range).ok_or(TRUNCATED)?;
        for (d, lo) in part.iter_mut().zip(low.by_ref()) {
            *d += f64::from(*lo);
        }
    }
    Ok(dst)
}

fn mode_code(mode: Mode) -> u32 {
    match mode {
        Mode::Ekf => 0,
        Mode::EkfBlr => 1,
        Mode::Ukf => 2,
    }
}

fn count(n: usize) -> Result<u32, CoreError> {
    u32::try_from(n).map_err(|_| CoreError::InvalidSpec("a table holds at most 2^32 - 1 values"))
}

/// Writes `view` and `config` (mode included) as tables into `sink`. The local training data is
/// written only for [`Mode::EkfBlr`] (the other modes never read it). Fails when that mode's
/// view has no local data, or a count exceeds `u32`. The variance factors lie outside the
/// split ranges ([`encode_with`] can put them inside).
pub fn encode<S: TableSink>(
    view: &HbnView<'_>,
    config: &EkfConfig,
    sink: &mut S,
) -> Result<(), CoreError> {
    encode_with(view, config, [false; 2], sink)
}

/// [`encode`], with the variance factor of the transition GP (`split_factors[0]`) and of the
/// sensor GP (`[1]`) in the split ranges where asked: an `f32` export then keeps that factor to
/// about 48 bits, at the size of an `f64` one. Worth it where the latent variance
/// `k(x,x) - |F k|^2` cancels in most of its digits (a large signal variance against the
/// posterior's), which the exporter measures.
pub fn encode_with<S: TableSink>(
    view: &HbnView<'_>,
    config: &EkfConfig,
    split_factors: [bool; 2],
    sink: &mut S,
) -> Result<(), CoreError> {
    // Two passes: the first only counts the reals, to find the split ranges that the layout
    // lists before them; the second writes.
    let mut count_only = Writer::<S> {
        sink: None,
        reals: 0,
        split: Split::default(),
        open: None,
        limit: MAX_SPLIT_RANGES,
    };
    write_tables(
        view,
        config,
        split_factors,
        &Split::default(),
        &mut count_only,
    )?;
    let split = count_only.split;
    let mut writer = Writer {
        sink: Some(sink),
        reals: 0,
        split: Split::default(),
        open: None,
        limit: MAX_SPLIT_RANGES,
    };
    write_tables(view, config, split_factors, &split, &mut writer)
}

/// The split ranges the encoder found, as `(start, len)` pairs of reals.
#[derive(Clone, Copy, Debug, Default)]
struct Split {
    ranges: [[u32; 2]; MAX_VECTOR_SPLIT_RANGES],
    len: usize,
}

/// Writes into an optional sink, counting the reals and recording the split ranges.
struct Writer<'s, S> {
    sink: Option<&'s mut S>,
    reals: usize,
    split: Split,
    /// Where the split range being written began.
    open: Option<usize>,
    /// Most split ranges the layout may list.
    limit: usize,
}

impl<S: TableSink> Writer<'_, S> {
    fn int(&mut self, v: u32) {
        if let Some(s) = self.sink.as_mut() {
            s.int(v);
        }
    }

    fn key(&mut self, v: u64) {
        if let Some(s) = self.sink.as_mut() {
            s.key(v);
        }
    }

    fn real(&mut self, v: f64) {
        if let Some(s) = self.sink.as_mut() {
            s.real(v);
        }
        self.reals += 1;
    }

    /// The reals written next, until [`Writer::end_split`], lie in a split range.
    fn begin_split(&mut self) {
        self.open = Some(self.reals);
    }

    /// Closes the split range begun last (merged with the one before when they touch).
    fn end_split(&mut self) -> Result<(), CoreError> {
        let Some(start) = self.open.take() else {
            return Ok(());
        };
        if self.reals == start {
            return Ok(());
        }
        let (start, end) = (count(start)?, count(self.reals)?);
        let split = &mut self.split;
        if let Some(last) = split
            .len
            .checked_sub(1)
            .and_then(|i| split.ranges.get_mut(i))
            && last[0] + last[1] == start
        {
            last[1] = end - last[0];
            return Ok(());
        }
        let too_many = CoreError::InvalidSpec("too many split ranges");
        if split.len >= self.limit {
            return Err(too_many);
        }
        let slot = split.ranges.get_mut(split.len).ok_or(too_many)?;
        *slot = [start, end - start];
        split.len += 1;
        Ok(())
    }
}

fn write_tables<S: TableSink>(
    view: &HbnView<'_>,
    config: &EkfConfig,
    split_factors: [bool; 2],
    split: &Split,
    w: &mut Writer<'_, S>,
) -> Result<(), CoreError> {
    let blr = config.mode == Mode::EkfBlr;
    let locals = match (blr, view.transition_local, view.sensor_local) {
        (false, _, _) => None,
        (true, Some(t), Some(s)) => Some((t, s)),
        (true, _, _) => {
            return Err(CoreError::InvalidSpec(
                "EKF+BLR needs the local training data in the model",
            ));
        }
    };
    w.int(MAGIC);
    w.int(VERSION);
    w.int(count(split.len)?);
    for [start, len] in split.ranges.iter().take(split.len) {
        w.int(*start);
        w.int(*len);
    }
    w.int(mode_code(config.mode));
    w.int(u32::from(view.init.is_some()));
    w.int(u32::from(locals.is_some()));
    w.int(count(view.blr.max_neighbours)?);
    let c = config;
    w.begin_split();
    for v in [
        c.q_floor,
        c.r_floor,
        c.qx_model_floor,
        c.r_model_floor,
        c.p_min,
        c.p_max,
        c.jac_max,
        c.innovation_min,
        c.nis_gate,
        c.x_bounds.0,
        c.x_bounds.1,
        c.y_bounds.0,
        c.y_bounds.1,
        c.x0_mean,
        c.x0_var,
        c.q_scale,
        c.r_scale,
        c.std_scale,
        view.blr.nu0,
        view.blr.kappa,
    ] {
        w.real(v);
    }
    w.end_split()?;
    encode_gp(&view.transition, split_factors[0], w)?;
    encode_gp(&view.sensor, split_factors[1], w)?;
    if let Some((t, s)) = locals {
        encode_local(&t, w)?;
        encode_local(&s, w)?;
    }
    if let Some(init) = view.init {
        w.int(count(init.pairs().len())?);
        w.int(count(init.neighbours())?);
        w.begin_split();
        w.real(init.var_floor());
        w.end_split()?;
        for p in init.pairs() {
            w.real(p[0]);
            w.real(p[1]);
        }
    }
    w.begin_split();
    w.int(count(view.plays.radii().len())?);
    for &r in view.plays.radii() {
        w.real(r);
    }
    w.int(count(view.plays.lags().len())?);
    for &a in view.plays.lags() {
        w.real(a);
    }
    w.int(count(view.sensor_memory.radii().len())?);
    for &r in view.sensor_memory.radii() {
        w.real(r);
    }
    w.end_split()?;
    w.int(END);
    Ok(())
}

fn encode_gp<S: TableSink>(
    gp: &GpView<'_>,
    split_factor: bool,
    w: &mut Writer<'_, S>,
) -> Result<(), CoreError> {
    let p = gp.parts();
    let spec = *p.kernel.spec();
    w.int(match spec.profile {
        Profile::SquaredExponential => 0,
        Profile::Matern52 => 1,
    });
    w.int(match spec.metric {
        Metric::Isotropic => 0,
        Metric::Ard => 1,
        Metric::Mahalanobis => 2,
    });
    w.int(count(spec.dim)?);
    w.int(count(spec.warp_units)?);
    match spec.direction {
        Some([a, b]) => {
            w.int(count(a)?);
            w.int(count(b)?);
        }
        None => {
            w.int(NONE);
            w.int(NONE);
        }
    }
    w.int(count(gp.len())?);
    w.int(u32::from(gp.is_sparse()));
    w.int(match gp.mean_input() {
        Some(j) => count(j)?,
        None => NONE,
    });
    w.int(count(p.kernel.whiten().len())?);
    w.int(count(p.linear.len())?);
    let factor = match p.variance {
        Variance::Exact { chol_packed } => chol_packed,
        Variance::Sparse { variance_factor } => variance_factor,
    };
    let scalars = [p.output_mean, p.output_scale, p.noise_var];
    let arrays: [&[f64]; 8] = [
        p.kernel.theta(),
        p.kernel.whiten(),
        p.input_mean,
        p.input_scale,
        &scalars,
        p.linear,
        p.features,
        p.directions,
    ];
    w.begin_split();
    for v in arrays.iter().flat_map(|s| s.iter()) {
        w.real(*v);
    }
    w.end_split()?;
    // The mean weights as an f32-representable high part and the rest: their sum is the weight
    // exactly in f64, and to about 48 bits once both are rounded to f32 (see
    // `GpParts::alpha_lo`).
    let weight = |i: usize| at(p.alpha, i) + at(p.alpha_lo, i);
    for i in 0..p.alpha.len() {
        w.real(split_f32(weight(i)).0);
    }
    for i in 0..p.alpha.len() {
        w.real(split_f32(weight(i)).1);
    }
    if split_factor {
        w.begin_split();
    }
    for v in factor {
        w.real(*v);
    }
    w.end_split()
}

/// `v` as `(hi, lo)`: `hi` the nearest `f32` value (as `f64`) and `lo = v - hi`, exact in
/// `f64`, so that `hi + lo == v`; `(v, 0)` where `v` is outside `f32`'s range (the `f32`
/// export then refuses it, as any such real).
pub fn split_f32(v: f64) -> (f64, f64) {
    // `as` rounds to the nearest `f32` (and saturates to infinity outside its range).
    #[allow(clippy::cast_possible_truncation)]
    let hi = f64::from(v as f32);
    if hi.is_finite() && v.is_finite() {
        (hi, v - hi)
    } else {
        (v, 0.0)
    }
}

fn encode_local<S: TableSink>(
    nb: &Neighbourhood<'_>,
    w: &mut Writer<'_, S>,
) -> Result<(), CoreError> {
    let p = nb.parts();
    w.int(count(nb.dim())?);
    w.int(count(p.targets.len())?);
    w.int(count(p.cell_keys.len())?);
    for &s in p.cell_start {
        w.int(s);
    }
    for &k in p.cell_keys {
        w.key(k);
    }
    for v in p.inputs.iter().chain(p.targets) {
        w.real(*v);
    }
    w.begin_split();
    for v in p.origin.iter().chain(p.half_window).chain(p.input_var) {
        w.real(*v);
    }
    w.end_split()
}

/// A cursor over the three arrays; every read is checked.
struct Reader<'a> {
    ints: &'a [u32],
    keys: &'a [u64],
    reals: &'a [f64],
}

impl<'a> Reader<'a> {
    fn int(&mut self) -> Result<u32, CoreError> {
        let (v, rest) = self.ints.split_first().ok_or(TRUNCATED)?;
        self.ints = rest;
        Ok(*v)
    }

    fn size(&mut self) -> Result<usize, CoreError> {
        usize::try_from(self.int()?).map_err(|_| TRUNCATED)
    }

    fn opt(&mut self) -> Result<Option<usize>, CoreError> {
        match self.int()? {
            NONE => Ok(None),
            v => usize::try_from(v).map(Some).map_err(|_| TRUNCATED),
        }
    }

    fn ints(&mut self, n: usize) -> Result<&'a [u32], CoreError> {
        let (v, rest) = self.ints.split_at_checked(n).ok_or(TRUNCATED)?;
        self.ints = rest;
        Ok(v)
    }

    fn keys(&mut self, n: usize) -> Result<&'a [u64], CoreError> {
        let (v, rest) = self.keys.split_at_checked(n).ok_or(TRUNCATED)?;
        self.keys = rest;
        Ok(v)
    }

    fn real(&mut self) -> Result<f64, CoreError> {
        let (v, rest) = self.reals.split_first().ok_or(TRUNCATED)?;
        self.reals = rest;
        Ok(*v)
    }

    fn reals(&mut self, n: usize) -> Result<&'a [f64], CoreError> {
        let (v, rest) = self.reals.split_at_checked(n).ok_or(TRUNCATED)?;
        self.reals = rest;
        Ok(v)
    }

    /// The next `N` reals.
    fn array<const N: usize>(&mut self) -> Result<[f64; N], CoreError> {
        let (v, rest) = self.reals.split_first_chunk::<N>().ok_or(TRUNCATED)?;
        self.reals = rest;
        Ok(*v)
    }
}

impl<'a> Reader<'a> {
    /// Reads the magic number and the version; fails unless they are hbn tables of a
    /// readable version.
    fn header(&mut self) -> Result<u32, CoreError> {
        if self.int()? != MAGIC {
            return Err(NOT_TABLES);
        }
        let version = self.int()?;
        if !(OLDEST_VERSION..=VERSION).contains(&version) {
            return Err(OTHER_VERSION);
        }
        Ok(version)
    }

    /// The split ranges as `(start, len)` pairs (version 6 and above), checked to be
    /// increasing and apart.
    fn split_pairs(&mut self, version: u32) -> Result<&'a [[u32; 2]], CoreError> {
        if version < 6 {
            return Ok(&[]);
        }
        self.split_pairs_upto(MAX_SPLIT_RANGES)
    }

    /// Reads the magic number and the version of a vector model's tables.
    fn vector_header(&mut self) -> Result<(), CoreError> {
        // The scalar tables' messages: a scalar firmware, which reads this through
        // `split_ranges`, then holds no text of its own for vector tables.
        if self.int()? != VECTOR_MAGIC {
            return Err(NOT_TABLES);
        }
        if self.int()? != VECTOR_VERSION {
            return Err(OTHER_VERSION);
        }
        Ok(())
    }

    /// The split ranges as `(start, len)` pairs, at most `max`, checked to be increasing and
    /// apart.
    fn split_pairs_upto(&mut self, max: usize) -> Result<&'a [[u32; 2]], CoreError> {
        let n = self.size()?;
        if n > max {
            return Err(TRUNCATED);
        }
        let (pairs, _) = self.ints(mul(n, 2)?)?.as_chunks::<2>();
        let mut end = 0u64;
        for &[start, len] in pairs {
            let (start, len) = (u64::from(start), u64::from(len));
            if start < end || len == 0 {
                return Err(TRUNCATED);
            }
            end = start + len;
        }
        Ok(pairs)
    }
}

fn mul(a: usize, b: usize) -> Result<usize, CoreError> {
    a.checked_mul(b).ok_or(TRUNCATED)
}

fn tri(n: usize) -> Result<usize, CoreError> {
    Ok(mul(n, n.checked_add(1).ok_or(TRUNCATED)?)? / 2)
}

/// Scratch values the step needs for the model in `layout` ([`crate::Estimator::scratch_len`]
/// of its view), read from the layout alone: a firmware can size its work memory before it
/// widens an `f32` table.
pub fn scratch_len(layout: &[u32]) -> Result<usize, CoreError> {
    let mut r = Reader {
        ints: layout,
        keys: &[],
        reals: &[],
    };
    let version = r.header()?;
    r.split_pairs(version)?;
    r.ints(4)?;
    let mut len = 0;
    // The two GPs' integers are adjacent: profile, metric, dim, warp units, direction (2),
    // n, sparse, mean input, whitening length, and (version 4 and above) the linear mean's
    // length.
    for _ in 0..2 {
        r.ints(6)?;
        let n = r.size()?;
        let sparse = r.int()? != 0;
        r.ints(if version >= 4 { 3 } else { 2 })?;
        len = len.max(crate::gp::predict_scratch(n, sparse, crate::gp::Want::EKF));
    }
    Ok(len)
}

impl<'a> Tables<'a> {
    /// Reads the model view and filter settings back, checking every value once (as the
    /// model's own view does). Fails on a table of another format or version, a truncated or
    /// corrupt table, or values the view's constructors reject.
    pub fn model(&self) -> Result<TableModel<'a>, CoreError> {
        let mut r = Reader {
            ints: self.layout,
            keys: self.keys,
            reals: self.reals,
        };
        let version = r.header()?;
        let split = r.split_pairs(version)?;
        let split = SplitRanges { pairs: split };
        if split.iter().any(|range| range.end > self.reals.len()) {
            return Err(TRUNCATED);
        }
        let mode = match r.int()? {
            0 => Mode::Ekf,
            1 => Mode::EkfBlr,
            2 => Mode::Ukf,
            _ => return Err(TRUNCATED),
        };
        let has_init = r.int()? != 0;
        let has_local = r.int()? != 0;
        let max_neighbours = r.size()?;
        let mut c = [0.0; 20];
        for v in c.iter_mut() {
            *v = r.real()?;
        }
        let [
            q_floor,
            r_floor,
            qx_model_floor,
            r_model_floor,
            p_min,
            p_max,
            jac_max,
            innovation_min,
            nis_gate,
            x_lo,
            x_hi,
            y_lo,
            y_hi,
            x0_mean,
            x0_var,
            q_scale,
            r_scale,
            std_scale,
            nu0,
            kappa,
        ] = c;
        let config = EkfConfig {
            mode,
            q_floor,
            r_floor,
            qx_model_floor,
            r_model_floor,
            p_min,
            p_max,
            jac_max,
            innovation_min,
            nis_gate,
            x_bounds: (x_lo, x_hi),
            y_bounds: (y_lo, y_hi),
            x0_mean,
            x0_var,
            q_scale,
            r_scale,
            std_scale,
        };
        let transition = read_gp(&mut r, version)?;
        let sensor = read_gp(&mut r, version)?;
        let (transition_local, sensor_local) = if has_local {
            (Some(read_local(&mut r)?), Some(read_local(&mut r)?))
        } else {
            (None, None)
        };
        let init = if has_init {
            let n = r.size()?;
            let neighbours = r.size()?;
            let var_floor = r.real()?;
            let (pairs, rest) = r.reals(mul(n, 2)?)?.as_chunks::<2>();
            if !rest.is_empty() {
                return Err(TRUNCATED);
            }
            Some(InitPrior::new(pairs, neighbours, var_floor)?)
        } else {
            None
        };
        let plays = if version >= 3 {
            let n = r.size()?;
            if n > crate::play::MAX_PLAYS {
                return Err(TRUNCATED);
            }
            let radii = r.reals(n)?;
            let lags = if version >= 5 {
                let n = r.size()?;
                if n > crate::play::MAX_PLAYS {
                    return Err(TRUNCATED);
                }
                r.reals(n)?
            } else {
                &[]
            };
            Plays::with_lags(radii, lags)?
        } else {
            Plays::NONE
        };
        let sensor_memory = if version >= 7 {
            let n = r.size()?;
            if n > crate::ekf::MAX_SENSOR_MEMORY {
                return Err(TRUNCATED);
            }
            Plays::new(r.reals(n)?)?
        } else {
            Plays::NONE
        };
        if r.int()? != END || !r.ints.is_empty() || !r.keys.is_empty() || !r.reals.is_empty() {
            return Err(TRUNCATED);
        }
        let view = HbnView {
            transition,
            sensor,
            transition_local,
            sensor_local,
            blr: LocalRegression {
                nu0,
                kappa,
                max_neighbours,
            },
            init,
            plays,
            sensor_memory,
        };
        view.validate()?;
        config.validate()?;
        Ok(TableModel { view, config })
    }
}

fn read_gp<'a>(r: &mut Reader<'a>, version: u32) -> Result<GpView<'a>, CoreError> {
    let profile = match r.int()? {
        0 => Profile::SquaredExponential,
        1 => Profile::Matern52,
        _ => return Err(TRUNCATED),
    };
    let metric = match r.int()? {
        0 => Metric::Isotropic,
        1 => Metric::Ard,
        2 => Metric::Mahalanobis,
        _ => return Err(TRUNCATED),
    };
    let dim = r.size()?;
    let warp_units = r.size()?;
    let direction = match (r.opt()?, r.opt()?) {
        (Some(a), Some(b)) => Some([a, b]),
        (None, None) => None,
        _ => return Err(TRUNCATED),
    };
    let spec = KernelSpec {
        profile,
        metric,
        dim,
        warp_units,
        direction,
    };
    spec.validate()?;
    let n = r.size()?;
    let sparse = r.int()? != 0;
    let mean_input = r.opt()?;
    let n_whiten = r.size()?;
    let n_linear = if version >= 4 { r.size()? } else { 0 };
    let theta = r.reals(spec.n_params())?;
    let whiten = r.reals(n_whiten)?;
    let kernel = Kernel::new(spec, theta, whiten)?;
    let input_mean = r.reals(dim)?;
    let input_scale = r.reals(dim)?;
    let output_mean = r.real()?;
    let output_scale = r.real()?;
    let noise_var = r.real()?;
    let linear = r.reals(n_linear)?;
    let features = r.reals(mul(n, dim)?)?;
    let directions = r.reals(if direction.is_some() { n } else { 0 })?;
    let alpha = r.reals(n)?;
    let alpha_lo = r.reals(n)?;
    let t = tri(n)?;
    let variance = if sparse {
        Variance::Sparse {
            variance_factor: r.reals(t)?,
        }
    } else {
        Variance::Exact {
            chol_packed: r.reals(t)?,
        }
    };
    let view = GpView::new(GpParts {
        kernel,
        input_mean,
        input_scale,
        output_mean,
        output_scale,
        linear,
        features,
        directions,
        alpha,
        alpha_lo,
        variance,
        noise_var,
    })?;
    match mean_input {
        Some(j) => view.with_mean_input(j),
        None => Ok(view),
    }
}

fn read_local<'a>(r: &mut Reader<'a>) -> Result<Neighbourhood<'a>, CoreError> {
    let dim = r.size()?;
    let n = r.size()?;
    let cells = r.size()?;
    let cell_start = r.ints(cells.checked_add(1).ok_or(TRUNCATED)?)?;
    let cell_keys = r.keys(cells)?;
    let inputs = r.reals(mul(n, dim)?)?;
    let targets = r.reals(n)?;
    let origin = r.reals(dim)?;
    let half_window = r.reals(dim)?;
    let input_var = r.reals(dim)?;
    Neighbourhood::new(
        dim,
        NeighbourhoodParts {
            inputs,
            targets,
            cell_keys,
            cell_start,
            origin,
            half_window,
            input_var,
        },
    )
}

// ---- vector models ----

/// The first-measurement prior of a vector model as tables hold it (what
/// [`VectorInitPrior::new`] is built from): training rows `[y (dy), x (dx)]`, each sensor's
/// distance scale, the neighbours averaged and each component's variance floor.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct VectorInitParts<'a> {
    /// Rows `[y (dy), x (dx)]`, row-major.
    pub rows: &'a [f64],
    /// Scale of each sensor's distance (`dy` values).
    pub y_scale: &'a [f64],
    /// Rows averaged.
    pub neighbours: usize,
    /// Floor of each component's variance (`dx` values).
    pub var_floor: &'a [f64],
}

impl<'a> VectorInitParts<'a> {
    /// The checked prior for a model of sizes `dims` ([`VectorInitPrior::new`]).
    pub fn prior(&self, dims: Dims) -> Result<VectorInitPrior<'a>, CoreError> {
        VectorInitPrior::new(
            self.rows,
            dims,
            self.y_scale,
            self.neighbours,
            self.var_floor,
        )
    }
}

/// Writes a vector model as tables into `sink`: the sizes, the settings (the entries of the
/// model's sizes only), one GP per state component and per sensor (as the scalar tables write
/// a GP), the prior of `x_0` from `init` (the view's own `init` is not read: its parts are
/// private to the step) and the plays. `split_factors[i]` puts the variance factor of GP `i`
/// (transitions first, then sensors; missing entries count as `false`) in the split ranges, as
/// [`encode_with`] does for a scalar model. Fails on an invalid view or settings, or a count
/// that exceeds `u32`.
pub fn encode_vector<S: TableSink>(
    view: &VectorView<'_>,
    init: Option<&VectorInitParts<'_>>,
    config: &VectorConfig,
    split_factors: &[bool],
    sink: &mut S,
) -> Result<(), CoreError> {
    view.validate()?;
    config.validate(view.dims)?;
    if let Some(init) = init {
        init.prior(view.dims)?;
    }
    let mut count_only = Writer::<S> {
        sink: None,
        reals: 0,
        split: Split::default(),
        open: None,
        limit: MAX_VECTOR_SPLIT_RANGES,
    };
    write_vector_tables(
        view,
        init,
        config,
        split_factors,
        &Split::default(),
        &mut count_only,
    )?;
    let split = count_only.split;
    let mut writer = Writer {
        sink: Some(sink),
        reals: 0,
        split: Split::default(),
        open: None,
        limit: MAX_VECTOR_SPLIT_RANGES,
    };
    write_vector_tables(view, init, config, split_factors, &split, &mut writer)
}

fn write_vector_tables<S: TableSink>(
    view: &VectorView<'_>,
    init: Option<&VectorInitParts<'_>>,
    config: &VectorConfig,
    split_factors: &[bool],
    split: &Split,
    w: &mut Writer<'_, S>,
) -> Result<(), CoreError> {
    let d = view.dims;
    w.int(VECTOR_MAGIC);
    w.int(VECTOR_VERSION);
    w.int(count(split.len)?);
    for [start, len] in split.ranges.iter().take(split.len) {
        w.int(*start);
        w.int(*len);
    }
    w.int(mode_code(config.mode));
    w.int(count(d.inputs)?);
    w.int(count(d.states)?);
    w.int(count(d.sensors)?);
    w.int(u32::from(init.is_some()));
    let c = config;
    w.begin_split();
    for v in [
        c.q_floor,
        c.r_floor,
        c.p_min,
        c.p_max,
        c.jac_max,
        c.innovation_min,
        c.nis_gate,
        c.q_scale,
        c.r_scale,
    ] {
        w.real(v);
    }
    for i in 0..d.states {
        let (lo, hi) = c.x_bounds.get(i).copied().unwrap_or((0.0, 0.0));
        for v in [
            lo,
            hi,
            at(&c.x0_mean, i),
            at(&c.x0_var, i),
            at(&c.qx_model_floor, i),
            at(&c.std_scale, i),
        ] {
            w.real(v);
        }
    }
    for j in 0..d.sensors {
        let (lo, hi) = c.y_bounds.get(j).copied().unwrap_or((0.0, 0.0));
        for v in [lo, hi, at(&c.r_model_floor, j)] {
            w.real(v);
        }
    }
    w.end_split()?;
    for (i, gp) in view.transitions.iter().chain(view.sensors).enumerate() {
        encode_gp(gp, split_factors.get(i).copied().unwrap_or(false), w)?;
    }
    if let Some(init) = init {
        let width = d.sensors + d.states;
        w.int(count(init.rows.len() / width.max(1))?);
        w.int(count(init.neighbours)?);
        w.begin_split();
        for v in init.y_scale.iter().chain(init.var_floor) {
            w.real(*v);
        }
        w.end_split()?;
        for v in init.rows {
            w.real(*v);
        }
    }
    w.begin_split();
    w.int(count(view.plays.radii().len())?);
    for &r in view.plays.radii() {
        w.real(r);
    }
    w.int(count(view.plays.lags().len())?);
    for &a in view.plays.lags() {
        w.real(a);
    }
    w.end_split()?;
    w.int(END);
    Ok(())
}

/// A vector model's constant tables, borrowed: the layout and the reals (widened to `f64` for
/// an `f32` export, see [`widen`]). A vector model has no local regression, so no keys.
#[derive(Clone, Copy, Debug)]
pub struct VectorTables<'a> {
    /// Structural integers.
    pub layout: &'a [u32],
    /// Real numbers.
    pub reals: &'a [f64],
}

/// What [`VectorTables::model`] returns: the GP views, plays, prior and settings of a vector
/// model. It holds the GP views the [`VectorView`] borrows ([`VectorTableModel::view`]), so it
/// is the storage a firmware keeps (a `static`, a stack value or a C filter's memory); nothing
/// in it points into itself, so it may be moved or copied.
#[derive(Clone, Copy, Debug)]
pub struct VectorTableModel<'a> {
    /// The model's sizes.
    pub dims: Dims,
    /// The filter settings (mode included; the entries past the sizes hold the defaults of
    /// [`VectorTableModel::view`]'s unused components: box `(0, 1)`, variance and scale 1).
    pub config: VectorConfig,
    /// The memory operators.
    pub plays: Plays,
    /// The first-measurement prior, if the tables hold one.
    pub init: Option<VectorInitPrior<'a>>,
    transitions: [GpView<'a>; MAX_STATES],
    sensors: [GpView<'a>; MAX_SENSORS],
}

impl<'a> VectorTableModel<'a> {
    /// The model view the vector step reads ([`crate::VectorEkf::new`],
    /// [`crate::VectorEstimator::new`]), borrowing this model's GP views.
    pub fn view(&self) -> VectorView<'_> {
        VectorView {
            dims: self.dims,
            transitions: self.transitions.get(..self.dims.states).unwrap_or(&[]),
            sensors: self.sensors.get(..self.dims.sensors).unwrap_or(&[]),
            plays: self.plays,
            init: self.init,
        }
    }

    /// Scratch values the step needs ([`VectorView::scratch_len`]).
    pub fn scratch_len(&self) -> usize {
        self.view().scratch_len()
    }
}

/// Scratch values the vector step needs for the model in `layout`
/// ([`VectorView::scratch_len`] of its view), read from the layout alone, as [`scratch_len`]
/// does for a scalar model.
pub fn vector_scratch_len(layout: &[u32]) -> Result<usize, CoreError> {
    let mut r = Reader {
        ints: layout,
        keys: &[],
        reals: &[],
    };
    r.vector_header()?;
    r.split_pairs_upto(MAX_VECTOR_SPLIT_RANGES)?;
    let _mode = r.int()?;
    let dims = Dims::new(r.size()?, r.size()?, r.size()?)?;
    let _has_init = r.int()?;
    let mut len = 0;
    // Each GP's integers: profile, metric, dim, warp units, direction (2), n, sparse, mean
    // input, whitening length, linear mean's length.
    for _ in 0..dims.states + dims.sensors {
        r.ints(6)?;
        let n = r.size()?;
        let sparse = r.int()? != 0;
        r.ints(3)?;
        len = len.max(crate::gp::predict_scratch(n, sparse, crate::gp::Want::ALL));
    }
    Ok(len)
}

impl<'a> VectorTables<'a> {
    /// Reads the vector model back, checking every value once (as the model's own view and
    /// settings are checked: [`VectorView::validate`], [`VectorConfig::validate`]). Fails on
    /// tables of another kind, format or version, truncated or corrupt tables, or values the
    /// constructors reject.
    pub fn model(&self) -> Result<VectorTableModel<'a>, CoreError> {
        let mut r = Reader {
            ints: self.layout,
            keys: &[],
            reals: self.reals,
        };
        r.vector_header()?;
        let split = SplitRanges {
            pairs: r.split_pairs_upto(MAX_VECTOR_SPLIT_RANGES)?,
        };
        if split.iter().any(|range| range.end > self.reals.len()) {
            return Err(TRUNCATED);
        }
        let mode = match r.int()? {
            0 => Mode::Ekf,
            1 => Mode::EkfBlr,
            2 => Mode::Ukf,
            _ => return Err(TRUNCATED),
        };
        let dims = Dims::new(r.size()?, r.size()?, r.size()?)?;
        let has_init = r.int()? != 0;
        let mut config = VectorConfig {
            mode,
            x_bounds: [(0.0, 1.0); MAX_STATES],
            y_bounds: [(0.0, 1.0); MAX_SENSORS],
            x0_mean: [0.0; MAX_STATES],
            x0_var: [1.0; MAX_STATES],
            qx_model_floor: [0.0; MAX_STATES],
            r_model_floor: [0.0; MAX_SENSORS],
            q_floor: r.real()?,
            r_floor: r.real()?,
            p_min: r.real()?,
            p_max: r.real()?,
            jac_max: r.real()?,
            innovation_min: r.real()?,
            nis_gate: r.real()?,
            q_scale: r.real()?,
            r_scale: r.real()?,
            std_scale: [1.0; MAX_STATES],
        };
        for i in 0..dims.states {
            let [lo, hi, mean, var, floor, std] = r.array::<6>()?;
            set(&mut config.x_bounds, i, (lo, hi));
            set(&mut config.x0_mean, i, mean);
            set(&mut config.x0_var, i, var);
            set(&mut config.qx_model_floor, i, floor);
            set(&mut config.std_scale, i, std);
        }
        for j in 0..dims.sensors {
            let [lo, hi, floor] = r.array::<3>()?;
            set(&mut config.y_bounds, j, (lo, hi));
            set(&mut config.r_model_floor, j, floor);
        }
        let first = read_gp(&mut r, VERSION)?;
        let mut transitions = [first; MAX_STATES];
        for slot in transitions.iter_mut().take(dims.states).skip(1) {
            *slot = read_gp(&mut r, VERSION)?;
        }
        let first = read_gp(&mut r, VERSION)?;
        let mut sensors = [first; MAX_SENSORS];
        for slot in sensors.iter_mut().take(dims.sensors).skip(1) {
            *slot = read_gp(&mut r, VERSION)?;
        }
        let init = if has_init {
            let rows = r.size()?;
            let neighbours = r.size()?;
            let y_scale = r.reals(dims.sensors)?;
            let var_floor = r.reals(dims.states)?;
            let rows = r.reals(mul(rows, dims.sensors + dims.states)?)?;
            Some(
                VectorInitParts {
                    rows,
                    y_scale,
                    neighbours,
                    var_floor,
                }
                .prior(dims)?,
            )
        } else {
            None
        };
        let n = r.size()?;
        if n > crate::play::MAX_PLAYS {
            return Err(TRUNCATED);
        }
        let radii = r.reals(n)?;
        let n = r.size()?;
        if n > crate::play::MAX_PLAYS {
            return Err(TRUNCATED);
        }
        let plays = Plays::with_lags(radii, r.reals(n)?)?;
        if r.int()? != END || !r.ints.is_empty() || !r.reals.is_empty() {
            return Err(TRUNCATED);
        }
        let model = VectorTableModel {
            dims,
            config,
            plays,
            init,
            transitions,
            sensors,
        };
        model.view().validate()?;
        config.validate(dims)?;
        Ok(model)
    }
}

/// Sets entry `i` of `v` (no-op past its end).
fn set<T>(v: &mut [T], i: usize, x: T) {
    if let Some(slot) = v.get_mut(i) {
        *slot = x;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn layout(pairs: &[u32]) -> [u32; 16] {
        let mut l = [0; 16];
        l[0] = MAGIC;
        l[1] = VERSION;
        l[2] = (pairs.len() / 2) as u32;
        l[3..3 + pairs.len()].copy_from_slice(pairs);
        l
    }

    /// `widen` adds the low parts (after the widened values) to the values of the split
    /// ranges, in order, and leaves the others as rounded.
    #[test]
    fn widen_adds_the_low_parts_of_the_split_ranges() {
        let l = layout(&[0, 2, 3, 1]);
        assert_eq!(split_ranges(&l).unwrap().total(), 3);
        let reals = [1.0f32, 2.0, 3.0, 4.0, 5.0, 0.25, 0.5, 0.125];
        assert_eq!(widen_scratch(&l, reals.len()).unwrap(), 5);
        let mut out = [0.0; 8];
        let wide = widen(&l, &reals, &mut out).unwrap();
        assert_eq!(wide, [1.25, 2.5, 3.0, 4.125, 5.0]);
        // Too little memory, and too few reals for the low parts.
        assert!(widen(&l, &reals, &mut [0.0; 4]).is_err());
        assert!(widen(&l, &reals[..2], &mut out).is_err());
        // A range past the widened values.
        assert!(widen(&layout(&[5, 2]), &reals, &mut out).is_err());
    }

    /// Ranges must be increasing, apart and non-empty, and at most `MAX_SPLIT_RANGES`; tables
    /// of version 5 have none.
    #[test]
    fn bad_split_ranges_are_rejected() {
        assert!(split_ranges(&layout(&[0, 2, 1, 1])).is_err());
        assert!(split_ranges(&layout(&[3, 1, 0, 1])).is_err());
        assert!(split_ranges(&layout(&[0, 0])).is_err());
        let mut many = layout(&[]);
        many[2] = MAX_SPLIT_RANGES as u32 + 1;
        assert!(split_ranges(&many).is_err());
        let mut v5 = layout(&[0, 2]);
        v5[1] = 5;
        assert_eq!(split_ranges(&v5).unwrap().total(), 0);
        let mut foreign = layout(&[]);
        foreign[0] = 7;
        assert!(split_ranges(&foreign).is_err());
    }
}
