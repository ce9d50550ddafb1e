//! The geometry-aware network (dissertation eq 6.10-6.15): DeepSets over the contact points,
//! fusion with force and depth, node states `[h_global || position]` on the top-surface
//! graph, residual mean-aggregation GCN layers and a shared readout of nodal displacement and
//! force.

use ocm_learn::burn;
use ocm_learn::burn::module::Module;
use ocm_learn::burn::tensor::{Device, Tensor, TensorData};
use ocm_learn::deepsets::{DeepSets, DeepSetsConfig};
use ocm_learn::gcn::{Gcn, GcnConfig, GraphTensors};
use ocm_learn::{Mlp, MlpConfig};
use serde::{Deserialize, Serialize};

use crate::{NpeError, Result};

/// Displacement past the contact threshold that the contact head's rule term turns into one
/// logit, m.
pub const CONTACT_RULE_WIDTH_M: f64 = 10e-6;

/// Architecture name stored in checkpoints.
pub const ARCHITECTURE: &str = "npe/ga-gnn";

/// Where the sensor is and the fixed scales that bring inputs and targets to order one.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Scales {
    /// Centre of the top face (x, y) and its highest point (z), m: the origin of the scaled
    /// coordinates.
    pub center_m: [f64; 3],
    /// Length that scales x and y, m.
    pub xy_m: f64,
    /// Length that scales z (heights relative to the top), m.
    pub z_m: f64,
    /// Force that scales the resultant force input, N.
    pub force_n: f64,
    /// Depth that scales the depth input, m.
    pub depth_m: f64,
    /// Displacement unit of the targets, m.
    pub displacement_m: f64,
    /// Nodal force unit of the targets, N.
    pub nodal_force_n: f64,
}

impl Scales {
    /// Scaled coordinates of a sensor-frame point.
    pub fn point(&self, p: &[f64; 3]) -> [f32; 3] {
        [
            ((p[0] - self.center_m[0]) / self.xy_m) as f32,
            ((p[1] - self.center_m[1]) / self.xy_m) as f32,
            ((p[2] - self.center_m[2]) / self.z_m) as f32,
        ]
    }
}

/// Widths, depth and inputs of the network, the scales and the loss weight.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct NpeConfig {
    /// Hidden width of the point network phi.
    pub point_hidden: usize,
    /// Features per point after phi (d_h).
    pub point_features: usize,
    /// Geometric embedding width (d_g).
    pub geometry_features: usize,
    /// Hidden width of the fusion MLP.
    pub fusion_hidden: usize,
    /// Node state width: h_global takes what the node inputs leave
    /// ([`NpeConfig::global_width`]): the rest position takes 3, the node's own penetration by
    /// the contact points 1 and, with [`NpeConfig::node_gap`], the gap input 2.
    pub width: usize,
    /// Number of GCN layers (L).
    pub layers: usize,
    /// Hidden width of the readout MLP.
    pub readout_hidden: usize,
    /// Whether the contact points reach the network (false: the ablation without geometry).
    pub use_geometry: bool,
    /// Whether the resultant force reaches the network (false: the FEM point network of
    /// Ch.6.6.1, geometry and depth only).
    pub use_force: bool,
    /// Factor on the DeepSets sum: the grid cell area in units of 10 mm^2, so the sum is an
    /// integral over the contact region.
    pub set_scale: f64,
    /// Input and target scales.
    pub scales: Scales,
    /// Weight of the nodal force term in the loss (eq 6.17), on the scaled targets.
    pub lambda: f64,
    /// Weight of the resultant term: the squared error of the summed nodal force (the force
    /// on the body), in newtons. Zero in checkpoints written before it existed; left out of
    /// the stored configuration when zero, so those checkpoints still load.
    #[serde(default, skip_serializing_if = "is_zero")]
    pub lambda_total: f64,
    /// The contact prior on the readout: the nodal force is zero outside the nodes the body
    /// penetrates (and their neighbours), and the vertical displacement is read out as a
    /// correction to minus the node's own penetration. False in checkpoints written before it
    /// existed (then not stored, so those still load).
    #[serde(default, skip_serializing_if = "is_false")]
    pub contact_prior: bool,
    /// A contact head beside the readout: a logit per node of "in contact in the FEM"
    /// (-u_z > 30 um), trained with a binary cross-entropy on the FEM's own contact flags, so
    /// the contact state is classified rather than read off a threshold on the regressed u_z.
    /// False in checkpoints written before it existed (then not stored).
    #[serde(default, skip_serializing_if = "is_false")]
    pub contact_head: bool,
    /// Weight of the contact head's cross-entropy in the loss (0 when there is no head).
    #[serde(default, skip_serializing_if = "is_zero")]
    pub lambda_contact: f64,
    /// The gap input: two more values in each node's initial state, the x-y distance to the
    /// nearest contact point (within [`crate::data::GAP_REACH_M`]) and that point's signed
    /// height above the node (negative: it presses the node down), so a node just outside
    /// the contact knows how near and how deep the body is. False in checkpoints written
    /// before it existed (then not stored, so those still load).
    #[serde(default, skip_serializing_if = "is_false")]
    pub node_gap: bool,
}

