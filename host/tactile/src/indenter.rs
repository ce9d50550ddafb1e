//! Rigid indenters: closed STL surfaces, placed in the gel frame, queried for signed distances.

use crate::{Result, TactileError};
use nalgebra::{Matrix3, Rotation3, Vector3};
// parry speaks glam (through rapier's version, one parry in the build); its points are
// converted at this boundary.
use parry3d_f64::math::Vector as PVec;
use parry3d_f64::query::PointQuery;
use parry3d_f64::shape::{FeatureId, TriMesh, TriMeshFlags};
use std::path::Path;

/// An indenter surface in its own frame, metres, with the tip (lowest point) at z = `z_min`.
#[derive(Clone)]
pub struct Indenter {
    /// Name for reports.
    pub name: String,
    /// The triangle mesh (parry, with pseudo-normals for inside/outside).
    mesh: TriMesh,
    /// Lowest z of the surface in its own frame, m.
    pub z_min: f64,
    /// Bounding box of the surface in its own frame, m.
    pub bounds: ([f64; 3], [f64; 3]),
    /// Edges (end points, own frame, m) where the surface touches itself: more than two
    /// triangles share them, so the outside there is a crevice of zero width.
    pub pinch_edges: Vec<[Vector3<f64>; 2]>,
}

impl std::fmt::Debug for Indenter {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Indenter")
            .field("name", &self.name)
            .field("triangles", &self.mesh.indices().len())
            .field("bounds", &self.bounds)
            .finish()
    }
}

/// The closest point of the indenter surface to a query point, in the gel frame.
#[derive(Debug, Clone, Copy)]
pub struct Proximity {
    /// Signed distance, m: positive outside the indenter, negative inside (penetration).
    pub distance: f64,
    /// Outward unit normal of the indenter at the closest point (the direction that separates).
    pub normal: Vector3<f64>,
}

impl Indenter {
    /// Reads an STL; coordinates are taken as millimetres when the part is larger than 0.2 in
    /// its file's units (no indenter is 20 cm wide) and as metres otherwise.
    pub fn from_stl(path: impl AsRef<Path>) -> Result<Self> {
        let path = path.as_ref();
        let mesh = ocm_fem::mesh::stl::read_path(path)?;
        let name = path
            .file_stem()
            .map(|s| s.to_string_lossy().into_owned())
            .unwrap_or_default();
        let (lo, hi) = mesh.bounds();
        let extent = (0..3).map(|k| hi[k] - lo[k]).fold(0.0, f64::max);
        let scale = if extent > 0.2 { 1e-3 } else { 1.0 };
        let points: Vec<[f64; 3]> = mesh.points.iter().map(|p| p.map(|c| c * scale)).collect();
        // Exporters round float32 coordinates differently on neighbouring facets: vertices
        // closer than 1e-6 of the part's size are one vertex (unseen id4 needs it).
        let (points, triangles) = weld(points, &mesh.triangles, 1e-6 * extent * scale);
        Self::from_triangles(&name, points, triangles)
    }

    /// Builds an indenter from a triangle surface in metres. The surface must be closed (every
    /// edge shared by exactly two triangles) and is oriented so that its volume is positive.
    pub fn from_triangles(
        name: &str,
        points: Vec<[f64; 3]>,
        mut triangles: Vec<[usize; 3]>,
    ) -> Result<Self> {
        let err = |msg: String| TactileError::Indenter {
            name: name.to_string(),
            msg,
        };
        if triangles.is_empty() {
            return Err(err("the surface has no triangles".into()));
        }
        // Closed: every directed edge is matched by as many reversed ones (an edge where two
        // lobes touch, used by four triangles, is allowed: unseen id4 has one).
        let mut count: std::collections::HashMap<(usize, usize), i64> = Default::default();
        let mut uses: std::collections::HashMap<(usize, usize), usize> = Default::default();
        for t in &triangles {
            for e in 0..3 {
                let (a, b) = (t[e], t[(e + 1) % 3]);
                let key = (a.min(b), a.max(b));
                *count.entry(key).or_default() += if a < b { 1 } else { -1 };
                *uses.entry(key).or_default() += 1;
            }
        }
        let mut pinch_edges: Vec<[Vector3<f64>; 2]> = uses
            .iter()
            .filter(|&(_, &n)| n > 2)
            .map(|(&(a, b), _)| [Vector3::from(points[a]), Vector3::from(points[b])])
            .collect();
        pinch_edges.sort_by(|p, q| {
            (p[0].x, p[0].y, p[0].z)
                .partial_cmp(&(q[0].x, q[0].y, q[0].z))
                .unwrap_or(std::cmp::Ordering::Equal)
        });
        let open = count.values().filter(|&&c| c != 0).count();
        if open > 0 {
            return Err(err(format!(
                "the surface is not closed: {open} edges are not matched by an oppositely \
                 oriented triangle, so inside and outside are undefined"
            )));
        }
        let vol = ocm_fem::mesh::surface::enclosed_volume(&points, &triangles);
        if !(vol.abs() > 0.0) {
            return Err(err("the surface encloses no volume".into()));
        }
        if vol < 0.0 {
            for t in &mut triangles {
                t.swap(1, 2);
            }
        }
        let mut lo = [f64::INFINITY; 3];
        let mut hi = [f64::NEG_INFINITY; 3];
        for p in &points {
            for k in 0..3 {
                lo[k] = lo[k].min(p[k]);
                hi[k] = hi[k].max(p[k]);
            }
        }
        let verts: Vec<PVec> = points.iter().map(|p| PVec::new(p[0], p[1], p[2])).collect();
        let idx: Vec<[u32; 3]> = triangles.iter().map(|t| t.map(|i| i as u32)).collect();
        let mesh = TriMesh::with_flags(verts, idx, TriMeshFlags::ORIENTED)
            .map_err(|e| err(format!("cannot build the triangle mesh: {e:?}")))?;
        Ok(Indenter {
            name: name.to_string(),
            mesh,
            z_min: lo[2],
            bounds: (lo, hi),
            pinch_edges,
        })
    }

