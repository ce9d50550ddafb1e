//! Linear tetrahedron: reference geometry, internal force, tangent stiffness and energy.

use crate::material::{Material, hyperelastic, linear_tensor};
use crate::{FemError, Result};
use nalgebra::{Matrix3, SMatrix, SVector, Vector3};

/// 12-vector of nodal forces of one tet.
pub type Vec12 = SVector<f64, 12>;
/// 12x12 element stiffness.
pub type Mat12 = SMatrix<f64, 12, 12>;

/// Reference data of one tetrahedron.
#[derive(Debug, Clone)]
pub struct TetGeom {
    /// Node indices.
    pub nodes: [usize; 4],
    /// Rest volume, m^3 (positive).
    pub volume: f64,
    /// Inverse of the rest edge matrix [X1-X0, X2-X0, X3-X0].
    pub dm_inv: Matrix3<f64>,
    /// Shape-function gradients dN_a/dX (rows of the B operator).
    pub grad: [Vector3<f64>; 4],
    /// Rest positions of the four nodes (for the corotational frame).
    pub rest: [Vector3<f64>; 4],
}

impl TetGeom {
    /// Builds the reference data; fails on a degenerate or inverted rest tet.
    pub fn new(index: usize, nodes: [usize; 4], x: &[Vector3<f64>]) -> Result<Self> {
        let rest = nodes.map(|i| x[i]);
        let dm = Matrix3::from_columns(&[rest[1] - rest[0], rest[2] - rest[0], rest[3] - rest[0]]);
        let det = dm.determinant();
        let scale = (rest[1] - rest[0])
            .norm()
            .max((rest[2] - rest[0]).norm())
            .max((rest[3] - rest[0]).norm());
        if !(det > 1e-12 * scale.powi(3)) {
            return Err(FemError::Model(format!(
                "tet {index} is degenerate or inverted at rest (6V = {det:.3e}); orient tets first"
            )));
        }
        let dm_inv = dm
            .try_inverse()
            .ok_or_else(|| FemError::Model(format!("tet {index} is singular")))?;
        let r = |k: usize| Vector3::new(dm_inv[(k, 0)], dm_inv[(k, 1)], dm_inv[(k, 2)]);
        let (g1, g2, g3) = (r(0), r(1), r(2));
        Ok(TetGeom {
            nodes,
            volume: det / 6.0,
            dm_inv,
            grad: [-(g1 + g2 + g3), g1, g2, g3],
            rest,
        })
    }

    /// Deformation gradient at current positions.
    pub fn deformation_gradient(&self, x: &[Vector3<f64>]) -> Matrix3<f64> {
        let p = self.nodes.map(|i| x[i]);
        Matrix3::from_columns(&[p[1] - p[0], p[2] - p[0], p[3] - p[0]]) * self.dm_inv
    }

    /// Small-strain stiffness K0 = V B^T C B.
    pub fn linear_stiffness(&self, mu: f64, lambda: f64) -> Mat12 {
        contract(&linear_tensor(mu, lambda), &self.grad, self.volume)
    }
}

/// K_ab[i][k] = V sum_jl A(3i+j, 3k+l) G_a[j] G_b[l].
fn contract(a: &SMatrix<f64, 9, 9>, g: &[Vector3<f64>; 4], vol: f64) -> Mat12 {
    let mut k = Mat12::zeros();
    for na in 0..4 {
        // m[i][(k,l)] = sum_j A(3i+j,3k+l) G_a[j]
        let mut m = [[0.0; 9]; 3];
        for (i, mi) in m.iter_mut().enumerate() {
            for (c, mic) in mi.iter_mut().enumerate() {
                *mic = (0..3).map(|j| a[(3 * i + j, c)] * g[na][j]).sum();
            }
        }
        for nb in 0..4 {
            for i in 0..3 {
                for kk in 0..3 {
                    let v: f64 = (0..3).map(|l| m[i][3 * kk + l] * g[nb][l]).sum();
                    k[(3 * na + i, 3 * nb + kk)] = vol * v;
                }
            }
        }
    }
    k
}

