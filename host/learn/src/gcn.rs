//! Residual graph convolution on a fixed graph (dissertation eq 6.13-6.14): mean over the
//! neighbours, a linear map, LayerNorm, ReLU, added to the input.
//!
//! Node features are laid out node-major, `[nodes, batch, width]`, so one gather and one
//! scatter-add over the edge list serve every sample of a batch that shares the graph.

use burn::module::Module;
use burn::nn::{Initializer, LayerNorm, LayerNormConfig, Linear, LinearConfig};
use burn::tensor::{Device, IndexingUpdateOp, Int, Tensor, TensorData, activation};
use serde::{Deserialize, Serialize};

use crate::error::{LearnError, Result};
use crate::init::seeded_init;

/// Epsilon of the layers' LayerNorm (burn's default, stated so plain evaluations match).
pub const LAYER_NORM_EPSILON: f64 = 1e-5;

/// A fixed undirected graph for mean aggregation: every edge is used in both directions.
#[derive(Debug, Clone, PartialEq)]
pub struct Graph {
    /// Number of nodes.
    pub num_nodes: usize,
    /// Message sources (both directions of every edge).
    pub src: Vec<usize>,
    /// Message targets, aligned with `src`.
    pub dst: Vec<usize>,
    /// 1 / degree of each node (0 for an isolated node, whose neighbour mean is then zero).
    pub inv_degree: Vec<f32>,
}

impl Graph {
    /// The graph of `num_nodes` nodes and undirected `edges`; duplicates (in either direction)
    /// count once, self-loops and out-of-range nodes are errors.
    pub fn from_edges(num_nodes: usize, edges: &[[usize; 2]]) -> Result<Self> {
        let mut set = std::collections::BTreeSet::new();
        for (k, &[a, b]) in edges.iter().enumerate() {
            if a >= num_nodes || b >= num_nodes {
                return Err(LearnError::Data(format!(
                    "graph edge {k} ({a}, {b}) names a node beyond the {num_nodes} nodes"
                )));
            }
            if a == b {
                return Err(LearnError::Data(format!(
                    "graph edge {k} is a self-loop on node {a}"
                )));
            }
            set.insert((a.min(b), a.max(b)));
        }
        let mut src = Vec::with_capacity(2 * set.len());
        let mut dst = Vec::with_capacity(2 * set.len());
        let mut degree = vec![0usize; num_nodes];
        for &(a, b) in &set {
            src.extend([a, b]);
            dst.extend([b, a]);
            degree[a] += 1;
            degree[b] += 1;
        }
        Ok(Self {
            num_nodes,
            src,
            dst,
            inv_degree: degree
                .iter()
                .map(|&d| if d == 0 { 0.0 } else { 1.0 / d as f32 })
                .collect(),
        })
    }

    /// The index and degree tensors on `device`.
    pub fn tensors(&self, device: &Device) -> GraphTensors {
        let ints = |v: &[usize]| {
            let v: Vec<i64> = v.iter().map(|&i| i as i64).collect();
            let n = v.len();
            Tensor::<1, Int>::from_data(TensorData::new(v, [n]), device)
        };
        GraphTensors {
            num_nodes: self.num_nodes,
            src: ints(&self.src),
            dst: ints(&self.dst),
            inv_degree: Tensor::from_data(
                TensorData::new(self.inv_degree.clone(), [self.num_nodes, 1]),
                device,
            ),
        }
    }
}

/// A [`Graph`] as tensors on one device.
#[derive(Debug, Clone)]
pub struct GraphTensors {
    num_nodes: usize,
    src: Tensor<1, Int>,
    dst: Tensor<1, Int>,
    inv_degree: Tensor<2>,
}

impl GraphTensors {
    /// Mean of the neighbours' features, `[nodes, batch, width]` to the same shape.
    pub fn mean_neighbours(&self, h: Tensor<3>) -> Tensor<3> {
        let [n, b, w] = h.dims();
        let flat = h.reshape([n, b * w]);
        let messages = flat.clone().select(0, self.src.clone());
        let sum = Tensor::<2>::zeros([self.num_nodes, b * w], &flat.device()).select_assign(
            0,
            self.dst.clone(),
            messages,
            IndexingUpdateOp::Add,
        );
        (sum * self.inv_degree.clone()).reshape([n, b, w])
    }
}