fn is_zero(v: &f64) -> bool {
    *v == 0.0
}

fn is_false(v: &bool) -> bool {
    !*v
}

impl NpeConfig {
    /// The default network for contact points on a grid of `spacing_m` over a top face
    /// centred at `center_m`.
    pub fn new(center_m: [f64; 3], spacing_m: f64) -> Self {
        NpeConfig {
            point_hidden: 64,
            point_features: 64,
            geometry_features: 64,
            fusion_hidden: 64,
            width: 32,
            layers: 6,
            readout_hidden: 64,
            use_geometry: true,
            use_force: true,
            set_scale: spacing_m * spacing_m * 1e6 / 10.0,
            scales: Scales {
                center_m,
                xy_m: 5e-3,
                z_m: 0.5e-3,
                force_n: 2.0,
                depth_m: 0.5e-3,
                displacement_m: 1e-4,
                nodal_force_n: 0.01,
            },
            lambda: 1.0,
            lambda_total: 0.0,
            contact_prior: false,
            contact_head: false,
            lambda_contact: 0.0,
            node_gap: false,
        }
    }

    /// Spacing of the contact grid the engine was built for, m (from [`NpeConfig::set_scale`]:
    /// the cell area in units of 10 mm^2).
    pub fn grid_spacing_m(&self) -> f64 {
        (self.set_scale * 10.0 * 1e-6).sqrt()
    }

    /// Factor from the scaled penetration input to the scaled displacement target.
    pub fn depth_to_displacement(&self) -> f32 {
        (self.scales.z_m / self.scales.displacement_m) as f32
    }

    /// Values each node adds to its initial state: its rest position (3), its own
    /// penetration (1) and, with the gap input, the distance and height of the nearest
    /// contact point (2).
    pub fn node_inputs(&self) -> usize {
        if self.node_gap { 6 } else { 4 }
    }

    /// Width of h_global: the node state less the node's own inputs.
    pub fn global_width(&self) -> usize {
        self.width.saturating_sub(self.node_inputs())
    }

    /// Builds the network with weights drawn from `seed`.
    pub fn init(&self, device: &Device, seed: u64) -> Result<NpeNet> {
        if self.width <= self.node_inputs() || self.layers == 0 {
            return Err(NpeError::Input(format!(
                "NPE width {} must exceed the {} node inputs and layers {} be positive",
                self.width,
                self.node_inputs(),
                self.layers
            )));
        }
        if self.contact_prior && !self.use_geometry {
            return Err(NpeError::Input(
                "the contact prior needs the contact points (geometry input)".into(),
            ));
        }
        if self.node_gap && !self.use_geometry {
            return Err(NpeError::Input(
                "the gap input needs the contact points (geometry input)".into(),
            ));
        }
        let encoder = DeepSetsConfig {
            phi: MlpConfig::relu(3, &[self.point_hidden], self.point_features),
            rho: MlpConfig::relu(
                self.point_features,
                &[self.point_hidden],
                self.geometry_features,
            ),
            scale: self.set_scale,
        }
        .init(device, seed)?;
        Ok(NpeNet {
            encoder,
            fusion: MlpConfig::relu(
                self.geometry_features + 2,
                &[self.fusion_hidden],
                self.global_width(),
            )
            .init(device, seed.wrapping_add(10)),
            gcn: GcnConfig {
                width: self.width,
                layers: self.layers,
            }
            .init(device, seed.wrapping_add(20)),
            readout: MlpConfig::relu(self.width, &[self.readout_hidden], 6)
                .init(device, seed.wrapping_add(30)),
            contact: self
                .contact_head
                .then(|| self.contact_head_init(device, seed)),
        })
    }

