//! The three-bellows soft manipulator of dissertation Ch.4.4 built from the real mesh.
//!
//! `ManipulatorWhole25.vtk` (Gmsh, millimetres) holds the tets of the whole robot *including* the
//! three cavity volumes, plus triangle surfaces: the outer skin and the three closed cavity walls
//! (on mesh nodes, but only about 60 % of their triangles are tet faces). We drop the tets whose
//! centroid lies inside a wall, keep the face-connected solid, pressurise the walls as given (so the
//! cavity volume is the wall's), clamp the bottom face, and make the base connectors and the top
//! frame rigid: by default as true rigid bodies ([`Model::add_rigid_body`]; the base touches the
//! clamp and so is clamped whole), or as a stiff penalty ([`Model::make_rigid`]) with
//! `rigid = "penalty"`.

use crate::material::Material;
use crate::mesh::{Mesh, surface, vtk};
use crate::model::{Loads, Model, State};
use crate::solve::statics::{StaticReport, StaticSolver};
use crate::{FemError, Result};
use nalgebra::{Matrix3, Rotation3, Vector3};
use serde::{Deserialize, Serialize};

pub use crate::material::Law;

/// How the rigid parts (base connectors, top frame) are modelled.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "snake_case")]
pub enum RigidMode {
    /// Rigid-body constraints: each part moves with six DOFs, exactly rigid.
    #[default]
    Constraint,
    /// Stiff penalty: the parts' elements are `rigid_factor` times stiffer.
    Penalty,
}

/// Parameters of the bellows scene (SI units unless the name says mm).
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(default)]
pub struct BellowsConfig {
    /// Young's modulus, Pa.
    pub young_pa: f64,
    /// Poisson's ratio.
    pub poisson: f64,
    /// Law.
    pub law: Law,
    /// Density, kg/m^3 (Ch.4.4.5: 1040).
    pub density_kg_m3: f64,
    /// Gravity along -z, m/s^2 (0 disables).
    pub gravity_m_s2: f64,
    /// How the rigid parts are modelled.
    pub rigid: RigidMode,
    /// Stiffness multiplier of the rigid parts (penalty mode).
    pub rigid_factor: f64,
    /// Nodes with z below this are clamped, mm.
    pub fixed_below_mm: f64,
    /// Nodes (constraint) or elements entirely (penalty) below this height are rigid (base
    /// connectors), mm.
    pub rigid_base_below_mm: f64,
    /// Nodes (constraint) or elements entirely (penalty) above this height are rigid (top
    /// frame), mm.
    pub rigid_top_above_mm: f64,
    /// Tool-centre point above the top face along the plate normal, mm.
    pub tcp_offset_mm: f64,
    /// Rayleigh mass coefficient, 1/s (App. E: 0.05).
    pub rayleigh_alpha: f64,
    /// Rayleigh stiffness coefficient, s (App. E: 0.005).
    pub rayleigh_beta: f64,
}

impl Default for BellowsConfig {
    /// The committed material calibration ([`crate::calibration::bellows_material`]) and the
    /// scene of Ch.4.4.
    fn default() -> Self {
        let m = crate::calibration::bellows_material();
        BellowsConfig {
            young_pa: m.young_pa,
            poisson: m.poisson,
            law: m.law,
            density_kg_m3: m.density_kg_m3,
            gravity_m_s2: 0.0,
            rigid: RigidMode::Constraint,
            rigid_factor: 100.0,
            fixed_below_mm: 0.5,
            rigid_base_below_mm: 15.0,
            rigid_top_above_mm: 157.0,
            tcp_offset_mm: 13.5,
            rayleigh_alpha: 0.05,
            rayleigh_beta: 0.005,
        }
    }
}

impl BellowsConfig {
    /// Refuses elastic constants out of range, naming the one given (see
    /// [`crate::material::check_elastic`]).
    pub fn validate(&self) -> Result<()> {
        crate::material::check_elastic(self.young_pa, self.poisson).map_err(FemError::Model)
    }

