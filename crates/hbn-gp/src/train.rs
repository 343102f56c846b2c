//! Fitting: the executor that runs L-BFGS from several starts on the likelihood problem and
//! keeps the best.

use crate::GpError;
use crate::data::{check_data, column_stats, select_subset, whitening};
use crate::likelihood::{Likelihood, LikelihoodData, NegLml, Objective, param_of_noise};
use crate::model::{GaussianProcess, StartReport, TrainingReport};
use crate::params::{GpParams, MeanFunction};
use argmin::core::{
    CostFunction, Executor, Gradient, IterState, KV, Problem, Solver, State, TerminationReason,
    TerminationStatus,
};
use argmin::solver::linesearch::{LineSearch, MoreThuenteLineSearch};
use argmin::solver::quasinewton::LBFGS;
use hbn_core::kernel::MAX_DIM;
use hbn_core::rng::Rng;
use hbn_core::{Kernel, Metric};
use serde::{Deserialize, Serialize};
use std::time::Instant;

/// Why an optimiser start stopped.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case", tag = "termination")]
pub enum Termination {
    /// The gradient norm or the cost change fell below its tolerance.
    Converged,
    /// The iteration limit (`max_iters`) was reached first: raise it, or accept the result.
    MaxIters,
    /// The solver stopped for another reason it names (argmin's solver exit).
    SolverExit {
        /// The solver's words.
        reason: String,
    },
    /// The start failed; the other starts may still succeed.
    Failed {
        /// What went wrong.
        failure: StartFailure,
    },
}

impl Termination {
    fn of(status: &TerminationStatus) -> Self {
        match status {
            TerminationStatus::Terminated(TerminationReason::SolverConverged)
            | TerminationStatus::Terminated(TerminationReason::TargetCostReached) => {
                Termination::Converged
            }
            TerminationStatus::Terminated(TerminationReason::MaxItersReached) => {
                Termination::MaxIters
            }
            TerminationStatus::Terminated(other) => Termination::SolverExit {
                reason: other.text().to_owned(),
            },
            TerminationStatus::NotTerminated => Termination::SolverExit {
                reason: "not terminated".to_owned(),
            },
        }
    }
}

impl std::fmt::Display for Termination {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Termination::Converged => f.write_str("converged"),
            Termination::MaxIters => f.write_str("stopped at the iteration limit"),
            Termination::SolverExit { reason } if reason.to_lowercase().contains("line search") => {
                f.write_str("stopped where no step improves further")
            }
            Termination::SolverExit { reason } => write!(f, "stopped by the optimiser ({reason})"),
            Termination::Failed { failure } => write!(f, "failed: {failure}"),
        }
    }
}

/// Why an optimiser start failed.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, thiserror::Error)]
#[serde(rename_all = "kebab-case", tag = "kind")]
pub enum StartFailure {
    /// `K + noise I` stayed non-positive-definite during the search, even with jitter.
    #[error(
        "K + noise I is not positive definite even with jitter {jitter:e}; increase the noise \
         floor or remove duplicate inputs"
    )]
    NotPositiveDefinite {
        /// Largest jitter tried.
        jitter: f64,
    },
    /// The search ended at a non-finite likelihood.
    #[error("the optimiser ended at a non-finite likelihood")]
    NonFiniteLikelihood,
    /// The line search or the solver failed (argmin's message).
    #[error("the optimiser failed: {message}")]
    Solver {
        /// The solver's message.
        message: String,
    },
}

impl StartFailure {
    fn of(e: &argmin::core::Error) -> Self {
        match e.downcast_ref::<GpError>() {
            Some(GpError::NotPositiveDefinite { jitter, .. }) => {
                StartFailure::NotPositiveDefinite { jitter: *jitter }
            }
            _ => StartFailure::Solver {
                message: e.to_string(),
            },
        }
    }
}

/// Progress of a fit, for progress bars: reported after each optimiser start.
#[derive(Clone, Debug)]
pub struct FitProgress {
    /// Start just finished (0-based).
    pub start: usize,
    /// Starts in all.
    pub n_starts: usize,
    /// Best log marginal likelihood so far.
    pub best_lml: Option<f64>,
    /// Log marginal likelihood this start reached (`None` if it failed).
    pub lml: Option<f64>,
    /// Why this start stopped.
    pub termination: Termination,
}

/// Fits a GP to row-major inputs `x` (`n x dim`) and targets `y`.
pub fn fit(params: &GpParams, x: &[f64], y: &[f64]) -> Result<GaussianProcess, GpError> {
    fit_observed(params, x, y, &mut |_| {})
}

