//! The reduced static solve with contact, frame by frame along an indentation.

use super::basis::ReducedModel;
use crate::gel::Gel;
use crate::indent::{Approach, Placement};
use crate::indenter::{Indenter, Placed, Pose};
use crate::{Result, TactileError};
use nalgebra::{DMatrix, DVector, Vector3};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

/// Controls of the reduced contact solve.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct ReducedOptions {
    /// Normal penalty per unit area, Pa/m (as the full model's [`crate::contact::ContactParams`]).
    pub normal_penalty_pa_m: f64,
    /// Penetration accepted at equilibrium, m.
    pub penetration_tol_m: f64,
    /// Augmented-Lagrangian updates per frame.
    pub max_updates: usize,
    /// Linearisation passes per solve.
    pub max_passes: usize,
    /// A pass has settled when |dq| <= this fraction of |q|.
    pub settle: f64,
    /// Nodes whose signed distance is surely above this are not queried, m.
    pub reach_m: f64,
    /// Hold the area-weighted mean of the linearised gap over the nodes in contact at zero
    /// exactly: one uniform pressure multiplier over the contact on top of the per-node
    /// penalty, so the soft penalty still shapes the contact and the multiplier sets how deep
    /// it sits (README, "The contact's mean gap held exactly").
    #[serde(default)]
    pub hold_mean_gap: bool,
}

impl ReducedOptions {
    /// For modulus `young_pa`: 1/100 of the full model's normal penalty and no multiplier
    /// updates. The subspace cannot follow every contact node onto the indenter (sharp
    /// features, the basis' projection error), and a stiff penalty then bends the whole field
    /// to chase them: on held-out set-ups the nodal RMSE was 0.13 mm at the full model's penalty,
    /// 0.067 at 1/10, 0.027 at 1/100 and 0.026 at 1/1000 against a projection limit of 0.025
    /// (README, "Reduced model").
    pub fn for_modulus(young_pa: f64) -> Self {
        let c = crate::contact::ContactParams::for_modulus(young_pa);
        ReducedOptions {
            normal_penalty_pa_m: 0.01 * c.normal_penalty_pa_m,
            penetration_tol_m: c.penetration_tol_m,
            max_updates: 0,
            max_passes: 8,
            settle: 1e-4,
            reach_m: 0.1e-3,
            hold_mean_gap: false,
        }
    }
}

/// One solved frame of the reduced model.
#[derive(Debug, Clone)]
pub struct ReducedFrame {
    /// Indentation depth, m.
    pub depth_m: f64,
    /// Reduced coordinates.
    pub q: Vec<f64>,
    /// Nodes in contact: (mesh node, normal force N, indenter normal).
    pub active: Vec<(usize, f64, Vector3<f64>)>,
    /// Force of the gel on the indenter, N.
    pub indenter_force_n: [f64; 3],
    /// Deepest penetration at the frame (linearised gaps), m.
    pub max_penetration_m: f64,
    /// Linearisation passes over all multiplier updates.
    pub passes: usize,
    /// Signed-distance queries made.
    pub queries: usize,
}

impl ReducedFrame {
    /// Contact force on each listed node (zero off contact), N.
    pub fn nodal_force(&self, nodes: &[usize], num_nodes: usize) -> Vec<[f64; 3]> {
        let mut local = vec![usize::MAX; num_nodes];
        for (k, &i) in nodes.iter().enumerate() {
            local[i] = k;
        }
        let mut f = vec![[0.0; 3]; nodes.len()];
        for (i, p, n) in &self.active {
            if local[*i] != usize::MAX {
                f[local[*i]] = [p * n.x, p * n.y, p * n.z];
            }
        }
        f
    }
}

/// Per surface node: where and what its signed distance was last queried.
#[derive(Debug, Clone, Copy)]
struct Seen {
    gap: f64,
    normal: Vector3<f64>,
    at: Vector3<f64>,
    indenter_at: Vector3<f64>,
}

/// A stepwise indentation on the reduced model.
pub struct ReducedIndentation<'a> {
    model: &'a ReducedModel,
    gel: &'a Gel,
    indenter: &'a Indenter,
    approach: Approach,
    /// Reduced coordinates.
    pub q: DVector<f64>,
    lambda: Vec<f64>,
    seen: Vec<Option<Seen>>,
    /// Controls.
    pub options: ReducedOptions,
    /// Current depth, m.
    pub depth_m: f64,
    /// The hyper-reduced Neo-Hookean force in place of K_r q, when set.
    nonlinear: Option<super::hyper::ProjectedGel<'a>>,
    /// The nonlinear force and tangent last evaluated, and where.
    last_eval: Option<(DVector<f64>, super::hyper::ReducedForce)>,
}

