//! Operator inference (Peherstorfer & Willcox 2016, discrete-time form; the quadratic model of
//! Qian, Kramer, Peherstorfer & Willcox 2020): a non-intrusive reduced model fitted by regularised
//! least squares to the POD coordinates q_k = V^T u_k of the full model's training trajectories.
//!
//! The model is the two-step map
//!
//! q_{k+1} = A q_k + A2 q_{k-1} + H (q_k (x) q_k) + N (p_{k+1} (x) q_k) + B w_{k+1} + c
//!
//! (optionally more state and input lags, bilinear force-state and quadratic input terms),
//!
//! with w = (three chamber pressures in kPa, tip force in N), `q (x) q` the r(r+1)/2 unique products
//! q_i q_j (i <= j), and the optional bilinear terms `p (x) q` (the follower pressure load is
//! bilinear in pressure and position). Two lags, because the full model is second order: with
//! backward Euler the nodal velocity after step k is exactly (u_k - u_{k-1}) / dt, so (q_k, q_{k-1})
//! carries the reduced position and velocity. Every trajectory starts from rest (q_{-1} = q_{-2} = 0).
//!
//! Fit: the feature columns are scaled to unit root mean square, and the Tikhonov problem
//! min ||D Theta - Y||^2 + lambda n ||Theta||^2 (n rows) is solved through its normal equations
//! (D^T D + lambda n I) Theta = D^T Y by a Cholesky factorisation (faer `llt`): the Gram matrix is
//! formed once and every lambda of a regularisation path costs one p x p factorisation. A fit whose
//! linear part (the companion matrix of A, A2) has spectral radius >= 1, or whose free run leaves
//! the training range, is refused as unstable.

use crate::drive::Input;
use crate::rom::{ReducedStepReport, dot};
use crate::run::ReducedRun;
use crate::store::{ReducedProbe, basis_hash};
use crate::{MorError, Result, sha256_f64};
use faer::linalg::matmul::matmul;
use faer::linalg::solvers::Solve;
use faer::{Accum, Mat, Par, Side};
use nalgebra::{DMatrix, DVector};
use ocm_fem::npy;
use serde::{Deserialize, Serialize};
use std::path::Path;

/// Number of input channels: three chamber pressures (kPa) and the tip force (N, 3).
pub const INPUTS: usize = 6;
/// File format tag of `opinf.json`.
pub const OPINF_FORMAT: &str = "ocm-mor-opinf/1";
/// A free run is unstable once a coordinate exceeds this multiple of the training range.
pub const BLOW_UP_FACTOR: f64 = 10.0;

/// Which terms the inferred map carries besides the two linear lags, the inputs and the constant.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub struct OpInfTerms {
    /// Quadratic state terms H (q (x) q), unique products of the first `quadratic_modes`
    /// coordinates (0: none; more than r: all).
    pub quadratic_modes: usize,
    /// Bilinear pressure-state terms N (p (x) q).
    pub pressure_bilinear: bool,
    /// Coordinates the bilinear terms multiply (the first ones; more than r: all).
    pub bilinear_modes: usize,
    /// Bilinear force-state terms (F (x) q).
    #[serde(default)]
    pub force_bilinear: bool,
    /// Quadratic input terms E (w (x) w), unique products (a static nonlinearity in the inputs
    /// that feeds nothing back).
    #[serde(default)]
    pub input_quadratic: bool,
    /// State lags L >= 2: q_k, ..., q_{k-L+1} enter linearly (L > 2 adds memory of the truncated
    /// coordinates, an ARX form).
    #[serde(default = "two")]
    pub state_lags: usize,
    /// Input lags >= 1: w_{k+1}, ..., w_{k+2-lags} enter linearly.
    #[serde(default = "one")]
    pub input_lags: usize,
    /// The quadratic and bilinear state terms act on the new state q_{k+1} (as backward Euler's
    /// internal and follower forces do), so a step solves r polynomial equations by Newton.
    #[serde(default)]
    pub implicit: bool,
    /// Position-velocity terms q_i (q_j - q_{k-1,j}) of the first `quadratic_modes` coordinates
    /// (Rayleigh stiffness damping beta K(q) v is such a product).
    #[serde(default)]
    pub velocity_bilinear: bool,
}

fn two() -> usize {
    2
}

fn one() -> usize {
    1
}

impl OpInfTerms {
    /// Length of the feature vector for rank `r`.
    pub fn len(&self, r: usize) -> usize {
        let m = self.quadratic_modes.min(r);
        self.state_lags * r
            + m * (m + 1) / 2
            + if self.velocity_bilinear { m * m } else { 0 }
            + if self.pressure_bilinear {
                3 * self.bilinear_modes.min(r)
            } else {
                0
            }
            + if self.force_bilinear {
                3 * self.bilinear_modes.min(r)
            } else {
                0
            }
            + if self.input_quadratic {
                INPUTS * (INPUTS + 1) / 2
            } else {
                0
            }
            + self.input_lags * INPUTS
            + 1
    }

