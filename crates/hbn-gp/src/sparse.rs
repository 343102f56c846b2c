//! The sparse GP: Titsias' (2009) collapsed variational bound ("SGPR"/"VFE") on `m` inducing
//! inputs `Z`, trained on every sample in `O(n m^2)` time and `O(n d + m^2)` memory.
//!
//! With `K_mm = k(Z, Z)`, `K_mn = k(Z, X)`, noise `s2`, `P = K_mn K_nm`, `v = K_mn y`,
//! `L L^T = K_mm`, `B = I + L^{-1} P L^{-T} / s2 = L_B L_B^T` and `c = L_B^{-1} L^{-1} v / s2`:
//!
//! `F = -n/2 ln(2 pi) - sum ln diag(L_B) - n/2 ln s2 - (y^T y / s2 - c^T c) / 2
//!      - (sum_i k(x_i, x_i) - tr(L^{-1} P L^{-T})) / (2 s2)`  (`<=` the exact LML).
//!
//! Every sum over the samples (`P`, `v`, `y^T y`, `sum k_ii`) is a reduction over fixed blocks
//! of rows, computed in parallel and added in block order, so the result is bit-identical
//! whatever the number of threads; no `n x m` matrix is ever held whole.
//!
//! **Gradient.** In the whitened basis `A = L^{-1} K_mn` (`Q = A A^T`), with
//! `gamma = B^{-1} A y / s2` (the prediction weights are `beta = L^{-T} gamma`) and the
//! residuals `r = y - A^T gamma`, the bound's sensitivities are
//! - `dF/dK_mn = L^{-T} ((I - B^{-1}) A + gamma r^T) / s2` (one column per sample, a second
//!   blocked pass),
//! - `dF/dK_mm = -L^{-T} ((I - B^{-1}) Q / s2 + gamma gamma^T) L^{-1} / 2`,
//! - `dF/dk_jj = -1 / (2 s2)`,
//! - `dF/ds2 = (tr(B^{-1} Q) - n s2 + |r|^2 + sum k_jj - tr Q) / (2 s2^2)`,
//! - `dF/d ln s_f^2 = (|gamma|^2 - (tr(B^{-1} Q) + sum k_jj - tr Q) / s2) / 2` in closed form
//!   (the signal variance scales every kernel value),
//!
//! with `I - B^{-1} = B^{-1} Q / s2` formed as a product: no factor is a difference of large
//! terms, which `K_mm^{-1} - Sigma` would be when `K_mm` is ill-conditioned;
//! and the chain rule through each kernel entry gives every hyperparameter and, optionally,
//! every inducing input. `docs/sparse.md` derives them; the tests check them against finite
//! differences, and the bound and predictions against the exact GP (with `Z = X`) and an
//! independent numpy implementation.
//!
//! **Inducing inputs** start from greedy conditional-variance selection (a pivoted Cholesky
//! of the kernel matrix at the starting hyperparameters, Burt et al. 2020): each new point is
//! the sample the current ones explain worst. It needs no random seed, spreads points along a
//! time series where the signal moves, and skips duplicates (the residual variance of a
//! repeated input is zero). It runs on an evenly strided pool of at most
//! [`INIT_POOL_MIN`] (or `32 m`) samples so that its `pool x m` table stays small.

use crate::GpError;
use crate::factor::factor_with_jitter;
use crate::likelihood::{
    EvalMemo, EvalStats, Evaluation, LOG_BOUND, LikelihoodData, Objective, add_pair_theta_grad,
    noise_of, scale_slope, soft_bound_penalty,
};
use crate::model::{GaussianProcess, SparseFactors, StartReport, TrainingReport};
use crate::params::{GpParams, SparseParams};
use crate::train::{
    COST_TOLERANCE_PER_SAMPLE, FitProgress, REFINE_TOLERANCE_PER_SAMPLE, Standardised, multi_start,
    run_lbfgs_with_stall, starting_point,
};
use faer::linalg::matmul::matmul;
use faer::linalg::matmul::triangular::{self, BlockStructure};
use faer::linalg::triangular_inverse::invert_lower_triangular;
use faer::linalg::triangular_solve::{
    solve_lower_triangular_in_place, solve_upper_triangular_in_place,
};
use faer::{Accum, Mat, Par};
use hbn_core::kernel::{
    MAX_DIM, Prepared, Profile, profile_and_slope_with, profiles_and_slopes_with,
};
use hbn_core::{Kernel, Metric};
use rayon::prelude::*;
use std::time::Instant;

/// Rows per block of the blocked reductions over the samples.
pub const BLOCK_ROWS: usize = 1024;
/// Smallest candidate pool of the greedy inducing-point selection.
pub const INIT_POOL_MIN: usize = 8192;

/// The kernel profile with the platform's `sqrt` (training runs on a host; `libm`'s is one
/// scalar instruction in inline assembly that the compiler cannot vectorise).
#[inline(always)]
fn profile_and_slope(profile: Profile, r2: f64) -> (f64, f64) {
    profile_and_slope_with(profile, r2, f64::sqrt)
}

/// The collapsed bound as an optimisation problem. The optimised vector is the kernel's
/// `theta`, the noise parameter and, when the inducing inputs are learned, `Z` (`m x d`,
/// standardised units).
pub struct SparseBound<'a> {
    data: LikelihoodData<'a>,
    /// Inducing inputs used when they are not optimised (`m x d`, standardised).
    z_fixed: Vec<f64>,
    /// Direction signs of the inducing inputs (fixed).
    z_dirs: Vec<f64>,
    optimize_z: bool,
    noise_floor: f64,
    max_jitter_retries: usize,
    /// Upper soft bound of `ln s_f^2` ([`SparseBound::with_max_signal_variance`]).
    signal_log_max: f64,
    memo: EvalMemo,
}

/// The bound and the posterior at fixed hyperparameters and inducing inputs.
pub struct SparsePosterior {
    /// The collapsed bound `F`.
    pub bound: f64,
    /// Prediction weights `beta = Sigma K_mn y / s2` (`m`).
    pub beta: Vec<f64>,
    /// `R` with `R^T R = K_mm^{-1} - Sigma`, row-packed lower triangle
    /// ([`fold_sparse_variance`]).
    pub variance_factor: Vec<f64>,
    /// Jitter added to `K_mm`'s, `B`'s or the folded factor's diagonal, the largest (0 if none).
    pub jitter: f64,
    /// Mean squared training residual `|y - K_nm beta|^2 / n` (standardised units).
    pub mean_squared_residual: f64,
    /// Mean squared leave-one-out residual of the posterior mean (standardised units).
    pub loo_mean_squared_residual: f64,
}

