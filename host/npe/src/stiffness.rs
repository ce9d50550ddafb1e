//! The total contact force read from a displacement field of the top face (Table 6.1 scores
//! "the total contact force estimated from the predicted nodal deformation"): a smooth
//! stiffness functional `F = sum_v k(x_v, y_v) (-u_z,v) + k2(x_v, y_v) u_z,v^2`, with `k` and
//! `k2` polynomials over the face, fitted by least squares on FEM fields of training set-ups.
//!
//! Why a fitted functional and not the FEM's condensed stiffness: the gel is hyperelastic and
//! indented to a quarter of its thickness, so the rest tangent alone underestimates the force
//! of deep indents; the quadratic term carries that stiffening. The polynomial keeps the
//! unknowns few (the training set has hundreds of samples, the face 2,552 nodes).

use nalgebra::{DMatrix, DVector};
use serde::{Deserialize, Serialize};

use crate::{NpeError, Result};

/// Displacement unit of the features, m (the features are sums of millimetres).
const U_UNIT_M: f64 = 1e-3;

/// A fitted force-from-displacement functional of the top face.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ForceFromDisplacement {
    /// Total degree of the polynomials in x and y.
    pub degree: usize,
    /// Centre of the face (x, y), m, and half its extent, m: the polynomials' [-1, 1] square.
    pub frame_m: [[f64; 2]; 2],
    /// Coefficients: the linear term's monomials, then the quadratic term's.
    pub coef: Vec<f64>,
}

fn monomials(degree: usize, x: f64, y: f64, out: &mut Vec<f64>) {
    for total in 0..=degree {
        for i in 0..=total {
            out.push(x.powi(i as i32) * y.powi((total - i) as i32));
        }
    }
}

/// The basis of each node, `[node][monomial]`, for the face `rest_m` (frame from its outline).
fn basis(degree: usize, rest_m: &[[f64; 3]]) -> ([[f64; 2]; 2], Vec<Vec<f64>>) {
    let mut lo = [f64::INFINITY; 2];
    let mut hi = [f64::NEG_INFINITY; 2];
    for p in rest_m {
        for k in 0..2 {
            lo[k] = lo[k].min(p[k]);
            hi[k] = hi[k].max(p[k]);
        }
    }
    let c = [0.5 * (lo[0] + hi[0]), 0.5 * (lo[1] + hi[1])];
    let h = [
        (0.5 * (hi[0] - lo[0])).max(1e-9),
        (0.5 * (hi[1] - lo[1])).max(1e-9),
    ];
    let b = rest_m
        .iter()
        .map(|p| {
            let mut v = Vec::new();
            monomials(degree, (p[0] - c[0]) / h[0], (p[1] - c[1]) / h[1], &mut v);
            v
        })
        .collect();
    ([c, h], b)
}

fn features(basis: &[Vec<f64>], u_m: &[[f64; 3]]) -> Vec<f64> {
    let k = basis.first().map_or(0, Vec::len);
    let mut f = vec![0.0; 2 * k];
    for (b, u) in basis.iter().zip(u_m) {
        let d = -u[2] / U_UNIT_M;
        for (j, &bj) in b.iter().enumerate() {
            f[j] += bj * d;
            f[k + j] += bj * d * d;
        }
    }
    f
}

