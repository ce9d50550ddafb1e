//! From a height field on the image grid to an RGB DIGIT frame: surface slopes by central
//! differences, the gradient bin of every pixel, the calibrated intensity change of that bin at
//! that image position, added to the background (the difference model the table was fitted as).

use super::calib::{CALIB_FRAME_COLS, CALIB_FRAME_ROWS, PolyCalib, basis};
use crate::{Result, TactileError};
use rayon::prelude::*;
use std::path::Path;

/// An 8-bit RGB image, row-major, channels interleaved.
#[derive(Debug, Clone, PartialEq)]
pub struct RgbImage {
    /// Rows.
    pub rows: usize,
    /// Columns.
    pub cols: usize,
    /// rows x cols x 3 bytes.
    pub data: Vec<u8>,
}

fn image_err(path: &Path, msg: impl Into<String>) -> TactileError {
    TactileError::Image {
        path: path.display().to_string(),
        msg: msg.into(),
    }
}

impl RgbImage {
    /// Reads a PNG or JPEG that must hold exactly three channels (RGB).
    pub fn read(path: impl AsRef<Path>) -> Result<Self> {
        let path = path.as_ref();
        let img = image::open(path).map_err(|e| image_err(path, e.to_string()))?;
        let ch = img.color().channel_count();
        if ch != 3 {
            return Err(image_err(
                path,
                format!(
                    "has {ch} channel(s) ({:?}); a DIGIT frame is RGB with 3",
                    img.color()
                ),
            ));
        }
        let rgb = img.to_rgb8();
        Ok(RgbImage {
            rows: rgb.height() as usize,
            cols: rgb.width() as usize,
            data: rgb.into_raw(),
        })
    }

    /// Reads an RGB image of `rows` x `cols`, or of twice that (the DIGIT's 640 x 480 stream),
    /// which is averaged over 2 x 2 blocks; any other size is an error naming both.
    pub fn read_sized(path: impl AsRef<Path>, rows: usize, cols: usize) -> Result<Self> {
        let path = path.as_ref();
        let img = Self::read(path)?;
        if (img.rows, img.cols) == (rows, cols) {
            Ok(img)
        } else if (img.rows, img.cols) == (2 * rows, 2 * cols) {
            Ok(img.half())
        } else {
            Err(image_err(
                path,
                format!(
                    "is {} x {} (cols x rows); expected {cols} x {rows} or {} x {}",
                    img.cols,
                    img.rows,
                    2 * cols,
                    2 * rows
                ),
            ))
        }
    }

    /// Half resolution by 2 x 2 block means (rounded).
    pub fn half(&self) -> Self {
        let (rows, cols) = (self.rows / 2, self.cols / 2);
        let mut data = vec![0u8; rows * cols * 3];
        for r in 0..rows {
            for c in 0..cols {
                for ch in 0..3 {
                    let at =
                        |rr: usize, cc: usize| u32::from(self.data[(rr * self.cols + cc) * 3 + ch]);
                    let s = at(2 * r, 2 * c)
                        + at(2 * r, 2 * c + 1)
                        + at(2 * r + 1, 2 * c)
                        + at(2 * r + 1, 2 * c + 1);
                    data[(r * cols + c) * 3 + ch] = ((s + 2) / 4) as u8;
                }
            }
        }
        RgbImage { rows, cols, data }
    }

    /// One channel as f64 (for the metrics).
    pub fn channel(&self, ch: usize) -> Vec<f64> {
        self.data
            .iter()
            .skip(ch)
            .step_by(3)
            .map(|&v| f64::from(v))
            .collect()
    }

    /// All values as f64, interleaved.
    pub fn to_f64(&self) -> Vec<f64> {
        self.data.iter().map(|&v| f64::from(v)).collect()
    }

