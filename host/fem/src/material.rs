//! Constitutive laws: corotational linear elasticity and two compressible Neo-Hookean forms.
//!
//! Hyperelastic laws give the first Piola-Kirchhoff stress P(F) and its derivative
//! A = dP/dF as a 9x9 matrix indexed (3i+j, 3k+l), so that element tangents follow by contraction.

use nalgebra::{Matrix3, SMatrix};
use serde::{Deserialize, Serialize};

/// 9x9 fourth-order tensor dP_ij/dF_kl stored as (3i+j, 3k+l).
pub type Tangent4 = SMatrix<f64, 9, 9>;

/// A material law with its parameters (SI units: Pa).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(tag = "law", rename_all = "snake_case")]
pub enum Material {
    /// Linear elasticity in a rotated frame (SOFA TetrahedronFEMForceField, polar method).
    Corotational {
        /// Young's modulus, Pa.
        young_pa: f64,
        /// Poisson's ratio.
        poisson: f64,
    },
    /// Compressible Neo-Hookean, dissertation eq 2.1: mu/2 (I1-3) - mu ln J + lambda/2 (ln J)^2.
    NeoHookean {
        /// Shear modulus mu, Pa.
        mu_pa: f64,
        /// Lame lambda, Pa.
        lambda_pa: f64,
    },
    /// Neo-Hookean with isochoric I1, dissertation eq 5.6: mu/2 (J^-2/3 I1 - 3) + kappa/2 (J-1)^2.
    NeoHookeanBulk {
        /// Shear modulus mu, Pa.
        mu_pa: f64,
        /// Bulk modulus kappa, Pa.
        kappa_pa: f64,
    },
}

/// Lame parameters (mu, lambda) from Young's modulus and Poisson's ratio.
pub fn lame(young: f64, poisson: f64) -> (f64, f64) {
    let mu = young / (2.0 * (1.0 + poisson));
    let lambda = young * poisson / ((1.0 + poisson) * (1.0 - 2.0 * poisson));
    (mu, lambda)
}

impl Material {
    /// Corotational material from (E, nu).
    pub fn corotational(young_pa: f64, poisson: f64) -> Self {
        Material::Corotational { young_pa, poisson }
    }
    /// Eq 2.1 Neo-Hookean from (E, nu).
    pub fn neo_hookean(young_pa: f64, poisson: f64) -> Self {
        let (mu_pa, lambda_pa) = lame(young_pa, poisson);
        Material::NeoHookean { mu_pa, lambda_pa }
    }
    /// Eq 5.6 Neo-Hookean from (E, nu): mu = E/(2(1+nu)), kappa = E/(3(1-2nu)).
    pub fn neo_hookean_bulk(young_pa: f64, poisson: f64) -> Self {
        Material::NeoHookeanBulk {
            mu_pa: young_pa / (2.0 * (1.0 + poisson)),
            kappa_pa: young_pa / (3.0 * (1.0 - 2.0 * poisson)),
        }
    }

    /// Checks that parameters are finite and physically admissible.
    pub fn validate(&self) -> crate::Result<()> {
        let ok = match *self {
            Material::Corotational { young_pa, poisson } => {
                young_pa.is_finite() && young_pa > 0.0 && poisson > -1.0 && poisson < 0.5
            }
            Material::NeoHookean { mu_pa, lambda_pa } => {
                mu_pa.is_finite()
                    && lambda_pa.is_finite()
                    && mu_pa > 0.0
                    && lambda_pa > -2.0 / 3.0 * mu_pa
            }
            Material::NeoHookeanBulk { mu_pa, kappa_pa } => {
                mu_pa.is_finite() && kappa_pa.is_finite() && mu_pa > 0.0 && kappa_pa > 0.0
            }
        };
        if ok {
            Ok(())
        } else {
            Err(crate::FemError::Model(format!(
                "inadmissible material parameters {self:?}"
            )))
        }
    }

