//! Local Bayesian linear regression (thesis Sec. 4.3), allocation-free.
//!
//! Around the current operating point `z`, the training samples whose every coordinate lies
//! within `+-half_window_j` of `z_j` are regressed on their deviation from `z` with an intercept:
//!
//! `Y_i = t_i - mu_GP(z) = [1, x_i - z] B + e_i`, `e_i ~ N(0, Sigma)` (one output: `m = 1`).
//!
//! Conjugate Normal-inverse-Wishart prior from the GP:
//! `B_bar = [0, grad mu_GP(z)]`, `Lambda0 = diag(Sigma_hat / s_epi^2, kappa S_x)`: the slopes'
//! prior weighs like `kappa` samples spread as the data (`S_x` the empirical input variance),
//! and the intercept's prior variance `Sigma / Lambda0_00` equals the GP's own latent variance
//! `s_epi^2` at `z` (where the GP is sure of its mean, the neighbours cannot move it; where it
//! is unsure, they can),
//! `Sigma ~ IW(nu0, V0)` with `V0 = (nu0 - m - 1) Sigma_hat` and `Sigma_hat` the GP's learned
//! noise variance. This scaling makes `E[Sigma] = Sigma_hat` under the prior. The EKF adds the
//! GP's latent variance to `E[Sigma]` itself, so `Sigma_hat` leaves it out (the thesis' "GP
//! predictive variance" would count it twice); an empty window returns the prior exactly and the
//! EKF+BLR step then equals the plain EKF's bit for bit.
//!
//! Posterior: `Lambda_n = Lambda0 + X^T X`, `B_n = Lambda_n^{-1} (Lambda0 B_bar + X^T Y)`,
//! `nu_n = nu0 + n`, `V_n = V0 + (Y - X B_n)^T (Y - X B_n) + (B_n - B_bar)^T Lambda0 (B_n - B_bar)`,
//! `E[Sigma] = V_n / (nu_n - m - 1)`. The intercept of `B_n` corrects the GP mean at `z`; its
//! slopes are the Jacobian row; `E[Sigma]` is the noise variance.
//!
//! The neighbourhood query uses a uniform grid built at training time (cells as wide as the
//! window, so a window touches at most `2^d` cells), keys sorted for binary search, and fixed
//! capacity: at most [`BLR_MAX_NEIGHBOURS`] nearest samples (ties by index), returned in index
//! order, from at most [`BLR_MAX_SCAN`] candidates. Time and memory are bounded.

use crate::CoreError;
use crate::kernel::{MAX_DIM, at, clamp_to, set};

/// Capacity of the neighbour buffer.
pub const BLR_MAX_NEIGHBOURS: usize = 48;
/// Most candidates examined per query.
pub const BLR_MAX_SCAN: usize = 2048;
/// Largest input dimension the local regression supports (the HBN's transition has 4).
pub const BLR_MAX_DIM: usize = 4;
const P: usize = BLR_MAX_DIM + 1;

/// Bits per coordinate in a cell key.
pub const CELL_BITS: u32 = 16;

/// Settings of the local regression (checked by [`LocalRegression::validate`]).
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub struct LocalRegression {
    /// Prior degrees of freedom `nu0` (`> 2`): how many samples the GP's noise level weighs.
    pub nu0: f64,
    /// Prior weight `kappa` (`> 0`) of the GP gradient, in samples spread like the data.
    pub kappa: f64,
    /// Most neighbours used (`1..=BLR_MAX_NEIGHBOURS`).
    pub max_neighbours: usize,
}

impl Default for LocalRegression {
    fn default() -> Self {
        Self {
            nu0: 20.0,
            kappa: 1.0,
            max_neighbours: 32,
        }
    }
}

impl LocalRegression {
    /// Checks the settings once.
    pub fn validate(&self) -> Result<(), CoreError> {
        if !(self.nu0.is_finite() && self.nu0 > 2.0) {
            return Err(CoreError::InvalidSpec("BLR nu0 must be > 2"));
        }
        if !(self.kappa.is_finite() && self.kappa > 0.0) {
            return Err(CoreError::InvalidSpec("BLR kappa must be > 0"));
        }
        if self.max_neighbours == 0 || self.max_neighbours > BLR_MAX_NEIGHBOURS {
            return Err(CoreError::InvalidSpec(
                "BLR max_neighbours must be in 1..=BLR_MAX_NEIGHBOURS",
            ));
        }
        Ok(())
    }

