//! Tests of the multi-signal systems.

use super::*;
use crate::systems::SWEEP_PEAK;

/// `0 -> 1 -> 0` in steps of 0.001 (2001 samples, `u = 0.5` at 500 rising and 1500 falling).
fn slow_triangle() -> Vec<f64> {
    (0..=1000)
        .chain((0..1000).rev())
        .map(|i| i as f64 * 0.001)
        .collect()
}

fn max_abs_diff(a: &[f64], b: &[f64]) -> f64 {
    a.iter()
        .zip(b)
        .map(|(p, q)| (p - q).abs())
        .fold(0.0, f64::max)
}

fn random_inputs(kind: MultiKind, steps: usize, seed: u64) -> Vec<Vec<f64>> {
    generate_multi_input(kind.inputs(), steps, 0.02, seed).unwrap()
}

#[test]
fn dimensions_names_and_mixing_shapes() {
    let dims = [(MultiKind::Finger, 2, 2, 3), (MultiKind::Arm, 3, 3, 4)];
    for (kind, du, dx, dy) in dims {
        assert_eq!((kind.inputs(), kind.states(), kind.sensors()), (du, dx, dy));
        let m = kind.state_mix();
        assert_eq!(m.len(), dx, "{kind}");
        assert!(m.iter().all(|r| r.len() == du), "{kind}");
        let s = kind.sensor_mix();
        assert_eq!(s.len(), dy, "{kind}");
        assert!(s.iter().all(|r| r.len() == dx), "{kind}");
        assert_eq!(kind.to_string(), kind.name());
        assert_eq!(kind.name().parse::<MultiKind>().unwrap(), kind);
        assert_eq!(
            kind.name().to_uppercase().parse::<MultiKind>().unwrap(),
            kind
        );
        assert!(!kind.description().is_empty() && !kind.description().contains('\n'));
        let t = simulate_multi_random(&MultiConfig::new(kind), 50).unwrap();
        assert_eq!((t.u.len(), t.x.len(), t.y.len()), (du, dx, dy), "{kind}");
        assert!(t.x.iter().chain(&t.y).all(|s| s.len() == 50), "{kind}");
        assert_eq!(t.len(), 50);
    }
    let err = "hand".parse::<MultiKind>().unwrap_err().to_string();
    assert!(
        err.contains("hand") && err.contains("finger") && err.contains("arm"),
        "{err}"
    );
}

#[test]
fn cross_weights_are_between_a_third_and_a_half_of_the_direct_ones() {
    for kind in MultiKind::ALL {
        // Tip component i is driven directly by chamber i with weight 1; every other chamber
        // with a weight of magnitude in [1/3, 1/2].
        for (i, row) in kind.state_mix().iter().enumerate() {
            for (c, &w) in row.iter().enumerate() {
                if c == i {
                    assert_eq!(w, 1.0, "{kind} state {i}");
                } else {
                    assert!(
                        (1.0 / 3.0..=0.5).contains(&w.abs()),
                        "{kind} state {i} chamber {c}: {w}"
                    );
                }
            }
        }
        // Each sensor reads every tip component, none with less than a third of the
        // largest (direct) weight.
        for (j, row) in kind.sensor_mix().iter().enumerate() {
            let direct = row.iter().fold(0.0f64, |a, w| a.max(w.abs()));
            assert_eq!(direct, 1.0, "{kind} sensor {j}");
            for (i, &w) in row.iter().enumerate() {
                assert!(w.abs() >= direct / 3.0, "{kind} sensor {j} state {i}: {w}");
            }
            // The mixture moves with the all-inputs sweep (a positive row sum).
            assert!(row.iter().sum::<f64>() > 0.5, "{kind} sensor {j}");
        }
    }
    // The arm's weights are the projections the docs derive: chambers 120 degrees apart.
    let a2 = ARM_ELONGATION_SQ;
    for (i, row) in ARM_STATE_MIX.iter().enumerate() {
        for (c, &w) in row.iter().enumerate() {
            let angle = 2.0 * std::f64::consts::PI * (i as f64 - c as f64) / 3.0;
            let want = (angle.cos() + a2) / (1.0 + a2);
            assert!((w - want).abs() < 1e-12, "arm [{i}][{c}]: {w} vs {want}");
        }
    }
}

