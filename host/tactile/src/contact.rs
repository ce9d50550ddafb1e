//! Node-to-surface contact between the gel's surface nodes and a rigid indenter.
//!
//! Normal: augmented Lagrangian. Each surface node i carries a pressure-like penalty
//! k_i = eps_n A_i (A_i its lumped surface area) and a multiplier lambda_i; its normal force is
//! p_i = max(0, lambda_i - k_i g_i) along the indenter's outward normal (g_i the signed distance).
//! After Newton converges, lambda_i <- p_i until the deepest penetration is within the tolerance.
//!
//! Tangential: Coulomb friction regularised by a tangential penalty k_t,i = eps_t A_i with a
//! return map: the trial force f_tr = P f_old - k_t P ds (ds the slip of the node relative to the
//! indenter since the last converged step, P the tangent projector) sticks when |f_tr| <= mu p and
//! is scaled back onto the cone otherwise. The tangent drops the non-symmetric dp/dx term of a
//! sliding node (Newton stays convergent, a little slower, with a symmetric solver).
//!
//! Held planes (frictionless, a retry): where a node's closest point jumps between faces (a
//! crevice between two bumps, a valley of a faceted texture), the force above turns with it
//! and Newton stalls. Under the held-plane law each node is instead pushed by the tangent
//! planes of the faces it has met, each with its own penalty and multiplier, two or three at
//! once in a crevice or a concave corner; the planes are renewed from the true closest points
//! after every Newton solve until no node penetrates the true surface beyond the tolerance.

use crate::indenter::Placed;
use nalgebra::{Matrix3, Vector3};
use serde::{Deserialize, Serialize};

/// Contact law parameters.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct ContactParams {
    /// Normal penalty per unit area, Pa/m.
    pub normal_penalty_pa_m: f64,
    /// Tangential (stick) penalty per unit area, Pa/m.
    pub tangential_penalty_pa_m: f64,
    /// Coulomb friction coefficient (0: frictionless).
    pub friction: f64,
    /// Largest penetration accepted at equilibrium, m.
    pub penetration_tol_m: f64,
    /// Augmented-Lagrangian updates per step before giving up.
    pub max_updates: usize,
}

impl ContactParams {
    /// Defaults for a gel of Young's modulus `young_pa`: eps_n = 1000 E / (1 mm), so a pressure of
    /// E penetrates 1 um before the multiplier updates; tolerance 0.5 um (5 % of one 10 um step).
    pub fn for_modulus(young_pa: f64) -> Self {
        let eps = 1e3 * young_pa / 1e-3;
        ContactParams {
            normal_penalty_pa_m: eps,
            tangential_penalty_pa_m: eps,
            friction: 0.0,
            penetration_tol_m: 0.5e-6,
            max_updates: 12,
        }
    }

    /// Checks that every parameter is usable: finite positive penalties and tolerance, a
    /// finite non-negative friction coefficient.
    pub fn validate(&self) -> crate::Result<()> {
        let positive = [
            ("normal penalty", self.normal_penalty_pa_m, "Pa/m"),
            ("tangential penalty", self.tangential_penalty_pa_m, "Pa/m"),
            ("penetration tolerance", self.penetration_tol_m, "m"),
        ];
        for (name, v, unit) in positive {
            if !(v.is_finite() && v > 0.0) {
                return Err(crate::TactileError::Input(format!(
                    "the contact's {name} must be a positive number, got {v} {unit}"
                )));
            }
        }
        if !(self.friction.is_finite() && self.friction >= 0.0) {
            return Err(crate::TactileError::Input(format!(
                "the Coulomb friction coefficient must be a finite number >= 0, got {}",
                self.friction
            )));
        }
        Ok(())
    }
}

/// Converged contact history of one surface node.
#[derive(Debug, Clone, Copy, Default)]
pub struct NodeHistory {
    /// Augmented-Lagrangian multiplier, N.
    pub lambda_n: f64,
    /// Tangential force at the last converged step, N.
    pub tangential_n: Vector3<f64>,
    /// Position at the last converged step, m.
    pub position_m: Vector3<f64>,
}

/// What a contact evaluation yields for one active node.
#[derive(Debug, Clone, Copy)]
pub struct NodeForce {
    /// Index into the gel's surface list.
    pub k: usize,
    /// Force on the node, N.
    pub force: Vector3<f64>,
    /// Normal pressure force magnitude, N.
    pub normal_n: f64,
    /// Signed distance, m.
    pub gap_m: f64,
    /// Outward normal of the indenter at the closest point.
    pub normal: Vector3<f64>,
    /// -d(force)/dx, symmetric approximation.
    pub stiffness: Matrix3<f64>,
    /// Whether the node slides.
    pub slipping: bool,
    /// Normal penalty potential p^2 / (2 k_n), J (its gradient is the normal force).
    pub energy_j: f64,
}

