//! The direction test that tells dry friction from a static map of the inputs.
//!
//! Friction flips with the direction of motion; a static map of the inputs (the
//! `nonlinearity` extension) gives the same force whichever way the part moves. When an input
//! follows the direction of motion (a regulator's chamber pressure sags while the piston
//! extends), the two explain nearly the same residual and the information criterion may
//! prefer the map. The test compares rows that move in opposite directions at the same inputs:
//! the baseline's training residual is stratified into cells of equal inputs (quintiles of each
//! input), and in each cell with both directions `r = a + sum_k b_k (u_k - mean_k) + c dir` is
//! fitted (`dir` = +-1, the in-cell slopes absorb what the map varies within a cell). The
//! direction effects `c` are pooled by inverse variance. Rows of one passage in one direction
//! are not independent: each cell's standard error is inflated by `sqrt(rows / passages)`.

use serde::Serialize;

use crate::extension::Prepared;
use crate::lsq;

/// Input quantile bins per input.
const BINS: usize = 5;
/// Fewest rows of each direction in a cell.
const MIN_ROWS: usize = 10;
/// Pooled direction effect, in standard errors, that counts as a flip with the direction.
pub const SIGNIFICANCE: f64 = 4.0;

/// Result of the direction test on one output channel and one velocity source.
#[derive(Debug, Clone, Serialize)]
pub struct DirectionTest {
    /// Output channel.
    pub output: String,
    /// The state whose direction of motion is tested.
    pub state: String,
    /// Half the residual's difference between moving up and moving down at equal inputs
    /// (output units): the Coulomb level that a friction would have.
    pub effect: f64,
    /// Its standard error (passages, not rows, as independent units).
    pub std_err: f64,
    /// Cells with both directions.
    pub cells: usize,
    /// True when `|effect| > SIGNIFICANCE * std_err`.
    pub flips: bool,
}

/// The direction test of every output channel against every velocity source; empty when
/// the record has no state or no cell holds both directions.
pub fn direction_tests(prep: &Prepared) -> Vec<DirectionTest> {
    let rec = prep.rec;
    let n = rec.len();
    let k_in = rec.inputs.len();
    let mut out = Vec::new();
    if k_in == 0 || k_in > 3 {
        return out;
    }
    // the quantile cell of each row, on the training rows' quantiles
    let mut cell = vec![0usize; n];
    for inp in &rec.inputs {
        let mut tr: Vec<f64> = (0..n)
            .filter(|&i| prep.train[i])
            .map(|i| inp.values[i])
            .collect();
        if tr.is_empty() {
            return out;
        }
        tr.sort_by(|a, b| a.total_cmp(b));
        let edges: Vec<f64> = (1..BINS).map(|q| tr[q * tr.len() / BINS]).collect();
        for i in 0..n {
            let b = edges.iter().filter(|e| inp.values[i] >= **e).count();
            cell[i] = cell[i] * BINS + b;
        }
    }
    let cells = BINS.pow(k_in as u32);
    for (state, v, v0) in prep.velocities() {
        // moving rows only, with their direction; passages counted per direction change
        let dir: Vec<f64> = v
            .iter()
            .map(|x| {
                if *x > v0 {
                    1.0
                } else if *x < -v0 {
                    -1.0
                } else {
                    0.0
                }
            })
            .collect();
        for (c, ch) in prep.channels.iter().enumerate() {
            let r: Vec<f64> = ch.y.iter().zip(&ch.yhat).map(|(a, b)| a - b).collect();
            let (mut sw, mut swc, mut used) = (0.0, 0.0, 0usize);
            for q in 0..cells {
                let rows: Vec<usize> = (0..n)
                    .filter(|&i| prep.train[i] && cell[i] == q && dir[i] != 0.0)
                    .collect();
                let up = rows.iter().filter(|&&i| dir[i] > 0.0).count();
                let dn = rows.len() - up;
                if up < MIN_ROWS || dn < MIN_ROWS {
                    continue;
                }
                let passages = 1 + rows
                    .windows(2)
                    .filter(|w| w[1] != w[0] + 1 || dir[w[1]] != dir[w[0]])
                    .count();
                let mut mask = vec![false; n];
                for &i in &rows {
                    mask[i] = true;
                }
                let ones = vec![1.0; n];
                let centred: Vec<Vec<f64>> = rec
                    .inputs
                    .iter()
                    .map(|inp| {
                        let m =
                            rows.iter().map(|&i| inp.values[i]).sum::<f64>() / rows.len() as f64;
                        inp.values.iter().map(|x| x - m).collect()
                    })
                    .collect();
                let mut cols: Vec<&[f64]> = vec![&ones, &dir];
                cols.extend(centred.iter().map(|x| x.as_slice()));
                let fit = lsq::fit(&cols, &r, &mask, &[]);
                let se = fit.std_err[1] * (rows.len() as f64 / passages as f64).sqrt();
                if se > 0.0 && se.is_finite() && fit.coef[1].is_finite() {
                    let w = 1.0 / (se * se);
                    sw += w;
                    swc += w * fit.coef[1];
                    used += 1;
                }
            }
            if used == 0 {
                continue;
            }
            let effect = swc / sw;
            let std_err = 1.0 / sw.sqrt();
            out.push(DirectionTest {
                output: rec.outputs[c].name.clone(),
                state: state.clone(),
                effect,
                std_err,
                cells: used,
                flips: effect.abs() > SIGNIFICANCE * std_err,
            });
        }
    }
    out
}
