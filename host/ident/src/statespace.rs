//! Linear state-space baselines for dynamic `series` records:
//!
//! `x[k+1] = A x[k] + B (u[k] - u_mean)`, `y[k] = C x[k] + D u[k] + d`,
//!
//! identified by subspace identification (PO-MOESP: an LQ factorisation of block Hankel
//! matrices of inputs and outputs, the SVD of the future outputs' projection on the past gives
//! the extended observability matrix, hence `A` and `C`; `B` by least squares on the simulated
//! output), then refined by Levenberg-Marquardt on the free-run simulation error. `C`, `D` and
//! `d` enter linearly: given `(A, B)` the simulated states are regressors and the output map is
//! a least-squares fit (variable projection), which is also how the extensions are fitted
//! jointly with it. The order (0 to [`MAX_ORDER`], 0 being the static affine map) minimises the
//! BIC of the free-run training error. Every prediction is a free-run simulation: each trial
//! starts at rest for its first input and never sees a measured output.

use nalgebra::{DMatrix, DVector};

use crate::signal;

/// Largest order tried.
pub const MAX_ORDER: usize = 5;
/// Block rows of the Hankel matrices (past and future horizons), the longest that the
/// training windows allow first. The horizon must span a good part of the slowest mode's
/// period: with 10 block rows at 100 Hz a 0.5-2 Hz oscillator's observability estimate is
/// noise, and the refinement then starts far off (two-mass oscillators stopped at 4-10 % of
/// the static map's error, against 0.5 % with 30 block rows).
const HORIZONS: [usize; 3] = [30, 20, 10];
/// Most Hankel columns used (evenly thinned): enough for the subspace step, which the
/// free-run refinement then corrects on every training row.
const MAX_COLUMNS: usize = 6000;
/// Levenberg-Marquardt iterations of the free-run refinement.
const LM_ITERATIONS: usize = 20;
/// Most training rows scored in the refinement and the order choice (evenly thinned; the
/// simulation itself always runs over every row).
const MAX_SCORED_ROWS: usize = 4000;

/// A fitted linear state-space model (the output map is fitted per channel by the baseline).
#[derive(Debug, Clone)]
pub struct StateSpace {
    /// State matrix, `n x n`.
    pub a: DMatrix<f64>,
    /// Input matrix, `n x m`.
    pub b: DMatrix<f64>,
    /// Input means of the training rows (the state is driven by the deviations).
    pub u_mean: Vec<f64>,
    /// Per order tried: (order, training free-run RMSE pooled over outputs, BIC).
    pub orders: Vec<(usize, f64, f64)>,
    /// The refined `(A, B)` of the orders tried below the chosen one (lowest first).
    pub lower: Vec<(DMatrix<f64>, DMatrix<f64>)>,
    /// Samples of lag between where the input drives the states and where an extension's
    /// force acts (0: along `B`, as the input does); see [`StateSpace::force_entry`].
    pub entry_lag: f64,
}

impl StateSpace {
    /// The same model at a lower order tried by [`StateSpace::identify`] (`None` when that
    /// order was not tried).
    pub fn at_lower_order(&self, n: usize) -> Option<StateSpace> {
        let (a, b) = self.lower.iter().find(|(a, _)| a.nrows() == n)?;
        Some(StateSpace {
            a: a.clone(),
            b: b.clone(),
            u_mean: self.u_mean.clone(),
            orders: self.orders.clone(),
            lower: Vec::new(),
            entry_lag: 0.0,
        })
    }

    /// The same model with an extension's force entering after a lag of `lag` samples.
    pub fn with_entry_lag(&self, lag: f64) -> StateSpace {
        StateSpace {
            entry_lag: lag,
            ..self.clone()
        }
    }

