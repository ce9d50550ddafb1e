//! Behaviour of the training loop, the networks and the checkpoints on small real problems.

use ocm_learn::burn::module::Module;
use ocm_learn::burn::tensor::{Device, Tensor, TensorData};
use ocm_learn::checkpoint::param_shapes;
use ocm_learn::{
    Checkpoint, CheckpointInfo, LearnError, LrSchedule, Mlp, MlpConfig, SequenceEncoderConfig,
    Split, Standardizer, TrainConfig, batch_gradients, cpu, cpu_autodiff, gather_rows,
    save_checkpoint, train, train_split_sharded, values,
};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use std::collections::BTreeMap;

/// 512 samples of `y = sin(2 x0) + x0 x1`, inputs uniform in [-1.5, 1.5]^2, scaled.
fn regression(seed: u64) -> (Vec<f32>, Vec<f32>) {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let mut x = Vec::new();
    let mut y = Vec::new();
    for _ in 0..512 {
        let a: f64 = rng.random_range(-1.5..1.5);
        let b: f64 = rng.random_range(-1.5..1.5);
        x.extend([a, b]);
        y.push((2.0 * a).sin() + a * b);
    }
    let sx = Standardizer::fit(&x, 2).unwrap();
    let sy = Standardizer::fit(&y, 1).unwrap();
    (sx.apply(&x).unwrap(), sy.apply(&y).unwrap())
}

fn mse(model: &Mlp, x: &[f32], y: &[f32], batch: &[usize], device: &Device) -> Tensor<1> {
    let xb = gather_rows(x, 2, batch, device);
    let yb = gather_rows(y, 1, batch, device);
    (model.forward(xb) - yb).powi_scalar(2).mean()
}

fn fit(x: &[f32], y: &[f32], cfg: &TrainConfig, seed: u64) -> (f64, ocm_learn::TrainReport<Mlp>) {
    let model = MlpConfig::relu(2, &[32, 32], 1).init(&cpu_autodiff(), seed);
    let split = Split::random(y.len(), cfg.val_fraction, cfg.seed);
    let before = ocm_learn::train::evaluate(&model.valid(), &split.val, 512, &cpu(), &|m, b, d| {
        mse(m, x, y, b, d)
    });
    let report = train(model, y.len(), cfg, |m, b, d| mse(m, x, y, b, d)).unwrap();
    (before, report)
}

fn small_cfg(epochs: usize) -> TrainConfig {
    TrainConfig {
        epochs,
        batch_size: 32,
        learning_rate: 3e-3,
        val_fraction: 0.25,
        patience: 0,
        grad_clip_norm: None,
        seed: 11,
        progress: false,
        lr_schedule: LrSchedule::Constant,
    }
}

#[test]
fn training_cuts_the_loss_and_cannot_fit_shuffled_targets() {
    let (x, y) = regression(1);
    let (before, report) = fit(&x, &y, &small_cfg(60), 5);
    let ratio = report.best_loss / before;
    // A smooth 2-D function: the validation loss must fall at least 20-fold.
    assert!(
        ratio < 0.05,
        "validation loss {before:.3} -> {:.4} (ratio {ratio:.3})",
        report.best_loss
    );

    // The same inputs with the targets permuted carry no signal: the held-out loss cannot fall
    // much below the targets' variance (1 in scaled units).
    let mut shuffled = y.clone();
    let mut rng = ChaCha8Rng::seed_from_u64(99);
    rand::seq::SliceRandom::shuffle(shuffled.as_mut_slice(), &mut rng);
    let (before_s, report_s) = fit(&x, &shuffled, &small_cfg(60), 5);
    let ratio_s = report_s.best_loss / before_s;
    assert!(
        report_s.best_loss > 0.7 && ratio_s > 0.5,
        "shuffled targets: validation loss {before_s:.3} -> {:.3}",
        report_s.best_loss
    );
}

