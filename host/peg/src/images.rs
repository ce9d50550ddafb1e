//! Rendered tactile images of replayed frames (Ch.6.6.4): each pad's nodal displacement from
//! the engine goes through the DIGIT renderer of `ocm_tactile::optics` (calibrated
//! slope-to-colour tables over a real background), one PNG per frame with the left pad beside
//! the right.

use std::path::{Path, PathBuf};

use ocm_npe::{Fields, Surface};
use ocm_tactile::dataset::TopSurface;
use ocm_tactile::gel::Gel;
use ocm_tactile::optics::camera::fit_landscape;
use ocm_tactile::optics::{Renderer, RgbImage, SurfaceSampler};
use ocm_tactile::real::{render_step, side_by_side};

use crate::error::{PegError, Result};

/// Largest distance between a top node of the engine's surface and the gel's, m, for the two
/// to count as the same mesh.
const SAME_NODE_M: f64 = 1e-9;

/// Turns the engine's top-face displacement into DIGIT images.
#[derive(Debug, Clone)]
pub struct TactileImager {
    renderer: Renderer,
    sampler: SurfaceSampler,
    top: TopSurface,
    num_nodes: usize,
}

impl TactileImager {
    /// An imager for an engine predicting on `surface`, trained on the gel `gel` (its top nodes
    /// must be the surface's, in the same order), with the gel seen in the renderer's image
    /// size as the landscape DIGIT frame.
    pub fn new(gel: &Gel, renderer: Renderer, surface: &Surface) -> Result<Self> {
        let top = TopSurface::from_gel(gel);
        if top.rest_m.len() != surface.rest_m.len() {
            return Err(PegError::Invalid(format!(
                "the engine predicts on {} top nodes, the gel mesh has {}: not the mesh it was \
                 trained on",
                surface.rest_m.len(),
                top.rest_m.len()
            )));
        }
        if let Some(i) = (0..top.rest_m.len()).find(|&i| {
            (0..3).any(|k| (top.rest_m[i][k] - surface.rest_m[i][k]).abs() > SAME_NODE_M)
        }) {
            return Err(PegError::Invalid(format!(
                "top node {i} of the engine lies at {:?} m, the gel's at {:?} m: not the mesh \
                 it was trained on",
                surface.rest_m[i], top.rest_m[i]
            )));
        }
        let map = fit_landscape(gel, renderer.rows, renderer.cols);
        let sampler = SurfaceSampler::new(gel, renderer.rows, renderer.cols, &map);
        Ok(TactileImager {
            renderer,
            sampler,
            top,
            num_nodes: gel.num_nodes(),
        })
    }

    /// The image of one pad from its top-node displacement, m.
    pub fn image(&self, top_displacement_m: &[[f64; 3]]) -> Result<RgbImage> {
        if top_displacement_m.len() != self.top.nodes.len() {
            return Err(PegError::Invalid(format!(
                "{} nodal displacements for {} top nodes",
                top_displacement_m.len(),
                self.top.nodes.len()
            )));
        }
        let u = self.top.extend(top_displacement_m, self.num_nodes);
        Ok(render_step(&self.renderer, &self.sampler, &u)?)
    }

    /// Left and right pads side by side.
    pub fn pair(&self, fields: &[Fields; 2]) -> Result<RgbImage> {
        let l = self.image(&fields[0].displacement_m)?;
        let r = self.image(&fields[1].displacement_m)?;
        Ok(side_by_side(&[&l, &r])?)
    }
}

/// Writes `tactile_NNNN.png` (left pad | right pad) into `dir` for every `every`-th frame and
/// the last; returns the paths written. `progress(done, total)` after each image.
pub fn write_images(
    dir: &Path,
    fields: &[[Fields; 2]],
    imager: &TactileImager,
    every: usize,
    progress: &mut dyn FnMut(usize, usize),
) -> Result<Vec<PathBuf>> {
    std::fs::create_dir_all(dir).map_err(|e| PegError::file(dir, e))?;
    let every = every.max(1);
    let last = fields.len().saturating_sub(1);
    let chosen: Vec<usize> = (0..fields.len())
        .filter(|k| k % every == 0 || *k == last)
        .collect();
    let mut out = Vec::with_capacity(chosen.len());
    for (done, &k) in chosen.iter().enumerate() {
        let img = imager.pair(&fields[k])?;
        let p = dir.join(format!("tactile_{k:04}.png"));
        img.write_png(&p)?;
        out.push(p);
        progress(done + 1, chosen.len());
    }
    Ok(out)
}
