//! The lumped residual, the forward and inverse models and their checkpoints, on trajectories
//! of a known lumped system.

use ocm_dynamics::eval::{evaluate_forward, evaluate_inverse, predict_forward};
use ocm_dynamics::forward::physics_loss;
use ocm_dynamics::inverse::CycleTarget;
use ocm_dynamics::lumped::demo_system;
use ocm_dynamics::samples::scaled_slope_t;
use ocm_dynamics::synth::lumped_trajectories;
use ocm_dynamics::{
    ForwardConfig, InverseConfig, LumpedModel, Samples, Scalers, TrainedForward, TrainedInverse,
    Trajectory, continue_forward, train_forward, train_inverse,
};
use ocm_learn::burn::tensor::{Tensor, TensorData};
use ocm_learn::{LrSchedule, TrainConfig, cpu, cpu_autodiff, tensor2, values};

fn rel_rms(model: &LumpedModel, trajs: &[Trajectory]) -> f64 {
    let (r, a) = model.residual_rms(trajs);
    r.iter().zip(&a).map(|(r, a)| r / a).fold(0.0, f64::max)
}

#[test]
fn residual_vanishes_on_exact_trajectories_to_second_order() {
    let sys = demo_system(3, 1).unwrap();
    let coarse = lumped_trajectories(&sys, 3, 400, 0.01, 5);
    let fine = lumped_trajectories(&sys, 3, 800, 0.005, 5);
    let (rc, rf) = (rel_rms(&sys, &coarse), rel_rms(&sys, &fine));
    assert!(rc < 0.05, "residual / acceleration at dt 10 ms: {rc:.4}");
    let order = (rc / rf).log2();
    assert!(
        (1.6..2.4).contains(&order),
        "convergence order {order:.2} ({rc:.2e} -> {rf:.2e})"
    );
    // Not a placeholder: a trajectory that is not a solution (pressures of another run) has a
    // residual of the order of the acceleration itself.
    let mut wrong = coarse[0].clone();
    wrong.pressure_kpa = coarse[1].pressure_kpa.clone();
    let rw = rel_rms(&sys, &[wrong]);
    assert!(
        rw > 10.0 * rc,
        "residual with the wrong inputs {rw:.3} vs {rc:.4}"
    );
}

#[test]
fn identification_recovers_the_lumped_system() {
    let sys = demo_system(4, 2).unwrap();
    let trajs = lumped_trajectories(&sys, 4, 500, 0.01, 9);
    let id = LumpedModel::identify(&trajs).unwrap();
    let rel = |a: &[f64], b: &[f64]| {
        let d: f64 = a.iter().zip(b).map(|(a, b)| (a - b) * (a - b)).sum();
        let n: f64 = b.iter().map(|b| b * b).sum();
        (d / n).sqrt()
    };
    assert!(
        rel(&id.a_x, &sys.a_x) < 0.05,
        "A_x off by {:.3}",
        rel(&id.a_x, &sys.a_x)
    );
    assert!(
        rel(&id.a_v, &sys.a_v) < 0.15,
        "A_v off by {:.3}",
        rel(&id.a_v, &sys.a_v)
    );
    assert!(
        rel(&id.a_p, &sys.a_p) < 0.05,
        "A_p off by {:.3}",
        rel(&id.a_p, &sys.a_p)
    );
    assert!(
        rel(&id.a_f, &sys.a_f) < 0.05,
        "A_f off by {:.3}",
        rel(&id.a_f, &sys.a_f)
    );
    // Least squares on the residual itself: no model does better on the data.
    let (ri, _) = id.residual_rms(&trajs);
    let (rt, _) = sys.residual_rms(&trajs);
    for (a, b) in ri.iter().zip(&rt) {
        assert!(*a <= b * (1.0 + 1e-9), "identified {a} vs true {b}");
    }
}

