//! Contact masks on the gel's top face (Ch.6.5.1): the downward displacement of the top-face
//! nodes is interpolated onto a pixel grid, thresholded, closed morphologically and filled.

use crate::gel::Gel;
use crate::{Result, TactileError};
use serde::{Deserialize, Serialize};

/// A regular pixel grid over the top face: pixel (row, col) covers
/// x in [x0 + col p, x0 + (col+1) p), y in [y0 + row p, ...).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Grid {
    /// Lower-left corner (x, y), m.
    pub origin_m: [f64; 2],
    /// Pixel size, m.
    pub pixel_m: f64,
    /// Columns (along x).
    pub cols: usize,
    /// Rows (along y).
    pub rows: usize,
}

/// Downward displacement above which a top-face point is in contact, m (Ch.6.5.1: 30 um).
pub const CONTACT_THRESHOLD_M: f64 = 30e-6;
/// Side of the square closing kernel, pixels (Ch.6.5.1: 15 x 15).
pub const CLOSING_KERNEL_PX: usize = 15;
/// Radius of the box blur a mask of camera frames sees, pixels: the real frame's change
/// against the background is blurred over 5 x 5 pixels (JPEG and sensor noise), and the FEM's
/// slope image, on a grid at the camera's resolution, goes through the same blur.
pub const BLUR_RADIUS_PX: usize = 2;

impl Grid {
    /// The gel's top face at the DIGIT camera's resolution: 240 x 320 pixels over 15 x 20 mm
    /// (0.0625 mm per pixel), so the 15 x 15 closing kernel spans the same 0.94 mm as on the
    /// camera image.
    pub fn for_gel(gel: &Gel) -> Self {
        let (lo, hi) = gel.top_bounds();
        let pixel = 0.0625e-3;
        Grid {
            origin_m: lo,
            pixel_m: pixel,
            cols: ((hi[0] - lo[0]) / pixel).round().max(1.0) as usize,
            rows: ((hi[1] - lo[1]) / pixel).round().max(1.0) as usize,
        }
    }

    /// Centre of pixel (row, col), m.
    pub fn center(&self, row: usize, col: usize) -> [f64; 2] {
        [
            self.origin_m[0] + (col as f64 + 0.5) * self.pixel_m,
            self.origin_m[1] + (row as f64 + 0.5) * self.pixel_m,
        ]
    }
}

/// Interpolates a nodal scalar over the top triangles (projected on xy) onto `grid`; pixels
/// outside every triangle get 0. Row-major, rows x cols.
pub fn rasterize(gel: &Gel, grid: &Grid, nodal: &[f64]) -> Vec<f64> {
    let mut img = vec![0.0; grid.rows * grid.cols];
    let p = &gel.mesh.points;
    for t in &gel.top_triangles {
        let [a, b, c] = t.map(|i| [p[i][0], p[i][1]]);
        let det = crate::gel::doubled_area(a, b, c);
        if det.abs() < 1e-30 {
            continue;
        }
        let lo = [a[0].min(b[0]).min(c[0]), a[1].min(b[1]).min(c[1])];
        let hi = [a[0].max(b[0]).max(c[0]), a[1].max(b[1]).max(c[1])];
        let to_px = |v: f64, o: f64| (v - o) / grid.pixel_m - 0.5;
        let c0 = to_px(lo[0], grid.origin_m[0]).ceil().max(0.0) as usize;
        let c1 = (to_px(hi[0], grid.origin_m[0]).floor()).min(grid.cols as f64 - 1.0);
        let r0 = to_px(lo[1], grid.origin_m[1]).ceil().max(0.0) as usize;
        let r1 = (to_px(hi[1], grid.origin_m[1]).floor()).min(grid.rows as f64 - 1.0);
        if c1 < 0.0 || r1 < 0.0 {
            continue;
        }
        let v = t.map(|i| nodal[i]);
        for row in r0..=r1 as usize {
            for col in c0..=c1 as usize {
                if let Some([l1, l2, l3]) =
                    crate::gel::barycentric(a, b, c, det, grid.center(row, col))
                {
                    img[row * grid.cols + col] = l1 * v[0] + l2 * v[1] + l3 * v[2];
                }
            }
        }
    }
    img
}

