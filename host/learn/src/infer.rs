//! Plain `f32` inference of trained modules for latency-bound single calls: the weights are
//! copied out of the burn modules once, the dense products go through faer's matrix kernels,
//! and a call builds no tensor, graph or autodiff state. Training stays on burn; these mirror
//! [`Mlp::forward`], [`DeepSets::forward`] and [`Gcn::forward`] and are tested against them.

use burn::nn::Linear;
use faer::linalg::matmul::matmul;
use faer::{Accum, MatMut, MatRef, Par};
use wide::f32x8;

use crate::deepsets::DeepSets;
use crate::gcn::{Gcn, Graph, LAYER_NORM_EPSILON};
use crate::mlp::{Activation, Mlp};
use crate::values;

/// `out = x W (+ out when `add`)` for row-major `x` `[rows, k]`, `W` `[k, n]`, `out` `[rows, n]`.
fn gemm(out: &mut [f32], x: &[f32], w: &[f32], rows: usize, k: usize, n: usize, add: bool) {
    let a = MatRef::from_row_major_slice(x, rows, k);
    let b = MatRef::from_row_major_slice(w, k, n);
    let c = MatMut::from_row_major_slice_mut(out, rows, n);
    let accum = if add { Accum::Add } else { Accum::Replace };
    matmul(c, accum, a, b, 1.0f32, Par::Seq);
}

impl Activation {
    /// Applies the nonlinearity to every value in place.
    pub fn apply_slice(self, v: &mut [f32]) {
        if self == Self::Relu {
            let (chunks, rest) = v.as_chunks_mut::<LANES>();
            for c in chunks {
                *c = f32x8::from(*c).fast_max(f32x8::splat(0.0)).to_array();
            }
            rest.iter_mut().for_each(|x| *x = x.max(0.0));
        } else {
            v.iter_mut().for_each(|x| *x = self.scalar(*x));
        }
    }

    /// Applies the nonlinearity to one value (the same functions as [`Activation::apply`]).
    pub fn scalar(self, x: f32) -> f32 {
        match self {
            Self::Relu => x.max(0.0),
            Self::Gelu => 0.5 * x * (1.0 + libm::erff(x * std::f32::consts::FRAC_1_SQRT_2)),
            Self::Tanh => x.tanh(),
        }
    }
}

/// A linear layer `y = x W + b` with its weights as plain row-major values.
#[derive(Debug, Clone, PartialEq)]
pub struct DenseLayer {
    /// Input features.
    pub input: usize,
    /// Output features.
    pub output: usize,
    /// `[input, output]`, row-major (burn's layout).
    pub weight: Vec<f32>,
    /// `[output]` (zeros for a layer without bias).
    pub bias: Vec<f32>,
}

impl DenseLayer {
    /// Copies the weights of a burn layer.
    pub fn from_linear(l: &Linear) -> Self {
        let [input, output] = l.weight.dims();
        DenseLayer {
            input,
            output,
            weight: values(l.weight.val()),
            bias: l
                .bias
                .as_ref()
                .map_or_else(|| vec![0.0; output], |b| values(b.val())),
        }
    }

    /// `out = x W + b` for `rows` row-major inputs; `out` is resized to `rows * output`.
    pub fn forward_rows(&self, x: &[f32], rows: usize, out: &mut Vec<f32>) {
        debug_assert_eq!(x.len(), rows * self.input);
        out.clear();
        // Reserved up front: growing the buffer row by row was a tenth of an NPE call.
        out.reserve(rows * self.output);
        for _ in 0..rows {
            out.extend_from_slice(&self.bias);
        }
        gemm(out, x, &self.weight, rows, self.input, self.output, true);
    }

    /// `x W + b` for one input vector.
    pub fn forward_vec(&self, x: &[f32]) -> Vec<f32> {
        let mut y = self.bias.clone();
        for (i, &xi) in x.iter().enumerate().take(self.input) {
            let row = &self.weight[i * self.output..(i + 1) * self.output];
            for (yo, &w) in y.iter_mut().zip(row) {
                *yo += xi * w;
            }
        }
        y
    }
}

