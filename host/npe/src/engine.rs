//! The trained engine as a function: contact points, force and depth in; nodal displacement
//! and force of the gel's top surface out.

use std::path::Path;

use ocm_learn::burn::module::Module;
use ocm_learn::burn::tensor::{Device, Tensor, TensorData};
use ocm_learn::gcn::{Graph, GraphTensors};
use ocm_learn::{Checkpoint, CheckpointInfo, cpu, save_checkpoint, values};
use serde::{Deserialize, Serialize};

use crate::data::{NodeLocator, contact_gate};
use crate::kernel::Kernel;
use crate::model::{ARCHITECTURE, Inputs, NpeConfig, NpeNet};
use crate::{NpeError, Result};

/// The top surface the engine predicts on: rest positions (sensor frame, m) and edges.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Surface {
    /// Rest position of each top node, m.
    pub rest_m: Vec<[f64; 3]>,
    /// Undirected edges between top nodes.
    pub edges: Vec<[usize; 2]>,
}

/// Predicted fields on the top nodes.
#[derive(Debug, Clone, PartialEq)]
pub struct Fields {
    /// Nodal displacement, m.
    pub displacement_m: Vec<[f64; 3]>,
    /// Nodal contact force on the gel, N.
    pub nodal_force_n: Vec<[f64; 3]>,
    /// Points dropped because they lie off the top face or above it (not pressing).
    pub ignored_points: usize,
}

impl Fields {
    /// Force on the indenter from the predicted nodal forces (minus their sum), N.
    pub fn total_force_n(&self) -> [f64; 3] {
        let mut t = [0.0; 3];
        for f in &self.nodal_force_n {
            for d in 0..3 {
                t[d] -= f[d];
            }
        }
        t
    }
}

/// The contact head's logit per node (None for an engine without a head).
pub type ContactLogits = Option<Vec<f32>>;

/// The contact state of every node: `logits` above 0 when given (the contact head), else the
/// downward displacement above the contact-node metric's 30 um.
pub fn contact_state(displacement_m: &[[f64; 3]], logits: Option<&[f32]>) -> Vec<bool> {
    match logits {
        Some(z) => z.iter().map(|&v| v > 0.0).collect(),
        None => displacement_m
            .iter()
            .map(|u| -u[2] > ocm_tactile::mask::CONTACT_THRESHOLD_M)
            .collect(),
    }
}

/// How far below the top face a contact point may lie, m: deeper points would cut through
/// most of the DIGIT gel (about 4 mm thick over its fixed base), which the training data never
/// shows.
pub const MAX_POINT_DEPTH_M: f64 = 3e-3;
/// Slack on the top face's outline and height when sorting out points that do not press, m.
const OUTLINE_TOL_M: f64 = 1e-6;

/// The neural physics engine: the network with its surface, on the CPU.
#[derive(Debug)]
pub struct Npe {
    /// Network configuration.
    pub config: NpeConfig,
    /// The surface.
    pub surface: Surface,
    net: NpeNet,
    device: Device,
    positions: Tensor<3>,
    graph: GraphTensors,
    kernel: Kernel,
    lo: [f64; 2],
    hi: [f64; 2],
    locator: NodeLocator,
}

impl Npe {
    /// Wraps a network (on any device; it is moved to the plain CPU device).
    pub fn new(net: NpeNet, config: NpeConfig, surface: Surface) -> Result<Self> {
        let device = cpu();
        let plain_graph = Graph::from_edges(surface.rest_m.len(), &surface.edges)?;
        let graph = plain_graph.tensors(&device);
        let pos: Vec<f32> = surface
            .rest_m
            .iter()
            .flat_map(|p| config.scales.point(p))
            .collect();
        let kernel = Kernel::new(&net, &config, &plain_graph, pos.clone());
        let positions =
            Tensor::<3>::from_data(TensorData::new(pos, [surface.rest_m.len(), 1, 3]), &device);
        let mut lo = [f64::INFINITY; 2];
        let mut hi = [f64::NEG_INFINITY; 2];
        for p in &surface.rest_m {
            for k in 0..2 {
                lo[k] = lo[k].min(p[k]);
                hi[k] = hi[k].max(p[k]);
            }
        }
        Ok(Npe {
            net: net.to_device(&device),
            config,
            device,
            positions,
            graph,
            kernel,
            lo,
            hi,
            locator: NodeLocator::new(&surface.rest_m),
            surface,
        })
    }

    /// The x-y outline of the top face (lowest and highest x, y of its nodes), m.
    pub fn face_bounds(&self) -> ([f64; 2], [f64; 2]) {
        (self.lo, self.hi)
    }

    /// The network.
    pub fn net(&self) -> &NpeNet {
        &self.net
    }