    /// The posterior at `z` given the GP's mean, mean gradient and predictive variance there.
    pub fn posterior(
        &self,
        nb: &Neighbourhood<'_>,
        z: &[f64],
        gp_mean: f64,
        gp_grad: &[f64],
        gp_latent_var: f64,
        gp_noise_var: f64,
    ) -> Posterior {
        let d = nb.dim.min(z.len()).min(gp_grad.len());
        let mut idx = [0u32; BLR_MAX_NEIGHBOURS];
        // `validate` keeps `max_neighbours` in `1..=BLR_MAX_NEIGHBOURS`; a caller that skipped
        // it gets the buffer's capacity instead of a panic.
        let cap = self.max_neighbours.min(BLR_MAX_NEIGHBOURS);
        let (n, capped) = match idx.get_mut(..cap) {
            Some(buf) => nb.query(z, buf),
            None => (0, false),
        };
        let m_out = 1.0;
        // Prior.
        let mut b_bar = [0.0; P];
        for (b, g) in b_bar.iter_mut().skip(1).zip(gp_grad).take(d) {
            *b = *g;
        }
        // The prior noise level is the GP's learned noise alone: the EKF adds the GP's latent
        // (epistemic) variance to the BLR noise itself, so including it here would count it
        // twice. The latent variance enters as the intercept's prior variance below.
        let sigma_hat = gp_noise_var.max(0.0);
        let sigma_hat = if sigma_hat.is_finite() && sigma_hat > 0.0 {
            sigma_hat
        } else {
            f64::MIN_POSITIVE
        };
        if n == 0 {
            // No local data: the posterior is the prior, exactly (the EKF+BLR step then equals
            // the plain EKF's bit for bit).
            return Posterior::prior(gp_grad, d, sigma_hat, n, capped);
        }
        let mut lambda0 = [0.0; P];
        // Intercept prior variance Sigma / Lambda0_00 = the GP's own uncertainty about its mean.
        let latent = gp_latent_var.max(sigma_hat * 1e-12);
        // `clamp_to`, not `f64::clamp`: an unvalidated `kappa` above 1e12 or NaN must not panic.
        lambda0[0] = clamp_to(sigma_hat / latent, self.kappa, 1e12);
        for (l, v) in lambda0.iter_mut().skip(1).zip(nb.input_var).take(d) {
            *l = self.kappa * v;
        }
        for l in lambda0.iter_mut().skip(1 + d) {
            *l = 1.0; // padding: unused regressors stay at their zero prior
        }
        let v0 = (self.nu0 - m_out - 1.0) * sigma_hat;

        // Sufficient statistics: X^T X, X^T Y, Y^T Y.
        let mut xtx = [[0.0; P]; P];
        let mut xty = [0.0; P];
        let mut yty = 0.0;
        for &i in idx.get(..n).unwrap_or(&[]) {
            let i = i as usize;
            // `query` returns indices of rows that exist; skip anything else.
            let start = i * nb.dim;
            let (Some(x_i), Some(&t_i)) = (nb.inputs.get(start..start + d), nb.targets.get(i))
            else {
                continue;
            };
            let mut row = [0.0; P];
            row[0] = 1.0;
            for ((r, x), zj) in row.iter_mut().skip(1).zip(x_i).zip(z) {
                *r = x - zj;
            }
            let y = t_i - gp_mean;
            for ((xty_a, ra), xtx_a) in xty.iter_mut().zip(&row).zip(xtx.iter_mut()) {
                *xty_a += ra * y;
                for (xtx_ab, rb) in xtx_a.iter_mut().zip(&row) {
                    *xtx_ab += ra * rb;
                }
            }
            yty += y * y;
        }
        // Lambda_n and its right-hand side.
        let mut lam_n = xtx;
        let mut rhs = xty;
        for (a, ((lam_a, rhs_a), (l0, bb))) in lam_n
            .iter_mut()
            .zip(rhs.iter_mut())
            .zip(lambda0.iter().zip(&b_bar))
            .enumerate()
        {
            if let Some(diag) = lam_a.get_mut(a) {
                *diag += l0;
            }
            *rhs_a += l0 * bb;
        }
        let Some(b_n) = solve_spd(&lam_n, &rhs) else {
            return Posterior::prior(gp_grad, d, sigma_hat, n, capped);
        };
        // Residual sum of squares from the statistics: Y^T Y - 2 B^T X^T Y + B^T X^T X B.
        let mut rss = yty;
        for ((bn_a, xty_a), xtx_a) in b_n.iter().zip(&xty).zip(&xtx) {
            rss -= 2.0 * bn_a * xty_a;
            for (xtx_ab, bn_b) in xtx_a.iter().zip(&b_n) {
                rss += bn_a * xtx_ab * bn_b;
            }
        }
        let mut prior_dev = 0.0;
        for ((bn_a, bb_a), l0_a) in b_n.iter().zip(&b_bar).zip(&lambda0) {
            let dv = bn_a - bb_a;
            prior_dev += dv * l0_a * dv;
        }
        let v_n = v0 + rss.max(0.0) + prior_dev.max(0.0);
        let nu_n = self.nu0 + n as f64;
        let mut grad = [0.0; MAX_DIM];
        for (g, b) in grad.iter_mut().zip(b_n.iter().skip(1)).take(d) {
            *g = *b;
        }
        Posterior {
            intercept: b_n[0],
            grad,
            noise: v_n / (nu_n - m_out - 1.0),
            n,
            capped,
        }
    }
}