#[test]
fn cosine_schedule_runs_from_the_rate_to_its_final_fraction() {
    let (base, total) = (2e-3, 1000);
    let cosine = LrSchedule::Cosine {
        final_fraction: 0.1,
    };
    let close = |a: f64, b: f64| assert!((a - b).abs() <= 1e-12 * b, "{a} vs {b}");
    assert_eq!(cosine.rate(base, 0, total), base);
    // Half a cosine: 1/2 (1 + cos(pi t)) is 0.8536 at a quarter, 1/2 at half, 0 at the end.
    close(
        cosine.rate(base, 250, total),
        base * (0.1 + 0.9 * 0.853_553_390_593_273_8),
    );
    close(cosine.rate(base, 500, total), base * 0.55);
    close(cosine.rate(base, total, total), base * 0.1);
    close(cosine.rate(base, 2 * total, total), base * 0.1);
    let rates: Vec<f64> = (0..=total).map(|k| cosine.rate(base, k, total)).collect();
    assert!(rates.windows(2).all(|w| w[1] <= w[0]), "never rises");
    assert_eq!(LrSchedule::Constant.rate(base, 700, total), base);
    assert_eq!(LrSchedule::cosine_to(Some(0.1)), cosine);
    assert_eq!(LrSchedule::cosine_to(None), LrSchedule::Constant);
    assert!(cosine.validate().is_ok());
    for bad in [-0.1, 1.5, f64::NAN] {
        let r = LrSchedule::Cosine {
            final_fraction: bad,
        }
        .validate();
        assert!(matches!(r, Err(LearnError::Config(_))), "{bad}: {r:?}");
    }
    // A configuration saved before the schedule existed reads as a constant step.
    let mut old = serde_json::to_value(small_cfg(3)).unwrap();
    old.as_object_mut().unwrap().remove("lr_schedule");
    let read: TrainConfig = serde_json::from_value(old).unwrap();
    assert_eq!(read.lr_schedule, LrSchedule::Constant);
    let cfg = TrainConfig {
        lr_schedule: cosine,
        ..small_cfg(3)
    };
    let back: TrainConfig = serde_json::from_str(&serde_json::to_string(&cfg).unwrap()).unwrap();
    assert_eq!(back, cfg);
}

#[test]
fn the_loop_steps_along_the_schedule() {
    let (x, y) = regression(9);
    let schedule = LrSchedule::Cosine {
        final_fraction: 0.1,
    };
    let run = |lr_schedule| {
        let cfg = TrainConfig {
            lr_schedule,
            ..small_cfg(5)
        };
        fit(&x, &y, &cfg, 4).1
    };
    let constant = run(LrSchedule::Constant);
    let cosine = run(schedule);
    // 384 training samples in batches of 32: 12 steps an epoch, 60 in all.
    for r in &cosine.curve {
        assert_eq!(r.learning_rate, schedule.rate(3e-3, 12 * r.epoch - 1, 60));
    }
    assert!(cosine.curve[4].learning_rate < 0.11 * 3e-3);
    assert!(constant.curve.iter().all(|r| r.learning_rate == 3e-3));
    assert_ne!(weights(&cosine.model), weights(&constant.model));
    // Decaying to the full rate is the constant step, bit for bit.
    let flat = run(LrSchedule::Cosine {
        final_fraction: 1.0,
    });
    assert_eq!(weights(&flat.model), weights(&constant.model));
}

