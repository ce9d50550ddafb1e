//! The FEM against real DIGIT frames (issue 16 item 4, issue 17 item 1): measured contact
//! masks from the real frames by background subtraction, simulated masks from the FEM at the
//! same depths, the gel-to-image map fitted on half of the depths and scored on the other half;
//! then frames rendered from the FEM against the real frames.

use crate::gel::Gel;
use crate::mask::{
    BLUR_RADIUS_PX, CLOSING_KERNEL_PX, Grid, Mask, MaskRule, box_blur, mask_from_fn,
};
use crate::metrics;
use crate::optics::render::IDENTITY_COLOUR;
use crate::optics::{CameraMap, Renderer, RgbImage, SurfaceSampler};
use crate::{Result, TactileError};
use serde::{Deserialize, Serialize};
use std::path::Path;

/// Rows of the compared images (the DIGIT frame at half its 640 x 480 stream).
pub const ROWS: usize = 240;
/// Columns of the compared images.
pub const COLS: usize = 320;

/// The optical calibration used by default, relative to the `digit` data folder.
pub const DEFAULT_CALIB: &str = "optics/taxim_polycalib.npz";
/// The no-contact background used by default (frame 00 of the real edge sequence), relative to
/// the `digit` data folder.
pub const DEFAULT_BACKGROUND: &str = "real-frames-edge6/edge6_00.jpg";

/// The renderer every tool starts from: the default calibration over the default background,
/// at the real frames' size.
pub fn default_renderer(digit: &Path) -> Result<Renderer> {
    let calib = crate::optics::PolyCalib::from_npz(digit.join(DEFAULT_CALIB))?;
    let bg = RgbImage::read_sized(digit.join(DEFAULT_BACKGROUND), ROWS, COLS)?;
    Renderer::new(calib, &bg)
}

/// Reads `{prefix}_00.jpg`, `{prefix}_01.jpg`, ... from `dir` until the first missing number,
/// at 240 x 320 (a 480 x 640 frame is averaged over 2 x 2 blocks). Frame 0 is the background.
pub fn load_frames(dir: &Path, prefix: &str) -> Result<Vec<RgbImage>> {
    let mut frames = Vec::new();
    loop {
        let p = dir.join(format!("{prefix}_{:02}.jpg", frames.len()));
        if !p.exists() {
            break;
        }
        frames.push(RgbImage::read_sized(&p, ROWS, COLS)?);
    }
    if frames.len() < 3 {
        return Err(TactileError::Input(format!(
            "{}: found {} frames {prefix}_NN.jpg; need a background and at least two contact frames",
            dir.display(),
            frames.len()
        )));
    }
    Ok(frames)
}

/// The image as a mask grid with one unit per pixel (centroids in pixels).
pub fn image_grid(rows: usize, cols: usize) -> Grid {
    Grid {
        origin_m: [0.0, 0.0],
        pixel_m: 1.0,
        cols,
        rows,
    }
}

/// How a contact mask is measured on a real frame.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct MaskOptions {
    /// Change against the background above which a pixel is in contact: the mean over R, G, B
    /// of |frame - background| after the box blur of [`BLUR_RADIUS_PX`], grey levels.
    pub threshold: f64,
}

impl Default for MaskOptions {
    fn default() -> Self {
        MaskOptions { threshold: 10.0 }
    }
}

/// Mean absolute change over the channels, box-blurred over [`BLUR_RADIUS_PX`] (JPEG and sensor
/// noise; the FEM's slope masks see the same blur).
pub fn change_image(frame: &RgbImage, bg: &RgbImage) -> Result<Vec<f64>> {
    if (frame.rows, frame.cols) != (bg.rows, bg.cols) || frame.data.len() != bg.data.len() {
        return Err(TactileError::Input(format!(
            "frame is {} x {} but the background is {} x {} (cols x rows)",
            frame.cols, frame.rows, bg.cols, bg.rows
        )));
    }
    let (rows, cols) = (frame.rows, frame.cols);
    let d: Vec<f64> = frame
        .data
        .chunks_exact(3)
        .zip(bg.data.chunks_exact(3))
        .map(|(a, b)| {
            (0..3)
                .map(|k| (f64::from(a[k]) - f64::from(b[k])).abs())
                .sum::<f64>()
                / 3.0
        })
        .collect();
    Ok(box_blur(&d, rows, cols, BLUR_RADIUS_PX))
}

/// The measured contact mask of a real frame: the blurred change against the background above
/// the threshold, closed with the 15 x 15 kernel of the FEM masks and with holes filled.
pub fn measured_mask(frame: &RgbImage, bg: &RgbImage, opts: &MaskOptions) -> Result<Mask> {
    if !(opts.threshold > 0.0) {
        return Err(TactileError::Input(format!(
            "mask threshold {} grey levels is not positive",
            opts.threshold
        )));
    }
    let d = change_image(frame, bg)?;
    let raw = mask_from_fn(image_grid(frame.rows, frame.cols), |r, c| {
        d[r * frame.cols + c] > opts.threshold
    });
    Ok(raw.closed(CLOSING_KERNEL_PX).filled())
}

/// A mask on the gel grid seen through the camera map: each image pixel centre takes the gel
/// grid cell it falls in (off the grid: no contact).
pub fn warp_mask(gel_mask: &Mask, map: &CameraMap, rows: usize, cols: usize) -> Mask {
    let g = gel_mask.grid;
    mask_from_fn(image_grid(rows, cols), |r, c| {
        let p = map.to_gel([c as f64 + 0.5, r as f64 + 0.5]);
        let gc = ((p[0] - g.origin_m[0]) / g.pixel_m).floor();
        let gr = ((p[1] - g.origin_m[1]) / g.pixel_m).floor();
        gc >= 0.0
            && gr >= 0.0
            && (gc as usize) < g.cols
            && (gr as usize) < g.rows
            && gel_mask.pixels[gr as usize * g.cols + gc as usize]
    })
}

/// Mask agreement at one depth.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct MaskScore {
    /// Real frame index (depth = index x step from the start of the real sequence).
    pub frame: usize,
    /// FEM step compared with it (0: before first touch, an empty mask).
    pub fem_step: usize,
    /// Intersection over union.
    pub iou: f64,
    /// Centroid distance on the gel, mm (NaN when a mask is empty).
    pub centroid_error_mm: f64,
    /// Angle between the principal axes, rad.
    pub rotation_error_rad: f64,
    /// Real mask area, mm^2 on the gel.
    pub real_area_mm2: f64,
    /// FEM mask area, mm^2 on the gel.
    pub fem_area_mm2: f64,
}

