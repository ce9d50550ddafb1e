//! Throughput of the articulated simulation: environments stepped in a batch over a fixed
//! number of threads, each with a seeded random walk of commanded postures (clamped onto the
//! limits with the explicit clamping API). The contact scenes put a plate 20 mm above the TCP
//! sensor at rest, within reach of the walk; the report says how many steps touched it.

use crate::batch::{BatchModel, EnvState};
use crate::chain::{ChainGeometry, N_JOINTS, Posture};
use crate::constraints::Limits;
use crate::sim::{SceneConfig, Sim, Surface};
use crate::{Result, SurrogateError};
use nalgebra::Vector3;
use rand::{Rng, SeedableRng};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use std::sync::atomic::{AtomicUsize, Ordering};

/// Which stepper is timed.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Engine {
    /// The reduced-coordinate batch stepper ([`crate::batch`]), free (no surroundings).
    Batch,
    /// The batch stepper with the plate above the TCP (penalty contact of the TCP sensor).
    BatchContact,
    /// The rapier scene ([`crate::sim`]) with the plate above the TCP (every link collides).
    Rapier,
}

impl Engine {
    /// Every engine, in the order the CLI reports them.
    pub const ALL: [Engine; 3] = [Engine::Batch, Engine::BatchContact, Engine::Rapier];

    /// Parses `batch`, `batch-contact` or `rapier`.
    pub fn parse(s: &str) -> Result<Self> {
        match s {
            "batch" => Ok(Engine::Batch),
            "batch-contact" => Ok(Engine::BatchContact),
            "rapier" => Ok(Engine::Rapier),
            e => Err(SurrogateError::Invalid(format!(
                "unknown engine {e:?} (batch, batch-contact or rapier)"
            ))),
        }
    }
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
    /// Fraction of the timed steps whose TCP sensor touched the plate (0 for the free scene).
    #[serde(default)]
    pub contact_fraction: f64,
}

/// Times the configured engine.
pub fn run(chain: &ChainGeometry, limits: &Limits, cfg: &BenchConfig) -> Result<BenchReport> {
    run_with_progress(chain, limits, cfg, |_| {})
}

/// [`run`], calling `on_repeat` with the count of finished repeats (progress bars).
pub fn run_with_progress(
    chain: &ChainGeometry,
    limits: &Limits,
    cfg: &BenchConfig,
    mut on_repeat: impl FnMut(usize),
) -> Result<BenchReport> {
    match cfg.engine {
        Engine::Rapier => run_rapier(chain, limits, cfg, &mut on_repeat),
        Engine::Batch => run_batch(chain, limits, cfg, false, &mut on_repeat),
        Engine::BatchContact => run_batch(chain, limits, cfg, true, &mut on_repeat),
    }
}

/// Most worker threads a bench starts.
const MAX_THREADS: usize = 1024;

fn check(cfg: &BenchConfig) -> Result<rayon::ThreadPool> {
    for (name, v) in [
        ("envs", cfg.envs),
        ("steps", cfg.steps),
        ("threads", cfg.threads),
        ("repeats", cfg.repeats),
    ] {
        if v == 0 {
            return Err(SurrogateError::Invalid(format!(
                "bench {name} = 0: must be positive"
            )));
        }
    }
    if cfg.threads > MAX_THREADS {
        return Err(SurrogateError::Invalid(format!(
            "bench threads = {}: at most {MAX_THREADS} (each is an operating-system thread)",
            cfg.threads
        )));
    }
    rayon::ThreadPoolBuilder::new()
        .num_threads(cfg.threads)
        .build()
        .map_err(|e| SurrogateError::Solver(format!("thread pool: {e}")))
}

/// The plate of the contact scenes: 20 mm above the TCP sensor's top at rest.
fn plate(chain: &ChainGeometry, cfg: &SceneConfig) -> Surface {
    Surface::Plane {
        height_m: chain.tcp(&[0.0; N_JOINTS]).z + cfg.tcp_sensor_radius_m + 0.02,
    }
}

