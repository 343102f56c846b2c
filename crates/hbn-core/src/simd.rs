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
//! And it holds the kernels written with AVX2 intrinsics, where the compiler's own
//! vectorisation chooses a poor layout: the sparse GP's `T k` (`lower_packed_times_rows4`), and
//! the sums over rows of features of the vector filter's kernel pass, the squared distances
//! (`sq_dists_rows4`) and the mean gradient's weighted differences (`weighted_diffs`), and its
//! sparse variance `|R k|^2` (`lower_packed_norm2_rows4`). Each adds its terms in the order of
//! a plain loop that runs without AVX2, so the bits are the same either way.
//!
//! This module holds the crate's only `unsafe` code: the calls of `#[target_feature]` functions,
//! made only after the CPU was seen to support the feature, the SSE2 square root (SSE2 is
//! part of every x86-64 CPU), and the unaligned (or masked) vector loads and stores of those
//! kernels.
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
/// The rows go in blocks of four, two blocks at a time (eight independent sums). Each row
/// sums the columns before its block (a multiple of four) in one four-lane accumulator, then
/// adds the block's triangle column by column: the order of `crate::gp`'s row-by-row loop, so
/// the bits are the same (multiplications and additions stay separate, never fused). The
/// compiler's own vectorisation of that loop pairs lanes across rows with shuffles, and one
/// row at a time waits on its accumulator.
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
    // A chunk of exactly four values (what `as_chunks` yields) as one vector.
    let load = |c: &[f64; 4]| {
        // SAFETY: the pointer is to four readable, initialised `f64`s; the load is unaligned.
        unsafe { _mm256_loadu_pd(c.as_ptr()) }
    };
    fn heads(r: &[f64], i: usize) -> &[[f64; 4]] {
        r.get(..i).unwrap_or(&[]).as_chunks::<4>().0
    }
    fn chunk(r: &[f64], i: usize) -> Option<&[f64; 4]> {
        r.get(i..).and_then(|t| t.first_chunk::<4>())
    }
    // The block of rows `i..i + 4` (`i` a multiple of four), from the sums of their first `i`
    // columns in the lanes of `acc` (one vector per row): row r's (x0 + x1) + (x2 + x3), then
    // the block's triangle column by column.
    let finish = |acc: [__m256d; 4], rs: [&[f64]; 4], kb: &[f64; 4], block: &mut [f64]| {
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
        let [k0, k1, k2, k3] = *kb;
        if let (
            Some([o0, o1, o2, o3]),
            [.., a00],
            [.., a10, a11],
            [.., a20, a21, a22],
            [.., a30, a31, a32, a33],
        ) = (block.first_chunk_mut::<4>(), rs[0], rs[1], rs[2], rs[3])
        {
            *o0 = s0 + a00 * k0;
            *o1 = (s1 + a10 * k0) + a11 * k1;
            *o2 = ((s2 + a20 * k0) + a21 * k1) + a22 * k2;
            *o3 = (((s3 + a30 * k0) + a31 * k1) + a32 * k2) + a33 * k3;
        }
    };
    let kb = |i: usize| k.get(i..).and_then(|t| t.first_chunk::<4>());
    let mut i = 0;
    // Two blocks of four rows at a time (eight independent sums), the chunks of columns the
    // two share first, then the one more of the second block.
    while i + 8 <= out.len() {
        let (Some(r0), Some(r1), Some(r2), Some(r3), Some(r4), Some(r5), Some(r6), Some(r7)) = (
            row(i),
            row(i + 1),
            row(i + 2),
            row(i + 3),
            row(i + 4),
            row(i + 5),
            row(i + 6),
            row(i + 7),
        ) else {
            return i;
        };
        let (Some(ka), Some(kb4), Some(k_head)) = (kb(i), kb(i + 4), k.get(..i)) else {
            return i;
        };
        let mut acc: [__m256d; 8] = [_mm256_setzero_pd(); 8];
        let it = k_head
            .as_chunks::<4>()
            .0
            .iter()
            .zip(heads(r0, i).iter().zip(heads(r1, i)))
            .zip(heads(r2, i).iter().zip(heads(r3, i)))
            .zip(heads(r4, i).iter().zip(heads(r5, i)))
            .zip(heads(r6, i).iter().zip(heads(r7, i)));
        for ((((kc, (c0, c1)), (c2, c3)), (c4, c5)), (c6, c7)) in it {
            let kv = load(kc);
            for (a, c) in acc.iter_mut().zip([c0, c1, c2, c3, c4, c5, c6, c7]) {
                *a = _mm256_add_pd(*a, _mm256_mul_pd(load(c), kv));
            }
        }
        // Columns `i..i + 4`: a whole chunk for the second block's rows.
        let [a0, a1, a2, a3, mut a4, mut a5, mut a6, mut a7] = acc;
        if let (Some(c4), Some(c5), Some(c6), Some(c7)) =
            (chunk(r4, i), chunk(r5, i), chunk(r6, i), chunk(r7, i))
        {
            let kv = load(ka);
            a4 = _mm256_add_pd(a4, _mm256_mul_pd(load(c4), kv));
            a5 = _mm256_add_pd(a5, _mm256_mul_pd(load(c5), kv));
            a6 = _mm256_add_pd(a6, _mm256_mul_pd(load(c6), kv));
            a7 = _mm256_add_pd(a7, _mm256_mul_pd(load(c7), kv));
        }
        let (lo, hi) = out
            .get_mut(i..i + 8)
            .and_then(|b| b.split_at_mut_checked(4))
            .unwrap_or((&mut [], &mut []));
        finish([a0, a1, a2, a3], [r0, r1, r2, r3], ka, lo);
        finish([a4, a5, a6, a7], [r4, r5, r6, r7], kb4, hi);
        i += 8;
    }
    if i + 4 <= out.len() {
        let (Some(r0), Some(r1), Some(r2), Some(r3), Some(ka), Some(k_head)) = (
            row(i),
            row(i + 1),
            row(i + 2),
            row(i + 3),
            kb(i),
            k.get(..i),
        ) else {
            return i;
        };
        let mut acc: [__m256d; 4] = [_mm256_setzero_pd(); 4];
        let it = k_head
            .as_chunks::<4>()
            .0
            .iter()
            .zip(heads(r0, i).iter().zip(heads(r1, i)))
            .zip(heads(r2, i).iter().zip(heads(r3, i)));
        for ((kc, (c0, c1)), (c2, c3)) in it {
            let kv = load(kc);
            for (a, c) in acc.iter_mut().zip([c0, c1, c2, c3]) {
                *a = _mm256_add_pd(*a, _mm256_mul_pd(load(c), kv));
            }
        }
        finish(
            acc,
            [r0, r1, r2, r3],
            ka,
            out.get_mut(i..i + 4).unwrap_or(&mut []),
        );
        i += 4;
    }
    i
}