#[test]
fn early_stopping_keeps_the_best_epoch() {
    let (x, y) = regression(2);
    let mut shuffled = y.clone();
    rand::seq::SliceRandom::shuffle(shuffled.as_mut_slice(), &mut ChaCha8Rng::seed_from_u64(3));
    let cfg = TrainConfig {
        patience: 4,
        learning_rate: 1e-2,
        ..small_cfg(300)
    };
    let (_, report) = fit(&x, &shuffled, &cfg, 8);
    assert!(
        report.stopped_early,
        "overfitting noise must trigger early stopping"
    );
    let last = report.curve.last().unwrap().epoch;
    assert_eq!(
        last,
        report.best_epoch + 4,
        "stops `patience` epochs after the best"
    );
    let best = report
        .curve
        .iter()
        .map(|r| r.val_loss)
        .fold(f64::INFINITY, f64::min);
    assert_eq!(best, report.best_loss);
    // The returned model is the best epoch's: its validation loss is the recorded minimum.
    let split = Split::random(y.len(), cfg.val_fraction, cfg.seed);
    let again = ocm_learn::train::evaluate(&report.model, &split.val, 32, &cpu(), &|m, b, d| {
        mse(m, &x, &shuffled, b, d)
    });
    assert!(
        (again - best).abs() < 1e-6 * best.max(1.0),
        "{again} vs {best}"
    );
}

fn weights(m: &Mlp) -> Vec<f32> {
    m.layers
        .iter()
        .flat_map(|l| {
            let mut w = values(l.weight.val());
            w.extend(values(l.bias.as_ref().unwrap().val()));
            w
        })
        .collect()
}

#[test]
fn same_seed_same_weights() {
    let (x, y) = regression(4);
    let cfg = small_cfg(3);
    let (_, a) = fit(&x, &y, &cfg, 21);
    let (_, b) = fit(&x, &y, &cfg, 21);
    assert_eq!(weights(&a.model), weights(&b.model));
    assert_eq!(
        a.curve.iter().map(|r| r.train_loss).collect::<Vec<_>>(),
        b.curve.iter().map(|r| r.train_loss).collect::<Vec<_>>()
    );
    let (_, c) = fit(&x, &y, &cfg, 22);
    assert_ne!(weights(&a.model), weights(&c.model));
    let other_order = TrainConfig { seed: 12, ..cfg };
    let (_, d) = fit(&x, &y, &other_order, 21);
    assert_ne!(weights(&a.model), weights(&d.model));
    // Initialisation alone is seeded too, for every network.
    let enc = SequenceEncoderConfig {
        input: 5,
        d_model: 16,
        n_heads: 4,
        d_ff: 32,
        n_layers: 2,
        max_len: 6,
    };
    let e1 = enc.init(&cpu(), 3);
    let e2 = enc.init(&cpu(), 3);
    let probe = Tensor::<3>::from_data(
        TensorData::new(
            (0..60).map(|i| (i as f32 * 0.37).sin()).collect::<Vec<_>>(),
            [2, 6, 5],
        ),
        &cpu(),
    );
    assert_eq!(
        values(e1.forward(probe.clone())),
        values(e2.forward(probe.clone()))
    );
    assert_ne!(
        values(e1.forward(probe.clone())),
        values(enc.init(&cpu(), 4).forward(probe))
    );
}

/// Every weight's and bias's gradient in `g`, layer after layer.
fn gradients(m: &Mlp, g: &ocm_learn::burn::optim::GradientsParams) -> Vec<f32> {
    m.layers
        .iter()
        .flat_map(|l| {
            let mut v = values(g.get::<2>(l.weight.id).unwrap());
            v.extend(values(g.get::<1>(l.bias.as_ref().unwrap().id).unwrap()));
            v
        })
        .collect()
}

fn max_abs_diff(a: &[f32], b: &[f32]) -> f32 {
    assert_eq!(a.len(), b.len());
    a.iter()
        .zip(b)
        .map(|(p, q)| (p - q).abs())
        .fold(0.0, f32::max)
}

