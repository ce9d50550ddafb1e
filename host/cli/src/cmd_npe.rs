//! `ocm npe`: train, evaluate and time the neural physics engine of the DIGIT gel.

use crate::plot::{Chart, Series};
use anyhow::Context;
use ocm_learn::LrSchedule;
use ocm_npe::data::{Prepared, SetupSplit};
use ocm_npe::eval::{Extra, SampleScore, Scores, evaluate_with, fit_stiffness};
use ocm_npe::fit::{FitOptions, fit};
use ocm_npe::{Npe, figure};
use ocm_tactile::dataset::{Dataset, TopSurface};
use ocm_tactile::gel::{Gel, GelMaterial};
use std::path::{Path, PathBuf};

/// NPE subcommands.
#[derive(clap::Subcommand, Debug)]
pub enum NpeCommand {
    /// Trains the engine on a dataset of `ocm tactile dataset`, split by set-up (held-out seen
    /// set-ups and the unseen indenters are never trained on); writes npe.ckpt, the loss curve
    /// (CSV, PNG) and the split.
    Train {
        /// Dataset folder.
        #[arg(long, default_value = "out/npe/dataset")]
        dataset: PathBuf,
        /// Output folder.
        #[arg(long, default_value = "out/npe/model")]
        out: PathBuf,
        /// Most epochs.
        #[arg(long, default_value_t = 40)]
        epochs: usize,
        /// Samples per step.
        #[arg(long, default_value_t = 8)]
        batch: usize,
        /// Adam step size.
        #[arg(long, default_value_t = 2e-3)]
        lr: f64,
        /// Lower the step size along half a cosine, step by step, from --lr down to this
        /// fraction of it at the end of the last planned epoch (absent: --lr throughout).
        #[arg(long, value_parser = crate::arg_check::fraction)]
        lr_final: Option<f64>,
        /// Early-stopping patience, epochs.
        #[arg(long, default_value_t = 10)]
        patience: usize,
        /// Node state width.
        #[arg(long, default_value_t = 32)]
        width: usize,
        /// GCN layers.
        #[arg(long, default_value_t = 6)]
        layers: usize,
        /// Seed of weights, split and shuffling.
        #[arg(long, default_value_t = 0)]
        seed: u64,
        /// Seed of the weights and the shuffling only (--seed still splits): engines of one
        /// split that differ in their training run, e.g. members of an ensemble for `eval
        /// --ensemble`.
        #[arg(long)]
        weight_seed: Option<u64>,
        /// Seen set-ups held out for the test.
        #[arg(long, default_value_t = 8)]
        test_setups: usize,
        /// Seen set-ups held out for validation (early stopping).
        #[arg(long, default_value_t = 5)]
        val_setups: usize,
        /// Weight of the resultant term of the loss: squared error of the summed nodal force,
        /// N^2 (0: eq 6.17 alone).
        #[arg(long, value_parser = crate::arg_check::non_negative, default_value_t = 0.0)]
        lambda_total: f64,
        /// Contact prior on the readout: nodal force only at penetrated nodes and their
        /// neighbours, vertical displacement as a correction to minus the penetration.
        #[arg(long)]
        contact_prior: bool,
        /// A contact head beside the readout: a per-node classifier of the FEM's contact state
        /// (-u_z > 30 um), trained with a cross-entropy; `eval` then reads the contact nodes
        /// from it.
        #[arg(long)]
        contact_head: bool,
        /// Weight of the contact head's cross-entropy.
        #[arg(long, default_value_t = 1.0)]
        lambda_contact: f64,
        /// The gap input: each node's initial state also gets the x-y distance to the nearest
        /// contact point (within 1 mm) and that point's height above the node.
        #[arg(long)]
        node_gap: bool,
        /// Fine-tune this checkpoint of `ocm npe train` (same split: same --seed, --test-setups,
        /// --val-setups and dataset) instead of starting from random weights; its architecture
        /// is kept, the loss weights and the contact head are these options'.
        #[arg(long)]
        init_from: Option<PathBuf>,
        /// Add the training samples turned half a turn about the top face's centre and/or
        /// mirrored across its centre lines (comma-separated: rot180, mirror-x, mirror-y);
        /// validation and test samples stay as measured.
        #[arg(long, value_delimiter = ',')]
        symmetries: Vec<ocm_npe::symmetry::Symmetry>,
        /// More data sets of `ocm tactile dataset` on the same gel (comma-separated folders,
        /// e.g. random placements of the seen indenters) whose set-ups all go to training: the
        /// split of --dataset's set-ups stays what it is without them. --symmetries applies to
        /// their samples too.
        #[arg(long, value_delimiter = ',')]
        extra_train: Vec<PathBuf>,
        /// Threads that share each batch: its samples are split between them and their
        /// gradients summed, so the step is the whole batch's up to rounding (1 repeats a
        /// single-thread run bit for bit; runs with the same count repeat each other).
        #[arg(long, default_value_t = 2, value_parser = clap::value_parser!(u32).range(1..=64))]
        threads: u32,
        /// Leave the contact points out (the ablation without geometry).
        #[arg(long)]
        no_geometry: bool,
        /// Leave the force out (the FEM point network: geometry and depth only).
        #[arg(long)]
        no_force: bool,
        /// Print a JSON summary.
        #[arg(long)]
        json: bool,
    },
    /// Scores a trained engine against the FEM (Table 6.1) on the held-out seen set-ups and the
    /// unseen indenters, separately; writes scores.json, per-sample CSVs, plots and field
    /// images (FEM | NPE | |difference|).
    Eval {
        /// Checkpoint of `ocm npe train`.
        #[arg(long, default_value = "out/npe/model/npe.ckpt")]
        model: PathBuf,
        /// Dataset folder.
        #[arg(long, default_value = "out/npe/dataset")]
        dataset: PathBuf,
        /// Data directory (default: OCM_DATA_DIR, else ../shared/data), for the gel mesh.
        #[arg(long)]
        data: Option<PathBuf>,
        /// Output folder (default: beside the checkpoint, eval/).
        #[arg(long)]
        out: Option<PathBuf>,
        /// Field images per group.
        #[arg(long, default_value_t = 4)]
        images: usize,
        /// Test-time symmetrisation: also run the engine on each sample turned and/or mirrored
        /// (comma-separated: rot180, mirror-x, mirror-y) and average the outputs mapped back
        /// (one more engine call per map).
        #[arg(long, value_delimiter = ',')]
        symmetrise: Vec<ocm_npe::symmetry::Symmetry>,
        /// More checkpoints of the same split (comma-separated; e.g. `train --weight-seed`
        /// runs) whose outputs are averaged with --model's: an ensemble.
        #[arg(long, value_delimiter = ',')]
        ensemble: Vec<PathBuf>,
        /// Print JSON.
        #[arg(long)]
        json: bool,
    },
    /// Median latency of one engine call on one sample of the held-out set (the one with the
    /// most contact points), with the CPU backend on `--threads` threads.
    Bench {
        /// Checkpoint of `ocm npe train`.
        #[arg(long, default_value = "out/npe/model/npe.ckpt")]
        model: PathBuf,
        /// Dataset folder.
        #[arg(long, default_value = "out/npe/dataset")]
        dataset: PathBuf,
        /// Timed calls.
        #[arg(long, value_parser = crate::arg_check::count, default_value_t = 200)]
        calls: usize,
        /// Worker threads.
        #[arg(long, value_parser = crate::arg_check::count, default_value_t = 1)]
        threads: usize,
        /// Print JSON.
        #[arg(long)]
        json: bool,
    },
}