/// An [`Mlp`] as plain layers.
#[derive(Debug, Clone, PartialEq)]
pub struct DenseMlp {
    /// Hidden layers followed by the output layer.
    pub layers: Vec<DenseLayer>,
    /// Nonlinearity after each hidden layer.
    pub activation: Activation,
}

impl DenseMlp {
    /// Copies the weights of a burn MLP.
    pub fn from_mlp(m: &Mlp) -> Self {
        DenseMlp {
            layers: m.layers.iter().map(DenseLayer::from_linear).collect(),
            activation: m.activation(),
        }
    }

    /// Input features.
    pub fn input(&self) -> usize {
        self.layers.first().map_or(0, |l| l.input)
    }

    /// Output features.
    pub fn output(&self) -> usize {
        self.layers.last().map_or(0, |l| l.output)
    }

    /// Maps `rows` row-major inputs to `[rows, output]`.
    pub fn forward_rows(&self, x: &[f32], rows: usize) -> Vec<f32> {
        if self.layers.is_empty() {
            return x.to_vec();
        }
        let mut cur = Vec::new();
        let mut next = Vec::new();
        let last = self.layers.len() - 1;
        for (i, l) in self.layers.iter().enumerate() {
            // The first layer reads the caller's rows directly instead of a copy of them.
            let input: &[f32] = if i == 0 { x } else { &cur };
            l.forward_rows(input, rows, &mut next);
            if i < last {
                self.activation.apply_slice(&mut next);
            }
            std::mem::swap(&mut cur, &mut next);
        }
        cur
    }

    /// Maps one input vector.
    pub fn forward_vec(&self, x: &[f32]) -> Vec<f32> {
        let mut cur = x.to_vec();
        let last = self.layers.len().saturating_sub(1);
        for (i, l) in self.layers.iter().enumerate() {
            cur = l.forward_vec(&cur);
            if i < last {
                cur.iter_mut().for_each(|v| *v = self.activation.scalar(*v));
            }
        }
        cur
    }
}

/// A [`DeepSets`] encoder as plain layers, for one set at a time.
#[derive(Debug, Clone, PartialEq)]
pub struct DenseDeepSets {
    /// Point-wise network.
    pub phi: DenseMlp,
    /// Set network.
    pub rho: DenseMlp,
    /// Factor on the sum.
    pub scale: f32,
}

impl DenseDeepSets {
    /// Copies the weights of a burn encoder.
    pub fn from_deepsets(d: &DeepSets) -> Self {
        DenseDeepSets {
            phi: DenseMlp::from_mlp(&d.phi),
            rho: DenseMlp::from_mlp(&d.rho),
            scale: d.scale() as f32,
        }
    }

    /// `rho(scale * sum_i phi(p_i))` of one set of row-major points (`phi.input()` values
    /// each; empty gives `rho(0)`). phi's output layer is linear, so the sum passes through it:
    /// `sum_i (a_i W + b) = (sum_i a_i) W + n b`, one vector product instead of one per point.
    pub fn forward_set(&self, points: &[f32]) -> Vec<f32> {
        let d_in = self.phi.input().max(1);
        let n = points.len() / d_in;
        let width = self.phi.output();
        let pooled = match self.phi.layers.split_last() {
            Some((out_layer, hidden)) if n > 0 => {
                let mut cur = points.to_vec();
                let mut next = Vec::new();
                for l in hidden {
                    l.forward_rows(&cur, n, &mut next);
                    self.phi.activation.apply_slice(&mut next);
                    std::mem::swap(&mut cur, &mut next);
                }
                let k = out_layer.input;
                let mut sum = vec![0.0f32; k];
                for row in cur.chunks_exact(k) {
                    for (s, &v) in sum.iter_mut().zip(row) {
                        *s += v;
                    }
                }
                let mut y = out_layer.forward_vec(&sum);
                // forward_vec added b once; the sum over n points carries it n times.
                for (yo, &b) in y.iter_mut().zip(&out_layer.bias) {
                    *yo += (n as f32 - 1.0) * b;
                }
                y.iter_mut().for_each(|v| *v *= self.scale);
                y
            }
            _ => vec![0.0; width],
        };
        self.rho.forward_vec(&pooled)
    }
}

