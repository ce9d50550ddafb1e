//! Training the engine with the shared loop of `ocm-learn` (loss eq 6.17).

use std::path::PathBuf;

use ocm_learn::burn::module::Module;
use ocm_learn::burn::tensor::activation::log_sigmoid;
use ocm_learn::burn::tensor::{Device, Tensor, TensorData};
use ocm_learn::gcn::Graph;
use ocm_learn::{EpochRecord, LrSchedule, Split, TrainConfig, cpu_autodiff, train_split_sharded};
use ocm_tactile::mask::CONTACT_THRESHOLD_M;
use serde::{Deserialize, Serialize};

use crate::data::{Prepared, SetupSplit, same_surface};
use crate::engine::{Npe, Surface};
use crate::model::{NpeConfig, NpeNet};
use crate::symmetry::{self, Symmetry};
use crate::{NpeError, Result};

/// How to train.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct FitOptions {
    /// Most passes over the training set.
    pub epochs: usize,
    /// Samples per step.
    pub batch_size: usize,
    /// Adam step size.
    pub learning_rate: f64,
    /// Epochs without a validation improvement before stopping.
    pub patience: usize,
    /// Seed of the weights, the split of set-ups and the shuffling.
    pub seed: u64,
    /// Seed of the weights and the shuffling alone, in place of `seed`, so that engines of one
    /// split differ only in their training run (members of an ensemble); `seed` still splits.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub weight_seed: Option<u64>,
    /// Seen set-ups held out for the test.
    pub test_setups: usize,
    /// Seen set-ups held out for validation.
    pub val_setups: usize,
    /// Feed the contact points (false: the ablation without geometry).
    pub use_geometry: bool,
    /// Feed the resultant force (false: the FEM point network, geometry and depth only).
    pub use_force: bool,
    /// Node state width.
    pub width: usize,
    /// GCN layers.
    pub layers: usize,
    /// Weight of the resultant-force term of the loss ([`NpeConfig::lambda_total`]).
    #[serde(default)]
    pub lambda_total: f64,
    /// The contact prior on the readout ([`NpeConfig::contact_prior`]).
    #[serde(default)]
    pub contact_prior: bool,
    /// The contact head ([`NpeConfig::contact_head`]).
    #[serde(default)]
    pub contact_head: bool,
    /// Weight of the contact head's cross-entropy ([`NpeConfig::lambda_contact`]).
    #[serde(default)]
    pub lambda_contact: f64,
    /// The gap input ([`NpeConfig::node_gap`]).
    #[serde(default)]
    pub node_gap: bool,
    /// Fine-tune this trained engine (`npe.ckpt`) instead of starting from random weights:
    /// its architecture and scales are kept (`width`, `layers`, the inputs, the gap input and
    /// the contact prior of these options are ignored), the loss weights and the contact head are these
    /// options'. The split must be the one it was trained with.
    #[serde(default)]
    pub init_from: Option<PathBuf>,
    /// Symmetries of the top face whose images of the training samples are added to the
    /// training set ([`crate::symmetry`]; validation and test stay as measured).
    #[serde(default)]
    pub symmetries: Vec<Symmetry>,
    /// Set-ups of the data that go to training only, outside the seeded split (extra
    /// placements, say): the held-out set-ups stay those of the data without them.
    #[serde(default)]
    pub train_only: Vec<String>,
    /// Threads that share each batch ([`ocm_learn::train_split_sharded`]; 1: the batch on
    /// one thread). The step is the same up to rounding, and the same for the same count.
    #[serde(default = "one")]
    pub threads: usize,
    /// How the step size changes over the run (older `train.json` files: constant).
    #[serde(default)]
    pub lr_schedule: LrSchedule,
    /// Show a progress bar.
    pub progress: bool,
}

impl Default for FitOptions {
    fn default() -> Self {
        FitOptions {
            epochs: 40,
            batch_size: 8,
            learning_rate: 2e-3,
            patience: 10,
            seed: 0,
            weight_seed: None,
            test_setups: 8,
            val_setups: 5,
            use_geometry: true,
            use_force: true,
            width: 32,
            layers: 6,
            lambda_total: 0.0,
            contact_prior: false,
            contact_head: false,
            lambda_contact: 1.0,
            node_gap: false,
            init_from: None,
            symmetries: Vec::new(),
            train_only: Vec::new(),
            threads: 1,
            lr_schedule: LrSchedule::Constant,
            progress: false,
        }
    }
}

fn one() -> usize {
    1
}

