//! The neural physics engine as the tactile encoder: a pad's contact goes into the gel mesh's
//! frame and onto the engine's contact grid, and the engine's global contact code h_global
//! (eq 6.11) is the latent.
//!
//! Frames: the sensor frame has z into the gel; the mesh of `DIGIT_v8.vtk` has z up with the
//! top face at `z_top`. A rotation of 180 degrees about x maps one onto the other:
//! `mesh = (c_x + x, c_y - y, z_top - z)` with `c` the centre of the top face
//! (`scales.center_m`), so the sensor origin sits on the face's centre.

use std::path::Path;

use ocm_npe::{Fields, Npe};

use crate::encoder::TactileEncoder;
use crate::error::Result;
use crate::patch::convex_hull;

/// The engine's h_global of each pad's contact.
#[derive(Debug)]
pub struct NpeEncoder {
    npe: Npe,
    spacing_m: f64,
}

/// Tolerance of the inside-the-patch test, m (round-off of rapier's manifold corners).
const INSIDE_TOL_M: f64 = 1e-9;

impl NpeEncoder {
    /// Wraps a trained engine.
    pub fn new(npe: Npe) -> Self {
        let spacing_m = npe.config.grid_spacing_m();
        NpeEncoder { npe, spacing_m }
    }

    /// Loads a checkpoint of `ocm npe train`.
    pub fn load(path: impl AsRef<Path>) -> Result<Self> {
        Ok(Self::new(Npe::load(path)?))
    }

    /// The engine.
    pub fn npe(&self) -> &Npe {
        &self.npe
    }

    /// A sensor-frame point in the mesh's frame.
    pub fn to_mesh(&self, p: [f64; 3]) -> [f64; 3] {
        let c = self.npe.config.scales.center_m;
        [c[0] + p[0], c[1] - p[1], c[2] - p[2]]
    }

    /// The contact as the engine's input: points in the mesh frame and the depth (m, the
    /// deepest point's). A rigid proxy reports the corners of the overlap polygon; the engine
    /// was trained on the body's surface sampled on its contact grid. So a patch with area
    /// is filled: every grid point inside the points' convex hull (sensor x-y), at the depth
    /// of the least-squares plane through the points (clamped to the points' depth range).
    /// Points and edges (no area) go in as they are. Non-finite points are an error.
    pub fn engine_input(&self, points: &[[f64; 3]]) -> Result<(Vec<[f64; 3]>, f64)> {
        if let Some((i, p)) = points
            .iter()
            .enumerate()
            .find(|(_, p)| p.iter().any(|v| !v.is_finite()))
        {
            return Err(crate::error::PegError::Invalid(format!(
                "contact point {i} ({p:?}) is not finite"
            )));
        }
        let depth = points.iter().map(|p| p[2]).fold(0.0, f64::max);
        let xy: Vec<[f64; 2]> = points.iter().map(|p| [p[0], p[1]]).collect();
        let hull = convex_hull(&xy);
        let plane = (hull.len() >= 3).then(|| plane_fit(points)).flatten();
        let Some(plane) = plane else {
            return Ok((points.iter().map(|&p| self.to_mesh(p)).collect(), depth));
        };
        let zmin = points.iter().map(|p| p[2]).fold(f64::INFINITY, f64::min);
        let (lo, hi) = self.npe.face_bounds();
        let h = self.spacing_m;
        let c = self.npe.config.scales.center_m;
        // The grid's pixel centres over the face's outline, as ContactGrid lays them out.
        let cols = ((hi[0] - lo[0]) / h).round().max(1.0) as usize;
        let rows = ((hi[1] - lo[1]) / h).round().max(1.0) as usize;
        // Sensor bounding box of the hull in mesh coordinates (y flips).
        let (mut bx, mut by) = (
            [f64::INFINITY, f64::NEG_INFINITY],
            [f64::INFINITY, f64::NEG_INFINITY],
        );
        for v in &hull {
            bx = [bx[0].min(c[0] + v[0]), bx[1].max(c[0] + v[0])];
            by = [by[0].min(c[1] - v[1]), by[1].max(c[1] - v[1])];
        }
        let index = |v: f64, o: f64, n: usize| ((v - o) / h - 0.5).clamp(0.0, n as f64 - 1.0);
        let (c0, c1) = (
            index(bx[0], lo[0], cols).floor(),
            index(bx[1], lo[0], cols).ceil(),
        );
        let (r0, r1) = (
            index(by[0], lo[1], rows).floor(),
            index(by[1], lo[1], rows).ceil(),
        );
        let mut out = Vec::new();
        for r in r0 as usize..=r1 as usize {
            for col in c0 as usize..=c1 as usize {
                let xm = lo[0] + (col as f64 + 0.5) * h;
                let ym = lo[1] + (r as f64 + 0.5) * h;
                let (xs, ys) = (xm - c[0], c[1] - ym);
                if !inside(&hull, [xs, ys]) {
                    continue;
                }
                let d = (plane[0] + plane[1] * xs + plane[2] * ys).clamp(zmin, depth);
                if d > 0.0 {
                    out.push([xm, ym, c[2] - d]);
                }
            }
        }
        Ok((out, depth))
    }

