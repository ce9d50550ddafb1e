//! The perception network on real DIGIT frames: each camera frame is warped into the networks'
//! landscape frame through the camera map `compare-real` fitted, its change against the warped
//! background goes through the network, and the predicted contact is warped back into the
//! camera image and scored against the mask measured on the real frame.

use super::{NetData, NetKind, contact_mask, elongation, pairs};
use crate::mask::{CLOSING_KERNEL_PX, Grid, Mask, mask_from_fn};
use crate::optics::{CameraMap, RgbImage};
use crate::real::{self, MaskOptions, OpticsFile};
use crate::{Result, TactileError};
use ocm_learn::UNet;
use ocm_learn::burn::tensor::Device;
use serde::{Deserialize, Serialize};

/// `src` (seen through `src_map`) resampled bilinearly at the pixel centres of a rows x cols
/// image seen through `dst_map`; points outside `src` take its nearest border pixel.
pub fn warp_image(
    src: &RgbImage,
    src_map: &CameraMap,
    dst_map: &CameraMap,
    rows: usize,
    cols: usize,
) -> RgbImage {
    let mut data = vec![0u8; rows * cols * 3];
    let at = |r: usize, c: usize, ch: usize| f64::from(src.data[(r * src.cols + c) * 3 + ch]);
    for r in 0..rows {
        for c in 0..cols {
            let q = src_map.to_px(dst_map.to_gel([c as f64 + 0.5, r as f64 + 0.5]));
            let x = (q[0] - 0.5).clamp(0.0, (src.cols - 1) as f64);
            let y = (q[1] - 0.5).clamp(0.0, (src.rows - 1) as f64);
            let (c0, r0) = (x.floor() as usize, y.floor() as usize);
            let (c1, r1) = ((c0 + 1).min(src.cols - 1), (r0 + 1).min(src.rows - 1));
            let (fx, fy) = (x - c0 as f64, y - r0 as f64);
            for ch in 0..3 {
                let v = (1.0 - fy) * ((1.0 - fx) * at(r0, c0, ch) + fx * at(r0, c1, ch))
                    + fy * ((1.0 - fx) * at(r1, c0, ch) + fx * at(r1, c1, ch));
                data[(r * cols + c) * 3 + ch] = (v.clamp(0.0, 255.0) + 0.5) as u8;
            }
        }
    }
    RgbImage { rows, cols, data }
}

/// `mask` (on the image of `src_map`) seen through `dst_map` on a rows x cols image: each pixel
/// centre takes the source pixel it falls in (outside: no contact).
pub fn warp_mask_between(
    mask: &Mask,
    src_map: &CameraMap,
    dst_map: &CameraMap,
    rows: usize,
    cols: usize,
) -> Mask {
    let g = mask.grid;
    mask_from_fn(real::image_grid(rows, cols), |r, c| {
        let q = src_map.to_px(dst_map.to_gel([c as f64 + 0.5, r as f64 + 0.5]));
        let (x, y) = (q[0].floor(), q[1].floor());
        x >= 0.0
            && y >= 0.0
            && (x as usize) < g.cols
            && (y as usize) < g.rows
            && mask.pixels[y as usize * g.cols + x as usize]
    })
}

/// Applies the inverse of a colour transform to a channel-major `[3, n]` delta image: a change
/// in the real sensor's colours back into the calibrating sensor's (the ones the network was
/// trained on). An error when the transform is singular.
pub fn uncolour(delta: &mut [f32], colour: &[[f64; 3]; 3]) -> Result<()> {
    let m = colour;
    let det = m[0][0] * (m[1][1] * m[2][2] - m[1][2] * m[2][1])
        - m[0][1] * (m[1][0] * m[2][2] - m[1][2] * m[2][0])
        + m[0][2] * (m[1][0] * m[2][1] - m[1][1] * m[2][0]);
    if !(det.abs() > 1e-9) {
        return Err(TactileError::Input(format!(
            "colour transform {m:?} is singular (determinant {det:e})"
        )));
    }
    let mut inv = [[0.0f64; 3]; 3];
    for (i, row) in inv.iter_mut().enumerate() {
        for (j, v) in row.iter_mut().enumerate() {
            // inv[i][j] = cofactor[j][i] / det.
            let (a, b) = ((j + 1) % 3, (j + 2) % 3);
            let (c, d) = ((i + 1) % 3, (i + 2) % 3);
            *v = (m[a][c] * m[b][d] - m[a][d] * m[b][c]) / det;
        }
    }
    recolour(delta, &inv);
    Ok(())
}

