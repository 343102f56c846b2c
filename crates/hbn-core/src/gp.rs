//! Allocation-free GP prediction from borrowed slices.
//!
//! A trained GP is, for prediction, a handful of arrays (see [`GpView`]): the support points
//! already mapped to kernel *features* (`u = L phi(x_std)`, see [`crate::kernel`]), the
//! weights `alpha = (K + s_n^2 I)^{-1} y`, and the lower Cholesky factor of `K + s_n^2 I`
//! packed row by row. Prediction at one point costs `n` kernel evaluations for the mean and
//! its gradient, plus one packed forward substitution (`n^2 / 2` multiply-adds) for the
//! variance and, if asked, one back substitution for the variance gradient.
//!
//! Scratch memory is passed in by the caller, sized by [`GpView::predict_scratch`], so the
//! same code runs in firmware from a `static` buffer.
//!
//! **Sparse GPs** (Titsias 2009, "SGPR"/"VFE") use the same view with a different
//! [`Variance`]: `features` holds the `m` inducing points, `alpha = Sigma K_mn y / s_n^2` with
//! `Sigma = (K_mm + K_mn K_nm / s_n^2)^{-1}`, and the latent variance is
//! `k(x,x) - k^T (K_mm^{-1} - Sigma) k`. Training folds the two terms into one lower-triangular
//! factor `R` with `R^T R = K_mm^{-1} - Sigma` (positive semi-definite), so the variance is
//! `k(x,x) - |R k|^2`: one packed matrix-vector product (`m^2 / 2` independent multiply-adds,
//! no dependency chain) instead of two triangular solves, and no difference of two large
//! quadratic forms (`hbn_gp`'s `fold_sparse_variance` says how `R` is formed without one).

use crate::CoreError;
use crate::kernel::{
    FEATURE_JACOBIAN_LEN, Kernel, MAX_DENSE_DIM, MAX_DIM, Profile, at, feature_jacobian_entry,
    profiles, profiles_and_slopes,
};

/// Which outputs of [`GpView::predict`] to compute. The mean is always computed.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Want {
    /// Predictive variance of the latent function (noise excluded).
    pub variance: bool,
    /// Gradient of the mean with respect to the raw input.
    pub grad_mean: bool,
    /// Gradient of the variance with respect to the raw input (implies `variance`).
    pub grad_variance: bool,
}

impl Want {
    /// The mean only.
    pub const MEAN: Want = Want {
        variance: false,
        grad_mean: false,
        grad_variance: false,
    };
    /// Mean and variance.
    pub const VARIANCE: Want = Want {
        variance: true,
        grad_mean: false,
        grad_variance: false,
    };
    /// Mean, variance and mean gradient: what the EKF step needs.
    pub const EKF: Want = Want {
        variance: true,
        grad_mean: true,
        grad_variance: false,
    };
    /// Everything.
    pub const ALL: Want = Want {
        variance: true,
        grad_mean: true,
        grad_variance: true,
    };
}

/// GP prediction at one point, in the raw (unstandardised) units of the data.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Prediction {
    /// Predictive mean.
    pub mean: f64,
    /// Predictive variance of the latent function, `>= 0` (0 if not requested).
    pub variance: f64,
    /// The GP's prior variance `k(x, x)` at this input, in the same units as `variance` (0 if
    /// the variance was not requested): `variance / prior_variance` near 1 means the data say
    /// nothing here (extrapolation).
    pub prior_variance: f64,
    /// `d mean / d x` (first `dim` entries; zero if not requested).
    pub grad_mean: [f64; MAX_DIM],
    /// `d variance / d x` (first `dim` entries; zero if not requested).
    pub grad_variance: [f64; MAX_DIM],
}

/// A trained GP as borrowed slices: what a firmware can keep in a `static`.
///
/// All matrices are row-major. `n` support points, `d` inputs.
#[derive(Clone, Copy, Debug)]
pub struct GpView<'a> {
    kernel: Kernel<'a>,
    input_mean: &'a [f64],
    input_scale: &'a [f64],
    output_mean: f64,
    output_scale: f64,
    linear: &'a [f64],
    features: &'a [f64],
    directions: &'a [f64],
    alpha: &'a [f64],
    alpha_lo: &'a [f64],
    variance: Variance<'a>,
    noise_var: f64,
    mean_input: Option<usize>,
}

/// How a [`GpView`] computes the latent variance: the exact GP's Cholesky factor, or the
/// folded variance factor of a sparse (inducing-point) GP. All matrices are lower-triangular and packed by
/// rows: row `i` holds `i + 1` values starting at `i (i + 1) / 2`.
#[derive(Clone, Copy, Debug)]
pub enum Variance<'a> {
    /// Exact GP: `L` with `L L^T = K + s_n^2 I` (`n (n + 1) / 2` values);
    /// `var = k(x,x) - |L^{-1} k|^2` by forward substitution.
    Exact {
        /// The packed Cholesky factor.
        chol_packed: &'a [f64],
    },
    /// Sparse GP on `m` inducing points: `var = k(x,x) - |R k|^2`.
    Sparse {
        /// `R`, lower-triangular with `R^T R = K_mm^{-1} - Sigma`, where
        /// `Sigma = (K_mm + K_mn K_nm / s_n^2)^{-1}` (`m (m + 1) / 2` values).
        variance_factor: &'a [f64],
    },
}

impl Variance<'_> {
    /// True for the sparse (inducing-point) form.
    pub fn is_sparse(&self) -> bool {
        matches!(self, Variance::Sparse { .. })
    }
}

/// The slices and scalars a [`GpView`] is built from.
#[derive(Clone, Copy, Debug)]
pub struct GpParts<'a> {
    /// The kernel with its hyperparameters (in standardised units).
    pub kernel: Kernel<'a>,
    /// Per-input mean subtracted before the kernel (`d`).
    pub input_mean: &'a [f64],
    /// Per-input scale divided out before the kernel (`d`, all `> 0`).
    pub input_scale: &'a [f64],
    /// Output mean added to the GP mean.
    pub output_mean: f64,
    /// Output scale (`> 0`) multiplying the standardised GP output.
    pub output_scale: f64,
    /// Slopes of a linear prior mean in raw units, empty or `d` values: the mean becomes
    /// `output_mean + sum_j linear_j (x_j - input_mean_j) + output_scale * GP(z)` and its
    /// gradient gains `linear` (variances are unchanged). Empty for a GP with a constant mean.
    pub linear: &'a [f64],
    /// Support points in feature space, `n x d`.
    pub features: &'a [f64],
    /// Direction signs of the support points (`n`), or empty without the direction factor.
    pub directions: &'a [f64],
    /// Mean weights: `alpha = (K + s_n^2 I)^{-1} y_std` (`n`) for the exact GP, or
    /// `Sigma K_mn y_std / s_n^2` for a sparse GP (one per inducing point).
    pub alpha: &'a [f64],
    /// Low parts of the mean weights, empty or one per support point: the weights are
    /// `alpha + alpha_lo`. Models leave it empty; model tables ([`crate::tables`]) split each
    /// weight into an `f32`-representable high part and the rest, so that an `f32` export keeps
    /// the weights to about 48 bits (the mean `k^T alpha` cancels: rounding `alpha` alone to
    /// `f32` moves a sparse model's estimate by 5% of the range of `x`).
    pub alpha_lo: &'a [f64],
    /// The variance factors (exact or sparse).
    pub variance: Variance<'a>,
    /// Learned noise variance `s_n^2` in standardised output units.
    pub noise_var: f64,
}

impl<'a> GpView<'a> {
    /// Checks every length and value once; prediction then needs no checks on the model.
    pub fn new(parts: GpParts<'a>) -> Result<Self, CoreError> {
        let spec = *parts.kernel.spec();
        let d = spec.dim;
        let n = parts.alpha.len();
        if n == 0 {
            return Err(CoreError::Empty);
        }
        let expect = |got: usize, expected: usize| {
            if got == expected {
                Ok(())
            } else {
                Err(CoreError::DimensionMismatch { expected, got })
            }
        };
        expect(parts.input_mean.len(), d)?;
        expect(parts.input_scale.len(), d)?;
        expect(parts.features.len(), n * d)?;
        if !parts.linear.is_empty() {
            expect(parts.linear.len(), d)?;
        }
        if !parts.alpha_lo.is_empty() {
            expect(parts.alpha_lo.len(), n)?;
        }
        let tri = n * (n + 1) / 2;
        let factor = match parts.variance {
            Variance::Exact { chol_packed } => chol_packed,
            Variance::Sparse { variance_factor } => variance_factor,
        };
        expect(factor.len(), tri)?;
        if spec.direction.is_some() {
            expect(parts.directions.len(), n)?;
        }
        let finite = |s: &[f64]| s.iter().all(|v| v.is_finite());
        if !(finite(parts.input_mean)
            && finite(parts.linear)
            && finite(parts.features)
            && finite(parts.directions)
            && finite(parts.alpha)
            && finite(parts.alpha_lo)
            && finite(factor)
            && parts.output_mean.is_finite()
            && parts.noise_var.is_finite())
        {
            return Err(CoreError::NonFinite);
        }
        let positive = |v: f64| v.is_finite() && v > 0.0;
        if !parts.input_scale.iter().all(|&s| positive(s)) || !positive(parts.output_scale) {
            return Err(CoreError::InvalidSpec(
                "input and output scales must be finite and > 0",
            ));
        }
        // The factor is triangular with a positive diagonal (a Cholesky factor, or the product
        // of two such inverses).
        for i in 0..n {
            if factor
                .get(i * (i + 1) / 2 + i)
                .and_then(|v| v.partial_cmp(&0.0))
                != Some(core::cmp::Ordering::Greater)
            {
                return Err(CoreError::InvalidSpec(
                    "triangular factor diagonal must be > 0",
                ));
            }
        }
        Ok(Self {
            kernel: parts.kernel,
            input_mean: parts.input_mean,
            input_scale: parts.input_scale,
            output_mean: parts.output_mean,
            output_scale: parts.output_scale,
            linear: parts.linear,
            features: parts.features,
            directions: parts.directions,
            alpha: parts.alpha,
            alpha_lo: parts.alpha_lo,
            variance: parts.variance,
            noise_var: parts.noise_var,
            mean_input: None,
        })
    }

