//! Indentation set-ups (`indenter_settings.json`, `unseen_indenter_settings.json`): which
//! indenter, where over the gel and how rotated.

use crate::indent::Placement;
use crate::{Result, TactileError};
use serde::Deserialize;
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
