//! FEM actuation samples of the bellows: the boundary nodes of every bellows layer, the TCP and the
//! backbone over a set of pressures, solved once and cached to a JSON file.
//!
//! The samples come from the full static FEM of `ocm-fem` (`sweep::run`: each state continued
//! from the previous equilibrium), not from the reduced model: a few hundred static states are
//! cheap enough to solve once and cache, and they carry no reduction error.

use crate::{Result, SurrogateError};
use nalgebra::Vector3;
use ocm_fem::bellows::Bellows;
use ocm_fem::mesh::surface;
use serde::{Deserialize, Serialize};

/// Format tag of the samples file.
pub const FORMAT: &str = "ocm-surrogate-fem-samples/1";

/// Boundary nodes picked per layer (the hexagon of Fig 4.8).
pub const NODES_PER_LAYER: usize = 6;

/// The layers of the bellows found on the rest mesh.
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
pub struct Layers {
    /// Per layer, the mesh node indices of its boundary nodes: one per 60 degree sector about
    /// the robot axis (sectors start at the first chamber's angle, so two per chamber lobe), the
    /// skin node of the layer's ridge band farthest from the axis in that sector.
    pub nodes: Vec<[usize; NODES_PER_LAYER]>,
    /// Per layer, the ridge height range at rest, m.
    pub ridge_z_m: Vec<[f64; 2]>,
}

/// Finds the bellows layers (convolution ridges) on the rest configuration.
///
/// Skin nodes of the flexible zone (between the rigid base and top frame) are binned by height
/// (1 mm); bins whose largest distance from the axis is in the top fifth of the zone's range are
/// ridge bins; neighbouring ridge bins (gaps under 3 mm) form one layer.
pub fn find_layers(b: &Bellows) -> Result<Layers> {
    let rest = &b.model.rest;
    let skin: std::collections::BTreeSet<usize> =
        surface::boundary_faces(&b.mesh.points, &b.mesh.tets)
            .into_iter()
            .flatten()
            .collect();
    let (z0, z1) = (
        b.config.rigid_base_below_mm * 1e-3,
        b.config.rigid_top_above_mm * 1e-3,
    );
    let axis = b.base_center;
    // Sectors start at the first chamber's centre, so each chamber's lobe splits into two
    // sectors (the mesh has no skin nodes between the lobes at the ridge heights).
    let a0 = b
        .chamber_angles_deg
        .first()
        .copied()
        .unwrap_or(0.0)
        .to_radians();
    let radial = |i: usize| ((rest[i].x - axis.x).powi(2) + (rest[i].y - axis.y).powi(2)).sqrt();
    let zone: Vec<usize> = skin
        .iter()
        .copied()
        .filter(|&i| rest[i].z > z0 && rest[i].z < z1)
        .collect();
    if zone.is_empty() {
        return Err(SurrogateError::Invalid(
            "no skin nodes between the rigid base and top frame".into(),
        ));
    }
    let bin = 1e-3;
    let nb = ((z1 - z0) / bin).ceil() as usize;
    let mut rmax = vec![f64::NAN; nb];
    for &i in &zone {
        let k = (((rest[i].z - z0) / bin) as usize).min(nb - 1);
        if !(rmax[k] >= radial(i)) {
            rmax[k] = radial(i);
        }
    }
    let filled: Vec<f64> = rmax.iter().copied().filter(|r| r.is_finite()).collect();
    let lo = filled.iter().copied().fold(f64::INFINITY, f64::min);
    let hi = filled.iter().copied().fold(f64::NEG_INFINITY, f64::max);
    let thresh = lo + 0.8 * (hi - lo);
    let mut groups: Vec<[usize; 2]> = vec![];
    for k in 0..nb {
        if rmax[k] >= thresh {
            match groups.last_mut() {
                Some(g) if k - g[1] <= 3 => g[1] = k,
                _ => groups.push([k, k]),
            }
        }
    }
    let mut layers = Layers {
        nodes: vec![],
        ridge_z_m: vec![],
    };
    for g in groups {
        let (za, zb) = (z0 + g[0] as f64 * bin, z0 + (g[1] + 1) as f64 * bin);
        let mut best = [None::<(usize, f64)>; NODES_PER_LAYER];
        for &i in &zone {
            let (z, r) = (rest[i].z, radial(i));
            if z < za || z >= zb {
                continue;
            }
            let ang = ((rest[i].y - axis.y).atan2(rest[i].x - axis.x) - a0)
                .rem_euclid(std::f64::consts::TAU);
            let s = ((ang / std::f64::consts::TAU * NODES_PER_LAYER as f64) as usize)
                .min(NODES_PER_LAYER - 1);
            if best[s].is_none_or(|(_, rb)| r > rb) {
                best[s] = Some((i, r));
            }
        }
        if best.iter().any(|b| b.is_none()) {
            return Err(SurrogateError::Invalid(format!(
                "layer at z {:.1}..{:.1} mm has an empty 60 degree sector",
                za * 1e3,
                zb * 1e3
            )));
        }
        layers.nodes.push(best.map(|b| b.map(|x| x.0).unwrap_or(0)));
        layers.ridge_z_m.push([za, zb]);
    }
    if layers.nodes.is_empty() {
        return Err(SurrogateError::Invalid("no bellows layer found".into()));
    }
    Ok(layers)
}

