//! `ocm tactile train perception|rendering` and `ocm tactile perceive`: the U-Net perception and
//! rendering networks on pairs from the tactile FEM data set and the physically based renderer.

use anyhow::Context;
use ocm_learn::{LrSchedule, Split, TrainConfig, cpu, cpu_autodiff};
use ocm_tactile::dataset::{Dataset, TopSurface};
use ocm_tactile::gel::{Gel, GelMaterial};
use ocm_tactile::mask::Grid;
use ocm_tactile::nets::pairs::{self, build_pairs_mirrored, delta_of, depth_image, downscale};
use ocm_tactile::nets::{self, NetConfig, NetData, NetKind};
use ocm_tactile::optics::{GridToMesh, RgbImage};
use ocm_tactile::real::{self, COLS, ROWS, difference_image, side_by_side};
use std::path::PathBuf;

/// Which network to train.
#[derive(clap::ValueEnum, Clone, Copy, Debug)]
pub enum NetArg {
    /// RGB delta image -> surface displacement u_z (f_theta, eq 5.9-5.15).
    Perception,
    /// Splatted nodal displacement -> RGB delta image (f_theta+, eq 5.16-5.22).
    Rendering,
}

/// Arguments of `ocm tactile train`.
#[derive(clap::Args, Debug)]
pub struct TrainNetArgs {
    /// Which network.
    #[arg(value_enum)]
    pub net: NetArg,
    /// Data set folder written by `ocm tactile dataset` (FEM states of the seen and unseen
    /// set-ups); the unseen set-ups are held out and scored.
    #[arg(long, default_value = "out/npe/dataset")]
    pub dataset: PathBuf,
    /// Data directory (default: OCM_DATA_DIR, else ../shared/data).
    #[arg(long)]
    pub data: Option<PathBuf>,
    /// Image reduction: 1 trains on 240 x 320, 2 on 120 x 160 (block means), 4 on 60 x 80.
    #[arg(long, default_value_t = 2)]
    pub scale: usize,
    /// Passes over the training samples.
    #[arg(long, default_value_t = 30)]
    pub epochs: usize,
    /// Samples per optimiser step.
    #[arg(long, default_value_t = 8)]
    pub batch: usize,
    /// Adam step size (the dissertation's 1e-5 is for far longer runs on a GPU).
    #[arg(long, default_value_t = 1e-3)]
    pub lr: f64,
    /// Fraction of the seen samples used for validation and early stopping.
    #[arg(long, default_value_t = 0.15)]
    pub val_fraction: f64,
    /// Stop after this many epochs without a validation improvement.
    #[arg(long, default_value_t = 8)]
    pub patience: usize,
    /// Seed of the weights, the split and the shuffling.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Perception: weight of the contact-mask term (cross-entropy of the soft 30 um threshold)
    /// beside eq 5.15's MSE on dz; 0 trains on eq 5.15 alone.
    #[arg(long, default_value_t = 0.02)]
    pub mask_loss: f32,
    /// Perception: weight of the soft contact IoU term (1 - soft IoU of the sigmoid of the same
    /// logit, per sample, averaged over samples): weighs small and shallow contacts like large
    /// ones; 0 leaves it out.
    #[arg(long, default_value_t = 0.0)]
    pub iou_loss: f32,
    /// Perception: weight (1/N^2) of the surface-force term: the squared force, in N, of the
    /// depth error through the gel's linear top-face compliance on each target's 30 um patch
    /// (`nets::force::LinearForceMap`); 0 leaves it out.
    #[arg(long, default_value_t = 0.0)]
    pub force_loss: f32,
    /// Also train on the seen states with the surface mirrored across the image rows, columns
    /// and both, each rendered anew (4 x the training samples; validation and held-out
    /// samples stay unmirrored).
    #[arg(long)]
    pub mirror: bool,
    /// Output folder (checkpoint, loss curve, summary.json, example PNGs).
    #[arg(long, default_value = "out/tactile/nets")]
    pub out: PathBuf,
    /// Start from this checkpoint's weights (same network and size) instead of random ones:
    /// a second stage at a lower `--lr` (there is no learning-rate schedule).
    #[arg(long)]
    pub init_from: Option<PathBuf>,
    /// Render the pairs with the optics `compare-real` fitted to the real sensor (its
    /// map.json: colour transform, depth shading, smoothing) instead of the calibration as
    /// measured; the image layout stays the networks' landscape frame.
    #[arg(long)]
    pub optics: Option<PathBuf>,
    /// Score this checkpoint (written by an earlier run with the same data set, scale and
    /// seed) on the same split instead of training; writes `<net>_scores.json` in `--out`.
    #[arg(long)]
    pub score_only: Option<PathBuf>,
    /// With --score-only on a perception checkpoint: also the surface force of each held-out
    /// sample through eq 5.8 (predicted u_z on the top nodes, the gel model solved with it)
    /// against the contact FEM's force; writes `perception_force.json`.
    #[arg(long, requires = "score_only")]
    pub force: bool,
    /// With --force: only the predicted fields (skips the two reference solves per sample
    /// from the FEM's own u_z, on the image grid and on the nodes).
    #[arg(long, requires = "force")]
    pub force_fast: bool,
    /// With --force: indentation above which a top node is in the prescribed contact patch, um
    /// (the contact masks' 30 um by default).
    #[arg(long, requires = "force", default_value_t = 30.0)]
    pub force_threshold_um: f64,
    /// With --force: hold the patch's x and y (a contact stuck where it was touched) instead of
    /// leaving them free (frictionless).
    #[arg(long, requires = "force")]
    pub force_stuck: bool,
    /// With --force: score every K-th held-out sample only (the solves take seconds each).
    #[arg(long, requires = "force", value_parser = crate::arg_check::count, default_value_t = 1)]
    pub force_every: usize,
    /// With --score-only on a perception checkpoint: the surface force of every held-out
    /// sample through the gel's linear top-face compliance (seconds; the quantity the
    /// `--force-loss` term trains), written to `perception_force_linear.json`.
    #[arg(long, requires = "score_only")]
    pub force_linear: bool,
    /// With --score-only on a perception checkpoint: choose the indentation threshold of the
    /// predicted contact mask (10 to 100 um in 2.5 um steps) by the median IoU on the
    /// validation samples, and score the held-out ones at it (the true masks stay at 30 um).
    #[arg(long, requires = "score_only")]
    pub fit_threshold: bool,
    /// Arithmetic of the plain engine's convolutions when scoring (training itself runs in
    /// f32): f32, winograd or bf16 (see `ocm tactile perceive --precision`).
    #[arg(long, default_value = "f32")]
    pub precision: nets::infer::Precision,
    /// What computes the training gradients: `plain`, the plain engine's hand-written
    /// forward and backward passes (about 10 times faster on a CPU, the same gradients to
    /// round-off), or `burn`, burn's autodiff graph (how the checkpoints before it were
    /// trained). Both use burn's Adam and checkpoints.
    #[arg(long, default_value = "plain")]
    pub engine: nets::Engine,
    /// Print the JSON summary.
    #[arg(long)]
    pub json: bool,
}