/// [`fit`], calling `observe` after each optimiser start.
pub fn fit_observed(
    params: &GpParams,
    x: &[f64],
    y: &[f64],
    observe: &mut dyn FnMut(FitProgress),
) -> Result<GaussianProcess, GpError> {
    let t0 = Instant::now();
    params.validate()?;
    let spec = params.kernel;
    let d = spec.dim;
    let n_all = check_data(x, y, d)?;
    let data = Standardised::new(params, x, y);
    // The noise floor is relative to the targets' variance; a linear mean leaves the kernel a
    // residual of smaller scale, in whose units the floor is larger.
    let floored;
    let params = if data.output_scale == data.targets_scale {
        params
    } else {
        floored = GpParams {
            noise_floor: params.noise_floor * (data.targets_scale / data.output_scale).powi(2),
            ..params.clone()
        };
        &floored
    };
    if let Some(sparse) = &params.sparse {
        return crate::sparse::fit_sparse(params, sparse, x, y, &data, t0, observe);
    }
    let Standardised {
        input_mean,
        input_scale,
        output_mean,
        output_scale,
        std_x,
        std_y,
        linear,
        ..
    } = data;

    // Subset.
    let keep = select_subset(
        &std_x,
        d,
        params.max_points,
        params.subset_policy,
        params.seed,
    );
    let subset_policy = (keep.len() < n_all).then_some(params.subset_policy);
    let support_x: Vec<f64> = keep
        .iter()
        .flat_map(|&i| x[i * d..i * d + d].iter().copied())
        .collect();
    let support_y: Vec<f64> = keep.iter().map(|&i| y[i]).collect();
    let xs: Vec<f64> = keep
        .iter()
        .flat_map(|&i| std_x[i * d..i * d + d].iter().copied())
        .collect();
    let ys: Vec<f64> = keep.iter().map(|&i| std_y[i]).collect();
    let directions: Vec<f64> = support_x
        .chunks_exact(d)
        .map(|r| spec.direction_of(r))
        .collect();
    let whiten = if spec.metric == Metric::Mahalanobis {
        whitening(&xs, d)
    } else {
        Vec::new()
    };

    let lik = Likelihood::new(
        LikelihoodData {
            spec,
            whiten: &whiten,
            x: &xs,
            directions: &directions,
            y: &ys,
        },
        params.noise_floor,
        params.max_jitter_retries,
    )
    .with_max_signal_variance(params.max_signal_variance.unwrap_or(f64::INFINITY));

    let (theta0, noise0) = starting_point(params, &input_scale, output_scale)?;
    let mut report = TrainingReport {
        n_samples: n_all,
        n_support: keep.len(),
        subset_policy,
        ..Default::default()
    };
    let (theta, noise) = if params.optimize {
        let p = multi_start(
            &lik,
            &theta0,
            noise0,
            &[],
            params,
            EXACT_COST_TOLERANCE,
            &mut report,
            observe,
        )?;
        report.add_stats(lik.stats());
        report.check_signal_bound(p[0], lik.signal_log_max);
        let n_k = spec.n_params();
        (p[..n_k].to_vec(), lik.noise_of(p[n_k]))
    } else {
        (theta0, noise0)
    };
    // Final factorisation at the chosen hyperparameters.
    let solved = lik.solve(&theta, noise)?;
    report.final_jitter = solved.factor.jitter;
    let n = keep.len();
    let kernel = Kernel::new(spec, &theta, &whiten)?;
    let mut features = Vec::with_capacity(n * d);
    let mut u = [0.0; MAX_DIM];
    let mut jac = [0.0; hbn_core::kernel::FEATURE_JACOBIAN_LEN];
    for row in xs.chunks_exact(d) {
        kernel.features(row, &mut u, &mut jac);
        features.extend_from_slice(&u[..d]);
    }
    // Leave-one-out residuals e_i = alpha_i / [K_y^-1]_ii (Rasmussen & Williams Eq. 5.12).
    let kinv = solved.factor.inverse();
    let loo_standardised = (0..n)
        .map(|i| (solved.alpha[i] / kinv[(i, i)]).powi(2))
        .sum::<f64>()
        / n as f64;
    report.seconds = t0.elapsed().as_secs_f64();
    let mut gp = GaussianProcess {
        kernel: spec,
        theta,
        // The jitter is part of the factor's diagonal: keep it in the noise so the model is consistent.
        noise_variance: noise + solved.factor.jitter,
        whiten,
        input_mean,
        input_scale,
        output_mean,
        output_scale,
        linear,
        support_x,
        support_y,
        directions: if spec.direction.is_some() {
            directions
        } else {
            Vec::new()
        },
        features,
        alpha: solved.alpha,
        chol_packed: Vec::new(),
        sparse: None,
        log_marginal_likelihood: solved.lml,
        loo_error_variance: loo_standardised * output_scale * output_scale,
        report,
    };
    // The prediction factor comes from the routine that recomputes it when a file is loaded
    // (files leave it out), so a loaded model predicts bit for bit as the trained one.
    gp.restore_factor()?;
    Ok(gp)
}

