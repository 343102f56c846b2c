//! The HBN extended Kalman filter step (thesis Sec. 4.1, Eqs. 21-24), allocation-free.
//!
//! ## Timing (no measurement lag)
//!
//! The filter estimates `x_k` from `u_0..u_k` and `y_0..y_k`. Its state after step `k` is
//!
//! `z_k = [x_k, x_{k-1}, s_k]`, with `s_k` the noise-free sensor output (`y_k = s_k + v_k`),
//!
//! and it remembers the known inputs `u_{k-1}` (and `u_{k-2}`), which play the role of the
//! thesis' delay state `s1` (a state with zero covariance is just a known input). Step `k >= 1`:
//!
//! 1. **predict** with the transition GP and the inputs of the *previous* samples:
//!    `x_k^- = H_D(x_{k-1}, x_{k-2}, u_{k-1}, u_{k-2})`, then the sensor GP at the new state:
//!    `s_k^- = H_S(x_{k-1}, s_{k-1}, x_k^-)`;
//! 2. **update** with `y_k` through `H = [0, 0, 1]`.
//!
//! Linearisation (Eq. 23) with `a_i = dH_D/d(input i)` and `c, e, f` the sensor gradients with
//! respect to `x_{k-1}, s_{k-1}, x_k`, chain rule through `H_D` where the sensor reads the new x:
//!
//! ```text
//!     | a1          a2     0 |            | 1 |
//! F = | 1           0      0 |,     G  =  | 0 |,   Q = G q_x G^T + diag(0, 0, q_s)
//!     | c + f a1    f a2   e |            | f |
//! ```
//!
//! `q_x` = transition GP variance + its learned noise (EKF+BLR: + the BLR noise estimate instead
//! of the learned noise), `q_s` = sensor GP variance, `R` = sensor learned noise (EKF+BLR: the
//! BLR noise estimate). `u_k` is stored for the
//! next step; it does not influence `x_k` (the transition only reads inputs up to `k - 1`).
//!
//! ## Guards (Assumption 4, Eq. 24)
//!
//! Noise floors (`q I <= Q`, `r <= R`), bounded Jacobian entries (`|F_ij| <= f`), a state box
//! around the training range, a Joseph-form update, symmetrisation, and an eigenvalue clamp
//! `p1 I <= P <= p2 I`. A (near-)singular innovation skips the update. Invalid inputs or
//! measurements skip the affected phase. Every guard that fires sets a bit in [`Flags`]; no NaN
//! leaves the step.

use crate::CoreError;
use crate::blr::{LocalRegression, Neighbourhood};
use crate::gp::{GpView, Want};
use crate::kernel::{MAX_DIM, clamp_to};
use crate::play::{PlayState, Plays, transition_input};
use nalgebra::{Matrix3, Vector3};

/// Guard flags of one step (a bit set).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub struct Flags(pub u32);

impl Flags {
    /// The input `u_k` was NaN/Inf; the previous input was held.
    pub const INPUT_INVALID: u32 = 1 << 0;
    /// The measurement `y_k` was NaN/Inf; the update was skipped.
    pub const MEASUREMENT_INVALID: u32 = 1 << 1;
    /// A GP prediction failed; the prediction fell back to a random walk.
    pub const MODEL_INVALID: u32 = 1 << 2;
    /// A Jacobian entry exceeded its bound and was clamped.
    pub const JACOBIAN_CLAMPED: u32 = 1 << 3;
    /// A noise variance was raised to its floor.
    pub const NOISE_FLOOR: u32 = 1 << 4;
    /// The innovation variance was (near-)singular or non-finite; the update was skipped.
    pub const INNOVATION_SINGULAR: u32 = 1 << 5;
    /// The covariance left `[p_min, p_max]` and its eigenvalues were clamped.
    pub const COVARIANCE_CLAMPED: u32 = 1 << 6;
    /// The state left its box and was clamped.
    pub const STATE_CLAMPED: u32 = 1 << 7;
    /// The innovation exceeded the outlier gate ([`EkfConfig::nis_gate`]); the measurement
    /// was down-weighted to the gate's NIS, not skipped (despite the flag's name).
    pub const OUTLIER_REJECTED: u32 = 1 << 8;
    /// EKF+BLR: the transition window held no training samples (prior used).
    pub const BLR_EMPTY_TRANSITION: u32 = 1 << 9;
    /// EKF+BLR: the sensor window held no training samples (prior used).
    pub const BLR_EMPTY_SENSOR: u32 = 1 << 10;
    /// EKF+BLR: more samples than the cap fell in a window; the nearest were kept.
    pub const BLR_CAPPED: u32 = 1 << 11;
    /// The first sample: the filter was initialised.
    pub const INITIALISED: u32 = 1 << 12;
    /// Either GP's latent variance exceeded [`EXTRAPOLATION_RATIO`] of its prior variance or of
    /// the variance of its training targets, whichever is smaller: the operating point is
    /// outside the training data, and the GP's uncertainty there is as large as the signal.
    pub const EXTRAPOLATION: u32 = 1 << 13;
    /// The transition's prediction from the estimate had left the state box for
    /// [`LOST_AFTER`] steps in a row: the filter was lost, and re-started from the model's
    /// [`InitPrior`] at this step's measurement (the inputs and plays kept).
    pub const RELOCALISED: u32 = 1 << 14;

    /// Whether `bit` is set.
    pub fn has(self, bit: u32) -> bool {
        self.0 & bit != 0
    }

    /// Name of each bit, in bit order (bit `i` is `NAMES[i]`).
    pub const NAMES: [&'static str; 15] = [
        "input_invalid",
        "measurement_invalid",
        "model_invalid",
        "jacobian_clamped",
        "noise_floor",
        "innovation_singular",
        "covariance_clamped",
        "state_clamped",
        "outlier_rejected",
        "blr_empty_transition",
        "blr_empty_sensor",
        "blr_capped",
        "initialised",
        "extrapolation",
        "relocalised",
    ];

    /// Names of the set flags, for logs (`no_std`: yields `&'static str`).
    pub fn names(self) -> impl Iterator<Item = &'static str> {
        Self::NAMES
            .into_iter()
            .enumerate()
            .filter(move |(i, _)| self.0 & (1 << i) != 0)
            .map(|(_, n)| n)
    }
}

/// Estimation mode. The default is [`Mode::Ekf`] (what `hbn estimate` and Python use when no
/// mode is given).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
#[cfg_attr(feature = "serde", serde(rename_all = "kebab-case"))]
pub enum Mode {
    /// Plain EKF: GP mean gradients as Jacobians, GP variances + learned noise as Q and R.
    #[default]
    Ekf,
    /// EKF with local Bayesian linear regression for the Jacobians and the noise (Sec. 4.3).
    EkfBlr,
    /// Unscented (sigma-point) filter, thesis Sec. 6.3: the prediction passes 8 sigma points
    /// of `[x_{k-1}, x_{k-2}, s_{k-1}, w]` (`w` the transition noise) through the GP means
    /// instead of linearising them; the GP variances are the noise as in the EKF.
    Ukf,
}

impl Mode {
    /// Every mode, in the order of their names.
    pub const ALL: [Mode; 3] = [Mode::Ekf, Mode::EkfBlr, Mode::Ukf];

    /// The mode's name: `ekf`, `ekf-blr` or `ukf` (what [`core::str::FromStr`] accepts).
    pub const fn name(self) -> &'static str {
        match self {
            Mode::Ekf => "ekf",
            Mode::EkfBlr => "ekf-blr",
            Mode::Ukf => "ukf",
        }
    }
}

impl core::fmt::Display for Mode {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.write_str(self.name())
    }
}

impl core::str::FromStr for Mode {
    type Err = CoreError;
    /// Parses `ekf`, `ekf-blr` (also `ekf+blr`, `ekf_blr`) or `ukf`; case-insensitive.
    fn from_str(s: &str) -> Result<Self, CoreError> {
        let t = s.trim();
        if t.eq_ignore_ascii_case("ekf") {
            Ok(Mode::Ekf)
        } else if t.eq_ignore_ascii_case("ukf") {
            Ok(Mode::Ukf)
        } else if ["ekf-blr", "ekf+blr", "ekf_blr"]
            .iter()
            .any(|n| t.eq_ignore_ascii_case(n))
        {
            Ok(Mode::EkfBlr)
        } else {
            Err(CoreError::InvalidSpec(
                "unknown mode; choose \"ekf\", \"ekf-blr\" or \"ukf\"",
            ))
        }
    }
}

/// Filter settings, in the raw units of the signals. Checked once by [`Estimator::new`].
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub struct EkfConfig {
    /// Estimation mode.
    pub mode: Mode,
    /// Floor of the process noise variances (`q` of Eq. 24).
    pub q_floor: f64,
    /// Floor of the measurement noise variance (`r` of Eq. 24).
    pub r_floor: f64,
    /// Model-error floor of `q_x` (the transition GP's leave-one-out error variance). Not a
    /// guard: applying it sets no flag.
    pub qx_model_floor: f64,
    /// Model-error floor of `R` (the sensor GP's leave-one-out error variance). Not a guard.
    pub r_model_floor: f64,
    /// Lower eigenvalue bound of P (`p1`).
    pub p_min: f64,
    /// Upper eigenvalue bound of P (`p2`).
    pub p_max: f64,
    /// Bound on each Jacobian entry (`f`).
    pub jac_max: f64,
    /// Smallest innovation variance accepted for an update.
    pub innovation_min: f64,
    /// Outlier gate on the normalised innovation squared `NIS = nu^2 / S`; `0` disables it. A
    /// measurement whose NIS exceeds the gate is down-weighted, not skipped: the update uses
    /// the innovation variance `nu^2 / gate` (its measurement variance inflated by the
    /// difference), so its NIS is the gate's and the state moves by `P_xs gate / nu`, less the
    /// larger the outlier. A spike barely moves the state; a lasting offset (a state that is
    /// off, or a model error, as on noise-free data where `R` is tiny) is followed at a
    /// bounded pace instead of being ignored until the state is lost.
    pub nis_gate: f64,
    /// State box: `x` and `s` are clamped to `[lo, hi]` (from the training ranges).
    pub x_bounds: (f64, f64),
    /// Box of the sensor state `s`.
    pub y_bounds: (f64, f64),
    /// Initial mean of `x` (e.g. the training mean), used when the model has no
    /// [`InitPrior`] or the first measurement is not finite.
    pub x0_mean: f64,
    /// Initial variance of `x` (e.g. the training variance); see `x0_mean`.
    pub x0_var: f64,
    /// Scale of the process noise `Q` (both `q_x` and `q_s`, model floors included), learned
    /// on held-out data by filter-aware training (`1` = the GP variances as they are).
    #[cfg_attr(feature = "serde", serde(default = "one"))]
    pub q_scale: f64,
    /// Scale of the measurement noise `R` (model floor included); see `q_scale`.
    #[cfg_attr(feature = "serde", serde(default = "one"))]
    pub r_scale: f64,
    /// Scale of the reported standard deviation of `x` (calibration: the filter's own `P` is
    /// not changed); see `q_scale`.
    #[cfg_attr(feature = "serde", serde(default = "one"))]
    pub std_scale: f64,
}

#[cfg(feature = "serde")]
fn one() -> f64 {
    1.0
}

