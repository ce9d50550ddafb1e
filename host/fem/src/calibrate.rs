//! Material calibration: hyperelastic fits to uniaxial data and the (E, nu) grid search of Ch.4.4.3.
//!
//! Units of `E50_stress_stretch.csv` are not stated. We read the stress as **kPa**: its initial
//! slope (about 1.2 MPa per unit strain) and its stress at 100 % strain (about 0.95 MPa) match the
//! Formlabs Elastic 50A data sheet (tensile modulus and 100 % modulus of order 1 MPa), while MPa
//! or Pa would be three orders of magnitude off for a Shore 50A elastomer.

use crate::{FemError, Result};
use serde::Serialize;

/// One uniaxial sample: stretch and nominal (engineering) stress in Pa.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct UniaxialSample {
    /// Stretch lambda = L/L0.
    pub stretch: f64,
    /// Nominal stress, Pa.
    pub stress_pa: f64,
}

/// Reads a `stretch,stress` CSV with stress in kPa (see module docs); the header is required.
pub fn read_stress_stretch_kpa(path: impl AsRef<std::path::Path>) -> Result<Vec<UniaxialSample>> {
    let path = path.as_ref();
    let text = std::fs::read_to_string(path).map_err(|source| FemError::Io {
        path: path.display().to_string(),
        source,
    })?;
    parse_stress_stretch_kpa(&text)
}

/// Parses `stretch,stress` CSV text (stress in kPa).
pub fn parse_stress_stretch_kpa(text: &str) -> Result<Vec<UniaxialSample>> {
    let text = text.trim_start_matches('\u{feff}');
    let mut rdr = csv::ReaderBuilder::new()
        .has_headers(true)
        .from_reader(text.as_bytes());
    let hdr = rdr
        .headers()
        .map_err(|e| FemError::parse("CSV", "line 1", e.to_string()))?
        .clone();
    let col = |name: &str| {
        hdr.iter()
            .position(|h| h.trim().eq_ignore_ascii_case(name))
            .ok_or_else(|| FemError::parse("CSV", "line 1", format!("missing column '{name}'")))
    };
    let (cs, cp) = (col("stretch")?, col("stress")?);
    let mut out = vec![];
    for (k, rec) in rdr.records().enumerate() {
        let line = format!("line {}", k + 2);
        let rec = rec.map_err(|e| FemError::parse("CSV", line.clone(), e.to_string()))?;
        let get = |c: usize| -> Result<f64> {
            let s = rec.get(c).unwrap_or("").trim();
            s.parse::<f64>()
                .ok()
                .filter(|v| v.is_finite())
                .ok_or_else(|| {
                    FemError::parse("CSV", line.clone(), format!("'{s}' is not a finite number"))
                })
        };
        let (l, p) = (get(cs)?, get(cp)?);
        if l <= 0.0 {
            return Err(FemError::parse(
                "CSV",
                line,
                format!("stretch {l} must be positive"),
            ));
        }
        out.push(UniaxialSample {
            stretch: l,
            stress_pa: p * 1e3,
        });
    }
    if out.is_empty() {
        return Err(FemError::parse("CSV", "end", "no data rows"));
    }
    Ok(out)
}

