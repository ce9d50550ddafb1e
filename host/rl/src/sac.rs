//! Soft actor-critic on the vectorised environments: a tanh-squashed Gaussian actor (an MLP with
//! the mean and log standard deviation as outputs), two Q networks on (observation, action), a
//! replay buffer, a fixed entropy temperature and target Q networks copied from the live ones
//! every `target_every` updates (a hard update instead of Polyak averaging: `ocm-learn`'s modules
//! have no parameter averaging, and a copy is one clone).

use crate::env::{ACT_DIM, EnvConfig, OBS_DIM};
use crate::error::{Result, RlError};
use crate::policy::Policy;
use crate::ppo::{RlRecord, score};
use crate::robot::Robot;
use crate::vec_env::VecEnv;
use ocm_learn::burn::module::Module;
use ocm_learn::burn::optim::{AdamConfig, GradientsParams};
use ocm_learn::burn::tensor::{Device, Tensor, activation};
use ocm_learn::{Activation, Mlp, MlpConfig};
use rand::seq::index::sample;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, StandardNormal};
use serde::{Deserialize, Serialize};
use std::path::PathBuf;
use std::sync::Arc;
use std::time::Instant;

/// Settings of SAC.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SacConfig {
    /// Vector steps (each steps every environment once and makes one update).
    pub steps: usize,
    /// Parallel environments.
    pub envs: usize,
    /// Vector steps with uniformly random actions before learning starts.
    pub warmup: usize,
    /// Transitions per update.
    pub batch: usize,
    /// Adam step size.
    pub learning_rate: f64,
    /// Discount.
    pub gamma: f64,
    /// Entropy temperature.
    pub temperature: f64,
    /// Copy the Q networks to their targets every this many updates.
    pub target_every: usize,
    /// Hidden widths.
    pub hidden: Vec<usize>,
    /// Seed.
    pub seed: u64,
    /// Threads stepping the environments.
    pub threads: usize,
    /// Evaluate every this many vector steps.
    pub eval_every: usize,
    /// Episodes per evaluation.
    pub eval_episodes: usize,
    /// A BC policy checkpoint to start from: it acts (with Gaussian noise of `init_noise`)
    /// during the warm-up, the actor's mean is fitted to it on the warm-up data before the SAC
    /// updates begin, and it anchors the actor with `bc_weight`.
    #[serde(default)]
    pub init_from: Option<PathBuf>,
    /// Noise of the warm-up actions around the initial policy, action units.
    #[serde(default)]
    pub init_noise: f64,
    /// Gradient steps fitting the actor's tanh(mean) to the initial policy after the warm-up.
    #[serde(default)]
    pub pretrain_steps: usize,
    /// Vector steps after the warm-up in which only the Q networks learn.
    #[serde(default)]
    pub critic_warmup: usize,
    /// Weight of the squared distance between tanh(mean) and the initial policy's action in the
    /// actor loss (0: plain SAC after the start).
    #[serde(default)]
    pub bc_weight: f64,
}

impl Default for SacConfig {
    fn default() -> Self {
        SacConfig {
            steps: 10_000,
            envs: 8,
            warmup: 200,
            batch: 256,
            learning_rate: 3e-4,
            gamma: 0.95,
            temperature: 0.005,
            target_every: 50,
            hidden: vec![128, 128],
            seed: 0,
            threads: 2,
            eval_every: 500,
            eval_episodes: 2,
            init_from: None,
            init_noise: 0.1,
            pretrain_steps: 0,
            critic_warmup: 0,
            bc_weight: 0.0,
        }
    }
}

fn mlp(input: usize, hidden: &[usize], output: usize) -> MlpConfig {
    MlpConfig {
        input,
        hidden: hidden.to_vec(),
        output,
        activation: Activation::Relu,
    }
}

/// Squashed sample, its log-probability (`[n, 1]`), from actor outputs and standard normals.
fn sample_action(out: Tensor<2>, eps: Tensor<2>) -> (Tensor<2>, Tensor<2>) {
    let mean = out.clone().narrow(1, 0, ACT_DIM);
    let log_std = out.narrow(1, ACT_DIM, ACT_DIM).clamp(-5.0, 1.0);
    let u = mean + log_std.clone().exp() * eps.clone();
    let a = activation::tanh(u);
    let jac = (a.clone() * a.clone()).neg().add_scalar(1.0 + 1e-6).log();
    let logp = ((eps.clone() * eps).mul_scalar(-0.5) - log_std - jac)
        .sum_dim(1)
        .add_scalar(-0.5 * ACT_DIM as f32 * (2.0 * std::f32::consts::PI).ln());
    (a, logp)
}

fn normals(rng: &mut ChaCha8Rng, n: usize, device: &Device) -> Tensor<2> {
    let v: Vec<f32> = (0..n * ACT_DIM)
        .map(|_| StandardNormal.sample(rng))
        .collect();
    ocm_learn::tensor2(v, n, ACT_DIM, device)
}

