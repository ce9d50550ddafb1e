//! The perception network f_theta (image -> surface displacement, eq 5.9-5.15) and the rendering
//! network f_theta+ (splatted displacement -> image, eq 5.16-5.22), both U-Nets from
//! `ocm-learn`, trained on pairs from the tactile FEM and the physically based renderer
//! ([`pairs`]).

pub mod backprop;
pub mod bench;
pub mod bf16;
pub mod force;
pub mod infer;
mod map;
pub mod pairs;
pub mod plain_loss;
pub mod real_frames;
mod winograd;

use crate::mask::{Grid, Mask, mask_from_fn};
use crate::metrics;
use crate::optics::RgbImage;
use crate::real::{score_ssim, score_ssim_in};
use crate::{Result, TactileError};
use ocm_learn::burn::tensor::{Device, Tensor, TensorData, activation};
use ocm_learn::mlp::Activation;
use ocm_learn::{Split, TrainConfig, TrainReport, UNet, UNetConfig, UNetNorm, values};
use pairs::{Pairs, frame_from_delta};
use serde::{Deserialize, Serialize};

/// Most negative u_z of the displacement normalisation (eq 5.15's dz_min), m.
pub const DZ_MIN_M: f64 = -8.0e-4;
/// Least negative u_z of the normalisation (dz_max), m.
pub const DZ_MAX_M: f64 = -3.0e-5;
/// Grey levels per unit of the perception network's input (delta images are within about
/// +-60 grey levels).
pub const DELTA_SCALE: f32 = 32.0;
/// Indentation (-u_z) above which a pixel is in contact, m (the FEM masks' threshold).
pub const CONTACT_DZ_M: f64 = 30e-6;
/// Clip scale of the rendering network's displacement input (eq 5.17), m.
pub const DZ_SCALE_M: f64 = 1e-3;
/// Fourier frequencies of the positional encoding (eq 5.18).
pub const FOURIER_FREQS: usize = 4;
/// Width of the soft contact threshold of the perception network's mask loss, in normalised
/// dz units (0.02 is 15 um): the contact logit is (1 - dz_norm) / this, 0 at the 30 um mask
/// threshold (which sits exactly at dz_norm = 1, dz_max being -30 um).
pub const MASK_LOGIT_WIDTH: f32 = 0.02;

/// Pixels added to the intersection and the union of the soft contact IoU term, so a sample
/// without contact whose prediction has none scores 1 and the ratio stays finite.
pub const SOFT_IOU_EPS: f32 = 1.0;

/// u_z (m) -> the perception network's target: 0 at dz_min, 1 at dz_max (no clipping, so an
/// undeformed pixel sits slightly above 1).
pub fn dz_to_target(dz_m: f64) -> f64 {
    (dz_m - DZ_MIN_M) / (DZ_MAX_M - DZ_MIN_M)
}

/// The inverse of [`dz_to_target`], m.
pub fn target_to_dz(t: f64) -> f64 {
    DZ_MIN_M + t * (DZ_MAX_M - DZ_MIN_M)
}

/// Which network.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub enum NetKind {
    /// Image -> displacement (f_theta).
    Perception,
    /// Displacement -> image (f_theta+).
    Rendering,
}

impl NetKind {
    /// Checkpoint architecture name.
    pub fn architecture(self) -> &'static str {
        match self {
            NetKind::Perception => "tactile.perception",
            NetKind::Rendering => "tactile.rendering",
        }
    }
}

/// A network and the image size it works on.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct NetConfig {
    /// Which network.
    pub kind: NetKind,
    /// The U-Net.
    pub unet: UNetConfig,
    /// Image rows.
    pub rows: usize,
    /// Image columns.
    pub cols: usize,
}

impl NetConfig {
    /// f_theta as in eq 5.9-5.14: 3 levels of 32 / 64 / 128 channels, batch norm and ReLU,
    /// 3 input channels (the delta image), 3 outputs [p_x, p_y, dz].
    pub fn perception(rows: usize, cols: usize) -> Self {
        NetConfig {
            kind: NetKind::Perception,
            unet: UNetConfig {
                input: 3,
                output: 3,
                widths: vec![32, 64, 128],
                norm: UNetNorm::Batch,
                activation: Activation::Relu,
            },
            rows,
            cols,
        }
    }

    /// f_theta+: two encoder stages and a bottleneck (16 / 32 / 64 channels; the dissertation
    /// gives no widths), group norm (8 groups) and GELU; inputs dz, x, y and 4 Fourier
    /// frequencies of x and y (19 channels); 3 outputs through tanh.
    pub fn rendering(rows: usize, cols: usize) -> Self {
        NetConfig {
            kind: NetKind::Rendering,
            unet: UNetConfig {
                input: 3 + 4 * FOURIER_FREQS,
                output: 3,
                widths: vec![16, 32, 64],
                norm: UNetNorm::Group(8),
                activation: Activation::Gelu,
            },
            rows,
            cols,
        }
    }

    /// Builds the network with weights from `seed`; an error if the image size does not fit.
    pub fn init(&self, device: &Device, seed: u64) -> Result<UNet> {
        let net = self.unet.init(device, seed)?;
        net.check_input(self.unet.input, self.rows, self.cols)?;
        Ok(net)
    }
}