/// Applies a 3 x 3 colour transform (rows: output R, G, B) to every pixel of a channel-major
/// `[3, n]` delta image.
pub fn recolour(delta: &mut [f32], m: &[[f64; 3]; 3]) {
    let n = delta.len() / 3;
    for p in 0..n {
        let d = [delta[p], delta[n + p], delta[2 * n + p]].map(f64::from);
        for (ch, row) in m.iter().enumerate() {
            delta[ch * n + p] = (row[0] * d[0] + row[1] * d[1] + row[2] * d[2]) as f32;
        }
    }
}

/// `frame` with each channel's median change against `bg` removed (the brightness drift
/// between takes), rounded and clipped to 0..255.
pub fn drift_removed(frame: &RgbImage, bg: &RgbImage) -> Result<RgbImage> {
    let d = pairs::delta_of(frame, bg)?;
    let n = frame.rows * frame.cols;
    let mut data = frame.data.clone();
    for ch in 0..3 {
        let mut v = d[ch * n..(ch + 1) * n].to_vec();
        v.sort_by(f32::total_cmp);
        let m = v[n / 2];
        for p in 0..n {
            let x = f32::from(frame.data[p * 3 + ch]) - m;
            data[p * 3 + ch] = (x.clamp(0.0, 255.0) + 0.5) as u8;
        }
    }
    Ok(RgbImage {
        rows: frame.rows,
        cols: frame.cols,
        data,
    })
}

/// The colour transform that brings the real sensor's change into the rendered (calibrated)
/// domain the network was trained in, fitted by least squares on the fitting frames `fit`:
/// the FEM state paired with each real frame (`fields`, [`OpticsFile::step_for`]) rendered by
/// `renderer` (the optics the network's pairs were rendered with) through the fitted camera map,
/// against the real frame, drift removed, over every pixel. It is the same fit as the optics'
/// ([`real::fit_colour`]) with the roles of real and rendered exchanged: it minimises the error
/// in the rendered domain, so a colour direction the real sensor barely shows is shrunk, not
/// amplified as by inverting the forward transform ([`uncolour`]).
pub fn fit_recolour(
    gel: &crate::gel::Gel,
    fields: &[Vec<[f64; 3]>],
    frames: &[RgbImage],
    fitted: &OpticsFile,
    renderer: &crate::optics::Renderer,
    fit: &[usize],
) -> Result<[[f64; 3]; 3]> {
    let bg = frames
        .first()
        .ok_or_else(|| TactileError::Input("no real frames".into()))?;
    let sampler = crate::optics::SurfaceSampler::new(gel, bg.rows, bg.cols, &fitted.map);
    let rendered = fit
        .iter()
        .map(|&k| real::render_paired(renderer, &sampler, fields, fitted.step_for(k)))
        .collect::<Result<Vec<_>>>()?;
    let real_frames = fit
        .iter()
        .map(|&k| {
            frames.get(k).ok_or_else(|| {
                TactileError::Input(format!("fitting frame {k} of {} frames", frames.len()))
            })
        })
        .collect::<Result<Vec<_>>>()?;
    fit_recolour_images(&real_frames, &rendered, bg)
}

/// The least-squares transform of [`fit_recolour`] from paired real and rendered frames on the
/// common background `bg` (the real frames' drift removed first).
pub fn fit_recolour_images(
    real_frames: &[&RgbImage],
    rendered: &[RgbImage],
    bg: &RgbImage,
) -> Result<[[f64; 3]; 3]> {
    if real_frames.len() != rendered.len() {
        return Err(TactileError::Input(format!(
            "{} real frames against {} rendered",
            real_frames.len(),
            rendered.len()
        )));
    }
    let mut triples = Vec::with_capacity(rendered.len());
    for (f, r) in real_frames.iter().zip(rendered) {
        triples.push((drift_removed(f, bg)?, r, vec![0.0f32; bg.rows * bg.cols]));
    }
    Ok(real::fit_colour(&triples, bg).0)
}

