//! The optical calibration of a real DIGIT: a table over binned surface-gradient angles whose
//! every bin holds, per colour channel, a quadratic polynomial in the image position giving the
//! intensity change against the no-contact background (the layout of Taxim's `polycalib.npz`,
//! Si and Yuan 2022).
//!
//! Table layout: `grad_r`, `grad_g`, `grad_b` are `bins x bins x 6`; the first index bins the
//! gradient magnitude angle atan|grad h| over [0, pi/2] in steps of (pi/2)/(bins-1), the second
//! the gradient direction atan2(dh/drow, dh/dcol) over [-pi, pi] in steps of 2 pi/(bins-1)
//! (h grows towards the camera); the six coefficients multiply (x^2, y^2, x y, x, y, 1) with x the
//! column and y the row of the calibration camera's 640 x 480 frame.

use crate::{Result, TactileError};
use std::io::Read;
use std::path::Path;

/// Columns of the frame the polynomials were fitted in (the DIGIT's 640 x 480 stream).
pub const CALIB_FRAME_COLS: usize = 640;
/// Rows of the frame the polynomials were fitted in.
pub const CALIB_FRAME_ROWS: usize = 480;

/// A gradient-to-colour polynomial table.
#[derive(Debug, Clone, PartialEq)]
pub struct PolyCalib {
    /// Bins per axis (magnitude and direction).
    pub bins: usize,
    /// Per bin (magnitude-major), per channel R, G, B, the six coefficients: 18 values per bin.
    pub coeffs: Vec<f32>,
    /// Squared slope at which each magnitude bin 1..bins-1 starts, tan^2(k (pi/2) / (bins - 1)):
    /// binning compares squared slopes with these instead of taking an arctangent per pixel.
    mag_edges2: Vec<f32>,
}

fn calib_err(path: &str, msg: impl Into<String>) -> TactileError {
    TactileError::Calibration {
        path: path.to_string(),
        msg: msg.into(),
    }
}

impl PolyCalib {
    /// Builds a table from `bins x bins x 6` arrays (row-major) for R, G and B; `name` labels
    /// the errors.
    pub fn from_tables(bins: usize, tables: [&[f64]; 3], name: &str) -> Result<Self> {
        if bins < 3 || bins.is_multiple_of(2) {
            return Err(calib_err(
                name,
                format!("bins = {bins}: need an odd count of at least 3 (a zero-gradient bin)"),
            ));
        }
        let n = bins * bins * 6;
        let mut coeffs = vec![0.0f32; bins * bins * 18];
        for (ch, t) in tables.iter().enumerate() {
            let cname = ["grad_r", "grad_g", "grad_b"][ch];
            if t.len() != n {
                return Err(calib_err(
                    name,
                    format!(
                        "{cname} holds {} values, a {bins} x {bins} x 6 table needs {n}",
                        t.len()
                    ),
                ));
            }
            if let Some(i) = t.iter().position(|v| !v.is_finite()) {
                return Err(calib_err(
                    name,
                    format!(
                        "{cname}[{}, {}, {}] is {}",
                        i / (6 * bins),
                        (i / 6) % bins,
                        i % 6,
                        t[i]
                    ),
                ));
            }
            for b in 0..bins * bins {
                for k in 0..6 {
                    coeffs[b * 18 + ch * 6 + k] = t[b * 6 + k] as f32;
                }
            }
        }
        let step = std::f64::consts::FRAC_PI_2 / (bins - 1) as f64;
        let mag_edges2 = (1..bins)
            .map(|k| {
                if k == bins - 1 {
                    f32::INFINITY
                } else {
                    (k as f64 * step).tan().powi(2) as f32
                }
            })
            .collect();
        Ok(PolyCalib {
            bins,
            coeffs,
            mag_edges2,
        })
    }

    /// Reads a Taxim-style `polycalib.npz` (arrays `bins`, `grad_r`, `grad_g`, `grad_b`).
    pub fn from_npz(path: impl AsRef<Path>) -> Result<Self> {
        let path = path.as_ref();
        let bytes = std::fs::read(path).map_err(|e| TactileError::io(path, e))?;
        Self::from_npz_bytes(&bytes, &path.display().to_string())
    }