/// What the first pass and the `m x m` algebra leave for the gradient.
struct Core {
    bound: f64,
    jitter: f64,
    /// The jitter on `K_mm`'s diagonal alone (part of `kmm`, with no `theta` dependence).
    kmm_jitter: f64,
    /// The larger relative jitter of the two factorisations (`K_mm`, `B`).
    relative_jitter: f64,
    /// Inducing features `m x d`.
    uz: Vec<f64>,
    /// The same by input (`d x m`, [`by_input`]), for the kernel blocks.
    uz_by_input: Vec<f64>,
    kmm: Mat<f64>,
    cmm: Mat<f64>,
    tk: f64,
    tr_q: f64,
    linv: Mat<f64>,
    c_factor: Mat<f64>,
    /// `L_B^{-1}`.
    lb_inv: Mat<f64>,
    beta: Vec<f64>,
    /// `Q = A A^T`.
    q: Mat<f64>,
    /// `L` (`L L^T = K_mm`, lower).
    l: Mat<f64>,
    /// `c = L_B^{-1} A y / s2`.
    c_vec: Vec<f64>,
}

/// Sums of one block of samples.
struct BlockSums {
    /// `A A^T` of the block.
    aat: Mat<f64>,
    /// `A y` of the block.
    ay: Vec<f64>,
    yy: f64,
    tk: f64,
}

fn mat_vec(a: &Mat<f64>, x: &[f64]) -> Vec<f64> {
    (0..a.nrows())
        .map(|i| (0..a.ncols()).map(|j| a[(i, j)] * x[j]).sum())
        .collect()
}

fn mat_t_vec(a: &Mat<f64>, x: &[f64]) -> Vec<f64> {
    (0..a.ncols())
        .map(|j| (0..a.nrows()).map(|i| a[(i, j)] * x[i]).sum())
        .collect()
}

/// `L^{-1}` of a lower-triangular `L` (upper part zero).
pub(crate) fn lower_inverse(l: faer::MatRef<'_, f64>) -> Mat<f64> {
    let m = l.nrows();
    let mut inv = Mat::zeros(m, m);
    invert_lower_triangular(inv.as_mut(), l, Par::Seq);
    for i in 0..m {
        for j in i + 1..m {
            inv[(i, j)] = 0.0;
        }
    }
    inv
}

/// Folds the sparse GP's latent variance `k** - k^T (K_mm^{-1} - Sigma) k` into one
/// lower-triangular factor: from `A = L^{-1}` (`L L^T = K_mm`) and `G = L_B^{-1}`
/// (`L_B L_B^T = B = I + A K_mn K_nm A^T / s2`), returns `R`, row-packed, with
/// `R^T R = K_mm^{-1} - Sigma`, and the jitter its factorisation needed.
///
/// Since `Sigma = A^T B^{-1} A`, `K_mm^{-1} - Sigma = A^T M A` with `M = I - G^T G = I - B^{-1}`,
/// whose eigenvalues lie in `[0, 1)`: forming `M` subtracts numbers of order 1, never two large
/// quadratic forms (which the two-factor form `|A k|^2 - |G A k|^2` does at every
/// prediction). With `J` the reversal permutation and `J M J = F F^T` (Cholesky), `M = U U^T` with
/// `U = J F J` upper-triangular, so `R = U^T A` is lower-triangular and the variance is one packed
/// triangular product, `k** - |R k|^2`. `M` is only semi-definite where the data do not inform an
/// inducing direction; the factorisation then retries with reported jitter `delta`, which lowers
/// the variance by `delta k^T K_mm^{-1} k <= delta k**`.
pub fn fold_sparse_variance(
    a: faer::MatRef<'_, f64>,
    g: faer::MatRef<'_, f64>,
    max_jitter_retries: usize,
) -> Result<(Vec<f64>, f64), GpError> {
    let m = a.nrows();
    let gtg = g.transpose() * g;
    // J M J, symmetric by construction.
    let mut mr = Mat::from_fn(m, m, |i, j| {
        let (p, q) = (m - 1 - i, m - 1 - j);
        let v = 0.5 * (gtg[(p, q)] + gtg[(q, p)]);
        if i == j { 1.0 - v } else { -v }
    });
    let factor = factor_with_jitter(&mut mr, max_jitter_retries)?;
    let f = factor.llt.L();
    // U^T[i][j] = U[j][i] = F[m-1-j][m-1-i]: lower-triangular.
    let ut = Mat::from_fn(m, m, |i, j| {
        if j <= i {
            f[(m - 1 - j, m - 1 - i)]
        } else {
            0.0
        }
    });
    let a_lower = Mat::from_fn(m, m, |i, j| if j <= i { a[(i, j)] } else { 0.0 });
    let r = &ut * &a_lower;
    Ok((pack_lower(&r), factor.jitter))
}

/// Unpacks a row-packed lower triangle (`m (m + 1) / 2` values) into a dense matrix.
pub(crate) fn unpack_lower(packed: &[f64], m: usize) -> Mat<f64> {
    Mat::from_fn(m, m, |i, j| {
        if j <= i {
            packed.get(i * (i + 1) / 2 + j).copied().unwrap_or(0.0)
        } else {
            0.0
        }
    })
}

fn pack_lower(a: &Mat<f64>) -> Vec<f64> {
    let m = a.nrows();
    let mut out = Vec::with_capacity(m * (m + 1) / 2);
    for i in 0..m {
        for j in 0..=i {
            out.push(a[(i, j)]);
        }
    }
    out
}

impl<'a> SparseBound<'a> {
    /// A bound over `data` with inducing inputs `z` (`m x d`, standardised) and their direction
    /// signs; `optimize_z` appends `Z` to the optimised vector.
    pub fn new(
        data: LikelihoodData<'a>,
        z: Vec<f64>,
        z_dirs: Vec<f64>,
        optimize_z: bool,
        noise_floor: f64,
        max_jitter_retries: usize,
    ) -> Self {
        Self {
            data,
            z_fixed: z,
            z_dirs,
            optimize_z,
            noise_floor,
            max_jitter_retries,
            signal_log_max: LOG_BOUND,
            memo: EvalMemo::default(),
        }
    }

    /// Keeps the signal variance below `max` (standardised units) with the same smooth
    /// penalty as every log-parameter's `[-LOG_BOUND, LOG_BOUND]` box
    /// ([`GpParams::max_signal_variance`](crate::GpParams::max_signal_variance)).
    pub fn with_max_signal_variance(mut self, max: f64) -> Self {
        self.signal_log_max = max.ln().min(LOG_BOUND);
        self
    }

    /// Number of inducing points.
    pub fn n_inducing(&self) -> usize {
        self.z_dirs.len()
    }

    /// Length of the optimised vector.
    pub fn n_params(&self) -> usize {
        let z = if self.optimize_z {
            self.z_fixed.len()
        } else {
            0
        };
        self.data.spec.n_params() + 1 + z
    }

    /// The inducing inputs a parameter vector encodes (standardised units).
    pub fn inducing_of<'p>(&'p self, p: &'p [f64]) -> &'p [f64] {
        let start = self.data.spec.n_params() + 1;
        if self.optimize_z && p.len() == start + self.z_fixed.len() {
            &p[start..]
        } else {
            &self.z_fixed
        }
    }