/// The rendering network's coordinate channels at every pixel, `[2 + 4 F, rows, cols]`: x and y
/// in [0, 1] (pixel centres), then for x and y and k = 1..F, sin(2 pi k p) and cos(2 pi k p).
pub fn coordinate_channels(rows: usize, cols: usize) -> Vec<f32> {
    let n = rows * cols;
    let mut v = vec![0.0f32; (2 + 4 * FOURIER_FREQS) * n];
    for r in 0..rows {
        for c in 0..cols {
            let p = [
                (c as f64 + 0.5) / cols as f64,
                (r as f64 + 0.5) / rows as f64,
            ];
            let i = r * cols + c;
            v[i] = p[0] as f32;
            v[n + i] = p[1] as f32;
            let mut ch = 2;
            for q in p {
                for k in 1..=FOURIER_FREQS {
                    let a = 2.0 * std::f64::consts::PI * k as f64 * q;
                    v[ch * n + i] = a.sin() as f32;
                    v[(ch + 1) * n + i] = a.cos() as f32;
                    ch += 2;
                }
            }
        }
    }
    v
}

/// The inputs and targets of one network, flattened per sample.
#[derive(Debug, Clone)]
pub struct NetData {
    /// Which network.
    pub kind: NetKind,
    /// Image rows.
    pub rows: usize,
    /// Image columns.
    pub cols: usize,
    /// Input channels per sample (coordinates excluded for the rendering network).
    pub input: Vec<f32>,
    /// Input channels stored per sample.
    pub input_channels: usize,
    /// Target per sample: the normalised dz `[1, rows, cols]` (perception) or delta / 255
    /// `[3, rows, cols]` (rendering).
    pub target: Vec<f32>,
    /// Target channels.
    pub target_channels: usize,
    /// Contact mask per sample `[rows, cols]`: from the splatted dz (rendering loss, eq 5.20),
    /// from the rasterised dz (perception's mask loss).
    pub mask: Vec<f32>,
    /// Weight of the perception network's contact-mask term (binary cross-entropy of the soft
    /// threshold, see [`MASK_LOGIT_WIDTH`]) beside eq 5.15's MSE; 0 is eq 5.15 alone.
    pub mask_loss_weight: f32,
    /// Weight of the perception network's soft contact IoU term (1 - soft IoU per sample, the
    /// soft mask being the sigmoid of the same logit as the mask term, averaged over samples);
    /// 0 leaves it out. Unlike the pixel-averaged terms it weighs a small contact like a large one.
    pub iou_loss_weight: f32,
    /// Weight of the perception network's surface-force term, 1/N^2 (set with
    /// [`NetData::set_force_loss`]): the mean over samples of the squared force of the depth
    /// error, (sum W (dz_pred - dz_true))^2 in N^2, W the target's pixel weights; 0 leaves it out.
    force_loss_weight: f32,
    /// Per sample `[rows, cols]`, N/m: the linear surface force of a field with the target's
    /// contact patch is -sum W u_z ([`force::LinearForceMap::pixel_weights`]); empty unless the
    /// force term is used.
    force_weight: Vec<f32>,
    coords: Vec<f32>,
}

impl NetData {
    /// The inputs and targets of `kind` from rendered pairs.
    pub fn new(kind: NetKind, p: &Pairs) -> Self {
        match kind {
            NetKind::Perception => NetData {
                kind,
                rows: p.rows,
                cols: p.cols,
                input: p.delta.iter().map(|v| v / DELTA_SCALE).collect(),
                input_channels: 3,
                target: p
                    .dz_m
                    .iter()
                    .map(|&v| dz_to_target(f64::from(v)) as f32)
                    .collect(),
                target_channels: 1,
                mask: p
                    .dz_m
                    .iter()
                    .map(|&v| f32::from(-f64::from(v) > CONTACT_DZ_M))
                    .collect(),
                mask_loss_weight: 0.0,
                iou_loss_weight: 0.0,
                force_loss_weight: 0.0,
                force_weight: Vec::new(),
                coords: Vec::new(),
            },
            NetKind::Rendering => NetData {
                kind,
                rows: p.rows,
                cols: p.cols,
                input: p
                    .splat_dz_m
                    .iter()
                    .map(|&v| (f64::from(v) / DZ_SCALE_M).clamp(-1.0, 1.0) as f32)
                    .collect(),
                input_channels: 1,
                target: p.delta.iter().map(|v| v / 255.0).collect(),
                target_channels: 3,
                mask: p
                    .splat_dz_m
                    .iter()
                    .map(|&v| {
                        if -f64::from(v) > CONTACT_DZ_M {
                            1.0
                        } else {
                            0.0
                        }
                    })
                    .collect(),
                mask_loss_weight: 0.0,
                iou_loss_weight: 0.0,
                force_loss_weight: 0.0,
                force_weight: Vec::new(),
                coords: coordinate_channels(p.rows, p.cols),
            },
        }
    }

