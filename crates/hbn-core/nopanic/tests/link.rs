//! Links and runs the `#[no_panic]` wrappers: that this test binary links at all is the proof
//! that `Estimator::step` (and the GP prediction, the local regression and the packed solves)
//! contain no reachable panic after optimisation. The run itself checks the wrappers behave.

use hbn_core::blr::{LocalRegression, Neighbourhood, NeighbourhoodParts};
use hbn_core::gp::{GpParts, GpView, Variance, Want};
use hbn_core::kernel::{Kernel, KernelSpec};
use hbn_core::{EkfConfig, Estimator, HbnView, InitPrior, Mode, Plays};

/// A 2-point GP on `d` inputs with an identity Cholesky factor.
struct Gp {
    theta: Vec<f64>,
    mean: Vec<f64>,
    scale: Vec<f64>,
    feats: Vec<f64>,
    alpha: Vec<f64>,
    chol: Vec<f64>,
    spec: KernelSpec,
}

impl Gp {
    fn new(d: usize) -> Self {
        let spec = KernelSpec::se_ard(d);
        Gp {
            theta: vec![0.0; spec.n_params()],
            mean: vec![0.0; d],
            scale: vec![1.0; d],
            feats: (0..2 * d).map(|i| 0.1 * i as f64).collect(),
            alpha: vec![0.5, -0.25],
            chol: vec![1.0, 0.2, 1.0],
            spec,
        }
    }
    fn view(&self, sparse: bool) -> GpView<'_> {
        let variance = if sparse {
            Variance::Sparse {
                variance_factor: &self.chol,
            }
        } else {
            Variance::Exact {
                chol_packed: &self.chol,
            }
        };
        GpView::new(GpParts {
            kernel: Kernel::new(self.spec, &self.theta, &[]).unwrap(),
            input_mean: &self.mean,
            input_scale: &self.scale,
            output_mean: 0.0,
            output_scale: 1.0,
            linear: &[],
            features: &self.feats,
            directions: &[],
            alpha: &self.alpha,
            alpha_lo: &self.alpha,
            variance,
            noise_var: 0.01,
        })
        .unwrap()
    }
}

struct Local {
    inputs: Vec<f64>,
    targets: Vec<f64>,
}