/// `crate::gp::lower_packed_norm2` for the rows in full blocks of four, with AVX2 intrinsics
/// when the CPU has them: how many rows it did (a multiple of four; 0 without AVX2, where the
/// caller does them all) and the four lane sums of their squares.
///
/// Each row is one vector of four sums (lane `l` the columns `4 c + l`), its diagonal chunk a
/// masked load (zeros past the row's end); the four rows of a block reduce to one vector of
/// their sums, each `(x0 + x1) + (x2 + x3)`, whose squares add to the lanes of the result:
/// the order of the plain loop, so the bits are the same. Two blocks go at once.
pub(crate) fn lower_packed_norm2_rows4(t_packed: &[f64], k: &[f64]) -> (usize, [f64; 4]) {
    #[cfg(target_arch = "x86_64")]
    if avx2() {
        // SAFETY: the CPU supports AVX2 (as in `vectorised`).
        return unsafe { lower_packed_norm2_avx2(t_packed, k) };
    }
    let _ = (t_packed, k);
    (0, [0.0; 4])
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
fn lower_packed_norm2_avx2(t_packed: &[f64], k: &[f64]) -> (usize, [f64; 4]) {
    use core::arch::x86_64::{
        __m256d, __m256i, _mm256_add_pd, _mm256_hadd_pd, _mm256_loadu_pd, _mm256_maskload_pd,
        _mm256_mul_pd, _mm256_permute2f128_pd, _mm256_set_epi64x, _mm256_setzero_pd,
        _mm256_storeu_pd,
    };
    fn heads(r: &[f64], i: usize) -> &[[f64; 4]] {
        r.get(..i).unwrap_or(&[]).as_chunks::<4>().0
    }
    let row = |i: usize| crate::gp::lower_row(t_packed, i);
    let load = |c: &[f64; 4]| {
        // SAFETY: the pointer is to four readable, initialised `f64`s; the load is unaligned.
        unsafe { _mm256_loadu_pd(c.as_ptr()) }
    };
    // Lanes `0..=j` of each diagonal chunk belong to row `4 b + j`.
    let masks: [__m256i; 4] = [
        _mm256_set_epi64x(0, 0, 0, -1),
        _mm256_set_epi64x(0, 0, -1, -1),
        _mm256_set_epi64x(0, -1, -1, -1),
        _mm256_set_epi64x(-1, -1, -1, -1),
    ];
    // Row `i`'s entries from column `c` on (`j + 1` of them for row `4 b + j`, `c = 4 b`),
    // zeros in the other lanes.
    let diag = |r: &[f64], c: usize, mask: __m256i| -> __m256d {
        match r.get(c..) {
            // SAFETY: the mask loads lanes `0..=j` only, and the row holds those `j + 1`
            // values from column `c` on; the other lanes are not read.
            Some(t) if !t.is_empty() => unsafe { _mm256_maskload_pd(t.as_ptr(), mask) },
            _ => _mm256_setzero_pd(),
        }
    };
    // The four rows' sums, one per lane, each (x0 + x1) + (x2 + x3).
    let reduce = |a: [__m256d; 4]| -> __m256d {
        let (h01, h23) = (_mm256_hadd_pd(a[0], a[1]), _mm256_hadd_pd(a[2], a[3]));
        _mm256_add_pd(
            _mm256_permute2f128_pd::<0x20>(h01, h23),
            _mm256_permute2f128_pd::<0x31>(h01, h23),
        )
    };
    let kc = |c: usize| k.get(c..).and_then(|t| t.first_chunk::<4>());
    let n = k.len();
    let mut sq = _mm256_setzero_pd();
    let mut i = 0;
    let finish = |sq: __m256d| {
        let mut out = [0.0f64; 4];
        // SAFETY: `out` holds four writable `f64`s; the store is unaligned.
        unsafe { _mm256_storeu_pd(out.as_mut_ptr(), sq) };
        out
    };
    // Two blocks of four rows at a time: eight independent sums.
    while i + 8 <= n {
        let (Some(r0), Some(r1), Some(r2), Some(r3), Some(r4), Some(r5), Some(r6), Some(r7)) = (
            row(i),
            row(i + 1),
            row(i + 2),
            row(i + 3),
            row(i + 4),
            row(i + 5),
            row(i + 6),
            row(i + 7),
        ) else {
            return (i, finish(sq));
        };
        let (Some(ka), Some(kb), Some(k_head)) = (kc(i), kc(i + 4), k.get(..i)) else {
            return (i, finish(sq));
        };
        let mut acc: [__m256d; 8] = [_mm256_setzero_pd(); 8];
        let it = k_head
            .as_chunks::<4>()
            .0
            .iter()
            .zip(heads(r0, i).iter().zip(heads(r1, i)))
            .zip(heads(r2, i).iter().zip(heads(r3, i)))
            .zip(heads(r4, i).iter().zip(heads(r5, i)))
            .zip(heads(r6, i).iter().zip(heads(r7, i)));
        for ((((kv, (c0, c1)), (c2, c3)), (c4, c5)), (c6, c7)) in it {
            let kv = load(kv);
            for (a, c) in acc.iter_mut().zip([c0, c1, c2, c3, c4, c5, c6, c7]) {
                *a = _mm256_add_pd(*a, _mm256_mul_pd(load(c), kv));
            }
        }
        let [a0, a1, a2, a3, a4, a5, a6, a7] = acc;
        // Columns `i..i + 4`: the first block's diagonal chunk, a whole chunk of the second's.
        let kv = load(ka);
        let first = [r0, r1, r2, r3];
        let mut lo = [a0, a1, a2, a3];
        for ((a, r), mask) in lo.iter_mut().zip(first).zip(masks) {
            *a = _mm256_add_pd(*a, _mm256_mul_pd(diag(r, i, mask), kv));
        }
        let second = [r4, r5, r6, r7];
        let mut hi = [a4, a5, a6, a7];
        for (a, r) in hi.iter_mut().zip(second) {
            let c = r.get(i..).and_then(|t| t.first_chunk::<4>());
            if let Some(c) = c {
                *a = _mm256_add_pd(*a, _mm256_mul_pd(load(c), kv));
            }
        }
        // Columns `i + 4..i + 8`: the second block's diagonal chunk.
        let kv = load(kb);
        for ((a, r), mask) in hi.iter_mut().zip(second).zip(masks) {
            *a = _mm256_add_pd(*a, _mm256_mul_pd(diag(r, i + 4, mask), kv));
        }
        let (v_lo, v_hi) = (reduce(lo), reduce(hi));
        sq = _mm256_add_pd(sq, _mm256_mul_pd(v_lo, v_lo));
        sq = _mm256_add_pd(sq, _mm256_mul_pd(v_hi, v_hi));
        i += 8;
    }
    if i + 4 <= n {
        let (Some(r0), Some(r1), Some(r2), Some(r3), Some(ka), Some(k_head)) = (
            row(i),
            row(i + 1),
            row(i + 2),
            row(i + 3),
            kc(i),
            k.get(..i),
        ) else {
            return (i, finish(sq));
        };
        let mut acc: [__m256d; 4] = [_mm256_setzero_pd(); 4];
        let it = k_head
            .as_chunks::<4>()
            .0
            .iter()
            .zip(heads(r0, i).iter().zip(heads(r1, i)))
            .zip(heads(r2, i).iter().zip(heads(r3, i)));
        for ((kv, (c0, c1)), (c2, c3)) in it {
            let kv = load(kv);
            for (a, c) in acc.iter_mut().zip([c0, c1, c2, c3]) {
                *a = _mm256_add_pd(*a, _mm256_mul_pd(load(c), kv));
            }
        }
        let kv = load(ka);
        for ((a, r), mask) in acc.iter_mut().zip([r0, r1, r2, r3]).zip(masks) {
            *a = _mm256_add_pd(*a, _mm256_mul_pd(diag(r, i, mask), kv));
        }
        let v = reduce(acc);
        sq = _mm256_add_pd(sq, _mm256_mul_pd(v, v));
        i += 4;
    }
    (i, finish(sq))
}

/// Squared distances of `width`-wide rows to `u`, `r2[i] = sum_j (rows[i width + j] - u[j])^2`,
/// for the first `4 floor(r2.len() / 4)` rows, with AVX2 intrinsics when the CPU has them;
/// returns how many rows it wrote (0 without AVX2, where the caller does them all).
///
/// Four rows go at once, one per lane: a 4 x 4 block of the rows is transposed in registers
/// (two 128-bit loads and two unpacks per pair of columns) and each lane sums its row's squares
/// in column order, the order of `crate::gp`'s row-by-row loop, so the bits are the same.
pub(crate) fn sq_dists_rows4(rows: &[f64], width: usize, u: &[f64], r2: &mut [f64]) -> usize {
    #[cfg(target_arch = "x86_64")]
    if avx2() {
        // SAFETY: the CPU supports AVX2 (as in `vectorised`).
        return unsafe { sq_dists_avx2(rows, width, u, r2) };
    }
    let _ = (rows, width, u, r2);
    0
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
fn sq_dists_avx2(rows: &[f64], width: usize, u: &[f64], r2: &mut [f64]) -> usize {
    use core::arch::x86_64::{
        __m256d, _mm_loadu_pd, _mm256_add_pd, _mm256_castpd128_pd256, _mm256_insertf128_pd,
        _mm256_mul_pd, _mm256_set_pd, _mm256_set1_pd, _mm256_setzero_pd, _mm256_storeu_pd,
        _mm256_sub_pd, _mm256_unpackhi_pd, _mm256_unpacklo_pd,
    };
    let Some(u) = u.get(..width).filter(|_| width > 0) else {
        return 0;
    };
    let (u_heads, u_tail) = u.as_chunks::<4>();
    // `[lo[k], lo[k + 1], hi[k], hi[k + 1]]`, `k` 0 or 2.
    let pair = |lo: &[f64; 4], hi: &[f64; 4], k: usize| -> __m256d {
        let k = k & 2;
        // SAFETY: `k + 1 < 4`: each pointer is to two readable, initialised `f64`s of a
        // four-value array; the loads are unaligned.
        unsafe {
            _mm256_insertf128_pd::<1>(
                _mm256_castpd128_pd256(_mm_loadu_pd(lo.as_ptr().add(k))),
                _mm_loadu_pd(hi.as_ptr().add(k)),
            )
        }
    };
    // Four rows' columns `4 c..4 c + 4` (`x[r]` of row `r`), one column per vector.
    let columns = |x: [&[f64; 4]; 4]| -> [__m256d; 4] {
        let (t0, t1) = (pair(x[0], x[2], 0), pair(x[1], x[3], 0));
        let (t2, t3) = (pair(x[0], x[2], 2), pair(x[1], x[3], 2));
        [
            _mm256_unpacklo_pd(t0, t1),
            _mm256_unpackhi_pd(t0, t1),
            _mm256_unpacklo_pd(t2, t3),
            _mm256_unpackhi_pd(t2, t3),
        ]
    };
    // Four rows' column `j` of their tails (past the last full chunk).
    let column = |t: [&[f64]; 4], j: usize| -> __m256d {
        let at = |r: &[f64]| r.get(j).copied().unwrap_or(0.0);
        _mm256_set_pd(at(t[3]), at(t[2]), at(t[1]), at(t[0]))
    };
    let square_add = |acc: __m256d, col: __m256d, uj: f64| -> __m256d {
        let d = _mm256_sub_pd(col, _mm256_set1_pd(uj));
        _mm256_add_pd(acc, _mm256_mul_pd(d, d))
    };
    let store = |o: &mut [f64], v: __m256d| {
        if let Some(o) = o.first_chunk_mut::<4>() {
            // SAFETY: `o` holds four writable `f64`s; the store is unaligned.
            unsafe { _mm256_storeu_pd(o.as_mut_ptr(), v) };
        }
    };
    let mut rows = rows.chunks_exact(width.max(1)).map(|r| r.as_chunks::<4>());
    let mut done = 0;
    // Two blocks of four rows at a time, their columns interleaved: two independent chains of
    // additions.
    while done + 8 <= r2.len() {
        let (Some(a0), Some(a1), Some(a2), Some(a3), Some(b0), Some(b1), Some(b2), Some(b3)) = (
            rows.next(),
            rows.next(),
            rows.next(),
            rows.next(),
            rows.next(),
            rows.next(),
            rows.next(),
            rows.next(),
        ) else {
            return done;
        };
        let (mut acc_a, mut acc_b) = (_mm256_setzero_pd(), _mm256_setzero_pd());
        let chunks =
            a0.0.iter()
                .zip(a1.0)
                .zip(a2.0.iter().zip(a3.0))
                .zip(b0.0.iter().zip(b1.0).zip(b2.0.iter().zip(b3.0)))
                .zip(u_heads);
        for ((((x0, x1), (x2, x3)), ((y0, y1), (y2, y3))), uc) in chunks {
            let (ca, cb) = (columns([x0, x1, x2, x3]), columns([y0, y1, y2, y3]));
            for ((ca, cb), uj) in ca.into_iter().zip(cb).zip(uc) {
                acc_a = square_add(acc_a, ca, *uj);
                acc_b = square_add(acc_b, cb, *uj);
            }
        }
        for (j, uj) in u_tail.iter().enumerate() {
            acc_a = square_add(acc_a, column([a0.1, a1.1, a2.1, a3.1], j), *uj);
            acc_b = square_add(acc_b, column([b0.1, b1.1, b2.1, b3.1], j), *uj);
        }
        store(r2.get_mut(done..).unwrap_or(&mut []), acc_a);
        store(r2.get_mut(done + 4..).unwrap_or(&mut []), acc_b);
        done += 8;
    }
    if done + 4 <= r2.len()
        && let (Some(a0), Some(a1), Some(a2), Some(a3)) =
            (rows.next(), rows.next(), rows.next(), rows.next())
    {
        let mut acc = _mm256_setzero_pd();
        let chunks =
            a0.0.iter()
                .zip(a1.0)
                .zip(a2.0.iter().zip(a3.0))
                .zip(u_heads);
        for (((x0, x1), (x2, x3)), uc) in chunks {
            for (col, uj) in columns([x0, x1, x2, x3]).into_iter().zip(uc) {
                acc = square_add(acc, col, *uj);
            }
        }
        for (j, uj) in u_tail.iter().enumerate() {
            acc = square_add(acc, column([a0.1, a1.1, a2.1, a3.1], j), *uj);
        }
        store(r2.get_mut(done..).unwrap_or(&mut []), acc);
        done += 4;
    }
    done
}

/// `g[j] += (s0[j] + s1[j]) + (s2[j] + s3[j])` for the columns `j < cols` (`cols <= width`),
/// where `s_p[j]` sums `w[i] (rows[i width + j] - u[j])` over the rows `i < w.len()` with
/// `i mod 4 = p`, in row order: four independent sums per column instead of one chain. With
/// AVX2 intrinsics when the CPU has them (the columns four to a register, the last few in a
/// masked one), else [`weighted_diffs_plain`]: the same bits either way.
pub(crate) fn weighted_diffs(
    rows: &[f64],
    width: usize,
    cols: usize,
    u: &[f64],
    w: &[f64],
    g: &mut [f64],
) {
    #[cfg(target_arch = "x86_64")]
    if avx2() {
        // SAFETY (every arm): the CPU supports AVX2 (as in `vectorised`).
        let done = unsafe {
            match cols / 4 {
                0 => weighted_diffs_avx2::<0>(rows, width, cols, u, w, g),
                1 => weighted_diffs_avx2::<1>(rows, width, cols, u, w, g),
                2 => weighted_diffs_avx2::<2>(rows, width, cols, u, w, g),
                3 => weighted_diffs_avx2::<3>(rows, width, cols, u, w, g),
                4 => weighted_diffs_avx2::<4>(rows, width, cols, u, w, g),
                5 => weighted_diffs_avx2::<5>(rows, width, cols, u, w, g),
                6 => weighted_diffs_avx2::<6>(rows, width, cols, u, w, g),
                7 => weighted_diffs_avx2::<7>(rows, width, cols, u, w, g),
                8 => weighted_diffs_avx2::<8>(rows, width, cols, u, w, g),
                _ => false,
            }
        };
        if done {
            return;
        }
    }
    weighted_diffs_plain(rows, width, cols, u, w, g);
}

/// [`weighted_diffs`] one value at a time, in its order.
pub(crate) fn weighted_diffs_plain(
    rows: &[f64],
    width: usize,
    cols: usize,
    u: &[f64],
    w: &[f64],
    g: &mut [f64],
) {
    let mut parts = [[0.0; crate::kernel::MAX_DIM]; 4];
    for (i, (row, wi)) in rows.chunks_exact(width.max(1)).zip(w).enumerate() {
        if let Some(part) = parts.get_mut(i % 4) {
            for ((s, r), uj) in part.iter_mut().zip(row).zip(u).take(cols) {
                *s += wi * (r - uj);
            }
        }
    }
    let [s0, s1, s2, s3] = &parts;
    let sums = s0.iter().zip(s1).zip(s2.iter().zip(s3));
    for (gj, ((a, b), (c, d))) in g.iter_mut().zip(sums).take(cols) {
        *gj += (a + b) + (c + d);
    }
}

/// [`weighted_diffs`] for `CH = floor(cols / 4)` groups of four columns.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
fn weighted_diffs_avx2<const CH: usize>(
    rows: &[f64],
    width: usize,
    cols: usize,
    u: &[f64],
    w: &[f64],
    g: &mut [f64],
) -> bool {
    use core::arch::x86_64::{
        __m256d, __m256i, _mm256_add_pd, _mm256_loadu_pd, _mm256_maskload_pd, _mm256_maskstore_pd,
        _mm256_mul_pd, _mm256_set_epi64x, _mm256_set1_pd, _mm256_setzero_pd, _mm256_storeu_pd,
        _mm256_sub_pd,
    };
    let heads = 4 * CH;
    let (Some(u), Some(g)) = (u.get(..cols), g.get_mut(..cols)) else {
        return false;
    };
    if width == 0 || cols > width || heads > cols || rows.len() / width.max(1) < w.len() {
        return false;
    }
    let load = |c: &[f64]| match c.first_chunk::<4>() {
        // SAFETY: the pointer is to four readable, initialised `f64`s; the load is unaligned.
        Some(c4) => unsafe { _mm256_loadu_pd(c4.as_ptr()) },
        None => _mm256_setzero_pd(),
    };
    let (Some((g_head, g_tail)), Some((u_head, u_tail))) =
        (g.split_at_mut_checked(heads), u.split_at_checked(heads))
    else {
        return false;
    };
    // The last `cols - heads` (0 to 3) columns in the low lanes of one more register: masked
    // loads and stores touch those lanes only.
    let tail = g_tail.len().min(u_tail.len());
    let lane = |l: usize| if l < tail { -1 } else { 0 };
    let mask: __m256i = _mm256_set_epi64x(lane(3), lane(2), lane(1), lane(0));
    let load_tail = |c: &[f64]| {
        if c.len() >= tail && tail > 0 {
            // SAFETY: the lanes the mask loads are the first `tail` values of `c`, which it
            // holds; the others are not read.
            unsafe { _mm256_maskload_pd(c.as_ptr(), mask) }
        } else {
            _mm256_setzero_pd()
        }
    };
    let mut uv: [__m256d; CH] = [_mm256_setzero_pd(); CH];
    for (v, uc) in uv.iter_mut().zip(u_head.chunks_exact(4)) {
        *v = load(uc);
    }
    let u_tail = load_tail(u_tail);
    // One of the four partial sums: its head registers and its tail register.
    type Part<const CH: usize> = ([__m256d; CH], __m256d);
    let add_row = |part: &mut Part<CH>, row: &[f64], wi: f64| {
        let wv = _mm256_set1_pd(wi);
        let (r_head, r_tail) = row.split_at_checked(heads).unwrap_or((row, &[]));
        for ((a, v), rc) in part.0.iter_mut().zip(&uv).zip(r_head.chunks_exact(4)) {
            *a = _mm256_add_pd(*a, _mm256_mul_pd(wv, _mm256_sub_pd(load(rc), *v)));
        }
        if tail > 0 {
            let d = _mm256_sub_pd(load_tail(r_tail), u_tail);
            part.1 = _mm256_add_pd(part.1, _mm256_mul_pd(wv, d));
        }
    };
    let zero: Part<CH> = ([_mm256_setzero_pd(); CH], _mm256_setzero_pd());
    let (mut p0, mut p1, mut p2, mut p3) = (zero, zero, zero, zero);
    let mut it = rows.chunks_exact(width.max(1)).zip(w);
    // Rows four at a time, row `i` to sum `i mod 4`.
    while let Some((r0, w0)) = it.next() {
        add_row(&mut p0, r0, *w0);
        let Some((r1, w1)) = it.next() else { break };
        add_row(&mut p1, r1, *w1);
        let Some((r2, w2)) = it.next() else { break };
        add_row(&mut p2, r2, *w2);
        let Some((r3, w3)) = it.next() else { break };
        add_row(&mut p3, r3, *w3);
    }
    let total = |a: __m256d, b: __m256d, c: __m256d, d: __m256d| {
        _mm256_add_pd(_mm256_add_pd(a, b), _mm256_add_pd(c, d))
    };
    let heads_sums = p0.0.iter().zip(&p1.0).zip(p2.0.iter().zip(&p3.0));
    for (((a, b), (c, d)), gc) in heads_sums.zip(g_head.chunks_exact_mut(4)) {
        if let Some(o) = gc.first_chunk_mut::<4>() {
            let sum = _mm256_add_pd(load(o), total(*a, *b, *c, *d));
            // SAFETY: `o` holds four writable `f64`s; the store is unaligned.
            unsafe { _mm256_storeu_pd(o.as_mut_ptr(), sum) };
        }
    }
    if tail > 0 && g_tail.len() >= tail {
        let sum = _mm256_add_pd(load_tail(g_tail), total(p0.1, p1.1, p2.1, p3.1));
        // SAFETY: the lanes the mask stores are the first `tail` values of `g_tail`, which it
        // holds; the others are not written.
        unsafe { _mm256_maskstore_pd(g_tail.as_mut_ptr(), mask, sum) };
    }
    true
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

    /// Values of very different sizes, so that a sum in another order would differ.
    fn wild(len: usize, seed: f64) -> Vec<f64> {
        (0..len)
            .map(|i| {
                let x = i as f64 + seed;
                (x * 0.731).sin() * 10f64.powi((i % 13) as i32 - 6)
            })
            .collect()
    }

    /// The four-row squared distances and the four-column weighted sums give the bits of the
    /// plain loops of their order, at every width up to 32, for row counts that leave a
    /// remainder.
    #[test]
    fn row_and_column_blocks_give_the_bits_of_the_plain_loops() {
        for width in 1..=32 {
            for n in [1, 4, 7, 16] {
                let rows = wild(n * width, 0.3);
                let u = wild(width, 7.1);
                let w = wild(n, 2.9);
                let mut want = vec![0.0; n];
                for (r2, row) in want.iter_mut().zip(rows.chunks_exact(width)) {
                    let mut acc = 0.0;
                    for (r, u) in row.iter().zip(&u) {
                        let d = r - u;
                        acc += d * d;
                    }
                    *r2 = acc;
                }
                let mut got = vec![f64::NAN; n];
                let done = sq_dists_rows4(&rows, width, &u, &mut got);
                assert_eq!(done, if avx2() { n - n % 4 } else { 0 });
                for (g, w) in got.iter().zip(&want).take(done) {
                    assert_eq!(g.to_bits(), w.to_bits(), "width {width}, {n} rows");
                }
                for cols in [width, width / 2, width.min(4)] {
                    let start = wild(cols, 5.5);
                    let mut parts = vec![vec![0.0; cols]; 4];
                    for (i, (row, wi)) in rows.chunks_exact(width).zip(&w).enumerate() {
                        for ((g, r), uj) in parts[i % 4].iter_mut().zip(row).zip(&u) {
                            *g += wi * (r - uj);
                        }
                    }
                    let want_g: Vec<f64> = (0..cols)
                        .map(|j| {
                            start[j] + ((parts[0][j] + parts[1][j]) + (parts[2][j] + parts[3][j]))
                        })
                        .collect();
                    let bits = |v: &[f64]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
                    let mut got_g = start.clone();
                    weighted_diffs(&rows, width, cols, &u, &w, &mut got_g);
                    assert_eq!(bits(&got_g), bits(&want_g), "width {width}, {cols} columns");
                    let mut plain = start.clone();
                    weighted_diffs_plain(&rows, width, cols, &u, &w, &mut plain);
                    assert_eq!(bits(&plain), bits(&want_g), "width {width}, {cols} columns");
                }
            }
        }
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
