//! Hall-sensor calibration (App. C): a linear map from ADS1115 codes to
//! column length, fitted on the MCU by exact integer least squares.
//!
//! The fit runs in `i128`, so it is exact and identical on every target.
//! Outliers are removed by a median-absolute-deviation test (at most two
//! rounds), then the fit is repeated; R^2 and the RMS residual are reported.

use ocm_shared::protocol::{CalPoint, CalibrationError, CalibrationReport, MAX_CAL_POINTS};

use crate::fx::sat;

/// Fewest points a fit accepts.
pub const MIN_POINTS: usize = 3;
/// Smallest R^2 accepted, Q1.15 (0.90).
pub const MIN_R2_Q15: u16 = 29_491;

/// A fitted code -> length map with the code range it was fitted on.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct HallMap {
    /// Metres per code, Q24.40.
    pub slope_q40: i64,
    /// Length at code 0, metres Q8.24.
    pub offset_q24: i64,
    /// Lowest plausible code (fitted range widened by a quarter of its span).
    pub code_min: i16,
    /// Highest plausible code.
    pub code_max: i16,
}

impl HallMap {
    /// Column length for a code, metres Q8.24.
    pub fn length_q24(&self, code: i16) -> i32 {
        let l = self.offset_q24 + ((self.slope_q40 * i64::from(code)) >> 16);
        sat(l)
    }

    /// Whether the code lies in the plausible range and is not saturated.
    pub fn plausible(&self, code: i16) -> bool {
        code != i16::MIN && code != i16::MAX && code >= self.code_min && code <= self.code_max
    }
}

/// Plausible column lengths, metres Q8.24.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct LengthRange {
    /// Shortest accepted reference length.
    pub min_q24: i32,
    /// Longest accepted reference length.
    pub max_q24: i32,
}

struct Fit {
    slope_q40: i64,
    offset_q24: i64,
    ss_res: i128,
    ss_tot: i128,
    n: usize,
}

fn fit(points: &[(i32, i32)]) -> Result<Fit, CalibrationError> {
    let n = points.len() as i128;
    if points.len() < MIN_POINTS {
        return Err(CalibrationError::TooFewPoints);
    }
    let (mut sx, mut sy, mut sxx, mut sxy) = (0i128, 0i128, 0i128, 0i128);
    for &(x, y) in points {
        let (x, y) = (i128::from(x), i128::from(y));
        sx += x;
        sy += y;
        sxx += x * x;
        sxy += x * y;
    }
    let den = n * sxx - sx * sx;
    if den == 0 {
        return Err(CalibrationError::Degenerate);
    }
    let slope = ((n * sxy - sx * sy) << 16) / den; // Q40 m per code
    // More than 1 m per code is no Hall sensor; it also bounds every
    // product below.
    if slope.unsigned_abs() >= 1 << 40 {
        return Err(CalibrationError::Degenerate);
    }
    let offset = ((sy << 16) - slope * sx) / (n << 16); // Q24
    let (slope, offset) = (slope as i64, offset as i64);
    let mean_y = sy / n;
    let (mut ss_res, mut ss_tot) = (0i128, 0i128);
    for &(x, y) in points {
        let r = i128::from(y) - i128::from(offset + ((slope * i64::from(x)) >> 16));
        ss_res += r * r;
        let t = i128::from(y) - mean_y;
        ss_tot += t * t;
    }
    Ok(Fit {
        slope_q40: slope,
        offset_q24: offset,
        ss_res,
        ss_tot,
        n: points.len(),
    })
}

fn residual(f: &Fit, (x, y): (i32, i32)) -> i64 {
    i64::from(y) - (f.offset_q24 + ((f.slope_q40 * i64::from(x)) >> 16))
}