impl<'a> ReducedIndentation<'a> {
    /// Prepares the indentation of `gel` (reduced by `model`) by `indenter` at `placement`;
    /// errors when it would not touch the top face or the model is of another mesh.
    pub fn new(
        name: &str,
        model: &'a ReducedModel,
        gel: &'a Gel,
        indenter: &'a Indenter,
        placement: Placement,
        options: ReducedOptions,
    ) -> Result<Self> {
        model.check_gel(gel)?;
        let approach = Approach::new(name, gel, indenter, placement)?;
        Ok(ReducedIndentation {
            model,
            gel,
            indenter,
            approach,
            q: DVector::zeros(model.rank()),
            lambda: vec![0.0; gel.surface.len()],
            seen: vec![None; gel.surface.len()],
            options,
            depth_m: 0.0,
            nonlinear: None,
            last_eval: None,
        })
    }

    /// The internal force of the gel becomes `gel`'s hyper-reduced Neo-Hookean force on this
    /// model's basis instead of the rest stiffness' K_r q: each linearisation pass then also
    /// linearises the internal force at the current q (one Newton step on both).
    pub fn with_nonlinear(mut self, gel: &'a super::hyper::NonlinearGel) -> Self {
        self.nonlinear = Some(gel.on_basis(self.model));
        self
    }

    /// Pose of the indenter at `depth_m` from first touch.
    pub fn pose_at(&self, depth_m: f64) -> Pose {
        self.approach.pose_at(depth_m)
    }

    /// Solves the frame at `depth_m` (warm-started from the current state).
    pub fn advance_to(&mut self, depth_m: f64) -> Result<ReducedFrame> {
        if !depth_m.is_finite() {
            return Err(TactileError::Input(format!(
                "reduced indentation depth {depth_m} m is not finite"
            )));
        }
        let pose = self.approach.pose_at(depth_m);
        let placed = Placed {
            indenter: self.indenter,
            pose,
        };
        let (lo, hi) = placed.bounds();
        let margin = 0.5e-3;
        let gel = self.gel;
        // Surface nodes displaced by at most ~the depth: a 1.5 mm margin in z keeps every node
        // that can touch.
        let cands: Vec<usize> = gel
            .surface
            .iter()
            .enumerate()
            .filter(|&(_, &i)| {
                let p = gel.mesh.points[i];
                p[0] >= lo[0] - margin
                    && p[0] <= hi[0] + margin
                    && p[1] >= lo[1] - margin
                    && p[1] <= hi[1] + margin
                    && p[2] >= lo[2] - 1.5e-3
            })
            .map(|(k, _)| k)
            .collect();
        let o = self.options;
        let r = self.model.rank();
        let mut passes = 0;
        let mut queries = 0;
        let mut pen = 0.0;
        let mut active: Vec<(usize, f64, Vector3<f64>)> = Vec::new();
        for update in 0..=o.max_updates {
            let mut settled = false;
            // Passes that stop shrinking their step are damped: near sharp indenter features
            // the linearised normals can flip between passes.
            let (mut alpha, mut last_dq) = (1.0, f64::INFINITY);
            let mut near: Vec<(usize, f64, DVector<f64>)> = Vec::new();
            // The mean-gap multiplier's share of each near node's force, N (zero without them).
            let mut moment_force: Vec<f64> = Vec::new();
            while !settled && passes < o.max_passes * (update + 1) {
                passes += 1;
                queries += self.query(&placed, &cands);
                // a_i = Phi_i^T n_i for the nodes within reach.
                near.clear();
                for &k in &cands {
                    let Some(s) = self.seen[k] else { continue };
                    let i = gel.surface[k];
                    let x = self.position(i);
                    let g = s.gap + s.normal.dot(&(x - s.at))
                        - s.normal.dot(&(pose.translation - s.indenter_at));
                    if g > o.reach_m && self.lambda[k] == 0.0 {
                        continue;
                    }
                    let mut a = DVector::zeros(r);
                    for d in 0..3 {
                        let row = &self.model.modes[(3 * i + d) * r..(3 * i + d + 1) * r];
                        for j in 0..r {
                            a[j] += row[j] * s.normal[d];
                        }
                    }
                    // Linearised gap at the current q: g_i + a_i . (q' - q).
                    near.push((k, g - a.dot(&self.q), a));
                }
                let (q_new, extra) = match &self.nonlinear {
                    None => self.active_set_solve(&near, &self.model.stiffness, None)?,
                    Some(nl) => {
                        let ev = match self.last_eval.take() {
                            Some((at, ev)) if at == self.q => ev,
                            _ => nl.evaluate(self.q.as_slice(), true)?,
                        };
                        let k = ev
                            .tangent
                            .clone()
                            .unwrap_or_else(|| self.model.stiffness.clone());
                        // f(q') ~ f(q) + K (q' - q): the offset K q - f(q) joins the right side.
                        let offset = &k * &self.q - &ev.force;
                        self.last_eval = Some((self.q.clone(), ev));
                        self.active_set_solve(&near, &k, Some(&offset))?
                    }
                };
                moment_force = extra;
                let dq = (&q_new - &self.q).norm();
                settled = dq <= o.settle * q_new.norm().max(1e-30);
                if dq > 0.9 * last_dq {
                    alpha = (alpha * 0.5f64).max(1.0 / 16.0);
                }
                last_dq = dq;
                let step = (q_new - &self.q) * alpha;
                self.take_step(step)?;
            }
            // Pressures and penetration at the settled q (linearised gaps).
            active.clear();
            pen = 0.0f64;
            for (j, (k, g0, a)) in near.iter().enumerate() {
                let g = g0 + a.dot(&self.q);
                let kn = o.normal_penalty_pa_m * gel.area_m2[*k];
                let p = self.lambda[*k] + moment_force.get(j).copied().unwrap_or(0.0) - kn * g;
                if p > 0.0 {
                    pen = pen.max(-g);
                    let n = self.seen[*k].map(|s| s.normal).unwrap_or_else(Vector3::z);
                    active.push((gel.surface[*k], p, n));
                }
            }
            if pen <= o.penetration_tol_m || update == o.max_updates {
                break;
            }
            let updated: Vec<(usize, f64)> = near
                .iter()
                .map(|(k, g0, a)| {
                    let kn = o.normal_penalty_pa_m * gel.area_m2[*k];
                    (*k, (self.lambda[*k] - kn * (g0 + a.dot(&self.q))).max(0.0))
                })
                .collect();
            self.lambda.iter_mut().for_each(|h| *h = 0.0);
            for (k, p) in updated {
                self.lambda[k] = p;
            }
        }
        self.depth_m = depth_m;
        let mut total = Vector3::zeros();
        for (_, p, n) in &active {
            total -= n * *p;
        }
        Ok(ReducedFrame {
            depth_m,
            q: self.q.iter().copied().collect(),
            active,
            indenter_force_n: [total.x, total.y, total.z],
            max_penetration_m: pen.max(0.0),
            passes,
            queries,
        })
    }