    /// Kernel values `k(Z, x_j)` (column `j - start` of `kmn`), their `dk/dr2` (if asked) and
    /// the rows' features, for the rows `start..end`. `uz_by_input` holds the inducing features
    /// by input (`d x m`, [`by_input`]), so the distances vectorise over Z.
    #[allow(clippy::too_many_arguments)]
    fn cross_block(
        &self,
        kernel: &Kernel<'_>,
        uz_by_input: &[f64],
        start: usize,
        end: usize,
        kmn: &mut Mat<f64>,
        cmn: Option<&mut Mat<f64>>,
        ux: &mut [f64],
    ) {
        // The loop is half of a sparse training run (perf, 100,000 samples, m = 128). Compiled
        // for the baseline x86-64 target it vectorises two lanes wide; pulp runs it in a
        // function with the widest instruction set the CPU has (AVX2 on x86-64-v3), into which
        // `CrossBlock::with_simd` and what it calls inline. Lane-wise IEEE arithmetic (no fused
        // multiply-adds: Rust does not contract them) gives the same bits on every path.
        pulp::Arch::new().dispatch(CrossBlock {
            bound: self,
            kernel,
            uz_by_input,
            start,
            end,
            kmn,
            cmn,
            ux,
        });
    }

    fn n_blocks(&self) -> usize {
        self.data.y.len().div_ceil(BLOCK_ROWS)
    }

    fn block_range(&self, b: usize) -> (usize, usize) {
        let n = self.data.y.len();
        (b * BLOCK_ROWS, ((b + 1) * BLOCK_ROWS).min(n))
    }

    /// First pass and the `m x m` algebra.
    fn core(&self, kernel: &Kernel<'_>, z: &[f64], s2: f64) -> Result<Core, GpError> {
        let spec = *kernel.spec();
        let d = spec.dim;
        let m = self.n_inducing();
        let n = self.data.y.len();
        let sf2 = kernel.signal_variance();
        let mut uz = vec![0.0; m * d];
        let mut u = [0.0; MAX_DIM];
        let mut jac = [0.0; hbn_core::kernel::FEATURE_JACOBIAN_LEN];
        for a in 0..m {
            kernel.features(&z[a * d..a * d + d], &mut u, &mut jac);
            uz[a * d..a * d + d].copy_from_slice(&u[..d]);
        }
        let mut kmm = Mat::zeros(m, m);
        let mut cmm = Mat::zeros(m, m);
        for a in 0..m {
            for b in 0..m {
                let r2: f64 = (0..d)
                    .map(|j| (uz[a * d + j] - uz[b * d + j]).powi(2))
                    .sum();
                let (f, df) = profile_and_slope(spec.profile, r2);
                let dir = spec.direction_factor(self.z_dirs[a], self.z_dirs[b]);
                kmm[(a, b)] = sf2 * f * dir;
                cmm[(a, b)] = sf2 * df * dir;
            }
        }
        let factor = factor_with_jitter(&mut kmm, self.max_jitter_retries)?;
        let jitter = factor.jitter;
        for a in 0..m {
            kmm[(a, a)] += jitter;
        }
        let linv = lower_inverse(factor.llt.L());

        // Pass 1, in fixed blocks: A = L^{-1} K_mn one block at a time, Q = A A^T
        // (= L^{-1} P L^{-T}), A y, y^T y and sum k_jj. Forming A first (rather than P, then
        // two triangular solves) keeps the rounding error of Q at cond(L), not cond(K_mm).
        let l_factor = factor.llt.L();
        let uz_by_input = by_input(&uz, d, m);
        let sums: Vec<BlockSums> = (0..self.n_blocks())
            .into_par_iter()
            .map(|b| {
                let (start, end) = self.block_range(b);
                let rows = end - start;
                let mut kmn = Mat::zeros(m, rows);
                let mut ux = vec![0.0; rows * d];
                self.cross_block(kernel, &uz_by_input, start, end, &mut kmn, None, &mut ux);
                solve_lower_triangular_in_place(l_factor, kmn.as_mut(), Par::Seq);
                let a = kmn;
                // Q is symmetric: its lower half only (half the multiply-adds of the full
                // product), mirrored once after the blocks are summed.
                let mut q = Mat::zeros(m, m);
                triangular::matmul(
                    q.as_mut(),
                    BlockStructure::TriangularLower,
                    Accum::Replace,
                    a.as_ref(),
                    BlockStructure::Rectangular,
                    a.transpose(),
                    BlockStructure::Rectangular,
                    1.0,
                    Par::Seq,
                );
                let y = &self.data.y[start..end];
                // A y column by column (contiguous, in the same order per entry).
                let mut v = vec![0.0; m];
                for (c, &yc) in y.iter().enumerate() {
                    for (vi, aic) in v.iter_mut().zip(a.col_as_slice(c)) {
                        *vi += aic * yc;
                    }
                }
                let yy = y.iter().map(|t| t * t).sum();
                let tk = self.data.directions[start..end]
                    .iter()
                    .map(|&g| sf2 * spec.direction_factor(g, g))
                    .sum();
                BlockSums {
                    aat: q,
                    ay: v,
                    yy,
                    tk,
                }
            })
            .collect();
        let mut q = Mat::zeros(m, m);
        let mut av = vec![0.0; m];
        let (mut yy, mut tk) = (0.0, 0.0);
        for s in &sums {
            q += &s.aat;
            for (acc, x) in av.iter_mut().zip(&s.ay) {
                *acc += x;
            }
            yy += s.yy;
            tk += s.tk;
        }
        drop(sums);
        let q = Mat::from_fn(m, m, |i, j| if j <= i { q[(i, j)] } else { q[(j, i)] });
        let l_full = Mat::from_fn(m, m, |i, j| if j <= i { l_factor[(i, j)] } else { 0.0 });

        let tr_q: f64 = (0..m).map(|i| q[(i, i)]).sum();
        let mut bmat = Mat::from_fn(m, m, |i, j| q[(i, j)] / s2 + if i == j { 1.0 } else { 0.0 });
        let factor_b = factor_with_jitter(&mut bmat, self.max_jitter_retries)?;
        let lb = factor_b.llt.L();
        let lb_inv = lower_inverse(lb);
        let c_factor = &lb_inv * &linv;
        let c_vec: Vec<f64> = mat_vec(&lb_inv, &av).iter().map(|x| x / s2).collect();
        let beta = mat_t_vec(&c_factor, &c_vec);
        let log_det_b: f64 = (0..m).map(|i| lb[(i, i)].ln()).sum();
        let cc: f64 = c_vec.iter().map(|x| x * x).sum();
        let nf = n as f64;
        let bound = -0.5 * nf * (2.0 * std::f64::consts::PI).ln()
            - log_det_b
            - 0.5 * nf * s2.ln()
            - 0.5 * (yy / s2 - cc)
            - 0.5 * (tk - tr_q) / s2;
        if !bound.is_finite() || !beta.iter().all(|b| b.is_finite()) {
            return Err(GpError::NotPositiveDefinite {
                jitter: factor.jitter.max(factor_b.jitter),
                retries: factor.retries.max(factor_b.retries),
            });
        }
        Ok(Core {
            bound,
            jitter: jitter.max(factor_b.jitter),
            kmm_jitter: jitter,
            relative_jitter: factor.relative_jitter().max(factor_b.relative_jitter()),
            uz,
            uz_by_input,
            kmm,
            cmm,
            tk,
            tr_q,
            linv,
            c_factor,
            lb_inv,
            beta,
            q,
            c_vec,
            l: l_full,
        })
    }

