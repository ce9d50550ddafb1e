//! The reduced tactile model (dissertation Ch.5.4.2, eq 5.1-5.5): a POD basis of the gel's
//! displacement fields over many FEM indentations and a reduced static solve with contact.
//!
//! Basis: the snapshots u (3N, whole gel, metres) of full-FEM indentations go through the
//! workspace's randomized SVD (`ocm_mor::pod::pod`); u ~ Phi q (eq 5.4) with r modes.
//! Stiffness: eq 5.5 with the nonlinear operator K(u) of eq 5.1 taken at rest, K_r = Phi^T K_0 Phi
//! (r x r, computed once from the fem tangent). [`ReducedIndentation::with_nonlinear`] replaces
//! K_r q by the gel's Neo-Hookean force hyper-reduced by ECSW ([`crate::hyper`]); the figures in
//! the README say what the linearisation costs against the Neo-Hookean FEM.
//!
//! Contact (frictionless, as the data sets' FEM): the same node-to-surface law as [`crate::contact`],
//! p_i = max(0, lambda_i - k_i g_i) with k_i = eps_n A_i, on the gel's surface nodes. Each pass
//! queries the signed distances g_i and normals n_i (parry) at the current q and linearises
//! g_i(q') = g_i + a_i . (q' - q) with a_i = Phi_i^T n_i; the penalty problem is then solved
//! exactly by a semismooth Newton on the active set, (K_r + sum_A k_i a_i a_i^T) q' =
//! sum_A a_i (lambda_i - k_i g_i + k_i a_i . q). Passes repeat until q settles, then the
//! augmented-Lagrangian multipliers are updated until the penetration is within the tolerance
//! (or the update budget is spent: the frame reports its penetration).
//! A node is queried only when the 1-Lipschitz bound on its signed distance (last queried gap
//! minus how far it and the indenter moved since) could bring it within reach of contact.

use crate::gel::Gel;
use crate::indent::{Approach, Placement};
use crate::indenter::{Indenter, Placed, Pose};
use crate::{Result, TactileError};
use faer::Mat;
use nalgebra::{DMatrix, DVector, Vector3};
use ocm_fem::model::{Loads, Pattern};
use ocm_fem::solve::linear::SparseSolver;
use ocm_mor::pod::{PodOptions, pod};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use std::path::Path;

const FORMAT: &str = "ocm-tactile-reduced/1";

/// What a saved reduced model was built from.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ReducedInfo {
    /// Format tag.
    pub format: String,
    /// Gel mesh file name.
    pub mesh: String,
    /// Mesh nodes (3N rows of the modes).
    pub mesh_nodes: usize,
    /// Modes kept.
    pub rank: usize,
    /// Gel Young's modulus, Pa, and Poisson's ratio.
    pub material: [f64; 2],
    /// Snapshots in the POD.
    pub snapshots: usize,
    /// Where the snapshots came from (FEM folders or set-up names).
    pub sources: Vec<String>,
    /// Fraction of the snapshot energy the modes capture.
    pub captured_energy: f64,
}

/// A POD basis of the gel with its reduced stiffness.
#[derive(Debug, Clone)]
pub struct ReducedModel {
    /// Description.
    pub info: ReducedInfo,
    /// Modes, row-major 3N x r: row 3 i + d is DOF d of node i.
    pub modes: Vec<f64>,
    /// K_r = Phi^T K_0 Phi, r x r.
    pub stiffness: DMatrix<f64>,
    /// Singular values of the snapshot matrix (all that were computed), m.
    pub singular_values: Vec<f64>,
}

impl ReducedModel {
    /// Modes kept.
    pub fn rank(&self) -> usize {
        self.info.rank
    }

    /// POD of `snapshots` (displacement fields over all nodes of `gel`, m) and the reduced
    /// stiffness at rest. `sources` is recorded in the description.
    pub fn build(
        gel: &Gel,
        mesh: &str,
        snapshots: &[Vec<[f64; 3]>],
        sources: Vec<String>,
        opts: &PodOptions,
    ) -> Result<Self> {
        let n = gel.num_nodes();
        if snapshots.is_empty() {
            return Err(TactileError::Input(
                "the reduced model needs at least one snapshot".into(),
            ));
        }
        if let Some((k, s)) = snapshots.iter().enumerate().find(|(_, s)| s.len() != n) {
            return Err(TactileError::Input(format!(
                "snapshot {k} has {} nodes, the gel {n} (another mesh?)",
                s.len()
            )));
        }
        let a = Mat::<f64>::from_fn(3 * n, snapshots.len(), |i, j| snapshots[j][i / 3][i % 3]);
        let p = pod(a.as_ref(), opts).map_err(|e| TactileError::Input(format!("POD: {e}")))?;
        let r = p.rank();
        let mut modes = vec![0.0; 3 * n * r];
        for i in 0..3 * n {
            for j in 0..r {
                modes[i * r + j] = p.modes[(i, j)];
            }
        }
        let stiffness = reduced_stiffness(gel, &modes, r)?;
        Ok(ReducedModel {
            info: ReducedInfo {
                format: FORMAT.into(),
                mesh: mesh.into(),
                mesh_nodes: n,
                rank: r,
                material: [gel.material.young_pa, gel.material.poisson],
                snapshots: snapshots.len(),
                sources,
                captured_energy: p.captured_energy(),
            },
            modes,
            stiffness,
            singular_values: p.singular_values,
        })
    }

    /// The first `rank` modes of this model (POD modes are nested), with their stiffness.
    pub fn truncated(&self, rank: usize) -> Result<Self> {
        let r = self.rank();
        if rank == 0 || rank > r {
            return Err(TactileError::Input(format!(
                "rank {rank} is not within 1..={r} of the reduced model"
            )));
        }
        let rows = self.modes.len() / r;
        let mut modes = Vec::with_capacity(rows * rank);
        for i in 0..rows {
            modes.extend_from_slice(&self.modes[i * r..i * r + rank]);
        }
        let mut info = self.info.clone();
        info.rank = rank;
        Ok(ReducedModel {
            info,
            modes,
            stiffness: self.stiffness.view((0, 0), (rank, rank)).into_owned(),
            singular_values: self.singular_values.clone(),
        })
    }

    /// This basis with `extra` full fields (3N each, m) appended as modes: each is
    /// orthogonalised against the modes and the columns before it (twice) and dropped when
    /// nothing of it is left; the stiffness grows by the new rows and columns of Phi^T K_0 Phi.
    pub fn with_extra_modes(&self, rest: &RestStiffness, extra: &[Vec<f64>]) -> Result<Self> {
        let r = self.rank();
        let rows = self.modes.len() / r;
        let mut cols: Vec<Vec<f64>> = Vec::new();
        let col_of = |j: usize, cols: &[Vec<f64>], d: usize| -> f64 {
            if j < r {
                self.modes[d * r + j]
            } else {
                cols[j - r][d]
            }
        };
        for e in extra {
            if e.len() != rows {
                return Err(TactileError::Input(format!(
                    "an extra mode has {} entries, the basis {rows}",
                    e.len()
                )));
            }
            let mut v = e.clone();
            let scale = v.iter().map(|x| x * x).sum::<f64>().sqrt();
            for _ in 0..2 {
                for j in 0..r + cols.len() {
                    let a: f64 = (0..rows).map(|d| col_of(j, &cols, d) * v[d]).sum();
                    for (d, y) in v.iter_mut().enumerate() {
                        *y -= a * col_of(j, &cols, d);
                    }
                }
            }
            let norm = v.iter().map(|x| x * x).sum::<f64>().sqrt();
            if norm > 1e-8 * scale && norm > 0.0 {
                v.iter_mut().for_each(|x| *x /= norm);
                cols.push(v);
            }
        }
        let k = cols.len();
        let n = r + k;
        let mut modes = Vec::with_capacity(rows * n);
        for d in 0..rows {
            modes.extend_from_slice(&self.modes[d * r..(d + 1) * r]);
            modes.extend(cols.iter().map(|c| c[d]));
        }
        let mut stiffness = DMatrix::zeros(n, n);
        stiffness
            .view_mut((0, 0), (r, r))
            .copy_from(&self.stiffness);
        let free = &rest.pattern.dof_of;
        for (c, col) in cols.iter().enumerate() {
            let v: Vec<f64> = free.iter().map(|&d| col[d]).collect();
            let kv = ocm_fem::solve::spmv(&rest.pattern, &rest.values, &v);
            for a in 0..n {
                let x: f64 = free
                    .iter()
                    .zip(&kv)
                    .map(|(&d, y)| modes[d * n + a] * y)
                    .sum();
                stiffness[(a, r + c)] = x;
                stiffness[(r + c, a)] = x;
            }
        }
        let mut info = self.info.clone();
        info.rank = n;
        Ok(ReducedModel {
            info,
            modes,
            stiffness,
            singular_values: self.singular_values.clone(),
        })
    }

    /// Displacement of node `i` for reduced coordinates `q`, m.
    pub fn node_displacement(&self, i: usize, q: &[f64]) -> [f64; 3] {
        let r = self.rank();
        let mut u = [0.0; 3];
        for d in 0..3 {
            let row = &self.modes[(3 * i + d) * r..(3 * i + d + 1) * r];
            u[d] = row.iter().zip(q).map(|(a, b)| a * b).sum();
        }
        u
    }

    /// Displacement of the listed nodes for `q`, m.
    pub fn displacement_of(&self, nodes: &[usize], q: &[f64]) -> Vec<[f64; 3]> {
        nodes
            .iter()
            .map(|&i| self.node_displacement(i, q))
            .collect()
    }

    /// Displacement of every node for `q`, m.
    pub fn displacement(&self, q: &[f64]) -> Vec<[f64; 3]> {
        (0..self.info.mesh_nodes)
            .map(|i| self.node_displacement(i, q))
            .collect()
    }