impl EkfConfig {
    /// Checks every field once.
    pub fn validate(&self) -> Result<(), CoreError> {
        let pos = |v: f64| v.is_finite() && v > 0.0;
        if !(pos(self.q_floor)
            && pos(self.r_floor)
            && pos(self.p_min)
            && pos(self.p_max)
            && pos(self.jac_max))
        {
            return Err(CoreError::InvalidSpec(
                "q_floor, r_floor, p_min, p_max and jac_max must be finite and > 0",
            ));
        }
        if !(self.qx_model_floor.is_finite()
            && self.qx_model_floor >= 0.0
            && self.r_model_floor.is_finite()
            && self.r_model_floor >= 0.0)
        {
            return Err(CoreError::InvalidSpec(
                "model-error floors must be finite and >= 0",
            ));
        }
        if self.p_min >= self.p_max {
            return Err(CoreError::InvalidSpec("p_min must be below p_max"));
        }
        if !(pos(self.innovation_min) && self.nis_gate.is_finite() && self.nis_gate >= 0.0) {
            return Err(CoreError::InvalidSpec(
                "innovation_min must be > 0 and nis_gate >= 0",
            ));
        }
        let ok_box = |b: (f64, f64)| b.0.is_finite() && b.1.is_finite() && b.0 < b.1;
        if !(ok_box(self.x_bounds) && ok_box(self.y_bounds)) {
            return Err(CoreError::InvalidSpec(
                "state bounds must be finite with lo < hi",
            ));
        }
        if !(pos(self.q_scale) && pos(self.r_scale) && pos(self.std_scale)) {
            return Err(CoreError::InvalidSpec(
                "q_scale, r_scale and std_scale must be finite and > 0",
            ));
        }
        // The reported standard deviation is `std_scale * sqrt(P_11)` with `P_11 <= p_max`:
        // it must stay finite (a huge std_scale gives x_std = inf; the `step` fuzz target
        // reaches it).
        if !(self.std_scale * sqrt(self.p_max)).is_finite() {
            return Err(CoreError::InvalidSpec(
                "std_scale * sqrt(p_max) must be finite (the reported standard deviation)",
            ));
        }
        if !(self.x0_mean.is_finite() && pos(self.x0_var)) {
            return Err(CoreError::InvalidSpec(
                "x0_mean must be finite and x0_var > 0",
            ));
        }
        Ok(())
    }
}

/// Latent variance, as a fraction of the GP's prior variance or of the variance of its
/// training targets (the smaller), above which a prediction counts as extrapolation
/// ([`Flags::EXTRAPOLATION`]). The second reference matters for kernels fitted with a large
/// signal variance and long length scales, whose latent variance stays a small fraction of the
/// prior far outside the data.
pub const EXTRAPOLATION_RATIO: f64 = 0.5;

/// Steps in a row in which the transition GP's prediction from the estimate, `x_k^-`, left the
/// state box, after which the filter counts as lost and re-starts from the model's [`InitPrior`]
/// at the current measurement ([`Flags::RELOCALISED`]). The box is the training range of `x`
/// widened by 10% of its span on each side, so such a prediction comes from a state the model
/// knows nothing about; a filter there does not come back by itself (its Jacobians and
/// variances are extrapolations, and it can lock into a cycle between the two edges). The
/// prediction's mean counts, in every mode: not the posterior (the update may pull it back
/// each step while the next prediction leaves again), nor the unscented mode's sigma points.
/// Without an [`InitPrior`], or with a non-finite measurement, nothing happens.
pub const LOST_AFTER: u32 = 10;

/// Inputs of the thesis' sensor GP, `[x_{k-1}, y_{k-1}, x_k]`.
pub const SENSOR_DIM: usize = 3;

/// Inputs of a sensor GP of the state only, `[x_{k-1}, x_k]`: the output's level is a
/// function of the state's, so a filter can recover a drifted state from `y` alone (the
/// thesis' sensor, which also reads `y_{k-1}`, can learn increments only; docs/math.md,
/// "A sensor of the state only").
pub const SENSOR_STATE_DIM: usize = 2;

/// Most play operators of the state a sensor GP reads ([`HbnView::sensor_memory`]): its
/// inputs `[x_k, q^1_k, .., q^m_k]` fill [`SENSOR_DIM`].
pub const MAX_SENSOR_MEMORY: usize = SENSOR_DIM - 1;

/// Prior of `x_0` from the first measurement: training `(y, x)` pairs sorted by `y`. Hysteresis
/// makes `x` given `y` ambiguous; the spread of `x` over the training samples whose `y` is
/// nearest says how much. Checked once by [`InitPrior::new`]; [`InitPrior::prior`] is
/// allocation-free, `O(log n + neighbours)`.
#[derive(Clone, Copy, Debug)]
pub struct InitPrior<'a> {
    pairs: &'a [[f64; 2]],
    neighbours: usize,
    var_floor: f64,
}

impl<'a> InitPrior<'a> {
    /// `pairs`: `[y, x]` rows sorted by `y` (non-decreasing), finite, at least one; `neighbours`:
    /// how many nearest samples to average (`>= 1`); `var_floor`: the smallest variance
    /// returned (`> 0`).
    pub fn new(
        pairs: &'a [[f64; 2]],
        neighbours: usize,
        var_floor: f64,
    ) -> Result<Self, CoreError> {
        if pairs.is_empty() {
            return Err(CoreError::Empty);
        }
        if neighbours == 0 {
            return Err(CoreError::InvalidSpec(
                "InitPrior needs at least one neighbour",
            ));
        }
        if !(var_floor.is_finite() && var_floor > 0.0) {
            return Err(CoreError::InvalidSpec(
                "InitPrior's variance floor must be finite and > 0",
            ));
        }
        if !pairs.iter().all(|p| p[0].is_finite() && p[1].is_finite()) {
            return Err(CoreError::NonFinite);
        }
        if pairs.windows(2).any(|w| matches!(w, [a, b] if b[0] < a[0])) {
            return Err(CoreError::InvalidSpec(
                "InitPrior's pairs must be sorted by y",
            ));
        }
        Ok(Self {
            pairs,
            neighbours,
            var_floor,
        })
    }

    /// The `[y, x]` pairs, sorted by `y`.
    pub fn pairs(&self) -> &'a [[f64; 2]] {
        self.pairs
    }

    /// How many nearest samples [`InitPrior::prior`] averages.
    pub fn neighbours(&self) -> usize {
        self.neighbours
    }

    /// The smallest variance [`InitPrior::prior`] returns.
    pub fn var_floor(&self) -> f64 {
        self.var_floor
    }

    /// Mean and variance of `x` over the `neighbours` training samples whose `y` is nearest `y0`
    /// (ties go to the lower index), the variance at least the floor. `None` for a non-finite
    /// `y0`, and when the mean or variance overflows (pairs near `f64::MAX`).
    pub fn prior(&self, y0: f64) -> Option<(f64, f64)> {
        if !y0.is_finite() {
            return None;
        }
        let p = self.pairs;
        // Every index below is in bounds (`lo <= hi <= p.len()`); `get` keeps that checkable.
        let dist = |i: usize| p.get(i).map_or(f64::INFINITY, |q| libm::fabs(q[0] - y0));
        let k = self.neighbours.min(p.len());
        // Grow a window [lo, hi) outward from y0; the left side wins ties (lower index).
        let split = p.partition_point(|q| q[0] < y0);
        let (mut lo, mut hi) = (split, split);
        while hi - lo < k {
            let take_left = lo > 0 && (hi == p.len() || dist(lo - 1) <= dist(hi));
            if take_left {
                lo -= 1;
            } else if hi < p.len() {
                hi += 1;
            } else {
                break;
            }
        }
        // The walk takes ties on the left (equal distances, i.e. equal y) from the high-index
        // end; the nearest-k set takes them from the low-index end. When the window cuts such
        // a run, swap the part taken for the run's lowest indices.
        let (mut first, mut cut) = (lo..lo, lo..hi);
        if lo < split && lo > 0 && dist(lo - 1) == dist(lo) {
            let d = dist(lo);
            let run_hi = lo
                + p.get(lo..split)
                    .unwrap_or(&[])
                    .partition_point(|q| libm::fabs(q[0] - y0) >= d);
            let run_lo = p
                .get(..lo)
                .unwrap_or(&[])
                .partition_point(|q| libm::fabs(q[0] - y0) > d);
            first = run_lo..run_lo + (run_hi - lo);
            cut = run_hi..hi;
        }
        let picked = || {
            first
                .clone()
                .chain(cut.clone())
                .filter_map(|i| p.get(i))
                .map(|q| q[1])
        };
        let n = k.max(1) as f64;
        let mean = picked().sum::<f64>() / n;
        let var = picked().map(|v| (v - mean) * (v - mean)).sum::<f64>() / n;
        // Finite pairs near f64::MAX can still overflow the sums (the `step` fuzz target
        // reaches them): no prior then, and the caller falls back to its settings.
        if mean.is_finite() && var.is_finite() {
            Some((mean, var.max(self.var_floor)))
        } else {
            None
        }
    }
}

/// The trained HBN as borrowed views: what the step reads. A firmware can build it from
/// `static` slices.
#[derive(Clone, Copy, Debug)]
pub struct HbnView<'a> {
    /// Transition GP, inputs `[x_{k-1}, x_{k-2}, u_{k-1}, u_{k-2}]` and then the plays
    /// after `u_{k-1}` (one input per play operator, [`crate::play`]).
    pub transition: GpView<'a>,
    /// Sensor GP, inputs `[x_{k-1}, y_{k-1}, x_k]` (the thesis), or `[x_{k-1}, x_k]` (a
    /// sensor that reads the state only, [`SENSOR_STATE_DIM`]): its dimension says which.
    /// With [`HbnView::sensor_memory`] it reads `[x_k, q^1_k, .., q^m_k]` instead.
    pub sensor: GpView<'a>,
    /// Training samples and index for the transition's local regression (EKF+BLR only).
    pub transition_local: Option<Neighbourhood<'a>>,
    /// Training samples and index for the sensor's local regression (EKF+BLR only).
    pub sensor_local: Option<Neighbourhood<'a>>,
    /// Local regression settings (EKF+BLR only).
    pub blr: LocalRegression,
    /// Prior of `x_0` from the first measurement; without it (or with a non-finite first
    /// measurement) the filter starts from [`EkfConfig::x0_mean`] and [`EkfConfig::x0_var`].
    pub init: Option<InitPrior<'a>>,
    /// Play operators whose values extend the transition's inputs ([`Plays::NONE`]: the
    /// thesis' four inputs).
    pub plays: Plays,
    /// Play operators of the state (radii in the state's units, no lags, at most
    /// [`MAX_SENSOR_MEMORY`]) that the sensor GP reads with `x_k`: `[x_k, q^1_k, .., q^m_k]`
    /// with `q^i_k = clamp(q^i_{k-1}, x_k - r_i, x_k + r_i)`. The filter carries `q_{k-1}`,
    /// the plays of its estimates `x_0..x_{k-1}` ([`EkfState::memory`]), so a sensor whose
    /// output depends on the state's history (a relay or play-type sensor) reads that history
    /// without `y_{k-1}`. [`Plays::NONE`]: the sensor reads the thesis' or the state-only
    /// inputs.
    pub sensor_memory: Plays,
}

impl HbnView<'_> {
    /// Checks that the GPs have the HBN's input dimensions: 4 plus one per play operator for
    /// the transition, 3 ([`SENSOR_DIM`]) or 2 ([`SENSOR_STATE_DIM`]) for the sensor; the
    /// local regression of the transition reads its first 4 inputs, the sensor's the sensor
    /// GP's inputs.
    pub fn validate(&self) -> Result<(), CoreError> {
        let transition_dim = 4 + self.plays.len();
        if self.transition.dim() != transition_dim {
            return Err(CoreError::DimensionMismatch {
                expected: transition_dim,
                got: self.transition.dim(),
            });
        }
        let sensor_dim = self.sensor.dim();
        if !self.sensor_memory.is_empty() {
            let memory = self.sensor_memory;
            if !memory.lags().is_empty() || memory.len() > MAX_SENSOR_MEMORY {
                return Err(CoreError::InvalidSpec(
                    "a sensor reads at most 2 play operators of the state, and no lags",
                ));
            }
            if sensor_dim != 1 + memory.len() {
                return Err(CoreError::DimensionMismatch {
                    expected: 1 + memory.len(),
                    got: sensor_dim,
                });
            }
        } else if sensor_dim != SENSOR_DIM && sensor_dim != SENSOR_STATE_DIM {
            return Err(CoreError::DimensionMismatch {
                expected: SENSOR_DIM,
                got: sensor_dim,
            });
        }
        if let Some(n) = &self.transition_local
            && n.dim() != 4
        {
            return Err(CoreError::DimensionMismatch {
                expected: 4,
                got: n.dim(),
            });
        }
        if let Some(n) = &self.sensor_local
            && n.dim() != sensor_dim
        {
            return Err(CoreError::DimensionMismatch {
                expected: sensor_dim,
                got: n.dim(),
            });
        }
        self.blr.validate()
    }
}

