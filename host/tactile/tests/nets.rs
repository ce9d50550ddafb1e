//! The perception and rendering networks on a small synthetic set of dimples: a short training
//! run cuts the held-out loss well below predicting the mean, and does not with shuffled
//! targets; checkpoints round-trip; images of the wrong size are refused.

use ocm_learn::{LrSchedule, Split, TrainConfig, UNetConfig, UNetNorm, cpu, cpu_autodiff};
use ocm_tactile::nets::pairs::Pairs;
use ocm_tactile::nets::{self, Engine, NetConfig, NetData, NetKind};
use ocm_tactile::optics::RgbImage;

const ROWS: usize = 16;
const COLS: usize = 24;

/// Gaussian dimples of random centre, width and depth: u_z on the grid and splatted (here the
/// same field), and a delta image whose channels are the two slopes and the depth, scaled to
/// tens of grey levels (a stand-in for the optics with the same locality).
fn synthetic(n: usize, seed: u64) -> Pairs {
    let mut s = seed;
    let mut next = || {
        s = s
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        (s >> 33) as f64 / (1u64 << 31) as f64
    };
    let px = ROWS * COLS;
    let (mut dz, mut delta) = (Vec::new(), Vec::new());
    for _ in 0..n {
        let (r0, c0) = (3.0 + next() * 10.0, 3.0 + next() * 18.0);
        let w = 2.0 + next() * 3.0;
        let d = -(1e-4 + next() * 6e-4);
        let f: Vec<f64> = (0..px)
            .map(|i| {
                let (r, c) = ((i / COLS) as f64 + 0.5, (i % COLS) as f64 + 0.5);
                d * (-((r - r0).powi(2) + (c - c0).powi(2)) / (2.0 * w * w)).exp()
            })
            .collect();
        let at = |r: usize, c: usize| f[r.min(ROWS - 1) * COLS + c.min(COLS - 1)];
        let mut ch = vec![0.0f32; 3 * px];
        for r in 0..ROWS {
            for c in 0..COLS {
                let i = r * COLS + c;
                ch[i] = ((at(r, c + 1) - at(r, c.saturating_sub(1))) * 1e5) as f32;
                ch[px + i] = ((at(r + 1, c) - at(r.saturating_sub(1), c)) * 1e5) as f32;
                ch[2 * px + i] = (f[i] * 6e4) as f32;
            }
        }
        dz.extend(f.iter().map(|&v| v as f32));
        delta.extend(ch);
    }
    Pairs {
        rows: ROWS,
        cols: COLS,
        pixel_m: 62.5e-6,
        setup_names: vec!["synthetic".into()],
        setup_unseen: vec![false],
        setup: vec![0; n],
        depth_m: vec![0.0; n],
        mirror: vec![0; n],
        state: (0..n).collect(),
        delta,
        splat_dz_m: dz.clone(),
        dz_m: dz,
        background: RgbImage {
            rows: ROWS,
            cols: COLS,
            data: vec![128; px * 3],
        },
    }
}

fn small(kind: NetKind) -> NetConfig {
    let full = match kind {
        NetKind::Perception => NetConfig::perception(ROWS, COLS),
        NetKind::Rendering => NetConfig::rendering(ROWS, COLS),
    };
    NetConfig {
        unet: UNetConfig {
            widths: vec![8, 16],
            norm: match full.unet.norm {
                UNetNorm::Batch => UNetNorm::Batch,
                UNetNorm::Group(_) => UNetNorm::Group(4),
            },
            ..full.unet
        },
        ..full
    }
}

/// Held-out loss of training with true or shuffled targets, and the loss of a network that
/// outputs the same (untrained) prediction for every sample would have: the mean-target loss.
fn held_out_ratio(kind: NetKind, shuffle: Option<u64>) -> (f64, f64) {
    held_out_ratio_with(kind, shuffle, 0.0)
}

