//! The HBN filter for several inputs, a vector state and several sensors, allocation-free.
//!
//! A soft finger with `du` chambers, a tip of `dx` coordinates and `dy` strain sensors:
//! `u_k` in R^du, `x_k` in R^dx, `y_k` in R^dy (at most [`MAX_INPUTS`], [`MAX_STATES`],
//! [`MAX_SENSORS`]). The model has one transition GP per state component and one sensor GP
//! per sensor ([`VectorView`]):
//!
//! - transition `i`: `x^i_k = H_D^i(x_{k-1}, x_{k-2}, u_{k-1}, u_{k-2}, p_{k-1})`, every
//!   component of the state and every input, then the memory operators ([`Plays`]) of each
//!   input in input order (`2 dx + du (2 + plays)` inputs);
//! - sensor `j`: `s^j_k = H_S^j(x_{k-1}, s^j_{k-1}, x_k)` (`2 dx + 1` inputs), or
//!   `H_S^j(x_{k-1}, x_k)` for a sensor of the state only (`2 dx`): its GP's dimension says
//!   which.
//!
//! The filter's state is `z_k = [x_k, x_{k-1}, s_k]` of dimension `n = 2 dx + dy`
//! ([`MAX_AUGMENTED`]), with its full covariance. The EKF linearises every GP at the estimate:
//!
//! ```text
//!     | A1                 A2        0   |          | I   |
//! F = | I                  0         0   |,    G =  | 0   |,   Q = G diag(q_x) G^T + diag(0, 0, q_s)
//!     | C + Fs A1          Fs A2     E   |          | Fs  |
//! ```
//!
//! with `A1`, `A2` the transitions' gradients with respect to `x_{k-1}`, `x_{k-2}` (`dx x dx`),
//! `C`, `Fs` the sensors' with respect to `x_{k-1}`, `x_k` (`dy x dx`) and `E` the diagonal of
//! each sensor's gradient with respect to its own `s_{k-1}`. The update reads `y_k` through
//! `H = [0, 0, I]`, with a `dy x dy` innovation covariance; a sensor whose sample is missing
//! (not finite) is left out of that step's update. The UKF propagates `2 (n + dx)` cubature
//! points of `[z, w]` (`w` the transitions' noise) through the GP means.
//!
//! Scales: every component has its own units, so the guards work on the state divided by
//! the span of its box ([`VectorConfig::x_bounds`], [`VectorConfig::y_bounds`]): the noise
//! floors, the eigenvalue bounds of the covariance, the Jacobian bound and the smallest
//! innovation variance are in those units. The local regression (EKF+BLR) runs on scalar
//! models only: its neighbourhood, a box of +-2.5% of each input's range, holds no training
//! sample for 93-99% of the queries of a fresh run over a vector transition's 8 to 12 inputs
//! (against 9% over the scalar's 4; `docs/vector.md`), so it would silently be the EKF.
//! [`VectorEkf::new`] refuses it with a message that says so.
//!
//! Every loop runs over the model's sizes, not the maxima, so a small model pays for what it
//! has. The scalar filter ([`crate::ekf`]) stays the path of scalar models.

use crate::CoreError;
use crate::ekf::{Flags, LOST_AFTER, Mode};
use crate::gp::{GpView, Want};
use crate::kernel::{MAX_DIM, clamp_to};
use crate::play::{PlayState, Plays};

/// Most inputs (`du`) a vector model has.
pub const MAX_INPUTS: usize = 4;
/// Most state components (`dx`).
pub const MAX_STATES: usize = 3;
/// Most sensors (`dy`).
pub const MAX_SENSORS: usize = 4;
/// Largest filter state, `2 MAX_STATES + MAX_SENSORS`.
pub const MAX_AUGMENTED: usize = 2 * MAX_STATES + MAX_SENSORS;
/// Largest unscented augmentation: the state and the transitions' noise.
const MAX_SIGMA_DIM: usize = MAX_AUGMENTED + MAX_STATES;

/// A square matrix over the filter's state (its leading `n x n` block is used).
pub type AugMatrix = [[f64; MAX_AUGMENTED]; MAX_AUGMENTED];

/// The sizes of a vector model.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub struct Dims {
    /// Inputs `du` (1..=[`MAX_INPUTS`]).
    pub inputs: usize,
    /// State components `dx` (1..=[`MAX_STATES`]).
    pub states: usize,
    /// Sensors `dy` (1..=[`MAX_SENSORS`]).
    pub sensors: usize,
}

impl Dims {
    /// Checked sizes.
    pub fn new(inputs: usize, states: usize, sensors: usize) -> Result<Self, CoreError> {
        let d = Self {
            inputs,
            states,
            sensors,
        };
        d.validate()?;
        Ok(d)
    }

    /// Checks the sizes against the maxima.
    pub fn validate(&self) -> Result<(), CoreError> {
        if !(1..=MAX_INPUTS).contains(&self.inputs)
            || !(1..=MAX_STATES).contains(&self.states)
            || !(1..=MAX_SENSORS).contains(&self.sensors)
        {
            return Err(CoreError::InvalidSpec(
                "a vector model has 1..=4 inputs, 1..=3 state components and 1..=4 sensors",
            ));
        }
        Ok(())
    }

    /// Whether every size is 1 (a scalar model).
    pub const fn is_scalar(&self) -> bool {
        self.inputs == 1 && self.states == 1 && self.sensors == 1
    }

    /// Dimension of the filter's state, `2 dx + dy`.
    pub const fn augmented(&self) -> usize {
        2 * self.states + self.sensors
    }

    /// Inputs of each transition GP with `memory` operators per input:
    /// `2 dx + du (2 + memory)`.
    pub const fn transition_dim(&self, memory: usize) -> usize {
        2 * self.states + self.inputs * (2 + memory)
    }

    /// Inputs of a sensor GP: `2 dx + 1` if it reads its own previous output, else `2 dx`.
    pub const fn sensor_dim(&self, reads_output: bool) -> usize {
        2 * self.states + if reads_output { 1 } else { 0 }
    }
}

/// Prior of `x_0` from the first measurement vector: training rows `[y (dy), x (dx)]`; the
/// prior is the mean and variance of `x` over the `neighbours` rows whose `y` is nearest (in
/// `y` divided by `y_scale`). Linear in the number of rows, bounded.
#[derive(Clone, Copy, Debug)]
pub struct VectorInitPrior<'a> {
    rows: &'a [f64],
    dims: Dims,
    y_scale: [f64; MAX_SENSORS],
    neighbours: usize,
    var_floor: [f64; MAX_STATES],
}

/// Most neighbours a [`VectorInitPrior`] averages.
pub const MAX_INIT_NEIGHBOURS: usize = 64;

impl<'a> VectorInitPrior<'a> {
    /// Checks the rows (`dy + dx` values each, finite), the scales (positive) and
    /// `1 <= neighbours <= MAX_INIT_NEIGHBOURS`.
    pub fn new(
        rows: &'a [f64],
        dims: Dims,
        y_scale: &[f64],
        neighbours: usize,
        var_floor: &[f64],
    ) -> Result<Self, CoreError> {
        dims.validate()?;
        let width = dims.sensors + dims.states;
        if rows.is_empty() || !rows.len().is_multiple_of(width) {
            return Err(CoreError::DimensionMismatch {
                expected: width,
                got: rows.len(),
            });
        }
        if !rows.iter().all(|v| v.is_finite()) {
            return Err(CoreError::NonFinite);
        }
        if y_scale.len() != dims.sensors || var_floor.len() != dims.states {
            return Err(CoreError::DimensionMismatch {
                expected: dims.sensors,
                got: y_scale.len(),
            });
        }
        let pos = |v: &f64| v.is_finite() && *v > 0.0;
        if !(y_scale.iter().all(pos) && var_floor.iter().all(pos)) {
            return Err(CoreError::InvalidSpec(
                "initial prior scales and variance floors must be finite and > 0",
            ));
        }
        if neighbours == 0 || neighbours > MAX_INIT_NEIGHBOURS {
            return Err(CoreError::InvalidSpec(
                "initial prior neighbours must be in 1..=64",
            ));
        }
        let mut ys = [1.0; MAX_SENSORS];
        copy_into(&mut ys, y_scale);
        let mut vf = [0.0; MAX_STATES];
        copy_into(&mut vf, var_floor);
        Ok(Self {
            rows,
            dims,
            y_scale: ys,
            neighbours,
            var_floor: vf,
        })
    }

    /// Mean and variance of each state component given the first measurement `y0` (`None`
    /// if a component of `y0` is not finite).
    pub fn prior(&self, y0: &[f64]) -> Option<([f64; MAX_STATES], [f64; MAX_STATES])> {
        let (dy, dx) = (self.dims.sensors, self.dims.states);
        let y0 = y0.get(..dy)?;
        if !y0.iter().all(|v| v.is_finite()) {
            return None;
        }
        // The `k` nearest rows, kept sorted by distance (insertion into a fixed array).
        let k = self.neighbours;
        let mut best_d = [f64::INFINITY; MAX_INIT_NEIGHBOURS];
        let mut best_i = [usize::MAX; MAX_INIT_NEIGHBOURS];
        let width = dy + dx;
        for (i, row) in self.rows.chunks_exact(width.max(1)).enumerate() {
            let mut d2 = 0.0;
            for ((y, r), s) in y0.iter().zip(row).zip(&self.y_scale) {
                let e = (y - r) / s;
                d2 += e * e;
            }
            let worst = best_d.get(k - 1).copied().unwrap_or(f64::INFINITY);
            if d2.partial_cmp(&worst) != Some(core::cmp::Ordering::Less) {
                continue;
            }
            // Shift the tail right by one from the insertion point.
            let mut pos = k - 1;
            while pos > 0 && best_d.get(pos - 1).copied().unwrap_or(f64::INFINITY) > d2 {
                let (pd, pi) = (
                    best_d.get(pos - 1).copied().unwrap_or(f64::INFINITY),
                    best_i.get(pos - 1).copied().unwrap_or(usize::MAX),
                );
                set1(&mut best_d, pos, pd);
                if let Some(slot) = best_i.get_mut(pos) {
                    *slot = pi;
                }
                pos -= 1;
            }
            set1(&mut best_d, pos, d2);
            if let Some(slot) = best_i.get_mut(pos) {
                *slot = i;
            }
        }
        let (mut mean, mut sq) = ([0.0; MAX_STATES], [0.0; MAX_STATES]);
        let mut count = 0usize;
        for &i in best_i.iter().take(k) {
            let Some(row) = self
                .rows
                .get(i.saturating_mul(width)..i.saturating_mul(width) + width)
            else {
                continue;
            };
            count += 1;
            for (c, x) in row.iter().skip(dy).enumerate().take(dx) {
                add1(&mut mean, c, *x);
                add1(&mut sq, c, x * x);
            }
        }
        if count == 0 {
            return None;
        }
        let n = count as f64;
        let mut var = [0.0; MAX_STATES];
        for c in 0..dx {
            let m = at1(&mean, c) / n;
            set1(&mut mean, c, m);
            let v = (at1(&sq, c) / n - m * m).max(at1(&self.var_floor, c));
            set1(&mut var, c, v);
        }
        Some((mean, var))
    }
}