    /// Writes a PNG.
    pub fn write_png(&self, path: impl AsRef<Path>) -> Result<()> {
        let path = path.as_ref();
        let img = image::RgbImage::from_raw(self.cols as u32, self.rows as u32, self.data.clone())
            .ok_or_else(|| image_err(path, "pixel buffer does not match its size"))?;
        img.save(path).map_err(|e| image_err(path, e.to_string()))
    }
}

/// Surface slope (dh/drow, dh/dcol) at pixel (r, c) of a rows x cols height field with pixel
/// size `m_per_px`: central differences inside, one-sided at the border.
#[inline]
fn slope_at(h: &[f32], rows: usize, cols: usize, r: usize, c: usize, m_per_px: f32) -> (f32, f32) {
    let inv = 1.0 / m_per_px;
    let (c0, c1) = (c.saturating_sub(1), (c + 1).min(cols - 1));
    let (r0, r1) = (r.saturating_sub(1), (r + 1).min(rows - 1));
    let sc = (h[r * cols + c1] - h[r * cols + c0]) * (inv / (c1 - c0) as f32);
    let sr = (h[r1 * cols + c] - h[r0 * cols + c]) * (inv / (r1 - r0) as f32);
    (sr, sc)
}

/// The slopes the renderer uses, (dh/drow, dh/dcol) per pixel (see `slope_at`).
pub fn slopes(h: &[f32], rows: usize, cols: usize, m_per_px: f32) -> Result<Vec<(f32, f32)>> {
    check_field(h.len(), rows, cols)?;
    let mut out = Vec::with_capacity(rows * cols);
    for r in 0..rows {
        for c in 0..cols {
            out.push(slope_at(h, rows, cols, r, c, m_per_px));
        }
    }
    Ok(out)
}

fn check_field(n: usize, rows: usize, cols: usize) -> Result<()> {
    if rows < 2 || cols < 2 || n != rows * cols {
        return Err(TactileError::Input(format!(
            "height field of {n} values for a {rows} x {cols} image (need at least 2 x 2)"
        )));
    }
    Ok(())
}

/// A DIGIT frame renderer for one image size, calibration table and background.
#[derive(Debug, Clone)]
pub struct Renderer {
    calib: PolyCalib,
    /// Rows of the rendered image.
    pub rows: usize,
    /// Columns of the rendered image.
    pub cols: usize,
    /// Background, interleaved RGB.
    background: Vec<u8>,
    /// The flat bin's polynomial per pixel and channel (what a flat gel adds).
    flat: Vec<[f32; 3]>,
    /// Polynomial basis of every pixel at its calibration-frame position.
    basis: Vec<[f32; 6]>,
    /// Multiplies the intensity change (1 as calibrated; fitted when the sensor differs).
    pub gain: f32,
    /// Standard deviation of a Gaussian applied to the heights before the slopes, pixels (0:
    /// none); stands in for the gel's coating and the camera's defocus, fitted on real frames.
    pub smooth_px: f32,
    /// Colour transform of the calibrated change: output channel `i` gets
    /// sum_j colour[i][j] dS_j (identity as calibrated; fitted when the sensor's LEDs and
    /// camera differ from the calibrating one's).
    pub colour: [[f32; 3]; 3],
    /// Change per metre of (smoothed) height towards the camera, grey levels per m, per
    /// channel (0 as calibrated): the shading the slope table does not carry (the pressed gel
    /// darkens where it is deepest), fitted on real frames.
    pub depth_gain: [f32; 3],
}

/// The identity colour transform.
pub const IDENTITY_COLOUR: [[f32; 3]; 3] = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];

/// Box radius of each of the three passes of [`gaussian_blur`] for standard deviation `sigma`
/// (Wells 1986: three boxes of width w with 3 (w^2 - 1) / 12 = sigma^2).
pub fn box_radius(sigma: f32) -> usize {
    (((4.0 * sigma * sigma + 1.0).sqrt() - 1.0) / 2.0)
        .round()
        .max(1.0) as usize
}

