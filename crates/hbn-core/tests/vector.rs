//! The vector filter: its Jacobians against finite differences, its agreement with the scalar
//! filter on a model of one input, one state and one sensor, missing sensors, garbage input,
//! the observability diagnostic, and zero allocations at the largest sizes.

mod vector_common;

use hbn_core::vector::{
    Dims, MAX_AUGMENTED, VectorEkf, VectorInitPrior, VectorState, vector_state_information,
};
use hbn_core::{Ekf, EkfConfig, Flags, HbnView, LocalRegression, Mode, Plays};
use vector_common::{OwnedGp, config, model, model_with_sensor, scalar_config};

/// The EKF's `F` is the derivative of its prediction: a step without measurements (every
/// sensor missing) moves `z` exactly to the prediction, so finite differences of that map
/// over each component of `z` must give `F`'s columns.
#[test]
fn the_ekf_jacobian_is_the_derivative_of_its_prediction() {
    for reads_output in [true, false] {
        let dims = Dims::new(2, 2, 3).unwrap();
        let plays = Plays::new(&[0.1]).unwrap();
        let m = model(dims, plays, reads_output, 1);
        let views = m.views();
        let ekf = VectorEkf::new(views.view(dims, plays), config(dims, Mode::Ekf)).unwrap();
        let mut scratch = vec![0.0; ekf.scratch_len()];
        // A state inside the box after a few steps.
        let mut state = None;
        for k in 0..5 {
            let t = k as f64 * 0.1;
            ekf.step(
                &mut state,
                &mut scratch,
                &[0.4 + t, 0.5 - t],
                &[0.3, 0.5, 0.4],
            );
        }
        let base: VectorState = state.unwrap();
        let n = dims.augmented();
        let missing = [f64::NAN; 3];
        let u = [0.45, 0.4];
        fn one_step(
            ekf: &VectorEkf<'_>,
            base: VectorState,
            z: [f64; MAX_AUGMENTED],
            u: &[f64],
            y: &[f64],
            scratch: &mut [f64],
        ) -> ([f64; MAX_AUGMENTED], hbn_core::vector::VectorStepOutput) {
            let mut st = base;
            st.z = z;
            let mut st = Some(st);
            let out = ekf.step(&mut st, scratch, u, y);
            (st.map(|s| s.z).unwrap_or(z), out)
        }
        let predict = |z: &[f64; MAX_AUGMENTED], scratch: &mut [f64]| {
            one_step(&ekf, base, *z, &u, &missing, scratch)
        };
        let (_, out) = predict(&base.z, &mut scratch);
        assert_eq!(out.flags.0 & Flags::JACOBIAN_CLAMPED, 0);
        assert_eq!(out.flags.0 & Flags::STATE_CLAMPED, 0, "{:?}", out.flags);
        for c in 0..n {
            let h = 1e-6;
            let (mut a, mut b) = (base.z, base.z);
            a[c] += h;
            b[c] -= h;
            let (za, _) = predict(&a, &mut scratch);
            let (zb, _) = predict(&b, &mut scratch);
            for r in 0..n {
                let fd = (za[r] - zb[r]) / (2.0 * h);
                let f = out.jacobian[r][c];
                assert!(
                    (fd - f).abs() < 1e-6 * (1.0 + fd.abs()),
                    "reads_output {reads_output}: F[{r}][{c}] = {f}, finite differences {fd}"
                );
            }
        }
    }
}