    /// Least-squares reduced coordinates of a full field (Phi^T u, the modes being orthonormal).
    pub fn project(&self, u: &[[f64; 3]]) -> Vec<f64> {
        let r = self.rank();
        let mut q = vec![0.0; r];
        for (i, ui) in u.iter().enumerate() {
            for d in 0..3 {
                let row = &self.modes[(3 * i + d) * r..(3 * i + d + 1) * r];
                for j in 0..r {
                    q[j] += row[j] * ui[d];
                }
            }
        }
        q
    }

    /// Writes `rom.json`, `modes.npy` (3N x r), `stiffness.npy` (r x r, N/m) and
    /// `singular_values.npy` into `dir`.
    pub fn save(&self, dir: &Path) -> Result<()> {
        std::fs::create_dir_all(dir).map_err(|e| TactileError::io(dir, e))?;
        let r = self.rank();
        let rows = self.modes.len() / r;
        ocm_fem::npy::write_f64_2d_path(dir.join("modes.npy"), &self.modes, rows, r)?;
        let k: Vec<f64> = (0..r)
            .flat_map(|i| (0..r).map(move |j| (i, j)))
            .map(|(i, j)| self.stiffness[(i, j)])
            .collect();
        ocm_fem::npy::write_f64_2d_path(dir.join("stiffness.npy"), &k, r, r)?;
        let s = &self.singular_values;
        ocm_fem::npy::write_f64_2d_path(dir.join("singular_values.npy"), s, s.len(), 1)?;
        let path = dir.join("rom.json");
        let text = serde_json::to_string_pretty(&self.info)
            .map_err(|e| TactileError::Input(format!("rom.json: {e}")))?;
        std::fs::write(&path, text).map_err(|e| TactileError::io(&path, e))
    }

    /// Reads a model written by [`ReducedModel::save`]; shapes that disagree with `rom.json`
    /// are errors naming the file.
    pub fn load(dir: &Path) -> Result<Self> {
        let path = dir.join("rom.json");
        let text = std::fs::read_to_string(&path).map_err(|e| TactileError::io(&path, e))?;
        let info: ReducedInfo = serde_json::from_str(&text)
            .map_err(|e| TactileError::Input(format!("{}: {e}", path.display())))?;
        if info.format != FORMAT {
            return Err(TactileError::Input(format!(
                "{}: format '{}', expected '{FORMAT}'",
                path.display(),
                info.format
            )));
        }
        let r = info.rank;
        let read = |name: &str, rows: usize, cols: usize| -> Result<Vec<f64>> {
            let p = dir.join(name);
            let a = ocm_fem::npy::read_f64_2d(&p)?;
            if a.rows != rows || a.cols != cols {
                return Err(TactileError::Input(format!(
                    "{}: {} x {}, rom.json says {rows} x {cols}",
                    p.display(),
                    a.rows,
                    a.cols
                )));
            }
            if let Some(k) = a.data.iter().position(|v| !v.is_finite()) {
                return Err(TactileError::Input(format!(
                    "{}: entry {k} is not finite",
                    p.display()
                )));
            }
            Ok(a.data)
        };
        let modes = read("modes.npy", 3 * info.mesh_nodes, r)?;
        let k = read("stiffness.npy", r, r)?;
        let sv = ocm_fem::npy::read_f64_2d(dir.join("singular_values.npy"))?.data;
        Ok(ReducedModel {
            info,
            modes,
            stiffness: DMatrix::from_row_slice(r, r, &k),
            singular_values: sv,
        })
    }

    /// Checks that this model belongs to `gel` (node count and rest stiffness are not compared;
    /// the node count is).
    pub fn check_gel(&self, gel: &Gel) -> Result<()> {
        if self.info.mesh_nodes != gel.num_nodes() {
            return Err(TactileError::Input(format!(
                "the reduced model was built on {} ({} nodes), the gel has {} nodes",
                self.info.mesh,
                self.info.mesh_nodes,
                gel.num_nodes()
            )));
        }
        Ok(())
    }
}

/// Phi^T K_0 Phi from the fem tangent at rest (symmetrised against round-off).
fn reduced_stiffness(gel: &Gel, modes: &[f64], r: usize) -> Result<DMatrix<f64>> {
    let pattern = Pattern::new(&gel.model)?;
    let x0 = gel.model.rest_dofs();
    let ev = gel
        .model
        .evaluate(&pattern, &x0, &Loads::default(), 1.0, true)?;
    let vals = ev
        .tangent
        .ok_or_else(|| TactileError::Input("the fem returned no tangent at rest".into()))?;
    let free = &pattern.dof_of;
    let cols: Vec<Vec<f64>> = (0..r)
        .into_par_iter()
        .map(|j| {
            let v: Vec<f64> = free.iter().map(|&d| modes[d * r + j]).collect();
            ocm_fem::solve::spmv(&pattern, &vals, &v)
        })
        .collect();
    let mut k = DMatrix::zeros(r, r);
    for (j, kv) in cols.iter().enumerate() {
        for a in 0..r {
            k[(a, j)] = free
                .iter()
                .zip(kv)
                .map(|(&d, y)| modes[d * r + a] * y)
                .sum();
        }
    }
    Ok((&k + k.transpose()) * 0.5)
}

/// The gel's stiffness at rest, factorised once, for modes that follow a placement's contact.
pub struct RestStiffness {
    pattern: Pattern,
    values: Vec<f64>,
    solver: SparseSolver,
    nodes: usize,
}

impl RestStiffness {
    /// Assembles and factorises the fem tangent of `gel` at rest.
    pub fn new(gel: &Gel) -> Result<Self> {
        let pattern = Pattern::new(&gel.model)?;
        let x0 = gel.model.rest_dofs();
        let ev = gel
            .model
            .evaluate(&pattern, &x0, &Loads::default(), 1.0, true)?;
        let values = ev
            .tangent
            .ok_or_else(|| TactileError::Input("the fem returned no tangent at rest".into()))?;
        let mut solver = SparseSolver::new(
            pattern.num_free(),
            pattern.col_ptr.clone(),
            pattern.row_idx.clone(),
        );
        solver.factorize(&values)?;
        Ok(RestStiffness {
            pattern,
            values,
            solver,
            nodes: gel.num_nodes(),
        })
    }

    /// The linear response at rest (3N, m) to 1 N along -z on each listed node.
    pub fn respond_z(&self, nodes: &[usize]) -> Result<Vec<f64>> {
        let loads: Vec<(usize, [f64; 3])> = nodes.iter().map(|&i| (i, [0.0, 0.0, -1.0])).collect();
        self.respond(&loads)
    }

    /// The linear response at rest (3N, m) to the nodal forces `loads` (node, N); forces on
    /// fixed dofs are dropped.
    pub fn respond(&self, loads: &[(usize, [f64; 3])]) -> Result<Vec<f64>> {
        let mut rhs = vec![0.0; self.pattern.num_free()];
        for &(i, f) in loads {
            for (d, fd) in f.iter().enumerate() {
                if let Some(&k) = self.pattern.free_of.get(3 * i + d)
                    && k != usize::MAX
                {
                    rhs[k] += fd;
                }
            }
        }
        self.solver.solve_factored(&mut rhs)?;
        let mut u = vec![0.0; 3 * self.nodes];
        for (j, &d) in self.pattern.dof_of.iter().enumerate() {
            u[d] = rhs[j];
        }
        Ok(u)
    }
}

impl RestStiffness {
    /// One modified-Newton correction of the field `u` (3N, m) with the rest tangent: the change
    /// -K_0^{-1} (f_int(X + u) - K_0 u) (3N, m), which keeps the forces the linear model
    /// balances (K_0 u) and trades its linear internal force for the gel's Neo-Hookean one.
    pub fn nonlinear_correction(&self, gel: &Gel, u: &[f64]) -> Result<Vec<f64>> {
        if u.len() != 3 * self.nodes {
            return Err(TactileError::Input(format!(
                "a field of {} entries for a gel of {} nodes",
                u.len(),
                self.nodes
            )));
        }
        let mut x = gel.model.rest_dofs();
        for (xi, ui) in x.iter_mut().zip(u) {
            *xi += ui;
        }
        let ev = gel
            .model
            .evaluate(&self.pattern, &x, &Loads::default(), 1.0, false)?;
        let uf: Vec<f64> = self.pattern.dof_of.iter().map(|&d| u[d]).collect();
        let ku = ocm_fem::solve::spmv(&self.pattern, &self.values, &uf);
        let mut rhs: Vec<f64> = ku.iter().zip(&ev.residual).map(|(k, r)| k - r).collect();
        self.solver.solve_factored(&mut rhs)?;
        let mut du = vec![0.0; 3 * self.nodes];
        for (j, &d) in self.pattern.dof_of.iter().enumerate() {
            du[d] = rhs[j];
        }
        Ok(du)
    }
}

/// Rim width of the footprint's second load (README, "The worst held-out frame"), m.
pub const FOOTPRINT_RIM_M: f64 = 0.4e-3;

/// Nodal forces: (mesh node, force N).
pub type NodalLoads = Vec<(usize, [f64; 3])>;