    /// Columns that carry no quadratic or bilinear term (lags, inputs, constant).
    pub fn is_linear(&self, r: usize, column: usize) -> bool {
        let p = self.len(r);
        column < self.state_lags * r || column >= p - self.input_lags * INPUTS - 1
    }

    /// Derivatives of the state-dependent quadratic and bilinear features with respect to the
    /// state they read: (column, coordinate, value) triples.
    pub fn state_jacobian(
        &self,
        qn: &[f64],
        w0: &[f64; INPUTS],
        out: &mut Vec<(usize, usize, f64)>,
    ) {
        out.clear();
        let r = qn.len();
        let mut k = self.state_lags * r;
        let m = self.quadratic_modes.min(r);
        for i in 0..m {
            for j in i..m {
                out.push((k, i, qn[j]));
                out.push((k, j, qn[i]));
                k += 1;
            }
        }
        if self.velocity_bilinear {
            // Only with explicit terms (qn = q_k); the implicit form does not use them.
            k += m * m;
        }
        let b = self.bilinear_modes.min(r);
        for (on, range) in [(self.pressure_bilinear, 0..3), (self.force_bilinear, 3..6)] {
            if on {
                for a in range {
                    for i in 0..b {
                        out.push((k, i, w0[a]));
                        k += 1;
                    }
                }
            }
        }
    }

    /// Checks the lags.
    pub fn validate(&self) -> Result<()> {
        if self.implicit && self.velocity_bilinear {
            return Err(MorError::Invalid(
                "operator inference: position-velocity terms are explicit only".into(),
            ));
        }
        if self.state_lags < 2 || self.input_lags < 1 {
            return Err(MorError::Invalid(format!(
                "operator inference: {} state lags and {} input lags (at least 2 and 1)",
                self.state_lags, self.input_lags
            )));
        }
        Ok(())
    }

    /// Writes the features of the states `q[l]` = q_{k-l} (l < state lags, newest first) and the
    /// inputs `w[l]` = w_{k+1-l} (l < input lags) into `out` (length [`Self::len`]).
    /// `qn` is the state the quadratic and bilinear terms read (q_k, or q_{k+1} when implicit).
    pub fn features(&self, q: &[&[f64]], qn: &[f64], w: &[&[f64; INPUTS]], out: &mut [f64]) {
        let r = q[0].len();
        for l in 0..self.state_lags {
            out[l * r..(l + 1) * r].copy_from_slice(q[l]);
        }
        let mut k = self.state_lags * r;
        let (qp, q, w0) = (q[1], qn, w[0]);
        let m = self.quadratic_modes.min(r);
        for i in 0..m {
            let qi = q[i];
            for j in i..m {
                out[k] = qi * q[j];
                k += 1;
            }
        }
        if self.velocity_bilinear {
            for i in 0..m {
                for j in 0..m {
                    out[k] = q[i] * (q[j] - qp[j]);
                    k += 1;
                }
            }
        }
        let b = self.bilinear_modes.min(r);
        if self.pressure_bilinear {
            for p in &w0[..3] {
                for &qi in &q[..b] {
                    out[k] = p * qi;
                    k += 1;
                }
            }
        }
        if self.force_bilinear {
            for f in &w0[3..] {
                for &qi in &q[..b] {
                    out[k] = f * qi;
                    k += 1;
                }
            }
        }
        if self.input_quadratic {
            for i in 0..INPUTS {
                for j in i..INPUTS {
                    out[k] = w0[i] * w0[j];
                    k += 1;
                }
            }
        }
        for l in 0..self.input_lags {
            out[k..k + INPUTS].copy_from_slice(w[l]);
            k += INPUTS;
        }
        out[k] = 1.0;
    }
}

/// The input vector w of one step: pressures (kPa), tip force (N).
pub fn input_vector(i: &Input) -> [f64; INPUTS] {
    let (p, f) = (i.pressure_kpa, i.tip_force_n);
    [p[0], p[1], p[2], f[0], f[1], f[2]]
}

/// A training trajectory: the reduced state after each step (from rest) and that step's inputs.
#[derive(Debug, Clone)]
pub struct Trajectory {
    /// q_k after step k, k = 0..n.
    pub q: Vec<Vec<f64>>,
    /// Inputs held over step k.
    pub inputs: Vec<[f64; INPUTS]>,
}

/// Tikhonov weights, relative to the unit-mean-square feature columns (1 adds as much to the Gram
/// diagonal as the data).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Regularisation {
    /// On the linear columns (lags, inputs, constant).
    pub linear: f64,
    /// On the quadratic and bilinear columns.
    pub nonlinear: f64,
}

