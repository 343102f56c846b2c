//! The log marginal likelihood (thesis Eq. 7) and its analytic gradient: the *problem*,
//! kept apart from the optimiser that solves it (`train.rs`).
//!
//! With `K_y = K + s_n^2 I = L L^T` and `alpha = K_y^{-1} y`:
//!
//! `log p(y | X, theta) = -1/2 y^T alpha - sum_i ln L_ii - n/2 ln(2 pi)`
//!
//! `d/dtheta_p = 1/2 tr((alpha alpha^T - K_y^{-1}) dK_y/dtheta_p)`.
//!
//! The optimised vector is the kernel's `theta` followed by `ln(s_n^2 - floor)`, so the noise
//! variance never drops below the floor and every parameter is unconstrained.

use crate::GpError;
use crate::factor::{Factor, factor_with_jitter};
use faer::Mat;
use faer::linalg::solvers::Solve;
use hbn_core::kernel::Prepared;
use hbn_core::{Kernel, KernelSpec, Metric};
use rayon::prelude::*;
use std::sync::Mutex;

/// Standardised training data for one GP (row-major inputs).
#[derive(Clone, Copy, Debug)]
pub struct LikelihoodData<'a> {
    /// Kernel structure.
    pub spec: KernelSpec,
    /// Whitening matrix for the Mahalanobis metric (empty otherwise).
    pub whiten: &'a [f64],
    /// `n x d` standardised inputs.
    pub x: &'a [f64],
    /// `n` direction signs (zeros without the direction factor).
    pub directions: &'a [f64],
    /// `n` standardised targets.
    pub y: &'a [f64],
}

/// Log-parameters are kept inside `[-LOG_BOUND, LOG_BOUND]` (scikit-learn's default bounds
/// `1e-5..1e5`) by a smooth quadratic penalty on the optimised objective, so that length scales
/// and the signal variance cannot run off to values that make `K` numerically singular.
pub const LOG_BOUND: f64 = 11.512_925_464_970_229;
const PENALTY: f64 = 1e4;

/// Value and gradient of the log marginal likelihood at one parameter vector.
#[derive(Clone, Debug)]
pub struct Evaluation {
    /// Log marginal likelihood minus the bound penalty (what the optimiser maximises).
    pub lml: f64,
    /// Gradient with respect to the optimised vector (kernel theta, then the noise parameter).
    pub grad: Vec<f64>,
    /// Jitter the factorisation needed (0 if none).
    pub jitter: f64,
    /// The same relative to the factored matrix's mean diagonal ([`crate::factor::Factor::relative_jitter`]).
    pub relative_jitter: f64,
}

/// Counters of what the likelihood did, for the training report.
#[derive(Clone, Copy, Debug, Default)]
pub struct EvalStats {
    /// Likelihood evaluations.
    pub evaluations: usize,
    /// Evaluations that needed jitter.
    pub jitter_evaluations: usize,
    /// Largest jitter used, relative to the mean diagonal of the matrix factored.
    pub max_jitter: f64,
}

/// The last evaluation (argmin asks for the cost and the gradient at the same point in two
/// calls) and the counters of an objective.
#[derive(Default)]
pub(crate) struct EvalMemo {
    last: Mutex<Option<(Vec<f64>, Evaluation)>>,
    stats: Mutex<EvalStats>,
}

impl EvalMemo {
    /// The evaluation at `p` if it was the last one.
    pub fn recall(&self, p: &[f64]) -> Option<Evaluation> {
        let last = self.last.lock().ok()?;
        let (cp, ev) = last.as_ref()?;
        (cp.as_slice() == p).then(|| ev.clone())
    }

    /// Counts a fresh evaluation at `p` and remembers it.
    pub fn record(&self, p: &[f64], ev: &Evaluation) {
        if let Ok(mut s) = self.stats.lock() {
            s.evaluations += 1;
            if ev.jitter > 0.0 {
                s.jitter_evaluations += 1;
                s.max_jitter = s.max_jitter.max(ev.relative_jitter);
            }
        }
        if let Ok(mut last) = self.last.lock() {
            *last = Some((p.to_vec(), ev.clone()));
        }
    }

    /// Counters so far.
    pub fn stats(&self) -> EvalStats {
        self.stats.lock().map(|s| *s).unwrap_or_default()
    }
}

/// The log marginal likelihood as an optimisation problem.
pub struct Likelihood<'a> {
    data: LikelihoodData<'a>,
    noise_floor: f64,
    /// Upper soft bound of `ln s_f^2` ([`Likelihood::with_max_signal_variance`]).
    pub(crate) signal_log_max: f64,
    max_jitter_retries: usize,
    memo: EvalMemo,
}