/// Arguments of `ocm tactile perceive`.
#[derive(clap::Args, Debug)]
pub struct PerceiveArgs {
    /// Perception checkpoint written by `ocm tactile train perception`.
    pub checkpoint: PathBuf,
    /// RGB frames (320 x 240 or 640 x 480) in the orientation of the training images (gel y
    /// along the columns, x along the rows).
    #[arg(required_unless_present = "real")]
    pub images: Vec<PathBuf>,
    /// Instead of IMAGES: the 100 real edge6 frames, warped into the network's frame through
    /// the camera map of this `compare-real` map.json, scored against the masks measured on
    /// them (IoU, centroid, rotation); writes real_scores.json and example PNGs.
    #[arg(long)]
    pub real: Option<PathBuf>,
    /// With --real: map the real colour change back into the calibrated sensor's colours
    /// (inverse of the fitted colour transform) before the network; for a network trained on
    /// the calibration as measured (not with `train --optics`).
    #[arg(long)]
    pub uncolour: bool,
    /// With --real: bring the real change into the rendered domain by a colour transform
    /// fitted on the even frames (their paired FEM steps from this `ocm tactile indent` cache
    /// of edge6, e.g. out/tactile/edge6-fem, rendered with the calibration as measured, against
    /// the real frames: `real::fit_colour` with real and rendered exchanged); the odd frames
    /// are scored.
    #[arg(long, conflicts_with = "uncolour")]
    pub recolour_fem: Option<PathBuf>,
    /// With --real: multiply the real change by this gain before the network (the calibrating
    /// sensor's change is stronger than the real one's); choose it on the even frames
    /// (`even_frames` in the summary), the odd ones are the score.
    #[arg(long, conflicts_with_all = ["uncolour", "recolour_fem"])]
    pub gain: Option<f64>,
    /// With --real: shift the predicted masks in the camera image by the mean offset of their
    /// centroids from the measured ones over the even frames (fitted there, scored on the odd).
    #[arg(long, requires = "real")]
    pub shift_fit: bool,
    /// With --real: keep the real frames' brightness drift (by default each channel's median
    /// change over the camera's view is subtracted).
    #[arg(long)]
    pub keep_drift: bool,
    /// No-contact background of the same sensor. Default: frame 00 of the real edge6 sequence.
    #[arg(long)]
    pub background: Option<PathBuf>,
    /// Data directory (default: OCM_DATA_DIR, else ../shared/data).
    #[arg(long)]
    pub data: Option<PathBuf>,
    /// Output folder: depth_<name>.png, mask_<name>.png and the nodal field U of the top face
    /// (u_<name>.npy, M x 3, m; u_x = u_y = 0).
    #[arg(long, default_value = "out/tactile/perceive")]
    pub out: PathBuf,
    /// Arithmetic of the network's convolutions: winograd (f32 with Winograd's F(4 x 4,
    /// 3 x 3) where the channels allow: about 1.7 times the images per second of f32 on any
    /// x86-64 CPU, outputs within about 2e-6 RMS of f32's), f32 (direct), or bf16 (bfloat16
    /// weights and activations with f32 sums; as fast as winograd on CPUs with AVX-512 BF16,
    /// outputs within about 1 % RMS of f32's).
    #[arg(long, default_value = "winograd")]
    pub precision: nets::infer::Precision,
    /// Print JSON.
    #[arg(long)]
    pub json: bool,
}