    /// The slices and scalars this view was built from (what [`GpView::new`] checked): for
    /// exporting a model as constant tables.
    pub fn parts(&self) -> GpParts<'a> {
        GpParts {
            kernel: self.kernel,
            input_mean: self.input_mean,
            input_scale: self.input_scale,
            output_mean: self.output_mean,
            output_scale: self.output_scale,
            linear: self.linear,
            features: self.features,
            directions: self.directions,
            alpha: self.alpha,
            alpha_lo: self.alpha_lo,
            variance: self.variance,
            noise_var: self.noise_var,
        }
    }

    /// The same GP with the raw input `j` as its prior mean: predictions become
    /// `x[j] + GP(x)` (mean gradient `+1` in `j`; variances unchanged). For a GP fitted to the
    /// increments `t - x[j]` of its targets, e.g. `x_k - x_{k-1}`.
    pub fn with_mean_input(self, j: usize) -> Result<Self, CoreError> {
        if j >= self.dim() {
            return Err(CoreError::DimensionMismatch {
                expected: self.dim(),
                got: j,
            });
        }
        Ok(Self {
            mean_input: Some(j),
            ..self
        })
    }

    /// The input added to the mean ([`GpView::with_mean_input`]), if any.
    pub fn mean_input(&self) -> Option<usize> {
        self.mean_input
    }

    /// Number of support points (exact) or inducing points (sparse).
    pub fn len(&self) -> usize {
        self.alpha.len()
    }

    /// Always false: a view has at least one support point.
    pub fn is_empty(&self) -> bool {
        self.alpha.is_empty()
    }

    /// Number of inputs.
    pub fn dim(&self) -> usize {
        self.kernel.spec().dim
    }

    /// True for a sparse (inducing-point) GP.
    pub fn is_sparse(&self) -> bool {
        self.variance.is_sparse()
    }

    /// The kernel.
    pub fn kernel(&self) -> &Kernel<'a> {
        &self.kernel
    }

    /// The learned noise variance in raw output units.
    pub fn noise_variance(&self) -> f64 {
        self.noise_var * self.output_scale * self.output_scale
    }

    /// Variance of the training targets the GP was fitted to (its output scale squared):
    /// the spread of the signal it predicts.
    pub fn output_variance(&self) -> f64 {
        self.output_scale * self.output_scale
    }

    /// The standardised input `(x - mean) / scale` (the first `dim` values; the rest zero).
    fn standardise(&self, x_raw: &[f64]) -> [f64; MAX_DIM] {
        let mut z = [0.0; MAX_DIM];
        let std_in = x_raw.iter().zip(self.input_mean).zip(self.input_scale);
        for (zj, ((x, m), s)) in z.iter_mut().zip(std_in).take(self.dim()) {
            *zj = (x - m) / s;
        }
        z
    }

    /// Number of `f64` scratch values [`GpView::whiten`] needs.
    pub fn whiten_scratch(&self) -> usize {
        self.predict_scratch(Want::VARIANCE)
    }

    /// The whitened cross-covariance of the raw input `x_raw` with the support (inducing)
    /// points, `len()` values into `w`: `w = L^{-1} k` (exact GP) or `w = R k` (sparse GP),
    /// in standardised output units. With two such vectors,
    /// [`GpView::posterior_covariance`] gives the latent posterior covariance of two inputs
    /// without a solve. Returns the latent variance at `x_raw` (as [`GpView::predict`]).
    /// Allocation-free and panic-free; `O(n d + n^2)`. `scratch` must hold
    /// [`GpView::whiten_scratch`] values.
    pub fn whiten(
        &self,
        x_raw: &[f64],
        w: &mut [f64],
        scratch: &mut [f64],
    ) -> Result<f64, CoreError> {
        let n = self.len();
        if w.len() != n {
            return Err(CoreError::DimensionMismatch {
                expected: n,
                got: w.len(),
            });
        }
        let pred = self.predict(x_raw, Want::VARIANCE, scratch)?;
        // With `Want::VARIANCE` the scratch holds `k` (n values), then the whitened vector
        // (n values): see `predict` and `predict_scratch`.
        let whitened = scratch.get(n..2 * n).ok_or(CoreError::ScratchTooSmall {
            needed: 2 * n,
            got: scratch.len(),
        })?;
        // Equal lengths (checked above); a zip keeps a panic path out.
        for (o, v) in w.iter_mut().zip(whitened) {
            *o = *v;
        }
        Ok(pred.variance)
    }

    /// Latent posterior covariance (raw output units) of the GP at two raw inputs `a_raw`
    /// and `b_raw`, from their whitened vectors `w_a`, `w_b` ([`GpView::whiten`]):
    /// `s^2 (k(a, b) - w_a . w_b)`, `s^2` the [`GpView::output_variance`]. At `a = b` it is
    /// the latent variance ([`GpView::predict`] clamps that at zero against rounding; this
    /// does not). Allocation-free and panic-free (the link-time check covers it).
    pub fn posterior_covariance(
        &self,
        a_raw: &[f64],
        w_a: &[f64],
        b_raw: &[f64],
        w_b: &[f64],
    ) -> Result<f64, CoreError> {
        let d = self.dim();
        let n = self.len();
        for (x, w) in [(a_raw, w_a), (b_raw, w_b)] {
            if x.len() != d {
                return Err(CoreError::DimensionMismatch {
                    expected: d,
                    got: x.len(),
                });
            }
            if w.len() != n {
                return Err(CoreError::DimensionMismatch {
                    expected: n,
                    got: w.len(),
                });
            }
        }
        let (z_a, z_b) = (self.standardise(a_raw), self.standardise(b_raw));
        let spec = self.kernel.spec();
        let k_ab = self.kernel.eval(
            z_a.get(..d).unwrap_or(&z_a),
            spec.direction_of(a_raw),
            z_b.get(..d).unwrap_or(&z_b),
            spec.direction_of(b_raw),
        );
        let cov = self.output_variance() * (k_ab - dot(w_a, w_b));
        if cov.is_finite() {
            Ok(cov)
        } else {
            Err(CoreError::NonFinite)
        }
    }

    /// Number of `f64` scratch values [`GpView::predict`] needs for `want`.
    pub fn predict_scratch(&self, want: Want) -> usize {
        predict_scratch(self.len(), self.is_sparse(), want)
    }

    /// Predicts at one raw input `x_raw` (`dim` values).
    ///
    /// Allocation-free and panic-free; time is `O(n d)` for the mean and its gradient plus
    /// `O(n^2)` for the variance (`n` inducing points for a sparse GP).
    /// `scratch` must hold [`GpView::predict_scratch`] values.
    pub fn predict(
        &self,
        x_raw: &[f64],
        want: Want,
        scratch: &mut [f64],
    ) -> Result<Prediction, CoreError> {
        crate::simd::vectorised(
            #[inline(always)]
            || self.predict_inline(x_raw, want, scratch),
        )
    }

    /// The predictive mean alone at the raw input `x_raw`: [`GpView::predict`] with
    /// [`Want::default`], the same bits, without building the gradients' arrays of a
    /// [`Prediction`] (the unscented mode asks this for every sigma point).
    pub fn predict_mean(&self, x_raw: &[f64], scratch: &mut [f64]) -> Result<f64, CoreError> {
        crate::simd::vectorised(
            #[inline(always)]
            || {
                self.predict_inline(x_raw, Want::default(), scratch)
                    .map(|p| p.mean)
            },
        )
    }

    /// The EKF's prediction for the vector filter: [`GpView::predict`] with [`Want::EKF`], the
    /// same bits, but the mean gradient only with respect to the first `grad_cols` inputs,
    /// written into `grad_mean` (entries from `grad_cols` on are unspecified), and no
    /// [`Prediction`] to copy. A transition of a vector model reads 12 inputs, of which the
    /// filter differentiates 4 (the state's). Kernels whose feature Jacobian is not diagonal
    /// (warped or Mahalanobis) differentiate every input.
    pub(crate) fn predict_ekf_into(
        &self,
        x_raw: &[f64],
        grad_cols: usize,
        scratch: &mut [f64],
        grad_mean: &mut [f64; MAX_DIM],
    ) -> Result<Moments, CoreError> {
        crate::simd::vectorised(
            #[inline(always)]
            || {
                let mut unused = [0.0; MAX_DIM];
                self.predict_parts(
                    x_raw,
                    Want::EKF,
                    Pass::Rows { grad_cols },
                    scratch,
                    grad_mean,
                    &mut unused,
                )
            },
        )
    }

    /// [`GpView::predict`], inlined where it is called ([`crate::simd::vectorised`]).
    #[inline(always)]
    fn predict_inline(
        &self,
        x_raw: &[f64],
        want: Want,
        scratch: &mut [f64],
    ) -> Result<Prediction, CoreError> {
        let mut grad_mean = [0.0; MAX_DIM];
        let mut grad_variance = [0.0; MAX_DIM];
        let m = self.predict_parts(
            x_raw,
            want,
            Pass::ByDim,
            scratch,
            &mut grad_mean,
            &mut grad_variance,
        )?;
        Ok(Prediction {
            mean: m.mean,
            variance: m.variance,
            prior_variance: m.prior_variance,
            grad_mean,
            grad_variance,
        })
    }

    /// The prediction's work: the moments returned, the gradients written into `grad_mean`
    /// and `grad_variance` where `want` asks for them (their first `dim` entries; the arrays
    /// must hold zeros).
    #[inline(always)]
    fn predict_parts(
        &self,
        x_raw: &[f64],
        want: Want,
        pass: Pass,
        scratch: &mut [f64],
        grad_mean: &mut [f64; MAX_DIM],
        grad_variance: &mut [f64; MAX_DIM],
    ) -> Result<Moments, CoreError> {
        let d = self.dim();
        let n = self.len();
        if x_raw.len() != d {
            return Err(CoreError::DimensionMismatch {
                expected: d,
                got: x_raw.len(),
            });
        }
        if !x_raw.iter().all(|v| v.is_finite()) {
            return Err(CoreError::NonFinite);
        }
        let sparse = self.is_sparse();
        let needed = predict_scratch(n, sparse, want);
        if scratch.len() < needed {
            return Err(CoreError::ScratchTooSmall {
                needed,
                got: scratch.len(),
            });
        }
        let want_var = want.variance || want.grad_variance;

        let z = self.standardise(x_raw);
        let spec = *self.kernel.spec();
        let g_star = spec.direction_of(x_raw);
        let mut u_star = [0.0; MAX_DIM];
        let mut du_dz = [0.0; FEATURE_JACOBIAN_LEN];
        self.kernel
            .features(z.get(..d).unwrap_or(&z), &mut u_star, &mut du_dz);

        // The scratch length was checked against `predict_scratch` above, so every split
        // succeeds; the checked forms keep a panic path out of the step.
        let too_small = CoreError::ScratchTooSmall {
            needed,
            got: scratch.len(),
        };
        let (kvec, rest) = scratch.split_at_mut_checked(n).ok_or(too_small)?;
        let (cvec, rest) = rest
            .split_at_mut_checked(if want.grad_variance { n } else { 0 })
            .ok_or(too_small)?;
        let (vvec, rest) = rest
            .split_at_mut_checked(if want_var { n } else { 0 })
            .ok_or(too_small)?;
        // Sparse only: the variance gradient's weights `R^T R k`.
        let qvec = rest
            .get_mut(..if want.grad_variance && sparse { n } else { 0 })
            .ok_or(too_small)?;

        let acc = Accum {
            features: self.features,
            directions: self.directions,
            alpha: self.alpha,
            alpha_lo: self.alpha_lo,
            u_star: &u_star,
            g_star,
            sf2: self.kernel.signal_variance(),
            profile: spec.profile,
            direction: spec.direction.is_some(),
        };
        let mut grad_u = [0.0; MAX_DIM];
        let cslot = if want.grad_variance {
            Some(&mut *cvec)
        } else {
            None
        };
        // Without a gradient (the unscented mode's sigma points, a mean or variance alone) the
        // pass skips the profile's slope and the gradient sums.
        let grad = want.grad_mean || want.grad_variance;
        // The inputs whose mean gradient the pass computes (every one, but where the caller
        // asks for fewer and the feature Jacobian is diagonal).
        let grad_cols = match pass {
            Pass::Rows { grad_cols } if !want.grad_variance && diagonal_features(&spec) => {
                grad_cols.min(d)
            }
            _ => d,
        };
        let mean_std = match (pass, grad) {
            (Pass::ByDim, true) => acc.run_dim::<true>(d, kvec, cslot, &mut grad_u),
            (Pass::ByDim, false) => acc.run_dim::<false>(d, kvec, cslot, &mut grad_u),
            (Pass::Rows { .. }, true) => {
                acc.run_rows::<true>(d, grad_cols, kvec, cslot, &mut grad_u)
            }
            (Pass::Rows { .. }, false) => acc.run_rows::<false>(d, d, kvec, cslot, &mut grad_u),
        };

        let mut out = Moments {
            mean: self.output_mean + self.output_scale * mean_std,
            variance: 0.0,
            prior_variance: 0.0,
        };
        if want.grad_mean {
            if matches!(pass, Pass::Rows { .. }) && diagonal_features(&spec) {
                // A diagonal Jacobian: each input's own term alone (what the sum over the
                // features adds up to, with zeros).
                let cols = grad_mean.iter_mut().zip(self.input_scale).zip(&grad_u);
                for (j, ((o, s), g)) in cols.enumerate().take(grad_cols) {
                    let jac = feature_jacobian_entry(&du_dz, d, j, j);
                    *o = self.output_scale * (g * jac) / s;
                }
            } else {
                chain_to_raw(
                    &grad_u,
                    &du_dz,
                    d,
                    grad_cols,
                    self.output_scale,
                    self.input_scale,
                    grad_mean,
                );
            }
        }
        // `new` checked that `linear` is empty or has `d` slopes.
        let centred = x_raw.iter().zip(self.input_mean);
        for ((w, (x, m)), g) in self.linear.iter().zip(centred).zip(grad_mean.iter_mut()) {
            out.mean += w * (x - m);
            if want.grad_mean {
                *g += w;
            }
        }
        if let Some(j) = self.mean_input {
            // `with_mean_input` checked `j < dim`, so both exist.
            out.mean += x_raw.get(j).copied().unwrap_or(0.0);
            if want.grad_mean
                && let Some(g) = grad_mean.get_mut(j)
            {
                *g += 1.0;
            }
        }
        if want_var {
            let kss = acc.sf2 * spec.direction_factor(g_star, g_star);
            let s2 = self.output_scale * self.output_scale;
            // `weights` ends up as d var / d k / (-2): K^{-1} k (exact) or R^T R k (sparse).
            let (var_std, weights) = match self.variance {
                Variance::Exact { chol_packed } => {
                    forward_substitute_inline(chol_packed, kvec, vvec)?;
                    let var = kss - dot(vvec, vvec);
                    if want.grad_variance {
                        back_substitute_inline(chol_packed, vvec)?;
                    }
                    (var, &*vvec)
                }
                Variance::Sparse { variance_factor }
                    if matches!(pass, Pass::Rows { .. }) && !want.grad_variance =>
                {
                    (kss - lower_packed_norm2(variance_factor, kvec), &*qvec)
                }
                Variance::Sparse { variance_factor } => {
                    lower_packed_times(variance_factor, kvec, vvec);
                    let var = kss - dot(vvec, vvec);
                    if want.grad_variance {
                        lower_packed_transpose_times_inline(variance_factor, vvec, qvec);
                    }
                    (var, &*qvec)
                }
            };
            out.variance = s2 * var_std.max(0.0);
            out.prior_variance = s2 * kss;
            if want.grad_variance {
                // dvar/du* = -2 sum_i w_i dk_i/du* = 4 sum_i w_i c_i (u_i - u*).
                let mut gv_u = [0.0; MAX_DIM];
                let rows = self.features.chunks_exact(d.max(1));
                for ((w, c), row) in weights.iter().zip(cvec.iter()).zip(rows) {
                    let wc = 4.0 * w * c;
                    for ((g, r), u) in gv_u.iter_mut().zip(row).zip(&u_star).take(d) {
                        *g += wc * (r - u);
                    }
                }
                chain_to_raw(&gv_u, &du_dz, d, d, s2, self.input_scale, grad_variance);
            }
        }
        if !(out.mean.is_finite() && out.variance.is_finite()) {
            return Err(CoreError::NonFinite);
        }
        Ok(out)
    }
}

