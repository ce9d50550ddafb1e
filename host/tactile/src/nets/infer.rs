//! Plain inference of a trained [`UNet`] for full-size images: the weights are copied out of
//! the burn modules once (batch normalisation folded into the convolutions), each image runs
//! channel-last with a one-pixel zero border, and every 3 x 3 convolution is three matrix
//! products on overlapping views of that buffer (no im2col copy), through faer's kernels in
//! `f32` or the [`bf16`] kernel in bfloat16 ([`Precision`]). Images of a batch run in parallel
//! on the current rayon pool; one image runs its products and the passes between them there.
//! It mirrors [`UNet::forward`] with running statistics (evaluation) and is tested against it.

use faer::linalg::matmul::matmul;
use faer::{Accum, MatMut, MatRef, Par};
use ocm_learn::burn::nn::PaddingConfig2d;
use ocm_learn::burn::nn::conv::{Conv2d, ConvTranspose2d};
use ocm_learn::mlp::Activation;
use ocm_learn::unet::ConvBlock;
use ocm_learn::{UNet, values};
use rayon::prelude::*;

use super::bf16;
use super::map::{Map, give, give_half, on_pool, take, take_half};
use super::winograd;
use crate::{Result, TactileError};
use serde::{Deserialize, Serialize};

/// Arithmetic of the plain engine's convolutions.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Precision {
    /// `f32` throughout (faer's kernels), the same values as burn's graph to round-off.
    #[default]
    F32,
    /// The 3 x 3 convolutions and the upsamplings with bfloat16 weights and inputs and `f32`
    /// sums (AVX-512 BF16 where the CPU has it); the 1 x 1 head, normalisations and
    /// activations stay `f32`. The perception network's input, grey-level differences over
    /// 32, is exact in bfloat16 (integers up to 256 are).
    Bf16,
    /// `f32` with the 3 x 3 convolutions by Winograd's F(4 x 4, 3 x 3) ([`winograd`]) where
    /// the maps are whole tiles and the channels whole vectors (the others direct): a quarter
    /// of the multiplications, outputs within round-off of the direct ones, on any CPU.
    Winograd,
}

impl std::str::FromStr for Precision {
    type Err = TactileError;
    fn from_str(s: &str) -> Result<Self> {
        match s {
            "f32" => Ok(Precision::F32),
            "bf16" => Ok(Precision::Bf16),
            "winograd" => Ok(Precision::Winograd),
            other => Err(TactileError::Input(format!(
                "precision must be f32, bf16 or winograd, got {other:?}"
            ))),
        }
    }
}

/// A map's values rounded to bfloat16 (same layout, two zeros appended: a pair read past an
/// odd row stays inside), in a pooled buffer.
struct HalfMap(Vec<u16>);

impl HalfMap {
    fn of(x: &Map, par: Par) -> Self {
        let n = x.data.len();
        let mut v = take_half(n + 2);
        if on_pool(par) {
            const CHUNK: usize = 1 << 16;
            v[..n]
                .par_chunks_mut(CHUNK)
                .zip(x.data.par_chunks(CHUNK))
                .for_each(|(d, s)| bf16::convert(s, d));
        } else {
            bf16::convert(&x.data, &mut v[..n]);
        }
        v[n..].fill(0);
        HalfMap(v)
    }
}

impl Drop for HalfMap {
    fn drop(&mut self) {
        let v = std::mem::take(&mut self.0);
        give_half(v);
    }
}

/// One input's share of a 3 x 3 convolution: for each kernel row dy a `[3 c_in, c_out]`
/// row-major matrix whose rows run over (dx, input channel).
#[derive(Debug, Clone)]
struct Conv3Part {
    c_in: usize,
    taps: [Vec<f32>; 3],
    /// The taps packed for the bfloat16 kernel ([`Precision::Bf16`]).
    packed: Option<[bf16::Packed; 3]>,
    /// The taps in Winograd's domain ([`Precision::Winograd`]).
    wino: Option<winograd::Weights>,
}

/// Convolution, normalisation and nonlinearity of one level.
#[derive(Debug, Clone)]
struct Block {
    /// One part per input map (the encoder has one; a decoder level has the upsampled map and
    /// the skip, whose concatenation is the sum of two convolutions).
    parts: Vec<Conv3Part>,
    c_out: usize,
    /// Bias after the convolution (with batch normalisation folded in).
    bias: Vec<f32>,
    /// Group normalisation: groups, gamma, beta, epsilon.
    group: Option<(usize, Vec<f32>, Vec<f32>, f32)>,
    activation: Activation,
}

/// A 2 x 2 stride-2 transposed convolution: `[c_in, 4 c_out]` row-major, columns over
/// (ky, kx, output channel).
#[derive(Debug, Clone)]
pub(super) struct Up {
    pub(super) c_in: usize,
    pub(super) c_out: usize,
    pub(super) weight: Vec<f32>,
    pub(super) bias: Vec<f32>,
    /// The weight packed for the bfloat16 kernel ([`Precision::Bf16`]).
    packed: Option<bf16::Packed>,
}

