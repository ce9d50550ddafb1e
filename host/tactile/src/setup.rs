//! Indentation set-ups (`indenter_settings.json`, `unseen_indenter_settings.json`): which
//! indenter, where over the gel and how rotated.

use crate::indent::Placement;
use crate::{Result, TactileError};
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};

/// One set-up as the files give it.
#[derive(Debug, Clone, Deserialize)]
pub struct SetupRecord {
    /// Set-up name (e.g. `edge6`).
    pub name: String,
    /// The original scene's STL path (e.g. `Indenter/edge.STL`); only its file name is used.
    pub filename_stl: String,
    /// Indenter origin, mm (z is the original start height and is not used: depth is measured
    /// from first touch).
    pub translation: [f64; 3],
    /// Euler angles, degrees.
    pub orientation: [f64; 3],
}

/// A set-up resolved against the indenter folder.
#[derive(Debug, Clone)]
pub struct Setup {
    /// Set-up name.
    pub name: String,
    /// The indenter STL on disk.
    pub stl: PathBuf,
    /// Placement over the gel.
    pub placement: Placement,
    /// Whether it comes from the unseen set.
    pub unseen: bool,
}

/// Reads a set-up file and resolves each indenter in `stl_dir` (file names compared without
/// case). A set-up naming an STL that is not there is an error that names both.
pub fn read_setups(json: &Path, stl_dir: &Path, unseen: bool) -> Result<Vec<Setup>> {
    let text = std::fs::read_to_string(json).map_err(|e| TactileError::io(json, e))?;
    let records: Vec<SetupRecord> =
        serde_json::from_str(&text).map_err(|e| TactileError::Setup {
            setup: json.display().to_string(),
            msg: format!("not a list of set-ups: {e}"),
        })?;
    let listing: Vec<PathBuf> = std::fs::read_dir(stl_dir)
        .map_err(|e| TactileError::io(stl_dir, e))?
        .filter_map(|e| e.ok().map(|e| e.path()))
        .collect();
    records
        .into_iter()
        .map(|r| {
            let file = r
                .filename_stl
                .rsplit(['/', '\\'])
                .next()
                .unwrap_or("")
                .to_lowercase();
            let stl = listing
                .iter()
                .find(|p| {
                    p.file_name()
                        .is_some_and(|n| n.to_string_lossy().to_lowercase() == file)
                })
                .cloned()
                .ok_or_else(|| TactileError::Setup {
                    setup: r.name.clone(),
                    msg: format!(
                        "names indenter '{}', which is not in {}",
                        r.filename_stl,
                        stl_dir.display()
                    ),
                })?;
            if r.translation
                .iter()
                .chain(&r.orientation)
                .any(|v| !v.is_finite())
            {
                return Err(TactileError::Setup {
                    setup: r.name.clone(),
                    msg: "translation or orientation is not finite".into(),
                });
            }
            Ok(Setup {
                placement: Placement {
                    xy_m: [r.translation[0] * 1e-3, r.translation[1] * 1e-3],
                    euler_deg: r.orientation,
                },
                name: r.name,
                stl,
                unseen,
            })
        })
        .collect()
}

/// The seen and unseen DIGIT set-ups from the data directory's `digit/` folder.
pub fn digit_setups(digit_dir: &Path) -> Result<Vec<Setup>> {
    let mut s = read_setups(
        &digit_dir.join("indenter_settings.json"),
        &digit_dir.join("indenters"),
        false,
    )?;
    s.extend(read_setups(
        &digit_dir.join("unseen_indenter_settings.json"),
        &digit_dir.join("unseen-indenters"),
        true,
    )?);
    Ok(s)
}

/// A set-up as written beside its FEM results (`setup.json`): the indenter by file name, found
/// again in the data directory's `indenters/` or `unseen-indenters/`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SetupFile {
    /// Set-up name.
    pub name: String,
    /// File name of the indenter STL.
    pub stl_file: String,
    /// From the unseen set.
    pub unseen: bool,
    /// Indenter origin over the gel (x, y), m.
    pub xy_m: [f64; 2],
    /// Euler angles, degrees (R = Rz Ry Rx).
    pub euler_deg: [f64; 3],
}

impl Setup {
    /// Writes the set-up as `path` (JSON).
    pub fn write_json(&self, path: &Path) -> Result<()> {
        let f = SetupFile {
            name: self.name.clone(),
            stl_file: self
                .stl
                .file_name()
                .map(|n| n.to_string_lossy().into_owned())
                .unwrap_or_default(),
            unseen: self.unseen,
            xy_m: self.placement.xy_m,
            euler_deg: self.placement.euler_deg,
        };
        let text = serde_json::to_string_pretty(&f)
            .map_err(|e| TactileError::Input(format!("{}: {e}", path.display())))?;
        std::fs::write(path, text).map_err(|e| TactileError::io(path, e))
    }

    /// The set-up of a FEM results folder: its `setup.json` when present, otherwise the one named
    /// `name` among `known` (the data directory's set-ups).
    pub fn beside_fem(dir: &Path, name: &str, digit_dir: &Path, known: &[Setup]) -> Result<Setup> {
        let js = dir.join("setup.json");
        if js.is_file() {
            return Setup::read_json(&js, digit_dir);
        }
        known
            .iter()
            .find(|s| s.name == name)
            .cloned()
            .ok_or_else(|| TactileError::Setup {
                setup: name.to_string(),
                msg: format!(
                    "{}: no setup.json and no set-up of that name",
                    dir.display()
                ),
            })
    }

    /// Reads a set-up written by [`Setup::write_json`], resolving its STL in `digit_dir`; a
    /// missing STL or a non-finite placement is an error naming the file.
    pub fn read_json(path: &Path, digit_dir: &Path) -> Result<Setup> {
        let text = std::fs::read_to_string(path).map_err(|e| TactileError::io(path, e))?;
        let f: SetupFile = serde_json::from_str(&text)
            .map_err(|e| TactileError::Input(format!("{}: {e}", path.display())))?;
        let folder = if f.unseen {
            "unseen-indenters"
        } else {
            "indenters"
        };
        let stl = digit_dir.join(folder).join(&f.stl_file);
        if !stl.is_file() {
            return Err(TactileError::Setup {
                setup: f.name,
                msg: format!(
                    "{} names {}, which is missing",
                    path.display(),
                    stl.display()
                ),
            });
        }
        if f.xy_m.iter().chain(&f.euler_deg).any(|v| !v.is_finite()) {
            return Err(TactileError::Setup {
                setup: f.name,
                msg: format!("{}: placement is not finite", path.display()),
            });
        }
        Ok(Setup {
            name: f.name,
            stl,
            placement: Placement {
                xy_m: f.xy_m,
                euler_deg: f.euler_deg,
            },
            unseen: f.unseen,
        })
    }
}