    /// Where an extension's force enters the states, per input: `B + l (A - I) B` with `l`
    /// the [`StateSpace::entry_lag`] (in continuous time `(I + tau A_c) B`). When the input
    /// reaches the structure through a first-order lag of `l` samples (a pneumatic chamber's
    /// filling), that lag's mode has the eigenvalue `1 - 1/l`, so the factor removes it and
    /// keeps the rest: the force acts on the structure itself, not through the actuator. The
    /// choice does not depend on the state's coordinates.
    pub fn force_entry(a: &DMatrix<f64>, b: &DMatrix<f64>, lag: f64) -> DMatrix<f64> {
        if lag == 0.0 {
            return b.clone();
        }
        let n = a.nrows();
        b + (a - DMatrix::<f64>::identity(n, n)) * b * lag
    }

    /// Candidate entry lags (samples) from the real poles `0 < a < 1` of `A` and of the lower
    /// orders tried: `1 / (1 - a)`, kept between [`MIN_ENTRY_LAG`] and [`MAX_ENTRY_LAG`],
    /// lags within 20 % of a longer one dropped, longest first, at most [`ENTRY_LAGS`]. The
    /// lower orders count because an actuator's lag shows as a real pole at the plant's own
    /// order and can pair with another state into a complex pole above it.
    pub fn entry_lag_candidates(&self) -> Vec<f64> {
        let mut lags: Vec<f64> = std::iter::once(&self.a)
            .chain(self.lower.iter().map(|(a, _)| a))
            // nalgebra's Schur form indexes out of bounds on an empty matrix (order 0)
            .filter(|a| a.nrows() > 0)
            .flat_map(|a| a.complex_eigenvalues().iter().copied().collect::<Vec<_>>())
            .filter(|e| e.im.abs() < 1e-9 * e.re.abs().max(1.0) && e.re > 0.0 && e.re < 1.0)
            .map(|e| 1.0 / (1.0 - e.re))
            .filter(|l| (MIN_ENTRY_LAG..=MAX_ENTRY_LAG).contains(l))
            .collect();
        lags.sort_by(|a, b| b.total_cmp(a));
        let mut kept: Vec<f64> = Vec::new();
        for l in lags {
            if kept.last().is_none_or(|k| l < 0.8 * k) {
                kept.push(l);
            }
        }
        kept.truncate(ENTRY_LAGS);
        kept
    }

    /// The model order `n`.
    pub fn order(&self) -> usize {
        self.a.nrows()
    }

    /// Free-run states, `[state][row]`; each segment starts at rest for its first input.
    pub fn states(&self, inputs: &[&[f64]], starts: &[usize]) -> Vec<Vec<f64>> {
        let n = self.order();
        let rows = inputs.first().map(|u| u.len()).unwrap_or(0);
        let du: Vec<Vec<f64>> = inputs
            .iter()
            .zip(&self.u_mean)
            .map(|(u, m)| u.iter().map(|v| v - m).collect())
            .collect();
        let cols: Vec<&[f64]> = du.iter().map(|v| v.as_slice()).collect();
        simulate(&self.a, &self.b, &cols, starts, rows, n)
    }

    /// The free responses from each segment's initial state (see [`free_response_basis`]):
    /// regressors beside the states, so that a record that does not start at rest is not a
    /// transient misfit. Their coefficients are the initial state, fitted on training rows only.
    pub fn free_responses(&self, starts: &[usize], rows: usize) -> Vec<Vec<f64>> {
        free_response_basis(&self.a, starts, rows)
    }

    /// The response of an output with map `(c_row, d_k)` to a signal `f` entering the dynamics
    /// as a force of input `k` does (column `k` of [`StateSpace::force_entry`]), from rest at
    /// each segment start.
    pub fn filter(
        &self,
        f: &[f64],
        k: usize,
        c_row: &[f64],
        d_k: f64,
        starts: &[usize],
    ) -> Vec<f64> {
        let n = self.order();
        let bk = Self::force_entry(&self.a, &self.b, self.entry_lag)
            .columns(k, 1)
            .into_owned();
        let x = simulate(&self.a, &bk, &[f], starts, f.len(), n);
        let mut out: Vec<f64> = f.iter().map(|v| d_k * v).collect();
        for (j, xs) in x.iter().enumerate() {
            for i in 0..out.len() {
                out[i] += c_row[j] * xs[i];
            }
        }
        out
    }