/// A vector model as borrowed views: what the step reads.
#[derive(Clone, Copy, Debug)]
pub struct VectorView<'a> {
    /// Sizes.
    pub dims: Dims,
    /// One transition GP per state component (`dims.states`), inputs as in the module docs.
    pub transitions: &'a [GpView<'a>],
    /// One sensor GP per sensor (`dims.sensors`).
    pub sensors: &'a [GpView<'a>],
    /// Memory operators, applied to every input.
    pub plays: Plays,
    /// Prior of `x_0` from the first measurement (else the settings' `x0_mean`, `x0_var`).
    pub init: Option<VectorInitPrior<'a>>,
}

impl VectorView<'_> {
    /// Checks the GP counts and input dimensions.
    pub fn validate(&self) -> Result<(), CoreError> {
        let d = self.dims;
        d.validate()?;
        if self.transitions.len() != d.states {
            return Err(CoreError::DimensionMismatch {
                expected: d.states,
                got: self.transitions.len(),
            });
        }
        if self.sensors.len() != d.sensors {
            return Err(CoreError::DimensionMismatch {
                expected: d.sensors,
                got: self.sensors.len(),
            });
        }
        let t_dim = d.transition_dim(self.plays.len());
        if t_dim > MAX_DIM {
            return Err(CoreError::InvalidSpec(
                "the transition's inputs (2 dx + du (2 + memory)) exceed MAX_DIM (32)",
            ));
        }
        for gp in self.transitions {
            if gp.dim() != t_dim {
                return Err(CoreError::DimensionMismatch {
                    expected: t_dim,
                    got: gp.dim(),
                });
            }
        }
        for gp in self.sensors {
            if gp.dim() != d.sensor_dim(true) && gp.dim() != d.sensor_dim(false) {
                return Err(CoreError::DimensionMismatch {
                    expected: d.sensor_dim(true),
                    got: gp.dim(),
                });
            }
        }
        if let Some(init) = &self.init
            && init.dims != d
        {
            return Err(CoreError::InvalidSpec(
                "the initial prior's sizes differ from the model's",
            ));
        }
        Ok(())
    }

    /// Scratch values one GP prediction of this model needs (the largest of its GPs).
    pub fn scratch_len(&self) -> usize {
        self.transitions
            .iter()
            .chain(self.sensors)
            .map(|gp| gp.predict_scratch(Want::ALL))
            .max()
            .unwrap_or(0)
    }
}

/// Settings of the vector filter, checked once by [`VectorEkf::new`]. Bounds, the initial
/// state and model floors are per component in raw units; the guards are in units of each
/// component's box span (module docs).
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub struct VectorConfig {
    /// [`Mode::Ekf`] or [`Mode::Ukf`].
    pub mode: Mode,
    /// Box of each state component (training range widened).
    pub x_bounds: [(f64, f64); MAX_STATES],
    /// Box of each sensor's noise-free output.
    pub y_bounds: [(f64, f64); MAX_SENSORS],
    /// Initial mean of each state component.
    pub x0_mean: [f64; MAX_STATES],
    /// Initial variance of each state component (raw units, `> 0`).
    pub x0_var: [f64; MAX_STATES],
    /// Model-error floor of each transition's `q_x` (raw units).
    pub qx_model_floor: [f64; MAX_STATES],
    /// Model-error floor of each sensor's `R` (raw units).
    pub r_model_floor: [f64; MAX_SENSORS],
    /// Floor of the process noise variances (relative to the box's span squared).
    pub q_floor: f64,
    /// Floor of the measurement noise variances (relative).
    pub r_floor: f64,
    /// Lower eigenvalue bound of the scaled covariance.
    pub p_min: f64,
    /// Upper eigenvalue bound of the scaled covariance.
    pub p_max: f64,
    /// Bound on each scaled Jacobian entry.
    pub jac_max: f64,
    /// Smallest scaled innovation variance accepted for an update.
    pub innovation_min: f64,
    /// Outlier gate on the normalised innovation squared per sensor updated; `0` disables
    /// it. Above it the innovation covariance is inflated so that the NIS equals the gate
    /// (as [`crate::EkfConfig::nis_gate`]).
    pub nis_gate: f64,
    /// Scale of the process noise.
    pub q_scale: f64,
    /// Scale of the measurement noise.
    pub r_scale: f64,
    /// Scale of each reported standard deviation (calibration).
    pub std_scale: [f64; MAX_STATES],
}

impl VectorConfig {
    /// Checks the settings for a model of sizes `dims`.
    pub fn validate(&self, dims: Dims) -> Result<(), CoreError> {
        let pos = |v: f64| v.is_finite() && v > 0.0;
        if !(pos(self.q_floor)
            && pos(self.r_floor)
            && pos(self.p_min)
            && pos(self.p_max)
            && pos(self.jac_max)
            && pos(self.innovation_min)
            && pos(self.q_scale)
            && pos(self.r_scale)
            && self.nis_gate.is_finite()
            && self.nis_gate >= 0.0
            && self.p_min < self.p_max)
        {
            return Err(CoreError::InvalidSpec(
                "floors, bounds and scales must be finite and > 0 (p_min < p_max, nis_gate >= 0)",
            ));
        }
        if self.mode == Mode::EkfBlr {
            return Err(CoreError::InvalidSpec(
                "EKF+BLR is for scalar models; a vector model filters with the EKF or the UKF",
            ));
        }
        let ok_box = |b: &(f64, f64)| b.0.is_finite() && b.1.is_finite() && b.0 < b.1;
        for i in 0..dims.states {
            let b = self.x_bounds.get(i).copied().unwrap_or((0.0, 0.0));
            let floor = at1(&self.qx_model_floor, i);
            let std_scale = at1(&self.std_scale, i);
            if !(ok_box(&b)
                && at1(&self.x0_mean, i).is_finite()
                && pos(at1(&self.x0_var, i))
                && floor.is_finite()
                && floor >= 0.0
                && pos(std_scale)
                && (std_scale * crate::simd::sqrt(self.p_max) * (b.1 - b.0)).is_finite())
            {
                return Err(CoreError::InvalidSpec(
                    "each state component needs a finite box lo < hi, a finite x0_mean, \
                     x0_var > 0, a model floor >= 0 and std_scale > 0",
                ));
            }
        }
        for j in 0..dims.sensors {
            let b = self.y_bounds.get(j).copied().unwrap_or((0.0, 0.0));
            let floor = at1(&self.r_model_floor, j);
            if !(ok_box(&b) && floor.is_finite() && floor >= 0.0) {
                return Err(CoreError::InvalidSpec(
                    "each sensor needs a finite box lo < hi and a model floor >= 0",
                ));
            }
        }
        Ok(())
    }
}

/// The vector filter's memory between steps.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct VectorState {
    /// `[x_k, x_{k-1}, s_k]` (the first `2 dx + dy` entries).
    pub z: [f64; MAX_AUGMENTED],
    /// Covariance of `z`.
    pub p: AugMatrix,
    /// `u_k` of the last step.
    pub u_last: [f64; MAX_INPUTS],
    /// `u_{k-1}` of the last step.
    pub u_prev: [f64; MAX_INPUTS],
    /// Memory operators of each input after `u_k`.
    pub plays: [PlayState; MAX_INPUTS],
    /// Steps taken.
    pub steps: u64,
    /// Steps in a row that were lost: the transition prediction left the state box, or a value
    /// was clamped to its box ([`LOST_AFTER`] of them relocalise).
    pub lost_run: u32,
}

/// What one vector step returns.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct VectorStepOutput {
    /// Estimate of `x_k` (the first `dx` entries).
    pub x: [f64; MAX_STATES],
    /// Standard deviation of each component (calibrated by `std_scale`).
    pub x_std: [f64; MAX_STATES],
    /// Covariance of `x_k`, calibrated like `x_std` (`cov[i][i] = x_std[i]^2`).
    pub x_cov: [[f64; MAX_STATES]; MAX_STATES],
    /// Predicted measurement of each sensor before the update.
    pub y_pred: [f64; MAX_SENSORS],
    /// Innovation of each sensor (0 where it was not updated).
    pub innovation: [f64; MAX_SENSORS],
    /// Innovation variance of each sensor (the diagonal of `S`).
    pub innovation_var: [f64; MAX_SENSORS],
    /// Normalised innovation squared of the whole update, `nu^T S^{-1} nu`.
    pub nis: f64,
    /// Process noise variance of each transition.
    pub q_x: [f64; MAX_STATES],
    /// Measurement noise variance of each sensor.
    pub r: [f64; MAX_SENSORS],
    /// Linearised transition `F` of this step (identity on the first step).
    pub jacobian: AugMatrix,
    /// Guards that fired.
    pub flags: Flags,
}

/// The prediction phase of one vector step, as [`VectorEkf::predict`] returns it: what an
/// offline smoother records beside the filtered state (the vector twin of
/// [`crate::ekf::StepPrediction`]). Entries beyond the augmented dimension `2 dx + dy` are zero.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct VectorPrediction {
    /// Predicted mean `z_k^- = [x_k^-, x_{k-1}, s_k^-]` (before the update with `y_k`).
    pub z: [f64; MAX_AUGMENTED],
    /// Predicted covariance `P_k^-`, bounded as the step bounds it.
    pub p: AugMatrix,
    /// Cross-covariance `C_k = cov(z_{k-1}, z_k^-)` of the filtered previous state with the
    /// predicted one: `P_{k-1} F_k^T` when the prediction is linearised (the EKF, and the
    /// random walk the step falls back to), the sigma points' cross-covariance in the
    /// unscented mode.
    pub cross: AugMatrix,
    /// Guards that fired during the prediction.
    pub flags: Flags,
}

