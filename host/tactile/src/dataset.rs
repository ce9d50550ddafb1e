//! Datasets of indentations for the neural physics engine (dissertation Ch.6.5.1): per set-up
//! and saved depth, the top-face nodal displacement and contact force from the FEM, the
//! indenter pose, depth and total force, and the contact points in the sensor frame.
//!
//! Contact points are defined without the FEM, so a rigid-body scene can compute them at run
//! time: over a regular x-y grid on the gel's top face (the [`ContactGrid`]), the lowest point
//! of the rigid body above each grid point, kept where it lies below the undeformed top face.
//! The sensor frame is the gel mesh's frame (metres; z up from the base, the top face near
//! z_top). For a body moving along -z from first touch, the deepest contact point lies below
//! the undeformed top by the indentation depth (up to the grid's sampling).

use crate::gel::Gel;
use crate::indent::{IndentOptions, Indentation, StepOutput};
use crate::indenter::{Indenter, Placed};
use crate::mask::{Grid, Mask, rasterize};
use crate::output::{StepRow, write_force_depth_csv, write_step};
use crate::setup::Setup;
use crate::{Result, TactileError};
use nalgebra::Vector3;
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};

/// How a dataset is generated.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct DatasetOptions {
    /// Depth steps of the FEM (every step is saved).
    pub steps: usize,
    /// Depth increment, m.
    pub step_m: f64,
    /// Spacing of the contact-point grid, m.
    pub grid_spacing_m: f64,
}

impl Default for DatasetOptions {
    /// 20 steps of 50 um (to the protocol's 1 mm; a frictionless static solve at a depth does
    /// not depend on the path, so the 10 um steps of the protocol only cost time), contact
    /// points every 0.25 mm.
    fn default() -> Self {
        DatasetOptions {
            steps: 20,
            step_m: 50e-6,
            grid_spacing_m: 0.25e-3,
        }
    }
}

/// The gel's top face as a graph: its nodes, their rest positions and the triangle edges.
#[derive(Debug, Clone, PartialEq)]
pub struct TopSurface {
    /// Mesh node index of each top node (sorted).
    pub nodes: Vec<usize>,
    /// Rest position of each top node, m.
    pub rest_m: Vec<[f64; 3]>,
    /// Undirected edges of the top triangles, as indices into `nodes` (each once, a < b).
    pub edges: Vec<[usize; 2]>,
}

impl TopSurface {
    /// The top face of `gel` (its upward-facing boundary triangles).
    pub fn from_gel(gel: &Gel) -> Self {
        let nodes = gel.top.clone();
        let mut local = vec![usize::MAX; gel.num_nodes()];
        for (k, &i) in nodes.iter().enumerate() {
            local[i] = k;
        }
        let mut set = std::collections::BTreeSet::new();
        for t in &gel.top_triangles {
            for e in 0..3 {
                let (a, b) = (local[t[e]], local[t[(e + 1) % 3]]);
                set.insert([a.min(b), a.max(b)]);
            }
        }
        TopSurface {
            rest_m: nodes.iter().map(|&i| gel.mesh.points[i]).collect(),
            nodes,
            edges: set.into_iter().collect(),
        }
    }

    /// The top-node rows of a field over all mesh nodes.
    pub fn restrict(&self, field: &[[f64; 3]]) -> Vec<[f64; 3]> {
        self.nodes.iter().map(|&i| field[i]).collect()
    }

    /// A field over all `num_nodes` mesh nodes from its top-node rows (zero elsewhere).
    pub fn extend(&self, top: &[[f64; 3]], num_nodes: usize) -> Vec<[f64; 3]> {
        let mut full = vec![[0.0; 3]; num_nodes];
        for (&i, v) in self.nodes.iter().zip(top) {
            full[i] = *v;
        }
        full
    }
}

/// A regular grid over the top face with the undeformed height of the face at each grid point.
#[derive(Debug, Clone)]
pub struct ContactGrid {
    /// The grid (pixel centres are the sample points).
    pub grid: Grid,
    /// Height of the undeformed top face at each grid point, m (row-major).
    pub height_m: Vec<f64>,
    /// Whether the grid point lies over the top face.
    pub inside: Vec<bool>,
    /// Lowest height of the top face, m.
    pub z_min_m: f64,
}

/// Most points of a contact grid: a 1000 x 1000 raster, 25 um apart on the DIGIT's gel (ten
/// times finer than its nodes), a few hundred MB per field.
const MAX_GRID_POINTS: usize = 1_000_000;

impl ContactGrid {
    /// The grid over `gel`'s top face with spacing `spacing_m`.
    pub fn for_gel(gel: &Gel, spacing_m: f64) -> Result<Self> {
        if !(spacing_m.is_finite() && spacing_m > 0.0) {
            return Err(TactileError::Input(format!(
                "contact grid spacing {spacing_m} m must be positive"
            )));
        }
        let (lo, hi) = gel.top_bounds();
        let (cols, rows) = (
            ((hi[0] - lo[0]) / spacing_m).round().max(1.0),
            ((hi[1] - lo[1]) / spacing_m).round().max(1.0),
        );
        if cols * rows > MAX_GRID_POINTS as f64 {
            return Err(TactileError::Input(format!(
                "contact grid spacing {:.3e} mm makes {cols} x {rows} points over the gel's top face, more than {MAX_GRID_POINTS}: use a coarser spacing (the gel's nodes are about 0.25 mm apart)",
                spacing_m * 1e3
            )));
        }
        let grid = Grid {
            origin_m: lo,
            pixel_m: spacing_m,
            cols: cols as usize,
            rows: rows as usize,
        };
        let z: Vec<f64> = gel.mesh.points.iter().map(|p| p[2]).collect();
        let ones = vec![1.0; gel.num_nodes()];
        let height_m = rasterize(gel, &grid, &z);
        let inside: Vec<bool> = rasterize(gel, &grid, &ones)
            .iter()
            .map(|&c| c > 0.5)
            .collect();
        let z_min_m = gel.top.iter().map(|&i| z[i]).fold(f64::INFINITY, f64::min);
        Ok(ContactGrid {
            grid,
            height_m,
            inside,
            z_min_m,
        })
    }

    /// Contact points of a rigid body whose lowest surface point above (x, y) is
    /// `lower(x, y)` (None where the body does not cover the point): the grid points over the
    /// top face where that surface lies below the undeformed face, at the surface's height.
    pub fn points_below(&self, lower: impl Fn(f64, f64) -> Option<f64>) -> Vec<[f64; 3]> {
        let mut out = Vec::new();
        for r in 0..self.grid.rows {
            for c in 0..self.grid.cols {
                let k = r * self.grid.cols + c;
                if !self.inside[k] {
                    continue;
                }
                let [x, y] = self.grid.center(r, c);
                if let Some(z) = lower(x, y)
                    && z < self.height_m[k]
                {
                    out.push([x, y, z]);
                }
            }
        }
        out
    }

