//! Unit tests of the filter step (`hbn_core::ekf`) on a trained model: the linearisation
//! against finite differences of the GPs, the Joseph update against the textbook form, the
//! covariance bounds, every guard flag on a case built to fire it, the empty-BLR-window
//! identity, the outlier gate, the extrapolation flag and the unscented prediction.

use hbn_core::{Ekf, EkfConfig, EkfState, Flags, GpView, HbnView, Mode, StepOutput, Want};
use hbn_model::{HbnParams, HysteresisModel, Sequence};
use hbn_sim::{SimConfig, SystemKind, Trajectory, simulate_random};
use nalgebra::{Matrix3, SymmetricEigen, Vector3};
use std::sync::OnceLock;

struct Fixture {
    model: HysteresisModel,
    test: Trajectory,
}

fn params() -> HbnParams {
    HbnParams {
        max_points: 120,
        n_starts: 1,
        max_iters: 60,
        validation: 0.0,
        ..HbnParams::default()
    }
}

fn train(system: SystemKind, params: &HbnParams) -> Fixture {
    let cfg = SimConfig {
        noise_gain: 1.0,
        ..SimConfig::new(system)
    };
    let train = simulate_random(&cfg, 600).unwrap();
    let model =
        HysteresisModel::fit(&[Sequence::new(&train.u, &train.x, &train.y)], params).unwrap();
    let test = simulate_random(&SimConfig { seed: 77, ..cfg }, 400).unwrap();
    Fixture { model, test }
}

fn fixture() -> &'static Fixture {
    static F: OnceLock<Fixture> = OnceLock::new();
    F.get_or_init(|| train(SystemKind::Duhem, &params()))
}

/// A filter with `cfg`, its scratch, and the state after `steps` samples of the test run.
fn warm(f: &Fixture, cfg: EkfConfig, steps: usize) -> (Ekf<'_>, Vec<f64>, Option<EkfState>) {
    let ekf = Ekf::new(f.model.view().unwrap(), cfg).unwrap();
    let mut scratch = vec![0.0; ekf.scratch_len()];
    let mut state = None;
    for k in 0..steps {
        ekf.step(&mut state, &mut scratch, f.test.u[k], f.test.y[k]);
    }
    (ekf, scratch, state)
}

fn mean(gp: &GpView<'_>, x: &[f64]) -> f64 {
    let mut scratch = vec![0.0; gp.predict_scratch(Want::EKF)];
    gp.predict(x, Want::default(), &mut scratch).unwrap().mean
}

fn variance(gp: &GpView<'_>, x: &[f64]) -> f64 {
    let mut scratch = vec![0.0; gp.predict_scratch(Want::EKF)];
    gp.predict(x, Want::EKF, &mut scratch).unwrap().variance
}

/// The HBN's noise-free prediction `z_k = g(z_{k-1})` for known inputs and plays (module
/// docs of ekf.rs).
fn g(view: &HbnView<'_>, z: &Vector3<f64>, u1: f64, u2: f64, plays: &[f64]) -> Vector3<f64> {
    let xk = mean(&view.transition, &[&[z.x, z.y, u1, u2][..], plays].concat());
    let sk = mean(&view.sensor, &[z.x, z.z, xk]);
    Vector3::new(xk, z.x, sk)
}

fn rel(a: f64, b: f64) -> f64 {
    (a - b).abs() / a.abs().max(b.abs()).max(1e-12)
}

fn cfg(mode: Mode) -> EkfConfig {
    let c = fixture().model.untuned_config(mode);
    EkfConfig { nis_gate: 0.0, ..c }
}

/// The prediction alone: a step whose measurement is missing skips the update.
fn predict_only(
    ekf: &Ekf<'_>,
    scratch: &mut [f64],
    st: EkfState,
    u: f64,
) -> (EkfState, StepOutput) {
    let mut state = Some(st);
    let out = ekf.step(&mut state, scratch, u, f64::NAN);
    (state.unwrap(), out)
}