/// What one step returns.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct StepOutput {
    /// Estimate of `x_k`.
    pub x: f64,
    /// Its standard deviation.
    pub x_std: f64,
    /// Predicted measurement `s_k^-` (before the update with `y_k`).
    pub y_pred: f64,
    /// Innovation `y_k - s_k^-` (0 when the update was skipped).
    pub innovation: f64,
    /// Innovation variance `S`.
    pub innovation_var: f64,
    /// Normalised innovation squared `innovation^2 / S`.
    pub nis: f64,
    /// Process noise variance used for `x` (`q_x`).
    pub q_x: f64,
    /// Measurement noise variance used (`R`).
    pub r: f64,
    /// Linearised state transition `F` of this step (identity on the first step).
    pub jacobian: Matrix3<f64>,
    /// Guards that fired.
    pub flags: Flags,
}

/// The prediction phase of one step, as [`Ekf::predict`] returns it: what an offline smoother
/// records beside the filtered state (the Rauch-Tung-Striebel smoother of `hbn_model` needs the
/// predicted moments and the cross-covariance of the previous state with the predicted one).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct StepPrediction {
    /// Predicted mean `z_k^- = [x_k^-, x_{k-1}, s_k^-]` (before the update with `y_k`).
    pub z: Vector3<f64>,
    /// Predicted covariance `P_k^-`, bounded as the step bounds it.
    pub p: Matrix3<f64>,
    /// Cross-covariance `C_k = cov(z_{k-1}, z_k^-)` of the filtered previous state with the
    /// predicted one: `P_{k-1} F_k^T` when the prediction is linearised (EKF, EKF+BLR, and the
    /// random walk the step falls back to), the sigma points' cross-covariance in the
    /// unscented mode.
    pub cross: Matrix3<f64>,
    /// Guards that fired during the prediction (those of the step's prediction phase).
    pub flags: Flags,
}

/// The filter's memory between steps.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct EkfState {
    /// `[x_k, x_{k-1}, s_k]`.
    pub z: Vector3<f64>,
    /// Covariance of `z`.
    pub p: Matrix3<f64>,
    /// `u_k` of the last step (the next step's `u_{k-1}`).
    pub u_last: f64,
    /// `u_{k-1}` of the last step.
    pub u_prev: f64,
    /// The plays after `u_k` of the last step ([`HbnView::plays`]; unused slots hold `u_k`).
    pub plays: PlayState,
    /// The plays of the estimates `x_0..x_k` ([`HbnView::sensor_memory`]; unused slots hold
    /// the last estimate).
    pub memory: PlayState,
    /// Steps taken.
    pub steps: u64,
    /// Measurements down-weighted in a row by the outlier gate ([`EkfConfig::nis_gate`]).
    pub rejected_run: u32,
    /// Steps in a row whose transition prediction from the estimate left the state box
    /// ([`LOST_AFTER`]).
    pub lost_run: u32,
}

/// One linearised GP: value, input gradient, noise variance.
#[derive(Clone, Copy, Debug)]
struct Local {
    mean: f64,
    grad: [f64; 4],
    noise: f64,
    epistemic: f64,
}

/// The sensor GP's input at one point and how each of its entries moves with the filter's
/// `(x_{k-1}, s_{k-1}, x_k)`: `chain[i][j] = d input_i / d z_j` (a play of the state moves
/// with `x_k` while `x_k` drags it, and holds inside its band).
#[derive(Clone, Copy, Debug)]
struct SensorPoint {
    input: [f64; SENSOR_DIM],
    chain: [[f64; 3]; SENSOR_DIM],
}

impl SensorPoint {
    /// The gradient of the GP mean w.r.t. `(x_{k-1}, s_{k-1}, x_k)` from the one w.r.t. the
    /// GP's inputs (the chain rule through [`SensorPoint::chain`]).
    fn gradient(&self, local: &mut Local) {
        let mut out = [0.0; 4];
        for (g, row) in local.grad.iter().zip(&self.chain) {
            for (o, c) in out.iter_mut().zip(row) {
                *o += g * c;
            }
        }
        local.grad = out;
    }
}

/// Which relation of the HBN a linearisation is of.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Relation {
    /// `H_D`, the transition.
    Transition,
    /// `H_S`, the sensor.
    Sensor,
}

/// What a prediction hands to the update and the step's output.
#[derive(Clone, Copy, Debug)]
struct Predicted {
    q_x: f64,
    r: f64,
    s_pred: f64,
    jacobian: Matrix3<f64>,
    /// The transition GP's mean from the estimate left the state box ([`LOST_AFTER`]).
    left_box: bool,
}

/// Lower Cholesky factor of a symmetric positive-definite 3x3 matrix, `None` if it is not
/// (written out: no indexing, no panic path).
fn cholesky3(p: &Matrix3<f64>) -> Option<Matrix3<f64>> {
    let pos = |v: f64| v.is_finite() && v > 0.0;
    let d1 = p.m11;
    if !pos(d1) {
        return None;
    }
    let l11 = sqrt(d1);
    let l21 = p.m21 / l11;
    let l31 = p.m31 / l11;
    let d2 = p.m22 - l21 * l21;
    if !pos(d2) {
        return None;
    }
    let l22 = sqrt(d2);
    let l32 = (p.m32 - l31 * l21) / l22;
    let d3 = p.m33 - l31 * l31 - l32 * l32;
    if !pos(d3) {
        return None;
    }
    let l33 = sqrt(d3);
    Some(Matrix3::new(l11, 0.0, 0.0, l21, l22, 0.0, l31, l32, l33))
}

/// A checked model view and filter settings: the per-sample step as a function of the
/// filter's state and the caller's scratch memory. `Copy`, so a firmware or an owning wrapper
/// keeps it next to its state; [`Ekf::new`] does every check once and [`Ekf::step`] cannot
/// fail.
#[derive(Clone, Copy, Debug)]
pub struct Ekf<'m> {
    model: HbnView<'m>,
    config: EkfConfig,
}

impl<'m> Ekf<'m> {
    /// Checks model and settings once.
    pub fn new(model: HbnView<'m>, config: EkfConfig) -> Result<Self, CoreError> {
        model.validate()?;
        config.validate()?;
        if config.mode == Mode::EkfBlr
            && (model.transition_local.is_none() || model.sensor_local.is_none())
        {
            return Err(CoreError::InvalidSpec(
                "EKF+BLR needs the local training data in the model",
            ));
        }
        Ok(Self { model, config })
    }

    /// Scratch values [`Ekf::step`] needs (faer-style sizing).
    pub fn scratch_len(&self) -> usize {
        Estimator::scratch_len(&self.model)
    }