    /// The material for this configuration.
    pub fn material(&self) -> Material {
        match self.law {
            Law::Corotational => Material::corotational(self.young_pa, self.poisson),
            Law::NeoHookean => Material::neo_hookean(self.young_pa, self.poisson),
            Law::NeoHookeanBulk => Material::neo_hookean_bulk(self.young_pa, self.poisson),
        }
    }
}

/// The assembled manipulator model and the node sets used to read its state.
#[derive(Debug, Clone)]
pub struct Bellows {
    /// FE model (metres).
    pub model: Model,
    /// Volume mesh after removing the cavity fill (metres), for output.
    pub mesh: Mesh,
    /// Scene parameters.
    pub config: BellowsConfig,
    /// Nodes of the top face.
    pub top_face: Vec<usize>,
    /// Nodes of the rigid top frame (for the plate orientation).
    pub top_frame: Vec<usize>,
    /// The top frame's rigid body in [`Model::rigid_bodies`] (constraint mode).
    pub top_body: Option<usize>,
    /// Centre of the clamped base, m.
    pub base_center: Vector3<f64>,
    /// Chamber centre angles about z, degrees (chamber order).
    pub chamber_angles_deg: Vec<f64>,
    /// Tets removed from inside the cavities.
    pub removed_tets: usize,
}

/// The configuration state of Fig 4.3.
#[derive(Debug, Clone, Serialize)]
pub struct BellowsState {
    /// Tool-centre point, m.
    pub tcp_m: [f64; 3],
    /// Backbone arc length (constant-curvature fit from base centre to top-face centre), m.
    pub arc_length_m: f64,
    /// Backbone curvature, 1/m.
    pub curvature_per_m: f64,
    /// Bending plane angle about z, degrees.
    pub bending_direction_deg: f64,
    /// Top-plate rotation relative to rest as a rotation vector (axis * angle), rad.
    pub plate_rotation_rad: [f64; 3],
    /// Cavity volumes, m^3.
    pub cavity_volumes_m3: Vec<f64>,
}

impl Bellows {
    /// Loads the VTK mesh (millimetres) and builds the scene.
    pub fn load(vtk_path: impl AsRef<std::path::Path>, config: BellowsConfig) -> Result<Self> {
        let mesh = vtk::read_path(vtk_path)?;
        Self::from_mesh(mesh, config)
    }