/// Standardised copies of the data (statistics of all samples), with the prior mean removed
/// from the targets.
pub(crate) struct Standardised {
    pub input_mean: Vec<f64>,
    pub input_scale: Vec<f64>,
    pub output_mean: f64,
    /// Scale of the targets the kernel sees: the targets' standard deviation, or with a
    /// linear mean the product of it and the standardised residual's.
    pub output_scale: f64,
    /// The targets' standard deviation (1 without `normalize`).
    pub targets_scale: f64,
    /// `n x d` standardised inputs.
    pub std_x: Vec<f64>,
    /// `n` standardised targets with the prior mean removed: what the kernel models.
    pub std_y: Vec<f64>,
    /// Slopes of the linear mean in raw units (empty for a constant mean).
    pub linear: Vec<f64>,
}

/// Ridge added to the standardised inputs' second-moment matrix of the linear mean, relative
/// to its mean diagonal: keeps collinear inputs (`x_{k-1}` and `x_{k-2}`) solvable.
const LINEAR_RIDGE: f64 = 1e-8;
/// Smallest scale of the linear mean's residual, relative to the targets' (the kernel's noise
/// floor grows as the inverse square of it).
const MIN_RESIDUAL_SCALE: f64 = 1e-6;

impl Standardised {
    pub fn new(params: &GpParams, x: &[f64], y: &[f64]) -> Self {
        let d = params.kernel.dim;
        let (input_mean, input_scale) = if params.normalize {
            column_stats(x, d)
        } else {
            (vec![0.0; d], vec![1.0; d])
        };
        let (output_mean, targets_scale) = if params.normalize {
            let (m, s) = column_stats(y, 1);
            (m[0], s[0])
        } else {
            (0.0, 1.0)
        };
        let std_x: Vec<f64> = x
            .chunks_exact(d)
            .flat_map(|row| (0..d).map(|j| (row[j] - input_mean[j]) / input_scale[j]))
            .collect();
        let mut std_y: Vec<f64> = y
            .iter()
            .map(|v| (v - output_mean) / targets_scale)
            .collect();
        let (output_scale, linear) = match params.mean {
            MeanFunction::Constant => (targets_scale, Vec::new()),
            MeanFunction::Linear => {
                let beta = least_squares(&std_x, &std_y, d);
                for (t, row) in std_y.iter_mut().zip(std_x.chunks_exact(d)) {
                    *t -= row.iter().zip(&beta).map(|(a, b)| a * b).sum::<f64>();
                }
                // Floored so that an exactly linear relation keeps a finite noise floor.
                let rest_scale = if params.normalize {
                    column_stats(&std_y, 1).1[0].max(MIN_RESIDUAL_SCALE)
                } else {
                    1.0
                };
                for t in &mut std_y {
                    *t /= rest_scale;
                }
                let slopes = beta
                    .iter()
                    .zip(&input_scale)
                    .map(|(b, s)| b * targets_scale / s)
                    .collect();
                (targets_scale * rest_scale, slopes)
            }
        };
        Self {
            input_mean,
            input_scale,
            output_mean,
            output_scale,
            targets_scale,
            std_x,
            std_y,
            linear,
        }
    }
}

/// `beta` minimising `|y - X beta|^2 + ridge |beta|^2` for row-major `x` (`n x d`), by the
/// Cholesky factor of the `d x d` normal equations (`d <= MAX_DIM`). Zero when the system is
/// not positive definite even with the ridge (a constant input column is already zero after
/// standardisation and gets slope zero).
fn least_squares(x: &[f64], y: &[f64], d: usize) -> Vec<f64> {
    let n = y.len().max(1) as f64;
    let mut a = faer::Mat::<f64>::zeros(d, d);
    let mut b = faer::Mat::<f64>::zeros(d, 1);
    for (row, t) in x.chunks_exact(d).zip(y) {
        for i in 0..d {
            b[(i, 0)] += row[i] * t / n;
            for j in 0..=i {
                a[(i, j)] += row[i] * row[j] / n;
            }
        }
    }
    let mean_diag = (0..d).map(|i| a[(i, i)]).sum::<f64>() / d.max(1) as f64;
    for i in 0..d {
        a[(i, i)] += LINEAR_RIDGE * mean_diag.max(f64::MIN_POSITIVE);
    }
    match a.as_ref().llt(faer::Side::Lower) {
        Ok(llt) => {
            use faer::linalg::solvers::Solve;
            let beta = llt.solve(&b);
            let beta: Vec<f64> = (0..d).map(|i| beta[(i, 0)]).collect();
            if beta.iter().all(|v| v.is_finite()) {
                beta
            } else {
                vec![0.0; d]
            }
        }
        Err(_) => vec![0.0; d],
    }
}

