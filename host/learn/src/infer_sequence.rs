//! Plain `f32` inference of a trained [`SequenceEncoder`] for batched throughput: the weights
//! are copied out once, the dense products go through faer (as in [`crate::infer`]), and the
//! last block computes queries, attention output and feed-forward for the last step only,
//! because [`SequenceEncoder::forward_last`] reads nothing else. Training stays on burn; this
//! mirrors the burn forward pass and is tested against it.

use burn::nn::LayerNorm;
use burn::nn::activation::Activation as BurnActivation;
use burn::nn::transformer::TransformerEncoderLayer;
use rayon::prelude::*;

use crate::error::{LearnError, Result};
use crate::gcn::LAYER_NORM_EPSILON;
use crate::infer::DenseLayer;
use crate::mlp::Activation;
use crate::sequence::SequenceEncoder;
use crate::values;

/// Samples per work item: large enough for the matrix kernels, small enough to spread a batch
/// over the cores.
const CHUNK: usize = 64;

/// A LayerNorm's affine parameters.
#[derive(Debug, Clone, PartialEq)]
struct DenseNorm {
    gamma: Vec<f32>,
    beta: Vec<f32>,
}

impl DenseNorm {
    fn from_norm(n: &LayerNorm) -> Self {
        let gamma = values(n.gamma.val());
        let beta = n
            .beta
            .as_ref()
            .map_or_else(|| vec![0.0; gamma.len()], |b| values(b.val()));
        Self { gamma, beta }
    }

    /// Normalises each `d`-wide row of `x` into `out` (biased variance, as burn).
    fn rows(&self, x: &[f32], out: &mut Vec<f32>) {
        let d = self.gamma.len();
        out.clear();
        out.reserve(x.len());
        for row in x.chunks_exact(d) {
            let mean = row.iter().sum::<f32>() / d as f32;
            let var = row.iter().map(|v| (v - mean) * (v - mean)).sum::<f32>() / d as f32;
            let inv = 1.0 / (var + LAYER_NORM_EPSILON as f32).sqrt();
            out.extend(
                row.iter()
                    .zip(&self.gamma)
                    .zip(&self.beta)
                    .map(|((v, g), b)| (v - mean) * inv * g + b),
            );
        }
    }
}

/// One pre-norm encoder block.
#[derive(Debug, Clone, PartialEq)]
struct DenseBlock {
    /// The norm before attention (burn calls it `norm_2` in pre-norm blocks).
    norm_attn: DenseNorm,
    query: DenseLayer,
    key: DenseLayer,
    value: DenseLayer,
    output: DenseLayer,
    /// The norm before the feed-forward (`norm_1`).
    norm_ff: DenseNorm,
    inner: DenseLayer,
    outer: DenseLayer,
}

impl DenseBlock {
    fn from_layer(l: &TransformerEncoderLayer) -> Result<Self> {
        if !l.norm_first {
            return Err(LearnError::Config(
                "dense inference supports pre-norm encoder blocks only".into(),
            ));
        }
        if !matches!(l.pwff.activation, BurnActivation::Relu(_)) {
            return Err(LearnError::Config(
                "dense inference supports ReLU feed-forward layers only".into(),
            ));
        }
        Ok(Self {
            norm_attn: DenseNorm::from_norm(&l.norm_2),
            query: DenseLayer::from_linear(&l.mha.query),
            key: DenseLayer::from_linear(&l.mha.key),
            value: DenseLayer::from_linear(&l.mha.value),
            output: DenseLayer::from_linear(&l.mha.output),
            norm_ff: DenseNorm::from_norm(&l.norm_1),
            inner: DenseLayer::from_linear(&l.pwff.linear_inner),
            outer: DenseLayer::from_linear(&l.pwff.linear_outer),
        })
    }
}

/// Scratch buffers of one chunk, reused across its blocks.
#[derive(Default)]
struct Scratch {
    a: Vec<f32>,
    q: Vec<f32>,
    k: Vec<f32>,
    v: Vec<f32>,
    ctx: Vec<f32>,
    o: Vec<f32>,
    f: Vec<f32>,
    g: Vec<f32>,
    last: Vec<f32>,
}

/// The last step's row of each of `c` windows of `steps` rows, `d` wide, into `out`.
fn last_rows(x: &[f32], c: usize, steps: usize, d: usize, out: &mut Vec<f32>) {
    out.clear();
    for w in 0..c {
        let r = w * steps + steps - 1;
        out.extend_from_slice(&x[r * d..(r + 1) * d]);
    }
}

