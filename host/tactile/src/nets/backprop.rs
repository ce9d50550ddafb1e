//! Training passes of the plain engine: the U-Net's forward pass with batch statistics, kept
//! for the backward pass, and the gradients of every parameter by hand, on the same padded
//! channel-last maps and faer products as [`super::infer`]. burn's autodiff graph costs about
//! two seconds per full-size (240 x 320) image and step on 2 cores; these passes are the three
//! matrix products per convolution that training needs (forward, input gradient as a
//! convolution with the flipped kernel, weight gradient as the shifted views transposed times
//! the output gradient) and little else; the first two run by Winograd's F(4 x 4, 3 x 3)
//! ([`super::winograd`]) where the maps and channels allow (1.2-1.3 times the perception
//! network's training steps per second at 240 x 320). The gradients go back to burn by
//! parameter id, so burn's Adam, gradient clipping and checkpoints stay the only ones. Tested
//! against burn's autodiff on both networks.

use faer::linalg::matmul::matmul;
use faer::{Accum, MatMut, MatRef, Par};
use ocm_learn::burn::module::ParamId;
use ocm_learn::burn::nn::conv::Conv2d;
use ocm_learn::burn::optim::GradientsParams;
use ocm_learn::burn::tensor::{Device, Tensor, TensorData};
use ocm_learn::mlp::Activation;
use ocm_learn::unet::ConvBlock;
use ocm_learn::{UNet, values};
use rayon::prelude::*;

use super::infer::{
    Up, bias_of, check_batch, check_conv, conv3_f32, gelu, head_forward, head_weights, max_pool,
    normal_cdf2_and_gauss,
};
use super::map::Map;
use super::winograd::{self, Weights};
use crate::{Result, TactileError};

/// A 3 x 3 convolution's weights in the engine's layouts.
struct Conv {
    c_in: usize,
    c_out: usize,
    /// Forward taps: per kernel row dy, `[3 c_in, c_out]` with rows over (dx, input channel).
    taps: [Vec<f32>; 3],
    /// Input-gradient taps: the kernel flipped and transposed, per row `[3 c_out, c_in]`.
    flip: [Vec<f32>; 3],
    /// `taps` and `flip` in Winograd's domain, where the channels are whole vectors.
    wino: Option<(Weights, Weights)>,
    bias: Vec<f32>,
    ids: (ParamId, Option<ParamId>),
}

impl Conv {
    fn new(conv: &Conv2d) -> Result<Self> {
        let [c_out, c_in, _, _] = check_conv(conv, "U-Net block", 3)?;
        let w = values(conv.weight.val());
        let at =
            |co: usize, ci: usize, dy: usize, dx: usize| w[((co * c_in + ci) * 3 + dy) * 3 + dx];
        let taps = std::array::from_fn(|dy| {
            let mut t = vec![0.0f32; 3 * c_in * c_out];
            for dx in 0..3 {
                for ci in 0..c_in {
                    for co in 0..c_out {
                        t[(dx * c_in + ci) * c_out + co] = at(co, ci, dy, dx);
                    }
                }
            }
            t
        });
        let flip = std::array::from_fn(|dy| {
            let mut t = vec![0.0f32; 3 * c_out * c_in];
            for dx in 0..3 {
                for co in 0..c_out {
                    for ci in 0..c_in {
                        t[(dx * c_out + co) * c_in + ci] = at(co, ci, 2 - dy, 2 - dx);
                    }
                }
            }
            t
        });
        let wino = winograd::fits(4, 4, &[c_in], c_out).then(|| {
            (
                Weights::new(&taps, c_in, c_out),
                Weights::new(&flip, c_out, c_in),
            )
        });
        Ok(Conv {
            c_in,
            c_out,
            taps,
            flip,
            wino,
            bias: bias_of(conv, c_out),
            ids: (conv.weight.id, conv.bias.as_ref().map(|b| b.id)),
        })
    }

    /// Gradient taps (the forward taps' layout) to burn's `[c_out, c_in, 3, 3]`.
    fn to_burn(&self, d: &[Vec<f32>; 3]) -> Vec<f32> {
        let (c_in, c_out) = (self.c_in, self.c_out);
        let mut w = vec![0.0f32; c_out * c_in * 9];
        for (dy, t) in d.iter().enumerate() {
            for dx in 0..3 {
                for ci in 0..c_in {
                    for co in 0..c_out {
                        w[((co * c_in + ci) * 3 + dy) * 3 + dx] = t[(dx * c_in + ci) * c_out + co];
                    }
                }
            }
        }
        w
    }
}

/// The normalisation of a block while training.
enum Norm {
    /// Batch statistics; the running ones are moved towards them by `momentum`.
    Batch {
        gamma: Vec<f32>,
        beta: Vec<f32>,
        eps: f64,
        momentum: f64,
    },
    /// Statistics per image and group of channels.
    Group {
        groups: usize,
        gamma: Vec<f32>,
        beta: Vec<f32>,
        eps: f64,
    },
    /// No normalisation.
    Identity,
}

/// Convolution, normalisation and nonlinearity of one level, with the parameter ids of the
/// normalisation's scale and shift.
struct Block {
    conv: Conv,
    norm: Norm,
    norm_ids: Option<(ParamId, ParamId)>,
    act: Activation,
}

impl Block {
    fn new(b: &ConvBlock) -> Result<Self> {
        let conv = Conv::new(&b.conv)?;
        let (norm, norm_ids) = match (&b.batch, &b.group) {
            (Some(bn), _) => (
                Norm::Batch {
                    gamma: values(bn.gamma.val()),
                    beta: values(bn.beta.val()),
                    eps: bn.epsilon,
                    momentum: bn.momentum,
                },
                Some((bn.gamma.id, bn.beta.id)),
            ),
            (None, Some(gn)) => {
                let (Some(g), Some(be)) = (&gn.gamma, &gn.beta) else {
                    return Err(TactileError::Input(
                        "plain training takes group normalisations with a learned affine map"
                            .into(),
                    ));
                };
                (
                    Norm::Group {
                        groups: gn.num_groups,
                        gamma: values(g.val()),
                        beta: values(be.val()),
                        eps: gn.epsilon,
                    },
                    Some((g.id, be.id)),
                )
            }
            (None, None) => (Norm::Identity, None),
        };
        Ok(Block {
            conv,
            norm,
            norm_ids,
            act: b.activation(),
        })
    }
}