/// Starting (or fixed) kernel `theta` and noise variance, in standardised units, from the
/// defaults, `params.init` and `params.raw_init` (in that order).
pub(crate) fn starting_point(
    params: &GpParams,
    input_scale: &[f64],
    output_scale: f64,
) -> Result<(Vec<f64>, f64), GpError> {
    let spec = params.kernel;
    let mut theta0 = vec![0.0; spec.n_params()];
    spec.default_theta(&mut theta0)?;
    let mut noise0 = 0.1;
    if let Some(init) = &params.init {
        theta0.clone_from(&init.theta);
        noise0 = init.noise_variance;
    }
    if let Some(raw) = &params.raw_init {
        if let Some(ls) = &raw.length_scales {
            match spec.metric {
                Metric::Ard => {
                    for j in 0..spec.dim {
                        theta0[1 + j] = (ls[j] / input_scale[j]).ln();
                    }
                }
                Metric::Isotropic | Metric::Mahalanobis => theta0[1] = ls[0].ln(),
            }
        }
        if let Some(sf2) = raw.signal_variance {
            theta0[0] = (sf2 / (output_scale * output_scale)).ln();
        }
        if let Some(noise) = raw.noise_variance {
            noise0 = noise / (output_scale * output_scale);
        }
    }
    Ok((theta0, noise0))
}

/// Smallest per-iteration improvement of the exact GP's log marginal likelihood (nats) before
/// a start ends. Smooth data give a ridge of long length scales and a large signal variance
/// on which a start with `1e-8` goes on for hundreds of evaluations to gain less than 0.001
/// nats (on a 1000-sample Bouc-Wen log, 802 evaluations against 122 with `1e-5`, the same
/// likelihood to three decimals); `1e-5` ends it there.
pub(crate) const EXACT_COST_TOLERANCE: f64 = 1e-5;
/// The absolute tolerance of a sparse GP that learns its inducing inputs (`m d` more
/// parameters, each iteration gaining little).
pub(crate) const COST_TOLERANCE: f64 = 1e-8;
/// The sparse bound's counterpart, per sample: its value grows with the sample count, and an
/// absolute `1e-8` on a 10,000-sample search subset keeps every start iterating to
/// `max_iters` for changes far below what moves a hyperparameter. The bound's own rounding
/// noise is about `1e-8` of its value (evaluations at the same point, as the line search
/// closes in, differ by `8e-5` nats on a 3000-sample bound of 5630 nats), so `1e-8` per
/// sample (`3e-5` nats there) lies below the noise, and the line search goes on for dozens
/// of evaluations that change the bound only in that noise. With `1e-7` the demo's three
/// sparse fits take 58, 50 and 50 evaluations (101, 170 and 60 with `1e-8`), their bounds
/// within 0.002 nats.
pub(crate) const COST_TOLERANCE_PER_SAMPLE: f64 = 1e-7;
/// The stall tolerance per sample of the sparse bound's refinement on every sample (after the
/// search, on a subset when there are more than [`crate::SparseParams::search_samples`]
/// samples, and the inducing inputs chosen again at its optimum).
/// The full bound's rounding noise grows with the sample count and with the signal variance:
/// on the 100,000-sample benchmark, the sensor GP's refinement, its signal variance at the
/// `1e5` box, gains 187,500.9 -> 187,519.1 nats in its first 8 evaluations; with `1e-7` per
/// sample (0.01 nats, below that noise) it then makes 58 more whose values scatter by
/// 0.2 nats while the best rises by 0.23 (about 7 s of the 30).
/// Three iterations that together gain less than `1e-6` nats per sample (0.1 nats on
/// 100,000) end it ([`run_lbfgs_with_stall`]; one iteration's gain alone stops that
/// benchmark's transition GP 28 nats short, in a valley it crosses slowly): the refinement
/// exists for the tens of nats a subset's optimum leaves (34 for that transition GP).
pub(crate) const REFINE_TOLERANCE_PER_SAMPLE: f64 = 1e-6;