/// The moments of a prediction ([`GpView::predict_ekf_into`]), as in [`Prediction`].
#[derive(Clone, Copy, Debug)]
pub(crate) struct Moments {
    /// Predictive mean.
    pub(crate) mean: f64,
    /// Predictive variance of the latent function.
    pub(crate) variance: f64,
    /// Prior variance `k(x, x)`.
    pub(crate) prior_variance: f64,
}

/// Which kernel pass a prediction runs: the one compiled per dimension ([`Accum::run_dim`]),
/// or the pass over blocks of rows ([`Accum::run_rows`]) with the mean gradient of the
/// first `grad_cols` inputs only. Both give the same bits where both compute.
#[derive(Clone, Copy, Debug)]
enum Pass {
    ByDim,
    Rows { grad_cols: usize },
}

/// Whether the kernel's features are its inputs scaled one by one (no warping, a diagonal
/// metric), so that the gradient with respect to one input needs only its own feature.
fn diagonal_features(spec: &crate::kernel::KernelSpec) -> bool {
    spec.dim > MAX_DENSE_DIM
        || (spec.warp_units == 0 && spec.metric != crate::kernel::Metric::Mahalanobis)
}

/// Number of `f64` scratch values needed to predict with `n` support (or inducing) points.
pub const fn predict_scratch(n: usize, sparse: bool, want: Want) -> usize {
    let want_var = want.variance || want.grad_variance;
    let mut s = n;
    if want_var {
        s += n;
    }
    if want.grad_variance {
        s += n;
        if sparse {
            s += n;
        }
    }
    s
}

/// `out = T k` for a row-packed lower-triangular `T` (`n = out.len()` rows). The sparse GP's
/// rows are short (`m <= 256`), so what costs is not the arithmetic but the work at each row's
/// ends: row `i` sums its first `4 floor(i / 4)` columns in one four-lane accumulator (no tail
/// loop), then adds its last one to four products in column order. With AVX2, eight rows go at
/// once in intrinsics (`simd::lower_packed_times_rows4`), to the same bits.
/// `cargo bench --bench gp -- triangular` measures it.
pub fn lower_packed_times(t_packed: &[f64], k: &[f64], out: &mut [f64]) {
    let done = crate::simd::lower_packed_times_rows4(t_packed, k, out);
    lower_packed_times_from(t_packed, k, out, done);
}

/// `|T k|^2` for a row-packed lower-triangular `T` (`n = k.len()` rows; 0 for rows a short
/// factor does not have), the sparse variance's quadratic form without `T k` itself. Row `i`
/// sums its products in four lanes (lane `l` the columns `4 c + l`), the four columns from
/// `4 floor(i / 4)` on included with zeros past the diagonal, then `(x0 + x1) + (x2 + x3)`;
/// its square goes to lane `i mod 4` of the result's four sums. With AVX2 four rows go at
/// once, one per lane (`simd::lower_packed_norm2_rows4`), to the same bits: no
/// row ends to handle one by one, no `T k` to store.
pub(crate) fn lower_packed_norm2(t_packed: &[f64], k: &[f64]) -> f64 {
    let (done, sq) = crate::simd::lower_packed_norm2_rows4(t_packed, k);
    lower_packed_norm2_from(t_packed, k, done, sq)
}

/// Rows `first..` of [`lower_packed_norm2`], one by one, their squares added to the lane sums
/// `sq` of the rows before; returns the total.
#[inline(always)]
fn lower_packed_norm2_from(t_packed: &[f64], k: &[f64], first: usize, mut sq: [f64; 4]) -> f64 {
    let n = k.len();
    for i in first..n {
        let Some(row) = lower_row(t_packed, i) else {
            break;
        };
        let head = i - i % 4;
        let mut acc = [0.0f64; 4];
        let (row_head, row_tail) = row.split_at_checked(head).unwrap_or((row, &[]));
        let (k_head, k_tail) = k.split_at_checked(head).unwrap_or((k, &[]));
        for (c, kc) in row_head.chunks_exact(4).zip(k_head.chunks_exact(4)) {
            for ((a, t), k) in acc.iter_mut().zip(lanes4(c)).zip(lanes4(kc)) {
                *a += t * k;
            }
        }
        // The diagonal chunk: the row's last `i mod 4 + 1` entries, zeros past them.
        for (l, a) in acc.iter_mut().enumerate() {
            let t = row_tail.get(l).copied().unwrap_or(0.0);
            *a += t * k_tail.get(l).copied().unwrap_or(0.0);
        }
        let v = sum4(acc);
        if let Some(s) = sq.get_mut(i % 4) {
            *s += v * v;
        }
    }
    sum4(sq)
}

/// The row-packed row `i` of a lower-triangular factor (`i + 1` entries).
#[inline(always)]
pub(crate) fn lower_row(packed: &[f64], i: usize) -> Option<&[f64]> {
    let start = i * (i + 1) / 2;
    packed.get(start..start + i + 1)
}

/// The four lanes of a chunk of four (zeros for a chunk of another length, which
/// `chunks_exact(4)` never yields).
#[inline(always)]
fn lanes4(c: &[f64]) -> [f64; 4] {
    match c {
        [a, b, c, d] => [*a, *b, *c, *d],
        _ => [0.0; 4],
    }
}

/// `sum_l acc[l]` in a fixed order.
#[inline(always)]
fn sum4(a: [f64; 4]) -> f64 {
    (a[0] + a[1]) + (a[2] + a[3])
}

/// Rows `first..` of [`lower_packed_times`], one by one (0 for rows a short factor or `k`
/// does not have).
#[inline(always)]
fn lower_packed_times_from(t_packed: &[f64], k: &[f64], out: &mut [f64], first: usize) {
    for (i, o) in out.iter_mut().enumerate().skip(first) {
        // The first `4 floor(i / 4)` columns in four lanes, then the rest in column order.
        let head = i - i % 4;
        let row = lower_row(t_packed, i).and_then(|r| r.split_at_checked(head));
        let kk = k.get(..=i).and_then(|r| r.split_at_checked(head));
        *o = match (row, kk) {
            (Some((row_head, row_tail)), Some((k_head, k_tail))) => {
                let mut acc = [0.0f64; 4];
                for (c, kc) in row_head.chunks_exact(4).zip(k_head.chunks_exact(4)) {
                    for ((a, t), k) in acc.iter_mut().zip(lanes4(c)).zip(lanes4(kc)) {
                        *a += t * k;
                    }
                }
                row_tail
                    .iter()
                    .zip(k_tail)
                    .fold(sum4(acc), |s, (t, k)| s + t * k)
            }
            _ => 0.0,
        };
    }
}

/// `out = T^T v` for a row-packed lower-triangular `T` (`n = out.len()` rows): four rows at a
/// time, so each entry of `out` is loaded and stored once per four rows. Each entry still sums
/// its rows' terms one by one in row order.
pub fn lower_packed_transpose_times(t_packed: &[f64], v: &[f64], out: &mut [f64]) {
    crate::simd::vectorised(
        #[inline(always)]
        || lower_packed_transpose_times_inline(t_packed, v, out),
    )
}

#[inline(always)]
fn lower_packed_transpose_times_inline(t_packed: &[f64], v: &[f64], out: &mut [f64]) {
    out.fill(0.0);
    let n = out.len().min(v.len());
    let row = |i: usize| lower_row(t_packed, i);
    let mut i = 0;
    while i + 4 <= n {
        if let (Some(r0), Some(r1), Some(r2), Some(r3), Some(&[v0, v1, v2, v3])) = (
            row(i),
            row(i + 1),
            row(i + 2),
            row(i + 3),
            v.get(i..).and_then(|t| t.first_chunk::<4>()),
        ) {
            // Columns `..=i`, which all four rows have, then the triangle beyond.
            let it = out.iter_mut().zip(r0).zip(r1).zip(r2).zip(r3);
            for ((((o, a0), a1), a2), a3) in it {
                let mut s = *o;
                s += a0 * v0;
                s += a1 * v1;
                s += a2 * v2;
                s += a3 * v3;
                *o = s;
            }
            if let (Some([o1, o2, o3]), [.., a11], [.., a21, a22], [.., a31, a32, a33]) =
                (out.get_mut(i + 1..i + 4), r1, r2, r3)
            {
                *o1 += a11 * v1;
                *o1 += a21 * v2;
                *o1 += a31 * v3;
                *o2 += a22 * v2;
                *o2 += a32 * v3;
                *o3 += a33 * v3;
            }
        }
        i += 4;
    }
    for (i, &vi) in v.iter().enumerate().take(n).skip(i) {
        if let Some(r) = row(i) {
            for (o, t) in out.iter_mut().zip(r) {
                *o += t * vi;
            }
        }
    }
}

/// `grad_raw_j = out_scale * sum_r g_u[r] du_r/dz_j / in_scale_j`, for `j < cols` above
/// [`MAX_DENSE_DIM`] inputs (where the Jacobian is diagonal), for every `j < d` below.
fn chain_to_raw(
    g_u: &[f64; MAX_DIM],
    du_dz: &[f64; FEATURE_JACOBIAN_LEN],
    d: usize,
    cols: usize,
    out_scale: f64,
    in_scale: &[f64],
    out: &mut [f64; MAX_DIM],
) {
    if d > MAX_DENSE_DIM {
        // A diagonal Jacobian ([`Kernel::features`]).
        let cols = cols.min(d);
        for (((o, s), g), j) in out.iter_mut().zip(in_scale).zip(g_u).zip(du_dz).take(cols) {
            *o = out_scale * (g * j) / s;
        }
        return;
    }
    for (j, (o, s)) in out.iter_mut().zip(in_scale).take(d).enumerate() {
        let mut acc = 0.0;
        for (r, g) in g_u.iter().take(d).enumerate() {
            acc += g * at(du_dz, r * d + j);
        }
        *o = out_scale * acc / s;
    }
}

struct Accum<'s> {
    features: &'s [f64],
    directions: &'s [f64],
    alpha: &'s [f64],
    alpha_lo: &'s [f64],
    u_star: &'s [f64; MAX_DIM],
    g_star: f64,
    sf2: f64,
    profile: Profile,
    direction: bool,
}

/// Support points per block of [`Accum::run`]: its profile pass runs over a fixed-size array,
/// which the compiler vectorises (the exponential is straight-line code).
const BLOCK: usize = 16;

/// Support points per block of [`Accum::run_rows`]: enough profiles at once for the
/// exponentials' long chains of multiplications and additions to overlap.
const ROWS_BLOCK: usize = 64;

