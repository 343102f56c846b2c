//! End to end through the library pipeline: simulate -> MCAP log -> read and resample ->
//! train -> estimate -> accuracy bound.

mod common;

use hbn::core::Mode;
use hbn::io::Encoding;
use hbn::model::metrics::nrmse;
use hbn::model::{HbnParams, HysteresisModel};
use hbn::pipeline::{
    LogOptions, Method, SignalChoice, SimLog, TrainSignals, evaluate_log, simulate_log,
    train_from_logs,
};
use hbn::sim::{SimConfig, SystemKind};

/// At noise gain 1 the EKF beats open-loop GP simulation and stays below a stated bound, on
/// systems of different families; EKF+BLR stays close to it.
#[test]
fn simulate_log_train_estimate_beats_open_loop() {
    let dir = tempfile::tempdir().unwrap();
    for (i, system) in [
        SystemKind::MaxwellSlip,
        SystemKind::Preisach,
        SystemKind::SoftActuator,
    ]
    .into_iter()
    .enumerate()
    {
        let seed = 10 + i as u64;
        let log = |name: String, sim_seed, input_seed, steps, encoding| {
            let path = dir.path().join(name);
            let spec = SimLog {
                config: SimConfig {
                    system,
                    noise_gain: 1.0,
                    rate_hz: 100.0,
                    seed: sim_seed,
                },
                steps,
                input_seed,
                max_increment: 0.02,
                encoding,
            };
            simulate_log(&spec, &path).unwrap();
            path
        };
        // One training input, three noisy runs, alternating JSON and ROS 2 encodings.
        let train: Vec<_> = (0..3u64)
            .map(|r| {
                let enc = if r % 2 == 0 {
                    Encoding::Json
                } else {
                    Encoding::Ros2
                };
                log(
                    format!("{system}-train{r}.mcap"),
                    seed * 10 + r,
                    seed,
                    600,
                    enc,
                )
            })
            .collect();
        let params = HbnParams {
            max_points: 300,
            n_starts: 1,
            max_iters: 80,
            seed,
            ..HbnParams::default()
        };
        let model = train_from_logs(
            &train,
            &TrainSignals::default(),
            LogOptions::default(),
            params,
            &mut |_| {},
        )
        .unwrap()
        .model;
        assert_eq!(model.rate_hz(), 100.0);

        // The experiment protocol's test run for this seed, as a ROS 2 log.
        let test = log(
            format!("{system}-test.mcap"),
            seed.wrapping_add(0xBEEF),
            seed.wrapping_add(0x7E57),
            1500,
            Encoding::Ros2,
        );
        let ev = evaluate_log(
            &model,
            &test,
            &SignalChoice::default(),
            &Mode::ALL,
            LogOptions::default(),
            &mut |_| {},
        )
        .unwrap();
        let score = |m| ev.scores.iter().find(|s| s.method == m).unwrap().nrmse;
        let (ekf, blr, open) = (
            score(Method::Filter(Mode::Ekf)),
            score(Method::Filter(Mode::EkfBlr)),
            score(Method::OpenLoop),
        );
        let chosen = model.default_mode();
        let default = score(Method::Filter(chosen));
        eprintln!(
            "{system}: ekf {ekf:.4} ekf+blr {blr:.4} open loop {open:.4}; default {chosen} \
             {default:.4}, {}",
            model.params().candidate()
        );
        assert!(ekf < open, "{system}: EKF {ekf} not below open loop {open}");
        assert!(ekf < 0.08, "{system}: EKF nRMSE {ekf} above the bound 0.08");
        assert!(
            blr < 0.08,
            "{system}: EKF+BLR nRMSE {blr} above the bound 0.08"
        );
        // The mode the held-out data chose is within 15% of the better of EKF and EKF+BLR
        // on this unseen log. (EKF+BLR alone can trail the EKF by more than 10% with sparse
        // GPs, which the default may choose; here Preisach chooses EKF+BLR at about 1.1x the
        // EKF.)
        assert!(
            default <= 1.15 * ekf.min(blr),
            "{system}: default mode {chosen} {default} vs EKF {ekf}, EKF+BLR {blr}"
        );
    }
}

/// At noise gain 10 both filters stay bounded and EKF+BLR is within a few percent of the EKF.
#[test]
fn high_noise_stays_bounded() {
    let (model, _) = common::train_model(SystemKind::Duhem, 10.0, 300, 21);
    let test = common::test_run(SystemKind::Duhem, 10.0, 1500, 21);
    let ekf = model.estimate(&test.u, &test.y, Mode::Ekf).unwrap();
    let blr = model.estimate(&test.u, &test.y, Mode::EkfBlr).unwrap();
    let open = model.simulate_open_loop(&test.u).unwrap();
    let (e, b, o) = (
        nrmse(&ekf.x, &test.x),
        nrmse(&blr.x, &test.x),
        nrmse(&open, &test.x),
    );
    eprintln!("duhem gain 10: ekf {e:.4} ekf+blr {b:.4} open loop {o:.4}");
    assert!(
        ekf.x
            .iter()
            .chain(&blr.x)
            .chain(&ekf.x_std)
            .chain(&blr.x_std)
            .all(|v| v.is_finite())
    );
    assert!(e < o && b < o);
    assert!(b <= 1.05 * e, "EKF+BLR {b} vs EKF {e}");
    assert!(e < 0.12 && b < 0.12);
}