    /// Adds the surface-force term at `weight` (1/N^2) with per-sample pixel weights
    /// `pixel_weights` (`[rows, cols]` per sample, N/m, from
    /// [`force::LinearForceMap::pixel_weights`] on each sample's own target field); an error
    /// for the rendering network, a weight that is not finite and >= 0, or weights of another
    /// size or not finite.
    pub fn set_force_loss(&mut self, weight: f32, pixel_weights: Vec<f32>) -> Result<()> {
        let n = self.rows * self.cols;
        if self.kind != NetKind::Perception {
            return Err(TactileError::Input(
                "the surface-force term is for the perception network".into(),
            ));
        }
        if !(weight.is_finite() && weight >= 0.0) {
            return Err(TactileError::Input(format!(
                "surface-force loss weight {weight}: expected a finite value >= 0"
            )));
        }
        if pixel_weights.len() != self.len() * n {
            return Err(TactileError::Input(format!(
                "{} force weights for {} samples of {n} pixels",
                pixel_weights.len(),
                self.len()
            )));
        }
        if let Some(i) = pixel_weights.iter().position(|v| !v.is_finite()) {
            return Err(TactileError::Input(format!(
                "force weight of sample {} at pixel {} is {}",
                i / n,
                i % n,
                pixel_weights[i]
            )));
        }
        self.force_loss_weight = weight;
        self.force_weight = pixel_weights;
        Ok(())
    }

    /// Weight of the surface-force term (0 when it is not used), 1/N^2.
    pub fn force_loss_weight(&self) -> f32 {
        self.force_loss_weight
    }

    /// Number of samples.
    pub fn len(&self) -> usize {
        self.target.len() / (self.target_channels * self.rows * self.cols).max(1)
    }

    /// Whether there are no samples.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Channels of the network input (coordinates included).
    pub fn network_channels(&self) -> usize {
        self.input_channels + self.coords.len() / (self.rows * self.cols).max(1)
    }

    /// The network input of samples `idx`, `[b, C, rows, cols]` row-major.
    pub fn input_values(&self, idx: &[usize]) -> Vec<f32> {
        let per = self.input_channels * self.rows * self.cols;
        let mut v = Vec::with_capacity(idx.len() * (per + self.coords.len()));
        for &i in idx {
            v.extend_from_slice(&self.input[i * per..(i + 1) * per]);
            v.extend_from_slice(&self.coords);
        }
        v
    }

    /// The network input of samples `idx`, `[b, C, rows, cols]`.
    pub fn inputs(&self, idx: &[usize], device: &Device) -> Tensor<4> {
        Tensor::from_data(
            TensorData::new(
                self.input_values(idx),
                [idx.len(), self.network_channels(), self.rows, self.cols],
            ),
            device,
        )
    }

    fn rows_of(
        &self,
        v: &[f32],
        per: usize,
        idx: &[usize],
        ch: usize,
        device: &Device,
    ) -> Tensor<4> {
        let mut out = Vec::with_capacity(idx.len() * per);
        for &i in idx {
            out.extend_from_slice(&v[i * per..(i + 1) * per]);
        }
        Tensor::from_data(
            TensorData::new(out, [idx.len(), ch, self.rows, self.cols]),
            device,
        )
    }

    /// The loss of `net` on the inputs `idx` against the targets of `target_idx` (the same
    /// samples, or shuffled ones for a control): MSE on the dz channel (eq 5.15), plus the
    /// contact-mask term when [`NetData::mask_loss_weight`] is set, or the masked weighted L1
    /// (eq 5.19-5.22).
    pub fn loss(
        &self,
        net: &UNet,
        idx: &[usize],
        target_idx: &[usize],
        device: &Device,
    ) -> Tensor<1> {
        let n = self.rows * self.cols;
        let out = net.forward(self.inputs(idx, device));
        let target = self.rows_of(
            &self.target,
            self.target_channels * n,
            target_idx,
            self.target_channels,
            device,
        );
        match self.kind {
            NetKind::Perception => {
                let dz = out.narrow(1, 2, 1);
                let err = dz.clone() - target;
                let mut loss = err.clone().powi_scalar(2).mean();
                if self.force_loss_weight > 0.0 {
                    let w = self.rows_of(&self.force_weight, n, target_idx, 1, device);
                    // Normalised dz back to metres: the offset cancels in the difference.
                    let scale = (DZ_MAX_M - DZ_MIN_M) as f32;
                    let force_err = (err * w).sum_dim(3).sum_dim(2).mul_scalar(scale);
                    let term = force_err.powi_scalar(2).mean();
                    loss = loss + term.mul_scalar(self.force_loss_weight);
                }
                if self.mask_loss_weight <= 0.0 && self.iou_loss_weight <= 0.0 {
                    return loss;
                }
                let m = self.rows_of(&self.mask, n, target_idx, 1, device);
                let z = dz.neg().add_scalar(1.0).div_scalar(MASK_LOGIT_WIDTH);
                if self.iou_loss_weight > 0.0 {
                    let p = activation::sigmoid(z.clone());
                    let inter = (p.clone() * m.clone()).sum_dim(3).sum_dim(2);
                    let union = (p + m.clone()).sum_dim(3).sum_dim(2) - inter.clone();
                    let iou = inter.add_scalar(SOFT_IOU_EPS) / union.add_scalar(SOFT_IOU_EPS);
                    let term = iou.neg().add_scalar(1.0).mean();
                    loss = loss + term.mul_scalar(self.iou_loss_weight);
                }
                if self.mask_loss_weight > 0.0 {
                    // BCE with logits z: softplus(z) - y z.
                    let bce = (activation::softplus(z.clone(), 1.0) - z * m).mean();
                    loss = loss + bce.mul_scalar(self.mask_loss_weight);
                }
                loss
            }
            NetKind::Rendering => {
                let pred = activation::tanh(out);
                let m = self.rows_of(&self.mask, n, target_idx, 1, device);
                let err = (pred.clone() - target).abs().sum_dim(1);
                let eps = 1e-6;
                let inv = m.clone().neg().add_scalar(1.0);
                let contact = (err.clone() * m.clone()).sum() / (m.sum().add_scalar(eps));
                let bg = (err * inv.clone()).sum() / (inv.clone().sum().add_scalar(eps));
                let neutral = (pred * inv).abs().mean();
                contact + bg.mul_scalar(0.1) + neutral.mul_scalar(0.02)
            }
        }
    }

