//! The CPU's wider vector instructions for the hot loops, chosen at run time.
//!
//! A build for generic x86-64 vectorises with two-lane SSE2 only. [`vectorised`] runs a closure
//! inside a function compiled for AVX2 (four lanes) when the CPU has it, detected once with
//! CPUID and cached. The results are bit-identical either way: AVX2 only widens the vectors of
//! the same IEEE additions and multiplications in the same order (Rust never reorders them or
//! fuses a multiplication with an addition on its own), so a filter estimates to the same bits
//! on every x86-64 CPU. Other targets (a firmware's ARM core, say) run the closure as
//! it is, with whatever the build enables.
//!
//! What it buys is measured in `docs/benchmarks.md` ("Vector width chosen at run time").
//!
//! This module holds the crate's only `unsafe` code: the call of a `#[target_feature]` function,
//! made only after the CPU was seen to support the feature.
#![allow(unsafe_code)]

#[cfg(target_arch = "x86_64")]
cpufeatures::new!(cpu_avx2, "avx2");

/// Whether [`vectorised`] runs its closure compiled for AVX2 on this CPU.
#[inline]
pub fn avx2() -> bool {
    #[cfg(target_arch = "x86_64")]
    {
        cpu_avx2::get()
    }
    #[cfg(not(target_arch = "x86_64"))]
    {
        false
    }
}

/// Runs `f`, compiled for AVX2 when the CPU has it ([`avx2`]), else as built.
///
/// For the wider instructions to reach the loops, everything `f` calls on its hot path must be
/// inlined into it (`#[inline(always)]`): a function that is called, not inlined, runs as it
/// was built. The result is the same bits either way (see the module documentation).
#[inline(always)]
pub fn vectorised<R>(f: impl FnOnce() -> R) -> R {
    #[cfg(target_arch = "x86_64")]
    if avx2() {
        // SAFETY: `run_avx2` may use AVX2 instructions, and the CPU supports them (CPUID, with
        // the operating system's support for the wider registers, checked by `cpufeatures`).
        return unsafe { run_avx2(f) };
    }
    f()
}

/// `f()` in a function compiled with AVX2 enabled.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
#[inline]
unsafe fn run_avx2<R>(f: impl FnOnce() -> R) -> R {
    f()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_closure_runs_once_and_returns_its_value() {
        let mut calls = 0;
        let out = vectorised(|| {
            calls += 1;
            41 + 1
        });
        assert_eq!((out, calls), (42, 1));
    }

    /// The module's promise: the same sums to the bit with and without the wider vectors, on
    /// terms of very different size (so that a reordered sum would differ).
    #[test]
    fn wide_and_narrow_loops_give_the_same_bits() {
        let a: Vec<f64> = (0..1003)
            .map(|i| (f64::from(i) * 0.37).sin() * 10f64.powi(i % 17 - 8))
            .collect();
        let b: Vec<f64> = (0..1003).map(|i| 1.0 / (f64::from(i) + 0.3)).collect();
        #[inline(always)]
        fn sums(a: &[f64], b: &[f64]) -> [f64; 2] {
            [
                crate::gp::dot(a, b),
                a.iter().zip(b).map(|(x, y)| x * y + 1e-3 * x).sum(),
            ]
        }
        let wide = vectorised(|| sums(&a, &b));
        let narrow = sums(&a, &b);
        assert_eq!(wide.map(f64::to_bits), narrow.map(f64::to_bits));
    }
}
