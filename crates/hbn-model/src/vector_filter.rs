//! The owned streaming estimator of a vector model: [`VectorFilter`] holds the model, its
//! checked step ([`hbn_core::vector::VectorEkf`]), the state and the scratch, the vector twin
//! of [`crate::Filter`]. Its steps are those of [`VectorModel::estimate`], bit for bit.

use std::sync::Arc;

use hbn_core::vector::{Dims, VectorEkf, VectorState, VectorStepOutput, VectorView};
use hbn_core::{GpView, Mode};
use self_cell::self_cell;

use crate::{ModelError, VectorModel};

/// The checked views of a vector model's GPs, one per state component and one per sensor.
#[derive(Debug)]
struct GpViews<'a> {
    transitions: Vec<GpView<'a>>,
    sensors: Vec<GpView<'a>>,
}

// Two cells, because the step borrows the views' slices, which borrow the model: the inner
// cell owns the model and its GP views (built once: `GpView::new` checks every array, O(n^2));
// the outer one owns the inner cell and the checked step over those views.
self_cell!(
    struct ViewCell {
        owner: Arc<VectorModel>,
        #[covariant]
        dependent: GpViews,
    }
    impl {Debug}
);

self_cell!(
    struct StepCell {
        owner: ViewCell,
        #[covariant]
        dependent: VectorEkf,
    }
    impl {Debug}
);

/// The streaming estimator of a [`VectorModel`], owning everything it needs: the model (shared
/// through an [`Arc`]), the checked step, the state and the scratch memory. Built once (which
/// checks the model and settings); [`VectorFilter::step`] then never fails, allocates nothing
/// and is bounded in time. The first step initialises exactly as [`VectorModel::estimate`]
/// does (the prior of `x_0` from the first measurements), and every step equals the same
/// sample of [`VectorModel::estimate`] bit for bit.
///
/// ```no_run
/// use hbn_model::{HbnParams, VectorFilter, VectorModel, VectorSequence};
/// use hbn_core::{Mode, vector::Dims};
/// # fn data() -> (Vec<f64>, Vec<f64>, Vec<f64>) { unimplemented!() }
/// let (u, x, y) = data(); // row-major (T, 2), (T, 2), (T, 3)
/// let dims = Dims::new(2, 2, 3)?;
/// let params = HbnParams { max_points: 80, n_starts: 1, ..HbnParams::default() };
/// let model = VectorModel::fit(&[VectorSequence::new(&u, &x, &y, dims)], &params)?;
/// let mut filter = VectorFilter::new(model, Mode::Ekf)?;
/// for (u_k, y_k) in u.chunks_exact(2).zip(y.chunks_exact(3)) {
///     let out = filter.step(u_k, y_k);
///     assert!(out.x[..2].iter().all(|v| v.is_finite()));
/// }
/// # Ok::<(), Box<dyn std::error::Error>>(())
/// ```
#[derive(Debug)]
pub struct VectorFilter {
    cell: StepCell,
    state: Option<VectorState>,
    scratch: Vec<f64>,
}

impl VectorFilter {
    /// A filter over `model` in `mode` with the model's settings ([`VectorModel::config`]).
    /// Checks the model and settings once.
    pub fn new(model: impl Into<Arc<VectorModel>>, mode: Mode) -> Result<Self, ModelError> {
        let views = ViewCell::try_new(model.into(), |m| -> Result<GpViews<'_>, ModelError> {
            let d = m.dims();
            let transitions = (0..d.states)
                .map(|i| gp_view(m.transition(i)))
                .collect::<Result<_, _>>()?;
            let sensors = (0..d.sensors)
                .map(|j| gp_view(m.sensor(j)))
                .collect::<Result<_, _>>()?;
            Ok(GpViews {
                transitions,
                sensors,
            })
        })?;
        let cell = StepCell::try_new(views, |v| -> Result<VectorEkf<'_>, ModelError> {
            let model = v.borrow_owner();
            let gps = v.borrow_dependent();
            let view = VectorView {
                dims: model.dims(),
                transitions: &gps.transitions,
                sensors: &gps.sensors,
                plays: model.plays()?,
                init: model.init_prior(),
            };
            Ok(VectorEkf::new(view, model.config(mode))?)
        })?;
        let scratch = vec![0.0; cell.borrow_dependent().scratch_len()];
        Ok(Self {
            cell,
            state: None,
            scratch,
        })
    }

    /// Processes sample `k`: the inputs `u_k` (`du` values) and the measurements `y_k` (`dy`
    /// values; a non-finite one is left out of the update, and missing values count as not
    /// finite). No allocation, no panic, bounded time.
    pub fn step(&mut self, u_k: &[f64], y_k: &[f64]) -> VectorStepOutput {
        self.cell
            .borrow_dependent()
            .step(&mut self.state, &mut self.scratch, u_k, y_k)
    }

    /// Forgets the state: the next step initialises again, as at construction.
    pub fn reset(&mut self) {
        self.state = None;
    }

    /// The model.
    pub fn model(&self) -> &Arc<VectorModel> {
        self.cell.borrow_owner().borrow_owner()
    }

    /// The sizes: inputs, state components, sensors.
    pub fn dims(&self) -> Dims {
        self.cell.borrow_dependent().model().dims
    }

    /// The estimation mode.
    pub fn mode(&self) -> Mode {
        self.cell.borrow_dependent().config().mode
    }

    /// The state after the last step (`None` before the first).
    pub fn state(&self) -> Option<&VectorState> {
        self.state.as_ref()
    }
}

