//! The trained GP: owned arrays, a borrowed [`GpView`] for allocation-free prediction, and
//! versioned persistence.

use crate::GpError;
use crate::params::SubsetPolicy;
use hbn_core::{CoreError, GpParts, GpView, Kernel, KernelSpec, Prediction, Variance, Want};
use serde::{Deserialize, Serialize};
use std::path::Path;

/// Format tag of a standalone GP file.
pub const GP_FORMAT: &str = "hbn-gp";
/// GP file format version written. Files of every version from [`GP_FORMAT_OLDEST`] to this
/// one load: a sparse GP needs version 2 or above; versions 1 and 2 hold the exact GP's
/// Cholesky factor, which versions 3 and above leave out and loading recomputes; versions 2
/// and 3 hold a sparse GP's variance as two factors, which loading folds into one; only
/// version 5 holds the slopes of a linear prior mean.
pub const GP_FORMAT_VERSION: u32 = 5;
/// Oldest GP file format version this build reads.
pub const GP_FORMAT_OLDEST: u32 = 1;

/// One optimiser start.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct StartReport {
    /// Log marginal likelihood at the starting point (`None` if it could not be evaluated).
    pub initial_lml: Option<f64>,
    /// Log marginal likelihood reached (`None` if the start failed).
    pub final_lml: Option<f64>,
    /// L-BFGS iterations.
    pub iterations: u64,
    /// Why the start failed, if it did.
    pub error: Option<String>,
}

/// What training did: subset, starts, jitter. Nothing numerical is silent.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct TrainingReport {
    /// Samples given.
    pub n_samples: usize,
    /// Support points kept (exact GP) or inducing points used (sparse GP).
    pub n_support: usize,
    /// Inducing points asked for (sparse GP only); fewer are used when the kernel matrix of
    /// the inputs has a lower numerical rank (every other input's variance given the points
    /// chosen is below `1e-10` of the signal variance, [`crate::sparse::greedy_variance_selection`]).
    #[serde(default)]
    pub n_inducing_requested: Option<usize>,
    /// The policy applied when samples exceeded the maximum (`None` = all kept).
    pub subset_policy: Option<SubsetPolicy>,
    /// One entry per optimiser start (empty when hyperparameters were fixed).
    pub starts: Vec<StartReport>,
    /// Index of the start that won.
    pub best_start: Option<usize>,
    /// Sparse GP with more samples than its search subset: the starts ran on
    /// `search_samples` samples, and this L-BFGS run refined the winner on every sample.
    #[serde(default)]
    pub refinement: Option<StartReport>,
    /// Samples the multi-start search used (sparse GP; `None` = all).
    #[serde(default)]
    pub search_samples: Option<usize>,
    /// Likelihood evaluations in all.
    pub evaluations: usize,
    /// Evaluations whose Cholesky needed jitter.
    pub jitter_evaluations: usize,
    /// Largest jitter used during optimisation, relative to the mean diagonal of the matrix
    /// factored.
    pub max_jitter: f64,
    /// Jitter in the final factor (added to the noise variance on the diagonal).
    pub final_jitter: f64,
    /// Wall-clock seconds.
    pub seconds: f64,
    /// The optimised signal variance ended at its upper bound (the box's `1e5`, or a sparse
    /// GP's [`crate::GpParams::max_signal_variance`]), in the kernel's units.
    #[serde(default)]
    pub signal_variance_at_bound: Option<f64>,
}

impl TrainingReport {
    /// Records `signal_variance_at_bound` when `ln_sf2` (optimised) is within 0.05 of
    /// `signal_log_max`.
    pub(crate) fn check_signal_bound(&mut self, ln_sf2: f64, signal_log_max: f64) {
        if ln_sf2 > signal_log_max - 0.05 {
            self.signal_variance_at_bound = Some(signal_log_max.exp());
        }
    }

    /// Adds an objective's evaluation counters.
    pub fn add_stats(&mut self, stats: crate::likelihood::EvalStats) {
        self.evaluations += stats.evaluations;
        self.jitter_evaluations += stats.jitter_evaluations;
        self.max_jitter = self.max_jitter.max(stats.max_jitter);
    }

    /// How the support points were chosen, when they are a subset of the samples (normal for
    /// the exact GP on a long log; not a warning): e.g. "chosen from 2994 samples by
    /// farthest-point selection".
    pub fn subset_note(&self) -> Option<String> {
        self.subset_policy.map(|p| {
            format!(
                "chosen from {} samples by {}",
                self.n_samples,
                match p {
                    crate::SubsetPolicy::FarthestPoint => "farthest-point selection",
                    crate::SubsetPolicy::Random => "random selection",
                }
            )
        })
    }