impl ForceFromDisplacement {
    /// Fits the functional to `(displacement of every top node, total normal force on the
    /// body in N)` pairs on the face `rest_m`, by least squares with a small ridge.
    pub fn fit<'a>(
        degree: usize,
        rest_m: &[[f64; 3]],
        samples: impl IntoIterator<Item = (&'a [[f64; 3]], f64)>,
    ) -> Result<Self> {
        let (frame_m, b) = basis(degree, rest_m);
        let mut rows = Vec::new();
        let mut rhs = Vec::new();
        for (u, f) in samples {
            if u.len() != rest_m.len() || !f.is_finite() {
                return Err(NpeError::Input(format!(
                    "stiffness fit: a sample has {} nodes (face {}) or force {f}",
                    u.len(),
                    rest_m.len()
                )));
            }
            rows.push(features(&b, u));
            rhs.push(f);
        }
        let m = rows.first().map_or(0, Vec::len);
        if rows.len() < m {
            return Err(NpeError::Data(format!(
                "stiffness fit: {} samples for {m} coefficients",
                rows.len()
            )));
        }
        let a = DMatrix::from_fn(rows.len(), m, |i, j| rows[i][j]);
        // Columns scaled to unit norm, then a ridge of 1e-8 on the normal equations: the
        // monomials of a square face are nearly collinear at degree 4 and above.
        let norms: Vec<f64> = (0..m).map(|j| a.column(j).norm().max(1e-300)).collect();
        let an = DMatrix::from_fn(rows.len(), m, |i, j| a[(i, j)] / norms[j]);
        let mut ata = an.transpose() * &an;
        for j in 0..m {
            ata[(j, j)] += 1e-8;
        }
        let atb = an.transpose() * DVector::from_vec(rhs);
        let x = ata
            .cholesky()
            .ok_or_else(|| NpeError::Data("stiffness fit: singular normal equations".into()))?
            .solve(&atb);
        Ok(ForceFromDisplacement {
            degree,
            frame_m,
            coef: (0..m).map(|j| x[j] / norms[j]).collect(),
        })
    }

    /// Total normal force on the body, N, from the displacement `u_m` of the face `rest_m`.
    pub fn force_n(&self, rest_m: &[[f64; 3]], u_m: &[[f64; 3]]) -> f64 {
        let c = self.frame_m[0];
        let h = self.frame_m[1];
        let mut b = Vec::new();
        let mut total = 0.0;
        let k = self.coef.len() / 2;
        for (p, u) in rest_m.iter().zip(u_m) {
            b.clear();
            monomials(
                self.degree,
                (p[0] - c[0]) / h[0],
                (p[1] - c[1]) / h[1],
                &mut b,
            );
            let d = -u[2] / U_UNIT_M;
            for (j, &bj) in b.iter().enumerate().take(k) {
                total += bj * (self.coef[j] * d + self.coef[k + j] * d * d);
            }
        }
        total
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A functional with known coefficients is recovered from fields it generated, and the
    /// fitted one predicts a field it never saw; too few samples are an error.
    #[test]
    fn recovers_a_known_functional() {
        let rest: Vec<[f64; 3]> = (0..100)
            .map(|i| [f64::from(i % 10) * 1e-3, f64::from(i / 10) * 2e-3, 0.0])
            .collect();
        let (_, b) = basis(1, &rest);
        // Linear term k = 2 + 0.5 y - 0.3 x (monomial order 1, x^0 y^1, x^1 y^0), quadratic 4.
        let truth = [2.0, 0.5, -0.3, 4.0, 0.0, 0.0];
        let field = |s: usize| -> Vec<[f64; 3]> {
            (0..rest.len())
                .map(|v| {
                    let bump = ((v * 7 + s * 13) % 17) as f64 / 17.0;
                    [0.0, 0.0, -1e-4 * (1.0 + bump * (s % 5) as f64)]
                })
                .collect()
        };
        let force = |u: &[[f64; 3]]| -> f64 {
            let f = features(&b, u);
            f.iter().zip(truth).map(|(a, c)| a * c).sum()
        };
        let samples: Vec<(Vec<[f64; 3]>, f64)> = (0..20)
            .map(|s| {
                let u = field(s);
                let f = force(&u);
                (u, f)
            })
            .collect();
        let k =
            ForceFromDisplacement::fit(1, &rest, samples.iter().map(|(u, f)| (u.as_slice(), *f)))
                .unwrap();
        for (c, t) in k.coef.iter().zip(truth) {
            assert!((c - t).abs() < 1e-4, "coefficient {c} against {t}");
        }
        let u = field(37);
        assert!((k.force_n(&rest, &u) - force(&u)).abs() < 1e-4 * force(&u).abs());
        assert!(
            ForceFromDisplacement::fit(
                1,
                &rest,
                samples[..3].iter().map(|(u, f)| (u.as_slice(), *f))
            )
            .is_err()
        );
    }
}