fn report(cfg: &BenchConfig, engine: &str, rates: Vec<f64>, touched: usize) -> BenchReport {
    let mut sorted = rates.clone();
    sorted.sort_by(f64::total_cmp);
    BenchReport {
        config: *cfg,
        engine: engine.into(),
        steps_per_s_median: sorted[sorted.len() / 2],
        steps_per_s: rates,
        contact_fraction: touched as f64 / (cfg.envs * cfg.steps * cfg.repeats) as f64,
    }
}

/// Steps `envs` batch environments (gravity, implicit position motors, limits, a new clamped
/// command every step, the plate when `contact`), split over `threads` threads in chunks.
fn run_batch(
    chain: &ChainGeometry,
    limits: &Limits,
    cfg: &BenchConfig,
    contact: bool,
    on_repeat: &mut dyn FnMut(usize),
) -> Result<BenchReport> {
    let pool = check(cfg)?;
    let mut scene = SceneConfig::default();
    if contact {
        scene.surfaces = vec![plate(chain, &scene)];
    }
    let model = BatchModel::new(chain, limits, &scene)?;
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
    let touched = AtomicUsize::new(0);
    for _ in 0..cfg.repeats {
        let t = std::time::Instant::now();
        pool.install(|| {
            envs.par_chunks_mut(chunk).for_each(|part| {
                let mut hits = 0;
                for _ in 0..cfg.steps {
                    for (env, rng, q) in part.iter_mut() {
                        for v in q.iter_mut() {
                            *v += rng.random_range(-0.005..0.005);
                        }
                        if let Ok(applied) = model.command_clamped(env, q) {
                            *q = applied;
                        }
                        model.step(env);
                        if contact && model.tcp_force(env) != Vector3::zeros() {
                            hits += 1;
                        }
                    }
                }
                touched.fetch_add(hits, Ordering::Relaxed);
            })
        });
        rates.push((cfg.envs * cfg.steps) as f64 / t.elapsed().as_secs_f64());
        on_repeat(rates.len());
    }
    let name = if contact {
        "batch with a plate (reduced coordinates, TCP penalty contact)"
    } else {
        "batch free (reduced coordinates, no surroundings)"
    };
    Ok(report(cfg, name, rates, touched.into_inner()))
}

/// Steps `envs` rapier scenes (gravity, a plate 20 mm above the TCP at rest, position motors, a new
/// projected command every step) on `threads` threads.
fn run_rapier(
    chain: &ChainGeometry,
    limits: &Limits,
    cfg: &BenchConfig,
    on_repeat: &mut dyn FnMut(usize),
) -> Result<BenchReport> {
    let pool = check(cfg)?;
    let surface = plate(chain, &SceneConfig::default());
    let mut envs: Vec<(Sim, rand_chacha::ChaCha8Rng, Posture)> = (0..cfg.envs)
        .map(|k| {
            let scene = SceneConfig {
                surfaces: vec![surface],
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
    let touched = AtomicUsize::new(0);
    for _ in 0..cfg.repeats {
        let t = std::time::Instant::now();
        pool.install(|| {
            envs.par_iter_mut().for_each(|(sim, rng, q)| {
                let mut hits = 0;
                for _ in 0..cfg.steps {
                    for v in q.iter_mut() {
                        *v += rng.random_range(-0.005..0.005);
                    }
                    if let Ok(applied) = sim.command_clamped(q) {
                        *q = applied;
                    }
                    sim.step();
                    if sim.tcp_force() != Vector3::zeros() {
                        hits += 1;
                    }
                }
                touched.fetch_add(hits, Ordering::Relaxed);
            })
        });
        rates.push((cfg.envs * cfg.steps) as f64 / t.elapsed().as_secs_f64());
        on_repeat(rates.len());
    }
    Ok(report(
        cfg,
        "rapier3d-f64 multibody with a plate (rigid contact, every link)",
        rates,
        touched.into_inner(),
    ))
}