/// Runs L-BFGS from `params.n_starts` starts (the first at `theta0`/`noise0`, the rest
/// random in `theta` and the noise; `tail`, e.g. inducing inputs, is appended unchanged) and
/// returns the best optimised vector. Every start is recorded in `report` (the caller adds
/// the objective's counters with [`TrainingReport::add_stats`]).
#[allow(clippy::too_many_arguments)]
pub(crate) fn multi_start<O: Objective>(
    objective: &O,
    theta0: &[f64],
    noise0: f64,
    tail: &[f64],
    params: &GpParams,
    cost_tolerance: f64,
    report: &mut TrainingReport,
    observe: &mut dyn FnMut(FitProgress),
) -> Result<Vec<f64>, GpError> {
    let spec = params.kernel;
    let mut rng = Rng::new(params.seed);
    let mut best: Option<(f64, Vec<f64>, usize)> = None;
    let mut last_failure: Option<StartFailure> = None;
    for start in 0..params.n_starts {
        let mut p0 = theta0.to_vec();
        p0.push(param_of_noise(
            params.noise_floor,
            noise0.max(params.noise_floor * 2.0),
        ));
        if start > 0 {
            randomize(&mut p0, &spec, &mut rng);
        }
        p0.extend_from_slice(tail);
        let initial_lml = objective.evaluate(&p0).ok().map(|e| e.lml);
        let (lml, termination) = match run_lbfgs(objective, p0, params.max_iters, cost_tolerance) {
            Ok((p, lml, iters, termination)) => {
                report.starts.push(StartReport {
                    initial_lml,
                    final_lml: Some(lml),
                    iterations: iters,
                    error: None,
                });
                if best.as_ref().is_none_or(|b| lml > b.0) {
                    best = Some((lml, p, start));
                }
                (Some(lml), termination)
            }
            Err(failure) => {
                report.starts.push(StartReport {
                    initial_lml,
                    final_lml: None,
                    iterations: 0,
                    error: Some(failure.to_string()),
                });
                last_failure = Some(failure.clone());
                (None, Termination::Failed { failure })
            }
        };
        observe(FitProgress {
            start,
            n_starts: params.n_starts,
            best_lml: best.as_ref().map(|b| b.0),
            lml,
            termination,
        });
    }
    let Some((_, p, start)) = best else {
        return Err(GpError::OptimizationFailed {
            starts: params.n_starts,
            last: last_failure.unwrap_or(StartFailure::NonFiniteLikelihood),
        });
    };
    report.best_start = Some(start);
    Ok(p)
}

/// Random restart around the defaults, in log space.
fn randomize(p: &mut [f64], spec: &hbn_core::KernelSpec, rng: &mut Rng) {
    let ln10 = std::f64::consts::LN_10;
    p[0] = rng.uniform_in(-ln10, ln10);
    for j in 0..spec.n_metric() {
        p[1 + j] = match spec.metric {
            Metric::Mahalanobis => rng.uniform_in(-ln10, 2.0 * ln10),
            _ => rng.uniform_in(-ln10, ln10),
        };
    }
    let m = spec.dim * spec.warp_units;
    for i in 0..m {
        p[spec.warp_a_offset() + i] = rng.uniform_in(-2.0, 2.0);
        p[spec.warp_b_offset() + i] = rng.uniform_in(-1.5, 0.5);
    }
    // The noise parameter follows theta.
    p[spec.n_params()] = rng.uniform_in(-4.0 * ln10, -0.5);
}

/// The state argmin's line searches run on.
type LineState = IterState<Vec<f64>, Vec<f64>, (), (), (), f64>;

/// The More-Thuente line search as L-BFGS-B runs it (Byrd, Lu, Nocedal and Zhu 1995; the
/// optimiser of scipy's `fmin_l_bfgs_b`, which scikit-learn's GP uses): the first search of a
/// run tries a step of unit length in parameter space (`1 / |d|` along the steepest-descent
/// direction `d`, whose length is the gradient's), later ones the quasi-Newton step 1, and a
/// search ends once its interval of uncertainty is within 10% of the step (`xtol = 0.1`).
///
/// argmin's defaults are a first step of `|g|` (hundreds of log-units on a 100,000-sample
/// bound, so the first search spends about eight evaluations backing off and growing again)
/// and `xtol = 1e-10`. The second matters when the bound's rounding noise exceeds the
/// decrease a search looks for: on a 10,000-sample sensor search with the signal variance at
/// its bound (noise about 0.02 nats), it gives searches of 30 evaluations at one point.
///
/// Only `init` and `next_iter` are delegated: argmin's More-Thuente search keeps the
/// default `terminate` and ends itself from `next_iter`.
#[derive(Clone)]
struct LbfgsbLineSearch {
    inner: MoreThuenteLineSearch<Vec<f64>, Vec<f64>, f64>,
    searches: u64,
}

