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
//! What it buys is measured in `docs/performance.md`.
//!
//! It also holds [`sqrt`], the square root the core uses everywhere: `libm`'s is legacy-SSE
//! inline assembly, which stalls inside the AVX2 code on some CPUs.
//!
//! And it holds one kernel written with AVX2 intrinsics, the sparse GP's `T k`
//! (`lower_packed_times_rows4`), where the compiler's own vectorisation chooses a poor layout.
//!
//! This module holds the crate's only `unsafe` code: the calls of `#[target_feature]` functions,
//! made only after the CPU was seen to support the feature, the SSE2 square root (SSE2 is
//! part of every x86-64 CPU), and the unaligned vector loads and stores of that kernel.
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
/// the exact GP's EKF step takes about 4x longer with it. Here the square root is the
/// compiler's own operation (through `core::arch`), which it encodes as the code around it
/// needs, and which a loop can vectorise. Other targets use `libm::sqrt`.
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

/// `out = T k` for the first `4 floor(n / 4)` rows of a row-packed lower-triangular `T`
/// (`n = out.len()`), with AVX2 intrinsics when the CPU has them; returns how many rows it
/// wrote (0 without AVX2, where the caller does them all).
///
/// The rows go four at a time. Each row sums the columns before its block (a multiple of
/// four) in one four-lane accumulator, then adds the block's triangle column by column: the
/// order of `crate::gp`'s row-by-row loop, so the bits are the same (multiplications and
/// additions stay separate, never fused). The compiler's own vectorisation of that loop pairs
/// lanes across rows with shuffles, and one row at a time waits on its accumulator.
pub(crate) fn lower_packed_times_rows4(t_packed: &[f64], k: &[f64], out: &mut [f64]) -> usize {
    #[cfg(target_arch = "x86_64")]
    if avx2() {
        // SAFETY: the CPU supports AVX2 (as in `vectorised`).
        return unsafe { lower_packed_times_avx2(t_packed, k, out) };
    }
    let _ = (t_packed, k, out);
    0
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
fn lower_packed_times_avx2(t_packed: &[f64], k: &[f64], out: &mut [f64]) -> usize {
    use core::arch::x86_64::{
        __m256d, _mm256_add_pd, _mm256_hadd_pd, _mm256_loadu_pd, _mm256_mul_pd,
        _mm256_permute2f128_pd, _mm256_setzero_pd, _mm256_storeu_pd,
    };
    let row = |i: usize| crate::gp::lower_row(t_packed, i);
    // A chunk of exactly four values (what `chunks_exact(4)` yields) as one vector.
    let load = |c: &[f64]| match c.first_chunk::<4>() {
        // SAFETY: the pointer is to four readable, initialised `f64`s; the load is unaligned.
        Some(c4) => unsafe { _mm256_loadu_pd(c4.as_ptr()) },
        None => _mm256_setzero_pd(),
    };
    let mut done = 0;
    for (b, block) in out.chunks_exact_mut(4).enumerate() {
        let i = 4 * b;
        let (Some(r0), Some(r1), Some(r2), Some(r3), Some(k_head), Some(&[k0, k1, k2, k3])) = (
            row(i),
            row(i + 1),
            row(i + 2),
            row(i + 3),
            k.get(..i),
            k.get(i..).and_then(|t| t.first_chunk::<4>()),
        ) else {
            break;
        };
        let mut acc: [__m256d; 4] = [_mm256_setzero_pd(); 4];
        let it = k_head
            .chunks_exact(4)
            .zip(r0.chunks_exact(4))
            .zip(r1.chunks_exact(4))
            .zip(r2.chunks_exact(4))
            .zip(r3.chunks_exact(4));
        for ((((kc, c0), c1), c2), c3) in it {
            let kv = load(kc);
            for (a, c) in acc.iter_mut().zip([c0, c1, c2, c3]) {
                *a = _mm256_add_pd(*a, _mm256_mul_pd(load(c), kv));
            }
        }
        // Row r's (x0 + x1) + (x2 + x3), the four rows in one vector.
        let [a0, a1, a2, a3] = acc;
        let (h01, h23) = (_mm256_hadd_pd(a0, a1), _mm256_hadd_pd(a2, a3));
        let sums = _mm256_add_pd(
            _mm256_permute2f128_pd::<0x20>(h01, h23),
            _mm256_permute2f128_pd::<0x31>(h01, h23),
        );
        let mut s = [0.0f64; 4];
        // SAFETY: `s` holds four writable `f64`s; the store is unaligned.
        unsafe { _mm256_storeu_pd(s.as_mut_ptr(), sums) };
        let [s0, s1, s2, s3] = s;
        let (
            [o0, o1, o2, o3],
            [.., a00],
            [.., a10, a11],
            [.., a20, a21, a22],
            [.., a30, a31, a32, a33],
        ) = (block, r0, r1, r2, r3)
        else {
            break;
        };
        *o0 = s0 + a00 * k0;
        *o1 = (s1 + a10 * k0) + a11 * k1;
        *o2 = ((s2 + a20 * k0) + a21 * k1) + a22 * k2;
        *o3 = (((s3 + a30 * k0) + a31 * k1) + a32 * k2) + a33 * k3;
        done = i + 4;
    }
    done
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

    /// `sqrt` is the correctly rounded square root everywhere (the bits of `libm::sqrt`), in the
    /// wide code as in the narrow, on ordinary, tiny, huge and special arguments.
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