    /// Parses the bytes of a `polycalib.npz`; `name` labels the errors.
    pub fn from_npz_bytes(bytes: &[u8], name: &str) -> Result<Self> {
        let mut zip = zip::ZipArchive::new(std::io::Cursor::new(bytes))
            .map_err(|e| calib_err(name, format!("not a readable .npz (zip) archive: {e}")))?;
        let mut array = |key: &str| -> Result<ocm_fem::npy::ArrayNd> {
            let file = format!("{key}.npy");
            let mut entry = zip
                .by_name(&file)
                .map_err(|e| calib_err(name, format!("no array '{key}' ({file}): {e}")))?;
            let mut buf = Vec::new();
            entry
                .read_to_end(&mut buf)
                .map_err(|e| calib_err(name, format!("reading {file}: {e}")))?;
            ocm_fem::npy::parse_nd(&buf, &format!("{name}:{file}"))
                .map_err(|e| calib_err(name, e.to_string()))
        };
        let bins_arr = array("bins")?;
        let bins = match bins_arr.data[..] {
            [b] if b >= 1.0 && b.fract() == 0.0 && b < 1e5 => b as usize,
            _ => {
                return Err(calib_err(
                    name,
                    format!(
                        "'bins' must be one positive integer, got {:?}",
                        bins_arr.data
                    ),
                ));
            }
        };
        let mut tables = Vec::with_capacity(3);
        for key in ["grad_r", "grad_g", "grad_b"] {
            let a = array(key)?;
            if a.shape != [bins, bins, 6] {
                return Err(calib_err(
                    name,
                    format!(
                        "{key} has shape {:?}, expected [{bins}, {bins}, 6] from 'bins'",
                        a.shape
                    ),
                ));
            }
            tables.push(a.data);
        }
        Self::from_tables(bins, [&tables[0], &tables[1], &tables[2]], name)
    }

    /// The bin of a surface slope (dh/drow, dh/dcol), both dimensionless; h grows towards the
    /// camera. The whole first magnitude bin (slopes below tan 0.72 deg for 125 bins) is the
    /// flat bin: there the direction is noise, and the table's first row was filled from
    /// neighbouring bins, not measured per direction.
    #[inline]
    pub fn bin(&self, slope_row: f32, slope_col: f32) -> usize {
        let t2 = slope_row * slope_row + slope_col * slope_col;
        if t2 < self.flat_slope2() {
            return self.flat_bin();
        }
        self.bin_sloped(slope_row, slope_col, t2)
    }

    /// Squared slope below which a pixel is in the flat bin.
    #[inline]
    pub fn flat_slope2(&self) -> f32 {
        self.mag_edges2[0]
    }

    /// [`PolyCalib::bin`] of a slope known to lie outside the flat bin, given its squared
    /// magnitude `t2`. The magnitude bin is the number of bin edges at or below the slope (the
    /// floor of atan|s| / step, without the arctangent).
    #[inline]
    pub fn bin_sloped(&self, slope_row: f32, slope_col: f32, t2: f32) -> usize {
        let i = self.mag_edges2.partition_point(|&e| e <= t2);
        let binm = (self.bins - 1) as f32;
        let d = (slope_row.atan2(slope_col) + std::f32::consts::PI)
            * (binm / (2.0 * std::f32::consts::PI));
        let j = (d.max(0.0) as usize).min(self.bins - 1);
        i * self.bins + j
    }

    /// The flat-surface bin (zero slope: magnitude bin 0, middle direction bin), as the flat
    /// index `bin()` returns.
    #[inline]
    pub fn flat_bin(&self) -> usize {
        (self.bins - 1) / 2
    }