    /// The bound and the prediction factors at kernel `theta`, noise `s2` and inducing inputs
    /// `z` (standardised units).
    pub fn posterior(&self, theta: &[f64], s2: f64, z: &[f64]) -> Result<SparsePosterior, GpError> {
        let kernel = Kernel::new(self.data.spec, theta, self.data.whiten)?;
        let core = self.core(&kernel, z, s2)?;
        let (mean_squared_residual, loo_mean_squared_residual) = self.residuals(&kernel, &core, s2);
        let (variance_factor, fold_jitter) = fold_sparse_variance(
            core.linv.as_ref(),
            core.lb_inv.as_ref(),
            self.max_jitter_retries,
        )?;
        Ok(SparsePosterior {
            bound: core.bound,
            variance_factor,
            beta: core.beta,
            jitter: core.jitter.max(fold_jitter),
            mean_squared_residual,
            loo_mean_squared_residual,
        })
    }

    /// Mean squared training residual and mean squared leave-one-out residual of the
    /// posterior mean, one sample at a time (the closed form
    /// `y^T y - 2 v^T beta + beta^T P beta` cancels catastrophically when `s_f^2` is large).
    /// The mean `K_nm Sigma K_mn y / s2` is a linear smoother with hat-matrix diagonal
    /// `h_j = |C k_j|^2 / s2`, so the leave-one-out residual is exactly `r_j / (1 - h_j)`.
    fn residuals(&self, kernel: &Kernel<'_>, core: &Core, s2: f64) -> (f64, f64) {
        let m = self.n_inducing();
        let d = kernel.spec().dim;
        let parts: Vec<(f64, f64)> = (0..self.n_blocks())
            .into_par_iter()
            .map(|b| {
                let (start, end) = self.block_range(b);
                let rows = end - start;
                let mut kmn = Mat::zeros(m, rows);
                let mut ux = vec![0.0; rows * d];
                self.cross_block(
                    kernel,
                    &core.uz_by_input,
                    start,
                    end,
                    &mut kmn,
                    None,
                    &mut ux,
                );
                let mut ck = Mat::zeros(m, rows);
                matmul(
                    ck.as_mut(),
                    Accum::Replace,
                    core.c_factor.as_ref(),
                    kmn.as_ref(),
                    1.0,
                    Par::Seq,
                );
                let (mut sq, mut loo) = (0.0, 0.0);
                for c in 0..rows {
                    let kcol = kmn.col_as_slice(c);
                    let mean: f64 = kcol.iter().zip(&core.beta).map(|(k, b)| k * b).sum();
                    let r = self.data.y[start + c] - mean;
                    let h: f64 = ck.col_as_slice(c).iter().map(|v| v * v).sum::<f64>() / s2;
                    sq += r * r;
                    loo += (r / (1.0 - h).max(1e-12)).powi(2);
                }
                (sq, loo)
            })
            .collect();
        let n = self.data.y.len() as f64;
        let (sq, loo) = parts
            .iter()
            .fold((0.0, 0.0), |acc, p| (acc.0 + p.0, acc.1 + p.1));
        (sq / n, loo / n)
    }

