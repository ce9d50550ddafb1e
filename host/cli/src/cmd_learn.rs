//! `ocm learn`: train and evaluate the learned dynamics of the bellows manipulator (forward
//! Transformer-PINN, inverse MLP with cycle loss).

use std::path::Path;

use anyhow::{Context, Result, bail};
use ocm_dynamics::eval::{
    ForwardMetrics, InverseMetrics, evaluate_forward, evaluate_inverse, predict_forward,
};
use ocm_dynamics::lumped::demo_system;
use ocm_dynamics::synth::lumped_trajectories;
use ocm_dynamics::{
    ForwardConfig, InverseConfig, Samples, TrainedForward, TrainedInverse, Trajectory,
    continue_forward, train_forward, train_inverse,
};
use ocm_learn::{LrSchedule, TrainConfig, cpu, write_curve};

use crate::cmd_learn_args::{BenchArgs, DataArgs, EvalArgs, ModelKind, TrainArgs};
use crate::plot::{Chart, Series};

/// `ocm learn` subcommands.
#[derive(clap::Subcommand, Debug)]
pub enum LearnCommand {
    /// Train a model on the training sequences of a data set.
    Train(TrainArgs),
    /// Score trained models on the held-out sequences of a data set.
    Eval(EvalArgs),
    /// Time the forward model: one step at batch 1, and batched throughput.
    Bench(BenchArgs),
}

/// Runs `ocm learn`.
pub fn run(cmd: LearnCommand) -> Result<()> {
    match cmd {
        LearnCommand::Train(a) => run_train(a),
        LearnCommand::Eval(a) => run_eval(a),
        LearnCommand::Bench(a) => run_bench(a),
    }
}

/// Training and held-out trajectories.
fn load(args: &DataArgs) -> Result<(Vec<Trajectory>, Vec<Trajectory>)> {
    let all = match (&args.data, args.demo) {
        (Some(dir), _) if args.drop_nonfinite => {
            let (_, trajs, dropped) = ocm_dynamics::dataset::read_finite_trajectories(dir)
                .with_context(|| format!("reading data set {}", dir.display()))?;
            if !dropped.is_empty() {
                eprintln!(
                    "left out {} sequence(s) with non-finite values: {dropped:?}",
                    dropped.len()
                );
            }
            trajs
        }
        (Some(dir), _) => {
            ocm_dynamics::dataset::read_trajectories(dir)
                .with_context(|| format!("reading data set {}", dir.display()))?
                .1
        }
        (None, true) => {
            let sys = demo_system(8, 1)?;
            lumped_trajectories(&sys, args.demo_sequences, args.demo_steps, 0.01, 1)
        }
        (None, false) => bail!("give --data DIR (an `ocm mor` data set) or --demo"),
    };
    if !((0.0..1.0).contains(&args.test_fraction) && 0.0 < args.fraction && args.fraction <= 1.0) {
        bail!(
            "--test-fraction must be in [0, 1) and --fraction in (0, 1], got {} and {}",
            args.test_fraction,
            args.fraction
        );
    }
    let n_test = ((all.len() as f64) * args.test_fraction).round() as usize;
    if all.len() < 2 || n_test == 0 || n_test >= all.len() {
        bail!(
            "{} sequences cannot be split into training and held-out sets with --test-fraction {}",
            all.len(),
            args.test_fraction
        );
    }
    let mut train = all;
    let test = train.split_off(train.len() - n_test);
    let keep = ((train.len() as f64) * args.fraction).ceil().max(1.0) as usize;
    train.truncate(keep);
    Ok((train, test))
}

fn horizon_steps(horizon_s: f64, dt_s: f64) -> usize {
    (horizon_s / dt_s).round().max(1.0) as usize
}