    /// The engine's nodal fields for one pad's contact (sensor-frame points, normal force N).
    pub fn fields(&self, points: &[[f64; 3]], force_n: f64) -> Result<Fields> {
        let (pts, depth) = self.engine_input(points)?;
        Ok(self.npe.predict(&pts, force_n, depth)?)
    }
}

/// Whether `p` lies in the counter-clockwise convex polygon `hull` (edges included).
fn inside(hull: &[[f64; 2]], p: [f64; 2]) -> bool {
    (0..hull.len()).all(|i| {
        let a = hull[i];
        let b = hull[(i + 1) % hull.len()];
        let len = ((b[0] - a[0]).powi(2) + (b[1] - a[1]).powi(2)).sqrt();
        (b[0] - a[0]) * (p[1] - a[1]) - (b[1] - a[1]) * (p[0] - a[0]) >= -INSIDE_TOL_M * len
    })
}

/// Least-squares plane `z = a + b x + c y` through `points` (None when singular).
fn plane_fit(points: &[[f64; 3]]) -> Option<[f64; 3]> {
    let n = points.len() as f64;
    let mx = points.iter().map(|p| p[0]).sum::<f64>() / n;
    let my = points.iter().map(|p| p[1]).sum::<f64>() / n;
    let mz = points.iter().map(|p| p[2]).sum::<f64>() / n;
    let (mut sxx, mut syy, mut sxy, mut sxz, mut syz) = (0.0, 0.0, 0.0, 0.0, 0.0);
    for p in points {
        let (x, y, z) = (p[0] - mx, p[1] - my, p[2] - mz);
        sxx += x * x;
        syy += y * y;
        sxy += x * y;
        sxz += x * z;
        syz += y * z;
    }
    let det = sxx * syy - sxy * sxy;
    if det.abs() <= 1e-12 * (sxx * syy).max(f64::MIN_POSITIVE) {
        return None;
    }
    let b = (sxz * syy - syz * sxy) / det;
    let c = (syz * sxx - sxz * sxy) / det;
    Some([mz - b * mx - c * my, b, c])
}

impl TactileEncoder for NpeEncoder {
    fn name(&self) -> &str {
        "npe"
    }

    fn dim(&self) -> usize {
        self.npe.config.global_width()
    }