/// [`held_out_ratio`] training with the perception network's contact-mask term at
/// `mask_weight`; the held-out loss is eq 5.15's MSE alone either way.
fn held_out_ratio_with(kind: NetKind, shuffle: Option<u64>, mask_weight: f32) -> (f64, f64) {
    held_out_ratio_in(kind, shuffle, mask_weight, Engine::Burn)
}

/// [`held_out_ratio_with`] with the gradients from `engine`.
fn held_out_ratio_in(
    kind: NetKind,
    shuffle: Option<u64>,
    mask_weight: f32,
    engine: Engine,
) -> (f64, f64) {
    let pairs = synthetic(40, 3);
    let mut data = NetData::new(kind, &pairs);
    data.mask_loss_weight = mask_weight;
    let split = split_32_8();
    let cfg = small(kind);
    let net = cfg.init(&cpu_autodiff(), 11).unwrap();
    let tc = smoke_config(40, 8);
    let report = nets::train_with(&data, net, &split, &tc, shuffle, engine).unwrap();
    let first = report.curve[0].train_loss;
    data.mask_loss_weight = 0.0;
    let held = ocm_learn::train::evaluate(&report.model, &split.val, 8, &cpu(), &|m, idx, d| {
        data.loss(m, idx, idx, d)
    });
    // The mean-target baseline on the held-out samples (perception: MSE of the normalised dz;
    // rendering: the masked L1 of a prediction equal to the mean training delta is not a
    // closed form, so the untrained first epoch serves).
    let base = match kind {
        NetKind::Perception => {
            let n = ROWS * COLS;
            let mean: Vec<f64> = (0..n)
                .map(|p| {
                    split
                        .train
                        .iter()
                        .map(|&i| f64::from(data.target[i * n + p]))
                        .sum::<f64>()
                        / split.train.len() as f64
                })
                .collect();
            split
                .val
                .iter()
                .flat_map(|&i| (0..n).map(move |p| (i, p)))
                .map(|(i, p)| (f64::from(data.target[i * n + p]) - mean[p]).powi(2))
                .sum::<f64>()
                / (split.val.len() * n) as f64
        }
        NetKind::Rendering => first,
    };
    (held / base, report.curve.last().unwrap().train_loss / first)
}

#[test]
fn perception_training_learns_and_fails_on_shuffled_targets() {
    let (held, train) = held_out_ratio(NetKind::Perception, None);
    assert!(held < 0.3, "held-out loss / mean-target loss {held}");
    assert!(
        train < 0.1,
        "training loss fell only to {train} of its start"
    );
    let (held_shuffled, _) = held_out_ratio(NetKind::Perception, Some(9));
    eprintln!("perception: held-out {held}, training {train}, shuffled {held_shuffled}");
    assert!(
        held_shuffled > 0.6,
        "shuffled targets reach {held_shuffled} of the baseline: the test cannot fail"
    );
}

/// The same with the contact-mask term beside the MSE (the trained figures use it).
#[test]
fn perception_with_mask_loss_learns_and_fails_on_shuffled_targets() {
    let (held, _) = held_out_ratio_with(NetKind::Perception, None, 0.02);
    assert!(held < 0.3, "held-out MSE / mean-target MSE {held}");
    let (held_shuffled, _) = held_out_ratio_with(NetKind::Perception, Some(9), 0.02);
    eprintln!("perception with mask loss: held-out {held}, shuffled {held_shuffled}");
    assert!(
        held_shuffled > 0.6,
        "shuffled targets reach {held_shuffled} of the baseline: the test cannot fail"
    );
}