#[test]
fn scaled_physics_loss_matches_the_residual_and_its_gradient() {
    let sys = demo_system(3, 3).unwrap();
    let trajs = lumped_trajectories(&sys, 2, 120, 0.01, 4);
    let scalers = Scalers::fit(&trajs).unwrap();
    let data = Samples::build(&trajs, 5, &scalers, Some(&sys)).unwrap();
    let wt = scaled_slope_t(&sys, &scalers, 0.01);
    let batch: Vec<usize> = (0..data.len()).step_by(7).collect();
    let n = 3;
    // Scaled true velocities: the loss must be the f64 residual, scaled, squared and averaged.
    let pred = Samples::rows(&data.target, n, &batch);
    let loss = values(physics_loss(
        tensor2(pred.clone(), batch.len(), n, &cpu()),
        &data,
        &wt,
        &batch,
        &cpu(),
    ))[0];
    let mut direct = 0.0;
    for &s in &batch {
        let (ti, k) = data.origin[s];
        let t = &trajs[ti];
        let r = sys.residual(0.01, t.x(k), t.v(k), t.p(k), t.f(k), t.v(k + 1));
        direct += r
            .iter()
            .zip(&scalers.accel)
            .map(|(r, a)| (r / a).powi(2))
            .sum::<f64>();
    }
    direct /= (batch.len() * n) as f64;
    assert!(
        (f64::from(loss) - direct).abs() < 1e-3 * direct.max(1e-6),
        "tensor {loss} vs direct {direct}"
    );
    // Gradient with respect to the prediction against central differences, at a point off the
    // solution (where the gradient is not zero).
    let off: Vec<f32> = pred
        .iter()
        .enumerate()
        .map(|(i, v)| v + 0.3 * ((i as f32) * 1.3).sin())
        .collect();
    let ad_dev = cpu_autodiff();
    let p = tensor2(off.clone(), batch.len(), n, &ad_dev).require_grad();
    let l = physics_loss(p.clone(), &data, &wt, &batch, &ad_dev);
    let g = values(p.grad(&l.backward()).unwrap());
    for k in [0, 4, off.len() / 2, off.len() - 1] {
        let h = 1e-2f32;
        let eval = |d: f32| {
            let mut v = off.clone();
            v[k] += d;
            f64::from(
                values(physics_loss(
                    tensor2(v, batch.len(), n, &cpu()),
                    &data,
                    &wt,
                    &batch,
                    &cpu(),
                ))[0],
            )
        };
        let fd = (eval(h) - eval(-h)) / (2.0 * f64::from(h));
        let ad = f64::from(g[k]);
        assert!(
            (fd - ad).abs() < 1e-4 + 2e-2 * ad.abs(),
            "entry {k}: autodiff {ad} vs finite difference {fd}"
        );
    }
}

fn small_forward(n: usize) -> ForwardConfig {
    ForwardConfig {
        d_model: 32,
        n_heads: 4,
        d_ff: 64,
        n_layers: 1,
        head_hidden: vec![64, 64],
        ..ForwardConfig::dissertation(n)
    }
}

fn quick(epochs: usize, seed: u64) -> TrainConfig {
    TrainConfig {
        epochs,
        batch_size: 64,
        learning_rate: 2e-3,
        val_fraction: 0.2,
        patience: 0,
        grad_clip_norm: Some(1.0),
        seed,
        progress: false,
        lr_schedule: LrSchedule::Constant,
    }
}

