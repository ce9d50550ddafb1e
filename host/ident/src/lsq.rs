//! Linear least squares on selected rows, with optional non-negativity on chosen coefficients
//! and standard errors. Sizes here are small (tens of columns), so the normal equations with
//! column equilibration and a tiny ridge are accurate and cheap.

use nalgebra::{DMatrix, DVector};
use rayon::prelude::*;

/// A fitted linear model.
#[derive(Debug, Clone)]
pub struct LsqFit {
    /// Coefficients, one per column (zero where a non-negative coefficient was clamped).
    pub coef: Vec<f64>,
    /// Standard errors (white-residual assumption); zero for clamped coefficients.
    pub std_err: Vec<f64>,
    /// Residual sum of squares on the fitted rows.
    pub rss: f64,
    /// Number of fitted rows.
    pub rows: usize,
    /// Number of free (unclamped, non-degenerate) coefficients.
    pub dof_used: usize,
    /// True when the fit cancels huge terms against each other (the spread of some `coef_j * column_j`
    /// is more than [`CANCELLATION`] times the target's) or is not finite: its coefficients
    /// are not identified by the data and must not be reported as findings.
    pub ill_conditioned: bool,
}

/// Largest ratio of one term's RMS to the target's RMS before a fit counts as ill-conditioned.
pub const CANCELLATION: f64 = 1e4;

/// Rows times squared columns from which a fit's Gram matrix is computed on the thread pool
/// (some 10 ms of work on one core).
const PARALLEL_MIN_WORK: usize = 20_000_000;

