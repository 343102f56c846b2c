//! The explorer (thesis Sec. 3.4): bounds and increment bound kept under every phase, bounds
//! edge cases and a robot that does not follow, determinism, that seeking uncertainty reaches
//! where random steps do not, planning without a robot, resuming from a first batch, errors.

use hbn_model::explore::{ExploreError, ExploreParams, Explorer, Phase, Strategy};
use hbn_model::{HbnParams, HysteresisModel, Sequence, Signal};
use hbn_sim::{SimConfig, Simulator, SystemKind};

/// Small training parameters so the tests run in seconds.
fn quick(mut p: ExploreParams) -> ExploreParams {
    p.model = HbnParams {
        max_points: 80,
        n_starts: 1,
        max_iters: 40,
        validation: 0.0,
        ..HbnParams::default()
    };
    p
}

/// Drives a simulator with the explorer for `steps` samples; returns the inputs applied.
fn drive(explorer: &mut Explorer, system: SystemKind, seed: u64, steps: usize) -> Vec<f64> {
    let cfg = SimConfig {
        noise_gain: 1.0,
        seed,
        ..SimConfig::new(system)
    };
    let mut robot = Simulator::new(&cfg).unwrap();
    let mut applied = Vec::with_capacity(steps);
    for _ in 0..steps {
        let u = explorer.propose();
        let (x, y) = robot.step(u).unwrap();
        explorer.observe(u, x, y).unwrap();
        applied.push(u);
    }
    applied
}

fn assert_within(u: &[f64], lo: f64, hi: f64, eta: f64) {
    for (k, &v) in u.iter().enumerate() {
        assert!((lo..=hi).contains(&v), "u[{k}] = {v} outside [{lo}, {hi}]");
        if k > 0 {
            let step = (v - u[k - 1]).abs();
            assert!(step <= eta, "|u[{k}] - u[{}]| = {step} > {eta}", k - 1);
        }
    }
}

#[test]
fn proposals_keep_the_bounds_and_the_increment_bound_in_every_phase() {
    // A narrow range with a large step, so that the bounds are hit all the time, and a wide
    // one; pure seeking (alpha 1) pushes hardest against the bounds.
    for (lo, hi, eta, alpha) in [
        (0.3, 0.45, 0.05, 1.0),
        (0.0, 1.0, 0.02, 0.9),
        (0.0, 1.0, 0.3, 1.0),
    ] {
        let mut p = quick(ExploreParams::new(lo, hi, eta));
        p.random_samples = 40;
        p.alpha_start = alpha;
        p.alpha_end = alpha;
        p.optimize_every = 100;
        let mut explorer = Explorer::new(p).unwrap();
        let u = drive(&mut explorer, SystemKind::BoucWen, 1, 400);
        assert!(matches!(explorer.phase(), Phase::Seeking { .. }));
        assert_within(&u, lo, hi, eta);
        assert_eq!(u[0], lo, "the first input is u_start, by default u_min");
        assert!(explorer.warnings().is_empty(), "{:?}", explorer.warnings());
    }
}

#[test]
fn a_robot_that_did_not_follow_is_brought_back_inside_the_bounds() {
    let mut explorer = Explorer::new(quick(ExploreParams::new(0.0, 1.0, 0.02))).unwrap();
    explorer.observe(1.3, 0.5, 0.5).unwrap();
    assert_eq!(explorer.propose(), 1.0);
    explorer.observe(-0.4, 0.5, 0.5).unwrap();
    assert_eq!(explorer.propose(), 0.0);
    explorer.observe(0.999, 0.5, 0.5).unwrap();
    let u = explorer.propose();
    assert!((0.979..=1.0).contains(&u), "{u}");
}

#[test]
fn equal_seeds_and_observations_give_equal_proposals() {
    let run = |seed| {
        let mut p = quick(ExploreParams::new(0.0, 1.0, 0.02));
        p.random_samples = 30;
        p.seed = seed;
        let mut e = Explorer::new(p).unwrap();
        drive(&mut e, SystemKind::Duhem, 2, 150)
    };
    let a = run(5);
    assert_eq!(a, run(5));
    assert_ne!(a, run(6));
}