/// Which field of the top face a FEM contact mask thresholds.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub enum MaskRule {
    /// The downward displacement -u_z above [`CONTACT_THRESHOLD_M`] (Ch.6.5.1).
    Depth,
    /// The slope of the downward displacement, |grad u_z| (dimensionless) box-blurred like a
    /// real frame's change ([`BLUR_RADIUS_PX`]), above this value. A DIGIT camera sees the
    /// change of the surface normal, not of the depth: this is the FEM's counterpart of a mask
    /// measured on camera frames (see the tactile README).
    Slope(f64),
}

impl std::fmt::Display for MaskRule {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            MaskRule::Depth => write!(f, "-u_z > {} um", CONTACT_THRESHOLD_M * 1e6),
            MaskRule::Slope(t) => write!(
                f,
                "|grad u_z| ({0} x {0} box blur) > {t}",
                2 * BLUR_RADIUS_PX + 1
            ),
        }
    }
}

impl MaskRule {
    /// The contact mask of one FEM step under this rule: thresholded on `grid`, closed with a
    /// [`CLOSING_KERNEL_PX`] square and with holes filled.
    pub fn mask(&self, gel: &Gel, grid: &Grid, displacement: &[[f64; 3]]) -> Mask {
        let down: Vec<f64> = displacement.iter().map(|u| -u[2]).collect();
        let img = rasterize(gel, grid, &down);
        let pixels = match *self {
            MaskRule::Depth => img.iter().map(|&v| v > CONTACT_THRESHOLD_M).collect(),
            MaskRule::Slope(t) => slope_pixels(&img, grid, t),
        };
        Mask {
            grid: *grid,
            pixels,
        }
        .closed(CLOSING_KERNEL_PX)
        .filled()
    }
}

/// The pixels of a slope mask before closing: |grad img| ([`slope_image`]) box-blurred over
/// [`BLUR_RADIUS_PX`], above `min_slope`.
pub fn slope_pixels(img: &[f64], grid: &Grid, min_slope: f64) -> Vec<bool> {
    box_blur(
        &slope_image(img, grid),
        grid.rows,
        grid.cols,
        BLUR_RADIUS_PX,
    )
    .iter()
    .map(|&g| g > min_slope)
    .collect()
}

/// Mean over the (2 r + 1) x (2 r + 1) square about each pixel of a row-major image, the
/// square clipped at the border (separable running sums); r = 0 is the identity.
pub fn box_blur(src: &[f64], rows: usize, cols: usize, r: usize) -> Vec<f64> {
    if r == 0 {
        // Differences of prefix sums would only round to the pixels.
        return src.to_vec();
    }
    let mean = |sum: f64, n: usize| sum / n as f64;
    let a = window_pass(src, rows, cols, r, true, |v| v, mean);
    window_pass(&a, rows, cols, r, false, |v| v, mean)
}

/// One separable pass of a running window of radius `r` along the rows (or the columns) of a
/// row-major image: `out(sum, count)` of `value` over each pixel's window, clipped at the
/// border (prefix sums; counts of bools stay exact in f64).
fn window_pass<T: Copy, O: Copy + Default>(
    src: &[T],
    rows: usize,
    cols: usize,
    r: usize,
    along_rows: bool,
    value: impl Fn(T) -> f64,
    out: impl Fn(f64, usize) -> O,
) -> Vec<O> {
    let (lines, len) = if along_rows {
        (rows, cols)
    } else {
        (cols, rows)
    };
    let idx = |l: usize, k: usize| {
        if along_rows {
            l * cols + k
        } else {
            k * cols + l
        }
    };
    let mut res = vec![O::default(); src.len()];
    let mut prefix = vec![0.0; len + 1];
    for l in 0..lines {
        for k in 0..len {
            prefix[k + 1] = prefix[k] + value(src[idx(l, k)]);
        }
        for k in 0..len {
            let lo = k.saturating_sub(r);
            let hi = (k + r + 1).min(len);
            res[idx(l, k)] = out(prefix[hi] - prefix[lo], hi - lo);
        }
    }
    res
}