/// What one image keeps of a block's forward pass.
struct Kept {
    /// The convolution's input (the concatenation of the upsampled map and the skip in the
    /// decoder).
    input: Map,
    /// The normalised values (before the affine map), zero border.
    xhat: Map,
    /// The block's output, zero border.
    out: Map,
    /// Group normalisation: 1 / std per group.
    inv_std: Vec<f64>,
}

/// A batch's mean and biased variance per channel.
type BatchStats = (Vec<f64>, Vec<f64>);

/// Parameter gradients of one block.
struct BlockGrad {
    taps: [Vec<f32>; 3],
    bias: Vec<f64>,
    gamma: Vec<f64>,
    beta: Vec<f64>,
}

/// Whether images run in parallel (each one's products on its thread) or one after another
/// (products on the pool).
#[derive(Clone, Copy)]
struct Sched {
    images: bool,
    par: Par,
}

impl Sched {
    fn new(batch: usize) -> Self {
        if batch > 1 && rayon::current_num_threads() > 1 {
            Sched {
                images: true,
                par: Par::Seq,
            }
        } else {
            Sched {
                images: false,
                par: Par::rayon(0),
            }
        }
    }

    /// `f` on every item, in parallel over images or in order.
    fn map<T: Send, U: Send>(&self, items: Vec<T>, f: impl Fn(T) -> U + Sync + Send) -> Vec<U> {
        if self.images {
            items.into_par_iter().map(f).collect()
        } else {
            items.into_iter().map(f).collect()
        }
    }

    /// `f` on every item by reference.
    fn map_ref<T: Sync, U: Send>(&self, items: &[T], f: impl Fn(&T) -> U + Sync + Send) -> Vec<U> {
        if self.images {
            items.par_iter().map(f).collect()
        } else {
            items.iter().map(f).collect()
        }
    }
}

/// The 3 x 3 convolution of `x` with `taps` into a new map (zero border, no bias), by
/// Winograd's transforms with `wino` (the same taps transformed) where the map fits them.
fn conv3(x: &Map, taps: &[Vec<f32>; 3], wino: Option<&Weights>, c_out: usize, par: Par) -> Map {
    let (h, w) = (x.h, x.w);
    let pw = w + 2;
    let mut out = Map::uninit(h, w, c_out);
    let start = (pw + 1) * c_out;
    let dst = &mut out.data[start..start + h * pw * c_out];
    match wino {
        Some(wt) if winograd::fits(h, w, &[x.c], c_out) => {
            winograd::conv3(dst, &[(x, wt)], c_out, par)
        }
        _ => conv3_f32(dst, std::iter::once((x, taps)), c_out, par),
    }
    out.zero_border();
    out
}

/// The product rows of a map as [`conv3_f32`] writes them: `h (w + 2)` rows of `c` values from
/// interior pixel (0, 0) on, the border columns among them (zero in a map with zero border).
fn rows_view(y: &Map) -> MatRef<'_, f32> {
    let (pw, c) = (y.w + 2, y.c);
    let start = (pw + 1) * c;
    MatRef::from_row_major_slice(&y.data[start..start + y.h * pw * c], y.h * pw, c)
}

/// Gradient taps of a 3 x 3 convolution: per kernel row, the input's shifted view transposed
/// times the output gradient `dy` (zero border, so the junk product rows add nothing).
fn conv3_weight_grad(x: &Map, dy: &Map, par: Par) -> [Vec<f32>; 3] {
    let (c, pw, c_out) = (x.c, x.w + 2, dy.c);
    let m = x.h * pw;
    let g = rows_view(dy);
    std::array::from_fn(|k| {
        let mut t = vec![0.0f32; 3 * c * c_out];
        let a = MatRef::from_row_major_slice_with_stride(&x.data[k * pw * c..], m, 3 * c, c);
        matmul(
            MatMut::from_row_major_slice_mut(&mut t, 3 * c, c_out),
            Accum::Replace,
            a.transpose(),
            g,
            1.0f32,
            par,
        );
        t
    })
}

/// Pixels summed in f32 before each addition to the f64 totals: the inner loop vectorises, and
/// 256 terms in f32 lose at most about 1.5e-5 of their magnitude.
const SUM_BLOCK: usize = 256;

/// Per-channel sums of `a` and of `a * b` over whole buffers of `c` channels (borders must be
/// zero in `a`), f32 within blocks of pixels and f64 across them.
fn channel_sums2(a: &[f32], b: &[f32], c: usize) -> (Vec<f64>, Vec<f64>) {
    let (mut s1, mut s2) = (vec![0.0f64; c], vec![0.0f64; c]);
    let (mut p1, mut p2) = (vec![0.0f32; c], vec![0.0f32; c]);
    for (ba, bb) in a.chunks(SUM_BLOCK * c).zip(b.chunks(SUM_BLOCK * c)) {
        p1.fill(0.0);
        p2.fill(0.0);
        for (pa, pb) in ba.chunks_exact(c).zip(bb.chunks_exact(c)) {
            for (((x, y), &u), &v) in p1.iter_mut().zip(p2.iter_mut()).zip(pa).zip(pb) {
                *x += u;
                *y += u * v;
            }
        }
        s1.iter_mut()
            .zip(&p1)
            .for_each(|(t, &v)| *t += f64::from(v));
        s2.iter_mut()
            .zip(&p2)
            .for_each(|(t, &v)| *t += f64::from(v));
    }
    (s1, s2)
}