/// Result of one local regression.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Posterior {
    /// Posterior intercept: correction of the GP mean at the operating point.
    pub intercept: f64,
    /// Posterior slopes: the Jacobian row (first `dim` entries).
    pub grad: [f64; MAX_DIM],
    /// Posterior expected noise variance `E[Sigma]`.
    pub noise: f64,
    /// Neighbours used.
    pub n: usize,
    /// Whether the neighbour cap or the scan cap was reached.
    pub capped: bool,
}

impl Posterior {
    fn prior(gp_grad: &[f64], d: usize, sigma_hat: f64, n: usize, capped: bool) -> Self {
        let mut grad = [0.0; MAX_DIM];
        for (g, v) in grad.iter_mut().zip(gp_grad).take(d) {
            *g = *v;
        }
        Self {
            intercept: 0.0,
            grad,
            noise: sigma_hat,
            n,
            capped,
        }
    }
}

/// Training samples of one GP with a grid index, as borrowed slices (built by `hbn-model`).
#[derive(Clone, Copy, Debug)]
pub struct Neighbourhood<'a> {
    dim: usize,
    inputs: &'a [f64],
    targets: &'a [f64],
    cell_keys: &'a [u64],
    cell_start: &'a [u32],
    origin: &'a [f64],
    half_window: &'a [f64],
    input_var: &'a [f64],
}

/// The slices a [`Neighbourhood`] is built from.
#[derive(Clone, Copy, Debug)]
pub struct NeighbourhoodParts<'a> {
    /// Inputs, `N x dim` row-major, grouped by cell in key order.
    pub inputs: &'a [f64],
    /// Targets (`N`), same order.
    pub targets: &'a [f64],
    /// Sorted, distinct cell keys (`C`).
    pub cell_keys: &'a [u64],
    /// Offsets: cell `c` holds samples `cell_start[c]..cell_start[c + 1]` (`C + 1`).
    pub cell_start: &'a [u32],
    /// Grid origin (`dim`).
    pub origin: &'a [f64],
    /// Window half-widths (`dim`, `> 0`); cells are `2 * half_window` wide.
    pub half_window: &'a [f64],
    /// Empirical input variance `S_x` (`dim`, `> 0`).
    pub input_var: &'a [f64],
}

impl<'a> Neighbourhood<'a> {
    /// Checks the index once.
    pub fn new(dim: usize, parts: NeighbourhoodParts<'a>) -> Result<Self, CoreError> {
        if dim == 0 || dim > BLR_MAX_DIM {
            return Err(CoreError::InvalidSpec(
                "local regression supports 1..=4 inputs",
            ));
        }
        let n = parts.targets.len();
        let c = parts.cell_keys.len();
        let eq = |got: usize, expected: usize| {
            if got == expected {
                Ok(())
            } else {
                Err(CoreError::DimensionMismatch { expected, got })
            }
        };
        eq(parts.inputs.len(), n * dim)?;
        eq(parts.cell_start.len(), c + 1)?;
        eq(parts.origin.len(), dim)?;
        eq(parts.half_window.len(), dim)?;
        eq(parts.input_var.len(), dim)?;
        if parts.cell_start.first() != Some(&0)
            || parts.cell_start.last().map(|&v| v as usize) != Some(n)
        {
            return Err(CoreError::InvalidSpec(
                "cell offsets must start at 0 and end at N",
            ));
        }
        if parts
            .cell_start
            .windows(2)
            .any(|w| matches!(w, [a, b] if a > b))
            || parts
                .cell_keys
                .windows(2)
                .any(|w| matches!(w, [a, b] if a >= b))
        {
            return Err(CoreError::InvalidSpec(
                "cell keys must increase strictly and offsets must not decrease",
            ));
        }
        let pos = |s: &[f64]| s.iter().all(|v| v.is_finite() && *v > 0.0);
        if !pos(parts.half_window) || !pos(parts.input_var) {
            return Err(CoreError::InvalidSpec(
                "window half-widths and input variances must be > 0",
            ));
        }
        if !parts
            .inputs
            .iter()
            .chain(parts.targets)
            .chain(parts.origin)
            .all(|v| v.is_finite())
        {
            return Err(CoreError::NonFinite);
        }
        Ok(Self {
            dim,
            inputs: parts.inputs,
            targets: parts.targets,
            cell_keys: parts.cell_keys,
            cell_start: parts.cell_start,
            origin: parts.origin,
            half_window: parts.half_window,
            input_var: parts.input_var,
        })
    }