/// Approximately Gaussian blur of a rows x cols field: three box passes along rows and three
/// along columns (running sums, so the cost does not grow with `sigma`), border values
/// repeated. The standard deviation is sqrt((2r+1)^2 - 1) / 2 for r = [`box_radius`], within
/// one pixel of `sigma`; `sigma` <= 0 leaves the field as it is.
pub fn gaussian_blur(h: &[f32], rows: usize, cols: usize, sigma: f32) -> Vec<f32> {
    let mut out = vec![0.0f32; h.len()];
    let mut tmp = vec![0.0f32; h.len()];
    gaussian_blur_into(h, rows, cols, sigma, &mut tmp, &mut out);
    out
}

/// [`gaussian_blur`] into `out` with `tmp` as scratch (both rows x cols), allocating nothing.
pub fn gaussian_blur_into(
    h: &[f32],
    rows: usize,
    cols: usize,
    sigma: f32,
    tmp: &mut [f32],
    out: &mut [f32],
) {
    if !(sigma > 0.0) {
        out.copy_from_slice(h);
        return;
    }
    let r = box_radius(sigma);
    box_rows(h, out, cols, r);
    box_rows(out, tmp, cols, r);
    box_rows(tmp, out, cols, r);
    box_cols(out, tmp, rows, cols, r);
    box_cols(tmp, out, rows, cols, r);
    box_cols(out, tmp, rows, cols, r);
    out.copy_from_slice(tmp);
}

/// One box pass of radius `r` along every row of `src` into `dst` (running sum, border
/// repeated).
fn box_rows(src: &[f32], dst: &mut [f32], cols: usize, r: usize) {
    let w = 1.0 / (2 * r + 1) as f32;
    let last = cols as isize - 1;
    dst.par_chunks_mut(cols)
        .zip(src.par_chunks(cols))
        .with_min_len(16)
        .for_each(|(d, s)| {
            let at = |k: isize| s[k.clamp(0, last) as usize];
            let mut acc: f32 = (-(r as isize)..=r as isize).map(at).sum();
            for (c, v) in d.iter_mut().enumerate() {
                *v = acc * w;
                let c = c as isize;
                acc += at(c + r as isize + 1) - at(c - r as isize);
            }
        });
}

/// One box pass of radius `r` along every column of `src` into `dst`: whole rows at a time,
/// the running sum kept per column, bands of rows in parallel.
fn box_cols(src: &[f32], dst: &mut [f32], rows: usize, cols: usize, r: usize) {
    const BAND: usize = 30;
    let w = 1.0 / (2 * r + 1) as f32;
    let last = rows as isize - 1;
    let row = |k: isize| &src[k.clamp(0, last) as usize * cols..][..cols];
    dst.par_chunks_mut(BAND * cols)
        .enumerate()
        .for_each(|(band, d)| {
            let r0 = (band * BAND) as isize;
            let mut acc = vec![0.0f32; cols];
            for k in r0 - r as isize..=r0 + r as isize {
                for (a, v) in acc.iter_mut().zip(row(k)) {
                    *a += v;
                }
            }
            for (i, line) in d.chunks_mut(cols).enumerate() {
                let rr = r0 + i as isize;
                let (add, sub) = (row(rr + r as isize + 1), row(rr - r as isize));
                for (((o, a), p), m) in line.iter_mut().zip(acc.iter_mut()).zip(add).zip(sub) {
                    *o = *a * w;
                    *a += p - m;
                }
            }
        });
}

/// Scratch buffers of a renderer (the smoothed heights), reused from frame to frame.
#[derive(Debug, Clone, Default)]
pub struct RenderScratch {
    smooth: Vec<f32>,
    tmp: Vec<f32>,
}