    /// Contact points of a placed indenter (rays cast up from below the gel to its surface).
    pub fn contact_points(&self, placed: &Placed) -> Vec<[f64; 3]> {
        let below = self.z_min_m - 0.05;
        let up = placed.pose.rotation.transpose() * Vector3::z();
        let (lo, hi) = placed.bounds();
        self.points_below(|x, y| {
            if x < lo[0] || x > hi[0] || y < lo[1] || y > hi[1] {
                return None;
            }
            let origin = placed.pose.to_local(&Vector3::new(x, y, below));
            placed
                .indenter
                .ray_local(&origin, &up, 1.0)
                .map(|t| below + t)
        })
    }
}

/// One set-up's samples: fields on the top nodes and the inputs of the NPE.
#[derive(Debug, Clone)]
pub struct SetupSamples {
    /// Set-up name.
    pub name: String,
    /// Indenter name.
    pub indenter: String,
    /// From the unseen-indenter set.
    pub unseen: bool,
    /// Depth of each sample, m.
    pub depth_m: Vec<f64>,
    /// Force of the gel on the indenter, N.
    pub force_n: Vec<[f64; 3]>,
    /// Indenter origin in the sensor frame, m.
    pub translation_m: Vec<[f64; 3]>,
    /// Displacement of the top nodes, m.
    pub displacement_m: Vec<Vec<[f64; 3]>>,
    /// Contact force on the top nodes, N.
    pub nodal_force_n: Vec<Vec<[f64; 3]>>,
    /// Contact points in the sensor frame, m.
    pub points_m: Vec<Vec<[f64; 3]>>,
}

impl SetupSamples {
    /// No samples yet for this set-up and indenter.
    fn empty(setup: &Setup, indenter: &Indenter) -> Self {
        Self {
            name: setup.name.clone(),
            indenter: indenter.name.clone(),
            unseen: setup.unseen,
            depth_m: Vec::new(),
            force_n: Vec::new(),
            translation_m: Vec::new(),
            displacement_m: Vec::new(),
            nodal_force_n: Vec::new(),
            points_m: Vec::new(),
        }
    }
}

/// Per-set-up entry of the manifest.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct SetupEntry {
    /// Set-up name.
    pub name: String,
    /// Indenter name.
    pub indenter: String,
    /// From the unseen-indenter set.
    pub unseen: bool,
    /// Indenter origin over the gel (x, y), m.
    pub xy_m: [f64; 2],
    /// Euler angles, degrees (R = Rz Ry Rx).
    pub euler_deg: [f64; 3],
    /// Samples saved.
    pub samples: usize,
    /// Contact points over all samples.
    pub points: usize,
}

/// The dataset's manifest (`manifest.json`).
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct Manifest {
    /// Format tag.
    pub format: String,
    /// Which model made the fields: `fem`, or `reduced:<folder>` (empty in older data sets:
    /// the FEM).
    #[serde(default)]
    pub model: String,
    /// Gel mesh file.
    pub mesh: String,
    /// Mesh nodes.
    pub mesh_nodes: usize,
    /// Top-face nodes (rows of every nodal array).
    pub top_nodes: usize,
    /// Generation options.
    pub options: DatasetOptions,
    /// Gel Young's modulus, Pa, and Poisson's ratio.
    pub material: [f64; 2],
    /// What each file holds, with shapes and units.
    pub files: std::collections::BTreeMap<String, String>,
    /// Set-ups with samples.
    pub setups: Vec<SetupEntry>,
    /// Set-ups whose FEM stopped before the last depth (their converged steps are kept) or
    /// did not start, with the reason.
    pub stopped: Vec<(String, String)>,
}

const FORMAT: &str = "ocm-tactile-dataset/1";

fn file_docs() -> std::collections::BTreeMap<String, String> {
    [
        (
            "top_nodes.npy",
            "(M, 1) mesh node index of each top-face node",
        ),
        (
            "top_rest_m.npy",
            "(M, 3) rest position of each top node, m, sensor frame",
        ),
        (
            "top_edges.npy",
            "(E, 2) undirected top-triangle edges, indices into the top nodes",
        ),
        (
            "<setup>/depth_m.npy",
            "(S, 1) indentation depth from first touch, m",
        ),
        (
            "<setup>/force_n.npy",
            "(S, 3) force of the gel on the indenter, N",
        ),
        (
            "<setup>/translation_m.npy",
            "(S, 3) indenter origin in the sensor frame, m",
        ),
        (
            "<setup>/displacement_m.npy",
            "(S, 3M) top-node displacement, node-major (x, y, z), m",
        ),
        (
            "<setup>/nodal_force_n.npy",
            "(S, 3M) contact force on the top nodes, node-major, N",
        ),
        (
            "<setup>/points_m.npy",
            "(P, 3) contact points of all samples, sample after sample, m",
        ),
        (
            "<setup>/point_counts.npy",
            "(S, 1) contact points per sample",
        ),
        (
            "<setup>/mask_SSS.png",
            "contact mask of sample SSS (1-based), 8-bit, 255 = contact: -u_z of the top face \
             above 30 um on the 0.0625 mm grid, closed and hole-filled (the masks of \
             `ocm tactile indent`)",
        ),
        (
            "<setup>/mask_stats.npy",
            "(S, 4) per sample: mask area m^2, centroid x and y m (NaN when empty), \
             principal-axis angle rad",
        ),
    ]
    .into_iter()
    .map(|(a, b)| (a.to_string(), b.to_string()))
    .collect()
}

fn write_npy(path: &Path, data: &[f64], rows: usize, cols: usize) -> Result<()> {
    Ok(ocm_fem::npy::write_f64_2d_path(path, data, rows, cols)?)
}

fn flat3(v: &[[f64; 3]]) -> Vec<f64> {
    v.iter().flatten().copied().collect()
}

/// A nodal field of `nodes` x 3 values from an NPY file (`u_NNN.npy`, `f_NNN.npy`); another
/// shape is an error naming the file (a cache of another mesh).
pub(crate) fn read_nodal(p: &Path, nodes: usize) -> Result<Vec<[f64; 3]>> {
    let a = ocm_fem::npy::read_f64_2d(p)?;
    if a.rows != nodes || a.cols != 3 {
        return Err(TactileError::Input(format!(
            "{} is {} x {}, expected {nodes} x 3 (another mesh?)",
            p.display(),
            a.rows,
            a.cols
        )));
    }
    Ok(a.data.chunks(3).map(|c| [c[0], c[1], c[2]]).collect())
}