/// One linearised GP (its gradient goes into the caller's array).
#[derive(Clone, Copy, Debug)]
struct Local {
    mean: f64,
    noise: f64,
    epistemic: f64,
}

/// What the prediction hands to the update.
#[derive(Clone, Copy, Debug)]
struct Predicted {
    q_x: [f64; MAX_STATES],
    q_s: [f64; MAX_SENSORS],
    r: [f64; MAX_SENSORS],
    s_pred: [f64; MAX_SENSORS],
    jacobian: AugMatrix,
    left_box: bool,
}

/// A checked vector model and settings: the per-sample step (the vector twin of
/// [`crate::Ekf`]). `Copy`; [`VectorEkf::new`] checks everything once and
/// [`VectorEkf::step`] cannot fail.
#[derive(Clone, Copy, Debug)]
pub struct VectorEkf<'m> {
    model: VectorView<'m>,
    config: VectorConfig,
    /// Span of each component of `z`'s box.
    span: [f64; MAX_AUGMENTED],
}

impl<'m> VectorEkf<'m> {
    /// Checks model and settings once.
    pub fn new(model: VectorView<'m>, config: VectorConfig) -> Result<Self, CoreError> {
        model.validate()?;
        config.validate(model.dims)?;
        let d = model.dims;
        let mut span = [1.0; MAX_AUGMENTED];
        for i in 0..d.states {
            let b = config.x_bounds.get(i).copied().unwrap_or((0.0, 1.0));
            set1(&mut span, i, b.1 - b.0);
            set1(&mut span, d.states + i, b.1 - b.0);
        }
        for j in 0..d.sensors {
            let b = config.y_bounds.get(j).copied().unwrap_or((0.0, 1.0));
            set1(&mut span, 2 * d.states + j, b.1 - b.0);
        }
        Ok(Self {
            model,
            config,
            span,
        })
    }

    /// Scratch values [`VectorEkf::step`] needs.
    pub fn scratch_len(&self) -> usize {
        self.model.scratch_len()
    }