    /// The slices this index was built from (what [`Neighbourhood::new`] checked): for
    /// exporting a model as constant tables.
    pub fn parts(&self) -> NeighbourhoodParts<'a> {
        NeighbourhoodParts {
            inputs: self.inputs,
            targets: self.targets,
            cell_keys: self.cell_keys,
            cell_start: self.cell_start,
            origin: self.origin,
            half_window: self.half_window,
            input_var: self.input_var,
        }
    }

    /// Input dimension.
    pub fn dim(&self) -> usize {
        self.dim
    }

    /// Grid cell coordinate of value `v` on axis `j`.
    #[inline]
    pub fn cell_coord(origin: f64, half_window: f64, v: f64) -> u64 {
        let q = libm::floor((v - origin) / (2.0 * half_window));
        let max = ((1u64 << CELL_BITS) - 1) as f64;
        if q.is_nan() {
            0
        } else {
            q.clamp(0.0, max) as u64
        }
    }

    /// Key of a cell from its coordinates.
    #[inline]
    pub fn key(coords: &[u64]) -> u64 {
        coords.iter().fold(0u64, |k, &c| (k << CELL_BITS) | c)
    }

    /// Indices of the samples in the window around `z`, in index order: all of them when they
    /// fit in `out`, else the `out.len()` nearest (of equal distances, the lower index), and
    /// whether a cap was reached.
    pub fn query(&self, z: &[f64], out: &mut [u32]) -> (usize, bool) {
        // One copy per input dimension, so the per-sample loop has fixed-size arrays.
        match self.dim {
            1 => self.query_in::<1>(z, out),
            2 => self.query_in::<2>(z, out),
            3 => self.query_in::<3>(z, out),
            4 => self.query_in::<4>(z, out),
            _ => (0, false),
        }
    }

    /// [`Neighbourhood::query`] for `D` inputs.
    ///
    /// The window touches one or two cells per axis. The cells are visited in key order: for
    /// each combination of the first `D - 1` axes one binary search (from where the last one
    /// ended) finds the cell at the last axis' lower coordinate, and its neighbour along that
    /// axis, whose key is one more, is the next cell in the index when it exists, so the two
    /// are one run of samples.
    fn query_in<const D: usize>(&self, z: &[f64], out: &mut [u32]) -> (usize, bool) {
        let (Some(z), Some(origin), Some(half_window)) = (
            z.first_chunk::<D>(),
            self.origin.first_chunk::<D>(),
            self.half_window.first_chunk::<D>(),
        ) else {
            return (0, false);
        };
        if !z.iter().all(|v| v.is_finite()) || out.is_empty() {
            return (0, false);
        }
        let mut lo = [0u64; D];
        let mut span = [0u64; D];
        let mut inv_half_window = [0.0; D];
        let axes = z.iter().zip(origin).zip(half_window);
        for (((lo_j, span_j), inv), ((&zj, &origin), &hw)) in lo
            .iter_mut()
            .zip(span.iter_mut())
            .zip(inv_half_window.iter_mut())
            .zip(axes)
        {
            let a = Self::cell_coord(origin, hw, zj - hw);
            let b = Self::cell_coord(origin, hw, zj + hw);
            *lo_j = a;
            *span_j = b.saturating_sub(a).min(1) + 1; // 1 or 2 cells per axis
            *inv = 1.0 / hw;
        }
        let Some((&span_last, span_first)) = span.split_last() else {
            return (0, false);
        };
        let mut near = Nearest::new(out);
        let mut scanned = 0usize;
        let mut from = 0usize;
        let combos = 1usize << (D - 1);
        'cells: for mask in 0..combos {
            // Axis 0 is the key's most significant part, so it takes the mask's highest bit.
            let mut coords = lo;
            for (j, (c, &span_j)) in coords.iter_mut().zip(span_first).enumerate() {
                let bit = ((mask >> (D - 2 - j)) & 1) as u64;
                if bit >= span_j {
                    continue 'cells;
                }
                *c += bit;
            }
            let key_lo = Self::key(&coords);
            let key_hi = key_lo + (span_last - 1);
            let rest = self.cell_keys.get(from..).unwrap_or(&[]);
            let c = from + rest.partition_point(|&k| k < key_lo);
            from = c;
            let mut c_end = c;
            while c_end < c + 2 && self.cell_keys.get(c_end).is_some_and(|&k| k <= key_hi) {
                c_end += 1;
            }
            // `new` checked `cell_start` has one more entry than `cell_keys`.
            let (Some(&start), Some(&end)) = (self.cell_start.get(c), self.cell_start.get(c_end))
            else {
                continue;
            };
            let (start, end) = (start as usize, end as usize);
            let budget = BLR_MAX_SCAN - scanned;
            let take = (end - start).min(budget);
            let Some(rows) = self.inputs.get(start * D..(start + take) * D) else {
                break;
            };
            for (i, row) in (start..).zip(rows.chunks_exact(D)) {
                let Some(row) = row.first_chunk::<D>() else {
                    break;
                };
                // Scaled offsets by multiplication and without an early exit.
                let mut r2 = 0.0;
                let mut widest = 0.0f64;
                for ((x, zj), inv) in row.iter().zip(z).zip(&inv_half_window) {
                    let t = (x - zj) * inv;
                    r2 += t * t;
                    widest = widest.max(t.abs());
                }
                // Outside the window on some axis (or a NaN offset, which `max` would skip).
                if widest > 1.0 || r2.is_nan() {
                    continue;
                }
                near.offer(r2, i as u32);
            }
            scanned += take;
            if take < end - start {
                near.capped = true;
                break;
            }
        }
        (near.count, near.capped)
    }
}

