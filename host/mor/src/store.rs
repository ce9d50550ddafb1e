//! Bases and reduced models on disk, tied to the model they reduce by hashes.
//!
//! `DIR/basis.npy` (3N x r, float64) with `DIR/pod.json` ([`PodRecord`]); `DIR/ecsw.npy`
//! (n x 2: element index, weight) with `DIR/rom.json` ([`RomRecord`]).

use crate::rom::ReducedModel;
use crate::xs::{XS_DIM, XsProbe};
use crate::{MorError, Result, sha256_f64, sha256_hex};
use nalgebra::{DMatrix, DVector, Vector3};
use ocm_fem::bellows::Bellows;
use ocm_fem::npy;
use serde::{Deserialize, Serialize};
use std::path::Path;

/// SHA-256 of the full model: rest geometry, connectivity, material, scene parameters.
pub fn model_hash(b: &Bellows) -> String {
    let mut v: Vec<f64> = b.model.rest.iter().flat_map(|p| [p.x, p.y, p.z]).collect();
    for g in &b.model.elements {
        v.extend(g.nodes.iter().map(|&i| i as f64));
    }
    let cfg = serde_json::to_string(&b.config).unwrap_or_default();
    sha256_hex(format!("{}|{cfg}", sha256_f64(&v)).as_bytes())
}

/// SHA-256 of a basis (3N x r, column-major values and shape).
pub fn basis_hash(basis: &DMatrix<f64>) -> String {
    let mut v = vec![basis.nrows() as f64, basis.ncols() as f64];
    v.extend(basis.iter());
    sha256_f64(&v)
}

/// SHA-256 of a reduced model: its basis hash and the ECSW elements and weights.
pub fn rom_hash(rom: &ReducedModel) -> String {
    let mut v: Vec<f64> = vec![];
    for e in &rom.elements {
        v.extend([e.element as f64, e.weight]);
    }
    sha256_hex(format!("{}|{}", basis_hash(&rom.basis), sha256_f64(&v)).as_bytes())
}

/// What `ocm mor pod` measured.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct PodRecord {
    /// Model hash.
    pub model_hash: String,
    /// Basis hash.
    pub basis_hash: String,
    /// DOFs (rows).
    pub dofs: usize,
    /// Rank.
    pub rank: usize,
    /// Snapshots used.
    pub snapshots: usize,
    /// Singular values computed.
    pub singular_values: Vec<f64>,
    /// Fraction of the energy captured.
    pub captured_energy: f64,
    /// Relative projection error of held-out snapshots.
    pub held_out_projection_error: f64,
    /// Wall time of the SVD, s.
    pub seconds: f64,
}

/// Writes a basis and its record.
pub fn save_basis(dir: &Path, basis: &DMatrix<f64>, rec: &PodRecord) -> Result<()> {
    std::fs::create_dir_all(dir).map_err(|e| MorError::io(dir, e))?;
    // Row-major on disk (numpy's C order): row d holds the r mode values of DOF d.
    let (m, r) = basis.shape();
    let mut rowmajor = Vec::with_capacity(m * r);
    for i in 0..m {
        rowmajor.extend(basis.row(i).iter());
    }
    npy::write_f64_2d_path(dir.join("basis.npy"), &rowmajor, m, r)?;
    let p = dir.join("pod.json");
    std::fs::write(
        &p,
        serde_json::to_string_pretty(rec).map_err(|e| MorError::Invalid(e.to_string()))?,
    )
    .map_err(|e| MorError::io(&p, e))
}

/// Reads a basis for the model with `model_hash`; checks shape and hashes.
pub fn load_basis(dir: &Path, model_hash: &str, dofs: usize) -> Result<(DMatrix<f64>, PodRecord)> {
    let jp = dir.join("pod.json");
    let text = std::fs::read_to_string(&jp).map_err(|e| MorError::io(&jp, e))?;
    let rec: PodRecord = serde_json::from_str(&text)
        .map_err(|e| MorError::file(&jp, format!("not a POD record: {e}")))?;
    if rec.model_hash != model_hash {
        return Err(MorError::file(
            &jp,
            format!(
                "made for model {}, not this model {model_hash}",
                rec.model_hash
            ),
        ));
    }
    let bp = dir.join("basis.npy");
    let a = npy::read_f64_2d(&bp)?;
    if (a.rows, a.cols) != (dofs, rec.rank) {
        return Err(MorError::file(
            &bp,
            format!(
                "shape ({}, {}) but the model has {dofs} DOFs and pod.json rank {}",
                a.rows, a.cols, rec.rank
            ),
        ));
    }
    let basis = DMatrix::from_row_slice(a.rows, a.cols, &a.data);
    if basis_hash(&basis) != rec.basis_hash {
        return Err(MorError::file(
            &bp,
            "basis hash differs from pod.json (modified or corrupt)",
        ));
    }
    Ok((basis, rec))
}