    /// The model view.
    pub fn model(&self) -> &HbnView<'m> {
        &self.model
    }

    /// The settings.
    pub fn config(&self) -> &EkfConfig {
        &self.config
    }

    /// Processes sample `k`: input `u_k` and measurement `y_k`, advancing `state` (`None`
    /// before the first sample: the step initialises it). Allocation-free, panic-free, bounded
    /// time. A `scratch` shorter than [`Ekf::scratch_len`] makes every prediction fail, which
    /// the step reports as [`Flags::MODEL_INVALID`] (the [`Estimator`] checks it once).
    pub fn step(
        &self,
        state: &mut Option<EkfState>,
        scratch: &mut [f64],
        u_k: f64,
        y_k: f64,
    ) -> StepOutput {
        let mut flags = 0u32;
        let cfg = self.config;
        let Some(mut st) = *state else {
            let (st, out) = self.initialise(u_k, y_k);
            *state = Some(st);
            return out;
        };
        let u_k = if u_k.is_finite() {
            u_k
        } else {
            flags |= Flags::INPUT_INVALID;
            st.u_last
        };

        // ---- predict ----
        let pred = match cfg.mode {
            Mode::Ukf => {
                self.predict_unscented::<false>(&mut st, scratch, &mut flags)
                    .0
            }
            Mode::Ekf | Mode::EkfBlr => self.predict_linearised(&mut st, scratch, &mut flags),
        };
        st.p = bound_covariance(st.p, cfg.p_min, cfg.p_max, &mut flags);
        st.u_prev = st.u_last;
        st.u_last = u_k;
        self.model.plays.advance(&mut st.plays, u_k);

        // ---- update ----
        let (innovation, s_var, nis) = update(&mut st, y_k, pred.r, &cfg, &mut flags);
        st.steps = st.steps.saturating_add(1);
        if pred.left_box {
            st.lost_run = st.lost_run.saturating_add(1);
            if st.lost_run >= LOST_AFTER {
                self.relocalise(&mut st, y_k, &mut flags);
            }
        } else {
            st.lost_run = 0;
        }
        self.model.sensor_memory.advance(&mut st.memory, st.z.x);
        *state = Some(st);
        StepOutput {
            x: st.z.x,
            x_std: cfg.std_scale * sqrt(st.p.m11.max(0.0)),
            y_pred: pred.s_pred,
            innovation,
            innovation_var: s_var,
            nis,
            q_x: pred.q_x,
            r: pred.r,
            jacobian: pred.jacobian,
            flags: Flags(flags),
        }
    }

    /// The prediction phase of the next step from `state` (the filtered state after the last
    /// step), exactly as [`Ekf::step`] computes it, without updating anything: the predicted
    /// mean and covariance and the cross-covariance with `state` ([`StepPrediction`]). The next
    /// step does not depend on it, so a filter that records nothing does not pay for it; an
    /// offline smoother calls it before each step (it costs one more prediction per sample).
    /// Allocation-free, panic-free, bounded time; `scratch` as for [`Ekf::step`].
    pub fn predict(&self, state: &EkfState, scratch: &mut [f64]) -> StepPrediction {
        let cfg = self.config;
        let mut st = *state;
        let mut flags = 0u32;
        let (pred, cross) = match cfg.mode {
            Mode::Ukf => self.predict_unscented::<true>(&mut st, scratch, &mut flags),
            Mode::Ekf | Mode::EkfBlr => {
                (self.predict_linearised(&mut st, scratch, &mut flags), None)
            }
        };
        let cross = cross.unwrap_or_else(|| state.p * pred.jacobian.transpose());
        let p = bound_covariance(st.p, cfg.p_min, cfg.p_max, &mut flags);
        StepPrediction {
            z: st.z,
            p,
            cross,
            flags: Flags(flags),
        }
    }

    /// The first sample: `x_0` from the model's [`InitPrior`] at `y_0` when it has one and
    /// `y_0` is finite, else from the settings.
    fn initialise(&self, u_k: f64, y_k: f64) -> (EkfState, StepOutput) {
        let cfg = self.config;
        let (x0_mean, x0_var) = self
            .model
            .init
            .and_then(|prior| prior.prior(y_k))
            .unwrap_or((cfg.x0_mean, cfg.x0_var));
        let mut flags = Flags::INITIALISED;
        let u0 = if u_k.is_finite() {
            u_k
        } else {
            flags |= Flags::INPUT_INVALID;
            0.0
        };
        let r = self.fallback_r();
        let s0 = if y_k.is_finite() {
            clamp_flag(y_k, cfg.y_bounds, &mut flags)
        } else {
            flags |= Flags::MEASUREMENT_INVALID;
            0.5 * (cfg.y_bounds.0 + cfg.y_bounds.1)
        };
        let s_var = if y_k.is_finite() { r } else { cfg.p_max };
        let p = Matrix3::new(x0_var, x0_var, 0.0, x0_var, x0_var, 0.0, 0.0, 0.0, s_var);
        let mut f = flags;
        let p = bound_covariance(p, cfg.p_min, cfg.p_max, &mut f);
        let st = EkfState {
            z: Vector3::new(x0_mean, x0_mean, s0),
            p,
            u_last: u0,
            u_prev: u0,
            plays: self.model.plays.start(u0),
            memory: self.model.sensor_memory.start(x0_mean),
            steps: 1,
            rejected_run: 0,
            lost_run: 0,
        };
        let out = StepOutput {
            x: st.z.x,
            x_std: cfg.std_scale * sqrt(st.p.m11),
            y_pred: s0,
            innovation: 0.0,
            innovation_var: s_var,
            nis: 0.0,
            q_x: 0.0,
            r,
            jacobian: Matrix3::identity(),
            flags: Flags(f),
        };
        (st, out)
    }

    /// A lost filter's re-start: `x_k` and `x_{k-1}` from the model's [`InitPrior`] at `y_k`,
    /// uncorrelated with `s_k`, which is `y_k` with the variance of the first step. The
    /// inputs, their plays and the counters of steps are kept; the plays of the state restart
    /// at the new estimate. Nothing happens without a prior or with a non-finite `y_k` (the run
    /// counter then keeps counting).
    fn relocalise(&self, st: &mut EkfState, y_k: f64, flags: &mut u32) {
        let cfg = self.config;
        let Some((x_mean, x_var)) = self.model.init.and_then(|prior| prior.prior(y_k)) else {
            return;
        };
        let s = clamp_to(y_k, cfg.y_bounds.0, cfg.y_bounds.1);
        let x = clamp_to(x_mean, cfg.x_bounds.0, cfg.x_bounds.1);
        let r = self.fallback_r();
        let p = Matrix3::new(x_var, x_var, 0.0, x_var, x_var, 0.0, 0.0, 0.0, r);
        st.z = Vector3::new(x, x, s);
        st.p = bound_covariance(p, cfg.p_min, cfg.p_max, flags);
        st.memory = self.model.sensor_memory.start(x);
        st.lost_run = 0;
        st.rejected_run = 0;
        *flags |= Flags::RELOCALISED;
    }

    /// The prediction's noise variances at the linearisation point: `q_x` (transition) and
    /// `q_s` (sensor) of `Q`, and `R`.
    fn noises(&self, t: &Local, s: &Local, flags: &mut u32) -> (f64, f64, f64) {
        let cfg = &self.config;
        let q_x = floor_flag(
            cfg.q_scale * (t.noise + t.epistemic).max(cfg.qx_model_floor),
            cfg.q_floor,
            flags,
        );
        let q_s = floor_flag(cfg.q_scale * s.epistemic, cfg.q_floor, flags);
        let r = floor_flag(
            cfg.r_scale * s.noise.max(cfg.r_model_floor),
            cfg.r_floor,
            flags,
        );
        (q_x, q_s, r)
    }

    /// `R` when the sensor GP could not be evaluated (and at the first step): its learned
    /// noise, scaled and floored; the floor if the scaled noise overflows (as in `noises`: a
    /// huge `r_scale` gives `R = inf`, which the `step` fuzz target reaches).
    fn fallback_r(&self) -> f64 {
        let cfg = &self.config;
        let r = cfg.r_scale * self.model.sensor.noise_variance().max(cfg.r_model_floor);
        if r.is_finite() && r >= cfg.r_floor {
            r
        } else {
            cfg.r_floor
        }
    }

    /// The HBN's Jacobian `F` (module docs) from the transition gradient `a` and the sensor
    /// gradient `b` (w.r.t. `x_{k-1}, s_{k-1}, x_k`).
    fn jacobian(a1: f64, a2: f64, c: f64, e: f64, f: f64) -> Matrix3<f64> {
        Matrix3::new(a1, a2, 0.0, 1.0, 0.0, 0.0, c + f * a1, f * a2, e)
    }

    /// Prediction when the transition GP failed: a random walk with a large process noise.
    fn random_walk(&self, st: &mut EkfState) -> Predicted {
        let big = self.config.p_max * 0.01;
        let f_mat = Matrix3::new(1.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0);
        let (x1, s1) = (st.z.x, st.z.z);
        st.z = Vector3::new(x1, x1, s1);
        st.p =
            f_mat * st.p * f_mat.transpose() + Matrix3::from_diagonal(&Vector3::new(big, 0.0, big));
        Predicted {
            q_x: big,
            r: self.fallback_r(),
            s_pred: s1,
            jacobian: f_mat,
            left_box: false,
        }
    }

    /// EKF / EKF+BLR prediction: linearise both GPs at the estimate, `P = F P F^T + Q`.
    fn predict_linearised(
        &self,
        st: &mut EkfState,
        scratch: &mut [f64],
        flags: &mut u32,
    ) -> Predicted {
        let cfg = self.config;
        let (x1, x2, s1) = (st.z.x, st.z.y, st.z.z);
        let a_in = self.transition_input(st, x1, x2);
        let Some(t) = self.linearise(Relation::Transition, &a_in, scratch, flags) else {
            return self.random_walk(st);
        };
        let xk = clamp_flag(t.mean, cfg.x_bounds, flags);
        let a1 = clamp_jac(t.grad[0], cfg.jac_max, flags);
        let a2 = clamp_jac(t.grad[1], cfg.jac_max, flags);
        let b_in = self.sensor_input(st, x1, s1, xk);
        let (f_mat, g_vec, q_x, q_s, r, s_pred) = match self.linearise_sensor(&b_in, scratch, flags)
        {
            Some(s) => {
                let c = clamp_jac(s.grad[0], cfg.jac_max, flags);
                let e = clamp_jac(s.grad[1], cfg.jac_max, flags);
                let f = clamp_jac(s.grad[2], cfg.jac_max, flags);
                let (q_x, q_s, r) = self.noises(&t, &s, flags);
                let s_pred = clamp_flag(s.mean, cfg.y_bounds, flags);
                (
                    Self::jacobian(a1, a2, c, e, f),
                    Vector3::new(1.0, 0.0, f),
                    q_x,
                    q_s,
                    r,
                    s_pred,
                )
            }
            None => {
                let q_x = floor_flag(
                    cfg.q_scale * (t.noise + t.epistemic).max(cfg.qx_model_floor),
                    cfg.q_floor,
                    flags,
                );
                (
                    Matrix3::new(a1, a2, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0),
                    Vector3::new(1.0, 0.0, 0.0),
                    q_x,
                    cfg.p_max * 0.01,
                    self.fallback_r(),
                    s1,
                )
            }
        };
        st.z = Vector3::new(xk, x1, s_pred);
        let q = g_vec * q_x * g_vec.transpose()
            + Matrix3::new(0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, q_s);
        st.p = f_mat * st.p * f_mat.transpose() + q;
        Predicted {
            q_x,
            r,
            s_pred,
            jacobian: f_mat,
            left_box: outside(t.mean, cfg.x_bounds),
        }
    }

    /// Unscented prediction (spherical-cubature rule: the UKF with `alpha = 1`, `beta = 0`,
    /// `kappa = 0`, all weights `1/8`, so the predicted covariance is positive semi-definite by
    /// construction). The augmented state `[x_{k-1}, x_{k-2}, s_{k-1}, w]` with covariance
    /// `diag(P, q_x)` gives 8 sigma points `mean +- 2 L_i` (`L` its Cholesky factor); each
    /// passes through `x_k = H_D(x_{k-1}, x_{k-2}, u_{k-1}, u_{k-2}) + w` and
    /// `s_k = H_S(x_{k-1}, s_{k-1}, x_k)` (GP means). `P` is their covariance plus `q_s`
    /// on `s`. `q_x`, `q_s` and `R` come from the GP variances at the mean, as in the EKF; the
    /// reported Jacobian is the EKF's at the mean (a diagnostic: the UKF does not use it).
    ///
    /// With `CROSS`, it also returns the sigma points' cross-covariance `cov(z_{k-1}, z_k^-)`
    /// ([`Ekf::predict`]); `None` when it fell back to the random walk. Without it (the step)
    /// nothing more is computed.
    fn predict_unscented<const CROSS: bool>(
        &self,
        st: &mut EkfState,
        scratch: &mut [f64],
        flags: &mut u32,
    ) -> (Predicted, Option<Matrix3<f64>>) {
        let cfg = self.config;
        let (x1, x2, s1) = (st.z.x, st.z.y, st.z.z);
        let Some(t) = self.linearise(
            Relation::Transition,
            &self.transition_input(st, x1, x2),
            scratch,
            flags,
        ) else {
            return (self.random_walk(st), None);
        };
        let xk_mean = clamp_to(t.mean, cfg.x_bounds.0, cfg.x_bounds.1);
        let Some(s) =
            self.linearise_sensor(&self.sensor_input(st, x1, s1, xk_mean), scratch, flags)
        else {
            *flags |= Flags::MODEL_INVALID;
            return (self.random_walk(st), None);
        };
        let (q_x, q_s, r) = self.noises(&t, &s, flags);
        let Some(l) = cholesky3(&st.p) else {
            *flags |= Flags::MODEL_INVALID;
            return (self.random_walk(st), None);
        };
        // sqrt(n) with n = 4 augmented dimensions.
        let spread = 2.0;
        let w_dev = spread * sqrt(q_x);
        let mut sum = Vector3::zeros();
        let mut free_sum = Vector3::zeros();
        let mut points = [Vector3::zeros(); 8];
        let mut boxed_points = [Vector3::zeros(); 8];
        // The state deviation of each point (the cross-covariance's left factor).
        let mut deviations = [Vector3::zeros(); 8];
        let mut ok = true;
        for (i, (point, boxed)) in points.iter_mut().zip(&mut boxed_points).enumerate() {
            let sign = if i % 2 == 0 { spread } else { -spread };
            // Points 0..6: the state columns of `L`; points 6, 7: the noise `w`.
            let column = match i / 2 {
                0 => Some(Vector3::new(l.m11, l.m21, l.m31)),
                1 => Some(Vector3::new(0.0, l.m22, l.m32)),
                2 => Some(Vector3::new(0.0, 0.0, l.m33)),
                _ => None,
            };
            let (dz, w) = match column {
                Some(col) => (col * sign, 0.0),
                None => (Vector3::zeros(), if i % 2 == 0 { w_dev } else { -w_dev }),
            };
            if CROSS && let Some(d) = deviations.get_mut(i) {
                *d = dz;
            }
            let (a, b, c) = (x1 + dz.x, x2 + dz.y, s1 + dz.z);
            let xk = if dz.x == 0.0 && dz.y == 0.0 {
                Some(t.mean)
            } else {
                self.mean_of(
                    Relation::Transition,
                    &self.transition_input(st, a, b),
                    scratch,
                )
            };
            let Some(xk) = xk else {
                ok = false;
                break;
            };
            let xk = xk + w;
            // A point pushed into the box flags it, as a clamped EKF prediction does.
            let x_in = clamp_flag(xk, cfg.x_bounds, flags);
            let Some(sk) = self.mean_of(
                Relation::Sensor,
                &self.sensor_input(st, a, c, x_in).input,
                scratch,
            ) else {
                ok = false;
                break;
            };
            // The mean is that of the points clamped to the box (the state's support); the
            // covariance is that of the points as they are. Clamping them for the covariance
            // too would collapse their spread where the state is pinned against its bound, so
            // the reported std would fall to the floor exactly where the estimate is worst (a
            // std of 5e-7 and a mean NEES of 5e8 on a noise-free Preisach run).
            *point = Vector3::new(xk, a, sk);
            *boxed = Vector3::new(x_in, a, clamp_to(sk, cfg.y_bounds.0, cfg.y_bounds.1));
            sum += *boxed;
            free_sum += *point;
        }
        if !ok {
            *flags |= Flags::MODEL_INVALID;
            return (self.random_walk(st), None);
        }
        let mean = sum / 8.0;
        let free_mean = free_sum / 8.0;
        let mut p = Matrix3::zeros();
        for point in &points {
            let dev = point - free_mean;
            p += dev * dev.transpose();
        }
        p /= 8.0;
        p.m33 += q_s;
        let cross = CROSS.then(|| {
            let mut c = Matrix3::zeros();
            for (dev, point) in deviations.iter().zip(&points) {
                c += dev * (point - free_mean).transpose();
            }
            c / 8.0
        });
        let cj = |v: f64| {
            if v.is_finite() {
                clamp_to(v, -cfg.jac_max, cfg.jac_max)
            } else {
                0.0
            }
        };
        let jacobian = Self::jacobian(
            cj(t.grad[0]),
            cj(t.grad[1]),
            cj(s.grad[0]),
            cj(s.grad[1]),
            cj(s.grad[2]),
        );
        st.z = Vector3::new(
            clamp_flag(mean.x, cfg.x_bounds, flags),
            clamp_flag(mean.y, cfg.x_bounds, flags),
            clamp_flag(mean.z, cfg.y_bounds, flags),
        );
        st.p = p;
        let pred = Predicted {
            q_x,
            r,
            s_pred: st.z.z,
            jacobian,
            left_box: outside(t.mean, cfg.x_bounds),
        };
        (pred, cross)
    }

    /// The transition's input at states `x_{k-1} = x1`, `x_{k-2} = x2`: the inputs and plays
    /// come from the state (all [`MAX_DIM`] values; the GP reads its first `dim`).
    fn transition_input(&self, st: &EkfState, x1: f64, x2: f64) -> [f64; MAX_DIM] {
        transition_input(x1, x2, st.u_last, st.u_prev, &st.plays)
    }

    /// The sensor GP's input at `x_{k-1} = x1`, `s_{k-1} = s1`, `x_k = xk`: `[x1, s1, xk]`,
    /// `[x1, xk, 0]` for a sensor of the state only (the GP reads its first two), or
    /// `[xk, q^1, .., q^m]` for a sensor with memory, each play `q^i` moved from the state's
    /// [`EkfState::memory`] by `xk` (the GP reads its first `1 + m`).
    fn sensor_input(&self, st: &EkfState, x1: f64, s1: f64, xk: f64) -> SensorPoint {
        const X1: [f64; 3] = [1.0, 0.0, 0.0];
        const S1: [f64; 3] = [0.0, 1.0, 0.0];
        const XK: [f64; 3] = [0.0, 0.0, 1.0];
        const NONE: [f64; 3] = [0.0; 3];
        let memory = self.model.sensor_memory;
        if !memory.is_empty() {
            let mut point = SensorPoint {
                input: [xk; SENSOR_DIM],
                chain: [XK, NONE, NONE],
            };
            for ((r, q), (slot, row)) in memory
                .radii()
                .iter()
                .zip(&st.memory)
                .zip(point.input.iter_mut().zip(&mut point.chain).skip(1))
            {
                let held = crate::play::clamp_play(*q, xk - r, xk + r);
                *slot = held;
                // The play moves with `x_k` where `x_k` drags it (at either edge of its band).
                *row = if held == *q { NONE } else { XK };
            }
            point
        } else if self.model.sensor.dim() == SENSOR_STATE_DIM {
            SensorPoint {
                input: [x1, xk, 0.0],
                chain: [X1, XK, NONE],
            }
        } else {
            SensorPoint {
                input: [x1, s1, xk],
                chain: [X1, S1, XK],
            }
        }
    }

    /// [`Ekf::linearise`] of the sensor at `point`, its gradient w.r.t. `(x_{k-1}, s_{k-1},
    /// x_k)`.
    fn linearise_sensor(
        &self,
        point: &SensorPoint,
        scratch: &mut [f64],
        flags: &mut u32,
    ) -> Option<Local> {
        let mut local = self.linearise(Relation::Sensor, &point.input, scratch, flags)?;
        point.gradient(&mut local);
        Some(local)
    }

    /// The GP mean of one relation at `input` (no variance, no gradient), `None` on failure.
    fn mean_of(&self, which: Relation, input: &[f64], scratch: &mut [f64]) -> Option<f64> {
        let gp = match which {
            Relation::Transition => &self.model.transition,
            Relation::Sensor => &self.model.sensor,
        };
        let input = input.get(..gp.dim())?;
        gp.predict_mean(input, scratch)
            .ok()
            .filter(|m| m.is_finite())
    }

    /// Linearises one relation of the HBN at `input` in the configured mode.
    fn linearise(
        &self,
        which: Relation,
        input: &[f64],
        scratch: &mut [f64],
        flags: &mut u32,
    ) -> Option<Local> {
        let (gp, local, blr_empty) = match which {
            Relation::Transition => (
                &self.model.transition,
                self.model.transition_local,
                Flags::BLR_EMPTY_TRANSITION,
            ),
            Relation::Sensor => (
                &self.model.sensor,
                self.model.sensor_local,
                Flags::BLR_EMPTY_SENSOR,
            ),
        };
        let d = gp.dim();
        // `HbnView::validate` fixed `d` at 4 + plays (transition) or 3 (sensor), at most the
        // input's length.
        let Some(input) = input.get(..d) else {
            *flags |= Flags::MODEL_INVALID;
            return None;
        };
        let p = match gp.predict(input, Want::EKF, scratch) {
            Ok(p) => p,
            Err(_) => {
                *flags |= Flags::MODEL_INVALID;
                return None;
            }
        };
        let mut out = Local {
            mean: p.mean,
            grad: [0.0; 4],
            noise: gp.noise_variance(),
            epistemic: p.variance,
        };
        if p.variance > EXTRAPOLATION_RATIO * p.prior_variance.min(gp.output_variance()) {
            *flags |= Flags::EXTRAPOLATION;
        }
        for (g, pg) in out.grad.iter_mut().zip(&p.grad_mean).take(d) {
            *g = *pg;
        }
        if self.config.mode == Mode::EkfBlr
            && let Some(nb) = local
        {
            let post = self.model.blr.posterior(
                &nb,
                input,
                p.mean,
                p.grad_mean.get(..d).unwrap_or(&[]),
                p.variance,
                out.noise,
            );
            if post.n == 0 {
                *flags |= blr_empty;
            }
            if post.capped {
                *flags |= Flags::BLR_CAPPED;
            }
            if post.noise.is_finite()
                && post.grad.iter().take(d).all(|g| g.is_finite())
                && post.intercept.is_finite()
            {
                out.mean += post.intercept;
                for (g, pg) in out.grad.iter_mut().zip(&post.grad).take(d) {
                    *g = *pg;
                }
                // BLR's expected noise covariance replaces the GP's learned (homoscedastic)
                // noise; the GP's epistemic variance still applies.
                out.noise = post.noise;
            }
        }
        if !(out.mean.is_finite()
            && out.noise.is_finite()
            && out.epistemic.is_finite()
            && out.grad.iter().all(|g| g.is_finite()))
        {
            *flags |= Flags::MODEL_INVALID;
            return None;
        }
        Some(out)
    }
}