impl Accum<'_> {
    /// [`Accum::run`] for `d` inputs (the kernel pass is compiled per dimension).
    #[inline(always)]
    fn run_dim<const GRAD: bool>(
        &self,
        d: usize,
        kvec: &mut [f64],
        cvec: Option<&mut [f64]>,
        grad_u: &mut [f64; MAX_DIM],
    ) -> f64 {
        match d {
            1 => self.run::<1, GRAD>(kvec, cvec, grad_u),
            2 => self.run::<2, GRAD>(kvec, cvec, grad_u),
            3 => self.run::<3, GRAD>(kvec, cvec, grad_u),
            4 => self.run::<4, GRAD>(kvec, cvec, grad_u),
            5 => self.run::<5, GRAD>(kvec, cvec, grad_u),
            6 => self.run::<6, GRAD>(kvec, cvec, grad_u),
            7 => self.run::<7, GRAD>(kvec, cvec, grad_u),
            8 => self.run::<8, GRAD>(kvec, cvec, grad_u),
            // Wider inputs (vector models) share one pass over `d` of `MAX_DIM` slots.
            _ => self.run_wide::<GRAD>(d, kvec, cvec, grad_u),
        }
    }

    /// One pass over the support points, in blocks of [`BLOCK`]: squared distances, then the
    /// profile and its slope for the whole block, then `k_i` into `kvec`, `dk_i/dr2` into
    /// `cvec`, the mean (returned) and its feature-space gradient.
    #[inline(always)]
    fn run<const D: usize, const GRAD: bool>(
        &self,
        kvec: &mut [f64],
        cvec: Option<&mut [f64]>,
        grad_u: &mut [f64; MAX_DIM],
    ) -> f64 {
        self.run_width::<D, GRAD>(D, kvec, cvec, grad_u)
    }

    /// [`Accum::run`] for `d` (9..=[`MAX_DIM`]) inputs: one compiled pass for every width
    /// ([`Accum::run_rows`]).
    #[inline(always)]
    fn run_wide<const GRAD: bool>(
        &self,
        d: usize,
        kvec: &mut [f64],
        cvec: Option<&mut [f64]>,
        grad_u: &mut [f64; MAX_DIM],
    ) -> f64 {
        self.run_rows::<GRAD>(d, d, kvec, cvec, grad_u)
    }

    /// The pass of [`Accum::run_width`] over rows of `d` features (1..=[`MAX_DIM`]), with the
    /// gradient of the first `grad_cols` features only (the others are left zero), to
    /// rounding: the sums over the rows (the mean, the gradient's columns) go in four partial
    /// sums, so that no chain of `n` additions holds the CPU up. Rows of many features are
    /// too wide for one row's sums to keep the CPU busy, so with AVX2 the squared distances
    /// go four rows at a time (`simd::sq_dists_rows4`, in [`Accum::run_width`]'s order) and
    /// the gradient's sums four columns at a time (`simd::weighted_diffs`), to the same bits
    /// as without AVX2.
    #[inline(always)]
    fn run_rows<const GRAD: bool>(
        &self,
        d: usize,
        grad_cols: usize,
        kvec: &mut [f64],
        mut cvec: Option<&mut [f64]>,
        grad_u: &mut [f64; MAX_DIM],
    ) -> f64 {
        // `1 <= MAX_DIM`: the clamp cannot panic.
        let width = d.clamp(1, MAX_DIM);
        let us = self.u_star;
        // The mean in four sums (lane `i mod 4` of row `i`): no chain of `n` additions.
        let mut mean4 = [0.0f64; 4];
        let mut gsum = [0.0; MAX_DIM];
        let n = kvec.len().min(self.alpha.len());
        let mut first = 0;
        while first < n {
            let last = n.min(first + ROWS_BLOCK);
            let (Some(rows), Some(k_out), Some(alpha)) = (
                self.features.get(first * width..last * width),
                kvec.get_mut(first..last),
                self.alpha.get(first..last),
            ) else {
                break;
            };
            let mut r2 = [0.0; ROWS_BLOCK];
            let r2_rows = r2.get_mut(..last - first).unwrap_or(&mut []);
            let done = crate::simd::sq_dists_rows4(rows, width, us, r2_rows);
            for (r2_i, row) in r2_rows
                .iter_mut()
                .zip(rows.chunks_exact(width.max(1)))
                .skip(done)
            {
                let mut acc = 0.0;
                for (r, u) in row.iter().zip(us) {
                    let dj = r - u;
                    acc += dj * dj;
                }
                *r2_i = acc;
            }
            let (mut k, mut c) = ([0.0; ROWS_BLOCK], [0.0; ROWS_BLOCK]);
            if GRAD {
                profiles_and_slopes(self.profile, &r2, &mut k, &mut c);
            } else {
                profiles(self.profile, &r2, &mut k);
            }
            if self.direction {
                let dirs = self.directions.get(first..).unwrap_or(&[]);
                for ((k_j, c_j), dir) in k.iter_mut().zip(c.iter_mut()).zip(dirs) {
                    let factor = 0.5 * (1.0 + self.g_star * dir);
                    *k_j *= factor;
                    *c_j *= factor;
                }
            }
            let mut a = [0.0; ROWS_BLOCK];
            for (a_j, hi) in a.iter_mut().zip(alpha) {
                *a_j = *hi;
            }
            if let Some(lo) = self.alpha_lo.get(first..) {
                for (a_j, lo) in a.iter_mut().zip(lo) {
                    *a_j += lo;
                }
            }
            for (k_j, c_j) in k.iter_mut().zip(c.iter_mut()) {
                *k_j *= self.sf2;
                *c_j *= self.sf2;
            }
            for (k_out, k_j) in k_out.iter_mut().zip(&k) {
                *k_out = *k_j;
            }
            if let Some(cv) = cvec
                .as_deref_mut()
                .filter(|_| GRAD)
                .and_then(|cv| cv.get_mut(first..))
            {
                for (c_out, c_j) in cv.iter_mut().zip(&c) {
                    *c_out = *c_j;
                }
            }
            if GRAD {
                // dk/du* = c dr2/du* = -2 c (u_i - u*): the mean's gradient weights.
                let mut w = [0.0; ROWS_BLOCK];
                for ((w_j, c_j), a_j) in w.iter_mut().zip(&c).zip(&a).take(last - first) {
                    *w_j = -2.0 * c_j * a_j;
                }
                let w = w.get(..last - first).unwrap_or(&[]);
                crate::simd::weighted_diffs(rows, width, grad_cols, us, w, &mut gsum);
            }
            // The same sums with or without the gradient: the mean is bit-identical either way.
            let rows_here = last - first;
            let quads = k.as_chunks::<4>().0.iter().zip(a.as_chunks::<4>().0);
            for (q, (kq, aq)) in quads.enumerate().take(rows_here.div_ceil(4)) {
                // Lane `l` of the last quad counts only for a row this block has.
                let lanes = (rows_here - 4 * q).min(4);
                if lanes == 4 {
                    for ((m, k_j), a_j) in mean4.iter_mut().zip(kq).zip(aq) {
                        *m += k_j * a_j;
                    }
                } else {
                    for ((m, k_j), a_j) in mean4.iter_mut().zip(kq).zip(aq).take(lanes) {
                        *m += k_j * a_j;
                    }
                }
            }
            first = last;
        }
        for (g, s) in grad_u.iter_mut().zip(&gsum) {
            *g = *s;
        }
        sum4(mean4)
    }

    /// The pass over rows of `width` features, with arrays of `D >= width` slots (`D ==
    /// width` for the passes compiled per dimension).
    #[inline(always)]
    fn run_width<const D: usize, const GRAD: bool>(
        &self,
        width: usize,
        kvec: &mut [f64],
        mut cvec: Option<&mut [f64]>,
        grad_u: &mut [f64; MAX_DIM],
    ) -> f64 {
        // `width.max(1)` below: a chunk size the optimiser sees is not zero (no panic path).
        let mut us = [0.0; D];
        for (u, s) in us.iter_mut().zip(self.u_star) {
            *u = *s;
        }
        let mut mean = 0.0;
        let mut gsum = [0.0; D];
        // Blocks by index and checked slices: a zip of `chunks` iterators keeps a division
        // (by the chunk size) that the link-time no-panic proof cannot discharge.
        let n = kvec.len().min(self.alpha.len());
        let mut first = 0;
        while first < n {
            let last = n.min(first + BLOCK);
            let (Some(rows), Some(k_out), Some(alpha)) = (
                self.features.get(first * width..last * width),
                kvec.get_mut(first..last),
                self.alpha.get(first..last),
            ) else {
                break;
            };
            let mut r2 = [0.0; BLOCK];
            for (r2_i, row) in r2.iter_mut().zip(rows.chunks_exact(width.max(1))) {
                let mut acc = 0.0;
                for (r, u) in row.iter().zip(&us) {
                    let dj = r - u;
                    acc += dj * dj;
                }
                *r2_i = acc;
            }
            let (mut k, mut c) = ([0.0; BLOCK], [0.0; BLOCK]);
            if GRAD {
                profiles_and_slopes(self.profile, &r2, &mut k, &mut c);
            } else {
                profiles(self.profile, &r2, &mut k);
            }
            if self.direction {
                let dirs = self.directions.get(first..).unwrap_or(&[]);
                for ((k_j, c_j), dir) in k.iter_mut().zip(c.iter_mut()).zip(dirs) {
                    let factor = 0.5 * (1.0 + self.g_star * dir);
                    *k_j *= factor;
                    *c_j *= factor;
                }
            }
            let mut a = [0.0; BLOCK];
            for (a_j, hi) in a.iter_mut().zip(alpha) {
                *a_j = *hi;
            }
            if let Some(lo) = self.alpha_lo.get(first..) {
                for (a_j, lo) in a.iter_mut().zip(lo) {
                    *a_j += lo;
                }
            }
            for (k_j, c_j) in k.iter_mut().zip(c.iter_mut()) {
                *k_j *= self.sf2;
                *c_j *= self.sf2;
            }
            for (k_out, k_j) in k_out.iter_mut().zip(&k) {
                *k_out = *k_j;
            }
            // Only a gradient pass has slopes (the variance gradient's weights need them).
            if let Some(cv) = cvec
                .as_deref_mut()
                .filter(|_| GRAD)
                .and_then(|cv| cv.get_mut(first..))
            {
                for (c_out, c_j) in cv.iter_mut().zip(&c) {
                    *c_out = *c_j;
                }
            }
            if GRAD {
                // dk/du* = c dr2/du* = -2 c (u_i - u*): the mean's gradient weights.
                for ((row, (k_j, c_j)), a_j) in rows
                    .chunks_exact(width.max(1))
                    .zip(k.iter().zip(&c))
                    .zip(&a)
                {
                    mean += k_j * a_j;
                    let w = -2.0 * c_j * a_j;
                    for ((g, r), u) in gsum.iter_mut().zip(row).zip(&us) {
                        *g += w * (r - u);
                    }
                }
            } else {
                // The same sum in the same order: the mean is bit-identical either way.
                for (k_j, a_j) in k.iter().zip(&a) {
                    mean += k_j * a_j;
                }
            }
            first = last;
        }
        for (g, s) in grad_u.iter_mut().zip(&gsum) {
            *g = *s;
        }
        mean
    }
}

/// Dot product with eight independent accumulators over fixed-size chunks, so the compiler
/// vectorises it without bounds checks (the variance's triangular solve is this loop).
#[inline]
pub fn dot(a: &[f64], b: &[f64]) -> f64 {
    let n = a.len().min(b.len());
    let (a, b) = (a.get(..n).unwrap_or(&[]), b.get(..n).unwrap_or(&[]));
    let mut acc = [0.0f64; 8];
    let (ca, cb) = (a.chunks_exact(8), b.chunks_exact(8));
    let (ra, rb) = (ca.remainder(), cb.remainder());
    for (x, y) in ca.zip(cb) {
        for ((s, x), y) in acc.iter_mut().zip(x).zip(y) {
            *s += x * y;
        }
    }
    let mut s = ((acc[0] + acc[4]) + (acc[1] + acc[5])) + ((acc[2] + acc[6]) + (acc[3] + acc[7]));
    for (x, y) in ra.iter().zip(rb) {
        s += x * y;
    }
    s
}

/// Checks that a row-packed triangular factor holds at least `n` rows.
fn check_packed(packed: &[f64], n: usize) -> Result<(), CoreError> {
    let expected = n.saturating_mul(n.saturating_add(1)) / 2;
    if packed.len() < expected {
        Err(CoreError::DimensionMismatch {
            expected,
            got: packed.len(),
        })
    } else {
        Ok(())
    }
}

/// Row `i` of a row-packed lower-triangular matrix: `(L[i, 0..i], L[i, i])`.
#[inline(always)]
fn packed_row(packed: &[f64], i: usize) -> Option<(&[f64], f64)> {
    let start = i * (i + 1) / 2;
    let row = packed.get(start..start + i + 1)?;
    let (diag, off) = row.split_last()?;
    Some((off, *diag))
}

