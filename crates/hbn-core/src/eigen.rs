//! Eigendecomposition of a symmetric 3x3 matrix by cyclic Jacobi rotations: written out on the
//! matrix's named entries (no indexing, no panic path), a fixed bound on the sweeps, so the
//! covariance bound of the estimator step stays provably panic-free (`crates/hbn-core/nopanic`).

use nalgebra::{Matrix3, Vector3};

/// Most Jacobi sweeps (three rotations each). Cyclic Jacobi converges quadratically; a 3x3
/// matrix reaches machine precision in well under 10 sweeps.
pub const MAX_SWEEPS: usize = 32;

/// Eigenvalues and orthonormal eigenvectors (the columns) of the symmetric part of `a`:
/// `a = Q diag(values) Q^T`. `None` if an entry is not finite or the sweeps do not converge.
pub fn symmetric_eigen3(a: &Matrix3<f64>) -> Option<(Vector3<f64>, Matrix3<f64>)> {
    if !a.iter().all(|v| v.is_finite()) {
        return None;
    }
    // The working copy: the diagonal d1..d3 and the upper off-diagonal o12, o13, o23.
    let mut d = [a.m11, a.m22, a.m33];
    let (mut o12, mut o13, mut o23) = (
        0.5 * (a.m12 + a.m21),
        0.5 * (a.m13 + a.m31),
        0.5 * (a.m23 + a.m32),
    );
    let mut q = Matrix3::<f64>::identity();
    let scale = d
        .iter()
        .chain([o12, o13, o23].iter())
        .fold(0.0f64, |m, v| m.max(v.abs()));
    if scale == 0.0 {
        return Some((Vector3::zeros(), q));
    }
    for _ in 0..MAX_SWEEPS {
        let off = o12 * o12 + o13 * o13 + o23 * o23;
        if off <= (f64::EPSILON * scale) * (f64::EPSILON * scale) {
            return Some((Vector3::new(d[0], d[1], d[2]), q));
        }
        // Rotations in the planes (1,2), (1,3), (2,3).
        rotate(Plane::P12, &mut d, &mut o12, &mut o13, &mut o23, &mut q);
        rotate(Plane::P13, &mut d, &mut o12, &mut o13, &mut o23, &mut q);
        rotate(Plane::P23, &mut d, &mut o12, &mut o13, &mut o23, &mut q);
    }
    let off = o12 * o12 + o13 * o13 + o23 * o23;
    // Not converged to machine precision: accept a result good to ~1e-12 relative.
    (off <= (1e-12 * scale) * (1e-12 * scale)).then(|| (Vector3::new(d[0], d[1], d[2]), q))
}

#[derive(Clone, Copy)]
enum Plane {
    P12,
    P13,
    P23,
}