/// The perception network on one real frame, against the mask measured on it.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct RealFrameScore {
    /// Real frame index.
    pub frame: usize,
    /// IoU of the predicted and measured masks in the camera image.
    pub iou: f64,
    /// Centroid distance on the gel, mm (NaN when a mask is empty).
    pub centroid_mm: f64,
    /// Predicted minus measured centroid along the camera image's columns and rows, mm on the
    /// gel (NaN when a mask is empty): a constant offset over the frames is a registration
    /// error, a varying one a shape error.
    #[serde(default)]
    pub centroid_offset_mm: [f64; 2],
    /// Shift (columns, rows) applied to the predicted mask in the camera image, pixels
    /// ([`RealOptions::shift_fit`]; zero without).
    #[serde(default)]
    pub applied_shift_px: [i64; 2],
    /// Angle between the principal axes, rad (NaN when a mask is empty).
    pub rotation_rad: f64,
    /// Elongation of the measured mask ([`super::elongation`]).
    pub real_elongation: f64,
    /// Measured contact area, mm^2 on the gel.
    pub real_area_mm2: f64,
    /// Predicted contact area, mm^2 on the gel.
    pub predicted_area_mm2: f64,
    /// Deepest predicted indentation, mm.
    pub predicted_depth_mm: f64,
    /// Indentation of the FEM step paired with the frame by the fitted offset, mm (10 um
    /// steps; 0 before first touch).
    pub paired_fem_depth_mm: f64,
}

/// Options of [`perceive_real`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RealOptions {
    /// Map the real change back into the calibrated colours ([`uncolour`]) before the network
    /// (for a network trained on frames rendered with the calibration as measured).
    pub uncolour: bool,
    /// Map the real change into the rendered domain with this transform ([`fit_recolour`])
    /// before the network (after the drift removal).
    pub recolour: Option<[[f64; 3]; 3]>,
    /// Subtract from each channel of the real change its median over the pixels the camera
    /// sees (the frames drift by a few grey levels in brightness between takes; the rendered
    /// training frames never do, and the fitted depth shading reads a uniform darkening as a
    /// uniform indentation).
    pub remove_drift: bool,
    /// How the real masks are measured.
    pub mask: MaskOptions,
    /// Indentation per real frame, m.
    pub step_m: f64,
    /// Shift every predicted mask in the camera image by the mean predicted-minus-measured
    /// centroid offset over the even frames (a registration of the network's path fitted on
    /// half the depths; the odd frames are the score).
    pub shift_fit: bool,
    /// Arithmetic of the network's convolutions.
    pub precision: super::infer::Precision,
}

impl Default for RealOptions {
    fn default() -> Self {
        RealOptions {
            uncolour: false,
            recolour: None,
            remove_drift: true,
            mask: MaskOptions::default(),
            step_m: 10e-6,
            shift_fit: false,
            precision: super::infer::Precision::F32,
        }
    }
}