/// Candidate loads on a placement's footprint (label, nodal forces N), from the geometry alone:
/// the top nodes inside `placed` at rest, the outside top nodes, and per footprint node its
/// nearest outside top node (the in-plane direction out of the footprint, the distance to its edge).
pub fn footprint_load_cases(
    gel: &Gel,
    placed: &Placed,
    rim_m: f64,
) -> Vec<(&'static str, NodalLoads)> {
    let at = |i: usize| Vector3::from(gel.mesh.points[i]);
    let inside: Vec<bool> = gel
        .top
        .par_iter()
        .map(|&i| placed.query(&at(i)).distance < 0.0)
        .collect();
    let (mut foot, mut out) = (Vec::new(), Vec::new());
    for (&i, &on) in gel.top.iter().zip(&inside) {
        if on { foot.push(i) } else { out.push(i) }
    }
    if foot.is_empty() {
        return Vec::new();
    }
    let nearest = |i: usize, set: &[usize]| -> (f64, Vector3<f64>) {
        let mut best = (f64::INFINITY, Vector3::zeros());
        for &o in set {
            let mut d = at(o) - at(i);
            d.z = 0.0;
            let n = d.norm();
            if n < best.0 {
                best = (n, d / n.max(1e-30));
            }
        }
        best
    };
    let edge: Vec<(f64, Vector3<f64>)> = foot.iter().map(|&i| nearest(i, &out)).collect();
    let c = foot.iter().map(|&i| at(i)).sum::<Vector3<f64>>() / foot.len() as f64;
    let reach = foot
        .iter()
        .map(|&i| ((at(i) - c).xy()).norm())
        .fold(0.0, f64::max)
        .max(1e-9);
    let z = |w: f64| [0.0, 0.0, -w];
    let mut cases: Vec<(&'static str, NodalLoads)> = Vec::new();
    cases.push(("foot", foot.iter().map(|&i| (i, z(1.0))).collect()));
    cases.push((
        "rim",
        foot.iter()
            .zip(&edge)
            .filter(|(_, e)| e.0 < rim_m)
            .map(|(&i, _)| (i, z(1.0)))
            .collect(),
    ));
    cases.push((
        "ring2",
        foot.iter()
            .zip(&edge)
            .filter(|(_, e)| e.0 >= rim_m && e.0 < 2.5 * rim_m)
            .map(|(&i, _)| (i, z(1.0)))
            .collect(),
    ));
    cases.push((
        "out",
        foot.iter()
            .zip(&edge)
            .map(|(&i, e)| (i, [e.1.x, e.1.y, 0.0]))
            .collect(),
    ));
    cases.push((
        "out_rim",
        foot.iter()
            .zip(&edge)
            .filter(|(_, e)| e.0 < rim_m)
            .map(|(&i, e)| (i, [e.1.x, e.1.y, 0.0]))
            .collect(),
    ));
    cases.push((
        "radial",
        foot.iter()
            .map(|&i| {
                let d = (at(i) - c) / reach;
                (i, [d.x, d.y, 0.0])
            })
            .collect(),
    ));
    for (name, k) in [("tilt_x", 0), ("tilt_y", 1)] {
        cases.push((
            name,
            foot.iter()
                .map(|&i| (i, z((at(i)[k] - c[k]) / reach)))
                .collect(),
        ));
    }
    let skirt: Vec<(usize, [f64; 3])> = out
        .iter()
        .filter_map(|&o| {
            let (d, v) = nearest(o, &foot);
            (d < 2.5 * rim_m).then_some((o, [-v.x, -v.y, 0.0]))
        })
        .collect();
    cases.push(("skirt", skirt));
    cases.retain(|(_, l)| !l.is_empty());
    cases
}

/// Every footprint load [`footprint_load_cases`] knows: the normal loads `foot` (uniform on the
/// footprint), `rim` (its nodes within the rim width of its edge), `ring2` (the next 1.5 rim
/// widths inwards), `tilt_x` / `tilt_y` (linear in x / y across it); the in-plane loads `out`
/// (each footprint node towards its nearest outside top node), `out_rim` (the same on the rim),
/// `radial` (away from the footprint's centroid, growing with the distance) and `skirt` (outside
/// top nodes within 2.5 rim widths, away from the footprint).
pub const FOOTPRINT_LOADS: [&str; 9] = [
    "foot", "rim", "ring2", "out", "out_rim", "radial", "tilt_x", "tilt_y", "skirt",
];

/// The footprint loads `--enrich` uses unless told otherwise (README, "The worst held-out frame").
pub const DEFAULT_FOOTPRINT_LOADS: [&str; 2] = ["foot", "rim"];

/// Per-placement modes: the rest stiffness and the footprint loads whose responses join the basis.
#[derive(Clone, Copy)]
pub struct Enrichment<'a> {
    /// The factorised rest stiffness.
    pub rest: &'a RestStiffness,
    /// Labels out of [`FOOTPRINT_LOADS`].
    pub loads: &'a [&'a str],
}

/// Checks that every label in `loads` is one of [`FOOTPRINT_LOADS`], or `nl_` and one of them
/// (the second-order field of that load's response, [`second_order_mode`]).
pub fn check_footprint_loads(loads: &[&str]) -> Result<()> {
    let known = |l: &str| FOOTPRINT_LOADS.contains(&l.strip_prefix("nl_").unwrap_or(l));
    match loads.iter().find(|l| !known(l)) {
        Some(bad) => Err(TactileError::Input(format!(
            "unknown footprint load '{bad}' (known: {}, each also with the prefix nl_)",
            FOOTPRINT_LOADS.join(", ")
        ))),
        None => Ok(()),
    }
}

/// `model` with the modes of this placement appended: the rest responses to the footprint
/// loads `loads` ([`footprint_load_cases`]) of the indenter at `depth_m`, in that order; a load
/// with no node (e.g. no rim on a footprint a few nodes wide) or one the modes already hold adds none.
pub fn placement_model(
    model: &ReducedModel,
    enrich: Enrichment,
    gel: &Gel,
    indenter: &Indenter,
    approach: &Approach,
    depth_m: f64,
) -> Result<ReducedModel> {
    check_footprint_loads(enrich.loads)?;
    let placed = Placed {
        indenter,
        pose: approach.pose_at(depth_m),
    };
    let cases = footprint_load_cases(gel, &placed, FOOTPRINT_RIM_M);
    let mut responses: Vec<(&str, Vec<f64>)> = Vec::new();
    let mut extra = Vec::new();
    for l in enrich.loads {
        let base = l.strip_prefix("nl_").unwrap_or(l);
        let Some((_, loads)) = cases.iter().find(|(k, _)| *k == base) else {
            continue;
        };
        let u = match responses.iter().find(|(k, _)| *k == base) {
            Some((_, u)) => u.clone(),
            None => {
                let u = enrich.rest.respond(loads)?;
                responses.push((base, u.clone()));
                u
            }
        };
        if base == *l {
            extra.push(u);
        } else {
            extra.push(second_order_mode(enrich.rest, gel, &u, depth_m)?);
        }
    }
    model.with_extra_modes(enrich.rest, &extra)
}

/// The second-order field of a response `u` (3N, m): `u` scaled to a largest |u_z| of half of
/// `depth_m`, then one modified-Newton correction with the rest tangent
/// ([`RestStiffness::nonlinear_correction`]). It carries the in-plane flow under a pressed
/// footprint that the linear response lacks. A unit load concentrates under its nodes: where
/// the scaled field inverts an element, the scale is halved (up to 6 times).
pub fn second_order_mode(
    rest: &RestStiffness,
    gel: &Gel,
    u: &[f64],
    depth_m: f64,
) -> Result<Vec<f64>> {
    let top = u.chunks(3).map(|c| c[2].abs()).fold(0.0, f64::max);
    if !(top > 0.0 && depth_m > 0.0) {
        return Err(TactileError::Input(format!(
            "a second-order mode needs a response with a normal part and a depth > 0 (got {depth_m} m)"
        )));
    }
    let mut scale = 0.5 * depth_m / top;
    for _ in 0..6 {
        let scaled: Vec<f64> = u.iter().map(|v| v * scale).collect();
        match rest.nonlinear_correction(gel, &scaled) {
            Ok(du) => return Ok(du),
            Err(TactileError::Fem(ocm_fem::FemError::Inverted { .. })) => scale *= 0.5,
            Err(e) => return Err(e),
        }
    }
    Err(TactileError::Input(
        "a second-order mode inverts an element at every scale tried".into(),
    ))
}

/// Controls of the reduced contact solve.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct ReducedOptions {
    /// Normal penalty per unit area, Pa/m (as the full model's [`crate::contact::ContactParams`]).
    pub normal_penalty_pa_m: f64,
    /// Penetration accepted at equilibrium, m.
    pub penetration_tol_m: f64,
    /// Augmented-Lagrangian updates per frame.
    pub max_updates: usize,
    /// Linearisation passes per solve.
    pub max_passes: usize,
    /// A pass has settled when |dq| <= this fraction of |q|.
    pub settle: f64,
    /// Nodes whose signed distance is surely above this are not queried, m.
    pub reach_m: f64,
    /// Hold the area-weighted mean of the linearised gap over the nodes in contact at zero
    /// exactly: one uniform pressure multiplier over the contact on top of the per-node
    /// penalty, so the soft penalty still shapes the contact and the multiplier sets how deep
    /// it sits (README, "The contact's mean gap held exactly").
    #[serde(default)]
    pub hold_mean_gap: bool,
}

impl ReducedOptions {
    /// For modulus `young_pa`: 1/100 of the full model's normal penalty and no multiplier
    /// updates. The subspace cannot follow every contact node onto the indenter (sharp
    /// features, the basis' projection error), and a stiff penalty then bends the whole field
    /// to chase them: on held-out set-ups the nodal RMSE was 0.13 mm at the full model's penalty,
    /// 0.067 at 1/10, 0.027 at 1/100 and 0.026 at 1/1000 against a projection limit of 0.025
    /// (README, "Reduced model").
    pub fn for_modulus(young_pa: f64) -> Self {
        let c = crate::contact::ContactParams::for_modulus(young_pa);
        ReducedOptions {
            normal_penalty_pa_m: 0.01 * c.normal_penalty_pa_m,
            penetration_tol_m: c.penetration_tol_m,
            max_updates: 0,
            max_passes: 8,
            settle: 1e-4,
            reach_m: 0.1e-3,
            hold_mean_gap: false,
        }
    }
}

/// One solved frame of the reduced model.
#[derive(Debug, Clone)]
pub struct ReducedFrame {
    /// Indentation depth, m.
    pub depth_m: f64,
    /// Reduced coordinates.
    pub q: Vec<f64>,
    /// Nodes in contact: (mesh node, normal force N, indenter normal).
    pub active: Vec<(usize, f64, Vector3<f64>)>,
    /// Force of the gel on the indenter, N.
    pub indenter_force_n: [f64; 3],
    /// Deepest penetration at the frame (linearised gaps), m.
    pub max_penetration_m: f64,
    /// Linearisation passes over all multiplier updates.
    pub passes: usize,
    /// Signed-distance queries made.
    pub queries: usize,
}