fn digit_gel(data: Option<&std::path::Path>, mesh: &str) -> anyhow::Result<(PathBuf, Gel)> {
    let digit = ocm_datadir::data_file(data, "digit")?;
    let gel = Gel::digit(digit.join(mesh), GelMaterial::default())?;
    Ok((digit, gel))
}

/// `ocm tactile train perception|rendering`.
pub fn train(a: TrainNetArgs) -> anyhow::Result<()> {
    let t0 = std::time::Instant::now();
    let ds = Dataset::read(&a.dataset)
        .with_context(|| format!("reading the data set {}", a.dataset.display()))?;
    let (digit, gel) = digit_gel(a.data.as_deref(), &ds.manifest.mesh)?;
    let mut renderer = real::default_renderer(&digit)?;
    if let Some(p) = &a.optics {
        real::OpticsFile::read(p)?.apply(&mut renderer);
    }
    let pairs = build_pairs_mirrored(&ds, &gel, &renderer, a.scale, a.mirror)?;
    let t_pairs = t0.elapsed().as_secs_f64();
    let kind = match a.net {
        NetArg::Perception => NetKind::Perception,
        NetArg::Rendering => NetKind::Rendering,
    };
    let mut data = NetData::new(kind, &pairs);
    data.mask_loss_weight = a.mask_loss;
    data.iou_loss_weight = a.iou_loss;
    if a.force_loss > 0.0 {
        anyhow::ensure!(
            matches!(kind, NetKind::Perception),
            "--force-loss is for the perception network"
        );
        let t = std::time::Instant::now();
        let (lin, to_mesh) = linear_force_map(&gel, &pairs, a.scale)?;
        let n = pairs.pixels();
        let mut w = Vec::with_capacity(pairs.len() * n);
        for i in 0..pairs.len() {
            w.extend(lin.pixel_weights(
                &to_mesh,
                &pairs.dz_m[i * n..(i + 1) * n],
                nets::CONTACT_DZ_M,
            )?);
        }
        data.set_force_loss(a.force_loss, w)?;
        if !a.json {
            println!(
                "surface-force term: linear top-face compliance and the weights of {} samples in {:.1} s",
                pairs.len(),
                t.elapsed().as_secs_f64()
            );
        }
    }
    let seen = pairs.samples_where_unseen(false);
    let held = pairs.samples_where_unseen(true);
    anyhow::ensure!(
        !seen.is_empty(),
        "no seen set-ups in {}",
        a.dataset.display()
    );
    let inner = Split::random(seen.len(), a.val_fraction, a.seed);
    let mut train: Vec<usize> = inner.train.iter().map(|&i| seen[i]).collect();
    train.extend(pairs.mirrors_of(&train));
    let split = Split {
        train,
        val: inner.val.iter().map(|&i| seen[i]).collect(),
    };
    let cfg = match kind {
        NetKind::Perception => NetConfig::perception(pairs.rows, pairs.cols),
        NetKind::Rendering => NetConfig::rendering(pairs.rows, pairs.cols),
    };
    if let Some(ck) = &a.score_only {
        return score_only(&a, ck, kind, &data, &pairs, &held, &split.val, (&ds, &gel));
    }
    let net = match &a.init_from {
        Some(p) => {
            let (net, c) = nets::load(p, &cpu_autodiff())?;
            anyhow::ensure!(
                c == cfg,
                "{} holds {:?} at {} x {}, not the {:?} network at {} x {} asked for",
                p.display(),
                c.kind,
                c.cols,
                c.rows,
                cfg.kind,
                cfg.cols,
                cfg.rows
            );
            net
        }
        None => cfg.init(&cpu_autodiff(), a.seed)?,
    };
    let tc = TrainConfig {
        epochs: a.epochs,
        batch_size: a.batch,
        learning_rate: a.lr,
        val_fraction: a.val_fraction,
        patience: a.patience,
        grad_clip_norm: Some(1.0),
        seed: a.seed,
        progress: !a.json,
        lr_schedule: LrSchedule::Constant,
    };
    let t1 = std::time::Instant::now();
    let report = nets::train_with(&data, net, &split, &tc, None, a.engine)?;
    let train_s = t1.elapsed().as_secs_f64();
    std::fs::create_dir_all(&a.out).with_context(|| format!("creating {}", a.out.display()))?;
    let name = match kind {
        NetKind::Perception => "perception",
        NetKind::Rendering => "rendering",
    };
    let ckpt = a.out.join(format!("{name}.ckpt"));
    let meta = serde_json::json!({
        "seed": a.seed,
        "mask_loss": a.mask_loss,
    "iou_loss": a.iou_loss,
        "force_loss": a.force_loss,
        "mirror": a.mirror,
        "init_from": a.init_from.as_ref().map(|p| p.display().to_string()),
        "optics": a.optics.as_ref().map(|p| p.display().to_string()),
        "learning_rate": a.lr,
        "dataset": a.dataset.display().to_string(),
        "scale": a.scale,
        "train_samples": split.train.len(),
        "val_samples": split.val.len(),
        "best_epoch": report.best_epoch,
        "best_val_loss": report.best_loss,
        "train_seconds": train_s,
        "engine": a.engine,
    });
    nets::save(&ckpt, &report.model, &cfg, meta)?;
    ocm_learn::write_curve(
        &a.out,
        &format!("{name}_loss"),
        &format!("{name} network"),
        &report.curve,
    )?;
    let dev = cpu();
    let mut images = Vec::new();
    let example = |k: usize| held[(k * held.len()) / 3 + held.len() / 6];
    let (held_scores, val_scores) = match kind {
        NetKind::Perception => {
            let (h, pred) =
                nets::score_perception(&report.model, &data, &pairs, &held, &dev, a.precision)?;
            let (v, _) = nets::score_perception(
                &report.model,
                &data,
                &pairs,
                &split.val,
                &dev,
                a.precision,
            )?;
            let n = pairs.pixels();
            for k in 0..3.min(held.len()) {
                let i = example(k);
                let j = held.iter().position(|&x| x == i).unwrap_or(0);
                let img = side_by_side(&[
                    &pairs.frame(i),
                    &depth_image(&pairs.dz_m[i * n..(i + 1) * n], pairs.rows, pairs.cols),
                    &depth_image(&pred[j * n..(j + 1) * n], pairs.rows, pairs.cols),
                ])?;
                let p = a.out.join(format!(
                    "perception_{}_{i}.png",
                    pairs.setup_names[pairs.setup[i]]
                ));
                img.write_png(&p)?;
                images.push(p.display().to_string());
            }
            (serde_json::to_value(h)?, serde_json::to_value(v)?)
        }
        NetKind::Rendering => {
            let (h, frames) =
                nets::score_rendering(&report.model, &data, &pairs, &held, &dev, a.precision)?;
            let (v, _) =
                nets::score_rendering(&report.model, &data, &pairs, &split.val, &dev, a.precision)?;
            for k in 0..3.min(held.len()) {
                let i = example(k);
                let j = held.iter().position(|&x| x == i).unwrap_or(0);
                let truth = pairs.frame(i);
                let img = side_by_side(&[
                    &truth,
                    &frames[j],
                    &difference_image(&truth, &frames[j], 4.0),
                ])?;
                let p = a.out.join(format!(
                    "rendering_{}_{i}.png",
                    pairs.setup_names[pairs.setup[i]]
                ));
                img.write_png(&p)?;
                images.push(p.display().to_string());
            }
            (serde_json::to_value(h)?, serde_json::to_value(v)?)
        }
    };
    let v = serde_json::json!({
        "network": name,
        "architecture": cfg,
        "image": [pairs.rows, pairs.cols],
        "scale": a.scale,
        "mask_loss": a.mask_loss,
    "iou_loss": a.iou_loss,
        "force_loss": a.force_loss,
        "mirror": a.mirror,
        "init_from": a.init_from.as_ref().map(|p| p.display().to_string()),
        "optics": a.optics.as_ref().map(|p| p.display().to_string()),
        "learning_rate": a.lr,
        "samples": pairs.len(),
        "train_samples": split.train.len(),
        "val_samples": split.val.len(),
        "held_out_samples": held.len(),
        "held_out_setups": pairs.setup_names.iter().zip(&pairs.setup_unseen).filter(|(_, u)| **u).map(|(n, _)| n.clone()).collect::<Vec<_>>(),
        "pairs_seconds": t_pairs,
        "train_seconds": train_s,
        "epochs_run": report.curve.len(),
        "engine": a.engine,
        "best_epoch": report.best_epoch,
        "best_val_loss": report.best_loss,
        "first_train_loss": report.curve.first().map(|r| r.train_loss),
        "scored_in": a.precision,
        "held_out": held_scores,
        "validation": val_scores,
        "checkpoint": ckpt.display().to_string(),
        "images": images,
        "threads": rayon_threads(),
    });
    std::fs::write(
        a.out.join(format!("{name}_summary.json")),
        serde_json::to_string_pretty(&v)?,
    )?;
    if a.json {
        println!("{}", serde_json::to_string_pretty(&v)?);
    } else {
        println!(
            "{name}: {} training / {} validation / {} held-out samples at {} x {}, {} epochs in {:.0} s (best {}, val loss {:.4e}); held out: {}; checkpoint {}",
            split.train.len(),
            split.val.len(),
            held.len(),
            pairs.cols,
            pairs.rows,
            report.curve.len(),
            train_s,
            report.best_epoch,
            report.best_loss,
            v["held_out"],
            ckpt.display()
        );
    }
    Ok(())
}

