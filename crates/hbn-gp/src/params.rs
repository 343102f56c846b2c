//! Checked training parameters (linfa style): validated once, before fitting.

use crate::GpError;
use hbn_core::KernelSpec;
use serde::{Deserialize, Serialize};

/// How to reduce the data when there are more samples than `max_points`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum SubsetPolicy {
    /// Greedy farthest-point sampling in standardised input space (deterministic, covers the
    /// input space evenly). The default.
    FarthestPoint,
    /// A uniformly random subset drawn with the training seed.
    Random,
}

/// The GP's prior mean: what the kernel does not have to explain.
///
/// With [`MeanFunction::Linear`] the targets' least-squares linear fit on the inputs is
/// subtracted before the GP is trained (in standardised units, with a tiny ridge), and added
/// back in prediction, its slopes joining the mean gradient. A relation that is nearly linear,
/// as `x_k` in `x_{k-1}` at a high sample rate, otherwise makes the likelihood nearly flat along a
/// ridge of growing signal variance and length scales: the optimiser follows it towards the
/// box edge and the fit extrapolates like a polynomial. The kernel then models only the
/// nonlinear rest, whose scale sets the output standardisation. `docs/sparse.md` has the
/// measurements.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum MeanFunction {
    /// The targets' mean (with `normalize`; zero without). Parameters and model files
    /// without the field read as this.
    #[default]
    Constant,
    /// The targets' linear least-squares fit on the inputs.
    Linear,
}

impl MeanFunction {
    /// Every choice, in the order of their names.
    pub const ALL: [MeanFunction; 2] = [MeanFunction::Constant, MeanFunction::Linear];

    /// `constant` or `linear`.
    pub const fn name(self) -> &'static str {
        match self {
            MeanFunction::Constant => "constant",
            MeanFunction::Linear => "linear",
        }
    }
}

impl std::fmt::Display for MeanFunction {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

impl std::str::FromStr for MeanFunction {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        MeanFunction::ALL
            .into_iter()
            .find(|m| m.name().eq_ignore_ascii_case(s.trim()))
            .ok_or_else(|| format!("unknown mean `{s}`; choose constant or linear"))
    }
}

/// Hyperparameters to start from (standardised units, see [`hbn_core::kernel`]).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Hyperparameters {
    /// Kernel hyperparameters in the layout of [`KernelSpec::n_params`].
    pub theta: Vec<f64>,
    /// Noise variance `s_n^2` (standardised output units).
    pub noise_variance: f64,
}

/// Starting (or fixed) hyperparameters in the *raw* units of the data; `None` entries keep
/// their defaults. Converted to the standardised parameterisation once the data are seen.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct RawHyperparameters {
    /// Length scales: one per input (ARD) or one (isotropic, Mahalanobis scale `c`).
    pub length_scales: Option<Vec<f64>>,
    /// Signal variance `s_f^2`.
    pub signal_variance: Option<f64>,
    /// Noise variance `s_n^2`.
    pub noise_variance: Option<f64>,
}

/// Settings of the sparse (inducing-point) GP: Titsias' collapsed variational bound
/// ("SGPR"/"VFE") over every sample, `O(n m^2)` to train and `O(m^2)` to predict.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct SparseParams {
    /// Number of inducing points `m` (`>= 1`; at most the number of distinct samples are used).
    pub n_inducing: usize,
    /// Fixed initial inducing inputs in raw units (`m x dim`, row-major); `None` selects them
    /// by greedy conditional variance (pivoted Cholesky, Burt et al. 2020).
    #[serde(default)]
    pub inducing_inputs: Option<Vec<f64>>,
    /// Learn the inducing inputs together with the hyperparameters (analytic gradients).
    #[serde(default)]
    pub optimize_inducing: bool,
    /// With more samples than this, the multi-start search runs on an evenly strided subset
    /// of this many samples, then L-BFGS refines the winner on every sample for at most
    /// `refine_iters` iterations. Hyperparameters are a handful of numbers that a subset
    /// determines well; the refinement and the final posterior use every sample.
    #[serde(default = "default_search_samples")]
    pub search_samples: usize,
    /// Iterations of the refinement on every sample (0 skips it).
    #[serde(default = "default_refine_iters")]
    pub refine_iters: u64,
}

