//! Proximal policy optimisation (clipped surrogate, generalised advantage estimation) on the
//! vectorised environments, with `ocm-learn` MLPs for the policy mean and the value.
//!
//! The policy is Gaussian with a state-independent standard deviation that is annealed linearly
//! from `std_start` to `std_end` (not learned: fewer moving parts, and the schedule is seeded
//! and reproducible). Truncated episodes bootstrap from the value of their final observation.
//! The deterministic policy (the mean) is scored every `eval_every` iterations on fixed seeds;
//! the best one by mean return is kept.

use crate::env::{ACT_DIM, Env, EnvConfig, OBS_DIM};
use crate::error::{Result, RlError};
use crate::eval::evaluate;
use crate::policy::{Policy, check_residual_scale, policy_config, zero_output_mlp};
use crate::robot::Robot;
use crate::vec_env::VecEnv;
use ocm_learn::burn::module::Module;
use ocm_learn::burn::optim::{AdamConfig, GradientsParams};
use ocm_learn::burn::tensor::Tensor;
use ocm_learn::{Activation, Mlp, MlpConfig};
use rand::SeedableRng;
use rand::seq::SliceRandom;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, StandardNormal};
use serde::{Deserialize, Serialize};
use std::path::PathBuf;
use std::sync::Arc;
use std::time::Instant;

/// Seeds of the evaluation episodes during training (disjoint from the training seeds).
pub const EVAL_SEED: u64 = 1_000_000;

/// Settings of PPO.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct PpoConfig {
    /// Rollout-and-update iterations.
    pub iterations: usize,
    /// Parallel environments.
    pub envs: usize,
    /// Steps per environment and iteration.
    pub horizon: usize,
    /// Passes over each rollout.
    pub epochs: usize,
    /// Samples per gradient step.
    pub minibatch: usize,
    /// Adam step size of both networks.
    pub learning_rate: f64,
    /// Discount.
    pub gamma: f64,
    /// GAE lambda.
    pub lambda: f64,
    /// Ratio clip epsilon.
    pub clip: f64,
    /// Exploration standard deviation at the start, action units.
    pub std_start: f64,
    /// Exploration standard deviation at the end.
    pub std_end: f64,
    /// Hidden widths of policy and value networks.
    pub hidden: Vec<usize>,
    /// Seed of weights, episodes and noise.
    pub seed: u64,
    /// Threads stepping the environments.
    pub threads: usize,
    /// Evaluate the deterministic policy every this many iterations.
    pub eval_every: usize,
    /// Episodes per evaluation.
    pub eval_episodes: usize,
    /// Start the policy from this checkpoint (a BC policy of the same shape) instead of random
    /// weights; the untouched start is scored too, so the kept policy is never worse on the
    /// evaluation episodes.
    #[serde(default)]
    pub init_from: Option<PathBuf>,
    /// Iterations at the start in which only the value network learns (the policy is held), so
    /// that a warm-started policy is not pushed around by an untrained critic.
    #[serde(default)]
    pub critic_warmup: usize,
    /// Weight of the squared distance of the policy mean to the initial policy's mean in the
    /// actor loss (with `init_from`: a KL anchor to the start, since the Gaussians share their
    /// standard deviation; 0: none).
    #[serde(default)]
    pub bc_weight: f64,
    /// Learn a residual on this policy checkpoint (a BC policy.ckpt) instead of a policy: the
    /// environment gets the base's action plus `residual_scale` times the Gaussian sample
    /// clamped to [-1, 1]; the residual network starts with a zero output layer, so iteration
    /// 0 is the base exactly. With `bc_weight` the anchor is the zero correction.
    #[serde(default)]
    pub residual_on: Option<PathBuf>,
    /// Largest residual correction per action value, action units.
    #[serde(default = "default_residual_scale")]
    pub residual_scale: f64,
    /// Factor on the exploration standard deviation per action value (theta_x, theta_y, d).
    /// One action unit moves the TCP about 84 mm sideways (a bend) and 30 mm along z (d, three
    /// prismatic joints of 0..20 mm) at mid-range, while pressing a plate 1 mm further is
    /// more than 1 N, so the contact tasks need far less noise than the free paths, and
    /// differently per action value.
    #[serde(default = "default_std_scale")]
    pub std_scale: [f64; ACT_DIM],
}

