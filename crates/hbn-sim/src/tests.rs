//! System-level tests.

use super::*;

/// `0 -> 1 -> 0` in steps of 0.01 (201 samples, peak at index 100).
fn triangle() -> Vec<f64> {
    let mut u: Vec<f64> = (0..=100).map(|i| i as f64 * 0.01).collect();
    u.extend((0..100).rev().map(|i| i as f64 * 0.01));
    u
}

/// Linear interpolation of `b` where `a` first crosses `level` in `a[range]`, upward or downward.
fn crossing(a: &[f64], b: &[f64], level: f64, range: core::ops::Range<usize>, up: bool) -> f64 {
    for k in range.start.max(1)..range.end {
        let (a0, a1) = (a[k - 1], a[k]);
        let hit = if up {
            a0 < level && a1 >= level
        } else {
            a0 > level && a1 <= level
        };
        if hit {
            let t = (level - a0) / (a1 - a0);
            return b[k - 1] + t * (b[k] - b[k - 1]);
        }
    }
    panic!("no crossing of {level}");
}

fn argmax(v: &[f64]) -> usize {
    let mut best = 0;
    for (i, &x) in v.iter().enumerate() {
        if x > v[best] {
            best = i;
        }
    }
    best
}

/// Minimum loop opening required, in units of the nominal range (10 % of range_x for u -> x,
/// 2 % of range_y for x -> y).
const X_LOOP_MARGIN: f64 = 0.10;
const Y_LOOP_MARGIN: f64 = 0.02;

#[test]
fn every_system_is_hysteretic_in_x_and_in_y() {
    for kind in SystemKind::ALL {
        let u = triangle();
        let t = simulate(&SimConfig::new(kind), &u).unwrap();
        // u -> x at u = 0.5 (exact sample 50 up, 150 down).
        let dx = (t.x[50] - t.x[150]).abs();
        assert!(
            dx > X_LOOP_MARGIN * kind.nominal_range_x(),
            "{kind}: x(0.5) up {} down {}",
            t.x[50],
            t.x[150]
        );
        // x -> y at the mid level of x, up and down branches split at the peak of x.
        let peak = argmax(&t.x);
        let level = 0.5 * (t.x[0] + t.x[peak]);
        let y_up = crossing(&t.x, &t.y, level, 0..peak + 1, true);
        let y_down = crossing(&t.x, &t.y, level, peak..t.x.len(), false);
        assert!(
            (y_up - y_down).abs() > Y_LOOP_MARGIN * kind.nominal_range_y(),
            "{kind}: y at x = {level}: up {y_up} down {y_down}"
        );
    }
}

#[test]
fn y_is_not_an_affine_function_of_x() {
    // On the quasi-static virgin-free ascending branch, y(x) is curved: the chord midpoint
    // differs from the value at the middle.
    for kind in SystemKind::ALL {
        let t = simulate(&SimConfig::new(kind), &triangle()).unwrap();
        let y_mid = crossing(&t.x, &t.y, 0.5 * t.x[100], 0..101, true);
        let chord = 0.5 * (t.y[0] + t.y[100]);
        assert!(
            (y_mid - chord).abs() > 0.02,
            "{kind}: {y_mid} vs chord {chord}"
        );
    }
}

#[test]
fn calibrated_major_loop_spans_unit_interval() {
    for kind in SystemKind::ALL {
        // Slow triangle: 100 s per sample is quasi-static even for the soft actuator.
        let mut u: Vec<f64> = (0..=400).map(|i| i as f64 * 0.0025).collect();
        u.extend((0..400).rev().map(|i| i as f64 * 0.0025));
        let cfg = SimConfig {
            rate_hz: 0.01,
            ..SimConfig::new(kind)
        };
        let t = simulate(&cfg, &u).unwrap();
        assert!(t.x[0].abs() < 1e-12 && t.y[0].abs() < 1e-12, "{kind}");
        assert!((t.x[400] - 1.0).abs() < 0.02, "{kind}: x(1) = {}", t.x[400]);
        assert!((t.y[400] - 1.0).abs() < 0.02, "{kind}: y(1) = {}", t.y[400]);
        assert!(t.x[800].abs() < 0.02, "{kind}: x end {}", t.x[800]);
        assert!(t.y[800].abs() < 0.02, "{kind}: y end {}", t.y[800]);
    }
}

