//! The gel: its tetrahedral mesh, Neo-Hookean material (eq 5.6), fixed base and contact surface.

use crate::{Result, TactileError};
use ocm_fem::material::Material;
use ocm_fem::mesh::Mesh;
use ocm_fem::model::Model;
use serde::{Deserialize, Serialize};
use std::path::Path;

/// Material of the gel: eq 5.6 with mu and kappa from (E, nu).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct GelMaterial {
    /// Young's modulus, Pa.
    pub young_pa: f64,
    /// Poisson's ratio.
    pub poisson: f64,
}

impl Default for GelMaterial {
    /// A soft silicone: E = 0.3 MPa, nu = 0.45 (the dissertation does not state its calibrated
    /// values; under prescribed indentation the displacements do not depend on E at all).
    fn default() -> Self {
        GelMaterial {
            young_pa: 0.3e6,
            poisson: 0.45,
        }
    }
}

impl GelMaterial {
    /// Checks the parameters a user gives: a finite positive Young's modulus and a Poisson's
    /// ratio strictly inside (-1, 0.5) (0.5 is incompressible, which the bulk term of eq 5.6
    /// cannot represent).
    pub fn validate(&self) -> Result<()> {
        ocm_fem::material::check_elastic(self.young_pa, self.poisson)
            .map_err(|e| TactileError::Input(format!("the gel's {e}")))
    }

    /// The FEM law (eq 5.6).
    pub fn law(&self) -> Material {
        Material::neo_hookean_bulk(self.young_pa, self.poisson)
    }
}

/// Mass density of the gel, kg/m^3 (statics does not use it; the model requires one).
const DENSITY_KG_M3: f64 = 1100.0;

/// The gel model with its surfaces.
#[derive(Debug, Clone)]
pub struct Gel {
    /// Mesh in metres (tets oriented; `triangles` are the outward boundary faces).
    pub mesh: Mesh,
    /// FE model with the base fixed.
    pub model: Model,
    /// Surface nodes that may touch an indenter (boundary nodes not fully fixed), sorted.
    pub surface: Vec<usize>,
    /// Lumped boundary area of each `surface` node, m^2.
    pub area_m2: Vec<f64>,
    /// Nodes of the upward-facing boundary triangles (the contact face), sorted.
    pub top: Vec<usize>,
    /// Boundary triangles with all three nodes on the top face.
    pub top_triangles: Vec<[usize; 3]>,
    /// Height of the top face, m.
    pub z_top: f64,
    /// Material.
    pub material: GelMaterial,
}

/// DIGIT base: nodes with z at or below this are fixed, m.
pub const DIGIT_BASE_Z_M: f64 = 0.5e-3;

impl Gel {
    /// Reads a gel mesh (legacy VTK in metres) and fixes the nodes at or below `base_z_m`.
    pub fn from_vtk(path: impl AsRef<Path>, material: GelMaterial, base_z_m: f64) -> Result<Self> {
        let mut mesh = ocm_fem::mesh::vtk::read_path(path)?;
        mesh.remove_unused_points();
        Self::from_mesh(mesh, material, base_z_m)
    }

    /// The DIGIT gel at `path` with its base fixed (z <= 0.5 mm).
    pub fn digit(path: impl AsRef<Path>, material: GelMaterial) -> Result<Self> {
        Self::from_vtk(path, material, DIGIT_BASE_Z_M)
    }

    /// Builds the gel from a tet mesh in metres; nodes with z <= `base_z_m` are fixed.
    pub fn from_mesh(mesh: Mesh, material: GelMaterial, base_z_m: f64) -> Result<Self> {
        let gel = Self::with_constraints(mesh, material, |p| [p.z <= base_z_m; 3])?;
        if !gel.model.fixed.iter().any(|&f| f) {
            return Err(TactileError::Input(format!(
                "no gel node lies at or below the base height {:.3} mm",
                base_z_m * 1e3
            )));
        }
        Ok(gel)
    }

    /// Builds the gel from a tet mesh in metres with the displacement components that
    /// `constrain(rest position)` marks held at zero (rollers, symmetry planes, clamps).
    pub fn with_constraints(
        mut mesh: Mesh,
        material: GelMaterial,
        constrain: impl Fn(&nalgebra::Vector3<f64>) -> [bool; 3],
    ) -> Result<Self> {
        material.validate()?;
        mesh.orient_tets();
        mesh.triangles = ocm_fem::mesh::surface::boundary_faces(&mesh.points, &mesh.tets);
        let mut model = Model::new(&mesh, material.law(), DENSITY_KG_M3)?;
        for i in 0..mesh.points.len() {
            let c = constrain(&model.rest[i]);
            for d in 0..3 {
                if c[d] {
                    model.prescribe(i, d, 0.0);
                }
            }
        }
        let n = mesh.points.len();
        let mut area = vec![0.0; n];
        let mut on_surface = vec![false; n];
        for t in &mesh.triangles {
            let p = t.map(|i| nalgebra::Vector3::from(mesh.points[i]));
            let a = 0.5 * (p[1] - p[0]).cross(&(p[2] - p[0])).norm();
            for &i in t {
                area[i] += a / 3.0;
                on_surface[i] = true;
            }
        }
        let surface: Vec<usize> = (0..n)
            .filter(|&i| on_surface[i] && !(0..3).all(|d| model.fixed[3 * i + d]))
            .collect();
        let z_top = mesh
            .points
            .iter()
            .map(|p| p[2])
            .fold(f64::NEG_INFINITY, f64::max);
        // The top face: boundary triangles facing up (the DIGIT tip is slightly convex).
        let top_triangles: Vec<[usize; 3]> = mesh
            .triangles
            .iter()
            .filter(|t| {
                let p = t.map(|i| nalgebra::Vector3::from(mesh.points[i]));
                let nrm = (p[1] - p[0]).cross(&(p[2] - p[0]));
                nrm.z > 0.5 * nrm.norm()
                    && t.iter().all(|&i| !(0..3).all(|d| model.fixed[3 * i + d]))
            })
            .copied()
            .collect();
        let mut is_top = vec![false; n];
        for t in &top_triangles {
            for &i in t {
                is_top[i] = true;
            }
        }
        let top: Vec<usize> = (0..n).filter(|&i| is_top[i]).collect();
        model.refresh();
        Ok(Gel {
            area_m2: surface.iter().map(|&i| area[i]).collect(),
            mesh,
            model,
            surface,
            top,
            top_triangles,
            z_top,
            material,
        })
    }

    /// Number of nodes.
    pub fn num_nodes(&self) -> usize {
        self.mesh.points.len()
    }

    /// Bounding box of the top face (x, y), m.
    pub fn top_bounds(&self) -> ([f64; 2], [f64; 2]) {
        let mut lo = [f64::INFINITY; 2];
        let mut hi = [f64::NEG_INFINITY; 2];
        for &i in &self.top {
            for k in 0..2 {
                lo[k] = lo[k].min(self.mesh.points[i][k]);
                hi[k] = hi[k].max(self.mesh.points[i][k]);
            }
        }
        (lo, hi)
    }
}