    fn latent(&self, points: &[[f64; 3]], force_n: f64) -> Result<Vec<f32>> {
        let (pts, depth) = self.engine_input(points)?;
        Ok(self.npe.latent(&pts, force_n, depth)?)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use ocm_learn::cpu;
    use ocm_npe::Surface;
    use ocm_npe::model::NpeConfig;

    /// An engine on a 15 x 20 mm face (x centred on 0, y from 0 to 20 mm, top at 2 mm, as
    /// DIGIT_v8) with nodes every 1 mm and untrained weights.
    fn encoder() -> NpeEncoder {
        let mut rest_m = Vec::new();
        let mut edges = Vec::new();
        let (nx, ny) = (16, 21);
        for j in 0..ny {
            for i in 0..nx {
                rest_m.push([(i as f64 - 7.5) * 1e-3, j as f64 * 1e-3, 2e-3]);
                let k = j * nx + i;
                if i + 1 < nx {
                    edges.push([k, k + 1]);
                }
                if j + 1 < ny {
                    edges.push([k, k + nx]);
                }
            }
        }
        let mut cfg = NpeConfig::new([0.0, 10e-3, 2e-3], 0.25e-3);
        cfg.layers = 1;
        cfg.width = 8;
        let net = cfg.init(&cpu(), 1).unwrap();
        NpeEncoder::new(Npe::new(net, cfg, Surface { rest_m, edges }).unwrap())
    }

    #[test]
    fn a_flat_patch_fills_the_grid_inside_its_corners() {
        let e = encoder();
        // A 2 x 3 mm rectangle 0.3 mm deep with corners at x in [1, 3] mm, y in [-1, 2] mm.
        let corners =
            [[1e-3, -1e-3], [3e-3, -1e-3], [3e-3, 2e-3], [1e-3, 2e-3]].map(|[x, y]| [x, y, 0.3e-3]);
        let (pts, depth) = e.engine_input(&corners).unwrap();
        assert_eq!(depth, 0.3e-3);
        // Pixel centres every 0.25 mm on the 15 x 20 mm face: 8 x 12 fall inside the
        // rectangle (its edges lie on pixel borders).
        assert_eq!(pts.len(), 8 * 12);
        for p in &pts {
            // Mesh frame: x = c_x + x_s, y = c_y - y_s, z = z_top - depth.
            assert!(p[0] > 1e-3 && p[0] < 3e-3, "{p:?}");
            assert!(p[1] > 8e-3 && p[1] < 11e-3, "{p:?}");
            assert!((p[2] - 1.7e-3).abs() < 1e-12);
        }
        // A tilted plane keeps the corner depths' range and interpolates between them.
        let tilted = [
            [1e-3, -1e-3, 0.1e-3],
            [3e-3, -1e-3, 0.3e-3],
            [3e-3, 2e-3, 0.3e-3],
            [1e-3, 2e-3, 0.1e-3],
        ];
        let (pts, depth) = e.engine_input(&tilted).unwrap();
        assert_eq!(depth, 0.3e-3);
        for p in &pts {
            let want = 0.1e-3 + (p[0] - 1e-3) / 2e-3 * 0.2e-3;
            assert!((2e-3 - p[2] - want).abs() < 1e-9, "{p:?}");
        }
    }

    #[test]
    fn edges_pass_as_they_are_and_bad_points_are_errors() {
        let e = encoder();
        let edge = [[0.0, 0.0, 0.2e-3], [0.0, 3e-3, 0.2e-3]];
        let (pts, _) = e.engine_input(&edge).unwrap();
        let want = [[0.0, 10e-3, 1.8e-3], [0.0, 7e-3, 1.8e-3]];
        assert_eq!(pts.len(), 2);
        for (p, q) in pts.iter().zip(want) {
            assert!((0..3).all(|k| (p[k] - q[k]).abs() < 1e-12), "{p:?}");
        }
        assert_eq!(e.latent(&[], 0.0).unwrap(), vec![0.0; e.dim()]);
        let err = e
            .latent(&[[0.0, f64::NAN, 0.0]], 1.0)
            .unwrap_err()
            .to_string();
        assert!(err.contains("contact point 0"), "{err}");
        assert!(e.latent(&edge, -1.0).is_err());
        // Different patches give different latents.
        let a = e.latent(&edge, 1.0).unwrap();
        let b = e
            .latent(&[[2e-3, 0.0, 0.2e-3], [2e-3, 3e-3, 0.2e-3]], 1.0)
            .unwrap();
        assert_ne!(a, b);
    }
}
