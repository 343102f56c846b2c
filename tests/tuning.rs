//! Filter-aware training judged on data it never saw: runs of a simulator, each with its own
//! input, trained once without tuning (`validation = 0`) and once with it (the default); a
//! fresh test run scores both. Tuning must make the default estimate's uncertainty honest
//! (mean NEES near 1, the 2-sigma band holding most of the truth) and its predictive density
//! better, without losing accuracy. The noise scales must reach the step: the `std` scale
//! multiplies the reported standard deviation exactly, and `q`/`r` change the filter.

use hbn::core::Mode;
use hbn::model::metrics::{calibration, nrmse};
use hbn::model::{HbnParams, HysteresisModel};
use hbn::pipeline::experiment::{ExperimentConfig, test_trajectory, training_set};
use hbn::pipeline::sequences;
use hbn::sim::{SystemKind, Trajectory};

fn runs(system: SystemKind, cfg: &ExperimentConfig) -> Vec<Trajectory> {
    (0..6u64)
        .flat_map(|r| training_set(system, 1.0, 40 + r, cfg).expect("simulate"))
        .collect()
}

#[test]
fn tuning_makes_the_uncertainty_honest_on_unseen_data() {
    let system = SystemKind::Duhem;
    let cfg = ExperimentConfig {
        train_steps: 500,
        repeats: 1,
        test_steps: 800,
        ..ExperimentConfig::default()
    };
    let train = runs(system, &cfg);
    let test = test_trajectory(system, 1.0, 7, &cfg).expect("test run");
    let fit = |validation: f64| {
        let params = HbnParams {
            max_points: 300,
            n_starts: 1,
            seed: 1,
            validation,
            ..HbnParams::default()
        };
        HysteresisModel::fit(&sequences(&train), &params).expect("fit")
    };
    let untuned = fit(0.0);
    let tuned = fit(HbnParams::default().validation);
    assert!(untuned.summary().validation.is_none());
    assert_eq!(untuned.default_mode(), Mode::Ekf);
    let report = tuned
        .summary()
        .validation
        .as_ref()
        .expect("validation table");
    assert_eq!(report.rows.len(), Mode::ALL.len());
    assert_eq!(report.holdout.from, vec![375; 6]);
    // The search of (q, r) keeps to its cap; the std scales and the table use every held-out
    // sample (3000, under the calibration cap).
    assert_eq!(report.samples, report.holdout.held_out);
    assert!(report.searched <= hbn::model::tuning::MAX_VALIDATION_SAMPLES);
    assert!(report.searched < report.samples);
    for row in &report.rows {
        // The std scale is the root mean NEES of the samples the table scores, so there the
        // tuned mean NEES is 1; and the identity stands in where it scores better, so tuning
        // never makes the table's NLPD worse.
        let tuned = &row.tuned.calibration;
        assert_eq!(tuned.samples, report.samples, "{row:?}");
        assert!((tuned.mean_nees - 1.0).abs() < 1e-9, "{row:?}");
        assert!(tuned.nlpd <= row.untuned.calibration.nlpd + 1e-9, "{row:?}");
    }

    let score = |m: &HysteresisModel| {
        let est = m
            .estimate(&test.u, &test.y, m.default_mode())
            .expect("estimate");
        (
            nrmse(&est.x, &test.x),
            calibration(&est.x, &est.x_std, &test.x),
        )
    };
    let (e0, c0) = score(&untuned);
    let (e1, c1) = score(&tuned);
    println!(
        "untuned: nRMSE {e0:.4} {c0:?}\ntuned ({:?}): nRMSE {e1:.4} {c1:?}",
        tuned.tuning()
    );
    // Honest: NEES near 1, the 2-sigma band holds most of the truth.
    assert!(
        (0.25..=2.5).contains(&c1.mean_nees),
        "tuned mean NEES {}",
        c1.mean_nees
    );
    assert!(
        c1.coverage_2sigma >= 0.85,
        "tuned 2-sigma coverage {}",
        c1.coverage_2sigma
    );
    // Better predictive density than the untuned default, and no worse accuracy (10% slack).
    assert!(c1.nlpd < c0.nlpd - 0.2, "NLPD {} vs {}", c1.nlpd, c0.nlpd);
    assert!(e1 <= 1.1 * e0, "nRMSE {e1} vs {e0}");
}

#[test]
fn noise_scales_reach_the_step() {
    let cfg = ExperimentConfig {
        train_steps: 300,
        repeats: 2,
        test_steps: 300,
        ..ExperimentConfig::default()
    };
    let train = training_set(SystemKind::BoucWen, 1.0, 3, &cfg).expect("simulate");
    let params = HbnParams {
        max_points: 100,
        n_starts: 1,
        validation: 0.0,
        ..HbnParams::default()
    };
    let model = HysteresisModel::fit(&sequences(&train), &params).expect("fit");
    let test = test_trajectory(SystemKind::BoucWen, 1.0, 3, &cfg).expect("test");
    for mode in Mode::ALL {
        let base = model.ekf_config(mode);
        assert_eq!(
            (base.q_scale, base.r_scale, base.std_scale),
            (1.0, 1.0, 1.0)
        );
        let run = |f: &dyn Fn(&mut hbn::core::EkfConfig)| {
            let mut c = base;
            f(&mut c);
            model.estimate_with(&test.u, &test.y, &c).expect("estimate")
        };
        let a = run(&|_| {});
        // The std scale only scales what is reported.
        let b = run(&|c| c.std_scale = 3.0);
        assert_eq!(a.x, b.x);
        for (sa, sb) in a.x_std.iter().zip(&b.x_std) {
            assert!(
                (sb - 3.0 * sa).abs() <= 1e-12 * sb.abs().max(1e-300),
                "{sa} {sb}"
            );
        }
        // R scales the measurement noise (in the plain EKF the sensor GP's noise is the same
        // at every step; with BLR it depends on the state, which R changes).
        let c = run(&|c| c.r_scale = 4.0);
        if mode == Mode::Ekf {
            for (ra, rc) in a.r.iter().zip(&c.r) {
                assert!((rc - 4.0 * ra).abs() <= 1e-9 * rc.abs(), "r {ra} {rc}");
            }
        }
        assert!(a.x.iter().zip(&c.x).any(|(p, q)| p != q), "{mode:?}");
        // Q scales the process noise: the estimate changes.
        let d = run(&|c| c.q_scale = 10.0);
        assert!(a.x.iter().zip(&d.x).any(|(p, q)| p != q), "{mode:?}");
        assert!(d.q_x.iter().zip(&a.q_x).skip(1).any(|(qd, qa)| qd > qa));
    }
}

