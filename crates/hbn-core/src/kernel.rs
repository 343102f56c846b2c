//! Covariance functions of the thesis (Sec. 2.2, 3.3; Eqs. 5, 17, 18, 19) and Matern 5/2.
//!
//! A kernel here is a composition, evaluated in this order on a *standardised* input `x`:
//!
//! 1. optional **tanh input warping** (Eq. 18), per input `j`:
//!    `phi_j(x_j) = sum_i b_ji tanh(x_j + a_ji)` (`b_ji > 0`, so `phi_j` is monotone). The
//!    thesis' additive `c_j` cancels in every stationary kernel (only differences
//!    `phi(x) - phi(x')` enter), so it is not a hyperparameter: its likelihood gradient is
//!    identically zero;
//! 2. a **metric** giving the squared distance `r2 = (p - p')^T M (p - p')`:
//!    isotropic `M = I / l^2`, ARD `M = diag(1 / l_j^2)`, or Mahalanobis (Eq. 17)
//!    `M = (c S)^{-1}` with `S` the empirical covariance of the (standardised) training inputs,
//!    fixed at training time, and `c` a learned scale;
//! 3. a **profile** `f(r2)`: squared exponential `exp(-r2 / 2)` (Eq. 5) or Matern 5/2;
//! 4. the signal variance `s_f^2` and, optionally, the **direction-advantage factor** (Eq. 19)
//!    `1/2 (1 + g g')`, where `g = sgn(x_raw[a] - x_raw[b])` is the direction in which the
//!    hysteresis input moves at that sample.
//!
//! `k(x, x') = s_f^2 * f(r2) * D(g, g')`.
//!
//! Hyperparameters live in one slice `theta`, in this order (positive quantities as logs):
//! `[ln s_f^2, metric..., a_11..a_dm, ln b_11..ln b_dm]` with metric = `[ln l]` (isotropic),
//! `[ln l_1..ln l_d]` (ARD) or `[ln c]` (Mahalanobis). See [`KernelSpec::n_params`].
//!
//! Because `r2 = |L (p - p')|^2` with `M = L^T L`, prediction works on *features*
//! `u = L phi(x)` computed once per support point ([`Kernel::features`]); training works on
//! [`Prepared`] points that carry what the hyperparameter gradients need.

use crate::CoreError;

/// Largest number of GP inputs the allocation-free code supports (a vector model's transition
/// reads `2 dx + 2 du` values plus the memory of every input).
pub const MAX_DIM: usize = 32;
/// Largest number of inputs of a kernel whose features mix or warp its inputs (tanh warping or
/// the Mahalanobis metric): their feature Jacobian is a dense `d x d` matrix. Kernels with a
/// diagonal metric and no warping take up to [`MAX_DIM`] inputs.
pub const MAX_DENSE_DIM: usize = 8;
/// Length of the feature-Jacobian buffer of [`Kernel::features`] (see
/// [`feature_jacobian_entry`] for its layout).
pub const FEATURE_JACOBIAN_LEN: usize = MAX_DENSE_DIM * MAX_DENSE_DIM;
/// Largest number of tanh units per input in the warping.
pub const MAX_WARP_UNITS: usize = 4;

/// Entry `du_r / dx_c` of a feature Jacobian written by [`Kernel::features`] for a kernel of
/// `d` inputs: row-major `d x d` up to [`MAX_DENSE_DIM`] inputs, diagonal above.
#[inline]
pub fn feature_jacobian_entry(
    du_dx: &[f64; FEATURE_JACOBIAN_LEN],
    d: usize,
    r: usize,
    c: usize,
) -> f64 {
    if d <= MAX_DENSE_DIM {
        at(du_dx, r * d + c)
    } else if r == c {
        at(du_dx, r)
    } else {
        0.0
    }
}

const SQRT5: f64 = 2.236_067_977_499_79;

/// The radial profile `f(r2)` of a stationary kernel.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
#[cfg_attr(feature = "serde", serde(rename_all = "kebab-case"))]
pub enum Profile {
    /// Squared exponential, `exp(-r2 / 2)` (thesis Eq. 5).
    SquaredExponential,
    /// Matern 5/2, `(1 + sqrt5 r + 5/3 r^2) exp(-sqrt5 r)` with `r = sqrt(r2)`.
    Matern52,
}

/// How squared distances are measured.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
#[cfg_attr(feature = "serde", serde(rename_all = "kebab-case"))]
pub enum Metric {
    /// One length scale for all inputs.
    Isotropic,
    /// One length scale per input (automatic relevance determination).
    Ard,
    /// `(c S)^{-1}` with `S` the empirical input covariance (thesis Eq. 17) and a learned `c`.
    Mahalanobis,
}

/// The structure of a kernel: everything but the hyperparameter values.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
#[cfg_attr(feature = "serde", serde(rename_all = "kebab-case"))]
pub struct KernelSpec {
    /// Radial profile.
    pub profile: Profile,
    /// Distance metric.
    pub metric: Metric,
    /// Number of inputs (1..=[`MAX_DIM`]).
    pub dim: usize,
    /// tanh units per input in the warping; 0 disables warping (0..=[`MAX_WARP_UNITS`]).
    pub warp_units: usize,
    /// Direction-advantage factor: `Some([a, b])` uses `g = sgn(x_raw[a] - x_raw[b])`.
    pub direction: Option<[usize; 2]>,
}

impl KernelSpec {
    /// ARD squared exponential on `dim` inputs, no warping, no direction factor.
    pub const fn se_ard(dim: usize) -> Self {
        Self {
            profile: Profile::SquaredExponential,
            metric: Metric::Ard,
            dim,
            warp_units: 0,
            direction: None,
        }
    }