fn default_search_samples() -> usize {
    SparseParams::DEFAULT_SEARCH_SAMPLES
}

fn default_refine_iters() -> u64 {
    SparseParams::DEFAULT_REFINE_ITERS
}

impl SparseParams {
    /// Default of [`SparseParams::search_samples`].
    pub const DEFAULT_SEARCH_SAMPLES: usize = 10_000;
    /// Default of [`SparseParams::refine_iters`].
    pub const DEFAULT_REFINE_ITERS: u64 = 20;

    /// `m` inducing points chosen by greedy conditional variance, not optimised.
    pub fn new(n_inducing: usize) -> Self {
        Self {
            n_inducing,
            inducing_inputs: None,
            optimize_inducing: false,
            search_samples: Self::DEFAULT_SEARCH_SAMPLES,
            refine_iters: Self::DEFAULT_REFINE_ITERS,
        }
    }
}

/// GP training parameters. Build with [`GpParams::new`], adjust fields, then
/// [`GpParams::validate`] (done by [`crate::fit`]).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct GpParams {
    /// Kernel structure.
    pub kernel: KernelSpec,
    /// Starting (or, with `optimize = false`, fixed) hyperparameters; `None` = defaults.
    pub init: Option<Hyperparameters>,
    /// Starting (or fixed) hyperparameters in raw data units; applied after `init`.
    pub raw_init: Option<RawHyperparameters>,
    /// Optimise hyperparameters by maximising the log marginal likelihood.
    pub optimize: bool,
    /// Optimiser starts in all (the first from `init`/defaults, the rest random). `>= 1`.
    pub n_starts: usize,
    /// L-BFGS iterations per start.
    pub max_iters: u64,
    /// Seed of the random starts and of the random subset policy.
    pub seed: u64,
    /// Standardise inputs (per column) and outputs before the kernel. On by default.
    pub normalize: bool,
    /// Lower bound of the noise variance during optimisation (`> 0`), relative to the
    /// targets' variance (with `normalize`; raw units without). With a linear mean the kernel
    /// models the residual, and the floor in its units is scaled to keep this meaning.
    pub noise_floor: f64,
    /// Most support points kept; more samples are reduced by `subset_policy`.
    pub max_points: usize,
    /// Subset policy when the data exceed `max_points`.
    pub subset_policy: SubsetPolicy,
    /// Jitter retries when the Cholesky factorisation fails (each multiplies the jitter by 10).
    pub max_jitter_retries: usize,
    /// `Some` trains a sparse GP on every sample (`max_points` and `subset_policy` are then
    /// unused); `None` trains the exact GP.
    #[serde(default)]
    pub sparse: Option<SparseParams>,
    /// The prior mean ([`MeanFunction`]); parameter sets without the field read as
    /// [`MeanFunction::Constant`].
    #[serde(default)]
    pub mean: MeanFunction,
    /// Largest signal variance `s_f^2` the optimiser may reach, in the units the kernel sees
    /// (the variance of what it models: the targets', or with a linear mean the residual's,
    /// when `normalize`), kept by the same smooth penalty as the `[1e-5, 1e5]` box of every
    /// log-parameter; exact and sparse GPs alike. `None`: only the box. Near-linear and
    /// near-polynomial relations make the likelihood nearly flat along a ridge of growing
    /// `s_f^2` and length scales; on noise-free data the optimiser follows it to the box edge,
    /// a fit that extrapolates like a polynomial and can carry a filter away from the data.
    /// `docs/sparse.md` has the measurements.
    #[serde(default)]
    pub max_signal_variance: Option<f64>,
}