    /// [`NetData::predict_in`] on the plain engine; `None` when it does not take this network
    /// or input (then burn's graph decides).
    fn predict_plain(
        &self,
        net: &UNet,
        idx: &[usize],
        chunk: usize,
        precision: infer::Precision,
    ) -> Option<Vec<f32>> {
        let plain = infer::PlainUNet::new(net).ok()?.with_precision(precision);
        self.predict_on(&plain, idx, chunk)
    }

    /// [`NetData::predict`] on an engine built once by the caller (a loop over single
    /// images need not copy the weights out of burn for each); `None` when the engine does
    /// not take this input.
    pub fn predict_on(
        &self,
        plain: &infer::PlainUNet,
        idx: &[usize],
        chunk: usize,
    ) -> Option<Vec<f32>> {
        let n = self.rows * self.cols;
        let c = plain.output_channels();
        let mut out = Vec::with_capacity(idx.len() * n * self.target_channels);
        for b in idx.chunks(chunk.max(1)) {
            let y = plain
                .forward(&self.input_values(b), b.len(), self.rows, self.cols)
                .ok()?;
            for img in y.chunks_exact(c * n) {
                match self.kind {
                    NetKind::Perception => out.extend(
                        img.get(2 * n..3 * n)?
                            .iter()
                            .map(|&t| target_to_dz(f64::from(t)) as f32),
                    ),
                    NetKind::Rendering => out.extend(img.iter().map(|v| v.tanh() * 255.0)),
                }
            }
        }
        Some(out)
    }

    /// Network output for samples `idx` in chunks of `chunk`: the predicted dz (m, `[rows,
    /// cols]` per sample) or delta image (grey levels, `[3, rows, cols]`). Off an autodiff
    /// device it runs on the plain engine ([`infer::PlainUNet`], the same values several times
    /// faster), on one through burn's graph.
    pub fn predict(&self, net: &UNet, idx: &[usize], chunk: usize, device: &Device) -> Vec<f32> {
        self.predict_in(net, idx, chunk, device, infer::Precision::F32)
    }

    /// [`NetData::predict`] with the plain engine's convolutions in `precision` (burn's graph,
    /// on an autodiff device or where the plain engine does not apply, is always `f32`).
    pub fn predict_in(
        &self,
        net: &UNet,
        idx: &[usize],
        chunk: usize,
        device: &Device,
        precision: infer::Precision,
    ) -> Vec<f32> {
        if let Some(out) = (!device.is_autodiff())
            .then(|| self.predict_plain(net, idx, chunk, precision))
            .flatten()
        {
            return out;
        }
        let mut out = Vec::new();
        for b in idx.chunks(chunk.max(1)) {
            let y = net.forward(self.inputs(b, device));
            match self.kind {
                NetKind::Perception => out.extend(
                    values(y.narrow(1, 2, 1))
                        .into_iter()
                        .map(|t| target_to_dz(f64::from(t)) as f32),
                ),
                NetKind::Rendering => {
                    out.extend(values(activation::tanh(y)).into_iter().map(|v| v * 255.0))
                }
            }
        }
        out
    }
}

/// Which engine computes the training gradients.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Engine {
    /// burn's autodiff graph of [`NetData::loss`].
    #[default]
    Burn,
    /// The plain engine's hand-written passes ([`backprop`]) and [`NetData::loss_and_grad`];
    /// the validation loss through [`infer::PlainUNet`].
    Plain,
}

impl std::str::FromStr for Engine {
    type Err = TactileError;
    fn from_str(s: &str) -> Result<Self> {
        match s {
            "burn" => Ok(Engine::Burn),
            "plain" => Ok(Engine::Plain),
            other => Err(TactileError::Input(format!(
                "training engine must be burn or plain, got {other:?}"
            ))),
        }
    }
}

/// Trains `net` (built on an autodiff device) on `split` with burn's autodiff; with
/// `shuffle_targets` each training input is paired with another sample's target (a control
/// that must not learn).
pub fn train(
    data: &NetData,
    net: UNet,
    split: &Split,
    cfg: &TrainConfig,
    shuffle_targets: Option<u64>,
) -> Result<TrainReport<UNet>> {
    train_with(data, net, split, cfg, shuffle_targets, Engine::Burn)
}

