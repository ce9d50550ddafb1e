//! The gel: its tetrahedral mesh, Neo-Hookean material (eq 5.6), fixed base and contact surface.

use crate::{Result, TactileError};
use ocm_fem::material::Material;
use ocm_fem::mesh::Mesh;
use ocm_fem::model::Model;
use serde::{Deserialize, Serialize};
use std::path::Path;

/// Material of the gel: a compressible Neo-Hookean law with mu and its bulk term from (E, nu).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct GelMaterial {
    /// Young's modulus, Pa.
    pub young_pa: f64,
    /// Poisson's ratio.
    pub poisson: f64,
    /// How the energy grows with the volume change (eq 5.6's when a stored material does not
    /// say).
    #[serde(default)]
    pub volumetric: VolumetricLaw,
}

/// The volumetric part of the gel's law. Both share the small-strain E and nu, and differ under
/// large compression: on square1 pressed 1 mm into DIGIT_v8 (half its thickness) the force is
/// 75.8 N with eq 5.6 and 171 N with the ln J form (README, "Indefinite tangents").
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum VolumetricLaw {
    /// Eq 5.6: mu/2 (J^-2/3 I1 - 3) + kappa/2 (J - 1)^2, kappa = E / (3 (1 - 2 nu)); its energy
    /// stays finite as J goes to 0, so crushed elements soften.
    #[default]
    Bulk,
    /// Eq 2.1: mu/2 (I1 - 3) - mu ln J + lambda/2 (ln J)^2; its energy grows without bound as J
    /// goes to 0.
    LogJ,
}