/// One solved pressure state.
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
pub struct FemSample {
    /// Chamber pressures, kPa (gauge).
    pub pressures_kpa: [f64; 3],
    /// Tool-centre point, m (mesh frame).
    pub tcp_m: [f64; 3],
    /// Backbone arc length from the base centre to the top-face centre, m.
    pub arc_length_m: f64,
    /// Per layer, the positions of its boundary nodes, m.
    pub layer_nodes_m: Vec<[[f64; 3]; NODES_PER_LAYER]>,
}

/// A cached set of FEM samples with the scene facts the surrogate geometry needs.
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
pub struct FemSamples {
    /// [`FORMAT`].
    pub format: String,
    /// The layers (node indices) the samples were read at.
    pub layers: Layers,
    /// Height of the top of the rigid base, m.
    pub rigid_base_top_m: f64,
    /// Height of the bottom of the rigid top frame, m.
    pub rigid_top_bottom_m: f64,
    /// Height of the top face at rest, m.
    pub top_face_m: f64,
    /// TCP offset above the top face, m.
    pub tcp_offset_m: f64,
    /// Largest distance of a rigid-base node from the axis, m.
    pub base_radius_m: f64,
    /// Largest distance of a top-frame node from the axis, m.
    pub top_radius_m: f64,
    /// Mass of the FEM body, kg.
    pub fem_mass_kg: f64,
    /// The rest state (zero pressure, not solved).
    pub rest: FemSample,
    /// Training samples (a pressure grid).
    pub samples: Vec<FemSample>,
    /// Held-out samples (seeded random pressures), never used to fit.
    pub held_out: Vec<FemSample>,
}

fn sample_of(
    layers: &Layers,
    p: [f64; 3],
    st: &ocm_fem::bellows::BellowsState,
    pos: &[Vector3<f64>],
) -> FemSample {
    FemSample {
        pressures_kpa: p,
        tcp_m: st.tcp_m,
        arc_length_m: st.arc_length_m,
        layer_nodes_m: layers
            .nodes
            .iter()
            .map(|l| l.map(|i| [pos[i].x, pos[i].y, pos[i].z]))
            .collect(),
    }
}

impl FemSample {
    /// The boundary nodes of layer `k` as vectors.
    pub fn layer(&self, k: usize) -> Vec<Vector3<f64>> {
        self.layer_nodes_m[k]
            .iter()
            .map(|p| Vector3::new(p[0], p[1], p[2]))
            .collect()
    }
}

/// Solves the bellows at every training and held-out pressure triple (kPa, each list in order,
/// continued) and records samples. `on_point` sees a running count of finished states.
pub fn collect(
    b: &Bellows,
    pressures_kpa: &[[f64; 3]],
    held_out_kpa: &[[f64; 3]],
    mut on_point: impl FnMut(usize),
) -> Result<FemSamples> {
    let layers = find_layers(b)?;
    let rest_state = ocm_fem::model::State::at_rest(&b.model);
    let rest = sample_of(
        &layers,
        [0.0; 3],
        &b.state_of(&rest_state),
        &rest_state.positions(),
    );
    let mut done = 0;
    let mut run = |list: &[[f64; 3]]| -> Result<Vec<FemSample>> {
        let mut out = Vec::with_capacity(list.len());
        ocm_fem::sweep::run(b, list, |_, pt, st| {
            out.push(sample_of(
                &layers,
                pt.pressures_kpa,
                &pt.state,
                &st.positions(),
            ));
            done += 1;
            on_point(done);
        })?;
        Ok(out)
    };
    let samples = run(pressures_kpa)?;
    let held_out = run(held_out_kpa)?;
    let zmax = b.model.rest.iter().map(|p| p.z).fold(f64::MIN, f64::max);
    let c = b.base_center;
    let radius_where = |keep: &dyn Fn(f64) -> bool| {
        b.model
            .rest
            .iter()
            .filter(|p| keep(p.z))
            .map(|p| ((p.x - c.x).powi(2) + (p.y - c.y).powi(2)).sqrt())
            .fold(0.0, f64::max)
    };
    let (zb, zt) = (
        b.config.rigid_base_below_mm * 1e-3,
        b.config.rigid_top_above_mm * 1e-3,
    );
    Ok(FemSamples {
        format: FORMAT.into(),
        layers,
        rigid_base_top_m: b.config.rigid_base_below_mm * 1e-3,
        rigid_top_bottom_m: b.config.rigid_top_above_mm * 1e-3,
        top_face_m: zmax,
        tcp_offset_m: b.config.tcp_offset_mm * 1e-3,
        base_radius_m: radius_where(&|z| z <= zb),
        top_radius_m: radius_where(&|z| z >= zt),
        fem_mass_kg: b.model.total_mass(),
        rest,
        samples,
        held_out,
    })
}

impl FemSamples {
    /// Writes the samples as JSON.
    pub fn write(&self, path: &std::path::Path) -> Result<()> {
        crate::json::write(path, self, "samples")
    }

