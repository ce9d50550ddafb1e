//! Training pairs of the perception and rendering networks: FEM states from an `ocm tactile
//! dataset` folder, rendered by the physically based renderer (real calibration, real
//! background) into delta images, with the displacement rasterised on the same image grid and
//! splatted from the nodes (eq 5.16).

use crate::dataset::{Dataset, TopSurface};
use crate::gel::Gel;
use crate::mask::Grid;
use crate::optics::{CameraMap, Renderer, RgbImage, SurfaceSampler};
use crate::{Result, TactileError};

/// Standard deviation of the Gaussian splatting kernel, pixels of the full 240 x 320 image
/// (eq 5.16).
pub const SPLAT_SIGMA_PX: f64 = 1.5;

/// Images, displacements and splats of every sample, at one resolution. Image layout:
/// [`image_map`], the gel's 20 mm side along the 320 columns.
#[derive(Debug, Clone)]
pub struct Pairs {
    /// Image rows.
    pub rows: usize,
    /// Image columns.
    pub cols: usize,
    /// Gel length per pixel, m.
    pub pixel_m: f64,
    /// Set-up names, in dataset order.
    pub setup_names: Vec<String>,
    /// Whether each set-up is from the unseen-indenter set.
    pub setup_unseen: Vec<bool>,
    /// Set-up of each sample.
    pub setup: Vec<usize>,
    /// Indentation depth of each sample, m.
    pub depth_m: Vec<f64>,
    /// Mirror of each sample: 0 none, bit 0 the image rows reversed (gel x mirrored), bit 1
    /// the columns (gel y); see [`build_pairs_mirrored`].
    pub mirror: Vec<u8>,
    /// The FEM state each sample was rendered from (its index among the unmirrored samples).
    pub state: Vec<usize>,
    /// Rendered minus background, grey levels, per sample `[3, rows, cols]` channel-major.
    pub delta: Vec<f32>,
    /// Surface displacement u_z on the image grid (negative into the gel), m, per sample
    /// `[rows, cols]` (eq 5.15's target).
    pub dz_m: Vec<f32>,
    /// Nodal u_z splatted with a normalised Gaussian kernel (eq 5.16), m, per sample
    /// `[rows, cols]` (the rendering network's input).
    pub splat_dz_m: Vec<f32>,
    /// The background at this resolution.
    pub background: RgbImage,
}

impl Pairs {
    /// Number of samples.
    pub fn len(&self) -> usize {
        self.depth_m.len()
    }

    /// Whether there are no samples.
    pub fn is_empty(&self) -> bool {
        self.depth_m.is_empty()
    }

    /// Pixels per image.
    pub fn pixels(&self) -> usize {
        self.rows * self.cols
    }

    /// Unmirrored samples of the seen (`unseen` false) or unseen set-ups.
    pub fn samples_where_unseen(&self, unseen: bool) -> Vec<usize> {
        (0..self.len())
            .filter(|&i| self.setup_unseen[self.setup[i]] == unseen && self.mirror[i] == 0)
            .collect()
    }

    /// The mirrored copies of the unmirrored samples `originals` (for training on them
    /// without leaking a validation state into training).
    pub fn mirrors_of(&self, originals: &[usize]) -> Vec<usize> {
        let states: std::collections::HashSet<usize> =
            originals.iter().map(|&i| self.state[i]).collect();
        (0..self.len())
            .filter(|&i| self.mirror[i] != 0 && states.contains(&self.state[i]))
            .collect()
    }

    /// The image plane as a mask grid (origin at the image corner, `pixel_m` per pixel):
    /// areas, distances and undirected angle differences measured on it are those on the gel.
    pub fn grid(&self) -> Grid {
        Grid {
            origin_m: [0.0, 0.0],
            pixel_m: self.pixel_m,
            rows: self.rows,
            cols: self.cols,
        }
    }

    /// Sample `i`'s rendered frame (background + delta, rounded).
    pub fn frame(&self, i: usize) -> RgbImage {
        frame_from_delta(
            &self.background,
            &self.delta[i * 3 * self.pixels()..][..3 * self.pixels()],
        )
    }
}

/// Background plus a channel-major `[3, rows, cols]` delta, rounded and clipped to 0..255.
pub fn frame_from_delta(bg: &RgbImage, delta: &[f32]) -> RgbImage {
    let n = bg.rows * bg.cols;
    let mut data = bg.data.clone();
    for p in 0..n {
        for ch in 0..3 {
            let v = f32::from(bg.data[p * 3 + ch]) + delta[ch * n + p];
            data[p * 3 + ch] = (v.clamp(0.0, 255.0) + 0.5) as u8;
        }
    }
    RgbImage {
        rows: bg.rows,
        cols: bg.cols,
        data,
    }
}

