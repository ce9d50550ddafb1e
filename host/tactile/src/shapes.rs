//! Analytic indenter surfaces (sphere, cylinder) as closed triangle meshes, for verification
//! against Hertz and the flat punch and for tests without data files.

use crate::Result;
use crate::indenter::Indenter;

/// A sphere of radius `r_m` centred at (0, 0, r_m) (lowest point at the origin), from a
/// latitude-longitude mesh with `n` bands, refined towards the lowest pole where contact happens.
pub fn sphere(r_m: f64, n: usize) -> Result<Indenter> {
    let n = n.max(4);
    let seg = 2 * n;
    let mut pts = vec![[0.0, 0.0, 0.0]];
    // Polar angle from the bottom pole, graded quadratically so the contact cap is fine.
    let theta = |k: usize| std::f64::consts::PI * (k as f64 / n as f64).powf(1.5);
    for k in 1..n {
        let t = theta(k);
        for j in 0..seg {
            let phi = 2.0 * std::f64::consts::PI * j as f64 / seg as f64;
            pts.push([
                r_m * t.sin() * phi.cos(),
                r_m * t.sin() * phi.sin(),
                r_m * (1.0 - t.cos()),
            ]);
        }
    }
    pts.push([0.0, 0.0, 2.0 * r_m]);
    let top = pts.len() - 1;
    let ring = |k: usize, j: usize| 1 + (k - 1) * seg + j % seg;
    let mut tris = Vec::new();
    for j in 0..seg {
        tris.push([0, ring(1, j + 1), ring(1, j)]);
        tris.push([top, ring(n - 1, j), ring(n - 1, j + 1)]);
    }
    for k in 1..n - 1 {
        for j in 0..seg {
            let (a, b, c, d) = (
                ring(k, j),
                ring(k, j + 1),
                ring(k + 1, j),
                ring(k + 1, j + 1),
            );
            tris.push([a, b, d]);
            tris.push([a, d, c]);
        }
    }
    Indenter::from_triangles("sphere", pts, tris)
}

/// A flat-ended cylinder of radius `a_m` and height `h_m` standing on the origin (axis z), with
/// `seg` segments around.
pub fn cylinder(a_m: f64, h_m: f64, seg: usize) -> Result<Indenter> {
    let seg = seg.max(8);
    let mut pts = vec![[0.0, 0.0, 0.0], [0.0, 0.0, h_m]];
    for z in [0.0, h_m] {
        for j in 0..seg {
            let phi = 2.0 * std::f64::consts::PI * j as f64 / seg as f64;
            pts.push([a_m * phi.cos(), a_m * phi.sin(), z]);
        }
    }
    let lo = |j: usize| 2 + j % seg;
    let hi = |j: usize| 2 + seg + j % seg;
    let mut tris = Vec::new();
    for j in 0..seg {
        tris.push([0, lo(j + 1), lo(j)]);
        tris.push([1, hi(j), hi(j + 1)]);
        tris.push([lo(j), lo(j + 1), hi(j + 1)]);
        tris.push([lo(j), hi(j + 1), hi(j)]);
    }
    Indenter::from_triangles("cylinder", pts, tris)
}

/// A box [-a, a] x [-b, b] x [0, h], m.
pub fn block(a_m: f64, b_m: f64, h_m: f64) -> Result<Indenter> {
    let mut pts = Vec::new();
    for k in 0..8 {
        pts.push([
            if k & 1 == 0 { -a_m } else { a_m },
            if k & 2 == 0 { -b_m } else { b_m },
            if k & 4 == 0 { 0.0 } else { h_m },
        ]);
    }
    let quads = [
        [0, 2, 3, 1],
        [4, 5, 7, 6],
        [0, 1, 5, 4],
        [2, 6, 7, 3],
        [0, 4, 6, 2],
        [1, 3, 7, 5],
    ];
    let tris = quads
        .iter()
        .flat_map(|q| [[q[0], q[1], q[2]], [q[0], q[2], q[3]]])
        .collect();
    Indenter::from_triangles("block", pts, tris)
}

/// The quarter block [0, l]^2 x [0, h] of the verification tests: `n`^3 hexes (as tets) graded
/// towards the contact corner (0, 0, h) by x = l (f s + (1 - f) s^4) per axis (f = `fine`),
/// symmetry rollers on x = 0 and y = 0 and a roller base, of modulus `young_pa` and Poisson's
/// ratio `poisson`.
pub fn quarter_block(
    n: usize,
    l_m: f64,
    h_m: f64,
    fine: f64,
    young_pa: f64,
    poisson: f64,
) -> Result<crate::gel::Gel> {
    let g = |s: f64| fine * s + (1.0 - fine) * s.powi(4);
    let mesh = ocm_fem::mesh::generate::mapped_block([n, n, n], |u| {
        [l_m * g(u[0]), l_m * g(u[1]), h_m * (1.0 - g(1.0 - u[2]))]
    });
    let tol = 1e-12;
    crate::gel::Gel::with_constraints(mesh, crate::gel::GelMaterial { young_pa, poisson }, |p| {
        [p.x < tol, p.y < tol, p.z < tol]
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::Vector3;

    /// Enclosed volumes against the analytic ones; signed distances of the sphere against
    /// |x - c| - r (up to the faceting).
    #[test]
    fn volumes_and_distances() {
        let r = 2e-3;
        let s = sphere(r, 40).unwrap();
        let v = 4.0 / 3.0 * std::f64::consts::PI * r.powi(3);
        assert!((s.volume() - v).abs() < 0.01 * v);
        for p in [
            Vector3::new(0.0, 0.0, -0.1e-3),
            Vector3::new(0.3e-3, 0.1e-3, 0.05e-3),
            Vector3::new(0.0, 0.0, 0.2e-3),
            Vector3::new(3e-3, 0.0, 2e-3),
        ] {
            let q = s.query_local(&p);
            let exact = (p - Vector3::new(0.0, 0.0, r)).norm() - r;
            assert!(
                (q.distance - exact).abs() < 2e-6,
                "{p:?}: {} vs {exact}",
                q.distance
            );
            let n = (p - Vector3::new(0.0, 0.0, r)).normalize();
            assert!(q.normal.dot(&n) > 0.99, "{p:?}");
        }
        let c = cylinder(1e-3, 2e-3, 64).unwrap();
        let vc = std::f64::consts::PI * 1e-6 * 2e-3;
        assert!((c.volume() - vc).abs() < 0.01 * vc);
        let q = c.query_local(&Vector3::new(0.2e-3, 0.0, 0.01e-3));
        assert!((q.distance + 0.01e-3).abs() < 1e-12 && (q.normal.z + 1.0).abs() < 1e-9);
        let b = block(1e-3, 2e-3, 1e-3).unwrap();
        assert!((b.volume() - 8e-9).abs() < 1e-20);
    }

    /// An open surface is refused with an error that says so.
    #[test]
    fn open_surface_is_an_error() {
        let pts = vec![
            [0.0, 0.0, 0.0],
            [1.0, 0.0, 0.0],
            [0.0, 1.0, 0.0],
            [0.0, 0.0, 1.0],
        ];
        let tris = vec![[0, 2, 1], [0, 1, 3], [0, 3, 2]];
        let e = Indenter::from_triangles("cap", pts, tris)
            .unwrap_err()
            .to_string();
        assert!(e.contains("cap") && e.contains("not closed"), "{e}");
    }
}