impl Regularisation {
    /// Parses `LINEAR` or `LINEAR:NONLINEAR` (e.g. `1e-6:1e-2`).
    pub fn parse(text: &str) -> Result<Self> {
        let bad = || {
            MorError::Invalid(format!(
                "regularisation {text:?}: expected LINEAR or LINEAR:NONLINEAR, non-negative numbers"
            ))
        };
        let mut it = text.split(':');
        let num = |s: Option<&str>| -> Result<Option<f64>> {
            match s {
                None => Ok(None),
                Some(s) => match s.trim().parse::<f64>() {
                    Ok(v) if v >= 0.0 && v.is_finite() => Ok(Some(v)),
                    _ => Err(bad()),
                },
            }
        };
        let linear = num(it.next())?.ok_or_else(bad)?;
        let nonlinear = num(it.next())?.unwrap_or(linear);
        if it.next().is_some() {
            return Err(bad());
        }
        Ok(Regularisation { linear, nonlinear })
    }
}

/// The least-squares problem of a set of trajectories, formed once for a regularisation path.
#[derive(Debug, Clone)]
pub struct LeastSquares {
    terms: OpInfTerms,
    rank: usize,
    rows: usize,
    scale: Vec<f64>,
    gram: Mat<f64>,
    rhs: Mat<f64>,
}

/// Visits the (features, target) pairs of `trajs`.
fn for_each_row(
    trajs: &[Trajectory],
    terms: OpInfTerms,
    rank: usize,
    mut f: impl FnMut(&[f64], &[f64]),
) {
    let zero = vec![0.0; rank];
    let zw = [0.0; INPUTS];
    let mut phi = vec![0.0; terms.len(rank)];
    for t in trajs {
        for k in 0..t.q.len() {
            // Before the first step the robot rests with zero inputs.
            let q: Vec<&[f64]> = (0..terms.state_lags)
                .map(|l| {
                    if k > l {
                        t.q[k - 1 - l].as_slice()
                    } else {
                        zero.as_slice()
                    }
                })
                .collect();
            let w: Vec<&[f64; INPUTS]> = (0..terms.input_lags)
                .map(|l| if k >= l { &t.inputs[k - l] } else { &zw })
                .collect();
            let qn = if terms.implicit {
                t.q[k].as_slice()
            } else {
                q[0]
            };
            terms.features(&q, qn, &w, &mut phi);
            f(&phi, &t.q[k]);
        }
    }
}

impl LeastSquares {
    /// Forms the scaled Gram matrix and right-hand side of `trajs` (every state of rank `rank`).
    pub fn new(trajs: &[Trajectory], terms: OpInfTerms, rank: usize) -> Result<Self> {
        terms.validate()?;
        for (i, t) in trajs.iter().enumerate() {
            if t.q.len() != t.inputs.len() || t.q.iter().any(|q| q.len() != rank) {
                return Err(MorError::Invalid(format!(
                    "operator inference: trajectory {i} has {} states and {} inputs, or a state \
                     not of rank {rank}",
                    t.q.len(),
                    t.inputs.len()
                )));
            }
            if t.q
                .iter()
                .flatten()
                .chain(t.inputs.iter().flatten())
                .any(|x| !x.is_finite())
            {
                return Err(MorError::Invalid(format!(
                    "operator inference: trajectory {i} holds a non-finite value"
                )));
            }
        }
        let p = terms.len(rank);
        let rows: usize = trajs.iter().map(|t| t.q.len()).sum();
        if rows == 0 {
            return Err(MorError::Invalid(
                "operator inference: no training states".into(),
            ));
        }
        let mut d = Mat::<f64>::zeros(rows, p);
        let mut y = Mat::<f64>::zeros(rows, rank);
        let mut i = 0;
        for_each_row(trajs, terms, rank, |phi, q| {
            for (j, v) in phi.iter().enumerate() {
                d[(i, j)] = *v;
            }
            for (j, v) in q.iter().enumerate() {
                y[(i, j)] = *v;
            }
            i += 1;
        });
        let scale: Vec<f64> = (0..p)
            .map(|j| {
                let ms = d.col(j).iter().map(|x| x * x).sum::<f64>() / rows as f64;
                if ms > 0.0 { ms.sqrt() } else { 1.0 }
            })
            .collect();
        for j in 0..p {
            let s = 1.0 / scale[j];
            for v in d.col_mut(j).iter_mut() {
                *v *= s;
            }
        }
        let mut gram = Mat::<f64>::zeros(p, p);
        matmul(
            gram.as_mut(),
            Accum::Replace,
            d.transpose(),
            d.as_ref(),
            1.0,
            Par::rayon(0),
        );
        let mut rhs = Mat::<f64>::zeros(p, rank);
        matmul(
            rhs.as_mut(),
            Accum::Replace,
            d.transpose(),
            y.as_ref(),
            1.0,
            Par::rayon(0),
        );
        Ok(LeastSquares {
            terms,
            rank,
            rows,
            scale,
            gram,
            rhs,
        })
    }