#[test]
fn sharded_batches_give_the_whole_batch_gradient() {
    let (x, y) = regression(6);
    let device = cpu_autodiff();
    let model = MlpConfig::relu(2, &[16, 16], 1).init(&device, 4);
    let loss = |m: &Mlp, b: &[usize], d: &Device| mse(m, &x, &y, b, d);
    // Seven samples in three threads: parts of 3, 2 and 2, so a part's mean must be weighted by
    // its size to give the batch's.
    let batch: Vec<usize> = (40..47).collect();
    let (v1, g1) = batch_gradients(&model, &batch, 1, &device, &loss);
    let (v3, g3) = batch_gradients(&model, &batch, 3, &device, &loss);
    let (full, sharded) = (gradients(&model, &g1), gradients(&model, &g3));
    let scale = full.iter().fold(0.0f32, |m, g| m.max(g.abs()));
    assert!((v1 - v3).abs() < 1e-6 * v1, "loss {v1} vs {v3}");
    let err = max_abs_diff(&full, &sharded);
    assert!(
        err < 1e-5 * scale,
        "gradient differs by {err} (scale {scale})"
    );
    // The parts' plain mean is measurably another gradient, so the check above can fail.
    let plain: Vec<Vec<f32>> = [&batch[..3], &batch[3..5], &batch[5..]]
        .iter()
        .map(|p| gradients(&model, &batch_gradients(&model, p, 1, &device, &loss).1))
        .collect();
    let mean: Vec<f32> = (0..full.len())
        .map(|i| plain.iter().map(|g| g[i]).sum::<f32>() / 3.0)
        .collect();
    assert!(max_abs_diff(&full, &mean) > 100.0 * err.max(1e-7 * scale));
    // More threads than samples leave none idle with an empty part.
    let (v9, g9) = batch_gradients(&model, &batch[..2], 9, &device, &loss);
    let (v2, g2) = batch_gradients(&model, &batch[..2], 1, &device, &loss);
    assert!((v9 - v2).abs() < 1e-6 * v2);
    assert!(max_abs_diff(&gradients(&model, &g9), &gradients(&model, &g2)) < 1e-5 * scale);
    // A diverged part makes the batch's loss diverge, with no gradients to step on.
    let nan = |m: &Mlp, b: &[usize], d: &Device| {
        let l = mse(m, &x, &y, b, d);
        if b.contains(&46) {
            l.mul_scalar(f32::NAN)
        } else {
            l
        }
    };
    let (vn, gn) = batch_gradients(&model, &batch, 3, &device, &nan);
    assert!(vn.is_nan() && gn.is_empty());
}

#[test]
fn sharded_training_is_seeded_and_follows_the_single_thread_run() {
    let (x, y) = regression(7);
    let cfg = small_cfg(4);
    let split = Split::random(y.len(), cfg.val_fraction, cfg.seed);
    let run = |shards| {
        let model = MlpConfig::relu(2, &[32, 32], 1).init(&cpu_autodiff(), 3);
        train_split_sharded(model, &split, &cfg, shards, |m, b, d| mse(m, &x, &y, b, d)).unwrap()
    };
    let (one, two, again) = (run(1), run(2), run(2));
    assert_eq!(weights(&two.model), weights(&again.model));
    let losses =
        |r: &ocm_learn::TrainReport<Mlp>| r.curve.iter().map(|e| e.val_loss).collect::<Vec<_>>();
    assert_eq!(losses(&two), losses(&again));
    // Rounding alone separates the two: the same steps, the same curve to 10^-5.
    for (a, b) in losses(&one).iter().zip(losses(&two)) {
        assert!((a - b).abs() < 1e-5 * a, "validation loss {a} vs {b}");
    }
    // And it learns: four epochs cut the validation loss by 80 % (0.74 -> 0.15).
    assert!(
        losses(&two)[3] < 0.3 * losses(&two)[0],
        "{:?}",
        losses(&two)
    );
}

#[test]
fn split_is_seeded_disjoint_and_complete() {
    let s = Split::random(103, 0.2, 7);
    assert_eq!(s.val.len(), 21);
    let mut all: Vec<usize> = s.train.iter().chain(&s.val).copied().collect();
    all.sort_unstable();
    assert_eq!(all, (0..103).collect::<Vec<_>>());
    assert_eq!(s, Split::random(103, 0.2, 7));
    assert_ne!(s, Split::random(103, 0.2, 8));
}