/// Gram matrix pieces shared by the likelihood and its gradient.
struct Gram {
    /// `K` without noise (column-major lower triangle).
    k: Vec<f64>,
    /// `dk/dr2` per pair (same layout).
    c: Vec<f64>,
    /// Features `n x d`.
    u: Vec<f64>,
}

/// Everything the final model needs from a factorisation.
pub struct Solved {
    /// The factor.
    pub factor: Factor,
    /// `K_y^{-1} y`.
    pub alpha: Vec<f64>,
    /// Log marginal likelihood.
    pub lml: f64,
}

impl<'a> Likelihood<'a> {
    /// A problem over `data` with the given noise floor and jitter retries.
    pub fn new(data: LikelihoodData<'a>, noise_floor: f64, max_jitter_retries: usize) -> Self {
        Self {
            data,
            noise_floor,
            signal_log_max: LOG_BOUND,
            max_jitter_retries,
            memo: EvalMemo::default(),
        }
    }

    /// Keeps `s_f^2` below `max` (kernel units) by the box's smooth penalty
    /// ([`GpParams::max_signal_variance`](crate::GpParams::max_signal_variance)).
    pub fn with_max_signal_variance(mut self, max: f64) -> Self {
        self.signal_log_max = max.ln().min(LOG_BOUND);
        self
    }

    /// Number of optimised parameters.
    pub fn n_params(&self) -> usize {
        self.data.spec.n_params() + 1
    }

    /// Noise variance encoded by the last parameter.
    pub fn noise_of(&self, p_noise: f64) -> f64 {
        noise_of(self.noise_floor, p_noise)
    }

    /// Parameter encoding a noise variance (clamped just above the floor).
    pub fn param_of_noise(&self, noise: f64) -> f64 {
        param_of_noise(self.noise_floor, noise)
    }

    /// Counters so far.
    pub fn stats(&self) -> EvalStats {
        self.memo.stats()
    }

    fn prepare(&self, kernel: &Kernel<'_>) -> Vec<Prepared> {
        let d = self.data.spec.dim;
        self.data
            .x
            .chunks_exact(d)
            .zip(self.data.directions)
            .map(|(row, &g)| kernel.prepare(row, g))
            .collect()
    }

    /// Kernel features `u = L phi(x)` of every point (`n x d`): `r2 = |u_i - u_j|^2`.
    fn features(&self, kernel: &Kernel<'_>) -> Vec<f64> {
        let d = self.data.spec.dim;
        let mut out = Vec::with_capacity(self.data.y.len() * d);
        let mut u = [0.0; hbn_core::MAX_DIM];
        let mut jac = [0.0; hbn_core::kernel::FEATURE_JACOBIAN_LEN];
        for row in self.data.x.chunks_exact(d) {
            kernel.features(row, &mut u, &mut jac);
            out.extend_from_slice(&u[..d]);
        }
        out
    }

    /// `K` (without noise) and `dk/dr2` for every pair, from features, in parallel by columns
    /// (column-major lower triangles; one `exp` per pair).
    fn gram(&self, kernel: &Kernel<'_>) -> Gram {
        let d = self.data.spec.dim;
        let n = self.data.y.len();
        let u = self.features(kernel);
        let spec = *kernel.spec();
        let sf2 = kernel.signal_variance();
        let dirs = self.data.directions;
        let mut k = vec![0.0; n * n];
        let mut c = vec![0.0; n * n];
        k.par_chunks_mut(n)
            .zip(c.par_chunks_mut(n))
            .enumerate()
            .for_each(|(j, (kcol, ccol))| {
                let uj = &u[j * d..j * d + d];
                for i in j..n {
                    let ui = &u[i * d..i * d + d];
                    let r2: f64 = ui.iter().zip(uj).map(|(a, b)| (a - b) * (a - b)).sum();
                    let (f, df) = hbn_core::kernel::profile_and_slope(spec.profile, r2);
                    let dir = spec.direction_factor(dirs[i], dirs[j]);
                    kcol[i] = sf2 * f * dir;
                    ccol[i] = sf2 * df * dir;
                }
            });
        Gram { k, c, u }
    }

    /// Factorises `K + s_n^2 I` at kernel `theta` and noise `noise` (fixed hyperparameters).
    pub fn solve(&self, theta: &[f64], noise: f64) -> Result<Solved, GpError> {
        Ok(self.solve_with_gram(theta, noise)?.0)
    }

