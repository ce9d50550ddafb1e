//! Training runs of the forward and inverse models, and their checkpoints.

use std::collections::BTreeMap;
use std::path::Path;

use ocm_learn::burn::tensor::Device;
use ocm_learn::{
    Checkpoint, CheckpointInfo, EpochRecord, Standardizer, TrainConfig, cpu, cpu_autodiff,
    save_checkpoint, train,
};
use serde::{Deserialize, Serialize};

use crate::error::{DynamicsError, Result};
use crate::forward::{self, ForwardConfig, ForwardModel, forward_loss};
use crate::inverse::{self, CycleTarget, InverseConfig, InverseModel, inverse_loss};
use crate::lumped::LumpedModel;
use crate::samples::{Samples, Scalers, scaled_slope_t};
use crate::trajectory::{Trajectory, check_set};

/// The physics weight of eq 4.15.
pub const DEFAULT_LAMBDA: f64 = 0.15;
/// The cycle weight of eq 4.19.
pub const DEFAULT_BETA: f64 = 0.1;

/// Facts stored with a model, beside its weights and scalers.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ModelMeta {
    /// Time step of the training data, s.
    pub dt_s: f64,
    /// The residual's scale per component ([`Scalers::accel`]; checkpoints written before the
    /// residual was scaled as a velocity defect hold the acceleration's spread here).
    pub accel_scale: Vec<f64>,
    /// The lumped model of the physics residual.
    pub lumped: LumpedModel,
    /// Physics weight (forward) or cycle weight (inverse).
    pub loss_weight: f64,
    /// Seed of the weights.
    pub weight_seed: u64,
    /// Training settings.
    pub train: TrainConfig,
    /// Epoch of the kept weights and its validation loss.
    pub best_epoch: usize,
    /// Validation loss of the kept weights (scaled units).
    pub best_loss: f64,
    /// Training samples (windows).
    pub samples: usize,
}

/// A trained forward model with everything needed to use it.
#[derive(Debug, Clone)]
pub struct TrainedForward {
    /// Shape.
    pub config: ForwardConfig,
    /// Weights (no autodiff).
    pub model: ForwardModel,
    /// Scalings it was trained with.
    pub scalers: Scalers,
    /// Run facts.
    pub meta: ModelMeta,
}

/// A trained inverse model with everything needed to use it.
#[derive(Debug, Clone)]
pub struct TrainedInverse {
    /// Shape.
    pub config: InverseConfig,
    /// Weights (no autodiff).
    pub model: InverseModel,
    /// Scalings it was trained with (those of the forward model it was cycled through).
    pub scalers: Scalers,
    /// Run facts.
    pub meta: ModelMeta,
}

/// Trains the forward model on `trajs`; the lumped model of the residual is identified from
/// the same trajectories. Returns the model and the loss curve.
pub fn train_forward(
    trajs: &[Trajectory],
    config: &ForwardConfig,
    train_cfg: &TrainConfig,
    lambda: f64,
    weight_seed: u64,
) -> Result<(TrainedForward, Vec<EpochRecord>)> {
    let (dt, n) = check_set(trajs)?;
    if config.state_dim != n {
        return Err(DynamicsError::Data(format!(
            "model expects {} state components, data has {n}",
            config.state_dim
        )));
    }
    let lumped = LumpedModel::identify(trajs)?;
    let scalers = Scalers::fit(trajs)?;
    let data = Samples::build(trajs, config.window, &scalers, Some(&lumped))?;
    let slope_t = scaled_slope_t(&lumped, &scalers, dt);
    let model = config.init(&cpu_autodiff(), weight_seed);
    let report = train(model, data.len(), train_cfg, |m, batch, device| {
        forward_loss(m, &data, &slope_t, lambda, batch, device)
    })?;
    let meta = ModelMeta {
        dt_s: dt,
        accel_scale: scalers.accel.clone(),
        lumped,
        loss_weight: lambda,
        weight_seed,
        train: train_cfg.clone(),
        best_epoch: report.best_epoch,
        best_loss: report.best_loss,
        samples: data.len(),
    };
    Ok((
        TrainedForward {
            config: config.clone(),
            model: report.model,
            scalers,
            meta,
        },
        report.curve,
    ))
}

/// Continues training the forward model stored at `init` on `trajs` (a second stage at a lower
/// learning rate, say): its shape, scalings and lumped model are kept, so `trajs` should be the
/// trajectories it was trained on. Returns the model and the curve of this stage.
pub fn continue_forward(
    trajs: &[Trajectory],
    init: &Path,
    train_cfg: &TrainConfig,
    lambda: f64,
) -> Result<(TrainedForward, Vec<EpochRecord>)> {
    let (dt, n) = check_set(trajs)?;
    let start = TrainedForward::load(init)?;
    if start.config.state_dim != n || (start.meta.dt_s - dt).abs() > 1e-12 * dt {
        return Err(DynamicsError::Data(format!(
            "{} holds a model of {} state components at dt {} s, the data has {n} at {dt} s",
            init.display(),
            start.config.state_dim,
            start.meta.dt_s
        )));
    }
    let ck = Checkpoint::read(init)?;
    let model = ck.load_into(
        start.config.init(&cpu_autodiff(), start.meta.weight_seed),
        forward::ARCHITECTURE,
        &start.config,
    )?;
    let lumped = start.meta.lumped.clone();
    let scalers = start.scalers.clone();
    let data = Samples::build(trajs, start.config.window, &scalers, Some(&lumped))?;
    let slope_t = scaled_slope_t(&lumped, &scalers, dt);
    let report = train(model, data.len(), train_cfg, |m, batch, device| {
        forward_loss(m, &data, &slope_t, lambda, batch, device)
    })?;
    let meta = ModelMeta {
        loss_weight: lambda,
        train: train_cfg.clone(),
        best_epoch: report.best_epoch,
        best_loss: report.best_loss,
        samples: data.len(),
        ..start.meta
    };
    Ok((
        TrainedForward {
            config: start.config,
            model: report.model,
            scalers,
            meta,
        },
        report.curve,
    ))
}