/// Model selection: among candidates that differ in the inducing setting, the one with the
/// lowest held-out NLPD (and no worse held-out nRMSE) is returned whichever is listed first,
/// it is the model that training the chosen candidate's parameters alone gives, and the table
/// reports every candidate.
#[test]
fn selection_returns_the_candidate_with_the_best_held_out_score() {
    use hbn::model::{Param, ParamValue, Selection};
    let cfg = ExperimentConfig {
        train_steps: 400,
        repeats: 1,
        test_steps: 300,
        ..ExperimentConfig::default()
    };
    let train: Vec<Trajectory> = (0..3u64)
        .flat_map(|r| training_set(SystemKind::Duhem, 1.0, 60 + r, &cfg).expect("simulate"))
        .collect();
    // Without play operators: with them the transition is close enough to linear in its
    // inputs that three inducing points score as well as the exact GP held out (measured:
    // NLPD -2.484 against -2.467), and the case would not separate the candidates.
    let base = HbnParams {
        max_points: 120,
        n_starts: 1,
        seed: 2,
        memory: Vec::new(),
        // One configuration (the default also offers sparse GPs to choose among).
        select: Selection::default(),
        ..HbnParams::default()
    };
    // Three inducing points against the exact GP, each listed first in turn. (Which wins
    // depends on where the sparse search starts: from its own starts the exact GP won held
    // out; from the exact GP's optimum, as when the exact one is the primary, the sparse
    // one did: NLPD -2.65 against -2.51.)
    let tiny = Some(3);
    for (primary, alternative) in [(tiny, None), (None, tiny)] {
        let params = HbnParams {
            n_inducing: primary,
            select: Selection {
                kernels: vec![],
                inducing: vec![alternative],
                lags: vec![],
                sensor_inputs: vec![],
            },
            ..base.clone()
        };
        assert_eq!(params.candidates().len(), 2);
        let model = HysteresisModel::fit(&sequences(&train), &params).expect("fit");
        let report = model.summary().validation.as_ref().expect("validation");
        let rows = &report.candidates;
        assert_eq!(rows.len(), 2);
        assert_eq!(rows[0].candidate.n_inducing, primary);
        let nlpd = |i: usize| rows[i].scored.expect("scored").1.calibration.nlpd;
        let nrmse = |i: usize| rows[i].scored.expect("scored").1.nrmse;
        // The rule: the lower NLPD, if at least as accurate held out as the first.
        let best = if nlpd(1) < nlpd(0) && nrmse(1) <= nrmse(0) {
            1
        } else {
            0
        };
        assert_eq!(rows.iter().filter(|r| r.chosen).count(), 1);
        assert!(rows[best].chosen, "{rows:?}");
        // The chosen candidate's own model: it records its configuration with no
        // alternatives left. The primary configuration's parameters train the same model
        // alone, with the same held-out table. (A sparse alternative's search started from the
        // exact primary's optimum, which model selection has at hand; trained alone it starts
        // from its own starts, and its optimum may differ.)
        assert_eq!(model.params().n_inducing, rows[best].candidate.n_inducing);
        assert!(model.params().select.is_empty());
        if best == 0 || rows[best].candidate.n_inducing.is_none() {
            let alone =
                HysteresisModel::fit(&sequences(&train), model.params()).expect("chosen alone");
            let alone_report = alone.summary().validation.as_ref().expect("validation");
            assert_eq!(report.rows, alone_report.rows);
            assert_eq!(model.tuning(), alone.tuning());
            assert_eq!(model.transition().theta(), alone.transition().theta());
        }
    }
    // Choosing needs held-out data: without it the primary configuration is trained, and the
    // report says the alternatives were not compared.
    let mut p = HbnParams {
        validation: 0.0,
        ..base
    };
    p.set(
        Param::Inducing,
        ParamValue::List(vec![ParamValue::Text("exact".into()), ParamValue::Int(32)]),
    )
    .expect("a list");
    assert_eq!(p.select.inducing, vec![Some(32)]);
    let model = HysteresisModel::fit(&sequences(&train), &p).expect("validation 0");
    assert_eq!(model.params().n_inducing, None);
    assert!(model.summary().validation.is_none());
    assert!(
        model
            .summary()
            .warnings
            .iter()
            .any(|w| w.contains("no model selection: validation is 0")),
        "{:?}",
        model.summary().warnings
    );
}