/// The estimator for firmware: a checked [`Ekf`], its state and the caller's scratch memory,
/// all borrowed. (`hbn_model::Filter` is the std twin that owns model, state and scratch.)
#[derive(Debug)]
pub struct Estimator<'m, 's> {
    ekf: Ekf<'m>,
    state: Option<EkfState>,
    scratch: &'s mut [f64],
}

impl<'m, 's> Estimator<'m, 's> {
    /// Scratch values [`Estimator::new`] needs for `model` (faer-style sizing).
    pub fn scratch_len(model: &HbnView<'_>) -> usize {
        model
            .transition
            .predict_scratch(Want::EKF)
            .max(model.sensor.predict_scratch(Want::EKF))
    }

    /// Checks model, settings and scratch size once; the step then cannot fail.
    pub fn new(
        model: HbnView<'m>,
        config: EkfConfig,
        scratch: &'s mut [f64],
    ) -> Result<Self, CoreError> {
        let ekf = Ekf::new(model, config)?;
        let needed = ekf.scratch_len();
        if scratch.len() < needed {
            return Err(CoreError::ScratchTooSmall {
                needed,
                got: scratch.len(),
            });
        }
        Ok(Self {
            ekf,
            state: None,
            scratch,
        })
    }

    /// The current state (`None` before the first step).
    pub fn state(&self) -> Option<&EkfState> {
        self.state.as_ref()
    }

    /// The settings.
    pub fn config(&self) -> &EkfConfig {
        self.ekf.config()
    }

    /// Forgets the state; the next step initialises again.
    pub fn reset(&mut self) {
        self.state = None;
    }

    /// Processes sample `k` ([`Ekf::step`]). Allocation-free, panic-free, bounded time.
    pub fn step(&mut self, u_k: f64, y_k: f64) -> StepOutput {
        self.ekf.step(&mut self.state, self.scratch, u_k, y_k)
    }
}

/// Measurement update with the Joseph form; returns (innovation, S, NIS).
fn update(
    st: &mut EkfState,
    y_k: f64,
    r: f64,
    cfg: &EkfConfig,
    flags: &mut u32,
) -> (f64, f64, f64) {
    // `P_ss + R` of two finite variances can still overflow (`P_ss` near `p_max` and a huge
    // `R`; the `step` fuzz target reaches it): saturated at the largest finite value, it is a
    // measurement that carries no information, as it should be.
    let s_var = saturating_sum(st.p.m33, r);
    if !y_k.is_finite() {
        *flags |= Flags::MEASUREMENT_INVALID;
        return (0.0, s_var, 0.0);
    }
    if !(s_var.is_finite() && s_var >= cfg.innovation_min) {
        *flags |= Flags::INNOVATION_SINGULAR;
        return (0.0, s_var, 0.0);
    }
    let innovation = y_k - st.z.z;
    let nis = innovation * innovation / s_var;
    // The outlier gate down-weights: `S` becomes `nu^2 / gate` (larger than `S`, finite as
    // `nu` is) and `R` grows by the same amount, so the Joseph form below stays consistent.
    let (s_used, r) = if cfg.nis_gate > 0.0 && nis > cfg.nis_gate {
        *flags |= Flags::OUTLIER_REJECTED;
        st.rejected_run = st.rejected_run.saturating_add(1);
        let s_gated = innovation * innovation / cfg.nis_gate;
        (s_gated, r + (s_gated - s_var))
    } else {
        st.rejected_run = 0;
        (s_var, r)
    };
    let gain: Vector3<f64> = st.p.column(2) / s_used;
    let z = st.z + gain * innovation;
    // Joseph form: P = (I - K H) P (I - K H)^T + K R K^T, H = [0, 0, 1].
    // `I - K H`: the identity with `K` subtracted from its last column (written out, with the
    // same `0 - k` / `1 - k` arithmetic as an in-place subtraction).
    let i_kh: Matrix3<f64> = Matrix3::new(
        1.0,
        0.0,
        0.0 - gain.x,
        0.0,
        1.0,
        0.0 - gain.y,
        0.0,
        0.0,
        1.0 - gain.z,
    );
    let p: Matrix3<f64> = i_kh * st.p * i_kh.transpose() + gain * r * gain.transpose();
    if z.iter().all(|v| v.is_finite()) && p.iter().all(|v| v.is_finite()) {
        st.z = Vector3::new(
            clamp_flag(z.x, cfg.x_bounds, flags),
            clamp_flag(z.y, cfg.x_bounds, flags),
            clamp_flag(z.z, cfg.y_bounds, flags),
        );
        st.p = bound_covariance(p, cfg.p_min, cfg.p_max, flags);
    } else {
        *flags |= Flags::INNOVATION_SINGULAR;
    }
    (innovation, s_var, nis)
}

/// `a + b`, or `f64::MAX` where the sum overflows (both are finite, non-negative variances).
fn saturating_sum(a: f64, b: f64) -> f64 {
    let s = a + b;
    if s.is_finite() { s } else { f64::MAX }
}

/// Symmetrises `p` and clamps its eigenvalues into `[lo, hi]`.
fn bound_covariance(p: Matrix3<f64>, lo: f64, hi: f64, flags: &mut u32) -> Matrix3<f64> {
    let sym = (p + p.transpose()) * 0.5;
    if !sym.iter().all(|v| v.is_finite()) {
        *flags |= Flags::COVARIANCE_CLAMPED;
        return Matrix3::identity() * hi;
    }
    // Cheap exit: Gershgorin discs inside [lo, hi] mean every eigenvalue is.
    let mut inside = true;
    let entry = |i: usize, j: usize| sym.get((i, j)).copied().unwrap_or(0.0);
    for i in 0..3 {
        let radius: f64 = (0..3).filter(|&j| j != i).map(|j| entry(i, j).abs()).sum();
        if entry(i, i) - radius < lo || entry(i, i) + radius > hi {
            inside = false;
        }
    }
    if inside || inside_by_ldl(&sym, lo, hi) {
        return sym;
    }
    // Our own Jacobi solver, written without indexing: the link-time no-panic proof
    // (`crates/hbn-core/nopanic`) covers it with the rest of the step.
    match crate::eigen::symmetric_eigen3(&sym) {
        Some((eigenvalues, eigenvectors)) => {
            let mut vals = eigenvalues;
            let mut changed = false;
            for v in vals.iter_mut() {
                let c = clamp_to(*v, lo, hi);
                if c != *v {
                    changed = true;
                    *v = c;
                }
            }
            if !changed {
                return sym;
            }
            *flags |= Flags::COVARIANCE_CLAMPED;
            let q = eigenvectors;
            let out = q * Matrix3::from_diagonal(&vals) * q.transpose();
            (out + out.transpose()) * 0.5
        }
        None => {
            *flags |= Flags::COVARIANCE_CLAMPED;
            Matrix3::identity() * hi
        }
    }
}