    fn solve_with_gram(&self, theta: &[f64], noise: f64) -> Result<(Solved, Gram), GpError> {
        let kernel = Kernel::new(self.data.spec, theta, self.data.whiten)?;
        let gram = self.gram(&kernel);
        let n = self.data.y.len();
        let lower = &gram.k;
        let mut k = Mat::from_fn(n, n, |i, j| {
            if i >= j {
                lower[j * n + i]
            } else {
                lower[i * n + j]
            }
        });
        for i in 0..n {
            k[(i, i)] += noise;
        }
        let factor = factor_with_jitter(&mut k, self.max_jitter_retries)?;
        let y = Mat::from_fn(n, 1, |i, _| self.data.y[i]);
        let alpha_m = factor.llt.solve(&y);
        let alpha: Vec<f64> = (0..n).map(|i| alpha_m[(i, 0)]).collect();
        let fit: f64 = alpha.iter().zip(self.data.y).map(|(a, y)| a * y).sum();
        let lml = -0.5 * fit
            - 0.5 * factor.log_det()
            - 0.5 * n as f64 * (2.0 * std::f64::consts::PI).ln();
        if !lml.is_finite() || !alpha.iter().all(|a| a.is_finite()) {
            return Err(GpError::NotPositiveDefinite {
                jitter: factor.jitter,
                retries: factor.retries,
            });
        }
        Ok((Solved { factor, alpha, lml }, gram))
    }

