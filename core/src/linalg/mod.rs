//! Sparse linear algebra: a symmetric positive definite solver that keeps its factorization
//! (faer's sparse Cholesky), so several right-hand sides reuse one factorization; and, for
//! systems too big to factorize quickly, conjugate gradients preconditioned by algebraic
//! multigrid ([`amg_pcg`]), chosen by size in [`solve_spd`].
//!
//! Always faer's *simplicial* factorization, never its supernodal one: the supernodal
//! kernels pick SIMD code (AVX2 with FMA, or not) by the CPU at run time, so the last bits
//! of a solution, and every artifact hash downstream, would depend on the machine (the
//! solid's field hashes differently under an emulated pre-AVX CPU). The simplicial kernels
//! are plain scalar loops, which Rust compiles without fused multiply-adds, so they round the
//! same on every x86-64 (and every IEEE 754) machine. Sequential too, for the thread count.

use faer::dyn_stack::{MemBuffer, MemStack};
use faer::sparse::linalg::SupernodalThreshold;
use faer::sparse::linalg::cholesky::{
    CholeskySymbolicParams, LltRef, SymbolicCholesky, factorize_symbolic_cholesky,
};
use faer::sparse::{SparseColMat, SymbolicSparseColMatRef, Triplet};
use std::sync::Arc;

pub mod amg_pcg;
pub use amg_pcg::IterativeParams;

#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum SolveError {
    #[error("sparse matrix could not be built: {0}")]
    Build(String),
    #[error("matrix is not positive definite (a mesh component with no constraint?): {0}")]
    NotPositiveDefinite(String),
    #[error("matrix is singular: {0}")]
    Singular(String),
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

/// The symbolic analysis (fill-reducing ordering, elimination tree), forced simplicial.
fn analyse(
    pattern: SymbolicSparseColMatRef<'_, usize>,
) -> Result<SymbolicCholesky<usize>, SolveError> {
    factorize_symbolic_cholesky(
        pattern,
        faer::Side::Lower,
        Default::default(),
        CholeskySymbolicParams {
            supernodal_flop_ratio_threshold: SupernodalThreshold::FORCE_SIMPLICIAL,
            ..Default::default()
        },
    )
    .map_err(|e| SolveError::Build(format!("{e:?}")))
}

/// A numeric factorization: the shared symbolic part and the factor's values.
struct Factor {
    symbolic: Arc<SymbolicCholesky<usize>>,
    values: Vec<f64>,
}

impl Factor {
    /// Factorizes `lower` (the lower triangle of an SPD matrix with `symbolic`'s pattern).
    fn new(
        symbolic: Arc<SymbolicCholesky<usize>>,
        lower: &SparseColMat<usize, f64>,
    ) -> Result<Factor, SolveError> {
        let par = faer::Par::Seq;
        let mut values = vec![0.0; symbolic.len_val()];
        let mut buf =
            MemBuffer::new(symbolic.factorize_numeric_llt_scratch::<f64>(par, Default::default()));
        symbolic
            .factorize_numeric_llt(
                &mut values,
                lower.as_ref(),
                faer::Side::Lower,
                Default::default(),
                par,
                MemStack::new(&mut buf),
                Default::default(),
            )
            .map_err(|e| SolveError::NotPositiveDefinite(format!("{e:?}")))?;
        Ok(Factor { symbolic, values })
    }

    /// Solves A X = B in place for `k` right-hand sides stored column-major in `rhs`.
    fn solve(&self, rhs: &mut [f64], k: usize) {
        let n = self.symbolic.nrows();
        assert_eq!(rhs.len(), n * k, "right-hand side has the wrong length");
        let par = faer::Par::Seq;
        let mut buf = MemBuffer::new(self.symbolic.solve_in_place_scratch::<f64>(k, par));
        LltRef::new(&self.symbolic, &self.values).solve_in_place_with_conj(
            faer::Conj::No,
            faer::MatMut::from_column_major_slice_mut(rhs, n, k),
            par,
            MemStack::new(&mut buf),
        );
    }
}

/// A factorized sparse SPD matrix.
pub struct SpdSolver {
    factor: Factor,
}