    /// Rows (training states).
    pub fn rows(&self) -> usize {
        self.rows
    }

    /// The operator (r x p, unscaled) of regularisation `lambda` (relative to the unit-mean-square
    /// features: lambda = 1 adds as much to the Gram diagonal as the data).
    pub fn solve(&self, lambda: f64) -> Result<DMatrix<f64>> {
        self.solve_split(Regularisation {
            linear: lambda,
            nonlinear: lambda,
        })
    }

    /// The operator of a regularisation with separate weights on the linear columns (lags,
    /// inputs, constant) and on the quadratic and bilinear ones.
    pub fn solve_split(&self, reg: Regularisation) -> Result<DMatrix<f64>> {
        let lambda = reg;
        for l in [reg.linear, reg.nonlinear] {
            if !(l >= 0.0 && l.is_finite()) {
                return Err(MorError::Invalid(format!(
                    "operator inference: regularisation {l} is not a finite non-negative number"
                )));
            }
        }
        let p = self.scale.len();
        let mut g = self.gram.clone();
        for j in 0..p {
            let l = if self.terms.is_linear(self.rank, j) {
                reg.linear
            } else {
                reg.nonlinear
            };
            g[(j, j)] += l * self.rows as f64;
        }
        let llt = g.llt(Side::Lower).map_err(|e| {
            MorError::Solve(format!(
                "operator inference: the regularised Gram matrix is not positive definite \
                 ({lambda:?}: {e:?}); raise the regularisation"
            ))
        })?;
        let theta = llt.solve(&self.rhs);
        Ok(DMatrix::from_fn(self.rank, p, |i, j| {
            theta[(j, i)] / self.scale[j]
        }))
    }

    /// The terms of the features.
    pub fn terms(&self) -> OpInfTerms {
        self.terms
    }
}

/// Relative fit residual ||D O^T - Y||_F / ||Y||_F of `operator` on `trajs` (one-step error).
pub fn fit_residual(trajs: &[Trajectory], terms: OpInfTerms, operator: &DMatrix<f64>) -> f64 {
    let r = operator.nrows();
    let (mut num, mut den) = (0.0, 0.0);
    for_each_row(trajs, terms, r, |phi, q| {
        for i in 0..r {
            let pred: f64 = operator.row(i).iter().zip(phi).map(|(a, b)| a * b).sum();
            num += (pred - q[i]).powi(2);
            den += q[i] * q[i];
        }
    });
    (num / den.max(f64::MIN_POSITIVE)).sqrt()
}

/// An inferred reduced model.
#[derive(Debug, Clone)]
pub struct OpInfModel {
    /// Terms of the map.
    pub terms: OpInfTerms,
    /// Operator, r x p (columns: the features of [`OpInfTerms::features`]).
    pub operator: DMatrix<f64>,
    /// Operator rows, row-major (the step's dot products read them contiguously).
    rows: Vec<f64>,
    /// Largest |q_i| a free run may reach before it counts as blown up.
    pub state_bound: f64,
    /// Time step the map advances, s.
    pub dt_s: f64,
}

/// The state of an inferred model: the last reduced coordinates and inputs.
#[derive(Debug, Clone)]
pub struct OpInfState {
    /// q_k, q_{k-1}, ... (newest first, state lags long).
    pub q: Vec<Vec<f64>>,
    /// w_k, w_{k-1}, ... (newest first, input lags - 1 long).
    pub w: Vec<[f64; INPUTS]>,
}

impl OpInfModel {
    /// A model of `operator` (r x p).
    pub fn new(
        terms: OpInfTerms,
        operator: DMatrix<f64>,
        state_bound: f64,
        dt_s: f64,
    ) -> Result<Self> {
        terms.validate()?;
        let r = operator.nrows();
        if operator.ncols() != terms.len(r) {
            return Err(MorError::Invalid(format!(
                "operator inference: operator has {} columns, rank {r} with {terms:?} needs {}",
                operator.ncols(),
                terms.len(r)
            )));
        }
        if operator.iter().any(|x| !x.is_finite()) {
            return Err(MorError::Invalid(
                "operator inference: operator holds a non-finite value".into(),
            ));
        }
        let mut rows = Vec::with_capacity(operator.len());
        for i in 0..r {
            rows.extend(operator.row(i).iter());
        }
        Ok(OpInfModel {
            terms,
            operator,
            rows,
            state_bound,
            dt_s,
        })
    }