#[test]
fn quasi_static_sweep_spans_the_unit_interval_per_component() {
    for kind in MultiKind::ALL {
        // The calibration's own sweep: from the virgin state, all inputs together
        // 0 -> 1 -> 0 twice (steps of 0.005), lags following their targets exactly; the
        // second cycle spans exactly [0, 1] in every state component and every sensor.
        let mut sys = MultiSystem::new(kind, 0.01).unwrap();
        sys.set_quasi_static(true);
        sys.reset();
        let cycle = sweep();
        let (mut x, mut y) = (vec![0.0; kind.states()], vec![0.0; kind.sensors()]);
        let mut xs = vec![Vec::new(); kind.states()];
        let mut ys = vec![Vec::new(); kind.sensors()];
        for pass in 0..2 {
            for &u in &cycle {
                sys.actuate(&vec![u; kind.inputs()], &mut x);
                sys.sense(&x, &mut y);
                if pass == 1 {
                    xs.iter_mut().zip(&x).for_each(|(s, &v)| s.push(v));
                    ys.iter_mut().zip(&y).for_each(|(s, &v)| s.push(v));
                }
            }
        }
        for (name, s) in xs
            .iter()
            .map(|s| ("x", s))
            .chain(ys.iter().map(|s| ("y", s)))
        {
            let lo = s.iter().copied().fold(f64::INFINITY, f64::min);
            let hi = s.iter().copied().fold(f64::NEG_INFINITY, f64::max);
            assert!(
                lo.abs() < 1e-9 && (hi - 1.0).abs() < 1e-9,
                "{kind} {name}: [{lo}, {hi}]"
            );
            // Monotone enough that the extremes sit at the ends of the sweep.
            assert!(
                s[SWEEP_PEAK] > 1.0 - 0.01,
                "{kind} {name}: peak {}",
                s[SWEEP_PEAK]
            );
        }
        // The public simulator starts relaxed at 0 and reaches 1 on a quasi-static sweep
        // (0.01 Hz: every lag settles within a sample).
        let cfg = MultiConfig {
            rate_hz: 0.01,
            ..MultiConfig::new(kind)
        };
        let tri = slow_triangle();
        let t = simulate_multi(&cfg, &vec![tri; kind.inputs()]).unwrap();
        for s in t.x.iter().chain(&t.y) {
            assert!(s[0].abs() < 0.01, "{kind}: start {}", s[0]);
            assert!((s[1000] - 1.0).abs() < 0.01, "{kind}: peak {}", s[1000]);
            assert!(s[2000].abs() < 0.01, "{kind}: end {}", s[2000]);
        }
    }
}

#[test]
fn every_state_component_depends_on_every_input() {
    for kind in MultiKind::ALL {
        let u = random_inputs(kind, 2000, 5);
        let cfg = MultiConfig::new(kind);
        let base = simulate_multi(&cfg, &u).unwrap();
        for c in 0..kind.inputs() {
            let mut v = u.clone();
            v[c].iter_mut().for_each(|s| *s *= 0.7);
            let moved = simulate_multi(&cfg, &v).unwrap();
            for i in 0..kind.states() {
                let d = max_abs_diff(&base.x[i], &moved.x[i]);
                assert!(d > 0.05, "{kind}: input {c} moves x{i} by only {d}");
            }
            for j in 0..kind.sensors() {
                let d = max_abs_diff(&base.y[j], &moved.y[j]);
                assert!(d > 0.02, "{kind}: input {c} moves y{j} by only {d}");
            }
        }
    }
}