/// The nearest samples seen so far, in the caller's buffer in the order they came (the
/// query offers them in index order). Until the buffer is full each is appended; then one
/// nearer than the farthest kept (the later one of equal distances, which has the higher
/// index) replaces it: the farthest leaves, those after it move up one place, and the new
/// one goes last, so the order stays that of the index. No sort: most windows hold about as
/// many samples as the buffer, and a sorted insertion would shift half the buffer for each.
struct Nearest<'o> {
    dist: [f64; BLR_MAX_NEIGHBOURS],
    out: &'o mut [u32],
    cap: usize,
    count: usize,
    /// Where the farthest kept sample is (meaningful once the buffer is full).
    worst: usize,
    capped: bool,
}

impl<'o> Nearest<'o> {
    fn new(out: &'o mut [u32]) -> Self {
        let cap = out.len().min(BLR_MAX_NEIGHBOURS);
        Self {
            dist: [f64::INFINITY; BLR_MAX_NEIGHBOURS],
            out,
            cap,
            count: 0,
            worst: 0,
            capped: false,
        }
    }

    /// Keeps sample `iu` (higher than every index offered before) at squared distance `r2`
    /// (not NaN) if it is among the `cap` nearest.
    #[inline(always)]
    fn offer(&mut self, r2: f64, iu: u32) {
        let cap = self.cap;
        if self.count < cap {
            if let (Some(d), Some(o)) =
                (self.dist.get_mut(self.count), self.out.get_mut(self.count))
            {
                *d = r2;
                *o = iu;
                self.count += 1;
            }
            if self.count == cap {
                self.worst = self.farthest();
            }
            return;
        }
        self.capped = true;
        // Equal distance loses: the kept sample has the lower index.
        if !self.dist.get(self.worst).is_some_and(|&d| r2 < d) {
            return;
        }
        // `worst < cap <= min(out.len(), BLR_MAX_NEIGHBOURS)`: every `get` succeeds.
        for p in self.worst..cap - 1 {
            if let (Some(&d), Some(&o)) = (self.dist.get(p + 1), self.out.get(p + 1))
                && let (Some(dp), Some(op)) = (self.dist.get_mut(p), self.out.get_mut(p))
            {
                *dp = d;
                *op = o;
            }
        }
        if let (Some(d), Some(o)) = (self.dist.get_mut(cap - 1), self.out.get_mut(cap - 1)) {
            *d = r2;
            *o = iu;
        }
        self.worst = self.farthest();
    }

    /// Position of the farthest kept sample, the last of equal distances.
    #[inline(always)]
    fn farthest(&self) -> usize {
        let mut worst = 0;
        let mut d_worst = f64::NEG_INFINITY;
        for (p, &d) in self.dist.iter().enumerate().take(self.count) {
            if d >= d_worst {
                d_worst = d;
                worst = p;
            }
        }
        worst
    }
}