/// Scores one pair of image-space masks; `px_per_m` converts pixels to gel lengths.
pub fn score_masks(real: &Mask, fem: &Mask, px_per_m: f64) -> Result<(f64, f64, f64)> {
    let iou = metrics::iou(real, fem)?;
    let (a, b) = (real.stats(), fem.stats());
    let cen = metrics::centroid_error(&a, &b) / px_per_m * 1e3;
    Ok((iou, cen, metrics::rotation_error(a.angle_rad, b.angle_rad)))
}

/// What the mask fit found.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct MaskFit {
    /// The gel-to-image map.
    pub map: CameraMap,
    /// Real frame k is compared with FEM step round((k - offset) x `steps_per_frame`): the real
    /// sequence starts above the gel. In frames; in steps too at one step per frame.
    pub offset_steps: usize,
    /// FEM steps (10 um) per real frame: 1 when the frames were taken at the steps, more when
    /// they are samples of a video whose indenter moved farther between them.
    #[serde(default = "one")]
    pub steps_per_frame: f64,
    /// Mean IoU on the fitting depths.
    pub fit_iou: f64,
}

impl MaskFit {
    /// The FEM step paired with real frame `k` (0 before the first touch).
    pub fn step_for(&self, k: usize) -> usize {
        paired_step(k, self.offset_steps, self.steps_per_frame)
    }
}

/// FEM step round((k - offset) x steps_per_frame) paired with real frame k; 0 (no contact) at
/// or before the offset.
pub fn paired_step(k: usize, offset: usize, steps_per_frame: f64) -> usize {
    if k <= offset {
        0
    } else {
        ((k - offset) as f64 * steps_per_frame).round() as usize
    }
}

/// The camera map and optics `compare-real` fitted, as its `map.json` holds them.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct OpticsFile {
    /// The gel-to-image map of the real camera.
    pub map: CameraMap,
    /// Real frame k shows FEM step round((k - offset) x `steps_per_frame`).
    pub offset_steps: usize,
    /// FEM steps per real frame (1 in maps written before it was fitted).
    #[serde(default = "one")]
    pub steps_per_frame: f64,
    /// Gain on the calibrated change.
    #[serde(default = "one")]
    pub gain: f64,
    /// Height smoothing, pixels.
    #[serde(default)]
    pub smooth_px: f32,
    /// Colour transform of the calibrated change (rows: R, G, B out).
    pub colour: [[f64; 3]; 3],
    /// Depth shading, grey levels per m.
    pub depth_gain_per_m: [f64; 3],
}

fn one() -> f64 {
    1.0
}

impl OpticsFile {
    /// Reads `map.json` as `compare-real` writes it; an error names the file and what is
    /// missing.
    pub fn read(path: &Path) -> Result<Self> {
        let text = std::fs::read_to_string(path)
            .map_err(|e| TactileError::Input(format!("reading {}: {e}", path.display())))?;
        serde_json::from_str(&text).map_err(|e| {
            TactileError::Input(format!(
                "{} is not a compare-real map.json (map, offset_steps, colour, depth_gain_per_m): {e}",
                path.display()
            ))
        })
    }

    /// The FEM step paired with real frame `k` (0 before the first touch).
    pub fn step_for(&self, k: usize) -> usize {
        paired_step(k, self.offset_steps, self.steps_per_frame)
    }

    /// Sets `renderer`'s optics (gain, smoothing, colour transform, depth shading) to these.
    pub fn apply(&self, renderer: &mut Renderer) {
        set_optics(
            renderer,
            self.gain,
            self.smooth_px,
            &self.colour,
            &self.depth_gain_per_m,
        );
    }
}

/// A mask with its pixel count and bounding box (rows, cols; inclusive), for fast IoUs.
struct Boxed<'a> {
    mask: &'a Mask,
    count: usize,
    /// [r0, r1, c0, c1]; None when empty.
    bbox: Option<[usize; 4]>,
}

impl<'a> Boxed<'a> {
    fn new(mask: &'a Mask) -> Self {
        let g = mask.grid;
        let (mut r0, mut r1, mut c0, mut c1) = (usize::MAX, 0, usize::MAX, 0);
        let mut count = 0;
        for r in 0..g.rows {
            for c in 0..g.cols {
                if mask.pixels[r * g.cols + c] {
                    count += 1;
                    r0 = r0.min(r);
                    r1 = r1.max(r);
                    c0 = c0.min(c);
                    c1 = c1.max(c);
                }
            }
        }
        Boxed {
            mask,
            count,
            bbox: (count > 0).then_some([r0, r1, c0, c1]),
        }
    }
}

/// IoU of a real image mask against a gel-grid mask seen through `map`, visiting only the
/// pixels inside the two bounding boxes (identical to warping the whole mask first). None when
/// both are empty.
fn warped_iou(real: &Boxed, gel: &Boxed, map: &CameraMap) -> Option<f64> {
    let (rows, cols) = (real.mask.grid.rows, real.mask.grid.cols);
    let g = gel.mask.grid;
    // Image box of the gel mask: its gel-grid box corners mapped to the image.
    let gbox = gel.bbox.map(|[r0, r1, c0, c1]| {
        let corners = [
            [c0 as f64, r0 as f64],
            [c1 as f64 + 1.0, r0 as f64],
            [c0 as f64, r1 as f64 + 1.0],
            [c1 as f64 + 1.0, r1 as f64 + 1.0],
        ]
        .map(|[c, r]| map.to_px([g.origin_m[0] + c * g.pixel_m, g.origin_m[1] + r * g.pixel_m]));
        let lo_c = corners.iter().map(|p| p[0]).fold(f64::INFINITY, f64::min);
        let hi_c = corners
            .iter()
            .map(|p| p[0])
            .fold(f64::NEG_INFINITY, f64::max);
        let lo_r = corners.iter().map(|p| p[1]).fold(f64::INFINITY, f64::min);
        let hi_r = corners
            .iter()
            .map(|p| p[1])
            .fold(f64::NEG_INFINITY, f64::max);
        let cl = |v: f64, n: usize| v.clamp(0.0, n as f64 - 1.0) as usize;
        [
            cl(lo_r.floor() - 1.0, rows),
            cl(hi_r.ceil() + 1.0, rows),
            cl(lo_c.floor() - 1.0, cols),
            cl(hi_c.ceil() + 1.0, cols),
        ]
    });
    let Some([r0, r1, c0, c1]) = gbox else {
        return (real.count > 0).then_some(0.0);
    };
    let (sn, cs) = map.angle_rad.sin_cos();
    let inv = 1.0 / map.px_per_m;
    let (mut inter, mut warped) = (0usize, 0usize);
    for r in r0..=r1 {
        for c in c0..=c1 {
            let u = (c as f64 + 0.5 - map.offset_px[0]) * inv;
            let v = (r as f64 + 0.5 - map.offset_px[1]) * inv;
            let x = cs * u + sn * v;
            let y = -sn * u + cs * v;
            let y = if map.mirror { -y } else { y };
            let gc = ((x - g.origin_m[0]) / g.pixel_m).floor();
            let gr = ((y - g.origin_m[1]) / g.pixel_m).floor();
            if gc >= 0.0
                && gr >= 0.0
                && (gc as usize) < g.cols
                && (gr as usize) < g.rows
                && gel.mask.pixels[gr as usize * g.cols + gc as usize]
            {
                warped += 1;
                inter += usize::from(real.mask.pixels[r * cols + c]);
            }
        }
    }
    let union = real.count + warped - inter;
    if union == 0 {
        None
    } else {
        Some(inter as f64 / union as f64)
    }
}