/// The contact-mask term equals a direct sum: loss(w) - loss(0) = w mean(softplus(z) - y z)
/// with z = (1 - dz_norm) / width from the network's own output and y the FEM contact mask.
#[test]
fn mask_loss_is_the_soft_threshold_cross_entropy() {
    let pairs = synthetic(6, 8);
    let mut data = NetData::new(NetKind::Perception, &pairs);
    let net = small(NetKind::Perception).init(&cpu(), 3).unwrap();
    let idx: Vec<usize> = (0..6).collect();
    let dev = cpu();
    let at = |d: &NetData| f64::from(ocm_learn::values(d.loss(&net, &idx, &idx, &dev))[0]);
    let mse = at(&data);
    data.mask_loss_weight = 0.5;
    let with = at(&data);
    let pred = data.predict(&net, &idx, 6, &dev);
    let n = ROWS * COLS;
    let (mut bce, mut contact) = (0.0, 0usize);
    for (k, &dz) in pred.iter().enumerate() {
        let z = (1.0 - nets::dz_to_target(f64::from(dz))) / f64::from(nets::MASK_LOGIT_WIDTH);
        let y = -f64::from(pairs.dz_m[k]) > nets::CONTACT_DZ_M;
        contact += usize::from(y);
        // softplus without overflow: max(z, 0) + ln(1 + e^-|z|).
        bce += z.max(0.0) + (-z.abs()).exp().ln_1p() - if y { z } else { 0.0 };
    }
    let bce = bce / (6 * n) as f64;
    assert!(contact > 0 && contact < 6 * n, "{contact}");
    assert!(
        ((with - mse) / 0.5 - bce).abs() < 1e-3 * bce.abs().max(1.0),
        "{} vs {bce}",
        (with - mse) / 0.5
    );
}

/// The soft contact IoU term equals a direct sum: loss(w) - loss(0) = w mean over samples of
/// 1 - (sum p y + eps) / (sum (p + y - p y) + eps), p the sigmoid of the mask term's logit.
#[test]
fn iou_loss_is_the_per_sample_soft_jaccard() {
    let pairs = synthetic(14, 8);
    let mut data = NetData::new(NetKind::Perception, &pairs);
    // A few epochs bring the untrained network's output (far off the normalised range, where
    // the MSE would swamp a term below 1 in f32) near the targets.
    let split = Split {
        train: (6..14).collect(),
        val: (0..6).collect(),
    };
    let tc = smoke_config(5, 4);
    let init = small(NetKind::Perception).init(&cpu_autodiff(), 3).unwrap();
    let net = nets::train(&data, init, &split, &tc, None).unwrap().model;
    let idx: Vec<usize> = (0..6).collect();
    let dev = cpu();
    let at = |d: &NetData| f64::from(ocm_learn::values(d.loss(&net, &idx, &idx, &dev))[0]);
    let mse = at(&data);
    data.iou_loss_weight = 0.5;
    let with = at(&data);
    let pred = data.predict(&net, &idx, 6, &dev);
    let n = ROWS * COLS;
    let eps = f64::from(nets::SOFT_IOU_EPS);
    let mut term = 0.0;
    for k in 0..6 {
        let (mut inter, mut union) = (0.0, 0.0);
        let span = k * n..(k + 1) * n;
        for (dz_pred, dz_true) in pred[span.clone()].iter().zip(&pairs.dz_m[span]) {
            let z =
                (1.0 - nets::dz_to_target(f64::from(*dz_pred))) / f64::from(nets::MASK_LOGIT_WIDTH);
            let p = 1.0 / (1.0 + (-z).exp());
            let y = f64::from(u8::from(-f64::from(*dz_true) > nets::CONTACT_DZ_M));
            inter += p * y;
            union += p + y - p * y;
        }
        term += 1.0 - (inter + eps) / (union + eps);
    }
    let term = term / 6.0;
    assert!(term > 0.01, "{term}");
    assert!(
        ((with - mse) / 0.5 - term).abs() < 1e-3 * term,
        "{} vs {term}",
        (with - mse) / 0.5
    );
}

