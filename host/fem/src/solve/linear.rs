//! Sparse direct solves with faer, reusing one symbolic analysis across Newton iterations.

use crate::{FemError, Result};
use faer::dyn_stack::{MemBuffer, MemStack};
use faer::linalg::solvers::Solve;
use faer::sparse::linalg::cholesky::{LltRef, SymbolicCholesky, factorize_symbolic_cholesky};
use faer::sparse::linalg::solvers::{Lu, SymbolicLu};
use faer::sparse::{SparseColMatRef, SymbolicSparseColMatRef};
use faer::{Conj, MatMut, Par, Side};
use std::sync::Arc;

/// The numeric factor kept between a factorization and the solves that reuse it.
#[derive(Debug, Clone)]
enum Factor {
    None,
    /// Cholesky values on the cached symbolic structure.
    Llt,
    Lu(Box<Lu<usize, f64>>),
}

/// The square matrix with `values` on the CSC structure (`col_ptr`, `row_idx`) of order `n`.
fn matrix<'a>(
    n: usize,
    col_ptr: &'a [usize],
    row_idx: &'a [usize],
    values: &'a [f64],
) -> SparseColMatRef<'a, usize, f64> {
    SparseColMatRef::new(
        SymbolicSparseColMatRef::new_checked(n, n, col_ptr, None, row_idx),
        values,
    )
}

/// A square sparse matrix structure (full, both triangles) and cached factorizations.
///
/// Factorizations run sequentially: for the few thousand unknowns of our meshes the supernodal
/// fronts are small, and on the shared two-core machines thread hand-offs cost more than they
/// save (the numeric Cholesky of the bellows tangent takes about a third of the time on one thread).
#[derive(Debug, Clone)]
pub struct SparseSolver {
    n: usize,
    col_ptr: Vec<usize>,
    row_idx: Vec<usize>,
    llt: Option<Arc<SymbolicCholesky<usize>>>,
    l_values: Vec<f64>,
    lu: Option<SymbolicLu<usize>>,
    factor: Factor,
    /// How many factorizations fell back to LU because the matrix was not positive definite.
    pub lu_fallbacks: usize,
    /// The exponent of the last shift [`SparseSolver::solve_descent`] needed: the next
    /// indefinite matrix of a Newton solve is likely to need one as large, so the ladder
    /// starts two decades below it instead of at 1e-8.
    last_shift_exp: i32,
}

const PAR: Par = Par::Seq;

/// The least and largest Jacobi-scaled shifts [`SparseSolver::solve_descent`] tries, as powers of
/// ten.
const SHIFT_EXP_MIN: i32 = -8;
const SHIFT_EXP_MAX: i32 = 2;

impl SparseSolver {
    /// Takes a CSC structure with sorted rows in each column.
    pub fn new(n: usize, col_ptr: Vec<usize>, row_idx: Vec<usize>) -> Self {
        SparseSolver {
            n,
            col_ptr,
            row_idx,
            llt: None,
            l_values: vec![],
            lu: None,
            factor: Factor::None,
            lu_fallbacks: 0,
            last_shift_exp: SHIFT_EXP_MIN,
        }
    }

    /// Number of unknowns.
    pub fn dim(&self) -> usize {
        self.n
    }

    /// Column pointers.
    pub fn col_ptr(&self) -> &[usize] {
        &self.col_ptr
    }

    /// Row indices.
    pub fn row_idx(&self) -> &[usize] {
        &self.row_idx
    }

    /// Solves A x = b in place (`rhs` holds b on entry and x on exit).
    ///
    /// Tries Cholesky first (symmetric positive definite: the usual stable case);
    /// falls back to LU for indefinite tangents (e.g. under cavity suction).
    pub fn solve(&mut self, values: &[f64], rhs: &mut [f64]) -> Result<()> {
        self.factorize(values)?;
        self.solve_factored(rhs)
    }

