//! Analytic indenter surfaces (sphere, cylinder) as closed triangle meshes, for verification
//! against Hertz and the flat punch and for tests without data files.

use crate::Result;
use crate::indenter::Indenter;

/// A sphere of radius `r_m` centred at (0, 0, r_m) (lowest point at the origin), from a
/// latitude-longitude mesh with `n` bands, refined towards the lowest pole where contact happens.
pub fn sphere(r_m: f64, n: usize) -> Result<Indenter> {
    let (pts, tris) = sphere_surface(r_m, n);
    Indenter::from_triangles("sphere", pts, tris)
}

/// The closed triangle surface of [`sphere`]: points (m) and outward-wound triangles (to write
/// an STL of it).
pub fn sphere_surface(r_m: f64, n: usize) -> (Vec<[f64; 3]>, Vec<[usize; 3]>) {
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
    (pts, tris)
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

/// The faces of a box whose corner k sits at (x_k, y_k, z_k) = bits 0, 1, 2 of k, each wound
/// outward.
const BOX_QUADS: [[usize; 4]; 6] = [
    [0, 2, 3, 1],
    [4, 5, 7, 6],
    [0, 1, 5, 4],
    [2, 6, 7, 3],
    [0, 4, 6, 2],
    [1, 3, 7, 5],
];

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
    let tris = BOX_QUADS
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
    crate::gel::Gel::with_constraints(mesh, crate::gel::GelMaterial::new(young_pa, poisson), |p| {
        [p.x < tol, p.y < tol, p.z < tol]
    })
}

/// The quarter block [0, l]^3 refined around the contact corner (0, 0, l) by cube shells: a
/// uniform core cube of side `core_m` with `m` hexes per edge, then `layers` shells, each the
/// previous one scaled about the corner by a constant ratio (core_m to l). Every shell keeps
/// m x m hexes per face, so the element size grows in proportion to the distance from the
/// corner: a contact of radius a between core_m and l meets elements of about a / m whatever
/// its size, which a tensor-product grading cannot do at the same cost. Symmetry rollers on
/// x = 0 and y = 0 and a roller base, as [`quarter_block`].
pub fn shell_quarter_block(
    m: usize,
    layers: usize,
    core_m: f64,
    l_m: f64,
    young_pa: f64,
    poisson: f64,
) -> Result<crate::gel::Gel> {
    if m == 0 || layers == 0 || !(core_m > 0.0 && core_m < l_m && l_m.is_finite()) {
        return Err(crate::TactileError::Input(format!(
            "shell block needs m >= 1, layers >= 1 and 0 < core < l (got m {m}, layers {layers}, \
             core {core_m} m, l {l_m} m)"
        )));
    }
    let ratio = (l_m / core_m).powf(1.0 / layers as f64);
    let scale = |t: usize| {
        if t == layers {
            l_m / core_m
        } else {
            ratio.powi(t as i32)
        }
    };
    let mf = m as f64;
    let mut b = BlockMesher::new(l_m * 1e-9);
    // Corner frame (xi, eta, zeta) = (x, y, l - z): the contact corner at its origin.
    let place = |v: [f64; 3]| [v[0], v[1], l_m - v[2]];
    b.add([m, m, m], |[i, j, k]| {
        place([i as f64, j as f64, k as f64].map(|c| c / mf * core_m))
    });
    // The three shell stacks; their index axes run the same way on every shared face, so the
    // six-tet split of the hexes conforms across them.
    b.add([layers, m, m], |[t, j, k]| {
        let s = scale(t) * core_m;
        place([s, s * j as f64 / mf, s * k as f64 / mf])
    });
    b.add([m, layers, m], |[i, t, k]| {
        let s = scale(t) * core_m;
        place([s * i as f64 / mf, s, s * k as f64 / mf])
    });
    b.add([m, m, layers], |[i, j, t]| {
        let s = scale(t) * core_m;
        place([s * i as f64 / mf, s * j as f64 / mf, s])
    });
    let tol = 1e-12;
    crate::gel::Gel::with_constraints(
        b.mesh,
        crate::gel::GelMaterial::new(young_pa, poisson),
        |p| [p.x < tol, p.y < tol, p.z < tol],
    )
}

/// Structured hex blocks split into six tets each, merged where their nodes coincide.
struct BlockMesher {
    mesh: ocm_fem::mesh::Mesh,
    ids: std::collections::HashMap<[i64; 3], usize>,
    quantum: f64,
}

impl BlockMesher {
    fn new(quantum: f64) -> Self {
        BlockMesher {
            mesh: ocm_fem::mesh::Mesh::default(),
            ids: std::collections::HashMap::new(),
            quantum,
        }
    }

