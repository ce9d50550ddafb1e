//! The training loop shared by every network: seeded split and shuffling, Adam, early stopping
//! on the validation loss, progress bar and loss curve.

use std::time::Instant;

use burn::grad_clipping::GradientClippingConfig;
use burn::module::{Module, ModuleVisitor, Param};
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
    /// How the step size changes over the run (older files without it: constant).
    #[serde(default)]
    pub lr_schedule: LrSchedule,
}

/// How the Adam step size changes over a run, step by step.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case")]
pub enum LrSchedule {
    /// `learning_rate` at every step.
    #[default]
    Constant,
    /// Half a cosine from `learning_rate` at the first step down to `final_fraction` of it
    /// after the last step of the planned `epochs` (early stopping cuts the tail off).
    Cosine {
        /// The fraction of `learning_rate` the run ends at, in [0, 1].
        final_fraction: f64,
    },
}

impl LrSchedule {
    /// A cosine down to `final_fraction` where one is given, else the constant step (a
    /// command line's optional flag).
    pub fn cosine_to(final_fraction: Option<f64>) -> Self {
        final_fraction.map_or(Self::Constant, |final_fraction| Self::Cosine {
            final_fraction,
        })
    }

    /// The step size of optimiser step `step` (from 0) of `total`, for a base rate `base`.
    pub fn rate(&self, base: f64, step: usize, total: usize) -> f64 {
        match *self {
            Self::Constant => base,
            Self::Cosine { final_fraction } => {
                let t = (step as f64 / total.max(1) as f64).min(1.0);
                let cos = 0.5 * (1.0 + (std::f64::consts::PI * t).cos());
                base * (final_fraction + (1.0 - final_fraction) * cos)
            }
        }
    }

    /// Checks the schedule's parameters.
    pub fn validate(&self) -> Result<()> {
        match *self {
            Self::Constant => Ok(()),
            Self::Cosine { final_fraction } if (0.0..=1.0).contains(&final_fraction) => Ok(()),
            Self::Cosine { final_fraction } => Err(LearnError::Config(format!(
                "the cosine schedule's final fraction {final_fraction} must lie in [0, 1]"
            ))),
        }
    }
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
            lr_schedule: LrSchedule::Constant,
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
    F: Fn(&M, &[usize], &Device) -> Tensor<1> + Sync,
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
    F: Fn(&M, &[usize], &Device) -> Tensor<1> + Sync,
{
    train_split_sharded(model, split, cfg, 1, loss)
}

/// [`train_split`] with every batch cut into `shards` contiguous parts whose losses and
/// gradients are computed on as many threads, then combined in a fixed order, each part
/// weighted by its share of the batch. Since `loss` is a mean over samples, the step is the
/// whole batch's up to rounding, and the same for any run with the same `shards`; 1 is
/// [`train_split`] bit for bit. Only for networks whose samples do not interact: batch norm
/// would normalise over each part, and its running statistics are shared between the forks.
pub fn train_split_sharded<M, F>(
    model: M,
    split: &Split,
    cfg: &TrainConfig,
    shards: usize,
    loss: F,
) -> Result<TrainReport<M>>
where
    M: Module,
    F: Fn(&M, &[usize], &Device) -> Tensor<1> + Sync,
{
    let device = autodiff_device(&model)?;
    let plain = device.clone().inner();
    train_split_steps(
        model,
        split,
        cfg,
        |model, batch| Ok(batch_gradients(model, batch, shards, &device, &loss)),
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

/// The mean loss over `batch` and its gradients by parameter, computed on `shards` threads
/// (see [`train_split_sharded`]); a non-finite loss comes with no gradients.
pub fn batch_gradients<M, F>(
    model: &M,
    batch: &[usize],
    shards: usize,
    device: &Device,
    loss: &F,
) -> (f64, GradientsParams)
where
    M: Module,
    F: Fn(&M, &[usize], &Device) -> Tensor<1> + Sync,
{
    let part = |model: &M, part: &[usize]| {
        let l = loss(model, part, device);
        let value = f64::from(l.clone().detach().into_scalar::<f32>());
        // A diverged loss has no gradients worth taking; the loop stops on its value.
        let grads = if value.is_finite() {
            GradientsParams::from_grads(l.backward(), model)
        } else {
            GradientsParams::new()
        };
        (value, grads)
    };
    let parts = shard(batch, shards);
    if parts.len() == 1 {
        return part(model, batch);
    }
    // Each thread takes a fork of the parameters (same ids, new autodiff nodes), so the
    // parts' graphs share no node and back-propagate independently.
    let results: Vec<_> = std::thread::scope(|s| {
        let handles: Vec<_> = parts
            .iter()
            .map(|&p| {
                let replica = model.clone().fork(device);
                let part = &part;
                s.spawn(move || part(&replica, p))
            })
            .collect();
        // A panic in `loss` reaches the caller as it would on one thread.
        handles
            .into_iter()
            .map(|h| h.join().unwrap_or_else(|e| std::panic::resume_unwind(e)))
            .collect()
    });
    let mut value = 0.0;
    let mut sum = WeightedSum {
        parts: Vec::with_capacity(parts.len()),
        weights: Vec::with_capacity(parts.len()),
        out: GradientsParams::new(),
    };
    for ((v, g), p) in results.into_iter().zip(&parts) {
        let w = p.len() as f64 / batch.len() as f64;
        value += v * w;
        sum.parts.push(g);
        sum.weights.push(w as f32);
    }
    if !value.is_finite() {
        return (value, GradientsParams::new());
    }
    model.visit(&mut sum);
    (value, sum.out)
}

/// `batch` cut into at most `shards` contiguous parts whose sizes differ by one at most.
fn shard(batch: &[usize], shards: usize) -> Vec<&[usize]> {
    let k = shards.clamp(1, batch.len().max(1));
    let (q, r) = (batch.len() / k, batch.len() % k);
    let mut parts = Vec::with_capacity(k);
    let mut start = 0;
    for i in 0..k {
        let len = q + usize::from(i < r);
        parts.push(&batch[start..start + len]);
        start += len;
    }
    parts
}

/// Sums the parts' gradients of every parameter, each part scaled by its weight, in part order.
struct WeightedSum {
    parts: Vec<GradientsParams>,
    weights: Vec<f32>,
    out: GradientsParams,
}

impl ModuleVisitor for WeightedSum {
    fn visit_float<const D: usize>(&mut self, param: &Param<Tensor<D>>) {
        let mut acc: Option<Tensor<D>> = None;
        for (g, &w) in self.parts.iter_mut().zip(&self.weights) {
            if let Some(t) = g.remove::<D>(param.id) {
                let t = t.mul_scalar(w);
                acc = Some(match acc {
                    None => t,
                    Some(a) => a + t,
                });
            }
        }
        if let Some(a) = acc {
            self.out.register(param.id, a);
        }
    }
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
    cfg.lr_schedule.validate()?;
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
    let total_steps = cfg.epochs * order.len().div_ceil(cfg.batch_size);
    let mut steps = 0;
    let mut rate = cfg.learning_rate;
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
            rate = cfg.lr_schedule.rate(cfg.learning_rate, steps, total_steps);
            model = optim.step(rate, model, grads);
            steps += 1;
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
            learning_rate: rate,
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