fn info<'a>(cfg: &'a MlpConfig) -> CheckpointInfo<'a, MlpConfig> {
    CheckpointInfo {
        architecture: "test/mlp",
        config: cfg,
        scalers: BTreeMap::from([(
            "input".to_string(),
            Standardizer {
                mean: vec![1.0, -2.0],
                std: vec![0.5, 3.0],
            },
        )]),
        meta: serde_json::json!({"epochs": 3}),
    }
}

fn probe_output(m: &Mlp) -> Vec<f32> {
    let x = Tensor::<2>::from_data(
        TensorData::new(vec![0.3f32, -1.2, 2.0, 0.1, -0.5, 0.7], [3, 2]),
        &cpu(),
    );
    values(m.forward(x))
}

#[test]
fn checkpoint_round_trip_restores_outputs_and_scalers() {
    let dir = std::env::temp_dir().join(format!("ocm-learn-ck-{}", std::process::id()));
    let path = dir.join("mlp.ckpt");
    let cfg = MlpConfig::relu(2, &[16, 8], 1);
    let (x, y) = regression(6);
    let model = cfg.init(&cpu_autodiff(), 1);
    let trained = train(model, y.len(), &small_cfg(2), |m, b, d| {
        mse(m, &x, &y, b, d)
    })
    .unwrap()
    .model;
    save_checkpoint(&path, &trained, &info(&cfg)).unwrap();
    let ck = Checkpoint::read(&path).unwrap();
    let stored: MlpConfig = ck.config().unwrap();
    assert_eq!(stored, cfg);
    // A model built from another seed takes the stored weights exactly.
    let loaded = ck
        .load_into(stored.init(&cpu(), 999), "test/mlp", &cfg)
        .unwrap();
    assert_eq!(probe_output(&loaded), probe_output(&trained));
    assert_ne!(probe_output(&cfg.init(&cpu(), 999)), probe_output(&trained));
    assert_eq!(ck.scaler("input").unwrap().std, vec![0.5, 3.0]);
    assert_eq!(ck.header.meta["epochs"], 3);
    assert_eq!(ck.header.params, param_shapes(&trained));
    assert!(ck.scaler("output").is_err());
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn corrupt_or_mismatched_checkpoints_are_refused() {
    let dir = std::env::temp_dir().join(format!("ocm-learn-bad-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join("mlp.ckpt");
    let cfg = MlpConfig::relu(2, &[16, 8], 1);
    let model = cfg.init(&cpu(), 1);
    save_checkpoint(&path, &model, &info(&cfg)).unwrap();
    let good = std::fs::read(&path).unwrap();
    let corrupt = |bytes: &[u8], name: &str| {
        let p = dir.join(name);
        std::fs::write(&p, bytes).unwrap();
        match Checkpoint::read(&p) {
            Err(LearnError::CorruptCheckpoint { path, reason }) => {
                assert_eq!(path, p);
                reason
            }
            other => panic!("{name}: expected a corrupt-checkpoint error, got {other:?}"),
        }
    };
    let mut flipped = good.clone();
    let last = flipped.len() - 5;
    flipped[last] ^= 0x40;
    assert!(corrupt(&flipped, "payload.ckpt").contains("weights checksum"));
    let mut header = good.clone();
    header[40] ^= 0x01;
    assert!(corrupt(&header, "header.ckpt").contains("header checksum"));
    assert!(corrupt(&good[..good.len() - 100], "short.ckpt").contains("bytes"));
    assert!(corrupt(b"P6 not a checkpoint at all, just some text", "text.ckpt").contains("magic"));
    assert!(corrupt(&good[..20], "stub.ckpt").contains("shorter"));

    let ck = Checkpoint::read(&path).unwrap();
    let mismatch = |r: ocm_learn::Result<Mlp>| match r {
        Err(LearnError::CheckpointMismatch { reason, .. }) => reason,
        other => panic!("expected a mismatch, got {other:?}"),
    };
    let wider = MlpConfig::relu(2, &[32, 8], 1);
    assert!(
        mismatch(ck.load_into(wider.init(&cpu(), 1), "test/mlp", &wider)).contains("configuration")
    );
    assert!(
        mismatch(ck.load_into(cfg.init(&cpu(), 1), "test/transformer", &cfg)).contains("test/mlp")
    );
    // Same configuration claimed, different network: the shape check catches it.
    assert!(mismatch(ck.load_into(wider.init(&cpu(), 1), "test/mlp", &cfg)).contains("shapes"));
    // A checkpoint of another kind is named as such before its configuration is decoded.
    match ck.config_of::<MlpConfig>(&["test/npe", "test/unet"]) {
        Err(LearnError::CheckpointMismatch { reason, .. }) => assert_eq!(
            reason,
            "holds a 'test/mlp' model, expected 'test/npe' or 'test/unet'"
        ),
        other => panic!("expected a mismatch, got {other:?}"),
    }
    assert_eq!(ck.config_of::<MlpConfig>(&["test/mlp"]).unwrap(), cfg);
    let missing = Checkpoint::read(&dir.join("absent.ckpt"));
    assert!(matches!(missing, Err(LearnError::Io { .. })));
    std::fs::remove_dir_all(&dir).ok();
}

/// Central differences of the scalar loss against autodiff for a few weights of each kind.
fn check_gradients<M: Module>(
    model: M,
    loss: impl Fn(&M) -> Tensor<1>,
    params: impl Fn(&M) -> Vec<Tensor<2>>,
    rebuild: impl Fn(&M, usize, usize, f32) -> M,
) {
    let l = loss(&model);
    let grads = l.backward();
    let ps = params(&model);
    let mut checked = 0;
    for (pi, p) in ps.iter().enumerate() {
        let g = values(p.grad(&grads).expect("parameter has a gradient"));
        let n = g.len();
        for k in [0, n / 3, n / 2, n - 1] {
            let h = 1e-2f32;
            let up = values(loss(&rebuild(&model, pi, k, h)).inner())[0] as f64;
            let down = values(loss(&rebuild(&model, pi, k, -h)).inner())[0] as f64;
            let fd = (up - down) / (2.0 * f64::from(h));
            let ad = f64::from(g[k]);
            let tol = 2e-3 + 2e-2 * ad.abs().max(fd.abs());
            assert!(
                (fd - ad).abs() < tol,
                "param {pi} entry {k}: autodiff {ad:.6} vs finite difference {fd:.6}"
            );
            checked += 1;
        }
    }
    assert!(checked >= 8);
}

#[test]
fn mlp_gradients_match_finite_differences() {
    let device = cpu_autodiff();
    let cfg = MlpConfig {
        activation: ocm_learn::Activation::Tanh,
        ..MlpConfig::relu(3, &[7, 5], 2)
    };
    let x = Tensor::<2>::from_data(
        TensorData::new(
            (0..12).map(|i| (i as f32 * 0.7).cos()).collect::<Vec<_>>(),
            [4, 3],
        ),
        &device,
    );
    let t = Tensor::<2>::from_data(
        TensorData::new(
            (0..8).map(|i| (i as f32 * 0.3).sin()).collect::<Vec<_>>(),
            [4, 2],
        ),
        &device,
    );
    let loss = |m: &Mlp| (m.forward(x.clone()) - t.clone()).powi_scalar(2).mean();
    check_gradients(
        cfg.init(&device, 4),
        loss,
        |m| m.layers.iter().map(|l| l.weight.val()).collect(),
        |m, pi, k, h| {
            let mut m = m.clone();
            m.layers[pi].weight = m.layers[pi].weight.clone().map(|w| {
                let dims = w.dims();
                let mut v = values(w.clone());
                v[k] += h;
                Tensor::from_data(TensorData::new(v, dims), &w.device()).require_grad()
            });
            m
        },
    );
}

#[test]
fn sequence_encoder_input_gradient_matches_finite_differences() {
    // The encoder's gradient with respect to its input exercises every layer: embedding,
    // positions, attention, feed-forward, the norms and the last-step readout.
    let device = cpu_autodiff();
    let enc = SequenceEncoderConfig {
        input: 3,
        d_model: 8,
        n_heads: 2,
        d_ff: 16,
        n_layers: 2,
        max_len: 4,
    }
    .init(&device, 9);
    let base: Vec<f32> = (0..24).map(|i| (i as f32 * 0.41).sin()).collect();
    let w: Vec<f32> = (0..16).map(|i| (i as f32 * 0.9).cos()).collect();
    let weight = Tensor::<2>::from_data(TensorData::new(w, [2, 8]), &device);
    let loss = |v: &[f32], track: bool| {
        let mut x = Tensor::<3>::from_data(TensorData::new(v.to_vec(), [2, 4, 3]), &device);
        if track {
            x = x.require_grad();
        }
        ((enc.forward_last(x.clone()) * weight.clone()).sum(), x)
    };
    let pairs =
        ocm_learn::gradcheck::gradient_pairs(&base, &[0, 1, 2, 5, 11, 17, 23], 1e-2, loss).unwrap();
    for p in &pairs {
        assert!(p.agrees(3e-3, 3e-2), "input {}: {p:?}", p.index);
    }
    // Only the last step is read out, but attention lets earlier steps influence it.
    assert!(pairs[..3].iter().any(|p| p.autodiff.abs() > 1e-4));
}

#[test]
fn loss_curve_is_written_as_csv_and_png() {
    let dir = std::env::temp_dir().join(format!("ocm-learn-curve-{}", std::process::id()));
    let (x, y) = regression(7);
    let report = train(
        MlpConfig::relu(2, &[8], 1).init(&cpu_autodiff(), 2),
        y.len(),
        &small_cfg(4),
        |m, b, d| mse(m, &x, &y, b, d),
    )
    .unwrap();
    ocm_learn::write_curve(&dir, "loss", "test", &report.curve).unwrap();
    let csv = std::fs::read_to_string(dir.join("loss.csv")).unwrap();
    let lines: Vec<&str> = csv.lines().collect();
    assert_eq!(
        lines[0],
        "epoch,train_loss,val_loss,learning_rate,elapsed_s"
    );
    assert_eq!(lines.len(), 5);
    let png = std::fs::read(dir.join("loss.png")).unwrap();
    assert_eq!(&png[1..4], b"PNG");
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn training_refuses_bad_settings() {
    let (x, y) = regression(8);
    let plain = MlpConfig::relu(2, &[8], 1).init(&cpu(), 2);
    let r = train(plain, y.len(), &small_cfg(1), |m, b, d| {
        mse(m, &x, &y, b, d)
    });
    assert!(matches!(r, Err(LearnError::Config(_))), "{r:?}");
    let zero_batch = TrainConfig {
        batch_size: 0,
        ..small_cfg(1)
    };
    let bad_fraction = TrainConfig {
        lr_schedule: LrSchedule::Cosine {
            final_fraction: 2.0,
        },
        ..small_cfg(1)
    };
    for (name, cfg) in [("batch of 0", zero_batch), ("cosine to 2", bad_fraction)] {
        let r = train(
            MlpConfig::relu(2, &[8], 1).init(&cpu_autodiff(), 2),
            y.len(),
            &cfg,
            |m, b, d| mse(m, &x, &y, b, d),
        );
        assert!(matches!(r, Err(LearnError::Config(_))), "{name}: {r:?}");
    }
    let huge = TrainConfig {
        learning_rate: 1e9,
        ..small_cfg(5)
    };
    let r = train(
        MlpConfig::relu(2, &[8], 1).init(&cpu_autodiff(), 2),
        y.len(),
        &huge,
        |m, b, d| mse(m, &x, &y, b, d).mul_scalar(1e30).mul_scalar(1e30),
    );
    assert!(matches!(r, Err(LearnError::Diverged { .. })), "{r:?}");
}
