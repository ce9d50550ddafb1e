//! The mapping MLPs of App. D: f_SP from chamber pressures to the rigid-link surrogate's joints,
//! its inverse from the joint groups back to pressures, and f_RS between two pressure domains.
//!
//! All three are the same network, a [64, 64, 64] ReLU MLP with a linear output, trained on
//! standardised inputs and outputs with the MSE of the standardised outputs, Adam at 1e-3,
//! batch 32, at most 200 epochs, early stopping after 20 epochs without a validation gain
//! (App. D). [`SurrogateMlp`] plugs f_SP and its inverse into the surrogate's
//! [`ActuationMap`](ocm_surrogate::mapping::ActuationMap) as a
//! [`Regressor`](ocm_surrogate::mapping::Regressor).

use std::collections::BTreeMap;
use std::path::Path;

use ocm_learn::burn::tensor::Device;
use ocm_learn::{
    Checkpoint, CheckpointInfo, EpochRecord, LrSchedule, Mlp, MlpConfig, Standardizer, TrainConfig,
    cpu, cpu_autodiff, gather_rows, save_checkpoint, tensor2, train, values,
};
use ocm_surrogate::chain::{N_JOINTS, Posture};
use ocm_surrogate::fem_samples::FemSample;
use ocm_surrogate::mapping::{Match, Regressor, group_means};
use serde::{Deserialize, Serialize};

use crate::error::{DynamicsError, Result};

/// Architecture name stored in checkpoints.
pub const ARCHITECTURE: &str = "ocm-dynamics/map";

/// What a mapping network maps.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub enum MapRole {
    /// f_SP: chamber pressures (kPa) to surrogate joints (rad, m).
    PressureToJoints,
    /// Inverse of f_SP: joint group means (rad, rad, m) to chamber pressures (kPa).
    JointsToPressure,
    /// f_RS: pressures of one domain (kPa) to the pressures of another that give the same TCP.
    PressureToPressure,
}

/// Shape of a mapping network.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct MapConfig {
    /// What it maps.
    pub role: MapRole,
    /// Input features.
    pub input: usize,
    /// Output features.
    pub output: usize,
    /// Hidden widths (ReLU).
    pub hidden: Vec<usize>,
}

impl MapConfig {
    /// App. D's network: three hidden layers of 64 with ReLU, linear output.
    pub fn dissertation(role: MapRole, input: usize, output: usize) -> Self {
        Self {
            role,
            input,
            output,
            hidden: vec![64; 3],
        }
    }

    fn mlp(&self) -> MlpConfig {
        MlpConfig::relu(self.input, &self.hidden, self.output)
    }
}

/// App. D's training settings: Adam at 1e-3, batch 32, 200 epochs, patience 20; 10 % of the
/// samples validate.
pub fn dissertation_train_config(seed: u64) -> TrainConfig {
    TrainConfig {
        epochs: 200,
        batch_size: 32,
        learning_rate: 1e-3,
        val_fraction: 0.1,
        patience: 20,
        grad_clip_norm: None,
        seed,
        progress: false,
        lr_schedule: LrSchedule::Constant,
    }
}

/// Facts stored with a mapping network.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct MapMeta {
    /// Seed of the weights.
    pub weight_seed: u64,
    /// Training settings.
    pub train: TrainConfig,
    /// Epoch of the kept weights.
    pub best_epoch: usize,
    /// Validation loss of the kept weights (standardised units).
    pub best_loss: f64,
    /// Training samples.
    pub samples: usize,
}

/// A trained mapping network with its scalings.
#[derive(Debug, Clone)]
pub struct TrainedMap {
    /// Shape.
    pub config: MapConfig,
    /// Weights (no autodiff).
    pub model: Mlp,
    /// Scaling of the inputs.
    pub input: Standardizer,
    /// Scaling of the outputs.
    pub output: Standardizer,
    /// Run facts.
    pub meta: MapMeta,
}

fn check_rows(what: &str, data: &[f64], dim: usize) -> Result<usize> {
    if dim == 0 || data.is_empty() || !data.len().is_multiple_of(dim) {
        return Err(DynamicsError::Data(format!(
            "{what}: {} values are not rows of {dim}",
            data.len()
        )));
    }
    if let Some(i) = data.iter().position(|v| !v.is_finite()) {
        return Err(DynamicsError::Data(format!(
            "{what}: row {} column {} is not finite",
            i / dim,
            i % dim
        )));
    }
    Ok(data.len() / dim)
}

