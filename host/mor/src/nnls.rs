//! Non-negative least squares (Lawson-Hanson active set) for ECSW, stopped early once the residual
//! meets the tolerance, which is what makes the weights sparse.
//!
//! The passive-set least-squares problems are solved through their Gram matrix, grown one column at
//! a time; ECSW asks for relative residuals of 1e-2..1e-5, well within the normal equations' reach.

use crate::{MorError, Result};
use faer::linalg::matmul::matmul;
use faer::{Accum, MatRef, Par};
use nalgebra::{DMatrix, DVector};

/// NNLS solution.
#[derive(Debug, Clone)]
pub struct Nnls {
    /// Weights (non-negative), one per column.
    pub weights: Vec<f64>,
    /// ||G w - b|| / ||b||.
    pub relative_residual: f64,
}

/// Solves min ||G w - b|| subject to w >= 0 until ||G w - b|| <= tol ||b||; `g` is column-major
/// `rows` x `cols`.
pub fn solve(g: &[f64], rows: usize, cols: usize, b: &[f64], tol: f64) -> Result<Nnls> {
    if g.len() != rows * cols || b.len() != rows {
        return Err(MorError::Invalid("NNLS: inconsistent sizes".into()));
    }
    let gm = MatRef::from_column_major_slice(g, rows, cols);
    let col = |j: usize| &g[j * rows..(j + 1) * rows];
    let dot = |a: &[f64], c: &[f64]| a.iter().zip(c).map(|(x, y)| x * y).sum::<f64>();
    let bnorm = dot(b, b).sqrt();
    let mut w = vec![0.0; cols];
    let mut passive: Vec<usize> = vec![];
    let mut in_p = vec![false; cols];
    let mut resid = b.to_vec();
    let residual_of = |w: &[f64], p: &[usize]| -> Vec<f64> {
        let mut r = b.to_vec();
        for &j in p {
            for (ri, gi) in r.iter_mut().zip(col(j)) {
                *ri -= w[j] * gi;
            }
        }
        r
    };
    // Gram matrix of the passive columns, kept in the order of `passive` and grown one column at a
    // time (rows x |P| per added column instead of rows x |P|^2 per solve).
    let mut gram: Vec<Vec<f64>> = vec![];
    let mut gb: Vec<f64> = vec![];
    let ls = |gram: &[Vec<f64>], gb: &[f64]| -> Result<Vec<f64>> {
        let n = gb.len();
        let g = DMatrix::from_fn(n, n, |a, c| gram[a][c]);
        let rhs = DVector::from_column_slice(gb);
        let z = match g.clone().cholesky() {
            Some(ch) => ch.solve(&rhs),
            None => g
                .lu()
                .solve(&rhs)
                .ok_or_else(|| MorError::Solve("NNLS: singular passive set".into()))?,
        };
        Ok(z.iter().copied().collect())
    };
    let max_outer = 3 * cols.min(rows) + 10;
    let mut grad = faer::Mat::<f64>::zeros(cols, 1);
    for _ in 0..max_outer {
        let rn = dot(&resid, &resid).sqrt();
        if rn <= tol * bnorm {
            break;
        }
        let rm = MatRef::from_column_major_slice(&resid, rows, 1);
        matmul(
            grad.as_mut(),
            Accum::Replace,
            gm.transpose(),
            rm,
            1.0,
            Par::rayon(0),
        );
        let pick = (0..cols)
            .filter(|&j| !in_p[j] && grad[(j, 0)] > 0.0)
            .max_by(|&a, &c| grad[(a, 0)].total_cmp(&grad[(c, 0)]));
        let Some(j) = pick else { break };
        let cj = col(j);
        for (row, &i) in gram.iter_mut().zip(&passive) {
            row.push(dot(col(i), cj));
        }
        let mut last: Vec<f64> = passive.iter().map(|&i| dot(col(i), cj)).collect();
        last.push(dot(cj, cj));
        gram.push(last);
        gb.push(dot(cj, b));
        passive.push(j);
        in_p[j] = true;
        loop {
            let z = ls(&gram, &gb)?;
            if z.iter().all(|&v| v > 0.0) {
                for (&i, &v) in passive.iter().zip(&z) {
                    w[i] = v;
                }
                break;
            }
            // Step from w towards z until the first passive weight reaches zero; drop it.
            let mut alpha = f64::INFINITY;
            for (&i, &v) in passive.iter().zip(&z) {
                if v <= 0.0 {
                    alpha = alpha.min(w[i] / (w[i] - v));
                }
            }
            for (&i, &v) in passive.iter().zip(&z) {
                w[i] += alpha * (v - w[i]);
            }
            let keep: Vec<bool> = passive.iter().map(|&i| w[i] > 1e-14).collect();
            for (&i, &k) in passive.iter().zip(&keep) {
                if !k {
                    w[i] = 0.0;
                    in_p[i] = false;
                }
            }
            let pick = |v: &[f64]| -> Vec<f64> {
                v.iter()
                    .zip(&keep)
                    .filter(|(_, k)| **k)
                    .map(|(x, _)| *x)
                    .collect()
            };
            gram = gram
                .iter()
                .zip(&keep)
                .filter(|(_, k)| **k)
                .map(|(r, _)| pick(r))
                .collect();
            gb = pick(&gb);
            passive = passive
                .iter()
                .zip(&keep)
                .filter(|(_, k)| **k)
                .map(|(i, _)| *i)
                .collect();
            if passive.is_empty() {
                break;
            }
        }
        resid = residual_of(&w, &passive);
    }
    let rn = dot(&resid, &resid).sqrt();
    Ok(Nnls {
        weights: w,
        relative_residual: if bnorm > 0.0 { rn / bnorm } else { 0.0 },
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn recovers_a_sparse_non_negative_solution_and_respects_the_sign() {
        // 30 x 12 random G; b = G w* with w* sparse and non-negative.
        let mut s = 12345u64;
        let mut rnd = || {
            s = s
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (s >> 11) as f64 / (1u64 << 53) as f64 - 0.5
        };
        let (rows, cols) = (30, 12);
        let g: Vec<f64> = (0..rows * cols).map(|_| rnd()).collect();
        let mut wstar = vec![0.0; cols];
        wstar[2] = 1.5;
        wstar[7] = 0.25;
        wstar[9] = 3.0;
        let b: Vec<f64> = (0..rows)
            .map(|i| (0..cols).map(|j| g[j * rows + i] * wstar[j]).sum())
            .collect();
        let sol = solve(&g, rows, cols, &b, 1e-12).unwrap();
        assert!(sol.weights.iter().all(|&w| w >= 0.0));
        for j in 0..cols {
            assert!(
                (sol.weights[j] - wstar[j]).abs() < 1e-9,
                "{:?}",
                sol.weights
            );
        }
        // A target with a negative component cannot be met: the best w stays non-negative and the
        // residual is what the KKT conditions leave (gradient <= 0 on zero weights).
        let bneg: Vec<f64> = b
            .iter()
            .zip(0..)
            .map(|(v, i)| v - g[4 * rows + i] * 2.0)
            .collect();
        let sol = solve(&g, rows, cols, &bneg, 1e-12).unwrap();
        assert!(sol.weights.iter().all(|&w| w >= 0.0));
        assert!(sol.relative_residual > 1e-3);
        let r: Vec<f64> = (0..rows)
            .map(|i| {
                bneg[i]
                    - (0..cols)
                        .map(|j| g[j * rows + i] * sol.weights[j])
                        .sum::<f64>()
            })
            .collect();
        for j in 0..cols {
            let gr: f64 = (0..rows).map(|i| g[j * rows + i] * r[i]).sum();
            if sol.weights[j] == 0.0 {
                assert!(gr <= 1e-9, "KKT: column {j} gradient {gr}");
            } else {
                assert!(gr.abs() <= 1e-8, "KKT: passive column {j} gradient {gr}");
            }
        }
    }
}