/// The U-Net's weights as plain values (see the module documentation).
#[derive(Debug, Clone)]
pub struct PlainUNet {
    input: usize,
    output: usize,
    down: Vec<Block>,
    up: Vec<Up>,
    merge: Vec<Block>,
    /// 1 x 1 head, `[c, output]` row-major.
    head: Vec<f32>,
    head_bias: Vec<f32>,
    precision: Precision,
}

pub(super) fn bias_of(conv: &Conv2d, c_out: usize) -> Vec<f32> {
    conv.bias
        .as_ref()
        .map_or_else(|| vec![0.0; c_out], |b| values(b.val()))
}

pub(super) fn check_conv(conv: &Conv2d, what: &str, kernel: usize) -> Result<[usize; 4]> {
    let d = conv.weight.dims();
    let pad = if kernel == 3 {
        PaddingConfig2d::Explicit(1, 1, 1, 1)
    } else {
        PaddingConfig2d::Valid
    };
    let same_size = conv.padding == pad
        || (conv.padding == PaddingConfig2d::Same)
        || (kernel == 1 && conv.padding == PaddingConfig2d::Explicit(0, 0, 0, 0));
    if !same_size
        || d[2] != kernel
        || d[3] != kernel
        || conv.stride != [1, 1]
        || conv.dilation != [1, 1]
        || conv.groups != 1
    {
        return Err(TactileError::Input(format!(
            "{what}: plain inference takes {kernel} x {kernel} convolutions of stride 1 that \
             keep the size, got weights {d:?}, stride {:?}, padding {:?}",
            conv.stride, conv.padding
        )));
    }
    Ok(d)
}

impl Block {
    /// From a block whose inputs have `splits` channels (concatenated in that order).
    fn new(b: &ConvBlock, splits: &[usize]) -> Result<Self> {
        let [c_out, c_in, _, _] = check_conv(&b.conv, "U-Net block", 3)?;
        if splits.iter().sum::<usize>() != c_in {
            return Err(TactileError::Input(format!(
                "U-Net block takes {c_in} channels, its inputs have {splits:?}"
            )));
        }
        let w = values(b.conv.weight.val());
        let mut bias = bias_of(&b.conv, c_out);
        // Batch normalisation with running statistics is an affine map per output channel.
        let mut scale = vec![1.0f32; c_out];
        if let Some(bn) = &b.batch {
            let (g, be) = (values(bn.gamma.val()), values(bn.beta.val()));
            let (mean, var) = (
                values(bn.running_mean.value()),
                values(bn.running_var.value()),
            );
            for co in 0..c_out {
                let s = g[co] / (var[co] + bn.epsilon as f32).sqrt();
                scale[co] = s;
                bias[co] = (bias[co] - mean[co]) * s + be[co];
            }
        }
        let mut parts = Vec::new();
        let mut offset = 0;
        for &ci_n in splits {
            let taps = std::array::from_fn(|dy| {
                let mut t = vec![0.0f32; 3 * ci_n * c_out];
                for dx in 0..3 {
                    for ci in 0..ci_n {
                        for co in 0..c_out {
                            t[(dx * ci_n + ci) * c_out + co] =
                                w[((co * c_in + offset + ci) * 3 + dy) * 3 + dx] * scale[co];
                        }
                    }
                }
                t
            });
            parts.push(Conv3Part {
                c_in: ci_n,
                taps,
                packed: None,
                wino: None,
            });
            offset += ci_n;
        }
        let group = match &b.group {
            Some(gn) => {
                let ones = vec![1.0; c_out];
                let zeros = vec![0.0; c_out];
                let gamma = gn.gamma.as_ref().map_or(ones, |g| values(g.val()));
                let beta = gn.beta.as_ref().map_or(zeros, |g| values(g.val()));
                Some((gn.num_groups, gamma, beta, gn.epsilon as f32))
            }
            None => None,
        };
        Ok(Block {
            parts,
            c_out,
            bias,
            group,
            activation: b.activation(),
        })
    }

    /// The inputs with their Winograd weights, when every part has them and the maps fit.
    fn winograd_inputs<'a>(
        &'a self,
        inputs: &[&'a Map],
    ) -> Option<Vec<(&'a Map, &'a winograd::Weights)>> {
        let (h, w) = (inputs[0].h, inputs[0].w);
        let cs: Vec<usize> = inputs.iter().map(|x| x.c).collect();
        if !winograd::fits(h, w, &cs, self.c_out) {
            return None;
        }
        inputs
            .iter()
            .zip(&self.parts)
            .map(|(x, p)| p.wino.as_ref().map(|wt| (*x, wt)))
            .collect()
    }

