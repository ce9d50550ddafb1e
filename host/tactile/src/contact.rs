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
        }
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
