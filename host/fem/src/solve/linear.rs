//! Sparse direct solves with faer, reusing one symbolic analysis across Newton iterations.

use crate::{FemError, Result};
use faer::linalg::solvers::Solve;
use faer::sparse::linalg::solvers::{Llt, Lu, SymbolicLlt, SymbolicLu};
use faer::sparse::{SparseColMatRef, SymbolicSparseColMatRef};
use faer::{MatMut, Side};

/// A square sparse matrix structure (full, both triangles) and cached factorizations.
#[derive(Debug, Clone)]
pub struct SparseSolver {
    n: usize,
    col_ptr: Vec<usize>,
    row_idx: Vec<usize>,
    llt: Option<SymbolicLlt<usize>>,
    lu: Option<SymbolicLu<usize>>,
    /// How many factorizations fell back to LU because the matrix was not positive definite.
    pub lu_fallbacks: usize,
}

impl SparseSolver {
    /// Takes a CSC structure with sorted rows in each column.
    pub fn new(n: usize, col_ptr: Vec<usize>, row_idx: Vec<usize>) -> Self {
        SparseSolver {
            n,
            col_ptr,
            row_idx,
            llt: None,
            lu: None,
            lu_fallbacks: 0,
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
        if values.len() != self.row_idx.len() || rhs.len() != self.n {
            return Err(FemError::Linear(
                "matrix or right-hand side has the wrong size".into(),
            ));
        }
        if self.n == 0 {
            return Ok(());
        }
        if values.iter().chain(rhs.iter()).any(|v| !v.is_finite()) {
            return Err(FemError::Linear(
                "matrix or right-hand side contains NaN or infinity".into(),
            ));
        }
        let a = SparseColMatRef::new(
            SymbolicSparseColMatRef::new_checked(
                self.n,
                self.n,
                &self.col_ptr,
                None,
                &self.row_idx,
            ),
            values,
        );
        if self.llt.is_none() {
            self.llt = Some(
                SymbolicLlt::try_new(a.symbolic(), Side::Lower)
                    .map_err(|e| FemError::Linear(format!("symbolic Cholesky: {e:?}")))?,
            );
        }
        let sym = self
            .llt
            .clone()
            .ok_or_else(|| FemError::Linear("no symbolic factorization".into()))?;
        let mut b = MatMut::from_column_major_slice_mut(rhs, self.n, 1);
        match Llt::try_new_with_symbolic(sym, a, Side::Lower) {
            Ok(f) => f.solve_in_place(b.as_mut()),
            Err(_) => {
                self.lu_fallbacks += 1;
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
                f.solve_in_place(b.as_mut());
            }
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

    /// 1-D Laplacian (SPD) and an indefinite variant, against residual checks.
    #[test]
    fn solves_spd_and_indefinite() {
        let n: usize = 50;
        let mut cp = vec![0];
        let mut ri = vec![];
        let mut v = vec![];
        for j in 0..n {
            for i in j.saturating_sub(1)..(j + 2).min(n) {
                ri.push(i);
                v.push(if i == j { 2.0 } else { -1.0 });
            }
            cp.push(ri.len());
        }
        let b: Vec<f64> = (0..n).map(|i| (i as f64).sin()).collect();
        let mut s = SparseSolver::new(n, cp.clone(), ri.clone());
        for shift in [0.0, -1.5] {
            let vals: Vec<f64> = v
                .iter()
                .zip(&ri)
                .enumerate()
                .map(|(k, (&x, _))| {
                    let col = cp.partition_point(|&p| p <= k) - 1;
                    if ri[k] == col { x + shift } else { x }
                })
                .collect();
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
}