    /// Convolution of the inputs (same size, channels as the parts), normalisation, activation.
    fn forward(&self, inputs: &[&Map], par: Par) -> Map {
        let (h, w) = (inputs[0].h, inputs[0].w);
        let pw = w + 2;
        // Output rows over (r, padded column): the last two columns of each row are unused.
        let m = h * pw;
        let c_out = self.c_out;
        // Product row q = r (w + 2) + col is interior pixel (r, col) of the output map, at
        // padded index q + w + 3: the product is written straight into the map, its two unused
        // columns per row landing on the border, which is zeroed afterwards.
        let mut out = Map::uninit(h, w, c_out);
        let start = (pw + 1) * c_out;
        let dst = &mut out.data[start..start + m * c_out];
        if self.parts.iter().all(|p| p.packed.is_some()) {
            // The same shifted views as below, over bfloat16 copies of the inputs, summed in
            // one fused product.
            let halves: Vec<HalfMap> = inputs.iter().map(|x| HalfMap::of(x, par)).collect();
            let mut terms = Vec::with_capacity(3 * self.parts.len());
            for ((part, x), half) in self.parts.iter().zip(inputs).zip(&halves) {
                let c = part.c_in;
                debug_assert_eq!(x.c, c);
                for (dy, b) in part.packed.iter().flatten().enumerate() {
                    terms.push(bf16::Term {
                        src: &half.0,
                        offset: dy * pw * c,
                        stride: c,
                        b,
                    });
                }
            }
            bf16::product(&terms, m, dst, on_pool(par));
        } else if let Some(wino) = self.winograd_inputs(inputs) {
            winograd::conv3(dst, &wino, c_out, par);
        } else {
            conv3_f32(
                dst,
                self.parts
                    .iter()
                    .zip(inputs)
                    .map(|(part, x)| (*x, &part.taps)),
                c_out,
                par,
            );
        }
        out.zero_border();
        let bias = &self.bias;
        let c = c_out;
        match (&self.group, self.activation) {
            // Bias and ReLU in one pass over the row (perception's every block).
            (None, Activation::Relu) => out.for_rows(par, |_, row| {
                for px in row.chunks_exact_mut(c) {
                    for (v, b) in px.iter_mut().zip(bias) {
                        *v = (*v + b).max(0.0);
                    }
                }
            }),
            (None, act) => out.for_rows(par, |_, row| {
                for px in row.chunks_exact_mut(c) {
                    px.iter_mut().zip(bias).for_each(|(v, b)| *v += b);
                }
                activate(row, act);
            }),
            (Some((groups, gamma, beta, eps)), act) => {
                group_norm(&mut out, bias, *groups, gamma, beta, *eps, act, par);
            }
        }
        out
    }
}

/// The f32 3 x 3 convolution of maps of one size, summed over `inputs` (each with its taps, one
/// `[3 c_in, c_out]` row-major matrix per kernel row, rows over (dx, input channel)), written
/// into `dst`: `h (w + 2)` product rows of `c_out` values, row q = r (w + 2) + col being the
/// output pixel (r, col) (columns w and w + 1 of each row are junk the caller puts on a border).
pub(super) fn conv3_f32<'a>(
    dst: &mut [f32],
    inputs: impl Iterator<Item = (&'a Map, &'a [Vec<f32>; 3])>,
    c_out: usize,
    par: Par,
) {
    let mut accum = Accum::Replace;
    for (x, taps) in inputs {
        let (c, pw) = (x.c, x.w + 2);
        let m = x.h * pw;
        for (dy, tap) in taps.iter().enumerate() {
            // Row q of this view is the 3 x c values of the pixels (r + dy, col .. col + 3) of
            // the padded input, consecutive rows overlapping by 2 c. faer checks that the last
            // element, (m - 1) c + 3 c - 1 past the start, lies in the slice (the map keeps 2
            // spare pixels for dy = 2).
            let a = MatRef::from_row_major_slice_with_stride(&x.data[dy * pw * c..], m, 3 * c, c);
            let b = MatRef::from_row_major_slice(tap, 3 * c, c_out);
            matmul(
                MatMut::from_row_major_slice_mut(&mut dst[..m * c_out], m, c_out),
                accum,
                a,
                b,
                1.0f32,
                par,
            );
            accum = Accum::Add;
        }
    }
}

/// Applies `act` to every value (each maps 0 to 0, so the zero border stays zero).
fn activate(v: &mut [f32], act: Activation) {
    match act {
        Activation::Relu => v.iter_mut().for_each(|x| *x = x.max(0.0)),
        Activation::Gelu => gelu(v),
        Activation::Tanh => v.iter_mut().for_each(|x| *x = x.tanh()),
    }
}