#[test]
fn linearisation_matches_finite_differences_of_the_gps() {
    let f = fixture();
    let (ekf, mut scratch, state) = warm(f, cfg(Mode::Ekf), 150);
    let st = state.unwrap();
    let view = f.model.view().unwrap();
    let (u1, u2) = (st.u_last, st.u_prev);
    // The default model reads two play operators; the filter carries their values after the
    // last input, as a run of the operators over the inputs so far gives them.
    assert_eq!(view.plays.len(), 2);
    let mut runs = vec![[0.0; hbn_core::MAX_PLAYS]; 150];
    view.plays.run(&f.test.u[..150], &mut runs);
    let plays = &runs[149][..2];
    assert_eq!(&st.plays[..2], plays);
    assert!(
        plays.iter().any(|p| (p - u1).abs() > 1e-9),
        "plays equal the input"
    );
    let (next, out) = predict_only(&ekf, &mut scratch, st, f.test.u[150]);
    assert!(!out.flags.has(Flags::JACOBIAN_CLAMPED) && !out.flags.has(Flags::COVARIANCE_CLAMPED));

    // The mean is g(z).
    let z_pred = g(&view, &st.z, u1, u2, plays);
    for i in 0..3 {
        assert!(
            rel(next.z[i], z_pred[i]) < 1e-12,
            "z[{i}]: {} vs {}",
            next.z[i],
            z_pred[i]
        );
    }
    // F against central differences of g. The step is not tiny: the GP mean is a sum of
    // large weights that cancel, so it is smooth only down to ~1e-9 (h = 1e-6 is noise).
    let span = f.model.stats().1.span();
    let mut fd = Matrix3::zeros();
    for j in 0..3 {
        let h = 1e-3 * span;
        let mut zp = st.z;
        let mut zm = st.z;
        zp[j] += h;
        zm[j] -= h;
        let col = (g(&view, &zp, u1, u2, plays) - g(&view, &zm, u1, u2, plays)) / (2.0 * h);
        fd.set_column(j, &col);
    }
    let scale = fd.abs().max().max(1.0);
    for i in 0..3 {
        for j in 0..3 {
            assert!(
                (out.jacobian[(i, j)] - fd[(i, j)]).abs() < 1e-5 * scale,
                "F[{i}{j}] = {} vs finite difference {}",
                out.jacobian[(i, j)],
                fd[(i, j)]
            );
        }
    }
    // Q: q_x from the transition GP's variance and noise, q_s from the sensor GP's variance,
    // entering through G = [1, 0, dH_S/dx_k].
    let c = ekf.config();
    let a_in = [&[st.z.x, st.z.y, u1, u2][..], plays].concat();
    let q_x = (view.transition.noise_variance() + variance(&view.transition, &a_in))
        .max(c.qx_model_floor)
        .max(c.q_floor);
    assert!(rel(out.q_x, q_x) < 1e-12, "q_x {} vs {}", out.q_x, q_x);
    let b_in = [st.z.x, st.z.z, z_pred.x];
    let q_s = variance(&view.sensor, &b_in).max(c.q_floor);
    let h = 1e-3 * span;
    let f_x = (mean(&view.sensor, &[st.z.x, st.z.z, z_pred.x + h])
        - mean(&view.sensor, &[st.z.x, st.z.z, z_pred.x - h]))
        / (2.0 * h);
    let gv = Vector3::new(1.0, 0.0, f_x);
    let mut q = gv * q_x * gv.transpose();
    q[(2, 2)] += q_s;
    let p_pred = fd * st.p * fd.transpose() + q;
    let p_scale = p_pred.abs().max();
    for i in 0..3 {
        for j in 0..3 {
            assert!(
                (next.p[(i, j)] - p_pred[(i, j)]).abs() < 1e-4 * p_scale,
                "P[{i}{j}] = {} vs F P F^T + Q = {}",
                next.p[(i, j)],
                p_pred[(i, j)]
            );
        }
    }
    // R: the sensor GP's noise (or its model-error floor).
    let r = view
        .sensor
        .noise_variance()
        .max(c.r_model_floor)
        .max(c.r_floor);
    assert!(rel(out.r, r) < 1e-12);
}