/// One Jacobi rotation zeroing the off-diagonal entry of `plane`.
fn rotate(
    plane: Plane,
    d: &mut [f64; 3],
    o12: &mut f64,
    o13: &mut f64,
    o23: &mut f64,
    q: &mut Matrix3<f64>,
) {
    // (p, q) the plane, r the third index; apq the entry to zero, apr / aqr the others.
    let [d1, d2, d3] = *d;
    let (app, aqq, apq, apr, aqr) = match plane {
        Plane::P12 => (d1, d2, *o12, *o13, *o23),
        Plane::P13 => (d1, d3, *o13, *o12, *o23),
        Plane::P23 => (d2, d3, *o23, *o12, *o13),
    };
    if apq == 0.0 {
        return;
    }
    // Classic symmetric Schur decomposition (Golub & Van Loan, Alg. 8.5.1).
    let theta = (aqq - app) / (2.0 * apq);
    let t = theta.signum() / (theta.abs() + crate::simd::sqrt(theta * theta + 1.0));
    // theta = +-inf (apq tiny): t = 0, no rotation needed.
    let t = if t.is_finite() { t } else { 0.0 };
    let c = 1.0 / crate::simd::sqrt(t * t + 1.0);
    let s = t * c;
    let new_pp = app - t * apq;
    let new_qq = aqq + t * apq;
    // The third row/column: r mixes with p and q.
    let new_pr = c * apr - s * aqr;
    let new_qr = s * apr + c * aqr;
    match plane {
        Plane::P12 => {
            *d = [new_pp, new_qq, d3];
            (*o12, *o13, *o23) = (0.0, new_pr, new_qr);
        }
        Plane::P13 => {
            *d = [new_pp, d2, new_qq];
            (*o13, *o12, *o23) = (0.0, new_pr, new_qr);
        }
        Plane::P23 => {
            *d = [d1, new_pp, new_qq];
            (*o23, *o12, *o13) = (0.0, new_pr, new_qr);
        }
    }
    // Q <- Q J: columns p and q rotate.
    let (cp, cq) = match plane {
        Plane::P12 => (q.column(0).into_owned(), q.column(1).into_owned()),
        Plane::P13 => (q.column(0).into_owned(), q.column(2).into_owned()),
        Plane::P23 => (q.column(1).into_owned(), q.column(2).into_owned()),
    };
    let new_p = cp * c - cq * s;
    let new_q = cp * s + cq * c;
    let (p_col, q_col) = match plane {
        Plane::P12 => (0, 1),
        Plane::P13 => (0, 2),
        Plane::P23 => (1, 2),
    };
    q.set_column(p_col, &new_p);
    q.set_column(q_col, &new_q);
}

/// Eigenvalues and orthonormal eigenvectors (the columns of the returned matrix) of the
/// symmetric part of the leading `n x n` block of `a` (`n <= A`), by cyclic Jacobi rotations
/// with at most [`MAX_SWEEPS`] sweeps: `a = Q diag(values) Q^T`. Entries outside the block are
/// zero in the result. `None` if an entry is not finite, `n > A`, or the sweeps do not
/// converge to about `1e-12` relative.
pub fn symmetric_eigen_n<const A: usize>(
    a: &[[f64; A]; A],
    n: usize,
) -> Option<([f64; A], [[f64; A]; A])> {
    if n > A {
        return None;
    }
    let get = |m: &[[f64; A]; A], i: usize, j: usize| -> f64 {
        m.get(i).and_then(|r| r.get(j)).copied().unwrap_or(0.0)
    };
    let mut w = [[0.0; A]; A];
    let mut q = [[0.0; A]; A];
    let mut scale = 0.0f64;
    for i in 0..n {
        for j in 0..n {
            let v = 0.5 * (get(a, i, j) + get(a, j, i));
            if !v.is_finite() {
                return None;
            }
            scale = scale.max(v.abs());
            put(&mut w, i, j, v);
        }
        put(&mut q, i, i, 1.0);
    }
    let off = |w: &[[f64; A]; A]| -> f64 {
        let mut s = 0.0;
        for i in 0..n {
            for j in (i + 1)..n {
                let v = get(w, i, j);
                s += v * v;
            }
        }
        s
    };
    let diag = |w: &[[f64; A]; A]| -> [f64; A] {
        let mut d = [0.0; A];
        for (i, di) in d.iter_mut().enumerate().take(n) {
            *di = get(w, i, i);
        }
        d
    };
    if scale == 0.0 {
        return Some((diag(&w), q));
    }
    for _ in 0..MAX_SWEEPS {
        if off(&w) <= (f64::EPSILON * scale) * (f64::EPSILON * scale) {
            return Some((diag(&w), q));
        }
        for p in 0..n {
            for r in (p + 1)..n {
                let apq = get(&w, p, r);
                if apq == 0.0 {
                    continue;
                }
                let (app, aqq) = (get(&w, p, p), get(&w, r, r));
                // Golub & Van Loan, Alg. 8.5.1 (symmetric Schur).
                let tau = (aqq - app) / (2.0 * apq);
                let t = if tau >= 0.0 {
                    1.0 / (tau + crate::simd::sqrt(1.0 + tau * tau))
                } else {
                    -1.0 / (-tau + crate::simd::sqrt(1.0 + tau * tau))
                };
                let c = 1.0 / crate::simd::sqrt(1.0 + t * t);
                let s = t * c;
                // W <- J^T W J on rows and columns p, r.
                for k in 0..n {
                    let (wkp, wkr) = (get(&w, k, p), get(&w, k, r));
                    put(&mut w, k, p, c * wkp - s * wkr);
                    put(&mut w, k, r, s * wkp + c * wkr);
                }
                for k in 0..n {
                    let (wpk, wrk) = (get(&w, p, k), get(&w, r, k));
                    put(&mut w, p, k, c * wpk - s * wrk);
                    put(&mut w, r, k, s * wpk + c * wrk);
                }
                for k in 0..n {
                    let (qkp, qkr) = (get(&q, k, p), get(&q, k, r));
                    put(&mut q, k, p, c * qkp - s * qkr);
                    put(&mut q, k, r, s * qkp + c * qkr);
                }
            }
        }
    }
    (off(&w) <= (1e-12 * scale) * (1e-12 * scale)).then(|| (diag(&w), q))
}