/// Per-channel sums over a map's whole buffer (its border must be zero).
fn channel_sums(x: &Map) -> Vec<f64> {
    let c = x.c;
    let mut s = vec![0.0f64; c];
    let mut p = vec![0.0f32; c];
    for block in x.data.chunks(SUM_BLOCK * c) {
        p.fill(0.0);
        for px in block.chunks_exact(c) {
            p.iter_mut().zip(px).for_each(|(a, &v)| *a += v);
        }
        s.iter_mut().zip(&p).for_each(|(t, &v)| *t += f64::from(v));
    }
    s
}

/// `d = g d - m1 - xhat m2` per channel over whole buffers: the gradient through a
/// normalisation, given per-channel coefficients.
fn normalisation_grad(d: &mut [f32], xhat: &[f32], g: &[f32], m1: &[f32], m2: &[f32]) {
    let c = g.len();
    for (dp, xp) in d.chunks_exact_mut(c).zip(xhat.chunks_exact(c)) {
        for ((((v, &x), &g), &a), &b) in dp.iter_mut().zip(xp).zip(g).zip(m1).zip(m2) {
            *v = g * *v - a - x * b;
        }
    }
}

/// The channels of `a` then `b` in one map (same size).
fn concat(a: &Map, b: &Map) -> Map {
    let (ca, cb) = (a.c, b.c);
    let mut out = Map::uninit(a.h, a.w, ca + cb);
    for ((o, x), y) in out
        .data
        .chunks_exact_mut(ca + cb)
        .zip(a.data.chunks_exact(ca))
        .zip(b.data.chunks_exact(cb))
    {
        o[..ca].copy_from_slice(x);
        o[ca..].copy_from_slice(y);
    }
    out
}

/// A map's first `ca` channels and the rest, as two maps.
fn split(x: &Map, ca: usize) -> (Map, Map) {
    let cb = x.c - ca;
    let mut a = Map::uninit(x.h, x.w, ca);
    let mut b = Map::uninit(x.h, x.w, cb);
    for ((px, pa), pb) in x
        .data
        .chunks_exact(x.c)
        .zip(a.data.chunks_exact_mut(ca))
        .zip(b.data.chunks_exact_mut(cb))
    {
        pa.copy_from_slice(&px[..ca]);
        pb.copy_from_slice(&px[ca..]);
    }
    (a, b)
}

/// The derivative of the exact GELU, Phi(z) + z phi(z), with [`gelu`]'s erf approximation.
fn gelu_slope(z: f32) -> f32 {
    let (cdf2, gauss) = normal_cdf2_and_gauss(z);
    // phi(z) = e^(-z^2 / 2) / sqrt(2 pi).
    0.5 * cdf2 + z * gauss * 0.398_942_3
}

impl Block {
    /// The normalisation's scale and shift per channel (1 and 0 without one).
    fn affine(&self) -> (Vec<f32>, Vec<f32>) {
        match &self.norm {
            Norm::Batch { gamma, beta, .. } | Norm::Group { gamma, beta, .. } => {
                (gamma.clone(), beta.clone())
            }
            Norm::Identity => (vec![1.0; self.conv.c_out], vec![0.0; self.conv.c_out]),
        }
    }

    /// The block on a batch: convolution, statistics, normalisation, activation; with batch
    /// normalisation also the batch's mean and (biased) variance per channel.
    fn forward(&self, inputs: Vec<Map>, s: Sched) -> (Vec<Kept>, Option<BatchStats>) {
        let c = self.conv.c_out;
        let conv = |x: Map| {
            let wino = self.conv.wino.as_ref().map(|w| &w.0);
            let mut y = conv3(&x, &self.conv.taps, wino, c, s.par);
            let bias = &self.conv.bias;
            for row in y.data.chunks_exact_mut(c) {
                row.iter_mut().zip(bias).for_each(|(v, b)| *v += b);
            }
            y.zero_border();
            (x, y)
        };
        let ys = s.map(inputs, conv);
        let (h, w) = (ys[0].1.h, ys[0].1.w);
        // Per channel (batch) or per image and group: mean and 1 / std.
        let mut batch_stats = None;
        let scale_shift: Vec<(Vec<f32>, Vec<f32>, Vec<f64>)> = match &self.norm {
            Norm::Batch { eps, .. } => {
                let sums = s.map_ref(&ys, |(_, y)| channel_sums2(&y.data, &y.data, c));
                let n = (ys.len() * h * w) as f64;
                let mut mean = vec![0.0f64; c];
                let mut var = vec![0.0f64; c];
                for (sm, sq) in &sums {
                    mean.iter_mut().zip(sm).for_each(|(a, b)| *a += b);
                    var.iter_mut().zip(sq).for_each(|(a, b)| *a += b);
                }
                mean.iter_mut().for_each(|m| *m /= n);
                for (v, m) in var.iter_mut().zip(&mean) {
                    *v = (*v / n - m * m).max(0.0);
                }
                let inv: Vec<f64> = var.iter().map(|v| 1.0 / (v + eps).sqrt()).collect();
                let sc: Vec<f32> = inv.iter().map(|&i| i as f32).collect();
                let sh: Vec<f32> = mean
                    .iter()
                    .zip(&inv)
                    .map(|(m, i)| (-m * i) as f32)
                    .collect();
                batch_stats = Some((mean, var));
                vec![(sc, sh, Vec::new()); ys.len()]
            }
            Norm::Group { groups, eps, .. } => s.map_ref(&ys, |(_, y)| {
                let cg = c / groups;
                let (sm, q) = channel_sums2(&y.data, &y.data, c);
                let n = (h * w * cg) as f64;
                let mut sc = vec![0.0f32; c];
                let mut sh = vec![0.0f32; c];
                let mut inv_g = vec![0.0f64; *groups];
                for g in 0..*groups {
                    let mean = sm[g * cg..(g + 1) * cg].iter().sum::<f64>() / n;
                    let var =
                        (q[g * cg..(g + 1) * cg].iter().sum::<f64>() / n - mean * mean).max(0.0);
                    let inv = 1.0 / (var + eps).sqrt();
                    inv_g[g] = inv;
                    for ch in g * cg..(g + 1) * cg {
                        sc[ch] = inv as f32;
                        sh[ch] = (-mean * inv) as f32;
                    }
                }
                (sc, sh, inv_g)
            }),
            Norm::Identity => vec![(vec![1.0; c], vec![0.0; c], Vec::new()); ys.len()],
        };
        let (gamma, beta) = self.affine();
        let act = self.act;
        let kept = s.map(
            ys.into_iter().zip(scale_shift).collect(),
            |((input, mut xhat), (sc, sh, inv_std))| {
                let mut out = Map::uninit(h, w, c);
                for (px, o) in xhat
                    .data
                    .chunks_exact_mut(c)
                    .zip(out.data.chunks_exact_mut(c))
                {
                    for (((((x, y), &a), &b), &g), &be) in px
                        .iter_mut()
                        .zip(o)
                        .zip(&sc)
                        .zip(&sh)
                        .zip(&gamma)
                        .zip(&beta)
                    {
                        *x = *x * a + b;
                        *y = *x * g + be;
                    }
                }
                match act {
                    Activation::Relu => out.data.iter_mut().for_each(|v| *v = v.max(0.0)),
                    Activation::Gelu => gelu(&mut out.data),
                    Activation::Tanh => out.data.iter_mut().for_each(|v| *v = v.tanh()),
                }
                xhat.zero_border();
                out.zero_border();
                Kept {
                    input,
                    xhat,
                    out,
                    inv_std,
                }
            },
        );
        (kept, batch_stats)
    }