#[test]
fn joseph_update_equals_the_textbook_update() {
    let f = fixture();
    let (ekf, mut scratch, state) = warm(f, cfg(Mode::Ekf), 200);
    let st = state.unwrap();
    let (u, y) = (f.test.u[200], f.test.y[200]);
    let (pred, _) = predict_only(&ekf, &mut scratch, st, u);
    let mut state = Some(st);
    let out = ekf.step(&mut state, &mut scratch, u, y);
    let post = state.unwrap();
    assert!(!out.flags.has(Flags::COVARIANCE_CLAMPED) && !out.flags.has(Flags::STATE_CLAMPED));
    // K = P H^T / S, P+ = P - K S K^T, z+ = z + K (y - s).
    let s = pred.p[(2, 2)] + out.r;
    assert!(rel(out.innovation_var, s) < 1e-12);
    let k: Vector3<f64> = pred.p.column(2) / s;
    let innovation = y - pred.z.z;
    assert!(rel(out.innovation, innovation) < 1e-12);
    assert!(rel(out.nis, innovation * innovation / s) < 1e-12);
    let z = pred.z + k * innovation;
    let p = pred.p - k * s * k.transpose();
    let p_scale = pred.p.abs().max();
    for i in 0..3 {
        assert!(rel(post.z[i], z[i]) < 1e-12, "z[{i}]");
        for j in 0..3 {
            assert!(
                (post.p[(i, j)] - p[(i, j)]).abs() < 1e-9 * p_scale,
                "P+[{i}{j}] {} vs {}",
                post.p[(i, j)],
                p[(i, j)]
            );
            assert_eq!(post.p[(i, j)], post.p[(j, i)], "P+ symmetric");
        }
    }
    assert!(
        post.p[(0, 0)] < pred.p[(0, 0)],
        "a measurement shrinks the variance of x"
    );
    assert_eq!(out.x_std, post.p[(0, 0)].sqrt());
}

#[test]
fn covariance_stays_within_its_bounds() {
    let f = fixture();
    let span = f.model.stats().1.span();
    for (name, lo, hi) in [
        ("tight upper bound", 1e-16, 1e-6 * span * span),
        ("high lower bound", 1e-2 * span * span, 4.0 * span * span),
    ] {
        let c = EkfConfig {
            p_min: lo,
            p_max: hi,
            ..cfg(Mode::Ekf)
        };
        let ekf = Ekf::new(f.model.view().unwrap(), c).unwrap();
        let mut scratch = vec![0.0; ekf.scratch_len()];
        let mut state = None;
        let mut clamped = 0;
        for k in 0..f.test.u.len() {
            let out = ekf.step(&mut state, &mut scratch, f.test.u[k], f.test.y[k]);
            clamped += usize::from(out.flags.has(Flags::COVARIANCE_CLAMPED));
            let p = state.unwrap().p;
            assert_eq!(p, p.transpose(), "{name}: P symmetric at {k}");
            let eig = SymmetricEigen::new(p).eigenvalues;
            for v in eig.iter() {
                assert!(
                    *v >= lo * (1.0 - 1e-9) - 1e-15 * hi && *v <= hi * (1.0 + 1e-9),
                    "{name}: eigenvalue {v} outside [{lo}, {hi}] at step {k}"
                );
            }
        }
        assert!(clamped > 0, "{name}: the bound never fired");
    }
}

/// Runs the test log with a changed configuration (and optionally changed inputs) and returns
/// how many steps set `bit`.
fn count(mode: Mode, change: impl Fn(&mut EkfConfig), u: &[f64], y: &[f64], bit: u32) -> usize {
    count_from(0, mode, change, u, y, bit)
}

/// [`count`] over the steps from `from` on.
fn count_from(
    from: usize,
    mode: Mode,
    change: impl Fn(&mut EkfConfig),
    u: &[f64],
    y: &[f64],
    bit: u32,
) -> usize {
    let f = fixture();
    let mut c = cfg(mode);
    change(&mut c);
    let ekf = Ekf::new(f.model.view().unwrap(), c).unwrap();
    let mut scratch = vec![0.0; ekf.scratch_len()];
    let mut state = None;
    u.iter()
        .zip(y)
        .map(|(&u, &y)| ekf.step(&mut state, &mut scratch, u, y).flags.has(bit))
        .skip(from)
        .filter(|&fired| fired)
        .count()
}