impl Default for GelMaterial {
    /// A soft silicone: E = 0.3 MPa, nu = 0.45 (the dissertation does not state its calibrated
    /// values; under prescribed indentation the displacements do not depend on E at all).
    fn default() -> Self {
        GelMaterial {
            young_pa: 0.3e6,
            poisson: 0.45,
            volumetric: VolumetricLaw::Bulk,
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

    /// Eq 5.6's gel of modulus `young_pa` and Poisson's ratio `poisson`.
    pub fn new(young_pa: f64, poisson: f64) -> Self {
        GelMaterial {
            young_pa,
            poisson,
            volumetric: VolumetricLaw::Bulk,
        }
    }

    /// The FEM law (eq 5.6 unless `volumetric` says otherwise).
    pub fn law(&self) -> Material {
        match self.volumetric {
            VolumetricLaw::Bulk => Material::neo_hookean_bulk(self.young_pa, self.poisson),
            VolumetricLaw::LogJ => Material::neo_hookean(self.young_pa, self.poisson),
        }
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

/// Twice the signed area of the triangle (a, b, c) in the plane (positive anticlockwise).
pub fn doubled_area(a: [f64; 2], b: [f64; 2], c: [f64; 2]) -> f64 {
    (b[0] - a[0]) * (c[1] - a[1]) - (c[0] - a[0]) * (b[1] - a[1])
}

/// Barycentric weights of `q` in the triangle (a, b, c) of doubled signed area `det`
/// ([`doubled_area`], not zero), or None when `q` lies outside it beyond a 1e-9 tolerance on
/// the weights (points on a shared edge belong to both triangles).
pub fn barycentric(
    a: [f64; 2],
    b: [f64; 2],
    c: [f64; 2],
    det: f64,
    q: [f64; 2],
) -> Option<[f64; 3]> {
    let l1 = ((b[0] - q[0]) * (c[1] - q[1]) - (c[0] - q[0]) * (b[1] - q[1])) / det;
    let l2 = ((c[0] - q[0]) * (a[1] - q[1]) - (a[0] - q[0]) * (c[1] - q[1])) / det;
    let l3 = 1.0 - l1 - l2;
    let eps = -1e-9;
    (l1 >= eps && l2 >= eps && l3 >= eps).then_some([l1, l2, l3])
}

/// A surface layer of the gel stiffer (or softer) than its body: every element whose centroid
/// lies less than `thickness_m` below the top face has its stiffness scaled by
/// `stiffness_ratio` (the FEM's per-element scale). Real DIGIT gels carry a reflective coating,
/// and a stiff skin spreads a contact's deformation beyond the contact like a plate.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Skin {
    /// Thickness below the top face, m.
    pub thickness_m: f64,
    /// The layer's stiffness over the body's (1: the same gel).
    pub stiffness_ratio: f64,
}

impl Skin {
    /// Checks the parameters a user gives: a finite non-negative thickness and a finite
    /// positive stiffness ratio.
    pub fn validate(&self) -> Result<()> {
        if !(self.thickness_m >= 0.0 && self.thickness_m.is_finite()) {
            return Err(TactileError::Input(format!(
                "the skin's thickness must be finite and not negative (got {} m)",
                self.thickness_m
            )));
        }
        if !(self.stiffness_ratio > 0.0 && self.stiffness_ratio.is_finite()) {
            return Err(TactileError::Input(format!(
                "the skin's stiffness ratio must be finite and positive (got {})",
                self.stiffness_ratio
            )));
        }
        Ok(())
    }
}

impl Gel {
    /// Depth of every element's centroid below the top face, m: the height of the top face
    /// over the centroid (interpolated on the top triangle above it) minus the centroid's
    /// height; infinite where no top triangle lies above it.
    pub fn element_depths_m(&self) -> Vec<f64> {
        let pts = &self.mesh.points;
        let (lo, hi) = self.top_bounds();
        let n_tri = self.top_triangles.len().max(1);
        // About two triangles per cell.
        let cells_per_side = ((n_tri as f64 / 2.0).sqrt().ceil() as usize).clamp(1, 512);
        let size = [
            ((hi[0] - lo[0]) / cells_per_side as f64).max(f64::MIN_POSITIVE),
            ((hi[1] - lo[1]) / cells_per_side as f64).max(f64::MIN_POSITIVE),
        ];
        let cell = |v: f64, k: usize| -> usize {
            (((v - lo[k]) / size[k]).floor().max(0.0) as usize).min(cells_per_side - 1)
        };
        let mut buckets: Vec<Vec<usize>> = vec![Vec::new(); cells_per_side * cells_per_side];
        for (t, tri) in self.top_triangles.iter().enumerate() {
            let (mut a, mut b) = ([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]);
            for &i in tri {
                for k in 0..2 {
                    a[k] = a[k].min(pts[i][k]);
                    b[k] = b[k].max(pts[i][k]);
                }
            }
            for cx in cell(a[0], 0)..=cell(b[0], 0) {
                for cy in cell(a[1], 1)..=cell(b[1], 1) {
                    buckets[cx * cells_per_side + cy].push(t);
                }
            }
        }
        // The top face's height at (x, y), if a top triangle lies over it.
        let top_z = |x: f64, y: f64| -> Option<f64> {
            if x < lo[0] || x > hi[0] || y < lo[1] || y > hi[1] {
                return None;
            }
            let b = &buckets[cell(x, 0) * cells_per_side + cell(y, 1)];
            b.iter().find_map(|&t| {
                let [p, q, r] = self.top_triangles[t].map(|i| pts[i]);
                let [a, b, c] = [p, q, r].map(|v| [v[0], v[1]]);
                let det = doubled_area(a, b, c);
                if det.abs() < 1e-30 {
                    return None;
                }
                let l = barycentric(a, b, c, det, [x, y])?;
                Some(l[0] * p[2] + l[1] * q[2] + l[2] * r[2])
            })
        };
        self.mesh
            .tets
            .iter()
            .map(|t| {
                let c = t.iter().fold([0.0; 3], |mut c, &i| {
                    for k in 0..3 {
                        c[k] += 0.25 * pts[i][k];
                    }
                    c
                });
                top_z(c[0], c[1]).map_or(f64::INFINITY, |z| z - c[2])
            })
            .collect()
    }

    /// Scales the stiffness of the elements within `skin` below the top face (on top of any
    /// scale they had); returns how many were scaled. A thickness of 0 scales none; a thicker
    /// layer that holds no element's centroid (a mesh too coarse for it) is an error.
    pub fn stiffen_skin(&mut self, skin: &Skin) -> Result<usize> {
        skin.validate()?;
        let depths = self.element_depths_m();
        let mut count = 0;
        for (scale, &d) in self.model.element_scale.iter_mut().zip(&depths) {
            if d < skin.thickness_m {
                *scale *= skin.stiffness_ratio;
                count += 1;
            }
        }
        if count == 0 && skin.thickness_m > 0.0 {
            let shallowest = depths.iter().copied().fold(f64::INFINITY, f64::min);
            return Err(TactileError::Input(format!(
                "a skin {:.1} um thick holds no element of this mesh: the shallowest element centroid lies {:.1} um below the top face",
                skin.thickness_m * 1e6,
                shallowest * 1e6
            )));
        }
        Ok(count)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn signed_volume(m: &Mesh, t: [usize; 4]) -> f64 {
        let p = t.map(|i| nalgebra::Vector3::from(m.points[i]));
        (p[1] - p[0]).cross(&(p[2] - p[0])).dot(&(p[3] - p[0])) / 6.0
    }

    /// Both volumetric laws give the same stress to first order in a small strain, and under
    /// strong compression the ln J law resists far more (eq 5.6's bulk energy stays finite).
    #[test]
    fn volumetric_laws_share_small_strains_and_part_under_compression() {
        use nalgebra::Matrix3;
        use ocm_fem::material::hyperelastic;
        let bulk = GelMaterial::default();
        let log = GelMaterial {
            volumetric: VolumetricLaw::LogJ,
            ..bulk
        };
        let p11 =
            |m: &GelMaterial, f: Matrix3<f64>| hyperelastic(&m.law(), &f, false).unwrap().1[(0, 0)];
        let eps = 1e-5;
        let small = Matrix3::from_diagonal(&nalgebra::Vector3::new(1.0 - eps, 1.0, 1.0));
        let (a, b) = (p11(&bulk, small), p11(&log, small));
        assert!((a - b).abs() < 1e-3 * a.abs(), "{a} against {b}");
        // Linear elasticity in uniaxial strain: sigma = (lambda + 2 mu) eps.
        let (mu, lam) = ocm_fem::material::lame(bulk.young_pa, bulk.poisson);
        assert!((a + (lam + 2.0 * mu) * eps).abs() < 1e-3 * a.abs(), "{a}");
        // The ln J law's share of the compressive stress grows as the element is crushed.
        let ratio = |j: f64| {
            let f = Matrix3::from_diagonal(&nalgebra::Vector3::new(j, 1.0, 1.0));
            let (a, b) = (p11(&bulk, f), p11(&log, f));
            assert!(a < 0.0 && b < 0.0, "J {j}: eq 5.6 {a} Pa, ln J {b} Pa");
            b / a
        };
        let (half, tenth) = (ratio(0.5), ratio(0.1));
        assert!(
            half > 1.0 && tenth > 4.0 && tenth > 2.0 * half,
            "{half} {tenth}"
        );
        let back: GelMaterial = serde_json::from_str(r#"{"young_pa":3e5,"poisson":0.45}"#).unwrap();
        assert_eq!(back, bulk);
        let text = serde_json::to_string(&log).unwrap();
        assert!(text.contains("log_j"), "{text}");
        assert_eq!(serde_json::from_str::<GelMaterial>(&text).unwrap(), log);
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

    /// On a flat box every element's depth is the top's height minus its centroid's; on a
    /// crowned box the bucketed search finds the same top triangle as a search over all of
    /// them, and the skin scales exactly the elements above its thickness.
    #[test]
    fn skin_depths_follow_the_top_face() {
        let flat = ocm_fem::mesh::generate::box_mesh([6, 5, 4], [3e-3, 2.5e-3, 2e-3]);
        let gel = Gel::from_mesh(flat.clone(), GelMaterial::default(), 0.0).unwrap();
        let depths = gel.element_depths_m();
        assert_eq!(depths.len(), gel.model.elements.len());
        for (t, d) in gel.mesh.tets.iter().zip(&depths) {
            let cz = t.iter().map(|&i| gel.mesh.points[i][2]).sum::<f64>() / 4.0;
            assert!((d - (2e-3 - cz)).abs() < 1e-15, "{d} against {}", 2e-3 - cz);
        }
        let mut crowned = flat;
        Crown {
            radius_m: 4e-3,
            apex_m: [1.2e-3, 1.0e-3],
        }
        .apply(&mut crowned, 0.0)
        .unwrap();
        let gel = Gel::from_mesh(crowned, GelMaterial::default(), 0.0).unwrap();
        let depths = gel.element_depths_m();
        let pts = &gel.mesh.points;
        for (t, d) in gel.mesh.tets.iter().zip(&depths) {
            let c = t.iter().fold([0.0; 3], |mut c, &i| {
                (0..3).for_each(|k| c[k] += 0.25 * pts[i][k]);
                c
            });
            // Every top triangle, with a tolerance on its edges: the one over the centroid.
            let above = gel.top_triangles.iter().find_map(|tri| {
                let [p, q, r] = tri.map(|i| pts[i]);
                let det = (q[0] - p[0]) * (r[1] - p[1]) - (r[0] - p[0]) * (q[1] - p[1]);
                let l1 = ((c[0] - p[0]) * (r[1] - p[1]) - (r[0] - p[0]) * (c[1] - p[1])) / det;
                let l2 = ((q[0] - p[0]) * (c[1] - p[1]) - (c[0] - p[0]) * (q[1] - p[1])) / det;
                let l0 = 1.0 - l1 - l2;
                (l0.min(l1).min(l2) >= -1e-9).then(|| l0 * p[2] + l1 * q[2] + l2 * r[2])
            });
            let want = above.expect("a top triangle over every centroid") - c[2];
            assert!((d - want).abs() < 1e-12, "{d} against {want}");
            assert!(*d > 0.0);
        }
        let skin = Skin {
            thickness_m: 0.3e-3,
            stiffness_ratio: 4.0,
        };
        let mut stiff = gel.clone();
        let n = stiff.stiffen_skin(&skin).unwrap();
        let want = depths.iter().filter(|&&d| d < 0.3e-3).count();
        assert!(n == want && n > 0 && n < depths.len());
        for (s, d) in stiff.model.element_scale.iter().zip(&depths) {
            assert_eq!(*s, if *d < 0.3e-3 { 4.0 } else { 1.0 });
        }
        // Thinner than the top layer's shallowest centroid: no element, an error naming it.
        let shallowest = depths.iter().copied().fold(f64::INFINITY, f64::min);
        let e = stiff
            .clone()
            .stiffen_skin(&Skin {
                thickness_m: 0.5 * shallowest,
                stiffness_ratio: 2.0,
            })
            .unwrap_err()
            .to_string();
        assert!(e.contains("holds no element"), "{e}");
        let none = Skin {
            thickness_m: 0.0,
            stiffness_ratio: 2.0,
        };
        assert_eq!(stiff.clone().stiffen_skin(&none).unwrap(), 0);
        for bad in [
            Skin {
                thickness_m: -1e-4,
                stiffness_ratio: 2.0,
            },
            Skin {
                thickness_m: f64::NAN,
                stiffness_ratio: 2.0,
            },
            Skin {
                thickness_m: 1e-4,
                stiffness_ratio: 0.0,
            },
            Skin {
                thickness_m: 1e-4,
                stiffness_ratio: f64::INFINITY,
            },
        ] {
            let e = stiff.clone().stiffen_skin(&bad).unwrap_err().to_string();
            assert!(e.contains("skin"), "{e}");
        }
    }

    /// A block on rollers with its top pressed down uniformly, a quarter of its height made
    /// stiffer: the two layers carry the same stress in series, so (with nu = 0, no lateral
    /// strain to match) the strain energy is A d^2 / (2 (h_s / (k E) + (H - h_s) / E)).
    #[test]
    fn a_stiff_skin_acts_in_series_with_the_body() {
        let (lx, ly, h) = (2e-3, 1.5e-3, 2e-3);
        let e = 0.3e6;
        let material = GelMaterial::new(e, 0.0);
        let d = 0.2e-6;
        let energy = |skin: Option<Skin>| {
            let mesh = ocm_fem::mesh::generate::box_mesh([3, 2, 4], [lx, ly, h]);
            let tol = 1e-9;
            let mut gel =
                Gel::with_constraints(mesh, material, |p| [p.x <= tol, p.y <= tol, p.z <= tol])
                    .unwrap();
            let scaled = skin.map_or(0, |s| gel.stiffen_skin(&s).unwrap());
            for &i in &gel.top {
                gel.model.prescribe(i, 2, -d);
            }
            let mut solver = ocm_fem::solve::statics::StaticSolver::new(&gel.model).unwrap();
            let loads = ocm_fem::model::Loads {
                pressures_pa: vec![],
            };
            let (_, report) = solver.solve_from_rest(&gel.model, &loads).unwrap();
            (report.strain_energy, scaled)
        };
        let series = |k: f64| 0.5 * lx * ly * d * d / (0.5e-3 / (k * e) + 1.5e-3 / e);
        let (plain, none) = energy(None);
        assert_eq!(none, 0);
        assert!((plain - series(1.0)).abs() < 1e-4 * series(1.0), "{plain}");
        for k in [4.0, 0.25] {
            // The top hex layer is 0.5 mm thick: its tets' centroids lie 0.125-0.375 mm deep.
            let (u, scaled) = energy(Some(Skin {
                thickness_m: 0.45e-3,
                stiffness_ratio: k,
            }));
            assert_eq!(scaled, 3 * 2 * 6);
            println!("k {k}: energy {u:e} J, series {:e} J", series(k));
            assert!((u - series(k)).abs() < 1e-4 * series(k), "k {k}: {u}");
        }
    }
}
