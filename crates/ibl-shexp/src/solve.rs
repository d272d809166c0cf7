//! Dense linear least squares in f64: column equilibration, Householder QR, back substitution,
//! and the condition number from the singular values of R (one-sided Jacobi).
//!
//! Why QR and not normal equations: κ(AᵀA) = κ(A)², and the vMF damping makes high-band
//! columns small at large α; QR on the equilibrated matrix keeps the full f64 precision.

/// Result of [`least_squares`].
#[derive(Clone, Debug)]
pub struct LsSolution {
    /// One solution vector per right-hand side.
    pub x: Vec<Vec<f64>>,
    /// 2-norm condition number of the column-equilibrated matrix.
    pub condition: f64,
}

/// Minimises ‖A x − b_k‖₂ for each right-hand side b_k.
///
/// `a` is row-major m×k, `rhs` is a list of length-m vectors. Returns `None` when the system is
/// under-determined (m < k) or numerically rank deficient (a zero column or κ > 1e12).
pub fn least_squares(a: &[f64], m: usize, k: usize, rhs: &[Vec<f64>]) -> Option<LsSolution> {
    assert_eq!(a.len(), m * k);
    if m < k || k == 0 {
        return None;
    }
    // Column-major copy, equilibrated to unit column norms.
    let mut q = vec![0.0f64; m * k];
    let mut scale = vec![0.0f64; k];
    for j in 0..k {
        let mut s = 0.0;
        for i in 0..m {
            let v = a[i * k + j];
            q[j * m + i] = v;
            s += v * v;
        }
        let s = s.sqrt();
        if s == 0.0 || !s.is_finite() {
            return None;
        }
        scale[j] = s;
        for i in 0..m {
            q[j * m + i] /= s;
        }
    }
    let mut b: Vec<Vec<f64>> = rhs.to_vec();
    for bk in &b {
        assert_eq!(bk.len(), m);
    }
    // Householder QR, applying each reflector to the remaining columns and the RHS.
    let mut rdiag = vec![0.0f64; k];
    for j in 0..k {
        let col = &mut q[j * m..(j + 1) * m];
        let norm = col[j..].iter().map(|v| v * v).sum::<f64>().sqrt();
        if norm == 0.0 {
            return None;
        }
        let alpha = if col[j] > 0.0 { -norm } else { norm };
        // v = x − α e1, stored in place; ‖v‖² = 2 norm (norm + |x_j|).
        col[j] -= alpha;
        let vnorm2 = 2.0 * norm * (norm + (col[j] + alpha).abs());
        rdiag[j] = alpha;
        let (head, tail) = q.split_at_mut((j + 1) * m);
        let v = &head[j * m + j..j * m + m];
        for c in 0..(k - j - 1) {
            let w = &mut tail[c * m + j..c * m + m];
            let d: f64 = v.iter().zip(w.iter()).map(|(a, b)| a * b).sum();
            let f = 2.0 * d / vnorm2;
            for (wi, vi) in w.iter_mut().zip(v) {
                *wi -= f * vi;
            }
        }
        for bk in &mut b {
            let w = &mut bk[j..];
            let d: f64 = v.iter().zip(w.iter()).map(|(a, b)| a * b).sum();
            let f = 2.0 * d / vnorm2;
            for (wi, vi) in w.iter_mut().zip(v) {
                *wi -= f * vi;
            }
        }
    }
    // R: upper triangle of q above the diagonal, rdiag on it.
    let r_at = |i: usize, j: usize| -> f64 {
        if i == j {
            rdiag[i]
        } else {
            q[j * m + i]
        }
    };
    let mut r = vec![0.0f64; k * k];
    for i in 0..k {
        for j in i..k {
            r[i * k + j] = r_at(i, j);
        }
    }
    let sv = singular_values(&r, k);
    let smax = sv.iter().cloned().fold(0.0, f64::max);
    let smin = sv.iter().cloned().fold(f64::INFINITY, f64::min);
    let condition = if smin > 0.0 {
        smax / smin
    } else {
        f64::INFINITY
    };
    if condition.is_nan() || condition >= 1e12 {
        return None;
    }
    let x = b
        .iter()
        .map(|bk| {
            let mut x = vec![0.0f64; k];
            for i in (0..k).rev() {
                let mut s = bk[i];
                for j in i + 1..k {
                    s -= r[i * k + j] * x[j];
                }
                x[i] = s / r[i * k + i];
            }
            for j in 0..k {
                x[j] /= scale[j];
            }
            x
        })
        .collect();
    Some(LsSolution { x, condition })
}

