//! The owned streaming filter equals batch estimation bit for bit, initialises from the first
//! measurement like it, and a trained model file depends only on data and parameters.

use hbn_core::{Flags, Mode};
use hbn_model::{Filter, HbnParams, HysteresisModel, Sequence};
use hbn_sim::{SimConfig, SystemKind, simulate_random};
use std::sync::Arc;

fn model() -> (HysteresisModel, hbn_sim::Trajectory) {
    let cfg = SimConfig {
        noise_gain: 1.0,
        ..SimConfig::new(SystemKind::Duhem)
    };
    let train = simulate_random(&cfg, 400).unwrap();
    let params = HbnParams {
        max_points: 100,
        n_starts: 1,
        max_iters: 40,
        ..HbnParams::default()
    };
    let m = HysteresisModel::fit(&[Sequence::new(&train.u, &train.x, &train.y)], &params).unwrap();
    let mut test = simulate_random(&SimConfig { seed: 9, ..cfg }, 500).unwrap();
    // Drop-outs: the guard paths must agree too.
    test.u[40] = f64::NAN;
    test.y[41] = f64::INFINITY;
    test.y[300] = f64::NAN;
    (m, test)
}

fn bits(v: &[f64]) -> Vec<u64> {
    v.iter().map(|x| x.to_bits()).collect()
}

#[test]
fn streaming_equals_batch_bit_for_bit() {
    let (m, test) = model();
    let m = Arc::new(m);
    for mode in Mode::ALL {
        let batch = m.estimate(&test.u, &test.y, mode).unwrap();
        let mut filter = Filter::new(m.clone(), mode).unwrap();
        assert_eq!(filter.mode(), mode);
        for pass in 0..2 {
            let mut stream = hbn_model::Estimate::with_capacity(test.u.len());
            for (&u, &y) in test.u.iter().zip(&test.y) {
                stream.push(&filter.step(u, y));
            }
            for (name, a, b) in [
                ("x", &stream.x, &batch.x),
                ("x_std", &stream.x_std, &batch.x_std),
                ("y_pred", &stream.y_pred, &batch.y_pred),
                ("innovation", &stream.innovation, &batch.innovation),
                ("nis", &stream.nis, &batch.nis),
                ("q_x", &stream.q_x, &batch.q_x),
                ("r", &stream.r, &batch.r),
                ("obs_min", &stream.obs_min, &batch.obs_min),
                ("obs_x", &stream.obs_x, &batch.obs_x),
                ("obs_max", &stream.obs_max, &batch.obs_max),
            ] {
                assert_eq!(bits(a), bits(b), "{mode} pass {pass}: {name}");
            }
            assert_eq!(stream.flags, batch.flags, "{mode} pass {pass}");
            assert!(Flags(stream.flags[40]).has(Flags::INPUT_INVALID));
            // After a reset the filter starts over exactly as a new one.
            filter.reset();
            assert!(filter.state().is_none());
        }
        // Filter::run is the same batch.
        let run = filter.run(&test.u, &test.y).unwrap();
        assert_eq!(bits(&run.x), bits(&batch.x));
        assert_eq!(bits(&run.obs_min), bits(&batch.obs_min));
    }
}

#[test]
fn the_first_step_takes_the_prior_from_the_first_measurement() {
    let (m, test) = model();
    let (mean, var) = m.initial_state(test.y[0]).unwrap();
    let mut filter = Filter::new(m.clone(), Mode::Ekf).unwrap();
    let out = filter.step(test.u[0], test.y[0]);
    assert!(out.flags.has(Flags::INITIALISED));
    assert_eq!(out.x, mean);
    // The covariance bound may nudge the (rank-one) initial covariance by rounding.
    // The reported std carries the learned std scale (filter-aware training).
    let sd = m.ekf_config(Mode::Ekf).std_scale * var.sqrt();
    assert!((out.x_std - sd).abs() < 1e-9 * sd, "{} {}", out.x_std, sd);
    // Not the training mean: the prior really comes from y_0.
    assert_ne!(mean, m.ekf_config(Mode::Ekf).x0_mean);
    // A non-finite first measurement falls back to the training prior.
    let mut f2 = Filter::new(m.clone(), Mode::Ekf).unwrap();
    let out = f2.step(test.u[0], f64::NAN);
    assert_eq!(out.x, m.ekf_config(Mode::Ekf).x0_mean);
    assert_eq!(
        m.estimate(&[test.u[0]], &[f64::NAN], Mode::Ekf).unwrap().x[0],
        out.x
    );
}

#[test]
fn model_files_depend_only_on_data_and_parameters() {
    let (a, _) = model();
    let (b, _) = model();
    assert!(a.summary().seconds > 0.0);
    assert_eq!(a.to_json().unwrap(), b.to_json().unwrap());
    let dir = tempfile::tempdir().unwrap();
    let f = dir.path().join("m.hbn");
    a.save(&f).unwrap();
    let back = HysteresisModel::load(&f).unwrap();
    assert_eq!(back.to_json().unwrap(), a.to_json().unwrap());
    // Every start of both GPs is accounted for, with why it stopped.
    assert_eq!(back.summary().starts.len(), 2);
}

#[test]
fn mismatched_lengths_are_a_data_error() {
    let (m, test) = model();
    let e = m.estimate(&test.u, &test.y[1..], Mode::Ekf).unwrap_err();
    assert!(matches!(
        e,
        hbn_model::ModelError::Data(hbn_model::DataError::InputOutputLength { .. })
    ));
}