#[test]
fn every_sensor_depends_on_every_state_component() {
    for kind in MultiKind::ALL {
        let t = simulate_multi(&MultiConfig::new(kind), &random_inputs(kind, 2000, 6)).unwrap();
        // The sensors alone, fed with the recorded state and with one component shifted.
        let read = |shift: Option<usize>| {
            let mut sys = MultiSystem::new(kind, 0.01).unwrap();
            let mut y = vec![Vec::new(); kind.sensors()];
            let (mut xk, mut yk) = (vec![0.0; kind.states()], vec![0.0; kind.sensors()]);
            for k in 0..t.len() {
                for (i, v) in xk.iter_mut().enumerate() {
                    *v = t.x[i][k] + if shift == Some(i) { 0.05 } else { 0.0 };
                }
                sys.sense(&xk, &mut yk);
                y.iter_mut().zip(&yk).for_each(|(s, &v)| s.push(v));
            }
            y
        };
        let base = read(None);
        assert_eq!(base, t.y, "{kind}: the sensors alone reproduce y");
        for i in 0..kind.states() {
            let moved = read(Some(i));
            for j in 0..kind.sensors() {
                let d = max_abs_diff(&base[j], &moved[j]);
                assert!(d > 0.01, "{kind}: x{i} moves y{j} by only {d}");
            }
        }
    }
}

#[test]
fn every_state_component_is_hysteretic() {
    for kind in MultiKind::ALL {
        // All inputs together, slowly (1 Hz: the lags settle within a sample, so the loop is
        // the operators' own, not the lags'), at u = 0.5 rising and falling.
        let cfg = MultiConfig {
            rate_hz: 1.0,
            ..MultiConfig::new(kind)
        };
        let tri = slow_triangle();
        assert_eq!((tri[500], tri[1500]), (0.5, 0.5));
        let t = simulate_multi(&cfg, &vec![tri; kind.inputs()]).unwrap();
        for (i, x) in t.x.iter().enumerate() {
            let opening = x[1500] - x[500];
            assert!(
                opening > 0.15,
                "{kind} x{i}: up {} down {}",
                x[500],
                x[1500]
            );
        }
        for (j, y) in t.y.iter().enumerate() {
            let opening = y[1500] - y[500];
            assert!(
                opening > 0.05,
                "{kind} y{j}: up {} down {}",
                y[500],
                y[1500]
            );
        }
    }
}

#[test]
fn the_lags_make_it_rate_dependent() {
    for kind in MultiKind::ALL {
        let u = random_inputs(kind, 3000, 2);
        let at = |rate_hz| {
            simulate_multi(
                &MultiConfig {
                    rate_hz,
                    ..MultiConfig::new(kind)
                },
                &u,
            )
            .unwrap()
        };
        let (slow, fast) = (at(50.0), at(200.0));
        assert_eq!(slow.rate_hz, 50.0);
        for i in 0..kind.states() {
            let d = max_abs_diff(&slow.x[i], &fast.x[i]);
            assert!(d > 0.05, "{kind} x{i}: {d}");
        }
        for j in 0..kind.sensors() {
            let d = max_abs_diff(&slow.y[j], &fast.y[j]);
            assert!(d > 0.05, "{kind} y{j}: {d}");
        }
    }
}

#[test]
fn deterministic_given_config_and_input() {
    for kind in MultiKind::ALL {
        let u = random_inputs(kind, 3000, 1);
        let cfg = MultiConfig {
            noise_gain: 2.0,
            seed: 3,
            rate_hz: 73.0,
            ..MultiConfig::new(kind)
        };
        let a = simulate_multi(&cfg, &u).unwrap();
        let b = simulate_multi(&cfg, &u).unwrap();
        let bits = |t: &MultiTrajectory| -> Vec<u64> {
            t.x.iter()
                .chain(&t.y)
                .flatten()
                .map(|v| v.to_bits())
                .collect()
        };
        assert_eq!(bits(&a), bits(&b), "{kind}");
        let other = simulate_multi(&MultiConfig { seed: 4, ..cfg }, &u).unwrap();
        assert_ne!(bits(&a), bits(&other), "{kind}");
    }
}

