//! Scene files (TOML) for `ocm fem run`: a mesh, a material, constraints and an analysis.
//!
//! ```toml
//! mesh = "../shared/data/digit/DIGIT_remesh2.vtk"   # relative to the scene file
//! length_unit = "m"                                   # "m" or "mm"
//! [material]
//! law = "neo_hookean_bulk"                            # corotational | neo_hookean | neo_hookean_bulk
//! young_pa = 1.5e5
//! poisson = 0.45
//! density_kg_m3 = 1040.0
//! [[fix_box]]                                         # metres
//! lo = [-1, -1, -1]
//! hi = [1, 1, 0.0005]
//! [static]
//! gravity_m_s2 = [0, 0, -9.81]
//! ```
//! or, for the bellows manipulator, `[bellows]` (see [`crate::bellows::BellowsConfig`]; its
//! `rigid = "constraint" | "penalty"` picks rigid bodies or stiffened elements for the rigid parts)
//! with `pressures_kpa = [[10, 0, 0], ...]`. A `[dynamic]` table (dt_s, steps, integrator) runs
//! implicit dynamics of the last static load from rest instead.

use crate::bellows::{Bellows, BellowsConfig, Law};
use crate::material::Material;
use crate::mesh::{Mesh, stl, vtk};
use crate::model::{Loads, Model, State};
use crate::solve::dynamics::{DynamicSolver, Integrator};
use crate::solve::statics::StaticSolver;
use crate::{FemError, Result};
use nalgebra::Vector3;
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};

/// Material table.
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct MaterialSpec {
    /// Constitutive law.
    pub law: Law,
    /// Young's modulus, Pa.
    pub young_pa: f64,
    /// Poisson's ratio.
    pub poisson: f64,
    /// Density, kg/m^3.
    #[serde(default = "default_density")]
    pub density_kg_m3: f64,
}

fn default_density() -> f64 {
    1040.0
}

/// Box of clamped nodes, metres.
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct FixBox {
    /// Lower corner.
    pub lo: [f64; 3],
    /// Upper corner.
    pub hi: [f64; 3],
}

/// Plane of clamped nodes, metres.
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct FixPlane {
    /// A point on the plane.
    pub point: [f64; 3],
    /// Its normal.
    pub normal: [f64; 3],
    /// Distance tolerance.
    pub tol: f64,
}

/// Dynamic analysis.
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct DynamicSpec {
    /// Time step, s.
    pub dt_s: f64,
    /// Number of steps.
    pub steps: usize,
    /// Integrator.
    #[serde(default = "default_integrator")]
    pub integrator: Integrator,
}

fn default_integrator() -> Integrator {
    Integrator::ImplicitEuler
}

/// A scene file.
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Scene {
    /// Mesh path (VTK), relative to the scene file.
    pub mesh: PathBuf,
    /// Unit of the mesh coordinates: "m" or "mm".
    #[serde(default = "default_unit")]
    pub length_unit: String,
    /// Generic material (ignored for bellows scenes).
    pub material: Option<MaterialSpec>,
    /// Bellows manipulator scene parameters.
    pub bellows: Option<BellowsConfig>,
    /// Pressure states for bellows scenes, kPa.
    #[serde(default)]
    pub pressures_kpa: Vec<[f64; 3]>,
    /// Clamp boxes.
    #[serde(default)]
    pub fix_box: Vec<FixBox>,
    /// Clamp planes.
    #[serde(default)]
    pub fix_plane: Vec<FixPlane>,
    /// Gravity, m/s^2 (generic scenes).
    #[serde(default)]
    pub gravity_m_s2: [f64; 3],
    /// Optional cavity STL (generic scenes; its vertices must coincide with mesh nodes).
    pub cavity_stl: Option<PathBuf>,
    /// Cavity pressure for generic scenes, Pa.
    #[serde(default)]
    pub cavity_pressure_pa: f64,
    /// Dynamic analysis instead of static.
    pub dynamic: Option<DynamicSpec>,
}

fn default_unit() -> String {
    "m".into()
}

/// One result of a scene run.
#[derive(Debug, Clone, Serialize)]
pub struct SceneResult {
    /// Label (pressure state or time).
    pub label: String,
    /// Largest nodal displacement, m.
    pub max_displacement_m: f64,
    /// Newton iterations.
    pub iterations: usize,
    /// Bellows state, when a bellows scene.
    pub bellows: Option<crate::bellows::BellowsState>,
    /// Nodal displacements (not serialised).
    #[serde(skip)]
    pub displacement: Vec<[f64; 3]>,
}

