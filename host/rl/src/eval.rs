//! Evaluation on 100-point episodes: position and force errors per step (the rows of
//! Table 4.2), returns, and the tracked trajectories for plots.

use crate::env::{Env, StepInfo};
use crate::error::{Result, RlError};
use serde::{Deserialize, Serialize};

/// Mean and standard deviation.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize, Default)]
pub struct MeanStd {
    /// Mean.
    pub mean: f64,
    /// Population standard deviation.
    pub std: f64,
}

impl MeanStd {
    /// Of a sample (zeros when empty).
    pub fn of(v: &[f64]) -> Self {
        if v.is_empty() {
            return MeanStd::default();
        }
        let n = v.len() as f64;
        let mean = v.iter().sum::<f64>() / n;
        let var = v.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / n;
        MeanStd {
            mean,
            std: var.sqrt(),
        }
    }
}

/// The outcome of an evaluation.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct EvalReport {
    /// Episodes run.
    pub episodes: usize,
    /// Steps scored.
    pub steps: usize,
    /// TCP distance to the step's target over all steps, mm.
    pub position_error_mm: MeanStd,
    /// Norm of the force error over all steps, N (zero for tasks without force objective).
    pub force_error_n: MeanStd,
    /// Undiscounted return per episode.
    pub episode_return: MeanStd,
    /// Episodes that terminated (TCP lost).
    pub failures: usize,
    /// Step details of the first episode (for plots).
    pub first_episode: Vec<StepInfo>,
}

/// Runs `episodes` episodes with seeds `seed, seed + 1, ...`, choosing actions with
/// `act(env, obs)`.
pub fn evaluate(
    env: &mut Env,
    episodes: usize,
    seed: u64,
    act: impl FnMut(&mut Env, &[f64]) -> Result<[f64; 3]>,
) -> Result<EvalReport> {
    let mut e = 0u64;
    let mut start = |env: &mut Env| {
        let o = env.reset(seed.wrapping_add(e));
        e += 1;
        o
    };
    evaluate_episodes(env, episodes, &mut start, act)
}

/// Runs `episodes` episodes, each begun by `start` (a reset, or [`Env::reset_with`] for other
/// paths), choosing actions with `act(env, obs)`.
pub fn evaluate_episodes(
    env: &mut Env,
    episodes: usize,
    start: &mut dyn FnMut(&mut Env) -> Result<Vec<f64>>,
    mut act: impl FnMut(&mut Env, &[f64]) -> Result<[f64; 3]>,
) -> Result<EvalReport> {
    // the report's means and success rate are over the episodes: none leaves them 0/0
    if episodes == 0 {
        return Err(RlError::Invalid(
            "evaluation episodes = 0: at least one is needed".into(),
        ));
    }
    let (mut pos, mut force, mut returns) = (vec![], vec![], vec![]);
    let mut failures = 0;
    let mut first = vec![];
    for e in 0..episodes {
        let mut obs = start(env)?;
        let mut ret = 0.0;
        loop {
            let a = act(env, &obs)?;
            let s = env.step(&a)?;
            ret += s.reward;
            pos.push(s.info.position_error_m * 1e3);
            force.push(s.info.force_error_n);
            if e == 0 {
                first.push(s.info);
            }
            obs = s.obs;
            if s.terminated {
                failures += 1;
            }
            if s.terminated || s.truncated {
                break;
            }
        }
        returns.push(ret);
    }
    Ok(EvalReport {
        episodes,
        steps: pos.len(),
        position_error_mm: MeanStd::of(&pos),
        force_error_n: MeanStd::of(&force),
        episode_return: MeanStd::of(&returns),
        failures,
        first_episode: first,
    })
}