/// Shape of a [`Gcn`].
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct GcnConfig {
    /// Feature width of every node (kept by the residual layers).
    pub width: usize,
    /// Number of layers.
    pub layers: usize,
}

impl GcnConfig {
    /// Builds the layers with weights drawn from `seed`.
    pub fn init(&self, device: &Device, seed: u64) -> Gcn {
        let layers = (0..self.layers)
            .map(|_| GcnLayer {
                // Eq 6.13 has no bias: the LayerNorm's shift plays that part.
                linear: LinearConfig::new(self.width, self.width)
                    .with_bias(false)
                    .with_initializer(Initializer::Zeros)
                    .init(device),
                norm: LayerNormConfig::new(self.width)
                    .with_epsilon(LAYER_NORM_EPSILON)
                    .init(device),
            })
            .collect();
        seeded_init(Gcn { layers }, seed)
    }
}

/// One residual layer: `h + ReLU(LN(W mean_{u in N(v)} h_u))`.
#[derive(Module, Debug)]
pub struct GcnLayer {
    linear: Linear,
    norm: LayerNorm,
}

impl GcnLayer {
    /// The linear map W (no bias).
    pub fn linear(&self) -> &Linear {
        &self.linear
    }

    /// The LayerNorm.
    pub fn norm(&self) -> &LayerNorm {
        &self.norm
    }

    /// Applies the layer to `[nodes, batch, width]`.
    pub fn forward(&self, h: Tensor<3>, graph: &GraphTensors) -> Tensor<3> {
        let m = self.linear.forward(graph.mean_neighbours(h.clone()));
        h + activation::relu(self.norm.forward(m))
    }
}

/// A stack of residual mean-aggregation graph convolutions.
#[derive(Module, Debug)]
pub struct Gcn {
    /// The layers, applied in order.
    pub layers: Vec<GcnLayer>,
}