    /// Rank r.
    pub fn rank(&self) -> usize {
        self.operator.nrows()
    }

    /// The rest state.
    pub fn rest_state(&self) -> OpInfState {
        OpInfState {
            q: vec![vec![0.0; self.rank()]; self.terms.state_lags],
            w: vec![[0.0; INPUTS]; self.terms.input_lags - 1],
        }
    }

    /// Spectral radius of the linear part: the companion matrix of the state lags,
    /// [[A_1, ..., A_L], [I, 0, ...], ...], of the map linearised at rest.
    pub fn spectral_radius(&self) -> Result<f64> {
        let r = self.rank();
        let n = self.terms.state_lags * r;
        let c = Mat::<f64>::from_fn(n, n, |i, j| {
            if i < r {
                self.operator[(i, j)]
            } else if j + r == i {
                1.0
            } else {
                0.0
            }
        });
        let ev = c
            .eigenvalues()
            .map_err(|e| MorError::Solve(format!("operator inference: eigenvalues: {e:?}")))?;
        Ok(ev.iter().map(|z| z.norm()).fold(0.0, f64::max))
    }

    /// Refuses a model whose linear part is not contracting.
    pub fn check_stable(&self) -> Result<f64> {
        let rho = self.spectral_radius()?;
        if rho.is_finite() && rho < 1.0 {
            Ok(rho)
        } else {
            Err(MorError::Solve(format!(
                "operator inference: unstable fit (spectral radius of the linear part {rho:.6} >= 1)"
            )))
        }
    }

    /// Advances `s` by one step under `w`; `phi` is scratch of length p.
    pub fn step(&self, s: &mut OpInfState, w: &[f64; INPUTS], phi: &mut [f64]) -> Result<()> {
        let r = self.rank();
        let p = phi.len();
        let ws: Vec<&[f64; INPUTS]> = std::iter::once(w).chain(&s.w).collect();
        let mut x = s.q[0].clone();
        let mut xn = vec![0.0; r];
        let mut jac = vec![];
        let mut converged = !self.terms.implicit;
        for _ in 0..if self.terms.implicit { 30 } else { 1 } {
            let q: Vec<&[f64]> = s.q.iter().map(Vec::as_slice).collect();
            self.terms.features(&q, &x, &ws, phi);
            for i in 0..r {
                xn[i] = dot(&self.rows[i * p..(i + 1) * p], phi);
            }
            if !self.terms.implicit {
                break;
            }
            // Newton on g(x) = x - O phi(x): J = I - O dphi/dx.
            self.terms.state_jacobian(&x, w, &mut jac);
            let mut j = DMatrix::<f64>::identity(r, r);
            for &(col, c, v) in &jac {
                for i in 0..r {
                    j[(i, c)] -= self.rows[i * p + col] * v;
                }
            }
            let g = DVector::from_fn(r, |i, _| x[i] - xn[i]);
            let Some(dx) = j.lu().solve(&g) else {
                break;
            };
            let (mut nd, mut nx) = (0.0, 0.0);
            for i in 0..r {
                x[i] -= dx[i];
                nd += dx[i] * dx[i];
                nx += x[i] * x[i];
            }
            if nd <= 1e-24 * nx.max(1e-300) {
                converged = true;
                xn.copy_from_slice(&x);
                break;
            }
        }
        if !converged {
            return Err(MorError::Solve(
                "operator inference: the implicit step did not converge".into(),
            ));
        }
        drop(ws);
        // Shift the histories: the oldest state's buffer becomes q_{k+1}.
        s.q.rotate_right(1);
        s.q[0].copy_from_slice(&xn);
        if !s.w.is_empty() {
            s.w.rotate_right(1);
            s.w[0] = *w;
        }
        if s.q[0]
            .iter()
            .any(|x| !x.is_finite() || x.abs() > self.state_bound)
        {
            return Err(MorError::Solve(format!(
                "operator inference: the free run left the training range (|q| > {:.3e}): unstable",
                self.state_bound
            )));
        }
        Ok(())
    }

    /// Free run from rest over `inputs`: q after each step.
    pub fn simulate(&self, inputs: &[Input]) -> Result<Vec<Vec<f64>>> {
        let mut s = self.rest_state();
        let mut phi = vec![0.0; self.terms.len(self.rank())];
        let mut out = Vec::with_capacity(inputs.len());
        for (k, i) in inputs.iter().enumerate() {
            self.step(&mut s, &input_vector(i), &mut phi)
                .map_err(|e| MorError::Solve(format!("step {k}: {e}")))?;
            out.push(s.q[0].clone());
        }
        Ok(out)
    }