    /// Reads and checks a samples file.
    pub fn read(path: &std::path::Path) -> Result<Self> {
        let s: FemSamples = crate::json::read(path)?;
        s.check(&path.display().to_string())?;
        Ok(s)
    }

    /// Checks the format tag, shapes and finiteness.
    pub fn check(&self, name: &str) -> Result<()> {
        if self.format != FORMAT {
            return Err(SurrogateError::parse(
                name,
                "format",
                format!("expected {FORMAT}, found {}", self.format),
            ));
        }
        // sizes and the mass must be positive: a negative one builds a chain of negative
        // length or an inertia of the wrong sign far from this file
        for (field, v) in [
            ("fem_mass_kg", self.fem_mass_kg),
            ("base_radius_m", self.base_radius_m),
            ("top_radius_m", self.top_radius_m),
        ] {
            if !(v.is_finite() && v > 0.0) {
                return Err(SurrogateError::parse(
                    name,
                    field,
                    format!("{v} must be a finite value above 0"),
                ));
            }
        }
        for (field, v) in [
            ("rigid_base_top_m", self.rigid_base_top_m),
            ("rigid_top_bottom_m", self.rigid_top_bottom_m),
            ("top_face_m", self.top_face_m),
            ("tcp_offset_m", self.tcp_offset_m),
        ] {
            if !v.is_finite() {
                return Err(SurrogateError::parse(
                    name,
                    field,
                    format!("{v} is not finite"),
                ));
            }
        }
        if self.tcp_offset_m < 0.0 {
            return Err(SurrogateError::parse(
                name,
                "tcp_offset_m",
                format!("{} m: the TCP lies above the top face", self.tcp_offset_m),
            ));
        }
        if !(self.rigid_base_top_m < self.rigid_top_bottom_m
            && self.rigid_top_bottom_m <= self.top_face_m)
        {
            return Err(SurrogateError::parse(
                name,
                "rigid_base_top_m",
                format!(
                    "heights base top {} m, top frame bottom {} m, top face {} m must rise in that order",
                    self.rigid_base_top_m, self.rigid_top_bottom_m, self.top_face_m
                ),
            ));
        }
        let nl = self.layers.nodes.len();
        let all = std::iter::once(("rest".to_string(), &self.rest))
            .chain(
                self.samples
                    .iter()
                    .enumerate()
                    .map(|(k, s)| (format!("samples[{k}]"), s)),
            )
            .chain(
                self.held_out
                    .iter()
                    .enumerate()
                    .map(|(k, s)| (format!("held_out[{k}]"), s)),
            );
        for (at, s) in all {
            if s.layer_nodes_m.len() != nl {
                return Err(SurrogateError::parse(
                    name,
                    at,
                    format!("{} layers, expected {nl}", s.layer_nodes_m.len()),
                ));
            }
            let finite = s
                .pressures_kpa
                .iter()
                .chain(&s.tcp_m)
                .all(|v| v.is_finite())
                && s.arc_length_m.is_finite()
                && s.layer_nodes_m
                    .iter()
                    .flatten()
                    .flatten()
                    .all(|v| v.is_finite());
            if !finite {
                return Err(SurrogateError::parse(name, at, "non-finite value"));
            }
            if s.arc_length_m <= 0.0 {
                return Err(SurrogateError::parse(
                    name,
                    at,
                    format!("arc length {} m must be above 0", s.arc_length_m),
                ));
            }
        }
        Ok(())
    }
}

/// The lab's working pressure range, kPa (issue 12; the FEM accepts -20..35 kPa).
pub const PRESSURE_RANGE_KPA: [f64; 2] = [-20.0, 35.0];

/// Errors unless every chamber pressure (kPa) is finite and inside [`PRESSURE_RANGE_KPA`]; the
/// error names the chamber, the value and the range.
pub fn check_pressures_kpa(p_kpa: &[f64; 3]) -> Result<()> {
    for (k, &p) in p_kpa.iter().enumerate() {
        SurrogateError::check_value(
            || format!("chamber {} pressure", k + 1),
            p,
            PRESSURE_RANGE_KPA,
            0.0,
            "kPa",
        )?;
    }
    Ok(())
}

/// A serpentine grid of `levels` equally spaced pressures per chamber over [`PRESSURE_RANGE_KPA`].
pub fn pressure_grid(levels: usize) -> Vec<[f64; 3]> {
    let [lo, hi] = PRESSURE_RANGE_KPA;
    let n = levels.max(2);
    let v: Vec<f64> = (0..n)
        .map(|k| lo + (hi - lo) * k as f64 / (n - 1) as f64)
        .collect();
    ocm_fem::sweep::grid(&v)
}

/// `n` uniformly random pressure triples in [`PRESSURE_RANGE_KPA`] from `seed`.
pub fn random_pressures(n: usize, seed: u64) -> Vec<[f64; 3]> {
    use rand::{Rng, SeedableRng};
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
    let [lo, hi] = PRESSURE_RANGE_KPA;
    (0..n)
        .map(|_| [0; 3].map(|_| rng.random_range(lo..hi)))
        .collect()
}