/// The gel's linear top-face force map and the resampler from the pairs' image grid to its top
/// nodes.
fn linear_force_map(
    gel: &Gel,
    pairs: &pairs::Pairs,
    scale: usize,
) -> anyhow::Result<(ocm_tactile::nets::force::LinearForceMap, GridToMesh)> {
    let (map, _, _) = pairs::image_map(gel, scale);
    let top = TopSurface::from_gel(gel);
    let to_mesh = GridToMesh::new(&top.rest_m, pairs.rows, pairs.cols, &map)?;
    Ok((ocm_tactile::nets::force::LinearForceMap::new(gel)?, to_mesh))
}

/// `--score-only`: the held-out and validation scores of a trained checkpoint (and with
/// `--force` the surface force of the held-out samples).
#[allow(clippy::too_many_arguments)]
fn score_only(
    a: &TrainNetArgs,
    ck: &std::path::Path,
    kind: NetKind,
    data: &NetData,
    pairs: &pairs::Pairs,
    held: &[usize],
    val: &[usize],
    (ds, gel): (&Dataset, &Gel),
) -> anyhow::Result<()> {
    let dev = cpu();
    let (net, cfg) = nets::load(ck, &dev)?;
    anyhow::ensure!(
        cfg.kind == kind && (cfg.rows, cfg.cols) == (pairs.rows, pairs.cols),
        "{} holds a {:?} network at {} x {}, asked to score {kind:?} at {} x {}",
        ck.display(),
        cfg.kind,
        cfg.cols,
        cfg.rows,
        pairs.cols,
        pairs.rows
    );
    let mut force = serde_json::Value::Null;
    let mut force_linear = serde_json::Value::Null;
    let (h, v) = match kind {
        NetKind::Perception => {
            let (mut h, pred) = nets::score_perception(&net, data, pairs, held, &dev, a.precision)?;
            let (mut vs, vpred) =
                nets::score_perception(&net, data, pairs, val, &dev, a.precision)?;
            if a.fit_threshold {
                let candidates: Vec<f64> = (0..=36).map(|k| 10e-6 + 2.5e-6 * k as f64).collect();
                let (t, _) = nets::fit_threshold(&vpred, pairs, val, &candidates)?;
                h = nets::score_predicted(&pred, pairs, held, t, h.images_per_s)?;
                vs = nets::score_predicted(&vpred, pairs, val, t, vs.images_per_s)?;
            }
            if a.force_linear {
                let (lin, to_mesh) = linear_force_map(gel, pairs, a.scale)?;
                let f = ocm_tactile::nets::force::score_force_linear(
                    &lin,
                    &to_mesh,
                    pairs,
                    ds,
                    &pred,
                    held,
                    nets::CONTACT_DZ_M,
                )?;
                std::fs::create_dir_all(&a.out)
                    .with_context(|| format!("creating {}", a.out.display()))?;
                std::fs::write(
                    a.out.join("perception_force_linear.json"),
                    serde_json::to_string_pretty(&f)?,
                )?;
                // The validation samples (seen set-ups) beside them: whether a force error is
                // one of unseen shapes or of the network's depth in general.
                let fv = ocm_tactile::nets::force::score_force_linear(
                    &lin,
                    &to_mesh,
                    pairs,
                    ds,
                    &vpred,
                    val,
                    nets::CONTACT_DZ_M,
                )?;
                std::fs::write(
                    a.out.join("perception_force_linear_validation.json"),
                    serde_json::to_string_pretty(&fv)?,
                )?;
                let mut brief = serde_json::to_value(&f)?;
                let mut vbrief = serde_json::to_value(&fv)?;
                for b in [&mut brief, &mut vbrief] {
                    if let Some(o) = b.as_object_mut() {
                        o.remove("per_sample");
                    }
                }
                force_linear = serde_json::json!({"held_out": brief, "validation": vbrief});
            }
            if a.force {
                use ocm_tactile::nets::force::{SurfaceForceModel, score_force};
                let (map, _, _) = pairs::image_map(gel, a.scale);
                let top = TopSurface::from_gel(gel);
                let to_mesh = GridToMesh::new(&top.rest_m, pairs.rows, pairs.cols, &map)?;
                let model = SurfaceForceModel::new(gel)?;
                anyhow::ensure!(a.force_every >= 1, "--force-every must be at least 1");
                let n = pairs.pixels();
                let (mut sub, mut sub_pred) = (Vec::new(), Vec::new());
                for (k, &i) in held.iter().enumerate().step_by(a.force_every) {
                    sub.push(i);
                    sub_pred.extend_from_slice(&pred[k * n..(k + 1) * n]);
                }
                let f = score_force(
                    &model,
                    &to_mesh,
                    pairs,
                    ds,
                    &sub_pred,
                    &sub,
                    !a.force_fast,
                    a.force_threshold_um * 1e-6,
                    a.force_stuck,
                )?;
                std::fs::create_dir_all(&a.out)
                    .with_context(|| format!("creating {}", a.out.display()))?;
                std::fs::write(
                    a.out.join("perception_force.json"),
                    serde_json::to_string_pretty(&f)?,
                )?;
                let mut brief = serde_json::to_value(&f)?;
                if let Some(o) = brief.as_object_mut() {
                    o.remove("per_sample");
                }
                force = brief;
            }
            (serde_json::to_value(h)?, serde_json::to_value(vs)?)
        }
        NetKind::Rendering => (
            serde_json::to_value(
                nets::score_rendering(&net, data, pairs, held, &dev, a.precision)?.0,
            )?,
            serde_json::to_value(
                nets::score_rendering(&net, data, pairs, val, &dev, a.precision)?.0,
            )?,
        ),
    };
    let name = match kind {
        NetKind::Perception => "perception",
        NetKind::Rendering => "rendering",
    };
    let v = serde_json::json!({
        "network": name,
        "checkpoint": ck.display().to_string(),
        "image": [pairs.rows, pairs.cols],
        "scored_in": a.precision,
        "held_out": h,
        "validation": v,
        "surface_force": force,
        "surface_force_linear": force_linear,
    });
    std::fs::create_dir_all(&a.out).with_context(|| format!("creating {}", a.out.display()))?;
    std::fs::write(
        a.out.join(format!("{name}_scores.json")),
        serde_json::to_string_pretty(&v)?,
    )?;
    if a.json {
        println!("{}", serde_json::to_string_pretty(&v)?);
    } else {
        println!("{name} {}: held out {}", ck.display(), v["held_out"]);
    }
    Ok(())
}