    /// Gradients of the block from those of its outputs `d_out` (zero border); with
    /// `input_grad` also the gradients of its inputs.
    fn backward(
        &self,
        kept: &[&Kept],
        d_out: Vec<Map>,
        input_grad: bool,
        batch_inv_std: Option<&[f64]>,
        s: Sched,
    ) -> (Vec<Option<Map>>, BlockGrad) {
        let c = self.conv.c_out;
        let (gamma, beta) = self.affine();
        let act = self.act;
        // dz = d_out * act'(z), with per-channel sums of dz and dz * xhat.
        let staged = s.map(
            d_out.into_iter().zip(kept).collect(),
            |(mut d, k): (Map, &&Kept)| {
                match act {
                    Activation::Relu => {
                        for (v, &o) in d.data.iter_mut().zip(&k.out.data) {
                            *v = if o > 0.0 { *v } else { 0.0 };
                        }
                    }
                    Activation::Gelu => {
                        for (dp, xp) in d.data.chunks_exact_mut(c).zip(k.xhat.data.chunks_exact(c))
                        {
                            for (((v, &x), &g), &b) in dp.iter_mut().zip(xp).zip(&gamma).zip(&beta)
                            {
                                *v *= gelu_slope(x * g + b);
                            }
                        }
                    }
                    Activation::Tanh => {
                        for (v, &o) in d.data.iter_mut().zip(&k.out.data) {
                            *v *= 1.0 - o * o;
                        }
                    }
                }
                let (s1, s2) = channel_sums2(&d.data, &k.xhat.data, c);
                (d, s1, s2)
            },
        );
        let mut d_gamma = vec![0.0f64; c];
        let mut d_beta = vec![0.0f64; c];
        for (_, s1, s2) in &staged {
            d_beta.iter_mut().zip(s1).for_each(|(a, b)| *a += b);
            d_gamma.iter_mut().zip(s2).for_each(|(a, b)| *a += b);
        }
        let norm = &self.norm;
        let (d_gamma_all, d_beta_all) = (&d_gamma, &d_beta);
        let per_image = s.map(
            staged.into_iter().zip(kept).collect(),
            |((mut d, s1, s2), k): ((Map, Vec<f64>, Vec<f64>), &&Kept)| {
                let (h, w) = (d.h, d.w);
                // dz -> gradient of the convolution's output y.
                match norm {
                    Norm::Batch { .. } => {
                        let inv = batch_inv_std.expect("batch statistics kept");
                        let n = (kept.len() * h * w) as f64;
                        let g: Vec<f64> = (0..c).map(|ch| f64::from(gamma[ch]) * inv[ch]).collect();
                        let m1: Vec<f32> = (0..c)
                            .map(|ch| (g[ch] * d_beta_all[ch] / n) as f32)
                            .collect();
                        let m2: Vec<f32> = (0..c)
                            .map(|ch| (g[ch] * d_gamma_all[ch] / n) as f32)
                            .collect();
                        let g: Vec<f32> = g.iter().map(|&v| v as f32).collect();
                        normalisation_grad(&mut d.data, &k.xhat.data, &g, &m1, &m2);
                    }
                    Norm::Group { groups, .. } => {
                        let cg = c / groups;
                        let n = (h * w * cg) as f64;
                        let (mut gs, mut m1, mut m2) =
                            (vec![0.0f32; c], vec![0.0f32; c], vec![0.0f32; c]);
                        for g in 0..*groups {
                            let chs = g * cg..(g + 1) * cg;
                            let t1: f64 = chs.clone().map(|ch| s1[ch] * f64::from(gamma[ch])).sum();
                            let t2: f64 = chs.clone().map(|ch| s2[ch] * f64::from(gamma[ch])).sum();
                            let inv = k.inv_std[g];
                            for ch in chs {
                                gs[ch] = (inv * f64::from(gamma[ch])) as f32;
                                m1[ch] = (inv * t1 / n) as f32;
                                m2[ch] = (inv * t2 / n) as f32;
                            }
                        }
                        normalisation_grad(&mut d.data, &k.xhat.data, &gs, &m1, &m2);
                    }
                    Norm::Identity => {}
                }
                d.zero_border();
                let bias = channel_sums(&d);
                let taps = conv3_weight_grad(&k.input, &d, s.par);
                let wino = self.conv.wino.as_ref().map(|w| &w.1);
                let dx =
                    input_grad.then(|| conv3(&d, &self.conv.flip, wino, self.conv.c_in, s.par));
                (dx, taps, bias)
            },
        );
        let mut grad = BlockGrad {
            taps: std::array::from_fn(|_| vec![0.0f32; 3 * self.conv.c_in * c]),
            bias: vec![0.0; c],
            gamma: d_gamma,
            beta: d_beta,
        };
        let mut dxs = Vec::with_capacity(per_image.len());
        for (dx, taps, bias) in per_image {
            for (a, b) in grad.taps.iter_mut().zip(&taps) {
                a.iter_mut().zip(b).for_each(|(x, y)| *x += y);
            }
            grad.bias.iter_mut().zip(&bias).for_each(|(a, b)| *a += b);
            dxs.push(dx);
        }
        (dxs, grad)
    }
}