/// The FEM steps cached in `dir` (`u_NNN.npy`, `f_NNN.npy` over all mesh nodes, as `ocm tactile
/// indent` writes them): the consecutive steps from 1 found there, at most `opts.steps`. The
/// force on the indenter is minus the sum of the nodal contact forces (as the FEM reports it).
/// A `force_depth.csv` beside them must list the same depths, else the cache is refused; each
/// step's contact law is read from it, and whether it records the laws at all is returned
/// beside the steps (every run since the held-plane retry writes them).
fn read_cache(dir: &Path, opts: &DatasetOptions, nodes: usize) -> Result<(Vec<StepOutput>, bool)> {
    let mut out = Vec::new();
    for k in 1..=opts.steps {
        let (u, f) = (
            dir.join(format!("u_{k:03}.npy")),
            dir.join(format!("f_{k:03}.npy")),
        );
        if !(u.exists() && f.exists()) {
            break;
        }
        let read = |p: &Path| read_nodal(p, nodes);
        let contact_force = read(&f)?;
        let mut total = [0.0; 3];
        for v in &contact_force {
            for d in 0..3 {
                total[d] -= v[d];
            }
        }
        out.push(StepOutput {
            step: k,
            depth_m: k as f64 * opts.step_m,
            displacement: read(&u)?,
            contact_force,
            indenter_force_n: total,
            newton_iterations: 0,
            multiplier_updates: 0,
            max_penetration_m: 0.0,
            residual_n: 0.0,
            active_nodes: 0,
            slipping_nodes: 0,
            cuts: 0,
            held_planes: false,
            shifted_solves: 0,
        });
    }
    let mut records_law = false;
    if let Ok(csv) = std::fs::read_to_string(dir.join("force_depth.csv")) {
        let law = csv
            .lines()
            .next()
            .and_then(|h| h.split(',').position(|c| c == "contact_law"));
        records_law = law.is_some();
        for (line, st) in csv.lines().skip(1).zip(&mut out) {
            st.held_planes = law.is_some_and(|j| line.split(',').nth(j) == Some("held_planes"));
            let depth_mm: f64 = line
                .split(',')
                .nth(1)
                .and_then(|v| v.parse().ok())
                .unwrap_or(f64::NAN);
            if !((depth_mm * 1e-3 - st.depth_m).abs() < 1e-9) {
                return Err(TactileError::Input(format!(
                    "{}: step {} is at {depth_mm} mm, the dataset wants {} mm (another protocol?)",
                    dir.join("force_depth.csv").display(),
                    st.step,
                    st.depth_m * 1e3
                )));
            }
        }
    }
    Ok((out, records_law))
}

/// `count` random placements of the `base` set-ups' indenters over `gel` (issue item 6: random
/// positions and rotations): set-up k takes base set-up k mod len, a rotation about z uniform in
/// [0, 360) degrees added to its Euler z angle, and puts the centre of its tip (the part within
/// 0.3 mm of its lowest point) uniformly over the top face shrunk by `margin_m` on each side.
/// Named `r<seed>-<k>-<base>`; deterministic in `seed`.
pub fn random_setups(
    gel: &Gel,
    base: &[Setup],
    count: usize,
    seed: u64,
    margin_m: f64,
) -> Result<Vec<Setup>> {
    use rand::{Rng, SeedableRng};
    if base.is_empty() && count > 0 {
        return Err(TactileError::Input(
            "random placements need at least one base set-up".into(),
        ));
    }
    let (lo, hi) = gel.top_bounds();
    if !(margin_m >= 0.0 && 2.0 * margin_m < (hi[0] - lo[0]).min(hi[1] - lo[1])) {
        return Err(TactileError::Input(format!(
            "placement margin {:.3} mm leaves no room on the {:.2} x {:.2} mm top face",
            margin_m * 1e3,
            (hi[0] - lo[0]) * 1e3,
            (hi[1] - lo[1]) * 1e3
        )));
    }
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
    let mut loaded: Vec<Option<Indenter>> = vec![None; base.len()];
    let mut out = Vec::with_capacity(count);
    for k in 0..count {
        let b = k % base.len();
        if loaded[b].is_none() {
            loaded[b] = Some(Indenter::from_stl(&base[b].stl)?);
        }
        let ind = loaded[b].as_ref().expect("loaded above");
        let mut euler = base[b].placement.euler_deg;
        euler[2] = (euler[2] + rng.random_range(0.0..360.0)) % 360.0;
        let rot = crate::indenter::Pose::rotation_from_degrees(euler);
        let tip = ind.tip_center_xy(&rot, 0.3e-3);
        let target = [
            rng.random_range(lo[0] + margin_m..hi[0] - margin_m),
            rng.random_range(lo[1] + margin_m..hi[1] - margin_m),
        ];
        let mut s = base[b].clone();
        s.name = format!("r{seed}-{k:04}-{}", base[b].name);
        s.placement.xy_m = [target[0] - tip[0], target[1] - tip[1]];
        s.placement.euler_deg = euler;
        out.push(s);
    }
    Ok(out)
}

/// The samples of one set-up: the FEM steps from `cache` (reused when there, else run and
/// written there; a step that does not converge ends the set-up, and the reason is returned
/// beside the steps before it; a partial cache whose table does not record the contact law
/// predates the held-plane retry and is run again) and the contact points at each depth.
pub fn setup_samples(
    gel: &Gel,
    top: &TopSurface,
    cgrid: &ContactGrid,
    setup: &Setup,
    opts: &DatasetOptions,
    cache: &Path,
) -> Result<(SetupSamples, Option<String>)> {
    let indenter = Indenter::from_stl(&setup.stl)?;
    let mut iopts = IndentOptions::protocol(gel.material.young_pa);
    iopts.steps = opts.steps;
    iopts.step_m = opts.step_m;
    let mut run = Indentation::new(&setup.name, gel, &indenter, setup.placement, iopts)?;
    let (mut steps, records_law) = read_cache(cache, opts, gel.num_nodes())?;
    if steps.len() < opts.steps && !records_law {
        // A run that stopped before the held-plane retry existed (or was cut off before its
        // force-depth table) may go further now: it is run again from rest.
        steps.clear();
    }
    let mut stopped = None;
    std::fs::create_dir_all(cache).map_err(|e| TactileError::io(cache, e))?;
    setup.write_json(&cache.join("setup.json"))?;
    if steps.is_empty() {
        let grid = Grid::for_gel(gel);
        let mut rows = Vec::new();
        for k in 1..=opts.steps {
            match run.advance_to(k as f64 * opts.step_m) {
                Ok(st) => {
                    rows.push(StepRow::new(
                        &st,
                        write_step(cache, gel, &grid, &st, false)?,
                    ));
                    steps.push(st);
                }
                Err(e @ TactileError::NoConvergence { .. }) => {
                    stopped = Some(e.to_string());
                    break;
                }
                Err(e) => return Err(e),
            }
        }
        write_force_depth_csv(&cache.join("force_depth.csv"), &rows)?;
    } else if steps.len() < opts.steps {
        stopped = Some(format!(
            "the FEM cache {} holds the first {} of {} steps",
            cache.display(),
            steps.len(),
            opts.steps
        ));
    }
    let mut s = SetupSamples::empty(setup, &indenter);
    for st in &steps {
        let pose = run.pose_at(st.depth_m);
        let placed = Placed {
            indenter: &indenter,
            pose,
        };
        s.depth_m.push(st.depth_m);
        s.force_n.push(st.indenter_force_n);
        s.translation_m.push(pose.translation.into());
        s.displacement_m.push(top.restrict(&st.displacement));
        s.nodal_force_n.push(top.restrict(&st.contact_force));
        s.points_m.push(cgrid.contact_points(&placed));
    }
    Ok((s, stopped))
}

