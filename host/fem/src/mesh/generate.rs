//! Structured tet meshes for verification: boxes and mapped (e.g. cylindrical) blocks.

use super::Mesh;

/// Box `[0,lx]x[0,ly]x[0,lz]` with nx*ny*nz hexes, each split into 6 tets along its main diagonal
/// (Kuhn split: conforming across hexes).
pub fn box_mesh(n: [usize; 3], size: [f64; 3]) -> Mesh {
    mapped_block(n, |u| [u[0] * size[0], u[1] * size[1], u[2] * size[2]])
}

/// A block of hexes in the unit cube mapped by `map`, split into tets as in [`box_mesh`].
pub fn mapped_block(n: [usize; 3], map: impl Fn([f64; 3]) -> [f64; 3]) -> Mesh {
    let [nx, ny, nz] = n.map(|v| v.max(1));
    let id = |i: usize, j: usize, k: usize| (k * (ny + 1) + j) * (nx + 1) + i;
    let mut m = Mesh::default();
    for k in 0..=nz {
        for j in 0..=ny {
            for i in 0..=nx {
                m.points.push(map([
                    i as f64 / nx as f64,
                    j as f64 / ny as f64,
                    k as f64 / nz as f64,
                ]));
            }
        }
    }
    // Each permutation of the axes is a monotone path from corner 000 to 111: one tet.
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
                    let mut t = [id(c[0], c[1], c[2]); 4];
                    for (s, &ax) in p.iter().enumerate() {
                        c[ax] += 1;
                        t[s + 1] = id(c[0], c[1], c[2]);
                    }
                    m.tets.push(t);
                }
            }
        }
    }
    m.orient_tets();
    m
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::mesh::surface;

    #[test]
    fn box_volume_and_closed_boundary() {
        let m = box_mesh([3, 2, 4], [1.0, 2.0, 0.5]);
        let v: f64 = (0..m.tets.len()).map(|t| m.tet_volume(t)).sum();
        assert!((v - 1.0).abs() < 1e-12);
        let b = surface::boundary_faces(&m.points, &m.tets);
        assert_eq!(b.len(), 2 * 2 * (3 * 2 + 2 * 4 + 3 * 4));
        assert_eq!(surface::open_edges(&b), 0);
    }
}