    /// Factorizes A (values on the structure given to [`SparseSolver::new`]) and keeps the factor
    /// for [`SparseSolver::solve_factored`].
    pub fn factorize(&mut self, values: &[f64]) -> Result<()> {
        if self.try_llt(values)? {
            return Ok(());
        }
        self.lu_fallbacks += 1;
        let a = matrix(self.n, &self.col_ptr, &self.row_idx, values);
        if self.lu.is_none() {
            self.lu = Some(
                SymbolicLu::try_new(a.symbolic())
                    .map_err(|e| FemError::Linear(format!("symbolic LU: {e:?}")))?,
            );
        }
        let sym = self
            .lu
            .clone()
            .ok_or_else(|| FemError::Linear("no symbolic LU".into()))?;
        let f = Lu::try_new_with_symbolic(sym, a)
            .map_err(|e| FemError::Linear(format!("singular matrix: {e:?}")))?;
        self.factor = Factor::Lu(Box::new(f));
        Ok(())
    }

    /// Solves (A + tau D) x = b in place, where D is the diagonal of A in absolute value and
    /// tau the least of 0, 1e-8, 1e-7, ..., 1e2 at which Cholesky succeeds (the ladder starts
    /// two decades below the last call's shift); returns tau.
    ///
    /// For minimising an energy whose tangent A may be indefinite (a Neo-Hookean gel crushed
    /// under a punch's edge): the step is then a descent direction, which the LU solve of
    /// [`SparseSolver::solve`] does not promise (Nocedal and Wright, Numerical Optimization,
    /// 2nd ed., Alg. 3.3, with a Jacobi-scaled shift since the unknowns' stiffnesses differ).
    pub fn solve_descent(&mut self, values: &[f64], rhs: &mut [f64]) -> Result<f64> {
        if self.try_llt(values)? {
            self.solve_factored(rhs)?;
            return Ok(0.0);
        }
        let diag: Vec<usize> = (0..self.n)
            .map(|j| {
                let rows = &self.row_idx[self.col_ptr[j]..self.col_ptr[j + 1]];
                rows.binary_search(&j)
                    .map(|k| self.col_ptr[j] + k)
                    .map_err(|_| FemError::Linear(format!("column {j} has no diagonal entry")))
            })
            .collect::<Result<_>>()?;
        let floor = diag.iter().map(|&k| values[k].abs()).fold(0.0, f64::max) * 1e-12;
        let mut shifted = values.to_vec();
        for e in (self.last_shift_exp - 2).max(SHIFT_EXP_MIN)..=SHIFT_EXP_MAX {
            let tau = 10f64.powi(e);
            for &k in &diag {
                shifted[k] = values[k] + tau * values[k].abs().max(floor);
            }
            if self.try_llt(&shifted)? {
                self.last_shift_exp = e;
                self.solve_factored(rhs)?;
                return Ok(tau);
            }
        }
        Err(FemError::Linear(
            "no shift up to 100 times the diagonal makes the matrix positive definite".into(),
        ))
    }

    /// Cholesky of A kept as the factor when A is positive definite; false when it is not.
    fn try_llt(&mut self, values: &[f64]) -> Result<bool> {
        self.factor = Factor::None;
        if values.len() != self.row_idx.len() {
            return Err(FemError::Linear("matrix has the wrong size".into()));
        }
        if self.n == 0 {
            return Ok(true);
        }
        if values.iter().any(|v| !v.is_finite()) {
            return Err(FemError::Linear("matrix contains NaN or infinity".into()));
        }
        let a = matrix(self.n, &self.col_ptr, &self.row_idx, values);
        if self.llt.is_none() {
            let sym = factorize_symbolic_cholesky(
                a.symbolic(),
                Side::Lower,
                Default::default(),
                Default::default(),
            )
            .map_err(|e| FemError::Linear(format!("symbolic Cholesky: {e:?}")))?;
            self.l_values = vec![0.0; sym.len_val()];
            self.llt = Some(Arc::new(sym));
        }
        let sym = self
            .llt
            .clone()
            .ok_or_else(|| FemError::Linear("no symbolic factorization".into()))?;
        let mut buf =
            MemBuffer::try_new(sym.factorize_numeric_llt_scratch::<f64>(PAR, Default::default()))
                .map_err(|e| FemError::Linear(format!("Cholesky workspace: {e:?}")))?;
        let llt = sym.factorize_numeric_llt::<f64>(
            &mut self.l_values,
            a,
            Side::Lower,
            Default::default(),
            PAR,
            MemStack::new(&mut buf),
            Default::default(),
        );
        if llt.is_ok() {
            self.factor = Factor::Llt;
        }
        Ok(llt.is_ok())
    }

