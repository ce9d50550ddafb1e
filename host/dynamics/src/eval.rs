//! Held-out scores of the forward and inverse models in physical units (Table 4.1's metrics,
//! plus a free-running rollout).

use ocm_learn::burn::tensor::{Device, Tensor, TensorData};
use ocm_learn::{tensor2, values};
use serde::{Deserialize, Serialize};

use crate::error::Result;
use crate::forward::ForwardModel;
use crate::inverse::{InverseConfig, InverseModel};
use crate::samples::{Samples, Scalers};
use crate::trajectory::{FORCE_DIM, PRESSURE_DIM, Trajectory};

/// Components of X_S that are the TCP position (m); errors are Euclidean over them.
pub const TCP_DIM: usize = 3;

/// Scores of the forward model.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ForwardMetrics {
    /// Samples scored.
    pub samples: usize,
    /// Mean Euclidean one-step TCP velocity error, mm/s.
    pub velocity_error_mm_s: f64,
    /// Mean Euclidean one-step TCP position error, mm: `x_t + dt/2 (v_t + v_hat_{t+1})`
    /// against `x_{t+1}`.
    pub position_error_mm: f64,
    /// Free-running rollouts scored.
    pub rollouts: usize,
    /// Length of each rollout, s.
    pub rollout_horizon_s: f64,
    /// Mean Euclidean TCP error over all steps of the rollouts, mm.
    pub rollout_mean_error_mm: f64,
    /// Mean Euclidean TCP error at the end of the rollouts, mm.
    pub rollout_final_error_mm: f64,
}

/// Scores of the inverse model.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct InverseMetrics {
    /// Samples scored.
    pub samples: usize,
    /// Mean absolute pressure error over chambers and samples, kPa.
    pub pressure_mae_kpa: f64,
    /// Root mean square pressure error, kPa.
    pub pressure_rmse_kpa: f64,
}

fn tcp_norm(a: &[f64], b: &[f64]) -> f64 {
    a.iter()
        .zip(b)
        .take(TCP_DIM)
        .map(|(a, b)| (a - b) * (a - b))
        .sum::<f64>()
        .sqrt()
}

/// Physical velocity predictions `v_hat_{t+1}` for every sample of `data`.
pub fn predict_forward(
    model: &ForwardModel,
    scalers: &Scalers,
    data: &Samples,
    device: &Device,
) -> Result<Vec<f64>> {
    let idx: Vec<usize> = (0..data.len()).collect();
    let mut out = Vec::with_capacity(data.len() * data.state_dim);
    for batch in idx.chunks(1024) {
        let x = Tensor::<3>::from_data(
            TensorData::new(
                data.windows(batch),
                [batch.len(), data.window, data.step_dim()],
            ),
            device,
        );
        out.extend(scalers.velocity.invert(&values(model.forward(x)))?);
    }
    Ok(out)
}

/// One-step errors on all windows of `trajs` and free-running rollouts of `horizon` steps.
pub fn evaluate_forward(
    model: &ForwardModel,
    scalers: &Scalers,
    window: usize,
    trajs: &[Trajectory],
    horizon: usize,
    device: &Device,
) -> Result<ForwardMetrics> {
    let data = Samples::build(trajs, window, scalers, None)?;
    let pred = predict_forward(model, scalers, &data, device)?;
    let n = data.state_dim;
    let (mut ev, mut ex) = (0.0, 0.0);
    for (s, &(ti, k)) in data.origin.iter().enumerate() {
        let t = &trajs[ti];
        let v_hat = &pred[s * n..(s + 1) * n];
        ev += tcp_norm(v_hat, t.v(k + 1));
        let x_hat: Vec<f64> = (0..n)
            .map(|i| t.x(k)[i] + 0.5 * t.dt_s * (t.v(k)[i] + v_hat[i]))
            .collect();
        ex += tcp_norm(&x_hat, t.x(k + 1));
    }
    let count = data.len() as f64;
    let (rollouts, mean_err, final_err) =
        rollout_errors(model, scalers, window, trajs, horizon, device)?;
    Ok(ForwardMetrics {
        samples: data.len(),
        velocity_error_mm_s: 1e3 * ev / count,
        position_error_mm: 1e3 * ex / count,
        rollouts,
        rollout_horizon_s: horizon as f64 * trajs[0].dt_s,
        rollout_mean_error_mm: 1e3 * mean_err,
        rollout_final_error_mm: 1e3 * final_err,
    })
}

