//! The training loop shared by every network: seeded split and shuffling, Adam, early stopping
//! on the validation loss, progress bar and loss curve.

use std::time::Instant;

use burn::grad_clipping::GradientClippingConfig;
use burn::module::Module;
use burn::optim::{AdamConfig, GradientsParams};
use burn::tensor::{Device, Tensor};
use indicatif::{ProgressBar, ProgressStyle};
use rand::SeedableRng;
use rand::seq::SliceRandom;
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};

use crate::curve::EpochRecord;
use crate::error::{LearnError, Result};

/// How to train.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TrainConfig {
    /// Upper bound on the number of passes over the training set.
    pub epochs: usize,
    /// Samples per optimiser step.
    pub batch_size: usize,
    /// Adam step size.
    pub learning_rate: f64,
    /// Fraction of the samples held out for validation (0 disables validation and early
    /// stopping).
    pub val_fraction: f64,
    /// Stop after this many epochs without a validation improvement (0: never stop early).
    pub patience: usize,
    /// Clip the global gradient norm to this value (None: no clipping).
    pub grad_clip_norm: Option<f64>,
    /// Seed of the split and of the shuffling (the weights have their own seed).
    pub seed: u64,
    /// Show a progress bar on stderr.
    pub progress: bool,
}

impl Default for TrainConfig {
    fn default() -> Self {
        Self {
            epochs: 100,
            batch_size: 64,
            learning_rate: 1e-3,
            val_fraction: 0.2,
            patience: 20,
            grad_clip_norm: None,
            seed: 0,
            progress: false,
        }
    }
}

/// Sample indices of the training and validation sets.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct Split {
    /// Samples the optimiser sees.
    pub train: Vec<usize>,
    /// Samples that only score the model.
    pub val: Vec<usize>,
}

impl Split {
    /// A seeded random split of `n` samples with `val_fraction` of them (rounded) held out.
    pub fn random(n: usize, val_fraction: f64, seed: u64) -> Self {
        let mut idx: Vec<usize> = (0..n).collect();
        idx.shuffle(&mut ChaCha8Rng::seed_from_u64(seed));
        let n_val = ((n as f64) * val_fraction.clamp(0.0, 1.0)).round() as usize;
        let n_val = n_val.min(n.saturating_sub(1));
        let val = idx.split_off(n - n_val);
        Self { train: idx, val }
    }
}

/// The outcome of [`train`].
#[derive(Debug)]
pub struct TrainReport<M> {
    /// The model of the epoch with the lowest validation loss (the last epoch without
    /// validation), detached from autodiff, ready to evaluate or save.
    pub model: M,
    /// Losses per epoch.
    pub curve: Vec<EpochRecord>,
    /// Epoch of the returned model.
    pub best_epoch: usize,
    /// Validation loss of the returned model (training loss without validation).
    pub best_loss: f64,
    /// Whether training stopped before `epochs` for lack of improvement.
    pub stopped_early: bool,
}

/// Trains `model` (built on an autodiff device) on `n_samples` samples.
///
/// `loss(model, batch, device)` returns the scalar mean loss over the samples `batch`, with its
/// tensors built on `device`; it is called with the autodiff device while training and with
/// the plain device (and a model without autodiff) for validation. The split comes from
/// [`Split::random`] with `cfg.seed`, and the training order is reshuffled every epoch.
pub fn train<M, F>(model: M, n_samples: usize, cfg: &TrainConfig, loss: F) -> Result<TrainReport<M>>
where
    M: Module,
    F: Fn(&M, &[usize], &Device) -> Tensor<1>,
{
    let split = Split::random(n_samples, cfg.val_fraction, cfg.seed);
    train_split(model, &split, cfg, loss)
}

/// [`train`] on a given split.
pub fn train_split<M, F>(
    model: M,
    split: &Split,
    cfg: &TrainConfig,
    loss: F,
) -> Result<TrainReport<M>>
where
    M: Module,
    F: Fn(&M, &[usize], &Device) -> Tensor<1>,
{
    let device = autodiff_device(&model)?;
    let plain = device.clone().inner();
    train_split_steps(
        model,
        split,
        cfg,
        |model, batch| {
            let l = loss(model, batch, &device);
            let value = f64::from(l.clone().detach().into_scalar::<f32>());
            // A diverged loss has no gradients worth taking; the loop stops on its value.
            let grads = if value.is_finite() {
                GradientsParams::from_grads(l.backward(), model)
            } else {
                GradientsParams::new()
            };
            Ok((value, grads))
        },
        |valid, samples| {
            Ok(evaluate(
                valid,
                samples,
                cfg.batch_size.max(256),
                &plain,
                &loss,
            ))
        },
    )
}

/// The device of `model`'s parameters, which must be an autodiff device.
fn autodiff_device<M: Module>(model: &M) -> Result<Device> {
    let device = model
        .devices()
        .into_iter()
        .next()
        .ok_or_else(|| LearnError::Config("the model has no parameters".into()))?;
    if !device.is_autodiff() {
        return Err(LearnError::Config(
            "train needs a model built on an autodiff device (Device::autodiff)".into(),
        ));
    }
    Ok(device)
}