fn default_residual_scale() -> f64 {
    0.1
}

fn default_std_scale() -> [f64; ACT_DIM] {
    [1.0; ACT_DIM]
}

impl Default for PpoConfig {
    fn default() -> Self {
        PpoConfig {
            iterations: 100,
            envs: 8,
            horizon: 100,
            epochs: 8,
            minibatch: 200,
            learning_rate: 3e-4,
            gamma: 0.95,
            lambda: 0.95,
            clip: 0.2,
            std_start: 0.3,
            std_end: 0.05,
            hidden: vec![128, 128],
            seed: 0,
            threads: 2,
            eval_every: 5,
            eval_episodes: 2,
            init_from: None,
            critic_warmup: 0,
            bc_weight: 0.0,
            residual_on: None,
            residual_scale: default_residual_scale(),
            std_scale: default_std_scale(),
        }
    }
}

/// One point of a training curve.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct RlRecord {
    /// Iteration, from 1.
    pub iteration: usize,
    /// Environment steps so far.
    pub env_steps: usize,
    /// Mean reward per step of the iteration's (exploring) rollout.
    pub mean_reward: f64,
    /// Mean return of the deterministic policy on the evaluation episodes (NaN when not scored).
    pub eval_return: f64,
    /// Its mean position error, mm.
    pub eval_position_error_mm: f64,
    /// Its mean force error, N.
    pub eval_force_error_n: f64,
    /// Wall time, s.
    pub elapsed_s: f64,
}

/// Writes a training curve as CSV (units in the header).
pub fn write_curve_csv(path: &std::path::Path, curve: &[RlRecord]) -> Result<()> {
    let mut w = csv::Writer::from_path(path).map_err(|e| RlError::io(path, e.into()))?;
    let io = |e: csv::Error| RlError::io(path, e.into());
    w.write_record([
        "iteration",
        "env_steps",
        "mean_step_reward",
        "eval_return",
        "eval_position_error_mm",
        "eval_force_error_n",
        "elapsed_s",
    ])
    .map_err(io)?;
    for r in curve {
        w.write_record([
            r.iteration.to_string(),
            r.env_steps.to_string(),
            format!("{}", r.mean_reward),
            format!("{}", r.eval_return),
            format!("{}", r.eval_position_error_mm),
            format!("{}", r.eval_force_error_n),
            format!("{:.3}", r.elapsed_s),
        ])
        .map_err(io)?;
    }
    w.flush().map_err(|e| RlError::io(path, e))
}

fn forward_rows(m: &Mlp, rows: &[f64], cols: usize) -> Vec<f64> {
    let device = ocm_learn::cpu();
    let x = ocm_learn::tensor2(
        rows.iter().map(|&v| v as f32).collect(),
        rows.len() / cols,
        cols,
        &device,
    );
    ocm_learn::values(m.forward(x))
        .into_iter()
        .map(f64::from)
        .collect()
}

/// Scores a policy on `episodes` evaluation episodes: (mean return, position mm, force N).
pub fn score(
    robot: &Arc<Robot>,
    env: &EnvConfig,
    policy: &Policy,
    episodes: usize,
) -> Result<(f64, f64, f64)> {
    let mut e = Env::new(robot.clone(), *env)?;
    let r = evaluate(&mut e, episodes, EVAL_SEED, |_, obs| policy.act(obs))?;
    Ok((
        r.episode_return.mean,
        r.position_error_mm.mean,
        r.force_error_n.mean,
    ))
}