    /// q += step; with the nonlinear force, a step that inverts a sampled element is halved
    /// (up to 12 times) and the force and tangent at the accepted q are kept for the next pass.
    fn take_step(&mut self, step: DVector<f64>) -> Result<()> {
        let Some(nl) = &self.nonlinear else {
            self.q += step;
            return Ok(());
        };
        let mut s = step;
        for _ in 0..12 {
            let cand = &self.q + &s;
            match nl.evaluate(cand.as_slice(), true) {
                Ok(ev) => {
                    self.last_eval = Some((cand.clone(), ev));
                    self.q = cand;
                    return Ok(());
                }
                Err(TactileError::Fem(ocm_fem::FemError::Inverted { .. })) => s *= 0.5,
                Err(e) => return Err(e),
            }
        }
        Err(TactileError::Input(format!(
            "the reduced nonlinear solve inverts an element at depth {:.4} mm even after 12 step halvings",
            self.depth_m * 1e3
        )))
    }

    fn position(&self, i: usize) -> Vector3<f64> {
        let u = self.model.node_displacement(i, self.q.as_slice());
        Vector3::from(self.gel.mesh.points[i]) + Vector3::from(u)
    }

    /// Queries the candidates whose distance bound says they may be within reach; returns how
    /// many were queried.
    fn query(&mut self, placed: &Placed, cands: &[usize]) -> usize {
        let t = placed.pose.translation;
        let reach = self.options.reach_m;
        let todo: Vec<(usize, Vector3<f64>)> = cands
            .iter()
            .filter_map(|&k| {
                let x = self.position(self.gel.surface[k]);
                let needed = match self.seen[k] {
                    None => true,
                    Some(s) => s.gap - (x - s.at).norm() - (t - s.indenter_at).norm() <= reach,
                };
                needed.then_some((k, x))
            })
            .collect();
        let found: Vec<(usize, Seen)> = todo
            .par_iter()
            .with_min_len(64)
            .map(|&(k, x)| {
                let q = placed.query(&x);
                (
                    k,
                    Seen {
                        gap: q.distance,
                        normal: q.normal,
                        at: x,
                        indenter_at: t,
                    },
                )
            })
            .collect();
        for (k, s) in found {
            self.seen[k] = Some(s);
        }
        todo.len()
    }

