//! Synthetic vector models for the core's tests: exact SE-ARD GPs fitted (by solving, not
//! optimising) to smooth functions of random inputs.
#![allow(clippy::needless_range_loop)]
#![allow(dead_code)]

use hbn_core::gp::{GpParts, GpView, Variance};
use hbn_core::kernel::{FEATURE_JACOBIAN_LEN, Kernel, KernelSpec, MAX_DIM};
use hbn_core::vector::{Dims, MAX_SENSORS, MAX_STATES, VectorConfig, VectorView};
use hbn_core::{EkfConfig, Mode, Plays};

/// An exact GP's owned arrays.
pub struct OwnedGp {
    spec: KernelSpec,
    theta: Vec<f64>,
    feats: Vec<f64>,
    alpha: Vec<f64>,
    packed: Vec<f64>,
    mean: Vec<f64>,
    scale: Vec<f64>,
    noise: f64,
}

struct Lcg(u64);
impl Lcg {
    fn next(&mut self) -> f64 {
        self.0 = self
            .0
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        (self.0 >> 11) as f64 / (1u64 << 53) as f64
    }
}

impl OwnedGp {
    /// Fits `f` at `n` random inputs in `[0, 1]^d` with length scale `ell` (standardised
    /// units: inputs used as they are) and noise variance `noise`.
    pub fn fit(
        d: usize,
        n: usize,
        ell: f64,
        noise: f64,
        seed: u64,
        f: impl Fn(&[f64]) -> f64,
    ) -> Self {
        Self::fit_ard(&vec![ell; d], n, noise, seed, f)
    }

    /// [`OwnedGp::fit`] with one length scale per input (a huge one: an input the GP ignores).
    pub fn fit_ard(
        ell: &[f64],
        n: usize,
        noise: f64,
        seed: u64,
        f: impl Fn(&[f64]) -> f64,
    ) -> Self {
        let d = ell.len();
        let spec = KernelSpec::se_ard(d);
        let mut theta = vec![0.0; spec.n_params()];
        theta[0] = (0.2f64).ln();
        for (t, l) in theta.iter_mut().skip(1).zip(ell) {
            *t = l.ln();
        }
        let kernel = Kernel::new(spec, &theta, &[]).unwrap();
        let mut rng = Lcg(seed.wrapping_mul(0x9E37_79B9_7F4A_7C15) | 1);
        let xs: Vec<Vec<f64>> = (0..n)
            .map(|_| (0..d).map(|_| rng.next()).collect())
            .collect();
        let ys: Vec<f64> = xs.iter().map(|x| f(x)).collect();
        let ymean = ys.iter().sum::<f64>() / n as f64;
        let yc: Vec<f64> = ys.iter().map(|y| y - ymean).collect();
        let mut k = vec![vec![0.0; n]; n];
        for i in 0..n {
            for j in 0..n {
                k[i][j] = kernel.eval(&xs[i], 0.0, &xs[j], 0.0);
            }
            k[i][i] += noise;
        }
        let mut l = vec![vec![0.0; n]; n];
        for i in 0..n {
            for j in 0..=i {
                let mut acc = k[i][j];
                for m in 0..j {
                    acc -= l[i][m] * l[j][m];
                }
                l[i][j] = if i == j { acc.sqrt() } else { acc / l[j][j] };
            }
        }
        let mut w = vec![0.0; n];
        for i in 0..n {
            let mut acc = yc[i];
            for m in 0..i {
                acc -= l[i][m] * w[m];
            }
            w[i] = acc / l[i][i];
        }
        let mut alpha = vec![0.0; n];
        for i in (0..n).rev() {
            let mut acc = w[i];
            for m in i + 1..n {
                acc -= l[m][i] * alpha[m];
            }
            alpha[i] = acc / l[i][i];
        }
        let mut packed = Vec::with_capacity(n * (n + 1) / 2);
        for (i, row) in l.iter().enumerate() {
            packed.extend_from_slice(&row[..=i]);
        }
        let mut feats = Vec::with_capacity(n * d);
        for x in &xs {
            let mut u = [0.0; MAX_DIM];
            let mut jac = [0.0; FEATURE_JACOBIAN_LEN];
            kernel.features(x, &mut u, &mut jac);
            feats.extend_from_slice(&u[..d]);
        }
        Self {
            spec,
            theta,
            feats,
            alpha,
            packed,
            mean: vec![0.0; d],
            scale: vec![1.0; d],
            noise,
        }
        .with_output_mean(ymean)
    }

    fn with_output_mean(mut self, m: f64) -> Self {
        // Stored in `mean`'s spare slot is not possible; keep it in `noise`'s neighbour.
        self.mean.push(m);
        self
    }

    pub fn view(&self) -> GpView<'_> {
        let d = self.spec.dim;
        GpView::new(GpParts {
            kernel: Kernel::new(self.spec, &self.theta, &[]).unwrap(),
            input_mean: &self.mean[..d],
            input_scale: &self.scale,
            output_mean: self.mean[d],
            output_scale: 1.0,
            linear: &[],
            features: &self.feats,
            directions: &[],
            alpha: &self.alpha,
            alpha_lo: &[],
            variance: Variance::Exact {
                chol_packed: &self.packed,
            },
            noise_var: self.noise,
        })
        .unwrap()
    }
}

