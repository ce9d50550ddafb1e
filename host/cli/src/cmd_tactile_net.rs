//! `ocm tactile train perception|rendering` and `ocm tactile perceive`: the U-Net perception and
//! rendering networks on pairs from the tactile FEM data set and the physically based renderer.

use anyhow::Context;
use ocm_learn::{Split, TrainConfig, cpu, cpu_autodiff};
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
    /// Also train on the seen states with the surface mirrored across the image rows, columns
    /// and both, each rendered anew (4 x the training samples; validation and held-out
    /// samples stay unmirrored).
    #[arg(long)]
    pub mirror: bool,
    /// Output folder (checkpoint, loss curve, summary.json, example PNGs).
    #[arg(long, default_value = "out/tactile/nets")]
    pub out: PathBuf,
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
    #[arg(required = true)]
    pub images: Vec<PathBuf>,
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
    let renderer = real::default_renderer(&digit)?;
    let pairs = build_pairs_mirrored(&ds, &gel, &renderer, a.scale, a.mirror)?;
    let t_pairs = t0.elapsed().as_secs_f64();
    let kind = match a.net {
        NetArg::Perception => NetKind::Perception,
        NetArg::Rendering => NetKind::Rendering,
    };
    let mut data = NetData::new(kind, &pairs);
    data.mask_loss_weight = a.mask_loss;
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
    let net = cfg.init(&cpu_autodiff(), a.seed)?;
    let tc = TrainConfig {
        epochs: a.epochs,
        batch_size: a.batch,
        learning_rate: a.lr,
        val_fraction: a.val_fraction,
        patience: a.patience,
        grad_clip_norm: Some(1.0),
        seed: a.seed,
        progress: !a.json,
    };
    let t1 = std::time::Instant::now();
    let report = nets::train(&data, net, &split, &tc, None)?;
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
        "mirror": a.mirror,
        "dataset": a.dataset.display().to_string(),
        "scale": a.scale,
        "train_samples": split.train.len(),
        "val_samples": split.val.len(),
        "best_epoch": report.best_epoch,
        "best_val_loss": report.best_loss,
        "train_seconds": train_s,
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
            let (h, pred) = nets::score_perception(&report.model, &data, &pairs, &held, &dev)?;
            let (v, _) = nets::score_perception(&report.model, &data, &pairs, &split.val, &dev)?;
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
            let (h, frames) = nets::score_rendering(&report.model, &data, &pairs, &held, &dev)?;
            let (v, _) = nets::score_rendering(&report.model, &data, &pairs, &split.val, &dev)?;
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
        "mirror": a.mirror,
        "samples": pairs.len(),
        "train_samples": split.train.len(),
        "val_samples": split.val.len(),
        "held_out_samples": held.len(),
        "held_out_setups": pairs.setup_names.iter().zip(&pairs.setup_unseen).filter(|(_, u)| **u).map(|(n, _)| n.clone()).collect::<Vec<_>>(),
        "pairs_seconds": t_pairs,
        "train_seconds": train_s,
        "epochs_run": report.curve.len(),
        "best_epoch": report.best_epoch,
        "best_val_loss": report.best_loss,
        "first_train_loss": report.curve.first().map(|r| r.train_loss),
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
    let scale = ROWS / cfg.rows;
    let (digit, gel) = digit_gel(a.data.as_deref(), "DIGIT_v8.vtk")?;
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
        let dz = data.predict(&net, &[0], 1, &dev);
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
    let v = serde_json::json!({ "checkpoint": a.checkpoint.display().to_string(), "frames": rows });
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