impl Renderer {
    /// A renderer producing images of the background's size. Image positions map linearly onto
    /// the calibration's 640 x 480 frame (pixel centres to pixel centres).
    pub fn new(calib: PolyCalib, background: &RgbImage) -> Result<Self> {
        let (rows, cols) = (background.rows, background.cols);
        if rows < 2 || cols < 2 || background.data.len() != rows * cols * 3 {
            return Err(TactileError::Input(format!(
                "background of {} bytes is not a {cols} x {rows} RGB image",
                background.data.len()
            )));
        }
        let sx = CALIB_FRAME_COLS as f32 / cols as f32;
        let sy = CALIB_FRAME_ROWS as f32 / rows as f32;
        let mut bas = Vec::with_capacity(rows * cols);
        let mut flat = Vec::with_capacity(rows * cols);
        let flat_bin = calib.flat_bin();
        for r in 0..rows {
            for c in 0..cols {
                let b = basis((c as f32 + 0.5) * sx - 0.5, (r as f32 + 0.5) * sy - 0.5);
                flat.push(std::array::from_fn(|ch| calib.eval(flat_bin, ch, &b)));
                bas.push(b);
            }
        }
        Ok(Renderer {
            calib,
            rows,
            cols,
            background: background.data.clone(),
            flat,
            basis: bas,
            gain: 1.0,
            smooth_px: 0.0,
            colour: IDENTITY_COLOUR,
            depth_gain: [0.0; 3],
        })
    }

    /// The background this renderer adds to.
    pub fn background(&self) -> RgbImage {
        RgbImage {
            rows: self.rows,
            cols: self.cols,
            data: self.background.clone(),
        }
    }

    /// Renders heights towards the camera `h` (m, rows x cols) with pixel size `m_per_px` (m)
    /// into `out` (rows x cols x 3). A zero-slope pixel keeps its background value exactly.
    pub fn render_into(&self, h: &[f32], m_per_px: f32, out: &mut [u8]) -> Result<()> {
        self.render_with(h, m_per_px, &mut RenderScratch::default(), out)
    }

    /// [`Renderer::render_into`] with scratch buffers kept between frames: no allocation per
    /// frame once `scratch` has grown to the image size.
    pub fn render_with(
        &self,
        h: &[f32],
        m_per_px: f32,
        scratch: &mut RenderScratch,
        out: &mut [u8],
    ) -> Result<()> {
        let (rows, cols) = (self.rows, self.cols);
        check_field(h.len(), rows, cols)?;
        if out.len() != rows * cols * 3 {
            return Err(TactileError::Input(format!(
                "output buffer of {} bytes for a {cols} x {rows} RGB image",
                out.len()
            )));
        }
        if !(m_per_px > 0.0 && m_per_px.is_finite()) {
            return Err(TactileError::Input(format!(
                "pixel size {m_per_px} m is not positive"
            )));
        }
        if let Some(i) = h.iter().position(|v| !v.is_finite()) {
            return Err(TactileError::Input(format!(
                "height at pixel (row {}, col {}) is {}",
                i / cols,
                i % cols,
                h[i]
            )));
        }
        let h = if self.smooth_px > 0.0 {
            scratch.smooth.resize(h.len(), 0.0);
            scratch.tmp.resize(h.len(), 0.0);
            gaussian_blur_into(
                h,
                rows,
                cols,
                self.smooth_px,
                &mut scratch.tmp,
                &mut scratch.smooth,
            );
            &scratch.smooth[..]
        } else {
            h
        };
        let inv = 1.0 / m_per_px;
        let flat2 = self.calib.flat_slope2();
        let identity = self.colour == IDENTITY_COLOUR;
        let depth = self.depth_gain != [0.0; 3];
        let m = self.colour.map(|row| row.map(|v| v * self.gain));
        out.par_chunks_mut(cols * 3)
            .enumerate()
            .with_min_len(16)
            .for_each(|(r, line)| {
                let (r0, r1) = (r.saturating_sub(1), (r + 1).min(rows - 1));
                let inv_r = inv / (r1 - r0) as f32;
                let (up, mid, dn) = (
                    &h[r0 * cols..][..cols],
                    &h[r * cols..][..cols],
                    &h[r1 * cols..][..cols],
                );
                let bg = &self.background[r * cols * 3..][..cols * 3];
                let basis = &self.basis[r * cols..][..cols];
                let flat = &self.flat[r * cols..][..cols];
                let half = 0.5 * inv;
                for c in 0..cols {
                    let sr = (dn[c] - up[c]) * inv_r;
                    let sc = if c > 0 && c + 1 < cols {
                        (mid[c + 1] - mid[c - 1]) * half
                    } else {
                        let (c0, c1) = (c.saturating_sub(1), (c + 1).min(cols - 1));
                        (mid[c1] - mid[c0]) * (inv / (c1 - c0) as f32)
                    };
                    let px = &mut line[c * 3..c * 3 + 3];
                    let bgp = &bg[c * 3..c * 3 + 3];
                    let t2 = sr * sr + sc * sc;
                    let mut d = [0.0f32; 3];
                    if depth {
                        d = self.depth_gain.map(|g| g * mid[c]);
                    }
                    if t2 < flat2 {
                        // A change below half a grey level rounds back to the background.
                        if !depth || d.iter().all(|v| v.abs() < 0.5) {
                            px.copy_from_slice(bgp);
                            continue;
                        }
                    } else {
                        let bin = self.calib.bin_sloped(sr, sc, t2);
                        let b = &basis[c];
                        let ds: [f32; 3] =
                            std::array::from_fn(|ch| self.calib.eval(bin, ch, b) - flat[c][ch]);
                        for ch in 0..3 {
                            d[ch] += if identity {
                                self.gain * ds[ch]
                            } else {
                                m[ch][0] * ds[0] + m[ch][1] * ds[1] + m[ch][2] * ds[2]
                            };
                        }
                    }
                    for ch in 0..3 {
                        let v = f32::from(bgp[ch]) + d[ch];
                        // Round half up on the clamped value: round() for the 0..255 range,
                        // without the libm call.
                        px[ch] = (v.clamp(0.0, 255.0) + 0.5) as u8;
                    }
                }
            });
        Ok(())
    }