    /// Human-readable warnings (jitter, failed starts, fewer inducing points than asked);
    /// empty when all went cleanly.
    pub fn warnings(&self) -> Vec<String> {
        let mut w = Vec::new();
        if let Some(asked) = self.n_inducing_requested
            && asked > self.n_support
        {
            // The greedy selection stops once every candidate's variance given the points
            // chosen is below 1e-10 of the signal variance (`greedy_variance_selection`): the
            // kernel matrix of the inputs has that numerical rank, whatever their number.
            w.push(format!(
                "{n} of the {asked} inducing points asked for are used: under the learned \
                 kernel every training input's variance given these {n} is below 1e-10 of the \
                 signal variance (the inputs span few of the kernel's length scales), so more \
                 points would change nothing; not a fault: {n} inducing points give the same \
                 fit, and inputs that vary more (wider or faster excitation) would use more",
                n = self.n_support
            ));
        }
        if self.jitter_evaluations > 0 {
            w.push(format!(
                "{} of {} likelihood evaluations needed Cholesky jitter (at most {:.0e} of \
                 the mean diagonal)",
                self.jitter_evaluations, self.evaluations, self.max_jitter
            ));
        }
        if self.final_jitter > 0.0 {
            w.push(format!(
                "the final factor needed jitter {:e}",
                self.final_jitter
            ));
        }
        if let Some(bound) = self.signal_variance_at_bound {
            w.push(format!(
                "the signal variance ended at its upper bound ({bound:.3e} times the targets' \
                 variance): the fit is close to a polynomial along a ridge of long length \
                 scales and may extrapolate badly (noise-free data do this; see docs/sparse.md)"
            ));
        }
        let failed = self.starts.iter().filter(|s| s.error.is_some()).count();
        if failed > 0 {
            w.push(format!(
                "{failed} of {} optimiser starts failed",
                self.starts.len()
            ));
        }
        w
    }
}

/// The prediction factor of a sparse GP (see [`hbn_core::Variance::Sparse`]).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct SparseFactors {
    /// `R` with `R^T R = K_mm^{-1} - Sigma`, row-packed lower triangle
    /// ([`crate::sparse::fold_sparse_variance`]). Files of format 3 and older do not have it;
    /// [`GaussianProcess::restore_factor`] folds it from their two factors on load.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub variance_factor: Vec<f64>,
    /// Files of format 3 and older: `L^{-1}` with `L L^T = K_mm`, row-packed lower triangle
    /// (read, folded into `variance_factor`, then dropped; never written).
    #[serde(default, skip_serializing)]
    pub kmm_inv_factor: Vec<f64>,
    /// Files of format 3 and older: `L_B^{-1} L^{-1}`, row-packed lower triangle (read,
    /// folded, dropped; never written).
    #[serde(default, skip_serializing)]
    pub sigma_factor: Vec<f64>,
}

/// A trained GP, exact or sparse (inducing points). Construct with [`crate::fit`]; predict
/// with [`GaussianProcess::view`] (allocation-free) or the convenience
/// [`GaussianProcess::predict`].
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct GaussianProcess {
    pub(crate) kernel: KernelSpec,
    pub(crate) theta: Vec<f64>,
    pub(crate) noise_variance: f64,
    pub(crate) whiten: Vec<f64>,
    pub(crate) input_mean: Vec<f64>,
    pub(crate) input_scale: Vec<f64>,
    pub(crate) output_mean: f64,
    pub(crate) output_scale: f64,
    /// Slopes of the linear prior mean in raw units ([`crate::MeanFunction::Linear`]); empty
    /// for a constant mean (and in files of format 4 and older).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub(crate) linear: Vec<f64>,
    pub(crate) support_x: Vec<f64>,
    pub(crate) support_y: Vec<f64>,
    pub(crate) directions: Vec<f64>,
    pub(crate) features: Vec<f64>,
    pub(crate) alpha: Vec<f64>,
    /// Exact GP only (empty for a sparse GP). Not written to files: it is `O(n^2)` (87% of
    /// a default model file) and a deterministic function of the other fields, recomputed by
    /// [`GaussianProcess::restore_factor`] on load, with the routine that made it in training.
    #[serde(default, skip_serializing)]
    pub(crate) chol_packed: Vec<f64>,
    /// Sparse GP only.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub(crate) sparse: Option<SparseFactors>,
    pub(crate) log_marginal_likelihood: f64,
    /// Mean squared leave-one-out prediction error (raw units).
    #[serde(default)]
    pub(crate) loo_error_variance: f64,
    pub(crate) report: TrainingReport,
}

