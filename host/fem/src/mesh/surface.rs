//! Surface analysis: boundary faces of a tet mesh, connected components, enclosed volumes.

use super::Mesh;
use nalgebra::Vector3;
use std::collections::HashMap;

/// Faces of `tets` that belong to exactly one tet, oriented with outward normals.
pub fn boundary_faces(points: &[[f64; 3]], tets: &[[usize; 4]]) -> Vec<[usize; 3]> {
    let mut count: HashMap<[usize; 3], (usize, [usize; 3])> = HashMap::new();
    for t in tets {
        // Faces opposite each vertex, listed so that a positively oriented tet gives outward normals.
        let f = [
            [t[1], t[2], t[3]],
            [t[0], t[3], t[2]],
            [t[0], t[1], t[3]],
            [t[0], t[2], t[1]],
        ];
        let vol = signed_volume(points, t);
        for mut face in f {
            if vol < 0.0 {
                face.swap(1, 2);
            }
            let mut key = face;
            key.sort_unstable();
            count
                .entry(key)
                .and_modify(|e| e.0 += 1)
                .or_insert((1, face));
        }
    }
    let mut out: Vec<[usize; 3]> = count
        .into_values()
        .filter(|(n, _)| *n == 1)
        .map(|(_, f)| f)
        .collect();
    out.sort_unstable();
    out
}

fn signed_volume(points: &[[f64; 3]], t: &[usize; 4]) -> f64 {
    let p = |i: usize| Vector3::from(points[i]);
    (p(t[1]) - p(t[0]))
        .cross(&(p(t[2]) - p(t[0])))
        .dot(&(p(t[3]) - p(t[0])))
}

/// Groups triangles into edge-connected components; returns the triangle indices of each.
pub fn components(triangles: &[[usize; 3]]) -> Vec<Vec<usize>> {
    let mut edge_tris: HashMap<(usize, usize), Vec<usize>> = HashMap::new();
    for (k, t) in triangles.iter().enumerate() {
        for e in 0..3 {
            let (a, b) = (t[e], t[(e + 1) % 3]);
            edge_tris.entry((a.min(b), a.max(b))).or_default().push(k);
        }
    }
    let mut comp = vec![usize::MAX; triangles.len()];
    let mut out = Vec::new();
    for seed in 0..triangles.len() {
        if comp[seed] != usize::MAX {
            continue;
        }
        let id = out.len();
        let mut members = vec![seed];
        comp[seed] = id;
        let mut stack = vec![seed];
        while let Some(k) = stack.pop() {
            let t = triangles[k];
            for e in 0..3 {
                let (a, b) = (t[e], t[(e + 1) % 3]);
                for &n in &edge_tris[&(a.min(b), a.max(b))] {
                    if comp[n] == usize::MAX {
                        comp[n] = id;
                        members.push(n);
                        stack.push(n);
                    }
                }
            }
        }
        members.sort_unstable();
        out.push(members);
    }
    out
}

/// Volume enclosed by a closed triangle surface (positive for outward normals), eq: V = sum x_a.(x_b x x_c)/6.
pub fn enclosed_volume(points: &[[f64; 3]], triangles: &[[usize; 3]]) -> f64 {
    triangles
        .iter()
        .map(|t| {
            let p = |i: usize| Vector3::from(points[i]);
            p(t[0]).dot(&p(t[1]).cross(&p(t[2])))
        })
        .sum::<f64>()
        / 6.0
}

/// Number of edges used by other than exactly two triangles (0 for a closed manifold surface).
pub fn open_edges(triangles: &[[usize; 3]]) -> usize {
    let mut n: HashMap<(usize, usize), usize> = HashMap::new();
    for t in triangles {
        for e in 0..3 {
            let (a, b) = (t[e], t[(e + 1) % 3]);
            *n.entry((a.min(b), a.max(b))).or_default() += 1;
        }
    }
    n.values().filter(|&&c| c != 2).count()
}

