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

/// The lower triangle (row ≥ col) of the n×n matrix given by triplets, duplicates summed;
/// with `full_diagonal`, every diagonal entry is in the pattern even when no triplet names it.
fn lower_matrix(
    n: usize,
    triplets: &[(usize, usize, f64)],
    full_diagonal: bool,
) -> Result<SparseColMat<usize, f64>, SolveError> {
    let diagonal = (0..if full_diagonal { n } else { 0 }).map(|i| Triplet::new(i, i, 0.0));
    let lower: Vec<Triplet<usize, usize, f64>> = triplets
        .iter()
        .filter(|t| t.0 >= t.1)
        .map(|&(row, col, val)| Triplet::new(row, col, val))
        .chain(diagonal)
        .collect();
    SparseColMat::<usize, f64>::try_new_from_triplets(n, n, &lower)
        .map_err(|e| SolveError::Build(format!("{e:?}")))
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
        let m = lower_matrix(n, triplets, false)?;
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

/// A sparse symmetric positive definite matrix whose off-diagonal entries are fixed and
/// whose diagonal may change between factorizations: the fill-reducing ordering and the
/// symbolic factorization (elimination tree, supernodes) are computed once in [`SpdPattern::new`],
/// each [`SpdPattern::factorize`] only redoes the numeric part. Used where a sequence of
/// systems differs by diagonal penalty terms (constraints added one group at a time).
pub struct SpdPattern {
    n: usize,
    symbolic: faer::sparse::linalg::solvers::SymbolicLlt<usize>,
    lower: SparseColMat<usize, f64>,
    /// Position of entry (i, i) in `lower`'s value array.
    diag_pos: Vec<usize>,
}

impl SpdPattern {
    /// The n×n matrix given by (row, col, value) triplets (duplicates summed, only row ≥ col
    /// read, as in [`SpdSolver::new`]). Every diagonal entry is part of the pattern even when
    /// no triplet names it.
    pub fn new(n: usize, triplets: &[(usize, usize, f64)]) -> Result<Self, SolveError> {
        faer::set_global_parallelism(faer::Par::Seq);
        let m = lower_matrix(n, triplets, true)?;
        let mut diag_pos = vec![usize::MAX; n];
        {
            let col_ptr = m.symbolic().col_ptr();
            let row_idx = m.symbolic().row_idx();
            for c in 0..n {
                for k in col_ptr[c]..col_ptr[c + 1] {
                    if row_idx[k] == c {
                        diag_pos[c] = k;
                    }
                }
            }
        }
        let symbolic =
            faer::sparse::linalg::solvers::SymbolicLlt::try_new(m.symbolic(), faer::Side::Lower)
                .map_err(|e| SolveError::Build(format!("{e:?}")))?;
        Ok(SpdPattern {
            n,
            symbolic,
            lower: m,
            diag_pos,
        })
    }

    pub fn n(&self) -> usize {
        self.n
    }

    /// Factorizes the matrix plus `diag(extra_diagonal)` (length n), reusing the symbolic
    /// analysis: the numeric phase a fresh factorization with this pattern would run.
    pub fn factorize(&self, extra_diagonal: &[f64]) -> Result<SpdFactor, SolveError> {
        assert_eq!(
            extra_diagonal.len(),
            self.n,
            "diagonal has the wrong length"
        );
        faer::set_global_parallelism(faer::Par::Seq);
        let mut m = self.lower.clone();
        {
            let val = m.val_mut();
            for (i, &d) in extra_diagonal.iter().enumerate() {
                val[self.diag_pos[i]] += d;
            }
        }
        let llt = faer::sparse::linalg::solvers::Llt::try_new_with_symbolic(
            self.symbolic.clone(),
            m.as_ref(),
            faer::Side::Lower,
        )
        .map_err(|e| SolveError::NotPositiveDefinite(format!("{e:?}")))?;
        Ok(SpdFactor { n: self.n, llt })
    }
}

/// A numeric factorization made by [`SpdPattern::factorize`].
pub struct SpdFactor {
    n: usize,
    llt: faer::sparse::linalg::solvers::Llt<usize, f64>,
}

impl SpdFactor {
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

    #[test]
    fn pattern_refactorization_matches_a_fresh_factorization() {
        // A path Laplacian plus a changing diagonal: singular without it, so the extra
        // diagonal must really be applied for the factorization to succeed.
        let n = 40;
        let mut t = Vec::new();
        for i in 0..n - 1 {
            t.push((i, i, 1.0));
            t.push((i + 1, i + 1, 1.0));
            t.push((i + 1, i, -1.0));
        }
        let pat = SpdPattern::new(n, &t).unwrap();
        assert!(pat.factorize(&vec![0.0; n]).is_err());
        for step in 0..3 {
            let extra: Vec<f64> = (0..n)
                .map(|i| if i % (7 - step) == 0 { 1e3 } else { 0.0 })
                .collect();
            let f = pat.factorize(&extra).unwrap();
            let mut fresh_t = t.clone();
            fresh_t.extend(extra.iter().enumerate().map(|(i, &d)| (i, i, d)));
            let fresh = SpdSolver::new(n, &fresh_t).unwrap();
            let b: Vec<f64> = (0..n).map(|i| (i as f64 * 0.7).cos()).collect();
            let (mut x, mut y) = (b.clone(), b.clone());
            f.solve(&mut x, 1);
            fresh.solve(&mut y, 1);
            for i in 0..n {
                assert!((x[i] - y[i]).abs() <= 1e-9 * y[i].abs().max(1.0));
            }
        }
    }
}