fn run_train(a: TrainArgs) -> Result<()> {
    if a.kind == ModelKind::Map {
        return crate::cmd_learn_map::train(&a);
    }
    let (train, test) = load(&a.data)?;
    let n = train[0].state_dim;
    std::fs::create_dir_all(&a.out).with_context(|| format!("creating {}", a.out.display()))?;
    let (epochs, lr) = match a.kind {
        ModelKind::Forward => (a.epochs.unwrap_or(300), a.lr.unwrap_or(5e-4)),
        ModelKind::Inverse | ModelKind::Map => (a.epochs.unwrap_or(200), a.lr.unwrap_or(1e-3)),
    };
    let cfg = TrainConfig {
        epochs,
        batch_size: a.batch_size.unwrap_or(64),
        learning_rate: lr,
        val_fraction: 0.1,
        patience: a.patience.unwrap_or(30),
        grad_clip_norm: Some(1.0),
        seed: a.seed,
        progress: !a.json,
        lr_schedule: LrSchedule::cosine_to(a.lr_final),
    };
    let start = std::time::Instant::now();
    let summary = match a.kind {
        ModelKind::Forward => {
            let mut config = ForwardConfig::dissertation(n);
            if a.small {
                config.d_model = 64;
                config.n_layers = 1;
                config.d_ff = 128;
            }
            let (model, curve) = match &a.init_from {
                Some(init) => continue_forward(&train, init, &cfg, a.lambda)?,
                None => train_forward(&train, &config, &cfg, a.lambda, a.seed)?,
            };
            let config = model.config.clone();
            let path = a.out.join("forward.ckpt");
            model.save(&path)?;
            write_curve(&a.out, "loss", "forward model", &curve)?;
            let dt = train[0].dt_s;
            let m = evaluate_forward(
                &model.model,
                &model.scalers,
                config.window,
                &test,
                horizon_steps(1.0, dt),
                &cpu(),
            )?;
            serde_json::json!({
                "model": "forward", "checkpoint": path, "train_sequences": train.len(),
                "test_sequences": test.len(), "train_seconds": start.elapsed().as_secs_f64(),
                "epochs_run": curve.len(), "best_epoch": model.meta.best_epoch,
                "lambda": a.lambda, "held_out": m,
            })
        }
        ModelKind::Map => bail!("the mapping networks do not train on trajectories"),
        ModelKind::Inverse => {
            let fpath = a
                .forward
                .as_deref()
                .context("--forward CKPT is required for the inverse model")?;
            let fwd = TrainedForward::load(fpath)
                .with_context(|| format!("loading {}", fpath.display()))?;
            let (model, curve) = train_inverse(
                &train,
                &fwd,
                &InverseConfig {
                    current_velocity: !a.no_current_velocity,
                    ..InverseConfig::dissertation(n)
                },
                &cfg,
                a.beta,
                a.seed,
            )?;
            let path = a.out.join("inverse.ckpt");
            model.save(&path)?;
            write_curve(&a.out, "loss", "inverse model", &curve)?;
            let m = evaluate_inverse(&model.model, &model.config, &model.scalers, &test, &cpu())?;
            serde_json::json!({
                "model": "inverse", "checkpoint": path, "forward": fpath,
                "train_sequences": train.len(), "test_sequences": test.len(),
                "train_seconds": start.elapsed().as_secs_f64(), "epochs_run": curve.len(),
                "best_epoch": model.meta.best_epoch, "beta": a.beta, "held_out": m,
            })
        }
    };
    std::fs::write(
        a.out.join("summary.json"),
        serde_json::to_string_pretty(&summary)?,
    )?;
    if a.json {
        println!("{}", serde_json::to_string_pretty(&summary)?);
    } else {
        println!("{}", text_summary(&summary));
    }
    Ok(())
}

fn text_summary(s: &serde_json::Value) -> String {
    let h = &s["held_out"];
    match s["model"].as_str() {
        Some("forward") => format!(
            "forward model: {} epochs in {:.0} s; held out: velocity {:.2} mm/s, position {:.3} mm, 1 s rollout {:.2} mm",
            s["epochs_run"],
            s["train_seconds"].as_f64().unwrap_or(f64::NAN),
            h["velocity_error_mm_s"].as_f64().unwrap_or(f64::NAN),
            h["position_error_mm"].as_f64().unwrap_or(f64::NAN),
            h["rollout_mean_error_mm"].as_f64().unwrap_or(f64::NAN),
        ),
        _ => format!(
            "inverse model: {} epochs in {:.0} s; held out: pressure MAE {:.3} kPa, RMSE {:.3} kPa",
            s["epochs_run"],
            s["train_seconds"].as_f64().unwrap_or(f64::NAN),
            h["pressure_mae_kpa"].as_f64().unwrap_or(f64::NAN),
            h["pressure_rmse_kpa"].as_f64().unwrap_or(f64::NAN),
        ),
    }
}