/// Training with the soft IoU term beside the mask term still learns the depth, and does not
/// on shuffled targets.
#[test]
fn perception_with_iou_loss_learns_and_fails_on_shuffled_targets() {
    let run = |shuffle| {
        let pairs = synthetic(40, 3);
        let mut data = NetData::new(NetKind::Perception, &pairs);
        data.mask_loss_weight = 0.02;
        data.iou_loss_weight = 0.05;
        let split = split_32_8();
        let net = small(NetKind::Perception)
            .init(&cpu_autodiff(), 11)
            .unwrap();
        let tc = smoke_config(40, 8);
        let report = nets::train(&data, net, &split, &tc, shuffle).unwrap();
        let pred = data.predict(&report.model, &split.val, 8, &cpu());
        let s = nets::score_predicted(&pred, &pairs, &split.val, nets::CONTACT_DZ_M, 1.0).unwrap();
        s.iou_mean
    };
    let (iou, shuffled) = (run(None), run(Some(9)));
    eprintln!("perception with the IoU term: held-out mean IoU {iou}, shuffled {shuffled}");
    assert!(iou > 0.6, "held-out mean IoU {iou}");
    assert!(
        shuffled < iou - 0.2,
        "shuffled targets reach IoU {shuffled} against {iou}: the test cannot fail"
    );
}

/// A block gel under the synthetic images (24 x 16 pixels of 62.5 um: 1.5 x 1 mm, 0.5 mm
/// thick, base fixed), its linear top-face force map and the resampler from the image grid.
fn block_force_map() -> (
    ocm_tactile::nets::force::LinearForceMap,
    ocm_tactile::optics::GridToMesh,
) {
    use ocm_tactile::gel::{Gel, GelMaterial};
    let mesh = ocm_fem::mesh::generate::box_mesh([12, 8, 4], [1.5e-3, 1e-3, 0.5e-3]);
    let gel = Gel::from_mesh(mesh, GelMaterial::default(), 1e-9).unwrap();
    let top = ocm_tactile::dataset::TopSurface::from_gel(&gel);
    let map = ocm_tactile::optics::CameraMap {
        px_per_m: 1.0 / 62.5e-6,
        angle_rad: 0.0,
        mirror: false,
        offset_px: [0.0, 0.0],
    };
    let to_mesh = ocm_tactile::optics::GridToMesh::new(&top.rest_m, ROWS, COLS, &map).unwrap();
    let lin = ocm_tactile::nets::force::LinearForceMap::new(&gel).unwrap();
    (lin, to_mesh)
}

/// Pixel weights of every sample's own target field (30 um patch).
fn force_weights(
    pairs: &Pairs,
    lin: &ocm_tactile::nets::force::LinearForceMap,
    to_mesh: &ocm_tactile::optics::GridToMesh,
) -> Vec<f32> {
    let n = ROWS * COLS;
    (0..pairs.len())
        .flat_map(|i| {
            lin.pixel_weights(to_mesh, &pairs.dz_m[i * n..(i + 1) * n], nets::CONTACT_DZ_M)
                .unwrap()
        })
        .collect()
}

/// The surface-force term equals the force of the depth error computed on the gel directly:
/// loss(w) - loss(0) = w mean over samples of (F(pred) - F(true))^2, F the linear force of each
/// field resampled onto the top nodes with the true field's patch (the node-level path, not
/// the pixel weights the loss uses); bad weights are refused.
#[test]
fn force_loss_is_the_force_of_the_depth_error() {
    let pairs = synthetic(6, 8);
    let (lin, to_mesh) = block_force_map();
    let mut data = NetData::new(NetKind::Perception, &pairs);
    let net = small(NetKind::Perception).init(&cpu(), 3).unwrap();
    let idx: Vec<usize> = (0..6).collect();
    let dev = cpu();
    let at = |d: &NetData| f64::from(ocm_learn::values(d.loss(&net, &idx, &idx, &dev))[0]);
    let mse = at(&data);
    let w = force_weights(&pairs, &lin, &to_mesh);
    assert!(data.set_force_loss(0.5, w[1..].to_vec()).is_err());
    let mut bad = w.clone();
    bad[7] = f32::NAN;
    assert!(data.set_force_loss(0.5, bad).is_err());
    assert!(data.set_force_loss(f32::NAN, w.clone()).is_err());
    data.set_force_loss(0.5, w).unwrap();
    let with = at(&data);
    let pred = data.predict(&net, &idx, 6, &dev);
    let n = ROWS * COLS;
    let mut term = 0.0;
    for k in 0..6 {
        let truth = to_mesh.sample(&pairs.dz_m[k * n..(k + 1) * n]).unwrap();
        let guess = to_mesh.sample(&pred[k * n..(k + 1) * n]).unwrap();
        let (patch, wn) = lin.patch_weights(&truth, nets::CONTACT_DZ_M).unwrap();
        assert!(!patch.is_empty());
        let df: f64 = -patch
            .iter()
            .zip(&wn)
            .map(|(&j, w)| w * (guess[j] - truth[j]))
            .sum::<f64>();
        term += df * df;
    }
    let term = term / 6.0;
    assert!(term > 1e-6, "{term}");
    let got = (with - mse) / 0.5;
    eprintln!("force term {term:.4e} N^2 beside the MSE {mse:.4e}");
    assert!((got - term).abs() < 2e-3 * term, "{got} vs {term}");
    let mut render = NetData::new(NetKind::Rendering, &pairs);
    assert!(render.set_force_loss(0.5, vec![0.0; 6 * n]).is_err());
}

