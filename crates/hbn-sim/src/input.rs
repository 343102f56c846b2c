//! Test and training inputs with bounded increments (Assumption 2 of HBN.md).

use hbn_core::rng::Rng;

use crate::SimError;

/// Default bound on `|u[k+1] - u[k]|` used by [`crate::simulate_random`].
pub const DEFAULT_MAX_INCREMENT: f64 = 0.02;

/// Salt mixed into the seed of the input generator so that an input and the measurement noise
/// of a simulation run with the same seed do not share one random stream.
const INPUT_SALT: u64 = 0x5EED_1A7E_0F1A_7E55;

/// Generated increments stay below this fraction of `max_increment`, so floating-point rounding
/// can never push an increment over the bound.
const MARGIN: f64 = 0.999;

/// How the test/training input is generated: values in `[0,1]`, `|u[k+1]-u[k]| <= max_increment`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum InputKind {
    /// Ramps between random levels in `[0,1]` at random (bounded) slopes: produces nested minor loops.
    RandomRamps,
    /// Bounded random walk reflected at 0 and 1.
    RandomWalk,
    /// Decaying-amplitude sine sweep (first-order reversal curves), deterministic given steps.
    DecayingSine,
}

/// Generates `steps` input samples of the given kind, starting at `u[0] = 0` (the relaxed
/// state), all in `[0, 1]` with `|u[k+1] - u[k]| <= max_increment`.
///
/// `max_increment` must be finite and in `(0, 1]`. The random kinds are deterministic per
/// `seed` (the generator is `hbn_core::rng::Rng` seeded with `seed` xor a fixed salt);
/// `DecayingSine` ignores the seed: its amplitude decays linearly from 1 to 0.05 over `steps`
/// and its angular step is `1.9 * max_increment - (amplitude decrement)` (at least
/// `0.5 * max_increment`), so the sweep visits first-order reversal curves.
pub fn generate_input(
    kind: InputKind,
    steps: usize,
    max_increment: f64,
    seed: u64,
) -> Result<Vec<f64>, SimError> {
    if !(max_increment.is_finite() && max_increment > 0.0 && max_increment <= 1.0) {
        return Err(SimError::InvalidParameter {
            name: "max_increment",
            value: max_increment,
            reason: "must be finite and in (0, 1]",
        });
    }
    let mut out = Vec::with_capacity(steps);
    if steps == 0 {
        return Ok(out);
    }
    let m = MARGIN * max_increment;
    let mut rng = Rng::new(seed ^ INPUT_SALT);
    let mut u = 0.0f64;
    out.push(u);
    match kind {
        InputKind::RandomRamps => {
            let mut target = rng.uniform();
            let mut slope = rng.uniform_in(0.1 * m, m);
            while out.len() < steps {
                let diff = target - u;
                if diff.abs() <= slope {
                    u = target;
                    target = rng.uniform();
                    slope = rng.uniform_in(0.1 * m, m);
                } else {
                    u += slope.copysign(diff);
                }
                out.push(u);
            }
        }
        InputKind::RandomWalk => {
            while out.len() < steps {
                let mut v = u + rng.uniform_in(-m, m);
                if v > 1.0 {
                    v = 2.0 - v;
                }
                if v < 0.0 {
                    v = -v;
                }
                u = v.clamp(0.0, 1.0);
                out.push(u);
            }
        }
        InputKind::DecayingSine => {
            let da = if steps > 1 {
                0.95 / (steps - 1) as f64
            } else {
                0.0
            };
            let omega = (1.9 * m - da).max(0.5 * m);
            for k in 1..steps {
                let a = 1.0 - da * k as f64;
                let target = 0.5 - 0.5 * a * (omega * k as f64).cos();
                // Safety net (inactive for the chosen omega): keep both guarantees exactly.
                u = target.clamp(u - m, u + m).clamp(0.0, 1.0);
                out.push(u);
            }
        }
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    const KINDS: [InputKind; 3] = [
        InputKind::RandomRamps,
        InputKind::RandomWalk,
        InputKind::DecayingSine,
    ];

    #[test]
    fn within_unit_interval_and_increments_bounded() {
        for kind in KINDS {
            for &m in &[0.005, 0.02, 0.1, 1.0] {
                let u = generate_input(kind, 20_000, m, 3).unwrap();
                assert_eq!(u.len(), 20_000);
                assert_eq!(u[0], 0.0);
                assert!(u.iter().all(|v| (0.0..=1.0).contains(v)), "{kind:?}");
                let worst = u
                    .windows(2)
                    .map(|w| (w[1] - w[0]).abs())
                    .fold(0.0, f64::max);
                assert!(worst <= m, "{kind:?} m={m} worst={worst}");
                // Not degenerate: it moves and covers a good part of [0, 1].
                let (lo, hi) = u
                    .iter()
                    .fold((1.0f64, 0.0f64), |(l, h), &v| (l.min(v), h.max(v)));
                assert!(
                    m < 0.02 || hi - lo > 0.8,
                    "{kind:?} m={m} covers only [{lo}, {hi}]"
                );
            }
        }
    }

    #[test]
    fn deterministic_per_seed() {
        for kind in KINDS {
            let a = generate_input(kind, 5000, 0.02, 11).unwrap();
            let b = generate_input(kind, 5000, 0.02, 11).unwrap();
            assert_eq!(a, b);
            let c = generate_input(kind, 5000, 0.02, 12).unwrap();
            if kind == InputKind::DecayingSine {
                assert_eq!(a, c);
            } else {
                assert_ne!(a, c);
            }
        }
    }

    #[test]
    fn ramps_reverse_often_and_sine_decays() {
        let u = generate_input(InputKind::RandomRamps, 10_000, 0.02, 1).unwrap();
        let reversals = u
            .windows(3)
            .filter(|w| (w[1] - w[0]) * (w[2] - w[1]) < 0.0)
            .count();
        assert!(reversals > 50, "{reversals}");
        let s = generate_input(InputKind::DecayingSine, 4000, 0.02, 0).unwrap();
        let early = s[..1000]
            .iter()
            .fold(0.0f64, |a, &v| a.max((v - 0.5).abs()));
        let late = s[3000..]
            .iter()
            .fold(0.0f64, |a, &v| a.max((v - 0.5).abs()));
        assert!(early > 0.45 && late < 0.2, "{early} {late}");
    }

    #[test]
    fn rejects_bad_increment_and_handles_small_sizes() {
        for &m in &[0.0, -0.1, 1.5, f64::NAN, f64::INFINITY] {
            assert!(generate_input(InputKind::RandomWalk, 10, m, 0).is_err());
        }
        assert!(
            generate_input(InputKind::RandomRamps, 0, 0.02, 0)
                .unwrap()
                .is_empty()
        );
        assert_eq!(
            generate_input(InputKind::DecayingSine, 1, 0.02, 0).unwrap(),
            vec![0.0]
        );
    }
}