    /// Free run with X_S after each step (velocity (q_k - q_{k-1}) / dt, as backward Euler's) and
    /// the wall time of each step alone.
    pub fn run(&self, probe: &ReducedProbe, inputs: &[Input]) -> Result<ReducedRun> {
        let mut s = self.rest_state();
        let mut phi = vec![0.0; self.terms.len(self.rank())];
        let mut xs = Vec::with_capacity(inputs.len());
        let mut step_seconds = Vec::with_capacity(inputs.len());
        for (k, i) in inputs.iter().enumerate() {
            let w = input_vector(i);
            let t0 = std::time::Instant::now();
            self.step(&mut s, &w, &mut phi)
                .map_err(|e| MorError::Solve(format!("step {k}: {e}")))?;
            step_seconds.push(t0.elapsed().as_secs_f64());
            let q = DVector::from_column_slice(&s.q[0]);
            let v = (&q - DVector::from_column_slice(&s.q[1])) / self.dt_s;
            xs.push(probe.compact_state(&q, &v));
        }
        Ok(ReducedRun {
            xs,
            step_seconds,
            report: ReducedStepReport::default(),
        })
    }
}

/// Largest |q_i| over `trajs`, times [`BLOW_UP_FACTOR`].
pub fn state_bound(trajs: &[Trajectory]) -> f64 {
    BLOW_UP_FACTOR
        * trajs
            .iter()
            .flat_map(|t| t.q.iter().flatten())
            .fold(0.0f64, |m, x| m.max(x.abs()))
}

/// One point of a regularisation path.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct PathPoint {
    /// Regularisation.
    pub lambda: Regularisation,
    /// Relative one-step fit residual on the fitting trajectories.
    pub fit_residual: f64,
    /// Spectral radius of the linear part.
    pub spectral_radius: f64,
    /// Free-run validation error (the caller's score, e.g. TCP RMSE in mm); NaN when unstable.
    pub validation_error: f64,
}

/// Fits `train` along `lambdas`, scores each stable fit's free run by `score` (lower is better;
/// `Err` = unstable) and returns the path and the best lambda (None when every fit is unstable).
pub fn regularisation_path(
    train: &[Trajectory],
    terms: OpInfTerms,
    rank: usize,
    dt_s: f64,
    lambdas: &[Regularisation],
    score: &mut dyn FnMut(&OpInfModel) -> Result<f64>,
) -> Result<(Vec<PathPoint>, Option<Regularisation>)> {
    let ls = LeastSquares::new(train, terms, rank)?;
    let bound = state_bound(train);
    let mut path = vec![];
    let mut best: Option<(Regularisation, f64)> = None;
    for &lambda in lambdas {
        let op = ls.solve_split(lambda)?;
        let fit = fit_residual(train, terms, &op);
        let m = OpInfModel::new(terms, op, bound, dt_s)?;
        let rho = m.spectral_radius()?;
        let val = if rho < 1.0 {
            // A free run that blows up scores NaN: rejected, not reported.
            score(&m).unwrap_or(f64::NAN)
        } else {
            f64::NAN
        };
        if val.is_finite() && best.is_none_or(|(_, b)| val < b) {
            best = Some((lambda, val));
        }
        path.push(PathPoint {
            lambda,
            fit_residual: fit,
            spectral_radius: rho,
            validation_error: val,
        });
    }
    Ok((path, best.map(|b| b.0)))
}

/// What `ocm mor reduce --method opinf` stored beside `opinf.npy`.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct OpInfRecord {
    /// Format tag, [`OPINF_FORMAT`].
    pub format: String,
    /// Hash of the basis the coordinates are taken in.
    pub basis_hash: String,
    /// SHA-256 of the operator (row-major values and shape).
    pub operator_hash: String,
    /// Rank r.
    pub rank: usize,
    /// Terms of the map.
    pub terms: OpInfTerms,
    /// Features p (columns of the operator).
    pub features: usize,
    /// Chosen regularisation.
    pub lambda: Regularisation,
    /// Time step, s.
    pub dt_s: f64,
    /// Blow-up bound on |q_i|.
    pub state_bound: f64,
    /// Spectral radius of the linear part.
    pub spectral_radius: f64,
    /// Training sequences of the final fit.
    pub training_sequences: usize,
    /// Validation sequences the regularisation was chosen on (the last training ones).
    pub validation_sequences: usize,
    /// The regularisation path (validation error: free-run TCP RMSE, mm).
    pub path: Vec<PathPoint>,
}

/// SHA-256 of an operator (shape and row-major values).
pub fn operator_hash(op: &DMatrix<f64>) -> String {
    let mut v = vec![op.nrows() as f64, op.ncols() as f64];
    for i in 0..op.nrows() {
        v.extend(op.row(i).iter());
    }
    sha256_f64(&v)
}