/// Mean IoU over pairs (real mask, FEM gel-grid mask) under `map`; pairs with both masks empty
/// are skipped (they say nothing about the map).
fn mean_iou(pairs: &[(Boxed, Boxed)], map: &CameraMap) -> f64 {
    let mut s = 0.0;
    let mut n = 0usize;
    for (real, gel) in pairs {
        if let Some(v) = warped_iou(real, gel, map) {
            s += v;
            n += 1;
        }
    }
    if n == 0 { 0.0 } else { s / n as f64 }
}

/// Compass (pattern) search maximising `f` from `x0` with initial steps `step` (a zero step
/// holds its coordinate); the IoU is piecewise constant, so no gradients. Steps halve when no
/// move improves, until all are below `tol` times their start.
fn compass_max(f: &dyn Fn(&[f64]) -> f64, x0: &[f64], step: &[f64], tol: f64) -> (Vec<f64>, f64) {
    let mut x = x0.to_vec();
    let mut fx = f(&x);
    let mut h = step.to_vec();
    for _ in 0..400 {
        let mut moved = false;
        for i in 0..x.len() {
            if h[i] == 0.0 {
                continue;
            }
            for sgn in [1.0, -1.0] {
                let mut y = x.clone();
                y[i] += sgn * h[i];
                let fy = f(&y);
                if fy > fx {
                    x = y;
                    fx = fy;
                    moved = true;
                    break;
                }
            }
        }
        if !moved {
            for (hi, si) in h.iter_mut().zip(step) {
                *hi *= 0.5;
                if *hi < tol * si {
                    return (x, fx);
                }
            }
        }
    }
    (x, fx)
}

/// Fits the gel-to-image map (scale, rotation, mirror, shift) and the step offset between the
/// real sequence and the FEM on the frames `fit` (indices into `real`), maximising the mean
/// mask IoU. `fem[j]` is the gel-grid mask of FEM step j + 1; real frame k pairs with step
/// [`paired_step`]`(k, offset, steps_per_frame)` (an empty mask below 1). `offsets` lists the
/// offsets tried. Every offset, mirror and half-turn starts from second moments and is
/// searched on every other fitting frame; the best is refined on all of them. `px_per_m` fixes
/// the scale (pixels per metre of gel) instead of fitting it. Fitting frames paired past the
/// FEM's last step are left out.
pub fn fit_map(
    real: &[Mask],
    fem: &[Mask],
    fit: &[usize],
    offsets: std::ops::RangeInclusive<usize>,
    px_per_m: Option<f64>,
    steps_per_frame: f64,
) -> Result<MaskFit> {
    if !(steps_per_frame > 0.0) || !steps_per_frame.is_finite() {
        return Err(TactileError::Input(format!(
            "FEM steps per real frame must be finite and positive (got {steps_per_frame})"
        )));
    }
    use rayon::prelude::*;
    let Some(gel_grid) = fem.first().map(|m| m.grid) else {
        return Err(TactileError::Input("no FEM masks to fit against".into()));
    };
    let empty = mask_from_fn(gel_grid, |_, _| false);
    let pair = |k: usize, o: usize| -> &Mask {
        match paired_step(k, o, steps_per_frame) {
            j @ 1.. if j <= fem.len() => &fem[j - 1],
            _ => &empty,
        }
    };
    let pairs_for = |o: usize, every: usize| -> Vec<(Boxed, Boxed)> {
        fit.iter()
            .filter(|&&k| paired_step(k, o, steps_per_frame) <= fem.len())
            .step_by(every)
            .map(|&k| (Boxed::new(&real[k]), Boxed::new(pair(k, o))))
            .collect()
    };
    let make = |x: &[f64], mirror: bool| CameraMap {
        px_per_m: px_per_m.unwrap_or(x[0].exp()),
        angle_rad: x[1],
        mirror,
        offset_px: [x[2], x[3]],
    };
    let mut starts = Vec::new();
    for o in offsets {
        let pairs = pairs_for(o, 1);
        // Start from second moments of the deepest fitting pair with both masks present.
        let Some((rm, gm)) = pairs.iter().rev().find(|(r, g)| r.count > 0 && g.count > 0) else {
            continue;
        };
        let (rs, gs) = (rm.mask.stats(), gm.mask.stats());
        let s0 = px_per_m.unwrap_or((rs.area_m2 / gs.area_m2).sqrt());
        for mirror in [false, true] {
            let ga = if mirror { -gs.angle_rad } else { gs.angle_rad };
            for flip in [0.0, std::f64::consts::PI] {
                let angle = rs.angle_rad - ga + flip;
                let m0 = make(&[s0.ln(), angle, 0.0, 0.0], mirror);
                let c = m0.to_px(gs.centroid_m);
                let x0 = vec![
                    s0.ln(),
                    angle,
                    rs.centroid_m[0] - c[0],
                    rs.centroid_m[1] - c[1],
                ];
                starts.push((o, mirror, x0));
            }
        }
    }
    let step = [if px_per_m.is_some() { 0.0 } else { 0.1 }, 0.1, 8.0, 8.0];
    let coarse: Vec<(usize, bool, Vec<f64>, f64)> = starts
        .into_par_iter()
        .map(|(o, mirror, x0)| {
            let pairs = pairs_for(o, 2);
            let f = |x: &[f64]| mean_iou(&pairs, &make(x, mirror));
            let (x, fx) = compass_max(&f, &x0, &step, 0.05);
            (o, mirror, x, fx)
        })
        .collect();
    let Some((o, mirror, x, _)) = coarse.into_iter().max_by(|a, b| a.3.total_cmp(&b.3)) else {
        return Err(TactileError::Input(
            "no fitting depth has contact in both the real frames and the FEM".into(),
        ));
    };
    let pairs = pairs_for(o, 1);
    let f = |x: &[f64]| mean_iou(&pairs, &make(x, mirror));
    let fine_step: Vec<f64> = step.iter().map(|v| v * 0.25).collect();
    let (x, fx) = compass_max(&f, &x, &fine_step, 0.04);
    Ok(MaskFit {
        map: make(&x, mirror),
        offset_steps: o,
        steps_per_frame,
        fit_iou: fx,
    })
}