/// `ocm tactile perceive --real MAP`: the network on the real edge6 frames.
fn perceive_real(
    a: &PerceiveArgs,
    net: &ocm_learn::UNet,
    cfg: &NetConfig,
    digit: &std::path::Path,
    gel: &Gel,
    map_json: &std::path::Path,
) -> anyhow::Result<()> {
    use ocm_tactile::nets::real_frames::{self, RealOptions};
    let fitted = real::OpticsFile::read(map_json)?;
    let frames = real::load_frames(&digit.join("real-frames-edge6"), "edge6")?;
    let (land, _, _) = pairs::image_map(gel, 1);
    let recolour = match &a.recolour_fem {
        Some(dir) => {
            let fields = real::read_cached_steps(dir, 100, gel.num_nodes()).with_context(|| {
                format!(
                    "{} does not hold the 100 edge6 steps u_001.npy .. u_100.npy of this mesh",
                    dir.display()
                )
            })?;
            let even: Vec<usize> = (1..frames.len()).filter(|k| k % 2 == 0).collect();
            let renderer = real::default_renderer(digit)?;
            Some(real_frames::fit_recolour(
                gel, &fields, &frames, &fitted, &renderer, &even,
            )?)
        }
        None => match a.gain {
            Some(g) => {
                anyhow::ensure!(
                    g.is_finite() && g > 0.0,
                    "--gain {g}: expected a finite value > 0"
                );
                Some([[g, 0.0, 0.0], [0.0, g, 0.0], [0.0, 0.0, g]])
            }
            None => None,
        },
    };
    let opts = RealOptions {
        uncolour: a.uncolour,
        recolour,
        remove_drift: !a.keep_drift,
        shift_fit: a.shift_fit,
        precision: a.precision,
        ..RealOptions::default()
    };
    let t = std::time::Instant::now();
    let (scores, pred) = real_frames::perceive_real(
        net,
        (cfg.rows, cfg.cols),
        &land,
        &frames,
        &fitted,
        &opts,
        &cpu(),
    )?;
    let seconds = t.elapsed().as_secs_f64();
    // parity: None for every frame, Some(1) for the odd ones, Some(0) for the even ones.
    let med = |f: &dyn Fn(&real_frames::RealFrameScore) -> f64, parity: Option<usize>| {
        let v: Vec<f64> = scores
            .iter()
            .filter(|s| parity.is_none_or(|p| s.frame % 2 == p))
            .map(f)
            .filter(|x| !x.is_nan())
            .collect();
        ocm_mor::run::median(&v)
    };
    let summary = |parity: Option<usize>| {
        serde_json::json!({
            "frames": scores.iter().filter(|s| parity.is_none_or(|p| s.frame % 2 == p)).count(),
            "iou_median": med(&|s| s.iou, parity),
            "centroid_mm_median": med(&|s| s.centroid_mm, parity),
            "rotation_rad_median": med(&|s| s.rotation_rad, parity),
            "rotation_rad_median_elongated": med(&|s| if s.real_elongation >= nets::ROTATION_MIN_ELONGATION { s.rotation_rad } else { f64::NAN }, parity),
        })
    };
    std::fs::create_dir_all(&a.out).with_context(|| format!("creating {}", a.out.display()))?;
    let n = cfg.rows * cfg.cols;
    let mut images = Vec::new();
    for k in [41usize, 61, 81, 99] {
        if k >= frames.len() {
            continue;
        }
        let img = side_by_side(&[
            &downscale(
                &real_frames::warp_image(&frames[k], &fitted.map, &land, ROWS, COLS),
                ROWS / cfg.rows,
            ),
            &depth_image(&pred[(k - 1) * n..k * n], cfg.rows, cfg.cols),
        ])?;
        let p = a.out.join(format!("real_{k:02}.png"));
        img.write_png(&p)?;
        images.push(p.display().to_string());
    }
    let v = serde_json::json!({
        "checkpoint": a.checkpoint.display().to_string(),
        "map": map_json.display().to_string(),
        "uncolour": a.uncolour,
        "recolour": recolour,
        "remove_drift": !a.keep_drift,
        "image": [cfg.rows, cfg.cols],
        "gain": a.gain,
        "shift_fit": a.shift_fit,
        "all_frames": summary(None),
        "odd_frames": summary(Some(1)),
        "even_frames": summary(Some(0)),
        "seconds": seconds,
        "images": images,
        "per_frame": scores,
    });
    std::fs::write(
        a.out.join("real_scores.json"),
        serde_json::to_string_pretty(&v)?,
    )?;
    if a.json {
        println!("{}", serde_json::to_string_pretty(&v)?);
    } else {
        println!(
            "real edge6 frames: all {}; odd {}; files in {}",
            v["all_frames"],
            v["odd_frames"],
            a.out.display()
        );
    }
    Ok(())
}