impl TrainedMap {
    /// Trains `config`'s network on row-major `inputs` -> `outputs`.
    pub fn train(
        inputs: &[f64],
        outputs: &[f64],
        config: &MapConfig,
        train_cfg: &TrainConfig,
        weight_seed: u64,
    ) -> Result<(Self, Vec<EpochRecord>)> {
        let n = check_rows("map inputs", inputs, config.input)?;
        let m = check_rows("map outputs", outputs, config.output)?;
        if n != m {
            return Err(DynamicsError::Data(format!(
                "{n} input rows but {m} output rows"
            )));
        }
        let input = Standardizer::fit(inputs, config.input)?;
        let output = Standardizer::fit(outputs, config.output)?;
        let (x, y) = (input.apply(inputs)?, output.apply(outputs)?);
        let (di, dout) = (config.input, config.output);
        let model = config.mlp().init(&cpu_autodiff(), weight_seed);
        let report = train(model, n, train_cfg, |m: &Mlp, batch, device: &Device| {
            let xb = gather_rows(&x, di, batch, device);
            let yb = gather_rows(&y, dout, batch, device);
            (m.forward(xb) - yb).powi_scalar(2).mean()
        })?;
        let meta = MapMeta {
            weight_seed,
            train: train_cfg.clone(),
            best_epoch: report.best_epoch,
            best_loss: report.best_loss,
            samples: n,
        };
        Ok((
            Self {
                config: config.clone(),
                model: report.model,
                input,
                output,
                meta,
            },
            report.curve,
        ))
    }

    /// Outputs for row-major `inputs`, physical units.
    pub fn predict(&self, inputs: &[f64]) -> Result<Vec<f64>> {
        let n = check_rows("map inputs", inputs, self.config.input)?;
        let x = tensor2(self.input.apply(inputs)?, n, self.config.input, &cpu());
        Ok(self.output.invert(&values(self.model.forward(x)))?)
    }

    /// Writes the checkpoint.
    pub fn save(&self, path: &Path) -> Result<()> {
        let info = CheckpointInfo {
            architecture: ARCHITECTURE,
            config: &self.config,
            scalers: BTreeMap::from([
                ("input".to_string(), self.input.clone()),
                ("output".to_string(), self.output.clone()),
            ]),
            meta: serde_json::to_value(&self.meta).unwrap_or(serde_json::Value::Null),
        };
        Ok(save_checkpoint(path, &self.model, &info)?)
    }

    /// Reads a checkpoint written by [`TrainedMap::save`].
    pub fn load(path: &Path) -> Result<Self> {
        let ck = Checkpoint::read(path)?;
        let mismatch = |reason: String| ocm_learn::LearnError::CheckpointMismatch {
            path: path.to_path_buf(),
            reason,
        };
        let config: MapConfig = ck.config_of(&[ARCHITECTURE])?;
        let model = ck.load_into(config.mlp().init(&cpu(), 0), ARCHITECTURE, &config)?;
        let meta: MapMeta = serde_json::from_value(ck.header.meta.clone())
            .map_err(|e| mismatch(format!("run facts do not decode: {e}")))?;
        let (input, output) = (ck.scaler("input")?.clone(), ck.scaler("output")?.clone());
        if input.dim() != config.input || output.dim() != config.output {
            return Err(mismatch(format!(
                "scalers of {} / {} features for a {} -> {} network",
                input.dim(),
                output.dim(),
                config.input,
                config.output
            ))
            .into());
        }
        Ok(Self {
            config,
            model,
            input,
            output,
            meta,
        })
    }
}

/// Training pairs of f_SP: pressures (kPa) and the L-BFGS-B postures of Algorithm 1.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct PosturePairs {
    /// Chamber pressures, kPa.
    pub pressures_kpa: Vec<[f64; 3]>,
    /// Optimised postures (rad, m), in the chain's joint order.
    pub postures: Vec<Posture>,
}

impl PosturePairs {
    /// Pairs of FEM samples and their Algorithm 1 matches.
    pub fn from_matches(samples: &[FemSample], matches: &[Match]) -> Result<Self> {
        if samples.len() != matches.len() || samples.is_empty() {
            return Err(DynamicsError::Data(format!(
                "{} samples but {} matches",
                samples.len(),
                matches.len()
            )));
        }
        Ok(Self {
            pressures_kpa: samples.iter().map(|s| s.pressures_kpa).collect(),
            postures: matches.iter().map(|m| m.posture).collect(),
        })
    }