    /// Checks the structure once, before anything uses it.
    pub fn validate(&self) -> Result<(), CoreError> {
        if self.dim == 0 || self.dim > MAX_DIM {
            return Err(CoreError::InvalidSpec("dim must be in 1..=MAX_DIM (32)"));
        }
        if (self.warp_units > 0 || self.metric == Metric::Mahalanobis) && self.dim > MAX_DENSE_DIM {
            return Err(CoreError::InvalidSpec(
                "a warped or Mahalanobis kernel takes at most MAX_DENSE_DIM (8) inputs",
            ));
        }
        if self.warp_units > MAX_WARP_UNITS {
            return Err(CoreError::InvalidSpec(
                "warp_units must be in 0..=MAX_WARP_UNITS (4)",
            ));
        }
        if let Some([a, b]) = self.direction
            && (a >= self.dim || b >= self.dim || a == b)
        {
            return Err(CoreError::InvalidSpec(
                "direction indices must be two different inputs < dim",
            ));
        }
        Ok(())
    }

    /// Number of metric hyperparameters.
    pub const fn n_metric(&self) -> usize {
        match self.metric {
            Metric::Isotropic | Metric::Mahalanobis => 1,
            Metric::Ard => self.dim,
        }
    }

    /// Total number of hyperparameters (the length of `theta`).
    pub const fn n_params(&self) -> usize {
        1 + self.n_metric() + 2 * self.dim * self.warp_units
    }

    /// Index of the first warp shift `a_11` in `theta`.
    pub const fn warp_a_offset(&self) -> usize {
        1 + self.n_metric()
    }

    /// Index of the first warp log-gain `ln b_11` in `theta`.
    pub const fn warp_b_offset(&self) -> usize {
        self.warp_a_offset() + self.dim * self.warp_units
    }

    /// Direction sign of a raw input vector: `sgn(x[a] - x[b])`, or 0 without the factor.
    #[inline]
    pub fn direction_of(&self, x_raw: &[f64]) -> f64 {
        match self.direction {
            Some([a, b]) => match (x_raw.get(a), x_raw.get(b)) {
                (Some(xa), Some(xb)) => sign(xa - xb),
                _ => 0.0,
            },
            None => 0.0,
        }
    }

    /// The direction factor `1/2 (1 + g g')`, or 1 without it.
    #[inline]
    pub fn direction_factor(&self, g1: f64, g2: f64) -> f64 {
        if self.direction.is_some() {
            0.5 * (1.0 + g1 * g2)
        } else {
            1.0
        }
    }

    /// A reasonable starting `theta` for standardised data (all length scales 1, unit
    /// variance, identity-like warping). Writes `n_params()` values.
    pub fn default_theta(&self, theta: &mut [f64]) -> Result<(), CoreError> {
        check_len(theta.len(), self.n_params())?;
        theta.fill(0.0);
        let m = self.warp_units;
        if m > 0 {
            // Units spread over [-1.5, 1.5] with gains summing to ~1.
            for j in 0..self.dim {
                for i in 0..m {
                    let a = if m == 1 {
                        0.0
                    } else {
                        -1.5 + 3.0 * i as f64 / (m - 1) as f64
                    };
                    set(theta, self.warp_a_offset() + j * m + i, a);
                    set(
                        theta,
                        self.warp_b_offset() + j * m + i,
                        libm::log(1.0 / m as f64),
                    );
                }
            }
        }
        Ok(())
    }
}

#[inline]
fn sign(v: f64) -> f64 {
    if v > 0.0 {
        1.0
    } else if v < 0.0 {
        -1.0
    } else {
        0.0
    }
}

/// `s[i]`, or 0 out of range (never after validation: the callers checked the lengths).
#[inline(always)]
pub(crate) fn at(s: &[f64], i: usize) -> f64 {
    s.get(i).copied().unwrap_or(0.0)
}

/// `s[i] = v`, ignored out of range (never after validation).
#[inline(always)]
pub(crate) fn set(s: &mut [f64], i: usize, v: f64) {
    if let Some(x) = s.get_mut(i) {
        *x = v;
    }
}

/// `v` clamped to `[lo, hi]` like `f64::clamp` (same result whenever `lo <= hi`), but with no
/// panic when `lo > hi` or a bound is NaN: then it returns `hi` when `v > hi`, else `lo` when
/// `v < lo`, else `v` (NaN stays NaN).
#[inline(always)]
pub(crate) fn clamp_to(v: f64, lo: f64, hi: f64) -> f64 {
    let mut x = v;
    if x < lo {
        x = lo;
    }
    if x > hi {
        x = hi;
    }
    x
}

#[inline]
fn check_len(got: usize, expected: usize) -> Result<(), CoreError> {
    if got == expected {
        Ok(())
    } else {
        Err(CoreError::DimensionMismatch { expected, got })
    }
}

/// Profile value `f(r2)` and its derivative `df/dr2`.
#[inline(always)]
pub fn profile_and_slope(profile: Profile, r2: f64) -> (f64, f64) {
    profile_and_slope_with(profile, r2, crate::simd::sqrt)
}

/// [`profile_and_slope`] for many squared distances at once: `f[i]` and `df[i]` from `r2[i]`,
/// for `i` below the shortest of the three lengths. The square roots go first, then one
/// branch-free loop that the compiler vectorises: the estimator step's prediction and
/// training's kernel blocks run through here.
#[inline(always)]
pub fn profiles_and_slopes(profile: Profile, r2: &[f64], f: &mut [f64], df: &mut [f64]) {
    profiles_and_slopes_with(profile, r2, f, df, crate::simd::sqrt)
}