/// Adds `bias`, applies group normalisation over the interior pixels (per group of channels,
/// mean and variance over all its values, as burn's `GroupNorm`; the sums in f64, per row and
/// then over the rows in order, so one image on the pool and a batch agree) and the
/// per-channel affine map, then `act`, in place.
#[allow(clippy::too_many_arguments)]
fn group_norm(
    x: &mut Map,
    bias: &[f32],
    groups: usize,
    gamma: &[f32],
    beta: &[f32],
    eps: f32,
    act: Activation,
    par: Par,
) {
    let (c, cg) = (x.c, x.c / groups);
    let n = (x.h * x.w * cg) as f64;
    let rows = x.map_rows(par, |_, row| {
        let mut sum = vec![0.0f64; c];
        let mut sq = vec![0.0f64; c];
        for px in row.chunks_exact_mut(c) {
            for (((v, b), s), q) in px.iter_mut().zip(bias).zip(&mut sum).zip(&mut sq) {
                *v += b;
                let v = f64::from(*v);
                *s += v;
                *q += v * v;
            }
        }
        (sum, sq)
    });
    let mut sum = vec![0.0f64; c];
    let mut sq = vec![0.0f64; c];
    for (rs, rq) in &rows {
        sum.iter_mut().zip(rs).for_each(|(a, b)| *a += b);
        sq.iter_mut().zip(rq).for_each(|(a, b)| *a += b);
    }
    let mut scale = vec![0.0f32; c];
    let mut shift = vec![0.0f32; c];
    for g in 0..groups {
        let mean = sum[g * cg..(g + 1) * cg].iter().sum::<f64>() / n;
        let var = (sq[g * cg..(g + 1) * cg].iter().sum::<f64>() / n - mean * mean).max(0.0);
        let inv = 1.0 / (var + f64::from(eps)).sqrt();
        for ch in g * cg..(g + 1) * cg {
            scale[ch] = (inv * f64::from(gamma[ch])) as f32;
            shift[ch] = (f64::from(beta[ch]) - mean * inv * f64::from(gamma[ch])) as f32;
        }
    }
    x.for_rows(par, |_, row| {
        for px in row.chunks_exact_mut(c) {
            for ((v, s), t) in px.iter_mut().zip(&scale).zip(&shift) {
                *v = *v * s + t;
            }
        }
        activate(row, act);
    });
}

/// e^y for y <= 0 without a library call, so the loops around it vectorise: y = k ln 2 + f with
/// |f| <= ln 2 / 2, e^f by its Taylor polynomial to degree 7 (relative error below 2e-8), and
/// 2^k through the exponent bits; below -87 it is 0.
#[inline(always)]
fn exp_neg(y_in: f32) -> f32 {
    const ROUND: f32 = 12_582_912.0; // 1.5 * 2^23: adding and subtracting it rounds to integer
    let y = y_in.max(-87.0);
    let k = (y * std::f32::consts::LOG2_E + ROUND) - ROUND;
    // ln 2 split in two so k ln 2 is exact to f32 precision.
    let f = (y - k * 0.693_145_75) - k * 1.428_606_8e-6;
    let p = 1.0
        + f * (1.0
            + f * (0.5
                + f * (1.0 / 6.0
                    + f * (1.0 / 24.0
                        + f * (1.0 / 120.0 + f * (1.0 / 720.0 + f * (1.0 / 5040.0)))))));
    // Wrapping arithmetic: k + 127 lies in 1..=127 here, and an overflow check would keep the
    // loop from vectorising (the dev profile checks overflow).
    let v = p * f32::from_bits(((k as i32).wrapping_add(127) as u32).wrapping_shl(23));
    if y_in < -87.0 { 0.0 } else { v }
}

/// GELU with the exact (erf) form, in place: erf through the rational approximation 7.1.26 of
/// Abramowitz and Stegun (absolute error below 1.5e-7), written so the loop vectorises (the
/// burn backend calls libm's erf per value, which dominated the rendering network's time). The
/// loop is compiled for the widest vector instructions the CPU has, chosen at run time (the
/// crate itself is built for baseline x86-64, whose SSE2 holds 4 values per instruction).
pub(super) fn gelu(v: &mut [f32]) {
    /// pulp's dispatch inlines `with_simd` into a function compiled with the detected target
    /// features (a closure's body would not be).
    struct Gelu<'a>(&'a mut [f32]);
    impl pulp::WithSimd for Gelu<'_> {
        type Output = ();
        #[inline(always)]
        fn with_simd<S: pulp::Simd>(self, _simd: S) {
            gelu_inline(self.0);
        }
    }
    pulp::Arch::new().dispatch(Gelu(v));
}

/// 1 + erf(x / sqrt 2) (twice the standard normal CDF) and e^(-x^2 / 2): erf through the
/// rational approximation 7.1.26 of Abramowitz and Stegun (absolute error below 1.5e-7),
/// written so loops around it vectorise.
#[inline(always)]
pub(super) fn normal_cdf2_and_gauss(x: f32) -> (f32, f32) {
    const P: f32 = 0.327_591_1;
    const A: [f32; 5] = [
        0.254_829_6,
        -0.284_496_74,
        1.421_413_7,
        -1.453_152_1,
        1.061_405_4,
    ];
    let z = x.abs() * std::f32::consts::FRAC_1_SQRT_2;
    let t = 1.0 / (1.0 + P * z);
    let poly = t * (A[0] + t * (A[1] + t * (A[2] + t * (A[3] + t * A[4]))));
    let gauss = exp_neg(-z * z);
    // 1 - erf(|x| / sqrt 2): taken directly for negative x, where 1 + erf cancels.
    let tail = poly * gauss;
    (if x < 0.0 { tail } else { 2.0 - tail }, gauss)
}