/// A model of one input, one state and one sensor run through the vector filter follows the
/// scalar filter: the same GPs, the same settings, the same estimates and deviations, in
/// the EKF and the UKF, for both sensor kinds.
#[test]
fn a_one_by_one_model_follows_the_scalar_filter() {
    for mode in [Mode::Ekf, Mode::Ukf] {
        for reads_output in [true, false] {
            let dims = Dims::new(1, 1, 1).unwrap();
            let m = model(dims, Plays::NONE, reads_output, 2);
            let views = m.views();
            let vekf = VectorEkf::new(views.view(dims, Plays::NONE), config(dims, mode)).unwrap();
            let scalar_view = HbnView {
                transition: views.transitions[0],
                sensor: views.sensors[0],
                transition_local: None,
                sensor_local: None,
                blr: LocalRegression::default(),
                init: None,
                plays: Plays::NONE,
                sensor_memory: Plays::NONE,
            };
            let sekf = Ekf::new(scalar_view, scalar_config(mode)).unwrap();
            let mut scratch = vec![0.0; vekf.scratch_len().max(sekf.scratch_len())];
            let (mut vs, mut ss) = (None, None);
            let mut worst: f64 = 0.0;
            for k in 0..300 {
                let t = k as f64;
                let u = 0.5 + 0.4 * (0.05 * t).sin();
                let y = 0.5 + 0.3 * (0.05 * t - 0.3).sin() + 0.01 * (1.7 * t).cos();
                let vo = vekf.step(&mut vs, &mut scratch, &[u], &[y]);
                let so = sekf.step(&mut ss, &mut scratch, u, y);
                assert_eq!(
                    vo.flags.0 & !Flags::COVARIANCE_CLAMPED,
                    so.flags.0 & !Flags::COVARIANCE_CLAMPED,
                    "step {k}"
                );
                worst = worst
                    .max((vo.x[0] - so.x).abs())
                    .max((vo.x_std[0] - so.x_std).abs())
                    .max((vo.y_pred[0] - so.y_pred).abs());
            }
            assert!(
                worst < 1e-9,
                "{mode:?} reads_output {reads_output}: {worst:e}"
            );
        }
    }
}

/// A missing sensor is left out of the update (flagged); the others still correct the state;
/// garbage never produces a NaN.
#[test]
fn missing_sensors_and_garbage_never_give_nan() {
    let dims = Dims::new(2, 2, 3).unwrap();
    let plays = Plays::new(&[0.1]).unwrap();
    let m = model(dims, plays, true, 3);
    let views = m.views();
    for mode in [Mode::Ekf, Mode::Ukf] {
        let ekf = VectorEkf::new(views.view(dims, plays), config(dims, mode)).unwrap();
        let mut scratch = vec![0.0; ekf.scratch_len()];
        let mut state = None;
        let values = [
            0.3,
            f64::NAN,
            f64::INFINITY,
            -1e300,
            1e300,
            0.7,
            f64::NEG_INFINITY,
            0.5,
        ];
        let mut seen_missing = false;
        for k in 0..400 {
            let pick = |i: usize| values[(k * 7 + i * 3) % values.len()];
            let u = [pick(0), pick(1)];
            let y = if k % 5 == 0 {
                [0.4, f64::NAN, 0.5]
            } else {
                [pick(2), pick(3), pick(4)]
            };
            let out = ekf.step(&mut state, &mut scratch, &u, &y);
            seen_missing |= out.flags.has(Flags::MEASUREMENT_INVALID);
            assert!(
                out.x.iter().all(|v| v.is_finite()),
                "{mode:?} step {k}: {out:?}"
            );
            assert!(out.x_std.iter().all(|v| v.is_finite() && *v >= 0.0));
            assert!(out.nis.is_finite());
            let st = state.unwrap();
            assert!(st.p.iter().flatten().all(|v| v.is_finite()));
        }
        assert!(seen_missing);
        // Too-short slices count as missing, without a panic.
        let out = ekf.step(&mut state, &mut scratch, &[0.5], &[0.5]);
        assert!(out.x.iter().all(|v| v.is_finite()));
    }
}

/// A sensor that sees only `x_0` leaves `x_1` unobservable when the dynamics do not couple
/// them: the diagnostic gives `x_1` no information and `x_0` some.
#[test]
fn a_component_no_sensor_sees_is_reported_unobservable() {
    let dims = Dims::new(1, 2, 1).unwrap();
    let n = dims.augmented();
    let mut f = [[0.0; MAX_AUGMENTED]; MAX_AUGMENTED];
    // x_0' = 0.9 x_0, x_1' = 0.8 x_1 (uncoupled); s' = 0.5 x_0 + 0.2 s.
    f[0][0] = 0.9;
    f[1][1] = 0.8;
    f[2][0] = 1.0;
    f[3][1] = 1.0;
    f[4][0] = 0.5 * 0.9;
    f[4][4] = 0.2;
    let _ = n;
    let jac = vec![f; 20];
    let r = vec![[1e-4, 0.0, 0.0, 0.0]; 20];
    let info = vector_state_information(dims, &jac, &r).unwrap();
    assert!(info[0] > 1.0, "{info:?}");
    assert!(info[1] < 1e-9 * info[0], "{info:?}");
    // Coupling x_1 into x_0 makes it observable.
    let mut coupled = f;
    coupled[0][1] = 0.3;
    coupled[4][1] = 0.5 * 0.3;
    let info = vector_state_information(dims, &vec![coupled; 20], &r).unwrap();
    assert!(info[1] > 1e-3 * info[0], "{info:?}");
}