impl LbfgsbLineSearch {
    /// L-BFGS-B's relative width tolerance of the interval of uncertainty.
    const WIDTH_TOLERANCE: f64 = 0.1;

    fn new() -> Result<Self, argmin::core::Error> {
        Ok(Self {
            inner: MoreThuenteLineSearch::new().with_width_tolerance(Self::WIDTH_TOLERANCE)?,
            searches: 0,
        })
    }
}

impl LineSearch<Vec<f64>, f64> for LbfgsbLineSearch {
    /// Called by L-BFGS on its own copy before each search (the search runs on a clone), so
    /// the count persists across the run's searches.
    fn search_direction(&mut self, direction: Vec<f64>) {
        let unit_step = 1.0 / direction.iter().map(|v| v * v).sum::<f64>().sqrt();
        let step = if self.searches == 0 && unit_step.is_finite() && unit_step > 0.0 {
            unit_step
        } else {
            1.0
        };
        self.searches += 1;
        // `step` is positive and finite here (a zero or subnormal direction gives an infinite
        // `unit_step`, and 1 is used), which is all `initial_step_length` checks.
        let _ = self.inner.initial_step_length(step);
        self.inner.search_direction(direction);
    }

    fn initial_step_length(&mut self, step_length: f64) -> Result<(), argmin::core::Error> {
        self.inner.initial_step_length(step_length)
    }
}

impl<O> Solver<O, LineState> for LbfgsbLineSearch
where
    O: CostFunction<Param = Vec<f64>, Output = f64>
        + Gradient<Param = Vec<f64>, Gradient = Vec<f64>>,
{
    fn name(&self) -> &str {
        "More-Thuente line search (L-BFGS-B settings)"
    }

    fn init(
        &mut self,
        problem: &mut Problem<O>,
        state: LineState,
    ) -> Result<(LineState, Option<KV>), argmin::core::Error> {
        self.inner.init(problem, state)
    }

    fn next_iter(
        &mut self,
        problem: &mut Problem<O>,
        state: LineState,
    ) -> Result<(LineState, Option<KV>), argmin::core::Error> {
        self.inner.next_iter(problem, state)
    }
}

/// L-BFGS that also stops once its best value has improved by less than `tolerance` over the
/// last [`StallGuard::WINDOW`] iterations. argmin's cost tolerance compares one iteration with
/// the one before, so where an objective's rounding noise exceeds it (a sparse bound on
/// 100,000 samples with its signal variance at the box: values scattered by 0.2 nats) the
/// iterations go on, each step drawing a new value from the noise. A tolerance of 0 never
/// stops it (the best value never rises).
struct StallGuard<S> {
    inner: S,
    tolerance: f64,
    /// The best cost when each iteration began (the first: after `init`).
    best: Vec<f64>,
}

impl<S> StallGuard<S> {
    /// Iterations the best value must improve over by at least the tolerance.
    const WINDOW: usize = 3;
}

impl<O, S> Solver<O, LineState> for StallGuard<S>
where
    S: Solver<O, LineState>,
{
    fn name(&self) -> &str {
        self.inner.name()
    }

    fn init(
        &mut self,
        problem: &mut Problem<O>,
        state: LineState,
    ) -> Result<(LineState, Option<KV>), argmin::core::Error> {
        self.inner.init(problem, state)
    }

    fn next_iter(
        &mut self,
        problem: &mut Problem<O>,
        state: LineState,
    ) -> Result<(LineState, Option<KV>), argmin::core::Error> {
        self.inner.next_iter(problem, state)
    }

    fn terminate(&mut self, state: &LineState) -> TerminationStatus {
        let inner = self.inner.terminate(state);
        if inner.terminated() {
            return inner;
        }
        let now = state.get_best_cost();
        self.best.push(now);
        let then = self
            .best
            .len()
            .checked_sub(Self::WINDOW + 1)
            .and_then(|i| self.best.get(i));
        match then {
            Some(&then) if then - now < self.tolerance => {
                TerminationStatus::Terminated(TerminationReason::SolverConverged)
            }
            _ => TerminationStatus::NotTerminated,
        }
    }
}