/// Eight lanes: the node-state loops run on `wide`'s portable SIMD type, which keeps them
/// vectorised even where the crate is built without LLVM's auto-vectoriser (the workspace's
/// dev profile).
const LANES: usize = 8;

fn lanes(v: &[f32]) -> Vec<f32x8> {
    v.chunks(LANES)
        .map(|c| {
            let mut a = [0.0f32; LANES];
            a[..c.len()].copy_from_slice(c);
            f32x8::from(a)
        })
        .collect()
}

/// Neighbour-mean aggregation of a fixed graph in compressed rows: for each node, its
/// neighbours and 1 / degree (an isolated node's mean is zero).
#[derive(Debug, Clone, PartialEq)]
struct NeighbourMean {
    offsets: Vec<usize>,
    neighbours: Vec<usize>,
    inv_degree: Vec<f32>,
}

impl NeighbourMean {
    /// The rows of `graph` (messages `src -> dst`).
    fn new(graph: &Graph) -> Self {
        let n = graph.num_nodes;
        let mut count = vec![0usize; n];
        for &d in &graph.dst {
            count[d] += 1;
        }
        let mut offsets = vec![0usize; n + 1];
        for i in 0..n {
            offsets[i + 1] = offsets[i] + count[i];
        }
        let mut fill = offsets.clone();
        let mut neighbours = vec![0usize; graph.src.len()];
        for (&s, &d) in graph.src.iter().zip(&graph.dst) {
            neighbours[fill[d]] = s;
            fill[d] += 1;
        }
        NeighbourMean {
            offsets,
            neighbours,
            inv_degree: graph.inv_degree.clone(),
        }
    }

    fn num_nodes(&self) -> usize {
        self.inv_degree.len()
    }

    /// `out[v] = mean_{u in N(v)} h[u]` for node rows of `row` vectors.
    fn apply(&self, h: &[f32x8], row: usize, out: &mut [f32x8]) {
        // The common widths get a fixed-length accumulator the compiler keeps in registers.
        match row {
            1 => self.apply_fixed::<1>(h, out),
            2 => self.apply_fixed::<2>(h, out),
            4 => self.apply_fixed::<4>(h, out),
            8 => self.apply_fixed::<8>(h, out),
            _ => {
                for (v, acc) in out.chunks_exact_mut(row).enumerate() {
                    acc.fill(f32x8::splat(0.0));
                    for &u in &self.neighbours[self.offsets[v]..self.offsets[v + 1]] {
                        for (a, &x) in acc.iter_mut().zip(&h[u * row..(u + 1) * row]) {
                            *a += x;
                        }
                    }
                    let s = f32x8::splat(self.inv_degree[v]);
                    acc.iter_mut().for_each(|a| *a *= s);
                }
            }
        }
    }

    fn apply_fixed<const R: usize>(&self, h: &[f32x8], out: &mut [f32x8]) {
        let (rows, _) = h.as_chunks::<R>();
        let (outs, _) = out.as_chunks_mut::<R>();
        for (v, o) in outs.iter_mut().enumerate() {
            let mut acc = [f32x8::splat(0.0); R];
            for &u in &self.neighbours[self.offsets[v]..self.offsets[v + 1]] {
                let x = &rows[u];
                for k in 0..R {
                    acc[k] += x[k];
                }
            }
            let s = f32x8::splat(self.inv_degree[v]);
            for k in 0..R {
                o[k] = acc[k] * s;
            }
        }
    }
}

