//! `ocm rl`: reinforcement learning on the surrogate: train (behaviour cloning or PPO), evaluate
//! on 100-point episodes with plots of the tracked paths, and benchmark the environments.

use crate::plot::{Chart, Series};
use crate::progress::bar;
use anyhow::Context;
use indicatif::ProgressBar;
use ocm_learn::TrainConfig;
use ocm_rl::bc::{self, BcConfig};
use ocm_rl::bench::{self, BenchConfig};
use ocm_rl::env::{Env, EnvConfig, PHYSICS_DT_S};
use ocm_rl::eval::{EvalReport, evaluate};
use ocm_rl::policy::{Policy, PolicyMeta, policy_config};
use ocm_rl::ppo::{self, PpoConfig, RlRecord};
use ocm_rl::robot::Robot;
use ocm_rl::sac::{self, SacConfig};
use ocm_rl::tasks::TaskKind;
use std::path::{Path, PathBuf};
use std::sync::Arc;

/// The tasks on the command line.
#[derive(clap::ValueEnum, Clone, Copy, Debug)]
pub enum Task {
    /// Task 1: circle of radius 25 mm.
    Circle,
    /// Task 1: star inscribed in the circle.
    Star,
    /// Task 2: the circle under a hanging weight of 50-200 g.
    Weight,
    /// Task 2: press a plate with a target force.
    Force,
    /// Task 3: tilted ellipse (eq 4.28) on a sloped plate with 1 N normal force.
    Ellipse,
}

impl Task {
    fn kind(self) -> TaskKind {
        match self {
            Task::Circle => TaskKind::Circle,
            Task::Star => TaskKind::Star,
            Task::Weight => TaskKind::Weight,
            Task::Force => TaskKind::Force,
            Task::Ellipse => TaskKind::Ellipse,
        }
    }
}

/// Training algorithms.
#[derive(clap::ValueEnum, Clone, Copy, Debug)]
pub enum Algorithm {
    /// Behaviour cloning of the inverse-equilibrium expert.
    Bc,
    /// Proximal policy optimisation.
    Ppo,
    /// Soft actor-critic.
    Sac,
}

/// RL subcommands.
#[derive(clap::Subcommand, Debug)]
pub enum RlCommand {
    /// Trains a policy; writes policy.ckpt (the best), curve.csv/png, eval.json and the plots of
    /// the tracked path against the reference.
    Train {
        /// Surrogate model (from `ocm surrogate map`).
        #[arg(long)]
        model: PathBuf,
        /// Task.
        #[arg(long, value_enum)]
        task: Task,
        /// Algorithm.
        #[arg(long, value_enum, default_value = "bc")]
        algo: Algorithm,
        /// Seed.
        #[arg(long, default_value_t = 0)]
        seed: u64,
        /// BC: expert episodes.
        #[arg(long, default_value_t = 64)]
        episodes: usize,
        /// BC: training epochs (upper bound, early stopping on 10 % held out).
        #[arg(long, default_value_t = 300)]
        epochs: usize,
        /// PPO: iterations.
        #[arg(long, default_value_t = 100)]
        iterations: usize,
        /// SAC: vector steps (each steps every environment once and makes one update).
        #[arg(long, default_value_t = 10_000)]
        steps: usize,
        /// PPO and SAC: parallel environments.
        #[arg(long, default_value_t = 8)]
        envs: usize,
        /// Threads.
        #[arg(long, default_value_t = 2)]
        threads: usize,
        /// Evaluation episodes of 100 points after training.
        #[arg(long, default_value_t = 5)]
        eval_episodes: usize,
        /// Output folder.
        #[arg(long)]
        out: PathBuf,
        /// Print a JSON summary.
        #[arg(long)]
        json: bool,
    },
    /// Evaluates a saved policy (or the expert) on 100-point episodes, with plots.
    Eval {
        /// Surrogate model (from `ocm surrogate map`).
        #[arg(long)]
        model: PathBuf,
        /// Policy checkpoint (policy.ckpt); without it the expert is evaluated.
        #[arg(long)]
        policy: Option<PathBuf>,
        /// Task (default: the policy's).
        #[arg(long, value_enum)]
        task: Option<Task>,
        /// Episodes.
        #[arg(long, default_value_t = 10)]
        episodes: usize,
        /// First episode seed.
        #[arg(long, default_value_t = 2_000_000)]
        seed: u64,
        /// Folder for eval.json and the plots.
        #[arg(long)]
        out: Option<PathBuf>,
        /// Print JSON.
        #[arg(long)]
        json: bool,
    },
    /// Environment steps per second (single and vectorised) and policy inference rate, medians.
    Bench {
        /// Surrogate model (from `ocm surrogate map`).
        #[arg(long)]
        model: PathBuf,
        /// Task.
        #[arg(long, value_enum, default_value = "circle")]
        task: Task,
        /// Policy to time (default: an untrained network of the default shape).
        #[arg(long)]
        policy: Option<PathBuf>,
        /// Environments of the vector run.
        #[arg(long, default_value_t = 16)]
        envs: usize,
        /// Threads of the vector run.
        #[arg(long, default_value_t = 2)]
        threads: usize,
        /// Control steps per environment and repeat.
        #[arg(long, default_value_t = 200)]
        steps: usize,
        /// Repeats.
        #[arg(long, default_value_t = 5)]
        repeats: usize,
        /// Print JSON.
        #[arg(long)]
        json: bool,
    },
}