    /// Renders a height field into a new image (see [`Renderer::render_into`]).
    pub fn render(&self, h: &[f32], m_per_px: f32) -> Result<RgbImage> {
        let mut data = vec![0u8; self.rows * self.cols * 3];
        self.render_into(h, m_per_px, &mut data)?;
        Ok(RgbImage {
            rows: self.rows,
            cols: self.cols,
            data,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The running-sum blur equals three plain box means along rows then three along columns,
    /// each sum taken directly with the border repeated.
    #[test]
    fn blur_matches_direct_box_sums() {
        let (rows, cols) = (37, 53);
        let h: Vec<f32> = (0..rows * cols)
            .map(|i| ((i * 7919) % 101) as f32 / 101.0)
            .collect();
        for sigma in [1.0f32, 2.5, 8.0] {
            let r = box_radius(sigma) as isize;
            let pass = |src: &[f32], along_rows: bool| -> Vec<f32> {
                let mut out = vec![0.0f32; src.len()];
                for y in 0..rows as isize {
                    for x in 0..cols as isize {
                        let mut s = 0.0f64;
                        for k in -r..=r {
                            let (yy, xx) = if along_rows {
                                (y, (x + k).clamp(0, cols as isize - 1))
                            } else {
                                ((y + k).clamp(0, rows as isize - 1), x)
                            };
                            s += f64::from(src[yy as usize * cols + xx as usize]);
                        }
                        out[y as usize * cols + x as usize] = (s / (2 * r + 1) as f64) as f32;
                    }
                }
                out
            };
            let mut want = h.clone();
            for along in [true, true, true, false, false, false] {
                want = pass(&want, along);
            }
            let got = gaussian_blur(&h, rows, cols, sigma);
            let worst = got
                .iter()
                .zip(&want)
                .map(|(a, b)| (a - b).abs())
                .fold(0.0f32, f32::max);
            assert!(worst < 1e-5, "sigma {sigma}: worst {worst}");
        }
    }
}