impl ReducedFrame {
    /// Contact force on each listed node (zero off contact), N.
    pub fn nodal_force(&self, nodes: &[usize], num_nodes: usize) -> Vec<[f64; 3]> {
        let mut local = vec![usize::MAX; num_nodes];
        for (k, &i) in nodes.iter().enumerate() {
            local[i] = k;
        }
        let mut f = vec![[0.0; 3]; nodes.len()];
        for (i, p, n) in &self.active {
            if local[*i] != usize::MAX {
                f[local[*i]] = [p * n.x, p * n.y, p * n.z];
            }
        }
        f
    }
}

/// Per surface node: where and what its signed distance was last queried.
#[derive(Debug, Clone, Copy)]
struct Seen {
    gap: f64,
    normal: Vector3<f64>,
    at: Vector3<f64>,
    indenter_at: Vector3<f64>,
}

/// A stepwise indentation on the reduced model.
pub struct ReducedIndentation<'a> {
    model: &'a ReducedModel,
    gel: &'a Gel,
    indenter: &'a Indenter,
    approach: Approach,
    /// Reduced coordinates.
    pub q: DVector<f64>,
    lambda: Vec<f64>,
    seen: Vec<Option<Seen>>,
    /// Controls.
    pub options: ReducedOptions,
    /// Current depth, m.
    pub depth_m: f64,
    /// The hyper-reduced Neo-Hookean force in place of K_r q, when set.
    nonlinear: Option<crate::hyper::ProjectedGel<'a>>,
    /// The nonlinear force and tangent last evaluated, and where.
    last_eval: Option<(DVector<f64>, crate::hyper::ReducedForce)>,
}

impl<'a> ReducedIndentation<'a> {
    /// Prepares the indentation of `gel` (reduced by `model`) by `indenter` at `placement`;
    /// errors when it would not touch the top face or the model is of another mesh.
    pub fn new(
        name: &str,
        model: &'a ReducedModel,
        gel: &'a Gel,
        indenter: &'a Indenter,
        placement: Placement,
        options: ReducedOptions,
    ) -> Result<Self> {
        model.check_gel(gel)?;
        let approach = Approach::new(name, gel, indenter, placement)?;
        Ok(ReducedIndentation {
            model,
            gel,
            indenter,
            approach,
            q: DVector::zeros(model.rank()),
            lambda: vec![0.0; gel.surface.len()],
            seen: vec![None; gel.surface.len()],
            options,
            depth_m: 0.0,
            nonlinear: None,
            last_eval: None,
        })
    }

    /// The internal force of the gel becomes `gel`'s hyper-reduced Neo-Hookean force on this
    /// model's basis instead of the rest stiffness' K_r q: each linearisation pass then also
    /// linearises the internal force at the current q (one Newton step on both).
    pub fn with_nonlinear(mut self, gel: &'a crate::hyper::NonlinearGel) -> Self {
        self.nonlinear = Some(gel.on_basis(self.model));
        self
    }

    /// Pose of the indenter at `depth_m` from first touch.
    pub fn pose_at(&self, depth_m: f64) -> Pose {
        self.approach.pose_at(depth_m)
    }

    /// Solves the frame at `depth_m` (warm-started from the current state).
    pub fn advance_to(&mut self, depth_m: f64) -> Result<ReducedFrame> {
        if !depth_m.is_finite() {
            return Err(TactileError::Input(format!(
                "reduced indentation depth {depth_m} m is not finite"
            )));
        }
        let pose = self.approach.pose_at(depth_m);
        let placed = Placed {
            indenter: self.indenter,
            pose,
        };
        let (lo, hi) = placed.bounds();
        let margin = 0.5e-3;
        let gel = self.gel;
        // Surface nodes displaced by at most ~the depth: a 1.5 mm margin in z keeps every node
        // that can touch.
        let cands: Vec<usize> = gel
            .surface
            .iter()
            .enumerate()
            .filter(|&(_, &i)| {
                let p = gel.mesh.points[i];
                p[0] >= lo[0] - margin
                    && p[0] <= hi[0] + margin
                    && p[1] >= lo[1] - margin
                    && p[1] <= hi[1] + margin
                    && p[2] >= lo[2] - 1.5e-3
            })
            .map(|(k, _)| k)
            .collect();
        let o = self.options;
        let r = self.model.rank();
        let mut passes = 0;
        let mut queries = 0;
        let mut pen = 0.0;
        let mut active: Vec<(usize, f64, Vector3<f64>)> = Vec::new();
        for update in 0..=o.max_updates {
            let mut settled = false;
            // Passes that stop shrinking their step are damped: near sharp indenter features
            // the linearised normals can flip between passes.
            let (mut alpha, mut last_dq) = (1.0, f64::INFINITY);
            let mut near: Vec<(usize, f64, DVector<f64>)> = Vec::new();
            // The mean-gap multiplier's share of each near node's force, N (zero without them).
            let mut moment_force: Vec<f64> = Vec::new();
            while !settled && passes < o.max_passes * (update + 1) {
                passes += 1;
                queries += self.query(&placed, &cands);
                // a_i = Phi_i^T n_i for the nodes within reach.
                near.clear();
                for &k in &cands {
                    let Some(s) = self.seen[k] else { continue };
                    let i = gel.surface[k];
                    let x = self.position(i);
                    let g = s.gap + s.normal.dot(&(x - s.at))
                        - s.normal.dot(&(pose.translation - s.indenter_at));
                    if g > o.reach_m && self.lambda[k] == 0.0 {
                        continue;
                    }
                    let mut a = DVector::zeros(r);
                    for d in 0..3 {
                        let row = &self.model.modes[(3 * i + d) * r..(3 * i + d + 1) * r];
                        for j in 0..r {
                            a[j] += row[j] * s.normal[d];
                        }
                    }
                    // Linearised gap at the current q: g_i + a_i . (q' - q).
                    near.push((k, g - a.dot(&self.q), a));
                }
                let (q_new, extra) = match &self.nonlinear {
                    None => self.active_set_solve(&near, &self.model.stiffness, None)?,
                    Some(nl) => {
                        let ev = match self.last_eval.take() {
                            Some((at, ev)) if at == self.q => ev,
                            _ => nl.evaluate(self.q.as_slice(), true)?,
                        };
                        let k = ev
                            .tangent
                            .clone()
                            .unwrap_or_else(|| self.model.stiffness.clone());
                        // f(q') ~ f(q) + K (q' - q): the offset K q - f(q) joins the right side.
                        let offset = &k * &self.q - &ev.force;
                        self.last_eval = Some((self.q.clone(), ev));
                        self.active_set_solve(&near, &k, Some(&offset))?
                    }
                };
                moment_force = extra;
                let dq = (&q_new - &self.q).norm();
                settled = dq <= o.settle * q_new.norm().max(1e-30);
                if dq > 0.9 * last_dq {
                    alpha = (alpha * 0.5f64).max(1.0 / 16.0);
                }
                last_dq = dq;
                let step = (q_new - &self.q) * alpha;
                self.take_step(step)?;
            }
            // Pressures and penetration at the settled q (linearised gaps).
            active.clear();
            pen = 0.0f64;
            for (j, (k, g0, a)) in near.iter().enumerate() {
                let g = g0 + a.dot(&self.q);
                let kn = o.normal_penalty_pa_m * gel.area_m2[*k];
                let p = self.lambda[*k] + moment_force.get(j).copied().unwrap_or(0.0) - kn * g;
                if p > 0.0 {
                    pen = pen.max(-g);
                    let n = self.seen[*k].map(|s| s.normal).unwrap_or_else(Vector3::z);
                    active.push((gel.surface[*k], p, n));
                }
            }
            if pen <= o.penetration_tol_m || update == o.max_updates {
                break;
            }
            let updated: Vec<(usize, f64)> = near
                .iter()
                .map(|(k, g0, a)| {
                    let kn = o.normal_penalty_pa_m * gel.area_m2[*k];
                    (*k, (self.lambda[*k] - kn * (g0 + a.dot(&self.q))).max(0.0))
                })
                .collect();
            self.lambda.iter_mut().for_each(|h| *h = 0.0);
            for (k, p) in updated {
                self.lambda[k] = p;
            }
        }
        self.depth_m = depth_m;
        let mut total = Vector3::zeros();
        for (_, p, n) in &active {
            total -= n * *p;
        }
        Ok(ReducedFrame {
            depth_m,
            q: self.q.iter().copied().collect(),
            active,
            indenter_force_n: [total.x, total.y, total.z],
            max_penetration_m: pen.max(0.0),
            passes,
            queries,
        })
    }

    /// q += step; with the nonlinear force, a step that inverts a sampled element is halved
    /// (up to 12 times) and the force and tangent at the accepted q are kept for the next pass.
    fn take_step(&mut self, step: DVector<f64>) -> Result<()> {
        let Some(nl) = &self.nonlinear else {
            self.q += step;
            return Ok(());
        };
        let mut s = step;
        for _ in 0..12 {
            let cand = &self.q + &s;
            match nl.evaluate(cand.as_slice(), true) {
                Ok(ev) => {
                    self.last_eval = Some((cand.clone(), ev));
                    self.q = cand;
                    return Ok(());
                }
                Err(TactileError::Fem(ocm_fem::FemError::Inverted { .. })) => s *= 0.5,
                Err(e) => return Err(e),
            }
        }
        Err(TactileError::Input(format!(
            "the reduced nonlinear solve inverts an element at depth {:.4} mm even after 12 step halvings",
            self.depth_m * 1e3
        )))
    }

    fn position(&self, i: usize) -> Vector3<f64> {
        let u = self.model.node_displacement(i, self.q.as_slice());
        Vector3::from(self.gel.mesh.points[i]) + Vector3::from(u)
    }