    /// Signed distance and separating normal of a point given in the indenter's own frame.
    pub fn query_local(&self, p: &Vector3<f64>) -> Proximity {
        let (proj, feature) = self
            .mesh
            .project_local_point_and_get_feature(PVec::new(p.x, p.y, p.z));
        let d = p - Vector3::new(proj.point.x, proj.point.y, proj.point.z);
        let dist = d.norm();
        let sign = if proj.is_inside { -1.0 } else { 1.0 };
        // On the surface the offset vanishes; the face normal then separates.
        let normal = if dist > 1e-12 {
            d * (sign / dist)
        } else {
            match feature {
                // the face id is the triangle's own (front or back); the mesh's triangle is
                // the projection's sub-shape
                FeatureId::Face(_) => self
                    .mesh
                    .triangle(proj.subshape % self.mesh.indices().len() as u32)
                    .normal()
                    .map(|n| Vector3::new(n.x, n.y, n.z))
                    .unwrap_or_else(Vector3::z),
                _ => Vector3::z(),
            }
        };
        Proximity {
            distance: sign * dist,
            normal,
        }
    }

    /// The point of the surface's self-touching edges nearest to a point of its own frame, and
    /// the distance to it, m; `None` when the surface nowhere touches itself.
    pub fn nearest_pinch_local(&self, p: &Vector3<f64>) -> Option<(f64, Vector3<f64>)> {
        self.pinch_edges
            .iter()
            .map(|[a, b]| {
                let ab = b - a;
                let t =
                    ((p - a).dot(&ab) / ab.norm_squared().max(f64::MIN_POSITIVE)).clamp(0.0, 1.0);
                let c = a + ab * t;
                ((p - c).norm(), c)
            })
            .min_by(|x, y| x.0.total_cmp(&y.0))
    }

    /// Lowest z of the surface after rotating it by `rotation` about its own origin, m.
    pub fn lowest_z(&self, rotation: &Matrix3<f64>) -> f64 {
        self.mesh
            .vertices()
            .iter()
            .map(|v| (rotation * Vector3::new(v.x, v.y, v.z)).z)
            .fold(f64::INFINITY, f64::min)
    }

    /// Centre (x, y) of the part of the surface within `band_m` of its lowest point after
    /// rotating it by `rotation` about its own origin, m: where it first presses the gel.
    pub fn tip_center_xy(&self, rotation: &Matrix3<f64>, band_m: f64) -> [f64; 2] {
        let low = self.lowest_z(rotation);
        let (mut lo, mut hi) = ([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]);
        for v in self.mesh.vertices() {
            let q = rotation * Vector3::new(v.x, v.y, v.z);
            if q.z <= low + band_m {
                for k in 0..2 {
                    lo[k] = lo[k].min(q[k]);
                    hi[k] = hi[k].max(q[k]);
                }
            }
        }
        [0.5 * (lo[0] + hi[0]), 0.5 * (lo[1] + hi[1])]
    }