/// One L-BFGS start: best parameters, their log marginal likelihood, iterations, and why it
/// stopped.
/// `cost_tolerance` ends the start once an iteration improves the objective by less (in
/// nats; [`EXACT_COST_TOLERANCE`] for the exact GP, [`COST_TOLERANCE`] for a sparse GP that
/// learns its inducing inputs, [`COST_TOLERANCE_PER_SAMPLE`] times the sample
/// count for the sparse bound).
pub(crate) fn run_lbfgs<O: Objective>(
    lik: &O,
    p0: Vec<f64>,
    max_iters: u64,
    cost_tolerance: f64,
) -> Result<(Vec<f64>, f64, u64, Termination), StartFailure> {
    run_lbfgs_with_stall(lik, p0, max_iters, cost_tolerance, 0.0)
}

/// [`run_lbfgs`] that also ends once the best value has gained less than `stall_tolerance`
/// nats over the last three iterations ([`StallGuard`]; 0: never).
pub(crate) fn run_lbfgs_with_stall<O: Objective>(
    lik: &O,
    p0: Vec<f64>,
    max_iters: u64,
    cost_tolerance: f64,
    stall_tolerance: f64,
) -> Result<(Vec<f64>, f64, u64, Termination), StartFailure> {
    let linesearch = LbfgsbLineSearch::new().map_err(|e| StartFailure::of(&e))?;
    let lbfgs = LBFGS::new(linesearch, 10)
        .with_tolerance_grad(1e-5)
        .and_then(|s| s.with_tolerance_cost(cost_tolerance))
        .map_err(|e| StartFailure::of(&e))?;
    let solver = StallGuard {
        inner: lbfgs,
        tolerance: stall_tolerance,
        best: Vec::new(),
    };
    let res = Executor::new(NegLml(lik), solver)
        .configure(|state| state.param(p0).max_iters(max_iters))
        .run()
        .map_err(|e| StartFailure::of(&e))?;
    let state = res.state();
    let lml = -state.get_best_cost();
    let p = match state.get_best_param() {
        Some(p) if lml.is_finite() => p.clone(),
        _ => return Err(StartFailure::NonFiniteLikelihood),
    };
    Ok((
        p,
        lml,
        state.get_iter(),
        Termination::of(state.get_termination_status()),
    ))
}