/// [`train`] with the gradients from `engine`. Both engines share burn's Adam, clipping,
/// split, shuffling, early stopping and checkpoints.
pub fn train_with(
    data: &NetData,
    net: UNet,
    split: &Split,
    cfg: &TrainConfig,
    shuffle_targets: Option<u64>,
    engine: Engine,
) -> Result<TrainReport<UNet>> {
    let mut target_of: Vec<usize> = (0..data.len()).collect();
    if let Some(seed) = shuffle_targets {
        use rand::SeedableRng;
        use rand::seq::SliceRandom;
        let mut t = split.train.clone();
        t.shuffle(&mut rand_chacha::ChaCha8Rng::seed_from_u64(seed));
        for (a, b) in split.train.iter().zip(t) {
            target_of[*a] = b;
        }
    }
    let targets = |idx: &[usize]| -> Vec<usize> { idx.iter().map(|&i| target_of[i]).collect() };
    match engine {
        Engine::Burn => Ok(ocm_learn::train_split(net, split, cfg, |m, idx, dev| {
            data.loss(m, idx, &targets(idx), dev)
        })?),
        Engine::Plain => {
            let learn = |e: TactileError| ocm_learn::LearnError::Data(e.to_string());
            let device = ocm_learn::cpu();
            let (rows, cols) = (data.rows, data.cols);
            Ok(ocm_learn::train_split_steps(
                net,
                split,
                cfg,
                |m, idx| {
                    let t = targets(idx);
                    backprop::TrainPass::new(m)
                        .and_then(|pass| {
                            pass.step(
                                &data.input_values(idx),
                                idx.len(),
                                rows,
                                cols,
                                &device,
                                |out| data.loss_and_grad(out, idx, &t),
                            )
                        })
                        .map_err(learn)
                },
                |m, samples| {
                    let plain = infer::PlainUNet::new(m).map_err(learn)?;
                    let mut sum = 0.0;
                    for b in samples.chunks(cfg.batch_size.max(1)) {
                        let out = plain
                            .forward(&data.input_values(b), b.len(), rows, cols)
                            .map_err(learn)?;
                        let (l, _) = data.loss_and_grad(&out, b, b).map_err(learn)?;
                        sum += l * b.len() as f64;
                    }
                    Ok(sum / samples.len().max(1) as f64)
                },
            )?)
        }
    }
}

/// Least elongation ([`elongation`]) of the true contact mask for its principal axis to count
/// as defined: 0.2 is an axis ratio sqrt(l1 / l2) of 1.12. Below it (discs, rings, squares,
/// dot grids) the second moments are nearly equal and the axis angle is set by a few rim
/// pixels, so the rotation error measures pixel noise, not orientation.
pub const ROTATION_MIN_ELONGATION: f64 = 0.2;

/// Elongation of a mask, 1 - l2 / l1 with l1 >= l2 the eigenvalues of its second central
/// moments: 0 for a disc or a square (no defined principal axis), towards 1 for a line.
/// 0 for an empty mask.
pub fn elongation(mask: &Mask) -> f64 {
    let g = mask.grid;
    let (mut n, mut sr, mut sc) = (0.0, 0.0, 0.0);
    for (i, _) in mask.pixels.iter().enumerate().filter(|(_, p)| **p) {
        n += 1.0;
        sr += (i / g.cols) as f64;
        sc += (i % g.cols) as f64;
    }
    if n == 0.0 {
        return 0.0;
    }
    let (cr, cc) = (sr / n, sc / n);
    let (mut mrr, mut mcc, mut mrc) = (0.0, 0.0, 0.0);
    for (i, _) in mask.pixels.iter().enumerate().filter(|(_, p)| **p) {
        let (dr, dc) = ((i / g.cols) as f64 - cr, (i % g.cols) as f64 - cc);
        mrr += dr * dr;
        mcc += dc * dc;
        mrc += dr * dc;
    }
    let mean = 0.5 * (mrr + mcc);
    let half_gap = (0.25 * (mrr - mcc).powi(2) + mrc * mrc).sqrt();
    let (l1, l2) = (mean + half_gap, mean - half_gap);
    if l1 <= 0.0 { 0.0 } else { 1.0 - l2 / l1 }
}

/// One scored held-out sample of the perception network.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct PerceptionSample {
    /// Sample index in the pairs.
    pub sample: usize,
    /// Set-up name.
    pub setup: String,
    /// Indentation depth, mm.
    pub depth_mm: f64,
    /// Contact pixels of the true mask.
    pub true_pixels: usize,
    /// Contact pixels of the predicted mask.
    #[serde(default)]
    pub pred_pixels: usize,
    /// True contact pixels the prediction misses.
    #[serde(default)]
    pub missed_pixels: usize,
    /// Predicted contact pixels outside the true mask.
    #[serde(default)]
    pub extra_pixels: usize,
    /// Contact-mask IoU.
    pub iou: f64,
    /// Centroid error, mm (NaN when the prediction has no contact).
    pub centroid_mm: f64,
    /// Rotation error, rad (NaN when the prediction has no contact).
    pub rotation_rad: f64,
    /// Elongation of the true mask ([`elongation`]).
    pub true_elongation: f64,
}