/// What `ocm mor reduce` built.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct RomRecord {
    /// Basis hash.
    pub basis_hash: String,
    /// Reduced-model hash (basis and ECSW).
    pub rom_hash: String,
    /// Rank.
    pub rank: usize,
    /// ECSW tolerance.
    pub ecsw_tolerance: f64,
    /// Elements kept of the straining ones.
    pub elements: usize,
    /// Straining elements of the full model.
    pub full_elements: usize,
    /// Training residual.
    pub relative_residual: f64,
}

/// Writes ECSW weights and the record.
pub fn save_rom(dir: &Path, rom: &ReducedModel, rec: &RomRecord) -> Result<()> {
    std::fs::create_dir_all(dir).map_err(|e| MorError::io(dir, e))?;
    let v: Vec<f64> = rom
        .elements
        .iter()
        .flat_map(|e| [e.element as f64, e.weight])
        .collect();
    npy::write_f64_2d_path(dir.join("ecsw.npy"), &v, rom.elements.len(), 2)?;
    let p = dir.join("rom.json");
    std::fs::write(
        &p,
        serde_json::to_string_pretty(rec).map_err(|e| MorError::Invalid(e.to_string()))?,
    )
    .map_err(|e| MorError::io(&p, e))
}

/// Rebuilds a hyper-reduced model from its Galerkin model and the saved weights.
pub fn load_rom(dir: &Path, galerkin: &ReducedModel) -> Result<(ReducedModel, RomRecord)> {
    let jp = dir.join("rom.json");
    let text = std::fs::read_to_string(&jp).map_err(|e| MorError::io(&jp, e))?;
    let rec: RomRecord = serde_json::from_str(&text)
        .map_err(|e| MorError::file(&jp, format!("not a ROM record: {e}")))?;
    if rec.basis_hash != basis_hash(&galerkin.basis) {
        return Err(MorError::file(
            &jp,
            "made for another basis (basis hash differs)",
        ));
    }
    let wp = dir.join("ecsw.npy");
    let a = npy::read_f64_2d(&wp)?;
    if a.cols != 2 {
        return Err(MorError::file(
            &wp,
            format!("{} columns, expected 2 (element, weight)", a.cols),
        ));
    }
    let index: std::collections::HashMap<usize, usize> = galerkin
        .elements
        .iter()
        .enumerate()
        .map(|(k, e)| (e.element, k))
        .collect();
    let mut rom = galerkin.clone();
    rom.elements = a
        .data
        .chunks_exact(2)
        .enumerate()
        .map(|(row, c)| {
            let e = c[0] as usize;
            match index.get(&e) {
                Some(&k) if c[1] > 0.0 && c[0] == e as f64 => {
                    let mut el = galerkin.elements[k].clone();
                    el.weight = c[1];
                    Ok(el)
                }
                _ => Err(MorError::file(
                    &wp,
                    format!("row {row}: element {} weight {} is not valid", c[0], c[1]),
                )),
            }
        })
        .collect::<Result<_>>()?;
    if rom_hash(&rom) != rec.rom_hash {
        return Err(MorError::file(
            &wp,
            "weights differ from rom.json's hash (modified or corrupt)",
        ));
    }
    Ok((rom, rec))
}

/// X_S reader for reduced states: the basis rows of the probe nodes only.
#[derive(Debug, Clone)]
pub struct ReducedProbe {
    probe: XsProbe,
    slot: std::collections::HashMap<usize, usize>,
    rows: DMatrix<f64>,
}

impl ReducedProbe {
    /// Gathers the rows of `rom`'s basis that X_S reads.
    pub fn new(probe: XsProbe, rom: &ReducedModel) -> Self {
        Self::of_basis(probe, &rom.basis)
    }

    /// Gathers the rows of `basis` (3N x r) that X_S reads.
    pub fn of_basis(probe: XsProbe, basis: &DMatrix<f64>) -> Self {
        let nodes = probe.nodes();
        let r = basis.ncols();
        let mut rows = DMatrix::zeros(3 * nodes.len(), r);
        for (k, &i) in nodes.iter().enumerate() {
            for d in 0..3 {
                rows.row_mut(3 * k + d).copy_from(&basis.row(3 * i + d));
            }
        }
        ReducedProbe {
            slot: nodes.iter().enumerate().map(|(k, &i)| (i, k)).collect(),
            probe,
            rows,
        }
    }

    /// X_S and its rate of reduced coordinates and velocities (through [`XsProbe::compact_state`]).
    pub fn compact_state(&self, q: &DVector<f64>, v: &DVector<f64>) -> [f64; 2 * XS_DIM] {
        let u = &self.rows * q;
        let w = &self.rows * v;
        let at = |f: &DVector<f64>, i: usize| {
            let k = self.slot.get(&i).copied().unwrap_or(usize::MAX);
            if k == usize::MAX {
                Vector3::zeros()
            } else {
                Vector3::new(f[3 * k], f[3 * k + 1], f[3 * k + 2])
            }
        };
        self.probe.compact_state(&|i| at(&u, i), &|i| at(&w, i))
    }
}