/// |grad f| of a row-major image on `grid` by central differences (one-sided at the border).
pub fn slope_image(img: &[f64], grid: &Grid) -> Vec<f64> {
    let (rows, cols) = (grid.rows, grid.cols);
    let diff = |lo: usize, hi: usize, a: f64, b: f64| {
        if hi > lo {
            (b - a) / ((hi - lo) as f64 * grid.pixel_m)
        } else {
            0.0
        }
    };
    let mut out = vec![0.0; rows * cols];
    for r in 0..rows {
        let (r0, r1) = (r.saturating_sub(1), (r + 1).min(rows - 1));
        for c in 0..cols {
            let (c0, c1) = (c.saturating_sub(1), (c + 1).min(cols - 1));
            let gx = diff(c0, c1, img[r * cols + c0], img[r * cols + c1]);
            let gy = diff(r0, r1, img[r0 * cols + c], img[r1 * cols + c]);
            out[r * cols + c] = gx.hypot(gy);
        }
    }
    out
}

/// A binary mask on a grid with its shape statistics.
#[derive(Debug, Clone, PartialEq)]
pub struct Mask {
    /// The grid.
    pub grid: Grid,
    /// Row-major pixels.
    pub pixels: Vec<bool>,
}

/// Area, centroid and principal-axis angle of a mask.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct MaskStats {
    /// Area, m^2.
    pub area_m2: f64,
    /// Centroid (x, y), m (NaN when empty).
    pub centroid_m: [f64; 2],
    /// Angle of the major principal axis from +x, rad, in (-pi/2, pi/2] (0 when isotropic).
    pub angle_rad: f64,
}

impl Mask {
    /// Contact mask of a step: -u_z of the top face above [`CONTACT_THRESHOLD_M`], closed with a
    /// [`CLOSING_KERNEL_PX`] square and with holes filled.
    pub fn from_displacement(gel: &Gel, grid: &Grid, displacement: &[[f64; 3]]) -> Self {
        MaskRule::Depth.mask(gel, grid, displacement)
    }

    /// Number of set pixels.
    pub fn count(&self) -> usize {
        self.pixels.iter().filter(|&&b| b).count()
    }

    /// Morphological closing (dilation then erosion) with a k x k square; the erosion treats the
    /// outside as set, so a patch touching the border is not eaten from there.
    pub fn closed(&self, k: usize) -> Mask {
        let r = k / 2;
        let dil = filter(&self.pixels, self.grid.rows, self.grid.cols, r, true);
        let ero = filter(&dil, self.grid.rows, self.grid.cols, r, false);
        Mask {
            grid: self.grid,
            pixels: ero,
        }
    }

    /// Dilation with a (2r+1) x (2r+1) square: every pixel within r pixels (Chebyshev) of a set
    /// one.
    pub fn dilated(&self, r: usize) -> Mask {
        Mask {
            grid: self.grid,
            pixels: filter(&self.pixels, self.grid.rows, self.grid.cols, r, true),
        }
    }