    /// Queries the candidates whose distance bound says they may be within reach; returns how
    /// many were queried.
    fn query(&mut self, placed: &Placed, cands: &[usize]) -> usize {
        let t = placed.pose.translation;
        let reach = self.options.reach_m;
        let todo: Vec<(usize, Vector3<f64>)> = cands
            .iter()
            .filter_map(|&k| {
                let x = self.position(self.gel.surface[k]);
                let needed = match self.seen[k] {
                    None => true,
                    Some(s) => s.gap - (x - s.at).norm() - (t - s.indenter_at).norm() <= reach,
                };
                needed.then_some((k, x))
            })
            .collect();
        let found: Vec<(usize, Seen)> = todo
            .par_iter()
            .with_min_len(64)
            .map(|&(k, x)| {
                let q = placed.query(&x);
                (
                    k,
                    Seen {
                        gap: q.distance,
                        normal: q.normal,
                        at: x,
                        indenter_at: t,
                    },
                )
            })
            .collect();
        for (k, s) in found {
            self.seen[k] = Some(s);
        }
        todo.len()
    }

    /// The exact minimiser of the penalty problem with linearised gaps g0_i + a_i . q:
    /// semismooth Newton on the active set (each step one r x r Cholesky). With
    /// `hold_mean_gap`, the contact force of node i also carries A_i mu, and mu holds
    /// sum_A A_i g_i = 0 (one more unknown, a Schur complement per step). Returns q and each
    /// near node's force from mu, N.
    fn active_set_solve(
        &self,
        near: &[(usize, f64, DVector<f64>)],
        stiffness: &DMatrix<f64>,
        offset: Option<&DVector<f64>>,
    ) -> Result<(DVector<f64>, Vec<f64>)> {
        let o = &self.options;
        let r = self.model.rank();
        let kn = |k: usize| o.normal_penalty_pa_m * self.gel.area_m2[k];
        let mut q = self.q.clone();
        let mut extra = vec![0.0; near.len()];
        let mut history: Vec<Vec<bool>> = Vec::new();
        let mut frozen = false;
        for _ in 0..50 {
            let act: Vec<bool> = near
                .iter()
                .zip(&extra)
                .map(|((k, g0, a), e)| self.lambda[*k] + e - kn(*k) * (g0 + a.dot(&q)) > 0.0)
                .collect();
            if history.last() == Some(&act) {
                return Ok((q, extra));
            }
            // With the mean-gap multiplier the active set can cycle (nodes at the edge of
            // the contact enter and leave as the mean shifts): the multipliers are then frozen
            // and the plain penalty problem with that fixed force settles as without them;
            // the next linearisation pass solves for them again.
            if !frozen && history.contains(&act) {
                frozen = true;
                history.clear();
            }
            let m = act.iter().filter(|&&b| b).count();
            // H = K_r + A^T A with the rows sqrt(k_i) a_i of the active nodes (one GEMM).
            let mut rows = DMatrix::zeros(m, r);
            let mut rhs = offset.cloned().unwrap_or_else(|| DVector::zeros(r));
            let mut at = 0;
            for ((k, g0, a), on) in near.iter().zip(&act) {
                if !on {
                    continue;
                }
                let kk = kn(*k);
                let s = kk.sqrt();
                for j in 0..r {
                    rows[(at, j)] = s * a[j];
                }
                rhs.axpy(self.lambda[*k] - kk * g0, a, 1.0);
                at += 1;
            }
            let h = stiffness + rows.tr_mul(&rows);
            let chol = h.cholesky().ok_or_else(|| {
                TactileError::Input(
                    "the reduced stiffness is not positive definite (a degenerate basis?)".into(),
                )
            })?;
            if frozen {
                for ((_, _, a), (on, e)) in near.iter().zip(act.iter().zip(&extra)) {
                    if *on {
                        rhs.axpy(*e, a, 1.0);
                    }
                }
            }
            q = chol.solve(&rhs);
            if frozen {
                history.push(act);
                continue;
            }
            extra.iter_mut().for_each(|e| *e = 0.0);
            if o.hold_mean_gap && m > 0 {
                // b = sum_A A_i a_i, c = sum_A A_i g0_i; H q = rhs + b mu with b . q = -c
                // gives mu = (-c - b . H^-1 rhs) / (b . H^-1 b).
                let mut b = DVector::zeros(r);
                let mut c = 0.0;
                for ((k, g0, a), on) in near.iter().zip(&act) {
                    if *on {
                        let area = self.gel.area_m2[*k];
                        b.axpy(area, a, 1.0);
                        c += area * g0;
                    }
                }
                let z = chol.solve(&b);
                let schur = b.dot(&z);
                if schur > 0.0 {
                    let mu = (-c - b.dot(&q)) / schur;
                    q.axpy(mu, &z, 1.0);
                    for ((k, _, _), e) in near.iter().zip(extra.iter_mut()) {
                        *e = self.gel.area_m2[*k] * mu;
                    }
                }
            }
            history.push(act);
        }
        Err(TactileError::Input(format!(
            "the reduced contact active set did not settle in 50 iterations at depth {:.4} mm",
            self.depth_m * 1e3
        )))
    }
}

/// A full-FEM indentation read back from its folder (as `ocm tactile indent` and the dataset's
/// FEM cache write it): depths from `force_depth.csv`, fields from `u_NNN.npy`.
#[derive(Debug, Clone)]
pub struct FemSequence {
    /// Depth of each step, m.
    pub depth_m: Vec<f64>,
    /// Nodal displacement of each step (N x 3), m.
    pub displacement: Vec<Vec<[f64; 3]>>,
    /// Force of the gel on the indenter at each step, N.
    pub force_n: Vec<[f64; 3]>,
}

impl FemSequence {
    /// Reads the consecutive steps from 1 in `dir` (at most as many as `force_depth.csv` lists).
    /// A run that stopped before writing `force_depth.csv` is read with step k at depth
    /// k `step_m` and the force from `f_NNN.npy` when `step_m` is given.
    pub fn read(dir: &Path, nodes: usize, step_m: Option<f64>) -> Result<Self> {
        let csv_path = dir.join("force_depth.csv");
        let csv = match (std::fs::read_to_string(&csv_path), step_m) {
            (Ok(c), _) => c,
            (Err(_), Some(h)) => Self::synthetic_csv(dir, nodes, h)?,
            (Err(e), None) => return Err(TactileError::io(&csv_path, e)),
        };
        let mut seq = FemSequence {
            depth_m: Vec::new(),
            displacement: Vec::new(),
            force_n: Vec::new(),
        };
        for (k, line) in csv.lines().skip(1).enumerate() {
            let p = dir.join(format!("u_{:03}.npy", k + 1));
            if !p.exists() {
                break;
            }
            let cols: Vec<f64> = line
                .split(',')
                .take(5)
                .map(|v| v.trim().parse().unwrap_or(f64::NAN))
                .collect();
            if cols.len() < 5 || cols.iter().any(|v| !v.is_finite()) {
                return Err(TactileError::Input(format!(
                    "{} line {}: expected step, depth_mm and three forces",
                    csv_path.display(),
                    k + 2
                )));
            }
            let a = ocm_fem::npy::read_f64_2d(&p)?;
            if a.rows != nodes || a.cols != 3 {
                return Err(TactileError::Input(format!(
                    "{} is {} x {}, expected {nodes} x 3 (another mesh?)",
                    p.display(),
                    a.rows,
                    a.cols
                )));
            }
            seq.depth_m.push(cols[1] * 1e-3);
            seq.force_n.push([cols[2], cols[3], cols[4]]);
            seq.displacement
                .push(a.data.chunks(3).map(|c| [c[0], c[1], c[2]]).collect());
        }
        Ok(seq)
    }

    /// The rows `step,depth_mm,fx,fy,fz` of a run without its CSV: depths k `step_m`, the
    /// force on the indenter minus the sum of `f_NNN.npy`.
    fn synthetic_csv(dir: &Path, nodes: usize, step_m: f64) -> Result<String> {
        let mut csv = String::from("step,depth_mm,force_x_n,force_y_n,force_z_n\n");
        for k in 1.. {
            let p = dir.join(format!("f_{k:03}.npy"));
            if !p.exists() {
                break;
            }
            let a = ocm_fem::npy::read_f64_2d(&p)?;
            if a.rows != nodes || a.cols != 3 {
                return Err(TactileError::Input(format!(
                    "{} is {} x {}, expected {nodes} x 3",
                    p.display(),
                    a.rows,
                    a.cols
                )));
            }
            let mut t = [0.0; 3];
            for c in a.data.chunks(3) {
                for d in 0..3 {
                    t[d] -= c[d];
                }
            }
            csv += &format!(
                "{k},{},{},{},{}\n",
                k as f64 * step_m * 1e3,
                t[0],
                t[1],
                t[2]
            );
        }
        Ok(csv)
    }
}

/// The reduced model against one full-FEM sequence.
#[derive(Debug, Clone, Serialize)]
pub struct SequenceScore {
    /// Set-up name.
    pub setup: String,
    /// Frames compared.
    pub frames: usize,
    /// Depth of each frame, m.
    pub depth_m: Vec<f64>,
    /// Nodal RMSE over all nodes per frame, m.
    pub rmse_m: Vec<f64>,
    /// Nodal RMSE over the top-face nodes per frame, m.
    pub rmse_top_m: Vec<f64>,
    /// The basis' own limit: RMSE of the FEM field's projection onto the modes, m.
    pub projection_rmse_m: Vec<f64>,
    /// Indenter force z, reduced and FEM, N.
    pub force_z_n: Vec<[f64; 2]>,
    /// Deepest penetration over the frames, m.
    pub max_penetration_m: f64,
    /// Linearisation passes over the frames of the last run.
    pub passes: usize,
    /// Signed-distance queries over the frames of the last run.
    pub queries: usize,
    /// Seconds of each timed repeat of the whole sequence (solve and top-face field).
    pub seconds: Vec<f64>,
}