/// [`gelu`]'s loop.
#[inline(always)]
fn gelu_inline(v: &mut [f32]) {
    for x in v.iter_mut() {
        *x *= 0.5 * normal_cdf2_and_gauss(*x).0;
    }
}

pub(super) fn max_pool(x: &Map, par: Par) -> Map {
    let (h, w, c) = (x.h / 2, x.w / 2, x.c);
    let mut out = Map::uninit(h, w, c);
    out.zero_border();
    out.for_rows(par, |r, row| {
        for (col, px) in row.chunks_exact_mut(c).enumerate() {
            let (a, b) = (x.at(2 * r, 2 * col), x.at(2 * r + 1, 2 * col));
            for (ch, v) in px.iter_mut().enumerate() {
                *v = x.data[a + ch]
                    .max(x.data[a + c + ch])
                    .max(x.data[b + ch])
                    .max(x.data[b + c + ch]);
            }
        }
    });
    out
}

impl Up {
    pub(super) fn new(u: &ConvTranspose2d) -> Result<Self> {
        let d = u.weight.dims();
        if d[2] != 2
            || d[3] != 2
            || u.stride != [2, 2]
            || u.groups != 1
            || u.padding != [0, 0]
            || u.padding_out != [0, 0]
            || u.dilation != [1, 1]
        {
            return Err(TactileError::Input(format!(
                "U-Net upsampling: plain inference takes 2 x 2 stride-2 transposed convolutions, \
                 got weights {d:?}, stride {:?}",
                u.stride
            )));
        }
        let (c_in, c_out) = (d[0], d[1]);
        let w = values(u.weight.val());
        let mut weight = vec![0.0f32; c_in * 4 * c_out];
        for ci in 0..c_in {
            for co in 0..c_out {
                for k in 0..4 {
                    weight[ci * 4 * c_out + k * c_out + co] = w[(ci * c_out + co) * 4 + k];
                }
            }
        }
        let bias = u
            .bias
            .as_ref()
            .map_or_else(|| vec![0.0; c_out], |b| values(b.val()));
        Ok(Up {
            c_in,
            c_out,
            weight,
            bias,
            packed: None,
        })
    }

    pub(super) fn forward(&self, x: &Map, par: Par) -> Map {
        let (h, w, pw) = (x.h, x.w, x.w + 2);
        let (ci, co) = (self.c_in, self.c_out);
        // Every pixel of the interior rows (borders included, they are zero) times the weights.
        let m = h * pw;
        let mut acc = take(m * 4 * co);
        if let Some(b) = &self.packed {
            let half = HalfMap::of(x, par);
            let term = bf16::Term {
                src: &half.0,
                offset: pw * ci,
                stride: ci,
                b,
            };
            bf16::product(&[term], m, &mut acc, on_pool(par));
        } else {
            let a = MatRef::from_row_major_slice(&x.data[pw * ci..(pw + m) * ci], m, ci);
            let b = MatRef::from_row_major_slice(&self.weight, ci, 4 * co);
            matmul(
                MatMut::from_row_major_slice_mut(&mut acc, m, 4 * co),
                Accum::Replace,
                a,
                b,
                1.0f32,
                par,
            );
        }
        let mut out = Map::uninit(2 * h, 2 * w, co);
        out.zero_border();
        let bias = &self.bias;
        // Output row R comes from input row R / 2, kernel row R % 2.
        out.for_rows(par, |rr, row| {
            let (r, ky) = (rr / 2, rr % 2);
            for (cc, px) in row.chunks_exact_mut(co).enumerate() {
                let (col, kx) = (cc / 2, cc % 2);
                let k = 2 * ky + kx;
                let src = &acc[(r * pw + col + 1) * 4 * co + k * co..][..co];
                for ((d, s), b) in px.iter_mut().zip(src).zip(bias) {
                    *d = s + b;
                }
            }
        });
        give(acc);
        out
    }
}

/// The 1 x 1 head's weights as `[c, output]` row-major, and `output`.
pub(super) fn head_weights(head: &Conv2d) -> Result<(Vec<f32>, usize)> {
    let [output, c_head, _, _] = check_conv(head, "U-Net head", 1)?;
    let hw = values(head.weight.val());
    let mut w = vec![0.0f32; c_head * output];
    for o in 0..output {
        for ch in 0..c_head {
            w[ch * output + o] = hw[o * c_head + ch];
        }
    }
    Ok((w, output))
}

/// The 1 x 1 head (`weight` `[c, output]` row-major) on a map, as a `[output, h, w]` image.
pub(super) fn head_forward(x: &Map, weight: &[f32], bias: &[f32], par: Par) -> Vec<f32> {
    let (h, w, c, output) = (x.h, x.w, x.c, bias.len());
    // Over the interior rows (border pixels included, then dropped).
    let pw = w + 2;
    let m = h * pw;
    let mut acc = take(m * output);
    matmul(
        MatMut::from_row_major_slice_mut(&mut acc, m, output),
        Accum::Replace,
        MatRef::from_row_major_slice(&x.data[pw * c..(pw + m) * c], m, c),
        MatRef::from_row_major_slice(weight, c, output),
        1.0f32,
        par,
    );
    let mut out = vec![0.0f32; output * h * w];
    for r in 0..h {
        for col in 0..w {
            let src = &acc[(r * pw + col + 1) * output..][..output];
            for (o, (s, b)) in src.iter().zip(bias).enumerate() {
                out[(o * h + r) * w + col] = s + b;
            }
        }
    }
    give(acc);
    out
}