/// A channel-major `[3, rows, cols]` delta (grey levels) of `img` against `bg`; an error naming
/// both sizes when they differ.
pub fn delta_of(img: &RgbImage, bg: &RgbImage) -> Result<Vec<f32>> {
    if (img.rows, img.cols) != (bg.rows, bg.cols) || img.data.len() != img.rows * img.cols * 3 {
        return Err(TactileError::Input(format!(
            "image of {} x {} (cols x rows) against a background of {} x {}",
            img.cols, img.rows, bg.cols, bg.rows
        )));
    }
    let n = img.rows * img.cols;
    let mut d = vec![0.0f32; 3 * n];
    for p in 0..n {
        for ch in 0..3 {
            d[ch * n + p] = f32::from(img.data[p * 3 + ch]) - f32::from(bg.data[p * 3 + ch]);
        }
    }
    Ok(d)
}

/// Means over `f` x `f` blocks of a `[rows, cols]` field.
pub fn block_mean(v: &[f32], rows: usize, cols: usize, f: usize) -> Vec<f32> {
    if f == 1 {
        return v.to_vec();
    }
    let (r2, c2) = (rows / f, cols / f);
    let mut out = vec![0.0f32; r2 * c2];
    let w = 1.0 / (f * f) as f32;
    for r in 0..r2 * f {
        for c in 0..c2 * f {
            out[(r / f) * c2 + c / f] += v[r * cols + c] * w;
        }
    }
    out
}

/// An RGB image reduced by `f` x `f` block means (rounded); `f` = 1 returns a copy.
pub fn downscale(img: &RgbImage, f: usize) -> RgbImage {
    if f <= 1 {
        return img.clone();
    }
    let (rows, cols) = (img.rows / f, img.cols / f);
    let mut data = vec![0u8; rows * cols * 3];
    for ch in 0..3 {
        let plane: Vec<f32> = img.channel(ch).iter().map(|&v| v as f32).collect();
        for (p, v) in block_mean(&plane, img.rows, img.cols, f).iter().enumerate() {
            data[p * 3 + ch] = (v + 0.5) as u8;
        }
    }
    RgbImage { rows, cols, data }
}

/// A u_z field (m, `[rows, cols]`) as a grey image: black undeformed, white at 1 mm into the
/// gel.
pub fn depth_image(dz_m: &[f32], rows: usize, cols: usize) -> RgbImage {
    RgbImage {
        rows,
        cols,
        data: dz_m
            .iter()
            .flat_map(|&v| {
                let g = ((-f64::from(v) / 1e-3 * 255.0).clamp(0.0, 255.0) + 0.5) as u8;
                [g, g, g]
            })
            .collect(),
    }
}

/// Normalised Gaussian splatting of values at points (column, row in pixels, centres at
/// half-integers) onto a rows x cols grid: sum_i K w_i / sum_i K within 3 sigma; pixels no point
/// reaches get 0.
pub fn splat(
    points_px: &[[f64; 2]],
    values: &[f64],
    rows: usize,
    cols: usize,
    sigma_px: f64,
) -> Vec<f32> {
    let mut num = vec![0.0f64; rows * cols];
    let mut den = vec![0.0f64; rows * cols];
    let reach = (3.0 * sigma_px).ceil() as isize;
    let inv = 1.0 / (2.0 * sigma_px * sigma_px);
    for (p, &v) in points_px.iter().zip(values) {
        let (c0, r0) = ((p[0] - 0.5).round() as isize, (p[1] - 0.5).round() as isize);
        for r in (r0 - reach).max(0)..=(r0 + reach).min(rows as isize - 1) {
            for c in (c0 - reach).max(0)..=(c0 + reach).min(cols as isize - 1) {
                let (dx, dy) = (c as f64 + 0.5 - p[0], r as f64 + 0.5 - p[1]);
                let k = (-(dx * dx + dy * dy) * inv).exp();
                let i = r as usize * cols + c as usize;
                num[i] += k * v;
                den[i] += k;
            }
        }
    }
    num.iter()
        .zip(&den)
        .map(|(n, d)| if *d > 1e-6 { (n / d) as f32 } else { 0.0 })
        .collect()
}

/// The image frame of the pairs: [`crate::optics::camera::landscape_map`].
pub fn image_map(gel: &Gel, scale: usize) -> (CameraMap, usize, usize) {
    crate::optics::camera::landscape_map(gel, scale)
}