    /// Log marginal likelihood and its gradient at the optimised vector `p`.
    pub fn evaluate(&self, p: &[f64]) -> Result<Evaluation, GpError> {
        if let Some(ev) = self.memo.recall(p) {
            return Ok(ev);
        }
        let n_k = self.data.spec.n_params();
        if p.len() != n_k + 1 {
            return Err(GpError::Shape {
                what: "optimised parameters",
                expected: n_k + 1,
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
        let noise = self.noise_of(p[n_k]);
        let (solved, gram) = self.solve_with_gram(theta, noise)?;
        let kernel = Kernel::new(self.data.spec, theta, self.data.whiten)?;
        let spec = self.data.spec;
        let d = spec.dim;
        let n = self.data.y.len();
        let kinv = solved.factor.inverse();
        let alpha = &solved.alpha;
        // Without warping every dK/dtheta follows from the stored K, dk/dr2 and features: no
        // exp per pair. With warping, the general path through `Kernel::grad_theta`.
        let prep = if spec.warp_units > 0 {
            self.prepare(&kernel)
        } else {
            Vec::new()
        };
        // 1/2 sum_ij W_ij dK_ij/dtheta with W = alpha alpha^T - K^{-1}, over the lower triangle.
        // Fixed row blocks summed in index order: the result does not depend on how rayon
        // schedules the blocks, so training is bit-for-bit reproducible.
        const BLOCK: usize = 16;
        let blocks: Vec<Vec<f64>> = (0..n.div_ceil(BLOCK))
            .into_par_iter()
            .map(|b| {
                let mut acc = vec![0.0; n_k];
                let mut g = vec![0.0; n_k];
                for i in b * BLOCK..((b + 1) * BLOCK).min(n) {
                    for j in 0..=i {
                        let w = alpha[i] * alpha[j] - kinv[(i, j)];
                        let w = if i == j { 0.5 * w } else { w };
                        if spec.warp_units > 0 {
                            kernel.grad_theta(&prep[i], &prep[j], &mut g);
                            for (a, gv) in acc.iter_mut().zip(&g) {
                                *a += w * gv;
                            }
                            continue;
                        }
                        let (kij, cij) = (gram.k[j * n + i], gram.c[j * n + i]);
                        let (ui, uj) = (&gram.u[i * d..i * d + d], &gram.u[j * d..j * d + d]);
                        add_pair_theta_grad(&spec, w, kij, cij, ui, uj, &mut acc);
                    }
                }
                acc
            })
            .collect();
        let mut partial = vec![0.0; n_k];
        for block in &blocks {
            for (x, y) in partial.iter_mut().zip(block) {
                *x += y;
            }
        }
        let mut grad = partial;
        let trace_w: f64 = (0..n).map(|i| alpha[i] * alpha[i] - kinv[(i, i)]).sum();
        grad.push(0.5 * trace_w * p[n_k].exp());
        // Soft bounds on every log-parameter (warp shifts a are not logs but share the bound).
        let penalty = soft_bound_penalty(p, &mut grad, self.signal_log_max);
        let ev = Evaluation {
            lml: solved.lml - penalty,
            grad,
            jitter: solved.factor.jitter,
            relative_jitter: solved.factor.relative_jitter(),
        };
        self.memo.record(p, &ev);
        Ok(ev)
    }
}

/// A training objective for the multi-start optimiser: the exact log marginal likelihood or
/// the sparse GP's variational bound. The optimised vector starts with the kernel's `theta`
/// and the noise parameter ([`noise_of`]); a sparse GP may append the inducing inputs.
pub trait Objective: Sync {
    /// Objective (to maximise) and gradient at `p`.
    fn evaluate(&self, p: &[f64]) -> Result<Evaluation, GpError>;
    /// Counters so far.
    fn stats(&self) -> EvalStats;
}

impl Objective for Likelihood<'_> {
    fn evaluate(&self, p: &[f64]) -> Result<Evaluation, GpError> {
        Likelihood::evaluate(self, p)
    }
    fn stats(&self) -> EvalStats {
        Likelihood::stats(self)
    }
}

/// Noise variance encoded by the noise parameter: `floor + exp(p)`.
pub fn noise_of(noise_floor: f64, p_noise: f64) -> f64 {
    noise_floor + p_noise.exp()
}

/// Noise parameter encoding a noise variance (clamped just above the floor).
pub fn param_of_noise(noise_floor: f64, noise: f64) -> f64 {
    (noise - noise_floor).max(noise_floor * 1e-3).ln()
}

/// Adds the smooth soft-bound penalty on log-parameters `p` to `grad`; returns the penalty.
/// Every parameter is kept inside `[-LOG_BOUND, LOG_BOUND]`; the first (`ln s_f^2`) also below
/// `signal_log_max` when that is lower.
pub(crate) fn soft_bound_penalty(p: &[f64], grad: &mut [f64], signal_log_max: f64) -> f64 {
    let mut penalty = 0.0;
    if let (Some(&v), Some(g)) = (p.first(), grad.first_mut()) {
        let excess = v - signal_log_max;
        if signal_log_max < LOG_BOUND && excess > 0.0 {
            penalty += PENALTY * excess * excess;
            *g -= 2.0 * PENALTY * excess;
        }
    }
    for (g, &v) in grad.iter_mut().zip(p) {
        let excess = v.abs() - LOG_BOUND;
        if excess > 0.0 {
            penalty += PENALTY * excess * excess;
            *g -= 2.0 * PENALTY * excess * v.signum();
        }
    }
    penalty
}

/// `acc += w * dk/dtheta` for one pair of points of an *unwarped* kernel, from the pair's
/// `k`, `c = dk/dr2` and features `u_i`, `u_j` (no `exp` needed).
#[inline]
pub(crate) fn add_pair_theta_grad(
    spec: &KernelSpec,
    w: f64,
    k: f64,
    c: f64,
    ui: &[f64],
    uj: &[f64],
    acc: &mut [f64],
) {
    acc[0] += w * k;
    let wc = w * c;
    match spec.metric {
        Metric::Ard => {
            for m in 0..spec.dim {
                let du = ui[m] - uj[m];
                acc[1 + m] -= 2.0 * wc * du * du;
            }
        }
        Metric::Isotropic | Metric::Mahalanobis => {
            let r2: f64 = ui.iter().zip(uj).map(|(a, b)| (a - b) * (a - b)).sum();
            acc[1] += scale_slope(spec.metric) * wc * r2;
        }
    }
}

/// `d r2 / d theta_1 = scale_slope * r2` for the single-scale metrics: `r2 = |u - u'|^2` with
/// `u = p / l` (isotropic, `theta_1 = ln l`) or `u = W p / sqrt(c)` (Mahalanobis,
/// `theta_1 = ln c`).
pub(crate) fn scale_slope(metric: Metric) -> f64 {
    if metric == Metric::Isotropic {
        -2.0
    } else {
        -1.0
    }
}

/// argmin adapter: minimise the negated objective.
pub(crate) struct NegLml<'b, O: Objective>(pub &'b O);

/// Cost the optimiser sees where the objective cannot be evaluated (a covariance that is not
/// positive definite even with jitter, or a non-finite value): large enough that the line
/// search backs off, small enough that its cubic interpolation cannot overflow. Without it,
/// one failed trial step would end the whole start at its initial point (a first L-BFGS step
/// of unit length can still leave the region where the covariance factors).
const FAILED_COST: f64 = 1e150;

impl<O: Objective> argmin::core::CostFunction for NegLml<'_, O> {
    type Param = Vec<f64>;
    type Output = f64;
    fn cost(&self, p: &Self::Param) -> Result<f64, argmin::core::Error> {
        Ok(self.0.evaluate(p).map_or(FAILED_COST, |e| -e.lml))
    }
}

impl<O: Objective> argmin::core::Gradient for NegLml<'_, O> {
    type Param = Vec<f64>;
    type Gradient = Vec<f64>;
    fn gradient(&self, p: &Self::Param) -> Result<Vec<f64>, argmin::core::Error> {
        Ok(match self.0.evaluate(p) {
            Ok(e) => e.grad.iter().map(|g| -g).collect(),
            Err(_) => vec![0.0; p.len()],
        })
    }
}