/// Training with the force term beside eq 5.15 learns the held-out force (its linear force
/// error well below that of predicting the mean field) and does not on shuffled targets.
#[test]
fn perception_with_force_loss_learns_and_fails_on_shuffled_targets() {
    let pairs = synthetic(40, 3);
    let (lin, to_mesh) = block_force_map();
    let w = force_weights(&pairs, &lin, &to_mesh);
    let n = ROWS * COLS;
    let split = split_32_8();
    let force = |field: &[f32]| lin.force(&to_mesh.sample(field).unwrap(), nets::CONTACT_DZ_M);
    let truth: Vec<f64> = split
        .val
        .iter()
        .map(|&i| force(&pairs.dz_m[i * n..(i + 1) * n]).unwrap())
        .collect();
    let mean_field: Vec<f32> = (0..n)
        .map(|p| {
            split
                .train
                .iter()
                .map(|&i| pairs.dz_m[i * n + p])
                .sum::<f32>()
                / 32.0
        })
        .collect();
    let f_mean = force(&mean_field).unwrap();
    let rmse = |f: &dyn Fn(usize) -> f64| {
        (truth
            .iter()
            .enumerate()
            .map(|(k, t)| (f(k) - t).powi(2))
            .sum::<f64>()
            / truth.len() as f64)
            .sqrt()
    };
    let base = rmse(&|_| f_mean);
    let run = |shuffle| {
        let mut data = NetData::new(NetKind::Perception, &pairs);
        data.set_force_loss(20.0, w.clone()).unwrap();
        let net = small(NetKind::Perception)
            .init(&cpu_autodiff(), 11)
            .unwrap();
        let tc = smoke_config(40, 8);
        let report = nets::train(&data, net, &split, &tc, shuffle).unwrap();
        let pred = data.predict(&report.model, &split.val, 8, &cpu());
        rmse(&|k| force(&pred[k * n..(k + 1) * n]).unwrap())
    };
    let (trained, shuffled) = (run(None), run(Some(9)));
    eprintln!(
        "force term: held-out linear force RMSE {trained:.4} N, shuffled {shuffled:.4} N, mean field {base:.4} N"
    );
    assert!(
        trained < 0.5 * base,
        "{trained} against the mean field's {base}"
    );
    assert!(
        shuffled > base,
        "shuffled targets reach {shuffled} N against {base}: the test cannot fail"
    );
}

#[test]
fn rendering_training_learns_and_fails_on_shuffled_targets() {
    let (held, train) = held_out_ratio(NetKind::Rendering, None);
    assert!(held < 0.4, "held-out loss / first-epoch loss {held}");
    assert!(
        train < 0.4,
        "training loss fell only to {train} of its start"
    );
    let (held_shuffled, _) = held_out_ratio(NetKind::Rendering, Some(9));
    eprintln!("rendering: held-out {held}, training {train}, shuffled {held_shuffled}");
    assert!(
        held_shuffled > held * 1.5,
        "shuffled {held_shuffled} vs true {held}: the test cannot fail"
    );
}