/// A scene ready to run.
pub struct Prepared {
    /// The model.
    pub model: Model,
    /// Mesh for output (metres).
    pub mesh: Mesh,
    /// The bellows wrapper for bellows scenes.
    pub bellows: Option<Bellows>,
    /// Load cases.
    pub loads: Vec<(String, Loads)>,
    /// Dynamic settings.
    pub dynamic: Option<DynamicSpec>,
}

impl Scene {
    /// Parses a scene from TOML text.
    pub fn from_toml(text: &str) -> Result<Self> {
        toml::from_str(text).map_err(|e| {
            let at = e.span().map_or("scene".to_string(), |s| {
                format!(
                    "line {}",
                    text[..s.start.min(text.len())].matches('\n').count() + 1
                )
            });
            FemError::parse("scene TOML", at, e.message().to_string())
        })
    }

    /// Builds the model; relative paths are resolved against `base`.
    pub fn prepare(&self, base: &Path) -> Result<Prepared> {
        let path = base.join(&self.mesh);
        let scale = match self.length_unit.as_str() {
            "m" => 1.0,
            "mm" => 1e-3,
            u => {
                return Err(FemError::Model(format!(
                    "length_unit '{u}' must be \"m\" or \"mm\""
                )));
            }
        };
        if let Some(cfg) = &self.bellows {
            if scale != 1e-3 {
                return Err(FemError::Model("bellows scenes read the mesh in mm".into()));
            }
            let b = Bellows::load(&path, cfg.clone())?;
            let loads = self
                .pressures_kpa
                .iter()
                .map(|p| {
                    crate::bellows::check_pressures(p)?;
                    Ok((format!("p_kpa={p:?}"), b.loads_kpa(p)))
                })
                .collect::<Result<Vec<_>>>()?;
            return Ok(Prepared {
                model: b.model.clone(),
                mesh: b.mesh.clone(),
                loads,
                bellows: Some(b),
                dynamic: self.dynamic.clone(),
            });
        }
        let spec = self
            .material
            .as_ref()
            .ok_or_else(|| FemError::Model("scene needs [material] or [bellows]".into()))?;
        let mut mesh = vtk::read_path(&path)?;
        mesh.scale(scale);
        mesh.remove_unused_points();
        let mat = match spec.law {
            Law::Corotational => Material::corotational(spec.young_pa, spec.poisson),
            Law::NeoHookean => Material::neo_hookean(spec.young_pa, spec.poisson),
            Law::NeoHookeanBulk => Material::neo_hookean_bulk(spec.young_pa, spec.poisson),
        };
        let mut model = Model::new(&mesh, mat, spec.density_kg_m3)?;
        model.gravity = Vector3::from(self.gravity_m_s2);
        let mut nfix = 0;
        for b in &self.fix_box {
            nfix += model.fix_box(b.lo, b.hi);
        }
        for p in &self.fix_plane {
            nfix += model.fix_plane(p.point, p.normal, p.tol);
        }
        if nfix == 0 && self.dynamic.is_none() {
            return Err(FemError::Model(
                "no node is clamped: a static solve would be singular".into(),
            ));
        }
        let mut loads = Loads::default();
        if let Some(c) = &self.cavity_stl {
            let mut s = stl::read_path(base.join(c))?;
            s.scale(scale);
            let (lo, hi) = mesh.bounds();
            let tol = 1e-6 * (0..3).map(|k| hi[k] - lo[k]).fold(0.0, f64::max);
            let map = crate::mesh::surface::match_points(&mesh, &s, tol).map_err(|(k, d)| {
                FemError::Model(format!(
                    "cavity STL vertex {k} is {d:.3e} m from the nearest mesh node"
                ))
            })?;
            model.add_cavity(
                "cavity",
                s.triangles.iter().map(|t| t.map(|i| map[i])).collect(),
            )?;
            loads.pressures_pa.push(self.cavity_pressure_pa);
        }
        Ok(Prepared {
            model,
            mesh,
            bellows: None,
            loads: vec![("static".into(), loads)],
            dynamic: self.dynamic.clone(),
        })
    }
}