/// Bound for clean outputs under inputs in [0, 1]: [-0.1, 1.1] (nominal ranges are 1).
const CLEAN_BOUND: (f64, f64) = (-0.1, 1.1);

#[test]
fn bounded_over_100k_random_steps() {
    for kind in SystemKind::ALL {
        for input in [InputKind::RandomRamps, InputKind::RandomWalk] {
            let u = generate_input(input, 100_000, 0.05, 9).unwrap();
            let t = simulate(&SimConfig::new(kind), &u).unwrap();
            for v in t.x.iter().chain(&t.y) {
                assert!(v.is_finite(), "{kind}");
                assert!(
                    (CLEAN_BOUND.0..=CLEAN_BOUND.1).contains(v),
                    "{kind} {input:?}: {v}"
                );
            }
            // And it actually moves across the range.
            let (lo, hi) =
                t.x.iter()
                    .fold((f64::MAX, f64::MIN), |(a, b), &v| (a.min(v), b.max(v)));
            assert!(hi - lo > 0.7, "{kind}: x spans only [{lo}, {hi}]");
        }
    }
}

#[test]
fn bounded_with_heavy_noise_and_extreme_inputs() {
    for kind in SystemKind::ALL {
        // Inputs over the whole admissible range [-0.5, 1.5], noise gain 10.
        let u: Vec<f64> = generate_input(InputKind::RandomWalk, 100_000, 0.05, 4)
            .unwrap()
            .into_iter()
            .map(|v| 2.0 * v - 0.5)
            .collect();
        let cfg = SimConfig {
            noise_gain: 10.0,
            seed: 5,
            ..SimConfig::new(kind)
        };
        let t = simulate(&cfg, &u).unwrap();
        for v in t.x.iter().chain(&t.y) {
            assert!(v.is_finite() && v.abs() <= 3.0, "{kind}: {v}");
        }
    }
}

#[test]
fn soft_actuators_are_rate_dependent_others_are_not() {
    let u = generate_input(InputKind::RandomRamps, 3000, 0.02, 2).unwrap();
    for kind in SystemKind::ALL {
        let slow = simulate(
            &SimConfig {
                rate_hz: 50.0,
                ..SimConfig::new(kind)
            },
            &u,
        )
        .unwrap();
        let fast = simulate(
            &SimConfig {
                rate_hz: 200.0,
                ..SimConfig::new(kind)
            },
            &u,
        )
        .unwrap();
        assert_eq!(slow.rate_hz, 50.0);
        let dx = slow
            .x
            .iter()
            .zip(&fast.x)
            .map(|(a, b)| (a - b).abs())
            .fold(0.0, f64::max);
        let dy = slow
            .y
            .iter()
            .zip(&fast.y)
            .map(|(a, b)| (a - b).abs())
            .fold(0.0, f64::max);
        if kind.is_rate_dependent() {
            assert!(dx > 0.05 && dy > 0.05, "{kind}: dx {dx} dy {dy}");
        } else {
            assert_eq!((slow.x, slow.y), (fast.x, fast.y), "{kind}");
        }
    }
    assert_eq!(
        SystemKind::ALL
            .iter()
            .filter(|k| k.is_rate_dependent())
            .count(),
        2
    );
}

#[test]
fn noise_free_is_exactly_the_clean_chain() {
    let u = generate_input(InputKind::RandomWalk, 2000, 0.02, 8).unwrap();
    for kind in SystemKind::ALL {
        let a = simulate(
            &SimConfig {
                seed: 1,
                ..SimConfig::new(kind)
            },
            &u,
        )
        .unwrap();
        let b = simulate(
            &SimConfig {
                seed: 2,
                ..SimConfig::new(kind)
            },
            &u,
        )
        .unwrap();
        assert_eq!(a, b, "{kind}");
        let mut sys = systems::System::new(kind, 0.01).unwrap();
        for (k, &uk) in u.iter().enumerate() {
            let x = sys.actuate(uk);
            assert_eq!(a.x[k].to_bits(), x.to_bits(), "{kind}");
            assert_eq!(a.y[k].to_bits(), sys.sense(x).to_bits(), "{kind}");
        }
    }
}

