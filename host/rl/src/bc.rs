//! Behaviour cloning from the expert of eq 4.31: roll the expert out with seeded action noise
//! (so the data covers the states a slightly wrong policy visits), label every observation with
//! the expert's clean action, and fit the policy MLP with the `ocm-learn` training loop.

use crate::env::{ACT_DIM, Env, EnvConfig, OBS_DIM};
use crate::error::{Result, RlError};
use crate::policy::{Policy, policy_config};
use crate::robot::Robot;
use ocm_learn::burn::tensor::Tensor;
use ocm_learn::{EpochRecord, LrSchedule, TrainConfig};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, Normal};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use std::sync::Arc;

/// Expert observations and actions, row-major.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Demonstrations {
    /// `n x 40` observations.
    pub obs: Vec<f32>,
    /// `n x 3` expert actions.
    pub actions: Vec<f32>,
}

impl Demonstrations {
    /// Number of pairs.
    pub fn len(&self) -> usize {
        self.actions.len() / ACT_DIM
    }

    /// Whether there are none.
    pub fn is_empty(&self) -> bool {
        self.actions.is_empty()
    }
}

/// Settings of behaviour cloning.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct BcConfig {
    /// Expert episodes.
    pub episodes: usize,
    /// Standard deviation of the executed action noise, action units.
    pub noise: f64,
    /// Hidden layer widths of the policy.
    pub hidden: Vec<usize>,
    /// The supervised training settings.
    pub train: TrainConfig,
    /// Seed of the episodes, the noise and the weights.
    pub seed: u64,
    /// Threads collecting episodes.
    pub threads: usize,
}

impl Default for BcConfig {
    fn default() -> Self {
        BcConfig {
            episodes: 64,
            noise: 0.03,
            hidden: vec![128, 128],
            train: TrainConfig {
                epochs: 300,
                batch_size: 256,
                learning_rate: 1e-3,
                val_fraction: 0.1,
                patience: 40,
                grad_clip_norm: None,
                seed: 0,
                progress: false,
                lr_schedule: LrSchedule::Constant,
            },
            seed: 0,
            threads: 2,
        }
    }
}

fn episode(robot: &Arc<Robot>, cfg: &EnvConfig, noise: f64, seed: u64) -> Result<Demonstrations> {
    let mut env = Env::new(robot.clone(), *cfg)?;
    let mut obs = env.reset(seed)?;
    let mut rng = ChaCha8Rng::seed_from_u64(seed ^ 0xbc00_0000_0000_0001);
    let normal = Normal::new(0.0, noise.max(1e-300))
        .map_err(|e| RlError::Invalid(format!("noise {noise}: {e}")))?;
    let mut d = Demonstrations::default();
    loop {
        let a = env.expert_action()?;
        d.obs.extend(obs.iter().map(|&v| v as f32));
        d.actions.extend(a.iter().map(|&v| v as f32));
        let noisy: Vec<f64> = a
            .iter()
            .map(|&v| {
                let n = if noise > 0.0 {
                    normal.sample(&mut rng)
                } else {
                    0.0
                };
                (v + n).clamp(-1.0, 1.0)
            })
            .collect();
        let s = env.step(&noisy)?;
        obs = s.obs;
        if s.terminated || s.truncated {
            break;
        }
    }
    Ok(d)
}

/// Expert episodes with seeds `seed, seed + 1, ...`, in parallel on `threads` threads (the
/// result does not depend on the thread count).
pub fn collect(
    robot: &Arc<Robot>,
    cfg: &EnvConfig,
    episodes: usize,
    noise: f64,
    seed: u64,
    threads: usize,
) -> Result<Demonstrations> {
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(threads.max(1))
        .build()
        .map_err(|e| RlError::Invalid(format!("thread pool: {e}")))?;
    let parts = pool.install(|| {
        (0..episodes)
            .into_par_iter()
            .map(|e| episode(robot, cfg, noise, seed.wrapping_add(e as u64)))
            .collect::<Result<Vec<_>>>()
    })?;
    let mut d = Demonstrations::default();
    for p in parts {
        d.obs.extend(p.obs);
        d.actions.extend(p.actions);
    }
    Ok(d)
}

/// Fits a policy to demonstrations (mean squared action error); returns it and its loss curve.
pub fn fit(
    demos: &Demonstrations,
    hidden: &[usize],
    train: &TrainConfig,
    seed: u64,
) -> Result<(Policy, Vec<EpochRecord>)> {
    if demos.is_empty() {
        return Err(RlError::Invalid("no demonstrations".into()));
    }
    let config = policy_config(hidden);
    let model = config.init(&ocm_learn::cpu_autodiff(), seed);
    let report = ocm_learn::train(model, demos.len(), train, |m, batch, device| {
        let x = ocm_learn::gather_rows(&demos.obs, OBS_DIM, batch, device);
        let y = ocm_learn::gather_rows(&demos.actions, ACT_DIM, batch, device);
        let d: Tensor<2> = m.forward(x) - y;
        (d.clone() * d).mean()
    })?;
    Ok((Policy::new(report.model, config), report.curve))
}

/// Collects demonstrations and fits a policy.
pub fn train(
    robot: &Arc<Robot>,
    env: &EnvConfig,
    cfg: &BcConfig,
) -> Result<(Policy, Vec<EpochRecord>)> {
    let demos = collect(robot, env, cfg.episodes, cfg.noise, cfg.seed, cfg.threads)?;
    let mut train = cfg.train.clone();
    train.seed = cfg.seed;
    fit(&demos, &cfg.hidden, &train, cfg.seed)
}