impl GpParams {
    /// Defaults for a kernel: optimise, 3 starts, normalise, noise floor 1e-6, 1000 points.
    pub fn new(kernel: KernelSpec) -> Self {
        Self {
            kernel,
            init: None,
            raw_init: None,
            optimize: true,
            n_starts: 3,
            max_iters: 200,
            seed: 0,
            normalize: true,
            noise_floor: 1e-6,
            max_points: 1000,
            subset_policy: SubsetPolicy::FarthestPoint,
            max_jitter_retries: 8,
            sparse: None,
            mean: MeanFunction::Constant,
            max_signal_variance: None,
        }
    }

    /// Checks every field once; the algorithm then trusts them.
    pub fn validate(&self) -> Result<(), GpError> {
        self.kernel.validate()?;
        let bad =
            |name: &'static str, reason: String| Err(GpError::InvalidParameter { name, reason });
        if self.n_starts == 0 {
            return bad("n_starts", "must be >= 1".into());
        }
        if !(self.noise_floor.is_finite() && self.noise_floor > 0.0) {
            return bad(
                "noise_floor",
                format!("must be finite and > 0, got {}", self.noise_floor),
            );
        }
        if !(crate::MIN_POINTS..=crate::MAX_EXACT_POINTS).contains(&self.max_points) {
            return bad(
                "max_points",
                format!(
                    "must be in {}..={}, got {} (for more samples use a sparse GP: n_inducing)",
                    crate::MIN_POINTS,
                    crate::MAX_EXACT_POINTS,
                    self.max_points
                ),
            );
        }
        if let Some(v) = self.max_signal_variance
            && !(v.is_finite() && v > 0.0)
        {
            return bad(
                "max_signal_variance",
                format!("must be finite and > 0, got {v}"),
            );
        }
        if let Some(sp) = &self.sparse {
            if sp.n_inducing == 0 {
                return bad("n_inducing", "must be >= 1".into());
            }
            if sp.search_samples < 2 {
                return bad(
                    "search_samples",
                    format!("must be >= 2, got {}", sp.search_samples),
                );
            }
            if let Some(z) = &sp.inducing_inputs {
                if sp.n_inducing.checked_mul(self.kernel.dim) != Some(z.len()) {
                    return bad(
                        "inducing_inputs",
                        format!(
                            "need n_inducing x dim = {} x {} values, got {}",
                            sp.n_inducing,
                            self.kernel.dim,
                            z.len()
                        ),
                    );
                }
                if !z.iter().all(|v| v.is_finite()) {
                    return bad("inducing_inputs", "must be finite".into());
                }
            }
        }
        if let Some(init) = &self.init {
            if init.theta.len() != self.kernel.n_params() {
                return bad(
                    "init.theta",
                    format!(
                        "kernel needs {} hyperparameters, got {}",
                        self.kernel.n_params(),
                        init.theta.len()
                    ),
                );
            }
            if !init.theta.iter().all(|v| v.is_finite()) {
                return bad("init.theta", "must be finite".into());
            }
            if !(init.noise_variance.is_finite() && init.noise_variance >= 0.0) {
                return bad(
                    "init.noise_variance",
                    format!("must be finite and >= 0, got {}", init.noise_variance),
                );
            }
        }
        if let Some(raw) = &self.raw_init {
            let positive = |v: f64| v.is_finite() && v > 0.0;
            if let Some(ls) = &raw.length_scales {
                let want = if self.kernel.metric == hbn_core::Metric::Ard {
                    self.kernel.dim
                } else {
                    1
                };
                if ls.len() != want {
                    return bad(
                        "length_scales",
                        format!("this kernel takes {want} length scale(s), got {}", ls.len()),
                    );
                }
                if !ls.iter().all(|&l| positive(l)) {
                    return bad("length_scales", "must be finite and > 0".into());
                }
            }
            if raw.signal_variance.is_some_and(|v| !positive(v)) {
                return bad("signal_variance", "must be finite and > 0".into());
            }
            if raw
                .noise_variance
                .is_some_and(|v| !(v.is_finite() && v >= 0.0))
            {
                return bad("noise_variance", "must be finite and >= 0".into());
            }
        }
        Ok(())
    }
}