/// True when every eigenvalue of the symmetric `p` is certainly inside `[lo, hi]` (`lo >= 0`):
/// `p - lo I` has an `L D L^T` factorisation with `D > 0` (so it is positive definite), and
/// the trace, the sum of the then positive eigenvalues, is at most `hi`. It decides most
/// steps, whose `x_k` and `x_{k-1}` are too correlated for the Gershgorin test, at a fraction
/// of a Jacobi sweep (without it the eigen-solver takes 11% of a sparse m = 64 step).
/// `false` sends the caller to the eigen-decomposition, which decides exactly.
fn inside_by_ldl(p: &Matrix3<f64>, lo: f64, hi: f64) -> bool {
    if !(lo >= 0.0 && p.trace() <= hi) {
        return false;
    }
    let (a11, a22, a33) = (p.m11 - lo, p.m22 - lo, p.m33 - lo);
    let (a21, a31, a32) = (p.m21, p.m31, p.m32);
    // Written so that a NaN anywhere answers `false`.
    let d1 = a11;
    if d1 > 0.0 {
        let (l21, l31) = (a21 / d1, a31 / d1);
        let d2 = a22 - l21 * a21;
        if d2 > 0.0 {
            let l32 = (a32 - l31 * a21) / d2;
            let d3 = a33 - l31 * a31 - l32 * l32 * d2;
            return d3 > 0.0 && d3.is_finite();
        }
    }
    false
}

/// Whether `v` lies outside `[b.0, b.1]` (or is not a number).
fn outside(v: f64, b: (f64, f64)) -> bool {
    !(v >= b.0 && v <= b.1)
}

fn clamp_flag(v: f64, b: (f64, f64), flags: &mut u32) -> f64 {
    let c = if v.is_finite() {
        clamp_to(v, b.0, b.1)
    } else {
        0.5 * (b.0 + b.1)
    };
    if c != v {
        *flags |= Flags::STATE_CLAMPED;
    }
    c
}

fn clamp_jac(v: f64, max: f64, flags: &mut u32) -> f64 {
    let c = if v.is_finite() {
        clamp_to(v, -max, max)
    } else {
        0.0
    };
    if c != v {
        *flags |= Flags::JACOBIAN_CLAMPED;
    }
    c
}

fn floor_flag(v: f64, floor: f64, flags: &mut u32) -> f64 {
    if v.is_finite() && v >= floor {
        v
    } else {
        *flags |= Flags::NOISE_FLOOR;
        floor
    }
}

fn sqrt(v: f64) -> f64 {
    crate::simd::sqrt(v)
}

/// Smallest and largest eigenvalue of the observability Gramian over the last `h + 1`
/// linearisations (thesis Sec. 4.2): `sum_s Phi_s^T H^T R_s^{-1} H Phi_s` with
/// `Phi_0 = I`, `Phi_{s+1} = F_s Phi_s`, `H = [0, 0, 1]`. `jacobians` and `r` are oldest first.
pub fn observability_eigenvalues(jacobians: &[Matrix3<f64>], r: &[f64]) -> Option<(f64, f64)> {
    let gram = observability_gramian(jacobians, r)?;
    let (v, _) = crate::eigen::symmetric_eigen3(&gram)?;
    let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
    for x in v.iter() {
        lo = lo.min(*x);
        hi = hi.max(*x);
    }
    Some((lo.max(0.0), hi))
}

/// The observability Gramian of [`observability_eigenvalues`].
fn observability_gramian(jacobians: &[Matrix3<f64>], r: &[f64]) -> Option<Matrix3<f64>> {
    if jacobians.is_empty() || jacobians.len() != r.len() {
        return None;
    }
    let mut phi = Matrix3::<f64>::identity();
    let mut gram = Matrix3::<f64>::zeros();
    for (k, (f, &rk)) in jacobians.iter().zip(r).enumerate() {
        if k > 0 {
            phi = f * phi;
        }
        let row = phi.row(2);
        let w = 1.0 / rk.max(f64::MIN_POSITIVE);
        gram += row.transpose() * row * w;
    }
    Some(gram)
}