/// Trains the inverse model on `trajs` with the cycle loss through `forward` (frozen).
pub fn train_inverse(
    trajs: &[Trajectory],
    forward: &TrainedForward,
    config: &InverseConfig,
    train_cfg: &TrainConfig,
    beta: f64,
    weight_seed: u64,
) -> Result<(TrainedInverse, Vec<EpochRecord>)> {
    let (dt, n) = check_set(trajs)?;
    if config.state_dim != n || forward.config.state_dim != n {
        return Err(DynamicsError::Data(format!(
            "models expect {} / {} state components, data has {n}",
            config.state_dim, forward.config.state_dim
        )));
    }
    let scalers = forward.scalers.clone();
    let data = Samples::build(trajs, forward.config.window, &scalers, None)?;
    let cols = config.input_dim();
    if cols > data.inverse_cols {
        return Err(DynamicsError::Data(format!(
            "the inverse model takes {cols} inputs, the forward model's scalings cover {} \
             (a checkpoint from before the current velocity was an input: retrain the forward \
             model, or leave the current velocity out)",
            data.inverse_cols
        )));
    }
    let (ad, plain) = (cpu_autodiff(), cpu());
    let cycle = CycleTarget::new(&forward.model, &scalers, &ad, &plain);
    let model = config.init(&ad, weight_seed);
    let report = train(model, data.len(), train_cfg, |m, batch, device: &Device| {
        inverse_loss(m, cols, &data, Some(&cycle), beta, batch, device)
    })?;
    let meta = ModelMeta {
        dt_s: dt,
        accel_scale: scalers.accel.clone(),
        lumped: forward.meta.lumped.clone(),
        loss_weight: beta,
        weight_seed,
        train: train_cfg.clone(),
        best_epoch: report.best_epoch,
        best_loss: report.best_loss,
        samples: data.len(),
    };
    Ok((
        TrainedInverse {
            config: config.clone(),
            model: report.model,
            scalers,
            meta,
        },
        report.curve,
    ))
}

fn scaler_map(s: &Scalers) -> BTreeMap<String, Standardizer> {
    BTreeMap::from([
        ("step".to_string(), s.step.clone()),
        ("velocity".to_string(), s.velocity.clone()),
        ("pressure".to_string(), s.pressure.clone()),
        ("inverse_input".to_string(), s.inverse_input.clone()),
    ])
}

fn read_parts(ck: &Checkpoint) -> Result<(Scalers, ModelMeta)> {
    let meta: ModelMeta = serde_json::from_value(ck.header.meta.clone()).map_err(|e| {
        ocm_learn::LearnError::CheckpointMismatch {
            path: ck.path.clone(),
            reason: format!("run facts do not decode: {e}"),
        }
    })?;
    let scalers = Scalers {
        step: ck.scaler("step")?.clone(),
        velocity: ck.scaler("velocity")?.clone(),
        pressure: ck.scaler("pressure")?.clone(),
        inverse_input: ck.scaler("inverse_input")?.clone(),
        accel: meta.accel_scale.clone(),
    };
    Ok((scalers, meta))
}

fn meta_json(meta: &ModelMeta) -> serde_json::Value {
    serde_json::to_value(meta).unwrap_or(serde_json::Value::Null)
}

impl TrainedForward {
    /// Writes the checkpoint.
    pub fn save(&self, path: &Path) -> Result<()> {
        let info = CheckpointInfo {
            architecture: forward::ARCHITECTURE,
            config: &self.config,
            scalers: scaler_map(&self.scalers),
            meta: meta_json(&self.meta),
        };
        Ok(save_checkpoint(path, &self.model, &info)?)
    }

    /// Reads a checkpoint written by [`TrainedForward::save`].
    pub fn load(path: &Path) -> Result<Self> {
        let ck = Checkpoint::read(path)?;
        let config: ForwardConfig = ck.config_of(&[forward::ARCHITECTURE])?;
        let model = ck.load_into(config.init(&cpu(), 0), forward::ARCHITECTURE, &config)?;
        let (scalers, meta) = read_parts(&ck)?;
        Ok(Self {
            config,
            model,
            scalers,
            meta,
        })
    }
}

impl TrainedInverse {
    /// Writes the checkpoint.
    pub fn save(&self, path: &Path) -> Result<()> {
        let info = CheckpointInfo {
            architecture: inverse::ARCHITECTURE,
            config: &self.config,
            scalers: scaler_map(&self.scalers),
            meta: meta_json(&self.meta),
        };
        Ok(save_checkpoint(path, &self.model, &info)?)
    }

    /// Reads a checkpoint written by [`TrainedInverse::save`].
    pub fn load(path: &Path) -> Result<Self> {
        let ck = Checkpoint::read(path)?;
        let config: InverseConfig = ck.config_of(&[inverse::ARCHITECTURE])?;
        let model = ck.load_into(config.init(&cpu(), 0), inverse::ARCHITECTURE, &config)?;
        let (scalers, meta) = read_parts(&ck)?;
        Ok(Self {
            config,
            model,
            scalers,
            meta,
        })
    }
}