#[test]
fn gain_zero_is_exactly_the_clean_chain() {
    for kind in MultiKind::ALL {
        let u = random_inputs(kind, 2000, 8);
        let run = |seed| {
            simulate_multi(
                &MultiConfig {
                    seed,
                    ..MultiConfig::new(kind)
                },
                &u,
            )
            .unwrap()
        };
        let a = run(1);
        assert_eq!(a, run(2), "{kind}");
        let mut sys = MultiSystem::new(kind, 0.01).unwrap();
        let (mut x, mut y) = (vec![0.0; kind.states()], vec![0.0; kind.sensors()]);
        for k in 0..a.len() {
            let uk: Vec<f64> = u.iter().map(|s| s[k]).collect();
            sys.actuate(&uk, &mut x);
            sys.sense(&x, &mut y);
            for (i, &v) in x.iter().enumerate() {
                assert_eq!(a.x[i][k].to_bits(), v.to_bits(), "{kind} x{i} at {k}");
            }
            for (j, &v) in y.iter().enumerate() {
                assert_eq!(a.y[j][k].to_bits(), v.to_bits(), "{kind} y{j} at {k}");
            }
        }
    }
}

#[test]
fn noise_is_uniform_within_its_width_and_the_disturbance_persists() {
    let n = 20_000;
    for kind in MultiKind::ALL {
        let u = random_inputs(kind, n, 3);
        let cfg = MultiConfig {
            noise_gain: 1.0,
            seed: 77,
            ..MultiConfig::new(kind)
        };
        let (wx, wy) = (cfg.noise_width_x(), cfg.noise_width_y());
        assert_eq!((wx, wy), (0.02, 0.02));
        let mut sim = MultiSimulator::new(&cfg).unwrap();
        let mut ex = vec![Vec::with_capacity(n); kind.states()];
        let mut ey = vec![Vec::with_capacity(n); kind.sensors()];
        let mut xs = vec![Vec::with_capacity(n); kind.states()];
        for k in 0..n {
            // What the system would give from where it stands, without this sample's noise.
            let mut twin = sim.system.clone();
            let uk: Vec<f64> = u.iter().map(|s| s[k]).collect();
            let (x, y) = sim.step(&uk).unwrap();
            let mut xc = vec![0.0; kind.states()];
            twin.actuate(&uk, &mut xc);
            for i in 0..kind.states() {
                ex[i].push(x[i] - xc[i]);
                twin.disturb(i, x[i] - xc[i]);
                xs[i].push(x[i]);
            }
            let mut yc = vec![0.0; kind.sensors()];
            twin.sense(&x, &mut yc);
            for j in 0..kind.sensors() {
                ey[j].push(y[j] - yc[j]);
            }
        }
        for (e, w) in ex.iter().map(|e| (e, wx)).chain(ey.iter().map(|e| (e, wy))) {
            assert!(e.iter().all(|v| v.abs() <= 0.5 * w + 1e-12), "{kind}");
            let mean = e.iter().sum::<f64>() / n as f64;
            let var = e.iter().map(|v| (v - mean) * (v - mean)).sum::<f64>() / n as f64;
            assert!(mean.abs() < 0.01 * w, "{kind}: mean {mean}");
            assert!(
                (var / (w * w / 12.0) - 1.0).abs() < 0.05,
                "{kind}: var {var}"
            );
            let outer = e.iter().filter(|v| v.abs() > 0.25 * w).count() as f64 / n as f64;
            assert!((outer - 0.5).abs() < 0.02, "{kind}: outer fraction {outer}");
        }
        // The disturbance enters the tip's lag and relaxes from there, so the noisy state
        // strays from the clean run by more than one sample's disturbance.
        let clean = simulate_multi(&MultiConfig::new(kind), &u).unwrap();
        for (i, x) in xs.iter().enumerate() {
            let d = max_abs_diff(x, &clean.x[i]);
            assert!(d > wx, "{kind} x{i}: strays only {d}");
            assert!(d < 10.0 * wx, "{kind} x{i}: strays {d}");
        }
        assert_eq!(simulate_multi(&cfg, &u).unwrap().x, xs, "{kind}");
    }
}