#[derive(serde::Serialize)]
struct EvalSummary {
    forward: ForwardMetrics,
    inverse: Option<InverseMetrics>,
    test_sequences: usize,
}

fn run_eval(a: EvalArgs) -> Result<()> {
    if let Some(dir) = &a.map {
        return crate::cmd_learn_map::eval(dir, &a);
    }
    let fpath = a
        .forward
        .as_deref()
        .context("--forward CKPT or --map DIR is required")?;
    let (_, test) = load(&a.data)?;
    let fwd =
        TrainedForward::load(fpath).with_context(|| format!("loading {}", fpath.display()))?;
    let dt = test[0].dt_s;
    let forward = evaluate_forward(
        &fwd.model,
        &fwd.scalers,
        fwd.config.window,
        &test,
        horizon_steps(a.horizon_s, dt),
        &cpu(),
    )?;
    let inverse = match &a.inverse {
        Some(p) => {
            let inv =
                TrainedInverse::load(p).with_context(|| format!("loading {}", p.display()))?;
            Some(evaluate_inverse(
                &inv.model,
                &inv.config,
                &inv.scalers,
                &test,
                &cpu(),
            )?)
        }
        None => None,
    };
    if let Some(out) = &a.out {
        plot_prediction(out, &fwd, &test[0])?;
    }
    let s = EvalSummary {
        forward,
        inverse,
        test_sequences: test.len(),
    };
    if a.json {
        println!("{}", serde_json::to_string_pretty(&s)?);
    } else {
        println!(
            "forward: velocity {:.2} mm/s, position {:.3} mm, rollout ({:.1} s) mean {:.2} mm, final {:.2} mm over {} sequences",
            s.forward.velocity_error_mm_s,
            s.forward.position_error_mm,
            s.forward.rollout_horizon_s,
            s.forward.rollout_mean_error_mm,
            s.forward.rollout_final_error_mm,
            s.test_sequences
        );
        if let Some(i) = &s.inverse {
            println!(
                "inverse: pressure MAE {:.3} kPa, RMSE {:.3} kPa",
                i.pressure_mae_kpa, i.pressure_rmse_kpa
            );
        }
    }
    Ok(())
}

/// Predicted against true TCP velocity over time on one held-out sequence (as Fig 4.21-B).
fn plot_prediction(out: &Path, fwd: &TrainedForward, traj: &Trajectory) -> Result<()> {
    if traj.state_dim < 3 {
        bail!(
            "X_S has {} components; the plot needs the three of the TCP position",
            traj.state_dim
        );
    }
    std::fs::create_dir_all(out).with_context(|| format!("creating {}", out.display()))?;
    let data = Samples::build(
        std::slice::from_ref(traj),
        fwd.config.window,
        &fwd.scalers,
        None,
    )?;
    let pred = predict_forward(&fwd.model, &fwd.scalers, &data, &cpu())?;
    let n = traj.state_dim;
    let mut csv = String::from(
        "time_s,vx_true_mm_s,vy_true_mm_s,vz_true_mm_s,vx_pred_mm_s,vy_pred_mm_s,vz_pred_mm_s\n",
    );
    let mut series = Vec::new();
    for (axis, name) in ["x", "y", "z"].iter().enumerate().take(n.min(3)) {
        let truth: Vec<(f64, f64)> = data
            .origin
            .iter()
            .map(|&(_, k)| ((k + 1) as f64 * traj.dt_s, 1e3 * traj.v(k + 1)[axis]))
            .collect();
        let p: Vec<(f64, f64)> = data
            .origin
            .iter()
            .enumerate()
            .map(|(s, &(_, k))| ((k + 1) as f64 * traj.dt_s, 1e3 * pred[s * n + axis]))
            .collect();
        series.push(Series {
            label: format!("v{name} true"),
            points: truth,
            dots: false,
        });
        series.push(Series {
            label: format!("v{name} predicted"),
            points: p,
            dots: true,
        });
    }
    for (s, &(_, k)) in data.origin.iter().enumerate() {
        let v = traj.v(k + 1);
        csv.push_str(&format!(
            "{:.4},{:.5},{:.5},{:.5},{:.5},{:.5},{:.5}\n",
            (k + 1) as f64 * traj.dt_s,
            1e3 * v[0],
            1e3 * v[1],
            1e3 * v[2],
            1e3 * pred[s * n],
            1e3 * pred[s * n + 1],
            1e3 * pred[s * n + 2]
        ));
    }
    let csv_path = out.join("prediction.csv");
    std::fs::write(&csv_path, csv).with_context(|| format!("writing {}", csv_path.display()))?;
    Chart {
        title: "TCP velocity: forward model against truth (held-out sequence)",
        x_label: "time (s)",
        y_label: "velocity (mm/s)",
        series,
        equal_axes: false,
    }
    .write(out, "prediction")
}