/// SHA-256 identifying an inferred model: its basis hash and operator hash.
pub fn model_hash(rec: &OpInfRecord) -> String {
    crate::sha256_hex(format!("{}|{}", rec.basis_hash, rec.operator_hash).as_bytes())
}

/// Writes `DIR/opinf.npy` (r x p, row-major) and `DIR/opinf.json`.
pub fn save(dir: &Path, m: &OpInfModel, rec: &OpInfRecord) -> Result<()> {
    std::fs::create_dir_all(dir).map_err(|e| MorError::io(dir, e))?;
    let (r, p) = m.operator.shape();
    npy::write_f64_2d_path(dir.join("opinf.npy"), &m.rows, r, p)?;
    let jp = dir.join("opinf.json");
    std::fs::write(
        &jp,
        serde_json::to_string_pretty(rec).map_err(|e| MorError::Invalid(e.to_string()))?,
    )
    .map_err(|e| MorError::io(&jp, e))
}

/// Reads an inferred model for `basis`; checks format, basis hash, shape, operator hash and
/// stability, naming the file at fault.
pub fn load(dir: &Path, basis: &DMatrix<f64>) -> Result<(OpInfModel, OpInfRecord)> {
    let jp = dir.join("opinf.json");
    let text = std::fs::read_to_string(&jp).map_err(|e| MorError::io(&jp, e))?;
    let rec: OpInfRecord = serde_json::from_str(&text)
        .map_err(|e| MorError::file(&jp, format!("not an operator-inference record: {e}")))?;
    if rec.format != OPINF_FORMAT {
        return Err(MorError::file(
            &jp,
            format!("format {:?}, expected {OPINF_FORMAT:?}", rec.format),
        ));
    }
    if rec.basis_hash != basis_hash(basis) {
        return Err(MorError::file(
            &jp,
            "made for another basis (basis hash differs)",
        ));
    }
    if rec.rank != basis.ncols() || rec.features != rec.terms.len(rec.rank) {
        return Err(MorError::file(
            &jp,
            format!(
                "rank {} with {} features does not fit the basis of rank {}",
                rec.rank,
                rec.features,
                basis.ncols()
            ),
        ));
    }
    let np = dir.join("opinf.npy");
    let a = npy::read_f64_2d(&np)?;
    if (a.rows, a.cols) != (rec.rank, rec.features) {
        return Err(MorError::file(
            &np,
            format!(
                "shape ({}, {}) but opinf.json says ({}, {})",
                a.rows, a.cols, rec.rank, rec.features
            ),
        ));
    }
    let op = DMatrix::from_row_slice(a.rows, a.cols, &a.data);
    if operator_hash(&op) != rec.operator_hash {
        return Err(MorError::file(
            &np,
            "operator hash differs from opinf.json (modified or corrupt)",
        ));
    }
    let m = OpInfModel::new(rec.terms, op, rec.state_bound, rec.dt_s)
        .map_err(|e| MorError::file(&np, e.to_string()))?;
    m.check_stable()
        .map_err(|e| MorError::file(&np, e.to_string()))?;
    Ok((m, rec))
}

/// Reduced trajectories V^T u of the first `sequences` sequences of stored snapshots, with their
/// inputs (regenerated from the snapshots' seed).
pub fn snapshot_trajectories(
    s: &crate::store::Snapshots,
    basis: &DMatrix<f64>,
    sequences: std::ops::Range<usize>,
) -> Result<Vec<Trajectory>> {
    let (n, steps) = (s.disp.cols, s.rec.steps);
    if basis.nrows() != n {
        return Err(MorError::Invalid(format!(
            "basis has {} rows, the snapshots {n} DOFs",
            basis.nrows()
        )));
    }
    let r = basis.ncols();
    let drive = crate::drive::DriveConfig {
        dt_s: s.rec.dt_s,
        ..crate::drive::DriveConfig::default()
    };
    let vt = Mat::<f64>::from_fn(r, n, |i, j| basis[(j, i)]);
    sequences
        .map(|k| {
            let x = s.matrix(k * steps, (k + 1) * steps);
            let mut q = Mat::<f64>::zeros(r, steps);
            matmul(
                q.as_mut(),
                Accum::Replace,
                vt.as_ref(),
                x.as_ref(),
                1.0,
                Par::rayon(0),
            );
            Ok(Trajectory {
                q: (0..steps)
                    .map(|j| (0..r).map(|i| q[(i, j)]).collect())
                    .collect(),
                inputs: crate::drive::sequence(&drive, s.rec.seed, k as u64, steps)
                    .iter()
                    .map(input_vector)
                    .collect(),
            })
        })
        .collect()
}

