//! The immutable FE model (geometry, material, mass, constraints, rigid bodies, cavities) and its
//! evolving state.

use crate::element::{self, Mat12, TetGeom};
use crate::material::Material;
use crate::mesh::Mesh;
pub use crate::pattern::{BodyDofs, Pattern};
use crate::pattern::{ElemKind, NONE};
pub use crate::rigid::{BodyState, RigidBody};
use crate::{FemError, Result};
use nalgebra::{Matrix3, SymmetricEigen, Vector3};
use serde::{Deserialize, Serialize};

/// How the mass matrix is formed from the density.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "snake_case")]
pub enum MassKind {
    /// Row-sum lumped (diagonal): each node carries a quarter of each adjacent tet.
    #[default]
    Lumped,
    /// Consistent linear-tet mass rho V (1 + delta_ab) / 20.
    Consistent,
}

/// A triangle surface loaded by gauge pressure along its normals: usually a closed cavity with
/// outward normals (enclosed volume positive), or an open loaded surface (then `volume` is not meaningful).
#[derive(Debug, Clone)]
pub struct Cavity {
    /// Name for reports.
    pub name: String,
    /// Triangles on model nodes.
    pub triangles: Vec<[usize; 3]>,
}

impl Cavity {
    /// Enclosed volume at positions `x`, m^3.
    pub fn volume(&self, x: &[Vector3<f64>]) -> f64 {
        self.triangles
            .iter()
            .map(|t| x[t[0]].dot(&x[t[1]].cross(&x[t[2]])))
            .sum::<f64>()
            / 6.0
    }
}

/// Skew matrix `[v]x` with `[v]x w = v x w`.
pub fn skew(v: &Vector3<f64>) -> Matrix3<f64> {
    Matrix3::new(0.0, -v.z, v.y, v.z, 0.0, -v.x, -v.y, v.x, 0.0)
}

/// Finite-element model: what does not change during a simulation.
#[derive(Debug, Clone)]
pub struct Model {
    /// Rest positions, m.
    pub rest: Vec<Vector3<f64>>,
    /// Tet reference data.
    pub elements: Vec<TetGeom>,
    /// Material law of all elements.
    pub material: Material,
    /// Stiffness multiplier per element (1 normally; large for penalty-rigid parts, see
    /// [`Model::make_rigid`]).
    pub element_scale: Vec<f64>,
    /// Mass density, kg/m^3.
    pub density_kg_m3: f64,
    /// Lumped or consistent mass.
    pub mass_kind: MassKind,
    /// Rayleigh damping D = alpha M + beta K.
    pub rayleigh_alpha: f64,
    /// Rayleigh stiffness-proportional coefficient, s.
    pub rayleigh_beta: f64,
    /// Gravitational acceleration, m/s^2.
    pub gravity: Vector3<f64>,
    /// Constant (dead) nodal forces, N.
    pub point_forces: Vec<(usize, Vector3<f64>)>,
    /// Pressurised cavities.
    pub cavities: Vec<Cavity>,
    /// Per DOF: constrained?
    pub fixed: Vec<bool>,
    /// Per DOF: prescribed displacement for constrained DOFs, m (scaled by the load factor in statics).
    pub prescribed: Vec<f64>,
    /// Rigid bodies (master-slave constraints, see [`Model::add_rigid_body`]).
    pub rigid_bodies: Vec<RigidBody>,
    k0: Vec<Mat12>,
    lumped: Vec<f64>,
}