    /// Identifies the model on the training rows (see the module docs).
    pub fn identify(
        inputs: &[&[f64]],
        outputs: &[&[f64]],
        starts: &[usize],
        train: &[bool],
    ) -> StateSpace {
        let m = inputs.len();
        let rows = train.len();
        let u_mean: Vec<f64> = inputs
            .iter()
            .map(|u| {
                let (s, k) = (0..rows)
                    .filter(|&i| train[i])
                    .fold((0.0, 0usize), |(s, k), i| (s + u[i], k + 1));
                if k > 0 { s / k as f64 } else { 0.0 }
            })
            .collect();
        let du: Vec<Vec<f64>> = inputs
            .iter()
            .zip(&u_mean)
            .map(|(u, mu)| u.iter().map(|v| v - mu).collect())
            .collect();
        let du_ref: Vec<&[f64]> = du.iter().map(|v| v.as_slice()).collect();
        let train_rows: Vec<usize> = (0..rows).filter(|&i| train[i]).collect();
        let stride = train_rows.len().div_ceil(MAX_SCORED_ROWS).max(1);
        let mut scored = vec![false; rows];
        for &i in train_rows.iter().step_by(stride) {
            scored[i] = true;
        }
        let ctx = FitContext {
            du: &du_ref,
            inputs,
            outputs,
            starts,
            train: &scored,
        };
        let n_obs = scored.iter().filter(|s| **s).count() * outputs.len();
        let k_out = outputs.len() * (m + 1);
        // segments whose initial state the training rows fit (see `free_response_basis`)
        let fitted_starts = signal::segments(starts, rows)
            .iter()
            .filter(|(s, e)| (*s..*e).any(|i| scored[i]))
            .count();
        let bic = |rss: f64, n: usize| {
            let k = n * (m + outputs.len()) + k_out + n * fitted_starts * outputs.len();
            n_obs as f64 * (rss / n_obs.max(1) as f64).max(1e-300).ln()
                + k as f64 * (n_obs.max(2) as f64).ln()
        };
        let static_rss = ctx.rss(&DMatrix::zeros(0, 0), &DMatrix::zeros(0, m));
        let mut orders = vec![(
            0,
            (static_rss / n_obs.max(1) as f64).sqrt(),
            bic(static_rss, 0),
        )];
        let mut best = (
            bic(static_rss, 0),
            DMatrix::zeros(0, 0),
            DMatrix::zeros(0, m),
        );
        let gamma = HORIZONS
            .iter()
            .find_map(|&h| observability(&du_ref, outputs, starts, train, h));
        let mut tried = Vec::new();
        for n in 1..=MAX_ORDER {
            let Some((a, b)) = gamma.as_ref().and_then(|(g, p)| initial_ab(g, *p, n, &ctx)) else {
                break;
            };
            let (a, b, rss) = ctx.refine(a, b);
            let score = bic(rss, n);
            orders.push((n, (rss / n_obs.max(1) as f64).sqrt(), score));
            tried.push((a.clone(), b.clone()));
            if score < best.0 {
                best = (score, a, b);
            } else if orders.len() >= 3 && orders[orders.len() - 2].2 > best.0 {
                // two orders in a row without a better criterion: higher ones fit noise
                break;
            }
        }
        let chosen = best.1.nrows();
        let lower = tried
            .into_iter()
            .filter(|(a, _)| a.nrows() < chosen)
            .collect();
        StateSpace {
            a: best.1,
            b: best.2,
            u_mean,
            orders,
            lower,
            entry_lag: 0.0,
        }
    }
}

/// Shortest entry lag tried (samples): a faster lag is within a sample of none.
pub const MIN_ENTRY_LAG: f64 = 2.0;
/// Longest entry lag tried (samples): slower real poles are drifts the record barely
/// determines, not an actuator.
pub const MAX_ENTRY_LAG: f64 = 60.0;
/// Most entry lags tried per record.
pub const ENTRY_LAGS: usize = 3;