/// The outcome of [`fit`].
#[derive(Debug)]
pub struct FitReport {
    /// The trained engine (best validation epoch).
    pub npe: Npe,
    /// Which set-ups went where.
    pub split: SetupSplit,
    /// Losses per epoch.
    pub curve: Vec<EpochRecord>,
    /// Epoch of the returned weights.
    pub best_epoch: usize,
    /// Its validation loss.
    pub best_loss: f64,
    /// Training samples.
    pub train_samples: usize,
    /// Wall time, s.
    pub seconds: f64,
}

/// Mean squared error of the scaled displacement plus `lambda` times that of the scaled nodal
/// force (eq 6.17), over the samples `batch`, plus `lambda_total` times the mean squared error
/// of the summed nodal force in newtons (a per-node error too small for the first two terms
/// adds up over 2,552 nodes to the resultant), plus, with a contact head, `lambda_contact`
/// times the mean binary cross-entropy of its logits against the FEM's contact flags.
pub fn loss(
    net: &NpeNet,
    cfg: &NpeConfig,
    p: &Prepared,
    batch: &[usize],
    positions: &Tensor<3>,
    graph: &ocm_learn::gcn::GraphTensors,
    device: &Device,
) -> Tensor<1> {
    let x = p.inputs(cfg, batch);
    let (out, logits, _) = net.forward_full(cfg, &x, positions, graph, device);
    let n = p.rest_m.len();
    let b = batch.len();
    let mut t = Vec::with_capacity(b * n * 6);
    for &i in batch {
        t.extend_from_slice(&p.samples[i].target);
    }
    let target = Tensor::<3>::from_data(TensorData::new(t, [b, n, 6]), device).swap_dims(0, 1);
    let d = out - target;
    let sq = d.clone() * d.clone();
    let mu = sq.clone().slice([0..n, 0..b, 0..3]).mean();
    let mf = sq.slice([0..n, 0..b, 3..6]).mean();
    let mut loss = mu + mf * cfg.lambda;
    if cfg.lambda_total > 0.0 {
        let total = d.slice([0..n, 0..b, 3..6]).sum_dim(0) * cfg.scales.nodal_force_n;
        loss = loss + (total.clone() * total).mean() * cfg.lambda_total;
    }
    match logits {
        Some(z) if cfg.lambda_contact > 0.0 => {
            let y = contact_flags(p, batch, cfg.scales.displacement_m);
            let y = Tensor::<3>::from_data(TensorData::new(y, [b, n, 1]), device).swap_dims(0, 1);
            loss + bce_with_logits(z, y) * cfg.lambda_contact
        }
        _ => loss,
    }
}

/// The FEM's contact flag of every node of samples `batch` (1 where -u_z > 30 um, the
/// threshold of the contact-node metric), sample after sample; `displacement_m` is the
/// targets' displacement unit.
pub fn contact_flags(p: &Prepared, batch: &[usize], displacement_m: f64) -> Vec<f32> {
    let t = (-CONTACT_THRESHOLD_M / displacement_m) as f32;
    batch
        .iter()
        .flat_map(|&i| p.samples[i].target.chunks(6).map(|r| f32::from(r[2] < t)))
        .collect()
}

/// Mean binary cross-entropy of logits `z` against 0/1 targets `y` (in the log-sigmoid form,
/// finite for any logit).
pub fn bce_with_logits<const D: usize>(z: Tensor<D>, y: Tensor<D>) -> Tensor<1> {
    let pos = log_sigmoid(z.clone());
    let neg = log_sigmoid(z.neg());
    let ones = y.ones_like();
    (y.clone() * pos + (ones - y) * neg).mean().neg()
}

/// The engine at `path` for fine-tuning, after checking it was trained on `split`'s held-out
/// set-ups and on no set-up `split` does not train on: another split would put its training
/// set-ups into the held-out ones. `split` may train on more set-ups.
fn start_from(path: &std::path::Path, split: &SetupSplit) -> Result<Npe> {
    let npe = Npe::load(path)?;
    let stored: SetupSplit = serde_json::from_value(Npe::run_meta(path)?["split"].clone())
        .map_err(|e| NpeError::Data(format!("{}: no set-up split stored: {e}", path.display())))?;
    let same_held_out =
        (&stored.test, &stored.val, &stored.unseen) == (&split.test, &split.val, &split.unseen);
    if !same_held_out || stored.train.iter().any(|s| !split.train.contains(s)) {
        return Err(NpeError::Input(format!(
            "{} was trained on another split of set-ups (test {:?}, validation {:?}); \
             fine-tune with the seed and held-out counts it was trained with",
            path.display(),
            stored.test,
            stored.val
        )));
    }
    Ok(npe)
}