/// Singular values of a small square matrix (row-major n×n) by one-sided Jacobi rotations.
pub(crate) fn singular_values(a: &[f64], n: usize) -> Vec<f64> {
    // Work on columns of U = A; rotate pairs until all are orthogonal.
    let mut u: Vec<f64> = a.to_vec();
    for _sweep in 0..60 {
        let mut off = 0.0f64;
        for p in 0..n {
            for qq in p + 1..n {
                let (mut alpha, mut beta, mut gamma) = (0.0, 0.0, 0.0);
                for i in 0..n {
                    let (x, y) = (u[i * n + p], u[i * n + qq]);
                    alpha += x * x;
                    beta += y * y;
                    gamma += x * y;
                }
                if gamma == 0.0 {
                    continue;
                }
                off = f64::max(off, gamma.abs() / (alpha * beta).sqrt());
                let zeta = (beta - alpha) / (2.0 * gamma);
                let t = zeta.signum() / (zeta.abs() + (1.0 + zeta * zeta).sqrt());
                let t = if zeta == 0.0 { 1.0 } else { t };
                let c = 1.0 / (1.0 + t * t).sqrt();
                let s = c * t;
                for i in 0..n {
                    let (x, y) = (u[i * n + p], u[i * n + qq]);
                    u[i * n + p] = c * x - s * y;
                    u[i * n + qq] = s * x + c * y;
                }
            }
        }
        if off < 1e-15 {
            break;
        }
    }
    (0..n)
        .map(|j| {
            (0..n)
                .map(|i| u[i * n + j] * u[i * n + j])
                .sum::<f64>()
                .sqrt()
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use ibl_core::linalg::solve_spd;
    use ibl_core::sampling::Pcg32;

    #[test]
    fn exact_systems_are_solved_to_round_off() {
        let mut rng = Pcg32::new(3, 9);
        let (m, k) = (200, 12);
        // Badly scaled columns (1e-5 … 1e3) as the vMF damping produces.
        let a: Vec<f64> = (0..m * k)
            .map(|i| (rng.next_f64() - 0.5) * 10f64.powi((i % k) as i32 / 2 - 5 + 3))
            .collect();
        let x_true: Vec<f64> = (0..k).map(|j| (j as f64 * 0.7).sin()).collect();
        let b: Vec<f64> = (0..m)
            .map(|i| (0..k).map(|j| a[i * k + j] * x_true[j]).sum())
            .collect();
        let sol = least_squares(&a, m, k, &[b]).unwrap();
        let err = sol.x[0]
            .iter()
            .zip(&x_true)
            .map(|(a, b)| (a - b).abs())
            .fold(0.0, f64::max);
        eprintln!(
            "max |x − x_true| = {err:.2e}, κ(equilibrated) = {:.1}",
            sol.condition
        );
        assert!(err < 1e-9);
    }

    #[test]
    fn overdetermined_matches_normal_equations() {
        let mut rng = Pcg32::new(4, 2);
        let (m, k) = (50, 3);
        let a: Vec<f64> = (0..m * k).map(|_| rng.next_f64()).collect();
        let b: Vec<f64> = (0..m).map(|_| rng.next_f64()).collect();
        let sol = least_squares(&a, m, k, std::slice::from_ref(&b)).unwrap();
        // The residual is orthogonal to every column.
        for j in 0..k {
            let d: f64 = (0..m)
                .map(|i| {
                    a[i * k + j] * (b[i] - (0..k).map(|c| a[i * k + c] * sol.x[0][c]).sum::<f64>())
                })
                .sum();
            assert!(d.abs() < 1e-12, "Aᵀr[{j}] = {d}");
        }
    }

    #[test]
    fn spd_solve_matches_qr_on_the_normal_equations() {
        // A badly scaled but full-rank least-squares problem: Cholesky on the equilibrated
        // normal equations agrees with QR to ~κ²·ε; a singular Gram matrix is refused.
        let (m, k) = (300, 12);
        let mut rng = Pcg32::new(5, 9);
        let a: Vec<f64> = (0..m * k)
            .map(|i| (rng.next_f64() - 0.5) * 10f64.powi((i % k) as i32 - 6))
            .collect();
        let b: Vec<f64> = (0..m).map(|_| rng.next_f64()).collect();
        let mut g = vec![0.0f64; k * k];
        let mut atb = vec![0.0f64; k];
        for r in 0..m {
            for i in 0..k {
                atb[i] += a[r * k + i] * b[r];
                for j in 0..k {
                    g[i * k + j] += a[r * k + i] * a[r * k + j];
                }
            }
        }
        let x = solve_spd(&g, &atb, k).unwrap();
        let qr = least_squares(&a, m, k, std::slice::from_ref(&b)).unwrap();
        for (j, (got, want)) in x.iter().zip(&qr.x[0]).enumerate() {
            let rel = (got - want).abs() / want.abs().max(1e-300);
            assert!(rel < 1e-8, "x[{j}]: {got} vs {want} ({rel:.1e})");
        }
        // Two equal columns: singular.
        let mut g2 = g.clone();
        for i in 0..k {
            g2[i * k + 1] = g[i * k];
            g2[k + i] = g[i];
        }
        g2[k + 1] = g[0];
        assert!(solve_spd(&g2, &atb, k).is_none());
        assert!(solve_spd(&[0.0], &[1.0], 1).is_none());
    }

    #[test]
    fn rank_deficient_and_underdetermined_are_refused() {
        let a = vec![1.0, 2.0, 2.0, 4.0, 3.0, 6.0];
        assert!(least_squares(&a, 3, 2, &[vec![1.0, 2.0, 3.0]]).is_none());
        assert!(least_squares(&[1.0, 2.0], 1, 2, &[vec![1.0]]).is_none());
        assert!(least_squares(&[0.0, 1.0, 0.0, 1.0], 2, 2, &[vec![1.0, 1.0]]).is_none());
    }

    #[test]
    fn singular_values_of_known_matrix() {
        // diag(3, 2) rotated: singular values 3 and 2.
        let (c, s) = (0.6f64, 0.8f64);
        let a = [3.0 * c, -2.0 * s, 3.0 * s, 2.0 * c];
        let mut sv = singular_values(&a, 2);
        sv.sort_by(|a, b| b.partial_cmp(a).unwrap());
        assert!(
            (sv[0] - 3.0).abs() < 1e-12 && (sv[1] - 2.0).abs() < 1e-12,
            "{sv:?}"
        );
    }
}