/// Range of the inputs after the random phase.
fn span_after(u: &[f64], from: usize) -> f64 {
    let tail = &u[from..];
    let max = tail.iter().copied().fold(f64::MIN, f64::max);
    let min = tail.iter().copied().fold(f64::MAX, f64::min);
    max - min
}

#[test]
fn seeking_uncertainty_covers_the_range_that_random_steps_leave_out() {
    // The thesis' per-sample rule. Both explorers share the random phase (same seed) near
    // u = 0. Then one keeps taking random steps (alpha 0: the thesis' step 1 forever), the
    // other seeks the transition GP's variance (alpha 1). A bounded random walk of 400 steps
    // of at most 0.02 spreads over ~0.2; seeking heads for the inputs the GP has not seen and
    // sweeps the whole range.
    let mut spans = Vec::new();
    for system in [SystemKind::BoucWen, SystemKind::Preisach] {
        for alpha in [0.0, 1.0] {
            let mut p = quick(ExploreParams::new(0.0, 1.0, 0.02));
            p.strategy = Strategy::Steps;
            p.horizon = 10;
            p.random_samples = 60;
            p.alpha_start = alpha;
            p.alpha_end = alpha;
            p.seed = 3;
            let mut e = Explorer::new(p).unwrap();
            let u = drive(&mut e, system, 3, 460);
            spans.push((system, alpha, span_after(&u, 60)));
        }
    }
    for pair in spans.chunks(2) {
        let (system, _, random) = pair[0];
        let (_, _, seeking) = pair[1];
        assert!(
            seeking > 0.8 && seeking > 2.0 * random,
            "{system}: seeking spans {seeking:.3}, random steps {random:.3}"
        );
    }
}

#[test]
fn ramps_move_at_most_max_step_and_arrive_at_their_targets() {
    // Random ramps only (alpha 0): piecewise-linear inputs whose slopes vary in
    // [0.1, 1] max_step, so the data hold slow and fast inputs.
    let mut p = quick(ExploreParams::new(0.0, 1.0, 0.02));
    p.alpha_start = 0.0;
    p.alpha_end = 0.0;
    let mut e = Explorer::new(p).unwrap();
    let u = drive(&mut e, SystemKind::Duhem, 1, 600);
    assert_within(&u, 0.0, 1.0, 0.02);
    let steps: Vec<f64> = u.windows(2).map(|w| (w[1] - w[0]).abs()).collect();
    let slow = steps.iter().filter(|&&s| s > 0.0 && s < 0.008).count();
    let fast = steps.iter().filter(|&&s| s > 0.012).count();
    assert!(slow > 50 && fast > 50, "slow {slow}, fast {fast}");
}

#[test]
fn the_alpha_schedule_ramps_from_start_to_end() {
    let mut p = quick(ExploreParams::new(0.0, 1.0, 0.02));
    p.random_samples = 20;
    p.alpha_start = 0.2;
    p.alpha_end = 0.8;
    p.alpha_ramp = 100;
    let mut e = Explorer::new(p).unwrap();
    drive(&mut e, SystemKind::Duhem, 1, 19);
    assert_eq!(e.phase(), Phase::Random);
    assert_eq!(e.alpha(), 0.0);
    drive(&mut e, SystemKind::Duhem, 1, 1);
    assert_eq!(e.phase(), Phase::Seeking { alpha: 0.2 });
    drive(&mut e, SystemKind::Duhem, 1, 50);
    assert!((e.alpha() - 0.5).abs() < 1e-12, "{}", e.alpha());
    drive(&mut e, SystemKind::Duhem, 1, 200);
    assert_eq!(e.alpha(), 0.8);
}

#[test]
fn the_model_is_trained_on_every_run_observed() {
    let mut p = quick(ExploreParams::new(0.0, 1.0, 0.02));
    p.random_samples = 30;
    let mut e = Explorer::new(p).unwrap();
    drive(&mut e, SystemKind::Duhem, 1, 120);
    e.start_run();
    assert_eq!(e.propose(), 0.0, "a new run starts at u_start");
    drive(&mut e, SystemKind::Duhem, 2, 80);
    assert_eq!(e.n_observed(), 200);
    assert_eq!(e.runs().count(), 2);
    let model = e.model().unwrap();
    // Two rows fewer per run: the transition reads two past samples.
    assert_eq!(model.summary().rows, 118 + 78);
    assert_eq!(model.summary().trajectories, 2);
}

