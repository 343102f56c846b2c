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
//! It also holds [`sqrt`], the square root the core uses everywhere: `libm`'s is legacy-SSE
//! inline assembly, which stalls inside the AVX2 code on some CPUs.
//!
//! This module holds the crate's only `unsafe` code: the call of a `#[target_feature]` function,
//! made only after the CPU was seen to support the feature, and the SSE2 square root (SSE2 is
//! part of every x86-64 CPU).
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

/// The correctly rounded square root of `x` (as IEEE 754 requires of every square root, so the
/// same bits as `libm::sqrt` and `f64::sqrt`), in an instruction encoding that suits the code
/// around it.
///
/// On x86-64, `libm::sqrt` is the legacy SSE `sqrtsd` in inline assembly, which the compiler
/// cannot re-encode. Inside [`vectorised`]'s AVX2 code each such instruction mixes the two
/// encodings, and on some CPUs that stalls every one of them: on an AMD EPYC (Zen 3) machine
/// the exact GP's EKF step took 181 us with it against about 40 us without (session 26,
/// `docs/benchmarks.md`). Here the square root is the compiler's own operation (through
/// `core::arch`), which it encodes as the code around it needs, and which a loop can
/// vectorise. Other targets use `libm::sqrt`.
#[inline(always)]
pub fn sqrt(x: f64) -> f64 {
    #[cfg(target_arch = "x86_64")]
    {
        use core::arch::x86_64::{_mm_cvtsd_f64, _mm_set_sd, _mm_sqrt_pd};
        // SAFETY: these need SSE2, which every x86-64 CPU has (it is part of the x86-64
        // baseline that every build for this architecture targets).
        unsafe { _mm_cvtsd_f64(_mm_sqrt_pd(_mm_set_sd(x))) }
    }
    #[cfg(not(target_arch = "x86_64"))]
    {
        libm::sqrt(x)
    }
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

    /// `sqrt` is the correctly rounded square root everywhere (the bits of `libm::sqrt`, which
    /// the filter used before), in the wide code as in the narrow, on ordinary, tiny, huge and
    /// special arguments.
    #[test]
    fn sqrt_gives_the_bits_of_libm_in_wide_and_narrow_code() {
        let mut args = vec![
            0.0,
            -0.0,
            f64::MIN_POSITIVE,
            f64::MIN_POSITIVE / 3.0,
            f64::MAX,
            f64::INFINITY,
            2.0,
            1e-300,
        ];
        args.extend((0..2000).map(|i| (f64::from(i) * 0.731).exp() * 1e-12 + f64::from(i) * 0.013));
        let narrow: Vec<u64> = args.iter().map(|&x| sqrt(x).to_bits()).collect();
        let wide: Vec<u64> = vectorised(|| args.iter().map(|&x| sqrt(x).to_bits()).collect());
        let reference: Vec<u64> = args.iter().map(|&x| libm::sqrt(x).to_bits()).collect();
        assert_eq!(narrow, reference);
        assert_eq!(wide, reference);
        assert!(sqrt(-1.0).is_nan() && sqrt(f64::NAN).is_nan());
    }
}
