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
    /// Inverse input `[X_S(t), tau(t), dX_S/dt(t+1), dX_S/dt(t)]` (checkpoints written before
    /// the current velocity was added hold the first `2n + 3` columns only).
    pub inverse_input: Standardizer,
    /// Scale of the residual per component, 1/s times the velocity's unit: the velocity spread
    /// per time step, `sigma_v / dt`. In these units the residual is the velocity defect of
    /// one step in the velocity's own scaled units, so its slope in the scaled prediction is
    /// about the identity and lambda weighs the physics target against the data target one to
    /// one (with the spread of the acceleration instead, the slope was 1.6-3.7 on the bellows
    /// data and the physics term outweighed the data term 2:1 at lambda = 0.15).
    pub accel: Vec<f64>,
}

impl Scalers {
    /// Fits all scalings on `trajs`.
    pub fn fit(trajs: &[Trajectory]) -> Result<Self> {
        let (dt, n) = check_set(trajs)?;
        let mut step = Vec::new();
        let mut vel = Vec::new();
        let mut pres = Vec::new();
        let mut inv = Vec::new();
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
                    inv.extend_from_slice(t.v(k));
                }
            }
        }
        let velocity = Standardizer::fit(&vel, n)?;
        let accel = velocity.std.iter().map(|s| s / dt).collect();
        Ok(Self {
            step: Standardizer::fit(&step, n + PRESSURE_DIM + FORCE_DIM)?,
            velocity,
            pressure: Standardizer::fit(&pres, PRESSURE_DIM)?,
            inverse_input: Standardizer::fit(&inv, 3 * n + FORCE_DIM)?,
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
    /// Scaled inverse input, per sample ([`Samples::inverse_cols`] columns).
    pub inverse_input: Vec<f32>,
    /// Columns of the inverse input: `3n + 3` with the current velocity, `2n + 3` for scalers
    /// of older checkpoints without it.
    pub inverse_cols: usize,
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
        let inverse_cols = scalers.inverse_input.dim();
        if inverse_cols != 3 * n + FORCE_DIM && inverse_cols != 2 * n + FORCE_DIM {
            return Err(DynamicsError::Data(format!(
                "inverse input scaling has {inverse_cols} columns, expected {} or {}",
                3 * n + FORCE_DIM,
                2 * n + FORCE_DIM
            )));
        }
        let mut out = Self {
            window,
            state_dim: n,
            dt_s: dt,
            steps: Vec::new(),
            last_row: Vec::new(),
            target: Vec::new(),
            residual_offset: Vec::new(),
            inverse_input: Vec::new(),
            inverse_cols,
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
                if inverse_cols > 2 * n + FORCE_DIM {
                    inv.extend_from_slice(t.v(k));
                }
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

    /// The scaled inverse inputs of `batch`, the first `cols` columns of each (`2n + 3` leaves
    /// out the current velocity).
    pub fn inverse_rows(&self, cols: usize, batch: &[usize]) -> Vec<f32> {
        let all = self.inverse_cols;
        let mut v = Vec::with_capacity(batch.len() * cols);
        for &s in batch {
            v.extend_from_slice(&self.inverse_input[s * all..s * all + cols.min(all)]);
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