/// Scores the fitted map on the frames `score`.
pub fn score_map(
    real: &[Mask],
    fem: &[Mask],
    fit: &MaskFit,
    score: &[usize],
) -> Result<Vec<MaskScore>> {
    let mut out = Vec::new();
    let s = fit.map.px_per_m;
    for &k in score {
        let j = fit.step_for(k);
        if j > fem.len() {
            // Deeper than the FEM ran: nothing to compare.
            continue;
        }
        let w = if j >= 1 {
            warp_mask(&fem[j - 1], &fit.map, real[k].grid.rows, real[k].grid.cols)
        } else {
            mask_from_fn(real[k].grid, |_, _| false)
        };
        if real[k].count() == 0 && w.count() == 0 {
            continue;
        }
        let (iou, cen, rot) = score_masks(&real[k], &w, s)?;
        out.push(MaskScore {
            frame: k,
            fem_step: j.min(fem.len()),
            iou,
            centroid_error_mm: cen,
            rotation_error_rad: rot,
            real_area_mm2: real[k].count() as f64 / (s * s) * 1e6,
            fem_area_mm2: w.count() as f64 / (s * s) * 1e6,
        });
    }
    Ok(out)
}

/// Rendered-against-real agreement at one depth.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct RenderScore {
    /// Real frame index.
    pub frame: usize,
    /// FEM step rendered.
    pub fem_step: usize,
    /// Mean absolute difference over all pixels and channels, grey levels.
    pub l1: f64,
    /// PSNR, dB (peak 255).
    pub psnr_db: f64,
    /// SSIM over the whole frame, mean of the R, G, B channels (an unchanged background
    /// dominates it: see `contact_ssim`).
    pub ssim: f64,
    /// IoU of the masks measured on the rendered and on the real frame.
    pub mask_iou: f64,
    /// SSIM (channel mean, 0-255, dynamic range 255) over the windows that overlap the real
    /// frame's measured contact (window centres in the mask dilated by 5 px); None when the real
    /// frame shows no contact.
    pub contact_ssim: Option<f64>,
    /// Mean absolute difference over the same contact region, grey levels.
    pub contact_l1: Option<f64>,
}

/// The pixels where a rendered frame is judged against a real one: the real frame's measured
/// contact mask dilated by the SSIM window's half-width, so that every window overlapping the
/// contact has its centre inside. None when the mask is empty.
pub fn contact_region(real_mask: &Mask) -> Option<Vec<bool>> {
    (real_mask.count() > 0).then(|| real_mask.dilated(metrics::SSIM_RADIUS).pixels)
}

/// Scores of a rendered frame against a real one (frame and FEM step left 0 for the caller):
/// L1, PSNR, SSIM (channel mean) and measured-mask IoU over the whole frame, and SSIM and L1
/// over the real contact region `region` (see [`contact_region`]).
pub fn score_frame(
    rendered: &RgbImage,
    real: &RgbImage,
    bg: &RgbImage,
    mask_opts: &MaskOptions,
    region: Option<&[bool]>,
) -> Result<RenderScore> {
    let (a, b) = (rendered.to_f64(), real.to_f64());
    let l1 = metrics::l1(&a, &b)?;
    let psnr_db = metrics::psnr(&a, &b, 255.0)?;
    let ssim = score_ssim(rendered, real)?;
    let mask_iou = metrics::iou(
        &measured_mask(rendered, bg, mask_opts)?,
        &measured_mask(real, bg, mask_opts)?,
    )?;
    let (contact_ssim, contact_l1) = match region {
        Some(reg) => {
            let (mut sum, mut n) = (0.0, 0usize);
            for (i, _) in reg.iter().enumerate().filter(|(_, in_)| **in_) {
                for ch in 0..3 {
                    sum += (a[i * 3 + ch] - b[i * 3 + ch]).abs();
                }
                n += 3;
            }
            (
                Some(score_ssim_in(rendered, real, reg)?),
                Some(sum / n.max(1) as f64),
            )
        }
        None => (None, None),
    };
    Ok(RenderScore {
        frame: 0,
        fem_step: 0,
        l1,
        psnr_db,
        ssim,
        mask_iou,
        contact_ssim,
        contact_l1,
    })
}

/// SSIM of two RGB images over the windows centred in `region`, the mean over channels.
pub fn score_ssim_in(a: &RgbImage, b: &RgbImage, region: &[bool]) -> Result<f64> {
    let mut ssim = 0.0;
    for ch in 0..3 {
        ssim += metrics::ssim_in(
            &a.channel(ch),
            &b.channel(ch),
            b.rows,
            b.cols,
            255.0,
            region,
        )? / 3.0;
    }
    Ok(ssim)
}

/// Height smoothings tried by [`compare`], Gaussian sigma in pixels.
pub const SMOOTHING_PX: [f32; 11] = [0.0, 1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0, 8.0, 10.0, 12.0];

/// SSIM of two RGB images, the mean over channels.
pub fn score_ssim(a: &RgbImage, b: &RgbImage) -> Result<f64> {
    let mut ssim = 0.0;
    for ch in 0..3 {
        ssim += metrics::ssim(&a.channel(ch), &b.channel(ch), b.rows, b.cols, 255.0)? / 3.0;
    }
    Ok(ssim)
}

/// Least-squares gain on the rendered intensity change: sum dS (R - B) / sum dS^2 over the
/// given (rendered at gain 1, real) pairs, with B the common background.
pub fn fit_gain(pairs: &[(RgbImage, &RgbImage)], bg: &RgbImage) -> f64 {
    let (mut num, mut den) = (0.0, 0.0);
    for (s, r) in pairs {
        for ((&sv, &rv), &bv) in s.data.iter().zip(&r.data).zip(&bg.data) {
            let ds = f64::from(sv) - f64::from(bv);
            num += ds * (f64::from(rv) - f64::from(bv));
            den += ds * ds;
        }
    }
    if den > 0.0 { num / den } else { 1.0 }
}

