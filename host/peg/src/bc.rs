//! Behaviour cloning (eq 6.19): an MLP from `[s, z_left, z_right]` (or `s` alone, the
//! no-touch baseline) to the expert's gripper velocity, trained on the squared error of the
//! standardised actions with the workspace's training loop.

use std::collections::BTreeMap;
use std::path::Path;

use ocm_learn::burn::tensor::Tensor;
use ocm_learn::{
    Checkpoint, CheckpointInfo, EpochRecord, LrSchedule, Mlp, MlpConfig, Standardizer, TrainConfig,
    cpu, cpu_autodiff, gather_rows, save_checkpoint, tensor2, train, values,
};
use serde::{Deserialize, Serialize};

use crate::demos::DemoSet;
use crate::error::{PegError, Result};
use crate::expert::ExpertConfig;
use crate::scene::{N_ACTION, N_PROPRIO, SceneConfig};
use crate::trial::Randomisation;

/// Architecture name in the checkpoints.
pub const ARCHITECTURE: &str = "ocm-peg/bc-mlp";

/// How to train a policy.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct BcConfig {
    /// Hidden layer widths (ReLU).
    pub hidden: Vec<usize>,
    /// The training loop's settings.
    pub train: TrainConfig,
    /// Seed of the initial weights.
    pub weight_seed: u64,
}

impl Default for BcConfig {
    fn default() -> Self {
        Self {
            hidden: vec![256, 256],
            train: TrainConfig {
                epochs: 60,
                batch_size: 256,
                learning_rate: 1e-3,
                val_fraction: 0.1,
                patience: 15,
                grad_clip_norm: None,
                seed: 0,
                progress: false,
                lr_schedule: LrSchedule::Constant,
            },
            weight_seed: 0,
        }
    }
}

/// What a checkpoint says about its policy beyond the network.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct PolicyMeta {
    /// Whether the tactile latents are inputs.
    pub touch: bool,
    /// The encoder of the latents (also stored for the baseline: its demonstrations' encoder).
    pub encoder: String,
    /// Latent values per sensor.
    pub latent_dim: usize,
    /// Demonstrations and rows trained on.
    pub demos: usize,
    /// Rows (control steps) trained on.
    pub rows: usize,
    /// Epoch of the kept weights.
    pub best_epoch: usize,
    /// Validation loss of the kept weights (standardised units).
    pub best_loss: f64,
    /// Training wall time, s.
    pub train_time_s: f64,
    /// The scene of its demonstrations (absent in checkpoints written before the grasp could
    /// be compliant: the default scene).
    #[serde(default)]
    pub scene: Option<SceneConfig>,
    /// The randomisation of its demonstrations' trials (absent in checkpoints written before
    /// the hole's position could be uncertain: the default).
    #[serde(default)]
    pub randomisation: Option<Randomisation>,
    /// The expert it was cloned from (absent in checkpoints written before the expert could
    /// search: the default).
    #[serde(default)]
    pub expert: Option<ExpertConfig>,
    /// The DAgger rounds that added the policy's own states to its demonstrations (absent:
    /// cloned from the demonstrations alone).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub dagger: Option<DaggerRecord>,
}

/// How a policy was trained on its own states (DAgger, Ross, Gordon and Bagnell 2011): each
/// round runs the policy on fresh trials, labels every state it visits with the expert's
/// action there, adds those rows to the data and clones again from scratch.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct DaggerConfig {
    /// Rounds of rollouts and retraining.
    pub rounds: usize,
    /// Trials per round.
    pub trials: usize,
    /// Seed of the rounds' trials (round r runs trials r * trials .. (r + 1) * trials of this
    /// stream; keep it apart from the evaluation's seeds).
    pub seed: u64,
}

/// One DAgger round: how the policy it rolled out did, and what it added.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct DaggerRound {
    /// Round number, from 1.
    pub round: usize,
    /// Success of the rolled-out policy on the round's trials.
    pub success_rate: f64,
    /// Rows (control steps) labelled and added.
    pub rows_added: usize,
    /// Rows trained on after the round.
    pub rows: usize,
    /// Validation loss of the policy trained after the round (standardised units).
    pub best_loss: f64,
    /// Wall time of the round (rollouts and training), s.
    pub wall_time_s: f64,
}

/// The DAgger settings of a policy and its rounds.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct DaggerRecord {
    /// The settings.
    pub config: DaggerConfig,
    /// The rounds, in order.
    pub rounds: Vec<DaggerRound>,
}

/// A trained policy: network, scalers and what it sees.
#[derive(Debug)]
pub struct BcPolicy {
    model: Mlp,
    obs_scaler: Standardizer,
    act_scaler: Standardizer,
    /// What the policy was trained on.
    pub meta: PolicyMeta,
    config: MlpConfig,
}

/// The trained policy with its loss curve.
#[derive(Debug)]
pub struct BcTraining {
    /// The policy (weights of the best validation epoch).
    pub policy: BcPolicy,
    /// Losses per epoch.
    pub curve: Vec<EpochRecord>,
}