/// Renders every sample of `ds` (on `gel`, the mesh the dataset was built on) with `renderer`
/// (background of the full image size, 240 x 320) and reduces images and fields by `scale`
/// (1 or a divisor of both sides: block means).
pub fn build_pairs(ds: &Dataset, gel: &Gel, renderer: &Renderer, scale: usize) -> Result<Pairs> {
    build_pairs_mirrored(ds, gel, renderer, scale, false)
}

/// [`build_pairs`], and with `mirror` three more samples per state of the seen set-ups: the
/// surface mirrored across the image rows, the columns and both, each rendered anew (the
/// calibration depends on the slope direction and the image position, so a mirrored image
/// would not be a valid frame; the mirrored surface is, the gel being symmetric about its
/// centre lines). Mirrored samples come after the unmirrored ones.
pub fn build_pairs_mirrored(
    ds: &Dataset,
    gel: &Gel,
    renderer: &Renderer,
    scale: usize,
    mirror: bool,
) -> Result<Pairs> {
    let (rows0, cols0) = (renderer.rows, renderer.cols);
    if scale == 0 || rows0 % scale != 0 || cols0 % scale != 0 {
        return Err(TactileError::Input(format!(
            "scale {scale} does not divide the {cols0} x {rows0} image"
        )));
    }
    if ds.top_rest_m.len() != gel.top.len() {
        return Err(TactileError::Input(format!(
            "dataset {} has {} top nodes, the gel {}: built on another mesh",
            ds.dir.display(),
            ds.top_rest_m.len(),
            gel.top.len()
        )));
    }
    let (map, r_img, c_img) = image_map(gel, 1);
    if (r_img, c_img) != (rows0, cols0) {
        return Err(TactileError::Input(format!(
            "renderer of {cols0} x {rows0} for a gel image of {c_img} x {r_img}"
        )));
    }
    let sampler = SurfaceSampler::new(gel, rows0, cols0, &map);
    let top = TopSurface::from_gel(gel);
    let (rows, cols) = (rows0 / scale, cols0 / scale);
    let node_px: Vec<[f64; 2]> = top
        .rest_m
        .iter()
        .map(|p| {
            let q = map.to_px([p[0], p[1]]);
            [q[0] / scale as f64, q[1] / scale as f64]
        })
        .collect();
    let bg0 = renderer.background();
    let background = downscale(&bg0, scale);
    let mut out = Pairs {
        rows,
        cols,
        pixel_m: sampler.m_per_px * scale as f64,
        setup_names: ds.setups.iter().map(|s| s.name.clone()).collect(),
        setup_unseen: ds.setups.iter().map(|s| s.unseen).collect(),
        setup: Vec::new(),
        depth_m: Vec::new(),
        mirror: Vec::new(),
        state: Vec::new(),
        delta: Vec::new(),
        dz_m: Vec::new(),
        splat_dz_m: Vec::new(),
        background,
    };
    let mut h = vec![0.0f32; rows0 * cols0];
    let mut hm = vec![0.0f32; rows0 * cols0];
    let mut img = vec![0u8; rows0 * cols0 * 3];
    let mut state = 0;
    let mut later = Vec::new();
    for (si, s) in ds.setups.iter().enumerate() {
        for (k, u_top) in s.displacement_m.iter().enumerate() {
            let u = top.extend(u_top, gel.num_nodes());
            sampler.heights(&u, &mut h)?;
            let vals: Vec<f64> = u_top.iter().map(|u| u[2]).collect();
            let variants: &[u8] = if mirror && !s.unseen {
                &[0, 1, 2, 3]
            } else {
                &[0]
            };
            for &m in variants {
                mirror_into(&h, rows0, cols0, m, &mut hm);
                renderer.render_into(&hm, sampler.m_per_px as f32, &mut img)?;
                let mut d = Vec::with_capacity(3 * rows * cols);
                for ch in 0..3 {
                    let dc: Vec<f32> = (0..rows0 * cols0)
                        .map(|p| f32::from(img[p * 3 + ch]) - f32::from(bg0.data[p * 3 + ch]))
                        .collect();
                    d.extend(block_mean(&dc, rows0, cols0, scale));
                }
                let dz: Vec<f32> = hm.iter().map(|v| -v).collect();
                let px: Vec<[f64; 2]> = node_px
                    .iter()
                    .map(|q| {
                        [
                            if m & 2 != 0 { cols as f64 - q[0] } else { q[0] },
                            if m & 1 != 0 { rows as f64 - q[1] } else { q[1] },
                        ]
                    })
                    .collect();
                let sample = (
                    d,
                    block_mean(&dz, rows0, cols0, scale),
                    splat(&px, &vals, rows, cols, SPLAT_SIGMA_PX / scale as f64),
                    si,
                    s.depth_m[k],
                    m,
                    state,
                );
                if m == 0 {
                    push_sample(&mut out, sample);
                } else {
                    later.push(sample);
                }
            }
            state += 1;
        }
    }
    for sample in later {
        push_sample(&mut out, sample);
    }
    Ok(out)
}