/// Trains an engine on `p` split by set-up.
pub fn fit(p: &Prepared, opts: &FitOptions) -> Result<FitReport> {
    let run_seed = opts.weight_seed.unwrap_or(opts.seed);
    let split = SetupSplit::with_train_only(
        p,
        opts.test_setups,
        opts.val_setups,
        opts.seed,
        &opts.train_only,
    )?;
    let mut idx = Split {
        train: p.samples_of(&split.train),
        val: p.samples_of(&split.val),
    };
    if idx.train.is_empty() {
        return Err(NpeError::Data("no training samples".into()));
    }
    let with_images;
    let p = if opts.symmetries.is_empty() {
        p
    } else {
        let (q, added) = symmetry::augmented(p, &idx.train, &opts.symmetries)?;
        idx.train.extend(added);
        with_images = q;
        &with_images
    };
    let start = match &opts.init_from {
        Some(path) => Some(start_from(path, &split)?),
        None => None,
    };
    let mut cfg = match &start {
        Some(npe) => npe.config.clone(),
        None => {
            let mut cfg = NpeConfig::new(Prepared::top_center(&p.rest_m), p.spacing_m);
            cfg.use_geometry = opts.use_geometry;
            cfg.use_force = opts.use_force;
            cfg.width = opts.width;
            cfg.layers = opts.layers;
            cfg.contact_prior = opts.contact_prior;
            cfg.node_gap = opts.node_gap;
            cfg
        }
    };
    cfg.lambda_total = opts.lambda_total;
    cfg.contact_head = opts.contact_head || cfg.contact_head;
    cfg.lambda_contact = if cfg.contact_head {
        opts.lambda_contact
    } else {
        0.0
    };
    if !(cfg.lambda_contact.is_finite() && cfg.lambda_contact >= 0.0) {
        return Err(NpeError::Input(format!(
            "contact loss weight {} must be finite and not negative",
            cfg.lambda_contact
        )));
    }
    let surface = Surface {
        rest_m: p.rest_m.clone(),
        edges: p.edges.clone(),
    };
    let ad = cpu_autodiff();
    let plain = ad.clone().inner();
    let graph = Graph::from_edges(p.rest_m.len(), &p.edges)?;
    let pos: Vec<f32> = p.rest_m.iter().flat_map(|q| cfg.scales.point(q)).collect();
    let n = p.rest_m.len();
    let pos_ad = Tensor::<3>::from_data(TensorData::new(pos.clone(), [n, 1, 3]), &ad);
    let pos_plain = Tensor::<3>::from_data(TensorData::new(pos, [n, 1, 3]), &plain);
    let (g_ad, g_plain) = (graph.tensors(&ad), graph.tensors(&plain));
    let net = match start {
        Some(npe) => {
            if !same_surface(
                (&npe.surface.rest_m, &npe.surface.edges),
                (&p.rest_m, &p.edges),
            ) {
                return Err(NpeError::Data(
                    "the engine to fine-tune was trained on another top surface".into(),
                ));
            }
            // A net built on the autodiff device takes the trained weights, so the optimiser
            // tracks them (the loaded engine lives on the plain device).
            let net = npe
                .config
                .init(&ad, run_seed)?
                .load_record(npe.net().clone().into_record());
            match (net.contact.is_some(), cfg.contact_head) {
                (false, true) => net.with_contact_head(Some(cfg.contact_head_init(&ad, run_seed))),
                _ => net,
            }
        }
        None => cfg.init(&ad, run_seed)?,
    };
    let t0 = std::time::Instant::now();
    let report = train_split_sharded(
        net,
        &idx,
        &TrainConfig {
            epochs: opts.epochs,
            batch_size: opts.batch_size,
            learning_rate: opts.learning_rate,
            val_fraction: 0.0,
            patience: opts.patience,
            grad_clip_norm: Some(10.0),
            seed: run_seed,
            progress: opts.progress,
            lr_schedule: opts.lr_schedule,
        },
        opts.threads,
        |m, batch, device| {
            if device.is_autodiff() {
                loss(m, &cfg, p, batch, &pos_ad, &g_ad, device)
            } else {
                loss(m, &cfg, p, batch, &pos_plain, &g_plain, device)
            }
        },
    )?;
    Ok(FitReport {
        npe: Npe::new(report.model, cfg, surface)?,
        split,
        curve: report.curve,
        best_epoch: report.best_epoch,
        best_loss: report.best_loss,
        train_samples: idx.train.len(),
        seconds: t0.elapsed().as_secs_f64(),
    })
}
