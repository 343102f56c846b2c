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
//! memory ([`widen_scratch`] values) that the view then borrows.
//!
//! The local training data of EKF+BLR is only written for that mode: the EKF and the UKF read
//! the two GPs, the filter settings and the prior of `x_0`.

use crate::CoreError;
use crate::blr::{LocalRegression, Neighbourhood, NeighbourhoodParts};
use crate::ekf::{EkfConfig, HbnView, InitPrior, Mode};
use crate::gp::{GpParts, GpView, Variance};
use crate::kernel::{Kernel, KernelSpec, Metric, Profile, at};
use crate::play::Plays;

/// First value of every layout: `"HBN1"` as little-endian bytes.
pub const MAGIC: u32 = u32::from_le_bytes(*b"HBN1");
/// Format version written by [`encode`] and read by [`Tables::model`] (3 adds the play
/// operators after the prior of `x_0`; 4 adds each GP's linear mean, its slope count after
/// the whitening length and its slopes after the output scalars; tables of version 2 are read
/// as having no plays, of versions 2 and 3 as having constant means; 5 adds the lags' count and
/// coefficients after the plays, and tables before it are read as having no lags).
pub const VERSION: u32 = 5;
/// Oldest format version [`Tables::model`] reads.
pub const OLDEST_VERSION: u32 = 2;
/// Last value of every layout (catches a truncated or misaligned table).
pub const END: u32 = u32::from_le_bytes(*b"END1");
/// A `u32` standing for "none" (no mean input, no direction factor).
const NONE: u32 = u32::MAX;

const TRUNCATED: CoreError = CoreError::InvalidSpec("model tables are truncated or corrupt");

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

/// `f64` values [`widen`] needs for `reals_f32` `f32` values: one each.
pub const fn widen_scratch(reals_f32: usize) -> usize {
    reals_f32
}

/// Converts `f32` reals into the front of `out` (at least [`widen_scratch`] values) and
/// returns that part, for [`Tables::reals`].
pub fn widen<'w>(reals: &[f32], out: &'w mut [f64]) -> Result<&'w [f64], CoreError> {
    let got = out.len();
    let Some(dst) = out.get_mut(..reals.len()) else {
        return Err(CoreError::ScratchTooSmall {
            needed: reals.len(),
            got,
        });
    };
    for (d, s) in dst.iter_mut().zip(reals) {
        *d = f64::from(*s);
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
/// view has no local data, or a count exceeds `u32`.
pub fn encode<S: TableSink>(
    view: &HbnView<'_>,
    config: &EkfConfig,
    sink: &mut S,
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
    sink.int(MAGIC);
    sink.int(VERSION);
    sink.int(mode_code(config.mode));
    sink.int(u32::from(view.init.is_some()));
    sink.int(u32::from(locals.is_some()));
    sink.int(count(view.blr.max_neighbours)?);
    let c = config;
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
        sink.real(v);
    }
    encode_gp(&view.transition, sink)?;
    encode_gp(&view.sensor, sink)?;
    if let Some((t, s)) = locals {
        encode_local(&t, sink)?;
        encode_local(&s, sink)?;
    }
    if let Some(init) = view.init {
        sink.int(count(init.pairs().len())?);
        sink.int(count(init.neighbours())?);
        sink.real(init.var_floor());
        for p in init.pairs() {
            sink.real(p[0]);
            sink.real(p[1]);
        }
    }
    sink.int(count(view.plays.radii().len())?);
    for &r in view.plays.radii() {
        sink.real(r);
    }
    sink.int(count(view.plays.lags().len())?);
    for &a in view.plays.lags() {
        sink.real(a);
    }
    sink.int(END);
    Ok(())
}

fn encode_gp<S: TableSink>(gp: &GpView<'_>, sink: &mut S) -> Result<(), CoreError> {
    let p = gp.parts();
    let spec = *p.kernel.spec();
    sink.int(match spec.profile {
        Profile::SquaredExponential => 0,
        Profile::Matern52 => 1,
    });
    sink.int(match spec.metric {
        Metric::Isotropic => 0,
        Metric::Ard => 1,
        Metric::Mahalanobis => 2,
    });
    sink.int(count(spec.dim)?);
    sink.int(count(spec.warp_units)?);
    match spec.direction {
        Some([a, b]) => {
            sink.int(count(a)?);
            sink.int(count(b)?);
        }
        None => {
            sink.int(NONE);
            sink.int(NONE);
        }
    }
    sink.int(count(gp.len())?);
    sink.int(u32::from(gp.is_sparse()));
    sink.int(match gp.mean_input() {
        Some(j) => count(j)?,
        None => NONE,
    });
    sink.int(count(p.kernel.whiten().len())?);
    sink.int(count(p.linear.len())?);
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
    for v in arrays.iter().flat_map(|s| s.iter()) {
        sink.real(*v);
    }
    // The mean weights as an f32-representable high part and the rest: their sum is the weight
    // exactly in f64, and to about 48 bits once both are rounded to f32 (see
    // `GpParts::alpha_lo`).
    let weight = |i: usize| at(p.alpha, i) + at(p.alpha_lo, i);
    for i in 0..p.alpha.len() {
        sink.real(split_f32(weight(i)).0);
    }
    for i in 0..p.alpha.len() {
        sink.real(split_f32(weight(i)).1);
    }
    for v in factor {
        sink.real(*v);
    }
    Ok(())
}

/// `v` as `(hi, lo)`: `hi` the nearest `f32` value (as `f64`) and `lo = v - hi`, exact in
/// `f64`, so that `hi + lo == v`; `(v, 0)` where `v` is outside `f32`'s range (the `f32`
/// export then refuses it, as any such real).
fn split_f32(v: f64) -> (f64, f64) {
    // `as` rounds to the nearest `f32` (and saturates to infinity outside its range).
    #[allow(clippy::cast_possible_truncation)]
    let hi = f64::from(v as f32);
    if hi.is_finite() && v.is_finite() {
        (hi, v - hi)
    } else {
        (v, 0.0)
    }
}

fn encode_local<S: TableSink>(nb: &Neighbourhood<'_>, sink: &mut S) -> Result<(), CoreError> {
    let p = nb.parts();
    sink.int(count(nb.dim())?);
    sink.int(count(p.targets.len())?);
    sink.int(count(p.cell_keys.len())?);
    for &s in p.cell_start {
        sink.int(s);
    }
    for &k in p.cell_keys {
        sink.key(k);
    }
    let arrays: [&[f64]; 5] = [p.inputs, p.targets, p.origin, p.half_window, p.input_var];
    for v in arrays.iter().flat_map(|s| s.iter()) {
        sink.real(*v);
    }
    Ok(())
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
    if r.int()? != MAGIC {
        return Err(CoreError::InvalidSpec("not hbn model tables"));
    }
    let version = r.int()?;
    if !(OLDEST_VERSION..=VERSION).contains(&version) {
        return Err(CoreError::InvalidSpec(
            "not hbn model tables of this format version",
        ));
    }
    r.ints(4)?;
    let mut len = 0;
    // The two GPs' integers are adjacent: profile, metric, dim, warp units, direction (2),
    // n, sparse, mean input, whitening length, and (version 4) the linear mean's length.
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
        if r.int()? != MAGIC {
            return Err(CoreError::InvalidSpec(
                "not hbn model tables (the magic number differs)",
            ));
        }
        let version = r.int()?;
        if !(OLDEST_VERSION..=VERSION).contains(&version) {
            return Err(CoreError::InvalidSpec(
                "model tables of another format version: export the model again",
            ));
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