    /// Number of pairs.
    pub fn len(&self) -> usize {
        self.postures.len()
    }

    /// Whether there is no pair.
    pub fn is_empty(&self) -> bool {
        self.postures.is_empty()
    }
}

/// f_SP and its inverse as App. D's MLPs, usable as the surrogate's regression.
#[derive(Debug, Clone)]
pub struct SurrogateMlp {
    /// Pressures (kPa) -> the 11 joints.
    pub forward: TrainedMap,
    /// Group means (theta_x, theta_y, d) -> pressures (kPa).
    pub inverse: TrainedMap,
}

/// Checkpoint file names of [`SurrogateMlp`] in its folder.
pub const FSP_FILE: &str = "fsp.ckpt";
/// See [`FSP_FILE`].
pub const FSP_INVERSE_FILE: &str = "fsp_inverse.ckpt";

impl SurrogateMlp {
    /// Trains both networks on `pairs` (the inverse on the group means of the postures);
    /// returns the loss curves of both.
    pub fn train(
        pairs: &PosturePairs,
        train_cfg: &TrainConfig,
        weight_seed: u64,
    ) -> Result<(Self, Vec<EpochRecord>, Vec<EpochRecord>)> {
        if pairs.pressures_kpa.len() != pairs.postures.len() || pairs.is_empty() {
            return Err(DynamicsError::Data(format!(
                "{} pressures but {} postures",
                pairs.pressures_kpa.len(),
                pairs.postures.len()
            )));
        }
        let p: Vec<f64> = pairs.pressures_kpa.iter().flatten().copied().collect();
        let q: Vec<f64> = pairs.postures.iter().flatten().copied().collect();
        let g: Vec<f64> = pairs.postures.iter().flat_map(group_means).collect();
        let (forward, c1) = TrainedMap::train(
            &p,
            &q,
            &MapConfig::dissertation(MapRole::PressureToJoints, 3, N_JOINTS),
            train_cfg,
            weight_seed,
        )?;
        let (inverse, c2) = TrainedMap::train(
            &g,
            &p,
            &MapConfig::dissertation(MapRole::JointsToPressure, 3, 3),
            train_cfg,
            weight_seed.wrapping_add(1),
        )?;
        Ok((Self { forward, inverse }, c1, c2))
    }

    /// Writes both checkpoints into `dir` ([`FSP_FILE`], [`FSP_INVERSE_FILE`]).
    pub fn save(&self, dir: &Path) -> Result<()> {
        self.forward.save(&dir.join(FSP_FILE))?;
        self.inverse.save(&dir.join(FSP_INVERSE_FILE))
    }

    /// Reads both checkpoints from `dir` and checks their roles and shapes.
    pub fn load(dir: &Path) -> Result<Self> {
        let forward = TrainedMap::load(&dir.join(FSP_FILE))?;
        let inverse = TrainedMap::load(&dir.join(FSP_INVERSE_FILE))?;
        let ok = forward.config.role == MapRole::PressureToJoints
            && (forward.config.input, forward.config.output) == (3, N_JOINTS)
            && inverse.config.role == MapRole::JointsToPressure
            && (inverse.config.input, inverse.config.output) == (3, 3);
        if !ok {
            return Err(DynamicsError::Data(format!(
                "{}: the checkpoints are not f_SP (3 -> {N_JOINTS}) and its inverse (3 -> 3)",
                dir.display()
            )));
        }
        Ok(Self { forward, inverse })
    }
}

fn surrogate_err(e: DynamicsError) -> ocm_surrogate::SurrogateError {
    ocm_surrogate::SurrogateError::Invalid(format!("mapping MLP: {e}"))
}

impl Regressor for SurrogateMlp {
    fn name(&self) -> &str {
        "mlp"
    }

    fn posture(&self, pressures_kpa: &[f64; 3]) -> ocm_surrogate::Result<Posture> {
        let y = self.forward.predict(pressures_kpa).map_err(surrogate_err)?;
        Ok(std::array::from_fn(|j| y[j]))
    }

    fn pressures(&self, group_means: &[f64; 3]) -> ocm_surrogate::Result<[f64; 3]> {
        let y = self.inverse.predict(group_means).map_err(surrogate_err)?;
        Ok([y[0], y[1], y[2]])
    }
}
