//! Training samples cut from trajectories: the forward model's input windows and targets, the
//! physics residual's per-sample offsets, and the inverse model's inputs and targets, all in
//! scaled units.

use ocm_learn::Standardizer;
use serde::{Deserialize, Serialize};

use crate::error::{DynamicsError, Result};
use crate::lumped::LumpedModel;
use crate::trajectory::{FORCE_DIM, PRESSURE_DIM, Trajectory, check_set};

/// The scalings of every quantity the networks see, fitted on training trajectories.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Scalers {
    /// Per-step input `s_t = [X_S, P_S, tau]`.
    pub step: Standardizer,
    /// Velocity dX_S/dt (the forward target and part of the inverse input).
    pub velocity: Standardizer,
    /// Chamber pressures (the inverse target).
    pub pressure: Standardizer,
    /// Inverse input `[X_S(t), tau(t), dX_S/dt(t+1)]`.
    pub inverse_input: Standardizer,
    /// Scale of the residual per component (spread of the finite-difference acceleration).
    pub accel: Vec<f64>,
}

impl Scalers {
    /// Fits all scalings on `trajs`.
    pub fn fit(trajs: &[Trajectory]) -> Result<Self> {
        let (_, n) = check_set(trajs)?;
        let mut step = Vec::new();
        let mut vel = Vec::new();
        let mut pres = Vec::new();
        let mut inv = Vec::new();
        let mut acc = Vec::new();
        for t in trajs {
            for k in 0..t.len() {
                step.extend_from_slice(t.x(k));
                step.extend_from_slice(t.p(k));
                step.extend_from_slice(t.f(k));
                vel.extend_from_slice(t.v(k));
                pres.extend_from_slice(t.p(k));
                if k + 1 < t.len() {
                    inv.extend_from_slice(t.x(k));
                    inv.extend_from_slice(t.f(k));
                    inv.extend_from_slice(t.v(k + 1));
                    acc.extend(t.v(k + 1).iter().zip(t.v(k)).map(|(a, b)| (a - b) / t.dt_s));
                }
            }
        }
        let accel = Standardizer::fit(&acc, n)?.std;
        Ok(Self {
            step: Standardizer::fit(&step, n + PRESSURE_DIM + FORCE_DIM)?,
            velocity: Standardizer::fit(&vel, n)?,
            pressure: Standardizer::fit(&pres, PRESSURE_DIM)?,
            inverse_input: Standardizer::fit(&inv, 2 * n + FORCE_DIM)?,
            accel,
        })
    }

    /// Components of X_S.
    pub fn state_dim(&self) -> usize {
        self.velocity.dim()
    }
}

/// Samples of a set of trajectories for a window of `window` steps.
#[derive(Debug, Clone)]
pub struct Samples {
    /// Steps per window.
    pub window: usize,
    /// Components of X_S.
    pub state_dim: usize,
    /// Time step, s.
    pub dt_s: f64,
    /// Scaled step rows of all trajectories, one after the other (`rows x step_dim`).
    steps: Vec<f32>,
    /// Row index (into `steps`) of the window's last step `t`, per sample.
    last_row: Vec<usize>,
    /// Scaled dX_S/dt(t+1), per sample.
    pub target: Vec<f32>,
    /// Scaled residual offset `b_t` (zero without a lumped model), per sample.
    pub residual_offset: Vec<f32>,
    /// Scaled inverse input, per sample.
    pub inverse_input: Vec<f32>,
    /// Scaled P_S(t), per sample.
    pub pressure: Vec<f32>,
    /// Trajectory and step `t` of each sample.
    pub origin: Vec<(usize, usize)>,
}