/// Least-squares colour transform and depth shading of the optics: per output channel i,
/// real_i - B_i ~ sum_j M[i][j] dS_j + g_i h over every pixel of the given (rendered with the
/// identity transform and no depth term, real, heights as the renderer smoothed them) triples,
/// with dS the rendered change. Returns (M, g in grey levels per m); without any sloped or
/// pressed pixel, the identity and no depth term.
pub fn fit_colour(
    pairs: &[(RgbImage, &RgbImage, Vec<f32>)],
    bg: &RgbImage,
) -> ([[f64; 3]; 3], [f64; 3]) {
    // Heights in units of 0.1 mm keep the normal equations balanced against grey levels.
    const H_UNIT_M: f64 = 1e-4;
    let mut ata = nalgebra::Matrix4::<f64>::zeros();
    let mut atb = [nalgebra::Vector4::<f64>::zeros(); 3];
    for (s, r, h) in pairs {
        for (p, &hp) in h.iter().enumerate() {
            let x = nalgebra::Vector4::new(
                f64::from(s.data[p * 3]) - f64::from(bg.data[p * 3]),
                f64::from(s.data[p * 3 + 1]) - f64::from(bg.data[p * 3 + 1]),
                f64::from(s.data[p * 3 + 2]) - f64::from(bg.data[p * 3 + 2]),
                f64::from(hp) / H_UNIT_M,
            );
            if x == nalgebra::Vector4::zeros() {
                continue;
            }
            ata += x * x.transpose();
            for ch in 0..3 {
                atb[ch] += x * (f64::from(r.data[p * 3 + ch]) - f64::from(bg.data[p * 3 + ch]));
            }
        }
    }
    let mut m = [[0.0; 3]; 3];
    let mut g = [0.0; 3];
    // A regressor that never varies (a channel the table leaves unchanged) gets coefficient 0
    // through a vanishing ridge instead of making the equations singular.
    let ridge = 1e-9 * ata.trace().max(1e-12);
    let chol = (ata + nalgebra::Matrix4::identity() * ridge).cholesky();
    for ch in 0..3 {
        match &chol {
            Some(c) => {
                let sol = c.solve(&atb[ch]);
                m[ch] = [sol[0], sol[1], sol[2]];
                g[ch] = sol[3] / H_UNIT_M;
            }
            None => m[ch][ch] = 1.0,
        }
    }
    (m, g)
}

/// Renders FEM step displacements `u` with the renderer through `sampler`.
pub fn render_step(
    renderer: &Renderer,
    sampler: &SurfaceSampler,
    u: &[[f64; 3]],
) -> Result<RgbImage> {
    let mut h = vec![0.0f32; sampler.rows * sampler.cols];
    sampler.heights(u, &mut h)?;
    renderer.render(&h, sampler.m_per_px as f32)
}

/// Images side by side with a 4-pixel white gap (all the same number of rows).
pub fn side_by_side(images: &[&RgbImage]) -> Result<RgbImage> {
    let Some(first) = images.first() else {
        return Err(TactileError::Input("nothing to put side by side".into()));
    };
    let rows = first.rows;
    if let Some(i) = images.iter().position(|m| m.rows != rows) {
        return Err(TactileError::Input(format!(
            "image {i} has {} rows, the first {rows}",
            images[i].rows
        )));
    }
    let gap = 4;
    let cols: usize = images.iter().map(|m| m.cols).sum::<usize>() + gap * (images.len() - 1);
    let mut data = vec![255u8; rows * cols * 3];
    let mut c0 = 0;
    for m in images {
        for r in 0..rows {
            let dst = (r * cols + c0) * 3;
            data[dst..dst + m.cols * 3]
                .copy_from_slice(&m.data[r * m.cols * 3..(r + 1) * m.cols * 3]);
        }
        c0 += m.cols + gap;
    }
    Ok(RgbImage { rows, cols, data })
}

/// |a - b| per channel, scaled by `gain` and clipped (a difference image that shows small errors).
pub fn difference_image(a: &RgbImage, b: &RgbImage, gain: f64) -> RgbImage {
    RgbImage {
        rows: a.rows,
        cols: a.cols,
        data: a
            .data
            .iter()
            .zip(&b.data)
            .map(|(&x, &y)| ((f64::from(x) - f64::from(y)).abs() * gain).min(255.0) as u8)
            .collect(),
    }
}

/// Reads FEM step displacements `u_001.npy` .. `u_{steps}.npy` (N x 3, m) written by
/// `ocm tactile indent`; `None` when any is missing or has the wrong node count.
pub fn read_cached_steps(dir: &Path, steps: usize, nodes: usize) -> Option<Vec<Vec<[f64; 3]>>> {
    (1..=steps)
        .map(|j| {
            let a = ocm_fem::npy::read_f64_2d(dir.join(format!("u_{j:03}.npy"))).ok()?;
            (a.rows == nodes && a.cols == 3)
                .then(|| a.data.chunks_exact(3).map(|c| [c[0], c[1], c[2]]).collect())
        })
        .collect()
}

/// The measured mask of each of `frames` against frame 0, the background (itself empty).
pub fn measured_masks(frames: &[RgbImage], mask: &MaskOptions) -> Result<Vec<Mask>> {
    let Some(bg) = frames.first() else {
        return Err(TactileError::Input("no real frames".into()));
    };
    frames.iter().map(|f| measured_mask(f, bg, mask)).collect()
}

/// The gel-grid FEM masks of each step under `rule`.
pub fn fem_masks(gel: &Gel, steps: &[Vec<[f64; 3]>], rule: MaskRule) -> Vec<Mask> {
    let grid = Grid::for_gel(gel);
    steps.iter().map(|u| rule.mask(gel, &grid, u)).collect()
}

/// Which optical parameters `compare` fits on the fitting frames (beside the smoothing).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub enum OpticsFit {
    /// One gain on the calibrated change (least squares).
    Gain,
    /// A 3 x 3 colour transform of the calibrated change and a depth shading per channel
    /// (least squares, [`fit_colour`]).
    ColourDepth,
}

/// Options of the whole comparison.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct CompareOptions {
    /// How real (and rendered) frames are turned into masks.
    pub mask: MaskOptions,
    /// How the real contact region that the contact SSIM and L1 are taken over is measured:
    /// the default threshold whatever `mask` is, so that a fitted mask threshold does not move
    /// the region those figures are compared on.
    pub region: MaskOptions,
    /// Step offsets tried on each side of the first-contact estimate.
    pub offset_window: usize,
    /// The optical parameters fitted.
    pub optics: OpticsFit,
    /// A map and offset fitted before (skips the map fit, the slow part).
    pub fixed_fit: Option<MaskFit>,
    /// The map's scale, pixels per metre of gel, when it is known rather than fitted.
    pub px_per_m: Option<f64>,
    /// FEM steps per real frame in the map fit ([`MaskFit::steps_per_frame`]).
    pub steps_per_frame: f64,
    /// How the FEM's masks are drawn (the depth of Ch.6.5.1 by default).
    pub fem_mask: MaskRule,
}

impl Default for CompareOptions {
    fn default() -> Self {
        CompareOptions {
            mask: MaskOptions::default(),
            region: MaskOptions::default(),
            offset_window: 6,
            optics: OpticsFit::ColourDepth,
            fixed_fit: None,
            px_per_m: None,
            steps_per_frame: 1.0,
            fem_mask: MaskRule::Depth,
        }
    }
}