/// Perception scores on held-out samples.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct PerceptionScores {
    /// Samples scored (a contact in the FEM mask).
    pub samples: usize,
    /// Median contact-mask IoU.
    pub iou_median: f64,
    /// Mean contact-mask IoU.
    pub iou_mean: f64,
    /// Median centroid error, mm.
    pub centroid_mm_median: f64,
    /// Median rotation error over every contact, rad (isotropic contacts included).
    pub rotation_rad_median: f64,
    /// Median rotation error over the contacts whose true mask has a defined principal axis
    /// (elongation at least [`ROTATION_MIN_ELONGATION`]), rad.
    #[serde(default)]
    pub rotation_rad_median_elongated: f64,
    /// Samples in that median.
    #[serde(default)]
    pub rotation_elongated_samples: usize,
    /// RMSE of u_z over all pixels, m.
    pub dz_rmse_m: f64,
    /// RMSE of u_z over the pixels of the true contact masks, m (the depth the surface force
    /// integrates; outside the contact the mask terms push the prediction above the surface).
    #[serde(default)]
    pub dz_rmse_contact_m: f64,
    /// Images per second of inference (batches of 8).
    pub images_per_s: f64,
    /// Every scored sample.
    #[serde(default)]
    pub per_sample: Vec<PerceptionSample>,
    /// Indentation above which a predicted pixel is in contact, m.
    #[serde(default = "default_threshold")]
    pub pred_threshold_m: f64,
}

fn default_threshold() -> f64 {
    CONTACT_DZ_M
}

/// Rendering scores on held-out samples (against the physically based renderer's frames).
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct RenderingScores {
    /// Samples scored.
    pub samples: usize,
    /// Median L1, grey levels (whole frame).
    pub l1_median: f64,
    /// Median PSNR, dB.
    pub psnr_db_median: f64,
    /// Median SSIM (whole frame).
    pub ssim_median: f64,
    /// Median SSIM over the windows overlapping the contact (samples with contact).
    pub contact_ssim_median: f64,
    /// Images per second of inference (batches of 8).
    pub images_per_s: f64,
}

fn median(mut v: Vec<f64>) -> f64 {
    v.retain(|x| !x.is_nan());
    if v.is_empty() {
        return f64::NAN;
    }
    v.sort_by(f64::total_cmp);
    let n = v.len();
    if n % 2 == 1 {
        v[n / 2]
    } else {
        0.5 * (v[n / 2 - 1] + v[n / 2])
    }
}

/// The contact mask (-u_z above [`CONTACT_DZ_M`]) of a `[rows, cols]` u_z field on `grid`.
pub fn contact_mask(grid: Grid, dz_m: &[f32]) -> Mask {
    mask_from_fn(grid, |r, c| {
        -f64::from(dz_m[r * grid.cols + c]) > CONTACT_DZ_M
    })
}

/// The contact mask of a `[rows, cols]` u_z field on `grid` at another threshold
/// (indentation above `threshold_m`).
pub fn contact_mask_at(grid: Grid, dz_m: &[f32], threshold_m: f64) -> Mask {
    mask_from_fn(grid, |r, c| {
        -f64::from(dz_m[r * grid.cols + c]) > threshold_m
    })
}

/// Scores a perception network on samples `idx` of `pairs`.
pub fn score_perception(
    net: &UNet,
    data: &NetData,
    pairs: &Pairs,
    idx: &[usize],
    device: &Device,
    precision: infer::Precision,
) -> Result<(PerceptionScores, Vec<f32>)> {
    let t0 = std::time::Instant::now();
    let pred = data.predict_in(net, idx, 8, device, precision);
    let ips = idx.len() as f64 / t0.elapsed().as_secs_f64();
    let scores = score_predicted(&pred, pairs, idx, CONTACT_DZ_M, ips)?;
    Ok((scores, pred))
}

/// Threshold on the predicted indentation (m) with the best median contact IoU over samples
/// `idx` of `pairs`, among `candidates_m`; the true masks keep [`CONTACT_DZ_M`]. For choosing
/// it on validation samples: the network's field is smooth at the rim, so where it crosses
/// 30 um need not be where the FEM's does.
pub fn fit_threshold(
    pred: &[f32],
    pairs: &Pairs,
    idx: &[usize],
    candidates_m: &[f64],
) -> Result<(f64, f64)> {
    let mut best = (CONTACT_DZ_M, f64::NEG_INFINITY);
    for &t in candidates_m {
        let s = score_predicted(pred, pairs, idx, t, f64::NAN)?;
        if s.iou_median > best.1 {
            best = (t, s.iou_median);
        }
    }
    Ok(best)
}