/// The checked view of a GP the model has (a missing one is an inconsistent model).
fn gp_view(gp: Option<&hbn_gp::GaussianProcess>) -> Result<GpView<'_>, ModelError> {
    let gp = gp.ok_or(ModelError::Core(hbn_core::CoreError::InvalidSpec(
        "the model's parts disagree with its sizes",
    )))?;
    Ok(gp.view()?)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::{HbnParams, VectorSequence};

    /// A cross-coupled two-input, two-state, three-sensor toy with a sensor dropout.
    fn data(n: usize, phase: f64) -> (Vec<f64>, Vec<f64>, Vec<f64>) {
        let (mut u, mut x, mut y) = (Vec::new(), Vec::new(), Vec::new());
        let (mut a, mut b) = (0.0f64, 0.0f64);
        for k in 0..n {
            let t = k as f64 * 0.05 + phase;
            let u0 = t.sin();
            let u1 = (0.7 * t).cos();
            a = 0.8 * a + 0.2 * (u0 + 0.3 * u1);
            b = 0.85 * b + 0.15 * (u1 - 0.2 * u0);
            u.extend([u0, u1]);
            x.extend([a, b]);
            y.extend([a + 0.1 * b, b - 0.05 * a * a, a + b]);
        }
        (u, x, y)
    }

    fn model() -> VectorModel {
        let (u, x, y) = data(240, 0.0);
        let dims = Dims::new(2, 2, 3).unwrap();
        let params = HbnParams {
            max_points: 60,
            n_starts: 1,
            max_iters: 30,
            ..HbnParams::default()
        };
        VectorModel::fit(&[VectorSequence::new(&u, &x, &y, dims)], &params).unwrap()
    }

    #[test]
    fn steps_equal_the_batch_estimate_bit_for_bit_in_every_mode() {
        let model = Arc::new(model());
        let (u, _, mut y) = data(150, 1.3);
        y[40 * 3 + 1] = f64::NAN; // a dropout of sensor 1
        for mode in [Mode::Ekf, Mode::Ukf] {
            let batch = model.estimate(&u, &y, mode).unwrap();
            let mut filter = VectorFilter::new(model.clone(), mode).unwrap();
            assert_eq!(filter.mode(), mode);
            assert_eq!(filter.dims(), model.dims());
            for round in 0..2 {
                for (k, (u_k, y_k)) in u.chunks_exact(2).zip(y.chunks_exact(3)).enumerate() {
                    let o = filter.step(u_k, y_k);
                    for i in 0..2 {
                        assert_eq!(o.x[i].to_bits(), batch.x[k * 2 + i].to_bits(), "{k} {i}");
                        assert_eq!(o.x_std[i].to_bits(), batch.x_std[k * 2 + i].to_bits());
                        for j in 0..2 {
                            assert_eq!(
                                o.x_cov[i][j].to_bits(),
                                batch.x_cov[k * 4 + i * 2 + j].to_bits()
                            );
                        }
                    }
                    for j in 0..3 {
                        assert_eq!(o.y_pred[j].to_bits(), batch.y_pred[k * 3 + j].to_bits());
                        assert_eq!(
                            o.innovation[j].to_bits(),
                            batch.innovation[k * 3 + j].to_bits()
                        );
                    }
                    assert_eq!(o.nis.to_bits(), batch.nis[k].to_bits());
                    assert_eq!(o.flags.0, batch.flags[k]);
                }
                assert_eq!(filter.state().map(|s| s.steps), Some(150));
                // After a reset the filter starts again as the batch estimate does.
                filter.reset();
                assert!(filter.state().is_none(), "round {round}");
            }
        }
    }

    #[test]
    fn the_first_step_initialises_from_the_first_measurements() {
        let model = model();
        let (u, _, y) = data(5, 0.4);
        let mut filter = VectorFilter::new(model, Mode::Ekf).unwrap();
        let first = filter.step(&u[..2], &y[..3]);
        assert!(first.flags.names().any(|n| n == "initialised"));
        let second = filter.step(&u[2..4], &y[3..6]);
        assert!(!second.flags.names().any(|n| n == "initialised"));
        assert!(Arc::strong_count(filter.model()) == 1);
    }
}