    /// Gain and offset of the threshold rule inside the contact head's logit, in the scaled
    /// displacement: `logit = head(h) + gain (-u_z - t)`, t being the metric's 30 um. The head
    /// starts near the rule on the regressed u_z ([`CONTACT_RULE_WIDTH_M`] past the threshold
    /// = 1 logit) and learns the correction where the rule fails.
    pub fn contact_rule(&self) -> (f32, f32) {
        let unit = self.scales.displacement_m;
        (
            (unit / CONTACT_RULE_WIDTH_M) as f32,
            (ocm_tactile::mask::CONTACT_THRESHOLD_M / unit) as f32,
        )
    }

    /// A fresh contact head (final node state -> readout width -> one logit).
    pub fn contact_head_init(&self, device: &Device, seed: u64) -> Mlp {
        MlpConfig::relu(self.width, &[self.readout_hidden], 1).init(device, seed.wrapping_add(40))
    }
}

/// Inputs of a batch, already scaled.
#[derive(Debug, Clone, Default)]
pub struct Inputs {
    /// Contact points of every sample, sample after sample, scaled (3 per point).
    pub points: Vec<f32>,
    /// Points per sample.
    pub counts: Vec<usize>,
    /// Scaled (force, depth) per sample.
    pub scalars: Vec<f32>,
    /// Scaled penetration of each node by the contact points nearest to it, sample after
    /// sample (`nodes` per sample; 0 where no point is nearest).
    pub node_depth: Vec<f32>,
    /// Contact gate of each node, sample after sample: 1 where the node or a neighbour is
    /// penetrated, else 0 (filled only for an engine with the contact prior).
    pub node_gate: Vec<f32>,
    /// Gap input of each node, sample after sample, 2 per node: the scaled x-y distance to
    /// the nearest contact point and that point's scaled height above the node
    /// ([`crate::data::NodeLocator::node_gap`]; filled only for an engine with the gap input).
    pub node_gap: Vec<f32>,
}

/// Multiplier and offset that apply the contact prior to a scaled readout row
/// `(u_x, u_y, u_z, f_x, f_y, f_z)`: `out * mul + add`. `depth` is the node's scaled
/// penetration, `gate` its contact gate; `depth_to_u` converts the penetration's scale to the
/// displacement's.
pub fn prior_row(depth: f32, gate: f32, depth_to_u: f32) -> ([f32; 6], [f32; 6]) {
    (
        [1.0, 1.0, 1.0, gate, gate, gate],
        [0.0, 0.0, -depth * depth_to_u, 0.0, 0.0, 0.0],
    )
}

/// The network.
#[derive(Module, Debug)]
pub struct NpeNet {
    pub(crate) encoder: DeepSets,
    pub(crate) fusion: Mlp,
    pub(crate) gcn: Gcn,
    pub(crate) readout: Mlp,
    pub(crate) contact: Option<Mlp>,
}

impl NpeNet {
    /// The global context h_global, `[batch, global_width]`.
    pub fn global(&self, cfg: &NpeConfig, x: &Inputs, device: &Device) -> Tensor<2> {
        let b = x.counts.len();
        let total: usize = x.counts.iter().sum();
        let g = if cfg.use_geometry {
            let pts = (total > 0).then(|| {
                Tensor::<2>::from_data(TensorData::new(x.points.clone(), [total, 3]), device)
            });
            self.encoder.forward(pts, &x.counts, device)
        } else {
            Tensor::<2>::zeros([b, cfg.geometry_features], device)
        };
        let mut s = x.scalars.clone();
        if !cfg.use_force {
            for k in 0..b {
                s[2 * k] = 0.0;
            }
        }
        let s = Tensor::<2>::from_data(TensorData::new(s, [b, 2]), device);
        self.fusion.forward(Tensor::cat(vec![g, s], 1))
    }