/// Trains a policy with PPO; `on_iteration` sees each curve point (progress bars).
pub fn train(
    robot: &Arc<Robot>,
    env_cfg: &EnvConfig,
    cfg: &PpoConfig,
    mut on_iteration: impl FnMut(&RlRecord),
) -> Result<(Policy, Vec<RlRecord>)> {
    if cfg.iterations == 0 || cfg.envs == 0 || cfg.horizon == 0 || cfg.minibatch == 0 {
        return Err(RlError::Invalid(
            "PPO needs iterations, envs, horizon and minibatch >= 1".into(),
        ));
    }
    if !cfg.std_scale.iter().all(|v| *v > 0.0 && v.is_finite()) {
        return Err(RlError::Invalid(format!(
            "PPO std_scale {:?} must be finite and > 0",
            cfg.std_scale
        )));
    }
    if !(cfg.bc_weight >= 0.0 && cfg.bc_weight.is_finite()) {
        return Err(RlError::Invalid(format!(
            "PPO bc_weight {} must be finite and >= 0",
            cfg.bc_weight
        )));
    }
    let device = ocm_learn::cpu_autodiff();
    let pcfg = policy_config(&cfg.hidden);
    let vcfg = MlpConfig {
        input: OBS_DIM,
        hidden: cfg.hidden.clone(),
        output: 1,
        activation: Activation::Tanh,
    };
    let base = match &cfg.residual_on {
        Some(path) => {
            if cfg.init_from.is_some() {
                return Err(RlError::Invalid(
                    "PPO takes either init_from (fine-tune a policy) or residual_on (learn a \
                     correction to it), not both"
                        .into(),
                ));
            }
            check_residual_scale(cfg.residual_scale)?;
            Some(Policy::load(path)?.0)
        }
        None => None,
    };
    let make_policy = |mlp: Mlp| -> Result<Policy> {
        match &base {
            Some(b) => Policy::residual_on(b.clone(), mlp, pcfg.clone(), cfg.residual_scale),
            None => Ok(Policy::new(mlp, pcfg.clone())),
        }
    };
    let mut actor = match (&cfg.init_from, &base) {
        (Some(path), _) => load_actor(path, &pcfg, &device, cfg.seed)?,
        (None, Some(_)) => zero_output_mlp(&pcfg, &device, cfg.seed),
        (None, None) => pcfg.init(&device, cfg.seed),
    };
    let anchor = (cfg.bc_weight > 0.0).then(|| actor.valid());
    let mut critic = vcfg.init(&device, cfg.seed ^ 0x0c41_71c0);
    let mut opt_a = AdamConfig::new().init();
    let mut opt_c = AdamConfig::new().init();
    let mut venv = VecEnv::new(robot.clone(), *env_cfg, cfg.envs, cfg.threads)?;
    let mut obs = venv.reset(cfg.seed)?;
    let mut rng = ChaCha8Rng::seed_from_u64(cfg.seed ^ 0x9905_0000_0000_0001);
    let (n, t_len) = (cfg.envs, cfg.horizon);
    let start = Instant::now();
    let mut curve = vec![];
    let mut best: Option<(f64, Policy)> = None;
    let mut steps_done = 0;
    if cfg.init_from.is_some() || base.is_some() {
        let p = make_policy(actor.valid())?;
        let (r, pe, fe) = score(robot, env_cfg, &p, cfg.eval_episodes.max(1))?;
        let rec = RlRecord {
            iteration: 0,
            env_steps: 0,
            mean_reward: f64::NAN,
            eval_return: r,
            eval_position_error_mm: pe,
            eval_force_error_n: fe,
            elapsed_s: start.elapsed().as_secs_f64(),
        };
        best = Some((r, p));
        on_iteration(&rec);
        curve.push(rec);
    }
    for it in 1..=cfg.iterations {
        let frac = (it - 1) as f64 / (cfg.iterations.max(2) - 1) as f64;
        let std = cfg.std_start + (cfg.std_end - cfg.std_start) * frac;
        let a_eval = actor.valid();
        let c_eval = critic.valid();
        let mut b_obs = Vec::with_capacity(n * t_len * OBS_DIM);
        let mut b_act = Vec::with_capacity(n * t_len * ACT_DIM);
        let mut b_logp = Vec::with_capacity(n * t_len);
        let mut b_rew = vec![0.0; n * t_len];
        let mut b_val = vec![0.0; n * t_len];
        let mut b_end = vec![false; n * t_len];
        let mut raw_reward = 0.0;
        for t in 0..t_len {
            let mean = forward_rows(&a_eval, &obs, OBS_DIM);
            let value = forward_rows(&c_eval, &obs, OBS_DIM);
            let mut acts = Vec::with_capacity(n * ACT_DIM);
            for i in 0..n {
                let mut lp = 0.0;
                for k in 0..ACT_DIM {
                    let eps: f64 = StandardNormal.sample(&mut rng);
                    let a = mean[i * ACT_DIM + k] + std * cfg.std_scale[k] * eps;
                    lp += -0.5 * eps * eps;
                    acts.push(a);
                }
                b_logp.push(lp);
            }
            b_obs.extend_from_slice(&obs);
            b_act.extend_from_slice(&acts);
            // The environment clips; the policy's log-probability is of the unclipped sample.
            let clipped: Vec<f64> = match &base {
                Some(b) => b
                    .act_batch(&obs)?
                    .iter()
                    .zip(&acts)
                    .map(|(ab, r)| (ab + cfg.residual_scale * r.clamp(-1.0, 1.0)).clamp(-1.0, 1.0))
                    .collect(),
                None => acts.iter().map(|a| a.clamp(-1.0, 1.0)).collect(),
            };
            let s = venv.step(&clipped)?;
            let final_values: Vec<Option<f64>> = s
                .final_obs
                .iter()
                .zip(&s.truncated)
                .map(|(o, &tr)| match (o, tr) {
                    (Some(o), true) => Some(forward_rows(&c_eval, o, OBS_DIM)[0]),
                    _ => None,
                })
                .collect();
            raw_reward += s.rewards.iter().sum::<f64>();
            for i in 0..n {
                let idx = t * n + i;
                b_val[idx] = value[i];
                b_rew[idx] = s.rewards[i] + final_values[i].map_or(0.0, |v| cfg.gamma * v);
                b_end[idx] = s.terminated[i] || s.truncated[i];
            }
            obs = s.obs;
        }
        steps_done += n * t_len;
        let last_v = forward_rows(&c_eval, &obs, OBS_DIM);
        // GAE over each environment's column.
        let mut adv = vec![0.0; n * t_len];
        for i in 0..n {
            let mut gae = 0.0;
            for t in (0..t_len).rev() {
                let idx = t * n + i;
                let next_v = if b_end[idx] {
                    0.0
                } else if t + 1 < t_len {
                    b_val[(t + 1) * n + i]
                } else {
                    last_v[i]
                };
                let delta = b_rew[idx] + cfg.gamma * next_v - b_val[idx];
                gae = delta
                    + if b_end[idx] {
                        0.0
                    } else {
                        cfg.gamma * cfg.lambda * gae
                    };
                adv[idx] = gae;
            }
        }
        let ret: Vec<f64> = adv.iter().zip(&b_val).map(|(a, v)| a + v).collect();
        let mean_adv = adv.iter().sum::<f64>() / adv.len() as f64;
        let std_adv =
            (adv.iter().map(|a| (a - mean_adv).powi(2)).sum::<f64>() / adv.len() as f64).sqrt();
        let adv_n: Vec<f32> = adv
            .iter()
            .map(|a| ((a - mean_adv) / (std_adv + 1e-8)) as f32)
            .collect();
        let obs32: Vec<f32> = b_obs.iter().map(|&v| v as f32).collect();
        let act32: Vec<f32> = b_act.iter().map(|&v| v as f32).collect();
        let anchor32: Vec<f32> = match &anchor {
            Some(m) => forward_rows(m, &b_obs, OBS_DIM)
                .into_iter()
                .map(|v| v as f32)
                .collect(),
            None => vec![],
        };
        let mut order: Vec<usize> = (0..n * t_len).collect();
        let inv2s2 = ocm_learn::tensor2(
            cfg.std_scale
                .iter()
                .map(|k| (0.5 / (std * std * k * k)) as f32)
                .collect(),
            1,
            ACT_DIM,
            &device,
        );
        for _ in 0..cfg.epochs {
            order.shuffle(&mut rng);
            for mb in order.chunks(cfg.minibatch) {
                let m = mb.len();
                let x = ocm_learn::gather_rows(&obs32, OBS_DIM, mb, &device);
                let a = ocm_learn::gather_rows(&act32, ACT_DIM, mb, &device);
                let old: Vec<f32> = mb.iter().map(|&j| b_logp[j] as f32).collect();
                let old = ocm_learn::tensor2(old, m, 1, &device);
                let ad = ocm_learn::tensor2(mb.iter().map(|&j| adv_n[j]).collect(), m, 1, &device);
                let rt =
                    ocm_learn::tensor2(mb.iter().map(|&j| ret[j] as f32).collect(), m, 1, &device);
                let mu: Tensor<2> = actor.forward(x.clone());
                let d = mu.clone() - a;
                // log N(a; mu, std) up to the constant the old log-probability shares.
                let logp = (d.clone() * d * inv2s2.clone()).sum_dim(1).neg();
                let ratio = (logp - old).exp();
                let s1 = ratio.clone() * ad.clone();
                let s2 = ratio.clamp(1.0 - cfg.clip as f32, 1.0 + cfg.clip as f32) * ad;
                if it > cfg.critic_warmup {
                    let mut loss_a = s1.min_pair(s2).mean().neg();
                    if anchor.is_some() {
                        let start = ocm_learn::gather_rows(&anchor32, ACT_DIM, mb, &device);
                        let da = mu - start;
                        loss_a = loss_a
                            + (da.clone() * da)
                                .sum_dim(1)
                                .mean()
                                .mul_scalar(cfg.bc_weight as f32);
                    }
                    let grads = GradientsParams::from_grads(loss_a.backward(), &actor);
                    actor = opt_a.step(cfg.learning_rate, actor, grads);
                }
                let dv: Tensor<2> = critic.forward(x) - rt;
                let loss_c = (dv.clone() * dv).mean();
                let grads = GradientsParams::from_grads(loss_c.backward(), &critic);
                critic = opt_c.step(cfg.learning_rate, critic, grads);
            }
        }
        let mean_reward = raw_reward / b_rew.len() as f64;
        let mut rec = RlRecord {
            iteration: it,
            env_steps: steps_done,
            mean_reward,
            eval_return: f64::NAN,
            eval_position_error_mm: f64::NAN,
            eval_force_error_n: f64::NAN,
            elapsed_s: start.elapsed().as_secs_f64(),
        };
        if it % cfg.eval_every.max(1) == 0 || it == cfg.iterations {
            let p = make_policy(actor.valid())?;
            let (r, pe, fe) = score(robot, env_cfg, &p, cfg.eval_episodes.max(1))?;
            rec.eval_return = r;
            rec.eval_position_error_mm = pe;
            rec.eval_force_error_n = fe;
            if best.as_ref().is_none_or(|(b, _)| r > *b) {
                best = Some((r, p));
            }
        }
        on_iteration(&rec);
        curve.push(rec);
    }
    let (_, policy) = best.ok_or_else(|| RlError::Invalid("no evaluation ran".into()))?;
    Ok((policy, curve))
}

/// The policy network of a saved policy checkpoint, on the training device (warm start).
pub fn load_actor(
    path: &std::path::Path,
    pcfg: &MlpConfig,
    device: &ocm_learn::burn::tensor::Device,
    seed: u64,
) -> Result<Mlp> {
    let ck = ocm_learn::Checkpoint::read(path)?;
    Ok(ck.load_into(pcfg.init(device, seed), crate::policy::ARCHITECTURE, pcfg)?)
}