/// `m[i][j] = v`, ignored out of range.
#[inline(always)]
fn put<const A: usize>(m: &mut [[f64; A]; A], i: usize, j: usize, v: f64) {
    if let Some(x) = m.get_mut(i).and_then(|r| r.get_mut(j)) {
        *x = v;
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rng::Rng;
    use nalgebra::SymmetricEigen;

    fn check(a: Matrix3<f64>) {
        let (vals, q) = symmetric_eigen3(&a).expect("converges");
        let scale = a.abs().max().max(1e-300);
        // Q orthonormal, A = Q diag Q^T.
        let qtq = q.transpose() * q;
        assert!((qtq - Matrix3::identity()).abs().max() < 1e-13, "{qtq}");
        let back = q * Matrix3::from_diagonal(&vals) * q.transpose();
        assert!((back - a).abs().max() < 1e-13 * scale, "{a} vs {back}");
        // Same eigenvalues as nalgebra's solver.
        let mut ours = [vals.x, vals.y, vals.z];
        let r = SymmetricEigen::new(a).eigenvalues;
        let mut theirs = [r.x, r.y, r.z];
        ours.sort_by(f64::total_cmp);
        theirs.sort_by(f64::total_cmp);
        for (o, t) in ours.iter().zip(&theirs) {
            assert!((o - t).abs() < 1e-12 * scale, "{ours:?} vs {theirs:?}");
        }
    }

    #[test]
    fn random_symmetric_matrices() {
        let mut rng = Rng::new(5);
        for i in 0..2000 {
            let mag = 10f64.powi(i % 21 - 10);
            let b = Matrix3::from_fn(|_, _| rng.normal() * mag);
            check(b + b.transpose());
            // Covariance-like: positive semi-definite, often near singular.
            let c = b * b.transpose();
            check(c);
        }
    }

    #[test]
    fn repeated_zero_and_diagonal_eigenvalues() {
        check(Matrix3::identity());
        check(Matrix3::zeros());
        check(Matrix3::from_diagonal(&Vector3::new(3.0, -1.0, 3.0)));
        // Rank one: eigenvalues 0, 0, |v|^2.
        let v = Vector3::new(1.0, 2.0, -2.0);
        check(v * v.transpose());
        // The estimator's first covariance: [[v, v, 0], [v, v, 0], [0, 0, r]].
        check(Matrix3::new(2.0, 2.0, 0.0, 2.0, 2.0, 0.0, 0.0, 0.0, 1e-6));
        // Entries far apart in magnitude.
        check(Matrix3::new(
            1e8, 1e-3, 0.0, 1e-3, 1e-8, 1e-9, 0.0, 1e-9, 1.0,
        ));
    }

    #[test]
    fn non_finite_input_gives_none() {
        let mut a = Matrix3::identity();
        a.m23 = f64::NAN;
        assert!(symmetric_eigen3(&a).is_none());
        a.m23 = f64::INFINITY;
        assert!(symmetric_eigen3(&a).is_none());
    }
}