/// Everything the comparison measured.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct Comparison {
    /// Frames used for fitting (even indices).
    pub fit_frames: Vec<usize>,
    /// Frames scored (odd indices).
    pub score_frames: Vec<usize>,
    /// The fitted map and step offset.
    pub fit: MaskFit,
    /// Offsets tried (inclusive range).
    pub offsets_tried: [usize; 2],
    /// Mask scores on the scored frames with contact in either mask.
    pub masks: Vec<MaskScore>,
    /// Gain on the rendered intensity change, fitted on the fitting frames.
    pub gain: f64,
    /// Height smoothing (Gaussian sigma, pixels) chosen on the fitting frames.
    pub smooth_px: f32,
    /// Colour transform of the calibrated change fitted on the fitting frames
    /// ([`crate::optics::Renderer::colour`]; identity under [`OpticsFit::Gain`]).
    pub colour: [[f64; 3]; 3],
    /// Depth shading, grey levels per m ([`crate::optics::Renderer::depth_gain`]).
    pub depth_gain: [f64; 3],
    /// Rendered-against-real scores with the scalar gain alone (the previous optics model),
    /// for comparison; empty under [`OpticsFit::Gain`].
    pub render_scalar_gain: Vec<RenderScore>,
    /// Mean contact-region SSIM (see [`RenderScore::contact_ssim`]) on the fitting frames with
    /// contact, at that smoothing and gain.
    pub fit_ssim: f64,
    /// Rendered-against-real scores with the fitted gain.
    pub render: Vec<RenderScore>,
    /// The same with the calibration as measured (gain 1, no smoothing).
    pub render_gain1: Vec<RenderScore>,
    /// The baseline of rendering nothing: the background frame against each real frame.
    pub background_only: Vec<RenderScore>,
}

/// Fitting-frame SSIM, smoothing, gain, colour transform and depth shading of one optics fit.
type FittedOptics = (f64, f32, f64, [[f64; 3]; 3], [f64; 3]);

const IDENTITY_F64: [[f64; 3]; 3] = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];

/// Sets the renderer's optical parameters.
pub fn set_optics(
    r: &mut Renderer,
    gain: f64,
    smooth_px: f32,
    colour: &[[f64; 3]; 3],
    depth_gain: &[f64; 3],
) {
    r.gain = gain as f32;
    r.smooth_px = smooth_px;
    r.colour = colour.map(|row| row.map(|v| v as f32));
    r.depth_gain = depth_gain.map(|v| v as f32);
}

/// The heights the renderer uses for real frame k (sampled, then smoothed by its
/// `smooth_px`); zeros before first touch.
fn smoothed_heights(
    renderer: &Renderer,
    sampler: &SurfaceSampler,
    fields: &[Vec<[f64; 3]>],
    step: usize,
) -> Result<Vec<f32>> {
    let mut h = vec![0.0f32; sampler.rows * sampler.cols];
    if let Some(u) = fem_field(fields, step) {
        sampler.heights(u, &mut h)?;
    }
    Ok(crate::optics::render::gaussian_blur(
        &h,
        sampler.rows,
        sampler.cols,
        renderer.smooth_px,
    ))
}

/// The displacement of FEM step `step` (`fields[step - 1]`; None at step 0, before the touch,
/// and past the last step).
fn fem_field(fields: &[Vec<[f64; 3]>], step: usize) -> Option<&Vec<[f64; 3]>> {
    fields.get(step.checked_sub(1)?)
}

/// Renders FEM step `step` (the background at step 0, before the touch), as paired with a
/// real frame by [`MaskFit::step_for`].
pub fn render_paired(
    renderer: &Renderer,
    sampler: &SurfaceSampler,
    fields: &[Vec<[f64; 3]>],
    step: usize,
) -> Result<RgbImage> {
    match fem_field(fields, step) {
        Some(u) => render_step(renderer, sampler, u),
        None => Ok(renderer.background()),
    }
}

/// Share of its largest mask's area from which a real fitting frame, or a FEM step, counts as
/// touched when the step offsets to try are centred ([`MaskPairs::offsets`]).
pub const FIRST_CONTACT_SHARE: f64 = 0.01;

/// The measured masks of the real frames beside the FEM's, the even frames to fit on and the
/// odd ones to score: the mask half of [`compare`], on its own so that several FEM runs (of
/// candidate indenter tilts, say) can be fitted against the same frames and the best kept.
pub struct MaskPairs {
    /// Measured mask of each real frame (frame 0, the background, is empty).
    pub real: Vec<Mask>,
    /// FEM mask of step j + 1 at index j.
    pub fem: Vec<Mask>,
    /// Frames fitted on (even, from 2).
    pub fit_frames: Vec<usize>,
    /// Frames scored (odd).
    pub score_frames: Vec<usize>,
    /// How the real masks were measured.
    pub mask: MaskOptions,
}

impl MaskPairs {
    /// Masks of `frames` (frame 0 the background) measured with `mask`, and of the FEM's
    /// `fields` (10 um apart) drawn by `rule`.
    pub fn new(
        gel: &Gel,
        fields: &[Vec<[f64; 3]>],
        frames: &[RgbImage],
        mask: &MaskOptions,
        rule: MaskRule,
    ) -> Result<MaskPairs> {
        Ok(MaskPairs::from_masks(
            measured_masks(frames, mask)?,
            fem_masks(gel, fields, rule),
            *mask,
        ))
    }

    /// Pairs of masks measured before: `real` (one per frame, frame 0 the background) by
    /// [`measured_masks`] with `mask`, `fem` by [`fem_masks`]; so that candidates sharing a
    /// threshold or a FEM mask rule measure each once.
    pub fn from_masks(real: Vec<Mask>, fem: Vec<Mask>, mask: MaskOptions) -> MaskPairs {
        let n = real.len();
        MaskPairs {
            real,
            fem,
            fit_frames: (1..n).filter(|k| k % 2 == 0).collect(),
            score_frames: (1..n).filter(|k| k % 2 == 1).collect(),
            mask,
        }
    }