/// Result of a hyperelastic fit.
#[derive(Debug, Clone, Serialize)]
pub struct Fit {
    /// Model name.
    pub model: &'static str,
    /// Parameters by name, Pa.
    pub params: Vec<(&'static str, f64)>,
    /// Root-mean-square stress error, Pa.
    pub rmse_pa: f64,
    /// Small-strain Young's modulus implied by the fit (incompressible: E = 3 mu), Pa.
    pub young_pa: f64,
}

/// Incompressible Neo-Hookean nominal stress: P = mu (l - l^-2).
pub fn neo_hookean_stress(mu: f64, l: f64) -> f64 {
    mu * (l - l.powi(-2))
}

/// Incompressible Mooney-Rivlin nominal stress: P = 2 (l - l^-2) (C10 + C01 / l).
pub fn mooney_rivlin_stress(c10: f64, c01: f64, l: f64) -> f64 {
    2.0 * (l - l.powi(-2)) * (c10 + c01 / l)
}

fn rmse(data: &[UniaxialSample], f: impl Fn(f64) -> f64) -> f64 {
    (data
        .iter()
        .map(|s| (f(s.stretch) - s.stress_pa).powi(2))
        .sum::<f64>()
        / data.len() as f64)
        .sqrt()
}

/// Least-squares Neo-Hookean fit (linear in mu, solved exactly).
pub fn fit_neo_hookean(data: &[UniaxialSample]) -> Result<Fit> {
    let (num, den) = data.iter().fold((0.0, 0.0), |a, s| {
        let g = s.stretch - s.stretch.powi(-2);
        (a.0 + g * s.stress_pa, a.1 + g * g)
    });
    if den <= 0.0 {
        return Err(FemError::Model(
            "uniaxial data has no stretch away from 1".into(),
        ));
    }
    let mu = num / den;
    Ok(Fit {
        model: "neo_hookean",
        params: vec![("mu_pa", mu)],
        rmse_pa: rmse(data, |l| neo_hookean_stress(mu, l)),
        young_pa: 3.0 * mu,
    })
}

/// Least-squares two-parameter Mooney-Rivlin fit (linear in C10, C01; 2x2 normal equations).
pub fn fit_mooney_rivlin(data: &[UniaxialSample]) -> Result<Fit> {
    let mut a = [[0.0; 2]; 2];
    let mut b = [0.0; 2];
    for s in data {
        let g = 2.0 * (s.stretch - s.stretch.powi(-2));
        let phi = [g, g / s.stretch];
        for i in 0..2 {
            b[i] += phi[i] * s.stress_pa;
            for j in 0..2 {
                a[i][j] += phi[i] * phi[j];
            }
        }
    }
    let det = a[0][0] * a[1][1] - a[0][1] * a[1][0];
    if det.abs() <= 1e-12 * a[0][0] * a[1][1] {
        return Err(FemError::Model(
            "Mooney-Rivlin fit is ill-conditioned for this data".into(),
        ));
    }
    let c10 = (b[0] * a[1][1] - b[1] * a[0][1]) / det;
    let c01 = (a[0][0] * b[1] - a[1][0] * b[0]) / det;
    Ok(Fit {
        model: "mooney_rivlin",
        params: vec![("c10_pa", c10), ("c01_pa", c01)],
        rmse_pa: rmse(data, |l| mooney_rivlin_stress(c10, c01, l)),
        young_pa: 6.0 * (c10 + c01),
    })
}

/// Young's modulus from the initial linear region (strain <= `max_strain`), as in Ch.4.4.3; slope through 0.
pub fn initial_modulus(data: &[UniaxialSample], max_strain: f64) -> Result<f64> {
    let (num, den) =
        data.iter()
            .filter(|s| s.stretch - 1.0 <= max_strain)
            .fold((0.0, 0.0), |a, s| {
                let e = s.stretch - 1.0;
                (a.0 + e * s.stress_pa, a.1 + e * e)
            });
    if den <= 0.0 {
        return Err(FemError::Model(format!(
            "no samples with 0 < strain <= {max_strain}"
        )));
    }
    Ok(num / den)
}

/// One cell of an (E, nu) grid search.
#[derive(Debug, Clone, Serialize)]
pub struct GridCell {
    /// Young's modulus, Pa.
    pub young_pa: f64,
    /// Poisson's ratio.
    pub poisson: f64,
    /// Error of the response against the target (NaN when the simulation failed).
    pub error: f64,
}

/// Evaluates `error(E, nu)` on the grid (failures recorded as NaN) and returns all cells and the best.
pub fn grid_search(
    youngs_pa: &[f64],
    poissons: &[f64],
    mut error: impl FnMut(f64, f64) -> Result<f64>,
) -> Result<(Vec<GridCell>, GridCell)> {
    let mut cells = vec![];
    // the first failure, so that a grid on which nothing solves says why
    let mut first_failure: Option<String> = None;
    for &e in youngs_pa {
        for &nu in poissons {
            let err = error(e, nu).unwrap_or_else(|why| {
                first_failure.get_or_insert_with(|| format!("E = {e:e} Pa, nu = {nu}: {why}"));
                f64::NAN
            });
            cells.push(GridCell {
                young_pa: e,
                poisson: nu,
                error: err,
            });
        }
    }
    let best = cells
        .iter()
        .filter(|c| c.error.is_finite())
        .min_by(|a, b| a.error.total_cmp(&b.error))
        .cloned()
        .ok_or_else(|| {
            FemError::Model(format!(
                "every one of the {} grid points failed; the first, {}",
                cells.len(),
                first_failure
                    .as_deref()
                    .unwrap_or("gave a non-finite error")
            ))
        })?;
    Ok((cells, best))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn fits_recover_synthetic_parameters() {
        let data: Vec<UniaxialSample> = (0..60)
            .map(|k| {
                let l = 1.0 + 0.05 * k as f64;
                UniaxialSample {
                    stretch: l,
                    stress_pa: mooney_rivlin_stress(1.5e5, 0.4e5, l),
                }
            })
            .collect();
        let mr = fit_mooney_rivlin(&data).unwrap();
        assert!((mr.params[0].1 - 1.5e5).abs() < 1e-3 && (mr.params[1].1 - 0.4e5).abs() < 1e-3);
        assert!(mr.rmse_pa < 1e-6);
        let nh = fit_neo_hookean(&data).unwrap();
        assert!(
            nh.rmse_pa > 1.0,
            "a one-parameter law cannot fit MR data exactly"
        );
        let e0 = initial_modulus(&data, 0.06).unwrap();
        assert!((e0 - 6.0 * 1.9e5).abs() / (6.0 * 1.9e5) < 0.1);
    }

    #[test]
    fn csv_errors_are_located() {
        let e = parse_stress_stretch_kpa("stretch,stress\n1.0,0\n1.1,abc\n")
            .unwrap_err()
            .to_string();
        assert!(e.contains("line 3") && e.contains("abc"), "{e}");
        assert!(parse_stress_stretch_kpa("a,b\n1,2\n").is_err());
    }

    #[test]
    fn grid_search_finds_the_minimum() {
        let es = [1.0, 2.0, 3.0];
        let nus = [0.3, 0.4, 0.45];
        let (cells, best) = grid_search(&es, &nus, |e, nu| {
            if e > 2.5 {
                return Err(FemError::Model("diverged".into()));
            }
            Ok((e - 2.0).powi(2) + (nu - 0.4).powi(2))
        })
        .unwrap();
        assert_eq!(cells.len(), 9);
        assert_eq!((best.young_pa, best.poisson), (2.0, 0.4));
        assert!(cells.iter().filter(|c| c.error.is_nan()).count() == 3);
        // nothing solves: the error counts the points and says why the first failed
        let e = grid_search(&es, &nus, |e, _| {
            Err(FemError::Model(format!("diverged at {e}")))
        })
        .unwrap_err()
        .to_string();
        assert!(
            e.contains("every one of the 9 grid points failed")
                && e.contains("E = 1e0 Pa, nu = 0.3: invalid model: diverged at 1"),
            "{e}"
        );
    }
}