impl Model {
    /// Builds a model from a mesh in metres. Tets are oriented; a degenerate tet is an error.
    pub fn new(mesh: &Mesh, material: Material, density_kg_m3: f64) -> Result<Self> {
        mesh.validate()?;
        material.validate()?;
        if !(density_kg_m3 > 0.0 && density_kg_m3.is_finite()) {
            return Err(FemError::Model(format!(
                "density {density_kg_m3} must be positive"
            )));
        }
        if mesh.tets.is_empty() {
            return Err(FemError::Model("mesh has no tetrahedra".into()));
        }
        let mut m = mesh.clone();
        m.orient_tets();
        let rest: Vec<Vector3<f64>> = m.points.iter().map(|p| Vector3::from(*p)).collect();
        let elements = m
            .tets
            .iter()
            .enumerate()
            .map(|(i, t)| TetGeom::new(i, *t, &rest))
            .collect::<Result<Vec<_>>>()?;
        let n = rest.len();
        let mut model = Model {
            element_scale: vec![1.0; elements.len()],
            rest,
            elements,
            material,
            density_kg_m3,
            mass_kind: MassKind::Lumped,
            rayleigh_alpha: 0.0,
            rayleigh_beta: 0.0,
            gravity: Vector3::zeros(),
            point_forces: vec![],
            cavities: vec![],
            fixed: vec![false; 3 * n],
            prescribed: vec![0.0; 3 * n],
            rigid_bodies: vec![],
            k0: vec![],
            lumped: vec![],
        };
        model.refresh();
        Ok(model)
    }

    /// Recomputes cached matrices after changing material or density.
    pub fn refresh(&mut self) {
        self.k0 = if matches!(self.material, Material::Corotational { .. }) {
            let (mu, lam) = self.material.small_strain_lame();
            self.elements
                .iter()
                .map(|g| g.linear_stiffness(mu, lam))
                .collect()
        } else {
            vec![]
        };
        let mut lumped = vec![0.0; self.rest.len()];
        for g in &self.elements {
            for &i in &g.nodes {
                lumped[i] += self.density_kg_m3 * g.volume / 4.0;
            }
        }
        self.lumped = lumped;
    }

    /// Replaces the material (and the cached small-strain stiffnesses).
    pub fn set_material(&mut self, material: Material) -> Result<()> {
        material.validate()?;
        self.material = material;
        self.refresh();
        Ok(())
    }

    /// Number of nodes.
    pub fn num_nodes(&self) -> usize {
        self.rest.len()
    }

    /// Nodal (lumped) masses, kg.
    pub fn nodal_masses(&self) -> &[f64] {
        &self.lumped
    }

    /// Total mass, kg.
    pub fn total_mass(&self) -> f64 {
        self.lumped.iter().sum()
    }

    /// Fixes all three DOFs of the selected nodes at zero displacement; returns how many nodes.
    pub fn fix_nodes(&mut self, select: impl Fn(&Vector3<f64>) -> bool) -> usize {
        let mut n = 0;
        for i in 0..self.rest.len() {
            if select(&self.rest[i]) {
                for d in 0..3 {
                    self.fixed[3 * i + d] = true;
                    self.prescribed[3 * i + d] = 0.0;
                }
                n += 1;
            }
        }
        n
    }

    /// Fixes the nodes inside an axis-aligned box (inclusive bounds, metres).
    pub fn fix_box(&mut self, lo: [f64; 3], hi: [f64; 3]) -> usize {
        self.fix_nodes(|p| (0..3).all(|k| p[k] >= lo[k] && p[k] <= hi[k]))
    }

    /// Fixes the nodes within `tol` of the plane through `point` with normal `normal`.
    pub fn fix_plane(&mut self, point: [f64; 3], normal: [f64; 3], tol: f64) -> usize {
        let n = Vector3::from(normal).normalize();
        let p0 = Vector3::from(point);
        self.fix_nodes(|p| (p - p0).dot(&n).abs() <= tol)
    }

    /// Prescribes the displacement of one DOF (applied in full at load factor 1).
    pub fn prescribe(&mut self, node: usize, dim: usize, displacement: f64) {
        self.fixed[3 * node + dim] = true;
        self.prescribed[3 * node + dim] = displacement;
    }

    /// Makes a part nearly rigid: every element whose nodes all satisfy `select` is stiffened by
    /// `factor`.
    ///
    /// This is a stiff-penalty alternative to [`Model::add_rigid_body`]: the part keeps its shape up
    /// to strains of order 1/factor while rotating freely (the corotational and hyperelastic laws
    /// are objective); large factors make Newton work harder. Returns how many elements were
    /// stiffened.
    pub fn make_rigid(&mut self, select: impl Fn(&Vector3<f64>) -> bool, factor: f64) -> usize {
        let mut n = 0;
        for (e, g) in self.elements.iter().enumerate() {
            if g.nodes.iter().all(|&i| select(&self.rest[i])) {
                self.element_scale[e] = factor;
                n += 1;
            }
        }
        n
    }

