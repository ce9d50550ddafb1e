//! The inverse model f_S-dagger: `[X_S(t), tau(t), dX_S/dt(t+1)]` to the pressures P_S(t)
//! (eq 4.17-4.19), with a cycle loss through the frozen forward model.

use ocm_learn::burn;
use ocm_learn::burn::module::Module;
use ocm_learn::burn::tensor::{Device, Tensor, TensorData};
use ocm_learn::{Mlp, MlpConfig, tensor2};
use serde::{Deserialize, Serialize};

use crate::forward::ForwardModel;
use crate::samples::{Samples, Scalers};
use crate::trajectory::{FORCE_DIM, PRESSURE_DIM};

/// Architecture name stored in checkpoints.
pub const ARCHITECTURE: &str = "ocm-dynamics/inverse";

/// Shape of the inverse model; the default is the dissertation's 3 x 128 ReLU MLP.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct InverseConfig {
    /// Components of X_S.
    pub state_dim: usize,
    /// Hidden widths.
    pub hidden: Vec<usize>,
    /// Whether the input holds the current velocity dX_S/dt(t) as part of the system state
    /// (absent in checkpoints written before it existed: false).
    #[serde(default)]
    pub current_velocity: bool,
}

impl InverseConfig {
    /// Three hidden layers of 128 with ReLU, the current velocity in the input (the state of
    /// a second-order system; see the crate's README).
    pub fn dissertation(state_dim: usize) -> Self {
        Self {
            state_dim,
            hidden: vec![128; 3],
            current_velocity: true,
        }
    }

    /// Input features: X_S, tau, dX_S/dt(t+1), and dX_S/dt(t) with `current_velocity`.
    pub fn input_dim(&self) -> usize {
        let v = if self.current_velocity {
            self.state_dim
        } else {
            0
        };
        2 * self.state_dim + FORCE_DIM + v
    }

    /// Builds the model with weights drawn from `seed`.
    pub fn init(&self, device: &Device, seed: u64) -> InverseModel {
        InverseModel {
            mlp: MlpConfig::relu(self.input_dim(), &self.hidden, PRESSURE_DIM).init(device, seed),
        }
    }
}

/// The inverse MLP.
#[derive(Module, Debug)]
pub struct InverseModel {
    mlp: Mlp,
}

impl InverseModel {
    /// Scaled inputs `[batch, 2n+3]` to scaled pressures `[batch, 3]`.
    pub fn forward(&self, x: Tensor<2>) -> Tensor<2> {
        self.mlp.forward(x)
    }
}

/// The frozen forward model on both devices the training loop uses, with the map from the
/// inverse model's scaled pressures to the forward model's scaled pressure inputs.
#[derive(Debug, Clone)]
pub struct CycleTarget {
    train: ForwardModel,
    eval: ForwardModel,
    /// `p_fwd = p_inv * gain + shift`, per chamber.
    gain: Vec<f32>,
    shift: Vec<f32>,
}

impl CycleTarget {
    /// Freezes `forward` (trained with the same `scalers`) for use on `autodiff` and `plain`.
    pub fn new(
        forward: &ForwardModel,
        scalers: &Scalers,
        autodiff: &Device,
        plain: &Device,
    ) -> Self {
        let n = scalers.state_dim();
        let (gain, shift) = (0..PRESSURE_DIM)
            .map(|j| {
                let (mi, si) = (scalers.pressure.mean[j], scalers.pressure.std[j]);
                let (mf, sf) = (scalers.step.mean[n + j], scalers.step.std[n + j]);
                ((si / sf) as f32, ((mi - mf) / sf) as f32)
            })
            .unzip();
        Self {
            train: forward.clone().to_device(autodiff).no_grad(),
            eval: forward.clone().to_device(plain).no_grad(),
            gain,
            shift,
        }
    }

    /// Scaled forward prediction with P_S(t) in the last step replaced by `p_scaled` (the
    /// inverse model's output).
    pub fn predict(
        &self,
        data: &Samples,
        batch: &[usize],
        p_scaled: Tensor<2>,
        device: &Device,
    ) -> Tensor<2> {
        let (b, m, f, n) = (batch.len(), data.window, data.step_dim(), data.state_dim);
        let mut windows = data.windows(batch);
        for s in 0..b {
            let row = (s * m + m - 1) * f;
            windows[row + n..row + n + PRESSURE_DIM].fill(0.0);
        }
        let base = Tensor::<3>::from_data(TensorData::new(windows, [b, m, f]), device);
        // A [3, f] selector puts the three pressures into their columns of the last step.
        let mut sel = vec![0.0f32; PRESSURE_DIM * f];
        for j in 0..PRESSURE_DIM {
            sel[j * f + n + j] = 1.0;
        }
        let gain = tensor2(self.gain.clone(), 1, PRESSURE_DIM, device);
        let shift = tensor2(self.shift.clone(), 1, PRESSURE_DIM, device);
        let p = p_scaled * gain + shift;
        let last = p
            .matmul(tensor2(sel, PRESSURE_DIM, f, device))
            .reshape([b, 1, f]);
        let x = if m > 1 {
            base + Tensor::cat(vec![Tensor::zeros([b, m - 1, f], device), last], 1)
        } else {
            base + last
        };
        let model = if device.is_autodiff() {
            &self.train
        } else {
            &self.eval
        };
        model.forward(x)
    }
}

/// `mean (P_hat - P)^2 + beta mean (f_S(X'_t) - v)^2`, scaled units; `cycle` None gives the
/// supervised term alone. `cols` is the model's input width ([`InverseConfig::input_dim`]).
#[allow(clippy::too_many_arguments)]
pub fn inverse_loss(
    model: &InverseModel,
    cols: usize,
    data: &Samples,
    cycle: Option<&CycleTarget>,
    beta: f64,
    batch: &[usize],
    device: &Device,
) -> Tensor<1> {
    let n = data.state_dim;
    let b = batch.len();
    let x = tensor2(data.inverse_rows(cols, batch), b, cols, device);
    let p_hat = model.forward(x);
    let p = tensor2(
        Samples::rows(&data.pressure, PRESSURE_DIM, batch),
        b,
        PRESSURE_DIM,
        device,
    );
    let supervised = (p_hat.clone() - p).powi_scalar(2).mean();
    match cycle {
        Some(c) if beta != 0.0 => {
            let v_hat = c.predict(data, batch, p_hat, device);
            let v = tensor2(Samples::rows(&data.target, n, batch), b, n, device);
            supervised + (v_hat - v).powi_scalar(2).mean().mul_scalar(beta)
        }
        _ => supervised,
    }
}