/// A node's contact plane held through Newton solves: the indenter's tangent plane at the
/// node's closest point, in the indenter's own frame, with its multiplier.
#[derive(Debug, Clone, Copy)]
pub struct HeldPlane {
    /// A point of the plane, indenter frame, m.
    pub point: Vector3<f64>,
    /// Its outward unit normal, indenter frame.
    pub normal: Vector3<f64>,
    /// Augmented-Lagrangian multiplier, N.
    pub lambda_n: f64,
}

/// Most planes a node holds at once (a corner of three faces).
const MAX_PLANES: usize = 3;
/// Two closest-point planes are one when their normals are this close (cosine).
const SAME_PLANE_COS: f64 = 0.985;

/// Contact of a set of surface nodes against one indenter.
#[derive(Debug, Clone)]
pub struct Contact {
    /// Law.
    pub params: ContactParams,
    /// Surface node ids.
    pub nodes: Vec<usize>,
    /// Their lumped areas, m^2.
    pub area_m2: Vec<f64>,
    /// Converged history per node.
    pub history: Vec<NodeHistory>,
    /// Planes per node when the held-plane law is on (`None`: each node against its closest
    /// point). A node held by the planes of two faces at once stays in a crevice or concave
    /// corner of the indenter, where its closest point jumps from face to face.
    pub held: Option<Vec<Vec<HeldPlane>>>,
}

impl Contact {
    /// Contact for `nodes` with `area_m2`, at rest positions `x`.
    pub fn new(params: ContactParams, nodes: Vec<usize>, area_m2: Vec<f64>, x: &[f64]) -> Self {
        let history = nodes
            .iter()
            .map(|&i| NodeHistory {
                position_m: Vector3::new(x[3 * i], x[3 * i + 1], x[3 * i + 2]),
                ..Default::default()
            })
            .collect();
        Contact {
            params,
            nodes,
            area_m2,
            history,
            held: None,
        }
    }

    /// Frictionless forces of the held planes at positions `x`; each active node's `gap_m` is
    /// its true signed distance to the indenter, its `normal` the direction of its net force.
    fn evaluate_held(
        &self,
        planes: &[Vec<HeldPlane>],
        placed: &Placed,
        candidates: &[usize],
        x: &[f64],
    ) -> Vec<NodeForce> {
        let (r, t) = (placed.pose.rotation, placed.pose.translation);
        let mut out = Vec::new();
        for &k in candidates {
            if planes[k].is_empty() {
                continue;
            }
            let i = self.nodes[k];
            let xi = Vector3::new(x[3 * i], x[3 * i + 1], x[3 * i + 2]);
            let kn = self.params.normal_penalty_pa_m * self.area_m2[k];
            let mut force = Vector3::zeros();
            let mut stiffness = Matrix3::zeros();
            let mut energy = 0.0;
            for pl in &planes[k] {
                let n = r * pl.normal;
                let g = n.dot(&(xi - (r * pl.point + t)));
                let p = pl.lambda_n - kn * g;
                if p > 0.0 {
                    force += n * p;
                    stiffness += n * n.transpose() * kn;
                    energy += p * p / (2.0 * kn);
                }
            }
            let magnitude = force.norm();
            if !(magnitude > 0.0) {
                continue;
            }
            out.push(NodeForce {
                k,
                force,
                normal_n: magnitude,
                gap_m: placed.query(&xi).distance,
                normal: force / magnitude,
                stiffness,
                slipping: false,
                energy_j: energy,
            });
        }
        out
    }

