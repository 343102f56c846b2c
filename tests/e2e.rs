//! End to end: simulate -> MCAP log -> read and resample -> train -> estimate -> accuracy bound.

mod common;

use hbn::core::Mode;
use hbn::io::{
    Encoding, ReadOptions, ResampleOptions, ScalarTopic, SignalPath, read_signals, resample,
    write_scalar_log,
};
use hbn::model::metrics::nrmse;
use hbn::model::{HbnModel, HbnParams, Sequence};
use hbn::sim::{InputKind, SimConfig, SystemKind, Trajectory, generate_input, simulate};
use std::path::Path;

fn write_log(path: &Path, t: &Trajectory, encoding: Encoding) {
    let t_ns: Vec<u64> = (0..t.u.len())
        .map(|k| 1_000_000_000 + k as u64 * 10_000_000)
        .collect();
    let topics = [
        ScalarTopic {
            topic: "/input",
            values: &t.u,
        },
        ScalarTopic {
            topic: "/state",
            values: &t.x,
        },
        ScalarTopic {
            topic: "/sensor",
            values: &t.y,
        },
    ];
    write_scalar_log(path, &t_ns, &topics, encoding).unwrap();
}

fn read_log(path: &Path) -> (Vec<f64>, Vec<f64>, Vec<f64>) {
    let paths: Vec<SignalPath> = ["/input.data", "/state.data", "/sensor.data"]
        .iter()
        .map(|p| p.parse().unwrap())
        .collect();
    let raw = read_signals(path, &paths, &ReadOptions::default()).unwrap();
    let a = resample(&raw, &ResampleOptions::new(100.0)).unwrap();
    (
        a.columns[0].clone(),
        a.columns[1].clone(),
        a.columns[2].clone(),
    )
}

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
        let u_train = generate_input(InputKind::RandomRamps, 600, 0.02, seed).unwrap();
        let mut seqs_owned = Vec::new();
        for r in 0..3 {
            let t = simulate(
                &SimConfig {
                    system,
                    noise_gain: 1.0,
                    rate_hz: 100.0,
                    seed: seed * 10 + r,
                },
                &u_train,
            )
            .unwrap();
            let path = dir.path().join(format!("{system}-train{r}.mcap"));
            write_log(
                &path,
                &t,
                if r % 2 == 0 {
                    Encoding::Json
                } else {
                    Encoding::Ros2
                },
            );
            seqs_owned.push(read_log(&path));
        }
        let seqs: Vec<Sequence<'_>> = seqs_owned
            .iter()
            .map(|(u, x, y)| Sequence { u, x, y })
            .collect();
        let params = HbnParams {
            max_points: 300,
            n_starts: 1,
            max_iters: 80,
            seed,
            ..HbnParams::default()
        };
        let model = HbnModel::fit(&seqs, &params).unwrap();

        let test = common::test_run(system, 1.0, 1500, seed);
        let path = dir.path().join(format!("{system}-test.mcap"));
        write_log(&path, &test, Encoding::Ros2);
        let (u, x, y) = read_log(&path);
        let ekf = nrmse(&model.estimate(&u, &y, Mode::Ekf).unwrap().x, &x);
        let blr = nrmse(&model.estimate(&u, &y, Mode::EkfBlr).unwrap().x, &x);
        let open = nrmse(&model.simulate_open_loop(&u).unwrap(), &x);
        eprintln!("{system}: ekf {ekf:.4} ekf+blr {blr:.4} open loop {open:.4}");
        assert!(ekf < open, "{system}: EKF {ekf} not below open loop {open}");
        assert!(ekf < 0.08, "{system}: EKF nRMSE {ekf} above the bound 0.08");
        assert!(
            blr < 0.08 && blr <= 1.1 * ekf,
            "{system}: EKF+BLR {blr} vs EKF {ekf}"
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
    let back = HbnModel::load(&path).unwrap();
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