impl Gcn {
    /// Propagates `[nodes, batch, width]` through every layer.
    pub fn forward(&self, h: Tensor<3>, graph: &GraphTensors) -> Tensor<3> {
        self.layers.iter().fold(h, |h, l| l.forward(h, graph))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::{cpu, cpu_autodiff, values};

    fn path4() -> Graph {
        // 0 - 1 - 2 - 3 plus a duplicate (reversed) edge and an isolated node 4.
        Graph::from_edges(5, &[[0, 1], [1, 2], [2, 3], [2, 1]]).unwrap()
    }

    #[test]
    fn mean_of_neighbours_matches_hand_computation() {
        let device = cpu();
        let g = path4();
        assert_eq!(
            g.src.len(),
            6,
            "duplicate edge counted once, both directions"
        );
        let x: Vec<f32> = vec![1.0, 10.0, 2.0, 20.0, 4.0, 40.0, 8.0, 80.0, 16.0, 160.0];
        let h = Tensor::<3>::from_data(TensorData::new(x, [5, 1, 2]), &device);
        let m = values(g.tensors(&device).mean_neighbours(h));
        let expect = [2.0, 20.0, 2.5, 25.0, 5.0, 50.0, 4.0, 40.0, 0.0, 0.0];
        for (a, b) in m.iter().zip(expect) {
            assert!((a - b).abs() < 1e-6, "{m:?}");
        }
    }

    #[test]
    fn bad_edges_are_errors() {
        assert!(
            Graph::from_edges(2, &[[0, 2]])
                .unwrap_err()
                .to_string()
                .contains("edge 0")
        );
        assert!(
            Graph::from_edges(2, &[[1, 1]])
                .unwrap_err()
                .to_string()
                .contains("self-loop")
        );
    }

    /// The layer against a plain f64 evaluation of eq 6.13-6.14.
    #[test]
    fn layer_matches_independent_evaluation() {
        let device = cpu();
        let gcn = GcnConfig {
            width: 3,
            layers: 1,
        }
        .init(&device, 4);
        let g = path4();
        let x: Vec<f32> = (0..30).map(|i| (i as f32 * 0.37).sin()).collect();
        let h = Tensor::<3>::from_data(TensorData::new(x.clone(), [5, 2, 3]), &device);
        let out = values(gcn.forward(h, &g.tensors(&device)));
        let w = values(gcn.layers[0].linear.weight.val()); // [in, out]
        let xs = |v: usize, b: usize, k: usize| f64::from(x[(v * 2 + b) * 3 + k]);
        for v in 0..5 {
            for b in 0..2 {
                let nb: Vec<usize> = (0..g.src.len())
                    .filter(|&e| g.dst[e] == v)
                    .map(|e| g.src[e])
                    .collect();
                let mean: Vec<f64> = (0..3)
                    .map(|k| {
                        if nb.is_empty() {
                            0.0
                        } else {
                            nb.iter().map(|&u| xs(u, b, k)).sum::<f64>() / nb.len() as f64
                        }
                    })
                    .collect();
                let m: Vec<f64> = (0..3)
                    .map(|o| (0..3).map(|i| mean[i] * f64::from(w[i * 3 + o])).sum())
                    .collect();
                let mu = m.iter().sum::<f64>() / 3.0;
                let var = m.iter().map(|a| (a - mu).powi(2)).sum::<f64>() / 3.0;
                for o in 0..3 {
                    let ln = (m[o] - mu) / (var + 1e-5).sqrt();
                    let expect = xs(v, b, o) + ln.max(0.0);
                    let got = f64::from(out[(v * 2 + b) * 3 + o]);
                    assert!(
                        (got - expect).abs() < 1e-4,
                        "node {v} sample {b}: {got} vs {expect}"
                    );
                }
            }
        }
    }

    #[test]
    fn relabelling_the_nodes_permutes_the_output() {
        let device = cpu();
        let gcn = GcnConfig {
            width: 4,
            layers: 3,
        }
        .init(&device, 1);
        let g = path4();
        let perm = [3usize, 0, 4, 1, 2]; // new index of old node i
        let edges: Vec<[usize; 2]> = (0..g.src.len())
            .map(|e| [perm[g.src[e]], perm[g.dst[e]]])
            .collect();
        let gp = Graph::from_edges(5, &edges).unwrap();
        let x: Vec<f32> = (0..20).map(|i| (i as f32 * 0.7).cos()).collect();
        let mut xp = vec![0.0; 20];
        for i in 0..5 {
            xp[perm[i] * 4..perm[i] * 4 + 4].copy_from_slice(&x[i * 4..i * 4 + 4]);
        }
        let run = |v: Vec<f32>, g: &Graph| {
            values(gcn.forward(
                Tensor::<3>::from_data(TensorData::new(v, [5, 1, 4]), &device),
                &g.tensors(&device),
            ))
        };
        let (a, b) = (run(x, &g), run(xp, &gp));
        for i in 0..5 {
            for k in 0..4 {
                assert!((a[i * 4 + k] - b[perm[i] * 4 + k]).abs() < 1e-5);
            }
        }
    }

    #[test]
    fn input_gradient_matches_finite_differences() {
        let device = cpu_autodiff();
        let gcn = GcnConfig {
            width: 4,
            layers: 2,
        }
        .init(&device, 7);
        let g = path4().tensors(&device);
        let base: Vec<f32> = (0..40).map(|i| (i as f32 * 0.53).sin()).collect();
        let wv: Vec<f32> = (0..40).map(|i| (i as f32 * 0.29).cos()).collect();
        let weight = Tensor::<3>::from_data(TensorData::new(wv, [5, 2, 4]), &device);
        let loss = |v: &[f32], track: bool| {
            let mut x = Tensor::<3>::from_data(TensorData::new(v.to_vec(), [5, 2, 4]), &device);
            if track {
                x = x.require_grad();
            }
            ((gcn.forward(x.clone(), &g) * weight.clone()).sum(), x)
        };
        let pairs =
            crate::gradcheck::gradient_pairs(&base, &[0, 7, 13, 22, 31, 39], 1e-2, loss).unwrap();
        for p in pairs {
            assert!(p.agrees(3e-3, 3e-2), "input {}: {p:?}", p.index);
        }
    }
}