impl SpdSolver {
    /// Factorizes the n×n matrix given by (row, col, value) triplets; duplicates are summed.
    /// Only the lower triangle (row ≥ col) is read, so callers may pass either half or both.
    pub fn new(n: usize, triplets: &[(usize, usize, f64)]) -> Result<Self, SolveError> {
        let m = lower_matrix(n, triplets, false)?;
        let symbolic = Arc::new(analyse(m.symbolic())?);
        Ok(SpdSolver {
            factor: Factor::new(symbolic, &m)?,
        })
    }

    /// Solves A X = B in place for `k` right-hand sides stored column-major in `rhs`
    /// (length n·k).
    pub fn solve(&self, rhs: &mut [f64], k: usize) {
        self.factor.solve(rhs, k)
    }
}

/// Solves A X = B in place for `k` right-hand sides stored column-major in `rhs` (length
/// n·k), A the SPD matrix given by triplets as in [`SpdSolver::new`] (only row ≥ col read).
/// Below `params.min_unknowns` unknowns by the exact Cholesky factorization; from there on
/// by AMG-preconditioned conjugate gradients ([`amg_pcg`]) to `params.tolerance`, falling
/// back to the factorization if the iteration does not converge. A simplicial factorization
/// of a 700 000-vertex mesh Laplacian takes 13 s of CPU; the iteration a few tenths.
pub fn solve_spd(
    n: usize,
    triplets: &[(usize, usize, f64)],
    rhs: &mut [f64],
    k: usize,
    params: &IterativeParams,
) -> Result<(), SolveError> {
    if n >= params.min_unknowns {
        match amg_pcg::solve(n, triplets, rhs, k, params)? {
            Some(report) => {
                tracing::debug!(
                    "AMG-PCG: levels {:?}, iterations {:?}, relative residuals {:?}",
                    report.level_sizes,
                    report.iterations,
                    report.relative_residuals
                );
                return Ok(());
            }
            None => tracing::warn!(
                "AMG-PCG did not reach a relative residual of {:e} in {} iterations on {n} unknowns; \
                 factorizing instead",
                params.tolerance,
                params.max_iterations
            ),
        }
    }
    SpdSolver::new(n, triplets)?.solve(rhs, k);
    Ok(())
}

/// A sparse symmetric positive definite matrix whose off-diagonal entries are fixed and
/// whose diagonal may change between factorizations: the fill-reducing ordering and the
/// symbolic factorization (elimination tree) are computed once in [`SpdPattern::new`],
/// each [`SpdPattern::factorize`] only redoes the numeric part. Used where a sequence of
/// systems differs by diagonal penalty terms (constraints added one group at a time).
pub struct SpdPattern {
    n: usize,
    symbolic: Arc<SymbolicCholesky<usize>>,
    lower: SparseColMat<usize, f64>,
    /// Position of entry (i, i) in `lower`'s value array.
    diag_pos: Vec<usize>,
}

impl SpdPattern {
    /// The n×n matrix given by (row, col, value) triplets (duplicates summed, only row ≥ col
    /// read, as in [`SpdSolver::new`]). Every diagonal entry is part of the pattern even when
    /// no triplet names it.
    pub fn new(n: usize, triplets: &[(usize, usize, f64)]) -> Result<Self, SolveError> {
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
        let symbolic = Arc::new(analyse(m.symbolic())?);
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
        let mut m = self.lower.clone();
        {
            let val = m.val_mut();
            for (i, &d) in extra_diagonal.iter().enumerate() {
                val[self.diag_pos[i]] += d;
            }
        }
        Ok(SpdFactor {
            factor: Factor::new(self.symbolic.clone(), &m)?,
        })
    }
}

/// A numeric factorization made by [`SpdPattern::factorize`].
pub struct SpdFactor {
    factor: Factor,
}

impl SpdFactor {
    /// Solves A X = B in place for `k` right-hand sides stored column-major in `rhs`
    /// (length n·k).
    pub fn solve(&self, rhs: &mut [f64], k: usize) {
        self.factor.solve(rhs, k)
    }
}

/// The symbolic LU analysis (column ordering, fill pattern) of a square sparse matrix, forced
/// simplicial like the Cholesky above, so that solutions do not depend on the CPU. Numeric
/// factorizations of matrices with the same pattern reuse it.
#[derive(Clone)]
pub struct LuPattern {
    symbolic: Arc<faer::sparse::linalg::lu::SymbolicLu<usize>>,
}