/// A [`SequenceEncoder`] as plain layers, evaluating [`SequenceEncoder::forward_last`].
#[derive(Debug, Clone, PartialEq)]
pub struct DenseSequenceEncoder {
    d_model: usize,
    n_heads: usize,
    embed: DenseLayer,
    /// `[max_len, d_model]` sinusoids.
    positions: Vec<f32>,
    max_len: usize,
    blocks: Vec<DenseBlock>,
    norm: DenseNorm,
}

impl DenseSequenceEncoder {
    /// Copies the weights of a trained encoder.
    pub fn from_encoder(e: &SequenceEncoder) -> Result<Self> {
        let (embed, positions, blocks, norm) = e.parts();
        let [_, max_len, d_model] = positions.sinusoids.dims();
        Ok(Self {
            d_model,
            n_heads: blocks.n_heads,
            embed: DenseLayer::from_linear(embed),
            positions: values(positions.sinusoids.clone()),
            max_len,
            blocks: blocks
                .layers
                .iter()
                .map(DenseBlock::from_layer)
                .collect::<Result<_>>()?,
            norm: DenseNorm::from_norm(norm),
        })
    }

    /// Features per step.
    pub fn input(&self) -> usize {
        self.embed.input
    }

    /// Embedding width.
    pub fn width(&self) -> usize {
        self.d_model
    }

    /// `[batch, steps, input]` row-major windows to the last step's embedding `[batch,
    /// d_model]`, chunks of the batch spread over rayon's threads.
    pub fn forward_last(&self, x: &[f32], batch: usize, steps: usize) -> Result<Vec<f32>> {
        let f = self.input();
        if steps == 0 || steps > self.max_len {
            return Err(LearnError::Data(format!(
                "{steps} steps per window; the encoder takes 1..={}",
                self.max_len
            )));
        }
        if x.len() != batch * steps * f {
            return Err(LearnError::Data(format!(
                "{} inputs for {batch} windows of {steps} x {f}",
                x.len()
            )));
        }
        let d = self.d_model;
        let mut out = vec![0.0f32; batch * d];
        out.par_chunks_mut(CHUNK * d)
            .zip(x.par_chunks(CHUNK * steps * f))
            .for_each_init(Scratch::default, |s, (o, xc)| {
                self.chunk(xc, o.len() / d, steps, s, o);
            });
        Ok(out)
    }

    /// The forward pass of `c` windows into `out` (`[c, d_model]`).
    fn chunk(&self, x: &[f32], c: usize, steps: usize, s: &mut Scratch, out: &mut [f32]) {
        let d = self.d_model;
        let rows = c * steps;
        let mut h = Vec::new();
        self.embed.forward_rows(x, rows, &mut h);
        for (r, row) in h.chunks_exact_mut(d).enumerate() {
            let t = r % steps;
            for (v, p) in row.iter_mut().zip(&self.positions[t * d..(t + 1) * d]) {
                *v += p;
            }
        }
        let n_blocks = self.blocks.len();
        for (bi, b) in self.blocks.iter().enumerate() {
            // The last block only feeds the last step onwards.
            let last_only = bi + 1 == n_blocks;
            b.norm_attn.rows(&h, &mut s.a);
            b.key.forward_rows(&s.a, rows, &mut s.k);
            b.value.forward_rows(&s.a, rows, &mut s.v);
            let q_per = if last_only { 1 } else { steps };
            if last_only {
                last_rows(&s.a, c, steps, d, &mut s.last);
                b.query.forward_rows(&s.last, c, &mut s.q);
            } else {
                b.query.forward_rows(&s.a, rows, &mut s.q);
            }
            self.attend(c, steps, q_per, s);
            b.output.forward_rows(&s.ctx, c * q_per, &mut s.o);
            if last_only {
                last_rows(&h, c, steps, d, &mut s.last);
                std::mem::swap(&mut h, &mut s.last);
            }
            for (v, o) in h.iter_mut().zip(&s.o) {
                *v += o;
            }
            let hr = c * q_per;
            b.norm_ff.rows(&h, &mut s.f);
            b.inner.forward_rows(&s.f, hr, &mut s.g);
            Activation::Relu.apply_slice(&mut s.g);
            b.outer.forward_rows(&s.g, hr, &mut s.f);
            for (v, o) in h.iter_mut().zip(&s.f) {
                *v += o;
            }
        }
        let mut normed = Vec::new();
        self.norm.rows(&h, &mut normed);
        out.copy_from_slice(&normed);
    }