    /// Writes the engine (weights, configuration, surface and `meta`) to `path`.
    pub fn save(&self, path: &Path, meta: serde_json::Value) -> Result<()> {
        let meta = serde_json::json!({ "surface": self.surface, "run": meta });
        save_checkpoint(
            path,
            &self.net,
            &CheckpointInfo {
                architecture: ARCHITECTURE,
                config: &self.config,
                scalers: Default::default(),
                meta,
            },
        )?;
        Ok(())
    }

    /// Reads an engine written by [`Npe::save`] (`ocm npe train`).
    pub fn load(path: impl AsRef<Path>) -> Result<Self> {
        let ck = Checkpoint::read(path.as_ref())?;
        let config: NpeConfig = ck.config_of(&[ARCHITECTURE])?;
        let surface: Surface =
            serde_json::from_value(ck.header.meta["surface"].clone()).map_err(|e| {
                NpeError::Data(format!(
                    "{}: the checkpoint carries no readable top surface: {e}",
                    path.as_ref().display()
                ))
            })?;
        let net = ck.load_into(config.init(&cpu(), 0)?, ARCHITECTURE, &config)?;
        Self::new(net, config, surface)
    }

    /// Run facts stored with a checkpoint (None when absent).
    pub fn run_meta(path: impl AsRef<Path>) -> Result<serde_json::Value> {
        Ok(Checkpoint::read(path.as_ref())?.header.meta["run"].clone())
    }

    /// Checks the inputs and keeps the points that press on the top face. NaN or infinite
    /// values, a negative force or depth, and points deeper than [`MAX_POINT_DEPTH_M`] below
    /// the top are errors; points off the face's outline or above its highest point are
    /// dropped (they cannot press on it).
    fn admit(&self, points_m: &[[f64; 3]], force_n: f64, depth_m: f64) -> Result<Inputs> {
        if !(force_n.is_finite() && force_n >= 0.0) {
            return Err(NpeError::Input(format!(
                "resultant force {force_n} N must be finite and not negative (the force the \
                 body presses on the gel with)"
            )));
        }
        if !(depth_m.is_finite() && depth_m >= 0.0) {
            return Err(NpeError::Input(format!(
                "depth {depth_m} m must be finite and not negative"
            )));
        }
        let z_top = self.config.scales.center_m[2];
        let mut x = Inputs::default();
        let n = self.surface.rest_m.len();
        // Sized once: growing them point by point was a tenth of a call in reallocations.
        x.points.reserve(3 * points_m.len());
        x.node_depth.reserve(n);
        x.node_gate
            .reserve(if self.config.contact_prior { n } else { 0 });
        x.node_gap
            .reserve(if self.config.node_gap { 2 * n } else { 0 });
        let mut kept = 0;
        let mut admitted = Vec::with_capacity(points_m.len());
        for (i, p) in points_m.iter().enumerate() {
            if p.iter().any(|v| !v.is_finite()) {
                return Err(NpeError::Input(format!(
                    "contact point {i} ({}, {}, {}) is not finite",
                    p[0], p[1], p[2]
                )));
            }
            if p[2] < z_top - MAX_POINT_DEPTH_M {
                return Err(NpeError::Input(format!(
                    "contact point {i} lies {:.3} mm below the top face, deeper than the \
                     {:.1} mm the engine covers",
                    (z_top - p[2]) * 1e3,
                    MAX_POINT_DEPTH_M * 1e3
                )));
            }
            let off = p[0] < self.lo[0] - OUTLINE_TOL_M
                || p[0] > self.hi[0] + OUTLINE_TOL_M
                || p[1] < self.lo[1] - OUTLINE_TOL_M
                || p[1] > self.hi[1] + OUTLINE_TOL_M
                || p[2] > z_top + OUTLINE_TOL_M;
            if !off {
                x.points.extend(self.config.scales.point(p));
                admitted.push(*p);
                kept += 1;
            }
        }
        self.locator
            .node_depth(&admitted, self.config.scales.z_m, &mut x.node_depth);
        if self.config.contact_prior {
            contact_gate(&x.node_depth, &self.surface.edges, &mut x.node_gate);
        }
        if self.config.node_gap {
            self.locator.node_gap(
                &admitted,
                self.config.grid_spacing_m(),
                self.config.scales.z_m,
                &mut x.node_gap,
            );
        }
        x.counts.push(kept);
        x.scalars
            .push((force_n / self.config.scales.force_n) as f32);
        x.scalars
            .push((depth_m / self.config.scales.depth_m) as f32);
        Ok(x)
    }

