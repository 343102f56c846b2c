//! Data checks, standardisation, the Mahalanobis whitening matrix and subset selection.

use crate::GpError;
use crate::params::SubsetPolicy;
use hbn_core::rng::Rng;

/// Checks shapes and values of row-major inputs `x` (`n x dim`) and targets `y` (`n`).
pub fn check_data(x: &[f64], y: &[f64], dim: usize) -> Result<usize, GpError> {
    let n = y.len();
    if n < 2 {
        return Err(GpError::TooFewSamples { min: 2, got: n });
    }
    if x.len() != n * dim {
        return Err(GpError::Shape {
            what: "inputs (rows x dim) vs targets",
            expected: n * dim,
            got: x.len(),
        });
    }
    if let Some(i) = x.iter().position(|v| !v.is_finite()) {
        return Err(GpError::NonFinite {
            what: "inputs",
            row: i / dim,
        });
    }
    if let Some(i) = y.iter().position(|v| !v.is_finite()) {
        return Err(GpError::NonFinite {
            what: "targets",
            row: i,
        });
    }
    let (lo, hi) = y
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(l, h), &v| {
            (l.min(v), h.max(v))
        });
    if hi - lo <= 1e-12 * lo.abs().max(hi.abs()).max(1.0) {
        return Err(GpError::ConstantTargets { value: lo });
    }
    Ok(n)
}

/// Per-column mean and standard deviation (population); a constant column gets scale 1.
pub fn column_stats(x: &[f64], dim: usize) -> (Vec<f64>, Vec<f64>) {
    let n = (x.len() / dim).max(1) as f64;
    let mut mean = vec![0.0; dim];
    for row in x.chunks_exact(dim) {
        for (m, v) in mean.iter_mut().zip(row) {
            *m += v / n;
        }
    }
    let mut var = vec![0.0; dim];
    for row in x.chunks_exact(dim) {
        for j in 0..dim {
            var[j] += (row[j] - mean[j]).powi(2) / n;
        }
    }
    let scale = var
        .iter()
        .map(|v| if v.sqrt() > 1e-12 { v.sqrt() } else { 1.0 })
        .collect();
    (mean, scale)
}

/// Row-major lower-triangular `W` with `W^T W = (S + eps I)^{-1}`, `S` the covariance of `x`.
pub fn whitening(x: &[f64], dim: usize) -> Vec<f64> {
    let n = (x.len() / dim).max(1) as f64;
    let (mean, _) = column_stats(x, dim);
    let mut s = vec![0.0; dim * dim];
    for row in x.chunks_exact(dim) {
        for a in 0..dim {
            for b in 0..dim {
                s[a * dim + b] += (row[a] - mean[a]) * (row[b] - mean[b]) / n;
            }
        }
    }
    let tr = (0..dim).map(|i| s[i * dim + i]).sum::<f64>() / dim as f64;
    let eps = 1e-6 * tr.max(1e-12);
    for i in 0..dim {
        s[i * dim + i] += eps;
    }
    // Cholesky S = L L^T, then W = L^{-1} (lower triangular).
    let mut l = vec![0.0; dim * dim];
    for i in 0..dim {
        for j in 0..=i {
            let mut v = s[i * dim + j];
            for k in 0..j {
                v -= l[i * dim + k] * l[j * dim + k];
            }
            l[i * dim + j] = if i == j {
                v.max(eps).sqrt()
            } else {
                v / l[j * dim + j]
            };
        }
    }
    let mut w = vec![0.0; dim * dim];
    for c in 0..dim {
        // Solve L w_c = e_c by forward substitution.
        for i in 0..dim {
            let mut v = if i == c { 1.0 } else { 0.0 };
            for k in 0..i {
                v -= l[i * dim + k] * w[k * dim + c];
            }
            w[i * dim + c] = v / l[i * dim + i];
        }
    }
    w
}

/// Indices of at most `m` rows of `x_std` (`n x dim`) chosen by `policy`, sorted ascending.
pub fn select_subset(
    x_std: &[f64],
    dim: usize,
    m: usize,
    policy: SubsetPolicy,
    seed: u64,
) -> Vec<usize> {
    let n = x_std.len() / dim;
    if n <= m {
        return (0..n).collect();
    }
    let mut chosen = match policy {
        SubsetPolicy::Random => {
            let mut idx: Vec<usize> = (0..n).collect();
            let mut rng = Rng::new(seed ^ 0x005A_B5E7);
            for i in 0..m {
                let j = i + rng.below(n - i);
                idx.swap(i, j);
            }
            idx.truncate(m);
            idx
        }
        SubsetPolicy::FarthestPoint => farthest_points(x_std, dim, n, m),
    };
    chosen.sort_unstable();
    chosen
}

