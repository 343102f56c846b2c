//! The owned streaming estimator: [`Filter`] holds the model, the checked core step, the state
//! and the scratch, so a robot node keeps one value next to nothing else and calls
//! [`Filter::step`] per sample. Batch estimation ([`HysteresisModel::estimate`]) runs the same
//! per-sample code ([`Tracker::step`]) in a loop, so streaming and batch cannot differ.

use std::sync::Arc;

use hbn_core::{Ekf, EkfState, Mode, StepOutput, observability_eigenvalues, state_information};
use nalgebra::Matrix3;
use self_cell::self_cell;

use crate::estimate::{Estimate, OBSERVABILITY_WINDOW};
use crate::{HysteresisModel, ModelError};

/// One sample's result: the core step's output plus the observability diagnostic.
/// Dereferences to [`StepOutput`], so `out.x` and `out.x_std` read directly.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FilterOutput {
    /// The EKF step's output.
    pub step: StepOutput,
    /// Smallest eigenvalue of the `h = 3` observability Gramian over the last
    /// `OBSERVABILITY_WINDOW + 1` linearisations (NaN for the first samples).
    pub obs_min: f64,
    /// Largest eigenvalue of that Gramian (NaN for the first samples).
    pub obs_max: f64,
    /// Information on `x` alone in that Gramian, the other state components left free
    /// ([`hbn_core::state_information`]; NaN for the first samples).
    pub obs_x: f64,
}

impl std::ops::Deref for FilterOutput {
    type Target = StepOutput;
    fn deref(&self) -> &StepOutput {
        &self.step
    }
}

const WINDOW: usize = OBSERVABILITY_WINDOW + 1;

/// The filter's memory between samples beside the core state: the last linearisations for the
/// observability Gramian, in fixed arrays (no allocation per step).
#[derive(Clone, Debug)]
pub(crate) struct Tracker {
    state: Option<EkfState>,
    scratch: Vec<f64>,
    jacobians: [Matrix3<f64>; WINDOW],
    r: [f64; WINDOW],
    seen: usize,
}

impl Tracker {
    pub(crate) fn new(ekf: &Ekf<'_>) -> Self {
        Self {
            state: None,
            scratch: vec![0.0; ekf.scratch_len()],
            jacobians: [Matrix3::identity(); WINDOW],
            r: [0.0; WINDOW],
            seen: 0,
        }
    }

    pub(crate) fn reset(&mut self) {
        self.state = None;
        self.seen = 0;
    }

    /// One sample: the core step, then the observability window (oldest first).
    pub(crate) fn step(&mut self, ekf: &Ekf<'_>, u_k: f64, y_k: f64) -> FilterOutput {
        let step = ekf.step(&mut self.state, &mut self.scratch, u_k, y_k);
        self.jacobians.rotate_left(1);
        self.r.rotate_left(1);
        self.jacobians[WINDOW - 1] = step.jacobian;
        self.r[WINDOW - 1] = step.r;
        self.seen = (self.seen + 1).min(WINDOW);
        let (obs_min, obs_max, obs_x) = if self.seen == WINDOW {
            let (lo, hi) =
                observability_eigenvalues(&self.jacobians, &self.r).unwrap_or((f64::NAN, f64::NAN));
            let x = state_information(&self.jacobians, &self.r).unwrap_or(f64::NAN);
            (lo, hi, x)
        } else {
            (f64::NAN, f64::NAN, f64::NAN)
        };
        FilterOutput {
            step,
            obs_min,
            obs_max,
            obs_x,
        }
    }

    pub(crate) fn state(&self) -> Option<&EkfState> {
        self.state.as_ref()
    }

    /// The state, to update with a measurement of it (offline smoothing of training logs).
    pub(crate) fn state_mut(&mut self) -> Option<&mut EkfState> {
        self.state.as_mut()
    }
}

// The owner is the model (shared, so several filters and the caller can hold one copy); the
// dependent is the checked core step over its arrays. `GpView::new` checks every array, O(n^2),
// so the view is built once here and never per step; self_cell keeps both in one value without
// unsafe code in this crate.
self_cell!(
    struct ModelCell {
        owner: Arc<HysteresisModel>,
        #[covariant]
        dependent: Ekf,
    }
    impl {Debug}
);