/// Gradient of a max pooling: each output gradient goes to the first of its four inputs that
/// holds the maximum.
fn max_pool_grad(x: &Map, pooled: &Map, d: &Map) -> Map {
    let c = x.c;
    let mut out = Map::uninit(x.h, x.w, c);
    out.data.fill(0.0);
    for r in 0..pooled.h {
        for col in 0..pooled.w {
            let (p, q) = (pooled.at(r, col), d.at(r, col));
            let cand = [
                x.at(2 * r, 2 * col),
                x.at(2 * r, 2 * col) + c,
                x.at(2 * r + 1, 2 * col),
                x.at(2 * r + 1, 2 * col) + c,
            ];
            for ch in 0..c {
                let m = pooled.data[p + ch];
                if let Some(at) = cand.iter().find(|&&a| x.data[a + ch] == m) {
                    out.data[at + ch] += d.data[q + ch];
                }
            }
        }
    }
    out
}

/// Gradients of a per-pixel product of `x` with `weight` (`[c, n]` row-major; the head, a
/// transposed convolution) from the output gradient rows `g` (`[h (w + 2), n]`, the forward
/// product's rows, zero on the border columns): the input gradient as a map and the weight
/// gradient `[c, n]`.
fn pointwise_grads(x: &Map, g: &[f32], weight: &[f32], par: Par) -> (Map, Vec<f32>) {
    let (h, w, c, pw) = (x.h, x.w, x.c, x.w + 2);
    let m = h * pw;
    let n = weight.len() / c;
    let gm = MatRef::from_row_major_slice(g, m, n);
    let mut dx = Map::uninit(h, w, c);
    dx.data.fill(0.0);
    matmul(
        MatMut::from_row_major_slice_mut(&mut dx.data[pw * c..(pw + m) * c], m, c),
        Accum::Replace,
        gm,
        MatRef::from_row_major_slice(weight, c, n).transpose(),
        1.0f32,
        par,
    );
    dx.zero_border();
    let mut dw = vec![0.0f32; c * n];
    matmul(
        MatMut::from_row_major_slice_mut(&mut dw, c, n),
        Accum::Replace,
        MatRef::from_row_major_slice(&x.data[pw * c..(pw + m) * c], m, c).transpose(),
        gm,
        1.0f32,
        par,
    );
    (dx, dw)
}

/// Gradients of a 2 x 2 stride-2 transposed convolution from its output gradient `d`: the
/// input gradient, the weight `[c_in, 4 c_out]` and the bias.
fn up_backward(u: &Up, x: &Map, d: &Map, par: Par) -> (Map, Vec<f32>, Vec<f64>) {
    let (h, w, pw) = (x.h, x.w, x.w + 2);
    let co = u.c_out;
    let m = h * pw;
    // G: the output gradient gathered per input pixel (rows as in the forward product).
    let mut g = vec![0.0f32; m * 4 * co];
    for r in 0..h {
        for col in 0..w {
            let row = &mut g[(r * pw + col + 1) * 4 * co..][..4 * co];
            for k in 0..4 {
                let at = d.at(2 * r + k / 2, 2 * col + k % 2);
                row[k * co..(k + 1) * co].copy_from_slice(&d.data[at..at + co]);
            }
        }
    }
    let (dx, dw) = pointwise_grads(x, &g, &u.weight, par);
    (dx, dw, channel_sums(d))
}

/// The U-Net's weights copied out of burn for one training step (see the module
/// documentation).
pub struct TrainPass<'a> {
    net: &'a UNet,
    input: usize,
    output: usize,
    down: Vec<Block>,
    up: Vec<Up>,
    merge: Vec<Block>,
    /// 1 x 1 head, `[c, output]` row-major.
    head: Vec<f32>,
    head_bias: Vec<f32>,
}

/// One image's state through the forward pass.
struct Image {
    down: Vec<Kept>,
    merge: Vec<Kept>,
}

impl Image {
    /// The last decoder level's output (the head's input).
    fn top(&self) -> &Map {
        &self.merge.last().expect("a decoder level").out
    }
}

impl<'a> TrainPass<'a> {
    /// Copies the weights of `net`.
    pub fn new(net: &'a UNet) -> Result<Self> {
        let input = net.down[0].conv.weight.dims()[1];
        let down = net
            .down
            .iter()
            .map(Block::new)
            .collect::<Result<Vec<_>>>()?;
        let merge = net
            .merge
            .iter()
            .map(Block::new)
            .collect::<Result<Vec<_>>>()?;
        let up = net.up.iter().map(Up::new).collect::<Result<Vec<_>>>()?;
        if down.len() < 2 || up.len() + 1 != down.len() || merge.len() != up.len() {
            return Err(TactileError::Input(
                "plain training takes a U-Net with one decoder level per encoder level below the \
                 top"
                .into(),
            ));
        }
        let (head, output) = head_weights(&net.head)?;
        Ok(TrainPass {
            net,
            input,
            output,
            down,
            up,
            merge,
            head,
            head_bias: bias_of(&net.head, output),
        })
    }