/// Polynomial degree of the force-from-displacement functional `eval` fits: 0 (one weight
/// per term over the whole face) scored best on the validation set-ups of data set v2.
const STIFFNESS_DEGREE: usize = 0;

fn write_json(path: &Path, v: &serde_json::Value) -> anyhow::Result<()> {
    std::fs::write(path, serde_json::to_string_pretty(v)?)
        .with_context(|| format!("writing {}", path.display()))
}

fn split_of(model: &Path) -> anyhow::Result<SetupSplit> {
    let meta = Npe::run_meta(model)?;
    serde_json::from_value(meta["split"].clone())
        .with_context(|| format!("{}: no set-up split stored", model.display()))
}

/// A trained engine, the set-up split it was trained with, and the data set prepared in
/// its scales: what `eval` and `bench` both start from.
fn load_with_data(
    model: &Path,
    dataset: &Path,
) -> anyhow::Result<(Npe, SetupSplit, Dataset, Prepared)> {
    let npe = Npe::load(model)?;
    let split = split_of(model)?;
    let ds = Dataset::read(dataset)?;
    let p = Prepared::from_dataset(&ds, &npe.config.scales);
    Ok((npe, split, ds, p))
}

fn write_scores_csv(path: &Path, per: &[SampleScore]) -> anyhow::Result<()> {
    let mut s = String::from(
        "setup,depth_mm,contact_accuracy,rmse_mm,orientation_deg,force_pred_n,force_fem_n,force_off_contact_n,elongation_fem,elongation_pred,mask_px_fem,mask_px_pred\n",
    );
    for r in per {
        s.push_str(&format!(
            "{},{:.3},{:.5},{:.5},{},{:.5},{:.5},{:.5},{},{},{},{}\n",
            r.setup,
            r.depth_mm,
            r.contact_accuracy,
            r.rmse_mm,
            r.orientation_deg
                .map_or(String::new(), |v| format!("{v:.4}")),
            r.force_pred_n,
            r.force_fem_n,
            r.force_off_contact_n,
            r.elongation_fem
                .map_or(String::new(), |v| format!("{v:.4}")),
            r.elongation_pred
                .map_or(String::new(), |v| format!("{v:.4}")),
            r.mask_pixels[0],
            r.mask_pixels[1]
        ));
    }
    std::fs::write(path, s).with_context(|| format!("writing {}", path.display()))
}