/// One residual layer `h + ReLU(LN(W mean_N h))` with the LayerNorm's centring folded into
/// the weight (`W (I - 11^T / w)`, so the product is already centred per row), padded to whole
/// vectors with zeros (padded lanes stay zero).
#[derive(Debug, Clone, PartialEq)]
struct DenseGcnLayer {
    centred_weight: Vec<f32>,
    gamma: Vec<f32x8>,
    beta: Vec<f32x8>,
}

/// A [`Gcn`] on a fixed graph as plain layers.
#[derive(Debug, Clone, PartialEq)]
pub struct DenseGcn {
    width: usize,
    padded: usize,
    layers: Vec<DenseGcnLayer>,
    mean: NeighbourMean,
}

impl DenseGcn {
    /// Copies the weights of a burn GCN for `graph`.
    pub fn new(gcn: &Gcn, graph: &Graph) -> Self {
        let width = gcn
            .layers
            .first()
            .map_or(0, |l| l.linear().weight.dims()[1]);
        let padded = width.div_ceil(LANES) * LANES;
        let layers = gcn
            .layers
            .iter()
            .map(|l| {
                let dense = DenseLayer::from_linear(l.linear());
                let w = dense.output;
                let mut centred = vec![0.0f32; padded * padded];
                for (i, row) in dense.weight.chunks_exact(w).enumerate() {
                    let m = row.iter().sum::<f32>() / w as f32;
                    for (o, &v) in row.iter().enumerate() {
                        centred[i * padded + o] = v - m;
                    }
                }
                let norm = l.norm();
                DenseGcnLayer {
                    centred_weight: centred,
                    gamma: lanes(&values(norm.gamma.val())),
                    beta: lanes(
                        &norm
                            .beta
                            .as_ref()
                            .map_or_else(|| vec![0.0; w], |b| values(b.val())),
                    ),
                }
            })
            .collect();
        DenseGcn {
            width,
            padded,
            layers,
            mean: NeighbourMean::new(graph),
        }
    }

    /// Feature width.
    pub fn width(&self) -> usize {
        self.width
    }