    /// Scaled dot-product attention of `q_per` queries per window (the last `q_per` steps)
    /// over all `steps` keys, per head, into `s.ctx` (`[c * q_per, d_model]`).
    fn attend(&self, c: usize, steps: usize, q_per: usize, s: &mut Scratch) {
        let d = self.d_model;
        let dk = d / self.n_heads;
        let scale = 1.0 / (dk as f32).sqrt();
        s.ctx.clear();
        s.ctx.resize(c * q_per * d, 0.0);
        let mut w = vec![0.0f32; steps];
        for win in 0..c {
            for qi in 0..q_per {
                let qrow = win * q_per + qi;
                for hd in 0..self.n_heads {
                    let off = hd * dk;
                    let q = &s.q[qrow * d + off..qrow * d + off + dk];
                    let mut max = f32::NEG_INFINITY;
                    for (j, wj) in w.iter_mut().enumerate() {
                        let kr = (win * steps + j) * d + off;
                        let dot: f32 = q.iter().zip(&s.k[kr..kr + dk]).map(|(a, b)| a * b).sum();
                        *wj = dot * scale;
                        max = max.max(*wj);
                    }
                    let mut sum = 0.0;
                    for wj in w.iter_mut() {
                        *wj = (*wj - max).exp();
                        sum += *wj;
                    }
                    let ctx = &mut s.ctx[qrow * d + off..qrow * d + off + dk];
                    for (j, wj) in w.iter().enumerate() {
                        let vr = (win * steps + j) * d + off;
                        let p = wj / sum;
                        for (cv, vv) in ctx.iter_mut().zip(&s.v[vr..vr + dk]) {
                            *cv += p * vv;
                        }
                    }
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sequence::SequenceEncoderConfig;
    use burn::module::{Module, ModuleMapper, Param};
    use burn::tensor::{Tensor, TensorData};
    use rand::{Rng, SeedableRng};

    /// Adds seeded noise to every parameter, norms and biases included (a fresh model has
    /// unit norms and zero biases, which would hide a swapped norm or a dropped bias).
    struct Perturb(rand_chacha::ChaCha8Rng);

    impl ModuleMapper for Perturb {
        fn map_float<const D: usize>(&mut self, param: Param<Tensor<D>>) -> Param<Tensor<D>> {
            let rng = &mut self.0;
            param.map(|t| {
                let dims = t.dims();
                let n: usize = dims.iter().product();
                let noise: Vec<f32> = (0..n).map(|_| rng.random_range(-0.3f32..0.3)).collect();
                t.clone() + Tensor::<D>::from_data(TensorData::new(noise, dims), &t.device())
            })
        }
    }

    #[test]
    fn dense_encoder_matches_burn_on_the_last_step() {
        let device = crate::cpu();
        let cfg = SequenceEncoderConfig {
            input: 14,
            d_model: 32,
            n_heads: 4,
            d_ff: 48,
            n_layers: 2,
            max_len: 10,
        };
        let enc = cfg
            .init(&device, 7)
            .map(&mut Perturb(rand_chacha::ChaCha8Rng::seed_from_u64(3)));
        let dense = DenseSequenceEncoder::from_encoder(&enc).expect("dense");
        // 130 windows: two full chunks and a partial one.
        let (b, m) = (130, 10);
        let x: Vec<f32> = (0..b * m * cfg.input)
            .map(|i| ((i as f32) * 0.37).sin() * 1.5)
            .collect();
        let want = values(enc.forward_last(Tensor::<3>::from_data(
            TensorData::new(x.clone(), [b, m, cfg.input]),
            &device,
        )));
        let got = dense.forward_last(&x, b, m).expect("forward");
        assert_eq!(got.len(), want.len());
        let worst = got
            .iter()
            .zip(&want)
            .map(|(g, w)| (g - w).abs())
            .fold(0.0f32, f32::max);
        // The outputs are LayerNorm-ed (order one): f32 round-off only.
        assert!(worst < 2e-4, "worst difference {worst}");
        // A shorter window uses the first positions, as burn.
        let x5: Vec<f32> = x[..4 * 5 * cfg.input].to_vec();
        let want5 = values(enc.forward_last(Tensor::<3>::from_data(
            TensorData::new(x5.clone(), [4, 5, cfg.input]),
            &device,
        )));
        let got5 = dense.forward_last(&x5, 4, 5).expect("forward");
        let worst5 = got5
            .iter()
            .zip(&want5)
            .map(|(g, w)| (g - w).abs())
            .fold(0.0f32, f32::max);
        assert!(worst5 < 2e-4, "worst difference {worst5}");
    }

    #[test]
    fn bad_shapes_are_refused() {
        let device = crate::cpu();
        let cfg = SequenceEncoderConfig {
            input: 3,
            d_model: 8,
            n_heads: 2,
            d_ff: 8,
            n_layers: 1,
            max_len: 4,
        };
        let dense = DenseSequenceEncoder::from_encoder(&cfg.init(&device, 1)).expect("dense");
        assert!(dense.forward_last(&[0.0; 15], 1, 5).is_err());
        assert!(dense.forward_last(&[0.0; 11], 1, 4).is_err());
        assert!(dense.forward_last(&[0.0; 12], 1, 0).is_err());
    }
}