#[test]
fn unit_gain_noise_is_uniform_within_one_percent_of_range() {
    let u = generate_input(InputKind::RandomRamps, 20_000, 0.02, 3).unwrap();
    // A propagating disturbance is not added to the output: see the `soft-actuator-load` tests.
    for kind in SystemKind::ALL
        .into_iter()
        .filter(|k| !k.disturbance_propagates())
    {
        let clean = simulate(&SimConfig::new(kind), &u).unwrap();
        let cfg = SimConfig {
            noise_gain: 1.0,
            seed: 77,
            ..SimConfig::new(kind)
        };
        let noisy = simulate(&cfg, &u).unwrap();
        let r = kind.nominal_range_x();
        let res: Vec<f64> = noisy.x.iter().zip(&clean.x).map(|(a, b)| a - b).collect();
        assert!(res.iter().all(|e| e.abs() <= 0.01 * r), "{kind}");
        let n = res.len() as f64;
        let mean = res.iter().sum::<f64>() / n;
        let var = res.iter().map(|e| (e - mean) * (e - mean)).sum::<f64>() / n;
        let want = (0.02 * r) * (0.02 * r) / 12.0;
        assert!(mean.abs() < 2e-4 * r, "{kind}: mean {mean}");
        assert!(
            (var / want - 1.0).abs() < 0.05,
            "{kind}: var {var} vs {want}"
        );
        // Uniform, not Gaussian: a quarter of the mass in each quarter of [-0.01, 0.01] r.
        let outer = res.iter().filter(|e| e.abs() > 0.005 * r).count() as f64 / n;
        assert!((outer - 0.5).abs() < 0.02, "{kind}: outer fraction {outer}");
        // The sensor output is perturbed too.
        assert!(noisy.y.iter().zip(&clean.y).any(|(a, b)| a != b), "{kind}");
        // Same seed: bit-identical; different seed: different.
        assert_eq!(simulate(&cfg, &u).unwrap(), noisy, "{kind}");
        let other = simulate(&SimConfig { seed: 78, ..cfg }, &u).unwrap();
        assert_ne!(other.x, noisy.x, "{kind}");
        assert_ne!(other.y, noisy.y, "{kind}");
    }
}

#[test]
fn simulate_random_is_ramps_with_default_increment() {
    let cfg = SimConfig {
        seed: 12,
        noise_gain: 0.5,
        ..SimConfig::new(SystemKind::SoftActuator)
    };
    let t = simulate_random(&cfg, 1500).unwrap();
    assert_eq!(t.u.len(), 1500);
    assert_eq!((t.x.len(), t.y.len()), (1500, 1500));
    let u = generate_input(InputKind::RandomRamps, 1500, DEFAULT_MAX_INCREMENT, 12).unwrap();
    assert_eq!(t, simulate(&cfg, &u).unwrap());
    assert_eq!(t, simulate_random(&cfg, 1500).unwrap());
    assert!(simulate_random(&cfg, 0).unwrap().u.is_empty());
}

#[test]
fn rejects_bad_configs_and_inputs() {
    let ok = SimConfig::new(SystemKind::Duhem);
    assert!(ok.validate().is_ok());
    assert_eq!(ok.rate_hz, 100.0);
    assert_eq!((ok.noise_gain, ok.seed), (0.0, 0));
    for g in [-0.1, f64::NAN, f64::INFINITY] {
        let c = SimConfig {
            noise_gain: g,
            ..ok.clone()
        };
        assert!(matches!(
            c.validate(),
            Err(SimError::InvalidParameter {
                name: "noise_gain",
                ..
            })
        ));
        assert!(simulate(&c, &[0.0]).is_err());
        assert!(simulate_random(&c, 10).is_err());
    }
    for r in [0.0, -100.0, f64::NAN, f64::INFINITY] {
        let c = SimConfig {
            rate_hz: r,
            ..ok.clone()
        };
        assert!(matches!(
            simulate(&c, &[0.0]),
            Err(SimError::InvalidParameter {
                name: "rate_hz",
                ..
            })
        ));
    }
    for bad in [f64::NAN, f64::INFINITY, f64::NEG_INFINITY] {
        assert!(matches!(
            simulate(&ok, &[0.0, bad]),
            Err(SimError::NonFiniteInput { index: 1, .. })
        ));
    }
    for bad in [1.5001, -0.5001, 7.0] {
        assert!(matches!(
            simulate(&ok, &[0.0, 0.1, bad]),
            Err(SimError::InputOutOfRange { index: 2, .. })
        ));
    }
    let t = simulate(&ok, &[-0.5, 1.5, 0.0]).unwrap();
    assert_eq!(t.x.len(), 3);
    assert!(simulate(&ok, &[]).unwrap().x.is_empty());
}

