//! Deterministic policies: an MLP of `ocm-learn` from the 40 observation values to the three
//! action values (clamped to [-1, 1] when acting), or to six (SAC: mean and log standard deviation
//! of a Gaussian squashed by tanh; acting takes tanh of the mean), saved as an `ocm-learn`
//! checkpoint.

use crate::env::{ACT_DIM, OBS_DIM};
use crate::error::{Result, RlError};
use ocm_learn::burn::tensor::Device;
use ocm_learn::{Activation, Checkpoint, CheckpointInfo, Mlp, MlpConfig, save_checkpoint};
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;
use std::path::Path;

/// Architecture name in checkpoints.
pub const ARCHITECTURE: &str = "rl.policy";

/// Facts stored with a policy.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct PolicyMeta {
    /// Task name.
    pub task: String,
    /// Algorithm (`bc`, `ppo`).
    pub algorithm: String,
    /// Seed of the run.
    pub seed: u64,
    /// Score that selected this checkpoint (mean position error in mm, or force error in N).
    pub score: f64,
}

/// The policy network shape: tanh hidden layers of the given widths.
pub fn policy_config(hidden: &[usize]) -> MlpConfig {
    MlpConfig {
        input: OBS_DIM,
        hidden: hidden.to_vec(),
        output: ACT_DIM,
        activation: Activation::Tanh,
    }
}

/// A trained policy on the plain CPU device.
#[derive(Debug, Clone)]
pub struct Policy {
    /// The network (its output is the action mean).
    pub mlp: Mlp,
    /// Its shape.
    pub config: MlpConfig,
    device: Device,
}

impl Policy {
    /// Wraps a network (moved to the plain CPU device).
    pub fn new(mlp: Mlp, config: MlpConfig) -> Self {
        let device = ocm_learn::cpu();
        Policy {
            mlp,
            config,
            device,
        }
    }

    /// Actions of `n` observations (row-major `n x 40`), clamped to [-1, 1].
    pub fn act_batch(&self, obs: &[f64]) -> Result<Vec<f64>> {
        if !obs.len().is_multiple_of(OBS_DIM) {
            return Err(RlError::Invalid(format!(
                "observations have {} values, not a multiple of {OBS_DIM}",
                obs.len()
            )));
        }
        let n = obs.len() / OBS_DIM;
        let x = ocm_learn::tensor2(
            obs.iter().map(|&v| v as f32).collect(),
            n,
            OBS_DIM,
            &self.device,
        );
        let y = ocm_learn::values(self.mlp.forward(x));
        let width = self.config.output;
        if width == 2 * ACT_DIM {
            // A squashed Gaussian (SAC): the first half is the mean before tanh.
            return Ok((0..n)
                .flat_map(|i| (0..ACT_DIM).map(move |k| (i, k)))
                .map(|(i, k)| f64::from(y[i * width + k]).tanh())
                .collect());
        }
        Ok(y.iter().map(|&v| f64::from(v).clamp(-1.0, 1.0)).collect())
    }

    /// The action of one observation.
    pub fn act(&self, obs: &[f64]) -> Result<[f64; 3]> {
        let a = self.act_batch(obs)?;
        if a.len() != ACT_DIM {
            return Err(RlError::Invalid(format!(
                "one observation of {OBS_DIM} values expected, got {}",
                obs.len()
            )));
        }
        Ok([a[0], a[1], a[2]])
    }

    /// Writes the policy with its facts.
    pub fn save(&self, path: &Path, meta: &PolicyMeta) -> Result<()> {
        let meta = serde_json::to_value(meta)
            .map_err(|e| RlError::Invalid(format!("policy facts: {e}")))?;
        save_checkpoint(
            path,
            &self.mlp,
            &CheckpointInfo {
                architecture: ARCHITECTURE,
                config: &self.config,
                scalers: BTreeMap::new(),
                meta,
            },
        )?;
        Ok(())
    }

    /// Reads a policy written by [`Policy::save`] and its facts.
    pub fn load(path: &Path) -> Result<(Self, PolicyMeta)> {
        let ck = Checkpoint::read(path)?;
        let config: MlpConfig = ck.config()?;
        if config.input != OBS_DIM || (config.output != ACT_DIM && config.output != 2 * ACT_DIM) {
            return Err(RlError::Invalid(format!(
                "{}: policy maps {} -> {} values, the environments {OBS_DIM} -> {ACT_DIM}",
                path.display(),
                config.input,
                config.output
            )));
        }
        let mlp = ck.load_into(config.init(&ocm_learn::cpu(), 0), ARCHITECTURE, &config)?;
        let meta: PolicyMeta = serde_json::from_value(ck.header.meta.clone()).map_err(|e| {
            RlError::Invalid(format!(
                "{}: policy facts do not decode: {e}",
                path.display()
            ))
        })?;
        Ok((Policy::new(mlp, config), meta))
    }
}
