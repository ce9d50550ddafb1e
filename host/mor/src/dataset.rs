//! Sharded datasets of (time, P_S, tip force, X_S, dX_S/dt) sequences as NPY with a JSON manifest.
//!
//! Layout of `DIR` (the contract the learned-dynamics and surrogate crates read; see README.md):
//! - `manifest.json`: [`Manifest`]: what was simulated (model kind and hash, basis hash, seed,
//!   time step, drive ranges), how many rows and sequences, the shard count, and per array its
//!   columns with units;
//! - `shard-IIII-of-NNNN/`: the arrays of sequences `[I S / N, (I + 1) S / N)` (S sequences), each
//!   a float64 C-order `.npy` of `rows x columns`, and `shard.json` ([`ShardRecord`], written last:
//!   a shard without it is unfinished) with its row count and the SHA-256 of every array file.
//!
//! Sequence k is simulated from rest with the inputs [`crate::drive::sequence`]`(seed, k)`, so a
//! shard's rows do not depend on the other shards: the shards' arrays stacked in shard order equal
//! the arrays of one unsharded run byte for byte (the data after the headers).

use crate::drive::{self, DriveConfig, Input};
use crate::xs::{XS_DIM, XS_NAMES};
use crate::{MorError, Result, sha256_hex};
use ocm_fem::npy;
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};

/// Format tag of the manifest.
pub const FORMAT: &str = "ocm-mor-dataset/1";

/// Which model produced the data.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum ModelKind {
    /// The full FEM.
    Full,
    /// The reduced (POD-Galerkin, ECSW) model.
    Reduced,
    /// The operator-inference reduced model (`ocm mor reduce --method opinf`).
    ReducedOpinf,
}

/// One array of a shard.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ArraySpec {
    /// File name inside each shard folder.
    pub file: String,
    /// Column names with units.
    pub columns: Vec<String>,
}

/// What a dataset holds.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Manifest {
    /// [`FORMAT`].
    pub format: String,
    /// Model kind.
    pub model: ModelKind,
    /// SHA-256 of the full model (mesh, material, scene), hex.
    pub model_hash: String,
    /// SHA-256 of the reduced model (basis and ECSW weights), hex; `null` for the full model.
    pub basis_hash: Option<String>,
    /// Rows (time steps) in all shards together.
    pub samples: usize,
    /// Steps per sequence (the last sequence may be shorter).
    pub sequence_steps: usize,
    /// Number of sequences.
    pub sequences: usize,
    /// Seed of the inputs.
    pub seed: u64,
    /// Time step, s.
    pub dt_s: f64,
    /// Input ranges.
    pub drive: DriveConfig,
    /// Number of shards.
    pub shards: usize,
    /// Arrays of every shard.
    pub arrays: Vec<ArraySpec>,
    /// Frame and meaning of X_S.
    pub frame: String,
}

/// The completion record of one shard.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ShardRecord {
    /// Shard index.
    pub shard: usize,
    /// Shard count.
    pub of: usize,
    /// First sequence.
    pub first_sequence: usize,
    /// One past the last sequence.
    pub end_sequence: usize,
    /// Rows.
    pub rows: usize,
    /// SHA-256 of each array file, in manifest order.
    pub sha256: Vec<String>,
    /// Wall time of the simulation, s.
    pub seconds: f64,
}

/// The arrays (names, columns) every shard holds.
pub fn array_specs() -> Vec<ArraySpec> {
    let s = |v: &[&str]| v.iter().map(|c| c.to_string()).collect::<Vec<_>>();
    let dot: Vec<String> = XS_NAMES.iter().map(|n| format!("d_{n}_per_s")).collect();
    vec![
        ArraySpec {
            file: "sequence.npy".into(),
            columns: s(&["sequence_index", "step_index"]),
        },
        ArraySpec {
            file: "time_s.npy".into(),
            columns: s(&["time_s"]),
        },
        ArraySpec {
            file: "pressure_kpa.npy".into(),
            columns: s(&["p1_kpa", "p2_kpa", "p3_kpa"]),
        },
        ArraySpec {
            file: "tip_force_n.npy".into(),
            columns: s(&["fx_n", "fy_n", "fz_n"]),
        },
        ArraySpec {
            file: "xs.npy".into(),
            columns: s(&XS_NAMES),
        },
        ArraySpec {
            file: "xs_dot.npy".into(),
            columns: dot,
        },
    ]
}

