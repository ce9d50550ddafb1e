//! A discretised Preisach plane: relay hysterons `R_ab` (up at `u >= a`, down at `u <= b`,
//! held in between) on a grid of thresholds `a >= b` across the drive's range, weighted by
//! non-negative weights found by non-negative least squares (the Lawson-Hanson solver of
//! `ocm-mor`, the workspace's one NNLS). Every rate-independent hysteresis with wiping-out and
//! congruent minor loops is a Preisach model (Mayergoyz), Prandtl-Ishlinskii included, so the
//! plane is the most flexible variant of the `hysteresis` cause.

/// One relay's output over the record (`+1` up, `-1` down); each segment starts down unless
/// its first input is already above the up threshold (a history from below).
pub fn relay(u: &[f64], starts: &[usize], up: f64, down: f64) -> Vec<f64> {
    let mut out = vec![0.0; u.len()];
    for (s, e) in crate::signal::segments(starts, u.len()) {
        let mut state = -1.0;
        for i in s..e {
            if u[i] >= up {
                state = 1.0;
            } else if u[i] <= down {
                state = -1.0;
            }
            out[i] = state;
        }
    }
    out
}

/// The relays of a plane with `levels` thresholds evenly inside `[lo, hi]` (cell centres), for
/// every pair `up >= down`: `levels (levels + 1) / 2` columns, with their thresholds.
pub fn plane(
    u: &[f64],
    starts: &[usize],
    lo: f64,
    hi: f64,
    levels: usize,
) -> Vec<(f64, f64, Vec<f64>)> {
    let step = (hi - lo) / levels as f64;
    let at = |i: usize| lo + (i as f64 + 0.5) * step;
    let mut out = Vec::new();
    for a in 0..levels {
        for b in 0..=a {
            out.push((at(a), at(b), relay(u, starts, at(a), at(b))));
        }
    }
    out
}

/// Non-negative least squares of `target` on `nonneg` columns (weights >= 0) and `free`
/// columns (either sign), on the rows where `mask` holds (evenly thinned to at most
/// `max_rows`). The free columns are projected out first (for given weights their best
/// coefficients are a least-squares fit), so the solver sees a pure NNLS problem. Returns the
/// weights of the non-negative columns and the coefficients of the free ones; `None` when the
/// solver fails.
pub fn nnls_fit(
    nonneg: &[&[f64]],
    free: &[&[f64]],
    target: &[f64],
    mask: &[bool],
    max_rows: usize,
) -> Option<(Vec<f64>, Vec<f64>)> {
    let n = target.len();
    let rows_all: Vec<usize> = (0..n).filter(|&i| mask[i]).collect();
    let stride = rows_all.len().div_ceil(max_rows.max(1)).max(1);
    let rows: Vec<usize> = rows_all.into_iter().step_by(stride).collect();
    let nr = rows.len();
    if nr == 0 {
        return None;
    }
    let mut sub = vec![false; n];
    for &i in &rows {
        sub[i] = true;
    }
    let project = |col: &[f64]| -> Vec<f64> {
        if free.is_empty() {
            return rows.iter().map(|&i| col[i]).collect();
        }
        let fit = crate::lsq::fit(free, col, &sub, &[]);
        let p = crate::lsq::predict(free, &fit.coef, n);
        rows.iter().map(|&i| col[i] - p[i]).collect()
    };
    // columns scaled to unit norm (the solver's gradient test is scale-sensitive)
    let mut g = Vec::with_capacity(nr * nonneg.len());
    let mut scale = Vec::with_capacity(nonneg.len());
    for c in nonneg {
        let pc = project(c);
        let norm = pc.iter().map(|v| v * v).sum::<f64>().sqrt();
        let s = if norm > 1e-12 { 1.0 / norm } else { 0.0 };
        g.extend(pc.iter().map(|v| v * s));
        scale.push(s);
    }
    let b = project(target);
    let sol = ocm_mor::nnls::solve(&g, nr, nonneg.len(), &b, 1e-12).ok()?;
    let weights: Vec<f64> = sol.weights.iter().zip(&scale).map(|(w, s)| w * s).collect();
    let coef = if free.is_empty() {
        Vec::new()
    } else {
        let rest: Vec<f64> = (0..n)
            .map(|i| {
                target[i]
                    - nonneg
                        .iter()
                        .zip(&weights)
                        .map(|(c, w)| w * c[i])
                        .sum::<f64>()
            })
            .collect();
        crate::lsq::fit(free, &rest, &sub, &[]).coef
    };
    Some((weights, coef))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A hysteresis of the Preisach class that no play-operator (Prandtl-Ishlinskii) model
    /// reproduces: two relays with off-centre thresholds (a discontinuous, asymmetric loop).
    /// The plane's NNLS fit must reproduce it to rounding (the thresholds lie on the grid),
    /// with non-negative weights, and beat the best non-negative play-operator fit.
    #[test]
    fn nnls_on_the_plane_recovers_a_relay_hysteresis() {
        let n = 3000;
        let u: Vec<f64> = (0..n)
            .map(|i| {
                let t = i as f64 / n as f64;
                (2.0 * std::f64::consts::PI * 7.0 * t).sin() * (0.3 + 0.7 * t)
            })
            .collect();
        let (lo, hi) = (-1.0, 1.0);
        let levels = 8;
        let grid = plane(&u, &[0], lo, hi, levels);
        // two relays of the grid with weights 2 and 0.5, plus an offset
        let truth: Vec<f64> = (0..n)
            .map(|i| 2.0 * grid[20].2[i] + 0.5 * grid[9].2[i] + 0.3)
            .collect();
        let cols: Vec<&[f64]> = grid.iter().map(|g| g.2.as_slice()).collect();
        let ones = vec![1.0; n];
        let mask = vec![true; n];
        let (w, c) = nnls_fit(&cols, &[&ones], &truth, &mask, 10_000).unwrap();
        assert!(w.iter().all(|v| *v >= 0.0));
        let pred: Vec<f64> = (0..n)
            .map(|i| {
                c[0] + cols
                    .iter()
                    .zip(&w)
                    .map(|(col, wj)| wj * col[i])
                    .sum::<f64>()
            })
            .collect();
        let err = crate::signal::rms(
            &pred
                .iter()
                .zip(&truth)
                .map(|(a, b)| a - b)
                .collect::<Vec<_>>(),
        );
        assert!(err < 1e-8, "plane residual {err}");
        // play operators of six widths (and the input itself) leave a clear misfit
        let mut pi: Vec<Vec<f64>> = [0.005, 0.015, 0.035, 0.07, 0.14, 0.28]
            .iter()
            .map(|w| {
                let p = crate::signal::play(&u, &[0], w * (hi - lo));
                u.iter().zip(&p).map(|(a, b)| a - b).collect()
            })
            .collect();
        pi.push(u.clone());
        let pcols: Vec<&[f64]> = pi.iter().map(|v| v.as_slice()).collect();
        let fit = crate::lsq::fit(
            &[pcols.as_slice(), &[&ones]].concat(),
            &truth,
            &mask,
            &[true, true, true, true, true, true, false, false],
        );
        let pi_err = (fit.rss / n as f64).sqrt();
        assert!(
            pi_err > 1e3 * err.max(1e-12) && pi_err > 0.05,
            "PI {pi_err}"
        );
    }
}