/// Fits `target ~ sum coef_j * columns[j]` on the rows where `mask` is true.
/// Columns listed in `nonneg` are constrained to be >= 0 (active-set elimination).
pub fn fit(columns: &[&[f64]], target: &[f64], mask: &[bool], nonneg: &[bool]) -> LsqFit {
    let p = columns.len();
    let rows: Vec<usize> = (0..target.len()).filter(|&i| mask[i]).collect();
    let n = rows.len();
    // Gram matrix and moment vector once; sub-problems pick sub-blocks. The selected rows are
    // gathered into contiguous columns first (a gather per product was most of a fit's time
    // with hundreds of columns); every sum still runs over the rows in order, so the result is
    // bit for bit the plain loop's (the selection's refinements end in other local optima with
    // rounding-level changes, see the README).
    // Threads pay only on large fits: on the batteries' 2000-row records a fit takes well
    // under a millisecond, and the pool's idle threads spinning between thousands of such fits
    // cost more system time than the fits themselves (perf: 40 % of a battery in the scheduler)
    let parallel = n * p * p >= PARALLEL_MIN_WORK;
    let gather = |col: &&[f64]| -> Vec<f64> { rows.iter().map(|&i| col[i]).collect() };
    let gathered: Vec<Vec<f64>> = if parallel {
        columns.par_iter().map(gather).collect()
    } else {
        columns.iter().map(gather).collect()
    };
    let t: Vec<f64> = rows.iter().map(|&i| target[i]).collect();
    let dot = |x: &[f64], y: &[f64]| -> f64 {
        let mut s = 0.0;
        for (a, b) in x.iter().zip(y) {
            s += a * b;
        }
        s
    };
    let yy = dot(&t, &t);
    // Row a of the Gram matrix's upper triangle and b[a]: independent of the other rows, so
    // the rows are computed in parallel (large records: a 100k-row fit spends most of its time
    // here) and land in their places.
    let gram_row = |a: usize| -> (f64, Vec<f64>) {
        let xa = &gathered[a];
        let mut row = Vec::with_capacity(p - a);
        // Four products at a time: each still sums its rows in order (bit for bit the
        // plain loop), but four independent sums keep the floating-point adder busy, where
        // one sum waits on its own last addition.
        let mut c = a;
        while c + 4 <= p {
            let (y0, y1, y2, y3) = (
                &gathered[c],
                &gathered[c + 1],
                &gathered[c + 2],
                &gathered[c + 3],
            );
            let (mut s0, mut s1, mut s2, mut s3) = (0.0, 0.0, 0.0, 0.0);
            for ((((x, v0), v1), v2), v3) in xa.iter().zip(y0).zip(y1).zip(y2).zip(y3) {
                s0 += x * v0;
                s1 += x * v1;
                s2 += x * v2;
                s3 += x * v3;
            }
            row.extend([s0, s1, s2, s3]);
            c += 4;
        }
        for y in &gathered[c..p] {
            row.push(dot(xa, y));
        }
        (dot(xa, &t), row)
    };
    let upper: Vec<(f64, Vec<f64>)> = if parallel {
        (0..p).into_par_iter().map(gram_row).collect()
    } else {
        (0..p).map(gram_row).collect()
    };
    let mut g = DMatrix::<f64>::zeros(p, p);
    let mut b = DVector::<f64>::zeros(p);
    for (a, (ba, row)) in upper.into_iter().enumerate() {
        b[a] = ba;
        for (k, s) in row.into_iter().enumerate() {
            g[(a, a + k)] = s;
            g[(a + k, a)] = s;
        }
    }
    let mut active: Vec<bool> = (0..p).map(|j| g[(j, j)] > 0.0).collect();
    loop {
        let idx: Vec<usize> = (0..p).filter(|&j| active[j]).collect();
        let (x, inv_diag) = solve_sub(&g, &b, &idx);
        // Drop the most negative constrained coefficient and re-solve.
        let worst = idx
            .iter()
            .enumerate()
            .filter(|(k, j)| nonneg.get(**j).copied().unwrap_or(false) && x[*k] < 0.0)
            .min_by(|a, b| x[a.0].total_cmp(&x[b.0]));
        if let Some((_, &j)) = worst {
            active[j] = false;
            continue;
        }
        let mut coef = vec![0.0; p];
        for (k, &j) in idx.iter().enumerate() {
            coef[j] = x[k];
        }
        // rss = y'y - 2 c'b + c'Gc, evaluated directly for accuracy.
        let mut rss = 0.0;
        for &i in &rows {
            let mut pred = 0.0;
            for &j in &idx {
                pred += coef[j] * columns[j][i];
            }
            let r = target[i] - pred;
            rss += r * r;
        }
        let dof_used = idx.len();
        let sigma2 = if n > dof_used {
            rss / (n - dof_used) as f64
        } else {
            0.0
        };
        let mut std_err = vec![0.0; p];
        for (k, &j) in idx.iter().enumerate() {
            std_err[j] = (sigma2 * inv_diag[k]).max(0.0).sqrt();
        }
        // centred: an un-centred column (a pressure of 1e5 Pa beside an intercept) is a
        // benign representation, a huge varying term is not
        let nf = n.max(1) as f64;
        let mean_of = |x: &[f64]| rows.iter().map(|&i| x[i]).sum::<f64>() / nf;
        let ty = mean_of(target);
        let target_var = (yy / nf - ty * ty).max(0.0);
        let ill_conditioned = !rss.is_finite()
            || coef.iter().chain(&std_err).any(|v| !v.is_finite())
            || idx.iter().any(|&j| {
                let m = mean_of(columns[j]);
                let var = (g[(j, j)] / nf - m * m).max(0.0);
                coef[j] * coef[j] * var > CANCELLATION * CANCELLATION * target_var.max(1e-300)
            });
        return LsqFit {
            coef,
            std_err,
            rss,
            rows: n,
            dof_used,
            ill_conditioned,
        };
    }
}

/// Solves the sub-system on `idx` with Jacobi equilibration and a relative ridge of 1e-10,
/// returning the solution and the diagonal of the inverse Gram matrix.
fn solve_sub(g: &DMatrix<f64>, b: &DVector<f64>, idx: &[usize]) -> (Vec<f64>, Vec<f64>) {
    let k = idx.len();
    if k == 0 {
        return (Vec::new(), Vec::new());
    }
    let scale: Vec<f64> = idx
        .iter()
        .map(|&j| {
            let d = g[(j, j)];
            if d > 0.0 { 1.0 / d.sqrt() } else { 1.0 }
        })
        .collect();
    let mut a = DMatrix::<f64>::zeros(k, k);
    let mut r = DVector::<f64>::zeros(k);
    for (u, &ju) in idx.iter().enumerate() {
        r[u] = b[ju] * scale[u];
        for (v, &jv) in idx.iter().enumerate() {
            a[(u, v)] = g[(ju, jv)] * scale[u] * scale[v];
        }
        a[(u, u)] += 1e-10;
    }
    let chol = match a.clone().cholesky() {
        Some(c) => c,
        None => {
            for u in 0..k {
                a[(u, u)] += 1e-6;
            }
            match a.cholesky() {
                Some(c) => c,
                None => return (vec![0.0; k], vec![0.0; k]),
            }
        }
    };
    let x = chol.solve(&r);
    let inv = chol.inverse();
    let sol = (0..k).map(|u| x[u] * scale[u]).collect();
    let inv_diag = (0..k).map(|u| inv[(u, u)] * scale[u] * scale[u]).collect();
    (sol, inv_diag)
}