    /// Propagates node states `[nodes, batch, width]` (row-major) through every layer, in
    /// place.
    pub fn forward(&self, h: &mut [f32], batch: usize) {
        let (w, vecs) = (self.width, self.padded / LANES);
        let rows = self.mean.num_nodes() * batch;
        debug_assert_eq!(h.len(), rows * w);
        let eps = LAYER_NORM_EPSILON as f32;
        let mut x = vec![f32x8::splat(0.0); rows * vecs];
        for (xr, hr) in x.chunks_exact_mut(vecs).zip(h.chunks_exact(w)) {
            let flat: &mut [f32] = bytemuck::cast_slice_mut(xr);
            flat[..w].copy_from_slice(hr);
        }
        let mut m = vec![f32x8::splat(0.0); x.len()];
        let mut z = vec![f32x8::splat(0.0); x.len()];
        let inv_w = f32x8::splat(1.0 / w as f32);
        let eps = f32x8::splat(eps);
        // 1 / sqrt(variance + eps) per row, computed eight rows at a time: one square root
        // per row would otherwise be a serial chain.
        let mut inv = vec![0.0f32; rows.div_ceil(LANES) * LANES];
        for l in &self.layers {
            self.mean.apply(&x, batch * vecs, &mut m);
            gemm(
                bytemuck::cast_slice_mut(&mut z),
                bytemuck::cast_slice(&m),
                &l.centred_weight,
                rows,
                self.padded,
                self.padded,
                false,
            );
            for (v, zr) in inv.iter_mut().zip(z.chunks_exact(vecs)) {
                *v = zr
                    .iter()
                    .fold(f32x8::splat(0.0), |a, &q| a + q * q)
                    .reduce_add();
            }
            for c in inv.as_chunks_mut::<LANES>().0 {
                let var = f32x8::from(*c) * inv_w;
                *c = (f32x8::splat(1.0) / (var + eps).sqrt()).to_array();
            }
            for ((xr, zr), &s) in x.chunks_exact_mut(vecs).zip(z.chunks_exact(vecs)).zip(&inv) {
                let s = f32x8::splat(s);
                for (((xv, &zv), &g), &b) in xr.iter_mut().zip(zr).zip(&l.gamma).zip(&l.beta) {
                    *xv += (zv * s * g + b).fast_max(f32x8::splat(0.0));
                }
            }
        }
        for (hr, xr) in h.chunks_exact_mut(w).zip(x.chunks_exact(vecs)) {
            let flat: &[f32] = bytemuck::cast_slice(xr);
            hr.copy_from_slice(&flat[..w]);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::deepsets::DeepSetsConfig;
    use crate::gcn::GcnConfig;
    use crate::mlp::MlpConfig;
    use crate::{cpu, tensor2};
    use burn::tensor::{Tensor, TensorData};

    fn close(a: &[f32], b: &[f32], tol: f32) {
        assert_eq!(a.len(), b.len());
        for (i, (x, y)) in a.iter().zip(b).enumerate() {
            assert!(
                (x - y).abs() <= tol * (1.0 + y.abs()),
                "value {i}: {x} vs {y}"
            );
        }
    }

    #[test]
    fn mlp_matches_burn_for_every_activation() {
        let device = cpu();
        for act in [Activation::Relu, Activation::Gelu, Activation::Tanh] {
            let cfg = MlpConfig {
                input: 5,
                hidden: vec![17, 9],
                output: 3,
                activation: act,
            };
            let mlp = cfg.init(&device, 11);
            let x: Vec<f32> = (0..35).map(|i| (i as f32 * 0.41).sin() * 2.0).collect();
            let want = values(mlp.forward(tensor2(x.clone(), 7, 5, &device)));
            let dense = DenseMlp::from_mlp(&mlp);
            close(&dense.forward_rows(&x, 7), &want, 1e-5);
            close(&dense.forward_vec(&x[5..10]), &want[3..6], 1e-5);
        }
    }

    #[test]
    fn deepsets_matches_burn_including_the_empty_set() {
        let device = cpu();
        let enc = DeepSetsConfig {
            phi: MlpConfig::relu(3, &[16], 8),
            rho: MlpConfig::relu(8, &[16], 5),
            scale: 0.25,
        }
        .init(&device, 5)
        .unwrap();
        let dense = DenseDeepSets::from_deepsets(&enc);
        let p: Vec<f32> = (0..33).map(|i| (i as f32 * 0.77).cos()).collect();
        let want = values(enc.forward(Some(tensor2(p.clone(), 11, 3, &device)), &[11], &device));
        close(&dense.forward_set(&p), &want, 1e-5);
        let empty = values(enc.forward(None, &[0], &device));
        close(&dense.forward_set(&[]), &empty, 1e-6);
    }

    #[test]
    fn gcn_matches_burn_on_a_batch() {
        let device = cpu();
        let gcn = GcnConfig {
            width: 6,
            layers: 3,
        }
        .init(&device, 2);
        // A ring of 7 nodes with a chord, plus an isolated node.
        let mut edges: Vec<[usize; 2]> = (0..7).map(|i| [i, (i + 1) % 7]).collect();
        edges.push([0, 3]);
        let g = Graph::from_edges(8, &edges).unwrap();
        let x: Vec<f32> = (0..8 * 2 * 6).map(|i| (i as f32 * 0.29).sin()).collect();
        let want = values(gcn.forward(
            Tensor::<3>::from_data(TensorData::new(x.clone(), [8, 2, 6]), &device),
            &g.tensors(&device),
        ));
        let mut h = x;
        DenseGcn::new(&gcn, &g).forward(&mut h, 2);
        close(&h, &want, 1e-4);
    }
}
