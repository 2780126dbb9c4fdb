//! Sparse linear algebra: a symmetric positive definite solver that keeps its factorization
//! (faer's sparse Cholesky), so several right-hand sides reuse one factorization.

use faer::linalg::solvers::Solve;
use faer::sparse::{SparseColMat, Triplet};

#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum SolveError {
    #[error("sparse matrix could not be built: {0}")]
    Build(String),
    #[error("matrix is not positive definite (a mesh component with no constraint?): {0}")]
    NotPositiveDefinite(String),
}

/// A factorized sparse SPD matrix.
pub struct SpdSolver {
    n: usize,
    llt: faer::sparse::linalg::solvers::Llt<usize, f64>,
}

impl SpdSolver {
    /// Factorizes the n×n matrix given by (row, col, value) triplets; duplicates are summed.
    /// Only the lower triangle (row ≥ col) is read, so callers may pass either half or both.
    pub fn new(n: usize, triplets: &[(usize, usize, f64)]) -> Result<Self, SolveError> {
        // Sequential: faer's parallel factorization is fast but texsyn's outputs must be
        // bit-identical for any thread count, and these systems are small.
        faer::set_global_parallelism(faer::Par::Seq);
        let lower: Vec<Triplet<usize, usize, f64>> = triplets
            .iter()
            .filter(|t| t.0 >= t.1)
            .map(|&(row, col, val)| Triplet::new(row, col, val))
            .collect();
        let m = SparseColMat::<usize, f64>::try_new_from_triplets(n, n, &lower)
            .map_err(|e| SolveError::Build(format!("{e:?}")))?;
        let llt = m
            .sp_cholesky(faer::Side::Lower)
            .map_err(|e| SolveError::NotPositiveDefinite(format!("{e:?}")))?;
        Ok(SpdSolver { n, llt })
    }

    /// Solves A X = B in place for `k` right-hand sides stored column-major in `rhs`
    /// (length n·k).
    pub fn solve(&self, rhs: &mut [f64], k: usize) {
        assert_eq!(
            rhs.len(),
            self.n * k,
            "right-hand side has the wrong length"
        );
        faer::set_global_parallelism(faer::Par::Seq);
        let mat = faer::MatMut::from_column_major_slice_mut(rhs, self.n, k);
        self.llt.solve_in_place(mat);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn solves_a_tridiagonal_system_with_two_right_hand_sides() {
        // A = tridiag(-1, 2.5, -1); check A·x = b by multiplying back.
        let n = 50;
        let mut t = Vec::new();
        for i in 0..n {
            t.push((i, i, 2.5));
            if i + 1 < n {
                t.push((i + 1, i, -1.0));
                t.push((i, i + 1, -1.0));
            }
        }
        let s = SpdSolver::new(n, &t).unwrap();
        let b: Vec<f64> = (0..2 * n).map(|i| (i as f64 * 0.37).sin()).collect();
        let mut x = b.clone();
        s.solve(&mut x, 2);
        for c in 0..2 {
            for i in 0..n {
                let xi = |j: usize| x[c * n + j];
                let mut ax = 2.5 * xi(i);
                if i > 0 {
                    ax -= xi(i - 1);
                }
                if i + 1 < n {
                    ax -= xi(i + 1);
                }
                assert!((ax - b[c * n + i]).abs() < 1e-10);
            }
        }
    }

    #[test]
    fn indefinite_matrix_is_an_error() {
        let t = vec![(0, 0, 1.0), (1, 1, -1.0)];
        assert!(SpdSolver::new(2, &t).is_err());
    }
}