    /// Small-strain (mu, lambda) of this law, for the linear tangent at rest.
    pub fn small_strain_lame(&self) -> (f64, f64) {
        match *self {
            Material::Corotational { young_pa, poisson } => lame(young_pa, poisson),
            Material::NeoHookean { mu_pa, lambda_pa } => (mu_pa, lambda_pa),
            Material::NeoHookeanBulk { mu_pa, kappa_pa } => (mu_pa, kappa_pa - 2.0 / 3.0 * mu_pa),
        }
    }
}

/// Checks the elastic constants a user gives: a finite positive Young's modulus and a
/// Poisson's ratio strictly inside (-1, 0.5) (0.5 is incompressible: its bulk modulus is
/// infinite). The message names the constant and the value given (the derived Lame or bulk
/// moduli would hide which one is wrong).
pub fn check_elastic(young_pa: f64, poisson: f64) -> std::result::Result<(), String> {
    if !(young_pa.is_finite() && young_pa > 0.0) {
        return Err(format!(
            "Young's modulus must be a positive number, got {young_pa} Pa"
        ));
    }
    if !(poisson > -1.0 && poisson < 0.5) {
        return Err(format!(
            "Poisson's ratio must lie strictly between -1 and 0.5 (0.5 is incompressible), got {poisson}"
        ));
    }
    Ok(())
}

/// Isotropic linear elasticity tensor C as a 9x9 (3i+j, 3k+l) matrix.
pub fn linear_tensor(mu: f64, lambda: f64) -> Tangent4 {
    let mut c = Tangent4::zeros();
    for i in 0..3 {
        for j in 0..3 {
            for k in 0..3 {
                for l in 0..3 {
                    let d = |a: usize, b: usize| if a == b { 1.0 } else { 0.0 };
                    c[(3 * i + j, 3 * k + l)] =
                        lambda * d(i, j) * d(k, l) + mu * (d(i, k) * d(j, l) + d(i, l) * d(j, k));
                }
            }
        }
    }
    c
}

/// Hyperelastic response at F: energy density, P and dP/dF. `None` when J <= 0.
pub fn hyperelastic(
    m: &Material,
    f: &Matrix3<f64>,
    want_tangent: bool,
) -> Option<(f64, Matrix3<f64>, Option<Tangent4>)> {
    let j = f.determinant();
    if !(j > 0.0) {
        return None;
    }
    let h = f.try_inverse()?.transpose();
    let i1 = f.norm_squared();
    let d = |a: usize, b: usize| if a == b { 1.0 } else { 0.0 };
    match *m {
        Material::NeoHookean {
            mu_pa: mu,
            lambda_pa: lam,
        } => {
            let lnj = j.ln();
            let w = 0.5 * mu * (i1 - 3.0) - mu * lnj + 0.5 * lam * lnj * lnj;
            let p = mu * (f - h) + lam * lnj * h;
            let a = want_tangent.then(|| {
                let mut a = Tangent4::zeros();
                let c1 = mu - lam * lnj;
                for i in 0..3 {
                    for jj in 0..3 {
                        for k in 0..3 {
                            for l in 0..3 {
                                a[(3 * i + jj, 3 * k + l)] = mu * d(i, k) * d(jj, l)
                                    + c1 * h[(i, l)] * h[(k, jj)]
                                    + lam * h[(i, jj)] * h[(k, l)];
                            }
                        }
                    }
                }
                a
            });
            Some((w, p, a))
        }
        Material::NeoHookeanBulk {
            mu_pa: mu,
            kappa_pa: kap,
        } => {
            let a23 = j.powf(-2.0 / 3.0);
            let w = 0.5 * mu * (a23 * i1 - 3.0) + 0.5 * kap * (j - 1.0).powi(2);
            let p = mu * a23 * (f - (i1 / 3.0) * h) + kap * (j - 1.0) * j * h;
            let a = want_tangent.then(|| {
                let mut a = Tangent4::zeros();
                for i in 0..3 {
                    for jj in 0..3 {
                        for k in 0..3 {
                            for l in 0..3 {
                                let iso = d(i, k) * d(jj, l)
                                    - 2.0 / 3.0 * (f[(i, jj)] * h[(k, l)] + h[(i, jj)] * f[(k, l)])
                                    + 2.0 / 9.0 * i1 * h[(i, jj)] * h[(k, l)]
                                    + i1 / 3.0 * h[(i, l)] * h[(k, jj)];
                                let vol = j * (2.0 * j - 1.0) * h[(i, jj)] * h[(k, l)]
                                    - j * (j - 1.0) * h[(i, l)] * h[(k, jj)];
                                a[(3 * i + jj, 3 * k + l)] = mu * a23 * iso + kap * vol;
                            }
                        }
                    }
                }
                a
            });
            Some((w, p, a))
        }
        Material::Corotational { .. } => None,
    }
}