    /// Adds an n[0] x n[1] x n[2] hex block whose node (i, j, k) lies at `pos([i, j, k])`.
    fn add(&mut self, n: [usize; 3], pos: impl Fn([usize; 3]) -> [f64; 3]) {
        let [nx, ny, nz] = n;
        let local = |i: usize, j: usize, k: usize| (k * (ny + 1) + j) * (nx + 1) + i;
        let mut global = vec![0; (nx + 1) * (ny + 1) * (nz + 1)];
        for k in 0..=nz {
            for j in 0..=ny {
                for i in 0..=nx {
                    let p = pos([i, j, k]);
                    let key = p.map(|c| (c / self.quantum).round() as i64);
                    let next = self.mesh.points.len();
                    let id = *self.ids.entry(key).or_insert(next);
                    if id == next {
                        self.mesh.points.push(p);
                    }
                    global[local(i, j, k)] = id;
                }
            }
        }
        let perms = [
            [0, 1, 2],
            [0, 2, 1],
            [1, 0, 2],
            [1, 2, 0],
            [2, 0, 1],
            [2, 1, 0],
        ];
        for k in 0..nz {
            for j in 0..ny {
                for i in 0..nx {
                    for p in perms {
                        let mut c = [i, j, k];
                        let mut t = [global[local(i, j, k)]; 4];
                        for (s, &ax) in p.iter().enumerate() {
                            c[ax] += 1;
                            t[s + 1] = global[local(c[0], c[1], c[2])];
                        }
                        self.mesh.tets.push(t);
                    }
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::Vector3;

    /// The shell-graded block fills [0, l]^3 exactly with a closed, conforming boundary (a
    /// non-conforming split between the stacks would leave interior faces on the boundary),
    /// and its elements grow with the distance from the contact corner.
    #[test]
    fn shell_block_is_conforming_and_graded() {
        let (m, layers, core, l) = (4, 6, 0.5e-3, 8e-3);
        let gel = shell_quarter_block(m, layers, core, l, 1e5, 0.3).unwrap();
        let mesh = &gel.mesh;
        let v: f64 = (0..mesh.tets.len()).map(|t| mesh.tet_volume(t)).sum();
        assert!((v - l.powi(3)).abs() < 1e-9 * l.powi(3), "volume {v}");
        assert!((0..mesh.tets.len()).all(|t| mesh.tet_volume(t) > 0.0));
        let b = ocm_fem::mesh::surface::boundary_faces(&mesh.points, &mesh.tets);
        assert_eq!(ocm_fem::mesh::surface::open_edges(&b), 0);
        let area: f64 = b
            .iter()
            .map(|t| {
                let p = t.map(|i| Vector3::from(mesh.points[i]));
                0.5 * (p[1] - p[0]).cross(&(p[2] - p[0])).norm()
            })
            .sum();
        assert!((area - 6.0 * l * l).abs() < 1e-9 * l * l, "area {area}");
        assert_eq!(
            mesh.points.len(),
            (m + 1).pow(3) + 3 * layers * (m + 1) * (m + 1) - 3 * layers * (m + 1) + layers
        );
        // Node spacing along the top edge y = 0, z = l: core / m at the corner, then growing.
        let mut xs: Vec<f64> = mesh
            .points
            .iter()
            .filter(|p| p[1].abs() < 1e-12 && (p[2] - l).abs() < 1e-12)
            .map(|p| p[0])
            .collect();
        xs.sort_by(f64::total_cmp);
        assert_eq!(xs.len(), m + layers + 1);
        let dx: Vec<f64> = xs.windows(2).map(|w| w[1] - w[0]).collect();
        assert!((dx[0] - core / m as f64).abs() < 1e-15);
        assert!(dx.windows(2).all(|w| w[1] >= w[0] - 1e-15));
        assert!(dx[dx.len() - 1] > 10.0 * dx[0]);
        assert!(shell_quarter_block(0, 3, core, l, 1e5, 0.3).is_err());
        assert!(shell_quarter_block(4, 3, l, l, 1e5, 0.3).is_err());
    }

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

    /// Two cubes that share one edge: the edge is the surface's one self-touching edge, and the
    /// nearest point on it is found for points beside it and beyond its end.
    #[test]
    fn cubes_sharing_an_edge_touch_there() {
        let mm = 1e-3;
        let mut pts: Vec<[f64; 3]> = Vec::new();
        let mut index = |p: [f64; 3]| {
            pts.iter().position(|q| *q == p).unwrap_or_else(|| {
                pts.push(p);
                pts.len() - 1
            })
        };
        let mut tris = Vec::new();
        for origin in [[0.0, 0.0], [1.0, 1.0]] {
            let corner: Vec<usize> = (0..8)
                .map(|k| {
                    index([
                        (origin[0] + f64::from(k & 1)) * mm,
                        (origin[1] + f64::from((k >> 1) & 1)) * mm,
                        f64::from((k >> 2) & 1) * mm,
                    ])
                })
                .collect();
            for q in BOX_QUADS {
                let c = q.map(|i| corner[i]);
                tris.push([c[0], c[1], c[2]]);
                tris.push([c[0], c[2], c[3]]);
            }
        }
        assert_eq!(pts.len(), 14, "the cubes share two corners");
        let two = Indenter::from_triangles("two cubes", pts, tris).unwrap();
        assert!((two.volume() - 2e-9).abs() < 1e-21);
        assert_eq!(two.pinch_edges.len(), 1);
        let (d, c) = two
            .nearest_pinch_local(&Vector3::new(1.2 * mm, 0.9 * mm, 0.5 * mm))
            .unwrap();
        assert!((d - 0.05f64.sqrt() * mm).abs() < 1e-12, "{d}");
        assert!((c - Vector3::new(mm, mm, 0.5 * mm)).norm() < 1e-12, "{c:?}");
        let (d, c) = two
            .nearest_pinch_local(&Vector3::new(mm, mm, 1.5 * mm))
            .unwrap();
        assert!(
            (d - 0.5 * mm).abs() < 1e-12 && (c.z - mm).abs() < 1e-12,
            "{d} {c:?}"
        );
        let one = block(1e-3, 2e-3, 1e-3).unwrap();
        assert!(one.pinch_edges.is_empty());
        assert!(one.nearest_pinch_local(&Vector3::zeros()).is_none());
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