/// Trains a policy on `demos`; `touch` selects the inputs.
pub fn train_bc(demos: &DemoSet, touch: bool, cfg: &BcConfig) -> Result<BcTraining> {
    if demos.rows() < 2 {
        return Err(PegError::Invalid(format!(
            "{} demonstration rows are too few to train on",
            demos.rows()
        )));
    }
    let start = std::time::Instant::now();
    let (x, in_dim) = demos.inputs(touch);
    let obs_scaler = Standardizer::fit(&x, in_dim)?;
    let act_scaler = Standardizer::fit(&demos.actions, N_ACTION)?;
    let xs = obs_scaler.apply(&x)?;
    let ys = act_scaler.apply(&demos.actions)?;
    let config = MlpConfig::relu(in_dim, &cfg.hidden, N_ACTION);
    let model = config.init(&cpu_autodiff(), cfg.weight_seed);
    let report = train(model, demos.rows(), &cfg.train, |m: &Mlp, batch, device| {
        let xb = gather_rows(&xs, in_dim, batch, device);
        let yb = gather_rows(&ys, N_ACTION, batch, device);
        let d: Tensor<2> = m.forward(xb) - yb;
        (d.clone() * d).mean()
    })?;
    Ok(BcTraining {
        policy: BcPolicy {
            model: report.model,
            obs_scaler,
            act_scaler,
            meta: PolicyMeta {
                touch,
                encoder: demos.encoder.clone(),
                latent_dim: demos.latent_dim,
                demos: demos.demos(),
                rows: demos.rows(),
                best_epoch: report.best_epoch,
                best_loss: report.best_loss,
                train_time_s: start.elapsed().as_secs_f64(),
                scene: Some(demos.settings.scene.clone()),
                randomisation: Some(demos.settings.randomisation.clone()),
                expert: Some(demos.settings.expert.clone()),
                dagger: None,
            },
            config,
        },
        curve: report.curve,
    })
}

impl BcPolicy {
    /// Observation values the policy reads from a full observation.
    pub fn input_dim(&self) -> usize {
        self.config.input
    }

    /// Gripper velocities for a batch of full observations `[s, z_left, z_right]` (the
    /// baseline reads `s` only). Wrong lengths and non-finite values are errors.
    pub fn act_batch(&self, obs: &[Vec<f64>]) -> Result<Vec<[f64; N_ACTION]>> {
        if obs.is_empty() {
            return Ok(Vec::new());
        }
        let full = N_PROPRIO + 2 * self.meta.latent_dim;
        let d = self.input_dim();
        let mut x = Vec::with_capacity(obs.len() * d);
        for (i, o) in obs.iter().enumerate() {
            if o.len() != full {
                return Err(PegError::Invalid(format!(
                    "observation {i} has {} values, the policy expects {full}",
                    o.len()
                )));
            }
            if let Some(j) = o.iter().position(|v| !v.is_finite()) {
                return Err(PegError::Invalid(format!(
                    "observation {i} value {j} is not finite"
                )));
            }
            x.extend_from_slice(&o[..d]);
        }
        let xs = self.obs_scaler.apply(&x)?;
        let out = values(self.model.forward(tensor2(xs, obs.len(), d, &cpu())));
        let a = self.act_scaler.invert(&out)?;
        Ok(a.chunks_exact(N_ACTION)
            .map(|r| std::array::from_fn(|k| r[k]))
            .collect())
    }

    /// Writes the checkpoint (weights, scalers, meta).
    pub fn save(&self, path: &Path) -> Result<()> {
        let mut scalers = BTreeMap::new();
        scalers.insert("obs".to_string(), self.obs_scaler.clone());
        scalers.insert("action".to_string(), self.act_scaler.clone());
        let meta = serde_json::to_value(&self.meta)
            .map_err(|e| PegError::file(path, format!("meta: {e}")))?;
        save_checkpoint(
            path,
            &self.model,
            &CheckpointInfo {
                architecture: ARCHITECTURE,
                config: &self.config,
                scalers,
                meta,
            },
        )?;
        Ok(())
    }

    /// Reads a checkpoint written by [`BcPolicy::save`].
    pub fn load(path: &Path) -> Result<Self> {
        let ck = Checkpoint::read(path)?;
        let config: MlpConfig = ck.config_of(&[ARCHITECTURE])?;
        let meta: PolicyMeta = serde_json::from_value(ck.header.meta.clone())
            .map_err(|e| PegError::file(path, format!("policy meta: {e}")))?;
        let obs_scaler = ck.scaler("obs")?.clone();
        let act_scaler = ck.scaler("action")?.clone();
        let expected = if meta.touch {
            N_PROPRIO + 2 * meta.latent_dim
        } else {
            N_PROPRIO
        };
        if config.input != expected || config.output != N_ACTION || obs_scaler.dim() != expected {
            return Err(PegError::file(
                path,
                format!(
                    "network {} -> {} does not fit a policy reading {expected} values",
                    config.input, config.output
                ),
            ));
        }
        let model = ck.load_into(config.init(&cpu(), 0), ARCHITECTURE, &config)?;
        Ok(Self {
            model,
            obs_scaler,
            act_scaler,
            meta,
            config,
        })
    }
}