#[test]
fn every_flag_fires_on_a_case_built_for_it_and_not_on_clean_data() {
    let f = fixture();
    let (u, y) = (&f.test.u[..], &f.test.y[..]);
    let (sx, sy) = (f.model.stats().1.span(), f.model.stats().2.span());
    let same = |_: &mut EkfConfig| {};
    let mut u_bad = u.to_vec();
    u_bad[50] = f64::NAN;
    let mut y_bad = y.to_vec();
    y_bad[60] = f64::INFINITY;
    let mut y_spike = y.to_vec();
    y_spike[120] += 50.0 * sy;
    let xb = f.model.untuned_config(Mode::Ekf).x_bounds;
    type Change = Box<dyn Fn(&mut EkfConfig)>;
    // (flag expected, mode, change of the configuration, u, y)
    type Case<'a> = (u32, Mode, Change, &'a [f64], &'a [f64]);
    let cases: Vec<Case<'_>> = vec![
        (Flags::INPUT_INVALID, Mode::Ekf, Box::new(same), &u_bad, y),
        (
            Flags::MEASUREMENT_INVALID,
            Mode::Ekf,
            Box::new(same),
            u,
            &y_bad,
        ),
        (
            Flags::JACOBIAN_CLAMPED,
            Mode::Ekf,
            Box::new(|c| c.jac_max = 1e-3),
            u,
            y,
        ),
        (
            Flags::NOISE_FLOOR,
            Mode::Ekf,
            Box::new(move |c| c.q_floor = sx * sx),
            u,
            y,
        ),
        (
            Flags::INNOVATION_SINGULAR,
            Mode::Ekf,
            Box::new(move |c| c.innovation_min = 1e6 * sy * sy),
            u,
            y,
        ),
        (
            Flags::COVARIANCE_CLAMPED,
            Mode::Ekf,
            Box::new(move |c| c.p_max = 1e-8 * sx * sx),
            u,
            y,
        ),
        (
            Flags::STATE_CLAMPED,
            Mode::Ekf,
            Box::new(move |c| c.x_bounds = (xb.0, xb.0 + 0.3 * (xb.1 - xb.0))),
            u,
            y,
        ),
        (
            Flags::OUTLIER_REJECTED,
            Mode::Ekf,
            Box::new(|c| c.nis_gate = 25.0),
            u,
            &y_spike,
        ),
        (Flags::INITIALISED, Mode::Ekf, Box::new(same), u, y),
    ];
    for (bit, mode, change, u_case, y_case) in &cases {
        let name = Flags(*bit).names().next().unwrap();
        let fired = count(*mode, change, u_case, y_case, *bit);
        assert!(fired > 0, "{name} never fired on its case");
        if *bit != Flags::INITIALISED {
            // The first step's covariance is singular by construction (x_0 = x_{-1}) and
            // is clamped there, so clean data are counted from the second step.
            assert_eq!(
                count_from(1, *mode, same, u, y, *bit),
                0,
                "{name} fired on clean data"
            );
        }
    }
    // Extrapolation: rare on data like the training data; set on every step while the
    // input is far outside its training range (the filter reads `u_{k-1}`, `u_{k-2}`).
    let inside = count(Mode::Ekf, same, u, y, Flags::EXTRAPOLATION);
    assert!(
        inside * 20 < u.len(),
        "extrapolation on {inside} of {} clean steps",
        u.len()
    );
    let mut u_far = u[..130].to_vec();
    for v in &mut u_far[100..120] {
        *v += 5.0 * f.model.stats().0.span();
    }
    let outside = count_from(
        101,
        Mode::Ekf,
        same,
        &u_far,
        &y[..130],
        Flags::EXTRAPOLATION,
    );
    assert!(
        outside >= 20,
        "extrapolation on {outside} of 20 steps outside the data"
    );
    // More training samples in the local window than the regression keeps: capped (the
    // empty windows have their own test below).
    let mut view = f.model.view().unwrap();
    view.blr.max_neighbours = 2;
    let ekf = Ekf::new(view, cfg(Mode::EkfBlr)).unwrap();
    let mut scratch = vec![0.0; ekf.scratch_len()];
    let mut state = None;
    let capped = (0..u.len())
        .filter(|&k| {
            ekf.step(&mut state, &mut scratch, u[k], y[k])
                .flags
                .has(Flags::BLR_CAPPED)
        })
        .count();
    assert!(capped > u.len() / 4, "blr_capped on {capped} steps");
    // A GP failure: a scratch too short for the prediction.
    let ekf = Ekf::new(f.model.view().unwrap(), cfg(Mode::Ekf)).unwrap();
    let mut short = vec![0.0; 1];
    let mut state = None;
    ekf.step(&mut state, &mut short, u[0], y[0]);
    let out = ekf.step(&mut state, &mut short, u[1], y[1]);
    assert!(out.flags.has(Flags::MODEL_INVALID) && out.x.is_finite() && out.x_std.is_finite());
}