    /// The model view.
    pub fn model(&self) -> &VectorView<'m> {
        &self.model
    }

    /// The settings.
    pub fn config(&self) -> &VectorConfig {
        &self.config
    }

    /// Processes sample `k`: inputs `u_k` (`du` values) and measurements `y_k` (`dy`
    /// values; a non-finite one is left out of the update), advancing `state` (`None` before
    /// the first sample). Allocation-free, panic-free, bounded time. Missing values (shorter
    /// slices) count as not finite.
    pub fn step(
        &self,
        state: &mut Option<VectorState>,
        scratch: &mut [f64],
        u_k: &[f64],
        y_k: &[f64],
    ) -> VectorStepOutput {
        let d = self.model.dims;
        let mut flags = 0u32;
        let y = padded::<MAX_SENSORS>(y_k, d.sensors);
        let Some(st) = state.as_mut() else {
            let (st, out) = self.initialise(u_k, &y);
            *state = Some(st);
            return out;
        };
        let mut u = st.u_last;
        for a in 0..d.inputs {
            let v = u_k.get(a).copied().unwrap_or(f64::NAN);
            if v.is_finite() {
                set1(&mut u, a, v);
            } else {
                flags |= Flags::INPUT_INVALID;
            }
        }
        let pred = match self.config.mode {
            Mode::Ukf => self.predict_unscented(st, scratch, &mut flags, None),
            Mode::Ekf | Mode::EkfBlr => self.predict_linearised(st, scratch, &mut flags),
        };
        self.bound_covariance(&mut st.p, &mut flags);
        st.u_prev = st.u_last;
        st.u_last = u;
        for (a, ps) in st.plays.iter_mut().enumerate().take(d.inputs) {
            self.model.plays.advance(ps, at1(&u, a));
        }
        let upd = self.update(st, &y, &pred.r, &mut flags);
        st.steps = st.steps.saturating_add(1);
        // Lost: the prediction left the state box, or a state or sensor value had to be
        // clamped to its box (a filter stuck at the box's edge, where every GP extrapolates,
        // is as lost as one outside it).
        if pred.left_box || flags & Flags::STATE_CLAMPED != 0 {
            st.lost_run = st.lost_run.saturating_add(1);
            if st.lost_run >= LOST_AFTER {
                self.relocalise(st, &y, &mut flags);
            }
        } else {
            st.lost_run = 0;
        }
        self.output(st, &pred, &upd, flags)
    }

    /// The prediction phase of the next step from `state` (the filtered state after the last
    /// step), exactly as [`VectorEkf::step`] computes it, without updating anything
    /// ([`VectorPrediction`]). The next step does not depend on it; an offline smoother calls
    /// it before each step. Allocation-free, panic-free, bounded time; `scratch` as for
    /// [`VectorEkf::step`].
    pub fn predict(&self, state: &VectorState, scratch: &mut [f64]) -> VectorPrediction {
        let n = self.model.dims.augmented().min(MAX_AUGMENTED);
        let mut st = *state;
        let mut flags = 0u32;
        let mut cross = [[0.0; MAX_AUGMENTED]; MAX_AUGMENTED];
        let mut unscented = false;
        let pred = match self.config.mode {
            Mode::Ukf => {
                let before = flags;
                let pred = self.predict_unscented(&mut st, scratch, &mut flags, Some(&mut cross));
                unscented = (flags & !before) & Flags::MODEL_INVALID == 0;
                pred
            }
            Mode::Ekf | Mode::EkfBlr => self.predict_linearised(&mut st, scratch, &mut flags),
        };
        if !unscented {
            // P_{k-1} F^T.
            for a in 0..n {
                for b in 0..n {
                    let mut acc = 0.0;
                    for c in 0..n {
                        acc += at2(&state.p, a, c) * at2(&pred.jacobian, b, c);
                    }
                    set2(&mut cross, a, b, acc);
                }
            }
        }
        self.bound_covariance(&mut st.p, &mut flags);
        VectorPrediction {
            z: st.z,
            p: st.p,
            cross,
            flags: Flags(flags),
        }
    }

    /// Span of each component of the augmented state `[x_k, x_{k-1}, s_k]` (its box's width;
    /// 1 beyond `2 dx + dy`): the units in which the covariance bounds `p_min` and `p_max`
    /// apply, `P_ij / (span_i span_j)`.
    pub fn spans(&self) -> &[f64; MAX_AUGMENTED] {
        &self.span
    }

    /// The step's report from the state after the update.
    fn output(
        &self,
        st: &VectorState,
        pred: &Predicted,
        upd: &Updated,
        flags: u32,
    ) -> VectorStepOutput {
        let dx = self.model.dims.states;
        let mut out = VectorStepOutput {
            x: [0.0; MAX_STATES],
            x_std: [0.0; MAX_STATES],
            x_cov: [[0.0; MAX_STATES]; MAX_STATES],
            y_pred: pred.s_pred,
            innovation: upd.innovation,
            innovation_var: upd.innovation_var,
            nis: upd.nis,
            q_x: pred.q_x,
            r: pred.r,
            jacobian: pred.jacobian,
            flags: Flags(flags),
        };
        for i in 0..dx {
            set1(&mut out.x, i, at1(&st.z, i));
            let si = at1(&self.config.std_scale, i);
            set1(&mut out.x_std, i, si * sqrt(at2(&st.p, i, i).max(0.0)));
            for j in 0..dx {
                let sj = at1(&self.config.std_scale, j);
                if let Some(c) = out.x_cov.get_mut(i).and_then(|r| r.get_mut(j)) {
                    *c = si * sj * at2(&st.p, i, j);
                }
            }
        }
        out
    }

    /// The first sample: `x_0` from the model's prior at `y_0`, else from the settings; `s_0`
    /// is `y_0` (or the box's centre for a missing sensor, with a large variance).
    fn initialise(&self, u_k: &[f64], y: &[f64; MAX_SENSORS]) -> (VectorState, VectorStepOutput) {
        let d = self.model.dims;
        let cfg = &self.config;
        let mut flags = Flags::INITIALISED;
        let mut u0 = [0.0; MAX_INPUTS];
        for a in 0..d.inputs {
            let v = u_k.get(a).copied().unwrap_or(f64::NAN);
            if v.is_finite() {
                set1(&mut u0, a, v);
            } else {
                flags |= Flags::INPUT_INVALID;
            }
        }
        let (x_mean, x_var) = self
            .model
            .init
            .and_then(|p| p.prior(y))
            .unwrap_or((cfg.x0_mean, cfg.x0_var));
        let mut st = VectorState {
            z: [0.0; MAX_AUGMENTED],
            p: [[0.0; MAX_AUGMENTED]; MAX_AUGMENTED],
            u_last: u0,
            u_prev: u0,
            plays: [self.model.plays.start(0.0); MAX_INPUTS],
            steps: 1,
            lost_run: 0,
        };
        for (a, ps) in st.plays.iter_mut().enumerate() {
            *ps = self.model.plays.start(at1(&u0, a));
        }
        let mut r = [0.0; MAX_SENSORS];
        for j in 0..d.sensors {
            set1(&mut r, j, self.fallback_r(j));
        }
        self.reset_state(&mut st, &x_mean, &x_var, y, &r, &mut flags);
        self.bound_covariance(&mut st.p, &mut flags);
        let mut jacobian = [[0.0; MAX_AUGMENTED]; MAX_AUGMENTED];
        for i in 0..d.augmented() {
            set2(&mut jacobian, i, i, 1.0);
        }
        let mut s_pred = [0.0; MAX_SENSORS];
        let mut innovation_var = [0.0; MAX_SENSORS];
        for j in 0..d.sensors {
            let k = 2 * d.states + j;
            set1(&mut s_pred, j, at1(&st.z, k));
            set1(&mut innovation_var, j, at2(&st.p, k, k));
        }
        let pred = Predicted {
            q_x: [0.0; MAX_STATES],
            q_s: [0.0; MAX_SENSORS],
            r,
            s_pred,
            jacobian,
            left_box: false,
        };
        let upd = Updated {
            innovation: [0.0; MAX_SENSORS],
            innovation_var,
            nis: 0.0,
        };
        let out = self.output(&st, &pred, &upd, flags);
        (st, out)
    }

    /// Sets `x_k = x_{k-1}` to the given mean and variance (fully correlated, as one state
    /// seen twice) and `s` to the measurement (variance `r`; the box's centre with a large
    /// variance where it is missing).
    fn reset_state(
        &self,
        st: &mut VectorState,
        x_mean: &[f64; MAX_STATES],
        x_var: &[f64; MAX_STATES],
        y: &[f64; MAX_SENSORS],
        r: &[f64; MAX_SENSORS],
        flags: &mut u32,
    ) {
        let d = self.model.dims;
        let cfg = &self.config;
        st.p = [[0.0; MAX_AUGMENTED]; MAX_AUGMENTED];
        for i in 0..d.states {
            let b = cfg.x_bounds.get(i).copied().unwrap_or((0.0, 1.0));
            let x = clamp_to(at1(x_mean, i), b.0, b.1);
            set1(&mut st.z, i, x);
            set1(&mut st.z, d.states + i, x);
            let v = at1(x_var, i);
            set2(&mut st.p, i, i, v);
            set2(&mut st.p, i, d.states + i, v);
            set2(&mut st.p, d.states + i, i, v);
            set2(&mut st.p, d.states + i, d.states + i, v);
        }
        for j in 0..d.sensors {
            let k = 2 * d.states + j;
            let b = cfg.y_bounds.get(j).copied().unwrap_or((0.0, 1.0));
            let yj = at1(y, j);
            if yj.is_finite() {
                set1(&mut st.z, k, clamp_flag(yj, b, flags));
                set2(&mut st.p, k, k, at1(r, j));
            } else {
                *flags |= Flags::MEASUREMENT_INVALID;
                set1(&mut st.z, k, 0.5 * (b.0 + b.1));
                let sp = b.1 - b.0;
                set2(&mut st.p, k, k, cfg.p_max * sp * sp);
            }
        }
    }

    /// A lost filter's re-start from the model's prior at `y_k` (every sensor finite).
    fn relocalise(&self, st: &mut VectorState, y: &[f64; MAX_SENSORS], flags: &mut u32) {
        let Some((x_mean, x_var)) = self.model.init.and_then(|p| p.prior(y)) else {
            return;
        };
        let d = self.model.dims;
        let mut r = [0.0; MAX_SENSORS];
        for j in 0..d.sensors {
            set1(&mut r, j, self.fallback_r(j));
        }
        self.reset_state(st, &x_mean, &x_var, y, &r, flags);
        self.bound_covariance(&mut st.p, flags);
        st.lost_run = 0;
        *flags |= Flags::RELOCALISED;
    }

    /// `R` of sensor `j` from its learned noise, scaled and floored.
    fn fallback_r(&self, j: usize) -> f64 {
        let cfg = &self.config;
        let floor = cfg.r_floor * sq(self.span_y(j));
        let noise = self
            .model
            .sensors
            .get(j)
            .map_or(0.0, |g| g.noise_variance());
        let r = cfg.r_scale * noise.max(at1(&cfg.r_model_floor, j));
        if r.is_finite() && r >= floor {
            r
        } else {
            floor
        }
    }

    fn span_x(&self, i: usize) -> f64 {
        at1(&self.span, i)
    }

    fn span_y(&self, j: usize) -> f64 {
        at1(&self.span, 2 * self.model.dims.states + j)
    }

    /// The transitions' input at `x_{k-1} = x1`, `x_{k-2} = x2` and the stored inputs.
    fn transition_input(
        &self,
        st: &VectorState,
        x1: &[f64; MAX_STATES],
        x2: &[f64; MAX_STATES],
    ) -> [f64; MAX_DIM] {
        let d = self.model.dims;
        let mut input = [0.0; MAX_DIM];
        let m = self.model.plays.len();
        let mut next = 0;
        let mut put = |values: &[f64], count: usize| {
            for v in values.iter().take(count) {
                set1(&mut input, next, *v);
                next += 1;
            }
        };
        put(x1, d.states);
        put(x2, d.states);
        put(&st.u_last, d.inputs);
        put(&st.u_prev, d.inputs);
        for p in st.plays.iter().take(d.inputs) {
            put(p, m);
        }
        input
    }

    /// Sensor `j`'s input `[x_{k-1}, s^j_{k-1}, x_k]` (or `[x_{k-1}, x_k]`).
    fn sensor_input(
        &self,
        j: usize,
        x1: &[f64; MAX_STATES],
        s1: f64,
        xk: &[f64; MAX_STATES],
    ) -> [f64; MAX_DIM] {
        let d = self.model.dims;
        let reads_output = self.sensor_reads_output(j);
        let mut input = [0.0; MAX_DIM];
        let own = [s1];
        let values = x1
            .iter()
            .take(d.states)
            .chain(own.iter().take(usize::from(reads_output)))
            .chain(xk.iter().take(d.states));
        for (slot, v) in input.iter_mut().zip(values) {
            *slot = *v;
        }
        input
    }

    fn sensor_reads_output(&self, j: usize) -> bool {
        let d = self.model.dims;
        self.model
            .sensors
            .get(j)
            .is_some_and(|g| g.dim() == d.sensor_dim(true))
    }

    /// The mean of `gp` at `input` (`None` on failure).
    fn mean_of(gp: &GpView<'_>, input: &[f64; MAX_DIM], scratch: &mut [f64]) -> Option<f64> {
        let input = input.get(..gp.dim())?;
        gp.predict_mean(input, scratch)
            .ok()
            .filter(|m| m.is_finite())
    }

    /// Mean, learned noise and epistemic variance of `gp` at `input`, and into `grad` the
    /// mean's gradient with respect to the first `grad_cols` inputs (what the Jacobian reads:
    /// a transition's `x_{k-1}` and `x_{k-2}`, every input of a sensor).
    fn linearise(
        gp: &GpView<'_>,
        input: &[f64; MAX_DIM],
        grad_cols: usize,
        scratch: &mut [f64],
        flags: &mut u32,
        grad: &mut [f64; MAX_DIM],
    ) -> Option<Local> {
        let d = gp.dim();
        let Some(x) = input.get(..d) else {
            *flags |= Flags::MODEL_INVALID;
            return None;
        };
        let p = match gp.predict_ekf_into(x, grad_cols, scratch, grad) {
            Ok(p) => p,
            Err(_) => {
                *flags |= Flags::MODEL_INVALID;
                return None;
            }
        };
        if p.variance > crate::ekf::EXTRAPOLATION_RATIO * p.prior_variance.min(gp.output_variance())
        {
            *flags |= Flags::EXTRAPOLATION;
        }
        let out = Local {
            mean: p.mean,
            noise: gp.noise_variance(),
            epistemic: p.variance,
        };
        if !(out.mean.is_finite()
            && out.noise.is_finite()
            && out.epistemic.is_finite()
            && grad.iter().take(grad_cols.min(d)).all(|g| g.is_finite()))
        {
            *flags |= Flags::MODEL_INVALID;
            return None;
        }
        Some(out)
    }

    /// Current `x_{k-1}` (`z[0..dx]`), `x_{k-2}` (`z[dx..2dx]`) and `s_{k-1}`.
    fn split(
        &self,
        z: &[f64; MAX_AUGMENTED],
    ) -> ([f64; MAX_STATES], [f64; MAX_STATES], [f64; MAX_SENSORS]) {
        let d = self.model.dims;
        let (mut x1, mut x2, mut s1) = ([0.0; MAX_STATES], [0.0; MAX_STATES], [0.0; MAX_SENSORS]);
        for i in 0..d.states {
            set1(&mut x1, i, at1(z, i));
            set1(&mut x2, i, at1(z, d.states + i));
        }
        for j in 0..d.sensors {
            set1(&mut s1, j, at1(z, 2 * d.states + j));
        }
        (x1, x2, s1)
    }

    /// Prediction when a transition GP failed: a random walk with a large process noise.
    fn random_walk(&self, st: &mut VectorState) -> Predicted {
        let d = self.model.dims;
        let n = d.augmented();
        let cfg = &self.config;
        let mut f = [[0.0; MAX_AUGMENTED]; MAX_AUGMENTED];
        for i in 0..d.states {
            set2(&mut f, i, i, 1.0);
            set2(&mut f, d.states + i, i, 1.0);
        }
        for j in 0..d.sensors {
            let k = 2 * d.states + j;
            set2(&mut f, k, k, 1.0);
        }
        let mut p = sandwich(&f, &st.p, n);
        let mut z = st.z;
        for i in 0..d.states {
            set1(&mut z, d.states + i, at1(&st.z, i));
            add2(&mut p, i, i, 0.01 * cfg.p_max * sq(self.span_x(i)));
        }
        let mut s_pred = [0.0; MAX_SENSORS];
        let mut r = [0.0; MAX_SENSORS];
        for j in 0..d.sensors {
            let k = 2 * d.states + j;
            add2(&mut p, k, k, 0.01 * cfg.p_max * sq(self.span_y(j)));
            set1(&mut s_pred, j, at1(&z, k));
            set1(&mut r, j, self.fallback_r(j));
        }
        st.z = z;
        st.p = p;
        let mut q_x = [0.0; MAX_STATES];
        for i in 0..d.states {
            set1(&mut q_x, i, 0.01 * cfg.p_max * sq(self.span_x(i)));
        }
        let mut q_s = [0.0; MAX_SENSORS];
        for j in 0..d.sensors {
            set1(&mut q_s, j, 0.01 * cfg.p_max * sq(self.span_y(j)));
        }
        Predicted {
            q_x,
            q_s,
            r,
            s_pred,
            jacobian: f,
            left_box: false,
        }
    }

    /// `q_x` of transition `i` from its linearisation.
    fn q_x(&self, i: usize, t: &Local, flags: &mut u32) -> f64 {
        let cfg = &self.config;
        floor_flag(
            cfg.q_scale * (t.noise + t.epistemic).max(at1(&cfg.qx_model_floor, i)),
            cfg.q_floor * sq(self.span_x(i)),
            flags,
        )
    }

    /// `q_s` and `R` of sensor `j` from its linearisation.
    fn q_s_r(&self, j: usize, s: &Local, flags: &mut u32) -> (f64, f64) {
        let cfg = &self.config;
        let span2 = sq(self.span_y(j));
        let q_s = floor_flag(cfg.q_scale * s.epistemic, cfg.q_floor * span2, flags);
        let r = floor_flag(
            cfg.r_scale * s.noise.max(at1(&cfg.r_model_floor, j)),
            cfg.r_floor * span2,
            flags,
        );
        (q_s, r)
    }

    /// A gradient entry of output `out_span` with respect to an input of `in_span`, bounded in
    /// scaled units.
    fn clamp_grad(&self, g: f64, out_span: f64, in_span: f64, flags: &mut u32) -> f64 {
        let max = self.config.jac_max * out_span / in_span;
        let c = if g.is_finite() {
            clamp_to(g, -max, max)
        } else {
            0.0
        };
        if c != g {
            *flags |= Flags::JACOBIAN_CLAMPED;
        }
        c
    }

    /// EKF prediction: every GP linearised at the estimate, `P = F P F^T + Q`.
    fn predict_linearised(
        &self,
        st: &mut VectorState,
        scratch: &mut [f64],
        flags: &mut u32,
    ) -> Predicted {
        let d = self.model.dims;
        let (dx, dy) = (d.states.min(MAX_STATES), d.sensors.min(MAX_SENSORS));
        let n = d.augmented().min(MAX_AUGMENTED);
        let cfg = self.config;
        let (x1, x2, s1) = self.split(&st.z);
        let t_in = self.transition_input(st, &x1, &x2);
        let mut xk = [0.0; MAX_STATES];
        let mut a1 = [[0.0; MAX_STATES]; MAX_STATES];
        let mut a2 = [[0.0; MAX_STATES]; MAX_STATES];
        let mut q_x = [0.0; MAX_STATES];
        let mut left_box = false;
        for (i, gp) in self.model.transitions.iter().enumerate().take(dx) {
            let mut grad = [0.0; MAX_DIM];
            let Some(t) = Self::linearise(gp, &t_in, 2 * dx, scratch, flags, &mut grad) else {
                return self.random_walk(st);
            };
            let b = cfg.x_bounds.get(i).copied().unwrap_or((0.0, 1.0));
            left_box |= outside(t.mean, b);
            set1(&mut xk, i, clamp_flag(t.mean, b, flags));
            for c in 0..dx {
                let (si, sc) = (self.span_x(i), self.span_x(c));
                let g1 = self.clamp_grad(at1(&grad, c), si, sc, flags);
                let g2 = self.clamp_grad(at1(&grad, dx + c), si, sc, flags);
                set3(&mut a1, i, c, g1);
                set3(&mut a2, i, c, g2);
            }
            set1(&mut q_x, i, self.q_x(i, &t, flags));
        }
        // Sensors: gradients w.r.t. x_{k-1} (c), own s_{k-1} (e), x_k (fs).
        let mut c_mat = [[0.0; MAX_STATES]; MAX_SENSORS];
        let mut fs = [[0.0; MAX_STATES]; MAX_SENSORS];
        let mut e = [0.0; MAX_SENSORS];
        let mut q_s = [0.0; MAX_SENSORS];
        let mut r = [0.0; MAX_SENSORS];
        let mut s_pred = [0.0; MAX_SENSORS];
        for (j, gp) in self.model.sensors.iter().enumerate().take(dy) {
            let reads = self.sensor_reads_output(j);
            let b = cfg.y_bounds.get(j).copied().unwrap_or((0.0, 1.0));
            let s_in = self.sensor_input(j, &x1, at1(&s1, j), &xk);
            let mut grad = [0.0; MAX_DIM];
            match Self::linearise(gp, &s_in, gp.dim(), scratch, flags, &mut grad) {
                Some(s) => {
                    let sy = self.span_y(j);
                    let off = dx + usize::from(reads);
                    for c in 0..dx {
                        let sc = self.span_x(c);
                        let gc = self.clamp_grad(at1(&grad, c), sy, sc, flags);
                        let gf = self.clamp_grad(at1(&grad, off + c), sy, sc, flags);
                        if let Some(row) = c_mat.get_mut(j) {
                            set1(row, c, gc);
                        }
                        if let Some(row) = fs.get_mut(j) {
                            set1(row, c, gf);
                        }
                    }
                    if reads {
                        set1(&mut e, j, self.clamp_grad(at1(&grad, dx), sy, sy, flags));
                    }
                    let (qs, rj) = self.q_s_r(j, &s, flags);
                    set1(&mut q_s, j, qs);
                    set1(&mut r, j, rj);
                    set1(&mut s_pred, j, clamp_flag(s.mean, b, flags));
                }
                None => {
                    // This sensor keeps its value with a large variance.
                    set1(&mut e, j, 1.0);
                    set1(&mut q_s, j, 0.01 * cfg.p_max * sq(self.span_y(j)));
                    set1(&mut r, j, self.fallback_r(j));
                    set1(&mut s_pred, j, at1(&s1, j));
                }
            }
        }
        // F and G (module docs).
        let mut f = [[0.0; MAX_AUGMENTED]; MAX_AUGMENTED];
        for i in 0..dx {
            for c in 0..dx {
                set2(&mut f, i, c, at3(&a1, i, c));
                set2(&mut f, i, dx + c, at3(&a2, i, c));
            }
            set2(&mut f, dx + i, i, 1.0);
        }
        for j in 0..dy {
            let k = 2 * dx + j;
            let fs_row = fs.get(j).copied().unwrap_or([0.0; MAX_STATES]);
            let c_row = c_mat.get(j).copied().unwrap_or([0.0; MAX_STATES]);
            for c in 0..dx {
                let mut v1 = at1(&c_row, c);
                let mut v2 = 0.0;
                for i in 0..dx {
                    v1 += at1(&fs_row, i) * at3(&a1, i, c);
                    v2 += at1(&fs_row, i) * at3(&a2, i, c);
                }
                set2(&mut f, k, c, v1);
                set2(&mut f, k, dx + c, v2);
            }
            set2(&mut f, k, k, at1(&e, j));
        }
        let mut p = sandwich(&f, &st.p, n);
        // Q = G diag(q_x) G^T + diag(0, 0, q_s), G = [I; 0; Fs].
        let mut g = [[0.0; MAX_STATES]; MAX_AUGMENTED];
        for i in 0..dx {
            if let Some(row) = g.get_mut(i) {
                set1(row, i, 1.0);
            }
        }
        for j in 0..dy {
            if let (Some(row), Some(fs_row)) = (g.get_mut(2 * dx + j), fs.get(j)) {
                for c in 0..dx {
                    set1(row, c, at1(fs_row, c));
                }
            }
        }
        for (p_row, g_a) in p.iter_mut().zip(&g).take(n) {
            for (pab, g_b) in p_row.iter_mut().zip(&g).take(n) {
                let mut q = 0.0;
                for ((ga, qi), gb) in g_a.iter().zip(&q_x).zip(g_b).take(dx) {
                    q += ga * qi * gb;
                }
                *pab += q;
            }
        }
        for j in 0..dy {
            let k = 2 * dx + j;
            add2(&mut p, k, k, at1(&q_s, j));
        }
        let mut z = [0.0; MAX_AUGMENTED];
        for i in 0..dx {
            set1(&mut z, i, at1(&xk, i));
            set1(&mut z, dx + i, at1(&x1, i));
        }
        for j in 0..dy {
            set1(&mut z, 2 * dx + j, at1(&s_pred, j));
        }
        st.z = z;
        st.p = p;
        Predicted {
            q_x,
            q_s,
            r,
            s_pred,
            jacobian: f,
            left_box,
        }
    }

    /// Unscented prediction (spherical cubature: `2 L` points `mean +- sqrt(L) S_i` of the
    /// augmented `[z, w]`, `L = n + dx`, all weights `1 / (2 L)`). Each point passes through
    /// the transitions' means plus its noise `w`, then the sensors' means. The mean is that of
    /// the points clamped to the box, the covariance that of the points as they are (as in
    /// [`crate::Ekf`]), plus `q_s` on the sensors. The noises come from the GP variances at
    /// the mean; the reported Jacobian is the EKF's at the mean.
    ///
    /// With `cross`, it also writes the cross-covariance of the state before the prediction
    /// with the predicted one (left as it is where the prediction falls back to the
    /// linearised one or the random walk).
    fn predict_unscented(
        &self,
        st: &mut VectorState,
        scratch: &mut [f64],
        flags: &mut u32,
        cross: Option<&mut AugMatrix>,
    ) -> Predicted {
        let d = self.model.dims;
        let (dx, dy) = (d.states, d.sensors);
        let n = d.augmented();
        let big_l = n + dx;
        let cfg = self.config;
        // The linearisation at the mean gives the noises and the diagnostic Jacobian.
        let mut lin_state = *st;
        let before = *flags;
        let lin = self.predict_linearised(&mut lin_state, scratch, flags);
        if (*flags & !before) & Flags::MODEL_INVALID != 0 {
            // A GP failed at the mean: the linearised prediction's fallback stands.
            *st = lin_state;
            return lin;
        }
        // Augmented covariance diag(P, q_x) and its Cholesky factor.
        let mut pa = [[0.0; MAX_SIGMA_DIM]; MAX_SIGMA_DIM];
        for a in 0..n {
            for b in 0..n {
                set_s(&mut pa, a, b, at2(&st.p, a, b));
            }
        }
        for i in 0..dx {
            set_s(&mut pa, n + i, n + i, at1(&lin.q_x, i));
        }
        let Some(l) = cholesky_n(&pa, big_l) else {
            *flags |= Flags::MODEL_INVALID;
            return self.random_walk(st);
        };
        let spread = sqrt(big_l as f64);
        let (x1m, x2m, s1m) = self.split(&st.z);
        // The transitions' means at the mean (reused by points that move only s or w).
        let t_in_mean = self.transition_input(st, &x1m, &x2m);
        let mut xk_mean = [0.0; MAX_STATES];
        for (i, gp) in self.model.transitions.iter().enumerate().take(dx) {
            let Some(m) = Self::mean_of(gp, &t_in_mean, scratch) else {
                *flags |= Flags::MODEL_INVALID;
                return self.random_walk(st);
            };
            set1(&mut xk_mean, i, m);
        }
        let mut sum = [0.0; MAX_AUGMENTED];
        let mut free_sum = [0.0; MAX_AUGMENTED];
        let mut points = [[0.0; MAX_AUGMENTED]; 2 * MAX_SIGMA_DIM];
        let count = 2 * big_l;
        for (idx, point) in points.iter_mut().enumerate().take(count) {
            let col = idx / 2;
            let sign = if idx % 2 == 0 { spread } else { -spread };
            let mut dz = [0.0; MAX_SIGMA_DIM];
            for a in 0..big_l {
                set_s1(&mut dz, a, sign * at_s(&l, a, col));
            }
            let mut x1 = x1m;
            let mut x2 = x2m;
            let mut s1 = s1m;
            let mut moved_x = false;
            for i in 0..dx {
                let (d1, d2) = (at_s1(&dz, i), at_s1(&dz, dx + i));
                moved_x |= d1 != 0.0 || d2 != 0.0;
                add1s(&mut x1, i, d1);
                add1s(&mut x2, i, d2);
            }
            for j in 0..dy {
                add1s4(&mut s1, j, at_s1(&dz, 2 * dx + j));
            }
            let mut xk = [0.0; MAX_STATES];
            if moved_x {
                let t_in = self.transition_input(st, &x1, &x2);
                for (i, gp) in self.model.transitions.iter().enumerate().take(dx) {
                    let Some(m) = Self::mean_of(gp, &t_in, scratch) else {
                        *flags |= Flags::MODEL_INVALID;
                        return self.random_walk(st);
                    };
                    set1(&mut xk, i, m);
                }
            } else {
                xk = xk_mean;
            }
            let mut xk_in = [0.0; MAX_STATES];
            for i in 0..dx {
                let v = at1(&xk, i) + at_s1(&dz, n + i);
                set1(&mut xk, i, v);
                let b = cfg.x_bounds.get(i).copied().unwrap_or((0.0, 1.0));
                set1(&mut xk_in, i, clamp_flag(v, b, flags));
            }
            for i in 0..dx {
                set1(point, i, at1(&xk, i));
                set1(point, dx + i, at1(&x1, i));
                add1(&mut sum, i, at1(&xk_in, i));
                add1(&mut sum, dx + i, at1(&x1, i));
                add1(&mut free_sum, i, at1(&xk, i));
                add1(&mut free_sum, dx + i, at1(&x1, i));
            }
            for (j, gp) in self.model.sensors.iter().enumerate().take(dy) {
                let s_in = self.sensor_input(j, &x1, at1(&s1, j), &xk_in);
                let Some(sk) = Self::mean_of(gp, &s_in, scratch) else {
                    *flags |= Flags::MODEL_INVALID;
                    return self.random_walk(st);
                };
                let b = cfg.y_bounds.get(j).copied().unwrap_or((0.0, 1.0));
                set1(point, 2 * dx + j, sk);
                add1(&mut sum, 2 * dx + j, clamp_to(sk, b.0, b.1));
                add1(&mut free_sum, 2 * dx + j, sk);
            }
        }
        let w = 1.0 / count as f64;
        let mut p = [[0.0; MAX_AUGMENTED]; MAX_AUGMENTED];
        for point in points.iter().take(count) {
            for a in 0..n {
                let da = at1(point, a) - w * at1(&free_sum, a);
                for b in 0..n {
                    let db = at1(point, b) - w * at1(&free_sum, b);
                    add2(&mut p, a, b, w * da * db);
                }
            }
        }
        if let Some(c) = cross {
            // cov(z_{k-1}, z_k^-): the points' deviations in `z` are `+-sqrt(L) S_{a, col}`
            // (they sum to zero, so the predicted points need no centring).
            *c = [[0.0; MAX_AUGMENTED]; MAX_AUGMENTED];
            for (idx, point) in points.iter().enumerate().take(count) {
                let col = idx / 2;
                let sign = if idx % 2 == 0 { spread } else { -spread };
                for a in 0..n {
                    let da = w * sign * at_s(&l, a, col);
                    for b in 0..n {
                        add2(c, a, b, da * at1(point, b));
                    }
                }
            }
        }
        let mut z = [0.0; MAX_AUGMENTED];
        for i in 0..dx {
            let b = cfg.x_bounds.get(i).copied().unwrap_or((0.0, 1.0));
            set1(&mut z, i, clamp_flag(w * at1(&sum, i), b, flags));
            set1(&mut z, dx + i, clamp_flag(w * at1(&sum, dx + i), b, flags));
        }
        let mut s_pred = [0.0; MAX_SENSORS];
        for j in 0..dy {
            let k = 2 * dx + j;
            // q_s: the sensor's epistemic variance at the mean, as in the EKF.
            add2(&mut p, k, k, at1(&lin.q_s, j));
            let b = cfg.y_bounds.get(j).copied().unwrap_or((0.0, 1.0));
            let v = clamp_flag(w * at1(&sum, k), b, flags);
            set1(&mut z, k, v);
            set1(&mut s_pred, j, v);
        }
        st.z = z;
        st.p = p;
        Predicted {
            q_x: lin.q_x,
            q_s: lin.q_s,
            r: lin.r,
            s_pred,
            jacobian: lin.jacobian,
            left_box: lin.left_box,
        }
    }

    /// Measurement update of the sensors with a finite sample, Joseph form.
    fn update(
        &self,
        st: &mut VectorState,
        y: &[f64; MAX_SENSORS],
        r: &[f64; MAX_SENSORS],
        flags: &mut u32,
    ) -> Updated {
        let d = self.model.dims;
        let (dx, dy) = (d.states.min(MAX_STATES), d.sensors.min(MAX_SENSORS));
        let n = d.augmented().min(MAX_AUGMENTED);
        let cfg = &self.config;
        let mut out = Updated {
            innovation: [0.0; MAX_SENSORS],
            innovation_var: [0.0; MAX_SENSORS],
            nis: 0.0,
        };
        // The sensors updated this step: index into z.
        let mut rows = [0usize; MAX_SENSORS];
        let mut sensor_of = [0usize; MAX_SENSORS];
        let mut m = 0usize;
        for j in 0..dy {
            let k = 2 * dx + j;
            set1(
                &mut out.innovation_var,
                j,
                saturating_sum(at2(&st.p, k, k), at1(r, j)),
            );
            if at1(y, j).is_finite() {
                if let (Some(slot), Some(sj)) = (rows.get_mut(m), sensor_of.get_mut(m)) {
                    *slot = k;
                    *sj = j;
                }
                m += 1;
            } else {
                *flags |= Flags::MEASUREMENT_INVALID;
            }
        }
        let m = m.min(MAX_SENSORS);
        if m == 0 {
            return out;
        }
        // S = H P H^T + R, innovation nu.
        let mut s = [[0.0; MAX_SENSORS]; MAX_SENSORS];
        let mut nu = [0.0; MAX_SENSORS];
        for a in 0..m {
            let (ka, ja) = (at_u(&rows, a), at_u(&sensor_of, a));
            set1(&mut nu, a, at1(y, ja) - at1(&st.z, ka));
            for b in 0..m {
                let kb = at_u(&rows, b);
                set4(&mut s, a, b, at2(&st.p, ka, kb));
            }
            add4(&mut s, a, a, at1(r, ja));
        }
        // Scaled check of the smallest pivot.
        let Some(l) = cholesky4(&s, m) else {
            *flags |= Flags::INNOVATION_SINGULAR;
            return out;
        };
        for a in 0..m {
            let ja = at_u(&sensor_of, a);
            let pivot = at4(&s, a, a);
            if pivot.is_nan() || pivot < cfg.innovation_min * sq(self.span_y(ja)) {
                *flags |= Flags::INNOVATION_SINGULAR;
                return out;
            }
        }
        // NIS = nu^T S^-1 nu = |L^-1 nu|^2.
        let v = forward4(&l, &nu, m);
        // An overflowing NIS (a wild measurement) saturates: it is then gated like any outlier.
        let nis: f64 = v.iter().take(m).map(|x| x * x).sum::<f64>().min(f64::MAX);
        out.nis = nis;
        for a in 0..m {
            let ja = at_u(&sensor_of, a);
            set1(&mut out.innovation, ja, at1(&nu, a));
        }
        // The outlier gate inflates S (and R by the same amount).
        let gate = cfg.nis_gate * m as f64;
        let (s_used, l_used) = if cfg.nis_gate > 0.0 && nis > gate {
            *flags |= Flags::OUTLIER_REJECTED;
            let factor = nis / gate;
            let mut s2 = s;
            for a in 0..m {
                for b in 0..m {
                    set4(&mut s2, a, b, at4(&s, a, b) * factor);
                }
            }
            match cholesky4(&s2, m) {
                Some(l2) => (s2, l2),
                None => {
                    *flags |= Flags::INNOVATION_SINGULAR;
                    return out;
                }
            }
        } else {
            (s, l)
        };
        // R used: S_used - H P H^T.
        let mut r_used = [[0.0; MAX_SENSORS]; MAX_SENSORS];
        for a in 0..m {
            let ka = at_u(&rows, a);
            for b in 0..m {
                let kb = at_u(&rows, b);
                set4(&mut r_used, a, b, at4(&s_used, a, b) - at2(&st.p, ka, kb));
            }
        }
        // K = P H^T S^-1 (n x m): solve S K^T = H P for each state row.
        let mut k_gain = [[0.0; MAX_SENSORS]; MAX_AUGMENTED];
        for i in 0..n {
            let mut ph = [0.0; MAX_SENSORS];
            for a in 0..m {
                set1(&mut ph, a, at2(&st.p, i, at_u(&rows, a)));
            }
            let w = forward4(&l_used, &ph, m);
            let kr = backward4(&l_used, &w, m);
            if let Some(row) = k_gain.get_mut(i) {
                *row = kr;
            }
        }
        // z += K nu; Joseph: P = (I - K H) P (I - K H)^T + K R K^T.
        let mut z = st.z;
        let mut a_mat = [[0.0; MAX_AUGMENTED]; MAX_AUGMENTED];
        for i in 0..n {
            let row = k_gain.get(i).copied().unwrap_or([0.0; MAX_SENSORS]);
            let mut dzi = 0.0;
            for a in 0..m {
                dzi += at1(&row, a) * at1(&nu, a);
            }
            add1(&mut z, i, dzi);
            set2(&mut a_mat, i, i, 1.0);
            for a in 0..m {
                add2(&mut a_mat, i, at_u(&rows, a), -at1(&row, a));
            }
        }
        let mut p = sandwich(&a_mat, &st.p, n);
        // + K R K^T, as (K R) K^T: row i of K R, then its products with the rows of K^T (each
        // holds the column of K of one sensor).
        let mut kt = [[0.0; MAX_AUGMENTED]; MAX_SENSORS];
        for (j, k_row) in k_gain.iter().enumerate().take(n) {
            for (kt_row, v) in kt.iter_mut().zip(k_row).take(m) {
                set1(kt_row, j, *v);
            }
        }
        for (p_row, k_row) in p.iter_mut().zip(&k_gain).take(n) {
            let mut kr = [0.0; MAX_SENSORS];
            for (kia, r_row) in k_row.iter().zip(&r_used).take(m) {
                for (krb, rab) in kr.iter_mut().zip(r_row).take(m) {
                    *krb += kia * rab;
                }
            }
            let mut acc = [0.0; MAX_AUGMENTED];
            for (krb, kt_row) in kr.iter().zip(&kt).take(m) {
                for (acc_j, kjb) in acc.iter_mut().zip(kt_row) {
                    *acc_j += krb * kjb;
                }
            }
            for (pij, acc_j) in p_row.iter_mut().zip(&acc).take(n) {
                *pij += acc_j;
            }
        }
        let finite = z.iter().take(n).all(|v| v.is_finite())
            && p.iter()
                .take(n)
                .all(|r| r.iter().take(n).all(|v| v.is_finite()));
        if !finite {
            *flags |= Flags::INNOVATION_SINGULAR;
            return out;
        }
        for i in 0..dx {
            let b = cfg.x_bounds.get(i).copied().unwrap_or((0.0, 1.0));
            let v = clamp_flag(at1(&z, i), b, flags);
            set1(&mut z, i, v);
            let v = clamp_flag(at1(&z, dx + i), b, flags);
            set1(&mut z, dx + i, v);
        }
        for j in 0..dy {
            let b = cfg.y_bounds.get(j).copied().unwrap_or((0.0, 1.0));
            let k = 2 * dx + j;
            let v = clamp_flag(at1(&z, k), b, flags);
            set1(&mut z, k, v);
        }
        st.z = z;
        st.p = p;
        self.bound_covariance(&mut st.p, flags);
        out
    }

    /// Symmetrises `p` and clamps the eigenvalues of the scaled covariance
    /// (`P_ij / (span_i span_j)`) into `[p_min, p_max]`, in place.
    fn bound_covariance(&self, p: &mut AugMatrix, flags: &mut u32) {
        let n = self.model.dims.augmented().min(MAX_AUGMENTED);
        let (lo, hi) = (self.config.p_min, self.config.p_max);
        let span = &self.span;
        let mut scaled = [[0.0; MAX_AUGMENTED]; MAX_AUGMENTED];
        let mut finite = true;
        // The lower triangle (each entry is its mirror's value), then the upper.
        for (i, (row, si)) in scaled.iter_mut().zip(span).enumerate().take(n) {
            for (j, (v, sj)) in row.iter_mut().zip(span).enumerate().take(i + 1) {
                *v = 0.5 * (at2(p, i, j) + at2(p, j, i)) / (si * sj);
                finite &= v.is_finite();
            }
        }
        mirror_lower(&mut scaled, n);
        // `p` from a scaled covariance: `m_ij span_i span_j`, zero outside the leading block.
        let unscale = |m: &AugMatrix, p: &mut AugMatrix| {
            *p = [[0.0; MAX_AUGMENTED]; MAX_AUGMENTED];
            for ((o_row, m_row), si) in p.iter_mut().zip(m).zip(span).take(n) {
                for ((o, v), sj) in o_row.iter_mut().zip(m_row).zip(span).take(n) {
                    *o = v * si * sj;
                }
            }
        };
        let fallback = |flags: &mut u32, p: &mut AugMatrix| {
            *flags |= Flags::COVARIANCE_CLAMPED;
            let mut m = [[0.0; MAX_AUGMENTED]; MAX_AUGMENTED];
            for i in 0..n {
                set2(&mut m, i, i, hi);
            }
            unscale(&m, p);
        };
        if !finite {
            return fallback(flags, p);
        }
        if inside_by_ldl(&scaled, n, lo, hi) {
            return unscale(&scaled, p);
        }
        let Some((vals, q)) = crate::eigen::symmetric_eigen_n(&scaled, n) else {
            return fallback(flags, p);
        };
        let mut clamped = vals;
        let mut changed = false;
        for v in clamped.iter_mut().take(n) {
            let c = clamp_to(*v, lo, hi);
            if c != *v {
                changed = true;
                *v = c;
            }
        }
        if !changed {
            return unscale(&scaled, p);
        }
        *flags |= Flags::COVARIANCE_CLAMPED;
        let mut out = [[0.0; MAX_AUGMENTED]; MAX_AUGMENTED];
        for i in 0..n {
            for j in 0..=i {
                let mut acc = 0.0;
                for k in 0..n {
                    acc += at2(&q, i, k) * at1(&clamped, k) * at2(&q, j, k);
                }
                set2(&mut out, i, j, acc);
                set2(&mut out, j, i, acc);
            }
        }
        unscale(&out, p)
    }
}