    /// Fills holes: unset pixels not connected (4-neighbours) to the border become set.
    pub fn filled(&self) -> Mask {
        let (rows, cols) = (self.grid.rows, self.grid.cols);
        let mut outside = vec![false; rows * cols];
        let mut stack = Vec::new();
        for r in 0..rows {
            for c in 0..cols {
                if (r == 0 || c == 0 || r == rows - 1 || c == cols - 1)
                    && !self.pixels[r * cols + c]
                {
                    outside[r * cols + c] = true;
                    stack.push((r, c));
                }
            }
        }
        while let Some((r, c)) = stack.pop() {
            let mut visit = |rr: usize, cc: usize| {
                let i = rr * cols + cc;
                if !self.pixels[i] && !outside[i] {
                    outside[i] = true;
                    stack.push((rr, cc));
                }
            };
            if r > 0 {
                visit(r - 1, c);
            }
            if r + 1 < rows {
                visit(r + 1, c);
            }
            if c > 0 {
                visit(r, c - 1);
            }
            if c + 1 < cols {
                visit(r, c + 1);
            }
        }
        Mask {
            grid: self.grid,
            pixels: outside.iter().map(|&o| !o).collect(),
        }
    }

    /// Area, centroid and principal-axis angle (from the second central moments).
    pub fn stats(&self) -> MaskStats {
        let g = &self.grid;
        let (mut n, mut sx, mut sy) = (0.0, 0.0, 0.0);
        for r in 0..g.rows {
            for c in 0..g.cols {
                if self.pixels[r * g.cols + c] {
                    let p = g.center(r, c);
                    n += 1.0;
                    sx += p[0];
                    sy += p[1];
                }
            }
        }
        if n == 0.0 {
            return MaskStats {
                area_m2: 0.0,
                centroid_m: [f64::NAN; 2],
                angle_rad: 0.0,
            };
        }
        let (cx, cy) = (sx / n, sy / n);
        let (mut mxx, mut myy, mut mxy) = (0.0, 0.0, 0.0);
        for r in 0..g.rows {
            for c in 0..g.cols {
                if self.pixels[r * g.cols + c] {
                    let p = g.center(r, c);
                    let (dx, dy) = (p[0] - cx, p[1] - cy);
                    mxx += dx * dx;
                    myy += dy * dy;
                    mxy += dx * dy;
                }
            }
        }
        MaskStats {
            area_m2: n * g.pixel_m * g.pixel_m,
            centroid_m: [cx, cy],
            angle_rad: principal_angle(mxx, myy, mxy),
        }
    }

    /// Writes the mask as an 8-bit PNG (255 = contact), row 0 at the top.
    pub fn write_png(&self, path: impl AsRef<std::path::Path>) -> Result<()> {
        let path = path.as_ref();
        let img =
            image::GrayImage::from_fn(self.grid.cols as u32, self.grid.rows as u32, |c, r| {
                image::Luma([if self.pixels[r as usize * self.grid.cols + c as usize] {
                    255
                } else {
                    0
                }])
            });
        img.save(path).map_err(|e| TactileError::Image {
            path: path.display().to_string(),
            msg: e.to_string(),
        })
    }
}

/// Major-axis angle of second moments (mxx, myy, mxy), rad in (-pi/2, pi/2].
pub fn principal_angle(mxx: f64, myy: f64, mxy: f64) -> f64 {
    let a = 0.5 * (2.0 * mxy).atan2(mxx - myy);
    if a <= -std::f64::consts::FRAC_PI_2 {
        a + std::f64::consts::PI
    } else {
        a
    }
}

/// Square max (dilate) or min (erode) filter of radius r, separable; the erosion sees the
/// outside as set.
fn filter(px: &[bool], rows: usize, cols: usize, r: usize, dilate: bool) -> Vec<bool> {
    let count = |b: bool| f64::from(u8::from(b));
    let keep = |set: f64, n: usize| if dilate { set > 0.0 } else { set == n as f64 };
    let a = window_pass(px, rows, cols, r, true, count, keep);
    window_pass(&a, rows, cols, r, false, count, keep)
}

