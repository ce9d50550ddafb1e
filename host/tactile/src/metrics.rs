//! Calibration and image metrics (Ch.5.5, Table 5.2).

use crate::mask::{Mask, MaskStats};
use crate::{Result, TactileError};

fn same_len(what: &str, a: usize, b: usize) -> Result<()> {
    if a != b {
        return Err(TactileError::Input(format!(
            "{what}: {a} values against {b}"
        )));
    }
    if a == 0 {
        return Err(TactileError::Input(format!("{what}: nothing to compare")));
    }
    Ok(())
}

/// Nodal position RMSE: sqrt(mean_i |a_i - b_i|^2), in the units of the inputs.
pub fn nodal_rmse(a: &[[f64; 3]], b: &[[f64; 3]]) -> Result<f64> {
    same_len("nodal RMSE", a.len(), b.len())?;
    let s: f64 = a
        .iter()
        .zip(b)
        .map(|(p, q)| (0..3).map(|k| (p[k] - q[k]).powi(2)).sum::<f64>())
        .sum();
    Ok((s / a.len() as f64).sqrt())
}

/// Intersection over union of two masks on the same grid (1 when both are empty).
pub fn iou(a: &Mask, b: &Mask) -> Result<f64> {
    if a.grid != b.grid {
        return Err(TactileError::Input(
            "IoU of masks on different grids".into(),
        ));
    }
    let (mut inter, mut uni) = (0usize, 0usize);
    for (&p, &q) in a.pixels.iter().zip(&b.pixels) {
        inter += usize::from(p && q);
        uni += usize::from(p || q);
    }
    Ok(if uni == 0 {
        1.0
    } else {
        inter as f64 / uni as f64
    })
}

/// Distance between mask centroids, m (NaN when either mask is empty).
pub fn centroid_error(a: &MaskStats, b: &MaskStats) -> f64 {
    ((a.centroid_m[0] - b.centroid_m[0]).powi(2) + (a.centroid_m[1] - b.centroid_m[1]).powi(2))
        .sqrt()
}

/// Angle between two principal axes (undirected lines), rad in [0, pi/2].
pub fn rotation_error(a_rad: f64, b_rad: f64) -> f64 {
    let d = (a_rad - b_rad).rem_euclid(std::f64::consts::PI);
    d.min(std::f64::consts::PI - d)
}

/// RMSE between two force-depth curves sampled at the same depths, N.
pub fn force_rmse(a: &[f64], b: &[f64]) -> Result<f64> {
    same_len("force RMSE", a.len(), b.len())?;
    let s: f64 = a.iter().zip(b).map(|(x, y)| (x - y).powi(2)).sum();
    Ok((s / a.len() as f64).sqrt())
}

/// Mean absolute difference of two images (any channel layout, same length), on their scale
/// (0-255 for 8-bit images).
pub fn l1(a: &[f64], b: &[f64]) -> Result<f64> {
    same_len("L1", a.len(), b.len())?;
    Ok(a.iter().zip(b).map(|(x, y)| (x - y).abs()).sum::<f64>() / a.len() as f64)
}

/// Peak signal-to-noise ratio, dB, for peak value `peak` (255 for 8-bit); infinite when equal.
pub fn psnr(a: &[f64], b: &[f64], peak: f64) -> Result<f64> {
    same_len("PSNR", a.len(), b.len())?;
    let mse = a.iter().zip(b).map(|(x, y)| (x - y).powi(2)).sum::<f64>() / a.len() as f64;
    Ok(if mse == 0.0 {
        f64::INFINITY
    } else {
        10.0 * (peak * peak / mse).log10()
    })
}

/// Half-width of the SSIM window (11 x 11).
pub const SSIM_RADIUS: usize = 5;

/// Structural similarity (Wang et al. 2004) of two single-channel images (rows x cols,
/// row-major) with an 11 x 11 Gaussian window (sigma 1.5), K1 = 0.01, K2 = 0.03 and dynamic
/// range `peak`; the mean over all window positions that fit inside the image. For colour images
/// call it per channel and average.
pub fn ssim(a: &[f64], b: &[f64], rows: usize, cols: usize, peak: f64) -> Result<f64> {
    let map = ssim_map(a, b, rows, cols, peak)?;
    Ok(map.iter().sum::<f64>() / map.len() as f64)
}