    /// One training step's forward and backward pass on `[batch, input, h, w]`:
    /// `loss(outputs)` gets the network's `[batch, output, h, w]` and returns the loss and its
    /// gradient with respect to them. Returns the loss and the gradients of every parameter by
    /// id (on `device`, the plain device of the optimiser), and moves the running statistics of
    /// the batch normalisations as burn's training pass does.
    pub fn step(
        &self,
        x: &[f32],
        batch: usize,
        h: usize,
        w: usize,
        device: &Device,
        loss: impl FnOnce(&[f32]) -> Result<(f64, Vec<f32>)>,
    ) -> Result<(f64, GradientsParams)> {
        let per = check_batch(self.input, self.down.len(), x.len(), batch, h, w)?;
        let s = Sched::new(batch);
        // Encoder.
        let mut inputs: Vec<Map> = s.map(x.chunks_exact(per).collect(), |img| {
            Map::from_chw(img, self.input, h, w, Par::Seq)
        });
        let mut images: Vec<Image> = (0..batch)
            .map(|_| Image {
                down: Vec::new(),
                merge: Vec::new(),
            })
            .collect();
        let mut bn_inv: Vec<Option<Vec<f64>>> = Vec::new();
        let levels = self.down.len();
        for (l, blk) in self.down.iter().enumerate() {
            let (kept, stats) = blk.forward(inputs, s);
            bn_inv.push(self.move_running(&self.net.down[l], blk, stats));
            for (img, k) in images.iter_mut().zip(kept) {
                img.down.push(k);
            }
            inputs = if l + 1 < levels {
                s.map_ref(&images, |img| max_pool(&img.down[l].out, Par::Seq))
            } else {
                Vec::new()
            };
        }
        // Decoder.
        let mut merge_inv = Vec::new();
        for (k, (u, blk)) in self.up.iter().zip(&self.merge).enumerate() {
            let skip_level = levels - 2 - k;
            let cats = s.map_ref(&images, |img| {
                let below = if k == 0 {
                    &img.down[levels - 1].out
                } else {
                    &img.merge[k - 1].out
                };
                concat(&u.forward(below, Par::Seq), &img.down[skip_level].out)
            });
            let (kept, stats) = blk.forward(cats, s);
            merge_inv.push(self.move_running(&self.net.merge[k], blk, stats));
            for (img, kp) in images.iter_mut().zip(kept) {
                img.merge.push(kp);
            }
        }
        // Head.
        let (o, pw) = (self.output, w + 2);
        let c0 = images[0].top().c;
        let outs = s.map_ref(&images, |img| {
            head_forward(img.top(), &self.head, &self.head_bias, Par::Seq)
        });
        let (value, d_out) = loss(&outs.concat())?;
        if d_out.len() != batch * o * h * w {
            return Err(TactileError::Input(format!(
                "the loss gave {} output gradients for {batch} x {o} x {h} x {w}",
                d_out.len()
            )));
        }
        let mut grads = GradientsParams::new();
        if !value.is_finite() {
            return Ok((value, grads));
        }
        // Head backward: the gradient rows in the product layout.
        let head_parts = s.map(
            images.iter().enumerate().collect(),
            |(b, img): (usize, &Image)| {
                let m = h * pw;
                let mut g = vec![0.0f32; m * o];
                let src = &d_out[b * o * h * w..(b + 1) * o * h * w];
                for r in 0..h {
                    for col in 0..w {
                        for ch in 0..o {
                            g[(r * pw + col + 1) * o + ch] = src[(ch * h + r) * w + col];
                        }
                    }
                }
                let (dx, dw) = pointwise_grads(img.top(), &g, &self.head, Par::Seq);
                let db: Vec<f64> = (0..o)
                    .map(|ch| {
                        src[ch * h * w..(ch + 1) * h * w]
                            .iter()
                            .map(|&v| f64::from(v))
                            .sum()
                    })
                    .collect();
                (dx, dw, db)
            },
        );
        let mut d_head = vec![0.0f32; c0 * o];
        let mut d_head_bias = vec![0.0f64; o];
        let mut d = Vec::with_capacity(batch);
        for (dx, dw, db) in head_parts {
            d_head.iter_mut().zip(&dw).for_each(|(a, b)| *a += b);
            d_head_bias.iter_mut().zip(&db).for_each(|(a, b)| *a += b);
            d.push(dx);
        }
        let mut hw = vec![0.0f32; o * c0];
        for ch in 0..c0 {
            for oo in 0..o {
                hw[oo * c0 + ch] = d_head[ch * o + oo];
            }
        }
        register(
            &mut grads,
            self.net.head.weight.id,
            hw,
            [o, c0, 1, 1],
            device,
        );
        if let Some(b) = &self.net.head.bias {
            register(&mut grads, b.id, to_f32(&d_head_bias), [o], device);
        }
        // Decoder backward, top level first; the skips' gradients wait for their encoder level.
        let mut skip_grads: Vec<Option<Vec<Map>>> = (0..levels).map(|_| None).collect();
        for k in (0..self.merge.len()).rev() {
            let blk = &self.merge[k];
            let kept: Vec<&Kept> = images.iter().map(|img| &img.merge[k]).collect();
            let (dxs, g) = blk.backward(&kept, d, true, merge_inv[k].as_deref(), s);
            self.register_block(&mut grads, blk, &g, device);
            let cu = self.up[k].c_out;
            let splits = s.map(dxs, |dx| split(&dx.expect("input gradient asked"), cu));
            let (d_up, d_skip): (Vec<Map>, Vec<Map>) = splits.into_iter().unzip();
            skip_grads[levels - 2 - k] = Some(d_skip);
            // The upsampling's input: the bottleneck (k = 0) or the decoder level below.
            let u = &self.up[k];
            let ups = s.map(
                d_up.into_iter().zip(&images).collect(),
                |(du, img): (Map, &Image)| {
                    let below = if k == 0 {
                        &img.down[levels - 1].out
                    } else {
                        &img.merge[k - 1].out
                    };
                    up_backward(u, below, &du, Par::Seq)
                },
            );
            let mut dw = vec![0.0f32; u.c_in * 4 * u.c_out];
            let mut db = vec![0.0f64; u.c_out];
            d = Vec::with_capacity(batch);
            for (dx, w4, b) in ups {
                dw.iter_mut().zip(&w4).for_each(|(a, x)| *a += x);
                db.iter_mut().zip(&b).for_each(|(a, x)| *a += x);
                d.push(dx);
            }
            let (ci, co) = (u.c_in, u.c_out);
            let mut wb = vec![0.0f32; ci * co * 4];
            for i in 0..ci {
                for j in 0..co {
                    for kk in 0..4 {
                        wb[(i * co + j) * 4 + kk] = dw[i * 4 * co + kk * co + j];
                    }
                }
            }
            let bu = &self.net.up[k];
            register(&mut grads, bu.weight.id, wb, [ci, co, 2, 2], device);
            if let Some(b) = &bu.bias {
                register(&mut grads, b.id, to_f32(&db), [co], device);
            }
        }
        // Encoder backward, bottleneck first: d holds the gradient of level l's output.
        for l in (0..levels).rev() {
            if let Some(skip) = skip_grads[l].take() {
                for (a, b) in d.iter_mut().zip(&skip) {
                    a.data.iter_mut().zip(&b.data).for_each(|(x, y)| *x += y);
                }
            }
            let blk = &self.down[l];
            let kept: Vec<&Kept> = images.iter().map(|img| &img.down[l]).collect();
            let (dxs, g) = blk.backward(&kept, d, l > 0, bn_inv[l].as_deref(), s);
            self.register_block(&mut grads, blk, &g, device);
            d = if l > 0 {
                s.map(
                    dxs.into_iter().zip(&images).collect(),
                    |(dx, img): (Option<Map>, &Image)| {
                        let dx = dx.expect("input gradient asked");
                        max_pool_grad(&img.down[l - 1].out, &img.down[l].input, &dx)
                    },
                )
            } else {
                Vec::new()
            };
        }
        Ok((value, grads))
    }