    /// Held-plane law: each plane's multiplier takes its force at `x`, then every candidate
    /// node within `band_m` of the indenter (or inside it) takes the tangent plane at its
    /// closest point, replacing a held plane of about the same normal and adding to the others
    /// (a node pushed from one face into another holds both); a node farther out with no
    /// force lets its planes go. Returns the largest true penetration, m.
    pub fn refresh_planes(
        &mut self,
        placed: &Placed,
        candidates: &[usize],
        x: &[f64],
        band_m: f64,
        update_multipliers: bool,
    ) -> f64 {
        let n_nodes = self.nodes.len();
        let held = self.held.get_or_insert_with(|| vec![Vec::new(); n_nodes]);
        let (r, t) = (placed.pose.rotation, placed.pose.translation);
        let mut penetration: f64 = 0.0;
        for &k in candidates {
            let i = self.nodes[k];
            let xi = Vector3::new(x[3 * i], x[3 * i + 1], x[3 * i + 2]);
            let kn = self.params.normal_penalty_pa_m * self.area_m2[k];
            let mut pushing = false;
            for pl in held[k].iter_mut() {
                if update_multipliers {
                    let n = r * pl.normal;
                    let g = n.dot(&(xi - (r * pl.point + t)));
                    pl.lambda_n = (pl.lambda_n - kn * g).max(0.0);
                }
                pushing |= pl.lambda_n > 0.0;
            }
            let q = placed.query(&xi);
            penetration = penetration.max(-q.distance);
            if q.distance > band_m {
                if !pushing {
                    held[k].clear();
                }
                continue;
            }
            let normal = r.transpose() * q.normal;
            let point = placed.pose.to_local(&(xi - q.normal * q.distance));
            let planes = &mut held[k];
            if let Some(same) = planes
                .iter_mut()
                .find(|pl| pl.normal.dot(&normal) > SAME_PLANE_COS)
            {
                // A node on an edge between two facets of a curved face alternates between
                // their normals when it takes each in turn; their mean holds it on the edge.
                same.point = point;
                same.normal = (same.normal + normal).normalize();
            } else {
                if planes.len() == MAX_PLANES
                    && let Some(weakest) = (0..planes.len())
                        .min_by(|&a, &b| planes[a].lambda_n.total_cmp(&planes[b].lambda_n))
                {
                    planes.remove(weakest);
                }
                planes.push(HeldPlane {
                    point,
                    normal,
                    lambda_n: 0.0,
                });
            }
        }
        penetration
    }

    /// Forces of the active nodes at positions `x` with the indenter at `placed`, which moved by
    /// `indenter_motion` since the last converged step. `candidates` limits the nodes queried.
    pub fn evaluate(
        &self,
        placed: &Placed,
        indenter_motion: &Vector3<f64>,
        candidates: &[usize],
        x: &[f64],
    ) -> Vec<NodeForce> {
        if let Some(planes) = &self.held {
            return self.evaluate_held(planes, placed, candidates, x);
        }
        let mut out = Vec::new();
        let pr = &self.params;
        for &k in candidates {
            let i = self.nodes[k];
            let xi = Vector3::new(x[3 * i], x[3 * i + 1], x[3 * i + 2]);
            let q = placed.query(&xi);
            let kn = pr.normal_penalty_pa_m * self.area_m2[k];
            let h = &self.history[k];
            let p = h.lambda_n - kn * q.distance;
            if !(p > 0.0) {
                continue;
            }
            let n = q.normal;
            let mut force = n * p;
            let mut stiffness = n * n.transpose() * kn;
            let mut slipping = false;
            if pr.friction > 0.0 {
                let proj = Matrix3::identity() - n * n.transpose();
                let kt = pr.tangential_penalty_pa_m * self.area_m2[k];
                let slip = proj * ((xi - h.position_m) - indenter_motion);
                let trial = proj * h.tangential_n - kt * slip;
                let limit = pr.friction * p;
                let tn = trial.norm();
                if tn <= limit {
                    force += trial;
                    stiffness += proj * kt;
                } else {
                    let t = trial / tn;
                    force += t * limit;
                    stiffness += (proj - t * t.transpose()) * (kt * limit / tn);
                    slipping = true;
                }
            }
            out.push(NodeForce {
                k,
                force,
                normal_n: p,
                gap_m: q.distance,
                normal: n,
                stiffness,
                slipping,
                energy_j: p * p / (2.0 * kn),
            });
        }
        out
    }

    /// Augmented-Lagrangian update after a converged Newton solve: lambda <- p on the active
    /// nodes, 0 elsewhere.
    pub fn update_multipliers(&mut self, active: &[NodeForce]) {
        for h in &mut self.history {
            h.lambda_n = 0.0;
        }
        for a in active {
            self.history[a.k].lambda_n = a.normal_n;
        }
    }

    /// Stores the converged step: tangential forces and positions (friction history).
    pub fn commit_step(&mut self, active: &[NodeForce], x: &[f64]) {
        for (k, h) in self.history.iter_mut().enumerate() {
            let i = self.nodes[k];
            h.tangential_n = Vector3::zeros();
            h.position_m = Vector3::new(x[3 * i], x[3 * i + 1], x[3 * i + 2]);
        }
        for a in active {
            self.history[a.k].tangential_n = a.force - a.normal * a.normal_n;
        }
    }
}