/// A trained model saved and loaded estimates bit-identically.
#[test]
fn saved_model_estimates_identically() {
    let (model, _) = common::train_model(SystemKind::Duhem, 1.0, 100, 4);
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("m.hbn");
    model.save(&path).unwrap();
    let back = HysteresisModel::load(&path).unwrap();
    let test = common::test_run(SystemKind::Duhem, 1.0, 300, 4);
    for mode in [Mode::Ekf, Mode::EkfBlr] {
        let a = model.estimate(&test.u, &test.y, mode).unwrap();
        let b = back.estimate(&test.u, &test.y, mode).unwrap();
        let bits = |v: &[f64]| v.iter().map(|x| x.to_bits()).collect::<Vec<u64>>();
        for (p, q) in [
            (&a.x, &b.x),
            (&a.x_std, &b.x_std),
            (&a.nis, &b.nis),
            (&a.obs_min, &b.obs_min),
        ] {
            assert_eq!(bits(p), bits(q), "{mode:?}");
        }
        assert_eq!(a.flags, b.flags);
    }
}

/// Play operators ride along in the model file, and a model file without them (no `memory`
/// parameter, no `play_radii`) loads as a model without them: it estimates bit
/// for bit as the same model trained with `memory` empty.
#[test]
fn model_files_with_and_without_play_operators_load() {
    let (model, runs) = common::train_model(SystemKind::Preisach, 1.0, 100, 5);
    let plays = model.plays().unwrap();
    assert_eq!(plays.len(), hbn::model::DEFAULT_MEMORY.len());
    let u_span = model.stats().0.span();
    for (r, f) in plays.radii().iter().zip(hbn::model::DEFAULT_MEMORY) {
        assert!(
            (r - f * u_span).abs() <= 1e-12 * u_span,
            "{r} vs {f} x {u_span}"
        );
    }
    let back = HysteresisModel::from_json(&model.to_json().unwrap(), "mem").unwrap();
    assert_eq!(back.plays().unwrap(), plays);

    // Without memory, and without the fields.
    let params = HbnParams {
        memory: Vec::new(),
        max_points: 100,
        n_starts: 1,
        max_iters: 60,
        seed: 5,
        ..HbnParams::default()
    };
    let plain = HysteresisModel::fit(&hbn::pipeline::sequences(&runs), &params).unwrap();
    assert!(plain.plays().unwrap().is_empty());
    let mut v: serde_json::Value = serde_json::from_str(&plain.to_json().unwrap()).unwrap();
    let m = v["model"].as_object_mut().unwrap();
    assert!(m.remove("play_radii").is_some());
    assert!(
        m["params"]
            .as_object_mut()
            .unwrap()
            .remove("memory")
            .is_some()
    );
    let old = HysteresisModel::from_json(&v.to_string(), "old").unwrap();
    assert!(old.params().memory.is_empty() && old.plays().unwrap().is_empty());
    let test = common::test_run(SystemKind::Preisach, 1.0, 300, 5);
    let bits = |v: &[f64]| v.iter().map(|x| x.to_bits()).collect::<Vec<u64>>();
    for mode in Mode::ALL {
        let a = plain.estimate(&test.u, &test.y, mode).unwrap();
        let b = old.estimate(&test.u, &test.y, mode).unwrap();
        assert_eq!(bits(&a.x), bits(&b.x), "{mode:?}");
    }
    // The plays change the transition's inputs, so the estimates differ.
    let with = model.estimate(&test.u, &test.y, Mode::Ekf).unwrap();
    let without = plain.estimate(&test.u, &test.y, Mode::Ekf).unwrap();
    assert_ne!(bits(&with.x), bits(&without.x));
}

/// Lags ride along in the model file at the model's rate, reach the transition GP as inputs
/// after the plays, and change the estimate; a file without the `lags` parameter loads as a
/// model without them, estimating bit for bit as one trained without them. (What they gain on
/// a system with creep is the accuracy report's, not this test's: with this test's small
/// training budget the soft actuator's estimate is not better with them.)
#[test]
fn lags_ride_along_and_reach_the_transition_gp() {
    let system = SystemKind::SoftActuator;
    let (with, _) = common::train_model_with(system, 1.0, 150, 1, |p| p.lags = vec![1.0]);
    let (plain, _) = common::train_model_with(system, 1.0, 150, 1, |_| {});
    let plays = with.plays().unwrap();
    let a = hbn::core::lag_coefficient(1.0, with.rate_hz()).unwrap();
    assert_eq!(plays.lags(), &[a]);
    assert_eq!(plays.radii().len(), hbn::model::DEFAULT_MEMORY.len());
    assert_eq!(plays.len(), hbn::model::DEFAULT_MEMORY.len() + 1);
    assert_eq!(
        with.transition().kernel().dim,
        plain.transition().kernel().dim + 1
    );
    let back = HysteresisModel::from_json(&with.to_json().unwrap(), "lags").unwrap();
    assert_eq!(back.plays().unwrap(), plays);

    // Without lags, and without the field.
    let mut v: serde_json::Value = serde_json::from_str(&plain.to_json().unwrap()).unwrap();
    let params = v["model"]["params"].as_object_mut().unwrap();
    assert!(params.remove("lags").is_some());
    let old = HysteresisModel::from_json(&v.to_string(), "old").unwrap();
    assert!(old.params().lags.is_empty() && old.plays().unwrap().lags().is_empty());

    let test = common::test_run(system, 1.0, 400, 1);
    let bits = |v: &[f64]| v.iter().map(|x| x.to_bits()).collect::<Vec<u64>>();
    let a_old = old.estimate(&test.u, &test.y, Mode::Ekf).unwrap();
    let a_plain = plain.estimate(&test.u, &test.y, Mode::Ekf).unwrap();
    assert_eq!(bits(&a_old.x), bits(&a_plain.x));
    let a_with = with.estimate(&test.u, &test.y, Mode::Ekf).unwrap();
    assert_ne!(bits(&a_with.x), bits(&a_plain.x));
    assert!(a_with.x.iter().all(|x| x.is_finite()));
}