    /// The bound (minus the soft-bound penalty) and its gradient at the optimised vector `p`.
    pub fn evaluate(&self, p: &[f64]) -> Result<Evaluation, GpError> {
        if let Some(ev) = self.memo.recall(p) {
            return Ok(ev);
        }
        let spec = self.data.spec;
        let n_k = spec.n_params();
        if p.len() != self.n_params() {
            return Err(GpError::Shape {
                what: "optimised parameters",
                expected: self.n_params(),
                got: p.len(),
            });
        }
        if !p.iter().all(|v| v.is_finite()) {
            return Err(GpError::NonFinite {
                what: "hyperparameters",
                row: 0,
            });
        }
        let theta = &p[..n_k];
        let s2 = noise_of(self.noise_floor, p[n_k]);
        let z = self.inducing_of(p);
        let kernel = Kernel::new(spec, theta, self.data.whiten)?;
        let core = self.core(&kernel, z, s2)?;
        let d = spec.dim;
        let m = self.n_inducing();
        let n = self.data.y.len();
        let warped = spec.warp_units > 0;

        // Sensitivities (see the module docs), in the whitened basis: `one_minus` is
        // I - B^{-1} = B^{-1} Q / s2, formed as a product (no difference of large terms), and
        // dF/dK_mm = -1/2 L^{-T} ((I - B^{-1}) Q / s2 + gamma gamma^T) L^{-1}.
        let binv = core.lb_inv.transpose() * &core.lb_inv;
        let q_s2 = Mat::from_fn(m, m, |i, j| core.q[(i, j)] / s2);
        let one_minus = symmetrised(&(&binv * &q_s2));
        let gamma = mat_t_vec(&core.lb_inv, &core.c_vec);
        let s_k = symmetrised(&(&one_minus * &q_s2));
        let s_k = Mat::from_fn(m, m, |i, j| s_k[(i, j)] + gamma[i] * gamma[j]);
        let g_kmm = core.linv.transpose() * &s_k * &core.linv * (-0.5);
        // tr(Sigma P) = tr(B^{-1} Q).
        let tr_sigma_p: f64 = (0..m)
            .map(|i| (0..m).map(|j| binv[(i, j)] * core.q[(j, i)]).sum::<f64>())
            .sum();

        let prep_z: Vec<Prepared> = if warped {
            (0..m)
                .map(|a| kernel.prepare(&z[a * d..a * d + d], self.z_dirs[a]))
                .collect()
        } else {
            Vec::new()
        };

        // Pass 2: dF/dK_mn column by column, chained into theta (and the inducing features).
        let want_z = self.optimize_z;
        let parts: Vec<(Vec<f64>, Vec<f64>, f64)> = (0..self.n_blocks())
            .into_par_iter()
            .map(|b| {
                let (start, end) = self.block_range(b);
                let rows = end - start;
                let mut kmn = Mat::zeros(m, rows);
                let mut cmn = Mat::zeros(m, rows);
                let mut ux = vec![0.0; rows * d];
                self.cross_block(
                    &kernel,
                    &core.uz_by_input,
                    start,
                    end,
                    &mut kmn,
                    Some(&mut cmn),
                    &mut ux,
                );
                // G = L^{-T} ((I - B^{-1}) A + gamma r^T) / s2 with A = L^{-1} K_mn and the
                // residuals r = y - A^T gamma: every factor is of moderate size (forming
                // W K_mn + beta y^T instead subtracts large terms).
                let mut a = kmn.clone();
                solve_lower_triangular_in_place(core.l.as_ref(), a.as_mut(), Par::Seq);
                let y = &self.data.y[start..end];
                let mut g = Mat::zeros(m, rows);
                matmul(
                    g.as_mut(),
                    Accum::Replace,
                    one_minus.as_ref(),
                    a.as_ref(),
                    1.0,
                    Par::Seq,
                );
                let mut rss = 0.0;
                for col in 0..rows {
                    let mean: f64 = a
                        .col_as_slice(col)
                        .iter()
                        .zip(&gamma)
                        .map(|(x, t)| x * t)
                        .sum();
                    let r = y[col] - mean;
                    rss += r * r;
                    for (gv, t) in g.col_as_slice_mut(col).iter_mut().zip(&gamma) {
                        *gv = (*gv + t * r) / s2;
                    }
                }
                solve_upper_triangular_in_place(core.l.transpose(), g.as_mut(), Par::Seq);
                let mut acc = vec![0.0; n_k];
                let mut gz = vec![0.0; if want_z { m * d } else { 0 }];
                if !warped {
                    // Unwarped (the default): sums over Z, vectorised, in the widest
                    // instruction set the CPU has (as `cross_block`).
                    pulp::Arch::new().dispatch(UnwarpedGrads {
                        spec: &spec,
                        kmn: &kmn,
                        cmn: &cmn,
                        g: &g,
                        uz: &core.uz,
                        uz_by_input: &core.uz_by_input,
                        ux: &ux,
                        acc: &mut acc,
                        gz: &mut gz,
                    });
                    return (acc, gz, rss);
                }
                let mut tmp = vec![0.0; n_k];
                for col in 0..rows {
                    let (ccol, gcol) = (cmn.col_as_slice(col), g.col_as_slice(col));
                    let xu = &ux[col * d..col * d + d];
                    let j = start + col;
                    let px =
                        kernel.prepare(&self.data.x[j * d..j * d + d], self.data.directions[j]);
                    for a in 0..m {
                        let (gw, c) = (gcol[a], ccol[a]);
                        let za = &core.uz[a * d..a * d + d];
                        kernel.grad_theta(&prep_z[a], &px, &mut tmp);
                        for (s, t) in acc.iter_mut().zip(&tmp) {
                            *s += gw * t;
                        }
                        if want_z {
                            let gc = 2.0 * gw * c;
                            for j in 0..d {
                                gz[a * d + j] += gc * (za[j] - xu[j]);
                            }
                        }
                    }
                }
                (acc, gz, rss)
            })
            .collect();
        let mut grad_theta = vec![0.0; n_k];
        let mut grad_uz = vec![0.0; if want_z { m * d } else { 0 }];
        let mut rss = 0.0;
        for (acc, gz, r) in &parts {
            rss += r;
            for (s, t) in grad_theta.iter_mut().zip(acc) {
                *s += t;
            }
            for (s, t) in grad_uz.iter_mut().zip(gz) {
                *s += t;
            }
        }

        // K_mm and diagonal terms.
        let mut tmp = vec![0.0; n_k];
        for a in 0..m {
            for b in 0..m {
                let gw = g_kmm[(a, b)];
                let (za, zb) = (&core.uz[a * d..a * d + d], &core.uz[b * d..b * d + d]);
                // K_mm includes the jitter on its diagonal, which has no theta dependence.
                let k = core.kmm[(a, b)] - if a == b { core.kmm_jitter } else { 0.0 };
                if warped {
                    kernel.grad_theta(&prep_z[a], &prep_z[b], &mut tmp);
                    for (s, t) in grad_theta.iter_mut().zip(&tmp) {
                        *s += gw * t;
                    }
                } else {
                    add_pair_theta_grad(&spec, gw, k, core.cmm[(a, b)], za, zb, &mut grad_theta);
                }
                if want_z {
                    let gc = 4.0 * gw * core.cmm[(a, b)];
                    for j in 0..d {
                        grad_uz[a * d + j] += gc * (za[j] - zb[j]);
                    }
                }
            }
        }
        let d_s2 = (tr_sigma_p - n as f64 * s2 + rss + core.tk - core.tr_q) / (2.0 * s2 * s2);
        // The signal variance scales K_mm, K_mn and every k_jj alike (A by s_f, Q by s_f^2),
        // which gives its derivative in closed form: the sum over the entries above adds
        // terms of order n / s2 that cancel to a few units. K_mm's jitter is relative to its
        // mean diagonal, so it scales too.
        let gamma_sq: f64 = gamma.iter().map(|g| g * g).sum();
        grad_theta[0] = -0.5 * tr_sigma_p / s2 + 0.5 * gamma_sq - 0.5 * (core.tk - core.tr_q) / s2;

        let mut grad = grad_theta;
        grad.push(d_s2 * (s2 - self.noise_floor));
        let penalty = soft_bound_penalty(&p[..=n_k], &mut grad, self.signal_log_max);
        if want_z {
            // Features to inputs: dF/dz_c = sum_r dF/du_r du_r/dz_c.
            let mut u = [0.0; MAX_DIM];
            let mut jac = [0.0; hbn_core::kernel::FEATURE_JACOBIAN_LEN];
            for a in 0..m {
                kernel.features(&z[a * d..a * d + d], &mut u, &mut jac);
                for c in 0..d {
                    grad.push(
                        (0..d)
                            .map(|r| {
                                grad_uz[a * d + r]
                                    * hbn_core::kernel::feature_jacobian_entry(&jac, d, r, c)
                            })
                            .sum(),
                    );
                }
            }
        }
        let ev = Evaluation {
            lml: core.bound - penalty,
            grad,
            jitter: core.jitter,
            relative_jitter: core.relative_jitter,
        };
        if !ev.grad.iter().all(|g| g.is_finite()) {
            return Err(GpError::NonFinite {
                what: "bound gradient",
                row: 0,
            });
        }
        self.memo.record(p, &ev);
        Ok(ev)
    }
}

/// The second pass's chain into `theta` (and the inducing features) for one block of an
/// unwarped kernel, run by [`pulp::Arch::dispatch`] so that [`add_column_theta_grad`]'s loops
/// over the inducing points vectorise four lanes wide where the CPU can (lane by lane the same
/// IEEE operations, so the same bits on every path).
struct UnwarpedGrads<'a> {
    spec: &'a hbn_core::KernelSpec,
    kmn: &'a Mat<f64>,
    cmn: &'a Mat<f64>,
    g: &'a Mat<f64>,
    uz: &'a [f64],
    uz_by_input: &'a [f64],
    ux: &'a [f64],
    acc: &'a mut [f64],
    gz: &'a mut [f64],
}