/// Solves `A x = b` for a small symmetric positive-definite `A` by Cholesky.
///
/// Indices are loop counters below `P` on `P`-sized arrays; `m` and `set_m` read and write
/// through `get` so that no panic path exists (the optimiser removes the checks).
fn solve_spd(a: &[[f64; P]; P], b: &[f64; P]) -> Option<[f64; P]> {
    #[inline(always)]
    fn m(a: &[[f64; P]; P], i: usize, j: usize) -> f64 {
        a.get(i).map_or(0.0, |r| at(r, j))
    }
    #[inline(always)]
    fn set_m(a: &mut [[f64; P]; P], i: usize, j: usize, v: f64) {
        if let Some(r) = a.get_mut(i) {
            set(r, j, v);
        }
    }
    let mut l = [[0.0; P]; P];
    for i in 0..P {
        for j in 0..=i {
            let mut s = m(a, i, j);
            for k in 0..j {
                s -= m(&l, i, k) * m(&l, j, k);
            }
            if i == j {
                if s.is_nan() || s <= 0.0 || !s.is_finite() {
                    return None;
                }
                set_m(&mut l, i, i, crate::simd::sqrt(s));
            } else {
                let v = s / m(&l, j, j);
                set_m(&mut l, i, j, v);
            }
        }
    }
    let mut y = [0.0; P];
    for i in 0..P {
        let mut s = at(b, i);
        for k in 0..i {
            s -= m(&l, i, k) * at(&y, k);
        }
        set(&mut y, i, s / m(&l, i, i));
    }
    let mut x = [0.0; P];
    for i in (0..P).rev() {
        let mut s = at(&y, i);
        for k in i + 1..P {
            s -= m(&l, k, i) * at(&x, k);
        }
        set(&mut x, i, s / m(&l, i, i));
    }
    Some(x)
}

#[cfg(test)]
mod tests {
    extern crate std;
    use super::*;
    use std::vec::Vec;

    /// Builds a grid index the way `hbn-model` does (test-only helper).
    struct Owned {
        inputs: Vec<f64>,
        targets: Vec<f64>,
        keys: Vec<u64>,
        start: Vec<u32>,
        origin: Vec<f64>,
        hw: Vec<f64>,
        var: Vec<f64>,
    }

    fn build(dim: usize, x: &[f64], y: &[f64], hw: &[f64], var: &[f64]) -> Owned {
        let n = y.len();
        let origin: Vec<f64> = (0..dim)
            .map(|j| (0..n).map(|i| x[i * dim + j]).fold(f64::INFINITY, f64::min))
            .collect();
        let mut order: Vec<(u64, usize)> = (0..n)
            .map(|i| {
                let c: Vec<u64> = (0..dim)
                    .map(|j| Neighbourhood::cell_coord(origin[j], hw[j], x[i * dim + j]))
                    .collect();
                (Neighbourhood::key(&c), i)
            })
            .collect();
        order.sort();
        let mut keys = Vec::new();
        let mut start = Vec::new();
        for (pos, (k, _)) in order.iter().enumerate() {
            if keys.last() != Some(k) {
                keys.push(*k);
                start.push(pos as u32);
            }
        }
        start.push(n as u32);
        Owned {
            inputs: order
                .iter()
                .flat_map(|&(_, i)| x[i * dim..i * dim + dim].to_vec())
                .collect(),
            targets: order.iter().map(|&(_, i)| y[i]).collect(),
            keys,
            start,
            origin,
            hw: hw.to_vec(),
            var: var.to_vec(),
        }
    }