/// Through the filter: sensors trained on `x_0` only give Jacobians that leave `x_1` without
/// information, and a sensor of both makes it observable.
#[test]
fn the_filter_jacobians_carry_the_unobservable_component() {
    let dims = Dims::new(1, 2, 1).unwrap();
    for (sees_both, observable) in [(false, false), (true, true)] {
        let m = vector_common::model_with_sensor(dims, sees_both, 4);
        let views = m.views();
        let ekf = VectorEkf::new(views.view(dims, Plays::NONE), config(dims, Mode::Ekf)).unwrap();
        let mut scratch = vec![0.0; ekf.scratch_len()];
        let mut state = None;
        let (mut jac, mut r) = (Vec::new(), Vec::new());
        for k in 0..60 {
            let t = k as f64;
            let out = ekf.step(
                &mut state,
                &mut scratch,
                &[0.5 + 0.3 * (0.1 * t).sin()],
                &[0.5 + 0.2 * (0.1 * t).cos()],
            );
            if k > 0 {
                jac.push(out.jacobian);
                r.push(out.r);
            }
        }
        let info =
            vector_state_information(dims, &jac[jac.len() - 10..], &r[r.len() - 10..]).unwrap();
        if observable {
            assert!(info[1] > 1e-3 * info[0], "{info:?}");
        } else {
            assert!(info[1] < 1e-6 * info[0], "{info:?}");
        }
    }
}

/// Settings are checked once: EKF+BLR, a bad box or a wrong GP count are refused.
#[test]
fn bad_settings_and_shapes_are_refused() {
    let dims = Dims::new(2, 2, 3).unwrap();
    let plays = Plays::new(&[0.1]).unwrap();
    let m = model(dims, plays, true, 5);
    let views = m.views();
    let view = views.view(dims, plays);
    assert!(VectorEkf::new(view, config(dims, Mode::EkfBlr)).is_err());
    let mut bad = config(dims, Mode::Ekf);
    bad.x_bounds[1] = (1.0, 0.0);
    assert!(VectorEkf::new(view, bad).is_err());
    let mut short = view;
    short.sensors = &views.sensors[..2];
    assert!(VectorEkf::new(short, config(dims, Mode::Ekf)).is_err());
    assert!(Dims::new(5, 1, 1).is_err());
    assert!(Dims::new(1, 4, 1).is_err());
    assert!(Dims::new(1, 1, 5).is_err());
    let _unused: Option<OwnedGp> = None;
}

/// `EkfConfig` stays what the scalar filter reads.
#[test]
fn scalar_config_is_valid() {
    let c: EkfConfig = scalar_config(Mode::Ekf);
    c.validate().unwrap();
}

/// A filter held at the state box's edge by measurements the box cannot explain is lost, even
/// though each prediction from the edge stays inside the box: after `LOST_AFTER` clamped steps
/// it relocalises from the first-measurement prior. Measurements the box explains never
/// relocalise it.
#[test]
fn a_filter_held_at_the_box_edge_relocalises() {
    let dims = Dims::new(1, 2, 1).unwrap();
    let plays = Plays::new(&[]).unwrap();
    // The sensor reads x_0 + 0.5 x_1; the prior maps y to x_0 = x_1 = y / 1.5.
    let m = model_with_sensor(dims, true, 5);
    let views = m.views();
    let rows: Vec<f64> = (0..=20)
        .flat_map(|i| {
            let y = 0.1 * f64::from(i);
            [y, y / 1.5, y / 1.5]
        })
        .collect();
    let init = VectorInitPrior::new(&rows, dims, &[1.0], 3, &[1e-4, 1e-4]).unwrap();
    let mut view = views.view(dims, plays);
    view.init = Some(init);
    for mode in [Mode::Ekf, Mode::Ukf] {
        let mut cfg = config(dims, mode);
        cfg.x_bounds[0] = (0.0, 1.0);
        cfg.x_bounds[1] = (0.0, 1.0);
        // No outlier gate: every measurement pushes.
        cfg.nis_gate = 1e12;
        let ekf = VectorEkf::new(view, cfg).unwrap();
        let run = |y: f64| {
            let mut scratch = vec![0.0; ekf.scratch_len()];
            let mut state = None;
            let mut clamped = 0;
            let mut relocalised = 0;
            for _ in 0..60 {
                let out = ekf.step(&mut state, &mut scratch, &[0.2], &[y]);
                assert!(out.x.iter().all(|v| v.is_finite()));
                clamped += usize::from(out.flags.has(Flags::STATE_CLAMPED));
                relocalised += usize::from(out.flags.has(Flags::RELOCALISED));
            }
            (clamped, relocalised)
        };
        // 1.8 needs x_0 + 0.5 x_1 = 1.8 > 1.5, the most the box allows.
        let (clamped, relocalised) = run(1.8);
        assert!(clamped >= 10, "{mode:?}: clamped {clamped} times");
        assert!(relocalised >= 1, "{mode:?}: never relocalised");
        // 0.6 is inside: no clamping, no relocalisation.
        assert_eq!(run(0.6), (0, 0), "{mode:?}");
    }
}

