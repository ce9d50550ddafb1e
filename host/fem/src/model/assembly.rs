//! Assembly: energy, forces, tangent and mass of a model at a configuration, on the reduced
//! system of a [`Pattern`].

use super::description::{MassKind, Model};
use super::pattern::{ElemKind, NONE, Pattern};
use super::state::State;
use crate::element;
use crate::rigid::{BodyState, skew};
use crate::{FemError, Result};
use nalgebra::{Matrix3, Vector3};

/// Loads of one solve: cavity pressures (gauge, Pa); gravity and point forces come from the model.
#[derive(Debug, Clone, Default)]
pub struct Loads {
    /// Pressure per cavity, Pa.
    pub pressures_pa: Vec<f64>,
}

/// Result of evaluating the model at a configuration.
#[derive(Debug, Clone)]
pub struct Evaluation {
    /// Strain energy, J.
    pub strain_energy: f64,
    /// Potential of the external loads: -(f_dead . x) - sum p V, J.
    pub load_potential: f64,
    /// Internal force f_int, full DOF vector, N.
    pub f_int: Vec<f64>,
    /// External force f_ext, full DOF vector, N.
    pub f_ext: Vec<f64>,
    /// Residual f_int - f_ext on the reduced DOFs (free node DOFs, then per rigid body the
    /// resultant force, N, and moment about its reference point, N m).
    pub residual: Vec<f64>,
    /// Tangent K_int - dF_ext/dx on the reduced DOFs (T^T K T plus the symmetric rotation term
    /// of the rigid bodies), CSC values (when asked for).
    pub tangent: Option<Vec<f64>>,
    /// Cavity volumes, m^3.
    pub cavity_volumes: Vec<f64>,
    /// Smallest element volume ratio J.
    pub min_jacobian: f64,
}

