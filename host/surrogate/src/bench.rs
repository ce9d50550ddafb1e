//! Throughput of the articulated simulation: environments stepped in a batch over a fixed
//! number of threads, each with a seeded random walk of commanded postures.

use crate::batch::{BatchModel, EnvState};
use crate::chain::{ChainGeometry, N_JOINTS, Posture};
use crate::constraints::Limits;
use crate::sim::{SceneConfig, Sim, Surface};
use crate::{Result, SurrogateError};
use rand::{Rng, SeedableRng};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

/// Which stepper is timed.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Engine {
    /// The reduced-coordinate batch stepper ([`crate::batch`]), no contact.
    Batch,
    /// The rapier scene ([`crate::sim`]) with a plate above the TCP.
    Rapier,
}

/// Benchmark settings.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct BenchConfig {
    /// The stepper.
    pub engine: Engine,
    /// Environments in the batch.
    pub envs: usize,
    /// Steps per environment and repeat.
    pub steps: usize,
    /// Worker threads.
    pub threads: usize,
    /// Timed repeats (the median is reported).
    pub repeats: usize,
    /// Seed of the command random walks.
    pub seed: u64,
}

/// Benchmark result.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct BenchReport {
    /// The settings.
    pub config: BenchConfig,
    /// What was stepped.
    pub engine: String,
    /// Median over repeats of environment steps per second.
    pub steps_per_s_median: f64,
    /// Every repeat's steps per second.
    pub steps_per_s: Vec<f64>,
}

/// Times the configured engine.
pub fn run(chain: &ChainGeometry, limits: &Limits, cfg: &BenchConfig) -> Result<BenchReport> {
    match cfg.engine {
        Engine::Rapier => run_rapier(chain, limits, cfg),
        Engine::Batch => run_batch(chain, limits, cfg),
    }
}

fn check(cfg: &BenchConfig) -> Result<rayon::ThreadPool> {
    if cfg.envs == 0 || cfg.steps == 0 || cfg.threads == 0 || cfg.repeats == 0 {
        return Err(SurrogateError::Invalid(format!(
            "bench sizes must be positive: {cfg:?}"
        )));
    }
    rayon::ThreadPoolBuilder::new()
        .num_threads(cfg.threads)
        .build()
        .map_err(|e| SurrogateError::Solver(format!("thread pool: {e}")))
}

fn report(cfg: &BenchConfig, engine: &str, rates: Vec<f64>) -> BenchReport {
    let mut sorted = rates.clone();
    sorted.sort_by(f64::total_cmp);
    BenchReport {
        config: *cfg,
        engine: engine.into(),
        steps_per_s_median: sorted[sorted.len() / 2],
        steps_per_s: rates,
    }
}

/// Steps `envs` batch environments (gravity, implicit position motors, limits, a new projected
/// command every step), split over `threads` threads in chunks.
fn run_batch(chain: &ChainGeometry, limits: &Limits, cfg: &BenchConfig) -> Result<BenchReport> {
    let pool = check(cfg)?;
    let model = BatchModel::new(chain, limits, &SceneConfig::default())?;
    let mut envs: Vec<(EnvState, rand_chacha::ChaCha8Rng, Posture)> = (0..cfg.envs)
        .map(|k| {
            Ok((
                model.env_at(&[0.0; N_JOINTS])?,
                rand_chacha::ChaCha8Rng::seed_from_u64(cfg.seed.wrapping_add(k as u64)),
                [0.0; N_JOINTS],
            ))
        })
        .collect::<Result<_>>()?;
    let chunk = cfg.envs.div_ceil(cfg.threads);
    let mut rates = Vec::with_capacity(cfg.repeats);
    for _ in 0..cfg.repeats {
        let t = std::time::Instant::now();
        pool.install(|| {
            envs.par_chunks_mut(chunk).for_each(|part| {
                for _ in 0..cfg.steps {
                    for (env, rng, q) in part.iter_mut() {
                        for v in q.iter_mut() {
                            *v += rng.random_range(-0.005..0.005);
                        }
                        if let Ok(applied) = model.command(env, q) {
                            *q = applied;
                        }
                        model.step(env);
                    }
                }
            })
        });
        rates.push((cfg.envs * cfg.steps) as f64 / t.elapsed().as_secs_f64());
    }
    Ok(report(
        cfg,
        "batch (reduced coordinates, no contact)",
        rates,
    ))
}

/// Steps `envs` rapier scenes (gravity, a plate 20 mm above the TCP at rest, position motors, a new
/// projected command every step) on `threads` threads.
fn run_rapier(chain: &ChainGeometry, limits: &Limits, cfg: &BenchConfig) -> Result<BenchReport> {
    let pool = check(cfg)?;
    let ceiling = chain.tcp(&[0.0; N_JOINTS]).z + 0.02;
    let mut envs: Vec<(Sim, rand_chacha::ChaCha8Rng, Posture)> = (0..cfg.envs)
        .map(|k| {
            let scene = SceneConfig {
                surfaces: vec![Surface::Plane { height_m: ceiling }],
                ..SceneConfig::default()
            };
            Ok((
                Sim::new(chain, limits, scene)?,
                rand_chacha::ChaCha8Rng::seed_from_u64(cfg.seed.wrapping_add(k as u64)),
                [0.0; N_JOINTS],
            ))
        })
        .collect::<Result<_>>()?;
    let mut rates = Vec::with_capacity(cfg.repeats);
    for _ in 0..cfg.repeats {
        let t = std::time::Instant::now();
        pool.install(|| {
            envs.par_iter_mut().for_each(|(sim, rng, q)| {
                for _ in 0..cfg.steps {
                    for v in q.iter_mut() {
                        *v += rng.random_range(-0.005..0.005);
                    }
                    if let Ok(applied) = sim.command(q) {
                        *q = applied;
                    }
                    sim.step();
                }
            })
        });
        rates.push((cfg.envs * cfg.steps) as f64 / t.elapsed().as_secs_f64());
    }
    Ok(report(cfg, "rapier3d-f64 multibody with contact", rates))
}