/// `sum coef_j * columns[j]` on every row.
pub fn predict(columns: &[&[f64]], coef: &[f64], n: usize) -> Vec<f64> {
    let mut out = vec![0.0; n];
    for (c, &k) in columns.iter().zip(coef) {
        if k != 0.0 {
            for i in 0..n {
                out[i] += k * c[i];
            }
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn recovers_exact_coefficients_and_standard_errors_scale() {
        let n = 200;
        let x1: Vec<f64> = (0..n).map(|i| (i as f64 * 0.1).sin()).collect();
        let x2: Vec<f64> = (0..n).map(|i| 1e3 * (i as f64 * 0.037).cos()).collect();
        let y: Vec<f64> = (0..n).map(|i| 2.0 * x1[i] - 3e-3 * x2[i]).collect();
        let mask = vec![true; n];
        let f = fit(&[&x1, &x2], &y, &mask, &[]);
        assert!((f.coef[0] - 2.0).abs() < 1e-8);
        assert!((f.coef[1] + 3e-3).abs() < 1e-10);
        assert!(f.rss < 1e-12);
    }

    #[test]
    fn nonnegativity_clamps_and_matches_reduced_fit() {
        let n = 100;
        let x1: Vec<f64> = (0..n).map(|i| i as f64 / n as f64).collect();
        let x2: Vec<f64> = (0..n).map(|i| ((i * 7) % 13) as f64).collect();
        let y: Vec<f64> = (0..n).map(|i| 1.5 * x1[i] - 0.2 * x2[i]).collect();
        let mask = vec![true; n];
        let c = fit(&[&x1, &x2], &y, &mask, &[false, true]);
        assert_eq!(c.coef[1], 0.0);
        let r = fit(&[&x1], &y, &mask, &[]);
        assert!((c.coef[0] - r.coef[0]).abs() < 1e-12);
        assert!((c.rss - r.rss).abs() < 1e-9 * r.rss.max(1.0));
    }

    #[test]
    fn nearly_collinear_columns_are_flagged_ill_conditioned() {
        let n = 300;
        let x1: Vec<f64> = (0..n).map(|i| (i as f64 * 0.05).sin()).collect();
        // a second column equal to the first up to a tiny difference that the target needs:
        // the fit cancels two coefficients of about 1e5
        let d: Vec<f64> = (0..n).map(|i| [1.0, -0.5, -0.5][i % 3]).collect();
        let x2: Vec<f64> = (0..n).map(|i| x1[i] + 1e-5 * d[i]).collect();
        let y: Vec<f64> = (0..n).map(|i| x1[i] + d[i]).collect();
        let mask = vec![true; n];
        let bad = fit(&[&x1, &x2], &y, &mask, &[]);
        assert!(bad.ill_conditioned, "{:?}", bad.coef);
        let good = fit(&[&x1, &d], &y, &mask, &[]);
        assert!(!good.ill_conditioned && (good.coef[1] - 1.0).abs() < 1e-9);
    }

    #[test]
    fn standard_error_matches_closed_form_for_a_mean() {
        // y = c + noise-like alternation: se(c) = s / sqrt(n)
        let n = 400;
        let y: Vec<f64> = (0..n)
            .map(|i| 5.0 + if i % 2 == 0 { 1.0 } else { -1.0 })
            .collect();
        let one = vec![1.0; n];
        let f = fit(&[&one], &y, &vec![true; n], &[]);
        let s = (n as f64 / (n as f64 - 1.0)).sqrt();
        assert!((f.coef[0] - 5.0).abs() < 1e-8);
        assert!((f.std_err[0] - s / (n as f64).sqrt()).abs() < 1e-9);
    }
}