impl pulp::WithSimd for UnwarpedGrads<'_> {
    type Output = ();

    #[inline(always)]
    fn with_simd<S: pulp::Simd>(self, _simd: S) {
        let UnwarpedGrads {
            spec,
            kmn,
            cmn,
            g,
            uz,
            uz_by_input,
            ux,
            acc,
            gz,
        } = self;
        let d = spec.dim;
        let m = kmn.nrows();
        let mut column_scratch = vec![0.0; 2 * m];
        for col in 0..kmn.ncols() {
            let (kcol, ccol, gcol) = (
                kmn.col_as_slice(col),
                cmn.col_as_slice(col),
                g.col_as_slice(col),
            );
            let xu = &ux[col * d..col * d + d];
            add_column_theta_grad(
                spec,
                gcol,
                kcol,
                ccol,
                uz_by_input,
                xu,
                acc,
                &mut column_scratch,
            );
            if !gz.is_empty() {
                for (a, za) in uz.chunks_exact(d).enumerate().take(m) {
                    let gc = 2.0 * gcol[a] * ccol[a];
                    for j in 0..d {
                        gz[a * d + j] += gc * (za[j] - xu[j]);
                    }
                }
            }
        }
    }
}

/// [`SparseBound::cross_block`]'s arguments, run by [`pulp::Arch::dispatch`].
struct CrossBlock<'a, 'b, 'k> {
    bound: &'a SparseBound<'b>,
    kernel: &'a Kernel<'k>,
    uz_by_input: &'a [f64],
    start: usize,
    end: usize,
    kmn: &'a mut Mat<f64>,
    cmn: Option<&'a mut Mat<f64>>,
    ux: &'a mut [f64],
}

impl pulp::WithSimd for CrossBlock<'_, '_, '_> {
    type Output = ();

    #[inline(always)]
    fn with_simd<S: pulp::Simd>(self, _simd: S) {
        let CrossBlock {
            bound,
            kernel,
            uz_by_input,
            start,
            end,
            kmn,
            mut cmn,
            ux,
        } = self;
        let spec = *kernel.spec();
        let d = spec.dim;
        let m = bound.n_inducing();
        let sf2 = kernel.signal_variance();
        let mut u = [0.0; MAX_DIM];
        // Per column: the squared distances, then the profile for all m at once (the core's
        // vectorised `profiles_and_slopes`), then the scale and direction factors.
        let mut r2 = vec![0.0; m];
        let mut slope = vec![0.0; m];
        for (col, j) in (start..end).enumerate() {
            kernel.feature_vector(&bound.data.x[j * d..j * d + d], &mut u);
            let u = &u[..d];
            ux[col * d..col * d + d].copy_from_slice(u);
            let gj = bound.data.directions[j];
            r2.fill(0.0);
            for (zi, ui) in uz_by_input.chunks_exact(m).zip(u) {
                for (r2_a, z) in r2.iter_mut().zip(zi) {
                    let t = z - ui;
                    *r2_a += t * t;
                }
            }
            let kcol = &mut kmn.col_as_slice_mut(col)[..m];
            profiles_and_slopes_with(spec.profile, &r2, kcol, &mut slope, f64::sqrt);
            if spec.direction.is_some() {
                for ((k, c), za_dir) in kcol.iter_mut().zip(slope.iter_mut()).zip(&bound.z_dirs) {
                    let dir = spec.direction_factor(*za_dir, gj);
                    *k *= sf2 * dir;
                    *c *= sf2 * dir;
                }
            } else {
                for (k, c) in kcol.iter_mut().zip(slope.iter_mut()) {
                    *k *= sf2;
                    *c *= sf2;
                }
            }
            if let Some(c) = cmn.as_deref_mut() {
                c.col_as_slice_mut(col)[..m].copy_from_slice(&slope);
            }
        }
    }
}

impl Objective for SparseBound<'_> {
    fn evaluate(&self, p: &[f64]) -> Result<Evaluation, GpError> {
        SparseBound::evaluate(self, p)
    }
    fn stats(&self) -> EvalStats {
        self.memo.stats()
    }
}

/// `m` points of `d` features (`m x d`, row-major) by input instead (`d x m`), so that sums
/// over the points are contiguous loops that vectorise.
/// `(A + A^T) / 2`: a product that is symmetric in exact arithmetic, made so in rounding.
fn symmetrised(a: &Mat<f64>) -> Mat<f64> {
    Mat::from_fn(a.nrows(), a.ncols(), |i, j| 0.5 * (a[(i, j)] + a[(j, i)]))
}

fn by_input(points: &[f64], d: usize, m: usize) -> Vec<f64> {
    let mut out = vec![0.0; d * m];
    for (a, p) in points.chunks_exact(d.max(1)).enumerate().take(m) {
        for (i, v) in p.iter().enumerate() {
            out[i * m + a] = *v;
        }
    }
    out
}

/// `acc += sum_a w_a dk(z_a, x)/dtheta` for one sample `x` (features `xu`) against every
/// inducing point of an *unwarped* kernel: [`add_pair_theta_grad`] summed over `a` first, in
/// contiguous loops over the points (`uz_by_input` from [`by_input`]).
/// `scratch` holds at least `2 m` values.
#[allow(clippy::too_many_arguments)]
#[inline(always)]
fn add_column_theta_grad(
    spec: &hbn_core::KernelSpec,
    w: &[f64],
    k: &[f64],
    c: &[f64],
    uz_by_input: &[f64],
    xu: &[f64],
    acc: &mut [f64],
    scratch: &mut [f64],
) {
    let m = w.len();
    acc[0] += hbn_core::gp::dot(w, k);
    let (wc, sq) = scratch.split_at_mut(m);
    for ((wc, w), c) in wc.iter_mut().zip(w).zip(c) {
        *wc = w * c;
    }
    let sq = &mut sq[..m];
    match spec.metric {
        Metric::Ard => {
            for (i, (zi, xi)) in uz_by_input.chunks_exact(m).zip(xu).enumerate() {
                for (s, z) in sq.iter_mut().zip(zi) {
                    *s = (z - xi) * (z - xi);
                }
                acc[1 + i] -= 2.0 * hbn_core::gp::dot(wc, sq);
            }
        }
        Metric::Isotropic | Metric::Mahalanobis => {
            let r2 = sq;
            r2.fill(0.0);
            for (zi, xi) in uz_by_input.chunks_exact(m).zip(xu) {
                for (r, z) in r2.iter_mut().zip(zi) {
                    *r += (z - xi) * (z - xi);
                }
            }
            acc[1] += scale_slope(spec.metric) * hbn_core::gp::dot(wc, r2);
        }
    }
}