/// The plain engine's training (hand-written gradients) learns as burn's does and fails on
/// shuffled targets, for both networks.
#[test]
fn plain_engine_training_learns_and_fails_on_shuffled_targets() {
    for (kind, bound) in [(NetKind::Perception, 0.3), (NetKind::Rendering, 0.4)] {
        let (held, train) = held_out_ratio_in(kind, None, 0.02, Engine::Plain);
        let (shuffled, _) = held_out_ratio_in(kind, Some(9), 0.02, Engine::Plain);
        eprintln!(
            "{kind:?} on the plain engine: held-out {held}, training {train}, shuffled {shuffled}"
        );
        assert!(held < bound, "{kind:?}: held-out loss ratio {held}");
        assert!(
            train < 0.4,
            "{kind:?}: training loss fell only to {train} of its start"
        );
        assert!(
            shuffled > held * 1.5,
            "{kind:?}: shuffled {shuffled} vs true {held}: the test cannot fail"
        );
    }
}

/// Both engines from the same weights, split and order give the same loss curve (Adam, batch
/// statistics and running statistics included). The training losses agree to round-off. The
/// validation loss of the batch-normalised perception network less closely: a convolution's
/// bias before a batch normalisation has no effect on the loss, its gradient is round-off in
/// either engine, and Adam turns that into steps of the full learning rate in directions that
/// differ between them; the running mean follows the bias, and the evaluation outputs with it.
#[test]
fn plain_and_burn_engines_train_alike() {
    let pairs = synthetic(40, 3);
    for kind in [NetKind::Perception, NetKind::Rendering] {
        let mut data = NetData::new(kind, &pairs);
        data.mask_loss_weight = 0.02;
        let cfg = small(kind);
        let curve = |engine| {
            let net = cfg.init(&cpu_autodiff(), 11).unwrap();
            nets::train_with(&data, net, &split_32_8(), &smoke_config(3, 8), None, engine)
                .unwrap()
                .curve
        };
        let (b, p) = (curve(Engine::Burn), curve(Engine::Plain));
        let val_tol = match kind {
            NetKind::Perception => 0.02,
            NetKind::Rendering => 1e-3,
        };
        assert_eq!(b.len(), p.len());
        for (x, y) in b.iter().zip(&p) {
            for (what, u, v, tol) in [
                ("training", x.train_loss, y.train_loss, 1e-4),
                ("validation", x.val_loss, y.val_loss, val_tol),
            ] {
                eprintln!(
                    "{kind:?} epoch {} {what}: burn {u:.6e}, plain {v:.6e}",
                    x.epoch
                );
                assert!(
                    (u - v).abs() <= tol * u.abs(),
                    "{kind:?} epoch {} {what} loss: {u} vs {v}",
                    x.epoch
                );
            }
        }
    }
}

/// Saved and loaded, a network with batch-norm running statistics predicts the same; a
/// checkpoint of the other network is refused by name.
#[test]
fn checkpoint_round_trip() {
    let pairs = synthetic(12, 4);
    let data = NetData::new(NetKind::Perception, &pairs);
    let cfg = small(NetKind::Perception);
    let split = Split {
        train: (0..12).collect(),
        val: vec![],
    };
    let tc = TrainConfig {
        epochs: 2,
        batch_size: 4,
        val_fraction: 0.0,
        patience: 0,
        ..TrainConfig::default()
    };
    let net = cfg.init(&cpu_autodiff(), 2).unwrap();
    let model = nets::train(&data, net, &split, &tc, None).unwrap().model;
    let dir = std::env::temp_dir().join(format!("ocm-tactile-nets-{}", std::process::id()));
    let path = dir.join("p.ckpt");
    nets::save(&path, &model, &cfg, serde_json::json!({"seed": 2})).unwrap();
    let (back, cfg2) = nets::load(&path, &cpu()).unwrap();
    assert_eq!(cfg2, cfg);
    let idx: Vec<usize> = (0..12).collect();
    let a = data.predict(&model, &idx, 4, &cpu());
    let b = data.predict(&back, &idx, 4, &cpu());
    assert_eq!(a, b);
    // The running statistics moved during training, so this also checks they were saved.
    let fresh = cfg.init(&cpu(), 2).unwrap();
    assert_ne!(data.predict(&fresh, &idx, 4, &cpu()), a);
    std::fs::remove_dir_all(&dir).ok();
}