    /// Makes the nodes whose rest position satisfies `select` one rigid body; returns its index.
    ///
    /// The nodes then follow six DOFs exactly (master-slave elimination, see [`crate::rigid`]);
    /// elements with all nodes on the body carry no strain. A body with a fixed DOF on any node is
    /// clamped whole at rest when the solvers are built (a prescribed non-zero displacement on it is
    /// an error there). Errors: no node selected, a node already on another body, or nodes that do
    /// not fix a rotation (fewer than three, or all on one line).
    pub fn add_rigid_body(
        &mut self,
        name: &str,
        select: impl Fn(&Vector3<f64>) -> bool,
    ) -> Result<usize> {
        let nodes: Vec<usize> = (0..self.rest.len())
            .filter(|&i| select(&self.rest[i]))
            .collect();
        if nodes.is_empty() {
            return Err(FemError::Model(format!(
                "rigid body '{name}': no node selected"
            )));
        }
        for other in &self.rigid_bodies {
            if let Some(i) = nodes.iter().find(|i| other.nodes.binary_search(i).is_ok()) {
                return Err(FemError::Model(format!(
                    "rigid body '{name}': node {i} already belongs to rigid body '{}'",
                    other.name
                )));
            }
        }
        let mass: f64 = nodes.iter().map(|&i| self.lumped[i]).sum();
        let center0 = nodes
            .iter()
            .map(|&i| self.rest[i] * self.lumped[i])
            .sum::<Vector3<f64>>()
            / mass;
        let offsets: Vec<Vector3<f64>> = nodes.iter().map(|&i| self.rest[i] - center0).collect();
        // Second moment of the nodes: singular when they lie on a line (a free spin about it).
        let spread = offsets
            .iter()
            .map(|r| r * r.transpose())
            .sum::<Matrix3<f64>>();
        let eig = SymmetricEigen::new(spread).eigenvalues;
        let hi = eig.max();
        if eig.iter().filter(|&&e| e > 1e-10 * hi).count() < 2 {
            return Err(FemError::Model(format!(
                "rigid body '{name}': its {} nodes lie on a line or at a point and leave a rotation free",
                nodes.len()
            )));
        }
        self.rigid_bodies.push(RigidBody {
            name: name.to_string(),
            nodes,
            offsets,
            center0,
            mass_kg: mass,
        });
        Ok(self.rigid_bodies.len() - 1)
    }

    /// Writes the slave positions, velocities and accelerations of every rigid body into `state`
    /// from its body states (x_i = c + R (X_i - C0), v_i = v_c + w x r_i,
    /// a_i = a_c + alpha x r_i + w x (w x r_i)).
    pub fn place_bodies(&self, state: &mut State) -> Result<()> {
        self.check_bodies(state)?;
        for (body, bs) in self.rigid_bodies.iter().zip(&state.bodies) {
            let rot = bs.rotation_matrix();
            let (w, al) = (bs.angular_velocity, bs.angular_acceleration);
            let home = bs.is_home(body);
            for (&i, off) in body.nodes.iter().zip(&body.offsets) {
                let r = rot * off;
                let x = if home { self.rest[i] } else { bs.center + r };
                let v = bs.velocity + w.cross(&r);
                let a = bs.acceleration + al.cross(&r) + w.cross(&w.cross(&r));
                for d in 0..3 {
                    state.x[3 * i + d] = x[d];
                    state.v[3 * i + d] = v[d];
                    state.a[3 * i + d] = a[d];
                }
            }
        }
        Ok(())
    }