/// Greedy conditional-variance selection of at most `m` inducing points among the rows of
/// `x_std` (`n x d`), under `kernel`: a pivoted Cholesky that picks, each time, the row with the
/// largest residual variance `k(x, x) - Q(x, x)`, lowest index first on ties. Stops early when
/// every residual is below `1e-10 s_f^2` (the data have fewer distinct inputs). Candidates are
/// an evenly strided pool of at most `max(INIT_POOL_MIN, 32 m)` rows. Returns row indices.
pub fn greedy_variance_selection(
    kernel: &Kernel<'_>,
    x_std: &[f64],
    directions: &[f64],
    m: usize,
) -> Vec<usize> {
    let spec = *kernel.spec();
    let d = spec.dim;
    let n = directions.len().min(x_std.len() / d.max(1));
    let pool_size = n.min(INIT_POOL_MIN.max(m.saturating_mul(32)));
    let pool: Vec<usize> = (0..pool_size).map(|i| i * n / pool_size).collect();
    let sf2 = kernel.signal_variance();
    let mut feats = vec![0.0; pool_size * d];
    let mut u = [0.0; MAX_DIM];
    let mut jac = [0.0; hbn_core::kernel::FEATURE_JACOBIAN_LEN];
    for (i, &row) in pool.iter().enumerate() {
        kernel.features(&x_std[row * d..row * d + d], &mut u, &mut jac);
        feats[i * d..i * d + d].copy_from_slice(&u[..d]);
    }
    let mut residual: Vec<f64> = pool
        .iter()
        .map(|&row| sf2 * spec.direction_factor(directions[row], directions[row]))
        .collect();
    let target = m.min(pool_size);
    // The Cholesky columns chosen so far, by candidate: row `i` holds `e_0(i), .., e_t(i)`, so
    // each candidate's inner product with the pivot's row is one contiguous dot product.
    let mut e_rows = vec![0.0; pool_size * target];
    let mut chosen = Vec::with_capacity(target);
    let tol = 1e-10 * sf2;
    while chosen.len() < target {
        let (best, best_r) =
            residual
                .iter()
                .enumerate()
                .fold(
                    (0, f64::NEG_INFINITY),
                    |acc, (i, &r)| {
                        if r > acc.1 { (i, r) } else { acc }
                    },
                );
        // NaN residuals (never expected) also stop the selection.
        if best_r.partial_cmp(&tol) != Some(std::cmp::Ordering::Greater) {
            break;
        }
        let sqrt_r = best_r.sqrt();
        let fb = &feats[best * d..best * d + d];
        let gb = directions[pool[best]];
        let t = chosen.len();
        let e_best = e_rows[best * target..best * target + t].to_vec();
        let e: Vec<f64> = (0..pool_size)
            .into_par_iter()
            .map(|i| {
                let fi = &feats[i * d..i * d + d];
                let r2: f64 = fb.iter().zip(fi).map(|(p, q)| (p - q) * (p - q)).sum();
                let (f, _) = profile_and_slope(spec.profile, r2);
                let k = sf2 * f * spec.direction_factor(gb, directions[pool[i]]);
                let s = hbn_core::gp::dot(&e_best, &e_rows[i * target..i * target + t]);
                (k - s) / sqrt_r
            })
            .collect();
        for (i, (r, ei)) in residual.iter_mut().zip(&e).enumerate() {
            *r -= ei * ei;
            e_rows[i * target + t] = *ei;
        }
        residual[best] = f64::NEG_INFINITY;
        chosen.push(pool[best]);
    }
    chosen
}

