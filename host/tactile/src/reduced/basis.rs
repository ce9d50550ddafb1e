//! The reduced model's basis: POD modes of FEM displacement fields, the stiffness at rest
//! projected on them, and their files.

use crate::gel::Gel;
use crate::{Result, TactileError};
use faer::Mat;
use nalgebra::DMatrix;
use ocm_fem::model::{Loads, Pattern};
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
pub(super) fn reduced_stiffness(gel: &Gel, modes: &[f64], r: usize) -> Result<DMatrix<f64>> {
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