    /// Builds the scene from a mesh in millimetres with cavity triangle surfaces.
    pub fn from_mesh(mut mesh: Mesh, config: BellowsConfig) -> Result<Self> {
        config.validate()?;
        mesh.orient_tets();
        let comps = surface::components(&mesh.triangles);
        let mut surfaces: Vec<(f64, Vec<[usize; 3]>)> = comps
            .iter()
            .map(|c| {
                let t: Vec<[usize; 3]> = c.iter().map(|&k| mesh.triangles[k]).collect();
                (surface::enclosed_volume(&mesh.points, &t).abs(), t)
            })
            .filter(|(_, t)| surface::open_edges(t) == 0)
            .collect();
        // The largest closed surface is the skin; the others are cavity walls.
        surfaces.sort_by(|a, b| b.0.total_cmp(&a.0));
        if surfaces.len() < 2 {
            return Err(FemError::Model(format!(
                "expected the skin and cavity walls as closed triangle surfaces, found {}",
                surfaces.len()
            )));
        }
        let cavities: Vec<Vec<[usize; 3]>> = surfaces.drain(1..).map(|(_, t)| t).collect();
        let before = mesh.tets.len();
        let pts = mesh.points.clone();
        // The cavity walls are not all faces of the tet mesh (Gmsh kept their nodes but not every
        // face), so the fill is found geometrically: tets whose centroid lies inside a wall go.
        mesh.tets.retain(|t| {
            let mut c = [0.0; 3];
            for &i in t {
                for k in 0..3 {
                    c[k] += pts[i][k] / 4.0;
                }
            }
            cavities
                .iter()
                .all(|cav| surface::winding_number(&pts, cav, c).abs() < 0.5)
        });
        // Tets left hanging by an edge or a vertex would be mechanisms: keep the face-connected solid.
        let (region, _) = surface::regions_cut_by(&mesh.tets, &[]);
        let mut k = 0;
        mesh.tets.retain(|_| {
            k += 1;
            region[k - 1] == 0
        });
        let removed = before - mesh.tets.len();
        let mut chambers: Vec<(f64, Vec<[usize; 3]>)> = cavities
            .into_iter()
            .map(|t| {
                let n = (t.len() * 3) as f64;
                let (sx, sy) = t
                    .iter()
                    .flatten()
                    .fold((0.0, 0.0), |a, &i| (a.0 + pts[i][0], a.1 + pts[i][1]));
                let ang = (sy / n).atan2(sx / n).to_degrees().rem_euclid(360.0);
                (ang, t)
            })
            .collect();
        chambers.sort_by(|a, b| a.0.total_cmp(&b.0));
        mesh.triangles = chambers.iter().flat_map(|c| c.1.iter().copied()).collect();
        let map = mesh.remove_unused_points();
        let remap = |t: &[usize; 3]| -> Result<[usize; 3]> {
            let f = |i: usize| {
                map[i]
                    .ok_or_else(|| FemError::Model(format!("cavity node {i} is not on the solid")))
            };
            Ok([f(t[0])?, f(t[1])?, f(t[2])?])
        };
        mesh.scale(1e-3);
        let mut model = Model::new(&mesh, config.material(), config.density_kg_m3)?;
        model.gravity = Vector3::new(0.0, 0.0, -config.gravity_m_s2);
        model.rayleigh_alpha = config.rayleigh_alpha;
        model.rayleigh_beta = config.rayleigh_beta;
        for (k, (_, tris)) in chambers.iter().enumerate() {
            let t = tris.iter().map(remap).collect::<Result<Vec<_>>>()?;
            model.add_cavity(&format!("chamber{}", k + 1), t)?;
        }
        let zf = config.fixed_below_mm * 1e-3;
        let nfixed = model.fix_nodes(|p| p.z <= zf);
        if nfixed == 0 {
            return Err(FemError::Model(format!(
                "no nodes below z = {} mm to clamp",
                config.fixed_below_mm
            )));
        }
        let (zb, zt) = (
            config.rigid_base_below_mm * 1e-3,
            config.rigid_top_above_mm * 1e-3,
        );
        let top_body = match config.rigid {
            RigidMode::Penalty => {
                model.make_rigid(|p| p.z <= zb, config.rigid_factor);
                model.make_rigid(|p| p.z >= zt, config.rigid_factor);
                None
            }
            RigidMode::Constraint => {
                model.add_rigid_body("base", |p| p.z <= zb)?;
                Some(model.add_rigid_body("top", |p| p.z >= zt)?)
            }
        };
        let zmax = model
            .rest
            .iter()
            .map(|p| p.z)
            .fold(f64::NEG_INFINITY, f64::max);
        let top_face: Vec<usize> = (0..model.num_nodes())
            .filter(|&i| model.rest[i].z >= zmax - 1e-4)
            .collect();
        let top_frame: Vec<usize> = (0..model.num_nodes())
            .filter(|&i| model.rest[i].z >= zt)
            .collect();
        let base: Vec<usize> = (0..model.num_nodes())
            .filter(|&i| model.rest[i].z <= zf)
            .collect();
        let base_center =
            base.iter().map(|&i| model.rest[i]).sum::<Vector3<f64>>() / base.len() as f64;
        Ok(Bellows {
            chamber_angles_deg: chambers.iter().map(|c| c.0).collect(),
            model,
            mesh,
            config,
            top_face,
            top_frame,
            top_body,
            base_center: Vector3::new(base_center.x, base_center.y, 0.0),
            removed_tets: removed,
        })
    }