#[test]
fn an_empty_blr_window_reproduces_the_plain_ekf_bit_for_bit() {
    // A window of 1e-9 of each input's range holds no training sample around any estimate.
    let f = train(
        SystemKind::Duhem,
        &HbnParams {
            blr_window: 1e-9,
            ..params()
        },
    );
    let view = f.model.view().unwrap();
    let run = |mode| {
        let c = EkfConfig {
            mode,
            ..f.model.untuned_config(Mode::Ekf)
        };
        let ekf = Ekf::new(view, c).unwrap();
        let mut scratch = vec![0.0; ekf.scratch_len()];
        let mut state = None;
        let outs: Vec<StepOutput> = (0..f.test.u.len())
            .map(|k| ekf.step(&mut state, &mut scratch, f.test.u[k], f.test.y[k]))
            .collect();
        outs
    };
    let (ekf, blr) = (run(Mode::Ekf), run(Mode::EkfBlr));
    let empty = Flags::BLR_EMPTY_TRANSITION | Flags::BLR_EMPTY_SENSOR;
    for (k, (a, b)) in ekf.iter().zip(&blr).enumerate() {
        if k > 0 {
            assert_eq!(b.flags.0 & empty, empty, "step {k}: a window was not empty");
        }
        assert_eq!(a.x.to_bits(), b.x.to_bits(), "x at {k}");
        assert_eq!(a.x_std.to_bits(), b.x_std.to_bits(), "x_std at {k}");
        assert_eq!(a.q_x.to_bits(), b.q_x.to_bits(), "q_x at {k}");
        assert_eq!(a.r.to_bits(), b.r.to_bits(), "R at {k}");
        assert_eq!(a.jacobian, b.jacobian, "F at {k}");
        assert_eq!(a.flags.0, b.flags.0 & !empty, "other flags at {k}");
    }
}