/// Writes one set-up's arrays into `dir`.
pub fn write_setup(dir: &Path, s: &SetupSamples) -> Result<()> {
    std::fs::create_dir_all(dir).map_err(|e| TactileError::io(dir, e))?;
    let n = s.depth_m.len();
    let m = s.displacement_m.first().map_or(0, Vec::len);
    write_npy(&dir.join("depth_m.npy"), &s.depth_m, n, 1)?;
    write_npy(&dir.join("force_n.npy"), &flat3(&s.force_n), n, 3)?;
    write_npy(
        &dir.join("translation_m.npy"),
        &flat3(&s.translation_m),
        n,
        3,
    )?;
    let u: Vec<f64> = s.displacement_m.iter().flat_map(|v| flat3(v)).collect();
    write_npy(&dir.join("displacement_m.npy"), &u, n, 3 * m)?;
    let f: Vec<f64> = s.nodal_force_n.iter().flat_map(|v| flat3(v)).collect();
    write_npy(&dir.join("nodal_force_n.npy"), &f, n, 3 * m)?;
    let p: Vec<f64> = s.points_m.iter().flat_map(|v| flat3(v)).collect();
    write_npy(&dir.join("points_m.npy"), &p, p.len() / 3, 3)?;
    let c: Vec<f64> = s.points_m.iter().map(|v| v.len() as f64).collect();
    write_npy(&dir.join("point_counts.npy"), &c, n, 1)
}

/// Writes the contact mask of every sample of `s` into `dir` (`mask_SSS.png`, 1-based) and
/// their area, centroid and angle (`mask_stats.npy`), from the top-face displacement.
pub fn write_masks(dir: &Path, gel: &Gel, top: &TopSurface, s: &SetupSamples) -> Result<()> {
    let grid = Grid::for_gel(gel);
    let mut stats = Vec::with_capacity(4 * s.displacement_m.len());
    for (k, u) in s.displacement_m.iter().enumerate() {
        let mask = Mask::from_displacement(gel, &grid, &top.extend(u, gel.num_nodes()));
        mask.write_png(dir.join(format!("mask_{:03}.png", k + 1)))?;
        let st = mask.stats();
        stats.extend([st.area_m2, st.centroid_m[0], st.centroid_m[1], st.angle_rad]);
    }
    write_npy(
        &dir.join("mask_stats.npy"),
        &stats,
        s.displacement_m.len(),
        4,
    )
}

/// Builds the dataset of `setups` into `out` (FEM steps cached under `cache/<setup>`),
/// calling `progress(name, index)` before each set-up. A set-up whose FEM stops early keeps its
/// converged depths and is listed in the manifest's `stopped` with the reason.
pub fn build(
    gel: &Gel,
    mesh_name: &str,
    setups: &[Setup],
    opts: &DatasetOptions,
    cache: &Path,
    out: &Path,
    progress: impl FnMut(&str, usize),
) -> Result<Manifest> {
    let top = TopSurface::from_gel(gel);
    let cgrid = ContactGrid::for_gel(gel, opts.grid_spacing_m)?;
    build_with(
        gel,
        mesh_name,
        "fem",
        setups,
        opts,
        out,
        progress,
        |setup| {
            let (s, stopped) =
                setup_samples(gel, &top, &cgrid, setup, opts, &cache.join(&setup.name))?;
            Ok((s, stopped, false))
        },
    )
}

/// The samples of one set-up from the reduced model: the same depths and arrays as the FEM's
/// (frictionless, warm-started from depth to depth). Its solve always returns, so nothing
/// stops early. With `enrich`, the basis first grows by the footprint modes of this placement
/// at its deepest pose ([`crate::reduced::placement_model`]).
#[allow(clippy::too_many_arguments)]
pub fn setup_samples_reduced(
    gel: &Gel,
    top: &TopSurface,
    cgrid: &ContactGrid,
    setup: &Setup,
    opts: &DatasetOptions,
    model: &crate::reduced::ReducedModel,
    options: crate::reduced::ReducedOptions,
    enrich: Option<crate::reduced::Enrichment>,
) -> Result<SetupSamples> {
    let indenter = Indenter::from_stl(&setup.stl)?;
    // Footprint modes of this placement at its deepest pose (README, "The worst held-out frame").
    let local = match enrich {
        Some(e) => {
            let approach =
                crate::indent::Approach::new(&setup.name, gel, &indenter, setup.placement)?;
            let deepest = opts.steps as f64 * opts.step_m;
            Some(crate::reduced::placement_model(
                model, e, gel, &indenter, &approach, deepest,
            )?)
        }
        None => None,
    };
    let model = local.as_ref().unwrap_or(model);
    let mut run = crate::reduced::ReducedIndentation::new(
        &setup.name,
        model,
        gel,
        &indenter,
        setup.placement,
        options,
    )?;
    let mut s = SetupSamples::empty(setup, &indenter);
    for k in 1..=opts.steps {
        let d = k as f64 * opts.step_m;
        let f = run.advance_to(d)?;
        let pose = run.pose_at(d);
        let placed = Placed {
            indenter: &indenter,
            pose,
        };
        s.depth_m.push(d);
        s.force_n.push(f.indenter_force_n);
        s.translation_m.push(pose.translation.into());
        s.displacement_m
            .push(model.displacement_of(&top.nodes, &f.q));
        s.nodal_force_n
            .push(f.nodal_force(&top.nodes, gel.num_nodes()));
        s.points_m.push(cgrid.contact_points(&placed));
    }
    Ok(s)
}

/// Builds the data set of `setups` into `out` with the reduced model `model` (saved in
/// `model_dir`). Resumable: a set-up whose arrays are already in `out` is read back, not
/// recomputed, so an interrupted run continues where it stopped. With `enrich`, each set-up's
/// basis grows by its footprint modes, and the manifest's model says which loads.
#[allow(clippy::too_many_arguments)]
pub fn build_reduced(
    gel: &Gel,
    mesh_name: &str,
    setups: &[Setup],
    opts: &DatasetOptions,
    model: &crate::reduced::ReducedModel,
    model_dir: &Path,
    options: crate::reduced::ReducedOptions,
    enrich: Option<crate::reduced::Enrichment>,
    out: &Path,
    progress: impl FnMut(&str, usize),
) -> Result<Manifest> {
    model.check_gel(gel)?;
    let top = TopSurface::from_gel(gel);
    let cgrid = ContactGrid::for_gel(gel, opts.grid_spacing_m)?;
    let tag = match enrich {
        Some(e) => format!(
            "reduced:{}+footprint:{}",
            model_dir.display(),
            e.loads.join(",")
        ),
        None => format!("reduced:{}", model_dir.display()),
    };
    build_with(gel, mesh_name, &tag, setups, opts, out, progress, |setup| {
        let dir = out.join(&setup.name);
        // `write_setup` writes point_counts.npy last and `write_masks` mask_stats.npy after
        // it: with both there the set-up is complete; with the arrays alone only its masks
        // are missing (an interrupted run, or a data set from before the masks).
        if dir.join("point_counts.npy").is_file() {
            let indenter = setup
                .stl
                .file_stem()
                .map(|n| n.to_string_lossy().into_owned())
                .unwrap_or_default();
            let s = read_setup_arrays(
                &dir,
                &setup.name,
                &indenter,
                setup.unseen,
                top.nodes.len(),
                None,
            )?;
            let complete = dir.join("mask_stats.npy").is_file();
            return Ok((s, None, complete));
        }
        let s = setup_samples_reduced(gel, &top, &cgrid, setup, opts, model, options, enrich)?;
        Ok((s, None, false))
    })
}