/// Median of a small slice, sorted in place by insertion (at most
/// [`MAX_CAL_POINTS`] items; a library sort would cost more stack than the
/// MCU can spare).
fn median(v: &mut [i64]) -> i64 {
    for i in 1..v.len() {
        let mut j = i;
        while j > 0 && v[j - 1] > v[j] {
            v.swap(j - 1, j);
            j -= 1;
        }
    }
    v.get(v.len() / 2).copied().unwrap_or(0)
}

/// Fits the map of actuator `actuator` from `points`.
pub fn calibrate(
    actuator: u8,
    points: &[CalPoint],
    range: LengthRange,
) -> Result<(HallMap, CalibrationReport), CalibrationError> {
    let mut kept: heapless::Vec<(i32, i32), MAX_CAL_POINTS> = heapless::Vec::new();
    let mut rejected = 0u8;
    for p in points.iter().take(MAX_CAL_POINTS) {
        if p.length_q24 < range.min_q24 || p.length_q24 > range.max_q24 {
            return Err(CalibrationError::LengthOutOfRange);
        }
        if p.code == i16::MIN || p.code == i16::MAX {
            // A saturated ADC reading carries no length information.
            rejected = rejected.saturating_add(1);
            continue;
        }
        let _ = kept.push((i32::from(p.code), p.length_q24));
    }
    let mut f = fit(&kept)?;
    for _ in 0..2 {
        let mut abs: heapless::Vec<i64, MAX_CAL_POINTS> = heapless::Vec::new();
        for &pt in &kept {
            let _ = abs.push(residual(&f, pt).abs());
        }
        // 1.4826 MAD estimates sigma for Gaussian noise; 4 sigma is a
        // conservative cut. The floor (1 um) keeps exact data intact.
        let mad = median(&mut abs);
        let cut = (mad * 59_304 / 10_000).max(17);
        let before = kept.len();
        let fit_now = &f;
        kept.retain(|&pt| residual(fit_now, pt).abs() <= cut);
        let dropped = before - kept.len();
        if dropped == 0 {
            break;
        }
        rejected = rejected.saturating_add(dropped as u8);
        f = fit(&kept)?;
    }
    let r2_q15 = if f.ss_tot == 0 {
        return Err(CalibrationError::Degenerate);
    } else {
        let unexplained = (f.ss_res << 15) / f.ss_tot;
        (32_768 - unexplained).clamp(0, 32_768) as u16
    };
    if r2_q15 < MIN_R2_Q15 {
        return Err(CalibrationError::PoorFit { r2_q15 });
    }
    let rms = (f.ss_res / f.n as i128).clamp(0, i128::from(u64::MAX)) as u64;
    let (mut lo, mut hi) = (i64::MAX, i64::MIN);
    for &(x, _) in &kept {
        lo = lo.min(i64::from(x));
        hi = hi.max(i64::from(x));
    }
    let margin = (hi - lo) / 4;
    let map = HallMap {
        slope_q40: f.slope_q40,
        offset_q24: f.offset_q24,
        code_min: (lo - margin).clamp(i64::from(i16::MIN) + 1, i64::from(i16::MAX) - 1) as i16,
        code_max: (hi + margin).clamp(i64::from(i16::MIN) + 1, i64::from(i16::MAX) - 1) as i16,
    };
    let report = CalibrationReport {
        actuator,
        slope_q40: f.slope_q40,
        offset_q24: f.offset_q24,
        r2_q15,
        rms_residual_q24: rms.isqrt().min(u64::from(u32::MAX)) as u32,
        used: f.n as u8,
        rejected,
    };
    Ok((map, report))
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::vec::Vec;

    fn range() -> LengthRange {
        LengthRange {
            min_q24: 1 << 20,
            max_q24: 1 << 24,
        }
    }

    fn pts(f: impl Fn(i16) -> f64, codes: &[i16]) -> heapless::Vec<CalPoint, MAX_CAL_POINTS> {
        codes
            .iter()
            .map(|&c| CalPoint {
                code: c,
                length_q24: (f(c) * 16_777_216.0).round() as i32,
            })
            .collect()
    }

    #[test]
    fn exact_line_is_recovered_with_r2_one() {
        // 0.12 m at code 16000, 4 um per code.
        let line = |c: i16| 0.12 + 4e-6 * (f64::from(c) - 16_000.0);
        let codes = [12_000, 13_000, 14_500, 16_000, 17_200, 19_000, 20_000];
        let (map, rep) = calibrate(2, &pts(line, &codes), range()).unwrap();
        assert_eq!(rep.r2_q15, 32_768);
        assert_eq!(rep.used, 7);
        assert_eq!(rep.rejected, 0);
        for c in [12_000i16, 15_555, 20_000] {
            let got = f64::from(map.length_q24(c)) / 16_777_216.0;
            assert!((got - line(c)).abs() < 2e-7, "{got} vs {}", line(c));
        }
        assert!(map.plausible(16_000) && !map.plausible(30_000) && !map.plausible(i16::MAX));
    }

    #[test]
    fn outlier_is_rejected_and_fit_matches_float_least_squares_on_the_rest() {
        let line = |c: i16| 0.1 + 3e-6 * f64::from(c);
        let codes = [1_000, 3_000, 5_000, 7_000, 9_000, 11_000, 13_000, 15_000];
        let mut p = pts(line, &codes);
        // Deterministic noise of +-0.1 mm and one gross outlier (+5 mm).
        for (i, q) in p.iter_mut().enumerate() {
            q.length_q24 += if i % 2 == 0 { 1_677 } else { -1_677 };
        }
        p[3].length_q24 += 83_886;
        let (map, rep) = calibrate(0, &p, range()).unwrap();
        assert_eq!(rep.rejected, 1);
        assert_eq!(rep.used, 7);
        // Reference: ordinary least squares in f64 on the kept points.
        let kept: Vec<(f64, f64)> = p
            .iter()
            .enumerate()
            .filter(|(i, _)| *i != 3)
            .map(|(_, q)| (f64::from(q.code), f64::from(q.length_q24) / 16_777_216.0))
            .collect();
        let n = kept.len() as f64;
        let (sx, sy): (f64, f64) = kept.iter().fold((0.0, 0.0), |a, p| (a.0 + p.0, a.1 + p.1));
        let sxx: f64 = kept.iter().map(|p| p.0 * p.0).sum();
        let sxy: f64 = kept.iter().map(|p| p.0 * p.1).sum();
        let slope = (n * sxy - sx * sy) / (n * sxx - sx * sx);
        let offset = (sy - slope * sx) / n;
        let got_slope = map.slope_q40 as f64 / 2f64.powi(40);
        assert!((got_slope - slope).abs() < 1e-11, "{got_slope} vs {slope}");
        assert!((map.offset_q24 as f64 / 16_777_216.0 - offset).abs() < 1e-7);
        assert!(rep.r2_q15 > 32_000 && rep.r2_q15 < 32_768);
    }

    #[test]
    fn bad_inputs_are_named() {
        let line = |c: i16| 0.1 + 3e-6 * f64::from(c);
        assert_eq!(
            calibrate(0, &pts(line, &[1, 2]), range()).unwrap_err(),
            CalibrationError::TooFewPoints
        );
        assert_eq!(
            calibrate(0, &pts(line, &[5, 5, 5, 5]), range()).unwrap_err(),
            CalibrationError::Degenerate
        );
        assert_eq!(
            calibrate(0, &pts(|_| 3.0, &[1, 2, 3]), range()).unwrap_err(),
            CalibrationError::LengthOutOfRange
        );
        // Pure noise around a constant: R^2 near zero.
        let noisy = pts(
            |c| 0.1 + if c % 2 == 0 { 1e-3 } else { -1e-3 },
            &[1, 2, 3, 4, 5, 6, 7, 8],
        );
        assert!(matches!(
            calibrate(0, &noisy, range()).unwrap_err(),
            CalibrationError::PoorFit { .. }
        ));
    }
}