impl Samples {
    /// Cuts every window of `window` steps that has a next velocity.
    pub fn build(
        trajs: &[Trajectory],
        window: usize,
        scalers: &Scalers,
        lumped: Option<&LumpedModel>,
    ) -> Result<Self> {
        let (dt, n) = check_set(trajs)?;
        if n != scalers.state_dim() {
            return Err(DynamicsError::Data(format!(
                "trajectories have {n} state components, the scalers {}",
                scalers.state_dim()
            )));
        }
        if window == 0 {
            return Err(DynamicsError::Data(
                "window must be at least one step".into(),
            ));
        }
        if let Some(l) = lumped
            && l.state_dim != n
        {
            return Err(DynamicsError::Data(format!(
                "lumped model has {} components, the data {n}",
                l.state_dim
            )));
        }
        let slope = lumped.map(|l| l.residual_slope(dt));
        let mut out = Self {
            window,
            state_dim: n,
            dt_s: dt,
            steps: Vec::new(),
            last_row: Vec::new(),
            target: Vec::new(),
            residual_offset: Vec::new(),
            inverse_input: Vec::new(),
            pressure: Vec::new(),
            origin: Vec::new(),
        };
        let mut row0 = 0;
        for (ti, t) in trajs.iter().enumerate() {
            let mut raw = Vec::with_capacity(t.len() * (n + 6));
            for k in 0..t.len() {
                raw.extend_from_slice(t.x(k));
                raw.extend_from_slice(t.p(k));
                raw.extend_from_slice(t.f(k));
            }
            out.steps.extend(scalers.step.apply(&raw)?);
            for k in window.saturating_sub(1)..t.len().saturating_sub(1) {
                out.last_row.push(row0 + k);
                out.origin.push((ti, k));
                out.target.extend(scalers.velocity.apply(t.v(k + 1))?);
                let mut inv = t.x(k).to_vec();
                inv.extend_from_slice(t.f(k));
                inv.extend_from_slice(t.v(k + 1));
                out.inverse_input.extend(scalers.inverse_input.apply(&inv)?);
                out.pressure.extend(scalers.pressure.apply(t.p(k))?);
                match (lumped, &slope) {
                    (Some(l), Some(g)) => {
                        let h = l.residual_offset(dt, t.x(k), t.v(k), t.p(k), t.f(k));
                        // b_t = (G mu_v + h_t) / sigma_a.
                        for i in 0..n {
                            let gm: f64 = (0..n)
                                .map(|j| g[i * n + j] * scalers.velocity.mean[j])
                                .sum();
                            out.residual_offset
                                .push(((gm + h[i]) / scalers.accel[i]) as f32);
                        }
                    }
                    _ => out.residual_offset.extend(std::iter::repeat_n(0.0, n)),
                }
            }
            row0 += t.len();
        }
        if out.last_row.is_empty() {
            return Err(DynamicsError::Data(format!(
                "no trajectory is longer than the window of {window} steps"
            )));
        }
        Ok(out)
    }

    /// Number of samples.
    pub fn len(&self) -> usize {
        self.last_row.len()
    }

    /// Whether there is no sample.
    pub fn is_empty(&self) -> bool {
        self.last_row.is_empty()
    }

    /// Features per step.
    pub fn step_dim(&self) -> usize {
        self.state_dim + PRESSURE_DIM + FORCE_DIM
    }

    /// The scaled input windows of `batch`, row-major `[batch, window, step_dim]`.
    pub fn windows(&self, batch: &[usize]) -> Vec<f32> {
        let f = self.step_dim();
        let mut v = Vec::with_capacity(batch.len() * self.window * f);
        for &s in batch {
            let last = self.last_row[s];
            let first = last + 1 - self.window;
            v.extend_from_slice(&self.steps[first * f..(last + 1) * f]);
        }
        v
    }

    /// Rows `batch` of a per-sample array with `cols` columns.
    pub fn rows(data: &[f32], cols: usize, batch: &[usize]) -> Vec<f32> {
        let mut v = Vec::with_capacity(batch.len() * cols);
        for &s in batch {
            v.extend_from_slice(&data[s * cols..(s + 1) * cols]);
        }
        v
    }
}

/// The residual's slope in scaled units, transposed for a row-vector product:
/// `W^T` with `W = diag(1/sigma_a) G diag(sigma_v)`, row-major `n x n`.
pub fn scaled_slope_t(lumped: &LumpedModel, scalers: &Scalers, dt: f64) -> Vec<f32> {
    let n = lumped.state_dim;
    let g = lumped.residual_slope(dt);
    let mut wt = vec![0.0f32; n * n];
    for i in 0..n {
        for j in 0..n {
            let w = g[i * n + j] * scalers.velocity.std[j] / scalers.accel[i];
            wt[j * n + i] = w as f32;
        }
    }
    wt
}