/// An `f64` array of `cols` columns (and `rows` rows, when given) read from `p`; a shape that
/// disagrees or a non-finite value is an error naming the file, and the row and column.
fn read_checked(p: &Path, cols: usize, rows: Option<usize>) -> Result<Vec<f64>> {
    let a = ocm_fem::npy::read_f64_2d(p)?;
    if a.cols != cols || rows.is_some_and(|r| r != a.rows) {
        return Err(TactileError::Input(format!(
            "{}: {} x {}, expected {} x {cols} (another mesh, or an interrupted write?)",
            p.display(),
            a.rows,
            a.cols,
            rows.map_or("N".to_string(), |r| r.to_string()),
        )));
    }
    // a NaN would surface only as a diverged training, far from its cause
    if let Some(k) = a.data.iter().position(|v| !v.is_finite()) {
        return Err(TactileError::Input(format!(
            "{}: row {}, column {} is {}; a data set holds finite values only",
            p.display(),
            k / cols.max(1),
            k % cols.max(1),
            a.data[k]
        )));
    }
    Ok(a.data)
}

/// One set-up's arrays read back from `dir` (as [`write_setup`] wrote them), for `m` top
/// nodes; with `samples`, each per-sample array must hold that many rows. A shape that
/// disagrees, point counts that do not add up, or a non-finite value is an error naming the
/// file (and the row and column of the value).
fn read_setup_arrays(
    dir: &Path,
    name: &str,
    indenter: &str,
    unseen: bool,
    m: usize,
    samples: Option<usize>,
) -> Result<SetupSamples> {
    let read =
        |file: &str, cols: usize, rows: Option<usize>| read_checked(&dir.join(file), cols, rows);
    let rows3 =
        |v: Vec<f64>| -> Vec<[f64; 3]> { v.chunks(3).map(|c| [c[0], c[1], c[2]]).collect() };
    let depth_m = read("depth_m.npy", 1, samples)?;
    // every other per-sample array has as many rows as the depths
    let n = Some(depth_m.len());
    let counts = read("point_counts.npy", 1, n)?;
    let pts = rows3(read("points_m.npy", 3, None)?);
    let total: f64 = counts.iter().sum();
    if counts.iter().any(|c| *c < 0.0 || c.fract() != 0.0) || total as usize != pts.len() {
        return Err(TactileError::Input(format!(
            "{}: {} points but the counts in point_counts.npy add to {total}",
            dir.join("points_m.npy").display(),
            pts.len()
        )));
    }
    let mut points_m = Vec::new();
    let mut at = 0;
    for &c in &counts {
        points_m.push(pts[at..at + c as usize].to_vec());
        at += c as usize;
    }
    let fields = |file: &str| -> Result<Vec<Vec<[f64; 3]>>> {
        Ok(read(file, 3 * m, n)?
            .chunks(3 * m)
            .map(|r| rows3(r.to_vec()))
            .collect())
    };
    Ok(SetupSamples {
        name: name.to_string(),
        indenter: indenter.to_string(),
        unseen,
        force_n: rows3(read("force_n.npy", 3, n)?),
        translation_m: rows3(read("translation_m.npy", 3, n)?),
        displacement_m: fields("displacement_m.npy")?,
        nodal_force_n: fields("nodal_force_n.npy")?,
        depth_m,
        points_m,
    })
}

/// The data-set loop shared by the FEM and the reduced model: `samples` yields one set-up's
/// samples, why it stopped early (if it did) and whether its files in `out` are already
/// complete (then they are not written again).
#[allow(clippy::too_many_arguments)]
fn build_with(
    gel: &Gel,
    mesh_name: &str,
    model: &str,
    setups: &[Setup],
    opts: &DatasetOptions,
    out: &Path,
    mut progress: impl FnMut(&str, usize),
    mut samples: impl FnMut(&Setup) -> Result<(SetupSamples, Option<String>, bool)>,
) -> Result<Manifest> {
    std::fs::create_dir_all(out).map_err(|e| TactileError::io(out, e))?;
    let top = TopSurface::from_gel(gel);
    let idx: Vec<f64> = top.nodes.iter().map(|&i| i as f64).collect();
    write_npy(&out.join("top_nodes.npy"), &idx, idx.len(), 1)?;
    write_npy(
        &out.join("top_rest_m.npy"),
        &flat3(&top.rest_m),
        top.rest_m.len(),
        3,
    )?;
    let e: Vec<f64> = top.edges.iter().flatten().map(|&i| i as f64).collect();
    write_npy(&out.join("top_edges.npy"), &e, top.edges.len(), 2)?;
    let mut manifest = Manifest {
        format: FORMAT.into(),
        model: model.into(),
        mesh: mesh_name.into(),
        mesh_nodes: gel.num_nodes(),
        top_nodes: top.nodes.len(),
        options: *opts,
        material: [gel.material.young_pa, gel.material.poisson],
        files: file_docs(),
        setups: Vec::new(),
        stopped: Vec::new(),
    };
    for (k, setup) in setups.iter().enumerate() {
        progress(&setup.name, k);
        match samples(setup) {
            Ok((s, stopped, complete)) => {
                if let Some(why) = stopped {
                    manifest.stopped.push((setup.name.clone(), why));
                }
                if s.depth_m.is_empty() {
                    continue;
                }
                if !complete {
                    let dir = out.join(&setup.name);
                    write_setup(&dir, &s)?;
                    write_masks(&dir, gel, &top, &s)?;
                }
                manifest.setups.push(SetupEntry {
                    name: s.name.clone(),
                    indenter: s.indenter.clone(),
                    unseen: s.unseen,
                    xy_m: setup.placement.xy_m,
                    euler_deg: setup.placement.euler_deg,
                    samples: s.depth_m.len(),
                    points: s.points_m.iter().map(Vec::len).sum(),
                });
            }
            Err(e @ TactileError::OffGel { .. }) => {
                manifest.stopped.push((setup.name.clone(), e.to_string()));
            }
            Err(e) => return Err(e),
        }
        let text = serde_json::to_string_pretty(&manifest)
            .map_err(|e| TactileError::Input(format!("manifest: {e}")))?;
        let path = out.join("manifest.json");
        std::fs::write(&path, text).map_err(|e| TactileError::io(&path, e))?;
    }
    Ok(manifest)
}

/// A dataset read back: the top-face graph and every set-up's samples.
#[derive(Debug, Clone)]
pub struct Dataset {
    /// The folder.
    pub dir: PathBuf,
    /// Its manifest.
    pub manifest: Manifest,
    /// Rest positions of the top nodes, m.
    pub top_rest_m: Vec<[f64; 3]>,
    /// Top-face edges.
    pub top_edges: Vec<[usize; 2]>,
    /// Samples per set-up, in manifest order.
    pub setups: Vec<SetupSamples>,
}