/// Images of the wrong size or channel count are refused with both sizes named.
#[test]
fn wrong_images_are_refused() {
    let img = RgbImage {
        rows: 10,
        cols: 12,
        data: vec![0; 360],
    };
    let e = nets::check_image(&img, 16, 24, "frame.png")
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("frame.png") && e.contains("12 x 10") && e.contains("24 x 16"),
        "{e}"
    );
    let bad = RgbImage {
        rows: 16,
        cols: 24,
        data: vec![0; 16 * 24 * 4],
    };
    assert!(nets::check_image(&bad, 16, 24, "rgba.png").is_err());
    let dir = std::env::temp_dir().join(format!("ocm-tactile-gray-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let p = dir.join("gray.png");
    image::GrayImage::new(24, 16).save(&p).unwrap();
    let e = RgbImage::read(&p).unwrap_err().to_string();
    assert!(e.contains("1 channel"), "{e}");
    std::fs::remove_dir_all(&dir).ok();
}

/// The bfloat16 engine on a trained perception network: its depth maps differ from the f32
/// engine's by a small fraction of the network's own error, and its contact masks are nearly
/// the same.
#[test]
fn bfloat16_inference_keeps_a_trained_networks_predictions() {
    use ocm_tactile::nets::infer::Precision;
    let pairs = synthetic(40, 3);
    let data = NetData::new(NetKind::Perception, &pairs);
    let split = split_32_8();
    let net = small(NetKind::Perception)
        .init(&cpu_autodiff(), 11)
        .unwrap();
    let report = nets::train(&data, net, &split, &smoke_config(30, 8), None).unwrap();
    let dev = cpu();
    let full = data.predict_in(&report.model, &split.val, 8, &dev, Precision::F32);
    let half = data.predict_in(&report.model, &split.val, 8, &dev, Precision::Bf16);
    let n = ROWS * COLS;
    let truth = &pairs.dz_m[32 * n..40 * n];
    let rms = |a: &[f32], b: &[f32]| {
        (a.iter()
            .zip(b)
            .map(|(x, y)| f64::from(x - y).powi(2))
            .sum::<f64>()
            / a.len() as f64)
            .sqrt()
    };
    let (own, rounding) = (rms(&full, truth), rms(&half, &full));
    eprintln!("bf16: u_z RMS difference {rounding:e} m, the network's own error {own:e} m");
    assert!(
        rounding > 0.0 && rounding < 0.05 * own,
        "bf16 moves u_z by {rounding} m RMS against the network's error of {own} m"
    );
    let grid = pairs.grid();
    for k in 0..split.val.len() {
        let m = |dz: &[f32]| nets::contact_mask(grid, &dz[k * n..(k + 1) * n]);
        let (a, b) = (m(&full), m(&half));
        if a.count() + b.count() > 0 {
            let iou = ocm_tactile::metrics::iou(&a, &b).unwrap();
            assert!(iou > 0.9, "sample {k}: f32 and bf16 masks IoU {iou}");
        }
    }
}

/// The synthetic set's split: 32 samples to train on, the last 8 held out.
fn split_32_8() -> Split {
    Split {
        train: (0..32).collect(),
        val: (32..40).collect(),
    }
}

/// The smoke runs' training settings: fixed epochs, no validation split or early stop, seed 5.
fn smoke_config(epochs: usize, batch_size: usize) -> TrainConfig {
    TrainConfig {
        epochs,
        batch_size,
        learning_rate: 3e-3,
        val_fraction: 0.0,
        patience: 0,
        grad_clip_norm: None,
        seed: 5,
        progress: false,
        lr_schedule: LrSchedule::Constant,
    }
}