/// [`profiles_and_slopes`] with the caller's square root: training on a host passes
/// `f64::sqrt`, which the compiler vectorises (`libm`'s is one scalar instruction in inline
/// assembly, and takes a fifth of a sparse training run's kernel blocks).
#[inline(always)]
pub fn profiles_and_slopes_with(
    profile: Profile,
    r2: &[f64],
    f: &mut [f64],
    df: &mut [f64],
    sqrt: impl Fn(f64) -> f64,
) {
    match profile {
        Profile::SquaredExponential => {
            for ((r2_i, f_i), df_i) in r2.iter().zip(f.iter_mut()).zip(df.iter_mut()) {
                let e = exp_nonpositive(-0.5 * r2_i);
                *f_i = e;
                *df_i = -0.5 * e;
            }
        }
        Profile::Matern52 => {
            // `f` holds r = sqrt(r2) until the second loop overwrites it.
            for (r_i, r2_i) in f.iter_mut().zip(r2) {
                *r_i = sqrt(if *r2_i > 0.0 { *r2_i } else { 0.0 });
            }
            for ((r2_i, f_i), df_i) in r2.iter().zip(f.iter_mut()).zip(df.iter_mut()) {
                let (value, lin, e) = matern52(*f_i, *r2_i);
                *f_i = value;
                *df_i = -(5.0 / 6.0) * lin * e;
            }
        }
    }
}

/// The profile values of [`profiles_and_slopes`] without the slopes, computed by the same
/// operations (so bit-identical to its `f`): a mean-only prediction needs no slope.
#[inline(always)]
pub fn profiles(profile: Profile, r2: &[f64], f: &mut [f64]) {
    match profile {
        Profile::SquaredExponential => {
            for (r2_i, f_i) in r2.iter().zip(f.iter_mut()) {
                *f_i = exp_nonpositive(-0.5 * r2_i);
            }
        }
        Profile::Matern52 => {
            for (r_i, r2_i) in f.iter_mut().zip(r2) {
                *r_i = crate::simd::sqrt(if *r2_i > 0.0 { *r2_i } else { 0.0 });
            }
            for (r2_i, f_i) in r2.iter().zip(f.iter_mut()) {
                *f_i = matern52(*f_i, *r2_i).0;
            }
        }
    }
}

/// Matern 5/2 at `r = sqrt(r2)`: the profile `(1 + sqrt5 r + 5/3 r2) exp(-sqrt5 r)`, and the
/// two factors its slope `-(5/6) (1 + sqrt5 r) exp(-sqrt5 r)` reuses. One formula for
/// [`profiles_and_slopes_with`] and [`profiles`], so their values agree to the bit.
#[inline(always)]
fn matern52(r: f64, r2: f64) -> (f64, f64, f64) {
    let e = exp_nonpositive(-SQRT5 * r);
    let lin = 1.0 + SQRT5 * r;
    ((lin + (5.0 / 3.0) * r2) * e, lin, e)
}

/// Most negative argument [`exp_nonpositive`] resolves; below it the result is `exp(EXP_FLOOR)`
/// (about `3e-308`), which no kernel value can tell from zero.
pub const EXP_FLOOR: f64 = -708.0;

/// `exp(x)` for the kernels' non-positive arguments, within 2 ulp of the correctly rounded
/// value on `[EXP_FLOOR, 0]`; arguments below `EXP_FLOOR` give `exp(EXP_FLOOR)`, positive
/// ones `1`.
///
/// Straight-line code (no branches, no table), so a loop over support points vectorises
/// (`libm::exp` in its place takes a third of a sparse m = 64 estimator step, 128 calls per
/// step). The method is Cody and Waite's: `x = k ln 2 + r` with `|r| <= ln 2 / 2`,
/// `k` rounded to nearest by adding and subtracting `1.5 * 2^52` (whose bit pattern then
/// holds `k`), `exp(r) = 1 + r + r^2 q(r)` with a degree-9 polynomial `q` (error below
/// `2e-17` relative), and `2^k` assembled in the exponent bits.
#[inline(always)]
pub fn exp_nonpositive(x: f64) -> f64 {
    const LOG2E: f64 = core::f64::consts::LOG2_E;
    // ln 2 split so that `k * LN2_HI` is exact for |k| < 2^20 (the high part has 33 bits).
    const LN2_HI: f64 = 6.931_471_803_691_238e-1;
    const LN2_LO: f64 = 1.908_214_929_270_587_7e-10;
    const ROUND: f64 = 6_755_399_441_055_744.0; // 1.5 * 2^52
    // `q(r) = (exp(r) - 1 - r) / r^2` on [-ln 2 / 2, ln 2 / 2] to 1.3e-17 (a degree-9 Chebyshev
    // fit, `mpmath.chebyfit`, highest degree first); close to the Taylor terms 1/(j+2)!.
    const C: [f64; 10] = [
        2.510_037_583_256_123_4e-8,
        2.762_007_587_998_336_7e-7,
        2.755_726_848_031_002_4e-6,
        2.480_152_132_236_869_2e-5,
        1.984_126_986_304_054_5e-4,
        1.388_888_891_719_671_9e-3,
        8.333_333_333_330_065e-3,
        4.166_666_666_662_416_4e-2,
        1.666_666_666_666_666_9e-1,
        5.000_000_000_000_001e-1,
    ];
    let x = clamp_to(x, EXP_FLOOR, 0.0);
    let shifted = x * LOG2E + ROUND;
    let k = shifted - ROUND;
    let r = (x - k * LN2_HI) - k * LN2_LO;
    let mut p = 0.0;
    for c in C {
        p = p * r + c;
    }
    let e_r = 1.0 + r + r * r * p;
    // `shifted`'s low mantissa bits hold k in two's complement; k is in [-1022, 0] here.
    let k_int = shifted.to_bits().wrapping_sub(ROUND.to_bits());
    let scale = f64::from_bits(k_int.wrapping_add(1023) << 52);
    e_r * scale
}

