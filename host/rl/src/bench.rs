//! Throughput: environment steps per second (one environment, and a vector of them on a thread
//! pool) and policy inference rate, as medians over repeats.

use crate::env::{ACT_DIM, Env, EnvConfig};
use crate::error::Result;
use crate::policy::Policy;
use crate::robot::Robot;
use crate::vec_env::VecEnv;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};
use std::sync::Arc;
use std::time::Instant;

/// What to measure.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct BenchConfig {
    /// Environments of the vector run.
    pub envs: usize,
    /// Threads of the vector run.
    pub threads: usize,
    /// Control steps per environment and repeat.
    pub steps: usize,
    /// Repeats (the median is reported).
    pub repeats: usize,
    /// Policy evaluations per repeat.
    pub inferences: usize,
}

/// Medians of the repeats.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct BenchReport {
    /// Control steps per second of one environment.
    pub single_steps_per_s: f64,
    /// Control steps per second summed over the vector environment.
    pub vector_steps_per_s: f64,
    /// Physics steps per control step.
    pub substeps: usize,
    /// Single-observation policy evaluations per second.
    pub policy_hz: f64,
}

/// Runs the benchmark with random actions (seeded) and `policy` for the inference rate.
pub fn run(
    robot: &Arc<Robot>,
    env_cfg: &EnvConfig,
    policy: &Policy,
    cfg: &BenchConfig,
) -> Result<BenchReport> {
    let mut rng = ChaCha8Rng::seed_from_u64(0);
    let repeats = cfg.repeats.max(1);
    let steps = cfg.steps.max(1);
    let mut small =
        |n: usize| -> Vec<f64> { (0..n).map(|_| rng.random_range(-0.3..0.3)).collect() };
    let mut single = vec![];
    let mut env = Env::new(robot.clone(), *env_cfg)?;
    for r in 0..repeats {
        env.reset(r as u64)?;
        let acts = small(steps * ACT_DIM);
        let t = Instant::now();
        for k in 0..steps {
            let s = env.step(&acts[k * ACT_DIM..(k + 1) * ACT_DIM])?;
            if s.terminated || s.truncated {
                env.reset(k as u64)?;
            }
        }
        single.push(steps as f64 / t.elapsed().as_secs_f64());
    }
    let mut vector = vec![];
    let mut venv = VecEnv::new(robot.clone(), *env_cfg, cfg.envs.max(1), cfg.threads.max(1))?;
    for r in 0..repeats {
        venv.reset(r as u64)?;
        let acts = small(venv.len() * ACT_DIM);
        let t = Instant::now();
        for _ in 0..steps {
            venv.step(&acts)?;
        }
        vector.push((steps * venv.len()) as f64 / t.elapsed().as_secs_f64());
    }
    let obs = env.reset(0)?;
    let mut hz = vec![];
    for _ in 0..repeats {
        let t = Instant::now();
        for _ in 0..cfg.inferences.max(1) {
            std::hint::black_box(policy.act(&obs)?);
        }
        hz.push(cfg.inferences.max(1) as f64 / t.elapsed().as_secs_f64());
    }
    Ok(BenchReport {
        single_steps_per_s: ocm_mor::run::median(&single),
        vector_steps_per_s: ocm_mor::run::median(&vector),
        substeps: env_cfg.substeps,
        policy_hz: ocm_mor::run::median(&hz),
    })
}