    /// Nodal displacement and force of the top surface for contact points in the sensor frame
    /// (m; as [`ocm_tactile::dataset::ContactGrid`] defines them), the resultant normal force
    /// pressing on the gel (N) and the depth (m). No point presses on the face: a zero field.
    pub fn predict(&self, points_m: &[[f64; 3]], force_n: f64, depth_m: f64) -> Result<Fields> {
        let x = self.admit(points_m, force_n, depth_m)?;
        let ignored = points_m.len() - x.counts[0];
        let n = self.surface.rest_m.len();
        if x.counts[0] == 0 {
            return Ok(Fields {
                displacement_m: vec![[0.0; 3]; n],
                nodal_force_n: vec![[0.0; 3]; n],
                ignored_points: ignored,
            });
        }
        let (out, _) = self.kernel.forward(&x);
        let mut fields = self.unscale(&out);
        fields.ignored_points = ignored;
        Ok(fields)
    }

    /// [`Npe::predict`] and the contact state of every top node: the contact head's logit
    /// above 0 when the engine has one, else -u_z above 30 um (the threshold of the
    /// contact-node metric). No point presses on the face: no node in contact.
    pub fn predict_contact(
        &self,
        points_m: &[[f64; 3]],
        force_n: f64,
        depth_m: f64,
    ) -> Result<(Fields, Vec<bool>)> {
        let x = self.admit(points_m, force_n, depth_m)?;
        let ignored = points_m.len() - x.counts[0];
        let n = self.surface.rest_m.len();
        if x.counts[0] == 0 {
            let fields = Fields {
                displacement_m: vec![[0.0; 3]; n],
                nodal_force_n: vec![[0.0; 3]; n],
                ignored_points: ignored,
            };
            return Ok((fields, vec![false; n]));
        }
        let (out, logits, _) = self.kernel.forward_full(&x);
        let mut fields = self.unscale(&out);
        fields.ignored_points = ignored;
        let contact = contact_state(&fields.displacement_m, logits.as_deref());
        Ok((fields, contact))
    }

    /// Whether the engine carries a contact head.
    pub fn has_contact_head(&self) -> bool {
        self.net.contact.is_some()
    }

    /// The contact head's logits from the plain kernel (first) and from burn (second) on one
    /// call; for comparisons.
    pub fn contact_logits_both(
        &self,
        points_m: &[[f64; 3]],
        force_n: f64,
        depth_m: f64,
    ) -> Result<(ContactLogits, ContactLogits)> {
        let x = self.admit(points_m, force_n, depth_m)?;
        let (_, plain, _) = self.kernel.forward_full(&x);
        let (_, burn, _) =
            self.net
                .forward_full(&self.config, &x, &self.positions, &self.graph, &self.device);
        Ok((plain, burn.map(values)))
    }

    /// Physical fields from the network's scaled `[nodes, 1, 6]` output.
    pub fn unscale(&self, out: &[f32]) -> Fields {
        let s = &self.config.scales;
        let rows = out.len() / 6;
        let (mut u, mut f) = (Vec::with_capacity(rows), Vec::with_capacity(rows));
        for r in out.chunks(6) {
            u.push([0, 1, 2].map(|k| f64::from(r[k]) * s.displacement_m));
            f.push([3, 4, 5].map(|k| f64::from(r[k]) * s.nodal_force_n));
        }
        Fields {
            displacement_m: u,
            nodal_force_n: f,
            ignored_points: 0,
        }
    }

    /// The tactile latent: the global context h_global (eq 6.11) of the contact,
    /// [`NpeConfig::global_width`] values; all zeros when no point presses on the face.
    pub fn latent(&self, points_m: &[[f64; 3]], force_n: f64, depth_m: f64) -> Result<Vec<f32>> {
        let x = self.admit(points_m, force_n, depth_m)?;
        if x.counts[0] == 0 {
            return Ok(vec![0.0; self.config.global_width()]);
        }
        Ok(self.kernel.global(&x))
    }

    /// The network's burn forward pass on one call (what [`Npe::predict`] computes through
    /// the plain kernel), scaled `[nodes, 6]`, with h_global; for comparisons.
    pub fn predict_scaled_burn(
        &self,
        points_m: &[[f64; 3]],
        force_n: f64,
        depth_m: f64,
    ) -> Result<(Vec<f32>, Vec<f32>)> {
        let x = self.admit(points_m, force_n, depth_m)?;
        let (out, hg) =
            self.net
                .forward(&self.config, &x, &self.positions, &self.graph, &self.device);
        Ok((values(out), values(hg)))
    }

    /// The plain kernel's pass on one call, scaled `[nodes, 6]`, with h_global.
    pub fn predict_scaled(
        &self,
        points_m: &[[f64; 3]],
        force_n: f64,
        depth_m: f64,
    ) -> Result<(Vec<f32>, Vec<f32>)> {
        let x = self.admit(points_m, force_n, depth_m)?;
        Ok(self.kernel.forward(&x))
    }

    /// Scaled positions and graph tensors, for batched evaluation.
    pub fn parts(&self) -> (&Tensor<3>, &GraphTensors, &Device) {
        (&self.positions, &self.graph, &self.device)
    }
}