    fn view(o: &Owned, dim: usize) -> Neighbourhood<'_> {
        Neighbourhood::new(
            dim,
            NeighbourhoodParts {
                inputs: &o.inputs,
                targets: &o.targets,
                cell_keys: &o.keys,
                cell_start: &o.start,
                origin: &o.origin,
                half_window: &o.hw,
                input_var: &o.var,
            },
        )
        .unwrap()
    }

    /// Dense closed form of the posterior (m = 1) for comparison.
    #[allow(clippy::too_many_arguments)]
    fn closed_form(
        x: &[[f64; 2]],
        y: &[f64],
        z: [f64; 2],
        mu: f64,
        grad: [f64; 2],
        var: f64,
        l00: f64,
        s: [f64; 2],
        cfg: &LocalRegression,
    ) -> (f64, [f64; 2], f64) {
        let p = 3;
        let mut l0 = [[0.0; 3]; 3];
        l0[0][0] = l00;
        l0[1][1] = cfg.kappa * s[0];
        l0[2][2] = cfg.kappa * s[1];
        let bbar = [0.0, grad[0], grad[1]];
        let rows: Vec<[f64; 3]> = x.iter().map(|r| [1.0, r[0] - z[0], r[1] - z[1]]).collect();
        let ys: Vec<f64> = y.iter().map(|v| v - mu).collect();
        let mut ln = l0;
        let mut rhs = [0.0; 3];
        for a in 0..p {
            rhs[a] = l0[a][a] * bbar[a];
        }
        for (r, yv) in rows.iter().zip(&ys) {
            for a in 0..p {
                rhs[a] += r[a] * yv;
                for b in 0..p {
                    ln[a][b] += r[a] * r[b];
                }
            }
        }
        // 3x3 inverse by cofactors.
        let m = ln;
        let det = m[0][0] * (m[1][1] * m[2][2] - m[1][2] * m[2][1])
            - m[0][1] * (m[1][0] * m[2][2] - m[1][2] * m[2][0])
            + m[0][2] * (m[1][0] * m[2][1] - m[1][1] * m[2][0]);
        let inv = [
            [
                (m[1][1] * m[2][2] - m[1][2] * m[2][1]) / det,
                (m[0][2] * m[2][1] - m[0][1] * m[2][2]) / det,
                (m[0][1] * m[1][2] - m[0][2] * m[1][1]) / det,
            ],
            [
                (m[1][2] * m[2][0] - m[1][0] * m[2][2]) / det,
                (m[0][0] * m[2][2] - m[0][2] * m[2][0]) / det,
                (m[0][2] * m[1][0] - m[0][0] * m[1][2]) / det,
            ],
            [
                (m[1][0] * m[2][1] - m[1][1] * m[2][0]) / det,
                (m[0][1] * m[2][0] - m[0][0] * m[2][1]) / det,
                (m[0][0] * m[1][1] - m[0][1] * m[1][0]) / det,
            ],
        ];
        let bn: Vec<f64> = (0..3)
            .map(|a| (0..3).map(|b| inv[a][b] * rhs[b]).sum())
            .collect();
        let mut v = (cfg.nu0 - 2.0) * var;
        for (r, yv) in rows.iter().zip(&ys) {
            let e = yv - (0..3).map(|a| r[a] * bn[a]).sum::<f64>();
            v += e * e;
        }
        for a in 0..3 {
            v += (bn[a] - bbar[a]) * l0[a][a] * (bn[a] - bbar[a]);
        }
        (bn[0], [bn[1], bn[2]], v / (cfg.nu0 + y.len() as f64 - 2.0))
    }

    #[test]
    fn posterior_equals_closed_form() {
        let x = [
            [0.50, 0.20],
            [0.52, 0.21],
            [0.49, 0.18],
            [0.51, 0.22],
            [0.48, 0.19],
            [0.53, 0.205],
        ];
        let y = [1.0, 1.1, 0.95, 1.08, 0.9, 1.12];
        let flat: Vec<f64> = x.iter().flat_map(|r| r.to_vec()).collect();
        let hw = [0.05, 0.05];
        let s = [0.08, 0.03];
        let o = build(2, &flat, &y, &hw, &s);
        let nb = view(&o, 2);
        let cfg = LocalRegression::default();
        let z = [0.505, 0.2];
        let post = cfg.posterior(&nb, &z, 1.02, &[2.0, 1.0], 0.004, 0.006);
        let (b0, b, noise) =
            closed_form(&x, &y, z, 1.02, [2.0, 1.0], 0.006, 0.006 / 0.004, s, &cfg);
        assert_eq!(post.n, 6);
        assert!(
            (post.intercept - b0).abs() < 1e-12,
            "{} {}",
            post.intercept,
            b0
        );
        assert!((post.grad[0] - b[0]).abs() < 1e-10 && (post.grad[1] - b[1]).abs() < 1e-10);
        assert!(
            (post.noise - noise).abs() < 1e-12 * noise.max(1.0),
            "{} {}",
            post.noise,
            noise
        );
    }

    #[test]
    fn empty_window_gives_the_prior() {
        let x = [0.0, 0.0, 1.0, 1.0];
        let y = [0.0, 1.0];
        let o = build(2, &x, &y, &[0.01, 0.01], &[0.25, 0.25]);
        let nb = view(&o, 2);
        let cfg = LocalRegression::default();
        let post = cfg.posterior(&nb, &[0.5, 0.5], 0.3, &[0.7, -0.2], 0.01, 0.03);
        assert_eq!(post.n, 0);
        assert_eq!(post.intercept, 0.0);
        assert!((post.grad[0] - 0.7).abs() < 1e-15 && (post.grad[1] + 0.2).abs() < 1e-15);
        // E[Sigma] under the prior is the GP's learned noise, exactly: the latent variance
        // (0.01) is not added, because the EKF adds it to the BLR noise itself.
        assert_eq!(post.noise, 0.03);
    }

    #[test]
    fn noise_estimate_converges_to_the_true_level() {
        // y = 2 x1 - x2 + noise(sd 0.1); many samples in a small window.
        let mut rng = crate::rng::Rng::new(9);
        let n = 4000;
        let mut x = Vec::new();
        let mut y = Vec::new();
        for _ in 0..n {
            let a = rng.uniform_in(0.45, 0.55);
            let b = rng.uniform_in(0.15, 0.25);
            x.extend([a, b]);
            y.push(2.0 * a - b + 0.1 * rng.normal());
        }
        let o = build(2, &x, &y, &[0.05, 0.05], &[0.1, 0.1]);
        let nb = view(&o, 2);
        // A weak noise prior (nu0 = 3) so that the 48 neighbours dominate it.
        let cfg = LocalRegression {
            nu0: 3.0,
            max_neighbours: BLR_MAX_NEIGHBOURS,
            ..LocalRegression::default()
        };
        // GP says the noise is tiny (epistemic only): BLR must still find sd 0.1.
        let mut est = 0.0;
        let probes = 200;
        for k in 0..probes {
            let z = [0.47 + 0.06 * (k as f64 / probes as f64), 0.2];
            let post = cfg.posterior(&nb, &z, 2.0 * z[0] - z[1], &[2.0, -1.0], 1e-6, 0.0);
            assert!(post.capped && post.n == BLR_MAX_NEIGHBOURS);
            est += post.noise / probes as f64;
        }
        // nu0 = 3 prior pseudo-samples at 1e-6 vs 48 samples at 0.01: expect ~0.01 * 46/49.
        assert!(
            (est.sqrt() - 0.1).abs() < 0.015,
            "estimated sd {}",
            est.sqrt()
        );
    }

    /// A dense window holds far more samples than the buffer: the query must return exactly the
    /// 48 nearest (ties by index), in index order (checked against a sort of every sample in
    /// the window), for every input dimension.
    #[test]
    fn a_full_window_returns_the_nearest_in_index_order() {
        for d in 1..=BLR_MAX_DIM {
            let mut rng = crate::rng::Rng::new(5 + d as u64);
            let n = 1500;
            // Coarse values make equal distances (ties) common.
            let x: Vec<f64> = (0..n * d)
                .map(|_| (rng.uniform() * 20.0).round() / 20.0)
                .collect();
            let y = vec![0.0; n];
            let hw: Vec<f64> = [0.25, 0.2, 0.3, 0.35][..d].to_vec();
            let o = build(d, &x, &y, &hw, &vec![0.1; d]);
            let nb = view(&o, d);
            let inv: Vec<f64> = hw.iter().map(|h| 1.0 / h).collect();
            let (mut full, mut partial) = (0, 0);
            for _ in 0..40 {
                let z: Vec<f64> = (0..d).map(|_| rng.uniform()).collect();
                let mut want: Vec<(f64, u32)> = (0..n)
                    .filter_map(|i| {
                        let mut r2 = 0.0;
                        let mut widest = 0.0f64;
                        for j in 0..d {
                            // The index keeps its samples in cell order; `out` indexes those.
                            let t = (o.inputs[i * d + j] - z[j]) * inv[j];
                            r2 += t * t;
                            widest = widest.max(t.abs());
                        }
                        (widest <= 1.0).then_some((r2, i as u32))
                    })
                    .collect();
                want.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
                for cap in [BLR_MAX_NEIGHBOURS, 32, 5, 1] {
                    let mut out = vec![0u32; cap];
                    let (k, capped) = nb.query(&z, &mut out);
                    assert_eq!(capped, want.len() > cap, "d = {d}, cap {cap}");
                    if cap == BLR_MAX_NEIGHBOURS {
                        full += usize::from(capped);
                        partial += usize::from(!capped && !want.is_empty());
                    }
                    let mut kept: Vec<u32> = want.iter().take(cap).map(|&(_, i)| i).collect();
                    kept.sort_unstable();
                    assert_eq!(&out[..k], &kept[..], "d = {d}, cap {cap}");
                }
            }
            assert!(full >= 10, "d = {d}: only {full} of 40 windows were full");
            if d == BLR_MAX_DIM {
                assert!(
                    partial >= 5,
                    "d = {d}: only {partial} of 40 windows were partial"
                );
            }
        }
    }

    #[test]
    fn query_is_exact_and_deterministic() {
        let mut rng = crate::rng::Rng::new(2);
        let n = 3000;
        let x: Vec<f64> = (0..n * 3).map(|_| rng.uniform()).collect();
        let y: Vec<f64> = (0..n).map(|i| i as f64).collect();
        let hw = [0.06, 0.08, 0.1];
        let o = build(3, &x, &y, &hw, &[0.1; 3]);
        let nb = view(&o, 3);
        for _ in 0..50 {
            let z = [rng.uniform(), rng.uniform(), rng.uniform()];
            let mut out = [0u32; BLR_MAX_NEIGHBOURS];
            let (k, capped) = nb.query(&z, &mut out);
            let brute = (0..n)
                .filter(|&i| (0..3).all(|j| ((x[i * 3 + j] - z[j]) / hw[j]).abs() <= 1.0))
                .count();
            assert_eq!(k, brute.min(BLR_MAX_NEIGHBOURS));
            assert_eq!(capped, brute > BLR_MAX_NEIGHBOURS);
            let mut out2 = [0u32; BLR_MAX_NEIGHBOURS];
            assert_eq!(nb.query(&z, &mut out2), (k, capped));
            assert_eq!(out, out2);
        }
    }
}