/// A mask from explicit pixels (tests and measured masks).
pub fn mask_from_fn(grid: Grid, f: impl Fn(usize, usize) -> bool) -> Mask {
    let mut pixels = vec![false; grid.rows * grid.cols];
    for r in 0..grid.rows {
        for c in 0..grid.cols {
            pixels[r * grid.cols + c] = f(r, c);
        }
    }
    Mask { grid, pixels }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn grid(rows: usize, cols: usize) -> Grid {
        Grid {
            origin_m: [0.0, 0.0],
            pixel_m: 1.0,
            cols,
            rows,
        }
    }

    /// A tilted rectangle's centroid and axis come back; its area is the pixel count.
    #[test]
    fn stats_of_a_rotated_rectangle() {
        let th: f64 = 0.5;
        let m = mask_from_fn(grid(200, 200), |r, c| {
            let (x, y) = (c as f64 + 0.5 - 90.0, r as f64 + 0.5 - 110.0);
            let u = x * th.cos() + y * th.sin();
            let v = -x * th.sin() + y * th.cos();
            u.abs() < 60.0 && v.abs() < 15.0
        });
        let s = m.stats();
        assert!((s.centroid_m[0] - 90.0).abs() < 0.5 && (s.centroid_m[1] - 110.0).abs() < 0.5);
        assert!((s.angle_rad - th).abs() < 0.01, "{}", s.angle_rad);
        assert!((s.area_m2 - 120.0 * 30.0).abs() < 0.03 * 3600.0);
    }

    /// The slope mask of a bowl u_z = -c (R^2 - r^2) (slope 2 c r) is the annulus where 2 c r
    /// passes the threshold, filled to the bowl's disc; above the rim's slope 2 c R it is
    /// empty, and a depth mask of the same bowl is the disc where the depth passes 30 um.
    #[test]
    fn slope_mask_of_a_bowl() {
        let mesh = ocm_fem::mesh::generate::box_mesh([60, 60, 1], [12e-3, 12e-3, 2e-3]);
        let gel = Gel::from_mesh(mesh, crate::gel::GelMaterial::default(), 1e-9).unwrap();
        let grid = Grid::for_gel(&gel);
        let (c, rr) = (40.0, 4e-3); // 1/m, m: 0.64 mm deep at the centre, rim slope 0.32
        let u: Vec<[f64; 3]> = gel
            .mesh
            .points
            .iter()
            .map(|p| {
                let r2 = (p[0] - 6e-3).powi(2) + (p[1] - 6e-3).powi(2);
                [0.0, 0.0, -c * (rr * rr - r2).max(0.0)]
            })
            .collect();
        let disc = std::f64::consts::PI * rr * rr;
        // A slope of 0.2 is reached at r = 2.5 mm: the raw mask is a ring 1.5 mm wide.
        let m = MaskRule::Slope(0.2).mask(&gel, &grid, &u);
        let s = m.stats();
        assert!(
            (s.area_m2 / disc - 1.0).abs() < 0.03,
            "{} of {disc}",
            s.area_m2
        );
        assert!((s.centroid_m[0] - 6e-3).abs() < 0.1e-3 && (s.centroid_m[1] - 6e-3).abs() < 0.1e-3);
        assert!(
            !MaskRule::Slope(0.35)
                .mask(&gel, &grid, &u)
                .pixels
                .iter()
                .any(|&b| b)
        );
        // The depth mask: c (R^2 - r^2) > 30 um inside r^2 < R^2 - 30e-6 / c.
        let depth = Mask::from_displacement(&gel, &grid, &u).stats().area_m2;
        let want = std::f64::consts::PI * (rr * rr - 30e-6 / c);
        assert!((depth / want - 1.0).abs() < 0.03, "{depth} against {want}");
        // The slope image itself: 2 c r at r = 3 mm, to a pixel's worth of interpolation.
        let down: Vec<f64> = u.iter().map(|v| -v[2]).collect();
        let g = slope_image(&rasterize(&gel, &grid, &down), &grid);
        let at = |x: f64, y: f64| {
            let (col, row) = ((x / grid.pixel_m) as usize, (y / grid.pixel_m) as usize);
            g[row * grid.cols + col]
        };
        let want = 2.0 * c * 3e-3;
        assert!(
            (at(9e-3, 6e-3) / want - 1.0).abs() < 0.05,
            "{}",
            at(9e-3, 6e-3)
        );
        assert!(
            (at(6e-3, 3e-3) / want - 1.0).abs() < 0.05,
            "{}",
            at(6e-3, 3e-3)
        );
        assert!(at(1e-3, 1e-3) == 0.0, "flat outside the bowl");
    }

    /// A ramp of slope s across w columns: central differences give s on its inner columns and
    /// s / 2 on the two at its ends, 3 s in all for w = 3, so the 5 x 5 blur leaves at most
    /// 3 s / 5 of a ramp narrower than itself, as it leaves of a real frame's change; a ramp 12
    /// columns wide keeps s at its middle.
    #[test]
    fn slope_pixels_see_the_blur_of_real_frames() {
        assert_eq!(BLUR_RADIUS_PX, 2);
        let g = Grid {
            origin_m: [0.0, 0.0],
            pixel_m: 1e-4,
            cols: 60,
            rows: 20,
        };
        let s = 0.1;
        let ramp = |w: f64| -> Vec<f64> {
            (0..g.rows * g.cols)
                .map(|i| s * g.pixel_m * ((i % g.cols) as f64 - 20.0).clamp(0.0, w))
                .collect()
        };
        let raw = |img: &[f64], t: f64| slope_image(img, &g).iter().any(|&v| v > t);
        let any = |px: Vec<bool>| px.iter().any(|&b| b);
        let narrow = ramp(3.0);
        assert!(raw(&narrow, 0.07), "unblurred, the narrow ramp passes 0.07");
        assert!(
            !any(slope_pixels(&narrow, &g, 0.061)),
            "blurred: 3 s / 5 = 0.06"
        );
        assert!(any(slope_pixels(&narrow, &g, 0.059)));
        let blurred = box_blur(&slope_image(&narrow, &g), g.rows, g.cols, BLUR_RADIUS_PX);
        let peak = blurred.iter().cloned().fold(0.0, f64::max);
        assert!((peak - 0.6 * s).abs() < 1e-12, "{peak}");
        let wide = slope_pixels(&ramp(12.0), &g, 0.099);
        assert!(wide[10 * g.cols + 26] && !wide[10 * g.cols + 10]);
        let count = wide.iter().filter(|&&b| b).count();
        // Columns 23..=29: their 5-column windows hold only the ramp's inner columns 21..=31.
        assert_eq!(
            count,
            7 * g.rows,
            "the wide ramp's columns whose window is all slope s"
        );
    }

    /// Closing bridges a gap narrower than the kernel, keeps a wide one, and filling closes a ring.
    #[test]
    fn closing_and_filling() {
        let m = mask_from_fn(grid(40, 60), |r, c| {
            (10..30).contains(&r) && !(20..24).contains(&c)
        });
        let closed = m.closed(5);
        assert!(
            closed.pixels[20 * 60 + 22],
            "a 4-pixel gap is bridged by a 5x5 kernel"
        );
        assert_eq!(closed.count(), 20 * 60, "nothing else grows");
        let wide = mask_from_fn(grid(40, 60), |r, c| {
            (10..30).contains(&r) && !(20..30).contains(&c)
        });
        assert!(!wide.closed(5).pixels[20 * 60 + 25]);
        let ring = mask_from_fn(grid(40, 40), |r, c| {
            let d = ((r as f64 - 20.0).powi(2) + (c as f64 - 20.0).powi(2)).sqrt();
            (8.0..12.0).contains(&d)
        });
        let f = ring.filled();
        assert!(f.pixels[20 * 40 + 20] && !f.pixels[0]);
    }
}