    /// The step offsets worth trying: `window` on each side of the first real fitting frame
    /// with contact minus the frames the FEM's first step with contact takes at
    /// `steps_per_frame`. Either counts as in contact from [`FIRST_CONTACT_SHARE`] of its
    /// largest mask's area: at a low threshold a few pixels of noise in a real frame cross it
    /// long before the indenter touches.
    pub fn offsets(&self, window: usize, steps_per_frame: f64) -> Result<(usize, usize)> {
        let largest = self
            .fit_frames
            .iter()
            .map(|&k| self.real[k].count())
            .max()
            .unwrap_or(0);
        let k0 = self
            .fit_frames
            .iter()
            .copied()
            .find(|&k| {
                let c = self.real[k].count();
                c > 0 && c as f64 >= FIRST_CONTACT_SHARE * largest as f64
            })
            .ok_or_else(|| {
                TactileError::Input(format!(
                    "no real fitting frame shows contact at threshold {} grey levels",
                    self.mask.threshold
                ))
            })?;
        let fem_largest = self.fem.iter().map(Mask::count).max().unwrap_or(0);
        let j0 = self
            .fem
            .iter()
            .position(|m| {
                let c = m.count();
                c > 0 && c as f64 >= FIRST_CONTACT_SHARE * fem_largest as f64
            })
            .ok_or_else(|| {
                TactileError::Input("no FEM step reaches the FEM mask's threshold".into())
            })?
            + 1;
        let centre = k0.saturating_sub((j0 as f64 / steps_per_frame).round() as usize);
        Ok((centre.saturating_sub(window), centre + window))
    }

    /// The map and step offset fitted on the fitting frames ([`fit_map`]).
    pub fn fit(
        &self,
        offsets: std::ops::RangeInclusive<usize>,
        px_per_m: Option<f64>,
        steps_per_frame: f64,
    ) -> Result<MaskFit> {
        fit_map(
            &self.real,
            &self.fem,
            &self.fit_frames,
            offsets,
            px_per_m,
            steps_per_frame,
        )
    }

    /// `fit` scored on the scoring frames ([`score_map`]).
    pub fn score(&self, fit: &MaskFit) -> Result<Vec<MaskScore>> {
        score_map(&self.real, &self.fem, fit, &self.score_frames)
    }
}

/// The FEM (`fields[j]` = displacement of step j + 1, 10 um apart) against the real frames
/// (`frames[0]` the background, frame k at k steps from the start): masks, the map fitted on
/// the even frames and scored on the odd ones, then rendered frames with `renderer` (whose
/// background should be frame 0). `progress` is called with a stage name.
pub fn compare(
    gel: &Gel,
    fields: &[Vec<[f64; 3]>],
    frames: &[RgbImage],
    renderer: &mut Renderer,
    opts: &CompareOptions,
    progress: &mut dyn FnMut(&str),
) -> Result<Comparison> {
    let bg = &frames[0];
    progress("fitting the gel-to-image map");
    let pairs = MaskPairs::new(gel, fields, frames, &opts.mask, opts.fem_mask)?;
    let (lo, hi) = pairs.offsets(opts.offset_window, opts.steps_per_frame)?;
    let fit = match opts.fixed_fit {
        Some(f) => f,
        None => pairs.fit(lo..=hi, opts.px_per_m, opts.steps_per_frame)?,
    };
    let masks = pairs.score(&fit)?;
    progress("rendering");
    let sampler = SurfaceSampler::new(gel, bg.rows, bg.cols, &fit.map);
    // Smoothing and gain of the optics, fitted on the fitting frames: for each smoothing the
    // least-squares gain, then the smoothing with the best mean SSIM over the contact regions
    // (over the whole frame the unchanged background decides, and rendering faintly wins).
    let regions: Vec<Option<Vec<bool>>> = if opts.region == opts.mask {
        pairs.real.iter().map(contact_region).collect()
    } else {
        frames
            .iter()
            .map(|f| Ok(contact_region(&measured_mask(f, bg, &opts.region)?)))
            .collect::<Result<_>>()?
    };
    let MaskPairs {
        fit_frames,
        score_frames,
        ..
    } = pairs;
    let fit_optics = |renderer: &mut Renderer, model: OpticsFit| -> Result<FittedOptics> {
        let mut best: Option<FittedOptics> = None;
        for smooth in SMOOTHING_PX {
            renderer.smooth_px = smooth;
            renderer.gain = 1.0;
            renderer.colour = IDENTITY_COLOUR;
            renderer.depth_gain = [0.0; 3];
            let mut pairs = Vec::new();
            let mut triples = Vec::new();
            for &k in &fit_frames {
                let img = render_paired(renderer, &sampler, fields, fit.step_for(k))?;
                match model {
                    OpticsFit::Gain => pairs.push((img, &frames[k])),
                    OpticsFit::ColourDepth => {
                        let h = smoothed_heights(renderer, &sampler, fields, fit.step_for(k))?;
                        triples.push((img, &frames[k], h));
                    }
                }
            }
            let (gain, colour, depth) = match model {
                OpticsFit::Gain => (fit_gain(&pairs, bg), IDENTITY_F64, [0.0; 3]),
                OpticsFit::ColourDepth => {
                    let (m, g) = fit_colour(&triples, bg);
                    (1.0, m, g)
                }
            };
            drop((pairs, triples));
            set_optics(renderer, gain, smooth, &colour, &depth);
            let (mut ssim, mut n) = (0.0, 0usize);
            for &k in &fit_frames {
                let Some(reg) = &regions[k] else { continue };
                let img = render_paired(renderer, &sampler, fields, fit.step_for(k))?;
                ssim += score_ssim_in(&img, &frames[k], reg)?;
                n += 1;
            }
            let ssim = ssim / n.max(1) as f64;
            if best.is_none_or(|b| ssim > b.0) {
                best = Some((ssim, smooth, gain, colour, depth));
            }
        }
        Ok(best.unwrap_or((f64::NAN, 0.0, 1.0, IDENTITY_F64, [0.0; 3])))
    };
    let scalar = if opts.optics == OpticsFit::Gain {
        None
    } else {
        Some(fit_optics(renderer, OpticsFit::Gain)?)
    };
    let (fit_ssim, smooth_px, gain, colour, depth_gain) = fit_optics(renderer, opts.optics)?;
    let mut render = Vec::new();
    let mut render_gain1 = Vec::new();
    let mut render_scalar_gain = Vec::new();
    let mut background_only = Vec::new();
    for &k in &score_frames {
        if fit.step_for(k) > fields.len() {
            continue;
        }
        let region = regions[k].as_deref();
        background_only.push(RenderScore {
            frame: k,
            ..score_frame(bg, &frames[k], bg, &opts.mask, region)?
        });
        let mut models = vec![
            (gain, smooth_px, colour, depth_gain, &mut render),
            (1.0, 0.0, IDENTITY_F64, [0.0; 3], &mut render_gain1),
        ];
        if let Some((_, sm, g, _, _)) = scalar {
            models.push((g, sm, IDENTITY_F64, [0.0; 3], &mut render_scalar_gain));
        }
        for (g, sm, col, dep, sink) in models {
            set_optics(renderer, g, sm, &col, &dep);
            let img = render_paired(renderer, &sampler, fields, fit.step_for(k))?;
            sink.push(RenderScore {
                frame: k,
                fem_step: fit.step_for(k).min(fields.len()),
                ..score_frame(&img, &frames[k], bg, &opts.mask, region)?
            });
        }
    }
    set_optics(renderer, gain, smooth_px, &colour, &depth_gain);
    Ok(Comparison {
        fit_frames,
        score_frames,
        fit,
        offsets_tried: [lo, hi],
        masks,
        gain,
        smooth_px,
        colour,
        depth_gain,
        render_scalar_gain,
        fit_ssim,
        render,
        render_gain1,
        background_only,
    })
}