/// Solves `L v = k` for a row-packed lower-triangular `L` (`v` and `k` of length `n`; the first
/// `min(v.len(), k.len())` rows are solved).
///
/// Errors with [`CoreError::DimensionMismatch`] when `l_packed` holds fewer than
/// `n (n + 1) / 2` values (then `v` is left unspecified).
pub fn forward_substitute_packed(
    l_packed: &[f64],
    k: &[f64],
    v: &mut [f64],
) -> Result<(), CoreError> {
    crate::simd::vectorised(
        #[inline(always)]
        || forward_substitute_inline(l_packed, k, v),
    )
}

#[inline(always)]
fn forward_substitute_inline(l_packed: &[f64], k: &[f64], v: &mut [f64]) -> Result<(), CoreError> {
    let n = v.len().min(k.len());
    check_packed(l_packed, n)?;
    let short = CoreError::DimensionMismatch {
        expected: n * (n + 1) / 2,
        got: l_packed.len(),
    };
    // Four rows at a time: their dot products with the solved part `v[..i]` (two rows per
    // pass, sharing each load of `v`: three loads per two multiply-adds instead of four),
    // then the 4 x 4 triangle.
    let mut i = 0;
    while i + 4 <= n {
        let row = |r: usize| packed_row(l_packed, r).ok_or(short);
        let ((l0, d0), (l1, d1), (l2, d2), (l3, d3)) =
            (row(i)?, row(i + 1)?, row(i + 2)?, row(i + 3)?);
        let (solved, rest) = v.split_at_mut_checked(i).ok_or(short)?;
        let (head1, tail1) = l1.split_at_checked(i).ok_or(short)?;
        let (head2, tail2) = l2.split_at_checked(i).ok_or(short)?;
        let (head3, tail3) = l3.split_at_checked(i).ok_or(short)?;
        let [s0, s1, s2, s3] = dot4([l0, head1, head2, head3], solved);
        let (Some(&[k0, k1, k2, k3]), Some([v0, v1, v2, v3]), [a10], [a20, a21], [a30, a31, a32]) = (
            k.get(i..).and_then(|t| t.first_chunk::<4>()),
            rest.first_chunk_mut::<4>(),
            tail1,
            tail2,
            tail3,
        ) else {
            return Err(short);
        };
        *v0 = (k0 - s0) / d0;
        *v1 = (k1 - (s1 + a10 * *v0)) / d1;
        *v2 = (k2 - (s2 + a20 * *v0 + a21 * *v1)) / d2;
        *v3 = (k3 - (s3 + a30 * *v0 + a31 * *v1 + a32 * *v2)) / d3;
        i += 4;
    }
    for r in i..n {
        let (off, diag) = packed_row(l_packed, r).ok_or(short)?;
        let (solved, rest) = v.split_at_mut_checked(r).ok_or(short)?;
        let vr = rest.first_mut().ok_or(short)?;
        let kr = k.get(r).copied().ok_or(short)?;
        *vr = (kr - dot(off, solved)) / diag;
    }
    Ok(())
}

/// The dot products of four rows with one vector `b` (all cut to the shortest length). The
/// rows go in pairs: each row keeps eight partial sums over chunks of eight, as [`dot`] does,
/// so each vectorises along the row, and a pair shares every load of `b`. (On the exact
/// n = 500 EKF step this is about 10% faster than the four rows at once with four sums each,
/// which LLVM vectorises across the rows, and about 20% faster than one row at a time.)
#[inline(always)]
fn dot4(rows: [&[f64]; 4], b: &[f64]) -> [f64; 4] {
    let n = rows.iter().fold(b.len(), |n, r| n.min(r.len()));
    fn cut(s: &[f64], n: usize) -> &[f64] {
        s.get(..n).unwrap_or(&[])
    }
    let [r0, r1, r2, r3] = rows;
    let (b, r0, r1, r2, r3) = (cut(b, n), cut(r0, n), cut(r1, n), cut(r2, n), cut(r3, n));
    let (mut a0, mut a1, mut a2, mut a3) = ([0.0f64; 4], [0.0f64; 4], [0.0f64; 4], [0.0f64; 4]);
    {
        let pairs = [(&mut a0, &mut a1, r0, r1), (&mut a2, &mut a3, r2, r3)];
        for (p, q, x, z) in pairs {
            let mut sp = [0.0f64; 8];
            let mut sq = [0.0f64; 8];
            let it = b
                .chunks_exact(8)
                .zip(x.chunks_exact(8))
                .zip(z.chunks_exact(8));
            for ((y, x), z) in it {
                for ((s, x), y) in sp.iter_mut().zip(x).zip(y) {
                    *s += x * y;
                }
                for ((s, z), y) in sq.iter_mut().zip(z).zip(y) {
                    *s += z * y;
                }
            }
            *p = [sp[0] + sp[4], sp[1] + sp[5], sp[2] + sp[6], sp[3] + sp[7]];
            *q = [sq[0] + sq[4], sq[1] + sq[5], sq[2] + sq[6], sq[3] + sq[7]];
        }
    }
    let acc = [a0, a1, a2, a3];
    let tail = n - n % 8;
    let mut out = [0.0; 4];
    for ((o, a), r) in out.iter_mut().zip(&acc).zip([r0, r1, r2, r3]) {
        let mut s = (a[0] + a[2]) + (a[1] + a[3]);
        let (rx, ry) = (r.get(tail..).unwrap_or(&[]), b.get(tail..).unwrap_or(&[]));
        for (x, y) in rx.iter().zip(ry) {
            s += x * y;
        }
        *o = s;
    }
    out
}

/// Solves `L^T w = v` in place for a row-packed lower-triangular `L` (`n = v.len()` rows).
///
/// Errors with [`CoreError::DimensionMismatch`] when `l_packed` holds fewer than
/// `n (n + 1) / 2` values (then `v` is left unchanged).
pub fn back_substitute_packed(l_packed: &[f64], v: &mut [f64]) -> Result<(), CoreError> {
    crate::simd::vectorised(
        #[inline(always)]
        || back_substitute_inline(l_packed, v),
    )
}