impl LuPattern {
    pub fn new(pattern: SymbolicSparseColMatRef<'_, usize>) -> Result<Self, SolveError> {
        use faer::sparse::linalg::lu::{LuSymbolicParams, factorize_symbolic_lu};
        let symbolic = factorize_symbolic_lu(
            pattern,
            LuSymbolicParams {
                supernodal_flop_ratio_threshold: SupernodalThreshold::FORCE_SIMPLICIAL,
                ..Default::default()
            },
        )
        .map_err(|e| SolveError::Build(format!("{e:?}")))?;
        Ok(LuPattern {
            symbolic: Arc::new(symbolic),
        })
    }

    /// Factorizes `mat` (this pattern's matrix) and solves `mat · X = B` in place for `k`
    /// right-hand sides stored column-major in `rhs`.
    pub fn solve(
        &self,
        mat: &SparseColMat<usize, f64>,
        rhs: &mut [f64],
        k: usize,
    ) -> Result<(), SolveError> {
        use faer::sparse::linalg::lu::NumericLu;
        let n = mat.nrows();
        assert_eq!(rhs.len(), n * k, "right-hand side has the wrong length");
        let par = faer::Par::Seq;
        let mut numeric = NumericLu::<usize, f64>::new();
        let mut buf = MemBuffer::new(
            self.symbolic
                .factorize_numeric_lu_scratch::<f64>(par, Default::default())
                .or(self.symbolic.solve_in_place_scratch::<f64>(k, par)),
        );
        let lu = self
            .symbolic
            .factorize_numeric_lu(
                &mut numeric,
                mat.as_ref(),
                par,
                MemStack::new(&mut buf),
                Default::default(),
            )
            .map_err(|e| SolveError::Singular(format!("{e:?}")))?;
        lu.solve_in_place_with_conj(
            faer::Conj::No,
            faer::MatMut::from_column_major_slice_mut(rhs, n, k),
            par,
            MemStack::new(&mut buf),
        );
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::math::PureMath;

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
        let b: Vec<f64> = (0..2 * n).map(|i| (i as f64 * 0.37).sin_pure()).collect();
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

    /// The CPU-independence above rests on the simplicial kernels: on a grid Laplacian big
    /// enough that faer's default analysis goes supernodal, ours must not.
    #[test]
    fn factorizations_are_simplicial_where_faer_would_go_supernodal() {
        use faer::sparse::linalg::cholesky::SymbolicCholeskyRaw;
        // A 3D grid: enough fill for faer's flop-ratio rule to choose supernodes.
        let side = 16;
        let id = |x: usize, y: usize, z: usize| (z * side + y) * side + x;
        let mut t = Vec::new();
        for z in 0..side {
            for y in 0..side {
                for x in 0..side {
                    let i = id(x, y, z);
                    t.push((i, i, 6.01));
                    if x + 1 < side {
                        t.push((id(x + 1, y, z), i, -1.0));
                    }
                    if y + 1 < side {
                        t.push((id(x, y + 1, z), i, -1.0));
                    }
                    if z + 1 < side {
                        t.push((id(x, y, z + 1), i, -1.0));
                    }
                }
            }
        }
        let m = lower_matrix(side * side * side, &t, false).unwrap();
        let default = factorize_symbolic_cholesky(
            m.symbolic(),
            faer::Side::Lower,
            Default::default(),
            Default::default(),
        )
        .unwrap();
        assert!(matches!(default.raw(), SymbolicCholeskyRaw::Supernodal(_)));
        let ours = analyse(m.symbolic()).unwrap();
        assert!(matches!(ours.raw(), SymbolicCholeskyRaw::Simplicial(_)));
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
            let b: Vec<f64> = (0..n).map(|i| (i as f64 * 0.7).cos_pure()).collect();
            let (mut x, mut y) = (b.clone(), b.clone());
            f.solve(&mut x, 1);
            fresh.solve(&mut y, 1);
            for i in 0..n {
                assert!((x[i] - y[i]).abs() <= 1e-9 * y[i].abs().max(1.0));
            }
        }
    }
}