#[test]
fn bounded_over_long_random_runs_and_extreme_inputs() {
    for kind in MultiKind::ALL {
        let u = generate_multi_input(kind.inputs(), 100_000, 0.05, 9).unwrap();
        let t = simulate_multi(&MultiConfig::new(kind), &u).unwrap();
        for s in &t.x {
            assert!(s.iter().all(|v| (-0.1..=1.1).contains(v)), "{kind}");
            let lo = s.iter().copied().fold(f64::INFINITY, f64::min);
            let hi = s.iter().copied().fold(f64::NEG_INFINITY, f64::max);
            assert!(hi - lo > 0.7, "{kind}: x spans only [{lo}, {hi}]");
        }
        for s in &t.y {
            assert!(s.iter().all(|v| (-1.2..=1.2).contains(v)), "{kind}");
        }
        // The whole admissible range, heavy noise.
        let wide: Vec<Vec<f64>> = u
            .iter()
            .map(|s| s.iter().map(|v| 2.0 * v - 0.5).collect())
            .collect();
        let cfg = MultiConfig {
            noise_gain: 10.0,
            seed: 5,
            ..MultiConfig::new(kind)
        };
        let t = simulate_multi(&cfg, &wide).unwrap();
        for v in t.x.iter().chain(&t.y).flatten() {
            assert!(v.is_finite() && v.abs() <= 4.0, "{kind}: {v}");
        }
    }
}

#[test]
fn inputs_are_independent_random_ramps() {
    let u = generate_multi_input(3, 5000, 0.02, 11).unwrap();
    assert_eq!(u.len(), 3);
    for s in &u {
        assert_eq!(s.len(), 5000);
        assert_eq!(s[0], 0.0);
        assert!(s.iter().all(|v| (0.0..=1.0).contains(v)));
        assert!(s.windows(2).all(|w| (w[1] - w[0]).abs() <= 0.02));
    }
    // Each input moves on its own: no two are equal, nor strongly correlated.
    for a in 0..3 {
        for b in a + 1..3 {
            assert_ne!(u[a], u[b]);
            let (ma, mb) = (
                u[a].iter().sum::<f64>() / 5000.0,
                u[b].iter().sum::<f64>() / 5000.0,
            );
            let cov: f64 = u[a]
                .iter()
                .zip(&u[b])
                .map(|(p, q)| (p - ma) * (q - mb))
                .sum();
            let va: f64 = u[a].iter().map(|p| (p - ma) * (p - ma)).sum();
            let vb: f64 = u[b].iter().map(|q| (q - mb) * (q - mb)).sum();
            let r = cov / (va * vb).sqrt();
            assert!(r.abs() < 0.3, "inputs {a} and {b}: correlation {r}");
        }
    }
    assert_eq!(u, generate_multi_input(3, 5000, 0.02, 11).unwrap());
    assert_ne!(u, generate_multi_input(3, 5000, 0.02, 12).unwrap());
    // The first inputs do not depend on how many are drawn.
    assert_eq!(u[..2], generate_multi_input(2, 5000, 0.02, 11).unwrap()[..]);
    assert!(generate_multi_input(2, 10, 0.0, 1).is_err());
    assert!(generate_multi_input(0, 10, 0.02, 1).unwrap().is_empty());
    // The convenience runner draws its input from the config's seed.
    let cfg = MultiConfig {
        seed: 12,
        noise_gain: 0.5,
        ..MultiConfig::new(MultiKind::Arm)
    };
    let t = simulate_multi_random(&cfg, 700).unwrap();
    let u = generate_multi_input(3, 700, crate::DEFAULT_MAX_INCREMENT, 12).unwrap();
    assert_eq!(t, simulate_multi(&cfg, &u).unwrap());
}