/// What the measurements of the window say about `x` itself: the information on the first
/// state component with the other two (`x_{k-1}`, `s`) left free, the Schur complement
/// `G_00 - g^T G_RR^+ g` of the Gramian `G` of [`observability_eigenvalues`] (`R` the other
/// two components; `^+` a pseudo-inverse that drops eigenvalues below `1e-12` of the largest).
/// Unlike the smallest eigenvalue, it stays large when a component that does not matter is
/// unobservable: where the transition no longer reads `x_{k-2}` (its gradient `0`), `x_{k-1}`
/// cannot be seen, but it does not affect anything either. `None` for an empty or mismatched
/// window or a non-finite Gramian.
pub fn state_information(jacobians: &[Matrix3<f64>], r: &[f64]) -> Option<f64> {
    let g = observability_gramian(jacobians, r)?;
    if !g.iter().all(|v| v.is_finite()) {
        return None;
    }
    // The 2x2 block of the other components, by its eigen-decomposition.
    let (a, b, d) = (g.m22, g.m23, g.m33);
    let half_tr = 0.5 * (a + d);
    let disc = sqrt((0.5 * (a - d)) * (0.5 * (a - d)) + b * b);
    let (l1, l2) = (half_tr + disc, half_tr - disc);
    // Unit eigenvector of l1 (the other is orthogonal).
    let (v1x, v1y) = if b.abs() > 0.0 {
        let (x, y) = (l1 - d, b);
        let n = sqrt(x * x + y * y);
        (x / n, y / n)
    } else if a >= d {
        (1.0, 0.0)
    } else {
        (0.0, 1.0)
    };
    let (v2x, v2y) = (-v1y, v1x);
    let scale = l1.abs().max(g.m11.abs());
    let (gx, gy) = (g.m12, g.m13);
    let mut explained = 0.0;
    for (l, vx, vy) in [(l1, v1x, v1y), (l2, v2x, v2y)] {
        if l > 1e-12 * scale {
            let p = gx * vx + gy * vy;
            explained += p * p / l;
        }
    }
    let info = g.m11 - explained;
    info.is_finite().then_some(info.max(0.0))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rng::Rng;

    fn gate_config(nis_gate: f64) -> EkfConfig {
        EkfConfig {
            mode: Mode::Ekf,
            q_floor: 1e-8,
            r_floor: 1e-8,
            qx_model_floor: 0.0,
            r_model_floor: 0.0,
            p_min: 1e-12,
            p_max: 1e3,
            jac_max: 1e3,
            innovation_min: 1e-12,
            nis_gate,
            x_bounds: (-1e3, 1e3),
            y_bounds: (-1e3, 1e3),
            x0_mean: 0.0,
            x0_var: 1.0,
            q_scale: 1.0,
            r_scale: 1.0,
            std_scale: 1.0,
        }
    }

    fn gate_state() -> EkfState {
        EkfState {
            z: Vector3::new(0.2, 0.1, 0.5),
            p: Matrix3::new(0.04, 0.01, 0.02, 0.01, 0.03, 0.01, 0.02, 0.01, 0.05),
            u_last: 0.0,
            u_prev: 0.0,
            plays: [0.0; crate::play::MAX_PLAYS],
            memory: [0.0; crate::play::MAX_PLAYS],
            steps: 5,
            rejected_run: 0,
            lost_run: 0,
        }
    }

    /// A GP that is its linear mean `sum_j slopes_j x_j` (one support point with zero weight;
    /// a small, finite variance from a long-length-scale kernel).
    /// A model of two [`linear_gp`]s (transition slopes `slopes_t`, sensor slopes `slopes_s`,
    /// the kernel's first `1 + dim` entries of `theta` each) and nothing else: no local
    /// regressions, prior, plays or sensor memory.
    fn linear_view<'a>(
        theta: &'a [f64],
        zeros: &'a [f64],
        ones: &'a [f64],
        slopes_t: &'a [f64],
        slopes_s: &'a [f64],
    ) -> HbnView<'a> {
        HbnView {
            transition: linear_gp(&theta[..=slopes_t.len()], zeros, ones, slopes_t),
            sensor: linear_gp(&theta[..=slopes_s.len()], zeros, ones, slopes_s),
            transition_local: None,
            sensor_local: None,
            blr: LocalRegression::default(),
            init: None,
            plays: Plays::NONE,
            sensor_memory: Plays::NONE,
        }
    }

    fn linear_gp<'a>(
        theta: &'a [f64],
        zeros: &'a [f64],
        ones: &'a [f64],
        slopes: &'a [f64],
    ) -> GpView<'a> {
        let d = slopes.len();
        GpView::new(crate::gp::GpParts {
            kernel: crate::kernel::Kernel::new(crate::kernel::KernelSpec::se_ard(d), theta, &[])
                .unwrap(),
            input_mean: &zeros[..d],
            input_scale: &ones[..d],
            output_mean: 0.0,
            output_scale: 1.0,
            linear: slopes,
            features: &zeros[..d],
            directions: &[],
            alpha: &zeros[..1],
            alpha_lo: &[],
            variance: crate::gp::Variance::Exact {
                chol_packed: &ones[..1],
            },
            noise_var: 1e-6,
        })
        .unwrap()
    }

    /// A sensor of the state only (`[x_{k-1}, x_k]`, dimension 2) steps as the thesis' sensor
    /// (`[x_{k-1}, y_{k-1}, x_k]`) whose mean has no slope in `y_{k-1}` and whose kernel does
    /// not vary along it: same estimates, standard deviations and Jacobians in every mode that
    /// runs without local data. Fails if the two-input sensor read `s_{k-1}` where it reads
    /// `x_k`, or if its gradient w.r.t. `x_k` landed elsewhere than the Jacobian's `f`.
    #[test]
    fn a_sensor_of_the_state_only_steps_as_the_thesis_sensor_blind_to_y() {
        let (zeros, ones) = ([0.0; 4], [1.0; 4]);
        let theta_t = [0.0, 3.0, 3.0, 3.0, 3.0];
        // The long length scale along y_{k-1} makes the 3-input kernel equal the 2-input one.
        let theta_s3 = [0.0, 3.0, 40.0, 3.0];
        let theta_s2 = [0.0, 3.0, 3.0];
        let slopes_t = [0.8, 0.1, 0.3, -0.2];
        let (slopes_s3, slopes_s2) = ([-0.6, 0.0, 1.4], [-0.6, 1.4]);
        let transition = linear_gp(&theta_t, &zeros, &ones, &slopes_t);
        let thesis = HbnView {
            transition,
            sensor: linear_gp(&theta_s3, &zeros, &ones, &slopes_s3),
            transition_local: None,
            sensor_local: None,
            blr: LocalRegression::default(),
            init: None,
            plays: Plays::NONE,
            sensor_memory: Plays::NONE,
        };
        let state_only = HbnView {
            sensor: linear_gp(&theta_s2, &zeros, &ones, &slopes_s2),
            ..thesis
        };
        assert_eq!(state_only.sensor.dim(), SENSOR_STATE_DIM);
        state_only.validate().unwrap();
        for mode in [Mode::Ekf, Mode::Ukf] {
            let cfg = EkfConfig {
                mode,
                ..gate_config(1e9)
            };
            let (a, b) = (
                Ekf::new(thesis, cfg).unwrap(),
                Ekf::new(state_only, cfg).unwrap(),
            );
            let mut scratch = [0.0; 64];
            assert!(a.scratch_len() <= 64 && b.scratch_len() <= 64);
            let (mut sa, mut sb) = (None, None);
            let mut moved = 0.0;
            for k in 0..60 {
                let u = (k as f64 * 0.3).sin();
                let y = 0.5 * (k as f64 * 0.2).cos();
                let oa = a.step(&mut sa, &mut scratch, u, y);
                let ob = b.step(&mut sb, &mut scratch, u, y);
                let tol = 1e-9 * (1.0 + oa.x.abs());
                assert!(
                    (oa.x - ob.x).abs() < tol,
                    "{mode:?} step {k}: {oa:?} {ob:?}"
                );
                assert!((oa.x_std - ob.x_std).abs() < tol, "{mode:?} step {k}");
                assert!(
                    (oa.jacobian - ob.jacobian).abs().max() < 1e-9,
                    "{mode:?} {k}"
                );
                moved += (oa.x - 0.0).abs();
            }
            // The comparison is of filters that move.
            assert!(moved > 1.0, "{mode:?}: {moved}");
        }
        // The sensor's row of F: c + f a1, f a2, e = (-0.6 + 1.4 * 0.8, 1.4 * 0.1, 0).
        let cfg = gate_config(1e9);
        let ekf = Ekf::new(state_only, cfg).unwrap();
        let mut scratch = [0.0; 64];
        let mut st = None;
        ekf.step(&mut st, &mut scratch, 0.1, 0.2);
        let out = ekf.step(&mut st, &mut scratch, 0.2, 0.3);
        let j = out.jacobian;
        assert!((j.m31 - (-0.6 + 1.4 * 0.8)).abs() < 1e-9, "{j}");
        assert!((j.m32 - 1.4 * 0.1).abs() < 1e-9, "{j}");
        assert!(j.m33.abs() < 1e-12, "{j}");
    }

    /// A sensor with memory reads `[x_k, q^1_k, q^2_k]`: the plays of the filter's estimates
    /// moved by the predicted `x_k`. On a linear sensor the predicted measurement is
    /// `b . [x_k, q^1, q^2]`, the Jacobian's sensor row is `(f a1, f a2, 0)` with
    /// `f = b_0 + sum_i b_i [play i moves with x_k]`, and after each step the memory holds the
    /// plays of the estimates so far. Fails if a held play passed `x_k`'s slope on (or a moving
    /// one did not), if the memory followed the prediction instead of the estimate, or if the
    /// sensor read the thesis' inputs.
    #[test]
    fn a_sensor_with_memory_reads_the_plays_of_its_estimates() {
        let (zeros, ones) = ([0.0; 4], [1.0; 4]);
        let theta = [0.0, 3.0, 3.0, 3.0, 3.0];
        let slopes_t = [0.8, 0.1, 0.3, -0.2];
        let slopes_s = [0.5, 0.7, -0.4];
        let radii = [0.05, 0.3];
        let memory = Plays::new(&radii).unwrap();
        let view = HbnView {
            sensor_memory: memory,
            ..linear_view(&theta, &zeros, &ones, &slopes_t, &slopes_s)
        };
        view.validate().unwrap();
        // Two plays need three sensor inputs; lags are refused.
        let two_inputs = HbnView {
            sensor_memory: Plays::new(&[0.1]).unwrap(),
            ..view
        };
        assert!(two_inputs.validate().is_err());
        let lagged = HbnView {
            sensor_memory: Plays::with_lags(&[0.1], &[0.5]).unwrap(),
            ..view
        };
        assert!(lagged.validate().is_err());
        for mode in [Mode::Ekf, Mode::Ukf] {
            let ekf = Ekf::new(
                view,
                EkfConfig {
                    mode,
                    ..gate_config(1e9)
                },
            )
            .unwrap();
            let mut scratch = [0.0; 64];
            let mut st = None;
            let first = ekf.step(&mut st, &mut scratch, 0.0, 0.0);
            let mut estimates = [first.x; crate::play::MAX_PLAYS];
            let (mut held, mut moving) = ([0usize; 2], [0usize; 2]);
            for k in 1..120 {
                let u = (k as f64 * 0.13).sin() + 0.3 * (k as f64 * 0.71).sin();
                let y = 0.4 * (k as f64 * 0.09).cos();
                let Some(before) = st else {
                    panic!("no state after a step")
                };
                assert_eq!(&before.memory[..2], &estimates[..2], "{mode:?} step {k}");
                let xk = ekf.predict(&before, &mut scratch).z.x;
                let mut f = slopes_s[0];
                let mut s_pred = slopes_s[0] * xk;
                for i in 0..2 {
                    let q = before.memory[i].clamp(xk - radii[i], xk + radii[i]);
                    s_pred += slopes_s[i + 1] * q;
                    if q == before.memory[i] {
                        held[i] += 1;
                    } else {
                        moving[i] += 1;
                        f += slopes_s[i + 1];
                    }
                }
                let out = ekf.step(&mut st, &mut scratch, u, y);
                if mode == Mode::Ekf {
                    assert!((out.y_pred - s_pred).abs() < 1e-9, "step {k}: {out:?}");
                    let j = out.jacobian;
                    assert!((j.m31 - f * slopes_t[0]).abs() < 1e-9, "step {k}: {j}");
                    assert!((j.m32 - f * slopes_t[1]).abs() < 1e-9, "step {k}: {j}");
                    assert!(j.m33.abs() < 1e-12, "step {k}: {j}");
                }
                assert!(out.x.is_finite() && out.x_std.is_finite());
                memory.advance(&mut estimates, out.x);
            }
            // Both plays both held and moved.
            assert!(
                held.iter().chain(&moving).all(|&n| n > 5),
                "{mode:?}: {held:?} {moving:?}"
            );
        }
    }

    /// [`Ekf::predict`] is the step's prediction phase: the step's update applied to it gives
    /// the step's state bit for bit, in both modes that run without local data, and its
    /// predicted measurement is the step's. On a linear model the unscented cross-covariance
    /// is the linearised one, `P F^T` (the cubature rule is exact for linear maps).
    #[test]
    fn predict_is_the_steps_prediction() {
        let (zeros, ones) = ([0.0; 4], [1.0; 4]);
        let theta = [0.0, 3.0, 3.0, 3.0, 3.0];
        let slopes_t = [0.8, 0.1, 0.3, -0.2];
        let slopes_s = [-0.6, 0.2, 1.4];
        let view = linear_view(&theta, &zeros, &ones, &slopes_t, &slopes_s);
        for mode in [Mode::Ekf, Mode::Ukf] {
            let cfg = EkfConfig {
                mode,
                ..gate_config(0.0)
            };
            let ekf = Ekf::new(view, cfg).unwrap();
            let mut scratch = [0.0; 64];
            let mut state = None;
            ekf.step(&mut state, &mut scratch, 0.1, 0.2);
            for k in 0..40 {
                let u = (k as f64 * 0.3).sin();
                let y = 0.5 * (k as f64 * 0.2).cos();
                let before = state.unwrap();
                let pred = ekf.predict(&before, &mut scratch);
                let out = ekf.step(&mut state, &mut scratch, u, y);
                assert_eq!(pred.z.z, out.y_pred, "{mode:?} {k}");
                assert_eq!(pred.flags.0 & !out.flags.0, 0, "{mode:?} {k}");
                let mut st = EkfState {
                    z: pred.z,
                    p: pred.p,
                    ..before
                };
                let mut flags = 0;
                update(&mut st, y, out.r, &cfg, &mut flags);
                let after = state.unwrap();
                assert_eq!((st.z, st.p), (after.z, after.p), "{mode:?} {k}");
                if mode == Mode::Ekf {
                    assert_eq!(pred.cross, before.p * out.jacobian.transpose());
                }
            }
        }
        // The unscented cross-covariance against `P F^T` at the UKF's own states.
        let cfg = EkfConfig {
            mode: Mode::Ukf,
            ..gate_config(0.0)
        };
        let ukf = Ekf::new(view, cfg).unwrap();
        let mut scratch = [0.0; 64];
        let mut state = None;
        ukf.step(&mut state, &mut scratch, 0.1, 0.2);
        for k in 0..40 {
            let before = state.unwrap();
            let pred = ukf.predict(&before, &mut scratch);
            let out = ukf.step(&mut state, &mut scratch, 0.3, 0.1 * k as f64);
            let linear = before.p * out.jacobian.transpose();
            assert!(
                (pred.cross - linear).abs().max() < 1e-9 * (1.0 + linear.abs().max()),
                "{k}: {} vs {linear}",
                pred.cross
            );
        }
    }

    /// A sensor GP of neither 3 nor 2 inputs is refused, and so is a sensor's local data of
    /// another dimension than its GP's.
    #[test]
    fn the_sensor_dimension_is_checked() {
        let (zeros, ones) = ([0.0; 4], [1.0; 4]);
        let theta = [0.0, 3.0, 3.0, 3.0, 3.0];
        let slopes_t = [0.8, 0.1, 0.3, -0.2];
        let one = [1.0];
        let view = linear_view(&theta, &zeros, &ones, &slopes_t, &one);
        assert_eq!(
            view.validate(),
            Err(CoreError::DimensionMismatch {
                expected: SENSOR_DIM,
                got: 1
            })
        );
        let (inputs, targets, keys, start) = ([0.0; 3], [0.0], [0u64], [0u32, 1]);
        let (origin, hw, var) = ([0.0; 3], [1.0; 3], [1.0; 3]);
        let local3 = Neighbourhood::new(
            3,
            crate::blr::NeighbourhoodParts {
                inputs: &inputs,
                targets: &targets,
                cell_keys: &keys,
                cell_start: &start,
                origin: &origin,
                half_window: &hw,
                input_var: &var,
            },
        )
        .unwrap();
        let slopes_s2 = [-0.6, 1.4];
        let mismatched = HbnView {
            sensor: linear_gp(&theta[..3], &zeros, &ones, &slopes_s2),
            sensor_local: Some(local3),
            ..view
        };
        assert_eq!(
            mismatched.validate(),
            Err(CoreError::DimensionMismatch {
                expected: 2,
                got: 3
            })
        );
    }

    /// A filter whose model throws the state out of its box holds it at the edge; after
    /// [`LOST_AFTER`] predictions in a row outside the box (each clamped) it re-starts from the
    /// [`InitPrior`] at the measurement, flags it, and counts again from zero. A stable model
    /// never does, and without a prior the filter stays clamped (nothing to re-start from).
    #[test]
    fn a_lost_filter_relocalises_from_the_measurement() {
        let theta = [0.0, 3.0, 3.0, 3.0, 3.0];
        let (zeros, ones) = ([0.0; 4], [1.0; 4]);
        let pairs = [[-0.5, -0.4], [0.0, 0.0], [0.3, 0.25], [0.5, 0.4]];
        let run = |slope: f64, with_prior: bool| {
            let slopes_t = [slope, 0.0, 0.0, 0.0];
            let model = HbnView {
                init: with_prior.then(|| InitPrior::new(&pairs, 1, 1e-4).unwrap()),
                ..linear_view(&theta, &zeros, &ones, &slopes_t, &[0.0, 0.0, 1.0])
            };
            let cfg = EkfConfig {
                x_bounds: (-1.0, 1.0),
                y_bounds: (-1.0, 1.0),
                x0_mean: 0.5,
                ..gate_config(25.0)
            };
            let ekf = Ekf::new(model, cfg).unwrap();
            let mut scratch = [0.0; 64];
            assert!(ekf.scratch_len() <= scratch.len());
            let mut state = None;
            let outs: [StepOutput; 40] =
                core::array::from_fn(|_| ekf.step(&mut state, &mut scratch, 0.0, 0.3));
            (outs, state.unwrap())
        };
        // x_k = 4 x_{k-1}: every prediction from 0.3 leaves the box [-1, 1].
        let (outs, _) = run(4.0, true);
        let clamped = |o: &StepOutput| o.flags.has(Flags::STATE_CLAMPED);
        let relocalised: [bool; 40] =
            core::array::from_fn(|k| outs[k].flags.has(Flags::RELOCALISED));
        let first = relocalised
            .iter()
            .position(|&r| r)
            .expect("never relocalised");
        // It fires on the LOST_AFTER-th clamped step of a run, not before (the first step
        // predicts 4 x 0.25 = 1, the edge itself).
        let lost = LOST_AFTER as usize;
        assert!(first >= lost, "{first}");
        assert!(
            outs[first + 1 - lost..=first].iter().all(clamped),
            "{first}"
        );
        assert!(!clamped(&outs[first - lost]), "{first}");
        // The re-start: x from the prior at y = 0.3 (the pair (0.3, 0.25)), its variance the
        // floor, s = y.
        assert_eq!(outs[first].x, 0.25);
        assert!(
            (outs[first].x_std - 1e-2).abs() < 1e-8,
            "{}",
            outs[first].x_std
        );
        // It counts again from zero: the step after the re-start predicts the edge again
        // (unclamped), and the next re-start ends the next LOST_AFTER clamped steps.
        let second = first + 1 + relocalised[first + 1..].iter().position(|&r| r).unwrap();
        assert!(!clamped(&outs[first + 1]));
        assert_eq!(second, first + 1 + lost);
        // Without a prior: clamped throughout, never relocalised, still counting.
        let (outs, st) = run(4.0, false);
        assert!(outs.iter().all(|o| !o.flags.has(Flags::RELOCALISED)));
        assert!(outs[1..].iter().all(clamped));
        assert_eq!(st.lost_run, 39);
        // A stable model (x_k = 0.5 x_{k-1}) stays in its box and never re-starts.
        let (outs, st) = run(0.5, true);
        assert!(
            outs[1..]
                .iter()
                .all(|o| !clamped(o) && !o.flags.has(Flags::RELOCALISED))
        );
        assert_eq!(st.lost_run, 0);
    }

    /// Below the gate the update is the plain Kalman update; above it the innovation variance
    /// becomes `nu^2 / gate`, so the state moves by `P_xs gate / nu`: less the larger the
    /// outlier, never skipped, and the Joseph form with the inflated `R` keeps `P` symmetric
    /// positive definite. The flag and the run count say so.
    #[test]
    fn the_outlier_gate_down_weights_in_proportion() {
        let (r, gate) = (0.01, 25.0);
        let cfg = gate_config(gate);
        let s_var = gate_state().p.m33 + r;
        let step = |y: f64, cfg: &EkfConfig| {
            let mut st = gate_state();
            let mut flags = 0;
            let out = update(&mut st, y, r, cfg, &mut flags);
            (st, flags, out)
        };
        // Inside the gate: K = P_col / S, exactly the ungated update.
        let nu = 3.0 * s_var.sqrt();
        let (st, flags, (innov, s_out, nis)) = step(0.5 + nu, &cfg);
        assert_eq!(flags & Flags::OUTLIER_REJECTED, 0);
        assert_eq!(st.rejected_run, 0);
        let (open, _, _) = step(0.5 + nu, &gate_config(0.0));
        assert_eq!(st.z, open.z);
        assert!((innov - nu).abs() < 1e-12 && (s_out - s_var).abs() < 1e-15);
        assert!((nis - 9.0).abs() < 1e-9);
        // Outside: the reported NIS and S are the model's; the move is P_xs gate / nu.
        let mut last_move = f64::INFINITY;
        for sigmas in [6.0, 20.0, 100.0, 1e4] {
            let nu = sigmas * s_var.sqrt();
            let (st, flags, (_, s_out, nis)) = step(0.5 + nu, &cfg);
            assert_ne!(flags & Flags::OUTLIER_REJECTED, 0, "{sigmas}");
            assert_eq!(st.rejected_run, 1);
            assert!((s_out - s_var).abs() < 1e-15 && (nis - sigmas * sigmas).abs() < 1e-6 * nis);
            let moved = st.z.x - gate_state().z.x;
            let want = gate_state().p.m13 * gate / nu;
            assert!(
                (moved - want).abs() < 1e-12 * want.abs().max(1.0),
                "{moved} vs {want}"
            );
            assert!(moved > 0.0 && moved < last_move, "{sigmas}: {moved}");
            last_move = moved;
            let (vals, _) = crate::eigen::symmetric_eigen3(&st.p).unwrap();
            assert!(vals.iter().all(|&v| v > 0.0), "{vals:?}");
            assert_eq!(st.p, st.p.transpose());
        }
        // A run of gated measurements is counted; an accepted one resets the count.
        let mut st = gate_state();
        let mut flags = 0;
        for k in 1..=3 {
            let y = st.z.z + 50.0 * s_var.sqrt();
            update(&mut st, y, r, &cfg, &mut flags);
            assert_eq!(st.rejected_run, k);
        }
        let y = st.z.z;
        update(&mut st, y, r, &cfg, &mut flags);
        assert_eq!(st.rejected_run, 0);
    }

    #[test]
    fn the_ldl_exit_only_accepts_covariances_inside_the_bounds() {
        // Random symmetric matrices, many of them near the bounds: whenever the cheap test
        // says "inside", the eigenvalues (Jacobi) are inside; and it decides the correlated
        // case it exists for, where Gershgorin's discs reach below the floor.
        let mut rng = Rng::new(7);
        let (lo, hi) = (1e-3, 10.0);
        let mut accepted = 0;
        for _ in 0..20_000 {
            let b = Matrix3::from_fn(|_, _| rng.normal());
            let scale = 0.3 * rng.normal().abs();
            let p = b * b.transpose() * scale + Matrix3::identity() * (lo * 2.0 * rng.uniform());
            let (vals, _) = crate::eigen::symmetric_eigen3(&p).unwrap();
            if inside_by_ldl(&p, lo, hi) {
                accepted += 1;
                assert!(vals.iter().all(|&v| v >= lo && v <= hi), "{vals:?} {p}");
            }
        }
        assert!(accepted > 1000, "{accepted}");
        // x_k and x_{k-1} nearly equal: a strongly correlated but well-bounded covariance.
        let p = Matrix3::new(1.0, 0.99, 0.1, 0.99, 1.0, 0.1, 0.1, 0.1, 0.5);
        assert!(
            p[(1, 1)] - 0.99 - 0.1 < lo,
            "Gershgorin would not decide this one"
        );
        assert!(inside_by_ldl(&p, lo, hi));
        let mut flags = 0;
        assert_eq!(bound_covariance(p, lo, hi, &mut flags), p);
        assert_eq!(flags, 0);
        // Below the floor, above the ceiling, indefinite: not decided here.
        assert!(!inside_by_ldl(&(p * 1e-3), lo, hi));
        assert!(!inside_by_ldl(&(p * 10.0), lo, hi));
        assert!(!inside_by_ldl(
            &Matrix3::new(1.0, 2.0, 0.0, 2.0, 1.0, 0.0, 0.0, 0.0, 1.0),
            lo,
            hi
        ));
        assert!(!inside_by_ldl(&(p * f64::NAN), lo, hi));
    }

    #[test]
    fn state_information_ignores_a_component_that_does_not_matter() {
        // The transition reads x_{k-1} only (a2 = 0): x_{k-2} is unobservable and irrelevant.
        let f = Matrix3::new(0.9, 0.0, 0.0, 1.0, 0.0, 0.0, 0.3, 0.0, 0.5);
        let jac = [f; 4];
        let r = [0.01; 4];
        let (lo, hi) = observability_eigenvalues(&jac, &r).unwrap();
        assert!(lo <= 1e-12 * hi, "{lo} {hi}");
        let info = state_information(&jac, &r).unwrap();
        assert!(info > 1e-3 * hi, "{info} vs {hi}");
        // A sensor blind to x (c = f = 0 in every row): no information on x.
        let blind = Matrix3::new(0.9, 0.1, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 0.5);
        let info = state_information(&[blind; 4], &r).unwrap();
        let (_, hi) = observability_eigenvalues(&[blind; 4], &r).unwrap();
        assert!(info <= 1e-12 * hi, "{info} vs {hi}");
        // A full-rank case: the Schur complement equals 1 / (G^-1)_00.
        let full = Matrix3::new(0.8, 0.3, 0.0, 1.0, 0.0, 0.0, 0.4, 0.2, 0.6);
        let jac = [full; 4];
        let g = observability_gramian(&jac, &r).unwrap();
        let want = 1.0 / g.try_inverse().unwrap()[(0, 0)];
        let got = state_information(&jac, &r).unwrap();
        assert!((got - want).abs() <= 1e-9 * want, "{got} vs {want}");
    }

    /// The nearest-k set by (distance, index), found by sorting (what the allocation-free walk
    /// must equal): mean and variance of x.
    fn brute(pairs: &[[f64; 2]], y0: f64, k: usize) -> (f64, f64) {
        let mut order: [usize; 64] = core::array::from_fn(|i| i);
        let order = &mut order[..pairs.len()];
        order.sort_by(|&a, &b| {
            libm::fabs(pairs[a][0] - y0)
                .total_cmp(&libm::fabs(pairs[b][0] - y0))
                .then(a.cmp(&b))
        });
        let mut near = [0usize; 64];
        let k = k.min(pairs.len());
        near[..k].copy_from_slice(&order[..k]);
        near[..k].sort_unstable();
        let mean = near[..k].iter().map(|&i| pairs[i][1]).sum::<f64>() / k as f64;
        let var = near[..k]
            .iter()
            .map(|&i| (pairs[i][1] - mean) * (pairs[i][1] - mean))
            .sum::<f64>()
            / k as f64;
        (mean, var)
    }

    #[test]
    fn init_prior_takes_the_nearest_samples_ties_by_index() {
        let mut rng = Rng::new(5);
        for case in 0..400 {
            let n = 1 + (case % 40);
            // Few distinct y values: many ties, runs cut by the window on both sides.
            let mut pairs = [[0.0; 2]; 64];
            for p in pairs[..n].iter_mut() {
                *p = [(rng.uniform() * 6.0).floor(), rng.uniform()];
            }
            let pairs = &mut pairs[..n];
            pairs.sort_by(|a, b| a[0].total_cmp(&b[0]).then(a[1].total_cmp(&b[1])));
            let k = 1 + (case % 7);
            let prior = InitPrior::new(pairs, k, 1e-300).unwrap();
            for y0 in [-1.0, 0.0, 1.5, 2.0, 2.5, 3.0, 5.0, 9.0] {
                let (m, v) = prior.prior(y0).unwrap();
                let (bm, bv) = brute(pairs, y0, k);
                assert!((m - bm).abs() < 1e-12, "case {case} y0 {y0}: {m} vs {bm}");
                assert!((v - bv.max(1e-300)).abs() < 1e-12, "case {case} y0 {y0}");
            }
            assert!(prior.prior(f64::NAN).is_none());
        }
    }

    #[test]
    fn init_prior_rejects_bad_tables() {
        assert_eq!(InitPrior::new(&[], 1, 1.0).unwrap_err(), CoreError::Empty);
        let unsorted = [[1.0, 0.0], [0.0, 0.0]];
        assert!(InitPrior::new(&unsorted, 1, 1.0).is_err());
        let nan = [[f64::NAN, 0.0]];
        assert_eq!(
            InitPrior::new(&nan, 1, 1.0).unwrap_err(),
            CoreError::NonFinite
        );
        assert!(InitPrior::new(&[[0.0, 0.0]], 0, 1.0).is_err());
        assert!(InitPrior::new(&[[0.0, 0.0]], 1, 0.0).is_err());
    }

    #[test]
    fn init_prior_that_overflows_is_no_prior() {
        // Finite pairs whose mean (sum) or spread overflows: no prior, so the estimator starts
        // from its settings instead of x = inf (a case the `step` fuzz target reaches).
        let big = [[0.0, f64::MAX], [0.1, f64::MAX]];
        assert_eq!(InitPrior::new(&big, 2, 1.0).unwrap().prior(0.0), None);
        let spread = [[0.0, f64::MAX], [0.1, -f64::MAX]];
        assert_eq!(InitPrior::new(&spread, 2, 1.0).unwrap().prior(0.0), None);
        // One such sample alone is a fine prior.
        assert_eq!(
            InitPrior::new(&big, 1, 1.0).unwrap().prior(0.0),
            Some((f64::MAX, 1.0))
        );
    }
}