fn robot(model: &Path) -> anyhow::Result<Arc<Robot>> {
    Ok(Arc::new(
        Robot::read(model, PHYSICS_DT_S).with_context(|| format!("reading {}", model.display()))?,
    ))
}

fn mkdir(out: &Path) -> anyhow::Result<()> {
    std::fs::create_dir_all(out).with_context(|| format!("creating {}", out.display()))
}

/// Plots of the first evaluation episode: tracked TCP against the reference in x-y and x-z (mm),
/// and the force against its target over the steps for force tasks.
fn plot_episode(out: &Path, task: TaskKind, label: &str, r: &EvalReport) -> anyhow::Result<()> {
    let ep = &r.first_episode;
    let pick = |f: &dyn Fn(&ocm_rl::env::StepInfo) -> (f64, f64)| -> Vec<(f64, f64)> {
        ep.iter().map(f).collect()
    };
    for (stem, ax, ay, (i, j)) in [
        ("track_xy", "x (mm)", "y (mm)", (0, 1)),
        ("track_xz", "x (mm)", "z (mm)", (0, 2)),
    ] {
        Chart {
            title: &format!("{} - {label}: TCP against the reference", task.name()),
            x_label: ax,
            y_label: ay,
            series: vec![
                Series {
                    label: "reference X_ref".into(),
                    points: pick(&|s| (s.target_m[i] * 1e3, s.target_m[j] * 1e3)),
                    dots: true,
                },
                Series {
                    label: format!("surrogate X_P ({label})"),
                    points: pick(&|s| (s.tcp_m[i] * 1e3, s.tcp_m[j] * 1e3)),
                    dots: false,
                },
            ],
            equal_axes: true,
        }
        .write(out, stem)?;
    }
    if task.has_force() {
        let mut series = vec![];
        for (k, name) in ["x", "y", "z"].iter().enumerate() {
            series.push(Series {
                label: format!("F_{name} target"),
                points: ep
                    .iter()
                    .map(|s| (s.point as f64, s.force_target_n[k]))
                    .collect(),
                dots: true,
            });
            series.push(Series {
                label: format!("F_{name}"),
                points: ep.iter().map(|s| (s.point as f64, s.force_n[k])).collect(),
                dots: false,
            });
        }
        Chart {
            title: &format!("{} - {label}: TCP force against its target", task.name()),
            x_label: "step",
            y_label: "force on the TCP (N)",
            series,
            equal_axes: false,
        }
        .write(out, "force")?;
    }
    Ok(())
}

fn write_json(path: &Path, v: &serde_json::Value) -> anyhow::Result<()> {
    std::fs::write(path, serde_json::to_string_pretty(v)?)
        .with_context(|| format!("writing {}", path.display()))
}