/// Scores predicted u_z fields `pred` (`[rows, cols]` per sample of `idx`, m) against the FEM's
/// on `pairs`, the predicted mask taken at `pred_threshold_m`; `ips` is reported as the speed.
pub fn score_predicted(
    pred: &[f32],
    pairs: &Pairs,
    idx: &[usize],
    pred_threshold_m: f64,
    ips: f64,
) -> Result<PerceptionScores> {
    let n = pairs.pixels();
    if pred.len() != idx.len() * n {
        return Err(TactileError::Input(format!(
            "{} predicted values for {} samples of {n} pixels",
            pred.len(),
            idx.len()
        )));
    }
    let grid = pairs.grid();
    let (mut ious, mut cens, mut rots, mut rots_el) =
        (Vec::new(), Vec::new(), Vec::new(), Vec::new());
    let mut per_sample = Vec::new();
    let (mut se, mut count) = (0.0, 0usize);
    let (mut se_contact, mut count_contact) = (0.0, 0usize);
    for (k, &i) in idx.iter().enumerate() {
        let truth = &pairs.dz_m[i * n..(i + 1) * n];
        let p = &pred[k * n..(k + 1) * n];
        for (a, b) in truth.iter().zip(p) {
            let e = f64::from(a - b).powi(2);
            se += e;
            count += 1;
            if -f64::from(*a) > CONTACT_DZ_M {
                se_contact += e;
                count_contact += 1;
            }
        }
        let mt = contact_mask(grid, truth);
        if mt.count() == 0 {
            continue;
        }
        let mp = contact_mask_at(grid, p, pred_threshold_m);
        let iou = metrics::iou(&mt, &mp)?;
        ious.push(iou);
        let el = elongation(&mt);
        let (mut cen, mut rot) = (f64::NAN, f64::NAN);
        if mp.count() > 0 {
            let (st, sp) = (mt.stats(), mp.stats());
            cen = metrics::centroid_error(&st, &sp) * 1e3;
            rot = metrics::rotation_error(st.angle_rad, sp.angle_rad);
            cens.push(cen);
            rots.push(rot);
            if el >= ROTATION_MIN_ELONGATION {
                rots_el.push(rot);
            }
        }
        per_sample.push(PerceptionSample {
            sample: i,
            setup: pairs
                .setup_names
                .get(pairs.setup[i])
                .cloned()
                .unwrap_or_default(),
            depth_mm: pairs.depth_m[i] * 1e3,
            true_pixels: mt.count(),
            pred_pixels: mp.count(),
            missed_pixels: mt
                .pixels
                .iter()
                .zip(&mp.pixels)
                .filter(|(t, p)| **t && !**p)
                .count(),
            extra_pixels: mt
                .pixels
                .iter()
                .zip(&mp.pixels)
                .filter(|(t, p)| !**t && **p)
                .count(),
            iou,
            centroid_mm: cen,
            rotation_rad: rot,
            true_elongation: el,
        });
    }
    let samples = ious.len();
    let mean = ious.iter().sum::<f64>() / samples.max(1) as f64;
    Ok(PerceptionScores {
        samples,
        iou_median: median(ious),
        iou_mean: mean,
        centroid_mm_median: median(cens),
        rotation_rad_median: median(rots),
        rotation_elongated_samples: rots_el.len(),
        rotation_rad_median_elongated: median(rots_el),
        dz_rmse_m: (se / count.max(1) as f64).sqrt(),
        dz_rmse_contact_m: (se_contact / count_contact.max(1) as f64).sqrt(),
        images_per_s: ips,
        per_sample,
        pred_threshold_m,
    })
}

/// Scores a rendering network on samples `idx` of `pairs`: its frames (background + predicted
/// delta) against the physically based renderer's.
pub fn score_rendering(
    net: &UNet,
    data: &NetData,
    pairs: &Pairs,
    idx: &[usize],
    device: &Device,
    precision: infer::Precision,
) -> Result<(RenderingScores, Vec<RgbImage>)> {
    let t0 = std::time::Instant::now();
    let pred = data.predict_in(net, idx, 8, device, precision);
    let ips = idx.len() as f64 / t0.elapsed().as_secs_f64();
    let n = pairs.pixels();
    let grid = pairs.grid();
    let (mut l1, mut psnr, mut ssim, mut cssim) = (Vec::new(), Vec::new(), Vec::new(), Vec::new());
    let mut frames = Vec::new();
    for (k, &i) in idx.iter().enumerate() {
        let img = frame_from_delta(&pairs.background, &pred[k * 3 * n..(k + 1) * 3 * n]);
        let truth = pairs.frame(i);
        let (a, b) = (img.to_f64(), truth.to_f64());
        l1.push(metrics::l1(&a, &b)?);
        psnr.push(metrics::psnr(&a, &b, 255.0)?);
        ssim.push(score_ssim(&img, &truth)?);
        let m = contact_mask(grid, &pairs.dz_m[i * n..(i + 1) * n]);
        if let Some(region) = crate::real::contact_region(&m) {
            cssim.push(score_ssim_in(&img, &truth, &region)?);
        }
        frames.push(img);
    }
    Ok((
        RenderingScores {
            samples: idx.len(),
            l1_median: median(l1),
            psnr_db_median: median(psnr),
            ssim_median: median(ssim),
            contact_ssim_median: median(cssim),
            images_per_s: ips,
        },
        frames,
    ))
}

/// Checks that an image can go through a network of `rows` x `cols`: RGB of exactly that size.
pub fn check_image(img: &RgbImage, rows: usize, cols: usize, what: &str) -> Result<()> {
    if (img.rows, img.cols) != (rows, cols) || img.data.len() != rows * cols * 3 {
        return Err(TactileError::Input(format!(
            "{what} is {} x {} (cols x rows) with {} bytes; the network takes {cols} x {rows} RGB",
            img.cols,
            img.rows,
            img.data.len()
        )));
    }
    Ok(())
}

/// Writes a trained network with its configuration and `meta` (seed, data, losses).
pub fn save(
    path: &std::path::Path,
    net: &UNet,
    cfg: &NetConfig,
    meta: serde_json::Value,
) -> Result<()> {
    Ok(ocm_learn::save_checkpoint(
        path,
        net,
        &ocm_learn::checkpoint::CheckpointInfo {
            architecture: cfg.kind.architecture(),
            config: cfg,
            scalers: Default::default(),
            meta,
        },
    )?)
}