impl Dataset {
    /// Reads a dataset written by [`build`]; a missing file or a shape that disagrees with the
    /// manifest is an error naming the file.
    pub fn read(dir: &Path) -> Result<Self> {
        let mpath = dir.join("manifest.json");
        let text = std::fs::read_to_string(&mpath).map_err(|e| TactileError::io(&mpath, e))?;
        let manifest: Manifest = serde_json::from_str(&text)
            .map_err(|e| TactileError::Input(format!("{}: {e}", mpath.display())))?;
        if manifest.format != FORMAT {
            return Err(TactileError::Input(format!(
                "{}: format '{}', expected '{FORMAT}'",
                mpath.display(),
                manifest.format
            )));
        }
        let m = manifest.top_nodes;
        let top_rest_m: Vec<[f64; 3]> = read_checked(&dir.join("top_rest_m.npy"), 3, Some(m))?
            .chunks(3)
            .map(|c| [c[0], c[1], c[2]])
            .collect();
        let top_edges = read_checked(&dir.join("top_edges.npy"), 2, None)?
            .chunks(2)
            .map(|c| [c[0] as usize, c[1] as usize])
            .collect::<Vec<_>>();
        if let Some(e) = top_edges.iter().find(|e| e[0] >= m || e[1] >= m) {
            return Err(TactileError::Input(format!(
                "{}: edge {e:?} names a node beyond the {m} top nodes",
                dir.join("top_edges.npy").display()
            )));
        }
        let setups = manifest
            .setups
            .iter()
            .map(|e| {
                read_setup_arrays(
                    &dir.join(&e.name),
                    &e.name,
                    &e.indenter,
                    e.unseen,
                    m,
                    Some(e.samples),
                )
            })
            .collect::<Result<Vec<_>>>()?;
        Ok(Dataset {
            dir: dir.to_path_buf(),
            manifest,
            top_rest_m,
            top_edges,
            setups,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::gel::GelMaterial;
    use crate::indenter::Pose;
    use nalgebra::Matrix3;

    /// A flat 6 x 4 x 2 mm block of tets (top at z = 2 mm), base fixed.
    fn block() -> Gel {
        let mesh = ocm_fem::mesh::generate::box_mesh([12, 8, 2], [6e-3, 4e-3, 2e-3]);
        Gel::from_mesh(mesh, GelMaterial::default(), 1e-9).unwrap()
    }

    /// Lowest point at the origin, centre at (0, 0, r).
    fn sphere(radius: f64) -> Indenter {
        crate::shapes::sphere(radius, 48).unwrap()
    }

    #[test]
    fn top_surface_graph_of_a_block() {
        let gel = block();
        let top = TopSurface::from_gel(&gel);
        assert_eq!(top.nodes.len(), 13 * 9);
        assert!(top.rest_m.iter().all(|p| (p[2] - 2e-3).abs() < 1e-12));
        // A structured grid of 12 x 8 squares, each split into two triangles: horizontal,
        // vertical and one diagonal per square.
        assert_eq!(top.edges.len(), 12 * 9 + 13 * 8 + 12 * 8);
        let f: Vec<[f64; 3]> = (0..gel.num_nodes()).map(|i| [i as f64, 0.0, 0.0]).collect();
        let back = top.extend(&top.restrict(&f), gel.num_nodes());
        for &i in &top.nodes {
            assert_eq!(back[i], f[i]);
        }
    }

    /// A sphere of radius R pressed d into a flat face: the contact points are the grid points
    /// within sqrt(2 R d - d^2) of the axis, each on the sphere's lower surface, the deepest
    /// d below the face.
    #[test]
    fn contact_points_of_a_sphere_match_the_cap() {
        let gel = block();
        let spacing = 0.1e-3;
        let cg = ContactGrid::for_gel(&gel, spacing).unwrap();
        let r = 1.5e-3;
        let ind = sphere(r);
        let (cx, cy, d) = (3.0e-3, 2.0e-3, 0.2e-3);
        let placed = Placed {
            indenter: &ind,
            pose: Pose {
                rotation: Matrix3::identity(),
                translation: Vector3::new(cx, cy, 2e-3 - d),
            },
        };
        let pts = cg.contact_points(&placed);
        let a = (2.0 * r * d - d * d).sqrt();
        let mut expect = 0;
        for row in 0..cg.grid.rows {
            for col in 0..cg.grid.cols {
                let [x, y] = cg.grid.center(row, col);
                // The polygonal sphere lies inside the true one: keep clear of the rim.
                let rho = ((x - cx).powi(2) + (y - cy).powi(2)).sqrt();
                if rho < a - 0.02e-3 {
                    expect += 1;
                }
            }
        }
        assert!(
            pts.len() as f64 >= expect as f64 * 0.97 && pts.len() as f64 <= expect as f64 * 1.1,
            "{} points, about {expect} expected",
            pts.len()
        );
        let mut deepest: f64 = 0.0;
        for p in &pts {
            let rho2 = (p[0] - cx).powi(2) + (p[1] - cy).powi(2);
            let z_true = 2e-3 - d + r - (r * r - rho2).max(0.0).sqrt();
            // Chord error of the graded 48-band tessellation of a 1.5 mm sphere: below 10 um.
            assert!((p[2] - z_true).abs() < 10e-6, "{p:?} vs z {z_true}");
            assert!(p[2] < 2e-3);
            deepest = deepest.max(2e-3 - p[2]);
        }
        assert!((deepest - d).abs() < 5e-6, "deepest {deepest} vs depth {d}");
        // Lifted clear of the face: no contact points.
        let lifted = Placed {
            indenter: &ind,
            pose: Pose {
                rotation: Matrix3::identity(),
                translation: Vector3::new(cx, cy, 2e-3 + 1e-4),
            },
        };
        assert!(cg.contact_points(&lifted).is_empty());
        // Beside the gel: no contact points either.
        let beside = Placed {
            indenter: &ind,
            pose: Pose {
                rotation: Matrix3::identity(),
                translation: Vector3::new(20e-3, cy, 2e-3 - d),
            },
        };
        assert!(cg.contact_points(&beside).is_empty());
    }

    /// A fresh scratch folder for one test.
    fn scratch(tag: &str) -> PathBuf {
        let d = std::env::temp_dir().join(format!("ocm-dataset-{tag}-{}", std::process::id()));
        std::fs::remove_dir_all(&d).ok();
        std::fs::create_dir_all(&d).unwrap();
        d
    }

    /// A FEM cache that stopped short is reused as stopped when its table records the contact
    /// law, and run again in full when it predates that column (written before the held-plane
    /// retry, which may take it further).
    #[test]
    fn partial_caches_before_the_held_plane_retry_are_run_again() {
        let gel = block();
        let dir = scratch("partial");
        let stl = sphere_stl(&dir, "ball", 1.5e-3, 0.0, 0.0);
        let setup = setup_of("a", stl, [3e-3, 2e-3], [0.0; 3]);
        let opts = DatasetOptions {
            steps: 3,
            step_m: 50e-6,
            grid_spacing_m: 0.25e-3,
        };
        let top = TopSurface::from_gel(&gel);
        let cgrid = ContactGrid::for_gel(&gel, opts.grid_spacing_m).unwrap();
        let cache = dir.join("fem").join("a");
        let samples = || setup_samples(&gel, &top, &cgrid, &setup, &opts, &cache).unwrap();
        let (full, stopped) = samples();
        assert_eq!((full.depth_m.len(), stopped), (3, None));
        // cut the cache back to two steps, as a run that stopped there leaves it
        let csv_path = cache.join("force_depth.csv");
        let csv = std::fs::read_to_string(&csv_path).unwrap();
        let two: Vec<&str> = csv.lines().take(3).collect();
        std::fs::remove_file(cache.join("u_003.npy")).unwrap();
        std::fs::remove_file(cache.join("f_003.npy")).unwrap();
        std::fs::write(&csv_path, two.join("\n") + "\n").unwrap();
        let (s, stopped) = samples();
        assert_eq!(s.depth_m.len(), 2);
        assert!(stopped.unwrap().contains("holds the first 2 of 3 steps"));
        // the same cut without the contact-law column: run again, to the same fields
        let law = two[0].split(',').position(|c| c == "contact_law").unwrap();
        let old: Vec<String> = two
            .iter()
            .map(|l| {
                let mut cols: Vec<&str> = l.split(',').collect();
                cols.remove(law);
                cols.join(",")
            })
            .collect();
        std::fs::remove_file(cache.join("u_003.npy")).ok();
        std::fs::write(&csv_path, old.join("\n") + "\n").unwrap();
        let (again, stopped) = samples();
        assert_eq!((again.depth_m.len(), stopped), (3, None));
        assert_eq!(again.displacement_m, full.displacement_m);
        assert!(read_cache(&cache, &opts, gel.num_nodes()).unwrap().1);
    }

    /// Writes a sphere of radius `r` whose lowest point lies at `(ox, oy, 0)` as a binary STL
    /// (metres: the part is smaller than 0.2) and returns its path.
    fn sphere_stl(dir: &Path, name: &str, r: f64, ox: f64, oy: f64) -> PathBuf {
        let (pts, tris) = crate::shapes::sphere_surface(r, 24);
        let mesh = ocm_fem::mesh::Mesh {
            points: pts.iter().map(|p| [p[0] + ox, p[1] + oy, p[2]]).collect(),
            triangles: tris,
            ..Default::default()
        };
        let path = dir.join(format!("{name}.stl"));
        let mut f = std::fs::File::create(&path).unwrap();
        ocm_fem::mesh::stl::write_binary(&mut f, &mesh).unwrap();
        path
    }

    fn setup_of(name: &str, stl: PathBuf, xy: [f64; 2], euler: [f64; 3]) -> Setup {
        Setup {
            name: name.into(),
            stl,
            placement: crate::indent::Placement {
                xy_m: xy,
                euler_deg: euler,
            },
            unseen: false,
        }
    }

    /// Random placements: the same seed gives the same set-ups, another seed others; set-up k
    /// takes base k mod 2 and is named r<seed>-<k>-<base>; the tip's centre (the sphere's
    /// lowest point, 1 mm off the STL origin, so the rotation moves it) lands uniformly inside
    /// the top face less the margin; only the Euler z angle changes. Bad margins and an empty
    /// base are errors.
    #[test]
    fn random_setups_are_seeded_and_stay_on_the_gel() {
        let gel = block();
        let dir = scratch("random");
        let base = [
            setup_of(
                "ball",
                sphere_stl(&dir, "ball", 1e-3, 1e-3, 0.0),
                [3e-3, 2e-3],
                [0.0, 0.0, 30.0],
            ),
            setup_of(
                "pea",
                sphere_stl(&dir, "pea", 0.5e-3, 0.0, -0.5e-3),
                [1e-3, 1e-3],
                [5.0, 0.0, 0.0],
            ),
        ];
        let margin = 0.5e-3;
        let a = random_setups(&gel, &base, 40, 7, margin).unwrap();
        let b = random_setups(&gel, &base, 40, 7, margin).unwrap();
        let c = random_setups(&gel, &base, 40, 8, margin).unwrap();
        assert_eq!(a.len(), 40);
        for (x, y) in a.iter().zip(&b) {
            assert_eq!(x.name, y.name);
            assert_eq!(x.placement, y.placement);
        }
        assert!(
            a.iter()
                .zip(&c)
                .all(|(x, y)| x.placement.xy_m != y.placement.xy_m)
        );
        let (lo, hi) = gel.top_bounds();
        let mut tips = vec![];
        for (k, s) in a.iter().enumerate() {
            let bs = &base[k % 2];
            assert_eq!(s.name, format!("r7-{k:04}-{}", bs.name));
            assert_eq!(s.stl, bs.stl);
            let e = s.placement.euler_deg;
            assert_eq!(e[..2], bs.placement.euler_deg[..2]);
            assert!((0.0..360.0).contains(&e[2]));
            // Below the placed sphere's centre lies its lowest point: the STL's centre turned.
            let rot = crate::indenter::Pose::rotation_from_degrees(e);
            let off = if k % 2 == 0 {
                Vector3::new(1e-3, 0.0, 1e-3)
            } else {
                Vector3::new(0.0, -0.5e-3, 0.5e-3)
            };
            let t = rot * off;
            let tip = [s.placement.xy_m[0] + t.x, s.placement.xy_m[1] + t.y];
            for d in 0..2 {
                assert!(
                    tip[d] >= lo[d] + margin - 5e-5 && tip[d] <= hi[d] - margin + 5e-5,
                    "{}: tip {tip:?}",
                    s.name
                );
            }
            tips.push(tip);
        }
        // Uniform over the face: the tips spread over most of it.
        for d in 0..2 {
            let (mn, mx) = tips
                .iter()
                .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), t| {
                    (a.min(t[d]), b.max(t[d]))
                });
            assert!(mx - mn > 0.6 * (hi[d] - lo[d] - 2.0 * margin), "axis {d}");
        }
        assert!(random_setups(&gel, &base, 3, 7, 2.5e-3).is_err());
        assert!(random_setups(&gel, &base, 3, 7, -1e-3).is_err());
        assert!(random_setups(&gel, &[], 3, 7, margin).is_err());
        std::fs::remove_dir_all(&dir).ok();
    }

    /// `build_reduced` resumes: a set-up whose arrays and masks are in the output folder is
    /// read back, not recomputed (a marker put into its files survives the rerun); a set-up
    /// whose folder is gone is recomputed to the same arrays; a set-up with arrays but no
    /// masks gets its masks. The masks agree with their statistics and sit under the sphere.
    #[test]
    fn build_reduced_resumes_and_writes_masks() {
        use crate::reduced::{ReducedModel, ReducedOptions};
        let gel = block();
        let dir = scratch("resume");
        let stl = sphere_stl(&dir, "ball", 1.5e-3, 0.0, 0.0);
        let setups = [
            setup_of("a", stl.clone(), [3e-3, 2e-3], [0.0; 3]),
            setup_of("b", stl.clone(), [2.5e-3, 2.2e-3], [0.0; 3]),
        ];
        // The basis: the FEM of the ball at both placements.
        let ind = Indenter::from_stl(&stl).unwrap();
        let mut o = IndentOptions::protocol(gel.material.young_pa);
        o.steps = 4;
        o.step_m = 50e-6;
        let mut fields: Vec<Vec<[f64; 3]>> = vec![];
        for s in &setups {
            let mut run = Indentation::new("fem", &gel, &ind, s.placement, o).unwrap();
            fields.extend(run.run(|_| {}).unwrap().into_iter().map(|s| s.displacement));
        }
        let pod = ocm_mor::pod::PodOptions {
            truncation: ocm_mor::pod::Truncation::Rank(8),
            oversampling: 4,
            power_iterations: 2,
            seed: 1,
        };
        let model = ReducedModel::build(&gel, "block", &fields, vec!["fem".into()], &pod).unwrap();
        let opts = DatasetOptions {
            steps: 3,
            step_m: 50e-6,
            grid_spacing_m: 0.25e-3,
        };
        let ro = ReducedOptions::for_modulus(gel.material.young_pa);
        let out = dir.join("data");
        let try_run = || {
            build_reduced(
                &gel,
                "block",
                &setups,
                &opts,
                &model,
                &dir,
                ro,
                None,
                &out,
                |_, _| {},
            )
        };
        let run = || try_run().unwrap();
        let first = run();
        assert_eq!(first.setups.len(), 2);
        let d1 = Dataset::read(&out).unwrap();
        // Masks: one PNG per sample, its pixel count is the stats' area, and the deepest mask
        // is centred under the ball.
        let grid = Grid::for_gel(&gel);
        for (e, s) in first.setups.iter().zip(&setups) {
            let sd = out.join(&e.name);
            let stats = ocm_fem::npy::read_f64_2d(sd.join("mask_stats.npy")).unwrap();
            assert_eq!((stats.rows, stats.cols), (3, 4));
            for k in 0..3 {
                let png =
                    crate::image_io::read_gray(sd.join(format!("mask_{:03}.png", k + 1))).unwrap();
                assert_eq!((png.rows, png.cols), (grid.rows, grid.cols));
                let set = png.pixels.iter().filter(|&&v| v > 127.0).count() as f64;
                let area = stats.data[4 * k];
                assert!((set * grid.pixel_m * grid.pixel_m - area).abs() < 1e-15);
            }
            let last = &stats.data[8..12];
            assert!(last[0] > 0.0);
            for d in 0..2 {
                assert!(
                    (last[1 + d] - s.placement.xy_m[d]).abs() < 0.15e-3,
                    "{}: centroid {last:?}",
                    e.name
                );
            }
        }
        // Interrupted: b's folder is gone; a, complete, carries a marker in its forces.
        let force_a = out.join("a").join("force_n.npy");
        let marked: Vec<f64> = d1.setups[0]
            .force_n
            .iter()
            .flatten()
            .map(|f| 2.0 * f)
            .collect();
        write_npy(&force_a, &marked, 3, 3).unwrap();
        std::fs::remove_dir_all(out.join("b")).unwrap();
        let second = run();
        let d2 = Dataset::read(&out).unwrap();
        assert_eq!(
            serde_json::to_string(&first.setups).unwrap(),
            serde_json::to_string(&second.setups).unwrap()
        );
        let f2: Vec<f64> = d2.setups[0].force_n.iter().flatten().copied().collect();
        assert_eq!(f2, marked, "a finished set-up is read back, not recomputed");
        let mut poisoned = marked.clone();
        poisoned[5] = f64::NAN;
        write_npy(&force_a, &poisoned, 3, 3).unwrap();
        let e = Dataset::read(&out).unwrap_err().to_string();
        assert!(e.contains("force_n.npy: row 1, column 2 is NaN"), "{e}");
        // resuming reads a finished set-up back with the same checks
        let e = try_run().unwrap_err().to_string();
        assert!(e.contains("force_n.npy: row 1, column 2 is NaN"), "{e}");
        write_npy(&force_a, &marked, 3, 3).unwrap();
        // point counts that do not add up to the points are refused, not cut short
        let counts_a = out.join("a").join("point_counts.npy");
        let counts = ocm_fem::npy::read_f64_2d(&counts_a).unwrap().data;
        let mut more = counts.clone();
        more[2] += 1.0;
        write_npy(&counts_a, &more, 3, 1).unwrap();
        for e in [
            try_run().unwrap_err().to_string(),
            Dataset::read(&out).unwrap_err().to_string(),
        ] {
            assert!(e.contains("points_m.npy") && e.contains("add to"), "{e}");
        }
        write_npy(&counts_a, &counts, 3, 1).unwrap();
        let (b1, b2) = (&d1.setups[1], &d2.setups[1]);
        assert_eq!(b1.displacement_m, b2.displacement_m);
        assert_eq!(b1.force_n, b2.force_n);
        assert_eq!(b1.points_m, b2.points_m);
        assert!(out.join("b").join("mask_003.png").is_file());
        // Arrays without masks: the masks are written, the arrays read back.
        std::fs::remove_file(out.join("a").join("mask_stats.npy")).unwrap();
        std::fs::remove_file(out.join("a").join("mask_002.png")).unwrap();
        run();
        assert!(out.join("a").join("mask_002.png").is_file());
        assert!(out.join("a").join("mask_stats.npy").is_file());
        let f3 = ocm_fem::npy::read_f64_2d(&force_a).unwrap().data;
        assert_eq!(f3, marked);

        // With footprint modes: the manifest names them, and each set-up's fields are the
        // reduced solve on the basis grown at that placement's deepest pose.
        let rest = crate::reduced::RestStiffness::new(&gel).unwrap();
        let loads = crate::reduced::DEFAULT_FOOTPRINT_LOADS;
        let enrich = crate::reduced::Enrichment {
            rest: &rest,
            loads: &loads,
        };
        let out_e = dir.join("enriched");
        let me = build_reduced(
            &gel,
            "block",
            &setups,
            &opts,
            &model,
            &dir,
            ro,
            Some(enrich),
            &out_e,
            |_, _| {},
        )
        .unwrap();
        assert!(me.model.ends_with("+footprint:foot,rim"), "{}", me.model);
        let de = Dataset::read(&out_e).unwrap();
        let s = &setups[1];
        let approach = crate::indent::Approach::new("b", &gel, &ind, s.placement).unwrap();
        let em =
            crate::reduced::placement_model(&model, enrich, &gel, &ind, &approach, 150e-6).unwrap();
        assert!(em.rank() > model.rank());
        let mut direct =
            crate::reduced::ReducedIndentation::new("b", &em, &gel, &ind, s.placement, ro).unwrap();
        let top = TopSurface::from_gel(&gel);
        for k in 0..3 {
            let f = direct.advance_to((k + 1) as f64 * 50e-6).unwrap();
            assert_eq!(
                de.setups[1].displacement_m[k],
                em.displacement_of(&top.nodes, &f.q)
            );
        }
        assert_ne!(de.setups[1].displacement_m, b2.displacement_m);
        std::fs::remove_dir_all(&dir).ok();
    }

    #[test]
    fn bad_spacing_is_an_error() {
        let gel = block();
        assert!(ContactGrid::for_gel(&gel, 0.0).is_err());
        assert!(ContactGrid::for_gel(&gel, f64::NAN).is_err());
        // a spacing fine enough to overflow the raster's size is refused, naming it
        for spacing_m in [1e-12, 1e-7] {
            let e = ContactGrid::for_gel(&gel, spacing_m)
                .unwrap_err()
                .to_string();
            assert!(e.contains("more than 1000000"), "{e}");
        }
    }
}