#[test]
fn bad_configs_and_inputs_are_errors() {
    let ok = MultiConfig::new(MultiKind::Finger);
    assert_eq!((ok.rate_hz, ok.noise_gain, ok.seed), (100.0, 0.0, 0));
    let two = vec![vec![0.0, 0.1, 0.2]; 2];
    for g in [-0.1, f64::NAN, f64::INFINITY] {
        let c = MultiConfig {
            noise_gain: g,
            ..ok.clone()
        };
        assert!(matches!(
            simulate_multi(&c, &two),
            Err(SimError::InvalidParameter {
                name: "noise_gain",
                ..
            })
        ));
        assert!(MultiSimulator::new(&c).is_err());
        assert!(simulate_multi_random(&c, 10).is_err());
    }
    for r in [0.0, -1.0, f64::NAN, f64::INFINITY] {
        let c = MultiConfig {
            rate_hz: r,
            ..ok.clone()
        };
        assert!(matches!(
            simulate_multi(&c, &two),
            Err(SimError::InvalidParameter {
                name: "rate_hz",
                ..
            })
        ));
    }
    let three = vec![vec![0.0; 3]; 3];
    let e = simulate_multi(&ok, &three).unwrap_err();
    assert!(
        matches!(
            e,
            SimError::InputCount {
                system: "finger",
                expected: 2,
                got: 3
            }
        ),
        "{e}"
    );
    assert!(matches!(
        simulate_multi(&ok, &[]),
        Err(SimError::InputCount { got: 0, .. })
    ));
    let e = simulate_multi(&ok, &[vec![0.0; 3], vec![0.0; 2]]).unwrap_err();
    assert!(
        matches!(
            e,
            SimError::InputLengthMismatch {
                input: 1,
                len: 2,
                expected: 3
            }
        ),
        "{e}"
    );
    for bad in [f64::NAN, f64::INFINITY, f64::NEG_INFINITY] {
        let u = vec![vec![0.0, 0.1, 0.2], vec![0.0, 0.1, bad]];
        assert!(matches!(
            simulate_multi(&ok, &u),
            Err(SimError::NonFiniteMultiInput {
                input: 1,
                index: 2,
                ..
            })
        ));
    }
    for bad in [1.5001, -0.5001, 7.0] {
        let u = vec![vec![0.0, bad, 0.2], vec![0.0, 0.1, 0.2]];
        let e = simulate_multi(&ok, &u).unwrap_err();
        assert!(
            matches!(
                e,
                SimError::MultiInputOutOfRange {
                    input: 0,
                    index: 1,
                    ..
                }
            ),
            "{e}"
        );
        assert!(e.to_string().contains("input signal 0"), "{e}");
    }
    let t = simulate_multi(&ok, &[vec![-0.5, 1.5], vec![1.5, -0.5]]).unwrap();
    assert_eq!(t.len(), 2);
    let t = simulate_multi(&ok, &[vec![], vec![]]).unwrap();
    assert!(t.is_empty() && t.x.iter().all(Vec::is_empty) && t.y.len() == 3);
}

#[test]
fn a_rejected_step_leaves_the_simulator_where_it_was() {
    let cfg = MultiConfig {
        noise_gain: 1.0,
        seed: 4,
        ..MultiConfig::new(MultiKind::Arm)
    };
    let u = random_inputs(MultiKind::Arm, 300, 4);
    let whole = simulate_multi(&cfg, &u).unwrap();
    let mut sim = MultiSimulator::new(&cfg).unwrap();
    assert_eq!(sim.kind(), MultiKind::Arm);
    for k in 0..300 {
        let uk: Vec<f64> = u.iter().map(|s| s[k]).collect();
        if k == 150 {
            assert!(matches!(
                sim.step(&[0.1, f64::NAN, 0.1]),
                Err(SimError::NonFiniteMultiInput {
                    input: 1,
                    index: 150,
                    ..
                })
            ));
            assert!(matches!(
                sim.step(&[0.1, 0.1, 9.0]),
                Err(SimError::MultiInputOutOfRange {
                    input: 2,
                    index: 150,
                    ..
                })
            ));
            assert!(matches!(
                sim.step(&[0.1, 0.1]),
                Err(SimError::InputCount { got: 2, .. })
            ));
        }
        let (x, y) = sim.step(&uk).unwrap();
        for (i, v) in x.iter().enumerate() {
            assert_eq!(*v, whole.x[i][k], "x{i} at {k}");
        }
        for (j, v) in y.iter().enumerate() {
            assert_eq!(*v, whole.y[j][k], "y{j} at {k}");
        }
    }
    assert_eq!(sim.steps(), 300);
}