#[test]
fn a_plan_keeps_the_bounds_spreads_out_and_leaves_the_explorer_unchanged() {
    let mut p = quick(ExploreParams::new(0.0, 1.0, 0.02));
    p.random_samples = 60;
    p.alpha_start = 1.0;
    p.alpha_end = 1.0;
    let mut e = Explorer::new(p).unwrap();
    let first = drive(&mut e, SystemKind::BoucWen, 1, 60);
    let before = e.n_observed();
    let (u_plan, x_plan) = e.plan(400);
    assert_eq!(e.n_observed(), before);
    assert_eq!((u_plan.len(), x_plan.len()), (400, 400));
    let mut all = first.clone();
    all.extend(&u_plan);
    assert_within(&all, 0.0, 1.0, 0.02);
    assert!(x_plan.iter().all(|x| x.is_finite()));
    assert!(span_after(&u_plan, 0) > 0.8, "{}", span_after(&u_plan, 0));
    // Deterministic, and the explorer's own next proposal is the plan's first.
    assert_eq!(e.plan(400).0, u_plan);
    assert_eq!(e.propose(), u_plan[0]);
}

#[test]
fn resuming_from_a_first_batch_continues_its_last_run() {
    let cfg = SimConfig {
        noise_gain: 1.0,
        ..SimConfig::new(SystemKind::Duhem)
    };
    let batch = hbn_sim::simulate_random(&cfg, 300).unwrap();
    let params = HbnParams {
        max_points: 80,
        n_starts: 1,
        validation: 0.0,
        ..HbnParams::default()
    };
    let seqs = [Sequence::new(&batch.u, &batch.x, &batch.y)];
    let model = HysteresisModel::fit(&seqs, &params).unwrap();
    let e = Explorer::resume(ExploreParams::new(0.0, 1.0, 0.02), &model, &seqs).unwrap();
    assert!(matches!(e.phase(), Phase::Seeking { .. }));
    // The model's own parameters: the configuration it was trained as (with `validation = 0`
    // the primary one, with the kernels its GPs chose by evidence; model files keep no
    // alternatives).
    let mut trained_as = params.with_candidate(&params.candidate());
    trained_as.transition_kernel = model.params().transition_kernel;
    trained_as.sensor_kernel = model.params().sensor_kernel;
    assert_eq!(e.params().model, trained_as);
    let (u_plan, _) = e.plan(200);
    let mut all = vec![*batch.u.last().unwrap()];
    all.extend(&u_plan);
    assert_within(&all, 0.0, 1.0, 0.02);
}

#[test]
fn every_bad_parameter_is_named() {
    let base = || ExploreParams::new(0.0, 1.0, 0.02);
    let cases: Vec<(&str, ExploreParams)> = vec![
        ("u_min", ExploreParams::new(f64::NAN, 1.0, 0.02)),
        ("u_max", ExploreParams::new(0.0, f64::INFINITY, 0.02)),
        ("u_max", ExploreParams::new(1.0, 1.0, 0.02)),
        ("max_step", ExploreParams::new(0.0, 1.0, 0.0)),
        ("max_step", ExploreParams::new(0.0, 1.0, f64::NAN)),
        (
            "u_start",
            ExploreParams {
                u_start: Some(2.0),
                ..base()
            },
        ),
        (
            "random_samples",
            ExploreParams {
                random_samples: 3,
                ..base()
            },
        ),
        (
            "alpha_start",
            ExploreParams {
                alpha_start: -0.1,
                ..base()
            },
        ),
        (
            "alpha_end",
            ExploreParams {
                alpha_end: 1.5,
                ..base()
            },
        ),
        (
            "refit_every",
            ExploreParams {
                refit_every: 0,
                ..base()
            },
        ),
        (
            "optimize_every",
            ExploreParams {
                optimize_every: 0,
                ..base()
            },
        ),
        (
            "candidates",
            ExploreParams {
                candidates: 1,
                ..base()
            },
        ),
        (
            "horizon",
            ExploreParams {
                horizon: 0,
                ..base()
            },
        ),
        ("pool", ExploreParams { pool: 1, ..base() }),
        (
            "pool",
            ExploreParams {
                pool: hbn_model::explore::MAX_POOL + 1,
                ..base()
            },
        ),
    ];
    for (field, params) in cases {
        match Explorer::new(params) {
            Err(ExploreError::InvalidParameter { name, reason }) => {
                assert_eq!(name, field, "{reason}");
                assert!(!reason.is_empty());
            }
            other => panic!("{field}: expected InvalidParameter, got {other:?}"),
        }
    }
    // Training parameters are checked up front too.
    let mut p = base();
    p.model.max_points = 0;
    assert!(matches!(Explorer::new(p), Err(ExploreError::Model(_))));
}