    /// Moves a batch normalisation's running statistics towards the batch's (burn's
    /// momentum update) and returns 1 / std of the batch per channel.
    fn move_running(
        &self,
        b: &ConvBlock,
        blk: &Block,
        stats: Option<BatchStats>,
    ) -> Option<Vec<f64>> {
        let (Norm::Batch { eps, momentum, .. }, Some(bn), Some((mean, var))) =
            (&blk.norm, &b.batch, stats)
        else {
            return None;
        };
        let device = bn.running_mean.value().device();
        let moved = |old: Vec<f32>, new: &[f64]| -> Vec<f32> {
            old.iter()
                .zip(new)
                .map(|(&o, &n)| ((1.0 - momentum) * f64::from(o) + momentum * n) as f32)
                .collect()
        };
        let c = mean.len();
        let rm = moved(values(bn.running_mean.value_sync()), &mean);
        let rv = moved(values(bn.running_var.value_sync()), &var);
        bn.running_mean
            .update(Tensor::from_data(TensorData::new(rm, [c]), &device));
        bn.running_var
            .update(Tensor::from_data(TensorData::new(rv, [c]), &device));
        Some(var.iter().map(|v| 1.0 / (v + eps).sqrt()).collect())
    }

    /// Registers a block's gradients under its burn parameters' ids.
    fn register_block(
        &self,
        grads: &mut GradientsParams,
        blk: &Block,
        g: &BlockGrad,
        device: &Device,
    ) {
        let (ci, co) = (blk.conv.c_in, blk.conv.c_out);
        register(
            grads,
            blk.conv.ids.0,
            blk.conv.to_burn(&g.taps),
            [co, ci, 3, 3],
            device,
        );
        if let Some(id) = blk.conv.ids.1 {
            register(grads, id, to_f32(&g.bias), [co], device);
        }
        if let Some((gid, bid)) = blk.norm_ids {
            register(grads, gid, to_f32(&g.gamma), [co], device);
            register(grads, bid, to_f32(&g.beta), [co], device);
        }
    }
}

fn to_f32(v: &[f64]) -> Vec<f32> {
    v.iter().map(|&x| x as f32).collect()
}