    /// Writes the slave positions of every rigid body into `x` from `bodies`.
    pub(crate) fn place_positions(&self, x: &mut [f64], bodies: &[BodyState]) {
        for (body, bs) in self.rigid_bodies.iter().zip(bodies) {
            let rot = bs.rotation_matrix();
            let home = bs.is_home(body);
            for (&i, off) in body.nodes.iter().zip(&body.offsets) {
                let p = if home {
                    self.rest[i]
                } else {
                    bs.center + rot * off
                };
                x[3 * i..3 * i + 3].copy_from_slice(p.as_slice());
            }
        }
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

    /// Errors unless `state` has one body state per rigid body.
    pub(crate) fn check_bodies(&self, state: &State) -> Result<()> {
        if state.bodies.len() != self.rigid_bodies.len() {
            return Err(FemError::Model(format!(
                "state has {} rigid-body states, model {} rigid bodies (build the state after adding bodies)",
                state.bodies.len(),
                self.rigid_bodies.len()
            )));
        }
        Ok(())
    }

    /// Puts the clamped bodies of `pat` back at rest in `state`.
    pub(crate) fn rest_clamped(&self, pat: &Pattern, state: &mut State) {
        for &b in &pat.clamped_bodies {
            state.bodies[b] = BodyState::at_rest(&self.rigid_bodies[b]);
        }
    }

    /// Adds an open surface loaded by pressure along its triangle normals (right-hand rule), as given.
    pub fn add_pressure_surface(
        &mut self,
        name: &str,
        triangles: Vec<[usize; 3]>,
    ) -> Result<usize> {
        if let Some(t) = triangles
            .iter()
            .find(|t| t.iter().any(|&i| i >= self.rest.len()))
        {
            return Err(FemError::Model(format!(
                "surface {name}: triangle {t:?} references a missing node"
            )));
        }
        self.cavities.push(Cavity {
            name: name.to_string(),
            triangles,
        });
        Ok(self.cavities.len() - 1)
    }

    /// Adds a pressurised cavity (closed surface on model nodes), oriented so its volume is positive.
    pub fn add_cavity(&mut self, name: &str, triangles: Vec<[usize; 3]>) -> Result<usize> {
        if let Some(t) = triangles
            .iter()
            .find(|t| t.iter().any(|&i| i >= self.rest.len()))
        {
            return Err(FemError::Model(format!(
                "cavity {name}: triangle {t:?} references a missing node"
            )));
        }
        let mut c = Cavity {
            name: name.to_string(),
            triangles,
        };
        if c.volume(&self.rest) < 0.0 {
            for t in &mut c.triangles {
                t.swap(1, 2);
            }
        }
        self.cavities.push(c);
        Ok(self.cavities.len() - 1)
    }

    /// Rest positions as a flat DOF vector.
    pub fn rest_dofs(&self) -> Vec<f64> {
        self.rest.iter().flat_map(|p| [p.x, p.y, p.z]).collect()
    }

    pub(crate) fn k0(&self, e: usize) -> Option<&Mat12> {
        self.k0.get(e)
    }

    /// Small-strain stiffness of element `e` that [`crate::element::evaluate`] needs for the
    /// corotational law (`None` for the hyperelastic laws).
    pub fn element_k0(&self, e: usize) -> Option<&Mat12> {
        self.k0(e)
    }
}

/// A configuration of the model (positions and velocities, flat DOF vectors).
#[derive(Debug, Clone)]
pub struct State {
    /// Current positions, m.
    pub x: Vec<f64>,
    /// Velocities, m/s.
    pub v: Vec<f64>,
    /// Accelerations, m/s^2 (used by Newmark).
    pub a: Vec<f64>,
    /// Time, s.
    pub t: f64,
    /// Rigid-body states, one per [`Model::rigid_bodies`] entry.
    pub bodies: Vec<BodyState>,
}

impl State {
    /// The undeformed state at rest.
    pub fn at_rest(model: &Model) -> Self {
        let x = model.rest_dofs();
        let n = x.len();
        State {
            x,
            v: vec![0.0; n],
            a: vec![0.0; n],
            t: 0.0,
            bodies: model.rigid_bodies.iter().map(BodyState::at_rest).collect(),
        }
    }

    /// Nodal displacements x - X.
    pub fn displacements(&self, model: &Model) -> Vec<[f64; 3]> {
        model
            .rest
            .iter()
            .enumerate()
            .map(|(i, p)| {
                [
                    self.x[3 * i] - p.x,
                    self.x[3 * i + 1] - p.y,
                    self.x[3 * i + 2] - p.z,
                ]
            })
            .collect()
    }

    /// Positions as vectors.
    pub fn positions(&self) -> Vec<Vector3<f64>> {
        self.x
            .chunks_exact(3)
            .map(|c| Vector3::new(c[0], c[1], c[2]))
            .collect()
    }
}

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
}