#[test]
fn the_shipped_outlier_gate_down_weights_spikes_and_follows_a_persistent_change() {
    let f = fixture();
    let shipped = f.model.ekf_config(Mode::Ekf);
    assert!(
        shipped.nis_gate > 0.0,
        "trained models ship with the gate on"
    );
    let sy = f.model.stats().2.span();
    let spikes = [80, 150, 151, 260];
    let mut y = f.test.y.clone();
    for &k in &spikes {
        y[k] += if k % 2 == 0 { 0.5 } else { -0.5 } * sy;
    }
    let run = |y: &[f64], c: EkfConfig| {
        let ekf = Ekf::new(f.model.view().unwrap(), c).unwrap();
        let mut scratch = vec![0.0; ekf.scratch_len()];
        let mut state = None;
        (0..y.len())
            .map(|k| ekf.step(&mut state, &mut scratch, f.test.u[k], y[k]))
            .collect::<Vec<_>>()
    };
    let clean = run(&f.test.y, shipped);
    let gated = run(&y, shipped);
    let open = run(
        &y,
        EkfConfig {
            nis_gate: 0.0,
            ..shipped
        },
    );
    let err = |o: &[StepOutput]| {
        (o.iter()
            .zip(&f.test.x)
            .map(|(o, x)| (o.x - x).powi(2))
            .sum::<f64>()
            / o.len() as f64)
            .sqrt()
    };
    for &k in &spikes {
        assert!(
            gated[k].flags.has(Flags::OUTLIER_REJECTED),
            "spike at {k} taken"
        );
    }
    let rejected = gated
        .iter()
        .filter(|o| o.flags.has(Flags::OUTLIER_REJECTED))
        .count();
    assert_eq!(rejected, spikes.len(), "only the spikes are rejected");
    assert!(
        err(&gated) < 1.05 * err(&clean) && err(&open) > 1.2 * err(&clean),
        "RMSE clean {:.4}, spikes gated {:.4}, spikes not gated {:.4}",
        err(&clean),
        err(&gated),
        err(&open)
    );
    // A lasting offset is not an outlier: gated measurements are down-weighted, not skipped,
    // so the filter follows it at a bounded pace and the gate stops firing.
    let mut shifted = f.test.y.clone();
    for v in &mut shifted[200..] {
        *v += 0.5 * sy;
    }
    let out = run(&shifted, shipped);
    let run_len = out[200..]
        .iter()
        .take_while(|o| o.flags.has(Flags::OUTLIER_REJECTED))
        .count();
    assert!(
        (1..40).contains(&run_len),
        "{run_len} gated measurements in a row"
    );
    assert!(!out[200 + run_len].flags.has(Flags::OUTLIER_REJECTED));
    // Each gated step moved the predicted measurement toward the shifted one.
    let gap = |k: usize| (shifted[k] - out[k].y_pred).abs();
    assert!(
        gap(200 + run_len) < 0.5 * gap(200),
        "{} vs {}",
        gap(200 + run_len),
        gap(200)
    );
}

#[test]
fn unscented_prediction_tends_to_the_linearised_one_for_a_small_covariance() {
    let f = fixture();
    let sx = f.model.stats().1.span();
    // Small noise too: the noise `w` is a sigma-point dimension of its own.
    let quiet = |mode| EkfConfig {
        q_scale: 1e-12,
        qx_model_floor: 0.0,
        q_floor: 1e-20 * sx * sx,
        ..cfg(mode)
    };
    let (ekf, mut scratch, state) = warm(f, quiet(Mode::Ekf), 150);
    let ukf = Ekf::new(f.model.view().unwrap(), quiet(Mode::Ukf)).unwrap();
    let mut st = state.unwrap();
    // A small, correlated covariance: the sigma points see the GPs as linear.
    let a = Matrix3::new(1.0, 0.0, 0.0, 0.6, 0.8, 0.0, 0.2, -0.3, 0.9) * (1e-4 * sx);
    st.p = a * a.transpose();
    let (e, _) = predict_only(&ekf, &mut scratch, st, f.test.u[150]);
    let (s, out) = predict_only(&ukf, &mut scratch, st, f.test.u[150]);
    assert!(!out.flags.has(Flags::MODEL_INVALID));
    for i in 0..3 {
        assert!(
            (e.z[i] - s.z[i]).abs() < 1e-6 * sx,
            "mean[{i}]: EKF {} UKF {}",
            e.z[i],
            s.z[i]
        );
    }
    let scale = e.p.abs().max();
    for i in 0..3 {
        for j in 0..3 {
            assert!(
                (e.p[(i, j)] - s.p[(i, j)]).abs() < 2e-3 * scale,
                "P[{i}{j}]: EKF {} UKF {}",
                e.p[(i, j)],
                s.p[(i, j)]
            );
        }
    }
    // A large covariance: the sigma points see the curvature, so the two differ, and the
    // unscented mean is the average of the GP through the points, not the GP at the mean.
    let b = a * 300.0;
    st.p = b * b.transpose();
    let (e, _) = predict_only(&ekf, &mut scratch, st, f.test.u[150]);
    let (s, _) = predict_only(&ukf, &mut scratch, st, f.test.u[150]);
    assert!(e.z != s.z && e.p != s.p);
}

#[test]
fn settings_whose_reported_deviation_overflows_are_rejected() {
    // x_std = std_scale * sqrt(P_11) <= std_scale * sqrt(p_max): it must stay finite (the
    // step fuzz target found x_std = inf with std_scale = 1e200 and p_max = 1e308).
    let mut c = cfg(Mode::Ekf);
    c.p_max = 1e308;
    c.std_scale = 1e200;
    assert!(c.validate().is_err());
    c.std_scale = 1e100;
    assert!(c.validate().is_ok());
}