/// Which constitutive law a body uses (the bellows manipulator's is stored in its calibration).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "snake_case")]
pub enum Law {
    /// Corotational linear elasticity (as the original SOFA scene).
    #[default]
    Corotational,
    /// Neo-Hookean, eq 2.1.
    NeoHookean,
    /// Neo-Hookean, eq 5.6.
    NeoHookeanBulk,
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sample_f() -> Matrix3<f64> {
        Matrix3::new(1.1, 0.2, -0.05, 0.03, 0.9, 0.1, -0.1, 0.04, 1.2)
    }

    /// P is the derivative of W, and A the derivative of P, both checked by central differences.
    #[test]
    fn stress_and_tangent_match_finite_differences() {
        for m in [
            Material::NeoHookean {
                mu_pa: 3.0,
                lambda_pa: 20.0,
            },
            Material::NeoHookeanBulk {
                mu_pa: 3.0,
                kappa_pa: 20.0,
            },
        ] {
            let f = sample_f();
            let (_, p, a) = hyperelastic(&m, &f, true).unwrap();
            let a = a.unwrap();
            let h = 1e-6;
            for k in 0..3 {
                for l in 0..3 {
                    let mut fp = f;
                    fp[(k, l)] += h;
                    let mut fm = f;
                    fm[(k, l)] -= h;
                    let (wp, pp, _) = hyperelastic(&m, &fp, false).unwrap();
                    let (wm, pm, _) = hyperelastic(&m, &fm, false).unwrap();
                    assert!(
                        ((wp - wm) / (2.0 * h) - p[(k, l)]).abs() < 1e-6,
                        "{m:?} dW/dF"
                    );
                    let dp = (pp - pm) / (2.0 * h);
                    for i in 0..3 {
                        for j in 0..3 {
                            let e = a[(3 * i + j, 3 * k + l)];
                            assert!(
                                (dp[(i, j)] - e).abs() < 1e-5 * (1.0 + e.abs()),
                                "{m:?} A[{i}{j}{k}{l}]"
                            );
                        }
                    }
                }
            }
        }
    }

    /// At F = I both laws reduce to linear elasticity with the stated small-strain constants.
    #[test]
    fn tangent_at_rest_is_linear_elasticity() {
        for m in [
            Material::neo_hookean(1e6, 0.3),
            Material::neo_hookean_bulk(1e6, 0.3),
        ] {
            let (w, p, a) = hyperelastic(&m, &Matrix3::identity(), true).unwrap();
            assert!(w.abs() < 1e-9 && p.norm() < 1e-6);
            let (mu, lam) = m.small_strain_lame();
            let c = linear_tensor(mu, lam);
            // Compare on symmetric strains only: the linear tensor is symmetrised over minor indices.
            let e = Matrix3::new(0.01, 0.002, 0.0, 0.002, -0.003, 0.004, 0.0, 0.004, 0.005);
            let ev = SMatrix::<f64, 9, 1>::from_iterator((0..9).map(|r| e[(r / 3, r % 3)]));
            let s1 = a.unwrap() * ev;
            let s2 = c * ev;
            assert!((s1 - s2).norm() < 1e-6 * s2.norm(), "{m:?}");
        }
    }

    #[test]
    fn inverted_is_rejected() {
        let f = Matrix3::new(-1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0);
        assert!(hyperelastic(&Material::neo_hookean(1.0, 0.3), &f, true).is_none());
    }
}