impl GaussianProcess {
    /// Forgets the wall-clock seconds in the training report, so that the saved GP (and an HBN
    /// model holding it) depends only on its data and parameters.
    pub fn forget_timing(&mut self) {
        self.report.seconds = 0.0;
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::likelihood::{EvalStats, Evaluation};
    use std::sync::Mutex;

    /// `-scale * sum ln cosh(p_i - 1)`: a bowl around 1 that grows linearly far away (as a
    /// log likelihood does in log-parameters), plus a deterministic noise of relative size
    /// `noise` on the value and the gradient, drawn from the bits of `p` (a bound's rounding
    /// noise). Records every point evaluated.
    struct Bowl {
        scale: f64,
        noise: f64,
        points: Mutex<Vec<Vec<f64>>>,
    }

    impl Bowl {
        fn new(scale: f64, noise: f64) -> Self {
            Self {
                scale,
                noise,
                points: Mutex::new(Vec::new()),
            }
        }

        fn distinct_points(&self) -> Vec<Vec<f64>> {
            let mut seen: Vec<Vec<f64>> = Vec::new();
            for p in self.points.lock().unwrap().iter() {
                if seen.last() != Some(p) {
                    seen.push(p.clone());
                }
            }
            seen
        }
    }

    impl Objective for Bowl {
        fn evaluate(&self, p: &[f64]) -> Result<Evaluation, GpError> {
            self.points.lock().unwrap().push(p.to_vec());
            let value: f64 = p.iter().map(|v| (v - 1.0).cosh().ln()).sum::<f64>() * -self.scale;
            let bits = p.iter().fold(0u64, |h, v| {
                (h ^ v.to_bits()).wrapping_mul(0x9E37_79B9_7F4A_7C15)
            });
            let unit = (bits >> 11) as f64 / (1u64 << 53) as f64 - 0.5;
            Ok(Evaluation {
                lml: value + unit * self.noise * self.scale * p.len() as f64,
                grad: p
                    .iter()
                    .map(|v| -self.scale * ((v - 1.0).tanh() + unit * self.noise))
                    .collect(),
                jitter: 0.0,
                relative_jitter: 0.0,
            })
        }

        fn stats(&self) -> EvalStats {
            EvalStats::default()
        }
    }

    #[test]
    fn the_first_trial_step_has_unit_length_whatever_the_gradient_scale() {
        for scale in [1e-3, 1.0, 1e5] {
            let bowl = Bowl::new(scale, 0.0);
            let p0 = vec![0.0, 3.0, -2.0];
            let (p, _, _, _) = run_lbfgs(&bowl, p0.clone(), 100, 1e-12 * scale).unwrap();
            assert!(p.iter().all(|v| (v - 1.0).abs() < 1e-2), "{p:?}");
            let points = bowl.distinct_points();
            let step: f64 = points[1]
                .iter()
                .zip(&p0)
                .map(|(a, b)| (a - b).powi(2))
                .sum::<f64>()
                .sqrt();
            assert!(
                (step - 1.0).abs() < 1e-12,
                "scale {scale}: first step {step}"
            );
        }
    }

    #[test]
    fn a_search_in_rounding_noise_ends_within_a_few_evaluations() {
        // Noise of 1e-6 of the scale per coordinate: near the optimum no trial point can show
        // the decrease the line search looks for. With a width tolerance of 1e-10 each search
        // there halves its interval about 30 times before it gives up.
        let bowl = Bowl::new(1e5, 1e-6);
        let p0 = vec![0.0, 3.0, -2.0, 0.5];
        let (p, _, iterations, _) = run_lbfgs(&bowl, p0, 100, 1e-7 * 1e4).unwrap();
        assert!(p.iter().all(|v| (v - 1.0).abs() < 1e-2), "{p:?}");
        let evaluations = bowl.distinct_points().len() as u64;
        // Here: 39 evaluations in 10 iterations; 85 in 11 with a width tolerance of 1e-10.
        assert!(
            evaluations <= 5 * iterations,
            "{evaluations} evaluations in {iterations} iterations"
        );
    }

    /// [`Bowl`]'s value with noise of `amplitude` nats on the value alone (the gradient exact),
    /// as a sparse bound on many samples has it: its terms cancel in the value, while the
    /// gradient is analytic.
    struct NoisyValue {
        bowl: Bowl,
        amplitude: f64,
    }

    impl Objective for NoisyValue {
        fn evaluate(&self, p: &[f64]) -> Result<Evaluation, GpError> {
            let mut ev = self.bowl.evaluate(p)?;
            let bits = p.iter().fold(0x51u64, |h, v| {
                (h ^ v.to_bits()).wrapping_mul(0x9E37_79B9_7F4A_7C15)
            });
            ev.lml += ((bits >> 11) as f64 / (1u64 << 53) as f64 - 0.5) * self.amplitude;
            Ok(ev)
        }

        fn stats(&self) -> EvalStats {
            EvalStats::default()
        }
    }

    #[test]
    fn iterations_in_rounding_noise_stop_once_three_gain_too_little() {
        // Value noise of a nat: next to the optimum every step draws a new value from it, so
        // one iteration's change (the cost tolerance) rarely falls below 1e-3, and the line
        // searches go on until the gradient is small. Here: 11 iterations and 31 evaluations
        // without the stall rule, 7 and 12 with it.
        let p0 = vec![0.0, 3.0, -2.0, 0.5];
        let run = |stall: f64| {
            let f = NoisyValue {
                bowl: Bowl::new(1e3, 0.0),
                amplitude: 1.0,
            };
            let (p, lml, iterations, termination) =
                run_lbfgs_with_stall(&f, p0.clone(), 60, 1e-3, stall).unwrap();
            assert!(
                matches!(termination, Termination::Converged),
                "{termination:?}"
            );
            (p, lml, iterations, f.bowl.distinct_points().len())
        };
        let (_, lml_free, iterations_free, evaluations_free) = run(0.0);
        let (p, lml, iterations, evaluations) = run(2.0);
        assert!(p.iter().all(|v| (v - 1.0).abs() < 1e-2), "{p:?}");
        assert!(
            iterations < iterations_free && 2 * evaluations < evaluations_free,
            "{iterations} iterations ({evaluations} evaluations) against {iterations_free} \
             ({evaluations_free})"
        );
        // What the extra iterations found is noise: a nat at most.
        assert!(lml_free - lml < 1.0, "{lml_free} against {lml}");
    }

    #[test]
    fn the_stall_rule_leaves_a_steady_descent_alone() {
        // From far out the bowl's slope is constant: every iteration gains far more than the
        // stall tolerance, so the run ends at the optimum, where the cost tolerance ends it.
        let bowl = Bowl::new(1.0, 0.0);
        let (p, _, _, termination) =
            run_lbfgs_with_stall(&bowl, vec![12.0, -9.0, 7.0], 200, 1e-12, 1e-6).unwrap();
        assert!(p.iter().all(|v| (v - 1.0).abs() < 1e-4), "{p:?}");
        assert!(
            matches!(termination, Termination::Converged),
            "{termination:?}"
        );
    }
}