    /// Solves with the factor of the last successful [`SparseSolver::factorize`].
    pub fn solve_factored(&self, rhs: &mut [f64]) -> Result<()> {
        if rhs.len() != self.n {
            return Err(FemError::Linear(
                "right-hand side has the wrong size".into(),
            ));
        }
        if self.n == 0 {
            return Ok(());
        }
        if rhs.iter().any(|v| !v.is_finite()) {
            return Err(FemError::Linear(
                "right-hand side contains NaN or infinity".into(),
            ));
        }
        let mut b = MatMut::from_column_major_slice_mut(rhs, self.n, 1);
        match (&self.factor, &self.llt) {
            (Factor::Llt, Some(sym)) => {
                let mut buf = MemBuffer::try_new(sym.solve_in_place_scratch::<f64>(1, PAR))
                    .map_err(|e| FemError::Linear(format!("solve workspace: {e:?}")))?;
                LltRef::<usize, f64>::new(sym, &self.l_values).solve_in_place_with_conj(
                    Conj::No,
                    b.as_mut(),
                    PAR,
                    MemStack::new(&mut buf),
                );
            }
            (Factor::Lu(f), _) => f.solve_in_place(b.as_mut()),
            _ => return Err(FemError::Linear("no factorization to solve with".into())),
        }
        if rhs.iter().any(|v| !v.is_finite()) {
            return Err(FemError::Linear(
                "solution is not finite (singular matrix)".into(),
            ));
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// CSC pattern and values of the tridiagonal matrix `[-1, diag, -1]`.
    fn tridiagonal(n: usize, diag: f64) -> (Vec<usize>, Vec<usize>, Vec<f64>) {
        let mut cp = vec![0];
        let mut ri = vec![];
        let mut v = vec![];
        for j in 0..n {
            for i in j.saturating_sub(1)..(j + 2).min(n) {
                ri.push(i);
                v.push(if i == j { diag } else { -1.0 });
            }
            cp.push(ri.len());
        }
        (cp, ri, v)
    }

    /// `v` with each diagonal entry replaced by `f(column, entry)`.
    fn map_diag(cp: &[usize], ri: &[usize], v: &[f64], f: impl Fn(usize, f64) -> f64) -> Vec<f64> {
        v.iter()
            .enumerate()
            .map(|(k, &x)| {
                let col = cp.partition_point(|&p| p <= k) - 1;
                if ri[k] == col { f(col, x) } else { x }
            })
            .collect()
    }

    /// 1-D Laplacian (SPD) and an indefinite variant, against residual checks.
    #[test]
    fn solves_spd_and_indefinite() {
        let n: usize = 50;
        let (cp, ri, v) = tridiagonal(n, 2.0);
        let b: Vec<f64> = (0..n).map(|i| (i as f64).sin()).collect();
        let mut s = SparseSolver::new(n, cp.clone(), ri.clone());
        for shift in [0.0, -1.5] {
            let vals = map_diag(&cp, &ri, &v, |_, x| x + shift);
            let mut x = b.clone();
            s.solve(&vals, &mut x).unwrap();
            for i in 0..n {
                let mut ax = 0.0;
                for j in 0..n {
                    for k in cp[j]..cp[j + 1] {
                        if ri[k] == i {
                            ax += vals[k] * x[j];
                        }
                    }
                }
                assert!((ax - b[i]).abs() < 1e-9);
            }
        }
        assert_eq!(s.lu_fallbacks, 1);
        let mut x = b.clone();
        assert!(s.solve(&vec![f64::NAN; v.len()], &mut x).is_err());
    }

    /// On a positive definite matrix `solve_descent` is the plain solve; on an indefinite one
    /// it solves the least shifted matrix of its ladder that Cholesky accepts, so that the step
    /// descends (b . x > 0), and the next call starts its ladder near that shift.
    #[test]
    fn descent_solve_shifts_only_indefinite_matrices() {
        let n: usize = 40;
        let (cp, ri, v) = tridiagonal(n, 2.0);
        let b: Vec<f64> = (0..n).map(|i| 1.0 + (i as f64).cos()).collect();
        let mut s = SparseSolver::new(n, cp.clone(), ri.clone());
        let mut x = b.clone();
        assert_eq!(s.solve_descent(&v, &mut x).unwrap(), 0.0);
        let mut y = b.clone();
        SparseSolver::new(n, cp.clone(), ri.clone())
            .solve(&v, &mut y)
            .unwrap();
        assert!(x.iter().zip(&y).all(|(a, b)| (a - b).abs() < 1e-12));
        // diagonal 0.9 - 0.5 i / n under off-diagonal -1: indefinite (eigenvalues reach below 0)
        let diag = |i: usize| 1.5 - 0.5 * i as f64 / n as f64 - 0.6;
        let vals = map_diag(&cp, &ri, &v, |col, _| diag(col));
        let mut x = b.clone();
        let tau = s.solve_descent(&vals, &mut x).unwrap();
        assert!(tau > 0.0, "an indefinite matrix needs a shift");
        assert!(x.iter().zip(&b).map(|(a, b)| a * b).sum::<f64>() > 0.0);
        // (A + tau |diag A|) x = b, row by row
        for i in 0..n {
            let d = diag(i) + tau * diag(i).abs();
            let mut ax = d * x[i];
            if i > 0 {
                ax -= x[i - 1];
            }
            if i + 1 < n {
                ax -= x[i + 1];
            }
            assert!((ax - b[i]).abs() < 1e-8 * (1.0 + d.abs()), "row {i}");
        }
        // the shift is the least of the ladder: a tenth of it does not factor
        let lower = map_diag(&cp, &ri, &vals, |_, x| x + 0.1 * tau * x.abs());
        let mut z = b.clone();
        let mut fresh = SparseSolver::new(n, cp.clone(), ri.clone());
        fresh.solve(&lower, &mut z).unwrap();
        assert_eq!(
            fresh.lu_fallbacks, 1,
            "a tenth of the shift stays indefinite"
        );
        assert_eq!(
            s.lu_fallbacks, 0,
            "the descent solve never falls back to LU"
        );
    }

    /// One factorization serves several right-hand sides, each solved as a fresh `solve` would.
    #[test]
    fn factor_is_reused_across_right_hand_sides() {
        let n: usize = 30;
        let (cp, ri, v) = tridiagonal(n, 2.5);
        let mut s = SparseSolver::new(n, cp.clone(), ri.clone());
        let mut x = vec![1.0; n];
        assert!(s.solve_factored(&mut x).is_err(), "no factor yet");
        s.factorize(&v).unwrap();
        for k in 1..4 {
            let b: Vec<f64> = (0..n).map(|i| ((i * k) as f64).cos()).collect();
            let mut x = b.clone();
            s.solve_factored(&mut x).unwrap();
            let mut fresh = SparseSolver::new(n, cp.clone(), ri.clone());
            let mut y = b.clone();
            fresh.solve(&v, &mut y).unwrap();
            for i in 0..n {
                assert!((x[i] - y[i]).abs() < 1e-12);
            }
            // A x = b row by row for this tridiagonal matrix.
            for i in 0..n {
                let mut ax = 2.5 * x[i];
                if i > 0 {
                    ax -= x[i - 1];
                }
                if i + 1 < n {
                    ax -= x[i + 1];
                }
                assert!((ax - b[i]).abs() < 1e-10);
            }
        }
        assert!(s.factorize(&vec![f64::NAN; v.len()]).is_err());
        let mut x = vec![1.0; n];
        assert!(
            s.solve_factored(&mut x).is_err(),
            "a failed factorization leaves no factor"
        );
    }
}