fn register<const D: usize>(
    grads: &mut GradientsParams,
    id: ParamId,
    v: Vec<f32>,
    shape: [usize; D],
    device: &Device,
) {
    grads.register(
        id,
        Tensor::<D>::from_data(TensorData::new(v, shape), device),
    );
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::nets::{NetConfig, NetData, NetKind, coordinate_channels};
    use ocm_learn::burn::optim::GradientsParams;
    use ocm_learn::{cpu, cpu_autodiff};

    fn wave(n: usize, k: usize, scale: f32, offset: f32) -> Vec<f32> {
        (0..n)
            .map(|i| {
                offset
                    + scale * ((i * 7 + k * 3) as f32 * 0.37).sin() * ((i % 13) as f32 * 0.21).cos()
            })
            .collect()
    }

    /// A small data set of `kind` with every loss term switched on.
    fn data(kind: NetKind, rows: usize, cols: usize, samples: usize) -> NetData {
        let n = rows * cols;
        // Targets: a smooth bump per sample, so the masks have contact and background.
        let bump = |s: usize, p: usize| {
            let (r, c) = ((p / cols) as f32, (p % cols) as f32);
            let (r0, c0) = (rows as f32 * (0.3 + 0.1 * s as f32), cols as f32 * 0.5);
            (-((r - r0).powi(2) + (c - c0).powi(2)) / (0.05 * n as f32)).exp()
        };
        let (input_channels, target_channels, coords) = match kind {
            NetKind::Perception => (3, 1, Vec::new()),
            NetKind::Rendering => (1, 3, coordinate_channels(rows, cols)),
        };
        let mut target = Vec::new();
        let mut mask = Vec::new();
        for s in 0..samples {
            for ch in 0..target_channels {
                for p in 0..n {
                    target.push(match kind {
                        NetKind::Perception => 1.05 - 0.9 * bump(s, p),
                        NetKind::Rendering => 0.3 * bump(s, p) * (ch as f32 - 1.0),
                    });
                }
            }
            for p in 0..n {
                mask.push(f32::from(bump(s, p) > 0.3));
            }
        }
        NetData {
            kind,
            rows,
            cols,
            input: wave(samples * input_channels * n, 1, 1.0, 0.1),
            input_channels,
            target,
            target_channels,
            mask,
            mask_loss_weight: 0.3,
            iou_loss_weight: 0.2,
            force_loss_weight: if kind == NetKind::Perception {
                2e-3
            } else {
                0.0
            },
            force_weight: if kind == NetKind::Perception {
                wave(samples * n, 5, 40.0, 10.0)
            } else {
                Vec::new()
            },
            coords,
        }
    }

    /// Every parameter of the U-Net: (name, id, values of `grads` there).
    fn named_grads(net: &UNet, grads: &GradientsParams) -> Vec<(String, Vec<f32>)> {
        let mut out = Vec::new();
        let mut add = |name: String, id: ParamId, d: usize| {
            let v = match d {
                1 => grads.get::<1>(id).map(values),
                _ => grads.get::<4>(id).map(values),
            };
            out.push((name, v.unwrap_or_default()));
        };
        for (tag, blocks) in [("down", &net.down), ("merge", &net.merge)] {
            for (l, b) in blocks.iter().enumerate() {
                add(format!("{tag}{l}.w"), b.conv.weight.id, 4);
                if let Some(bias) = &b.conv.bias {
                    add(format!("{tag}{l}.b"), bias.id, 1);
                }
                if let Some(bn) = &b.batch {
                    add(format!("{tag}{l}.bn.gamma"), bn.gamma.id, 1);
                    add(format!("{tag}{l}.bn.beta"), bn.beta.id, 1);
                }
                if let Some(gn) = &b.group {
                    add(
                        format!("{tag}{l}.gn.gamma"),
                        gn.gamma.as_ref().map(|g| g.id).unwrap(),
                        1,
                    );
                    add(
                        format!("{tag}{l}.gn.beta"),
                        gn.beta.as_ref().map(|g| g.id).unwrap(),
                        1,
                    );
                }
            }
        }
        for (k, u) in net.up.iter().enumerate() {
            add(format!("up{k}.w"), u.weight.id, 4);
            if let Some(b) = &u.bias {
                add(format!("up{k}.b"), b.id, 1);
            }
        }
        add("head.w".into(), net.head.weight.id, 4);
        if let Some(b) = &net.head.bias {
            add("head.b".into(), b.id, 1);
        }
        out
    }

    /// The plain passes' loss, parameter gradients and running statistics against burn's
    /// autodiff of [`NetData::loss`] on the same weights.
    fn check(kind: NetKind, rows: usize, cols: usize, batch: usize) {
        let d = data(kind, rows, cols, batch + 1);
        let cfg = match kind {
            NetKind::Perception => NetConfig::perception(rows, cols),
            NetKind::Rendering => NetConfig::rendering(rows, cols),
        };
        let dev = cpu_autodiff();
        // Two nets from one seed: their running statistics must not be shared.
        let burn_net = cfg.init(&dev, 7).unwrap();
        let plain_net = cfg.init(&dev, 7).unwrap();
        let idx: Vec<usize> = (0..batch).collect();
        let t: Vec<usize> = (1..=batch).collect();
        let l = d.loss(&burn_net, &idx, &t, &dev);
        let want_loss = f64::from(l.clone().into_scalar::<f32>());
        let want = GradientsParams::from_grads(l.backward(), &burn_net);
        let pass = TrainPass::new(&plain_net).unwrap();
        let (got_loss, got) = pass
            .step(&d.input_values(&idx), batch, rows, cols, &cpu(), |out| {
                d.loss_and_grad(out, &idx, &t)
            })
            .unwrap();
        assert!(
            (got_loss - want_loss).abs() <= 1e-5 * want_loss.abs(),
            "{kind:?} loss {got_loss} against burn's {want_loss}"
        );
        let (w, g) = (named_grads(&burn_net, &want), named_grads(&plain_net, &got));
        assert_eq!(w.len(), g.len());
        for ((name, a), (_, b)) in w.iter().zip(&g) {
            assert_eq!(a.len(), b.len(), "{kind:?} {name}: sizes");
            assert!(!a.is_empty(), "{kind:?} {name}: burn has no gradient");
            let scale = a.iter().fold(0.0f32, |m, v| m.max(v.abs()));
            let worst = a
                .iter()
                .zip(b)
                .fold(0.0f32, |m, (x, y)| m.max((x - y).abs()));
            // A batch normalisation's conv bias has no effect on the loss: both gradients are
            // round-off of sums that cancel.
            let bias_under_bn = name.ends_with(".b")
                && !name.starts_with("up")
                && !name.starts_with("head")
                && kind == NetKind::Perception;
            // Measured: within 1.5e-5 of each parameter's largest gradient (with the direct
            // convolutions and with Winograd's alike).
            let tol = if bias_under_bn { 1e-4 } else { 1e-4 * scale };
            assert!(
                worst <= tol,
                "{kind:?} {name}: worst difference {worst:e} of {scale:e}"
            );
        }
        // The running statistics moved alike.
        for (a, b) in burn_net
            .down
            .iter()
            .chain(&burn_net.merge)
            .zip(plain_net.down.iter().chain(&plain_net.merge))
        {
            if let (Some(x), Some(y)) = (&a.batch, &b.batch) {
                for (p, q) in [
                    (&x.running_mean, &y.running_mean),
                    (&x.running_var, &y.running_var),
                ] {
                    let (p, q) = (values(p.value()), values(q.value()));
                    let worst = p
                        .iter()
                        .zip(&q)
                        .fold(0.0f32, |m, (u, v)| m.max((u - v).abs()));
                    assert!(
                        worst <= 1e-5,
                        "{kind:?} running statistics differ by {worst:e}"
                    );
                }
            }
        }
    }

    #[test]
    fn perception_gradients_match_burns_autodiff() {
        check(NetKind::Perception, 16, 24, 3);
    }

    #[test]
    fn rendering_gradients_match_burns_autodiff() {
        check(NetKind::Rendering, 12, 16, 2);
    }

    #[test]
    fn one_image_on_the_pool_matches_burns_autodiff() {
        check(NetKind::Perception, 8, 8, 1);
    }
}
