//! Where the gel's top face lands on the camera image, and the resampling of the FEM surface
//! displacement onto the image grid.

use crate::gel::Gel;
use crate::mask::Grid;
use crate::{Result, TactileError};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

/// A similarity map from gel coordinates (x, y in metres, top face) to continuous image
/// coordinates (column, row; pixel (r, c) covers [c, c+1) x [r, r+1)): optional mirror of y,
/// rotation, uniform scale, shift. The DIGIT camera looks at the gel face-on through a short
/// lens; perspective and lens distortion are left out (see the README).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct CameraMap {
    /// Scale, image pixels per metre of gel.
    pub px_per_m: f64,
    /// Rotation of the gel axes in the image, rad.
    pub angle_rad: f64,
    /// Mirror gel y before rotating (the camera sees the gel from below).
    pub mirror: bool,
    /// Image position of the gel origin (column, row), pixels.
    pub offset_px: [f64; 2],
}

impl CameraMap {
    /// The map that makes the image the mask grid: columns along x, rows along y.
    pub fn for_grid(grid: &Grid) -> Self {
        let s = 1.0 / grid.pixel_m;
        CameraMap {
            px_per_m: s,
            angle_rad: 0.0,
            mirror: false,
            offset_px: [-grid.origin_m[0] * s, -grid.origin_m[1] * s],
        }
    }

    /// Gel (x, y) in m -> image (column, row) in pixels.
    pub fn to_px(&self, p: [f64; 2]) -> [f64; 2] {
        let y = if self.mirror { -p[1] } else { p[1] };
        let (s, c) = self.angle_rad.sin_cos();
        [
            self.px_per_m * (c * p[0] - s * y) + self.offset_px[0],
            self.px_per_m * (s * p[0] + c * y) + self.offset_px[1],
        ]
    }

    /// Image (column, row) in pixels -> gel (x, y) in m.
    pub fn to_gel(&self, q: [f64; 2]) -> [f64; 2] {
        let u = (q[0] - self.offset_px[0]) / self.px_per_m;
        let v = (q[1] - self.offset_px[1]) / self.px_per_m;
        let (s, c) = self.angle_rad.sin_cos();
        let x = c * u + s * v;
        let y = -s * u + c * v;
        [x, if self.mirror { -y } else { y }]
    }

    /// Gel length covered by one image pixel, m.
    pub fn m_per_px(&self) -> f64 {
        1.0 / self.px_per_m
    }
}

/// The gel seen as a 240 x 320 landscape image like the DIGIT's: the gel's mask grid
/// transposed (image rows along gel x, columns along gel y, 0.0625 mm per pixel), reduced by
/// `scale`. Returns the map and the image size (rows, cols). This is the frame of the
/// networks' pairs and of `ocm tactile render` without a fitted map.
pub fn landscape_map(gel: &Gel, scale: usize) -> (CameraMap, usize, usize) {
    let g = Grid::for_gel(gel);
    let scale = scale.max(1);
    let s = 1.0 / (g.pixel_m * scale as f64);
    // Mirror y then turn a quarter: (x, y) -> (y, x), a transposition.
    let map = CameraMap {
        px_per_m: s,
        angle_rad: std::f64::consts::FRAC_PI_2,
        mirror: true,
        offset_px: [-g.origin_m[1] * s, -g.origin_m[0] * s],
    };
    (map, g.cols / scale, g.rows / scale)
}

/// The landscape frame of [`landscape_map`] fitted into a `rows` x `cols` image: the map
/// itself where the gel's grid has that size (DIGIT_v8 at 240 x 320), otherwise the gel
/// scaled to the largest size that fits and centred, so no part of the top face is cut off.
pub fn fit_landscape(gel: &Gel, rows: usize, cols: usize) -> CameraMap {
    let (map, r, c) = landscape_map(gel, 1);
    if (r, c) == (rows, cols) {
        return map;
    }
    let (lo, hi) = gel.top_bounds();
    // Image rows run along gel x, columns along gel y.
    let s = (rows as f64 / (hi[0] - lo[0])).min(cols as f64 / (hi[1] - lo[1]));
    let mid = [(lo[0] + hi[0]) / 2.0, (lo[1] + hi[1]) / 2.0];
    CameraMap {
        px_per_m: s,
        angle_rad: std::f64::consts::FRAC_PI_2,
        mirror: true,
        offset_px: [
            cols as f64 / 2.0 - mid[1] * s,
            rows as f64 / 2.0 - mid[0] * s,
        ],
    }
}

/// Precomputed linear interpolation of top-face nodal values at the image's pixel centres:
/// each pixel remembers the top triangle (in the rest configuration, projected on x-y) that
/// holds it and its barycentric weights; pixels off the gel get weight zero (a flat surface).
#[derive(Debug, Clone)]
pub struct SurfaceSampler {
    /// Image rows.
    pub rows: usize,
    /// Image columns.
    pub cols: usize,
    /// Gel length per pixel, m.
    pub m_per_px: f64,
    nodes: Vec<[u32; 3]>,
    weights: Vec<[f32; 3]>,
    num_nodes: usize,
}