struct Replay {
    obs: Vec<f32>,
    act: Vec<f32>,
    rew: Vec<f32>,
    next: Vec<f32>,
    cont: Vec<f32>,
}

impl Replay {
    fn len(&self) -> usize {
        self.rew.len()
    }
}

fn rows(src: &[f32], cols: usize, idx: &[usize], device: &Device) -> Tensor<2> {
    ocm_learn::gather_rows(src, cols, idx, device)
}

fn q_of(q: &Mlp, obs: Tensor<2>, act: Tensor<2>) -> Tensor<2> {
    q.forward(Tensor::cat(vec![obs, act], 1))
}

/// Trains a policy with SAC; `on_eval` sees each evaluated curve point.
pub fn train(
    robot: &Arc<Robot>,
    env_cfg: &EnvConfig,
    cfg: &SacConfig,
    mut on_eval: impl FnMut(&RlRecord),
) -> Result<(Policy, Vec<RlRecord>)> {
    if cfg.steps == 0 || cfg.envs == 0 || cfg.batch == 0 {
        return Err(RlError::Invalid(
            "SAC needs steps, envs and batch >= 1".into(),
        ));
    }
    let device = ocm_learn::cpu_autodiff();
    let plain = ocm_learn::cpu();
    let acfg = mlp(OBS_DIM, &cfg.hidden, 2 * ACT_DIM);
    let qcfg = mlp(OBS_DIM + ACT_DIM, &cfg.hidden, 1);
    let mut actor = acfg.init(&device, cfg.seed);
    let mut q1 = qcfg.init(&device, cfg.seed ^ 0x51);
    let mut q2 = qcfg.init(&device, cfg.seed ^ 0x52);
    let (mut t1, mut t2) = (q1.valid(), q2.valid());
    let mut opt_a = AdamConfig::new().init();
    let mut opt_q1 = AdamConfig::new().init();
    let mut opt_q2 = AdamConfig::new().init();
    let mut venv = VecEnv::new(robot.clone(), *env_cfg, cfg.envs, cfg.threads)?;
    let mut obs = venv.reset(cfg.seed)?;
    let mut rng = ChaCha8Rng::seed_from_u64(cfg.seed ^ 0x5ac0_0000_0000_0001);
    let mut buf = Replay {
        obs: vec![],
        act: vec![],
        rew: vec![],
        next: vec![],
        cont: vec![],
    };
    let n = cfg.envs;
    let alpha = cfg.temperature as f32;
    let gamma = cfg.gamma as f32;
    let start = Instant::now();
    let mut curve = vec![];
    let mut best: Option<(f64, Policy)> = None;
    let mut rewards_since = (0.0, 0usize);
    let teacher = match &cfg.init_from {
        Some(p) => Some(Policy::load(p)?.0),
        None => None,
    };
    // The teacher's actions on rows of the replay buffer, as a tensor on `device`.
    let teach =
        |t: &Policy, rows_obs: &[f32], idx: &[usize], device: &Device| -> Result<Tensor<2>> {
            let mut o = Vec::with_capacity(idx.len() * OBS_DIM);
            for &i in idx {
                o.extend(
                    rows_obs[i * OBS_DIM..(i + 1) * OBS_DIM]
                        .iter()
                        .map(|&v| f64::from(v)),
                );
            }
            let a = t.act_batch(&o)?;
            Ok(ocm_learn::tensor2(
                a.iter().map(|&v| v as f32).collect(),
                idx.len(),
                ACT_DIM,
                device,
            ))
        };
    for step in 1..=cfg.steps {
        let acts: Vec<f64> = if step <= cfg.warmup {
            match &teacher {
                Some(t) => t
                    .act_batch(&obs)?
                    .into_iter()
                    .map(|a| {
                        let e: f64 = StandardNormal.sample(&mut rng);
                        (a + cfg.init_noise * e).clamp(-1.0, 1.0)
                    })
                    .collect(),
                None => (0..n * ACT_DIM)
                    .map(|_| rng.random_range(-1.0..1.0))
                    .collect(),
            }
        } else {
            let x = ocm_learn::tensor2(obs.iter().map(|&v| v as f32).collect(), n, OBS_DIM, &plain);
            let eps = normals(&mut rng, n, &plain);
            let (a, _) = sample_action(actor.valid().forward(x), eps);
            ocm_learn::values(a).into_iter().map(f64::from).collect()
        };
        let s = venv.step(&acts)?;
        for i in 0..n {
            let next = s.final_obs[i]
                .as_deref()
                .unwrap_or(&s.obs[i * OBS_DIM..(i + 1) * OBS_DIM]);
            buf.obs.extend(
                obs[i * OBS_DIM..(i + 1) * OBS_DIM]
                    .iter()
                    .map(|&v| v as f32),
            );
            buf.act.extend(
                acts[i * ACT_DIM..(i + 1) * ACT_DIM]
                    .iter()
                    .map(|&v| v as f32),
            );
            buf.rew.push(s.rewards[i] as f32);
            buf.next.extend(next.iter().map(|&v| v as f32));
            buf.cont.push(if s.terminated[i] { 0.0 } else { 1.0 });
            rewards_since.0 += s.rewards[i];
            rewards_since.1 += 1;
        }
        obs = s.obs;
        if step == cfg.warmup.max(1)
            && let Some(t) = &teacher
        {
            // Fit tanh(mean) of the actor to the teacher on the warm-up states.
            for _ in 0..cfg.pretrain_steps {
                let idx = sample(&mut rng, buf.len(), cfg.batch.min(buf.len())).into_vec();
                let o = rows(&buf.obs, OBS_DIM, &idx, &device);
                let target = teach(t, &buf.obs, &idx, &device)?;
                let mean = activation::tanh(actor.forward(o).narrow(1, 0, ACT_DIM));
                let d = mean - target;
                let loss = (d.clone() * d).mean();
                let g = GradientsParams::from_grads(loss.backward(), &actor);
                actor = opt_a.step(cfg.learning_rate, actor, g);
            }
        }
        if step > cfg.warmup && buf.len() >= cfg.batch {
            let idx = sample(&mut rng, buf.len(), cfg.batch).into_vec();
            let m = idx.len();
            let o = rows(&buf.obs, OBS_DIM, &idx, &device);
            let a = rows(&buf.act, ACT_DIM, &idx, &device);
            let r = rows(&buf.rew, 1, &idx, &device);
            let c = rows(&buf.cont, 1, &idx, &device);
            let next_plain = rows(&buf.next, OBS_DIM, &idx, &plain);
            // Target: r + gamma c (min Q_target(s', a') - alpha log pi(a'|s')), no gradient.
            let (a2, logp2) = sample_action(
                actor.valid().forward(next_plain.clone()),
                normals(&mut rng, m, &plain),
            );
            let qn = q_of(&t1, next_plain.clone(), a2.clone()).min_pair(q_of(&t2, next_plain, a2));
            let y: Vec<f32> = ocm_learn::values(qn - logp2.mul_scalar(alpha));
            let rv = ocm_learn::values(r);
            let cv = ocm_learn::values(c);
            let y: Vec<f32> = (0..m).map(|k| rv[k] + gamma * cv[k] * y[k]).collect();
            let y = ocm_learn::tensor2(y, m, 1, &device);
            let d1 = q_of(&q1, o.clone(), a.clone()) - y.clone();
            let l1 = (d1.clone() * d1).mean();
            let g = GradientsParams::from_grads(l1.backward(), &q1);
            q1 = opt_q1.step(cfg.learning_rate, q1, g);
            let d2 = q_of(&q2, o.clone(), a) - y;
            let l2 = (d2.clone() * d2).mean();
            let g = GradientsParams::from_grads(l2.backward(), &q2);
            q2 = opt_q2.step(cfg.learning_rate, q2, g);
            // Actor: alpha log pi(a|s) - min Q(s, a), a reparameterised.
            let o_actor = o.clone();
            let (an, logp) = sample_action(actor.forward(o.clone()), normals(&mut rng, m, &device));
            let qa = q_of(&q1, o.clone(), an.clone()).min_pair(q_of(&q2, o, an));
            let mut la = (logp.mul_scalar(alpha) - qa).mean();
            if step > cfg.warmup + cfg.critic_warmup {
                if let (Some(t), true) = (&teacher, cfg.bc_weight > 0.0) {
                    let target = teach(t, &buf.obs, &idx, &device)?;
                    let mean = activation::tanh(actor.forward(o_actor).narrow(1, 0, ACT_DIM));
                    let d = mean - target;
                    la = la + (d.clone() * d).mean().mul_scalar(cfg.bc_weight as f32);
                }
                let g = GradientsParams::from_grads(la.backward(), &actor);
                actor = opt_a.step(cfg.learning_rate, actor, g);
            }
            if step % cfg.target_every.max(1) == 0 {
                t1 = q1.valid();
                t2 = q2.valid();
            }
        }
        if step % cfg.eval_every.max(1) == 0 || step == cfg.steps {
            let p = Policy::new(actor.valid(), acfg.clone());
            let (ret, pe, fe) = score(robot, env_cfg, &p, cfg.eval_episodes.max(1))?;
            let rec = RlRecord {
                iteration: step,
                env_steps: step * n,
                mean_reward: rewards_since.0 / rewards_since.1.max(1) as f64,
                eval_return: ret,
                eval_position_error_mm: pe,
                eval_force_error_n: fe,
                elapsed_s: start.elapsed().as_secs_f64(),
            };
            rewards_since = (0.0, 0);
            if best.as_ref().is_none_or(|(b, _)| ret > *b) {
                best = Some((ret, p));
            }
            on_eval(&rec);
            curve.push(rec);
        }
    }
    let (_, policy) = best.ok_or_else(|| RlError::Invalid("no evaluation ran".into()))?;
    Ok((policy, curve))
}