#[test]
fn system_names_parse_and_display() {
    let names = [
        "maxwell-slip",
        "generalized-pi",
        "bouc-wen",
        "preisach",
        "duhem",
        "soft-actuator",
        "soft-actuator-load",
    ];
    for (kind, name) in SystemKind::ALL.into_iter().zip(names) {
        assert_eq!(kind.name(), name);
        assert_eq!(kind.to_string(), name);
        assert_eq!(name.parse::<SystemKind>().unwrap(), kind);
        assert_eq!(
            name.to_uppercase()
                .replace('-', "_")
                .parse::<SystemKind>()
                .unwrap(),
            kind
        );
        assert!(!kind.description().is_empty() && !kind.description().contains('\n'));
    }
    let err = "hysteron".parse::<SystemKind>().unwrap_err();
    let msg = err.to_string();
    assert!(msg.contains("hysteron"), "{msg}");
    for name in names {
        assert!(msg.contains(name), "{msg}");
    }
}

#[test]
fn deterministic_given_config_and_input() {
    let u = generate_input(InputKind::DecayingSine, 3000, 0.02, 0).unwrap();
    for kind in SystemKind::ALL {
        let cfg = SimConfig {
            noise_gain: 2.0,
            seed: 3,
            rate_hz: 73.0,
            ..SimConfig::new(kind)
        };
        let a = simulate(&cfg, &u).unwrap();
        let b = simulate(&cfg, &u).unwrap();
        assert!(
            a.x.iter()
                .chain(&a.y)
                .zip(b.x.iter().chain(&b.y))
                .all(|(p, q)| p.to_bits() == q.to_bits())
        );
    }
}

#[test]
fn a_rejected_step_leaves_the_simulator_where_it_was() {
    let cfg = SimConfig {
        noise_gain: 1.0,
        seed: 4,
        ..SimConfig::new(SystemKind::BoucWen)
    };
    let u = generate_input(InputKind::RandomRamps, 300, 0.02, 4).unwrap();
    let whole = simulate(&cfg, &u).unwrap();
    let mut sim = Simulator::new(&cfg).unwrap();
    for (k, &uk) in u.iter().enumerate() {
        if k == 150 {
            assert!(matches!(
                sim.step(f64::NAN),
                Err(SimError::NonFiniteInput { index: 150, .. })
            ));
            assert!(matches!(
                sim.step(9.0),
                Err(SimError::InputOutOfRange { index: 150, .. })
            ));
        }
        let (x, y) = sim.step(uk).unwrap();
        assert_eq!((x, y), (whole.x[k], whole.y[k]), "sample {k}");
    }
    assert_eq!(sim.steps(), 300);
}

#[test]
fn only_the_load_disturbance_propagates() {
    let propagating: Vec<SystemKind> = SystemKind::ALL
        .into_iter()
        .filter(|k| k.disturbance_propagates())
        .collect();
    assert_eq!(propagating, [SystemKind::SoftActuatorLoad]);
    assert!(SystemKind::SoftActuatorLoad.is_rate_dependent());
}

/// Noise-free, `soft-actuator-load` is the soft actuator, bit for bit, at any rate.
#[test]
fn the_load_system_without_noise_is_the_soft_actuator() {
    let u = generate_input(InputKind::RandomRamps, 3000, 0.02, 6).unwrap();
    for rate_hz in [30.0, 100.0, 400.0] {
        let cfg = |system| SimConfig {
            rate_hz,
            seed: 9,
            ..SimConfig::new(system)
        };
        let load = simulate(&cfg(SystemKind::SoftActuatorLoad), &u).unwrap();
        let soft = simulate(&cfg(SystemKind::SoftActuator), &u).unwrap();
        assert_eq!(load, soft, "{rate_hz} Hz");
    }
}