/// Reads a network written by [`save`] onto `device`; an error names a file that holds another
/// architecture or does not match its configuration.
pub fn load(path: &std::path::Path, device: &Device) -> Result<(UNet, NetConfig)> {
    let ck = ocm_learn::Checkpoint::read(path)?;
    let cfg: NetConfig = ck.config_of(&[
        NetKind::Perception.architecture(),
        NetKind::Rendering.architecture(),
    ])?;
    let net = cfg.init(device, 0)?;
    let net = ck.load_into(net, cfg.kind.architecture(), &cfg)?;
    Ok((net, cfg))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn grid() -> Grid {
        Grid {
            origin_m: [0.0, 0.0],
            pixel_m: 1e-4,
            rows: 60,
            cols: 80,
        }
    }

    /// A disc and a square have no principal axis (elongation near 0), a 4 : 1 bar is far
    /// above the threshold (1 - 1/16 for its second moments), and an empty mask is 0.
    #[test]
    fn elongation_of_known_shapes() {
        let disc = mask_from_fn(grid(), |r, c| {
            (r as f64 - 30.0).powi(2) + (c as f64 - 40.0).powi(2) < 15.0f64.powi(2)
        });
        assert!(elongation(&disc) < 0.02, "{}", elongation(&disc));
        let square = mask_from_fn(grid(), |r, c| {
            (20..40).contains(&r) && (30..50).contains(&c)
        });
        assert!(elongation(&square) < 1e-9);
        let bar = mask_from_fn(grid(), |r, c| {
            (25..35).contains(&r) && (20..60).contains(&c)
        });
        // Moments of a 10 x 40 pixel block: (n^2 - 1) / 12 per axis.
        let expect = 1.0 - (100.0 - 1.0) / (1600.0 - 1.0);
        assert!((elongation(&bar) - expect).abs() < 1e-9);
        assert!(elongation(&bar) > ROTATION_MIN_ELONGATION);
        // Rotating the bar by 90 degrees keeps its elongation.
        let tall = mask_from_fn(grid(), |r, c| {
            (10..50).contains(&r) && (35..45).contains(&c)
        });
        assert!((elongation(&tall) - expect).abs() < 1e-9);
        assert_eq!(elongation(&mask_from_fn(grid(), |_, _| false)), 0.0);
    }

    /// A prediction that is the truth at 80 % depth: at 30 um its mask is too small, and the
    /// threshold fitted on it is the one where the masks coincide (24 um), with IoU 1; a
    /// mismatched prediction is refused.
    #[test]
    fn threshold_fit_finds_the_scaled_rim() {
        let (rows, cols) = (20, 30);
        let n = rows * cols;
        let mut dz = vec![0.0f32; 2 * n];
        for k in 0..2 {
            for r in 0..rows {
                for c in 0..cols {
                    let d = ((r as f64 - 10.0).powi(2)
                        + (c as f64 - 12.0 - 4.0 * k as f64).powi(2))
                    .sqrt();
                    dz[k * n + r * cols + c] = (-(200e-6 - 20e-6 * d).max(0.0)) as f32;
                }
            }
        }
        let pairs = Pairs {
            rows,
            cols,
            pixel_m: 1e-4,
            setup_names: vec!["cone".into()],
            setup_unseen: vec![false],
            setup: vec![0; 2],
            depth_m: vec![2e-4; 2],
            mirror: vec![0; 2],
            state: vec![0, 1],
            delta: vec![0.0; 6 * n],
            dz_m: dz.clone(),
            splat_dz_m: Vec::new(),
            background: RgbImage {
                rows,
                cols,
                data: vec![0; 3 * n],
            },
        };
        let pred: Vec<f32> = dz.iter().map(|v| 0.8 * v).collect();
        let idx = [0, 1];
        let at30 = score_predicted(&pred, &pairs, &idx, CONTACT_DZ_M, 1.0).unwrap();
        assert!(at30.iou_median < 0.95, "{}", at30.iou_median);
        // The error is 0.2 |u_z|: its RMSE over the true contact pixels, summed directly.
        let inside: Vec<f64> = dz
            .iter()
            .filter(|v| -f64::from(**v) > CONTACT_DZ_M)
            .map(|v| 0.2 * f64::from(*v))
            .collect();
        let rms = (inside.iter().map(|e| e * e).sum::<f64>() / inside.len() as f64).sqrt();
        assert!(
            (at30.dz_rmse_contact_m - rms).abs() < 1e-6 * rms,
            "{} vs {rms}",
            at30.dz_rmse_contact_m
        );
        assert!(at30.dz_rmse_contact_m > at30.dz_rmse_m);
        // The shallower prediction's mask lies inside the true one: nothing extra, the rest missed.
        for s in &at30.per_sample {
            assert_eq!(s.extra_pixels, 0);
            assert!(s.missed_pixels > 0);
            assert_eq!(s.pred_pixels + s.missed_pixels, s.true_pixels);
        }
        let cands: Vec<f64> = (0..=20).map(|k| 10e-6 + 2e-6 * k as f64).collect();
        let (t, iou) = fit_threshold(&pred, &pairs, &idx, &cands).unwrap();
        // 0.8 (200 - 20 d) um > t  <=>  200 - 20 d > t / 0.8: t = 24 um reproduces 30 um.
        assert!((t - 24e-6).abs() < 1e-9, "{t}");
        assert!((iou - 1.0).abs() < 1e-12);
        assert!(score_predicted(&pred[..n], &pairs, &idx, t, 1.0).is_err());
    }
}