    /// Intensity change of channel `ch` (0 R, 1 G, 2 B) in bin `bin` at calibration-frame
    /// position (x column, y row), grey levels.
    #[inline]
    pub fn eval(&self, bin: usize, ch: usize, basis: &[f32; 6]) -> f32 {
        let c = &self.coeffs[bin * 18 + ch * 6..bin * 18 + ch * 6 + 6];
        c[0] * basis[0]
            + c[1] * basis[1]
            + c[2] * basis[2]
            + c[3] * basis[3]
            + c[4] * basis[4]
            + c[5] * basis[5]
    }
}

/// The polynomial basis (x^2, y^2, x y, x, y, 1) at calibration-frame position (x, y).
pub fn basis(x: f32, y: f32) -> [f32; 6] {
    [x * x, y * y, x * y, x, y, 1.0]
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Bins follow the table layout: magnitude angle over [0, pi/2], direction over [-pi, pi].
    #[test]
    fn binning_matches_the_layout() {
        let bins = 125;
        let t = vec![0.0; bins * bins * 6];
        let c = PolyCalib::from_tables(bins, [&t, &t, &t], "t").unwrap();
        assert_eq!(c.bin(0.0, 0.0), 62);
        // Slope just above 1 along +col (a hair towards +row, off the bin edges): angle pi/4 ->
        // magnitude bin 0.25 pi / (0.5 pi / 124) = 62, direction ~0 -> 62.
        let b = c.bin(0.01, 1.0001);
        assert_eq!((b / bins, b % bins), (62, 62));
        // Along -col, a hair towards -row: direction just above -pi -> the first bin.
        let b = c.bin(-0.01, -1.0001);
        assert_eq!((b / bins, b % bins), (62, 0));
        // Along +row (a hair towards -col): direction just above pi/2 -> 1.5 pi / (2 pi / 124) = 93.
        let b = c.bin(0.5, -0.01);
        assert_eq!(b % bins, 93);
        let mag = (0.5f64.hypot(0.01)).atan() / (0.5 * std::f64::consts::PI / 124.0);
        assert_eq!(b / bins, mag as usize);
        assert!(PolyCalib::from_tables(4, [&t, &t, &t], "t").is_err());
        let mut bad = t.clone();
        bad[7] = f64::NAN;
        let e = PolyCalib::from_tables(bins, [&t, &bad, &t], "x.npz")
            .unwrap_err()
            .to_string();
        assert!(e.contains("x.npz") && e.contains("grad_g[0, 1, 1]"), "{e}");
    }

    /// The magnitude bin from squared-slope edges equals floor(atan|s| / step) computed in f64
    /// for slopes spread over the whole range (skipping those within 1e-5 rad of an edge, where
    /// rounding may decide either way), and the direction bin is unchanged.
    #[test]
    fn edge_binning_equals_the_arctangent() {
        let bins = 125;
        let t = vec![0.0; bins * bins * 6];
        let c = PolyCalib::from_tables(bins, [&t, &t, &t], "t").unwrap();
        let step = std::f64::consts::FRAC_PI_2 / (bins - 1) as f64;
        let mut checked = 0;
        for k in 0..20_000 {
            let mag = (k as f64 * 0.000_61).powi(2) * 3.0;
            let dir = k as f64 * 2.399_963;
            let (sr, sc) = ((mag * dir.sin()) as f32, (mag * dir.cos()) as f32);
            let a = f64::from(sr).hypot(f64::from(sc)).atan() / step;
            if (a - a.round()).abs() < 1e-5 / step {
                continue;
            }
            let want_i = (a as usize).min(bins - 1);
            let b = c.bin(sr, sc);
            assert_eq!(b / bins, want_i, "slope ({sr}, {sc})");
            if want_i > 0 {
                let d = (f64::from(sr).atan2(f64::from(sc)) + std::f64::consts::PI)
                    / (2.0 * std::f64::consts::PI / (bins - 1) as f64);
                if (d - d.round()).abs() > 1e-4 {
                    assert_eq!(b % bins, (d as usize).min(bins - 1), "slope ({sr}, {sc})");
                }
            } else {
                assert_eq!(b, c.flat_bin());
            }
            checked += 1;
        }
        assert!(checked > 19_000, "{checked}");
    }
}