/// What to generate.
#[derive(Debug, Clone)]
pub struct DatasetSpec {
    /// Model kind.
    pub model: ModelKind,
    /// Model hash.
    pub model_hash: String,
    /// Basis hash (reduced model).
    pub basis_hash: Option<String>,
    /// Total rows.
    pub samples: usize,
    /// Steps per sequence.
    pub sequence_steps: usize,
    /// Seed.
    pub seed: u64,
    /// Inputs.
    pub drive: DriveConfig,
}

impl DatasetSpec {
    /// Number of sequences.
    pub fn sequences(&self) -> usize {
        self.samples.div_ceil(self.sequence_steps.max(1))
    }

    /// Steps of sequence `k`.
    pub fn steps_of(&self, k: usize) -> usize {
        (self.samples - k * self.sequence_steps).min(self.sequence_steps)
    }

    /// The manifest for `shards` shards.
    pub fn manifest(&self, shards: usize) -> Manifest {
        Manifest {
            format: FORMAT.into(),
            model: self.model,
            model_hash: self.model_hash.clone(),
            basis_hash: self.basis_hash.clone(),
            samples: self.samples,
            sequence_steps: self.sequence_steps,
            sequences: self.sequences(),
            seed: self.seed,
            dt_s: self.drive.dt_s,
            drive: self.drive,
            shards,
            arrays: array_specs(),
            frame: "mesh frame of the bellows: metres, z along the axis at rest, origin at the \
                    base-face centre; X_S = TCP (3), backbone arc length, curvature, top-plate \
                    rotation vector (3); xs_dot is d/dt of the same numbers; each row is the \
                    state after the step whose held inputs are on that row"
                .into(),
        }
    }
}

/// Folder of shard `i` of `n`.
pub fn shard_dir(dir: &Path, i: usize, n: usize) -> PathBuf {
    dir.join(format!("shard-{i:04}-of-{n:04}"))
}

/// Sequences of shard `i` of `n` among `s`.
pub fn shard_range(s: usize, i: usize, n: usize) -> (usize, usize) {
    (i * s / n, (i + 1) * s / n)
}

fn read_json<T: for<'de> Deserialize<'de>>(path: &Path) -> Result<T> {
    let text = std::fs::read_to_string(path).map_err(|e| MorError::io(path, e))?;
    serde_json::from_str(&text)
        .map_err(|e| MorError::file(path, format!("not a valid record: {e}")))
}

fn write_json(path: &Path, v: &impl Serialize) -> Result<()> {
    let text = serde_json::to_string_pretty(v).map_err(|e| MorError::Invalid(e.to_string()))?;
    std::fs::write(path, text).map_err(|e| MorError::io(path, e))
}

/// Compares a manifest on disk with the one a run would write; names the first difference.
fn check_manifest(path: &Path, have: &Manifest, want: &Manifest) -> Result<()> {
    let a = serde_json::to_value(have).map_err(|e| MorError::Invalid(e.to_string()))?;
    let b = serde_json::to_value(want).map_err(|e| MorError::Invalid(e.to_string()))?;
    if let (Some(a), Some(b)) = (a.as_object(), b.as_object()) {
        for (k, v) in b {
            if a.get(k) != Some(v) {
                return Err(MorError::file(
                    path,
                    format!(
                        "{k} is {} but this run has {v} (another dataset lives here: use another --out)",
                        a.get(k).map_or("missing".to_string(), |x| x.to_string())
                    ),
                ));
            }
        }
    }
    Ok(())
}

/// X_S and its rate after each step of a sequence.
pub type XsRows = Vec<[f64; 2 * XS_DIM]>;

/// What a shard run did.
#[derive(Debug, Clone, Serialize)]
pub struct ShardOutcome {
    /// The shard folder.
    pub dir: PathBuf,
    /// True when the shard was already complete and valid.
    pub skipped: bool,
    /// Its record.
    pub record: ShardRecord,
}

