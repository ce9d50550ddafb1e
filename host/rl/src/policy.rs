//! Deterministic policies: an MLP of `ocm-learn` from the 40 observation values to the three
//! action values (clamped to [-1, 1] when acting), or to six (SAC: mean and log standard deviation
//! of a Gaussian squashed by tanh; acting takes tanh of the mean), saved as an `ocm-learn`
//! checkpoint. A residual policy adds a bounded correction of its own network to a base policy
//! (`scale` times its output clamped to [-1, 1]; [`Policy::zero_residual`] starts it at exactly
//! the base), and is saved as two checkpoints: its own network and the base beside it.

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
    /// Set for a residual policy: where its base is and how large its correction may be.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub residual: Option<ResidualMeta>,
}

/// How a residual policy's checkpoint names its base.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ResidualMeta {
    /// File name of the base policy's checkpoint, in the residual checkpoint's folder.
    pub base_file: String,
    /// Largest correction per action value, action units.
    pub scale: f64,
}

/// The base of a residual policy.
#[derive(Debug, Clone)]
pub struct Residual {
    /// The policy the correction is added to.
    pub base: Box<Policy>,
    /// Largest correction per action value, action units.
    pub scale: f64,
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
    residual: Option<Residual>,
}

/// Checks a residual scale: finite and in (0, 2].
pub fn check_residual_scale(scale: f64) -> Result<()> {
    if !(scale > 0.0 && scale <= 2.0) {
        return Err(RlError::Invalid(format!(
            "residual scale {scale} must be in (0, 2] action units"
        )));
    }
    Ok(())
}

/// A policy network whose output layer is zero (weights and bias): it outputs exactly zero for
/// every observation, and its hidden layers are drawn from `seed`.
pub fn zero_output_mlp(config: &MlpConfig, device: &Device, seed: u64) -> Mlp {
    use ocm_learn::burn::nn::{Initializer, LinearConfig};
    let mut mlp = config.init(device, seed);
    let fan_in = config.hidden.last().copied().unwrap_or(config.input);
    if let Some(last) = mlp.layers.last_mut() {
        *last = LinearConfig::new(fan_in, config.output)
            .with_initializer(Initializer::Zeros)
            .init(device);
    }
    mlp
}

impl Policy {
    /// Wraps a network (moved to the plain CPU device).
    pub fn new(mlp: Mlp, config: MlpConfig) -> Self {
        let device = ocm_learn::cpu();
        Policy {
            mlp,
            config,
            device,
            residual: None,
        }
    }

    /// A residual policy: `base` plus `scale` times this network's output clamped to [-1, 1]
    /// (the sum clamped to the action box). The network maps observations to the 3 actions.
    pub fn residual_on(base: Policy, mlp: Mlp, config: MlpConfig, scale: f64) -> Result<Self> {
        check_residual_scale(scale)?;
        if config.input != OBS_DIM || config.output != ACT_DIM {
            return Err(RlError::Invalid(format!(
                "a residual network maps {OBS_DIM} -> {ACT_DIM} values, not {} -> {}",
                config.input, config.output
            )));
        }
        let mut p = Policy::new(mlp, config);
        p.residual = Some(Residual {
            base: Box::new(base),
            scale,
        });
        Ok(p)
    }

    /// A residual on `base` whose correction is zero for every observation (hidden widths
    /// `hidden`, hidden weights from `seed`): it acts exactly as `base`.
    pub fn zero_residual(base: Policy, hidden: &[usize], scale: f64, seed: u64) -> Result<Self> {
        let config = policy_config(hidden);
        let mlp = zero_output_mlp(&config, &ocm_learn::cpu(), seed);
        Policy::residual_on(base, mlp, config, scale)
    }

    /// The base and scale of a residual policy (`None` for a plain one).
    pub fn residual(&self) -> Option<&Residual> {
        self.residual.as_ref()
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
        if let Some(r) = &self.residual {
            let base = r.base.act_batch(obs)?;
            return Ok(base
                .iter()
                .zip(&y)
                .map(|(&b, &c)| (b + r.scale * f64::from(c).clamp(-1.0, 1.0)).clamp(-1.0, 1.0))
                .collect());
        }
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

    /// Writes the policy with its facts; a residual policy writes its base beside it
    /// (`<stem>.base.ckpt`) and names it in the facts.
    pub fn save(&self, path: &Path, meta: &PolicyMeta) -> Result<()> {
        let mut meta = meta.clone();
        if let Some(r) = &self.residual {
            let stem = path
                .file_stem()
                .map_or("policy".into(), |s| s.to_string_lossy().into_owned());
            let base_file = format!("{stem}.base.ckpt");
            let mut base_meta = meta.clone();
            base_meta.residual = None;
            base_meta.algorithm = format!("base of {}", meta.algorithm);
            r.base.save(&path.with_file_name(&base_file), &base_meta)?;
            meta.residual = Some(ResidualMeta {
                base_file,
                scale: r.scale,
            });
        } else {
            meta.residual = None;
        }
        let meta = serde_json::to_value(&meta)
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
        let config: MlpConfig = ck.config_of(&[ARCHITECTURE])?;
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
        let policy = match &meta.residual {
            None => Policy::new(mlp, config),
            Some(r) => {
                let base_path = path.with_file_name(&r.base_file);
                if base_path == path || r.base_file.contains(['/', '\\']) {
                    return Err(RlError::Invalid(format!(
                        "{}: residual base '{}' must be another file in the same folder",
                        path.display(),
                        r.base_file
                    )));
                }
                let (base, _) = Policy::load(&base_path)?;
                Policy::residual_on(base, mlp, config, r.scale)
                    .map_err(|e| RlError::Invalid(format!("{}: {e}", path.display())))?
            }
        };
        Ok((policy, meta))
    }
}
