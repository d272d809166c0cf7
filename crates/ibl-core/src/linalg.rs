//! Small dense linear algebra the bakes share: the symmetric positive-definite solve behind
//! least-squares fits done through their normal equations.

/// Solves the symmetric positive-definite system G x = b (row-major k×k, full) by Cholesky on
/// the Jacobi-equilibrated matrix D⁻¹GD⁻¹, D = √diag(G). Returns `None` when G is not
/// numerically positive definite (a zero diagonal, or a pivot below 1e-12 of the scaled
/// diagonal, i.e. κ of the equilibrated matrix beyond ~1e12), so callers can fall back to QR.
///
/// Why normal equations: GᵀG and Gᵀr accumulate row by row in k² work per row without storing
/// the design matrix (QR costs ~4× that and m×k memory). κ(GᵀG) = κ² of the design: fine for
/// the well-conditioned systems that use it (SH-exp Gauss–Newton steps, corrected by a line
/// search; the bilinear fit of coarse prefiltered levels, diagonally dominant).
pub fn solve_spd(g: &[f64], b: &[f64], k: usize) -> Option<Vec<f64>> {
    assert_eq!(b.len(), k);
    Some(Cholesky::new(g, k)?.solve(b))
}

/// [`solve_spd`] split in two: the factorisation of the symmetric positive-definite k×k
/// matrix G (Cholesky of D⁻¹GD⁻¹, D = √diag G) once, then any number of right-hand sides
/// (the bilinear read fit solves four per level with one matrix).
pub struct Cholesky {
    k: usize,
    d: Vec<f64>,
    l: Vec<f64>,
    /// Each row's first non-zero column (the envelope of G, which L keeps).
    first: Vec<usize>,
}

impl Cholesky {
    /// Factorises G (row-major k×k); `None` where it is not numerically positive definite
    /// (see [`solve_spd`]).
    pub fn new(g: &[f64], k: usize) -> Option<Self> {
        assert_eq!(g.len(), k * k);
        let d: Vec<f64> = (0..k).map(|i| g[i * k + i].sqrt()).collect();
        if d.iter().any(|v| v.is_nan() || *v <= 0.0 || !v.is_finite()) {
            return None;
        }
        // Lower-triangular L of the scaled matrix. L keeps G's envelope: row i of L is zero
        // before G's first non-zero column f_i (George & Liu, "Computer Solution of Large
        // Sparse Positive Definite Systems", 1981, §4.2), so the entries and products before
        // it are zeros and are skipped; the remaining sums are the same, term for term. The
        // bilinear read fit's matrices couple a texel with its neighbours only: most rows
        // start a face-row before the diagonal.
        let first: Vec<usize> = (0..k)
            .map(|i| (0..i).find(|&j| g[i * k + j] != 0.0).unwrap_or(i))
            .collect();
        let mut l = vec![0.0f64; k * k];
        for i in 0..k {
            for j in first[i]..=i {
                let mut sum = g[i * k + j] / (d[i] * d[j]);
                for p in first[i].max(first[j])..j {
                    sum -= l[i * k + p] * l[j * k + p];
                }
                if i == j {
                    if sum.is_nan() || sum <= 1e-12 {
                        return None;
                    }
                    l[i * k + i] = sum.sqrt();
                } else {
                    l[i * k + j] = sum / l[j * k + j];
                }
            }
        }
        Some(Cholesky { k, d, l, first })
    }