/// What `ocm mor snapshots` stored beside `displacements.npy` and `xs.npy`.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct SnapshotRecord {
    /// Model hash.
    pub model_hash: String,
    /// Seed of the inputs.
    pub seed: u64,
    /// Training sequences (the first ones).
    pub sequences: usize,
    /// Held-out sequences (after the training ones, never used to fit).
    pub held_out: usize,
    /// Steps per sequence.
    pub steps: usize,
    /// Time step, s.
    pub dt_s: f64,
    /// Degrees of freedom (3N).
    pub dofs: usize,
    /// Full-model wall time per step, s (mean over all sequences).
    pub seconds_per_step: f64,
}

/// Snapshots on disk: the record, displacements (M x 3N, m) and X_S with its rate (M x 16).
#[derive(Debug, Clone)]
pub struct Snapshots {
    /// The record.
    pub rec: SnapshotRecord,
    /// Rows = snapshots (M x 3N), m.
    pub disp: npy::Array2,
    /// Rows = X_S and rate per snapshot.
    pub xs: npy::Array2,
}

/// Writes `S/displacements.npy`, `S/xs.npy` and `S/snapshots.json`.
pub fn save_snapshots(dir: &Path, rec: &SnapshotRecord, disp: &[f64], xs: &[f64]) -> Result<()> {
    std::fs::create_dir_all(dir).map_err(|e| MorError::io(dir, e))?;
    let m = (rec.sequences + rec.held_out) * rec.steps;
    npy::write_f64_2d_path(dir.join("displacements.npy"), disp, m, rec.dofs)?;
    npy::write_f64_2d_path(dir.join("xs.npy"), xs, m, 2 * XS_DIM)?;
    let p = dir.join("snapshots.json");
    std::fs::write(
        &p,
        serde_json::to_string_pretty(rec).map_err(|e| MorError::Invalid(e.to_string()))?,
    )
    .map_err(|e| MorError::io(&p, e))
}

/// Reads snapshots of the model with `model_hash`; checks the record against the arrays.
pub fn load_snapshots(dir: &Path, model_hash: &str) -> Result<Snapshots> {
    let jp = dir.join("snapshots.json");
    let text = std::fs::read_to_string(&jp).map_err(|e| MorError::io(&jp, e))?;
    let rec: SnapshotRecord = serde_json::from_str(&text)
        .map_err(|e| MorError::file(&jp, format!("not a snapshot record: {e}")))?;
    if rec.model_hash != model_hash {
        return Err(MorError::file(
            &jp,
            format!(
                "snapshots of model {}, not of this model {model_hash}",
                rec.model_hash
            ),
        ));
    }
    let m = (rec.sequences + rec.held_out) * rec.steps;
    let dp = dir.join("displacements.npy");
    let disp = npy::read_f64_2d(&dp)?;
    if (disp.rows, disp.cols) != (m, rec.dofs) {
        return Err(MorError::file(
            &dp,
            format!(
                "shape ({}, {}) but snapshots.json implies ({m}, {})",
                disp.rows, disp.cols, rec.dofs
            ),
        ));
    }
    let xp = dir.join("xs.npy");
    let xs = npy::read_f64_2d(&xp)?;
    if (xs.rows, xs.cols) != (m, 2 * XS_DIM) {
        return Err(MorError::file(
            &xp,
            format!(
                "shape ({}, {}) but expected ({m}, {})",
                xs.rows,
                xs.cols,
                2 * XS_DIM
            ),
        ));
    }
    Ok(Snapshots { rec, disp, xs })
}

impl Snapshots {
    /// Rows of the training sequences.
    pub fn train_rows(&self) -> usize {
        self.rec.sequences * self.rec.steps
    }

    /// Column-major 3N x (b - a) matrix of snapshot rows a..b.
    pub fn matrix(&self, a: usize, b: usize) -> faer::Mat<f64> {
        let n = self.disp.cols;
        faer::Mat::<f64>::from_fn(n, b - a, |i, j| self.disp.data[(a + j) * n + i])
    }

    /// X_S row `k`.
    pub fn xs_row(&self, k: usize) -> [f64; 2 * XS_DIM] {
        let mut o = [0.0; 2 * XS_DIM];
        o.copy_from_slice(&self.xs.data[k * 2 * XS_DIM..(k + 1) * 2 * XS_DIM]);
        o
    }

    /// Held-out sequences: (sequence index, inputs, full-model X_S rows).
    pub fn held_out(
        &self,
        drive: &crate::drive::DriveConfig,
    ) -> Vec<(usize, Vec<crate::drive::Input>, Vec<[f64; 2 * XS_DIM]>)> {
        let r = &self.rec;
        (r.sequences..r.sequences + r.held_out)
            .map(|k| {
                let inputs = crate::drive::sequence(drive, r.seed, k as u64, r.steps);
                let xs = (0..r.steps).map(|j| self.xs_row(k * r.steps + j)).collect();
                (k, inputs, xs)
            })
            .collect()
    }

    /// Reduced coordinates V^T u of every `every`-th training snapshot (ECSW training set).
    pub fn training_q(&self, basis: &DMatrix<f64>, every: usize) -> Vec<DVector<f64>> {
        let n = self.disp.cols;
        (0..self.train_rows())
            .step_by(every.max(1))
            .map(|k| {
                basis.transpose() * DVector::from_column_slice(&self.disp.data[k * n..(k + 1) * n])
            })
            .collect()
    }
}
