//! The engine's forward pass for one call on plain `f32` values (`ocm_learn::infer`): the
//! weights, the graph's neighbour lists and the scaled rest positions are laid out once when
//! the engine is built, so a call allocates a few buffers and builds no tensor. It computes
//! what [`NpeNet::forward`] computes (tested against it); training and batched evaluation stay
//! on burn.

use ocm_learn::gcn::Graph;
use ocm_learn::infer::{DenseDeepSets, DenseGcn, DenseMlp};

use crate::model::{Inputs, NpeConfig, NpeNet, prior_row};

/// The network of one engine as plain layers.
#[derive(Debug, Clone)]
pub struct Kernel {
    encoder: DenseDeepSets,
    fusion: DenseMlp,
    gcn: DenseGcn,
    readout: DenseMlp,
    contact: Option<DenseMlp>,
    /// Scaled rest positions, `[nodes, 3]`.
    positions: Vec<f32>,
    use_geometry: bool,
    use_force: bool,
    geometry_features: usize,
    /// Scaled-penetration-to-displacement factor when the readout carries the contact prior.
    prior: Option<f32>,
    /// Gain and offset of the contact head's threshold rule ([`NpeConfig::contact_rule`]).
    rule: (f32, f32),
    /// Whether the node states carry the gap input ([`NpeConfig::node_gap`]).
    gap: bool,
}

impl Kernel {
    /// Lays out `net` (configured by `cfg`) on `graph` with the scaled rest positions
    /// `positions` (`[nodes, 3]`, row-major).
    pub fn new(net: &NpeNet, cfg: &NpeConfig, graph: &Graph, positions: Vec<f32>) -> Self {
        Kernel {
            encoder: DenseDeepSets::from_deepsets(&net.encoder),
            fusion: DenseMlp::from_mlp(&net.fusion),
            gcn: DenseGcn::new(&net.gcn, graph),
            readout: DenseMlp::from_mlp(&net.readout),
            contact: net.contact.as_ref().map(DenseMlp::from_mlp),
            positions,
            use_geometry: cfg.use_geometry,
            use_force: cfg.use_force,
            geometry_features: cfg.geometry_features,
            prior: cfg.contact_prior.then(|| cfg.depth_to_displacement()),
            rule: cfg.contact_rule(),
            gap: cfg.node_gap,
        }
    }

    fn nodes(&self) -> usize {
        self.positions.len() / 3
    }

    /// h_global of the first sample of `x` (eq 6.10-6.11).
    pub fn global(&self, x: &Inputs) -> Vec<f32> {
        let count = x.counts.first().copied().unwrap_or(0);
        let mut g = if self.use_geometry {
            self.encoder.forward_set(&x.points[..3 * count])
        } else {
            vec![0.0; self.geometry_features]
        };
        let force = if self.use_force { x.scalars[0] } else { 0.0 };
        g.extend([force, x.scalars[1]]);
        self.fusion.forward_vec(&g)
    }

    /// Scaled nodal (displacement, force) of the first sample of `x`, `[nodes, 6]`, and its
    /// h_global.
    pub fn forward(&self, x: &Inputs) -> (Vec<f32>, Vec<f32>) {
        let (out, _, hg) = self.run(x, false);
        (out, hg)
    }

    /// [`Kernel::forward`] and the contact head's logit per node (None without a head).
    pub fn forward_full(&self, x: &Inputs) -> (Vec<f32>, Option<Vec<f32>>, Vec<f32>) {
        self.run(x, true)
    }

    /// The pass, with the contact head only when asked (it costs about a tenth of a call).
    fn run(&self, x: &Inputs, with_head: bool) -> (Vec<f32>, Option<Vec<f32>>, Vec<f32>) {
        let hg = self.global(x);
        let n = self.nodes();
        let width = self.gcn.width();
        let depth = (self.use_geometry && x.node_depth.len() >= n).then(|| &x.node_depth[..n]);
        let gap = (self.gap && x.node_gap.len() >= 2 * n).then(|| &x.node_gap[..2 * n]);
        let mut h = Vec::with_capacity(n * width);
        for v in 0..n {
            h.extend_from_slice(&hg);
            h.extend_from_slice(&self.positions[3 * v..3 * v + 3]);
            h.push(depth.map_or(0.0, |d| d[v]));
            if self.gap {
                h.extend_from_slice(gap.map_or(&[0.0, 0.0], |g| &g[2 * v..2 * v + 2]));
            }
        }
        debug_assert_eq!(h.len(), n * width);
        self.gcn.forward(&mut h, 1);
        let head = self
            .contact
            .as_ref()
            .filter(|_| with_head)
            .map(|c| c.forward_rows(&h, n));
        let mut out = self.readout.forward_rows(&h, n);
        if let (Some(k), Some(d)) = (self.prior, depth)
            && x.node_gate.len() >= n
        {
            for (v, row) in out.chunks_mut(6).enumerate() {
                let (mul, add) = prior_row(d[v], x.node_gate[v], k);
                for c in 0..6 {
                    row[c] = row[c] * mul[c] + add[c];
                }
            }
        }
        let logits = head.map(|mut z| {
            let (gain, t) = self.rule;
            for (l, row) in z.iter_mut().zip(out.chunks(6)) {
                *l += (-row[2] - t) * gain;
            }
            z
        });
        (out, logits, hg)
    }
}