/// Maps every point of `surface` to the nearest point of `mesh` if within `tol`; None if any is farther.
pub fn match_points(mesh: &Mesh, surface: &Mesh, tol: f64) -> Result<Vec<usize>, (usize, f64)> {
    // Uniform grid hash keeps the search linear for meshes of a few thousand points.
    let cell = tol.max(1e-12) * 4.0;
    let key = |p: &[f64; 3]| p.map(|c| (c / cell).floor() as i64);
    let mut grid: HashMap<[i64; 3], Vec<usize>> = HashMap::new();
    for (i, p) in mesh.points.iter().enumerate() {
        grid.entry(key(p)).or_default().push(i);
    }
    let mut out = Vec::with_capacity(surface.points.len());
    for (k, q) in surface.points.iter().enumerate() {
        let kq = key(q);
        let mut best = (usize::MAX, f64::INFINITY);
        for dx in -1..=1 {
            for dy in -1..=1 {
                for dz in -1..=1 {
                    if let Some(v) = grid.get(&[kq[0] + dx, kq[1] + dy, kq[2] + dz]) {
                        for &i in v {
                            let p = mesh.points[i];
                            let d = ((p[0] - q[0]).powi(2)
                                + (p[1] - q[1]).powi(2)
                                + (p[2] - q[2]).powi(2))
                            .sqrt();
                            if d < best.1 {
                                best = (i, d);
                            }
                        }
                    }
                }
            }
        }
        if best.1 > tol {
            return Err((k, best.1));
        }
        out.push(best.0);
    }
    Ok(out)
}

/// Generalised winding number of a closed triangle surface about `q` (+-1 inside, 0 outside).
pub fn winding_number(points: &[[f64; 3]], triangles: &[[usize; 3]], q: [f64; 3]) -> f64 {
    let q = Vector3::from(q);
    let mut w = 0.0;
    for t in triangles {
        let a = Vector3::from(points[t[0]]) - q;
        let b = Vector3::from(points[t[1]]) - q;
        let c = Vector3::from(points[t[2]]) - q;
        let (la, lb, lc) = (a.norm(), b.norm(), c.norm());
        let num = a.dot(&b.cross(&c));
        let den = la * lb * lc + a.dot(&b) * lc + a.dot(&c) * lb + b.dot(&c) * la;
        // Van Oosterom-Strackee solid angle of the triangle seen from q.
        w += 2.0 * num.atan2(den);
    }
    w / (4.0 * std::f64::consts::PI)
}

/// Splits tets into regions connected through shared faces, never crossing a face of `walls`.
/// Returns a region id per tet (ids are 0..count, largest region first) and the count.
pub fn regions_cut_by(tets: &[[usize; 4]], walls: &[[usize; 3]]) -> (Vec<usize>, usize) {
    let sorted = |mut f: [usize; 3]| {
        f.sort_unstable();
        f
    };
    let wall: std::collections::HashSet<[usize; 3]> = walls.iter().map(|&f| sorted(f)).collect();
    let mut faces: HashMap<[usize; 3], Vec<usize>> = HashMap::new();
    for (e, t) in tets.iter().enumerate() {
        for skip in 0..4 {
            let mut f = [0; 3];
            let mut k = 0;
            for (j, &n) in t.iter().enumerate() {
                if j != skip {
                    f[k] = n;
                    k += 1;
                }
            }
            let f = sorted(f);
            if !wall.contains(&f) {
                faces.entry(f).or_default().push(e);
            }
        }
    }
    let mut parent: Vec<usize> = (0..tets.len()).collect();
    fn root(p: &mut [usize], mut i: usize) -> usize {
        while p[i] != i {
            p[i] = p[p[i]];
            i = p[i];
        }
        i
    }
    for v in faces.values() {
        for w in v.windows(2) {
            let (a, b) = (root(&mut parent, w[0]), root(&mut parent, w[1]));
            parent[a] = b;
        }
    }
    let roots: Vec<usize> = (0..tets.len()).map(|e| root(&mut parent, e)).collect();
    let mut size: HashMap<usize, usize> = HashMap::new();
    for &r in &roots {
        *size.entry(r).or_default() += 1;
    }
    let mut order: Vec<(usize, usize)> = size.into_iter().collect();
    order.sort_by(|a, b| b.1.cmp(&a.1).then(a.0.cmp(&b.0)));
    let id: HashMap<usize, usize> = order
        .iter()
        .enumerate()
        .map(|(k, &(r, _))| (r, k))
        .collect();
    (roots.iter().map(|r| id[r]).collect(), order.len())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn unit_tet_surface_is_closed_and_outward() {
        let pts = [
            [0.0, 0.0, 0.0],
            [1.0, 0.0, 0.0],
            [0.0, 1.0, 0.0],
            [0.0, 0.0, 1.0],
        ];
        let f = boundary_faces(&pts, &[[0, 1, 2, 3]]);
        assert_eq!(f.len(), 4);
        assert_eq!(open_edges(&f), 0);
        assert!((enclosed_volume(&pts, &f) - 1.0 / 6.0).abs() < 1e-15);
        // The same tet listed with the opposite orientation still yields outward faces.
        let f2 = boundary_faces(&pts, &[[0, 2, 1, 3]]);
        assert!((enclosed_volume(&pts, &f2) - 1.0 / 6.0).abs() < 1e-15);
        assert_eq!(components(&f).len(), 1);
    }
}