/// Greedy farthest-point sampling of `m < n` rows of `x_std` (`n x dim`): the row nearest the
/// origin first, then each time the row farthest (squared Euclidean distance) from those
/// chosen, the first such row on ties. A row at distance zero from every chosen one can be
/// chosen again once no row is farther (data with fewer than `m` distinct rows).
///
/// The distances to the chosen set are kept column by column: each round updates them with
/// the newest point and takes their maximum in one pass over contiguous columns, which the
/// compiler vectorises (run in the widest instruction set the CPU has, through
/// [`pulp::Arch::dispatch`]), then finds the first row at that maximum. Every distance is the
/// same sum in the same order as a row-by-row loop's, so the subset is the same.
fn farthest_points(x_std: &[f64], dim: usize, n: usize, m: usize) -> Vec<usize> {
    let row = |i: usize| &x_std[i * dim..i * dim + dim];
    let d2 = |a: &[f64], b: &[f64]| a.iter().zip(b).map(|(p, q)| (p - q) * (p - q)).sum::<f64>();
    // Start at the point nearest the origin (the mean of standardised data).
    let zero = vec![0.0; dim];
    let first = (0..n)
        .min_by(|&a, &b| d2(row(a), &zero).total_cmp(&d2(row(b), &zero)))
        .unwrap_or(0);
    let columns: Vec<Vec<f64>> = (0..dim)
        .map(|j| (0..n).map(|i| x_std[i * dim + j]).collect())
        .collect();
    let mut dist = vec![f64::INFINITY; n];
    let mut chosen = vec![first];
    let mut next = first;
    while chosen.len() < m {
        let far = pulp::Arch::new().dispatch(Farthest {
            columns: &columns,
            centre: row(next),
            dist: &mut dist,
        });
        // The first row at the largest distance (distances are finite: the data were checked).
        next = dist.iter().position(|&d| d == far).unwrap_or(0);
        chosen.push(next);
    }
    chosen
}

/// One round of [`farthest_points`]: `dist_i = min(dist_i, |x_i - centre|^2)` over every row,
/// returning the largest `dist_i`.
struct Farthest<'a> {
    columns: &'a [Vec<f64>],
    centre: &'a [f64],
    dist: &'a mut [f64],
}