/// States of `x[k+1] = A x[k] + B v[k]`, each segment starting at the rest state of its first
/// input (`x = (I - A)^-1 B v`, or zero when `I - A` is singular); `[state][row]`.
fn simulate(
    a: &DMatrix<f64>,
    b: &DMatrix<f64>,
    v: &[&[f64]],
    starts: &[usize],
    rows: usize,
    n: usize,
) -> Vec<Vec<f64>> {
    let mut out = vec![vec![0.0; rows]; n];
    if n == 0 {
        return out;
    }
    let m = v.len();
    let ia = DMatrix::<f64>::identity(n, n) - a;
    let lu = ia.lu();
    let mut x = vec![0.0; n];
    let mut nx = vec![0.0; n];
    // row-major copies: the inner loop runs rows x n x (n + m) times
    let af: Vec<f64> = (0..n)
        .flat_map(|j| (0..n).map(move |l| (j, l)))
        .map(|(j, l)| a[(j, l)])
        .collect();
    let bf: Vec<f64> = (0..n)
        .flat_map(|j| (0..m).map(move |k| (j, k)))
        .map(|(j, k)| b[(j, k)])
        .collect();
    for (s, e) in signal::segments(starts, rows) {
        let v0 = DVector::from_iterator(m, v.iter().map(|c| c[s]));
        let x0 = lu.solve(&(b * v0)).unwrap_or_else(|| DVector::zeros(n));
        for j in 0..n {
            x[j] = if x0[j].is_finite() { x0[j] } else { 0.0 };
        }
        for i in s..e {
            for j in 0..n {
                out[j][i] = x[j];
            }
            for j in 0..n {
                let ar = &af[j * n..(j + 1) * n];
                let br = &bf[j * m..(j + 1) * m];
                let mut acc: f64 = ar.iter().zip(&x).map(|(p, q)| p * q).sum();
                for (k, bk) in br.iter().enumerate() {
                    acc += bk * v[k][i];
                }
                nx[j] = acc;
            }
            std::mem::swap(&mut x, &mut nx);
        }
    }
    out
}

/// For each segment, an orthonormal basis of the sequences `c A^k x0` (k counted from the
/// segment's start, zero outside it) that any output row `c` and initial state `x0` give: by
/// Cayley-Hamilton they span at most `n` dimensions, and the `n` sequences `w A^k e_j` of one
/// generic row `w` span them when `(A, w)` is observable (Gram-Schmidt drops the dependent
/// ones otherwise). A record rarely starts at rest (the generator's oscillators start at zero
/// displacement under a non-zero force, a real rig wherever it was left); without these
/// columns the decaying transient is misfit that the refinement trades against the dynamics.
pub fn free_response_basis(a: &DMatrix<f64>, starts: &[usize], rows: usize) -> Vec<Vec<f64>> {
    let n = a.nrows();
    let mut out = Vec::new();
    if n == 0 {
        return out;
    }
    // row-major A for the row-vector recursion r <- r A
    let af: Vec<f64> = (0..n * n).map(|t| a[(t / n, t % n)]).collect();
    for (s, e) in signal::segments(starts, rows) {
        let len = e - s;
        let mut seq = vec![vec![0.0; len]; n];
        // a generic row: irrational-looking, alternating weights
        let mut r: Vec<f64> = (0..n)
            .map(|j| (1.0 + 0.618 * j as f64) * if j % 2 == 0 { 1.0 } else { -1.0 })
            .collect();
        let mut next = vec![0.0; n];
        let r0 = r.iter().map(|v| v.abs()).fold(0.0, f64::max);
        for k in 0..len {
            for j in 0..n {
                seq[j][k] = r[j];
            }
            let big = r.iter().map(|v| v.abs()).fold(0.0, f64::max);
            // a decayed transient: the remaining rows stay zero
            if big < 1e-13 * r0 || !big.is_finite() {
                break;
            }
            for (j, nj) in next.iter_mut().enumerate() {
                *nj = (0..n).map(|l| r[l] * af[l * n + j]).sum();
            }
            std::mem::swap(&mut r, &mut next);
        }
        let mut basis: Vec<Vec<f64>> = Vec::new();
        for v in seq {
            let norm0 = v.iter().map(|x| x * x).sum::<f64>().sqrt();
            if norm0 <= 0.0 || !norm0.is_finite() {
                continue;
            }
            let mut w = v;
            // modified Gram-Schmidt, twice for orthogonality in floating point
            for _ in 0..2 {
                for b in &basis {
                    let d: f64 = w.iter().zip(b).map(|(x, y)| x * y).sum();
                    for (x, y) in w.iter_mut().zip(b) {
                        *x -= d * y;
                    }
                }
            }
            let norm = w.iter().map(|x| x * x).sum::<f64>().sqrt();
            if norm > 1e-7 * norm0 {
                basis.push(w.iter().map(|x| x / norm).collect());
            }
        }
        for b in basis {
            let mut col = vec![0.0; rows];
            col[s..e].copy_from_slice(&b);
            out.push(col);
        }
    }
    out
}

