//! The forward model f_S: a window of m steps `s_t = [X_S, P_S, tau]` to the next velocity
//! dX_S/dt(t+1) (eq 4.9-4.16), trained on MSE plus the lumped physics residual.

use ocm_learn::burn;
use ocm_learn::burn::module::Module;
use ocm_learn::burn::tensor::{Device, Tensor, TensorData};
use ocm_learn::infer::DenseMlp;
use ocm_learn::infer_sequence::DenseSequenceEncoder;
use ocm_learn::{Mlp, MlpConfig, SequenceEncoder, SequenceEncoderConfig, tensor2};
use serde::{Deserialize, Serialize};

use crate::samples::Samples;
use crate::trajectory::{FORCE_DIM, PRESSURE_DIM};

/// Architecture name stored in checkpoints.
pub const ARCHITECTURE: &str = "ocm-dynamics/forward";

/// Shape of the forward model; the defaults are the dissertation's.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ForwardConfig {
    /// Components of X_S.
    pub state_dim: usize,
    /// Steps per input window (m).
    pub window: usize,
    /// Embedding width.
    pub d_model: usize,
    /// Attention heads.
    pub n_heads: usize,
    /// Feed-forward width of each encoder block.
    pub d_ff: usize,
    /// Encoder blocks.
    pub n_layers: usize,
    /// Hidden widths of the ReLU head.
    pub head_hidden: Vec<usize>,
}

impl ForwardConfig {
    /// The dissertation's model for `state_dim` components: m = 10, d_model 128, 2 pre-norm
    /// blocks of 4 heads and feed-forward 256, a 3 x 128 ReLU head.
    pub fn dissertation(state_dim: usize) -> Self {
        Self {
            state_dim,
            window: 10,
            d_model: 128,
            n_heads: 4,
            d_ff: 256,
            n_layers: 2,
            head_hidden: vec![128; 3],
        }
    }

    /// Features per step.
    pub fn step_dim(&self) -> usize {
        self.state_dim + PRESSURE_DIM + FORCE_DIM
    }

    /// Builds the model with weights drawn from `seed`.
    pub fn init(&self, device: &Device, seed: u64) -> ForwardModel {
        let encoder = SequenceEncoderConfig {
            input: self.step_dim(),
            d_model: self.d_model,
            n_heads: self.n_heads,
            d_ff: self.d_ff,
            n_layers: self.n_layers,
            max_len: self.window,
        }
        .init(device, seed);
        let head = MlpConfig::relu(self.d_model, &self.head_hidden, self.state_dim)
            .init(device, seed.wrapping_add(1));
        ForwardModel { encoder, head }
    }
}

/// Transformer encoder over the window, the last step's embedding through a ReLU head.
#[derive(Module, Debug)]
pub struct ForwardModel {
    encoder: SequenceEncoder,
    head: Mlp,
}

impl ForwardModel {
    /// Scaled windows `[batch, window, step_dim]` to scaled velocities `[batch, state_dim]`.
    pub fn forward(&self, windows: Tensor<3>) -> Tensor<2> {
        self.head.forward(self.encoder.forward_last(windows))
    }

    /// The same model as plain arrays, for fast batched inference.
    pub fn dense(&self) -> crate::Result<DenseForward> {
        Ok(DenseForward {
            encoder: DenseSequenceEncoder::from_encoder(&self.encoder)?,
            head: DenseMlp::from_mlp(&self.head),
        })
    }
}

/// [`ForwardModel`] as plain `f32` arrays (no tensors, graph or autodiff), for batched
/// inference (`ocm learn bench`). It computes the same function to f32 round-off.
#[derive(Debug, Clone)]
pub struct DenseForward {
    encoder: DenseSequenceEncoder,
    head: DenseMlp,
}

impl DenseForward {
    /// Scaled windows, row-major `[batch, steps, step_dim]`, to scaled velocities `[batch,
    /// state_dim]`.
    pub fn forward(&self, windows: &[f32], batch: usize, steps: usize) -> crate::Result<Vec<f32>> {
        let h = self.encoder.forward_last(windows, batch, steps)?;
        Ok(self.head.forward_rows(&h, batch))
    }
}

/// The forward loss `mean (v_hat - v)^2 + lambda mean R^2`, both in scaled units.
///
/// `slope_t` is the residual's scaled slope (see [`crate::samples::scaled_slope_t`]), `n x n`
/// row-major; the residual of a sample is `v_hat W^T + b_t`.
pub fn forward_loss(
    model: &ForwardModel,
    data: &Samples,
    slope_t: &[f32],
    lambda: f64,
    batch: &[usize],
    device: &Device,
) -> Tensor<1> {
    let n = data.state_dim;
    let b = batch.len();
    let x = Tensor::<3>::from_data(
        TensorData::new(data.windows(batch), [b, data.window, data.step_dim()]),
        device,
    );
    let pred = model.forward(x);
    let target = tensor2(Samples::rows(&data.target, n, batch), b, n, device);
    let mse = (pred.clone() - target).powi_scalar(2).mean();
    if lambda == 0.0 {
        return mse;
    }
    mse + physics_loss(pred, data, slope_t, batch, device).mul_scalar(lambda)
}

/// `mean R^2` of scaled predictions `pred` (`[batch, n]`): the physics term alone.
pub fn physics_loss(
    pred: Tensor<2>,
    data: &Samples,
    slope_t: &[f32],
    batch: &[usize],
    device: &Device,
) -> Tensor<1> {
    let n = data.state_dim;
    let w = tensor2(slope_t.to_vec(), n, n, device);
    let offset = tensor2(
        Samples::rows(&data.residual_offset, n, batch),
        batch.len(),
        n,
        device,
    );
    (pred.matmul(w) + offset).powi_scalar(2).mean()
}
