//! Plain `f32` inference of trained modules for latency-bound single calls: the weights are
//! copied out of the burn modules once, the dense products go through faer's matrix kernels,
//! and a call builds no tensor, graph or autodiff state. Training stays on burn; these mirror
//! [`Mlp::forward`], [`DeepSets::forward`] and [`Gcn::forward`] and are tested against them.

use burn::nn::Linear;
use faer::linalg::matmul::matmul;
use faer::{Accum, MatMut, MatRef, Par};
use pulp::{Simd, WithSimd};

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
            /// ReLU on the widest vectors the CPU has ([`DenseGcn::forward`] says why).
            struct Relu<'a>(&'a mut [f32]);
            impl WithSimd for Relu<'_> {
                type Output = ();
                #[inline(always)]
                fn with_simd<S: Simd>(self, simd: S) {
                    let (head, tail) = S::as_mut_simd_f32s(self.0);
                    let zero = simd.splat_f32s(0.0);
                    head.iter_mut().for_each(|c| *c = simd.max_f32s(*c, zero));
                    tail.iter_mut().for_each(|x| *x = x.max(0.0));
                }
            }
            pulp::Arch::new().dispatch(Relu(v));
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

/// Rows of node states are padded to a multiple of this many values: every vector width pulp
/// dispatches to (1, 4, 8 or 16 lanes) divides it, so a row is whole vectors on every CPU.
const ROW_ALIGN: usize = 16;

/// Rows of node states a GCN layer computes at a time (their means and products take 32 kB
/// each at width 32).
const GCN_BLOCK_ROWS: usize = 256;

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

    /// `out[v - first] = mean_{u in N(v)} h[u]` for the nodes `v` from `first` on that `out`
    /// holds, node rows of `row` vectors.
    #[inline(always)]
    fn apply<S: Simd>(
        &self,
        simd: S,
        h: &[S::f32s],
        row: usize,
        first: usize,
        out: &mut [S::f32s],
    ) {
        // The common widths get a fixed-length accumulator the compiler keeps in registers.
        match row {
            1 => self.apply_fixed::<S, 1>(simd, h, first, out),
            2 => self.apply_fixed::<S, 2>(simd, h, first, out),
            4 => self.apply_fixed::<S, 4>(simd, h, first, out),
            8 => self.apply_fixed::<S, 8>(simd, h, first, out),
            _ => {
                for (v, acc) in (first..).zip(out.chunks_exact_mut(row)) {
                    acc.fill(simd.splat_f32s(0.0));
                    for &u in &self.neighbours[self.offsets[v]..self.offsets[v + 1]] {
                        for (a, &x) in acc.iter_mut().zip(&h[u * row..(u + 1) * row]) {
                            *a = simd.add_f32s(*a, x);
                        }
                    }
                    let s = simd.splat_f32s(self.inv_degree[v]);
                    acc.iter_mut().for_each(|a| *a = simd.mul_f32s(*a, s));
                }
            }
        }
    }

    #[inline(always)]
    fn apply_fixed<S: Simd, const R: usize>(
        &self,
        simd: S,
        h: &[S::f32s],
        first: usize,
        out: &mut [S::f32s],
    ) {
        let (rows, _) = h.as_chunks::<R>();
        let (outs, _) = out.as_chunks_mut::<R>();
        for (v, o) in (first..).zip(outs.iter_mut()) {
            let mut acc = [simd.splat_f32s(0.0); R];
            for &u in &self.neighbours[self.offsets[v]..self.offsets[v + 1]] {
                let x = &rows[u];
                for k in 0..R {
                    acc[k] = simd.add_f32s(acc[k], x[k]);
                }
            }
            let s = simd.splat_f32s(self.inv_degree[v]);
            for k in 0..R {
                o[k] = simd.mul_f32s(acc[k], s);
            }
        }
    }
}