/// Writes, for real frame `k`, `compare_KK.png` (real | rendered | 4 x |difference|) and
/// `masks_KK.png` (the real frame in grey, red where the real mask is, green where the FEM's).
// The inputs are those `compare` took plus its result; a bundle struct would only rename them.
#[allow(clippy::too_many_arguments)]
pub fn write_figures(
    dir: &Path,
    gel: &Gel,
    fields: &[Vec<[f64; 3]>],
    frames: &[RgbImage],
    renderer: &Renderer,
    c: &Comparison,
    opts: &CompareOptions,
    k: usize,
) -> Result<Vec<String>> {
    let bg = &frames[0];
    let sampler = SurfaceSampler::new(gel, bg.rows, bg.cols, &c.fit.map);
    let img = render_paired(renderer, &sampler, fields, c.fit.step_for(k))?;
    let diff = difference_image(&img, &frames[k], 4.0);
    let p1 = dir.join(format!("compare_{k:02}.png"));
    side_by_side(&[&frames[k], &img, &diff])?.write_png(&p1)?;
    let real = measured_mask(&frames[k], bg, &opts.mask)?;
    let fm = match fem_field(fields, c.fit.step_for(k)) {
        Some(u) => {
            let grid = Grid::for_gel(gel);
            warp_mask(
                &opts.fem_mask.mask(gel, &grid, u),
                &c.fit.map,
                bg.rows,
                bg.cols,
            )
        }
        None => mask_from_fn(image_grid(bg.rows, bg.cols), |_, _| false),
    };
    let overlay = RgbImage {
        rows: bg.rows,
        cols: bg.cols,
        data: frames[k]
            .data
            .chunks_exact(3)
            .zip(real.pixels.iter().zip(&fm.pixels))
            .flat_map(|(px, (&r, &f))| {
                let g = ((u32::from(px[0]) + u32::from(px[1]) + u32::from(px[2])) / 6) as u8;
                [if r { 255 } else { g }, if f { 255 } else { g }, g]
            })
            .collect(),
    };
    let p2 = dir.join(format!("masks_{k:02}.png"));
    overlay.write_png(&p2)?;
    Ok(vec![p1.display().to_string(), p2.display().to_string()])
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The bounding-box IoU used by the fit equals the IoU of the fully warped mask.
    #[test]
    fn boxed_iou_equals_full_warp() {
        let g = Grid {
            origin_m: [0.0, 0.0],
            pixel_m: 0.1e-3,
            cols: 100,
            rows: 80,
        };
        let gel_mask = mask_from_fn(g, |r, c| (20..50).contains(&c) && (30..40).contains(&r));
        let real = mask_from_fn(image_grid(120, 160), |r, c| {
            (r as f64 - 60.0).hypot(c as f64 - 70.0) < 25.0
        });
        for (angle, mirror) in [(0.0, false), (0.4, true), (2.0, false)] {
            let map = CameraMap {
                px_per_m: 12_000.0,
                angle_rad: angle,
                mirror,
                offset_px: [40.0, if mirror { 90.0 } else { 20.0 }],
            };
            let full = metrics::iou(&real, &warp_mask(&gel_mask, &map, 120, 160)).unwrap();
            let fast = warped_iou(&Boxed::new(&real), &Boxed::new(&gel_mask), &map).unwrap();
            assert!((full - fast).abs() < 1e-12, "{full} {fast}");
        }
    }

    /// The blur keeps a constant field and the mean of a spike; sigma 0 is the identity.
    #[test]
    fn gaussian_blur_conserves() {
        use crate::optics::render::gaussian_blur;
        let c = vec![2.5f32; 30 * 40];
        assert!(
            gaussian_blur(&c, 30, 40, 2.0)
                .iter()
                .all(|v| (v - 2.5).abs() < 1e-5)
        );
        let mut s = vec![0.0f32; 30 * 40];
        s[15 * 40 + 20] = 1.0;
        let b = gaussian_blur(&s, 30, 40, 1.5);
        assert!((b.iter().sum::<f32>() - 1.0).abs() < 1e-5);
        assert!(b[15 * 40 + 20] < 0.1 && b[15 * 40 + 21] > 0.0);
        assert_eq!(gaussian_blur(&s, 30, 40, 0.0), s);
    }

    /// A map.json as compare-real writes it reads back and sets the renderer's optics; one
    /// without a colour transform is refused naming the file.
    #[test]
    fn optics_file_reads_and_applies() {
        let dir = std::env::temp_dir().join(format!("ocm-optics-file-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let good = dir.join("map.json");
        std::fs::write(
            &good,
            r#"{"colour": [[0.5, 0, 0], [0, 2, 0], [0, 0, 1]], "depth_gain_per_m": [-10, 0, 5],
                "fit_iou": 0.5, "gain": 1.0, "offset_steps": 16, "smooth_px": 7.0,
                "map": {"angle_rad": 1.0, "mirror": true, "offset_px": [3, 4], "px_per_m": 17000}}"#,
        )
        .unwrap();
        let f = OpticsFile::read(&good).unwrap();
        assert_eq!(f.offset_steps, 16);
        // A map written before the rate was fitted pairs one step per frame.
        assert_eq!(f.steps_per_frame, 1.0);
        assert_eq!((f.step_for(16), f.step_for(20)), (0, 4));
        assert!(f.map.mirror && f.map.px_per_m == 17000.0);
        let bg = RgbImage {
            rows: 4,
            cols: 4,
            data: vec![100; 48],
        };
        let table = vec![0.0; 3 * 3 * 6];
        let calib =
            crate::optics::PolyCalib::from_tables(3, [&table, &table, &table], "t").unwrap();
        let mut r = Renderer::new(calib, &bg).unwrap();
        f.apply(&mut r);
        assert_eq!(r.colour[1][1], 2.0);
        assert_eq!(r.depth_gain, [-10.0, 0.0, 5.0]);
        assert_eq!(r.smooth_px, 7.0);
        let bad = dir.join("bad.json");
        std::fs::write(&bad, r#"{"map": {"angle_rad": 1.0, "mirror": true, "offset_px": [3, 4], "px_per_m": 1}, "offset_steps": 1}"#).unwrap();
        let e = OpticsFile::read(&bad).unwrap_err().to_string();
        assert!(e.contains("bad.json") && e.contains("colour"), "{e}");
        std::fs::remove_dir_all(&dir).ok();
    }
}