    /// The exact minimiser of the penalty problem with linearised gaps g0_i + a_i . q:
    /// semismooth Newton on the active set (each step one r x r Cholesky). With
    /// `hold_mean_gap`, the contact force of node i also carries A_i mu, and mu holds
    /// sum_A A_i g_i = 0 (one more unknown, a Schur complement per step). Returns q and each
    /// near node's force from mu, N.
    fn active_set_solve(
        &self,
        near: &[(usize, f64, DVector<f64>)],
        stiffness: &DMatrix<f64>,
        offset: Option<&DVector<f64>>,
    ) -> Result<(DVector<f64>, Vec<f64>)> {
        let o = &self.options;
        let r = self.model.rank();
        let kn = |k: usize| o.normal_penalty_pa_m * self.gel.area_m2[k];
        let mut q = self.q.clone();
        let mut extra = vec![0.0; near.len()];
        let mut history: Vec<Vec<bool>> = Vec::new();
        let mut frozen = false;
        for _ in 0..50 {
            let act: Vec<bool> = near
                .iter()
                .zip(&extra)
                .map(|((k, g0, a), e)| self.lambda[*k] + e - kn(*k) * (g0 + a.dot(&q)) > 0.0)
                .collect();
            if history.last() == Some(&act) {
                return Ok((q, extra));
            }
            // With the mean-gap multiplier the active set can cycle (nodes at the edge of
            // the contact enter and leave as the mean shifts): the multipliers are then frozen
            // and the plain penalty problem with that fixed force settles as without them;
            // the next linearisation pass solves for them again.
            if !frozen && history.contains(&act) {
                frozen = true;
                history.clear();
            }
            let m = act.iter().filter(|&&b| b).count();
            // H = K_r + A^T A with the rows sqrt(k_i) a_i of the active nodes (one GEMM).
            let mut rows = DMatrix::zeros(m, r);
            let mut rhs = offset.cloned().unwrap_or_else(|| DVector::zeros(r));
            let mut at = 0;
            for ((k, g0, a), on) in near.iter().zip(&act) {
                if !on {
                    continue;
                }
                let kk = kn(*k);
                let s = kk.sqrt();
                for j in 0..r {
                    rows[(at, j)] = s * a[j];
                }
                rhs.axpy(self.lambda[*k] - kk * g0, a, 1.0);
                at += 1;
            }
            let h = stiffness + rows.tr_mul(&rows);
            let chol = h.cholesky().ok_or_else(|| {
                TactileError::Input(
                    "the reduced stiffness is not positive definite (a degenerate basis?)".into(),
                )
            })?;
            if frozen {
                for ((_, _, a), (on, e)) in near.iter().zip(act.iter().zip(&extra)) {
                    if *on {
                        rhs.axpy(*e, a, 1.0);
                    }
                }
            }
            q = chol.solve(&rhs);
            if frozen {
                history.push(act);
                continue;
            }
            extra.iter_mut().for_each(|e| *e = 0.0);
            if o.hold_mean_gap && m > 0 {
                // b = sum_A A_i a_i, c = sum_A A_i g0_i; H q = rhs + b mu with b . q = -c
                // gives mu = (-c - b . H^-1 rhs) / (b . H^-1 b).
                let mut b = DVector::zeros(r);
                let mut c = 0.0;
                for ((k, g0, a), on) in near.iter().zip(&act) {
                    if *on {
                        let area = self.gel.area_m2[*k];
                        b.axpy(area, a, 1.0);
                        c += area * g0;
                    }
                }
                let z = chol.solve(&b);
                let schur = b.dot(&z);
                if schur > 0.0 {
                    let mu = (-c - b.dot(&q)) / schur;
                    q.axpy(mu, &z, 1.0);
                    for ((k, _, _), e) in near.iter().zip(extra.iter_mut()) {
                        *e = self.gel.area_m2[*k] * mu;
                    }
                }
            }
            history.push(act);
        }
        Err(TactileError::Input(format!(
            "the reduced contact active set did not settle in 50 iterations at depth {:.4} mm",
            self.depth_m * 1e3
        )))
    }
}