/// Everything the free-run error of an `(A, B)` pair needs.
struct FitContext<'a> {
    du: &'a [&'a [f64]],
    inputs: &'a [&'a [f64]],
    outputs: &'a [&'a [f64]],
    starts: &'a [usize],
    train: &'a [bool],
}

impl FitContext<'_> {
    /// Training residuals of the free-run model, all outputs stacked (the output map fitted
    /// by least squares); `None` when the simulation is not finite.
    fn residuals(&self, a: &DMatrix<f64>, b: &DMatrix<f64>) -> Option<Vec<f64>> {
        let rows = self.train.len();
        let n = a.nrows();
        let x = simulate(a, b, self.du, self.starts, rows, n);
        if x.iter()
            .any(|s| s.iter().any(|v| !v.is_finite() || v.abs() > 1e150))
        {
            return None;
        }
        let ones = vec![1.0; rows];
        let free = free_response_basis(a, self.starts, rows);
        let mut cols: Vec<&[f64]> = x.iter().map(|s| s.as_slice()).collect();
        cols.extend(self.inputs.iter().copied());
        cols.push(&ones);
        cols.extend(free.iter().map(|v| v.as_slice()));
        let mut res = Vec::new();
        for y in self.outputs {
            let fit = crate::lsq::fit(&cols, y, self.train, &[]);
            let p = crate::lsq::predict(&cols, &fit.coef, rows);
            res.extend((0..rows).filter(|&i| self.train[i]).map(|i| y[i] - p[i]));
        }
        Some(res)
    }

    fn rss(&self, a: &DMatrix<f64>, b: &DMatrix<f64>) -> f64 {
        self.residuals(a, b)
            .map(|r| r.iter().map(|e| e * e).sum())
            .unwrap_or(f64::INFINITY)
    }

    /// Levenberg-Marquardt ([`crate::lm`]) on the entries of `(A, B)` minimising the free-run
    /// training error; returns the refined pair and its RSS.
    fn refine(&self, a: DMatrix<f64>, b: DMatrix<f64>) -> (DMatrix<f64>, DMatrix<f64>, f64) {
        let (n, m) = (a.nrows(), b.ncols());
        let pack = |a: &DMatrix<f64>, b: &DMatrix<f64>| -> Vec<f64> {
            a.iter().chain(b.iter()).copied().collect()
        };
        let unpack = |t: &[f64]| -> (DMatrix<f64>, DMatrix<f64>) {
            (
                DMatrix::from_column_slice(n, n, &t[..n * n]),
                DMatrix::from_column_slice(n, m, &t[n * n..]),
            )
        };
        let theta = pack(&a, &b);
        let Some(r) = self.residuals(&a, &b) else {
            return (a, b, f64::INFINITY);
        };
        let cost: f64 = r.iter().map(|e| e * e).sum();
        let settings = crate::lm::Settings {
            iterations: LM_ITERATIONS,
            tolerance: 1e-7,
            patience: 1,
            diag_floor: 1e-12,
            diag_add: 0.0,
            steps: crate::lm::Steps::Floor(1e-2),
            nonneg: &[],
        };
        let residuals = |t: &[f64]| {
            let (ta, tb) = unpack(t);
            self.residuals(&ta, &tb)
        };
        let (theta, _, cost, _) = crate::lm::minimise(theta, r, cost, &settings, &residuals);
        let (a, b) = unpack(&theta);
        (a, b, cost)
    }
}