    fn node_depth(&self, cfg: &NpeConfig, x: &Inputs, n: usize, device: &Device) -> Tensor<3> {
        let b = x.counts.len();
        if !cfg.use_geometry || x.node_depth.len() != b * n {
            return Tensor::<3>::zeros([n, b, 1], device);
        }
        Tensor::<3>::from_data(TensorData::new(x.node_depth.clone(), [b, n, 1]), device)
            .swap_dims(0, 1)
    }

    /// The gap input `[nodes, batch, 2]` (zeros when the inputs carry none).
    fn node_gap(&self, x: &Inputs, n: usize, device: &Device) -> Tensor<3> {
        let b = x.counts.len();
        if x.node_gap.len() != b * n * 2 {
            return Tensor::<3>::zeros([n, b, 2], device);
        }
        Tensor::<3>::from_data(TensorData::new(x.node_gap.clone(), [b, n, 2]), device)
            .swap_dims(0, 1)
    }

    /// Scaled nodal (displacement, force), `[nodes, batch, 6]`, and h_global.
    /// `positions` is the scaled rest position of every node, `[nodes, 1, 3]`; the node
    /// states start as `[h_global || position || own penetration]`.
    pub fn forward(
        &self,
        cfg: &NpeConfig,
        x: &Inputs,
        positions: &Tensor<3>,
        graph: &GraphTensors,
        device: &Device,
    ) -> (Tensor<3>, Tensor<2>) {
        let (out, _, hg) = self.forward_full(cfg, x, positions, graph, device);
        (out, hg)
    }

    /// Replaces the contact head (None removes it): fine-tuning a trained engine with a new
    /// head keeps the rest of the network.
    pub fn with_contact_head(mut self, head: Option<Mlp>) -> Self {
        self.contact = head;
        self
    }

    /// [`NpeNet::forward`] and the contact head's logits `[nodes, batch, 1]` (None without a
    /// head).
    pub fn forward_full(
        &self,
        cfg: &NpeConfig,
        x: &Inputs,
        positions: &Tensor<3>,
        graph: &GraphTensors,
        device: &Device,
    ) -> (Tensor<3>, Option<Tensor<3>>, Tensor<2>) {
        let b = x.counts.len();
        let n = positions.dims()[0];
        let hg = self.global(cfg, x, device);
        let mut parts = vec![
            hg.clone()
                .reshape([1, b, cfg.global_width()])
                .repeat_dim(0, n),
            positions.clone().repeat_dim(1, b),
            self.node_depth(cfg, x, n, device),
        ];
        if cfg.node_gap {
            parts.push(self.node_gap(x, n, device));
        }
        let h0 = Tensor::cat(parts, 2);
        let h = self.gcn.forward(h0, graph);
        let head = self.contact.as_ref().map(|c| c.forward(h.clone()));
        let out = self.readout.forward(h);
        let with_rule = |out: Tensor<3>| {
            let logits = head.map(|z| {
                let uz = out.clone().slice([0..n, 0..b, 2..3]);
                let (gain, t) = cfg.contact_rule();
                z + (uz.neg() - t) * gain
            });
            (out, logits, hg)
        };
        if !cfg.contact_prior || x.node_depth.len() != b * n || x.node_gate.len() != b * n {
            return with_rule(out);
        }
        let k = cfg.depth_to_displacement();
        let (mut mul, mut add) = (vec![0.0; n * b * 6], vec![0.0; n * b * 6]);
        for v in 0..n {
            for j in 0..b {
                let (m, a) = prior_row(x.node_depth[j * n + v], x.node_gate[j * n + v], k);
                let at = (v * b + j) * 6;
                mul[at..at + 6].copy_from_slice(&m);
                add[at..at + 6].copy_from_slice(&a);
            }
        }
        let mul = Tensor::<3>::from_data(TensorData::new(mul, [n, b, 6]), device);
        let add = Tensor::<3>::from_data(TensorData::new(add, [n, b, 6]), device);
        with_rule(out * mul + add)
    }
}