fn line(name: &str, s: &Scores) -> String {
    format!(
        "{name:<14} {:>4} samples | contact nodes {:.2} % | RMSE {:.4} +- {:.4} mm (pooled {:.4}) | orientation {:.2} +- {:.2} deg ({} elongated) | force RMSE {:.4} N (off-contact nodes {:.4} N rms)",
        s.samples,
        s.contact_accuracy_pct,
        s.rmse_mm[0],
        s.rmse_mm[1],
        s.rmse_pooled_mm,
        s.orientation_deg[0],
        s.orientation_deg[1],
        s.orientation_samples,
        s.force_rmse_n,
        s.force_off_contact_rms_n
    ) + &format!(
        "\n{:<14} force: {:.1} % of the FEM force's rms, median |error| {:.1} %, mean FEM force {:.2} N; nodal force RMSE {:.4} N per node ({:.4} N on FEM contact nodes); from the predicted displacement {:.4} N (the functional on the FEM displacement {:.4} N)\n{:<14} contact nodes: {} wrong of {} FEM contact ({} false positive, {} false negative; {} within 10 um of the threshold, {} penetrated, {} on the rim); penetration > 30 um alone: {:.2} %",
        "",
        s.force_rmse_relative_pct,
        s.force_median_relative_pct,
        s.force_fem_mean_n,
        s.nodal_force_rmse_n,
        s.nodal_force_rmse_contact_n,
        s.force_from_u_rmse_n.unwrap_or(f64::NAN),
        s.force_from_fem_u_rmse_n.unwrap_or(f64::NAN),
        "",
        s.contact.false_pos + s.contact.false_neg,
        s.contact.fem_contact,
        s.contact.false_pos,
        s.contact.false_neg,
        s.contact.wrong_near_threshold,
        s.contact.wrong_penetrated,
        s.contact.wrong_rim,
        s.penetration_rule_accuracy_pct
    )
}