/// Runs the reduced model through the depths of `fem` (`repeats` timed runs from rest, each
/// solving every frame and evaluating the top-face field), then scores the last run's fields
/// against the FEM. With `nonlinear` the internal force is that hyper-reduced Neo-Hookean force.
#[allow(clippy::too_many_arguments)]
pub fn score_sequence(
    model: &ReducedModel,
    gel: &Gel,
    setup: &crate::setup::Setup,
    fem: &FemSequence,
    options: ReducedOptions,
    repeats: usize,
    enrich: Option<Enrichment>,
    nonlinear: Option<&crate::hyper::NonlinearGel>,
) -> Result<SequenceScore> {
    let indenter = Indenter::from_stl(&setup.stl)?;
    let mut seconds = Vec::new();
    let mut frames = Vec::new();
    let deepest = fem.depth_m.iter().copied().fold(0.0, f64::max);
    let mut local = None;
    for _ in 0..repeats.max(1) {
        let t0 = std::time::Instant::now();
        // Per-placement modes are part of each timed run: a new placement pays for them.
        if let Some(enrich) = enrich {
            let approach = Approach::new(&setup.name, gel, &indenter, setup.placement)?;
            local = Some(placement_model(
                model, enrich, gel, &indenter, &approach, deepest,
            )?);
        }
        let model = local.as_ref().unwrap_or(model);
        let mut run =
            ReducedIndentation::new(&setup.name, model, gel, &indenter, setup.placement, options)?;
        if let Some(nl) = nonlinear {
            run = run.with_nonlinear(nl);
        }
        frames.clear();
        for &d in &fem.depth_m {
            let f = run.advance_to(d)?;
            let top = model.displacement_of(&gel.top, &f.q);
            std::hint::black_box(&top);
            frames.push(f);
        }
        seconds.push(t0.elapsed().as_secs_f64());
    }
    let mut s = SequenceScore {
        setup: setup.name.clone(),
        frames: frames.len(),
        depth_m: fem.depth_m.clone(),
        rmse_m: Vec::new(),
        rmse_top_m: Vec::new(),
        projection_rmse_m: Vec::new(),
        force_z_n: Vec::new(),
        max_penetration_m: frames
            .iter()
            .map(|f| f.max_penetration_m)
            .fold(0.0, f64::max),
        passes: frames.iter().map(|f| f.passes).sum(),
        queries: frames.iter().map(|f| f.queries).sum(),
        seconds,
    };
    s.depth_m.truncate(s.frames);
    let model = local.as_ref().unwrap_or(model);
    for ((f, u), force) in frames.iter().zip(&fem.displacement).zip(&fem.force_n) {
        let ur = model.displacement(&f.q);
        s.rmse_m.push(crate::metrics::nodal_rmse(&ur, u)?);
        let top_r: Vec<[f64; 3]> = gel.top.iter().map(|&i| ur[i]).collect();
        let top_f: Vec<[f64; 3]> = gel.top.iter().map(|&i| u[i]).collect();
        s.rmse_top_m
            .push(crate::metrics::nodal_rmse(&top_r, &top_f)?);
        let up = model.displacement(&model.project(u));
        s.projection_rmse_m
            .push(crate::metrics::nodal_rmse(&up, u)?);
        s.force_z_n.push([f.indenter_force_n[2], force[2]]);
    }
    Ok(s)
}

/// The frame of the largest nodal RMSE over several scored sequences.
#[derive(Debug, Clone, Serialize)]
pub struct WorstFrame {
    /// Set-up name.
    pub setup: String,
    /// Depth of the frame, m.
    pub depth_m: f64,
    /// Nodal RMSE over all nodes, m.
    pub rmse_m: f64,
    /// Nodal RMSE over the top face, m.
    pub rmse_top_m: f64,
    /// The basis' own limit at that frame (projection RMSE), m.
    pub projection_rmse_m: f64,
}