type Sample = (Vec<f32>, Vec<f32>, Vec<f32>, usize, f64, u8, usize);

fn push_sample(out: &mut Pairs, (delta, dz, splat, setup, depth, mirror, state): Sample) {
    out.delta.extend(delta);
    out.dz_m.extend(dz);
    out.splat_dz_m.extend(splat);
    out.setup.push(setup);
    out.depth_m.push(depth);
    out.mirror.push(mirror);
    out.state.push(state);
}

/// `h` (rows x cols) into `out` with the rows reversed (bit 0 of `m`) and the columns (bit 1).
pub fn mirror_into(h: &[f32], rows: usize, cols: usize, m: u8, out: &mut [f32]) {
    for r in 0..rows {
        let rs = if m & 1 != 0 { rows - 1 - r } else { r };
        let src = &h[rs * cols..][..cols];
        let dst = &mut out[r * cols..][..cols];
        if m & 2 != 0 {
            for (d, s) in dst.iter_mut().zip(src.iter().rev()) {
                *d = *s;
            }
        } else {
            dst.copy_from_slice(src);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A lone point splats its value over its reach; overlapping points give their weighted
    /// mean; a constant field stays constant.
    #[test]
    fn splatting_is_a_normalised_kernel_mean() {
        let s = splat(&[[5.5, 4.5]], &[2.0], 10, 12, 1.5);
        assert_eq!(s[4 * 12 + 5], 2.0);
        assert!((s[4 * 12 + 9] - 2.0).abs() < 1e-6);
        assert_eq!(s[4 * 12 + 11], 0.0);
        let s = splat(&[[5.5, 4.5], [7.5, 4.5]], &[1.0, 3.0], 10, 12, 1.5);
        assert!((s[4 * 12 + 6] - 2.0).abs() < 1e-6);
        assert!(s[4 * 12 + 5] > 1.0 && s[4 * 12 + 5] < 2.0);
        let pts: Vec<[f64; 2]> = (0..40)
            .map(|i| [(i % 8) as f64 * 1.3, (i / 8) as f64 * 1.9])
            .collect();
        let s = splat(&pts, &[0.7; 40], 10, 12, 1.5);
        assert!(
            s.iter()
                .filter(|v| **v != 0.0)
                .all(|v| (v - 0.7).abs() < 1e-6)
        );
        assert_eq!(block_mean(&[1.0, 3.0, 5.0, 7.0], 2, 2, 2), vec![4.0]);
    }

    /// Mirroring reverses rows (bit 0), columns (bit 1) or both, and is its own inverse.
    #[test]
    fn mirroring() {
        let h: Vec<f32> = (0..6).map(|v| v as f32).collect();
        let mut o = vec![0.0; 6];
        mirror_into(&h, 2, 3, 1, &mut o);
        assert_eq!(o, [3.0, 4.0, 5.0, 0.0, 1.0, 2.0]);
        mirror_into(&h, 2, 3, 2, &mut o);
        assert_eq!(o, [2.0, 1.0, 0.0, 5.0, 4.0, 3.0]);
        mirror_into(&h, 2, 3, 3, &mut o);
        assert_eq!(o, [5.0, 4.0, 3.0, 2.0, 1.0, 0.0]);
        let mut back = vec![0.0; 6];
        mirror_into(&o, 2, 3, 3, &mut back);
        assert_eq!(back, h);
    }

    /// Delta and frame are inverse (up to rounding) and sizes are checked.
    #[test]
    fn delta_round_trip() {
        let bg = RgbImage {
            rows: 2,
            cols: 3,
            data: (0..18).map(|i| (i * 10) as u8).collect(),
        };
        let img = RgbImage {
            rows: 2,
            cols: 3,
            data: (0..18).map(|i| (i * 10 + i % 5) as u8).collect(),
        };
        let d = delta_of(&img, &bg).unwrap();
        assert_eq!(frame_from_delta(&bg, &d), img);
        let small = RgbImage {
            rows: 1,
            cols: 3,
            data: vec![0; 9],
        };
        assert!(delta_of(&small, &bg).is_err());
    }
}