/// A vector model's owned GPs.
pub struct Model {
    pub transitions: Vec<OwnedGp>,
    pub sensors: Vec<OwnedGp>,
}

/// Its views (kept apart so the view can borrow them).
pub struct Views<'a> {
    pub transitions: Vec<GpView<'a>>,
    pub sensors: Vec<GpView<'a>>,
}

impl Model {
    pub fn views(&self) -> Views<'_> {
        Views {
            transitions: self.transitions.iter().map(|g| g.view()).collect(),
            sensors: self.sensors.iter().map(|g| g.view()).collect(),
        }
    }
}

impl<'a> Views<'a> {
    pub fn view(&'a self, dims: Dims, plays: Plays) -> VectorView<'a> {
        VectorView {
            dims,
            transitions: &self.transitions,
            sensors: &self.sensors,
            plays,
            init: None,
        }
    }
}

/// A cross-coupled model: each transition a smooth function of all its inputs, each sensor of
/// every state component (and its own previous output when `reads_output`).
pub fn model(dims: Dims, plays: Plays, reads_output: bool, seed: u64) -> Model {
    let t_dim = dims.transition_dim(plays.len());
    let dx = dims.states;
    let transitions = (0..dx)
        .map(|i| {
            OwnedGp::fit(t_dim, 40, 0.8, 1e-4, seed * 31 + i as u64, move |x| {
                let mut v = 0.0;
                for (j, xj) in x.iter().enumerate() {
                    let w = if j == i { 0.6 } else { 0.25 / (1.0 + j as f64) };
                    v += w * xj;
                }
                v + 0.1 * (3.0 * x[0]).sin()
            })
        })
        .collect();
    let s_dim = dims.sensor_dim(reads_output);
    let sensors = (0..dims.sensors)
        .map(|j| {
            OwnedGp::fit(s_dim, 40, 0.9, 1e-4, seed * 57 + 100 + j as u64, move |x| {
                let mut v = 0.0;
                for (c, xc) in x.iter().enumerate() {
                    v += (0.3 + 0.2 * ((c + j) % 3) as f64) * xc;
                }
                (1.2 * v / x.len() as f64).tanh()
            })
        })
        .collect();
    Model {
        transitions,
        sensors,
    }
}

/// A model of one input and two uncoupled state components whose one sensor (state only)
/// reads `x_0` alone, or both when `sees_both`.
pub fn model_with_sensor(dims: Dims, sees_both: bool, seed: u64) -> Model {
    let t_dim = dims.transition_dim(0);
    // Inputs: [x1_0, x1_1, x2_0, x2_1, u1, u2].
    assert_eq!(t_dim, 6);
    let ard = |relevant: &[usize], d: usize| -> Vec<f64> {
        (0..d)
            .map(|j| if relevant.contains(&j) { 1.0 } else { 1e6 })
            .collect()
    };
    let transitions = vec![
        OwnedGp::fit_ard(&ard(&[0, 2, 4], 6), 60, 1e-5, seed, |x| {
            0.7 * x[0] + 0.2 * x[2] + 0.1 * x[4]
        }),
        OwnedGp::fit_ard(&ard(&[1, 3, 4], 6), 60, 1e-5, seed + 1, |x| {
            0.6 * x[1] + 0.2 * x[3] + 0.2 * x[4]
        }),
    ];
    // Sensor of the state only: [x1_0, x1_1, xk_0, xk_1].
    let seen: &[usize] = if sees_both { &[2, 3] } else { &[2] };
    let sensors = vec![OwnedGp::fit_ard(
        &ard(seen, 4),
        60,
        1e-5,
        seed + 2,
        move |x| {
            if sees_both { x[2] + 0.5 * x[3] } else { x[2] }
        },
    )];
    Model {
        transitions,
        sensors,
    }
}

/// Settings with guards that stay out of the way on these models.
pub fn config(dims: Dims, mode: Mode) -> VectorConfig {
    let _ = dims;
    VectorConfig {
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
        jac_max: 1e3,
        innovation_min: 1e-14,
        nis_gate: 25.0,
        q_scale: 1.0,
        r_scale: 1.0,
        std_scale: [1.0; MAX_STATES],
    }
}

/// The scalar filter's settings equal to [`config`] for a model of one of each (spans 3).
pub fn scalar_config(mode: Mode) -> EkfConfig {
    let span2 = 9.0;
    EkfConfig {
        mode,
        q_floor: 1e-12 * span2,
        r_floor: 1e-12 * span2,
        qx_model_floor: 0.0,
        r_model_floor: 0.0,
        p_min: 1e-14 * span2,
        p_max: 4.0 * span2,
        jac_max: 1e3,
        innovation_min: 1e-14 * span2,
        nis_gate: 25.0,
        x_bounds: (-1.0, 2.0),
        y_bounds: (-1.0, 2.0),
        x0_mean: 0.5,
        x0_var: 0.05,
        q_scale: 1.0,
        r_scale: 1.0,
        std_scale: 1.0,
    }
}