/// [`profile_and_slope`] with the caller's `sqrt` (training on a host passes `f64::sqrt`):
/// the one-pair case of [`profiles_and_slopes_with`], which holds the formulas.
#[inline(always)]
pub fn profile_and_slope_with(profile: Profile, r2: f64, sqrt: impl Fn(f64) -> f64) -> (f64, f64) {
    let (mut f, mut df) = ([0.0], [0.0]);
    profiles_and_slopes_with(profile, &[r2], &mut f, &mut df, sqrt);
    (f[0], df[0])
}

/// A training point prepared for hyperparameter gradients: the warped input and the
/// derivatives of the warp with respect to its parameters and its input.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Prepared {
    /// `phi(x)` (equal to `x` without warping).
    pub p: [f64; MAX_DIM],
    /// `d phi_j / d a_ji`.
    pub dp_da: [[f64; MAX_WARP_UNITS]; MAX_DENSE_DIM],
    /// `d phi_j / d ln b_ji`.
    pub dp_db: [[f64; MAX_WARP_UNITS]; MAX_DENSE_DIM],
    /// `d phi_j / d x_j`.
    pub dp_dx: [f64; MAX_DIM],
    /// Direction sign `g` of this point.
    pub g: f64,
}

/// A kernel: a validated [`KernelSpec`] with borrowed hyperparameters.
#[derive(Clone, Copy, Debug)]
pub struct Kernel<'a> {
    spec: KernelSpec,
    theta: &'a [f64],
    /// Row-major `d x d` lower-triangular `W` with `W^T W = S^{-1}` (Mahalanobis only).
    whiten: &'a [f64],
    /// `s_f^2 = exp(theta_0)`, computed once: every prediction needs it.
    signal_variance: f64,
    /// The metric's per-input factor of `u = L p`, computed once from `theta`: `exp(-ln l)`
    /// (isotropic, every input), `exp(-ln l_j)` (ARD), `exp(-ln c / 2)` (Mahalanobis), for
    /// the first [`MAX_DENSE_DIM`] inputs ([`Kernel::scale`] computes the rest): a scalar
    /// model's kernels keep their size, and with them its firmware's memory.
    metric_scale: [f64; MAX_DENSE_DIM],
}

impl<'a> Kernel<'a> {
    /// Builds a kernel view, checking the slice lengths against the spec.
    ///
    /// `whiten` must hold `dim * dim` values for [`Metric::Mahalanobis`] and may be empty
    /// otherwise.
    pub fn new(spec: KernelSpec, theta: &'a [f64], whiten: &'a [f64]) -> Result<Self, CoreError> {
        spec.validate()?;
        check_len(theta.len(), spec.n_params())?;
        if spec.metric == Metric::Mahalanobis {
            check_len(whiten.len(), spec.dim * spec.dim)?;
        }
        if theta.iter().chain(whiten.iter()).any(|v| !v.is_finite()) {
            return Err(CoreError::NonFinite);
        }
        let mut metric_scale = [0.0; MAX_DENSE_DIM];
        for (j, s) in metric_scale.iter_mut().enumerate().take(spec.dim) {
            *s = match spec.metric {
                Metric::Isotropic => libm::exp(-at(theta, 1)),
                Metric::Ard => libm::exp(-at(theta, 1 + j)),
                Metric::Mahalanobis => libm::exp(-0.5 * at(theta, 1)),
            };
        }
        Ok(Self {
            spec,
            theta,
            whiten,
            signal_variance: libm::exp(at(theta, 0)),
            metric_scale,
        })
    }

    /// The metric's factor of input `j` in `u = L p` (ARD and isotropic metrics).
    #[inline(always)]
    fn scale(&self, j: usize) -> f64 {
        if j < MAX_DENSE_DIM {
            at(&self.metric_scale, j)
        } else {
            match self.spec.metric {
                Metric::Ard => libm::exp(-at(self.theta, 1 + j)),
                Metric::Isotropic | Metric::Mahalanobis => at(&self.metric_scale, 0),
            }
        }
    }

    /// The structure of this kernel.
    pub fn spec(&self) -> &KernelSpec {
        &self.spec
    }