#[test]
fn a_non_finite_observation_is_rejected_and_not_recorded() {
    let mut e = Explorer::new(ExploreParams::new(0.0, 1.0, 0.02)).unwrap();
    e.observe(0.0, 0.1, 0.2).unwrap();
    let err = e.observe(0.01, f64::NAN, 0.2).unwrap_err();
    assert!(matches!(
        err,
        ExploreError::NonFiniteObservation {
            index: 1,
            signal: Signal::State,
            ..
        }
    ));
    assert!(err.to_string().contains("x is NaN"), "{err}");
    assert_eq!(e.n_observed(), 1);
}

#[test]
fn refits_beside_the_loop_are_used_lag_samples_after_they_start_however_fast_they_run() {
    let lag = 30;
    let params = || {
        let mut p = quick(ExploreParams::new(0.0, 1.0, 0.05));
        p.random_samples = 60;
        p.refit_every = 10;
        p.optimize_every = 80;
        p.seed = 3;
        p
    };
    let cfg = SimConfig {
        noise_gain: 1.0,
        seed: 4,
        ..SimConfig::new(SystemKind::Duhem)
    };
    // Drives the simulator with `lag` (pausing `pause` per sample); returns the inputs, the
    // samples after which the GP's hyperparameters changed (a fit or re-learning was used),
    // and the warnings.
    let run = |lag: usize, pause: std::time::Duration| {
        let mut explorer = Explorer::new(ExploreParams { lag, ..params() }).unwrap();
        let mut robot = Simulator::new(&cfg).unwrap();
        let (mut applied, mut learned_at) = (Vec::new(), Vec::new());
        let mut theta: Option<Vec<f64>> = None;
        for k in 0..260 {
            let u = explorer.propose();
            let (x, y) = robot.step(u).unwrap();
            explorer.observe(u, x, y).unwrap();
            applied.push(u);
            let now = explorer.transition().map(|gp| gp.theta().to_vec());
            if now != theta {
                if theta.is_none() {
                    // The first GP started at the end of the random phase, on the data then.
                    let rows = explorer.transition().unwrap().report().n_samples;
                    assert!(rows < 60, "fitted on {rows} rows, started at 60 samples");
                }
                learned_at.push(k + 1);
                theta = now;
            }
            std::thread::sleep(pause);
        }
        (applied, learned_at, explorer.warnings().to_vec())
    };
    // Two loops, one slow (every refit has finished long before it is applied) and one as
    // fast as it goes (refits are still running when they are due, so `observe()` waits):
    // the proposals are the same, bit for bit.
    let (fast, learned_fast, warnings) = run(lag, std::time::Duration::ZERO);
    let (slow, learned_slow, _) = run(lag, std::time::Duration::from_millis(3));
    assert!(warnings.is_empty(), "{warnings:?}");
    // The first fit (at 60 samples) waits as long as a refit, 10 samples; the re-learnings,
    // due every 80 samples from there (at 140 and 220), wait the whole lag.
    assert_eq!(learned_fast, vec![60 + 10, 140 + lag, 220 + lag]);
    assert_eq!(learned_slow, learned_fast);
    assert_eq!(fast, slow);
    assert_within(&fast, 0.0, 1.0, 0.05);
    // Refitting inside `observe()`, the same fits are used the sample they start.
    let (_, learned_inline, _) = run(0, std::time::Duration::ZERO);
    assert_eq!(learned_inline, vec![60, 140, 220]);
}