#[inline(always)]
fn back_substitute_inline(l_packed: &[f64], v: &mut [f64]) -> Result<(), CoreError> {
    let n = v.len();
    check_packed(l_packed, n)?;
    let short = CoreError::DimensionMismatch {
        expected: n * (n + 1) / 2,
        got: l_packed.len(),
    };
    for j in (0..n).rev() {
        let (off, diag) = packed_row(l_packed, j).ok_or(short)?;
        let (head, rest) = v.split_at_mut_checked(j).ok_or(short)?;
        let vj = rest.first_mut().ok_or(short)?;
        let wj = *vj / diag;
        *vj = wj;
        // v[0..j] -= wj * L[j, 0..j]
        for (vi, lji) in head.iter_mut().zip(off) {
            *vi -= wj * lji;
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::kernel::{KernelSpec, Metric};

    /// Dense reference GP (O(n^3), test only).
    struct Dense {
        spec: KernelSpec,
        theta: [f64; 16],
        x: [[f64; 3]; 6],
        y: [f64; 6],
        noise: f64,
    }

    fn cholesky(a: &[[f64; 6]; 6]) -> [[f64; 6]; 6] {
        let mut l = [[0.0; 6]; 6];
        for i in 0..6 {
            for j in 0..=i {
                let mut s = a[i][j];
                for k in 0..j {
                    s -= l[i][k] * l[j][k];
                }
                l[i][j] = if i == j { s.sqrt() } else { s / l[j][j] };
            }
        }
        l
    }

    struct Owned {
        theta: [f64; 16],
        feats: [f64; 18],
        dirs: [f64; 6],
        alpha: [f64; 6],
        packed: [f64; 21],
        mean: [f64; 3],
        scale: [f64; 3],
    }

    impl Dense {
        fn build(&self, w: &[f64]) -> Owned {
            let n_p = self.spec.n_params();
            let k = Kernel::new(self.spec, &self.theta[..n_p], w).unwrap();
            let mean = [0.1, -0.2, 0.3];
            let scale = [1.5, 0.5, 2.0];
            let std = |x: &[f64; 3]| {
                [
                    (x[0] - mean[0]) / scale[0],
                    (x[1] - mean[1]) / scale[1],
                    (x[2] - mean[2]) / scale[2],
                ]
            };
            let dirs: [f64; 6] = core::array::from_fn(|i| self.spec.direction_of(&self.x[i]));
            let mut kk = [[0.0; 6]; 6];
            for i in 0..6 {
                for j in 0..6 {
                    kk[i][j] = k.eval(&std(&self.x[i]), dirs[i], &std(&self.x[j]), dirs[j]);
                }
                kk[i][i] += self.noise;
            }
            let l = cholesky(&kk);
            let mut packed = [0.0; 21];
            for i in 0..6 {
                for j in 0..=i {
                    packed[i * (i + 1) / 2 + j] = l[i][j];
                }
            }
            let mut v = [0.0; 6];
            forward_substitute_packed(&packed, &self.y, &mut v).unwrap();
            back_substitute_packed(&packed, &mut v).unwrap();
            let mut feats = [0.0; 18];
            for i in 0..6 {
                let mut u = [0.0; MAX_DIM];
                let mut jac = [0.0; FEATURE_JACOBIAN_LEN];
                k.features(&std(&self.x[i]), &mut u, &mut jac);
                feats[i * 3..i * 3 + 3].copy_from_slice(&u[..3]);
            }
            Owned {
                theta: self.theta,
                feats,
                dirs,
                alpha: v,
                packed,
                mean,
                scale,
            }
        }
    }

    fn view<'a>(o: &'a Owned, spec: KernelSpec, w: &'a [f64], noise: f64) -> GpView<'a> {
        GpView::new(GpParts {
            kernel: Kernel::new(spec, &o.theta[..spec.n_params()], w).unwrap(),
            input_mean: &o.mean,
            input_scale: &o.scale,
            output_mean: 0.0,
            output_scale: 1.0,
            linear: &[],
            features: &o.feats,
            directions: if spec.direction.is_some() {
                &o.dirs
            } else {
                &[]
            },
            alpha: &o.alpha,
            alpha_lo: &[],
            variance: Variance::Exact {
                chol_packed: &o.packed,
            },
            noise_var: noise,
        })
        .unwrap()
    }

    fn setup(spec: KernelSpec) -> Dense {
        let mut theta = [0.0; 16];
        for (i, t) in theta.iter_mut().enumerate().take(spec.n_params()) {
            *t = 0.2 * libm::cos(0.9 * i as f64);
        }
        let x = core::array::from_fn(|i| {
            let t = i as f64;
            [libm::sin(t), libm::cos(1.3 * t), 0.3 * t - 0.5]
        });
        let y = core::array::from_fn(|i| libm::sin(0.7 * i as f64) + 0.1 * i as f64);
        Dense {
            spec,
            theta,
            x,
            y,
            noise: 0.05,
        }
    }

    const W: [f64; 9] = [1.2, 0.0, 0.0, -0.4, 0.9, 0.0, 0.1, 0.3, 1.1];

    fn all_specs() -> [KernelSpec; 4] {
        [
            KernelSpec::se_ard(3),
            KernelSpec {
                profile: Profile::Matern52,
                ..KernelSpec::se_ard(3)
            },
            KernelSpec {
                metric: Metric::Mahalanobis,
                warp_units: 2,
                direction: Some([2, 0]),
                ..KernelSpec::se_ard(3)
            },
            KernelSpec {
                metric: Metric::Isotropic,
                ..KernelSpec::se_ard(3)
            },
        ]
    }

    #[test]
    fn mean_and_variance_match_dense_formulae() {
        for spec in all_specs() {
            let dense = setup(spec);
            let owned = dense.build(&W);
            let gp = view(&owned, spec, &W, dense.noise);
            let k = Kernel::new(spec, &owned.theta[..spec.n_params()], &W).unwrap();
            let xs = [0.4, 0.1, -0.2];
            let zs = [
                (xs[0] - 0.1) / 1.5,
                (xs[1] + 0.2) / 0.5,
                (xs[2] - 0.3) / 2.0,
            ];
            let gs = spec.direction_of(&xs);
            let mut scratch = [0.0; 32];
            let p = gp.predict(&xs, Want::ALL, &mut scratch).unwrap();
            // Dense: mean = k^T alpha; var = kss - k^T (K+s I)^{-1} k
            let mut kv = [0.0; 6];
            for i in 0..6 {
                let zi = [
                    (dense.x[i][0] - 0.1) / 1.5,
                    (dense.x[i][1] + 0.2) / 0.5,
                    (dense.x[i][2] - 0.3) / 2.0,
                ];
                kv[i] = k.eval(&zi, owned.dirs[i], &zs, gs);
            }
            let mean: f64 = (0..6).map(|i| kv[i] * owned.alpha[i]).sum();
            let mut w = [0.0; 6];
            forward_substitute_packed(&owned.packed, &kv, &mut w).unwrap();
            back_substitute_packed(&owned.packed, &mut w).unwrap();
            let var = k.eval(&zs, gs, &zs, gs) - (0..6).map(|i| kv[i] * w[i]).sum::<f64>();
            assert!((p.mean - mean).abs() < 1e-12, "{spec:?}");
            assert!((p.variance - var).abs() < 1e-12, "{spec:?}");
        }
    }

    #[test]
    fn a_prediction_without_gradients_is_bit_identical_to_one_with_them() {
        // More points than a block of the kernel pass, and a partial last block; exact and
        // sparse variance factors; every profile, metric and the direction factor.
        let n = 37usize;
        let feats: Vec<f64> = (0..3 * n)
            .map(|i| 1.3 * libm::sin(0.37 * i as f64 + 0.2))
            .collect();
        let dirs: Vec<f64> = (0..n)
            .map(|i| if i % 3 == 0 { -1.0 } else { 1.0 })
            .collect();
        let alpha: Vec<f64> = (0..n).map(|i| libm::cos(0.61 * i as f64)).collect();
        // A factor with a large diagonal (exact: `L^-1 k` is small) and one with a small
        // one (sparse: `R k` is small), so that both variances stay positive.
        let factor = |diag: f64| {
            let mut packed = vec![0.0; n * (n + 1) / 2];
            for i in 0..n {
                for j in 0..=i {
                    packed[i * (i + 1) / 2 + j] = if i == j {
                        diag * (1.0 + 0.2 * libm::sin(i as f64))
                    } else {
                        0.02 * diag * libm::cos((i * 5 + j) as f64)
                    };
                }
            }
            packed
        };
        let (exact_factor, sparse_factor) = (factor(20.0), factor(0.02));
        let (mean, scale) = ([0.1, -0.2, 0.3], [1.5, 0.5, 2.0]);
        for spec in all_specs() {
            let mut theta = [0.0; 16];
            for (i, t) in theta.iter_mut().enumerate().take(spec.n_params()) {
                *t = 0.2 * libm::cos(0.9 * i as f64);
            }
            for sparse in [false, true] {
                let gp = GpView::new(GpParts {
                    kernel: Kernel::new(spec, &theta[..spec.n_params()], &W).unwrap(),
                    input_mean: &mean,
                    input_scale: &scale,
                    output_mean: 0.3,
                    output_scale: 2.0,
                    linear: &[],
                    features: &feats,
                    directions: if spec.direction.is_some() { &dirs } else { &[] },
                    alpha: &alpha,
                    alpha_lo: &[],
                    variance: if sparse {
                        Variance::Sparse {
                            variance_factor: &sparse_factor,
                        }
                    } else {
                        Variance::Exact {
                            chol_packed: &exact_factor,
                        }
                    },
                    noise_var: 0.01,
                })
                .unwrap();
                let mut scratch = vec![0.0; gp.predict_scratch(Want::ALL)];
                for q in 0..5 {
                    let t = q as f64;
                    let x = [libm::sin(t), 0.5 * libm::cos(2.0 * t), 0.7 * t - 1.0];
                    let all = gp.predict(&x, Want::ALL, &mut scratch).unwrap();
                    let mean_only = gp.predict(&x, Want::MEAN, &mut scratch).unwrap();
                    let var_only = gp.predict(&x, Want::VARIANCE, &mut scratch).unwrap();
                    assert_eq!(mean_only.mean.to_bits(), all.mean.to_bits(), "{spec:?}");
                    assert_eq!(var_only.mean.to_bits(), all.mean.to_bits(), "{spec:?}");
                    assert_eq!(
                        var_only.variance.to_bits(),
                        all.variance.to_bits(),
                        "{spec:?} sparse {sparse}"
                    );
                    assert!(
                        all.variance > 0.0,
                        "{spec:?} sparse {sparse}: {}",
                        all.variance
                    );
                    assert!(all.grad_mean.iter().any(|g| *g != 0.0));
                    // `predict` runs on the CPU's widest vectors (`simd`); its body inlined
                    // here runs on the build's. Every output to the bit.
                    for want in [Want::ALL, Want::EKF, Want::MEAN] {
                        let wide = gp.predict(&x, want, &mut scratch).unwrap();
                        let narrow = gp.predict_inline(&x, want, &mut scratch).unwrap();
                        assert_eq!(bits(&wide), bits(&narrow), "{spec:?} sparse {sparse}");
                    }
                }
            }
        }
    }

    /// The vector filter's prediction (`predict_ekf_into`) agrees with `predict` with
    /// `Want::EKF` to rounding (it sums the mean in four lanes, the gradient's columns in four
    /// partial sums and the sparse variance's `|R k|^2` without `R k`): the moments, and the
    /// mean gradient of the inputs it asks for (all of them for a kernel whose features mix or
    /// warp its inputs), on narrow and wide inputs, with a partial last block of rows, for
    /// exact and sparse factors; and it gives the same bits on the CPU's widest vectors as
    /// inlined on the build's.
    #[test]
    fn the_vector_filters_prediction_agrees_with_predict() {
        let n = 37usize;
        let alpha: Vec<f64> = (0..n).map(|i| libm::cos(0.61 * i as f64)).collect();
        let alpha_lo: Vec<f64> = (0..n).map(|i| 1e-9 * libm::sin(i as f64)).collect();
        let dirs: Vec<f64> = (0..n)
            .map(|i| if i % 3 == 0 { -1.0 } else { 1.0 })
            .collect();
        // A large diagonal for the exact factor (`L^-1 k` small), a small one for the sparse
        // (`R k` small): both variances positive.
        let factor = |diag: f64| {
            let mut packed = vec![0.0; n * (n + 1) / 2];
            for i in 0..n {
                for j in 0..=i {
                    packed[i * (i + 1) / 2 + j] = if i == j {
                        diag * (1.0 + 0.2 * libm::sin(i as f64))
                    } else {
                        0.02 * diag * libm::cos((i * 5 + j) as f64)
                    };
                }
            }
            packed
        };
        let (exact_factor, sparse_factor) = (factor(20.0), factor(0.1));
        let mut specs: Vec<KernelSpec> = all_specs().to_vec();
        for d in [5, 12, 14] {
            specs.push(KernelSpec::se_ard(d));
            specs.push(KernelSpec {
                profile: Profile::Matern52,
                direction: Some([1, 0]),
                ..KernelSpec::se_ard(d)
            });
        }
        let close = |a: f64, b: f64, scale: f64| (a - b).abs() <= 1e-11 * scale;
        for spec in specs {
            let d = spec.dim;
            let feats: Vec<f64> = (0..d * n)
                .map(|i| 1.3 * libm::sin(0.37 * i as f64 + 0.2))
                .collect();
            let theta: Vec<f64> = (0..spec.n_params())
                .map(|i| 0.2 * libm::cos(0.9 * i as f64))
                .collect();
            let whiten: Vec<f64> = (0..d * d)
                .map(|i| if i % (d + 1) == 0 { 1.1 } else { 0.1 })
                .collect();
            let (mean, scale): (Vec<f64>, Vec<f64>) = (0..d)
                .map(|j| (0.1 * j as f64, 1.0 + 0.1 * j as f64))
                .unzip();
            let slopes: Vec<f64> = (0..d).map(|j| 0.05 * j as f64).collect();
            for (sparse, linear) in [(false, &[][..]), (true, &slopes[..])] {
                let gp = GpView::new(GpParts {
                    kernel: Kernel::new(spec, &theta, &whiten).unwrap(),
                    input_mean: &mean,
                    input_scale: &scale,
                    output_mean: 0.3,
                    output_scale: 2.0,
                    linear,
                    features: &feats,
                    directions: if spec.direction.is_some() { &dirs } else { &[] },
                    alpha: &alpha,
                    alpha_lo: if sparse { &alpha_lo } else { &[] },
                    variance: if sparse {
                        Variance::Sparse {
                            variance_factor: &sparse_factor,
                        }
                    } else {
                        Variance::Exact {
                            chol_packed: &exact_factor,
                        }
                    },
                    noise_var: 0.01,
                })
                .unwrap()
                .with_mean_input(0)
                .unwrap();
                let mut scratch = vec![0.0; gp.predict_scratch(Want::ALL)];
                for q in 0..3 {
                    let x: Vec<f64> = (0..d)
                        .map(|j| 0.4 * libm::sin(q as f64 + 0.7 * j as f64))
                        .collect();
                    let want = gp.predict(&x, Want::EKF, &mut scratch).unwrap();
                    assert!(want.variance > 0.0, "{spec:?} sparse {sparse}");
                    let g_scale = 1.0 + want.grad_mean.iter().fold(0.0f64, |m, g| m.max(g.abs()));
                    for grad_cols in [1, 4, d] {
                        let mut grad = [0.0; MAX_DIM];
                        let got = gp
                            .predict_ekf_into(&x, grad_cols, &mut scratch, &mut grad)
                            .unwrap();
                        let what = format!("{spec:?} sparse {sparse}, {grad_cols} columns");
                        assert!(close(got.mean, want.mean, 1.0 + want.mean.abs()), "{what}");
                        assert!(
                            close(got.variance, want.variance, want.prior_variance),
                            "{what}: {} {}",
                            got.variance,
                            want.variance
                        );
                        assert_eq!(got.prior_variance, want.prior_variance, "{what}");
                        let cols = if diagonal_features(&spec) {
                            grad_cols.min(d)
                        } else {
                            d
                        };
                        for j in 0..cols {
                            assert!(close(grad[j], want.grad_mean[j], g_scale), "{what}, {j}");
                        }
                        // Inlined here, on the build's vectors: the same bits.
                        let mut narrow = [0.0; MAX_DIM];
                        let inline = gp
                            .predict_parts(
                                &x,
                                Want::EKF,
                                Pass::Rows { grad_cols },
                                &mut scratch,
                                &mut narrow,
                                &mut [0.0; MAX_DIM],
                            )
                            .unwrap();
                        let moments = |m: Moments| [m.mean, m.variance].map(f64::to_bits);
                        assert_eq!(moments(got), moments(inline), "{what}");
                        assert_eq!(grad.map(f64::to_bits), narrow.map(f64::to_bits), "{what}");
                    }
                }
            }
        }
    }

    /// Every number of a prediction, as bits.
    fn bits(p: &Prediction) -> Vec<u64> {
        let head = [p.mean, p.variance, p.prior_variance];
        head.iter()
            .chain(&p.grad_mean)
            .chain(&p.grad_variance)
            .map(|v| v.to_bits())
            .collect()
    }

    /// The public triangular products run on the CPU's widest vectors (`simd`), their bodies
    /// inlined here on the build's: the same bits, on sizes around every block and chunk.
    #[test]
    fn triangular_products_give_the_same_bits_on_wide_and_narrow_vectors() {
        for n in [0usize, 1, 3, 4, 7, 8, 9, 17, 64, 101, 203] {
            let packed: Vec<f64> = (0..n * (n + 1) / 2)
                .map(|i| 1.0 + 0.3 * libm::sin(0.37 * i as f64) * 10f64.powi(i as i32 % 7 - 3))
                .collect();
            let k: Vec<f64> = (0..n).map(|i| libm::cos(0.7 * i as f64) + 0.2).collect();
            let (mut wide, mut narrow) = (vec![0.0; n], vec![0.0; n]);
            let as_bits = |v: &[f64]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
            forward_substitute_packed(&packed, &k, &mut wide).unwrap();
            forward_substitute_inline(&packed, &k, &mut narrow).unwrap();
            assert_eq!(as_bits(&wide), as_bits(&narrow), "forward, n = {n}");
            back_substitute_packed(&packed, &mut wide).unwrap();
            back_substitute_inline(&packed, &mut narrow).unwrap();
            assert_eq!(as_bits(&wide), as_bits(&narrow), "back, n = {n}");
            lower_packed_times(&packed, &k, &mut wide);
            lower_packed_times_from(&packed, &k, &mut narrow, 0);
            assert_eq!(as_bits(&wide), as_bits(&narrow), "times, n = {n}");
            lower_packed_transpose_times(&packed, &k, &mut wide);
            lower_packed_transpose_times_inline(&packed, &k, &mut narrow);
            assert_eq!(as_bits(&wide), as_bits(&narrow), "transpose, n = {n}");
        }
    }

    /// `|T k|^2` (the vector filter's sparse variance) on the CPU's widest vectors gives the
    /// bits of its plain loop, and the textbook sum to rounding, on sizes around every block.
    #[test]
    fn the_packed_norm_gives_the_bits_of_its_loop() {
        for n in (0..23usize).chain([31, 64, 101]) {
            let packed: Vec<f64> = (0..n * (n + 1) / 2)
                .map(|i| libm::sin(0.37 * i as f64 + 0.1) * 10f64.powi(i as i32 % 5 - 2))
                .collect();
            let k: Vec<f64> = (0..n).map(|i| libm::cos(0.7 * i as f64) + 0.2).collect();
            let got = lower_packed_norm2(&packed, &k);
            let plain = lower_packed_norm2_from(&packed, &k, 0, [0.0; 4]);
            assert_eq!(got.to_bits(), plain.to_bits(), "n = {n}");
            let mut tk = vec![0.0; n];
            lower_packed_times(&packed, &k, &mut tk);
            let want: f64 = tk.iter().map(|v| v * v).sum();
            assert!(
                (got - want).abs() <= 1e-13 * want.max(1.0),
                "n = {n}: {got} {want}"
            );
            // A short factor counts the rows it has.
            let short = lower_packed_norm2(&packed[..packed.len().saturating_sub(1)], &k);
            assert!(short.is_finite());
        }
    }

    /// `T k` and `T^T v` against the textbook double loop on every size around the four-row
    /// blocks. `T^T v` sums each entry's terms in row order, as the loop does: the same bits.
    #[test]
    fn triangular_products_match_the_textbook_loops() {
        for n in (0..23usize).chain([64, 101, 128]) {
            let packed: Vec<f64> = (0..n * (n + 1) / 2)
                .map(|i| libm::sin(0.37 * i as f64 + 0.1) * 10f64.powi(i as i32 % 5 - 2))
                .collect();
            let k: Vec<f64> = (0..n).map(|i| libm::cos(0.7 * i as f64) + 0.2).collect();
            let t = |i: usize, j: usize| packed[i * (i + 1) / 2 + j];
            let mut out = vec![f64::NAN; n];
            lower_packed_times(&packed, &k, &mut out);
            for i in 0..n {
                let (mut want, mut scale) = (0.0, 0.0);
                for j in 0..=i {
                    want += t(i, j) * k[j];
                    scale += (t(i, j) * k[j]).abs();
                }
                assert!(
                    (out[i] - want).abs() <= 1e-14 * scale,
                    "T k, n = {n}, row {i}: {} against {want}",
                    out[i]
                );
            }
            let mut out = vec![f64::NAN; n];
            lower_packed_transpose_times(&packed, &k, &mut out);
            for j in 0..n {
                let mut want = 0.0;
                for i in j..n {
                    want += t(i, j) * k[i];
                }
                assert_eq!(
                    out[j].to_bits(),
                    want.to_bits(),
                    "T^T v, n = {n}, entry {j}"
                );
            }
        }
    }

    #[test]
    fn forward_substitution_matches_the_textbook_loop() {
        // Every size around the four-row blocks, a well-conditioned factor.
        for n in 0..23usize {
            let mut packed = vec![0.0; n * (n + 1) / 2];
            for i in 0..n {
                for j in 0..=i {
                    let t = (i * 7 + j * 3) as f64;
                    packed[i * (i + 1) / 2 + j] = if i == j {
                        2.0 + 0.1 * libm::sin(t)
                    } else {
                        0.3 * libm::cos(t)
                    };
                }
            }
            let k: Vec<f64> = (0..n).map(|i| libm::sin(0.7 * i as f64) + 0.2).collect();
            let mut want = vec![0.0; n];
            for i in 0..n {
                let mut s = k[i];
                for j in 0..i {
                    s -= packed[i * (i + 1) / 2 + j] * want[j];
                }
                want[i] = s / packed[i * (i + 1) / 2 + i];
            }
            let mut got = vec![0.0; n];
            forward_substitute_packed(&packed, &k, &mut got).unwrap();
            for (g, w) in got.iter().zip(&want) {
                assert!(
                    (g - w).abs() <= 1e-13 * (1.0 + w.abs()),
                    "n = {n}: {g} vs {w}"
                );
            }
            // A factor one value short is an error, not a panic.
            if n > 0 {
                let e = forward_substitute_packed(&packed[..packed.len() - 1], &k, &mut got);
                assert!(e.is_err());
            }
        }
    }

    #[test]
    fn posterior_covariance_matches_the_dense_formula() {
        let std = |x: &[f64; 3]| [(x[0] - 0.1) / 1.5, (x[1] + 0.2) / 0.5, (x[2] - 0.3) / 2.0];
        for spec in all_specs() {
            let dense = setup(spec);
            let owned = dense.build(&W);
            let gp = view(&owned, spec, &W, dense.noise);
            let k = Kernel::new(spec, &owned.theta[..spec.n_params()], &W).unwrap();
            let (a, b) = ([0.4, 0.1, -0.2], [-0.3, 0.6, -0.5]);
            let (ga, gb) = (spec.direction_of(&a), spec.direction_of(&b));
            let k_support = |x: &[f64; 3], g: f64| -> [f64; 6] {
                core::array::from_fn(|i| k.eval(&std(&dense.x[i]), owned.dirs[i], &std(x), g))
            };
            // Dense: k(a, b) - k_a^T (K + s I)^{-1} k_b.
            let (ka, kb) = (k_support(&a, ga), k_support(&b, gb));
            let mut solved = [0.0; 6];
            forward_substitute_packed(&owned.packed, &kb, &mut solved).unwrap();
            back_substitute_packed(&owned.packed, &mut solved).unwrap();
            let want =
                k.eval(&std(&a), ga, &std(&b), gb) - (0..6).map(|i| ka[i] * solved[i]).sum::<f64>();
            let mut scratch = vec![0.0; gp.whiten_scratch()];
            let (mut w_a, mut w_b) = ([0.0; 6], [0.0; 6]);
            let var_a = gp.whiten(&a, &mut w_a, &mut scratch).unwrap();
            gp.whiten(&b, &mut w_b, &mut scratch).unwrap();
            let got = gp.posterior_covariance(&a, &w_a, &b, &w_b).unwrap();
            assert!((got - want).abs() < 1e-12, "{spec:?}: {got} vs {want}");
            assert!(want.abs() > 1e-3, "{spec:?}: the points are correlated");
            let own = gp.posterior_covariance(&a, &w_a, &a, &w_a).unwrap();
            assert!((own - var_a).abs() < 1e-12, "{spec:?}");
            let p = gp.predict(&a, Want::VARIANCE, &mut scratch).unwrap();
            assert_eq!(var_a, p.variance);
            // Wrong lengths are errors, not panics.
            assert!(gp.whiten(&a, &mut [0.0; 5], &mut scratch).is_err());
            assert!(gp.whiten(&a, &mut w_a, &mut [0.0; 3]).is_err());
            assert!(gp.posterior_covariance(&a[..2], &w_a, &b, &w_b).is_err());
            assert!(gp.posterior_covariance(&a, &w_a[..5], &b, &w_b).is_err());
        }
    }

    #[test]
    fn gradients_match_finite_differences() {
        for spec in all_specs() {
            let dense = setup(spec);
            let owned = dense.build(&W);
            let gp = view(&owned, spec, &W, dense.noise);
            let mut scratch = [0.0; 32];
            // Keep x[2] > x[0] across the perturbation so the direction sign is constant.
            let x0 = [0.4, 0.1, 0.9];
            let p = gp.predict(&x0, Want::ALL, &mut scratch).unwrap();
            for j in 0..3 {
                let h = 1e-6;
                let (mut a, mut b) = (x0, x0);
                a[j] += h;
                b[j] -= h;
                let pa = gp.predict(&a, Want::ALL, &mut scratch).unwrap();
                let pb = gp.predict(&b, Want::ALL, &mut scratch).unwrap();
                let fd_m = (pa.mean - pb.mean) / (2.0 * h);
                let fd_v = (pa.variance - pb.variance) / (2.0 * h);
                assert!(
                    (fd_m - p.grad_mean[j]).abs() < 1e-7 * (1.0 + fd_m.abs()),
                    "{spec:?} mean j={j}: {fd_m} vs {}",
                    p.grad_mean[j]
                );
                assert!(
                    (fd_v - p.grad_variance[j]).abs() < 1e-7 * (1.0 + fd_v.abs()),
                    "{spec:?} var j={j}: {fd_v} vs {}",
                    p.grad_variance[j]
                );
            }
        }
    }

    /// A GP wider than the passes compiled per dimension (a vector model's transition) predicts
    /// the dense formulae' mean and variance, and its gradients agree with finite differences.
    #[test]
    fn a_wide_gp_matches_the_dense_formulae_and_finite_differences() {
        const D: usize = 14;
        const N: usize = 9;
        for profile in [Profile::SquaredExponential, Profile::Matern52] {
            let spec = KernelSpec {
                profile,
                ..KernelSpec::se_ard(D)
            };
            let theta: [f64; D + 1] = core::array::from_fn(|i| 0.3 * libm::sin(1.7 * i as f64));
            let k = Kernel::new(spec, &theta, &[]).unwrap();
            let xs: [[f64; D]; N] = core::array::from_fn(|i| {
                core::array::from_fn(|j| libm::sin(0.9 * i as f64 + 0.4 * j as f64))
            });
            let y: [f64; N] = core::array::from_fn(|i| libm::cos(0.7 * i as f64));
            let noise = 0.05;
            let mut kk = [[0.0; N]; N];
            for i in 0..N {
                for j in 0..N {
                    kk[i][j] = k.eval(&xs[i], 0.0, &xs[j], 0.0);
                }
                kk[i][i] += noise;
            }
            // Cholesky, packed.
            let mut l = [[0.0; N]; N];
            for i in 0..N {
                for j in 0..=i {
                    let mut acc = kk[i][j];
                    for m in 0..j {
                        acc -= l[i][m] * l[j][m];
                    }
                    l[i][j] = if i == j { acc.sqrt() } else { acc / l[j][j] };
                }
            }
            let mut packed = [0.0; N * (N + 1) / 2];
            for i in 0..N {
                for j in 0..=i {
                    packed[i * (i + 1) / 2 + j] = l[i][j];
                }
            }
            let alpha = spd_solve(&kk, &y);
            let mut feats = [0.0; N * D];
            for i in 0..N {
                let mut u = [0.0; MAX_DIM];
                let mut jac = [0.0; FEATURE_JACOBIAN_LEN];
                k.features(&xs[i], &mut u, &mut jac);
                feats[i * D..i * D + D].copy_from_slice(&u[..D]);
            }
            let (mean0, scale1) = ([0.0; D], [1.0; D]);
            let gp = GpView::new(GpParts {
                kernel: k,
                input_mean: &mean0,
                input_scale: &scale1,
                output_mean: 0.0,
                output_scale: 1.0,
                linear: &[],
                features: &feats,
                directions: &[],
                alpha: &alpha,
                alpha_lo: &[],
                variance: Variance::Exact {
                    chol_packed: &packed,
                },
                noise_var: noise,
            })
            .unwrap();
            let mut scratch = [0.0; 4 * N];
            let x0: [f64; D] = core::array::from_fn(|j| 0.2 * libm::cos(1.1 * j as f64));
            let p = gp.predict(&x0, Want::ALL, &mut scratch).unwrap();
            let kstar: [f64; N] = core::array::from_fn(|i| k.eval(&x0, 0.0, &xs[i], 0.0));
            let mean: f64 = kstar.iter().zip(&alpha).map(|(a, b)| a * b).sum();
            let v = spd_solve(&kk, &kstar);
            let var =
                k.eval(&x0, 0.0, &x0, 0.0) - kstar.iter().zip(&v).map(|(a, b)| a * b).sum::<f64>();
            assert!((p.mean - mean).abs() < 1e-12, "{profile:?}");
            assert!((p.variance - var).abs() < 1e-12, "{profile:?}");
            for j in 0..D {
                let h = 1e-6;
                let (mut a, mut b) = (x0, x0);
                a[j] += h;
                b[j] -= h;
                let pa = gp.predict(&a, Want::ALL, &mut scratch).unwrap();
                let pb = gp.predict(&b, Want::ALL, &mut scratch).unwrap();
                let fd_m = (pa.mean - pb.mean) / (2.0 * h);
                let fd_v = (pa.variance - pb.variance) / (2.0 * h);
                assert!(
                    (fd_m - p.grad_mean[j]).abs() < 1e-7 * (1.0 + fd_m.abs()),
                    "{profile:?} j={j}"
                );
                assert!(
                    (fd_v - p.grad_variance[j]).abs() < 1e-7 * (1.0 + fd_v.abs()),
                    "{profile:?} j={j}"
                );
            }
            // Without gradients the mean is bit-identical.
            let q = gp.predict(&x0, Want::default(), &mut scratch).unwrap();
            assert_eq!(q.mean.to_bits(), p.mean.to_bits());
            let m = gp.predict_mean(&x0, &mut scratch).unwrap();
            assert_eq!(m.to_bits(), p.mean.to_bits());
        }
    }

    /// A linear prior mean adds `w . (x - input_mean)` to the mean and `w` to its gradient,
    /// and leaves the variance alone; a slope count other than 0 or `d` is refused.
    #[test]
    fn linear_mean_adds_its_plane_and_slopes() {
        let spec = KernelSpec::se_ard(3);
        let dense = setup(spec);
        let owned = dense.build(&W);
        let plain = view(&owned, spec, &W, dense.noise);
        let slopes = [0.7, -1.3, 0.25];
        let tilted = GpView::new(GpParts {
            linear: &slopes,
            ..plain.parts()
        })
        .unwrap();
        let mut scratch = [0.0; 32];
        let x0 = [0.4, 0.1, 0.9];
        let p = plain.predict(&x0, Want::ALL, &mut scratch).unwrap();
        let q = tilted.predict(&x0, Want::ALL, &mut scratch).unwrap();
        let plane: f64 = (0..3).map(|j| slopes[j] * (x0[j] - owned.mean[j])).sum();
        assert!((q.mean - (p.mean + plane)).abs() < 1e-12);
        assert_eq!(q.variance, p.variance);
        for j in 0..3 {
            assert!((q.grad_mean[j] - (p.grad_mean[j] + slopes[j])).abs() < 1e-12);
            assert_eq!(q.grad_variance[j], p.grad_variance[j]);
            let h = 1e-6;
            let (mut a, mut b) = (x0, x0);
            a[j] += h;
            b[j] -= h;
            let fd = (tilted.predict(&a, Want::MEAN, &mut scratch).unwrap().mean
                - tilted.predict(&b, Want::MEAN, &mut scratch).unwrap().mean)
                / (2.0 * h);
            assert!((fd - q.grad_mean[j]).abs() < 1e-7 * (1.0 + fd.abs()));
        }
        assert!(matches!(
            GpView::new(GpParts {
                linear: &slopes[..2],
                ..plain.parts()
            }),
            Err(CoreError::DimensionMismatch {
                expected: 3,
                got: 2
            })
        ));
        assert!(matches!(
            GpView::new(GpParts {
                linear: &[0.0, f64::NAN, 0.0],
                ..plain.parts()
            }),
            Err(CoreError::NonFinite)
        ));
    }

    #[test]
    fn bad_calls_return_errors() {
        let spec = KernelSpec::se_ard(3);
        let dense = setup(spec);
        let owned = dense.build(&W);
        let gp = view(&owned, spec, &W, dense.noise);
        let mut small = [0.0; 3];
        assert!(matches!(
            gp.predict(&[0.0; 3], Want::ALL, &mut small),
            Err(CoreError::ScratchTooSmall { .. })
        ));
        let mut scratch = [0.0; 32];
        assert!(matches!(
            gp.predict(&[0.0; 2], Want::ALL, &mut scratch),
            Err(CoreError::DimensionMismatch { .. })
        ));
        assert!(matches!(
            gp.predict(&[0.0, f64::NAN, 0.0], Want::ALL, &mut scratch),
            Err(CoreError::NonFinite)
        ));
        assert_eq!(gp.predict_scratch(Want::default()), 6);
        assert_eq!(predict_scratch(6, true, Want::ALL), 24);
        assert_eq!(gp.predict_scratch(Want::EKF), 12);
        assert_eq!(gp.predict_scratch(Want::ALL), 18);
    }

    /// Solves `M x = b` for a small symmetric positive definite `M` (test only).
    fn spd_solve<const N: usize>(m: &[[f64; N]; N], b: &[f64; N]) -> [f64; N] {
        let mut l = [[0.0; N]; N];
        for i in 0..N {
            for j in 0..=i {
                let mut s = m[i][j];
                for k in 0..j {
                    s -= l[i][k] * l[j][k];
                }
                l[i][j] = if i == j { s.sqrt() } else { s / l[j][j] };
            }
        }
        let mut y = [0.0; N];
        for i in 0..N {
            let s: f64 = (0..i).map(|k| l[i][k] * y[k]).sum();
            y[i] = (b[i] - s) / l[i][i];
        }
        let mut x = [0.0; N];
        for i in (0..N).rev() {
            let s: f64 = (i + 1..N).map(|k| l[k][i] * x[k]).sum();
            x[i] = (y[i] - s) / l[i][i];
        }
        x
    }

    fn chol3(a: &[[f64; 3]; 3]) -> [[f64; 3]; 3] {
        let mut l = [[0.0; 3]; 3];
        for i in 0..3 {
            for j in 0..=i {
                let mut s = a[i][j];
                for k in 0..j {
                    s -= l[i][k] * l[j][k];
                }
                l[i][j] = if i == j { s.sqrt() } else { s / l[j][j] };
            }
        }
        l
    }

    /// A sparse GP on 3 inducing points built densely from 6 samples: the view's packed-factor
    /// predictions must equal the textbook formulas `mean = k^T Sigma K_mn y / s2`,
    /// `var = kss - k^T K_mm^{-1} k + k^T Sigma k` computed by solves.
    #[test]
    fn sparse_view_matches_dense_formulae_and_fd_gradients() {
        for spec in all_specs() {
            let dense = setup(spec);
            let n_p = spec.n_params();
            let k = Kernel::new(spec, &dense.theta[..n_p], &W).unwrap();
            let mean = [0.1, -0.2, 0.3];
            let scale = [1.5, 0.5, 2.0];
            let std = |x: &[f64; 3]| -> [f64; 3] {
                core::array::from_fn(|j| (x[j] - mean[j]) / scale[j])
            };
            let zx: [[f64; 3]; 3] = [[0.2, 0.5, -0.1], [-0.6, 0.9, 0.7], [0.8, -0.3, 1.2]];
            let zg: [f64; 3] = core::array::from_fn(|i| spec.direction_of(&zx[i]));
            let xg: [f64; 6] = core::array::from_fn(|i| spec.direction_of(&dense.x[i]));
            let s2 = dense.noise;
            let kz = |a: usize, b: usize| k.eval(&std(&zx[a]), zg[a], &std(&zx[b]), zg[b]);
            let kzx = |a: usize, n: usize| k.eval(&std(&zx[a]), zg[a], &std(&dense.x[n]), xg[n]);
            let kmm: [[f64; 3]; 3] = core::array::from_fn(|a| core::array::from_fn(|b| kz(a, b)));
            let mut sig_inv = kmm;
            let mut kmn_y = [0.0; 3];
            for a in 0..3 {
                for b in 0..3 {
                    sig_inv[a][b] += (0..6).map(|n| kzx(a, n) * kzx(b, n)).sum::<f64>() / s2;
                }
                kmn_y[a] = (0..6).map(|n| kzx(a, n) * dense.y[n]).sum::<f64>();
            }
            let beta = spd_solve(&sig_inv, &kmn_y).map(|v| v / s2);
            // The folded factor: R lower-triangular with R^T R = W = K_mm^{-1} - Sigma, from
            // the reversed Cholesky factor G of J W J (J the reversal): R = J G^T J.
            let unit =
                |c: usize| -> [f64; 3] { core::array::from_fn(|i| f64::from(u8::from(i == c))) };
            let kinv_cols: [[f64; 3]; 3] = core::array::from_fn(|c| spd_solve(&kmm, &unit(c)));
            let sig_cols: [[f64; 3]; 3] = core::array::from_fn(|c| spd_solve(&sig_inv, &unit(c)));
            let jwj: [[f64; 3]; 3] = core::array::from_fn(|i| {
                core::array::from_fn(|j| kinv_cols[2 - j][2 - i] - sig_cols[2 - j][2 - i])
            });
            let g = chol3(&jwj);
            let mut r_packed = [0.0; 6];
            for i in 0..3 {
                for j in 0..=i {
                    r_packed[i * (i + 1) / 2 + j] = g[2 - j][2 - i];
                }
            }
            let mut feats = [0.0; 9];
            for i in 0..3 {
                let mut u = [0.0; MAX_DIM];
                let mut jac = [0.0; FEATURE_JACOBIAN_LEN];
                k.features(&std(&zx[i]), &mut u, &mut jac);
                feats[i * 3..i * 3 + 3].copy_from_slice(&u[..3]);
            }
            let gp = GpView::new(GpParts {
                kernel: k,
                input_mean: &mean,
                input_scale: &scale,
                output_mean: 0.0,
                output_scale: 1.0,
                linear: &[],
                features: &feats,
                directions: if spec.direction.is_some() { &zg } else { &[] },
                alpha: &beta,
                alpha_lo: &[],
                variance: Variance::Sparse {
                    variance_factor: &r_packed,
                },
                noise_var: s2,
            })
            .unwrap();
            assert!(gp.is_sparse());
            let mut scratch = [0.0; 32];
            let x0 = [0.4, 0.1, 0.9];
            let p = gp.predict(&x0, Want::ALL, &mut scratch).unwrap();
            let zs = std(&x0);
            let gs = spec.direction_of(&x0);
            let ks: [f64; 3] = core::array::from_fn(|a| k.eval(&std(&zx[a]), zg[a], &zs, gs));
            let want_mean: f64 = (0..3).map(|a| ks[a] * beta[a]).sum();
            let kinv_k = spd_solve(&kmm, &ks);
            let sig_k = spd_solve(&sig_inv, &ks);
            let want_var = k.eval(&zs, gs, &zs, gs)
                - (0..3).map(|a| ks[a] * kinv_k[a]).sum::<f64>()
                + (0..3).map(|a| ks[a] * sig_k[a]).sum::<f64>();
            assert!((p.mean - want_mean).abs() < 1e-10, "{spec:?}");
            assert!(
                (p.variance - want_var).abs() < 1e-10,
                "{spec:?}: {} vs {want_var}",
                p.variance
            );
            for j in 0..3 {
                let h = 1e-6;
                let (mut a, mut b) = (x0, x0);
                a[j] += h;
                b[j] -= h;
                let pa = gp.predict(&a, Want::ALL, &mut scratch).unwrap();
                let pb = gp.predict(&b, Want::ALL, &mut scratch).unwrap();
                let fd_m = (pa.mean - pb.mean) / (2.0 * h);
                let fd_v = (pa.variance - pb.variance) / (2.0 * h);
                assert!((fd_m - p.grad_mean[j]).abs() < 1e-7 * (1.0 + fd_m.abs()));
                assert!(
                    (fd_v - p.grad_variance[j]).abs() < 1e-7 * (1.0 + fd_v.abs()),
                    "{spec:?} var j={j}: {fd_v} vs {}",
                    p.grad_variance[j]
                );
            }
            // Posterior covariance with a second input: k(a, b) - k_a^T (K_mm^{-1} - Sigma) k_b.
            let x1 = [-0.2, 0.7, 0.3];
            let (z1, g1) = (std(&x1), spec.direction_of(&x1));
            let k1: [f64; 3] = core::array::from_fn(|a| k.eval(&std(&zx[a]), zg[a], &z1, g1));
            let want_cov = k.eval(&zs, gs, &z1, g1)
                - (0..3).map(|a| ks[a] * spd_solve(&kmm, &k1)[a]).sum::<f64>()
                + (0..3)
                    .map(|a| ks[a] * spd_solve(&sig_inv, &k1)[a])
                    .sum::<f64>();
            let (mut w0, mut w1) = ([0.0; 3], [0.0; 3]);
            gp.whiten(&x0, &mut w0, &mut scratch).unwrap();
            gp.whiten(&x1, &mut w1, &mut scratch).unwrap();
            let cov = gp.posterior_covariance(&x0, &w0, &x1, &w1).unwrap();
            assert!(
                (cov - want_cov).abs() < 1e-10,
                "{spec:?}: {cov} vs {want_cov}"
            );
            // Every `Want` gives the same numbers as `Want::ALL` where it computes them.
            let e = gp.predict(&x0, Want::EKF, &mut scratch).unwrap();
            assert_eq!(e.variance, p.variance);
            assert_eq!(e.grad_mean, p.grad_mean);
        }
    }
}