impl SurfaceSampler {
    /// Locates every pixel centre of a rows x cols image on the gel's top triangles.
    pub fn new(gel: &Gel, rows: usize, cols: usize, map: &CameraMap) -> Self {
        let mut nodes = vec![[0u32; 3]; rows * cols];
        let mut weights = vec![[0.0f32; 3]; rows * cols];
        let p = &gel.mesh.points;
        for t in &gel.top_triangles {
            let [a, b, c] = t.map(|i| map.to_px([p[i][0], p[i][1]]));
            let det = crate::gel::doubled_area(a, b, c);
            if det.abs() < 1e-12 {
                continue;
            }
            let lo = [a[0].min(b[0]).min(c[0]), a[1].min(b[1]).min(c[1])];
            let hi = [a[0].max(b[0]).max(c[0]), a[1].max(b[1]).max(c[1])];
            let c0 = (lo[0] - 0.5).ceil().max(0.0);
            let c1 = (hi[0] - 0.5).floor().min(cols as f64 - 1.0);
            let r0 = (lo[1] - 0.5).ceil().max(0.0);
            let r1 = (hi[1] - 0.5).floor().min(rows as f64 - 1.0);
            if c1 < c0 || r1 < r0 {
                continue;
            }
            for row in r0 as usize..=r1 as usize {
                for col in c0 as usize..=c1 as usize {
                    let q = [col as f64 + 0.5, row as f64 + 0.5];
                    if let Some([l1, l2, l3]) = crate::gel::barycentric(a, b, c, det, q) {
                        let k = row * cols + col;
                        nodes[k] = t.map(|i| i as u32);
                        weights[k] = [l1 as f32, l2 as f32, l3 as f32];
                    }
                }
            }
        }
        SurfaceSampler {
            rows,
            cols,
            m_per_px: map.m_per_px(),
            nodes,
            weights,
            num_nodes: gel.num_nodes(),
        }
    }

    /// Number of pixels that lie on the gel.
    pub fn covered(&self) -> usize {
        self.weights
            .iter()
            .filter(|w| w[0] + w[1] + w[2] > 0.5)
            .count()
    }

    /// Surface height towards the camera (-u_z of the top face, m) at every pixel.
    pub fn heights(&self, displacement: &[[f64; 3]], out: &mut [f32]) -> Result<()> {
        if displacement.len() != self.num_nodes {
            return Err(TactileError::Input(format!(
                "displacement field has {} nodes, the gel has {}",
                displacement.len(),
                self.num_nodes
            )));
        }
        if out.len() != self.rows * self.cols {
            return Err(TactileError::Input(format!(
                "height buffer holds {} pixels, the image has {} x {}",
                out.len(),
                self.rows,
                self.cols
            )));
        }
        if let Some(i) = displacement.iter().position(|u| !u[2].is_finite()) {
            return Err(TactileError::Input(format!(
                "displacement of node {i} is {:?}",
                displacement[i]
            )));
        }
        out.par_chunks_mut(self.cols)
            .zip(self.nodes.par_chunks(self.cols))
            .zip(self.weights.par_chunks(self.cols))
            .for_each(|((line, nodes), weights)| {
                for ((h, n), w) in line.iter_mut().zip(nodes).zip(weights) {
                    *h = -(w[0] * displacement[n[0] as usize][2] as f32
                        + w[1] * displacement[n[1] as usize][2] as f32
                        + w[2] * displacement[n[2] as usize][2] as f32);
                }
            });
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn map_round_trips_with_mirror_and_rotation() {
        for mirror in [false, true] {
            let m = CameraMap {
                px_per_m: 16_000.0,
                angle_rad: 0.7,
                mirror,
                offset_px: [12.0, -30.0],
            };
            let p = [3.1e-3, -7.4e-3];
            let q = m.to_gel(m.to_px(p));
            assert!((q[0] - p[0]).abs() < 1e-15 && (q[1] - p[1]).abs() < 1e-15);
            // Distances scale by px_per_m.
            let a = m.to_px([0.0, 0.0]);
            let b = m.to_px([1e-3, 0.0]);
            assert!(((b[0] - a[0]).hypot(b[1] - a[1]) - 16.0).abs() < 1e-9);
        }
        let g = Grid {
            origin_m: [1e-3, 2e-3],
            pixel_m: 0.5e-3,
            cols: 10,
            rows: 8,
        };
        let m = CameraMap::for_grid(&g);
        let c = g.center(3, 5);
        let q = m.to_px(c);
        assert!((q[0] - 5.5).abs() < 1e-9 && (q[1] - 3.5).abs() < 1e-9);
    }
}