/// One residual layer `h + ReLU(LN(W mean_N h))` with the LayerNorm's centring folded into
/// the weight (`W (I - 11^T / w)`, so the product is already centred per row), padded to whole
/// rows of [`ROW_ALIGN`] values with zeros (padded lanes stay zero).
#[derive(Debug, Clone, PartialEq)]
struct DenseGcnLayer {
    centred_weight: Vec<f32>,
    gamma: Vec<f32>,
    beta: Vec<f32>,
}

/// A [`Gcn`] on a fixed graph as plain layers.
#[derive(Debug, Clone, PartialEq)]
pub struct DenseGcn {
    width: usize,
    padded: usize,
    layers: Vec<DenseGcnLayer>,
    mean: NeighbourMean,
}

/// `v` followed by zeros up to `len` values.
fn padded_to(mut v: Vec<f32>, len: usize) -> Vec<f32> {
    v.resize(len, 0.0);
    v
}

impl DenseGcn {
    /// Copies the weights of a burn GCN for `graph`.
    pub fn new(gcn: &Gcn, graph: &Graph) -> Self {
        let width = gcn
            .layers
            .first()
            .map_or(0, |l| l.linear().weight.dims()[1]);
        let padded = width.div_ceil(ROW_ALIGN) * ROW_ALIGN;
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
                    gamma: padded_to(values(norm.gamma.val()), padded),
                    beta: padded_to(
                        norm.beta
                            .as_ref()
                            .map_or_else(|| vec![0.0; w], |b| values(b.val())),
                        padded,
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
    /// place. The node-state loops run on the widest vectors the CPU has, chosen at run time
    /// (the crate is built for baseline x86-64, whose SSE2 holds 4 values per instruction).
    pub fn forward(&self, h: &mut [f32], batch: usize) {
        /// pulp's dispatch inlines `with_simd` into a function compiled with the detected
        /// target features (a closure's body would not be).
        struct Propagate<'a>(&'a DenseGcn, &'a mut [f32], usize);
        impl WithSimd for Propagate<'_> {
            type Output = ();
            #[inline(always)]
            fn with_simd<S: Simd>(self, simd: S) {
                self.0.forward_in(simd, self.1, self.2);
            }
        }
        pulp::Arch::new().dispatch(Propagate(self, h, batch));
    }

    #[inline(always)]
    fn forward_in<S: Simd>(&self, simd: S, h: &mut [f32], batch: usize) {
        let (w, p) = (self.width, self.padded);
        let nodes = self.mean.num_nodes();
        let rows = nodes * batch;
        debug_assert_eq!(h.len(), rows * w);
        let mut x = vec![0.0f32; rows * p];
        for (xr, hr) in x.chunks_exact_mut(p).zip(h.chunks_exact(w)) {
            xr[..w].copy_from_slice(hr);
        }
        // A layer reads the previous layer's states whole (the neighbour means) and writes the
        // next ones block by block, so the means and products of a block stay in cache.
        let mut next = vec![0.0f32; x.len()];
        let block_nodes = GCN_BLOCK_ROWS.div_ceil(batch).max(1);
        let block_rows = block_nodes * batch;
        let mut m = vec![0.0f32; block_rows * p];
        let mut z = vec![0.0f32; block_rows * p];
        let vecs = p / S::F32_LANES;
        let zero = simd.splat_f32s(0.0);
        let inv_w = 1.0 / w as f32;
        let eps = simd.splat_f32s(LAYER_NORM_EPSILON as f32);
        // 1 / sqrt(variance + eps) per row, the square roots a vector of rows at a time: one
        // per row would otherwise be a serial chain.
        let mut inv = vec![0.0f32; block_rows.div_ceil(ROW_ALIGN) * ROW_ALIGN];
        for l in &self.layers {
            let gamma = S::as_simd_f32s(&l.gamma).0;
            let beta = S::as_simd_f32s(&l.beta).0;
            for first in (0..nodes).step_by(block_nodes) {
                let n = (nodes - first).min(block_nodes) * batch;
                let (m, z) = (&mut m[..n * p], &mut z[..n * p]);
                let xv = S::as_simd_f32s(&x).0;
                self.mean
                    .apply(simd, xv, batch * vecs, first, S::as_mut_simd_f32s(m).0);
                gemm(z, m, &l.centred_weight, n, p, p, false);
                let zv = S::as_simd_f32s(z).0;
                for (v, zr) in inv.iter_mut().zip(zv.chunks_exact(vecs)) {
                    let sq = zr.iter().fold(zero, |a, &q| simd.mul_add_f32s(q, q, a));
                    *v = simd.reduce_sum_f32s(sq) * inv_w;
                }
                for c in S::as_mut_simd_f32s(&mut inv).0 {
                    *c =
                        simd.div_f32s(simd.splat_f32s(1.0), simd.sqrt_f32s(simd.add_f32s(*c, eps)));
                }
                let rows = first * batch * vecs..(first * batch + n) * vecs;
                let xr = xv[rows.clone()].chunks_exact(vecs);
                let yv = &mut S::as_mut_simd_f32s(&mut next).0[rows];
                for (((yr, xr), zr), &s) in yv
                    .chunks_exact_mut(vecs)
                    .zip(xr)
                    .zip(zv.chunks_exact(vecs))
                    .zip(&inv)
                {
                    let s = simd.splat_f32s(s);
                    for ((((yv, &xv), &zv), &g), &b) in
                        yr.iter_mut().zip(xr).zip(zr).zip(gamma).zip(beta)
                    {
                        let y = simd.mul_add_f32s(simd.mul_f32s(zv, s), g, b);
                        *yv = simd.add_f32s(xv, simd.max_f32s(y, zero));
                    }
                }
            }
            std::mem::swap(&mut x, &mut next);
        }
        for (hr, xr) in h.chunks_exact_mut(w).zip(x.chunks_exact(p)) {
            hr.copy_from_slice(&xr[..w]);
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
        // A ring of 7 nodes with a chord, plus an isolated node; and a ring of 300 nodes with
        // chords, whose layers take several blocks of rows (GCN_BLOCK_ROWS) with a partial
        // last one.
        let mut small: Vec<[usize; 2]> = (0..7).map(|i| [i, (i + 1) % 7]).collect();
        small.push([0, 3]);
        let mut large: Vec<[usize; 2]> = (0..300).map(|i| [i, (i + 1) % 300]).collect();
        large.extend((0..300).step_by(7).map(|i| [i, (i * 13 + 5) % 300]));
        for (nodes, edges) in [(8, small), (300, large)] {
            let batch = 2;
            let g = Graph::from_edges(nodes, &edges).unwrap();
            let x: Vec<f32> = (0..nodes * batch * 6)
                .map(|i| (i as f32 * 0.29).sin())
                .collect();
            let want = values(gcn.forward(
                Tensor::<3>::from_data(TensorData::new(x.clone(), [nodes, batch, 6]), &device),
                &g.tensors(&device),
            ));
            let dense = DenseGcn::new(&gcn, &g);
            let mut h = x.clone();
            dense.forward(&mut h, batch);
            close(&h, &want, 1e-4);
            // Every vector width the dispatch may pick (1, 4, 8 and 16 lanes), whatever this
            // CPU has: a row is whole vectors on each.
            for lanes in [1, 4, 8, 16] {
                let mut h = x.clone();
                match lanes {
                    1 => dense.forward_in(pulp::Scalar::new(), &mut h, batch),
                    4 => dense.forward_in(pulp::Scalar128b, &mut h, batch),
                    8 => dense.forward_in(pulp::Scalar256b, &mut h, batch),
                    _ => dense.forward_in(pulp::Scalar512b, &mut h, batch),
                }
                close(&h, &want, 1e-4);
            }
        }
    }

    #[test]
    fn relu_on_any_length_clears_only_negatives() {
        let mut v: Vec<f32> = (0..37).map(|i| (i as f32 * 0.9).sin()).collect();
        let want: Vec<f32> = v.iter().map(|x| x.max(0.0)).collect();
        Activation::Relu.apply_slice(&mut v);
        assert_eq!(v, want);
    }
}