/// The streaming estimator, owning everything it needs: the model (shared through an
/// [`Arc`]), the checked step, the state and the scratch memory. Built once (which checks the
/// model and settings); [`Filter::step`] then never fails, allocates nothing and is bounded in
/// time. The first step initialises exactly as batch estimation does (the prior of `x_0` from
/// the first measurement, [`HysteresisModel::initial_state`]).
///
/// ```
/// use hbn_model::{Filter, HysteresisModel, HbnParams, Sequence};
/// use hbn_core::Mode;
/// # let u: Vec<f64> = (0..300).map(|k| (k as f64 * 0.05).sin()).collect();
/// # let x: Vec<f64> = u.iter().map(|v| 0.8 * v).collect();
/// # let y: Vec<f64> = x.iter().map(|v| v + 0.1 * v * v).collect();
/// let params = HbnParams { max_points: 80, n_starts: 1, ..HbnParams::default() };
/// let model = HysteresisModel::fit(&[Sequence::new(&u, &x, &y)], &params)?;
/// let mut filter = Filter::new(model, Mode::Ekf)?;
/// for (&u_k, &y_k) in u.iter().zip(&y) {
///     let out = filter.step(u_k, y_k);
///     assert!(out.x.is_finite() && out.x_std >= 0.0);
/// }
/// # Ok::<(), hbn_model::ModelError>(())
/// ```
#[derive(Debug)]
pub struct Filter {
    cell: ModelCell,
    tracker: Tracker,
}

impl Filter {
    /// A filter over `model` in `mode` with the model's default settings
    /// ([`HysteresisModel::ekf_config`]). Checks the model and settings once.
    pub fn new(model: impl Into<Arc<HysteresisModel>>, mode: Mode) -> Result<Self, ModelError> {
        let cell = ModelCell::try_new(model.into(), |m| -> Result<Ekf<'_>, ModelError> {
            Ok(Ekf::new(m.view()?, m.ekf_config(mode))?)
        })?;
        let tracker = Tracker::new(cell.borrow_dependent());
        Ok(Self { cell, tracker })
    }

    /// Processes sample `k`: input `u_k` and measurement `y_k`. No allocation, no panic,
    /// bounded time; NaN or infinite samples are held or skipped and reported in the flags.
    pub fn step(&mut self, u_k: f64, y_k: f64) -> FilterOutput {
        self.tracker.step(self.cell.borrow_dependent(), u_k, y_k)
    }

    /// Forgets the state: the next step initialises again, as at construction.
    pub fn reset(&mut self) {
        self.tracker.reset();
    }

    /// Runs the filter from a fresh start over a whole sequence (what
    /// [`HysteresisModel::estimate`] returns for the same model and mode). Leaves the filter in the
    /// state after the last sample.
    pub fn run(&mut self, u: &[f64], y: &[f64]) -> Result<Estimate, ModelError> {
        self.reset();
        run(&mut self.tracker, self.cell.borrow_dependent(), u, y)
    }

    /// The model.
    pub fn model(&self) -> &Arc<HysteresisModel> {
        self.cell.borrow_owner()
    }

    /// The estimation mode.
    pub fn mode(&self) -> Mode {
        self.cell.borrow_dependent().config().mode
    }

    /// The state after the last step (`None` before the first).
    pub fn state(&self) -> Option<&EkfState> {
        self.tracker.state()
    }
}

/// The batch loop over [`Tracker::step`] shared by [`Filter::run`] and
/// [`HysteresisModel::estimate`].
pub(crate) fn run(
    tracker: &mut Tracker,
    ekf: &Ekf<'_>,
    u: &[f64],
    y: &[f64],
) -> Result<Estimate, ModelError> {
    if u.len() != y.len() {
        return Err(crate::DataError::InputOutputLength {
            u: u.len(),
            y: y.len(),
        }
        .into());
    }
    let mut out = Estimate::with_capacity(u.len());
    for (&u_k, &y_k) in u.iter().zip(y) {
        out.push(&tracker.step(ekf, u_k, y_k));
    }
    Ok(out)
}
