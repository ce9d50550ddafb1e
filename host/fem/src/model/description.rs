//! The immutable FE model: geometry, material, mass, constraints, rigid bodies, cavities.

use crate::element::{Mat12, TetGeom};
use crate::material::Material;
use crate::mesh::Mesh;
use crate::rigid::{BodyState, RigidBody};
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
    pub(super) lumped: Vec<f64>,
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