/// The disturbance process alone: stationary variance `w^2 / 12` and lag-one correlation
/// `exp(-dt / 0.3 s)` at every rate.
#[test]
fn the_load_disturbance_is_ar1_with_the_others_variance() {
    for rate_hz in [25.0, 100.0, 500.0] {
        let dt = 1.0 / rate_hz;
        let width = 0.06;
        let mut load = systems::LoadDisturbance::new(width, dt);
        let mut rng = Rng::new(17);
        let d: Vec<f64> = (0..400_000)
            .map(|_| load.step(rng.uniform() - 0.5))
            .collect();
        let d = &d[5000..];
        let n = d.len() as f64;
        let mean = d.iter().sum::<f64>() / n;
        let var = d.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / n;
        let want = width * width / 12.0;
        assert!(
            (var / want - 1.0).abs() < 0.06,
            "{rate_hz} Hz: var {var} vs {want}"
        );
        let cov1 = d
            .windows(2)
            .map(|w| (w[0] - mean) * (w[1] - mean))
            .sum::<f64>()
            / (n - 1.0);
        let a = (-dt / systems::LOAD_TAU).exp();
        assert!(
            (cov1 / var - a).abs() < 0.01,
            "{rate_hz} Hz: rho {} vs {a}",
            cov1 / var
        );
    }
}

/// `soft-actuator-load` at gain 1: the state strays from the clean one by about the others'
/// disturbance (standard deviation within a factor 2 of `0.02 / sqrt(12)`), slowly (its
/// deviation 0.1 s later is strongly correlated with it: the disturbance propagates), and the
/// sensor reads the disturbed state plus the usual measurement noise.
#[test]
fn the_load_disturbance_propagates_through_the_dynamics() {
    let u = generate_input(InputKind::RandomRamps, 20_000, 0.02, 3).unwrap();
    let system = SystemKind::SoftActuatorLoad;
    let clean = simulate(&SimConfig::new(system), &u).unwrap();
    let cfg = SimConfig {
        noise_gain: 1.0,
        seed: 77,
        ..SimConfig::new(system)
    };
    let noisy = simulate(&cfg, &u).unwrap();
    let dev: Vec<f64> = noisy.x.iter().zip(&clean.x).map(|(a, b)| a - b).collect();
    let n = dev.len() as f64;
    let mean = dev.iter().sum::<f64>() / n;
    let var = dev.iter().map(|e| (e - mean).powi(2)).sum::<f64>() / n;
    let sd = var.sqrt();
    let others = 0.02 / 12f64.sqrt();
    assert!(
        (0.5 * others..2.0 * others).contains(&sd),
        "sd {sd} vs {others}"
    );
    assert!(mean.abs() < 0.3 * others, "mean {mean}");
    let lag = 10;
    let cov = dev
        .windows(lag + 1)
        .map(|w| (w[0] - mean) * (w[lag] - mean))
        .sum::<f64>()
        / (n - lag as f64);
    assert!(cov / var > 0.6, "correlation at 0.1 s: {}", cov / var);
    // The measurement noise: y is the sensor's reading of the recorded x within +-0.01.
    let mut sys = systems::System::new(system, 0.01).unwrap();
    for k in 0..noisy.x.len() {
        let y_clean = sys.sense(noisy.x[k]);
        assert!((noisy.y[k] - y_clean).abs() <= 0.01 + 1e-12, "sample {k}");
    }
    // x and y stay in about [0, 1].
    for v in noisy.x.iter().chain(&noisy.y) {
        assert!((-0.1..=1.1).contains(v), "{v}");
    }
    assert_eq!(simulate(&cfg, &u).unwrap(), noisy);
    let other = simulate(&SimConfig { seed: 78, ..cfg }, &u).unwrap();
    assert_ne!(other.x, noisy.x);
    eprintln!(
        "load: sd {sd} (others {others}), correlation at 0.1 s {}",
        cov / var
    );
}