/// Fits a sparse GP (called by [`crate::fit`] when `params.sparse` is set).
pub(crate) fn fit_sparse(
    params: &GpParams,
    sp: &SparseParams,
    x: &[f64],
    y: &[f64],
    data: &Standardised,
    t0: Instant,
    observe: &mut dyn FnMut(FitProgress),
) -> Result<GaussianProcess, GpError> {
    let spec = params.kernel;
    let d = spec.dim;
    let n = y.len();
    let ys = &data.std_y;
    let directions: Vec<f64> = x.chunks_exact(d).map(|r| spec.direction_of(r)).collect();
    let whiten = if spec.metric == Metric::Mahalanobis {
        crate::data::whitening(&data.std_x, d)
    } else {
        Vec::new()
    };
    let (theta0, noise0) = starting_point(params, &data.input_scale, data.output_scale)?;

    // Inducing inputs (standardised) and their direction signs: given, or greedy conditional
    // variance under a kernel.
    let select = |theta: &[f64]| -> Result<(Vec<f64>, Vec<f64>), GpError> {
        let kernel = Kernel::new(spec, theta, &whiten)?;
        let idx = greedy_variance_selection(&kernel, &data.std_x, &directions, sp.n_inducing);
        Ok((
            idx.iter()
                .flat_map(|&i| data.std_x[i * d..i * d + d].iter().copied())
                .collect(),
            idx.iter().map(|&i| directions[i]).collect(),
        ))
    };
    let (mut z_std, mut z_dirs) = match &sp.inducing_inputs {
        Some(z) => (
            z.chunks_exact(d)
                .flat_map(|row| (0..d).map(|j| (row[j] - data.input_mean[j]) / data.input_scale[j]))
                .collect(),
            z.chunks_exact(d).map(|r| spec.direction_of(r)).collect(),
        ),
        None => select(&theta0)?,
    };
    let all = LikelihoodData {
        spec,
        whiten: &whiten,
        x: &data.std_x,
        directions: &directions,
        y: ys,
    };
    fn bound_on<'b>(
        data: LikelihoodData<'b>,
        z: &[f64],
        zd: &[f64],
        sp: &SparseParams,
        params: &GpParams,
    ) -> SparseBound<'b> {
        SparseBound::new(
            data,
            z.to_vec(),
            zd.to_vec(),
            sp.optimize_inducing,
            params.noise_floor,
            params.max_jitter_retries,
        )
        .with_max_signal_variance(params.max_signal_variance.unwrap_or(f64::INFINITY))
    }
    let mut report = TrainingReport {
        n_samples: n,
        n_inducing_requested: Some(sp.n_inducing),
        ..Default::default()
    };
    let n_k = spec.n_params();
    let (theta, noise) = if params.optimize {
        let tail = if sp.optimize_inducing {
            z_std.clone()
        } else {
            Vec::new()
        };
        // 1. Multi-start search, on an evenly strided subset when the data are large.
        let use_subset = n > sp.search_samples;
        let rows: Vec<usize> = if use_subset {
            (0..sp.search_samples)
                .map(|i| i * n / sp.search_samples)
                .collect()
        } else {
            Vec::new()
        };
        let sub_x: Vec<f64> = rows
            .iter()
            .flat_map(|&i| data.std_x[i * d..i * d + d].iter().copied())
            .collect();
        let sub_dirs: Vec<f64> = rows.iter().map(|&i| directions[i]).collect();
        let sub_y: Vec<f64> = rows.iter().map(|&i| ys[i]).collect();
        let search = if use_subset {
            report.search_samples = Some(sp.search_samples);
            bound_on(
                LikelihoodData {
                    x: &sub_x,
                    directions: &sub_dirs,
                    y: &sub_y,
                    ..all
                },
                &z_std,
                &z_dirs,
                sp,
                params,
            )
        } else {
            bound_on(all, &z_std, &z_dirs, sp, params)
        };
        // The per-sample tolerance for the hyperparameters; learning Z (`m d` more
        // parameters, each iteration gaining little) keeps the exact GP's absolute one: with
        // the per-sample one, a learned-Z fit stops below the fixed-Z fit it starts from.
        let tolerance = |rows: usize| {
            if sp.optimize_inducing {
                crate::train::COST_TOLERANCE
            } else {
                COST_TOLERANCE_PER_SAMPLE * rows as f64
            }
        };
        let search_rows = if use_subset { sp.search_samples } else { n };
        let mut p = multi_start(
            &search,
            &theta0,
            noise0,
            &tail,
            params,
            tolerance(search_rows),
            &mut report,
            observe,
        )?;
        report.add_stats(search.stats());
        if sp.optimize_inducing {
            z_std = search.inducing_of(&p).to_vec();
        }
        // 2. Greedy selection again under the learned kernel (Burt et al. 2020): the starting
        //    kernel's length scales rarely match the learned ones.
        let reselect = sp.inducing_inputs.is_none() && !sp.optimize_inducing;
        if reselect {
            (z_std, z_dirs) = select(&p[..n_k])?;
        }
        // 3. Refine on every sample.
        let full = bound_on(all, &z_std, &z_dirs, sp, params);
        if sp.refine_iters > 0 && (use_subset || reselect) {
            let initial_lml = full.evaluate(&p).ok().map(|e| e.lml);
            // Learned inducing inputs keep their absolute tolerance and no stall rule.
            let stall = if sp.optimize_inducing {
                0.0
            } else {
                REFINE_TOLERANCE_PER_SAMPLE * n as f64
            };
            let run = run_lbfgs_with_stall(&full, p.clone(), sp.refine_iters, tolerance(n), stall);
            report.refinement = Some(match run {
                Ok((q, lml, iterations, _termination)) => {
                    p = q;
                    StartReport {
                        initial_lml,
                        final_lml: Some(lml),
                        iterations,
                        error: None,
                    }
                }
                Err(e) => StartReport {
                    initial_lml,
                    final_lml: None,
                    iterations: 0,
                    error: Some(e.to_string()),
                },
            });
            report.add_stats(full.stats());
        }
        if sp.optimize_inducing {
            z_std = full.inducing_of(&p).to_vec();
        }
        report.check_signal_bound(p[0], full.signal_log_max);
        (p[..n_k].to_vec(), noise_of(params.noise_floor, p[n_k]))
    } else {
        (theta0, noise0)
    };
    let m = z_dirs.len();
    report.n_support = m;
    let z_final = z_std;
    let bound = bound_on(all, &z_final, &z_dirs, sp, params);
    let post = bound.posterior(&theta, noise, &z_final)?;
    report.final_jitter = post.jitter;

    let kernel = Kernel::new(spec, &theta, &whiten)?;
    let mut features = Vec::with_capacity(m * d);
    let mut u = [0.0; MAX_DIM];
    let mut jac = [0.0; hbn_core::kernel::FEATURE_JACOBIAN_LEN];
    for row in z_final.chunks_exact(d) {
        kernel.features(row, &mut u, &mut jac);
        features.extend_from_slice(&u[..d]);
    }
    let support_x: Vec<f64> = z_final
        .chunks_exact(d)
        .flat_map(|row| (0..d).map(|j| row[j] * data.input_scale[j] + data.input_mean[j]))
        .collect();
    report.seconds = t0.elapsed().as_secs_f64();
    let s2_out = data.output_scale * data.output_scale;
    Ok(GaussianProcess {
        kernel: spec,
        theta,
        noise_variance: noise,
        whiten,
        input_mean: data.input_mean.clone(),
        input_scale: data.input_scale.clone(),
        output_mean: data.output_mean,
        output_scale: data.output_scale,
        linear: data.linear.clone(),
        support_x,
        support_y: Vec::new(),
        directions: if spec.direction.is_some() {
            z_dirs
        } else {
            Vec::new()
        },
        features,
        alpha: post.beta,
        chol_packed: Vec::new(),
        sparse: Some(SparseFactors {
            variance_factor: post.variance_factor,
            kmm_inv_factor: Vec::new(),
            sigma_factor: Vec::new(),
        }),
        log_marginal_likelihood: post.bound,
        loo_error_variance: post.loo_mean_squared_residual * s2_out,
        report,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A lower-triangular matrix with a positive diagonal from a seed (test data).
    fn lower(m: usize, seed: u64) -> Mat<f64> {
        let mut rng = hbn_core::rng::Rng::new(seed);
        Mat::from_fn(m, m, |i, j| match i.cmp(&j) {
            std::cmp::Ordering::Greater => rng.uniform_in(-0.5, 0.5),
            std::cmp::Ordering::Equal => rng.uniform_in(0.5, 2.0),
            std::cmp::Ordering::Less => 0.0,
        })
    }

    /// `R^T R = A^T (I - G^T G) A` for the folded factor, and `R` is lower-triangular.
    #[test]
    fn the_folded_factor_reproduces_the_two_factor_form() {
        let m = 7;
        let a = lower(m, 1);
        // G = L_B^{-1} for some B = I + Q (Q positive semi-definite): B = I + C C^T.
        let c = lower(m, 2);
        let b = Mat::<f64>::identity(m, m) + &c * c.transpose();
        let lb = b.llt(faer::Side::Lower).unwrap().L().to_owned();
        let g = lower_inverse(lb.as_ref());
        let (r_packed, jitter) = fold_sparse_variance(a.as_ref(), g.as_ref(), 8).unwrap();
        assert_eq!(jitter, 0.0);
        assert_eq!(r_packed.len(), m * (m + 1) / 2);
        let r = unpack_lower(&r_packed, m);
        let want = a.transpose() * (Mat::<f64>::identity(m, m) - g.transpose() * &g) * &a;
        let got = r.transpose() * &r;
        let scale = (0..m).map(|i| want[(i, i)]).fold(0.0, f64::max);
        for i in 0..m {
            for j in 0..m {
                assert!(
                    (got[(i, j)] - want[(i, j)]).abs() <= 1e-12 * scale,
                    "({i}, {j}): {} vs {}",
                    got[(i, j)],
                    want[(i, j)]
                );
            }
        }
    }

    /// Where the data inform no direction (`B = I`, so `M = 0`), the factorisation retries with
    /// jitter, says so, and gives a finite factor whose variance reduction is that jitter's.
    #[test]
    fn an_uninformed_direction_is_folded_with_reported_jitter() {
        let m = 4;
        let a = lower(m, 3);
        let g = Mat::<f64>::identity(m, m);
        let (r_packed, jitter) = fold_sparse_variance(a.as_ref(), g.as_ref(), 8).unwrap();
        assert!(jitter > 0.0 && jitter < 1e-8, "jitter {jitter}");
        assert!(r_packed.iter().all(|v| v.is_finite()));
        // R^T R = jitter * A^T A: the variance reduction is at most jitter * k^T K_mm^{-1} k.
        let r = unpack_lower(&r_packed, m);
        let want = a.transpose() * &a * faer::Scale(jitter);
        let got = r.transpose() * &r;
        for i in 0..m {
            for j in 0..m {
                assert!((got[(i, j)] - want[(i, j)]).abs() <= 1e-6 * jitter * 10.0);
            }
        }
    }
}