/// SSIM averaged only over the windows whose centre pixel lies in `region` (rows x cols): the
/// similarity where something happens (a contact), not diluted by an unchanged background.
/// An error when no window centre lies in the region.
pub fn ssim_in(
    a: &[f64],
    b: &[f64],
    rows: usize,
    cols: usize,
    peak: f64,
    region: &[bool],
) -> Result<f64> {
    same_len("SSIM region", region.len(), rows * cols)?;
    let map = ssim_map(a, b, rows, cols, peak)?;
    let oc = cols - 2 * SSIM_RADIUS;
    let (mut sum, mut n) = (0.0, 0usize);
    for (i, v) in map.iter().enumerate() {
        let (r, c) = (i / oc + SSIM_RADIUS, i % oc + SSIM_RADIUS);
        if region[r * cols + c] {
            sum += v;
            n += 1;
        }
    }
    if n == 0 {
        return Err(TactileError::Input(
            "SSIM region holds no window centre (empty, or only within 5 px of the border)".into(),
        ));
    }
    Ok(sum / n as f64)
}

/// The SSIM of every 11 x 11 window that fits inside the image, row-major over window
/// positions ((rows - 10) x (cols - 10); entry (r, c) is the window centred on pixel
/// (r + 5, c + 5)).
pub fn ssim_map(a: &[f64], b: &[f64], rows: usize, cols: usize, peak: f64) -> Result<Vec<f64>> {
    same_len("SSIM", a.len(), b.len())?;
    if a.len() != rows * cols {
        return Err(TactileError::Input(format!(
            "SSIM: {} pixels for a {rows} x {cols} image",
            a.len()
        )));
    }
    const W: usize = 2 * SSIM_RADIUS + 1;
    if rows < W || cols < W {
        return Err(TactileError::Input(format!(
            "SSIM needs at least {W} x {W} pixels, got {rows} x {cols}"
        )));
    }
    if !(peak > 0.0 && peak.is_finite()) {
        return Err(TactileError::Input(format!(
            "SSIM dynamic range {peak} is not positive"
        )));
    }
    let g: Vec<f64> = {
        let v: Vec<f64> = (0..W)
            .map(|i| (-((i as f64 - 5.0).powi(2)) / (2.0 * 1.5 * 1.5)).exp())
            .collect();
        let s: f64 = v.iter().sum();
        v.iter().map(|x| x / s).collect()
    };
    // Separable Gaussian filtering of a, b, a^2, b^2, ab over the 'valid' region.
    let blur = |img: &dyn Fn(usize) -> f64| -> Vec<f64> {
        let oc = cols - W + 1;
        let or = rows - W + 1;
        let mut tmp = vec![0.0; rows * oc];
        for r in 0..rows {
            for c in 0..oc {
                tmp[r * oc + c] = (0..W).map(|k| g[k] * img(r * cols + c + k)).sum();
            }
        }
        let mut out = vec![0.0; or * oc];
        for r in 0..or {
            for c in 0..oc {
                out[r * oc + c] = (0..W).map(|k| g[k] * tmp[(r + k) * oc + c]).sum();
            }
        }
        out
    };
    let ma = blur(&|i| a[i]);
    let mb = blur(&|i| b[i]);
    let saa = blur(&|i| a[i] * a[i]);
    let sbb = blur(&|i| b[i] * b[i]);
    let sab = blur(&|i| a[i] * b[i]);
    let c1 = (0.01 * peak).powi(2);
    let c2 = (0.03 * peak).powi(2);
    Ok((0..ma.len())
        .map(|i| {
            let (mx, my) = (ma[i], mb[i]);
            let vx = saa[i] - mx * mx;
            let vy = sbb[i] - my * my;
            let cxy = sab[i] - mx * my;
            ((2.0 * mx * my + c1) * (2.0 * cxy + c2)) / ((mx * mx + my * my + c1) * (vx + vy + c2))
        })
        .collect())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::mask::{Grid, mask_from_fn};

    #[test]
    fn nodal_rmse_of_a_uniform_shift() {
        let a = vec![[0.0, 0.0, 0.0]; 10];
        let b = vec![[3.0, 4.0, 0.0]; 10];
        assert!((nodal_rmse(&a, &b).unwrap() - 5.0).abs() < 1e-12);
        let mut c = a.clone();
        c[0] = [2.0, 0.0, 0.0];
        // One node off by 2 among 10: sqrt(4 / 10).
        assert!((nodal_rmse(&a, &c).unwrap() - 0.4f64.sqrt()).abs() < 1e-12);
        assert!(nodal_rmse(&a, &b[..3]).is_err());
    }

    #[test]
    fn iou_of_overlapping_squares() {
        let g = Grid {
            origin_m: [0.0, 0.0],
            pixel_m: 1.0,
            rows: 50,
            cols: 50,
        };
        let a = mask_from_fn(g, |r, c| r < 20 && c < 20);
        let b = mask_from_fn(g, |r, c| r < 20 && (10..30).contains(&c));
        // 200 shared of 600.
        assert!((iou(&a, &b).unwrap() - 1.0 / 3.0).abs() < 1e-12);
        assert_eq!(iou(&a, &a).unwrap(), 1.0);
        let sa = a.stats();
        let sb = b.stats();
        assert!((centroid_error(&sa, &sb) - 10.0).abs() < 1e-9);
    }

    #[test]
    fn rotation_error_is_undirected() {
        let pi = std::f64::consts::PI;
        assert!((rotation_error(0.1, -0.1) - 0.2).abs() < 1e-12);
        assert!((rotation_error(pi / 2.0 - 0.05, -pi / 2.0 + 0.05) - 0.1).abs() < 1e-12);
        assert!(rotation_error(0.3, 0.3 + pi).abs() < 1e-12);
    }

    #[test]
    fn force_l1_psnr_known_values() {
        assert!(
            (force_rmse(&[1.0, 2.0, 3.0], &[1.0, 2.0, 5.0]).unwrap() - (4.0f64 / 3.0).sqrt()).abs()
                < 1e-12
        );
        let a = vec![10.0; 100];
        let b = vec![12.0; 100];
        assert!((l1(&a, &b).unwrap() - 2.0).abs() < 1e-12);
        // MSE 4 at peak 255: 10 log10(65025 / 4).
        assert!((psnr(&a, &b, 255.0).unwrap() - 10.0 * (65025.0f64 / 4.0).log10()).abs() < 1e-9);
        assert!(psnr(&a, &a, 255.0).unwrap().is_infinite());
    }

    #[test]
    fn ssim_identity_constant_and_contrast() {
        let (rows, cols) = (32, 40);
        let a: Vec<f64> = (0..rows * cols)
            .map(|i| {
                128.0 + 60.0 * ((i % cols) as f64 * 0.3).sin() * ((i / cols) as f64 * 0.2).cos()
            })
            .collect();
        assert!((ssim(&a, &a, rows, cols, 255.0).unwrap() - 1.0).abs() < 1e-12);
        // A constant offset keeps structure and contrast: only the luminance term drops, to
        // (2 mx my + c1) / (mx^2 + my^2 + c1) with mx, my the local means.
        let b: Vec<f64> = a.iter().map(|v| v + 10.0).collect();
        let s = ssim(&a, &b, rows, cols, 255.0).unwrap();
        assert!(s < 1.0 && s > 0.99, "{s}");
        // Inverting the pattern about its mean makes the structure term negative.
        let c: Vec<f64> = a.iter().map(|v| 256.0 - v).collect();
        assert!(ssim(&a, &c, rows, cols, 255.0).unwrap() < 0.0);
        // Two constant images of equal value: exactly 1; of different value: the luminance term.
        let k1 = vec![100.0; rows * cols];
        let k2 = vec![50.0; rows * cols];
        let c1 = (0.01f64 * 255.0).powi(2);
        let expect = (2.0 * 100.0 * 50.0 + c1) / (100.0f64 * 100.0 + 50.0 * 50.0 + c1);
        assert!((ssim(&k1, &k2, rows, cols, 255.0).unwrap() - expect).abs() < 1e-9);
        assert!(ssim(&a, &b, rows, cols - 1, 255.0).is_err());
    }

    /// The normalised 1-d Gaussian (sigma 1.5) of the 11 x 11 window, built here independently
    /// of `ssim_map`; the window weight at (i, j) is g_i g_j.
    fn gauss() -> Vec<f64> {
        let g: Vec<f64> = (0..11)
            .map(|i| (-((i as f64 - 5.0) * (i as f64 - 5.0)) / 4.5).exp())
            .collect();
        let s: f64 = g.iter().sum();
        g.iter().map(|v| v / s).collect()
    }

    /// A checkerboard m + d (-1)^(r+c) against m' + alpha d (-1)^(r+c) has, in every window,
    /// mean m + d e with e = +-S^2 (S = sum_i g_i (-1)^i, sign by the parity of r + c), both
    /// variances and the covariance proportional to d^2 (1 - S^4): SSIM takes one closed-form
    /// value per parity, and the mean over windows weighs the two by their counts.
    #[test]
    fn ssim_of_checkerboards_matches_the_closed_form() {
        let (rows, cols, peak) = (23usize, 30usize, 255.0);
        let (m, d, m2, alpha) = (120.0, 40.0, 131.0, 0.6);
        let x = |r: usize, c: usize| if (r + c).is_multiple_of(2) { 1.0 } else { -1.0 };
        let a: Vec<f64> = (0..rows * cols)
            .map(|i| m + d * x(i / cols, i % cols))
            .collect();
        let b: Vec<f64> = (0..rows * cols)
            .map(|i| m2 + alpha * d * x(i / cols, i % cols))
            .collect();
        let g = gauss();
        let s: f64 = (0..11).map(|i| g[i] * x(i, 0)).sum::<f64>();
        let s2 = s * s;
        let (c1, c2) = ((0.01 * peak) * (0.01 * peak), (0.03 * peak) * (0.03 * peak));
        let var = d * d * (1.0 - s2 * s2);
        let value = |e: f64| {
            let (mx, my) = (m + d * e, m2 + alpha * d * e);
            ((2.0 * mx * my + c1) * (2.0 * alpha * var + c2))
                / ((mx * mx + my * my + c1) * ((1.0 + alpha * alpha) * var + c2))
        };
        // Window (r, c) starts at pixel (r, c): its first weight sits on parity r + c.
        let (or, oc) = (rows - 10, cols - 10);
        let even = (0..or * oc)
            .filter(|i| (i / oc + i % oc).is_multiple_of(2))
            .count();
        let expect =
            (even as f64 * value(s2) + (or * oc - even) as f64 * value(-s2)) / (or * oc) as f64;
        let got = ssim(&a, &b, rows, cols, peak).unwrap();
        assert!((got - expect).abs() < 1e-12, "{got} vs {expect}");
        assert!(value(s2) != value(-s2));
        // Only windows centred on an even-parity pixel (window start parity is the same).
        let region: Vec<bool> = (0..rows * cols)
            .map(|i| (i / cols + i % cols).is_multiple_of(2))
            .collect();
        let got = ssim_in(&a, &b, rows, cols, peak, &region).unwrap();
        assert!((got - value(s2)).abs() < 1e-12, "{got} vs {}", value(s2));
        assert!(ssim_in(&a, &b, rows, cols, peak, &vec![false; rows * cols]).is_err());
        assert!(ssim_in(&a, &b, rows, cols, peak, &region[1..]).is_err());
        assert!(ssim(&a, &b, rows, cols, 0.0).is_err());
    }

    /// The separable filtering against a direct 11 x 11 sum per window on a pseudo-random pair.
    #[test]
    fn ssim_map_matches_direct_window_sums() {
        let (rows, cols, peak) = (19usize, 26usize, 255.0);
        let mut state = 12345u64;
        let mut next = || {
            state = state
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (state >> 33) as f64 / (1u64 << 31) as f64 * 255.0
        };
        let a: Vec<f64> = (0..rows * cols).map(|_| next()).collect();
        let b: Vec<f64> = a.iter().map(|v| 0.5 * v + 0.3 * next() + 20.0).collect();
        let g = gauss();
        let map = ssim_map(&a, &b, rows, cols, peak).unwrap();
        let oc = cols - 10;
        for (i, got) in map.iter().enumerate() {
            let (r, c) = (i / oc, i % oc);
            let (mut mx, mut my, mut xx, mut yy, mut xy) = (0.0, 0.0, 0.0, 0.0, 0.0);
            for (di, gi) in g.iter().enumerate() {
                for (dj, gj) in g.iter().enumerate() {
                    let (k, wt) = ((r + di) * cols + c + dj, gi * gj);
                    mx += wt * a[k];
                    my += wt * b[k];
                    xx += wt * a[k] * a[k];
                    yy += wt * b[k] * b[k];
                    xy += wt * a[k] * b[k];
                }
            }
            let (c1, c2) = (6.5025, 58.5225);
            let want = ((2.0 * mx * my + c1) * (2.0 * (xy - mx * my) + c2))
                / ((mx * mx + my * my + c1) * (xx - mx * mx + yy - my * my + c2));
            assert!((got - want).abs() < 1e-9, "window {r},{c}: {got} vs {want}");
        }
    }
}