/// [`train_split`] with the gradients computed by the caller: `step(model, batch)` returns the
/// batch's mean loss and the gradients of the model's parameters (by `ParamId`, on the plain
/// device), and `validate(model, samples)` the mean loss of the detached model over
/// `samples`. For engines other than burn's autodiff (the optimiser, clipping, split,
/// shuffling, early stopping and curve stay these).
pub fn train_split_steps<M, S, V>(
    model: M,
    split: &Split,
    cfg: &TrainConfig,
    mut step: S,
    validate: V,
) -> Result<TrainReport<M>>
where
    M: Module,
    S: FnMut(&M, &[usize]) -> Result<(f64, GradientsParams)>,
    V: Fn(&M, &[usize]) -> Result<f64>,
{
    if cfg.batch_size == 0 || cfg.epochs == 0 {
        return Err(LearnError::Config(
            "batch_size and epochs must be positive".into(),
        ));
    }
    if !(cfg.learning_rate.is_finite() && cfg.learning_rate > 0.0) {
        return Err(LearnError::Config(format!(
            "learning rate {} must be positive",
            cfg.learning_rate
        )));
    }
    if split.train.is_empty() {
        return Err(LearnError::Data("no training samples".into()));
    }
    autodiff_device(&model)?;
    let mut optim = AdamConfig::new()
        .with_grad_clipping(
            cfg.grad_clip_norm
                .map(|n| GradientClippingConfig::Norm(n as f32)),
        )
        .init();
    let mut rng = ChaCha8Rng::seed_from_u64(cfg.seed ^ 0x5eed_0f0c_3a11_0001);
    let mut order = split.train.clone();
    let bar = progress_bar(cfg);
    let start = Instant::now();
    let mut model = model;
    let mut curve = Vec::new();
    let mut best: Option<(f64, usize, M)> = None;
    let mut since_best = 0;
    let mut stopped_early = false;
    for epoch in 1..=cfg.epochs {
        order.shuffle(&mut rng);
        let mut sum = 0.0;
        for batch in order.chunks(cfg.batch_size) {
            let (value, grads) = step(&model, batch)?;
            if !value.is_finite() {
                bar.abandon();
                return Err(LearnError::Diverged { epoch, loss: value });
            }
            sum += value * batch.len() as f64;
            model = optim.step(cfg.learning_rate, model, grads);
        }
        let train_loss = sum / order.len() as f64;
        let valid = model.valid();
        let val_loss = if split.val.is_empty() {
            f64::NAN
        } else {
            validate(&valid, &split.val)?
        };
        curve.push(EpochRecord {
            epoch,
            train_loss,
            val_loss,
            elapsed_s: start.elapsed().as_secs_f64(),
        });
        bar.set_message(format!("train {train_loss:.3e} val {val_loss:.3e}"));
        bar.inc(1);
        let score = if split.val.is_empty() {
            train_loss
        } else {
            val_loss
        };
        let improved = best.as_ref().is_none_or(|(b, _, _)| score < *b);
        if improved {
            best = Some((score, epoch, valid));
            since_best = 0;
        } else {
            since_best += 1;
        }
        if !split.val.is_empty() && cfg.patience > 0 && since_best >= cfg.patience {
            stopped_early = epoch < cfg.epochs;
            break;
        }
    }
    bar.finish_and_clear();
    let (best_loss, best_epoch, model) = if split.val.is_empty() {
        let last = curve.last().map_or(f64::NAN, |r| r.train_loss);
        (last, curve.len(), model.valid())
    } else {
        best.ok_or_else(|| LearnError::Data("no epoch ran".into()))?
    };
    Ok(TrainReport {
        model,
        curve,
        best_epoch,
        best_loss,
        stopped_early,
    })
}

/// Mean of `loss` over `samples` in chunks of `chunk`, weighting each chunk by its size.
pub fn evaluate<M, F>(model: &M, samples: &[usize], chunk: usize, device: &Device, loss: &F) -> f64
where
    F: Fn(&M, &[usize], &Device) -> Tensor<1>,
{
    let mut sum = 0.0;
    for batch in samples.chunks(chunk.max(1)) {
        sum += f64::from(loss(model, batch, device).into_scalar::<f32>()) * batch.len() as f64;
    }
    sum / samples.len().max(1) as f64
}

fn progress_bar(cfg: &TrainConfig) -> ProgressBar {
    if !cfg.progress {
        return ProgressBar::hidden();
    }
    let bar = ProgressBar::new(cfg.epochs as u64);
    if let Ok(style) =
        ProgressStyle::with_template("{elapsed_precise} [{bar:30}] epoch {pos}/{len} {msg}")
    {
        bar.set_style(style.progress_chars("=> "));
    }
    bar
}