#[test]
fn forward_and_inverse_learn_the_lumped_system_and_survive_checkpoints() {
    let sys = demo_system(3, 4).unwrap();
    let trajs = lumped_trajectories(&sys, 6, 300, 0.01, 10);
    let (train_set, test_set) = trajs.split_at(5);
    let (fwd, curve) = train_forward(train_set, &small_forward(3), &quick(12, 1), 0.15, 7).unwrap();
    assert!(
        curve.last().unwrap().train_loss < 0.1 * curve[0].train_loss.max(0.1),
        "{curve:?}"
    );
    let metrics = evaluate_forward(&fwd.model, &fwd.scalers, 10, test_set, 50, &cpu()).unwrap();
    // Baseline: predict zero velocity. The model must do far better on held-out motion.
    let data = Samples::build(test_set, 10, &fwd.scalers, None).unwrap();
    let mut zero = 0.0;
    for &(ti, k) in &data.origin {
        let v = test_set[ti].v(k + 1);
        zero += (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
    }
    let zero_mm_s = 1e3 * zero / data.len() as f64;
    assert!(
        metrics.velocity_error_mm_s < 0.3 * zero_mm_s,
        "velocity error {:.2} mm/s vs zero-velocity baseline {zero_mm_s:.2}",
        metrics.velocity_error_mm_s
    );
    assert!(metrics.rollout_mean_error_mm.is_finite() && metrics.rollouts > 0);

    let dir = std::env::temp_dir().join(format!("ocm-dyn-{}", std::process::id()));
    let fpath = dir.join("forward.ckpt");
    fwd.save(&fpath).unwrap();
    let back = TrainedForward::load(&fpath).unwrap();
    let a = predict_forward(&fwd.model, &fwd.scalers, &data, &cpu()).unwrap();
    let b = predict_forward(&back.model, &back.scalers, &data, &cpu()).unwrap();
    let diff = a
        .iter()
        .zip(&b)
        .map(|(a, b)| (a - b).abs())
        .fold(0.0, f64::max);
    let scale = a.iter().map(|a| a.abs()).fold(0.0, f64::max);
    assert!(
        diff <= 1e-6 * scale,
        "a reloaded forward model predicts as before: max difference {diff:e} of {scale:e}"
    );
    // A second stage from the checkpoint starts where the first ended, not from scratch.
    let lower = TrainConfig {
        learning_rate: 2e-4,
        ..quick(2, 1)
    };
    let (more, more_curve) = continue_forward(train_set, &fpath, &lower, 0.15).unwrap();
    eprintln!(
        "second stage: first val {:.3e}, stage one best {:.3e}, from scratch {:.3e}",
        more_curve[0].val_loss, fwd.meta.best_loss, curve[0].val_loss
    );
    assert!(more_curve[0].val_loss < 2.0 * fwd.meta.best_loss);
    assert!(more_curve[0].val_loss < 0.2 * curve[0].val_loss);
    assert_eq!(more.scalers, back.scalers);
    assert_eq!(more.meta.lumped, back.meta.lumped);
    // Data of another shape is refused.
    let other = lumped_trajectories(&demo_system(4, 4).unwrap(), 2, 100, 0.01, 1);
    assert!(continue_forward(&other, &fpath, &lower, 0.15).is_err());
    // JSON keeps the lumped model to the last bit or one unit in the last place.
    let (l0, l1) = (&fwd.meta.lumped, &back.meta.lumped);
    for (a, b) in l0
        .a_x
        .iter()
        .chain(&l0.a_v)
        .chain(&l0.a_p)
        .chain(&l0.c)
        .zip(l1.a_x.iter().chain(&l1.a_v).chain(&l1.a_p).chain(&l1.c))
    {
        assert!((a - b).abs() <= 1e-14 * a.abs(), "{a} vs {b}");
    }

    // The cycle's splice is exact: the true pressure spliced back gives the forward prediction.
    let scalers = &fwd.scalers;
    let cycle = CycleTarget::new(&fwd.model, scalers, &cpu_autodiff(), &cpu());
    let batch: Vec<usize> = (0..data.len()).step_by(13).collect();
    let p_true = tensor2(
        Samples::rows(&data.pressure, 3, &batch),
        batch.len(),
        3,
        &cpu(),
    );
    let spliced = values(cycle.predict(&data, &batch, p_true, &cpu()));
    let x = Tensor::<3>::from_data(
        TensorData::new(data.windows(&batch), [batch.len(), 10, data.step_dim()]),
        &cpu(),
    );
    let direct = values(fwd.model.forward(x));
    for (s, d) in spliced.iter().zip(&direct) {
        assert!((s - d).abs() < 1e-4, "{s} vs {d}");
    }
    // The plain-array model (the benchmark's) computes the trained model's function.
    let dense = fwd
        .model
        .dense()
        .unwrap()
        .forward(&data.windows(&batch), batch.len(), 10)
        .unwrap();
    assert_eq!(dense.len(), direct.len());
    for (a, d) in dense.iter().zip(&direct) {
        assert!(
            (a - d).abs() < 1e-4 * d.abs().max(1.0),
            "dense {a} vs burn {d}"
        );
    }

    let (inv, icurve) = train_inverse(
        train_set,
        &fwd,
        &InverseConfig::dissertation(3),
        &quick(15, 2),
        0.1,
        3,
    )
    .unwrap();
    assert!(icurve.last().unwrap().val_loss < icurve[0].val_loss);
    let im = evaluate_inverse(&inv.model, &inv.config, &inv.scalers, test_set, &cpu()).unwrap();
    // Baseline: the mean training pressure.
    let mut base = 0.0;
    let mut count = 0.0;
    for t in test_set {
        for k in 0..t.len() - 1 {
            for j in 0..3 {
                base += (t.p(k)[j] - inv.scalers.pressure.mean[j]).abs();
                count += 1.0;
            }
        }
    }
    let base = base / count;
    assert!(
        im.pressure_mae_kpa < 0.3 * base,
        "pressure error {:.3} kPa vs mean baseline {base:.3}",
        im.pressure_mae_kpa
    );
    let ipath = dir.join("inverse.ckpt");
    inv.save(&ipath).unwrap();
    let iback = TrainedInverse::load(&ipath).unwrap();
    let again = evaluate_inverse(
        &iback.model,
        &iback.config,
        &iback.scalers,
        test_set,
        &cpu(),
    )
    .unwrap();
    assert!(
        (again.pressure_mae_kpa - im.pressure_mae_kpa).abs() < 1e-9 * im.pressure_mae_kpa,
        "{again:?} vs {im:?}"
    );
    // A checkpoint of the other kind is refused by name.
    let err = TrainedForward::load(&ipath).unwrap_err().to_string();
    assert!(err.contains("ocm-dynamics/inverse"), "{err}");
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn bad_trajectories_are_refused_with_a_reason() {
    let sys = demo_system(3, 5).unwrap();
    let mut t = lumped_trajectories(&sys, 1, 50, 0.01, 1).remove(0);
    t.state[7] = f64::NAN;
    let e = Scalers::fit(&[t.clone()]).unwrap_err().to_string();
    assert!(e.contains("state step 2 column 1"), "{e}");
    t.state.pop();
    assert!(t.validate().unwrap_err().to_string().contains("state has"));
    let short = lumped_trajectories(&sys, 1, 8, 0.01, 1);
    let scalers = Scalers::fit(&short).unwrap();
    assert!(Samples::build(&short, 10, &scalers, None).is_err());
}