impl Model {
    /// Evaluates energy, forces and (optionally) the tangent at `x`.
    ///
    /// Dead loads (gravity, point forces) are scaled by `lambda`; cavity pressures are taken as given.
    pub fn evaluate(
        &self,
        pat: &Pattern,
        x: &[f64],
        loads: &Loads,
        lambda: f64,
        want_tangent: bool,
    ) -> Result<Evaluation> {
        if x.len() != 3 * self.num_nodes() {
            return Err(FemError::Model(format!(
                "state has {} DOFs, model {}",
                x.len(),
                3 * self.num_nodes()
            )));
        }
        if let Some(i) = loads.pressures_pa.iter().position(|p| !p.is_finite()) {
            return Err(FemError::Model(format!(
                "pressure of cavity {i} is not finite"
            )));
        }
        if let Some(i) = x.iter().position(|v| !v.is_finite()) {
            return Err(FemError::Model(format!("position DOF {i} is not finite")));
        }
        if loads.pressures_pa.len() > self.cavities.len() {
            return Err(FemError::Model(format!(
                "{} pressures given for {} cavities",
                loads.pressures_pa.len(),
                self.cavities.len()
            )));
        }
        let pos: Vec<Vector3<f64>> = x
            .chunks_exact(3)
            .map(|c| Vector3::new(c[0], c[1], c[2]))
            .collect();
        if pat.elem_kind.len() != self.elements.len() || pat.node_body.len() != self.num_nodes() {
            return Err(FemError::Model(
                "pattern was built for another model".into(),
            ));
        }
        let ndof = x.len();
        let centers = pat.body_centers(x);
        let mut f_int = vec![0.0; ndof];
        let mut k_vals = want_tangent.then(|| vec![0.0; pat.nnz()]);
        let mut energy = 0.0;
        let mut min_j = f64::INFINITY;
        let mut local = [0.0f64; 144];
        for (e, g) in self.elements.iter().enumerate() {
            // An element on one rigid body moves rigidly: no strain, no force, nothing to reduce.
            if let ElemKind::Inside(_) = pat.elem_kind[e] {
                continue;
            }
            let ev = element::evaluate(
                e,
                g,
                &self.material,
                self.k0(e),
                self.element_scale[e],
                &pos,
                want_tangent,
            )?;
            energy += ev.energy;
            min_j = min_j.min(ev.jacobian);
            for a in 0..4 {
                for i in 0..3 {
                    f_int[3 * g.nodes[a] + i] += ev.force[3 * a + i];
                }
            }
            if let (Some(kv), Some(ke), ElemKind::Coupled(ci)) =
                (k_vals.as_mut(), ev.stiffness.as_ref(), pat.elem_kind[e])
            {
                let c = &pat.couplings[ci as usize];
                for r in 0..12 {
                    for cc in 0..12 {
                        local[r * 12 + cc] = ke[(r, cc)];
                    }
                }
                let arms = pat.arms(c, &g.nodes, &pos, &centers);
                pat.add_coupled(c, &local, &arms, kv);
            } else if let (Some(kv), Some(ke)) = (k_vals.as_mut(), ev.stiffness.as_ref()) {
                let map = &pat.elem_map[e];
                for r in 0..12 {
                    for c in 0..12 {
                        let slot = map[r * 12 + c];
                        if slot != NONE {
                            kv[slot as usize] += ke[(r, c)];
                        }
                    }
                }
            }
        }
        // Dead loads: gravity on lumped masses (equal to consistent M g for linear tets) and point forces.
        let mut f_ext = vec![0.0; ndof];
        for (i, &m) in self.lumped.iter().enumerate() {
            for d in 0..3 {
                f_ext[3 * i + d] += lambda * m * self.gravity[d];
            }
        }
        for (i, f) in &self.point_forces {
            for d in 0..3 {
                f_ext[3 * i + d] += lambda * f[d];
            }
        }
        let mut potential = -f_ext.iter().zip(x).map(|(f, xi)| f * xi).sum::<f64>();
        let mut volumes = Vec::with_capacity(self.cavities.len());
        for (ci, c) in self.cavities.iter().enumerate() {
            volumes.push(c.volume(&pos));
            let p = loads.pressures_pa.get(ci).copied().unwrap_or(0.0);
            if p == 0.0 {
                continue;
            }
            potential -= p * volumes[ci];
            for (ti, t) in c.triangles.iter().enumerate() {
                let pts = t.map(|i| pos[i]);
                // Follower pressure: each node takes a third of p N, N = (b-a)x(c-a)/2 the area vector.
                // On a closed surface these sum to p dV/dx; the form also holds for open surfaces.
                let n_area = 0.5 * (pts[1] - pts[0]).cross(&(pts[2] - pts[0]));
                for &node in t {
                    for d in 0..3 {
                        f_ext[3 * node + d] += p * n_area[d] / 3.0;
                    }
                }
                let coupled = pat.tri_coupled[ci][ti];
                if let (Some(kv), true) = (k_vals.as_mut(), coupled != NONE) {
                    let c = &pat.couplings[coupled as usize];
                    for m in 0..3 {
                        let dn = skew(&(pts[(m + 2) % 3] - pts[(m + 1) % 3])) * 0.5;
                        for n in 0..3 {
                            for i in 0..3 {
                                for kk in 0..3 {
                                    local[(3 * n + i) * 9 + 3 * m + kk] = -p / 3.0 * dn[(i, kk)];
                                }
                            }
                        }
                    }
                    let arms = pat.arms(c, t, &pos, &centers);
                    pat.add_coupled(c, &local[..81], &arms, kv);
                } else if let Some(kv) = k_vals.as_mut() {
                    // dN/dx_a = [x_c - x_b]x / 2 (cyclic); every row node gets -p/3 of it.
                    let map = &pat.tri_maps[ci][ti];
                    for m in 0..3 {
                        let dn = skew(&(pts[(m + 2) % 3] - pts[(m + 1) % 3])) * 0.5;
                        for n in 0..3 {
                            for i in 0..3 {
                                for kk in 0..3 {
                                    let slot = map[(3 * n + i) * 9 + 3 * m + kk];
                                    if slot != NONE {
                                        kv[slot as usize] -= p / 3.0 * dn[(i, kk)];
                                    }
                                }
                            }
                        }
                    }
                }
            }
        }
        let net: Vec<f64> = f_int.iter().zip(&f_ext).map(|(a, b)| a - b).collect();
        if let Some(kv) = k_vals.as_mut() {
            // Rotating a body turns the arms of its nodal forces f_i = (f_int - f_ext)_i: the moment
            // sum r_i x f_i changes by sum (r_i f_i^T - (f_i . r_i) I) dtheta. Its symmetric part is
            // the Hessian of the potential under R <- exp(dtheta) R and the whole term at
            // equilibrium (the skew rest is -[m]x / 2, m the body's residual moment).
            for (b, c) in pat.bodies.iter().zip(&centers) {
                let mut geo = Matrix3::zeros();
                for &i in &b.nodes {
                    let f = Vector3::new(net[3 * i], net[3 * i + 1], net[3 * i + 2]);
                    let r = pos[i] - c;
                    geo += 0.5 * (r * f.transpose() + f * r.transpose())
                        - Matrix3::identity() * f.dot(&r);
                }
                for i in 0..3 {
                    for k in 0..3 {
                        let slot = b.block[(3 + i) * 6 + 3 + k];
                        if slot != NONE {
                            kv[slot as usize] += geo[(i, k)];
                        }
                    }
                }
            }
        }
        let residual = pat.reduce(x, &net);
        Ok(Evaluation {
            residual,
            strain_energy: energy,
            load_potential: potential,
            f_int,
            f_ext,
            tangent: k_vals,
            cavity_volumes: volumes,
            min_jacobian: min_j,
        })
    }

    /// Reduced mass matrix values T^T M T on `pat` (lumped or consistent) with the bodies at rest.
    pub fn mass_values(&self, pat: &Pattern) -> Vec<f64> {
        self.mass_values_at(pat, &self.rest_dofs())
    }