/// Runs the model on its own predictions from non-overlapping starts in every trajectory,
/// inputs (P_S, tau) taken from the data; returns (count, mean error, final error) in m.
pub fn rollout_errors(
    model: &ForwardModel,
    scalers: &Scalers,
    window: usize,
    trajs: &[Trajectory],
    horizon: usize,
    device: &Device,
) -> Result<(usize, f64, f64)> {
    let n = scalers.state_dim();
    let f = n + PRESSURE_DIM + FORCE_DIM;
    // (trajectory, start step t0): the window ends at t0, the rollout predicts t0+1..=t0+horizon.
    let mut starts = Vec::new();
    for (ti, t) in trajs.iter().enumerate() {
        let mut t0 = window.saturating_sub(1);
        while horizon > 0 && t0 + horizon < t.len() {
            starts.push((ti, t0));
            t0 += horizon;
        }
    }
    if starts.is_empty() {
        return Ok((0, f64::NAN, f64::NAN));
    }
    let row = |t: &Trajectory, k: usize, x: &[f64]| -> Vec<f64> {
        let mut r = x.to_vec();
        r.extend_from_slice(t.p(k));
        r.extend_from_slice(t.f(k));
        r
    };
    let mut win: Vec<Vec<Vec<f64>>> = starts
        .iter()
        .map(|&(ti, t0)| {
            let t = &trajs[ti];
            (t0 + 1 - window..=t0).map(|k| row(t, k, t.x(k))).collect()
        })
        .collect();
    let mut x: Vec<Vec<f64>> = starts
        .iter()
        .map(|&(ti, t0)| trajs[ti].x(t0).to_vec())
        .collect();
    let mut v: Vec<Vec<f64>> = starts
        .iter()
        .map(|&(ti, t0)| trajs[ti].v(t0).to_vec())
        .collect();
    let (mut sum, mut last) = (0.0, 0.0);
    let b = starts.len();
    for step in 1..=horizon {
        let raw: Vec<f64> = win.iter().flatten().flatten().copied().collect();
        let input = Tensor::<3>::from_data(
            TensorData::new(scalers.step.apply(&raw)?, [b, window, f]),
            device,
        );
        let v_hat = scalers.velocity.invert(&values(model.forward(input)))?;
        for (r, &(ti, t0)) in starts.iter().enumerate() {
            let t = &trajs[ti];
            let vh = &v_hat[r * n..(r + 1) * n];
            for i in 0..n {
                x[r][i] += 0.5 * t.dt_s * (v[r][i] + vh[i]);
            }
            v[r] = vh.to_vec();
            let k = t0 + step;
            let e = tcp_norm(&x[r], t.x(k));
            sum += e;
            if step == horizon {
                last += e;
            }
            win[r].remove(0);
            win[r].push(row(t, k, &x[r]));
        }
    }
    Ok((b, sum / (b * horizon) as f64, last / b as f64))
}

/// Pressure errors of the inverse model (of shape `config`) on all samples of `trajs`.
pub fn evaluate_inverse(
    model: &InverseModel,
    config: &InverseConfig,
    scalers: &Scalers,
    trajs: &[Trajectory],
    device: &Device,
) -> Result<InverseMetrics> {
    let data = Samples::build(trajs, 1, scalers, None)?;
    let cols = config.input_dim();
    if cols > data.inverse_cols {
        return Err(crate::DynamicsError::Data(format!(
            "the inverse model takes {cols} inputs, its scalings cover {}",
            data.inverse_cols
        )));
    }
    let (mut abs, mut sq) = (0.0, 0.0);
    let idx: Vec<usize> = (0..data.len()).collect();
    for batch in idx.chunks(4096) {
        let x = tensor2(data.inverse_rows(cols, batch), batch.len(), cols, device);
        let p_hat = scalers.pressure.invert(&values(model.forward(x)))?;
        for (r, &s) in batch.iter().enumerate() {
            let (ti, k) = data.origin[s];
            for j in 0..PRESSURE_DIM {
                let e = p_hat[r * PRESSURE_DIM + j] - trajs[ti].p(k)[j];
                abs += e.abs();
                sq += e * e;
            }
        }
    }
    let count = (data.len() * PRESSURE_DIM) as f64;
    Ok(InverseMetrics {
        samples: data.len(),
        pressure_mae_kpa: abs / count,
        pressure_rmse_kpa: (sq / count).sqrt(),
    })
}