    /// The hyperparameters (see the module docs for the layout).
    pub fn theta(&self) -> &'a [f64] {
        self.theta
    }

    /// The whitening matrix (Mahalanobis only; empty otherwise).
    pub fn whiten(&self) -> &'a [f64] {
        self.whiten
    }

    /// Signal variance `s_f^2`.
    #[inline]
    pub fn signal_variance(&self) -> f64 {
        self.signal_variance
    }

    /// Warps one standardised input: `p = phi(x)`, plus parameter and input derivatives.
    pub fn prepare(&self, x_std: &[f64], g: f64) -> Prepared {
        let d = self.spec.dim;
        let m = self.spec.warp_units;
        let mut out = Prepared {
            p: [0.0; MAX_DIM],
            dp_da: [[0.0; MAX_WARP_UNITS]; MAX_DENSE_DIM],
            dp_db: [[0.0; MAX_WARP_UNITS]; MAX_DENSE_DIM],
            dp_dx: [1.0; MAX_DIM],
            g,
        };
        if m == 0 {
            for (p_out, &x) in out.p.iter_mut().zip(x_std).take(d) {
                *p_out = x;
            }
            return out;
        }
        let rows = out
            .p
            .iter_mut()
            .zip(out.dp_dx.iter_mut())
            .zip(out.dp_da.iter_mut().zip(out.dp_db.iter_mut()));
        for (j, (&x, ((p_out, dx_out), (da, db)))) in x_std.iter().zip(rows).take(d).enumerate() {
            if m == 0 {
                *p_out = x;
                continue;
            }
            let (mut p, mut dx) = (0.0, 0.0);
            for i in 0..m {
                let a = at(self.theta, self.spec.warp_a_offset() + j * m + i);
                let b = libm::exp(at(self.theta, self.spec.warp_b_offset() + j * m + i));
                let t = libm::tanh(x + a);
                let sech2 = 1.0 - t * t;
                p += b * t;
                dx += b * sech2;
                set(da, i, b * sech2);
                set(db, i, b * t);
            }
            *p_out = p;
            *dx_out = dx;
        }
        out
    }

    /// Applies the metric factor `L` (with `M = L^T L`) to a warped point: `u = L p`.
    #[inline]
    fn apply_metric(&self, p: &[f64; MAX_DIM], u: &mut [f64; MAX_DIM]) {
        let d = self.spec.dim;
        match self.spec.metric {
            Metric::Isotropic | Metric::Ard if d <= MAX_DENSE_DIM => {
                for ((uj, pj), s) in u.iter_mut().zip(p).zip(&self.metric_scale).take(d) {
                    *uj = pj * s;
                }
            }
            Metric::Isotropic | Metric::Ard => {
                for (j, (uj, pj)) in u.iter_mut().zip(p).enumerate().take(d) {
                    *uj = pj * self.scale(j);
                }
            }
            Metric::Mahalanobis => {
                let s = self.metric_scale[0];
                for (r, ur) in u.iter_mut().take(d).enumerate() {
                    let mut acc = 0.0;
                    for (c, pc) in p.iter().take(d).enumerate() {
                        acc += at(self.whiten, r * d + c) * pc;
                    }
                    *ur = acc * s;
                }
            }
        }
    }

    /// `M v` for the metric matrix `M` (used by gradients).
    #[inline]
    fn metric_times(&self, v: &[f64; MAX_DIM], out: &mut [f64; MAX_DIM]) {
        let d = self.spec.dim;
        match self.spec.metric {
            Metric::Isotropic => {
                let s = libm::exp(-2.0 * at(self.theta, 1));
                for (oj, vj) in out.iter_mut().zip(v).take(d) {
                    *oj = vj * s;
                }
            }
            Metric::Ard => {
                for (j, (oj, vj)) in out.iter_mut().zip(v).take(d).enumerate() {
                    *oj = vj * libm::exp(-2.0 * at(self.theta, 1 + j));
                }
            }
            Metric::Mahalanobis => {
                // M = W^T W / c
                let s = libm::exp(-at(self.theta, 1));
                let mut wv = [0.0; MAX_DIM];
                for (r, wvr) in wv.iter_mut().take(d).enumerate() {
                    for (c, vc) in v.iter().take(d).enumerate() {
                        *wvr += at(self.whiten, r * d + c) * vc;
                    }
                }
                for (c, oc) in out.iter_mut().take(d).enumerate() {
                    let mut acc = 0.0;
                    for (r, wvr) in wv.iter().take(d).enumerate() {
                        acc += at(self.whiten, r * d + c) * wvr;
                    }
                    *oc = acc * s;
                }
            }
        }
    }

    /// Feature vector `u = L phi(x)` of a standardised input only (see [`Kernel::features`]).
    pub fn feature_vector(&self, x_std: &[f64], u: &mut [f64; MAX_DIM]) {
        let prep = self.prepare(x_std, 0.0);
        self.apply_metric(&prep.p, u);
    }

    /// Feature vector `u = L phi(x)` of a standardised input, so that `r2 = |u - u'|^2`,
    /// and the input Jacobian of the features `du_r / dx_c`, laid out as
    /// [`feature_jacobian_entry`] reads it: row-major `d x d` for `d <= MAX_DENSE_DIM`, its
    /// diagonal above (where [`KernelSpec::validate`] allows only diagonal metrics without
    /// warping).
    #[inline]
    pub fn features(
        &self,
        x_std: &[f64],
        u: &mut [f64; MAX_DIM],
        du_dx: &mut [f64; FEATURE_JACOBIAN_LEN],
    ) {
        let d = self.spec.dim;
        if d > MAX_DENSE_DIM {
            self.features_wide(x_std, u, du_dx);
            return;
        }
        if self.spec.warp_units == 0 && self.spec.metric != Metric::Mahalanobis {
            // No warping (`phi(x) = x`, slope 1) and a diagonal metric: what the general
            // path below computes, without preparing the warp's derivatives.
            let scales = u.iter_mut().zip(x_std).zip(&self.metric_scale);
            for (r, ((uj, x), s)) in scales.enumerate().take(d) {
                *uj = x * s;
                for c in 0..d {
                    set(du_dx, r * d + c, if r == c { *s } else { 0.0 });
                }
            }
            return;
        }
        let prep = self.prepare(x_std, 0.0);
        self.apply_metric(&prep.p, u);
        // du/dx = L diag(phi'(x)), entry by entry: `L` is diagonal (isotropic, ARD) or
        // `sqrt(1/c) W` (Mahalanobis).
        match self.spec.metric {
            Metric::Isotropic | Metric::Ard => {
                for r in 0..d {
                    for c in 0..d {
                        let v = if r == c {
                            at(&prep.dp_dx, c) * at(&self.metric_scale, c)
                        } else {
                            0.0
                        };
                        set(du_dx, r * d + c, v);
                    }
                }
            }
            Metric::Mahalanobis => {
                let s = at(&self.metric_scale, 0);
                for r in 0..d {
                    for c in 0..d {
                        let v = at(self.whiten, r * d + c) * at(&prep.dp_dx, c) * s;
                        set(du_dx, r * d + c, v);
                    }
                }
            }
        }
    }

    /// [`Kernel::features`] above [`MAX_DENSE_DIM`] inputs, where the metric is diagonal and
    /// nothing is warped: `u_j = s_j x_j`, and the Jacobian is the diagonal `s_j`.
    #[inline(never)]
    fn features_wide(
        &self,
        x_std: &[f64],
        u: &mut [f64; MAX_DIM],
        du_dx: &mut [f64; FEATURE_JACOBIAN_LEN],
    ) {
        let d = self.spec.dim;
        for (j, ((uj, jac), x)) in u
            .iter_mut()
            .zip(du_dx.iter_mut())
            .zip(x_std)
            .enumerate()
            .take(d)
        {
            let s = self.scale(j);
            *uj = x * s;
            *jac = s;
        }
    }

    /// `k(x, x')` for two standardised inputs with direction signs `g`, `g'`.
    pub fn eval(&self, x1: &[f64], g1: f64, x2: &[f64], g2: f64) -> f64 {
        let p1 = self.prepare(x1, g1);
        let p2 = self.prepare(x2, g2);
        self.eval_prepared(&p1, &p2)
    }

    /// `k` between two prepared points.
    #[inline]
    pub fn eval_prepared(&self, p1: &Prepared, p2: &Prepared) -> f64 {
        let (r2, _) = self.r2_and_mdelta(p1, p2);
        let (f, _) = profile_and_slope(self.spec.profile, r2);
        self.signal_variance() * f * self.spec.direction_factor(p1.g, p2.g)
    }

    #[inline]
    fn r2_and_mdelta(&self, p1: &Prepared, p2: &Prepared) -> (f64, [f64; MAX_DIM]) {
        let d = self.spec.dim;
        let mut delta = [0.0; MAX_DIM];
        for ((dj, a), b) in delta.iter_mut().zip(&p1.p).zip(&p2.p).take(d) {
            *dj = a - b;
        }
        let mut md = [0.0; MAX_DIM];
        self.metric_times(&delta, &mut md);
        let mut r2 = 0.0;
        for (dj, mj) in delta.iter().zip(&md).take(d) {
            r2 += dj * mj;
        }
        (r2.max(0.0), md)
    }

    /// Gradient of `k(x1, x2)` with respect to the first (standardised) input `x1`;
    /// writes `dim` values into `out` and returns `k`.
    pub fn grad_x(&self, x1: &[f64], g1: f64, x2: &[f64], g2: f64, out: &mut [f64]) -> f64 {
        let p1 = self.prepare(x1, g1);
        let p2 = self.prepare(x2, g2);
        let (r2, md) = self.r2_and_mdelta(&p1, &p2);
        let (f, df) = profile_and_slope(self.spec.profile, r2);
        let scale = self.signal_variance() * self.spec.direction_factor(g1, g2);
        for ((o, mj), dpj) in out.iter_mut().zip(&md).zip(&p1.dp_dx).take(self.spec.dim) {
            // dr2/dx1_j = 2 (M delta)_j phi'_j(x1_j)
            *o = scale * df * 2.0 * mj * dpj;
        }
        scale * f
    }

    /// Gradient of `k(p1, p2)` with respect to every hyperparameter in `theta`
    /// (`n_params()` values into `out`); returns `k`.
    pub fn grad_theta(&self, p1: &Prepared, p2: &Prepared, out: &mut [f64]) -> f64 {
        let spec = &self.spec;
        let d = spec.dim;
        let (r2, md) = self.r2_and_mdelta(p1, p2);
        let (f, df) = profile_and_slope(spec.profile, r2);
        let sf2 = self.signal_variance();
        let dir = spec.direction_factor(p1.g, p2.g);
        let k = sf2 * f * dir;
        let c = sf2 * dir * df; // dk/dr2
        set(out, 0, k);
        match spec.metric {
            Metric::Isotropic => set(out, 1, c * (-2.0 * r2)),
            Metric::Mahalanobis => set(out, 1, c * (-r2)),
            Metric::Ard => {
                for (j, (a, b)) in p1.p.iter().zip(&p2.p).take(d).enumerate() {
                    let delta = a - b;
                    let v = c * (-2.0 * delta * delta * libm::exp(-2.0 * at(self.theta, 1 + j)));
                    set(out, 1 + j, v);
                }
            }
        }
        let m = spec.warp_units;
        let warp = md
            .iter()
            .zip(p1.dp_da.iter().zip(&p2.dp_da))
            .zip(p1.dp_db.iter().zip(&p2.dp_db));
        for (j, ((mdj, (a1, a2)), (b1, b2))) in warp.take(d).enumerate() {
            for (i, ((a1, a2), (b1, b2))) in
                a1.iter().zip(a2).zip(b1.iter().zip(b2)).take(m).enumerate()
            {
                let dr2_da = 2.0 * mdj * (a1 - a2);
                let dr2_db = 2.0 * mdj * (b1 - b2);
                set(out, spec.warp_a_offset() + j * m + i, c * dr2_da);
                set(out, spec.warp_b_offset() + j * m + i, c * dr2_db);
            }
        }
        k
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Distance in units in the last place between two positive finite doubles.
    fn ulps(a: f64, b: f64) -> u64 {
        a.to_bits().abs_diff(b.to_bits())
    }

    #[test]
    fn exp_nonpositive_is_within_two_ulp_of_libm() {
        // A dense sweep of the kernels' range, finest near 0 where kernel values matter most,
        // plus the reduction's edges (half-integer multiples of ln 2) where rounding of k flips.
        let mut worst = (0u64, 0.0f64);
        let mut check = |x: f64| {
            let (got, want) = (exp_nonpositive(x), libm::exp(x));
            let e = ulps(got, want);
            if e > worst.0 {
                worst = (e, x);
            }
        };
        for i in 0..=200_000 {
            check(-(i as f64) * 1e-5); // [-2, 0]
            check(-(i as f64) * 3.54e-3); // [-708, 0]
        }
        for k in 0..2042 {
            let edge = -(k as f64 + 0.5) * core::f64::consts::LN_2;
            for dx in [-1e-12, 0.0, 1e-12] {
                if edge + dx >= EXP_FLOOR {
                    check(edge + dx);
                }
            }
        }
        assert!(worst.0 <= 2, "{} ulp at x = {}", worst.0, worst.1);
        // The edges of the domain: exactly 1 at 0, the floor below it, NaN stays NaN.
        assert_eq!(exp_nonpositive(0.0), 1.0);
        assert_eq!(exp_nonpositive(-0.0), 1.0);
        assert_eq!(exp_nonpositive(3.0), 1.0);
        assert_eq!(exp_nonpositive(-1e9), exp_nonpositive(EXP_FLOOR));
        assert_eq!(
            exp_nonpositive(f64::NEG_INFINITY),
            exp_nonpositive(EXP_FLOOR)
        );
        assert!(exp_nonpositive(EXP_FLOOR) > 0.0 && exp_nonpositive(EXP_FLOOR) < 1e-307);
        assert!(exp_nonpositive(f64::NAN).is_nan());
    }

    fn specs() -> [KernelSpec; 6] {
        let d = 3;
        [
            KernelSpec {
                metric: Metric::Isotropic,
                ..KernelSpec::se_ard(d)
            },
            KernelSpec::se_ard(d),
            KernelSpec {
                metric: Metric::Mahalanobis,
                ..KernelSpec::se_ard(d)
            },
            KernelSpec {
                profile: Profile::Matern52,
                ..KernelSpec::se_ard(d)
            },
            KernelSpec {
                warp_units: 2,
                metric: Metric::Mahalanobis,
                direction: Some([2, 0]),
                ..KernelSpec::se_ard(d)
            },
            KernelSpec {
                warp_units: 1,
                profile: Profile::Matern52,
                direction: Some([1, 0]),
                ..KernelSpec::se_ard(d)
            },
        ]
    }

    fn theta_for(spec: &KernelSpec) -> [f64; 40] {
        let mut t = [0.0; 40];
        for (i, v) in t.iter_mut().enumerate().take(spec.n_params()) {
            *v = 0.3 * libm::sin(1.7 * i as f64 + 0.2);
        }
        t
    }

    const W: [f64; 9] = [1.2, 0.0, 0.0, -0.4, 0.9, 0.0, 0.1, 0.3, 1.1];

    #[test]
    fn se_matches_closed_form() {
        let spec = KernelSpec::se_ard(2);
        let theta = [libm::log(2.0), libm::log(0.5), libm::log(2.0)];
        let k = Kernel::new(spec, &theta, &[]).unwrap();
        let v = k.eval(&[0.1, 0.2], 0.0, &[0.4, -0.6], 0.0);
        let r2 = (0.3f64 / 0.5).powi(2) + (0.8f64 / 2.0).powi(2);
        assert!((v - 2.0 * (-0.5 * r2).exp()).abs() < 1e-15);
    }

    #[test]
    fn matern_matches_closed_form() {
        let spec = KernelSpec {
            profile: Profile::Matern52,
            ..KernelSpec::se_ard(1)
        };
        let theta = [0.0, libm::log(0.7)];
        let k = Kernel::new(spec, &theta, &[]).unwrap();
        let r = 0.5f64 / 0.7;
        let want = (1.0 + 5f64.sqrt() * r + 5.0 / 3.0 * r * r) * (-(5f64.sqrt()) * r).exp();
        assert!((k.eval(&[0.5], 0.0, &[0.0], 0.0) - want).abs() < 1e-15);
    }

    #[test]
    fn direction_factor_blocks_opposite_branches() {
        let spec = KernelSpec {
            direction: Some([0, 1]),
            ..KernelSpec::se_ard(2)
        };
        let theta = [0.0; 3];
        let k = Kernel::new(spec, &theta, &[]).unwrap();
        let x = [0.1, 0.2];
        assert!((k.eval(&x, 1.0, &x, 1.0) - 1.0).abs() < 1e-15);
        assert_eq!(k.eval(&x, 1.0, &x, -1.0), 0.0);
        assert!((k.eval(&x, 0.0, &x, 1.0) - 0.5).abs() < 1e-15);
        assert_eq!(spec.direction_of(&[2.0, 1.0]), 1.0);
        assert_eq!(spec.direction_of(&[1.0, 2.0]), -1.0);
    }

    #[test]
    fn mahalanobis_uses_whitening() {
        let spec = KernelSpec {
            metric: Metric::Mahalanobis,
            ..KernelSpec::se_ard(2)
        };
        let w = [2.0, 0.0, 1.0, 1.0];
        let theta = [0.0, libm::log(4.0)];
        let k = Kernel::new(spec, &theta, &w).unwrap();
        // delta = (1, 1): W delta = (2, 2), r2 = 8 / 4 = 2.
        let v = k.eval(&[1.0, 1.0], 0.0, &[0.0, 0.0], 0.0);
        assert!((v - (-1.0f64).exp()).abs() < 1e-15);
    }

    #[test]
    fn input_gradient_matches_finite_differences() {
        for spec in specs() {
            let theta = theta_for(&spec);
            let theta = &theta[..spec.n_params()];
            let k = Kernel::new(spec, theta, &W).unwrap();
            let x1 = [0.3, -0.7, 1.1];
            let x2 = [-0.2, 0.4, 0.9];
            let mut g = [0.0; 3];
            k.grad_x(&x1, 1.0, &x2, 1.0, &mut g);
            for j in 0..3 {
                let h = 1e-6;
                let (mut a, mut b) = (x1, x1);
                a[j] += h;
                b[j] -= h;
                let fd = (k.eval(&a, 1.0, &x2, 1.0) - k.eval(&b, 1.0, &x2, 1.0)) / (2.0 * h);
                assert!(
                    (fd - g[j]).abs() < 1e-8 * (1.0 + fd.abs()),
                    "{spec:?} j={j} fd={fd} an={}",
                    g[j]
                );
            }
        }
    }

    #[test]
    fn hyperparameter_gradient_matches_finite_differences() {
        for spec in specs() {
            let base = theta_for(&spec);
            let n = spec.n_params();
            let x1 = [0.3, -0.7, 1.1];
            let x2 = [-0.2, 0.4, 0.9];
            let k = Kernel::new(spec, &base[..n], &W).unwrap();
            let mut g = [0.0; 40];
            let kv = k.grad_theta(&k.prepare(&x1, 1.0), &k.prepare(&x2, 1.0), &mut g[..n]);
            assert!((kv - k.eval(&x1, 1.0, &x2, 1.0)).abs() < 1e-15);
            for i in 0..n {
                let h = 1e-6;
                let (mut a, mut b) = (base, base);
                a[i] += h;
                b[i] -= h;
                let ka = Kernel::new(spec, &a[..n], &W)
                    .unwrap()
                    .eval(&x1, 1.0, &x2, 1.0);
                let kb = Kernel::new(spec, &b[..n], &W)
                    .unwrap()
                    .eval(&x1, 1.0, &x2, 1.0);
                let fd = (ka - kb) / (2.0 * h);
                assert!(
                    (fd - g[i]).abs() < 1e-8 * (1.0 + fd.abs()),
                    "{spec:?} i={i} fd={fd} an={}",
                    g[i]
                );
            }
        }
    }

    #[test]
    fn features_reproduce_the_kernel() {
        for spec in specs() {
            let theta = theta_for(&spec);
            let k = Kernel::new(spec, &theta[..spec.n_params()], &W).unwrap();
            let x1 = [0.3, -0.7, 1.1];
            let x2 = [-0.2, 0.4, 0.9];
            let (mut u1, mut u2) = ([0.0; MAX_DIM], [0.0; MAX_DIM]);
            let mut jac = [0.0; FEATURE_JACOBIAN_LEN];
            k.features(&x1, &mut u1, &mut jac);
            k.features(&x2, &mut u2, &mut jac);
            let r2: f64 = (0..3).map(|j| (u1[j] - u2[j]).powi(2)).sum();
            let (f, _) = profile_and_slope(spec.profile, r2);
            let want = k.eval(&x1, 0.0, &x2, 0.0) / spec.direction_factor(0.0, 0.0);
            assert!((k.signal_variance() * f - want).abs() < 1e-14, "{spec:?}");
            // Feature Jacobian against finite differences.
            k.features(&x1, &mut u1, &mut jac);
            for c in 0..3 {
                let h = 1e-6;
                let (mut a, mut b) = (x1, x1);
                a[c] += h;
                b[c] -= h;
                let (mut ua, mut ub) = ([0.0; MAX_DIM], [0.0; MAX_DIM]);
                let mut tmp = [0.0; FEATURE_JACOBIAN_LEN];
                k.features(&a, &mut ua, &mut tmp);
                k.features(&b, &mut ub, &mut tmp);
                for r in 0..3 {
                    let fd = (ua[r] - ub[r]) / (2.0 * h);
                    assert!((fd - jac[r * 3 + c]).abs() < 1e-8, "{spec:?}");
                }
            }
        }
    }

    #[test]
    fn invalid_specs_are_rejected() {
        assert!(KernelSpec::se_ard(0).validate().is_err());
        assert!(KernelSpec::se_ard(MAX_DIM).validate().is_ok());
        assert!(KernelSpec::se_ard(MAX_DIM + 1).validate().is_err());
        // Warped and Mahalanobis kernels have dense feature Jacobians: at most 8 inputs.
        let wide = KernelSpec::se_ard(MAX_DENSE_DIM + 1);
        assert!(
            KernelSpec {
                warp_units: 1,
                ..wide
            }
            .validate()
            .is_err()
        );
        assert!(
            KernelSpec {
                metric: Metric::Mahalanobis,
                ..wide
            }
            .validate()
            .is_err()
        );
        assert!(
            KernelSpec {
                warp_units: 1,
                ..KernelSpec::se_ard(MAX_DENSE_DIM)
            }
            .validate()
            .is_ok()
        );
        assert!(
            KernelSpec {
                direction: Some([0, 0]),
                ..KernelSpec::se_ard(2)
            }
            .validate()
            .is_err()
        );
        assert!(
            KernelSpec {
                warp_units: 5,
                ..KernelSpec::se_ard(2)
            }
            .validate()
            .is_err()
        );
        assert!(Kernel::new(KernelSpec::se_ard(2), &[0.0; 2], &[]).is_err());
        assert!(Kernel::new(KernelSpec::se_ard(2), &[0.0, f64::NAN, 0.0], &[]).is_err());
    }
}