    /// G⁻¹b: L y = D⁻¹ b, Lᵀ z = y, x = D⁻¹ z.
    pub fn solve(&self, b: &[f64]) -> Vec<f64> {
        let (k, d, l) = (self.k, &self.d, &self.l);
        assert_eq!(b.len(), k);
        let mut y = vec![0.0f64; k];
        for i in 0..k {
            let mut sum = b[i] / d[i];
            for p in self.first[i]..i {
                sum -= l[i * k + p] * y[p];
            }
            y[i] = sum / l[i * k + i];
        }
        for i in (0..k).rev() {
            let mut sum = y[i];
            for p in i + 1..k {
                sum -= l[p * k + i] * y[p];
            }
            y[i] = sum / l[i * k + i];
        }
        y.iter().zip(d).map(|(z, di)| z / di).collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sampling::Pcg32;

    #[test]
    fn residual_of_a_random_spd_system_is_round_off() {
        // G = AᵀA + I from a random A, b random: ‖Gx − b‖ at round-off, x independent of how
        // the system is scaled (the equilibration is internal).
        let (m, k) = (40, 9);
        let mut rng = Pcg32::new(11, 3);
        let a: Vec<f64> = (0..m * k).map(|_| rng.next_f64() - 0.5).collect();
        let mut g = vec![0.0f64; k * k];
        for r in 0..m {
            for i in 0..k {
                for j in 0..k {
                    g[i * k + j] += a[r * k + i] * a[r * k + j];
                }
            }
        }
        for i in 0..k {
            g[i * k + i] += 1.0;
        }
        let b: Vec<f64> = (0..k).map(|_| rng.next_f64()).collect();
        let x = solve_spd(&g, &b, k).unwrap();
        for i in 0..k {
            let gx: f64 = (0..k).map(|j| g[i * k + j] * x[j]).sum();
            assert!((gx - b[i]).abs() < 1e-12, "row {i}: {gx} vs {}", b[i]);
        }
        let g1e6: Vec<f64> = g.iter().map(|v| v * 1e6).collect();
        let b1e6: Vec<f64> = b.iter().map(|v| v * 1e6).collect();
        let y = solve_spd(&g1e6, &b1e6, k).unwrap();
        assert!(x.iter().zip(&y).all(|(p, q)| (p - q).abs() < 1e-12));
        // Not positive definite: refused, not a NaN answer.
        assert!(solve_spd(&[1.0, 2.0, 2.0, 1.0], &[1.0, 1.0], 2).is_none());
        assert!(solve_spd(&[f64::NAN], &[1.0], 1).is_none());
    }

    #[test]
    fn the_envelope_skips_only_zeros_bit_for_bit() {
        // A sparse SPD matrix with a narrow band and a few far couplings (as a cube's face
        // edges make): the factor and the solution equal the dense algorithm's bit for bit.
        let k = 64;
        let mut rng = Pcg32::new(5, 9);
        let mut g = vec![0.0f64; k * k];
        let couple = |g: &mut Vec<f64>, i: usize, j: usize, v: f64| {
            g[i * k + j] += v;
            g[j * k + i] += v;
        };
        for i in 0..k {
            couple(&mut g, i, i, 4.0);
            if i >= 1 {
                couple(&mut g, i, i - 1, -0.5 - rng.next_f64() * 0.4);
            }
            if i >= 8 {
                couple(&mut g, i, i - 8, -0.3 * rng.next_f64());
            }
        }
        couple(&mut g, 50, 3, -0.7);
        couple(&mut g, 40, 20, -0.2);
        let dense = |g: &[f64]| -> Vec<f64> {
            let d: Vec<f64> = (0..k).map(|i| g[i * k + i].sqrt()).collect();
            let mut l = vec![0.0f64; k * k];
            for i in 0..k {
                for j in 0..=i {
                    let mut sum = g[i * k + j] / (d[i] * d[j]);
                    for p in 0..j {
                        sum -= l[i * k + p] * l[j * k + p];
                    }
                    l[i * k + j] = if i == j {
                        sum.sqrt()
                    } else {
                        sum / l[j * k + j]
                    };
                }
            }
            l
        };
        let chol = Cholesky::new(&g, k).expect("SPD");
        assert_eq!(chol.first[50], 3);
        assert_eq!(chol.first[30], 22);
        let want = dense(&g);
        for (a, b) in chol.l.iter().zip(&want) {
            assert_eq!(a.to_bits(), b.to_bits());
        }
        let b: Vec<f64> = (0..k).map(|_| rng.next_f64() - 0.5).collect();
        let x = chol.solve(&b);
        for i in 0..k {
            let gx: f64 = (0..k).map(|j| g[i * k + j] * x[j]).sum();
            assert!((gx - b[i]).abs() < 1e-12, "row {i}");
        }
    }

    #[test]
    fn one_factorisation_solves_every_right_hand_side_and_refuses_a_singular_matrix() {
        let g = [4.0, 1.0, 0.5, 1.0, 3.0, 0.2, 0.5, 0.2, 2.0];
        let chol = Cholesky::new(&g, 3).expect("SPD");
        for b in [[1.0, 0.0, 0.0], [0.3, -2.0, 5.0]] {
            let x = chol.solve(&b);
            for i in 0..3 {
                let r: f64 = (0..3).map(|j| g[i * 3 + j] * x[j]).sum::<f64>() - b[i];
                assert!(r.abs() < 1e-12, "{r}");
            }
        }
        assert!(Cholesky::new(&[1.0, 1.0, 1.0, 1.0], 2).is_none());
    }
}