fn summary(r: &EvalReport) -> serde_json::Value {
    serde_json::json!({
        "episodes": r.episodes,
        "steps": r.steps,
        "position_error_mm": r.position_error_mm,
        "force_error_n": r.force_error_n,
        "episode_return": r.episode_return,
        "failures": r.failures,
    })
}

fn print_eval(task: TaskKind, who: &str, r: &EvalReport) {
    println!(
        "{} ({who}): position error {:.3} +- {:.3} mm, force error {:.3} +- {:.3} N, return {:.2}, \
         {} steps, {} lost",
        task.name(),
        r.position_error_mm.mean,
        r.position_error_mm.std,
        r.force_error_n.mean,
        r.force_error_n.std,
        r.episode_return.mean,
        r.steps,
        r.failures
    );
}

fn curve_chart(out: &Path, task: TaskKind, algo: &str, curve: &[RlRecord]) -> anyhow::Result<()> {
    let pts: Vec<(f64, f64)> = curve
        .iter()
        .filter(|r| r.eval_return.is_finite())
        .map(|r| (r.env_steps as f64, r.eval_return / 100.0))
        .collect();
    let roll: Vec<(f64, f64)> = curve
        .iter()
        .filter(|r| r.mean_reward.is_finite())
        .map(|r| (r.env_steps as f64, r.mean_reward))
        .collect();
    let mut series = vec![Series {
        label: "evaluation: mean reward per step (deterministic policy)".into(),
        points: pts,
        dots: false,
    }];
    if !roll.is_empty() {
        series.push(Series {
            label: "rollout: mean reward per step".into(),
            points: roll,
            dots: false,
        });
    }
    Chart {
        title: &format!("{} - {algo}: training curve", task.name()),
        x_label: "environment steps",
        y_label: "normalised reward (eq 4.29)",
        series,
        equal_axes: false,
    }
    .write(out, "curve")
}