impl Local {
    fn new(d: usize) -> Self {
        Local {
            inputs: (0..10 * d).map(|i| (i % 7) as f64 * 0.01).collect(),
            targets: (0..10).map(|i| i as f64 * 0.1).collect(),
        }
    }
    fn view(&self, d: usize, one: &'static [f64]) -> Neighbourhood<'_> {
        Neighbourhood::new(
            d,
            NeighbourhoodParts {
                inputs: &self.inputs,
                targets: &self.targets,
                cell_keys: &[0],
                cell_start: &[0, 10],
                origin: &one[..d],
                half_window: &[1.0; 4][..d],
                input_var: &[1.0; 4][..d],
            },
        )
        .unwrap()
    }
}

/// Settings for `mode`; every field is set here once, so a new field breaks one place.
fn config(mode: Mode) -> EkfConfig {
    EkfConfig {
        mode,
        q_floor: 1e-10,
        r_floor: 1e-10,
        qx_model_floor: 0.0,
        r_model_floor: 0.0,
        p_min: 1e-14,
        p_max: 4.0,
        jac_max: 20.0,
        innovation_min: 1e-12,
        nis_gate: 9.0,
        x_bounds: (-1.0, 2.0),
        y_bounds: (-1.0, 2.0),
        x0_mean: 0.5,
        x0_var: 0.1,
        q_scale: 1.0,
        r_scale: 1.0,
        std_scale: 1.0,
    }
}

#[test]
fn step_links_without_panic_paths_and_stays_finite() {
    // The sparse views carry two play operators (the transition then reads 6 inputs).
    let (tr, tr_plays, se) = (Gp::new(4), Gp::new(6), Gp::new(3));
    let plays = Plays::new(&[0.05, 0.3]).unwrap();
    let (tl, sl) = (Local::new(4), Local::new(3));
    static ZERO: [f64; 4] = [0.0; 4];
    let pairs = [[0.0, 0.1], [0.5, 0.4], [0.5, 0.6], [1.0, 0.9]];
    let init = InitPrior::new(&pairs, 2, 1e-6).unwrap();
    let views = [false, true].map(|sparse| HbnView {
        transition: if sparse {
            tr_plays.view(true)
        } else {
            tr.view(false)
        },
        sensor: se.view(sparse),
        transition_local: Some(tl.view(4, &ZERO)),
        sensor_local: Some(sl.view(3, &ZERO)),
        blr: LocalRegression::default(),
        init: Some(init),
        plays: if sparse { plays } else { Plays::NONE },
        // The sparse view's sensor reads the state and two plays of it.
        sensor_memory: if sparse { plays } else { Plays::NONE },
    });
    for (view, mode) in views.iter().flat_map(|v| Mode::ALL.map(|m| (*v, m))) {
        let mut scratch = vec![0.0; Estimator::scratch_len(&view)];
        let mut est = Estimator::new(view, config(mode), &mut scratch).unwrap();
        let inputs = [0.1, f64::NAN, 1e300, -f64::INFINITY, 0.3, 0.0, -1e-300];
        for k in 0..1000 {
            let u = inputs[k % inputs.len()];
            let y = inputs[(k * 3 + 1) % inputs.len()];
            let out = hbn_core_nopanic::step(&mut est, u, y);
            assert!(out.x.is_finite() && out.x_std.is_finite(), "{out:?}");
            if k == 500 {
                hbn_core_nopanic::reset(&mut est);
            }
        }
    }
    let gp = tr.view(false);
    let mut scratch = [0.0; 16];
    assert!(hbn_core_nopanic::predict(&gp, &[0.1; 4], Want::ALL, &mut scratch).is_ok());
    assert!(hbn_core_nopanic::predict(&gp, &[0.1; 3], Want::ALL, &mut scratch).is_err());
    assert!(hbn_core_nopanic::predict(&gp, &[0.1; 4], Want::ALL, &mut scratch[..2]).is_err());
    let (mut w_a, mut w_b) = ([0.0; 2], [0.0; 2]);
    let var = hbn_core_nopanic::whiten(&gp, &[0.1; 4], &mut w_a, &mut scratch).unwrap();
    hbn_core_nopanic::whiten(&gp, &[0.3; 4], &mut w_b, &mut scratch).unwrap();
    let own = hbn_core_nopanic::posterior_covariance(&gp, &[0.1; 4], &w_a, &[0.1; 4], &w_a);
    // An arbitrary factor: the predicted variance is clamped at 0, the covariance is not.
    assert!((own.unwrap().max(0.0) - var).abs() < 1e-12);
    assert!(hbn_core_nopanic::posterior_covariance(&gp, &[0.1; 4], &w_a, &[0.3; 4], &w_b).is_ok());
    assert!(hbn_core_nopanic::whiten(&gp, &[0.1; 4], &mut [0.0; 3], &mut scratch).is_err());
    assert!(hbn_core_nopanic::whiten(&gp, &[0.1; 4], &mut w_a, &mut scratch[..3]).is_err());
    assert!(hbn_core_nopanic::posterior_covariance(&gp, &[0.1; 3], &w_a, &[0.3; 4], &w_b).is_err());
    let nb = tl.view(4, &ZERO);
    for m in [0, 1, 48, 64, usize::MAX] {
        let blr = LocalRegression {
            max_neighbours: m,
            ..LocalRegression::default()
        };
        let p = hbn_core_nopanic::posterior(&blr, &nb, &[0.02; 4], 0.1, &[1.0; 4], 0.1, 0.1);
        assert!(p.n <= 48);
    }
    let mut v = [0.0; 3];
    assert!(hbn_core_nopanic::substitute(&[1.0, 0.0, 1.0], &[1.0; 3], &mut v).is_err());
    assert!(
        hbn_core_nopanic::substitute(&[1.0, 0.0, 1.0, 0.0, 0.0, 1.0], &[1.0; 3], &mut v).is_ok()
    );
}

/// The widening wrapper links (no panic path) and widens a split range.
#[test]
fn widen_links_without_panic_paths() {
    let layout = [hbn_core::tables::MAGIC, hbn_core::tables::VERSION, 1, 1, 1];
    let mut out = [0.0; 3];
    let wide = hbn_core_nopanic::widen(&layout, &[1.0, 2.0, 0.5], &mut out).unwrap();
    assert_eq!(wide, [1.0, 2.5]);
    assert!(hbn_core_nopanic::widen(&layout, &[1.0], &mut out).is_err());
}

/// The vector step (2 inputs with one play each, 2 states, 3 sensors: transitions of 10
/// inputs, wider than the passes compiled per dimension) links without panic paths and stays
/// finite on garbage.
#[test]
fn vector_step_links_without_panic_paths_and_stays_finite() {
    use hbn_core::vector::{
        Dims, MAX_SENSORS, MAX_STATES, VectorConfig, VectorEstimator, VectorView,
    };
    let dims = Dims::new(2, 2, 3).unwrap();
    let plays = Plays::new(&[0.1]).unwrap();
    let t = Gp::new(dims.transition_dim(1));
    let s = Gp::new(dims.sensor_dim(true));
    for sparse in [false, true] {
        let transitions = [t.view(sparse), t.view(sparse)];
        let sensors = [s.view(sparse), s.view(sparse), s.view(sparse)];
        let view = VectorView {
            dims,
            transitions: &transitions,
            sensors: &sensors,
            plays,
            init: None,
        };
        for mode in [Mode::Ekf, Mode::Ukf] {
            let config = VectorConfig {
                mode,
                x_bounds: [(-1.0, 2.0); MAX_STATES],
                y_bounds: [(-1.0, 2.0); MAX_SENSORS],
                x0_mean: [0.5; MAX_STATES],
                x0_var: [0.05; MAX_STATES],
                qx_model_floor: [0.0; MAX_STATES],
                r_model_floor: [0.0; MAX_SENSORS],
                q_floor: 1e-12,
                r_floor: 1e-12,
                p_min: 1e-14,
                p_max: 4.0,
                jac_max: 20.0,
                innovation_min: 1e-14,
                nis_gate: 25.0,
                q_scale: 1.0,
                r_scale: 1.0,
                std_scale: [1.0; MAX_STATES],
            };
            let mut scratch = vec![0.0; view.scratch_len()];
            let mut est = VectorEstimator::new(view, config, &mut scratch).unwrap();
            let values = [0.3, f64::NAN, f64::INFINITY, -1e300, 0.7];
            for k in 0..200 {
                let pick = |i: usize| values[(k * 3 + i) % values.len()];
                let out = hbn_core_nopanic::vector_step(
                    &mut est,
                    &[pick(0), pick(1)][..k % 3],
                    &[pick(2), pick(3), pick(4)],
                );
                assert!(out.x.iter().all(|v| v.is_finite()));
            }
        }
    }
}
