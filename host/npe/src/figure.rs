//! Images of displacement fields: FEM | NPE | |difference| of the downward displacement over
//! the top face, on the contact-mask grid.

use std::path::Path;

use ocm_tactile::dataset::TopSurface;
use ocm_tactile::gel::Gel;
use ocm_tactile::mask::{Grid, rasterize};

use crate::{NpeError, Result};

/// Colour of `t` in [0, 1] on a dark-blue to yellow ramp.
fn ramp(t: f64) -> [u8; 3] {
    const STOPS: [[f64; 3]; 5] = [
        [68.0, 1.0, 84.0],
        [59.0, 82.0, 139.0],
        [33.0, 145.0, 140.0],
        [94.0, 201.0, 98.0],
        [253.0, 231.0, 37.0],
    ];
    let t = if t.is_finite() {
        t.clamp(0.0, 1.0)
    } else {
        0.0
    } * 4.0;
    let k = (t.floor() as usize).min(3);
    let f = t - k as f64;
    [0, 1, 2].map(|c| (STOPS[k][c] * (1.0 - f) + STOPS[k + 1][c] * f).round() as u8)
}

/// Writes `path` (PNG): the downward displacement of the FEM, of the NPE and their absolute
/// difference side by side, one colour scale (0 to the FEM's largest value), 4 px gaps.
pub fn write_comparison(
    path: &Path,
    gel: &Gel,
    top: &TopSurface,
    fem_m: &[[f64; 3]],
    npe_m: &[[f64; 3]],
) -> Result<()> {
    let grid = Grid::for_gel(gel);
    let down = |u: &[[f64; 3]]| -> Vec<f64> {
        let full = top.extend(u, gel.num_nodes());
        rasterize(gel, &grid, &full.iter().map(|v| -v[2]).collect::<Vec<_>>())
    };
    let (a, b) = (down(fem_m), down(npe_m));
    let d: Vec<f64> = a.iter().zip(&b).map(|(x, y)| (x - y).abs()).collect();
    let peak = a.iter().copied().fold(1e-9, f64::max);
    let gap = 4;
    let (w, h) = (grid.cols as u32, grid.rows as u32);
    let mut img = image::RgbImage::from_pixel(3 * w + 2 * gap, h, image::Rgb([255, 255, 255]));
    for (k, field) in [&a, &b, &d].iter().enumerate() {
        for r in 0..grid.rows {
            for c in 0..grid.cols {
                let v = field[r * grid.cols + c] / peak;
                // Row 0 is the lowest y: flip so +y points up in the picture.
                img.put_pixel(
                    k as u32 * (w + gap) + c as u32,
                    h - 1 - r as u32,
                    image::Rgb(ramp(v)),
                );
            }
        }
    }
    img.save(path)
        .map_err(|e| NpeError::Data(format!("writing {}: {e}", path.display())))
}