/// Writes shard `shard` of `shards` into `dir`, simulating each sequence with `simulate` (inputs
/// to X_S and its rate per step). A complete, valid shard is skipped.
pub fn write_shard(
    dir: &Path,
    spec: &DatasetSpec,
    shard: usize,
    shards: usize,
    simulate: &mut dyn FnMut(&[Input]) -> Result<XsRows>,
    progress: &mut dyn FnMut(usize, usize),
) -> Result<ShardOutcome> {
    if shards == 0 || shard >= shards {
        return Err(MorError::Invalid(format!(
            "shard {shard}/{shards}: the index must be below the count"
        )));
    }
    if spec.samples == 0 || spec.sequence_steps == 0 {
        return Err(MorError::Invalid(
            "a dataset needs samples and sequence steps".into(),
        ));
    }
    std::fs::create_dir_all(dir).map_err(|e| MorError::io(dir, e))?;
    let want = spec.manifest(shards);
    let mpath = dir.join("manifest.json");
    if mpath.exists() {
        let have: Manifest = read_json(&mpath)?;
        check_manifest(&mpath, &have, &want)?;
    } else {
        write_json(&mpath, &want)?;
    }
    let sdir = shard_dir(dir, shard, shards);
    let rpath = sdir.join("shard.json");
    if rpath.exists() {
        let rec = validate_shard(dir, &want, shard)?;
        return Ok(ShardOutcome {
            dir: sdir,
            skipped: true,
            record: rec,
        });
    }
    std::fs::create_dir_all(&sdir).map_err(|e| MorError::io(&sdir, e))?;
    let (a, b) = shard_range(spec.sequences(), shard, shards);
    let mut cols: Vec<Vec<f64>> = vec![vec![]; 6];
    let t0 = std::time::Instant::now();
    let total: usize = (a..b).map(|k| spec.steps_of(k)).sum();
    let mut done = 0;
    for k in a..b {
        let steps = spec.steps_of(k);
        let inputs = drive::sequence(&spec.drive, spec.seed, k as u64, steps);
        let xs = simulate(&inputs)?;
        if xs.len() != steps {
            return Err(MorError::Invalid(format!(
                "sequence {k}: simulator returned {} rows for {steps} steps",
                xs.len()
            )));
        }
        for (j, (inp, x)) in inputs.iter().zip(&xs).enumerate() {
            cols[0].extend([k as f64, j as f64]);
            cols[1].push((j + 1) as f64 * spec.drive.dt_s);
            cols[2].extend(inp.pressure_kpa);
            cols[3].extend(inp.tip_force_n);
            cols[4].extend(&x[..XS_DIM]);
            cols[5].extend(&x[XS_DIM..]);
        }
        done += steps;
        progress(done, total);
    }
    let seconds = t0.elapsed().as_secs_f64();
    let mut sha = vec![];
    for (arr, data) in want.arrays.iter().zip(&cols) {
        let path = sdir.join(&arr.file);
        let ncol = arr.columns.len();
        let mut bytes = vec![];
        npy::write_f64_2d(&mut bytes, data, data.len() / ncol, ncol)?;
        std::fs::write(&path, &bytes).map_err(|e| MorError::io(&path, e))?;
        sha.push(sha256_hex(&bytes));
    }
    let record = ShardRecord {
        shard,
        of: shards,
        first_sequence: a,
        end_sequence: b,
        rows: total,
        sha256: sha,
        seconds,
    };
    write_json(&rpath, &record)?;
    Ok(ShardOutcome {
        dir: sdir,
        skipped: false,
        record,
    })
}