    /// Distance along +z from the local point `origin` (direction `dir`, local frame) to the
    /// surface, if the ray hits it within `max_m`.
    pub fn ray_local(&self, origin: &Vector3<f64>, dir: &Vector3<f64>, max_m: f64) -> Option<f64> {
        use parry3d_f64::query::{Ray, RayCast};
        let ray = Ray::new(
            PVec::new(origin.x, origin.y, origin.z),
            PVec::new(dir.x, dir.y, dir.z),
        );
        self.mesh.cast_local_ray(&ray, max_m, true)
    }

    /// Volume enclosed by the surface, m^3.
    pub fn volume(&self) -> f64 {
        let pts: Vec<[f64; 3]> = self
            .mesh
            .vertices()
            .iter()
            .map(|p| [p.x, p.y, p.z])
            .collect();
        let tris: Vec<[usize; 3]> = self
            .mesh
            .indices()
            .iter()
            .map(|t| t.map(|i| i as usize))
            .collect();
        ocm_fem::mesh::surface::enclosed_volume(&pts, &tris)
    }
}

/// Merges vertices that round to the same multiple of `tol` and drops triangles that collapse.
fn weld(points: Vec<[f64; 3]>, tris: &[[usize; 3]], tol: f64) -> (Vec<[f64; 3]>, Vec<[usize; 3]>) {
    let mut index = std::collections::HashMap::new();
    let mut out = Vec::new();
    let map: Vec<usize> = points
        .iter()
        .map(|p| {
            let key = p.map(|c| (c / tol).round() as i64);
            *index.entry(key).or_insert_with(|| {
                out.push(*p);
                out.len() - 1
            })
        })
        .collect();
    let tris = tris
        .iter()
        .map(|t| t.map(|i| map[i]))
        .filter(|t| t[0] != t[1] && t[1] != t[2] && t[0] != t[2])
        .collect();
    (out, tris)
}

/// Where an indenter sits in the gel frame: x_gel = R x_local + t.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Pose {
    /// Rotation, local to gel.
    pub rotation: Matrix3<f64>,
    /// Translation, m.
    pub translation: Vector3<f64>,
}

impl Pose {
    /// Rotation from Euler angles in degrees, applied about x, then y, then z (R = Rz Ry Rx).
    pub fn rotation_from_degrees(euler_deg: [f64; 3]) -> Matrix3<f64> {
        let [a, b, c] = euler_deg.map(f64::to_radians);
        (Rotation3::from_axis_angle(&Vector3::z_axis(), c)
            * Rotation3::from_axis_angle(&Vector3::y_axis(), b)
            * Rotation3::from_axis_angle(&Vector3::x_axis(), a))
        .into_inner()
    }

    /// Gel-frame point to the indenter frame.
    pub fn to_local(&self, x: &Vector3<f64>) -> Vector3<f64> {
        self.rotation.transpose() * (x - self.translation)
    }
}

/// An indenter placed in the gel frame.
#[derive(Debug, Clone)]
pub struct Placed<'a> {
    /// The surface.
    pub indenter: &'a Indenter,
    /// Its pose.
    pub pose: Pose,
}

impl Placed<'_> {
    /// Signed distance and separating normal (gel frame) of gel-frame point `x`.
    pub fn query(&self, x: &Vector3<f64>) -> Proximity {
        let p = self.indenter.query_local(&self.pose.to_local(x));
        Proximity {
            distance: p.distance,
            normal: self.pose.rotation * p.normal,
        }
    }

    /// The nearest point (gel frame) of the surface's self-touching edges to gel-frame point
    /// `x`, and the distance to it, m.
    pub fn nearest_pinch(&self, x: &Vector3<f64>) -> Option<(f64, Vector3<f64>)> {
        self.indenter
            .nearest_pinch_local(&self.pose.to_local(x))
            .map(|(d, c)| (d, self.pose.rotation * c + self.pose.translation))
    }

    /// Axis-aligned box of the placed surface in the gel frame, m (from its local box corners).
    pub fn bounds(&self) -> ([f64; 3], [f64; 3]) {
        let (lo, hi) = self.indenter.bounds;
        let mut a = [f64::INFINITY; 3];
        let mut b = [f64::NEG_INFINITY; 3];
        for c in 0..8 {
            let p = Vector3::new(
                if c & 1 == 0 { lo[0] } else { hi[0] },
                if c & 2 == 0 { lo[1] } else { hi[1] },
                if c & 4 == 0 { lo[2] } else { hi[2] },
            );
            let q = self.pose.rotation * p + self.pose.translation;
            for k in 0..3 {
                a[k] = a[k].min(q[k]);
                b[k] = b[k].max(q[k]);
            }
        }
        (a, b)
    }
}