/// Runs an `ocm npe` subcommand.
pub fn run(cmd: NpeCommand) -> anyhow::Result<()> {
    match cmd {
        NpeCommand::Train {
            dataset,
            out,
            epochs,
            batch,
            lr,
            lr_final,
            patience,
            width,
            layers,
            seed,
            weight_seed,
            test_setups,
            val_setups,
            lambda_total,
            contact_prior,
            contact_head,
            lambda_contact,
            node_gap,
            init_from,
            symmetries,
            extra_train,
            threads,
            no_geometry,
            no_force,
            json,
        } => {
            let scales = ocm_npe::model::NpeConfig::new([0.0; 3], 1e-3).scales;
            let ds = Dataset::read(&dataset)?;
            let mut p = Prepared::from_dataset(&ds, &scales);
            drop(ds);
            let mut train_only = Vec::new();
            for dir in &extra_train {
                // An unseen indenter's set-up among them is refused by the split.
                let extra = Prepared::from_dataset(&Dataset::read(dir)?, &scales);
                train_only.extend(extra.setup_names.iter().cloned());
                p.append(extra)
                    .with_context(|| format!("--extra-train {}", dir.display()))?;
            }
            let opts = FitOptions {
                epochs,
                batch_size: batch,
                learning_rate: lr,
                patience,
                seed,
                weight_seed,
                use_geometry: !no_geometry,
                use_force: !no_force,
                width,
                layers,
                lambda_total,
                contact_prior,
                contact_head,
                lambda_contact,
                node_gap,
                init_from,
                symmetries,
                train_only,
                threads: threads as usize,
                lr_schedule: LrSchedule::cosine_to(lr_final),
                test_setups,
                val_setups,
                progress: !json,
            };
            let r = fit(&p, &opts)?;
            std::fs::create_dir_all(&out).with_context(|| format!("creating {}", out.display()))?;
            let ckpt = out.join("npe.ckpt");
            let meta = serde_json::json!({
                "split": r.split,
                "options": opts,
                "config": r.npe.config,
                "dataset": dataset.display().to_string(),
                "extra_train": extra_train.iter().map(|d| d.display().to_string()).collect::<Vec<_>>(),
                "train_samples": r.train_samples,
                "best_epoch": r.best_epoch,
                "best_val_loss": r.best_loss,
                "seconds": r.seconds,
            });
            r.npe.save(&ckpt, meta.clone())?;
            ocm_learn::write_curve(&out, "loss", "NPE loss (eq 6.17, scaled units)", &r.curve)?;
            write_json(&out.join("train.json"), &meta)?;
            if json {
                println!("{}", serde_json::to_string_pretty(&meta)?);
            } else {
                println!(
                    "trained on {} samples of {} set-ups in {:.0} s; best epoch {} (validation loss {:.4e}); {}",
                    r.train_samples,
                    r.split.train.len(),
                    r.seconds,
                    r.best_epoch,
                    r.best_loss,
                    ckpt.display()
                );
            }
            Ok(())
        }
        NpeCommand::Eval {
            model,
            dataset,
            data,
            out,
            images,
            symmetrise,
            ensemble,
            json,
        } => {
            let (npe, split, ds, p) = load_with_data(&model, &dataset)?;
            let mut members = Vec::new();
            for path in &ensemble {
                // A member of another split has trained on this one's held-out set-ups.
                let theirs =
                    split_of(path).with_context(|| format!("--ensemble {}", path.display()))?;
                anyhow::ensure!(
                    theirs == split,
                    "--ensemble {}: trained on another split than --model {} (same --seed, \
                     --test-setups, --val-setups and dataset needed)",
                    path.display(),
                    model.display()
                );
                members.push(
                    Npe::load(path).with_context(|| format!("--ensemble {}", path.display()))?,
                );
            }
            let digit = ocm_datadir::data_file(data.as_deref(), "digit")?;
            let gel = Gel::digit(
                digit.join(&ds.manifest.mesh),
                GelMaterial::new(ds.manifest.material[0], ds.manifest.material[1]),
            )?;
            let top = TopSurface::from_gel(&gel);
            anyhow::ensure!(
                top.nodes.len() == npe.surface.rest_m.len(),
                "the mesh has {} top nodes, the engine {}",
                top.nodes.len(),
                npe.surface.rest_m.len()
            );
            let out = out.unwrap_or_else(|| model.parent().unwrap_or(Path::new(".")).join("eval"));
            std::fs::create_dir_all(&out).with_context(|| format!("creating {}", out.display()))?;
            let mut summary = serde_json::Map::new();
            let mut text = Vec::new();
            // Table 6.1 reads the total force from the predicted deformation: the stiffness
            // functional is fitted on the training set-ups' FEM fields only.
            let stiffness = fit_stiffness(
                &p,
                &p.samples_of(&split.train),
                STIFFNESS_DEGREE,
                npe.config.scales.displacement_m,
            )?;
            for (name, setups) in [("held-out seen", &split.test), ("unseen", &split.unseen)] {
                let idx = p.samples_of(setups);
                if idx.is_empty() {
                    text.push(format!("{name}: no samples"));
                    continue;
                }
                let (scores, per) = evaluate_with(
                    &npe,
                    &p,
                    &idx,
                    &gel,
                    &top,
                    8,
                    &Extra {
                        stiffness: Some(&stiffness),
                        thresholds_m: &[],
                        symmetrise: &symmetrise,
                        ensemble: &members,
                    },
                )?;
                let stem = name.replace([' ', '-'], "_");
                write_scores_csv(&out.join(format!("{stem}.csv")), &per)?;
                Chart {
                    title: &format!("NPE vs FEM total force, {name} set-ups"),
                    x_label: "FEM force F_z [N]",
                    y_label: "NPE force F_z [N]",
                    series: vec![Series {
                        label: "samples".into(),
                        points: per
                            .iter()
                            .map(|s| (s.force_fem_n, s.force_pred_n))
                            .collect(),
                        dots: true,
                    }],
                    equal_axes: true,
                }
                .write(&out, &format!("{stem}_force"))?;
                Chart {
                    title: &format!("NPE displacement RMSE against depth, {name} set-ups"),
                    x_label: "depth [mm]",
                    y_label: "nodal displacement RMSE [mm]",
                    series: vec![Series {
                        label: "samples".into(),
                        points: per.iter().map(|s| (s.depth_mm, s.rmse_mm)).collect(),
                        dots: true,
                    }],
                    equal_axes: false,
                }
                .write(&out, &format!("{stem}_rmse"))?;
                // Images of the deepest sample of the first few set-ups.
                for setup in setups.iter().take(images) {
                    let Some(&i) = idx
                        .iter()
                        .filter(|&&i| &p.setup_names[p.samples[i].setup] == setup)
                        .max_by(|&&a, &&b| p.samples[a].depth_m.total_cmp(&p.samples[b].depth_m))
                    else {
                        continue;
                    };
                    let s = &p.samples[i];
                    let pred = npe.predict(&s.points_m, s.force_n[2], s.depth_m)?;
                    let sc = npe.config.scales.displacement_m;
                    let fem: Vec<[f64; 3]> = s
                        .target
                        .chunks(6)
                        .map(|r| [0, 1, 2].map(|k| f64::from(r[k]) * sc))
                        .collect();
                    figure::write_comparison(
                        &out.join(format!("field_{setup}.png")),
                        &gel,
                        &top,
                        &fem,
                        &pred.displacement_m,
                    )?;
                }
                text.push(line(name, &scores));
                summary.insert(name.to_string(), serde_json::to_value(&scores)?);
            }
            summary.insert("model".into(), model.display().to_string().into());
            summary.insert("symmetrise".into(), serde_json::to_value(&symmetrise)?);
            summary.insert("ensemble".into(), serde_json::to_value(&ensemble)?);
            summary.insert("split".into(), serde_json::to_value(&split)?);
            let summary = serde_json::Value::Object(summary);
            write_json(&out.join("scores.json"), &summary)?;
            if json {
                println!("{}", serde_json::to_string_pretty(&summary)?);
            } else {
                for t in text {
                    println!("{t}");
                }
                println!("files in {}", out.display());
            }
            Ok(())
        }
        NpeCommand::Bench {
            model,
            dataset,
            calls,
            threads,
            json,
        } => {
            let (npe, split, _, p) = load_with_data(&model, &dataset)?;
            let idx = p.samples_of(&split.test);
            let &i = idx
                .iter()
                .max_by_key(|&&i| p.samples[i].points_m.len())
                .context("no held-out sample to time")?;
            let s = &p.samples[i];
            let lat = ocm_npe::bench::latency(
                &npe,
                &s.points_m,
                s.force_n[2],
                s.depth_m,
                10,
                calls,
                threads,
            )?;
            let v = serde_json::json!({
                "latency": lat,
                "threads": threads,
                "setup": p.setup_names[s.setup],
                "depth_mm": s.depth_m * 1e3,
                "nodes": npe.surface.rest_m.len(),
            });
            if json {
                println!("{}", serde_json::to_string_pretty(&v)?);
            } else {
                println!(
                    "NPE call ({} nodes, {} points, {} thread(s)): median {:.3} ms, p10 {:.3} ms, p90 {:.3} ms over {} calls",
                    npe.surface.rest_m.len(),
                    lat.points,
                    threads,
                    lat.median_ms,
                    lat.p10_p90_ms[0],
                    lat.p10_p90_ms[1],
                    lat.calls
                );
            }
            Ok(())
        }
    }
}