/// Runs an `ocm rl` subcommand.
pub fn run(cmd: RlCommand) -> anyhow::Result<()> {
    match cmd {
        RlCommand::Train {
            model,
            task,
            algo,
            seed,
            episodes,
            epochs,
            iterations,
            steps,
            envs,
            threads,
            eval_episodes,
            out,
            json,
        } => {
            let robot = robot(&model)?;
            let kind = task.kind();
            let cfg = EnvConfig::new(kind);
            mkdir(&out)?;
            let t0 = std::time::Instant::now();
            let (policy, name) = match algo {
                Algorithm::Bc => {
                    let bc_cfg = BcConfig {
                        episodes,
                        seed,
                        threads,
                        train: TrainConfig {
                            epochs,
                            progress: !json,
                            ..BcConfig::default().train
                        },
                        ..BcConfig::default()
                    };
                    if !json {
                        eprintln!("collecting {episodes} expert episodes ...");
                    }
                    let (policy, curve) = bc::train(&robot, &cfg, &bc_cfg)?;
                    ocm_learn::write_curve(
                        &out,
                        "curve",
                        &format!("{} - BC loss", kind.name()),
                        &curve,
                    )?;
                    (policy, "bc")
                }
                Algorithm::Ppo => {
                    let p_cfg = PpoConfig {
                        iterations,
                        envs,
                        seed,
                        threads,
                        ..PpoConfig::default()
                    };
                    let b = if json {
                        ProgressBar::hidden()
                    } else {
                        bar(iterations, "PPO")
                    };
                    let (policy, curve) = ppo::train(&robot, &cfg, &p_cfg, |r| {
                        b.inc(1);
                        if r.eval_return.is_finite() {
                            b.set_message(format!(
                                "PPO eval {:.2} mm / {:.2} N",
                                r.eval_position_error_mm, r.eval_force_error_n
                            ));
                        }
                    })?;
                    b.finish_and_clear();
                    ppo::write_curve_csv(&out.join("curve.csv"), &curve)?;
                    curve_chart(&out, kind, "PPO", &curve)?;
                    (policy, "ppo")
                }
                Algorithm::Sac => {
                    let s_cfg = SacConfig {
                        steps,
                        envs,
                        seed,
                        threads,
                        ..SacConfig::default()
                    };
                    let b = if json {
                        ProgressBar::hidden()
                    } else {
                        bar(steps, "SAC")
                    };
                    let (policy, curve) = sac::train(&robot, &cfg, &s_cfg, |r| {
                        b.set_position(r.iteration as u64);
                        b.set_message(format!(
                            "SAC eval {:.2} mm / {:.2} N",
                            r.eval_position_error_mm, r.eval_force_error_n
                        ));
                    })?;
                    b.finish_and_clear();
                    ppo::write_curve_csv(&out.join("curve.csv"), &curve)?;
                    curve_chart(&out, kind, "SAC", &curve)?;
                    (policy, "sac")
                }
            };
            let train_s = t0.elapsed().as_secs_f64();
            let mut env = Env::new(robot.clone(), cfg)?;
            let report = evaluate(&mut env, eval_episodes, 2_000_000, |_, o| policy.act(o))?;
            let meta = PolicyMeta {
                task: kind.name().into(),
                algorithm: name.into(),
                seed,
                score: report.episode_return.mean,
            };
            policy.save(&out.join("policy.ckpt"), &meta)?;
            plot_episode(&out, kind, name, &report)?;
            let v = serde_json::json!({
                "task": kind.name(),
                "algorithm": name,
                "seed": seed,
                "train_seconds": train_s,
                "eval": summary(&report),
                "policy": out.join("policy.ckpt"),
            });
            write_json(&out.join("eval.json"), &v)?;
            if json {
                println!("{}", serde_json::to_string_pretty(&v)?);
            } else {
                print_eval(kind, name, &report);
                println!("trained in {train_s:.0} s; wrote {}", out.display());
            }
        }
        RlCommand::Eval {
            model,
            policy,
            task,
            episodes,
            seed,
            out,
            json,
        } => {
            let robot = robot(&model)?;
            let loaded = match &policy {
                Some(p) => {
                    Some(Policy::load(p).with_context(|| format!("reading {}", p.display()))?)
                }
                None => None,
            };
            let kind = match (task, &loaded) {
                (Some(t), _) => t.kind(),
                (None, Some((_, m))) => TaskKind::from_name(&m.task)
                    .with_context(|| format!("policy names an unknown task '{}'", m.task))?,
                (None, None) => anyhow::bail!("give --task or --policy"),
            };
            let mut env = Env::new(robot.clone(), EnvConfig::new(kind))?;
            let (report, who) = match &loaded {
                Some((p, m)) => (
                    evaluate(&mut env, episodes, seed, |_, o| p.act(o))?,
                    m.algorithm.clone(),
                ),
                None => (
                    evaluate(&mut env, episodes, seed, |e, _| e.expert_action())?,
                    "expert".to_string(),
                ),
            };
            if let Some(out) = &out {
                mkdir(out)?;
                plot_episode(out, kind, &who, &report)?;
                write_json(&out.join("eval.json"), &summary(&report))?;
            }
            if json {
                println!("{}", serde_json::to_string_pretty(&summary(&report))?);
            } else {
                print_eval(kind, &who, &report);
            }
        }
        RlCommand::Bench {
            model,
            task,
            policy,
            envs,
            threads,
            steps,
            repeats,
            json,
        } => {
            let robot = robot(&model)?;
            let cfg = EnvConfig::new(task.kind());
            let p = match &policy {
                Some(path) => Policy::load(path)?.0,
                None => {
                    let c = policy_config(&BcConfig::default().hidden);
                    Policy::new(c.init(&ocm_learn::cpu(), 0), c)
                }
            };
            let r = bench::run(
                &robot,
                &cfg,
                &p,
                &BenchConfig {
                    envs,
                    threads,
                    steps,
                    repeats,
                    inferences: 2000,
                },
            )?;
            if json {
                println!("{}", serde_json::to_string_pretty(&r)?);
            } else {
                println!(
                    "{}: {:.0} control steps/s single, {:.0} vectorised ({envs} envs, {threads} \
                     threads), {} physics steps each; policy {:.0} Hz (medians of {repeats})",
                    task.kind().name(),
                    r.single_steps_per_s,
                    r.vector_steps_per_s,
                    r.substeps,
                    r.policy_hz
                );
            }
        }
    }
    Ok(())
}