/// Checks a finished shard against the manifest: record, file hashes, shapes.
pub fn validate_shard(dir: &Path, manifest: &Manifest, shard: usize) -> Result<ShardRecord> {
    let n = manifest.shards;
    let sdir = shard_dir(dir, shard, n);
    let rpath = sdir.join("shard.json");
    if !rpath.exists() {
        return Err(MorError::file(&rpath, "missing: the shard is unfinished"));
    }
    let rec: ShardRecord = read_json(&rpath)?;
    let (a, b) = shard_range(manifest.sequences, shard, n);
    if (rec.shard, rec.of, rec.first_sequence, rec.end_sequence) != (shard, n, a, b) {
        return Err(MorError::file(
            &rpath,
            format!(
                "records shard {}/{} sequences {}..{}, the manifest expects {shard}/{n} sequences {a}..{b}",
                rec.shard, rec.of, rec.first_sequence, rec.end_sequence
            ),
        ));
    }
    let spec_rows: usize = (a..b)
        .map(|k| (manifest.samples - k * manifest.sequence_steps).min(manifest.sequence_steps))
        .sum();
    if rec.rows != spec_rows {
        return Err(MorError::file(
            &rpath,
            format!("{} rows, the manifest implies {spec_rows}", rec.rows),
        ));
    }
    if rec.sha256.len() != manifest.arrays.len() {
        return Err(MorError::file(&rpath, "wrong number of array hashes"));
    }
    for (arr, sha) in manifest.arrays.iter().zip(&rec.sha256) {
        let path = sdir.join(&arr.file);
        let bytes = std::fs::read(&path).map_err(|e| MorError::io(&path, e))?;
        let a = npy::parse_f64_2d(&bytes, &path.display().to_string())?;
        if (a.rows, a.cols) != (rec.rows, arr.columns.len()) {
            return Err(MorError::file(
                &path,
                format!(
                    "shape ({}, {}) but the manifest says ({}, {})",
                    a.rows,
                    a.cols,
                    rec.rows,
                    arr.columns.len()
                ),
            ));
        }
        if &sha256_hex(&bytes) != sha {
            return Err(MorError::file(
                &path,
                "content differs from the SHA-256 in shard.json (modified or corrupt)",
            ));
        }
    }
    Ok(rec)
}

/// A dataset read back: the manifest and every array with all shards stacked.
#[derive(Debug, Clone)]
pub struct Dataset {
    /// Manifest.
    pub manifest: Manifest,
    /// Arrays in manifest order (row-major, `samples x columns`).
    pub arrays: Vec<Vec<f64>>,
}

/// Reads and checks a complete dataset; `basis_hash`, when given, must match the manifest's.
pub fn read(dir: &Path, basis_hash: Option<&str>) -> Result<Dataset> {
    let mpath = dir.join("manifest.json");
    let manifest: Manifest = read_json(&mpath)?;
    if manifest.format != FORMAT {
        return Err(MorError::file(
            &mpath,
            format!("format '{}' is not '{FORMAT}'", manifest.format),
        ));
    }
    if manifest.arrays != array_specs() {
        return Err(MorError::file(
            &mpath,
            "array list differs from this version's",
        ));
    }
    // the shard checks below derive each sequence's rows from these three
    if manifest.samples == 0
        || manifest.sequence_steps == 0
        || manifest.shards == 0
        || manifest.samples.div_ceil(manifest.sequence_steps) != manifest.sequences
    {
        return Err(MorError::file(
            &mpath,
            format!(
                "samples {}, sequence_steps {}, sequences {} and shards {} do not fit together (need samples >= 1, sequence_steps >= 1, shards >= 1 and sequences = ceil(samples / sequence_steps))",
                manifest.samples, manifest.sequence_steps, manifest.sequences, manifest.shards
            ),
        ));
    }
    if let Some(h) = basis_hash
        && manifest.basis_hash.as_deref() != Some(h)
    {
        return Err(MorError::file(
            &mpath,
            format!(
                "basis hash {} does not match the reduced model's {h}",
                manifest
                    .basis_hash
                    .as_deref()
                    .unwrap_or("(none: full model)")
            ),
        ));
    }
    let mut arrays = vec![vec![]; manifest.arrays.len()];
    for s in 0..manifest.shards {
        validate_shard(dir, &manifest, s)?;
        let sdir = shard_dir(dir, s, manifest.shards);
        for (k, arr) in manifest.arrays.iter().enumerate() {
            arrays[k].extend(npy::read_f64_2d(sdir.join(&arr.file))?.data);
        }
    }
    let rows = arrays[0].len() / 2;
    if rows != manifest.samples {
        return Err(MorError::file(
            &mpath,
            format!(
                "{} samples declared, the shards hold {rows}",
                manifest.samples
            ),
        ));
    }
    Ok(Dataset { manifest, arrays })
}
