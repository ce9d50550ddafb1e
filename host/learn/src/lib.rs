//! Learning building blocks shared by every network of the toolkit, on `burn` with its pure-Rust
//! CPU backend (`flex`) and autodiff.
//!
//! - [`train`]: seeded split and shuffling, Adam, early stopping, progress bar, loss curve.
//! - [`checkpoint`]: weights with architecture, configuration and scaling, checksummed.
//! - [`scaling`]: per-feature standardisation stored with the checkpoint.
//! - [`mlp`], [`sequence`], [`unet`]: the networks (MLP, pre-norm Transformer encoder, U-Net).
//! - [`infer`]: plain `f32` inference of trained MLPs, DeepSets and GCNs (latency-bound calls).
//! - [`init`]: seeded initialisation independent of burn's global generator.

pub mod checkpoint;
pub mod curve;
pub mod deepsets;
pub mod error;
pub mod gcn;
pub mod gradcheck;
pub mod infer;
pub mod infer_sequence;
pub mod init;
pub mod mlp;
pub mod scaling;
pub mod sequence;
pub mod train;
pub mod unet;

pub use burn;
pub use checkpoint::{Checkpoint, CheckpointHeader, CheckpointInfo, save_checkpoint};
pub use curve::EpochRecord;
pub use error::{LearnError, Result};
pub use mlp::{Activation, Mlp, MlpConfig};
pub use scaling::Standardizer;
pub use sequence::{SequenceEncoder, SequenceEncoderConfig};
pub use train::{
    LrSchedule, Split, TrainConfig, TrainReport, batch_gradients, train, train_split,
    train_split_sharded, train_split_steps,
};
pub use unet::{UNet, UNetConfig, UNetNorm};

use burn::tensor::{Device, Tensor, TensorData};

/// The CPU device without autodiff (evaluation).
pub fn cpu() -> Device {
    Device::flex()
}

/// The CPU device with autodiff (training).
pub fn cpu_autodiff() -> Device {
    Device::flex().autodiff()
}

/// A `[rows, cols]` tensor from row-major values.
pub fn tensor2(values: Vec<f32>, rows: usize, cols: usize, device: &Device) -> Tensor<2> {
    Tensor::from_data(TensorData::new(values, [rows, cols]), device)
}

/// The rows `idx` of row-major `data` with `cols` columns, as a `[idx.len(), cols]` tensor.
pub fn gather_rows(data: &[f32], cols: usize, idx: &[usize], device: &Device) -> Tensor<2> {
    let mut v = Vec::with_capacity(idx.len() * cols);
    for &i in idx {
        v.extend_from_slice(&data[i * cols..(i + 1) * cols]);
    }
    tensor2(v, idx.len(), cols, device)
}

/// The values of a tensor, row-major, as `f32`.
pub fn values<const D: usize>(t: Tensor<D>) -> Vec<f32> {
    t.into_data().iter::<f32>().collect()
}

/// Writes `<stem>.csv` and `<stem>.png` of a loss curve into `dir`.
pub fn write_curve(
    dir: &std::path::Path,
    stem: &str,
    title: &str,
    curve: &[EpochRecord],
) -> Result<()> {
    std::fs::create_dir_all(dir).map_err(|e| LearnError::io(dir, e))?;
    curve::write_csv(&dir.join(format!("{stem}.csv")), curve)?;
    curve::write_png(&dir.join(format!("{stem}.png")), title, curve)
}