/// What the update reports.
#[derive(Clone, Copy, Debug)]
struct Updated {
    innovation: [f64; MAX_SENSORS],
    innovation_var: [f64; MAX_SENSORS],
    nis: f64,
}

/// The estimator for firmware: a checked [`VectorEkf`], its state and the caller's scratch
/// memory, all borrowed (the vector twin of [`crate::Estimator`]).
#[derive(Debug)]
pub struct VectorEstimator<'m, 's> {
    ekf: VectorEkf<'m>,
    state: Option<VectorState>,
    scratch: &'s mut [f64],
}

impl<'m, 's> VectorEstimator<'m, 's> {
    /// Checks model, settings and scratch size once; the step then cannot fail.
    pub fn new(
        model: VectorView<'m>,
        config: VectorConfig,
        scratch: &'s mut [f64],
    ) -> Result<Self, CoreError> {
        let ekf = VectorEkf::new(model, config)?;
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
    pub fn state(&self) -> Option<&VectorState> {
        self.state.as_ref()
    }

    /// Forgets the state; the next step initialises again.
    pub fn reset(&mut self) {
        self.state = None;
    }

    /// Processes sample `k` ([`VectorEkf::step`]).
    pub fn step(&mut self, u_k: &[f64], y_k: &[f64]) -> VectorStepOutput {
        self.ekf.step(&mut self.state, self.scratch, u_k, y_k)
    }
}

/// What the measurements of a window say about each state component: for component `i` of
/// `x_k`, the information with every other component of the filter's state left free (the
/// Schur complement `G_ii - g^T G_rr^+ g` of the observability Gramian
/// `G = sum_s Phi_s^T H^T R_s^{-1} H Phi_s`, `Phi_0 = I`, `Phi_{s+1} = F_s Phi_s`,
/// `H = [0, 0, I]`; `^+` drops eigenvalues below `1e-12` of the largest). A component no
/// sensor sees, directly or through the dynamics, has information 0. `jacobians` and `r` (one
/// noise variance per sensor) are oldest first. `None` for an empty or mismatched window or a
/// non-finite Gramian.
pub fn vector_state_information(
    dims: Dims,
    jacobians: &[AugMatrix],
    r: &[[f64; MAX_SENSORS]],
) -> Option<[f64; MAX_STATES]> {
    if jacobians.is_empty() || jacobians.len() != r.len() || dims.validate().is_err() {
        return None;
    }
    let n = dims.augmented();
    let mut phi = [[0.0; MAX_AUGMENTED]; MAX_AUGMENTED];
    for i in 0..n {
        set2(&mut phi, i, i, 1.0);
    }
    let mut gram = [[0.0; MAX_AUGMENTED]; MAX_AUGMENTED];
    for (k, (f, rk)) in jacobians.iter().zip(r).enumerate() {
        if k > 0 {
            phi = product(f, &phi, n);
        }
        for j in 0..dims.sensors {
            let row = 2 * dims.states + j;
            let w = 1.0 / at1(rk, j).max(f64::MIN_POSITIVE);
            for a in 0..n {
                for b in 0..n {
                    add2(&mut gram, a, b, at2(&phi, row, a) * w * at2(&phi, row, b));
                }
            }
        }
    }
    if !gram
        .iter()
        .take(n)
        .all(|r| r.iter().take(n).all(|v| v.is_finite()))
    {
        return None;
    }
    let mut info = [0.0; MAX_STATES];
    for i in 0..dims.states {
        // The block of the other components and the coupling g.
        let mut rest = [[0.0; MAX_AUGMENTED]; MAX_AUGMENTED];
        let mut g = [0.0; MAX_AUGMENTED];
        let mut m = 0;
        let mut idx = [0usize; MAX_AUGMENTED];
        for a in (0..n).filter(|&a| a != i) {
            if let Some(slot) = idx.get_mut(m) {
                *slot = a;
            }
            m += 1;
        }
        for a in 0..m {
            let ia = at_ua(&idx, a);
            set1(&mut g, a, at2(&gram, i, ia));
            for b in 0..m {
                set2(&mut rest, a, b, at2(&gram, ia, at_ua(&idx, b)));
            }
        }
        let (vals, q) = crate::eigen::symmetric_eigen_n(&rest, m)?;
        let largest = vals
            .iter()
            .take(m)
            .fold(at2(&gram, i, i).abs(), |acc, v| acc.max(v.abs()));
        let mut explained = 0.0;
        for k in 0..m {
            let l = at1(&vals, k);
            if l > 1e-12 * largest {
                let mut proj = 0.0;
                for a in 0..m {
                    proj += at1(&g, a) * at2(&q, a, k);
                }
                explained += proj * proj / l;
            }
        }
        let v = at2(&gram, i, i) - explained;
        if !v.is_finite() {
            return None;
        }
        set1(&mut info, i, v.max(0.0));
    }
    Some(info)
}

// ---- small fixed-size helpers (checked access: no panic path) ----

fn sqrt(v: f64) -> f64 {
    crate::simd::sqrt(v)
}

fn sq(v: f64) -> f64 {
    v * v
}

fn saturating_sum(a: f64, b: f64) -> f64 {
    let s = a + b;
    if s.is_finite() { s } else { f64::MAX }
}

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

fn floor_flag(v: f64, floor: f64, flags: &mut u32) -> f64 {
    if v.is_finite() && v >= floor {
        v
    } else {
        *flags |= Flags::NOISE_FLOOR;
        floor
    }
}

/// The first `n` values of `v`, the rest NaN (missing).
fn padded<const N: usize>(v: &[f64], n: usize) -> [f64; N] {
    let mut out = [f64::NAN; N];
    for (o, x) in out.iter_mut().zip(v).take(n) {
        *o = *x;
    }
    out
}

fn copy_into(dst: &mut [f64], src: &[f64]) {
    for (d, s) in dst.iter_mut().zip(src) {
        *d = *s;
    }
}

#[inline(always)]
fn at1(v: &[f64], i: usize) -> f64 {
    v.get(i).copied().unwrap_or(0.0)
}

#[inline(always)]
fn set1(v: &mut [f64], i: usize, x: f64) {
    if let Some(s) = v.get_mut(i) {
        *s = x;
    }
}

#[inline(always)]
fn add1(v: &mut [f64], i: usize, x: f64) {
    if let Some(s) = v.get_mut(i) {
        *s += x;
    }
}

#[inline(always)]
fn add1s(v: &mut [f64; MAX_STATES], i: usize, x: f64) {
    add1(v, i, x);
}

#[inline(always)]
fn add1s4(v: &mut [f64; MAX_SENSORS], i: usize, x: f64) {
    add1(v, i, x);
}

#[inline(always)]
fn at_u(v: &[usize; MAX_SENSORS], i: usize) -> usize {
    v.get(i).copied().unwrap_or(0)
}

#[inline(always)]
fn at_ua(v: &[usize; MAX_AUGMENTED], i: usize) -> usize {
    v.get(i).copied().unwrap_or(0)
}

#[inline(always)]
fn at2(m: &AugMatrix, i: usize, j: usize) -> f64 {
    m.get(i).and_then(|r| r.get(j)).copied().unwrap_or(0.0)
}

#[inline(always)]
fn set2(m: &mut AugMatrix, i: usize, j: usize, v: f64) {
    if let Some(x) = m.get_mut(i).and_then(|r| r.get_mut(j)) {
        *x = v;
    }
}

#[inline(always)]
fn add2(m: &mut AugMatrix, i: usize, j: usize, v: f64) {
    if let Some(x) = m.get_mut(i).and_then(|r| r.get_mut(j)) {
        *x += v;
    }
}

#[inline(always)]
fn at3(m: &[[f64; MAX_STATES]; MAX_STATES], i: usize, j: usize) -> f64 {
    m.get(i).and_then(|r| r.get(j)).copied().unwrap_or(0.0)
}

#[inline(always)]
fn set3(m: &mut [[f64; MAX_STATES]; MAX_STATES], i: usize, j: usize, v: f64) {
    if let Some(x) = m.get_mut(i).and_then(|r| r.get_mut(j)) {
        *x = v;
    }
}

#[inline(always)]
fn at4(m: &[[f64; MAX_SENSORS]; MAX_SENSORS], i: usize, j: usize) -> f64 {
    m.get(i).and_then(|r| r.get(j)).copied().unwrap_or(0.0)
}

#[inline(always)]
fn set4(m: &mut [[f64; MAX_SENSORS]; MAX_SENSORS], i: usize, j: usize, v: f64) {
    if let Some(x) = m.get_mut(i).and_then(|r| r.get_mut(j)) {
        *x = v;
    }
}

#[inline(always)]
fn add4(m: &mut [[f64; MAX_SENSORS]; MAX_SENSORS], i: usize, j: usize, v: f64) {
    if let Some(x) = m.get_mut(i).and_then(|r| r.get_mut(j)) {
        *x += v;
    }
}

#[inline(always)]
fn at_s(m: &[[f64; MAX_SIGMA_DIM]; MAX_SIGMA_DIM], i: usize, j: usize) -> f64 {
    m.get(i).and_then(|r| r.get(j)).copied().unwrap_or(0.0)
}

#[inline(always)]
fn set_s(m: &mut [[f64; MAX_SIGMA_DIM]; MAX_SIGMA_DIM], i: usize, j: usize, v: f64) {
    if let Some(x) = m.get_mut(i).and_then(|r| r.get_mut(j)) {
        *x = v;
    }
}

#[inline(always)]
fn at_s1(v: &[f64; MAX_SIGMA_DIM], i: usize) -> f64 {
    at1(v, i)
}

#[inline(always)]
fn set_s1(v: &mut [f64; MAX_SIGMA_DIM], i: usize, x: f64) {
    set1(v, i, x);
}

/// `F P F^T` over the leading `n x n` blocks.
fn sandwich(f: &AugMatrix, p: &AugMatrix, n: usize) -> AugMatrix {
    let n = n.min(MAX_AUGMENTED);
    let fp = product(f, p, n);
    let mut out = [[0.0; MAX_AUGMENTED]; MAX_AUGMENTED];
    // The lower triangle, row by row, each entry the dot product of a row of `F P` with a
    // row of `F` in column order; then the upper triangle mirrors it.
    for (i, (o_row, fp_row)) in out.iter_mut().zip(&fp).enumerate().take(n) {
        for (o, f_row) in o_row.iter_mut().zip(f).take(i + 1) {
            let mut acc = 0.0;
            for (x, y) in fp_row.iter().zip(f_row).take(n) {
                acc += x * y;
            }
            *o = acc;
        }
    }
    mirror_lower(&mut out, n);
    out
}

/// Copies the strict lower triangle of the leading `n x n` block onto the upper one.
fn mirror_lower(m: &mut AugMatrix, n: usize) {
    let n = n.min(MAX_AUGMENTED);
    for i in 1..n {
        for j in 0..i {
            let v = at2(m, i, j);
            set2(m, j, i, v);
        }
    }
}

/// `A B` over the leading `n x n` blocks (a zero entry of `A` adds nothing).
fn product(a: &AugMatrix, b: &AugMatrix, n: usize) -> AugMatrix {
    let n = n.min(MAX_AUGMENTED);
    let mut out = [[0.0; MAX_AUGMENTED]; MAX_AUGMENTED];
    for (o_row, a_row) in out.iter_mut().zip(a).take(n) {
        for (aik, b_row) in a_row.iter().zip(b).take(n) {
            if *aik == 0.0 {
                continue;
            }
            for (o, bkj) in o_row.iter_mut().zip(b_row).take(n) {
                *o += aik * bkj;
            }
        }
    }
    out
}

/// Lower Cholesky factor of the leading `m x m` block (`None` unless positive definite).
fn cholesky4(
    s: &[[f64; MAX_SENSORS]; MAX_SENSORS],
    m: usize,
) -> Option<[[f64; MAX_SENSORS]; MAX_SENSORS]> {
    let mut l = [[0.0; MAX_SENSORS]; MAX_SENSORS];
    for i in 0..m {
        for j in 0..=i {
            let mut acc = at4(s, i, j);
            for k in 0..j {
                acc -= at4(&l, i, k) * at4(&l, j, k);
            }
            if i == j {
                if !(acc.is_finite() && acc > 0.0) {
                    return None;
                }
                set4(&mut l, i, i, sqrt(acc));
            } else {
                let v = acc / at4(&l, j, j);
                set4(&mut l, i, j, v);
            }
        }
    }
    Some(l)
}

/// Solves `L w = b` (leading `m`).
fn forward4(
    l: &[[f64; MAX_SENSORS]; MAX_SENSORS],
    b: &[f64; MAX_SENSORS],
    m: usize,
) -> [f64; MAX_SENSORS] {
    let mut w = [0.0; MAX_SENSORS];
    for i in 0..m {
        let mut acc = at1(b, i);
        for k in 0..i {
            acc -= at4(l, i, k) * at1(&w, k);
        }
        set1(&mut w, i, acc / at4(l, i, i));
    }
    w
}

/// Solves `L^T x = w` (leading `m`).
fn backward4(
    l: &[[f64; MAX_SENSORS]; MAX_SENSORS],
    w: &[f64; MAX_SENSORS],
    m: usize,
) -> [f64; MAX_SENSORS] {
    let mut x = [0.0; MAX_SENSORS];
    for i in (0..m).rev() {
        let mut acc = at1(w, i);
        for k in (i + 1)..m {
            acc -= at4(l, k, i) * at1(&x, k);
        }
        set1(&mut x, i, acc / at4(l, i, i));
    }
    x
}

/// Lower Cholesky factor of the leading `m x m` block of a sigma-point covariance.
fn cholesky_n(
    a: &[[f64; MAX_SIGMA_DIM]; MAX_SIGMA_DIM],
    m: usize,
) -> Option<[[f64; MAX_SIGMA_DIM]; MAX_SIGMA_DIM]> {
    let mut l = [[0.0; MAX_SIGMA_DIM]; MAX_SIGMA_DIM];
    for i in 0..m {
        for j in 0..=i {
            let mut acc = at_s(a, i, j);
            for k in 0..j {
                acc -= at_s(&l, i, k) * at_s(&l, j, k);
            }
            if i == j {
                if !(acc.is_finite() && acc > 0.0) {
                    return None;
                }
                set_s(&mut l, i, i, sqrt(acc));
            } else {
                let v = acc / at_s(&l, j, j);
                set_s(&mut l, i, j, v);
            }
        }
    }
    Some(l)
}

/// True when every eigenvalue of the symmetric leading `n x n` block of `p` is certainly in
/// `[lo, hi]`: `p - lo I` has an `L D L^T` factorisation with `D > 0` and the trace is at
/// most `hi` (as the scalar filter's test).
fn inside_by_ldl(p: &AugMatrix, n: usize, lo: f64, hi: f64) -> bool {
    let n = n.min(MAX_AUGMENTED);
    let trace: f64 = (0..n).map(|i| at2(p, i, i)).sum();
    if !(lo >= 0.0 && trace <= hi) {
        return false;
    }
    let mut l = [[0.0; MAX_AUGMENTED]; MAX_AUGMENTED];
    let mut dd = [0.0; MAX_AUGMENTED];
    for j in 0..n {
        let mut dj = at2(p, j, j) - lo;
        for k in 0..j {
            dj -= at2(&l, j, k) * at2(&l, j, k) * at1(&dd, k);
        }
        if !(dj > 0.0 && dj.is_finite()) {
            return false;
        }
        set1(&mut dd, j, dj);
        for i in (j + 1)..n {
            let mut acc = at2(p, i, j);
            for k in 0..j {
                acc -= at2(&l, i, k) * at2(&l, j, k) * at1(&dd, k);
            }
            set2(&mut l, i, j, acc / dj);
        }
    }
    true
}