    /// Reduced mass matrix values T^T M T on `pat` at positions `x` (a rigid body's inertia turns
    /// with it).
    pub fn mass_values_at(&self, pat: &Pattern, x: &[f64]) -> Vec<f64> {
        let mut m = vec![0.0; pat.nnz()];
        let pos: Vec<Vector3<f64>> = x
            .chunks_exact(3)
            .map(|c| Vector3::new(c[0], c[1], c[2]))
            .collect();
        let centers = pat.body_centers(x);
        match self.mass_kind {
            MassKind::Lumped => {
                for (j, &d) in pat.dof_of.iter().enumerate() {
                    m[pat.diag[j]] += self.lumped[d / 3];
                }
                // sum m_i T_i^T T_i with T_i = [I, -[r_i]x].
                for (b, c) in pat.bodies.iter().zip(&centers) {
                    let mut blk = nalgebra::Matrix6::<f64>::zeros();
                    for &i in &b.nodes {
                        let mi = self.lumped[i];
                        let rx = skew(&(pos[i] - c));
                        let mut t = nalgebra::Matrix3x6::<f64>::zeros();
                        t.fixed_view_mut::<3, 3>(0, 0)
                            .copy_from(&Matrix3::identity());
                        t.fixed_view_mut::<3, 3>(0, 3).copy_from(&(-rx));
                        blk += t.transpose() * t * mi;
                    }
                    for p in 0..36 {
                        if b.block[p] != NONE {
                            m[b.block[p] as usize] += blk[(p / 6, p % 6)];
                        }
                    }
                }
            }
            MassKind::Consistent => {
                let mut local = [0.0f64; 144];
                for (e, g) in self.elements.iter().enumerate() {
                    let c = self.density_kg_m3 * g.volume / 20.0;
                    let ci = match pat.elem_kind[e] {
                        ElemKind::Plain => None,
                        ElemKind::Coupled(ci) => Some(ci),
                        ElemKind::Inside(ci) if ci != NONE => Some(ci),
                        ElemKind::Inside(_) => continue,
                    };
                    if let Some(ci) = ci {
                        local.fill(0.0);
                        for a in 0..4 {
                            for b in 0..4 {
                                let v = if a == b { 2.0 * c } else { c };
                                for i in 0..3 {
                                    local[(3 * a + i) * 12 + 3 * b + i] = v;
                                }
                            }
                        }
                        let cp = &pat.couplings[ci as usize];
                        let arms = pat.arms(cp, &g.nodes, &pos, &centers);
                        pat.add_coupled(cp, &local, &arms, &mut m);
                        continue;
                    }
                    let map = &pat.elem_map[e];
                    for a in 0..4 {
                        for b in 0..4 {
                            let v = if a == b { 2.0 * c } else { c };
                            for i in 0..3 {
                                let slot = map[(3 * a + i) * 12 + 3 * b + i];
                                if slot != NONE {
                                    m[slot as usize] += v;
                                }
                            }
                        }
                    }
                }
            }
        }
        m
    }

    /// y = M x over all DOFs (full vectors), for kinetic energy and momentum.
    pub fn mass_times(&self, x: &[f64]) -> Vec<f64> {
        let mut y = vec![0.0; x.len()];
        match self.mass_kind {
            MassKind::Lumped => {
                for (d, yd) in y.iter_mut().enumerate() {
                    *yd = self.lumped[d / 3] * x[d];
                }
            }
            MassKind::Consistent => {
                for g in &self.elements {
                    let c = self.density_kg_m3 * g.volume / 20.0;
                    for a in 0..4 {
                        for b in 0..4 {
                            let v = if a == b { 2.0 * c } else { c };
                            for i in 0..3 {
                                y[3 * g.nodes[a] + i] += v * x[3 * g.nodes[b] + i];
                            }
                        }
                    }
                }
            }
        }
        y
    }

    /// Moves `x` and `bodies` by `alpha` times the reduced increment `dq` (free node DOFs add,
    /// bodies translate and turn, R <- exp(alpha dtheta) R) and places the slaves.
    pub(crate) fn apply_increment(
        &self,
        pat: &Pattern,
        x: &mut [f64],
        bodies: &mut [BodyState],
        dq: &[f64],
        alpha: f64,
    ) {
        for (j, &d) in pat.dof_of.iter().enumerate() {
            x[d] += alpha * dq[j];
        }
        for b in &pat.bodies {
            let f = b.first;
            let dc = Vector3::new(dq[f], dq[f + 1], dq[f + 2]) * alpha;
            let dt = Vector3::new(dq[f + 3], dq[f + 4], dq[f + 5]) * alpha;
            bodies[b.body] = bodies[b.body].moved(dc, dt);
        }
        if !pat.bodies.is_empty() {
            self.place_positions(x, bodies);
        }
    }

    /// Puts the clamped bodies of `pat` back at rest in `state`.
    pub(crate) fn rest_clamped(&self, pat: &Pattern, state: &mut State) {
        for &b in &pat.clamped_bodies {
            state.bodies[b] = BodyState::at_rest(&self.rigid_bodies[b]);
        }
    }
}