impl Prepared {
    /// Runs every load case (static) or the dynamic analysis; `progress` is called after each result.
    pub fn run(&self, mut progress: impl FnMut(usize, usize)) -> Result<Vec<SceneResult>> {
        let result = |label: String, s: &State, iterations: usize| {
            let displacement = s.displacements(&self.model);
            SceneResult {
                label,
                max_displacement_m: displacement
                    .iter()
                    .map(|d| (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt())
                    .fold(0.0, f64::max),
                iterations,
                bellows: self.bellows.as_ref().map(|b| b.state_of(s)),
                displacement,
            }
        };
        let mut out = vec![];
        if let Some(d) = &self.dynamic {
            let loads = self.loads.last().map(|l| l.1.clone()).unwrap_or_default();
            let mut solver = DynamicSolver::new(&self.model, d.integrator)?;
            let mut s = State::at_rest(&self.model);
            for k in 0..d.steps {
                let rep = solver.step(&self.model, &mut s, &loads, d.dt_s)?;
                out.push(result(format!("t={:.6}", s.t), &s, rep.iterations));
                progress(k + 1, d.steps);
            }
            return Ok(out);
        }
        let mut solver = StaticSolver::new(&self.model)?;
        let n = self.loads.len();
        for (k, (label, loads)) in self.loads.iter().enumerate() {
            let (s, rep) = solver.solve_from_rest(&self.model, loads)?;
            out.push(result(label.clone(), &s, rep.iterations));
            progress(k + 1, n);
        }
        Ok(out)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn scene_errors_name_the_line() {
        let e = Scene::from_toml("mesh = \"a.vtk\"\nlength_unit = 3\n")
            .unwrap_err()
            .to_string();
        assert!(e.contains("line 2"), "{e}");
        let e = Scene::from_toml("mesh = \"a.vtk\"\nbogus = 1\n")
            .unwrap_err()
            .to_string();
        assert!(e.contains("bogus"), "{e}");
    }

    #[test]
    fn bellows_rigid_mode_is_read_and_checked() {
        let text = "mesh = \"m.vtk\"\nlength_unit = \"mm\"\n[bellows]\n";
        let s = Scene::from_toml(text).unwrap();
        assert_eq!(
            s.bellows.unwrap().rigid,
            crate::bellows::RigidMode::Constraint,
            "rigid bodies by default"
        );
        let s = Scene::from_toml(&format!("{text}rigid = \"penalty\"\n")).unwrap();
        assert_eq!(s.bellows.unwrap().rigid, crate::bellows::RigidMode::Penalty);
        let e = Scene::from_toml(&format!("{text}rigid = \"glue\"\n"))
            .unwrap_err()
            .to_string();
        assert!(e.contains("line 4") && e.contains("glue"), "{e}");
    }

    #[test]
    fn generic_scene_runs_a_clamped_block_under_gravity() {
        let dir = std::env::temp_dir().join(format!("ocm-fem-scene-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let m = crate::mesh::generate::box_mesh([10, 2, 2], [0.1, 0.02, 0.02]);
        vtk::write_path(dir.join("block.vtk"), &m, "block", &[], &[]).unwrap();
        let s = Scene::from_toml(
            "mesh = \"block.vtk\"\ngravity_m_s2 = [0, 0, -9.81]\n[material]\nlaw = \"neo_hookean\"\nyoung_pa = 1e6\npoisson = 0.3\n[[fix_plane]]\npoint = [0, 0, 0]\nnormal = [1, 0, 0]\ntol = 1e-9\n",
        )
        .unwrap();
        let p = s.prepare(&dir).unwrap();
        let r = p.run(|_, _| {}).unwrap();
        // Euler-Bernoulli tip sag under self-weight w L^4 / (8 E I), within coarse-tet stiffness error.
        let (l, h) = (0.1f64, 0.02f64);
        let w = 1040.0 * 9.81 * h * h;
        let sag = w * l.powi(4) / (8.0 * 1e6 * h.powi(4) / 12.0);
        assert!(
            r[0].max_displacement_m > 0.3 * sag && r[0].max_displacement_m < 1.1 * sag,
            "{} vs {sag}",
            r[0].max_displacement_m
        );
        std::fs::remove_dir_all(&dir).ok();
    }
}