#[derive(Serialize, Deserialize)]
struct GpFile {
    format: String,
    version: u32,
    gp: GaussianProcess,
}

impl GaussianProcess {
    /// The allocation-free predictor over this model's arrays.
    pub fn view(&self) -> Result<GpView<'_>, CoreError> {
        GpView::new(GpParts {
            kernel: Kernel::new(self.kernel, &self.theta, &self.whiten)?,
            input_mean: &self.input_mean,
            input_scale: &self.input_scale,
            output_mean: self.output_mean,
            output_scale: self.output_scale,
            linear: &self.linear,
            features: &self.features,
            directions: &self.directions,
            alpha: &self.alpha,
            alpha_lo: &[],
            variance: match &self.sparse {
                Some(f) => Variance::Sparse {
                    variance_factor: &f.variance_factor,
                },
                None => Variance::Exact {
                    chol_packed: &self.chol_packed,
                },
            },
            noise_var: self.noise_variance,
        })
    }

    /// Predicts at one raw input (allocates its scratch; use [`GaussianProcess::view`] in loops).
    pub fn predict(&self, x: &[f64], want: Want) -> Result<Prediction, GpError> {
        let view = self.view()?;
        let mut scratch = vec![0.0; view.predict_scratch(want)];
        Ok(view.predict(x, want, &mut scratch)?)
    }

    /// Predicts at many raw inputs (`rows x dim`, row-major) with one scratch buffer.
    pub fn predict_many(&self, x: &[f64], want: Want) -> Result<Vec<Prediction>, GpError> {
        let view = self.view()?;
        let d = view.dim();
        if !x.len().is_multiple_of(d) {
            return Err(GpError::Shape {
                what: "prediction inputs (rows x dim)",
                expected: d,
                got: x.len() % d,
            });
        }
        let mut scratch = vec![0.0; view.predict_scratch(want)];
        x.chunks_exact(d)
            .map(|row| Ok(view.predict(row, want, &mut scratch)?))
            .collect()
    }

    /// Kernel structure.
    pub fn kernel(&self) -> &KernelSpec {
        &self.kernel
    }
    /// Kernel hyperparameters (log-parameterised, standardised units).
    pub fn theta(&self) -> &[f64] {
        &self.theta
    }
    /// Noise variance in standardised output units (jitter excluded).
    pub fn noise_variance_std(&self) -> f64 {
        self.noise_variance
    }
    /// The kernel hyperparameters and noise variance, as a fit takes them to start from or
    /// to keep ([`crate::GpParams::init`]).
    pub fn hyperparameters(&self) -> crate::Hyperparameters {
        crate::Hyperparameters {
            theta: self.theta.clone(),
            noise_variance: self.noise_variance,
        }
    }
    /// Noise variance in raw output units.
    pub fn noise_variance(&self) -> f64 {
        self.noise_variance * self.output_scale * self.output_scale
    }
    /// Signal variance `s_f^2` in raw output units.
    pub fn signal_variance(&self) -> f64 {
        self.theta.first().map_or(0.0, |t| t.exp()) * self.output_scale * self.output_scale
    }
    /// Length scales in raw input units (ARD: one per input; isotropic: one; Mahalanobis: the
    /// scale `c` of the covariance). Empty for other metrics.
    pub fn length_scales(&self) -> Vec<f64> {
        match self.kernel.metric {
            hbn_core::Metric::Ard => (0..self.kernel.dim)
                .map(|j| self.theta[1 + j].exp() * self.input_scale[j])
                .collect(),
            hbn_core::Metric::Isotropic => vec![self.theta[1].exp()],
            hbn_core::Metric::Mahalanobis => vec![self.theta[1].exp()],
        }
    }
    /// Per-input mean and scale used for standardisation.
    pub fn input_standardisation(&self) -> (&[f64], &[f64]) {
        (&self.input_mean, &self.input_scale)
    }
    /// Output mean and scale used for standardisation. With a linear mean the scale is that
    /// of the residual the kernel models, not of the raw targets.
    pub fn output_standardisation(&self) -> (f64, f64) {
        (self.output_mean, self.output_scale)
    }
    /// Slopes of the linear prior mean in raw units, one per input (the prediction's mean is
    /// `output_mean + sum_j slope_j (x_j - input_mean_j) + GP`); empty for a constant mean.
    pub fn linear_mean(&self) -> &[f64] {
        &self.linear
    }
    /// Support inputs (exact GP) or inducing inputs (sparse GP), raw units, `n x dim`.
    pub fn support_inputs(&self) -> &[f64] {
        &self.support_x
    }
    /// Support targets (raw units; empty for a sparse GP, whose inducing points carry none).
    pub fn support_targets(&self) -> &[f64] {
        &self.support_y
    }
    /// Number of support points (exact) or inducing points (sparse).
    pub fn n_support(&self) -> usize {
        self.alpha.len()
    }
    /// True for a sparse (inducing-point) GP.
    pub fn is_sparse(&self) -> bool {
        self.sparse.is_some()
    }
    /// Log marginal likelihood of the standardised targets at the fitted hyperparameters
    /// (equal to the raw-target value when `normalize` is off). For a sparse GP, the collapsed
    /// variational bound (a lower bound of it).
    pub fn log_marginal_likelihood(&self) -> f64 {
        self.log_marginal_likelihood
    }
    /// The model's own estimate of its prediction error, in raw output units, used by the EKF
    /// as a floor of its noise variances. Exact GP: the mean squared leave-one-out error over
    /// the support points, `mean_i (alpha_i / [K_y^-1]_ii)^2`; unlike the noise hyperparameter
    /// it includes model mismatch (e.g. kinks the kernel cannot follow). Sparse GP: the same
    /// over every sample, exact for its mean, a linear smoother `y_hat = H y` with
    /// `H = K_nm Sigma K_mn / s_n^2`: `mean_j (r_j / (1 - H_jj))^2`.
    pub fn loo_error_variance(&self) -> f64 {
        self.loo_error_variance
    }
    /// What training did.
    pub fn report(&self) -> &TrainingReport {
        &self.report
    }

    /// Recomputes the exact GP's Cholesky factor after deserialisation (files leave it out);
    /// does nothing for a sparse GP or when the factor is present (files of format 1 and 2).
    /// Loaders call it; it gives the factor [`crate::fit`] made, bit for bit, because training
    /// ends by computing the factor with this same routine.
    pub fn restore_factor(&mut self) -> Result<(), GpError> {
        if let Some(f) = &mut self.sparse {
            if f.variance_factor.is_empty() {
                // A file of format 3 or older: fold its two factors, A = L^{-1} and
                // C = L_B^{-1} A, into one (L_B^{-1} = C A^{-1}).
                let m = self.alpha.len();
                let tri = m * (m + 1) / 2;
                for (what, v) in [
                    ("kmm_inv_factor", &f.kmm_inv_factor),
                    ("sigma_factor", &f.sigma_factor),
                ] {
                    if v.len() != tri {
                        return Err(GpError::Shape {
                            what,
                            expected: tri,
                            got: v.len(),
                        });
                    }
                }
                let a = crate::sparse::unpack_lower(&f.kmm_inv_factor, m);
                let c = crate::sparse::unpack_lower(&f.sigma_factor, m);
                let l = crate::sparse::lower_inverse(a.as_ref());
                let g = &c * &l;
                let g = faer::Mat::from_fn(m, m, |i, j| if j <= i { g[(i, j)] } else { 0.0 });
                let (r, _jitter) = crate::sparse::fold_sparse_variance(a.as_ref(), g.as_ref(), 8)?;
                f.variance_factor = r;
                f.kmm_inv_factor = Vec::new();
                f.sigma_factor = Vec::new();
            }
            return Ok(());
        }
        if !self.chol_packed.is_empty() {
            return Ok(());
        }
        self.chol_packed = self.exact_factor()?;
        Ok(())
    }

    /// Packed lower Cholesky factor of `K + s_n^2 I` over the support points, from the stored
    /// kernel features, directions, hyperparameters and noise (which includes any jitter
    /// training needed). Fails rather than adding jitter: training checked that it succeeds.
    pub(crate) fn exact_factor(&self) -> Result<Vec<f64>, GpError> {
        let d = self.kernel.dim;
        let n = self.alpha.len();
        if n > crate::MAX_EXACT_POINTS {
            return Err(GpError::InvalidParameter {
                name: "max_points",
                reason: format!(
                    "an exact GP has at most {} support points, this one {n}",
                    crate::MAX_EXACT_POINTS
                ),
            });
        }
        let kernel = Kernel::new(self.kernel, &self.theta, &self.whiten)?;
        let has_dirs = self.kernel.direction.is_some();
        if self.features.len() != n * d || (has_dirs && self.directions.len() != n) {
            return Err(GpError::Shape {
                what: "support-point features (n x dim)",
                expected: n * d,
                got: self.features.len(),
            });
        }
        let sf2 = kernel.signal_variance();
        let spec = self.kernel;
        let dir = |i: usize| if has_dirs { self.directions[i] } else { 0.0 };
        let u = &self.features;
        let mut k = faer::Mat::from_fn(n, n, |i, j| {
            if j > i {
                return 0.0;
            }
            let r2: f64 = u[i * d..i * d + d]
                .iter()
                .zip(&u[j * d..j * d + d])
                .map(|(a, b)| (a - b) * (a - b))
                .sum();
            let (f, _) = hbn_core::kernel::profile_and_slope(spec.profile, r2);
            let k_ij = sf2 * f * spec.direction_factor(dir(i), dir(j));
            if i == j {
                k_ij + self.noise_variance
            } else {
                k_ij
            }
        });
        let factor = crate::factor::factor_with_jitter(&mut k, 0)?;
        let l = factor.llt.L();
        let mut packed = Vec::with_capacity(n * (n + 1) / 2);
        for i in 0..n {
            for j in 0..=i {
                packed.push(l[(i, j)]);
            }
        }
        Ok(packed)
    }

    /// Serialises to JSON (exact float round trip) with a format tag and version.
    pub fn to_json(&self) -> Result<String, GpError> {
        let file = GpFile {
            format: GP_FORMAT.into(),
            version: GP_FORMAT_VERSION,
            gp: self.clone(),
        };
        serde_json::to_string(&file).map_err(|e| GpError::Format {
            path: "<memory>".into(),
            reason: e.to_string(),
        })
    }

    /// Parses JSON written by [`GaussianProcess::to_json`], checking format, version and
    /// every array length. `origin` names the source in errors.
    pub fn from_json(text: &str, origin: &str) -> Result<Self, GpError> {
        let value: serde_json::Value = serde_json::from_str(text).map_err(|e| GpError::Format {
            path: origin.into(),
            reason: format!("not a JSON GP model file: {e}"),
        })?;
        let format = value.get("format").and_then(|f| f.as_str()).unwrap_or("");
        if format != GP_FORMAT {
            return Err(GpError::Format {
                path: origin.into(),
                reason: format!("not an hbn GP model (format tag {format:?})"),
            });
        }
        let version = value.get("version").and_then(|v| v.as_u64()).unwrap_or(0);
        if !(u64::from(GP_FORMAT_OLDEST)..=u64::from(GP_FORMAT_VERSION)).contains(&version) {
            return Err(GpError::Format {
                path: origin.into(),
                reason: format!(
                    "GP format version {version} is not supported (this build reads {GP_FORMAT_OLDEST} to {GP_FORMAT_VERSION}); retrain or convert"
                ),
            });
        }
        let mut file: GpFile = serde_json::from_value(value).map_err(|e| GpError::Format {
            path: origin.into(),
            reason: format!("malformed GP model: {e}"),
        })?;
        file.gp.restore_factor().map_err(|e| GpError::Format {
            path: origin.into(),
            reason: format!("inconsistent GP model: {e}"),
        })?;
        file.gp.view().map_err(|e| GpError::Format {
            path: origin.into(),
            reason: format!("inconsistent GP model: {e}"),
        })?;
        Ok(file.gp)
    }

    /// Writes the model atomically (temporary file in the same directory, then rename).
    pub fn save(&self, path: &Path) -> Result<(), GpError> {
        let text = self.to_json()?;
        crate::write_atomic(path, text.as_bytes())
    }

    /// Loads a model written by [`GaussianProcess::save`].
    pub fn load(path: &Path) -> Result<Self, GpError> {
        let text = std::fs::read_to_string(path).map_err(|source| GpError::Io {
            path: path.display().to_string(),
            source,
        })?;
        Self::from_json(&text, &path.display().to_string())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::{GpParams, fit};

    /// What "fewer inducing points than asked" counts: not distinct inputs (all 2000 differ
    /// here) but the numerical rank of the learned kernel's matrix over them. A smooth relation
    /// on inputs that span a fraction of one length scale is determined by a few points; the
    /// warning says so, and that asking for that many gives the same fit.
    #[test]
    fn fewer_inducing_points_counts_the_kernel_rank() {
        let x: Vec<f64> = (0..2000).map(|i| i as f64 / 2000.0).collect();
        let y: Vec<f64> = x.iter().map(|v| 0.3 * v + 0.1 * v * v).collect();
        let mut params = GpParams::new(KernelSpec::se_ard(1));
        params.n_starts = 1;
        params.max_iters = 30;
        params.sparse = Some(crate::SparseParams::new(32));
        let gp = fit(&params, &x, &y).unwrap();
        let used = gp.n_support();
        assert!(used < 32, "{used}");
        let w = gp.report().warnings();
        let msg = w
            .iter()
            .find(|w| w.contains("inducing points asked for"))
            .unwrap();
        assert!(
            msg.starts_with(&format!("{used} of the 32 inducing points asked for")),
            "{msg}"
        );
        assert!(msg.contains("below 1e-10 of the signal variance"), "{msg}");
        assert!(msg.contains("give the same fit"), "{msg}");
        assert!(!msg.contains("distinct"), "{msg}");
        // The same number asked for: the same fit, and no warning.
        params.sparse = Some(crate::SparseParams::new(used));
        let again = fit(&params, &x, &y).unwrap();
        assert_eq!(again.n_support(), used);
        assert!(
            !again
                .report()
                .warnings()
                .iter()
                .any(|w| w.contains("asked for")),
            "{:?}",
            again.report().warnings()
        );
    }

    fn trained() -> GaussianProcess {
        let x: Vec<f64> = (0..120).map(|i| (i as f64 * 0.731).sin() * 2.0).collect();
        let y: Vec<f64> = x
            .chunks_exact(2)
            .map(|r| (1.3 * r[0]).sin() + 0.5 * r[1])
            .collect();
        let mut params = GpParams::new(KernelSpec::se_ard(2));
        params.n_starts = 1;
        params.max_iters = 20;
        fit(&params, &x, &y).unwrap()
    }

    #[test]
    fn files_leave_the_factor_out_and_loading_recomputes_it_bit_for_bit() {
        let gp = trained();
        assert_eq!(gp.chol_packed.len(), 60 * 61 / 2);
        let text = gp.to_json().unwrap();
        let value: serde_json::Value = serde_json::from_str(&text).unwrap();
        assert!(value["gp"].get("chol_packed").is_none(), "factor written");
        let back = GaussianProcess::from_json(&text, "mem").unwrap();
        let same_bits = |a: &[f64], b: &[f64]| {
            a.len() == b.len() && a.iter().zip(b).all(|(p, q)| p.to_bits() == q.to_bits())
        };
        assert!(same_bits(&gp.chol_packed, &back.chol_packed));
        // The factor is right: L L^T = K + s_n^2 I at a diagonal entry (k(x, x) = sf2).
        let l00 = back.chol_packed[0];
        let sf2 = Kernel::new(gp.kernel, &gp.theta, &gp.whiten)
            .unwrap()
            .signal_variance();
        assert!((l00 * l00 - (sf2 + gp.noise_variance)).abs() < 1e-12);
    }

    #[test]
    fn files_of_format_2_with_the_factor_load_as_written() {
        let gp = trained();
        let mut value: serde_json::Value = serde_json::from_str(&gp.to_json().unwrap()).unwrap();
        value["version"] = 2.into();
        // A factor that differs from the recomputed one in the last bit: it must be used as is.
        let mut old = gp.chol_packed.clone();
        old[0] = f64::from_bits(old[0].to_bits() + 1);
        value["gp"]["chol_packed"] = serde_json::to_value(&old).unwrap();
        let back = GaussianProcess::from_json(&value.to_string(), "mem").unwrap();
        assert_eq!(back.chol_packed, old);
    }

    #[test]
    fn a_file_whose_factor_cannot_be_recomputed_is_an_error() {
        let gp = trained();
        let mut value: serde_json::Value = serde_json::from_str(&gp.to_json().unwrap()).unwrap();
        // A negative noise larger than the signal variance: K + s_n^2 I is not positive definite.
        value["gp"]["noise_variance"] = (-1e3).into();
        let e = GaussianProcess::from_json(&value.to_string(), "m.json").unwrap_err();
        assert!(matches!(e, GpError::Format { .. }), "{e}");
        // Features of the wrong length: a shape error, not a panic.
        let mut value: serde_json::Value = serde_json::from_str(&gp.to_json().unwrap()).unwrap();
        value["gp"]["features"] = serde_json::to_value(vec![0.0; 3]).unwrap();
        assert!(GaussianProcess::from_json(&value.to_string(), "m.json").is_err());
    }
}
