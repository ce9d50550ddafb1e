//! N environments stepped together on a thread pool, with automatic reset.
//!
//! Actions and observations are flat row-major slices (`n x 3`, `n x 40`). An environment whose
//! episode ends is reset at once with the next seed of its own sequence (`seed + i + n * k` for
//! environment i's k-th episode), and its final observation is kept in [`VecStep::final_obs`]
//! (Gymnasium's same-step autoreset).

use crate::env::{ACT_DIM, Env, EnvConfig, OBS_DIM, StepInfo};
use crate::error::{Result, RlError};
use crate::robot::Robot;
use rayon::prelude::*;
use std::sync::Arc;

/// The result of stepping all environments.
#[derive(Debug, Clone, PartialEq)]
pub struct VecStep {
    /// Observations after the step (after the reset of finished environments), `n x 40`.
    pub obs: Vec<f64>,
    /// Rewards.
    pub rewards: Vec<f64>,
    /// Terminated flags.
    pub terminated: Vec<bool>,
    /// Truncated flags.
    pub truncated: Vec<bool>,
    /// The last observation of every environment whose episode ended in this step.
    pub final_obs: Vec<Option<Vec<f64>>>,
    /// Step details.
    pub infos: Vec<StepInfo>,
}

/// Vectorised environments.
pub struct VecEnv {
    envs: Vec<Env>,
    episodes: Vec<u64>,
    seed: u64,
    pool: rayon::ThreadPool,
}

impl VecEnv {
    /// `n` environments of `robot` with `config` on `threads` threads.
    pub fn new(robot: Arc<Robot>, config: EnvConfig, n: usize, threads: usize) -> Result<Self> {
        if n == 0 || threads == 0 {
            return Err(RlError::Invalid(
                "a vector environment needs n >= 1 environments and >= 1 thread".into(),
            ));
        }
        let envs = (0..n)
            .map(|_| Env::new(robot.clone(), config))
            .collect::<Result<Vec<_>>>()?;
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .map_err(|e| RlError::Invalid(format!("thread pool: {e}")))?;
        Ok(VecEnv {
            envs,
            episodes: vec![0; n],
            seed: 0,
            pool,
        })
    }

    /// Number of environments.
    pub fn len(&self) -> usize {
        self.envs.len()
    }

    /// Whether there are no environments (never: construction needs one).
    pub fn is_empty(&self) -> bool {
        self.envs.is_empty()
    }

    /// The environments.
    pub fn envs(&self) -> &[Env] {
        &self.envs
    }

    /// Mutable access to the environments (experts, inspection).
    pub fn envs_mut(&mut self) -> &mut [Env] {
        &mut self.envs
    }

    fn episode_seed(&self, i: usize) -> u64 {
        self.seed
            .wrapping_add(i as u64)
            .wrapping_add(self.envs.len() as u64 * self.episodes[i])
    }

    /// Resets every environment; environment i gets seed `seed + i`.
    pub fn reset(&mut self, seed: u64) -> Result<Vec<f64>> {
        self.seed = seed;
        self.episodes.iter_mut().for_each(|e| *e = 0);
        let seeds: Vec<u64> = (0..self.envs.len()).map(|i| self.episode_seed(i)).collect();
        let envs = &mut self.envs;
        let obs: Vec<Vec<f64>> = self.pool.install(|| {
            envs.par_iter_mut()
                .zip(seeds.par_iter())
                .map(|(e, &s)| e.reset(s))
                .collect::<Result<Vec<_>>>()
        })?;
        Ok(obs.concat())
    }

    /// Steps every environment with its row of `actions` (`n x 3`).
    pub fn step(&mut self, actions: &[f64]) -> Result<VecStep> {
        let n = self.envs.len();
        if actions.len() != n * ACT_DIM {
            return Err(RlError::ActionSize {
                found: actions.len(),
                expected: n * ACT_DIM,
            });
        }
        let envs = &mut self.envs;
        let steps = self.pool.install(|| {
            envs.par_iter_mut()
                .zip(actions.par_chunks(ACT_DIM))
                .map(|(e, a)| e.step(a))
                .collect::<Result<Vec<_>>>()
        })?;
        let mut out = VecStep {
            obs: Vec::with_capacity(n * OBS_DIM),
            rewards: Vec::with_capacity(n),
            terminated: Vec::with_capacity(n),
            truncated: Vec::with_capacity(n),
            final_obs: Vec::with_capacity(n),
            infos: Vec::with_capacity(n),
        };
        for (i, s) in steps.into_iter().enumerate() {
            if s.terminated || s.truncated {
                self.episodes[i] += 1;
                let seed = self.episode_seed(i);
                let obs = self.envs[i].reset(seed)?;
                out.obs.extend_from_slice(&obs);
                out.final_obs.push(Some(s.obs));
            } else {
                out.obs.extend_from_slice(&s.obs);
                out.final_obs.push(None);
            }
            out.rewards.push(s.reward);
            out.terminated.push(s.terminated);
            out.truncated.push(s.truncated);
            out.infos.push(s.info);
        }
        Ok(out)
    }
}