impl pulp::WithSimd for Farthest<'_> {
    type Output = f64;

    #[inline(always)]
    fn with_simd<S: pulp::Simd>(self, _simd: S) -> f64 {
        let Farthest {
            columns,
            centre,
            dist,
        } = self;
        // Squared distances by column, in chunks of eight rows: the same sum over the inputs
        // in the same order as `(x_i - c) . (x_i - c)` row by row.
        const CHUNK: usize = 8;
        let mut lane_max = [f64::NEG_INFINITY; CHUNK];
        let n = dist.len();
        let mut start = 0;
        while start + CHUNK <= n {
            let mut acc = [0.0f64; CHUNK];
            for (col, &c) in columns.iter().zip(centre) {
                let Some(xs) = col.get(start..start + CHUNK) else {
                    break;
                };
                for (a, &x) in acc.iter_mut().zip(xs) {
                    let t = x - c;
                    *a += t * t;
                }
            }
            let Some(ds) = dist.get_mut(start..start + CHUNK) else {
                break;
            };
            for ((d, &a), mx) in ds.iter_mut().zip(&acc).zip(&mut lane_max) {
                let v = if a < *d { a } else { *d };
                *d = v;
                *mx = if v > *mx { v } else { *mx };
            }
            start += CHUNK;
        }
        let mut far = lane_max
            .iter()
            .fold(f64::NEG_INFINITY, |m, &v| if v > m { v } else { m });
        for i in start..n {
            let a = columns
                .iter()
                .zip(centre)
                .map(|(col, &c)| (col[i] - c) * (col[i] - c))
                .sum::<f64>();
            let v = if a < dist[i] { a } else { dist[i] };
            dist[i] = v;
            far = if v > far { v } else { far };
        }
        far
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn whitening_inverts_the_covariance() {
        let mut rng = Rng::new(1);
        let x: Vec<f64> = (0..300)
            .flat_map(|_| {
                let a = rng.normal();
                let b = 0.8 * a + 0.3 * rng.normal();
                [a, b, rng.normal() * 2.0]
            })
            .collect();
        let w = whitening(&x, 3);
        let w = &w;
        // Whitened data have (near) identity covariance.
        let z: Vec<f64> = x
            .chunks_exact(3)
            .flat_map(|r| {
                (0..3)
                    .map(move |i| (0..3).map(|j| w[i * 3 + j] * r[j]).sum::<f64>())
                    .collect::<Vec<_>>()
            })
            .collect();
        let (_, sd) = column_stats(&z, 3);
        for s in sd {
            assert!((s - 1.0).abs() < 1e-3, "{s}");
        }
    }

    #[test]
    fn subsets_are_deterministic_and_spread() {
        let x: Vec<f64> = (0..100).map(|i| i as f64 / 10.0).collect();
        let fp = select_subset(&x, 1, 5, SubsetPolicy::FarthestPoint, 0);
        assert_eq!(fp.len(), 5);
        assert!(
            fp.contains(&0) && fp.contains(&99),
            "extremes first: {fp:?}"
        );
        let r1 = select_subset(&x, 1, 10, SubsetPolicy::Random, 3);
        assert_eq!(r1, select_subset(&x, 1, 10, SubsetPolicy::Random, 3));
        assert_ne!(r1, select_subset(&x, 1, 10, SubsetPolicy::Random, 4));
    }

    /// The textbook greedy loop, row by row: the first row farthest from the chosen set.
    fn farthest_points_by_rows(x: &[f64], dim: usize, m: usize) -> Vec<usize> {
        let n = x.len() / dim;
        let d2 = |a: usize, b: &[f64]| -> f64 {
            let mut s = 0.0;
            for j in 0..dim {
                s += (x[a * dim + j] - b[j]) * (x[a * dim + j] - b[j]);
            }
            s
        };
        let origin = vec![0.0; dim];
        let mut first = 0;
        for i in 1..n {
            if d2(i, &origin) < d2(first, &origin) {
                first = i;
            }
        }
        let mut chosen = vec![first];
        let mut dist = vec![f64::INFINITY; n];
        while chosen.len() < m {
            let c: Vec<f64> = x[chosen[chosen.len() - 1] * dim..][..dim].to_vec();
            let mut best = 0;
            for i in 0..n {
                dist[i] = dist[i].min(d2(i, &c));
                if dist[i] > dist[best] {
                    best = i;
                }
            }
            chosen.push(best);
        }
        chosen.sort_unstable();
        chosen
    }

    #[test]
    fn farthest_points_are_the_textbook_loops_choice() {
        let mut rng = Rng::new(5);
        // Every dimension the GPs use, row counts around the eight-row chunks, and data
        // with ties: rows on a coarse grid, and fewer distinct rows than points to choose.
        for dim in 1..=8 {
            for n in [9, 64, 203, 1000] {
                let smooth: Vec<f64> = (0..n * dim).map(|_| rng.normal()).collect();
                let grid: Vec<f64> = (0..n * dim).map(|_| (rng.normal() * 2.0).round()).collect();
                let few: Vec<f64> = (0..n * dim).map(|i| ((i / dim) % 5) as f64).collect();
                for (name, x) in [("smooth", &smooth), ("grid", &grid), ("few", &few)] {
                    let m = (n / 3).max(6).min(n - 1);
                    assert_eq!(
                        select_subset(x, dim, m, SubsetPolicy::FarthestPoint, 0),
                        farthest_points_by_rows(x, dim, m),
                        "{name}: dim {dim}, n {n}, m {m}"
                    );
                }
            }
        }
    }

    #[test]
    fn bad_data_is_rejected() {
        assert!(matches!(
            check_data(&[], &[], 1),
            Err(GpError::TooFewSamples { .. })
        ));
        assert!(matches!(
            check_data(&[1.0, 2.0], &[1.0, 2.0, 3.0], 1),
            Err(GpError::Shape { .. })
        ));
        assert!(matches!(
            check_data(&[1.0, f64::NAN], &[1.0, 2.0], 1),
            Err(GpError::NonFinite { row: 1, .. })
        ));
        assert!(matches!(
            check_data(&[1.0, 2.0], &[1.0, f64::INFINITY], 1),
            Err(GpError::NonFinite { .. })
        ));
        assert!(matches!(
            check_data(&[1.0, 2.0], &[3.0, 3.0], 1),
            Err(GpError::ConstantTargets { .. })
        ));
    }
}