/// Runs the perception network (`net` on `size` = (rows, cols) images of the landscape frame
/// `land`, `land` at full 240 x 320 scale) on `frames` (camera frames, frame 0 the background)
/// and scores every frame from 1 on where the measured or the predicted mask has contact.
/// The predicted mask is the 30 um threshold, warped into the camera image, closed with the
/// FEM masks' kernel and hole-filled (as the FEM masks of `compare-real`). Also returns the
/// predicted u_z of every frame (m, `[rows, cols]` each).
pub fn perceive_real(
    net: &UNet,
    size: (usize, usize),
    land: &CameraMap,
    frames: &[RgbImage],
    fitted: &OpticsFile,
    opts: &RealOptions,
    device: &Device,
) -> Result<(Vec<RealFrameScore>, Vec<f32>)> {
    let (rows, cols) = size;
    if frames.len() < 2 {
        return Err(TactileError::Input(format!(
            "{} real frames: need a background and at least one contact frame",
            frames.len()
        )));
    }
    let (r0, c0) = (real::ROWS, real::COLS);
    if !(r0.is_multiple_of(rows) && c0.is_multiple_of(cols) && r0 / rows == c0 / cols) {
        return Err(TactileError::Input(format!(
            "network of {cols} x {rows} does not divide the {c0} x {r0} frame"
        )));
    }
    let scale = r0 / rows;
    let warp =
        |img: &RgbImage| pairs::downscale(&warp_image(img, &fitted.map, land, r0, c0), scale);
    let bg = warp(&frames[0]);
    let n = rows * cols;
    // Pixels of the network's image whose centre the real camera sees.
    let seen: Vec<usize> = (0..n)
        .filter(|&p| {
            let q = [
                ((p % cols) as f64 + 0.5) * scale as f64,
                ((p / cols) as f64 + 0.5) * scale as f64,
            ];
            let t = fitted.map.to_px(land.to_gel(q));
            t[0] >= 0.0 && t[1] >= 0.0 && t[0] < c0 as f64 && t[1] < r0 as f64
        })
        .collect();
    let mut delta = Vec::with_capacity((frames.len() - 1) * 3 * n);
    for f in &frames[1..] {
        let mut d = pairs::delta_of(&warp(f), &bg)?;
        if opts.remove_drift && !seen.is_empty() {
            for ch in 0..3 {
                let mut v: Vec<f32> = seen.iter().map(|&p| d[ch * n + p]).collect();
                v.sort_by(f32::total_cmp);
                let m = v[v.len() / 2];
                for x in &mut d[ch * n..(ch + 1) * n] {
                    *x -= m;
                }
            }
        }
        if opts.uncolour {
            uncolour(&mut d, &fitted.colour)?;
        }
        if let Some(m) = &opts.recolour {
            recolour(&mut d, m);
        }
        delta.extend(d);
    }
    let k = frames.len() - 1;
    let small_map = CameraMap {
        px_per_m: land.px_per_m / scale as f64,
        offset_px: land.offset_px.map(|v| v / scale as f64),
        ..*land
    };
    let grid = Grid {
        origin_m: [0.0, 0.0],
        pixel_m: small_map.m_per_px(),
        rows,
        cols,
    };
    let batch = pairs::Pairs {
        rows,
        cols,
        pixel_m: grid.pixel_m,
        setup_names: vec!["real".into()],
        setup_unseen: vec![true],
        setup: vec![0; k],
        depth_m: vec![0.0; k],
        mirror: vec![0; k],
        state: (0..k).collect(),
        delta,
        dz_m: vec![0.0; k * n],
        splat_dz_m: Vec::new(),
        background: bg,
    };
    let data = NetData::new(NetKind::Perception, &batch);
    let idx: Vec<usize> = (0..k).collect();
    let pred = data.predict_in(net, &idx, 8, device, opts.precision);
    let px_per_m = fitted.map.px_per_m;
    let area = |m: &Mask| m.count() as f64 / (px_per_m * px_per_m) * 1e6;
    let mut masks = Vec::new();
    for (j, f) in frames[1..].iter().enumerate() {
        let small = contact_mask(grid, &pred[j * n..(j + 1) * n]);
        let predicted = warp_mask_between(&small, &small_map, &fitted.map, r0, c0)
            .closed(CLOSING_KERNEL_PX)
            .filled();
        let measured = real::measured_mask(f, &frames[0], &opts.mask)?;
        if measured.count() == 0 && predicted.count() == 0 {
            continue;
        }
        masks.push((j + 1, predicted, measured));
    }
    let shift = if opts.shift_fit {
        fit_shift(&masks)?
    } else {
        [0, 0]
    };
    let mut out = Vec::new();
    for (frame, predicted, measured) in masks {
        let j = frame - 1;
        let dz = &pred[j * n..(j + 1) * n];
        let predicted = shift_mask(&predicted, shift);
        let (iou, cen, rot) = real::score_masks(&measured, &predicted, px_per_m)?;
        let empty = measured.count() == 0 || predicted.count() == 0;
        let (sm, sp) = (measured.stats(), predicted.stats());
        let offset = |k: usize| {
            if empty {
                f64::NAN
            } else {
                (sp.centroid_m[k] - sm.centroid_m[k]) / px_per_m * 1e3
            }
        };
        out.push(RealFrameScore {
            frame,
            iou,
            centroid_mm: if empty { f64::NAN } else { cen },
            centroid_offset_mm: [offset(0), offset(1)],
            applied_shift_px: shift,
            rotation_rad: if empty { f64::NAN } else { rot },
            real_elongation: elongation(&measured),
            real_area_mm2: area(&measured),
            predicted_area_mm2: area(&predicted),
            predicted_depth_mm: -f64::from(dz.iter().copied().fold(0.0f32, f32::min)) * 1e3,
            paired_fem_depth_mm: fitted.step_for(frame) as f64 * opts.step_m * 1e3,
        });
    }
    Ok((out, pred))
}