/// Checks `values` values as a `[batch, input, h, w]` input of a U-Net of `levels` levels and
/// returns the values per image.
pub(super) fn check_batch(
    input: usize,
    levels: usize,
    values: usize,
    batch: usize,
    h: usize,
    w: usize,
) -> Result<usize> {
    let div = 1usize << (levels.max(1) - 1);
    let per = input * h * w;
    if batch == 0
        || h == 0
        || w == 0
        || !h.is_multiple_of(div)
        || !w.is_multiple_of(div)
        || values != batch * per
    {
        return Err(TactileError::Input(format!(
            "a U-Net input must be {input} channels with height and width divisible by {div}; got \
             {values} values for {batch} x {input} x {h} x {w}"
        )));
    }
    Ok(per)
}

impl PlainUNet {
    /// Copies the weights of `net` (evaluation: batch normalisation with running statistics).
    pub fn new(net: &UNet) -> Result<Self> {
        let input = net.down[0].conv.weight.dims()[1];
        let mut down = Vec::new();
        let mut c = input;
        for b in &net.down {
            let blk = Block::new(b, &[c])?;
            c = blk.c_out;
            down.push(blk);
        }
        let mut up = Vec::new();
        let mut merge = Vec::new();
        // Decoder level k joins the upsampled map with the skip of encoder level L - 2 - k.
        for (k, (u, m)) in net.up.iter().zip(&net.merge).enumerate() {
            let u = Up::new(u)?;
            let skip = net.down.len().checked_sub(2 + k).map(|l| down[l].c_out);
            let Some(skip) = skip else {
                return Err(TactileError::Input(
                    "U-Net with more decoder than encoder levels".into(),
                ));
            };
            merge.push(Block::new(m, &[u.c_out, skip])?);
            up.push(u);
        }
        let (head, output) = head_weights(&net.head)?;
        Ok(PlainUNet {
            input,
            output,
            down,
            up,
            merge,
            head,
            head_bias: bias_of(&net.head, output),
            precision: Precision::F32,
        })
    }

    /// The same network with its convolutions in `precision` (see [`Precision`]).
    pub fn with_precision(mut self, precision: Precision) -> Self {
        let bf = precision == Precision::Bf16;
        let wino = precision == Precision::Winograd;
        for blk in self.down.iter_mut().chain(&mut self.merge) {
            let c_out = blk.c_out;
            for part in &mut blk.parts {
                let c = part.c_in;
                part.packed = bf.then(|| {
                    std::array::from_fn(|dy| bf16::Packed::new(&part.taps[dy], 3 * c, c_out))
                });
                part.wino = (wino && winograd::fits(4, 4, &[c], c_out))
                    .then(|| winograd::Weights::new(&part.taps, c, c_out));
            }
        }
        for u in &mut self.up {
            u.packed = bf.then(|| bf16::Packed::new(&u.weight, u.c_in, 4 * u.c_out));
        }
        self.precision = precision;
        self
    }

    /// The arithmetic of the convolutions.
    pub fn precision(&self) -> Precision {
        self.precision
    }

    /// Output channels.
    pub fn output_channels(&self) -> usize {
        self.output
    }

    /// One `[input, h, w]` image to `[output, h, w]`, matrix products on `par` threads.
    fn forward_one(&self, x: &[f32], h: usize, w: usize, par: Par) -> Vec<f32> {
        let mut levels: Vec<Map> = Vec::with_capacity(self.down.len());
        let first = Map::from_chw(x, self.input, h, w, par);
        for (l, b) in self.down.iter().enumerate() {
            let y = if l == 0 {
                b.forward(&[&first], par)
            } else {
                b.forward(&[&max_pool(&levels[l - 1], par)], par)
            };
            levels.push(y);
        }
        let mut x = levels.pop().expect("at least two levels");
        for (u, m) in self.up.iter().zip(&self.merge) {
            let skip = levels.pop().expect("one skip per decoder level");
            let up = u.forward(&x, par);
            x = m.forward(&[&up, &skip], par);
        }
        head_forward(&x, &self.head, &self.head_bias, par)
    }