/// Root-mean-square difference of two signals.
fn rms_diff(a: &[f64], b: &[f64]) -> f64 {
    let n = a.len().min(b.len()).max(1) as f64;
    (a.iter().zip(b).map(|(p, q)| (p - q) * (p - q)).sum::<f64>() / n).sqrt()
}

#[test]
fn without_noise_the_posterior_is_the_state() {
    let config = MultiConfig::new(MultiKind::Finger);
    let traj = simulate_multi(&config, &random_inputs(MultiKind::Finger, 300, 3)).unwrap();
    let post = multi_posterior_estimate(&config, &traj.u, &traj.y, 3, 1).unwrap();
    for i in 0..2 {
        assert!(max_abs_diff(&post.mean[i], &traj.x[i]) < 1e-12);
        assert!(post.std[i].iter().all(|s| *s < 1e-12));
    }
}

#[test]
fn the_posterior_uses_the_sensors_and_its_band_covers_the_state() {
    let config = MultiConfig {
        noise_gain: 10.0,
        seed: 11,
        ..MultiConfig::new(MultiKind::Arm)
    };
    let traj = simulate_multi_random(&config, 600).unwrap();
    let post = multi_posterior_estimate(&config, &traj.u, &traj.y, 400, 2).unwrap();
    // The same filter without the sensors (every output missing) is the prior: the
    // disturbances accumulate in the tips' lags.
    let missing = vec![vec![f64::NAN; traj.len()]; 4];
    let prior = multi_posterior_estimate(&config, &traj.u, &missing, 400, 2).unwrap();
    for i in 0..3 {
        let (with, without) = (
            rms_diff(&post.mean[i], &traj.x[i]),
            rms_diff(&prior.mean[i], &traj.x[i]),
        );
        assert!(
            with < 0.7 * without,
            "x{i}: {with} with the sensors, {without} without"
        );
        let inside = (0..traj.len())
            .filter(|&k| (post.mean[i][k] - traj.x[i][k]).abs() <= 2.0 * post.std[i][k])
            .count() as f64
            / traj.len() as f64;
        assert!(
            (0.9..=1.0).contains(&inside),
            "x{i}: 2-sigma coverage {inside}"
        );
    }
    assert!(post.resamples > 0 && post.min_effective_particles >= 1.0);
}

#[test]
fn the_posterior_refuses_wrong_outputs_and_no_particles() {
    let config = MultiConfig::new(MultiKind::Finger);
    let traj = simulate_multi(&config, &random_inputs(MultiKind::Finger, 20, 1)).unwrap();
    let two = &traj.y[..2];
    assert!(matches!(
        multi_posterior_estimate(&config, &traj.u, two, 10, 0),
        Err(SimError::OutputShape { got: 2, .. })
    ));
    let mut short = traj.y.clone();
    short[1].pop();
    assert!(matches!(
        multi_posterior_estimate(&config, &traj.u, &short, 10, 0),
        Err(SimError::OutputShape {
            signal: 1,
            len: 19,
            ..
        })
    ));
    assert!(matches!(
        multi_posterior_estimate(&config, &traj.u, &traj.y, 0, 0),
        Err(SimError::InvalidParameter {
            name: "particles",
            ..
        })
    ));
}