/// What one element contributes at a configuration.
#[derive(Debug, Clone)]
pub struct ElementEval {
    /// Strain energy, J.
    pub energy: f64,
    /// Internal force dE/dx, N.
    pub force: Vec12,
    /// Tangent stiffness (when asked for).
    pub stiffness: Option<Mat12>,
    /// Volume ratio J = det F.
    pub jacobian: f64,
}

/// Polar rotation of F (closest rotation), via SVD with the reflection removed.
pub fn polar_rotation(f: &Matrix3<f64>) -> Matrix3<f64> {
    let svd = f.svd(true, true);
    let (Some(u), Some(vt)) = (svd.u, svd.v_t) else {
        return Matrix3::identity();
    };
    let mut r = u * vt;
    if r.determinant() < 0.0 {
        let mut u2 = u;
        // Flip the column belonging to the smallest singular value.
        let (kmin, _) =
            svd.singular_values
                .iter()
                .enumerate()
                .fold(
                    (0, f64::INFINITY),
                    |b, (k, &s)| if s < b.1 { (k, s) } else { b },
                );
        u2.column_mut(kmin).neg_mut();
        r = u2 * vt;
    }
    r
}

/// Evaluates element `e` at positions `x` (`k0` is its precomputed small-strain stiffness for corotational laws).
pub fn evaluate(
    index: usize,
    geom: &TetGeom,
    mat: &Material,
    k0: Option<&Mat12>,
    scale: f64,
    x: &[Vector3<f64>],
    want_tangent: bool,
) -> Result<ElementEval> {
    let f = geom.deformation_gradient(x);
    let jac = f.determinant();
    if !(jac > 0.0) {
        return Err(FemError::Inverted {
            element: index,
            jacobian: jac,
        });
    }
    match mat {
        Material::Corotational { .. } => {
            let k0 = k0.ok_or_else(|| FemError::Model("corotational element without K0".into()))?;
            let r = polar_rotation(&f);
            let mut u = Vec12::zeros();
            for a in 0..4 {
                let ul = r.transpose() * x[geom.nodes[a]] - geom.rest[a];
                u.fixed_rows_mut::<3>(3 * a).copy_from(&ul);
            }
            let fl = k0 * u;
            let energy = 0.5 * u.dot(&fl) * scale;
            let mut force = Vec12::zeros();
            for a in 0..4 {
                force
                    .fixed_rows_mut::<3>(3 * a)
                    .copy_from(&(r * fl.fixed_rows::<3>(3 * a) * scale));
            }
            // Forces are SOFA's. The tangent adds the variation of the polar rotation that SOFA's
            // R K0 R^T neglects, so Newton converges quadratically. With F = R S and Omega = R^T dR,
            // skew(R^T dF) = [(tr S I - S) omega]x / 2 gives omega for each nodal direction.
            let stiffness = want_tangent.then(|| {
                let s_mat = r.transpose() * f;
                let minv = (Matrix3::identity() * s_mat.trace() - s_mat).try_inverse();
                let mut k = Mat12::zeros();
                let rtx: [Vector3<f64>; 4] =
                    std::array::from_fn(|b| r.transpose() * x[geom.nodes[b]]);
                for col in 0..12 {
                    let (b, kk) = (col / 3, col % 3);
                    let mut du = Vec12::zeros();
                    let mut omega_m = Matrix3::zeros();
                    if let Some(minv) = minv {
                        let mut df = Matrix3::zeros();
                        df.set_row(kk, &geom.grad[b].transpose());
                        let m = r.transpose() * df;
                        let w = Vector3::new(
                            m[(2, 1)] - m[(1, 2)],
                            m[(0, 2)] - m[(2, 0)],
                            m[(1, 0)] - m[(0, 1)],
                        ) * 0.5;
                        omega_m = crate::rigid::skew(&(2.0 * minv * w));
                    }
                    for c in 0..4 {
                        let mut v = -(omega_m * rtx[c]);
                        if c == b {
                            v += r.transpose().column(kk);
                        }
                        du.fixed_rows_mut::<3>(3 * c).copy_from(&v);
                    }
                    let dfl = k0 * du;
                    for a in 0..4 {
                        let fa = fl.fixed_rows::<3>(3 * a).into_owned();
                        let dfa = r * (omega_m * fa + dfl.fixed_rows::<3>(3 * a));
                        for i in 0..3 {
                            k[(3 * a + i, col)] = dfa[i] * scale;
                        }
                    }
                }
                k
            });
            Ok(ElementEval {
                energy,
                force,
                stiffness,
                jacobian: jac,
            })
        }
        _ => {
            let (w, p, a) = hyperelastic(mat, &f, want_tangent).ok_or(FemError::Inverted {
                element: index,
                jacobian: jac,
            })?;
            let mut force = Vec12::zeros();
            for n in 0..4 {
                force
                    .fixed_rows_mut::<3>(3 * n)
                    .copy_from(&(p * geom.grad[n] * (geom.volume * scale)));
            }
            Ok(ElementEval {
                energy: w * geom.volume * scale,
                force,
                stiffness: a.map(|a| contract(&a, &geom.grad, geom.volume * scale)),
                jacobian: jac,
            })
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn tet() -> (Vec<Vector3<f64>>, TetGeom) {
        let x = vec![
            Vector3::new(0.0, 0.0, 0.0),
            Vector3::new(1.0, 0.1, 0.0),
            Vector3::new(0.2, 1.0, 0.1),
            Vector3::new(0.1, 0.2, 0.9),
        ];
        let g = TetGeom::new(0, [0, 1, 2, 3], &x).unwrap();
        (x, g)
    }

    fn deformed(x: &[Vector3<f64>]) -> Vec<Vector3<f64>> {
        let f = Matrix3::new(1.05, 0.1, 0.0, -0.02, 0.95, 0.07, 0.03, 0.0, 1.1);
        x.iter()
            .map(|p| f * p + Vector3::new(0.3, -0.1, 0.2))
            .collect()
    }

    /// Element force is the gradient of element energy, and the tangent the Jacobian of the force.
    #[test]
    fn hyperelastic_element_force_and_tangent_match_fd() {
        let (x, g) = tet();
        let y = deformed(&x);
        for m in [
            Material::neo_hookean(1e3, 0.3),
            Material::neo_hookean_bulk(1e3, 0.45),
        ] {
            let e = evaluate(0, &g, &m, None, 1.0, &y, true).unwrap();
            let k = e.stiffness.unwrap();
            let h = 1e-6;
            for d in 0..12 {
                let mut yp = y.clone();
                yp[d / 3][d % 3] += h;
                let mut ym = y.clone();
                ym[d / 3][d % 3] -= h;
                let ep = evaluate(0, &g, &m, None, 1.0, &yp, false).unwrap();
                let em = evaluate(0, &g, &m, None, 1.0, &ym, false).unwrap();
                assert!(
                    ((ep.energy - em.energy) / (2.0 * h) - e.force[d]).abs()
                        < 1e-5 * (1.0 + e.force[d].abs())
                );
                let col = (ep.force - em.force) / (2.0 * h);
                assert!(
                    (col - k.column(d)).norm() < 1e-5 * (1.0 + k.norm()),
                    "{m:?} column {d}"
                );
            }
        }
    }

    /// A rigid rotation produces no force; near it the tangent R K0 R^T is the exact Jacobian.
    #[test]
    fn corotational_is_rotation_invariant_and_tangent_exact_at_zero_stress() {
        let (x, g) = tet();
        let m = Material::corotational(1e3, 0.3);
        let (mu, lam) = m.small_strain_lame();
        let k0 = g.linear_stiffness(mu, lam);
        let rot = nalgebra::Rotation3::from_euler_angles(0.7, -0.4, 1.2).into_inner();
        let y: Vec<_> = x
            .iter()
            .map(|p| rot * p + Vector3::new(1.0, 2.0, 3.0))
            .collect();
        let e = evaluate(0, &g, &m, Some(&k0), 1.0, &y, true).unwrap();
        assert!(e.force.norm() < 1e-9 && e.energy.abs() < 1e-12);
        let k = e.stiffness.unwrap();
        let h = 1e-7;
        for d in 0..12 {
            let mut yp = y.clone();
            yp[d / 3][d % 3] += h;
            let mut ym = y.clone();
            ym[d / 3][d % 3] -= h;
            let fp = evaluate(0, &g, &m, Some(&k0), 1.0, &yp, false)
                .unwrap()
                .force;
            let fm = evaluate(0, &g, &m, Some(&k0), 1.0, &ym, false)
                .unwrap()
                .force;
            assert!(((fp - fm) / (2.0 * h) - k.column(d)).norm() < 1e-5 * k.norm());
        }
    }

    /// Under large rotation and finite strain the corotational tangent is the exact force Jacobian.
    #[test]
    fn corotational_tangent_matches_fd_when_stressed() {
        let (x, g) = tet();
        let m = Material::corotational(1e3, 0.3);
        let (mu, lam) = m.small_strain_lame();
        let k0 = g.linear_stiffness(mu, lam);
        let rot = nalgebra::Rotation3::from_euler_angles(0.3, 0.9, -0.6).into_inner();
        let y: Vec<_> = deformed(&x).iter().map(|p| rot * p).collect();
        let e = evaluate(0, &g, &m, Some(&k0), 2.0, &y, true).unwrap();
        let k = e.stiffness.unwrap();
        assert!(
            (k - k.transpose()).norm() < 1e-8 * k.norm(),
            "conservative: symmetric tangent"
        );
        let h = 1e-6;
        for d in 0..12 {
            let mut yp = y.clone();
            yp[d / 3][d % 3] += h;
            let mut ym = y.clone();
            ym[d / 3][d % 3] -= h;
            let ep = evaluate(0, &g, &m, Some(&k0), 2.0, &yp, false).unwrap();
            let em = evaluate(0, &g, &m, Some(&k0), 2.0, &ym, false).unwrap();
            assert!(
                ((ep.energy - em.energy) / (2.0 * h) - e.force[d]).abs() < 1e-5 * e.force.norm()
            );
            assert!(
                ((ep.force - em.force) / (2.0 * h) - k.column(d)).norm() < 1e-5 * k.norm(),
                "column {d}"
            );
        }
    }

    /// Small strains: corotational, both Neo-Hookeans and K0 agree to first order.
    #[test]
    fn laws_agree_at_small_strain() {
        let (x, g) = tet();
        let eps = 1e-6;
        let y: Vec<_> = x
            .iter()
            .map(|p| p + eps * Vector3::new(p.y + 0.3 * p.z, 0.5 * p.x, -p.z))
            .collect();
        let (mu, lam) = crate::material::lame(1e3, 0.3);
        let k0 = g.linear_stiffness(mu, lam);
        let mut u = Vec12::zeros();
        for a in 0..4 {
            u.fixed_rows_mut::<3>(3 * a).copy_from(&(y[a] - x[a]));
        }
        let lin = k0 * u;
        for m in [
            Material::corotational(1e3, 0.3),
            Material::neo_hookean(1e3, 0.3),
            Material::neo_hookean_bulk(1e3, 0.3),
        ] {
            let f = evaluate(0, &g, &m, Some(&k0), 1.0, &y, false)
                .unwrap()
                .force;
            assert!((f - lin).norm() < 1e-4 * lin.norm(), "{m:?}");
        }
    }

    #[test]
    fn inversion_is_reported() {
        let (x, g) = tet();
        let mut y = x.clone();
        y[3].z = -0.5;
        let e = evaluate(0, &g, &Material::neo_hookean(1.0, 0.3), None, 1.0, &y, true).unwrap_err();
        assert!(matches!(e, FemError::Inverted { element: 0, .. }));
    }
}