#[test]
fn an_innovation_variance_that_overflows_saturates_and_the_output_stays_finite() {
    // P_ss near p_max plus a huge (finite) R overflowed to an infinite innovation variance
    // (found by the step fuzz target). It saturates at f64::MAX: the measurement carries no
    // information, the update leaves the estimate where the prediction put it.
    let f = fixture();
    for mode in [Mode::Ekf, Mode::Ukf] {
        let mut c = cfg(mode);
        // Every eigenvalue of P at least 5e307, R = 1e300 * 1.5e8 = 1.5e308: their sum overflows.
        c.p_min = 5e307;
        c.p_max = 1e308;
        c.r_scale = 1e300;
        c.r_model_floor = 1.5e8;
        let (ekf, mut scratch, mut state) = warm(f, c, 3);
        for k in 3..40 {
            let out = ekf.step(&mut state, &mut scratch, f.test.u[k], f.test.y[k]);
            for v in [
                out.x,
                out.x_std,
                out.y_pred,
                out.innovation_var,
                out.nis,
                out.q_x,
                out.r,
            ] {
                assert!(v.is_finite(), "{mode:?} step {k}: {out:?}");
            }
        }
        // An invalid measurement reports the same saturated variance.
        let out = ekf.step(&mut state, &mut scratch, f.test.u[40], f64::NAN);
        assert!(out.innovation_var.is_finite(), "{mode:?}: {out:?}");
    }
}

/// A state pinned against its box keeps its uncertainty: the unscented prediction's covariance
/// is that of its sigma points unclamped (clamped, their spread collapsed, so the reported std
/// fell to the floor exactly where the estimate was worst), and its predicted variance stays of
/// the order of the linearised one.
#[test]
fn a_state_pinned_at_its_bound_keeps_its_uncertainty() {
    let f = fixture();
    let (_, mut scratch, state) = warm(f, cfg(Mode::Ekf), 150);
    let st = state.unwrap();
    // A box whose top lies well below the predicted state: the highest state (stepping down
    // from the estimate) from which the GP predicts a rise of at least 10% of the range.
    let sx = f.model.stats().1.span();
    let plain = Ekf::new(f.model.view().unwrap(), cfg(Mode::Ekf)).unwrap();
    let pinned = |top: f64| {
        let mut st = st;
        st.z.x = top;
        st.z.y = top;
        st
    };
    let top = (2..40)
        .map(|k| st.z.x - 0.05 * k as f64 * sx)
        .find(|&top| {
            let (e, _) = predict_only(&plain, &mut scratch, pinned(top), f.test.u[150]);
            e.z.x > top + 0.1 * sx
        })
        .expect("no state from which the GP predicts a rise");
    let boxed = |mode| EkfConfig {
        x_bounds: (top - sx, top),
        ..cfg(mode)
    };
    let st = pinned(top);
    let ekf = Ekf::new(f.model.view().unwrap(), boxed(Mode::Ekf)).unwrap();
    let ukf = Ekf::new(f.model.view().unwrap(), boxed(Mode::Ukf)).unwrap();
    let (e, e_out) = predict_only(&ekf, &mut scratch, st, f.test.u[150]);
    let (s, s_out) = predict_only(&ukf, &mut scratch, st, f.test.u[150]);
    assert!(
        e_out.flags.has(Flags::STATE_CLAMPED) && s_out.flags.has(Flags::STATE_CLAMPED),
        "{e_out:?} {s_out:?} top {top} e {e:?} s {s:?}"
    );
    let p_min = boxed(Mode::Ukf).p_min;
    assert!(
        s.p[(0, 0)] > 0.25 * e.p[(0, 0)] && s.p[(0, 0)] > 1e3 * p_min,
        "UKF x variance {} against the EKF's {} (p_min {p_min})",
        s.p[(0, 0)],
        e.p[(0, 0)]
    );
    // The mean stays in the box.
    assert!(s.z.x <= top, "{} > {top}", s.z.x);
}