/// Largest batch `ocm learn bench` times: a batch is `batch x window x step` floats, and a
/// million windows of the default model is already about 1 GB.
const MAX_BENCH_BATCH: usize = 1 << 20;

fn run_bench(a: BenchArgs) -> Result<()> {
    use ocm_learn::burn::tensor::{Tensor, TensorData};
    use std::time::Instant;
    // an empty batch reaches the matrix kernels with zero-sized operands (a crash, not an
    // error), and a huge one exhausts the memory
    if !(1..=MAX_BENCH_BATCH).contains(&a.batch) {
        bail!(
            "--batch must be between 1 and {MAX_BENCH_BATCH}, got {}",
            a.batch
        );
    }
    let fwd = TrainedForward::load(&a.forward)
        .with_context(|| format!("loading {}", a.forward.display()))?;
    let (m, f) = (fwd.config.window, fwd.config.step_dim());
    let device = cpu();
    // The same windows for both paths.
    let raw =
        |b: usize| -> Vec<f32> { (0..b * m * f).map(|i| ((i as f32) * 0.37).sin()).collect() };
    let input = |b: usize| Tensor::<3>::from_data(TensorData::new(raw(b), [b, m, f]), &device);
    let run = |b: usize, reps: usize| -> Vec<f64> {
        (0..reps)
            .map(|_| {
                let x = input(b);
                let t = Instant::now();
                let y = ocm_learn::values(fwd.model.forward(x));
                std::hint::black_box(y);
                t.elapsed().as_secs_f64()
            })
            .collect()
    };
    let dense = fwd.model.dense()?;
    let run_dense = |b: usize, reps: usize| -> Result<Vec<f64>> {
        let x = raw(b);
        (0..reps)
            .map(|_| {
                let t = Instant::now();
                let y = dense.forward(&x, b, m)?;
                std::hint::black_box(y);
                Ok(t.elapsed().as_secs_f64())
            })
            .collect()
    };
    let median = |mut v: Vec<f64>| {
        v.sort_by(f64::total_cmp);
        v[v.len() / 2]
    };
    run(1, 20);
    let single_s = median(run(1, 300));
    run(a.batch, 2);
    let batched_s = median(run(a.batch, 15));
    run_dense(1, 20)?;
    let dense_single_s = median(run_dense(1, 300)?);
    run_dense(a.batch, 2)?;
    let dense_batched_s = median(run_dense(a.batch, 15)?);
    let s = serde_json::json!({
        "batch1_step_ms": 1e3 * dense_single_s,
        "batch": a.batch,
        "batched_steps_per_s": a.batch as f64 / dense_batched_s,
        "burn_batch1_step_ms": 1e3 * single_s,
        "burn_batched_steps_per_s": a.batch as f64 / batched_s,
        "threads": std::thread::available_parallelism().map(|n| n.get()).unwrap_or(1),
    });
    if a.json {
        println!("{}", serde_json::to_string_pretty(&s)?);
    } else {
        println!(
            "forward model, plain arrays: {:.3} ms per step at batch 1, {:.0} steps/s at batch {}",
            1e3 * dense_single_s,
            a.batch as f64 / dense_batched_s,
            a.batch
        );
        println!(
            "forward model, burn tensors: {:.3} ms per step at batch 1, {:.0} steps/s at batch {}",
            1e3 * single_s,
            a.batch as f64 / batched_s,
            a.batch
        );
    }
    Ok(())
}