    /// `[batch, input, h, w]` (row-major) to `[batch, output, h, w]`; h and w must divide by
    /// 2^(levels - 1). Images run in parallel on the current rayon pool; a single image uses
    /// the pool inside its matrix products instead.
    pub fn forward(&self, x: &[f32], batch: usize, h: usize, w: usize) -> Result<Vec<f32>> {
        let per = check_batch(self.input, self.down.len(), x.len(), batch, h, w)?;
        if batch == 1 || rayon::current_num_threads() == 1 {
            let par = if batch == 1 { Par::rayon(0) } else { Par::Seq };
            return Ok(x
                .chunks_exact(per)
                .flat_map(|img| self.forward_one(img, h, w, par))
                .collect());
        }
        let outs: Vec<Vec<f32>> = x
            .par_chunks_exact(per)
            .map(|img| self.forward_one(img, h, w, Par::Seq))
            .collect();
        Ok(outs.concat())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::nets::NetConfig;
    use ocm_learn::burn::module::{Param, RunningState};
    use ocm_learn::burn::tensor::{Device, Tensor, TensorData};

    fn wave(n: usize, k: usize, scale: f32, offset: f32) -> Vec<f32> {
        (0..n)
            .map(|i| offset + scale * ((i * 7 + k * 3) as f32 * 0.37).sin())
            .collect()
    }

    /// Moves every normalisation away from identity (gamma, beta, running statistics), so
    /// the folding is exercised.
    fn perturb_norms(net: &mut UNet, dev: &Device) {
        let t = |v: Vec<f32>| {
            let n = v.len();
            Tensor::<1>::from_data(TensorData::new(v, [n]), dev)
        };
        for (k, b) in net.down.iter_mut().chain(net.merge.iter_mut()).enumerate() {
            let c = b.conv.weight.dims()[0];
            if let Some(bn) = b.batch.as_mut() {
                bn.gamma = Param::from_tensor(t(wave(c, k, 0.3, 1.0)));
                bn.beta = Param::from_tensor(t(wave(c, k + 1, 0.2, 0.0)));
                bn.running_mean = RunningState::new(t(wave(c, k + 2, 0.1, 0.0)));
                bn.running_var = RunningState::new(t(wave(c, k + 3, 0.4, 1.0)));
            }
            if let Some(gn) = b.group.as_mut() {
                gn.gamma = Some(Param::from_tensor(t(wave(c, k, 0.3, 1.0))));
                gn.beta = Some(Param::from_tensor(t(wave(c, k + 1, 0.2, 0.0))));
            }
        }
    }

    /// The largest difference of `got` from `want`, and the largest magnitude of `want`.
    fn worst_and_scale(got: &[f32], want: &[f32]) -> (f32, f32) {
        let scale = want.iter().fold(0.0f32, |m, v| m.max(v.abs()));
        let worst = got
            .iter()
            .zip(want)
            .fold(0.0f32, |m, (a, b)| m.max((a - b).abs()));
        (worst, scale)
    }

    /// The plain forward pass equals burn's (evaluation mode) for both networks, one image
    /// and a parallel batch, at two sizes (12 x 20 has an odd-sized bottleneck, 3 x 5); a
    /// wrong input size is refused.
    #[test]
    fn plain_forward_matches_burn() {
        let dev = ocm_learn::cpu();
        for (rows, cols, cfg) in [(16, 24), (12, 20)].into_iter().flat_map(|(r, c)| {
            [NetConfig::perception(r, c), NetConfig::rendering(r, c)].map(|n| (r, c, n))
        }) {
            let mut net = cfg.init(&dev, 5).unwrap();
            perturb_norms(&mut net, &dev);
            let plain = PlainUNet::new(&net).unwrap();
            let c = cfg.unet.input;
            for batch in [1, 3] {
                let x = wave(batch * c * rows * cols, batch, 1.0, 0.1);
                let t = Tensor::<4>::from_data(
                    TensorData::new(x.clone(), [batch, c, rows, cols]),
                    &dev,
                );
                let want = values(net.forward(t));
                let pool = rayon::ThreadPoolBuilder::new()
                    .num_threads(2)
                    .build()
                    .unwrap();
                let got = pool
                    .install(|| plain.forward(&x, batch, rows, cols))
                    .unwrap();
                assert_eq!(got.len(), want.len());
                let (err, scale) = worst_and_scale(&got, &want);
                assert!(
                    err < 1e-4 * scale,
                    "{:?} batch {batch}: {err} of {scale}",
                    cfg.kind
                );
            }
            assert!(
                plain
                    .forward(&vec![0.0; c * 14 * cols], 1, 14, cols)
                    .is_err()
            );
            assert!(
                plain
                    .forward(&vec![0.0; c * rows * cols], 2, rows, cols)
                    .is_err()
            );
        }
    }

    /// `cfg`'s network (seeded, normalisations perturbed) on two images in direct f32 and in
    /// `precision`; checks that one image alone (its products on a 2-thread pool) gives the
    /// batch's first output and that switching back to f32 restores f32's values bit for bit.
    /// Returns the engine in `precision`, its outputs and f32's.
    fn engine_against_f32(
        cfg: &NetConfig,
        seed: u64,
        precision: Precision,
    ) -> (PlainUNet, Vec<f32>, Vec<f32>) {
        let dev = ocm_learn::cpu();
        let mut net = cfg.init(&dev, seed).unwrap();
        perturb_norms(&mut net, &dev);
        let plain = PlainUNet::new(&net).unwrap();
        let (rows, cols, c) = (cfg.rows, cfg.cols, cfg.unet.input);
        let x = wave(2 * c * rows * cols, seed as usize, 1.0, 0.1);
        let want = plain.forward(&x, 2, rows, cols).unwrap();
        let engine = plain.with_precision(precision);
        assert_eq!(engine.precision(), precision);
        let got = engine.forward(&x, 2, rows, cols).unwrap();
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(2)
            .build()
            .unwrap();
        let first = pool
            .install(|| engine.forward(&x[..c * rows * cols], 1, rows, cols))
            .unwrap();
        assert_eq!(first, got[..first.len()]);
        let back = engine.clone().with_precision(Precision::F32);
        assert_eq!(back.forward(&x, 2, rows, cols).unwrap(), want);
        (engine, got, want)
    }

    /// Winograd's engine against the direct f32 one, at sizes where it takes every level
    /// whose channels allow (perception 16 x 32: 16 x 32, 8 x 16 and 4 x 8; rendering 16 x 40
    /// has a 4 x 10 bottleneck, direct): outputs within round-off (relative RMS below 1e-5;
    /// measured 1.5e-6 on the full-size networks) yet not bit for bit the direct values (the
    /// path ran).
    #[test]
    fn winograd_engine_matches_f32_to_round_off() {
        for cfg in [NetConfig::perception(16, 32), NetConfig::rendering(16, 40)] {
            let (wino, got, want) = engine_against_f32(&cfg, 4, Precision::Winograd);
            // The first block's 3 or 19 input channels are not whole vectors: direct there.
            let parts: Vec<bool> = wino
                .down
                .iter()
                .chain(&wino.merge)
                .flat_map(|b| b.parts.iter().map(|p| p.wino.is_some()))
                .collect();
            assert!(!parts[0] && parts[1..].iter().all(|&w| w), "{parts:?}");
            let rel = crate::nets::bench::relative_rms_difference(&got, &want);
            let (worst, scale) = worst_and_scale(&got, &want);
            assert!(
                got != want && rel < 1e-5 && worst < 1e-4 * scale,
                "{:?}: relative RMS {rel}, worst {worst} of {scale}",
                cfg.kind
            );
        }
        assert_eq!(
            "winograd".parse::<Precision>().unwrap(),
            Precision::Winograd
        );
    }

    /// The bfloat16 engine against the f32 one: the rounding of weights and activations (2^-8
    /// relative at most per value, random in sign) moves the outputs by a fraction of a
    /// percent, never more than 2 %, and switching back to f32 restores the f32 values bit for
    /// bit.
    #[test]
    fn bf16_engine_stays_within_its_rounding() {
        for cfg in [NetConfig::perception(24, 32), NetConfig::rendering(16, 40)] {
            let (_, got, want) = engine_against_f32(&cfg, 9, Precision::Bf16);
            let rel = crate::nets::bench::relative_rms_difference(&got, &want);
            let (worst, scale) = worst_and_scale(&got, &want);
            assert!(
                rel > 1e-5 && rel < 0.02 && worst < 0.05 * scale,
                "{:?}: relative RMS {rel}, worst {worst} of {scale}",
                cfg.kind
            );
        }
        assert!("bf16".parse::<Precision>().unwrap() == Precision::Bf16);
        assert!("f16".parse::<Precision>().is_err());
    }

    /// erf by its Maclaurin series in f64 (for |z| <= 3.6 the largest term is below 1e6, so the
    /// sum keeps about 1e-10).
    fn erf_series(z: f64) -> f64 {
        let (mut term, mut sum) = (z, 0.0);
        for n in 0..200 {
            sum += term / (2 * n + 1) as f64;
            term *= -z * z / (n + 1) as f64;
        }
        sum * 2.0 / std::f64::consts::PI.sqrt()
    }

    /// The vectorisable exponential against the library's, GELU against erf's series.
    #[test]
    fn exp_and_gelu_match_references() {
        for i in 0..2000 {
            let y = -(i as f32) * 0.05;
            let (a, b) = (exp_neg(y), y.exp());
            if y < -87.0 {
                assert_eq!(a, 0.0, "{y}");
            } else {
                assert!((a - b).abs() <= 3e-7 * b, "{y}: {a} vs {b}");
            }
        }
        let xs: Vec<f32> = (-250..=250).map(|i| i as f32 * 0.02).collect();
        let mut g = xs.clone();
        gelu(&mut g);
        for (x, y) in xs.iter().zip(&g) {
            let x64 = f64::from(*x);
            let exact = 0.5 * x64 * (1.0 + erf_series(x64 * std::f64::consts::FRAC_1_SQRT_2));
            let err = (f64::from(*y) - exact).abs();
            assert!(err < 3e-7 * (1.0 + x64.abs()), "{x}: {y} vs {exact}");
        }
        // Far out GELU is x or 0.
        let mut far = [-20.0f32, 20.0];
        gelu(&mut far);
        assert_eq!(far, [0.0, 20.0]);
    }
}