    /// Loads for chamber pressures in kPa (gauge).
    pub fn loads_kpa(&self, p_kpa: &[f64]) -> Loads {
        Loads {
            pressures_pa: p_kpa.iter().map(|p| p * 1e3).collect(),
        }
    }

    /// Reads the Fig 4.3 state from a solved configuration.
    pub fn state_of(&self, s: &State) -> BellowsState {
        let pos = s.positions();
        let r = match self.top_body.and_then(|b| s.bodies.get(b)) {
            Some(body) => body.rotation_matrix(),
            None => {
                // Penalty mode: best-fit rotation of the top frame (Kabsch).
                let rest = &self.model.rest;
                let c0 = self
                    .top_frame
                    .iter()
                    .map(|&i| rest[i])
                    .sum::<Vector3<f64>>()
                    / self.top_frame.len() as f64;
                let c1 = self.top_frame.iter().map(|&i| pos[i]).sum::<Vector3<f64>>()
                    / self.top_frame.len() as f64;
                let mut h = Matrix3::zeros();
                for &i in &self.top_frame {
                    h += (pos[i] - c1) * (rest[i] - c0).transpose();
                }
                crate::element::polar_rotation(&h)
            }
        };
        let rot = Rotation3::from_matrix_unchecked(r);
        let top1 = self.top_face.iter().map(|&i| pos[i]).sum::<Vector3<f64>>()
            / self.top_face.len() as f64;
        let tcp = self.tcp_from(&top1, &r);
        let d = top1 - self.base_center;
        let (arc, kappa) = backbone_arc(&d);
        let rv = rot.scaled_axis();
        BellowsState {
            tcp_m: [tcp.x, tcp.y, tcp.z],
            arc_length_m: arc,
            curvature_per_m: kappa,
            bending_direction_deg: d.y.atan2(d.x).to_degrees(),
            plate_rotation_rad: [rv.x, rv.y, rv.z],
            cavity_volumes_m3: self.model.cavities.iter().map(|c| c.volume(&pos)).collect(),
        }
    }

    /// The tool-centre point from the top-face centre and the top-plate rotation, m.
    pub fn tcp_from(&self, top_center: &Vector3<f64>, rotation: &Matrix3<f64>) -> Vector3<f64> {
        top_center + rotation * Vector3::z() * self.config.tcp_offset_mm * 1e-3
    }

    /// Static solve of one pressure state from rest.
    pub fn solve_kpa(
        &self,
        solver: &mut StaticSolver,
        p_kpa: &[f64],
    ) -> Result<(State, StaticReport)> {
        check_pressures(p_kpa)?;
        solver.solve_from_rest(&self.model, &self.loads_kpa(p_kpa))
    }
}

/// Constant-curvature backbone through the base centre and the top-face centre, tangent to z at
/// the base: (arc length m, curvature 1/m) from their offset `d`, m.
pub fn backbone_arc(d: &Vector3<f64>) -> (f64, f64) {
    let horiz = d.xy().norm();
    if horiz < 1e-9 {
        (d.z, 0.0)
    } else {
        let k = 2.0 * horiz / (horiz * horiz + d.z * d.z);
        let theta = 2.0 * horiz.atan2(d.z);
        (theta / k, k)
    }
}

/// Rejects pressures outside the actuator range of the dissertation (-20..35 kPa) or non-finite.
pub fn check_pressures(p_kpa: &[f64]) -> Result<()> {
    for (k, p) in p_kpa.iter().enumerate() {
        if !p.is_finite() || !(-20.0..=35.0).contains(p) {
            return Err(FemError::Model(format!(
                "chamber {} pressure {p} kPa outside -20..35 kPa",
                k + 1
            )));
        }
    }
    Ok(())
}
