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
        let nodes = probe.nodes();
        let r = rom.rank();
        let mut rows = DMatrix::zeros(3 * nodes.len(), r);
        for (k, &i) in nodes.iter().enumerate() {
            for d in 0..3 {
                rows.row_mut(3 * k + d).copy_from(&rom.basis.row(3 * i + d));
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