/// Free-run TCP RMSE (mm) of `m` over sequences `seqs` of the snapshots, against their stored X_S,
/// and the wall time of every step.
pub fn snapshot_tcp_rmse_mm(
    m: &OpInfModel,
    probe: &ReducedProbe,
    s: &crate::store::Snapshots,
    seqs: std::ops::Range<usize>,
) -> Result<(f64, Vec<f64>)> {
    let steps = s.rec.steps;
    let drive = crate::drive::DriveConfig {
        dt_s: s.rec.dt_s,
        ..crate::drive::DriveConfig::default()
    };
    let (mut sq, mut n, mut times) = (0.0, 0usize, vec![]);
    for k in seqs {
        let inputs = crate::drive::sequence(&drive, s.rec.seed, k as u64, steps);
        let run = m
            .run(probe, &inputs)
            .map_err(|e| MorError::Solve(format!("sequence {k}: {e}")))?;
        let full: Vec<_> = (0..steps).map(|j| s.xs_row(k * steps + j)).collect();
        let e = crate::run::tcp_rmse_mm(&run.xs, &full)?;
        sq += e * e * steps as f64;
        n += steps;
        times.extend(run.step_seconds);
    }
    Ok(((sq / n.max(1) as f64).sqrt(), times))
}

/// How to fit an inferred model to stored snapshots.
#[derive(Debug, Clone)]
pub struct FitOptions {
    /// Terms of the map.
    pub terms: OpInfTerms,
    /// Regularisations to try.
    pub lambdas: Vec<Regularisation>,
    /// The last training sequences of the main snapshots hold out for choosing the
    /// regularisation (then refitted with all).
    pub validation_sequences: usize,
}

/// Fits an inferred model on the training sequences of `s` (and every sequence of `extra`, other
/// seeds' snapshots of the same model): the regularisation with the smallest free-run TCP RMSE on
/// the last `validation_sequences` training sequences of `s` wins, and the map is refitted on all
/// training sequences with it. Held-out sequences of `s` are never read.
pub fn fit_snapshots(
    s: &crate::store::Snapshots,
    extra: &[&crate::store::Snapshots],
    basis: &DMatrix<f64>,
    probe: &crate::xs::XsProbe,
    opts: &FitOptions,
) -> Result<(OpInfModel, OpInfRecord)> {
    let nseq = s.rec.sequences;
    let nval = opts.validation_sequences;
    if nval == 0 || nval >= nseq {
        return Err(MorError::Invalid(format!(
            "operator inference: {nval} validation sequences of {nseq} training ones (need 1..{nseq})"
        )));
    }
    if opts.lambdas.is_empty() {
        return Err(MorError::Invalid(
            "operator inference: no regularisation to try".into(),
        ));
    }
    let r = basis.ncols();
    let rp = ReducedProbe::of_basis(probe.clone(), basis);
    let mut other = vec![];
    for e in extra {
        if e.rec.dt_s != s.rec.dt_s {
            return Err(MorError::Invalid(format!(
                "operator inference: extra snapshots at dt {} s, the main ones at {} s",
                e.rec.dt_s, s.rec.dt_s
            )));
        }
        other.extend(snapshot_trajectories(
            e,
            basis,
            0..e.rec.sequences + e.rec.held_out,
        )?);
    }
    let main = snapshot_trajectories(s, basis, 0..nseq)?;
    let fit: Vec<Trajectory> = main[..nseq - nval].iter().chain(&other).cloned().collect();
    let mut score =
        |m: &OpInfModel| snapshot_tcp_rmse_mm(m, &rp, s, nseq - nval..nseq).map(|x| x.0);
    let (path, best) =
        regularisation_path(&fit, opts.terms, r, s.rec.dt_s, &opts.lambdas, &mut score)?;
    let Some(lambda) = best else {
        return Err(MorError::Solve(format!(
            "operator inference: every fit is unstable (rank {r}, {} regularisations)",
            opts.lambdas.len()
        )));
    };
    let all: Vec<Trajectory> = main.into_iter().chain(other).collect();
    let ls = LeastSquares::new(&all, opts.terms, r)?;
    let m = OpInfModel::new(
        opts.terms,
        ls.solve_split(lambda)?,
        state_bound(&all),
        s.rec.dt_s,
    )?;
    let spectral_radius = m.check_stable()?;
    // The refit is checked on the validation sequences too: a blow-up is refused, not reported.
    snapshot_tcp_rmse_mm(&m, &rp, s, nseq - nval..nseq)?;
    let rec = OpInfRecord {
        format: OPINF_FORMAT.into(),
        basis_hash: basis_hash(basis),
        operator_hash: operator_hash(&m.operator),
        rank: r,
        terms: opts.terms,
        features: opts.terms.len(r),
        lambda,
        dt_s: s.rec.dt_s,
        state_bound: m.state_bound,
        spectral_radius,
        training_sequences: all.len(),
        validation_sequences: nval,
        path,
    };
    Ok((m, rec))
}