/// The worst frame (largest all-node RMSE) of `scores`; `None` when no frame was scored.
pub fn worst_frame(scores: &[SequenceScore]) -> Option<WorstFrame> {
    scores
        .iter()
        .flat_map(|s| (0..s.rmse_m.len()).map(move |k| (s, k)))
        .max_by(|a, b| a.0.rmse_m[a.1].total_cmp(&b.0.rmse_m[b.1]))
        .map(|(s, k)| WorstFrame {
            setup: s.setup.clone(),
            depth_m: s.depth_m.get(k).copied().unwrap_or(f64::NAN),
            rmse_m: s.rmse_m[k],
            rmse_top_m: s.rmse_top_m[k],
            projection_rmse_m: s.projection_rmse_m[k],
        })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::gel::GelMaterial;
    use crate::indent::{IndentOptions, Indentation};
    use ocm_mor::pod::Truncation;

    /// A 6 x 4 x 2 mm block of tets, base fixed, top at z = 2 mm.
    fn block() -> Gel {
        let mesh = ocm_fem::mesh::generate::box_mesh([12, 8, 4], [6e-3, 4e-3, 2e-3]);
        Gel::from_mesh(mesh, GelMaterial::default(), 1e-9).unwrap()
    }

    fn place(x: f64, y: f64) -> Placement {
        Placement {
            xy_m: [x, y],
            euler_deg: [0.0; 3],
        }
    }

    /// A sphere on the block, its FEM (depths, fields, forces) and the rank-8 reduced model
    /// built from those fields alone.
    #[allow(clippy::type_complexity)]
    fn sphere_with_its_own_modes() -> (
        Gel,
        Indenter,
        Placement,
        Vec<f64>,
        Vec<Vec<[f64; 3]>>,
        Vec<f64>,
        ReducedModel,
    ) {
        let gel = block();
        let ind = crate::shapes::sphere(1.5e-3, 32).unwrap();
        let p = place(3e-3, 2e-3);
        let (depths, fields, force) = fem(&gel, &ind, p);
        let opts = PodOptions {
            truncation: Truncation::Rank(8),
            oversampling: 4,
            power_iterations: 2,
            seed: 3,
        };
        let m = ReducedModel::build(&gel, "block", &fields, vec!["fem".into()], &opts).unwrap();
        (gel, ind, p, depths, fields, force, m)
    }

    /// The full FEM of a sphere pressed 8 x 25 um at `p`.
    fn fem(gel: &Gel, ind: &Indenter, p: Placement) -> (Vec<f64>, Vec<Vec<[f64; 3]>>, Vec<f64>) {
        let mut o = IndentOptions::protocol(gel.material.young_pa);
        o.steps = 8;
        o.step_m = 25e-6;
        let mut run = Indentation::new("fem", gel, ind, p, o).unwrap();
        let out = run.run(|_| {}).unwrap();
        (
            out.iter().map(|s| s.depth_m).collect(),
            out.iter().map(|s| s.displacement.clone()).collect(),
            out.iter().map(|s| s.indenter_force_n[2]).collect(),
        )
    }

    /// Built from the FEM of one placement with all its snapshots as modes, the reduced solve
    /// at that placement reproduces the FEM: the linearisation at rest and the discrete
    /// contact cost a few per cent of the field, and with the Neo-Hookean force of every
    /// element (`hyper`) it matches the FEM to 1 % of field and force; the stiffness is Phi^T K Phi (checked against
    /// the energy of a mode), the model survives a save/load round trip, and without contact
    /// it stays at rest.
    #[test]
    fn reduced_solve_reproduces_its_fem() {
        let (gel, ind, p, depths, fields, force, m) = sphere_with_its_own_modes();
        assert_eq!(m.rank(), 8);
        // Mode 0's stiffness entry equals twice the strain energy of a small multiple of it
        // (central difference of the fem's energy).
        let h = 1e-7;
        let pattern = Pattern::new(&gel.model).unwrap();
        let energy = |t: f64| {
            let mut x = gel.model.rest_dofs();
            for (i, v) in x.iter_mut().enumerate() {
                *v += t * m.modes[i * 8];
            }
            gel.model
                .evaluate(&pattern, &x, &Loads::default(), 1.0, false)
                .unwrap()
                .strain_energy
        };
        let k00 = (energy(h) - 2.0 * energy(0.0) + energy(-h)) / (h * h);
        assert!(
            (k00 - m.stiffness[(0, 0)]).abs() < 1e-3 * k00,
            "{k00} vs {}",
            m.stiffness[(0, 0)]
        );
        let dir = std::env::temp_dir().join(format!("ocm-reduced-{}", std::process::id()));
        m.save(&dir).unwrap();
        let back = ReducedModel::load(&dir).unwrap();
        std::fs::remove_dir_all(&dir).ok();
        assert_eq!(back.info, m.info);
        assert_eq!(back.modes, m.modes);
        // With the full model's stiff penalty: the basis holds this set-up's fields exactly.
        let mut ro = ReducedOptions::for_modulus(gel.material.young_pa);
        ro.normal_penalty_pa_m =
            crate::contact::ContactParams::for_modulus(gel.material.young_pa).normal_penalty_pa_m;
        let mut run = ReducedIndentation::new("rom", &back, &gel, &ind, p, ro).unwrap();
        let umax = fields
            .last()
            .unwrap()
            .iter()
            .map(|u| u[2].abs())
            .fold(0.0, f64::max);
        let mut linear = Vec::new();
        for ((d, u), f) in depths.iter().zip(&fields).zip(&force) {
            let fr = run.advance_to(*d).unwrap();
            let e = crate::metrics::nodal_rmse(&back.displacement(&fr.q), u).unwrap();
            let rms = crate::metrics::nodal_rmse(u, &vec![[0.0; 3]; u.len()]).unwrap();
            println!(
                "depth {:.3} mm: RMSE {:.2} um of a {:.2} um field; force {:.4} vs FEM {:.4} N",
                d * 1e3,
                e * 1e6,
                rms * 1e6,
                fr.indenter_force_n[2],
                f
            );
            assert!(e < 0.1 * rms, "depth {d}: RMSE {e} vs field {rms}");
            assert!((fr.indenter_force_n[2] - f).abs() < 0.1 * f.abs());
            linear.push((e, (fr.indenter_force_n[2] - f).abs()));
        }
        assert!(umax > 150e-6);
        // The same solve with the gel's Neo-Hookean force (every element, weight 1): the
        // linearisation at rest is gone, so field and force come closer to the FEM's.
        let all = crate::hyper::NonlinearGel::all_elements(&gel).unwrap();
        let mut run = ReducedIndentation::new("rom-nl", &back, &gel, &ind, p, ro)
            .unwrap()
            .with_nonlinear(&all);
        for (((d, u), f), (e_lin, f_lin)) in depths.iter().zip(&fields).zip(&force).zip(&linear) {
            let fr = run.advance_to(*d).unwrap();
            let e = crate::metrics::nodal_rmse(&back.displacement(&fr.q), u).unwrap();
            let df = (fr.indenter_force_n[2] - f).abs();
            println!(
                "nonlinear, depth {:.3} mm: RMSE {:.4} um (linear {:.2}); force error {:.2e} N (linear {:.4})",
                d * 1e3,
                e * 1e6,
                e_lin * 1e6,
                df,
                f_lin
            );
            // Measured: below 5 nm and 0.05 mN at every depth, against 0.01-0.72 um and
            // 0.1-5.3 mN for the linear solve: the linearisation was all of its error.
            let rms = crate::metrics::nodal_rmse(u, &vec![[0.0; 3]; u.len()]).unwrap();
            assert!(
                e < 0.01 * rms,
                "depth {d}: nonlinear RMSE {e} of a {rms} field"
            );
            assert!(df < 0.01 * f.abs(), "depth {d}: force error {df} of {f}");
            assert!(
                e < *e_lin && df < *f_lin,
                "depth {d}: no better than linear"
            );
        }
        // Lifted 1 mm off the gel: no contact, no displacement.
        let mut off = ReducedIndentation::new("off", &back, &gel, &ind, p, ro).unwrap();
        let fr = off.advance_to(-1e-3).unwrap();
        assert!(fr.active.is_empty());
        assert!(fr.q.iter().all(|&v| v == 0.0));
    }

    /// The mean gap held exactly, on a basis that holds the FEM's fields (a sphere's own 8
    /// fields): with the soft default penalty the indenter sinks into the subspace gel (mean
    /// gap -6 to -24 um); holding the contact's mean gap at zero puts it back on the surface,
    /// so field and force come closer to the FEM's at every depth.
    #[test]
    fn holding_the_mean_gap_puts_the_indenter_on_the_surface() {
        let (gel, ind, p, depths, fields, force, m) = sphere_with_its_own_modes();
        let approach = Approach::new("m", &gel, &ind, p).unwrap();
        let mut results = Vec::new();
        for hold in [false, true] {
            let mut ro = ReducedOptions::for_modulus(gel.material.young_pa);
            ro.hold_mean_gap = hold;
            let mut run = ReducedIndentation::new("m", &m, &gel, &ind, p, ro).unwrap();
            let mut out = Vec::new();
            for ((d, u), f) in depths.iter().zip(&fields).zip(&force) {
                let fr = run.advance_to(*d).unwrap();
                let ur = m.displacement(&fr.q);
                let e = crate::metrics::nodal_rmse(&ur, u).unwrap();
                // Area-weighted mean signed distance of the nodes in contact (parry's, at the
                // reduced field's positions).
                let placed = Placed {
                    indenter: &ind,
                    pose: approach.pose_at(*d),
                };
                let (mut w, mut g) = (0.0, 0.0);
                for (i, _, _) in &fr.active {
                    let k = gel.surface.iter().position(|s| s == i).unwrap();
                    let x = Vector3::from(gel.mesh.points[*i]) + Vector3::from(ur[*i]);
                    w += gel.area_m2[k];
                    g += gel.area_m2[k] * placed.query(&x).distance;
                }
                let df = (fr.indenter_force_n[2] - f).abs();
                println!(
                    "hold {hold}, depth {:.3} mm: RMSE {:.3} um, mean gap {:.3} um, force {:.4} vs FEM {:.4} N",
                    d * 1e3,
                    e * 1e6,
                    g / w * 1e6,
                    fr.indenter_force_n[2],
                    f
                );
                out.push((e, g / w, df));
            }
            results.push(out);
        }
        let (soft, held) = (&results[0], &results[1]);
        for (k, (s, h)) in soft.iter().zip(held).enumerate() {
            assert!(
                s.1 < -5e-6,
                "depth {k}: the soft penalty's mean gap {}",
                s.1
            );
            assert!(h.0 < s.0, "depth {k}: RMSE {} vs {} without", h.0, s.0);
            assert!(
                h.2 < s.2,
                "depth {k}: force error {} vs {} without",
                h.2,
                s.2
            );
        }
        // Measured: |mean gap| below 1 nm at 7 of 8 depths; at 0.1 mm the active set cycles
        // and the frozen multiplier leaves -20 um (as soft as without it, -24 um).
        let exact = held.iter().filter(|h| h.1.abs() < 1e-9).count();
        assert!(exact >= 7, "mean gap held at only {exact} depths");
        let worst = |v: &[(f64, f64, f64)]| v.iter().map(|x| x.0).fold(0.0, f64::max);
        // Measured 1.36 against 3.43 um.
        assert!(worst(held) < 0.5 * worst(soft));
    }

    /// Held out of the basis: built from the FEM of a sphere at twelve placements 0.5 mm apart
    /// (rank 24), the reduced solve (default options, as the benches run it) at a placement
    /// between them stays within a bound near its measured error, and `worst_frame` picks the
    /// frame of the largest error. A solve without contact, with the wrong stiffness or with
    /// the wrong gaps misses most of the field and fails this.
    const RANK_HELD_OUT: usize = 24;

    #[test]
    fn reduced_solve_generalises_to_a_held_out_placement() {
        let gel = block();
        let ind = crate::shapes::sphere(1.5e-3, 32).unwrap();
        let mut snaps = Vec::new();
        for x in [2.5e-3, 3.0e-3, 3.5e-3, 4.0e-3] {
            for y in [1.5e-3, 2.0e-3, 2.5e-3] {
                snaps.extend(fem(&gel, &ind, place(x, y)).1);
            }
        }
        let opts = PodOptions {
            truncation: Truncation::Rank(RANK_HELD_OUT),
            oversampling: 8,
            power_iterations: 2,
            seed: 5,
        };
        let m = ReducedModel::build(&gel, "block", &snaps, vec!["grid".into()], &opts).unwrap();
        let p = place(3.2e-3, 2.2e-3);
        let (depths, fields, _) = fem(&gel, &ind, p);
        let ro = ReducedOptions::for_modulus(gel.material.young_pa);
        let mut run = ReducedIndentation::new("held-out", &m, &gel, &ind, p, ro).unwrap();
        let mut score = SequenceScore {
            setup: "held-out".into(),
            frames: depths.len(),
            depth_m: depths.clone(),
            rmse_m: Vec::new(),
            rmse_top_m: Vec::new(),
            projection_rmse_m: Vec::new(),
            force_z_n: Vec::new(),
            max_penetration_m: 0.0,
            passes: 0,
            queries: 0,
            seconds: Vec::new(),
        };
        for (d, u) in depths.iter().zip(&fields) {
            let fr = run.advance_to(*d).unwrap();
            let ur = m.displacement(&fr.q);
            let e = crate::metrics::nodal_rmse(&ur, u).unwrap();
            let proj = crate::metrics::nodal_rmse(&m.displacement(&m.project(u)), u).unwrap();
            let rms = crate::metrics::nodal_rmse(u, &vec![[0.0; 3]; u.len()]).unwrap();
            println!(
                "depth {:.3} mm: RMSE {:.3} um ({:.1} % of the field), projection {:.3} um",
                d * 1e3,
                e * 1e6,
                100.0 * e / rms,
                proj * 1e6
            );
            // Measured: 38 and 23 % of the field at the two shallowest depths (a contact a few
            // nodes wide), 16-19 % below them; 1.8-4.5 times the projection limit.
            let bound = if *d < 60e-6 { 0.45 } else { 0.22 };
            assert!(e < bound * rms, "depth {d}: RMSE {e} of a {rms} field");
            assert!(e < 5.0 * proj, "depth {d}: RMSE {e}, projection {proj}");
            let top_r: Vec<[f64; 3]> = gel.top.iter().map(|&i| ur[i]).collect();
            let top_f: Vec<[f64; 3]> = gel.top.iter().map(|&i| u[i]).collect();
            score.rmse_m.push(e);
            score
                .rmse_top_m
                .push(crate::metrics::nodal_rmse(&top_r, &top_f).unwrap());
            score.projection_rmse_m.push(proj);
        }
        let w = worst_frame(std::slice::from_ref(&score)).unwrap();
        let k = score
            .rmse_m
            .iter()
            .enumerate()
            .max_by(|a, b| a.1.total_cmp(b.1))
            .unwrap()
            .0;
        assert_eq!(w.rmse_m, score.rmse_m[k]);
        assert_eq!(w.depth_m, depths[k]);
        assert_eq!(w.projection_rmse_m, score.projection_rmse_m[k]);
        assert!(worst_frame(&[]).is_none());

        // With the footprint modes of this placement: orthonormal columns, the stiffness
        // equal to Phi^T K_0 Phi of the grown basis, a lower projection limit at every depth and
        // the reduced solve within the bounds above.
        let rest = RestStiffness::new(&gel).unwrap();
        let approach = Approach::new("held-out", &gel, &ind, p).unwrap();
        let deepest = *depths.last().unwrap();
        let enrich = Enrichment {
            rest: &rest,
            loads: &DEFAULT_FOOTPRINT_LOADS,
        };
        let em = placement_model(&m, enrich, &gel, &ind, &approach, deepest).unwrap();
        let n = em.rank();
        // The sphere's footprint is a few nodes wide, all of them on its rim: one new mode.
        assert_eq!(n, RANK_HELD_OUT + 1);
        let rows = em.modes.len() / n;
        for a in 0..n {
            for b in 0..n {
                let dot: f64 = (0..rows)
                    .map(|d| em.modes[d * n + a] * em.modes[d * n + b])
                    .sum();
                let want = if a == b { 1.0 } else { 0.0 };
                assert!((dot - want).abs() < 1e-9, "columns {a}, {b}: {dot}");
            }
        }
        let k_direct = reduced_stiffness(&gel, &em.modes, n).unwrap();
        let scale = k_direct.abs().max();
        assert!(
            (&k_direct - &em.stiffness).abs().max() < 1e-9 * scale,
            "grown stiffness differs from Phi^T K Phi"
        );
        let mut run = ReducedIndentation::new("enriched", &em, &gel, &ind, p, ro).unwrap();
        let plain = score.rmse_m.iter().zip(&score.projection_rmse_m);
        for ((d, u), (plain, plain_proj)) in depths.iter().zip(&fields).zip(plain) {
            let fr = run.advance_to(*d).unwrap();
            let e = crate::metrics::nodal_rmse(&em.displacement(&fr.q), u).unwrap();
            let proj = crate::metrics::nodal_rmse(&em.displacement(&em.project(u)), u).unwrap();
            println!(
                "enriched, depth {:.3} mm: RMSE {:.3} um (POD alone {:.3}), projection {:.3} um",
                d * 1e3,
                e * 1e6,
                plain * 1e6,
                proj * 1e6
            );
            let rms = crate::metrics::nodal_rmse(u, &vec![[0.0; 3]; u.len()]).unwrap();
            assert!(
                proj < *plain_proj,
                "depth {d}: projection {proj} vs {plain_proj}"
            );
            let bound = if *d < 60e-6 { 0.45 } else { 0.22 };
            assert!(
                e < bound * rms,
                "depth {d}: enriched RMSE {e} of a {rms} field"
            );
        }
    }

    /// The footprint loads of a flat cylindrical punch (radius 1.2 mm) on the block's 0.5 mm
    /// grid of top nodes, checked against the geometry: the footprint is the top nodes within
    /// the radius, the rim those with an outside top node within the rim width, the in-plane
    /// loads point out of the footprint; the responses solve K_0 u = f, the modified-Newton
    /// correction is of second order in the field, and every load's mode keeps the grown basis
    /// orthonormal with the stiffness Phi^T K_0 Phi.
    #[test]
    fn footprint_loads_follow_the_indenter_geometry() {
        let gel = block();
        let punch = crate::shapes::cylinder(1.2e-3, 2e-3, 64).unwrap();
        let (cx, cy) = (3e-3, 2e-3);
        let p = place(cx, cy);
        let approach = Approach::new("punch", &gel, &punch, p).unwrap();
        let placed = Placed {
            indenter: &punch,
            pose: approach.pose_at(0.1e-3),
        };
        let rim_m = 0.6e-3;
        let cases = footprint_load_cases(&gel, &placed, rim_m);
        let at = |i: usize| gel.mesh.points[i];
        let r_of = |i: usize| ((at(i)[0] - cx).powi(2) + (at(i)[1] - cy).powi(2)).sqrt();
        let nodes = |label: &str| -> Vec<(usize, [f64; 3])> {
            cases
                .iter()
                .find(|(k, _)| *k == label)
                .map(|(_, l)| l.clone())
                .unwrap_or_else(|| panic!("no {label} loads"))
        };
        let foot: Vec<usize> = nodes("foot").iter().map(|(i, _)| *i).collect();
        let want: Vec<usize> = gel
            .top
            .iter()
            .copied()
            .filter(|&i| r_of(i) < 1.2e-3)
            .collect();
        let mut sorted = foot.clone();
        sorted.sort();
        let mut want_sorted = want.clone();
        want_sorted.sort();
        assert_eq!(sorted, want_sorted);
        assert_eq!(foot.len(), 21);
        let outside: Vec<usize> = gel
            .top
            .iter()
            .copied()
            .filter(|i| !foot.contains(i))
            .collect();
        let gap = |i: usize| -> f64 {
            outside
                .iter()
                .map(|&o| ((at(o)[0] - at(i)[0]).powi(2) + (at(o)[1] - at(i)[1]).powi(2)).sqrt())
                .fold(f64::INFINITY, f64::min)
        };
        let rim: Vec<usize> = nodes("rim").iter().map(|(i, _)| *i).collect();
        for &i in &foot {
            assert_eq!(
                rim.contains(&i),
                gap(i) < rim_m,
                "node {i} at r {}",
                r_of(i)
            );
        }
        assert!(!rim.is_empty() && rim.len() < foot.len());
        for label in ["out", "out_rim", "radial", "skirt"] {
            for (i, f) in nodes(label) {
                assert_eq!(f[2], 0.0, "{label}: in-plane");
                let along = f[0] * (at(i)[0] - cx) + f[1] * (at(i)[1] - cy);
                if r_of(i) > 1e-9 {
                    assert!(along > 0.0, "{label}: node {i} loaded towards the centre");
                }
                if label != "radial" {
                    assert!(((f[0].powi(2) + f[1].powi(2)).sqrt() - 1.0).abs() < 1e-12);
                }
            }
        }
        for (i, _) in nodes("skirt") {
            assert!(!foot.contains(&i) && r_of(i) < 1.2e-3 + 2.5 * rim_m);
        }

        // Responses: K_0 u = f on the free dofs, nothing on the fixed base.
        let rest = RestStiffness::new(&gel).unwrap();
        let loads = nodes("out");
        let u = rest.respond(&loads).unwrap();
        let uf: Vec<f64> = rest.pattern.dof_of.iter().map(|&d| u[d]).collect();
        let ku = ocm_fem::solve::spmv(&rest.pattern, &rest.values, &uf);
        let mut f = vec![0.0; 3 * gel.num_nodes()];
        for (i, v) in &loads {
            for d in 0..3 {
                f[3 * i + d] += v[d];
            }
        }
        let err: f64 = rest
            .pattern
            .dof_of
            .iter()
            .zip(&ku)
            .map(|(&d, k)| (k - f[d]).powi(2))
            .sum::<f64>()
            .sqrt();
        assert!(err < 1e-8 * (loads.len() as f64).sqrt(), "K_0 u - f: {err}");
        let z = rest.respond_z(&foot).unwrap();
        for i in (0..gel.num_nodes()).filter(|&i| at(i)[2] < 1e-9) {
            assert_eq!([u[3 * i], u[3 * i + 1], u[3 * i + 2]], [0.0; 3]);
        }

        // The correction of a field is the nonlinear remainder: second order in the field.
        let scale = 20e-6 / z.iter().map(|v| v.abs()).fold(0.0, f64::max);
        let c1 = rest
            .nonlinear_correction(&gel, &z.iter().map(|v| v * scale).collect::<Vec<_>>())
            .unwrap();
        let c2 = rest
            .nonlinear_correction(&gel, &z.iter().map(|v| 2.0 * v * scale).collect::<Vec<_>>())
            .unwrap();
        let norm = |v: &[f64]| v.iter().map(|x| x * x).sum::<f64>().sqrt();
        let ratio = norm(&c2) / norm(&c1);
        println!(
            "correction of a 20 um field: {:.3e} of it; doubled: ratio {ratio:.3}",
            norm(&c1) / (scale * norm(&z))
        );
        assert!((ratio - 4.0).abs() < 0.2, "second order: ratio {ratio}");
        assert!(norm(&c1) < 0.05 * scale * norm(&z));
        assert!(rest.nonlinear_correction(&gel, &[0.0; 3]).is_err());

        // Every load's mode: orthonormal columns, stiffness Phi^T K_0 Phi; a bad label refused.
        let ind = crate::shapes::sphere(1.5e-3, 32).unwrap();
        let snaps = fem(&gel, &ind, place(2.5e-3, 2e-3)).1;
        let opts = PodOptions {
            truncation: Truncation::Rank(6),
            oversampling: 4,
            power_iterations: 1,
            seed: 3,
        };
        let m = ReducedModel::build(&gel, "block", &snaps, vec!["one".into()], &opts).unwrap();
        let enrich = Enrichment {
            rest: &rest,
            loads: &FOOTPRINT_LOADS,
        };
        let em = placement_model(&m, enrich, &gel, &punch, &approach, 0.1e-3).unwrap();
        let n = em.rank();
        // placement_model's rim is FOOTPRINT_RIM_M, narrower than this grid: no rim loads.
        let used = footprint_load_cases(&gel, &placed, FOOTPRINT_RIM_M);
        println!("{} load cases, rank 6 + {}", used.len(), n - 6);
        assert!(!used.iter().any(|(k, _)| *k == "rim"));
        assert!(n > 6 + 4 && n <= 6 + used.len());
        // The grown basis holds every load's response (dependent ones add no mode).
        for (label, loads) in &used {
            let u = rest.respond(loads).unwrap();
            let nodal: Vec<[f64; 3]> = u.chunks(3).map(|c| [c[0], c[1], c[2]]).collect();
            let back = em.displacement(&em.project(&nodal));
            let miss = crate::metrics::nodal_rmse(&back, &nodal).unwrap();
            let size = crate::metrics::nodal_rmse(&nodal, &vec![[0.0; 3]; nodal.len()]).unwrap();
            assert!(
                miss < 1e-6 * size,
                "{label}: {miss} of {size} outside the basis"
            );
        }
        let rows = em.modes.len() / n;
        for a in 0..n {
            for b in 0..n {
                let dot: f64 = (0..rows)
                    .map(|d| em.modes[d * n + a] * em.modes[d * n + b])
                    .sum();
                let want = if a == b { 1.0 } else { 0.0 };
                assert!((dot - want).abs() < 1e-9, "columns {a}, {b}: {dot}");
            }
        }
        let k_direct = reduced_stiffness(&gel, &em.modes, n).unwrap();
        assert!((&k_direct - &em.stiffness).abs().max() < 1e-9 * k_direct.abs().max());
        // The second-order mode of the footprint load is a new direction, orthogonal to the
        // grown basis' columns like every other, and its label is checked like the loads'.
        let nl = Enrichment {
            rest: &rest,
            loads: &["foot", "nl_foot"],
        };
        let nm = placement_model(&m, nl, &gel, &punch, &approach, 0.1e-3).unwrap();
        assert_eq!(nm.rank(), 6 + 2);
        assert!(check_footprint_loads(&["nl_foot", "rim"]).is_ok());
        assert!(check_footprint_loads(&["nl_sideways"]).is_err());
        let bad = Enrichment {
            rest: &rest,
            loads: &["foot", "sideways"],
        };
        assert!(placement_model(&m, bad, &gel, &punch, &approach, 0.1e-3).is_err());
    }
}