/// [`VectorEkf::predict`] is the step's prediction phase: with every sensor missing the step
/// moves the state exactly to it, its sensors' part is the step's predicted measurement, and
/// its cross-covariance is `P F^T` for the EKF. For the UKF at a small covariance the sigma
/// points' cross-covariance agrees with `P F^T` (the cubature rule is exact to second order).
#[test]
fn predict_is_the_steps_prediction() {
    let dims = Dims::new(2, 2, 3).unwrap();
    let plays = Plays::new(&[0.1]).unwrap();
    let m = model(dims, plays, true, 3);
    let views = m.views();
    let n = dims.augmented();
    let times_ft = |p: &[[f64; MAX_AUGMENTED]; MAX_AUGMENTED],
                    f: &[[f64; MAX_AUGMENTED]; MAX_AUGMENTED]| {
        let mut c = [[0.0; MAX_AUGMENTED]; MAX_AUGMENTED];
        for a in 0..n {
            for b in 0..n {
                c[a][b] = (0..n).map(|k| p[a][k] * f[b][k]).sum();
            }
        }
        c
    };
    for mode in [Mode::Ekf, Mode::Ukf] {
        let ekf = VectorEkf::new(views.view(dims, plays), config(dims, mode)).unwrap();
        let mut scratch = vec![0.0; ekf.scratch_len()];
        let mut state = None;
        for k in 0..30 {
            let t = k as f64 * 0.1;
            let u = [0.4 + 0.2 * t.sin(), 0.5 - 0.1 * t];
            let y = if k % 3 == 2 {
                [f64::NAN; 3]
            } else {
                [0.3 + 0.05 * t.cos(), 0.5, 0.4]
            };
            let Some(before) = state else {
                ekf.step(&mut state, &mut scratch, &u, &y);
                continue;
            };
            let pred = ekf.predict(&before, &mut scratch);
            let out = ekf.step(&mut state, &mut scratch, &u, &y);
            for j in 0..dims.sensors {
                assert_eq!(pred.z[2 * dims.states + j], out.y_pred[j], "{mode:?} {k}");
            }
            assert_eq!(pred.flags.0 & !out.flags.0, 0, "{mode:?} {k}");
            if y[0].is_nan() {
                let after = state.unwrap();
                assert_eq!((pred.z, pred.p), (after.z, after.p), "{mode:?} {k}");
            }
            if mode == Mode::Ekf {
                assert_eq!(pred.cross, times_ft(&before.p, &out.jacobian), "{k}");
            }
            // The UKF at a hundred-thousandth of the covariance.
            if mode == Mode::Ukf {
                let mut small = before;
                for row in small.p.iter_mut() {
                    for v in row.iter_mut() {
                        *v *= 1e-5;
                    }
                }
                let pred = ekf.predict(&small, &mut scratch);
                let mut lin_state = Some(small);
                let lin = VectorEkf::new(views.view(dims, plays), config(dims, Mode::Ekf))
                    .unwrap()
                    .step(&mut lin_state, &mut scratch, &u, &y);
                let linear = times_ft(&small.p, &lin.jacobian);
                let scale = linear.iter().flatten().fold(0.0f64, |a, v| a.max(v.abs()));
                for (a, (row, lin_row)) in pred.cross.iter().zip(&linear).enumerate().take(n) {
                    for (b, (c, l)) in row.iter().zip(lin_row).enumerate().take(n) {
                        assert!(
                            (c - l).abs() < 1e-3 * scale,
                            "{k}: cross[{a}][{b}] {c} vs {l}"
                        );
                    }
                }
            }
        }
    }
}
