//! Inference throughput of the perception and rendering networks at a given image size.

use super::infer::{PlainUNet, Precision};
use super::{NetConfig, NetKind};
use crate::{Result, TactileError};
use ocm_learn::burn::tensor::{Tensor, TensorData};
use serde::{Deserialize, Serialize};

/// Images per second of one network on the current thread pool.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct NetBench {
    /// Which network.
    pub kind: NetKind,
    /// Which implementation: "burn" (the training graph on burn's CPU backend), "plain"
    /// ([`super::infer::PlainUNet`], what scoring and `ocm tactile perceive` use) or
    /// "plain-bf16" (the same with [`Precision::Bf16`]) or "plain-winograd" (with
    /// [`Precision::Winograd`]); "burn-train-step" and
    /// "plain-train-step" time a training step's forward and backward passes.
    pub engine: String,
    /// Image size (rows, cols).
    pub size: [usize; 2],
    /// Images per forward call.
    pub batch: usize,
    /// Worker threads of the pool it ran on.
    pub threads: usize,
    /// Images per second of each repeat.
    pub images_per_s: Vec<f64>,
    /// Median of `images_per_s`.
    pub median_images_per_s: f64,
    /// For "plain-bf16" and "plain-winograd": the RMS of its outputs' difference from the `f32` engine's, relative
    /// to the RMS of the `f32` outputs' deviation from their mean.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub relative_rms_difference: Option<f64>,
}

/// Deterministic input values in [-1, 1] of `n` elements.
fn input_values(n: usize) -> Vec<f32> {
    (0..n).map(|i| ((i as f32) * 0.618_034).sin()).collect()
}

/// RMS of `y - reference` over the RMS of `reference` about its mean.
pub fn relative_rms_difference(y: &[f32], reference: &[f32]) -> f64 {
    let n = reference.len().max(1) as f64;
    let mean = reference.iter().map(|&v| f64::from(v)).sum::<f64>() / n;
    let spread = reference
        .iter()
        .map(|&v| (f64::from(v) - mean).powi(2))
        .sum::<f64>();
    let diff = y
        .iter()
        .zip(reference)
        .map(|(&a, &b)| (f64::from(a) - f64::from(b)).powi(2))
        .sum::<f64>();
    (diff / spread.max(f64::MIN_POSITIVE)).sqrt()
}

/// Images per second of `repeats` timed calls of `run` on `batch` images, after one untimed
/// warm-up call, and the last call's output.
fn timed<T>(
    repeats: usize,
    batch: usize,
    mut run: impl FnMut() -> Result<T>,
) -> Result<(Vec<f64>, T)> {
    let mut last = run()?;
    let mut ips = Vec::with_capacity(repeats);
    for _ in 0..repeats {
        let t0 = std::time::Instant::now();
        last = std::hint::black_box(run()?);
        ips.push(batch as f64 / t0.elapsed().as_secs_f64());
    }
    Ok((ips, last))
}

/// Times `repeats` forward calls of a batch of `batch` images of `rows` x `cols` through a
/// freshly initialised `kind` network (after one warm-up call), on the current rayon pool,
/// with the plain engine in `f32`, in bfloat16 and in `f32` by Winograd's transforms and,
/// when `with_burn`, burn's graph; when `with_train`, also up to 2 forward and backward passes
/// on burn's autodiff device (engine "burn-train-step", images per second of training without
/// the optimiser step) and `repeats` on the plain engine's training passes
/// ("plain-train-step").
pub fn bench_inference(
    kind: NetKind,
    rows: usize,
    cols: usize,
    batch: usize,
    repeats: usize,
    with_burn: bool,
    with_train: bool,
) -> Result<Vec<NetBench>> {
    if batch == 0 || repeats == 0 {
        return Err(TactileError::Input(
            "a network benchmark needs a batch and repeats".into(),
        ));
    }
    let cfg = match kind {
        NetKind::Perception => NetConfig::perception(rows, cols),
        NetKind::Rendering => NetConfig::rendering(rows, cols),
    };
    let dev = ocm_learn::cpu();
    let net = cfg.init(&dev, 0)?;
    let c = cfg.unet.input;
    let x = input_values(batch * c * rows * cols);
    let threads = rayon::current_num_threads();
    let record = |engine: &str, ips: Vec<f64>| NetBench {
        kind,
        engine: engine.into(),
        size: [rows, cols],
        batch,
        threads,
        median_images_per_s: ocm_mor::run::median(&ips),
        images_per_s: ips,
        relative_rms_difference: None,
    };
    let plain = PlainUNet::new(&net)?;
    let (ips, reference) = timed(repeats, batch, || plain.forward(&x, batch, rows, cols))?;
    let mut out = vec![record("plain", ips)];
    let half = plain.clone().with_precision(Precision::Bf16);
    let (ips, y) = timed(repeats, batch, || half.forward(&x, batch, rows, cols))?;
    out.push(NetBench {
        relative_rms_difference: Some(relative_rms_difference(&y, &reference)),
        ..record("plain-bf16", ips)
    });
    let wino = plain.clone().with_precision(Precision::Winograd);
    let (ips, y) = timed(repeats, batch, || wino.forward(&x, batch, rows, cols))?;
    out.push(NetBench {
        relative_rms_difference: Some(relative_rms_difference(&y, &reference)),
        ..record("plain-winograd", ips)
    });
    let input = || Tensor::<4>::from_data(TensorData::new(x.clone(), [batch, c, rows, cols]), &dev);
    if with_burn {
        let (ips, _) = timed(repeats, batch, || {
            Ok(std::hint::black_box(ocm_learn::values(
                net.forward(input()),
            )))
        })?;
        out.push(record("burn", ips));
    }
    if with_train {
        // A training step's dominant cost: forward and backward through burn's autodiff
        // graph (batch statistics), the optimiser's update excluded.
        let dev = ocm_learn::cpu_autodiff();
        let net = cfg.init(&dev, 0)?;
        let (ips, _) = timed(repeats.min(2), batch, || {
            let t =
                Tensor::<4>::from_data(TensorData::new(x.clone(), [batch, c, rows, cols]), &dev);
            let loss = net.forward(t).powi_scalar(2).mean();
            Ok(std::hint::black_box(loss.backward()))
        })?;
        out.push(record("burn-train-step", ips));
        // The same on the plain engine (`train --engine plain`): the weights copied out of
        // burn, forward with batch statistics, backward, gradients handed back by id.
        let plain_dev = ocm_learn::cpu();
        let (ips, _) = timed(repeats, batch, || {
            let pass = super::backprop::TrainPass::new(&net)?;
            pass.step(&x, batch, rows, cols, &plain_dev, |out| {
                let n = out.len() as f64;
                let loss = out.iter().map(|&v| f64::from(v).powi(2)).sum::<f64>() / n;
                Ok((
                    loss,
                    out.iter()
                        .map(|&v| (2.0 * f64::from(v) / n) as f32)
                        .collect(),
                ))
            })
        })?;
        out.push(record("plain-train-step", ips));
    }
    Ok(out)
}