/// The extended observability matrix from PO-MOESP on the training windows, with the number
/// of outputs; `None` when too few windows fit in the training rows.
fn observability(
    du: &[&[f64]],
    outputs: &[&[f64]],
    starts: &[usize],
    train: &[bool],
    horizon: usize,
) -> Option<(DMatrix<f64>, usize)> {
    let (m, p, s) = (du.len(), outputs.len(), horizon);
    let rows = train.len();
    // windows of 2s rows inside one segment and inside the training rows
    let mut valid = Vec::new();
    for (a, e) in signal::segments(starts, rows) {
        let mut run = 0usize;
        for i in a..e {
            run = if train[i] { run + 1 } else { 0 };
            if run >= 2 * s {
                valid.push(i + 1 - 2 * s);
            }
        }
    }
    let r = 2 * s * (m + p);
    if valid.len() < 4 * r {
        return None;
    }
    let stride = valid.len().div_ceil(MAX_COLUMNS);
    let cols: Vec<usize> = valid.into_iter().step_by(stride).collect();
    // outputs centred on the training windows (the constant is not a state)
    let n_train = (0..rows).filter(|&i| train[i]).count().max(1) as f64;
    let y_mean: Vec<f64> = outputs
        .iter()
        .map(|y| (0..rows).filter(|&i| train[i]).map(|i| y[i]).sum::<f64>() / n_train)
        .collect();
    // H^T: one row per window, columns [U_f, U_p, Y_p, Y_f]
    let mut h = DMatrix::<f64>::zeros(cols.len(), r);
    for (w, &j) in cols.iter().enumerate() {
        let mut c = 0;
        for off in [s, 0] {
            for t in 0..s {
                for u in du {
                    h[(w, c)] = u[j + off + t];
                    c += 1;
                }
            }
        }
        for off in [0, s] {
            for t in 0..s {
                for (y, mu) in outputs.iter().zip(&y_mean) {
                    h[(w, c)] = y[j + off + t] - mu;
                    c += 1;
                }
            }
        }
    }
    // H = L Q^T with L = R^T from the QR factorisation of H^T
    let rr = h.qr().r();
    let l = rr.transpose();
    let (r1, r2) = (s * m, s * (2 * m + p));
    let l32 = l.view((r2, r1), (s * p, r2 - r1)).into_owned();
    let svd = l32.svd(true, false);
    let u = svd.u?;
    // singular values are returned unsorted in general: order the left vectors by them
    let mut idx: Vec<usize> = (0..svd.singular_values.len()).collect();
    idx.sort_by(|&a, &b| svd.singular_values[b].total_cmp(&svd.singular_values[a]));
    let mut g = DMatrix::<f64>::zeros(s * p, idx.len());
    for (k, &i) in idx.iter().enumerate() {
        g.set_column(k, &(u.column(i) * svd.singular_values[i].sqrt()));
    }
    Some((g, p))
}