/// The whole-pixel shift (columns, rows) that moves the predicted masks onto the measured ones
/// on average over the even frames of `masks` (frame, predicted, measured) where both have
/// contact: minus the mean centroid offset, rounded.
pub fn fit_shift(masks: &[(usize, Mask, Mask)]) -> Result<[i64; 2]> {
    let (mut sum, mut count) = ([0.0f64; 2], 0usize);
    for (frame, p, m) in masks {
        if frame % 2 == 0 && p.count() > 0 && m.count() > 0 {
            let (sp, sm) = (p.stats(), m.stats());
            for k in 0..2 {
                sum[k] += (sp.centroid_m[k] - sm.centroid_m[k]) / p.grid.pixel_m;
            }
            count += 1;
        }
    }
    if count == 0 {
        return Err(TactileError::Input(
            "no even frame with contact in both masks to fit the shift on".into(),
        ));
    }
    Ok(sum.map(|v| -(v / count as f64).round() as i64))
}

/// `mask` moved by `shift` (columns, rows) whole pixels; what leaves the grid is dropped.
pub fn shift_mask(mask: &Mask, shift: [i64; 2]) -> Mask {
    let g = mask.grid;
    mask_from_fn(g, |r, c| {
        let (sr, sc) = (r as i64 - shift[1], c as i64 - shift[0]);
        sr >= 0
            && sc >= 0
            && (sr as usize) < g.rows
            && (sc as usize) < g.cols
            && mask.pixels[sr as usize * g.cols + sc as usize]
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The fitted shift is minus the even frames' mean centroid offset and moves those masks
    /// onto the measured ones exactly.
    #[test]
    fn shift_fit_registers_offset_masks_on_even_frames() {
        let g = real::image_grid(40, 50);
        let disc = |r0: f64, c0: f64, rad: f64| {
            mask_from_fn(g, move |r, c| {
                (r as f64 - r0).powi(2) + (c as f64 - c0).powi(2) < rad * rad
            })
        };
        // Predicted discs 5 columns right and 3 rows up of the measured ones on the even
        // frames; an odd frame far off must not enter the fit.
        let masks = vec![
            (2, disc(20.0, 25.0, 6.0), disc(23.0, 20.0, 6.0)),
            (4, disc(18.0, 27.0, 8.0), disc(21.0, 22.0, 8.0)),
            (5, disc(5.0, 5.0, 3.0), disc(35.0, 45.0, 3.0)),
        ];
        let s = fit_shift(&masks).unwrap();
        assert_eq!(s, [-5, 3]);
        for (_, p, m) in &masks[..2] {
            let moved = shift_mask(p, s);
            assert_eq!(moved.pixels, m.pixels);
        }
        // Moved off the grid: nothing left; no even frame with both masks: an error.
        assert_eq!(shift_mask(&masks[0].1, [100, 0]).count(), 0);
        assert!(fit_shift(&masks[2..]).is_err());
    }

    /// Warping an image into another map and back reproduces it where both cover the gel, and
    /// a mask warped through the identity is unchanged.
    #[test]
    fn warps_invert_and_identity_keeps_masks() {
        let (rows, cols) = (30, 40);
        let data: Vec<u8> = (0..rows * cols * 3)
            .map(|i| {
                let p = i / 3;
                ((p / cols) * 3 + (p % cols) * 2 + (i % 3) * 20) as u8
            })
            .collect();
        let img = RgbImage { rows, cols, data };
        let a = CameraMap {
            px_per_m: 1000.0,
            angle_rad: 0.0,
            mirror: false,
            offset_px: [0.0, 0.0],
        };
        let b = CameraMap {
            px_per_m: 1000.0,
            angle_rad: std::f64::consts::PI,
            mirror: true,
            offset_px: [40.0, 0.0],
        };
        // b is a itself reflected across the image's vertical centre line: exactly a column
        // mirror of the pixel grid, so the bilinear warp is exact.
        let w = warp_image(&img, &a, &b, rows, cols);
        for r in 0..rows {
            for c in 0..cols {
                for ch in 0..3 {
                    assert_eq!(
                        w.data[(r * cols + c) * 3 + ch],
                        img.data[(r * cols + cols - 1 - c) * 3 + ch]
                    );
                }
            }
        }
        assert_eq!(warp_image(&w, &b, &a, rows, cols), img);
        let m = mask_from_fn(real::image_grid(rows, cols), |r, c| r > 5 && c < 12);
        assert_eq!(warp_mask_between(&m, &a, &a, rows, cols), m);
        let mm = warp_mask_between(&m, &a, &b, rows, cols);
        assert_eq!(mm.count(), m.count());
        assert!(mm.pixels[10 * cols + cols - 1] && !mm.pixels[10 * cols]);
    }

    /// The inverse colour transform undoes the transform; a singular one is refused.
    #[test]
    fn uncolour_inverts_the_colour_transform() {
        let m = [
            [0.03, -0.13, 0.33],
            [0.21, 0.69, 0.12],
            [-0.02, -0.74, -0.14],
        ];
        let calibrated = [[3.0f32, -1.0], [2.0, 5.0], [-4.0, 0.5]];
        let mut d = vec![0.0f32; 6];
        for p in 0..2 {
            for ch in 0..3 {
                d[ch * 2 + p] = (0..3)
                    .map(|j| m[ch][j] as f32 * calibrated[j][p])
                    .sum::<f32>();
            }
        }
        uncolour(&mut d, &m).unwrap();
        for p in 0..2 {
            for ch in 0..3 {
                assert!((d[ch * 2 + p] - calibrated[ch][p]).abs() < 1e-4, "{d:?}");
            }
        }
        let singular = [[1.0, 2.0, 3.0], [2.0, 4.0, 6.0], [0.0, 1.0, 1.0]];
        assert!(uncolour(&mut d, &singular).is_err());
    }

    /// Real frames made from rendered ones by a known colour transform plus a brightness
    /// drift: the fit recovers the transform's inverse (the drift removed), and applying it
    /// brings the real change back to the rendered one.
    #[test]
    fn recolour_fit_recovers_the_inverse_transform() {
        let (rows, cols) = (20, 30);
        let bg = RgbImage {
            rows,
            cols,
            data: (0..rows * cols * 3).map(|i| 100 + (i % 7) as u8).collect(),
        };
        let c = [[0.5, -0.1, 0.2], [0.1, 0.7, 0.0], [-0.2, 0.1, 0.6]];
        let mut rendered = Vec::new();
        let mut real_frames = Vec::new();
        for f in 0..3usize {
            let mut r = bg.clone();
            let mut q = bg.clone();
            for p in 0..rows * cols {
                // A patch of changes over a third of the frame (the rest stays background,
                // so the median change, the drift, is exactly the added offset).
                if (p + 5 * f) % 3 != 0 {
                    continue;
                }
                let d = [
                    ((p * 7 + f * 3) % 41) as f64 - 20.0,
                    ((p * 11 + f) % 37) as f64 - 18.0,
                    ((p * 5 + 2 * f) % 29) as f64 - 14.0,
                ];
                for ch in 0..3 {
                    r.data[p * 3 + ch] = (f64::from(bg.data[p * 3 + ch]) + d[ch]) as u8;
                    let out: f64 = (0..3).map(|j| c[ch][j] * d[j]).sum();
                    q.data[p * 3 + ch] = (f64::from(bg.data[p * 3 + ch]) + out).round() as u8;
                }
            }
            for (ch, v) in q.data.iter_mut().enumerate() {
                *v += [3u8, 1, 2][ch % 3];
            }
            rendered.push(r);
            real_frames.push(q);
        }
        let refs: Vec<&RgbImage> = real_frames.iter().collect();
        let m = fit_recolour_images(&refs, &rendered, &bg).unwrap();
        let mut d = vec![0.0f32; 3];
        for j in 0..3 {
            // m C = I up to the rounding of the real frames.
            for i in 0..3 {
                let e: f64 = (0..3).map(|k| m[i][k] * c[k][j]).sum();
                let want = if i == j { 1.0 } else { 0.0 };
                assert!((e - want).abs() < 0.03, "m = {m:?}: (m C)[{i}][{j}] = {e}");
            }
            d[j] = 10.0;
        }
        assert!(fit_recolour_images(&refs[..1], &rendered, &bg).is_err());
        recolour(
            &mut d,
            &[[0.0, 1.0, 0.0], [2.0, 0.0, 0.0], [0.0, 0.0, -1.0]],
        );
        assert_eq!(d, vec![10.0, 20.0, -10.0]);
    }
}
