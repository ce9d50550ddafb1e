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

    /// The DIGIT gel at `path` with its top face shaped by `crown` (flat when None) and its
    /// base fixed (z <= 0.5 mm).
    pub fn digit_crowned(
        path: impl AsRef<Path>,
        material: GelMaterial,
        crown: Option<&Crown>,
    ) -> Result<Self> {
        let mut mesh = ocm_fem::mesh::vtk::read_path(path)?;
        mesh.remove_unused_points();
        if let Some(c) = crown {
            c.apply(&mut mesh, DIGIT_BASE_Z_M)?;
        }
        Self::from_mesh(mesh, material, DIGIT_BASE_Z_M)
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
        // The top face: boundary triangles facing up (a crowned top is not level).
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

/// A convex crown of the gel's top face: the surface falls away from an apex as a paraboloid
/// of the given radius of curvature (a sphere's second-order form). Real DIGIT gels are domed
/// (TACTO models theirs as a sphere), while the fine mesh in the data is a flat box.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Crown {
    /// Radius of curvature at the apex, m.
    pub radius_m: f64,
    /// Apex (x, y), m.
    pub apex_m: [f64; 2],
}

/// Largest drop of a crowned top face, as a share of the gel's thickness above its fixed base:
/// farther out the crown is flat, so that no element is squeezed to less than 30 % of its
/// height. On the DIGIT gel (1.5 mm above the base) the plateau lies 1.05 mm below the apex,
/// deeper than the protocol's deepest step (1 mm): an indenter that reached it would press
/// the whole plateau under its edge at once (at 0.5, the edge6 masks grew a spur there from
/// 0.75 mm on).
pub const CROWN_MAX_DROP_SHARE: f64 = 0.7;

impl Crown {
    /// Drop of the top face below the apex at (x, y) before the cap, m.
    pub fn drop_m(&self, x: f64, y: f64) -> f64 {
        let (dx, dy) = (x - self.apex_m[0], y - self.apex_m[1]);
        (dx * dx + dy * dy) / (2.0 * self.radius_m)
    }

    /// Shapes `mesh` (metres): every node above `base_z_m` moves down by the drop under it
    /// (capped at [`CROWN_MAX_DROP_SHARE`] of the thickness above the base) times its height
    /// above the base over the top's, so the base stays where it is and each column of the gel
    /// is squeezed evenly. The shaped gel is the stress-free reference. A radius that is not
    /// finite and positive, or an apex that is not finite, is an error.
    pub fn apply(&self, mesh: &mut Mesh, base_z_m: f64) -> Result<()> {
        if !(self.radius_m > 0.0) || !self.radius_m.is_finite() {
            return Err(TactileError::Input(format!(
                "the crown's radius must be finite and positive (got {} m)",
                self.radius_m
            )));
        }
        if !self.apex_m.iter().all(|v| v.is_finite()) {
            return Err(TactileError::Input(format!(
                "the crown's apex must be finite (got {:?} m)",
                self.apex_m
            )));
        }
        let z_top = mesh
            .points
            .iter()
            .map(|p| p[2])
            .fold(f64::NEG_INFINITY, f64::max);
        let free = z_top - base_z_m;
        if !(free > 0.0) {
            return Err(TactileError::Input(format!(
                "the gel's top ({:.3} mm) is not above its base ({:.3} mm): nothing to crown",
                z_top * 1e3,
                base_z_m * 1e3
            )));
        }
        let cap = CROWN_MAX_DROP_SHARE * free;
        for p in &mut mesh.points {
            if p[2] > base_z_m {
                let drop = self.drop_m(p[0], p[1]).min(cap);
                p[2] -= drop * (p[2] - base_z_m) / free;
            }
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn signed_volume(m: &Mesh, t: [usize; 4]) -> f64 {
        let p = t.map(|i| nalgebra::Vector3::from(m.points[i]));
        (p[1] - p[0]).cross(&(p[2] - p[0])).dot(&(p[3] - p[0])) / 6.0
    }

    /// On a 4 x 4 x 2 mm box the top face follows the paraboloid up to the cap, the base does
    /// not move, every column is squeezed evenly and no tet turns over.
    #[test]
    fn crown_shapes_the_top_and_keeps_the_base() {
        let flat = ocm_fem::mesh::generate::box_mesh([8, 8, 4], [4e-3, 4e-3, 2e-3]);
        let base = 0.5e-3;
        let crown = Crown {
            radius_m: 5e-3,
            apex_m: [1e-3, 2e-3],
        };
        let mut m = flat.clone();
        crown.apply(&mut m, base).unwrap();
        let cap = CROWN_MAX_DROP_SHARE * 1.5e-3;
        let mut capped = 0;
        for (p, q) in flat.points.iter().zip(&m.points) {
            assert_eq!([p[0], p[1]], [q[0], q[1]]);
            let drop = ((p[0] - 1e-3).powi(2) + (p[1] - 2e-3).powi(2)) / 10e-3;
            if p[2] <= base {
                assert_eq!(p[2], q[2]);
            } else {
                let want = p[2] - drop.min(cap) * (p[2] - base) / 1.5e-3;
                assert!((q[2] - want).abs() < 1e-15, "{p:?} -> {q:?}");
            }
            if p[2] == 2e-3 && drop > cap {
                capped += 1;
            }
        }
        // The far corner is 3.6 mm from the apex (drop 1.3 mm): the cap is reached.
        assert!(capped > 0);
        let apex = m
            .points
            .iter()
            .position(|q| q[0] == 1e-3 && q[1] == 2e-3 && q[2] == 2e-3);
        assert!(apex.is_some(), "the apex stays at the top");
        for t in &flat.tets {
            let (v0, v1) = (signed_volume(&flat, *t), signed_volume(&m, *t));
            assert!(v0.signum() == v1.signum() && v1.abs() > 0.25 * v0.abs());
        }
    }

    /// A radius that is not positive or finite, or a non-finite apex, is refused.
    #[test]
    fn crown_refuses_bad_parameters() {
        let mut m = ocm_fem::mesh::generate::box_mesh([2, 2, 2], [1e-3, 1e-3, 1e-3]);
        for (r, a) in [
            (0.0, [0.0, 0.0]),
            (-1.0, [0.0, 0.0]),
            (f64::NAN, [0.0, 0.0]),
            (f64::INFINITY, [0.0, 0.0]),
            (1.0, [f64::NAN, 0.0]),
        ] {
            let c = Crown {
                radius_m: r,
                apex_m: a,
            };
            let e = c.apply(&mut m, 0.0).unwrap_err().to_string();
            assert!(e.contains("crown"), "{e}");
        }
        let c = Crown {
            radius_m: 1.0,
            apex_m: [0.0, 0.0],
        };
        assert!(
            c.apply(&mut m, 2e-3)
                .unwrap_err()
                .to_string()
                .contains("base")
        );
    }
}