/// `A` from the shift structure of the first `n` observability columns, `B` by least squares
/// of the simulated outputs; `None` when the order exceeds what the data resolves.
fn initial_ab(
    g: &DMatrix<f64>,
    p: usize,
    n: usize,
    ctx: &FitContext,
) -> Option<(DMatrix<f64>, DMatrix<f64>)> {
    if n > g.ncols() || g.nrows() < p * (n + 1) {
        return None;
    }
    let gn = g.columns(0, n).into_owned();
    let rows = gn.nrows();
    let up = gn.rows(0, rows - p).into_owned();
    let down = gn.rows(p, rows - p).into_owned();
    let a = up.pseudo_inverse(1e-12).ok()? * down;
    // keep the start inside the unit circle: the refinement cannot cross an unstable region
    let a = {
        let rho = a
            .clone()
            .complex_eigenvalues()
            .iter()
            .map(|z| z.norm())
            .fold(0.0, f64::max);
        if rho >= 0.999 { a * (0.99 / rho) } else { a }
    };
    let c = gn.rows(0, p).into_owned();
    // B: the output is linear in B given (A, C): one simulation per entry
    let m = ctx.du.len();
    let rows_n = ctx.train.len();
    let mut regs: Vec<Vec<Vec<f64>>> = vec![Vec::new(); p]; // [output][entry][row]
    for k in 0..m {
        for i in 0..n {
            let mut e = DMatrix::<f64>::zeros(n, 1);
            e[(i, 0)] = 1.0;
            let x = simulate(&a, &e, &[ctx.du[k]], ctx.starts, rows_n, n);
            for (o, reg) in regs.iter_mut().enumerate() {
                let mut col = vec![0.0; rows_n];
                for (l, xs) in x.iter().enumerate() {
                    for t in 0..rows_n {
                        col[t] += c[(o, l)] * xs[t];
                    }
                }
                reg.push(col);
            }
        }
    }
    // stacked least squares over the outputs (shared B), with per-output D, constant and
    // initial state
    let free = free_response_basis(&a, ctx.starts, rows_n);
    let nb = n * m;
    let extra = m + 1 + free.len();
    let np = nb + p * extra;
    let mut gm = DMatrix::<f64>::zeros(np, np);
    let mut rhs = DVector::<f64>::zeros(np);
    let train_rows: Vec<usize> = (0..rows_n).filter(|&i| ctx.train[i]).collect();
    for o in 0..p {
        let mut cols: Vec<&[f64]> = regs[o].iter().map(|v| v.as_slice()).collect();
        let ones = vec![1.0; rows_n];
        let mut idx: Vec<usize> = (0..nb).collect();
        for k in 0..m {
            cols.push(ctx.inputs[k]);
            idx.push(nb + o * extra + k);
        }
        cols.push(&ones);
        idx.push(nb + o * extra + m);
        for (f, col) in free.iter().enumerate() {
            cols.push(col);
            idx.push(nb + o * extra + m + 1 + f);
        }
        let y = ctx.outputs[o];
        for (ca, &ia) in cols.iter().zip(&idx) {
            rhs[ia] += train_rows.iter().map(|&t| ca[t] * y[t]).sum::<f64>();
            for (cb, &ib) in cols.iter().zip(&idx) {
                gm[(ia, ib)] += train_rows.iter().map(|&t| ca[t] * cb[t]).sum::<f64>();
            }
        }
    }
    let scale: Vec<f64> = (0..np)
        .map(|i| {
            if gm[(i, i)] > 0.0 {
                1.0 / gm[(i, i)].sqrt()
            } else {
                1.0
            }
        })
        .collect();
    for i in 0..np {
        rhs[i] *= scale[i];
        for j in 0..np {
            gm[(i, j)] *= scale[i] * scale[j];
        }
        gm[(i, i)] += 1e-10;
    }
    let sol = gm.cholesky()?.solve(&rhs);
    let mut b = DMatrix::<f64>::zeros(n, m);
    for k in 0..m {
        for i in 0..n {
            b[(i, k)] = sol[k * n + i] * scale[k * n + i];
        }
    }
    Some((a, b))
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;
    use rand_distr::{Distribution, Normal};

    /// A lightly damped oscillator driven by a random multisine: the identified model must
    /// reproduce the free-run response on held-out rows to near the noise, at order 2.
    #[test]
    fn identifies_a_damped_oscillator_from_free_run_error() {
        let dt = 0.01;
        let rows = 3000;
        let (wn, zeta) = (2.0 * std::f64::consts::PI * 1.5, 0.08);
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(3);
        let u: Vec<f64> = (0..rows)
            .map(|i| {
                let t = i as f64 * dt;
                (0.7 * t).sin()
                    + 0.5 * (2.3 * t + 1.0).sin()
                    + 0.4 * (6.1 * t + 2.0).sin()
                    + 0.3 * (13.0 * t).sin()
            })
            .collect();
        let (mut x, mut v) = (0.0, 0.0);
        let mut y = Vec::with_capacity(rows);
        for i in 0..rows {
            y.push(x);
            // semi-implicit Euler on fine substeps
            for _ in 0..10 {
                let h = dt / 10.0;
                v += h * (u[i] - 2.0 * zeta * wn * v - wn * wn * x);
                x += h * v;
            }
        }
        let sd = 1e-3 * crate::signal::rms(&y);
        let nd = Normal::new(0.0, sd).unwrap();
        let y: Vec<f64> = y.iter().map(|v| v + nd.sample(&mut rng)).collect();
        let train: Vec<bool> = (0..rows).map(|i| i < 2100).collect();
        let ss = StateSpace::identify(&[&u], &[&y], &[0], &train);
        // the true order is 2; the criterion may add a state that it resolves
        assert!((2..=3).contains(&ss.order()), "orders {:?}", ss.orders);
        let x = ss.states(&[&u], &[0]);
        let ones = vec![1.0; rows];
        let free = ss.free_responses(&[0], rows);
        let mut cols: Vec<&[f64]> = x.iter().map(|s| s.as_slice()).collect();
        cols.push(&u);
        cols.push(&ones);
        cols.extend(free.iter().map(|v| v.as_slice()));
        let fit = crate::lsq::fit(&cols, &y, &train, &[]);
        let p = crate::lsq::predict(&cols, &fit.coef, rows);
        let e: Vec<f64> = (2100..rows).map(|i| y[i] - p[i]).collect();
        let rmse = crate::signal::rms(&e);
        // A record that does not start at rest: without the initial-state responses the
        // decaying transient biased the output map and the held-out error was 18.6x the noise;
        // with them it is at the noise (measured 0.96x).
        eprintln!(
            "held-out free-run RMSE {rmse:.3e} = {:.2} x noise, orders {:?}",
            rmse / sd,
            ss.orders
        );
        assert!(
            rmse < 1.5 * sd,
            "held-out free-run RMSE {rmse} vs noise {sd}"
        );
    }

    /// An actuator lag in front of an oscillator, `z+ = a z + (1 - a) u` driving
    /// `x+ = A_p x + b_p z`: the force entry at the lag `1 / (1 - a)` is exactly where `z`
    /// drives the oscillator, `[0, b_p]` (worked by hand: `B + l (A - I) B` with
    /// `(A - I) B = (1 - a) [a - 1, b_p]`), in any coordinates of the state, and the lag is
    /// among the candidates read from `A`'s real poles.
    #[test]
    fn the_force_entry_skips_an_actuator_lag() {
        let a_lag = 0.92;
        let (wn, zeta, dt) = (2.0 * std::f64::consts::PI, 0.1, 0.01);
        let a = DMatrix::from_row_slice(
            3,
            3,
            &[
                a_lag,
                0.0,
                0.0,
                0.0,
                1.0,
                dt,
                0.3 * dt,
                -wn * wn * dt,
                1.0 - 2.0 * zeta * wn * dt,
            ],
        );
        let b = DMatrix::from_column_slice(3, 1, &[1.0 - a_lag, 0.0, 0.0]);
        let lag = 1.0 / (1.0 - a_lag);
        let e = StateSpace::force_entry(&a, &b, lag);
        let want = [0.0, 0.0, 0.3 * dt];
        for j in 0..3 {
            assert!((e[(j, 0)] - want[j]).abs() < 1e-14, "{e}");
        }
        assert_eq!(StateSpace::force_entry(&a, &b, 0.0), b);
        // a change of coordinates T moves the entry with the state
        let t = DMatrix::from_row_slice(3, 3, &[1.0, 0.4, -0.2, 0.3, 2.0, 0.1, -0.5, 0.2, 1.5]);
        let ti = t.clone().try_inverse().unwrap();
        let et = StateSpace::force_entry(&(&t * &a * &ti), &(&t * &b), lag);
        let moved = &t * &e;
        for j in 0..3 {
            assert!((et[(j, 0)] - moved[j]).abs() < 1e-12, "{et} vs {moved}");
        }
        let ss = StateSpace {
            a,
            b,
            u_mean: vec![0.0],
            orders: Vec::new(),
            lower: Vec::new(),
            entry_lag: 0.0,
        };
        let c = ss.entry_lag_candidates();
        assert_eq!(c.len(), 1, "{c:?}");
        assert!((c[0] - lag).abs() < 1e-9 * lag, "{c:?}");
    }
}
