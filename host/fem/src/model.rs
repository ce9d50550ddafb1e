//! The immutable FE model (geometry, material, mass, constraints, cavities) and its evolving state.

use crate::element::{self, Mat12, TetGeom};
use crate::material::Material;
use crate::mesh::Mesh;
use crate::{FemError, Result};
use nalgebra::{Matrix3, Vector3};
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

/// Skew matrix [v]x with [v]x w = v x w.
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
    /// Stiffness multiplier per element (1 normally; large for rigid parts, see [`Model::make_rigid`]).
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

    /// Makes a part rigid: every element whose nodes all satisfy `select` is stiffened by `factor`.
    ///
    /// This is a stiff-penalty rigid-body constraint: the part keeps its shape up to strains of order
    /// 1/factor while rotating freely (the corotational and hyperelastic laws are objective), and the
    /// tangent stays exact and symmetric. Returns how many elements were stiffened.
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

/// Sparse structure over free DOFs with element-to-value maps.
#[derive(Debug, Clone)]
pub struct Pattern {
    /// DOF -> free index, or usize::MAX when constrained.
    pub free_of: Vec<usize>,
    /// Free index -> DOF.
    pub dof_of: Vec<usize>,
    /// CSC column pointers (full symmetric pattern).
    pub col_ptr: Vec<usize>,
    /// CSC row indices.
    pub row_idx: Vec<usize>,
    elem_map: Vec<[u32; 144]>,
    tri_maps: Vec<Vec<[u32; 81]>>,
    diag: Vec<usize>,
}

const NONE: u32 = u32::MAX;

impl Pattern {
    /// Builds the structure for `model`.
    pub fn new(model: &Model) -> Result<Self> {
        let ndof = 3 * model.num_nodes();
        let mut free_of = vec![usize::MAX; ndof];
        let mut dof_of = vec![];
        for d in 0..ndof {
            if !model.fixed[d] {
                free_of[d] = dof_of.len();
                dof_of.push(d);
            }
        }
        let nf = dof_of.len();
        let mut cols: Vec<Vec<usize>> = vec![vec![]; nf];
        let mut add_clique = |nodes: &[usize]| {
            for &a in nodes {
                for &b in nodes {
                    for i in 0..3 {
                        for k in 0..3 {
                            let (r, c) = (free_of[3 * a + i], free_of[3 * b + k]);
                            if r != usize::MAX && c != usize::MAX {
                                cols[c].push(r);
                            }
                        }
                    }
                }
            }
        };
        for g in &model.elements {
            add_clique(&g.nodes);
        }
        for c in &model.cavities {
            for t in &c.triangles {
                add_clique(t);
            }
        }
        let mut col_ptr = vec![0usize];
        let mut row_idx = vec![];
        for (j, col) in cols.iter_mut().enumerate() {
            col.push(j);
            col.sort_unstable();
            col.dedup();
            row_idx.extend_from_slice(col);
            col_ptr.push(row_idx.len());
        }
        if row_idx.len() >= NONE as usize {
            return Err(FemError::Model(
                "matrix too large for 32-bit value maps".into(),
            ));
        }
        let find = |r: usize, c: usize| -> u32 {
            if r == usize::MAX || c == usize::MAX {
                return NONE;
            }
            let s = &row_idx[col_ptr[c]..col_ptr[c + 1]];
            match s.binary_search(&r) {
                Ok(k) => (col_ptr[c] + k) as u32,
                Err(_) => NONE,
            }
        };
        let map_nodes = |nodes: &[usize], out: &mut [u32]| {
            let m = nodes.len() * 3;
            for (a, &na) in nodes.iter().enumerate() {
                for (b, &nb) in nodes.iter().enumerate() {
                    for i in 0..3 {
                        for k in 0..3 {
                            out[(3 * a + i) * m + 3 * b + k] =
                                find(free_of[3 * na + i], free_of[3 * nb + k]);
                        }
                    }
                }
            }
        };
        let elem_map = model
            .elements
            .iter()
            .map(|g| {
                let mut m = [NONE; 144];
                map_nodes(&g.nodes, &mut m);
                m
            })
            .collect();
        let tri_maps = model
            .cavities
            .iter()
            .map(|c| {
                c.triangles
                    .iter()
                    .map(|t| {
                        let mut m = [NONE; 81];
                        map_nodes(t, &mut m);
                        m
                    })
                    .collect()
            })
            .collect();
        let diag = (0..nf).map(|j| find(j, j) as usize).collect();
        Ok(Pattern {
            free_of,
            dof_of,
            col_ptr,
            row_idx,
            elem_map,
            tri_maps,
            diag,
        })
    }

    /// Number of free DOFs.
    pub fn num_free(&self) -> usize {
        self.dof_of.len()
    }

    /// Number of stored matrix entries.
    pub fn nnz(&self) -> usize {
        self.row_idx.len()
    }
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
    /// Tangent K_int - dF_ext/dx over free DOFs, CSC values (when asked for).
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
        let ndof = x.len();
        let mut f_int = vec![0.0; ndof];
        let mut k_vals = want_tangent.then(|| vec![0.0; pat.nnz()]);
        let mut energy = 0.0;
        let mut min_j = f64::INFINITY;
        for (e, g) in self.elements.iter().enumerate() {
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
            if let (Some(kv), Some(ke)) = (k_vals.as_mut(), ev.stiffness.as_ref()) {
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
                if let Some(kv) = k_vals.as_mut() {
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
        Ok(Evaluation {
            strain_energy: energy,
            load_potential: potential,
            f_int,
            f_ext,
            tangent: k_vals,
            cavity_volumes: volumes,
            min_jacobian: min_j,
        })
    }

    /// Mass matrix values on `pat` (lumped or consistent), free DOFs only.
    pub fn mass_values(&self, pat: &Pattern) -> Vec<f64> {
        let mut m = vec![0.0; pat.nnz()];
        match self.mass_kind {
            MassKind::Lumped => {
                for (j, &d) in pat.dof_of.iter().enumerate() {
                    m[pat.diag[j]] += self.lumped[d / 3];
                }
            }
            MassKind::Consistent => {
                for (e, g) in self.elements.iter().enumerate() {
                    let c = self.density_kg_m3 * g.volume / 20.0;
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