fn rayon_threads() -> usize {
    std::thread::available_parallelism().map_or(1, |n| n.get())
}

/// `ocm tactile perceive`.
pub fn perceive(a: PerceiveArgs) -> anyhow::Result<()> {
    let dev = cpu();
    let (net, cfg) = nets::load(&a.checkpoint, &dev)?;
    anyhow::ensure!(
        cfg.kind == NetKind::Perception,
        "{} holds a {:?} network, not a perception network",
        a.checkpoint.display(),
        cfg.kind
    );
    anyhow::ensure!(
        ROWS.is_multiple_of(cfg.rows)
            && COLS.is_multiple_of(cfg.cols)
            && ROWS / cfg.rows == COLS / cfg.cols,
        "the network's {} x {} does not divide the DIGIT's {COLS} x {ROWS}",
        cfg.cols,
        cfg.rows
    );
    if a.precision == nets::infer::Precision::Bf16 && !nets::bf16::simd_available() {
        eprintln!(
            "warning: this CPU lacks AVX-512 BF16; bf16 runs in a portable loop, slower than f32"
        );
    }
    let scale = ROWS / cfg.rows;
    let (digit, gel) = digit_gel(a.data.as_deref(), "DIGIT_v8.vtk")?;
    if let Some(map_json) = &a.real {
        return perceive_real(&a, &net, &cfg, &digit, &gel, map_json);
    }
    let bg_path = a
        .background
        .unwrap_or_else(|| digit.join(real::DEFAULT_BACKGROUND));
    let bg = downscale(&RgbImage::read_sized(&bg_path, ROWS, COLS)?, scale);
    let (map, r_img, c_img) = pairs::image_map(&gel, scale);
    anyhow::ensure!(
        (r_img, c_img) == (cfg.rows, cfg.cols),
        "the network takes {} x {}, the gel image at scale {scale} is {c_img} x {r_img}",
        cfg.cols,
        cfg.rows
    );
    let small = Grid {
        origin_m: [0.0, 0.0],
        pixel_m: map.m_per_px(),
        rows: cfg.rows,
        cols: cfg.cols,
    };
    let top = TopSurface::from_gel(&gel);
    let to_mesh = GridToMesh::new(&top.rest_m, cfg.rows, cfg.cols, &map)?;
    std::fs::create_dir_all(&a.out).with_context(|| format!("creating {}", a.out.display()))?;
    // The weights are copied out of burn once, not per image.
    let plain = nets::infer::PlainUNet::new(&net)?.with_precision(a.precision);
    let mut rows = Vec::new();
    for path in &a.images {
        let img = downscale(&RgbImage::read_sized(path, ROWS, COLS)?, scale);
        nets::check_image(&img, cfg.rows, cfg.cols, &path.display().to_string())?;
        let delta = delta_of(&img, &bg)?;
        let single = pairs::Pairs {
            rows: cfg.rows,
            cols: cfg.cols,
            pixel_m: small.pixel_m,
            setup_names: vec![],
            setup_unseen: vec![],
            setup: vec![0],
            depth_m: vec![0.0],
            mirror: vec![0],
            state: vec![0],
            delta,
            dz_m: vec![0.0; cfg.rows * cfg.cols],
            splat_dz_m: vec![],
            background: bg.clone(),
        };
        let data = NetData::new(NetKind::Perception, &single);
        let t = std::time::Instant::now();
        let dz = data
            .predict_on(&plain, &[0], 1)
            .with_context(|| format!("{}: the network does not take this image", path.display()))?;
        let ms = t.elapsed().as_secs_f64() * 1e3;
        let stem = path
            .file_stem()
            .map_or("frame".into(), |s| s.to_string_lossy().to_string());
        depth_image(&dz, cfg.rows, cfg.cols).write_png(a.out.join(format!("depth_{stem}.png")))?;
        let mask = nets::contact_mask(small, &dz);
        mask.write_png(a.out.join(format!("mask_{stem}.png")))?;
        let u = to_mesh.displacement(&dz)?;
        let flat: Vec<f64> = u.iter().flatten().copied().collect();
        ocm_fem::npy::write_f64_2d_path(a.out.join(format!("u_{stem}.npy")), &flat, u.len(), 3)?;
        let st = mask.stats();
        rows.push(serde_json::json!({
            "image": path.display().to_string(),
            "contact_area_mm2": mask.count() as f64 * small.pixel_m * small.pixel_m * 1e6,
            "max_depth_mm": -dz.iter().copied().fold(0.0f32, f32::min) * 1e3,
            "centroid_mm": [st.centroid_m[0] * 1e3, st.centroid_m[1] * 1e3],
            "angle_rad": st.angle_rad,
            "milliseconds": ms,
        }));
    }
    let v = serde_json::json!({
        "checkpoint": a.checkpoint.display().to_string(),
        "precision": a.precision,
        "frames": rows,
    });
    if a.json {
        println!("{}", serde_json::to_string_pretty(&v)?);
    } else {
        for r in &rows {
            println!(
                "{}: contact {:.2} mm^2, deepest {:.3} mm",
                r["image"], r["contact_area_mm2"], r["max_depth_mm"]
            );
        }
        println!("files in {}", a.out.display());
    }
    Ok(())
}
